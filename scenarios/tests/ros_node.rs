//! `sgm ros` under an embedded ROS master (`ros-core-rs`: no ROS installation needed). Two robot
//! processes, each in its own namespace, are fed quickstart's sensor streams (its own bags,
//! published by this test's rosrust node at 3× real time) and must:
//! - accept every message and assemble every frame;
//! - align with each other through the master (object data on the team topic, requests over
//!   the Deliver services);
//! - publish what RViz needs: markers (a box and a label per object, in the class colours; the
//!   keyframe trajectory), the keyframe path, tf of the neighbour's world, the semantic map on
//!   demand, and a JSON status;
//! - refuse malformed messages (wrong field types, truncated data, unknown encodings, wrong
//!   frame, a zero quaternion) and a Deliver request that declares 4 GB, log and count each,
//!   and keep running;
//! - exit cleanly on SIGINT.
//!
//! The robots share a team key of their own, as in the field: 32 bytes from /dev/urandom as 64
//! hex digits in a file of mode 600, named by `SGM__COMMS__TEAM_KEY_FILE`.
//!
//! rosrust allows one node per process, so this file holds one test.

mod ros_common;

use ros_common::nodes::{bag_messages, play, team_key_file, Feed, Latest, Nodes, Statuses};
use ros_common::{embedded_master, poll};
use rosrust::RosMsg;
use serde_json::Value;
use sgm_bridge::convert::cloud::read_cloud;
use sgm_bridge::msg::{nav_msgs, sensor_msgs, sgm_msgs, std_msgs, tf2_msgs, visualization_msgs};
use sgm_model::perception::classes::ClassTable;
use sgm_scenarios::runner::run_recording;
use sgm_scenarios::scenario::Scenario;
use std::collections::BTreeMap;
use std::time::Duration;

const ROBOTS: [&str; 2] = ["alpha", "bravo"];
/// Bag time runs this many times faster than the wall clock.
const RATE: f64 = 3.0;

/// `sgm_msgs/Deliver` as a hostile caller sends it: [`LyingRequest`] for a request.
#[derive(Clone, Debug, Default, PartialEq)]
struct LyingDeliver;

/// A Deliver request whose `data` declares 0xFFFF_FFF0 bytes and holds 16.
#[derive(Clone, Debug, Default, PartialEq)]
struct LyingRequest;

impl rosrust::Message for LyingDeliver {
    fn msg_definition() -> String {
        String::new()
    }

    fn md5sum() -> String {
        <sgm_msgs::Deliver as rosrust::Message>::md5sum()
    }

    fn msg_type() -> String {
        "sgm_msgs/Deliver".into()
    }
}

impl RosMsg for LyingDeliver {
    fn encode<W: std::io::Write>(&self, _: W) -> std::io::Result<()> {
        Ok(())
    }

    fn decode<R: std::io::Read>(_: R) -> std::io::Result<Self> {
        Ok(Self)
    }
}

impl rosrust::ServicePair for LyingDeliver {
    type Request = LyingRequest;
    type Response = sgm_msgs::DeliverRes;
}

impl RosMsg for LyingRequest {
    fn encode<W: std::io::Write>(&self, mut w: W) -> std::io::Result<()> {
        w.write_all(&9u16.to_le_bytes())?;
        w.write_all(&0xFFFF_FFF0u32.to_le_bytes())?;
        w.write_all(&[0; 16])
    }

    fn decode<R: std::io::Read>(_: R) -> std::io::Result<Self> {
        Ok(Self)
    }
}

fn header(frame: &str) -> std_msgs::Header {
    std_msgs::Header { seq: 0, stamp: rosrust::Time::from_nanos(1_700_000_500_000_000_000), frame_id: frame.into() }
}

fn field(name: &str, offset: u32, datatype: u8) -> sensor_msgs::PointField {
    sensor_msgs::PointField { name: name.into(), offset, datatype, count: 1 }
}

/// A one-point cloud with x, y, z of the 4-byte `datatype` (5 int32, 7 float32).
fn cloud(frame: &str, datatype: u8, data_len: usize) -> sensor_msgs::PointCloud2 {
    let size = 4;
    sensor_msgs::PointCloud2 {
        header: header(frame),
        height: 1,
        width: 1,
        fields: vec![field("x", 0, datatype), field("y", size, datatype), field("z", 2 * size, datatype)],
        is_bigendian: false,
        point_step: 3 * size,
        row_step: 3 * size,
        data: vec![0; data_len],
        is_dense: true,
    }
}

fn image(encoding: &str) -> sensor_msgs::Image {
    sensor_msgs::Image {
        header: header("alpha/camera"),
        height: 1,
        width: 2,
        encoding: encoding.into(),
        is_bigendian: 0,
        step: 6,
        data: vec![1, 2, 3, 4, 5, 6],
    }
}

fn count(status: &Value, group: &str, topic: &str) -> u64 {
    status[group][topic].as_u64().unwrap_or_else(|| panic!("status has no {group}.{topic}: {status}"))
}

#[test]
fn two_nodes_align_through_an_embedded_master_and_refuse_bad_input() {
    let dir = tempfile::tempdir().unwrap();
    let scenario = Scenario::load("quickstart").unwrap();
    let bags_dir = dir.path().join("bags");
    actix_rt::System::new().block_on(run_recording(&scenario, None, Some(&bags_dir))).unwrap();
    let messages = bag_messages(&ROBOTS.map(|r| bags_dir.join(format!("{r}.bag"))));

    let master = embedded_master();
    // One process, one rosrust node: set before rosrust reads them (no other thread reads env).
    std::env::set_var("ROS_MASTER_URI", format!("http://{master}"));
    std::env::set_var("ROS_IP", "127.0.0.1");
    rosrust::try_init("sgm_node_test").expect("rosrust node");
    team_key_file(dir.path());
    let mut nodes = Nodes::start(master, dir.path(), &ROBOTS, 1, &[]);

    let mut feeds: BTreeMap<String, Feed> = BTreeMap::new();
    for (_, topic, _) in &messages {
        if !feeds.contains_key(topic) {
            if let Some(feed) = Feed::advertise(topic) {
                feeds.insert(topic.clone(), feed);
            }
        }
    }
    assert_eq!(feeds.len(), 9, "four sensor topics per robot and /tf_static: {:?}", feeds.keys().collect::<Vec<_>>());
    let statuses = Statuses::subscribe(&ROBOTS);
    let subscribed = || feeds.values().all(|f| f.subscribers() > 0) && ROBOTS.iter().all(|r| statuses.of(r).is_some());
    poll(60, || format!("the nodes did not subscribe (logs: {})", nodes.log("alpha")), || subscribed().then_some(()));

    // Play the bags at RATE until both robots are aligned, stopping after a frame's cloud.
    let mut published: BTreeMap<&str, u64> = BTreeMap::new();
    play(&messages, &feeds, RATE, |topic| {
        if !topic.ends_with("/points") {
            return false;
        }
        let robot = ROBOTS.iter().find(|r| topic.starts_with(&format!("/{r}/"))).unwrap();
        *published.entry(robot).or_default() += 1;
        ROBOTS.iter().all(|r| statuses.of(r).is_some_and(|s| Statuses::aligned(&s)))
    });
    for robot in ROBOTS {
        let sent = published[robot];
        let s = statuses.wait_for(robot, 60, "every frame", |s| count(s, "sync", "frames") == sent);
        assert_eq!(count(&s, "accepted", "points"), sent, "{robot}: {s}");
        assert!(s["refused"].as_object().unwrap().values().all(|v| v == 0), "{robot}: {s}");
        assert!(Statuses::aligned(&s), "{robot} did not align after {sent} frames: {s}");
        assert!(count(&s, "transport", "sent") > 0 && count(&s, "transport", "received") > 0, "{robot}: {s}");
        assert!(s["comms"]["sent"]["by_kind"]["ObjectData"]["count"].as_u64() > Some(0), "{robot}: {s}");
        // The simulator's label ids are fusion.classes ids (segmenter identity): none unknown.
        assert_eq!(s["fusion"]["segmenter"], "identity", "{robot}: {s}");
        assert_eq!(count(&s, "fusion", "unknown_label_points"), 0, "{robot}: {s}");
        // The camera's mount came from /tf_static (the bag's, as robot_state_publisher gives it).
        assert_eq!(s["tf"]["mounts"][1]["source"], "tf", "{robot}: {s}");
        assert_eq!(s["health"].as_array().map(Vec::len), Some(0), "{robot}: {s}");
        assert!(nodes.log(robot).contains("sgm node up"), "{robot}'s log");
        eprintln!("{robot}: {sent}/{sent} frames, aligned with {}", s["neighbours"]);
    }

    // What RViz shows of alpha, consistent with its status.
    let classes = ClassTable::new(scenario.fusion.classes.clone()).unwrap();
    let markers = Latest::<visualization_msgs::MarkerArray>::subscribe("/alpha/sgm/markers");
    let path = Latest::<nav_msgs::Path>::subscribe("/alpha/sgm/path");
    let tf = Latest::<tf2_msgs::TFMessage>::subscribe("/tf");
    let map = Latest::<sensor_msgs::PointCloud2>::subscribe("/alpha/sgm/map");
    let status = statuses.of("alpha").unwrap();
    let objects = status["objects"].as_u64().unwrap() as usize;
    let keyframes = status["keyframes"].as_u64().unwrap() as usize;
    let m =
        markers.wait_for(20, "alpha's markers", |m| m.markers.iter().filter(|m| m.ns == "objects").count() == objects);
    assert_eq!(m.markers[0].action, 3, "DELETEALL first");
    let boxes: Vec<_> = m.markers.iter().filter(|m| m.ns == "objects").collect();
    let labels: BTreeMap<i32, &str> =
        m.markers.iter().filter(|m| m.ns == "labels").map(|m| (m.id, m.text.as_str())).collect();
    assert_eq!(labels.len(), objects);
    for b in &boxes {
        assert_eq!((b.type_, b.header.frame_id.as_str()), (1, "alpha/odom"));
        let name = labels[&b.id].split(' ').next().unwrap();
        let class = classes.by_name(name).unwrap_or_else(|| panic!("label {:?} names no class", labels[&b.id]));
        let rgb = [b.color.r, b.color.g, b.color.b].map(|c| (c * 255.0).round() as u8);
        assert_eq!(rgb, class.colour, "object {} ({name}) in its class colour", b.id);
    }
    let trajectory = m.markers.iter().find(|m| m.ns == "keyframes").expect("the keyframe trajectory");
    assert_eq!(trajectory.points.len(), keyframes);
    let p = path.wait_for(20, "alpha's path", |p| p.poses.len() == keyframes);
    assert_eq!(p.header.frame_id, "alpha/odom");
    assert!(p.poses.windows(2).all(|w| w[0].header.stamp < w[1].header.stamp), "path stamps increase");
    // The team's tf tree: bravo (id 2) places its world under alpha's (id 1), the frame alpha
    // registered on the master; the transform is the inverse of bravo's local_from_remote.
    let t = tf.wait_for(20, "bravo's place in alpha's world", |t| {
        t.transforms.iter().any(|t| t.header.frame_id == "alpha/odom" && t.child_frame_id == "bravo/odom")
    });
    let t = t.transforms.iter().find(|t| t.child_frame_id == "bravo/odom").unwrap();
    let bravo = statuses.of("bravo").unwrap();
    let v: Vec<f64> = serde_json::from_value(bravo["neighbours"][0]["local_from_remote"].clone()).unwrap();
    let bravo_from_alpha = nalgebra::Isometry3::from_parts(
        nalgebra::Translation3::new(v[0], v[1], v[2]),
        nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(v[6], v[3], v[4], v[5])),
    );
    let alpha_from_bravo = bravo_from_alpha.inverse();
    let (tr, q) = (&t.transform.translation, &t.transform.rotation);
    let expected = alpha_from_bravo.translation.vector;
    assert!((nalgebra::Vector3::new(tr.x, tr.y, tr.z) - expected).norm() < 1e-6, "tf {tr:?} ≠ {expected}");
    let got = nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q.w, q.x, q.y, q.z));
    assert!(got.angle_to(&alpha_from_bravo.rotation) < 1e-6);
    assert!(
        tf.get().is_none_or(|m| m.transforms.iter().all(|t| t.child_frame_id != "alpha/odom")),
        "alpha, the lowest id, is the tree's root"
    );
    let semantic = map.wait_for(20, "alpha's semantic map", |c| c.width > 0);
    assert_eq!(semantic.header.frame_id, "alpha/odom");
    let scan = read_cloud(&semantic, "label").expect("the map reads back");
    assert_eq!(scan.points.len(), semantic.width as usize * semantic.height as usize);
    assert!(scan.labels.is_some(), "the map carries labels");

    // Malformed input to alpha: each refused, logged and counted; alpha keeps running.
    let bad_points = rosrust::publish::<sensor_msgs::PointCloud2>("/alpha/points", 10).unwrap();
    let bad_labels = rosrust::publish::<sensor_msgs::Image>("/alpha/labels", 10).unwrap();
    let bad_odometry = rosrust::publish::<nav_msgs::Odometry>("/alpha/odometry", 10).unwrap();
    let lidar = "alpha/base_link";
    let mut zero_quaternion = nav_msgs::Odometry { header: header("alpha/odom"), ..Default::default() };
    zero_quaternion.child_frame_id = "alpha/base_link".into();
    let connected = || {
        [bad_points.subscriber_count(), bad_labels.subscriber_count(), bad_odometry.subscriber_count()]
            .iter()
            .all(|&n| n > 0)
    };
    poll(20, || "alpha did not connect to the test's second publishers".into(), || connected().then_some(()));
    let before = statuses.of("alpha").unwrap();
    bad_points.send(cloud(lidar, 5, 12)).unwrap(); // int32 coordinates
    bad_points.send(cloud(lidar, 7, 5)).unwrap(); // 5 bytes of a 12-byte point
    bad_points.send(cloud("elsewhere", 7, 12)).unwrap(); // wrong frame
    bad_labels.send(image("yuv422")).unwrap();
    bad_labels.send(image("bayer_rggb8")).unwrap();
    bad_odometry.send(zero_quaternion).unwrap();
    let expected = [("points", 3), ("labels", 2), ("odometry", 1), ("camera_info", 0)];
    let after = statuses.wait_for("alpha", 20, "refusals", |s| {
        expected.iter().all(|(topic, n)| count(s, "refused", topic) == count(&before, "refused", topic) + n)
    });
    assert_eq!(count(&after, "accepted", "points"), count(&before, "accepted", "points"));
    assert!(nodes.running("alpha"), "alpha died on malformed input");
    let log = nodes.log("alpha");
    for reason in ["datatype 5", "data is 5 bytes", "frame `elsewhere`", "encoding `yuv422`", "encoding `bayer_rggb8`"]
    {
        assert!(log.contains(reason), "alpha's log names {reason:?}:\n{log}");
    }
    assert_eq!(log.matches("message refused").count(), 6, "{log}");

    // A Deliver request whose `data` declares 4 GB, of which 16 bytes come: refused before
    // anything is reserved (rosrust's own decoder reserves the 4 GB and waits for the rest, so
    // the caller would get no answer at all), logged and counted; alpha keeps running.
    let service = format!("/sgm/robot_{}/deliver", after["id"]);
    let client = rosrust::client::<LyingDeliver>(&service).expect("alpha's Deliver service");
    let (answered, answer) = std::sync::mpsc::channel();
    std::thread::spawn(move || answered.send(client.req(&LyingRequest).map_err(|e| e.to_string())));
    // The refusal reaches the caller as rosrust's failure reply or, with the unread bytes still
    // in the socket, as a connection reset.
    let reply = answer.recv_timeout(Duration::from_secs(20)).expect("alpha answers a lying Deliver request");
    assert!(!matches!(reply, Ok(Ok(_))), "alpha took a request declaring 4 GB: {reply:?}");
    statuses.wait_for("alpha", 20, "the refused request counted", |s| s["transport"]["refused"] == 1);
    assert!(nodes.running("alpha"), "alpha died on a lying Deliver request");
    let log = nodes.log("alpha");
    assert!(log.contains("Deliver request refused: field `data` declares 4294967280 bytes"), "{log}");

    // Shut down (each writes its snapshot on SIGINT) and start alpha again: it resumes with
    // its map and its alignment, before any new sensor input.
    let before = statuses.of("alpha").unwrap();
    nodes.interrupt();
    let snapshot = dir.path().join("snapshots/alpha.snapshot");
    assert!(snapshot.is_file(), "no snapshot at {}", snapshot.display());
    drop(statuses);
    let mut again = Nodes::start(master, dir.path(), &["alpha"], 2, &[]);
    let statuses = Statuses::subscribe(&ROBOTS); // only what the new alpha publishes
    let resumed = statuses.wait_for("alpha", 60, "the resumed status", |_| true);
    assert!(again.running("alpha"));
    assert!(again.log("alpha").contains("resuming"), "{}", again.log("alpha"));
    for key in ["keyframes", "objects"] {
        assert_eq!(resumed[key], before[key], "{key}: {resumed} after {before}");
    }
    assert!(Statuses::aligned(&resumed), "alpha forgot its alignment: {resumed}");
    again.interrupt();
}
