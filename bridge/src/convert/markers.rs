//! What a robot shows in RViz: its objects as boxes coloured by class with text labels, the
//! scene graph's edges (keyframe trajectory, object → anchor keyframe), its keyframe path, and
//! the tf of every aligned neighbour's world.

use crate::convert::geometry::pose_msg;
use crate::msg::{geometry_msgs, nav_msgs, std_msgs, visualization_msgs::Marker, visualization_msgs::MarkerArray};
use sgm_actors::tracker::MapSummary;
use sgm_model::geometry::Pose3;
use sgm_model::perception::classes::ClassTable;
use std::collections::BTreeMap;

const CUBE: i32 = 1;
const LINE_STRIP: i32 = 4;
const LINE_LIST: i32 = 5;
const TEXT_VIEW_FACING: i32 = 9;
const DELETEALL: i32 = 3;

fn colour([r, g, b]: [u8; 3], a: f32) -> std_msgs::ColorRGBA {
    std_msgs::ColorRGBA { r: f32::from(r) / 255.0, g: f32::from(g) / 255.0, b: f32::from(b) / 255.0, a }
}

fn point(p: &nalgebra::Point3<f64>) -> geometry_msgs::Point {
    geometry_msgs::Point { x: p.x, y: p.y, z: p.z }
}

fn marker(header: &std_msgs::Header, ns: &str, id: i32, kind: i32) -> Marker {
    let mut m = Marker { header: header.clone(), ns: ns.into(), id, type_: kind, action: 0, ..Default::default() };
    m.pose.orientation.w = 1.0;
    m
}

/// The map as markers in `header.frame_id`: a DELETEALL first (objects merge and vanish),
/// then per object a box (`objects`, confirmed opaque, tentative translucent) and its class
/// name (`labels`), then the edges (`keyframes`, `anchors`).
pub fn map_markers(header: &std_msgs::Header, map: &MapSummary, classes: &ClassTable) -> MarkerArray {
    let mut markers = vec![Marker { header: header.clone(), action: DELETEALL, ..Default::default() }];
    for o in &map.objects {
        let class = classes.get(o.label);
        let rgb = class.map_or([128, 128, 128], |c| c.colour);
        let id = o.id.0 as i32;
        let mut cube = marker(header, "objects", id, CUBE);
        cube.pose = pose_msg(&Pose3::translation(o.centroid.x, o.centroid.y, o.centroid.z));
        cube.scale = geometry_msgs::Vector3 { x: o.size.x.max(0.05), y: o.size.y.max(0.05), z: o.size.z.max(0.05) };
        cube.color = colour(rgb, if o.confirmed { 0.9 } else { 0.35 });
        markers.push(cube);
        let mut text = marker(header, "labels", id, TEXT_VIEW_FACING);
        text.pose.position = point(&(o.centroid + nalgebra::Vector3::new(0.0, 0.0, o.size.z / 2.0 + 0.4)));
        text.scale.z = 0.6;
        text.color = colour([255, 255, 255], 1.0);
        text.text = match class {
            Some(c) => format!("{} {}", c.name, o.id),
            None => format!("label {} {}", o.label.0, o.id),
        };
        markers.push(text);
    }
    let mut trajectory = marker(header, "keyframes", 0, LINE_STRIP);
    trajectory.scale.x = 0.1;
    trajectory.color = colour([40, 120, 255], 1.0);
    trajectory.points = map.keyframes.iter().map(|k| point(&k.world_from_body.translation.vector.into())).collect();
    let positions: BTreeMap<_, _> =
        map.keyframes.iter().map(|k| (k.id, k.world_from_body.translation.vector)).collect();
    let mut anchors = marker(header, "anchors", 0, LINE_LIST);
    anchors.scale.x = 0.03;
    anchors.color = colour([200, 200, 200], 0.5);
    for o in &map.objects {
        if let Some(k) = positions.get(&o.anchor) {
            anchors.points.push(point(&(*k).into()));
            anchors.points.push(point(&o.centroid));
        }
    }
    if trajectory.points.len() >= 2 {
        markers.push(trajectory);
    }
    if !anchors.points.is_empty() {
        markers.push(anchors);
    }
    MarkerArray { markers }
}

/// The keyframe trajectory as a path in `header.frame_id`.
pub fn keyframe_path(
    header: &std_msgs::Header,
    map: &MapSummary,
    time_of: impl Fn(f64) -> rosrust::Time,
) -> nav_msgs::Path {
    let poses = map
        .keyframes
        .iter()
        .map(|k| geometry_msgs::PoseStamped {
            header: std_msgs::Header { seq: 0, stamp: time_of(k.stamp), frame_id: header.frame_id.clone() },
            pose: pose_msg(&k.world_from_body),
        })
        .collect();
    nav_msgs::Path { header: header.clone(), poses }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Point3, Vector3};
    use sgm_actors::tracker::MapObject;
    use sgm_model::scene_graph::{Keyframe, KeyframeId, LabelId, ObjectId};

    #[test]
    fn objects_become_boxes_labels_and_edges() {
        let classes = ClassTable::new(sgm_actors::config::default_classes()).unwrap();
        let tree = classes.classes().iter().find(|c| c.name == "tree").unwrap();
        let keyframe = |id, x| Keyframe {
            id: KeyframeId(id),
            stamp: f64::from(id),
            world_from_body: Pose3::translation(x, 0.0, 0.0),
        };
        let map = MapSummary {
            keyframes: vec![keyframe(0, 0.0), keyframe(1, 2.0)],
            objects: vec![MapObject {
                id: ObjectId(7),
                label: LabelId(tree.id),
                centroid: Point3::new(3.0, 4.0, 2.0),
                size: Vector3::new(1.0, 1.0, 4.0),
                anchor: KeyframeId(1),
                confirmed: true,
            }],
            clouds: Default::default(),
            moving_objects: 0,
            merged_objects: 0,
            expired_objects: 0,
            glimpse_sightings: 0,
        };
        let header = std_msgs::Header { frame_id: "alpha/odom".into(), ..Default::default() };
        let array = map_markers(&header, &map, &classes);
        let kinds: Vec<(String, i32, i32)> = array.markers.iter().map(|m| (m.ns.clone(), m.type_, m.action)).collect();
        assert_eq!(
            kinds,
            vec![
                (String::new(), 0, DELETEALL),
                ("objects".into(), CUBE, 0),
                ("labels".into(), TEXT_VIEW_FACING, 0),
                ("keyframes".into(), LINE_STRIP, 0),
                ("anchors".into(), LINE_LIST, 0),
            ]
        );
        let cube = &array.markers[1];
        assert_eq!((cube.id, cube.pose.position.x, cube.pose.position.y, cube.scale.z), (7, 3.0, 4.0, 4.0));
        assert_eq!(cube.color.r, f32::from(tree.colour[0]) / 255.0);
        assert_eq!(array.markers[2].text, "tree obj7");
        assert_eq!(array.markers[4].points[0].x, 2.0);
        assert_eq!(array.markers[4].points[1].y, 4.0);

        let path = keyframe_path(&header, &map, |t| rosrust::Time { sec: t as u32, nsec: 0 });
        assert_eq!(path.poses.len(), 2);
        assert_eq!((path.poses[1].pose.position.x, path.poses[1].header.stamp.sec), (2.0, 1));
    }
}
