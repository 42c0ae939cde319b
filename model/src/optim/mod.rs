//! Pose-graph optimisation (paper §III, eq. 1): the local step, where every robot optimises its
//! keyframes together with the neighbour keyframes tied to them.

pub mod consistency;
pub mod factors;
pub mod g2o;
pub mod graph;
pub mod gravity;
pub mod keyframe_graph;
pub mod manifold;
pub mod marginals;
pub mod robust;
pub mod shared_factors;
pub mod solver;
