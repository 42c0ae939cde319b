//! One robot's configuration: a section per actor, loaded with the `config` crate from built-in
//! defaults, then a TOML file, then `SGM__SECTION__KEY` environment variables
//! (`SGM__MATCHER__EDGE_SHARPNESS=2`), and validated before anything starts: an error names the
//! key, the value and the allowed range. The book's configuration reference lists every key.

use crate::protocol::RetryConfig;
use serde::{Deserialize, Serialize};
pub use sgm_model::matching::place_candidates::ScanContextSection;
use sgm_model::matching::MatcherConfig;
use sgm_model::perception::classes::{ClassSpec, ClassTable};
use sgm_model::perception::colour_ids::{ColourIds, PaletteError};
use sgm_model::perception::icp::IcpConfig;
use sgm_model::perception::keyframes::KeyframeConfig;
use sgm_model::perception::label_map::{LabelMap, LabelMapError, LabelMapSpec};
use sgm_model::perception::label_vote::LabelVote;
use sgm_model::perception::loop_closure::LoopClosureConfig;
use sgm_model::perception::structure_check::StructureCheck;
use sgm_model::perception::tracker::TrackerConfig;
use sgm_model::scene_graph::CloudStoreConfig;
use sgm_model::wire::team_key::{TeamKeyError, MIN_SALT_BYTES};
use sgm_model::wire::{TeamKey, WireLimits};
use std::path::{Path, PathBuf};

/// Everything one robot needs; `[robot]`, `[fusion]`, `[classes]`, `[tracker]`, `[matcher]`,
/// `[optimiser]`, `[comms]`, `[persistence]`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RobotConfig {
    pub robot: RobotSection,
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

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FusionConfig {
    /// Points of one class closer than this join one cluster, m. Default 0.3.
    pub cluster_tolerance_m: f64,
    /// LiDAR returns farther than this are ignored, m. Default 60.
    pub max_range_m: f64,
    /// Objects are clustered from labelled returns within this range only (farther ones keep
    /// their labels in the keyframe cloud): distant objects are seen by too few, too sparse
    /// returns for a trustworthy centroid, m. Default 30.
    pub object_range_m: f64,
    /// Clusters flatter than this are not objects: labels that bled onto the ground behind an
    /// object in the image, m. Default 0.2.
    pub min_object_height_m: f64,
    /// Each labelled return takes the most common class among its neighbours first: labels
    /// that bled across depth edges in the image go back to what surrounds them in 3D
    /// (`model::perception::label_vote`).
    pub label_vote: LabelVote,
    /// The class table. Default: [`default_classes`].
    pub classes: Vec<ClassSpec>,
}

impl Default for FusionConfig {
    fn default() -> Self {
        Self {
            cluster_tolerance_m: 0.3,
            max_range_m: 60.0,
            object_range_m: 30.0,
            min_object_height_m: 0.2,
            label_vote: LabelVote::default(),
            classes: default_classes(),
        }
    }
}

/// The built-in class table: the outdoor and indoor objects of the paper's experiments.
pub fn default_classes() -> Vec<ClassSpec> {
    let class = |name: &str, id: u16, colour: [u8; 3], matchable: bool, object: bool, max_extent_m: f64| ClassSpec {
        name: name.into(),
        id,
        colour,
        matchable,
        object,
        min_points: 5,
        max_points: 50_000,
        max_extent_m,
    };
    vec![
        class("ground", 0, [120, 120, 120], false, false, 1e3),
        class("wall", 1, [200, 200, 200], false, false, 1e3),
        class("tree", 2, [30, 140, 40], true, true, 8.0),
        class("lamp_post", 3, [250, 220, 60], true, true, 6.0),
        class("bench", 4, [150, 90, 40], true, true, 3.0),
        class("trash_can", 5, [60, 60, 200], true, true, 1.5),
        class("chair", 6, [220, 80, 80], true, true, 1.5),
        class("table", 7, [180, 130, 70], true, true, 3.0),
        class("bookshelf", 8, [120, 60, 160], true, true, 3.0),
        class("car", 9, [40, 160, 200], false, true, 6.0),
    ]
}

#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TrackerSection {
    pub keyframes: KeyframeConfig,
    pub tracking: TrackerConfig,
    pub loop_closure: LoopClosureConfig,
    /// How much of the semantic layer the map holds (old scans compacted, then evicted).
    pub cloud_store: CloudStoreConfig,
}

/// Inter-robot association.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Association {
    /// Object-graph matching, then object-cloud and keyframe ICP (the paper).
    #[default]
    Objects,
    /// None: robots exchange object data but never align (the evaluation's "no inter-robot
    /// association" baseline).
    None,
    /// Scan Context descriptors of every keyframe instead of objects, then coarse-to-fine
    /// keyframe ICP (the evaluation's Swarm-SC baseline, paper §V-B).
    ScanContext,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MatcherSection {
    /// How robots find each other. Default `objects`.
    pub association: Association,
    /// Object-graph matching (paper §IV-C).
    #[serde(flatten)]
    pub matching: MatcherConfig,
    /// The Scan Context baseline (used with `association = "scan_context"` only).
    pub scan_context: ScanContextSection,
    /// Matched objects needed before object clouds are requested. Default 4.
    pub min_matched_objects: usize,
    /// Matching against one neighbour is tried at most this often (on new local objects or
    /// new neighbour data), s. Default 2.
    pub match_interval_s: f64,
    /// Object-cloud ICP (paper §IV-D).
    pub icp: IcpConfig,
    /// Neighbour keyframes around each observing keyframe that are requested (paper: ±5).
    /// Default 5.
    pub keyframe_neighbourhood: usize,
    /// Neighbour keyframes registered per alignment round, at most (spread evenly over those
    /// the neighbourhood names): bounds radio bytes and ICP time. Default 8 (16 cost twice the bytes for
    /// the same alignments: book, evaluation chapter).
    pub max_keyframes_per_alignment: usize,
    /// Voxel size of keyframe-to-keyframe ICP (`icp.voxel_m` is for object clouds), m.
    /// Default 0.3.
    pub keyframe_voxel_m: f64,
    /// Iteration cap of keyframe-to-keyframe ICP (it starts from the object-cloud estimate and
    /// converges in a few; a wrong match is refuted sooner). Default 20.
    pub keyframe_max_iterations: usize,
    /// Verification of keyframe registrations with the ground left out
    /// (`model::perception::structure_check`).
    pub structure_check: StructureCheck,
    /// A keyframe registration counts when this fraction of its structure points agree.
    /// Default 0.3.
    pub min_structure_agreement: f64,
    /// Registrations that must count before an alignment is accepted; fewer refute the object
    /// match (the neighbour goes back to waiting for object data). Default 2.
    pub min_keyframe_factors: usize,
    /// Neighbour keyframes (clouds) held per neighbour between rounds, at most: kept so that a
    /// round after a refutation need not ask for them again; the lowest ids outside the current
    /// round go first, and all go once the neighbour is aligned. Default 16 (two rounds; a
    /// keyframe is about 370 KB as held, and a pair refuted again and again fills its cap).
    pub max_held_keyframes: usize,
}

impl Default for MatcherSection {
    fn default() -> Self {
        Self {
            association: Association::Objects,
            matching: MatcherConfig::default(),
            scan_context: ScanContextSection::default(),
            min_matched_objects: 4,
            match_interval_s: 2.0,
            icp: IcpConfig { max_correspondence_distance_m: 1.0, voxel_m: 0.1, ..IcpConfig::default() },
            keyframe_neighbourhood: 5,
            max_keyframes_per_alignment: 8,
            keyframe_voxel_m: 0.3,
            keyframe_max_iterations: 20,
            structure_check: StructureCheck::default(),
            min_structure_agreement: 0.3,
            min_keyframe_factors: 2,
            max_held_keyframes: 16,
        }
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct OptimiserConfig {
    /// Odometry noise per keyframe step, standard deviations (rotation rad ×3, translation m ×3).
    /// Default 0.01 rad, 0.05 m.
    pub odometry_sigmas: [f64; 6],
    /// Optimise after this many new keyframes (1: every keyframe), and at once on a loop closure
    /// or new inter-robot constraints. Default 10.
    pub every_keyframes: usize,
    /// Reject wrong loop closures and inter-robot factors: graduated non-convexity with
    /// truncated least squares over them (odometry and priors are trusted), decided again at
    /// every solve. false: plain least squares. Default true.
    pub reject_outliers: bool,
}

impl Default for OptimiserConfig {
    fn default() -> Self {
        Self { odometry_sigmas: [0.01, 0.01, 0.01, 0.05, 0.05, 0.05], every_keyframes: 10, reject_outliers: true }
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CommsConfig {
    /// Team secret: 64 hex digits (the key's 32 bytes), or a passphrase of ≥ 12 characters
    /// (derived with argon2id and `team_salt`). Default: [`DEVELOPMENT_TEAM_KEY`], which is
    /// public: `sgm ros` refuses it and every other key of [`PUBLIC_TEAM_KEYS`] unless started
    /// with `--development-key`. `Debug` prints `<redacted>`.
    pub team_key: Secret,
    /// A file holding the team key instead (64 hex digits or a passphrase; one trailing newline
    /// is stripped), readable and writable by its owner only (mode 600, like an ssh private
    /// key). A relative path is resolved against the current directory of the process. Not
    /// allowed together with a `team_key` other than the default. Default: none.
    pub team_key_file: Option<PathBuf>,
    /// The salt of passphrase derivation (argon2id), at least 8 bytes. Not secret, but give each
    /// team its own, so that a precomputed table of passphrases for the default salt is no use.
    /// Hex keys do not use it. Default "sgm team".
    pub team_salt: String,
    /// Shortest interval between two ObjectData broadcasts, s. Default 2.
    pub object_data_interval_s: f64,
    /// ObjectData is broadcast again, unchanged, after this long without a broadcast, so a lost
    /// one is made good and neighbours keep hearing us (keep it below `link_timeout_s`); a
    /// neighbour first heard or back from silence gets it at the next `object_data_interval_s`,
    /// s. Default 10.
    pub object_data_refresh_s: f64,
    /// Objects whose centroid moved farther than this count as a significant change, m.
    /// Default 0.5.
    pub significant_move_m: f64,
    /// Centroid quantum of ObjectData, mm. Default 20.
    pub centroid_resolution_mm: u16,
    /// Keyframe requests are coalesced over this window before being sent, s. Default 0.5.
    pub request_window_s: f64,
    /// Keyframes requested but not yet received, per neighbour, at most. Default 32.
    pub max_keyframes_in_flight: usize,
    /// Keyframes waiting to be requested, per neighbour, at most; more are reported unavailable
    /// (reason busy) to the Matcher at once. Default 1024.
    pub max_keyframes_waiting: usize,
    /// Keyframe ids per KeyframeRequest, at most. Default 16.
    pub max_keyframes_per_request: usize,
    /// Keyframe responses sent per tick, at most (the outgoing budget). Default 16.
    pub max_responses_per_tick: usize,
    /// A neighbour silent for this long is down: requests to it wait, neither retried nor given
    /// up, and are asked afresh when it is heard again, s. Default 30.
    pub link_timeout_s: f64,
    /// Cloud quantum of keyframe responses, m. Default 0.01.
    pub cloud_resolution_m: f64,
    pub retry: RetryConfig,
    pub limits: WireLimits,
}

/// The key every build knows: fine in simulation, never in the field.
pub const DEVELOPMENT_TEAM_KEY: &str = "sgm development team key - replace me";

/// The default `comms.team_salt`.
pub const DEFAULT_TEAM_SALT: &str = "sgm team";

/// A team key anyone can read: the default, and every key printed in the book, the scenario
/// library or the shipped ROS configurations (a test scans them and fails on one missing
/// here). `sgm ros` refuses them without `--development-key`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PublicTeamKey {
    /// As written: 64 hex digits or a passphrase.
    pub text: &'static str,
    /// Where it is published.
    pub published: &'static str,
}

/// Every public team key (see [`PublicTeamKey`]).
pub const PUBLIC_TEAM_KEYS: &[PublicTeamKey] = &[
    PublicTeamKey { text: DEVELOPMENT_TEAM_KEY, published: "the built-in default (DEVELOPMENT_TEAM_KEY)" },
    PublicTeamKey {
        text: "sgm example fleet - replace this passphrase",
        published: "the example configurations of earlier versions of the ROS package (bridge/ros/sgm/config)",
    },
    PublicTeamKey {
        text: "correct horse battery staple",
        published: "the book's configuration example (book/src/configuration.md)",
    },
    PublicTeamKey {
        text: "000102030405060708090a0b0c0d0e0f101112131415161718191a1b1c1d1e1f",
        published: "the book's worked envelope example (book/src/wire.md)",
    },
];

/// A secret string from the configuration: (de)serialised as the plain string (the
/// configuration layers need it), never shown by `Debug`.
#[derive(Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(transparent)]
pub struct Secret(String);

impl Secret {
    pub fn new(text: impl Into<String>) -> Self {
        Self(text.into())
    }

    /// The secret itself: for deriving the key, never for printing.
    pub fn expose(&self) -> &str {
        &self.0
    }
}

impl From<&str> for Secret {
    fn from(text: &str) -> Self {
        Self(text.into())
    }
}

impl std::fmt::Debug for Secret {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("<redacted>")
    }
}

impl Default for CommsConfig {
    fn default() -> Self {
        Self {
            team_key: DEVELOPMENT_TEAM_KEY.into(),
            team_key_file: None,
            team_salt: DEFAULT_TEAM_SALT.into(),
            object_data_interval_s: 2.0,
            object_data_refresh_s: 10.0,
            significant_move_m: 0.5,
            centroid_resolution_mm: 20,
            request_window_s: 0.5,
            max_keyframes_in_flight: 32,
            max_keyframes_waiting: 1024,
            max_keyframes_per_request: 16,
            max_responses_per_tick: 16,
            link_timeout_s: 30.0,
            cloud_resolution_m: 0.01,
            retry: RetryConfig::default(),
            limits: WireLimits::default(),
        }
    }
}

impl CommsConfig {
    /// The team key: read from `team_key_file` if it is set, else `team_key`; a passphrase is
    /// derived with `team_salt` (once per process: [`TeamKey::from_passphrase`]).
    pub fn team_key(&self) -> Result<TeamKey, ConfigError> {
        check(
            self.team_salt.len() >= MIN_SALT_BYTES,
            "comms.team_salt",
            format!("{:?}", self.team_salt),
            "at least 8 bytes (argon2's shortest salt); set a value of the team's own",
        )?;
        let invalid = |key: &str, value: String, e: TeamKeyError| ConfigError::Invalid {
            key: key.into(),
            value,
            allowed: e.to_string(),
        };
        match &self.team_key_file {
            Some(path) => {
                if self.team_key.expose() != DEVELOPMENT_TEAM_KEY {
                    return Err(ConfigError::KeyFile {
                        path: path.display().to_string(),
                        problem: "comms.team_key is set too: give the key in one place only (remove comms.team_key)"
                            .into(),
                    });
                }
                let text = read_key_file(path)?;
                TeamKey::from_text(text.expose(), &self.team_salt)
                    .map_err(|e| invalid("comms.team_key_file", path.display().to_string(), e))
            }
            None => TeamKey::from_text(self.team_key.expose(), &self.team_salt)
                .map_err(|e| invalid("comms.team_key", "<secret>".into(), e)),
        }
    }

    /// The entry of [`PUBLIC_TEAM_KEYS`] the team key is, if any. Compared on the key itself,
    /// so a hex spelling of a public passphrase's key is caught, with this team's salt or the
    /// default one.
    pub fn public_team_key(&self) -> Result<Option<&'static PublicTeamKey>, ConfigError> {
        let key = self.team_key()?;
        let salts = [self.team_salt.as_str(), DEFAULT_TEAM_SALT];
        Ok(PUBLIC_TEAM_KEYS
            .iter()
            .find(|public| salts.iter().any(|salt| TeamKey::from_text(public.text, salt).is_ok_and(|k| k == key))))
    }
}

/// The content of a team key file, checked: a regular file, private to its owner, not empty.
fn read_key_file(path: &Path) -> Result<Secret, ConfigError> {
    let refused = |problem: String| ConfigError::KeyFile { path: path.display().to_string(), problem };
    if path.as_os_str().is_empty() {
        return Err(refused("an empty path names no file".into()));
    }
    let metadata = std::fs::metadata(path).map_err(|e| refused(format!("cannot be read: {e}")))?;
    if !metadata.is_file() {
        return Err(refused("is not a file".into()));
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let mode = metadata.permissions().mode() & 0o777;
        if mode & 0o077 != 0 {
            return Err(refused(format!(
                "its mode {mode:03o} lets group or others at the team key; `chmod 600 {}` makes it its owner's alone",
                path.display()
            )));
        }
    }
    let text = std::fs::read_to_string(path).map_err(|e| refused(format!("cannot be read: {e}")))?;
    let text = match text.strip_suffix('\n') {
        Some(line) => line.strip_suffix('\r').unwrap_or(line),
        None => &text,
    };
    if text.is_empty() {
        return Err(refused("is empty: it must hold the team key (64 hex digits or a passphrase)".into()));
    }
    Ok(Secret::new(text))
}

/// A configuration that cannot be loaded or is out of range.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ConfigError {
    #[error("{source_name}: {message}")]
    Load { source_name: String, message: String },
    #[error("{key} = {value}: allowed {allowed}")]
    Invalid { key: String, value: String, allowed: String },
    #[error("comms.team_key_file = {path}: {problem}")]
    KeyFile { path: String, problem: String },
    /// `[classes]`: the message names the key (`classes.map.chair: …`).
    #[error(transparent)]
    Classes(#[from] LabelMapError),
    /// `[classes.palette]`: the message names the colour.
    #[error(transparent)]
    Palette(#[from] PaletteError),
}

fn check(ok: bool, key: &str, value: impl ToString, allowed: &str) -> Result<(), ConfigError> {
    if ok {
        Ok(())
    } else {
        Err(ConfigError::Invalid { key: key.into(), value: value.to_string(), allowed: allowed.into() })
    }
}

fn positive(v: f64) -> bool {
    v.is_finite() && v > 0.0
}

fn non_negative(v: f64) -> bool {
    v.is_finite() && v >= 0.0
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

    /// Checks every key against its allowed range.
    pub fn validate(&self) -> Result<(), ConfigError> {
        self.matcher.matching.validate().map_err(|e| ConfigError::Invalid {
            key: format!("matcher.{}", e.key),
            value: e.value,
            allowed: e.allowed.into(),
        })?;
        self.colour_ids()?;
        let f = &self.fusion;
        check(positive(f.cluster_tolerance_m), "fusion.cluster_tolerance_m", f.cluster_tolerance_m, "finite and > 0")?;
        check(positive(f.max_range_m), "fusion.max_range_m", f.max_range_m, "finite and > 0")?;
        check(positive(f.object_range_m), "fusion.object_range_m", f.object_range_m, "finite and > 0")?;
        check(
            non_negative(f.min_object_height_m),
            "fusion.min_object_height_m",
            f.min_object_height_m,
            "finite and ≥ 0",
        )?;
        check(non_negative(f.label_vote.voxel_m), "fusion.label_vote.voxel_m", f.label_vote.voxel_m, "finite and ≥ 0")?;
        let k = &self.tracker.keyframes;
        check(positive(k.min_translation_m), "tracker.keyframes.min_translation_m", k.min_translation_m, "> 0")?;
        check(positive(k.min_rotation_rad), "tracker.keyframes.min_rotation_rad", k.min_rotation_rad, "> 0")?;
        let t = &self.tracker.tracking;
        check(
            positive(t.max_track_distance_m),
            "tracker.tracking.max_track_distance_m",
            t.max_track_distance_m,
            "> 0",
        )?;
        check(positive(t.search_radius_m), "tracker.tracking.search_radius_m", t.search_radius_m, "> 0")?;
        check(t.confirm_after >= 1, "tracker.tracking.confirm_after", t.confirm_after, "≥ 1")?;
        let l = &self.tracker.loop_closure;
        check(positive(l.search_radius_m), "tracker.loop_closure.search_radius_m", l.search_radius_m, "> 0")?;
        check(non_negative(l.time_gap_s), "tracker.loop_closure.time_gap_s", l.time_gap_s, "finite and ≥ 0")?;
        check(positive(l.max_rmse_m), "tracker.loop_closure.max_rmse_m", l.max_rmse_m, "> 0")?;
        check(
            non_negative(l.min_interval_s),
            "tracker.loop_closure.min_interval_s",
            l.min_interval_s,
            "finite and ≥ 0",
        )?;
        let c = &self.tracker.cloud_store;
        for (key, v) in [
            ("tracker.cloud_store.budget_mb", c.budget_mb),
            ("tracker.cloud_store.redundant_within_m", c.redundant_within_m),
        ] {
            check(non_negative(v), key, v, "finite and ≥ 0")?;
        }
        for (key, v) in [
            ("tracker.cloud_store.object_voxel_m", c.object_voxel_m),
            ("tracker.cloud_store.structure_voxel_m", c.structure_voxel_m),
        ] {
            check(positive(v), key, v, "finite and > 0")?;
        }
        let m = &self.matcher;
        check(m.min_matched_objects >= 3, "matcher.min_matched_objects", m.min_matched_objects, "≥ 3")?;
        check(
            positive(m.icp.max_correspondence_distance_m),
            "matcher.icp.max_correspondence_distance_m",
            m.icp.max_correspondence_distance_m,
            "> 0",
        )?;
        let sc = &m.scan_context;
        let shape = (1..=255).contains(&sc.descriptor.rings) && (1..=255).contains(&sc.descriptor.sectors);
        check(shape, "matcher.scan_context.rings", sc.descriptor.rings, "rings and sectors 1–255")?;
        check(shape, "matcher.scan_context.sectors", sc.descriptor.sectors, "rings and sectors 1–255")?;
        let r = sc.descriptor.max_range_m;
        check(positive(r), "matcher.scan_context.max_range_m", r, "> 0")?;
        let h = sc.descriptor.height_offset_m;
        check(h.is_finite(), "matcher.scan_context.height_offset_m", h, "finite")?;
        let d = sc.max_distance;
        check(d.is_finite() && (0.0..=1.0).contains(&d), "matcher.scan_context.max_distance", d, "0–1")?;
        let c = sc.ring_key_candidates;
        check(c >= 1, "matcher.scan_context.ring_key_candidates", c, "≥ 1")?;
        let c = sc.coarse_correspondence_m;
        check(positive(c), "matcher.scan_context.coarse_correspondence_m", c, "> 0")?;
        check(sc.max_places >= 2, "matcher.scan_context.max_places", sc.max_places, "≥ 2")?;
        check(m.keyframe_neighbourhood <= 50, "matcher.keyframe_neighbourhood", m.keyframe_neighbourhood, "0–50")?;
        check(
            m.keyframe_voxel_m.is_finite() && (0.0..=5.0).contains(&m.keyframe_voxel_m),
            "matcher.keyframe_voxel_m",
            m.keyframe_voxel_m,
            "0 ≤ x ≤ 5 m",
        )?;
        check(
            (0.0..=1.0).contains(&m.min_structure_agreement),
            "matcher.min_structure_agreement",
            m.min_structure_agreement,
            "0 ≤ x ≤ 1",
        )?;
        check(
            m.match_interval_s.is_finite() && (0.0..=3600.0).contains(&m.match_interval_s),
            "matcher.match_interval_s",
            m.match_interval_s,
            "0 ≤ x ≤ 3600 s",
        )?;
        check(
            (1..=1000).contains(&m.keyframe_max_iterations),
            "matcher.keyframe_max_iterations",
            m.keyframe_max_iterations,
            "1 ≤ x ≤ 1000",
        )?;
        check(m.min_keyframe_factors >= 1, "matcher.min_keyframe_factors", m.min_keyframe_factors, "≥ 1")?;
        check(
            m.max_keyframes_per_alignment >= m.min_keyframe_factors,
            "matcher.max_keyframes_per_alignment",
            m.max_keyframes_per_alignment,
            "≥ matcher.min_keyframe_factors",
        )?;
        check(
            m.max_held_keyframes >= m.max_keyframes_per_alignment,
            "matcher.max_held_keyframes",
            m.max_held_keyframes,
            "≥ matcher.max_keyframes_per_alignment",
        )?;
        let sc = &m.structure_check;
        for (key, v) in [
            ("matcher.structure_check.voxel_m", sc.voxel_m),
            ("matcher.structure_check.ground_clearance_m", sc.ground_clearance_m),
            ("matcher.structure_check.inlier_m", sc.inlier_m),
        ] {
            check(v.is_finite() && (0.0..=10.0).contains(&v), key, v, "0 ≤ x ≤ 10 m")?;
        }
        let o = &self.optimiser;
        check(
            o.odometry_sigmas.iter().all(|s| positive(*s)),
            "optimiser.odometry_sigmas",
            format!("{:?}", o.odometry_sigmas),
            "six values > 0",
        )?;
        check(o.every_keyframes >= 1, "optimiser.every_keyframes", o.every_keyframes, "≥ 1")?;
        let c = &self.comms;
        c.team_key()?;
        check(positive(c.object_data_interval_s), "comms.object_data_interval_s", c.object_data_interval_s, "> 0")?;
        check(
            c.object_data_refresh_s.is_finite() && c.object_data_refresh_s >= c.object_data_interval_s,
            "comms.object_data_refresh_s",
            c.object_data_refresh_s,
            "finite, ≥ comms.object_data_interval_s",
        )?;
        check(positive(c.significant_move_m), "comms.significant_move_m", c.significant_move_m, "> 0")?;
        check(c.centroid_resolution_mm >= 1, "comms.centroid_resolution_mm", c.centroid_resolution_mm, "1–65535")?;
        check(
            c.request_window_s.is_finite() && c.request_window_s >= 0.0,
            "comms.request_window_s",
            c.request_window_s,
            "≥ 0",
        )?;
        check(c.max_keyframes_in_flight >= 1, "comms.max_keyframes_in_flight", c.max_keyframes_in_flight, "≥ 1")?;
        check(c.max_keyframes_waiting >= 1, "comms.max_keyframes_waiting", c.max_keyframes_waiting, "≥ 1")?;
        check(
            (1..=c.limits.max_ids).contains(&c.max_keyframes_per_request),
            "comms.max_keyframes_per_request",
            c.max_keyframes_per_request,
            "1 – comms.limits.max_ids",
        )?;
        check(c.max_responses_per_tick >= 1, "comms.max_responses_per_tick", c.max_responses_per_tick, "≥ 1")?;
        check(positive(c.link_timeout_s), "comms.link_timeout_s", c.link_timeout_s, "> 0")?;
        check(positive(c.cloud_resolution_m), "comms.cloud_resolution_m", c.cloud_resolution_m, "> 0")?;
        check(positive(c.retry.timeout_s), "comms.retry.timeout_s", c.retry.timeout_s, "> 0")?;
        check(c.retry.backoff.is_finite() && c.retry.backoff >= 1.0, "comms.retry.backoff", c.retry.backoff, "≥ 1")?;
        check(
            c.limits.max_envelope_bytes >= 1024,
            "comms.limits.max_envelope_bytes",
            c.limits.max_envelope_bytes,
            "≥ 1024",
        )?;
        let p = &self.persistence;
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
        std::env::set_var("SGM_TEST_B__MATCHER__EDGE_SHARPNESS", "-1");
        let e = RobotConfig::load_with_env(None, "SGM_TEST_B").unwrap_err();
        assert_eq!(e.to_string(), "matcher.edge_sharpness = -1: allowed finite and > 0");
        std::env::set_var("SGM_TEST_C__COMMS__MAX_KEYFRAMES_IN_FLIGHT", "0");
        let e = RobotConfig::load_with_env(None, "SGM_TEST_C").unwrap_err();
        assert_eq!(e.to_string(), "comms.max_keyframes_in_flight = 0: allowed ≥ 1");
        std::env::set_var("SGM_TEST_E__MATCHER__SCAN_CONTEXT__MAX_PLACES", "1");
        let e = RobotConfig::load_with_env(None, "SGM_TEST_E").unwrap_err();
        assert_eq!(e.to_string(), "matcher.scan_context.max_places = 1: allowed ≥ 2");
        writeln!(file, "[comms.limits]\nbogus = 1").unwrap();
        let e = RobotConfig::load_with_env(Some(file.path()), "SGM_TEST_D").unwrap_err();
        assert!(e.to_string().contains("bogus"), "{e}");
    }

    #[test]
    fn team_keys_hex_or_passphrase() {
        let mut c = CommsConfig { team_key: Secret::new("ab".repeat(32)), ..CommsConfig::default() };
        assert_eq!(c.team_key().unwrap(), TeamKey::from_bytes([0xab; 32]));
        c.team_key = "short".into();
        assert!(c.team_key().unwrap_err().to_string().starts_with("comms.team_key = <secret>: allowed"));
        c.team_key = "a passphrase of our own".into();
        let ours = c.team_key().unwrap();
        assert_eq!(ours, TeamKey::from_passphrase("a passphrase of our own", DEFAULT_TEAM_SALT).unwrap());
        // The salt changes a passphrase's key, not a hex key's.
        c.team_salt = "field team 7".into();
        assert_ne!(c.team_key().unwrap(), ours);
        c.team_key = Secret::new("ab".repeat(32));
        assert_eq!(c.team_key().unwrap(), TeamKey::from_bytes([0xab; 32]));
        c.team_salt = "short".into();
        assert_eq!(
            c.team_key().unwrap_err().to_string(),
            "comms.team_salt = \"short\": allowed at least 8 bytes (argon2's shortest salt); set a value of the team's own"
        );
    }

    #[test]
    fn debug_prints_never_show_the_team_key() {
        let passphrase = "our secret fleet passphrase";
        let mut config = RobotConfig::default();
        config.comms.team_key = passphrase.into();
        for text in [format!("{config:?}"), format!("{:?}", config.comms), format!("{config:#?}")] {
            assert!(!text.contains(passphrase), "{text}");
            assert!(text.contains("team_key: <redacted>"), "{text}");
        }
        config.comms.team_key = Secret::new("5e".repeat(32));
        assert!(!format!("{config:?}").contains(&"5e".repeat(32)));
        // Serialised as the plain string: the configuration layers read it back.
        let layer = config::Config::try_from(&config.comms).unwrap();
        assert_eq!(layer.get_string("team_key").unwrap(), "5e".repeat(32));
    }

    /// A file in `dir` holding `content`, with `mode`.
    fn key_file(dir: &Path, name: &str, content: &str, mode: u32) -> PathBuf {
        use std::os::unix::fs::PermissionsExt;
        let path = dir.join(name);
        std::fs::write(&path, content).unwrap();
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(mode)).unwrap();
        path
    }

    #[test]
    fn team_key_files_are_read_and_checked() {
        let dir = tempfile::tempdir().unwrap();
        let from_file = |path: &Path| CommsConfig { team_key_file: Some(path.into()), ..CommsConfig::default() };
        let hex = "c0ffee".repeat(10) + "abcd";
        let path = key_file(dir.path(), "hex.key", &format!("{hex}\n"), 0o600);
        assert_eq!(from_file(&path).team_key().unwrap(), TeamKey::from_hex(&hex).unwrap());
        let path = key_file(dir.path(), "phrase.key", "a passphrase in a file\r\n", 0o400);
        let phrase = TeamKey::from_passphrase("a passphrase in a file", DEFAULT_TEAM_SALT).unwrap();
        assert_eq!(from_file(&path).team_key().unwrap(), phrase);
        // One newline is stripped, no more.
        let path = key_file(dir.path(), "two.key", "a passphrase in a file\n\n", 0o600);
        let two = from_file(&path).team_key().unwrap();
        assert_ne!(two, phrase);
        assert_eq!(two, TeamKey::from_passphrase("a passphrase in a file\n", DEFAULT_TEAM_SALT).unwrap());
        // Relative to the current directory.
        let here = tempfile::NamedTempFile::new_in(".").unwrap();
        std::fs::write(here.path(), &hex).unwrap();
        let relative = PathBuf::from(here.path().file_name().unwrap());
        assert!(relative.is_relative());
        assert_eq!(from_file(&relative).team_key().unwrap(), TeamKey::from_hex(&hex).unwrap());

        let refused = |path: &Path| from_file(path).team_key().unwrap_err().to_string();
        let missing = dir.path().join("missing.key");
        let e = refused(&missing);
        assert!(e.starts_with(&format!("comms.team_key_file = {}: cannot be read: ", missing.display())), "{e}");
        let e = refused(dir.path());
        assert_eq!(e, format!("comms.team_key_file = {}: is not a file", dir.path().display()));
        for content in ["", "\n"] {
            let path = key_file(dir.path(), "empty.key", content, 0o600);
            assert!(refused(&path).ends_with(": is empty: it must hold the team key (64 hex digits or a passphrase)"));
        }
        for mode in [0o644, 0o640, 0o604, 0o620, 0o602, 0o610] {
            let path = key_file(dir.path(), "open.key", &hex, mode);
            let e = refused(&path);
            assert_eq!(
                e,
                format!(
                    "comms.team_key_file = {0}: its mode {mode:03o} lets group or others at the team key; \
                     `chmod 600 {0}` makes it its owner's alone",
                    path.display()
                )
            );
        }
        let path = key_file(dir.path(), "short.key", "short\n", 0o600);
        assert_eq!(
            refused(&path),
            format!(
                "comms.team_key_file = {}: allowed a team passphrase needs at least 12 characters; got 5",
                path.display()
            )
        );
        // Both places at once: refused, whatever the file holds.
        let path = key_file(dir.path(), "both.key", &hex, 0o600);
        let both = CommsConfig { team_key: "another passphrase".into(), ..from_file(&path) };
        assert_eq!(
            both.team_key().unwrap_err().to_string(),
            format!(
                "comms.team_key_file = {}: comms.team_key is set too: give the key in one place only \
                 (remove comms.team_key)",
                path.display()
            )
        );
        // Through the loader and the environment, as `sgm ros` reads it.
        std::env::set_var("SGM_TEST_KEYFILE__COMMS__TEAM_KEY_FILE", dir.path().join("hex.key"));
        let loaded = RobotConfig::load_with_env(None, "SGM_TEST_KEYFILE").unwrap();
        assert_eq!(loaded.comms.team_key().unwrap(), TeamKey::from_hex(&hex).unwrap());
        std::env::set_var("SGM_TEST_KEYFILE_OPEN__COMMS__TEAM_KEY_FILE", dir.path().join("open.key"));
        let e = RobotConfig::load_with_env(None, "SGM_TEST_KEYFILE_OPEN").unwrap_err().to_string();
        assert!(e.contains("chmod 600"), "{e}");
    }

    #[test]
    fn public_keys_are_known_whatever_their_spelling() {
        let public = |c: &CommsConfig| c.public_team_key().unwrap().map(|p| p.text);
        let default = CommsConfig::default();
        assert_eq!(public(&default), Some(DEVELOPMENT_TEAM_KEY));
        for listed in PUBLIC_TEAM_KEYS {
            let c = CommsConfig { team_key: listed.text.into(), ..CommsConfig::default() };
            assert_eq!(public(&c), Some(listed.text));
        }
        // The development key's derived bytes, spelt in hex (argon2id with the default salt,
        // model/src/wire/team_key.rs has the reference).
        let hex = "178984debcad4b8387b20e9405f600d1962300082e5eb49281673f14ec77ab0a";
        let c = CommsConfig { team_key: hex.into(), ..CommsConfig::default() };
        assert_eq!(public(&c), Some(DEVELOPMENT_TEAM_KEY));
        // ... also when the team has its own salt; and a public passphrase under that salt.
        let salted = CommsConfig { team_salt: "our own team salt".into(), ..c };
        assert_eq!(public(&salted), Some(DEVELOPMENT_TEAM_KEY));
        let salted = CommsConfig { team_key: DEVELOPMENT_TEAM_KEY.into(), ..salted };
        assert_eq!(public(&salted), Some(DEVELOPMENT_TEAM_KEY));
        // In a key file.
        let dir = tempfile::tempdir().unwrap();
        let path = key_file(dir.path(), "team.key", "sgm example fleet - replace this passphrase\n", 0o600);
        let c = CommsConfig { team_key_file: Some(path), ..CommsConfig::default() };
        assert_eq!(public(&c), Some("sgm example fleet - replace this passphrase"));
        // A key of our own is not public.
        let ours = CommsConfig { team_key: Secret::new("3c".repeat(32)), ..CommsConfig::default() };
        assert_eq!(public(&ours), None);
        let ours = CommsConfig { team_key: "a passphrase nobody printed".into(), ..CommsConfig::default() };
        assert_eq!(public(&ours), None);
    }
}
