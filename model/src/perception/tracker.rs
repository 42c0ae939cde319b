//! Object tracker (paper §IV-A, eqs. 2–4): object candidates of a new keyframe are associated
//! with objects by a linear assignment on centroid distance, c_ij = ‖p_i − p_j‖₂, accepted when
//! c_ij < c_max (`max_track_distance_m`). Beyond the paper, candidates are matched against the
//! map's objects near the keyframe (within `search_radius_m`), not only the previous keyframe's,
//! so an object that leaves the view and returns keeps its id. Only equal labels may associate.
//! Associated objects are re-anchored to the new keyframe (scene graph); unassociated candidates
//! become new objects; an object is confirmed after `confirm_after` sightings.
//!
//! Moving things (beyond the paper; issue 31): a class marked dynamic never becomes an object,
//! but a segmenter does not know which car will drive off, and a person it calls a chair walks
//! on. The tracker follows such an object from keyframe to keyframe (each step within c_max),
//! so its centroid wanders. An object is *moving* when, within `moving_window_s`, its centroid
//! has been farther than
//!
//!   ‖p_now − p_k‖ > `moving_m` + ½ max(size_x, size_y)      (p_k: an earlier sighting in the window)
//!
//! from where it was seen (each sighting kept in its keyframe's frame, so the comparison goes
//! through the current keyframe poses). A static object's centroid moves with its partial views,
//! by at most about half its extent, and an id that hops along a row of alike neighbours by
//! about their spacing (2 m, as `moving_m` was first, took real objects in `quickstart`; 3 m
//! takes one spurious object there); the short window keeps odometry drift out (a revisit after
//! a long loop compares nothing older than the window). A moving object stays moving and is no
//! longer confirmed: neither shared nor matched. A walker may be confirmed for the sightings
//! before it has gone `moving_m` (about 2 s at a walk).
//!
//! Keeping the object layer clean (beyond the paper; issue 31). One keyframe's candidates go to
//! distinct objects, so one object seen as two pieces in one keyframe (a lamp post cut by a gap
//! between beams, before `clustering` joined columns, or a bookshelf cut by an occluder) stays
//! two objects for ever, one above the other. After each keyframe, an object it saw and another
//! of the same label are one (`merge_stacked`) when either centroid lies in the other's
//! footprint:
//!
//!   |x_a − x_b| ≤ ½ size_x  and  |y_a − y_b| ≤ ½ size_y      (of a or of b; world axes)
//!
//! The older object keeps its id and takes the other's sightings (scene graph:
//! `merge_objects`); moving objects are left alone. A segmenter's false positive (a blob, a
//! label that bled onto a wall) is seen once or twice where nothing is; left in the map, later
//! false positives of its class within c_max attach to it until it is confirmed, and the
//! matcher meets objects that no other robot has. A *tentative* object (fewer than
//! `confirm_after` sightings) not seen for `tentative_expiry_s` is removed.

use super::clustering::ObjectCandidate;
use crate::scene_graph::{KeyframeId, ObjectId, SceneGraph, SceneGraphError};
use crate::spatial::lap::{self, CostMatrix};
use nalgebra::Point3;
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, BTreeSet, VecDeque};

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TrackerConfig {
    /// c_max of eq. 4, m. Default 1.0.
    pub max_track_distance_m: f64,
    /// Map objects within this distance of the keyframe are association candidates, m. Default 30.
    pub search_radius_m: f64,
    /// Sightings before an object is confirmed (shared and matched). Default 3.
    pub confirm_after: u32,
    /// An object whose centroid moves farther than this (beyond half its horizontal extent)
    /// within `moving_window_s` is moving: no longer confirmed, m. 0: no object is ever moving.
    /// Default 3.0.
    pub moving_m: f64,
    /// The window over which an object's sightings are compared, s. Default 10.
    pub moving_window_s: f64,
    /// Objects of one label standing in one column (either centroid in the other's footprint)
    /// are merged after each keyframe. Default true.
    pub merge_stacked: bool,
    /// A tentative object (not yet confirmed) not seen for this long is removed, s. 0: never.
    /// Default 10.
    pub tentative_expiry_s: f64,
}

impl Default for TrackerConfig {
    fn default() -> Self {
        Self {
            max_track_distance_m: 1.0,
            search_radius_m: 30.0,
            confirm_after: 3,
            moving_m: 3.0,
            moving_window_s: 10.0,
            merge_stacked: true,
            tentative_expiry_s: 10.0,
        }
    }
}

/// At most this many recent sightings are kept per object.
const MAX_RECENT: usize = 16;

/// Tracker state: sightings per object, the recent ones where they were seen, and the objects
/// found moving (serialisable with the scene graph).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ObjectTracker {
    sightings: BTreeMap<ObjectId, u32>,
    /// Each object's sightings within `moving_window_s`: the keyframe and the centroid in its
    /// body frame, oldest first.
    #[serde(default)]
    recent: BTreeMap<ObjectId, VecDeque<(KeyframeId, Point3<f64>)>>,
    #[serde(default)]
    moving: BTreeSet<ObjectId>,
    /// Objects merged into another so far.
    #[serde(default)]
    merged: u64,
    /// Tentative objects removed so far.
    #[serde(default)]
    expired: u64,
}

/// What one keyframe's candidates became.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TrackUpdate {
    /// Candidate index → the object it was associated with or created (after merges: the object
    /// it is now part of, so an id may repeat).
    pub objects: Vec<ObjectId>,
    pub created: Vec<ObjectId>,
    /// Objects that reached `confirm_after` sightings with this keyframe.
    pub newly_confirmed: Vec<ObjectId>,
    /// (kept, merged into it) for each pair of objects found to be one.
    pub merged: Vec<(ObjectId, ObjectId)>,
    /// Tentative objects removed, unseen for `tentative_expiry_s`.
    pub expired: Vec<ObjectId>,
}

/// Cost of a forbidden association (different labels): never below c_max.
const FORBIDDEN: f64 = 1e9;

impl ObjectTracker {
    pub fn sightings(&self, id: ObjectId) -> u32 {
        self.sightings.get(&id).copied().unwrap_or(0)
    }

    pub fn is_confirmed(&self, id: ObjectId, config: &TrackerConfig) -> bool {
        self.sightings(id) >= config.confirm_after && !self.moving.contains(&id)
    }

    /// Whether `id` was found moving.
    pub fn is_moving(&self, id: ObjectId) -> bool {
        self.moving.contains(&id)
    }

    /// Objects found moving so far.
    pub fn moving_count(&self) -> usize {
        self.moving.len()
    }

    /// Objects merged into another so far.
    pub fn merged_count(&self) -> u64 {
        self.merged
    }

    /// Tentative objects removed so far.
    pub fn expired_count(&self) -> u64 {
        self.expired
    }

    /// Records the sighting of `id` at `keyframe` (centroid in its body frame; world through
    /// the keyframe's pose), and marks `id` moving when it moved as the module doc says.
    fn watch_motion(
        &mut self,
        graph: &SceneGraph,
        id: ObjectId,
        keyframe: KeyframeId,
        candidate: &ObjectCandidate,
        config: &TrackerConfig,
    ) {
        if config.moving_m.is_nan() || config.moving_m <= 0.0 || self.moving.contains(&id) {
            return;
        }
        let Some(now) = graph.keyframe(keyframe) else { return };
        let p_now = now.world_from_body * candidate.centroid;
        let recent = self.recent.entry(id).or_default();
        recent.retain(|(k, _)| graph.keyframe(*k).is_some_and(|f| now.stamp - f.stamp <= config.moving_window_s));
        let reach = config.moving_m + 0.5 * candidate.size.x.max(candidate.size.y);
        let moved = recent
            .iter()
            .any(|(k, c)| graph.keyframe(*k).is_some_and(|f| (f.world_from_body * c - p_now).norm() > reach));
        if moved {
            self.moving.insert(id);
            self.recent.remove(&id);
            return;
        }
        if recent.len() == MAX_RECENT {
            recent.pop_front();
        }
        recent.push_back((keyframe, candidate.centroid));
    }

    /// Associates `candidates` (centroids in the keyframe's body frame) observed at `keyframe`.
    pub fn update(
        &mut self,
        graph: &mut SceneGraph,
        keyframe: KeyframeId,
        candidates: &[ObjectCandidate],
        config: &TrackerConfig,
    ) -> Result<TrackUpdate, SceneGraphError> {
        let world_from_body =
            graph.keyframe(keyframe).ok_or(SceneGraphError::UnknownKeyframe(keyframe))?.world_from_body;
        let in_world: Vec<_> = candidates.iter().map(|c| world_from_body * c.centroid).collect();
        let here = world_from_body.translation.vector;
        let nearby: Vec<(ObjectId, nalgebra::Point3<f64>, crate::scene_graph::LabelId)> = graph
            .objects()
            .filter_map(|o| graph.centroid_in_world(o.id).map(|p| (o.id, p, o.label)))
            .filter(|(_, p, _)| (p.coords - here).norm() <= config.search_radius_m)
            .collect();
        let mut costs = CostMatrix::filled(candidates.len(), nearby.len(), FORBIDDEN);
        for (i, c) in candidates.iter().enumerate() {
            for (j, (_, p, label)) in nearby.iter().enumerate() {
                if *label == c.label {
                    costs.set(i, j, (in_world[i] - p).norm());
                }
            }
        }
        let assignment = if nearby.is_empty() { vec![None; candidates.len()] } else { lap::solve(&costs) };
        let mut update = TrackUpdate::default();
        for (i, c) in candidates.iter().enumerate() {
            let matched = assignment[i].filter(|&j| costs.get(i, j) < config.max_track_distance_m).map(|j| nearby[j].0);
            let id = match matched {
                Some(id) => {
                    graph.observe_object(id, in_world[i], c.size, keyframe)?;
                    id
                }
                None => {
                    let id = graph.add_object(c.label, in_world[i], c.size, keyframe)?;
                    update.created.push(id);
                    id
                }
            };
            self.watch_motion(graph, id, keyframe, c, config);
            let count = self.sightings.entry(id).or_insert(0);
            *count += 1;
            if *count == config.confirm_after && !self.moving.contains(&id) {
                update.newly_confirmed.push(id);
            }
            update.objects.push(id);
        }
        if config.merge_stacked {
            self.merge_stacked(graph, &mut update, config)?;
        }
        self.expire_tentative(graph, keyframe, &mut update, config)?;
        Ok(update)
    }

    /// Merges each object this keyframe saw with the objects of its label in one column with
    /// it (module doc), into the older id.
    fn merge_stacked(
        &mut self,
        graph: &mut SceneGraph,
        update: &mut TrackUpdate,
        config: &TrackerConfig,
    ) -> Result<(), SceneGraphError> {
        let seen: BTreeSet<ObjectId> = update.objects.iter().copied().collect();
        for id in seen {
            let Some(object) = graph.object(id) else { continue };
            let (label, size) = (object.label, object.size);
            let Some(p) = graph.centroid_in_world(id) else { continue };
            if self.moving.contains(&id) {
                continue;
            }
            let column: Vec<ObjectId> = graph
                .objects()
                .filter(|o| o.id != id && o.label == label && !self.moving.contains(&o.id))
                .filter(|o| {
                    graph
                        .centroid_in_world(o.id)
                        .is_some_and(|q| in_footprint(&q, &p, &size) || in_footprint(&p, &q, &o.size))
                })
                .map(|o| o.id)
                .collect();
            for other in column {
                let (keep, gone) = (id.min(other), id.max(other));
                if graph.object(keep).is_none() || graph.object(gone).is_none() {
                    continue;
                }
                let was_confirmed = self.is_confirmed(keep, config) || self.is_confirmed(gone, config);
                graph.merge_objects(keep, gone)?;
                let gone_sightings = self.sightings.remove(&gone).unwrap_or(0);
                *self.sightings.entry(keep).or_insert(0) += gone_sightings;
                self.recent.remove(&gone);
                self.merged += 1;
                for o in update.objects.iter_mut().filter(|o| **o == gone) {
                    *o = keep;
                }
                update.created.retain(|o| *o != gone);
                update.newly_confirmed.retain(|o| *o != gone);
                if !was_confirmed && self.is_confirmed(keep, config) && !update.newly_confirmed.contains(&keep) {
                    update.newly_confirmed.push(keep);
                }
                update.merged.push((keep, gone));
            }
        }
        Ok(())
    }

    /// Removes the tentative objects last seen more than `tentative_expiry_s` before `keyframe`.
    fn expire_tentative(
        &mut self,
        graph: &mut SceneGraph,
        keyframe: KeyframeId,
        update: &mut TrackUpdate,
        config: &TrackerConfig,
    ) -> Result<(), SceneGraphError> {
        let expiry = config.tentative_expiry_s;
        let Some(now) = graph.keyframe(keyframe).map(|k| k.stamp) else { return Ok(()) };
        if expiry.is_nan() || expiry <= 0.0 {
            return Ok(());
        }
        let stale: Vec<ObjectId> = graph
            .objects()
            .filter(|o| self.sightings(o.id) < config.confirm_after && !self.moving.contains(&o.id))
            .filter(|o| graph.keyframe(o.anchor).is_some_and(|k| now - k.stamp > expiry))
            .map(|o| o.id)
            .collect();
        for id in stale {
            graph.remove_object(id)?;
            self.sightings.remove(&id);
            self.recent.remove(&id);
            self.expired += 1;
            update.expired.push(id);
        }
        Ok(())
    }
}

/// Whether `p` lies within the footprint (xy extent `size`, world axes) of an object at `centre`.
fn in_footprint(p: &Point3<f64>, centre: &Point3<f64>, size: &nalgebra::Vector3<f64>) -> bool {
    (p.x - centre.x).abs() <= 0.5 * size.x && (p.y - centre.y).abs() <= 0.5 * size.y
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{pose_from_yaw_translation, Pose3};
    use crate::scene_graph::{Keyframe, LabelId};
    use nalgebra::{Point3, Vector3};

    fn candidate(label: u16, x: f64, y: f64) -> ObjectCandidate {
        ObjectCandidate {
            label: LabelId(label),
            centroid: Point3::new(x, y, 0.5),
            size: Vector3::repeat(0.6),
            points: 100,
        }
    }

    /// A robot driving along x past two chairs and a bench; candidates are given in the body
    /// frame of each keyframe, with 10 cm of noise.
    #[test]
    fn ids_survive_occlusion_and_neighbours_stay_apart() {
        let mut graph = SceneGraph::new();
        let mut tracker = ObjectTracker::default();
        let config = TrackerConfig::default();
        let world = [(1u16, 5.0, 2.0), (1, 5.0, 3.2), (2, 9.0, -2.0)];
        let mut ids_per_kf = Vec::new();
        for (k, x) in [0.0, 1.0, 2.0, 3.0].into_iter().enumerate() {
            let kf = KeyframeId(k as u32);
            graph
                .add_keyframe(Keyframe {
                    id: kf,
                    stamp: k as f64,
                    world_from_body: pose_from_yaw_translation(0.1 * k as f64, Vector3::new(x, 0.0, 0.0)),
                })
                .unwrap();
            let body_from_world = graph.keyframe(kf).unwrap().world_from_body.inverse();
            let noise = [0.1, -0.08, 0.05, -0.1][k];
            // Keyframe 2: the first chair is occluded.
            let seen: Vec<ObjectCandidate> = world
                .iter()
                .enumerate()
                .filter(|(o, _)| !(k == 2 && *o == 0))
                .map(|(_, &(l, wx, wy))| {
                    let b = body_from_world * Point3::new(wx + noise, wy - noise, 0.5);
                    candidate(l, b.x, b.y)
                })
                .collect();
            ids_per_kf.push(tracker.update(&mut graph, kf, &seen, &config).unwrap());
        }
        assert_eq!(graph.object_count(), 3, "no duplicates: each object keeps one id");
        let first = &ids_per_kf[0].objects;
        assert_eq!(ids_per_kf[1].objects, *first);
        assert_eq!(ids_per_kf[2].objects, vec![first[1], first[2]]);
        assert_eq!(ids_per_kf[3].objects, *first, "the occluded chair kept its id");
        assert_eq!(tracker.sightings(first[0]), 3);
        assert!(tracker.is_confirmed(first[0], &config) && tracker.is_confirmed(first[1], &config));
        assert_eq!(ids_per_kf[2].newly_confirmed, vec![first[1], first[2]]);
        assert_eq!(ids_per_kf[3].newly_confirmed, vec![first[0]]);
        // The object is anchored to the latest keyframe that saw it.
        assert_eq!(graph.object(first[0]).unwrap().anchor, KeyframeId(3));
        assert_eq!(graph.keyframes_observing(first[0]).count(), 3);
    }

    /// Trunks (0.3 m in radius, 3 m tall) on a 12° hill, passed by a body that walks up, across
    /// and down it tilted with the ground under it and turning: each keyframe sees the half of
    /// each trunk that faces it, above the ground, so its centroid moves with the viewpoint.
    /// Association is in 3-D world coordinates, so the slope costs nothing: one id per trunk.
    #[test]
    fn objects_on_a_slope_keep_their_ids_from_every_viewpoint() {
        let tan = 12f64.to_radians().tan();
        let ground = |x: f64, y: f64| tan * (0.6 * x + 0.8 * y);
        let trunks = [(4.0, 3.0), (9.0, -2.0), (5.5, 3.2 + 1.6), (-3.0, 6.0)];
        let route =
            [(0.0, 0.0, 0.3), (3.0, -2.0, 1.2), (7.0, 1.0, 2.0), (8.0, 6.0, 2.9), (2.0, 8.0, -2.0), (-1.0, 3.0, -0.9)];
        let mut graph = SceneGraph::new();
        let mut tracker = ObjectTracker::default();
        let config = TrackerConfig::default();
        let mut ids: Vec<Vec<ObjectId>> = Vec::new();
        for (k, &(x, y, yaw)) in route.iter().enumerate() {
            // The body 0.5 m above the ground, its z along the ground's normal.
            let normal = Vector3::new(-0.6 * tan, -0.8 * tan, 1.0).normalize();
            let tilt = nalgebra::UnitQuaternion::rotation_between(&Vector3::z(), &normal).unwrap();
            let yawed = nalgebra::UnitQuaternion::from_euler_angles(0.0, 0.0, yaw);
            let world_from_body = Pose3::from_parts(Vector3::new(x, y, ground(x, y) + 0.5).into(), tilt * yawed);
            let kf = KeyframeId(k as u32);
            graph.add_keyframe(Keyframe { id: kf, stamp: k as f64, world_from_body }).unwrap();
            let seen: Vec<ObjectCandidate> = trunks
                .iter()
                .map(|&(tx, ty)| {
                    // The visible half: surface points facing the sensor, from the ground up.
                    let facing = (Vector3::new(x - tx, y - ty, 0.0)).normalize();
                    let mut sum = Vector3::zeros();
                    let n = 200;
                    for j in 0..n {
                        let a = std::f64::consts::PI * (j as f64 / n as f64 - 0.5);
                        let (c, s) = (a.cos(), a.sin());
                        let radial = Vector3::new(facing.x * c - facing.y * s, facing.x * s + facing.y * c, 0.0);
                        let (px, py) = (tx + 0.3 * radial.x, ty + 0.3 * radial.y);
                        sum += Vector3::new(px, py, ground(px, py) + 3.0 * (j % 10) as f64 / 9.0);
                    }
                    let in_body = world_from_body.inverse() * Point3::from(sum / n as f64);
                    ObjectCandidate {
                        label: LabelId(1),
                        centroid: in_body,
                        size: Vector3::new(0.6, 0.6, 3.0),
                        points: n,
                    }
                })
                .collect();
            ids.push(tracker.update(&mut graph, kf, &seen, &config).unwrap().objects);
        }
        assert_eq!(graph.object_count(), trunks.len(), "no duplicates on the slope");
        assert!(ids.iter().all(|kf| *kf == ids[0]), "{ids:?}");
    }

    #[test]
    fn far_or_other_label_candidates_become_new_objects() {
        let mut graph = SceneGraph::new();
        let mut tracker = ObjectTracker::default();
        let config = TrackerConfig::default();
        graph
            .add_keyframe(Keyframe {
                id: KeyframeId(0),
                stamp: 0.0,
                world_from_body: pose_from_yaw_translation(0.0, Vector3::zeros()),
            })
            .unwrap();
        graph
            .add_keyframe(Keyframe {
                id: KeyframeId(1),
                stamp: 1.0,
                world_from_body: pose_from_yaw_translation(0.0, Vector3::zeros()),
            })
            .unwrap();
        let a = tracker.update(&mut graph, KeyframeId(0), &[candidate(1, 2.0, 0.0)], &config).unwrap();
        // 1.5 m away (> c_max) and a different label at the same place: both new.
        let b = tracker
            .update(&mut graph, KeyframeId(1), &[candidate(1, 3.5, 0.0), candidate(2, 2.0, 0.0)], &config)
            .unwrap();
        assert_eq!(b.created.len(), 2);
        assert!(!b.objects.contains(&a.objects[0]));
        assert_eq!(graph.object_count(), 3);
        assert!(tracker.update(&mut graph, KeyframeId(9), &[], &config).is_err());
    }

    /// Keyframes 1 s apart along x, at `x(k)`.
    fn keyframes(graph: &mut SceneGraph, n: usize, x: impl Fn(usize) -> f64) {
        for k in 0..n {
            let world_from_body = pose_from_yaw_translation(0.0, Vector3::new(x(k), 0.0, 0.0));
            graph.add_keyframe(Keyframe { id: KeyframeId(k as u32), stamp: k as f64, world_from_body }).unwrap();
        }
    }

    /// A "chair" that is a person walking at 1.4 m/s beside the robot: tracked from keyframe to
    /// keyframe (each step within c_max = 1.5 m), confirmed at its third sighting (2.8 m gone),
    /// found moving at its fourth (4.2 m > 3 m + 0.3 m) and no longer confirmed; a real chair
    /// seen with 0.3 m of jitter stays confirmed.
    #[test]
    fn a_walking_object_is_found_moving_and_unconfirmed() {
        let mut graph = SceneGraph::new();
        let mut tracker = ObjectTracker::default();
        let config = TrackerConfig { max_track_distance_m: 1.5, ..TrackerConfig::default() };
        keyframes(&mut graph, 8, |k| 0.5 * k as f64);
        let mut ids = Vec::new();
        for k in 0..8 {
            let body_from_world = graph.keyframe(KeyframeId(k)).unwrap().world_from_body.inverse();
            let walker = body_from_world * Point3::new(3.0 + 1.4 * f64::from(k), 2.0, 0.5);
            let jitter = [0.3, -0.3, 0.2, -0.1, 0.3, -0.3, 0.0, 0.1][k as usize];
            let chair = body_from_world * Point3::new(6.0 + jitter, -2.0 - jitter, 0.5);
            let seen = [candidate(1, walker.x, walker.y), candidate(1, chair.x, chair.y)];
            ids.push(tracker.update(&mut graph, KeyframeId(k), &seen, &config).unwrap());
        }
        let (walker, chair) = (ids[0].objects[0], ids[0].objects[1]);
        assert!(ids.iter().all(|u| u.objects == vec![walker, chair]), "tracked throughout");
        assert!(tracker.is_moving(walker) && !tracker.is_confirmed(walker, &config));
        let confirmed_at: Vec<usize> = (0..8).filter(|&k| ids[k].newly_confirmed.contains(&walker)).collect();
        assert_eq!(confirmed_at, vec![2], "confirmed once, before it had gone far enough to tell");
        assert!(!tracker.is_moving(chair) && tracker.is_confirmed(chair, &config));
        assert_eq!(tracker.moving_count(), 1);
        // With the guard off the walker is confirmed like any object.
        let (mut graph, mut off) = (SceneGraph::new(), ObjectTracker::default());
        let config = TrackerConfig { moving_m: 0.0, ..config };
        keyframes(&mut graph, 4, |_| 0.0);
        for k in 0..4 {
            let seen = [candidate(1, 3.0 + 1.4 * f64::from(k), 2.0)];
            off.update(&mut graph, KeyframeId(k), &seen, &config).unwrap();
        }
        assert_eq!(off.moving_count(), 0);
    }

    /// A static object whose sightings drift apart slowly (the odometry's drift over a long
    /// mission, each re-anchoring within c_max): 4.5 m over 150 s, but never more than 0.9 m
    /// within the window, so never moving.
    #[test]
    fn drift_between_distant_sightings_is_not_motion() {
        let config = TrackerConfig::default();
        let mut graph = SceneGraph::new();
        let mut tracker = ObjectTracker::default();
        for k in 0..6u32 {
            let world_from_body = pose_from_yaw_translation(0.0, Vector3::zeros());
            graph.add_keyframe(Keyframe { id: KeyframeId(k), stamp: 30.0 * f64::from(k), world_from_body }).unwrap();
            let seen = [candidate(1, 5.0 + 0.9 * f64::from(k), 0.0)];
            tracker.update(&mut graph, KeyframeId(k), &seen, &config).unwrap();
        }
        assert_eq!(tracker.moving_count(), 0, "4.5 m over 150 s, but never more than 0.9 m within 10 s");
    }

    /// A lamp post seen, at the first keyframe, as two pieces one above the other (pole and
    /// head: two candidates, so two objects), then whole: the pieces are one object from the
    /// first keyframe on. Seen whole, its centroid is 1.3 m above the pole's, beyond c_max
    /// (1 m): a new object, merged too. Confirmed at the third sighting; a chair 1.2 m from it,
    /// of the same label, stays apart. Without `merge_stacked` three objects stand there.
    #[test]
    fn pieces_of_one_column_become_one_object() {
        let piece = |x: f64, z: f64, size: f64| ObjectCandidate {
            label: LabelId(3),
            centroid: Point3::new(x, 0.0, z),
            size: Vector3::new(size, size, 1.0),
            points: 50,
        };
        let run = |config: &TrackerConfig| {
            let mut graph = SceneGraph::new();
            let mut tracker = ObjectTracker::default();
            keyframes(&mut graph, 3, |_| 0.0);
            let first = [piece(5.0, 0.6, 0.15), piece(5.02, 3.7, 0.5), piece(6.2, 0.5, 0.5)];
            let whole = [piece(5.01, 1.9, 0.5), piece(6.2, 0.5, 0.5)];
            let updates: Vec<TrackUpdate> = (0..3)
                .map(|k| {
                    let seen: &[ObjectCandidate] = if k == 0 { &first } else { &whole };
                    tracker.update(&mut graph, KeyframeId(k), seen, config).unwrap()
                })
                .collect();
            (graph, tracker, updates)
        };
        let config = TrackerConfig::default();
        let (graph, tracker, updates) = run(&config);
        assert_eq!(graph.object_count(), 2, "one post, one chair");
        let (post, chair) = (updates[0].objects[0], updates[0].objects[2]);
        assert_eq!(updates[0].objects, vec![post, post, chair], "both pieces are the post");
        assert_eq!(updates[0].merged.len(), 1);
        assert_eq!(updates[0].created, vec![post, chair], "the head's object was created and merged");
        assert_eq!((updates[1].objects.clone(), updates[1].merged.len()), (vec![post, chair], 1));
        assert!(updates[2].merged.is_empty(), "the post is found where it was last seen whole");
        assert_eq!(tracker.sightings(post), 4);
        assert_eq!(updates[1].newly_confirmed, vec![post], "confirmed at its third sighting");
        assert_eq!(graph.keyframes_observing(post).count(), 3);
        assert_eq!(tracker.merged_count(), 2);
        let (graph, _, _) = run(&TrackerConfig { merge_stacked: false, ..config });
        assert_eq!(graph.object_count(), 4, "without it: pole, head, whole post, chair");
    }

    /// A false positive seen once (a blob of class 2 at (4, 3)) is gone once it has not been
    /// seen for `tentative_expiry_s` (10 s); a chair seen three times in the first 3 s is
    /// confirmed and stays; with the expiry at 0 the blob stays.
    #[test]
    fn an_unconfirmed_object_unseen_for_a_while_expires() {
        let run = |config: &TrackerConfig| {
            let mut graph = SceneGraph::new();
            let mut tracker = ObjectTracker::default();
            keyframes(&mut graph, 13, |k| 0.2 * k as f64);
            let mut expired = Vec::new();
            for k in 0..13u32 {
                let here = graph.keyframe(KeyframeId(k)).unwrap().world_from_body.inverse();
                let mut seen = Vec::new();
                if k < 3 {
                    let chair = here * Point3::new(6.0, -2.0, 0.5);
                    seen.push(candidate(1, chair.x, chair.y));
                }
                if k == 0 {
                    seen.push(candidate(2, 4.0, 3.0));
                }
                let update = tracker.update(&mut graph, KeyframeId(k), &seen, config).unwrap();
                expired.push((k, update.expired));
            }
            (graph, tracker, expired)
        };
        let config = TrackerConfig::default();
        let (graph, tracker, expired) = run(&config);
        let gone: Vec<u32> = expired.iter().filter(|(_, e)| !e.is_empty()).map(|(k, _)| *k).collect();
        assert_eq!(gone, vec![11], "last seen at 0 s, gone when 11 s > 10 s have passed");
        assert_eq!(graph.object_count(), 1);
        let chair = graph.objects().next().unwrap().id;
        assert!(tracker.is_confirmed(chair, &config));
        assert_eq!((tracker.expired_count(), tracker.sightings(expired[11].1[0])), (1, 0));
        let (graph, _, _) = run(&TrackerConfig { tentative_expiry_s: 0.0, ..config });
        assert_eq!(graph.object_count(), 2, "never expires at 0");
    }

    /// The tracker's state goes into snapshots (postcard, which is not self-describing): a
    /// tracker with and without moving objects and recent sightings reads back equal.
    #[test]
    fn the_state_survives_the_snapshot_encoding() {
        let mut graph = SceneGraph::new();
        let mut tracker = ObjectTracker::default();
        let config = TrackerConfig::default();
        keyframes(&mut graph, 6, |_| 0.0);
        for k in 0..6 {
            let seen = [candidate(1, 3.0 + 0.9 * f64::from(k), 2.0), candidate(2, -4.0, 1.0)];
            tracker.update(&mut graph, KeyframeId(k), &seen, &config).unwrap();
        }
        assert_eq!(tracker.moving_count(), 1);
        for state in [ObjectTracker::default(), tracker] {
            let bytes = postcard::to_allocvec(&state).unwrap();
            assert_eq!(postcard::from_bytes::<ObjectTracker>(&bytes).unwrap(), state);
        }
    }
}
