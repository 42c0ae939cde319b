//! `RobotSupervisor`: one robot's actor tree (DESIGN.md §3). Builds and wires the children
//! explicitly (no registry: many robots share a process), owns the clock, forwards ticks, and
//! restarts a child that stops (actix `Supervisor`). What survives a restart: everything — each
//! child's state is its struct, which actix keeps across restarts; only the message being
//! handled when the child failed is lost (the map, the pose graph, the neighbour protocol states,
//! the request queues and the replay windows are not). What survives the whole robot going down
//! is its last snapshot ([`RobotHandle::freeze`], `crate::snapshot`), from which
//! [`start_robot_restored`] continues.

use crate::clock::Clock;
use crate::comms::{Comms, CommsLinks, CommsState};
use crate::config::{Association, ConfigError, OdometrySource, RobotConfig};
use crate::fusion::Fusion;
use crate::matcher::{Matcher, MatcherLinks, MatcherState};
use crate::messages::{Connect, Freeze, Halt, Republish, SensorFrame, Tick};
use crate::odometry::{Odometry, OdometryStage};
use crate::optimiser::{Optimiser, OptimiserLinks};
use crate::progress::FrameProgress;
use crate::sensor::Sensor;
use crate::snapshot::RobotSnapshot;
use crate::tracker::{ServedClouds, Tracker, TrackerLinks};
use crate::transport::{InProcessRadio, Transport};
use actix::{Actor, Addr, Context, Handler, Supervisor};
use sgm_model::matching::{LabelSimilarity, MatcherConfig};
use sgm_model::perception::classes::ClassTable;
use sgm_model::scene_graph::{KeyframeId, LabelId, RobotId};
use sgm_model::workers::Workers;
use std::collections::{BTreeMap, BTreeSet};

/// Addresses of one robot's actors (stable across restarts).
#[derive(Clone)]
pub struct RobotHandle {
    pub robot: RobotId,
    pub name: String,
    pub clock: Clock,
    pub supervisor: Addr<RobotSupervisor>,
    pub sensor: Addr<Sensor>,
    /// The internal odometry (`odometry.source = "internal"`).
    pub odometry: Option<Addr<Odometry>>,
    pub fusion: Addr<Fusion>,
    pub tracker: Addr<Tracker>,
    pub matcher: Addr<Matcher>,
    pub optimiser: Addr<Optimiser>,
    pub comms: Addr<Comms>,
    /// The newest frame the Tracker has handled (latency measurement).
    pub progress: FrameProgress,
}

pub struct RobotSupervisor {
    clock: Clock,
    sensor: Addr<Sensor>,
    tracker: Addr<Tracker>,
    matcher: Addr<Matcher>,
    optimiser: Addr<Optimiser>,
    comms: Addr<Comms>,
}

impl RobotHandle {
    /// The robot's state, frozen child by child along the pipeline (Tracker, Matcher,
    /// Optimiser, Comms: see [`Freeze`]).
    pub async fn freeze(&self) -> Result<RobotSnapshot, actix::MailboxError> {
        Ok(RobotSnapshot {
            robot: self.robot,
            name: self.name.clone(),
            taken_at: self.clock.now(),
            tracker: self.tracker.send(Freeze::default()).await?,
            matcher: self.matcher.send(Freeze::default()).await?,
            optimiser: self.optimiser.send(Freeze::default()).await?,
            comms: self.comms.send(Freeze::default()).await?,
        })
    }

    /// Takes the robot down: every child drops its links and the tree stops once the caller
    /// drops this handle (and the transport forgets the robot).
    pub fn halt(&self) {
        self.supervisor.do_send(Halt);
    }
}

impl Actor for RobotSupervisor {
    type Context = Context<Self>;
}

/// Starts one robot on the current actix system, attached to `radio`. The configuration is
/// validated first; nothing starts if it is invalid.
pub fn start_robot(config: &RobotConfig, clock: Clock, radio: &InProcessRadio) -> Result<RobotHandle, ConfigError> {
    start_robot_on(config, clock, Box::new(radio.clone()), |robot, comms| radio.attach(robot, comms.recipient()))
}

/// As [`start_robot`] over any transport; `attach` registers the robot's Comms with it.
pub fn start_robot_on(
    config: &RobotConfig,
    clock: Clock,
    transport: Box<dyn Transport>,
    attach: impl FnOnce(RobotId, Addr<Comms>),
) -> Result<RobotHandle, ConfigError> {
    start_robot_restored(config, clock, transport, attach, None, 0, Workers::sequential())
}

/// As [`start_robot_on`], continuing from `snapshot` when there is one: each child starts from
/// its part, and the Tracker hands the restored map to the Matcher and Comms. Sequence numbers
/// start at `sequence_floor` or the clock in microseconds, whichever is higher (simulation: 0,
/// so the counter of incarnation 0 follows its never-receding clock; a ROS node passes the first
/// sequence of its fresh incarnation), and go on above the snapshot's within one incarnation.
/// The Tracker's and Matcher's registrations may split their work over `workers` (the robot's
/// results are the same for any number of threads).
pub fn start_robot_restored(
    config: &RobotConfig,
    clock: Clock,
    transport: Box<dyn Transport>,
    attach: impl FnOnce(RobotId, Addr<Comms>),
    snapshot: Option<RobotSnapshot>,
    sequence_floor: u64,
    workers: Workers,
) -> Result<RobotHandle, ConfigError> {
    config.validate()?;
    let robot = RobotId(config.robot.id);
    let key = config.comms.team_key()?;
    let (classes, label_map) = config.class_tables()?;
    let labels = label_similarity(&classes, &config.matcher.matching)?;

    // Sequence numbers start at the clock in microseconds: a restarted robot never reuses one.
    let sequence_start = ((clock.now().max(0.0) * 1e6) as u64).max(sequence_floor);
    let comms_config = config.comms.clone();
    let comms_clock = clock.clone();
    let object_data = config.matcher.association != Association::ScanContext;
    let restored = snapshot.is_some();
    if let Some(s) = &snapshot {
        tracing::info!(robot = %robot, taken_at = s.taken_at, keyframes = s.keyframe_count(),
            objects = s.object_count(), "continuing from a snapshot");
    }
    let (tracker_state, matcher_state, optimiser_state, comms_state) = match snapshot {
        Some(s) => {
            let mut comms = s.comms;
            reconcile_held(&mut comms, &s.matcher, robot);
            (Some(s.tracker), Some(s.matcher), Some(s.optimiser), Some(comms))
        }
        None => (None, None, None, None),
    };
    // `Supervisor::start` takes a closure it may call again: each state is taken once.
    let comms = Supervisor::start(move |_| {
        let comms = Comms::new(robot, comms_config, key, comms_clock, transport, sequence_start);
        let comms = match comms_state {
            Some(state) => comms.thawed(state),
            None => comms,
        };
        if object_data {
            comms
        } else {
            comms.without_object_data()
        }
    });
    let tracker_config_classes = classes.clone();
    let served = ServedClouds {
        resolution_m: config.comms.cloud_resolution_m,
        keyframe_voxel_m: config.comms.keyframe_cloud_voxel_m,
    };
    if served.keyframe_voxel_m > config.matcher.keyframe_voxel_m {
        tracing::warn!(%robot, served = served.keyframe_voxel_m, registered = config.matcher.keyframe_voxel_m,
            "comms.keyframe_cloud_voxel_m is coarser than matcher.keyframe_voxel_m: neighbours registering our keyframes at that voxel get fewer points than they would thin to");
    }
    let tracker_config = (config.tracker.clone(), classes, config.optimiser.clone(), served);
    let progress = FrameProgress::default();
    let tracker_progress = progress.clone();
    let (tracker_workers, matcher_workers) = (workers.clone(), workers);
    let tracker = Supervisor::start(move |_| {
        let (t, classes, o, r) = tracker_config;
        let tracker = Tracker::new(robot, t, classes, &o, r)
            .with_progress(tracker_progress.clone())
            .with_workers(tracker_workers.clone());
        match tracker_state {
            Some(state) => tracker.thawed(state),
            None => tracker,
        }
    });
    let (matcher_config, retry, matcher_clock) = (config.matcher.clone(), config.comms.retry.clone(), clock.clone());
    let matcher = Supervisor::start(move |_| {
        let matcher = Matcher::new(robot, matcher_config, retry, matcher_clock, labels.clone())
            .with_workers(matcher_workers.clone());
        match matcher_state {
            Some(state) => matcher.thawed(state),
            None => matcher,
        }
    });
    let optimiser_config = config.optimiser.clone();
    // `matcher.max_tilt_deg = 0` declares the robots' worlds gravity-aligned: anchors are level.
    let level_anchors = config.matcher.matching.max_tilt_deg == 0.0;
    let own_estimates = config.comms.pose_updates.own_estimates;
    let slice_items = config.comms.limits.max_ids;
    let optimiser = Supervisor::start(move |_| {
        let optimiser = Optimiser::new(robot, optimiser_config)
            .with_level_anchors(level_anchors)
            .with_own_estimates(own_estimates)
            .with_slice_items(slice_items);
        match optimiser_state {
            Some(state) => optimiser.thawed(state),
            None => optimiser,
        }
    });
    let (fusion_config, fusion_classes) = (config.fusion.clone(), tracker_config_classes);
    let tracker_in = tracker.clone().recipient();
    let fusion = Supervisor::start(move |_| Fusion::new(&fusion_config, fusion_classes, label_map, tracker_in));
    let odometry = match config.odometry.source {
        OdometrySource::Internal => {
            let stage = OdometryStage::new(config.odometry.estimator.clone()).map_err(|e| ConfigError::Invalid {
                key: format!("odometry.estimator.{}", e.key),
                value: e.value.to_string(),
                allowed: e.allowed.into(),
            })?;
            let fusion_in = fusion.clone().recipient();
            Some(Supervisor::start(move |_| Odometry::new(stage.clone(), fusion_in.clone())))
        }
        OdometrySource::External => None,
    };
    let sensor_next = match &odometry {
        Some(odometry) => odometry.clone().recipient(),
        None => fusion.clone().recipient(),
    };
    let internal = odometry.is_some();
    let sensor = Supervisor::start(move |_| Sensor::new(sensor_next.clone(), internal));

    comms.do_send(Connect(CommsLinks {
        objects: matcher.clone().recipient(),
        object_clouds: matcher.clone().recipient(),
        keyframes: matcher.clone().recipient(),
        unavailable: matcher.clone().recipient(),
        descriptors: matcher.clone().recipient(),
        alignments: matcher.clone().recipient(),
        serve: tracker.clone().recipient(),
        link: matcher.clone().recipient(),
        keyframe_poses: optimiser.clone().recipient(),
        graph: optimiser.clone().recipient(),
    }));
    tracker.do_send(Connect(TrackerLinks {
        optimiser: optimiser.clone().recipient(),
        matcher_map: matcher.clone().recipient(),
        comms_map: comms.clone().recipient(),
        comms_outgoing: comms.clone().recipient(),
    }));
    matcher.do_send(Connect(MatcherLinks {
        request_clouds: comms.clone().recipient(),
        request_keyframes: comms.clone().recipient(),
        release_keyframes: comms.clone().recipient(),
        share_descriptors: comms.clone().recipient(),
        share_alignments: comms.clone().recipient(),
        optimiser: optimiser.clone().recipient(),
        withdraw: optimiser.clone().recipient(),
    }));
    optimiser.do_send(Connect(OptimiserLinks {
        tracker: tracker.clone().recipient(),
        matcher: matcher.clone().recipient(),
        comms: comms.clone().recipient(),
    }));
    attach(robot, comms.clone());
    if restored {
        tracker.do_send(Republish);
    }

    let supervisor = RobotSupervisor {
        clock: clock.clone(),
        sensor: sensor.clone(),
        tracker: tracker.clone(),
        matcher: matcher.clone(),
        optimiser: optimiser.clone(),
        comms: comms.clone(),
    }
    .start();
    Ok(RobotHandle {
        robot,
        name: config.robot.name.clone(),
        clock,
        supervisor,
        sensor,
        odometry,
        fusion,
        tracker,
        matcher,
        optimiser,
        comms,
        progress,
    })
}

impl Handler<SensorFrame> for RobotSupervisor {
    type Result = ();
    fn handle(&mut self, frame: SensorFrame, _: &mut Context<Self>) {
        self.sensor.do_send(frame);
    }
}

impl Handler<Halt> for RobotSupervisor {
    type Result = ();
    fn handle(&mut self, _: Halt, ctx: &mut Context<Self>) {
        self.tracker.do_send(Halt);
        self.matcher.do_send(Halt);
        self.optimiser.do_send(Halt);
        self.comms.do_send(Halt);
        actix::ActorContext::stop(ctx);
    }
}

impl Handler<Tick> for RobotSupervisor {
    type Result = ();
    fn handle(&mut self, tick: Tick, _: &mut Context<Self>) {
        self.clock.advance_to(tick.now);
        self.matcher.do_send(tick);
        self.comms.do_send(tick);
        self.optimiser.do_send(tick);
    }
}

/// A snapshot's parts are frozen one after the other: Comms, frozen after the Matcher, may count
/// as held a neighbour keyframe that reached the Matcher only after its part was taken. The
/// Matcher's part decides: what it does not hold is not held, and is asked for again when
/// wanted (never lost).
fn reconcile_held(comms: &mut CommsState, matcher: &MatcherState, robot: RobotId) {
    let matcher_held: BTreeMap<RobotId, BTreeSet<KeyframeId>> =
        matcher.neighbours.iter().map(|n| (n.robot, n.keyframes.iter().map(|k| k.id).collect())).collect();
    for (neighbour, held) in &mut comms.keyframes_held {
        let kept: BTreeSet<KeyframeId> = matcher_held.get(neighbour).cloned().unwrap_or_default();
        let lost = held.difference(&kept).count();
        if lost > 0 {
            tracing::info!(robot = %robot, neighbour = %neighbour, keyframes = lost,
                "keyframes Comms took after the Matcher's part of the snapshot: asked for again when wanted");
        }
        held.retain(|id| kept.contains(id));
    }
}

/// d_v's label table for the class table: `matcher.mislabel_similarity` between different
/// classes, `matcher.label_confusion` overriding named pairs. A pair naming a class that
/// `fusion.classes` does not have is a configuration error.
fn label_similarity(classes: &ClassTable, matching: &MatcherConfig) -> Result<LabelSimilarity, ConfigError> {
    let count = classes.classes().iter().map(|c| usize::from(c.id) + 1).max().unwrap_or(1);
    let mut labels = LabelSimilarity::uniform(count, matching.mislabel_similarity);
    for (k, pair) in matching.label_confusion.iter().enumerate() {
        let id = |name: &str, side: &str| {
            classes.by_name(name).map(|c| LabelId(c.id)).ok_or_else(|| ConfigError::Invalid {
                key: format!("matcher.label_confusion[{k}].{side}"),
                value: format!("{name:?}"),
                allowed: "the name of a class in fusion.classes".into(),
            })
        };
        labels.set(id(&pair.a, "a")?, id(&pair.b, "b")?, pair.similarity);
    }
    Ok(labels)
}

#[cfg(test)]
mod tests {
    use super::*;
    use sgm_model::matching::LabelConfusion;

    fn classes() -> ClassTable {
        ClassTable::new(crate::config::RobotConfig::default().fusion.classes).expect("the default class table")
    }

    #[test]
    fn the_robot_matches_with_the_configured_label_similarity() {
        let classes = classes();
        let id = |name: &str| LabelId(classes.by_name(name).expect(name).id);
        let (chair, bench, tree) = (id("chair"), id("bench"), id("tree"));
        let mut matching = MatcherConfig { mislabel_similarity: 0.2, ..MatcherConfig::default() };
        matching.label_confusion.push(LabelConfusion { a: "chair".into(), b: "bench".into(), similarity: 0.7 });
        let labels = label_similarity(&classes, &matching).expect("valid");
        assert_eq!(labels.get(chair, chair), 1.0);
        assert_eq!(labels.get(chair, bench), 0.7);
        assert_eq!(labels.get(bench, chair), 0.7);
        assert_eq!(labels.get(chair, tree), 0.2);
        let hard = label_similarity(&classes, &MatcherConfig { mislabel_similarity: 0.0, ..MatcherConfig::default() });
        assert!(!hard.expect("valid").is_soft());
    }

    /// The field case: Comms took neighbour keyframe 3 after the Matcher's part of the snapshot
    /// was frozen. Restored as they were, Comms would count 3 as held and never ask for it
    /// again while the Matcher lacks it; reconciled, only what the Matcher holds is held.
    #[test]
    fn comms_holds_after_a_restore_only_what_the_matcher_holds() {
        use crate::matcher::NeighbourMemory;
        use crate::messages::NeighbourKeyframe;
        let keyframe = |id| NeighbourKeyframe {
            robot: RobotId(2),
            id: KeyframeId(id),
            world_from_body: sgm_model::geometry::Pose3::identity(),
            covariance: nalgebra::Matrix6::identity(),
            points_in_body: Vec::new(),
            cloud_bytes: 0,
        };
        let matcher = MatcherState {
            neighbours: vec![NeighbourMemory {
                robot: RobotId(2),
                protocol: None,
                objects: None,
                keyframes: vec![keyframe(1), keyframe(2)],
                first_aligned: None,
                refuted: Vec::new(),
                graph_rounds_refuted: 0,
                closures: Default::default(),
                aligned_via: None,
                withdrawn: Vec::new(),
                withdrawals: 0,
                last_withdrawal: None,
                aligned_significance: None,
                challenged_bar: None,
                discredited: Vec::new(),
            }],
        };
        let mut comms = CommsState::default();
        comms.keyframes_held.insert(RobotId(2), [1, 2, 3].map(KeyframeId).into());
        comms.keyframes_held.insert(RobotId(5), [9].map(KeyframeId).into());
        reconcile_held(&mut comms, &matcher, RobotId(1));
        assert_eq!(comms.keyframes_held[&RobotId(2)], [1, 2].map(KeyframeId).into());
        assert!(comms.keyframes_held[&RobotId(5)].is_empty());
    }

    #[test]
    fn a_confusion_naming_an_unknown_class_is_refused_by_name() {
        let mut matching = MatcherConfig::default();
        matching.label_confusion.push(LabelConfusion { a: "chair".into(), b: "sofa".into(), similarity: 0.6 });
        let error = label_similarity(&classes(), &matching).expect_err("refused").to_string();
        assert!(error.contains("matcher.label_confusion[0].b") && error.contains("\"sofa\""), "{error}");
    }
}
