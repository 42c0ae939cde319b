//! Object-graph matching (paper §IV-B, §IV-C, eqs. 5–8) and the transform it implies.
//!
//! [`match_graphs`] runs the pipeline in [`matcher`](self::matcher): candidates → sparse affinity →
//! principal eigenvector → LAP (the paper), then geometric verification and explicit refusal
//! (beyond the paper). [`paper_baseline`] is the paper's dense formulation, kept to measure the
//! difference.

mod affinity;
pub mod alignment;
mod candidates;
pub mod closure;
mod config;
mod graph;
mod labels;
mod matcher;
mod null_model;
mod object_grid;
mod outcome;
mod overlap;
pub mod paper_baseline;
pub mod place_candidates;
pub mod relay;
pub mod scan_context;
pub mod settle;
pub mod significance;
mod spectral;
pub mod suspect;
mod symmetry;
pub mod tilt;
mod verification;
mod vertex;

pub use affinity::SparseAffinity;
pub use config::{LabelConfusion, MatcherConfig, MatcherConfigError};
pub use graph::{GraphError, GraphObject, ObjectGraph};
pub use labels::LabelSimilarity;
pub use matcher::match_graphs;
pub use outcome::{Alignment, MatchOutcome, MatchReport, MatchStats, Refusal, RefusalReason, VerifiedMatch};
pub use spectral::{principal_eigenvector, Eigen};
pub use vertex::VertexCompare;
