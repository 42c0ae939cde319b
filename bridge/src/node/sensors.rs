//! The node's sensor side: every input topic subscribed, each message checked by [`Inputs`],
//! counted (accepted, refused and why), and fed to the synchroniser, whose frames go to the
//! robot.

use super::error::{ros_error, NodeError};
use crate::bounded::{Bounded, Layout};
use crate::convert::time::Epoch;
use crate::error::InputError;
use crate::inputs::{Inputs, Payload};
use crate::persist::Intake;
use crate::sync::Synchroniser;
use std::collections::BTreeMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError};

/// Per input topic: messages accepted and refused, and why the latest was refused.
#[derive(Default)]
pub(super) struct InputCounts {
    pub(super) accepted: BTreeMap<&'static str, AtomicU64>,
    pub(super) refused: BTreeMap<&'static str, AtomicU64>,
    last_refusal: Mutex<BTreeMap<&'static str, String>>,
}

impl InputCounts {
    pub(super) fn new(topics: &[&'static str]) -> Self {
        Self {
            accepted: topics.iter().map(|t| (*t, AtomicU64::new(0))).collect(),
            refused: topics.iter().map(|t| (*t, AtomicU64::new(0))).collect(),
            last_refusal: Mutex::default(),
        }
    }

    /// The health checks' view.
    pub(super) fn tallies(&self) -> BTreeMap<String, crate::health::TopicTally> {
        let last = self.last_refusal.lock().unwrap_or_else(PoisonError::into_inner);
        self.accepted
            .iter()
            .map(|(topic, accepted)| {
                let tally = crate::health::TopicTally {
                    accepted: accepted.load(Ordering::Relaxed),
                    refused: self.refused.get(topic).map_or(0, |r| r.load(Ordering::Relaxed)),
                    last_refusal: last.get(topic).cloned(),
                };
                (topic.to_string(), tally)
            })
            .collect()
    }

    fn count<T>(&self, topic: &'static str, result: Result<T, InputError>) -> Option<T> {
        let (map, value) = match result {
            Ok(v) => (&self.accepted, Some(v)),
            Err(e) => {
                tracing::warn!(topic, "message refused: {e}");
                self.last_refusal.lock().unwrap_or_else(PoisonError::into_inner).insert(topic, e.to_string());
                (&self.refused, None)
            }
        };
        if let Some(c) = map.get(topic) {
            c.fetch_add(1, Ordering::Relaxed);
        }
        value
    }

    pub(super) fn snapshot(map: &BTreeMap<&'static str, AtomicU64>) -> serde_json::Value {
        map.iter().map(|(k, v)| (k.to_string(), serde_json::json!(v.load(Ordering::Relaxed)))).collect()
    }
}

/// What the sensor callbacks share.
pub(super) struct SensorSide {
    pub(super) sync: Mutex<Synchroniser>,
    pub(super) inputs: Inputs,
    pub(super) counts: InputCounts,
    pub(super) intake: Arc<Intake>,
    pub(super) epoch: Epoch,
}

impl SensorSide {
    pub(super) fn sync(&self) -> std::sync::MutexGuard<'_, Synchroniser> {
        self.sync.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// The ROS time of mission time `t` (outputs are stamped in ROS time).
    pub(super) fn ros_time(&self, t: sgm_model::scene_graph::Stamp) -> rosrust::Time {
        self.sync().ros_time(self.epoch, t)
    }

    /// Counts a checked input of `topic`, feeds it to the synchroniser, and hands every frame
    /// then assembled to the robot, moving its clock to the frame's stamp.
    fn receive(&self, topic: &'static str, input: Result<Payload, InputError>) {
        let Some(payload) = self.counts.count(topic, input) else { return };
        let mut sync = self.sync();
        sync.feed(self.epoch, payload);
        for frame in sync.ready() {
            self.intake.frame(frame);
        }
        if let Some(t) = sync.clock() {
            self.intake.advance_clock(t);
        }
    }
}

/// Subscribes `topic` (counted as `name`): each message is checked by `check` and received.
pub(super) fn subscribe<M: rosrust::Message + Layout>(
    topic: &str,
    queue: usize,
    side: &Arc<SensorSide>,
    name: &'static str,
    check: fn(&Inputs, &M) -> Result<Payload, InputError>,
) -> Result<rosrust::Subscriber, NodeError> {
    let side = side.clone();
    rosrust::subscribe(topic, queue, move |m: Bounded<M>| side.receive(name, check(&side.inputs, &m.0)))
        .map_err(ros_error)
}
