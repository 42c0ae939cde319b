//! Reads one robot's bag for the replay: the topics of the `[ros]` section (a bag topic matches
//! a configured name equal to it or ending it: `points` matches `/points` and `/alpha/points`),
//! each message decoded and checked by [`Inputs`]. A reader thread per bag decodes ahead into a
//! bounded channel, so bags decode in parallel and memory stays bounded. The bag's records are
//! read by [`super::records`], one chunk at a time and within bounds; [`decode_bag`] reads a bag
//! from any `Read` on the caller's thread (the `rosbag` fuzz target feeds it bytes).

use super::records::{BagLimits, ChunkRecord, ChunkSection, RecordError};
use crate::bounded::{check_within, Layout};
use crate::config::RosConfig;
use crate::error::InputError;
use crate::inputs::Inputs;
pub use crate::inputs::Payload;
use crate::msg::{nav_msgs, sensor_msgs, tf2_msgs};
use rosrust::{Message, RosMsg};
use sgm_model::perception::colour_ids::ColourIds;
use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufReader, Read};
use std::path::Path;
use std::sync::mpsc::{sync_channel, Receiver};

/// What the reader thread sends: messages in record-time order (nanoseconds since 1970), a
/// message refused (its topic and why), or the end.
#[derive(Debug)]
pub enum BagItem {
    Message {
        time_nanos: u64,
        payload: Payload,
    },
    /// `input` names the input as the status does (`points`, `odometry`, `tf_static`, …).
    Refused {
        topic: String,
        input: &'static str,
        error: InputError,
    },
    Failed(BagError),
}

#[derive(Debug, Clone, thiserror::Error)]
pub enum BagError {
    #[error("{path}: {message}")]
    Read { path: String, message: String },
    #[error("{path}: topic {topic} carries {found} (md5 {md5}), {expected} expected")]
    WrongType { path: String, topic: String, found: String, md5: String, expected: String },
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Kind {
    Cloud,
    Image,
    CameraInfo,
    Odometry,
    GroundTruth,
    Tf,
    TfStatic,
    Imu,
}

impl Kind {
    fn input_name(self) -> &'static str {
        match self {
            Kind::Cloud => "points",
            Kind::Image => "labels",
            Kind::CameraInfo => "camera_info",
            Kind::Odometry => "odometry",
            Kind::GroundTruth => "ground_truth",
            Kind::Tf => "tf",
            Kind::TfStatic => "tf_static",
            Kind::Imu => "imu",
        }
    }

    fn expected(self) -> (String, String) {
        match self {
            Kind::Cloud => (sensor_msgs::PointCloud2::msg_type(), sensor_msgs::PointCloud2::md5sum()),
            Kind::Image => (sensor_msgs::Image::msg_type(), sensor_msgs::Image::md5sum()),
            Kind::CameraInfo => (sensor_msgs::CameraInfo::msg_type(), sensor_msgs::CameraInfo::md5sum()),
            Kind::Odometry | Kind::GroundTruth => (nav_msgs::Odometry::msg_type(), nav_msgs::Odometry::md5sum()),
            Kind::Tf | Kind::TfStatic => (tf2_msgs::TFMessage::msg_type(), tf2_msgs::TFMessage::md5sum()),
            Kind::Imu => (sensor_msgs::Imu::msg_type(), sensor_msgs::Imu::md5sum()),
        }
    }
}

/// Whether bag topic `topic` is the configured `name`.
pub fn topic_matches(topic: &str, name: &str) -> bool {
    let (topic, name) = (topic.trim_start_matches('/'), name.trim_start_matches('/'));
    topic == name || topic.strip_suffix(name).is_some_and(|rest| rest.ends_with('/'))
}

/// Decodes a bag's message within the live node's bounds (`bounded`): its bytes walked against
/// M's layout and `ros.max_message_bytes` before rosrust reserves what a length prefix declares.
fn decode<M: RosMsg + Layout>(data: &[u8], max_bytes: usize) -> Result<M, InputError> {
    check_within::<M>(data, max_bytes).map_err(|e| InputError::invalid(format!("refused before decoding: {e}")))?;
    M::decode(data).map_err(|e| InputError::invalid(format!("does not decode: {e}")))
}

struct Decoder {
    path: String,
    topics: Vec<(String, Kind)>,
    inputs: Inputs,
    connections: BTreeMap<u32, Option<(String, Kind)>>,
    /// `ros.max_message_bytes`.
    max_bytes: usize,
}

impl Decoder {
    fn connection(&mut self, id: u32, topic: &str, msg_type: &str, md5: &str) -> Result<(), BagError> {
        let kind = self.topics.iter().find(|(name, _)| topic_matches(topic, name)).map(|(_, k)| *k);
        if let Some(kind) = kind {
            let (expected, expected_md5) = kind.expected();
            if msg_type != expected || md5 != expected_md5 {
                return Err(BagError::WrongType {
                    path: self.path.clone(),
                    topic: topic.into(),
                    found: msg_type.into(),
                    md5: md5.into(),
                    expected,
                });
            }
        }
        self.connections.insert(id, kind.map(|k| (topic.to_string(), k)));
        Ok(())
    }

    fn payload(&self, kind: Kind, data: &[u8]) -> Result<Payload, InputError> {
        match kind {
            Kind::Cloud => self.inputs.cloud(&decode(data, self.max_bytes)?),
            Kind::Image => self.inputs.image(&decode(data, self.max_bytes)?),
            Kind::CameraInfo => self.inputs.camera_info(&decode(data, self.max_bytes)?),
            Kind::Odometry => self.inputs.odometry(&decode(data, self.max_bytes)?),
            Kind::GroundTruth => self.inputs.ground_truth(&decode(data, self.max_bytes)?),
            Kind::Tf => self.inputs.tf(&decode(data, self.max_bytes)?, false),
            Kind::TfStatic => self.inputs.tf(&decode(data, self.max_bytes)?, true),
            Kind::Imu => self.inputs.imu(&decode(data, self.max_bytes)?),
        }
    }

    /// Decodes the bag in `section` into `out`; returns early once `out` returns false.
    fn run<R: Read>(
        mut self,
        mut section: ChunkSection<R>,
        out: &mut impl FnMut(BagItem) -> bool,
    ) -> Result<(), BagError> {
        let read_error = |path: &str, e: RecordError| BagError::Read { path: path.into(), message: e.to_string() };
        while let Some(chunk) = section.next_chunk().map_err(|e| read_error(&self.path, e))? {
            let mut messages = Vec::new();
            for record in chunk.records() {
                match record.map_err(|e| read_error(&self.path, e))? {
                    ChunkRecord::Connection { id, topic, msg_type, md5sum } => {
                        self.connection(id, &topic, &msg_type, &md5sum)?
                    }
                    ChunkRecord::Message { conn, time_nanos, data } => {
                        if let Some(Some((topic, kind))) = self.connections.get(&conn) {
                            messages.push((time_nanos, topic.clone(), *kind, data));
                        }
                    }
                }
            }
            // Record order within a chunk is arrival order; replay goes by record time.
            messages.sort_by_key(|m| m.0);
            for (time_nanos, topic, kind, data) in messages {
                let item = match self.payload(kind, data) {
                    Ok(payload) => BagItem::Message { time_nanos, payload },
                    Err(error) => BagItem::Refused { topic, input: kind.input_name(), error },
                };
                if !out(item) {
                    return Ok(());
                }
            }
        }
        Ok(())
    }
}

/// Reads a bag of `len` bytes from `bag` as robot `robot` (id `id`) on this thread, handing
/// each item to `out` until it returns false; a bag that cannot be read ends with one
/// [`BagItem::Failed`] (`name` names the bag in it). What [`read_bag`]'s thread runs.
pub fn decode_bag(bag: impl Read, len: u64, name: &str, source: &BagSource, mut out: impl FnMut(BagItem) -> bool) {
    let BagSource { config, robot, id, colours, imu } = source;
    let (robot, id) = (robot.as_str(), *id);
    let t = &config.topics;
    let mut topics = vec![
        (RosConfig::resolve(&t.points, robot, id), Kind::Cloud),
        (RosConfig::resolve(&t.labels, robot, id), Kind::Image),
        (RosConfig::resolve(&t.camera_info, robot, id), Kind::CameraInfo),
        (RosConfig::resolve(&t.odometry, robot, id), Kind::Odometry),
        (RosConfig::resolve(&t.ground_truth, robot, id), Kind::GroundTruth),
    ];
    if *imu {
        topics.push((RosConfig::resolve(&t.imu, robot, id), Kind::Imu));
    }
    if config.tf.listen {
        topics.push((RosConfig::resolve(&config.tf.static_topic, robot, id), Kind::TfStatic));
        topics.push((RosConfig::resolve(&config.tf.topic, robot, id), Kind::Tf));
    }
    let decoder = Decoder {
        path: name.to_string(),
        topics,
        inputs: match colours {
            Some(colours) => Inputs::new(config, robot, id).with_colours(colours.clone()),
            None => Inputs::new(config, robot, id),
        },
        connections: BTreeMap::new(),
        max_bytes: config.max_message_bytes,
    };
    let result = ChunkSection::open(bag, len, BagLimits::for_messages(config.max_message_bytes))
        .map_err(|e| BagError::Read { path: name.to_string(), message: e.to_string() })
        .and_then(|section| decoder.run(section, &mut out));
    if let Err(e) = result {
        out(BagItem::Failed(e));
    }
}

/// Whose bag it is: the `[ros]` section, the robot's name and id (`{robot}`, `{id}` in its
/// topics and frames), its palette for colour label images (refused without), and whether its
/// IMU topic (`ros.topics.imu`) is read.
#[derive(Clone, Debug)]
pub struct BagSource {
    pub config: RosConfig,
    pub robot: String,
    pub id: u16,
    pub colours: Option<ColourIds>,
    pub imu: bool,
}

impl BagSource {
    pub fn new(config: &RosConfig, robot: &str, id: u16) -> Self {
        Self { config: config.clone(), robot: robot.into(), id, colours: None, imu: false }
    }

    /// Also read `sensor_msgs/Imu` on `ros.topics.imu` ([`Payload::Imu`]).
    pub fn with_imu(mut self) -> Self {
        self.imu = true;
        self
    }

    pub fn with_colours(mut self, colours: ColourIds) -> Self {
        self.colours = Some(colours);
        self
    }
}

/// Starts reading `path` as `source` says on its own thread.
pub fn read_bag(path: &Path, source: BagSource) -> Receiver<BagItem> {
    let (sender, receiver) = sync_channel(64);
    let path = path.to_path_buf();
    std::thread::spawn(move || {
        let name = path.display().to_string();
        let opened = File::open(&path).and_then(|file| Ok((file.metadata()?.len(), file)));
        match opened {
            Ok((len, file)) => decode_bag(BufReader::new(file), len, &name, &source, |item| sender.send(item).is_ok()),
            Err(e) => {
                let _ = sender.send(BagItem::Failed(BagError::Read { path: name, message: e.to_string() }));
            }
        }
    });
    receiver
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn topics_match_with_or_without_namespace() {
        assert!(topic_matches("/points", "points"));
        assert!(topic_matches("/alpha/points", "points"));
        assert!(topic_matches("/alpha/points", "/alpha/points"));
        assert!(!topic_matches("/alpha/mypoints", "points"));
        assert!(!topic_matches("/points2", "points"));
    }

    /// A 30-byte Odometry in a bag that declares 4 GB of frame id: refused by the layout walk,
    /// not handed to rosrust (which would reserve the 4 GB), exactly as the live node refuses it.
    #[test]
    fn bag_messages_decode_within_the_live_nodes_bounds() {
        let mut data = vec![0u8; 12];
        data.extend_from_slice(&0xFFFF_FFF0u32.to_le_bytes());
        data.extend_from_slice(&[0u8; 14]);
        let e = decode::<nav_msgs::Odometry>(&data, 1 << 20).unwrap_err().to_string();
        assert!(e.starts_with("refused before decoding: field `header.frame_id`"), "{e}");
        // Within bounds but larger than the configured maximum.
        let odometry = nav_msgs::Odometry::default().encode_vec().unwrap();
        let e = decode::<nav_msgs::Odometry>(&odometry[4..], 100).unwrap_err().to_string();
        assert!(e.contains("at most 100 accepted"), "{e}");
        assert!(decode::<nav_msgs::Odometry>(&odometry[4..], 1 << 20).is_ok());
    }
}
