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
    let mut voxels = Downsampler::new(size, points.len());
    points.iter().for_each(|p| voxels.add(p));
    voxels.centroids()
}

/// [`downsample`] fed one point at a time (a cloud gathered from many scans need not be
/// collected first): the same centroids in the same order, bit for bit.
pub struct Downsampler {
    size: f64,
    index: FxHashMap<[i64; 3], usize>,
    sums: Vec<(nalgebra::Vector3<f64>, usize)>,
    /// The last point's voxel and slot: a scan is ordered along the sensor's sweep, so a point
    /// usually falls in its predecessor's voxel, which is then found without hashing (same
    /// slot, same sums: same bits).
    last: Option<([i64; 3], usize)>,
}

impl Downsampler {
    /// Voxels of side `size` (finite and positive), for about `expected` points.
    pub fn new(size: f64, expected: usize) -> Self {
        Self {
            size,
            index: FxHashMap::with_capacity_and_hasher(expected / 4 + 1, Default::default()),
            sums: Vec::new(),
            last: None,
        }
    }

    pub fn add(&mut self, p: &Point3<f64>) {
        let key = voxel_of(p, self.size);
        let slot = match self.last {
            Some((k, slot)) if k == key => slot,
            _ => *self.index.entry(key).or_insert_with(|| {
                self.sums.push((nalgebra::Vector3::zeros(), 0));
                self.sums.len() - 1
            }),
        };
        self.last = Some((key, slot));
        self.sums[slot].0 += p.coords;
        self.sums[slot].1 += 1;
    }

    /// The centroid of each occupied voxel, in order of its first point.
    pub fn centroids(self) -> Vec<Point3<f64>> {
        self.sums.into_iter().map(|(s, n)| Point3::from(s / n as f64)).collect()
    }
}

/// The index of the voxel of side `size` holding `p`: ⌊p / size⌋ per axis.
#[inline]
pub fn voxel_of(p: &Point3<f64>, size: f64) -> [i64; 3] {
    [(p.x / size).floor() as i64, (p.y / size).floor() as i64, (p.z / size).floor() as i64]
}

/// The first point of `points` in each voxel of side `size` (all of them for a size that is
/// not finite and positive).
pub fn downsample_first(points: &[Point3<f64>], size: f64) -> Vec<Point3<f64>> {
    if !size.is_finite() || size <= 0.0 {
        return points.to_vec();
    }
    let mut seen: FxHashSet<[i64; 3]> = FxHashSet::with_capacity_and_hasher(points.len() / 4 + 1, Default::default());
    // As in `downsample`: a point in its predecessor's voxel is not the first there.
    let mut last = None;
    points
        .iter()
        .filter(|p| {
            let key = voxel_of(p, size);
            let first = last != Some(key) && seen.insert(key);
            last = Some(key);
            first
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

    /// The shortcut for a point in its predecessor's voxel changes nothing: against a plain
    /// hash map (sums in arrival order, output in order of first arrival), bit for bit, on
    /// clouds whose runs stay in one voxel as a scan's do and on shuffled ones.
    fn by_hash_alone(points: &[Point3<f64>], size: f64) -> (Vec<Point3<f64>>, Vec<Point3<f64>>) {
        let (mut order, mut sums) = (Vec::new(), std::collections::HashMap::new());
        for p in points {
            let key = voxel_of(p, size);
            let entry = sums.entry(key).or_insert_with(|| {
                order.push((key, *p));
                (nalgebra::Vector3::zeros(), 0usize)
            });
            entry.0 += p.coords;
            entry.1 += 1;
        }
        let centroids = order.iter().map(|(k, _)| Point3::from(sums[k].0 / sums[k].1 as f64)).collect();
        (centroids, order.into_iter().map(|(_, p)| p).collect())
    }

    proptest::proptest! {
        #[test]
        fn the_last_voxel_shortcut_changes_nothing(
            walk in proptest::collection::vec((-0.3f64..0.3, -0.3f64..0.3, -0.1f64..0.1, 1usize..6), 0..200),
            size in 0.05f64..1.0,
        ) {
            // A random walk, each step repeated a few times with small offsets: runs of points in
            // one voxel, returns to voxels left earlier.
            let (mut at, mut points) = (Point3::new(0.0, 0.0, 0.0), Vec::new());
            for (dx, dy, dz, repeat) in walk {
                at += nalgebra::Vector3::new(dx, dy, dz);
                for k in 0..repeat {
                    points.push(at + nalgebra::Vector3::new(1e-3 * k as f64, -7e-4 * k as f64, 0.0));
                }
            }
            let (centroids, firsts) = by_hash_alone(&points, size);
            proptest::prop_assert_eq!(&downsample(&points, size), &centroids);
            proptest::prop_assert_eq!(&downsample_first(&points, size), &firsts);
        }
    }

    #[test]
    fn one_measured_point_per_voxel() {
        let pts = [Point3::new(0.1, 0.1, 0.1), Point3::new(0.3, 0.1, 0.1), Point3::new(1.5, 0.0, 0.0)];
        assert_eq!(downsample_first(&pts, 1.0), vec![pts[0], pts[2]]);
        assert_eq!(downsample_first(&pts, f64::NAN).len(), 3);
    }
}
