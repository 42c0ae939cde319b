//! The ground under a scan, on hills, kerbs and ramps as on level ground: a local height field
//! of the scan's low points, with a bound on the ground's slope to tell the ground from the
//! objects standing on it. Points in the body frame, z roughly up (the body may be tilted by
//! the slope it stands on; the ground is then level only near it).
//!
//! 1. **Seeds.** The points are binned into columns of side `cell_m` (in x, y); a column's seed
//!    is its low point: the 5th-percentile height of its points (the lowest, in a column of
//!    fewer than 20), robust to a stray return below the ground.
//! 2. **Ground seeds** — Vosselman's slope-based filter (Vosselman 2000, "Slope based filtering
//!    of laser altimetry data", eq. 2), applied to the seeds: a seed s is ground when no seed m of
//!    the (2W+1)² columns around its own lies lower than the steepest ground allows,
//!
//!    ```text
//!    z_s − z_m ≤ tolerance + tan(max_slope) · ‖xy_s − xy_m‖      for every such m
//!    ```
//!
//!    so the low point of a column that holds only an object (a trunk, a wall above a bench) is
//!    not taken for ground while a slope, a kerb or a ramp is.
//! 3. **Local plane.** Each column's ground is the least-squares plane through the ground seeds
//!    of the (2W+1)² columns around it, centred on the column's centre (x_c, y_c):
//!
//!    ```text
//!    g_c(x, y) = a + b·(x − x_c) + c·(y − y_c),   (a, b, c) = argmin Σ_m (g_c(x_m, y_m) − z_m)²
//!    ```
//!
//!    (normal equations AᵀA θ = Aᵀz); with fewer than three seeds, a singular system, or a plane
//!    steeper than `max_slope`, the level plane through their mean height (b = c = 0).
//! 4. A point's height above the ground is h(p) = z_p − g_{c(p)}(x_p, y_p); none where no ground
//!    seed lies within W columns.
//!
//! Why this and not another: a single height threshold (the scan's low percentile) assumes the
//! ground level with the sensor, so on a 10° hill the uphill ground 10 m away stands 1.8 m "high"
//! and the low side's objects sink below it; one robust plane fitted to the whole scan assumes
//! one slope over the sensor's range, which hills of 40 m wavelength, kerbs and ramps break. Local
//! planes over a 5 m × 5 m window (W = 2, 1 m columns) follow those (a hill of 10° and 9 m
//! wavelength bends away from a 5 m plane by less than 0.1 m), and the slope bound is what
//! separates the ground from a column with no ground in it. On level ground every local plane
//! is level at the ground's height, so heights are those of the old global rule up to noise.

use nalgebra::{Matrix3, Point3, Vector3};
use std::collections::BTreeMap;

/// Half width of the window of columns around a column, in columns (W).
pub const WINDOW: i64 = 2;

/// How the ground is found.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GroundParams {
    /// Column side, m (> 0).
    pub cell_m: f64,
    /// The steepest ground relative to the body's x-y plane, degrees (0 ≤ x < 90).
    pub max_slope_deg: f64,
    /// Height a seed may stand above the slope bound and still be ground, m.
    pub tolerance_m: f64,
}

/// A column's seed: its low point.
#[derive(Clone, Copy, Debug)]
struct Seed {
    point: Point3<f64>,
    ground: bool,
}

type Column = [i64; 2];

fn column(p: &Point3<f64>, cell: f64) -> Column {
    [(p.x / cell).floor() as i64, (p.y / cell).floor() as i64]
}

/// The seeds of the (2W+1)² columns around `c` (those that exist).
fn window<'a>(seeds: &'a BTreeMap<Column, Seed>, c: &Column) -> impl Iterator<Item = &'a Seed> + 'a {
    let c = *c;
    (-WINDOW..=WINDOW).flat_map(move |dx| {
        let lo = [c[0] + dx, c[1] - WINDOW];
        let hi = [c[0] + dx, c[1] + WINDOW];
        seeds.range(lo..=hi).map(|(_, s)| s)
    })
}

/// The local plane (a, b, c) of step 3 through `seeds` around `centre`; none without seeds.
fn plane(seeds: &[Point3<f64>], centre: (f64, f64), max_tan: f64) -> Option<Vector3<f64>> {
    if seeds.is_empty() {
        return None;
    }
    let mean = seeds.iter().map(|s| s.z).sum::<f64>() / seeds.len() as f64;
    let level = Vector3::new(mean, 0.0, 0.0);
    if seeds.len() < 3 {
        return Some(level);
    }
    // AᵀA θ = Aᵀz with rows (1, x − x_c, y − y_c).
    let (mut ata, mut atz) = (Matrix3::zeros(), Vector3::zeros());
    for s in seeds {
        let row = Vector3::new(1.0, s.x - centre.0, s.y - centre.1);
        ata += row * row.transpose();
        atz += row * s.z;
    }
    let fitted = ata.cholesky().map(|c| c.solve(&atz));
    Some(match fitted {
        Some(t) if t.iter().all(|v| v.is_finite()) && t[1].hypot(t[2]) <= max_tan => t,
        _ => level,
    })
}

/// Each point's height above the local ground (module documentation); `None` for a point that
/// is not finite or has no ground seed within [`WINDOW`] columns. `None` for every point when
/// `params` are out of range.
pub fn heights_above_ground(points: &[Point3<f64>], params: &GroundParams) -> Vec<Option<f64>> {
    let cell = params.cell_m;
    let valid =
        cell.is_finite() && cell > 0.0 && (0.0..90.0).contains(&params.max_slope_deg) && params.tolerance_m.is_finite();
    if !valid {
        return vec![None; points.len()];
    }
    let max_tan = params.max_slope_deg.to_radians().tan();
    let finite = |p: &Point3<f64>| p.coords.iter().all(|v| v.is_finite());
    // 1. Seeds: each column's 5th-percentile point by height.
    let mut columns: BTreeMap<Column, Vec<Point3<f64>>> = BTreeMap::new();
    for p in points.iter().filter(|p| finite(p)) {
        columns.entry(column(p, cell)).or_default().push(*p);
    }
    let mut seeds: BTreeMap<Column, Seed> = BTreeMap::new();
    for (c, mut members) in columns {
        members.sort_unstable_by(|a, b| a.z.total_cmp(&b.z));
        if let Some(low) = members.get(members.len() / 20) {
            seeds.insert(c, Seed { point: *low, ground: true });
        }
    }
    // 2. Ground seeds: none lower nearby than the slope bound allows.
    let ground: Vec<(Column, bool)> = seeds
        .iter()
        .map(|(c, s)| {
            let bounded = window(&seeds, c).all(|m| {
                let run = (s.point.xy() - m.point.xy()).norm();
                s.point.z - m.point.z <= params.tolerance_m + max_tan * run
            });
            (*c, bounded)
        })
        .collect();
    for (c, bounded) in ground {
        if let Some(s) = seeds.get_mut(&c) {
            s.ground = bounded;
        }
    }
    // 3. A local plane per column that holds points.
    let planes: BTreeMap<Column, Option<Vector3<f64>>> = seeds
        .keys()
        .map(|c| {
            let near: Vec<Point3<f64>> = window(&seeds, c).filter(|s| s.ground).map(|s| s.point).collect();
            let centre = ((c[0] as f64 + 0.5) * cell, (c[1] as f64 + 0.5) * cell);
            (*c, plane(&near, centre, max_tan))
        })
        .collect();
    // 4. Heights above the plane of each point's column.
    points
        .iter()
        .map(|p| {
            if !finite(p) {
                return None;
            }
            let c = column(p, cell);
            let t = planes.get(&c).copied().flatten()?;
            let centre = ((c[0] as f64 + 0.5) * cell, (c[1] as f64 + 0.5) * cell);
            Some(p.z - (t[0] + t[1] * (p.x - centre.0) + t[2] * (p.y - centre.1)))
        })
        .collect()
}
