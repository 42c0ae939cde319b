//! Every input a fuzz target crashed on (`fuzz/README.md`), kept in `tests/fuzz_regressions/`
//! and fed again to what the node decodes ROS messages with. The first, found by fuzzing
//! rosrust's own decoder, is 41 bytes of PointCloud2 whose `data` declares 4 143 379 968
//! bytes: rosrust reserved them before reading (an abort under the fuzzer's malloc limit).
//! Through `Bounded` every one is refused by name and allocates nothing of the sort.

use rosrust::RosMsg;
use sgm_bridge::bounded::{Bounded, Layout};
use sgm_bridge::bounded_deliver::BoundedDeliverReq;
use sgm_bridge::msg::{nav_msgs, sensor_msgs, sgm_msgs};
use std::path::Path;

fn refused<M: RosMsg + Layout>(framed: &[u8]) -> Option<String> {
    Bounded::<M>::decode_slice(framed).err().map(|e| e.to_string())
}

#[test]
fn every_crash_input_is_refused_without_a_large_allocation() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fuzz_regressions");
    let mut inputs: Vec<_> = std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().path()).collect();
    inputs.sort();
    assert!(!inputs.is_empty());
    for path in inputs {
        let data = std::fs::read(&path).unwrap();
        // As the fuzz target frames it: TCPROS's length prefix, then the message.
        let mut framed = (data.len() as u32).to_le_bytes().to_vec();
        framed.extend_from_slice(&data);
        let cloud = refused::<sensor_msgs::PointCloud2>(&framed);
        if path.file_name().is_some_and(|n| n.to_string_lossy().starts_with("ros_pointcloud2")) {
            assert!(cloud.as_deref().is_some_and(|e| e.contains("needs")), "{}: {cloud:?}", path.display());
        }
        // Every subscribed type decodes or refuses it; none panics or aborts.
        let _ = refused::<sensor_msgs::Image>(&framed);
        let _ = refused::<sensor_msgs::CameraInfo>(&framed);
        let _ = refused::<nav_msgs::Odometry>(&framed);
        let _ = refused::<sgm_msgs::Envelope>(&framed);
        let _ = BoundedDeliverReq::decode_slice(&framed);
    }
}
