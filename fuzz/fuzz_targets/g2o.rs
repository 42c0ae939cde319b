//! g2o pose graphs (`sgm optimize`): `read_g2o` on one or two files never panics.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    let (a, b) = text.split_at(text.char_indices().nth(text.len() / 2).map_or(0, |(i, _)| i));
    let _ = sgm_model::optim::g2o::read_g2o(&[&text]);
    let _ = sgm_model::optim::g2o::read_g2o(&[a, b]);
});
