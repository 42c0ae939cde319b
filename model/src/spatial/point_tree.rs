//! The kd-tree every perception stage searches: kiddo's immutable tree over single-precision
//! coordinates (micrometres at kilometre range — searches need no more; residuals keep f64),
//! with 4-point leaves, which measured fastest for ICP's query mix (`--example` numbers in
//! book/src/perception.md: nearest-one 2× and k-nearest 2× faster than kiddo's default 32).

use kiddo::immutable::float::kdtree::ImmutableKdTree;
use kiddo::SquaredEuclidean;
use nalgebra::Point3;
use std::num::NonZero;

const LEAF: usize = 4;

/// A kd-tree over a fixed set of points; items are indices into that set.
pub struct PointTree {
    tree: ImmutableKdTree<f32, u32, 3, LEAF>,
}

/// The squared distance between two keys exactly as the tree measures it (single precision,
/// summed x, y, z), so a search beside the tree can return the tree's bits.
#[inline]
pub fn squared_distance(a: &[f32; 3], b: &[f32; 3]) -> f32 {
    let d = [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
}

impl PointTree {
    /// A point as the tree holds it.
    #[inline]
    pub fn key(p: &Point3<f64>) -> [f32; 3] {
        [p.x as f32, p.y as f32, p.z as f32]
    }

    /// Builds the tree; `points` must hold fewer than 2³² points.
    pub fn new(points: &[Point3<f64>]) -> Self {
        let keys: Vec<[f32; 3]> = points.iter().map(Self::key).collect();
        Self { tree: ImmutableKdTree::new_from_slice(&keys) }
    }

    /// Squared distance to, and index of, the nearest point (`None` for an empty tree).
    pub fn nearest(&self, p: &Point3<f64>) -> Option<(f64, usize)> {
        if self.tree.size() == 0 {
            return None;
        }
        let nn = self.tree.nearest_one::<SquaredEuclidean>(&Self::key(p));
        Some((nn.distance as f64, nn.item as usize))
    }

    /// Indices of up to `k` nearest points within `radius` m of `p`, in no particular order.
    pub fn nearest_k_within(&self, p: &Point3<f64>, k: usize, radius: f64) -> Vec<usize> {
        self.nearest_k_within_distances(p, k, radius).into_iter().map(|(item, _)| item as usize).collect()
    }

    /// [`PointTree::nearest_k_within`] with each point's squared distance (single precision).
    pub fn nearest_k_within_distances(&self, p: &Point3<f64>, k: usize, radius: f64) -> Vec<(u32, f32)> {
        let Some(k) = NonZero::new(k) else { return Vec::new() };
        let r2 = (radius * radius) as f32;
        self.tree
            .nearest_n_within::<SquaredEuclidean>(&Self::key(p), r2, k, false)
            .iter()
            .map(|n| (n.item, n.distance))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// Against brute force on random clouds.
    #[test]
    fn matches_brute_force() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let pts: Vec<Point3<f64>> = (0..500)
            .map(|_| Point3::new(rng.random_range(-5.0..5.0), rng.random_range(-5.0..5.0), rng.random_range(0.0..2.0)))
            .collect();
        let tree = PointTree::new(&pts);
        for _ in 0..200 {
            let q = Point3::new(rng.random_range(-6.0..6.0), rng.random_range(-6.0..6.0), rng.random_range(-1.0..3.0));
            let mut by_distance: Vec<(f64, usize)> =
                pts.iter().enumerate().map(|(i, p)| ((p - q).norm_squared(), i)).collect();
            by_distance.sort_by(|a, b| a.0.total_cmp(&b.0));
            let (d2, i) = tree.nearest(&q).unwrap();
            assert_eq!(i, by_distance[0].1);
            assert!((d2 - by_distance[0].0).abs() < 1e-4);
            let mut got = tree.nearest_k_within(&q, 7, 2.0);
            got.sort_unstable();
            let mut want: Vec<usize> =
                by_distance.iter().take(7).filter(|(d2, _)| *d2 <= 4.0).map(|(_, i)| *i).collect();
            want.sort_unstable();
            assert_eq!(got, want);
        }
        assert_eq!(PointTree::new(&[]).nearest(&Point3::origin()), None);
    }
}
