//! Voxel-grid downsampling: the centroid of the points in each occupied voxel of side `size`.
//! Output order follows the first point of each voxel, so the result is deterministic.

use nalgebra::Point3;
use std::collections::HashMap;

pub fn downsample(points: &[Point3<f64>], size: f64) -> Vec<Point3<f64>> {
    if !size.is_finite() || size <= 0.0 {
        return points.to_vec();
    }
    let mut index: HashMap<[i64; 3], usize> = HashMap::with_capacity(points.len() / 4 + 1);
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
}
