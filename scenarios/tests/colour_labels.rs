//! Label images painted in a palette (rgb8), as many segmenters publish them, replay to the run
//! of the same images as class ids. Quickstart's bags are rewritten with every label image
//! painted (each pixel value in its colour, the background black) and replayed with the
//! palette's background entry: the report is that of the id images, and no pixel is unknown.
//! The same with ADE20K ids painted in mmsegmentation's ADE20K palette. A colour the palette
//! lacks is counted by colour and keeps its pixels out of every class.

use rosrust::RosMsg;
use sgm_bridge::bag::writer::BagWriter;
use sgm_bridge::convert::image::read_label_image;
use sgm_bridge::msg::sensor_msgs;
use sgm_model::perception::label_map::SegmenterClass;
use sgm_model::perception::segmenters::NO_LABEL;
use sgm_scenarios::replay::{replay, ReplayOutcome};
use sgm_scenarios::report;
use sgm_scenarios::runner::run_recording;
use sgm_scenarios::scenario::Scenario;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

const BACKGROUND: [u8; 3] = [0, 0, 0];

fn quickstart(segmenter: &str) -> Scenario {
    let mut scenario = Scenario::load_with_env("quickstart", "SGM_COLOUR_LABELS_TEST").unwrap();
    scenario.scenario.duration_s = 40.0;
    scenario.classes.segmenter = segmenter.into();
    scenario
}

/// Every message of `from` into `to`, label images painted by `paint` (pixel value → colour).
fn paint_bag(from: &Path, to: &Path, paint: &dyn Fn(u16) -> [u8; 3]) {
    let bag = rosbag::RosBag::new(from).unwrap();
    let mut writer = BagWriter::create(to).unwrap();
    let mut connections: BTreeMap<u32, (String, String)> = BTreeMap::new();
    for record in bag.chunk_records() {
        let rosbag::ChunkRecord::Chunk(chunk) = record.unwrap() else { continue };
        for message in chunk.messages() {
            match message.unwrap() {
                rosbag::MessageRecord::Connection(c) => {
                    connections.insert(c.id, (c.topic.to_string(), c.tp.to_string()));
                }
                rosbag::MessageRecord::MessageData(m) => {
                    let (topic, kind) = &connections[&m.conn_id];
                    let time = rosrust::Time::from_nanos(m.time as i64);
                    macro_rules! copy {
                        ($t:ty) => {
                            writer.write(topic, time, &<$t>::decode(m.data).unwrap()).unwrap()
                        };
                    }
                    match kind.as_str() {
                        "sensor_msgs/Image" => {
                            let mono = sensor_msgs::Image::decode(m.data).unwrap();
                            let (ids, _) = read_label_image(&mono, None).unwrap();
                            let data = ids.labels.iter().flat_map(|&l| paint(l)).collect();
                            let painted = sensor_msgs::Image {
                                encoding: "rgb8".into(),
                                step: mono.width * 3,
                                is_bigendian: 0,
                                data,
                                ..mono
                            };
                            writer.write(topic, time, &painted).unwrap();
                        }
                        "sensor_msgs/PointCloud2" => copy!(sensor_msgs::PointCloud2),
                        "sensor_msgs/CameraInfo" => copy!(sensor_msgs::CameraInfo),
                        "nav_msgs/Odometry" => copy!(sgm_bridge::msg::nav_msgs::Odometry),
                        "tf2_msgs/TFMessage" => {
                            let tf = sgm_bridge::msg::tf2_msgs::TFMessage::decode(m.data).unwrap();
                            writer.write_latched(topic, time, &tf).unwrap()
                        }
                        other => panic!("unexpected type {other}"),
                    }
                }
            }
        }
    }
    writer.finish().unwrap();
}

fn replay_bags(scenario: &Scenario, bags: &[PathBuf]) -> ReplayOutcome {
    actix_rt::System::new().block_on(replay(scenario, bags, None)).unwrap()
}

fn report_json(outcome: &ReplayOutcome, dir: &Path) -> Vec<u8> {
    report::write(&outcome.run, dir).unwrap();
    std::fs::read(dir.join("report.json")).unwrap()
}

/// Records quickstart with `segmenter`'s ids, replays the id bags and the bags painted by
/// `paint`, and checks the reports are the same and no pixel was unknown.
fn painted_replays_as_ids(segmenter: &str, paint: &dyn Fn(u16) -> [u8; 3]) {
    let dir = tempfile::tempdir().unwrap();
    let mut scenario = quickstart(segmenter);
    actix_rt::System::new().block_on(run_recording(&scenario, None, Some(&dir.path().join("ids")))).unwrap();
    let names = ["alpha", "bravo"];
    let ids: Vec<PathBuf> = names.iter().map(|r| dir.path().join("ids").join(format!("{r}.bag"))).collect();
    let painted: Vec<PathBuf> = names.iter().map(|r| dir.path().join(format!("{r}.painted.bag"))).collect();
    for (from, to) in ids.iter().zip(&painted) {
        paint_bag(from, to, paint);
    }
    let as_ids = replay_bags(&scenario, &ids);
    scenario.classes.palette.insert("#000000".into(), SegmenterClass::Name("none".into()));
    let as_colours = replay_bags(&scenario, &painted);
    for b in &as_colours.bags {
        assert!(b.refused.is_empty(), "{b:?}");
        assert_eq!(b.sync.unknown_colour_pixels, 0, "{b:?}");
        assert!(b.sync.frames > 0);
    }
    let confirmed = |o: &ReplayOutcome| {
        report::compute(&o.run.record).robots.iter().map(|r| r.confirmed_objects).collect::<Vec<_>>()
    };
    assert!(confirmed(&as_ids).iter().all(|&n| n > 0), "{:?}", confirmed(&as_ids));
    let (a, b) = (dir.path().join("report_ids"), dir.path().join("report_colours"));
    assert!(report_json(&as_ids, &a) == report_json(&as_colours, &b), "report.json differs between ids and colours");

    // Without the background entry, black is a colour the palette lacks: counted, no class.
    scenario.classes.palette.clear();
    let unknown = replay_bags(&scenario, &painted);
    let b = &unknown.bags[0];
    assert!(b.sync.unknown_colour_pixels > 0, "{b:?}");
    assert_eq!(b.sync.unknown_colours.keys().collect::<Vec<_>>(), ["#000000"], "{b:?}");
    assert_eq!(confirmed(&unknown), confirmed(&as_ids), "background pixels carry no class either way");
}

#[test]
fn identity_ids_painted_in_the_class_colours() {
    let scenario = quickstart("identity");
    let colours: BTreeMap<u16, [u8; 3]> = scenario.fusion.classes.iter().map(|c| (c.id, c.colour)).collect();
    assert!(!colours.values().any(|c| *c == BACKGROUND));
    painted_replays_as_ids("identity", &|l| if l == NO_LABEL { BACKGROUND } else { colours[&l] });
}

#[test]
fn ade20k_ids_painted_in_the_ade20k_palette() {
    let palette = sgm_model::perception::palettes::ADE20K_150_PALETTE;
    assert!(!palette.contains(&BACKGROUND));
    painted_replays_as_ids("ade20k_150", &|l| palette.get(usize::from(l)).copied().unwrap_or(BACKGROUND));
}
