//! An evaluation reference, not a part of the robots: every robot's final pose graph solved as
//! one graph of the team, which is what a back end whose robots shared their factors would give
//! from the same measurements (the book's Limitations and Evaluation chapters).
//!
//! From each robot's graph the team graph takes its own keyframes, the between factors among
//! them (odometry and the loop closures its solve kept) and the inter-robot factors it kept
//! (PCM's and GNC's rejections left out). A neighbour keyframe a robot holds is that neighbour's
//! own variable. Left out are each robot's ties of its neighbours' keyframes to their anchors
//! and the anchors' priors: they summarise what the neighbours measured, and the team graph
//! holds those measurements themselves. The reference robot's priors hold the gauge:
//!
//! ```text
//! X* = argmin Σ_{reference priors} ‖r‖² + Σ_k Σ_{robot k's kept between factors} ‖r‖²
//! ```
//!
//! Robot k's keyframes start where the reference robot's estimate of its world puts them
//! (`placed(k)`); a robot without one is left out, as the team ATE leaves it out. Both
//! robots of a pair may register the same two keyframes; each registration is a factor.
//! A robot that holds its neighbours' own chains (`optimiser.share_factors`) holds their
//! factors too: of its graph only the factors of its own measurements are taken — those from
//! its own keyframes, and of the inter-robot ones those its factor log holds (the others are a
//! neighbour's, inverted), so that no measurement counts twice.

use sgm_model::geometry::Pose3;
use sgm_model::optim::graph::Graph3;
use sgm_model::optim::keyframe_graph::KeyframeGraphState;
use sgm_model::optim::shared_factors::LogEntry;
use sgm_model::optim::solver::{optimize, LmParams};
use sgm_model::scene_graph::{KeyframeId, KeyframeRef, RobotId};
use std::collections::BTreeMap;

/// Each robot's keyframes as the team graph solves them, in the reference robot's world
/// (empty for a robot left out), or `None` when there is nothing to solve or the solve fails.
pub fn solve(
    graphs: &[Option<KeyframeGraphState>],
    placed: impl Fn(usize) -> Option<Pose3>,
) -> Option<Vec<Vec<(KeyframeId, Pose3)>>> {
    let members: Vec<Option<Pose3>> =
        graphs.iter().enumerate().map(|(k, g)| g.as_ref().and_then(|_| placed(k))).collect();
    let mut team = Graph3::default();
    let mut variable: BTreeMap<(usize, KeyframeId), usize> = BTreeMap::new();
    for (k, (graph, place)) in graphs.iter().zip(&members).enumerate() {
        let (Some(graph), Some(place)) = (graph, place) else { continue };
        for (r, v) in &graph.index {
            if let (KeyframeRef::Local(id), Some(value)) = (r, graph.graph.values.get(*v)) {
                variable.insert((k, *id), team.values.len());
                team.keys.push(((k as u64) << 40) | u64::from(id.0));
                team.values.push(place * value);
                team.fixed.push(false);
            }
        }
    }
    if team.values.is_empty() {
        return None;
    }
    // The robot whose world the team graph is solved in: the first one placed.
    let reference = members.iter().position(Option::is_some)?;
    for (k, graph) in graphs.iter().enumerate() {
        let (Some(graph), Some(_)) = (graph, members[k]) else { continue };
        // This robot's variable → the team's; anchors and unknown robots map to nothing.
        let of: BTreeMap<usize, usize> = graph
            .index
            .iter()
            .filter_map(|(r, v)| {
                let owner = match r {
                    KeyframeRef::Local(id) => (k, *id),
                    KeyframeRef::Remote { robot, keyframe } => (robot.index()?, *keyframe),
                };
                Some((*v, *variable.get(&owner)?))
            })
            .collect();
        let mut own = own_inter_robot(graph);
        let keyframe_of: BTreeMap<usize, KeyframeRef> = graph.index.iter().map(|(r, v)| (*v, *r)).collect();
        for (f, between) in graph.graph.betweens.iter().enumerate() {
            if graph.rejected.contains(&f) {
                continue;
            }
            // Its own measurements only: from its own keyframes, and to a neighbour's only as
            // often as its log holds that factor.
            match (keyframe_of.get(&between.from), keyframe_of.get(&between.to)) {
                (Some(KeyframeRef::Local(_)), Some(KeyframeRef::Local(_))) => {}
                (Some(KeyframeRef::Local(from)), Some(KeyframeRef::Remote { robot, keyframe })) => {
                    if let Some(own) = own.as_mut() {
                        match own.get_mut(&(*from, *robot, *keyframe)) {
                            Some(n) if *n > 0 => *n -= 1,
                            _ => continue,
                        }
                    }
                }
                _ => continue,
            }
            if let (Some(&from), Some(&to)) = (of.get(&between.from), of.get(&between.to)) {
                team.betweens.push(sgm_model::optim::factors::Between { from, to, ..between.clone() });
            }
        }
        if k == reference {
            for prior in &graph.graph.priors {
                if let Some(&v) = of.get(&prior.variable) {
                    team.priors.push(sgm_model::optim::factors::Prior { variable: v, ..prior.clone() });
                }
            }
        }
    }
    if let Err(e) = optimize(&mut team, &LmParams::default()) {
        tracing::warn!("team graph not solved: {e} (report team_ate_team_graph_m left empty)");
        return None;
    }
    let mut out = vec![Vec::new(); graphs.len()];
    for ((k, id), v) in variable {
        out[k].push((id, team.values[v]));
    }
    Some(out)
}

/// How many inter-robot factors of its own `graph` holds on each (own keyframe, neighbour,
/// its keyframe), from its factor log; `None` for a graph without a log (every inter-robot
/// factor it holds is then its own).
fn own_inter_robot(graph: &KeyframeGraphState) -> Option<BTreeMap<(KeyframeId, RobotId, KeyframeId), usize>> {
    if graph.log.is_empty() {
        return None;
    }
    let mut own = BTreeMap::new();
    for entry in graph.log.entries() {
        if let LogEntry::Factor(edge) = entry {
            if let KeyframeRef::Remote { robot, keyframe } = edge.to {
                *own.entry((edge.from, robot, keyframe)).or_default() += 1;
            }
        }
    }
    Some(own)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Matrix6, Vector3};
    use sgm_model::geometry::pose_from_yaw_translation;
    use sgm_model::optim::factors::{Between, Prior};
    use sgm_model::scene_graph::RobotId;

    const N: u32 = 6;

    /// Robot `k`'s graph as its Optimiser holds it: its chain of N keyframes (odometry saying
    /// 1 m along x, each with a yaw error), a prior on the first, the neighbour's keyframe 0
    /// held as a variable tied to an anchor (whose tie says it is 7 m off: a stale, wrong
    /// summary the team graph must not use), and one exact inter-robot factor to it.
    fn graph(k: usize, truth: &[Pose3], neighbour: &[Pose3], local_from_remote: Pose3) -> KeyframeGraphState {
        let mut g = KeyframeGraphState::default();
        let info = Matrix6::identity() * 100.0;
        for (i, pose) in truth.iter().enumerate() {
            g.graph.keys.push(i as u64);
            g.graph.values.push(*pose);
            g.graph.fixed.push(false);
            g.index.push((KeyframeRef::Local(KeyframeId(i as u32)), i));
        }
        for i in 1..truth.len() {
            // Odometry off by 0.02 rad of yaw a step: a chain that bends on its own.
            let measured = pose_from_yaw_translation(0.02, Vector3::new(1.0, 0.0, 0.0));
            g.graph.betweens.push(Between { from: i - 1, to: i, measured, sqrt_information: info });
        }
        g.graph.priors.push(Prior { variable: 0, mean: truth[0], sqrt_information: info * 10.0 });
        let (held, anchor) = (truth.len(), truth.len() + 1);
        let other = RobotId::from_index(1 - k);
        g.graph.values.extend([local_from_remote * neighbour[0], local_from_remote]);
        g.graph.keys.extend([1 << 40, 1 << 41]);
        g.graph.fixed.extend([false, false]);
        g.index.push((KeyframeRef::Remote { robot: other, keyframe: KeyframeId(0) }, held));
        g.anchors.push((other, anchor));
        let stale = Pose3::translation(7.0, 0.0, 0.0);
        g.graph.betweens.push(Between { from: anchor, to: held, measured: stale, sqrt_information: info });
        let last = truth.len() - 1;
        let exact = truth[last].inverse() * local_from_remote * neighbour[0];
        g.graph.betweens.push(Between { from: last, to: held, measured: exact, sqrt_information: info });
        g
    }

    fn chain(start: Pose3) -> Vec<Pose3> {
        (0..N).map(|i| start * Pose3::translation(f64::from(i), 0.0, 0.0)).collect()
    }

    /// Two robots, each with its odometry and one inter-robot factor: the team graph is their
    /// chains and both factors, not the anchors' ties, and its solve equals the same graph
    /// written by hand and solved directly.
    #[test]
    fn the_team_graph_is_every_robots_own_factors() {
        let alpha = chain(Pose3::identity());
        let bravo_world = pose_from_yaw_translation(2.0, Vector3::new(5.0, 3.0, 0.0));
        let bravo = chain(Pose3::identity());
        let graphs =
            [Some(graph(0, &alpha, &bravo, bravo_world)), Some(graph(1, &bravo, &alpha, bravo_world.inverse()))];
        let solved = solve(&graphs, |k| Some(if k == 0 { Pose3::identity() } else { bravo_world })).expect("solves");

        let mut direct = Graph3::default();
        let info = Matrix6::identity() * 100.0;
        for (k, start) in [Pose3::identity(), bravo_world].iter().enumerate() {
            for i in 0..N {
                direct.keys.push(u64::from(i) + 100 * k as u64);
                direct.values.push(start * Pose3::translation(f64::from(i), 0.0, 0.0));
                direct.fixed.push(false);
            }
            for i in 1..N as usize {
                let measured = pose_from_yaw_translation(0.02, Vector3::new(1.0, 0.0, 0.0));
                let (from, to) = (k * N as usize + i - 1, k * N as usize + i);
                direct.betweens.push(Between { from, to, measured, sqrt_information: info });
            }
        }
        let last = N as usize - 1;
        let alpha_to_bravo = alpha[last].inverse() * bravo_world * bravo[0];
        direct.betweens.push(Between { from: last, to: N as usize, measured: alpha_to_bravo, sqrt_information: info });
        let bravo_to_alpha = bravo[last].inverse() * bravo_world.inverse() * alpha[0];
        direct.betweens.push(Between {
            from: N as usize + last,
            to: 0,
            measured: bravo_to_alpha,
            sqrt_information: info,
        });
        direct.priors.push(Prior { variable: 0, mean: alpha[0], sqrt_information: info * 10.0 });
        optimize(&mut direct, &LmParams::default()).expect("solves");

        assert_eq!(solved.len(), 2);
        for (k, poses) in solved.iter().enumerate() {
            assert_eq!(poses.len(), N as usize);
            for (i, (id, pose)) in poses.iter().enumerate() {
                assert_eq!(id.0 as usize, i);
                let expected = direct.values[k * N as usize + i];
                assert!((pose.translation.vector - expected.translation.vector).norm() < 1e-9, "{k} {i}");
                assert!(pose.rotation.angle_to(&expected.rotation) < 1e-9, "{k} {i}");
            }
        }
        // The chains bent (the odometry's yaw error met two exact inter-robot factors), and
        // the 7 m ties were not used: bravo's first keyframe stays within centimetres of the
        // truth.
        let bravo_first = solved[1][0].1;
        assert!((bravo_first.translation.vector - bravo_world.translation.vector).norm() < 0.5);
    }

    /// A factor the robot's own solve rejected (PCM or GNC) is not in the team graph: a wrong
    /// one, 10 m off and marked rejected, leaves the solve as it was.
    #[test]
    fn factors_a_robot_rejected_stay_out() {
        let alpha = chain(Pose3::identity());
        let bravo_world = pose_from_yaw_translation(-1.0, Vector3::new(2.0, -3.0, 0.0));
        let graphs =
            [Some(graph(0, &alpha, &alpha, bravo_world)), Some(graph(1, &alpha, &alpha, bravo_world.inverse()))];
        let placed = |k| Some(if k == 0 { Pose3::identity() } else { bravo_world });
        let clean = solve(&graphs, placed).expect("solves");
        let mut with_outlier = graphs.clone();
        let g = with_outlier[0].as_mut().expect("alpha's graph");
        let wrong = Between {
            measured: Pose3::translation(10.0, 0.0, 0.0),
            ..g.graph.betweens[g.graph.betweens.len() - 1].clone()
        };
        g.graph.betweens.push(wrong);
        g.rejected.push(g.graph.betweens.len() - 1);
        assert_eq!(solve(&with_outlier, placed).expect("solves"), clean);
        with_outlier[0].as_mut().expect("alpha's graph").rejected.clear();
        assert_ne!(solve(&with_outlier, placed).expect("solves"), clean, "the wrong factor, kept, moves the solve");
    }

    /// A robot the reference has not placed is left out, and its factors with it; with no
    /// graph at all there is nothing to solve.
    #[test]
    fn a_robot_not_placed_is_left_out() {
        let alpha = chain(Pose3::identity());
        let bravo_world = Pose3::translation(0.0, 4.0, 0.0);
        let graphs =
            [Some(graph(0, &alpha, &alpha, bravo_world)), Some(graph(1, &alpha, &alpha, bravo_world.inverse()))];
        let solved = solve(&graphs, |k| (k == 0).then(Pose3::identity)).expect("solves");
        assert_eq!(solved[0].len(), N as usize);
        assert!(solved[1].is_empty());
        assert!(solve(&[None, None], |_| Some(Pose3::identity())).is_none());
    }

    /// Two robots' graphs built by their own API, each with an inter-robot factor of its own;
    /// then each reads the other's whole factor log (`optimiser.share_factors`). The team graph
    /// of the graphs after the exchange equals the one before (to 10⁻⁵ m, the solver's
    /// tolerance): a neighbour's chain, and its
    /// inter-robot factor held inverted, are not counted a second time. Counting them makes
    /// the answer move, which the test checks too.
    #[test]
    fn a_neighbours_chain_held_by_a_robot_counts_once() {
        use sgm_model::optim::keyframe_graph::KeyframeGraph;
        use sgm_model::scene_graph::{Keyframe, KeyframeEdge, KeyframeEdgeKind};
        let info = Matrix6::identity() * 100.0;
        let build = |y: f64, bend: f64| {
            let mut g = KeyframeGraph::default();
            let mut pose = Pose3::translation(0.0, y, 0.0);
            for k in 0..N {
                let step = pose_from_yaw_translation(bend, Vector3::new(1.0, 0.0, 0.0));
                let edges: Vec<KeyframeEdge> = (k > 0)
                    .then(|| KeyframeEdge {
                        kind: KeyframeEdgeKind::Odometry,
                        from: KeyframeId(k - 1),
                        to: KeyframeRef::Local(KeyframeId(k)),
                        from_from_to: step,
                        information: info,
                    })
                    .into_iter()
                    .collect();
                if k > 0 {
                    pose *= step;
                }
                g.add_keyframe(
                    &Keyframe { id: KeyframeId(k), stamp: f64::from(k), world_from_body: pose },
                    &edges,
                    100,
                );
            }
            g
        };
        let (mut a, mut b) = (build(0.0, 0.02), build(2.0, -0.03));
        let b_in_a = Pose3::identity();
        let across = Pose3::translation(0.0, 2.0, 0.0);
        a.add_neighbour(
            RobotId(2),
            &b_in_a,
            &[(KeyframeId(4), Pose3::translation(4.0, 2.0, 0.0), Matrix6::identity())],
            &[(KeyframeId(4), KeyframeId(4), across, info)],
        );
        b.add_neighbour(
            RobotId(1),
            &b_in_a,
            &[(KeyframeId(1), Pose3::translation(1.0, 0.0, 0.0), Matrix6::identity())],
            &[(KeyframeId(1), KeyframeId(1), across.inverse(), info)],
        );
        // Robot ids are 1-based: robot 1 is index 0.
        let placed = |_: usize| Some(Pose3::identity());
        let before = solve(&[Some(a.freeze()), Some(b.freeze())], placed).unwrap();
        let (slice_of_b, slice_of_a) = (b.factor_slice(RobotId(1), 0, 1000), a.factor_slice(RobotId(2), 0, 1000));
        let added = sgm_model::optim::keyframe_graph::ChainAdded::Added {
            keyframes: N as usize,
            factors: N as usize,
            dropped: 0,
        };
        assert_eq!(a.add_chain(RobotId(2), &slice_of_b), added);
        assert_eq!(b.add_chain(RobotId(1), &slice_of_a), added);
        let (fa, fb) = (a.freeze(), b.freeze());
        let after = solve(&[Some(fa.clone()), Some(fb.clone())], placed).unwrap();
        let gap = |x: &[Vec<(KeyframeId, Pose3)>], y: &[Vec<(KeyframeId, Pose3)>]| {
            x.iter()
                .flatten()
                .zip(y.iter().flatten())
                .map(|((_, p), (_, q))| (p.translation.vector - q.translation.vector).norm())
                .fold(0.0, f64::max)
        };
        assert!(gap(&before, &after) < 1e-5, "{}", gap(&before, &after));
        // The inter-robot factors were used: the second robot moved from where it started.
        assert!((before[1][4].1.translation.vector - Vector3::new(3.9937, 1.8202, 0.0)).norm() > 1e-3);
        // Without its log, a graph's every inter-robot factor counts as its own: the inverted
        // one counts twice, and the answer moves.
        let mut no_log = fa.clone();
        no_log.log = Default::default();
        let twice = solve(&[Some(no_log), Some(fb)], placed).unwrap();
        assert!(gap(&before, &twice) > 1e-3, "{}", gap(&before, &twice));
    }
}
