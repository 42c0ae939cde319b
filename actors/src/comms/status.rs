//! What Comms reports and what a snapshot keeps of it.

use actix::Message;
use sgm_model::scene_graph::{KeyframeId, RobotId};
use sgm_model::wire::{RejectionCounts, ReplayGuard, TrafficAccount};
use std::collections::{BTreeMap, BTreeSet};

/// What Comms has seen, for status and reports.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CommsStatus {
    pub sent: TrafficAccount,
    pub received: TrafficAccount,
    pub rejected: RejectionCounts,
    /// Keyframe responses sent for a keyframe this neighbour had already been sent.
    pub keyframes_sent_twice: u64,
    /// Largest number of keyframes in flight to one neighbour at any time.
    pub max_keyframes_in_flight: usize,
    /// Keyframes given up after every retry (reported to the Matcher, never silently dropped).
    pub keyframes_given_up: u64,
    /// Keyframes not queued because `max_keyframes_waiting` were already waiting (reported to
    /// the Matcher).
    pub keyframes_refused_locally: u64,
    pub neighbours: Vec<RobotId>,
    /// Neighbours silent for `link_timeout_s`, now.
    pub links_down: Vec<RobotId>,
    /// Links that went down, then came back, in all.
    pub link_losses: u64,
    /// Every keyframe asked of each neighbour, and what became of it.
    pub keyframe_ledger: BTreeMap<RobotId, KeyframeLedger>,
    /// ObjectData revision last broadcast (0: none yet).
    pub object_data_revision: u32,
}

/// What became of the keyframes wanted from one neighbour. Each id is counted once in
/// `wanted`, and once in exactly one of the other fields:
/// `wanted = received + refused + given_up + pending`.
#[derive(Clone, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct KeyframeLedger {
    pub wanted: u64,
    pub received: u64,
    /// The neighbour answered that it does not have them, or sent an undecodable one.
    pub refused: u64,
    /// Every retry timed out, or too many were waiting here already.
    pub given_up: u64,
    /// Waiting to be asked, or asked and not yet answered.
    pub pending: u64,
}

#[derive(Message)]
#[rtype(result = "CommsStatus")]
pub struct GetCommsStatus;

/// What of Comms a snapshot keeps: the numbering that must never repeat, the replay windows
/// per sender and incarnation (a message recorded before a crash is still refused after it),
/// which keyframes each
/// neighbour already gave us or was given (and at which pose), and the accounts.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CommsState {
    pub sequence: u64,
    pub revision: u32,
    pub replay: ReplayGuard,
    pub keyframes_held: BTreeMap<RobotId, BTreeSet<KeyframeId>>,
    pub keyframes_sent: BTreeMap<RobotId, BTreeSet<KeyframeId>>,
    /// The pose each neighbour was last told of each keyframe we served (`super::served`).
    pub keyframes_told: super::served::Told,
    pub status: CommsStatus,
}
