//! ROS 2 recordings (rosbag2) for the replay: a directory of `metadata.yaml` and its storage
//! files, or one storage file alone.
//!
//! - **Storages**: MCAP (`mcap_storage`, the `mcap` crate) and sqlite3 (`sqlite_storage`,
//!   `rusqlite`), each read as topics ([`StorageRecord::Topic`]: name, ROS 2 type, serialisation)
//!   and messages (topic, time in nanoseconds, bytes).
//! - **Metadata** (`metadata`): which storage, which files in which order, and how many messages
//!   per topic. A recording whose storage disagrees with it (a topic it does not list, another
//!   type, another count) ends with an error naming the topic; a storage file read alone is read
//!   without it.
//! - **Messages**: CDR (`super::cdr`), decoded within `ros.max_message_bytes` into the ROS 1
//!   types and checked by the same [`crate::inputs::Inputs`] as a ROS 1 bag's.

pub mod mcap_storage;
pub mod metadata;
pub mod sqlite_storage;

use super::reader::{file_head, BagError, BagItem, BagSource, Decoder, Serialisation, MCAP_MAGIC, SQLITE_MAGIC};
use super::records::BagLimits;
use metadata::{Metadata, StorageId};
use std::collections::BTreeMap;
use std::io::BufReader;
use std::path::{Path, PathBuf};

/// What a storage hands the reader, in order: a topic before the messages on it.
#[derive(Clone, Copy, Debug)]
pub enum StorageRecord<'a> {
    Topic { id: u32, name: &'a str, msg_type: &'a str, encoding: &'a str },
    Message { topic: u32, time_nanos: u64, data: &'a [u8] },
}

/// A recording's files, their storage, and its metadata when there is one.
#[derive(Clone, Debug)]
pub struct Recording {
    pub storage: StorageId,
    pub files: Vec<PathBuf>,
    pub metadata: Option<Metadata>,
}

impl Recording {
    /// A rosbag2 directory (by its `metadata.yaml`), or an `.mcap` or `.db3` file by its magic.
    pub fn open(path: &Path) -> Result<Self, String> {
        if path.is_dir() {
            let yaml = path.join("metadata.yaml");
            if !yaml.is_file() {
                return Err("a directory without metadata.yaml is no rosbag2 recording".into());
            }
            let metadata = Metadata::load(&yaml).map_err(|e| format!("metadata.yaml: {e}"))?;
            let storage = metadata.storage()?;
            let files: Vec<PathBuf> = metadata.relative_file_paths.iter().map(|f| path.join(f)).collect();
            if let Some(missing) = files.iter().find(|f| !f.is_file()) {
                return Err(format!("metadata.yaml lists {}, which is not there", missing.display()));
            }
            return Ok(Self { storage, files, metadata: Some(metadata) });
        }
        let head = file_head(path)?;
        let storage = if head.starts_with(MCAP_MAGIC) {
            StorageId::Mcap
        } else if head.starts_with(SQLITE_MAGIC) {
            StorageId::Sqlite3
        } else {
            return Err("neither an MCAP file nor an sqlite3 database".into());
        };
        Ok(Self { storage, files: vec![path.to_path_buf()], metadata: None })
    }
}

/// Reads the recording at `path` as `source` says on this thread, handing each item to `out`
/// until it returns false; one that cannot be read ends with one [`BagItem::Failed`].
pub fn decode_recording(path: &Path, source: &BagSource, mut out: impl FnMut(BagItem) -> bool) {
    let name = path.display().to_string();
    let result = Recording::open(path)
        .map_err(|message| BagError::Read { path: name.clone(), message })
        .and_then(|recording| Reading::new(&name, source, recording.metadata.clone()).run(&recording, &mut out));
    if let Err(e) = result {
        out(BagItem::Failed(e));
    }
}

/// Reads MCAP bytes as one storage file on this thread (what the `rosbag2` fuzz target feeds).
pub fn decode_mcap(bytes: &[u8], name: &str, source: &BagSource, mut out: impl FnMut(BagItem) -> bool) {
    let mut reading = Reading::new(name, source, None);
    let limit = reading.record_limit();
    let result = mcap_storage::read_mcap(bytes, limit, &mut |r| reading.visit(r, &mut out))
        .map_err(|e| reading.storage_error(name, e));
    if let Err(e) = result {
        out(BagItem::Failed(e));
    }
}

/// One recording being read: the decoder, and what is counted to check the metadata.
struct Reading {
    decoder: Decoder,
    metadata: Option<Metadata>,
    /// Topic names by id in the file being read.
    names: BTreeMap<u32, String>,
    /// Messages seen per topic name.
    counts: BTreeMap<String, u64>,
    /// An error of the decoder's, carried out of a storage's visit.
    stopped: Option<BagError>,
    /// `out` wants no more.
    done: bool,
}

impl Reading {
    fn new(name: &str, source: &BagSource, metadata: Option<Metadata>) -> Self {
        Self {
            decoder: Decoder::new(name, source, Serialisation::Cdr),
            metadata,
            names: BTreeMap::new(),
            counts: BTreeMap::new(),
            stopped: None,
            done: false,
        }
    }

    fn record_limit(&self) -> usize {
        usize::try_from(BagLimits::for_messages(self.decoder.max_bytes).max_chunk_bytes).unwrap_or(usize::MAX)
    }

    fn disagrees(&self, topic: &str, what: String) -> BagError {
        BagError::Disagrees { path: self.decoder.path.clone(), topic: topic.into(), what }
    }

    /// The error a storage ended with: the decoder's own if it stopped the storage.
    fn storage_error(&mut self, file: &str, message: String) -> BagError {
        self.stopped.take().unwrap_or(BagError::Read { path: file.into(), message })
    }

    fn run(mut self, recording: &Recording, out: &mut impl FnMut(BagItem) -> bool) -> Result<(), BagError> {
        let (limit, max_bytes) = (self.record_limit(), self.decoder.max_bytes);
        for file in &recording.files {
            let name = file.display().to_string();
            let read = |message| BagError::Read { path: name.clone(), message };
            self.names.clear();
            let result = match recording.storage {
                StorageId::Mcap => {
                    let f = std::fs::File::open(file).map_err(|e| read(format!("cannot read: {e}")))?;
                    mcap_storage::read_mcap(BufReader::new(f), limit, &mut |r| self.visit(r, out))
                }
                StorageId::Sqlite3 => {
                    let db = sqlite_storage::Database::open(file).map_err(read)?;
                    if let Some(metadata) = &self.metadata {
                        if let Some((topic, what)) =
                            check_database(&db, metadata, recording.files.len()).map_err(read)?
                        {
                            return Err(self.disagrees(&topic, what));
                        }
                    }
                    db.read(max_bytes, &mut |r| self.visit(r, out))
                }
            };
            result.map_err(|e| self.storage_error(&name, e))?;
            if self.done {
                return Ok(());
            }
        }
        self.check_counts()
    }

    /// Registers a topic or hands a message's item on; false once `out` wants no more.
    fn visit(&mut self, record: StorageRecord, out: &mut impl FnMut(BagItem) -> bool) -> Result<bool, String> {
        match record {
            StorageRecord::Topic { id, name, msg_type, encoding } => {
                if let Some(metadata) = &self.metadata {
                    let declared = metadata.topic(name).map(|t| t.topic_metadata.msg_type.clone());
                    let error = match declared {
                        None => Some("the storage has it, metadata.yaml does not list it".to_string()),
                        Some(declared) if declared != msg_type => {
                            Some(format!("metadata.yaml says {declared}, the storage {msg_type}"))
                        }
                        Some(_) => None,
                    };
                    if let Some(what) = error {
                        let e = self.disagrees(name, what);
                        return Err(self.stop(e));
                    }
                }
                self.names.insert(id, name.to_string());
                if let Err(e) = self.decoder.topic(id, name, msg_type, encoding) {
                    return Err(self.stop(e));
                }
                Ok(true)
            }
            StorageRecord::Message { topic, time_nanos, data } => {
                if let Some(name) = self.names.get(&topic) {
                    // Counted by name for the metadata's check, without a name's copy per message.
                    match self.counts.get_mut(name) {
                        Some(count) => *count += 1,
                        None => {
                            self.counts.insert(name.clone(), 1);
                        }
                    }
                }
                if let Some(item) = self.decoder.item(topic, time_nanos, data) {
                    self.done = !out(item);
                }
                Ok(!self.done)
            }
        }
    }

    /// Keeps `e` to end the reading with, and stops the storage.
    fn stop(&mut self, e: BagError) -> String {
        let message = e.to_string();
        self.stopped = Some(e);
        message
    }

    /// Every topic metadata.yaml lists holds the count it declares (MCAP: counted as read).
    fn check_counts(&self) -> Result<(), BagError> {
        let Some(metadata) = &self.metadata else { return Ok(()) };
        for t in &metadata.topics_with_message_count {
            let seen = self.counts.get(&t.topic_metadata.name).copied().unwrap_or(0);
            if seen != t.message_count {
                let what = format!("metadata.yaml declares {} messages, the storage holds {seen}", t.message_count);
                return Err(self.disagrees(&t.topic_metadata.name, what));
            }
        }
        Ok(())
    }
}

/// An sqlite3 file against its recording's metadata before any message is read: the same
/// topics, types and serialisation; the topic and what disagrees, if anything. Counts are
/// checked as read, for every storage.
fn check_database(
    db: &sqlite_storage::Database,
    metadata: &Metadata,
    files: usize,
) -> Result<Option<(String, String)>, String> {
    let topics = db.topics()?;
    for t in &metadata.topics_with_message_count {
        let declared = &t.topic_metadata;
        match topics.iter().find(|d| d.name == declared.name) {
            // A split recording's file holds the topics recorded while it was open.
            None if files > 1 => {}
            None => return Ok(Some((declared.name.clone(), "metadata.yaml lists it, the database does not".into()))),
            Some(d) if d.msg_type != declared.msg_type || d.encoding != declared.serialization_format => {
                return Ok(Some((
                    declared.name.clone(),
                    format!(
                        "metadata.yaml says {} in `{}`, the database {} in `{}`",
                        declared.msg_type, declared.serialization_format, d.msg_type, d.encoding
                    ),
                )))
            }
            Some(_) => {}
        }
    }
    Ok(None)
}
