//! A tf tree as tf2 keeps it: every frame has at most one parent, and an edge holds
//! `parent_from_child` (a transform's `header.frame_id` is the parent, `child_frame_id` the
//! child, and `transform` maps child coordinates into the parent's). Lookups compose the two
//! chains up to the frames' common ancestor:
//!
//! ```text
//! target_from_source = (ancestor_from_target)⁻¹ · ancestor_from_source
//! ancestor_from_frame = parent_from_child(f_k) · … · parent_from_child(f_0),   f_0 = frame
//! ```
//!
//! Only each edge's latest value is kept (the mounts this tree serves are rigid). What tf2
//! would accept in a way that corrupts the tree is refused here, naming the frames: a frame
//! as its own parent, a transform that would close a cycle, and a static frame given a second,
//! different parent (two publishers disagree about the tree: a duplicate frame). A dynamic
//! frame may move to another parent, as in tf2, unless that closes a cycle. The number of
//! frames is bounded.

use sgm_model::geometry::Pose3;
use std::collections::BTreeMap;

/// At most this many frames are held; transforms of further frames are refused.
pub const MAX_FRAMES: usize = 4096;

/// A frame id as tf2 keeps it: without a leading `/` (older drivers add one).
pub fn frame_name(id: &str) -> &str {
    id.trim_start_matches('/')
}

/// One edge: where `child` sits in `parent`.
#[derive(Clone, Debug, PartialEq)]
pub struct Edge {
    pub parent: String,
    pub parent_from_child: Pose3,
    /// From `/tf_static` (latched, never expires) rather than `/tf`.
    pub is_static: bool,
}

/// Why a transform was refused or a lookup failed.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum TfError {
    #[error("a transform with an empty frame id (parent `{parent}`, child `{child}`)")]
    EmptyFrame { parent: String, child: String },
    #[error("frame `{frame}` given itself as parent")]
    SelfParent { frame: String },
    #[error("`{parent}` → `{child}` would close a cycle: `{parent}` already descends from `{child}` ({path})")]
    Cycle { parent: String, child: String, path: String },
    #[error(
        "duplicate frame `{child}`: /tf_static has it under `{parent}`, another transform puts it under \
         `{new_parent}` (two publishers disagree; the first is kept)"
    )]
    Duplicate { child: String, parent: String, new_parent: String },
    #[error("the tf tree holds {max} frames already; `{child}` refused")]
    TooManyFrames { child: String, max: usize },
    #[error("no frame `{frame}` in tf ({known})")]
    Unknown { frame: String, known: String },
    #[error(
        "`{target_frame}` and `{source_frame}` are not connected in tf: `{target_frame}` is under `{target_root}`, \
         `{source_frame}` under `{source_root}`"
    )]
    Unreachable { target_frame: String, source_frame: String, target_root: String, source_root: String },
}

/// The frames and their parents.
#[derive(Clone, Debug, Default)]
pub struct TfTree {
    edges: BTreeMap<String, Edge>,
}

/// "frames known: a, b, c, …" for errors (at most 12 named).
fn known_frames<'a>(frames: impl Iterator<Item = &'a String>, count: usize) -> String {
    if count == 0 {
        return "tf holds no frame yet".into();
    }
    let named: Vec<&str> = frames.take(12).map(String::as_str).collect();
    let more = if count > named.len() { format!(", … ({count} in all)") } else { String::new() };
    format!("frames known: {}{more}", named.join(", "))
}

impl TfTree {
    pub fn new() -> Self {
        Self::default()
    }

    /// Every frame named by an edge (children and parents).
    fn frames(&self) -> std::collections::BTreeSet<&String> {
        self.edges.iter().flat_map(|(child, e)| [child, &e.parent]).collect()
    }

    pub fn contains(&self, frame: &str) -> bool {
        let frame = frame_name(frame);
        self.edges.contains_key(frame) || self.edges.values().any(|e| e.parent == frame)
    }

    /// The edge above `frame`, if it has a parent.
    pub fn edge(&self, frame: &str) -> Option<&Edge> {
        self.edges.get(frame_name(frame))
    }

    /// Sets `parent_from_child`; refuses what would corrupt the tree (see the module
    /// documentation). Returns whether the value changed (a new edge or a new value).
    pub fn insert(
        &mut self,
        parent: &str,
        child: &str,
        parent_from_child: Pose3,
        is_static: bool,
    ) -> Result<bool, TfError> {
        let (parent, child) = (frame_name(parent), frame_name(child));
        if parent.is_empty() || child.is_empty() {
            return Err(TfError::EmptyFrame { parent: parent.into(), child: child.into() });
        }
        if parent == child {
            return Err(TfError::SelfParent { frame: child.into() });
        }
        if let Some(old) = self.edges.get(child) {
            if old.parent != parent && (old.is_static || is_static) {
                return Err(TfError::Duplicate {
                    child: child.into(),
                    parent: old.parent.clone(),
                    new_parent: parent.into(),
                });
            }
        } else if self.edges.len() >= MAX_FRAMES {
            return Err(TfError::TooManyFrames { child: child.into(), max: MAX_FRAMES });
        }
        // `parent` must not descend from `child`.
        let mut path = vec![parent.to_string()];
        let mut at = parent;
        while let Some(edge) = self.edges.get(at) {
            path.push(edge.parent.clone());
            if edge.parent == child {
                path.reverse();
                return Err(TfError::Cycle { parent: parent.into(), child: child.into(), path: path.join(" → ") });
            }
            at = &edge.parent;
        }
        let edge = Edge { parent: parent.into(), parent_from_child, is_static };
        let changed = self.edges.get(child) != Some(&edge);
        self.edges.insert(child.into(), edge);
        Ok(changed)
    }

    /// `frame`'s chain to its root: (root, root_from_frame, frames passed from `frame` up).
    fn chain(&self, frame: &str) -> (String, Pose3, Vec<String>) {
        let mut root_from_frame = Pose3::identity();
        let mut passed = vec![frame.to_string()];
        let mut at = frame.to_string();
        // The insert checks keep the tree acyclic; the bound is a second guard.
        while let Some(edge) = self.edges.get(&at).filter(|_| passed.len() <= self.edges.len() + 1) {
            root_from_frame = edge.parent_from_child * root_from_frame;
            at = edge.parent.clone();
            passed.push(at.clone());
        }
        (at, root_from_frame, passed)
    }

    /// `target_from_source`: maps points of `source` into `target`.
    pub fn lookup(&self, target: &str, source: &str) -> Result<Pose3, TfError> {
        let (target, source) = (frame_name(target), frame_name(source));
        if target == source {
            return Ok(Pose3::identity());
        }
        for frame in [target, source] {
            if !self.contains(frame) {
                let frames = self.frames();
                return Err(TfError::Unknown {
                    frame: frame.into(),
                    known: known_frames(frames.iter().copied(), frames.len()),
                });
            }
        }
        let (target_root, _, target_chain) = self.chain(target);
        let (source_root, _, source_chain) = self.chain(source);
        if target_root != source_root {
            return Err(TfError::Unreachable {
                target_frame: target.into(),
                source_frame: source.into(),
                target_root,
                source_root,
            });
        }
        // The lowest common ancestor: the first frame of source's chain that target's holds.
        let ancestor = source_chain.iter().find(|f| target_chain.contains(f)).cloned().unwrap_or(source_root);
        let ancestor_from = |frame: &str| {
            let mut pose = Pose3::identity();
            let mut at = frame.to_string();
            while at != ancestor {
                let Some(edge) = self.edges.get(&at) else { break };
                pose = edge.parent_from_child * pose;
                at = edge.parent.clone();
            }
            pose
        };
        Ok(ancestor_from(target).inverse() * ancestor_from(source))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Point3, Vector3};
    use proptest::prelude::*;
    use sgm_model::geometry::pose_from_rpy_translation;

    fn pose(x: f64, yaw: f64) -> Pose3 {
        pose_from_rpy_translation(0.0, 0.0, yaw, Vector3::new(x, 0.0, 0.0))
    }

    fn close(a: &Pose3, b: &Pose3) -> bool {
        (a.to_homogeneous() - b.to_homogeneous()).norm() < 1e-9
    }

    /// base_link → lidar 1 m ahead; base_link → camera 0.5 m ahead turned 90° left: a point
    /// 2 m ahead of the lidar is 3 m ahead of the base, 2.5 m ahead of the camera's origin,
    /// which lies along the camera's −y (it faces +y of the base).
    #[test]
    fn siblings_compose_through_their_parent() {
        let mut tree = TfTree::new();
        tree.insert("base_link", "lidar", pose(1.0, 0.0), true).unwrap();
        tree.insert("/base_link", "camera", pose(0.5, std::f64::consts::FRAC_PI_2), true).unwrap();
        let camera_from_lidar = tree.lookup("camera", "lidar").unwrap();
        let p = camera_from_lidar * Point3::new(2.0, 0.0, 0.0);
        assert!((p - Point3::new(0.0, -2.5, 0.0)).norm() < 1e-12, "{p}");
        assert!(close(&tree.lookup("lidar", "camera").unwrap(), &camera_from_lidar.inverse()));
        assert!(close(&tree.lookup("base_link", "lidar").unwrap(), &pose(1.0, 0.0)));
        assert!(close(&tree.lookup("lidar", "lidar").unwrap(), &Pose3::identity()));
    }

    #[test]
    fn what_would_corrupt_the_tree_is_refused_by_name() {
        let mut tree = TfTree::new();
        tree.insert("a", "b", pose(1.0, 0.0), true).unwrap();
        tree.insert("b", "c", pose(1.0, 0.0), false).unwrap();
        let e = tree.insert("c", "a", pose(1.0, 0.0), false).unwrap_err();
        assert_eq!(e.to_string(), "`c` → `a` would close a cycle: `c` already descends from `a` (a → b → c)");
        let e = tree.insert("x", "b", pose(1.0, 0.0), false).unwrap_err();
        assert!(matches!(e, TfError::Duplicate { .. }), "{e}");
        assert!(e.to_string().contains("duplicate frame `b`: /tf_static has it under `a`"), "{e}");
        assert_eq!(
            tree.insert("d", "d", pose(0.0, 0.0), false).unwrap_err(),
            TfError::SelfParent { frame: "d".into() }
        );
        assert!(matches!(tree.insert("", "d", pose(0.0, 0.0), false), Err(TfError::EmptyFrame { .. })));
        // A dynamic frame may move to another parent, unless that closes a cycle.
        tree.insert("a", "c", pose(2.0, 0.0), false).unwrap();
        assert_eq!(tree.edge("c").unwrap().parent, "a");
        // Nothing refused changed the tree.
        assert!(close(&tree.lookup("a", "b").unwrap(), &pose(1.0, 0.0)));
    }

    #[test]
    fn lookups_name_missing_and_disconnected_frames() {
        let mut tree = TfTree::new();
        assert_eq!(
            tree.lookup("base_link", "camera").unwrap_err().to_string(),
            "no frame `base_link` in tf (tf holds no frame yet)"
        );
        tree.insert("base_link", "lidar", pose(1.0, 0.0), true).unwrap();
        tree.insert("camera_link", "camera_optical", pose(0.0, 0.0), true).unwrap();
        let e = tree.lookup("camera_optical", "base_link").unwrap_err().to_string();
        assert_eq!(
            e,
            "`camera_optical` and `base_link` are not connected in tf: `camera_optical` is under `camera_link`, \
             `base_link` under `base_link`"
        );
        let e = tree.lookup("camera", "lidar").unwrap_err().to_string();
        assert_eq!(e, "no frame `camera` in tf (frames known: base_link, camera_link, camera_optical, lidar)");
    }

    #[test]
    fn the_number_of_frames_is_bounded() {
        let mut tree = TfTree::new();
        for k in 0..MAX_FRAMES {
            tree.insert("root", &format!("f{k}"), Pose3::identity(), false).unwrap();
        }
        assert!(matches!(
            tree.insert("root", "one_more", Pose3::identity(), false),
            Err(TfError::TooManyFrames { .. })
        ));
        // Updating a known frame is still accepted.
        assert_eq!(tree.insert("root", "f0", pose(1.0, 0.0), false), Ok(true));
        assert_eq!(tree.insert("root", "f0", pose(1.0, 0.0), false), Ok(false));
    }

    fn arb_pose() -> impl Strategy<Value = Pose3> {
        (-5.0f64..5.0, -5.0f64..5.0, -5.0f64..5.0, -3.1f64..3.1, -1.5f64..1.5, -3.1f64..3.1)
            .prop_map(|(x, y, z, r, p, w)| pose_from_rpy_translation(r, p, w, Vector3::new(x, y, z)))
    }

    proptest! {
        /// A random tree (frame k's parent is one of frames 0..k): lookups compose
        /// (a_from_c = a_from_b · b_from_c), invert (b_from_a = a_from_b⁻¹), and agree with
        /// the poses of every frame in the root computed independently.
        #[test]
        fn lookups_compose_and_invert(
            parents in proptest::collection::vec(0usize..1000, 1..12),
            poses in proptest::collection::vec(arb_pose(), 12),
            picks in (0usize..13, 0usize..13, 0usize..13),
        ) {
            let mut tree = TfTree::new();
            let mut root_from = vec![Pose3::identity()];
            for (k, parent) in parents.iter().enumerate() {
                let parent = parent % (k + 1);
                let name = format!("f{}", k + 1);
                tree.insert(&format!("f{parent}"), &name, poses[k], k % 2 == 0).unwrap();
                root_from.push(root_from[parent] * poses[k]);
            }
            let n = root_from.len();
            let (a, b, c) = (picks.0 % n, picks.1 % n, picks.2 % n);
            let f = |k: usize| format!("f{k}");
            let a_from_b = tree.lookup(&f(a), &f(b)).unwrap();
            let b_from_c = tree.lookup(&f(b), &f(c)).unwrap();
            let a_from_c = tree.lookup(&f(a), &f(c)).unwrap();
            prop_assert!(close(&a_from_c, &(a_from_b * b_from_c)));
            prop_assert!(close(&tree.lookup(&f(b), &f(a)).unwrap(), &a_from_b.inverse()));
            prop_assert!(close(&a_from_c, &(root_from[a].inverse() * root_from[c])));
        }
    }
}
