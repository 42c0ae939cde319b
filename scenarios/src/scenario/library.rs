//! The shipped scenarios (`scenarios/library/*.toml`), built into the binary so that `sgm run NAME`
//! works from any directory.

const LIBRARY: &[(&str, &str)] = &[
    ("quickstart", include_str!("../../library/quickstart.toml")),
    ("outdoor_two_robots", include_str!("../../library/outdoor_two_robots.toml")),
    ("indoor_three_robots", include_str!("../../library/indoor_three_robots.toml")),
    ("team_of_eight", include_str!("../../library/team_of_eight.toml")),
    ("team_of_sixteen", include_str!("../../library/team_of_sixteen.toml")),
    ("legged_campus", include_str!("../../library/legged_campus.toml")),
    ("handheld_indoor", include_str!("../../library/handheld_indoor.toml")),
    ("faults/clean", include_str!("../../library/faults/clean.toml")),
    ("faults/loss_30", include_str!("../../library/faults/loss_30.toml")),
    ("faults/loss_60", include_str!("../../library/faults/loss_60.toml")),
    ("faults/duplicate_reorder", include_str!("../../library/faults/duplicate_reorder.toml")),
    ("faults/partition", include_str!("../../library/faults/partition.toml")),
    ("faults/late_join", include_str!("../../library/faults/late_join.toml")),
    ("faults/crash_restart", include_str!("../../library/faults/crash_restart.toml")),
    ("faults/false_factors", include_str!("../../library/faults/false_factors.toml")),
    ("field/fleet_four", include_str!("../../library/field/fleet_four.toml")),
    ("field/fleet_sixteen", include_str!("../../library/field/fleet_sixteen.toml")),
    ("endurance/team_of_eight_1h", include_str!("../../library/endurance/team_of_eight_1h.toml")),
    ("endurance/odometry_1h", include_str!("../../library/endurance/odometry_1h.toml")),
];

/// The TOML text of a library scenario.
pub fn get(name: &str) -> Option<&'static str> {
    LIBRARY.iter().find(|(n, _)| *n == name).map(|(_, text)| *text)
}

/// Every library scenario's name.
pub fn names() -> Vec<&'static str> {
    LIBRARY.iter().map(|(n, _)| *n).collect()
}
