//! The doctor's verdict per input, from what it observed: FAIL when the input cannot work (no
//! message, all refused, a mount the frames need is unknown, no frame assembled, no pixel of
//! any object class), WARN when it works worse than it should (some refused, frames dropped,
//! few points in the image, unknown ids, a pinned mount tf contradicts), OK otherwise. Every
//! health finding lifts the input it is about to WARN at least, quoted there (`input_refused`
//! is the input's own refusal line).

use super::{Doctor, InputVerdict, Verdict};
use crate::config::LabelSource;
use crate::health::{Check, Finding};
use crate::tf::listener::TfStatus;
use crate::tf::mounts::MountSource;
use sgm_actors::config::OdometrySource;

/// A share as a percentage with one decimal.
fn percent(part: u64, whole: u64) -> String {
    if whole == 0 {
        "0 %".into()
    } else {
        format!("{:.1} %", 100.0 * part as f64 / whole as f64)
    }
}

struct Judged {
    verdict: Verdict,
    problems: Vec<String>,
}

impl Judged {
    fn new() -> Self {
        Self { verdict: Verdict::Ok, problems: Vec::new() }
    }

    fn warn(&mut self, problem: String) {
        self.verdict = self.verdict.max(Verdict::Warn);
        self.problems.push(problem);
    }

    fn fail(&mut self, problem: String) {
        self.verdict = Verdict::Fail;
        self.problems.push(problem);
    }

    fn done(mut self, d: &Doctor, input: &str, seen: String) -> InputVerdict {
        for (verdict, text) in d.notes.get(input).into_iter().flatten() {
            self.verdict = self.verdict.max(*verdict);
            self.problems.push(text.clone());
        }
        InputVerdict { input: input.into(), verdict: self.verdict, seen, problems: self.problems }
    }
}

/// The messages of one topic: none, all refused, some refused.
fn messages(d: &Doctor, input: &str, topic: &str) -> (Judged, u64) {
    let mut j = Judged::new();
    let tally = d.tallies.get(input).cloned().unwrap_or_default();
    let last = tally.last_refusal.as_deref().unwrap_or("no reason kept");
    match (tally.accepted, tally.refused) {
        (0, 0) => j.fail(format!("no message on {topic}")),
        (0, r) => j.fail(format!("all {r} messages on {topic} refused (last: {last})")),
        (_, 0) => {}
        (a, r) => j.warn(format!("{r} of {} messages on {topic} refused (last: {last})", a + r)),
    }
    (j, tally.accepted)
}

fn rate(d: &Doctor, input: &str) -> String {
    d.stamps.get(input).and_then(|s| s.rate_hz()).map_or("rate unknown".into(), |hz| format!("{hz:.1} Hz"))
}

/// Health findings about `checks` lift `j` to WARN, quoted.
fn lift(j: &mut Judged, findings: &[Finding], checks: &[Check]) {
    for f in findings.iter().filter(|f| checks.contains(&f.check)) {
        j.warn(format!("{}; likely cause: {}", f.detail, f.likely_cause));
    }
}

/// The odometry topic (external odometry).
fn odometry_verdict(d: &Doctor, tf: &TfStatus, findings: &[Finding]) -> InputVerdict {
    let topics = &d.topics;
    let (mut j, poses) = messages(d, "odometry", &topics.odometry);
    lift(&mut j, findings, &[Check::NoOdometry, Check::OdometryDisagreesWithTf]);
    let compared = if tf.counts.odometry_compared > 0 {
        format!(
            "; against tf's {} → {}: {} compared, {} apart at most",
            tf.world_frame,
            tf.body_frame,
            tf.counts.odometry_compared,
            format_args!("{:.3} m", tf.counts.odometry_max_m)
        )
    } else {
        String::new()
    };
    j.done(
        d,
        "odometry",
        format!(
            "{poses} poses on {}, {}, {} → {}{compared}",
            topics.odometry,
            rate(d, "odometry"),
            d.inputs.world_frame(),
            d.inputs.body_frame()
        ),
    )
}

/// The IMU (the robot's own odometry): what its screen would drop, and the gaps it would
/// coast across.
fn imu_verdict(d: &Doctor, findings: &[Finding]) -> InputVerdict {
    let topic = &d.topics.imu;
    let (mut j, samples) = messages(d, "imu", topic);
    lift(&mut j, findings, &[Check::ImuShort]);
    let t = &d.imu;
    let limits = t.limits();
    if t.saturated > 0 {
        j.warn(format!(
            "{} samples at the gyro's ({} rad/s) or the accelerometer's ({} m/s²) range: used clipped to it, \
             the velocity re-learnt from the scans (odometry.estimator.imu_limits)",
            t.saturated, limits.gyro_range_rad_s, limits.accel_range_mps2
        ));
    }
    if t.non_finite > 0 {
        j.warn(format!("{} samples with a NaN or infinite value: dropped", t.non_finite));
    }
    if t.out_of_order > 0 {
        j.warn(format!(
            "{} samples not after the one before (time going backwards, or a repeat): dropped",
            t.out_of_order
        ));
    }
    if t.gaps > 0 {
        j.warn(format!(
            "{} intervals longer than {} s (the longest {:.3} s): the odometry coasts across them \
             (odometry.estimator.imu_limits.max_gap_s)",
            t.gaps, limits.max_gap_s, t.longest_interval_s
        ));
    }
    if samples > 0 && t.kept == 0 {
        j.fail(format!("none of the {samples} samples on {topic} is usable"));
    }
    j.done(
        d,
        "imu",
        format!(
            "{samples} samples on {topic}, {}, frame {}; the longest interval {:.1} ms",
            rate(d, "imu"),
            d.inputs.imu_frame(),
            1e3 * t.longest_interval_s
        ),
    )
}

pub(super) fn judge(d: &Doctor, tf: &TfStatus, findings: &[Finding]) -> Vec<InputVerdict> {
    let topics = &d.topics;
    let image = d.labels == LabelSource::Image;
    let mut out = Vec::new();

    let internal = d.source == OdometrySource::Internal;
    let (mut j, clouds) = messages(d, "points", &topics.points);
    if internal && d.untimed_clouds > 0 {
        j.warn(format!(
            "{} of {clouds} clouds carry no per-point time: the odometry registers them as they come, \
             not deskewed (the driver's time field, e.g. `t` or `time`, is missing)",
            d.untimed_clouds
        ));
    }
    let mean = d.points.checked_div(clouds).unwrap_or(0);
    out.push(j.done(
        d,
        "points",
        format!(
            "{clouds} clouds on {}, {}, {mean} points each, frame {}",
            topics.points,
            rate(d, "points"),
            d.inputs.lidar_frame()
        ),
    ));

    out.push(if internal { imu_verdict(d, findings) } else { odometry_verdict(d, tf, findings) });

    if image {
        let (mut j, images) = messages(d, "labels", &topics.labels);
        lift(&mut j, findings, &[Check::NoLabels]);
        let sizes: Vec<String> = d.pixels.sizes.keys().map(|(w, h)| format!("{w}×{h}")).collect();
        let s = &d.sync.counts;
        if s.unknown_colour_pixels > 0 {
            let colours: Vec<&String> = s.unknown_colours.keys().collect();
            j.warn(format!(
                "{} pixels of colours no palette entry has ({colours:?}): map them in [classes.palette]",
                s.unknown_colour_pixels
            ));
        }
        out.push(j.done(
            d,
            "labels",
            format!(
                "{images} images on {}, {}, {}, frame {}; nearest to their clouds within {} ms",
                topics.labels,
                rate(d, "labels"),
                if sizes.is_empty() { "no size".into() } else { sizes.join(", ") },
                d.inputs.camera_frame(),
                s.label_skew_max_ms
            ),
        ));

        let (mut j, infos) = messages(d, "camera_info", &topics.camera_info);
        let seen = match &d.camera {
            Some(c) => {
                if d.pixels.sizes.keys().any(|&(w, h)| (w, h) != (c.width, c.height)) {
                    j.fail(format!(
                        "label images are not {}×{} as camera_info says: every such frame is refused by Fusion",
                        c.width, c.height
                    ));
                }
                format!("{infos} on {}, {}×{}, fx {:.1}, fy {:.1}", topics.camera_info, c.width, c.height, c.fx, c.fy)
            }
            None => format!("{infos} on {}", topics.camera_info),
        };
        out.push(j.done(d, "camera_info", seen));
    }

    let mut j = Judged::new();
    let mut mounts = Vec::new();
    for m in tf
        .mounts
        .iter()
        .filter(|m| m.sensor == "lidar" || (image && m.sensor == "camera") || (internal && m.sensor == "imu"))
    {
        let how = match m.source {
            MountSource::SameFrame => "the body frame".to_string(),
            MountSource::Tf => format!("from tf ({} ← {})", m.body_frame, m.sensor_frame),
            MountSource::Config => format!("from {}", m.key),
            MountSource::Missing => {
                j.fail(format!(
                    "the {} mount {} ← {} is unknown: {}; publish it on tf or pin {}",
                    m.sensor,
                    m.body_frame,
                    m.sensor_frame,
                    m.tf_error.as_deref().unwrap_or("not in tf"),
                    m.key
                ));
                "unknown".to_string()
            }
        };
        mounts.push(format!("{} {how}", m.sensor));
    }
    lift(&mut j, findings, &[Check::MountDisagrees]);
    if tf.counts.refused > 0 {
        j.warn(format!(
            "{} transforms refused (last: {})",
            tf.counts.refused,
            tf.counts.last_refusal.as_deref().unwrap_or("no reason kept")
        ));
    }
    out.push(j.done(d, "tf", format!("{} transforms; {}", tf.counts.transforms, mounts.join(", "))));

    let mut j = Judged::new();
    let s = &d.sync.counts;
    // Clouds still waiting for their partners when a live window closed are not judged.
    let clouds = d.tallies.get("points").map_or(0, |t| t.accepted).saturating_sub(d.pending);
    let own = if internal { format!(", no_imu_mount {}", s.no_imu_mount) } else { String::new() };
    if clouds > 0 && d.frames == 0 {
        j.fail(format!(
            "none of {clouds} clouds became a frame: no_odometry {}, no_image {}, no_camera_info {}, no_lidar_mount {}{own}",
            s.no_odometry, s.no_image, s.no_camera_info, s.no_lidar_mount
        ));
    } else if d.frames < clouds {
        j.warn(format!(
            "{} of {clouds} clouds dropped (no_odometry {}, no_image {}, no_camera_info {}, no_lidar_mount {}, out_of_order {}{own})",
            clouds - d.frames,
            s.no_odometry,
            s.no_image,
            s.no_camera_info,
            s.no_lidar_mount,
            s.out_of_order
        ));
    }
    if internal && s.imu_short > 0 {
        j.warn(format!(
            "{} clouds handed on before the IMU covered their sweep (ros.sync.max_wait_s): the odometry coasted",
            s.imu_short
        ));
    }
    lift(&mut j, findings, &[Check::NoMount, Check::PointsOutsideImage]);
    let projected = if image {
        format!(
            "; {} unlabelled, {} motion-compensated; {} of the sampled points in the label image",
            s.unlabelled,
            s.compensated,
            percent(s.sampled_in_image, s.sampled_points)
        )
    } else {
        String::new()
    };
    let sweeps =
        if internal { format!(" ({} of them sweeps for the odometry alone)", s.sweeps) } else { String::new() };
    out.push(j.done(d, "frames", format!("{} of {clouds} clouds assembled into frames{sweeps}{projected}", d.frames)));

    if image {
        let mut j = Judged::new();
        let p = &d.pixels;
        if p.total > 0 && p.object_pixels == 0 {
            j.fail(format!(
                "no pixel means a class that makes objects under [classes] (segmenter {}): is classes.segmenter the \
                 network's table?",
                d.map.segmenter()
            ));
        }
        if p.unknown_pixels * 100 > p.total {
            let ids: Vec<String> = p.unknown.keys().map(u16::to_string).collect();
            j.warn(format!(
                "{} of the pixels carry ids [classes] does not know ({}): another segmenter's table?",
                percent(p.unknown_pixels, p.total),
                ids.join(", ")
            ));
        }
        let mut by_share: Vec<(&String, &u64)> = p.classes.iter().collect();
        by_share.sort_by(|a, b| b.1.cmp(a.1).then(a.0.cmp(b.0)));
        let top: Vec<String> =
            by_share.iter().take(6).map(|(name, n)| format!("{name} {}", percent(**n, p.total))).collect();
        out.push(j.done(
            d,
            "classes",
            format!(
                "segmenter {}: {} of the pixels of object classes; {}; no class {}, unknown {}",
                d.map.segmenter(),
                percent(p.object_pixels, p.total),
                if top.is_empty() { "no class seen".into() } else { top.join(", ") },
                percent(p.ignored, p.total),
                percent(p.unknown_pixels, p.total)
            ),
        ));
    }
    out
}
