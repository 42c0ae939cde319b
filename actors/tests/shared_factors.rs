//! Two Optimisers sharing their factors (`optimiser.share_factors`) over a radio that loses
//! messages: each ends up holding the other's whole chain — every keyframe, its odometry and
//! its inter-robot factor — in slices of at most `max_ids`, asked again after a loss (30 % of
//! messages, seeded) at the next period; an Optimiser that does not share answers nothing.

use actix::{Actor, Addr, Context, Handler, Message};
use nalgebra::{Matrix6, UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use sgm_actors::config::OptimiserConfig;
use sgm_actors::messages::*;
use sgm_actors::optimiser::{GetOptimiserStatus, Optimiser, OptimiserLinks, OptimiserStatus};
use sgm_model::geometry::{pose_from_yaw_translation, Pose3};
use sgm_model::scene_graph::{Keyframe, KeyframeEdge, KeyframeEdgeKind, KeyframeId, KeyframeRef, RobotId};
use sgm_model::wire::Message as WireMessage;
use std::sync::{Arc, Mutex};

const A: RobotId = RobotId(0);
const B: RobotId = RobotId(1);
const KEYFRAMES: u32 = 30;
const SLICE_ITEMS: usize = 8;

/// What crossed the radio, counted.
#[derive(Default)]
struct Traffic {
    sent: usize,
    lost: usize,
    largest_slice: usize,
}

/// One robot's side of the radio: its Optimiser's wire messages go to the other's, as its Comms
/// would deliver them, each lost with probability `loss` (seeded). Poses and transforms are
/// dropped.
struct Radio {
    from: RobotId,
    to: Option<Addr<Optimiser>>,
    loss: f64,
    rng: ChaCha8Rng,
    traffic: Arc<Mutex<Traffic>>,
}

impl Actor for Radio {
    type Context = Context<Self>;
}

#[derive(Message)]
#[rtype(result = "()")]
struct Peer(Addr<Optimiser>);

impl Handler<Peer> for Radio {
    type Result = ();
    fn handle(&mut self, msg: Peer, _: &mut Context<Self>) {
        self.to = Some(msg.0);
    }
}

impl Handler<Outgoing> for Radio {
    type Result = ();
    fn handle(&mut self, msg: Outgoing, _: &mut Context<Self>) {
        let mut traffic = self.traffic.lock().unwrap();
        traffic.sent += 1;
        if self.rng.random_bool(self.loss) {
            traffic.lost += 1;
            return;
        }
        let delivered = match msg.message {
            WireMessage::GraphFactorRequest(r) => NeighbourGraph::Request { robot: self.from, from: r.from },
            WireMessage::GraphFactors(m) => {
                let (slice, malformed) = m.to_slice();
                assert_eq!(malformed, 0);
                traffic.largest_slice = traffic.largest_slice.max(slice.items());
                NeighbourGraph::Slice { robot: self.from, slice }
            }
            other => panic!("not a factor message: {other:?}"),
        };
        if let Some(to) = &self.to {
            to.do_send(delivered);
        }
    }
}

impl Handler<PosesOptimised> for Radio {
    type Result = ();
    fn handle(&mut self, _: PosesOptimised, _: &mut Context<Self>) {}
}

impl Handler<NeighbourTransforms> for Radio {
    type Result = ();
    fn handle(&mut self, _: NeighbourTransforms, _: &mut Context<Self>) {}
}

fn information() -> Matrix6<f64> {
    Matrix6::from_diagonal(&nalgebra::Vector6::new(1e4, 1e4, 1e4, 400.0, 400.0, 400.0))
}

/// A robot's keyframes along a gentle curve, each with its odometry factor.
fn keyframes(offset_y: f64) -> Vec<NewKeyframe> {
    let step = pose_from_yaw_translation(0.05, Vector3::new(1.0, 0.0, 0.0));
    let mut pose = Pose3::translation(0.0, offset_y, 0.0);
    (0..KEYFRAMES)
        .map(|k| {
            let edges = if k == 0 {
                Vec::new()
            } else {
                pose *= step;
                vec![KeyframeEdge {
                    kind: KeyframeEdgeKind::Odometry,
                    from: KeyframeId(k - 1),
                    to: KeyframeRef::Local(KeyframeId(k)),
                    from_from_to: step,
                    information: information(),
                }]
            };
            NewKeyframe {
                keyframe: Keyframe { id: KeyframeId(k), stamp: f64::from(k), world_from_body: pose },
                edges,
                odom_from_body_rotation: UnitQuaternion::identity(),
                measured_up: None,
            }
        })
        .collect()
}

struct Run {
    a: OptimiserStatus,
    b: OptimiserStatus,
    traffic: Arc<Mutex<Traffic>>,
}

/// Both robots' keyframes, one inter-robot factor each way, then `seconds` of ticks.
async fn run(share_b: bool, loss: f64, seconds: u32) -> Run {
    let config = |share| OptimiserConfig { share_factors: share, every_keyframes: 1, ..OptimiserConfig::default() };
    let traffic = Arc::new(Mutex::new(Traffic::default()));
    let radio = |from: RobotId| {
        let rng = ChaCha8Rng::seed_from_u64(u64::from(from.0) + 7);
        Radio { from, to: None, loss, rng, traffic: traffic.clone() }.start()
    };
    let (radio_a, radio_b) = (radio(A), radio(B));
    let a = Optimiser::new(A, config(true)).with_slice_items(SLICE_ITEMS).start();
    let b = Optimiser::new(B, config(share_b)).with_slice_items(SLICE_ITEMS).start();
    radio_a.send(Peer(b.clone())).await.unwrap();
    radio_b.send(Peer(a.clone())).await.unwrap();
    for (optimiser, radio) in [(&a, &radio_a), (&b, &radio_b)] {
        optimiser
            .send(Connect(OptimiserLinks {
                tracker: radio.clone().recipient(),
                matcher: radio.clone().recipient(),
                comms: radio.clone().recipient(),
            }))
            .await
            .unwrap();
    }
    for (optimiser, offset) in [(&a, 0.0), (&b, 3.0)] {
        for k in keyframes(offset) {
            optimiser.send(k).await.unwrap();
        }
    }
    // B's world is A's moved 3 m along y: the same keyframe ids face each other.
    let b_in_a = Pose3::translation(0.0, 3.0, 0.0);
    let across = |k: u32| {
        let pose: Vec<NewKeyframe> = keyframes(0.0);
        pose[k as usize].keyframe.world_from_body
    };
    let constraint = |robot, local_from_remote: Pose3, k: u32| InterRobotConstraints {
        robot,
        local_from_remote,
        neighbour_keyframes: vec![(KeyframeId(k), across(k), Matrix6::identity() * 0.01)],
        factors: vec![(
            KeyframeId(k),
            KeyframeId(k),
            across(k).inverse() * local_from_remote * across(k),
            information(),
        )],
    };
    a.send(constraint(B, b_in_a, 10)).await.unwrap();
    b.send(constraint(A, b_in_a.inverse(), 20)).await.unwrap();
    for t in 0..2 * seconds {
        let now = f64::from(t) * 0.5;
        a.send(Tick { now }).await.unwrap();
        b.send(Tick { now }).await.unwrap();
        // Let the radio and the other side run.
        for _ in 0..4 {
            radio_a.send(Peer(b.clone())).await.unwrap();
            radio_b.send(Peer(a.clone())).await.unwrap();
            a.send(GetOptimiserStatus).await.unwrap();
            b.send(GetOptimiserStatus).await.unwrap();
        }
    }
    Run { a: a.send(GetOptimiserStatus).await.unwrap(), b: b.send(GetOptimiserStatus).await.unwrap(), traffic }
}

#[actix_rt::test]
async fn each_robot_holds_the_others_whole_chain_in_bounded_slices() {
    let run = run(true, 0.0, 20).await;
    for (status, other) in [(&run.a, B), (&run.b, A)] {
        assert_eq!(status.graph.chains.len(), 1, "{status:?}");
        let chain = status.graph.chains[0];
        assert_eq!(chain.robot, other);
        assert_eq!(chain.keyframes, KEYFRAMES as usize);
        // Its odometry and its inter-robot factor to us.
        assert_eq!(chain.factors, u64::from(KEYFRAMES - 1) + 1);
        assert_eq!((chain.dropped, chain.full), (0, false));
        // Both robots' inter-robot factors are ours to weigh now.
        assert_eq!(status.graph.inter_robot[0].factors, 2);
        assert_eq!(status.failures.failed_solves, 0);
    }
    let traffic = run.traffic.lock().unwrap();
    assert!(traffic.largest_slice <= SLICE_ITEMS && traffic.largest_slice > 0);
}

#[actix_rt::test]
async fn a_lossy_radio_delays_the_chain_and_loses_nothing() {
    let run = run(true, 0.3, 120).await;
    assert!(run.traffic.lock().unwrap().lost > 3);
    for status in [&run.a, &run.b] {
        let chain = status.graph.chains[0];
        assert_eq!((chain.keyframes, chain.factors, chain.dropped), (KEYFRAMES as usize, u64::from(KEYFRAMES), 0));
    }
}

#[actix_rt::test]
async fn a_robot_that_does_not_share_answers_nothing() {
    let run = run(false, 0.0, 20).await;
    assert!(run.a.graph.chains.is_empty(), "{:?}", run.a.graph.chains);
    assert!(run.b.graph.chains.is_empty());
    assert_eq!(run.a.graph.inter_robot[0].factors, 1);
}
