//! Reads one robot's recording for the replay: the topics of the `[ros]` section (a recorded
//! topic matches a configured name equal to it or ending it: `points` matches `/points` and
//! `/alpha/points`), each message decoded and checked by [`Inputs`]. A reader thread per
//! recording decodes ahead into a bounded channel, so recordings decode in parallel and memory
//! stays bounded.
//!
//! What the path holds chooses the reader ([`RecordingFormat::of`]): a ROS 1 bag's records are
//! read by [`super::records`], one chunk at a time and within bounds ([`decode_bag`] reads one
//! from any `Read` on the caller's thread; the `rosbag` fuzz target feeds it bytes); a ROS 2
//! recording (a rosbag2 directory, an `.mcap` or a `.db3`) by [`super::rosbag2`], its CDR
//! messages decoded by [`super::cdr`] into the same ROS 1 types, so both take the same checks.

use super::cdr::{self, FromCdr};
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
    /// A topic of another type than its input needs: `found` and `expected` with their md5sum
    /// (ROS 1) or serialisation (ROS 2).
    #[error("{path}: topic {topic} carries {found}, {expected} expected")]
    WrongType { path: String, topic: String, found: String, expected: String },
    /// A ROS 2 recording whose `metadata.yaml` disagrees with what its storage holds.
    #[error("{path}: metadata.yaml disagrees with the storage on topic {topic}: {what}")]
    Disagrees { path: String, topic: String, what: String },
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Kind {
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

    /// The ROS 2 type, as rosbag2 records it.
    fn ros2_type(self) -> &'static str {
        match self {
            Kind::Cloud => sensor_msgs::PointCloud2::ROS2_TYPE,
            Kind::Image => sensor_msgs::Image::ROS2_TYPE,
            Kind::CameraInfo => sensor_msgs::CameraInfo::ROS2_TYPE,
            Kind::Odometry | Kind::GroundTruth => nav_msgs::Odometry::ROS2_TYPE,
            Kind::Tf | Kind::TfStatic => tf2_msgs::TFMessage::ROS2_TYPE,
            Kind::Imu => sensor_msgs::Imu::ROS2_TYPE,
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

/// How a recording serialises its messages.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Serialisation {
    /// ROS 1 (a bag), each message's type checked by its md5sum.
    Ros1,
    /// CDR (rosbag2), each topic's type checked by its ROS 2 name.
    Cdr,
}

fn decode_as<M: RosMsg + Layout + FromCdr>(
    serialisation: Serialisation,
    data: &[u8],
    max_bytes: usize,
) -> Result<M, InputError> {
    match serialisation {
        Serialisation::Ros1 => decode(data, max_bytes),
        Serialisation::Cdr => {
            cdr::decode(data, max_bytes).map_err(|e| InputError::invalid(format!("does not decode from CDR: {e}")))
        }
    }
}

/// One recording's topics and their decoding: which recorded topic is which input, and each
/// message decoded and checked by [`Inputs`].
pub(super) struct Decoder {
    pub(super) path: String,
    topics: Vec<(String, Kind)>,
    inputs: Inputs,
    connections: BTreeMap<u32, Option<(String, Kind)>>,
    /// `ros.max_message_bytes`.
    pub(super) max_bytes: usize,
    serialisation: Serialisation,
}

impl Decoder {
    /// The decoder of `source`'s topics for a recording named `name`.
    pub(super) fn new(name: &str, source: &BagSource, serialisation: Serialisation) -> Self {
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
        Self {
            path: name.to_string(),
            topics,
            inputs: match colours {
                Some(colours) => Inputs::new(config, robot, id).with_colours(colours.clone()),
                None => Inputs::new(config, robot, id),
            },
            connections: BTreeMap::new(),
            max_bytes: config.max_message_bytes,
            serialisation,
        }
    }

    fn kind_of(&self, topic: &str) -> Option<Kind> {
        self.topics.iter().find(|(name, _)| topic_matches(topic, name)).map(|(_, k)| *k)
    }

    /// A ROS 1 connection: its topic, and its type checked by name and md5sum.
    fn connection(&mut self, id: u32, topic: &str, msg_type: &str, md5: &str) -> Result<(), BagError> {
        let kind = self.kind_of(topic);
        if let Some(kind) = kind {
            let (expected, expected_md5) = kind.expected();
            if msg_type != expected || md5 != expected_md5 {
                return Err(BagError::WrongType {
                    path: self.path.clone(),
                    topic: topic.into(),
                    found: format!("{msg_type} (md5 {md5})"),
                    expected,
                });
            }
        }
        self.connections.insert(id, kind.map(|k| (topic.to_string(), k)));
        Ok(())
    }

    /// A ROS 2 topic (a rosbag2 topic or an MCAP channel): its type checked by its ROS 2 name,
    /// and its serialisation (`cdr`). A later topic of the same id replaces it (each file of a
    /// split recording numbers its own).
    pub(super) fn topic(&mut self, id: u32, topic: &str, msg_type: &str, encoding: &str) -> Result<(), BagError> {
        let kind = self.kind_of(topic);
        if let Some(kind) = kind {
            if msg_type != kind.ros2_type() || encoding != "cdr" {
                return Err(BagError::WrongType {
                    path: self.path.clone(),
                    topic: topic.into(),
                    found: format!("{msg_type} in `{encoding}`"),
                    expected: format!("{} in `cdr`", kind.ros2_type()),
                });
            }
        }
        self.connections.insert(id, kind.map(|k| (topic.to_string(), k)));
        Ok(())
    }

    /// The item of a message on connection or topic `id` (None for a topic not read).
    pub(super) fn item(&self, id: u32, time_nanos: u64, data: &[u8]) -> Option<BagItem> {
        let Some(Some((topic, kind))) = self.connections.get(&id) else { return None };
        Some(match self.payload(*kind, data) {
            Ok(payload) => BagItem::Message { time_nanos, payload },
            Err(error) => BagItem::Refused { topic: topic.clone(), input: kind.input_name(), error },
        })
    }

    fn payload(&self, kind: Kind, data: &[u8]) -> Result<Payload, InputError> {
        let (s, max) = (self.serialisation, self.max_bytes);
        match kind {
            Kind::Cloud => self.inputs.cloud(&decode_as(s, data, max)?),
            Kind::Image => self.inputs.image(&decode_as(s, data, max)?),
            Kind::CameraInfo => self.inputs.camera_info(&decode_as(s, data, max)?),
            Kind::Odometry => self.inputs.odometry(&decode_as(s, data, max)?),
            Kind::GroundTruth => self.inputs.ground_truth(&decode_as(s, data, max)?),
            Kind::Tf => self.inputs.tf(&decode_as(s, data, max)?, false),
            Kind::TfStatic => self.inputs.tf(&decode_as(s, data, max)?, true),
            Kind::Imu => self.inputs.imu(&decode_as(s, data, max)?),
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
                        if let Some(Some(_)) = self.connections.get(&conn) {
                            messages.push((time_nanos, conn, data));
                        }
                    }
                }
            }
            // Record order within a chunk is arrival order; replay goes by record time.
            messages.sort_by_key(|m| m.0);
            for (time_nanos, conn, data) in messages {
                if let Some(item) = self.item(conn, time_nanos, data) {
                    if !out(item) {
                        return Ok(());
                    }
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
    let decoder = Decoder::new(name, source, Serialisation::Ros1);
    let result = ChunkSection::open(bag, len, BagLimits::for_messages(source.config.max_message_bytes))
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

/// What a recording's path holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RecordingFormat {
    /// A ROS 1 bag (`#ROSBAG V2.0`).
    Ros1,
    /// A ROS 2 recording: a rosbag2 directory (`metadata.yaml` and its storage files), or one
    /// storage file (MCAP by its magic, sqlite3 by its header).
    Ros2,
}

/// The magic bytes a ROS 1 bag, an MCAP file and an SQLite database begin with.
const ROS1_MAGIC: &[u8] = b"#ROSBAG V2.0\n";
pub(super) const MCAP_MAGIC: &[u8] = b"\x89MCAP0\r\n";
pub(super) const SQLITE_MAGIC: &[u8] = b"SQLite format 3\0";

/// The first 16 bytes of the file at `path` (fewer if it is shorter).
pub(super) fn file_head(path: &Path) -> Result<Vec<u8>, String> {
    let mut head = Vec::with_capacity(16);
    File::open(path).and_then(|file| file.take(16).read_to_end(&mut head)).map_err(|e| e.to_string())?;
    Ok(head)
}

impl RecordingFormat {
    /// Decides by what `path` holds, not by its name: a directory is a rosbag2 recording; a file
    /// by its first bytes.
    pub fn of(path: &Path) -> Result<Self, String> {
        let meta = std::fs::metadata(path).map_err(|e| e.to_string())?;
        if meta.is_dir() {
            return Ok(Self::Ros2);
        }
        let head = file_head(path)?;
        if head.starts_with(ROS1_MAGIC) {
            Ok(Self::Ros1)
        } else if head.starts_with(MCAP_MAGIC) || head.starts_with(SQLITE_MAGIC) {
            Ok(Self::Ros2)
        } else {
            Err("neither a ROS 1 bag (#ROSBAG V2.0), an MCAP file, a rosbag2 sqlite3 database nor a rosbag2 \
                 directory (metadata.yaml)"
                .into())
        }
    }
}

/// Starts reading `path` as `source` says on its own thread: a ROS 1 bag or a ROS 2 recording,
/// by what the path holds.
pub fn read_bag(path: &Path, source: BagSource) -> Receiver<BagItem> {
    let (sender, receiver) = sync_channel(64);
    let path = path.to_path_buf();
    std::thread::spawn(move || {
        let name = path.display().to_string();
        let send = |item| sender.send(item).is_ok();
        // A fault in a container library (the fuzz targets found one in the `mcap` crate's) ends
        // the reading with an error naming the file, not with a silent end of its stream.
        let read =
            std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| read_recording(&path, &name, &source, send)));
        if let Err(panic) = read {
            let what =
                panic.downcast_ref::<&str>().map(|s| s.to_string()).or_else(|| panic.downcast_ref::<String>().cloned());
            let message = format!("the reader failed on this file ({}); please report it", what.unwrap_or_default());
            let _ = sender.send(BagItem::Failed(BagError::Read { path: name, message }));
        }
    });
    receiver
}

/// Reads `path` by what it holds, on this thread.
fn read_recording(path: &Path, name: &str, source: &BagSource, mut send: impl FnMut(BagItem) -> bool) {
    match RecordingFormat::of(path) {
        Ok(RecordingFormat::Ros2) => super::rosbag2::decode_recording(path, source, send),
        Ok(RecordingFormat::Ros1) => {
            let opened = File::open(path).and_then(|file| Ok((file.metadata()?.len(), file)));
            match opened {
                Ok((len, file)) => decode_bag(BufReader::new(file), len, name, source, send),
                Err(e) => {
                    send(BagItem::Failed(BagError::Read { path: name.into(), message: e.to_string() }));
                }
            }
        }
        Err(message) => {
            send(BagItem::Failed(BagError::Read { path: name.into(), message }));
        }
    }
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
