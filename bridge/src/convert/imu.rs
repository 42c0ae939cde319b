//! IMU samples ↔ `sensor_msgs/Imu`, and a reading brought from the IMU's mount to the body. Written without an orientation (REP 145: orientation
//! covariance[0] = −1, the message carries rates and specific force only) and with the white
//! noise variances on the diagonals; read back with each value checked.

use crate::error::InputError;
use crate::msg::{geometry_msgs, sensor_msgs, std_msgs};
use nalgebra::Vector3;
use sgm_model::geometry::Pose3;
use sgm_model::perception::imu::ImuSample;

/// One IMU reading, in the IMU's frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImuReading {
    /// rad/s.
    pub angular_velocity: Vector3<f64>,
    /// Specific force (what an accelerometer measures: at rest it reads +g up), m/s².
    pub linear_acceleration: Vector3<f64>,
}

/// Largest rate and specific force a reading may hold (beyond any real IMU's range:
/// 2000 °/s gyros saturate at 35 rad/s, 16 g accelerometers at 157 m/s²).
pub const MAX_RATE_RAD_S: f64 = 100.0;
pub const MAX_SPECIFIC_FORCE_MPS2: f64 = 1000.0;

fn vector_msg(v: &Vector3<f64>) -> geometry_msgs::Vector3 {
    geometry_msgs::Vector3 { x: v.x, y: v.y, z: v.z }
}

fn diagonal(variance: f64) -> [f64; 9] {
    let mut c = [0.0; 9];
    (c[0], c[4], c[8]) = (variance, variance, variance);
    c
}

/// `reading` as a message; `gyro_variance` (rad²/s²) and `accel_variance` (m²/s⁴) per sample.
pub fn imu_msg(
    header: std_msgs::Header,
    reading: &ImuReading,
    gyro_variance: f64,
    accel_variance: f64,
) -> sensor_msgs::Imu {
    let mut orientation_covariance = [0.0; 9];
    orientation_covariance[0] = -1.0;
    sensor_msgs::Imu {
        header,
        orientation: geometry_msgs::Quaternion { x: 0.0, y: 0.0, z: 0.0, w: 1.0 },
        orientation_covariance,
        angular_velocity: vector_msg(&reading.angular_velocity),
        angular_velocity_covariance: diagonal(gyro_variance),
        linear_acceleration: vector_msg(&reading.linear_acceleration),
        linear_acceleration_covariance: diagonal(accel_variance),
    }
}

/// The reading of a message: rates and specific force finite and within range (the
/// orientation, if any, is not used).
pub fn reading_from_msg(msg: &sensor_msgs::Imu) -> Result<ImuReading, InputError> {
    let vector = |v: &geometry_msgs::Vector3, what: &str, max: f64| {
        let v = Vector3::new(v.x, v.y, v.z);
        if !v.iter().all(|c| c.is_finite()) {
            return Err(InputError::invalid(format!("{what} has a non-finite value")));
        }
        if v.amax() > max {
            return Err(InputError::invalid(format!("{what} {:.3} beyond ±{max} (saturated or corrupt)", v.amax())));
        }
        Ok(v)
    };
    Ok(ImuReading {
        angular_velocity: vector(&msg.angular_velocity, "angular_velocity", MAX_RATE_RAD_S)?,
        linear_acceleration: vector(&msg.linear_acceleration, "linear_acceleration", MAX_SPECIFIC_FORCE_MPS2)?,
    })
}

/// `reading`, taken in the IMU's frame at `stamp`, as an IMU at the body origin with the body's
/// axes would have read it. With `body_from_imu = (R, r)`:
///
/// ```text
/// ω_b = R ω_i
/// f_b = R f_i − ω_b × (ω_b × r)
/// ```
///
/// The IMU sits `r` off the origin, so on a turning body it also feels the centripetal
/// acceleration ω × (ω × r), taken out here. The tangential term α × r is not: the angular
/// acceleration α would come from differencing the gyro, and at 200 Hz that turns a gyro's
/// white noise of 0.014 rad/s per sample into about 6 rad/s², 0.6 m/s² at r = 0.1 m. That is
/// far more than the accelerometer's own noise and more than the term itself on any but a
/// violently shaking mount.
pub fn sample_in_body(stamp: f64, reading: &ImuReading, body_from_imu: &Pose3) -> ImuSample {
    let (rotation, lever) = (body_from_imu.rotation, body_from_imu.translation.vector);
    let angular_velocity = rotation * reading.angular_velocity;
    let centripetal = angular_velocity.cross(&angular_velocity.cross(&lever));
    ImuSample { stamp, angular_velocity, specific_force: rotation * reading.linear_acceleration - centripetal }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rosrust::RosMsg;

    /// Closed form: a body turning on the spot at 1 rad/s about z, its IMU 1 m ahead of the
    /// origin and mounted upside down (turned 180° about x). In its own axes the IMU reads the
    /// rate as −z, gravity's reaction as −z, and the 1 m/s² pull towards the axis as −x (x is
    /// shared). In the body: the rate +z, the specific force straight up, the pull gone.
    #[test]
    fn a_reading_off_the_origin_and_turned_comes_into_the_body() {
        let body_from_imu = Pose3::from_parts(
            nalgebra::Translation3::new(1.0, 0.0, 0.0),
            nalgebra::UnitQuaternion::from_euler_angles(std::f64::consts::PI, 0.0, 0.0),
        );
        let reading = ImuReading {
            angular_velocity: Vector3::new(0.0, 0.0, -1.0),
            linear_acceleration: Vector3::new(-1.0, 0.0, -9.81),
        };
        let sample = sample_in_body(2.5, &reading, &body_from_imu);
        assert_eq!(sample.stamp, 2.5);
        assert!((sample.angular_velocity - Vector3::new(0.0, 0.0, 1.0)).norm() < 1e-12, "{sample:?}");
        assert!((sample.specific_force - Vector3::new(0.0, 0.0, 9.81)).norm() < 1e-12, "{sample:?}");
        let same = sample_in_body(0.0, &reading, &Pose3::identity());
        assert_eq!(
            (same.angular_velocity, same.specific_force),
            (reading.angular_velocity, reading.linear_acceleration)
        );
    }

    #[test]
    fn a_reading_round_trips_through_the_wire_format_and_bad_values_are_refused() {
        let reading = ImuReading {
            angular_velocity: Vector3::new(0.1, -0.2, 0.3),
            linear_acceleration: Vector3::new(0.5, 0.0, 9.81),
        };
        let msg = imu_msg(std_msgs::Header::default(), &reading, 1e-6, 4e-4);
        let bytes = msg.encode_vec().expect("encodes");
        let back = sensor_msgs::Imu::decode_slice(&bytes).expect("decodes");
        assert_eq!(back.orientation_covariance[0], -1.0, "REP 145: no orientation");
        assert_eq!(back.angular_velocity_covariance[4], 1e-6);
        assert_eq!(reading_from_msg(&back).expect("valid"), reading);
        let mut bad = back.clone();
        bad.angular_velocity.y = f64::NAN;
        assert!(reading_from_msg(&bad).unwrap_err().to_string().contains("angular_velocity has a non-finite value"));
        let mut bad = back;
        bad.linear_acceleration.z = 5000.0;
        assert!(reading_from_msg(&bad).unwrap_err().to_string().contains("linear_acceleration 5000.000 beyond"));
    }
}
