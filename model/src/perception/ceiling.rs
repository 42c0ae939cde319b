//! The ceiling over a scan, found so that it can be left out as the ground is. A ceiling is the
//! ground seen from below: a plane over the whole scan that says nothing about where in the
//! plane the sensor is, or which way it faces. Left in, it lets any transform that keeps the
//! sensor's height agree with a scan taken anywhere under it (a half turn in a grid of
//! identical rooms). It is looked for among the points the ground was already taken from
//! (`structure_check`): ground that rises over the sensor (uphill, a bowl's rim) is gone by
//! then. In the scan's body frame (z up, the sensor at the origin):
//!
//! ```text
//! overhead columns   c ∈ C:  the points of c higher than `clearance` over the sensor
//! flat               c ∈ F ⊂ C:  max_c z − min_c z ≤ clearance      (a wall's column is not)
//! plane              z = a + b·x + c·y, least squares through the flat columns' centroids,
//!                    refitted on those within `clearance` of it (the inliers I)
//! ceiling            ⇔ the largest edge-connected patch of I has ≥ MIN_COLUMNS columns,
//!                      a > clearance and √(b² + c²) ≤ tan(max slope)
//! ceiling points     z ≥ a + b·x + c·y − clearance
//! ```
//!
//! Outdoors the columns over a sensor are walls, trunks, posts and crowns. A crown's underside
//! is flat, but it is a patch of a few columns, apart from the next crown's; an indoor world
//! open to the sky has walls only, whose columns are not flat. Neither has a ceiling, and
//! nothing is left out.

use nalgebra::{Matrix3, Point3, Vector3};
use std::collections::{BTreeMap, BTreeSet};

/// Fewest flat overhead columns that make a ceiling.
const MIN_COLUMNS: usize = 20;

/// One column's points over the sensor: lowest and highest z, their sum and count.
#[derive(Clone, Copy)]
struct Column {
    low: f64,
    high: f64,
    sum: Vector3<f64>,
    count: usize,
}

/// A plane z = a + b·x + c·y over the sensor (body frame).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ceiling {
    pub a: f64,
    pub b: f64,
    pub c: f64,
}

impl Ceiling {
    pub fn height_at(&self, x: f64, y: f64) -> f64 {
        self.a + self.b * x + self.c * y
    }

    /// Whether `p` is on the ceiling (within `clearance_m` under it) or above it.
    pub fn holds(&self, p: &Point3<f64>, clearance_m: f64) -> bool {
        p.z >= self.height_at(p.x, p.y) - clearance_m
    }
}

/// The ceiling over `points` (body frame), if they show one (module notes); columns of side
/// `cell_m`, no steeper than `max_slope_deg`.
pub fn find_ceiling(points: &[Point3<f64>], cell_m: f64, clearance_m: f64, max_slope_deg: f64) -> Option<Ceiling> {
    if !(cell_m.is_finite() && cell_m > 0.0 && clearance_m.is_finite() && clearance_m >= 0.0) {
        return None;
    }
    let mut columns: BTreeMap<(i64, i64), Column> = BTreeMap::new();
    for p in points.iter().filter(|p| p.z > clearance_m && p.coords.iter().all(|v| v.is_finite())) {
        let key = ((p.x / cell_m).floor() as i64, (p.y / cell_m).floor() as i64);
        let empty = Column { low: f64::INFINITY, high: f64::NEG_INFINITY, sum: Vector3::zeros(), count: 0 };
        let c = columns.entry(key).or_insert(empty);
        c.low = c.low.min(p.z);
        c.high = c.high.max(p.z);
        c.sum += p.coords;
        c.count += 1;
    }
    let flat: BTreeMap<(i64, i64), Vector3<f64>> = columns
        .into_iter()
        .filter(|(_, c)| c.high - c.low <= clearance_m)
        .map(|(key, c)| (key, c.sum / c.count as f64))
        .collect();
    if flat.len() < MIN_COLUMNS {
        return None;
    }
    let centroids: Vec<Vector3<f64>> = flat.values().copied().collect();
    let mut plane = fit(&centroids)?;
    let on = |plane: &Ceiling, p: &Vector3<f64>| (p.z - plane.height_at(p.x, p.y)).abs() <= clearance_m;
    for _ in 0..2 {
        let inliers: Vec<Vector3<f64>> = centroids.iter().filter(|p| on(&plane, p)).copied().collect();
        plane = fit(&inliers)?;
    }
    let inliers: BTreeSet<(i64, i64)> = flat.iter().filter(|(_, p)| on(&plane, p)).map(|(key, _)| *key).collect();
    let level = plane.b.hypot(plane.c) <= max_slope_deg.to_radians().tan();
    (largest_patch(&inliers) >= MIN_COLUMNS && plane.a > clearance_m && level).then_some(plane)
}

/// The number of columns in the largest edge-connected patch of `cells`.
fn largest_patch(cells: &BTreeSet<(i64, i64)>) -> usize {
    let mut seen: BTreeSet<(i64, i64)> = BTreeSet::new();
    let mut largest = 0;
    for start in cells {
        if !seen.insert(*start) {
            continue;
        }
        let (mut stack, mut size) = (vec![*start], 0);
        while let Some((x, y)) = stack.pop() {
            size += 1;
            for next in [(x + 1, y), (x - 1, y), (x, y + 1), (x, y - 1)] {
                if cells.contains(&next) && seen.insert(next) {
                    stack.push(next);
                }
            }
        }
        largest = largest.max(size);
    }
    largest
}

/// Least squares z = a + b·x + c·y through `points`; `None` when they do not fix a plane.
fn fit(points: &[Vector3<f64>]) -> Option<Ceiling> {
    let (mut normal, mut rhs) = (Matrix3::zeros(), Vector3::zeros());
    for p in points {
        let row = Vector3::new(1.0, p.x, p.y);
        normal += row * row.transpose();
        rhs += row * p.z;
    }
    let abc = normal.cholesky()?.solve(&rhs);
    abc.iter().all(|v| v.is_finite()).then(|| Ceiling { a: abc.x, b: abc.y, c: abc.z })
}

/// A square room 8 m across centred on the origin, in its own frame, for tests: `floor` points
/// on the floor (and as many on a ceiling at 3 m if `covered`), `wall` points on each of the four
/// walls, 3 m high.
#[cfg(test)]
pub(crate) fn square_room(covered: bool, floor: usize, wall: usize, rng: &mut impl rand::Rng) -> Vec<Point3<f64>> {
    let mut world = Vec::new();
    for _ in 0..floor {
        let (x, y) = (rng.random_range(-4.0..4.0), rng.random_range(-4.0..4.0));
        world.push(Point3::new(x, y, 0.0));
        if covered {
            world.push(Point3::new(x, y, 3.0));
        }
    }
    for _ in 0..wall {
        let (s, z) = (rng.random_range(-4.0..4.0), rng.random_range(0.0..3.0));
        world.extend([
            Point3::new(4.0, s, z),
            Point3::new(-4.0, s, z),
            Point3::new(s, 4.0, z),
            Point3::new(s, -4.0, z),
        ]);
    }
    world
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// A room seen from 1.5 m over its floor: floor, four walls 3 m high, and a ceiling at 3 m if
    /// `covered`; the body tilted by `roll` and `pitch` (rad).
    fn room(covered: bool, roll: f64, pitch: f64, rng: &mut ChaCha8Rng) -> Vec<Point3<f64>> {
        let world = square_room(covered, 3000, 1500, rng);
        let body = nalgebra::Isometry3::from_parts(
            nalgebra::Translation3::new(0.5, -1.0, 1.5),
            nalgebra::UnitQuaternion::from_euler_angles(roll, pitch, 0.3),
        );
        world.iter().map(|p| body.inverse() * p).collect()
    }

    /// Found under a ceiling, tilted or not, 1.5 m over the sensor: every ceiling point is held,
    /// and no wall point lower than the clearance under it.
    #[test]
    fn a_ceiling_over_a_tilted_sensor_is_found_and_holds_only_itself() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for (roll, pitch) in [(0.0, 0.0), (0.05, -0.03), (-0.08, 0.06)] {
            let scan = room(true, roll, pitch, &mut rng);
            let ceiling = find_ceiling(&scan, 1.0, 0.3, 20.0).expect("a ceiling");
            assert!((ceiling.a - 1.5).abs() < 0.05, "{ceiling:?}");
            // Back in the world frame each point's height says what it is.
            let body = nalgebra::Isometry3::from_parts(
                nalgebra::Translation3::new(0.5, -1.0, 1.5),
                nalgebra::UnitQuaternion::from_euler_angles(roll, pitch, 0.3),
            );
            for p in &scan {
                let z = (body * p).z;
                if z > 2.99 {
                    assert!(ceiling.holds(p, 0.3), "a ceiling point left: {z}");
                } else if z < 2.6 {
                    assert!(!ceiling.holds(p, 0.3), "a wall point taken: {z}");
                }
            }
        }
    }

    /// The same room open to the sky has none: its walls' columns are not flat.
    #[test]
    fn walls_alone_make_no_ceiling() {
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        assert_eq!(find_ceiling(&room(false, 0.02, 0.01, &mut rng), 1.0, 0.3, 20.0), None);
    }

    /// Flat things overhead apart from each other (the undersides of crowns, a few columns
    /// each) are no ceiling, however many; nor is a flat layer under the sensor, or too steep a
    /// one.
    #[test]
    fn crowns_floors_and_slopes_are_no_ceiling() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let mut scan = Vec::new();
        for k in 0..24 {
            let (cx, cy) = (-18.0 + 3.0 * (k % 12) as f64 + 0.5, 5.5 + 6.0 * (k / 12) as f64);
            for _ in 0..50 {
                scan.push(Point3::new(cx + rng.random_range(-0.4..0.4), cy + rng.random_range(-0.4..0.4), 1.0));
            }
            for _ in 0..50 {
                scan.push(Point3::new(cx, cy - 3.0, rng.random_range(-1.5..3.0)));
            }
        }
        assert_eq!(find_ceiling(&scan, 1.0, 0.3, 20.0), None, "24 crowns");
        // Joined into one canopy (the same crowns 1 m apart), they are one.
        let canopy: Vec<Point3<f64>> = (0..24 * 50)
            .map(|k| {
                Point3::new(
                    -6.0 + (k % 12) as f64 + rng.random_range(-0.5..0.5),
                    5.5 + (k / 600) as f64 + rng.random_range(-0.5..0.5),
                    1.0,
                )
            })
            .collect();
        assert!(find_ceiling(&canopy, 1.0, 0.3, 20.0).is_some(), "a canopy");
        let floor: Vec<Point3<f64>> =
            (0..5000).map(|_| Point3::new(rng.random_range(-8.0..8.0), rng.random_range(-8.0..8.0), -1.5)).collect();
        assert_eq!(find_ceiling(&floor, 1.0, 0.3, 20.0), None, "under the sensor");
        let steep: Vec<Point3<f64>> = (0..5000)
            .map(|_| {
                let (x, y) = (rng.random_range(-8.0..8.0), rng.random_range(-8.0..8.0));
                Point3::new(x, y, 3.0 + 0.5 * x)
            })
            .filter(|p| p.z > 0.3)
            .collect();
        assert_eq!(find_ceiling(&steep, 1.0, 0.3, 20.0), None, "a 27° slope");
    }

    #[test]
    fn bad_parameters_and_non_finite_points_find_nothing_and_do_not_panic() {
        let mut rng = ChaCha8Rng::seed_from_u64(6);
        let mut scan = room(true, 0.0, 0.0, &mut rng);
        assert_eq!(find_ceiling(&scan, 0.0, 0.3, 20.0), None);
        assert_eq!(find_ceiling(&scan, f64::NAN, 0.3, 20.0), None);
        assert_eq!(find_ceiling(&scan, 1.0, -1.0, 20.0), None);
        scan.push(Point3::new(f64::NAN, 0.0, 2.0));
        scan.push(Point3::new(0.0, f64::INFINITY, 2.0));
        assert!(find_ceiling(&scan, 1.0, 0.3, 20.0).is_some());
    }
}
