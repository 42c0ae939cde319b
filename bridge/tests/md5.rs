//! Each ROS type the bridge uses has the md5sum Debian's ROS 1 (common_msgs 1.13) gives it, so
//! our bare field lists interoperate with real nodes. The table was produced by `rosmsg md5`; when
//! `rosmsg` is installed (`.ci/run` installs it) every type is also checked live against it.

use rosrust::Message;
use sgm_bridge::msg::*;

fn ours() -> Vec<(&'static str, String)> {
    vec![
        ("std_msgs/Header", std_msgs::Header::md5sum()),
        ("std_msgs/ColorRGBA", std_msgs::ColorRGBA::md5sum()),
        ("std_msgs/String", std_msgs::String::md5sum()),
        ("geometry_msgs/Point", geometry_msgs::Point::md5sum()),
        ("geometry_msgs/Vector3", geometry_msgs::Vector3::md5sum()),
        ("geometry_msgs/Quaternion", geometry_msgs::Quaternion::md5sum()),
        ("geometry_msgs/Pose", geometry_msgs::Pose::md5sum()),
        ("geometry_msgs/PoseStamped", geometry_msgs::PoseStamped::md5sum()),
        ("geometry_msgs/PoseWithCovariance", geometry_msgs::PoseWithCovariance::md5sum()),
        ("geometry_msgs/Twist", geometry_msgs::Twist::md5sum()),
        ("geometry_msgs/TwistWithCovariance", geometry_msgs::TwistWithCovariance::md5sum()),
        ("geometry_msgs/Transform", geometry_msgs::Transform::md5sum()),
        ("geometry_msgs/TransformStamped", geometry_msgs::TransformStamped::md5sum()),
        ("sensor_msgs/PointField", sensor_msgs::PointField::md5sum()),
        ("sensor_msgs/PointCloud2", sensor_msgs::PointCloud2::md5sum()),
        ("sensor_msgs/Image", sensor_msgs::Image::md5sum()),
        ("sensor_msgs/RegionOfInterest", sensor_msgs::RegionOfInterest::md5sum()),
        ("sensor_msgs/CameraInfo", sensor_msgs::CameraInfo::md5sum()),
        ("sensor_msgs/Imu", sensor_msgs::Imu::md5sum()),
        ("nav_msgs/Odometry", nav_msgs::Odometry::md5sum()),
        ("nav_msgs/Path", nav_msgs::Path::md5sum()),
        ("visualization_msgs/Marker", visualization_msgs::Marker::md5sum()),
        ("visualization_msgs/MarkerArray", visualization_msgs::MarkerArray::md5sum()),
        ("tf2_msgs/TFMessage", tf2_msgs::TFMessage::md5sum()),
        ("rosgraph_msgs/Clock", rosgraph_msgs::Clock::md5sum()),
    ]
}

/// `rosmsg md5 TYPE` on Debian bookworm (ros_comm 1.15.15, common_msgs 1.13.1).
const DEBIAN: &[(&str, &str)] = &[
    ("std_msgs/Header", "2176decaecbce78abc3b96ef049fabed"),
    ("std_msgs/ColorRGBA", "a29a96539573343b1310c73607334b00"),
    ("std_msgs/String", "992ce8a1687cec8c8bd883ec73ca41d1"),
    ("geometry_msgs/Point", "4a842b65f413084dc2b10fb484ea7f17"),
    ("geometry_msgs/Vector3", "4a842b65f413084dc2b10fb484ea7f17"),
    ("geometry_msgs/Quaternion", "a779879fadf0160734f906b8c19c7004"),
    ("geometry_msgs/Pose", "e45d45a5a1ce597b249e23fb30fc871f"),
    ("geometry_msgs/PoseStamped", "d3812c3cbc69362b77dc0b19b345f8f5"),
    ("geometry_msgs/PoseWithCovariance", "c23e848cf1b7533a8d7c259073a97e6f"),
    ("geometry_msgs/Twist", "9f195f881246fdfa2798d1d3eebca84a"),
    ("geometry_msgs/TwistWithCovariance", "1fe8a28e6890a4cc3ae4c3ca5c7d82e6"),
    ("geometry_msgs/Transform", "ac9eff44abf714214112b05d54a3cf9b"),
    ("geometry_msgs/TransformStamped", "b5764a33bfeb3588febc2682852579b0"),
    ("sensor_msgs/PointField", "268eacb2962780ceac86cbd17e328150"),
    ("sensor_msgs/PointCloud2", "1158d486dd51d683ce2f1be655c3c181"),
    ("sensor_msgs/Image", "060021388200f6f0f447d0fcd9c64743"),
    ("sensor_msgs/RegionOfInterest", "bdb633039d588fcccb441a4d43ccfe09"),
    ("sensor_msgs/CameraInfo", "c9a58c1b0b154e0e6da7578cb991d214"),
    ("sensor_msgs/Imu", "6a62c6daae103f4ff57a132d6f95cec2"),
    ("nav_msgs/Odometry", "cd5e73d190d741a2f92e81eda573aca7"),
    ("nav_msgs/Path", "6227e2b7e9cce15051f669a5e197bbf7"),
    ("visualization_msgs/Marker", "4048c9de2a16f4ae8e0538085ebf1b97"),
    ("visualization_msgs/MarkerArray", "d155b9ce5188fbaf89745847fd5882d7"),
    ("tf2_msgs/TFMessage", "94810edda583a504dfda3829e70d7eec"),
    ("rosgraph_msgs/Clock", "a9c97c1d230cfc112e270351a944ee47"),
];

#[test]
fn md5sums_match_debians_recorded_table() {
    let ours = ours();
    assert_eq!(ours.len(), DEBIAN.len());
    for ((name, md5), (debian_name, debian_md5)) in ours.iter().zip(DEBIAN) {
        assert_eq!(name, debian_name);
        assert_eq!(md5, debian_md5, "{name}");
    }
}

/// Live against `rosmsg md5` when it is installed; required when `SGM_ROS_INTEROP=1`.
#[test]
fn md5sums_match_rosmsg_when_installed() {
    let required = std::env::var("SGM_ROS_INTEROP").is_ok_and(|v| v == "1");
    let probe = std::process::Command::new("rosmsg").arg("md5").arg("std_msgs/String").output();
    if !probe.as_ref().is_ok_and(|o| o.status.success()) {
        assert!(!required, "SGM_ROS_INTEROP=1 but `rosmsg md5` does not run: {probe:?}");
        eprintln!("rosmsg not installed: live md5 check skipped (the recorded table was checked)");
        return;
    }
    for (name, md5) in ours() {
        let out = std::process::Command::new("rosmsg").arg("md5").arg(name).output().expect("rosmsg runs");
        let live = String::from_utf8_lossy(&out.stdout).trim().to_string();
        assert_eq!(md5, live, "{name}: ours against `rosmsg md5`");
    }
}
