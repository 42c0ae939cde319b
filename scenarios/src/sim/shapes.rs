//! The solids of a simulated world and ray intersection with them. Two primitives suffice for
//! the paper's object classes: boxes turned about the vertical (benches, chairs, tables,
//! bookshelves, buildings, walls) and vertical cylinders (trees, lamp posts, trash cans).
//! Each class has a built-in shape made of parts, placed with a random yaw.

use crate::scenario::shapes::Part;
use nalgebra::{Point3, Vector3};

/// One primitive in the world frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Primitive {
    /// A box of half extents `half`, centred on `centre`, turned by `yaw` about z.
    Box { centre: Point3<f64>, half: Vector3<f64>, yaw: f64 },
    /// A vertical cylinder over (x, y) from height z0 to z1.
    Cylinder { x: f64, y: f64, radius: f64, z0: f64, z1: f64 },
}

/// A primitive with what it is: its class and the object instance it belongs to.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Solid {
    pub primitive: Primitive,
    pub label: u16,
    /// Object instance (walls and buildings have their own).
    pub instance: u32,
}

impl Primitive {
    /// The primitive raised by `dz`; a part that stands on the ground (its bottom at z = 0)
    /// also reaches `below` further down, so that it meets ground lower than its base.
    pub fn settled(self, dz: f64, below: f64) -> Self {
        match self {
            Primitive::Box { mut centre, mut half, yaw } => {
                if centre.z - half.z <= 1e-9 {
                    centre.z -= below / 2.0;
                    half.z += below / 2.0;
                }
                centre.z += dz;
                Primitive::Box { centre, half, yaw }
            }
            Primitive::Cylinder { x, y, radius, z0, z1 } => {
                let z0 = if z0 <= 1e-9 { z0 - below } else { z0 };
                Primitive::Cylinder { x, y, radius, z0: z0 + dz, z1: z1 + dz }
            }
        }
    }

    /// Centre and radius of a vertical cylinder enclosing the primitive (for culling).
    pub fn footprint(&self) -> (f64, f64, f64) {
        match *self {
            Primitive::Box { centre, half, .. } => (centre.x, centre.y, half.x.hypot(half.y)),
            Primitive::Cylinder { x, y, radius, .. } => (x, y, radius),
        }
    }

    /// Distance along the ray `origin + t·direction` (|direction| = 1) to the first surface
    /// hit from outside, if any.
    pub fn intersect(&self, origin: &Point3<f64>, direction: &Vector3<f64>) -> Option<f64> {
        self.intersect_turned(origin, direction, self.turn())
    }

    /// (sin, cos) of a box's yaw ((0, 1) for a cylinder): what [`Primitive::intersect_turned`]
    /// takes, for a caller that casts many rays at one primitive.
    pub fn turn(&self) -> (f64, f64) {
        match *self {
            Primitive::Box { yaw, .. } => yaw.sin_cos(),
            Primitive::Cylinder { .. } => (0.0, 1.0),
        }
    }

    /// [`Primitive::intersect`] with the yaw's (sin, cos) given ([`Primitive::turn`]).
    pub fn intersect_turned(&self, origin: &Point3<f64>, direction: &Vector3<f64>, turn: (f64, f64)) -> Option<f64> {
        match *self {
            Primitive::Box { centre, half, .. } => {
                let (s, c) = turn;
                let o = origin - centre;
                // Into the box frame: rotate by −yaw.
                let o = Vector3::new(c * o.x + s * o.y, -s * o.x + c * o.y, o.z);
                let d =
                    Vector3::new(c * direction.x + s * direction.y, -s * direction.x + c * direction.y, direction.z);
                slab(&o, &d, &half)
            }
            Primitive::Cylinder { x, y, radius, z0, z1 } => cylinder(origin, direction, x, y, radius, z0, z1),
        }
    }
}

/// Ray against an axis-aligned box centred on the origin (slab method).
fn slab(o: &Vector3<f64>, d: &Vector3<f64>, half: &Vector3<f64>) -> Option<f64> {
    let (mut enter, mut exit) = (f64::NEG_INFINITY, f64::INFINITY);
    for k in 0..3 {
        if d[k].abs() < 1e-12 {
            if o[k].abs() > half[k] {
                return None;
            }
            continue;
        }
        let (a, b) = ((-half[k] - o[k]) / d[k], (half[k] - o[k]) / d[k]);
        enter = enter.max(a.min(b));
        exit = exit.min(a.max(b));
    }
    (enter <= exit && enter > 0.0).then_some(enter)
}

fn cylinder(o: &Point3<f64>, d: &Vector3<f64>, x: f64, y: f64, r: f64, z0: f64, z1: f64) -> Option<f64> {
    let mut best: Option<f64> = None;
    let mut keep = |t: f64| {
        if t > 0.0 && best.is_none_or(|b| t < b) {
            best = Some(t);
        }
    };
    // Side: |o_xy + t d_xy − c|² = r².
    let (ox, oy) = (o.x - x, o.y - y);
    let a = d.x * d.x + d.y * d.y;
    if a > 1e-12 {
        let b = ox * d.x + oy * d.y;
        let c = ox * ox + oy * oy - r * r;
        let disc = b * b - a * c;
        if disc >= 0.0 && c > 0.0 {
            let t = (-b - disc.sqrt()) / a;
            let z = o.z + t * d.z;
            if z >= z0 && z <= z1 {
                keep(t);
            }
        }
    }
    // Caps.
    if d.z.abs() > 1e-12 {
        for zc in [z0, z1] {
            let t = (zc - o.z) / d.z;
            let (px, py) = (ox + t * d.x, oy + t * d.y);
            if px * px + py * py <= r * r {
                keep(t);
            }
        }
    }
    best
}

/// The parts of `shape` placed at ground point (x, y) with `yaw`, as world primitives.
pub fn place(shape: &[Part], x: f64, y: f64, yaw: f64) -> Vec<Primitive> {
    let (s, c) = yaw.sin_cos();
    shape
        .iter()
        .map(|part| match *part {
            Part::Box { centre, half } => Primitive::Box {
                centre: Point3::new(x + c * centre[0] - s * centre[1], y + s * centre[0] + c * centre[1], centre[2]),
                half: Vector3::from(half),
                yaw,
            },
            Part::Cylinder { radius, z0, z1 } => Primitive::Cylinder { x, y, radius, z0, z1 },
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rays_hit_boxes_and_cylinders_where_the_closed_form_says() {
        let o = Point3::new(0.0, 0.0, 1.0);
        let x = Vector3::x();
        let unit_box =
            Primitive::Box { centre: Point3::new(5.0, 0.0, 1.0), half: Vector3::new(1.0, 1.0, 1.0), yaw: 0.0 };
        assert!((unit_box.intersect(&o, &x).unwrap() - 4.0).abs() < 1e-12);
        // Turned 45°: the near corner is at 5 − √2.
        let turned = Primitive::Box {
            centre: Point3::new(5.0, 0.0, 1.0),
            half: Vector3::new(1.0, 1.0, 1.0),
            yaw: std::f64::consts::FRAC_PI_4,
        };
        assert!((turned.intersect(&o, &x).unwrap() - (5.0 - 2f64.sqrt())).abs() < 1e-12);
        assert!(unit_box.intersect(&o, &-x).is_none());
        let can = Primitive::Cylinder { x: 5.0, y: 0.0, radius: 0.5, z0: 0.0, z1: 2.0 };
        assert!((can.intersect(&o, &x).unwrap() - 4.5).abs() < 1e-12);
        // From above, straight down onto the lid.
        let above = Point3::new(5.0, 0.2, 10.0);
        assert!((can.intersect(&above, &-Vector3::z()).unwrap() - 8.0).abs() < 1e-12);
        // Over the top: a miss.
        assert!(can.intersect(&Point3::new(0.0, 0.0, 3.0), &x).is_none());
    }
}
