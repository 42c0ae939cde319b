//! Where a fixed cloud can be reached within a radius: the cells of side c (a hair over the
//! radius r) holding a point, dilated by one cell. A query whose cell is not in the set has no
//! point within r, so a search bounded by r can stop before it starts — ICP asks for the
//! nearest target point of every source point on every pass, and the source points outside the
//! overlap (a good part of two robots' scans) would otherwise each cost a full kd-tree descent
//! that ends far away.
//!
//! ```text
//! cell(x) = ⌊x / c⌋ per axis,  c = r (1 + 10⁻⁵)
//! ‖p − t‖ ≤ r  ⇒  |p_i − t_i| ≤ r < c  ⇒  |cell(p)_i − cell(t)_i| ≤ 1
//! ```
//!
//! Cells are taken of the points as the kd-tree holds them (single precision), and "within r"
//! is the kd-tree's single-precision distance; its rounding (a few parts in 10⁷ of r) is far
//! inside the 10⁻⁵ margin, so the set never misses a point the kd-tree would call within r.

use super::point_tree::PointTree;
use nalgebra::Point3;
use rustc_hash::FxHashSet;

/// The cells within one cell of a point of the cloud.
pub struct Reach {
    cell: f64,
    near: FxHashSet<[i64; 3]>,
}

impl Reach {
    /// The reach of `points` within `radius` m (> 0 and finite; otherwise every cell is near).
    pub fn new(points: &[Point3<f64>], radius: f64) -> Self {
        let cell = radius * (1.0 + 1e-5);
        let mut near = FxHashSet::default();
        if !(cell.is_finite() && cell > 0.0) {
            return Self { cell: f64::NAN, near };
        }
        let occupied: FxHashSet<[i64; 3]> = points.iter().map(|p| Self::cell_of(&PointTree::key(p), cell)).collect();
        for c in occupied {
            for dx in -1..=1 {
                for dy in -1..=1 {
                    for dz in -1..=1 {
                        near.insert([c[0].saturating_add(dx), c[1].saturating_add(dy), c[2].saturating_add(dz)]);
                    }
                }
            }
        }
        Self { cell, near }
    }

    fn cell_of(key: &[f32; 3], cell: f64) -> [i64; 3] {
        key.map(|v| (f64::from(v) / cell).floor() as i64)
    }

    /// False only when no point of the cloud is within the radius of `p`.
    pub fn may_reach(&self, p: &Point3<f64>) -> bool {
        if self.cell.is_nan() {
            return true;
        }
        self.near.contains(&Self::cell_of(&PointTree::key(p), self.cell))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::spatial::point_tree::squared_distance;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        /// A query the set turns away has no point within the radius, by brute force in the
        /// kd-tree's own arithmetic; queries at exactly the radius included.
        #[test]
        fn never_turns_away_a_query_with_a_point_within(
            points in prop::collection::vec((-20.0f64..20.0, -20.0f64..20.0, -3.0f64..3.0), 1..200),
            queries in prop::collection::vec((-25.0f64..25.0, -25.0f64..25.0, -4.0f64..4.0, 0.0f64..1.0, 0usize..200), 1..80),
            radius in 0.05f64..3.0,
        ) {
            let points: Vec<Point3<f64>> = points.iter().map(|&(x, y, z)| Point3::new(x, y, z)).collect();
            let reach = Reach::new(&points, radius);
            for (x, y, z, along, i) in queries {
                // A random query, and one on the sphere of the radius around a cloud point.
                let t = points[i % points.len()];
                let d = nalgebra::Vector3::new(x, y, z).normalize() * radius * along.max(0.999);
                for q in [Point3::new(x, y, z), t + d] {
                    let within = points.iter().any(|p| {
                        f64::from(squared_distance(&PointTree::key(p), &PointTree::key(&q))) <= radius * radius
                    });
                    prop_assert!(!within || reach.may_reach(&q), "{q:?} has a point within {radius}");
                }
            }
        }
    }

    #[test]
    fn far_queries_are_turned_away() {
        let points: Vec<Point3<f64>> = (0..100).map(|i| Point3::new(f64::from(i) * 0.1, 0.0, 0.0)).collect();
        let reach = Reach::new(&points, 1.0);
        assert!(reach.may_reach(&Point3::new(5.0, 0.9, 0.0)));
        assert!(!reach.may_reach(&Point3::new(5.0, 3.5, 0.0)));
        assert!(!reach.may_reach(&Point3::new(-3.5, 0.0, 0.0)));
        // A radius that is no radius turns nothing away.
        assert!(Reach::new(&points, 0.0).may_reach(&Point3::new(1e6, 0.0, 0.0)));
        assert!(Reach::new(&points, f64::NAN).may_reach(&Point3::new(1e6, 0.0, 0.0)));
    }
}
