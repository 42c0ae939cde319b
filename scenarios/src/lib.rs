//! `sgm-scenarios`: scenarios, the simulator, the runner and the bag replay, reports, and the
//! file formats of the CLI. The `sgm` binary is a thin shell over this library.
//!
//! The modules, lowest first; each uses only those above it (`tests/tests/layering.rs` holds
//! it): `memory`, `object_file`, `observation`, `settings` → [`scenario`] (scenario files, the
//! class shapes they name) → [`sim`] (world, sensors, radio) → [`record`] (what a run
//! observed), `bag_out`, [`front_end`] (the odometry alone on simulated sensors) → [`report`] (figures from a record), [`team`] (the robots stepped on
//! the virtual clock) → `result_bag` → [`runner`], [`replay`].

pub mod bag_odometry;
pub mod bag_out;
pub mod front_end;
pub mod memory;
pub mod object_file;
pub mod observation;
pub mod output_error;
pub mod record;
pub mod replay;
pub mod report;
pub mod result_bag;
pub mod runner;
pub mod scenario;
pub mod settings;
pub mod sim;
pub mod team;
pub mod threads;
