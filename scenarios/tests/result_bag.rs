//! `result.bag` (`sgm run`, `sgm replay`): the team's result in the live node's messages. Read
//! back with the `rosbag` crate (an independent reader): markers, paths and tf at every
//! observation; the objects in their class colours; bravo's world placed under alpha's by the
//! team's tree, as the report's alignment says; each robot's map and the team map at the end.

use rosrust::RosMsg;
use sgm_bridge::msg::{sensor_msgs, tf2_msgs, visualization_msgs};
use sgm_scenarios::report;
use sgm_scenarios::runner::{run_with, RunOutputs};
use sgm_scenarios::scenario::Scenario;
use std::collections::BTreeMap;

#[test]
fn the_result_bag_holds_what_rviz_shows() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("result.bag");
    let scenario = Scenario::load("quickstart").unwrap();
    let outputs = RunOutputs { result_bag: Some(&path), ..RunOutputs::default() };
    let outcome = actix_rt::System::new().block_on(run_with(&scenario, None, outputs)).unwrap();
    let computed = report::compute(&outcome.record);
    assert!(computed.alignments.iter().all(|a| a.first_aligned_s.is_some()));

    let bag = rosbag::RosBag::new(&path).unwrap();
    let mut topics = BTreeMap::new();
    let mut messages: BTreeMap<String, Vec<Vec<u8>>> = BTreeMap::new();
    for record in bag.chunk_records() {
        let rosbag::ChunkRecord::Chunk(chunk) = record.unwrap() else { continue };
        for message in chunk.messages() {
            match message.unwrap() {
                rosbag::MessageRecord::Connection(c) => {
                    topics.insert(c.id, (c.topic.to_string(), c.tp.to_string()));
                }
                rosbag::MessageRecord::MessageData(m) => {
                    messages.entry(topics[&m.conn_id].0.clone()).or_default().push(m.data.to_vec());
                }
            }
        }
    }
    let observations = outcome.record.series.len();
    for topic in ["/alpha/sgm/markers", "/bravo/sgm/markers", "/alpha/sgm/path", "/bravo/sgm/path", "/tf"] {
        assert_eq!(messages[topic].len(), observations, "{topic}");
    }
    for topic in ["/alpha/sgm/map", "/bravo/sgm/map", "/sgm/team_map"] {
        let cloud = sensor_msgs::PointCloud2::decode(&messages[topic][0][..]).unwrap();
        assert!(cloud.width > 1000, "{topic}: {} points", cloud.width);
    }

    // The last markers: a box per object of alpha's map, in its class colour.
    let last = visualization_msgs::MarkerArray::decode(&messages["/alpha/sgm/markers"].last().unwrap()[..]).unwrap();
    let (map, neighbours, _) = outcome.record.last.maps[0].clone().unwrap();
    let boxes: Vec<_> = last.markers.iter().filter(|m| m.ns == "objects").collect();
    assert_eq!(boxes.len(), map.objects.len());
    let colours: BTreeMap<u16, [u8; 3]> = scenario.fusion.classes.iter().map(|c| (c.id, c.colour)).collect();
    for (b, object) in boxes.iter().zip(&map.objects) {
        assert_eq!(b.header.frame_id, "alpha/odom");
        let rgb = [b.color.r, b.color.g, b.color.b].map(|c| (c * 255.0).round() as u8);
        assert_eq!(rgb, colours[&object.label.0]);
    }

    // The last tf: alpha's and bravo's bodies, and bravo's world under alpha's = the inverse of
    // bravo's estimate of alpha (local_from_remote), alpha being the root.
    let tf = tf2_msgs::TFMessage::decode(&messages["/tf"].last().unwrap()[..]).unwrap();
    let pairs: Vec<(&str, &str)> =
        tf.transforms.iter().map(|t| (t.header.frame_id.as_str(), t.child_frame_id.as_str())).collect();
    assert_eq!(
        pairs,
        [("alpha/odom", "alpha/base_link"), ("bravo/odom", "bravo/base_link"), ("alpha/odom", "bravo/odom")]
    );
    let (_, bravo_neighbours, _) = outcome.record.last.maps[1].clone().unwrap();
    let bravo_from_alpha = bravo_neighbours[0].local_from_remote.unwrap();
    let t = &tf.transforms[2].transform.translation;
    let expected = bravo_from_alpha.inverse().translation.vector;
    assert!((nalgebra::Vector3::new(t.x, t.y, t.z) - expected).norm() < 1e-9);
    assert!(neighbours.iter().all(|n| n.local_from_remote.is_some()));
}
