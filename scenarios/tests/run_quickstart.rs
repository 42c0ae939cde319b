//! The main job end to end: `quickstart` runs, its robots align, its report is byte-identical
//! on a second run (determinism, in the manner of copper-rs's test), and its ATE equals an
//! independent computation from the TUM files it wrote (Horn's closed-form quaternion
//! alignment, not the SVD the product uses).

use nalgebra::{Matrix3, Matrix4, Point3, Quaternion, SymmetricEigen, UnitQuaternion, Vector3};
use sgm_scenarios::report;
use sgm_scenarios::runner::run;
use sgm_scenarios::scenario::Scenario;
use std::path::Path;

fn run_into(dir: &Path) -> report::Report {
    let scenario = Scenario::load_with_env("quickstart", "SGM_QUICKSTART_TEST").unwrap();
    let outcome = actix_rt::System::new().block_on(run(&scenario, None)).unwrap();
    report::write(&outcome, dir).unwrap()
}

fn read_tum(path: &Path) -> Vec<(f64, Point3<f64>)> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .map(|l| {
            let v: Vec<f64> = l.split_whitespace().map(|x| x.parse().unwrap()).collect();
            (v[0], Point3::new(v[1], v[2], v[3]))
        })
        .collect()
}

/// Horn (1987): the rotation is the unit quaternion of the largest eigenvalue of N(S).
fn horn_rmse(estimate: &[Point3<f64>], truth: &[Point3<f64>]) -> f64 {
    let n = estimate.len() as f64;
    let me = estimate.iter().fold(Vector3::zeros(), |a, p| a + p.coords) / n;
    let mt = truth.iter().fold(Vector3::zeros(), |a, p| a + p.coords) / n;
    let mut s = Matrix3::zeros();
    for (e, t) in estimate.iter().zip(truth) {
        s += (e.coords - me) * (t.coords - mt).transpose();
    }
    let (sxx, sxy, sxz, syx, syy, syz, szx, szy, szz) =
        (s[(0, 0)], s[(0, 1)], s[(0, 2)], s[(1, 0)], s[(1, 1)], s[(1, 2)], s[(2, 0)], s[(2, 1)], s[(2, 2)]);
    let m = Matrix4::new(
        sxx + syy + szz,
        syz - szy,
        szx - sxz,
        sxy - syx,
        syz - szy,
        sxx - syy - szz,
        sxy + syx,
        szx + sxz,
        szx - sxz,
        sxy + syx,
        -sxx + syy - szz,
        syz + szy,
        sxy - syx,
        szx + sxz,
        syz + szy,
        -sxx - syy + szz,
    );
    let eig = SymmetricEigen::new(m);
    let k = eig.eigenvalues.imax();
    let q = eig.eigenvectors.column(k);
    let r = UnitQuaternion::from_quaternion(Quaternion::new(q[0], q[1], q[2], q[3]));
    let t = mt - r * me;
    let sum: f64 = estimate.iter().zip(truth).map(|(e, p)| (p.coords - (r * e.coords + t)).norm_squared()).sum();
    (sum / n).sqrt()
}

#[test]
fn quickstart_aligns_is_deterministic_and_its_ate_checks_out() {
    let (a, b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let report = run_into(a.path());
    let _ = run_into(b.path());
    let json_a = std::fs::read(a.path().join("report.json")).unwrap();
    let json_b = std::fs::read(b.path().join("report.json")).unwrap();
    assert!(json_a == json_b, "report.json differs between two runs of the same scenario and seed");

    // Both robots aligned, within the bounds.
    assert_eq!(report.alignments.len(), 2, "{:?}", report.alignments);
    for alignment in &report.alignments {
        assert_eq!(alignment.state, "Aligned", "{alignment:?}");
        assert!(alignment.translation_error_m.unwrap() < 0.5, "{alignment:?}");
        assert!(alignment.rotation_error_deg.unwrap() < 2.0, "{alignment:?}");
    }
    assert!(report.team_ate_rmse_m.unwrap() < 1.0, "{:?}", report.team_ate_rmse_m);
    assert_eq!(report.team_ate_robots, ["alpha", "bravo"]);

    // ATE from the TUM files by another method.
    for (estimate, truth, expected) in [
        ("team.tum", "team.truth.tum", report.team_ate_rmse_m.unwrap()),
        ("alpha.tum", "alpha.truth.tum", report.robots[0].ate_rmse_m.unwrap()),
    ] {
        let (e, t) = (read_tum(&a.path().join(estimate)), read_tum(&a.path().join(truth)));
        assert_eq!(e.len(), t.len());
        assert!(e.iter().zip(&t).all(|(x, y)| x.0 == y.0), "stamps pair up");
        let (e, t): (Vec<_>, Vec<_>) = (e.into_iter().map(|x| x.1).collect(), t.into_iter().map(|x| x.1).collect());
        let horn = horn_rmse(&e, &t);
        // The TUM files round to 1 nm: the two methods agree far below a millimetre.
        assert!((horn - expected).abs() < 1e-6, "{estimate}: {horn} vs {expected}");
    }

    // The message table and the rest of the directory.
    assert!(report.messages["ObjectData"].count > 0 && report.messages["KeyframeResponse"].count > 0);
    assert!(report.point_cloud_raw.bytes_total > 0 && report.bytes_ratio_to_raw < 0.2);
    for file in
        ["report.md", "timing.json", "map.png", "ate.png", "bytes.png", "map.pcd", "alpha.tum", "bravo.truth.tum"]
    {
        let meta = std::fs::metadata(a.path().join(file)).unwrap_or_else(|e| panic!("{file}: {e}"));
        assert!(meta.len() > 0, "{file} is empty");
    }
    let map = sgm_model::pcd::read_pcd(&std::fs::read(a.path().join("map.pcd")).unwrap()).unwrap();
    assert!(map.len() > 1000 && map.column_of("label").is_some());
}

/// `matcher.association = "none"` (the evaluation's no-association baseline): object data still
/// flows, but no robot matches, asks for object clouds or keyframes, or aligns.
#[test]
fn without_association_object_data_flows_and_nothing_aligns() {
    let mut scenario = Scenario::load_with_env("quickstart", "SGM_QUICKSTART_NONE_TEST").unwrap();
    scenario.matcher.association = sgm_actors::config::Association::None;
    let outcome = actix_rt::System::new().block_on(run(&scenario, None)).unwrap();
    let report = report::compute(&outcome.record);
    assert!(report.alignments.iter().all(|a| a.first_aligned_s.is_none()), "{:?}", report.alignments);
    assert!(report.messages["ObjectData"].count > 0);
    for kind in ["ObjectCloudRequest", "ObjectCloudResponse", "KeyframeRequest", "KeyframeResponse"] {
        assert_eq!(report.messages[kind].count, 0, "{kind}");
    }
}

/// `matcher.association = "scan_context"` (the evaluation's Swarm-SC baseline): descriptors
/// replace object data, and the robots align through keyframe ICP alone. With a strict
/// descriptor threshold (0.1) the first candidate is a true revisit and both robots align to a
/// few centimetres; at the default 0.13 this campus's 90° symmetry gives a false candidate at
/// 0.127 that keyframe ICP cannot refute (the evaluation chapter's Table 3 shows the cost).
#[test]
fn scan_context_association_aligns_without_object_data() {
    let mut scenario = Scenario::load_with_env("quickstart", "SGM_QUICKSTART_SC_TEST").unwrap();
    scenario.matcher.association = sgm_actors::config::Association::ScanContext;
    scenario.matcher.scan_context.max_distance = 0.1;
    let outcome = actix_rt::System::new().block_on(run(&scenario, None)).unwrap();
    let report = report::compute(&outcome.record);
    for kind in ["ObjectData", "ObjectCloudRequest", "ObjectCloudResponse"] {
        assert_eq!(report.messages[kind].count, 0, "{kind}");
    }
    assert!(report.messages["KeyframeDescriptors"].count > 0);
    assert!(report.messages["KeyframeResponse"].count > 0);
    for a in &report.alignments {
        let error = a.translation_error_m.unwrap_or(f64::INFINITY);
        assert!(a.first_aligned_s.is_some() && error < 0.5, "{a:?}");
    }
}
