//! Repeated layouts for the matcher (issue 33): places where many objects look alike and sit on a
//! grid, so that a shifted transform explains nearly as many objects as the true one.
//!
//! Each family is a world of identical objects on a regular layout, with what breaks its symmetry
//! in a real place (parked cars filling random slots, chairs pushed back by different amounts,
//! a few distinct landmarks) — or, for `LampGrid`, nothing at all. Two robots see two overlapping
//! windows of one world (each object detected with probability `DETECTION`), or, for the
//! "different place" pairs, windows of two independent worlds of the same layout (any transform
//! claimed is then wrong). Each view is expressed in its own random frame and carries the paper's
//! "Err" error when noisy (`matching_protocol`). Dimensions are those of real places: parking bays
//! 2.6 m wide, lamp posts every 12 m × 10 m, office desks 2.4 m × 3 m apart, lecture seats 0.6 m
//! apart in rows 1 m apart.

use super::matching_protocol::{make_graph, TrialPair, WorldObject};
use crate::geometry::{pose_from_yaw_translation, Pose3};
use crate::scene_graph::{LabelId, ObjectId};
use nalgebra::{Point3, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::f64::consts::{FRAC_PI_2, PI};

/// Labels of the layouts' objects.
pub const POLE: LabelId = LabelId(0);
pub const CAR: LabelId = LabelId(1);
pub const DESK: LabelId = LabelId(2);
pub const CHAIR: LabelId = LabelId(3);
/// Landmarks draw their labels from `FIRST_LANDMARK..CLASSES`.
const FIRST_LANDMARK: u16 = 4;
/// Label classes of every layout.
pub const CLASSES: u16 = 10;
/// Probability that a robot detects an object inside its window.
const DETECTION: f64 = 0.9;
/// A robot's window as a fraction of the world's extent in x and y.
const WINDOW: (f64, f64) = (0.6, 0.7);

/// A family of repeated layouts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Layout {
    /// Lamp posts on a 12 m × 10 m grid, cars in half of the 2.6 m bays between them, six
    /// landmarks (bins, trees, signs).
    ParkingLot,
    /// Desks on a 2.4 m × 3 m grid, a chair at each (15% missing, each pushed back 0–0.6 m), six
    /// landmarks (cabinets, plants, printers).
    Office,
    /// 20 seats a row 0.6 m apart, 12 rows 1 m apart (a tenth of seats folded away: not
    /// detected), four landmarks (lectern, screens).
    LectureHall,
    /// The parking lot's lamp posts alone: nothing tells one window of the grid from another.
    LampGrid,
}

impl Layout {
    pub const ALL: [Layout; 4] = [Layout::ParkingLot, Layout::Office, Layout::LectureHall, Layout::LampGrid];

    pub fn name(self) -> &'static str {
        match self {
            Layout::ParkingLot => "parking lot",
            Layout::Office => "office",
            Layout::LectureHall => "lecture hall",
            Layout::LampGrid => "lamp-post grid only",
        }
    }

    /// World extent in x and y, m.
    fn extent(self) -> (f64, f64) {
        match self {
            Layout::ParkingLot | Layout::LampGrid => (100.0, 60.0),
            Layout::Office => (36.0, 24.0),
            Layout::LectureHall => (16.0, 16.0),
        }
    }
}

/// One pair to generate.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LayoutPairSpec {
    pub layout: Layout,
    /// Both windows from one world (true) or from two independent worlds of the layout.
    pub same_place: bool,
    /// The paper's "Err" position error on both graphs.
    pub noisy: bool,
}

fn boxed(label: LabelId, x: f64, y: f64, yaw: f64, size: Vector3<f64>) -> WorldObject {
    WorldObject { label, centroid: Point3::new(x, y, size.z / 2.0), yaw, size }
}

fn landmarks(count: usize, (w, h): (f64, f64), rng: &mut ChaCha8Rng) -> Vec<WorldObject> {
    (0..count)
        .map(|_| {
            let size = Vector3::new(rng.random_range(0.4..1.5), rng.random_range(0.4..1.5), rng.random_range(0.5..2.5));
            let label = LabelId(rng.random_range(FIRST_LANDMARK..CLASSES));
            boxed(label, rng.random_range(0.0..w), rng.random_range(0.0..h), rng.random_range(-PI..PI), size)
        })
        .collect()
}

fn lamp_posts() -> Vec<WorldObject> {
    let post = Vector3::new(0.3, 0.3, 6.0);
    (0..8)
        .flat_map(|i| (0..6).map(move |j| boxed(POLE, 6.0 + 12.0 * i as f64, 5.0 + 10.0 * j as f64, 0.0, post)))
        .collect()
}

/// The objects of one world of `layout`.
fn world(layout: Layout, rng: &mut ChaCha8Rng) -> Vec<WorldObject> {
    let mut objects = Vec::new();
    match layout {
        Layout::LampGrid => objects.extend(lamp_posts()),
        Layout::ParkingLot => {
            objects.extend(lamp_posts());
            let car = Vector3::new(4.6, 1.9, 1.5);
            for row in 0..5 {
                for bay in 0..37 {
                    if rng.random_bool(0.5) {
                        // Parked across the bay, nose in, a little off its centre.
                        let x = 2.0 + 2.6 * bay as f64 + rng.random_range(-0.2..0.2);
                        let y = 10.0 + 10.0 * row as f64 + rng.random_range(-0.3..0.3);
                        objects.push(boxed(CAR, x, y, FRAC_PI_2 + rng.random_range(-0.05..0.05), car));
                    }
                }
            }
            objects.extend(landmarks(6, layout.extent(), rng));
        }
        Layout::Office => {
            let (desk, chair) = (Vector3::new(1.6, 0.8, 0.75), Vector3::new(0.6, 0.6, 0.9));
            for i in 0..14 {
                for j in 0..7 {
                    let (x, y) = (2.0 + 2.4 * i as f64, 2.0 + 3.0 * j as f64);
                    objects.push(boxed(DESK, x, y, 0.0, desk));
                    if rng.random_bool(0.85) {
                        let back = 0.7 + rng.random_range(0.0..0.6);
                        objects.push(boxed(CHAIR, x + rng.random_range(-0.3..0.3), y + back, 0.0, chair));
                    }
                }
            }
            objects.extend(landmarks(6, layout.extent(), rng));
        }
        Layout::LectureHall => {
            let seat = Vector3::new(0.5, 0.5, 0.9);
            for i in 0..20 {
                for j in 0..12 {
                    objects.push(boxed(CHAIR, 2.0 + 0.6 * i as f64, 3.0 + 1.0 * j as f64, 0.0, seat));
                }
            }
            objects.extend(landmarks(4, layout.extent(), rng));
        }
    }
    objects
}

/// The lower corner of a window of size `window` in a world of `extent`, near `near` when given
/// (shifted by at most half the window on each axis, so that the two windows overlap).
fn window_corner(extent: (f64, f64), window: (f64, f64), near: Option<(f64, f64)>, rng: &mut ChaCha8Rng) -> (f64, f64) {
    let axis = |extent: f64, window: f64, near: Option<f64>, rng: &mut ChaCha8Rng| {
        let span = (extent - window).max(0.0);
        match near {
            None => rng.random_range(0.0..=span),
            Some(c) => (c + rng.random_range(-0.5 * window..=0.5 * window)).clamp(0.0, span),
        }
    };
    let x = axis(extent.0, window.0, near.map(|n| n.0), rng);
    let y = axis(extent.1, window.1, near.map(|n| n.1), rng);
    (x, y)
}

/// Indices of the objects inside the window at `corner` that the robot detects.
fn seen(objects: &[WorldObject], corner: (f64, f64), window: (f64, f64), rng: &mut ChaCha8Rng) -> Vec<usize> {
    let hidden_seat = |o: &WorldObject, rng: &mut ChaCha8Rng| o.label == CHAIR && rng.random_bool(0.1);
    let mut out = Vec::new();
    for (k, o) in objects.iter().enumerate() {
        let inside = (o.centroid.x - corner.0) >= 0.0
            && (o.centroid.x - corner.0) <= window.0
            && (o.centroid.y - corner.1) >= 0.0
            && (o.centroid.y - corner.1) <= window.1;
        // Every object draws both numbers, inside or not: a pair's randomness does not depend on
        // where its window falls.
        let detected = rng.random_bool(DETECTION);
        let folded = hidden_seat(o, rng);
        if inside && detected && !folded {
            out.push(k);
        }
    }
    out
}

fn random_frame(extent: (f64, f64), rng: &mut ChaCha8Rng) -> Pose3 {
    let origin =
        Vector3::new(rng.random_range(0.0..extent.0), rng.random_range(0.0..extent.1), rng.random_range(-1.0..1.0));
    pose_from_yaw_translation(rng.random_range(-PI..PI), origin)
}

/// Generates one pair of `spec`, deterministic in `seed`.
pub fn generate_layout_pair(spec: &LayoutPairSpec, seed: u64) -> TrialPair {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let extent = spec.layout.extent();
    let window = (WINDOW.0 * extent.0, WINDOW.1 * extent.1);
    let local_world = world(spec.layout, &mut rng);
    let remote_world = if spec.same_place { local_world.clone() } else { world(spec.layout, &mut rng) };
    let local_corner = window_corner(extent, window, None, &mut rng);
    let remote_corner = window_corner(extent, window, spec.same_place.then_some(local_corner), &mut rng);
    let local_seen = seen(&local_world, local_corner, window, &mut rng);
    let remote_seen = seen(&remote_world, remote_corner, window, &mut rng);

    let world_from_local = random_frame(extent, &mut rng);
    let world_from_remote = random_frame(extent, &mut rng);
    let noise = spec.noisy.then_some(1.0);
    let (local, local_ids) = make_graph(&local_world, &local_seen, &world_from_local.inverse(), noise, &[], &mut rng);
    let (remote, remote_ids) =
        make_graph(&remote_world, &remote_seen, &world_from_remote.inverse(), noise, &[], &mut rng);
    let mut true_pairs: Vec<(ObjectId, ObjectId)> = if spec.same_place {
        local_ids.iter().filter_map(|(w, l)| remote_ids.iter().find(|(v, _)| v == w).map(|(_, r)| (*l, *r))).collect()
    } else {
        Vec::new()
    };
    true_pairs.sort();
    TrialPair { local, remote, local_from_remote: world_from_local.inverse() * world_from_remote, true_pairs }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_place_pairs_share_objects_that_agree_with_the_truth() {
        for layout in Layout::ALL {
            for seed in 0..20 {
                let pair = generate_layout_pair(&LayoutPairSpec { layout, same_place: true, noisy: false }, seed);
                assert!(pair.true_pairs.len() >= 3, "{layout:?} seed {seed}: {} shared", pair.true_pairs.len());
                for (l, r) in &pair.true_pairs {
                    let p = pair.local.objects().iter().find(|o| o.id == *l).unwrap();
                    let q = pair.remote.objects().iter().find(|o| o.id == *r).unwrap();
                    assert!((p.centroid - pair.local_from_remote * q.centroid).norm() < 1e-9);
                    assert_eq!(p.label, q.label);
                }
            }
        }
    }

    #[test]
    fn different_places_share_nothing_and_pairs_are_deterministic() {
        let spec = LayoutPairSpec { layout: Layout::ParkingLot, same_place: false, noisy: true };
        let (a, b) = (generate_layout_pair(&spec, 4), generate_layout_pair(&spec, 4));
        assert!(a.true_pairs.is_empty());
        assert_eq!(a.local, b.local);
        assert_eq!(a.remote, b.remote);
        assert_ne!(a.local, generate_layout_pair(&spec, 5).local);
    }

    #[test]
    fn the_grid_is_repeated_inside_a_window() {
        // The hard part is real: within one view, many objects share a label and a size.
        let pair =
            generate_layout_pair(&LayoutPairSpec { layout: Layout::LampGrid, same_place: true, noisy: false }, 1);
        assert!(pair.local.len() >= 12);
        assert!(pair.local.objects().iter().all(|o| o.label == POLE));
    }
}
