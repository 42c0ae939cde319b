//! Alignments relayed by neighbours (beyond the paper, which aligns each pair on its own). A
//! robot s that placed robot j's world in its own tells the team T_{s←j} (the `Alignments`
//! message). Robot r turns that into hints for its own transform to a neighbour it has not
//! placed yet:
//!
//! ```text
//! direct   (j = r):  T_{r←s} = T_{s←r}⁻¹
//! relayed  (j ≠ r):  T_{r←j} = T_{r←s} · T_{s←j}     T_{r←s}: our own alignment with s,
//!                                                    else s's T_{s←r}⁻¹ (a direct hint)
//! ```
//!
//! A hint is never taken as it comes: it only replaces graph matching as the first estimate. The
//! objects are associated through it ([`hinted_round`]: mutual nearest of similar label within
//! a gate, the best-supported 15 m patch, as a closure round plans; for a relayed hint, else all
//! of them, see [`Reach`]) and the rest of the round is the receiver's own: object-cloud ICP,
//! keyframe registration, the structure check and the round's verdict (`alignment::judge_round`).
//! A wrong hint is refuted like a wrong match. When fewer objects pair through a chained hint
//! than a graph match needs, the receiver may still start a round from its best patch (the
//! Matcher's `matcher.relay.min_relayed_pairs`): the pairs then only pick the keyframes to
//! register, object-cloud ICP is skipped below three, and the registrations decide.
//!
//! What this buys: two robots whose common objects are too few, or too alike, for graph
//! matching to be significant still align when either of them — or a third robot that placed
//! both — did; one good encounter spreads through the team.

use super::closure::{next_round, pairs_through, ClosurePair, ClosurePlan};
use super::{GraphObject, LabelSimilarity};
use crate::geometry::{pose_error, Pose3};
use crate::scene_graph::RobotId;
use nalgebra::Point3;
use std::collections::BTreeMap;

/// A first estimate of `local_from_remote` that a neighbour's alignment implies.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hint {
    /// The robot whose alignment it came from.
    pub via: RobotId,
    pub local_from_remote: Pose3,
}

/// Every hint for our transform to `remote`, direct ones first, then relayed ones in the
/// relaying robot's id order. `ours`: our own alignments (remote world in ours); `theirs`: each
/// neighbour's latest alignments (another robot's world in the neighbour's).
pub fn hints_for(
    me: RobotId,
    remote: RobotId,
    ours: &BTreeMap<RobotId, Pose3>,
    theirs: &BTreeMap<RobotId, Vec<(RobotId, Pose3)>>,
) -> Vec<Hint> {
    if remote == me {
        return Vec::new();
    }
    let placed_by = |s: RobotId, j: RobotId| placed_by(theirs, s, j);
    let mut hints: Vec<Hint> = placed_by(remote, me)
        .map(|remote_from_me| Hint { via: remote, local_from_remote: remote_from_me.inverse() })
        .into_iter()
        .collect();
    for &sender in theirs.keys().filter(|s| **s != remote && **s != me) {
        let Some(sender_from_remote) = placed_by(sender, remote) else { continue };
        let me_from_sender = ours.get(&sender).copied().or_else(|| placed_by(sender, me).map(|t| t.inverse()));
        if let Some(me_from_sender) = me_from_sender {
            hints.push(Hint { via: sender, local_from_remote: me_from_sender * sender_from_remote });
        }
    }
    hints
}

/// `placer`'s latest alignment of `placed` (its world in the placer's), from `theirs`.
pub fn placed_by(theirs: &BTreeMap<RobotId, Vec<(RobotId, Pose3)>>, placer: RobotId, placed: RobotId) -> Option<Pose3> {
    theirs.get(&placer)?.iter().find(|(r, _)| *r == placed).map(|(_, t)| *t)
}

/// The robots whose alignments contradict ours of `remote` (`own`: its world in ours): every
/// hint for it ([`hints_for`]) that lands farther than `tolerance_m` (the remote origin's
/// displacement) or `tolerance_deg` (the angle of the rotation between them) from `own`
/// (NaN counts as farther), through whom it came,
/// in the order of the hints. Around a cycle of alignments each transform should be the product
/// of the others; a wrong one (symmetric rooms that a half turn maps onto themselves) breaks
/// every cycle it is on:
///
/// ```text
/// contradicted by s  ⇔  ‖T_{r←j} ⊖ T_{r←s} · T_{s←j}‖ > tolerance    (or T_{j←r}⁻¹ when s = j)
/// ```
///
/// A cycle does not say which of its alignments is wrong: on a cycle of three, each robot sees
/// each of its two alignments contradicted through the other. It flags; the rounds decide.
pub fn contradicting(
    me: RobotId,
    remote: RobotId,
    own: &Pose3,
    ours: &BTreeMap<RobotId, Pose3>,
    theirs: &BTreeMap<RobotId, Vec<(RobotId, Pose3)>>,
    tolerance_m: f64,
    tolerance_deg: f64,
) -> Vec<RobotId> {
    hints_for(me, remote, ours, theirs)
        .into_iter()
        .filter(|hint| !agree(&hint.local_from_remote, own, tolerance_m, tolerance_deg))
        .map(|hint| hint.via)
        .collect()
}

/// Whether two estimates of one transform agree: the remote origin within `tolerance_m` and
/// the whole rotation between them (a turn about a diagonal axis counts in full) within
/// `tolerance_deg` (NaN never agrees).
pub fn agree(a: &Pose3, b: &Pose3, tolerance_m: f64, tolerance_deg: f64) -> bool {
    let e = pose_error(a, b);
    let turn_deg = a.rotation.angle_to(&b.rotation).to_degrees();
    e.translation_m <= tolerance_m && turn_deg <= tolerance_deg
}

/// Whether a graph match's `challenger` agrees with our alignment `current` where the match
/// stands: each of `matched` (the remote centroids it paired) is placed by the two within
/// `tolerance_m` of each other, and the whole rotation between them is within `tolerance_deg`.
///
/// ```text
/// agree ⇔ max_q ‖current·q − challenger·q‖ ≤ tolerance_m  ∧  ∠(R_current, R_challenger) ≤ tolerance_deg
/// ```
///
/// Not [`agree`]'s remote origin: a graph match refitted in 6-DoF (`matching.max_tilt_deg`)
/// may carry a tilt of a few degrees, within the angle's tolerance, which moves an origin 45 m
/// from the objects by 2 m while it places every matched object where ours does (on
/// `team_of_eight` two right alignments were withdrawn so, 2.6–2.8° and 2 m at the origin,
/// within 0.5 m at every matched object). With no matched centroid nothing is placed
/// elsewhere: it agrees.
pub fn agree_where_matched(
    current: &Pose3,
    challenger: &Pose3,
    matched: impl IntoIterator<Item = Point3<f64>>,
    tolerance_m: f64,
    tolerance_deg: f64,
) -> bool {
    let turn_deg = current.rotation.angle_to(&challenger.rotation).to_degrees();
    // `<=` is false for NaN: a NaN placement never agrees.
    turn_deg <= tolerance_deg && matched.into_iter().all(|q| ((current * q) - (challenger * q)).norm() <= tolerance_m)
}

/// Whether `transform` agrees with any of `barred` (our alignments of the same robot withdrawn
/// for good: a contradicted cycle settled against them, a stronger match elsewhere, the relay
/// they came from gone) within the contradiction tolerance:
/// the alignment that contradicted a withdrawn one, by definition beyond it, is never barred.
pub fn barred(barred: &[Pose3], transform: &Pose3, tolerance_m: f64, tolerance_deg: f64) -> bool {
    barred.iter().any(|t| agree(t, transform, tolerance_m, tolerance_deg))
}

/// Where a hint's first round may take its pairs from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Reach {
    /// One patch (`radius_m` around a seed): for a round that a single registration of ours
    /// settles (a direct hint), which can only check the ground it covers; also for a chained
    /// hint's round from fewer pairs than a graph match needs, whose pairs only say where its
    /// registrations look.
    Patch,
    /// One patch, else the whole map: for a round settled by as many registrations as a graph
    /// match (a relayed hint). A hint places the whole map, as a graph match does, so pairs far
    /// apart support it together: two robots that crossed each other's paths at an angle share
    /// objects along a line longer than a patch.
    WholeMap,
}

/// The object pairs a hint gives for a first round: those within `gate_m` of each other through
/// it, the best-supported patch of them (`radius_m` around its seed), when it has `min_pairs`;
/// with [`Reach::WholeMap`], else all of them, when they are `min_pairs` spread wider than a patch.
pub fn hinted_round(
    local: &[GraphObject],
    remote: &[GraphObject],
    hint: &Hint,
    labels: &LabelSimilarity,
    plan: &ClosurePlan,
    reach: Reach,
) -> Option<Vec<ClosurePair>> {
    let pairs = pairs_through(local, remote, &hint.local_from_remote, labels, plan.gate_m);
    match next_round(&pairs, &[], plan) {
        Some((_, round)) => Some(round),
        None if reach == Reach::WholeMap && pairs.len() >= plan.min_pairs => Some(pairs),
        None => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::pose_from_yaw_translation;
    use crate::scene_graph::{LabelId, ObjectId};
    use nalgebra::{Point3, Vector3};

    fn pose(yaw: f64, x: f64, y: f64) -> Pose3 {
        pose_from_yaw_translation(yaw, Vector3::new(x, y, 0.0))
    }

    fn close(a: &Pose3, b: &Pose3) -> bool {
        (a.translation.vector - b.translation.vector).norm() < 1e-9 && a.rotation.angle_to(&b.rotation) < 1e-9
    }

    /// Robots 1, 2 and 3 with worlds placed in a common frame W, and their true transforms
    /// t(a, b) = W_a⁻¹ · W_b.
    fn three_worlds() -> ([RobotId; 3], impl Fn(RobotId, RobotId) -> Pose3) {
        let robots = [RobotId(1), RobotId(2), RobotId(3)];
        let world: BTreeMap<RobotId, Pose3> =
            robots.into_iter().zip([pose(0.3, 4.0, -2.0), pose(-1.1, 20.0, 7.0), pose(2.0, -9.0, 1.0)]).collect();
        (robots, move |a: RobotId, b: RobotId| world[&a].inverse() * world[&b])
    }

    /// Three robots, one wrong alignment (robot 2's world turned by a half turn and shifted, as
    /// symmetric rooms allow): each cycle through it is broken, the others are not.
    #[test]
    fn a_wrong_alignment_is_contradicted_around_its_cycle() {
        let ([me, two, three], t) = three_worlds();
        let wrong = pose(std::f64::consts::PI, 28.0, 16.0) * t(me, two);
        // Robot 3 placed us and robot 2 right; robot 2 took our wrong alignment, inverted, and
        // placed robot 3 right.
        let theirs: BTreeMap<RobotId, Vec<(RobotId, Pose3)>> = [
            (three, vec![(me, t(three, me)), (two, t(three, two))]),
            (two, vec![(me, wrong.inverse()), (three, t(two, three))]),
        ]
        .into();
        let ours: BTreeMap<RobotId, Pose3> = [(two, wrong), (three, t(me, three))].into();
        let check = |remote: RobotId| contradicting(me, remote, &ours[&remote], &ours, &theirs, 2.0, 5.0);
        // Our alignment of robot 2: robot 2 agrees (it took ours), robot 3's path does not.
        assert_eq!(check(two), vec![three]);
        // Our right alignment of robot 3: robot 3 agrees; the path through our wrong one does not.
        // The cycle cannot say which is wrong.
        assert_eq!(check(three), vec![two]);
        // All right: no contradiction, even with a drift of 1 m and 1° along a chain.
        let drift = pose(1f64.to_radians(), 0.7, -0.7);
        let right: BTreeMap<RobotId, Pose3> = [(two, t(me, two)), (three, t(me, three))].into();
        let theirs: BTreeMap<RobotId, Vec<(RobotId, Pose3)>> =
            [(three, vec![(me, t(three, me)), (two, drift * t(three, two))]), (two, vec![(me, t(two, me))])].into();
        for remote in [two, three] {
            assert!(contradicting(me, remote, &right[&remote], &right, &theirs, 2.0, 5.0).is_empty());
        }
        // Past the tolerance, the drifted chain counts.
        assert_eq!(contradicting(me, two, &right[&two], &right, &theirs, 0.5, 5.0), vec![three]);
        // A turn about the remote origin, 4° about x and y each (5.7° in all): only the rotation
        // gate sees it, and in full.
        let tilt = nalgebra::UnitQuaternion::from_euler_angles(4f64.to_radians(), 4f64.to_radians(), 0.0);
        let turned = Pose3::from_parts(right[&two].translation, right[&two].rotation * tilt);
        assert_eq!(contradicting(me, two, &turned, &right, &theirs, 2.0, 5.0), vec![two, three]);
        assert!(contradicting(me, two, &turned, &right, &theirs, 2.0, 6.0).is_empty());
        // Robot 2's own alignment of us disagreeing names robot 2 itself (a cycle of two).
        let theirs: BTreeMap<RobotId, Vec<(RobotId, Pose3)>> =
            [(two, vec![(me, pose(0.5, 9.0, 0.0) * t(two, me))])].into();
        assert_eq!(contradicting(me, two, &right[&two], &right, &theirs, 2.0, 5.0), vec![two]);
        // A NaN alignment is never taken for agreement.
        let nan = Pose3::from_parts(nalgebra::Translation3::new(f64::NAN, 0.0, 0.0), right[&two].rotation);
        assert_eq!(contradicting(me, two, &nan, &right, &theirs, 2.0, 5.0), vec![two]);
    }

    /// A withdrawn alignment bars what agrees with it as a contradiction measures agreement —
    /// the whole rotation, so a tilt of 6° about a diagonal (4.2° about each axis, under 5°) is
    /// not barred — and never the alignment that contradicted it.
    #[test]
    fn a_withdrawn_alignment_bars_only_what_agrees_with_it() {
        let withdrawn = pose(-1.5, 2.0, 9.6);
        let near = withdrawn * pose(0.05, 0.5, 1.0);
        assert!(barred(&[withdrawn], &near, 2.0, 5.0));
        assert!(!barred(&[withdrawn], &(withdrawn * pose(0.0, 2.5, 0.0)), 2.0, 5.0), "2.5 m away");
        let diagonal =
            nalgebra::UnitQuaternion::from_scaled_axis(Vector3::new(1.0, 1.0, 0.0).normalize() * 6f64.to_radians());
        let tilted = withdrawn * Pose3::from_parts(nalgebra::Translation3::identity(), diagonal);
        assert!(!barred(&[withdrawn], &tilted, 2.0, 5.0), "6° about a diagonal");
        assert!(!barred(&[], &withdrawn, 2.0, 5.0));
        // Whatever contradicts it is beyond it.
        let (ours, theirs) = (BTreeMap::new(), [(RobotId(2), vec![(RobotId(1), tilted.inverse())])].into());
        assert_eq!(contradicting(RobotId(1), RobotId(2), &withdrawn, &ours, &theirs, 2.0, 5.0), vec![RobotId(2)]);
        assert!(barred(&[withdrawn], &tilted, 2.0, 7.0), "within a wider tolerance");
    }

    /// Three worlds placed in a common frame W: each transform is W_a⁻¹ · W_b, so any chain of
    /// hints must give it back exactly.
    #[test]
    fn direct_and_relayed_hints_compose_to_the_true_transform() {
        let ([me, two, three], t) = three_worlds();
        // Robot 2 placed us and robot 3; robot 3 placed robot 2.
        let theirs: BTreeMap<RobotId, Vec<(RobotId, Pose3)>> =
            [(two, vec![(me, t(two, me)), (three, t(two, three))]), (three, vec![(two, t(three, two))])].into();
        let to_two = hints_for(me, two, &BTreeMap::new(), &theirs);
        assert_eq!(to_two.len(), 1, "robot 3 has not placed us: nothing to chain through it");
        assert_eq!(to_two[0].via, two);
        assert!(close(&to_two[0].local_from_remote, &t(me, two)));
        // To robot 3: through robot 2's placement of us (inverted), then of robot 3.
        let to_three = hints_for(me, three, &BTreeMap::new(), &theirs);
        assert_eq!(to_three.len(), 1);
        assert_eq!(to_three[0].via, two);
        assert!(close(&to_three[0].local_from_remote, &t(me, three)));
        // Our own alignment with robot 2 is used before its placement of us.
        let ours: BTreeMap<RobotId, Pose3> = [(two, pose(0.0, 1.0, 0.0) * t(me, two))].into();
        let through_ours = hints_for(me, three, &ours, &theirs);
        assert!(close(&through_ours[0].local_from_remote, &(ours[&two] * t(two, three))));
        // Nobody placed robot 4, and a robot's own claims about itself are not hints.
        assert!(hints_for(me, RobotId(4), &ours, &theirs).is_empty());
        assert!(hints_for(two, two, &ours, &theirs).is_empty());
    }

    #[test]
    fn a_hint_gives_a_round_only_where_enough_objects_agree_through_it() {
        let labels = LabelSimilarity::hard(3);
        let object = |id: u32, label: u16, x: f64, y: f64| GraphObject {
            id: ObjectId(id),
            label: LabelId(label),
            centroid: Point3::new(x, y, 0.5),
            size: None,
        };
        let local_from_remote = pose(0.5, 3.0, -4.0);
        let local: Vec<GraphObject> =
            (0..6).map(|k| object(k, (k % 3) as u16, 2.0 * k as f64, (k * k) as f64 % 7.0)).collect();
        let remote: Vec<GraphObject> = local
            .iter()
            .map(|o| GraphObject {
                id: ObjectId(o.id.0 + 100),
                centroid: local_from_remote.inverse() * o.centroid,
                ..o.clone()
            })
            .collect();
        let plan = ClosurePlan { gate_m: 1.0, radius_m: 15.0, spacing_m: 0.0, min_pairs: 4 };
        let right = Hint { via: RobotId(2), local_from_remote };
        let round = hinted_round(&local, &remote, &right, &labels, &plan, Reach::Patch).unwrap();
        assert_eq!(round.len(), 6);
        assert!(round.iter().all(|p| p.remote.0 == p.local.0 + 100));
        let wrong = Hint { via: RobotId(2), local_from_remote: pose(0.5, 13.0, -4.0) };
        assert!(hinted_round(&local, &remote, &wrong, &labels, &plan, Reach::WholeMap).is_none());
        let few = ClosurePlan { min_pairs: 7, ..plan };
        assert!(hinted_round(&local, &remote, &right, &labels, &few, Reach::WholeMap).is_none());
        // No patch of 1 m holds 4 of them, but the whole map holds 6: all of them, in local
        // order, for a relayed hint; nothing for a direct one.
        let narrow = ClosurePlan { radius_m: 1.0, ..plan };
        assert!(next_round(&pairs_through(&local, &remote, &local_from_remote, &labels, 1.0), &[], &narrow).is_none());
        assert!(hinted_round(&local, &remote, &right, &labels, &narrow, Reach::Patch).is_none());
        let spread = hinted_round(&local, &remote, &right, &labels, &narrow, Reach::WholeMap).unwrap();
        assert_eq!(spread.iter().map(|p| p.local.0).collect::<Vec<_>>(), (0..6).collect::<Vec<_>>());
        let seven = ClosurePlan { min_pairs: 7, ..narrow };
        assert!(hinted_round(&local, &remote, &right, &labels, &seven, Reach::WholeMap).is_none());
    }

    #[test]
    fn a_challenger_is_judged_where_its_objects_are() {
        // Our alignment, and the remote's matched objects 180 m from its origin (a lawnmower's
        // far end), around (180, 0, 1).
        let current = pose(std::f64::consts::PI, 136.0, 136.0);
        let objects: Vec<Point3<f64>> =
            (0..8).map(|k| Point3::new(180.0 + (k % 4) as f64 * 6.0, (k / 4) as f64 * 8.0 - 4.0, 1.0)).collect();
        let (m, deg) = (2.0, 5.0);
        // A 1° tilt about a horizontal axis through the objects' middle: every object stays
        // within 0.2 m, while the remote origin moves by 3 m, a contradiction at the origin.
        let pivot = Point3::new(189.0, 0.0, 1.0);
        let tilt = nalgebra::UnitQuaternion::from_axis_angle(&Vector3::y_axis(), 1f64.to_radians());
        let about_pivot = Pose3::from_parts(nalgebra::Translation3::from(pivot.coords - tilt * pivot.coords), tilt);
        let tilted = current * about_pivot;
        assert!((tilted.translation.vector - current.translation.vector).z.abs() > 3.0);
        assert!(!agree(&current, &tilted, m, deg));
        assert!(agree_where_matched(&current, &tilted, objects.iter().copied(), m, deg));
        // The same tilt about the remote origin lifts the far objects by 3 m (a floor up):
        // elsewhere.
        let lifted = current * Pose3::from_parts(nalgebra::Translation3::identity(), tilt);
        assert!(!agree_where_matched(&current, &lifted, objects.iter().copied(), m, deg));
        // A shift by a period (12 m), a half turn about the objects, or a turn beyond the
        // tolerance put it elsewhere.
        let shifted = Pose3::translation(12.0, 0.0, 0.0) * current;
        assert!(!agree_where_matched(&current, &shifted, objects.iter().copied(), m, deg));
        let half = nalgebra::UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::PI);
        let turned =
            current * Pose3::from_parts(nalgebra::Translation3::from(pivot.coords - half * pivot.coords), half);
        assert!(!agree_where_matched(&current, &turned, objects.iter().copied(), m, deg));
        let yawed = current * pose(6f64.to_radians(), 0.0, 0.0);
        assert!(!agree_where_matched(&current, &yawed, std::iter::empty(), m, deg));
        // Just within the tolerance at the farthest object, and just beyond it.
        let nudged = |dx: f64| Pose3::translation(dx, 0.0, 0.0) * current;
        assert!(agree_where_matched(&current, &nudged(1.99), objects.iter().copied(), m, deg));
        assert!(!agree_where_matched(&current, &nudged(2.01), objects.iter().copied(), m, deg));
        // NaN never agrees; no matched object places nothing elsewhere.
        let nan = Pose3::from_parts(nalgebra::Translation3::new(f64::NAN, 0.0, 0.0), current.rotation);
        assert!(!agree_where_matched(&current, &nan, objects.iter().copied(), m, deg));
        assert!(agree_where_matched(&current, &shifted, std::iter::empty(), m, deg));
    }

    proptest::proptest! {
        /// Which of the two is ours does not matter, nor where the local world is put (a yaw
        /// and a shift keep distances and turns).
        #[test]
        fn agreement_where_matched_is_symmetric_and_frame_free(
            a in (-3.2f64..3.2, -200.0f64..200.0, -200.0f64..200.0),
            b in (-3.2f64..3.2, -200.0f64..200.0, -200.0f64..200.0),
            level in (-3.2f64..3.2, -50.0f64..50.0, -50.0f64..50.0),
            points in proptest::collection::vec((-100.0f64..100.0, -100.0f64..100.0, -3.0f64..3.0), 0..6),
            tolerance_m in 0.5f64..30.0,
        ) {
            let (current, challenger, frame) = (pose(a.0, a.1, a.2), pose(b.0, b.1, b.2), pose(level.0, level.1, level.2));
            let points: Vec<Point3<f64>> = points.into_iter().map(|(x, y, z)| Point3::new(x, y, z)).collect();
            let here = agree_where_matched(&current, &challenger, points.iter().copied(), tolerance_m, 5.0);
            let swapped = agree_where_matched(&challenger, &current, points.iter().copied(), tolerance_m, 5.0);
            let moved =
                agree_where_matched(&(frame * current), &(frame * challenger), points.iter().copied(), tolerance_m, 5.0);
            proptest::prop_assert_eq!(here, swapped);
            proptest::prop_assert_eq!(here, moved);
        }
    }
}
