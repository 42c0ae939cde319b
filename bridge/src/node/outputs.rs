//! The node's outputs: markers, path, map, status and tf publishers, and the publications
//! rosrust did not take, counted per output.

use crate::config::RosConfig;
use crate::msg::{nav_msgs, sensor_msgs, std_msgs, tf2_msgs, visualization_msgs};

/// Publications rosrust did not take (a publisher shut down, or a message it could not
/// serialise), per output: counted in the status (`publish_failures`) and logged once per output.
#[derive(Default)]
pub(super) struct PublishFailures(pub(super) std::collections::BTreeMap<&'static str, u64>);

impl PublishFailures {
    pub(super) fn check<E: std::fmt::Display>(&mut self, output: &'static str, sent: Result<(), E>) {
        if let Err(e) = sent {
            let n = self.0.entry(output).or_default();
            *n += 1;
            if *n == 1 {
                tracing::warn!(
                    output,
                    "publishing failed: {e} (further failures counted in the status's publish_failures)"
                );
            }
        }
    }
}

pub(super) struct Publishers {
    pub(super) markers: rosrust::Publisher<visualization_msgs::MarkerArray>,
    pub(super) path: rosrust::Publisher<nav_msgs::Path>,
    pub(super) map: rosrust::Publisher<sensor_msgs::PointCloud2>,
    pub(super) status: rosrust::Publisher<std_msgs::String>,
    pub(super) tf: rosrust::Publisher<tf2_msgs::TFMessage>,
}

impl Publishers {
    pub(super) fn advertise(ros: &RosConfig) -> Result<Self, rosrust::error::Error> {
        let q = ros.queue_size;
        let mut markers = rosrust::publish(&ros.topics.markers, q)?;
        let mut path = rosrust::publish(&ros.topics.path, q)?;
        let mut status = rosrust::publish(&ros.topics.status, q)?;
        // Latched: a late `rostopic echo` or RViz sees the latest at once.
        markers.set_latching(true);
        path.set_latching(true);
        status.set_latching(true);
        Ok(Self {
            markers,
            path,
            map: rosrust::publish(&ros.topics.map, q)?,
            status,
            tf: rosrust::publish(&ros.topics.tf, q)?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn publish_failures_are_counted_per_output() {
        let mut failures = PublishFailures::default();
        failures.check("markers", Ok::<(), String>(()));
        assert!(failures.0.is_empty(), "a publication taken is no failure");
        for _ in 0..3 {
            failures.check("map", Err("publisher shut down"));
        }
        failures.check("status", Err("publisher shut down"));
        assert_eq!(failures.0.get("map"), Some(&3));
        assert_eq!(failures.0.get("status"), Some(&1));
        assert_eq!(serde_json::json!({ "publish_failures": &failures.0 })["publish_failures"]["map"], 3);
    }
}
