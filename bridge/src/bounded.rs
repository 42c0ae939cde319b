//! Received ROS messages decoded within bounds.
//!
//! rosrust decodes a variable-length array by reserving what its length prefix declares, before
//! reading a byte of it (`rosmsg::decode_variable_primitive_vec`). A 60-byte PointCloud2 that
//! declares 4 × 10⁹ bytes of `data` makes it reserve 4 GB: the `ros_messages` fuzz target
//! found the abort in its first seconds (`fuzz/README.md`). The node therefore subscribes with
//! [`Bounded<M>`] instead of `M`. Before rosrust sees the bytes, they are checked. The whole
//! message must be within `ros.max_message_bytes`. A walk over M's layout ([`Layout`]) then
//! checks every length prefix against the bytes that remain, and the message must end exactly
//! where its bytes do. A message that fails is dropped with rosrust's "Failed to decode message"
//! error, naming the field; the subscriber goes on.

use crate::msg::{nav_msgs, rosgraph_msgs, sensor_msgs, sgm_msgs, std_msgs, tf2_msgs};
use std::io;
use std::sync::atomic::{AtomicUsize, Ordering};

/// Largest message accepted, bytes (`ros.max_message_bytes`, set by the node at start).
static MAX_MESSAGE_BYTES: AtomicUsize = AtomicUsize::new(crate::config::DEFAULT_MAX_MESSAGE_BYTES);

/// Sets the largest message [`Bounded`] accepts, bytes.
pub fn set_max_message_bytes(bytes: usize) {
    MAX_MESSAGE_BYTES.store(bytes, Ordering::Relaxed);
}

/// The largest message accepted, bytes (`ros.max_message_bytes`).
pub fn max_message_bytes() -> usize {
    MAX_MESSAGE_BYTES.load(Ordering::Relaxed)
}

/// Where a message's bytes do not fit its layout.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum LayoutError {
    #[error("{len} bytes, at most {max} accepted")]
    TooLarge { len: usize, max: usize },
    #[error("field `{field}` needs {needed} bytes, {left} left")]
    Short { field: &'static str, needed: u64, left: usize },
    #[error("field `{field}` declares {len} bytes, at most {max} accepted")]
    FieldTooLarge { field: &'static str, len: usize, max: usize },
    #[error("{0} bytes after the last field")]
    Trailing(usize),
}

/// A cursor over a message's serialised bytes that only checks, never allocates.
pub struct Walker<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Walker<'a> {
    pub fn new(bytes: &'a [u8]) -> Self {
        Self { bytes, at: 0 }
    }

    fn left(&self) -> usize {
        self.bytes.len() - self.at
    }

    /// Skips `n` bytes of `field`.
    pub fn skip(&mut self, field: &'static str, n: u64) -> Result<(), LayoutError> {
        let left = self.left();
        if n > left as u64 {
            return Err(LayoutError::Short { field, needed: n, left });
        }
        self.at += n as usize;
        Ok(())
    }

    fn length(&mut self, field: &'static str) -> Result<u64, LayoutError> {
        let left = self.left();
        let Some(b) = self.bytes.get(self.at..self.at + 4) else {
            return Err(LayoutError::Short { field, needed: 4, left });
        };
        self.at += 4;
        Ok(u64::from(u32::from_le_bytes([b[0], b[1], b[2], b[3]])))
    }

    /// A string or an array of fixed-size elements: a u32 count, then count × `element` bytes.
    pub fn array(&mut self, field: &'static str, element: u64) -> Result<(), LayoutError> {
        let count = self.length(field)?;
        self.skip(field, count.saturating_mul(element))
    }

    /// An array of variable-size elements, each walked by `element`.
    pub fn list(
        &mut self,
        field: &'static str,
        element: impl Fn(&mut Self) -> Result<(), LayoutError>,
    ) -> Result<(), LayoutError> {
        let count = self.length(field)?;
        for _ in 0..count {
            // Each element takes at least one byte: a count beyond the bytes left fails here.
            if self.left() == 0 {
                return Err(LayoutError::Short { field, needed: count, left: 0 });
            }
            element(self)?;
        }
        Ok(())
    }

    /// Every byte was walked.
    pub fn finish(&self) -> Result<(), LayoutError> {
        match self.left() {
            0 => Ok(()),
            n => Err(LayoutError::Trailing(n)),
        }
    }
}

/// A message's serialised layout (ROS 1: little-endian, u32 length prefixes).
pub trait Layout {
    fn walk(w: &mut Walker) -> Result<(), LayoutError>;
}

fn header(w: &mut Walker) -> Result<(), LayoutError> {
    w.skip("header.seq, header.stamp", 12)?;
    w.array("header.frame_id", 1)
}

impl Layout for sensor_msgs::PointCloud2 {
    fn walk(w: &mut Walker) -> Result<(), LayoutError> {
        header(w)?;
        w.skip("height, width", 8)?;
        w.list("fields", |w| {
            w.array("fields[].name", 1)?;
            w.skip("fields[].offset, datatype, count", 9)
        })?;
        w.skip("is_bigendian, point_step, row_step", 9)?;
        w.array("data", 1)?;
        w.skip("is_dense", 1)
    }
}

impl Layout for sensor_msgs::Image {
    fn walk(w: &mut Walker) -> Result<(), LayoutError> {
        header(w)?;
        w.skip("height, width", 8)?;
        w.array("encoding", 1)?;
        w.skip("is_bigendian, step", 5)?;
        w.array("data", 1)
    }
}

impl Layout for sensor_msgs::CameraInfo {
    fn walk(w: &mut Walker) -> Result<(), LayoutError> {
        header(w)?;
        w.skip("height, width", 8)?;
        w.array("distortion_model", 1)?;
        w.array("D", 8)?;
        w.skip("K, R, P", (9 + 9 + 12) * 8)?;
        w.skip("binning_x, binning_y", 8)?;
        w.skip("roi", 17)
    }
}

impl Layout for sensor_msgs::Imu {
    fn walk(w: &mut Walker) -> Result<(), LayoutError> {
        header(w)?;
        w.skip("orientation, covariance", (4 + 9) * 8)?;
        w.skip("angular_velocity, covariance", (3 + 9) * 8)?;
        w.skip("linear_acceleration, covariance", (3 + 9) * 8)
    }
}

impl Layout for nav_msgs::Odometry {
    fn walk(w: &mut Walker) -> Result<(), LayoutError> {
        header(w)?;
        w.array("child_frame_id", 1)?;
        w.skip("pose", (7 + 36) * 8)?;
        w.skip("twist", (6 + 36) * 8)
    }
}

impl Layout for sgm_msgs::Envelope {
    fn walk(w: &mut Walker) -> Result<(), LayoutError> {
        w.skip("from_robot", 2)?;
        w.array("data", 1)
    }
}

impl Layout for rosgraph_msgs::Clock {
    fn walk(w: &mut Walker) -> Result<(), LayoutError> {
        w.skip("clock", 8)
    }
}

impl Layout for tf2_msgs::TFMessage {
    fn walk(w: &mut Walker) -> Result<(), LayoutError> {
        w.list("transforms", |w| {
            header(w)?;
            w.array("transforms[].child_frame_id", 1)?;
            w.skip("transforms[].transform", 7 * 8)
        })
    }
}

impl Layout for std_msgs::Header {
    fn walk(w: &mut Walker) -> Result<(), LayoutError> {
        header(w)
    }
}

/// Checks `body` (a message without its 4-byte length prefix) against M's layout and
/// `ros.max_message_bytes`.
pub fn check<M: Layout>(body: &[u8]) -> Result<(), LayoutError> {
    check_within::<M>(body, max_message_bytes())
}

/// As [`check`], with at most `max` bytes.
pub fn check_within<M: Layout>(body: &[u8], max: usize) -> Result<(), LayoutError> {
    if body.len() > max {
        return Err(LayoutError::TooLarge { len: body.len(), max });
    }
    let mut w = Walker::new(body);
    M::walk(&mut w)?;
    w.finish()
}

/// M, received only once its bytes passed [`check`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Bounded<M>(pub M);

impl<M: rosrust::RosMsg + Layout> rosrust::RosMsg for Bounded<M> {
    fn encode<W: io::Write>(&self, w: W) -> io::Result<()> {
        self.0.encode(w)
    }

    fn decode<R: io::Read>(r: R) -> io::Result<Self> {
        // At most one byte more than accepted is read: enough to know it is too large.
        let max = max_message_bytes();
        let mut body = Vec::new();
        io::Read::read_to_end(&mut r.take(max as u64 + 1), &mut body)?;
        check::<M>(&body).map_err(|e| io::Error::new(io::ErrorKind::InvalidData, e))?;
        M::decode(&body[..]).map(Bounded)
    }

    fn decode_slice(bytes: &[u8]) -> io::Result<Self> {
        let body = bytes.get(4..).ok_or_else(|| io::Error::new(io::ErrorKind::UnexpectedEof, "no length prefix"))?;
        check::<M>(body).map_err(|e| io::Error::new(io::ErrorKind::InvalidData, e))?;
        M::decode(body).map(Bounded)
    }
}

impl<M: rosrust::Message + Layout> rosrust::Message for Bounded<M> {
    fn msg_definition() -> String {
        M::msg_definition()
    }

    fn md5sum() -> String {
        M::md5sum()
    }

    fn msg_type() -> String {
        M::msg_type()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::msg::geometry_msgs;
    use rosrust::RosMsg;

    fn cloud() -> sensor_msgs::PointCloud2 {
        sensor_msgs::PointCloud2 {
            header: std_msgs::Header { seq: 3, stamp: rosrust::Time::from_nanos(5), frame_id: "alpha/velodyne".into() },
            height: 1,
            width: 2,
            fields: vec![sensor_msgs::PointField { name: "x".into(), offset: 0, datatype: 7, count: 1 }],
            is_bigendian: false,
            point_step: 4,
            row_step: 8,
            data: vec![1, 2, 3, 4, 5, 6, 7, 8],
            is_dense: true,
        }
    }

    #[test]
    fn every_layout_walks_what_rosrust_encodes() {
        fn round_trip<M: rosrust::RosMsg + Layout + PartialEq + std::fmt::Debug>(m: M) {
            let bytes = m.encode_vec().unwrap();
            assert_eq!(check::<M>(&bytes[4..]), Ok(()));
            assert_eq!(Bounded::<M>::decode_slice(&bytes).unwrap().0, m);
            // Any truncation is refused by name, before rosrust sees it.
            for cut in 4..bytes.len() {
                assert!(check::<M>(&bytes[4..cut]).is_err(), "cut at {cut}");
            }
        }
        round_trip(cloud());
        round_trip(sensor_msgs::Image { encoding: "mono8".into(), data: vec![9; 12], ..Default::default() });
        round_trip(sensor_msgs::CameraInfo {
            D: vec![0.1; 5],
            distortion_model: "plumb_bob".into(),
            ..Default::default()
        });
        round_trip(nav_msgs::Odometry { child_frame_id: "alpha/base_link".into(), ..Default::default() });
        round_trip(sensor_msgs::Imu {
            header: std_msgs::Header { frame_id: "alpha/imu_link".into(), ..Default::default() },
            ..Default::default()
        });
        round_trip(sgm_msgs::Envelope { from_robot: 2, data: vec![1; 40] });
        let transform = geometry_msgs::TransformStamped {
            header: std_msgs::Header { frame_id: "base_link".into(), ..Default::default() },
            child_frame_id: "camera".into(),
            ..Default::default()
        };
        round_trip(tf2_msgs::TFMessage { transforms: vec![transform.clone(), transform] });
    }

    #[test]
    fn a_declared_length_beyond_the_bytes_is_refused_before_any_allocation() {
        // The fuzz crash: `data` declares 4 GB in a message of a few dozen bytes.
        let mut bytes = cloud().encode_vec().unwrap();
        let data_at = bytes.len() - 1 - 8 - 4;
        bytes[data_at..data_at + 4].copy_from_slice(&u32::MAX.to_le_bytes());
        let e = Bounded::<sensor_msgs::PointCloud2>::decode_slice(&bytes).unwrap_err();
        assert!(e.to_string().contains("field `data` needs 4294967295 bytes"), "{e}");
        let mut fields = cloud().encode_vec().unwrap();
        let fields_at = 4 + 12 + 4 + "alpha/velodyne".len() + 8;
        fields[fields_at..fields_at + 4].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(Bounded::<sensor_msgs::PointCloud2>::decode_slice(&fields).is_err());
        let mut trailing = cloud().encode_vec().unwrap();
        trailing.push(0);
        let e = Bounded::<sensor_msgs::PointCloud2>::decode_slice(&trailing).unwrap_err();
        assert!(e.to_string().contains("1 bytes after the last field"), "{e}");
        let whole = cloud().encode_vec().unwrap();
        let len = whole.len() - 4;
        assert_eq!(
            check_within::<sensor_msgs::PointCloud2>(&whole[4..], len - 1),
            Err(LayoutError::TooLarge { len, max: len - 1 })
        );
    }
}
