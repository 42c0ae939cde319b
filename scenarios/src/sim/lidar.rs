//! The LiDAR simulator: a spinning multi-beam pattern or a Livox-Mid-360-like non-repetitive
//! one, ray-cast against the world's solids and the ground (the plane z = 0, or the terrain's
//! height field). Solids are culled per
//! frame by azimuth: each solid within range covers the azimuth bins its footprint subtends from
//! the sensor, and a ray tests only the solids of its bin.

use crate::scenario::{LidarPattern, LidarSpec};
use crate::sim::world::{World, CEILING_INSTANCE};
use nalgebra::{Point3, Vector3};
use rand::Rng;
use rand_distr::{Distribution, Normal};
use sgm_model::geometry::Pose3;
use std::borrow::Cow;

const BINS: usize = 720;

/// One simulated frame, sensor (= body) frame, with the truth of every return.
#[derive(Clone, Debug, Default)]
pub struct LidarFrame {
    pub points: Vec<Point3<f64>>,
    pub labels: Vec<u16>,
    /// Object instance of each return (`u32::MAX`: ground).
    pub instances: Vec<u32>,
    /// Each return's time after the frame's stamp, s (empty when `lidar.sweep_s` is 0: every
    /// return from the pose at the stamp).
    pub times: Vec<f32>,
}

pub struct Lidar {
    spec: LidarSpec,
    /// Spinning: the fixed unit directions, sensor frame.
    fixed: Vec<Vector3<f64>>,
    /// Livox: index of the next direction of the low-discrepancy sequence.
    next: u64,
}

/// The azimuth bin of the horizontal direction (x, y), ⌊(atan2(y, x) mod 2π) / w⌋ for bins w
/// wide, exactly libm's, at a fifth of its cost on almost every ray: the arctangent is the
/// minimax polynomial of Abramowitz & Stegun 4.4.48 (|error| ≤ 1.2e-5 rad on the octant), whose
/// bin is libm's wherever it lies farther than [`POLY_MARGIN_RAD`] from a bin edge; within it
/// (about 1 % of rays at 720 bins), and for zero or NaN, libm decides.
fn azimuth_bin(x: f64, y: f64, bin_width: f64) -> usize {
    use std::f64::consts::{FRAC_PI_2, PI, TAU};
    let exact = || (y.atan2(x).rem_euclid(TAU) / bin_width) as usize % BINS;
    let (ax, ay) = (x.abs(), y.abs());
    let (lo, hi) = (ax.min(ay), ax.max(ay));
    if x.is_nan() || y.is_nan() || hi == 0.0 {
        return exact();
    }
    // atan(a), a ∈ [0, 1]: a (c1 + c3 a² + c5 a⁴ + c7 a⁶ + c9 a⁸).
    let a = lo / hi;
    let s = a * a;
    let mut theta = a * (0.999_866 + s * (-0.330_299_5 + s * (0.180_141 + s * (-0.085_133 + s * 0.020_835_1))));
    if ay > ax {
        theta = FRAC_PI_2 - theta;
    }
    if x < 0.0 {
        theta = PI - theta;
    }
    if y < 0.0 {
        theta = -theta;
    }
    let u = theta.rem_euclid(TAU) / bin_width;
    // Distance to the nearest bin edge (0 and BINS included: the cut at 2π is one), in bins.
    if (u - u.round()).abs() * bin_width <= POLY_MARGIN_RAD {
        return exact();
    }
    u as usize % BINS
}

/// How near a bin edge the polynomial arctangent leaves the bin to libm: over three times its
/// largest error (1.14e-5 rad at 45°).
const POLY_MARGIN_RAD: f64 = 4e-5;

fn direction(azimuth: f64, elevation: f64) -> Vector3<f64> {
    let (se, ce) = elevation.sin_cos();
    let (sa, ca) = azimuth.sin_cos();
    Vector3::new(ce * ca, ce * sa, se)
}

impl Lidar {
    pub fn new(spec: &LidarSpec) -> Self {
        let [lo, hi] = spec.vertical_fov_deg.map(f64::to_radians);
        let fixed = match spec.pattern {
            LidarPattern::Spinning => {
                let columns = (360.0 / spec.azimuth_step_deg).round().max(1.0) as usize;
                let rings = spec.beams;
                let mut d = Vec::with_capacity(columns * rings);
                for c in 0..columns {
                    let azimuth = (c as f64 * spec.azimuth_step_deg).to_radians();
                    for r in 0..rings {
                        let elevation = if rings == 1 { lo } else { lo + (hi - lo) * r as f64 / (rings - 1) as f64 };
                        d.push(direction(azimuth, elevation));
                    }
                }
                d
            }
            LidarPattern::Livox => Vec::new(),
        };
        Self { spec: spec.clone(), fixed, next: 0 }
    }

    /// This frame's directions: the fixed pattern, or the next `points_per_frame` of the R2
    /// sequence (Roberts 2018) — it never repeats and covers the field of view ever more densely,
    /// as a Livox's rosette does.
    fn directions(&mut self) -> Cow<'_, [Vector3<f64>]> {
        if self.spec.pattern == LidarPattern::Spinning {
            return Cow::Borrowed(&self.fixed);
        }
        const A1: f64 = 0.754_877_666_246_692_8; // 1/g, g the plastic number
        const A2: f64 = 0.569_840_290_998_053_3; // 1/g²
        let [lo, hi] = self.spec.vertical_fov_deg.map(f64::to_radians);
        let (s_lo, s_hi) = (lo.sin(), hi.sin());
        let n = self.spec.points_per_frame as u64;
        let out: Vec<Vector3<f64>> = (self.next..self.next + n)
            .map(|k| {
                let (u, v) = ((0.5 + A1 * k as f64).fract(), (0.5 + A2 * k as f64).fract());
                // Uniform over the sphere band: sin(elevation) uniform.
                direction(u * std::f64::consts::TAU, (s_lo + (s_hi - s_lo) * v).asin())
            })
            .collect();
        self.next += n;
        Cow::Owned(out)
    }

    /// Casts one frame from `world_from_sensor`, every return at once.
    pub fn scan(&mut self, world: &World, world_from_sensor: &Pose3, rng: &mut impl Rng) -> LidarFrame {
        self.sweep(world, &|_| *world_from_sensor, rng)
    }

    /// Casts one frame as the sensor sweeps: with `lidar.sweep_s` > 0, return k of the sweep is
    /// measured at τ = (its column, or its place in a Livox frame) / (their count) ·
    /// `sweep_s` from `world_from_sensor_at(τ)`, and reported in the sensor frame of that
    /// instant, as a driver does: a scan taken on the move comes out bent.
    pub fn sweep(
        &mut self,
        world: &World,
        world_from_sensor_at: &dyn Fn(f64) -> Pose3,
        rng: &mut impl Rng,
    ) -> LidarFrame {
        let sweep_s = self.spec.sweep_s;
        let start = world_from_sensor_at(0.0);
        let origin = Point3::from(start.translation.vector);
        let rotation = start.rotation;
        // How far the sensor moves during the sweep widens each solid's azimuth sector.
        let travel = if sweep_s > 0.0 {
            (world_from_sensor_at(sweep_s).translation.vector - start.translation.vector).norm()
        } else {
            0.0
        };
        let rings = match self.spec.pattern {
            LidarPattern::Spinning => self.spec.beams.max(1),
            LidarPattern::Livox => 1,
        };
        let max_range = self.spec.max_range_m;
        // Azimuth bins of the solids in range.
        let mut bins: Vec<Vec<u32>> = vec![Vec::new(); BINS];
        let bin_width = std::f64::consts::TAU / BINS as f64;
        for (k, solid) in world.solids.iter().enumerate() {
            let (x, y, r) = solid.primitive.footprint();
            let r = r + travel;
            let d = (x - origin.x).hypot(y - origin.y);
            if d - r > max_range {
                continue;
            }
            if d <= r + 0.05 {
                for bin in &mut bins {
                    bin.push(k as u32);
                }
                continue;
            }
            let centre = (y - origin.y).atan2(x - origin.x);
            let half = (r / d).min(1.0).asin() + bin_width;
            let (first, last) =
                (((centre - half) / bin_width).floor() as i64, ((centre + half) / bin_width).ceil() as i64);
            for b in first..=last {
                bins[b.rem_euclid(BINS as i64) as usize].push(k as u32);
            }
        }
        let turns: Vec<(f64, f64)> = world.solids.iter().map(|s| s.primitive.turn()).collect();
        let noise = Normal::new(0.0, self.spec.range_noise_m.max(0.0)).ok();
        let directions = self.directions();
        let count = directions.len().div_ceil(rings).max(1);
        let mut frame = LidarFrame::default();
        // The sensor's pose at the current column (every ring of a column fires at its time).
        let mut column: Option<(usize, f64, Point3<f64>, nalgebra::UnitQuaternion<f64>)> = None;
        for (k, d) in directions.iter().enumerate() {
            let (tau, origin, rotation) = if sweep_s > 0.0 {
                let at = k / rings;
                match column {
                    Some((c, tau, origin, rotation)) if c == at => (tau, origin, rotation),
                    _ => {
                        let tau = at as f64 / count as f64 * sweep_s;
                        let pose = world_from_sensor_at(tau);
                        let posed = (tau, Point3::from(pose.translation.vector), pose.rotation);
                        column = Some((at, posed.0, posed.1, posed.2));
                        posed
                    }
                }
            } else {
                (0.0, origin, rotation)
            };
            let dw = rotation * d;
            let bin = azimuth_bin(dw.x, dw.y, bin_width);
            let mut best = (f64::INFINITY, world.ground_label, u32::MAX);
            let flat = world.terrain.is_flat();
            if flat && dw.z < -1e-9 {
                best.0 = -origin.z / dw.z;
            }
            if let Some((c, t)) = world.ceiling.and_then(|c| Some((c, c.intersect(&origin, &dw)?))) {
                best = (t, c.label, CEILING_INSTANCE);
            }
            for &k in &bins[bin] {
                let solid = &world.solids[k as usize];
                if let Some(t) = solid.primitive.intersect_turned(&origin, &dw, turns[k as usize]) {
                    if t < best.0 {
                        best = (t, solid.label, solid.instance);
                    }
                }
            }
            if !flat {
                // The ground only matters before the nearest solid.
                if let Some(t) = world.terrain.intersect(&origin, &dw, best.0.min(max_range)) {
                    if t <= best.0 {
                        best = (t, world.ground_label, u32::MAX);
                    }
                }
            }
            let (t, label, instance) = best;
            if t > max_range || t < 0.3 {
                continue;
            }
            let t = t + noise.map_or(0.0, |n| n.sample(rng));
            // Drivers publish float32 coordinates (sensor_msgs/PointCloud2): so does ours, and a
            // scan written to a bag reads back bit for bit.
            frame.points.push(Point3::from(d * t).map(|v| f64::from(v as f32)));
            frame.labels.push(label);
            frame.instances.push(instance);
            if sweep_s > 0.0 {
                frame.times.push(tau as f32);
            }
        }
        frame
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::shapes::{Primitive, Solid};
    use crate::sim::world::Ceiling;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    fn world_with_a_wall() -> World {
        World {
            solids: vec![Solid {
                primitive: Primitive::Box {
                    centre: Point3::new(10.0, 0.0, 2.0),
                    half: Vector3::new(0.1, 5.0, 2.0),
                    yaw: 0.0,
                },
                label: 1,
                instance: 0,
            }],
            ground_label: 0,
            ..World::default()
        }
    }

    proptest::proptest! {
        /// The bin is libm's, to the index, at any scale.
        #[test]
        fn azimuth_bins_are_atan2s(x in -100.0f64..100.0, y in -100.0f64..100.0, scale in -12i32..12) {
            let (x, y) = (x * 2f64.powi(scale), y * 2f64.powi(scale));
            let w = std::f64::consts::TAU / BINS as f64;
            proptest::prop_assert_eq!(azimuth_bin(x, y, w), atan2_bin(x, y, w), "({}, {})", x, y);
        }

        /// Directions a hair from a bin edge, where the polynomial alone could be a bin off.
        #[test]
        fn azimuth_bins_at_the_edges_are_atan2s(edge in 0usize..=BINS, off in -1e-4f64..1e-4) {
            let w = std::f64::consts::TAU / BINS as f64;
            let (y, x) = (edge as f64 * w + off).sin_cos();
            proptest::prop_assert_eq!(azimuth_bin(x, y, w), atan2_bin(x, y, w), "({}, {})", x, y);
        }
    }

    fn atan2_bin(x: f64, y: f64, w: f64) -> usize {
        (y.atan2(x).rem_euclid(std::f64::consts::TAU) / w) as usize % BINS
    }

    #[test]
    fn azimuth_bins_of_the_axes_diagonals_zeros_and_nan() {
        let w = std::f64::consts::TAU / BINS as f64;
        let axes = [(1.0, 0.0), (1.0, 1.0), (0.0, 1.0), (-1.0, 1.0), (-1.0, 0.0), (-1.0, -0.0), (-1.0, -1.0)];
        let more = [(0.0, -1.0), (1.0, -1.0), (0.0, 0.0), (-0.0, 0.0), (-0.0, -0.0), (f64::NAN, 1.0), (1.0, f64::NAN)];
        for (x, y) in axes.into_iter().chain(more) {
            assert_eq!(azimuth_bin(x, y, w), atan2_bin(x, y, w), "({x}, {y})");
        }
    }

    #[test]
    fn returns_lie_on_the_surfaces_they_hit() {
        let spec = LidarSpec { range_noise_m: 0.0, ..LidarSpec::default() };
        let mut lidar = Lidar::new(&spec);
        let pose = Pose3::translation(0.0, 0.0, 1.0);
        let frame = lidar.scan(&world_with_a_wall(), &pose, &mut ChaCha8Rng::seed_from_u64(1));
        assert_eq!(frame.points.len(), frame.labels.len());
        let (mut wall, mut ground) = (0, 0);
        // Returns are float32 coordinates (as drivers publish): on the surface to f32 rounding,
        // half an ulp at ≤ 64 m is ≤ 4e-6 m.
        const F32: f64 = 1e-5;
        for (p, l) in frame.points.iter().zip(&frame.labels) {
            let w = pose * p;
            match l {
                1 => {
                    wall += 1;
                    assert!((w.x - 9.9).abs() < F32 && w.y.abs() <= 5.0 + F32, "{w}");
                }
                0 => {
                    ground += 1;
                    assert!(w.z.abs() < F32, "{w}");
                    // Nothing on the ground behind the wall.
                    assert!(!(w.x > 9.9 && w.y.abs() < 4.0), "{w}");
                }
                _ => panic!("label {l}"),
            }
        }
        assert!(wall > 100 && ground > 1000, "{wall} {ground}");
    }

    /// A sweep on the move is bent (the wall smeared over the distance travelled); deskewed with
    /// the body's twist (`model::perception::deskew`), every return lies on its surface again.
    /// Under a ceiling the upward beams return from it, with its label and instance, at its
    /// height and never from behind the wall; the wall above it is hidden; every return below it
    /// is the same as without it.
    #[test]
    fn a_ceiling_returns_the_upward_beams_and_hides_the_wall_above_it() {
        let spec = LidarSpec { range_noise_m: 0.0, ..LidarSpec::default() };
        let pose = Pose3::translation(0.0, 0.0, 1.0);
        let scan = |world: &World| Lidar::new(&spec).scan(world, &pose, &mut ChaCha8Rng::seed_from_u64(1));
        let open = scan(&world_with_a_wall());
        let covered = scan(&World { ceiling: Some(Ceiling { height_m: 3.0, label: 7 }), ..world_with_a_wall() });
        const F32: f64 = 1e-5;
        let mut on_ceiling = 0;
        for ((p, l), i) in covered.points.iter().zip(&covered.labels).zip(&covered.instances) {
            let w = pose * p;
            if *l == 7 {
                on_ceiling += 1;
                assert_eq!(*i, CEILING_INSTANCE);
                assert!((w.z - 3.0).abs() < F32, "{w}");
                assert!(!(w.x > 9.9 && w.y.abs() < 5.0), "behind the wall: {w}");
            } else {
                assert!(w.z < 3.0, "{w}");
            }
        }
        assert!(on_ceiling > 1000, "{on_ceiling}");
        // The wall is 4 m high: without the ceiling its top metre returns.
        let world_z = |frame: &LidarFrame| frame.points.iter().map(|p| (pose * p).z).collect::<Vec<_>>();
        assert!(world_z(&open).iter().any(|z| *z > 3.0 + F32));
        let under = |frame: &LidarFrame| {
            frame
                .points
                .iter()
                .zip(&frame.labels)
                .filter(|(p, l)| **l != 7 && (pose * *p).z < 3.0)
                .map(|(p, _)| *p)
                .collect::<Vec<_>>()
        };
        assert_eq!(under(&open), under(&covered));
    }

    #[test]
    fn a_sweep_on_the_move_is_bent_and_deskewing_straightens_it() {
        use sgm_model::geometry::lie::{se3_exp, Tangent3};
        use sgm_model::perception::deskew::deskew;
        let spec = LidarSpec { range_noise_m: 0.0, sweep_s: 0.1, ..LidarSpec::default() };
        let mut lidar = Lidar::new(&spec);
        let start = Pose3::translation(0.0, 0.0, 1.0);
        // 3 m/s forward, turning at 1 rad/s.
        let twist = Tangent3::new(0.0, 0.0, 1.0, 3.0, 0.0, 0.0);
        let pose_at = |t: f64| start * se3_exp(&(twist * t));
        let frame = lidar.sweep(&world_with_a_wall(), &pose_at, &mut ChaCha8Rng::seed_from_u64(1));
        assert_eq!(frame.times.len(), frame.points.len());
        assert!(frame.times.iter().all(|t| (0.0..0.1).contains(t)));
        assert!(frame.times.windows(2).all(|w| w[0] <= w[1]), "in sweep order");
        let on_wall = |points: &[Point3<f64>]| {
            points
                .iter()
                .zip(&frame.labels)
                .filter(|(_, l)| **l == 1)
                .map(|(p, _)| ((start * p).x - 9.9).abs())
                .fold(0.0f64, f64::max)
        };
        let bent = on_wall(&frame.points);
        assert!(bent > 0.1, "the wall is smeared by the motion: {bent}");
        let straight = deskew(&frame.points, &frame.times, &twist).expect("times fit");
        assert!(on_wall(&straight) < 1e-4, "{}", on_wall(&straight));
        for (p, l) in straight.iter().zip(&frame.labels) {
            if *l == 0 {
                assert!((start * p).z.abs() < 1e-4, "ground return off the ground: {}", start * p);
            }
        }
    }

    #[test]
    fn a_livox_pattern_never_repeats() {
        let spec = LidarSpec { pattern: LidarPattern::Livox, points_per_frame: 100, ..LidarSpec::default() };
        let mut lidar = Lidar::new(&spec);
        let (a, b) = (lidar.directions().into_owned(), lidar.directions().into_owned());
        assert_eq!(a.len(), 100);
        assert!(a.iter().all(|d| b.iter().all(|e| (d - e).norm() > 1e-9)));
        let [lo, hi] = spec.vertical_fov_deg.map(f64::to_radians);
        assert!(a.iter().all(|d| d.z.asin() >= lo - 1e-9 && d.z.asin() <= hi + 1e-9));
    }
}
