//! Tilted frames (beyond the paper; issue 31, "gravity"): two robots' world frames whose z axes
//! disagree by a few degrees (roll/pitch drift of an odometry without IMU).
//!
//! A planar hypothesis T_p = (R_z(ψ), t) of frames tilted by θ leaves residuals whose vertical
//! part is, to first order, a plane over the map: with g the tilt's gradient (‖g‖ = tan θ),
//!
//!   d_i = (p_i − T_p q_i)_z ≈ g · (p_i − c)_xy + e,   |d_i| ≤ r_z + tan θ_max · ‖(p_i − c)_xy‖,
//!
//! about the pivot c where the planar fit put its z offset (the inliers' weighted centroid), so
//! an object 20 m from c in a 3° tilt is 1 m off in z and leaves the vertical gate r_z.
//!
//! 1. Inliers of T_p under that relaxed vertical gate (the horizontal gate r is unchanged).
//! 2. The plane fit of their vertical residuals (least squares, centred positions x_i):
//!    ĝ = S⁻¹ Σ x_i d_i, S = Σ x_i x_iᵀ, σ̂² = Σ (d_i − d̄ − ĝ·x_i)² / (n − 3), floored at
//!    `MIN_SIGMA_M`; the tilt is real when the χ²₂ statistic ĝᵀ S ĝ / σ̂² ≥ `MIN_CHI2` and the
//!    inliers span at least r along their minor horizontal axis (λ_min(S) / n ≥ r²: a tilt is
//!    seen in two directions). A flat world's ĝ is noise, χ² ≥ 16 in 0.03 % of them (e^−8).
//!    A tilt under `MIN_TILT_DEG` (0.3°) is left to the planar estimate even when significant:
//!    it moves an object 30 m from c by < 0.16 m vertically, well inside r_z, and inter-robot
//!    ICP refines it. The gate reads the estimate ĝ, so it sits below the 0.5° that is promised
//!    corrected: a true 0.54° tilt under ±0.2 m of noise was once estimated under 0.5° and left
//!    (`matching_tilt::a_tilt_just_above_half_a_degree_under_noise`).
//! 3. The 6-DoF weighted Kabsch fit min Σ w_i ‖p_i − (R q_i + t)‖² of those inliers
//!    (`geometry::fit_rigid`, Full3d), re-scored and refined under the normal gates.
//! 4. Adopted when its tilt acos((R e_z) · e_z) ≤ θ_max + `ADOPT_MARGIN_DEG` (a true tilt of
//!    θ_max is estimated with noise) and it scores at least the planar hypothesis; otherwise the
//!    planar hypothesis stands.

use super::verification::{Evaluation, Scorer};
use super::ObjectGraph;
use crate::geometry::{fit_rigid, Correspondence, RigidModel};
use nalgebra::{Matrix2, Point3, Vector2, Vector3};

/// Fewest relaxed inliers to fit a tilt (3 for the plane, 2 more for its noise).
const MIN_INLIERS: usize = 5;
/// Smallest vertical noise assumed of a centroid difference, m (exact centroids would make any
/// rounding-level slope "significant").
const MIN_SIGMA_M: f64 = 0.05;
/// χ²₂ threshold of a real tilt (4 σ).
const MIN_CHI2: f64 = 16.0;
/// Smallest estimated tilt corrected, degrees (tilts from 0.5° are corrected: see the module
/// doc).
const MIN_TILT_DEG: f64 = 0.3;
/// Tilt beyond θ_max still adopted, degrees.
const ADOPT_MARGIN_DEG: f64 = 1.0;

/// What a tilt refit needs besides the scorer.
#[derive(Clone, Copy, Debug)]
pub struct TiltSearch {
    /// θ_max, degrees (> 0).
    pub max_tilt_deg: f64,
    /// Horizontal inlier distance r, m.
    pub radius_m: f64,
    /// Refinement rounds of the refit.
    pub rounds: usize,
}

/// The tilted refit of `planar` when the evidence supports one, else `None`.
pub fn refit(
    scorer: &Scorer,
    local: &ObjectGraph,
    remote: &ObjectGraph,
    planar: &Evaluation,
    search: TiltSearch,
) -> Option<Evaluation> {
    if search.max_tilt_deg.is_nan() || search.max_tilt_deg <= 0.0 || planar.inliers.len() < 2 {
        return None;
    }
    let total: f64 = planar.inliers.iter().map(|i| i.weight).sum();
    if total.is_nan() || total <= 0.0 {
        return None;
    }
    let pivot = planar
        .inliers
        .iter()
        .fold(Vector3::zeros(), |acc, i| acc + i.weight * local.objects()[i.local as usize].centroid.coords)
        / total;
    let max_slope = search.max_tilt_deg.to_radians().tan();
    let relaxed = scorer.evaluate_relaxed(&planar.local_from_remote, Point3::from(pivot), max_slope);
    let pairs: Vec<Correspondence> = relaxed
        .inliers
        .iter()
        .map(|i| Correspondence {
            in_local: local.objects()[i.local as usize].centroid,
            in_remote: remote.objects()[i.remote as usize].centroid,
            weight: i.weight,
        })
        .collect();
    if !tilt_is_significant(&pairs, &planar.local_from_remote, search.radius_m) {
        return None;
    }
    let pose = fit_rigid(&pairs, RigidModel::Full3d)?;
    let tilted = scorer.refine(scorer.evaluate(&pose), RigidModel::Full3d, search.rounds);
    let tilt_deg = tilt_slope(&tilted.local_from_remote).atan().to_degrees();
    (tilt_deg <= search.max_tilt_deg + ADOPT_MARGIN_DEG && tilted.score >= planar.score).then_some(tilted)
}

/// tan of the angle between the local z axis and the remote one mapped into the local frame.
pub fn tilt_slope(local_from_remote: &crate::geometry::Pose3) -> f64 {
    let z = local_from_remote.rotation * Vector3::z();
    z.xy().norm() / z.z.max(f64::MIN_POSITIVE)
}

/// Step 2: is the plane of vertical residuals of `pairs` under `planar` significantly tilted,
/// across a horizontal extent of at least `radius_m` in every direction?
fn tilt_is_significant(pairs: &[Correspondence], planar: &crate::geometry::Pose3, radius_m: f64) -> bool {
    let n = pairs.len();
    if n < MIN_INLIERS {
        return false;
    }
    let residual = |c: &Correspondence| (c.in_local - planar * c.in_remote).z;
    let mean_xy = pairs.iter().fold(Vector2::zeros(), |acc, c| acc + c.in_local.coords.xy()) / n as f64;
    let mean_d = pairs.iter().map(residual).sum::<f64>() / n as f64;
    let (mut s, mut b) = (Matrix2::zeros(), Vector2::zeros());
    for c in pairs {
        let x = c.in_local.coords.xy() - mean_xy;
        s += x * x.transpose();
        b += x * (residual(c) - mean_d);
    }
    let (a, off, d) = (s[(0, 0)], s[(0, 1)], s[(1, 1)]);
    let smallest = 0.5 * (a + d) - (0.25 * (a - d) * (a - d) + off * off).sqrt();
    if smallest.is_nan() || smallest / (n as f64) < radius_m * radius_m {
        return false;
    }
    let Some(s_inverse) = s.try_inverse() else { return false };
    let slope = s_inverse * b;
    let sum_sq: f64 = pairs
        .iter()
        .map(|c| {
            let x = c.in_local.coords.xy() - mean_xy;
            (residual(c) - mean_d - slope.dot(&x)).powi(2)
        })
        .sum();
    let sigma2 = (sum_sq / (n - 3) as f64).max(MIN_SIGMA_M * MIN_SIGMA_M);
    let chi2 = (slope.transpose() * s * slope)[(0, 0)] / sigma2;
    chi2 >= MIN_CHI2 && slope.norm() >= MIN_TILT_DEG.to_radians().tan()
}
