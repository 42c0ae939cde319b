//! Range checks of a scenario; each failure is (key, value, allowed).

use super::{Scenario, WorldKind};
use crate::scenario::shapes::shape_of;

type Failure = (String, String, String);

fn check(ok: bool, key: impl Into<String>, value: impl ToString, allowed: &str) -> Result<(), Failure> {
    if ok {
        Ok(())
    } else {
        Err((key.into(), value.to_string(), allowed.into()))
    }
}

fn within(v: f64, lo: f64, hi: f64) -> bool {
    v.is_finite() && v >= lo && v <= hi
}

/// `[section] mount_xyz_m, mount_rpy_deg, mount_error_deg, mount_error_m`.
fn check_mount(section: &str, xyz: [f64; 3], rpy: [f64; 3], error_deg: f64, error_m: f64) -> Result<(), Failure> {
    let all = |v: [f64; 3], lo, hi| v.iter().all(|v| within(*v, lo, hi));
    check(all(xyz, -5.0, 5.0), format!("{section}.mount_xyz_m"), format!("{xyz:?}"), "each −5 ≤ x ≤ 5 m")?;
    check(all(rpy, -180.0, 180.0), format!("{section}.mount_rpy_deg"), format!("{rpy:?}"), "each −180 ≤ x ≤ 180°")?;
    check(within(error_deg, 0.0, 10.0), format!("{section}.mount_error_deg"), error_deg, "0 ≤ x ≤ 10°")?;
    check(within(error_m, 0.0, 0.5), format!("{section}.mount_error_m"), error_m, "0 ≤ x ≤ 0.5 m")
}

impl Scenario {
    pub(super) fn validate(&self) -> Result<(), Failure> {
        self.ros.validate().map_err(|e| ("ros".to_string(), "(section)".to_string(), e.to_string()))?;
        let s = &self.scenario;
        check(within(s.duration_s, 1.0, 1e6), "scenario.duration_s", s.duration_s, "1 ≤ x ≤ 1e6 s")?;
        check(
            within(s.frame_interval_s, 0.01, 10.0),
            "scenario.frame_interval_s",
            s.frame_interval_s,
            "0.01 ≤ x ≤ 10 s",
        )?;
        check(
            within(s.report_interval_s, s.frame_interval_s, 1e6),
            "scenario.report_interval_s",
            s.report_interval_s,
            "≥ scenario.frame_interval_s",
        )?;

        let w = &self.world;
        for (k, v) in w.size_m.iter().enumerate() {
            check(within(*v, 5.0, 1e4), format!("world.size_m[{k}]"), v, "5 ≤ x ≤ 10000 m")?;
        }
        for (name, count) in &w.objects {
            let key = format!("world.objects.{name}");
            check(self.fusion.classes.iter().any(|c| &c.name == name), &key, count, "a class of [fusion].classes")?;
            check(shape_of(name).is_some(), &key, count, crate::scenario::shapes::KNOWN_SHAPES)?;
            check(*count <= 100_000, &key, count, "≤ 100000")?;
        }
        check(within(w.min_spacing_m, 0.0, 100.0), "world.min_spacing_m", w.min_spacing_m, "0 ≤ x ≤ 100 m")?;
        check(w.buildings <= 1000, "world.buildings", w.buildings, "≤ 1000")?;
        check(within(w.room_size_m, 3.0, 100.0), "world.room_size_m", w.room_size_m, "3 ≤ x ≤ 100 m")?;
        check(within(w.wall_height_m, 0.5, 50.0), "world.wall_height_m", w.wall_height_m, "0.5 ≤ x ≤ 50 m")?;
        check(
            within(w.door_width_m, 0.5, w.room_size_m - 1.0),
            "world.door_width_m",
            w.door_width_m,
            "0.5 m ≤ x ≤ world.room_size_m − 1 m",
        )?;
        check(
            !w.ceiling || w.kind == WorldKind::Indoor,
            "world.ceiling",
            w.ceiling,
            "true only with kind = \"indoor\"",
        )?;

        let t = &self.terrain;
        check(within(t.max_slope_deg, 0.0, 30.0), "terrain.max_slope_deg", t.max_slope_deg, "0 ≤ x ≤ 30°")?;
        check(
            within(t.hill_wavelength_m, 5.0, 1000.0),
            "terrain.hill_wavelength_m",
            t.hill_wavelength_m,
            "5 ≤ x ≤ 1000 m",
        )?;
        check(t.kerbs <= 100, "terrain.kerbs", t.kerbs, "≤ 100")?;
        check(within(t.kerb_height_m, 0.0, 0.5), "terrain.kerb_height_m", t.kerb_height_m, "0 ≤ x ≤ 0.5 m")?;
        check(t.ramps <= 100, "terrain.ramps", t.ramps, "≤ 100")?;
        check(
            t.ramp_slope_deg.is_finite() && t.ramp_slope_deg > 0.0 && t.ramp_slope_deg <= 30.0,
            "terrain.ramp_slope_deg",
            t.ramp_slope_deg,
            "0 < x ≤ 30°",
        )?;
        check(within(t.ramp_height_m, 0.0, 3.0), "terrain.ramp_height_m", t.ramp_height_m, "0 ≤ x ≤ 3 m")?;
        let p = &self.platforms;
        check(within(p.wheelbase_m, 0.1, 5.0), "platforms.wheelbase_m", p.wheelbase_m, "0.1 ≤ x ≤ 5 m")?;
        check(within(p.track_m, 0.1, 5.0), "platforms.track_m", p.track_m, "0.1 ≤ x ≤ 5 m")?;
        check(within(p.gait_hz, 0.1, 10.0), "platforms.gait_hz", p.gait_hz, "0.1 ≤ x ≤ 10 Hz")?;
        check(
            within(p.gait_amplitude_deg, 0.0, 20.0),
            "platforms.gait_amplitude_deg",
            p.gait_amplitude_deg,
            "0 ≤ x ≤ 20°",
        )?;
        check(within(p.gait_bounce_m, 0.0, 0.3), "platforms.gait_bounce_m", p.gait_bounce_m, "0 ≤ x ≤ 0.3 m")?;
        check(within(p.sway_deg, 0.0, 30.0), "platforms.sway_deg", p.sway_deg, "0 ≤ x ≤ 30°")?;
        check(within(p.sway_m, 0.0, 1.0), "platforms.sway_m", p.sway_m, "0 ≤ x ≤ 1 m")?;
        check(within(p.accel_mps2, 0.05, 20.0), "platforms.accel_mps2", p.accel_mps2, "0.05 ≤ x ≤ 20 m/s²")?;
        check(within(p.turn_radius_m, 0.0, 50.0), "platforms.turn_radius_m", p.turn_radius_m, "0 ≤ x ≤ 50 m")?;
        check(within(p.yaw_rate_dps, 1.0, 720.0), "platforms.yaw_rate_dps", p.yaw_rate_dps, "1 ≤ x ≤ 720 °/s")?;
        check(
            within(p.yaw_accel_dps2, 1.0, 7200.0),
            "platforms.yaw_accel_dps2",
            p.yaw_accel_dps2,
            "1 ≤ x ≤ 7200 °/s²",
        )?;
        check(
            within(p.still_at_start_s, 0.0, 600.0),
            "platforms.still_at_start_s",
            p.still_at_start_s,
            "0 ≤ x ≤ 600 s",
        )?;

        let i = &self.imu;
        check(
            within(i.rate_hz, 1.0 / s.frame_interval_s, 2000.0),
            "imu.rate_hz",
            i.rate_hz,
            "≥ the frame rate (1 / scenario.frame_interval_s) and ≤ 2000 Hz",
        )?;
        for (key, v) in [
            ("imu.gyro_noise", i.gyro_noise),
            ("imu.gyro_bias_walk", i.gyro_bias_walk),
            ("imu.accel_noise", i.accel_noise),
            ("imu.accel_bias_walk", i.accel_bias_walk),
        ] {
            check(within(v, 0.0, 1.0), key, v, "0 ≤ x ≤ 1")?;
        }
        check(
            within(i.gyro_turn_on_bias, 0.0, 0.1),
            "imu.gyro_turn_on_bias",
            i.gyro_turn_on_bias,
            "0 ≤ x ≤ 0.1 rad/s",
        )?;
        check(
            within(i.accel_turn_on_bias, 0.0, 1.0),
            "imu.accel_turn_on_bias",
            i.accel_turn_on_bias,
            "0 ≤ x ≤ 1 m/s²",
        )?;
        check(within(i.gravity_mps2, 9.7, 9.9), "imu.gravity_mps2", i.gravity_mps2, "9.7 ≤ x ≤ 9.9 m/s²")?;

        self.validate_segmentation()?;

        let l = &self.lidar;
        check((1..=256).contains(&l.beams), "lidar.beams", l.beams, "1 ≤ x ≤ 256")?;
        check(within(l.azimuth_step_deg, 0.05, 10.0), "lidar.azimuth_step_deg", l.azimuth_step_deg, "0.05 ≤ x ≤ 10°")?;
        let [lo, hi] = l.vertical_fov_deg;
        check(
            within(lo, -90.0, 90.0) && within(hi, lo, 90.0),
            "lidar.vertical_fov_deg",
            format!("[{lo}, {hi}]"),
            "−90 ≤ low ≤ high ≤ 90°",
        )?;
        check(
            (1..=500_000).contains(&l.points_per_frame),
            "lidar.points_per_frame",
            l.points_per_frame,
            "1 ≤ x ≤ 500000",
        )?;
        check(within(l.max_range_m, 1.0, 500.0), "lidar.max_range_m", l.max_range_m, "1 ≤ x ≤ 500 m")?;
        check(within(l.range_noise_m, 0.0, 1.0), "lidar.range_noise_m", l.range_noise_m, "0 ≤ x ≤ 1 m")?;
        check(
            within(l.sweep_s, 0.0, s.frame_interval_s.min(0.5)),
            "lidar.sweep_s",
            l.sweep_s,
            "0 ≤ x ≤ min(scenario.frame_interval_s, 0.5 s)",
        )?;
        check_mount("lidar", l.mount_xyz_m, l.mount_rpy_deg, l.mount_error_deg, l.mount_error_m)?;

        let c = &self.camera;
        check((16..=4096).contains(&c.width), "camera.width", c.width, "16 ≤ x ≤ 4096 px")?;
        check((16..=4096).contains(&c.height), "camera.height", c.height, "16 ≤ x ≤ 4096 px")?;
        check(
            within(c.horizontal_fov_deg, 10.0, 170.0),
            "camera.horizontal_fov_deg",
            c.horizontal_fov_deg,
            "10 ≤ x ≤ 170°",
        )?;
        check(within(c.mislabel_rate, 0.0, 1.0), "camera.mislabel_rate", c.mislabel_rate, "0 ≤ x ≤ 1")?;
        check(
            within(c.boundary_noise_px, 0.0, 50.0),
            "camera.boundary_noise_px",
            c.boundary_noise_px,
            "0 ≤ x ≤ 50 px",
        )?;
        check_mount("camera", c.mount_xyz_m, c.mount_rpy_deg, c.mount_error_deg, c.mount_error_m)?;
        let dt = s.frame_interval_s;
        check(
            within(c.exposure_offset_s, -dt, dt),
            "camera.exposure_offset_s",
            c.exposure_offset_s,
            "−scenario.frame_interval_s ≤ x ≤ scenario.frame_interval_s",
        )?;
        check(within(c.clock_offset_s, -0.5, 0.5), "camera.clock_offset_s", c.clock_offset_s, "−0.5 ≤ x ≤ 0.5 s")?;

        let o = &self.odometry;
        for (key, v) in [
            ("odometry.position_walk_m", o.position_walk_m),
            ("odometry.yaw_walk_deg", o.yaw_walk_deg),
            ("odometry.height_walk_m", o.height_walk_m),
            ("odometry.roll_pitch_deg", o.roll_pitch_deg),
            ("odometry.tilt_walk_deg", o.tilt_walk_deg),
        ] {
            check(within(v, 0.0, 10.0), key, v, "0 ≤ x ≤ 10")?;
        }
        self.validate_internal_odometry()?;

        let r = &self.radio;
        let is_robot = |name: &str| (0..self.robots.len()).any(|j| self.robot_name(j) == name);
        check(within(r.bandwidth_kbps, 1.0, 1e7), "radio.bandwidth_kbps", r.bandwidth_kbps, "1 ≤ x ≤ 1e7 kbit/s")?;
        check(within(r.latency_ms, 0.0, 60_000.0), "radio.latency_ms", r.latency_ms, "0 ≤ x ≤ 60000 ms")?;
        check(within(r.loss, 0.0, 1.0), "radio.loss", r.loss, "0 ≤ x ≤ 1")?;
        check(within(r.range_m, 0.0, 1e6), "radio.range_m", r.range_m, "0 (unlimited) ≤ x ≤ 1e6 m")?;
        check(r.queue_bytes >= 1024, "radio.queue_bytes", r.queue_bytes, "≥ 1024")?;
        check(within(r.duplicate, 0.0, 1.0), "radio.duplicate", r.duplicate, "0 ≤ x ≤ 1")?;
        check(within(r.jitter_ms, 0.0, 60_000.0), "radio.jitter_ms", r.jitter_ms, "0 ≤ x ≤ 60000 ms")?;
        for (k, p) in r.partitions.iter().enumerate() {
            let key = |field: &str| format!("radio.partitions[{k}].{field}");
            check(within(p.start_s, 0.0, 1e9), key("start_s"), p.start_s, "0 ≤ x")?;
            check(p.end_s.is_finite() && p.end_s > p.start_s, key("end_s"), p.end_s, "finite, > start_s")?;
            check(!p.robots.is_empty(), key("robots"), "[]", "at least one robot name")?;
            for name in &p.robots {
                check(is_robot(name), key("robots"), format!("{name:?}"), "names of robots of this scenario")?;
            }
        }

        for (k, f) in self.false_factors.iter().enumerate() {
            let key = |field: &str| format!("false_factors[{k}].{field}");
            check(is_robot(&f.robot), key("robot"), format!("{:?}", f.robot), "a robot of this scenario")?;
            check(
                is_robot(&f.neighbour) && f.neighbour != f.robot,
                key("neighbour"),
                format!("{:?}", f.neighbour),
                "another robot of this scenario",
            )?;
            check(within(f.at_s, 0.0, s.duration_s), key("at_s"), f.at_s, "0 ≤ x ≤ scenario.duration_s")?;
            check((1..=10_000).contains(&f.count), key("count"), f.count, "1 ≤ x ≤ 10000")?;
            check(within(f.translation_m, 0.0, 1e4), key("translation_m"), f.translation_m, "0 ≤ x ≤ 1e4 m")?;
            check(within(f.rotation_deg, 0.0, 180.0), key("rotation_deg"), f.rotation_deg, "0 ≤ x ≤ 180°")?;
        }

        check(!self.robots.is_empty(), "robots", "[]", "at least one [[robots]] table")?;
        check(self.robots.len() <= 64, "robots", self.robots.len(), "at most 64 robots")?;
        for (k, robot) in self.robots.iter().enumerate() {
            let key = |field: &str| format!("robots[{k}].{field}");
            let has_waypoints = robot.waypoints.len() >= 2;
            check(
                has_waypoints != robot.route.is_some(),
                key("waypoints"),
                robot.waypoints.len(),
                "≥ 2 waypoints, or a route instead (not both)",
            )?;
            for (i, p) in robot.waypoints.iter().enumerate() {
                check(
                    p.iter().all(|v| within(*v, -1e5, 1e5)),
                    key(&format!("waypoints[{i}]")),
                    format!("{p:?}"),
                    "finite, |x| ≤ 1e5 m",
                )?;
            }
            if let Some(route) = &robot.route {
                let [x0, y0, x1, y1] = route.region_m;
                check(
                    [x0, y0, x1, y1].iter().all(|v| v.is_finite()) && x1 > x0 && y1 > y0,
                    key("route.region_m"),
                    format!("{:?}", route.region_m),
                    "[x_min, y_min, x_max, y_max] with min < max",
                )?;
                check((1..=10_000).contains(&route.legs), key("route.legs"), route.legs, "1 ≤ x ≤ 10000")?;
            }
            check(within(robot.speed_mps, 0.05, 30.0), key("speed_mps"), robot.speed_mps, "0.05 ≤ x ≤ 30 m/s")?;
            check(
                within(robot.sensor_height_m, 0.1, 10.0),
                key("sensor_height_m"),
                robot.sensor_height_m,
                "0.1 ≤ x ≤ 10 m",
            )?;
            // The highest a ramp or kerb lifts a robot (hills are for campuses).
            let t = &self.terrain;
            let terrain_rise =
                if t.ramps > 0 { t.ramp_height_m } else { 0.0 } + if t.kerbs > 0 { t.kerb_height_m } else { 0.0 };
            check(
                !self.world.ceiling || robot.sensor_height_m + terrain_rise < self.world.wall_height_m - 0.3,
                key("sensor_height_m"),
                robot.sensor_height_m,
                "with world.ceiling, under it: x + the ramps' and kerbs' height < world.wall_height_m − 0.3 m",
            )?;
            check(
                within(robot.start_s, 0.0, s.duration_s - s.frame_interval_s),
                key("start_s"),
                robot.start_s,
                "0 ≤ x < scenario.duration_s",
            )?;
            if let Some(crash) = robot.crash_s {
                check(
                    within(crash, robot.start_s, s.duration_s),
                    key("crash_s"),
                    crash,
                    "start_s ≤ x ≤ scenario.duration_s",
                )?;
            }
            if let Some(restart) = robot.restart_s {
                let crash = robot.crash_s.unwrap_or(f64::INFINITY);
                check(
                    restart.is_finite() && restart > crash && restart <= s.duration_s,
                    key("restart_s"),
                    restart,
                    "crash_s < x ≤ scenario.duration_s (and crash_s set)",
                )?;
            }
            let name = self.robot_name(k);
            check(
                (0..k).all(|j| self.robot_name(j) != name),
                key("name"),
                format!("{name:?}"),
                "a name no other robot has",
            )?;
        }
        Ok(())
    }

    /// `[segmentation]`: rates and sizes in range; the confusion matrix names classes of
    /// `[fusion].classes`, with probabilities whose rows sum to 1.
    /// `odometry.source = "internal"`: an IMU, sweeps that fit the frames, and no crashes (the
    /// odometry's state is not in a snapshot yet).
    fn validate_internal_odometry(&self) -> Result<(), Failure> {
        let o = &self.odometry;
        if o.source != super::OdometrySourceSpec::Internal {
            return Ok(());
        }
        check(self.imu.enabled, "imu.enabled", self.imu.enabled, "true when odometry.source = \"internal\"")?;
        let frame = self.scenario.frame_interval_s;
        let per_frame = frame / o.sweep_interval_s;
        check(
            within(o.sweep_interval_s, 0.01, frame) && (per_frame - per_frame.round()).abs() < 1e-6,
            "odometry.sweep_interval_s",
            o.sweep_interval_s,
            "0.01 ≤ x ≤ scenario.frame_interval_s, dividing it into a whole number of sweeps",
        )?;
        check(
            self.lidar.sweep_s <= o.sweep_interval_s,
            "lidar.sweep_s",
            self.lidar.sweep_s,
            "≤ odometry.sweep_interval_s when odometry.source = \"internal\"",
        )?;
        check(
            self.imu.rate_hz * o.sweep_interval_s >= 1.0,
            "imu.rate_hz",
            self.imu.rate_hz,
            "≥ 1 / odometry.sweep_interval_s when odometry.source = \"internal\"",
        )?;
        if let Some(k) = self.robots.iter().position(|r| r.crash_s.is_some()) {
            return Err((
                format!("robots[{k}].crash_s"),
                format!("{:?}", self.robots[k].crash_s),
                "unset when odometry.source = \"internal\" (the odometry's state is not in a snapshot yet)".into(),
            ));
        }
        Ok(())
    }

    fn validate_segmentation(&self) -> Result<(), Failure> {
        let g = &self.segmentation;
        check(within(g.edge_bleed_px, 0.0, 50.0), "segmentation.edge_bleed_px", g.edge_bleed_px, "0 ≤ x ≤ 50 px")?;
        check(within(g.min_pixels, 0.0, 1e6), "segmentation.min_pixels", g.min_pixels, "0 ≤ x ≤ 1e6 px²")?;
        if let Some(r) = g.max_range_m {
            check(r.is_finite() && r > 0.0 && r <= 1e4, "segmentation.max_range_m", r, "0 < x ≤ 10000 m, or unset")?;
        }
        check(
            within(g.false_blobs_per_frame, 0.0, 100.0),
            "segmentation.false_blobs_per_frame",
            g.false_blobs_per_frame,
            "0 ≤ x ≤ 100",
        )?;
        check(within(g.false_blob_px, 1.0, 200.0), "segmentation.false_blob_px", g.false_blob_px, "1 ≤ x ≤ 200 px")?;
        check(g.people <= 1000, "segmentation.people", g.people, "≤ 1000")?;
        check(
            within(g.person_speed_mps, 0.0, 5.0),
            "segmentation.person_speed_mps",
            g.person_speed_mps,
            "0 ≤ x ≤ 5 m/s",
        )?;
        let is_class = |name: &str| self.fusion.classes.iter().any(|c| c.name == name);
        for (row, entries) in &g.confusion {
            let key = format!("segmentation.confusion.{row}");
            check(is_class(row), &key, "(row)", "a class of [fusion].classes")?;
            for (class, p) in entries {
                let key = format!("{key}.{class}");
                check(is_class(class), &key, p, "a class of [fusion].classes")?;
                check(within(*p, 0.0, 1.0), &key, p, "0 ≤ x ≤ 1")?;
            }
            let sum: f64 = entries.values().sum();
            check((sum - 1.0).abs() <= 1e-6, &key, format!("(row sum {sum})"), "probabilities summing to 1 (± 1e-6)")?;
        }
        Ok(())
    }
}
