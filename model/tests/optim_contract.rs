//! Pose-graph optimisation through its public interface: closed-form optima, g2o round trip and
//! malformed input, robust kernels against injected outliers.

use nalgebra::{Isometry2, SMatrix, Translation2, UnitComplex};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use sgm_model::optim::factors::Between;
use sgm_model::optim::g2o::{read_g2o, write_g2o, G2oGraph};
use sgm_model::optim::graph::{Graph2, GTSAM_PRIOR_SIGMAS_2D};
use sgm_model::optim::robust::{optimize_gnc_incremental, optimize_robust, RobustKernel};
use sgm_model::optim::solver::{optimize, LmParams};

fn pose(x: f64, y: f64, th: f64) -> Isometry2<f64> {
    Isometry2::from_parts(Translation2::new(x, y), UnitComplex::new(th))
}

fn planar(text: &str) -> Graph2 {
    match read_g2o(&[text]).unwrap() {
        G2oGraph::Planar(g) => g,
        G2oGraph::Spatial(_) => panic!("planar expected"),
    }
}

#[test]
fn conflicting_translations_average_in_closed_form() {
    // x0 fixed; z01 = z12 = 1, z02 = 2.3 along x with equal information:
    // minimise (x1 − 1)² + (x2 − x1 − 1)² + (x2 − 2.3)²  ⇒  x1 = 1.1, x2 = 2.2.
    let text = "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 0.5 0.3 0.1\nVERTEX_SE2 2 3 -0.2 -0.1\nFIX 0\n\
                EDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\nEDGE_SE2 1 2 1 0 0 1 0 0 1 0 1\nEDGE_SE2 0 2 2.3 0 0 1 0 0 1 0 1\n";
    let mut g = planar(text);
    let tight = LmParams { relative_error_tol: 1e-15, absolute_error_tol: 1e-20, ..LmParams::default() };
    let summary = optimize(&mut g, &tight).unwrap();
    assert!((g.values[1].translation.vector - nalgebra::Vector2::new(1.1, 0.0)).norm() < 1e-7);
    assert!((g.values[2].translation.vector - nalgebra::Vector2::new(2.2, 0.0)).norm() < 1e-7);
    assert!(g.values[1].rotation.angle().abs() < 1e-7 && g.values[2].rotation.angle().abs() < 1e-7);
    // Residuals −0.1 each at unit information: error ½ · 3 · 0.01.
    assert!((summary.final_error - 0.015).abs() < 1e-9, "{summary:?}");
    assert!(summary.converged);
}

#[test]
fn gauss_newton_and_lm_agree_and_a_chain_closes_exactly() {
    let text = "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 0 0 0\nVERTEX_SE2 2 0 0 0\n\
                EDGE_SE2 0 1 1 0 1.5707963267948966 100 0 0 100 0 400\nEDGE_SE2 1 2 2 0.5 0.3 100 0 0 100 0 400\n";
    for gauss_newton in [false, true] {
        let mut g = planar(text);
        g.add_prior_at_current(0, GTSAM_PRIOR_SIGMAS_2D);
        let s = optimize(&mut g, &LmParams { gauss_newton, ..LmParams::default() }).unwrap();
        assert!(s.final_error < 1e-18, "{s:?}");
        let expected = pose(1.0, 0.0, std::f64::consts::FRAC_PI_2) * pose(2.0, 0.5, 0.3);
        assert!((g.values[2].translation.vector - expected.translation.vector).norm() < 1e-9);
    }
}

#[test]
fn g2o_round_trips_exactly() {
    for path in ["../../shared/data/posegraph/3d/smallGrid3D.g2o", "../../shared/data/posegraph/2d/intel.g2o"] {
        let text = std::fs::read_to_string(std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(path))
            .expect("shared data beside the repo");
        let a = read_g2o(&[&text]).unwrap();
        let b = read_g2o(&[&write_g2o(&a)]).unwrap();
        match (&a, &b) {
            (G2oGraph::Planar(x), G2oGraph::Planar(y)) => {
                assert_eq!(x.keys, y.keys);
                let close = |p: &Isometry2<f64>, q: &Isometry2<f64>| {
                    (p.inverse() * q).translation.vector.norm() < 1e-12
                        && (p.inverse() * q).rotation.angle().abs() < 1e-12
                };
                assert!(x.values.iter().zip(&y.values).all(|(p, q)| close(p, q)));
                for (e, f) in x.betweens.iter().zip(&y.betweens) {
                    assert_eq!((e.from, e.to), (f.from, f.to));
                    assert!(close(&e.measured, &f.measured));
                    assert!((e.sqrt_information - f.sqrt_information).norm() < 1e-9 * e.sqrt_information.norm());
                }
            }
            (G2oGraph::Spatial(x), G2oGraph::Spatial(y)) => {
                assert_eq!(x.keys, y.keys);
                for (p, q) in x.values.iter().zip(&y.values) {
                    assert!(
                        (p.inverse() * q).translation.vector.norm() < 1e-12
                            && (p.inverse() * q).rotation.angle() < 1e-12
                    );
                }
                for (e, f) in x.betweens.iter().zip(&y.betweens) {
                    assert!((e.sqrt_information - f.sqrt_information).norm() < 1e-9 * e.sqrt_information.norm());
                }
            }
            _ => panic!("kind changed"),
        }
    }
}

#[test]
fn malformed_lines_name_the_line_and_the_fault() {
    let cases = [
        ("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 0 0\n", 2, "needs 3 numbers"),
        ("VERTEX_SE2 0 0 0 0\nEDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\n", 2, "unknown vertex 1"),
        ("VERTEX_SE2 x 0 0 0\n", 1, "not a vertex id"),
        ("VERTEX_SE2 0 0 nan 0\n", 1, "not finite"),
        ("VERTEX_SE2 0 0 abc 0\n", 1, "not a number"),
        ("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 0 0 0\nEDGE_SE2 0 1 1 0 0 -1 0 0 1 0 1\n", 3, "not positive definite"),
        ("VERTEX_SE2 0 0 0 0\nVERTEX_SE3:QUAT 1 0 0 0 0 0 0 1\n", 2, "mixes SE(2) and SE(3)"),
        ("VERTEX_SE3:QUAT 1 0 0 0 0 0 0 0\n", 1, "zero norm"),
        ("\n# comment\nVERTEX_XYZ 1 0 0 0\n", 3, "unknown element"),
        ("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 0 5 0 0\n", 2, "defined twice"),
        ("VERTEX_SE2 0 0 0 0\nFIX 7\n", 2, "FIX of unknown vertex 7"),
        ("VERTEX_SE2 0 0 0 0\nEDGE_SE2 0 0 1 0 0 1 0 0 1 0 1\n", 2, "to itself"),
    ];
    for (text, line, fragment) in cases {
        let (file, e) = read_g2o(&[text]).unwrap_err();
        assert_eq!((file, e.line), (0, line), "{text:?}: {e}");
        assert!(e.to_string().contains(fragment), "{text:?}: {e}");
    }
    // In a multi-file load the error names the right file.
    let (file, e) =
        read_g2o(&["VERTEX_SE2 0 0 0 0\n", "VERTEX_SE2 1 0 0 0\nEDGE_SE2 1 9 1 0 0 1 0 0 1 0 1\n"]).unwrap_err();
    assert_eq!((file, e.line), (1, 2));
}

/// A planar square-spiral trajectory with odometry and loop closures to poses ~4 m away, plus
/// `outliers` random wrong loop closures. Returns the graph and the outliers' edge indices.
fn spiral_with_outliers(outliers: usize, seed: u64) -> (Graph2, Vec<usize>) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let n = 300;
    let truth: Vec<Isometry2<f64>> = (0..n)
        .map(|k| {
            let lap = k / 40;
            let a = (k % 40) as f64 / 40.0 * std::f64::consts::TAU;
            let r = 10.0 + lap as f64 * 0.5;
            pose(r * a.cos(), r * a.sin(), a + std::f64::consts::FRAC_PI_2)
        })
        .collect();
    let info = SMatrix::<f64, 3, 3>::from_diagonal(&nalgebra::Vector3::new(100.0, 100.0, 1000.0));
    let sqrt_information = info.cholesky().unwrap().l().transpose();
    let noisy = |rng: &mut ChaCha8Rng, z: Isometry2<f64>| {
        z * pose(rng.random_range(-0.02..0.02), rng.random_range(-0.02..0.02), rng.random_range(-0.005..0.005))
    };
    let mut g = Graph2 {
        keys: (0..n as u64).collect(),
        values: vec![],
        fixed: vec![false; n],
        betweens: vec![],
        priors: vec![],
    };
    let mut current = truth[0];
    for k in 0..n {
        if k > 0 {
            let z = noisy(&mut rng, truth[k - 1].inverse() * truth[k]);
            g.betweens.push(Between { from: k - 1, to: k, measured: z, sqrt_information });
            current *= z;
        }
        g.values.push(current);
        if k >= 40 {
            let z = noisy(&mut rng, truth[k - 40].inverse() * truth[k]);
            g.betweens.push(Between { from: k - 40, to: k, measured: z, sqrt_information });
        }
    }
    let mut bad = Vec::new();
    for _ in 0..outliers {
        let (a, b) = (rng.random_range(0..n), rng.random_range(0..n));
        if a.abs_diff(b) < 2 {
            continue;
        }
        let z = pose(rng.random_range(-20.0..20.0), rng.random_range(-20.0..20.0), rng.random_range(-3.0..3.0));
        bad.push(g.betweens.len());
        g.betweens.push(Between { from: a, to: b, measured: z, sqrt_information });
    }
    g.add_prior_at_current(0, GTSAM_PRIOR_SIGMAS_2D);
    (g, bad)
}

#[test]
fn gnc_rejects_injected_outliers_and_recovers_the_clean_optimum() {
    let (mut clean, _) = spiral_with_outliers(0, 3);
    let clean_summary = optimize(&mut clean, &LmParams::default()).unwrap();
    let (mut dirty, bad) = spiral_with_outliers(52, 3); // ~20% of the 260 loop closures
    let plain = optimize(&mut dirty.clone(), &LmParams::default()).unwrap();
    let (summary, rejected) = optimize_robust(&mut dirty, &LmParams::default(), RobustKernel::Gnc).unwrap();
    let caught = bad.iter().filter(|k| rejected.contains(k)).count();
    assert!(caught * 100 >= bad.len() * 95, "rejected {caught} of {} outliers", bad.len());
    assert!(rejected.len() <= bad.len() + 3, "{} rejected for {} outliers", rejected.len(), bad.len());
    // On the inliers, the result is the clean optimum.
    let worst = dirty
        .values
        .iter()
        .zip(&clean.values)
        .map(|(a, b)| (a.inverse() * b).translation.vector.norm())
        .fold(0.0, f64::max);
    assert!(worst < 0.05, "GNC solution {worst} m from the clean one");
    assert!(
        summary.final_error < 1.01 * clean_summary.final_error + 1e-9,
        "{} vs {}",
        summary.final_error,
        clean_summary.final_error
    );
    assert!(plain.final_error > 100.0 * clean_summary.final_error, "outliers do corrupt least squares");
}

#[test]
fn m_estimators_downweight_outliers() {
    let (clean, _) = spiral_with_outliers(0, 5);
    let mut reference = clean.clone();
    optimize(&mut reference, &LmParams::default()).unwrap();
    let (dirty, _) = spiral_with_outliers(10, 5);
    let distance = |g: &Graph2| {
        g.values
            .iter()
            .zip(&reference.values)
            .map(|(a, b)| (a.inverse() * b).translation.vector.norm())
            .fold(0.0, f64::max)
    };
    let mut plain = dirty.clone();
    optimize(&mut plain, &LmParams::default()).unwrap();
    for kernel in [RobustKernel::Huber, RobustKernel::Cauchy] {
        let mut g = dirty.clone();
        optimize_robust(&mut g, &LmParams::default(), kernel).unwrap();
        assert!(distance(&g) < 0.5 * distance(&plain), "{kernel:?}: {} vs plain {}", distance(&g), distance(&plain));
    }
}

mod marginals_and_incremental {
    use super::*;
    use nalgebra::{DMatrix, Isometry3};
    use sgm_model::optim::g2o::read_g2o;
    use sgm_model::optim::graph::{Graph3, GTSAM_PRIOR_SIGMAS_3D};
    use sgm_model::optim::marginals::marginal_covariances;
    use sgm_model::optim::solver::{Optimizer, Structure};

    fn grid(name: &str) -> Graph3 {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/posegraph/3d").join(name);
        let text = std::fs::read_to_string(path).expect("shared data beside the repo");
        let G2oGraph::Spatial(mut g) = read_g2o(&[&text]).unwrap() else { panic!("3-D") };
        g.add_prior_at_current(0, GTSAM_PRIOR_SIGMAS_3D);
        g
    }

    fn tiny_grid() -> Graph3 {
        grid("tinyGrid3D.g2o")
    }

    /// Each requested pose's covariance against the dense inverse of H = Jᵀ J built here from the
    /// factor Jacobians, the poses asked for in the order given.
    fn check_against_the_dense_inverse(g: &Graph3, asked: &[usize]) {
        let n = g.values.len() * 6;
        let rows = (g.betweens.len() + g.priors.len()) * 6;
        let mut j = DMatrix::<f64>::zeros(rows, n);
        for (k, f) in g.betweens.iter().enumerate() {
            let lin = f.linearize(&g.values[f.from], &g.values[f.to]);
            j.view_mut((k * 6, f.from * 6), (6, 6)).copy_from(&lin.d_from);
            j.view_mut((k * 6, f.to * 6), (6, 6)).copy_from(&lin.d_to);
        }
        for (k, p) in g.priors.iter().enumerate() {
            let (_, jp) = p.linearize(&g.values[p.variable]);
            j.view_mut(((g.betweens.len() + k) * 6, p.variable * 6), (6, 6)).copy_from(&jp);
        }
        let dense = (j.transpose() * &j).try_inverse().expect("anchored graph");
        let structure = Structure::new(g).unwrap();
        let cov = marginal_covariances(g, &structure, asked).unwrap();
        assert_eq!(cov.len(), asked.len());
        for (c, &k) in cov.iter().zip(asked) {
            let reference = dense.view((k * 6, k * 6), (6, 6));
            assert!((c - reference).norm() < 1e-9 * reference.norm().max(1e-12), "pose {k}: {c} vs {reference}");
            assert!(c.symmetric_eigenvalues().min() > 0.0);
        }
    }

    #[test]
    fn marginals_equal_the_dense_inverse_of_the_stacked_jacobian() {
        let mut g = tiny_grid();
        optimize(&mut g, &LmParams::default()).unwrap();
        check_against_the_dense_inverse(&g, &(0..g.values.len()).collect::<Vec<_>>());
    }

    #[test]
    fn marginals_of_more_poses_than_one_batch_equal_the_dense_inverse() {
        // smallGrid3D's 125 poses: four batches of 32, asked for newest first and one twice.
        let mut g = grid("smallGrid3D.g2o");
        optimize(&mut g, &LmParams::default()).unwrap();
        let mut asked: Vec<usize> = (0..g.values.len()).rev().collect();
        asked.push(40);
        assert!(asked.len() > 3 * 32);
        check_against_the_dense_inverse(&g, &asked);
    }

    #[test]
    fn covariance_of_a_chain_adds_up_in_closed_form() {
        // x0 with prior σ0, x1 = x0 · z with z = identity and σ1: Cov(x1) = Σ0 + Σ1 (Ad = I).
        let sigma0 = [0.1, 0.2, 0.3, 1.0, 2.0, 3.0];
        let sigma1 = [0.05, 0.05, 0.05, 0.5, 0.5, 0.5];
        let mut g = Graph3 {
            keys: vec![0, 1],
            values: vec![Isometry3::identity(); 2],
            fixed: vec![false; 2],
            betweens: vec![],
            priors: vec![],
        };
        g.add_prior_at_current(0, sigma0);
        let s1 = SMatrix::<f64, 6, 6>::from_diagonal(&nalgebra::SVector::<f64, 6>::from_iterator(
            sigma1.iter().map(|s| 1.0 / s),
        ));
        g.betweens.push(Between { from: 0, to: 1, measured: Isometry3::identity(), sqrt_information: s1 });
        let structure = Structure::new(&g).unwrap();
        let cov = marginal_covariances(&g, &structure, &[0, 1]).unwrap();
        for k in 0..6 {
            assert!((cov[0][(k, k)] - sigma0[k] * sigma0[k]).abs() < 1e-12);
            assert!((cov[1][(k, k)] - (sigma0[k] * sigma0[k] + sigma1[k] * sigma1[k])).abs() < 1e-12);
        }
    }

    #[test]
    fn incremental_solves_reuse_the_symbolic_factorisation_while_the_structure_holds() {
        let (full, _) = spiral_with_outliers(0, 9);
        let mut reference = full.clone();
        optimize(&mut reference, &LmParams::default()).unwrap();

        // Robot's view: the first 150 poses, then everything, then one more measurement between
        // already-joined poses and a new prior (same structure: symbolic reused).
        let keep = |g: &Graph2, n: usize| {
            let mut part = g.clone();
            part.keys.truncate(n);
            part.values.truncate(n);
            part.fixed.truncate(n);
            part.betweens.retain(|f| f.from < n && f.to < n);
            part.priors.retain(|p| p.variable < n);
            part
        };
        let mut optimizer = Optimizer::new();
        let mut g = keep(&full, 150);
        optimizer.optimize(&mut g, &LmParams::default()).unwrap();
        let mut grown = full.clone();
        grown.values[..150].copy_from_slice(&g.values); // warm start where known
        optimizer.optimize(&mut grown, &LmParams::default()).unwrap();
        assert_eq!((optimizer.symbolic_builds, optimizer.symbolic_reuses), (2, 0));
        let repeat = grown.betweens[10].clone();
        grown.betweens.push(repeat);
        grown.add_prior_at_current(200, GTSAM_PRIOR_SIGMAS_2D);
        optimizer.optimize(&mut grown, &LmParams::default()).unwrap();
        assert_eq!((optimizer.symbolic_builds, optimizer.symbolic_reuses), (2, 1));
        // Same optimum as a fresh solve of the same graph.
        let mut fresh = full.clone();
        fresh.betweens.push(grown.betweens.last().unwrap().clone());
        fresh.priors = grown.priors.clone();
        optimize(&mut fresh, &LmParams::default()).unwrap();
        let worst = fresh
            .values
            .iter()
            .zip(&grown.values)
            .map(|(a, b)| (a.inverse() * b).translation.vector.norm())
            .fold(0.0, f64::max);
        assert!(worst < 1e-4, "{worst}");
    }
}

#[test]
fn incremental_gnc_decides_as_batch_gnc_and_keeps_a_decision_that_still_holds() {
    let (dirty, bad) = spiral_with_outliers(52, 3);
    let candidates: Vec<bool> =
        dirty.betweens.iter().map(|f| dirty.keys[f.from].abs_diff(dirty.keys[f.to]) != 1).collect();
    let mut batch = dirty.clone();
    let (_, batch_rejected) = optimize_robust(&mut batch, &LmParams::default(), RobustKernel::Gnc).unwrap();
    // No previous decision: least squares fails the check, so full GNC runs — the batch answer.
    let mut incremental = dirty.clone();
    let (_, rejected) = optimize_gnc_incremental(&mut incremental, &LmParams::default(), &candidates, &[]).unwrap();
    assert_eq!(rejected, batch_rejected);
    assert!(bad.iter().all(|k| rejected.contains(k)), "an outlier was kept");
    // The decision still holds at the solution: one least-squares solve keeps it and moves nothing.
    let before = incremental.values.clone();
    let (summary, again) =
        optimize_gnc_incremental(&mut incremental, &LmParams::default(), &candidates, &rejected).unwrap();
    assert_eq!(again, rejected);
    assert!(summary.iterations <= 2, "{} linearisations", summary.iterations);
    let moved = before
        .iter()
        .zip(&incremental.values)
        .map(|(a, b)| (a.inverse() * b).translation.vector.norm())
        .fold(0.0, f64::max);
    assert!(moved < 1e-3, "{moved}");
    // A stale decision (an inlier left out) is made again from scratch.
    let inlier = (0..candidates.len()).find(|k| candidates[*k] && !rejected.contains(k)).unwrap();
    let mut stale = rejected.clone();
    stale.push(inlier);
    let (_, redone) = optimize_gnc_incremental(&mut incremental, &LmParams::default(), &candidates, &stale).unwrap();
    assert!(!redone.contains(&inlier));
    assert!(bad.iter().all(|k| redone.contains(k)));
}
