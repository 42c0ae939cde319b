//! Poses ↔ geometry_msgs, and frame ids checked.

use crate::error::InputError;
use crate::msg::{geometry_msgs, nav_msgs, std_msgs};
use nalgebra::{Quaternion, Translation3, UnitQuaternion};
use sgm_model::geometry::Pose3;

pub fn pose_msg(pose: &Pose3) -> geometry_msgs::Pose {
    let (t, q) = (pose.translation.vector, pose.rotation.quaternion());
    geometry_msgs::Pose {
        position: geometry_msgs::Point { x: t.x, y: t.y, z: t.z },
        orientation: geometry_msgs::Quaternion { x: q.i, y: q.j, z: q.k, w: q.w },
    }
}

pub fn transform_msg(pose: &Pose3) -> geometry_msgs::Transform {
    let p = pose_msg(pose);
    geometry_msgs::Transform {
        translation: geometry_msgs::Vector3 { x: p.position.x, y: p.position.y, z: p.position.z },
        rotation: p.orientation,
    }
}

/// A pose from a message: finite values and a quaternion of norm within 1 ± 1e-3 (renormalised;
/// drivers round), anything else refused.
pub fn pose_from_msg(pose: &geometry_msgs::Pose) -> Result<Pose3, InputError> {
    let (p, o) = (&pose.position, &pose.orientation);
    let values = [p.x, p.y, p.z, o.x, o.y, o.z, o.w];
    if !values.iter().all(|v| v.is_finite()) {
        return Err(InputError::invalid("pose has a non-finite value"));
    }
    let q = Quaternion::new(o.w, o.x, o.y, o.z);
    let norm = q.norm();
    if (norm - 1.0).abs() > 1e-3 {
        return Err(InputError::invalid(format!("orientation quaternion has norm {norm:.6}, 1 expected")));
    }
    // A quaternion unit to rounding is kept bit for bit (what we wrote reads back unchanged).
    let rotation =
        if (norm - 1.0).abs() <= 1e-12 { UnitQuaternion::new_unchecked(q) } else { UnitQuaternion::new_normalize(q) };
    Ok(Pose3::from_parts(Translation3::new(p.x, p.y, p.z), rotation))
}

pub fn odometry_msg(header: std_msgs::Header, child_frame_id: &str, pose: &Pose3) -> nav_msgs::Odometry {
    let mut msg = nav_msgs::Odometry { header, child_frame_id: child_frame_id.to_string(), ..Default::default() };
    msg.pose.pose = pose_msg(pose);
    msg
}

/// `got` must equal `expected` unless `expected` is empty (any frame accepted). A leading `/`
/// is ignored on both (tf2 frame ids carry none, older drivers add one).
pub fn check_frame(got: &str, expected: &str) -> Result<(), InputError> {
    if expected.is_empty() || got.trim_start_matches('/') == expected.trim_start_matches('/') {
        Ok(())
    } else {
        Err(InputError::Frame { got: got.to_string(), expected: expected.to_string() })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn pose_round_trips(x in -1e4f64..1e4, y in -1e4f64..1e4, z in -1e3f64..1e3,
                            r in -3.1f64..3.1, p in -1.5f64..1.5, w in -3.1f64..3.1) {
            let pose = sgm_model::geometry::pose_from_rpy_translation(r, p, w, nalgebra::Vector3::new(x, y, z));
            let back = pose_from_msg(&pose_msg(&pose)).unwrap();
            prop_assert!((back.translation.vector - pose.translation.vector).norm() == 0.0);
            prop_assert!(back.rotation.angle_to(&pose.rotation) < 1e-12);
        }
    }

    #[test]
    fn bad_poses_and_frames_are_named() {
        let mut pose = geometry_msgs::Pose::default();
        pose.orientation.w = 1.0;
        assert!(pose_from_msg(&pose).is_ok());
        assert!(check_frame("alpha/odom", "/alpha/odom").is_ok());
        assert!(check_frame("alpha/odom", "").is_ok());
        assert_eq!(check_frame("alpha/odom", "map").unwrap_err().to_string(), "frame `alpha/odom`, `map` expected");
        pose.orientation.w = 0.0;
        assert!(pose_from_msg(&pose).unwrap_err().to_string().contains("norm 0.000000"));
        pose.orientation.w = 1.0;
        pose.position.x = f64::NAN;
        assert!(pose_from_msg(&pose).is_err());
    }
}
