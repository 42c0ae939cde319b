//! One robot as a tree of actix actors (DESIGN.md §3) and the SGM exchange between robots
//! (paper §IV-B..F):
//!
//! ```text
//! RobotSupervisor ─┬─ Sensor ─► Fusion ─► Tracker ─┬─► Optimiser ─► (Tracker, Matcher)
//!                  │                               ├─► Matcher ◄──► Comms ◄──► other robots
//!                  │                               └─► Comms
//! ```

pub mod clock;
pub mod comms;
pub mod config;
pub mod fusion;
pub mod matcher;
pub mod messages;
pub mod optimiser;
pub mod protocol;
pub mod sensor;
pub mod supervisor;
pub mod tracker;
pub mod transport;
