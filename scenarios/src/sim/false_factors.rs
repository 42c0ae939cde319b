//! Wrong inter-robot factors, injected into a robot's Optimiser as if false matches had passed
//! every check of the Matcher (scenario key `[[false_factors]]`): the test of the robust back
//! end.
//!
//! Each factor ties a random keyframe L of `robot` to a random keyframe R of `neighbour` with
//! z = (T_L⁻¹ T_R) · Exp(δ), T the true body poses at the keyframes' stamps and δ = (ω, v) with
//! ‖ω‖ = `rotation_deg` and ‖v‖ = `translation_m` about random axes: a measurement exactly that
//! wrong, claimed as confident as an ICP registration (σ = 1°, 5 cm). R's pose in the
//! neighbour's world (its map's estimate now) and the robot's own `local_from_remote` come with
//! it, as with a real match, so the back end must tell the lie from the factor alone. Injection
//! waits until `robot` has aligned `neighbour` (before that there is nothing in its graph to
//! corrupt).
//!
//! R's pose comes with a covariance that claims next to nothing (1 rad², 10⁴ m²): the
//! simulation does not know the neighbour's marginal, and a claimed one tighter than it would
//! be a second lie, one no outlier test can reach (a prior is not a candidate for rejection).
//! It was one: with σ = 0.57°, 0.1 m, about 12 times tighter than the honest marginals on
//! `faults/clean`, the keyframe stayed pinned where the injection put it for the rest of the
//! mission (the graph kept a keyframe's first prior), and the team ATE of `sgm bench outliers`
//! moved by 20 % with every false factor rejected. When the neighbour's own keyframe arrives
//! later, its prior replaces this one (`KeyframeGraph::add_neighbour`).

use crate::observation::Observation;
use crate::scenario::FalseFactorSpec;
use nalgebra::{Matrix6, Vector3, Vector6};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, UnitSphere};
use sgm_actors::messages::InterRobotConstraints;
use sgm_actors::protocol::ProtocolStage;
use sgm_model::geometry::Pose3;
use sgm_model::optim::manifold::Manifold;
use sgm_model::scene_graph::{KeyframeId, RobotId};

/// Standard deviations a false factor claims: rotation (rad), translation (m).
const CLAIMED_SIGMAS: (f64, f64) = (0.017_45, 0.05);
/// Covariance claimed for the neighbour keyframe (rotation rad², translation m²): next to
/// nothing, see the module's documentation.
const PRIOR_VARIANCES: (f64, f64) = (1.0, 1e4);

/// One factor injected: which robot got it, tying which keyframes, when.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct InjectedFactor {
    pub robot: usize,
    pub neighbour: usize,
    pub local: KeyframeId,
    pub remote: KeyframeId,
    pub at_s: f64,
}

/// The scenario's injections, each made once.
pub struct FalseFactors {
    specs: Vec<(FalseFactorSpec, usize, usize)>,
    done: Vec<bool>,
    rng: ChaCha8Rng,
    pub injected: Vec<InjectedFactor>,
}

impl FalseFactors {
    /// `index_of` maps a robot name to its index (names were validated with the scenario).
    pub fn new(specs: &[FalseFactorSpec], seed: u64, index_of: impl Fn(&str) -> Option<usize>) -> Self {
        let specs: Vec<_> =
            specs.iter().filter_map(|s| Some((s.clone(), index_of(&s.robot)?, index_of(&s.neighbour)?))).collect();
        Self {
            done: vec![false; specs.len()],
            specs,
            rng: ChaCha8Rng::seed_from_u64(seed ^ 0xFA15_E0FA_C708),
            injected: Vec::new(),
        }
    }

    /// Whether an injection is due at `t` (the caller then observes the team and calls
    /// [`FalseFactors::make`]).
    pub fn due(&self, t: f64) -> bool {
        self.specs.iter().zip(&self.done).any(|((s, _, _), done)| !done && t >= s.at_s)
    }

    /// The messages due at `t`: (robot index, constraints for its Optimiser).
    pub fn make(
        &mut self,
        t: f64,
        observation: &Observation,
        truth: impl Fn(usize, f64) -> Option<Pose3>,
    ) -> Vec<(usize, InterRobotConstraints)> {
        let mut out = Vec::new();
        for (n, (spec, k, r)) in self.specs.iter().enumerate() {
            if self.done[n] || t < spec.at_s {
                continue;
            }
            let (Some(Some((local, neighbours, _))), Some(Some((remote, _, _)))) =
                (observation.maps.get(*k), observation.maps.get(*r))
            else {
                continue;
            };
            let neighbour_id = RobotId::from_index(*r);
            let Some(local_from_remote) = neighbours
                .iter()
                .find(|s| s.robot == neighbour_id && s.state == Some(ProtocolStage::Aligned))
                .and_then(|s| s.local_from_remote)
            else {
                continue;
            };
            if local.keyframes.len() < 2 || remote.keyframes.is_empty() {
                continue;
            }
            self.done[n] = true;
            let (sr, st) = CLAIMED_SIGMAS;
            let information = Matrix6::from_diagonal(&Vector6::new(
                1.0 / (sr * sr),
                1.0 / (sr * sr),
                1.0 / (sr * sr),
                1.0 / (st * st),
                1.0 / (st * st),
                1.0 / (st * st),
            ));
            let (pr, pt) = PRIOR_VARIANCES;
            let prior = Matrix6::from_diagonal(&Vector6::new(pr, pr, pr, pt, pt, pt));
            let mut message = InterRobotConstraints {
                robot: neighbour_id,
                local_from_remote,
                neighbour_keyframes: Vec::new(),
                factors: Vec::new(),
            };
            for _ in 0..spec.count {
                let l = &local.keyframes[self.rng.random_range(0..local.keyframes.len())];
                let rk = &remote.keyframes[self.rng.random_range(0..remote.keyframes.len())];
                let (Some(truth_l), Some(truth_r)) = (truth(*k, l.stamp), truth(*r, rk.stamp)) else {
                    continue;
                };
                let omega: [f64; 3] = UnitSphere.sample(&mut self.rng);
                let v: [f64; 3] = UnitSphere.sample(&mut self.rng);
                let omega = Vector3::from(omega) * spec.rotation_deg.to_radians();
                let v = Vector3::from(v) * spec.translation_m;
                let delta = Vector6::new(omega.x, omega.y, omega.z, v.x, v.y, v.z);
                let measured: Pose3 = truth_l.inverse() * truth_r * Pose3::exp(&delta);
                message.neighbour_keyframes.push((rk.id, rk.world_from_body, prior));
                message.factors.push((l.id, rk.id, measured, information));
                self.injected.push(InjectedFactor { robot: *k, neighbour: *r, local: l.id, remote: rk.id, at_s: t });
            }
            tracing::info!(robot = k, neighbour = r, factors = message.factors.len(), at = t, "false factors injected");
            out.push((*k, message));
        }
        out
    }
}
