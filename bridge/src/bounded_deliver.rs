//! The `sgm_msgs/Deliver` service with its request and response read within bounds.
//!
//! rosrust's service server reads a request straight off the caller's TCP stream: it reads the
//! length prefix and ignores it, then decodes with `RosMsg::decode`, which reserves whatever the
//! `data` field's own prefix declares (up to 4 GB) before a byte of it has arrived. Any process
//! that can reach the master can call a robot's Deliver service. [`Bounded`](crate::bounded::Bounded)
//! does not fit here: it reads to the end of the stream, and a caller keeps the stream open for
//! the reply. [`BoundedDeliver`] is the same service (same type and md5sum, so other nodes and
//! `rosservice` see no difference) whose request and response are read field by field. A length
//! beyond `ros.max_message_bytes` is refused before anything is reserved, and bytes are kept only
//! as they arrive, so a stream that ends early costs what it sent.

use crate::bounded::{max_message_bytes, LayoutError};
use crate::msg::sgm_msgs;
use rosrust::RosMsg;
use std::io::{self, Read};
use std::sync::atomic::{AtomicU64, Ordering};

/// Requests refused by [`BoundedDeliverReq`]'s decoder in this process (one node per process).
static REFUSED_REQUESTS: AtomicU64 = AtomicU64::new(0);

/// How many Deliver requests were refused for their size or an early end.
pub fn refused_requests() -> u64 {
    REFUSED_REQUESTS.load(Ordering::Relaxed)
}

/// `sgm_msgs/Deliver` whose request and response decode within `ros.max_message_bytes`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BoundedDeliver;

/// A Deliver request, received only within bounds.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BoundedDeliverReq(pub sgm_msgs::DeliverReq);

/// A Deliver response, received only within bounds.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BoundedDeliverRes(pub sgm_msgs::DeliverRes);

impl rosrust::Message for BoundedDeliver {
    fn msg_definition() -> String {
        sgm_msgs::Deliver::msg_definition()
    }

    fn md5sum() -> String {
        sgm_msgs::Deliver::md5sum()
    }

    fn msg_type() -> String {
        sgm_msgs::Deliver::msg_type()
    }
}

impl RosMsg for BoundedDeliver {
    fn encode<W: io::Write>(&self, _: W) -> io::Result<()> {
        Ok(())
    }

    fn decode<R: Read>(_: R) -> io::Result<Self> {
        Ok(Self)
    }
}

impl rosrust::ServicePair for BoundedDeliver {
    type Request = BoundedDeliverReq;
    type Response = BoundedDeliverRes;
}

/// A u32 length prefix, then that many bytes of `field`; at most `max` of them.
fn read_counted<R: Read>(mut r: R, field: &'static str, max: usize) -> io::Result<Vec<u8>> {
    let declared = u32::decode(&mut r)?;
    let len = usize::try_from(declared).unwrap_or(usize::MAX);
    if len > max {
        return Err(io::Error::new(io::ErrorKind::InvalidData, LayoutError::FieldTooLarge { field, len, max }));
    }
    let mut bytes = Vec::new();
    r.take(u64::from(declared)).read_to_end(&mut bytes)?;
    if bytes.len() < len {
        let e = LayoutError::Short { field, needed: u64::from(declared), left: bytes.len() };
        return Err(io::Error::new(io::ErrorKind::UnexpectedEof, e));
    }
    Ok(bytes)
}

impl RosMsg for BoundedDeliverReq {
    fn encode<W: io::Write>(&self, w: W) -> io::Result<()> {
        self.0.encode(w)
    }

    /// `uint16 from_robot`, `uint8[] data`.
    fn decode<R: Read>(mut r: R) -> io::Result<Self> {
        let from_robot = u16::decode(&mut r)?;
        // rosrust drops a request that fails to decode without a word: say it here, once.
        let data = read_counted(&mut r, "data", max_message_bytes()).inspect_err(|e| {
            REFUSED_REQUESTS.fetch_add(1, Ordering::Relaxed);
            tracing::warn!(claimed_from = from_robot, "Deliver request refused: {e}");
        })?;
        Ok(Self(sgm_msgs::DeliverReq { from_robot, data }))
    }
}

impl RosMsg for BoundedDeliverRes {
    fn encode<W: io::Write>(&self, w: W) -> io::Result<()> {
        self.0.encode(w)
    }

    /// `bool accepted`, `string reason`.
    fn decode<R: Read>(mut r: R) -> io::Result<Self> {
        let accepted = bool::decode(&mut r)?;
        let reason = read_counted(&mut r, "reason", max_message_bytes())?;
        let reason = String::from_utf8(reason).map_err(|e| io::Error::new(io::ErrorKind::InvalidData, e))?;
        Ok(Self(sgm_msgs::DeliverRes { accepted, reason }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rosrust::Message;

    fn request() -> sgm_msgs::DeliverReq {
        sgm_msgs::DeliverReq { from_robot: 7, data: (0..=255).collect() }
    }

    #[test]
    fn the_service_is_sgm_msgs_deliver_to_everyone_else() {
        assert_eq!(BoundedDeliver::md5sum(), sgm_msgs::Deliver::md5sum());
        assert_eq!(BoundedDeliver::msg_type(), "sgm_msgs/Deliver");
    }

    #[test]
    fn requests_and_responses_read_back_what_rosrust_writes() {
        let bytes = request().encode_vec().unwrap();
        assert_eq!(BoundedDeliverReq::decode_slice(&bytes).unwrap().0, request());
        assert_eq!(BoundedDeliverReq(request()).encode_vec().unwrap(), bytes);
        let res = sgm_msgs::DeliverRes { accepted: false, reason: "not now".into() };
        assert_eq!(BoundedDeliverRes::decode_slice(&res.encode_vec().unwrap()).unwrap().0, res);
    }

    #[test]
    fn a_stream_that_ends_early_is_refused_by_field() {
        let bytes = request().encode_vec().unwrap();
        for cut in 4..bytes.len() {
            let e = BoundedDeliverReq::decode_slice(&bytes[..cut]).unwrap_err();
            assert_eq!(e.kind(), io::ErrorKind::UnexpectedEof, "cut at {cut}: {e}");
        }
        let e = BoundedDeliverReq::decode_slice(&bytes[..bytes.len() - 1]).unwrap_err();
        assert_eq!(e.to_string(), "field `data` needs 256 bytes, 255 left");
    }

    #[test]
    fn a_declared_length_beyond_the_limit_is_refused_before_reading_it() {
        // 6 bytes that declare 4 GB of data, the rest of the stream never sent: rosrust's own
        // decoder reserves the 4 GB and waits for them.
        let mut bytes = vec![0, 0, 0, 0, 7, 0];
        bytes.extend_from_slice(&0xFFFF_FFF0u32.to_le_bytes());
        let e = BoundedDeliverReq::decode_slice(&bytes).unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::InvalidData);
        let text = e.to_string();
        assert!(text.starts_with("field `data` declares 4294967280 bytes, at most"), "{text}");
        let e = read_counted(&[3, 0, 0, 0, 1, 2, 3][..], "reason", 2).unwrap_err();
        assert_eq!(e.to_string(), "field `reason` declares 3 bytes, at most 2 accepted");
    }
}
