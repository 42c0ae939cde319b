//! The node's snapshots: a consistent cut of the robot, written without stalling it.
//!
//! A snapshot's parts are frozen actor by actor, and between two of them the actors go on
//! handling messages: a keyframe Comms accepted after the Matcher was frozen would be held by
//! one part and missing from the other. So the node first **holds its inputs** — sensor frames
//! and envelopes from other robots wait in the [`Intake`] — then lets the robot finish what it
//! is doing ([`until_quiet`]: no handler has run for a few turns of the runtime), freezes every
//! part with nothing in flight between them, and lets the inputs go in the order they came.
//! Encoding, compressing, checksumming and writing (hundreds of milliseconds for a large map)
//! happen on a thread of their own ([`Snapshots`]): the robot only pauses for the copy.

use sgm_actors::messages::SensorFrame;
use sgm_actors::quiescence::until_quiet;
use sgm_actors::snapshot::SnapshotStore;
use sgm_actors::supervisor::RobotHandle;
use sgm_actors::transport::Delivered;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Mutex, PoisonError};
use std::thread::JoinHandle;

/// Inputs held while a snapshot is taken, at most; more are dropped (counted).
const MAX_HELD: usize = 100_000;

enum Held {
    Frame(Box<SensorFrame>),
    Envelope(Vec<u8>),
}

/// Where the robot's inputs enter: straight to the robot, or held while a snapshot is taken.
pub struct Intake {
    handle: RobotHandle,
    latency: std::sync::Arc<crate::latency::Latency>,
    held: Mutex<Option<Vec<Held>>>,
    /// Inputs dropped because too many were held.
    pub dropped: AtomicU64,
}

impl Intake {
    pub fn new(handle: RobotHandle) -> Self {
        let latency = crate::latency::Latency::start(handle.progress.clone());
        Self { handle, latency, held: Mutex::new(None), dropped: AtomicU64::new(0) }
    }

    /// Latency per frame, handed to handled (`crate::latency`).
    pub fn latency(&self) -> crate::latency::LatencySummary {
        self.latency.summary()
    }

    fn pass(&self, input: Held) {
        match input {
            Held::Frame(frame) => {
                self.handle.clock.advance_to(frame.stamp);
                self.latency.handed(frame.stamp);
                self.handle.supervisor.do_send(*frame);
            }
            Held::Envelope(bytes) => self.handle.comms.do_send(Delivered { bytes }),
        }
    }

    fn offer(&self, input: Held) {
        let mut held = self.held.lock().unwrap_or_else(PoisonError::into_inner);
        match held.as_mut() {
            Some(queue) if queue.len() >= MAX_HELD => {
                self.dropped.fetch_add(1, Ordering::Relaxed);
            }
            Some(queue) => queue.push(input),
            None => self.pass(input),
        }
    }

    /// A sensor frame: to the robot, moving its clock to the frame's stamp.
    pub fn frame(&self, frame: SensorFrame) {
        self.offer(Held::Frame(Box::new(frame)));
    }

    /// Simulated time passed (`/clock`): the robot's clock moves on (never back).
    pub fn advance_clock(&self, t: sgm_model::scene_graph::Stamp) {
        self.handle.clock.advance_to(t);
    }

    /// A sealed envelope from another robot: to Comms.
    pub fn envelope(&self, bytes: Vec<u8>) {
        self.offer(Held::Envelope(bytes));
    }

    fn hold(&self) {
        let mut held = self.held.lock().unwrap_or_else(PoisonError::into_inner);
        held.get_or_insert_with(Vec::new);
    }

    fn release(&self) {
        let mut held = self.held.lock().unwrap_or_else(PoisonError::into_inner);
        for input in held.take().unwrap_or_default() {
            self.pass(input);
        }
    }
}

/// Snapshots of one robot: taken on the actor thread, written on another, one at a time.
pub struct Snapshots {
    store: SnapshotStore,
    writing: Option<JoinHandle<()>>,
    /// Snapshots not taken because the previous one was still being written.
    pub skipped: u64,
}

impl Snapshots {
    pub fn new(store: SnapshotStore) -> Self {
        Self { store, writing: None, skipped: 0 }
    }

    /// Takes a consistent snapshot of the robot and starts writing it; skipped (and logged) if
    /// the previous one is still being written.
    pub async fn take(&mut self, handle: &RobotHandle, intake: &Intake) {
        if self.writing.as_ref().is_some_and(|w| !w.is_finished()) {
            self.skipped += 1;
            tracing::warn!(robot = %handle.name, "snapshot skipped: the previous one is still being written");
            return;
        }
        if let Some(done) = self.writing.take() {
            let _ = done.join();
        }
        intake.hold();
        until_quiet().await;
        let frozen = handle.freeze().await;
        intake.release();
        let snapshot = match frozen {
            Ok(snapshot) => snapshot,
            Err(e) => {
                tracing::warn!(robot = %handle.name, "snapshot not taken: {e}");
                return;
            }
        };
        let (store, name) = (self.store.clone(), handle.name.clone());
        let spawned =
            std::thread::Builder::new().name("sgm-snapshot".into()).spawn(move || match store.save(&snapshot) {
                Ok(bytes) => {
                    tracing::debug!(robot = %name, bytes, path = %store.current().display(), "snapshot written")
                }
                Err(e) => tracing::warn!(robot = %name, "snapshot not written: {e}"),
            });
        match spawned {
            Ok(writing) => self.writing = Some(writing),
            Err(e) => tracing::warn!(robot = %handle.name, "snapshot not written: no thread: {e}"),
        }
    }

    /// Waits for the snapshot being written, if any.
    pub fn finish(&mut self) {
        if let Some(writing) = self.writing.take() {
            let _ = writing.join();
        }
    }
}
