//! The ROS transport: `Comms`'s sealed envelopes over ROS 1, so robots in different processes
//! (or machines) cooperate through one master. Broadcasts (object data) go on the team topic
//! (`sgm_msgs/Envelope`); envelopes addressed to one robot (requests and replies) go to that
//! robot's `sgm_msgs/Deliver` service, read within bounds at both ends (`bounded_deliver`).
//! Sending runs on a worker thread behind a bounded queue: `Comms` never waits on the network,
//! and a full queue drops (counted) instead of growing. The payload is the wire protocol's,
//! MAC included: ROS adds transport, not trust.

use crate::bounded_deliver::{BoundedDeliver, BoundedDeliverReq};
use crate::config::RosConfig;
use crate::msg::sgm_msgs;
use sgm_actors::transport::Transport;
use sgm_model::scene_graph::{RobotId, Stamp};
use sgm_model::wire::Destination;
use std::collections::BTreeMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{sync_channel, SyncSender, TrySendError};
use std::sync::Arc;

/// Envelopes waiting to be sent; more are dropped.
const SEND_QUEUE: usize = 256;

/// What the transport did, for the status topic.
#[derive(Debug, Default)]
pub struct TransportCounts {
    pub sent: AtomicU64,
    pub send_failed: AtomicU64,
    pub queue_full: AtomicU64,
    pub received: AtomicU64,
}

impl TransportCounts {
    pub fn snapshot(&self) -> serde_json::Value {
        serde_json::json!({
            "sent": self.sent.load(Ordering::Relaxed),
            "send_failed": self.send_failed.load(Ordering::Relaxed),
            "queue_full": self.queue_full.load(Ordering::Relaxed),
            "received": self.received.load(Ordering::Relaxed),
            "refused": crate::bounded_deliver::refused_requests(),
        })
    }
}

pub struct RosTransport {
    queue: SyncSender<(Destination, Vec<u8>)>,
    counts: Arc<TransportCounts>,
}

impl RosTransport {
    /// Advertises the team topic and starts the sending thread.
    pub fn start(ros: &RosConfig, robot: RobotId, counts: Arc<TransportCounts>) -> Result<Self, rosrust::error::Error> {
        let team = rosrust::publish::<sgm_msgs::Envelope>(&ros.topics.team, ros.queue_size.max(64))?;
        let deliver_template = ros.topics.deliver.clone();
        let (queue, incoming) = sync_channel::<(Destination, Vec<u8>)>(SEND_QUEUE);
        let worker_counts = counts.clone();
        std::thread::spawn(move || {
            let mut clients: BTreeMap<u16, rosrust::Client<BoundedDeliver>> = BTreeMap::new();
            for (to, data) in incoming {
                let ok = match to {
                    Destination::Robot(r) => {
                        let name = RosConfig::resolve(&deliver_template, "", r.0);
                        let client = match clients.get(&r.0) {
                            Some(c) => Ok(c.clone()),
                            None => rosrust::client::<BoundedDeliver>(&name).inspect(|c| {
                                clients.insert(r.0, c.clone());
                            }),
                        };
                        let request = BoundedDeliverReq(sgm_msgs::DeliverReq { from_robot: robot.0, data });
                        match client.map_err(|e| e.to_string()).map(|c| c.req(&request).map_err(|e| e.to_string())) {
                            Ok(Ok(Ok(_))) => true,
                            Ok(Ok(Err(refusal))) => {
                                tracing::warn!(to = r.0, "delivery refused by the peer: {refusal}");
                                false
                            }
                            Ok(Err(e)) | Err(e) => {
                                // The peer may not be up (yet): its service is looked up anew next time.
                                clients.remove(&r.0);
                                tracing::debug!(to = r.0, "delivery failed: {e}");
                                false
                            }
                        }
                    }
                    Destination::Broadcast => team.send(sgm_msgs::Envelope { from_robot: robot.0, data }).is_ok(),
                };
                let counter = if ok { &worker_counts.sent } else { &worker_counts.send_failed };
                counter.fetch_add(1, Ordering::Relaxed);
            }
        });
        Ok(Self { queue, counts })
    }
}

impl Transport for RosTransport {
    fn transmit(&self, _from: RobotId, to: Destination, bytes: Vec<u8>, _now: Stamp) {
        if let Err(TrySendError::Full(_) | TrySendError::Disconnected(_)) = self.queue.try_send((to, bytes)) {
            self.counts.queue_full.fetch_add(1, Ordering::Relaxed);
        }
    }
}
