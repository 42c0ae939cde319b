//! Scenario files: `Scenario::from_toml`, and each loaded robot configuration validates. The body, and what must hold,
//! is `sgm_tests::fuzz_bodies::scenario_config` (`tests/src/fuzz_bodies.rs`).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| sgm_tests::fuzz_bodies::scenario_config(data));
