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

impl RobotId {
    /// The id of a team's `index`-th robot (zero-based, in configuration order): robots are
    /// numbered from 1. Saturates at `u16::MAX` (a team that large is refused by validation).
    pub fn from_index(index: usize) -> Self {
        Self(u16::try_from(index.saturating_add(1)).unwrap_or(u16::MAX))
    }

    /// The zero-based index of this robot in its team's configuration order (`None` for id 0,
    /// which no robot has).
    pub fn index(self) -> Option<usize> {
        usize::from(self.0).checked_sub(1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn robot_ids_count_from_one_and_index_from_zero() {
        assert_eq!(RobotId::from_index(0), RobotId(1));
        assert_eq!(RobotId::from_index(7), RobotId(8));
        assert_eq!(RobotId(8).index(), Some(7));
        assert_eq!(RobotId(0).index(), None);
        assert_eq!(RobotId::from_index(usize::MAX), RobotId(u16::MAX));
        for k in [0, 1, 15, 1000] {
            assert_eq!(RobotId::from_index(k).index(), Some(k));
        }
    }
}
