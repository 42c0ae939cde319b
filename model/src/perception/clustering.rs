//! Object candidates from labelled points (paper §IV-A: "the labeled point cloud is clustered into
//! distinct objects"): within each class, points are binned into voxels of side `tolerance_m`
//! and occupied voxels that touch (26-neighbourhood) form one cluster — connected components by
//! union–find over the sorted voxel keys, near-linear in the number of points. Two points in
//! one cluster are linked by a chain of steps shorter than 2√3 · tolerance; points farther than
//! 2 · tolerance from every other voxel's points are never joined.
//!
//! Pieces of one column are then joined (`merge_stacked`): a LiDAR leaves gaps along a tall
//! object (the beams of a Livox or spinning pattern fan out with height, an occluder cuts a
//! lamp post or a bookshelf in two), and two pieces of one object become two candidates, then
//! two map objects one above the other: a duplicate the tracker cannot join, because one
//! keyframe's candidates are assigned to distinct objects. Two clusters of one class are one
//! column when their footprints (the xy boxes, grown by half a voxel each way) overlap by at
//! least half the smaller one:
//!
//! ```text
//! |F_a ∩ F_b| ≥ ½ min(|F_a|, |F_b|),   F = [lo.x − t/2, hi.x + t/2] × [lo.y − t/2, hi.y + t/2]
//! ```
//!
//! (t: `tolerance_m`; joined transitively). Objects of one class do not stand on each other in
//! the worlds we model; different classes (a chair under a table) are never joined. Clusters
//! are kept when their point count and extent are plausible for the class.
//!
//! Extents (a candidate's size, the footprints above, the height test) are measured along the
//! axes of the frame the caller names, `axes_from_points`: the rotation of the odometry frame
//! from the body frame, gravity-aligned when an IMU is present and turned like the map up to
//! drift. A bench 2 m long along the world's x then has size (2, 0.5, ·) whichever way the robot
//! faced, the tracker and the object cloud read it along the map's axes, and a column stays a
//! column on a tilted body. Clustering itself (the voxels) and the centroid are in the points'
//! own frame.
//!
//! The far side (beyond the paper; issue 31). A cluster's returns lie on the side the sensor
//! sees, so their mean c̄ is short of the object's centre: by 2r/π for a round object of radius
//! r. The centroid is moved away from the sensor (the points' origin), horizontally, along the
//! measuring axes:
//!
//! ```text
//! c = c̄ + κ · ½ w⊥ · û,   û = c̄_xy / ‖c̄_xy‖,   w⊥ = extent of the returns across û
//! ```
//!
//! (κ: `far_side_shift`, 2/π by default, which puts a round object's centre on its axis; a box
//! seen corner-on wants ½, face-on 1, and an elongated one seen broadside is moved too far).
//! The horizontal box is then made symmetric about the moved centre, reaching every return;
//! the height is the returns' extent. The class's extent limit is checked on the returns'
//! extent, before the box is made symmetric.

use crate::scene_graph::LabelId;
use nalgebra::{Point3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// Plausibility limits of one class's clusters.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ClassLimits {
    pub min_points: usize,
    pub max_points: usize,
    /// Largest axis-aligned extent, m.
    pub max_extent_m: f64,
}

impl Default for ClassLimits {
    fn default() -> Self {
        Self { min_points: 10, max_points: 50_000, max_extent_m: 10.0 }
    }
}

/// Clustering parameters.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ClusterConfig {
    /// Voxel side: points in touching voxels of this size join one cluster, m. Default 0.3.
    pub tolerance_m: f64,
    /// Limits for classes without their own entry.
    pub default_limits: ClassLimits,
    /// Per-class limits, by class id.
    pub classes: BTreeMap<u16, ClassLimits>,
    /// Clusters flatter than this along the vertical are refused (labels bleeding onto the
    /// ground behind an object), m. Default 0: off.
    pub min_height_m: f64,
    /// Join clusters of one class stacked in one column (module doc). Default true.
    pub merge_stacked: bool,
    /// κ of the far-side shift (module doc, "The far side"): the centroid moves away from the
    /// sensor by κ times half the cluster's width across the line of sight. 0: off. Default 2/π.
    pub far_side_shift: f64,
}

impl Default for ClusterConfig {
    fn default() -> Self {
        Self {
            tolerance_m: 0.3,
            default_limits: ClassLimits::default(),
            classes: BTreeMap::new(),
            min_height_m: 0.0,
            merge_stacked: true,
            far_side_shift: std::f64::consts::FRAC_2_PI,
        }
    }
}

/// One cluster: an object candidate.
#[derive(Clone, Debug, PartialEq)]
pub struct ObjectCandidate {
    pub label: LabelId,
    pub centroid: Point3<f64>,
    /// Extent along the axes of `axes_from_points` (module doc), m: horizontally a box
    /// symmetric about the (far-side) centroid that reaches every return, vertically the
    /// returns' extent.
    pub size: Vector3<f64>,
    pub points: usize,
}

/// Clusters `points` by class (`labels[k]` is point k's class; `None` points are ignored),
/// measuring extents along the axes of `axes_from_points` (module doc).
/// Output is ordered by class, then by each cluster's first point: deterministic.
pub fn cluster(
    points: &[Point3<f64>],
    labels: &[Option<LabelId>],
    config: &ClusterConfig,
    axes_from_points: &UnitQuaternion<f64>,
) -> Vec<ObjectCandidate> {
    let mut by_class: BTreeMap<LabelId, Vec<usize>> = BTreeMap::new();
    for (k, (p, l)) in points.iter().zip(labels).enumerate() {
        if let Some(l) = l {
            if p.coords.iter().all(|v| v.is_finite()) {
                by_class.entry(*l).or_default().push(k);
            }
        }
    }
    let size = config.tolerance_m;
    let mut out = Vec::new();
    if !size.is_finite() || size <= 0.0 {
        return out;
    }
    for (label, members) in by_class {
        let limits = config.classes.get(&label.0).unwrap_or(&config.default_limits);
        // Voxel key of every member, members sorted by key: equal keys are contiguous.
        let key = |k: usize| {
            let p = points[k];
            [(p.x / size).floor() as i64, (p.y / size).floor() as i64, (p.z / size).floor() as i64]
        };
        let mut keyed: Vec<([i64; 3], usize)> = members.iter().map(|&k| (key(k), k)).collect();
        keyed.sort_unstable();
        let mut voxels: Vec<[i64; 3]> = Vec::new();
        let mut voxel_of = Vec::with_capacity(keyed.len());
        for (kk, _) in &keyed {
            if voxels.last() != Some(kk) {
                voxels.push(*kk);
            }
            voxel_of.push(voxels.len() - 1);
        }
        // Union–find over voxels, joining each voxel to its 13 "forward" neighbours.
        let mut parent: Vec<usize> = (0..voxels.len()).collect();
        for (v, k) in voxels.iter().enumerate() {
            for dx in -1..=1i64 {
                for dy in -1..=1i64 {
                    for dz in -1..=1i64 {
                        if (dx, dy, dz) <= (0, 0, 0) {
                            continue;
                        }
                        let neighbour = [k[0] + dx, k[1] + dy, k[2] + dz];
                        if let Ok(w) = voxels.binary_search(&neighbour) {
                            unite(&mut parent, v, w);
                        }
                    }
                }
            }
        }
        // Gather clusters in order of their first point (smallest index).
        let mut clusters: BTreeMap<usize, Vec<usize>> = BTreeMap::new();
        let mut first_of_root: BTreeMap<usize, usize> = BTreeMap::new();
        for (i, &(_, k)) in keyed.iter().enumerate() {
            let r = root(&mut parent, voxel_of[i]);
            first_of_root.entry(r).and_modify(|f| *f = (*f).min(k)).or_insert(k);
            clusters.entry(r).or_default().push(k);
        }
        let mut ordered: Vec<(usize, Vec<usize>)> =
            clusters.into_iter().map(|(r, pts)| (first_of_root.get(&r).copied().unwrap_or(usize::MAX), pts)).collect();
        ordered.sort_by_key(|(first, _)| *first);
        let mut pieces: Vec<Piece> =
            ordered.iter().map(|(_, members)| Piece::of(points, members, axes_from_points)).collect();
        if config.merge_stacked {
            pieces = join_columns(pieces, size);
        }
        for piece in pieces {
            if piece.count < limits.min_points || piece.count > limits.max_points {
                continue;
            }
            let extent = piece.hi - piece.lo;
            if extent.max() > limits.max_extent_m || extent.z < config.min_height_m {
                continue;
            }
            let (centroid, size) = far_side(points, &piece, axes_from_points, config.far_side_shift);
            out.push(ObjectCandidate { label, centroid, size, points: piece.count });
        }
    }
    out
}

/// The centre behind a piece's visible side and the box about it (module doc): the centroid
/// moved away from the sensor (the points' origin) by κ · ½ w⊥, horizontally, and the
/// horizontal extent made symmetric about it, reaching every return; (centroid in the points'
/// frame, size along the measuring axes).
fn far_side(
    points: &[Point3<f64>],
    piece: &Piece,
    axes_from_points: &UnitQuaternion<f64>,
    shift: f64,
) -> (Point3<f64>, Vector3<f64>) {
    let mean = piece.sum / piece.count as f64;
    let extent = piece.hi - piece.lo;
    let level = axes_from_points * mean;
    let range = level.xy().norm();
    if shift.is_nan() || shift <= 0.0 || range < 1e-6 {
        return (Point3::from(mean), extent);
    }
    let away = level.xy() / range;
    let across = nalgebra::Vector2::new(-away.y, away.x);
    let (mut lo, mut hi) = (f64::MAX, f64::MIN);
    for &k in &piece.members {
        let t = across.dot(&(axes_from_points * points[k].coords).xy());
        lo = lo.min(t);
        hi = hi.max(t);
    }
    let moved = level.xy() + away * (shift * 0.5 * (hi - lo));
    let centre = Vector3::new(moved.x, moved.y, level.z);
    let reach = |a: usize| 2.0 * (piece.hi[a] - centre[a]).max(centre[a] - piece.lo[a]);
    let size = Vector3::new(reach(0), reach(1), extent.z);
    (Point3::from(axes_from_points.inverse() * centre), size)
}

/// Union–find: the root of `v`'s set (halving the path on the way).
fn root(parent: &mut [usize], mut v: usize) -> usize {
    while parent[v] != v {
        parent[v] = parent[parent[v]];
        v = parent[v];
    }
    v
}

/// Union–find: joins the sets of `a` and `b`; the smaller root stays the root.
fn unite(parent: &mut [usize], a: usize, b: usize) {
    let (a, b) = (root(parent, a), root(parent, b));
    if a != b {
        parent[a.max(b)] = a.min(b);
    }
}

/// One cluster's bounds (along the measuring axes), point sum (in the points' frame) and
/// members.
#[derive(Clone)]
struct Piece {
    lo: Vector3<f64>,
    hi: Vector3<f64>,
    sum: Vector3<f64>,
    count: usize,
    members: Vec<usize>,
}

impl Piece {
    fn of(points: &[Point3<f64>], members: &[usize], axes_from_points: &UnitQuaternion<f64>) -> Self {
        let (mut lo, mut hi, mut sum) = (Vector3::repeat(f64::MAX), Vector3::repeat(f64::MIN), Vector3::zeros());
        for &k in members {
            let p = points[k].coords;
            let along_axes = axes_from_points * p;
            lo = lo.inf(&along_axes);
            hi = hi.sup(&along_axes);
            sum += p;
        }
        Self { lo, hi, sum, count: members.len(), members: members.to_vec() }
    }

    fn join(&mut self, other: &Piece) {
        self.lo = self.lo.inf(&other.lo);
        self.hi = self.hi.sup(&other.hi);
        self.sum += other.sum;
        self.count += other.count;
        self.members.extend_from_slice(&other.members);
    }

    /// The footprint grown by `grow` each way: (x₀, x₁, y₀, y₁).
    fn footprint(&self, grow: f64) -> [f64; 4] {
        [self.lo.x - grow, self.hi.x + grow, self.lo.y - grow, self.hi.y + grow]
    }
}

/// Whether two pieces stand in one column (module doc).
fn one_column(a: &Piece, b: &Piece, tolerance_m: f64) -> bool {
    let (fa, fb) = (a.footprint(0.5 * tolerance_m), b.footprint(0.5 * tolerance_m));
    let overlap = (fa[1].min(fb[1]) - fa[0].max(fb[0])).max(0.0) * (fa[3].min(fb[3]) - fa[2].max(fb[2])).max(0.0);
    let area = |f: [f64; 4]| (f[1] - f[0]) * (f[3] - f[2]);
    overlap > 0.0 && overlap >= 0.5 * area(fa).min(area(fb))
}

/// Joins the pieces that stand in one column (transitively, by union–find), keeping the order of
/// each column's first piece.
fn join_columns(pieces: Vec<Piece>, tolerance_m: f64) -> Vec<Piece> {
    let mut parent: Vec<usize> = (0..pieces.len()).collect();
    for a in 0..pieces.len() {
        for b in a + 1..pieces.len() {
            if one_column(&pieces[a], &pieces[b], tolerance_m) {
                unite(&mut parent, a, b);
            }
        }
    }
    let mut joined: Vec<Option<Piece>> = vec![None; pieces.len()];
    for (k, piece) in pieces.iter().enumerate() {
        let r = root(&mut parent, k);
        match &mut joined[r] {
            Some(column) => column.join(piece),
            slot => *slot = Some(piece.clone()),
        }
    }
    joined.into_iter().flatten().collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn boxed(rng: &mut ChaCha8Rng, centre: [f64; 3], half: f64, n: usize) -> Vec<Point3<f64>> {
        (0..n)
            .map(|_| {
                Point3::new(
                    centre[0] + rng.random_range(-half..half),
                    centre[1] + rng.random_range(-half..half),
                    centre[2] + rng.random_range(-half..half),
                )
            })
            .collect()
    }

    /// These tests' clouds fill their boxes rather than show one side: no far-side shift.
    fn filled() -> ClusterConfig {
        ClusterConfig { far_side_shift: 0.0, ..ClusterConfig::default() }
    }

    fn level() -> UnitQuaternion<f64> {
        UnitQuaternion::identity()
    }

    #[test]
    fn flat_clusters_are_refused_when_asked() {
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        // A 2 m × 2 m patch of "object" labels on the ground, and a real 1 m box.
        let mut points: Vec<Point3<f64>> =
            (0..200).map(|_| Point3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), -0.8)).collect();
        points.extend(boxed(&mut rng, [10.0, 0.0, 0.0], 0.5, 200));
        let labels = vec![Some(LabelId(3)); points.len()];
        let all = cluster(&points, &labels, &filled(), &level());
        assert_eq!(all.len(), 2);
        let upright = cluster(&points, &labels, &ClusterConfig { min_height_m: 0.2, ..filled() }, &level());
        assert_eq!(upright.len(), 1);
        assert!((upright[0].centroid.x - 10.0).abs() < 0.1);
    }

    #[test]
    fn separates_boxes_by_class_and_distance_and_drops_implausible_ones() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let mut points = Vec::new();
        let mut labels = Vec::new();
        let mut add = |pts: Vec<Point3<f64>>, label: Option<u16>| {
            labels.extend(std::iter::repeat_n(label.map(LabelId), pts.len()));
            points.extend(pts);
        };
        add(boxed(&mut rng, [0.0, 0.0, 0.5], 0.3, 200), Some(1)); // chair A
        add(boxed(&mut rng, [3.0, 0.0, 0.5], 0.3, 200), Some(1)); // chair B, 3 m away
        add(boxed(&mut rng, [0.0, 0.0, 0.5], 0.3, 150), Some(2)); // a table in the same place, other class
        add(boxed(&mut rng, [10.0, 10.0, 0.5], 0.05, 5), Some(1)); // too few points
        add(boxed(&mut rng, [5.0, 5.0, 0.5], 0.3, 300), None); // unlabelled
        let wall: Vec<Point3<f64>> = (0..600).map(|k| Point3::new(20.0 + 0.05 * k as f64, 0.0, 1.0)).collect(); // 30 m long
        add(wall, Some(1));
        let candidates = cluster(&points, &labels, &filled(), &level());
        assert_eq!(candidates.len(), 3, "{candidates:?}");
        let chairs: Vec<_> = candidates.iter().filter(|c| c.label == LabelId(1)).collect();
        assert_eq!(chairs.len(), 2);
        assert!((chairs[0].centroid - Point3::new(0.0, 0.0, 0.5)).norm() < 0.05);
        assert!((chairs[1].centroid - Point3::new(3.0, 0.0, 0.5)).norm() < 0.05);
        assert!(chairs.iter().all(|c| c.points == 200 && c.size.max() < 0.6 && c.size.min() > 0.5));
        let table = candidates.iter().find(|c| c.label == LabelId(2)).unwrap();
        assert_eq!(table.points, 150);
        // Per-class limits: walls of class 1 become acceptable with a larger extent.
        let mut config = filled();
        config.classes.insert(1, ClassLimits { max_extent_m: 50.0, ..ClassLimits::default() });
        assert_eq!(cluster(&points, &labels, &config, &level()).len(), 4);
    }

    /// A lamp post seen with a gap between beams: its pole (0.15 m across, up to 1.2 m) and its
    /// head (0.5 m across, 3.5–4 m up) are 2.3 m apart, two clusters, one column; a second post
    /// 3 m away and two chairs 1.2 m apart stay apart, and a table over a chair (another class)
    /// is never joined to it.
    #[test]
    fn pieces_of_one_column_are_one_candidate() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let (mut points, mut labels) = (Vec::new(), Vec::new());
        let mut add = |pts: Vec<Point3<f64>>, label: u16| {
            labels.extend(std::iter::repeat_n(Some(LabelId(label)), pts.len()));
            points.extend(pts);
        };
        for x in [0.0, 3.0] {
            let pole = (0..120)
                .map(|k| Point3::new(x + rng.random_range(-0.07..0.07), rng.random_range(-0.07..0.07), 0.01 * k as f64))
                .collect();
            add(pole, 1);
            add(boxed(&mut rng, [x, 0.0, 3.75], 0.25, 80), 1);
        }
        add(boxed(&mut rng, [10.0, 0.0, 0.4], 0.25, 100), 2); // chair
        add(boxed(&mut rng, [11.2, 0.0, 0.4], 0.25, 100), 2); // its neighbour
        add(boxed(&mut rng, [10.0, 0.0, 1.6], 0.4, 100), 3); // a table over the first chair
        let config = filled();
        let candidates = cluster(&points, &labels, &config, &level());
        let posts: Vec<_> = candidates.iter().filter(|c| c.label == LabelId(1)).collect();
        assert_eq!(posts.len(), 2, "{posts:?}");
        for (post, x) in posts.iter().zip([0.0, 3.0]) {
            assert_eq!(post.points, 200);
            assert!((post.centroid.x - x).abs() < 0.05 && post.size.z > 3.9, "{post:?}");
            // The centroid is the mean of all the column's returns: 120 on the pole (mean 0.6 m
            // up), 80 in the head (3.75 m).
            assert!((post.centroid.z - (120.0 * 0.595 + 80.0 * 3.75) / 200.0).abs() < 0.05, "{post:?}");
        }
        assert_eq!(candidates.iter().filter(|c| c.label == LabelId(2)).count(), 2, "the chairs stay apart");
        assert_eq!(candidates.iter().filter(|c| c.label == LabelId(3)).count(), 1);
        let apart = cluster(&points, &labels, &ClusterConfig { merge_stacked: false, ..config }, &level());
        assert_eq!(apart.iter().filter(|c| c.label == LabelId(1)).count(), 4, "two pieces per post without it");
    }

    /// A bench 2 m long along the world's x, 0.5 m deep, 0.8 m high, seen from a body turned by
    /// 90° (the bench runs along the body's y) and from one pitched by 20° on a slope: measured
    /// along the odometry axes it is 2 × 0.5 × 0.8 both times. Along the body's axes it was
    /// 0.5 × 2 (turned), and 0.8 m high grew to about 1.4 m (pitched).
    #[test]
    fn extents_are_measured_along_the_axes_given() {
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        let in_world: Vec<Vector3<f64>> = (0..400)
            .map(|_| {
                Vector3::new(rng.random_range(-1.0..1.0), rng.random_range(-0.25..0.25), rng.random_range(-0.4..0.4))
            })
            .collect();
        let labels = vec![Some(LabelId(5)); in_world.len()];
        for odom_from_body in [
            UnitQuaternion::from_euler_angles(0.0, 0.0, std::f64::consts::FRAC_PI_2),
            UnitQuaternion::from_euler_angles(0.0, 20f64.to_radians(), 0.7),
        ] {
            let in_body: Vec<Point3<f64>> = in_world
                .iter()
                .map(|p| Point3::from(odom_from_body.inverse() * (p + Vector3::new(4.0, 0.0, 0.0))))
                .collect();
            let [ref bench] = cluster(&in_body, &labels, &filled(), &odom_from_body)[..] else {
                panic!("one bench");
            };
            assert!((bench.size - Vector3::new(2.0, 0.5, 0.8)).amax() < 0.05, "{}", bench.size);
            // The centroid stays in the body frame.
            assert!((odom_from_body * bench.centroid.coords - Vector3::new(4.0, 0.0, 0.0)).norm() < 0.05);
            let [ref along_body] = cluster(&in_body, &labels, &filled(), &level())[..] else {
                panic!("one bench");
            };
            assert!((along_body.size - bench.size).amax() > 0.5, "{} {}", along_body.size, bench.size);
        }
    }

    /// The part of a vertical cylinder (a tree's crown, 2.5–5 m up) of radius `r` about `axis`
    /// that a sensor at the origin sees: the arc between the tangent points, ±α about the
    /// direction toward the sensor, cos α = r / d (d: the axis's distance), returns spread
    /// evenly over it.
    fn visible_arc(axis: [f64; 2], r: f64, n: usize) -> Vec<Point3<f64>> {
        let toward_sensor = (-axis[1]).atan2(-axis[0]);
        let alpha = (r / axis[0].hypot(axis[1])).acos();
        (0..n)
            .map(|k| {
                let t = (k as f64 + 0.5) / n as f64;
                let angle = toward_sensor - alpha + 2.0 * alpha * t;
                let z = 2.5 + 2.5 * ((k * 7) % n) as f64 / n as f64;
                Point3::new(axis[0] + r * angle.cos(), axis[1] + r * angle.sin(), z)
            })
            .collect()
    }

    /// How far in front of the axis the mean of `visible_arc` lies, and the far-side centroid
    /// (κ = 2/π): the arc's mean is r sin α / α in front, its width across the line of sight
    /// 2 r sin α, so the shift is (2/π) r sin α.
    fn short_of_axis(r: f64, d: f64) -> (f64, f64) {
        let alpha = (r / d).acos();
        let mean = r * alpha.sin() / alpha;
        (mean, mean - std::f64::consts::FRAC_2_PI * r * alpha.sin())
    }

    /// A crown of radius 1 m 10.4 m away (α = 84.5°): the mean of its returns is 0.675 m short
    /// of the axis, the far-side centroid 0.041 m (the closed forms of `short_of_axis`), its z
    /// unchanged, every return inside its box. A lamp post's pole (0.1 m) moves by 6 cm at most.
    #[test]
    fn the_far_side_of_a_round_object_is_found() {
        let crown = visible_arc([10.0, 3.0], 1.0, 2000);
        let labels = vec![Some(LabelId(2)); crown.len()];
        let (mean_short, far_short) = short_of_axis(1.0, 10.0f64.hypot(3.0));
        let axis = nalgebra::Point2::new(10.0, 3.0);
        let off = ClusterConfig { far_side_shift: 0.0, ..ClusterConfig::default() };
        let [ref mean] = cluster(&crown, &labels, &off, &level())[..] else { panic!("one crown") };
        assert!(((mean.centroid.xy() - axis).norm() - mean_short).abs() < 0.005, "{mean:?}");
        let [ref far] = cluster(&crown, &labels, &ClusterConfig::default(), &level())[..] else { panic!("one crown") };
        assert!(((far.centroid.xy() - axis).norm() - far_short).abs() < 0.005, "{far:?}");
        assert!(far_short < 0.05 && mean_short > 0.6);
        assert_eq!(far.centroid.z, mean.centroid.z, "the shift is horizontal");
        for p in &crown {
            let d = p - far.centroid;
            assert!(
                d.x.abs() <= 0.5 * far.size.x + 1e-9 && d.y.abs() <= 0.5 * far.size.y + 1e-9,
                "{p} outside {far:?}"
            );
        }
        let pole = visible_arc([4.0, -2.0], 0.1, 200);
        let [ref post] = cluster(&pole, &vec![Some(LabelId(3)); 200], &ClusterConfig::default(), &level())[..] else {
            panic!("one pole");
        };
        assert!((post.centroid.xy() - nalgebra::Point2::new(4.0, -2.0)).norm() < 0.01, "{post:?}");
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(64))]
        /// Any round object (radius 0.1–2 m, 3–25 m away, any bearing), measured along axes
        /// turned by any yaw: the far-side centroid lies where the closed form of the visible
        /// arc puts it (`short_of_axis`: 4 % of r short at d = 10 r, 41 % at d = 1.5 r), within
        /// 1 % of the radius, whatever the axes' yaw.
        #[test]
        fn the_far_side_is_found_whatever_the_bearing_and_the_axes(
            bearing in -3.1f64..3.1, range in 3.0f64..25.0, r in 0.1f64..2.0, yaw in -3.1f64..3.1,
        ) {
            let axis = [range * bearing.cos(), range * bearing.sin()];
            let crown = visible_arc(axis, r, 1000);
            let labels = vec![Some(LabelId(2)); crown.len()];
            let turned = UnitQuaternion::from_euler_angles(0.0, 0.0, yaw);
            let config = ClusterConfig { tolerance_m: 0.5, ..ClusterConfig::default() };
            let found = cluster(&crown, &labels, &config, &turned);
            proptest::prop_assert_eq!(found.len(), 1);
            let short = (found[0].centroid.xy() - nalgebra::Point2::new(axis[0], axis[1])).norm();
            let expected = short_of_axis(r, range).1;
            proptest::prop_assert!((short - expected).abs() < 0.01 * r, "{} m short, {} expected, r = {}", short, expected, r);
            let level = cluster(&crown, &labels, &config, &level());
            proptest::prop_assert!((level[0].centroid - found[0].centroid).norm() < 1e-9);
        }
    }
}
