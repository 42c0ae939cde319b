//! From a matched object graph to an inter-robot alignment (paper §IV-D): the neighbour
//! keyframes of a round, each registered by ICP onto the nearest local keyframe that observed a
//! matched object, checked for structure, and judged together.
//!
//! ```text
//! initial_k   = W_l(n_k)⁻¹ · local_from_remote · W_r(k)        (remote body k in local body n_k)
//! T_k         = ICP(remote points of k → local points of n_k, from initial_k)
//! implied_k   = W_l(n_k) · T_k · W_r(k)⁻¹                       (the local_from_remote it implies)
//! aligned     = medoid { implied_k }  if #accepted ≥ min_keyframe_factors
//! ```
//!
//! A registration is accepted when ICP converges and the structure check
//! ([`crate::perception::structure_check`]) agrees at least `min_structure_agreement`. Too few
//! accepted refute the match, unless keyframes were lost on the way (the round is then
//! incomplete and tried again). The medoid is robust to one registration that slid along a
//! degenerate direction. A refuted transform is remembered for [`REFUTED_FOR_S`]: a later match
//! landing near it is not pursued.

pub use crate::geometry::medoid;
use crate::geometry::{pose_error, Pose3};
use crate::perception::icp::{register, register_to, Freedom, IcpConfig, IcpTarget};
use crate::perception::structure_check::{StructureCheck, StructureTarget};
use crate::scene_graph::{KeyframeId, Stamp};
use crate::workers::Workers;
use nalgebra::{Matrix6, Point3, Vector3};
use std::collections::{BTreeMap, BTreeSet};

/// How long a refuted transform is remembered, s.
pub const REFUTED_FOR_S: f64 = 120.0;

/// Whether `transform` lands within 2 m and 5° of one refuted less than [`REFUTED_FOR_S`] ago.
pub fn refuted_recently(refuted: &[(Pose3, Stamp)], transform: &Pose3, now: Stamp) -> bool {
    refuted.iter().any(|(t, when)| {
        let e = pose_error(transform, t);
        now - when < REFUTED_FOR_S && e.translation_m < 2.0 && e.max_axis_rotation_deg() < 5.0
    })
}

/// At most `n` of `ids`, spread evenly over them (deterministic).
pub fn evenly(ids: BTreeSet<KeyframeId>, n: usize) -> BTreeSet<KeyframeId> {
    if ids.len() <= n {
        return ids;
    }
    let all: Vec<KeyframeId> = ids.into_iter().collect();
    (0..n).map(|i| all[i * all.len() / n]).collect()
}

/// The keyframes `k` either side of each of `ids` (ids saturate at 0 and `u32::MAX`).
pub fn neighbourhood(ids: impl IntoIterator<Item = KeyframeId>, k: u32) -> BTreeSet<KeyframeId> {
    ids.into_iter().flat_map(|id| (id.0.saturating_sub(k)..=id.0.saturating_add(k)).map(KeyframeId)).collect()
}

/// A turn by `yaw` about z, rad.
pub fn yaw_turn(yaw: f64) -> Pose3 {
    Pose3::from_parts(Default::default(), nalgebra::UnitQuaternion::from_euler_angles(0.0, 0.0, yaw))
}

/// A local keyframe as registration sees it: its pose and its scan's points (body frame).
#[derive(Clone, Copy, Debug)]
pub struct LocalView<'a> {
    pub world_from_body: &'a Pose3,
    pub points_in_body: &'a [Point3<f32>],
}

/// A neighbour keyframe of the round: its pose in the neighbour's world, covariance, points.
#[derive(Clone, Copy, Debug)]
pub struct RemoteView<'a> {
    pub id: KeyframeId,
    pub world_from_body: &'a Pose3,
    pub covariance: &'a Matrix6<f64>,
    pub points_in_body: &'a [Point3<f64>],
}

/// How the round's keyframes are registered and checked.
#[derive(Clone, Debug)]
pub struct RoundConfig<'a> {
    pub icp: &'a IcpConfig,
    pub structure: &'a StructureCheck,
    pub min_structure_agreement: f64,
    /// Least standard deviations of a factor, (rotation rad, translation m): see [`with_floor`].
    pub sigma_floor: (f64, f64),
    /// Threads each registration may split its correspondence search over (same answer).
    pub workers: &'a Workers,
    /// Gravity-aligned worlds: each registration keeps the relative tilt its initial guess
    /// holds and estimates x, y, z and yaw ([`crate::perception::level_icp`]).
    pub level: bool,
}

/// What a round's registrations gave.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RoundRegistrations {
    /// Accepted neighbour keyframes: (id, pose in the neighbour's world, covariance).
    pub neighbour_keyframes: Vec<(KeyframeId, Pose3, Matrix6<f64>)>,
    /// (local keyframe, neighbour keyframe, local_body_from_neighbour_body, information).
    pub factors: Vec<(KeyframeId, KeyframeId, Pose3, Matrix6<f64>)>,
    /// The local_from_remote each accepted registration implies.
    pub implied: Vec<Pose3>,
}

/// Registers every keyframe of `round` (in order) onto the nearest of `targets` (in id order,
/// the first of equally near ones) placed by `local_from_remote`; see the module documentation.
pub fn register_round<'a>(
    targets: &BTreeMap<KeyframeId, LocalView<'a>>,
    round: impl IntoIterator<Item = RemoteView<'a>>,
    local_from_remote: &Pose3,
    config: &RoundConfig,
) -> RoundRegistrations {
    let mut out = RoundRegistrations::default();
    // Several neighbour keyframes usually register to one local keyframe: make it ready once
    // (its ICP target and its structure; `None`: too few points to register onto).
    let mut ready: BTreeMap<KeyframeId, Option<(IcpTarget, StructureTarget)>> = BTreeMap::new();
    for remote in round {
        let in_local = local_from_remote * remote.world_from_body;
        let nearest = targets.iter().min_by(|a, b| {
            let da = (a.1.world_from_body.translation.vector - in_local.translation.vector).norm();
            let db = (b.1.world_from_body.translation.vector - in_local.translation.vector).norm();
            da.total_cmp(&db)
        });
        let Some((local_id, local)) = nearest else { continue };
        let target = ready.entry(*local_id).or_insert_with(|| {
            let points: Vec<Point3<f64>> = local.points_in_body.iter().map(|p| p.cast::<f64>()).collect();
            let icp = IcpTarget::new(&points, config.icp).ok()?;
            Some((icp, StructureTarget::new(&points, config.structure)))
        });
        let Some((icp_target, structure_target)) = target else { continue };
        let initial = local.world_from_body.inverse() * in_local;
        let freedom = if config.level {
            Freedom::Level(local.world_from_body.rotation.inverse() * Vector3::z())
        } else {
            Freedom::Full
        };
        let Ok(result) = register_to(remote.points_in_body, icp_target, &initial, config.icp, config.workers, freedom)
        else {
            continue;
        };
        if !result.converged {
            continue;
        }
        let agreement = structure_target.agreement(remote.points_in_body, &result.target_from_source, config.structure);
        if agreement.is_none_or(|a| a < config.min_structure_agreement) {
            continue;
        }
        out.neighbour_keyframes.push((remote.id, *remote.world_from_body, *remote.covariance));
        let information = with_floor(&result.information, config.sigma_floor);
        out.factors.push((*local_id, remote.id, result.target_from_source, information));
        out.implied.push(local.world_from_body * result.target_from_source * remote.world_from_body.inverse());
    }
    out
}

/// ICP's information Σ JᵀJ / RMSE² treats every point's residual as independent, so it claims
/// sub-millimetre precision from thousands of points, while a registration's real error is
/// systematic (the scans' own distortion, a surface seen from two sides). A factor's covariance
/// is ICP's plus a floor per axis:
///
/// ```text
/// Σ = H⁻¹ + diag(σ_r², σ_r², σ_r², σ_t², σ_t², σ_t²),   Ω = Σ⁻¹
/// ```
///
/// `sigma_floor` = (σ_r rad, σ_t m); (0, 0) keeps ICP's information.
pub fn with_floor(information: &Matrix6<f64>, sigma_floor: (f64, f64)) -> Matrix6<f64> {
    let (r, t) = sigma_floor;
    if r == 0.0 && t == 0.0 {
        return *information;
    }
    let Some(covariance) = information.try_inverse() else { return *information };
    let floor = Matrix6::from_diagonal(&nalgebra::Vector6::new(r * r, r * r, r * r, t * t, t * t, t * t));
    (covariance + floor).try_inverse().unwrap_or(*information)
}

/// What a finished round means.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum RoundVerdict {
    /// Keyframes were lost on the way and too few registered: say nothing, try again.
    Incomplete,
    /// Every keyframe came and too few registered: the match was wrong.
    Refuted,
    /// Enough registered: the neighbour's world is here (the medoid of the implied transforms,
    /// or the round's estimate if none was implied).
    Aligned(Pose3),
}

/// Judges a round: `accepted` registrations of at least `min_keyframe_factors` needed;
/// `incomplete` when keyframes were given up on.
pub fn judge_round(
    registrations: &RoundRegistrations,
    min_keyframe_factors: usize,
    incomplete: bool,
    estimate: &Pose3,
) -> RoundVerdict {
    match (registrations.factors.len() < min_keyframe_factors, incomplete) {
        (true, true) => RoundVerdict::Incomplete,
        (true, false) => RoundVerdict::Refuted,
        (false, _) => RoundVerdict::Aligned(medoid(&registrations.implied).unwrap_or(*estimate)),
    }
}

/// Scan Context association: the neighbour keyframe `remote` registered onto the local one
/// `local`, first with a correspondence distance of `coarse_correspondence_m` from the
/// descriptor's yaw (local_body_from_remote_body ≈ Rz(−yaw)), then with `fine`; the
/// local_from_remote it implies, or `None` when either stage fails.
pub fn coarse_to_fine(
    local: &LocalView,
    remote: &RemoteView,
    yaw: f64,
    coarse_correspondence_m: f64,
    fine: &IcpConfig,
) -> Option<Pose3> {
    let target: Vec<Point3<f64>> = local.points_in_body.iter().map(|p| p.cast::<f64>()).collect();
    let coarse = IcpConfig {
        max_correspondence_distance_m: coarse_correspondence_m,
        max_iterations: fine.max_iterations * 2,
        ..fine.clone()
    };
    let mut local_from_remote_body = yaw_turn(-yaw);
    for config in [&coarse, fine] {
        let result = register(remote.points_in_body, &target, &local_from_remote_body, config).ok()?;
        if !result.converged {
            return None;
        }
        local_from_remote_body = result.target_from_source;
    }
    Some(local.world_from_body * local_from_remote_body * remote.world_from_body.inverse())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::pose_from_rpy_translation;
    use nalgebra::Vector3;

    fn pose(x: f64, y: f64, yaw: f64) -> Pose3 {
        pose_from_rpy_translation(0.0, 0.0, yaw, Vector3::new(x, y, 0.0))
    }

    /// Three walls and a floor, with some posts: enough structure for ICP and the check.
    fn room() -> Vec<Point3<f64>> {
        let mut points = Vec::new();
        for i in 0..40 {
            for j in 0..20 {
                let (u, v) = (f64::from(i) * 0.25, f64::from(j) * 0.2);
                points.push(Point3::new(u - 5.0, 4.0, v));
                points.push(Point3::new(u - 5.0, -4.0, v));
                points.push(Point3::new(5.0, u * 0.8 - 4.0, v));
                points.push(Point3::new(u - 5.0, v * 2.0 - 4.0, 0.0));
            }
        }
        for (x, y) in [(-2.0, 1.0), (1.0, -2.0), (3.0, 2.5)] {
            for k in 0..20 {
                points.push(Point3::new(x, y, f64::from(k) * 0.1));
            }
        }
        points
    }

    #[test]
    fn the_medoid_ignores_one_estimate_that_slid() {
        // Closed form: summed distances 8.04 (the first), 8.06 and 8.06 (its two sides), and the
        // one that slid 5 m sideways and turned 0.3 rad is farthest from all.
        let estimates = [pose(1.0, 0.0, 0.0), pose(1.02, 0.0, 0.0), pose(0.98, 0.0, 0.0), pose(1.0, 5.0, 0.3)];
        assert_eq!(medoid(&estimates), Some(estimates[0]));
        assert_eq!(medoid(&[]), None);
    }

    #[test]
    fn a_refuted_transform_is_remembered_for_a_while_and_nearby() {
        let refuted = [(pose(10.0, 0.0, 0.0), 100.0)];
        assert!(refuted_recently(&refuted, &pose(11.0, 0.5, 0.05), 150.0));
        assert!(!refuted_recently(&refuted, &pose(13.0, 0.0, 0.0), 150.0), "3 m away");
        assert!(!refuted_recently(&refuted, &pose(10.0, 0.0, 0.2), 150.0), "11° turned");
        assert!(!refuted_recently(&refuted, &pose(10.0, 0.0, 0.0), 100.0 + REFUTED_FOR_S), "forgotten");
    }

    #[test]
    fn rounds_are_spread_and_widened() {
        let ids: BTreeSet<KeyframeId> = (0..10).map(KeyframeId).collect();
        assert_eq!(evenly(ids.clone(), 3), [0, 3, 6].map(KeyframeId).into_iter().collect());
        assert_eq!(evenly(ids.clone(), 20), ids);
        assert_eq!(
            neighbourhood([KeyframeId(1), KeyframeId(7)], 2),
            [0, 1, 2, 3, 5, 6, 7, 8, 9].map(KeyframeId).into_iter().collect()
        );
    }

    /// Two neighbour keyframes of one room, the neighbour's world 3 m and 20° from ours and the
    /// round's estimate 0.4 m and 3° off: both register, each implies the true transform
    /// (closed form), and the round aligns there; a round with too few is refuted, or
    /// incomplete when keyframes were lost.
    #[test]
    fn a_round_registers_its_keyframes_and_aligns_where_they_agree() {
        let points = room();
        let local_from_remote = pose(3.0, -1.0, 20f64.to_radians());
        let local_pose = pose(0.0, 0.0, 0.0);
        let local_points: Vec<Point3<f32>> = points.iter().map(|p| p.cast::<f32>()).collect();
        let targets: BTreeMap<KeyframeId, LocalView> =
            [(KeyframeId(4), LocalView { world_from_body: &local_pose, points_in_body: &local_points })].into();
        // The neighbour saw the same room from two places of its world.
        let remote_poses =
            [local_from_remote.inverse() * pose(0.5, 0.0, 0.0), local_from_remote.inverse() * pose(-0.5, 0.3, 0.1)];
        let remote_points: Vec<Vec<Point3<f64>>> = remote_poses
            .iter()
            .map(|w| {
                let body_from_local = (local_from_remote * w).inverse() * local_pose;
                points.iter().map(|p| body_from_local * p).collect()
            })
            .collect();
        let covariance = Matrix6::identity();
        let round = (0..2).map(|k| RemoteView {
            id: KeyframeId(10 + k as u32),
            world_from_body: &remote_poses[k],
            covariance: &covariance,
            points_in_body: &remote_points[k],
        });
        let estimate = local_from_remote * pose(0.4, 0.0, 3f64.to_radians());
        let icp = IcpConfig { max_correspondence_distance_m: 1.0, ..IcpConfig::default() };
        let structure = StructureCheck::default();
        let workers = Workers::sequential();
        let config = RoundConfig {
            icp: &icp,
            structure: &structure,
            min_structure_agreement: 0.5,
            sigma_floor: (0.0, 0.0),
            workers: &workers,
            level: false,
        };
        let registered = register_round(&targets, round.clone(), &estimate, &config);
        assert_eq!(registered.factors.len(), 2, "{registered:?}");
        assert_eq!(registered.factors[0].0, KeyframeId(4));
        for implied in &registered.implied {
            let e = pose_error(implied, &local_from_remote);
            assert!(e.translation_m < 0.02 && e.max_axis_rotation_deg() < 0.2, "{e:?}");
        }
        // Level (gravity-aligned worlds, a level estimate): as good, and level to the last bit
        // of the tilt the estimate holds.
        let level = register_round(&targets, round, &estimate, &RoundConfig { level: true, ..config });
        assert_eq!(level.factors.len(), 2, "{level:?}");
        for implied in &level.implied {
            let e = pose_error(implied, &local_from_remote);
            assert!(e.translation_m < 0.02 && e.max_axis_rotation_deg() < 0.2, "{e:?}");
            assert!((implied.rotation * Vector3::z()).angle(&Vector3::z()) < 1e-9);
        }
        let RoundVerdict::Aligned(aligned) = judge_round(&registered, 2, false, &estimate) else { panic!("aligned") };
        assert!(pose_error(&aligned, &local_from_remote).translation_m < 0.02);
        assert_eq!(judge_round(&registered, 3, false, &estimate), RoundVerdict::Refuted);
        assert_eq!(judge_round(&registered, 3, true, &estimate), RoundVerdict::Incomplete);
    }
}
