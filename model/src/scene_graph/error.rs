use super::{KeyframeId, ObjectId};

/// What went wrong when changing a scene graph. The graph is unchanged when one is returned.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SceneGraphError {
    #[error("keyframe {0} already exists")]
    DuplicateKeyframe(KeyframeId),
    #[error("keyframe {0} is not in the scene graph")]
    UnknownKeyframe(KeyframeId),
    #[error("object {0} is not in the scene graph")]
    UnknownObject(ObjectId),
    #[error("objects {keep} and {gone} cannot be merged: one object, two labels, or a share outside [0, 1]")]
    NotOneObject { keep: ObjectId, gone: ObjectId },
    #[error("a sighting's share {share} of object {id}'s estimate is outside [0, 1]")]
    ShareOutOfRange { id: ObjectId, share: f64 },
    #[error("{what} is not finite")]
    NonFinite { what: &'static str },
    #[error("keyframe {id} has stamp {stamp} s, earlier than the latest keyframe's {latest} s")]
    StampNotIncreasing { id: KeyframeId, stamp: f64, latest: f64 },
    #[error("semantic scan has {points} points but {labels} labels")]
    LabelCountMismatch { points: usize, labels: usize },
}
