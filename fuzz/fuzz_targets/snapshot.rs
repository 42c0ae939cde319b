//! Robot snapshots on disk. The first byte picks what the rest is: 0, a whole file (the frame
//! check, `model::snapshot::verify`, and the full decode); otherwise the postcard content of a
//! `RobotSnapshot`, framed here with a correct checksum (`model::snapshot::frame`) so that the fuzzer reaches the decoding
//! behind it — what a snapshot written by a different build would present. A decoded snapshot's
//! pose graph is then thawed into an Optimiser, whose consistency check must hold the line.
#![no_main]

use libfuzzer_sys::fuzz_target;
use sgm_actors::config::OptimiserConfig;
use sgm_actors::optimiser::Optimiser;
use sgm_actors::snapshot::{RobotSnapshot, ROBOT_SNAPSHOT_KIND};
use sgm_model::scene_graph::RobotId;
use sgm_model::snapshot::{decode, frame, verify};

fuzz_target!(|data: &[u8]| {
    let Some((mode, rest)) = data.split_first() else { return };
    let Ok(bytes) = (if *mode == 0 { Ok(rest.to_vec()) } else { frame(ROBOT_SNAPSHOT_KIND, rest) }) else { return };
    let framed_ok = verify(&bytes, ROBOT_SNAPSHOT_KIND).is_ok();
    let decoded = decode::<RobotSnapshot>(&bytes, ROBOT_SNAPSHOT_KIND, 64 << 20);
    assert!(framed_ok || decoded.is_err());
    if let Ok(snapshot) = decoded {
        let _ = Optimiser::new(RobotId(1), OptimiserConfig::default()).thawed(snapshot.optimiser);
    }
});
