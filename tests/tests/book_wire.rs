//! `book/src/wire.md` against the code. The chapter's annotated hex dumps are the bytes the real
//! encoder produces (same key, same sequence number, same message), byte for byte; its message
//! table has the tags postcard writes and the largest envelopes the count limits allow; its
//! limits table lists every limit with the value the code has (public constants and defaults
//! directly, private ones through behaviour or, for literals in actor code, through the source
//! text the number is written in); its rejection table has the order of `open`'s checks and the
//! counter each refusal lands in; and the sizes its prose states are measured with `seal`.
//!
//! Tables and dumps are found by the HTML comment before them (`<!-- limits-table -->`, …).

use nalgebra::{Point3, Vector3};
use sgm_actors::config::{CommsConfig, DEFAULT_TEAM_SALT};
use sgm_actors::protocol::RetryConfig;
use sgm_model::scene_graph::{KeyframeId, LabelId, ObjectId, RobotId};
use sgm_model::wire::cloud_codec::{self, CodecError};
use sgm_model::wire::messages::{
    Alignments, GraphFactorRequest, GraphFactors, KeyframeDescriptors, KeyframePoses, KeyframeRefusal,
    KeyframeRefusalReason, KeyframeRequest, KeyframeResponse, ObjectCloudRequest, ObjectCloudResponse, ObjectData,
    WireAlignment, WireDescriptor, WireFactor, WireFactorKind, WireInformation, WireKeyframePose, WireObject, WirePose,
    DESCRIPTOR_HEIGHT_STEP_M, SIZE_STEP_M,
};
use sgm_model::wire::team_key::{KDF_LANES, KDF_MEMORY_KIB, KDF_PASSES};
use sgm_model::wire::{
    open, seal, Destination, Envelope, Message, MessageKind, RejectionCounts, ReplayError, ReplayWindow, TeamKey,
    WireError, WireLimits, MAC_BYTES, PROTOCOL_VERSION,
};
mod common;

use common::table_cells;
use std::collections::BTreeSet;

const WIRE: &str = include_str!("../../book/src/wire.md");

/// The key of the chapter's examples: bytes 0x00, 0x01, …, 0x1f.
const EXAMPLE_KEY: &str = "000102030405060708090a0b0c0d0e0f101112131415161718191a1b1c1d1e1f";

fn example_key() -> TeamKey {
    TeamKey::from_hex(EXAMPLE_KEY).unwrap()
}

/// Robot 2 (started at t = 1 s, so its sequence numbers start at 1 000 000) broadcasts its
/// first ObjectData: revision 3, the default centroid quantum (2 cm), a tree and a bench.
fn object_data_example() -> Envelope {
    let objects = [
        (ObjectId(7), LabelId(2), Point3::new(12.34, -5.6, 1.1), Vector3::new(0.6, 0.6, 4.0)),
        (ObjectId(12), LabelId(4), Point3::new(3.0, 8.5, 0.44), Vector3::new(1.8, 0.6, 0.9)),
    ];
    Envelope {
        version: PROTOCOL_VERSION,
        from: RobotId(2),
        to: Destination::Broadcast,
        sequence: 1_000_001,
        message: Message::ObjectData(ObjectData::quantise(3, CommsConfig::default().centroid_resolution_mm, objects)),
    }
}

/// Robot 5 (sequence numbers from 2 000 000) asks robot 2 for keyframes 40 and 300 in its 17th
/// envelope.
fn keyframe_request_example() -> Envelope {
    Envelope {
        version: PROTOCOL_VERSION,
        from: RobotId(5),
        to: Destination::Robot(RobotId(2)),
        sequence: 2_000_017,
        message: Message::KeyframeRequest(KeyframeRequest { keyframes: vec![KeyframeId(40), KeyframeId(300)] }),
    }
}

/// The lines after `<!-- marker -->` up to the first blank line after some content.
fn block_after<'a>(marker: &str) -> Vec<&'a str> {
    let tag = format!("<!-- {marker} -->");
    let at = WIRE.find(&tag).unwrap_or_else(|| panic!("book/src/wire.md has no `{tag}`"));
    WIRE[at + tag.len()..].lines().skip_while(|l| l.trim().is_empty()).take_while(|l| !l.trim().is_empty()).collect()
}

/// The bytes of the fenced hex dump after `<!-- marker -->`: lines `OFFSET | HEX … | comment`,
/// each offset equal to the number of bytes before it.
fn hex_dump(marker: &str) -> Vec<u8> {
    let lines = block_after(marker);
    assert!(lines.first().is_some_and(|l| l.starts_with("```")), "{marker}: no fenced block after the marker");
    let mut bytes = Vec::new();
    for line in lines.iter().skip(1).take_while(|l| !l.starts_with("```")) {
        let cells: Vec<&str> = line.split('|').map(str::trim).collect();
        let Ok(offset) = usize::from_str_radix(cells[0], 16) else {
            assert!(cells[0] == "offset", "{marker}: line {line:?} has no hexadecimal offset");
            continue;
        };
        assert_eq!(offset, bytes.len(), "{marker}: line {line:?} has the wrong offset");
        let hex = cells.get(1).unwrap_or_else(|| panic!("{marker}: line {line:?} has no bytes"));
        for token in hex.split_whitespace() {
            assert_eq!(token.len(), 2, "{marker}: {token:?} in {line:?} is not one byte");
            bytes.push(u8::from_str_radix(token, 16).unwrap_or_else(|_| panic!("{marker}: {token:?} is not hex")));
        }
    }
    bytes
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect::<Vec<_>>().join(" ")
}

/// (cells) of every row of the Markdown table after `<!-- marker -->`, header and rule skipped.
fn table_after(marker: &str) -> Vec<Vec<String>> {
    let lines = block_after(marker);
    assert!(lines.len() > 2 && lines[1].starts_with("|---"), "{marker}: no table after the marker");
    lines[2..].iter().map(|l| table_cells(l)).collect()
}

fn check_dump(marker: &str, envelope: &Envelope) {
    let sealed = seal(envelope, &example_key(), &WireLimits::default()).unwrap();
    let written = hex_dump(marker);
    assert_eq!(written, sealed, "{marker}: the encoder writes\n{}\n", hex(&sealed));
    assert_eq!(open(&written, &example_key(), &WireLimits::default()).unwrap(), *envelope);
}

#[test]
fn the_object_data_dump_is_what_the_encoder_writes() {
    let envelope = object_data_example();
    let Message::ObjectData(data) = &envelope.message else { unreachable!() };
    // The quantised values the dump's comments name.
    let expected = [
        WireObject { id: ObjectId(7), label: LabelId(2), centroid: [617, -280, 55], size: [12, 12, 80] },
        WireObject { id: ObjectId(12), label: LabelId(4), centroid: [150, 425, 22], size: [36, 12, 18] },
    ];
    assert_eq!(data.objects, expected);
    check_dump("hexdump: object-data", &envelope);
}

#[test]
fn the_keyframe_request_dump_is_what_the_encoder_writes() {
    check_dump("hexdump: keyframe-request", &keyframe_request_example());
}

#[test]
fn the_example_key_is_the_one_the_chapter_names() {
    assert!(WIRE.contains(EXAMPLE_KEY), "book/src/wire.md does not name the example key {EXAMPLE_KEY}");
}

/// One message of each kind, small.
fn sample(kind: MessageKind) -> Message {
    let pose = WirePose { translation: [0.0; 3], rotation: [0.0, 0.0, 0.0, 1.0] };
    match kind {
        MessageKind::ObjectData => Message::ObjectData(ObjectData { revision: 1, resolution_mm: 20, objects: vec![] }),
        MessageKind::ObjectCloudRequest => Message::ObjectCloudRequest(ObjectCloudRequest { objects: vec![] }),
        MessageKind::ObjectCloudResponse => Message::ObjectCloudResponse(ObjectCloudResponse { objects: vec![] }),
        MessageKind::KeyframeRequest => Message::KeyframeRequest(KeyframeRequest { keyframes: vec![] }),
        MessageKind::KeyframeResponse => Message::KeyframeResponse(KeyframeResponse {
            keyframe: KeyframeId(1),
            stamp: 0.0,
            world_from_body: pose,
            covariance: [0.0; 21],
            cloud: vec![],
        }),
        MessageKind::KeyframeRefusal => {
            Message::KeyframeRefusal(KeyframeRefusal { keyframes: vec![], reason: KeyframeRefusalReason::Unknown })
        }
        MessageKind::KeyframeDescriptors => Message::KeyframeDescriptors(KeyframeDescriptors { descriptors: vec![] }),
        MessageKind::Alignments => Message::Alignments(Alignments { alignments: vec![] }),
        MessageKind::KeyframePoses => Message::KeyframePoses(KeyframePoses { poses: vec![] }),
        MessageKind::GraphFactorRequest => Message::GraphFactorRequest(GraphFactorRequest { from: 0 }),
        MessageKind::GraphFactors => {
            Message::GraphFactors(GraphFactors { from: 0, next: 0, keyframes: vec![], factors: vec![] })
        }
    }
}

/// The largest envelope of `kind` within the count limits (every varint at its longest), or
/// `None` when only `max_envelope_bytes` bounds it (it carries byte strings of any length).
fn largest(kind: MessageKind, limits: &WireLimits) -> Option<Envelope> {
    let ids = |n: usize| vec![KeyframeId(u32::MAX); n];
    let message = match kind {
        MessageKind::ObjectData => Message::ObjectData(ObjectData {
            revision: u32::MAX,
            resolution_mm: u16::MAX,
            objects: vec![
                WireObject {
                    id: ObjectId(u32::MAX),
                    label: LabelId(u16::MAX),
                    centroid: [i32::MIN; 3],
                    size: [u8::MAX; 3]
                };
                limits.max_objects
            ],
        }),
        MessageKind::ObjectCloudRequest => {
            Message::ObjectCloudRequest(ObjectCloudRequest { objects: vec![ObjectId(u32::MAX); limits.max_ids] })
        }
        MessageKind::KeyframeRequest => Message::KeyframeRequest(KeyframeRequest { keyframes: ids(limits.max_ids) }),
        MessageKind::KeyframeRefusal => Message::KeyframeRefusal(KeyframeRefusal {
            keyframes: ids(limits.max_ids),
            reason: KeyframeRefusalReason::Busy,
        }),
        MessageKind::Alignments => Message::Alignments(Alignments {
            alignments: vec![
                WireAlignment {
                    robot: RobotId(u16::MAX),
                    sender_from_robot: WirePose { translation: [1.0; 3], rotation: [0.0, 0.0, 0.0, 1.0] }
                };
                limits.max_ids
            ],
        }),
        MessageKind::KeyframePoses => Message::KeyframePoses(KeyframePoses {
            poses: vec![
                WireKeyframePose { keyframe: KeyframeId(u32::MAX), translation: [1.0; 3], rotation: [0.0; 3] };
                limits.max_ids
            ],
        }),
        MessageKind::GraphFactorRequest => Message::GraphFactorRequest(GraphFactorRequest { from: u32::MAX }),
        // Factors are the larger items: a keyframe is at most 42 bytes, a factor 119.
        MessageKind::GraphFactors => Message::GraphFactors(GraphFactors {
            from: u32::MAX,
            next: u32::MAX,
            keyframes: vec![],
            factors: vec![
                WireFactor {
                    kind: WireFactorKind::InterRobot,
                    from: KeyframeId(u32::MAX),
                    to: KeyframeId(u32::MAX),
                    translation: [1.0; 3],
                    rotation: [0.0; 3],
                    information: WireInformation::Full([1.0; 21]),
                };
                limits.max_ids
            ],
        }),
        MessageKind::ObjectCloudResponse | MessageKind::KeyframeResponse | MessageKind::KeyframeDescriptors => {
            return None
        }
    };
    Some(Envelope {
        version: PROTOCOL_VERSION,
        from: RobotId(u16::MAX),
        to: Destination::Robot(RobotId(u16::MAX)),
        sequence: u64::MAX,
        message,
    })
}

#[test]
fn the_message_table_has_the_true_tags_and_largest_sizes() {
    let key = example_key();
    let limits = WireLimits::default();
    let rows = table_after("messages-table");
    let mut listed = BTreeSet::new();
    for row in &rows {
        let tag: u8 = row[0].parse().unwrap_or_else(|_| panic!("messages-table: tag {:?} is not a number", row[0]));
        let name = row[1].trim_matches('`');
        let kind = *MessageKind::ALL
            .iter()
            .find(|k| k.name() == name)
            .unwrap_or_else(|| panic!("messages-table lists {name}, which is no MessageKind"));
        assert!(listed.insert(kind), "messages-table lists {name} twice");
        // version, from 1, to 0 (broadcast), sequence 1: the tag is byte 4.
        let envelope = Envelope {
            version: PROTOCOL_VERSION,
            from: RobotId(1),
            to: Destination::Broadcast,
            sequence: 1,
            message: sample(kind),
        };
        let bytes = seal(&envelope, &key, &limits).unwrap();
        assert_eq!(bytes[4], tag, "{name}: the book says tag {tag}, postcard writes {}", bytes[4]);
        let cell = row.last().unwrap();
        match (largest(kind, &limits), cell.parse::<usize>()) {
            (Some(e), Ok(written)) => {
                let len = seal(&e, &key, &limits).unwrap().len();
                assert_eq!(len, written, "{name}: the largest envelope is {len} bytes, the book says {written}");
            }
            (None, Err(_)) => assert!(cell.contains("max_envelope_bytes"), "{name}: {cell:?} names no bound"),
            (Some(e), Err(_)) => {
                panic!("{name}: the book gives no largest size; it is {}", seal(&e, &key, &limits).unwrap().len())
            }
            (None, Ok(_)) => panic!("{name}: only max_envelope_bytes bounds it, the book gives a number"),
        }
    }
    for kind in MessageKind::ALL {
        assert!(listed.contains(&kind), "messages-table does not list {}", kind.name());
    }
}

/// The width of the replay window, found by behaviour: the oldest age still accepted, plus one.
fn replay_window() -> u64 {
    let top = 10_000;
    (1..top)
        .find(|age| {
            let mut w = ReplayWindow::default();
            w.accept(top).unwrap();
            matches!(w.accept(top - age), Err(ReplayError::TooOld { .. }))
        })
        .unwrap()
}

/// Bits per axis of the cloud codec's cells, by behaviour: a cloud spanning 2^b cells on an axis
/// is refused from b = AXIS_BITS on.
fn codec_axis_bits() -> u32 {
    (1..40)
        .find(|bits| {
            let far = Point3::new(2f64.powi(*bits as i32), 0.0, 0.0);
            cloud_codec::encode(&[Point3::origin(), far], 1.0) == Err(CodecError::TooLarge)
        })
        .unwrap()
}

/// The shortest passphrase accepted, by behaviour.
fn shortest_passphrase() -> usize {
    (1..100).find(|n| TeamKey::from_passphrase(&"p".repeat(*n), DEFAULT_TEAM_SALT).is_ok()).unwrap()
}

/// The shortest `comms.team_salt` the configuration accepts, by behaviour.
fn shortest_salt() -> usize {
    let accepted = |n: usize| {
        let comms = CommsConfig {
            team_key: "a passphrase of the test".into(),
            team_salt: "s".repeat(n),
            ..CommsConfig::default()
        };
        comms.team_key().is_ok()
    };
    (1..100).find(|n| accepted(*n)).unwrap()
}

/// The smallest `comms.limits.max_envelope_bytes` the configuration accepts, by behaviour.
fn smallest_envelope_limit() -> usize {
    let valid = |n: usize| {
        let mut c = CommsConfig::default();
        c.limits.max_envelope_bytes = n;
        c.validate().is_ok()
    };
    assert!(valid(1 << 20));
    let (mut lo, mut hi) = (0, 1 << 20);
    while lo + 1 < hi {
        let mid = (lo + hi) / 2;
        if valid(mid) {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    hi
}

/// The code's value of a limit, by the name the chapter's table gives it.
fn code_value(name: &str) -> Option<f64> {
    let limits = WireLimits::default();
    let comms = CommsConfig::default();
    let retry = RetryConfig::default();
    Some(match name {
        "PROTOCOL_VERSION" => f64::from(PROTOCOL_VERSION),
        "MAC_BYTES" => MAC_BYTES as f64,
        "WireLimits::max_envelope_bytes" => limits.max_envelope_bytes as f64,
        "WireLimits::max_objects" => limits.max_objects as f64,
        "WireLimits::max_ids" => limits.max_ids as f64,
        "WireLimits::max_cloud_points" => limits.max_cloud_points as f64,
        "CommsConfig::validate" => smallest_envelope_limit() as f64,
        "cloud_codec::MAX_POINTS" => cloud_codec::MAX_POINTS as f64,
        "cloud_codec::AXIS_BITS" => f64::from(codec_axis_bits()),
        "cloud_codec::VERSION" => f64::from(cloud_codec::encode(&[], 0.01).unwrap().bytes[0]),
        "replay::WINDOW" => replay_window() as f64,
        "TeamKey::from_passphrase" => shortest_passphrase() as f64,
        "MIN_SALT_BYTES" => shortest_salt() as f64,
        "KDF_MEMORY_KIB" => f64::from(KDF_MEMORY_KIB),
        "KDF_PASSES" => f64::from(KDF_PASSES),
        "KDF_LANES" => f64::from(KDF_LANES),
        "SIZE_STEP_M" => SIZE_STEP_M,
        // An f32: its shortest decimal form, as written.
        "DESCRIPTOR_HEIGHT_STEP_M" => DESCRIPTOR_HEIGHT_STEP_M.to_string().parse().ok()?,
        "responses::QUEUED_PER_MAX_ID" => (sgm_actors::comms::responses::QUEUED_PER_MAX_ID * limits.max_ids) as f64,
        "PeerConfig::queue" => sgm_bridge::transport::peer::PeerConfig::default().queue as f64,
        "PeerConfig::call_timeout_s" => sgm_bridge::transport::peer::PeerConfig::default().call_timeout_s,
        "call::MAX_HEADER_BYTES" => sgm_bridge::transport::call::MAX_HEADER_BYTES as f64,
        "replay::MAX_INCARNATIONS" => sgm_model::wire::replay::MAX_INCARNATIONS as f64,
        "replay::MAX_RETIRED" => sgm_model::wire::replay::MAX_RETIRED as f64,
        "replay::MAX_JUMP" => sgm_model::wire::replay::MAX_JUMP as f64,
        "replay::RESERVE" => sgm_model::wire::replay::RESERVE as f64,
        "CommsConfig::max_keyframes_in_flight" => comms.max_keyframes_in_flight as f64,
        "CommsConfig::max_keyframes_waiting" => comms.max_keyframes_waiting as f64,
        "CommsConfig::max_keyframes_per_request" => comms.max_keyframes_per_request as f64,
        "CommsConfig::max_responses_per_tick" => comms.max_responses_per_tick as f64,
        "RetryConfig::timeout_s" => retry.timeout_s,
        "RetryConfig::backoff" => retry.backoff,
        "RetryConfig::max_retries" => f64::from(retry.max_retries),
        "RosConfig::max_message_bytes" => sgm_bridge::config::RosConfig::default().max_message_bytes as f64,
        _ => return None,
    })
}

const LIMIT_NAMES: [&str; 34] = [
    "PROTOCOL_VERSION",
    "MAC_BYTES",
    "WireLimits::max_envelope_bytes",
    "WireLimits::max_objects",
    "WireLimits::max_ids",
    "WireLimits::max_cloud_points",
    "CommsConfig::validate",
    "cloud_codec::MAX_POINTS",
    "cloud_codec::AXIS_BITS",
    "cloud_codec::VERSION",
    "replay::WINDOW",
    "TeamKey::from_passphrase",
    "MIN_SALT_BYTES",
    "KDF_MEMORY_KIB",
    "KDF_PASSES",
    "KDF_LANES",
    "SIZE_STEP_M",
    "DESCRIPTOR_HEIGHT_STEP_M",
    "responses::QUEUED_PER_MAX_ID",
    "PeerConfig::queue",
    "PeerConfig::call_timeout_s",
    "call::MAX_HEADER_BYTES",
    "replay::MAX_INCARNATIONS",
    "replay::MAX_RETIRED",
    "replay::MAX_JUMP",
    "replay::RESERVE",
    "CommsConfig::max_keyframes_in_flight",
    "CommsConfig::max_keyframes_waiting",
    "CommsConfig::max_keyframes_per_request",
    "CommsConfig::max_responses_per_tick",
    "RetryConfig::timeout_s",
    "RetryConfig::backoff",
    "RetryConfig::max_retries",
    "RosConfig::max_message_bytes",
];

#[test]
fn the_limits_table_has_the_values_of_the_code() {
    let rows = table_after("limits-table");
    let mut listed = BTreeSet::new();
    for row in &rows {
        // | what | value | name in code | file | beyond it |
        let name = row[2].split('`').nth(1).unwrap_or_else(|| panic!("limits-table: {:?} names no code", row[2]));
        let code =
            code_value(name).unwrap_or_else(|| panic!("limits-table lists `{name}`, which this test does not know"));
        let written: f64 =
            row[1].parse().unwrap_or_else(|_| panic!("limits-table: `{name}` = {:?} is not a number", row[1]));
        assert!((written - code).abs() <= 1e-9 * code.abs(), "`{name}`: the book says {written}, the code {code}");
        assert!(listed.insert(name.to_string()), "limits-table lists `{name}` twice");
    }
    for name in LIMIT_NAMES {
        assert!(listed.contains(name), "limits-table does not list `{name}`");
    }
}

#[test]
fn the_count_limits_refuse_one_more() {
    let key = example_key();
    let limits = WireLimits::default();
    let mut objects = largest(MessageKind::ObjectData, &limits).unwrap();
    if let Message::ObjectData(m) = &mut objects.message {
        m.objects.push(m.objects[0].clone());
    }
    assert!(matches!(seal(&objects, &key, &limits), Err(WireError::Limit { .. })));
    let mut ids = largest(MessageKind::KeyframeRequest, &limits).unwrap();
    if let Message::KeyframeRequest(m) = &mut ids.message {
        m.keyframes.push(KeyframeId(0));
    }
    assert!(matches!(seal(&ids, &key, &limits), Err(WireError::Limit { .. })));
    // Descriptors count as ids.
    let pose = WirePose { translation: [0.0; 3], rotation: [0.0, 0.0, 0.0, 1.0] };
    let d = WireDescriptor { keyframe: KeyframeId(0), world_from_body: pose, rings: 0, sectors: 0, cells: vec![] };
    let many = Envelope {
        version: PROTOCOL_VERSION,
        from: RobotId(1),
        to: Destination::Broadcast,
        sequence: 1,
        message: Message::KeyframeDescriptors(KeyframeDescriptors { descriptors: vec![d; limits.max_ids + 1] }),
    };
    assert!(matches!(seal(&many, &key, &limits), Err(WireError::Limit { .. })));
}

/// The names in backticks in a table cell.
fn code_names(cell: &str) -> Vec<&str> {
    cell.split('`').skip(1).step_by(2).collect()
}

/// The refusal `name` produced through the real API, by an input that also fails every later
/// check of `open` (so the error proves the order), recorded as `Comms` records it.
fn refused(name: &str) -> RejectionCounts {
    let key = example_key();
    let limits = WireLimits::default();
    let sealed_body = |body: &[u8]| {
        let mut bytes = body.to_vec();
        bytes.extend_from_slice(&key.mac(body));
        bytes
    };
    let mut counts = RejectionCounts::default();
    let wire = |bytes: &[u8]| open(bytes, &key, &limits).unwrap_err();
    let error = match name {
        // Zeros: also too large, a bad MAC, version 0 and undecodable.
        "WireError::TooLarge" => wire(&vec![0; limits.max_envelope_bytes + 1]),
        "WireError::TooShort" => wire(&[0; MAC_BYTES]),
        // A wrong tag on a body that has the wrong version and does not decode.
        "WireError::BadMac" => wire(&[[2, 0xff, 0xff].as_slice(), &[0; MAC_BYTES]].concat()),
        "WireError::Version" => wire(&sealed_body(&[2, 0xff, 0xff])),
        "WireError::Malformed" => wire(&sealed_body(&[PROTOCOL_VERSION, 0xff, 0xff])),
        "WireError::Limit" => {
            let mut e = largest(MessageKind::KeyframeRequest, &limits).unwrap();
            if let Message::KeyframeRequest(m) = &mut e.message {
                m.keyframes.push(KeyframeId(0));
            }
            let roomy = WireLimits { max_ids: limits.max_ids + 1, ..limits.clone() };
            wire(&seal(&e, &key, &roomy).unwrap())
        }
        "ReplayError::Duplicate" | "ReplayError::TooOld" => {
            let mut w = ReplayWindow::default();
            w.accept(100).unwrap();
            let again = if name.ends_with("Duplicate") { 100 } else { 1 };
            let e = w.accept(again).unwrap_err();
            assert_eq!(format!("{e:?}").split(['(', ' ']).next(), name.strip_prefix("ReplayError::"));
            counts.record_replay(&e);
            return counts;
        }
        _ => panic!("rejections-table names {name}, which this test cannot produce"),
    };
    let variant = format!("{error:?}");
    assert_eq!(
        variant.split(['(', ' ']).next(),
        name.strip_prefix("WireError::"),
        "{name}: the input meant for it gives {error}; the order of the checks differs"
    );
    counts.record_wire(&error);
    counts
}

#[test]
fn the_rejection_table_has_the_true_order_and_counters() {
    let rows = table_after("rejections-table");
    let order: Vec<&str> =
        rows.iter().flat_map(|r| code_names(&r[2])).filter(|n| n.starts_with("WireError::")).collect();
    let expected = [
        "WireError::TooLarge",
        "WireError::TooShort",
        "WireError::BadMac",
        "WireError::Version",
        "WireError::Malformed",
        "WireError::Limit",
    ];
    assert_eq!(order, expected, "rejections-table: the checks of `open`, in order");
    let mut replay = 0;
    for (k, row) in rows.iter().enumerate() {
        assert_eq!(row[0], (k + 1).to_string(), "rejections-table: steps are numbered in order");
        let counter = code_names(&row[3]);
        for name in code_names(&row[2]) {
            replay += usize::from(name.starts_with("ReplayError::"));
            let counts = refused(name);
            let json = serde_json::to_value(counts).unwrap();
            assert_eq!(counter.len(), 1, "{name}: one counter");
            assert_eq!(json[counter[0]], 1, "{name}: counted as {json}, the book says `{}`", counter[0]);
            assert_eq!(counts.total(), 1);
        }
    }
    assert_eq!(replay, 2, "rejections-table: both replay refusals");
}

/// The sizes the chapter states in its prose.
#[test]
fn the_sizes_in_the_prose() {
    let key = example_key();
    let limits = WireLimits::default();
    let len = |from: u16, to: Destination, sequence: u64, message: Message| {
        let e = Envelope { version: PROTOCOL_VERSION, from: RobotId(from), to, sequence, message };
        seal(&e, &key, &limits).unwrap().len()
    };
    let empty = || Message::KeyframeRequest(KeyframeRequest { keyframes: vec![] });
    // Header = envelope − empty count (1 byte) − MAC.
    let smallest = len(0, Destination::Broadcast, 0, empty());
    let widest = len(u16::MAX, Destination::Robot(RobotId(u16::MAX)), u64::MAX, empty());
    let (header_min, header_max) = (smallest - 1 - MAC_BYTES, widest - 1 - MAC_BYTES);
    // Lines are wrapped: compare with single spaces.
    let prose = WIRE.split_whitespace().collect::<Vec<_>>().join(" ");
    let says = |text: &str| assert!(prose.contains(text), "book/src/wire.md no longer says {text:?}");
    says(&format!("takes {header_min} to {header_max} bytes"));
    says(&format!("the smallest possible envelope is {smallest} bytes"));

    // KeyframeResponse: everything but the tag, the cloud's byte count (1 byte when empty) and
    // the cloud.
    let pose = WirePose { translation: [1.0; 3], rotation: [0.0, 0.0, 0.0, 1.0] };
    let response = |keyframe: u32| {
        Message::KeyframeResponse(KeyframeResponse {
            keyframe: KeyframeId(keyframe),
            stamp: 1.0,
            world_from_body: pose,
            covariance: [1.0; 21],
            cloud: vec![],
        })
    };
    let fixed = |keyframe| len(0, Destination::Broadcast, 0, response(keyframe)) - header_min - MAC_BYTES - 1;
    says(&format!("has {} to {} fixed bytes", fixed(0), fixed(u32::MAX)));

    // One descriptor of the default shape.
    let descriptor = |keyframe: u32| {
        let config = sgm_model::matching::scan_context::ScanContextConfig::default();
        let d = WireDescriptor {
            keyframe: KeyframeId(keyframe),
            world_from_body: pose,
            rings: config.rings as u8,
            sectors: config.sectors as u8,
            cells: vec![7; config.rings * config.sectors],
        };
        let one = Message::KeyframeDescriptors(KeyframeDescriptors { descriptors: vec![d] });
        let none = Message::KeyframeDescriptors(KeyframeDescriptors { descriptors: vec![] });
        len(0, Destination::Broadcast, 0, one) - len(0, Destination::Broadcast, 0, none)
    };
    says(&format!("costs {} to {} bytes per descriptor", descriptor(0), descriptor(u32::MAX)));

    // The worked examples' totals.
    let object_data = seal(&object_data_example(), &key, &limits).unwrap().len();
    says(&format!("The whole envelope is {object_data} bytes"));
    let request = seal(&keyframe_request_example(), &key, &limits).unwrap().len();
    says(&format!("The envelope is {request} bytes"));
}
