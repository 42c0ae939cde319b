//! This robot's world frame on the master, and the team's, followed while the node runs.

use crate::team_frames::{world_frame_param, WorldFrames};
use std::collections::BTreeMap;
use std::time::Duration;

/// Registers this robot's world frame on the master (`/sgm/world_frames/robot_{id}`) and keeps
/// `frames` up to date with the team's registrations, on a thread of its own (the master's
/// parameter calls block), every 5 s while the node runs.
pub(super) fn register_world_frame(id: u16, world_frame: &str, frames: WorldFrames) {
    let (name, frame) = (world_frame_param(id), world_frame.to_string());
    let spawned = std::thread::Builder::new().name("sgm-world-frames".into()).spawn(move || {
        match rosrust::param(&name) {
            Some(param) => {
                if let Ok(existing) = param.get::<String>() {
                    if existing != frame {
                        tracing::warn!(param = %name, existing, frame,
                            "another world frame was registered for this robot id: a second robot with this id, \
                             or this robot started before with another ros.frames.world; taking it over");
                    }
                }
                if let Err(e) = param.set(&frame) {
                    tracing::warn!(param = %name, "world frame not registered on the master: {e}");
                }
            }
            None => tracing::warn!(param = %name, "world frame not registered: not a valid parameter name"),
        }
        while rosrust::is_ok() {
            if let Some(Ok(registered)) =
                rosrust::param("/sgm/world_frames").map(|p| p.get::<BTreeMap<String, String>>())
            {
                frames.update(&registered);
            }
            std::thread::sleep(Duration::from_secs(5));
        }
    });
    if let Err(e) = spawned {
        tracing::warn!("world frames not followed (no thread: {e}): neighbours' worlds are named robot_ID");
    }
}
