//! Iterative closest point (paper §IV-D: inter-robot registration; LIO-SAM-style intra-robot
//! loop verification).
//!
//! Each iteration pairs every (downsampled) source point p = T s with its nearest target point
//! q (kd-tree) within `max_correspondence_distance_m`, then solves a Gauss–Newton step for a left
//! perturbation T ← Exp(δ) T, δ = (ω, v):
//! * point-to-point: r = p − q, ∂r/∂δ = [−p^, I];
//! * point-to-plane: r = nᵀ(p − q) with n the target normal, ∂r/∂δ = [(p × n)ᵀ, nᵀ]
//!   (`geometry::point_to_plane`, the step the odometry's registration takes too);
//!
//! weighted by a Huber kernel on |r| (scale `huber_m`). Stops when the step is below
//! `convergence_rotation_rad` and `convergence_translation_m`, or after `max_iterations`.
//! Reports, from the last correspondence pass (the step after it is below the convergence
//! thresholds), fitness (fraction of source points with a correspondence), inlier RMSE, and the
//! information matrix H = Σ Jᵀ J / RMSE² converted to the optimiser's chart (right
//! perturbation of `target_from_source`: H_right = Adᵀ H Ad), usable as a between factor.
//!
//! A pass's searches and normal fits are per point, so [`register_to`] may split them over
//! [`Workers`]; the sums are still taken one point at a time in source order, so the answer is
//! the same, bit for bit, for any number of threads (`split_passes_answer_as_one_thread`).

use super::level_icp;
use super::normals;
use crate::geometry::lie::{se3_adjoint, se3_exp, Matrix6, Tangent3};
use crate::geometry::point_to_plane::{self, NormalEquations};
use crate::geometry::Pose3;
use crate::spatial::neighbour_graph::NeighbourGraph;
use crate::spatial::voxel::Downsampler;
use crate::workers::Workers;
use nalgebra::{Matrix3, Point3, Vector3};

/// Error metric.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum IcpMethod {
    PointToPoint,
    #[default]
    PointToPlane,
}

/// ICP parameters.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct IcpConfig {
    pub method: IcpMethod,
    /// Pairs farther apart are not correspondences, m. Default 1.0.
    pub max_correspondence_distance_m: f64,
    /// Voxel size applied to both clouds first (0: none), m. Default 0.
    pub voxel_m: f64,
    /// Neighbours for target normals (point-to-plane), searched within the correspondence
    /// distance. Default 10.
    pub normal_neighbours: usize,
    /// Huber kernel scale on residuals, m. Default 0.1.
    pub huber_m: f64,
    /// Default 50.
    pub max_iterations: usize,
    /// Step size below which ICP has converged. Defaults 1e-6 rad, 1e-6 m.
    pub convergence_rotation_rad: f64,
    pub convergence_translation_m: f64,
    /// Smallest fitness of a converged registration (non-overlapping clouds fail it). Default 0.3.
    pub min_fitness: f64,
}

impl Default for IcpConfig {
    fn default() -> Self {
        Self {
            method: IcpMethod::PointToPlane,
            max_correspondence_distance_m: 1.0,
            voxel_m: 0.0,
            normal_neighbours: 10,
            huber_m: 0.1,
            max_iterations: 50,
            convergence_rotation_rad: 1e-6,
            convergence_translation_m: 1e-6,
            min_fitness: 0.3,
        }
    }
}

/// What ICP found.
#[derive(Clone, Debug, PartialEq)]
pub struct IcpResult {
    /// p_target = target_from_source · p_source.
    pub target_from_source: Pose3,
    /// Numerically converged and fitness ≥ `min_fitness`.
    pub converged: bool,
    pub fitness: f64,
    pub rmse_m: f64,
    pub iterations: usize,
    /// Information of `target_from_source` over (ω, v), right perturbation.
    pub information: Matrix6,
}

/// What a registration estimates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Freedom {
    /// The whole relative pose.
    Full,
    /// x, y, z and yaw about the world's up seen in the target body (unit): the relative tilt
    /// stays the initial guess's ([`super::level_icp`]).
    Level(Vector3<f64>),
}

/// Inputs ICP cannot use.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum IcpError {
    #[error("the {0} cloud has fewer than 3 finite points")]
    TooFewPoints(&'static str),
    #[error("parameter {0} is out of range")]
    Parameter(&'static str),
}

/// A target cloud made ready for registration once — its finite points (downsampled by
/// `voxel_m`), kd-tree, neighbour lists, reach and normals, all built as first needed — for any
/// number of sources: a round registers several neighbour keyframes onto one local keyframe.
/// Each answer is the same as a fresh [`register`]'s: what is kept depends on the cloud alone.
pub struct IcpTarget {
    graph: NeighbourGraph<'static>,
    /// Per point: its normal (`None` inside: too few neighbours), once fitted.
    normals: Vec<Option<Option<Vector3<f64>>>>,
    /// The settings it was made with: voxel size, neighbours, correspondence distance (bits).
    made_with: (u64, usize, u64),
}

fn checked(config: &IcpConfig) -> Result<(), IcpError> {
    let positive = |v: f64| v.is_finite() && v > 0.0;
    if !positive(config.max_correspondence_distance_m) || !positive(config.huber_m) || config.max_iterations == 0 {
        return Err(IcpError::Parameter("max_correspondence_distance_m, huber_m or max_iterations"));
    }
    Ok(())
}

/// The finite points of a cloud (about `expected` of them), downsampled by `voxel_m` when it is
/// finite and positive.
fn prepared_from(
    points: impl IntoIterator<Item = Point3<f64>>,
    expected: usize,
    config: &IcpConfig,
) -> Vec<Point3<f64>> {
    let finite = points.into_iter().filter(|p| p.coords.iter().all(|v| v.is_finite()));
    if !(config.voxel_m.is_finite() && config.voxel_m > 0.0) {
        return finite.collect();
    }
    let mut voxels = Downsampler::new(config.voxel_m, expected);
    finite.for_each(|p| voxels.add(&p));
    voxels.centroids()
}

fn prepared(points: &[Point3<f64>], config: &IcpConfig) -> Vec<Point3<f64>> {
    prepared_from(points.iter().copied(), points.len(), config)
}

fn made_with(config: &IcpConfig) -> (u64, usize, u64) {
    (config.voxel_m.to_bits(), config.normal_neighbours.max(3), config.max_correspondence_distance_m.to_bits())
}

impl IcpTarget {
    /// `target` made ready for registrations with `config` (its voxel size, normal neighbours
    /// and correspondence distance).
    pub fn new(target: &[Point3<f64>], config: &IcpConfig) -> Result<Self, IcpError> {
        checked(config)?;
        Self::from_prepared(prepared(target, config), config)
    }

    /// [`IcpTarget::new`] on a cloud gathered point by point (about `expected` of them, e.g. a
    /// submap of several scans), never collected whole: the same target.
    pub fn gathered(
        target: impl IntoIterator<Item = Point3<f64>>,
        expected: usize,
        config: &IcpConfig,
    ) -> Result<Self, IcpError> {
        checked(config)?;
        Self::from_prepared(prepared_from(target, expected, config), config)
    }

    fn from_prepared(target: Vec<Point3<f64>>, config: &IcpConfig) -> Result<Self, IcpError> {
        if target.len() < 3 {
            return Err(IcpError::TooFewPoints("target"));
        }
        let normals = vec![None; target.len()];
        // Target normals from each point's k nearest within the correspondence distance,
        // fitted when a source point first pairs with it; the same lists start each pass's
        // searches from the last pass's answers.
        let graph = NeighbourGraph::new(target, config.normal_neighbours.max(3), config.max_correspondence_distance_m);
        Ok(Self { graph, normals, made_with: made_with(config) })
    }
}

/// Registers `source` to `target` starting from `initial` (target_from_source).
pub fn register(
    source: &[Point3<f64>],
    target: &[Point3<f64>],
    initial: &Pose3,
    config: &IcpConfig,
) -> Result<IcpResult, IcpError> {
    checked(config)?;
    let source = prepared(source, config);
    if source.len() < 3 {
        return Err(IcpError::TooFewPoints("source"));
    }
    let mut target = IcpTarget::from_prepared(prepared(target, config), config)?;
    register_prepared(&source, &mut target, initial, config, &Workers::sequential(), Freedom::Full)
}

/// [`register`] onto a target made ready by [`IcpTarget::new`] with the same voxel size,
/// normal neighbours and correspondence distance as `config` (otherwise
/// [`IcpError::Parameter`]), estimating what `freedom` allows.
pub fn register_to(
    source: &[Point3<f64>],
    target: &mut IcpTarget,
    initial: &Pose3,
    config: &IcpConfig,
    workers: &Workers,
    freedom: Freedom,
) -> Result<IcpResult, IcpError> {
    checked(config)?;
    if target.made_with != made_with(config) {
        return Err(IcpError::Parameter(
            "voxel_m, normal_neighbours or max_correspondence_distance_m (not the target's)",
        ));
    }
    let source = prepared(source, config);
    if source.len() < 3 {
        return Err(IcpError::TooFewPoints("source"));
    }
    register_prepared(&source, target, initial, config, workers, freedom)
}

fn register_prepared(
    source: &[Point3<f64>],
    target: &mut IcpTarget,
    initial: &Pose3,
    config: &IcpConfig,
    workers: &Workers,
    freedom: Freedom,
) -> Result<IcpResult, IcpError> {
    let mut last_match: Vec<Option<usize>> = vec![None; source.len()];
    let mut pose = *initial;
    let mut iterations = 0;
    let mut step_converged = false;
    // Sums of the last correspondence pass (before its small final step).
    let mut sums = PassSums::default();
    while iterations < config.max_iterations {
        iterations += 1;
        sums = pass(source, target, &pose, &mut last_match, config, workers);
        if sums.pairs < 6 {
            break;
        }
        let step = match &freedom {
            Freedom::Full => sums.equations.step(),
            Freedom::Level(up) => level_icp::step(&sums.equations.hessian, &sums.equations.gradient, up),
        };
        let Some(delta) = step else { break };
        pose = se3_exp(&delta) * pose;
        let (w, v) = (delta.fixed_rows::<3>(0).norm(), delta.fixed_rows::<3>(3).norm());
        if w < config.convergence_rotation_rad && v < config.convergence_translation_m {
            step_converged = true;
            break;
        }
    }
    let h = sums.unweighted.gram();
    let fitness = sums.inliers as f64 / source.len() as f64;
    let rmse_m = if sums.inliers > 0 { (sums.sum2 / sums.inliers as f64).sqrt() } else { f64::INFINITY };
    let noise2 = rmse_m.max(1e-4).powi(2);
    let left = match &freedom {
        Freedom::Full => h / noise2,
        Freedom::Level(up) => level_icp::information(&(h / noise2), up),
    };
    let ad = se3_adjoint(&pose);
    let information = ad.transpose() * left * ad;
    Ok(IcpResult {
        target_from_source: pose,
        converged: step_converged && fitness >= config.min_fitness,
        fitness,
        rmse_m,
        iterations,
        information,
    })
}

/// Source points (or target normals) a thread takes at least, when a pass is split.
const MIN_SPLIT: usize = 256;

/// One correspondence pass at `pose`: each source point paired with its nearest target point
/// (its hint updated), the normal equations summed in source order.
///
/// Split over `workers`, the pass runs in three stages, each point's and each normal's answer a
/// function of the cloud alone: the nearest points, searched in pieces of the source on the
/// shared target (lists a piece lacks computed aside, kept afterwards); the normals the pairs
/// need and the target lacks, each fitted once, in pieces; the sums, in source order. So the
/// pass is the same, bit for bit, for any number of threads.
fn pass(
    source: &[Point3<f64>],
    target: &mut IcpTarget,
    pose: &Pose3,
    last_match: &mut [Option<usize>],
    config: &IcpConfig,
    workers: &Workers,
) -> PassSums {
    let mut sums = PassSums::default();
    let max_d2 = config.max_correspondence_distance_m.powi(2);
    let IcpTarget { graph, normals: target_normals, .. } = target;
    let shared = graph.shared();
    let hints: &[Option<usize>] = last_match;
    let found = workers.split(source.len(), MIN_SPLIT, |range| {
        let mut search = shared.search();
        let found: Vec<_> = range.map(|i| search.nearest_within(&(pose * source[i]), hints[i])).collect();
        (found, search.into_aside())
    });
    let Some(found) = found else {
        for (s, last) in source.iter().zip(last_match.iter_mut()) {
            let p = pose * s;
            let Some((d2, item)) = graph.nearest_within(&p, *last) else { continue };
            *last = Some(item);
            if d2 <= max_d2 {
                let normal = match config.method {
                    IcpMethod::PointToPlane => own_normal(graph, target_normals, item),
                    IcpMethod::PointToPoint => None,
                };
                sums.add(&Pair { p, q: graph.points()[item], d2, normal }, config);
            }
        }
        return sums.finished(config);
    };
    let mut nearest = Vec::with_capacity(source.len());
    for (piece, lists) in found {
        graph.absorb(lists);
        nearest.extend(piece);
    }
    if config.method == IcpMethod::PointToPlane {
        fit_normals(graph, target_normals, &nearest, max_d2, workers);
    }
    for ((s, last), found) in source.iter().zip(last_match.iter_mut()).zip(nearest) {
        let Some((d2, item)) = found else { continue };
        *last = Some(item);
        if d2 <= max_d2 {
            let normal = target_normals[item].flatten();
            sums.add(&Pair { p: pose * s, q: graph.points()[item], d2, normal }, config);
        }
    }
    sums.finished(config)
}

/// Target point `item`'s normal, fitted on first need.
fn own_normal(
    graph: &mut NeighbourGraph<'static>,
    normals: &mut [Option<Option<Vector3<f64>>>],
    item: usize,
) -> Option<Vector3<f64>> {
    if let Some(known) = normals[item] {
        return known;
    }
    let (points, around) = graph.neighbours_in(item);
    *normals[item].insert(normals::of_neighbours(points, around.iter().map(|&j| j as usize)))
}

/// Fits the normals of the target points `nearest` pairs with (within the distance) that it
/// lacks, each once, in pieces over `workers`.
fn fit_normals(
    graph: &mut NeighbourGraph<'static>,
    normals: &mut [Option<Option<Vector3<f64>>>],
    nearest: &[Option<(f64, usize)>],
    max_d2: f64,
    workers: &Workers,
) {
    let mut lacking: Vec<usize> =
        nearest.iter().flatten().filter(|(d2, item)| *d2 <= max_d2 && normals[*item].is_none()).map(|n| n.1).collect();
    lacking.sort_unstable();
    lacking.dedup();
    let shared = graph.shared();
    let fit = |range: std::ops::Range<usize>| {
        let mut search = shared.search();
        let fitted: Vec<_> = lacking[range]
            .iter()
            .map(|&item| {
                let (points, around) = search.neighbours_in(item);
                (item, normals::of_neighbours(points, around.iter().map(|&j| j as usize)))
            })
            .collect();
        (fitted, search.into_aside())
    };
    let pieces = workers.split(lacking.len(), MIN_SPLIT, fit).unwrap_or_else(|| vec![fit(0..lacking.len())]);
    for (fitted, lists) in pieces {
        graph.absorb(lists);
        for (item, normal) in fitted {
            normals[item] = Some(normal);
        }
    }
}

/// A source point p and its correspondence q within the distance (d² = ‖p − q‖²), with q's
/// normal (point-to-plane; `None`: none could be fitted).
struct Pair {
    p: Point3<f64>,
    q: Point3<f64>,
    d2: f64,
    normal: Option<Vector3<f64>>,
}

/// What a pass sums over its pairs, in source order.
#[derive(Default)]
struct PassSums {
    weighted: Moments,
    equations: NormalEquations,
    /// Pairs in the equations; inliers (pairs within the distance), Σ d² and moments of them.
    pairs: usize,
    inliers: usize,
    sum2: f64,
    unweighted: Moments,
}

impl PassSums {
    fn add(&mut self, pair: &Pair, config: &IcpConfig) {
        let huber = |r: f64| if r.abs() <= config.huber_m { 1.0 } else { config.huber_m / r.abs() };
        let Pair { p, q, d2, normal } = pair;
        self.inliers += 1;
        self.sum2 += d2;
        self.unweighted.add(1.0, &p.coords);
        match config.method {
            IcpMethod::PointToPlane => {
                let Some(n) = normal else { return };
                let (r, j) = point_to_plane::residual(p, q, n);
                self.equations.add(huber(r), r, &j);
            }
            IcpMethod::PointToPoint => {
                let e = p - q;
                let w = huber(e.norm());
                self.weighted.add(w, &p.coords);
                let (gw, gv) = (w * p.coords.cross(&e), w * e);
                self.equations.gradient += Tangent3::new(gw.x, gw.y, gw.z, gv.x, gv.y, gv.z);
            }
        }
        self.pairs += 1;
    }

    /// The sums once every pair is in (point-to-point: Σ w JᵀJ from the moments).
    fn finished(mut self, config: &IcpConfig) -> Self {
        if config.method == IcpMethod::PointToPoint {
            self.equations.hessian = self.weighted.gram();
        }
        self
    }
}

/// Weighted moments of the transformed source points p, enough for Σ w Jᵀ J of the
/// point-to-point Jacobian J = [−p^, I] without forming J per point:
/// Σ w Jᵀ J = [[Σw(|p|² I − p pᵀ), (Σ w p)^], [−(Σ w p)^, (Σ w) I]].
#[derive(Default)]
struct Moments {
    weight: f64,
    first: Vector3<f64>,
    second: Matrix3<f64>,
}

impl Moments {
    fn add(&mut self, w: f64, p: &Vector3<f64>) {
        self.weight += w;
        self.first.axpy(w, p, 1.0);
        self.second.ger(w, p, p, 1.0);
    }

    fn gram(&self) -> Matrix6 {
        let mut m = Matrix6::zeros();
        let skew = self.first.cross_matrix();
        m.fixed_view_mut::<3, 3>(0, 0).copy_from(&(Matrix3::identity() * self.second.trace() - self.second));
        m.fixed_view_mut::<3, 3>(0, 3).copy_from(&skew);
        m.fixed_view_mut::<3, 3>(3, 0).copy_from(&(-skew));
        m.fixed_view_mut::<3, 3>(3, 3).copy_from(&(Matrix3::identity() * self.weight));
        m
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{pose_error, pose_from_rpy_translation};
    use proptest::prelude::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use crate::perception::synthetic_room::box_room as room;

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(24))]
        #[test]
        fn recovers_known_transforms(r in -0.1f64..0.1, p in -0.1f64..0.1, y in -0.3f64..0.3, t in prop::array::uniform3(-0.4f64..0.4), plane in proptest::bool::ANY) {
            let target = room(4000, 1);
            let truth = pose_from_rpy_translation(r, p, y, Vector3::new(t[0], t[1], t[2]));
            // Source: the same room seen from elsewhere, sampled independently.
            let source: Vec<Point3<f64>> = room(4000, 2).iter().map(|q| truth.inverse() * q).collect();
            let config = IcpConfig { method: if plane { IcpMethod::PointToPlane } else { IcpMethod::PointToPoint }, max_iterations: 100, ..IcpConfig::default() };
            let result = register(&source, &target, &Pose3::identity(), &config).unwrap();
            let e = pose_error(&result.target_from_source, &truth);
            let (t_tol, r_tol) = if plane { (0.01, 0.2) } else { (0.05, 1.0) };
            prop_assert!(result.converged, "{result:?}");
            prop_assert!(e.translation_m < t_tol && e.max_axis_rotation_deg() < r_tol, "{e:?}");
            prop_assert!(result.fitness > 0.95);
        }
    }

    #[test]
    fn non_overlapping_clouds_do_not_converge() {
        let target = room(3000, 1);
        let far: Vec<Point3<f64>> = room(3000, 2).iter().map(|q| q + Vector3::new(50.0, 0.0, 0.0)).collect();
        let result = register(&far, &target, &Pose3::identity(), &IcpConfig::default()).unwrap();
        assert!(!result.converged && result.fitness < 0.3, "{result:?}");
        assert_eq!(
            register(&[Point3::origin()], &target, &Pose3::identity(), &IcpConfig::default()),
            Err(IcpError::TooFewPoints("source"))
        );
    }

    /// One target made ready serves several sources with the answers fresh registrations give,
    /// bit for bit, whatever came before; a config it was not made with is refused.
    #[test]
    fn a_ready_target_answers_as_a_fresh_one() {
        let target = room(3000, 1);
        for method in [IcpMethod::PointToPlane, IcpMethod::PointToPoint] {
            let config = IcpConfig { method, voxel_m: 0.1, max_iterations: 30, ..IcpConfig::default() };
            let mut ready = IcpTarget::new(&target, &config).unwrap();
            // Gathered point by point, with a non-finite point among them and a poor size guess.
            let mut gathered =
                IcpTarget::gathered(target.iter().copied().chain([Point3::new(f64::NAN, 0.0, 0.0)]), 7, &config)
                    .unwrap();
            for seed in 2..6 {
                let truth = pose_from_rpy_translation(0.02, -0.01, 0.1 * seed as f64, Vector3::new(0.2, -0.1, 0.05));
                let source: Vec<Point3<f64>> = room(2000, seed).iter().map(|q| truth.inverse() * q).collect();
                let fresh = register(&source, &target, &Pose3::identity(), &config).unwrap();
                let one = Workers::sequential();
                assert_eq!(
                    register_to(&source, &mut ready, &Pose3::identity(), &config, &one, Freedom::Full).unwrap(),
                    fresh
                );
                assert_eq!(
                    register_to(&source, &mut gathered, &Pose3::identity(), &config, &one, Freedom::Full).unwrap(),
                    fresh
                );
            }
            let other = IcpConfig { max_correspondence_distance_m: 0.5, ..config.clone() };
            assert!(matches!(
                register_to(
                    &room(500, 9),
                    &mut ready,
                    &Pose3::identity(),
                    &other,
                    &Workers::sequential(),
                    Freedom::Full
                ),
                Err(IcpError::Parameter(_))
            ));
        }
        assert_eq!(IcpTarget::new(&target[..2], &IcpConfig::default()).err(), Some(IcpError::TooFewPoints("target")));
    }

    /// A registration whose passes are split over threads answers as one thread does, bit for
    /// bit: on a fresh target, and on one that earlier registrations (split or not) made ready.
    #[test]
    fn split_passes_answer_as_one_thread() {
        let pool = std::sync::Arc::new(rayon::ThreadPoolBuilder::new().num_threads(3).build().unwrap());
        let (split, one) = (Workers::on(pool), Workers::sequential());
        let target = room(6000, 1);
        for method in [IcpMethod::PointToPlane, IcpMethod::PointToPoint] {
            let config = IcpConfig { method, max_iterations: 30, ..IcpConfig::default() };
            let mut shared = IcpTarget::new(&target, &config).unwrap();
            for seed in 2..6 {
                let truth = pose_from_rpy_translation(0.02, -0.01, 0.05 * seed as f64, Vector3::new(0.3, -0.1, 0.05));
                // Far more points than one piece: every pass is split.
                let source: Vec<Point3<f64>> = room(4000, seed).iter().map(|q| truth.inverse() * q).collect();
                assert!(split.split(source.len(), MIN_SPLIT, |r| r).is_some_and(|pieces| pieces.len() > 2));
                let mut fresh = IcpTarget::new(&target, &config).unwrap();
                let alone = register_to(&source, &mut fresh, &Pose3::identity(), &config, &one, Freedom::Full).unwrap();
                assert!(alone.fitness > 0.9, "{alone:?}");
                let mut fresh = IcpTarget::new(&target, &config).unwrap();
                assert_eq!(
                    register_to(&source, &mut fresh, &Pose3::identity(), &config, &split, Freedom::Full).unwrap(),
                    alone
                );
                let workers = if seed % 2 == 0 { &split } else { &one };
                assert_eq!(
                    register_to(&source, &mut shared, &Pose3::identity(), &config, workers, Freedom::Full).unwrap(),
                    alone
                );
            }
        }
    }

    #[test]
    fn moments_give_the_explicit_gram_matrix() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let mut moments = Moments::default();
        let mut explicit = Matrix6::zeros();
        for _ in 0..50 {
            let p = Vector3::new(rng.random_range(-9.0..9.0), rng.random_range(-9.0..9.0), rng.random_range(-2.0..2.0));
            let w = rng.random_range(0.1..1.0);
            let mut j = nalgebra::SMatrix::<f64, 3, 6>::zeros();
            j.fixed_view_mut::<3, 3>(0, 0).copy_from(&(-p.cross_matrix()));
            j.fixed_view_mut::<3, 3>(0, 3).copy_from(&Matrix3::identity());
            explicit += w * j.transpose() * j;
            moments.add(w, &p);
        }
        assert!((moments.gram() - explicit).norm() < 1e-9 * explicit.norm());
    }

    #[test]
    fn information_is_symmetric_positive_definite_on_a_room() {
        let target = room(3000, 1);
        let source = room(3000, 3);
        let result = register(&source, &target, &Pose3::identity(), &IcpConfig::default()).unwrap();
        assert!((result.information - result.information.transpose()).norm() < 1e-6 * result.information.norm());
        assert!(result.information.symmetric_eigenvalues().min() > 0.0);
    }
}
