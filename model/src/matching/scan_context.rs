//! Scan Context (Kim & Kim, IROS 2018): the place descriptor of the paper's Swarm-SC baseline
//! (§V-B, Table 3), which associates robots by whole-scan appearance instead of objects.
//!
//! A scan in its body frame is cut into `rings` × `sectors` polar bins out to `max_range_m`;
//! each bin holds the largest height of its points, z + `height_offset_m` (0 when empty or
//! below the offset). Two descriptors compare by the column shift (a yaw) that minimises
//!
//!   d(A, B) = min_s 1/|J_s| Σ_{j ∈ J_s} (1 − a_j · b_{j+s} / (‖a_j‖ ‖b_{j+s}‖)),
//!
//! where a_j is sector j of A (a column of `rings` values) and J_s the sectors non-empty in
//! both (eq. 6 of Kim & Kim). Retrieval first compares the rotation-invariant ring keys (the
//! mean of each ring).

use nalgebra::Point3;
use serde::{Deserialize, Serialize};

/// Descriptor shape. The defaults are Kim & Kim's (20 rings, 60 sectors of 6°, 80 m).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ScanContextConfig {
    pub rings: usize,
    pub sectors: usize,
    /// Points farther than this (horizontally) are ignored, m.
    pub max_range_m: f64,
    /// Added to every height so that the ground reads above zero: the sensor's height, m.
    pub height_offset_m: f64,
}

impl Default for ScanContextConfig {
    fn default() -> Self {
        Self { rings: 20, sectors: 60, max_range_m: 80.0, height_offset_m: 2.0 }
    }
}

/// One scan's descriptor: `rings` × `sectors` heights, ring-major.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ScanContext {
    pub rings: usize,
    pub sectors: usize,
    pub cells: Vec<f32>,
}

/// The best column shift between two descriptors and its distance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScanContextMatch {
    /// In [0, 1] (0: identical up to yaw); 1 when no sector is non-empty in both.
    pub distance: f64,
    /// `other`'s sector j + shift lines up with our sector j.
    pub shift: usize,
}

impl ScanContext {
    /// The descriptor of `points` (body frame, x forward, z up). A zero-sized or non-finite
    /// configuration gives an empty descriptor.
    pub fn new(points: &[Point3<f64>], config: &ScanContextConfig) -> Self {
        let (rings, sectors) = (config.rings, config.sectors);
        let mut cells = vec![0.0f32; rings * sectors];
        if rings == 0 || sectors == 0 || config.max_range_m.is_nan() || config.max_range_m <= 0.0 {
            return Self { rings, sectors, cells };
        }
        let tau = std::f64::consts::TAU;
        for p in points {
            let range = p.x.hypot(p.y);
            let height = p.z + config.height_offset_m;
            if range.is_nan() || range >= config.max_range_m || !height.is_finite() || height <= 0.0 {
                continue;
            }
            let ring = ((range / config.max_range_m * rings as f64) as usize).min(rings - 1);
            let azimuth = p.y.atan2(p.x).rem_euclid(tau);
            let sector = ((azimuth / tau * sectors as f64) as usize).min(sectors - 1);
            let cell = &mut cells[ring * sectors + sector];
            *cell = cell.max(height as f32);
        }
        Self { rings, sectors, cells }
    }

    pub fn cell(&self, ring: usize, sector: usize) -> f32 {
        self.cells[ring * self.sectors + sector]
    }

    /// The mean of each ring: invariant to yaw, for retrieval.
    pub fn ring_key(&self) -> Vec<f32> {
        if self.sectors == 0 {
            return vec![0.0; self.rings];
        }
        self.cells.chunks(self.sectors).map(|ring| ring.iter().sum::<f32>() / self.sectors as f32).collect()
    }

    /// The yaw, rad, of a match's `shift`: `other`'s scan is ours turned by it about z
    /// (other_from_ours rotates by this yaw; ours_from_other by its negative).
    pub fn yaw_of_shift(&self, shift: usize) -> f64 {
        shift as f64 * std::f64::consts::TAU / self.sectors.max(1) as f64
    }

    fn column(&self, j: usize) -> impl Iterator<Item = f64> + '_ {
        (0..self.rings).map(move |r| f64::from(self.cell(r, j)))
    }

    fn column_norms(&self) -> Vec<f64> {
        (0..self.sectors).map(|j| self.column(j).map(|v| v * v).sum::<f64>().sqrt()).collect()
    }

    /// The mean cosine distance of the columns non-empty in both, `other` shifted by `shift`
    /// sectors; None when no column pair counts.
    fn distance_with(&self, other: &ScanContext, norms: (&[f64], &[f64]), shift: usize) -> Option<f64> {
        let (mut sum, mut count) = (0.0, 0usize);
        for j in 0..self.sectors {
            let k = (j + shift) % self.sectors;
            let (a, b) = (norms.0[j], norms.1[k]);
            if a == 0.0 || b == 0.0 {
                continue;
            }
            let dot: f64 = self.column(j).zip(other.column(k)).map(|(x, y)| x * y).sum();
            sum += 1.0 - dot / (a * b);
            count += 1;
        }
        (count > 0).then(|| sum / count as f64)
    }

    fn same_shape(&self, other: &ScanContext) -> bool {
        (self.rings, self.sectors) == (other.rings, other.sectors) && self.sectors > 0
    }

    /// The distance to `other` at one column shift (module docs, without the min).
    pub fn distance_at(&self, other: &ScanContext, shift: usize) -> Option<f64> {
        self.same_shape(other)
            .then(|| self.distance_with(other, (&self.column_norms(), &other.column_norms()), shift))?
    }

    /// The column-shift distance to `other` (module docs). Descriptors of different shapes are
    /// as far apart as can be.
    pub fn compare(&self, other: &ScanContext) -> ScanContextMatch {
        let mut best = ScanContextMatch { distance: 1.0, shift: 0 };
        if !self.same_shape(other) {
            return best;
        }
        let (ours, theirs) = (self.column_norms(), other.column_norms());
        for shift in 0..self.sectors {
            if let Some(distance) = self.distance_with(other, (&ours, &theirs), shift) {
                if distance < best.distance {
                    best = ScanContextMatch { distance, shift };
                }
            }
        }
        best
    }
}

/// A descriptor with its ring key, ready for retrieval.
#[derive(Clone, Debug, PartialEq)]
pub struct Place {
    pub descriptor: ScanContext,
    pub ring_key: Vec<f32>,
}

impl Place {
    pub fn new(descriptor: ScanContext) -> Self {
        let ring_key = descriptor.ring_key();
        Self { descriptor, ring_key }
    }
}

/// Kim & Kim's two-stage retrieval: the `candidates` places of `database` nearest to `query`
/// by ring key (Euclidean), then of those the one with the smallest column-shift distance.
/// Ties keep the earlier entry, so the result is deterministic for an ordered database.
pub fn retrieve<'a, K: Copy + 'a>(
    query: &Place,
    database: impl IntoIterator<Item = (K, &'a Place)>,
    candidates: usize,
) -> Option<(K, ScanContextMatch)> {
    let key_distance =
        |p: &Place| -> f32 { query.ring_key.iter().zip(&p.ring_key).map(|(a, b)| (a - b) * (a - b)).sum::<f32>() };
    let mut nearest: Vec<(f32, K, &Place)> = database.into_iter().map(|(k, p)| (key_distance(p), k, p)).collect();
    nearest.sort_by(|a, b| a.0.total_cmp(&b.0));
    nearest.truncate(candidates);
    nearest
        .into_iter()
        .map(|(_, k, p)| (k, query.descriptor.compare(&p.descriptor)))
        .min_by(|a, b| a.1.distance.total_cmp(&b.1.distance))
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn config(rings: usize, sectors: usize) -> ScanContextConfig {
        ScanContextConfig { rings, sectors, max_range_m: 10.0, height_offset_m: 1.0 }
    }

    #[test]
    fn points_land_in_their_polar_bins_keeping_the_highest() {
        // 2 rings of 5 m, 4 sectors of 90°.
        let points = [
            Point3::new(1.0, 1.0, 0.5),   // ring 0, sector 0 (45°): 1.5
            Point3::new(2.0, 0.5, 2.0),   // ring 0, sector 0: 3.0 wins
            Point3::new(-6.0, 1.0, 0.0),  // ring 1 (6.08 m), sector 1 (170°): 1.0
            Point3::new(0.0, -7.0, -0.5), // ring 1, sector 3 (270°): 0.5
            Point3::new(3.0, -1.0, -2.0), // below the offset: ignored
            Point3::new(12.0, 0.0, 1.0),  // beyond max range: ignored
        ];
        let sc = ScanContext::new(&points, &config(2, 4));
        assert_eq!(sc.cells, vec![3.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.5]);
        assert_eq!(sc.ring_key(), vec![0.75, 0.375]);
    }

    /// Ring-major cells from columns (ring 0, ring 1).
    fn from_columns(columns: &[(f32, f32)]) -> ScanContext {
        let cells = columns.iter().map(|c| c.0).chain(columns.iter().map(|c| c.1)).collect();
        ScanContext { rings: 2, sectors: columns.len(), cells }
    }

    #[test]
    fn distance_by_hand() {
        let a = from_columns(&[(1.0, 0.0), (0.0, 1.0), (0.0, 0.0), (1.0, 1.0)]);
        let b = from_columns(&[(1.0, 1.0), (1.0, 0.0), (0.0, 1.0), (0.0, 0.0)]);
        // Shift 1: A0·B1 = (1,0)·(1,0), A1·B2 = (0,1)·(0,1), A3·B0 = (1,1)·(1,1): cosines 1;
        // A2 is empty. Distance 0.
        assert!(a.distance_at(&b, 1).unwrap() < 1e-15);
        let m = a.compare(&b);
        assert!(m.shift == 1 && m.distance < 1e-15, "{m:?}");
        // Shift 0: (1,0)·(1,1) gives 1 − 1/√2, (0,1)·(1,0) gives 1, A2 and B3 are empty.
        let expected = (2.0 - 1.0 / 2f64.sqrt()) / 2.0;
        assert!((a.distance_at(&b, 0).unwrap() - expected).abs() < 1e-15);
        // Shift 2: A0·B2 = (1,0)·(0,1) gives 1, A1·B3 empty, A3·B1 = (1,1)·(1,0) gives 1 − 1/√2.
        assert!((a.distance_at(&b, 2).unwrap() - expected).abs() < 1e-15);
        // Shift 3: A0·B3 empty, A1·B0 = (0,1)·(1,1), A3·B2 = (1,1)·(0,1): both 1 − 1/√2.
        assert!((a.distance_at(&b, 3).unwrap() - (1.0 - 1.0 / 2f64.sqrt())).abs() < 1e-15);
        assert_eq!(a.distance_at(&from_columns(&[(1.0, 1.0)]), 0), None, "different shapes");
        assert_eq!(a.compare(&from_columns(&[(1.0, 1.0)])).distance, 1.0);
    }

    #[test]
    fn empty_descriptors_are_as_far_as_can_be() {
        let empty = ScanContext::new(&[], &config(3, 6));
        assert_eq!(empty.compare(&empty), ScanContextMatch { distance: 1.0, shift: 0 });
        assert!(ScanContext::new(&[Point3::new(1.0, 0.0, 0.0)], &config(0, 6)).cells.is_empty());
    }

    proptest! {
        /// A scan turned by a whole number of sectors matches itself at that shift, distance 0,
        /// and the shift's yaw is the turn.
        #[test]
        fn yaw_turns_are_found(
            points in proptest::collection::vec((-9.0f64..9.0, -9.0f64..9.0, -0.5f64..3.0), 5..80),
            turn in 0usize..12,
        ) {
            let config = config(5, 12);
            let scan: Vec<Point3<f64>> = points.iter().map(|&(x, y, z)| Point3::new(x, y, z)).collect();
            // Keep points off the sector and ring borders so that rounding cannot move them.
            let scan: Vec<Point3<f64>> = scan
                .into_iter()
                .filter(|p| {
                    let a = p.y.atan2(p.x).rem_euclid(std::f64::consts::TAU) / (std::f64::consts::TAU / 12.0);
                    let r = p.x.hypot(p.y) / 2.0;
                    (a - a.round()).abs() > 1e-6 && (r - r.round()).abs() > 1e-6 && r > 1e-3
                })
                .collect();
            let original = ScanContext::new(&scan, &config);
            let yaw = turn as f64 * std::f64::consts::TAU / 12.0;
            let rotation = nalgebra::Rotation3::from_axis_angle(&nalgebra::Vector3::z_axis(), yaw);
            let turned = ScanContext::new(&scan.iter().map(|p| rotation * p).collect::<Vec<_>>(), &config);
            for (a, b) in original.ring_key().iter().zip(turned.ring_key()) {
                prop_assert!((a - b).abs() <= 1e-5 * a.abs().max(1.0), "ring keys {} {}", a, b);
            }
            let m = original.compare(&turned);
            if original.cells.iter().any(|&c| c > 0.0) {
                prop_assert!(m.distance < 1e-9, "{:?}", m);
                prop_assert!(original.distance_at(&turned, turn).is_some_and(|d| d < 1e-9));
                prop_assert!((original.yaw_of_shift(turn) - yaw).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn retrieval_finds_the_same_place_turned() {
        // A place: walls at ranges r (away from ring edges) whose height varies with the bearing b as h·(1 + sin(f·b)),
        // sampled at sector centres so that a turn by whole sectors moves no point across a bin
        // edge.
        let sector = std::f64::consts::TAU / 60.0;
        let place = |walls: &[(f64, f64, f64)], turn: usize| {
            let points: Vec<Point3<f64>> = walls
                .iter()
                .flat_map(|&(r, h, f)| {
                    (0..60).map(move |j| {
                        let b = (j as f64 + 0.5) * sector;
                        let turned = b + turn as f64 * sector;
                        Point3::new(r * turned.cos(), r * turned.sin(), h * (1.0 + (f * b).sin()))
                    })
                })
                .collect();
            Place::new(ScanContext::new(&points, &ScanContextConfig::default()))
        };
        let a = [(5.0, 3.0, 1.0), (13.0, 1.0, 2.0), (30.0, 6.0, 3.0)];
        let b = [(9.0, 2.0, 1.0), (21.0, 5.0, 5.0)];
        let c = [(3.0, 1.0, 1.0), (41.0, 2.0, 2.0), (61.0, 4.0, 3.0), (9.0, 0.5, 1.0)];
        let turn = 10; // 60°
        let database = [(1, place(&a, 0)), (2, place(&b, 0)), (3, place(&c, 0))];
        let query = place(&c, turn);
        let (id, m) = retrieve(&query, database.iter().map(|(k, p)| (*k, p)), 10).unwrap();
        assert_eq!(id, 3);
        assert!(m.distance < 0.05, "{m:?}");
        // The database scan, shifted by `shift` sectors, lines up with the query.
        assert_eq!(m.shift, 50, "{m:?}");
        assert_eq!(query.descriptor.yaw_of_shift(m.shift), 50.0 * std::f64::consts::TAU / 60.0);
        // One candidate by ring key: still the right place (ring keys are yaw-invariant).
        assert_eq!(retrieve(&query, database.iter().map(|(k, p)| (*k, p)), 1).map(|r| r.0), Some(3));
        assert_eq!(retrieve(&query, std::iter::empty::<(u8, &Place)>(), 10), None);
    }
}
