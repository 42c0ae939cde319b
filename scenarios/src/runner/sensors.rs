//! The simulated sensors of the whole team, one step at a time, either on the runner's thread
//! (one thread) or one step ahead of the robots on a thread of their own (more threads).
//!
//! A step's frames depend only on the world, the routes and each robot's own random streams,
//! never on what the robots did with earlier frames ([`super::sensing`]). So while the team
//! handles step k, the frames of step k + 1 can be simulated, and they are the same. The
//! simulating threads run in Linux's idle scheduling class: they take a core only when no
//! robot wants it — at a barrier, while one robot finishes its round alone — and the robots'
//! work is not slowed by them.

use super::sensing::{Sensed, Sensing, SimRobot};
use crate::scenario::Scenario;
use crate::sim::people::People;
use crate::sim::segmenter_errors::SegmenterErrors;
use crate::sim::world::World;
use crate::team::RunError;
use crate::threads::Threads;
use sgm_model::perception::projection::CameraModel;
use sgm_model::scene_graph::stamp_from_nanos;
use std::time::{Duration, Instant};
use tokio::sync::mpsc::{unbounded_channel, UnboundedReceiver, UnboundedSender};

/// Everything the sensors need, owned, so that it can move to a thread of its own.
pub(super) struct SensorState {
    pub scenario: Scenario,
    pub world: World,
    pub people: People,
    pub robots: Vec<SimRobot>,
    pub segmenter_errors: Option<SegmenterErrors>,
    pub camera: CameraModel,
    /// Half-size of a return's splat in the label image, px.
    pub splat: i64,
    /// The configured segmenter's id for each of our classes (`None`: ours).
    pub pixel_values: Option<Vec<u16>>,
    pub dt_nanos: i64,
    pub sweep_nanos: i64,
    pub sweeps_per_frame: i64,
}

impl SensorState {
    /// Step `step` of every robot (the people placed for it first), on `pool` if any, and the
    /// time it took.
    fn sense(&mut self, step: u64, pool: Option<&rayon::ThreadPool>) -> SensedStep {
        let started = Instant::now();
        let t = stamp_from_nanos(step as i64 * self.dt_nanos);
        self.people.place(&mut self.world, t);
        let sensing = Sensing {
            scenario: &self.scenario,
            world: &self.world,
            segmenter_errors: self.segmenter_errors.as_ref(),
            camera: &self.camera,
            splat: self.splat,
            pixel_values: self.pixel_values.as_deref(),
            dt_nanos: self.dt_nanos,
            sweep_nanos: self.sweep_nanos,
            sweeps_per_frame: self.sweeps_per_frame,
        };
        let robots = sensing.sense_all(&mut self.robots, step, t, pool);
        SensedStep { step, robots, took: started.elapsed() }
    }
}

/// One step's frames, for every robot (`None`: not on).
pub(super) struct SensedStep {
    step: u64,
    pub robots: Vec<Option<Sensed>>,
    /// Time spent simulating it.
    pub took: Duration,
}

/// The team's sensors.
pub(super) enum Sensors {
    /// Simulated on the runner's thread when asked for (one thread; or no pool could be built).
    Here(Box<SensorState>),
    /// Simulated one step ahead on a thread of their own.
    Ahead(Ahead),
}

impl Sensors {
    /// The sensors of `state`: one step ahead when `threads` allows more than one.
    pub fn start(state: SensorState, threads: Threads) -> Result<Self, RunError> {
        match threads.get() {
            1 => Ok(Self::Here(Box::new(state))),
            _ => Ahead::start(state, threads).map(Self::Ahead),
        }
    }

    /// Step `step`'s frames (steps are taken in order); ahead, the steps after it up to
    /// [`STEPS_AHEAD`] later, but not past `last`, are simulated meanwhile.
    pub async fn step(&mut self, step: u64, last: u64) -> Result<SensedStep, RunError> {
        match self {
            Self::Here(state) => Ok(state.sense(step, None)),
            Self::Ahead(ahead) => ahead.step(step, last).await,
        }
    }

    /// The sensors' state after the last step (the world, each robot's counts).
    pub fn finish(self) -> Result<SensorState, RunError> {
        match self {
            Self::Here(state) => Ok(*state),
            Self::Ahead(ahead) => ahead.finish(),
        }
    }
}

/// How many steps the sensors may run ahead of the robots. More hides more of the simulation
/// behind the robots' work (it runs only on cores they leave idle, and those come in bursts),
/// at the cost of frames held meanwhile: on team_of_sixteen, about 1 MB a robot a step.
pub(super) const STEPS_AHEAD: u64 = 4;

/// The sensors' own thread and its queue: steps asked for go in, their frames come out.
pub(super) struct Ahead {
    asks: Option<std::sync::mpsc::Sender<u64>>,
    frames: UnboundedReceiver<SensedStep>,
    /// The last step asked for.
    asked: u64,
    thread: Option<std::thread::JoinHandle<SensorState>>,
}

fn stopped(why: &str) -> RunError {
    RunError::Input(format!("the simulated sensors' thread {why}"))
}

impl Ahead {
    fn start(mut state: SensorState, threads: Threads) -> Result<Self, RunError> {
        let pool = threads.background_pool().map_err(|e| stopped(&format!("could not start: {e}")))?;
        let (asks, asked) = std::sync::mpsc::channel::<u64>();
        let (send, frames): (UnboundedSender<SensedStep>, _) = unbounded_channel();
        let thread = std::thread::Builder::new()
            .name("sgm-sensors".into())
            .spawn(move || {
                crate::threads::run_in_background();
                // Until the runner stops asking (it drops its end) or stops listening.
                while let Ok(step) = asked.recv() {
                    if send.send(state.sense(step, Some(&pool))).is_err() {
                        break;
                    }
                }
                state
            })
            .map_err(|e| stopped(&format!("could not start: {e}")))?;
        Ok(Self { asks: Some(asks), frames, asked: 0, thread: Some(thread) })
    }

    async fn step(&mut self, step: u64, last: u64) -> Result<SensedStep, RunError> {
        let asks = self.asks.as_ref().ok_or_else(|| stopped("was already finished"))?;
        let until = step.saturating_add(STEPS_AHEAD).min(last).max(step);
        while self.asked < until {
            self.asked += 1;
            asks.send(self.asked).map_err(|_| stopped("ended before the run"))?;
        }
        let sensed = self.frames.recv().await.ok_or_else(|| stopped("ended before the run (a panic?)"))?;
        if sensed.step != step {
            return Err(stopped(&format!("handed step {} back for step {step}", sensed.step)));
        }
        Ok(sensed)
    }

    /// Stops the thread once its last step is done, and takes the state back.
    fn finish(mut self) -> Result<SensorState, RunError> {
        drop(self.asks.take());
        let thread = self.thread.take().ok_or_else(|| stopped("was already finished"))?;
        thread.join().map_err(|_| stopped("panicked"))
    }
}

impl Drop for Ahead {
    /// A run that ends early (an error) stops the thread too, after the step it is on.
    fn drop(&mut self) {
        drop(self.asks.take());
        if let Some(thread) = self.thread.take() {
            // Its state goes with the failed run; a panic was already reported by its hook.
            let _ = thread.join();
        }
    }
}
