//! The ROS transport: `Comms`'s sealed envelopes over ROS 1, so robots in different processes
//! (or machines) cooperate through one master. Broadcasts (object data) go on the team topic
//! (`sgm_msgs/Envelope`): rosrust's publisher queues them and never waits on a subscriber.
//! Envelopes addressed to one robot (requests and replies) go to that robot's `sgm_msgs/Deliver`
//! service through its own queue and worker ([`peers`]): every call is bounded in time
//! ([`call`]), a peer that does not answer is marked down and probed with back-off
//! ([`peer`]), and no peer — crashed, out of range or hostile — delays another's traffic or a
//! broadcast. `Comms` never waits on the network. The payload is the wire protocol's, MAC
//! included: ROS adds transport, not trust.

pub mod call;
mod delivery;
pub mod locator;
pub mod peer;
pub mod peers;

use crate::config::RosConfig;
use crate::msg::sgm_msgs;
use peers::{Locator, Peers};
use sgm_actors::transport::Transport;
use sgm_model::scene_graph::{RobotId, Stamp};
use sgm_model::wire::Destination;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

/// What the transport did, for the status topic.
#[derive(Debug, Default)]
pub struct TransportCounts {
    /// Broadcasts handed to the team topic.
    pub broadcast: AtomicU64,
    /// Broadcasts the team topic's publisher did not take.
    pub broadcast_failed: AtomicU64,
    pub received: AtomicU64,
}

pub struct RosTransport {
    robot: RobotId,
    team: rosrust::Publisher<sgm_msgs::Envelope>,
    peers: Arc<Peers>,
    counts: Arc<TransportCounts>,
}

impl RosTransport {
    /// Advertises the team topic; peers' workers start with their first envelope. `locator`
    /// finds peers' Deliver services (the node's master: [`peers::MasterLocator`]).
    pub fn start(
        ros: &RosConfig,
        robot: RobotId,
        counts: Arc<TransportCounts>,
        locator: Arc<dyn Locator>,
    ) -> Result<Self, rosrust::error::Error> {
        let team = rosrust::publish::<sgm_msgs::Envelope>(&ros.topics.team, ros.queue_size.max(64))?;
        let peers = Arc::new(Peers::new(
            ros.peers.clone(),
            robot,
            rosrust::name(),
            ros.topics.deliver.clone(),
            ros.max_message_bytes,
            locator,
        ));
        Ok(Self { robot, team, peers, counts })
    }

    /// The peers' queues and links, shared with the status.
    pub fn peers(&self) -> Arc<Peers> {
        self.peers.clone()
    }
}

/// The transport's part of the status: totals, and each peer's link.
pub fn status(counts: &TransportCounts, peers: &Peers) -> serde_json::Value {
    let totals = peers.totals();
    serde_json::json!({
        "sent": counts.broadcast.load(Ordering::Relaxed) + totals.sent,
        "send_failed": counts.broadcast_failed.load(Ordering::Relaxed) + totals.failed,
        "queue_full": totals.dropped,
        "received": counts.received.load(Ordering::Relaxed),
        "refused": crate::bounded_deliver::refused_requests(),
        "peers": peers.status(),
    })
}

impl Transport for RosTransport {
    fn transmit(&self, _from: RobotId, to: Destination, bytes: Vec<u8>, _now: Stamp) {
        match to {
            Destination::Robot(peer) => self.peers.send(peer, bytes),
            Destination::Broadcast => {
                let sent = self.team.send(sgm_msgs::Envelope { from_robot: self.robot.0, data: bytes });
                let counter = if sent.is_ok() { &self.counts.broadcast } else { &self.counts.broadcast_failed };
                counter.fetch_add(1, Ordering::Relaxed);
            }
        }
    }
}
