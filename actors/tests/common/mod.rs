//! A small synthetic world for the actor tests: labelled boxes on a ground plane, scanned by
//! sampling their surfaces within 20 m, and robots following waypoints at constant speed.

use nalgebra::{Point3, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use sgm_model::geometry::Pose3;
use sgm_model::scene_graph::LabelId;

pub struct WorldObject {
    pub label: LabelId,
    pub centre: Point3<f64>,
    pub size: Vector3<f64>,
}

pub fn world(seed: u64) -> Vec<WorldObject> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..40)
        .map(|_| {
            let label = LabelId(rng.random_range(2..9));
            let size = Vector3::new(rng.random_range(0.4..1.5), rng.random_range(0.4..1.5), rng.random_range(0.5..3.0));
            let centre = Point3::new(rng.random_range(-30.0..30.0), rng.random_range(-30.0..30.0), size.z / 2.0);
            WorldObject { label, centre, size }
        })
        .collect()
}

/// Points on the objects within 20 m (box surfaces) and on the ground, labelled; body frame.
pub fn scan(
    world: &[WorldObject],
    world_from_body: &Pose3,
    rng: &mut ChaCha8Rng,
) -> (Vec<Point3<f64>>, Vec<Option<LabelId>>) {
    let body_from_world = world_from_body.inverse();
    let here = world_from_body.translation.vector;
    let (mut points, mut labels) = (Vec::new(), Vec::new());
    for o in world {
        if (o.centre.coords - here).xy().norm() > 20.0 {
            continue;
        }
        for _ in 0..150 {
            let mut u =
                Vector3::new(rng.random_range(-0.5..0.5), rng.random_range(-0.5..0.5), rng.random_range(-0.5..0.5));
            let axis = rng.random_range(0..3);
            u[axis] = if rng.random_bool(0.5) { 0.5 } else { -0.5 };
            points.push(body_from_world * (o.centre + u.component_mul(&o.size)));
            labels.push(Some(o.label));
        }
    }
    for _ in 0..1500 {
        let p = Point3::new(here.x + rng.random_range(-20.0..20.0), here.y + rng.random_range(-20.0..20.0), 0.0);
        points.push(body_from_world * p);
        labels.push(Some(LabelId(0)));
    }
    (points, labels)
}

/// Position and heading after `s` metres along the waypoints.
pub fn position(waypoints: &[Point3<f64>], s: f64) -> (Point3<f64>, f64) {
    let legs: Vec<f64> = waypoints.windows(2).map(|w| (w[1] - w[0]).norm()).collect();
    let mut s = s;
    for (k, len) in legs.iter().enumerate() {
        if s <= *len || k == legs.len() - 1 {
            let d = (waypoints[k + 1] - waypoints[k]) / *len;
            let t = s.min(*len);
            return (waypoints[k] + d * t, d.y.atan2(d.x));
        }
        s -= len;
    }
    (waypoints[0], 0.0)
}

/// Lets every actor run until no handler is running.
pub async fn settle() {
    sgm_actors::quiescence::until_quiet().await;
}
