//! How sealed envelopes travel between robots. `Comms` talks to a [`Transport`]; this file has
//! the in-process one (many robots in one process, scenarios and tests) with a [`RadioModel`]
//! hook deciding, per packet and destination, whether and when it arrives. The ROS transport
//! lives in the bridge crate.
//!
//! Delivery is deterministic: packets wait in a queue ordered by (arrival time, send order) and
//! are handed over when the owner of the clock calls [`InProcessRadio::deliver_due`].

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

struct Medium {
    endpoints: BTreeMap<RobotId, Recipient<Delivered>>,
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
            medium: Arc::new(Mutex::new(Medium { endpoints: BTreeMap::new(), queue: BTreeMap::new(), sent: 0, model })),
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

    /// Hands every packet due by `now` to its destination; returns how many.
    pub fn deliver_due(&self, now: Stamp) -> usize {
        let mut medium = self.medium();
        let mut delivered = 0;
        while let Some(entry) = medium.queue.first_entry() {
            if f64::from_bits(entry.key().0) > now {
                break;
            }
            let (to, bytes) = entry.remove();
            if let Some(endpoint) = medium.endpoints.get(&to) {
                endpoint.do_send(Delivered { bytes });
                delivered += 1;
            }
        }
        delivered
    }

    /// Packets still travelling.
    pub fn in_flight(&self) -> usize {
        self.medium().queue.len()
    }

    /// The earliest pending arrival, if any.
    pub fn next_arrival(&self) -> Option<Stamp> {
        self.medium().queue.keys().next().map(|k| f64::from_bits(k.0))
    }
}

impl Transport for InProcessRadio {
    fn transmit(&self, from: RobotId, to: Destination, bytes: Vec<u8>, now: Stamp) {
        let mut medium = self.medium();
        let targets: Vec<RobotId> =
            medium.endpoints.keys().copied().filter(|r| *r != from && to.includes(*r)).collect();
        for target in targets {
            for at in medium.model.arrivals(from, target, bytes.len(), now) {
                // Non-negative finite times order like their bit patterns.
                let at = if at.is_finite() { at.max(now).max(0.0) } else { continue };
                medium.sent += 1;
                let key = (at.to_bits(), medium.sent);
                medium.queue.insert(key, (target, bytes.clone()));
            }
        }
    }
}
