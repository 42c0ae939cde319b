//! The bridge's cost per LiDAR frame of 20 000 points (issue 7's target: ≤ 2 ms), from the bytes
//! a subscriber receives to the frame handed to the robot:
//! - `cloud_in_20k/{velodyne,sgm_labelled}`: decode a PointCloud2 (rosrust) and check and read
//!   it (`Inputs::cloud`), for a Velodyne layout (x y z intensity ring time, 22-byte points) and
//!   ours (x y z rgb label, labels in the cloud);
//! - `frame_in_20k`: one whole frame: odometry, a 640 × 480 mono16 label image and the Velodyne
//!   cloud, each decoded and checked, fed to the synchroniser, and the frame assembled;
//! - `label_image_in_640x480/{mono16_ids,rgb8_ade20k_palette}`: a label image decoded and read
//!   (`Inputs::image`) as class ids, and painted in ADE20K's palette (read back colour by colour).
//!
//! `benches/compare_rospy.sh` runs this beside rospy's decode and `point_cloud2.read_points`.

use criterion::{criterion_group, criterion_main, BatchSize, Criterion, Throughput};
use rosrust::RosMsg;
use sgm_bridge::config::{LabelSource, RosConfig};
use sgm_bridge::convert::cloud::cloud_msg;
use sgm_bridge::convert::geometry::odometry_msg;
use sgm_bridge::convert::image::{camera_info_msg, label_image_msg};
use sgm_bridge::convert::time::{Epoch, SCENARIO_EPOCH};
use sgm_bridge::inputs::Inputs;
use sgm_bridge::msg::{nav_msgs, sensor_msgs, std_msgs};
use sgm_bridge::sync::Synchroniser;
use sgm_model::geometry::Pose3;
use sgm_model::perception::projection::{CameraModel, LabelImage};
use std::hint::black_box;

const POINTS: usize = 20_000;
const FLOAT32: u8 = 7;
const UINT16: u8 = 4;

fn header(frame: &str, t: f64) -> std_msgs::Header {
    std_msgs::Header { seq: 0, stamp: SCENARIO_EPOCH.time(t), frame_id: frame.into() }
}

/// Points of a 16-ring scan around the sensor, 1250 per ring.
fn scan_points() -> Vec<nalgebra::Point3<f32>> {
    (0..POINTS)
        .map(|k| {
            let (ring, step) = ((k % 16) as f32, (k / 16) as f32);
            let (azimuth, elevation) = (step * std::f32::consts::TAU / 1250.0, (ring - 7.5).to_radians() * 2.0);
            let range = 5.0 + (k % 97) as f32 * 0.3;
            nalgebra::Point3::new(
                range * elevation.cos() * azimuth.cos(),
                range * elevation.cos() * azimuth.sin(),
                range * elevation.sin(),
            )
        })
        .collect()
}

/// The points in a Velodyne driver's layout, little-endian.
fn velodyne_cloud(frame: &str, t: f64) -> sensor_msgs::PointCloud2 {
    let layout =
        [("x", FLOAT32), ("y", FLOAT32), ("z", FLOAT32), ("intensity", FLOAT32), ("ring", UINT16), ("time", FLOAT32)];
    let mut fields = Vec::new();
    let mut offset = 0;
    for (name, datatype) in layout {
        fields.push(sensor_msgs::PointField { name: name.into(), offset, datatype, count: 1 });
        offset += if datatype == UINT16 { 2 } else { 4 };
    }
    let mut data = Vec::with_capacity(POINTS * offset as usize);
    for (k, p) in scan_points().iter().enumerate() {
        for v in [p.x, p.y, p.z, 40.0] {
            data.extend_from_slice(&v.to_le_bytes());
        }
        data.extend_from_slice(&((k % 16) as u16).to_le_bytes());
        data.extend_from_slice(&(k as f32 * 5e-6).to_le_bytes());
    }
    sensor_msgs::PointCloud2 {
        header: header(frame, t),
        height: 1,
        width: POINTS as u32,
        fields,
        is_bigendian: false,
        point_step: offset,
        row_step: offset * POINTS as u32,
        data,
        is_dense: true,
    }
}

/// A message's serialised body, as a subscriber receives it (no length prefix).
fn bytes<M: RosMsg>(m: &M) -> Vec<u8> {
    let mut out = Vec::new();
    m.encode(&mut out).unwrap_or_else(|e| panic!("{e}"));
    out
}

fn decode<M: RosMsg>(b: &[u8]) -> M {
    M::decode(b).unwrap_or_else(|e| panic!("the bench's own message does not decode: {e}"))
}

fn clouds(c: &mut Criterion) {
    let ros = RosConfig::default();
    let mut labelled_config = ros.clone();
    labelled_config.labels = LabelSource::Cloud;
    let velodyne = bytes(&velodyne_cloud("alpha/base_link", 1.0));
    let labels: Vec<u16> = (0..POINTS).map(|k| (k % 7) as u16).collect();
    let ours = bytes(&cloud_msg(header("alpha/base_link", 1.0), &scan_points(), Some(&labels), |_| [9, 9, 9]));
    let mut group = c.benchmark_group("cloud_in_20k");
    group.throughput(Throughput::Elements(POINTS as u64));
    let inputs = Inputs::new(&ros, "alpha", 1);
    group.bench_function("velodyne", |b| {
        b.iter(|| inputs.cloud(&decode::<sensor_msgs::PointCloud2>(black_box(&velodyne))))
    });
    let labelled = Inputs::new(&labelled_config, "alpha", 1);
    group.bench_function("sgm_labelled", |b| {
        b.iter(|| labelled.cloud(&decode::<sensor_msgs::PointCloud2>(black_box(&ours))))
    });
    group.finish();
}

fn frames(c: &mut Criterion) {
    let ros = RosConfig::default();
    let inputs = Inputs::new(&ros, "alpha", 1);
    let camera =
        CameraModel { width: 640, height: 480, fx: 500.0, fy: 500.0, cx: 320.0, cy: 240.0, distortion: [0.0; 5] };
    let image =
        LabelImage::new(640, 480, (0..640 * 480).map(|k| (k % 300) as u16).collect()).unwrap_or_else(|e| panic!("{e}"));
    let info = camera_info_msg(header("alpha/camera", 0.0), &camera);
    let epoch = Epoch { sec: SCENARIO_EPOCH.sec };
    let mut sync = Synchroniser::new(ros.sync.clone(), LabelSource::Image, Pose3::identity());
    if let Ok(payload) = inputs.camera_info(&info) {
        sync.feed(epoch, payload);
    }
    // Each iteration is the next frame, 0.1 s later: the synchroniser runs in steady state.
    let mut t = 0.0;
    let mut next_frame = || {
        t += 0.1;
        let pose = Pose3::translation(t, 0.0, 0.0);
        (
            bytes(&odometry_msg(header("alpha/odom", t), "alpha/base_link", &pose)),
            bytes(&label_image_msg(header("alpha/camera", t), &image)),
            bytes(&velodyne_cloud("alpha/base_link", t)),
        )
    };
    // One frame's messages decoded, checked and fed; the frames then assembled.
    let mut feed = move |(odometry, image, cloud): (Vec<u8>, Vec<u8>, Vec<u8>)| {
        let payloads = [
            inputs.odometry(&decode::<nav_msgs::Odometry>(&odometry)),
            inputs.image(&decode::<sensor_msgs::Image>(&image)),
            inputs.cloud(&decode::<sensor_msgs::PointCloud2>(&cloud)),
        ];
        for payload in payloads.into_iter().flatten() {
            sync.feed(epoch, payload);
        }
        sync.ready()
    };
    // The timeline believes the stamps once `ros.timeline.confirm_messages` agree: first frames.
    for _ in 0..3 {
        feed(next_frame());
    }
    let mut group = c.benchmark_group("frame_in_20k");
    group.throughput(Throughput::Elements(POINTS as u64));
    group.bench_function("odometry_image_cloud", |b| {
        b.iter_batched(
            &mut next_frame,
            |messages| {
                let frames = feed(messages);
                assert_eq!(frames.len(), 1, "one frame per iteration");
                frames
            },
            BatchSize::SmallInput,
        )
    });
    group.finish();
}

fn label_images(c: &mut Criterion) {
    use sgm_model::perception::palettes::ADE20K_150_PALETTE;
    let config = sgm_actors::config::RobotConfig {
        classes: sgm_model::perception::label_map::LabelMapSpec {
            segmenter: "ade20k_150".into(),
            ..Default::default()
        },
        ..Default::default()
    };
    let colours = config.colour_ids().unwrap_or_else(|e| panic!("{e}"));
    let inputs = Inputs::new(&RosConfig::default(), "alpha", 1).with_colours(colours);
    // Segments of 40 pixels of each of the 150 classes, row after row.
    let ids: Vec<u16> = (0..640 * 480).map(|k| ((k / 40) % 150) as u16).collect();
    let image = LabelImage::new(640, 480, ids.clone()).unwrap_or_else(|e| panic!("{e}"));
    let mono = bytes(&label_image_msg(header("alpha/camera", 0.0), &image));
    let rgb = bytes(&sensor_msgs::Image {
        header: header("alpha/camera", 0.0),
        height: 480,
        width: 640,
        encoding: "rgb8".into(),
        is_bigendian: 0,
        step: 640 * 3,
        data: ids.iter().flat_map(|&k| ADE20K_150_PALETTE[usize::from(k)]).collect(),
    });
    let mut group = c.benchmark_group("label_image_in_640x480");
    group.throughput(Throughput::Elements(640 * 480));
    for (name, message) in [("mono16_ids", &mono), ("rgb8_ade20k_palette", &rgb)] {
        group.bench_function(name, |b| b.iter(|| black_box(inputs.image(&decode::<sensor_msgs::Image>(message)))));
    }
    group.finish();
}

criterion_group!(benches, clouds, frames, label_images);
criterion_main!(benches);
