//! The LiDAR-inertial odometry: an error-state filter whose prediction is IMU propagation and
//! whose correction is scan-to-map registration held by that prediction. Per scan at stamp t:
//!
//! 1. **Predict** (`propagation`, `imu_queue`): the state and covariance from the last scan's
//!    time to t over the samples that arrived; across a gap the last sample is held, with the
//!    larger `coast` noise.
//! 2. **Deskew** (`perception::deskew`): each point at t + τ moved into the body at t by the
//!    predicted motion, T(t)⁻¹ T(t + τ), over the samples of the sweep (FAST-LIO2's backward
//!    propagation, forwards).
//! 3. **Register** (`registration`): the scan (voxel `scan_voxel_m`) onto the local map from
//!    the prediction, with the prediction as a prior of information (N P_aa Nᵀ)⁻¹ scaled by σ²
//!    (the scan's residuals carry weight 1/σ², the prior its own), within the adaptive threshold
//!    (`threshold`), which never goes below what the points' own noise produces: τ ≥ 3σ and
//!    the kernel κ ≥ σ (an IMU predicts to millimetres, and a threshold learnt from that alone
//!    would refuse every honest residual and give the scan no weight against the prior). The result is the pose's maximum a posteriori: in a direction the scan does
//!    not constrain (a corridor's axis, an open field's plane), the prior decides — the
//!    degeneracy is reported, and the IMU carries the estimate there.
//! 4. **Update** (`update`): the registered pose and the scan's information Hᵀ/σ² correct the
//!    velocity and biases through their correlation with the pose.
//! 5. **Map**: the deskewed scan (one measured point per voxel of `map_voxel_m`, as the scan
//!    registered is one per `scan_voxel_m`) enters the local map at the new pose.
//!
//! **A jolt beyond the IMU's range** (a kerb struck, a stumble): its samples are used clipped
//! (`imu_queue`), the excess beyond the range becomes uncertainty of what the sensor integrates
//! (`saturated_noise`), the velocity is decorrelated from the pose (`decorrelate_velocity`),
//! and the first scan after it is registered within 3σ of the predicted position.
//!
//! Nothing from outside can make it publish a NaN: a scan whose stamp does not advance is
//! refused unstored; a scan with no usable points, a registration that fails or that would move
//! the prediction by more than `max_correction_*`, or an update that is not well posed leaves
//! the prediction standing (coasting, counted with the reason); a state that is not finite or
//! faster than `max_speed_mps` is reset to the last registered one (velocity unknown again),
//! and says so. The filter starts once `level_min_samples` IMU samples give gravity (scans
//! before are refused): the odometry frame is the body's first pose, levelled, yaw zero, and
//! what it publishes is that frame turned about its origin to the up it has learnt since, once
//! that differs significantly (`propagation`: up is part of the state; `publish_up`). There
//! is no LiDAR-only mode: without the IMU's prediction, a legged robot's 4 Hz bounce defeats
//! the constant-velocity deskew and the threshold (KISS-ICP is the reference for that case,
//! `sgm bench odometry`).

use super::clone::PoseClone;
use super::config::OdometryConfig;
use super::imu_queue::{coasting_sample, ImuCounts, ImuLimits, ImuQueue, Saturation, Track};
use super::local_map::LocalMap;
use super::propagation::{ImuNoise, Matrix17, NavState, Propagator, STATE_DIM, UP};
use nalgebra::SMatrix;

/// Where δb_a starts in the error state; δu follows it (`up_prior` sets the two as one block).
const ACCEL_BIAS: usize = 12;
const _: () = assert!(super::propagation::UP == ACCEL_BIAS + 3);
/// The largest σ of up's tilt a moving start is given, rad (6°).
const MAX_MOVING_TILT_SIGMA_RAD: f64 = 0.1;
use super::registration::{register_scan, Degeneracy, Prior, RegistrationError};
use super::threshold::AdaptiveThreshold;
use super::update::{apply_pose_update, pose_covariance, pose_of, prior_information, scan_information, UpdateError};
use crate::geometry::lie::Matrix6;
use crate::geometry::up::MeasuredUp;
use crate::geometry::Pose3;
use crate::perception::deskew::{deskew_with, sweep_end_s, DeskewRefusal};
use crate::perception::imu::ImuSample;
use crate::spatial::voxel::downsample_first;
use nalgebra::{Point3, Vector3};
use serde::{Deserialize, Serialize};

/// Why a scan was refused (nothing about it was stored).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ScanRefusal {
    #[error("the scan's stamp {0} is not finite")]
    NonFiniteStamp(f64),
    #[error("the scan's stamp {stamp} is not after the last scan's {previous}")]
    NotAfterPrevious { stamp: f64, previous: f64 },
    #[error(
        "waiting for the IMU to find gravity: it needs samples over the {window_s} s before the first scan (at \
         least {needed} of them, spanning 90 % of the window, steady enough to level on); {samples} are waiting"
    )]
    WaitingForImu { samples: usize, needed: usize, window_s: f64 },
}

/// Why the prediction was kept instead of the scan's correction.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum CoastReason {
    #[error("no usable point in the scan")]
    NoPoints,
    #[error("registration failed: {0}")]
    Registration(RegistrationError),
    #[error("registration moved the prediction by {moved_m:.2} m and {turned_rad:.3} rad, more than allowed")]
    Implausible { moved_m: f64, turned_rad: f64 },
    #[error("update refused: {0}")]
    Update(UpdateError),
}

/// What happened to a scan.
#[derive(Clone, Debug, PartialEq)]
pub enum ScanOutcome {
    /// The filter started here: the scan is the local map's first.
    First,
    Registered {
        /// The scan's points registered (one per `scan_voxel_m`), and those of them that found
        /// a surface of the map within the threshold.
        points: usize,
        correspondences: usize,
        iterations: usize,
        converged: bool,
    },
    Coasted(CoastReason),
    /// The state diverged (not finite, or faster than allowed) and was reset to the last
    /// registered one.
    Reset {
        speed_mps: f64,
    },
}

/// The estimate at a scan.
#[derive(Clone, Debug)]
pub struct OdometryEstimate {
    pub stamp: f64,
    pub odom_from_body: Pose3,
    /// Odometry frame, m/s.
    pub velocity: Vector3<f64>,
    /// Cov of e = Log(T̂⁻¹ T), (ω, v), in the body frame.
    pub covariance: Matrix6,
    /// Cov of the motion since the scan [`LidarInertialOdometry::mark`] last marked (`clone`):
    /// e_Δ with Δ = T_mark⁻¹ T = Δ̂ Exp(e_Δ), (ω, v), in the body frame now. `None` before the
    /// first mark and after a reset.
    pub motion_covariance: Option<Matrix6>,
    /// Every point of the scan (same order, non-finite ones as they came), in the body at the
    /// stamp: deskewed when `deskew` is Ok.
    pub points_in_body: Vec<Point3<f64>>,
    pub deskew: Result<(), DeskewRefusal>,
    pub outcome: ScanOutcome,
    /// What the scan left unconstrained, when it was registered.
    pub degeneracy: Option<Degeneracy>,
    pub gyro_bias: Vector3<f64>,
    pub accel_bias: Vector3<f64>,
    /// Up (against gravity) in the filter's own frame (the published frame is that frame
    /// turned so that the last up it followed is ẑ): ẑ but for what the levelling got wrong.
    pub up: Vector3<f64>,
    /// The body's attitude in the filter's own frame and up in that frame with its σ (the worse
    /// horizontal axis of δu's covariance): the published pose's R_Pᵀ ẑ follows the filter's up
    /// only once the two part by more than 3σ (the frame's turns), so keyframes' gravity priors
    /// are made from this, each held to the latest up (the pose graph's gravity priors).
    pub measured_up: MeasuredUp,
}

/// Counts over the run, for status and the report.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct OdometryCounts {
    /// Scans that produced an estimate.
    pub scans: u64,
    pub refused: u64,
    pub registered: u64,
    pub coasted: u64,
    /// Of the registered, those with a weak direction.
    pub degenerate: u64,
    /// Of the registered, those of whose points fewer than `min_overlap` found a surface of the
    /// map.
    #[serde(default)]
    pub low_overlap: u64,
    pub resets: u64,
    pub not_deskewed: u64,
    pub imu: ImuCounts,
    /// Times the published frame was turned to the filter's up (`publish_up`).
    #[serde(default)]
    pub frame_turns: u64,
}

#[derive(Clone, Debug)]
struct Filter {
    time: f64,
    propagator: Propagator,
}

/// The odometry (module notes).
#[derive(Clone, Debug)]
pub struct LidarInertialOdometry {
    config: OdometryConfig,
    map: LocalMap,
    threshold: AdaptiveThreshold,
    imu: ImuQueue,
    filter: Option<Filter>,
    last_registered: Option<Filter>,
    counts: OdometryCounts,
    /// Where the first scan was taken, and whether the body has been farther than
    /// `START_RADIUS_M` from it since.
    start: Option<Vector3<f64>>,
    left_start: bool,
    /// The up the published frame is levelled to (`publish_up`), and what turning it since the
    /// last mark added to the published motion, as covariance ((ω, v), body frame).
    published_up: Vector3<f64>,
    frame_turn_since_mark: Matrix6,
}

/// The published frame follows the filter's up only once the two differ by more than this many
/// σ of up's own uncertainty (`publish_up`).
const REPUBLISH_SIGMAS: f64 = 3.0;

/// How far from its first pose the body must have been before scans of low overlap count, m.
const START_RADIUS_M: f64 = 1.0;

/// The process noise over a segment whose sample read at full scale, within `saturated_s` =
/// (gyro, accelerometer) seconds of such samples between two scans: the sensor that saturated
/// measured its value only up to the range, and the truth lies beyond by an amount nothing
/// bounds, so the range itself is taken as that excess's σ, one unknown over the whole jolt.
/// Its integral over the jolt adds (range · T)² to the variance of what the sensor integrates
/// (velocity, or attitude), T the saturated time, whatever the IMU's rate: a white density σ_s
/// over the jolt's segments adds σ_s² T, so σ_s² = σ² + range² T.
fn saturated_noise(noise: &ImuNoise, saturation: &Saturation, limits: &ImuLimits, saturated_s: (f64, f64)) -> ImuNoise {
    let widened = |density: f64, range: f64, t: f64| (density * density + range * range * t.max(0.0)).sqrt();
    ImuNoise {
        gyro_noise: if saturation.gyro {
            widened(noise.gyro_noise, limits.gyro_range_rad_s, saturated_s.0)
        } else {
            noise.gyro_noise
        },
        accel_noise: if saturation.accel {
            widened(noise.accel_noise, limits.accel_range_mps2, saturated_s.1)
        } else {
            noise.accel_noise
        },
        ..*noise
    }
}

/// The filter's frame turned about its origin so that `up` is ẑ (the smallest such turn; yaw
/// untouched to first order). The filter keeps its own frame — its map is in it — and learns
/// where up is within seconds of a swaying start; what it publishes is gravity-aligned, as the
/// matcher's 4-DoF transform needs (`LidarInertialOdometry::publish_up`).
fn levelled_from(up: &Vector3<f64>) -> Pose3 {
    let turn = nalgebra::UnitQuaternion::rotation_between(up, &Vector3::z())
        .unwrap_or_else(nalgebra::UnitQuaternion::identity);
    Pose3::from_parts(nalgebra::Translation3::identity(), turn)
}

/// The prior of (δb_a, δu) at start (module notes, "Gravity"). The odometry frame is the
/// levelled first pose R₀, levelled so that the mean force f̄ = R₀ᵀ g u + b_a reads ẑ:
/// a bias b_a leaves up at u ≈ ẑ − (R₀ b_a)_⊥ / g, i.e. δu = M δb_a with
/// M = [[0, 1, 0], [−1, 0, 0]] R₀ / g (u = Exp(B δu) ẑ ≈ ẑ + (δu_y, −δu_x, 0)), plus what the
/// levelling itself got wrong, independent, of variance `tilt_var`:
///
/// ```text
/// Cov(δb_a) = σ_a² I,   Cov(δu, δb_a) = σ_a² M,   Cov(δu) = σ_a² M Mᵀ + tilt_var I
/// ```
///
/// The two together explain the mean force whatever the bias; they part only when the body
/// turns, which is when a bias (turning with the body) and a tilt (staying with the frame)
/// stop reading the same.
fn up_prior(r0: &nalgebra::UnitQuaternion<f64>, accel_bias_var: f64, tilt_var: f64, g: f64) -> SMatrix<f64, 5, 5> {
    let m = SMatrix::<f64, 2, 3>::new(0.0, 1.0, 0.0, -1.0, 0.0, 0.0) * r0.to_rotation_matrix().into_inner() / g;
    let mut prior = SMatrix::<f64, 5, 5>::zeros();
    prior.fixed_view_mut::<3, 3>(0, 0).fill_diagonal(accel_bias_var);
    let cross = m * accel_bias_var;
    prior.fixed_view_mut::<2, 3>(3, 0).copy_from(&cross);
    prior.fixed_view_mut::<3, 2>(0, 3).copy_from(&cross.transpose());
    let uu = m * m.transpose() * accel_bias_var + nalgebra::Matrix2::identity() * tilt_var;
    prior.fixed_view_mut::<2, 2>(3, 3).copy_from(&uu);
    prior
}

/// After a jolt the IMU could not measure, the scan cannot tell how much of its correction the
/// jolt moved the body by and how much it changed its speed: a kerb stepped up is a
/// displacement with no speed left over, a stumble both. The velocity's correlation with the
/// pose (and the biases) is dropped, its own variance kept: the scan corrects where the body is,
/// and the next scans, through the correlation propagation builds again, how fast it moves.
/// Learnt instead from the one scan, the kerb of the tests' 0.26 m correction became 3.5 m/s
/// of climb, and the estimate rose through the ceiling.
/// The marked pose's cross-covariance with the velocity goes too (the clone is nearly the
/// current pose, and the joint covariance must stay positive semi-definite).
fn decorrelate_velocity(p: &mut Propagator) {
    for k in 6..9 {
        for j in (0..6).chain(9..STATE_DIM) {
            p.covariance[(k, j)] = 0.0;
            p.covariance[(j, k)] = 0.0;
        }
    }
    if let Some(clone) = &mut p.clone {
        clone.cross.fixed_view_mut::<3, 6>(6, 0).fill(0.0);
    }
}

fn finite_pose(pose: &Pose3) -> bool {
    pose.translation.vector.iter().chain(pose.rotation.coords.iter()).all(|c| c.is_finite())
}

fn finite_state(s: &NavState) -> bool {
    finite_pose(&pose_of(s))
        && s.velocity
            .iter()
            .chain(s.gyro_bias.iter())
            .chain(s.accel_bias.iter())
            .chain(s.up.iter())
            .all(|c| c.is_finite())
}

impl LidarInertialOdometry {
    pub fn new(config: OdometryConfig) -> Result<Self, super::config::OdometryConfigError> {
        config.validate()?;
        let mut map = LocalMap::new(config.local_map.clone()).map_err(|e| super::config::OdometryConfigError {
            key: format!("local_map.{}", e.key),
            value: e.value,
            allowed: e.allowed,
        })?;
        map.cache_planes(config.registration.plane_params());
        Ok(Self {
            threshold: AdaptiveThreshold::new(config.threshold.clone()),
            imu: ImuQueue::new(config.imu_limits),
            map,
            filter: None,
            last_registered: None,
            counts: OdometryCounts::default(),
            start: None,
            left_start: false,
            published_up: Vector3::z(),
            frame_turn_since_mark: Matrix6::zeros(),
            config,
        })
    }

    pub fn config(&self) -> &OdometryConfig {
        &self.config
    }

    pub fn counts(&self) -> OdometryCounts {
        OdometryCounts { imu: self.imu.counts(), ..self.counts }
    }

    pub fn local_map(&self) -> &LocalMap {
        &self.map
    }

    /// Marks the latest scan: later estimates carry the covariance of the motion since
    /// (`OdometryEstimate::motion_covariance`). Nothing to mark before the first scan.
    pub fn mark(&mut self) {
        if let Some(f) = &mut self.filter {
            f.propagator.clone = Some(PoseClone::of(&f.propagator.state, &f.propagator.covariance));
        }
        self.frame_turn_since_mark = Matrix6::zeros();
    }

    /// The published frame: the filter's turned about its origin so that `published_up` is ẑ.
    /// It follows the filter's up only when the two differ by more than `REPUBLISH_SIGMAS` of
    /// up's σ: every turn of it moves every published pose by it at once, and a turn at each
    /// scan by what the bias–tilt pair wandered (0.5° on `legged_campus` before the first
    /// turn) put that wander into every published motion; a swaying start's 2° is learnt, and
    /// published, within seconds. The turn is added to the motion's covariance since the mark
    /// (`frame_turn_since_mark`), as the error it is of the motion published across it.
    fn publish_up(&mut self, state: &NavState, covariance: &Matrix17) -> Pose3 {
        let sigma = covariance.fixed_view::<2, 2>(UP, UP).trace().max(0.0).sqrt();
        if self.published_up.angle(&state.up) > REPUBLISH_SIGMAS * sigma {
            let before = levelled_from(&self.published_up);
            self.published_up = state.up;
            self.counts.frame_turns += 1;
            let after = levelled_from(&self.published_up);
            // Exp(φ) P for the published pose P = L T: in P's body frame, (Rᵀφ, Rᵀ(φ × p)).
            let phi = (after * before.inverse()).rotation.scaled_axis();
            let published = after * pose_of(state);
            let r_t = published.rotation.inverse();
            let e = nalgebra::Vector6::from_iterator(
                (r_t * phi).iter().chain((r_t * phi.cross(&published.translation.vector)).iter()).copied(),
            );
            self.frame_turn_since_mark += e * e.transpose();
        }
        levelled_from(&self.published_up)
    }

    /// Takes IMU samples; bad ones are counted and dropped.
    pub fn push_imu(&mut self, samples: &[ImuSample]) {
        for s in samples {
            self.imu.push(s);
        }
    }

    /// The initial state and covariance at `stamp`, or why not yet.
    fn start(&self, stamp: f64) -> Result<Propagator, ScanRefusal> {
        let c = &self.config;
        let level = self.imu.level(stamp, c.level_window_s, c.level_min_samples, c.imu.gyro_noise).ok_or(
            ScanRefusal::WaitingForImu {
                samples: self.imu.waiting(),
                needed: c.level_min_samples,
                window_s: c.level_window_s,
            },
        )?;
        let (rotation, still, samples) = (level.rotation, level.still, level.samples);
        let gyro_bias = level.gyro_bias.unwrap_or_else(Vector3::zeros);
        // Still, the mean rate measured the gyro's bias to its white noise over the window
        // (σ/√T, T the window's duration: samples over the span they cover).
        let gyro_bias_variance = if still {
            let span = c.level_window_s.min(samples as f64 * 0.01).max(1e-3);
            (c.imu.gyro_noise.powi(2) / span).max(1e-10)
        } else {
            c.initial_gyro_bias_sigma_rad_s.powi(2)
        };
        let state = NavState { gyro_bias, ..NavState::at_rest(rotation, Vector3::zeros()) };
        // An IMU cannot tell rest from constant velocity, but a platform under way shakes its
        // IMU far beyond its noise: still, the body is at rest. Otherwise the velocity is
        // unknown, and the first scans measure it — where they can: along a corridor's axis an
        // unknown start velocity stays unknown, and was 0.1 m/s off in the tests' corridor.
        let velocity = if still { c.initial_still_velocity_sigma_mps } else { c.initial_velocity_sigma_mps }.powi(2);
        let mut p = Matrix17::zeros();
        for (k, v) in [
            1e-12,
            1e-12,
            1e-12,
            1e-12,
            1e-12,
            1e-12,
            velocity,
            velocity,
            velocity,
            gyro_bias_variance,
            gyro_bias_variance,
            gyro_bias_variance,
        ]
        .into_iter()
        .enumerate()
        {
            p[(k, k)] = v;
        }
        let g = c.imu.gravity_mps2;
        // Moving, the mean force is off gravity by the body's mean acceleration, which its
        // spread bounds; capped where δu's fixed basis stops being a small tilt (a gait's ±1 g
        // spread averages out over the window far better than that).
        let moving = if still { 0.0 } else { (level.force_spread_mps2 / g).min(MAX_MOVING_TILT_SIGMA_RAD) };
        let tilt = c.initial_tilt_sigma_rad.max(moving);
        let up = up_prior(&rotation, c.initial_accel_bias_sigma_mps2.powi(2), tilt.powi(2), g);
        p.fixed_view_mut::<5, 5>(ACCEL_BIAS, ACCEL_BIAS).copy_from(&up);
        Ok(Propagator::new(state, p, c.imu))
    }

    /// The filter propagated from its time to `to` (module notes, step 1), and whether a sample
    /// on the way read at full scale (a jolt: `saturated_noise`, `decorrelate_velocity`).
    fn predict(&self, filter: &Filter, to: f64) -> (Propagator, bool) {
        let mut p = filter.propagator.clone();
        let g = self.config.imu.gravity_mps2;
        let segments = self.imu.segments(filter.time, to);
        let saturated_s = |of: fn(&Saturation) -> bool| {
            segments.iter().filter(|s| of(&s.saturation)).map(|s| s.end - s.start).sum::<f64>()
        };
        let saturated_s = (saturated_s(|s| s.gyro), saturated_s(|s| s.accel));
        let jolted = saturated_s.0 > 0.0 || saturated_s.1 > 0.0;
        for segment in &segments {
            let sample =
                segment.sample.unwrap_or_else(|| coasting_sample(&p.state, g, segment.start, &Vector3::zeros()));
            let noise = if segment.gap { self.config.coast } else { self.config.imu };
            let noise = saturated_noise(&noise, &segment.saturation, &self.config.imu_limits, saturated_s);
            p.propagate_with(&sample, segment.end - segment.start, &noise);
        }
        if jolted {
            decorrelate_velocity(&mut p);
        }
        (p, jolted)
    }

    /// The scan's points in the body at `stamp`, moved along `track` (step 2).
    fn deskew(
        &self,
        track: &Track,
        stamp: f64,
        points: &[Point3<f64>],
        times: Option<&[f32]>,
    ) -> (Vec<Point3<f64>>, Result<(), DeskewRefusal>) {
        let Some(times) = times else { return (points.to_vec(), Err(DeskewRefusal::NoTimes)) };
        let (Some(at_stamp), Some((lo, hi))) = (track.state_at(stamp), track.span()) else {
            return (points.to_vec(), Err(DeskewRefusal::NoMotion));
        };
        let body_from_odom = pose_of(&at_stamp).inverse();
        let straight = deskew_with(points, times, |tau| {
            let t = (stamp + f64::from(tau)).clamp(lo, hi);
            track.state_at(t).map_or(Pose3::identity(), |s| body_from_odom * pose_of(&s))
        });
        match straight {
            Ok(p) => (p, Ok(())),
            Err(refusal) => (points.to_vec(), Err(refusal)),
        }
    }

    /// The points registration and the map use: finite, within range.
    fn usable(&self, points: &[Point3<f64>]) -> Vec<Point3<f64>> {
        let (lo, hi) = (self.config.min_range_m.powi(2), self.config.max_range_m.powi(2));
        points
            .iter()
            .filter(|p| p.coords.iter().all(|c| c.is_finite()))
            .filter(|p| (lo..=hi).contains(&p.coords.norm_squared()))
            .copied()
            .collect()
    }

    /// One scan: `points` in the sensor (= body) frame at their `times` after `stamp`.
    pub fn process_scan(
        &mut self,
        stamp: f64,
        points: &[Point3<f64>],
        times: Option<&[f32]>,
    ) -> Result<OdometryEstimate, ScanRefusal> {
        let refuse = |this: &mut Self, r: ScanRefusal| {
            this.counts.refused += 1;
            Err(r)
        };
        if !stamp.is_finite() {
            return refuse(self, ScanRefusal::NonFiniteStamp(stamp));
        }
        if let Some(f) = &self.filter {
            if stamp <= f.time {
                let previous = f.time;
                return refuse(self, ScanRefusal::NotAfterPrevious { stamp, previous });
            }
        }
        let (first, previous_time, predicted) = match &self.filter {
            Some(f) => (false, f.time, self.predict(f, stamp)),
            None => match self.start(stamp) {
                Ok(p) => (true, stamp, (p, false)),
                Err(r) => return refuse(self, r),
            },
        };
        // The motion from the last scan through this sweep's end, for deskewing.
        let sweep_end = sweep_end_s(times);
        let track_from = match &self.filter {
            Some(f) => (f.time, f.propagator.state),
            None => (stamp, predicted.0.state),
        };
        let segments = self.imu.segments(track_from.0, stamp + sweep_end.max(1e-6));
        let track = Track::new(&track_from.1, &segments, &self.config.imu, &Vector3::zeros());
        let (points_in_body, deskew) = self.deskew(&track, stamp, points, times);
        if deskew.is_err() {
            self.counts.not_deskewed += 1;
        }
        let usable = self.usable(&points_in_body);
        let scan = downsample_first(&usable, self.config.scan_voxel_m);
        let prediction = pose_of(&predicted.0.state);
        let (mut propagator, outcome, degeneracy) =
            if first { (predicted.0, ScanOutcome::First, None) } else { self.correct(predicted, &scan) };
        let mut outcome = outcome;
        let speed = propagator.state.velocity.norm();
        if !(finite_state(&propagator.state) && speed <= self.config.max_speed_mps) {
            propagator = self.reset_state();
            outcome = ScanOutcome::Reset { speed_mps: speed };
            self.counts.resets += 1;
        }
        match &outcome {
            ScanOutcome::Registered { points, correspondences, .. } => {
                self.counts.registered += 1;
                if degeneracy.as_ref().is_some_and(Degeneracy::is_degenerate) {
                    self.counts.degenerate += 1;
                }
                // Until the body has left its first spot, the map is that spot's scans, too
                // sparse at range for planes (a fifth of a campus scan finds one): not counted.
                if self.left_start && (*correspondences as f64) < self.config.min_overlap * *points as f64 {
                    self.counts.low_overlap += 1;
                }
            }
            ScanOutcome::Coasted(_) => self.counts.coasted += 1,
            ScanOutcome::First | ScanOutcome::Reset { .. } => {}
        }
        let pose = pose_of(&propagator.state);
        let start = *self.start.get_or_insert(pose.translation.vector);
        self.left_start |= (pose.translation.vector - start).norm() > START_RADIUS_M;
        if let (Some(f), ScanOutcome::Registered { .. }) = (&self.filter, &outcome) {
            let motion = pose_of(&f.propagator.state).inverse() * pose;
            self.threshold.update(&(prediction.inverse() * pose), &motion);
        }
        let to_map: Vec<Point3<f64>> =
            downsample_first(&usable, self.config.map_voxel_m).iter().map(|p| pose * p).collect();
        self.map.insert(&to_map, &Point3::from(pose.translation.vector));
        self.imu.advance(previous_time, stamp);
        let filter = Filter { time: stamp, propagator };
        if matches!(outcome, ScanOutcome::Registered { .. } | ScanOutcome::First) {
            self.last_registered = Some(filter.clone());
        }
        let state = filter.propagator.state;
        let covariance = pose_covariance(&filter.propagator.covariance.fixed_view::<6, 6>(0, 0).into_owned(), &state);
        let levelled = self.publish_up(&state, &filter.propagator.covariance);
        // σ of up on its worse axis; NaN (refused downstream) when the block is not finite.
        let block = filter.propagator.covariance.fixed_view::<2, 2>(UP, UP).into_owned();
        let up_sigma = if block.iter().all(|v| v.is_finite()) {
            block.symmetric_eigenvalues().max().max(0.0).sqrt()
        } else {
            f64::NAN
        };
        let measured_up = MeasuredUp { attitude_in_frame: state.rotation, up_in_frame: state.up, sigma_rad: up_sigma };
        let motion_covariance = filter
            .propagator
            .clone
            .as_ref()
            .map(|c| c.motion_covariance(&state, &filter.propagator.covariance) + self.frame_turn_since_mark);
        self.filter = Some(filter);
        self.counts.scans += 1;
        Ok(OdometryEstimate {
            stamp,
            odom_from_body: levelled * pose,
            velocity: levelled * state.velocity,
            covariance,
            motion_covariance,
            points_in_body,
            deskew,
            outcome,
            degeneracy,
            gyro_bias: state.gyro_bias,
            accel_bias: state.accel_bias,
            up: state.up,
            measured_up,
        })
    }

    /// Steps 3 and 4: the prediction corrected by the scan, or kept (with the reason).
    fn correct(
        &self,
        (predicted, jolted): (Propagator, bool),
        scan: &[Point3<f64>],
    ) -> (Propagator, ScanOutcome, Option<Degeneracy>) {
        let coast = |reason| (predicted.clone(), ScanOutcome::Coasted(reason), None);
        if scan.is_empty() {
            return coast(CoastReason::NoPoints);
        }
        let c = &self.config;
        let prediction = pose_of(&predicted.state);
        let sigma2 = c.point_noise_m * c.point_noise_m;
        let prior = prior_information(&predicted.covariance, &predicted.state).map(|information| Prior {
            map_from_body: prediction,
            information: information * (sigma2 / c.scan_information_scale),
        });
        // The search reaches as far as the prediction may be wrong, 3σ of its position, and the
        // kernel keeps residuals of σ weighted: millimetres while the IMU measures (below the
        // floors), decimetres after a jolt it could not (module notes).
        // √trace bounds the largest σ and is NaN-safe (f64::max drops a NaN).
        let spread = if jolted { predicted.covariance.fixed_view::<3, 3>(3, 3).trace().max(0.0).sqrt() } else { 0.0 };
        let registered = match register_scan(
            scan,
            &self.map,
            &prediction,
            self.threshold.correspondence_m().max(3.0 * c.point_noise_m).max(3.0 * spread),
            self.threshold.kernel_m().max(c.point_noise_m).max(spread),
            prior.as_ref(),
            &c.registration,
        ) {
            Ok(r) => r,
            Err(e) => return coast(CoastReason::Registration(e)),
        };
        let correction = prediction.inverse() * registered.map_from_body;
        let (moved_m, turned_rad) = (correction.translation.vector.norm(), correction.rotation.angle());
        if !(moved_m <= c.max_correction_m && turned_rad <= c.max_correction_rad) {
            return coast(CoastReason::Implausible { moved_m, turned_rad });
        }
        let information = scan_information(&registered.scan_hessian, &registered.map_from_body, c.point_noise_m)
            * c.scan_information_scale;
        let outcome = ScanOutcome::Registered {
            points: scan.len(),
            correspondences: registered.correspondences,
            iterations: registered.iterations,
            converged: registered.converged,
        };
        match apply_pose_update(&predicted.state, &predicted.covariance, &registered.map_from_body, &information) {
            Ok((state, covariance)) => {
                // The marked pose is corrected with the state (a singular prior: it is dropped).
                let clone =
                    predicted.clone.clone().and_then(|mut c| c.update(&predicted.covariance, &covariance).map(|()| c));
                (Propagator { state, covariance, clone, ..predicted }, outcome, Some(registered.degeneracy))
            }
            Err(e) => coast(CoastReason::Update(e)),
        }
    }

    /// The last registered state, its velocity unknown again (module notes); no motion since
    /// the mark is known across a reset.
    fn reset_state(&self) -> Propagator {
        let mut p = self.last_registered.as_ref().map_or_else(|| self.start_fallback(), |f| f.propagator.clone());
        p.clone = None;
        p.state.velocity = Vector3::zeros();
        decorrelate_velocity(&mut p);
        let v = self.config.initial_velocity_sigma_mps.powi(2);
        let mut velocity = p.covariance.fixed_view_mut::<3, 3>(6, 6);
        velocity.fill(0.0);
        velocity.fill_diagonal(v);
        p
    }

    fn start_fallback(&self) -> Propagator {
        let mut p = Matrix17::identity() * 1e-12;
        for k in 6..9 {
            p[(k, k)] = self.config.initial_velocity_sigma_mps.powi(2);
        }
        Propagator::new(NavState::at_rest(nalgebra::UnitQuaternion::identity(), Vector3::zeros()), p, self.config.imu)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::odometry::testing::{ImuErrors, Kerb, Sensors, SWEEP_S};

    struct Run {
        /// (estimate, truth in the odometry frame) per scan.
        track: Vec<(OdometryEstimate, Pose3)>,
        odometry: LidarInertialOdometry,
    }

    /// `seconds` of scans at 10 Hz; `deskew` false hands the scans in without their times.
    fn run(sensors: &mut Sensors, config: OdometryConfig, seconds: f64, deskew: bool) -> Run {
        let mut odometry = LidarInertialOdometry::new(config).expect("valid");
        // Gravity from the first second of samples; the odometry frame is the first pose, yaw
        // removed (its roll and pitch are gravity's).
        let first = 1.0;
        let start = sensors.truth(first);
        let yaw = start.rotation.euler_angles().2;
        let world_from_odom =
            Pose3::from_parts(start.translation, nalgebra::UnitQuaternion::from_euler_angles(0.0, 0.0, yaw));
        let mut track = Vec::new();
        let scans = (seconds / 0.1).round() as usize;
        for k in 0..scans {
            let stamp = first + k as f64 * 0.1;
            odometry.push_imu(&sensors.imu_until(stamp + SWEEP_S));
            let sweep = sensors.sweep(stamp);
            let times = deskew.then_some(sweep.times.as_slice());
            let estimate = odometry.process_scan(stamp, &sweep.points, times).expect("accepted");
            track.push((estimate, world_from_odom.inverse() * sensors.truth(stamp)));
        }
        Run { track, odometry }
    }

    impl Run {
        /// The error of each scan's pose (translation m, rotation rad) in the odometry frame,
        /// gravity-aligned on both sides: the truth's by construction, the estimate's as
        /// published (levelled by the up it learnt: an accelerometer's bias tilts the first
        /// levelling by bias/g, which the filter finds once the body turns).
        fn errors(&self) -> Vec<(f64, f64)> {
            self.track
                .iter()
                .map(|(e, t)| {
                    let d = t.inverse() * e.odom_from_body;
                    (d.translation.vector.norm(), d.rotation.angle())
                })
                .collect()
        }

        fn worst(&self) -> (f64, f64) {
            self.errors().into_iter().fold((0.0f64, 0.0f64), |a, b| (a.0.max(b.0), a.1.max(b.1)))
        }

        fn rms(&self) -> f64 {
            let e = self.errors();
            (e.iter().map(|x| x.0 * x.0).sum::<f64>() / e.len() as f64).sqrt()
        }

        fn length(&self) -> f64 {
            self.track.windows(2).map(|w| (w[1].1.translation.vector - w[0].1.translation.vector).norm()).sum()
        }
    }

    /// ADIS16448's white noise, and biases of 0.002 rad/s and 0.05 m/s².
    fn biased_imu() -> ImuErrors {
        ImuErrors {
            gyro_white: 1.7e-4,
            accel_white: 2e-3,
            gyro_bias: Vector3::new(0.002, -0.001, 0.0015),
            accel_bias: Vector3::new(0.05, -0.03, 0.02),
        }
    }

    #[test]
    fn a_legged_robot_in_a_room_is_tracked_to_centimetres() {
        let imu = biased_imu();
        let mut sensors = Sensors::new(false, imu, 1);
        let r = run(&mut sensors, OdometryConfig::default(), 20.0, true);
        let (length, worst) = (r.length(), r.worst());
        let counts = r.odometry.counts();
        assert!(length > 25.0, "{length}");
        // The first levelling reads the accelerometer's 0.058 m/s² of horizontal bias as a
        // 0.34° tilt (nothing at rest can tell them apart); the filter learns where up is as
        // the body turns, and the published frame follows once that is significant: its
        // attitude is within 0.15° (up's 3σ, `REPUBLISH_SIGMAS`) after 8 s.
        let errors = r.errors();
        let settled = errors[80..].iter().fold(0.0f64, |a, e| a.max(e.1));
        eprintln!("room: worst {worst:?}, after 8 s {settled}, {} frame turns", counts.frame_turns);
        assert!((1..=10).contains(&counts.frame_turns), "the published frame turns seldom: {counts:?}");
        assert!(errors[0].1 > 0.25f64.to_radians(), "the first levelling took the bias for tilt: {:?}", errors[0]);
        assert!(
            worst.0 < 0.08 && worst.1 < 0.5f64.to_radians() && settled < 0.15f64.to_radians(),
            "worst error {worst:?}, after 8 s {settled} rad, over {length:.1} m, {counts:?}"
        );
        assert_eq!(counts.registered, counts.scans - 1, "{counts:?}");
        assert_eq!((counts.resets, counts.coasted, counts.not_deskewed, counts.low_overlap), (0, 0, 0, 0));
        // The gyro's bias is found (the accelerometer's is weakly observable on this path).
        let last = &r.track.last().expect("scans").0;
        assert!((last.gyro_bias - imu.gyro_bias).norm() < 5e-4, "{} vs {}", last.gyro_bias, imu.gyro_bias);
        // No NaN, and a covariance that is symmetric positive definite.
        assert!(last.covariance.cholesky().is_some());
    }

    /// The motion between marks (every 5th scan: a keyframe's half second) and its covariance,
    /// against the true motion: the mean normalised squared error over 6 dimensions is near 6
    /// for an honest covariance. It must stay within a factor of 10 either way; the run's value
    /// is printed (`--nocapture`).
    #[test]
    fn the_motion_covariance_since_a_mark_is_honest() {
        let imu = biased_imu();
        let mut sensors = Sensors::new(false, imu, 1);
        let mut odometry = LidarInertialOdometry::new(OdometryConfig::default()).expect("valid");
        let (mut marked, mut nees, mut n) = (None, 0.0, 0);
        for k in 0..200 {
            let stamp = 1.0 + k as f64 * 0.1;
            odometry.push_imu(&sensors.imu_until(stamp + SWEEP_S));
            let sweep = sensors.sweep(stamp);
            let e = odometry.process_scan(stamp, &sweep.points, Some(&sweep.times)).expect("accepted");
            assert_eq!(e.motion_covariance.is_some(), marked.is_some(), "at scan {k}");
            if k % 5 != 0 {
                continue;
            }
            if let (Some((estimate, truth)), Some(covariance)) = (marked, e.motion_covariance) {
                let (estimate, truth): (Pose3, Pose3) = (estimate, truth);
                let moved = estimate.inverse() * e.odom_from_body;
                let really = truth.inverse() * sensors.truth(stamp);
                let error = crate::geometry::lie::se3_log(&(moved.inverse() * really));
                let info = covariance.cholesky().expect("positive definite").inverse();
                nees += (error.transpose() * info * error)[(0, 0)];
                n += 1;
            }
            odometry.mark();
            marked = Some((e.odom_from_body, sensors.truth(stamp)));
        }
        let mean = nees / f64::from(n);
        println!("mean NEES of the motion over half a second: {mean:.2} (6 is honest; {n} motions)");
        assert!(n >= 35 && (0.6..60.0).contains(&mean), "mean NEES {mean} over {n} motions");
    }

    #[test]
    fn deskewing_removes_the_sweeps_distortion() {
        let mut straight = Sensors::new(false, ImuErrors::default(), 2);
        let mut bent = Sensors::new(false, ImuErrors::default(), 2);
        let with = run(&mut straight, OdometryConfig::default(), 8.0, true);
        let without = run(&mut bent, OdometryConfig::default(), 8.0, false);
        let (a, b) = (with.rms(), without.rms());
        assert!(a < 0.02, "deskewed: {a}");
        assert!(b > 2.0 * a, "deskewed {a} vs not {b}");
        assert_eq!(without.odometry.counts().not_deskewed, 80);
    }

    /// A rig in a hand sways from the first sample: the levelling window sees it turn (so its
    /// mean rate is no gyro bias) and accelerate (so its mean force is gravity only to a
    /// degree or two). Taking the rate for a bias turned such a rig's estimate at 3°/s, and a
    /// filter sure of the levelling's up drove it hundreds of metres off.
    #[test]
    fn a_rig_swaying_from_the_start_is_tracked_once_it_learns_where_up_is() {
        let imu = biased_imu();
        let mut sensors = Sensors::new(false, imu, 1);
        sensors.sway = true;
        let r = run(&mut sensors, OdometryConfig::default(), 20.0, true);
        let counts = r.odometry.counts();
        let errors = r.errors();
        let settled = errors[80..].iter().fold((0.0f64, 0.0f64), |a, e| (a.0.max(e.0), a.1.max(e.1)));
        eprintln!("sway: worst {:?}, after 8 s {settled:?}, {} frame turns", r.worst(), counts.frame_turns);
        assert!((1..=10).contains(&counts.frame_turns), "the published frame turns seldom: {counts:?}");
        assert!(
            r.worst().0 < 0.2 && settled.0 < 0.05 && settled.1 < 0.15f64.to_radians(),
            "{:?} then {settled:?}, {counts:?}",
            r.worst()
        );
        assert_eq!((counts.resets, counts.coasted, counts.low_overlap), (0, 0, 0), "{counts:?}");
        // The sway's mean rate was not taken for the gyro's bias: the bias is found.
        let last = &r.track.last().expect("scans").0;
        assert!((last.gyro_bias - imu.gyro_bias).norm() < 5e-4, "{} vs {}", last.gyro_bias, imu.gyro_bias);
    }

    #[test]
    fn in_a_corridor_the_axis_is_weak_and_the_imu_carries_it() {
        let mut sensors = Sensors::new(true, ImuErrors::default(), 4);
        let r = run(&mut sensors, OdometryConfig::default(), 10.0, true);
        let counts = r.odometry.counts();
        assert!(counts.degenerate >= counts.registered * 9 / 10, "{counts:?}");
        let weak = r.track[50].0.degeneracy.clone().expect("registered");
        assert_eq!(weak.weak_translations.len(), 1);
        assert!(weak.weak_translations[0].x.abs() > 0.99, "{:?}", weak.weak_translations);
        // 13 m down the corridor with the IMU alone along it: the error along the axis is the
        // integral of the tilt's gravity leak (a milliradian is 1 cm/s²), within 5 % of the way;
        // across it, where the walls hold the estimate, centimetres.
        let (e, t) = r.track.last().expect("scans");
        let (dx, rest) = {
            let d = e.odom_from_body.translation.vector - t.translation.vector;
            (d.x.abs(), d.yz().norm())
        };
        let length = r.length();
        assert!(length > 12.0 && dx < 0.05 * length && rest < 0.03, "along {dx} of {length}, across {rest}");
    }

    #[test]
    fn bad_input_is_refused_or_coasted_and_never_yields_nan() {
        let mut sensors = Sensors::new(false, ImuErrors::default(), 5);
        let mut odometry = LidarInertialOdometry::new(OdometryConfig::default()).expect("valid");
        // No IMU yet: the first scan waits.
        let sweep = sensors.sweep(0.5);
        assert!(matches!(
            odometry.process_scan(0.5, &sweep.points, Some(&sweep.times)),
            Err(ScanRefusal::WaitingForImu { samples: 0, .. })
        ));
        odometry.push_imu(&sensors.imu_until(1.1));
        let sweep = sensors.sweep(1.0);
        let first = odometry.process_scan(1.0, &sweep.points, Some(&sweep.times)).expect("starts");
        assert_eq!(first.outcome, ScanOutcome::First);
        // Time going backwards, and a NaN stamp: refused, nothing stored.
        assert!(matches!(odometry.process_scan(0.9, &sweep.points, None), Err(ScanRefusal::NotAfterPrevious { .. })));
        assert!(matches!(odometry.process_scan(f64::NAN, &sweep.points, None), Err(ScanRefusal::NonFiniteStamp(_))));
        // An empty scan and an all-NaN one coast on the IMU.
        odometry.push_imu(&sensors.imu_until(1.2));
        let empty = odometry.process_scan(1.1, &[], Some(&[])).expect("coasts");
        assert_eq!(empty.outcome, ScanOutcome::Coasted(CoastReason::NoPoints));
        odometry.push_imu(&sensors.imu_until(1.3));
        let nan = vec![Point3::new(f64::NAN, 0.0, 0.0); 100];
        let coasted = odometry.process_scan(1.2, &nan, Some(&[0.0; 100])).expect("coasts");
        assert_eq!(coasted.outcome, ScanOutcome::Coasted(CoastReason::NoPoints));
        assert_eq!(coasted.points_in_body.len(), 100);
        // Mismatched times: used as they came, counted.
        odometry.push_imu(&sensors.imu_until(1.4));
        let sweep = sensors.sweep(1.3);
        let skewed = odometry.process_scan(1.3, &sweep.points, Some(&[0.0; 3])).expect("registers");
        assert!(skewed.deskew.is_err());
        // A second-long IMU gap: the robot coasts at constant velocity across it, with coasting
        // noise; the scan after still registers.
        let _lost = sensors.imu_until(2.3);
        odometry.push_imu(&sensors.imu_until(2.5));
        let sweep = sensors.sweep(2.4);
        let after_gap = odometry.process_scan(2.4, &sweep.points, Some(&sweep.times)).expect("accepted");
        assert!(matches!(after_gap.outcome, ScanOutcome::Registered { .. }), "{:?}", after_gap.outcome);
        let c = odometry.counts();
        assert_eq!(c.refused, 3);
        assert!(c.imu.gaps >= 1, "{c:?}");
        for e in [&first, &empty, &coasted, &skewed, &after_gap] {
            assert!(finite_pose(&e.odom_from_body) && e.covariance.iter().all(|v| v.is_finite()));
        }
        let start = sensors.truth(1.0);
        let heading = nalgebra::UnitQuaternion::from_euler_angles(0.0, 0.0, start.rotation.euler_angles().2);
        let truth = Pose3::from_parts(start.translation, heading).inverse() * sensors.truth(2.4);
        let d = truth.translation.vector - after_gap.odom_from_body.translation.vector;
        assert!(d.norm() < 0.1, "{d}");
    }

    #[test]
    fn a_saturated_segment_adds_the_full_scale_over_it_to_what_its_sensor_integrates() {
        // Propagated at rest from a zero covariance, once as measured and once marked
        // saturated: the difference is (range · dt)² on the velocity (accelerometer) or on the
        // attitude (gyro), and nothing on the other.
        let (dt, limits, noise) = (0.005, ImuLimits::default(), ImuNoise::default());
        let state = NavState::at_rest(nalgebra::UnitQuaternion::identity(), Vector3::zeros());
        let at_rest = ImuSample { stamp: 0.0, angular_velocity: Vector3::zeros(), specific_force: Vector3::z() * 9.81 };
        // The jolt held over `pieces` segments (a faster IMU): the same variance in the end.
        let split = |saturation: Saturation, pieces: usize| {
            let mut p = Propagator::new(state, Matrix17::zeros(), noise);
            for _ in 0..pieces {
                let piece = dt / pieces as f64;
                p.propagate_with(&at_rest, piece, &saturated_noise(&noise, &saturation, &limits, (dt, dt)));
            }
            p.covariance
        };
        let after = |saturation: Saturation| split(saturation, 1);
        let measured = after(Saturation::default());
        let accel = after(Saturation { gyro: false, accel: true }) - measured;
        let gyro = after(Saturation { gyro: true, accel: false }) - measured;
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * b.abs().max(1e-12);
        for k in 0..3 {
            assert!(close(accel[(6 + k, 6 + k)], (limits.accel_range_mps2 * dt).powi(2)), "{accel}");
            assert!(close(gyro[(k, k)], (limits.gyro_range_rad_s * dt).powi(2)), "{gyro}");
            assert_eq!((accel[(k, k)], gyro[(6 + k, 6 + k)]), (0.0, 0.0));
            let faster = split(Saturation { gyro: false, accel: true }, 5) - split(Saturation::default(), 5);
            assert!(close(faster[(6 + k, 6 + k)], accel[(6 + k, 6 + k)]), "{faster} vs {accel}");
        }
    }

    #[test]
    fn a_scan_is_counted_low_overlap_below_its_fraction_of_points_on_the_map() {
        // Each registered scan's fraction of points that found a surface, from its outcome, once
        // an earlier estimate was more than a metre from the first; the count is those below
        // `min_overlap`, whatever it is set to.
        let fractions = |min_overlap: f64| {
            let config = OdometryConfig { min_overlap, ..OdometryConfig::default() };
            let r = run(&mut Sensors::new(false, ImuErrors::default(), 4), config, 5.0, true);
            let first = r.track[0].0.odom_from_body.translation.vector;
            let mut left = false;
            let mut fractions = Vec::new();
            for (e, _) in &r.track {
                if let (true, ScanOutcome::Registered { points, correspondences, .. }) = (left, &e.outcome) {
                    fractions.push(*correspondences as f64 / *points as f64);
                }
                left |= (e.odom_from_body.translation.vector - first).norm() > START_RADIUS_M;
            }
            (fractions, r.odometry.counts().low_overlap)
        };
        let (seen, none) = fractions(0.0);
        assert_eq!(none, 0);
        assert!(seen.len() >= 20 && seen.iter().all(|f| (0.5..=1.0).contains(f)), "{seen:?}");
        let median = {
            let mut s = seen.clone();
            s.sort_by(f64::total_cmp);
            s[s.len() / 2]
        };
        let (_, below_median) = fractions(median);
        assert_eq!(below_median as usize, seen.iter().filter(|f| **f < median).count());
        assert!(below_median > 0);
        assert_eq!(fractions(1.0).1 as usize, seen.iter().filter(|f| **f < 1.0).count());
    }

    #[test]
    fn a_kerb_that_saturates_the_accelerometer_is_ridden_out() {
        // 0.3 m up in 40 ms: ±1 100 m/s², a 16 g accelerometer clipped on ~8 samples. Dropped
        // and the sample before held over them, the rise went unintegrated and the filter,
        // sure of its velocity, followed it into the floor (`legged_campus` seed 3).
        let mut sensors = Sensors::new(false, biased_imu(), 3);
        sensors.kerb = Some(Kerb { at_s: 6.02, height_m: 0.3, duration_s: 0.04 });
        let r = run(&mut sensors, OdometryConfig::default(), 15.0, true);
        let counts = r.odometry.counts();
        assert!(counts.imu.saturated >= 4, "{counts:?}");
        // Every scan's motion from the first within 5 cm, through the 0.3 m rise.
        let (worst, length) = (r.worst(), r.length());
        eprintln!("kerb: worst {worst:?}");
        assert!(worst.0 < 0.1 && worst.1 < 0.5f64.to_radians(), "worst error {worst:?} over {length:.1} m, {counts:?}");
        assert_eq!((counts.resets, counts.coasted), (0, 0), "{counts:?}");
    }

    #[test]
    fn a_diverged_state_is_reset_to_the_last_registered_one() {
        let mut sensors = Sensors::new(false, ImuErrors::default(), 6);
        let mut odometry = LidarInertialOdometry::new(OdometryConfig::default()).expect("valid");
        odometry.push_imu(&sensors.imu_until(1.1));
        let sweep = sensors.sweep(1.0);
        odometry.process_scan(1.0, &sweep.points, Some(&sweep.times)).expect("starts");
        // An accelerometer stuck at 150 m/s² sideways (below saturation) for 0.3 s: 45 m/s.
        let _ = sensors.imu_until(1.4);
        let stuck: Vec<ImuSample> = (0..60)
            .map(|k| ImuSample {
                stamp: 1.105 + k as f64 * 0.005,
                angular_velocity: Vector3::zeros(),
                specific_force: Vector3::new(0.0, 150.0, 9.81),
            })
            .collect();
        odometry.push_imu(&stuck);
        let sweep = sensors.sweep(1.4);
        let e = odometry.process_scan(1.4, &sweep.points, Some(&sweep.times)).expect("accepted");
        assert!(
            matches!(e.outcome, ScanOutcome::Reset { .. }),
            "{:?} at {} m/s, {:?}",
            e.outcome,
            e.velocity,
            e.odom_from_body.translation
        );
        assert!(finite_pose(&e.odom_from_body) && e.velocity.norm() == 0.0);
        assert_eq!(odometry.counts().resets, 1);
        // The IMU is sane again: the scans after register.
        odometry.push_imu(&sensors.imu_until(1.6));
        let sweep = sensors.sweep(1.5);
        let next = odometry.process_scan(1.5, &sweep.points, Some(&sweep.times)).expect("accepted");
        assert!(matches!(next.outcome, ScanOutcome::Registered { .. }), "{:?}", next.outcome);
    }
}
