//! The robots of a run, stepped together on the virtual clock — shared by the scenario runner
//! and the bag replay. One step at time t: the caller hands out the frames of t
//! ([`Team::frame`]); then [`Team::settle`] lets the team run until quiet, ticks every robot,
//! delivers what the radio has due, and lets the team run until quiet again.
//!
//! Each robot runs on a thread of its own ([`robot_thread`]). What the team hands a robot waits
//! in its inbox until the next "run until quiet", which sends it all on the robot's thread and
//! waits there until the robot is quiet — the virtual clock's barrier. Up to `threads` robots
//! run at once; the report is the same for any number.
//!
//! With snapshots kept ([`Team::keep_snapshots`]), each robot's state is frozen and written to
//! disk every `persistence.interval_s`; [`Team::crash`] takes a robot down with everything it
//! held, and its next frame starts it again from its latest snapshot on disk.

mod robot_thread;

use crate::observation::Observation;
use crate::record::Restart;
use crate::threads::Threads;
use robot_thread::{run_jobs, RobotThread};
use sgm_actors::clock::Clock;
use sgm_actors::comms::GetCommsStatus;
use sgm_actors::config::{PersistenceConfig, RobotConfig};
use sgm_actors::fusion::GetFusionStatus;
use sgm_actors::matcher::GetNeighbours;
use sgm_actors::messages::Freeze;
use sgm_actors::messages::{InterRobotConstraints, SensorFrame, Tick};
use sgm_actors::odometry::{GetOdometryStatus, OdometryStatus};
use sgm_actors::optimiser::{GetOptimiserStatus, OptimiserState, OptimiserStatus};
use sgm_actors::quiescence::until_quiet;
use sgm_actors::snapshot::SnapshotStore;
use sgm_actors::supervisor::{start_robot_restored, RobotHandle};
use sgm_actors::tracker::{GetMapSummary, GetSceneGraph};
use sgm_actors::transport::{Delivered, InProcessRadio};
use sgm_model::perception::deskew::DeskewCounts;
use sgm_model::scene_graph::{SceneGraph, Stamp};
use sgm_model::workers::Workers;
use std::collections::BTreeMap;
use std::path::Path;
use std::time::Duration;

#[derive(Debug, thiserror::Error)]
pub enum RunError {
    #[error("robot {robot}: {message}")]
    Robot { robot: String, message: String },
    #[error("the actor system stopped answering: {0}")]
    Mailbox(String),
    #[error("{0}")]
    Input(String),
    #[error(transparent)]
    Output(#[from] crate::output_error::OutputError),
}

fn mailbox(e: actix::MailboxError) -> RunError {
    RunError::Mailbox(e.to_string())
}

/// Something handed to a robot, sent on its thread at the next "run until quiet".
enum Input {
    Frame(Box<SensorFrame>),
    Tick(Stamp),
    Delivered(Delivered),
    Constraints(InterRobotConstraints),
}

impl Input {
    fn send_to(self, handle: &RobotHandle) {
        match self {
            Input::Frame(frame) => handle.supervisor.do_send(*frame),
            Input::Tick(now) => handle.supervisor.do_send(Tick { now }),
            Input::Delivered(packet) => handle.comms.do_send(packet),
            Input::Constraints(message) => handle.optimiser.do_send(message),
        }
    }
}

struct Member {
    name: String,
    clock: Clock,
    /// Its thread, from its first start on.
    thread: Option<RobotThread>,
    inbox: Vec<Input>,
    handle: Option<RobotHandle>,
    store: Option<SnapshotStore>,
    last_snapshot: Option<Stamp>,
    /// Down after a crash: the next start continues from the snapshot.
    crashed: Option<Crash>,
}

/// A crash not yet followed by a restart.
#[derive(Clone, Debug)]
struct Crash {
    at: Stamp,
    keyframes: usize,
}

pub struct Team {
    pub radio: InProcessRadio,
    members: Vec<Member>,
    threads: Threads,
    /// What one robot's registrations may split their work over.
    workers: Workers,
    snapshot_interval_s: f64,
    restarts: Vec<Restart>,
    /// Snapshots written, and their bytes in all.
    pub snapshots_written: (u64, u64),
}

impl Team {
    /// The team of robots `names`, talking over `radio`, up to `threads` of them running at once,
    /// each robot's registrations split over `workers`. Must be called inside an actix system.
    pub fn new(names: Vec<String>, radio: InProcessRadio, threads: Threads, workers: Workers) -> Self {
        let members = names
            .into_iter()
            .map(|name| Member {
                name,
                clock: Clock::starting_at(0.0),
                thread: None,
                inbox: Vec::new(),
                handle: None,
                store: None,
                last_snapshot: None,
                crashed: None,
            })
            .collect();
        Self {
            radio,
            members,
            threads,
            workers,
            snapshot_interval_s: f64::INFINITY,
            restarts: Vec::new(),
            snapshots_written: (0, 0),
        }
    }

    /// Every robot writes a snapshot into `directory` every `persistence.interval_s`. Stale
    /// snapshots of these robots already there are removed: a run never resumes from another.
    pub fn keep_snapshots(&mut self, directory: &Path, persistence: &PersistenceConfig) -> Result<(), RunError> {
        let max_bytes = persistence.max_snapshot_mib.saturating_mul(1 << 20);
        for member in &mut self.members {
            let store = SnapshotStore::new(directory, &member.name, max_bytes);
            for stale in [store.current(), store.previous()] {
                if stale.exists() {
                    std::fs::remove_file(&stale).map_err(|e| RunError::Input(format!("{}: {e}", stale.display())))?;
                }
            }
            member.store = Some(store);
        }
        self.snapshot_interval_s = persistence.interval_s;
        Ok(())
    }

    /// Writes the snapshot of every running robot whose interval has passed at `t`.
    pub async fn snapshot_due(&mut self, t: Stamp) -> Result<(), RunError> {
        for member in &mut self.members {
            let (Some(handle), Some(store)) = (&member.handle, &member.store) else { continue };
            if member.last_snapshot.is_some_and(|last| t - last < self.snapshot_interval_s) {
                continue;
            }
            let snapshot = handle.freeze().await.map_err(mailbox)?;
            let bytes = store
                .save(&snapshot)
                .map_err(|e| RunError::Robot { robot: member.name.clone(), message: e.to_string() })?;
            member.last_snapshot = Some(t);
            self.snapshots_written.0 += 1;
            self.snapshots_written.1 += bytes;
        }
        Ok(())
    }

    /// Takes robot `k` down at `t`: its actors halt and its radio goes deaf; what it held and
    /// had not written to a snapshot is gone.
    pub async fn crash(&mut self, k: usize, t: Stamp) -> Result<(), RunError> {
        let Some(member) = self.members.get_mut(k) else { return Ok(()) };
        let Some(handle) = member.handle.take() else { return Ok(()) };
        let keyframes = handle.tracker.send(GetMapSummary).await.map_err(mailbox)?.keyframes.len();
        tracing::info!(robot = %member.name, at = t, keyframes, "crash");
        self.radio.detach(handle.robot);
        member.crashed = Some(Crash { at: t, keyframes });
        let Some(thread) = member.thread.as_ref().and_then(RobotThread::handle) else { return Ok(()) };
        let halt = move || async move {
            handle.halt();
            until_quiet().await;
        };
        match run_jobs(vec![(thread, halt)], 1).await.pop().flatten() {
            Some(()) => Ok(()),
            None => Err(RunError::Robot { robot: member.name.clone(), message: "its thread stopped".into() }),
        }
    }

    /// Whether robot `k` is running.
    pub fn is_running(&self, k: usize) -> bool {
        self.members.get(k).is_some_and(|m| m.handle.is_some())
    }

    /// Crashes and restarts so far.
    pub fn restarts(&self) -> &[Restart] {
        &self.restarts
    }

    pub fn len(&self) -> usize {
        self.members.len()
    }

    pub fn is_empty(&self) -> bool {
        self.members.is_empty()
    }

    /// Moves robot `k`'s clock to `t` (it is switched on, or about to be).
    pub fn advance(&self, k: usize, t: Stamp) {
        if let Some(m) = self.members.get(k) {
            m.clock.advance_to(t);
        }
    }

    /// Hands robot `k` a frame (handled at the next [`Team::settle`]), starting it first (with
    /// `config()`, on its own thread) if it is not running yet.
    pub async fn frame(
        &mut self,
        k: usize,
        config: impl FnOnce() -> RobotConfig,
        frame: SensorFrame,
    ) -> Result<(), RunError> {
        let radio = self.radio.clone();
        let Some(member) = self.members.get_mut(k) else { return Ok(()) };
        if member.handle.is_none() {
            let name = member.name.clone();
            let failed = |message: String| RunError::Robot { robot: name.clone(), message };
            // After a crash: the latest whole snapshot on disk, if any.
            let snapshot = match (&member.crashed, &member.store) {
                (Some(_), Some(store)) => store.load().map_err(|e| failed(e.to_string()))?.map(|loaded| {
                    for skipped in &loaded.skipped {
                        tracing::warn!(robot = %member.name, "snapshot skipped: {skipped}");
                    }
                    loaded.snapshot
                }),
                _ => None,
            };
            if let Some(crash) = member.crashed.take() {
                self.restarts.push(Restart {
                    robot: member.name.clone(),
                    crashed_at: crash.at,
                    restarted_at: frame.stamp,
                    snapshot_taken_at: snapshot.as_ref().map(|s| s.taken_at),
                    keyframes_at_crash: crash.keyframes,
                    keyframes_in_snapshot: snapshot.as_ref().map_or(0, |s| s.keyframe_count()),
                    objects_in_snapshot: snapshot.as_ref().map_or(0, |s| s.object_count()),
                    snapshot_keyframes: snapshot
                        .as_ref()
                        .map(|s| s.tracker.graph.keyframes().map(|kf| kf.id).collect())
                        .unwrap_or_default(),
                });
            }
            let thread = member.thread.get_or_insert_with(RobotThread::start).handle();
            let thread = thread.ok_or_else(|| failed("its thread stopped".into()))?;
            let (config, clock, workers) = (config(), member.clock.clone(), self.workers.clone());
            // The robot's actors start on its thread, which they then never leave; what they do
            // on starting is done before the job ends (nothing runs between two barriers).
            let start = move || async move {
                let attach =
                    |robot, comms: actix::Addr<sgm_actors::comms::Comms>| radio.attach(robot, comms.recipient());
                let started =
                    start_robot_restored(&config, clock, Box::new(radio.clone()), attach, snapshot, 0, workers);
                until_quiet().await;
                started
            };
            let started = run_jobs(vec![(thread, start)], 1).await.pop().flatten();
            let handle = started.ok_or_else(|| failed("its thread stopped while it started".into()))?;
            member.handle = Some(handle.map_err(|e| failed(e.to_string()))?);
        }
        member.inbox.push(Input::Frame(Box::new(frame)));
        Ok(())
    }

    /// Sends every running robot its inbox, on its own thread, and waits there until it is
    /// quiet — at most `threads` robots at once; then hands what they transmitted to the radio,
    /// in its fixed order.
    async fn run_until_quiet(&mut self) -> Result<(), RunError> {
        let mut names = Vec::new();
        let mut jobs = Vec::new();
        for member in &mut self.members {
            let (Some(handle), Some(thread)) = (&member.handle, member.thread.as_ref().and_then(RobotThread::handle))
            else {
                continue;
            };
            if member.inbox.is_empty() {
                // Quiet since the last barrier, and nothing new: nothing to run.
                continue;
            }
            let (handle, inbox) = (handle.clone(), std::mem::take(&mut member.inbox));
            let job = move || async move {
                for input in inbox {
                    input.send_to(&handle);
                }
                until_quiet().await;
            };
            names.push(member.name.clone());
            jobs.push((thread, job));
        }
        let results = run_jobs(jobs, self.threads.get()).await;
        self.radio.flush();
        match names.into_iter().zip(results).find(|(_, r)| r.is_none()) {
            Some((robot, _)) => Err(RunError::Robot { robot, message: "its thread stopped".into() }),
            None => Ok(()),
        }
    }

    /// Runs the team until quiet, ticks it, delivers the radio's packets due by `t`, and runs
    /// it until quiet again.
    pub async fn settle(&mut self, t: Stamp) -> Result<(), RunError> {
        self.run_until_quiet().await?;
        for member in self.members.iter_mut().filter(|m| m.handle.is_some()) {
            member.inbox.push(Input::Tick(t));
        }
        self.run_until_quiet().await?;
        for (robot, packet) in self.radio.take_due(t) {
            let to = self.members.iter_mut().find(|m| m.handle.as_ref().is_some_and(|h| h.robot == robot));
            if let Some(member) = to {
                member.inbox.push(Input::Delivered(packet));
            }
        }
        self.run_until_quiet().await
    }

    /// What every robot knows at time `t`.
    pub async fn observe(&self, t: Stamp) -> Result<Observation, RunError> {
        let mut observation = Observation { t, ..Observation::default() };
        for member in &self.members {
            let Some(handle) = &member.handle else {
                observation.maps.push(None);
                continue;
            };
            let map = handle.tracker.send(GetMapSummary).await.map_err(mailbox)?;
            let neighbours = handle.matcher.send(GetNeighbours).await.map_err(mailbox)?;
            let comms = handle.comms.send(GetCommsStatus).await.map_err(mailbox)?;
            observation.maps.push(Some((map, neighbours, comms)));
        }
        Ok(observation)
    }

    /// Hands robot `k`'s Optimiser inter-robot constraints that did not come from its Matcher
    /// (fault injection), at the next [`Team::settle`].
    pub fn inject(&mut self, k: usize, message: InterRobotConstraints) {
        if let Some(member) = self.members.get_mut(k).filter(|m| m.handle.is_some()) {
            member.inbox.push(Input::Constraints(message));
        }
    }

    /// Time spent in handlers per actor kind, summed over the robots' threads (for
    /// `timing.json`).
    pub async fn busy_time(&self) -> BTreeMap<&'static str, Duration> {
        let jobs = self
            .members
            .iter()
            .filter_map(|m| m.thread.as_ref().and_then(RobotThread::handle))
            .map(|thread| (thread, || async { sgm_actors::containment::busy_time() }))
            .collect();
        let mut total = BTreeMap::new();
        for busy in run_jobs(jobs, self.threads.get()).await.into_iter().flatten() {
            for (actor, time) in busy {
                *total.entry(actor).or_default() += time;
            }
        }
        total
    }

    /// Each robot's pose graph at a glance (`None`: not running).
    pub async fn optimiser_statuses(&self) -> Result<Vec<Option<OptimiserStatus>>, RunError> {
        let mut out = Vec::new();
        for member in &self.members {
            out.push(match &member.handle {
                Some(handle) => Some(handle.optimiser.send(GetOptimiserStatus).await.map_err(mailbox)?),
                None => None,
            });
        }
        Ok(out)
    }

    /// Each robot's pose graph as its Optimiser holds it (`None`: not running).
    pub async fn pose_graphs(&self) -> Result<Vec<Option<OptimiserState>>, RunError> {
        let mut out = Vec::new();
        for member in &self.members {
            out.push(match &member.handle {
                Some(handle) => {
                    Some(handle.optimiser.send(Freeze::<OptimiserState>::default()).await.map_err(mailbox)?)
                }
                None => None,
            });
        }
        Ok(out)
    }

    /// Each robot's deskew counts since its Fusion (re)started (`None`: not running).
    pub async fn deskew_counts(&self) -> Result<Vec<Option<DeskewCounts>>, RunError> {
        let mut out = Vec::new();
        for member in &self.members {
            out.push(match &member.handle {
                Some(handle) => Some(handle.fusion.send(GetFusionStatus).await.map_err(mailbox)?.deskew),
                None => None,
            });
        }
        Ok(out)
    }

    /// Each robot's internal odometry's status (`None`: not running, or its odometry is
    /// external).
    pub async fn odometry_statuses(&self) -> Result<Vec<Option<OdometryStatus>>, RunError> {
        let mut out = Vec::new();
        for member in &self.members {
            out.push(match member.handle.as_ref().and_then(|h| h.odometry.as_ref()) {
                Some(odometry) => Some(odometry.send(GetOdometryStatus).await.map_err(mailbox)?),
                None => None,
            });
        }
        Ok(out)
    }

    /// Each robot's final map (empty if it never started).
    pub async fn maps(&self) -> Result<Vec<SceneGraph>, RunError> {
        let mut maps = Vec::new();
        for member in &self.members {
            maps.push(match &member.handle {
                Some(handle) => handle.tracker.send(GetSceneGraph).await.map_err(mailbox)?,
                None => SceneGraph::new(),
            });
        }
        Ok(maps)
    }
}
