//! Scenario files, which hold every section of a robot's configuration and `[ros]`:
//! `Scenario::from_toml` parses and validates without panicking, and a scenario that loads
//! gives each robot a configuration that validates.
#![no_main]

use libfuzzer_sys::fuzz_target;
use sgm_scenarios::scenario::Scenario;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    if let Ok(scenario) = Scenario::from_toml(text, "fuzz.toml", "SGM_FUZZ_UNSET") {
        for k in 0..scenario.robots.len() {
            assert!(scenario.robot_config(k).validate().is_ok());
        }
    }
});
