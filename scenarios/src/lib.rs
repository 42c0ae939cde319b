//! `sgm-scenarios`: configuration loading, the object-graph file format, benchmarks and (with
//! later issues) simulated scenarios. The `sgm` binary is a thin shell over this library.

pub mod bag_out;
pub mod memory;
pub mod object_file;
pub mod replay;
pub mod report;
pub mod result_bag;
pub mod runner;
pub mod scenario;
pub mod settings;
pub mod sim;
pub mod team;
