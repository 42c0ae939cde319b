//! ROS 2 recordings that are wrong in the ways recordings are: each is refused with an error
//! naming the file and the topic, a bad message alone is refused and the reading goes on, and
//! nothing panics. Recordings are written here with the `mcap` crate's writer and SQLite; the
//! messages are the rosbags-serialised fixtures of `fixtures/cdr/`. (Recordings written by
//! rosbags itself are replayed end to end by `tests/ros2_bags.sh`.)

use sgm_bridge::bag::reader::{read_bag, BagError, BagItem, BagSource, Payload};
use sgm_bridge::bag::rosbag2::decode_recording;
use sgm_bridge::config::RosConfig;
use std::collections::BTreeMap;
use std::path::Path;

fn fixture(name: &str) -> Vec<u8> {
    std::fs::read(format!("{}/tests/fixtures/cdr/{name}", env!("CARGO_MANIFEST_DIR"))).unwrap()
}

fn items(path: &Path) -> Vec<BagItem> {
    let mut items = Vec::new();
    decode_recording(path, &BagSource::new(&RosConfig::default(), "alpha", 1), |item| {
        items.push(item);
        true
    });
    items
}

/// An MCAP file of one topic of type `msg_type`, carrying `messages` (log time, bytes).
fn write_mcap(path: &Path, topic: &str, msg_type: &str, messages: &[(u64, Vec<u8>)]) {
    let mut w = mcap::Writer::new(std::io::BufWriter::new(std::fs::File::create(path).unwrap())).unwrap();
    let schema = w.add_schema(msg_type, "ros2msg", b"").unwrap();
    let channel = w.add_channel(schema, topic, "cdr", &BTreeMap::new()).unwrap();
    for (k, (t, data)) in messages.iter().enumerate() {
        let header =
            mcap::records::MessageHeader { channel_id: channel, sequence: k as u32, log_time: *t, publish_time: *t };
        w.write_to_known_channel(&header, data).unwrap();
    }
    w.finish().unwrap();
}

/// A rosbag2 sqlite3 database of one topic.
fn write_db3(path: &Path, topic: &str, msg_type: &str, messages: &[(i64, Vec<u8>)]) {
    let db = rusqlite::Connection::open(path).unwrap();
    db.execute_batch(
        "CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT NOT NULL, type TEXT NOT NULL,
           serialization_format TEXT NOT NULL, offered_qos_profiles TEXT NOT NULL);
         CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER NOT NULL, timestamp INTEGER NOT NULL,
           data BLOB NOT NULL);",
    )
    .unwrap();
    db.execute("INSERT INTO topics VALUES (1, ?1, ?2, 'cdr', '')", (topic, msg_type)).unwrap();
    for (t, data) in messages {
        db.execute("INSERT INTO messages (topic_id, timestamp, data) VALUES (1, ?1, ?2)", (t, data)).unwrap();
    }
}

fn metadata(storage: &str, file: &str, topic: &str, msg_type: &str, count: u64) -> String {
    format!(
        "rosbag2_bagfile_information:\n  version: 9\n  storage_identifier: {storage}\n  relative_file_paths:\n  - {file}\n  \
         compression_format: ''\n  compression_mode: ''\n  topics_with_message_count:\n  - message_count: {count}\n    \
         topic_metadata:\n      name: {topic}\n      type: {msg_type}\n      serialization_format: cdr\n"
    )
}

fn failure(items: &[BagItem]) -> String {
    match items.last() {
        Some(BagItem::Failed(e)) => e.to_string(),
        other => panic!("no failure at the end: {other:?}"),
    }
}

#[test]
fn both_storages_give_the_same_odometry() {
    let dir = tempfile::tempdir().unwrap();
    let odometry = fixture("Odometry.le.cdr");
    let big_endian = fixture("Odometry.be.cdr");
    write_mcap(
        &dir.path().join("a.mcap"),
        "/alpha/odometry",
        "nav_msgs/msg/Odometry",
        &[(1, odometry.clone()), (2, big_endian.clone())],
    );
    write_db3(&dir.path().join("a.db3"), "/alpha/odometry", "nav_msgs/msg/Odometry", &[(2, big_endian), (1, odometry)]);
    for file in ["a.mcap", "a.db3"] {
        let items = items(&dir.path().join(file));
        let poses: Vec<_> = items
            .iter()
            .map(|i| match i {
                BagItem::Message { time_nanos, payload: Payload::Odometry(stamp, pose) } => {
                    (*time_nanos, stamp.sec, pose.translation.vector.x)
                }
                other => panic!("{file}: {other:?}"),
            })
            .collect();
        assert_eq!(poses, [(1, 11, 1.0), (2, 11, 1.0)], "{file}");
    }
}

#[test]
fn a_topic_of_another_type_is_refused_naming_file_and_topic() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("wrong.mcap");
    write_mcap(&path, "/alpha/odometry", "geometry_msgs/msg/PoseStamped", &[(1, fixture("Odometry.le.cdr"))]);
    let e = failure(&items(&path));
    assert!(e.contains("wrong.mcap: topic /alpha/odometry carries geometry_msgs/msg/PoseStamped in `cdr`"), "{e}");
    assert!(e.ends_with("nav_msgs/msg/Odometry in `cdr` expected"), "{e}");
    // A topic the replay does not read may be of any type.
    let other = dir.path().join("other.mcap");
    write_mcap(&other, "/alpha/diagnostics", "diagnostic_msgs/msg/DiagnosticArray", &[(1, vec![0, 1, 0, 0])]);
    assert!(items(&other).is_empty());
}

#[test]
fn a_bad_message_is_refused_alone_and_the_reading_goes_on() {
    let dir = tempfile::tempdir().unwrap();
    let good = fixture("Odometry.le.cdr");
    // The child frame's length declares 4 GB.
    let mut long = good.clone();
    let at = 4 + 8 + 4 + "alpha/odom\0".len();
    let at = at.next_multiple_of(4);
    long[at..at + 4].copy_from_slice(&0xFFFF_FFF0u32.to_le_bytes());
    // An encapsulation that is not plain CDR (parameter lists, 0x0003).
    let mut pl_cdr = good.clone();
    pl_cdr[1] = 3;
    // Little-endian bytes under a big-endian flag: the frame id's length reads as 184 549 376.
    let mut wrong_order = good.clone();
    wrong_order[1] = 0;
    let path = dir.path().join("bad.mcap");
    write_mcap(
        &path,
        "/alpha/odometry",
        "nav_msgs/msg/Odometry",
        &[(1, long), (2, pl_cdr), (3, wrong_order), (4, good)],
    );
    let items = items(&path);
    let errors: Vec<String> = items[..3]
        .iter()
        .map(|i| match i {
            BagItem::Refused { topic, input: "odometry", error } => format!("{topic}: {error}"),
            other => panic!("{other:?}"),
        })
        .collect();
    assert!(
        errors[0]
            .starts_with("/alpha/odometry: does not decode from CDR: field `child_frame_id` needs 4294967280 bytes"),
        "{}",
        errors[0]
    );
    assert!(errors[1].contains("encapsulation kind 0x0003 is not plain CDR"), "{}", errors[1]);
    assert!(errors[2].contains("field `header.frame_id` needs 184549376 bytes"), "{}", errors[2]);
    assert!(matches!(items[3], BagItem::Message { time_nanos: 4, .. }));
    assert_eq!(items.len(), 4);
}

#[test]
fn metadata_that_disagrees_with_the_database_is_refused_naming_the_topic() {
    let dir = tempfile::tempdir().unwrap();
    let rec = dir.path().join("rec");
    std::fs::create_dir(&rec).unwrap();
    write_db3(&rec.join("rec_0.db3"), "/alpha/odometry", "nav_msgs/msg/Odometry", &[(1, fixture("Odometry.le.cdr"))]);
    let yaml = rec.join("metadata.yaml");
    std::fs::write(&yaml, metadata("sqlite3", "rec_0.db3", "/alpha/odometry", "nav_msgs/msg/Odometry", 1)).unwrap();
    assert!(matches!(items(&rec)[..], [BagItem::Message { .. }]));

    std::fs::write(&yaml, metadata("sqlite3", "rec_0.db3", "/alpha/odometry", "sensor_msgs/msg/Imu", 1)).unwrap();
    let e = failure(&items(&rec));
    assert!(e.contains("metadata.yaml disagrees with the storage on topic /alpha/odometry"), "{e}");
    assert!(e.contains("says sensor_msgs/msg/Imu in `cdr`, the database nav_msgs/msg/Odometry"), "{e}");

    std::fs::write(&yaml, metadata("sqlite3", "rec_0.db3", "/alpha/odometry", "nav_msgs/msg/Odometry", 2)).unwrap();
    let e = failure(&items(&rec));
    assert!(e.ends_with("on topic /alpha/odometry: metadata.yaml declares 2 messages, the storage holds 1"), "{e}");

    std::fs::write(&yaml, metadata("sqlite3", "rec_1.db3", "/alpha/odometry", "nav_msgs/msg/Odometry", 1)).unwrap();
    let e = failure(&items(&rec));
    assert!(e.contains("metadata.yaml lists") && e.contains("rec_1.db3, which is not there"), "{e}");

    std::fs::write(&yaml, metadata("mcap", "rec_0.db3", "/alpha/odometry", "nav_msgs/msg/Odometry", 1)).unwrap();
    let e = failure(&items(&rec));
    assert!(e.contains("rec_0.db3: not a readable MCAP file"), "{e}");
}

#[test]
fn damaged_storage_files_are_refused_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let db3 = dir.path().join("a.db3");
    write_db3(&db3, "/alpha/odometry", "nav_msgs/msg/Odometry", &[(1, fixture("Odometry.le.cdr"))]);
    let bytes = std::fs::read(&db3).unwrap();
    // A database whose pages after the header are overwritten.
    let mut garbled = bytes.clone();
    for b in &mut garbled[100..] {
        *b = 0xA5;
    }
    let path = dir.path().join("garbled.db3");
    std::fs::write(&path, garbled).unwrap();
    let e = failure(&items(&path));
    assert!(e.starts_with(&format!("{}: not a readable rosbag2 database", path.display())), "{e}");
    // A timestamp before 1970.
    let early = dir.path().join("early.db3");
    write_db3(&early, "/alpha/odometry", "nav_msgs/msg/Odometry", &[(-5, fixture("Odometry.le.cdr"))]);
    assert!(failure(&items(&early)).ends_with("message 1: timestamp -5 ns is before 1970"));

    let mcap = dir.path().join("a.mcap");
    write_mcap(&mcap, "/alpha/odometry", "nav_msgs/msg/Odometry", &[(1, fixture("Odometry.le.cdr"))]);
    let whole = std::fs::read(&mcap).unwrap();
    for cut in [0, 8, 20, whole.len() / 2, whole.len() - 1] {
        let path = dir.path().join(format!("cut{cut}.mcap"));
        std::fs::write(&path, &whole[..cut]).unwrap();
        let mut received = Vec::new();
        for item in read_bag(&path, BagSource::new(&RosConfig::default(), "alpha", 1)) {
            received.push(item);
        }
        let Some(BagItem::Failed(BagError::Read { path: named, .. })) = received.last() else {
            panic!("cut at {cut}: {received:?}")
        };
        assert_eq!(named, &path.display().to_string());
    }
}
