//! Our bag writer and reader, and both against the `rosbag` crate's reader (Debian's `rosbag
//! info/check/play` are run on the same kind of bag by `tests/ros_interop.sh` from `.ci/run`).

use nalgebra::Point3;
use sgm_bridge::bag::reader::{read_bag, BagItem, BagSource, Payload};
use sgm_bridge::bag::records::{BagLimits, ChunkRecord, ChunkSection};
use sgm_bridge::bag::writer::BagWriter;
use sgm_bridge::config::RosConfig;
use sgm_bridge::convert::cloud::cloud_msg;
use sgm_bridge::convert::geometry::odometry_msg;
use sgm_bridge::convert::image::label_image_msg;
use sgm_bridge::convert::time::SCENARIO_EPOCH;
use sgm_bridge::msg::std_msgs::Header;
use sgm_model::geometry::Pose3;
use sgm_model::perception::projection::LabelImage;
use sgm_model::scene_graph::stamp_from_nanos;

fn header(t: f64, frame: &str) -> Header {
    Header { seq: 0, stamp: SCENARIO_EPOCH.time(t), frame_id: frame.into() }
}

#[test]
fn written_bags_read_back_in_time_order_across_chunks() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("alpha.bag");
    let mut bag = BagWriter::create(&path).unwrap();
    let frames = 60; // 60 × 40 000 points × 12 bytes: many 768 KiB chunks
    for k in 1..=frames {
        let t = stamp_from_nanos(i64::from(k) * 100_000_000);
        let points: Vec<Point3<f32>> = (0..40_000).map(|i| Point3::new(i as f32 * 0.01, k as f32, 1.5)).collect();
        let pose = Pose3::translation(t, 0.0, 0.0);
        bag.write(
            "/alpha/odometry",
            SCENARIO_EPOCH.time(t),
            &odometry_msg(header(t, "alpha/odom"), "alpha/base_link", &pose),
        )
        .unwrap();
        bag.write(
            "/alpha/points",
            SCENARIO_EPOCH.time(t),
            &cloud_msg(header(t, "alpha/base_link"), &points, None, |_| [0; 3]),
        )
        .unwrap();
        let encoding_ok = k != 7;
        let mut image = label_image_msg(header(t, "alpha/camera"), &LabelImage::new(4, 2, vec![k as u16; 8]).unwrap());
        if !encoding_ok {
            image.encoding = "yuv422".into();
        }
        bag.write("/alpha/labels", SCENARIO_EPOCH.time(t), &image).unwrap();
    }
    // A second type on a topic already in use is refused.
    assert!(bag.write("/alpha/points", SCENARIO_EPOCH.time(9.0), &header(9.0, "x")).is_err());
    bag.finish().unwrap();
    if let Ok(dir) = std::env::var("SGM_KEEP_BAG") {
        std::fs::copy(&path, std::path::Path::new(&dir).join("alpha.bag")).unwrap();
    }

    let mut clouds = 0;
    let mut last = 0;
    let mut refused = Vec::new();
    for item in read_bag(&path, BagSource::new(&RosConfig::default(), "alpha", 1)) {
        match item {
            BagItem::Message { time_nanos, payload } => {
                assert!(time_nanos >= last, "record times in order");
                last = time_nanos;
                if let Payload::Cloud(t, scan) = payload {
                    clouds += 1;
                    assert_eq!(scan.points.len(), 40_000);
                    assert_eq!(SCENARIO_EPOCH.stamp(t), stamp_from_nanos(i64::from(clouds) * 100_000_000));
                    assert_eq!(scan.points[7].y, f64::from(clouds));
                }
            }
            BagItem::Refused { topic, error, .. } => refused.push(format!("{topic}: {error}")),
            BagItem::Failed(e) => panic!("{e}"),
        }
    }
    assert_eq!(clouds, frames);
    assert_eq!(refused, vec!["/alpha/labels: unsupported encoding `yuv422` (mono8, mono16, 8UC1, 16UC1, rgb8, bgr8, rgba8 or bgra8 expected)"]);
}

#[test]
fn a_topic_of_the_wrong_type_and_a_missing_file_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("wrong.bag");
    let mut bag = BagWriter::create(&path).unwrap();
    bag.write("/points", SCENARIO_EPOCH.time(1.0), &header(1.0, "x")).unwrap();
    bag.finish().unwrap();
    let items: Vec<BagItem> = read_bag(&path, BagSource::new(&RosConfig::default(), "alpha", 1)).into_iter().collect();
    assert!(
        matches!(&items[..], [BagItem::Failed(e)] if e.to_string().contains("topic /points carries std_msgs/Header"))
    );
    let items: Vec<BagItem> =
        read_bag(&dir.path().join("none.bag"), BagSource::new(&RosConfig::default(), "a", 1)).into_iter().collect();
    assert!(matches!(&items[..], [BagItem::Failed(e)] if e.to_string().contains("none.bag")));
    std::fs::write(dir.path().join("junk.bag"), b"#ROSBAG V2.0\n\x10\x00").unwrap();
    let items: Vec<BagItem> =
        read_bag(&dir.path().join("junk.bag"), BagSource::new(&RosConfig::default(), "a", 1)).into_iter().collect();
    assert!(matches!(&items[..], [BagItem::Failed(_)]));
}

/// Every connection and message of a bag, as (connection id, topic, type, md5sum) and
/// (connection id, time, bytes), read by our record reader.
type Contents = (Vec<(u32, String, String, String)>, Vec<(u32, u64, Vec<u8>)>);

fn ours(bytes: &[u8]) -> Contents {
    let mut section = ChunkSection::open(bytes, bytes.len() as u64, BagLimits::for_messages(1 << 20)).unwrap();
    let (mut connections, mut messages) = (Vec::new(), Vec::new());
    while let Some(chunk) = section.next_chunk().unwrap() {
        for record in chunk.records() {
            match record.unwrap() {
                ChunkRecord::Connection { id, topic, msg_type, md5sum } => {
                    connections.push((id, topic, msg_type, md5sum))
                }
                ChunkRecord::Message { conn, time_nanos, data } => messages.push((conn, time_nanos, data.to_vec())),
            }
        }
    }
    (connections, messages)
}

fn the_rosbag_crates(path: &std::path::Path) -> Contents {
    let bag = rosbag::RosBag::new(path).unwrap();
    let (mut connections, mut messages) = (Vec::new(), Vec::new());
    for record in bag.chunk_records() {
        let rosbag::ChunkRecord::Chunk(chunk) = record.unwrap() else { continue };
        for message in chunk.messages() {
            match message.unwrap() {
                rosbag::MessageRecord::Connection(c) => {
                    let md5: String = c.md5sum.iter().map(|b| format!("{b:02x}")).collect();
                    connections.push((c.id, c.topic.to_string(), c.tp.to_string(), md5))
                }
                rosbag::MessageRecord::MessageData(m) => messages.push((m.conn_id, m.time, m.data.to_vec())),
            }
        }
    }
    (connections, messages)
}

/// Our record reader (`bag::records`) reads what the `rosbag` crate reads, record for record:
/// a bag of ours with several chunks, and the `rosbag` fuzz target's seeds, which include bz2
/// and lz4 chunks written by Debian's `rosbag compress` (kept in `tests/bags/`, as cmin renames the corpus).
#[test]
fn our_records_are_the_rosbag_crates() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("chunks.bag");
    let mut bag = BagWriter::create(&path).unwrap();
    for k in 1..=40 {
        let t = stamp_from_nanos(i64::from(k) * 100_000_000);
        let points: Vec<Point3<f32>> = (0..3_000).map(|i| Point3::new(i as f32, k as f32, 0.5)).collect();
        bag.write("/alpha/points", SCENARIO_EPOCH.time(t), &cloud_msg(header(t, "lidar"), &points, None, |_| [0; 3]))
            .unwrap();
        let pose = Pose3::translation(t, 0.0, 0.0);
        bag.write("/alpha/odometry", SCENARIO_EPOCH.time(t), &odometry_msg(header(t, "odom"), "base", &pose)).unwrap();
    }
    bag.finish().unwrap();
    let seeds = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/bags");
    let mut bags = vec![path];
    bags.extend(["three_frames.bag", "three_frames_bz2.bag", "labels_in_cloud_lz4.bag"].map(|name| seeds.join(name)));
    for path in bags {
        let expected = the_rosbag_crates(&path);
        assert!(expected.1.len() >= 6, "{}", path.display());
        assert_eq!(ours(&std::fs::read(&path).unwrap()), expected, "{}", path.display());
    }
}
