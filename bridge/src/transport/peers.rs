//! Envelopes addressed to one robot: a [`PeerLink`] and a worker thread per peer, so a call that
//! hangs or fails holds up that peer's queue only. The worker looks the peer's Deliver service up
//! at the master (cached until a call fails), calls it within `ros.peers.call_timeout_s`
//! ([`super::call`]), and follows the link's back-off while the peer does not answer.

use super::delivery::{call, lock, Peer, Shared};
pub use super::locator::{Locator, LocatorError, MasterLocator};
use super::peer::{LinkState, Next, PeerCounts, PeerLink};
use crate::config::PeerConfig;
use crate::msg::sgm_msgs;
use serde::Serialize;
use sgm_model::scene_graph::RobotId;
use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex, PoisonError};
use std::time::Instant;

/// A peer's state for the status topic.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PeerStatus {
    /// `up` or `down`.
    pub state: &'static str,
    /// Since when the peer has been down, s of wall time ago.
    pub down_for_s: Option<f64>,
    pub queued: usize,
    #[serde(flatten)]
    pub counts: PeerCounts,
}

/// Every peer's queue and worker.
pub struct Peers {
    shared: Arc<Shared>,
    peers: Mutex<BTreeMap<u16, Arc<Peer>>>,
}

impl Peers {
    pub fn new(
        config: PeerConfig,
        robot: RobotId,
        caller_id: String,
        deliver_template: String,
        max_reply: usize,
        locator: Arc<dyn Locator>,
    ) -> Self {
        let shared = Shared {
            config,
            robot,
            caller_id,
            deliver_template,
            max_reply,
            locator,
            stop: AtomicBool::new(false),
            origin: Instant::now(),
        };
        Self { shared: Arc::new(shared), peers: Mutex::new(BTreeMap::new()) }
    }

    /// Queues `envelope` for `to`; its worker starts with its first envelope. Never waits on
    /// the network.
    pub fn send(&self, to: RobotId, envelope: Vec<u8>) {
        let peer = {
            let mut peers = lock(&self.peers);
            match peers.get(&to.0) {
                Some(peer) => peer.clone(),
                None => {
                    let peer = Arc::new(Peer {
                        link: Mutex::new(PeerLink::new(self.shared.config.clone())),
                        wake: Condvar::new(),
                        uri: Mutex::new(None),
                        lookup: Mutex::new(None),
                    });
                    let (shared, worker) = (self.shared.clone(), peer.clone());
                    let spawned = std::thread::Builder::new()
                        .name(format!("sgm-peer-{}", to.0))
                        .spawn(move || run(&shared, to, &worker));
                    if let Err(e) = spawned {
                        tracing::error!(peer = to.0, "no worker thread for the peer: {e}");
                    }
                    peers.insert(to.0, peer.clone());
                    peer
                }
            }
        };
        lock(&peer.link).push(envelope);
        peer.wake.notify_one();
    }

    /// An envelope arrived claiming to be from `from`: if its link is down, probe it now (the
    /// claim is not authenticated; a false one costs one probe).
    pub fn heard(&self, from: RobotId) {
        let peer = lock(&self.peers).get(&from.0).cloned();
        if let Some(peer) = peer {
            lock(&peer.link).heard(self.shared.origin.elapsed());
            peer.wake.notify_one();
        }
    }

    /// Every peer's link, by robot id.
    pub fn status(&self) -> BTreeMap<u16, PeerStatus> {
        let now = self.shared.origin.elapsed();
        lock(&self.peers)
            .iter()
            .map(|(id, peer)| {
                let link = lock(&peer.link);
                let (state, down_for_s) = match link.state() {
                    LinkState::Up => ("up", None),
                    LinkState::Down { since, .. } => ("down", Some(now.saturating_sub(since).as_secs_f64())),
                };
                (*id, PeerStatus { state, down_for_s, queued: link.queued(), counts: link.counts.clone() })
            })
            .collect()
    }

    /// Totals over every peer.
    pub fn totals(&self) -> PeerCounts {
        lock(&self.peers).values().fold(PeerCounts::default(), |mut t, peer| {
            let c = &lock(&peer.link).counts;
            t.sent += c.sent;
            t.failed += c.failed;
            t.dropped += c.dropped;
            t.downs += c.downs;
            t.probes += c.probes;
            t
        })
    }
}

impl Drop for Peers {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::Relaxed);
        for peer in lock(&self.peers).values() {
            peer.wake.notify_all();
        }
    }
}

/// The worker of peer `to`: takes the link's next step until the transport is dropped.
fn run(shared: &Shared, to: RobotId, peer: &Peer) {
    let service = crate::config::RosConfig::resolve(&shared.deliver_template, "", to.0);
    loop {
        let envelope = {
            let mut link = lock(&peer.link);
            loop {
                if shared.stop.load(Ordering::Relaxed) {
                    return;
                }
                match link.next(shared.origin.elapsed()) {
                    Next::Send(envelope) => break envelope,
                    Next::Wait(d) => link = peer.wake.wait_timeout(link, d).unwrap_or_else(PoisonError::into_inner).0,
                    Next::Idle => link = peer.wake.wait(link).unwrap_or_else(PoisonError::into_inner),
                }
            }
        };
        let request = sgm_msgs::DeliverReq { from_robot: shared.robot.0, data: envelope };
        let outcome = call(shared, peer, &service, &request);
        let mut link = lock(&peer.link);
        let was = link.state();
        match outcome {
            Ok(res) => {
                if !res.accepted {
                    tracing::warn!(peer = to.0, "delivery refused by the peer: {}", res.reason);
                }
                link.succeeded();
                if was != LinkState::Up {
                    tracing::info!(peer = to.0, %service, "peer answers again");
                }
            }
            Err(e) => {
                *lock(&peer.uri) = None;
                link.failed(request.data, shared.origin.elapsed());
                if was == LinkState::Up {
                    tracing::warn!(peer = to.0, %service, "peer not answering ({e}); its envelopes wait, probed with back-off");
                } else {
                    tracing::debug!(peer = to.0, %service, "probe failed: {e}");
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::msg::sgm_msgs;
    use rosrust::RosMsg;
    use std::io::{Read, Write};
    use std::net::{SocketAddr, TcpListener, TcpStream};
    use std::time::Duration;

    /// Services by name; a name missing is "no such service", a name mapped to `None` makes the
    /// lookup hang (a master that does not answer).
    struct Table(Mutex<BTreeMap<String, Option<String>>>);

    impl Locator for Table {
        fn lookup(&self, service: &str) -> Result<String, LocatorError> {
            let entry = lock(&self.0).get(service).cloned();
            let unknown = |reason: String| LocatorError::Lookup {
                service: service.into(),
                source: rosrust::error::ResponseError::Server(reason),
            };
            match entry {
                Some(Some(uri)) => Ok(uri),
                Some(None) => {
                    std::thread::sleep(Duration::from_secs(3600));
                    Err(unknown("never".into()))
                }
                None => Err(unknown(format!("no provider for {service}"))),
            }
        }
    }

    /// A Deliver service that answers every call, recording what it got.
    fn answering() -> (SocketAddr, Arc<Mutex<Vec<Vec<u8>>>>) {
        let listener = TcpListener::bind("127.0.0.1:0").expect("a port");
        let address = listener.local_addr().expect("an address");
        let got = Arc::new(Mutex::new(Vec::new()));
        let sink = got.clone();
        std::thread::spawn(move || {
            for stream in listener.incoming() {
                let Ok(mut stream) = stream else { continue };
                let sink = sink.clone();
                std::thread::spawn(move || {
                    let read = |s: &mut TcpStream| -> Option<Vec<u8>> {
                        let mut len = [0u8; 4];
                        s.read_exact(&mut len).ok()?;
                        let mut body = vec![0u8; u32::from_le_bytes(len) as usize];
                        s.read_exact(&mut body).ok()?;
                        Some(body)
                    };
                    let (Some(_header), Some(body)) = (read(&mut stream), read(&mut stream)) else { return };
                    let Ok(req) = sgm_msgs::DeliverReq::decode(&body[..]) else { return };
                    lock(&sink).push(req.data);
                    let mut res = Vec::new();
                    sgm_msgs::DeliverRes { accepted: true, reason: String::new() }.encode(&mut res).expect("ok");
                    let mut bytes = super::super::call::encode_header(&[("callerid", "/peer")]);
                    bytes.push(1);
                    bytes.extend_from_slice(&(res.len() as u32).to_le_bytes());
                    bytes.extend_from_slice(&res);
                    let _ = stream.write_all(&bytes);
                });
            }
        });
        (address, got)
    }

    /// A Deliver service that accepts connections and never answers.
    fn silent() -> SocketAddr {
        let listener = TcpListener::bind("127.0.0.1:0").expect("a port");
        let address = listener.local_addr().expect("an address");
        std::thread::spawn(move || {
            let mut held = Vec::new();
            for stream in listener.incoming() {
                held.push(stream);
            }
        });
        address
    }

    fn wait_for(what: &str, mut done: impl FnMut() -> bool) {
        let deadline = Instant::now() + Duration::from_secs(20);
        while !done() {
            assert!(Instant::now() < deadline, "timed out waiting for {what}");
            std::thread::sleep(Duration::from_millis(10));
        }
    }

    #[test]
    fn a_peer_that_never_answers_or_is_gone_holds_up_nobody_else() {
        let (good, got) = answering();
        let hung = silent();
        let gone = TcpListener::bind("127.0.0.1:0").and_then(|l| l.local_addr()).expect("a port");
        let table = Table(Mutex::new(BTreeMap::from([
            ("/sgm/robot_2/deliver".to_string(), Some(format!("rosrpc://{good}"))),
            ("/sgm/robot_3/deliver".to_string(), Some(format!("rosrpc://{hung}"))),
            ("/sgm/robot_4/deliver".to_string(), Some(format!("rosrpc://{gone}"))),
            ("/sgm/robot_6/deliver".to_string(), None),
        ])));
        let config = PeerConfig { queue: 16, call_timeout_s: 30.0, backoff_initial_s: 30.0, backoff_max_s: 30.0 };
        let peers = Peers::new(
            config,
            RobotId(1),
            "/sgm_alpha".into(),
            "/sgm/robot_{id}/deliver".into(),
            1024,
            Arc::new(table),
        );
        // The silent, gone, unknown and unlocatable peers first, many envelopes each...
        for k in 0..40u8 {
            for to in [3u8, 4, 5, 6] {
                peers.send(RobotId(u16::from(to)), vec![to, k]);
            }
        }
        // ...then the one that answers: it gets all of its own, in order, while robot 3's first
        // call (30 s timeout) and robot 6's lookup still hang.
        for k in 0..10u8 {
            peers.send(RobotId(2), vec![2, k]);
        }
        wait_for("robot 2's envelopes", || lock(&got).len() == 10);
        assert_eq!(*lock(&got), (0..10u8).map(|k| vec![2, k]).collect::<Vec<_>>());
        let status = peers.status();
        assert_eq!((status[&2].state, status[&2].counts.sent), ("up", 10));
        wait_for("robots 4 and 5 marked down", || {
            let s = peers.status();
            s[&4].state == "down" && s[&5].state == "down"
        });
        let status = peers.status();
        assert_eq!(status[&3].state, "up", "still in its first call");
        // Bounded queues: 40 sent to each, 16 kept (the one in the call aside).
        assert_eq!(status[&4].queued, 16);
        assert_eq!(status[&4].counts.dropped, 24);
    }

    #[test]
    fn a_peer_that_comes_back_gets_what_waited_for_it() {
        let gone = TcpListener::bind("127.0.0.1:0").and_then(|l| l.local_addr()).expect("a port");
        let table = Arc::new(Table(Mutex::new(BTreeMap::from([(
            "/sgm/robot_2/deliver".to_string(),
            Some(format!("rosrpc://{gone}")),
        )]))));
        let config = PeerConfig { queue: 16, call_timeout_s: 2.0, backoff_initial_s: 0.05, backoff_max_s: 0.2 };
        let peers = Peers::new(config, RobotId(1), "/a".into(), "/sgm/robot_{id}/deliver".into(), 1024, table.clone());
        for k in 0..5u8 {
            peers.send(RobotId(2), vec![k]);
        }
        wait_for("the peer down and probed", || peers.status()[&2].counts.probes >= 2);
        // It restarts elsewhere (a new port, registered anew at the master).
        let (good, got) = answering();
        lock(&table.0).insert("/sgm/robot_2/deliver".into(), Some(format!("rosrpc://{good}")));
        wait_for("every envelope delivered", || lock(&got).len() == 5);
        assert_eq!(*lock(&got), (0..5u8).map(|k| vec![k]).collect::<Vec<_>>(), "in order, none lost");
        let status = peers.status();
        assert_eq!((status[&2].state, status[&2].queued, status[&2].counts.downs), ("up", 0, 1));
    }
}
