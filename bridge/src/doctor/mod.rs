//! `sgm doctor`: a robot's inputs checked before (or beside) a mission, from a bag or a live
//! master, with a verdict per input. The same checks as the node's ([`Inputs`](crate::inputs), the
//! [`Synchroniser`], the mounts from tf, the [`Health`](crate::health::Health) findings), plus what
//! only a look at the whole stream tells: rates, sizes, which classes the label images' pixel
//! values mean under `[classes]`, and for a robot on its own odometry, its IMU as the odometry
//! would take it ([`imu`]). Plain state fed message by message ([`Doctor::observe`]); [`bag`]
//! feeds it a bag, [`live`] a running master.

pub mod bag;
mod error;
mod imu;
pub mod live;
mod report;
mod verdicts;

pub use error::DoctorError;
pub use report::{DoctorReport, InputVerdict, Verdict};

use crate::config::LabelSource;
use crate::convert::time::Epoch;
use crate::error::InputError;
use crate::health::{judge_whole_stream, HealthConfig, TopicTally};
use crate::inputs::{Inputs, Payload};
use crate::node::NodeConfig;
use crate::sync::Synchroniser;
use imu::ImuTally;
use sgm_actors::config::OdometrySource;
use sgm_model::perception::classes::ClassTable;
use sgm_model::perception::label_map::{LabelMap, Mapped};
use sgm_model::perception::projection::CameraModel;
use sgm_model::scene_graph::Stamp;
use std::collections::BTreeMap;

/// Every this-many-th pixel of a label image is counted in the class shares.
const PIXEL_SAMPLE: usize = 7;

/// Stamps of one input.
#[derive(Clone, Debug, Default)]
struct Stamps {
    first: Option<Stamp>,
    last: Option<Stamp>,
    count: u64,
}

impl Stamps {
    fn add(&mut self, t: Stamp) {
        self.first = Some(self.first.map_or(t, |f| f.min(t)));
        self.last = Some(self.last.map_or(t, |l| l.max(t)));
        self.count += 1;
    }

    /// Messages per second over the span of their stamps.
    fn rate_hz(&self) -> Option<f64> {
        let span = self.last? - self.first?;
        (self.count > 1 && span > 0.0).then(|| (self.count - 1) as f64 / span)
    }
}

/// What was seen of the label images' pixel values (a sample), by meaning.
#[derive(Clone, Debug, Default)]
struct PixelShares {
    /// Sampled pixels per SGM class name.
    classes: BTreeMap<String, u64>,
    /// Of an SGM class that makes objects (`fusion.classes`' `object`).
    object_pixels: u64,
    /// No class: an ignore value or a segmenter class no group takes.
    ignored: u64,
    /// Beyond `[classes]`: per pixel value (the first 32).
    unknown: BTreeMap<u16, u64>,
    unknown_pixels: u64,
    total: u64,
    /// Image sizes seen (width, height) → images.
    sizes: BTreeMap<(u32, u32), u64>,
}

/// The doctor's state.
pub struct Doctor {
    robot: String,
    labels: LabelSource,
    /// The input topics, as configured (`{robot}`, `{id}` filled in).
    topics: crate::config::RosTopics,
    /// What the caller found beside the messages (a topic nobody publishes), per input.
    notes: BTreeMap<String, Vec<(Verdict, String)>>,
    sync: Synchroniser,
    inputs: Inputs,
    map: LabelMap,
    classes: ClassTable,
    tallies: BTreeMap<String, TopicTally>,
    stamps: BTreeMap<&'static str, Stamps>,
    points: u64,
    pixels: PixelShares,
    camera: Option<CameraModel>,
    epoch: Option<Epoch>,
    frames: u64,
    /// Clouds still waiting for partners when a live window closed, and clouds heard before
    /// the window's first odometry pose (not judged: the window cut them off).
    pending: u64,
    /// Listening to streams that began before: clouds before the first pose are not judged.
    live: bool,
    /// What places a cloud has been heard: an odometry pose (external), an IMU sample
    /// (internal).
    pose_source_heard: bool,
    health: HealthConfig,
    /// Where the robot's odometry comes from: `odometry` or `imu` is the input it needs.
    source: OdometrySource,
    imu: ImuTally,
    /// Clouds with no per-point time (the robot's own odometry uses them as they come).
    untimed_clouds: u64,
}

impl Doctor {
    pub fn new(config: &NodeConfig) -> Result<Self, DoctorError> {
        let robot = config.robot.robot.name.clone();
        let id = config.robot.robot.id;
        let (classes, map) = config.robot.class_tables()?;
        let colours = config.robot.colour_ids()?;
        let inputs = Inputs::new(&config.ros, &robot, id).with_colours(colours);
        // The synchroniser the node would run: clouds meet the odometry topic, or the IMU of
        // the robot's own odometry.
        let source = config.robot.odometry.source;
        let sync = Synchroniser::for_robot(&config.ros, &inputs, source)?;
        let mut tallies = BTreeMap::new();
        let mut expected = vec!["points", Self::pose_input(source)];
        if config.ros.labels == LabelSource::Image {
            expected.extend(["labels", "camera_info"]);
        }
        for input in expected {
            tallies.insert(input.to_string(), TopicTally::default());
        }
        let t = &config.ros.topics;
        let resolve = |name: &str| crate::config::RosConfig::resolve(name, &robot, id);
        let topics = crate::config::RosTopics {
            points: resolve(&t.points),
            labels: resolve(&t.labels),
            camera_info: resolve(&t.camera_info),
            odometry: resolve(&t.odometry),
            imu: resolve(&t.imu),
            ..t.clone()
        };
        Ok(Self {
            robot,
            labels: config.ros.labels,
            topics,
            notes: BTreeMap::new(),
            sync,
            inputs,
            map,
            classes,
            tallies,
            stamps: BTreeMap::new(),
            points: 0,
            pixels: PixelShares::default(),
            camera: None,
            epoch: None,
            frames: 0,
            pending: 0,
            live: false,
            pose_source_heard: false,
            health: config.ros.health.clone(),
            source,
            imu: ImuTally::new(config.robot.odometry.estimator.imu_limits),
            untimed_clouds: 0,
        })
    }

    /// The input that places clouds: `odometry` (external) or `imu` (the robot's own).
    pub fn pose_input(source: OdometrySource) -> &'static str {
        match source {
            OdometrySource::External => "odometry",
            OdometrySource::Internal => "imu",
        }
    }

    /// Where the robot's odometry comes from.
    pub fn source(&self) -> OdometrySource {
        self.source
    }

    /// Listening to live streams that began before (a window, not a whole mission).
    pub fn live(mut self) -> Self {
        self.live = true;
        self
    }

    /// The checks of this robot's inputs (for feeding messages through them).
    pub fn inputs(&self) -> &Inputs {
        &self.inputs
    }

    /// The input topics, as configured.
    pub fn topics(&self) -> &crate::config::RosTopics {
        &self.topics
    }

    /// Something the caller found about `input` beside its messages, with its weight.
    pub fn note(&mut self, input: &str, verdict: Verdict, text: String) {
        self.notes.entry(input.to_string()).or_default().push((verdict, text));
    }

    /// One message on `input` (`points`, `labels`, `camera_info`, `odometry`, `imu`, `tf`,
    /// `tf_static`, `clock`), checked or refused.
    pub fn observe(&mut self, input: &str, result: Result<Payload, InputError>) {
        let tally = self.tallies.entry(input.to_string()).or_default();
        let payload = match result {
            Ok(payload) => {
                tally.accepted += 1;
                payload
            }
            Err(e) => {
                tally.refused += 1;
                tally.last_refusal = Some(e.to_string());
                return;
            }
        };
        let stamp = match &payload {
            Payload::Cloud(t, _) | Payload::Image(t, ..) | Payload::Odometry(t, _) | Payload::Imu(t, _) => Some(*t),
            _ => None,
        };
        if let Some(t) = stamp {
            let epoch = *self.epoch.get_or_insert_with(|| Epoch::at(t));
            if let Some(name) = static_name(input) {
                self.stamps.entry(name).or_default().add(epoch.stamp(t));
            }
        }
        match &payload {
            Payload::Odometry(..) if self.source == OdometrySource::External => self.pose_source_heard = true,
            Payload::Imu(..) if self.source == OdometrySource::Internal => self.pose_source_heard = true,
            // A live window opened between what places this cloud (its odometry, the IMU over
            // its sweep) and the cloud: it cannot be placed, through no fault of the streams.
            Payload::Cloud(..) if self.live && !self.pose_source_heard => {
                self.pending += 1;
                return;
            }
            _ => {}
        }
        match &payload {
            Payload::Cloud(_, scan) => {
                self.points += scan.points.len() as u64;
                self.untimed_clouds += u64::from(scan.times.is_none());
            }
            Payload::Imu(t, reading) => {
                let epoch = self.epoch.unwrap_or(Epoch { sec: 0 });
                self.imu.add(epoch.stamp(*t), reading);
            }
            Payload::Image(_, image, _) => self.count_pixels(image),
            Payload::CameraInfo(camera) => self.camera = Some(camera.clone()),
            _ => {}
        }
        let epoch = self.epoch.unwrap_or(Epoch { sec: 0 });
        self.sync.feed(epoch, payload);
        self.frames += self.sync.ready().len() as u64;
    }

    fn count_pixels(&mut self, image: &sgm_model::perception::projection::LabelImage) {
        let p = &mut self.pixels;
        *p.sizes.entry((image.width, image.height)).or_default() += 1;
        for &pixel in image.labels.iter().step_by(PIXEL_SAMPLE) {
            p.total += 1;
            match self.map.get(pixel) {
                Mapped::Class(label) => {
                    let class = self.classes.get(label);
                    if class.is_some_and(|c| c.object) {
                        p.object_pixels += 1;
                    }
                    *p.classes
                        .entry(class.map_or_else(|| format!("id {}", label.0), |c| c.name.clone()))
                        .or_default() += 1;
                }
                Mapped::Ignored => p.ignored += 1,
                Mapped::Unknown => {
                    p.unknown_pixels += 1;
                    if p.unknown.len() < 32 || p.unknown.contains_key(&pixel) {
                        *p.unknown.entry(pixel).or_default() += 1;
                    }
                }
            }
        }
    }

    /// The verdicts: `ended` when the input has ended (a bag: every waiting cloud is settled),
    /// not when a live window closed on streams that go on (clouds still waiting for their
    /// partners are left out). `source` names what was read.
    pub fn finish(mut self, source: String, ended: bool) -> DoctorReport {
        let epoch = self.epoch.unwrap_or(Epoch { sec: 0 });
        if ended {
            self.frames += self.sync.finish(epoch).len() as u64;
        } else {
            self.pending += self.sync.pending() as u64;
        }
        let span = self.stamps.values().filter_map(|s| Some((s.first?, s.last?))).fold(None, |acc, (f, l)| match acc {
            None => Some((f, l)),
            Some((a, b)) => Some((f64::min(a, f), f64::max(b, l))),
        });
        let (first, last) = span.unwrap_or((0.0, 0.0));
        let findings = judge_whole_stream(&self.health, &self.sync, &self.tallies, None, first, last);
        let tf = self.sync.tf();
        let inputs = verdicts::judge(&self, &tf, &findings);
        let verdict = inputs.iter().map(|v| v.verdict).max().unwrap_or(Verdict::Fail);
        DoctorReport { robot: self.robot, source, span_s: last - first, inputs, findings, verdict }
    }
}

/// The static name of an input (for the stamps map).
fn static_name(input: &str) -> Option<&'static str> {
    ["points", "labels", "camera_info", "odometry", "imu"].into_iter().find(|n| *n == input)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::LabelSource;
    use crate::convert::cloud::Scan;
    use crate::tf::{TfBatch, TfTransform};
    use nalgebra::Point3;
    use sgm_model::geometry::Pose3;
    use sgm_model::perception::projection::LabelImage;

    fn config() -> NodeConfig {
        let mut config = NodeConfig::default();
        config.robot.robot.name = "alpha".into();
        config.ros.timeline.confirm_messages = 1;
        config
    }

    fn at(t: f64) -> rosrust::Time {
        Epoch { sec: 100 }.time(t)
    }

    fn camera(width: u32) -> CameraModel {
        CameraModel { width, height: 2, fx: 1.0, fy: 1.0, cx: 1.0, cy: 1.0, distortion: [0.0; 5] }
    }

    /// Ten frames of a robot whose camera looks along +x at a tree (SGM class 2) and ground (0),
    /// its mount on tf_static; `image_width` and `pixel` let a test spoil them.
    fn feed(d: &mut Doctor, image_width: u32, pixel: u16) {
        let optical = sgm_model::perception::projection::optical_from_forward_body().inverse();
        let mount = TfTransform {
            stamp: rosrust::Time::default(),
            parent: "alpha/base_link".into(),
            child: "alpha/camera".into(),
            parent_from_child: optical,
        };
        d.observe("tf_static", Ok(Payload::Tf(TfBatch { is_static: true, transforms: vec![mount], refused: vec![] })));
        d.observe("camera_info", Ok(Payload::CameraInfo(camera(8))));
        for k in 0..10 {
            let t = f64::from(k) * 0.1;
            let pixels = (0..image_width * 2).map(|i| if i % 2 == 0 { 2 } else { pixel }).collect();
            let labels = LabelImage::new(image_width, 2, pixels);
            d.observe("odometry", Ok(Payload::Odometry(at(t), Pose3::translation(t, 0.0, 0.0))));
            d.observe("labels", Ok(Payload::Image(at(t), labels.unwrap(), Default::default())));
            let scan =
                Scan { points: vec![Point3::new(5.0, 0.0, 0.0); 32], labels: None, dropped_non_finite: 0, times: None };
            d.observe("points", Ok(Payload::Cloud(at(t), scan)));
        }
    }

    fn verdicts(report: &DoctorReport) -> Vec<(&str, Verdict)> {
        report.inputs.iter().map(|v| (v.input.as_str(), v.verdict)).collect()
    }

    #[test]
    fn healthy_inputs_are_ok() {
        let mut d = Doctor::new(&config()).unwrap();
        feed(&mut d, 8, 0);
        let report = d.finish("test".into(), true);
        assert_eq!(report.verdict, Verdict::Ok, "{}", report.text());
        assert!(report.text().contains("10 clouds on points, 10.0 Hz, 32 points each"), "{}", report.text());
        assert!(report.text().contains("camera from tf (alpha/base_link ← alpha/camera)"), "{}", report.text());
        assert!(report.text().contains("10 of 10 clouds assembled"), "{}", report.text());
    }

    /// No odometry, refused labels, images of another size than camera_info, unknown ids:
    /// each named on its input.
    #[test]
    fn broken_inputs_are_named() {
        let mut d = Doctor::new(&config()).unwrap();
        d.observe("labels", Err(InputError::Encoding("yuv422".into())));
        feed(&mut d, 9, 999);
        let mut no_odometry = Doctor::new(&config()).unwrap();
        no_odometry.observe(
            "points",
            Ok(Payload::Cloud(at(0.0), Scan { points: vec![], labels: None, dropped_non_finite: 0, times: None })),
        );
        let report = no_odometry.finish("test".into(), true);
        assert_eq!(report.verdict, Verdict::Fail);
        let odometry = report.inputs.iter().find(|v| v.input == "odometry").unwrap();
        assert_eq!(odometry.problems[0], "no message on odometry");

        let report = d.finish("test".into(), true);
        let text = report.text();
        assert_eq!(
            verdicts(&report),
            [
                ("points", Verdict::Ok),
                ("odometry", Verdict::Ok),
                ("labels", Verdict::Warn),
                ("camera_info", Verdict::Fail),
                ("tf", Verdict::Ok),
                ("frames", Verdict::Ok),
                ("classes", Verdict::Warn),
            ],
            "{text}"
        );
        assert!(text.contains("1 of 11 messages on labels refused (last: unsupported encoding `yuv422`"), "{text}");
        assert!(text.contains("label images are not 8×2 as camera_info says"), "{text}");
        assert!(text.contains("carry ids [classes] does not know (999)"), "{text}");
    }

    /// A live window opens after a cloud's odometry, or closes while the last cloud still waits
    /// for its odometry: neither is a drop.
    #[test]
    fn a_cloud_waiting_when_a_live_window_closes_is_not_judged() {
        let last_cloud = |d: &mut Doctor| {
            let scan =
                Scan { points: vec![Point3::new(5.0, 0.0, 0.0); 32], labels: None, dropped_non_finite: 0, times: None };
            d.observe("points", Ok(Payload::Cloud(at(1.05), scan)));
        };
        let mut live = Doctor::new(&config()).unwrap().live();
        // The window opens between a frame's odometry and its cloud: that cloud is not judged.
        let early =
            Scan { points: vec![Point3::new(5.0, 0.0, 0.0); 32], labels: None, dropped_non_finite: 0, times: None };
        live.observe("points", Ok(Payload::Cloud(at(-0.1), early)));
        feed(&mut live, 8, 0);
        last_cloud(&mut live);
        let report = live.finish("test".into(), false);
        assert_eq!(report.verdict, Verdict::Ok, "{}", report.text());
        let mut ended = Doctor::new(&config()).unwrap();
        feed(&mut ended, 8, 0);
        last_cloud(&mut ended);
        let report = ended.finish("test".into(), true);
        let frames = report.inputs.iter().find(|v| v.input == "frames").unwrap();
        assert_eq!(frames.verdict, Verdict::Warn, "{}", report.text());
    }

    /// The robot's own odometry: the doctor asks for the IMU, not an odometry topic, and names
    /// what the odometry would drop or coast across, and clouds it could not deskew.
    #[test]
    fn an_imu_stream_is_judged_as_the_odometry_would_take_it() {
        let mut config = config();
        config.robot.odometry.source = OdometrySource::Internal;
        config.ros.labels = LabelSource::Cloud;
        let still = crate::convert::imu::ImuReading {
            angular_velocity: nalgebra::Vector3::zeros(),
            linear_acceleration: nalgebra::Vector3::new(0.0, 0.0, 9.81),
        };
        let run = |spoil: bool| {
            let mut d = Doctor::new(&config).unwrap();
            for k in 0..=400u32 {
                let t = f64::from(k) * 0.005;
                if k % 20 == 0 && k < 400 {
                    let times = (!spoil || k % 40 == 0).then(|| (0..32).map(|i| i as f32 * 0.003).collect());
                    let scan = Scan {
                        points: vec![Point3::new(5.0, 0.0, 0.0); 32],
                        labels: Some(vec![1; 32]),
                        dropped_non_finite: 0,
                        times,
                    };
                    d.observe("points", Ok(Payload::Cloud(at(t), scan)));
                }
                // Spoilt: 0.5–0.6 s silent, one sample from the past, one beyond the gyro's range.
                if spoil && (100..120).contains(&k) {
                    continue;
                }
                let reading = match (spoil, k) {
                    (true, 150) => crate::convert::imu::ImuReading {
                        angular_velocity: nalgebra::Vector3::new(40.0, 0.0, 0.0),
                        ..still
                    },
                    _ => still,
                };
                d.observe("imu", Ok(Payload::Imu(at(t), reading)));
                if spoil && k == 200 {
                    d.observe("imu", Ok(Payload::Imu(at(0.5), still)));
                }
            }
            d.finish("test".into(), true)
        };
        let report = run(false);
        assert_eq!(report.verdict, Verdict::Ok, "{}", report.text());
        assert!(!report.inputs.iter().any(|v| v.input == "odometry"), "{}", report.text());
        assert!(report.text().contains("401 samples on imu, 200.0 Hz"), "{}", report.text());
        assert!(report.text().contains("20 of 20 clouds assembled into frames (0 of them sweeps"), "{}", report.text());

        let report = run(true);
        let text = report.text();
        assert_eq!(
            verdicts(&report),
            [("points", Verdict::Warn), ("imu", Verdict::Warn), ("tf", Verdict::Ok), ("frames", Verdict::Ok)],
            "{text}"
        );
        assert!(text.contains("10 of 20 clouds carry no per-point time"), "{text}");
        assert!(text.contains("1 samples at the gyro's"), "{text}");
        assert!(text.contains("1 samples not after the one before"), "{text}");
        assert!(text.contains("1 intervals longer than 0.05 s (the longest 0.105 s)"), "{text}");
    }
}
