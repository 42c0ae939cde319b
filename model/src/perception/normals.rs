//! Surface normals by principal component analysis of each point's k nearest neighbours: the
//! eigenvector of the smallest eigenvalue of their covariance. Points with fewer than 3
//! neighbours, or on a line, get no normal. The kd-tree holds f32 coordinates: neighbour search
//! needs micrometres, not f64.

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use nalgebra::{Matrix3, Point3, Vector3};
use std::num::NonZero;

/// Normal of every point (`None` where undetermined), using `tree` built over `points`.
pub fn estimate(points: &[Point3<f64>], tree: &ImmutableKdTree<f32, 3>, k: usize) -> Vec<Option<Vector3<f64>>> {
    let Some(k) = NonZero::new(k.max(3)) else { return vec![None; points.len()] };
    points
        .iter()
        .map(|p| {
            let nearest = tree.nearest_n::<SquaredEuclidean>(&[p.x as f32, p.y as f32, p.z as f32], k);
            if nearest.len() < 3 {
                return None;
            }
            let n = nearest.len() as f64;
            let mean = nearest.iter().fold(Vector3::zeros(), |acc, nb| acc + points[nb.item as usize].coords) / n;
            let mut cov = Matrix3::zeros();
            for nb in &nearest {
                let d = points[nb.item as usize].coords - mean;
                cov += d * d.transpose();
            }
            let eig = cov.symmetric_eigen();
            let mut order = [0, 1, 2];
            order.sort_by(|&a, &b| eig.eigenvalues[a].total_cmp(&eig.eigenvalues[b]));
            // A line has two small eigenvalues: no plane to speak of.
            if eig.eigenvalues[order[1]] <= 1e-12 * eig.eigenvalues[order[2]].max(1e-300) {
                return None;
            }
            Some(eig.eigenvectors.column(order[0]).into_owned().normalize())
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plane_normals_are_perpendicular() {
        let pts: Vec<Point3<f64>> =
            (0..100).map(|k| Point3::new((k % 10) as f64 * 0.1, (k / 10) as f64 * 0.1, 2.0)).collect();
        let arr: Vec<[f32; 3]> = pts.iter().map(|p| [p.x as f32, p.y as f32, p.z as f32]).collect();
        let tree = ImmutableKdTree::new_from_slice(&arr);
        for n in estimate(&pts, &tree, 8) {
            let n = n.expect("plane");
            assert!((n.z.abs() - 1.0).abs() < 1e-9);
        }
        let line: Vec<Point3<f64>> = (0..20).map(|k| Point3::new(k as f64, 0.0, 0.0)).collect();
        let arr: Vec<[f32; 3]> = line.iter().map(|p| [p.x as f32, p.y as f32, p.z as f32]).collect();
        assert!(estimate(&line, &ImmutableKdTree::new_from_slice(&arr), 5).iter().all(Option::is_none));
    }
}
