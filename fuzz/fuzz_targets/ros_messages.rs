//! The node's subscriptions: the bytes of a received message (after TCPROS's length prefix) as
//! each subscribed type — PointCloud2, Image, CameraInfo, Odometry, the team's Envelope —
//! through `bounded::Bounded` (the layout and size check, then rosrust's decoder) and, when
//! that accepts them, through the same checks and conversions as the live node (`Inputs`).
//! The same bytes as a request to the node's Deliver service (`bounded_deliver`).
#![no_main]

use libfuzzer_sys::fuzz_target;
use rosrust::RosMsg;
use sgm_bridge::bounded::{Bounded, Layout};
use sgm_bridge::bounded_deliver::BoundedDeliverReq;
use sgm_bridge::config::RosConfig;
use sgm_bridge::inputs::Inputs;
use sgm_bridge::msg::{nav_msgs, sensor_msgs, sgm_msgs};

fn decode<M: RosMsg + Layout>(framed: &[u8]) -> Option<M> {
    Bounded::<M>::decode_slice(framed).ok().map(|b| b.0)
}

fuzz_target!(|data: &[u8]| {
    let mut framed = (data.len() as u32).to_le_bytes().to_vec();
    framed.extend_from_slice(data);
    let mut config = RosConfig::default();
    config.labels = sgm_bridge::config::LabelSource::Cloud;
    let inputs = Inputs::new(&config, "alpha", 1);
    if let Some(m) = decode::<sensor_msgs::PointCloud2>(&framed) {
        let _ = inputs.cloud(&m);
    }
    if let Some(m) = decode::<sensor_msgs::Image>(&framed) {
        let _ = inputs.image(&m);
    }
    if let Some(m) = decode::<sensor_msgs::CameraInfo>(&framed) {
        let _ = inputs.camera_info(&m);
    }
    if let Some(m) = decode::<nav_msgs::Odometry>(&framed) {
        let _ = inputs.odometry(&m);
    }
    let _ = decode::<sgm_msgs::Envelope>(&framed);
    let _ = BoundedDeliverReq::decode_slice(&framed);
});
