//! What a match returns: an alignment the matcher stands behind, or a refusal that says why.

use crate::geometry::Pose3;
use crate::scene_graph::ObjectId;
use std::fmt;

/// A verified association: local object ↔ remote object.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VerifiedMatch {
    pub local: ObjectId,
    pub remote: ObjectId,
    /// Distance between the local centroid and the transformed remote centroid, m.
    pub residual_m: f64,
    /// Whether the two labels are equal (false: accepted through label confusion).
    pub same_label: bool,
}

/// An accepted transform.
#[derive(Clone, Debug, PartialEq)]
pub struct Alignment {
    /// p_local = local_from_remote · p_remote (the paper's T_{Wα→Wβ}).
    pub local_from_remote: Pose3,
    pub matches: Vec<VerifiedMatch>,
    /// −log10 NFA: how unlikely the agreement is by chance; accepted above −log10 ε.
    pub significance: f64,
    /// RMS of the match residuals, m.
    pub rmse_m: f64,
}

/// Why no transform was returned.
#[derive(Clone, Debug, PartialEq)]
pub enum RefusalReason {
    TooFewObjects {
        local: usize,
        remote: usize,
        required: usize,
    },
    NoCandidates,
    NoConsistentPair,
    TooFewVerified {
        verified: usize,
        required: usize,
    },
    Collinear {
        spread_m: f64,
        required_m: f64,
    },
    NotSignificant {
        significance: f64,
        required: f64,
    },
    Ambiguous {
        runner_up_displacement_m: f64,
        score_ratio: f64,
    },
    /// A second transform explains the shared ground at least as consistently (`overlap`): a
    /// repeated layout the objects cannot tell apart.
    Repeated {
        runner_up_displacement_m: f64,
        agreement: f64,
        runner_up_agreement: f64,
    },
}

impl fmt::Display for RefusalReason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::TooFewObjects { local, remote, required } => {
                write!(f, "too few objects: local {local}, remote {remote}, need at least {required} each")
            }
            Self::NoCandidates => write!(f, "no label-compatible object pairs"),
            Self::NoConsistentPair => write!(f, "no pair of associations agrees on an edge length"),
            Self::TooFewVerified { verified, required } => {
                write!(f, "only {verified} geometrically verified matches, need {required}")
            }
            Self::Collinear { spread_m, required_m } => {
                write!(f, "matched objects are nearly collinear (spread {spread_m:.2} m < {required_m} m)")
            }
            Self::NotSignificant { significance, required } => write!(
                f,
                "agreement could be chance (significance {significance:.2} < {required:.2}, i.e. too many false alarms expected)"
            ),
            Self::Ambiguous { runner_up_displacement_m, score_ratio } => write!(
                f,
                "ambiguous: a second transform {runner_up_displacement_m:.1} m away explains the data almost as well (score ratio {score_ratio:.2})"
            ),
            Self::Repeated { runner_up_displacement_m, agreement, runner_up_agreement } => write!(
                f,
                "repeated layout: a second transform {runner_up_displacement_m:.1} m away agrees with the shared ground as well (agreement {runner_up_agreement:.2} against {agreement:.2})"
            ),
        }
    }
}

/// A refusal, with the best transform seen if there was one (for diagnostics only).
#[derive(Clone, Debug, PartialEq)]
pub struct Refusal {
    pub reason: RefusalReason,
    pub best_guess: Option<Pose3>,
    pub significance: f64,
}

#[derive(Clone, Debug, PartialEq)]
pub enum MatchOutcome {
    Aligned(Alignment),
    Refused(Refusal),
}

impl MatchOutcome {
    pub fn alignment(&self) -> Option<&Alignment> {
        match self {
            Self::Aligned(a) => Some(a),
            Self::Refused(_) => None,
        }
    }

    pub fn significance(&self) -> f64 {
        match self {
            Self::Aligned(a) => a.significance,
            Self::Refused(r) => r.significance,
        }
    }
}

/// Counters of one matching run.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MatchStats {
    pub candidates: usize,
    pub affinity_nonzeros: usize,
    pub power_iterations: usize,
    pub power_converged: bool,
    pub hypotheses: usize,
}

/// Outcome plus what the spectral stage alone would have answered (the paper's matches).
#[derive(Clone, Debug, PartialEq)]
pub struct MatchReport {
    pub outcome: MatchOutcome,
    /// LAP on −x with the minimum assignment score: the paper's association, before verification.
    pub spectral_matches: Vec<(ObjectId, ObjectId)>,
    pub stats: MatchStats,
}
