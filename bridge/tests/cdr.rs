//! The CDR decoder against an independent serialiser: each fixture of `fixtures/cdr/` was
//! written by the `rosbags` Python package (`fixtures/cdr/generate.py`), in both byte orders.

use sgm_bridge::bag::cdr::{decode, CdrError, FromCdr};
use sgm_bridge::msg::{nav_msgs, sensor_msgs, tf2_msgs};

fn both<M: FromCdr>(name: &str) -> [M; 2] {
    ["le", "be"].map(|order| {
        let path = format!("{}/tests/fixtures/cdr/{name}.{order}.cdr", env!("CARGO_MANIFEST_DIR"));
        let bytes = std::fs::read(&path).unwrap();
        decode::<M>(&bytes, 1 << 20).unwrap_or_else(|e| panic!("{path}: {e}"))
    })
}

#[test]
fn point_clouds_decode_field_by_field() {
    for m in both::<sensor_msgs::PointCloud2>("PointCloud2") {
        assert_eq!(
            (m.header.stamp.sec, m.header.stamp.nsec, m.header.frame_id.as_str()),
            (1700000001, 500, "alpha/lidar")
        );
        assert_eq!(
            (m.height, m.width, m.point_step, m.row_step, m.is_bigendian, m.is_dense),
            (1, 2, 6, 12, false, true)
        );
        let fields: Vec<_> = m.fields.iter().map(|f| (f.name.as_str(), f.offset, f.datatype, f.count)).collect();
        assert_eq!(fields, [("x", 0, 7, 1), ("label", 4, 4, 1)]);
        assert_eq!(m.data, (0..12).collect::<Vec<u8>>());
    }
}

#[test]
fn images_and_camera_infos_decode() {
    for m in both::<sensor_msgs::Image>("Image") {
        assert_eq!((m.header.stamp.sec, m.header.stamp.nsec, m.header.frame_id.as_str()), (7, 8, "cam"));
        assert_eq!((m.height, m.width, m.encoding.as_str(), m.is_bigendian, m.step), (2, 3, "mono8", 0, 3));
        assert_eq!(m.data, [0, 1, 2, 3, 4, 5]);
    }
    for m in both::<sensor_msgs::CameraInfo>("CameraInfo") {
        assert_eq!((m.header.stamp.sec, m.height, m.width, m.distortion_model.as_str()), (9, 480, 640, "plumb_bob"));
        assert_eq!(m.D, [0.1, -0.2, 0.0, 0.0, 0.05]);
        assert_eq!(m.K, std::array::from_fn::<f64, 9, _>(|k| k as f64));
        assert_eq!(m.R, std::array::from_fn::<f64, 9, _>(|k| k as f64 + 10.0));
        assert_eq!(m.P, std::array::from_fn::<f64, 12, _>(|k| k as f64 + 20.0));
        assert_eq!((m.binning_x, m.binning_y), (1, 2));
        let roi = &m.roi;
        assert_eq!((roi.x_offset, roi.y_offset, roi.height, roi.width, roi.do_rectify), (3, 4, 5, 6, true));
    }
}

#[test]
fn odometry_imu_and_tf_decode() {
    for m in both::<nav_msgs::Odometry>("Odometry") {
        assert_eq!((m.header.frame_id.as_str(), m.child_frame_id.as_str()), ("alpha/odom", "alpha/base_link"));
        let p = &m.pose.pose;
        assert_eq!([p.position.x, p.position.y, p.position.z], [1.0, 2.0, 3.0]);
        assert_eq!([p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w], [0.0, 0.0, 0.6, 0.8]);
        assert_eq!(m.pose.covariance, std::array::from_fn::<f64, 36, _>(|k| k as f64));
        assert_eq!((m.twist.twist.linear.x, m.twist.twist.angular.z), (0.5, 0.1));
        assert_eq!(m.twist.covariance, std::array::from_fn::<f64, 36, _>(|k| 2.0 * k as f64));
    }
    for m in both::<sensor_msgs::Imu>("Imu") {
        assert_eq!((m.header.stamp.sec, m.header.stamp.nsec, m.header.frame_id.as_str()), (13, 14, "alpha/imu"));
        assert_eq!(m.orientation_covariance, [-1.0; 9]);
        assert_eq!([m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z], [0.01, 0.02, 0.03]);
        assert_eq!([m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z], [0.1, 0.2, 9.81]);
    }
    for m in both::<tf2_msgs::TFMessage>("TFMessage") {
        let t: Vec<_> = m.transforms.iter().map(|t| (t.header.frame_id.as_str(), t.child_frame_id.as_str())).collect();
        assert_eq!(t, [("alpha/base_link", "alpha/lidar"), ("alpha/base_link", "alpha/camera")]);
        let r = &m.transforms[1].transform.rotation;
        assert_eq!([r.x, r.y, r.z, r.w], [-0.5, 0.5, -0.5, 0.5]);
        assert_eq!(m.transforms[1].transform.translation.z, 0.25);
    }
}

/// Every cut of a fixture short of its end is refused with an error, never a panic, and never
/// read as the message; the whole one beyond the bound is refused as too large.
#[test]
fn cut_messages_are_refused() {
    let path = format!("{}/tests/fixtures/cdr/CameraInfo.le.cdr", env!("CARGO_MANIFEST_DIR"));
    let bytes = std::fs::read(path).unwrap();
    for cut in 0..bytes.len() - 3 {
        assert!(decode::<sensor_msgs::CameraInfo>(&bytes[..cut], 1 << 20).is_err(), "cut at {cut}");
    }
    assert_eq!(
        decode::<sensor_msgs::CameraInfo>(&bytes, 100).unwrap_err(),
        CdrError::TooLarge { len: bytes.len(), max: 100 }
    );
    // A stamp before 1970 has no ROS 1 time.
    let mut early = bytes.clone();
    early[4..8].copy_from_slice(&(-5i32).to_le_bytes());
    let e = decode::<sensor_msgs::CameraInfo>(&early, 1 << 20).unwrap_err().to_string();
    assert_eq!(e, "field `header.stamp.sec`: -5 is before 1970");
}
