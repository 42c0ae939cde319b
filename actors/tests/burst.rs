//! A burst of 100 matches within one second, each asking a neighbour for keyframes: the
//! requests in flight stay within the configured bound, no keyframe is requested or sent twice,
//! and every requested keyframe is either served or reported unavailable — over perfect links
//! and over a radio losing 30 % of packets.

use actix::{Actor, Addr, Context, Handler};
use nalgebra::{Matrix6, Point3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use sgm_actors::clock::Clock;
use sgm_actors::comms::{Comms, CommsLinks, CommsStatus, GetCommsStatus};
use sgm_actors::config::CommsConfig;
use sgm_actors::messages::*;
use sgm_actors::transport::{InProcessRadio, PerfectLinks, RadioModel};
use sgm_model::geometry::Pose3;
use sgm_model::scene_graph::{KeyframeId, RobotId, Stamp};
use sgm_model::wire::cloud_codec;
use sgm_model::wire::messages::{pack_covariance, KeyframeRefusal, KeyframeRefusalReason, KeyframeResponse, WirePose};
use sgm_model::wire::Message as WireMessage;
use std::collections::{BTreeMap, BTreeSet};
use std::sync::{Arc, Mutex};

const REQUESTER: RobotId = RobotId(1);
const SERVER: RobotId = RobotId(2);
/// The server's map holds keyframes 0..KNOWN; requests reach up to 300.
const KNOWN: u32 = 250;

/// Loses each packet with probability `loss`; 20 ms latency. Seeded.
struct LossyLinks {
    rng: ChaCha8Rng,
    loss: f64,
}

impl RadioModel for LossyLinks {
    fn arrivals(&mut self, _: RobotId, _: RobotId, _: usize, now: Stamp) -> Vec<Stamp> {
        (!self.rng.random_bool(self.loss)).then_some(now + 0.02).into_iter().collect()
    }
}

/// Nothing crosses between `from` and `until` (a partition); otherwise 20 ms latency.
struct PartitionedLinks {
    from: Stamp,
    until: Stamp,
}

impl RadioModel for PartitionedLinks {
    fn arrivals(&mut self, _: RobotId, _: RobotId, _: usize, now: Stamp) -> Vec<Stamp> {
        if (self.from..self.until).contains(&now) {
            Vec::new()
        } else {
            vec![now + 0.02]
        }
    }
}

/// What the requester's Comms handed to its (stand-in) Matcher.
#[derive(Default)]
struct Heard {
    served: BTreeMap<KeyframeId, usize>,
    reported: BTreeMap<KeyframeId, KeyframeRefusalReason>,
    /// Descriptor deliveries: (sender, keyframe ids).
    descriptors: Vec<(RobotId, Vec<KeyframeId>)>,
    links: Vec<LinkChanged>,
    /// Pose updates delivered: (sender, keyframe poses).
    poses: Vec<NeighbourKeyframePoses>,
    /// Factor-log requests and slices delivered.
    graph: Vec<NeighbourGraph>,
}

struct Recorder(Arc<Mutex<Heard>>);
impl Actor for Recorder {
    type Context = Context<Self>;
}
impl Handler<NeighbourKeyframe> for Recorder {
    type Result = ();
    fn handle(&mut self, msg: NeighbourKeyframe, _: &mut Context<Self>) {
        *self.0.lock().unwrap().served.entry(msg.id).or_default() += 1;
    }
}
impl Handler<LinkChanged> for Recorder {
    type Result = ();
    fn handle(&mut self, msg: LinkChanged, _: &mut Context<Self>) {
        self.0.lock().unwrap().links.push(msg);
    }
}
impl Handler<KeyframesUnavailable> for Recorder {
    type Result = ();
    fn handle(&mut self, msg: KeyframesUnavailable, _: &mut Context<Self>) {
        let mut heard = self.0.lock().unwrap();
        for id in msg.keyframes {
            heard.reported.insert(id, msg.reason);
        }
    }
}
impl Handler<NeighbourObjects> for Recorder {
    type Result = ();
    fn handle(&mut self, _: NeighbourObjects, _: &mut Context<Self>) {}
}
impl Handler<NeighbourDescriptors> for Recorder {
    type Result = ();
    fn handle(&mut self, msg: NeighbourDescriptors, _: &mut Context<Self>) {
        let ids = msg.descriptors.iter().map(|d| d.0).collect();
        self.0.lock().unwrap().descriptors.push((msg.robot, ids));
    }
}
impl Handler<NeighbourKeyframePoses> for Recorder {
    type Result = ();
    fn handle(&mut self, msg: NeighbourKeyframePoses, _: &mut Context<Self>) {
        self.0.lock().unwrap().poses.push(msg);
    }
}
impl Handler<NeighbourGraph> for Recorder {
    type Result = ();
    fn handle(&mut self, msg: NeighbourGraph, _: &mut Context<Self>) {
        self.0.lock().unwrap().graph.push(msg);
    }
}
impl Handler<NeighbourAlignments> for Recorder {
    type Result = ();
    fn handle(&mut self, _: NeighbourAlignments, _: &mut Context<Self>) {}
}
impl Handler<NeighbourObjectClouds> for Recorder {
    type Result = ();
    fn handle(&mut self, _: NeighbourObjectClouds, _: &mut Context<Self>) {}
}
impl Handler<Serve> for Recorder {
    type Result = ();
    fn handle(&mut self, _: Serve, _: &mut Context<Self>) {}
}

/// Stands in for the server's Tracker: a map of keyframes 0..KNOWN with small clouds.
struct Map {
    comms: Addr<Comms>,
}
impl Actor for Map {
    type Context = Context<Self>;
}
impl Handler<Serve> for Map {
    type Result = ();
    fn handle(&mut self, msg: Serve, _: &mut Context<Self>) {
        let Serve::Keyframes { robot, keyframes } = msg else { return };
        let (known, unknown): (Vec<KeyframeId>, Vec<KeyframeId>) = keyframes.into_iter().partition(|k| k.0 < KNOWN);
        for id in known {
            let points: Vec<Point3<f64>> = (0..20).map(|i| Point3::new(i as f64 * 0.1, f64::from(id.0), 0.0)).collect();
            let message = WireMessage::KeyframeResponse(KeyframeResponse {
                keyframe: id,
                stamp: f64::from(id.0),
                world_from_body: WirePose::from(&Pose3::identity()),
                covariance: pack_covariance(&(Matrix6::identity() * 0.01)),
                cloud: cloud_codec::encode(&points, 0.01).unwrap().bytes,
            });
            self.comms.do_send(Outgoing { to: robot, message });
        }
        if !unknown.is_empty() {
            let refusal = KeyframeRefusal { keyframes: unknown, reason: KeyframeRefusalReason::Unknown };
            self.comms.do_send(Outgoing { to: robot, message: WireMessage::KeyframeRefusal(refusal) });
        }
    }
}

async fn settle() {
    sgm_actors::quiescence::until_quiet().await;
}

struct Outcome {
    requested: BTreeSet<KeyframeId>,
    heard: Heard,
    requester: CommsStatus,
    server: CommsStatus,
}

/// A requester and a server (its map: [`Map`]) over `model`; what the requester's Comms hands
/// over is recorded in `heard`.
struct Pair {
    radio: InProcessRadio,
    clock: Clock,
    requester: Addr<Comms>,
    server: Addr<Comms>,
    heard: Arc<Mutex<Heard>>,
}

fn pair(model: Box<dyn RadioModel>, config: &CommsConfig) -> Pair {
    let radio = InProcessRadio::new(model);
    let clock = Clock::starting_at(0.0);
    let key = config.team_key().unwrap();
    let start = |robot: RobotId| {
        let comms = Comms::new(robot, config.clone(), key.clone(), clock.clone(), Box::new(radio.clone()), 0).start();
        radio.attach(robot, comms.clone().recipient());
        comms
    };
    let (requester, server) = (start(REQUESTER), start(SERVER));
    let heard = Arc::new(Mutex::new(Heard::default()));
    let recorder = Recorder(heard.clone()).start();
    let map = Map { comms: server.clone() }.start();
    let links = |serve: actix::Recipient<Serve>| CommsLinks {
        objects: recorder.clone().recipient(),
        object_clouds: recorder.clone().recipient(),
        keyframes: recorder.clone().recipient(),
        unavailable: recorder.clone().recipient(),
        descriptors: recorder.clone().recipient(),
        alignments: recorder.clone().recipient(),
        serve,
        link: recorder.clone().recipient(),
        keyframe_poses: recorder.clone().recipient(),
        graph: recorder.clone().recipient(),
    };
    requester.do_send(Connect(links(recorder.clone().recipient())));
    server.do_send(Connect(links(map.recipient())));
    Pair { radio, clock, requester, server, heard }
}

/// 100 requests of 6 keyframes each, one every 10 ms, then `seconds` of ticks every 100 ms.
async fn burst(model: Box<dyn RadioModel>, config: CommsConfig, seconds: u32) -> Outcome {
    let Pair { radio, clock, requester, server, heard } = pair(model, &config);

    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let mut requested = BTreeSet::new();
    for step in 0..100 {
        let now = f64::from(step) * 0.01;
        clock.advance_to(now);
        let keyframes: Vec<KeyframeId> = (0..6).map(|_| KeyframeId(rng.random_range(0..300))).collect();
        requested.extend(keyframes.iter().copied());
        requester.do_send(RequestKeyframes { robot: SERVER, keyframes });
        for comms in [&requester, &server] {
            comms.do_send(Tick { now });
        }
        radio.deliver_due(now);
        settle().await;
    }
    for step in 10..=seconds * 10 {
        let now = f64::from(step) * 0.1;
        clock.advance_to(now);
        for comms in [&requester, &server] {
            comms.do_send(Tick { now });
        }
        settle().await;
        radio.deliver_due(now);
        settle().await;
    }
    let requester = requester.send(GetCommsStatus).await.unwrap();
    let server = server.send(GetCommsStatus).await.unwrap();
    let heard = std::mem::take(&mut *heard.lock().unwrap());
    Outcome { requested, heard, requester, server }
}

#[actix_rt::test]
async fn a_burst_over_perfect_links_is_bounded_served_once_and_the_rest_reported() {
    let config = CommsConfig { max_keyframes_in_flight: 8, ..CommsConfig::default() };
    let o = burst(Box::new(PerfectLinks), config, 60).await;
    assert!(o.requested.len() > 250, "the burst asks for most of 0..300: {}", o.requested.len());
    // The bound holds, and the burst reaches it.
    assert_eq!(o.requester.max_keyframes_in_flight, 8);
    // Every known keyframe served exactly once, every unknown one reported as such.
    for id in &o.requested {
        if id.0 < KNOWN {
            assert_eq!(o.heard.served.get(id), Some(&1), "{id:?}");
            assert!(!o.heard.reported.contains_key(id), "{id:?}");
        } else {
            assert_eq!(o.heard.reported.get(id), Some(&KeyframeRefusalReason::Unknown), "{id:?}");
        }
    }
    assert_eq!(o.heard.served.len() + o.heard.reported.len(), o.requested.len());
    assert_eq!(o.server.keyframes_sent_twice, 0);
    assert_eq!((o.requester.keyframes_given_up, o.requester.keyframes_refused_locally), (0, 0));
    // The ledger accounts for every keyframe asked for.
    let ledger = &o.requester.keyframe_ledger[&SERVER];
    assert_eq!(ledger.wanted as usize, o.requested.len());
    assert_eq!(ledger.received as usize, o.heard.served.len());
    assert_eq!(ledger.refused as usize, o.heard.reported.len());
    assert_eq!((ledger.given_up, ledger.pending), (0, 0));
    // Coalescing: far fewer requests than the 100 matches asked for.
    let requests = o.requester.sent.get(sgm_model::wire::MessageKind::KeyframeRequest).count;
    assert!(requests < 100, "{requests} KeyframeRequests");
}

#[actix_rt::test]
async fn a_burst_over_a_lossy_radio_is_bounded_and_nothing_is_silently_dropped() {
    let config = CommsConfig { max_keyframes_in_flight: 16, max_keyframes_waiting: 200, ..CommsConfig::default() };
    let model = LossyLinks { rng: ChaCha8Rng::seed_from_u64(8), loss: 0.3 };
    // Long enough for every retry with back-off (5 + 10 + 20 + 40 + 80 s) of the last batch.
    let o = burst(Box::new(model), config, 900).await;
    assert!(o.requester.max_keyframes_in_flight <= 16);
    assert!(o.requester.keyframes_refused_locally > 0, "the waiting bound bites");
    assert!(o.requester.keyframes_given_up > 0 || o.server.keyframes_sent_twice > 0, "losses forced retries");
    for id in &o.requested {
        let served = o.heard.served.get(id).copied().unwrap_or(0);
        assert!(served <= 1, "{id:?} handed over {served} times");
        assert!(served == 1 || o.heard.reported.contains_key(id), "{id:?} neither served nor reported");
        if id.0 >= KNOWN {
            assert_eq!(served, 0);
        }
    }
    let ledger = &o.requester.keyframe_ledger[&SERVER];
    assert_eq!(ledger.wanted as usize, o.requested.len(), "{ledger:?}");
    assert_eq!(ledger.received as usize, o.heard.served.len(), "{ledger:?}");
    assert_eq!(ledger.pending, 0, "{ledger:?}");
    assert_eq!(ledger.received + ledger.refused + ledger.given_up, ledger.wanted, "{ledger:?}");
    assert_eq!(o.requester.links_down, Vec::<RobotId>::new());
}

/// A partition from 0.5 s to 400 s, longer than every retry with back-off: the requester sees
/// the link go down after `link_timeout_s`, stops retrying (nothing is given up), and once the
/// partition heals and the server is heard again (its ObjectData refresh), asks afresh: every
/// keyframe arrives.
#[actix_rt::test]
async fn a_partition_pauses_requests_and_the_heal_completes_them() {
    let config = CommsConfig { max_keyframes_in_flight: 16, max_keyframes_waiting: 1000, ..CommsConfig::default() };
    let Pair { radio, clock, requester, server, heard } =
        pair(Box::new(PartitionedLinks { from: 0.5, until: 400.0 }), &config);
    // The server has a map: its ObjectData makes it heard, then keeps it heard.
    let object = sgm_model::matching::GraphObject {
        id: sgm_model::scene_graph::ObjectId(1),
        label: sgm_model::scene_graph::LabelId(1),
        centroid: Point3::new(1.0, 2.0, 0.0),
        size: None,
    };
    server.do_send(map_with(vec![object]));
    let wanted: Vec<KeyframeId> = (0..40).map(KeyframeId).collect();
    let mut links_down_during = Vec::new();
    for step in 0..6000 {
        let now = f64::from(step) * 0.1;
        clock.advance_to(now);
        if step == 3 {
            requester.do_send(RequestKeyframes { robot: SERVER, keyframes: wanted.clone() });
        }
        for comms in [&requester, &server] {
            comms.do_send(Tick { now });
        }
        settle().await;
        radio.deliver_due(now);
        settle().await;
        if step == 3000 {
            links_down_during = requester.send(GetCommsStatus).await.unwrap().links_down;
        }
    }
    let status = requester.send(GetCommsStatus).await.unwrap();
    let heard = std::mem::take(&mut *heard.lock().unwrap());
    assert_eq!(links_down_during, vec![SERVER], "down while partitioned");
    assert_eq!(status.links_down, Vec::<RobotId>::new(), "back after the heal");
    assert_eq!(status.link_losses, 1);
    assert_eq!(heard.links, vec![LinkChanged { robot: SERVER, up: false }, LinkChanged { robot: SERVER, up: true }]);
    assert_eq!(status.keyframes_given_up, 0);
    let ledger = &status.keyframe_ledger[&SERVER];
    assert_eq!((ledger.wanted, ledger.received, ledger.refused, ledger.given_up, ledger.pending), (40, 40, 0, 0, 0));
    assert_eq!(heard.served.len(), 40);
    assert!(heard.served.values().all(|n| *n == 1));
}

/// The Scan Context baseline's path through Comms: descriptors shared between two broadcasts go
/// out together (at most `limits.max_ids` per envelope, at most once per
/// `object_data_interval_s`), arrive decoded with their poses, and no object data is sent.
#[actix_rt::test]
async fn descriptors_are_batched_broadcast_and_delivered() {
    use sgm_model::matching::scan_context::ScanContext;
    let config = CommsConfig {
        limits: sgm_model::wire::WireLimits { max_ids: 4, ..Default::default() },
        ..CommsConfig::default()
    };
    let radio = InProcessRadio::new(Box::new(PerfectLinks));
    let clock = Clock::starting_at(0.0);
    let key = config.team_key().unwrap();
    let heard = Arc::new(Mutex::new(Heard::default()));
    let recorder = Recorder(heard.clone()).start();
    let mut robots = Vec::new();
    for robot in [REQUESTER, SERVER] {
        let transport = Box::new(radio.clone());
        let comms =
            Comms::new(robot, config.clone(), key.clone(), clock.clone(), transport, 0).without_object_data().start();
        radio.attach(robot, comms.clone().recipient());
        comms.do_send(Connect(CommsLinks {
            objects: recorder.clone().recipient(),
            object_clouds: recorder.clone().recipient(),
            keyframes: recorder.clone().recipient(),
            unavailable: recorder.clone().recipient(),
            descriptors: recorder.clone().recipient(),
            alignments: recorder.clone().recipient(),
            serve: recorder.clone().recipient(),
            link: recorder.clone().recipient(),
            keyframe_poses: recorder.clone().recipient(),
            graph: recorder.clone().recipient(),
        }));
        robots.push(comms);
    }
    let sender = &robots[0];
    let points: Vec<Point3<f64>> = (0..50).map(|k| Point3::new(f64::from(k) * 0.5 + 1.0, 2.0, 0.5)).collect();
    let descriptor = ScanContext::new(&points, &Default::default());
    // Objects are ignored by a Comms without object data.
    sender.do_send(map_with(vec![sgm_model::matching::GraphObject {
        id: sgm_model::scene_graph::ObjectId(1),
        label: sgm_model::scene_graph::LabelId(3),
        centroid: Point3::origin(),
        size: None,
    }]));
    for (step, ids) in [(0u32, 0..6u32), (1, 6..7), (30, 7..8)] {
        let now = f64::from(step) * 0.1;
        clock.advance_to(now);
        for id in ids {
            let world_from_body =
                Pose3::from_parts(nalgebra::Translation3::new(f64::from(id), 0.0, 0.0), Default::default());
            sender.do_send(ShareDescriptor {
                keyframe: KeyframeId(id),
                world_from_body,
                descriptor: descriptor.clone(),
            });
        }
        sender.do_send(Tick { now });
        settle().await;
        radio.deliver_due(now);
        settle().await;
    }
    let status = sender.send(GetCommsStatus).await.unwrap();
    let heard = std::mem::take(&mut *heard.lock().unwrap());
    let batches: Vec<Vec<u32>> = heard.descriptors.iter().map(|(_, ids)| ids.iter().map(|k| k.0).collect()).collect();
    // At t = 0: six descriptors in envelopes of four and two; keyframe 6 (t = 0.1) waits for the
    // next broadcast (interval 2 s) and goes out with keyframe 7 at t = 3.
    assert_eq!(batches, vec![vec![0, 1, 2, 3], vec![4, 5], vec![6, 7]]);
    assert!(heard.descriptors.iter().all(|(from, _)| *from == REQUESTER));
    assert_eq!(status.sent.get(sgm_model::wire::MessageKind::KeyframeDescriptors).count, 3);
    assert_eq!(status.sent.get(sgm_model::wire::MessageKind::ObjectData).count, 0);
}

#[actix_rt::test]
async fn served_keyframes_that_a_solve_moves_are_told_to_the_neighbour_holding_them() {
    use sgm_model::geometry::pose_from_rpy_translation;
    let Pair { radio, clock, requester, server, heard } = pair(Box::new(PerfectLinks), &CommsConfig::default());
    let step = |now: f64| {
        clock.advance_to(now);
        for comms in [&requester, &server] {
            comms.do_send(Tick { now });
        }
    };
    requester.do_send(RequestKeyframes { robot: SERVER, keyframes: (0..4).map(KeyframeId).collect() });
    for k in 0..20 {
        step(f64::from(k) * 0.1);
        settle().await;
        radio.deliver_due(f64::from(k) * 0.1);
        settle().await;
    }
    assert_eq!(heard.lock().unwrap().served.len(), 4, "served at the identity");
    // The server's solve moves keyframe 1 by 0.3 m and turns keyframe 2 by 1°; 0 and 3 stay.
    let moved = |id: u32| match id {
        1 => pose_from_rpy_translation(0.0, 0.0, 0.0, nalgebra::Vector3::new(0.3, 0.0, 0.0)),
        2 => pose_from_rpy_translation(0.0, 0.0, 1f64.to_radians(), nalgebra::Vector3::zeros()),
        _ => Pose3::identity(),
    };
    let scan = Arc::new(sgm_model::scene_graph::SemanticScan::default());
    let keyframes = (0..4)
        .map(|id| {
            (KeyframeId(id), sgm_actors::map_view::ViewKeyframe { world_from_body: moved(id), scan: scan.clone() })
        })
        .collect();
    server.do_send(MapChanged(Arc::new(sgm_actors::map_view::MapView { keyframes, ..Default::default() })));
    for k in 20..40 {
        step(f64::from(k) * 0.1);
        settle().await;
        radio.deliver_due(f64::from(k) * 0.1);
        settle().await;
    }
    let heard_after = heard.clone();
    let heard = std::mem::take(&mut *heard.lock().unwrap());
    assert_eq!(heard.poses.len(), 1, "one update, once");
    assert_eq!(heard.poses[0].robot, SERVER);
    let told: Vec<u32> = heard.poses[0].poses.iter().map(|(k, _)| k.0).collect();
    assert_eq!(told, [1, 2]);
    for (k, pose) in &heard.poses[0].poses {
        let truth = moved(k.0);
        assert!((pose.translation.vector - truth.translation.vector).norm() < 1e-6);
        assert!((pose.rotation.inverse() * truth.rotation).angle() < 1e-6);
    }
    let status = server.send(GetCommsStatus).await.unwrap();
    assert_eq!(status.sent.get(sgm_model::wire::MessageKind::KeyframePoses).count, 1);
    // A pose that is not finite is dropped and counted; the rest of its message is delivered.
    use sgm_model::wire::messages::{KeyframePoses, WireKeyframePose};
    let bad = WireKeyframePose { keyframe: KeyframeId(0), translation: [f32::NAN, 0.0, 0.0], rotation: [0.0; 3] };
    let good = WireKeyframePose::new(KeyframeId(3), &moved(1));
    let message = WireMessage::KeyframePoses(KeyframePoses { poses: vec![bad, good] });
    server.do_send(Outgoing { to: REQUESTER, message });
    step(4.0);
    settle().await;
    radio.deliver_due(4.0);
    settle().await;
    let requester = requester.send(GetCommsStatus).await.unwrap();
    assert_eq!(requester.rejected.malformed, 1);
    let poses = std::mem::take(&mut heard_after.lock().unwrap().poses);
    assert_eq!(poses.len(), 1);
    assert_eq!(poses[0].poses.iter().map(|(k, _)| k.0).collect::<Vec<_>>(), [3]);
}

/// A map snapshot holding only `objects`, as the Tracker shares it.
fn map_with(objects: Vec<sgm_model::matching::GraphObject>) -> MapChanged {
    let objects = sgm_actors::map_view::LocalObjects { objects, ..Default::default() };
    MapChanged(std::sync::Arc::new(sgm_actors::map_view::MapView { objects, ..Default::default() }))
}
