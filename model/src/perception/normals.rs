//! Surface normals by principal component analysis of each point's k nearest neighbours: the
//! eigenvector of the smallest eigenvalue of their covariance. Points with fewer than 3
//! neighbours, or on a line, get no normal.

use nalgebra::{Matrix3, Point3, Vector3};

/// The normal of the surface through `points[i]` for each i of `neighbours` (at least 3; ICP
/// takes them from `spatial::neighbour_graph`, a point's k nearest within a radius).
pub fn of_neighbours(
    points: &[Point3<f64>],
    neighbours: impl IntoIterator<Item = usize> + Clone,
) -> Option<Vector3<f64>> {
    let (n, sum) =
        neighbours.clone().into_iter().fold((0usize, Vector3::zeros()), |(n, acc), i| (n + 1, acc + points[i].coords));
    if n < 3 {
        return None;
    }
    let mean = sum / n as f64;
    let mut cov = Matrix3::zeros();
    for i in neighbours {
        let d = points[i].coords - mean;
        cov += d * d.transpose();
    }
    smallest_eigenvector(&cov)
}

/// Unit eigenvector of the smallest eigenvalue of a symmetric positive semi-definite 3 × 3
/// matrix, in closed form (eigenvalues by the trigonometric solution of the characteristic
/// cubic, Smith 1961; the eigenvector as the largest cross product of two rows of A − λ I).
/// `None` when the two smallest eigenvalues are both ~0 (points on a line or a single point).
pub fn smallest_eigenvector(a: &Matrix3<f64>) -> Option<Vector3<f64>> {
    let scale = a.abs().max();
    if !scale.is_finite() || scale <= 0.0 {
        return None;
    }
    let m = a / scale;
    let q = m.trace() / 3.0;
    let p1 = m[(0, 1)].powi(2) + m[(0, 2)].powi(2) + m[(1, 2)].powi(2);
    let p2 = (m[(0, 0)] - q).powi(2) + (m[(1, 1)] - q).powi(2) + (m[(2, 2)] - q).powi(2) + 2.0 * p1;
    let p = (p2 / 6.0).sqrt();
    if p < 1e-15 {
        return None; // isotropic: no preferred direction
    }
    let b = (m - Matrix3::identity() * q) / p;
    let r = (b.determinant() / 2.0).clamp(-1.0, 1.0);
    let phi = r.acos() / 3.0;
    let largest = q + 2.0 * p * phi.cos();
    let smallest = q + 2.0 * p * (phi + 2.0 * std::f64::consts::FRAC_PI_3).cos();
    let middle = 3.0 * q - largest - smallest;
    // acos near ±1 amplifies rounding to ~1e-8: two eigenvalues below 1e-6 of the largest are
    // a line, not a plane.
    if middle <= 1e-6 * largest {
        return None;
    }
    let shifted = m - Matrix3::identity() * smallest;
    let (r0, r1, r2) = (shifted.row(0).transpose(), shifted.row(1).transpose(), shifted.row(2).transpose());
    let candidates = [r0.cross(&r1), r0.cross(&r2), r1.cross(&r2)];
    let best = candidates.iter().max_by(|x, y| x.norm_squared().total_cmp(&y.norm_squared()))?;
    let n = best.norm();
    (n > 0.0).then(|| best / n)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plane_normals_are_perpendicular() {
        use crate::spatial::neighbour_graph::NeighbourGraph;
        let estimate = |points: &[Point3<f64>], k: usize, radius: f64| -> Vec<Option<Vector3<f64>>> {
            let mut graph = NeighbourGraph::new(points, k, radius);
            (0..points.len()).map(|i| of_neighbours(points, graph.neighbours(i).iter().map(|&j| j as usize))).collect()
        };
        let pts: Vec<Point3<f64>> =
            (0..100).map(|k| Point3::new((k % 10) as f64 * 0.1, (k / 10) as f64 * 0.1, 2.0)).collect();
        for n in estimate(&pts, 8, 1.0) {
            let n = n.expect("plane");
            assert!((n.z.abs() - 1.0).abs() < 1e-9);
        }
        let line: Vec<Point3<f64>> = (0..20).map(|k| Point3::new(k as f64, 0.0, 0.0)).collect();
        assert!(estimate(&line, 5, 10.0).iter().all(Option::is_none));
    }

    #[test]
    fn closed_form_eigenvector_matches_nalgebra() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(4);
        for _ in 0..500 {
            let b = Matrix3::<f64>::from_fn(|_, _| rng.random_range(-1.0..1.0));
            let a: Matrix3<f64> = b * b.transpose();
            let eig = a.symmetric_eigen();
            let k = (0..3usize).min_by(|&i, &j| eig.eigenvalues[i].total_cmp(&eig.eigenvalues[j])).unwrap();
            let mut sorted: Vec<f64> = eig.eigenvalues.iter().copied().collect();
            sorted.sort_by(f64::total_cmp);
            if sorted[1] - sorted[0] < 1e-6 * sorted[2] {
                continue; // degenerate: the eigenvector is not unique
            }
            let ours = smallest_eigenvector(&a).unwrap();
            assert!(ours.dot(&eig.eigenvectors.column(k)).abs() > 1.0 - 1e-9);
        }
    }
}
