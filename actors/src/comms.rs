//! `Comms`: the robot's only door to other robots (paper §IV-B..F, DESIGN.md §4). Seals and opens
//! envelopes (team-key MAC, replay window, size limits), broadcasts ObjectData on significant
//! change with a rate limit (and again after `object_data_refresh_s` of quiet, or soon after a
//! neighbour is first heard or comes back, so a lost broadcast or a late joiner is never left
//! without it), coalesces keyframe requests over a window and bounds them in flight (never
//! asking twice for a keyframe held or in flight; timeouts retried with back-off, then
//! reported), paces keyframe responses, and accounts every message by type. A neighbour silent
//! for `link_timeout_s` is down: its requests are neither retried nor given up until it is heard
//! again, when they are asked for afresh. With the Scan
//! Context baseline (`matcher.association = "scan_context"`) it broadcasts keyframe descriptors
//! at the same pace instead of object data.

use crate::clock::Clock;
use crate::config::CommsConfig;
use crate::containment::contained;
use crate::journal::ReplayJournal;
use crate::messages::*;
use crate::protocol::Wait;
use crate::transport::{Delivered, Transport};
use actix::{Actor, Context, Handler, Message, MessageResult, Recipient, Supervised};
use nalgebra::Point3;
use sgm_model::scene_graph::{KeyframeId, ObjectId, RobotId, Stamp};
use sgm_model::wire::cloud_codec;
use sgm_model::wire::messages::{
    unpack_covariance, KeyframeDescriptors, KeyframeRequest, ObjectCloudRequest, ObjectData, RefusalReason,
    WireDescriptor,
};
use sgm_model::wire::{
    open, seal, Accepted, Destination, Envelope, Message as WireMessage, RejectionCounts, ReplayGuard, Sequence,
    TeamKey, TrafficAccount, PROTOCOL_VERSION,
};
use std::collections::{BTreeMap, BTreeSet, VecDeque};

/// Where Comms delivers what arrives.
#[derive(Clone)]
pub struct CommsLinks {
    pub objects: Recipient<NeighbourObjects>,
    pub object_clouds: Recipient<NeighbourObjectClouds>,
    pub keyframes: Recipient<NeighbourKeyframe>,
    pub unavailable: Recipient<KeyframesUnavailable>,
    pub descriptors: Recipient<NeighbourDescriptors>,
    pub serve: Recipient<Serve>,
    pub link: Recipient<LinkChanged>,
}

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
/// neighbour already gave us or was given, and the accounts.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CommsState {
    pub sequence: u64,
    pub revision: u32,
    pub replay: ReplayGuard,
    pub keyframes_held: BTreeMap<RobotId, BTreeSet<KeyframeId>>,
    pub keyframes_sent: BTreeMap<RobotId, BTreeSet<KeyframeId>>,
    pub status: CommsStatus,
}

/// Keyframe requests to one neighbour.
#[derive(Clone, Debug, Default)]
struct KeyframeRequests {
    /// Wanted, not yet asked for (coalescing).
    wanted: BTreeSet<KeyframeId>,
    in_flight: BTreeMap<KeyframeId, Wait>,
    /// Received and still held by the Matcher (it reports those it lets go).
    held: BTreeSet<KeyframeId>,
    /// Answered "not here" (or undecodable), and not wanted since.
    refused: BTreeSet<KeyframeId>,
    /// Every retry timed out, or too many were waiting; not wanted since.
    given_up: BTreeSet<KeyframeId>,
    window_opened: Option<Stamp>,
    /// Since when requests have been in flight without a break (for the link timeout).
    owed_since: Option<Stamp>,
    /// While the link is down: when it was last probed.
    last_probe: Option<Stamp>,
}

impl KeyframeRequests {
    fn ledger(&self) -> KeyframeLedger {
        let pending = (self.wanted.len() + self.in_flight.len()) as u64;
        let (received, refused, given_up) =
            (self.held.len() as u64, self.refused.len() as u64, self.given_up.len() as u64);
        KeyframeLedger { wanted: received + refused + given_up + pending, received, refused, given_up, pending }
    }
}

pub struct Comms {
    robot: RobotId,
    config: CommsConfig,
    key: TeamKey,
    clock: Clock,
    transport: Box<dyn Transport>,
    links: Option<CommsLinks>,
    sequence: u64,
    replay: ReplayGuard,
    last_heard: BTreeMap<RobotId, Stamp>,
    /// Each neighbour's incarnation when last heard.
    incarnations: BTreeMap<RobotId, u32>,
    links_down: BTreeSet<RobotId>,
    status: CommsStatus,
    // ObjectData broadcast (off when the Matcher associates by descriptors).
    object_data: bool,
    revision: u32,
    latest_objects: Option<LocalObjects>,
    broadcast_centroids: BTreeMap<ObjectId, Point3<f64>>,
    change_pending: bool,
    /// Someone needs the current ObjectData again (a new or returning neighbour).
    repeat_pending: bool,
    last_broadcast: Option<Stamp>,
    // Scan Context descriptors not yet broadcast.
    descriptors: Vec<WireDescriptor>,
    last_descriptors: Option<Stamp>,
    /// Where grown replay reservations go (the ROS node's journal file), if anywhere.
    journal: Option<std::sync::Arc<dyn ReplayJournal>>,
    // Keyframes.
    requests: BTreeMap<RobotId, KeyframeRequests>,
    responses: VecDeque<Outgoing>,
    keyframes_sent: BTreeMap<RobotId, BTreeSet<KeyframeId>>,
}

impl Comms {
    /// `sequence_start`: first sequence number (`incarnation ‖ counter`, see
    /// `sgm_model::wire::replay`). Sequences must never repeat under one team key, also across
    /// restarts: the ROS node starts a fresh random incarnation at every start; simulation
    /// stays in incarnation 0 and starts its counter at the (never receding) clock in µs.
    pub fn new(
        robot: RobotId,
        config: CommsConfig,
        key: TeamKey,
        clock: Clock,
        transport: Box<dyn Transport>,
        sequence_start: u64,
    ) -> Self {
        Self {
            robot,
            config,
            key,
            clock,
            transport,
            links: None,
            sequence: sequence_start,
            replay: ReplayGuard::default(),
            last_heard: BTreeMap::new(),
            incarnations: BTreeMap::new(),
            links_down: BTreeSet::new(),
            status: CommsStatus::default(),
            object_data: true,
            revision: 0,
            latest_objects: None,
            broadcast_centroids: BTreeMap::new(),
            change_pending: false,
            repeat_pending: false,
            last_broadcast: None,
            descriptors: Vec::new(),
            last_descriptors: None,
            journal: None,
            requests: BTreeMap::new(),
            responses: VecDeque::new(),
            keyframes_sent: BTreeMap::new(),
        }
    }

    pub fn freeze(&self) -> CommsState {
        CommsState {
            sequence: self.sequence,
            revision: self.revision,
            replay: self.replay.clone(),
            keyframes_held: self.requests.iter().map(|(r, q)| (*r, q.held.clone())).collect(),
            keyframes_sent: self.keyframes_sent.clone(),
            status: self.status.clone(),
        }
    }

    /// Continues from `state`: revisions go on above the snapshot's; sequence numbers too when
    /// this start keeps the snapshot's incarnation (simulation), and otherwise start afresh in
    /// the new one (a ROS node: what it sent after the snapshot stays unique).
    pub fn thawed(mut self, state: CommsState) -> Self {
        let incarnation = |s: u64| Sequence::from_bits(s).incarnation;
        if incarnation(state.sequence) == incarnation(self.sequence) {
            self.sequence = self.sequence.max(state.sequence);
        }
        self.revision = state.revision;
        self.replay = state.replay;
        for (robot, held) in state.keyframes_held {
            self.requests.entry(robot).or_default().held = held;
        }
        self.keyframes_sent = state.keyframes_sent;
        self.status = CommsStatus { links_down: Vec::new(), ..state.status };
        self
    }

    /// Without object data: the Scan Context baseline shares keyframe descriptors instead.
    pub fn without_object_data(mut self) -> Self {
        self.object_data = false;
        self
    }

    fn send(&mut self, to: Destination, message: WireMessage) {
        let kind = message.kind();
        self.sequence += 1;
        let envelope = Envelope { version: PROTOCOL_VERSION, from: self.robot, to, sequence: self.sequence, message };
        match seal(&envelope, &self.key, &self.config.limits) {
            Ok(bytes) => {
                self.status.sent.record(kind, bytes.len());
                self.transport.transmit(self.robot, to, bytes, self.clock.now());
            }
            Err(e) => tracing::warn!(robot = %self.robot, ?kind, "not sent: {e}"),
        }
    }

    /// Broadcasts ObjectData when the map changed significantly, when a neighbour needs it
    /// again, or after `object_data_refresh_s` without a broadcast — at most once per
    /// `object_data_interval_s`. An unchanged map is sent again under its old revision, which a
    /// neighbour holding it ignores. Revisions never repeat, also after a restart without a
    /// snapshot: a new one is at least the clock in whole seconds.
    fn try_broadcast(&mut self, now: Stamp) {
        let since = self.last_broadcast.map(|t| now - t);
        let due = since.is_none_or(|s| s >= self.config.object_data_interval_s);
        let stale = since.is_some_and(|s| s >= self.config.object_data_refresh_s);
        if !self.object_data || !due || !(self.change_pending || self.repeat_pending || stale) {
            return;
        }
        let Some(objects) = &self.latest_objects else { return };
        if self.change_pending || self.revision == 0 {
            self.revision = (self.revision + 1).max(now.clamp(0.0, f64::from(u32::MAX)) as u32);
        }
        let data = ObjectData::quantise(
            self.revision,
            self.config.centroid_resolution_mm,
            objects.objects.iter().map(|o| (o.id, o.label, o.centroid, o.size.unwrap_or_default())),
        );
        self.broadcast_centroids = objects.objects.iter().map(|o| (o.id, o.centroid)).collect();
        self.change_pending = false;
        self.repeat_pending = false;
        self.last_broadcast = Some(now);
        self.status.object_data_revision = self.revision;
        self.send(Destination::Broadcast, WireMessage::ObjectData(data));
    }

    /// A neighbour owing us keyframes and silent for `link_timeout_s` since the later of when it
    /// was last heard and when it began to owe goes down (reported to the Matcher). One with
    /// nothing outstanding may be quiet for as long as it likes.
    fn watch_links(&mut self, now: Stamp) {
        let silent: Vec<RobotId> = self
            .last_heard
            .iter()
            .filter(|(r, heard)| {
                let owed = self.requests.get(r).and_then(|q| q.owed_since);
                owed.is_some_and(|since| now - since.max(**heard) >= self.config.link_timeout_s)
                    && !self.links_down.contains(r)
            })
            .map(|(r, _)| *r)
            .collect();
        for robot in silent {
            tracing::info!(robot = %self.robot, neighbour = %robot, "link lost");
            self.links_down.insert(robot);
            self.status.link_losses += 1;
            if let Some(links) = &self.links {
                links.link.do_send(LinkChanged { robot, up: false });
            }
        }
        self.status.links_down = self.links_down.iter().copied().collect();
    }

    /// A neighbour was heard: a new one, or one back from silence, is sent our ObjectData soon;
    /// one back from silence has its unanswered keyframe requests asked for afresh.
    /// A neighbour heard under a new incarnation has restarted, perhaps from a snapshot: its
    /// replay windows then refuse our counters up to its journal's reservation, at most
    /// `RESERVE` above the highest it accepted. Our counter skips `RESERVE` (skipping is
    /// allowed; repeating is not) so that what we send next is heard at once.
    fn note_incarnation(&mut self, from: RobotId, sequence: u64) {
        let incarnation = Sequence::from_bits(sequence).incarnation;
        if self.incarnations.insert(from, incarnation).is_some_and(|before| before != incarnation) {
            self.sequence += sgm_model::wire::replay::RESERVE;
            tracing::info!(robot = %self.robot, neighbour = %from,
                "neighbour restarted (new incarnation): our counter skips past its replay reservation");
        }
    }

    fn heard(&mut self, from: RobotId, now: Stamp) {
        let first = self.last_heard.insert(from, now).is_none();
        if first {
            if !self.status.neighbours.contains(&from) {
                self.status.neighbours.push(from);
                self.status.neighbours.sort();
            }
            self.repeat_pending = true;
        }
        if self.links_down.remove(&from) {
            tracing::info!(robot = %self.robot, neighbour = %from, "link back");
            self.status.links_down = self.links_down.iter().copied().collect();
            self.repeat_pending = true;
            if let Some(q) = self.requests.get_mut(&from) {
                let unanswered: Vec<KeyframeId> = q.in_flight.keys().copied().collect();
                q.in_flight.clear();
                q.owed_since = None;
                q.last_probe = None;
                q.wanted.extend(unanswered);
                if !q.wanted.is_empty() {
                    q.window_opened = Some(now);
                }
            }
            if let Some(links) = &self.links {
                links.link.do_send(LinkChanged { robot: from, up: true });
            }
        }
    }

    /// Broadcasts the descriptors of keyframes made since the last broadcast, at most once per
    /// `object_data_interval_s`, in envelopes of at most `limits.max_ids`.
    fn broadcast_descriptors(&mut self, now: Stamp) {
        let due = self.last_descriptors.is_none_or(|t| now - t >= self.config.object_data_interval_s);
        if self.descriptors.is_empty() || !due {
            return;
        }
        self.last_descriptors = Some(now);
        let pending = std::mem::take(&mut self.descriptors);
        for chunk in pending.chunks(self.config.limits.max_ids.max(1)) {
            let message = WireMessage::KeyframeDescriptors(KeyframeDescriptors { descriptors: chunk.to_vec() });
            self.send(Destination::Broadcast, message);
        }
    }

    /// Queues keyframes for the next request window: never one held, in flight or already
    /// queued; beyond `max_keyframes_waiting`, reported unavailable at once.
    fn want_keyframes(&mut self, msg: RequestKeyframes) {
        let now = self.clock.now();
        let q = self.requests.entry(msg.robot).or_default();
        let mut overflow = Vec::new();
        for id in msg.keyframes {
            if q.held.contains(&id) || q.in_flight.contains_key(&id) || q.wanted.contains(&id) {
                continue;
            }
            if q.wanted.len() < self.config.max_keyframes_waiting {
                q.wanted.insert(id);
                q.given_up.remove(&id);
                q.refused.remove(&id);
            } else {
                overflow.push(id);
                q.given_up.insert(id);
            }
        }
        if !q.wanted.is_empty() && q.window_opened.is_none() {
            q.window_opened = Some(now);
        }
        if !overflow.is_empty() {
            self.status.keyframes_refused_locally += overflow.len() as u64;
            if let Some(links) = &self.links {
                let reason = RefusalReason::Busy;
                links.unavailable.do_send(KeyframesUnavailable { robot: msg.robot, keyframes: overflow, reason });
            }
        }
    }

    fn flush_requests(&mut self, now: Stamp) {
        let robots: Vec<RobotId> = self.requests.keys().copied().collect();
        for robot in robots {
            let Some(q) = self.requests.get_mut(&robot) else { continue };
            // Towards a silent neighbour nothing is retried, nor given up (see `heard`); it is
            // probed once per `link_timeout_s` with a request for a few of the keyframes it owes,
            // whose answer brings the link back.
            if self.links_down.contains(&robot) {
                if q.last_probe.is_none_or(|t| now - t >= self.config.link_timeout_s) {
                    q.last_probe = Some(now);
                    let keyframes = q.in_flight.keys().take(self.config.max_keyframes_per_request).copied().collect();
                    self.send(Destination::Robot(robot), WireMessage::KeyframeRequest(KeyframeRequest { keyframes }));
                }
                continue;
            }
            // Timeouts: retry with back-off, or report.
            let expired: Vec<(KeyframeId, Wait)> =
                q.in_flight.iter().filter(|(_, w)| w.expired(now)).map(|(k, w)| (*k, *w)).collect();
            let (mut retry, mut given_up) = (Vec::new(), Vec::new());
            for (id, wait) in expired {
                let heard = self.last_heard.get(&robot).is_some_and(|t| *t >= wait.sent);
                match wait.retry(now, &self.config.retry, heard) {
                    Some(next) => {
                        q.in_flight.insert(id, next);
                        retry.push(id);
                    }
                    None => {
                        q.in_flight.remove(&id);
                        q.given_up.insert(id);
                        given_up.push(id);
                    }
                }
            }
            // New requests once the coalescing window has passed, within the in-flight bound.
            let window_passed = q.window_opened.is_some_and(|t| now - t >= self.config.request_window_s);
            let mut fresh = Vec::new();
            if window_passed {
                let room = self.config.max_keyframes_in_flight.saturating_sub(q.in_flight.len());
                fresh = q.wanted.iter().copied().take(room).collect();
                for id in &fresh {
                    q.wanted.remove(id);
                    q.in_flight.insert(*id, Wait::new(now, &self.config.retry));
                }
                q.window_opened = if q.wanted.is_empty() { None } else { Some(now) };
            }
            self.status.max_keyframes_in_flight = self.status.max_keyframes_in_flight.max(q.in_flight.len());
            q.owed_since = if q.in_flight.is_empty() { None } else { q.owed_since.or(Some(now)) };
            let mut ids = retry;
            ids.extend(fresh);
            for chunk in ids.chunks(self.config.max_keyframes_per_request) {
                self.send(
                    Destination::Robot(robot),
                    WireMessage::KeyframeRequest(KeyframeRequest { keyframes: chunk.to_vec() }),
                );
            }
            if !given_up.is_empty() {
                self.status.keyframes_given_up += given_up.len() as u64;
                if let Some(links) = &self.links {
                    links.unavailable.do_send(KeyframesUnavailable {
                        robot,
                        keyframes: given_up,
                        reason: RefusalReason::Busy,
                    });
                }
            }
        }
    }

    fn send_responses(&mut self) {
        for _ in 0..self.config.max_responses_per_tick {
            let Some(out) = self.responses.pop_front() else { break };
            if let WireMessage::KeyframeResponse(r) = &out.message {
                if !self.keyframes_sent.entry(out.to).or_default().insert(r.keyframe) {
                    self.status.keyframes_sent_twice += 1;
                }
            }
            self.send(Destination::Robot(out.to), out.message);
        }
    }

    fn receive(&mut self, bytes: &[u8]) {
        let envelope = match open(bytes, &self.key, &self.config.limits) {
            Ok(e) => e,
            Err(e) => {
                self.status.rejected.record_wire(&e);
                tracing::debug!(robot = %self.robot, "refused envelope: {e}");
                return;
            }
        };
        if envelope.from == self.robot || !envelope.to.includes(self.robot) {
            return;
        }
        match self.replay.accept(envelope.from.0, envelope.sequence) {
            Err(e) => {
                self.status.rejected.record_replay(&e);
                return;
            }
            Ok(Accepted::ReservationGrew) => {
                if let Some(journal) = &self.journal {
                    journal.write(self.replay.reservations());
                }
            }
            Ok(Accepted::Reserved) => {}
        }
        let from = envelope.from;
        self.status.received.record(envelope.message.kind(), bytes.len());
        self.note_incarnation(from, envelope.sequence);
        self.heard(from, self.clock.now());
        let Some(links) = self.links.clone() else { return };
        match envelope.message {
            WireMessage::ObjectData(data) => links.objects.do_send(NeighbourObjects { robot: from, data }),
            WireMessage::KeyframeDescriptors(m) => {
                let total = m.descriptors.len();
                let descriptors: Vec<_> = m
                    .descriptors
                    .into_iter()
                    .filter_map(|d| Some((d.keyframe, d.world_from_body.to_pose()?, d.descriptor()?)))
                    .collect();
                self.status.rejected.malformed += (total - descriptors.len()) as u64;
                if !descriptors.is_empty() {
                    links.descriptors.do_send(NeighbourDescriptors { robot: from, descriptors });
                }
            }
            WireMessage::ObjectCloudRequest(r) => {
                links.serve.do_send(Serve::ObjectClouds { robot: from, objects: r.objects })
            }
            WireMessage::ObjectCloudResponse(r) => {
                links.object_clouds.do_send(NeighbourObjectClouds { robot: from, clouds: r.objects })
            }
            WireMessage::KeyframeRequest(r) => {
                if self.responses.len() + r.keyframes.len() > self.config.limits.max_ids * 4 {
                    // Outgoing budget spent: say so instead of dropping.
                    let refusal = sgm_model::wire::messages::KeyframeRefusal {
                        keyframes: r.keyframes,
                        reason: RefusalReason::Busy,
                    };
                    self.send(Destination::Robot(from), WireMessage::KeyframeRefusal(refusal));
                } else {
                    links.serve.do_send(Serve::Keyframes { robot: from, keyframes: r.keyframes });
                }
            }
            WireMessage::KeyframeResponse(r) => {
                let q = self.requests.entry(from).or_default();
                let asked = q.in_flight.remove(&r.keyframe).is_some() | q.wanted.remove(&r.keyframe);
                if !asked && q.held.contains(&r.keyframe) {
                    return; // a late duplicate of a retried request
                }
                // One given up on that arrives late after all is received.
                q.given_up.remove(&r.keyframe);
                let pose = r.world_from_body.to_pose();
                let covariance = unpack_covariance(&r.covariance);
                let points = cloud_codec::decode_at_most(&r.cloud, self.config.limits.max_cloud_points);
                match (pose, covariance, points) {
                    (Some(world_from_body), Some(covariance), Ok(points_in_body)) => {
                        q.held.insert(r.keyframe);
                        links.keyframes.do_send(NeighbourKeyframe {
                            robot: from,
                            id: r.keyframe,
                            world_from_body,
                            covariance,
                            points_in_body,
                        })
                    }
                    _ => {
                        q.refused.insert(r.keyframe);
                        self.status.rejected.malformed += 1;
                        links.unavailable.do_send(KeyframesUnavailable {
                            robot: from,
                            keyframes: vec![r.keyframe],
                            reason: RefusalReason::Unknown,
                        });
                    }
                }
            }
            // Busy: the keyframes stay in flight and their timeouts retry with back-off.
            WireMessage::KeyframeRefusal(r) if r.reason == RefusalReason::Busy => {}
            WireMessage::KeyframeRefusal(r) => {
                let q = self.requests.entry(from).or_default();
                for id in &r.keyframes {
                    if q.in_flight.remove(id).is_some() {
                        q.refused.insert(*id);
                    }
                }
                links.unavailable.do_send(KeyframesUnavailable {
                    robot: from,
                    keyframes: r.keyframes,
                    reason: r.reason,
                });
            }
        }
    }
}

impl Actor for Comms {
    type Context = Context<Self>;
}

impl Supervised for Comms {
    fn restarting(&mut self, _: &mut Context<Self>) {
        // Everything survives a restart: sequence, replay windows, requests, accounting.
        tracing::warn!(robot = %self.robot, "comms restarting");
    }
}

impl Handler<Delivered> for Comms {
    type Result = ();
    fn handle(&mut self, msg: Delivered, ctx: &mut Context<Self>) {
        contained(ctx, "comms", || {
            self.receive(&msg.bytes);
        });
    }
}

impl Handler<LocalObjects> for Comms {
    type Result = ();
    fn handle(&mut self, msg: LocalObjects, ctx: &mut Context<Self>) {
        contained(ctx, "comms", || {
            let significant = msg.objects.iter().any(|o| {
                self.broadcast_centroids
                    .get(&o.id)
                    .is_none_or(|c| (c - o.centroid).norm() > self.config.significant_move_m)
            }) || msg.objects.len() != self.broadcast_centroids.len();
            self.change_pending |= significant;
            self.latest_objects = Some(msg);
            self.try_broadcast(self.clock.now());
        });
    }
}

impl Handler<ShareDescriptor> for Comms {
    type Result = ();
    fn handle(&mut self, msg: ShareDescriptor, ctx: &mut Context<Self>) {
        contained(ctx, "comms", || {
            self.descriptors.push(WireDescriptor::quantise(msg.keyframe, &msg.world_from_body, &msg.descriptor));
        });
    }
}

impl Handler<RequestObjectClouds> for Comms {
    type Result = ();
    fn handle(&mut self, msg: RequestObjectClouds, ctx: &mut Context<Self>) {
        contained(ctx, "comms", || {
            for chunk in msg.objects.chunks(self.config.limits.max_ids) {
                self.send(
                    Destination::Robot(msg.robot),
                    WireMessage::ObjectCloudRequest(ObjectCloudRequest { objects: chunk.to_vec() }),
                );
            }
        });
    }
}

impl Handler<RequestKeyframes> for Comms {
    type Result = ();
    fn handle(&mut self, msg: RequestKeyframes, ctx: &mut Context<Self>) {
        contained(ctx, "comms", || self.want_keyframes(msg));
    }
}

impl Handler<KeyframesReleased> for Comms {
    type Result = ();
    fn handle(&mut self, msg: KeyframesReleased, ctx: &mut Context<Self>) {
        contained(ctx, "comms", || {
            if let Some(q) = self.requests.get_mut(&msg.robot) {
                for id in &msg.keyframes {
                    q.held.remove(id);
                }
            }
        });
    }
}

impl Handler<Outgoing> for Comms {
    type Result = ();
    fn handle(&mut self, msg: Outgoing, ctx: &mut Context<Self>) {
        contained(ctx, "comms", || {
            match msg.message {
                WireMessage::KeyframeResponse(ref r) => {
                    // A retried request must not queue a second copy of a response still waiting.
                    let queued = self.responses.iter().any(|q| {
                        q.to == msg.to
                            && matches!(&q.message, WireMessage::KeyframeResponse(x) if x.keyframe == r.keyframe)
                    });
                    if !queued {
                        self.responses.push_back(msg);
                    }
                }
                message => self.send(Destination::Robot(msg.to), message),
            }
        });
    }
}

impl Handler<Tick> for Comms {
    type Result = ();
    fn handle(&mut self, msg: Tick, ctx: &mut Context<Self>) {
        contained(ctx, "comms", || {
            self.watch_links(msg.now);
            self.try_broadcast(msg.now);
            self.broadcast_descriptors(msg.now);
            self.flush_requests(msg.now);
            self.send_responses();
        });
    }
}

/// Reports grown replay reservations to `journal` from now on (and the current ones at once).
#[derive(Message)]
#[rtype(result = "()")]
pub struct AttachJournal(pub std::sync::Arc<dyn ReplayJournal>);

impl Handler<AttachJournal> for Comms {
    type Result = ();
    fn handle(&mut self, msg: AttachJournal, _: &mut Context<Self>) {
        msg.0.write(self.replay.reservations());
        self.journal = Some(msg.0);
    }
}

impl Handler<GetCommsStatus> for Comms {
    type Result = MessageResult<GetCommsStatus>;
    fn handle(&mut self, _: GetCommsStatus, _: &mut Context<Self>) -> Self::Result {
        let mut status = self.status.clone();
        status.keyframe_ledger = self.requests.iter().map(|(r, q)| (*r, q.ledger())).collect();
        MessageResult(status)
    }
}

connects!(Comms => CommsLinks);
freezes!(Comms => CommsState);
stops_on_injected_failure!(Comms => "comms");
