//! `sgm doctor --live`: a robot's inputs heard on a running master for a while, through the
//! doctor. It subscribes as the node does (the same topics, bounded decoding, checks), in the
//! robot's namespace (`/ROBOT` unless `__ns:=` or `ROS_NAMESPACE` says otherwise, as roslaunch
//! runs the node), with the command line's remappings (`points:=cloud_registered_body`). An
//! input nobody publishes is named, with the master's topics of its type beside it.

use super::{Doctor, DoctorError, DoctorReport, Verdict};
use crate::bounded::{Bounded, Layout};
use crate::error::InputError;
use crate::inputs::{Inputs, Payload};
use crate::msg::{nav_msgs, sensor_msgs, tf2_msgs};
use crate::node::NodeConfig;
use sgm_actors::config::OdometrySource;
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;

type Check<M> = fn(&Inputs, &M) -> Result<Payload, InputError>;

/// The doctor, shared with the subscribers' callbacks until it is taken to judge.
type Shared = Arc<Mutex<Option<Doctor>>>;

/// Subscribes `topic` for input `input`: each message checked by `check` and observed.
fn listen<M: rosrust::Message + Layout>(
    doctor: &Shared,
    topic: &str,
    input: &'static str,
    check: Check<M>,
) -> Result<rosrust::Subscriber, DoctorError> {
    let doctor = doctor.clone();
    rosrust::subscribe(topic, 100, move |m: Bounded<M>| {
        let mut guard = doctor.lock().unwrap_or_else(PoisonError::into_inner);
        if let Some(d) = guard.as_mut() {
            let result = check(d.inputs(), &m.0);
            d.observe(input, result);
        }
    })
    .map_err(|e| DoctorError::Subscribe { topic: topic.to_string(), reason: e.to_string() })
}

/// Listens to robot `config`'s inputs on the master (`ROS_MASTER_URI`) for `duration`.
pub fn examine_live(config: &NodeConfig, duration: Duration) -> Result<DoctorReport, DoctorError> {
    let robot = config.robot.robot.name.clone();
    rosrust::try_init_with_options(&format!("sgm_doctor_{robot}_{}", std::process::id()), false)
        .map_err(|e| DoctorError::NoMaster(e.to_string()))?;
    crate::bounded::set_max_message_bytes(config.ros.max_message_bytes);
    let first = Doctor::new(config)?.live();
    let topics = first.topics().clone();
    let doctor: Shared = Arc::new(Mutex::new(Some(first)));
    let pose_input = match config.robot.odometry.source {
        OdometrySource::External => (
            "odometry",
            "nav_msgs/Odometry",
            listen::<nav_msgs::Odometry>(&doctor, &topics.odometry, "odometry", Inputs::odometry)?,
        ),
        OdometrySource::Internal => {
            ("imu", "sensor_msgs/Imu", listen::<sensor_msgs::Imu>(&doctor, &topics.imu, "imu", Inputs::imu)?)
        }
    };
    let mut subscribers = vec![
        ("points", "sensor_msgs/PointCloud2", listen(&doctor, &topics.points, "points", Inputs::cloud)?),
        pose_input,
    ];
    if config.ros.labels == crate::config::LabelSource::Image {
        subscribers.push((
            "labels",
            "sensor_msgs/Image",
            listen::<sensor_msgs::Image>(&doctor, &topics.labels, "labels", Inputs::image)?,
        ));
        subscribers.push((
            "camera_info",
            "sensor_msgs/CameraInfo",
            listen::<sensor_msgs::CameraInfo>(&doctor, &topics.camera_info, "camera_info", Inputs::camera_info)?,
        ));
    }
    let tf = &config.ros.tf;
    let tf_listeners = if tf.listen {
        vec![
            listen::<tf2_msgs::TFMessage>(&doctor, &tf.topic, "tf", |i, m| i.tf(m, false))?,
            listen::<tf2_msgs::TFMessage>(&doctor, &tf.static_topic, "tf_static", |i, m| i.tf(m, true))?,
        ]
    } else {
        Vec::new()
    };
    std::thread::sleep(duration);
    // Topics of the input's type that someone publishes (the master's types list subscribed
    // topics too, ours among them).
    let publishing: std::collections::BTreeSet<String> =
        rosrust::state().map(|s| s.publishers.into_iter().map(|t| t.name).collect()).unwrap_or_default();
    let published: Vec<_> =
        rosrust::topics().unwrap_or_default().into_iter().filter(|t| publishing.contains(&t.name)).collect();
    let taken = doctor.lock().unwrap_or_else(PoisonError::into_inner).take();
    let Some(mut d) = taken else { return Err(DoctorError::TakenTwice) };
    for (input, datatype, subscriber) in &subscribers {
        if subscriber.publisher_count() == 0 {
            let alike: Vec<&str> =
                published.iter().filter(|t| t.datatype == *datatype).map(|t| t.name.as_str()).collect();
            let alike = if alike.is_empty() { "none".to_string() } else { alike.join(", ") };
            d.note(
                input,
                Verdict::Fail,
                format!("nobody publishes it; {datatype} topics published on the master: {alike}"),
            );
        }
    }
    drop((subscribers, tf_listeners));
    let uri = std::env::var("ROS_MASTER_URI").unwrap_or_else(|_| "the default master".into());
    Ok(d.finish(format!("master {uri}, {:.0} s listened", duration.as_secs_f64()), false))
}
