//! A rosbag2 recording's `metadata.yaml` (rosbag2 `metadata_io`, versions 1–9): which storage
//! holds the messages, in which files, and how many per topic; what the replay checks the
//! storage against.
//!
//! ```yaml
//! rosbag2_bagfile_information:
//!   version: 9
//!   storage_identifier: mcap            # or sqlite3
//!   relative_file_paths: [run_0.mcap]
//!   compression_format: ''              # zstd with compression_mode FILE or MESSAGE
//!   compression_mode: ''
//!   topics_with_message_count:
//!     - message_count: 180
//!       topic_metadata: {name: /alpha/points, type: sensor_msgs/msg/PointCloud2, serialization_format: cdr}
//! ```

use serde::Deserialize;
use std::path::Path;

/// The largest `metadata.yaml` read, bytes (a recording of thousands of topics is far below).
pub const MAX_METADATA_BYTES: u64 = 4 << 20;

#[derive(Debug, Deserialize)]
struct File {
    rosbag2_bagfile_information: Metadata,
}

/// What the replay uses of `metadata.yaml`.
#[derive(Clone, Debug, Deserialize, PartialEq)]
pub struct Metadata {
    pub version: u32,
    pub storage_identifier: String,
    #[serde(default)]
    pub relative_file_paths: Vec<String>,
    #[serde(default)]
    pub compression_format: String,
    #[serde(default)]
    pub compression_mode: String,
    #[serde(default)]
    pub topics_with_message_count: Vec<TopicCount>,
}

#[derive(Clone, Debug, Deserialize, PartialEq)]
pub struct TopicCount {
    pub message_count: u64,
    pub topic_metadata: TopicMetadata,
}

#[derive(Clone, Debug, Deserialize, PartialEq)]
pub struct TopicMetadata {
    pub name: String,
    #[serde(rename = "type")]
    pub msg_type: String,
    pub serialization_format: String,
}

/// The storages a recording may name.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StorageId {
    Mcap,
    Sqlite3,
}

impl Metadata {
    /// Reads and checks `path`: bounded, YAML of rosbag2's shape, a storage we read, no
    /// rosbag2-level compression, files that stay inside the recording's directory.
    pub fn load(path: &Path) -> Result<Self, String> {
        let size = std::fs::metadata(path).map_err(|e| format!("cannot read: {e}"))?.len();
        if size > MAX_METADATA_BYTES {
            return Err(format!("{size} bytes, at most {MAX_METADATA_BYTES} read"));
        }
        let text = std::fs::read_to_string(path).map_err(|e| format!("cannot read: {e}"))?;
        Self::parse(&text)
    }

    pub fn parse(text: &str) -> Result<Self, String> {
        let file: File = serde_saphyr::from_str(text).map_err(|e| format!("not rosbag2 metadata: {e}"))?;
        let metadata = file.rosbag2_bagfile_information;
        metadata.storage()?;
        if !metadata.compression_mode.is_empty() || !metadata.compression_format.is_empty() {
            return Err(format!(
                "compressed by rosbag2 (compression_mode `{}`, compression_format `{}`), which the replay does not \
                 read; decompress it with `ros2 bag convert` (MCAP's own chunk compression is read)",
                metadata.compression_mode, metadata.compression_format
            ));
        }
        if metadata.relative_file_paths.is_empty() {
            return Err("relative_file_paths lists no file".into());
        }
        for file in &metadata.relative_file_paths {
            let inside = Path::new(file).components().all(|c| matches!(c, std::path::Component::Normal(_)));
            if !inside {
                return Err(format!("relative_file_paths: `{file}` is not a file inside the recording's directory"));
            }
        }
        Ok(metadata)
    }

    pub fn storage(&self) -> Result<StorageId, String> {
        match self.storage_identifier.as_str() {
            "mcap" => Ok(StorageId::Mcap),
            "sqlite3" => Ok(StorageId::Sqlite3),
            other => Err(format!("storage_identifier `{other}`: mcap or sqlite3 expected")),
        }
    }

    /// The declared count and type of `topic`, if the metadata lists it.
    pub fn topic(&self, topic: &str) -> Option<&TopicCount> {
        self.topics_with_message_count.iter().find(|t| t.topic_metadata.name == topic)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = "rosbag2_bagfile_information:
  version: 9
  storage_identifier: sqlite3
  relative_file_paths:
  - run_0.db3
  compression_format: ''
  compression_mode: ''
  duration:
    nanoseconds: 10
  topics_with_message_count:
  - message_count: 3
    topic_metadata:
      name: /alpha/points
      offered_qos_profiles: []
      serialization_format: cdr
      type: sensor_msgs/msg/PointCloud2
";

    #[test]
    fn rosbag2_metadata_reads_its_storage_files_and_topics() {
        let m = Metadata::parse(GOOD).unwrap();
        assert_eq!(m.storage(), Ok(StorageId::Sqlite3));
        assert_eq!(m.relative_file_paths, ["run_0.db3"]);
        let t = m.topic("/alpha/points").unwrap();
        assert_eq!((t.message_count, t.topic_metadata.msg_type.as_str()), (3, "sensor_msgs/msg/PointCloud2"));
        assert!(m.topic("/bravo/points").is_none());
    }

    #[test]
    fn metadata_we_cannot_follow_is_refused_with_why() {
        let e = Metadata::parse(&GOOD.replace("sqlite3", "rosbag_v2")).unwrap_err();
        assert_eq!(e, "storage_identifier `rosbag_v2`: mcap or sqlite3 expected");
        let e = Metadata::parse(&GOOD.replace("compression_mode: ''", "compression_mode: FILE")).unwrap_err();
        assert!(e.starts_with("compressed by rosbag2 (compression_mode `FILE`"), "{e}");
        let e = Metadata::parse(&GOOD.replace("run_0.db3", "../../etc/passwd")).unwrap_err();
        assert!(e.contains("not a file inside"), "{e}");
        let e = Metadata::parse("rosbag2_bagfile_information: [1, 2]").unwrap_err();
        assert!(e.starts_with("not rosbag2 metadata"), "{e}");
        assert!(Metadata::parse("- a\n- b: [").is_err());
    }
}
