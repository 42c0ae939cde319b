//! `[classes]` in a robot: the section loads from TOML (names and raw ids), its errors name the
//! key, and Fusion turns a segmenter's pixel values into SGM classes, counting the values it does
//! not know instead of dropping them silently.

use actix::{Actor, Context, Handler};
use nalgebra::Point3;
use sgm_actors::config::RobotConfig;
use sgm_actors::fusion::{Fusion, GetFusionStatus};
use sgm_actors::messages::{FrameLabels, LabelledScan, SensorFrame};
use sgm_model::geometry::Pose3;
use sgm_model::perception::label_map::SegmenterClass;
use sgm_model::scene_graph::LabelId;
use std::sync::{Arc, Mutex};

/// Keeps the labels of every scan Fusion hands on.
struct Tracker(Arc<Mutex<Vec<Vec<Option<LabelId>>>>>);

impl Actor for Tracker {
    type Context = Context<Self>;
}

impl Handler<LabelledScan> for Tracker {
    type Result = ();
    fn handle(&mut self, scan: LabelledScan, _: &mut Context<Self>) {
        self.0.lock().unwrap().push(scan.labels);
    }
}

fn load(toml: &str) -> Result<RobotConfig, String> {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("robot.toml");
    std::fs::write(&file, toml).unwrap();
    RobotConfig::load_with_env(Some(&file), "SGM_CLASSES_TEST").map_err(|e| e.to_string())
}

#[test]
fn the_section_loads_and_its_errors_name_the_key() {
    let config =
        load("[classes]\nsegmenter = \"ade20k_150\"\n[classes.map]\nchair = [\"chair\", 31]\ntrash_can = [138]\n")
            .expect("valid");
    assert_eq!(config.classes.segmenter, "ade20k_150");
    assert_eq!(config.classes.map["chair"], vec![SegmenterClass::Name("chair".into()), SegmenterClass::Id(31)]);
    assert_eq!(config.classes.map["trash_can"], vec![SegmenterClass::Id(138)]);
    assert_eq!(RobotConfig::default().classes.segmenter, "identity");

    let error = load("[classes]\nsegmenter = \"ade20k_150\"\n[classes.map]\nsofa = [\"sofa\"]\n").unwrap_err();
    assert!(error.starts_with("classes.map.sofa: no class \"sofa\" in fusion.classes (ground, wall,"), "{error}");
    let error = load("[classes]\nsegmenter = \"cityscapes\"\n[classes.map]\ncar = [19]\n").unwrap_err();
    assert_eq!(error, "classes.map.car: id 19 is beyond segmenter cityscapes's ids 0–18");
    let error = load("[classes]\nsegmenter = \"ade\"\n").unwrap_err();
    assert!(error.starts_with("classes.segmenter: unknown segmenter \"ade\"; known: identity, ade20k_150"), "{error}");
    let error = load("[classes]\npalete = []\n").unwrap_err();
    assert!(error.contains("palete"), "unknown keys are refused: {error}");
}

/// A chair of ADE20K ids (chair 19 and armchair 30 both, as a network labels one object) in a
/// frame with sky (2: no SGM class), the ignore value 255 and an id beyond ADE's table (150):
/// the chair comes out as SGM's chair, the sky and 255 carry no class unnoticed, and 150 is
/// counted per id.
#[test]
fn fusion_maps_ade_ids_and_counts_an_unknown_one() {
    let mut config = RobotConfig::default();
    config.classes.segmenter = "ade20k_150".into();
    config.fusion.label_vote.voxel_m = 0.0;
    let (classes, map) = config.class_tables().expect("valid");
    let chair = LabelId(classes.by_name("chair").unwrap().id);
    let scans = Arc::new(Mutex::new(Vec::new()));
    let seen = scans.clone();
    let status = actix_rt::System::new().block_on(async move {
        let tracker = Tracker(seen).start();
        let fusion = Fusion::new(&config.fusion, classes, map, tracker.recipient()).start();
        // 40 chair returns in a 0.4 m cube at 3 m, then the others.
        let mut points: Vec<Point3<f64>> = (0..40)
            .map(|k| {
                Point3::new(3.0 + 0.1 * f64::from(k % 4), 0.1 * f64::from((k / 4) % 4), 0.3 + 0.1 * f64::from(k / 16))
            })
            .collect();
        let mut labels: Vec<Option<LabelId>> =
            (0..40).map(|k| Some(LabelId(if k % 2 == 0 { 19 } else { 30 }))).collect();
        for (k, id) in [2u16, 255, 150, 150, 150].into_iter().enumerate() {
            points.push(Point3::new(-5.0, k as f64, 1.0));
            labels.push(Some(LabelId(id)));
        }
        let frame = SensorFrame {
            stamp: 1.0,
            odom_from_body: Pose3::identity(),
            points_in_body: points,
            point_times: None,
            points_deskewed: false,
            labels: FrameLabels::PerPoint(labels),
            imu: Vec::new(),
            motion_covariance: None,
            measured_up: None,
        };
        fusion.send(frame.clone()).await.unwrap();
        fusion.send(frame).await.unwrap();
        fusion.send(GetFusionStatus).await.unwrap()
    });
    assert_eq!(status.segmenter, "ade20k_150");
    assert_eq!(status.unknown_label_points, 6, "150 three times in each of two frames");
    assert_eq!(status.unknown_label_ids.into_iter().collect::<Vec<_>>(), vec![(150, 6)]);
    assert_eq!(status.unknown_label_other_points, 0);
    let scans = scans.lock().unwrap();
    assert_eq!(scans.len(), 2);
    assert!(scans[0][..40].iter().all(|l| *l == Some(chair)), "{:?}", &scans[0][..40]);
    assert!(scans[0][40..].iter().all(Option::is_none), "{:?}", &scans[0][40..]);
}
