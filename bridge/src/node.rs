//! `sgm ros`: one robot as a ROS 1 node. Sensor topics in (checked by [`Inputs`], assembled by
//! the [`Synchroniser`]), the robot's actor tree in the middle, RViz-ready outputs and the
//! inter-robot [`RosTransport`] out. Names come from the `[ros]` section and resolve in the
//! node's namespace; rosrust honours `ROS_MASTER_URI`, `ROS_IP`/`ROS_HOSTNAME`,
//! `ROS_NAMESPACE`, `__name:=`, `__ns:=` and `from:=to` remappings on the command line.
//!
//! The robot's clock is the newest sensor stamp (ROS time, seconds since 1970): the node runs
//! the same whether its sensors are live or a bag played at any rate. Handlers never read the
//! wall clock; only the tick and publish loop waits on it.

use crate::bounded::{Bounded, Layout};
use crate::bounded_deliver::{BoundedDeliver, BoundedDeliverReq, BoundedDeliverRes};
use crate::config::RosConfig;
use crate::convert::cloud::semantic_map;
use crate::convert::markers::{keyframe_path, map_markers};
use crate::convert::time::Epoch;
use crate::error::InputError;
use crate::inputs::{Inputs, Payload};
use crate::msg::{nav_msgs, rosgraph_msgs, sensor_msgs, sgm_msgs, std_msgs, tf2_msgs, visualization_msgs};
use crate::persist::{Intake, Snapshots};
use crate::sync::Synchroniser;
use crate::team_frames::{team_transform, world_frame_param, WorldFrames};
use crate::transport::peers::MasterLocator;
use crate::transport::{RosTransport, TransportCounts};
use serde::{Deserialize, Serialize};
use sgm_actors::clock::Clock;
use sgm_actors::comms::AttachJournal;
use sgm_actors::comms::GetCommsStatus;
use sgm_actors::config::{ConfigError, RobotConfig};
use sgm_actors::fusion::GetFusionStatus;
use sgm_actors::journal::JournalFile;
use sgm_actors::matcher::GetNeighbours;
use sgm_actors::messages::Tick;
use sgm_actors::snapshot::SnapshotStore;
use sgm_actors::supervisor::start_robot_restored;
use sgm_actors::tracker::{GetMapSummary, GetSceneGraph};
use sgm_model::geometry::Pose3;
use sgm_model::perception::classes::ClassTable;
use sgm_model::wire::Sequence;
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;

/// A node's configuration file: the robot's sections plus `[ros]`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct NodeConfig {
    #[serde(flatten)]
    pub robot: RobotConfig,
    pub ros: RosConfig,
}

impl NodeConfig {
    /// Defaults, then `file`, then `SGM__…` variables; both parts validated.
    pub fn load(file: Option<&Path>) -> Result<Self, NodeError> {
        let defaults = config::Config::try_from(&NodeConfig::default()).map_err(|e| {
            NodeError::Config(ConfigError::Load { source_name: "defaults".into(), message: e.to_string() })
        })?;
        let merged = sgm_actors::config::layered(Some(defaults), file, "SGM").map_err(NodeError::Config)?;
        let source_name = file.map_or("environment".into(), |p| p.display().to_string());
        let config: NodeConfig = merged
            .try_deserialize()
            .map_err(|e| NodeError::Config(ConfigError::Load { source_name, message: e.to_string() }))?;
        config.robot.validate().map_err(NodeError::Config)?;
        config.ros.validate().map_err(NodeError::Ros)?;
        Ok(config)
    }
}

#[derive(Debug, thiserror::Error)]
pub enum NodeError {
    #[error("{0}")]
    Config(ConfigError),
    #[error(
        "the team key is public ({published}): anyone who reaches the ROS master could forge, alter \
         and replay this team's messages. Give the team a key of its own: \
         `(umask 077 && head -c 32 /dev/urandom | od -An -vtx1 | tr -d ' \\n' > team.key)`, copy team.key \
         to every robot (mode 600) and set comms.team_key_file to its absolute path \
         (SGM__COMMS__TEAM_KEY_FILE=/path/to/team.key, or roslaunch sgm robot.launch \
         team_key_file:=/path/to/team.key); for development on a private network only, \
         `sgm ros --development-key` starts with a public key"
    )]
    PublicKey { published: &'static str },
    #[error("[ros]: {0}")]
    Ros(InputError),
    #[error("ROS: {0}")]
    Ros1(String),
    #[error("[persistence]: {0}")]
    Snapshot(sgm_actors::snapshot::StoreError),
}

fn ros_error(e: impl std::fmt::Display) -> NodeError {
    NodeError::Ros1(e.to_string())
}

/// Per input topic: messages accepted and refused, and why the latest was refused.
#[derive(Default)]
struct InputCounts {
    accepted: BTreeMap<&'static str, AtomicU64>,
    refused: BTreeMap<&'static str, AtomicU64>,
    last_refusal: Mutex<BTreeMap<&'static str, String>>,
}

impl InputCounts {
    fn new(topics: &[&'static str]) -> Self {
        Self {
            accepted: topics.iter().map(|t| (*t, AtomicU64::new(0))).collect(),
            refused: topics.iter().map(|t| (*t, AtomicU64::new(0))).collect(),
            last_refusal: Mutex::default(),
        }
    }

    /// The health checks' view.
    fn tallies(&self) -> BTreeMap<String, crate::health::TopicTally> {
        let last = self.last_refusal.lock().unwrap_or_else(PoisonError::into_inner);
        self.accepted
            .iter()
            .map(|(topic, accepted)| {
                let tally = crate::health::TopicTally {
                    accepted: accepted.load(Ordering::Relaxed),
                    refused: self.refused.get(topic).map_or(0, |r| r.load(Ordering::Relaxed)),
                    last_refusal: last.get(topic).cloned(),
                };
                (topic.to_string(), tally)
            })
            .collect()
    }

    fn count<T>(&self, topic: &'static str, result: Result<T, InputError>) -> Option<T> {
        let (map, value) = match result {
            Ok(v) => (&self.accepted, Some(v)),
            Err(e) => {
                tracing::warn!(topic, "message refused: {e}");
                self.last_refusal.lock().unwrap_or_else(PoisonError::into_inner).insert(topic, e.to_string());
                (&self.refused, None)
            }
        };
        if let Some(c) = map.get(topic) {
            c.fetch_add(1, Ordering::Relaxed);
        }
        value
    }

    fn snapshot(map: &BTreeMap<&'static str, AtomicU64>) -> serde_json::Value {
        map.iter().map(|(k, v)| (k.to_string(), serde_json::json!(v.load(Ordering::Relaxed)))).collect()
    }
}

/// What the sensor callbacks share.
struct SensorSide {
    sync: Mutex<Synchroniser>,
    inputs: Inputs,
    counts: InputCounts,
    intake: Arc<Intake>,
    epoch: Epoch,
}

impl SensorSide {
    fn sync(&self) -> std::sync::MutexGuard<'_, Synchroniser> {
        self.sync.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// The ROS time of mission time `t` (outputs are stamped in ROS time).
    fn ros_time(&self, t: sgm_model::scene_graph::Stamp) -> rosrust::Time {
        self.sync().ros_time(self.epoch, t)
    }

    /// Counts a checked input of `topic`, feeds it to the synchroniser, and hands every frame
    /// then assembled to the robot, moving its clock to the frame's stamp.
    fn receive(&self, topic: &'static str, input: Result<Payload, InputError>) {
        let Some(payload) = self.counts.count(topic, input) else { return };
        let mut sync = self.sync();
        sync.feed(self.epoch, payload);
        for frame in sync.ready() {
            self.intake.frame(frame);
        }
        if let Some(t) = sync.clock() {
            self.intake.advance_clock(t);
        }
    }
}

/// Subscribes `topic` (counted as `name`): each message is checked by `check` and received.
fn subscribe<M: rosrust::Message + Layout>(
    topic: &str,
    queue: usize,
    side: &Arc<SensorSide>,
    name: &'static str,
    check: fn(&Inputs, &M) -> Result<Payload, InputError>,
) -> Result<rosrust::Subscriber, NodeError> {
    let side = side.clone();
    rosrust::subscribe(topic, queue, move |m: Bounded<M>| side.receive(name, check(&side.inputs, &m.0)))
        .map_err(ros_error)
}

/// Whether a node may start with a team key of
/// [`PUBLIC_TEAM_KEYS`](sgm_actors::config::PUBLIC_TEAM_KEYS).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PublicKeys {
    /// Refuse to start (the default of `sgm ros`).
    Refuse,
    /// Start, with a warning (`sgm ros --development-key`).
    AllowForDevelopment,
}

/// Refuses a public team key (the default, or one printed in the book or the shipped
/// configurations) unless `public` allows it, and then warns. A ROS node listens on a network,
/// where anyone who knows the key can speak for the team.
pub fn check_team_key(config: &RobotConfig, public: PublicKeys) -> Result<(), NodeError> {
    let Some(key) = config.comms.public_team_key().map_err(NodeError::Config)? else { return Ok(()) };
    match public {
        PublicKeys::Refuse => Err(NodeError::PublicKey { published: key.published }),
        PublicKeys::AllowForDevelopment => {
            tracing::warn!(
                robot = %config.robot.name,
                "DEVELOPMENT KEY: the team key is public ({}); anyone who reaches the ROS master can \
                 forge, alter and replay this team's messages. Never use --development-key in the field: \
                 set comms.team_key_file to a key of the team's own",
                key.published
            );
            Ok(())
        }
    }
}

/// Runs robot `config` as a ROS node until ROS shuts down (SIGINT, `rosnode kill`); a public
/// team key is refused unless `public` allows it ([`check_team_key`]).
pub fn run(config: NodeConfig, public: PublicKeys) -> Result<(), NodeError> {
    check_team_key(&config.robot, public)?;
    let robot_name = config.robot.robot.name.clone();
    let id = config.robot.robot.id;
    rosrust::try_init(&format!("sgm_{robot_name}")).map_err(ros_error)?;
    let ros = config.ros.clone();
    crate::bounded::set_max_message_bytes(ros.max_message_bytes);
    let classes = ClassTable::new(config.robot.fusion.classes.clone())
        .map_err(|e| NodeError::Ros(InputError::invalid(format!("fusion.classes: {e}"))))?;
    let system = actix_rt::System::new();
    system.block_on(async move {
        let counts = Arc::new(TransportCounts::default());
        let locator = Arc::new(MasterLocator::of_this_node().map_err(ros_error)?);
        let transport = RosTransport::start(&ros, sgm_model::scene_graph::RobotId(id), counts.clone(), locator)
            .map_err(ros_error)?;
        let peers = transport.peers();
        // Snapshots: resume from the latest whole one; if the latest and the previous are both
        // unusable, refuse to start (and overwrite nothing) with the reason for each.
        let persistence = &config.robot.persistence;
        let store = (!persistence.directory.is_empty()).then(|| {
            SnapshotStore::new(
                &persistence.directory,
                &robot_name,
                persistence.max_snapshot_mib.saturating_mul(1 << 20),
            )
        });
        if let Some(store) = &store {
            store.check_writable().map_err(NodeError::Snapshot)?;
        }
        let mut snapshot = match (&store, persistence.resume) {
            (Some(store), true) => store.load().map_err(NodeError::Snapshot)?.map(|loaded| {
                for skipped in &loaded.skipped {
                    tracing::warn!(robot = %robot_name, "snapshot skipped: {skipped}");
                }
                tracing::info!(robot = %robot_name, path = %loaded.path.display(), "resuming");
                loaded.snapshot
            }),
            _ => None,
        };
        // What the robot may have accepted after its snapshot is never accepted again.
        let journal_path = JournalFile::path_in(Path::new(&persistence.directory), &robot_name);
        if let Some(snapshot) = &mut snapshot {
            match sgm_actors::journal::apply(snapshot, &journal_path) {
                Ok(0) => tracing::warn!(robot = %robot_name, path = %journal_path.display(),
                    "no replay journal beside the snapshot: envelopes accepted after it could be replayed once"),
                Ok(n) => tracing::info!(robot = %robot_name, windows = n,
                    "replay windows raised to the journal's reservations"),
                Err(e) => tracing::warn!(robot = %robot_name,
                    "replay journal unusable ({e}): envelopes accepted after the snapshot could be replayed once"),
            }
        }
        // Sequence numbers must never repeat, whatever the clock did across a restart: every
        // start is a new incarnation, drawn at random (`sgm_model::wire::replay`).
        let incarnation = random_incarnation();
        tracing::info!(robot = %robot_name, incarnation = format!("{incarnation:#08x}"), "incarnation");
        let mut comms_addr = None;
        let attach = |_, comms| comms_addr = Some(comms);
        let handle = start_robot_restored(
            &config.robot,
            Clock::starting_at(0.0),
            Box::new(transport),
            attach,
            snapshot,
            Sequence::first(incarnation),
        )
        .map_err(NodeError::Config)?;
        let Some(comms) = comms_addr else { return Err(ros_error("the robot's Comms did not start")) };
        if store.is_some() {
            let journal = JournalFile::start(Path::new(&persistence.directory), &robot_name);
            comms.do_send(AttachJournal(Arc::new(journal)));
        }
        let intake = Arc::new(Intake::new(handle.clone()));

        // Inter-robot traffic in: the team topic (others' broadcasts) and our Deliver service.
        let team_in = {
            let (intake, counts, peers) = (intake.clone(), counts.clone(), peers.clone());
            rosrust::subscribe(&ros.topics.team, ros.queue_size.max(64), move |m: Bounded<sgm_msgs::Envelope>| {
                let m = m.0;
                if m.from_robot != id {
                    counts.received.fetch_add(1, Ordering::Relaxed);
                    peers.heard(sgm_model::scene_graph::RobotId(m.from_robot));
                    intake.envelope(m.data);
                }
            })
            .map_err(ros_error)?
        };
        let deliver_name = RosConfig::resolve(&ros.topics.deliver, &robot_name, id);
        let deliver = {
            let (intake, counts, peers) = (intake.clone(), counts.clone(), peers.clone());
            rosrust::service::<BoundedDeliver, _>(&deliver_name, move |request: BoundedDeliverReq| {
                counts.received.fetch_add(1, Ordering::Relaxed);
                peers.heard(sgm_model::scene_graph::RobotId(request.0.from_robot));
                intake.envelope(request.0.data);
                // Authentication and decoding happen in Comms; receipt is all we can vouch for.
                Ok(BoundedDeliverRes(sgm_msgs::DeliverRes { accepted: true, reason: String::new() }))
            })
            .map_err(ros_error)?
        };

        let colours = config.robot.colour_ids().map_err(NodeError::Config)?;
        for (rgb, ids) in colours.ambiguous() {
            tracing::info!(robot = %robot_name, colour = %sgm_model::perception::colour_ids::hex(*rgb), ?ids,
                "colour label images: this colour paints several classes of the segmenter's palette and reads as \
                 the first; set it in [classes.palette] to choose");
        }
        let inputs = Inputs::new(&ros, &robot_name, id).with_colours(colours);
        let side = Arc::new(SensorSide {
            sync: Mutex::new(Synchroniser::for_robot(&ros, &inputs).map_err(NodeError::Ros)?),
            inputs,
            counts: InputCounts::new(&["points", "labels", "camera_info", "odometry", "clock", "tf", "tf_static"]),
            intake: intake.clone(),
            epoch: Epoch { sec: 0 },
        });
        let q = ros.queue_size;
        let t = &ros.topics;
        let points = subscribe(&t.points, q, &side, "points", Inputs::cloud)?;
        let labels = subscribe(&t.labels, q, &side, "labels", Inputs::image)?;
        let camera_info = subscribe(&t.camera_info, q, &side, "camera_info", Inputs::camera_info)?;
        let odometry = subscribe(&t.odometry, q, &side, "odometry", Inputs::odometry)?;
        // tf: the sensors' mounts when [ros] does not pin them, and tf's view of the odometry.
        let tf = if ros.tf.listen {
            let dynamic = subscribe(&ros.tf.topic, q.max(100), &side, "tf", |i, m| i.tf(m, false))?;
            let fixed = subscribe(&ros.tf.static_topic, q.max(100), &side, "tf_static", |i, m| i.tf(m, true))?;
            Some((dynamic, fixed))
        } else {
            None
        };
        // Simulated time (`rosbag play --clock`, a simulator): /clock moves the robot's clock
        // between sensor frames too, through the same timeline checks as the sensors' stamps.
        let sim_time = rosrust::param("/use_sim_time").and_then(|p| p.get::<bool>().ok()).unwrap_or(false);
        let clock = if sim_time {
            tracing::info!(robot = %robot_name, "use_sim_time: following /clock");
            Some(subscribe(&t.clock, 1, &side, "clock", |_, m: &rosgraph_msgs::Clock| Ok(Payload::Clock(m.clock)))?)
        } else {
            None
        };

        let publishers = Publishers::advertise(&ros).map_err(ros_error)?;
        let world_frames = WorldFrames::new(&ros);
        register_world_frame(id, side.inputs.world_frame(), world_frames.clone());
        tracing::info!(robot = %robot_name, id, service = %deliver_name, "sgm node up");
        let world_frame = side.inputs.world_frame().to_string();
        let mut health = crate::health::Health::new(ros.health.clone());
        let mut since_publish = Duration::ZERO;
        let tick = Duration::from_millis(100);
        let publish_every = Duration::from_secs_f64(ros.publish_interval_s);
        let mut seq = 0u32;
        let mut last_snapshot = handle.clock.now();
        let mut snapshots = store.clone().map(Snapshots::new);
        let mut body_published: Option<sgm_model::scene_graph::Stamp> = None;
        let mut failures = PublishFailures::default();
        while rosrust::is_ok() {
            actix_rt::time::sleep(tick).await;
            handle.supervisor.do_send(Tick { now: handle.clock.now() });
            // The body in the world, from the odometry, for the team's tf tree (the odometry's
            // own tf may be remapped away, or name frames every robot shares).
            if ros.publish_body_tf {
                let latest = side.sync().latest_odometry();
                if let Some((t, world_from_body)) = latest.filter(|(t, _)| body_published != Some(*t)) {
                    body_published = Some(t);
                    let transform = crate::msg::geometry_msgs::TransformStamped {
                        header: std_msgs::Header { seq: 0, stamp: side.ros_time(t), frame_id: world_frame.clone() },
                        child_frame_id: side.inputs.body_frame().to_string(),
                        transform: crate::convert::geometry::transform_msg(&world_from_body),
                    };
                    failures.check("tf", publishers.tf.send(tf2_msgs::TFMessage { transforms: vec![transform] }));
                }
            }
            if let Some(snapshots) = &mut snapshots {
                if handle.clock.now() - last_snapshot >= persistence.interval_s {
                    last_snapshot = handle.clock.now();
                    snapshots.take(&handle, &intake).await;
                }
            }
            since_publish += tick;
            if since_publish < publish_every {
                continue;
            }
            since_publish = Duration::ZERO;
            seq = seq.wrapping_add(1);
            let header =
                std_msgs::Header { seq, stamp: side.ros_time(handle.clock.now()), frame_id: world_frame.clone() };
            let (Ok(map), Ok(neighbours), Ok(comms_status), Ok(fusion_status)) = (
                handle.tracker.send(GetMapSummary).await,
                handle.matcher.send(GetNeighbours).await,
                handle.comms.send(GetCommsStatus).await,
                handle.fusion.send(GetFusionStatus).await,
            ) else {
                continue;
            };
            failures.check("markers", publishers.markers.send(map_markers(&header, &map, &classes)));
            failures.check("path", publishers.path.send(keyframe_path(&header, &map, |t| side.ros_time(t))));
            let own = sgm_model::scene_graph::RobotId(id);
            if let Some(transform) = team_transform(&header, own, &neighbours, &world_frames) {
                failures.check("tf", publishers.tf.send(tf2_msgs::TFMessage { transforms: vec![transform] }));
            }
            if publishers.map.subscriber_count() > 0 {
                if let Ok(graph) = handle.tracker.send(GetSceneGraph).await {
                    let map = semantic_map(&header, &[(&graph, Pose3::identity())], &classes, ros.map_voxel_m);
                    failures.check("map", publishers.map.send(map));
                }
            }
            let (sync_counts, timeline, tf_status, missing_mount) = {
                let sync = side.sync();
                (sync.counts.clone(), sync.timeline().clone(), sync.tf(), sync.missing_mount())
            };
            let confirmed = map.objects.iter().filter(|o| o.confirmed).count();
            let inputs = side.counts.tallies();
            let findings = health.update(
                handle.clock.now(),
                &crate::health::Observed {
                    sync: &sync_counts,
                    inputs: &inputs,
                    tf: &tf_status,
                    missing_mount: missing_mount.as_deref(),
                    objects: Some(confirmed),
                },
            );
            let status = serde_json::json!({
                "robot": robot_name,
                "id": id,
                "stamp": handle.clock.now(),
                "keyframes": map.keyframes.len(),
                "objects": map.objects.len(),
                "accepted": InputCounts::snapshot(&side.counts.accepted),
                "refused": InputCounts::snapshot(&side.counts.refused),
                "sync": sync_counts,
                "timeline": timeline,
                "tf": tf_status,
                "health": findings,
                "latency_ms": side.intake.latency(),
                "held_dropped": side.intake.dropped.load(Ordering::Relaxed),
                "transport": crate::transport::status(&counts, &peers),
                "publish_failures": &failures.0,
                "comms": comms_status,
                "fusion": fusion_status,
                "neighbours": neighbours.iter().map(|n| serde_json::json!({
                    "robot": n.robot.0,
                    "state": n.state,
                    "first_aligned": n.first_aligned,
                    "local_from_remote": n.local_from_remote.map(|p| {
                        let (t, q) = (p.translation.vector, p.rotation.quaternion());
                        [t.x, t.y, t.z, q.i, q.j, q.k, q.w]
                    }),
                })).collect::<Vec<_>>(),
            });
            failures.check("status", publishers.status.send(std_msgs::String { data: status.to_string() }));
        }
        drop((team_in, deliver, points, labels, camera_info, odometry, clock, tf));
        // Shutdown (SIGINT, rosnode kill): one last snapshot.
        if let Some(snapshots) = &mut snapshots {
            snapshots.take(&handle, &intake).await;
            snapshots.finish();
        }
        Ok(())
    })
}

/// Registers this robot's world frame on the master (`/sgm/world_frames/robot_{id}`) and keeps
/// `frames` up to date with the team's registrations, on a thread of its own (the master's
/// parameter calls block), every 5 s while the node runs.
fn register_world_frame(id: u16, world_frame: &str, frames: WorldFrames) {
    let (name, frame) = (world_frame_param(id), world_frame.to_string());
    let spawned = std::thread::Builder::new().name("sgm-world-frames".into()).spawn(move || {
        match rosrust::param(&name) {
            Some(param) => {
                if let Ok(existing) = param.get::<String>() {
                    if existing != frame {
                        tracing::warn!(param = %name, existing, frame,
                            "another world frame was registered for this robot id: a second robot with this id, \
                             or this robot started before with another ros.frames.world; taking it over");
                    }
                }
                if let Err(e) = param.set(&frame) {
                    tracing::warn!(param = %name, "world frame not registered on the master: {e}");
                }
            }
            None => tracing::warn!(param = %name, "world frame not registered: not a valid parameter name"),
        }
        while rosrust::is_ok() {
            if let Some(Ok(registered)) =
                rosrust::param("/sgm/world_frames").map(|p| p.get::<BTreeMap<String, String>>())
            {
                frames.update(&registered);
            }
            std::thread::sleep(Duration::from_secs(5));
        }
    });
    if let Err(e) = spawned {
        tracing::warn!("world frames not followed (no thread: {e}): neighbours' worlds are named robot_ID");
    }
}

/// A random, non-zero incarnation (0 is simulation's): std's `RandomState` keys come from the
/// operating system's entropy, different in every process.
fn random_incarnation() -> u32 {
    use std::hash::{BuildHasher, Hasher};
    let bits = std::collections::hash_map::RandomState::new().build_hasher().finish();
    let incarnation = (bits as u32) & ((1 << sgm_model::wire::replay::INCARNATION_BITS) - 1);
    incarnation.max(1)
}

/// Publications rosrust did not take (a publisher shut down, or a message it could not
/// serialise), per output: counted in the status (`publish_failures`) and logged once per output.
#[derive(Default)]
struct PublishFailures(std::collections::BTreeMap<&'static str, u64>);

impl PublishFailures {
    fn check<E: std::fmt::Display>(&mut self, output: &'static str, sent: Result<(), E>) {
        if let Err(e) = sent {
            let n = self.0.entry(output).or_default();
            *n += 1;
            if *n == 1 {
                tracing::warn!(
                    output,
                    "publishing failed: {e} (further failures counted in the status's publish_failures)"
                );
            }
        }
    }
}

struct Publishers {
    markers: rosrust::Publisher<visualization_msgs::MarkerArray>,
    path: rosrust::Publisher<nav_msgs::Path>,
    map: rosrust::Publisher<sensor_msgs::PointCloud2>,
    status: rosrust::Publisher<std_msgs::String>,
    tf: rosrust::Publisher<tf2_msgs::TFMessage>,
}

impl Publishers {
    fn advertise(ros: &RosConfig) -> Result<Self, rosrust::error::Error> {
        let q = ros.queue_size;
        let mut markers = rosrust::publish(&ros.topics.markers, q)?;
        let mut path = rosrust::publish(&ros.topics.path, q)?;
        let mut status = rosrust::publish(&ros.topics.status, q)?;
        // Latched: a late `rostopic echo` or RViz sees the latest at once.
        markers.set_latching(true);
        path.set_latching(true);
        status.set_latching(true);
        Ok(Self {
            markers,
            path,
            map: rosrust::publish(&ros.topics.map, q)?,
            status,
            tf: rosrust::publish(&ros.topics.tf, q)?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn publish_failures_are_counted_per_output() {
        let mut failures = PublishFailures::default();
        failures.check("markers", Ok::<(), String>(()));
        assert!(failures.0.is_empty(), "a publication taken is no failure");
        for _ in 0..3 {
            failures.check("map", Err("publisher shut down"));
        }
        failures.check("status", Err("publisher shut down"));
        assert_eq!(failures.0.get("map"), Some(&3));
        assert_eq!(failures.0.get("status"), Some(&1));
        assert_eq!(serde_json::json!({ "publish_failures": &failures.0 })["publish_failures"]["map"], 3);
    }

    /// `NodeConfig` flattens `RobotConfig`: a node's file sets `[classes]` beside `[ros]`, and a
    /// wrong entry is refused by name.
    #[test]
    fn a_node_file_sets_classes() {
        let file = tempfile::Builder::new().suffix(".toml").tempfile().unwrap();
        let text = "[classes]\nsegmenter = \"ade20k_150\"\n[classes.map]\nchair = [\"chair\", 30]\n[ros]\nlabels = \"image\"\n";
        std::fs::write(file.path(), text).unwrap();
        let config = NodeConfig::load(Some(file.path())).unwrap();
        assert_eq!(config.robot.classes.segmenter, "ade20k_150");
        assert_eq!(config.robot.classes.map["chair"].len(), 2);
        std::fs::write(file.path(), "[classes]\nsegmenter = \"ade20k_150\"\n[classes.map]\nsofa = [23]\n").unwrap();
        let error = NodeConfig::load(Some(file.path())).unwrap_err().to_string();
        assert!(error.contains("classes.map.sofa: no class \"sofa\" in fusion.classes"), "{error}");
    }

    /// Frame aliases keep their case and slashes (config's keys are frame ids, not identifiers).
    #[test]
    fn frame_aliases_keep_their_names() {
        let file = tempfile::Builder::new().suffix(".toml").tempfile().unwrap();
        let text = "[ros.frames.aliases]\ncamera_init = \"{robot}/odom\"\n\"Livox_Frame\" = \"{robot}/livox\"\n";
        std::fs::write(file.path(), text).unwrap();
        let config = NodeConfig::load(Some(file.path())).unwrap();
        let inputs = Inputs::new(&config.ros, "alpha", 1);
        assert_eq!(inputs.frame("camera_init"), "alpha/odom");
        assert_eq!(inputs.frame("/Livox_Frame"), "alpha/livox");
        assert_eq!(inputs.frame("body"), "body");
    }
}
