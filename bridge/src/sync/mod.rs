//! The synchroniser: three streams in (clouds, odometry, label images + camera info), typed
//! [`SensorFrame`](sgm_actors::messages::SensorFrame)s out — the same code for the live node and
//! the bag replay. A cloud gets the odometry pose at its stamp (the pose stamped exactly then, else
//! interpolated between the two bracketing poses — linear in translation, slerp in rotation — if
//! they are at most `max_odometry_gap_s` apart) and the label image nearest its stamp. An image
//! within `image_tolerance_s` labels it as it is; one farther but within `max_label_skew_s` (a
//! segmenter slower than the LiDAR) labels it with the body's motion in between compensated:
//!
//! ```text
//! camera(t_img)_from_body(t) = camera_from_body · world_from_body(t_img)⁻¹ · world_from_body(t)
//! ```
//!
//! (what moves in the scene meanwhile is not compensated). A cloud no image reaches is
//! assembled without labels (`unlabelled = "keep"`) or dropped. Images come in stamp order, so
//! once one at or after the cloud's stamp is in, no later one can be nearer. A cloud waits
//! while its partners may still come; once the streams are `max_wait_s` past it, it takes what
//! there is, or is dropped and counted. Time here is the streams' own (header stamps), never the wall
//! clock, so a replay is deterministic. Every buffer is bounded.
//!
//! Stamps are checked first by the [`Timeline`](crate::timeline::Timeline): a stamp far from its
//! stream waits until others confirm it (a jump: the timeline restarts, the buffers start afresh
//! and mission time goes on) or is dropped as an outlier (a glitch), so one bad stamp never stops
//! the streams.
//!
//! [`Synchroniser`] (`synchroniser.rs`) takes the streams in and owns their buffers; a cloud
//! meets its odometry pose and is assembled in `assemble.rs`, and finds its labels (from the
//! cloud, or the nearest image, motion-compensated) in `labels.rs`; what became of the clouds
//! is counted in [`SyncCounts`] (`counts.rs`).

mod assemble;
mod counts;
mod labels;
mod synchroniser;

#[cfg(test)]
mod fixtures;

pub use counts::SyncCounts;
pub use labels::PROJECTION_SAMPLE;
pub use synchroniser::Synchroniser;
