//! How a real segmentation network errs (`[segmentation]`), applied to a frame's true labels
//! before the camera renders them (or they go out per point), in this order:
//!
//! 1. **Confusion** — systematic, not a coin per frame: an object seen from sector
//!    s = ⌊(β + π) / 45°⌋ of the bearing β from it to the sensor is reported as the class
//!    drawn from its true class's row of the matrix with the uniform number
//!    u = hash(seed, instance, s): the same object from the same side is the same class in
//!    every frame and for every robot.
//! 2. **Misses** — an object whose returns span an image area (their bounding box in the
//!    image, (Δα·f + 1)(Δε·f + 1) px², f the camera's focal length in px/rad) below
//!    `min_pixels`, or whose nearest return is beyond `max_range_m`, gets no label.
//! 3. **Edge bleed** — a return lying within `edge_bleed_px` of a return of an object that is
//!    nearer by more than [`EDGE_STEP_M`] takes that object's label (and instance): the mask
//!    of the nearer object grows over what is behind it, only at depth edges.
//! 4. **False blobs** — N ~ Poisson(`false_blobs_per_frame`) discs of radius `false_blob_px`,
//!    each of a random matchable class, centred on a random background (ground, wall) return
//!    in the camera's view; the background returns inside take its label.
//!
//! The image here is spherical: a return at azimuth α, elevation ε is at pixel (α·f, ε·f),
//! which is the pinhole camera's image near its centre, and serves per-point labels (the whole
//! sweep) too.

use crate::scenario::SegmentationSpec;
use crate::sim::lidar::LidarFrame;
use crate::sim::world::NO_LABEL;
use nalgebra::Point3;
use rand::Rng;
use rand_distr::{Distribution, Poisson};
use sgm_model::geometry::Pose3;
use sgm_model::perception::classes::ClassSpec;
use std::collections::BTreeMap;
use std::f64::consts::{PI, TAU};

/// A depth step larger than this is an edge labels bleed across, m.
pub const EDGE_STEP_M: f64 = 0.5;
/// Sectors of the view around an object (confusion is drawn once per object and sector).
pub const VIEW_SECTORS: u64 = 8;
/// Instance of the returns of false blob j: `FIRST_BLOB_INSTANCE − j` (the ground is `u32::MAX`).
pub const FIRST_BLOB_INSTANCE: u32 = u32::MAX - 1;
/// At most this many blobs in one frame.
const MAX_BLOBS: usize = 1_000;
const GROUND: u32 = u32::MAX;

/// The error models of one scenario, with class names resolved to ids.
#[derive(Clone, Debug)]
pub struct SegmenterErrors {
    /// True class id → (reported class id, cumulative probability), in the row's order.
    confusion: BTreeMap<u16, Vec<(u16, f64)>>,
    edge_bleed_px: f64,
    min_pixels: f64,
    max_range_m: f64,
    false_blobs: Option<Poisson<f64>>,
    false_blob_px: f64,
    /// Classes that are objects (`object = true`): what can be confused, missed or bleed.
    object_labels: Vec<u16>,
    /// What a false blob may be.
    matchable: Vec<u16>,
    /// Focal length, px/rad.
    px_per_rad: f64,
    /// The camera's half fields of view (horizontal, vertical), rad; none: the whole sweep.
    view: Option<(f64, f64)>,
    seed: u64,
}

/// Azimuth, elevation and range of a return.
fn spherical(p: &Point3<f64>) -> (f64, f64, f64) {
    (p.y.atan2(p.x), p.z.atan2(p.x.hypot(p.y)), p.coords.norm())
}

/// `a − b` wrapped into (−π, π].
fn angle_between(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(TAU);
    if d > PI {
        d - TAU
    } else {
        d
    }
}

/// A uniform number in [0, 1) from a hash of the words (splitmix64).
fn unit_hash(words: &[u64]) -> f64 {
    let mut x = 0x9E37_79B9_7F4A_7C15u64;
    for w in words {
        x ^= w.wrapping_add(0x9E37_79B9_7F4A_7C15);
        x = (x ^ (x >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        x = (x ^ (x >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        x ^= x >> 31;
    }
    (x >> 11) as f64 / (1u64 << 53) as f64
}

impl SegmenterErrors {
    /// None when no error model is on. `classes`: `fusion.classes` (names of the matrix are
    /// validated against it; an unknown one is skipped). `px_per_rad`: the camera's focal
    /// length; `view`: its half fields of view when it is on.
    pub fn new(
        spec: &SegmentationSpec,
        classes: &[ClassSpec],
        px_per_rad: f64,
        view: Option<(f64, f64)>,
        seed: u64,
    ) -> Option<Self> {
        if spec.is_exact() {
            return None;
        }
        let id = |name: &str| classes.iter().find(|c| c.name == name).map(|c| c.id);
        let confusion = spec
            .confusion
            .iter()
            .filter_map(|(row, entries)| {
                let mut total = 0.0;
                let cumulative = entries
                    .iter()
                    .filter_map(|(name, p)| {
                        total += p;
                        Some((id(name)?, total))
                    })
                    .collect();
                Some((id(row)?, cumulative))
            })
            .collect();
        Some(Self {
            confusion,
            edge_bleed_px: spec.edge_bleed_px,
            min_pixels: spec.min_pixels,
            max_range_m: spec.max_range_m.unwrap_or(f64::INFINITY),
            false_blobs: if spec.false_blobs_per_frame > 0.0 {
                Poisson::new(spec.false_blobs_per_frame).ok()
            } else {
                None
            },
            false_blob_px: spec.false_blob_px,
            object_labels: classes.iter().filter(|c| c.object).map(|c| c.id).collect(),
            matchable: classes.iter().filter(|c| c.matchable).map(|c| c.id).collect(),
            px_per_rad,
            view,
            seed,
        })
    }

    /// The error models of `scenario` (none when all are off), with its camera's focal length
    /// and, when the camera is on, its view.
    pub fn of_scenario(scenario: &crate::scenario::Scenario) -> Option<Self> {
        let c = &scenario.camera;
        let model = crate::sim::camera::camera_model(c);
        let half = (c.horizontal_fov_deg.to_radians() / 2.0).min(PI / 2.0);
        let vertical = (half.tan() * f64::from(c.height) / f64::from(c.width.max(1))).atan();
        let view = c.enabled.then_some((half, vertical));
        Self::new(&scenario.segmentation, &scenario.fusion.classes, model.fx, view, scenario.scenario.seed)
    }

    /// Applies every model that is on to `frame`'s labels (and instances), in place.
    /// `world_from_body`: the sensor's pose (the bearing of the view on each object).
    pub fn apply(&self, frame: &mut LidarFrame, world_from_body: &Pose3, rng: &mut impl Rng) {
        let n = frame.points.len();
        if frame.labels.len() != n || frame.instances.len() != n {
            return;
        }
        if !self.confusion.is_empty() {
            self.confuse(frame, world_from_body);
        }
        if self.min_pixels > 0.0 || self.max_range_m.is_finite() {
            self.miss(frame);
        }
        if self.edge_bleed_px > 0.0 {
            self.bleed(frame);
        }
        if let Some(blobs) = &self.false_blobs {
            let count = blobs.sample(rng) as usize;
            self.paint_blobs(frame, count, rng);
        }
    }

    fn is_object(&self, label: u16, instance: u32) -> bool {
        instance != GROUND && label != NO_LABEL && self.object_labels.contains(&label)
    }

    /// Each object's returns: instance → their indices.
    fn objects(&self, frame: &LidarFrame) -> BTreeMap<u32, Vec<usize>> {
        let mut objects: BTreeMap<u32, Vec<usize>> = BTreeMap::new();
        for (k, (label, instance)) in frame.labels.iter().zip(&frame.instances).enumerate() {
            if self.is_object(*label, *instance) {
                objects.entry(*instance).or_default().push(k);
            }
        }
        objects
    }

    /// 1. The class each object is reported as, drawn once per object and view sector.
    fn confuse(&self, frame: &mut LidarFrame, world_from_body: &Pose3) {
        for (instance, returns) in self.objects(frame) {
            let Some(&first) = returns.first() else { continue };
            let Some(row) = frame.labels.get(first).and_then(|l| self.confusion.get(l)) else { continue };
            let centroid =
                returns.iter().filter_map(|k| frame.points.get(*k)).map(|p| p.coords).sum::<nalgebra::Vector3<f64>>()
                    / returns.len() as f64;
            let towards_sensor = world_from_body.rotation * -centroid;
            let bearing = towards_sensor.y.atan2(towards_sensor.x);
            let sector = (((bearing + PI) / (TAU / VIEW_SECTORS as f64)).floor() as u64).min(VIEW_SECTORS - 1);
            let u = unit_hash(&[self.seed, u64::from(instance), sector]);
            let Some(reported) = row.iter().find(|(_, c)| u < *c).or(row.last()).map(|(id, _)| *id) else { continue };
            for k in returns {
                if let Some(l) = frame.labels.get_mut(k) {
                    *l = reported;
                }
            }
        }
    }

    /// 2. Objects too small in the image or too far get no label.
    fn miss(&self, frame: &mut LidarFrame) {
        let f = self.px_per_rad;
        for (_, returns) in self.objects(frame) {
            let Some(first) = returns.first().and_then(|k| frame.points.get(*k)) else { continue };
            let (a0, _, _) = spherical(first);
            let (mut a_lo, mut a_hi, mut e_lo, mut e_hi, mut nearest) =
                (f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY);
            for p in returns.iter().filter_map(|k| frame.points.get(*k)) {
                let (a, e, r) = spherical(p);
                let a = angle_between(a, a0);
                (a_lo, a_hi, e_lo, e_hi) = (a_lo.min(a), a_hi.max(a), e_lo.min(e), e_hi.max(e));
                nearest = nearest.min(r);
            }
            let area = ((a_hi - a_lo) * f + 1.0) * ((e_hi - e_lo) * f + 1.0);
            if area < self.min_pixels || nearest > self.max_range_m {
                for k in returns {
                    if let Some(l) = frame.labels.get_mut(k) {
                        *l = NO_LABEL;
                    }
                }
            }
        }
    }

    /// 3. Labels of nearer objects bleed over what is behind them within `edge_bleed_px`.
    fn bleed(&self, frame: &mut LidarFrame) {
        let f = self.px_per_rad;
        let width = (TAU * f).ceil().max(1.0) as i64;
        let pixels: Vec<(i64, i64, f64)> = frame
            .points
            .iter()
            .map(|p| {
                let (a, e, r) = spherical(p);
                (((a + PI) * f).floor() as i64 % width, (e * f).floor() as i64, r)
            })
            .collect();
        let radius = self.edge_bleed_px.ceil() as i64;
        let (Some(v_lo), Some(v_hi)) = (pixels.iter().map(|p| p.1).min(), pixels.iter().map(|p| p.1).max()) else {
            return;
        };
        let (v0, height) = (v_lo - radius, v_hi - v_lo + 2 * radius + 1);
        // The nearest object return painting each pixel: (range, label, instance).
        let mut nearest = vec![(f64::INFINITY, NO_LABEL, GROUND); (width * height) as usize];
        for (k, (u, v, r)) in pixels.iter().enumerate() {
            let (label, instance) = (frame.labels[k], frame.instances[k]);
            if !self.is_object(label, instance) {
                continue;
            }
            for dv in -radius..=radius {
                for du in -radius..=radius {
                    if ((du * du + dv * dv) as f64) > self.edge_bleed_px * self.edge_bleed_px {
                        continue;
                    }
                    let cell = ((v + dv - v0) * width + (u + du).rem_euclid(width)) as usize;
                    if let Some(slot) = nearest.get_mut(cell) {
                        if *r < slot.0 {
                            *slot = (*r, label, instance);
                        }
                    }
                }
            }
        }
        for (k, (u, v, r)) in pixels.iter().enumerate() {
            let Some(&(near, label, instance)) = nearest.get(((v - v0) * width + u) as usize) else { continue };
            if near + EDGE_STEP_M < *r && label != frame.labels[k] {
                frame.labels[k] = label;
                frame.instances[k] = instance;
            }
        }
    }

    /// 4. `count` false blobs on the background in view.
    fn paint_blobs(&self, frame: &mut LidarFrame, count: usize, rng: &mut impl Rng) {
        if count == 0 || self.matchable.is_empty() {
            return;
        }
        let background: Vec<(usize, f64, f64)> = frame
            .points
            .iter()
            .enumerate()
            .filter(|(k, _)| frame.labels[*k] != NO_LABEL && !self.object_labels.contains(&frame.labels[*k]))
            .map(|(k, p)| {
                let (a, e, _) = spherical(p);
                (k, a, e)
            })
            .filter(|(k, a, e)| self.view.is_none_or(|(h, v)| frame.points[*k].x > 0.0 && a.abs() <= h && e.abs() <= v))
            .collect();
        if background.is_empty() {
            return;
        }
        let reach = self.false_blob_px / self.px_per_rad;
        for j in 0..count.min(MAX_BLOBS) {
            let (_, a0, e0) = background[rng.random_range(0..background.len())];
            let class = self.matchable[rng.random_range(0..self.matchable.len())];
            for (k, a, e) in &background {
                if angle_between(*a, a0).hypot(e - e0) <= reach {
                    frame.labels[*k] = class;
                    frame.instances[*k] = FIRST_BLOB_INSTANCE - j as u32;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    /// 134 px/rad: the default camera's (320 px over 100°).
    const F: f64 = 134.0;
    const GROUND_ID: u16 = 0;
    const WALL: u16 = 1;
    const TREE: u16 = 2;
    const BENCH: u16 = 4;

    fn classes() -> Vec<ClassSpec> {
        let class = |name: &str, id: u16, object: bool| ClassSpec {
            name: name.into(),
            id,
            colour: [0, 0, 0],
            matchable: object,
            object,
            dynamic: false,
            min_points: 5,
            max_points: 50_000,
            max_extent_m: 5.0,
        };
        vec![
            class("ground", GROUND_ID, false),
            class("wall", WALL, false),
            class("tree", TREE, true),
            class("bench", BENCH, true),
        ]
    }

    fn errors(spec: SegmentationSpec) -> SegmenterErrors {
        SegmenterErrors::new(&spec, &classes(), F, None, 11).expect("an effect is on")
    }

    fn push(frame: &mut LidarFrame, p: Point3<f64>, label: u16, instance: u32) {
        frame.points.push(p);
        frame.labels.push(label);
        frame.instances.push(instance);
    }

    /// A return at `range` m, `px` pixels left of straight ahead, `height` m up.
    fn at(range: f64, px: f64, height: f64) -> Point3<f64> {
        let a = px / F;
        Point3::new(range * a.cos(), range * a.sin(), height)
    }

    #[test]
    fn all_off_is_no_model() {
        assert!(SegmenterErrors::new(&SegmentationSpec::default(), &classes(), F, None, 1).is_none());
        let people = SegmentationSpec { people: 3, ..SegmentationSpec::default() };
        assert!(SegmenterErrors::new(&people, &classes(), F, None, 1).is_none(), "people are not an error");
    }

    #[test]
    fn confusion_follows_its_row_and_is_the_same_every_frame_from_the_same_side() {
        let row = [("bench".to_string(), 0.7), ("tree".to_string(), 0.3)].into_iter().collect();
        let spec =
            SegmentationSpec { confusion: [("bench".to_string(), row)].into_iter().collect(), ..Default::default() };
        let errors = errors(spec);
        // 2000 benches round the sensor, 3 returns each, and a tree that has no row.
        let mut frame = LidarFrame::default();
        for k in 0..2000u32 {
            let a = f64::from(k) * TAU / 2000.0;
            for z in [0.2, 0.4, 0.6] {
                push(&mut frame, Point3::new(10.0 * a.cos(), 10.0 * a.sin(), z), BENCH, k);
            }
        }
        push(&mut frame, Point3::new(3.0, 0.0, 1.0), TREE, 5000);
        let truth = frame.clone();
        let pose = Pose3::identity();
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        errors.apply(&mut frame, &pose, &mut rng);
        let trees = frame.labels[..6000].iter().filter(|l| **l == TREE).count();
        // 3 returns per object: 600 objects (1800 returns) expected, σ = √(2000·0.21) ≈ 20.5 objects.
        assert!((trees as f64 / 3.0 - 600.0).abs() < 80.0, "{} objects reported as trees", trees / 3);
        assert!(frame.labels[..6000].chunks(3).all(|c| c[0] == c[1] && c[1] == c[2]), "whole objects");
        assert_eq!(frame.labels[6000], TREE, "no row: as it is");
        // Systematic: the same frame from the same pose is the same, whatever the RNG.
        let mut again = truth.clone();
        errors.apply(&mut again, &pose, &mut ChaCha8Rng::seed_from_u64(99));
        assert_eq!(again.labels, frame.labels);
        // From the other side of each object (the sensor half a turn away), other draws.
        let mut turned = truth;
        errors.apply(
            &mut turned,
            &Pose3::from_parts(Default::default(), nalgebra::UnitQuaternion::from_euler_angles(0.0, 0.0, PI)),
            &mut rng,
        );
        let changed = turned.labels.iter().zip(&frame.labels).filter(|(a, b)| a != b).count();
        assert!(changed > 600, "{changed} returns differ seen from the other side");
    }

    #[test]
    fn labels_bleed_over_farther_surfaces_only_at_depth_edges() {
        let errors = errors(SegmentationSpec { edge_bleed_px: 3.0, ..Default::default() });
        let mut frame = LidarFrame::default();
        // A bench 5 m ahead (a column of returns straight ahead, one px apart in elevation).
        for k in 0..20 {
            push(&mut frame, at(5.0, 0.0, k as f64 * 0.04), BENCH, 7);
        }
        push(&mut frame, at(20.0, 2.0, 0.4), WALL, 1); // 0: a wall 2 px beside it, far behind
        push(&mut frame, at(5.2, 2.0, 0.4), GROUND_ID, GROUND); // 1: 2 px beside, at its depth
        push(&mut frame, at(20.0, 6.0, 0.4), WALL, 1); // 2: the wall 6 px away
        push(&mut frame, at(3.0, 2.0, 0.4), TREE, 8); // 3: a nearer tree beside it
        errors.apply(&mut frame, &Pose3::identity(), &mut ChaCha8Rng::seed_from_u64(1));
        let tail = |k: usize| (frame.labels[20 + k], frame.instances[20 + k]);
        assert_eq!(tail(0), (BENCH, 7), "the far wall next to the bench takes its label");
        assert_eq!(tail(1), (GROUND_ID, GROUND), "no depth edge, no bleed");
        assert_eq!(tail(2), (WALL, 1), "beyond edge_bleed_px");
        assert_eq!(tail(3), (TREE, 8), "a nearer object keeps its own");
        // The tree is 2 m nearer than the bench: it bleeds over the bench's returns beside it
        // (within 3 px, to a pixel's rounding), and only those.
        for k in 0..20 {
            let from_tree = (k as f64 * 0.04 / 5.0).atan() * F - (0.4f64 / 3.0).atan() * F;
            let l = frame.labels[k];
            assert!(l == BENCH || l == TREE && from_tree.abs() <= 4.0, "{k} ({from_tree} px): {l}");
        }
        assert!(frame.labels[..20].contains(&TREE));
    }

    #[test]
    fn small_and_far_objects_are_missed() {
        let spec = SegmentationSpec { min_pixels: 50.0, max_range_m: Some(30.0), ..Default::default() };
        let errors = errors(spec);
        let mut frame = LidarFrame::default();
        // A: 10 px wide, 20 px tall at 5 m: 11 × 21 px² — seen.
        for k in 0..=10 {
            push(&mut frame, at(5.0, k as f64, 0.0), BENCH, 1);
            push(&mut frame, at(5.0, k as f64, 20.0 / F * 5.0), BENCH, 1);
        }
        // B: 2 × 3 px: 3 × 4 = 12 px² — missed.
        push(&mut frame, at(8.0, 40.0, 0.0), TREE, 2);
        push(&mut frame, at(8.0, 42.0, 3.0 / F * 8.0), TREE, 2);
        // C: large (30 × 30 px) but at 35 m — missed.
        push(&mut frame, at(35.0, -60.0, 0.0), TREE, 3);
        push(&mut frame, at(35.0, -30.0, 30.0 / F * 35.0), TREE, 3);
        // The ground is no object: never missed.
        push(&mut frame, at(40.0, 0.0, -1.0), GROUND_ID, GROUND);
        errors.apply(&mut frame, &Pose3::identity(), &mut ChaCha8Rng::seed_from_u64(1));
        assert!(frame.labels[..22].iter().all(|l| *l == BENCH), "{:?}", &frame.labels[..22]);
        assert_eq!(&frame.labels[22..], &[NO_LABEL, NO_LABEL, NO_LABEL, NO_LABEL, GROUND_ID]);
    }

    #[test]
    fn false_blobs_come_at_their_rate_on_the_background_in_view() {
        let spec = SegmentationSpec { false_blobs_per_frame: 2.0, false_blob_px: 5.0, ..Default::default() };
        let view = Some((50f64.to_radians(), 40f64.to_radians()));
        let errors = SegmenterErrors::new(&spec, &classes(), F, view, 3).expect("on");
        // Ground returns every 2 px all round, 1 px below the horizon row by row, and a bench.
        let mut truth = LidarFrame::default();
        for row in 0..10 {
            for col in -420..420 {
                push(&mut truth, at(10.0, f64::from(col) * 2.0, -1.0 - f64::from(row) * 0.1), GROUND_ID, GROUND);
            }
        }
        let bench = truth.points.len();
        push(&mut truth, at(10.0, 0.0, -1.2), BENCH, 4);
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let (frames, mut blobs) = (2000, 0usize);
        for _ in 0..frames {
            let mut frame = truth.clone();
            errors.apply(&mut frame, &Pose3::identity(), &mut rng);
            let mut ids: Vec<u32> = frame.instances.iter().copied().filter(|i| *i != GROUND && *i != 4).collect();
            ids.sort_unstable();
            ids.dedup();
            blobs += ids.len();
            assert_eq!((frame.labels[bench], frame.instances[bench]), (BENCH, 4), "objects are not painted over");
            for (k, p) in frame.points.iter().enumerate() {
                if frame.instances[k] != GROUND && k != bench {
                    assert!(p.x > 0.0 && p.y.atan2(p.x).abs() <= 50f64.to_radians() + 5.0 / F, "in view: {p}");
                    assert!(frame.labels[k] == TREE || frame.labels[k] == BENCH, "a matchable class");
                }
            }
        }
        // Poisson(2) over 2000 frames: mean 2, σ of the mean ≈ 0.03 (overlapping blobs merge
        // rarely: 5 px discs on a 840 × 10-return band).
        let mean = blobs as f64 / f64::from(frames);
        assert!((mean - 2.0).abs() < 0.15, "{mean} blobs per frame");
    }
}
