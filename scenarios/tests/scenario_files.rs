//! Scenario files: every shipped scenario parses; bad files give an error naming the key.

use sgm_scenarios::scenario::{library, Scenario, ScenarioError};

fn parse(text: &str) -> Result<Scenario, ScenarioError> {
    Scenario::from_toml(text, "test.toml", "SGM_SCENARIO_TEST")
}

const ONE_ROBOT: &str = "[[robots]]\nwaypoints = [[0.0, 0.0], [10.0, 0.0]]\n";

#[test]
fn every_shipped_scenario_parses_and_is_what_its_name_says() {
    for name in library::names() {
        let s = Scenario::load_with_env(name, "SGM_SCENARIO_TEST").unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(s.scenario.name, name);
        assert!(!s.robots.is_empty());
        let file = library::get(name).unwrap();
        let on_disk =
            std::fs::read_to_string(sgm_scenarios::scenario::library_dir().join(format!("{name}.toml"))).unwrap();
        assert_eq!(file, on_disk, "{name}: the built-in copy is the file");
    }
    let outdoor = Scenario::load_with_env("outdoor_two_robots", "SGM_SCENARIO_TEST").unwrap();
    assert_eq!((outdoor.robots.len(), outdoor.scenario.duration_s, outdoor.world.size_m), (2, 600.0, [150.0, 150.0]));
    let indoor = Scenario::load_with_env("indoor_three_robots", "SGM_SCENARIO_TEST").unwrap();
    let heights: Vec<f64> = indoor.robots.iter().map(|r| r.sensor_height_m).collect();
    assert!(heights.iter().any(|h| (h - heights[0]).abs() > 0.5), "one robot carried higher: {heights:?}");
    assert_eq!(Scenario::load_with_env("team_of_eight", "SGM_SCENARIO_TEST").unwrap().robots.len(), 8);
}

#[test]
fn a_file_path_loads_too_and_unknown_names_list_the_library() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("mine.toml");
    std::fs::write(&path, format!("[scenario]\nname = \"mine\"\n{ONE_ROBOT}")).unwrap();
    assert_eq!(Scenario::load_with_env(path.to_str().unwrap(), "SGM_SCENARIO_TEST").unwrap().scenario.name, "mine");
    let e = Scenario::load_with_env("no_such_scenario", "SGM_SCENARIO_TEST").unwrap_err().to_string();
    assert!(e.contains("no_such_scenario") && e.contains("quickstart"), "{e}");
}

#[test]
fn an_unknown_key_is_named() {
    let e = parse(&format!("[world]\nsize = [10.0, 10.0]\n{ONE_ROBOT}")).unwrap_err().to_string();
    assert!(e.contains("size") && e.contains("test.toml"), "{e}");
    let e = parse(&format!("[wolrd]\nkind = \"campus\"\n{ONE_ROBOT}")).unwrap_err().to_string();
    assert!(e.contains("wolrd"), "{e}");
}

#[test]
fn a_wrong_unit_or_type_is_named() {
    let e = parse(&format!("[scenario]\nduration_s = \"10 min\"\n{ONE_ROBOT}")).unwrap_err().to_string();
    assert!(e.contains("duration_s"), "{e}");
    let e = parse(&format!("[radio]\nloss = 30.0\n{ONE_ROBOT}")).unwrap_err().to_string();
    assert_eq!(e, "test.toml: radio.loss = 30: allowed 0 ≤ x ≤ 1");
    let e = parse(&format!("[world.objects]\nunicorn = 3\n{ONE_ROBOT}")).unwrap_err().to_string();
    assert!(e.contains("world.objects.unicorn"), "{e}");
}

#[test]
fn a_missing_robot_is_named() {
    let e = parse("[scenario]\nduration_s = 60.0\n").unwrap_err().to_string();
    assert!(e.contains("robots") && e.contains("at least one"), "{e}");
    let e = parse("[[robots]]\nwaypoints = [[0.0, 0.0]]\n").unwrap_err().to_string();
    assert!(e.contains("robots[0].waypoints"), "{e}");
    let e = parse("[[robots]]\nname = \"a\"\nwaypoints = [[0.0, 0.0], [1.0, 0.0]]\n[[robots]]\nname = \"a\"\nwaypoints = [[0.0, 0.0], [1.0, 0.0]]\n")
        .unwrap_err()
        .to_string();
    assert!(e.contains("robots[1].name"), "{e}");
}

#[test]
fn robot_configuration_sections_are_shared_and_checked() {
    let s = parse(&format!("[matcher]\nedge_sharpness = 2.5\n{ONE_ROBOT}")).unwrap();
    assert_eq!(s.robot_config(0).matcher.matching.edge_sharpness, 2.5);
    assert_eq!(s.robot_config(0).robot.id, 1);
    let e = parse(&format!("[comms]\nmax_keyframes_in_flight = 0\n{ONE_ROBOT}")).unwrap_err().to_string();
    assert!(e.contains("comms.max_keyframes_in_flight"), "{e}");
}

#[test]
fn impossible_terrain_platforms_and_imus_are_refused_with_their_key() {
    let refused = |toml: &str, expected: &str| {
        let e = parse(&format!("{toml}\n{ONE_ROBOT}")).unwrap_err().to_string();
        assert_eq!(e, format!("test.toml: {expected}"));
    };
    refused("[terrain]\nmax_slope_deg = 90.0", "terrain.max_slope_deg = 90: allowed 0 ≤ x ≤ 30°");
    refused("[terrain]\nramp_slope_deg = 0.0", "terrain.ramp_slope_deg = 0: allowed 0 < x ≤ 30°");
    refused("[terrain]\nkerb_height_m = -0.1", "terrain.kerb_height_m = -0.1: allowed 0 ≤ x ≤ 0.5 m");
    refused("[platforms]\ngait_hz = -2.0", "platforms.gait_hz = -2: allowed 0.1 ≤ x ≤ 10 Hz");
    // A ceiling over a campus; a sensor that would look down on one.
    refused("[world]\nceiling = true", "world.ceiling = true: allowed true only with kind = \"indoor\"");
    refused(
        "[world]\nkind = \"indoor\"\nceiling = true\nwall_height_m = 1.0",
        "robots[0].sensor_height_m = 0.8: allowed with world.ceiling, under it: x + the ramps' and kerbs' height < world.wall_height_m − 0.3 m",
    );
    // An IMU slower than the LiDAR's frames.
    refused(
        "[scenario]\nframe_interval_s = 0.1\n[imu]\nrate_hz = 5.0",
        "imu.rate_hz = 5: allowed ≥ the frame rate (1 / scenario.frame_interval_s) and ≤ 2000 Hz",
    );
    refused("[imu]\ngyro_noise = -1e-4", "imu.gyro_noise = -0.0001: allowed 0 ≤ x ≤ 1");
    refused("[imu]\ngyro_turn_on_bias = 0.5", "imu.gyro_turn_on_bias = 0.5: allowed 0 ≤ x ≤ 0.1 rad/s");
    refused("[imu]\naccel_turn_on_bias = -0.1", "imu.accel_turn_on_bias = -0.1: allowed 0 ≤ x ≤ 1 m/s²");
    // A camera firing further from its scan than a frame, a wild mount, a clock a second off.
    refused(
        "[scenario]\nframe_interval_s = 0.1\n[camera]\nexposure_offset_s = 0.2",
        "camera.exposure_offset_s = 0.2: allowed −scenario.frame_interval_s ≤ x ≤ scenario.frame_interval_s",
    );
    refused(
        "[camera]\nmount_xyz_m = [0.0, 9.0, 0.0]",
        "camera.mount_xyz_m = [0.0, 9.0, 0.0]: allowed each −5 ≤ x ≤ 5 m",
    );
    refused("[camera]\nmount_error_deg = 45.0", "camera.mount_error_deg = 45: allowed 0 ≤ x ≤ 10°");
    refused(
        "[lidar]\nmount_rpy_deg = [0.0, 200.0, 0.0]",
        "lidar.mount_rpy_deg = [0.0, 200.0, 0.0]: allowed each −180 ≤ x ≤ 180°",
    );
    refused("[lidar]\nmount_error_m = -0.1", "lidar.mount_error_m = -0.1: allowed 0 ≤ x ≤ 0.5 m");
    refused("[camera]\nclock_offset_s = -1.0", "camera.clock_offset_s = -1: allowed −0.5 ≤ x ≤ 0.5 s");
    let e =
        parse("[[robots]]\nplatform = \"hovercraft\"\nwaypoints = [[0.0, 0.0], [1.0, 0.0]]\n").unwrap_err().to_string();
    assert!(e.contains("hovercraft") && e.contains("platform"), "{e}");
    let ok = parse(&format!("[terrain]\nmax_slope_deg = 15.0\nramps = 2\n[imu]\nenabled = true\n{ONE_ROBOT}")).unwrap();
    assert!(!ok.terrain.is_flat() && ok.imu.enabled);
}

#[test]
fn impossible_segmenter_errors_are_refused_with_their_key() {
    let refused = |toml: &str, expected: &str| {
        let e = parse(&format!("{toml}\n{ONE_ROBOT}")).unwrap_err().to_string();
        assert_eq!(e, format!("test.toml: {expected}"));
    };
    refused(
        "[segmentation.confusion]\nbench = { bench = 0.8, tree = 0.1 }",
        "segmentation.confusion.bench = (row sum 0.9): allowed probabilities summing to 1 (± 1e-6)",
    );
    refused(
        "[segmentation.confusion]\nbench = { bench = 0.5, unicorn = 0.5 }",
        "segmentation.confusion.bench.unicorn = 0.5: allowed a class of [fusion].classes",
    );
    refused(
        "[segmentation.confusion]\nunicorn = { bench = 1.0 }",
        "segmentation.confusion.unicorn = (row): allowed a class of [fusion].classes",
    );
    refused(
        "[segmentation.confusion]\nbench = { bench = 1.5, tree = -0.5 }",
        "segmentation.confusion.bench.bench = 1.5: allowed 0 ≤ x ≤ 1",
    );
    refused(
        "[segmentation]\nfalse_blobs_per_frame = -1.0",
        "segmentation.false_blobs_per_frame = -1: allowed 0 ≤ x ≤ 100",
    );
    refused("[segmentation]\nedge_bleed_px = -2.0", "segmentation.edge_bleed_px = -2: allowed 0 ≤ x ≤ 50 px");
    refused("[segmentation]\nmin_pixels = -1.0", "segmentation.min_pixels = -1: allowed 0 ≤ x ≤ 1e6 px²");
    refused("[segmentation]\nmax_range_m = 0.0", "segmentation.max_range_m = 0: allowed 0 < x ≤ 10000 m, or unset");
    refused("[segmentation]\nperson_speed_mps = -1.2", "segmentation.person_speed_mps = -1.2: allowed 0 ≤ x ≤ 5 m/s");
    let e = parse(&format!("[segmentation]\npeople = -3\n{ONE_ROBOT}")).unwrap_err().to_string();
    assert!(e.contains("segmentation.people"), "{e}");

    // Rows within 1e-6 of 1 are taken; people bring their class, dynamic, when it is missing.
    let ok = parse(&format!(
        "[segmentation]\npeople = 2\n[segmentation.confusion]\nbench = {{ bench = 0.6, tree = 0.4000004 }}\n{ONE_ROBOT}"
    ))
    .unwrap();
    let person = ok.fusion.classes.iter().find(|c| c.name == "person").expect("person added");
    assert!(person.dynamic && !person.matchable);
    assert!(ok.fusion.classes.iter().filter(|c| c.id == person.id).count() == 1, "a free id");
    let none = parse(ONE_ROBOT).unwrap();
    assert!(none.fusion.classes.iter().all(|c| c.name != "person"), "no people, no class");
}

/// The book: "A file's table replaces the default one" — not merged with it, which gave the
/// indoor scenarios a campus's trees, lamp posts and benches among their furniture.
#[test]
fn a_files_object_table_replaces_the_default_one() {
    let objects = |text: &str| parse(&format!("{text}{ONE_ROBOT}")).unwrap().world.objects;
    let given = objects("[world.objects]\nchair = 3\ntable = 2\n");
    assert_eq!(given.into_iter().collect::<Vec<_>>(), vec![("chair".to_string(), 3), ("table".to_string(), 2)]);
    assert_eq!(objects(""), sgm_scenarios::scenario::WorldSpec::default().objects);
    assert!(objects("[world.objects]\n").is_empty(), "an empty table: a world without objects");
    // The environment's keys go over the file's table (a prefix of its own: tests run in parallel).
    std::env::set_var("SGM_OBJECTS_TABLE_TEST__WORLD__OBJECTS__TABLE", "5");
    let both =
        Scenario::from_toml(&format!("[world.objects]\nchair = 3\n{ONE_ROBOT}"), "test.toml", "SGM_OBJECTS_TABLE_TEST");
    std::env::remove_var("SGM_OBJECTS_TABLE_TEST__WORLD__OBJECTS__TABLE");
    let both = both.unwrap().world.objects.into_iter().collect::<Vec<_>>();
    assert_eq!(both, vec![("chair".to_string(), 3), ("table".to_string(), 5)]);
    // ... and over the default table when the file gives none.
    std::env::set_var("SGM_OBJECTS_DEFAULT_TEST__WORLD__OBJECTS__TREE", "20");
    let over = Scenario::from_toml(ONE_ROBOT, "test.toml", "SGM_OBJECTS_DEFAULT_TEST");
    std::env::remove_var("SGM_OBJECTS_DEFAULT_TEST__WORLD__OBJECTS__TREE");
    let mut expected = sgm_scenarios::scenario::WorldSpec::default().objects;
    expected.insert("tree".into(), 20);
    assert_eq!(over.unwrap().world.objects, expected);
}
