//! Does a registration bring the *structure* of two scans together? Outdoors the ground plane
//! dominates a LiDAR scan, so an ICP fitness stays high even when the scans are metres apart in
//! the plane: the ground slides onto the ground. This check leaves the ground out — in each
//! scan's upright body frame, points less than `ground_clearance_m` above the scan's low
//! percentile — and measures the fraction of the source's remaining points (objects, walls,
//! trunks) that land within `inlier_m` of the target's:
//!
//! ```text
//! agreement = |{ p ∈ S_structure : min_q ‖T·p − q‖ ≤ inlier_m, q ∈ T_structure }| / |S_structure|
//! ```
//!
//! A true registration of overlapping scans scores high; a wrong inter-robot transform, which
//! the ground alone cannot reveal, scores low.

use crate::geometry::Pose3;
use crate::spatial::point_tree::PointTree;
use crate::spatial::voxel::downsample;
use nalgebra::Point3;
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct StructureCheck {
    /// Both scans are voxel-downsampled first, m. Default 0.2.
    pub voxel_m: f64,
    /// Points this far above the scan's 5th-percentile height are structure, m. Default 0.3.
    pub ground_clearance_m: f64,
    /// A structure point agrees when the other scan has one this close, m. Default 0.3.
    pub inlier_m: f64,
}

impl Default for StructureCheck {
    fn default() -> Self {
        Self { voxel_m: 0.2, ground_clearance_m: 0.3, inlier_m: 0.3 }
    }
}

/// The points of `scan` (body frame, z up) above its ground.
fn structure(scan: &[Point3<f64>], check: &StructureCheck) -> Vec<Point3<f64>> {
    let points = if check.voxel_m > 0.0 { downsample(scan, check.voxel_m) } else { scan.to_vec() };
    let mut heights: Vec<f64> = points.iter().map(|p| p.z).filter(|z| z.is_finite()).collect();
    if heights.is_empty() {
        return Vec::new();
    }
    heights.sort_unstable_by(f64::total_cmp);
    let ground = heights[heights.len() / 20];
    points.into_iter().filter(|p| p.z > ground + check.ground_clearance_m).collect()
}

/// The agreement of `target_from_source` (source and target in their body frames); `None`
/// when either scan has no structure.
pub fn structure_agreement(
    source: &[Point3<f64>],
    target: &[Point3<f64>],
    target_from_source: &Pose3,
    check: &StructureCheck,
) -> Option<f64> {
    let (s, t) = (structure(source, check), structure(target, check));
    if s.is_empty() || t.is_empty() {
        return None;
    }
    let tree = PointTree::new(&t);
    let r2 = check.inlier_m * check.inlier_m;
    let agreeing =
        s.iter().filter(|p| tree.nearest(&(target_from_source * *p)).is_some_and(|(d2, _)| d2 <= r2)).count();
    Some(agreeing as f64 / s.len() as f64)
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

    #[test]
    fn scans_without_structure_give_none() {
        let flat: Vec<Point3<f64>> = (0..100).map(|k| Point3::new(k as f64 * 0.3, 0.0, -1.0)).collect();
        assert!(structure_agreement(&flat, &flat, &Pose3::identity(), &StructureCheck::default()).is_none());
    }
}
