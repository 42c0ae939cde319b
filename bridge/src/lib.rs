//! SGM's ROS 1 bridge (DESIGN.md §5): ROS message ↔ model conversions, the synchroniser that
//! turns LiDAR, label image and odometry streams into sensor frames, ROS 1 bag reading and
//! writing, and the rosrust node with its inter-robot transport.
//!
//! The modules, lowest first; each uses only those before it (no two use each other):
//! `error`, `msg`, `latency`, [`tf`], [`timeline`] → [`convert`], [`persist`] → [`config`] (the
//! `[ros]` section, with the sections of the modules above it) → [`bounded`], [`inputs`],
//! [`team_frames`] → [`bag`], [`bounded_deliver`], [`sync`] → [`health`], [`transport`] →
//! [`node`] → [`doctor`].

pub mod bag;
pub mod bounded;
pub mod bounded_deliver;
pub mod config;
pub mod convert;
pub mod doctor;
pub mod error;
pub mod health;
pub mod inputs;
pub mod latency;
pub mod msg;
pub mod node;
pub mod persist;
pub mod sync;
pub mod team_frames;
pub mod tf;
pub mod timeline;
pub mod transport;
