//! `sgm odometry --bag FILE`: SGM's LiDAR-inertial odometry alone on one robot's ROS 1 bag.
//!
//! The bag's clouds (`ros.topics.points`, with their points' times when the cloud has a time
//! field) and IMU samples (`ros.topics.imu`, in `ros.frames.imu`) are read by the replay's
//! reader and checks; the clouds come into the body frame through the LiDAR's mount (pinned by
//! `ros.body_from_lidar`, or from the bag's tf), the samples through the IMU's
//! (`ros.body_from_imu`, or tf; `convert::imu::sample_in_body`). Samples wait, in the IMU's
//! frame, until its mount is known. A cloud is registered once the IMU has passed
//! the end of its sweep (its stamp plus its latest point's time), or at the end of the bag: the
//! IMU samples of the whole sweep are in the filter when it deskews. Stamps are mission time,
//! seconds after the whole second of the bag's first message, as in `sgm replay`; the
//! trajectory is written with ROS times.

use sgm_bridge::bag::reader::{read_bag, BagError, BagItem, BagSource};
use sgm_bridge::config::RosConfigError;
use sgm_bridge::convert::cloud::Scan;
use sgm_bridge::convert::imu::{sample_in_body, ImuReading};
use sgm_bridge::convert::time::Epoch;
use sgm_bridge::inputs::{Inputs, Payload};
use sgm_bridge::node::NodeConfig;
use sgm_bridge::sync::MAX_IMU_BUFFERED;
use sgm_bridge::tf::listener::TfListener;
use sgm_bridge::tf::mounts::Mount;
use sgm_model::geometry::Pose3;
use sgm_model::odometry::config::OdometryConfigError;
use sgm_model::odometry::estimator::{LidarInertialOdometry, OdometryCounts};
use sgm_model::perception::deskew::sweep_end_s;
use sgm_model::perception::imu::ImuSample;
use sgm_model::scene_graph::Stamp;
use std::collections::{BTreeMap, VecDeque};
use std::path::Path;
use std::time::{Duration, Instant};

/// Clouds waiting for the IMU to pass their sweep's end, at most (the oldest is registered
/// with what there is).
const MAX_WAITING_CLOUDS: usize = 20;

#[derive(Debug, thiserror::Error)]
pub enum BagOdometryError {
    #[error(transparent)]
    Bag(#[from] BagError),
    #[error("odometry.estimator: {0}")]
    Config(#[from] OdometryConfigError),
    #[error("ros: {0}")]
    Ros(#[from] RosConfigError),
    #[error("the bag has no cloud on {topic}")]
    NoClouds { topic: String },
    #[error("the bag has no IMU sample on {topic} (the odometry needs one; is ros.topics.imu right?)")]
    NoImu { topic: String },
}

/// The odometry's estimate at one cloud.
#[derive(Clone, Debug)]
pub struct BagPose {
    /// The cloud's stamp, mission time (`BagOdometry::epoch` gives its ROS time).
    pub stamp: Stamp,
    pub odom_from_body: Pose3,
}

#[derive(Clone, Debug, Default)]
pub struct BagOdometry {
    /// Mission time 0 in ROS time: the whole second of the bag's first cloud or IMU sample.
    pub epoch: Option<Epoch>,
    pub poses: Vec<BagPose>,
    pub counts: OdometryCounts,
    /// Messages refused by the input checks, per input, and the last reason.
    pub refused: BTreeMap<&'static str, (u64, String)>,
    /// Clouds registered without the IMU reaching their sweep's end (a gap, or too many waiting).
    pub registered_early: u64,
    /// Clouds left out: the LiDAR's mount was neither pinned nor in the bag's tf (yet).
    pub no_lidar_mount: u64,
    /// IMU samples left out: the IMU's mount was neither pinned nor in the bag's tf (yet).
    pub no_imu_mount: u64,
    /// The estimator's time per cloud.
    pub time_per_cloud: Duration,
}

struct Run {
    estimator: LidarInertialOdometry,
    epoch: Option<Epoch>,
    /// The LiDAR's and the IMU's mounts.
    mounts: TfListener,
    /// IMU samples waiting for the IMU's mount, in its frame (bounded as the synchroniser's).
    imu_waiting: VecDeque<(Stamp, ImuReading)>,
    /// Clouds waiting for the IMU, with the stamp their sweep ends at.
    waiting: VecDeque<(Stamp, Stamp, Scan)>,
    newest_imu: Option<Stamp>,
    out: BagOdometry,
    spent: Duration,
    clouds: u64,
    imu_samples: u64,
}

impl Run {
    /// Registers the waiting clouds whose sweeps the IMU has passed (all of them at the end).
    fn register_ready(&mut self, all: bool) {
        while let Some(&(_, end, _)) = self.waiting.front() {
            let covered = self.newest_imu.is_some_and(|n| n >= end);
            let crowded = self.waiting.len() > MAX_WAITING_CLOUDS;
            if !(covered || all || crowded) {
                return;
            }
            if !covered {
                self.out.registered_early += 1;
            }
            let Some((stamp, _, scan)) = self.waiting.pop_front() else { return };
            self.register(stamp, scan);
        }
    }

    fn register(&mut self, stamp: Stamp, scan: Scan) {
        let Some(body_from_lidar) = self.mounts.body_from_lidar() else {
            self.out.no_lidar_mount += 1;
            return;
        };
        let points: Vec<_> = if body_from_lidar == Pose3::identity() {
            scan.points
        } else {
            scan.points.iter().map(|p| body_from_lidar * p).collect()
        };
        self.clouds += 1;
        let started = Instant::now();
        let result = self.estimator.process_scan(stamp, &points, scan.times.as_deref());
        self.spent += started.elapsed();
        if let Ok(estimate) = result {
            self.out.poses.push(BagPose { stamp, odom_from_body: estimate.odom_from_body });
        }
    }

    fn imu(&mut self, stamp: Stamp, reading: ImuReading) {
        self.imu_samples += 1;
        // The mount known and nothing waiting (the usual case): straight into the estimator.
        if let (true, Some(body_from_imu)) = (self.imu_waiting.is_empty(), self.mounts.body_from_imu()) {
            self.newest_imu = Some(self.newest_imu.map_or(stamp, |n| n.max(stamp)));
            self.estimator.push_imu(&[sample_in_body(stamp, &reading, &body_from_imu)]);
            return;
        }
        if self.imu_waiting.len() == MAX_IMU_BUFFERED {
            self.imu_waiting.pop_front();
            self.out.no_imu_mount += 1;
        }
        self.imu_waiting.push_back((stamp, reading));
        self.pass_imu();
    }

    /// The waiting IMU samples into the estimator, once the IMU's mount is known.
    fn pass_imu(&mut self) {
        let Some(body_from_imu) = self.mounts.body_from_imu() else { return };
        let samples: Vec<ImuSample> =
            self.imu_waiting.drain(..).map(|(t, reading)| sample_in_body(t, &reading, &body_from_imu)).collect();
        if let Some(last) = samples.last() {
            self.newest_imu = Some(self.newest_imu.map_or(last.stamp, |n| n.max(last.stamp)));
        }
        self.estimator.push_imu(&samples);
    }
}

/// Runs the odometry of robot `config` (its `odometry.estimator`, whatever its
/// `odometry.source`) on the bag at `path`.
pub fn odometry_on_bag(path: &Path, config: &NodeConfig) -> Result<BagOdometry, BagOdometryError> {
    let (robot, id) = (config.robot.robot.name.as_str(), config.robot.robot.id);
    let inputs = Inputs::new(&config.ros, robot, id);
    let body = inputs.body_frame().to_string();
    let lidar = Mount::new("lidar", "ros.body_from_lidar", &body, inputs.lidar_frame(), config.ros.lidar_pin()?);
    let camera = Mount::new("camera", "ros.body_from_camera", &body, inputs.camera_frame(), config.ros.camera_pin()?);
    let imu = Mount::new("imu", "ros.body_from_imu", &body, inputs.imu_frame(), config.ros.imu_pin()?);
    let mut run = Run {
        estimator: LidarInertialOdometry::new(config.robot.odometry.estimator.clone())?,
        epoch: None,
        mounts: TfListener::new(config.ros.tf.clone(), inputs.world_frame(), &body, camera, lidar).with_imu(imu),
        imu_waiting: VecDeque::new(),
        waiting: VecDeque::new(),
        newest_imu: None,
        out: BagOdometry::default(),
        spent: Duration::ZERO,
        clouds: 0,
        imu_samples: 0,
    };
    let source = BagSource::new(&config.ros, robot, id).with_imu();
    for item in read_bag(path, source) {
        match item {
            BagItem::Message { payload: Payload::Cloud(time, scan), .. } => {
                let epoch = *run.epoch.get_or_insert_with(|| Epoch::at(time));
                let stamp = epoch.stamp(time);
                run.waiting.push_back((stamp, stamp + sweep_end_s(scan.times.as_deref()), scan));
            }
            BagItem::Message { payload: Payload::Imu(time, reading), .. } => {
                let epoch = *run.epoch.get_or_insert_with(|| Epoch::at(time));
                run.imu(epoch.stamp(time), reading);
            }
            BagItem::Message { payload: Payload::Tf(batch), .. } => {
                let epoch = run.epoch.unwrap_or(Epoch { sec: 0 });
                run.mounts.feed(batch, |t| epoch.stamp(t));
                run.pass_imu();
            }
            BagItem::Message { .. } => {}
            BagItem::Refused { input, error, .. } => {
                let entry = run.out.refused.entry(input).or_insert((0, String::new()));
                *entry = (entry.0 + 1, error.to_string());
            }
            BagItem::Failed(e) => return Err(e.into()),
        }
        run.register_ready(false);
    }
    run.register_ready(true);
    run.out.no_imu_mount += run.imu_waiting.len() as u64;
    let topics = &config.ros.topics;
    if run.clouds == 0 && run.out.no_lidar_mount == 0 && !run.out.refused.contains_key("points") {
        return Err(BagOdometryError::NoClouds {
            topic: sgm_bridge::config::RosConfig::resolve(&topics.points, robot, id),
        });
    }
    if run.imu_samples == 0 {
        return Err(BagOdometryError::NoImu { topic: sgm_bridge::config::RosConfig::resolve(&topics.imu, robot, id) });
    }
    run.out.counts = run.estimator.counts();
    run.out.epoch = run.epoch;
    run.out.time_per_cloud = run.spent / (run.clouds.max(1) as u32);
    Ok(run.out)
}
