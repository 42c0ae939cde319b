//! The robots of a run, stepped together on the virtual clock — shared by the scenario runner
//! and the bag replay. One step at time t: the caller hands out the frames of t
//! ([`Team::frame`]); then [`Team::settle`] lets the team run until quiet, ticks every robot,
//! delivers what the radio has due, and lets the team run until quiet again.

use crate::report::Observation;
use sgm_actors::clock::Clock;
use sgm_actors::comms::GetCommsStatus;
use sgm_actors::config::RobotConfig;
use sgm_actors::matcher::GetNeighbours;
use sgm_actors::messages::{SensorFrame, Tick};
use sgm_actors::quiescence::until_quiet;
use sgm_actors::supervisor::{start_robot, RobotHandle};
use sgm_actors::tracker::{GetMapSummary, GetSceneGraph};
use sgm_actors::transport::InProcessRadio;
use sgm_model::scene_graph::{SceneGraph, Stamp};
use std::time::{Duration, Instant};

/// Wall-clock facts of a run: kept out of the report so that the report is deterministic.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct Timing {
    pub wall_s: f64,
    pub sim_s: f64,
    pub realtime_factor: f64,
    /// Time in handlers per actor kind, s (one thread: CPU time).
    pub actor_busy_s: std::collections::BTreeMap<String, f64>,
    /// Time producing sensor frames (simulating, or reading and decoding bags), s.
    pub simulation_s: f64,
}

impl Timing {
    pub fn measure(wall: Instant, sim_s: f64, simulation: Duration) -> Self {
        let wall_s = wall.elapsed().as_secs_f64();
        Self {
            wall_s,
            sim_s,
            realtime_factor: sim_s / wall_s.max(1e-9),
            actor_busy_s: sgm_actors::containment::busy_time()
                .into_iter()
                .map(|(k, v)| (k.to_string(), v.as_secs_f64()))
                .collect(),
            simulation_s: simulation.as_secs_f64(),
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum RunError {
    #[error("robot {robot}: {message}")]
    Robot { robot: String, message: String },
    #[error("the actor system stopped answering: {0}")]
    Mailbox(String),
    #[error("{0}")]
    Input(String),
}

fn mailbox(e: actix::MailboxError) -> RunError {
    RunError::Mailbox(e.to_string())
}

struct Member {
    name: String,
    clock: Clock,
    handle: Option<RobotHandle>,
}

pub struct Team {
    pub radio: InProcessRadio,
    members: Vec<Member>,
}

impl Team {
    pub fn new(names: Vec<String>, radio: InProcessRadio) -> Self {
        let members =
            names.into_iter().map(|name| Member { name, clock: Clock::starting_at(0.0), handle: None }).collect();
        Self { radio, members }
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

    /// Hands robot `k` a frame, starting it first (with `config()`) if it is not running yet.
    pub fn frame(
        &mut self,
        k: usize,
        config: impl FnOnce() -> RobotConfig,
        frame: SensorFrame,
    ) -> Result<(), RunError> {
        let Some(member) = self.members.get_mut(k) else { return Ok(()) };
        if member.handle.is_none() {
            let handle = start_robot(&config(), member.clock.clone(), &self.radio)
                .map_err(|e| RunError::Robot { robot: member.name.clone(), message: e.to_string() })?;
            member.handle = Some(handle);
        }
        if let Some(handle) = &member.handle {
            handle.supervisor.do_send(frame);
        }
        Ok(())
    }

    /// Runs the team until quiet, ticks it, delivers the radio's packets due by `t`, and runs
    /// it until quiet again.
    pub async fn settle(&self, t: Stamp) {
        until_quiet().await;
        for handle in self.members.iter().filter_map(|m| m.handle.as_ref()) {
            handle.supervisor.do_send(Tick { now: t });
        }
        until_quiet().await;
        self.radio.deliver_due(t);
        until_quiet().await;
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
