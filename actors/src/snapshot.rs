//! Freeze and thaw (DESIGN.md §3): a robot's state as one value, and where it is kept on disk.
//!
//! [`RobotSnapshot`] gathers what each child's `freeze` returns; `start_robot_on` takes one back
//! and hands each part to its child's `thawed`. [`SnapshotStore`] keeps snapshots in a
//! directory, one file per robot, framed by `sgm_model::snapshot` (versioned, BLAKE3-checked):
//!
//! - saving writes `<name>.snapshot.tmp`, flushes it to disk, moves the current
//!   `<name>.snapshot` to `<name>.snapshot.prev` (only if it is a whole snapshot, so a good
//!   previous one is never replaced by a damaged one), renames the new file into place and
//!   flushes the directory: a crash at any point leaves a whole snapshot behind;
//! - loading reads `<name>.snapshot`, and if it is missing, truncated or corrupted says so and
//!   falls back to `<name>.snapshot.prev`.

use crate::comms::CommsState;
use crate::matcher::MatcherState;
use crate::optimiser::OptimiserState;
use crate::tracker::TrackerState;
use serde::{Deserialize, Serialize};
use sgm_model::scene_graph::{RobotId, Stamp};
use sgm_model::snapshot::{self, SnapshotError};
use std::fs::{self, File};
use std::io::Write;
use std::path::{Path, PathBuf};

/// What the frame's kind field says for a robot snapshot ("ROB1").
pub const ROBOT_SNAPSHOT_KIND: u32 = u32::from_le_bytes(*b"ROB1");

/// One robot's state at `taken_at`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RobotSnapshot {
    pub robot: RobotId,
    pub name: String,
    pub taken_at: Stamp,
    pub tracker: TrackerState,
    pub matcher: MatcherState,
    pub optimiser: OptimiserState,
    pub comms: CommsState,
}

impl RobotSnapshot {
    pub fn keyframe_count(&self) -> usize {
        self.tracker.graph.keyframe_count()
    }

    pub fn object_count(&self) -> usize {
        self.tracker.graph.objects().count()
    }
}

/// A snapshot that cannot be written or read.
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    #[error("{path}: {source}")]
    Io { path: PathBuf, source: std::io::Error },
    #[error("{path}: {source}")]
    Damaged { path: PathBuf, source: SnapshotError },
    #[error("{path}: a snapshot of robot {found:?}, not of {expected:?}")]
    OtherRobot { path: PathBuf, found: String, expected: String },
    #[error("{0}")]
    Encode(SnapshotError),
    #[error("no usable snapshot of {robot} in {directory}: {reasons}")]
    NoneUsable { robot: String, directory: PathBuf, reasons: String },
}

/// What [`SnapshotStore::load`] found.
#[derive(Debug)]
pub struct Loaded {
    pub snapshot: RobotSnapshot,
    pub path: PathBuf,
    /// Newer files that could not be used, and why (the previous snapshot was loaded instead).
    pub skipped: Vec<StoreError>,
}

/// Snapshots of one robot in one directory.
#[derive(Clone, Debug)]
pub struct SnapshotStore {
    directory: PathBuf,
    name: String,
    max_bytes: u64,
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> StoreError + '_ {
    move |source| StoreError::Io { path: path.to_path_buf(), source }
}

impl SnapshotStore {
    /// Snapshots of robot `name` in `directory`; contents unpacking to more than `max_bytes`
    /// are refused.
    pub fn new(directory: impl Into<PathBuf>, name: &str, max_bytes: u64) -> Self {
        Self { directory: directory.into(), name: name.to_string(), max_bytes }
    }

    pub fn current(&self) -> PathBuf {
        self.directory.join(format!("{}.snapshot", self.name))
    }

    pub fn previous(&self) -> PathBuf {
        self.directory.join(format!("{}.snapshot.prev", self.name))
    }

    fn temporary(&self) -> PathBuf {
        self.directory.join(format!("{}.snapshot.tmp", self.name))
    }

    /// Writes `snapshot` atomically (see the module comment); returns the bytes written.
    pub fn save(&self, snapshot: &RobotSnapshot) -> Result<u64, StoreError> {
        let bytes = snapshot::encode(ROBOT_SNAPSHOT_KIND, snapshot).map_err(StoreError::Encode)?;
        fs::create_dir_all(&self.directory).map_err(io(&self.directory))?;
        let (tmp, current, previous) = (self.temporary(), self.current(), self.previous());
        {
            let mut file = File::create(&tmp).map_err(io(&tmp))?;
            file.write_all(&bytes).map_err(io(&tmp))?;
            file.sync_all().map_err(io(&tmp))?;
        }
        // The frame's checksum is enough to know the current file is whole: no need to decode it.
        let whole = fs::read(&current).is_ok_and(|b| snapshot::verify(&b, ROBOT_SNAPSHOT_KIND).is_ok());
        if whole {
            fs::rename(&current, &previous).map_err(io(&current))?;
        }
        fs::rename(&tmp, &current).map_err(io(&tmp))?;
        // The renames are durable once the directory is (POSIX; elsewhere this is a no-op).
        if let Ok(dir) = File::open(&self.directory) {
            let _ = dir.sync_all();
        }
        Ok(bytes.len() as u64)
    }

    /// Creates the directory if needed and checks that a file can be written there, so that a
    /// node refuses to start rather than run for an interval_s to find out.
    pub fn check_writable(&self) -> Result<(), StoreError> {
        fs::create_dir_all(&self.directory).map_err(io(&self.directory))?;
        let probe = self.directory.join(format!(".{}.probe", self.name));
        File::create(&probe).and_then(|mut f| f.write_all(b"sgm")).map_err(io(&probe))?;
        fs::remove_file(&probe).map_err(io(&probe))
    }

    fn read(&self, path: &Path) -> Result<RobotSnapshot, StoreError> {
        let bytes = fs::read(path).map_err(io(path))?;
        let snapshot: RobotSnapshot = snapshot::decode(&bytes, ROBOT_SNAPSHOT_KIND, self.max_bytes)
            .map_err(|source| StoreError::Damaged { path: path.to_path_buf(), source })?;
        if snapshot.name != self.name {
            return Err(StoreError::OtherRobot {
                path: path.to_path_buf(),
                found: snapshot.name,
                expected: self.name.clone(),
            });
        }
        Ok(snapshot)
    }

    /// The latest whole snapshot: `None` when the robot has none (a first start); an error
    /// naming both files when neither can be used.
    pub fn load(&self) -> Result<Option<Loaded>, StoreError> {
        // A directory that cannot be read is not a first start: starting empty would write over
        // a map that is still there. Only "not found" means there is none.
        let present = |path: &Path| path.try_exists().map_err(io(path));
        match fs::read_dir(&self.directory) {
            Ok(_) => {}
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(source) => return Err(StoreError::Io { path: self.directory.clone(), source }),
        }
        let (current, previous) = (self.current(), self.previous());
        if !present(&current)? && !present(&previous)? {
            return Ok(None);
        }
        let mut skipped = Vec::new();
        for path in [current, previous] {
            if !present(&path)? {
                continue;
            }
            match self.read(&path) {
                Ok(snapshot) => return Ok(Some(Loaded { snapshot, path, skipped })),
                Err(e) => skipped.push(e),
            }
        }
        let reasons: Vec<String> = skipped.iter().map(ToString::to_string).collect();
        Err(StoreError::NoneUsable {
            robot: self.name.clone(),
            directory: self.directory.clone(),
            reasons: reasons.join("; "),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use sgm_model::geometry::Pose3;
    use sgm_model::optim::graph::Graph3;
    use sgm_model::perception::tracker::ObjectTracker;
    use sgm_model::scene_graph::{Keyframe, KeyframeId, SceneGraph};

    fn snapshot(name: &str, keyframes: u32) -> RobotSnapshot {
        let mut graph = SceneGraph::new();
        for k in 0..keyframes {
            let pose = Pose3::translation(f64::from(k), 0.0, 0.0);
            graph.add_keyframe(Keyframe { id: KeyframeId(k), stamp: f64::from(k), world_from_body: pose }).unwrap();
        }
        RobotSnapshot {
            robot: RobotId(1),
            name: name.into(),
            taken_at: f64::from(keyframes),
            tracker: TrackerState {
                graph,
                objects: ObjectTracker::default(),
                next_keyframe: keyframes,
                last_odometry: None,
                covariances: Default::default(),
                last_loop_attempt: None,
                own_poses: Default::default(),
            },
            matcher: MatcherState::default(),
            optimiser: OptimiserState {
                graph: Graph3::default(),
                index: Vec::new(),
                pending: 0,
                candidates: Vec::new(),
                rejected: Vec::new(),
                anchors: Vec::new(),
                realigned: Vec::new(),
                refreshed: vec![(RobotId(2), 3)],
                deferred: vec![(RobotId(2), KeyframeId(7), Pose3::translation(1.0, 2.0, 3.0))],
                updated: Vec::new(),
                withdrawals: vec![(RobotId(2), 1)],
                tilts: vec![(KeyframeId(0), nalgebra::Vector3::new(0.01, -0.02, 1.0).normalize())],
                frame_attitudes: vec![(KeyframeId(1), nalgebra::UnitQuaternion::from_euler_angles(0.01, 0.0, 1.0))],
                frame_up: Some((nalgebra::Vector3::new(0.0, 0.01, 1.0).normalize(), 0.003)),
                log: {
                    let mut log = sgm_model::optim::shared_factors::FactorLog::default();
                    log.keyframe(KeyframeId(0));
                    log
                },
                chains: vec![(
                    RobotId(2),
                    sgm_model::optim::keyframe_graph::NeighbourChain {
                        next: 3,
                        poses: [(KeyframeId(5), Pose3::translation(5.0, 1.0, 0.0))].into(),
                        factors: 1,
                        ..Default::default()
                    },
                )],
            },
            comms: CommsState {
                sequence: 99,
                keyframes_told: [(RobotId(2), [(KeyframeId(4), Pose3::translation(4.0, 0.0, 0.0))].into())].into(),
                ..CommsState::default()
            },
        }
    }

    #[test]
    fn saves_atomically_and_keeps_the_previous_one() {
        let dir = tempfile::tempdir().unwrap();
        let store = SnapshotStore::new(dir.path(), "alpha", 1 << 30);
        assert!(store.load().unwrap().is_none(), "a first start has none");
        store.save(&snapshot("alpha", 3)).unwrap();
        store.save(&snapshot("alpha", 5)).unwrap();
        let loaded = store.load().unwrap().unwrap();
        assert_eq!(loaded.snapshot, snapshot("alpha", 5));
        assert_eq!(loaded.path, store.current());
        assert!(loaded.skipped.is_empty());
        assert!(!dir.path().join("alpha.snapshot.tmp").exists());
        let previous = store.read(&store.previous()).unwrap();
        assert_eq!(previous.keyframe_count(), 3);
    }

    #[test]
    fn a_damaged_snapshot_is_named_and_the_previous_one_used() {
        let dir = tempfile::tempdir().unwrap();
        let store = SnapshotStore::new(dir.path(), "alpha", 1 << 30);
        store.save(&snapshot("alpha", 3)).unwrap();
        store.save(&snapshot("alpha", 5)).unwrap();
        let bytes = fs::read(store.current()).unwrap();
        // Truncated (a crash half-way through a copy), then one flipped bit.
        fs::write(store.current(), &bytes[..bytes.len() / 2]).unwrap();
        let loaded = store.load().unwrap().unwrap();
        assert_eq!(loaded.snapshot.keyframe_count(), 3);
        assert_eq!(loaded.path, store.previous());
        let reason = loaded.skipped[0].to_string();
        assert!(reason.contains("alpha.snapshot") && reason.contains("truncated"), "{reason}");
        let mut flipped = bytes.clone();
        let middle = flipped.len() / 2;
        flipped[middle] ^= 0x10;
        fs::write(store.current(), &flipped).unwrap();
        let reason = store.load().unwrap().unwrap().skipped[0].to_string();
        assert!(reason.contains("checksum"), "{reason}");
        // A damaged current snapshot never replaces the good previous one.
        store.save(&snapshot("alpha", 7)).unwrap();
        assert_eq!(store.read(&store.previous()).unwrap().keyframe_count(), 3);
        assert_eq!(store.load().unwrap().unwrap().snapshot.keyframe_count(), 7);
    }

    /// A directory that exists but cannot be read (here: a file where the directory should be)
    /// is an error naming it, never "no snapshot yet".
    #[test]
    fn a_directory_that_cannot_be_read_is_an_error_not_a_first_start() {
        let dir = tempfile::tempdir().unwrap();
        let not_a_directory = dir.path().join("snapshots");
        fs::write(&not_a_directory, b"a file").unwrap();
        let store = SnapshotStore::new(&not_a_directory, "alpha", 1 << 30);
        let e = store.load().unwrap_err().to_string();
        assert!(e.contains("snapshots"), "{e}");
        assert!(store.check_writable().is_err());
        // Missing altogether: a first start, and the directory is made.
        let store = SnapshotStore::new(dir.path().join("new"), "alpha", 1 << 30);
        assert!(store.load().unwrap().is_none());
        store.check_writable().unwrap();
    }

    #[test]
    fn neither_file_usable_is_an_error_naming_both() {
        let dir = tempfile::tempdir().unwrap();
        let store = SnapshotStore::new(dir.path(), "alpha", 1 << 30);
        fs::write(store.current(), b"not a snapshot at all").unwrap();
        SnapshotStore::new(dir.path(), "bravo", 1 << 30).save(&snapshot("bravo", 1)).unwrap();
        fs::copy(dir.path().join("bravo.snapshot"), store.previous()).unwrap();
        let error = store.load().unwrap_err().to_string();
        assert!(error.contains("alpha.snapshot:") && error.contains("not a snapshot"), "{error}");
        assert!(error.contains("alpha.snapshot.prev") && error.contains("\"bravo\""), "{error}");
        // Over the size bound: refused before unpacking.
        let small = SnapshotStore::new(dir.path(), "bravo", 10);
        assert!(small.load().unwrap_err().to_string().contains("limit"));
    }
}
