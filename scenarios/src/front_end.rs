//! The odometry front end (`sgm_model::odometry::estimator`) alone on a scenario's simulated
//! sensors: one robot's timed LiDAR sweeps (through its mount, as its driver reports them) and
//! IMU samples, built as the runner builds them, go through the estimator frame by frame; the
//! truth and the scenario's synthetic odometry (`[odometry]`'s noise model) are kept beside each
//! estimate, so that `sgm bench odometry` can set the two against each other. The IMU is
//! simulated with the scenario's `[imu]` noise whether or not the scenario turns it on (the
//! internal front end needs it); the estimator is told the same densities.

use crate::bag_out::{BagRecorder, RecordedFrame};
use crate::scenario::Scenario;
use crate::sim::imu::Imu;
use crate::sim::lidar::Lidar;
use crate::sim::mount::LidarMount;
use crate::sim::odometry::Odometry;
use crate::sim::setup::{sweep_in_body, SimulatedWorld};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use sgm_model::geometry::Pose3;
use sgm_model::odometry::config::OdometryConfig;
use sgm_model::odometry::estimator::{LidarInertialOdometry, OdometryCounts, ScanOutcome};
use sgm_model::odometry::propagation::ImuNoise;
use std::time::{Duration, Instant};

/// One frame: the stamp, the estimate (None: refused), the truth and the synthetic odometry.
#[derive(Clone, Debug)]
pub struct FrontEndFrame {
    pub t: f64,
    pub estimate: Option<Pose3>,
    /// The filter's up and attitude in its own frame (`OdometryEstimate::measured_up`).
    pub measured_up: Option<sgm_model::geometry::up::MeasuredUp>,
    pub outcome: Option<ScanOutcome>,
    pub truth: Pose3,
    pub synthetic: Pose3,
}

/// A robot's run of the front end.
#[derive(Clone, Debug)]
pub struct FrontEndRun {
    pub robot: String,
    pub frames: Vec<FrontEndFrame>,
    pub counts: OdometryCounts,
    /// Time in the estimator (not in simulating) per frame it took.
    pub time_per_frame: Duration,
    pub points_per_frame: f64,
}

/// The estimator's IMU noise: the scenario's.
pub fn imu_noise(scenario: &Scenario) -> ImuNoise {
    scenario.odometry_section().estimator.imu
}

#[derive(Debug, thiserror::Error)]
pub enum FrontEndError {
    #[error("the scenario has {robots} robots: there is no robot {index}")]
    NoSuchRobot { robots: usize, index: usize },
    #[error(transparent)]
    Config(#[from] sgm_model::odometry::config::OdometryConfigError),
    #[error(transparent)]
    Output(#[from] crate::output_error::OutputError),
}

/// Runs the front end on robot `k` of `scenario` for its whole mission (or `seconds`), a sweep
/// every `frame_interval_s` (default: the scenario's; a LiDAR's 10 Hz is 0.1).
pub fn run_front_end(
    scenario: &Scenario,
    k: usize,
    config: &OdometryConfig,
    seconds: Option<f64>,
    frame_interval_s: Option<f64>,
) -> Result<FrontEndRun, FrontEndError> {
    run_front_end_recording(scenario, k, config, seconds, frame_interval_s, None)
}

/// [`run_front_end`], and every sweep it takes, with its points' times, the IMU's samples, the
/// synthetic odometry and the truth, written to `bag_dir/NAME.bag` as `sgm run --bag-out`
/// writes them (for another odometry to run on the same data: `benches/compare_kiss_icp.sh`).
pub fn run_front_end_recording(
    scenario: &Scenario,
    k: usize,
    config: &OdometryConfig,
    seconds: Option<f64>,
    frame_interval_s: Option<f64>,
    bag_dir: Option<&std::path::Path>,
) -> Result<FrontEndRun, FrontEndError> {
    if k >= scenario.robots.len() {
        return Err(FrontEndError::NoSuchRobot { robots: scenario.robots.len(), index: k });
    }
    let seed = scenario.scenario.seed;
    let SimulatedWorld { routes, mut world, people } = SimulatedWorld::of(scenario);
    let route = &routes[k];
    let mut lidar = Lidar::new(&scenario.lidar);
    let mount = LidarMount::new(&scenario.lidar, seed, k);
    let mut imu = Imu::new(&scenario.imu, seed, k);
    let mut imu_rng = ChaCha8Rng::seed_from_u64(seed.wrapping_mul(0x2545_F491_4F6C_DD1D) ^ (k as u64 + 1));
    let mut rng = ChaCha8Rng::seed_from_u64(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ (k as u64 + 1));
    let mut synthetic = Odometry::new(&scenario.odometry);
    let mut estimator = LidarInertialOdometry::new(OdometryConfig { imu: imu_noise(scenario), ..config.clone() })?;
    let dt = frame_interval_s.unwrap_or(scenario.scenario.frame_interval_s);
    let duration = seconds.map_or(scenario.scenario.duration_s, |s| s.min(scenario.scenario.duration_s));
    let steps = (duration / dt).round() as u64;
    let sweep_s = scenario.lidar.sweep_s;
    let (mut frames, mut estimator_time, mut points) = (Vec::new(), Duration::ZERO, 0usize);
    let names = (0..scenario.robots.len()).map(|j| scenario.robot_name(j)).collect();
    let mut recorder = match bag_dir {
        Some(dir) => Some(BagRecorder::new(dir, &scenario.ros, names)?.with_imu(&scenario.imu)),
        None => None,
    };
    for step in 1..=steps {
        let t = step as f64 * dt;
        let Some(truth) = route.pose_at(t) else { continue };
        people.place(&mut world, t);
        let odometry = synthetic.step(&truth, &mut rng);
        let samples = imu.samples_until(t + sweep_s, &|s| route.pose_at(s), &mut imu_rng);
        let mut frame = sweep_in_body(&mut lidar, &mount, &world, route, t, &truth, &mut rng);
        if let Some(told) = mount.as_told(&frame.points) {
            frame.points = told;
        }
        let times = (!frame.times.is_empty()).then_some(&frame.times[..]);
        if let Some(recorder) = recorder.as_mut() {
            let recorded = RecordedFrame {
                t,
                odometry: &odometry,
                truth: &truth,
                points: &frame.points,
                labels: None,
                image: None,
                times,
                imu: &samples,
            };
            recorder.record(k, recorded)?;
        }
        points += frame.points.len();
        let started = Instant::now();
        estimator.push_imu(&samples);
        let result = estimator.process_scan(t, &frame.points, times);
        estimator_time += started.elapsed();
        let (estimate, measured_up, outcome) = match result {
            Ok(e) => (Some(e.odom_from_body), Some(e.measured_up), Some(e.outcome)),
            Err(_) => (None, None, None),
        };
        frames.push(FrontEndFrame { t, estimate, measured_up, outcome, truth, synthetic: odometry });
    }
    if let Some(recorder) = recorder {
        recorder.finish()?;
    }
    let taken = frames.iter().filter(|f| f.estimate.is_some()).count().max(1);
    Ok(FrontEndRun {
        robot: scenario.robot_name(k),
        points_per_frame: points as f64 / frames.len().max(1) as f64,
        frames,
        counts: estimator.counts(),
        time_per_frame: estimator_time / taken as u32,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn legged() -> Scenario {
        Scenario::load("legged_campus").expect("a library scenario")
    }

    #[test]
    fn the_front_end_is_deterministic_and_refuses_a_robot_that_is_not_there() {
        let scenario = legged();
        let config = OdometryConfig::default();
        let a = run_front_end(&scenario, 0, &config, Some(1.5), Some(0.1)).expect("runs");
        let b = run_front_end(&scenario, 0, &config, Some(1.5), Some(0.1)).expect("runs");
        assert_eq!(a.frames.len(), 15);
        // Gravity needs a second of samples (`level_window_s`); every sweep after is taken.
        let taken: Vec<bool> = a.frames.iter().map(|f| f.estimate.is_some()).collect();
        assert_eq!(taken, (1..=15).map(|k| k >= 10).collect::<Vec<_>>());
        let poses = |r: &FrontEndRun| r.frames.iter().map(|f| f.estimate).collect::<Vec<_>>();
        assert_eq!(poses(&a), poses(&b));
        assert_eq!(a.counts, b.counts);
        let robots = scenario.robots.len();
        assert!(matches!(
            run_front_end(&scenario, robots, &config, Some(1.0), None),
            Err(FrontEndError::NoSuchRobot { index, .. }) if index == robots
        ));
    }
}
