//! The report's figures. ATE by the paper's convention: each robot's optimised keyframe
//! positions against the truth at the same stamps, aligned by SE(3) Umeyama
//! (`model::eval::ate`, what `evo_ape tum -a` does); for the team, every robot's trajectory is
//! brought into the reference robot's (the first robot's) world by that robot's own estimate of
//! `local_from_remote`, merged into one, and aligned once. A robot the reference has not aligned
//! cannot be merged: it is listed in `team_ate_robots` only once it is.

use crate::observation::Observation;
use crate::record::{PairError, RobotTruth, RunRecord, SeriesPoint};
use crate::sim::radio::RadioStats;
use nalgebra::Point3;
use serde::Serialize;
use sgm_actors::protocol::ProtocolStage;
use sgm_model::eval::ate::ate;
use sgm_model::geometry::{pose_error, Pose3};
use sgm_model::matching::suspect::suspicions;
use sgm_model::scene_graph::{KeyframeId, RobotId};
use sgm_model::wire::{MessageKind, TrafficAccount};
use std::collections::BTreeMap;

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RobotReport {
    pub name: String,
    /// ATE RMSE of the robot's own trajectory, m (`None` with fewer than 3 keyframes).
    pub ate_rmse_m: Option<f64>,
    pub keyframes: usize,
    /// Objects in the map (confirmed or not).
    pub objects: usize,
    pub confirmed_objects: usize,
    /// Objects found moving (`tracker.tracking.moving_m`): kept out of the shared map.
    pub moving_objects: usize,
    /// Objects merged into another, one object seen as two (`tracker.tracking.merge_stacked`).
    pub merged_objects: u64,
    /// Tentative objects removed, unseen for `tracker.tracking.tentative_expiry_s`.
    pub expired_objects: u64,
    /// Sightings counted from scans between keyframes (`tracker.tracking.glimpse_spacing_m`).
    pub glimpse_sightings: u64,
    /// Confirmed objects whose class has a world object within 2 m (the robot's start frame
    /// placed on the truth), counted once per world object. None when the world is unknown
    /// (a replay).
    pub objects_found: Option<usize>,
    /// Confirmed objects beyond the first for one world object, or with nothing of their class
    /// within 2 m. None when the world is unknown.
    pub objects_spurious: Option<usize>,
    /// Mean distance of the found objects to their world object, m.
    pub object_error_m: Option<f64>,
    /// Distance travelled, m: along the true path, or the estimated keyframes without truth.
    pub distance_m: f64,
    pub frames: u64,
    /// The map's cloud store at the end (`tracker.cloud_store`).
    pub clouds: sgm_model::scene_graph::CloudStoreStats,
    /// Scans deskewed from their per-point times, and those used as they came with the reason
    /// (`fusion.deskew`; since Fusion last started).
    pub deskew: sgm_model::perception::deskew::DeskewCounts,
    /// The internal odometry's counts (`odometry.source = "internal"`; absent otherwise).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub odometry: Option<sgm_actors::odometry::OdometryStatus>,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct AlignmentReport {
    pub local: String,
    pub remote: String,
    /// Protocol state at the end.
    pub state: String,
    pub first_aligned_s: Option<f64>,
    /// The alignment (the first, or the one after a withdrawal) started from this robot's
    /// alignment (`matcher.relay`), not from object-graph matching.
    pub aligned_via: Option<String>,
    pub translation_error_m: Option<f64>,
    /// estimate − truth of local_from_remote's translation, local world axes, m.
    pub translation_error_xyz_m: Option<[f64; 3]>,
    /// Against the robots' start frames instead: includes the odometry drift of both maps up
    /// to where they met, m.
    pub start_frame_translation_error_m: Option<f64>,
    pub rotation_error_deg: Option<f64>,
    /// Closure rounds after the first alignment (`matcher.closures`): rounds, factors they
    /// added, keyframe-cloud bytes they cost.
    pub closures: sgm_actors::matcher::ClosureCounts,
    /// Inter-robot factors with this neighbour in the local pose graph (first round and
    /// closures, injected false ones included).
    pub inter_robot_factors: usize,
    /// Of those, outside the largest mutually consistent set (PCM) at the last solve: a
    /// neighbour whose factors disagree with each other shows here.
    pub inconsistent_factors: usize,
    /// Times the consistent set's transform moved the alignment.
    pub realigned: u32,
    /// Priors of the remote's keyframes moved by its pose updates (`KeyframePoses`,
    /// `[comms.pose_updates]`), in all.
    pub priors_refreshed: u64,
    /// The robots whose alignments, relayed around a cycle, put the remote elsewhere (the
    /// local robot's status, `matcher.relay.contradiction_m`): one alignment of the cycle is
    /// wrong.
    pub contradicted_by: Vec<String>,
    /// Times the local robot withdrew its alignment of the remote: a contradicted cycle
    /// settled against it by object evidence (`matcher.relay.settle`), or a stronger match that
    /// put the remote elsewhere (`matcher.relay.rematch`).
    pub withdrawals: u32,
    /// When and why the latest withdrawal was made.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub last_withdrawal: Option<String>,
    /// Why the local robot holds the remote suspect (`model::matching::suspect`: many of its
    /// inter-robot factors outside the consistent set, or its object graph's matches refuted
    /// again and again), one line per finding; omitted when nothing stands out.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub suspect: Vec<String>,
    /// The object-graph matches made against the remote and why the latest started no round
    /// (the local robot's status): why a pair is not aligned.
    pub match_attempts: sgm_actors::matcher::MatchAttempts,
}

impl AlignmentReport {
    /// " (relayed by NAME)" when the first alignment started from that robot's, else "".
    pub fn relayed_note(&self) -> String {
        self.aligned_via.as_ref().map_or(String::new(), |v| format!(" (relayed by {v})"))
    }

    /// ", contradicted through NAME, NAME" when robots' relayed alignments contradict it, and
    /// ", N alignment(s) withdrawn" when contradicted cycles were settled against it; else "".
    pub fn contradiction_note(&self) -> String {
        let mut note = String::new();
        if !self.contradicted_by.is_empty() {
            note += &format!(", contradicted through {}", self.contradicted_by.join(", "));
        }
        match self.withdrawals {
            0 => {}
            1 => note += ", 1 alignment withdrawn",
            n => note += &format!(", {n} alignments withdrawn"),
        }
        note
    }
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct MessageRow {
    pub count: u64,
    pub bytes_total: u64,
    pub bytes_mean: f64,
    pub bytes_max: u64,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Report {
    pub scenario: String,
    pub seed: u64,
    pub sim_s: f64,
    pub team_ate_rmse_m: Option<f64>,
    /// Robots merged into the team ATE (the reference first).
    pub team_ate_robots: Vec<String>,
    /// Team ATE of every robot: those the reference has not aligned are placed by the only
    /// guess a team without association has, their start frame on the reference's (Table 3's
    /// convention, so that methods that align fewer robots are not flattered), m.
    pub team_ate_all_start_guess_m: Option<f64>,
    /// Team ATE of every robot with each map joined to the reference by the true transform
    /// (each map placed on the truth by its best fit): what a central optimiser holding every
    /// raw scan with a perfect association reaches without re-optimising the maps, m.
    pub team_ate_oracle_join_m: Option<f64>,
    /// Team ATE of every robot the reference has aligned, each robot's keyframes where one
    /// graph of the team puts them: every robot's own odometry, loop and inter-robot factors
    /// solved together ([`super::team_graph`]). What a back end whose robots shared their
    /// factors would reach with the same measurements: a reference, not what the robots hold, m.
    pub team_ate_team_graph_m: Option<f64>,
    pub robots: Vec<RobotReport>,
    pub alignments: Vec<AlignmentReport>,
    /// Sent by the whole team, per message type (paper Table 4).
    pub messages: BTreeMap<String, MessageRow>,
    /// Sending every LiDAR frame as a raw PointCloud2 instead (16 bytes per point).
    pub point_cloud_raw: MessageRow,
    /// Total SGM bytes ÷ raw point-cloud bytes.
    pub bytes_ratio_to_raw: f64,
    pub radio: RadioStats,
    pub world_objects: usize,
    pub series: Vec<SeriesPoint>,
    /// What every robot holds of every other, and what survived each crash.
    pub ledger: super::ledger::Ledger,
    /// Outliers the back end rejected, and the false factors among them.
    pub back_end: super::back_end::BackEndReport,
}

fn row(stats: &sgm_model::wire::TrafficStats) -> MessageRow {
    MessageRow {
        count: stats.count,
        bytes_total: stats.bytes_total,
        bytes_mean: stats.bytes_mean(),
        bytes_max: stats.bytes_max,
    }
}

/// Keyframe positions of a robot's map (its world) and the true positions at their stamps.
pub(crate) fn trajectory(observation: &Observation, k: usize, truth: &RobotTruth) -> Vec<(f64, Pose3, Pose3)> {
    let Some(Some((map, _, _))) = observation.maps.get(k) else { return Vec::new() };
    map.keyframes.iter().filter_map(|kf| Some((kf.stamp, kf.world_from_body, truth.truth.pose_at(kf.stamp)?))).collect()
}

/// Where each robot's map sits on the truth at one observation: the SE(3) fit of its keyframes
/// to their true positions (`None` before 3 keyframes).
fn maps_on_truth(observation: &Observation, robots: &[RobotTruth]) -> Vec<Option<Pose3>> {
    (0..robots.len())
        .map(|k| {
            let samples = trajectory(observation, k, &robots[k]);
            let (e, t) = positions(&samples, &Pose3::identity());
            ate(&e, &t).map(|a| a.truth_from_estimate)
        })
        .collect()
}

/// The true local_from_remote between two drifting maps: each map placed on the truth by its
/// best fit, so that what is measured is how well the maps were joined, not how far each
/// drifted from its start (that is `start_frame_translation_error_m`). Falls back to the start
/// frames before a map has 3 keyframes. None without truth (a replayed bag without it).
fn true_local_from_remote(fits: &[Option<Pose3>], robots: &[RobotTruth], l: usize, r: usize) -> Option<Pose3> {
    let (local, remote) = (&robots[l], &robots[r]);
    if !(local.truth.is_known() && remote.truth.is_known()) {
        return None;
    }
    Some(match (fits[l], fits[r]) {
        (Some(a), Some(b)) => a.inverse() * b,
        _ => local.truth_from_world.inverse() * remote.truth_from_world,
    })
}

/// The reference robot's estimate of robot k's world: reference_world_from_k_world.
pub(crate) fn reference_from(observation: &Observation, k: usize) -> Option<Pose3> {
    if k == 0 {
        return Some(Pose3::identity());
    }
    let Some(Some((_, neighbours, _))) = observation.maps.first() else { return None };
    let id = RobotId::from_index(k);
    neighbours
        .iter()
        .find(|n| n.robot == id && n.state == Some(ProtocolStage::Aligned))
        .and_then(|n| n.local_from_remote)
}

fn positions(samples: &[(f64, Pose3, Pose3)], transform: &Pose3) -> (Vec<Point3<f64>>, Vec<Point3<f64>>) {
    samples
        .iter()
        .map(|(_, estimate, truth)| {
            (Point3::from((transform * estimate).translation.vector), Point3::from(truth.translation.vector))
        })
        .unzip()
}

/// Team ATE at one observation, and the robots it merged.
fn team_ate(observation: &Observation, robots: &[RobotTruth]) -> (Option<f64>, Vec<String>) {
    team_ate_placed(observation, robots, |k| reference_from(observation, k))
}

/// Team ATE with robot k's map placed in the reference's world by `placed(k)` (skipped when
/// `None`), and the robots it merged.
fn team_ate_placed(
    observation: &Observation,
    robots: &[RobotTruth],
    placed: impl Fn(usize) -> Option<Pose3>,
) -> (Option<f64>, Vec<String>) {
    let (mut estimate, mut truth, mut names) = (Vec::new(), Vec::new(), Vec::new());
    for (k, robot) in robots.iter().enumerate() {
        let Some(transform) = placed(k) else { continue };
        let samples = trajectory(observation, k, robot);
        if samples.is_empty() {
            continue;
        }
        let (e, t) = positions(&samples, &transform);
        estimate.extend(e);
        truth.extend(t);
        names.push(robot.name.clone());
    }
    (ate(&estimate, &truth).map(|a| a.rmse_m), names)
}

/// Team ATE of keyframe poses already in the reference's world (robots without any skipped).
fn team_ate_solved(
    observation: &Observation,
    robots: &[RobotTruth],
    solved: &[Vec<(KeyframeId, Pose3)>],
) -> Option<f64> {
    let (mut estimate, mut truth) = (Vec::new(), Vec::new());
    for (k, (robot, poses)) in robots.iter().zip(solved).enumerate() {
        let Some(Some((map, _, _))) = observation.maps.get(k) else { continue };
        let stamps: BTreeMap<KeyframeId, f64> = map.keyframes.iter().map(|f| (f.id, f.stamp)).collect();
        for (id, pose) in poses {
            let Some(t) = stamps.get(id).and_then(|s| robot.truth.pose_at(*s)) else { continue };
            estimate.push(Point3::from(pose.translation.vector));
            truth.push(Point3::from(t.translation.vector));
        }
    }
    ate(&estimate, &truth).map(|a| a.rmse_m)
}

fn pair_errors(observation: &Observation, robots: &[RobotTruth]) -> Vec<PairError> {
    let fits = maps_on_truth(observation, robots);
    let mut out = Vec::new();
    for (k, local) in robots.iter().enumerate() {
        let Some(Some((_, neighbours, _))) = observation.maps.get(k) else { continue };
        // Only what the robot has accepted: a claim still being verified carries a transform
        // too, and plotting it would read as an alignment that never was.
        for n in neighbours.iter().filter(|n| n.state == Some(ProtocolStage::Aligned)) {
            let Some(r) = n.robot.index() else { continue };
            let (Some(remote), Some(estimate)) = (robots.get(r), n.local_from_remote) else { continue };
            let Some(truth) = true_local_from_remote(&fits, robots, k, r) else { continue };
            let e = pose_error(&estimate, &truth);
            out.push(PairError {
                local: local.name.clone(),
                remote: remote.name.clone(),
                translation_error_m: e.translation_m,
                rotation_error_deg: e.max_axis_rotation_deg(),
            });
        }
    }
    out
}

fn bytes_sent(observation: &Observation) -> TrafficAccount {
    let mut total = TrafficAccount::default();
    for (_, _, comms) in observation.maps.iter().flatten() {
        total.merge(&comms.sent);
    }
    total
}

/// (found, spurious, mean error of the found) of a map's confirmed objects against the world.
fn object_quality(
    map: &sgm_actors::tracker::MapSummary,
    truth: &RobotTruth,
    world: &[(u16, Point3<f64>)],
) -> (usize, usize, Option<f64>) {
    let mut claimed = vec![false; world.len()];
    let (mut found, mut spurious, mut error_sum) = (0, 0, 0.0);
    for o in map.objects.iter().filter(|o| o.confirmed) {
        let p = truth.truth_from_world * o.centroid;
        let nearest = world
            .iter()
            .enumerate()
            .filter(|(_, (label, _))| *label == o.label.0)
            .map(|(w, (_, c))| (w, (c.xy() - p.xy()).norm()))
            .min_by(|a, b| a.1.total_cmp(&b.1));
        match nearest {
            Some((w, d)) if d <= 2.0 && !claimed[w] => {
                claimed[w] = true;
                found += 1;
                error_sum += d;
            }
            _ => spurious += 1,
        }
    }
    (found, spurious, (found > 0).then(|| error_sum / found as f64))
}

/// The series' point of one observation: what the team had made by then. Computed as the run
/// goes, so that a long run keeps one point per observation, not every observation's map.
pub fn series_point(observation: &Observation, robots: &[RobotTruth]) -> SeriesPoint {
    SeriesPoint {
        t: observation.t,
        team_ate_rmse_m: team_ate(observation, robots).0,
        bytes_total: bytes_sent(observation).bytes_total(),
        cloud_bytes: observation.maps.iter().flatten().map(|(map, _, _)| map.clouds.bytes as u64).sum(),
        alignments: pair_errors(observation, robots),
    }
}

pub fn compute(record: &RunRecord) -> Report {
    let last = &record.last;
    let robots = record
        .robots
        .iter()
        .enumerate()
        .map(|(k, truth)| {
            let samples = trajectory(last, k, truth);
            let (e, t) = positions(&samples, &Pose3::identity());
            let map = match last.maps.get(k) {
                Some(Some((map, _, _))) => Some(map),
                _ => None,
            };
            let (keyframes, objects, confirmed) = map.map_or((0, 0, 0), |m| {
                (m.keyframes.len(), m.objects.len(), m.objects.iter().filter(|o| o.confirmed).count())
            });
            // Along the true path; along the estimated keyframes when there is no truth.
            let length = |path: &[Point3<f64>]| path.windows(2).map(|w| (w[1] - w[0]).norm()).fold(0.0, |a, b| a + b);
            let distance_m = match map {
                Some(m) if t.is_empty() => length(
                    &m.keyframes.iter().map(|f| Point3::from(f.world_from_body.translation.vector)).collect::<Vec<_>>(),
                ),
                _ => length(&t),
            };
            let known_world = !record.world_objects.is_empty();
            let (found, spurious, error) =
                map.map_or((0, 0, None), |m| object_quality(m, truth, &record.world_objects));
            RobotReport {
                name: truth.name.clone(),
                ate_rmse_m: ate(&e, &t).map(|a| a.rmse_m),
                keyframes,
                objects,
                confirmed_objects: confirmed,
                objects_found: known_world.then_some(found),
                objects_spurious: known_world.then_some(spurious),
                object_error_m: error,
                distance_m,
                frames: truth.frames,
                clouds: map.map(|m| m.clouds).unwrap_or_default(),
                moving_objects: map.map_or(0, |m| m.moving_objects),
                merged_objects: map.map_or(0, |m| m.merged_objects),
                expired_objects: map.map_or(0, |m| m.expired_objects),
                glimpse_sightings: map.map_or(0, |m| m.glimpse_sightings),
                deskew: record.deskew.get(k).copied().flatten().unwrap_or_default(),
                odometry: record.odometry.get(k).copied().flatten(),
            }
        })
        .collect();
    let fits = maps_on_truth(last, &record.robots);
    let mut alignments = Vec::new();
    for (k, local) in record.robots.iter().enumerate() {
        let Some(Some((_, neighbours, _))) = last.maps.get(k) else { continue };
        let graph = record.optimisers.get(k).and_then(|s| s.as_ref());
        for n in neighbours {
            let held = graph.and_then(|g| g.graph.inter_robot.iter().find(|c| c.robot == n.robot));
            let Some(r) = n.robot.index() else { continue };
            let Some(remote) = record.robots.get(r) else { continue };
            let truth = true_local_from_remote(&fits, &record.robots, k, r);
            let known = truth.and(n.local_from_remote);
            let truth = truth.unwrap_or_else(Pose3::identity);
            let error = known.map(|estimate| pose_error(&estimate, &truth));
            let start_truth = local.truth_from_world.inverse() * remote.truth_from_world;
            let start_error = known.map(|estimate| pose_error(&estimate, &start_truth).translation_m);
            let xyz = known.map(|estimate| {
                let d = estimate.translation.vector - truth.translation.vector;
                [d.x, d.y, d.z]
            });
            alignments.push(AlignmentReport {
                local: local.name.clone(),
                remote: remote.name.clone(),
                state: n.state.map_or("?".into(), |s| s.to_string()),
                first_aligned_s: n.first_aligned,
                aligned_via: n.aligned_via.and_then(|v| Some(record.robots.get(v.index()?)?.name.clone())),
                translation_error_m: error.map(|e| e.translation_m),
                translation_error_xyz_m: xyz,
                start_frame_translation_error_m: start_error,
                rotation_error_deg: error.map(|e| e.max_axis_rotation_deg()),
                closures: n.closures,
                inter_robot_factors: held.map_or(0, |h| h.factors),
                inconsistent_factors: held.map_or(0, |h| h.inconsistent),
                realigned: held.map_or(0, |h| h.realigned),
                priors_refreshed: held.map_or(0, |h| h.refreshed),
                contradicted_by: n
                    .contradicted_by
                    .iter()
                    .filter_map(|v| Some(record.robots.get(v.index()?)?.name.clone()))
                    .collect(),
                withdrawals: n.withdrawals,
                last_withdrawal: n.last_withdrawal.clone(),
                suspect: suspicions(&n.suspect_evidence(held)),
                match_attempts: n.match_attempts.clone(),
            });
        }
    }
    let sent = bytes_sent(last);
    let messages: BTreeMap<String, MessageRow> =
        MessageKind::ALL.iter().map(|kind| (format!("{kind:?}"), row(&sent.get(*kind)))).collect();
    let raw_total: u64 = record.robots.iter().map(|r| r.raw_bytes).sum();
    let frames: u64 = record.robots.iter().map(|r| r.frames).sum();
    let point_cloud_raw = MessageRow {
        count: frames,
        bytes_total: raw_total,
        bytes_mean: if frames == 0 { 0.0 } else { raw_total as f64 / frames as f64 },
        bytes_max: record.robots.iter().map(|r| r.raw_max_bytes).max().unwrap_or(0),
    };
    let (team_ate_rmse_m, team_ate_robots) = team_ate(last, &record.robots);
    let start_guess = |k| Some(reference_from(last, k).unwrap_or_else(Pose3::identity));
    let team_ate_all_start_guess_m = team_ate_placed(last, &record.robots, start_guess).0;
    let oracle = |k| true_local_from_remote(&fits, &record.robots, 0, k);
    let team_ate_oracle_join_m = team_ate_placed(last, &record.robots, oracle).0;
    let team_ate_team_graph_m = super::team_graph::solve(&record.pose_graphs, |k| reference_from(last, k))
        .and_then(|solved| team_ate_solved(last, &record.robots, &solved));
    let series = record.series.clone();
    Report {
        scenario: record.scenario.clone(),
        seed: record.seed,
        sim_s: record.sim_s,
        team_ate_rmse_m,
        team_ate_robots,
        team_ate_all_start_guess_m,
        team_ate_oracle_join_m,
        team_ate_team_graph_m,
        robots,
        alignments,
        messages,
        point_cloud_raw,
        bytes_ratio_to_raw: if raw_total == 0 { 0.0 } else { sent.bytes_total() as f64 / raw_total as f64 },
        radio: record.radio.clone(),
        world_objects: record.world_objects.len(),
        series,
        ledger: super::ledger::compute(record, last),
        back_end: super::back_end::compute(record),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::record::TruthTrack;
    use nalgebra::Vector3;
    use sgm_actors::comms::CommsStatus;
    use sgm_actors::matcher::NeighbourStatus;
    use sgm_actors::tracker::MapSummary;
    use sgm_model::geometry::pose_from_yaw_translation;

    fn neighbour(index: usize, state: ProtocolStage, local_from_remote: Pose3) -> NeighbourStatus {
        NeighbourStatus {
            robot: RobotId::from_index(index),
            state: Some(state),
            local_from_remote: Some(local_from_remote),
            first_aligned: None,
            closures: Default::default(),
            aligned_via: None,
            keyframes_held: 0,
            objects_revision: None,
            contradicted_by: Vec::new(),
            withdrawals: 0,
            last_withdrawal: None,
            match_attempts: Default::default(),
            graph_rounds_refuted: 0,
        }
    }

    fn robot(name: &str, truth_from_world: Pose3) -> RobotTruth {
        RobotTruth {
            name: name.into(),
            truth: TruthTrack::Samples(vec![(0.0, truth_from_world)]),
            truth_from_world,
            frames: 1,
            raw_bytes: 0,
            raw_max_bytes: 0,
        }
    }

    /// A claim still being verified carries a transform, 40 m off here; the series must not
    /// plot it as an alignment. The accepted direction is there, and exact.
    #[test]
    fn the_series_holds_only_accepted_alignments() {
        let alpha_world = Pose3::identity();
        let bravo_world = pose_from_yaw_translation(0.5, Vector3::new(10.0, -4.0, 0.0));
        let robots = [robot("alpha", alpha_world), robot("bravo", bravo_world)];
        let truth = alpha_world.inverse() * bravo_world;
        let claim = pose_from_yaw_translation(0.1, Vector3::new(40.0, 0.0, 0.0));
        let observation = Observation {
            t: 30.0,
            maps: vec![
                Some((
                    MapSummary::default(),
                    vec![neighbour(1, ProtocolStage::KeyframesRequested, claim)],
                    CommsStatus::default(),
                )),
                Some((
                    MapSummary::default(),
                    vec![neighbour(0, ProtocolStage::Aligned, truth.inverse())],
                    CommsStatus::default(),
                )),
            ],
        };
        let point = series_point(&observation, &robots);
        assert_eq!(point.alignments.len(), 1, "{:?}", point.alignments);
        let pair = &point.alignments[0];
        assert_eq!((pair.local.as_str(), pair.remote.as_str()), ("bravo", "alpha"));
        assert!(pair.translation_error_m < 1e-9 && pair.rotation_error_deg < 1e-9, "{pair:?}");
    }
}
