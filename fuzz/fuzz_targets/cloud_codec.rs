//! Object and keyframe clouds from the radio: `cloud_codec::decode_at_most` never allocates
//! beyond its limit, never panics, and agrees with the header's declared count.
#![no_main]

use libfuzzer_sys::fuzz_target;
use sgm_model::wire::cloud_codec::{declared_points, decode_at_most};

fuzz_target!(|data: &[u8]| {
    if let Ok(points) = decode_at_most(data, 100_000) {
        assert_eq!(Some(points.len() as u64), declared_points(data));
        assert!(points.iter().all(|p| p.coords.iter().all(|v| v.is_finite())));
    }
});
