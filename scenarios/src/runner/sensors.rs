//! The simulated sensors of the whole team, one step at a time, either on the runner's thread
//! (one thread) or up to [`STEPS_AHEAD`] steps ahead of the robots on threads of their own
//! (more threads).
//!
//! A step's frames depend only on the world, the routes and each robot's own random streams,
//! never on what the robots did with earlier frames ([`super::sensing`]). So while the team
//! handles step k, the frames of steps k + 1, k + 2, … can be simulated, and they are the
//! same. The simulating threads run in Linux's idle scheduling class: they take a core only
//! when no robot wants it — at a barrier, while one robot finishes its round alone — and the
//! robots' work is not slowed by them.

use super::sensing::{Sensed, Sensing, SimRobot};
use crate::scenario::{OdometrySourceSpec, Scenario};
use crate::sim::camera::{camera_model, segmenter_ids, CameraMount};
use crate::sim::imu::Imu;
use crate::sim::lidar::Lidar;
use crate::sim::mount::LidarMount;
use crate::sim::odometry::Odometry;
use crate::sim::people::People;
use crate::sim::segmenter_errors::SegmenterErrors;
use crate::sim::setup::SimulatedWorld;
use crate::sim::world::World;
use crate::team::RunError;
use crate::threads::Threads;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use sgm_model::scene_graph::{nanos_from_stamp, stamp_from_nanos};
use std::time::{Duration, Instant};
use tokio::sync::mpsc::{unbounded_channel, UnboundedReceiver, UnboundedSender};

/// Everything the sensors need, owned, so that it can move to a thread of its own.
pub(super) struct SensorState {
    pub sensing: Sensing,
    pub world: World,
    pub people: People,
    pub robots: Vec<SimRobot>,
}

impl SensorState {
    /// The sensors of `scenario`'s robots and world, before the first step.
    pub fn of(scenario: &Scenario) -> Result<Self, RunError> {
        let seed = scenario.scenario.seed;
        let SimulatedWorld { routes, world, people } = SimulatedWorld::of(scenario);
        let camera = camera_model(&scenario.camera);
        let splat = splat_px(scenario, camera.fx);
        let (_, label_map) = scenario.robot_config(0).class_tables().map_err(|e| RunError::Input(e.to_string()))?;
        // The camera speaks the configured segmenter's ids (`[classes]`); None: they are ours.
        let pixel_values = segmenter_ids(&scenario.classes, &label_map);
        let stream = |k: usize, salt: u64| ChaCha8Rng::seed_from_u64(seed.wrapping_mul(salt) ^ (k as u64 + 1));
        let robots = routes
            .into_iter()
            .enumerate()
            .map(|(k, route)| SimRobot {
                name: scenario.robot_name(k),
                route,
                odometry: Odometry::new(&scenario.odometry),
                lidar: Lidar::new(&scenario.lidar),
                lidar_mount: LidarMount::new(&scenario.lidar, seed, k),
                camera: CameraMount::new(&scenario.camera, seed, k),
                imu: scenario.imu.enabled.then(|| (Imu::new(&scenario.imu, seed, k), stream(k, 0x2545_F491_4F6C_DD1D))),
                rng: stream(k, 0x9E37_79B9_7F4A_7C15),
                segmenter_rng: stream(k, 0x5E67_4D45_4E54_4552),
                sweep_rng: stream(k, 0x5357_4545_5053_0001),
                frames: 0,
                raw_bytes: 0,
                raw_max_bytes: 0,
            })
            .collect();
        let dt_nanos = nanos_from_stamp(scenario.scenario.frame_interval_s);
        let sweep_nanos = nanos_from_stamp(scenario.odometry.sweep_interval_s);
        let internal = scenario.odometry.source == OdometrySourceSpec::Internal;
        let sensing = Sensing {
            scenario: scenario.clone(),
            segmenter_errors: SegmenterErrors::of_scenario(scenario),
            camera,
            splat,
            pixel_values,
            dt_nanos,
            sweep_nanos,
            sweeps_per_frame: if internal { (dt_nanos / sweep_nanos.max(1)).max(1) } else { 1 },
        };
        Ok(Self { sensing, world, people, robots })
    }

    /// Step `step` of every robot (the people placed for it first), on `pool` if any, and the
    /// time it took.
    fn sense(&mut self, step: u64, pool: Option<&rayon::ThreadPool>) -> SensedStep {
        let started = Instant::now();
        let t = stamp_from_nanos(step as i64 * self.sensing.dt_nanos);
        self.people.place(&mut self.world, t);
        let robots = self.sensing.sense_all(&self.world, &mut self.robots, step, t, pool);
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
    /// Simulated on the runner's thread when asked for (one thread).
    Here(Box<SensorState>),
    /// Simulated ahead on threads of their own.
    Ahead(Ahead),
}

impl Sensors {
    /// The sensors of `state`: ahead when `threads` allows more than one.
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

/// How many steps the sensors may run ahead of the robots: enough to fill the idle cores of a
/// few barriers in a row, at the cost of the frames held meanwhile. On team_of_sixteen (2
/// threads), 4 steps left the robots waiting 5.7 s for frames and raised the peak resident
/// memory by 22 MiB; 8 steps, 5.5 s and 54 MiB.
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
        let Some(sensed) = self.frames.recv().await else { return Err(self.why_it_ended()) };
        if sensed.step != step {
            return Err(stopped(&format!("handed step {} back for step {step}", sensed.step)));
        }
        Ok(sensed)
    }

    /// Why the thread stopped handing frames back before the run's end: its panic's message.
    fn why_it_ended(&mut self) -> RunError {
        let Some(thread) = self.thread.take() else { return stopped("was already finished") };
        match thread.join() {
            Ok(_) => stopped("ended before the run"),
            Err(panic) => {
                let message = panic
                    .downcast_ref::<&str>()
                    .map(|s| s.to_string())
                    .or_else(|| panic.downcast_ref::<String>().cloned())
                    .unwrap_or_else(|| "no message".into());
                stopped(&format!("panicked: {message}"))
            }
        }
    }

    /// Stops the thread once its last step is done, and takes the state back.
    fn finish(mut self) -> Result<SensorState, RunError> {
        drop(self.asks.take());
        self.frames.close();
        let thread = self.thread.take().ok_or_else(|| stopped("was already finished"))?;
        thread.join().map_err(|_| stopped("panicked"))
    }
}

impl Drop for Ahead {
    /// A run that ends early (an error) stops the thread too, after the step it is on: closed,
    /// the queue takes no more frames, and the steps still asked for are not simulated. It is
    /// not waited for: its state goes with the failed run, and at idle priority its step may
    /// wait long for a core while the robots are still being torn down.
    fn drop(&mut self) {
        drop(self.asks.take());
        self.frames.close();
    }
}

/// Half-size of a return's splat in the label image: half the scan pattern's spacing in pixels.
fn splat_px(scenario: &Scenario, fx: f64) -> i64 {
    let l = &scenario.lidar;
    let spacing_deg = match l.pattern {
        crate::scenario::LidarPattern::Spinning => {
            let vertical = (l.vertical_fov_deg[1] - l.vertical_fov_deg[0]) / (l.beams.max(2) - 1) as f64;
            vertical.max(l.azimuth_step_deg)
        }
        crate::scenario::LidarPattern::Livox => {
            let area = 360.0 * (l.vertical_fov_deg[1] - l.vertical_fov_deg[0]);
            (area / l.points_per_frame.max(1) as f64).sqrt()
        }
    };
    ((spacing_deg.to_radians() * fx / 2.0).ceil() as i64).clamp(1, 8)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::num::NonZeroUsize;

    /// A step's frames, as bits: truth, odometry, every point and its time, the labels.
    fn bits(step: &SensedStep) -> Vec<u64> {
        let mut out = vec![step.step];
        for sensed in step.robots.iter().flatten() {
            let poses = [sensed.truth, sensed.odometry, sensed.truth_from_world];
            out.extend(poses.iter().flat_map(|p| p.to_homogeneous().iter().map(|v| v.to_bits()).collect::<Vec<_>>()));
            out.push(u64::from(sensed.down));
            let frames = sensed
                .sweeps
                .iter()
                .map(|s| (&s.points, &s.times))
                .chain(sensed.frame.iter().map(|f| (&f.points, &f.times)));
            for (points, times) in frames {
                out.extend(points.iter().flat_map(|p| p.coords.iter().map(|v| v.to_bits())));
                out.extend(times.iter().flatten().map(|t| u64::from(t.to_bits())));
            }
            if let Some(frame) = &sensed.frame {
                out.extend(format!("{:?}", frame.labels).bytes().map(u64::from));
            }
        }
        out
    }

    /// The handheld rig's scenario has all the sensors: people walking through, the camera's
    /// label image, the IMU and the sweeps of internal odometry.
    #[actix_rt::test]
    async fn frames_simulated_ahead_are_the_frames_simulated_in_turn() {
        let mut scenario = Scenario::load("handheld_indoor").expect("library scenario");
        scenario.scenario.duration_s = 6.0 * scenario.scenario.frame_interval_s;
        let steps = 6;
        let mut here = Sensors::start(SensorState::of(&scenario).expect("sensors"), Threads::one()).expect("here");
        let two = Threads::exactly(NonZeroUsize::new(2).expect("two"));
        let mut ahead = Sensors::start(SensorState::of(&scenario).expect("sensors"), two).expect("ahead");
        assert!(matches!(ahead, Sensors::Ahead(_)), "two threads simulate ahead");
        for step in 1..=steps {
            let (a, b) = (here.step(step, steps).await.expect("here"), ahead.step(step, steps).await.expect("ahead"));
            assert!(a.robots.iter().flatten().any(|s| s.frame.is_some()), "step {step} has frames");
            assert_eq!(bits(&a), bits(&b), "step {step}");
        }
        let (a, b) = (here.finish().expect("here"), ahead.finish().expect("ahead"));
        let counts = |s: &SensorState| s.robots.iter().map(|r| (r.frames, r.raw_bytes)).collect::<Vec<_>>();
        assert_eq!(counts(&a), counts(&b));
        assert_eq!(a.world.solids.len(), b.world.solids.len());
    }

    #[actix_rt::test]
    async fn a_step_out_of_turn_is_an_error_not_wrong_frames() {
        let mut scenario = Scenario::load("quickstart").expect("library scenario");
        scenario.scenario.duration_s = 4.0 * scenario.scenario.frame_interval_s;
        let two = Threads::exactly(NonZeroUsize::new(2).expect("two"));
        let mut ahead = Sensors::start(SensorState::of(&scenario).expect("sensors"), two).expect("ahead");
        ahead.step(1, 4).await.expect("first");
        let error = ahead.step(3, 4).await.err().expect("step 2 comes first");
        assert!(error.to_string().contains("handed step 2 back for step 3"), "{error}");
    }
}
