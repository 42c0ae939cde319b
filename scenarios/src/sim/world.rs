//! The world generator (seeded): ground, buildings or rooms, and objects of the scenario's
//! classes placed with a minimum spacing, away from the robots' routes and from walls.

use crate::scenario::shapes::{shape_of, Part};
use crate::scenario::{WorldKind, WorldSpec};
use crate::sim::shapes::{place, Primitive, Solid};
use crate::sim::terrain::Terrain;
use nalgebra::{Point2, Point3, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use sgm_model::perception::classes::ClassSpec;

/// Pixel/label value of "no class".
pub const NO_LABEL: u16 = u16::MAX;

/// One object of the world: what the maps should find.
#[derive(Clone, Debug, PartialEq)]
pub struct WorldObject {
    pub instance: u32,
    pub class: String,
    pub label: u16,
    /// Centre of the object's bounding box, world frame.
    pub centre: Point3<f64>,
}

#[derive(Clone, Debug, Default)]
pub struct World {
    pub solids: Vec<Solid>,
    pub objects: Vec<WorldObject>,
    pub ground_label: u16,
    /// Class ids of the matchable classes (what a mislabelled object may become).
    pub matchable_labels: Vec<u16>,
    /// [x_min, y_min, x_max, y_max].
    pub bounds: [f64; 4],
    /// RGB of each class id (for plots).
    pub colours: std::collections::BTreeMap<u16, [u8; 3]>,
    /// The ground (the plane z = 0 unless `settle_on` put the world on terrain).
    pub terrain: std::sync::Arc<Terrain>,
    /// The plane over the rooms, if any (`world.ceiling`).
    pub ceiling: Option<Ceiling>,
}

/// A flat ceiling: the plane z = `height_m`, seen from below only.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ceiling {
    pub height_m: f64,
    pub label: u16,
}

/// The instance of a ceiling's returns (the ground's is `u32::MAX`).
pub const CEILING_INSTANCE: u32 = u32::MAX - 1;

impl Ceiling {
    /// Where the ray from `origin` along `direction` meets the ceiling, if it goes up to it.
    pub fn intersect(&self, origin: &Point3<f64>, direction: &Vector3<f64>) -> Option<f64> {
        (direction.z > 1e-9 && origin.z < self.height_m).then(|| (self.height_m - origin.z) / direction.z)
    }
}

impl World {
    /// Stands the world on `terrain`: an object's parts rise by the ground's height under the
    /// object's centre, a wall or building by the height under its footprint's centre, and the
    /// parts that stand on the ground reach down to the lowest ground around their footprint,
    /// so that nothing floats over a slope.
    pub fn settle_on(&mut self, terrain: std::sync::Arc<Terrain>) {
        if !terrain.is_flat() {
            let base: std::collections::BTreeMap<u32, f64> =
                self.objects.iter().map(|o| (o.instance, terrain.height(o.centre.x, o.centre.y))).collect();
            for object in &mut self.objects {
                object.centre.z += base[&object.instance];
            }
            for solid in &mut self.solids {
                let (x, y, r) = solid.primitive.footprint();
                let dz = base.get(&solid.instance).copied().unwrap_or_else(|| terrain.height(x, y));
                let lowest = (0..16)
                    .map(|k| {
                        let a = f64::from(k) * std::f64::consts::TAU / 16.0;
                        terrain.height(x + r * a.cos(), y + r * a.sin())
                    })
                    .fold(terrain.height(x, y), f64::min);
                solid.primitive = solid.primitive.settled(dz, (dz - lowest).max(0.0));
            }
        }
        self.terrain = terrain;
    }
}

fn label_of(classes: &[ClassSpec], name: &str) -> u16 {
    classes.iter().find(|c| c.name == name).map_or(NO_LABEL, |c| c.id)
}

/// Distance from `p` to the segment a–b.
fn segment_distance(p: Point2<f64>, a: Point2<f64>, b: Point2<f64>) -> f64 {
    let ab = b - a;
    let t = if ab.norm_squared() > 0.0 { ((p - a).dot(&ab) / ab.norm_squared()).clamp(0.0, 1.0) } else { 0.0 };
    (p - (a + ab * t)).norm()
}

/// Builds the world. `routes`: the robots' paths (objects keep 1.5 m away from them).
pub fn generate(spec: &WorldSpec, classes: &[ClassSpec], routes: &[Vec<Point2<f64>>], seed: u64) -> World {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x5747_4f52_4c44);
    let [sx, sy] = spec.size_m;
    let bounds = [-sx / 2.0, -sy / 2.0, sx / 2.0, sy / 2.0];
    let wall = label_of(classes, "wall");
    let mut world = World {
        ground_label: label_of(classes, "ground"),
        matchable_labels: classes.iter().filter(|c| c.matchable).map(|c| c.id).collect(),
        bounds,
        colours: classes.iter().map(|c| (c.id, c.colour)).collect(),
        ..World::default()
    };
    let mut instance = 0u32;
    // Footprints objects must stay out of: (centre, half extents, yaw) boxes.
    let mut blocked: Vec<(Point2<f64>, f64, f64)> = Vec::new();
    let near_route = |p: Point2<f64>, clearance: f64| {
        routes.iter().any(|r| r.windows(2).any(|w| segment_distance(p, w[0], w[1]) < clearance))
    };
    match spec.kind {
        WorldKind::Campus => {
            for _ in 0..spec.buildings {
                for _attempt in 0..200 {
                    let (w, d) = (rng.random_range(8.0..20.0), rng.random_range(8.0..20.0));
                    let c = Point2::new(
                        rng.random_range(bounds[0] + w / 2.0..bounds[2] - w / 2.0),
                        rng.random_range(bounds[1] + d / 2.0..bounds[3] - d / 2.0),
                    );
                    let radius = w.hypot(d) / 2.0;
                    let clear = !near_route(c, radius + 2.0)
                        && blocked.iter().all(|(b, r, _)| (b - c).norm() > r + radius + 3.0);
                    if clear {
                        let height = spec.wall_height_m * 2.0;
                        world.solids.push(Solid {
                            primitive: Primitive::Box {
                                centre: Point3::new(c.x, c.y, height / 2.0),
                                half: Vector3::new(w / 2.0, d / 2.0, height / 2.0),
                                yaw: 0.0,
                            },
                            label: wall,
                            instance,
                        });
                        instance += 1;
                        blocked.push((c, radius, 0.0));
                        break;
                    }
                }
            }
        }
        WorldKind::Indoor => {
            let room = spec.room_size_m;
            let (nx, ny) = ((sx / room).floor().max(1.0) as usize, (sy / room).floor().max(1.0) as usize);
            let (x0, y0) = (-(nx as f64) * room / 2.0, -(ny as f64) * room / 2.0);
            let h = spec.wall_height_m;
            let t = 0.1;
            let wall_segment = |world: &mut World, a: Point2<f64>, b: Point2<f64>| {
                let centre = Point2::from((a.coords + b.coords) / 2.0);
                let length = (b - a).norm();
                let yaw = (b.y - a.y).atan2(b.x - a.x);
                world.solids.push(Solid {
                    primitive: Primitive::Box {
                        centre: Point3::new(centre.x, centre.y, h / 2.0),
                        half: Vector3::new(length / 2.0, t, h / 2.0),
                        yaw,
                    },
                    label: wall,
                    instance,
                });
            };
            let door = spec.door_width_m;
            // Lines x = x0 + i·room (vertical walls) and y = y0 + j·room (horizontal walls);
            // inner walls have a door in the middle of each room side.
            for i in 0..=nx {
                let x = x0 + i as f64 * room;
                for j in 0..ny {
                    let (ya, yb) = (y0 + j as f64 * room, y0 + (j + 1) as f64 * room);
                    if i == 0 || i == nx {
                        wall_segment(&mut world, Point2::new(x, ya), Point2::new(x, yb));
                    } else {
                        let mid = (ya + yb) / 2.0;
                        wall_segment(&mut world, Point2::new(x, ya), Point2::new(x, mid - door / 2.0));
                        wall_segment(&mut world, Point2::new(x, mid + door / 2.0), Point2::new(x, yb));
                    }
                }
            }
            for j in 0..=ny {
                let y = y0 + j as f64 * room;
                for i in 0..nx {
                    let (xa, xb) = (x0 + i as f64 * room, x0 + (i + 1) as f64 * room);
                    if j == 0 || j == ny {
                        wall_segment(&mut world, Point2::new(xa, y), Point2::new(xb, y));
                    } else {
                        let mid = (xa + xb) / 2.0;
                        wall_segment(&mut world, Point2::new(xa, y), Point2::new(mid - door / 2.0, y));
                        wall_segment(&mut world, Point2::new(mid + door / 2.0, y), Point2::new(xb, y));
                    }
                }
            }
            instance += 1;
            if spec.ceiling {
                world.ceiling = Some(Ceiling { height_m: h, label: wall });
            }
        }
    }
    let in_wall_clearance = |p: Point2<f64>, r: f64| -> bool {
        if spec.kind != WorldKind::Indoor {
            return true;
        }
        let room = spec.room_size_m;
        let [sx, sy] = spec.size_m;
        let (nx, ny) = ((sx / room).floor().max(1.0), (sy / room).floor().max(1.0));
        let (x0, y0) = (-nx * room / 2.0, -ny * room / 2.0);
        let (fx, fy) = ((p.x - x0).rem_euclid(room), (p.y - y0).rem_euclid(room));
        let inside = p.x > x0 && p.x < x0 + nx * room && p.y > y0 && p.y < y0 + ny * room;
        inside && fx > r + 0.3 && fx < room - r - 0.3 && fy > r + 0.3 && fy < room - r - 0.3
    };
    let mut placed: Vec<Point2<f64>> = Vec::new();
    for (class, count) in &spec.objects {
        let (Some(shape), label) = (shape_of(class), label_of(classes, class)) else { continue };
        let radius = shape
            .iter()
            .map(|p| place(&[*p], 0.0, 0.0, 0.0)[0].footprint())
            .map(|(x, y, r)| x.hypot(y) + r)
            .fold(0.0, f64::max);
        for _ in 0..*count {
            for _attempt in 0..500 {
                let p = Point2::new(rng.random_range(bounds[0]..bounds[2]), rng.random_range(bounds[1]..bounds[3]));
                let ok = !near_route(p, radius + 1.5)
                    && in_wall_clearance(p, radius)
                    && placed.iter().all(|q| (q - p).norm() >= spec.min_spacing_m.max(radius))
                    && blocked.iter().all(|(b, r, _)| (b - p).norm() > r + radius + 1.0);
                if !ok {
                    continue;
                }
                let yaw = rng.random_range(-std::f64::consts::PI..std::f64::consts::PI);
                let parts = place(shape, p.x, p.y, yaw);
                let top = shape
                    .iter()
                    .map(|part| match part {
                        Part::Box { centre, half } => centre[2] + half[2],
                        Part::Cylinder { z1, .. } => *z1,
                    })
                    .fold(0.0, f64::max);
                world.objects.push(WorldObject {
                    instance,
                    class: class.clone(),
                    label,
                    centre: Point3::new(p.x, p.y, top / 2.0),
                });
                for primitive in parts {
                    world.solids.push(Solid { primitive, label, instance });
                }
                instance += 1;
                placed.push(p);
                break;
            }
        }
    }
    world
}

#[cfg(test)]
mod tests {
    use super::*;
    use sgm_actors::config::default_classes;

    #[test]
    fn worlds_are_seeded_and_keep_objects_off_the_routes() {
        let spec = WorldSpec::default();
        let route = vec![Point2::new(-30.0, 0.0), Point2::new(30.0, 0.0)];
        let a = generate(&spec, &default_classes(), std::slice::from_ref(&route), 4);
        let b = generate(&spec, &default_classes(), std::slice::from_ref(&route), 4);
        assert_eq!(a.objects, b.objects);
        assert_eq!(a.objects.len(), spec.objects.values().sum::<usize>());
        for o in &a.objects {
            assert!(segment_distance(o.centre.xy(), route[0], route[1]) > 1.5, "{o:?}");
        }
        let c = generate(&spec, &default_classes(), &[route], 5);
        assert_ne!(a.objects, c.objects);
    }

    #[test]
    fn indoor_worlds_have_walls_with_doors_and_furniture_inside_rooms() {
        let spec = WorldSpec {
            kind: WorldKind::Indoor,
            size_m: [24.0, 16.0],
            objects: [("chair".to_string(), 20), ("table".to_string(), 6)].into_iter().collect(),
            min_spacing_m: 1.0,
            ..WorldSpec::default()
        };
        let w = generate(&spec, &default_classes(), &[], 1);
        // 3 × 2 rooms: outer walls 2·3 + 2·2 = 10 segments; inner walls split by doors:
        // 2 vertical lines × 2 rooms × 2 halves + 1 horizontal line × 3 rooms × 2 halves = 14.
        let walls = w.solids.iter().filter(|s| s.label == 1).count();
        assert_eq!(walls, 24);
        assert!(w.objects.len() >= 20, "{}", w.objects.len());
    }
}
