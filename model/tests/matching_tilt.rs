//! Tilted frames (`matching::tilt`): a remote frame tilted by a few degrees is recovered in 6-DoF;
//! with `max_tilt_deg = 0` the transform stays 4-DoF (x, y, z, yaw).

use nalgebra::{Point3, Unit, UnitQuaternion, Vector3};
use proptest::prelude::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use sgm_model::eval::matching_protocol::{generate_pair, PairSpec, SyntheticWorld};
use sgm_model::geometry::{pose_error, pose_from_yaw_translation, Pose3};
use sgm_model::matching::tilt::tilt_slope;
use sgm_model::matching::{match_graphs, GraphObject, LabelSimilarity, MatchOutcome, MatcherConfig, ObjectGraph};
use sgm_model::scene_graph::{LabelId, ObjectId};

/// `count` objects of 6 labels spread over a 60 m square, centroids 0–2 m high.
fn scene(count: usize, seed: u64) -> Vec<(Point3<f64>, u16)> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..count)
        .map(|_| {
            let p = Point3::new(rng.random_range(0.0..60.0), rng.random_range(0.0..60.0), rng.random_range(0.0..2.0));
            (p, rng.random_range(0..6))
        })
        .collect()
}

/// The scene in a frame: `frame_from_scene` applied, then uniform noise of ±`xy` m horizontally
/// and ±`z` m vertically.
fn graph(scene: &[(Point3<f64>, u16)], frame_from_scene: &Pose3, (xy, z): (f64, f64), seed: u64) -> ObjectGraph {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut noise = |k: f64| if k > 0.0 { rng.random_range(-k..k) } else { 0.0 };
    let objects = scene
        .iter()
        .enumerate()
        .map(|(k, &(p, label))| GraphObject {
            id: ObjectId(k as u32),
            label: LabelId(label),
            centroid: frame_from_scene * p + Vector3::new(noise(xy), noise(xy), noise(z)),
            size: None,
        })
        .collect();
    ObjectGraph::new(objects, 10_000).unwrap()
}

/// A frame yawed by `yaw`, tilted by `tilt_deg` about the horizontal axis at `azimuth`, shifted.
fn tilted(yaw: f64, tilt_deg: f64, azimuth: f64, t: Vector3<f64>) -> Pose3 {
    let axis = Unit::new_normalize(Vector3::new(azimuth.cos(), azimuth.sin(), 0.0));
    let tilt = UnitQuaternion::from_axis_angle(&axis, tilt_deg.to_radians());
    let mut pose = pose_from_yaw_translation(yaw, t);
    pose.rotation = tilt * pose.rotation;
    pose
}

fn aligned(local: &ObjectGraph, remote: &ObjectGraph, config: &MatcherConfig) -> Pose3 {
    let report = match_graphs(local, remote, &LabelSimilarity::hard(6), config);
    let MatchOutcome::Aligned(a) = &report.outcome else { panic!("refused: {:?}", report.outcome) };
    a.local_from_remote
}

#[test]
fn a_three_degree_tilt_is_recovered_exactly() {
    let objects = scene(30, 1);
    let local_from_remote = tilted(0.7, 3.0, 0.4, Vector3::new(12.0, -30.0, 0.8));
    let local = graph(&objects, &Pose3::identity(), (0.0, 0.0), 0);
    let remote = graph(&objects, &local_from_remote.inverse(), (0.0, 0.0), 0);
    let estimate = aligned(&local, &remote, &MatcherConfig::default());
    let e = pose_error(&estimate, &local_from_remote);
    assert!(e.max_axis_rotation_deg() < 0.05 && e.translation_m < 0.05, "{e:?}");
    // The planar (4-DoF) matcher keeps the 3° error: the refit is what recovers it.
    let flat = MatcherConfig { max_tilt_deg: 0.0, ..MatcherConfig::default() };
    let e = pose_error(&aligned(&local, &remote, &flat), &local_from_remote);
    assert!(e.max_axis_rotation_deg() > 2.0, "{e:?}");
}

#[test]
fn without_tilt_the_transform_stays_four_dof() {
    let objects = scene(30, 2);
    let local = graph(&objects, &Pose3::identity(), (0.0, 0.0), 0);
    let flat = MatcherConfig { max_tilt_deg: 0.0, ..MatcherConfig::default() };
    // Tilted frames, max_tilt 0: still a pure yaw.
    let remote = graph(&objects, &tilted(-1.2, 3.0, 2.0, Vector3::new(5.0, 8.0, 0.0)).inverse(), (0.3, 0.2), 3);
    assert_eq!(tilt_slope(&aligned(&local, &remote, &flat)), 0.0);
    // Untilted, noisy frames: the default (max_tilt 5°) finds no significant tilt and answers
    // exactly as the 4-DoF matcher.
    for seed in 0..20 {
        let spec = PairSpec { local: 35, remote: 32, overlap: 17, noisy: true, mislabels: 0 };
        let pair = generate_pair(&SyntheticWorld::default(), &spec, seed);
        let labels = LabelSimilarity::uniform(6, 0.3);
        let with_tilt = match_graphs(&pair.local, &pair.remote, &labels, &MatcherConfig::default());
        let without = match_graphs(&pair.local, &pair.remote, &labels, &flat);
        assert_eq!(with_tilt, without, "seed {seed}");
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// Any tilt up to 5°, yaw and translation, with ±0.2 m / ±0.1 m of position noise on the
    /// remote graph: the transform is recovered to the noise; a tilt under 0.5° may be left
    /// (the planar estimate keeps an estimated tilt under `tilt::MIN_TILT_DEG`, 0.3°).
    #[test]
    fn recovers_any_tilt_up_to_five_degrees(
        tilt_deg in 0.0f64..=5.0, azimuth in -std::f64::consts::PI..std::f64::consts::PI,
        yaw in -std::f64::consts::PI..std::f64::consts::PI,
        t in (-200.0f64..200.0, -200.0f64..200.0, -3.0f64..3.0), seed in 0u64..1000,
    ) {
        let objects = scene(25, seed);
        let truth = tilted(yaw, tilt_deg, azimuth, Vector3::new(t.0, t.1, t.2));
        let local = graph(&objects, &Pose3::identity(), (0.0, 0.0), 0);
        let remote = graph(&objects, &truth.inverse(), (0.2, 0.1), seed + 1);
        let estimate = aligned(&local, &remote, &MatcherConfig::default());
        let e = pose_error(&estimate, &truth);
        let left = if tilt_deg < 0.5 { tilt_deg } else { 0.0 };
        prop_assert!(e.max_axis_rotation_deg() < 0.3 + left, "{e:?}");
        for q in remote.objects() {
            // A tilt left in the estimate moves objects up to ~60 m from the pivot.
            let d = (estimate * q.centroid - truth * q.centroid).norm();
            prop_assert!(d < 0.3 + 60.0 * left.to_radians(), "object {:?} displaced {d} m", q.id);
        }
    }
}

/// A case CI's random draw found (before the property tests ran from a fixed seed): a 0.54°
/// tilt under ±0.2 m of noise whose estimate came out under the refit's gate when that gate was
/// 0.5° (0.52° of pitch, 0.38 m at the objects were left). The gate now reads 0.3° of estimated
/// tilt, so that every true tilt from 0.5° is corrected (`tilt::MIN_TILT_DEG`).
#[test]
fn a_tilt_just_above_half_a_degree_under_noise() {
    let objects = scene(25, 679);
    let truth = tilted(0.0, 0.539_390_776_436_121_5, -1.284_471_233_659_202_8, Vector3::zeros());
    let local = graph(&objects, &Pose3::identity(), (0.0, 0.0), 0);
    let remote = graph(&objects, &truth.inverse(), (0.2, 0.1), 680);
    let e = pose_error(&aligned(&local, &remote, &MatcherConfig::default()), &truth);
    assert!(e.max_axis_rotation_deg() < 0.3, "{e:?}");
}
