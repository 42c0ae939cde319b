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
//!   ‖(p_now − p_k)_xy‖ > `moving_m` + ½ max(size_x, size_y)      (p_k: an earlier sighting in the window)
//!
//! from where it was seen, horizontally (things move over the ground; a column seen whole, then
//! only its top, moves its centroid up, not away), each sighting kept in its keyframe's frame,
//! so the comparison goes through the current keyframe poses. A static object's centroid moves with its partial views,
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
//! footprint and their vertical extents are at most `max_stack_gap_m` apart:
//!
//!   |x_a − x_b| ≤ ½ size_x  and  |y_a − y_b| ≤ ½ size_y      (of a or of b; world axes)
//!   max(lo_a, lo_b) − min(hi_a, hi_b) ≤ `max_stack_gap_m`   (lo, hi = z ∓ ½ size_z)
//!
//! (the pieces merged on the library scenarios were at most 1.6 m apart; a chair on the floor
//! above stands 2.1 m or more over one below). The older object keeps its id and takes the other's sightings;
//! its centroid becomes the mean of both estimates' returns, as `clustering` joins a column,
//! and its size the extent of both (scene graph: `merge_objects`; read back, like every
//! object's, as a box centred on the centroid); its sightings are the keyframes that
//! saw either, so two pieces seen by one keyframe count once toward `confirm_after`. Merging
//! repeats until no piece is left, since the grown box may reach another. Moving objects are
//! left alone. A segmenter's false positive (a blob, a
//! label that bled onto a wall) is seen once or twice where nothing is; left in the map, later
//! false positives of its class within c_max attach to it until it is confirmed, and the
//! matcher meets objects that no other robot has. A *tentative* object (fewer than
//! `confirm_after` sightings) not seen for `tentative_expiry_s` is removed.
//!
//! Every view (beyond the paper; issue 31). The paper's object is its latest view, which moves
//! with every partial view and every side seen. An associated object's estimate (centroid and
//! size, read in the world through the current keyframe poses) moves toward the new view by
//!
//!   share = max(n / (W + n), 1 / `sighting_memory`)      (n: the view's returns, W: those so far)
//!
//! — the mean of all views weighted by their returns, each new one counting for at least
//! 1 / `sighting_memory`, so old views fade (1: the paper's latest view). A moving object
//! follows its latest view (share 1). A candidate's distance to an object is the nearer of the
//! object's estimate and its latest sighting: an estimate averaged over views lags behind a
//! thing that moves, and the latest sighting does not.
//!
//! Glimpses (beyond the paper; issue 31). Only keyframes add to the map, but every scan has
//! candidates. A camera looking ahead (100° wide) sees an object 2 m beside the route for
//! about 4 m of travel, two or three keyframes a metre apart; a segmenter that misses a view
//! now and then leaves many such objects short of `confirm_after`. On `handheld_indoor` seed 6
//! the two legged robots had one confirmed object in common and never aligned. A scan between
//! keyframes is a *glimpse*: its candidates, placed by the pose the scan would take as a
//! keyframe, are associated as a keyframe's are, and an association is one more sighting when
//! the sensor stands at least `glimpse_spacing_m` from where the object's latest sighting was
//! counted (a keyframe's or a glimpse's; read through that keyframe's current pose). The
//! spacing makes sightings views from different places, whatever the frame rate: a robot
//! standing still confirms nothing by looking longer. A glimpse makes no object, moves no
//! estimate and anchors nothing (the object's views stay the keyframes', whose scans hold its
//! points), and a moving object gains nothing.

use super::clustering::ObjectCandidate;
use crate::geometry::Pose3;
use crate::scene_graph::{KeyframeId, ObjectId, SceneGraph, SceneGraphError};
use crate::spatial::lap::{self, CostMatrix};
use nalgebra::{Point3, Vector3};
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
    /// Objects of one label standing in one column (either centroid in the other's footprint,
    /// at most `max_stack_gap_m` of free height between them) are merged after each keyframe.
    /// Default true.
    pub merge_stacked: bool,
    /// Objects in one column with more free height than this between them stay apart (a chair
    /// on each floor of a building), m. Default 2.0.
    pub max_stack_gap_m: f64,
    /// A tentative object (not yet confirmed) not seen for this long is removed, s. 0: never.
    /// Default 10.
    pub tentative_expiry_s: f64,
    /// An object's estimate is the mean of its sightings weighted by their returns, each new
    /// sighting counting for at least 1 / `sighting_memory` of it (module doc). 1: the latest
    /// sighting alone (the paper's re-anchoring). Default 20.
    pub sighting_memory: u32,
    /// A scan between keyframes counts as a sighting of an object it associates with when the
    /// sensor is at least this far from where the object's latest sighting was counted, m
    /// (module doc: glimpses). 0: only keyframes count. Default 0.
    pub glimpse_spacing_m: f64,
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
            max_stack_gap_m: 2.0,
            tentative_expiry_s: 10.0,
            sighting_memory: 20,
            glimpse_spacing_m: 0.0,
        }
    }
}

/// The share of a new sighting (`returns` points) in an estimate made of `fused` points
/// (module doc): its weight among all, and at least 1 / `memory`.
///
/// ```text
/// share = max(n / (W + n), 1 / memory)      (1 when W = 0 or memory ≤ 1)
/// ```
fn sighting_share(fused: usize, returns: usize, memory: u32) -> f64 {
    if fused == 0 || memory <= 1 {
        return 1.0;
    }
    (returns as f64 / (fused as f64 + returns as f64)).max(1.0 / f64::from(memory))
}

/// Where an object may be: its estimate, and its latest sighting if it has one.
type Whereabouts = [Option<Point3<f64>>; 2];

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
    /// The returns behind each object's estimate: of every sighting averaged into it, and of
    /// both pieces after a merge (the weights of a sighting's share and of a merge's centroid).
    #[serde(default)]
    points: BTreeMap<ObjectId, usize>,
    /// Where the sensor stood when each object's latest sighting was counted (a keyframe and
    /// the sensor in its body frame; the world through the keyframe's current pose): a glimpse
    /// counts only `glimpse_spacing_m` away from it.
    #[serde(default)]
    counted_from: BTreeMap<ObjectId, (KeyframeId, Point3<f64>)>,
    /// Sightings counted from glimpses so far.
    #[serde(default)]
    glimpsed: u64,
}

/// What one keyframe's candidates became.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TrackUpdate {
    /// Candidate index → the object it was associated with or created (after merges: the object
    /// it is now part of, so an id may repeat).
    pub objects: Vec<ObjectId>,
    pub created: Vec<ObjectId>,
    /// Objects that reached `confirm_after` sightings with this keyframe (glimpses confirm
    /// others between keyframes: [`ObjectTracker::glimpse`] returns them).
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

    /// The returns behind `id`'s estimate, accumulated over its views and merges (0 when
    /// unknown).
    fn points(&self, id: ObjectId) -> usize {
        self.points.get(&id).copied().unwrap_or(0)
    }

    /// Where `id` was last seen (its latest recent sighting, through the current keyframe pose).
    fn latest_sighting(&self, graph: &SceneGraph, id: ObjectId) -> Option<Point3<f64>> {
        let (k, c) = self.recent.get(&id)?.back()?;
        Some(graph.keyframe(*k)?.world_from_body * c)
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

    /// Sightings counted from glimpses so far.
    pub fn glimpse_count(&self) -> u64 {
        self.glimpsed
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
        if self.moving.contains(&id) {
            return;
        }
        if config.moving_m.is_nan() || config.moving_m <= 0.0 {
            // No motion test, but association still reads the latest sighting.
            self.recent.insert(id, VecDeque::from([(keyframe, candidate.centroid)]));
            return;
        }
        let Some(now) = graph.keyframe(keyframe) else { return };
        let p_now = now.world_from_body * candidate.centroid;
        let recent = self.recent.entry(id).or_default();
        recent.retain(|(k, _)| graph.keyframe(*k).is_some_and(|f| now.stamp - f.stamp <= config.moving_window_s));
        let reach = config.moving_m + 0.5 * candidate.size.x.max(candidate.size.y);
        let moved = recent
            .iter()
            .any(|(k, c)| graph.keyframe(*k).is_some_and(|f| (f.world_from_body * c - p_now).xy().norm() > reach));
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

    /// The LAP of eqs. 2–4: each candidate (centroid in the body frame at `world_from_body`)
    /// with the map object it associates with, if any, and its centroid in the world.
    fn associate(
        &self,
        graph: &SceneGraph,
        world_from_body: &Pose3,
        candidates: &[ObjectCandidate],
        config: &TrackerConfig,
    ) -> (Vec<Point3<f64>>, Vec<Option<ObjectId>>) {
        let in_world: Vec<_> = candidates.iter().map(|c| world_from_body * c.centroid).collect();
        let here = world_from_body.translation.vector;
        // An object is as near as its estimate or its latest sighting, whichever is nearer: an
        // estimate averaged over sightings lags behind a thing that moves (module doc).
        let nearby: Vec<(ObjectId, Whereabouts, crate::scene_graph::LabelId)> = graph
            .objects()
            .filter_map(|o| graph.centroid_in_world(o.id).map(|p| (o.id, p, o.label)))
            .filter(|(_, p, _)| (p.coords - here).norm() <= config.search_radius_m)
            .map(|(id, p, label)| (id, [Some(p), self.latest_sighting(graph, id)], label))
            .collect();
        let mut costs = CostMatrix::filled(candidates.len(), nearby.len(), FORBIDDEN);
        for (i, c) in candidates.iter().enumerate() {
            for (j, (_, at, label)) in nearby.iter().enumerate() {
                if *label == c.label {
                    let distance = at.iter().flatten().map(|p| (in_world[i] - p).norm()).fold(f64::INFINITY, f64::min);
                    costs.set(i, j, distance);
                }
            }
        }
        let assignment = if nearby.is_empty() { vec![None; candidates.len()] } else { lap::solve(&costs) };
        let matched = (0..candidates.len())
            .map(|i| assignment[i].filter(|&j| costs.get(i, j) < config.max_track_distance_m).map(|j| nearby[j].0))
            .collect();
        (in_world, matched)
    }

    /// Counts one more sighting of `id`; whether it confirmed it (reached `confirm_after`, not
    /// moving).
    fn count_sighting(&mut self, id: ObjectId, config: &TrackerConfig) -> bool {
        let count = self.sightings.entry(id).or_insert(0);
        *count = count.saturating_add(1);
        *count == config.confirm_after && !self.moving.contains(&id)
    }

    /// Where the sensor stood when `id`'s latest sighting was counted, in the world.
    fn counted_from(&self, graph: &SceneGraph, id: ObjectId) -> Option<Point3<f64>> {
        let (k, p) = self.counted_from.get(&id)?;
        Some(graph.keyframe(*k)?.world_from_body * p)
    }

    /// Counts a scan that is not a keyframe (glimpses, module doc), its body at
    /// `keyframe_from_body` from `keyframe` (the latest): each of its candidates (centroids in
    /// its body frame) that associates with a map object, `glimpse_spacing_m` or more from where
    /// that object's latest sighting was counted, is one more sighting of it. Nothing is
    /// created, moved or re-anchored. Returns the objects this confirmed.
    pub fn glimpse(
        &mut self,
        graph: &SceneGraph,
        keyframe: KeyframeId,
        keyframe_from_body: &Pose3,
        candidates: &[ObjectCandidate],
        config: &TrackerConfig,
    ) -> Vec<ObjectId> {
        let spacing = config.glimpse_spacing_m;
        if !(spacing > 0.0 && spacing.is_finite()) || candidates.is_empty() {
            return Vec::new();
        }
        let Some(at) = graph.keyframe(keyframe) else { return Vec::new() };
        let world_from_body = at.world_from_body * keyframe_from_body;
        let (_, matched) = self.associate(graph, &world_from_body, candidates, config);
        let here = Point3::from(world_from_body.translation.vector);
        let sensor = Point3::from(keyframe_from_body.translation.vector);
        let mut confirmed = Vec::new();
        for id in matched.into_iter().flatten() {
            let near = self.counted_from(graph, id).is_some_and(|p| (p - here).norm() < spacing);
            if self.moving.contains(&id) || near {
                continue;
            }
            self.counted_from.insert(id, (keyframe, sensor));
            self.glimpsed = self.glimpsed.saturating_add(1);
            if self.count_sighting(id, config) {
                confirmed.push(id);
            }
        }
        confirmed
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
        let (in_world, matched) = self.associate(graph, &world_from_body, candidates, config);
        let mut update = TrackUpdate::default();
        for (i, c) in candidates.iter().enumerate() {
            let id = match matched[i] {
                Some(id) => {
                    // A moving object's estimate is where it was seen last.
                    self.watch_motion(graph, id, keyframe, c, config);
                    let fused = if self.moving.contains(&id) { 0 } else { self.points(id) };
                    let share = sighting_share(fused, c.points, config.sighting_memory);
                    graph.observe_object(id, in_world[i], c.size, keyframe, share)?;
                    self.points.insert(id, if share < 1.0 { fused.saturating_add(c.points) } else { c.points });
                    id
                }
                None => {
                    let id = graph.add_object(c.label, in_world[i], c.size, keyframe)?;
                    update.created.push(id);
                    self.watch_motion(graph, id, keyframe, c, config);
                    self.points.insert(id, c.points);
                    id
                }
            };
            self.counted_from.insert(id, (keyframe, Point3::origin()));
            if self.count_sighting(id, config) {
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
    /// it (module doc), into the older id, until none is left: each merge grows the kept
    /// object's box, which may reach another piece.
    fn merge_stacked(
        &mut self,
        graph: &mut SceneGraph,
        update: &mut TrackUpdate,
        config: &TrackerConfig,
    ) -> Result<(), SceneGraphError> {
        let seen: BTreeSet<ObjectId> = update.objects.iter().copied().collect();
        for mut id in seen {
            while let Some(other) = self.first_in_column(graph, id, config) {
                let (keep, gone) = (id.min(other), id.max(other));
                self.fold(graph, update, keep, gone, config)?;
                id = keep;
            }
        }
        Ok(())
    }

    /// The first object of `id`'s label in one column with it (module doc), if `id` is still
    /// in the map and neither is moving.
    fn first_in_column(&self, graph: &SceneGraph, id: ObjectId, config: &TrackerConfig) -> Option<ObjectId> {
        let object = graph.object(id)?;
        if self.moving.contains(&id) {
            return None;
        }
        let p = graph.centroid_in_world(id)?;
        let a = Column { centroid: p, size: object.size };
        graph
            .objects()
            .filter(|o| o.id != id && o.label == object.label && !self.moving.contains(&o.id))
            .find(|o| {
                graph
                    .centroid_in_world(o.id)
                    .is_some_and(|q| a.is_one_with(&Column { centroid: q, size: o.size }, config.max_stack_gap_m))
            })
            .map(|o| o.id)
    }

    /// Folds `gone` into `keep` (scene graph: the union of the two) and carries the tracker's
    /// state over: the sightings are the keyframes that saw either (two pieces seen by one
    /// keyframe are one sighting), or more when glimpses counted more, the recent sightings
    /// both lists, newest kept, and where the latest sighting of either was counted.
    fn fold(
        &mut self,
        graph: &mut SceneGraph,
        update: &mut TrackUpdate,
        keep: ObjectId,
        gone: ObjectId,
        config: &TrackerConfig,
    ) -> Result<(), SceneGraphError> {
        let keep_was_confirmed = self.is_confirmed(keep, config);
        let (p_keep, p_gone) = (self.points(keep), self.points(gone));
        let gone_share = if p_keep + p_gone == 0 { 0.5 } else { p_gone as f64 / (p_keep + p_gone) as f64 };
        graph.merge_objects(keep, gone, gone_share)?;
        self.points.remove(&gone);
        self.points.insert(keep, p_keep.saturating_add(p_gone));
        let gone_sightings = self.sightings.remove(&gone).unwrap_or(0);
        // The latest counted sighting of either is the kept one's.
        if let Some(gone_from) = self.counted_from.remove(&gone) {
            let stamp = |k: Option<&(KeyframeId, Point3<f64>)>| {
                k.and_then(|(k, _)| graph.keyframe(*k)).map_or(f64::NEG_INFINITY, |f| f.stamp)
            };
            if stamp(Some(&gone_from)) >= stamp(self.counted_from.get(&keep)) {
                self.counted_from.insert(keep, gone_from);
            }
        }
        let seen_by = u32::try_from(graph.keyframes_observing(keep).count()).unwrap_or(u32::MAX);
        let sightings = self.sightings.entry(keep).or_insert(0);
        *sightings = seen_by.max(*sightings).max(gone_sightings);
        if let Some(gone_recent) = self.recent.remove(&gone) {
            let recent = self.recent.entry(keep).or_default();
            let mut both: Vec<_> = recent.drain(..).chain(gone_recent).collect();
            let stamp = |k: &KeyframeId| graph.keyframe(*k).map_or(f64::NEG_INFINITY, |f| f.stamp);
            both.sort_by(|(a, _), (b, _)| stamp(a).total_cmp(&stamp(b)).then(a.cmp(b)));
            let skip = both.len().saturating_sub(MAX_RECENT);
            recent.extend(both.into_iter().skip(skip));
        }
        self.merged += 1;
        for o in update.objects.iter_mut().filter(|o| **o == gone) {
            *o = keep;
        }
        update.created.retain(|o| *o != gone);
        update.newly_confirmed.retain(|o| *o != gone);
        // `keep` is confirmed now if either was: an id newly confirmed for whoever follows ids.
        if !keep_was_confirmed && self.is_confirmed(keep, config) && !update.newly_confirmed.contains(&keep) {
            update.newly_confirmed.push(keep);
        }
        update.merged.push((keep, gone));
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
            self.counted_from.remove(&id);
            self.recent.remove(&id);
            self.points.remove(&id);
            self.expired += 1;
            update.expired.push(id);
        }
        Ok(())
    }
}

/// An object's centroid and extent (world axes), as the column test takes them.
struct Column {
    centroid: Point3<f64>,
    size: Vector3<f64>,
}

impl Column {
    /// Whether `p` lies within the footprint (the xy extent).
    fn holds(&self, p: &Point3<f64>) -> bool {
        (p.x - self.centroid.x).abs() <= 0.5 * self.size.x && (p.y - self.centroid.y).abs() <= 0.5 * self.size.y
    }

    /// The free height between the two vertical extents; 0 when they overlap.
    fn gap_to(&self, other: &Column) -> f64 {
        let (lo_a, hi_a) = (self.centroid.z - 0.5 * self.size.z, self.centroid.z + 0.5 * self.size.z);
        let (lo_b, hi_b) = (other.centroid.z - 0.5 * other.size.z, other.centroid.z + 0.5 * other.size.z);
        (lo_a.max(lo_b) - hi_a.min(hi_b)).max(0.0)
    }

    /// One object in one column (module doc): either centroid in the other's footprint, with
    /// at most `max_gap_m` of free height between them.
    fn is_one_with(&self, other: &Column, max_gap_m: f64) -> bool {
        (self.holds(&other.centroid) || other.holds(&self.centroid)) && self.gap_to(other) <= max_gap_m
    }
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

    /// A chair at (6, 2) seen from keyframes on both sides of it, each view's centroid 0.2 m
    /// toward the robot (its visible side) and some views with more returns: the estimate is
    /// the mean of the views weighted by their returns, while the latest view alone is 0.2 m
    /// off. Past `sighting_memory` views a new one still counts for 1 / `sighting_memory`.
    #[test]
    fn sightings_are_averaged_by_their_returns() {
        let mut graph = SceneGraph::new();
        keyframes(&mut graph, 24, |_| 0.0);
        let view = |k: u32| {
            // Even keyframes see it from below (y < 2), odd ones from above; returns 100 or 300.
            let toward = if k % 2 == 0 { -0.2 } else { 0.2 };
            ObjectCandidate { points: if k % 4 < 2 { 100 } else { 300 }, ..candidate(6, 6.0, 2.0 + toward) }
        };
        let run = |memory: u32, views: u32| {
            let (mut graph, mut tracker) = (graph.clone(), ObjectTracker::default());
            let config = TrackerConfig { sighting_memory: memory, ..TrackerConfig::default() };
            for k in 0..views {
                tracker.update(&mut graph, KeyframeId(k), &[view(k)], &config).unwrap();
            }
            graph.centroid_in_world(ObjectId(0)).map(|p| p.y).unwrap_or(f64::NAN)
        };
        // Four views, 100 + 100 + 300 + 300 returns from below, above, below, above: the mean.
        let expected = (100.0 * 1.8 + 100.0 * 2.2 + 300.0 * 1.8 + 300.0 * 2.2) / 800.0;
        assert!((run(20, 4) - expected).abs() < 1e-9, "{}", run(20, 4));
        assert!((run(1, 4) - 2.2).abs() < 1e-9, "the paper's re-anchoring: the latest view");
        // Memory 2: each view counts for at least half. 1.8, then ½ of the way to 2.2 (2.0),
        // 300/500 of the way to 1.8 (1.88), and ½ (not 300/800) of the way to 2.2: 2.04.
        assert!((run(2, 4) - 2.04).abs() < 1e-9, "{}", run(2, 4));
        // Many views from both sides stay within the alternation's reach of the truth.
        assert!((run(20, 24) - 2.0).abs() < 0.03, "{}", run(20, 24));
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
        // With the guard off the walker is tracked, and confirmed, like any object: association
        // still reads its latest sighting, which its averaged estimate lags behind.
        let (mut graph, mut off) = (SceneGraph::new(), ObjectTracker::default());
        let config = TrackerConfig { moving_m: 0.0, ..config };
        keyframes(&mut graph, 4, |_| 0.0);
        let mut walker = Vec::new();
        for k in 0..4 {
            let seen = [candidate(1, 3.0 + 1.4 * f64::from(k), 2.0)];
            walker.extend(off.update(&mut graph, KeyframeId(k), &seen, &config).unwrap().objects);
        }
        assert_eq!(off.moving_count(), 0);
        assert!(walker.iter().all(|id| *id == walker[0]), "one object: {walker:?}");
        assert!(off.is_confirmed(walker[0], &config));
    }

    /// An 8 m tree seen whole, then less and less of its trunk as occluders rise in front of
    /// it: its centroid climbs 0.9 m a keyframe, 3.6 m in all (beyond `moving_m` + ½ its width,
    /// 3.3 m) and it is not moving, since it has not moved over the ground.
    #[test]
    fn a_centroid_that_climbs_is_not_motion() {
        let mut graph = SceneGraph::new();
        let mut tracker = ObjectTracker::default();
        keyframes(&mut graph, 5, |_| 0.0);
        let config = TrackerConfig::default();
        for k in 0..5u32 {
            let lo = 1.8 * f64::from(k);
            let view = ObjectCandidate {
                label: LabelId(2),
                centroid: Point3::new(6.0, 1.0, 0.5 * (lo + 8.0)),
                size: Vector3::new(0.6, 0.6, 8.0 - lo),
                points: 200,
            };
            let update = tracker.update(&mut graph, KeyframeId(k), &[view], &config).unwrap();
            assert!(update.created.is_empty() || k == 0, "one object throughout: {update:?}");
        }
        assert_eq!(tracker.moving_count(), 0);
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
    /// first keyframe on, their returns' mean (2.0 m up: 50 returns each), one sighting. Seen
    /// whole, its centroid (1.9 m up) is within c_max of that box's centre, 1.3 m above the
    /// pole's: without the union it would be a new object. Confirmed at the third keyframe, not
    /// the second (two pieces seen by one keyframe are one sighting); a chair 1.2 m from it, of
    /// the same label, stays apart. Without `merge_stacked` four objects stand there.
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
            let first = [piece(5.0, 0.6, 0.15), piece(5.02, 3.4, 0.5), piece(6.2, 0.5, 0.5)];
            let whole = [piece(5.01, 1.9, 0.5), piece(6.2, 0.5, 0.5)];
            let updates: Vec<TrackUpdate> = (0..3)
                .map(|k| {
                    let seen: &[ObjectCandidate] = if k == 0 { &first } else { &whole };
                    tracker.update(&mut graph, KeyframeId(k), seen, config).unwrap()
                })
                .collect();
            (graph, tracker, updates)
        };
        // The latest view alone: averaging sightings has its own test.
        let config = TrackerConfig { sighting_memory: 1, ..TrackerConfig::default() };
        let (graph, tracker, updates) = run(&config);
        assert_eq!(graph.object_count(), 2, "one post, one chair");
        let (post, chair) = (updates[0].objects[0], updates[0].objects[2]);
        assert_eq!(updates[0].objects, vec![post, post, chair], "both pieces are the post");
        assert_eq!(updates[0].merged.len(), 1);
        assert_eq!(updates[0].created, vec![post, chair], "the head's object was created and merged");
        let box_centre = graph.centroid_in_world(post).map(|p| p.z);
        assert!(updates[1..].iter().all(|u| u.objects == vec![post, chair] && u.merged.is_empty()), "{updates:?}");
        assert_eq!(tracker.sightings(post), 3);
        assert_eq!(updates[2].newly_confirmed, vec![post, chair], "confirmed at its third sighting");
        assert_eq!(graph.keyframes_observing(post).count(), 3);
        assert_eq!(tracker.merged_count(), 1);
        assert!(box_centre.is_some_and(|z| (z - 1.9).abs() < 1e-9), "the whole post's latest view");
        let (graph, _, _) = run(&TrackerConfig { merge_stacked: false, ..config });
        assert_eq!(graph.object_count(), 4, "without it: pole, head, whole post, chair");
    }

    /// A column seen in three pieces over three keyframes: the pole (0–1 m up), the head
    /// (3.5–4.5 m; 2.5 m above the pole, too far to be one with it alone), then the middle
    /// (1.5–2.8 m), which is one with both. All three are one object after the third keyframe:
    /// the middle folds into the pole, and the grown box reaches the head.
    #[test]
    fn a_column_seen_in_three_pieces_is_merged_whole() {
        let piece = |lo: f64, hi: f64| ObjectCandidate {
            label: LabelId(3),
            centroid: Point3::new(5.0, 0.0, 0.5 * (lo + hi)),
            size: Vector3::new(0.3, 0.3, hi - lo),
            points: 50,
        };
        let mut graph = SceneGraph::new();
        let mut tracker = ObjectTracker::default();
        keyframes(&mut graph, 3, |_| 0.0);
        let config = TrackerConfig::default();
        let pieces = [piece(0.0, 1.0), piece(3.5, 4.5), piece(1.5, 2.8)];
        let mut updates = Vec::new();
        for k in 0..3u32 {
            updates.push(tracker.update(&mut graph, KeyframeId(k), &pieces[k as usize..=k as usize], &config).unwrap());
            if k == 1 {
                assert_eq!(graph.object_count(), 2, "pole and head apart after two keyframes");
            }
        }
        let (pole, head) = (updates[0].objects[0], updates[1].objects[0]);
        assert!(updates[2].created.is_empty(), "the middle's object was folded away: {updates:?}");
        assert_eq!(graph.object_count(), 1);
        assert_eq!(updates[2].objects, vec![pole]);
        assert_eq!(updates[2].merged.len(), 2);
        assert!(graph.object(head).is_none());
        let post = graph.object(pole).unwrap();
        // Pole and middle (50 returns each): centroid 1.325 m up, size 2.8 m, read back as the box
        // 1.325 ± 1.4; with the head (50 returns, 4.0 m): ⅔ · 1.325 + ⅓ · 4.0, box up to 4.5 m.
        let centroid = graph.centroid_in_world(pole).map(|p| p.z).unwrap_or(f64::NAN);
        assert!((centroid - (2.0 * 1.325 + 4.0) / 3.0).abs() < 1e-9, "{post:?}");
        assert!((post.size.z - (4.5 - (1.325 - 1.4))).abs() < 1e-9, "{post:?}");
        assert_eq!(graph.keyframes_observing(pole).count(), 3);
        assert_eq!(tracker.sightings(pole), 3);
    }

    /// A tentative chair (one sighting) and a confirmed one 1.2 m from it (three), merged when a
    /// wider view of the second reaches the first: the merged object keeps the older, tentative
    /// id, and that id is reported newly confirmed.
    #[test]
    fn a_confirmed_piece_folded_into_a_tentative_one_confirms_the_kept_id() {
        let chair = |x: f64, width: f64| ObjectCandidate {
            label: LabelId(6),
            centroid: Point3::new(x, 0.0, 0.45),
            size: Vector3::new(width, 0.5, 0.9),
            points: 50,
        };
        let mut graph = SceneGraph::new();
        let mut tracker = ObjectTracker::default();
        keyframes(&mut graph, 5, |_| 0.0);
        // The latest view alone, whose width reaches the first chair at once.
        let config = TrackerConfig { sighting_memory: 1, ..TrackerConfig::default() };
        let seen = [
            vec![chair(5.0, 0.5)],
            vec![chair(6.2, 0.5)],
            vec![chair(6.2, 0.5)],
            vec![chair(6.2, 0.5)],
            vec![chair(6.2, 2.6)],
        ];
        let updates: Vec<TrackUpdate> =
            (0..5u32).map(|k| tracker.update(&mut graph, KeyframeId(k), &seen[k as usize], &config).unwrap()).collect();
        let (first, second) = (updates[0].objects[0], updates[1].objects[0]);
        assert_eq!(updates[3].newly_confirmed, vec![second]);
        assert_eq!(updates[4].merged, vec![(first, second)]);
        assert_eq!(updates[4].newly_confirmed, vec![first], "{:?}", updates[4]);
        assert!(tracker.is_confirmed(first, &config) && graph.object_count() == 1);
    }

    /// Two chairs in one column, one on each floor (3 m apart: 2.1 m of free height between
    /// them), are two objects; 1.8 m apart (a chair cut by a gap between beams, as merges on
    /// the library scenarios were up to 1.6 m) they are one.
    #[test]
    fn a_chair_on_the_floor_above_stays_apart() {
        let chair = |z: f64| ObjectCandidate {
            label: LabelId(6),
            centroid: Point3::new(5.0, 0.0, z),
            size: Vector3::new(0.5, 0.5, 0.9),
            points: 50,
        };
        for (above, objects) in [(3.45, 2), (3.15, 1)] {
            let mut graph = SceneGraph::new();
            let mut tracker = ObjectTracker::default();
            keyframes(&mut graph, 2, |_| 0.0);
            let config = TrackerConfig::default();
            tracker.update(&mut graph, KeyframeId(0), &[chair(0.45)], &config).unwrap();
            tracker.update(&mut graph, KeyframeId(1), &[chair(above)], &config).unwrap();
            assert_eq!(graph.object_count(), objects, "the upper chair at {above} m");
        }
    }

    /// A chair at (5, 2) seen by keyframe 0 (the sensor at x = 0), then by scans between
    /// keyframes (candidates in their body frames), with `glimpse_spacing_m` 0.4: the scan from
    /// x = 0.3 is too near where the chair was last counted, the one from 0.5 is a second
    /// sighting, from 0.7 again too near (0.2 from 0.5), from 0.9 the third, which confirms it.
    /// Nothing else changes: no object made of the bench only a glimpse saw, the chair's
    /// estimate and anchor where keyframe 0 left them. A candidate beyond c_max, an object found
    /// moving, and any glimpse with a spacing of 0, gain nothing.
    #[test]
    fn glimpses_count_sightings_a_spacing_apart_and_change_nothing_else() {
        let mut graph = SceneGraph::new();
        keyframes(&mut graph, 1, |_| 0.0);
        let mut tracker = ObjectTracker::default();
        let config = TrackerConfig { glimpse_spacing_m: 0.4, ..TrackerConfig::default() };
        let chair = tracker.update(&mut graph, KeyframeId(0), &[candidate(6, 5.0, 2.0)], &config).unwrap().objects[0];
        let before = (graph.centroid_in_world(chair), graph.object(chair).map(|o| o.anchor));
        let from = |x: f64| pose_from_yaw_translation(0.0, Vector3::new(x, 0.0, 0.0));
        let seen_from = |x: f64| [candidate(6, 5.0 - x, 2.1), candidate(4, 3.0, -2.0)];
        let glimpse = |tracker: &mut ObjectTracker, x: f64, seen: &[ObjectCandidate], config: &TrackerConfig| {
            tracker.glimpse(&graph, KeyframeId(0), &from(x), seen, config)
        };
        let off = TrackerConfig::default();
        assert!(glimpse(&mut tracker, 0.5, &seen_from(0.5), &off).is_empty());
        assert_eq!(tracker.sightings(chair), 1, "spacing 0: glimpses count nothing");
        assert!(glimpse(&mut tracker, 0.3, &seen_from(0.3), &config).is_empty());
        assert_eq!(tracker.sightings(chair), 1, "0.3 m from keyframe 0's sighting");
        assert!(glimpse(&mut tracker, 0.5, &seen_from(0.5), &config).is_empty());
        assert_eq!(tracker.sightings(chair), 2);
        let far = glimpse(&mut tracker, 1.5, &[candidate(6, 3.5 + 1.2, 2.0)], &config);
        assert!(far.is_empty() && tracker.sightings(chair) == 2, "a candidate 1.2 m off is not the chair");
        assert!(glimpse(&mut tracker, 0.7, &seen_from(0.7), &config).is_empty());
        assert_eq!(tracker.sightings(chair), 2, "0.2 m from the glimpse counted at 0.5");
        assert_eq!(glimpse(&mut tracker, 0.9, &seen_from(0.9), &config), vec![chair]);
        assert!(tracker.is_confirmed(chair, &config));
        assert_eq!(graph.object_count(), 1, "a glimpse makes no object");
        assert_eq!((graph.centroid_in_world(chair), graph.object(chair).map(|o| o.anchor)), before);
        // Where a sighting was counted moves with its keyframe: keyframe 0 moved 2 m along x puts
        // the glimpse counted at 0.9 at 2.9, so one from 3.0 is too near and one from 3.5 is not.
        let moved = from(2.0);
        graph.update_keyframe_poses([(KeyframeId(0), &moved)]).unwrap();
        assert!(tracker.glimpse(&graph, KeyframeId(0), &from(1.0), &seen_from(1.0), &config).is_empty());
        assert_eq!(tracker.sightings(chair), 3, "0.1 m from the glimpse counted at 0.9, moved to 2.9");
        assert!(tracker.glimpse(&graph, KeyframeId(0), &from(1.5), &seen_from(1.5), &config).is_empty());
        assert_eq!(tracker.sightings(chair), 4);
        tracker.moving.insert(chair);
        assert!(tracker.glimpse(&graph, KeyframeId(0), &from(2.5), &seen_from(2.5), &config).is_empty());
        assert_eq!(tracker.sightings(chair), 4, "a moving object gains no sightings");
        assert_eq!(tracker.glimpse_count(), 3, "the glimpses from 0.5, 0.9 and 3.5 counted");
    }

    /// A post seen low by keyframe 0 (x = 0) and high by keyframe 1 (x = 1): the high piece is
    /// a new object merged into the older one, which takes the piece's counted sighting (keyframe
    /// 1), so a glimpse 0.2 m past keyframe 1 is too near to count, one 0.6 m past counts.
    #[test]
    fn a_merge_keeps_the_latest_counted_sighting() {
        let mut graph = SceneGraph::new();
        keyframes(&mut graph, 2, |k| k as f64);
        let mut tracker = ObjectTracker::default();
        let config = TrackerConfig { glimpse_spacing_m: 0.4, ..TrackerConfig::default() };
        let piece =
            |x: f64, z: f64| ObjectCandidate { centroid: Point3::new(5.0 - x, 2.0, z), ..candidate(3, 0.0, 0.0) };
        let post = tracker.update(&mut graph, KeyframeId(0), &[piece(0.0, 0.5)], &config).unwrap().objects[0];
        let second = tracker.update(&mut graph, KeyframeId(1), &[piece(1.0, 2.0)], &config).unwrap();
        assert_eq!(second.merged.len(), 1, "{second:?}");
        assert_eq!(second.objects, vec![post]);
        assert_eq!(tracker.sightings(post), 2);
        let at = graph.centroid_in_world(post).unwrap();
        let glimpse = |tracker: &mut ObjectTracker, x: f64| {
            let seen = [piece(1.0 + x, at.z)];
            tracker.glimpse(
                &graph,
                KeyframeId(1),
                &pose_from_yaw_translation(0.0, Vector3::new(x, 0.0, 0.0)),
                &seen,
                &config,
            )
        };
        assert!(glimpse(&mut tracker, 0.2).is_empty());
        assert_eq!(tracker.sightings(post), 2, "0.2 m from keyframe 1, where the merged piece was counted");
        assert_eq!(glimpse(&mut tracker, 0.6), vec![post]);
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
