//! `sgm bench realism`: what each of the unkind world's effects costs (the simulator's terrain,
//! platforms, LiDAR, camera, segmenter and odometry keys). The paper's outdoor mission
//! (`outdoor_two_robots`) is run as it is, with each effect alone, and with all of them
//! (`legged_campus`, the same mission on the paper's robots); indoors, the paper's indoor
//! mission as it is (`indoor_three_robots`) and with all of them (`handheld_indoor`). For each:
//! the pairs aligned (and none more than [`super::WRONG_M`] off), the mean inter-robot error at
//! the end of the mission and the team ATE (`Report::team_ate_rmse_m`). One seed's odometry drift can move a row more
//! than its effect does (seed 1's terrain run drifts 2° in heading against 0.7° on flat ground,
//! and doubles bravo's ATE; seeds 2–4 show no cost), so each effect runs over `--seeds`
//! consecutive seeds and the row gives their mean and the spread of the team ATE.

use super::{aligned_right, duration_arg, load_cut, or_dash, run_all, Job, Section};
use serde::Serialize;
use sgm_scenarios::report::Report;
use sgm_scenarios::scenario::{LidarPattern, OdometrySourceSpec, Platform, Scenario};
use std::fmt::Write;

/// One effect: its name, what it turns on, and how.
struct Effect {
    name: &'static str,
    what: &'static str,
    apply: fn(&mut Scenario),
}

fn terrain(s: &mut Scenario) {
    s.terrain.max_slope_deg = 10.0;
    s.terrain.kerbs = 3;
    s.terrain.ramps = 2;
}

fn legged(s: &mut Scenario) {
    for r in &mut s.robots {
        r.platform = Platform::Legged;
        r.sensor_height_m = 0.5;
    }
}

fn livox(s: &mut Scenario) {
    s.lidar.pattern = LidarPattern::Livox;
    s.lidar.vertical_fov_deg = [-7.0, 52.0];
    s.lidar.points_per_frame = 20_000;
    s.lidar.max_range_m = 40.0;
}

fn sweep(s: &mut Scenario) {
    s.lidar.sweep_s = 0.1;
}

fn lidar_mount(s: &mut Scenario) {
    s.lidar.mount_xyz_m = [0.2, 0.0, 0.1];
    s.lidar.mount_rpy_deg = [0.0, 5.0, 0.0];
    s.lidar.mount_error_deg = 0.5;
    s.lidar.mount_error_m = 0.01;
}

fn camera_mount(s: &mut Scenario) {
    s.camera.mount_xyz_m = [0.25, 0.0, -0.08];
    s.camera.mount_rpy_deg = [0.0, 10.0, 0.0];
    s.camera.exposure_offset_s = 0.02;
}

fn calibration_errors(s: &mut Scenario) {
    camera_mount(s);
    s.camera.mount_error_deg = 1.0;
    s.camera.mount_error_m = 0.02;
    s.camera.clock_offset_s = 0.01;
}

fn confusion(s: &mut Scenario) {
    let row = |pairs: &[(&str, f64)]| pairs.iter().map(|(c, p)| (c.to_string(), *p)).collect();
    let c = &mut s.segmentation.confusion;
    c.insert("bench".into(), row(&[("bench", 0.9), ("trash_can", 0.1)]));
    c.insert("trash_can".into(), row(&[("trash_can", 0.9), ("bench", 0.1)]));
    c.insert("lamp_post".into(), row(&[("lamp_post", 0.85), ("tree", 0.15)]));
    c.insert("tree".into(), row(&[("tree", 0.95), ("lamp_post", 0.05)]));
}

fn people(s: &mut Scenario) {
    s.segmentation.people = 10;
    s.segmentation.add_person_class(&mut s.fusion.classes);
}

fn tilt_drift(s: &mut Scenario) {
    s.odometry.tilt_walk_deg = 0.1;
}

/// Each robot's own LiDAR-inertial odometry on its sweeps and an IMU whose biases start where a
/// calibrated MEMS part's do (the library's realism scenarios' values).
fn own_odometry(s: &mut Scenario) {
    sweep(s);
    s.imu.enabled = true;
    s.imu.gyro_turn_on_bias = 0.003;
    s.imu.accel_turn_on_bias = 0.05;
    s.odometry.source = OdometrySourceSpec::Internal;
}

const EFFECTS: &[Effect] = &[
    Effect { name: "none", what: "outdoor_two_robots as it is", apply: |_| {} },
    Effect { name: "terrain", what: "10° hills, 3 sidewalks with kerbs, 2 ramps", apply: terrain },
    Effect {
        name: "legged",
        what: "legged robots (gait roll/pitch 3° at 2 Hz, bounce), LiDAR at 0.5 m",
        apply: legged,
    },
    Effect { name: "livox", what: "a Livox-Mid-360-like pattern, 40 m", apply: livox },
    Effect { name: "sweep", what: "0.1 s sweeps, deskewed with the odometry's twist", apply: sweep },
    Effect {
        name: "legged + sweep",
        what: "a legged robot's sweeps, odometry twist only",
        apply: |s| {
            legged(s);
            sweep(s);
        },
    },
    Effect {
        name: "legged + sweep + IMU",
        what: "the same, deskewed with the gyro",
        apply: |s| {
            legged(s);
            sweep(s);
            s.imu.enabled = true;
        },
    },
    Effect {
        name: "lidar mount",
        what: "LiDAR 0.2 m ahead and 0.1 m up, pitched 5°, told 0.5° and 1 cm off",
        apply: lidar_mount,
    },
    Effect {
        name: "camera mount",
        what: "camera 0.25 m ahead, pitched 10°, firing 20 ms late (compensated)",
        apply: camera_mount,
    },
    Effect {
        name: "calibration errors",
        what: "that mount told 1° and 2 cm off, camera clock 10 ms off",
        apply: calibration_errors,
    },
    Effect {
        name: "confusion",
        what: "a systematic confusion matrix (bench ↔ trash can 10 %, lamp post → tree 15 %, tree → lamp post 5 %)",
        apply: confusion,
    },
    Effect {
        name: "edge bleed",
        what: "labels bleeding 3 px over farther surfaces",
        apply: |s| s.segmentation.edge_bleed_px = 3.0,
    },
    Effect {
        name: "misses",
        what: "objects under 100 px² or beyond 25 m missed",
        apply: |s| {
            s.segmentation.min_pixels = 100.0;
            s.segmentation.max_range_m = Some(25.0);
        },
    },
    Effect {
        name: "false blobs",
        what: "one false-positive blob per frame",
        apply: |s| s.segmentation.false_blobs_per_frame = 1.0,
    },
    Effect { name: "people", what: "10 people walking through (a dynamic class)", apply: people },
    Effect {
        name: "tilt drift",
        what: "odometry without gravity: roll/pitch walk 0.1°/√m, tilt estimated",
        apply: tilt_drift,
    },
    Effect {
        name: "tilt drift, 4-DoF",
        what: "the same, the matcher told the frames are level (matcher.max_tilt_deg = 0)",
        apply: |s| {
            tilt_drift(s);
            s.matcher.matching.max_tilt_deg = 0.0;
        },
    },
    Effect {
        name: "own odometry",
        what: "each robot's own LiDAR-inertial odometry on 0.1 s sweeps and an IMU with turn-on biases (0.003 rad/s, 0.05 m/s²), not the synthetic one",
        apply: own_odometry,
    },
];

/// Library scenarios run as they are, after the effects: the row's name, the scenario and what
/// it holds. `legged_campus` is every effect at once outdoors; indoors, `handheld_indoor` (every
/// effect, the paper's robots, a ceiling) stands beside the kind mission it makes unkind.
const WHOLE_SCENARIOS: &[(&str, &str, &str)] = &[
    ("all (legged_campus)", "legged_campus", "every effect above together, on the robots' own odometry"),
    ("indoors, as it is (indoor_three_robots)", "indoor_three_robots", "the paper's indoor mission as it is, three robots"),
    (
        "indoors, every effect (handheld_indoor)",
        "handheld_indoor",
        "the same rooms under a ceiling, with ramps: two legged robots and a handheld rig (6-DoF sway), every effect above, on the robots' own odometry",
    ),
];

/// One effect's figures over its seeds.
#[derive(Clone, Debug, Serialize)]
pub struct Row {
    pub effect: String,
    pub what: String,
    pub seeds: Vec<u64>,
    /// Over all seeds' runs.
    pub pairs: usize,
    pub aligned_right: usize,
    /// Mean over the aligned pairs of all seeds' runs, m and °.
    pub inter_robot_error_m: Option<f64>,
    pub inter_robot_error_deg: Option<f64>,
    /// Mean, least and most over the seeds' runs, m.
    pub team_ate_m: Option<f64>,
    pub team_ate_min_m: Option<f64>,
    pub team_ate_max_m: Option<f64>,
    pub sim_s: f64,
}

fn mean(v: &[f64]) -> Option<f64> {
    (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
}

fn row(effect: &str, what: &str, runs: &[(u64, Report)]) -> Row {
    let aligned: Vec<_> = runs.iter().flat_map(|(_, r)| &r.alignments).filter(|a| a.state == "Aligned").collect();
    let ates: Vec<f64> = runs.iter().filter_map(|(_, r)| r.team_ate_rmse_m).collect();
    Row {
        effect: effect.into(),
        what: what.into(),
        seeds: runs.iter().map(|(seed, _)| *seed).collect(),
        pairs: runs.iter().map(|(_, r)| r.alignments.len()).sum(),
        aligned_right: runs.iter().flat_map(|(_, r)| &r.alignments).filter(|a| aligned_right(a)).count(),
        inter_robot_error_m: mean(&aligned.iter().filter_map(|a| a.translation_error_m).collect::<Vec<_>>()),
        inter_robot_error_deg: mean(&aligned.iter().filter_map(|a| a.rotation_error_deg).collect::<Vec<_>>()),
        team_ate_m: mean(&ates),
        team_ate_min_m: ates.iter().copied().reduce(f64::min),
        team_ate_max_m: ates.iter().copied().reduce(f64::max),
        sim_s: runs.first().map_or(0.0, |(_, r)| r.sim_s),
    }
}

/// What `sgm bench realism` runs.
pub struct Options<'a> {
    /// Each mission cut to this many simulated seconds.
    pub duration: Option<f64>,
    /// Only the effects whose names contain this.
    pub only: Option<&'a str>,
    /// Each effect runs with the scenario's seed and the `seeds − 1` after it.
    pub seeds: u64,
}

/// Runs every effect over its seeds, on every core.
pub fn run_bench(options: &Options) -> anyhow::Result<Section> {
    let Options { duration, only, seeds } = *options;
    anyhow::ensure!(seeds >= 1, "--seeds must be at least 1, not {seeds}");
    let mut rows: Vec<(&str, &str)> = Vec::new();
    let mut jobs = Vec::new();
    let mut add = |rows: &mut Vec<(&'static str, &'static str)>, name, what, base: Scenario| {
        for k in 0..seeds {
            let mut scenario = base.clone();
            scenario.scenario.seed = base.scenario.seed + k;
            let label = format!("realism: {name}, seed {}", scenario.scenario.seed);
            jobs.push(Job { row: rows.len(), seed: scenario.scenario.seed, scenario, label });
        }
        rows.push((name, what));
    };
    for effect in EFFECTS.iter().filter(|e| only.is_none_or(|o| e.name.contains(o))) {
        let mut s = load_cut("outdoor_two_robots", duration)?;
        (effect.apply)(&mut s);
        add(&mut rows, effect.name, effect.what, s);
    }
    for &(name, scenario, what) in WHOLE_SCENARIOS {
        if only.is_none_or(|o| name.contains(o)) {
            add(&mut rows, name, what, load_cut(scenario, duration)?);
        }
    }
    let mut runs: Vec<Vec<(u64, Report)>> = rows.iter().map(|_| Vec::new()).collect();
    for (k, seed, report) in run_all(jobs)? {
        runs[k].push((seed, report));
    }
    let rows: Vec<Row> = rows.iter().zip(&runs).map(|((name, what), runs)| row(name, what, runs)).collect();
    let only_arg = only.map(|o| format!(" --only '{o}'")).unwrap_or_default();
    let seeds_arg = if seeds > 1 { format!(" --seeds {seeds}") } else { String::new() };
    let command = format!("sgm bench realism{}{seeds_arg}{only_arg}", duration_arg(duration));
    let mut md = format!("### The unkind world, one effect at a time\n\n`{command}`\n\n");
    md.push_str(
        "| Effect | What | Pairs aligned | Inter-robot error | Team ATE (least–most) |\n|---|---|---|---|---|\n",
    );
    for r in &rows {
        let _ = writeln!(
            md,
            "| {} | {} | {}/{} | {} m / {}° | {} m ({}–{}) |",
            r.effect,
            r.what,
            r.aligned_right,
            r.pairs,
            or_dash(r.inter_robot_error_m, 2),
            or_dash(r.inter_robot_error_deg, 2),
            or_dash(r.team_ate_m, 2),
            or_dash(r.team_ate_min_m, 2),
            or_dash(r.team_ate_max_m, 2)
        );
    }
    Ok(Section { markdown: md, json: serde_json::json!({ "command": command, "rows": rows }) })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every whole-scenario row names a library scenario, and `--only` can pick each alone.
    #[test]
    fn whole_scenario_rows_load_and_are_told_apart() {
        for &(name, scenario, _) in WHOLE_SCENARIOS {
            assert!(Scenario::load(scenario).is_ok(), "{name}: {scenario} is not in the library");
            let picked = WHOLE_SCENARIOS.iter().filter(|(other, _, _)| other.contains(scenario)).count();
            assert_eq!(picked, 1, "--only {scenario} picks {picked} rows");
            assert!(EFFECTS.iter().all(|e| !e.name.contains(scenario)), "--only {scenario} picks an effect too");
        }
        // The effects' names (and "all") do not pick the indoor rows.
        let indoor = WHOLE_SCENARIOS.iter().filter(|(name, _, _)| name.starts_with("indoors"));
        for (name, _, _) in indoor {
            let picked: Vec<_> = EFFECTS.iter().map(|e| e.name).chain(["all"]).filter(|e| name.contains(e)).collect();
            assert!(picked.is_empty(), "--only {picked:?} picks {name}");
        }
    }
}
