//! Inputs the wire fuzz target stopped on (`fuzz/regressions/wire_envelope/`), run again
//! through what the target checks. The one kept so far is an authenticated KeyframeResponse
//! whose covariance holds NaNs: it opens (the wire layer does not judge numbers), survives
//! re-encoding byte for byte (the target's first version compared values, and NaN ≠ NaN), and
//! its covariance does not unpack — Comms refuses the keyframe as malformed.

use sgm_model::wire::messages::unpack_covariance;
use sgm_model::wire::{open, Message, TeamKey, WireLimits};
use std::path::{Path, PathBuf};

/// Each input kept in `fuzz/regressions/TARGET/`, with its path.
fn regressions(target: &str) -> Vec<(PathBuf, Vec<u8>)> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../fuzz/regressions").join(target);
    let mut inputs: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|entry| {
            let path = entry.unwrap().path();
            let bytes = std::fs::read(&path).unwrap();
            (path, bytes)
        })
        .collect();
    inputs.sort();
    inputs
}

#[test]
fn wire_fuzz_regressions_open_consistently() {
    let key = TeamKey::from_bytes([7; 32]);
    let mut seen = 0;
    for (path, mut sealed) in regressions("wire_envelope") {
        let mac = key.mac(&sealed);
        sealed.extend_from_slice(&mac);
        let Ok(envelope) = open(&sealed, &key, &WireLimits::default()) else { continue };
        seen += 1;
        let again = postcard::to_stdvec(&envelope).unwrap();
        let back: sgm_model::wire::Envelope = postcard::from_bytes(&again).unwrap();
        assert_eq!(postcard::to_stdvec(&back).unwrap(), again, "{}", path.display());
        if let Message::KeyframeResponse(r) = &envelope.message {
            if r.covariance.iter().any(|v| !v.is_finite()) {
                assert!(unpack_covariance(&r.covariance).is_none(), "{}", path.display());
            }
        }
    }
    assert!(seen >= 1, "the NaN-covariance response opens");
}

/// Inputs the cloud codec target stopped on (`fuzz/regressions/cloud_codec/`). The one kept so
/// far declares a resolution of 1.8 × 10³⁰⁷ m: each cell index times it was infinite, and the
/// decoder returned infinite points. It is now refused.
#[test]
fn cloud_fuzz_regressions_never_decode_to_non_finite_points() {
    use sgm_model::wire::cloud_codec::{declared_points, decode_at_most};
    let mut refused = 0;
    for (path, bytes) in regressions("cloud_codec") {
        match decode_at_most(&bytes, 100_000) {
            Ok(points) => {
                assert_eq!(Some(points.len() as u64), declared_points(&bytes), "{}", path.display());
                assert!(points.iter().all(|p| p.coords.iter().all(|v| v.is_finite())), "{}", path.display());
            }
            Err(_) => refused += 1,
        }
    }
    assert!(refused >= 1, "the infinite-coordinates cloud is refused");
}

/// Inputs the PCD target stopped on (`fuzz/regressions/pcd/`): a COUNT of 1 999 999 998 made
/// the reader reserve a column per value (48 GB) before reading any; and, made by hand after
/// it, a 125-byte binary_compressed file declaring 200 million points, whose LZF output
/// (2.4 GB) was reserved before decompressing. Both are now refused by their headers. The
/// third, from the run with overflow checks, ends its header with an empty FIELDS line: a
/// point of no bytes, which the binary reader split the data by (a panic). Refused too.
#[test]
fn pcd_fuzz_regressions_are_refused_before_allocating() {
    let mut seen = 0;
    for (path, bytes) in regressions("pcd") {
        let e = sgm_model::pcd::read_pcd(&bytes).unwrap_err().to_string();
        let expected = if path.ends_with("no_fields_before_data") { "names no field" } else { "at most" };
        assert!(e.contains(expected), "{}: {e}", path.display());
        seen += 1;
    }
    assert_eq!(seen, 3);
}
