//! `sgm odometry --bag FILE --robot NAME [--id N] [--config FILE | --scenario NAME] --out
//! TRAJ.tum`: the LiDAR-inertial odometry alone on one robot's ROS 1 bag
//! (`sgm_scenarios::bag_odometry`); the trajectory as TUM (ROS times, `odom_from_body`), the
//! filter's counts on stderr.

use super::ros_cmd::RobotArgs;
use anyhow::{Context, Result};
use sgm_scenarios::bag_odometry::odometry_on_bag;
use sgm_scenarios::report::tum;
use std::path::PathBuf;

pub struct Options {
    pub robot: RobotArgs,
    pub bag: PathBuf,
    pub out: PathBuf,
}

pub fn execute(options: Options) -> Result<()> {
    let config = options.robot.node_config()?;
    let run = odometry_on_bag(&options.bag, &config).with_context(|| format!("{}", options.bag.display()))?;
    let mut text = String::new();
    if let Some(epoch) = run.epoch {
        for pose in &run.poses {
            let time = epoch.time(pose.stamp);
            tum::line(&mut text, f64::from(time.sec) + f64::from(time.nsec) * 1e-9, &pose.odom_from_body);
        }
    }
    std::fs::write(&options.out, text).with_context(|| format!("writing {}", options.out.display()))?;
    let c = run.counts;
    eprintln!(
        "{} poses to {}: {} scans registered, {} coasted, {} refused, {} degenerate, {} resets; {} clouds before the IMU covered their sweep; {:.1} ms per cloud",
        run.poses.len(),
        options.out.display(),
        c.registered,
        c.coasted,
        c.refused,
        c.degenerate,
        c.resets,
        run.registered_early,
        run.time_per_cloud.as_secs_f64() * 1e3
    );
    if run.no_lidar_mount > 0 {
        eprintln!("{} clouds left out: no LiDAR mount (pin ros.body_from_lidar, or record tf)", run.no_lidar_mount);
    }
    if run.no_imu_mount > 0 {
        eprintln!("{} IMU samples left out: no IMU mount (pin ros.body_from_imu, or record tf)", run.no_imu_mount);
    }
    for (input, (count, last)) in &run.refused {
        eprintln!("{count} {input} messages refused; the last: {last}");
    }
    Ok(())
}
