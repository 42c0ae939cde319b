//! Every committed fuzz input is a regression test: each file of `fuzz/corpus/TARGET/` and
//! `fuzz/regressions/TARGET/` runs through the target's body (`sgm_tests::fuzz_bodies`, the
//! function the `cargo fuzz` target calls), on stable and in the ordinary test build. A body
//! panics when what must hold does not; the test names every file that failed.

mod common;

use sgm_tests::fuzz_bodies::TARGETS;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};
use std::time::Instant;

fn fuzz_dir() -> PathBuf {
    common::workspace().join("fuzz")
}

/// The files directly in `dir`, sorted; none if it does not exist.
fn files(dir: &Path) -> Vec<PathBuf> {
    let Ok(entries) = std::fs::read_dir(dir) else { return Vec::new() };
    let mut files: Vec<PathBuf> = entries.flatten().map(|e| e.path()).filter(|p| p.is_file()).collect();
    files.sort();
    files
}

fn panic_text(payload: &(dyn std::any::Any + Send)) -> String {
    payload
        .downcast_ref::<String>()
        .cloned()
        .or_else(|| payload.downcast_ref::<&str>().map(|s| s.to_string()))
        .unwrap_or_else(|| "a panic".into())
}

/// Runs `target`'s body over its corpus and its regressions; fails naming each input that panicked.
fn replay(target: &str) {
    let (_, body) = TARGETS.iter().find(|(name, _)| *name == target).expect("a target of fuzz_bodies");
    let corpus = files(&fuzz_dir().join("corpus").join(target));
    let regressions = files(&fuzz_dir().join("regressions").join(target));
    assert!(!corpus.is_empty(), "fuzz/corpus/{target}/ holds no input");
    let started = Instant::now();
    let mut failed = Vec::new();
    for path in corpus.iter().chain(&regressions) {
        let data = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        if let Err(payload) = catch_unwind(AssertUnwindSafe(|| body(&data))) {
            failed.push(format!("{}: {}", path.display(), panic_text(payload.as_ref())));
        }
    }
    eprintln!(
        "{target}: {} corpus and {} regression inputs in {:.1} s",
        corpus.len(),
        regressions.len(),
        started.elapsed().as_secs_f64()
    );
    assert!(failed.is_empty(), "{target}: {} inputs failed:\n{}", failed.len(), failed.join("\n"));
}

macro_rules! corpus_tests {
    ($($target:ident),* $(,)?) => {
        $(
            #[test]
            fn $target() {
                replay(stringify!($target));
            }
        )*

        /// Every target of `fuzz/fuzz_targets/` has its body, its corpus and a test here.
        #[test]
        fn every_fuzz_target_is_replayed() {
            let tested = [$(stringify!($target)),*];
            let mut targets: Vec<String> = files(&fuzz_dir().join("fuzz_targets"))
                .iter()
                .filter_map(|p| p.file_stem().map(|s| s.to_string_lossy().into_owned()))
                .collect();
            targets.sort();
            let mut bodies: Vec<&str> = TARGETS.iter().map(|(name, _)| *name).collect();
            bodies.sort();
            let mut tested = tested.to_vec();
            tested.sort();
            assert_eq!(targets, bodies, "fuzz/fuzz_targets/ against sgm_tests::fuzz_bodies::TARGETS");
            assert_eq!(bodies, tested, "sgm_tests::fuzz_bodies::TARGETS against the tests here");
            for target in &targets {
                let source = std::fs::read_to_string(fuzz_dir().join("fuzz_targets").join(format!("{target}.rs")))
                    .expect("the target's source");
                assert!(source.contains(&format!("sgm_tests::fuzz_bodies::{target}(")), "{target}.rs calls its body");
            }
        }
    };
}

corpus_tests!(
    wire_envelope,
    cloud_codec,
    pcd,
    g2o,
    scenario_config,
    snapshot,
    ros_messages,
    rosbag,
    rosbag2_mcap,
    rosbag2_sqlite,
    cdr_messages,
    tcpros_reply
);

/// Writes the `rosbag` target's seeds into `$SGM_FUZZ_SEEDS`: bags as `sgm run --bag-out`
/// records them (`BagRecorder`), a few frames of a few points each so that the fuzzer mutates
/// small inputs: camera on (camera info, label image, odometry, ground truth, cloud) and camera
/// off (labels in the cloud). `fuzz/README.md` says how the compressed and damaged variants
/// were made from them.
#[test]
#[ignore = "writes the rosbag fuzz target's seeds: SGM_FUZZ_SEEDS=DIR"]
fn write_rosbag_seeds() {
    use nalgebra::Point3;
    use sgm_bridge::config::RosConfig;
    use sgm_model::geometry::Pose3;
    use sgm_model::perception::projection::{CameraModel, LabelImage};
    use sgm_scenarios::bag_out::{BagRecorder, RecordedFrame, RecordedImage};
    let dir = PathBuf::from(std::env::var("SGM_FUZZ_SEEDS").expect("SGM_FUZZ_SEEDS=DIR"));
    let camera = CameraModel { width: 4, height: 3, fx: 2.0, fy: 2.0, cx: 2.0, cy: 1.5, distortion: [0.0; 5] };
    let image = LabelImage::new(4, 3, (0..12).map(|i| i % 3).collect()).expect("a 4 × 3 image");
    for (name, frames, camera_on) in [("one_frame", 1, true), ("three_frames", 3, true), ("labels_in_cloud", 2, false)]
    {
        let mut recorder = BagRecorder::new(&dir, &RosConfig::default(), vec![name.to_string()]).expect("a recorder");
        for k in 0..frames {
            let t = 1.0 + 0.1 * f64::from(k);
            let pose = Pose3::translation(t, 0.0, 0.0);
            let points: Vec<Point3<f64>> = (0..4).map(|i| Point3::new(2.0 + f64::from(i), 0.5, 0.2)).collect();
            let labels = [1u16, 1, 2, 0];
            recorder
                .record(
                    0,
                    RecordedFrame {
                        t,
                        odometry: &pose,
                        truth: &pose,
                        points: &points,
                        labels: (!camera_on).then_some(&labels[..]),
                        image: camera_on.then_some(RecordedImage {
                            image: &image,
                            camera: &camera,
                            stamp: t,
                            camera_from_body: sgm_scenarios::sim::camera::camera_from_body(),
                        }),
                        times: None,
                        imu: &[],
                    },
                )
                .expect("recorded");
        }
        recorder.finish().expect("closed");
    }
}
