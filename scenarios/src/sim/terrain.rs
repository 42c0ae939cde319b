//! The ground as a height field (`[terrain]`): rolling hills, raised sidewalks with kerbs, and
//! ramps, sampled on a grid and read bilinearly, so that the LiDAR, the platforms and the
//! objects standing on it all see one surface.
//!
//! Hills are K = 4 seeded plane waves, hᵢ(p) = Aᵢ sin(kᵢ·p + φᵢ) with |kᵢ| = 2π/λᵢ. A wave's
//! steepest slope is Aᵢ|kᵢ|, so with Aᵢ = tan(max_slope)/(K|kᵢ|) the sum is never steeper
//! than `max_slope_deg` (|∇h| ≤ Σ Aᵢ|kᵢ|). A sidewalk is a 3 m strip raised by the kerb
//! height with 5 cm edges; a ramp climbs at `ramp_slope_deg` to a 4 m landing and down again.
//!
//! Rays are cast with a maximum map: the highest sample of each tile of 8 × 8 cells (and its
//! neighbours), so a ray stretch above it is skipped whole; the rest is marched at half a cell
//! and the crossing refined by bisection.

use crate::scenario::TerrainSpec;
use nalgebra::{Point3, Vector2, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Hill components.
const WAVES: usize = 4;
/// Their wavelengths relative to `hill_wavelength_m`.
const WAVELENGTHS: [f64; WAVES] = [1.0, 0.61, 0.37, 0.23];
/// Half width of a sidewalk and of a ramp, m.
const STRIP_HALF_WIDTH_M: f64 = 1.5;
/// Width of a kerb's or a ramp's side edge, m.
const EDGE_M: f64 = 0.05;
/// Half length of a ramp's landing, m.
const LANDING_HALF_M: f64 = 2.0;
/// The grid reaches this far beyond the world's bounds (beyond it, the edge height holds), m.
const MARGIN_M: f64 = 30.0;
/// Finest grid cell, m; larger worlds get coarser cells (at most `MAX_SAMPLES` per axis).
const CELL_M: f64 = 0.25;
const MAX_SAMPLES: usize = 2000;
/// Cells per side of a tile of the maximum map.
const TILE: usize = 8;

#[derive(Clone, Debug)]
struct Wave {
    k: Vector2<f64>,
    amplitude: f64,
    phase: f64,
}

/// A straight band across the world: a sidewalk, or a ramp (with a profile along it).
#[derive(Clone, Debug)]
struct Band {
    centre: Vector2<f64>,
    along: Vector2<f64>,
    height: f64,
    /// A ramp's run (horizontal length of one slope); none for a sidewalk.
    ramp_run: Option<f64>,
}

impl Band {
    fn height_at(&self, p: Vector2<f64>) -> f64 {
        let d = p - self.centre;
        let across = (d.x * self.along.y - d.y * self.along.x).abs();
        let side = ((STRIP_HALF_WIDTH_M + EDGE_M - across) / EDGE_M).clamp(0.0, 1.0);
        let profile = match self.ramp_run {
            None => 1.0,
            Some(run) => {
                let a = d.dot(&self.along).abs();
                (1.0 - (a - LANDING_HALF_M).max(0.0) / run).clamp(0.0, 1.0)
            }
        };
        self.height * side * profile
    }
}

/// The ground surface. `Terrain::flat()` (the default) is the plane z = 0.
#[derive(Clone, Debug)]
pub struct Terrain {
    /// No grid: the plane z = 0.
    flat: bool,
    origin: Vector2<f64>,
    cell: f64,
    nx: usize,
    ny: usize,
    /// Row-major, `heights[j * nx + i]` at origin + (i, j)·cell.
    heights: Vec<f64>,
    tiles_x: usize,
    tiles_y: usize,
    /// The highest sample of each tile and its eight neighbours.
    tile_max: Vec<f64>,
    /// A bound on the ground's slope |∇h| over each tile and its eight neighbours.
    tile_slope: Vec<f64>,
    /// The highest sample.
    highest: f64,
}

impl Default for Terrain {
    fn default() -> Self {
        Self::flat()
    }
}

impl Terrain {
    pub fn flat() -> Self {
        Self {
            flat: true,
            origin: Vector2::zeros(),
            cell: CELL_M,
            nx: 0,
            ny: 0,
            heights: Vec::new(),
            tiles_x: 0,
            tiles_y: 0,
            tile_max: Vec::new(),
            tile_slope: Vec::new(),
            highest: 0.0,
        }
    }

    /// The terrain of `spec` over `bounds` ([x_min, y_min, x_max, y_max]), seeded.
    pub fn generate(spec: &TerrainSpec, bounds: [f64; 4], seed: u64) -> Self {
        if spec.is_flat() {
            return Self::flat();
        }
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x0054_4552_5241_494e);
        let tan = spec.max_slope_deg.to_radians().tan();
        let waves: Vec<Wave> = WAVELENGTHS
            .iter()
            .map(|f| {
                let length = spec.hill_wavelength_m * f;
                let angle: f64 = rng.random_range(0.0..std::f64::consts::TAU);
                let k = Vector2::new(angle.cos(), angle.sin()) * std::f64::consts::TAU / length;
                Wave {
                    amplitude: tan / (WAVES as f64 * k.norm()),
                    k,
                    phase: rng.random_range(0.0..std::f64::consts::TAU),
                }
            })
            .collect();
        let mut band = |height: f64, ramp_run: Option<f64>| {
            let centre = Vector2::new(rng.random_range(bounds[0]..bounds[2]), rng.random_range(bounds[1]..bounds[3]));
            let angle: f64 = rng.random_range(0.0..std::f64::consts::PI);
            Band { centre, along: Vector2::new(angle.cos(), angle.sin()), height, ramp_run }
        };
        let mut bands: Vec<Band> = (0..spec.kerbs).map(|_| band(spec.kerb_height_m, None)).collect();
        let run = spec.ramp_height_m / spec.ramp_slope_deg.to_radians().tan();
        bands.extend((0..spec.ramps).map(|_| band(spec.ramp_height_m, Some(run))));
        let analytic = |p: Vector2<f64>| -> f64 {
            let hills: f64 = waves.iter().map(|w| w.amplitude * (w.k.dot(&p) + w.phase).sin()).sum();
            hills + bands.iter().map(|b| b.height_at(p)).sum::<f64>()
        };
        Self::sampled(bounds, analytic)
    }

    /// Samples `height` on the grid over `bounds` and builds the maximum map.
    pub(crate) fn sampled(bounds: [f64; 4], height: impl Fn(Vector2<f64>) -> f64) -> Self {
        let origin = Vector2::new(bounds[0] - MARGIN_M, bounds[1] - MARGIN_M);
        let extent = (bounds[2] - bounds[0]).max(bounds[3] - bounds[1]) + 2.0 * MARGIN_M;
        let cell = CELL_M.max(extent / (MAX_SAMPLES - 1) as f64);
        let samples = |span: f64| ((span + 2.0 * MARGIN_M) / cell).ceil() as usize + 1;
        let (nx, ny) = (samples(bounds[2] - bounds[0]), samples(bounds[3] - bounds[1]));
        let mut heights = Vec::with_capacity(nx * ny);
        for j in 0..ny {
            for i in 0..nx {
                heights.push(height(origin + Vector2::new(i as f64, j as f64) * cell));
            }
        }
        let (tiles_x, tiles_y) = ((nx - 1).div_ceil(TILE), (ny - 1).div_ceil(TILE));
        let mut own = vec![f64::NEG_INFINITY; tiles_x * tiles_y];
        for j in 0..ny {
            for i in 0..nx {
                // A sample on a tile's edge belongs to both tiles.
                for tj in j.saturating_sub(1) / TILE..=(j / TILE).min(tiles_y - 1) {
                    for ti in i.saturating_sub(1) / TILE..=(i / TILE).min(tiles_x - 1) {
                        let m = &mut own[tj * tiles_x + ti];
                        *m = m.max(heights[j * nx + i]);
                    }
                }
            }
        }
        // Within a cell the bilinear surface is no steeper along an axis than its steeper edge
        // along it, so |∇h| ≤ √2 · the steepest edge of the cell.
        let mut steepest = vec![0.0f64; tiles_x * tiles_y];
        for j in 0..ny - 1 {
            for i in 0..nx - 1 {
                let h = heights[j * nx + i];
                let edge = (heights[j * nx + i + 1] - h).abs().max((heights[(j + 1) * nx + i] - h).abs());
                let (ti, tj) = ((i / TILE).min(tiles_x - 1), (j / TILE).min(tiles_y - 1));
                let top = (heights[(j + 1) * nx + i + 1] - heights[(j + 1) * nx + i]).abs();
                let right = (heights[(j + 1) * nx + i + 1] - heights[j * nx + i + 1]).abs();
                let m = &mut steepest[tj * tiles_x + ti];
                *m = m.max(edge.max(top).max(right) * std::f64::consts::SQRT_2 / cell);
            }
        }
        let dilate = |own: &[f64]| {
            let mut out = own.to_vec();
            for tj in 0..tiles_y {
                for ti in 0..tiles_x {
                    let mut m = f64::NEG_INFINITY;
                    for nj in tj.saturating_sub(1)..=(tj + 1).min(tiles_y - 1) {
                        for ni in ti.saturating_sub(1)..=(ti + 1).min(tiles_x - 1) {
                            m = m.max(own[nj * tiles_x + ni]);
                        }
                    }
                    out[tj * tiles_x + ti] = m;
                }
            }
            out
        };
        let (tile_max, tile_slope) = (dilate(&own), dilate(&steepest));
        let highest = heights.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        Self { flat: false, origin, cell, nx, ny, heights, tiles_x, tiles_y, tile_max, tile_slope, highest }
    }

    pub fn is_flat(&self) -> bool {
        self.flat
    }

    /// Grid coordinates of (x, y), clamped to the grid.
    fn grid(&self, x: f64, y: f64) -> (f64, f64) {
        let gx = ((x - self.origin.x) / self.cell).clamp(0.0, (self.nx - 1) as f64);
        let gy = ((y - self.origin.y) / self.cell).clamp(0.0, (self.ny - 1) as f64);
        (gx, gy)
    }

    /// The ground's height under (x, y), m (bilinear between samples).
    pub fn height(&self, x: f64, y: f64) -> f64 {
        if self.flat {
            return 0.0;
        }
        let (gx, gy) = self.grid(x, y);
        let (i, j) = ((gx as usize).min(self.nx - 2), (gy as usize).min(self.ny - 2));
        let (fx, fy) = (gx - i as f64, gy - j as f64);
        let at = |i: usize, j: usize| self.heights[j * self.nx + i];
        let bottom = at(i, j) * (1.0 - fx) + at(i + 1, j) * fx;
        let top = at(i, j + 1) * (1.0 - fx) + at(i + 1, j + 1) * fx;
        bottom * (1.0 - fy) + top * fy
    }

    /// No point of the ground within a tile of (x, y) is higher than the first, nor steeper
    /// than the second.
    fn bounds_near(&self, x: f64, y: f64) -> (f64, f64) {
        let (gx, gy) = self.grid(x, y);
        let ti = (gx as usize / TILE).min(self.tiles_x - 1);
        let tj = (gy as usize / TILE).min(self.tiles_y - 1);
        let k = tj * self.tiles_x + ti;
        (self.tile_max[k], self.tile_slope[k])
    }

    /// Distance along the ray `origin + t·direction` (|direction| = 1) to the ground, up to
    /// `max_t`.
    pub fn intersect(&self, origin: &Point3<f64>, direction: &Vector3<f64>, max_t: f64) -> Option<f64> {
        if self.flat {
            return (direction.z < -1e-9).then(|| -origin.z / direction.z);
        }
        let above = |t: f64| {
            let p = origin + direction * t;
            p.z - self.height(p.x, p.y)
        };
        if above(0.0) <= 0.0 {
            return Some(0.0);
        }
        let horizontal = direction.x.hypot(direction.y);
        let fine = (0.5 * self.cell / horizontal.max(1e-9)).min(0.25);
        let coarse = fine * (TILE / 2) as f64;
        // Above the highest ground and not descending: no hit. Descending from above it: the
        // ray cannot meet the ground before it comes down to that height.
        let highest = self.highest;
        let mut t0 = if origin.z > highest && direction.z < 0.0 { (origin.z - highest) / -direction.z } else { 0.0 };
        while t0 < max_t {
            if direction.z >= 0.0 && origin.z + direction.z * t0 > highest {
                return None;
            }
            let t1 = (t0 + coarse).min(max_t);
            let lowest = (origin.z + direction.z * t0).min(origin.z + direction.z * t1);
            let middle = origin + direction * (0.5 * (t0 + t1));
            let (ceiling, slope) = self.bounds_near(middle.x, middle.y);
            if lowest <= ceiling {
                // Along the ray the gap to the ground closes at most this fast: a step shorter
                // than gap / closing cannot cross it, so longer steps than `fine` are safe
                // while the ray is high above the ground.
                let closing = slope * horizontal + (-direction.z).max(0.0);
                let (mut last, mut gap) = (t0, above(t0));
                let mut t = t0;
                while t < t1 {
                    t = (t + fine.max(0.9 * gap / closing.max(1e-9))).min(t1);
                    gap = above(t);
                    if gap <= 0.0 {
                        return Some(bisect(&above, last, t));
                    }
                    last = t;
                }
            }
            t0 = t1;
        }
        None
    }
}

/// The crossing of `f` between `lo` (above) and `hi` (at or below), to 1e-6 m of ray.
fn bisect(f: &impl Fn(f64) -> f64, mut lo: f64, mut hi: f64) -> f64 {
    while hi - lo > 1e-6 {
        let mid = 0.5 * (lo + hi);
        if f(mid) > 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    hi
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn hills(slope_deg: f64, seed: u64) -> Terrain {
        let spec = TerrainSpec { max_slope_deg: slope_deg, ..TerrainSpec::default() };
        Terrain::generate(&spec, [-40.0, -40.0, 40.0, 40.0], seed)
    }

    #[test]
    fn flat_terrain_is_the_plane_z_0() {
        let t = Terrain::generate(&TerrainSpec::default(), [-10.0, -10.0, 10.0, 10.0], 1);
        assert!(t.is_flat());
        assert_eq!(t.height(3.0, -2.0), 0.0);
        let d = Vector3::new(1.0, 0.0, -1.0).normalize();
        let hit = t.intersect(&Point3::new(0.0, 0.0, 1.0), &d, 100.0).unwrap();
        assert!((hit - 2f64.sqrt()).abs() < 1e-12);
        assert!(t.intersect(&Point3::new(0.0, 0.0, 1.0), &Vector3::x(), 100.0).is_none());
    }

    #[test]
    fn a_ramp_climbs_at_its_slope_to_its_landing_and_a_sidewalk_has_kerbs() {
        let run = 0.5 / 10f64.to_radians().tan();
        let ramp = Band { centre: Vector2::new(1.0, 2.0), along: Vector2::x(), height: 0.5, ramp_run: Some(run) };
        let at = |a: f64, across: f64| ramp.height_at(Vector2::new(1.0 + a, 2.0 + across));
        assert_eq!(at(0.0, 0.0), 0.5);
        assert_eq!(at(-LANDING_HALF_M, 1.0), 0.5);
        assert!((at(LANDING_HALF_M + run / 2.0, 0.0) - 0.25).abs() < 1e-12, "half way up");
        assert!((at(LANDING_HALF_M + 0.1, 0.0) - (0.5 - 0.1 * 10f64.to_radians().tan())).abs() < 1e-12);
        assert_eq!(at(LANDING_HALF_M + run + 0.1, 0.0), 0.0);
        assert_eq!(at(0.0, STRIP_HALF_WIDTH_M + EDGE_M + 0.01), 0.0, "beside the ramp");
        let walk = Band { centre: Vector2::zeros(), along: Vector2::y(), height: 0.12, ramp_run: None };
        assert_eq!(walk.height_at(Vector2::new(1.4, 50.0)), 0.12);
        assert_eq!(walk.height_at(Vector2::new(-1.6, -3.0)), 0.0);
        // The sampled terrain holds the landing at its height, and nothing above or below it.
        let spec = TerrainSpec { ramps: 1, ramp_slope_deg: 10.0, ramp_height_m: 0.5, ..TerrainSpec::default() };
        let t = Terrain::generate(&spec, [-20.0, -20.0, 20.0, 20.0], 3);
        let top = t.heights.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        assert!((top - 0.5).abs() < 1e-9, "{top}");
        assert!(t.heights.iter().all(|h| (0.0..=0.5 + 1e-12).contains(h)));
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(24))]

        /// The rolling ground is never steeper than asked (finite differences along both axes
        /// of the grid), and reaches a good part of it.
        #[test]
        fn hills_keep_within_their_slope(slope in 1.0f64..20.0, seed in 0u64..1000) {
            let t = hills(slope, seed);
            let tan = slope.to_radians().tan();
            let mut steepest = 0.0f64;
            for j in 0..t.ny - 1 {
                for i in 0..t.nx - 1 {
                    let h = t.heights[j * t.nx + i];
                    steepest = steepest.max((t.heights[j * t.nx + i + 1] - h).abs() / t.cell);
                    steepest = steepest.max((t.heights[(j + 1) * t.nx + i] - h).abs() / t.cell);
                }
            }
            prop_assert!(steepest <= tan * (1.0 + 1e-9), "{steepest} > {tan}");
            prop_assert!(steepest >= 0.2 * tan, "{steepest} ≪ {tan}");
        }

        /// A ray's hit lies on the ground, and no point of the ray before it is below ground
        /// (checked every centimetre), over hills, kerbs and ramps.
        #[test]
        fn rays_stop_at_the_first_crossing(
            seed in 0u64..1000,
            x in -30.0f64..30.0,
            y in -30.0f64..30.0,
            azimuth in 0.0f64..std::f64::consts::TAU,
            elevation in -0.6f64..0.2,
        ) {
            let spec = TerrainSpec { max_slope_deg: 15.0, kerbs: 3, ramps: 3, ..TerrainSpec::default() };
            let t = Terrain::generate(&spec, [-40.0, -40.0, 40.0, 40.0], seed);
            let origin = Point3::new(x, y, t.height(x, y) + 0.8);
            let d = Vector3::new(elevation.cos() * azimuth.cos(), elevation.cos() * azimuth.sin(), elevation.sin());
            let max_t = 60.0;
            match t.intersect(&origin, &d, max_t) {
                Some(hit) => {
                    let p = origin + d * hit;
                    prop_assert!((p.z - t.height(p.x, p.y)).abs() < 1e-4, "{p} vs {}", t.height(p.x, p.y));
                    let mut s = 0.0;
                    while s < hit - 0.02 {
                        let q = origin + d * s;
                        // A crest grazed within half a cell may be stepped over: by less than 1 cm.
                        prop_assert!(q.z >= t.height(q.x, q.y) - 0.01, "below ground at {s} before the hit at {hit}");
                        s += 0.01;
                    }
                }
                None => {
                    let mut s = 0.0;
                    while s < max_t {
                        let q = origin + d * s;
                        prop_assert!(q.z >= t.height(q.x, q.y) - 0.01, "missed the ground at {s}");
                        s += 0.01;
                    }
                }
            }
        }
    }
}
