//! Typed identifiers: a keyframe id can never be used where an object id is expected.

use serde::{Deserialize, Serialize};
use std::fmt;

macro_rules! typed_id {
    ($(#[$doc:meta])* $name:ident($inner:ty), $prefix:literal) => {
        $(#[$doc])*
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
        #[serde(transparent)]
        pub struct $name(pub $inner);

        impl fmt::Display for $name {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                write!(f, concat!($prefix, "{}"), self.0)
            }
        }
    };
}

typed_id!(
    /// A keyframe of one robot; unique within that robot.
    KeyframeId(u32),
    "kf"
);
typed_id!(
    /// An object of one robot's object layer; unique within that robot.
    ObjectId(u32),
    "obj"
);
typed_id!(
    /// A semantic class, index into the class table.
    LabelId(u16),
    "label"
);
typed_id!(
    /// A robot of the team.
    RobotId(u16),
    "robot"
);
