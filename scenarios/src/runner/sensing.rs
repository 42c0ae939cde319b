//! One step of one robot's sensors: its odometry, the unlabelled sweeps between two frames
//! (internal odometry), the IMU, and the labelled frame with its segmentation or label image.
//! Each robot draws only from its own random streams and reads the world without changing it,
//! so the robots' steps are simulated at once ([`sense_all`], on `threads` threads) and give the
//! same frames in any order.

use crate::record::RAW_BYTES_PER_POINT;
use crate::scenario::{CameraSpec, Scenario};
use crate::sim::camera::{mislabels, noisy_labels, render, CameraMount};
use crate::sim::imu::Imu;
use crate::sim::lidar::Lidar;
use crate::sim::mount::LidarMount;
use crate::sim::odometry::Odometry;
use crate::sim::segmenter_errors::SegmenterErrors;
use crate::sim::setup::sweep_in_body;
use crate::sim::trajectory::Route;
use crate::sim::world::{World, NO_LABEL};
use nalgebra::Point3;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use sgm_actors::messages::FrameLabels;
use sgm_model::geometry::Pose3;
use sgm_model::perception::imu::ImuSample;
use sgm_model::perception::projection::CameraModel;
use sgm_model::scene_graph::{stamp_from_nanos, LabelId, Stamp};

pub(super) struct SimRobot {
    pub name: String,
    pub route: Route,
    pub odometry: Odometry,
    pub lidar: Lidar,
    pub lidar_mount: LidarMount,
    pub camera: CameraMount,
    /// `[imu]`: the IMU and its own noise stream (the other sensors' draws do not depend on it).
    pub imu: Option<(Imu, ChaCha8Rng)>,
    pub rng: ChaCha8Rng,
    /// The segmenter's errors (`[segmentation]`), apart from `rng` so that with them off the
    /// run is the same.
    pub segmenter_rng: ChaCha8Rng,
    /// The unlabelled sweeps' range noise (internal odometry), apart from `rng` likewise.
    pub sweep_rng: ChaCha8Rng,
    pub frames: u64,
    pub raw_bytes: u64,
    pub raw_max_bytes: u64,
}

/// What every robot's sensors share, at every step.
pub(super) struct Sensing {
    pub scenario: Scenario,
    pub segmenter_errors: Option<SegmenterErrors>,
    pub camera: CameraModel,
    /// Half-size of a return's splat in the label image, px.
    pub splat: i64,
    /// The configured segmenter's id for each of our classes (`None`: ours).
    pub pixel_values: Option<Vec<u16>>,
    pub dt_nanos: i64,
    pub sweep_nanos: i64,
    /// Sweeps per frame (internal odometry; 1: none between frames).
    pub sweeps_per_frame: i64,
}

/// One robot's step.
pub(super) struct Sensed {
    pub truth: Pose3,
    pub odometry: Pose3,
    /// Where the robot's odometry started, in the truth (set at its first step).
    pub truth_from_world: Pose3,
    /// Crashed and not yet restarted: nothing else was simulated.
    pub down: bool,
    pub sweeps: Vec<Sweep>,
    pub frame: Option<Frame>,
}

/// An unlabelled sweep between two frames, as the driver hands it on.
pub(super) struct Sweep {
    pub stamp: Stamp,
    pub points: Vec<Point3<f64>>,
    pub times: Option<Vec<f32>>,
    pub imu: Vec<ImuSample>,
}

/// The labelled frame, as the driver hands it on.
pub(super) struct Frame {
    /// Through the mount the robot is told.
    pub points: Vec<Point3<f64>>,
    pub times: Option<Vec<f32>>,
    pub labels: FrameLabels,
    /// The per-point ids as recorded (camera off).
    pub recorded_labels: Option<Vec<u16>>,
    pub imu: Vec<ImuSample>,
}

impl Sensing {
    /// Every robot's step `step` (at `t`) in `world`, on `pool` if any; `None` for a robot that
    /// is not on (before its start or after its route).
    pub fn sense_all(
        &self,
        world: &World,
        robots: &mut [SimRobot],
        step: u64,
        t: Stamp,
        pool: Option<&rayon::ThreadPool>,
    ) -> Vec<Option<Sensed>> {
        let work = |(k, robot): (usize, &mut SimRobot)| self.sense(world, robot, k, step, t);
        match pool {
            Some(pool) => pool.install(|| robots.par_iter_mut().enumerate().map(work).collect()),
            None => robots.iter_mut().enumerate().map(work).collect(),
        }
    }

    fn sense(&self, world: &World, robot: &mut SimRobot, k: usize, step: u64, t: Stamp) -> Option<Sensed> {
        let scenario = &self.scenario;
        let truth = robot.route.pose_at(t)?;
        let odometry = robot.odometry.step(&truth, &mut robot.rng);
        let spec = scenario.robots.get(k)?;
        let crashed = spec.crash_s.is_some_and(|c| t >= c);
        if crashed && spec.restart_s.is_none_or(|r| t < r) {
            let truth_from_world = robot.odometry.truth_from_world;
            return Some(Sensed { truth, odometry, truth_from_world, down: true, sweeps: Vec::new(), frame: None });
        }
        let route = &robot.route;
        // The sweeps between the last frame and this one, for the internal odometry.
        let mut sweeps = Vec::new();
        for j in 1..self.sweeps_per_frame {
            let s = stamp_from_nanos((step as i64 - 1) * self.dt_nanos + j * self.sweep_nanos);
            let Some(truth_s) = route.pose_at(s) else { continue };
            let imu = match robot.imu.as_mut() {
                Some((imu, rng)) => imu.samples_until(s + scenario.lidar.sweep_s, &|u| route.pose_at(u), rng),
                None => Vec::new(),
            };
            let mount = robot.lidar_mount;
            let sweep = sweep_in_body(&mut robot.lidar, &mount, world, route, s, &truth_s, &mut robot.sweep_rng);
            let points = mount.as_told(&sweep.points).unwrap_or(sweep.points);
            let times = (!sweep.times.is_empty()).then_some(sweep.times);
            sweeps.push(Sweep { stamp: s, points, times, imu });
        }
        // A driver hands on a sweep once it ends: the IMU has sampled it by then.
        let imu = match robot.imu.as_mut() {
            Some((imu, rng)) => imu.samples_until(t + scenario.lidar.sweep_s, &|s| route.pose_at(s), rng),
            None => Vec::new(),
        };
        let mount = robot.lidar_mount;
        let mut frame = sweep_in_body(&mut robot.lidar, &mount, world, route, t, &truth, &mut robot.rng);
        if let Some(errors) = &self.segmenter_errors {
            errors.apply(&mut frame, &truth, &mut robot.segmenter_rng);
        }
        let wrong = mislabels(&frame, scenario.camera.mislabel_rate, &world.matchable_labels, &mut robot.rng);
        let as_pixel =
            |id: u16| self.pixel_values.as_deref().map_or(id, |v| v.get(usize::from(id)).copied().unwrap_or(NO_LABEL));
        let (labels, recorded_labels) = if scenario.camera.enabled {
            let shot = camera_shot(&scenario.camera, robot.camera.camera_from_body, route, t, &truth);
            let mut image = render(&scenario.camera, &frame, &wrong, self.splat, &shot, &mut robot.rng);
            if self.pixel_values.is_some() {
                image.labels.iter_mut().for_each(|l| *l = as_pixel(*l));
            }
            let labels = FrameLabels::Image {
                image,
                camera: self.camera.clone(),
                camera_from_body: robot.camera.configured_camera_from_body,
                image_offset_s: scenario.camera.exposure_offset_s + scenario.camera.clock_offset_s,
            };
            (labels, None)
        } else {
            let labels: Vec<u16> = noisy_labels(&frame, &wrong).into_iter().map(as_pixel).collect();
            let per_point = labels.iter().map(|&l| (l != NO_LABEL).then_some(LabelId(l))).collect();
            (FrameLabels::PerPoint(per_point), Some(labels))
        };
        robot.frames += 1;
        let raw = frame.points.len() as u64 * RAW_BYTES_PER_POINT;
        robot.raw_bytes += raw;
        robot.raw_max_bytes = robot.raw_max_bytes.max(raw);
        // What the robot's driver hands on: the returns through the mount it is told.
        let points = mount.as_told(&frame.points).unwrap_or(frame.points);
        let times = (!frame.times.is_empty()).then_some(frame.times);
        let frame = Frame { points, times, labels, recorded_labels, imu };
        let truth_from_world = robot.odometry.truth_from_world;
        Some(Sensed { truth, odometry, truth_from_world, down: false, sweeps, frame: Some(frame) })
    }
}

/// The camera at its exposure (`exposure_offset_s` after the stamp `t`) from the body at τ
/// after `t` (a return's time): `camera_from_body · B(t + e)⁻¹ · B(t + τ)`, the true poses of
/// `route` (`truth`, the pose at `t`, where the route has none).
fn camera_shot<'a>(
    spec: &CameraSpec,
    camera_from_body: Pose3,
    route: &'a Route,
    t: Stamp,
    truth: &'a Pose3,
) -> impl Fn(f32) -> Pose3 + 'a {
    let exposure = spec.exposure_offset_s;
    let at = move |s: Stamp| route.pose_at(s).unwrap_or(*truth);
    let body_at_exposure = (exposure != 0.0).then(|| at(t + exposure).inverse());
    move |tau: f32| match (body_at_exposure, tau == 0.0) {
        (None, true) => camera_from_body,
        (None, false) => camera_from_body * truth.inverse() * at(t + f64::from(tau)),
        (Some(inverse), _) => camera_from_body * inverse * at(t + f64::from(tau)),
    }
}
