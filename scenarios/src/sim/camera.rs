//! The camera and its segmentation network, simulated: a pinhole camera mounted on the body
//! (`mount_xyz_m`, `mount_rpy_deg`; by default forward at the LiDAR), firing at its own time
//! (`exposure_offset_s` after the scan's stamp), whose label image is rendered from the frame's
//! true returns (z-buffered splats) seen from where the camera was then, with two kinds of
//! error a real network makes — whole objects given a wrong class (`mislabel_rate`, per object
//! and frame) and labels bleeding across object boundaries (`boundary_noise_px`, Gaussian
//! jitter of each splat). The robot is told the mount with a calibration error
//! (`mount_error_deg`, `mount_error_m`) and the image's stamp with its clock's
//! (`clock_offset_s`). Fusion then labels the LiDAR points by projecting them into this image,
//! exactly as on a robot. Its pixel values are the configured segmenter's (`[classes]`,
//! [`segmenter_ids`]): `fusion.classes` ids by default.
//!
//! A return measured at τ after the stamp t from the body pose B(t + τ) is seen by the camera
//! at t + e as
//!
//!   p_camera = C · B(t + e)⁻¹ · B(t + τ) · p,    C = camera_from_body (the true mount)

use crate::scenario::CameraSpec;
use crate::sim::lidar::LidarFrame;
use crate::sim::mount::{body_from_mount, calibration_error};
use crate::sim::world::NO_LABEL;
use nalgebra::Point3;
use rand::Rng;
use rand_distr::{Distribution, Normal};
use sgm_model::geometry::Pose3;
use sgm_model::perception::label_map::{LabelMap, LabelMapSpec};
use sgm_model::perception::projection::{optical_from_forward_body, CameraModel, LabelImage};
use sgm_model::scene_graph::LabelId;
use std::collections::BTreeMap;

/// The camera looks along the body's x axis: camera z = body x, camera x = −body y,
/// camera y = −body z (the default mount).
pub fn camera_from_body() -> Pose3 {
    optical_from_forward_body()
}

const CAMERA_SALT: u64 = 0xCA3E_8A00;

/// A robot's camera mount: the true one, and the one its configuration says.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CameraMount {
    /// Where the camera is (the simulator renders from it).
    pub camera_from_body: Pose3,
    /// What the robot is told (`mount_error_*` away from the truth).
    pub configured_camera_from_body: Pose3,
}

impl CameraMount {
    /// Robot `robot`'s mount under `spec`; its calibration error is drawn from `seed` and the
    /// robot's index (each robot has its own).
    pub fn new(spec: &CameraSpec, seed: u64, robot: usize) -> Self {
        let camera_from_body = if spec.mount_xyz_m == [0.0; 3] && spec.mount_rpy_deg == [0.0; 3] {
            camera_from_body()
        } else {
            camera_from_body() * body_from_mount(spec.mount_xyz_m, spec.mount_rpy_deg).inverse()
        };
        match calibration_error(spec.mount_error_deg, spec.mount_error_m, seed, CAMERA_SALT, robot) {
            // body_from_told = body_from_true · E, so told_from_body = E⁻¹ · camera_from_body.
            Some(error) => Self { camera_from_body, configured_camera_from_body: error.inverse() * camera_from_body },
            None => Self { camera_from_body, configured_camera_from_body: camera_from_body },
        }
    }
}

pub fn camera_model(spec: &CameraSpec) -> CameraModel {
    let f = f64::from(spec.width) / 2.0 / (spec.horizontal_fov_deg.to_radians() / 2.0).tan();
    CameraModel {
        width: spec.width,
        height: spec.height,
        fx: f,
        fy: f,
        cx: f64::from(spec.width) / 2.0,
        cy: f64::from(spec.height) / 2.0,
        distortion: [0.0; 5],
    }
}

/// Per frame: which objects the network gets wrong, and as what.
pub fn mislabels(frame: &LidarFrame, rate: f64, matchable: &[u16], rng: &mut impl Rng) -> BTreeMap<u32, u16> {
    let mut wrong = BTreeMap::new();
    if rate <= 0.0 || matchable.len() < 2 {
        return wrong;
    }
    let mut seen: Vec<(u32, u16)> =
        frame.instances.iter().zip(&frame.labels).filter(|(i, _)| **i != u32::MAX).map(|(i, l)| (*i, *l)).collect();
    seen.sort_unstable();
    seen.dedup_by_key(|(i, _)| *i);
    for (instance, label) in seen {
        if matchable.contains(&label) && rng.random_bool(rate) {
            let others: Vec<u16> = matchable.iter().copied().filter(|l| *l != label).collect();
            wrong.insert(instance, others[rng.random_range(0..others.len())]);
        }
    }
    wrong
}

/// The label of each return as the network would see it (per-point mode).
pub fn noisy_labels(frame: &LidarFrame, wrong: &BTreeMap<u32, u16>) -> Vec<u16> {
    frame.labels.iter().zip(&frame.instances).map(|(l, i)| wrong.get(i).copied().unwrap_or(*l)).collect()
}

/// The simulator's class ids (those of `fusion.classes`) as the pixel values of the configured
/// segmenter (`[classes]`): `ids[sgm id]`, the smallest pixel value of the class's group, or
/// [`NO_LABEL`] for a class the segmenter cannot express (COCO has no lamp post). `None` for the
/// default `identity` with no groups of its own (nothing to translate).
pub fn segmenter_ids(spec: &LabelMapSpec, map: &LabelMap) -> Option<Vec<u16>> {
    if *spec == LabelMapSpec::default() {
        return None;
    }
    Some(
        (0..=u16::MAX)
            .map(|id| if id == NO_LABEL { NO_LABEL } else { map.pixel_of(LabelId(id)).unwrap_or(NO_LABEL) })
            .collect(),
    )
}

/// Renders the segmentation image of a frame. `splat_px`: half-size of the square each return
/// paints (about half the pattern's spacing in pixels); `camera_from_return(τ)`: the camera at
/// its exposure from the body at τ after the stamp (a return's time; 0 for an unswept frame).
pub fn render(
    spec: &CameraSpec,
    frame: &LidarFrame,
    wrong: &BTreeMap<u32, u16>,
    splat_px: i64,
    camera_from_return: &dyn Fn(f32) -> Pose3,
    rng: &mut impl Rng,
) -> LabelImage {
    let model = camera_model(spec);
    let (w, h) = (spec.width as i64, spec.height as i64);
    let mut depth = vec![f64::INFINITY; (w * h) as usize];
    let mut labels = vec![NO_LABEL; (w * h) as usize];
    let jitter = Normal::new(0.0, spec.boundary_noise_px.max(0.0)).ok();
    let labelled = noisy_labels(frame, wrong);
    // Returns come in time order: one transform per distinct time.
    let mut cached: Option<(f32, Pose3)> = None;
    for (k, (p, label)) in frame.points.iter().zip(labelled).enumerate() {
        let tau = frame.times.get(k).copied().unwrap_or(0.0);
        let camera_from_body = match cached {
            Some((at, pose)) if at == tau => pose,
            _ => {
                let pose = camera_from_return(tau);
                cached = Some((tau, pose));
                pose
            }
        };
        let pc: Point3<f64> = camera_from_body * p;
        let Some((u, v)) = model.project(&pc) else { continue };
        let (ju, jv) = jitter.map_or((0.0, 0.0), |n| (n.sample(rng), n.sample(rng)));
        let (u, v) = ((u + ju).round() as i64, (v + jv).round() as i64);
        for y in (v - splat_px).max(0)..=(v + splat_px).min(h - 1) {
            for x in (u - splat_px).max(0)..=(u + splat_px).min(w - 1) {
                let k = (y * w + x) as usize;
                if pc.z < depth[k] {
                    depth[k] = pc.z;
                    labels[k] = label;
                }
            }
        }
    }
    LabelImage { width: spec.width, height: spec.height, labels }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use sgm_model::perception::projection::label_points;
    use sgm_model::scene_graph::LabelId;

    fn frame() -> LidarFrame {
        // A column of returns 5 m ahead (object 7, class 4) in front of a far one (ground, 0).
        let mut f = LidarFrame::default();
        for k in 0..20 {
            let z = -0.5 + k as f64 * 0.05;
            f.points.push(Point3::new(5.0, 0.0, z));
            f.labels.push(4);
            f.instances.push(7);
            f.points.push(Point3::new(20.0, 0.0, z));
            f.labels.push(0);
            f.instances.push(u32::MAX);
        }
        f
    }

    #[test]
    fn fusion_reads_back_the_true_labels_of_a_noiseless_render() {
        let spec = CameraSpec { boundary_noise_px: 0.0, mislabel_rate: 0.0, ..CameraSpec::default() };
        let f = frame();
        let image = render(&spec, &f, &BTreeMap::new(), 1, &|_| camera_from_body(), &mut ChaCha8Rng::seed_from_u64(1));
        let labels = label_points(&f.points, &camera_from_body(), &camera_model(&spec), &image).unwrap();
        // The near column hides the far one: every point reads the near object's class.
        assert!(labels.iter().all(|l| *l == Some(LabelId(4))), "{labels:?}");
    }

    #[test]
    fn a_mislabelled_object_takes_another_matchable_class() {
        let f = frame();
        let wrong = mislabels(&f, 1.0, &[4, 5, 6], &mut ChaCha8Rng::seed_from_u64(3));
        let class = wrong[&7];
        assert!(class == 5 || class == 6);
        assert!(!wrong.contains_key(&u32::MAX));
        let noisy = noisy_labels(&f, &wrong);
        assert_eq!(noisy.iter().filter(|l| **l == class).count(), 20);
    }

    /// Narrow columns 6 m ahead (classes 1–3) before a far wall (class 0), points in the body at
    /// the scan's stamp.
    fn columns() -> LidarFrame {
        let mut f = LidarFrame::default();
        for c in 0..9 {
            let y = -2.4 + f64::from(c) * 0.6;
            for k in 0..20 {
                for dy in [-0.08, -0.04, 0.0, 0.04, 0.08] {
                    f.points.push(Point3::new(6.0, y + dy, -0.5 + f64::from(k) * 0.05));
                    f.labels.push(1 + c as u16 % 3);
                    f.instances.push(c);
                }
            }
        }
        for k in -60..=60 {
            for z in [-0.4, 0.0, 0.4] {
                f.points.push(Point3::new(20.0, f64::from(k) * 0.1, z));
                f.labels.push(0);
                f.instances.push(u32::MAX);
            }
        }
        f
    }

    /// Share of the columns' points that read their own class.
    fn column_hits(f: &LidarFrame, labels: &[Option<LabelId>]) -> f64 {
        let on_columns: Vec<bool> = f
            .instances
            .iter()
            .zip(&f.labels)
            .zip(labels)
            .filter(|((i, _), _)| **i != u32::MAX)
            .map(|((_, l), got)| *got == Some(LabelId(*l)))
            .collect();
        on_columns.iter().filter(|b| **b).count() as f64 / on_columns.len() as f64
    }

    /// A camera mounted off the LiDAR and turned, firing 50 ms after the scan while the body
    /// moves sideways at 2 m/s and turns at 0.5 rad/s: the robot's pipeline (the mount, the
    /// image's offset, the odometry's velocity: `motion::camera_at_offset`) labels the columns;
    /// without the offset compensated it misses them. The truth: poses written out, not a twist.
    #[test]
    fn a_mounted_camera_firing_later_labels_the_scan_once_its_motion_is_compensated() {
        use sgm_model::geometry::pose_from_yaw_translation;
        use sgm_model::perception::motion::{camera_at_offset, twist_between};
        let spec = CameraSpec {
            boundary_noise_px: 0.0,
            mislabel_rate: 0.0,
            mount_xyz_m: [0.1, 0.05, -0.1],
            mount_rpy_deg: [0.0, 5.0, 10.0],
            exposure_offset_s: 0.05,
            ..CameraSpec::default()
        };
        let body_at = |s: f64| pose_from_yaw_translation(0.5 * s, Vector3::new(0.0, 2.0 * s, 0.0));
        let mount = CameraMount::new(&spec, 1, 0);
        assert_eq!(mount.camera_from_body, mount.configured_camera_from_body, "no calibration error asked");
        let (t, e) = (1.0, spec.exposure_offset_s);
        let shot = |_: f32| mount.camera_from_body * body_at(t + e).inverse() * body_at(t);
        let f = columns();
        let image = render(&spec, &f, &BTreeMap::new(), 1, &shot, &mut ChaCha8Rng::seed_from_u64(1));
        let model = camera_model(&spec);
        let twist = twist_between(&body_at(t - 0.1), t - 0.1, &body_at(t), t).unwrap();
        let compensated = camera_at_offset(&mount.configured_camera_from_body, &twist, e);
        let good = column_hits(&f, &label_points(&f.points, &compensated, &model, &image).unwrap());
        let naive =
            column_hits(&f, &label_points(&f.points, &mount.configured_camera_from_body, &model, &image).unwrap());
        assert!(good > 0.95, "compensated: {good}");
        assert!(naive < 0.7, "uncompensated: {naive}");
        // The mount itself matters: a camera assumed at the LiDAR misreads them too.
        let at_lidar = column_hits(
            &f,
            &label_points(&f.points, &camera_at_offset(&camera_from_body(), &twist, e), &model, &image).unwrap(),
        );
        assert!(at_lidar < 0.7, "mount ignored: {at_lidar}");
    }

    #[test]
    fn the_told_mount_is_off_by_the_calibration_error_and_each_robot_has_its_own() {
        let spec = CameraSpec { mount_error_deg: 2.0, mount_error_m: 0.05, ..CameraSpec::default() };
        let a = CameraMount::new(&spec, 7, 0);
        let b = CameraMount::new(&spec, 7, 1);
        for m in [a, b] {
            let error = m.camera_from_body * m.configured_camera_from_body.inverse();
            assert!((error.rotation.angle().to_degrees() - 2.0).abs() < 1e-9);
            assert!((error.translation.vector.norm() - 0.05).abs() < 1e-9);
        }
        assert_ne!(a.configured_camera_from_body, b.configured_camera_from_body);
        assert_eq!(a, CameraMount::new(&spec, 7, 0), "seeded");
        assert_eq!(CameraMount::new(&CameraSpec::default(), 7, 0).camera_from_body, camera_from_body());
    }
}
