//! The radio's decoder: `wire::open` on (a) the bytes as received, which a foreign radio
//! controls entirely, and (b) the bytes sealed with the team key first — what a teammate with a
//! bug, or an attacker holding the key, could send — so that the fuzzer reaches the postcard
//! decoding of every message type and the limits behind the MAC. Whatever opens must survive
//! encoding and decoding again unchanged (compared as bytes: a NaN is not equal to itself).
#![no_main]

use libfuzzer_sys::fuzz_target;
use sgm_model::wire::{open, TeamKey, WireLimits, MAC_BYTES};

fuzz_target!(|data: &[u8]| {
    let key = TeamKey::from_bytes([7; 32]);
    let limits = WireLimits::default();
    assert!(open(data, &key, &limits).is_err() || data.len() > MAC_BYTES);
    let mut sealed = data.to_vec();
    sealed.extend_from_slice(&key.mac(data));
    if let Ok(envelope) = open(&sealed, &key, &limits) {
        let again = postcard::to_stdvec(&envelope).expect("an opened envelope encodes");
        let back: sgm_model::wire::Envelope = postcard::from_bytes(&again).expect("and decodes");
        assert_eq!(postcard::to_stdvec(&back).expect("encodes again"), again);
    }
});
