//! The bodies of the `cargo fuzz` targets (`fuzz/`), one plain function per target. Each target
//! is one line, `fuzz_target!(|data: &[u8]| sgm_tests::fuzz_bodies::TARGET(data))`, and
//! `tests/tests/fuzz_corpora.rs` runs the same functions on stable over every committed input
//! (`fuzz/corpus/TARGET/`, `fuzz/regressions/TARGET/`). A body panics when what must hold does
//! not; `fuzz/README.md` lists what each one feeds.

use rosrust::RosMsg;
use sgm_actors::config::OptimiserConfig;
use sgm_actors::optimiser::Optimiser;
use sgm_actors::snapshot::{RobotSnapshot, ROBOT_SNAPSHOT_KIND};
use sgm_bridge::bounded::{Bounded, Layout};
use sgm_bridge::bounded_deliver::BoundedDeliverReq;
use sgm_bridge::config::{LabelSource, RosConfig, DEFAULT_MAX_MESSAGE_BYTES};
use sgm_bridge::inputs::Inputs;
use sgm_bridge::msg::{nav_msgs, sensor_msgs, sgm_msgs};
use sgm_model::scene_graph::RobotId;
use sgm_model::wire::cloud_codec::{declared_points, decode_at_most};
use sgm_model::wire::{open, TeamKey, WireLimits, MAC_BYTES};
use sgm_scenarios::scenario::Scenario;

/// A target's body: panics when what must hold does not.
pub type Body = fn(&[u8]);

/// Every target by name, as `fuzz/corpus/` and `fuzz/regressions/` name their directories.
pub const TARGETS: &[(&str, Body)] = &[
    ("wire_envelope", wire_envelope),
    ("cloud_codec", cloud_codec),
    ("pcd", pcd),
    ("g2o", g2o),
    ("scenario_config", scenario_config),
    ("snapshot", snapshot),
    ("ros_messages", ros_messages),
    ("rosbag", rosbag),
    ("rosbag2_mcap", rosbag2_mcap),
    ("rosbag2_sqlite", rosbag2_sqlite),
    ("cdr_messages", cdr_messages),
    ("tcpros_reply", tcpros_reply),
];

/// The radio's decoder: `wire::open` on (a) the bytes as received, which a foreign radio
/// controls entirely, and (b) the bytes sealed with the team key first — what a teammate with a
/// bug, or an attacker holding the key, could send — so that the fuzzer reaches the postcard
/// decoding of every message type and the limits behind the MAC. Whatever opens must survive
/// encoding and decoding again unchanged (compared as bytes: a NaN is not equal to itself).
pub fn wire_envelope(data: &[u8]) {
    let key = TeamKey::from_bytes([7; 32]);
    let limits = WireLimits::default();
    assert!(open(data, &key, &limits).is_err() || data.len() > MAC_BYTES);
    let mut sealed = data.to_vec();
    sealed.extend_from_slice(&key.mac(data));
    if let Ok(envelope) = open(&sealed, &key, &limits) {
        let again = postcard::to_stdvec(&envelope).expect("an opened envelope encodes");
        let back: sgm_model::wire::Envelope = postcard::from_bytes(&again).expect("and decodes");
        assert_eq!(postcard::to_stdvec(&back).expect("encodes again"), again);
    }
}

/// Object and keyframe clouds from the radio: `cloud_codec::decode_at_most` never allocates
/// beyond its limit, never panics, and agrees with the header's declared count.
pub fn cloud_codec(data: &[u8]) {
    if let Ok(points) = decode_at_most(data, 100_000) {
        assert_eq!(Some(points.len() as u64), declared_points(data));
        assert!(points.iter().all(|p| p.coords.iter().all(|v| v.is_finite())));
    }
}

/// PCD files (ascii, binary, binary_compressed): `pcd::read_pcd` never panics.
pub fn pcd(data: &[u8]) {
    let _ = sgm_model::pcd::read_pcd(data);
}

/// g2o pose graphs (`sgm optimize`): `read_g2o` on one or two files never panics.
pub fn g2o(data: &[u8]) {
    let text = String::from_utf8_lossy(data);
    let (a, b) = text.split_at(text.char_indices().nth(text.len() / 2).map_or(0, |(i, _)| i));
    let _ = sgm_model::optim::g2o::read_g2o(&[&text]);
    let _ = sgm_model::optim::g2o::read_g2o(&[a, b]);
}

/// Scenario files, which hold every section of a robot's configuration and `[ros]`:
/// `Scenario::from_toml` parses and validates without panicking, and a scenario that loads
/// gives each robot a configuration that validates.
pub fn scenario_config(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else { return };
    if let Ok(scenario) = Scenario::from_toml(text, "fuzz.toml", "SGM_FUZZ_UNSET") {
        for k in 0..scenario.robots.len() {
            assert!(scenario.robot_config(k).validate().is_ok());
        }
    }
}

/// Robot snapshots on disk. The first byte picks what the rest is: 0, a whole file (the frame
/// check, `model::snapshot::verify`, and the full decode); otherwise the postcard content of a
/// `RobotSnapshot`, framed here with a correct checksum (`model::snapshot::frame`) so that the
/// fuzzer reaches the decoding behind it — what a snapshot written by a different build would
/// present. A decoded snapshot's pose graph is then thawed into an Optimiser, whose consistency
/// check must hold the line.
pub fn snapshot(data: &[u8]) {
    use sgm_model::snapshot::{decode, frame, verify};
    let Some((mode, rest)) = data.split_first() else { return };
    let Ok(bytes) = (if *mode == 0 { Ok(rest.to_vec()) } else { frame(ROBOT_SNAPSHOT_KIND, rest) }) else { return };
    let framed_ok = verify(&bytes, ROBOT_SNAPSHOT_KIND).is_ok();
    let decoded = decode::<RobotSnapshot>(&bytes, ROBOT_SNAPSHOT_KIND, 64 << 20);
    assert!(framed_ok || decoded.is_err());
    if let Ok(snapshot) = decoded {
        let _ = Optimiser::new(RobotId(1), OptimiserConfig::default()).thawed(snapshot.optimiser);
    }
}

fn bounded<M: RosMsg + Layout>(framed: &[u8]) -> Option<M> {
    Bounded::<M>::decode_slice(framed).ok().map(|b| b.0)
}

/// The node's subscriptions: the bytes of a received message (after TCPROS's length prefix) as
/// each subscribed type — PointCloud2, Image (ids or a palette's colours), CameraInfo,
/// Odometry, Imu, TFMessage, the team's Envelope — through `bounded::Bounded` (the layout and size
/// check, then rosrust's decoder) and, when that accepts them, through the same checks and
/// conversions as the live node (`Inputs`; a TFMessage into a robot's tf tree and mounts).
/// The same bytes as a request to the node's Deliver service (`bounded_deliver`).
pub fn ros_messages(data: &[u8]) {
    use sgm_actors::config::OdometrySource::Internal;
    let mut framed = (data.len() as u32).to_le_bytes().to_vec();
    framed.extend_from_slice(data);
    let config = RosConfig { labels: LabelSource::Cloud, ..RosConfig::default() };
    let mut inputs = Inputs::new(&config, "alpha", 1);
    // Colour label images read back through the built-in classes' palette.
    if let Ok(colours) = sgm_actors::config::RobotConfig::default().colour_ids() {
        inputs = inputs.with_colours(colours);
    }
    if let Some(m) = bounded::<sgm_bridge::msg::tf2_msgs::TFMessage>(&framed) {
        // Every transform into a robot's tf tree, and its mounts resolved.
        if let (Ok(payload), Ok(mut sync)) =
            (inputs.tf(&m, true), sgm_bridge::sync::Synchroniser::for_robot(&config, &inputs, Internal))
        {
            sync.feed(sgm_bridge::convert::time::Epoch { sec: 0 }, payload);
            let _ = sync.tf();
        }
    }
    if let Some(m) = bounded::<sensor_msgs::PointCloud2>(&framed) {
        let _ = inputs.cloud(&m);
    }
    if let Some(m) = bounded::<sensor_msgs::Image>(&framed) {
        let _ = inputs.image(&m);
    }
    if let Some(m) = bounded::<sensor_msgs::CameraInfo>(&framed) {
        let _ = inputs.camera_info(&m);
    }
    if let Some(m) = bounded::<nav_msgs::Odometry>(&framed) {
        let _ = inputs.odometry(&m);
    }
    if let Some(m) = bounded::<sensor_msgs::Imu>(&framed) {
        // A sample into the internal odometry's IMU stream, and a frame assembled with it.
        if let (Ok(payload), Ok(mut sync)) =
            (inputs.imu(&m), sgm_bridge::sync::Synchroniser::for_robot(&config, &inputs, Internal))
        {
            sync.feed(sgm_bridge::convert::time::Epoch { sec: 0 }, payload);
            let _ = sync.finish(sgm_bridge::convert::time::Epoch { sec: 0 });
        }
    }
    let _ = bounded::<sgm_msgs::Envelope>(&framed);
    let _ = BoundedDeliverReq::decode_slice(&framed);
}

/// ROS 1 bags for `sgm replay`: the bytes as a bag through the replay's reader
/// (`bag::reader::decode_bag`, what `read_bag`'s thread runs on a file: the bag's records read
/// within bounds by `bag::records`, its connections checked against the configured topics and
/// types, each message decoded within `ros.max_message_bytes` and checked by `Inputs`).
/// Whatever the bytes, the reader ends: with its messages and refusals, and at most one failure,
/// the last item.
pub fn rosbag(data: &[u8]) {
    use sgm_bridge::bag::reader::{decode_bag, BagItem, BagSource};
    let mut failed = false;
    decode_bag(data, data.len() as u64, "fuzz.bag", &BagSource::new(&RosConfig::default(), "alpha", 1), |item| {
        assert!(!failed, "an item after the failure");
        failed = matches!(item, BagItem::Failed(_));
        true
    });
}

/// What a reader of a recording must do whatever its bytes: end, with its messages and refusals
/// and at most one failure, the last item.
fn ends_with_at_most_one_failure(read: impl FnOnce(&mut dyn FnMut(sgm_bridge::bag::reader::BagItem) -> bool)) {
    use sgm_bridge::bag::reader::BagItem;
    let mut failed = false;
    read(&mut |item| {
        assert!(!failed, "an item after the failure");
        failed = matches!(item, BagItem::Failed(_));
        true
    });
}

/// The replay's robot, reading its IMU too (every input a recording may carry).
fn replay_source() -> sgm_bridge::bag::reader::BagSource {
    sgm_bridge::bag::reader::BagSource::new(&RosConfig::default(), "alpha", 1).with_imu()
}

/// ROS 2 recordings' MCAP storage for `sgm replay`: the bytes as an `.mcap` file through
/// `bag::rosbag2::decode_mcap` (the file streamed by the `mcap` crate's reader, every record
/// within the bound, chunks decompressed as they come; channels checked against the topics and
/// types; each message's CDR decoded within `ros.max_message_bytes` and checked by `Inputs`).
pub fn rosbag2_mcap(data: &[u8]) {
    let source = replay_source();
    ends_with_at_most_one_failure(|out| sgm_bridge::bag::rosbag2::decode_mcap(data, "fuzz.mcap", &source, out));
}

/// ROS 2 recordings' sqlite3 storage: the bytes as a `.db3` file (SQLite reads files, so they
/// are written to a temporary one) through `bag::rosbag2::decode_recording`, the replay's reader
/// of a storage file alone.
pub fn rosbag2_sqlite(data: &[u8]) {
    let Ok(dir) = tempfile::tempdir() else { return };
    let path = dir.path().join("fuzz.db3");
    if std::fs::write(&path, data).is_err() {
        return;
    }
    let source = replay_source();
    ends_with_at_most_one_failure(|out| sgm_bridge::bag::rosbag2::decode_recording(&path, &source, out));
}

/// The CDR decoder: the bytes as each ROS 2 message type the replay reads
/// (`bag::cdr::decode`, in the byte order the encapsulation says), and what decodes through the
/// same checks as a ROS 1 message's (`Inputs`).
pub fn cdr_messages(data: &[u8]) {
    use sgm_bridge::bag::cdr::decode;
    use sgm_bridge::msg::tf2_msgs;
    let max = DEFAULT_MAX_MESSAGE_BYTES;
    let inputs = Inputs::new(&RosConfig::default(), "alpha", 1);
    if let Ok(m) = decode::<sensor_msgs::PointCloud2>(data, max) {
        let _ = inputs.cloud(&m);
    }
    if let Ok(m) = decode::<sensor_msgs::Image>(data, max) {
        let _ = inputs.image(&m);
    }
    if let Ok(m) = decode::<sensor_msgs::CameraInfo>(data, max) {
        let _ = inputs.camera_info(&m);
    }
    if let Ok(m) = decode::<nav_msgs::Odometry>(data, max) {
        let _ = inputs.odometry(&m);
    }
    if let Ok(m) = decode::<sensor_msgs::Imu>(data, max) {
        let _ = inputs.imu(&m);
    }
    if let Ok(m) = decode::<tf2_msgs::TFMessage>(data, max) {
        let _ = inputs.tf(&m, false);
    }
}

/// The reply to our TCPROS service client (`transport::call`), which a peer that is slow, buggy
/// or hostile controls entirely: the bytes as a connection header's body (`decode_header`),
/// and as the whole reply stream (`read_reply`: header, ok byte, reply), with the node's
/// default bound on a reply.
pub fn tcpros_reply(data: &[u8]) {
    use sgm_bridge::transport::call::{decode_header, read_reply};
    let _ = decode_header(data);
    let _ = read_reply(&mut &data[..], DEFAULT_MAX_MESSAGE_BYTES);
}
