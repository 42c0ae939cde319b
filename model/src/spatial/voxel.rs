//! Voxel-grid downsampling: the centroid of the points in each occupied voxel of side `size`
//! (`downsample`), or the first point that fell in it (`downsample_first`, KISS-ICP's: every
//! point kept was measured, so none lies off the surfaces — a centroid of a voxel that straddles
//! a wall's edge floats between the wall and the floor, and a plane fitted through it tilts).
//! Output order follows the first point of each voxel, so the result is deterministic.

use nalgebra::Point3;
use rustc_hash::{FxHashMap, FxHashSet};

pub fn downsample(points: &[Point3<f64>], size: f64) -> Vec<Point3<f64>> {
    if !size.is_finite() || size <= 0.0 {
        return points.to_vec();
    }
    let mut index: FxHashMap<[i64; 3], usize> =
        FxHashMap::with_capacity_and_hasher(points.len() / 4 + 1, Default::default());
    let mut sums: Vec<(nalgebra::Vector3<f64>, usize)> = Vec::new();
    for p in points {
        let key = [(p.x / size).floor() as i64, (p.y / size).floor() as i64, (p.z / size).floor() as i64];
        let slot = *index.entry(key).or_insert_with(|| {
            sums.push((nalgebra::Vector3::zeros(), 0));
            sums.len() - 1
        });
        sums[slot].0 += p.coords;
        sums[slot].1 += 1;
    }
    sums.into_iter().map(|(s, n)| Point3::from(s / n as f64)).collect()
}

/// The first point of `points` in each voxel of side `size` (all of them for a size that is
/// not finite and positive).
pub fn downsample_first(points: &[Point3<f64>], size: f64) -> Vec<Point3<f64>> {
    if !size.is_finite() || size <= 0.0 {
        return points.to_vec();
    }
    let mut seen: FxHashSet<[i64; 3]> = FxHashSet::with_capacity_and_hasher(points.len() / 4 + 1, Default::default());
    points
        .iter()
        .filter(|p| {
            seen.insert([(p.x / size).floor() as i64, (p.y / size).floor() as i64, (p.z / size).floor() as i64])
        })
        .copied()
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_centroid_per_voxel() {
        let pts = [Point3::new(0.1, 0.1, 0.1), Point3::new(0.3, 0.1, 0.1), Point3::new(1.5, 0.0, 0.0)];
        let out = downsample(&pts, 1.0);
        assert_eq!(out, vec![Point3::new(0.2, 0.1, 0.1), Point3::new(1.5, 0.0, 0.0)]);
        assert_eq!(downsample(&pts, 0.0).len(), 3);
    }

    #[test]
    fn one_measured_point_per_voxel() {
        let pts = [Point3::new(0.1, 0.1, 0.1), Point3::new(0.3, 0.1, 0.1), Point3::new(1.5, 0.0, 0.0)];
        assert_eq!(downsample_first(&pts, 1.0), vec![pts[0], pts[2]]);
        assert_eq!(downsample_first(&pts, f64::NAN).len(), 3);
    }
}
