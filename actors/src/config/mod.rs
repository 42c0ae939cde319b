//! One robot's configuration: a section per actor (`perception`, `matcher`, `optimiser`,
//! `comms`, each with its checks; `error`: the error and its range checks), loaded with the `config` crate from built-in
//! defaults, then a TOML file, then `SGM__SECTION__KEY` environment variables
//! (`SGM__MATCHER__EDGE_SHARPNESS=2`), and validated before anything starts: an error names the
//! key, the value and the allowed range. The book's configuration reference lists every key.

mod comms;
mod error;
mod matcher;
mod odometry;
mod optimiser;
mod perception;

pub use comms::{
    CommsConfig, PoseUpdatesConfig, PublicTeamKey, Secret, DEFAULT_TEAM_SALT, DEVELOPMENT_TEAM_KEY, PUBLIC_TEAM_KEYS,
};
pub use error::ConfigError;
pub use matcher::{Association, MatcherSection, RelaySection};
pub use odometry::{OdometrySection, OdometrySource};
pub use optimiser::OptimiserConfig;
pub use perception::{default_classes, FusionConfig, TrackerSection};
pub use sgm_model::matching::place_candidates::ScanContextSection;

use error::check;
use serde::{Deserialize, Serialize};
use sgm_model::perception::classes::ClassTable;
use sgm_model::perception::colour_ids::ColourIds;
use sgm_model::perception::label_map::{LabelMap, LabelMapSpec};
use std::path::Path;

/// Everything one robot needs; `[robot]`, `[odometry]`, `[fusion]`, `[classes]`, `[tracker]`, `[matcher]`,
/// `[optimiser]`, `[comms]`, `[persistence]`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RobotConfig {
    pub robot: RobotSection,
    pub odometry: OdometrySection,
    pub fusion: FusionConfig,
    /// Which segmenter's pixel values the label images carry, and how they group onto
    /// `fusion.classes` (`model::perception::label_map`). Default: `identity`.
    pub classes: LabelMapSpec,
    pub tracker: TrackerSection,
    pub matcher: MatcherSection,
    pub optimiser: OptimiserConfig,
    pub comms: CommsConfig,
    pub persistence: PersistenceConfig,
}

/// Map snapshots on disk: the robot's scene graph, pose graph and neighbour knowledge, written
/// atomically every `interval_s` (and at shutdown) to `directory/<robot name>.snapshot`, the
/// previous good one kept as `.snapshot.prev`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PersistenceConfig {
    /// Where snapshots go; "" turns them off. Default "" (in scenarios, `sgm run --out DIR`
    /// uses DIR/snapshots).
    pub directory: String,
    /// Simulated or ROS time between two snapshots, s. Default 30.
    pub interval_s: f64,
    /// At start, continue from the robot's snapshot in `directory` if there is one (the
    /// previous one if the latest is damaged). Default true.
    pub resume: bool,
    /// A snapshot whose content unpacks to more than this is refused, MiB. Default 4096.
    pub max_snapshot_mib: u64,
}

impl Default for PersistenceConfig {
    fn default() -> Self {
        Self { directory: String::new(), interval_s: 30.0, resume: true, max_snapshot_mib: 4096 }
    }
}

impl PersistenceConfig {
    /// Checks every `persistence.*` key against its allowed range.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let p = self;
        check(p.interval_s.is_finite() && p.interval_s >= 1.0, "persistence.interval_s", p.interval_s, "≥ 1 s")?;
        check(
            (1..=1 << 20).contains(&p.max_snapshot_mib),
            "persistence.max_snapshot_mib",
            p.max_snapshot_mib,
            "1 – 1048576",
        )?;
        Ok(())
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RobotSection {
    /// Team-wide unique id (0–65535). Default 0.
    pub id: u16,
    /// Name in logs and reports. Default "robot".
    pub name: String,
}

impl Default for RobotSection {
    fn default() -> Self {
        Self { id: 0, name: "robot".into() }
    }
}

fn load_error(file: Option<&Path>, e: config::ConfigError) -> ConfigError {
    let source_name = file.map(|p| p.display().to_string()).unwrap_or_else(|| "environment".into());
    ConfigError::Load { source_name, message: e.to_string() }
}

/// The layers every SGM configuration is read from: `defaults` (if any), then `file` (TOML,
/// required when given), then `PREFIX__SECTION__KEY` environment variables.
pub fn layered(
    defaults: Option<config::Config>,
    file: Option<&Path>,
    prefix: &str,
) -> Result<config::Config, ConfigError> {
    let mut builder = config::Config::builder();
    if let Some(defaults) = defaults {
        builder = builder.add_source(defaults);
    }
    if let Some(path) = file {
        builder = builder.add_source(config::File::from(path).format(config::FileFormat::Toml).required(true));
    }
    builder.add_source(environment(prefix)).build().map_err(|e| load_error(file, e))
}

/// `PREFIX__SECTION__KEY=value` variables (nested keys joined by `__`, values parsed as TOML
/// scalars), the last layer of every SGM configuration.
pub fn environment(prefix: &str) -> config::Environment {
    config::Environment::with_prefix(prefix).prefix_separator("__").separator("__").try_parsing(true)
}

impl RobotConfig {
    /// Defaults, then `file` (TOML) if given, then `SGM__…` environment variables.
    pub fn load(file: Option<&Path>) -> Result<Self, ConfigError> {
        Self::load_with_env(file, "SGM")
    }

    /// As [`RobotConfig::load`] with another environment prefix (tests use their own).
    pub fn load_with_env(file: Option<&Path>, prefix: &str) -> Result<Self, ConfigError> {
        let defaults = config::Config::try_from(&RobotConfig::default()).map_err(|e| load_error(file, e))?;
        let merged = layered(Some(defaults), file, prefix)?;
        let config: RobotConfig = merged.try_deserialize().map_err(|e| load_error(file, e))?;
        config.validate()?;
        Ok(config)
    }

    /// The validated class table (`fusion.classes`) and the map of the segmenter's pixel values
    /// onto it (`[classes]`).
    pub fn class_tables(&self) -> Result<(ClassTable, LabelMap), ConfigError> {
        let classes = ClassTable::new(self.fusion.classes.clone()).map_err(|e| ConfigError::Invalid {
            key: "fusion.classes".into(),
            value: "(table)".into(),
            allowed: e.to_string(),
        })?;
        let map = LabelMap::new(&self.classes, &classes)?;
        Ok((classes, map))
    }

    /// Colour label images back to the segmenter's pixel values (its palette and
    /// `[classes.palette]`).
    pub fn colour_ids(&self) -> Result<ColourIds, ConfigError> {
        let (classes, _) = self.class_tables()?;
        Ok(ColourIds::new(&self.classes, &classes)?)
    }

    /// Checks every key against its allowed range (section by section: the first error found
    /// is returned).
    pub fn validate(&self) -> Result<(), ConfigError> {
        self.matcher.validate_matching()?;
        self.colour_ids()?;
        self.odometry.validate()?;
        self.fusion.validate()?;
        self.tracker.validate()?;
        self.matcher.validate()?;
        self.optimiser.validate()?;
        self.comms.validate()?;
        self.persistence.validate()?;
        // A snapshot holds the map in the odometry's frame, but not the internal odometry's own
        // state: a restored robot would start a new odometry frame under the old map.
        let p = &self.persistence;
        if self.odometry.source == OdometrySource::Internal && !p.directory.is_empty() && p.resume {
            return Err(ConfigError::Invalid {
                key: "persistence.resume".into(),
                value: "true".into(),
                allowed: "false with odometry.source = \"internal\": the odometry's own state is not in snapshots \
                          yet, so a resumed map would not fit the new odometry's frame (snapshots are still taken; \
                          with resume = false a restart begins a new map and overwrites them)"
                    .into(),
            });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    #[test]
    fn defaults_are_valid_and_round_trip_through_the_loader() {
        RobotConfig::default().validate().unwrap();
        assert_eq!(RobotConfig::load_with_env(None, "SGM_TEST_NONE").unwrap(), RobotConfig::default());
    }

    #[test]
    fn file_then_environment_overrides_and_errors_name_the_key() {
        let mut file = tempfile::NamedTempFile::new().unwrap();
        writeln!(
            file,
            "[robot]\nid = 7\nname = \"husky\"\n[matcher]\nedge_sharpness = 2.5\n[comms]\nmax_keyframes_in_flight = 8"
        )
        .unwrap();
        std::env::set_var("SGM_TEST_A__COMMS__REQUEST_WINDOW_S", "1.5");
        let c = RobotConfig::load_with_env(Some(file.path()), "SGM_TEST_A").unwrap();
        assert_eq!((c.robot.id, c.robot.name.as_str()), (7, "husky"));
        assert_eq!(c.matcher.matching.edge_sharpness, 2.5);
        assert_eq!((c.comms.max_keyframes_in_flight, c.comms.request_window_s), (8, 1.5));
        // One environment variable of a prefix of its own, refused with this message.
        let refused = |prefix: &str, key: &str, value: &str| {
            std::env::set_var(format!("{prefix}__{key}"), value);
            RobotConfig::load_with_env(None, prefix).unwrap_err().to_string()
        };
        for (prefix, key, value, message) in [
            ("SGM_TEST_B", "MATCHER__EDGE_SHARPNESS", "-1", "matcher.edge_sharpness = -1: allowed finite and > 0"),
            ("SGM_TEST_C", "COMMS__MAX_KEYFRAMES_IN_FLIGHT", "0", "comms.max_keyframes_in_flight = 0: allowed ≥ 1"),
            (
                "SGM_TEST_E",
                "MATCHER__SCAN_CONTEXT__MAX_PLACES",
                "1",
                "matcher.scan_context.max_places = 1: allowed ≥ 2",
            ),
            (
                "SGM_TEST_F",
                "TRACKER__TRACKING__MAX_STACK_GAP_M",
                "-1",
                "tracker.tracking.max_stack_gap_m = -1: allowed finite and ≥ 0",
            ),
            (
                "SGM_TEST_G",
                "TRACKER__TRACKING__SIGHTING_MEMORY",
                "0",
                "tracker.tracking.sighting_memory = 0: allowed ≥ 1 (1: the latest sighting alone)",
            ),
            ("SGM_TEST_H", "FUSION__FAR_SIDE_SHIFT", "1.5", "fusion.far_side_shift = 1.5: allowed in [0, 1] (0: off)"),
            (
                "SGM_TEST_I",
                "OPTIMISER__GRAVITY_SIGMA_DEG",
                "-0.1",
                "optimiser.gravity_sigma_deg = -0.1: allowed 0 (off) ≤ x ≤ 10°",
            ),
            (
                "SGM_TEST_J",
                "OPTIMISER__GRAVITY_SIGMA_DEG",
                "11",
                "optimiser.gravity_sigma_deg = 11: allowed 0 (off) ≤ x ≤ 10°",
            ),
            (
                "SGM_TEST_K",
                "TRACKER__TRACKING__GLIMPSE_SPACING_M",
                "-0.5",
                "tracker.tracking.glimpse_spacing_m = -0.5: allowed finite and ≥ 0 (0: only keyframes count)",
            ),
            (
                "SGM_TEST_L",
                "COMMS__KEYFRAME_CLOUD_VOXEL_M",
                "-0.3",
                "comms.keyframe_cloud_voxel_m = -0.3: allowed 0 (the whole scan) or comms.cloud_resolution_m ≤ x ≤ 5 m",
            ),
            (
                "SGM_TEST_N",
                "COMMS__KEYFRAME_CLOUD_VOXEL_M",
                "0.001",
                "comms.keyframe_cloud_voxel_m = 0.001: allowed 0 (the whole scan) or comms.cloud_resolution_m ≤ x ≤ 5 m",
            ),
            (
                "SGM_TEST_M",
                "MATCHER__CLOSURES__REFILL_BYTES_PER_S",
                "-1",
                "matcher.closures.refill_bytes_per_s = -1: allowed ≥ 0 bytes/s (0: a fixed budget)",
            ),
        ] {
            assert_eq!(refused(prefix, key, value), message);
        }
        writeln!(file, "[comms.limits]\nbogus = 1").unwrap();
        let e = RobotConfig::load_with_env(Some(file.path()), "SGM_TEST_D").unwrap_err();
        assert!(e.to_string().contains("bogus"), "{e}");
    }

    /// The internal odometry's state is not in snapshots: resuming a map under it is refused by
    /// key; snapshots without resuming, or no snapshots, are accepted.
    #[test]
    fn resuming_a_snapshot_under_the_internal_odometry_is_refused() {
        let mut c = RobotConfig::default();
        c.odometry.source = OdometrySource::Internal;
        c.validate().unwrap();
        c.persistence.directory = "/var/lib/sgm".into();
        let e = c.validate().unwrap_err().to_string();
        assert!(e.starts_with("persistence.resume = true: allowed false with odometry.source = \"internal\""), "{e}");
        c.persistence.resume = false;
        c.validate().unwrap();
    }
}
