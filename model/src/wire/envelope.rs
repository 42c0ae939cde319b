//! The envelope every inter-robot message travels in, and its authentication.
//!
//! Byte layout: `postcard(Envelope) ‖ tag`, where postcard writes
//! `version: u8 | from: varint u16 | to: 0 (broadcast) or 1 + varint u16 | sequence: varint u64 |
//! message tag: varint | message fields`, and `tag` is the 16-byte keyed-BLAKE3 MAC of everything
//! before it under the team key ([`super::TeamKey`]).
//!
//! [`open`] checks, in this order and before any allocation that depends on the content: total
//! size within [`WireLimits::max_envelope_bytes`], the MAC, the protocol version, the postcard
//! decoding (no trailing bytes), then per-message limits (objects per message, ids per request,
//! keyframes per object cloud, points declared by the clouds of one message, descriptor cells
//! that fill their shape). While decoding, a list's declared length reserves at most 1 MiB
//! (serde's cautious size hint) and the list grows only by elements actually read, and a byte
//! string is taken from the input only if it is all there: what postcard allocates is bounded
//! by the envelope's size bound.
//! Replay rejection needs per-sender state: [`super::ReplayWindow`], applied by the receiver.

use super::cloud_codec::declared_points;
use super::messages::{Message, MessageKind};
use super::team_key::TeamKey;
use crate::scene_graph::RobotId;
use serde::{Deserialize, Serialize};

/// Bumped on any incompatible change of the layout or of a message.
pub const PROTOCOL_VERSION: u8 = 1;
/// Bytes of the MAC at the end of every envelope.
pub const MAC_BYTES: usize = 16;

/// Who a message is for.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Destination {
    Broadcast,
    Robot(RobotId),
}

impl Destination {
    pub fn includes(&self, robot: RobotId) -> bool {
        match self {
            Destination::Broadcast => true,
            Destination::Robot(r) => *r == robot,
        }
    }
}

/// A message with its routing and sequencing.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Envelope {
    pub version: u8,
    pub from: RobotId,
    pub to: Destination,
    /// Strictly increasing per sender.
    pub sequence: u64,
    pub message: Message,
}

/// Bounds applied to every received envelope.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct WireLimits {
    /// Largest envelope, bytes. Default 4 MiB.
    pub max_envelope_bytes: usize,
    /// Most objects in one ObjectData or ObjectCloudResponse. Default 4096.
    pub max_objects: usize,
    /// Most ids in one request or refusal, and most entries of one `KeyframeDescriptors`,
    /// `Alignments` or `KeyframePoses`. Default 256.
    pub max_ids: usize,
    /// Most points in one decoded cloud. Default 500 000.
    pub max_cloud_points: usize,
}

impl Default for WireLimits {
    fn default() -> Self {
        Self { max_envelope_bytes: 4 << 20, max_objects: 4096, max_ids: 256, max_cloud_points: 500_000 }
    }
}

/// Why an envelope was refused (or could not be sealed).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum WireError {
    #[error("envelope of {0} bytes is shorter than its MAC")]
    TooShort(usize),
    #[error("envelope of {len} bytes exceeds the limit of {max}")]
    TooLarge { len: usize, max: usize },
    #[error("MAC does not verify under the team key")]
    BadMac,
    #[error("protocol version {got}, expected {expected}")]
    Version { got: u8, expected: u8 },
    #[error("malformed envelope: {0}")]
    Malformed(String),
    #[error("{kind:?} carries {count} {what}, limit {max}")]
    Limit { kind: MessageKind, what: &'static str, count: usize, max: usize },
}

/// Encodes and authenticates `envelope`; refuses what receivers with `limits` would refuse.
pub fn seal(envelope: &Envelope, key: &TeamKey, limits: &WireLimits) -> Result<Vec<u8>, WireError> {
    check_limits(&envelope.message, limits)?;
    let mut bytes = postcard::to_stdvec(envelope).map_err(|e| WireError::Malformed(e.to_string()))?;
    let len = bytes.len() + MAC_BYTES;
    if len > limits.max_envelope_bytes {
        return Err(WireError::TooLarge { len, max: limits.max_envelope_bytes });
    }
    let tag = key.mac(&bytes);
    bytes.extend_from_slice(&tag);
    Ok(bytes)
}

/// Authenticates and decodes one received envelope.
pub fn open(bytes: &[u8], key: &TeamKey, limits: &WireLimits) -> Result<Envelope, WireError> {
    if bytes.len() > limits.max_envelope_bytes {
        return Err(WireError::TooLarge { len: bytes.len(), max: limits.max_envelope_bytes });
    }
    if bytes.len() <= MAC_BYTES {
        return Err(WireError::TooShort(bytes.len()));
    }
    let (body, tag) = bytes.split_at(bytes.len() - MAC_BYTES);
    if !key.verify(body, tag) {
        return Err(WireError::BadMac);
    }
    if body[0] != PROTOCOL_VERSION {
        return Err(WireError::Version { got: body[0], expected: PROTOCOL_VERSION });
    }
    let (envelope, rest): (Envelope, &[u8]) =
        postcard::take_from_bytes(body).map_err(|e| WireError::Malformed(e.to_string()))?;
    if !rest.is_empty() {
        return Err(WireError::Malformed(format!("{} trailing bytes", rest.len())));
    }
    check_limits(&envelope.message, limits)?;
    Ok(envelope)
}

fn check_limits(message: &Message, limits: &WireLimits) -> Result<(), WireError> {
    let kind = message.kind();
    let (what, count, max) = match message {
        Message::ObjectData(m) => ("objects", m.objects.len(), limits.max_objects),
        Message::ObjectCloudResponse(m) => ("objects", m.objects.len(), limits.max_objects),
        Message::ObjectCloudRequest(m) => ("object ids", m.objects.len(), limits.max_ids),
        Message::KeyframeRequest(m) => ("keyframe ids", m.keyframes.len(), limits.max_ids),
        Message::KeyframeRefusal(m) => ("keyframe ids", m.keyframes.len(), limits.max_ids),
        Message::KeyframeResponse(_) => ("responses", 1, 1),
        Message::KeyframeDescriptors(m) => ("descriptors", m.descriptors.len(), limits.max_ids),
        Message::Alignments(m) => ("alignments", m.alignments.len(), limits.max_ids),
        Message::KeyframePoses(m) => ("keyframe poses", m.poses.len(), limits.max_ids),
        Message::GraphFactorRequest(_) => ("requests", 1, 1),
        Message::GraphFactors(m) => ("keyframes and factors", m.keyframes.len() + m.factors.len(), limits.max_ids),
    };
    if count > max {
        return Err(WireError::Limit { kind, what, count, max });
    }
    // Inside the message: lists within its parts, and the clouds' declared point counts (the
    // decoder allocates by them; it refuses a stream that does not hold what it declares).
    let points = |cloud: &[u8]| declared_points(cloud).ok_or(WireError::Malformed(format!("{kind:?}: cloud header")));
    let cloud_limit = |total: u64| {
        if total > limits.max_cloud_points as u64 {
            return Err(WireError::Limit {
                kind,
                what: "cloud points",
                count: total as usize,
                max: limits.max_cloud_points,
            });
        }
        Ok(())
    };
    match message {
        Message::ObjectData(m) if m.resolution_mm == 0 => {
            return Err(WireError::Malformed("ObjectData resolution of 0 mm".into()));
        }
        Message::ObjectCloudResponse(m) => {
            let mut total = 0u64;
            for object in &m.objects {
                if object.keyframes.len() > limits.max_ids {
                    return Err(WireError::Limit {
                        kind,
                        what: "keyframes of an object",
                        count: object.keyframes.len(),
                        max: limits.max_ids,
                    });
                }
                total = total.saturating_add(points(&object.cloud)?);
            }
            cloud_limit(total)?;
        }
        Message::KeyframeResponse(m) => cloud_limit(points(&m.cloud)?)?,
        Message::KeyframeDescriptors(m) => {
            if let Some(d) =
                m.descriptors.iter().find(|d| d.cells.len() != usize::from(d.rings) * usize::from(d.sectors))
            {
                return Err(WireError::Malformed(format!(
                    "descriptor of keyframe {}: {} cells for {} × {}",
                    d.keyframe.0,
                    d.cells.len(),
                    d.rings,
                    d.sectors
                )));
            }
        }
        Message::GraphFactors(m) if m.next < m.from => {
            return Err(WireError::Malformed(format!("GraphFactors from {} to {}", m.from, m.next)));
        }
        _ => {}
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene_graph::{KeyframeId, LabelId, ObjectId};
    use crate::wire::messages::{KeyframeRequest, ObjectData};
    use nalgebra::{Point3, Vector3};

    fn key() -> TeamKey {
        TeamKey::from_bytes([42; 32])
    }

    fn object_data(n: u32) -> Envelope {
        let objects = (0..n).map(|k| {
            let a = f64::from(k);
            (
                ObjectId(k),
                LabelId((k % 9) as u16),
                Point3::new(60.0 * a.sin(), 60.0 * a.cos(), 0.5),
                Vector3::new(0.6, 0.6, 1.1),
            )
        });
        Envelope {
            version: PROTOCOL_VERSION,
            from: RobotId(1),
            to: Destination::Broadcast,
            sequence: 1 << 40,
            message: Message::ObjectData(ObjectData::quantise(3, 20, objects)),
        }
    }

    #[test]
    fn seal_open_round_trip() {
        let e = object_data(50);
        let bytes = seal(&e, &key(), &WireLimits::default()).unwrap();
        assert_eq!(open(&bytes, &key(), &WireLimits::default()).unwrap(), e);
    }

    #[test]
    fn the_issue_size_targets() {
        // ObjectData ≤ 16 bytes per object, envelope and MAC included (paper: 7.76–18.4 KB per
        // message for tens of objects).
        let n = 100;
        let bytes = seal(&object_data(n), &key(), &WireLimits::default()).unwrap();
        let per_object = bytes.len() as f64 / f64::from(n);
        assert!(per_object <= 16.0, "{per_object} bytes per object");
        // KeyframeRequest for one keyframe ≤ 32 bytes, envelope and MAC included.
        let request = Envelope {
            version: PROTOCOL_VERSION,
            from: RobotId(3),
            to: Destination::Robot(RobotId(5)),
            sequence: 1 << 40,
            message: Message::KeyframeRequest(KeyframeRequest { keyframes: vec![KeyframeId(12_345)] }),
        };
        let len = seal(&request, &key(), &WireLimits::default()).unwrap().len();
        assert!(len <= 32, "{len} bytes");
    }

    #[test]
    fn refuses_tampering_wrong_keys_versions_truncation_and_oversize() {
        let limits = WireLimits::default();
        let bytes = seal(&object_data(5), &key(), &limits).unwrap();
        assert_eq!(open(&bytes, &TeamKey::from_bytes([1; 32]), &limits), Err(WireError::BadMac));
        let mut flipped = bytes.clone();
        flipped[7] ^= 1;
        assert_eq!(open(&flipped, &key(), &limits), Err(WireError::BadMac));
        assert_eq!(open(&bytes[..bytes.len() - 1], &key(), &limits), Err(WireError::BadMac));
        assert_eq!(open(&bytes[..10], &key(), &limits), Err(WireError::TooShort(10)));
        let small = WireLimits { max_envelope_bytes: 20, ..limits.clone() };
        assert!(matches!(open(&bytes, &key(), &small), Err(WireError::TooLarge { .. })));
        assert!(matches!(seal(&object_data(5), &key(), &small), Err(WireError::TooLarge { .. })));
        // A future version, correctly authenticated, is refused by version.
        let mut e = object_data(2);
        e.version = 2;
        let future = seal(&e, &key(), &limits).unwrap();
        assert_eq!(open(&future, &key(), &limits), Err(WireError::Version { got: 2, expected: 1 }));
        // Authenticated garbage is malformed, not a panic.
        let mut junk = vec![PROTOCOL_VERSION, 1, 0, 1, 99, 200, 200];
        let tag = key().mac(&junk);
        junk.extend_from_slice(&tag);
        assert!(matches!(open(&junk, &key(), &limits), Err(WireError::Malformed(_))));
        // Too many objects for the receiver.
        let few = WireLimits { max_objects: 3, ..limits };
        assert!(matches!(open(&bytes, &key(), &few), Err(WireError::Limit { count: 5, max: 3, .. })));
    }

    fn envelope_of(message: Message) -> Envelope {
        Envelope { version: PROTOCOL_VERSION, from: RobotId(2), to: Destination::Broadcast, sequence: 9, message }
    }

    #[test]
    fn refuses_oversized_parts_inside_a_message() {
        use crate::wire::cloud_codec::encode;
        use crate::wire::messages::{KeyframeDescriptors, ObjectCloud, ObjectCloudResponse, WireDescriptor};
        let strict = WireLimits { max_ids: 8, max_cloud_points: 150, ..WireLimits::default() };
        let cloud =
            |n: usize| encode(&(0..n).map(|k| Point3::new(k as f64, 0.0, 0.0)).collect::<Vec<_>>(), 0.1).unwrap().bytes;
        let response = |keyframes: usize, clouds: &[usize]| {
            envelope_of(Message::ObjectCloudResponse(ObjectCloudResponse {
                objects: clouds
                    .iter()
                    .enumerate()
                    .map(|(k, n)| ObjectCloud {
                        id: ObjectId(k as u32),
                        keyframes: (0..keyframes as u32).map(KeyframeId).collect(),
                        cloud: cloud(*n),
                    })
                    .collect(),
            }))
        };
        // Sealed as a foreign sender with the team key would, without the sender's own checks.
        let open_strict = |e: &Envelope| {
            let mut bytes = postcard::to_stdvec(e).unwrap();
            bytes.extend_from_slice(&key().mac(&bytes));
            open(&bytes, &key(), &strict)
        };
        // Within the limits: 8 keyframes per object, 100 + 50 points in all.
        assert!(open_strict(&response(8, &[100, 50])).is_ok());
        let e = open_strict(&response(9, &[10])).unwrap_err();
        assert!(matches!(e, WireError::Limit { what: "keyframes of an object", count: 9, max: 8, .. }), "{e}");
        // Each cloud is within the limit, together they are not.
        let e = open_strict(&response(1, &[100, 51])).unwrap_err();
        assert!(matches!(e, WireError::Limit { what: "cloud points", count: 151, max: 150, .. }), "{e}");
        // A cloud header that cannot be read.
        let mut bad = response(1, &[10]);
        if let Message::ObjectCloudResponse(r) = &mut bad.message {
            r.objects[0].cloud.truncate(12);
        }
        assert!(matches!(open_strict(&bad), Err(WireError::Malformed(_))));
        // A descriptor whose cells do not fill rings × sectors.
        let descriptor = WireDescriptor {
            keyframe: KeyframeId(4),
            world_from_body: (&crate::geometry::Pose3::identity()).into(),
            rings: 20,
            sectors: 60,
            cells: vec![0; 1199],
        };
        let e = open_strict(&envelope_of(Message::KeyframeDescriptors(KeyframeDescriptors {
            descriptors: vec![descriptor],
        })))
        .unwrap_err();
        assert!(e.to_string().contains("1199 cells for 20 × 60"), "{e}");
    }
}
