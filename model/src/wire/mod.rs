//! What crosses the radio (paper §IV-B..F, DESIGN.md §4): the typed inter-robot messages, the
//! authenticated envelope that carries them, replay rejection, per-type traffic accounting, and
//! the keyframe point-cloud codec.

pub mod accounting;
pub mod cloud_codec;
pub mod envelope;
pub mod graph_factors;
pub mod messages;
pub mod replay;
pub mod team_key;
mod varint;

pub use accounting::{RejectionCounts, TrafficAccount, TrafficStats};
pub use envelope::{open, seal, Destination, Envelope, WireError, WireLimits, MAC_BYTES, PROTOCOL_VERSION};
pub use messages::{Message, MessageKind};
pub use replay::{Accepted, ReplayError, ReplayGuard, ReplayWindow, Sequence};
pub use team_key::TeamKey;
