//! The Scan Context baseline's side of the Matcher, per neighbour: the neighbour's keyframe
//! descriptors, and the keyframe pairs whose descriptors agree, best first. Every pair is
//! compared once: each new local keyframe queries the neighbour's descriptors, each new
//! neighbour descriptor queries the local keyframes (Kim & Kim's ring-key pre-selection, then
//! the column-shift distance, `model::matching::scan_context::retrieve`).

use crate::geometry::Pose3;
use crate::matching::scan_context::{retrieve, Place, ScanContextConfig};
use crate::scene_graph::KeyframeId;
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, BTreeSet};

/// The Scan Context baseline's association (`association = "scan_context"`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ScanContextSection {
    /// Descriptor shape: `rings`, `sectors`, `max_range_m`, `height_offset_m`. Defaults
    /// 20, 60, 80 m, 2 m (Kim & Kim).
    #[serde(flatten)]
    pub descriptor: ScanContextConfig,
    /// A keyframe pair is a candidate below this column-shift distance. Default 0.13 (Kim &
    /// Kim's released code: "0.1–0.2 is fine" for 20 × 60 descriptors).
    pub max_distance: f64,
    /// Neighbour keyframes compared in full per query, the nearest by ring key. Default 10.
    pub ring_key_candidates: usize,
    /// Correspondence distance of the coarse ICP stage from the descriptor's yaw, m (the
    /// fine stage uses `icp.max_correspondence_distance_m`). Default 5.
    pub coarse_correspondence_m: f64,
    /// Descriptors kept at most: ours, and each neighbour's. Beyond it every second one is
    /// dropped (in keyframe order, the newest kept), so what stays spans the whole run, thinner
    /// the older it is. A 20 × 60 descriptor is 4.8 KB. Default 1000.
    pub max_places: usize,
}

impl Default for ScanContextSection {
    fn default() -> Self {
        Self {
            descriptor: ScanContextConfig::default(),
            max_distance: 0.13,
            ring_key_candidates: 10,
            coarse_correspondence_m: 5.0,
            max_places: 1000,
        }
    }
}

/// A local and a neighbour keyframe that look like the same place.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlaceCandidate {
    pub local: KeyframeId,
    pub remote: KeyframeId,
    /// Column-shift distance, in [0, 1].
    pub distance: f64,
    /// The neighbour's scan is ours turned by this yaw about z: local_body_from_remote_body
    /// ≈ Rz(−yaw) (same place, so no translation), rad.
    pub yaw: f64,
}

/// Candidates kept waiting at most (the best).
const MAX_WAITING: usize = 64;

/// Descriptors kept evenly over a run, at most `max`: the n-th to arrive is kept while n is a
/// multiple of the stride, and the stride doubles (dropping every second one held) whenever more
/// than `max` are held. Between `max / 2` and `max` stay, spread evenly from the first keyframe
/// to the newest, whatever the run's length.
#[derive(Clone, Debug)]
pub struct EvenPlaces {
    places: BTreeMap<KeyframeId, Place>,
    /// Arrival number of each held descriptor.
    arrival: BTreeMap<KeyframeId, u64>,
    arrived: u64,
    stride: u64,
}

impl Default for EvenPlaces {
    fn default() -> Self {
        Self { places: BTreeMap::new(), arrival: BTreeMap::new(), arrived: 0, stride: 1 }
    }
}

impl EvenPlaces {
    /// Offers keyframe `id`'s descriptor; returns the keyframes whose descriptors were dropped
    /// to stay within `max` (not `id` itself, even when it is not kept).
    pub fn insert(&mut self, id: KeyframeId, place: Place, max: usize) -> Vec<KeyframeId> {
        let n = self.arrived;
        self.arrived += 1;
        if n % self.stride != 0 || self.places.contains_key(&id) {
            return Vec::new();
        }
        self.places.insert(id, place);
        self.arrival.insert(id, n);
        let mut dropped = Vec::new();
        while self.places.len() > max.max(1) {
            self.stride = self.stride.saturating_mul(2);
            let stride = self.stride;
            let gone: Vec<KeyframeId> =
                self.arrival.iter().filter(|(_, n)| *n % stride != 0).map(|(k, _)| *k).collect();
            for k in &gone {
                self.places.remove(k);
                self.arrival.remove(k);
            }
            dropped.extend(gone);
        }
        dropped
    }

    /// Forgets keyframe `id`'s descriptor; whether one was held.
    pub fn remove(&mut self, id: KeyframeId) -> bool {
        self.arrival.remove(&id);
        self.places.remove(&id).is_some()
    }

    pub fn held(&self) -> &BTreeMap<KeyframeId, Place> {
        &self.places
    }
}

#[derive(Clone, Debug, Default)]
pub struct PlaceCandidates {
    /// Every keyframe pose the neighbour shared (its world); a few dozen bytes each, kept for
    /// the keyframes around a candidate.
    remote_poses: BTreeMap<KeyframeId, Pose3>,
    /// The neighbour's descriptors, at most `max_places`.
    remote: EvenPlaces,
    queried_local: BTreeSet<KeyframeId>,
    queried_remote: BTreeSet<KeyframeId>,
    /// Pairs already handed out (never handed out twice).
    tried: BTreeSet<(KeyframeId, KeyframeId)>,
    /// Best first.
    waiting: Vec<PlaceCandidate>,
}

impl PlaceCandidates {
    /// Keeps the neighbour's descriptor of keyframe `id` (the first one sent), thinning the
    /// descriptors to `max_places`.
    pub fn add_remote(&mut self, id: KeyframeId, world_from_body: Pose3, place: Place, max_places: usize) {
        if self.remote_poses.contains_key(&id) {
            return;
        }
        self.remote_poses.insert(id, world_from_body);
        for dropped in self.remote.insert(id, place, max_places) {
            self.queried_remote.remove(&dropped);
            self.waiting.retain(|c| c.remote != dropped);
            self.tried.retain(|&(_, remote)| remote != dropped);
        }
    }

    /// Forgets our keyframes whose descriptors are gone (thinned, or the scan evicted).
    pub fn forget_local(&mut self, dropped: &[KeyframeId]) {
        for id in dropped {
            self.queried_local.remove(id);
            self.waiting.retain(|c| c.local != *id);
            self.tried.retain(|&(local, _)| local != *id);
        }
    }

    /// Neighbour keyframes ever shared (never decreases: thinning drops descriptors only).
    pub fn remote_count(&self) -> usize {
        self.remote_poses.len()
    }

    /// Neighbour descriptors held.
    pub fn descriptors_held(&self) -> usize {
        self.remote.held().len()
    }

    pub fn remote_pose(&self, id: KeyframeId) -> Option<Pose3> {
        self.remote_poses.get(&id).copied()
    }

    pub fn knows_remote(&self, id: KeyframeId) -> bool {
        self.remote_poses.contains_key(&id)
    }

    /// Compares every pair not yet compared and keeps those under `max_distance`.
    pub fn update(&mut self, local: &BTreeMap<KeyframeId, Place>, config: &ScanContextSection) {
        let k = config.ring_key_candidates;
        let mut found = Vec::new();
        for (id, place) in local.iter().filter(|(id, _)| !self.queried_local.contains(id)) {
            let database = self.remote.held().iter().map(|(r, p)| (*r, p));
            if let Some((remote, m)) = retrieve(place, database, k) {
                let yaw = place.descriptor.yaw_of_shift(m.shift);
                found.push(PlaceCandidate { local: *id, remote, distance: m.distance, yaw });
            }
        }
        self.queried_local.extend(local.keys().copied());
        for (id, place) in self.remote.held().iter().filter(|(id, _)| !self.queried_remote.contains(id)) {
            if let Some((local_id, m)) = retrieve(place, local.iter().map(|(l, p)| (*l, p)), k) {
                // `place` is the query here: the match turned around (ours ↔ theirs).
                let sectors = place.descriptor.sectors.max(1);
                let yaw = place.descriptor.yaw_of_shift((sectors - m.shift) % sectors);
                found.push(PlaceCandidate { local: local_id, remote: *id, distance: m.distance, yaw });
            }
        }
        self.queried_remote.extend(self.remote.held().keys().copied());
        for c in found {
            let pair = (c.local, c.remote);
            let known = self.waiting.iter().any(|w| (w.local, w.remote) == pair);
            if c.distance <= config.max_distance && !known && !self.tried.contains(&pair) {
                self.waiting.push(c);
            }
        }
        self.waiting
            .sort_by(|a, b| a.distance.total_cmp(&b.distance).then((a.local, a.remote).cmp(&(b.local, b.remote))));
        self.waiting.truncate(MAX_WAITING);
    }

    /// The best candidate not handed out before.
    pub fn take_best(&mut self) -> Option<PlaceCandidate> {
        if self.waiting.is_empty() {
            return None;
        }
        let best = self.waiting.remove(0);
        self.tried.insert((best.local, best.remote));
        Some(best)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::pose_from_rpy_translation;
    use crate::matching::scan_context::ScanContext;
    use nalgebra::{Point3, Vector3};

    const SECTOR: f64 = std::f64::consts::TAU / 60.0;
    const MAX: usize = 1000;

    /// A place (`seed` makes places differ): three walls whose heights vary with the bearing,
    /// sampled at sector centres, seen from a body turned by `turn` whole sectors.
    fn scan(seed: u64, turn: usize) -> Vec<Point3<f64>> {
        let s = seed as f64;
        let walls = [(5.0 + s * 3.1, 1.0 + s * 0.3, 1.0), (17.0 + s * 2.3, 2.0, 2.0 + s), (45.0 - s, 3.0, 3.0)];
        walls
            .iter()
            .flat_map(|&(r, h, f)| {
                (0..60).map(move |j| {
                    let bearing = (j as f64 + 0.5) * SECTOR;
                    let seen = bearing - turn as f64 * SECTOR;
                    Point3::new(r * seen.cos(), r * seen.sin(), h * (1.0 + (f * bearing + s).sin()))
                })
            })
            .collect()
    }

    fn place(points: &[Point3<f64>]) -> Place {
        Place::new(ScanContext::new(points, &Default::default()))
    }

    #[test]
    fn the_same_place_is_found_with_its_yaw_and_handed_out_once() {
        let config = ScanContextSection::default();
        let local: BTreeMap<KeyframeId, Place> = (0..5).map(|k| (KeyframeId(k), place(&scan(k as u64, 0)))).collect();
        let mut c = PlaceCandidates::default();
        // The neighbour's keyframe 40 stands where our keyframe 3 stood, turned by 6 sectors
        // (36°); its keyframe 41 is somewhere new.
        let pose = pose_from_rpy_translation(0.0, 0.0, 0.0, Vector3::zeros());
        c.add_remote(KeyframeId(40), pose, place(&scan(3, 6)), MAX);
        c.add_remote(KeyframeId(41), pose, place(&scan(9, 0)), MAX);
        c.update(&local, &config);
        let best = c.take_best().expect("a candidate");
        assert_eq!((best.local, best.remote), (KeyframeId(3), KeyframeId(40)));
        assert!(best.distance < 1e-9, "{best:?}");
        // A point at bearing b in our body is at b − 6 sectors in theirs: theirs = Rz(−36°)·ours.
        assert!((best.yaw - 54.0 * SECTOR).abs() < 1e-9, "yaw {}", best.yaw);
        assert!(c.take_best().is_none(), "keyframe 41 matches nothing: {:?}", c.take_best());
        // Nothing is handed out twice, also after more updates.
        c.update(&local, &config);
        assert!(c.take_best().is_none_or(|n| (n.local, n.remote) != (best.local, best.remote)));
    }

    #[test]
    fn both_directions_find_the_pair() {
        // The local keyframe arrives after the neighbour's descriptor: found by the local query.
        let config = ScanContextSection::default();
        let pose = pose_from_rpy_translation(0.0, 0.0, 0.0, Vector3::zeros());
        let mut c = PlaceCandidates::default();
        c.add_remote(KeyframeId(7), pose, place(&scan(2, 10)), MAX);
        c.update(&BTreeMap::new(), &config);
        assert!(c.take_best().is_none());
        let local: BTreeMap<KeyframeId, Place> = [(KeyframeId(1), place(&scan(2, 0)))].into();
        c.update(&local, &config);
        let a = c.take_best().expect("found by the local query");
        // The neighbour's descriptor arrives after the local keyframe: found by its query.
        let mut d = PlaceCandidates::default();
        d.update(&local, &config);
        d.add_remote(KeyframeId(7), pose, place(&scan(2, 10)), MAX);
        d.update(&local, &config);
        let b = d.take_best().expect("found by the neighbour's query");
        assert_eq!((a.local, a.remote), (b.local, b.remote));
        assert!((a.yaw - 50.0 * SECTOR).abs() < 1e-9, "yaw {}", a.yaw);
        assert!((a.yaw - b.yaw).abs() < 1e-12, "the same yaw either way: {} {}", a.yaw, b.yaw);
        assert!((a.distance - b.distance).abs() < 1e-12);
    }
    #[test]
    fn descriptors_stay_within_the_bound_spread_evenly_over_the_run() {
        let one = place(&scan(1, 0));
        let mut places = EvenPlaces::default();
        let mut dropped_all = Vec::new();
        for k in 0..1000 {
            dropped_all.extend(places.insert(KeyframeId(k), one.clone(), 64));
            assert!(places.held().len() <= 64, "{} held after keyframe {k}", places.held().len());
        }
        let held: Vec<u32> = places.held().keys().map(|k| k.0).collect();
        // 1000 arrivals, at most 64 kept: every 16th, from the first to within 16 of the newest.
        assert_eq!(held, (0..1000).step_by(16).collect::<Vec<u32>>());
        assert!(dropped_all.iter().all(|k| !places.held().contains_key(k)));
        assert!(places.remove(KeyframeId(16)) && !places.remove(KeyframeId(16)));
        assert!(!places.held().contains_key(&KeyframeId(16)));
    }

    #[test]
    fn thinned_descriptors_are_never_candidates_but_their_poses_stay_known() {
        let config = ScanContextSection::default();
        let pose = pose_from_rpy_translation(0.0, 0.0, 0.0, Vector3::zeros());
        let local: BTreeMap<KeyframeId, Place> = (0..3).map(|k| (KeyframeId(k), place(&scan(k as u64, 0)))).collect();
        let mut c = PlaceCandidates::default();
        // Six neighbour keyframes, all our keyframe 1 seen turned; at most 4 descriptors kept.
        for r in 10..16u32 {
            c.add_remote(KeyframeId(r), pose, place(&scan(1, r as usize)), 4);
        }
        assert_eq!((c.remote_count(), c.descriptors_held()), (6, 3));
        assert!((10..16).all(|r| c.knows_remote(KeyframeId(r)) && c.remote_pose(KeyframeId(r)).is_some()));
        c.update(&local, &config);
        let mut handed = Vec::new();
        while let Some(best) = c.take_best() {
            handed.push(best.remote.0);
        }
        handed.sort_unstable();
        assert_eq!(handed, vec![10, 12, 14], "only the descriptors held");
        // Our keyframe 1's descriptor goes (thinned or its scan evicted): no candidate names it.
        let mut d = PlaceCandidates::default();
        d.add_remote(KeyframeId(10), pose, place(&scan(1, 3)), 4);
        d.update(&local, &config);
        d.forget_local(&[KeyframeId(1)]);
        assert!(d.take_best().is_none_or(|b| b.local != KeyframeId(1)));
    }
}
