//! Scan-to-map registration with a motion prior, and the degeneracy it reveals.
//!
//! A deskewed scan (body frame) is registered onto the local map (odometry frame) by
//! Gauss–Newton over a left perturbation T ← Exp(δ) T, δ = (ω, v). Each scan point s, at
//! p = T s, is paired with its nearest map point q within τ + v/2 (τ the adaptive threshold of
//! `threshold`, v the map's voxel: the map is sampled, so a point on a surface lies up to about
//! the sampling distance from its nearest map point whatever the pose error), and the plane
//! through q's `plane_neighbours` nearest map points (FAST-LIO2's
//! residual: Xu et al. 2022, "FAST-LIO2: Fast Direct LiDAR-Inertial Odometry", T-RO 38(4),
//! §V-B) gives the residual along its normal n:
//!
//! ```text
//! r = nᵀ(p − q),   ∂r/∂δ = [(p × n)ᵀ, nᵀ]
//! ```
//!
//! (`geometry::point_to_plane`: the residual and normal equations `sgm icp` solves too)
//!
//! kept when |r| ≤ τ: the threshold bounds the pose error's effect along the surface normal,
//! which is what the residual measures.
//!
//! The plane counts only when every neighbour lies within `plane_tolerance_m` of it and they
//! span a plane (λ₀ < `planarity` · λ₁ of their covariance, and λ₁ ≥ `planarity` · λ₂: points
//! along a line — one LiDAR ring across the floor — have no normal, and a normal fitted to them
//! points anywhere around the line, constraining the scan along a direction nothing measured). Points with no such plane are left
//! out, not paired point-to-point: a point-to-point residual on a surface pins the scan to the
//! map's sampling along the surface, a constraint that does not exist, and would hide the very
//! degeneracy measured below.
//!
//! each weighted by Geman–McClure, w = (κ² / (κ² + ‖r‖²))², κ the kernel scale (σ/3 of the
//! threshold). The prediction (IMU propagation) enters as a Gaussian prior on the pose,
//! e = Log(T_pred⁻¹ T) with information Λ, linearised exactly:
//!
//! ```text
//! e(Exp(δ) T) = Log(T_pred⁻¹ T · Exp(Ad(T⁻¹) δ)) ≈ e₀ + J_r⁻¹(e₀) Ad(T⁻¹) δ
//! (H_scan + Jₚᵀ Λ Jₚ) δ = −(b_scan + Jₚᵀ Λ e₀)
//! ```
//!
//! **Degeneracy** (Zhang, Kaess & Singh 2016, "On degeneracy of optimization-based state
//! estimation problems", ICRA): the scan term's Hessian H_scan, split into its rotation and
//! translation blocks (units differ), has an eigenvalue per direction; a direction whose
//! eigenvalue is below `weak_rotation_ratio` / `weak_translation_ratio` times its block's
//! largest is one the scan does not
//! constrain — the axis of a corridor, the plane of an open field. The weak directions are
//! reported, and nothing more is done about them here: the prior is in the same solve, weighted
//! by its information, so where the scan says little the prediction decides, and where the
//! scan says a little (trees on an open campus) both count. Solution remapping (Zhang et al.
//! §IV: keep the prediction along the weak axes and drop the scan's information there) was
//! tried and removed: on `outdoor_two_robots` the campus's horizontal directions measure 1–4 %
//! of the ground's vertical, so it handed the horizontal plane to the IMU alone, and the end
//! error over 60 m was 57 % against 0.04 % without it (`sgm bench odometry --duration 60`);
//! the corridors of the tests are held as well without it. The test is made once, on the
//! converged Hessian.

use super::local_map::{LocalMap, PlaneParams};
use crate::geometry::lie::{hat, se3_adjoint, se3_exp, se3_log, se3_right_jacobian_inverse, Matrix6};
use crate::geometry::point_to_plane::{self, NormalEquations};
use crate::geometry::Pose3;
use nalgebra::{Matrix3, Point3, SymmetricEigen, Vector3};
use rustc_hash::FxHashMap;
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RegistrationConfig {
    /// Default 30.
    pub max_iterations: usize,
    /// Steps below both bounds have converged. Defaults 1e-5 rad, 1e-4 m.
    pub convergence_rad: f64,
    pub convergence_m: f64,
    /// Fewer correspondences than this: no registration. Default 20.
    pub min_correspondences: usize,
    /// Map points a plane is fitted to. Default 5 (FAST-LIO2's).
    pub plane_neighbours: usize,
    /// Every one of them within this of the plane, m. Default 0.1.
    pub plane_tolerance_m: f64,
    /// ... and spanning a plane: λ₀ < planarity · λ₁ ≤ planarity² · λ₂ of their covariance (flat,
    /// and not a line). Default 0.1.
    pub planarity: f64,
    /// A direction is weak when its eigenvalue is below this fraction of its block's largest.
    /// Translations, default 0.05: a corridor's axis measures 0.002–0.02 in the simulated
    /// corridor of the odometry's tests, a closed room's weakest axis 0.1 or more. Rotations,
    /// default 0.01: a rotation's information grows with the square of its lever arms, so a
    /// 3 m corridor's roll measures ~0.025 of its yaw and is still well constrained.
    pub weak_translation_ratio: f64,
    pub weak_rotation_ratio: f64,
}

impl Default for RegistrationConfig {
    fn default() -> Self {
        Self {
            max_iterations: 30,
            convergence_rad: 1e-5,
            convergence_m: 1e-4,
            min_correspondences: 20,
            plane_neighbours: 5,
            plane_tolerance_m: 0.1,
            planarity: 0.1,
            weak_translation_ratio: 0.05,
            weak_rotation_ratio: 0.01,
        }
    }
}

impl RegistrationConfig {
    /// What a plane fit depends on ([`LocalMap::cache_planes`]).
    pub fn plane_params(&self) -> PlaneParams {
        PlaneParams {
            neighbours: self.plane_neighbours,
            tolerance_m: self.plane_tolerance_m,
            planarity: self.planarity,
        }
    }
}

/// The prediction: the pose and the information of e = Log(T_pred⁻¹ T), (ω, v).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Prior {
    pub map_from_body: Pose3,
    pub information: Matrix6,
}

/// What the scan does not constrain: rotations about the body (body-centred, odometry axes),
/// translations in the odometry frame.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Degeneracy {
    /// Eigenvalues of the rotation and translation blocks, ascending.
    pub rotation_eigenvalues: [f64; 3],
    pub translation_eigenvalues: [f64; 3],
    /// Unit axes of the weak rotations and translations.
    pub weak_rotations: Vec<Vector3<f64>>,
    pub weak_translations: Vec<Vector3<f64>>,
}

impl Degeneracy {
    pub fn is_degenerate(&self) -> bool {
        !(self.weak_rotations.is_empty() && self.weak_translations.is_empty())
    }
}

#[derive(Clone, Debug, PartialEq)]
pub struct Registration {
    pub map_from_body: Pose3,
    pub converged: bool,
    pub iterations: usize,
    /// Correspondences of the last pass.
    pub correspondences: usize,
    pub degeneracy: Degeneracy,
    /// The scan term's Gauss–Newton Hessian Σ w JᵀJ of the last pass (left perturbation,
    /// residuals in metres, no prior): divided by a residual's variance, the scan's information.
    pub scan_hessian: Matrix6,
}

#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum RegistrationError {
    #[error("the initial pose is not finite")]
    NonFiniteInitial,
    #[error("{found} correspondences within {threshold_m:.2} m, need {required}")]
    TooFewCorrespondences { found: usize, required: usize, threshold_m: f64 },
    #[error("the normal equations are singular")]
    Singular,
}

/// The normal of the plane through `points`, when they make one (see the module notes).
fn plane_normal(points: &[Point3<f64>], tolerance_m: f64, planarity: f64) -> Option<Vector3<f64>> {
    if points.len() < 3 {
        return None;
    }
    let mean = points.iter().map(|p| p.coords).sum::<Vector3<f64>>() / points.len() as f64;
    let covariance = points.iter().map(|p| (p.coords - mean) * (p.coords - mean).transpose()).sum::<Matrix3<f64>>();
    let eigen = SymmetricEigen::new(covariance);
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| eigen.eigenvalues[a].total_cmp(&eigen.eigenvalues[b]));
    let (l0, l1, l2) = (eigen.eigenvalues[order[0]], eigen.eigenvalues[order[1]], eigen.eigenvalues[order[2]]);
    let n = eigen.eigenvectors.column(order[0]).into_owned();
    let flat = points.iter().all(|p| n.dot(&(p.coords - mean)).abs() <= tolerance_m);
    (l1 > 0.0 && l0 < planarity * l1 && l1 >= planarity * l2 && flat).then_some(n)
}

/// Eigenvalues (ascending) and the axes below `ratio` of the largest, of a symmetric 3 × 3 block.
fn weak_axes(block: Matrix3<f64>, ratio: f64) -> ([f64; 3], Vec<Vector3<f64>>) {
    let eigen = SymmetricEigen::new(block);
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| eigen.eigenvalues[a].total_cmp(&eigen.eigenvalues[b]));
    let values = order.map(|k| eigen.eigenvalues[k]);
    let weak = order
        .iter()
        .filter(|&&k| eigen.eigenvalues[k] < ratio * values[2])
        .map(|&k| eigen.eigenvectors.column(k).into_owned())
        .collect();
    (values, weak)
}

/// M: the left perturbation δ of `pose` that an error a = (δθ, δp) of the error state
/// (R Exp(δθ), p + δp) makes, δ = M a, M = [[R, 0], [p^ R, I]] (Exp(δ)·T moves R to
/// R Exp(Rᵀω) and p to p + ω × p + v).
pub fn left_from_error(pose: &Pose3) -> Matrix6 {
    let r = pose.rotation.to_rotation_matrix().into_inner();
    let mut m = Matrix6::zeros();
    m.fixed_view_mut::<3, 3>(0, 0).copy_from(&r);
    m.fixed_view_mut::<3, 3>(3, 0).copy_from(&(hat(&pose.translation.vector) * r));
    m.fixed_view_mut::<3, 3>(3, 3).copy_from(&Matrix3::identity());
    m
}

/// The degeneracy of the scan Hessian `h` at `pose`, measured on a body-centred rotation
/// (Mᵀ H M: in the left perturbation a rotation turns about the map's origin, and its block grows
/// with the distance from it).
fn degeneracy_of(h: &Matrix6, pose: &Pose3, config: &RegistrationConfig) -> Degeneracy {
    let m = left_from_error(pose);
    let in_error = m.transpose() * h * m;
    let (rotation_eigenvalues, weak_rotations) =
        weak_axes(in_error.fixed_view::<3, 3>(0, 0).into_owned(), config.weak_rotation_ratio);
    let (translation_eigenvalues, weak_translations) =
        weak_axes(in_error.fixed_view::<3, 3>(3, 3).into_owned(), config.weak_translation_ratio);
    Degeneracy { rotation_eigenvalues, translation_eigenvalues, weak_rotations, weak_translations }
}

/// Registers `points_in_body` onto `map` from `initial` (see the module notes).
pub fn register_scan(
    points_in_body: &[Point3<f64>],
    map: &LocalMap,
    initial: &Pose3,
    threshold_m: f64,
    kernel_m: f64,
    prior: Option<&Prior>,
    config: &RegistrationConfig,
) -> Result<Registration, RegistrationError> {
    let finite = |p: &Point3<f64>| p.coords.iter().all(|c| c.is_finite());
    let initial_ok = initial.translation.vector.iter().chain(initial.rotation.coords.iter()).all(|c| c.is_finite());
    if !initial_ok {
        return Err(RegistrationError::NonFiniteInitial);
    }
    let kernel2 = (kernel_m * kernel_m).max(1e-12);
    let weight = |r2: f64| (kernel2 / (kernel2 + r2)).powi(2);
    // Planes by map point: kept in the map across scans when it keeps them for these
    // parameters, else for this registration (the map does not change during one).
    let mut planes: FxHashMap<[u64; 3], Option<Vector3<f64>>> = FxHashMap::default();
    let radius = map.config().voxel_m;
    let kept = map.plane_params() == Some(config.plane_params());
    let fit = |q: &Point3<f64>| {
        let around = map.nearest_k(q, config.plane_neighbours, radius);
        plane_normal(&around, config.plane_tolerance_m, config.planarity)
    };
    let mut pose = *initial;
    let (mut iterations, mut converged, mut correspondences) = (0, false, 0);
    let mut h_scan = Matrix6::zeros();
    while iterations < config.max_iterations {
        iterations += 1;
        let mut equations = NormalEquations::new();
        correspondences = 0;
        for s in points_in_body.iter().filter(|s| finite(s)) {
            let p = pose * s;
            let Some((q, _, slot)) = map.nearest_with_plane(&p, threshold_m + radius / 2.0) else { continue };
            let normal = match kept {
                true => *slot.get_or_init(|| fit(&q)),
                false => *planes.entry([q.x.to_bits(), q.y.to_bits(), q.z.to_bits()]).or_insert_with(|| fit(&q)),
            };
            let Some(n) = normal else { continue };
            let (r, j) = point_to_plane::residual(&p, &q, &n);
            if r.abs() > threshold_m {
                continue;
            }
            correspondences += 1;
            equations.add(weight(r * r), r, &j);
        }
        if correspondences < config.min_correspondences {
            return Err(RegistrationError::TooFewCorrespondences {
                found: correspondences,
                required: config.min_correspondences,
                threshold_m,
            });
        }
        h_scan = equations.hessian;
        if let Some(prior) = prior {
            let e0 = se3_log(&(prior.map_from_body.inverse() * pose));
            let j = se3_right_jacobian_inverse(&e0) * se3_adjoint(&pose.inverse());
            equations.hessian += j.transpose() * prior.information * j;
            equations.gradient += j.transpose() * prior.information * e0;
        }
        let Some(step) = equations.step() else { return Err(RegistrationError::Singular) };
        pose = se3_exp(&step) * pose;
        let (rotation, translation) = (step.fixed_rows::<3>(0).norm(), step.fixed_rows::<3>(3).norm());
        if rotation < config.convergence_rad && translation < config.convergence_m {
            converged = true;
            break;
        }
    }
    let degeneracy = degeneracy_of(&h_scan, &pose, config);
    Ok(Registration { map_from_body: pose, converged, iterations, correspondences, degeneracy, scan_hessian: h_scan })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::lie::Tangent3;
    use crate::geometry::pose_from_rpy_translation;
    use crate::odometry::local_map::LocalMapConfig;

    /// Surfaces sampled every 0.1 m: a closed box room (x ∈ [−6, 6], y ∈ [−4, 4], z ∈ [0, 3])
    /// with a pillar, or a corridor along x (walls at y = ±1.5, floor, ceiling) with nothing
    /// that varies along it.
    fn room() -> Vec<Point3<f64>> {
        let mut points = Vec::new();
        let step = 0.1;
        let range = |a: f64, b: f64| (0..((b - a) / step) as usize).map(move |i| a + i as f64 * step);
        for x in range(-6.0, 6.0) {
            for z in range(0.0, 3.0) {
                points.push(Point3::new(x, -4.0, z));
                points.push(Point3::new(x, 4.0, z));
            }
            for y in range(-4.0, 4.0) {
                points.push(Point3::new(x, y, 0.0));
            }
        }
        for y in range(-4.0, 4.0) {
            for z in range(0.0, 3.0) {
                points.push(Point3::new(-6.0, y, z));
                points.push(Point3::new(6.0, y, z));
            }
        }
        for z in range(0.0, 3.0) {
            for a in range(0.0, 1.0) {
                points.push(Point3::new(1.0 + a, 1.0, z));
                points.push(Point3::new(1.0, 1.0 + a, z));
            }
        }
        points
    }

    fn corridor() -> Vec<Point3<f64>> {
        let step = 0.1;
        let range = |a: f64, b: f64| (0..((b - a) / step) as usize).map(move |i| a + i as f64 * step);
        let mut points = Vec::new();
        for x in range(-20.0, 20.0) {
            for z in range(0.0, 3.0) {
                points.push(Point3::new(x, -1.5, z));
                points.push(Point3::new(x, 1.5, z));
            }
            for y in range(-1.5, 1.5) {
                points.push(Point3::new(x, y, 0.0));
                points.push(Point3::new(x, y, 3.0));
            }
        }
        points
    }

    fn map_of(points: &[Point3<f64>]) -> LocalMap {
        let mut map = LocalMap::new(LocalMapConfig { voxel_m: 0.5, ..Default::default() }).unwrap();
        map.insert(points, &Point3::new(0.0, 0.0, 1.5));
        map
    }

    /// The scan the body at `map_from_body` sees of `world` (every point, in its frame).
    fn scan(world: &[Point3<f64>], map_from_body: &Pose3) -> Vec<Point3<f64>> {
        world.iter().map(|p| map_from_body.inverse() * p).collect()
    }

    fn error(a: &Pose3, b: &Pose3) -> (f64, f64) {
        let d = a.inverse() * b;
        (d.translation.vector.norm(), d.rotation.angle())
    }

    #[test]
    fn a_closed_room_is_registered_exactly_and_nothing_is_weak() {
        let world = room();
        let map = map_of(&world);
        let truth = pose_from_rpy_translation(0.01, -0.02, 0.3, Vector3::new(0.5, -0.3, 0.1));
        let initial = pose_from_rpy_translation(0.0, 0.0, 0.25, Vector3::new(0.3, -0.1, 0.0));
        let r = register_scan(&scan(&world, &truth), &map, &initial, 1.0, 0.3, None, &RegistrationConfig::default())
            .unwrap();
        let (t, a) = error(&r.map_from_body, &truth);
        assert!(r.converged && t < 0.02 && a < 2e-3, "{t} m {a} rad after {} iterations", r.iterations);
        assert!(!r.degeneracy.is_degenerate(), "{:?}", r.degeneracy);
    }

    #[test]
    fn a_corridor_is_weak_along_its_axis_and_the_prior_holds_it_there() {
        let world = corridor();
        let map = map_of(&world);
        let truth = pose_from_rpy_translation(0.0, 0.0, 0.05, Vector3::new(2.0, 0.2, 0.0));
        let initial = pose_from_rpy_translation(0.0, 0.0, 0.0, Vector3::new(2.3, 0.0, 0.0));
        let config = RegistrationConfig::default();
        let free = register_scan(&scan(&world, &truth), &map, &initial, 1.0, 0.3, None, &config).unwrap();
        assert_eq!(free.degeneracy.weak_translations.len(), 1, "{:?}", free.degeneracy);
        assert!(free.degeneracy.weak_translations[0].x.abs() > 0.99, "{:?}", free.degeneracy);
        assert!(free.degeneracy.weak_rotations.is_empty(), "{:?}", free.degeneracy);
        // A loose prior (0.1 m, 0.01 rad) right along the corridor but 0.05 m and 0.01 rad off
        // across it: the well-seen directions follow the scan, the corridor's axis the prior.
        let mut information = Matrix6::zeros();
        for k in 0..3 {
            information[(k, k)] = 1e4;
            information[(k + 3, k + 3)] = 100.0;
        }
        let off = pose_from_rpy_translation(0.0, 0.0, 0.06, Vector3::new(2.0, 0.25, 0.0));
        let prior = Prior { map_from_body: off, information };
        let held = register_scan(&scan(&world, &truth), &map, &initial, 1.0, 0.3, Some(&prior), &config).unwrap();
        let (t, a) = error(&held.map_from_body, &truth);
        assert!(t < 0.01 && a < 1e-3, "{t} m {a} rad: {}", held.map_from_body);
    }

    #[test]
    fn the_prior_jacobian_matches_numeric_differentiation() {
        let pose = pose_from_rpy_translation(0.2, -0.1, 0.7, Vector3::new(1.0, 2.0, -0.5));
        let predicted = pose_from_rpy_translation(0.25, -0.05, 0.6, Vector3::new(1.3, 1.8, -0.4));
        let e = |t: &Pose3| se3_log(&(predicted.inverse() * t));
        let e0 = e(&pose);
        let j = se3_right_jacobian_inverse(&e0) * se3_adjoint(&pose.inverse());
        let h = 1e-6;
        for k in 0..6 {
            let mut d = Tangent3::zeros();
            d[k] = h;
            let numeric = (e(&(se3_exp(&d) * pose)) - e(&(se3_exp(&(-d)) * pose))) / (2.0 * h);
            assert!((numeric - j.column(k)).norm() < 1e-6, "column {k}: {numeric} vs {}", j.column(k));
        }
    }

    #[test]
    fn bad_input_is_refused_by_name() {
        let map = map_of(&room());
        let config = RegistrationConfig::default();
        let nan = pose_from_rpy_translation(0.0, 0.0, 0.0, Vector3::new(f64::NAN, 0.0, 0.0));
        let scan_points = scan(&room(), &Pose3::identity());
        assert_eq!(
            register_scan(&scan_points, &map, &nan, 1.0, 0.3, None, &config),
            Err(RegistrationError::NonFiniteInitial)
        );
        let empty = register_scan(&[], &map, &Pose3::identity(), 1.0, 0.3, None, &config).unwrap_err();
        assert_eq!(empty.to_string(), "0 correspondences within 1.00 m, need 20");
        let garbage = vec![Point3::new(f64::NAN, 0.0, 0.0); 100];
        assert!(register_scan(&garbage, &map, &Pose3::identity(), 1.0, 0.3, None, &config).is_err());
    }
}
