//! PCD files (ascii, binary, binary_compressed): `pcd::read_pcd` never panics.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = sgm_model::pcd::read_pcd(data);
});
