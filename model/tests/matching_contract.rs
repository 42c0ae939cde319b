//! The matcher's contract through its public interface: exact recovery on noise-free data, the
//! verified matches, refusals (too few, collinear, symmetric, no overlap) and determinism.

use nalgebra::{Point3, Vector3};
use proptest::prelude::*;
use sgm_model::eval::matching_protocol::{generate_pair, PairSpec, SyntheticWorld};
use sgm_model::geometry::{pose_error, pose_from_yaw_translation, Pose3};
use sgm_model::matching::{
    match_graphs, GraphObject, LabelSimilarity, MatchOutcome, MatcherConfig, ObjectGraph, RefusalReason,
};
use sgm_model::scene_graph::{LabelId, ObjectId};

fn graph(points: &[(f64, f64, f64, u16)], remote_from_local: &Pose3, id_offset: u32) -> ObjectGraph {
    let objects = points
        .iter()
        .enumerate()
        .map(|(k, &(x, y, z, label))| GraphObject {
            id: ObjectId(id_offset + k as u32),
            label: LabelId(label),
            centroid: remote_from_local * Point3::new(x, y, z),
            size: None,
        })
        .collect();
    ObjectGraph::new(objects, 10_000).unwrap()
}

/// Eight objects on a circle of radius 20 m, labelled by `label(k)`.
fn ring_of_eight(label: impl Fn(usize) -> u16) -> Vec<(f64, f64, f64, u16)> {
    (0..8)
        .map(|k| {
            let a = k as f64 * std::f64::consts::TAU / 8.0;
            (20.0 * a.cos(), 20.0 * a.sin(), 0.5, label(k))
        })
        .collect()
}

fn refusal(outcome: &MatchOutcome) -> Option<&RefusalReason> {
    match outcome {
        MatchOutcome::Refused(r) => Some(&r.reason),
        MatchOutcome::Aligned(_) => None,
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// Noise-free objects seen from any planar rigid transform: the transform is recovered
    /// exactly and every shared object is matched to its counterpart.
    #[test]
    fn recovers_any_rigid_transform_exactly(
        yaw in -std::f64::consts::PI..std::f64::consts::PI, tx in -500.0f64..500.0, ty in -500.0f64..500.0, tz in -3.0f64..3.0,
        seed in 0u64..1000,
    ) {
        let spec = PairSpec { local: 20, remote: 20, overlap: 20, noisy: false, mislabels: 0 };
        let pair = generate_pair(&SyntheticWorld::default(), &spec, seed);
        // Re-express the remote graph in a further arbitrary frame.
        let moved_from_remote = pose_from_yaw_translation(yaw, Vector3::new(tx, ty, tz));
        let remote = ObjectGraph::new(
            pair.remote.objects().iter().map(|o| GraphObject { centroid: moved_from_remote * o.centroid, ..o.clone() }).collect(),
            100,
        ).unwrap();
        let truth = pair.local_from_remote * moved_from_remote.inverse();
        let config = MatcherConfig::default();
        let report = match_graphs(&pair.local, &remote, &LabelSimilarity::hard(6), &config);
        let MatchOutcome::Aligned(a) = &report.outcome else { panic!("refused: {:?}", report.outcome) };
        let e = pose_error(&a.local_from_remote, &truth);
        prop_assert!(e.translation_m < 1e-6 && e.max_axis_rotation_deg() < 1e-6, "{e:?}");
        let mut found: Vec<_> = a.matches.iter().map(|m| (m.local, m.remote)).collect();
        found.sort();
        prop_assert_eq!(found, pair.true_pairs.clone());
        prop_assert!(a.rmse_m < 1e-6);
    }
}

#[test]
fn refuses_too_few_objects() {
    let local = graph(&[(0.0, 0.0, 0.5, 0), (10.0, 0.0, 0.5, 1)], &Pose3::identity(), 0);
    let remote = local.clone();
    let report = match_graphs(&local, &remote, &LabelSimilarity::hard(2), &MatcherConfig::default());
    assert!(matches!(
        refusal(&report.outcome),
        Some(RefusalReason::TooFewObjects { local: 2, remote: 2, required: 3 })
    ));
}

#[test]
fn refuses_collinear_objects() {
    // Lamp posts along a straight path, identical in both graphs: the transform along the line
    // is not determined well, and the rule (≥ 3 non-collinear matches) refuses.
    let line: Vec<(f64, f64, f64, u16)> =
        (0..8).map(|k| (k as f64 * 7.3, 0.1 * (k % 2) as f64, 2.0, (k % 3) as u16)).collect();
    let remote_from_local = pose_from_yaw_translation(0.7, Vector3::new(4.0, -3.0, 0.0));
    let local = graph(&line, &Pose3::identity(), 0);
    let remote = graph(&line, &remote_from_local, 100);
    let report = match_graphs(&local, &remote, &LabelSimilarity::hard(3), &MatcherConfig::default());
    assert!(matches!(refusal(&report.outcome), Some(RefusalReason::Collinear { .. })), "{:?}", report.outcome);
}

#[test]
fn refuses_symmetric_layouts() {
    // Eight identical chairs on a circle: every rotation by 45° explains the data equally well.
    let ring = ring_of_eight(|_| 0);
    let remote_from_local = pose_from_yaw_translation(1.1, Vector3::new(30.0, 5.0, 0.0));
    let local = graph(&ring, &Pose3::identity(), 0);
    let remote = graph(&ring, &remote_from_local, 100);
    let report = match_graphs(&local, &remote, &LabelSimilarity::hard(1), &MatcherConfig::default());
    assert!(matches!(refusal(&report.outcome), Some(RefusalReason::Ambiguous { .. })), "{:?}", report.outcome);
}

#[test]
fn breaking_the_symmetry_with_labels_allows_the_match() {
    let ring = ring_of_eight(|k| {
        if k == 0 {
            1
        } else if k == 3 {
            2
        } else {
            0
        }
    });
    let remote_from_local = pose_from_yaw_translation(1.1, Vector3::new(30.0, 5.0, 0.0));
    let local = graph(&ring, &Pose3::identity(), 0);
    let remote = graph(&ring, &remote_from_local, 100);
    let report = match_graphs(&local, &remote, &LabelSimilarity::hard(3), &MatcherConfig::default());
    let a = report.outcome.alignment().expect("labels break the symmetry");
    let e = pose_error(&a.local_from_remote, &remote_from_local.inverse());
    assert!(e.translation_m < 1e-6 && e.yaw_deg < 1e-6);
    assert_eq!(a.matches.len(), 8);
}

#[test]
fn refuses_pairs_that_share_nothing() {
    let config = MatcherConfig::default();
    let labels = LabelSimilarity::uniform(6, config.mislabel_similarity);
    let mut claims = 0;
    for seed in 0..200 {
        let spec = PairSpec { local: 35, remote: 32, overlap: 0, noisy: true, mislabels: 0 };
        let pair = generate_pair(&SyntheticWorld::default(), &spec, seed);
        if match_graphs(&pair.local, &pair.remote, &labels, &config).outcome.alignment().is_some() {
            claims += 1;
        }
    }
    // Measured rate ~1% (`sgm bench matching --reps 1000`); fixed seeds make this deterministic.
    assert!(claims <= 6, "{claims} false claims in 200 non-overlapping pairs");
}

#[test]
fn mislabelled_objects_still_match_through_label_confusion() {
    let config = MatcherConfig::default();
    let spec = PairSpec { local: 35, remote: 32, overlap: 17, noisy: false, mislabels: 9 };
    let pair = generate_pair(&SyntheticWorld::default(), &spec, 4);
    let soft = match_graphs(&pair.local, &pair.remote, &LabelSimilarity::uniform(6, 0.3), &config);
    let a = soft.outcome.alignment().expect("8 correctly labelled shared objects suffice");
    assert!(a.matches.iter().filter(|m| !m.same_label).count() >= 8, "mislabelled pairs are recovered");
    let hard = match_graphs(&pair.local, &pair.remote, &LabelSimilarity::hard(6), &config);
    if let Some(h) = hard.outcome.alignment() {
        assert!(h.matches.iter().all(|m| m.same_label));
    }
}

#[test]
fn same_input_gives_identical_output() {
    let config = MatcherConfig::default();
    let spec = PairSpec { local: 35, remote: 32, overlap: 17, noisy: true, mislabels: 3 };
    let pair = generate_pair(&SyntheticWorld::default(), &spec, 9);
    let labels = LabelSimilarity::uniform(6, 0.3);
    let a = match_graphs(&pair.local, &pair.remote, &labels, &config);
    let b = match_graphs(&pair.local, &pair.remote, &labels, &config);
    assert_eq!(a, b);
}

#[test]
fn large_graphs_match_at_the_paper_density() {
    // 200 / 200 objects, half shared, noisy: the eigenvector ranks poorly at this size (stage-2
    // seed sampling and the Lanczos solver are exercised); every pair must still align.
    let config = MatcherConfig::default();
    let labels = LabelSimilarity::uniform(6, config.mislabel_similarity);
    for seed in 0..3 {
        let spec = PairSpec { local: 200, remote: 200, overlap: 100, noisy: true, mislabels: 0 };
        let pair = generate_pair(&SyntheticWorld::with_density_for(300), &spec, seed);
        let report = match_graphs(&pair.local, &pair.remote, &labels, &config);
        let a = report.outcome.alignment().unwrap_or_else(|| panic!("seed {seed}: {:?}", report.outcome));
        let e = pose_error(&a.local_from_remote, &pair.local_from_remote);
        assert!(e.translation_m < 2.0 && e.max_axis_rotation_deg() < 20.0, "seed {seed}: {e:?}");
        let correct = a.matches.iter().filter(|m| pair.true_pairs.contains(&(m.local, m.remote))).count();
        assert!(
            correct * 10 >= pair.true_pairs.len() * 9,
            "seed {seed}: {correct} of {} shared objects",
            pair.true_pairs.len()
        );
        // Unshared objects that happen to lie within the inlier radius of a compatible local
        // object are indistinguishable by geometry: measured precision 91–98% here.
        assert!(correct * 10 >= a.matches.len() * 9, "seed {seed}: precision {correct} of {}", a.matches.len());
    }
}
