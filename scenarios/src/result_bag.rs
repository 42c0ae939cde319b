//! The team's result as a ROS 1 bag (`result.bag` in the report directory of `sgm run` and
//! `sgm replay`), in the messages the live node publishes, so that RViz (the ROS package's
//! `rviz/team.rviz`) and Foxglove open it as it is:
//!
//! - at every observation (`scenario.report_interval_s`), per robot: `/ROBOT/sgm/markers`
//!   (objects as boxes and labels in their class colours, the keyframe trajectory and
//!   object → keyframe edges), `/ROBOT/sgm/path`, and on `/tf` the team's tree of worlds
//!   ([`sgm_bridge::team_frames`]) and each robot's body at its newest keyframe;
//! - at the end: `/ROBOT/sgm/map`, each robot's semantic map, and `/sgm/team_map`, every
//!   robot's map merged into the first robot's world by its estimates (as the report's
//!   `map.pcd`), one point per `ros.map_voxel_m` voxel (0.25 m).
//!
//! Frames are the `[ros]` section's (`{robot}/odom`, `{robot}/base_link` by default), stamps
//! the mission's clock from `epoch`.

use crate::observation::Observation;
use crate::output_error::OutputError;
use sgm_bridge::bag::writer::BagWriter;
use sgm_bridge::config::RosConfig;
use sgm_bridge::convert::cloud::voxels_msg;
use sgm_bridge::convert::geometry::transform_msg;
use sgm_bridge::convert::markers::{keyframe_path, map_markers};
use sgm_bridge::convert::time::Epoch;
use sgm_bridge::msg::geometry_msgs::TransformStamped;
use sgm_bridge::msg::std_msgs::Header;
use sgm_bridge::msg::tf2_msgs::TFMessage;
use sgm_bridge::team_frames::{team_transform, WorldFrames};
use sgm_model::geometry::Pose3;
use sgm_model::perception::classes::ClassTable;
use sgm_model::scene_graph::{LabelledVoxels, RobotId, SceneGraph};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The team map's topic.
pub const TEAM_MAP_TOPIC: &str = "/sgm/team_map";

pub struct ResultBag {
    writer: BagWriter,
    path: PathBuf,
    names: Vec<String>,
    worlds: Vec<String>,
    bodies: Vec<String>,
    frames: WorldFrames,
    classes: ClassTable,
    epoch: Epoch,
    topics: [String; 3],
    /// `ros.map_voxel_m`: one point of the maps per voxel.
    map_voxel_m: f64,
}

impl ResultBag {
    /// Opens `path` for the team `names` (robot k has id k + 1), framed by `ros`, coloured by
    /// `classes`, stamped from `epoch`.
    pub fn create(
        path: &Path,
        names: &[String],
        ros: &RosConfig,
        classes: ClassTable,
        epoch: Epoch,
    ) -> Result<Self, OutputError> {
        let writer = BagWriter::create(path).map_err(OutputError::at(path))?;
        let id = |k: usize| RobotId::from_index(k).0;
        let worlds: Vec<String> =
            names.iter().enumerate().map(|(k, n)| RosConfig::resolve(&ros.frames.world, n, id(k))).collect();
        let bodies = names.iter().enumerate().map(|(k, n)| RosConfig::resolve(&ros.frames.body, n, id(k))).collect();
        let frames = WorldFrames::new(ros);
        let registered: BTreeMap<String, String> =
            worlds.iter().enumerate().map(|(k, w)| (format!("robot_{}", id(k)), w.clone())).collect();
        frames.update(&registered);
        let absolute = |template: &str| {
            let t = template.trim_start_matches('/');
            format!("/{{robot}}/{t}")
        };
        Ok(Self {
            writer,
            path: path.to_path_buf(),
            names: names.to_vec(),
            worlds,
            bodies,
            frames,
            classes,
            epoch,
            topics: [absolute(&ros.topics.markers), absolute(&ros.topics.path), absolute(&ros.topics.map)],
            map_voxel_m: ros.map_voxel_m,
        })
    }

    fn topic(&self, which: usize, k: usize) -> String {
        self.topics[which].replace("{robot}", &self.names[k])
    }

    fn io(&self, source: std::io::Error) -> OutputError {
        OutputError { path: self.path.clone(), source }
    }

    /// Writes what observation `o` shows: markers, paths, the team's tf.
    pub fn observe(&mut self, o: &Observation) -> Result<(), OutputError> {
        let time = self.epoch.time(o.t);
        let mut tf = TFMessage { transforms: Vec::new() };
        for (k, entry) in o.maps.iter().enumerate() {
            let Some((map, neighbours, _)) = entry else { continue };
            let header = Header { seq: 0, stamp: time, frame_id: self.worlds[k].clone() };
            let (markers, path) = (self.topic(0, k), self.topic(1, k));
            self.writer.write(&markers, time, &map_markers(&header, map, &self.classes)).map_err(|e| self.io(e))?;
            let epoch = self.epoch;
            self.writer.write(&path, time, &keyframe_path(&header, map, |t| epoch.time(t))).map_err(|e| self.io(e))?;
            if let Some(newest) = map.keyframes.last() {
                tf.transforms.push(TransformStamped {
                    header: header.clone(),
                    child_frame_id: self.bodies[k].clone(),
                    transform: transform_msg(&newest.world_from_body),
                });
            }
            tf.transforms.extend(team_transform(&header, RobotId::from_index(k), neighbours, &self.frames));
        }
        if !tf.transforms.is_empty() {
            self.writer.write("/tf", time, &tf).map_err(|e| self.io(e))?;
        }
        Ok(())
    }

    /// Writes the maps at the end (`last` places each robot's map in the first robot's world)
    /// and closes the bag; returns its path.
    pub fn finish(mut self, maps: &[SceneGraph], last: &Observation) -> Result<PathBuf, OutputError> {
        let time = self.epoch.time(last.t);
        // The team map from the robots' voxels (each keyframe point is voxelised once).
        let mut team = LabelledVoxels::new(self.map_voxel_m);
        for (k, map) in maps.iter().enumerate() {
            let mut voxels = LabelledVoxels::new(self.map_voxel_m);
            voxels.insert_graph(map, &Pose3::identity());
            let header = Header { seq: 0, stamp: time, frame_id: self.worlds[k].clone() };
            let topic = self.topic(2, k);
            self.writer.write(&topic, time, &voxels_msg(&header, &voxels, &self.classes)).map_err(|e| self.io(e))?;
            if let Some(first_from_robot) = crate::report::reference_from(last, k) {
                for (p, label) in voxels.points() {
                    team.insert(first_from_robot * p, label);
                }
            }
        }
        if let Some(first) = self.worlds.first() {
            let header = Header { seq: 0, stamp: time, frame_id: first.clone() };
            self.writer
                .write(TEAM_MAP_TOPIC, time, &voxels_msg(&header, &team, &self.classes))
                .map_err(|e| self.io(e))?;
        }
        let path = self.path.clone();
        self.writer.finish().map_err(OutputError::at(&path))?;
        Ok(path)
    }
}
