//! Does a registration bring the *structure* of two scans together? Outdoors the ground plane
//! dominates a LiDAR scan, so an ICP fitness stays high even when the scans are metres apart in
//! the plane: the ground slides onto the ground. This check leaves the ground out — in each
//! scan's body frame, points less than `ground_clearance_m` above the local ground
//! ([`crate::perception::ground`]: a plane per `ground_cell_m` column through the low points
//! around it, the ground no steeper than `max_ground_slope_deg`), so that hills, kerbs and
//! ramps are ground and the objects on their low side are not — and measures the fraction of the
//! source's remaining points (objects, walls, trunks) that land within `inlier_m` of the
//! target's:
//!
//! ```text
//! structure(S) = { p ∈ S : z_p − g(p) > ground_clearance_m },  g: the local ground under p
//! agreement = |{ p ∈ S_structure : min_q ‖T·p − q‖ ≤ inlier_m, q ∈ T_structure }| / |S_structure|
//! ```
//!
//! A point with no ground found near it (no low point within two columns that the slope bound
//! accepts) is measured against the scan's 5th-percentile height instead. A level scan — the
//! local ground within 0.15 m of that percentile under 95 % of its points within 15 m — is
//! measured against the percentile alone (g ≡ the low percentile), as before local grounds: on
//! level ground the local planes only add their noise at the clearance, which moved one of
//! `team_of_eight`'s 56 alignments. The level test reads the 95th percentile, not the median: a
//! kerb or a gentle slope that raises a tenth of the ground makes the scan non-level, where the
//! median did not notice. It reads only the near field: farther out the lowest return of a
//! column is often a wall above ground that no beam reached (on `team_of_eight`'s flat campus
//! the 95th percentile of all points is 0.36–0.45 m, of those within 15 m at most 0.07 m in
//! most scans).
//!
//! A ceiling over the scan ([`crate::perception::ceiling`]: a flat plane over the sensor) is
//! left out as the ground is, with the points within `ground_clearance_m` under it: under one,
//! a half turn in a grid of identical rooms agreed on the ceiling alone (`handheld_indoor`
//! seed 6 with `world.ceiling`: four directions aligned 180° off).
//!
//! A true registration of overlapping scans scores high; a wrong inter-robot transform, which
//! the ground alone cannot reveal, scores low.

use crate::geometry::Pose3;
use crate::perception::ceiling::find_ceiling;
use crate::perception::ground::{heights_above_ground, GroundParams};
use crate::spatial::point_tree::PointTree;
use crate::spatial::voxel::downsample;
use nalgebra::Point3;
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct StructureCheck {
    /// Both scans are voxel-downsampled first, m. Default 0.2.
    pub voxel_m: f64,
    /// Points this far above the local ground are structure, m. Default 0.3.
    pub ground_clearance_m: f64,
    /// A structure point agrees when the other scan has one this close, m. Default 0.3.
    pub inlier_m: f64,
    /// Side of the columns whose low points make the local ground, m. Default 1.0.
    pub ground_cell_m: f64,
    /// The steepest ground (relative to the body's x-y plane): a low point standing higher
    /// above its neighbours' is not ground, degrees. Default 20.
    pub max_ground_slope_deg: f64,
}

impl Default for StructureCheck {
    fn default() -> Self {
        Self { voxel_m: 0.2, ground_clearance_m: 0.3, inlier_m: 0.3, ground_cell_m: 1.0, max_ground_slope_deg: 20.0 }
    }
}

/// A scan whose local ground is this close to the scan's low percentile under 95 % of its points
/// within `LEVEL_RANGE_M` is level, m.
const LEVEL_M: f64 = 0.15;

/// The level test reads the points this close to the sensor (horizontally), m; all of them when
/// none this close has a local ground.
const LEVEL_RANGE_M: f64 = 15.0;

/// The points of `scan` (body frame, z up) above its local ground.
fn structure(scan: &[Point3<f64>], check: &StructureCheck) -> Vec<Point3<f64>> {
    let points: Vec<Point3<f64>> = if check.voxel_m > 0.0 { downsample(scan, check.voxel_m) } else { scan.to_vec() }
        .into_iter()
        .filter(|p| p.coords.iter().all(|v| v.is_finite()))
        .collect();
    let mut heights: Vec<f64> = points.iter().map(|p| p.z).collect();
    heights.sort_unstable_by(f64::total_cmp);
    let Some(&low) = heights.get(heights.len() / 20) else { return Vec::new() };
    let params = GroundParams {
        cell_m: check.ground_cell_m,
        max_slope_deg: check.max_ground_slope_deg,
        tolerance_m: check.ground_clearance_m,
    };
    let above = heights_above_ground(&points, &params);
    // A level scan (the local ground under 95 % of the near points within LEVEL_M of the scan's
    // low percentile) keeps the single threshold: local planes would only add noise there.
    // (All points when no near point has a local ground: a scan that sees no ground near it.)
    let offsets_within = |range: f64| -> Vec<f64> {
        points
            .iter()
            .zip(&above)
            .filter(|(p, _)| p.x.hypot(p.y) <= range)
            .filter_map(|(p, h)| h.map(|h| (p.z - h - low).abs()))
            .collect()
    };
    let mut offsets = offsets_within(LEVEL_RANGE_M);
    if offsets.is_empty() {
        offsets = offsets_within(f64::INFINITY);
    }
    offsets.sort_unstable_by(f64::total_cmp);
    let level = offsets.get(offsets.len() * 19 / 20).is_none_or(|&q| q <= LEVEL_M);
    let above_ground: Vec<Point3<f64>> = points
        .into_iter()
        .zip(above)
        .filter(|(p, h)| if level { p.z - low } else { h.unwrap_or(p.z - low) } > check.ground_clearance_m)
        .map(|(p, _)| p)
        .collect();
    match find_ceiling(&above_ground, check.ground_cell_m, check.ground_clearance_m, check.max_ground_slope_deg) {
        Some(ceiling) => above_ground.into_iter().filter(|p| !ceiling.holds(p, check.ground_clearance_m)).collect(),
        None => above_ground,
    }
}

/// The agreement of `target_from_source` (source and target in their body frames); `None`
/// when either scan has no structure.
pub fn structure_agreement(
    source: &[Point3<f64>],
    target: &[Point3<f64>],
    target_from_source: &Pose3,
    check: &StructureCheck,
) -> Option<f64> {
    StructureTarget::new(target, check).agreement(source, target_from_source, check)
}

/// A target scan's structure and its kd-tree, found once for the several sources a round
/// checks against it (with the same check).
pub struct StructureTarget {
    /// `None`: the scan has no structure.
    tree: Option<PointTree>,
}

impl StructureTarget {
    pub fn new(target: &[Point3<f64>], check: &StructureCheck) -> Self {
        let structure = structure(target, check);
        Self { tree: (!structure.is_empty()).then(|| PointTree::new(&structure)) }
    }

    /// [`structure_agreement`] of `source` onto this target (made with the same `check`).
    pub fn agreement(&self, source: &[Point3<f64>], target_from_source: &Pose3, check: &StructureCheck) -> Option<f64> {
        let tree = self.tree.as_ref()?;
        let s = structure(source, check);
        if s.is_empty() {
            return None;
        }
        let r2 = check.inlier_m * check.inlier_m;
        let agreeing =
            s.iter().filter(|p| tree.nearest(&(target_from_source * *p)).is_some_and(|(d2, _)| d2 <= r2)).count();
        Some(agreeing as f64 / s.len() as f64)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::pose_from_yaw_translation;
    use nalgebra::Vector3;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// Ground at z = −1 (body frame) and a few boxes, seen from `world_from_body`.
    fn scan(world_from_body: &Pose3, rng: &mut ChaCha8Rng) -> Vec<Point3<f64>> {
        let boxes = [(5.0, 2.0), (-3.0, 6.0), (8.0, -4.0), (-6.0, -5.0)];
        let mut world = Vec::new();
        for _ in 0..4000 {
            world.push(Point3::new(rng.random_range(-15.0..15.0), rng.random_range(-15.0..15.0), 0.0));
        }
        for (x, y) in boxes {
            for _ in 0..400 {
                world.push(Point3::new(
                    x + rng.random_range(-0.5..0.5),
                    y + rng.random_range(-0.5..0.5),
                    rng.random_range(0.0..2.0),
                ));
            }
        }
        let body_from_world = world_from_body.inverse();
        world.iter().map(|p| body_from_world * p).collect()
    }

    #[test]
    fn the_right_transform_agrees_and_a_sliding_one_does_not() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let a = pose_from_yaw_translation(0.0, Vector3::new(0.0, 0.0, 1.0));
        let b = pose_from_yaw_translation(0.4, Vector3::new(1.5, -1.0, 1.0));
        let (sa, sb) = (scan(&a, &mut rng), scan(&b, &mut rng));
        let truth = a.inverse() * b; // a_from_b: source b onto target a
        let check = StructureCheck { inlier_m: 0.5, ..StructureCheck::default() };
        let right = structure_agreement(&sb, &sa, &truth, &check).unwrap();
        // Slid 4 m along the ground: the ground still matches everywhere, the boxes do not.
        let slid = pose_from_yaw_translation(0.0, Vector3::new(4.0, 0.0, 0.0)) * truth;
        let wrong = structure_agreement(&sb, &sa, &slid, &check).unwrap();
        assert!(right > 0.9, "{right}");
        assert!(wrong < 0.2, "{wrong}");
    }

    /// A world of sloped ground `height(x, y)` with boxes (0.8 m × 0.8 m × 1.5 m) standing on
    /// it, scanned from `world_from_body`: the points in the body frame and their true heights
    /// above the ground.
    struct SlopedWorld<F: Fn(f64, f64) -> f64> {
        height: F,
        boxes: Vec<(f64, f64)>,
    }

    impl<F: Fn(f64, f64) -> f64> SlopedWorld<F> {
        fn scan(&self, world_from_body: &Pose3, rng: &mut ChaCha8Rng) -> Vec<Point3<f64>> {
            let centre = world_from_body.translation.vector;
            let mut world = Vec::new();
            for _ in 0..6000 {
                // Denser near the sensor, as a LiDAR's rings are.
                let (r, a) = (20.0 * rng.random::<f64>().powf(0.7), rng.random_range(0.0..std::f64::consts::TAU));
                let (x, y) = (centre.x + r * a.cos(), centre.y + r * a.sin());
                world.push(Point3::new(x, y, (self.height)(x, y) + rng.random_range(-0.02..0.02)));
            }
            for &(bx, by) in &self.boxes {
                for _ in 0..300 {
                    let (x, y) = (bx + rng.random_range(-0.4..0.4), by + rng.random_range(-0.4..0.4));
                    world.push(Point3::new(x, y, (self.height)(x, y) + rng.random_range(0.0..1.5)));
                }
            }
            let body_from_world = world_from_body.inverse();
            world.iter().map(|p| body_from_world * p).collect()
        }

        /// The true height above the ground of `p_in_body`.
        fn above_ground(&self, world_from_body: &Pose3, p_in_body: &Point3<f64>) -> f64 {
            let p = world_from_body * p_in_body;
            p.z - (self.height)(p.x, p.y)
        }
    }

    /// Of the downsampled scan: the fraction of points truly below `clearance − 0.15` that are
    /// taken for structure, and of those truly above `clearance + 0.15` that are not.
    fn errors<F: Fn(f64, f64) -> f64>(
        world: &SlopedWorld<F>,
        world_from_body: &Pose3,
        scan: &[Point3<f64>],
        kept: &[Point3<f64>],
        check: &StructureCheck,
    ) -> (f64, f64) {
        let all = downsample(scan, check.voxel_m);
        let h = |p: &Point3<f64>| world.above_ground(world_from_body, p);
        let c = check.ground_clearance_m;
        let ground = all.iter().filter(|p| h(p) < c - 0.15).count().max(1);
        let high = all.iter().filter(|p| h(p) > c + 0.15).count().max(1);
        let ground_kept = kept.iter().filter(|p| h(p) < c - 0.15).count();
        let high_kept = kept.iter().filter(|p| h(p) > c + 0.15).count();
        (ground_kept as f64 / ground as f64, 1.0 - high_kept as f64 / high as f64)
    }

    /// The boxes of the sloped worlds: uphill, downhill and across.
    fn boxes() -> Vec<(f64, f64)> {
        vec![(6.0, 1.0), (-7.0, -2.0), (2.0, 9.0), (-3.0, -12.0), (14.0, -5.0), (-15.0, 6.0)]
    }

    #[test]
    fn on_a_12_degree_slope_the_boxes_are_structure_and_the_ground_is_not() {
        let tan = 12f64.to_radians().tan();
        let world = SlopedWorld { height: |x: f64, y: f64| tan * (0.8 * x + 0.6 * y), boxes: boxes() };
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        // A level (gravity-aligned) body 0.5 m above the ground: the old global rule kept the
        // uphill ground, 4 m "high" at 20 m, and removed the boxes on the low side.
        let world_from_body = pose_from_yaw_translation(0.3, Vector3::new(0.0, 0.0, 0.5));
        let scan = world.scan(&world_from_body, &mut rng);
        let check = StructureCheck::default();
        let kept = structure(&scan, &check);
        let (ground_kept, high_lost) = errors(&world, &world_from_body, &scan, &kept, &check);
        assert!(ground_kept < 0.01, "ground taken for structure: {ground_kept}");
        assert!(high_lost < 0.05, "box points lost: {high_lost}");
    }

    #[test]
    fn on_level_ground_the_structure_is_the_old_rule_s_up_to_the_threshold() {
        let world = SlopedWorld { height: |_: f64, _: f64| 0.0, boxes: boxes() };
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        let world_from_body = pose_from_yaw_translation(0.0, Vector3::new(0.0, 0.0, 0.5));
        let scan = world.scan(&world_from_body, &mut rng);
        let check = StructureCheck::default();
        let kept = structure(&scan, &check);
        // The old rule: above the scan's 5th-percentile height by the clearance.
        let all = downsample(&scan, check.voxel_m);
        let mut z: Vec<f64> = all.iter().map(|p| p.z).collect();
        z.sort_unstable_by(f64::total_cmp);
        let old: Vec<Point3<f64>> =
            all.iter().filter(|p| p.z > z[z.len() / 20] + check.ground_clearance_m).copied().collect();
        let differs = |a: &[Point3<f64>], b: &[Point3<f64>]| {
            a.iter().filter(|p| !b.contains(p)).map(|p| world.above_ground(&world_from_body, p)).collect::<Vec<_>>()
        };
        for h in differs(&kept, &old).into_iter().chain(differs(&old, &kept)) {
            assert!((h - check.ground_clearance_m).abs() < 0.1, "a point {h} m high changed sides");
        }
        assert!(kept.len() as f64 > 0.9 * old.len() as f64, "{} of {}", kept.len(), old.len());
    }

    /// Level ground seen to 20 m, and beyond 25 m walls whose foot no beam reached (their lowest
    /// return 0.45 m up, as a LiDAR's near-horizontal rings leave it): their columns' local ground
    /// is that lowest return, but the scan stays level, so the walls' lower parts stay structure.
    #[test]
    fn far_walls_over_unseen_ground_keep_a_level_scan_level() {
        let world = SlopedWorld { height: |_: f64, _: f64| 0.0, boxes: boxes() };
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let world_from_body = pose_from_yaw_translation(0.2, Vector3::new(0.0, 0.0, 0.5));
        let mut scan = world.scan(&world_from_body, &mut rng);
        let mut walls = Vec::new();
        for _ in 0..3000 {
            let (r, a) = (rng.random_range(25.0..40.0), rng.random_range(0.0..std::f64::consts::TAU));
            walls.push(world_from_body.inverse() * Point3::new(r * a.cos(), r * a.sin(), rng.random_range(0.45..3.0)));
        }
        scan.extend(&walls);
        let check = StructureCheck::default();
        let kept = structure(&scan, &check);
        let low_wall: Vec<Point3<f64>> = downsample(&walls, check.voxel_m)
            .into_iter()
            .filter(|p| (0.5..0.7).contains(&world.above_ground(&world_from_body, p)))
            .collect();
        let low_wall_kept = low_wall.iter().filter(|p| kept.contains(p)).count();
        assert!(low_wall.len() > 50, "{}", low_wall.len());
        assert!(low_wall_kept as f64 > 0.9 * low_wall.len() as f64, "{low_wall_kept} of {}", low_wall.len());
    }

    /// Found by `slopes_kerbs_and_tilted_bodies` in CI (its minimal input): a 15 cm kerb on a
    /// slope too gentle to move the median point's local ground. When the level test read the
    /// median, the scan counted as level and every point was measured against the scan's low
    /// percentile, so the ground beyond the kerb and up the slope (0.3–0.45 m above it at 20 m)
    /// was structure: 6.2% of the ground.
    #[test]
    fn a_kerb_on_a_gentle_slope_is_not_structure() {
        let tan = 0.444f64.to_radians().tan();
        let world =
            SlopedWorld { height: move |x: f64, y: f64| tan * x + if -y > 8.947 { 0.15 } else { 0.0 }, boxes: boxes() };
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        let at = Vector3::new(0.0, 0.0, (world.height)(0.0, 0.0) + 0.5);
        let world_from_body = Pose3::from_parts(at.into(), nalgebra::UnitQuaternion::from_euler_angles(0.0, 0.0, 0.7));
        let scan = world.scan(&world_from_body, &mut rng);
        let check = StructureCheck::default();
        let kept = structure(&scan, &check);
        let (ground_kept, _) = errors(&world, &world_from_body, &scan, &kept, &check);
        assert!(ground_kept < 0.02, "ground taken for structure: {ground_kept}");
    }

    proptest::proptest! {
        // A fixed seed: CI runs the same 24 worlds every time (the case above was found with a
        // random one and is kept as its own test).
        #![proptest_config(proptest::prelude::ProptestConfig {
            cases: 24,
            rng_seed: proptest::test_runner::RngSeed::Fixed(31),
            ..proptest::prelude::ProptestConfig::default()
        })]
        /// Hills up to 15° in any direction, a 15 cm kerb, the body level or tilted with the
        /// slope under it: the ground is left out and the boxes are kept.
        #[test]
        fn slopes_kerbs_and_tilted_bodies(
            slope_deg in 0.0..15.0f64,
            azimuth in 0.0..std::f64::consts::TAU,
            kerb_at in -10.0..10.0f64,
            tilted: bool,
            seed: u64,
        ) {
            let tan = slope_deg.to_radians().tan();
            let (c, s) = (azimuth.cos(), azimuth.sin());
            let world = SlopedWorld {
                height: move |x: f64, y: f64| tan * (c * x + s * y) + if s * x - c * y > kerb_at { 0.15 } else { 0.0 },
                boxes: boxes(),
            };
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let at = Vector3::new(0.0, 0.0, (world.height)(0.0, 0.0) + 0.5);
            // Tilted: the body lies on the slope (its z along the ground's normal).
            let tilt = if tilted {
                nalgebra::UnitQuaternion::from_axis_angle(&nalgebra::Unit::new_normalize(Vector3::new(-s, c, 0.0)), -slope_deg.to_radians())
            } else {
                nalgebra::UnitQuaternion::identity()
            };
            let world_from_body = Pose3::from_parts(at.into(), tilt * nalgebra::UnitQuaternion::from_euler_angles(0.0, 0.0, 0.7));
            let scan = world.scan(&world_from_body, &mut rng);
            let check = StructureCheck::default();
            let kept = structure(&scan, &check);
            let (ground_kept, high_lost) = errors(&world, &world_from_body, &scan, &kept, &check);
            proptest::prop_assert!(ground_kept < 0.02, "ground taken for structure: {}", ground_kept);
            proptest::prop_assert!(high_lost < 0.08, "box points lost: {}", high_lost);
        }
    }

    /// A square room 8 m across, walls and ceiling 3 m high (the ceiling only if `covered`), and
    /// three boxes that break its symmetry, scanned from `world_from_body`.
    fn room_scan(covered: bool, world_from_body: &Pose3, rng: &mut ChaCha8Rng) -> Vec<Point3<f64>> {
        let mut world = crate::perception::ceiling::square_room(covered, 4000, 600, rng);
        for (bx, by) in [(2.0, 1.5), (-2.5, 2.0), (1.0, -2.5)] {
            for _ in 0..400 {
                let (x, y, z) =
                    (bx + rng.random_range(-0.4..0.4), by + rng.random_range(-0.4..0.4), rng.random_range(0.0..1.2));
                world.push(Point3::new(x, y, z));
            }
        }
        let body_from_world = world_from_body.inverse();
        world.iter().map(|p| body_from_world * p).collect()
    }

    /// Under a ceiling a half turn of a square room agrees no better than in the same room open
    /// to the sky: the ceiling is left out as the ground is (the walls, symmetric, still agree;
    /// the boxes do not). The right transform agrees in both.
    #[test]
    fn a_ceiling_lends_a_half_turn_no_agreement() {
        let a = pose_from_yaw_translation(0.3, Vector3::new(-1.0, -0.5, 1.5));
        let b = pose_from_yaw_translation(-0.8, Vector3::new(1.2, 0.7, 1.5));
        let check = StructureCheck::default();
        let half_turn = pose_from_yaw_translation(std::f64::consts::PI, Vector3::zeros());
        let (right, wrong) = (a.inverse() * b, a.inverse() * half_turn * b);
        let agreements = |covered: bool| {
            let mut rng = ChaCha8Rng::seed_from_u64(9);
            let (sa, sb) = (room_scan(covered, &a, &mut rng), room_scan(covered, &b, &mut rng));
            let target = StructureTarget::new(&sa, &check);
            (target.agreement(&sb, &right, &check).unwrap(), target.agreement(&sb, &wrong, &check).unwrap())
        };
        let (open_right, open_wrong) = agreements(false);
        let (covered_right, covered_wrong) = agreements(true);
        assert!(open_right > 0.9 && covered_right > 0.9, "{open_right} {covered_right}");
        assert!(open_wrong < 0.85, "{open_wrong}");
        assert!((covered_wrong - open_wrong).abs() < 0.03, "open {open_wrong}, covered {covered_wrong}");
        // The ceiling is not structure: none of a covered scan's structure is within 0.3 m of it.
        let mut rng = ChaCha8Rng::seed_from_u64(10);
        let kept = structure(&room_scan(true, &a, &mut rng), &check);
        assert!(
            kept.iter().all(|p| (a * p).z < 2.7 + 1e-9),
            "{:?}",
            kept.iter().map(|p| (a * p).z).fold(0.0, f64::max)
        );
    }

    #[test]
    fn scans_without_structure_give_none() {
        let flat: Vec<Point3<f64>> = (0..100).map(|k| Point3::new(k as f64 * 0.3, 0.0, -1.0)).collect();
        assert!(structure_agreement(&flat, &flat, &Pose3::identity(), &StructureCheck::default()).is_none());
    }
}
