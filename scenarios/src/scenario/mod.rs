//! Scenario files: a simulated world, its sensors, the radio, the robots and their routes, and
//! the robot configuration every robot shares — one TOML file, loaded with the `config` crate
//! from built-in defaults, then the file, then `SGM__SECTION__KEY` environment variables (the same
//! variables as a robot's configuration: `SGM__MATCHER__EDGE_SHARPNESS=2 sgm run` works on
//! both). Validated before anything runs; errors name the key. The book's scenario chapter
//! documents every key with its default and unit.

pub mod imu;
pub mod library;
mod radio;
mod robots;
pub mod segmentation;
mod sensors;
pub mod shapes;
pub mod terrain;
mod validate;

pub use imu::ImuSpec;
pub use radio::{PartitionSpec, RadioSpec};
pub use robots::{RobotSpec, RouteSpec};
pub use segmentation::SegmentationSpec;
pub use sensors::{CameraSpec, LidarPattern, LidarSpec, OdometrySourceSpec, OdometrySpec};
pub use terrain::{Platform, PlatformsSpec, TerrainSpec};

use serde::{Deserialize, Serialize};
use sgm_actors::config::{
    environment, CommsConfig, ConfigError, FusionConfig, MatcherSection, OptimiserConfig, PersistenceConfig,
    RobotConfig, RobotSection, TrackerSection,
};
use sgm_model::perception::label_map::LabelMapSpec;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// A scenario that cannot be loaded or is out of range.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ScenarioError {
    #[error("{source_name}: {message}")]
    Load { source_name: String, message: String },
    #[error("{source_name}: {key} = {value}: allowed {allowed}")]
    Invalid { source_name: String, key: String, value: String, allowed: String },
    /// The robots' sections (`[comms]`, `[matcher]`, …), checked as a robot's configuration.
    #[error("{source_name}: {error}")]
    Robot { source_name: String, error: ConfigError },
    #[error("no scenario named {name:?} in the library ({known}) and no file at that path")]
    Unknown { name: String, known: String },
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Scenario {
    pub scenario: ScenarioSection,
    pub world: WorldSpec,
    /// The ground: flat unless hills, kerbs or ramps are asked for.
    pub terrain: TerrainSpec,
    /// How each platform kind's body moves.
    pub platforms: PlatformsSpec,
    pub lidar: LidarSpec,
    pub camera: CameraSpec,
    /// How the segmentation network errs, and people walking through.
    pub segmentation: SegmentationSpec,
    pub imu: ImuSpec,
    pub odometry: OdometrySpec,
    pub radio: RadioSpec,
    pub robots: Vec<RobotSpec>,
    /// The robot configuration every robot shares (`[fusion]`, `[classes]`, `[tracker]`,
    /// `[matcher]`, `[optimiser]`, `[comms]`, `[persistence]`, as in a robot configuration file).
    pub fusion: FusionConfig,
    pub classes: LabelMapSpec,
    pub tracker: TrackerSection,
    pub matcher: MatcherSection,
    pub optimiser: OptimiserConfig,
    pub comms: CommsConfig,
    /// Map snapshots. In a scenario a robot resumes from its snapshot only after a crash
    /// (`robots[k].crash_s`), never at the start of a run.
    pub persistence: PersistenceConfig,
    /// Topics and frames of the bags `sgm run --bag-out` writes and `sgm replay` reads.
    pub ros: sgm_bridge::config::RosConfig,
    /// Wrong inter-robot factors injected into robots' Optimisers (`sim::false_factors`).
    pub false_factors: Vec<FalseFactorSpec>,
}

impl Default for Scenario {
    fn default() -> Self {
        let robot = RobotConfig::default();
        Self {
            scenario: ScenarioSection::default(),
            world: WorldSpec::default(),
            terrain: TerrainSpec::default(),
            platforms: PlatformsSpec::default(),
            lidar: LidarSpec::default(),
            camera: CameraSpec::default(),
            segmentation: SegmentationSpec::default(),
            imu: ImuSpec::default(),
            odometry: OdometrySpec::default(),
            radio: RadioSpec::default(),
            robots: Vec::new(),
            fusion: robot.fusion,
            classes: robot.classes,
            tracker: robot.tracker,
            matcher: robot.matcher,
            optimiser: robot.optimiser,
            comms: robot.comms,
            persistence: robot.persistence,
            ros: sgm_bridge::config::RosConfig::default(),
            false_factors: Vec::new(),
        }
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ScenarioSection {
    /// Name in reports. Default "scenario".
    pub name: String,
    /// One line for reports. Default "".
    pub description: String,
    /// Simulated mission length, s. Default 120.
    pub duration_s: f64,
    /// Seed of every random choice (world, sensors, odometry, radio). Default 1.
    pub seed: u64,
    /// Interval between two sensor frames of one robot, s. Default 0.5.
    pub frame_interval_s: f64,
    /// Interval of the report's time series (alignment error, ATE, bytes), s. Default 10.
    pub report_interval_s: f64,
}

impl Default for ScenarioSection {
    fn default() -> Self {
        Self {
            name: "scenario".into(),
            description: String::new(),
            duration_s: 120.0,
            seed: 1,
            frame_interval_s: 0.5,
            report_interval_s: 10.0,
        }
    }
}

/// What kind of place the world generator builds.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum WorldKind {
    /// Open ground with scattered objects and a few buildings.
    Campus,
    /// A grid of rooms joined by doors, furniture along the walls and in the middle.
    Indoor,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct WorldSpec {
    /// Default "campus".
    pub kind: WorldKind,
    /// Extent along x and y, centred on the origin, m. Default [80, 80].
    pub size_m: [f64; 2],
    /// Objects per class name (classes of `[fusion]` with a built-in shape: tree, lamp_post,
    /// bench, trash_can, chair, table, bookshelf, car). Default 12 trees, 8 lamp posts,
    /// 10 benches, 8 trash cans.
    pub objects: BTreeMap<String, usize>,
    /// Smallest distance between two objects' centres, m. Default 2.
    pub min_spacing_m: f64,
    /// Campus: rectangular buildings (labelled wall). Default 3.
    pub buildings: usize,
    /// Indoor: side of one square room, m. Default 8.
    pub room_size_m: f64,
    /// Height of walls and buildings, m. Default 3.
    pub wall_height_m: f64,
    /// Indoor: width of the door in each wall between rooms, m. Default 1.6.
    pub door_width_m: f64,
    /// Indoor: a flat ceiling at `wall_height_m` over the rooms (labelled wall), as every
    /// building has. Default false: the rooms are open to the sky, as every figure measured before
    /// the key was.
    pub ceiling: bool,
}

impl Default for WorldSpec {
    fn default() -> Self {
        let objects = [("tree", 12), ("lamp_post", 8), ("bench", 10), ("trash_can", 8)];
        Self {
            kind: WorldKind::Campus,
            size_m: [80.0, 80.0],
            objects: objects.iter().map(|(k, n)| (k.to_string(), *n)).collect(),
            min_spacing_m: 2.0,
            buildings: 3,
            room_size_m: 8.0,
            wall_height_m: 3.0,
            door_width_m: 1.6,
            ceiling: false,
        }
    }
}

/// `count` false inter-robot factors handed to `robot`'s Optimiser at `at_s` (or as soon after
/// as it has aligned `neighbour`), each tying one of its keyframes to one of `neighbour`'s with
/// a measurement `translation_m` and `rotation_deg` wrong.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FalseFactorSpec {
    /// The robot (name) whose Optimiser receives them.
    pub robot: String,
    /// The neighbour (name) whose keyframes they claim to tie to.
    pub neighbour: String,
    /// When, s.
    pub at_s: f64,
    /// How many (≥ 1).
    pub count: usize,
    /// Translation error of each, m. Default 5.
    pub translation_m: f64,
    /// Rotation error of each, degrees. Default 30.
    pub rotation_deg: f64,
}

impl Default for FalseFactorSpec {
    fn default() -> Self {
        Self {
            robot: String::new(),
            neighbour: String::new(),
            at_s: 0.0,
            count: 0,
            translation_m: 5.0,
            rotation_deg: 30.0,
        }
    }
}

impl Scenario {
    /// `name_or_path`: a name from the library (`quickstart`, …) or a TOML file.
    pub fn load(name_or_path: &str) -> Result<Self, ScenarioError> {
        Self::load_with_env(name_or_path, "SGM")
    }

    /// As [`Scenario::load`] with another environment prefix (tests use their own).
    pub fn load_with_env(name_or_path: &str, prefix: &str) -> Result<Self, ScenarioError> {
        let path = PathBuf::from(name_or_path);
        if path.is_file() {
            let text = std::fs::read_to_string(&path)
                .map_err(|e| ScenarioError::Load { source_name: path.display().to_string(), message: e.to_string() })?;
            return Self::from_toml(&text, &path.display().to_string(), prefix);
        }
        match library::get(name_or_path) {
            Some(text) => Self::from_toml(text, &format!("library/{name_or_path}.toml"), prefix),
            None => Err(ScenarioError::Unknown { name: name_or_path.into(), known: library::names().join(", ") }),
        }
    }

    /// Parses `text` (TOML) over the defaults, then the environment; validates.
    pub fn from_toml(text: &str, source_name: &str, prefix: &str) -> Result<Self, ScenarioError> {
        let load =
            |e: config::ConfigError| ScenarioError::Load { source_name: source_name.into(), message: e.to_string() };
        let defaults = defaults_source()
            .map_err(|message| ScenarioError::Load { source_name: "defaults".into(), message: message.clone() })?;
        // A table the file gives replaces the default one: the layers merge tables key by key,
        // which would add the default objects to the file's. The environment's keys go over
        // whichever table applies.
        let file = config::Config::builder()
            .add_source(config::File::from_str(text, config::FileFormat::Toml))
            .build()
            .map_err(load)?;
        let mut layers = config::Config::builder().add_source(defaults);
        if file.get_table("world.objects").is_err() {
            layers =
                layers.add_source(default_objects().map_err(|message| ScenarioError::Load {
                    source_name: "defaults".into(),
                    message: message.clone(),
                })?);
        }
        let merged = layers.add_source(file).add_source(environment(prefix)).build().map_err(load)?;
        let mut scenario: Scenario = merged.try_deserialize().map_err(load)?;
        // People are labelled `person`: a dynamic class unless the file says otherwise.
        scenario.segmentation.add_person_class(&mut scenario.fusion.classes);
        scenario.validate().map_err(|(key, value, allowed)| ScenarioError::Invalid {
            source_name: source_name.into(),
            key,
            value,
            allowed,
        })?;
        scenario
            .robot_config(0)
            .validate()
            .map_err(|error| ScenarioError::Robot { source_name: source_name.into(), error })?;
        Ok(scenario)
    }

    /// The configuration of robot `k` (id k + 1).
    pub fn robot_config(&self, k: usize) -> RobotConfig {
        RobotConfig {
            robot: RobotSection { id: k as u16 + 1, name: self.robot_name(k) },
            odometry: self.odometry_section(),
            fusion: self.fusion.clone(),
            classes: self.classes.clone(),
            tracker: self.tracker.clone(),
            matcher: self.matcher.clone(),
            optimiser: self.optimiser.clone(),
            comms: self.comms.clone(),
            persistence: self.persistence.clone(),
        }
    }

    /// A robot's `[odometry]`: internal with the default estimator told the `[imu]` it is
    /// given; external (the synthetic odometry comes with each frame) otherwise.
    pub fn odometry_section(&self) -> sgm_actors::config::OdometrySection {
        use sgm_actors::config::{OdometrySection, OdometrySource};
        let i = &self.imu;
        let imu = sgm_model::odometry::propagation::ImuNoise {
            gyro_noise: i.gyro_noise,
            accel_noise: i.accel_noise,
            gyro_bias_walk: i.gyro_bias_walk,
            accel_bias_walk: i.accel_bias_walk,
            gravity_mps2: i.gravity_mps2,
        };
        let source = match self.odometry.source {
            OdometrySourceSpec::Synthetic => OdometrySource::External,
            OdometrySourceSpec::Internal => OdometrySource::Internal,
        };
        OdometrySection { source, estimator: sgm_model::odometry::config::OdometryConfig { imu, ..Default::default() } }
    }

    /// Whether any robot crashes (the run then keeps snapshots).
    pub fn has_crashes(&self) -> bool {
        self.robots.iter().any(|r| r.crash_s.is_some())
    }

    pub fn robot_name(&self, k: usize) -> String {
        match self.robots.get(k) {
            Some(r) if !r.name.is_empty() => r.name.clone(),
            _ => format!("robot{k}"),
        }
    }

    /// The scenario with another seed.
    pub fn with_seed(mut self, seed: u64) -> Self {
        self.scenario.seed = seed;
        self
    }
}

/// `Scenario::default()` as the bottom layer of every scenario, built once per process.
///
/// `config::Config::try_from` sets it key by key and rebuilds the whole tree after each key
/// (`Config::set` calls `refresh`): 10.8 ms, against 0.34 ms for the rest of a load of
/// `quickstart` (release; `cargo bench -p sgm-scenarios --bench scenario_load`). The
/// `scenario_config` fuzz target parses one scenario per input.
fn defaults_source() -> Result<config::Config, &'static String> {
    static DEFAULTS: std::sync::OnceLock<Result<config::Config, String>> = std::sync::OnceLock::new();
    DEFAULTS
        .get_or_init(|| {
            // Without the default objects: they are a layer of their own (`default_objects`), laid
            // only under a file that gives no table.
            let mut defaults = Scenario::default();
            defaults.world.objects.clear();
            config::Config::try_from(&defaults).map_err(|e| e.to_string())
        })
        .as_ref()
        .cloned()
}

/// The default `[world.objects]` table as a layer of its own, laid under a file that gives none.
fn default_objects() -> Result<config::Config, &'static String> {
    static OBJECTS: std::sync::OnceLock<Result<config::Config, String>> = std::sync::OnceLock::new();
    OBJECTS
        .get_or_init(|| {
            let mut builder = config::Config::builder();
            for (class, count) in WorldSpec::default().objects {
                builder =
                    builder.set_default(format!("world.objects.{class}"), count as u64).map_err(|e| e.to_string())?;
            }
            builder.build().map_err(|e| e.to_string())
        })
        .as_ref()
        .cloned()
}

/// Where the file of a library scenario would be in a checkout (for messages and docs).
pub fn library_dir() -> &'static Path {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/library"))
}
