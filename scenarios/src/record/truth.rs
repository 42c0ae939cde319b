//! A robot's true trajectory: the simulator's route, or the poses a bag's ground-truth topic
//! carried (looked up exactly at their stamps, interpolated between them up to half a second).

use crate::sim::trajectory::Route;
use sgm_model::geometry::{levelled, Pose3};
use sgm_model::scene_graph::Stamp;

/// Samples further apart than this are not interpolated.
const MAX_GAP_S: f64 = 0.5;

#[derive(Clone, Debug)]
pub enum TruthTrack {
    Route(Route),
    /// (stamp, pose), stamps increasing.
    Samples(Vec<(Stamp, Pose3)>),
}

impl TruthTrack {
    /// Whether there is any truth at all.
    pub fn is_known(&self) -> bool {
        match self {
            TruthTrack::Route(_) => true,
            TruthTrack::Samples(samples) => !samples.is_empty(),
        }
    }

    /// Where a robot's own odometry put its world frame, in the truth: the body's true pose
    /// at `origin` (the scan the odometry started on), levelled, its yaw and position kept
    /// (`model::odometry::estimator`).
    pub fn odometry_origin(&self, origin: Stamp) -> Option<Pose3> {
        self.pose_at(origin).map(|p| levelled(&p))
    }

    pub fn pose_at(&self, t: Stamp) -> Option<Pose3> {
        match self {
            TruthTrack::Route(route) => route.pose_at(t),
            TruthTrack::Samples(samples) => {
                let after = samples.partition_point(|(s, _)| *s < t);
                let (s1, p1) = samples.get(after)?;
                if *s1 == t {
                    return Some(*p1);
                }
                let (s0, p0) = samples.get(after.checked_sub(1)?)?;
                if s1 - s0 > MAX_GAP_S {
                    return None;
                }
                Some(sgm_model::geometry::interpolate(p0, p1, (t - s0) / (s1 - s0)))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn samples_exact_interpolated_or_none() {
        let track = TruthTrack::Samples(vec![
            (1.0, Pose3::translation(0.0, 0.0, 0.0)),
            (1.2, Pose3::translation(2.0, 0.0, 0.0)),
            (5.0, Pose3::translation(9.0, 0.0, 0.0)),
        ]);
        assert_eq!(track.pose_at(1.2), Some(Pose3::translation(2.0, 0.0, 0.0)));
        assert!((track.pose_at(1.1).unwrap().translation.x - 1.0).abs() < 1e-12);
        assert_eq!(track.pose_at(3.0), None);
        assert_eq!(track.pose_at(0.5), None);
        assert_eq!(track.pose_at(6.0), None);
    }
}
