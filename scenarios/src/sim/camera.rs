//! The camera and its segmentation network, simulated: a forward pinhole camera at the LiDAR,
//! whose label image is rendered from the frame's true returns (z-buffered splats), with two
//! kinds of error a real network makes — whole objects given a wrong class (`mislabel_rate`,
//! per object and frame) and labels bleeding across object boundaries (`boundary_noise_px`,
//! Gaussian jitter of each splat). Fusion then labels the LiDAR points by projecting them into
//! this image, exactly as on a robot. Its pixel values are the configured segmenter's
//! (`[classes]`, [`segmenter_ids`]): `fusion.classes` ids by default.

use crate::scenario::CameraSpec;
use crate::sim::lidar::LidarFrame;
use crate::sim::world::NO_LABEL;
use nalgebra::Point3;
use rand::Rng;
use rand_distr::{Distribution, Normal};
use sgm_model::geometry::Pose3;
use sgm_model::perception::label_map::{LabelMap, LabelMapSpec};
use sgm_model::perception::projection::{CameraModel, LabelImage};
use sgm_model::scene_graph::LabelId;
use std::collections::BTreeMap;

/// The camera looks along the body's x axis: camera z = body x, camera x = −body y,
/// camera y = −body z.
pub fn camera_from_body() -> Pose3 {
    sgm_model::perception::projection::optical_from_forward_body()
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
/// paints (about half the pattern's spacing in pixels).
pub fn render(
    spec: &CameraSpec,
    frame: &LidarFrame,
    wrong: &BTreeMap<u32, u16>,
    splat_px: i64,
    rng: &mut impl Rng,
) -> LabelImage {
    let model = camera_model(spec);
    let camera_from_body = camera_from_body();
    let (w, h) = (spec.width as i64, spec.height as i64);
    let mut depth = vec![f64::INFINITY; (w * h) as usize];
    let mut labels = vec![NO_LABEL; (w * h) as usize];
    let jitter = Normal::new(0.0, spec.boundary_noise_px.max(0.0)).ok();
    let labelled = noisy_labels(frame, wrong);
    for (p, label) in frame.points.iter().zip(labelled) {
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
        let image = render(&spec, &f, &BTreeMap::new(), 1, &mut ChaCha8Rng::seed_from_u64(1));
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
}
