//! The replay journal: what a receiver may have accepted since its last snapshot.
//!
//! A snapshot keeps `Comms`'s replay windows as they were when it was taken. Envelopes accepted
//! after it and before a crash could be replayed to the restored robot and accepted again. So
//! `Comms` reserves counters ahead of what it accepts, per sender and incarnation
//! ([`sgm_model::wire::replay::RESERVE`]), and hands every grown reservation to a
//! [`ReplayJournal`]; the ROS node keeps it in `<robot>.replay` beside the snapshot
//! ([`JournalFile`]) and, after a restore, refuses every counter at or below it
//! ([`ReplayGuard::restored`](sgm_model::wire::ReplayGuard::restored)). A reservation grows
//! when the highest accepted counter comes within `RESERVE / 2` of it, so the file, written on a
//! thread of its own, has `RESERVE / 2` envelopes of that sender to land before the guarantee
//! could be outrun.

use serde::{Deserialize, Serialize};
use sgm_model::snapshot::{self, SnapshotError};
use sgm_model::wire::ReplayGuard;
use std::fs::{self, File};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::mpsc::{channel, Sender};

/// The frame kind of a journal file ("RPL1").
pub const JOURNAL_KIND: u32 = u32::from_le_bytes(*b"RPL1");

/// Where `Comms` reports grown reservations: (sender, incarnation, reserved counter).
pub trait ReplayJournal: Send + Sync {
    fn write(&self, reservations: Vec<(u16, u32, u64)>);
}

/// A journal file's content.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Reservations {
    pub entries: Vec<(u16, u32, u64)>,
}

/// A journal that cannot be read.
#[derive(Debug, thiserror::Error)]
pub enum JournalError {
    #[error("{path}: {source}")]
    Io { path: PathBuf, source: std::io::Error },
    #[error("{path}: {source}")]
    Damaged { path: PathBuf, source: SnapshotError },
    #[error("{path}: not encoded: {source}")]
    Encode { path: PathBuf, source: SnapshotError },
}

/// `<directory>/<robot>.replay`, written atomically (temporary file, flush, rename) by a thread
/// of its own, the latest reservations winning.
pub struct JournalFile {
    path: PathBuf,
    queue: Sender<Vec<(u16, u32, u64)>>,
}

impl JournalFile {
    pub fn path_in(directory: &Path, robot: &str) -> PathBuf {
        directory.join(format!("{robot}.replay"))
    }

    /// Starts the writer of `robot`'s journal in `directory`.
    pub fn start(directory: &Path, robot: &str) -> Self {
        let path = Self::path_in(directory, robot);
        let (queue, incoming) = channel::<Vec<(u16, u32, u64)>>();
        let target = path.clone();
        std::thread::spawn(move || {
            while let Ok(mut entries) = incoming.recv() {
                // Only the newest matters.
                while let Ok(newer) = incoming.try_recv() {
                    entries = newer;
                }
                if let Err(e) = write_atomically(&target, &Reservations { entries }) {
                    tracing::warn!("replay journal not written: {e}");
                }
            }
        });
        Self { path, queue }
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The reservations in `path`: none if there is no file; an error naming the file if it
    /// cannot be read or is damaged.
    pub fn load(path: &Path) -> Result<Option<Reservations>, JournalError> {
        let bytes = match fs::read(path) {
            Ok(bytes) => bytes,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(source) => return Err(JournalError::Io { path: path.to_path_buf(), source }),
        };
        snapshot::decode(&bytes, JOURNAL_KIND, 64 << 20)
            .map(Some)
            .map_err(|source| JournalError::Damaged { path: path.to_path_buf(), source })
    }
}

/// After loading a snapshot: raises its replay windows (`snapshot.comms.replay`) to the
/// reservations of the journal at `path`; how many (sender, incarnation) it raised, none when
/// there is no journal.
pub fn apply(replay: &mut ReplayGuard, path: &Path) -> Result<usize, JournalError> {
    let Some(reservations) = JournalFile::load(path)? else { return Ok(0) };
    let n = reservations.entries.len();
    replay.restored(reservations.entries);
    Ok(n)
}

impl ReplayJournal for JournalFile {
    fn write(&self, reservations: Vec<(u16, u32, u64)>) {
        if self.queue.send(reservations).is_err() {
            // The writer thread is gone (it only ends when its queue closes, or by a panic).
            tracing::error!(path = %self.path.display(), "replay journal writer stopped: reservations not written");
        }
    }
}

fn write_atomically(path: &Path, reservations: &Reservations) -> Result<(), JournalError> {
    let bytes = snapshot::encode(JOURNAL_KIND, reservations)
        .map_err(|source| JournalError::Encode { path: path.to_path_buf(), source })?;
    let tmp = path.with_extension("replay.tmp");
    let io = |path: &Path, source| JournalError::Io { path: path.to_path_buf(), source };
    let mut file = File::create(&tmp).map_err(|e| io(&tmp, e))?;
    file.write_all(&bytes).and_then(|()| file.sync_all()).map_err(|e| io(&tmp, e))?;
    fs::rename(&tmp, path).map_err(|e| io(path, e))
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::{Duration, Instant};

    #[test]
    fn the_newest_reservations_land_in_the_file_and_read_back() {
        let dir = tempfile::tempdir().unwrap();
        let journal = JournalFile::start(dir.path(), "alpha");
        assert!(JournalFile::load(journal.path()).unwrap().is_none(), "no file yet: a first start");
        journal.write(vec![(2, 7, 64)]);
        journal.write(vec![(2, 7, 97), (3, 1, 64)]);
        let deadline = Instant::now() + Duration::from_secs(10);
        loop {
            let loaded = JournalFile::load(journal.path()).unwrap_or_default();
            if loaded.is_some_and(|r| r.entries == vec![(2, 7, 97), (3, 1, 64)]) {
                break;
            }
            assert!(Instant::now() < deadline, "the journal never held the newest reservations");
            std::thread::sleep(Duration::from_millis(10));
        }
        // A damaged file is an error naming it.
        fs::write(journal.path(), b"garbage").unwrap();
        let e = JournalFile::load(journal.path()).unwrap_err().to_string();
        assert!(e.contains("alpha.replay"), "{e}");
    }
}
