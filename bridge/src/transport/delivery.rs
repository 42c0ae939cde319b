//! One delivery to a peer, as its worker makes it: where the peer's Deliver service is (cached
//! until a call there fails; a lookup at the master bounded in time, and one at most running per
//! peer), and the call ([`super::call`]), lookup and delivery within `ros.peers.call_timeout_s`.
//! With the state a worker works on: the peer's ([`Peer`]) and all workers' ([`Shared`]).

use super::call::{deliver, service_address, CallError, CallTarget};
use super::locator::{Locator, LocatorError};
use super::peer::PeerLink;
use crate::config::PeerConfig;
use crate::msg::sgm_msgs;
use sgm_model::scene_graph::RobotId;
use std::sync::atomic::AtomicBool;
use std::sync::mpsc::{self, Receiver, RecvTimeoutError};
use std::sync::{Arc, Condvar, Mutex, MutexGuard, PoisonError};
use std::time::{Duration, Instant};

/// One peer as its worker and the status see it.
pub(super) struct Peer {
    pub(super) link: Mutex<PeerLink>,
    pub(super) wake: Condvar,
    /// Where its service was found, until a call there fails.
    pub(super) uri: Mutex<Option<String>>,
    /// A lookup still running (the master did not answer in time): its answer is taken before
    /// another lookup starts, so a silent master costs one thread per peer at most.
    pub(super) lookup: Mutex<Option<Receiver<Result<String, LocatorError>>>>,
}

pub(super) fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

/// What the workers share.
pub(super) struct Shared {
    pub(super) config: PeerConfig,
    pub(super) robot: RobotId,
    pub(super) caller_id: String,
    /// `ros.topics.deliver` with `{id}`.
    pub(super) deliver_template: String,
    pub(super) max_reply: usize,
    pub(super) locator: Arc<dyn Locator>,
    pub(super) stop: AtomicBool,
    pub(super) origin: Instant,
}

/// Where the peer's service is: the cached address, or a lookup bounded by `timeout`.
fn locate(shared: &Shared, peer: &Peer, service: &str, timeout: Duration) -> Result<String, CallError> {
    if let Some(uri) = lock(&peer.uri).clone() {
        return Ok(uri);
    }
    let mut pending = lock(&peer.lookup);
    let receiver = match pending.take() {
        Some(receiver) => receiver,
        None => {
            let (tx, rx) = mpsc::channel();
            let (locator, name) = (shared.locator.clone(), service.to_string());
            std::thread::Builder::new()
                .name("sgm-lookup".into())
                .spawn(move || {
                    let _ = tx.send(locator.lookup(&name));
                })
                .map_err(CallError::Io)?;
            rx
        }
    };
    match receiver.recv_timeout(timeout) {
        Ok(Ok(uri)) => {
            *lock(&peer.uri) = Some(uri.clone());
            Ok(uri)
        }
        Ok(Err(e)) => Err(CallError::Lookup(e)),
        Err(RecvTimeoutError::Timeout) => {
            *pending = Some(receiver);
            Err(CallError::Timeout(timeout))
        }
        Err(RecvTimeoutError::Disconnected) => Err(CallError::Refused("the lookup thread ended".into())),
    }
}

/// One bounded call: lookup (if needed) and delivery share `ros.peers.call_timeout_s`.
pub(super) fn call(
    shared: &Shared,
    peer: &Peer,
    service: &str,
    request: &sgm_msgs::DeliverReq,
) -> Result<sgm_msgs::DeliverRes, CallError> {
    let timeout = shared.config.call_timeout();
    let started = Instant::now();
    let uri = locate(shared, peer, service, timeout)?;
    let left = timeout.saturating_sub(started.elapsed());
    if left.is_zero() {
        return Err(CallError::Timeout(timeout));
    }
    let target = CallTarget {
        address: service_address(&uri)?,
        service,
        caller_id: &shared.caller_id,
        timeout: left,
        max_reply: shared.max_reply,
    };
    deliver(&target, request)
}
