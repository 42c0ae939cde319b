//! `sgm ros`: one robot as a ROS 1 node. Sensor topics in (checked by [`Inputs`], assembled by the
//! [`Synchroniser`]), the robot's actor tree in the middle, RViz-ready outputs and the inter-robot
//! [`RosTransport`] out. Names come from the `[ros]` section and resolve in the node's namespace;
//! rosrust honours `ROS_MASTER_URI`, `ROS_IP`/`ROS_HOSTNAME`, `ROS_NAMESPACE`, `__name:=`, `__ns:=`
//! and `from:=to` remappings on the command line.
//!
//! The robot's clock is the newest sensor stamp (ROS time, seconds since 1970): the node runs
//! the same whether its sensors are live or a bag played at any rate. Handlers never read the
//! wall clock; only the tick and publish loop waits on it.
//!
//! The node's configuration file (`config.rs`: [`NodeConfig`]) and its errors (`error.rs`:
//! [`NodeError`]); the team key refused unless public keys are allowed (`team_key.rs`); the
//! sensor side, inputs checked, counted and fed to the synchroniser (`sensors.rs`); the outputs
//! and their publication failures (`outputs.rs`); this robot's world frame registered on the
//! master (`world_frames.rs`); and the node itself, started and ticked (here: [`run`]).

mod config;
mod error;
mod odometry_out;
mod outputs;
mod sensors;
mod suspects;
mod team_key;
mod world_frames;

pub use config::NodeConfig;
pub use error::NodeError;
pub use team_key::{check_team_key, PublicKeys};

use crate::bounded::Bounded;
use crate::bounded_deliver::{BoundedDeliver, BoundedDeliverReq, BoundedDeliverRes};
use crate::config::RosConfig;
use crate::convert::cloud::semantic_map;
use crate::convert::markers::{keyframe_path, map_markers};
use crate::convert::time::Epoch;
use crate::inputs::{Inputs, Payload};
use crate::msg::{rosgraph_msgs, sgm_msgs, std_msgs, tf2_msgs};
use crate::persist::{Intake, Snapshots};
use crate::sync::Synchroniser;
use crate::team_frames::{team_transform, WorldFrames};
use crate::transport::peers::MasterLocator;
use crate::transport::{RosTransport, TransportCounts};
use actix::Actor;
use error::ros_error;
use odometry_out::{OdometryOutCounts, OdometryPublisher};
use outputs::{PublishFailures, Publishers};
use sensors::{subscribe, InputCounts, SensorSide};
use sgm_actors::clock::Clock;
use sgm_actors::comms::AttachJournal;
use sgm_actors::comms::GetCommsStatus;
use sgm_actors::config::OdometrySource;
use sgm_actors::fusion::GetFusionStatus;
use sgm_actors::journal::JournalFile;
use sgm_actors::matcher::GetNeighbours;
use sgm_actors::messages::Tick;
use sgm_actors::odometry::{AttachOdometryOutput, GetOdometryStatus};
use sgm_actors::snapshot::SnapshotStore;
use sgm_actors::supervisor::start_robot_restored;
use sgm_actors::tracker::{GetMapSummary, GetSceneGraph};
use sgm_model::geometry::Pose3;
use sgm_model::perception::classes::ClassTable;
use sgm_model::wire::Sequence;
use sgm_model::workers::Workers;
use std::path::Path;
use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex};
use std::time::Duration;
use world_frames::register_world_frame;

/// Runs robot `config` as a ROS node until ROS shuts down (SIGINT, `rosnode kill`); a public
/// team key is refused unless `public` allows it ([`check_team_key`]).
pub fn run(config: NodeConfig, public: PublicKeys) -> Result<(), NodeError> {
    check_team_key(&config.robot, public)?;
    let robot_name = config.robot.robot.name.clone();
    let id = config.robot.robot.id;
    rosrust::try_init(&format!("sgm_{robot_name}")).map_err(ros_error)?;
    let ros = config.ros.clone();
    crate::bounded::set_max_message_bytes(ros.max_message_bytes);
    let classes = ClassTable::new(config.robot.fusion.classes.clone()).map_err(NodeError::Classes)?;
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
            match sgm_actors::journal::apply(&mut snapshot.comms.replay, &journal_path) {
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
            Workers::sequential(),
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
        // The robot's own odometry reads the IMU instead of an odometry topic.
        let source = config.robot.odometry.source;
        let internal = source == OdometrySource::Internal;
        let motion = if internal { "imu" } else { "odometry" };
        let side = Arc::new(SensorSide {
            sync: Mutex::new(Synchroniser::for_robot(&ros, &inputs, source).map_err(NodeError::Ros)?),
            inputs,
            counts: InputCounts::new(&["points", "labels", "camera_info", motion, "clock", "tf", "tf_static"]),
            intake: intake.clone(),
            epoch: Epoch { sec: 0 },
        });
        let q = ros.queue_size;
        let t = &ros.topics;
        let points = subscribe(&t.points, q, &side, "points", Inputs::cloud)?;
        let labels = subscribe(&t.labels, q, &side, "labels", Inputs::image)?;
        let camera_info = subscribe(&t.camera_info, q, &side, "camera_info", Inputs::camera_info)?;
        let motion = if internal {
            // 200 Hz and more: a queue of at least a second's samples.
            subscribe(&t.imu, q.max(400), &side, "imu", Inputs::imu)?
        } else {
            subscribe(&t.odometry, q, &side, "odometry", Inputs::odometry)?
        };
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
        // The robot's own odometry out: nav_msgs/Odometry and world → body on tf.
        let odometry_out = Arc::new(OdometryOutCounts::default());
        if let Some(odometry) = &handle.odometry {
            let publisher = OdometryPublisher {
                side: side.clone(),
                odometry: rosrust::publish(&t.odometry_out, q.max(100)).map_err(ros_error)?,
                tf: rosrust::publish(&t.tf, q.max(100)).map_err(ros_error)?,
                world_frame: side.inputs.world_frame().to_string(),
                body_frame: side.inputs.body_frame().to_string(),
                counts: odometry_out.clone(),
            };
            odometry.do_send(AttachOdometryOutput(publisher.start().recipient()));
        }
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
        let mut suspects = suspects::Suspects::default();
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
            let odometry_status = match &handle.odometry {
                Some(odometry) => odometry.send(GetOdometryStatus).await.ok(),
                None => None,
            };
            let (Ok(map), Ok(neighbours), Ok(comms_status), Ok(fusion_status), Ok(pose_graph)) = (
                handle.tracker.send(GetMapSummary).await,
                handle.matcher.send(GetNeighbours).await,
                handle.comms.send(GetCommsStatus).await,
                handle.fusion.send(GetFusionStatus).await,
                handle.optimiser.send(sgm_actors::optimiser::GetOptimiserStatus).await,
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
            let suspect = suspects.judge(&robot_name, &neighbours, &pose_graph.graph);
            let status = serde_json::json!({
                "robot": robot_name,
                "id": id,
                "stamp": handle.clock.now(),
                "keyframes": map.keyframes.len(),
                "objects": map.objects.len(),
                "moving_objects": map.moving_objects,
                "merged_objects": map.merged_objects,
                "expired_objects": map.expired_objects,
                "glimpse_sightings": map.glimpse_sightings,
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
                "odometry": odometry_status,
                "odometry_out": internal.then(|| odometry_out.snapshot()),
                "pose_graph": pose_graph,
                "neighbours": neighbours.iter().map(|n| serde_json::json!({
                    "robot": n.robot.0,
                    "state": n.state,
                    "first_aligned": n.first_aligned,
                    "aligned_via": n.aligned_via.map(|r| r.0),
                    "contradicted_by": n.contradicted_by.iter().map(|r| r.0).collect::<Vec<_>>(),
                    "withdrawals": n.withdrawals,
                    "last_withdrawal": n.last_withdrawal,
                    "suspect": suspect.get(&n.robot),
                    "closures": n.closures,
                    "match_attempts": n.match_attempts,
                    "local_from_remote": n.local_from_remote.map(|p| {
                        let (t, q) = (p.translation.vector, p.rotation.quaternion());
                        [t.x, t.y, t.z, q.i, q.j, q.k, q.w]
                    }),
                })).collect::<Vec<_>>(),
            });
            failures.check("status", publishers.status.send(std_msgs::String { data: status.to_string() }));
        }
        drop((team_in, deliver, points, labels, camera_info, motion, clock, tf));
        // Shutdown (SIGINT, rosnode kill): one last snapshot.
        if let Some(snapshots) = &mut snapshots {
            snapshots.take(&handle, &intake).await;
            snapshots.finish();
        }
        Ok(())
    })
}

/// A random, non-zero incarnation (0 is simulation's): std's `RandomState` keys come from the
/// operating system's entropy, different in every process.
fn random_incarnation() -> u32 {
    use std::hash::{BuildHasher, Hasher};
    let bits = std::collections::hash_map::RandomState::new().build_hasher().finish();
    let incarnation = (bits as u32) & ((1 << sgm_model::wire::replay::INCARNATION_BITS) - 1);
    incarnation.max(1)
}
