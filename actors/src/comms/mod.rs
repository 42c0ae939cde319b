//! `Comms`: the robot's only door to other robots (paper §IV-B..F, DESIGN.md §4). A thin actor
//! over plain parts, each handed `now` and the input and returning what to send:
//! - [`door`]: seals and opens envelopes (team-key MAC, replay window per sender and
//!   incarnation, size limits), numbering what we send so that it never repeats;
//! - [`broadcast`]: ObjectData on significant change with a rate limit (and again after
//!   `object_data_refresh_s` of quiet, or soon after a neighbour is first heard or comes back,
//!   so a lost broadcast or a late joiner is never left without it); with the Scan Context
//!   baseline (`matcher.association = "scan_context"`) keyframe descriptors at the same pace;
//!   our alignments when one is made or moves (hints for the neighbours, `matcher::relay`);
//! - [`requests`]: keyframe requests coalesced over a window and bounded in flight (never
//!   asking twice for a keyframe held or in flight; timeouts retried with back-off, then
//!   reported);
//! - [`link_watch`]: a neighbour silent for `link_timeout_s` while it owes us keyframes is
//!   down: its requests are neither retried nor given up until it is heard again, when they are
//!   asked for afresh;
//! - [`responses`]: keyframe responses paced per tick, never queued twice;
//! - [`served`]: keyframes we served, told again (`KeyframePoses`) when our solves move them,
//!   so a neighbour's priors on them do not go stale; the poses a neighbour tells us go to the
//!   Optimiser;
//! - [`status`]: every message accounted by type, and what a snapshot keeps.

pub mod broadcast;
pub mod door;
pub mod link_watch;
pub mod requests;
pub mod responses;
pub mod served;
pub mod status;

pub use status::{CommsState, CommsStatus, GetCommsStatus, KeyframeLedger};

use crate::clock::Clock;
use crate::config::CommsConfig;
use crate::containment::contained;
use crate::journal::ReplayJournal;
use crate::messages::*;
use crate::transport::{Delivered, Transport};
use actix::{Actor, Context, Handler, Message, MessageResult, Recipient, Supervised};
use broadcast::{AlignmentBroadcast, DescriptorBroadcast, ObjectBroadcast};
use door::Door;
use link_watch::LinkWatch;
use requests::{KeyframeRequests, RequestBook, ResponseFate};
use responses::Responses;
use served::ServedPoses;
use sgm_model::scene_graph::{RobotId, Stamp};
use sgm_model::wire::cloud_codec;
use sgm_model::wire::messages::{
    unpack_covariance, KeyframeRefusalReason, KeyframeRequest, ObjectCloudRequest, WireDescriptor,
};
use sgm_model::wire::{Destination, Message as WireMessage, TeamKey};

/// Where Comms delivers what arrives.
#[derive(Clone)]
pub struct CommsLinks {
    pub objects: Recipient<NeighbourObjects>,
    pub object_clouds: Recipient<NeighbourObjectClouds>,
    pub keyframes: Recipient<NeighbourKeyframe>,
    pub unavailable: Recipient<KeyframesUnavailable>,
    pub descriptors: Recipient<NeighbourDescriptors>,
    pub alignments: Recipient<NeighbourAlignments>,
    pub serve: Recipient<Serve>,
    pub link: Recipient<LinkChanged>,
    /// A neighbour's new estimates of keyframes it served us.
    pub keyframe_poses: Recipient<NeighbourKeyframePoses>,
    /// A neighbour's requests for our factor log, and the slices of its own
    /// (`optimiser.share_factors`).
    pub graph: Recipient<NeighbourGraph>,
}

pub struct Comms {
    robot: RobotId,
    config: CommsConfig,
    key: TeamKey,
    clock: Clock,
    transport: Box<dyn Transport>,
    links: Option<CommsLinks>,
    door: Door,
    watch: LinkWatch,
    status: CommsStatus,
    objects: ObjectBroadcast,
    descriptors: DescriptorBroadcast,
    alignments: AlignmentBroadcast,
    /// Where grown replay reservations go (the ROS node's journal file), if anywhere.
    journal: Option<std::sync::Arc<dyn ReplayJournal>>,
    requests: RequestBook,
    responses: Responses,
    served: ServedPoses,
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
            door: Door::new(robot, sequence_start),
            watch: LinkWatch::default(),
            status: CommsStatus::default(),
            objects: ObjectBroadcast::default(),
            descriptors: DescriptorBroadcast::default(),
            alignments: AlignmentBroadcast::default(),
            journal: None,
            requests: RequestBook::new(),
            responses: Responses::default(),
            served: ServedPoses::default(),
        }
    }

    pub fn freeze(&self) -> CommsState {
        CommsState {
            sequence: self.door.sequence(),
            revision: self.objects.revision(),
            replay: self.door.replay().clone(),
            keyframes_held: self.requests.iter().map(|(r, q)| (*r, q.held().clone())).collect(),
            keyframes_sent: self.responses.sent().clone(),
            keyframes_told: self.served.told().clone(),
            status: self.status.clone(),
        }
    }

    /// Continues from `state`: revisions go on above the snapshot's; sequence numbers too when
    /// this start keeps the snapshot's incarnation (simulation), and otherwise start afresh in
    /// the new one (a ROS node: what it sent after the snapshot stays unique).
    pub fn thawed(mut self, state: CommsState) -> Self {
        self.door.thaw(state.sequence, state.replay);
        self.objects = std::mem::take(&mut self.objects).with_revision(state.revision);
        for (robot, held) in state.keyframes_held {
            self.requests.insert(robot, KeyframeRequests::with_held(held));
        }
        self.responses = Responses::with_sent(state.keyframes_sent);
        self.served = ServedPoses::with_told(state.keyframes_told);
        self.status = CommsStatus { links_down: Vec::new(), ..state.status };
        self
    }

    /// Without object data: the Scan Context baseline shares keyframe descriptors instead.
    pub fn without_object_data(mut self) -> Self {
        self.objects.disable();
        self
    }

    fn send(&mut self, to: Destination, message: WireMessage) {
        let kind = message.kind();
        match self.door.seal(to, message, &self.key, &self.config.limits) {
            Ok(bytes) => {
                self.status.sent.record(kind, bytes.len());
                self.transport.transmit(self.robot, to, bytes, self.clock.now());
            }
            Err(e) => tracing::warn!(robot = %self.robot, ?kind, "not sent: {e}"),
        }
    }

    fn try_broadcast(&mut self, now: Stamp) {
        if let Some(data) = self.objects.due(now, &self.config) {
            self.status.object_data_revision = self.objects.revision();
            self.send(Destination::Broadcast, WireMessage::ObjectData(data));
        }
        if let Some(alignments) = self.alignments.due(now, &self.config) {
            self.send(Destination::Broadcast, WireMessage::Alignments(alignments));
        }
    }

    fn broadcast_descriptors(&mut self, now: Stamp) {
        for message in self.descriptors.due(now, &self.config) {
            self.send(Destination::Broadcast, WireMessage::KeyframeDescriptors(message));
        }
    }

    /// Links lost now are reported to the Matcher.
    fn watch_links(&mut self, now: Stamp) {
        let requests = &self.requests;
        let lost = self.watch.lost(now, self.config.link_timeout_s, |r| requests.get(&r).and_then(|q| q.owed_since()));
        for robot in lost {
            tracing::info!(robot = %self.robot, neighbour = %robot, "link lost");
            self.status.link_losses += 1;
            if let Some(links) = &self.links {
                links.link.do_send(LinkChanged { robot, up: false });
            }
        }
        self.status.links_down = self.watch.down();
    }

    fn heard(&mut self, from: RobotId, now: Stamp) {
        let heard = self.watch.heard(from, now);
        if heard.first {
            if !self.status.neighbours.contains(&from) {
                self.status.neighbours.push(from);
                self.status.neighbours.sort();
            }
            self.objects.repeat();
            self.alignments.repeat();
        }
        if heard.back {
            tracing::info!(robot = %self.robot, neighbour = %from, "link back");
            self.status.links_down = self.watch.down();
            self.objects.repeat();
            self.alignments.repeat();
            if let Some(q) = self.requests.get_mut(&from) {
                q.link_back(now);
            }
            if let Some(links) = &self.links {
                links.link.do_send(LinkChanged { robot: from, up: true });
            }
        }
    }

    fn want_keyframes(&mut self, msg: RequestKeyframes) {
        let now = self.clock.now();
        let overflow = self.requests.entry(msg.robot).or_default().want(msg.keyframes, now, &self.config);
        if !overflow.is_empty() {
            self.status.keyframes_refused_locally += overflow.len() as u64;
            if let Some(links) = &self.links {
                let reason = KeyframeRefusalReason::Busy;
                links.unavailable.do_send(KeyframesUnavailable { robot: msg.robot, keyframes: overflow, reason });
            }
        }
    }

    fn flush_requests(&mut self, now: Stamp) {
        let robots: Vec<RobotId> = self.requests.keys().copied().collect();
        for robot in robots {
            let down = self.watch.is_down(robot);
            let heard_at = self.watch.last_heard(robot);
            let Some(q) = self.requests.get_mut(&robot) else { continue };
            let flush = q.flush(now, !down, heard_at, &self.config);
            if !down {
                self.status.max_keyframes_in_flight = self.status.max_keyframes_in_flight.max(flush.in_flight);
            }
            for keyframes in flush.requests {
                self.send(Destination::Robot(robot), WireMessage::KeyframeRequest(KeyframeRequest { keyframes }));
            }
            if !flush.given_up.is_empty() {
                self.status.keyframes_given_up += flush.given_up.len() as u64;
                if let Some(links) = &self.links {
                    links.unavailable.do_send(KeyframesUnavailable {
                        robot,
                        keyframes: flush.given_up,
                        reason: KeyframeRefusalReason::Busy,
                    });
                }
            }
        }
    }

    fn send_responses(&mut self) {
        for (out, twice) in self.responses.take(self.config.max_responses_per_tick) {
            if twice {
                self.status.keyframes_sent_twice += 1;
            }
            if let WireMessage::KeyframeResponse(r) = &out.message {
                if let Some(pose) = r.world_from_body.to_pose() {
                    self.served.served(out.to, r.keyframe, pose);
                }
            }
            self.send(Destination::Robot(out.to), out.message);
        }
    }

    /// Served keyframes our solves moved, told to the neighbours holding them.
    fn send_pose_updates(&mut self, now: Stamp) {
        // The map as last shared: its keyframe poses are what served keyframes are told.
        let Some(map) = self.objects.latest().cloned() else { return };
        let (watch, timeout) = (&self.watch, self.config.link_timeout_s);
        let heard = |r| !watch.is_down(r) && watch.last_heard(r).is_some_and(|t| now - t < timeout);
        let due = self.served.due(now, &map, &self.config.pose_updates, self.config.limits.max_ids, heard);
        for (robot, messages) in due {
            for message in messages {
                self.send(Destination::Robot(robot), WireMessage::KeyframePoses(message));
            }
        }
    }

    fn receive(&mut self, bytes: &[u8]) {
        let Some(admitted) = self.door.open(bytes, &self.key, &self.config.limits, &mut self.status.rejected) else {
            return;
        };
        if admitted.reservations_grew {
            if let Some(journal) = &self.journal {
                journal.write(self.door.replay().reservations());
            }
        }
        let from = admitted.from;
        if admitted.sender_restarted {
            self.served.retell(from);
        }
        self.status.received.record(admitted.message.kind(), bytes.len());
        self.heard(from, self.clock.now());
        let Some(links) = self.links.clone() else { return };
        match admitted.message {
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
            WireMessage::Alignments(m) => {
                let total = m.alignments.len();
                let alignments: Vec<_> = m
                    .alignments
                    .into_iter()
                    .filter(|a| a.robot != from)
                    .filter_map(|a| Some((a.robot, a.sender_from_robot.to_pose()?)))
                    .collect();
                self.status.rejected.malformed += (total - alignments.len()) as u64;
                if !alignments.is_empty() {
                    links.alignments.do_send(NeighbourAlignments { robot: from, alignments });
                }
            }
            WireMessage::KeyframePoses(m) => {
                let total = m.poses.len();
                let poses: Vec<_> = m.poses.iter().filter_map(|p| Some((p.keyframe, p.to_pose()?))).collect();
                self.status.rejected.malformed += (total - poses.len()) as u64;
                if !poses.is_empty() {
                    links.keyframe_poses.do_send(NeighbourKeyframePoses { robot: from, poses });
                }
            }
            WireMessage::GraphFactorRequest(r) => {
                links.graph.do_send(NeighbourGraph::Request { robot: from, from: r.from })
            }
            WireMessage::GraphFactors(m) => {
                let (slice, malformed) = m.to_slice();
                self.status.rejected.malformed += malformed as u64;
                links.graph.do_send(NeighbourGraph::Slice { robot: from, slice });
            }
            WireMessage::ObjectCloudRequest(r) => {
                links.serve.do_send(Serve::ObjectClouds { robot: from, objects: r.objects })
            }
            WireMessage::ObjectCloudResponse(r) => {
                links.object_clouds.do_send(NeighbourObjectClouds { robot: from, clouds: r.objects })
            }
            WireMessage::KeyframeRequest(r) => {
                if !self.responses.room_for(r.keyframes.len(), self.config.limits.max_ids) {
                    // Outgoing budget spent: say so instead of dropping.
                    let refusal = sgm_model::wire::messages::KeyframeRefusal {
                        keyframes: r.keyframes,
                        reason: KeyframeRefusalReason::Busy,
                    };
                    self.send(Destination::Robot(from), WireMessage::KeyframeRefusal(refusal));
                } else {
                    links.serve.do_send(Serve::Keyframes { robot: from, keyframes: r.keyframes });
                }
            }
            WireMessage::KeyframeResponse(r) => {
                let q = self.requests.entry(from).or_default();
                if q.response(r.keyframe) == ResponseFate::Duplicate {
                    return;
                }
                let pose = r.world_from_body.to_pose();
                let covariance = unpack_covariance(&r.covariance);
                let points = cloud_codec::decode_at_most(&r.cloud, self.config.limits.max_cloud_points);
                match (pose, covariance, points) {
                    (Some(world_from_body), Some(covariance), Ok(points_in_body)) => {
                        q.decoded(r.keyframe, true);
                        links.keyframes.do_send(NeighbourKeyframe {
                            robot: from,
                            id: r.keyframe,
                            world_from_body,
                            covariance,
                            points_in_body,
                            cloud_bytes: r.cloud.len() as u64,
                        })
                    }
                    _ => {
                        q.decoded(r.keyframe, false);
                        self.status.rejected.malformed += 1;
                        links.unavailable.do_send(KeyframesUnavailable {
                            robot: from,
                            keyframes: vec![r.keyframe],
                            reason: KeyframeRefusalReason::Unknown,
                        });
                    }
                }
            }
            // Busy: the keyframes stay in flight and their timeouts retry with back-off.
            WireMessage::KeyframeRefusal(r) if r.reason == KeyframeRefusalReason::Busy => {}
            WireMessage::KeyframeRefusal(r) => {
                self.requests.entry(from).or_default().refused(&r.keyframes);
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

impl Handler<MapChanged> for Comms {
    type Result = ();
    fn handle(&mut self, msg: MapChanged, ctx: &mut Context<Self>) {
        contained(ctx, "comms", || {
            self.objects.objects(msg.0, self.config.significant_move_m);
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

impl Handler<ShareAlignments> for Comms {
    type Result = ();
    fn handle(&mut self, msg: ShareAlignments, ctx: &mut Context<Self>) {
        contained(ctx, "comms", || {
            self.alignments.alignments(msg.0);
            self.try_broadcast(self.clock.now());
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
                q.released(&msg.keyframes);
            }
        });
    }
}

impl Handler<Outgoing> for Comms {
    type Result = ();
    fn handle(&mut self, msg: Outgoing, ctx: &mut Context<Self>) {
        contained(ctx, "comms", || match msg.message {
            WireMessage::KeyframeResponse(_) => self.responses.push(msg),
            message => self.send(Destination::Robot(msg.to), message),
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
            self.send_pose_updates(msg.now);
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
        msg.0.write(self.door.replay().reservations());
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
