//! How sealed envelopes travel between robots. `Comms` talks to a [`Transport`]; this file has
//! the in-process one (many robots in one process, scenarios and tests) with a [`RadioModel`]
//! hook deciding, per packet and destination, whether and when it arrives. The ROS transport
//! lives in the bridge crate.
//!
//! Delivery is deterministic even when the robots run on threads of their own: what robots
//! transmit waits in an outbox per sender until the owner of the clock calls
//! [`InProcessRadio::flush`] (or delivers), which hands it to the [`RadioModel`] in a fixed
//! order — by sender, then in each sender's own order — however the threads interleaved. The
//! packets then wait in a queue ordered by (arrival time, that order) and are handed over when
//! the owner of the clock calls [`InProcessRadio::deliver_due`] or [`InProcessRadio::take_due`].

use actix::{Message, Recipient};
use sgm_model::scene_graph::{RobotId, Stamp};
use sgm_model::wire::Destination;
use std::collections::BTreeMap;
use std::sync::{Arc, Mutex, PoisonError};

/// A sealed envelope arriving at a robot.
#[derive(Message, Clone, Debug)]
#[rtype(result = "()")]
pub struct Delivered {
    pub bytes: Vec<u8>,
}

/// What `Comms` needs from a link layer.
pub trait Transport: Send {
    /// Hands `bytes` to the link; `now` is the sender's clock.
    fn transmit(&self, from: RobotId, to: Destination, bytes: Vec<u8>, now: Stamp);
}

/// The radio's physics: whether, when and how often a packet of `bytes` from `from` reaches `to`.
pub trait RadioModel: Send {
    /// Arrival times: none if lost, one normally, more if the medium duplicated the packet.
    fn arrivals(&mut self, from: RobotId, to: RobotId, bytes: usize, now: Stamp) -> Vec<Stamp>;
}

/// Every packet arrives at once.
#[derive(Clone, Copy, Debug, Default)]
pub struct PerfectLinks;

impl RadioModel for PerfectLinks {
    fn arrivals(&mut self, _: RobotId, _: RobotId, _: usize, now: Stamp) -> Vec<Stamp> {
        vec![now]
    }
}

/// A packet handed to the link and not yet to the radio's model.
struct Outgoing {
    to: Destination,
    bytes: Vec<u8>,
    now: Stamp,
}

struct Medium {
    endpoints: BTreeMap<RobotId, Recipient<Delivered>>,
    /// Per sender, in its send order: what was transmitted since the last flush.
    outbox: BTreeMap<RobotId, Vec<Outgoing>>,
    queue: BTreeMap<(u64, u64), (RobotId, Vec<u8>)>,
    sent: u64,
    model: Box<dyn RadioModel>,
}

/// The shared in-process medium. Clones share it.
#[derive(Clone)]
pub struct InProcessRadio {
    medium: Arc<Mutex<Medium>>,
}

impl InProcessRadio {
    pub fn new(model: Box<dyn RadioModel>) -> Self {
        Self {
            medium: Arc::new(Mutex::new(Medium {
                endpoints: BTreeMap::new(),
                outbox: BTreeMap::new(),
                queue: BTreeMap::new(),
                sent: 0,
                model,
            })),
        }
    }

    fn medium(&self) -> std::sync::MutexGuard<'_, Medium> {
        // A panic elsewhere cannot leave the queue half-updated: every update is one insert/remove.
        self.medium.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Registers the robot's receiving end (its Comms).
    pub fn attach(&self, robot: RobotId, endpoint: Recipient<Delivered>) {
        self.medium().endpoints.insert(robot, endpoint);
    }

    /// Forgets the robot's receiving end (it went down): packets for it are dropped on arrival
    /// until it attaches again.
    pub fn detach(&self, robot: RobotId) {
        self.medium().endpoints.remove(&robot);
    }

    /// Hands what was transmitted since the last flush to the radio's model, by sender and then
    /// in each sender's order, so that the model's draws and the queue's order do not depend on
    /// how the senders' threads interleaved. Call it only when no robot is running (between
    /// steps).
    pub fn flush(&self) {
        let mut medium = self.medium();
        let outbox = std::mem::take(&mut medium.outbox);
        for (from, packets) in outbox {
            for packet in packets {
                medium.enqueue(from, packet);
            }
        }
    }

    /// Hands every packet due by `now` to its destination; returns how many.
    pub fn deliver_due(&self, now: Stamp) -> usize {
        let due = self.take_due(now);
        let medium = self.medium();
        let mut delivered = 0;
        for (to, packet) in due {
            if let Some(endpoint) = medium.endpoints.get(&to) {
                endpoint.do_send(packet);
                delivered += 1;
            }
        }
        delivered
    }

    /// Takes every packet due by `now` whose destination is attached, in arrival order, for the
    /// caller to hand over (packets for a robot that is down are dropped). Flushes first.
    pub fn take_due(&self, now: Stamp) -> Vec<(RobotId, Delivered)> {
        self.flush();
        let mut medium = self.medium();
        let mut due = Vec::new();
        while let Some(entry) = medium.queue.first_entry() {
            if f64::from_bits(entry.key().0) > now {
                break;
            }
            let (to, bytes) = entry.remove();
            if medium.endpoints.contains_key(&to) {
                due.push((to, Delivered { bytes }));
            }
        }
        due
    }

    /// Packets still travelling (flushes first).
    pub fn in_flight(&self) -> usize {
        self.flush();
        self.medium().queue.len()
    }

    /// The earliest pending arrival, if any (flushes first).
    pub fn next_arrival(&self) -> Option<Stamp> {
        self.flush();
        self.medium().queue.keys().next().map(|k| f64::from_bits(k.0))
    }
}

impl Medium {
    /// Asks the model when `packet` from `from` reaches each attached robot it is for, and queues
    /// it for each arrival.
    fn enqueue(&mut self, from: RobotId, packet: Outgoing) {
        let Outgoing { to, bytes, now } = packet;
        let targets: Vec<RobotId> = self.endpoints.keys().copied().filter(|r| *r != from && to.includes(*r)).collect();
        for target in targets {
            for at in self.model.arrivals(from, target, bytes.len(), now) {
                // Non-negative finite times order like their bit patterns.
                let at = if at.is_finite() { at.max(now).max(0.0) } else { continue };
                self.sent += 1;
                let key = (at.to_bits(), self.sent);
                self.queue.insert(key, (target, bytes.clone()));
            }
        }
    }
}

impl Transport for InProcessRadio {
    fn transmit(&self, from: RobotId, to: Destination, bytes: Vec<u8>, now: Stamp) {
        self.medium().outbox.entry(from).or_default().push(Outgoing { to, bytes, now });
    }
}
