//! `sgm`: the SGM command line.
//!
//! * `sgm run [SCENARIO] [--out DIR] [--seed N]`: a simulated multi-robot mission and its report.
//! * `sgm match LOCAL.json REMOTE.json [--config FILE]`: match two object graphs (stable contract).
//! * `sgm optimize IN.g2o … [-o OUT] [--robust …] [--json]`: pose-graph optimisation.
//! * `sgm icp SOURCE.pcd TARGET.pcd [...]`: ICP registration.
//! * `sgm pcd-convert IN.pcd OUT.pcd [--format ...]`: PCD format conversion.
//! * `sgm encode-cloud CLOUD.pcd [--resolution M]`: keyframe cloud codec size and error.
//! * `sgm bench matching [--reps N] [--seed S]`: the paper's Tables 1–2 protocol.
//! * `sgm bench messages [--duration S] [--json FILE]`: the paper's Table 4 analogue.

use clap::{Parser, Subcommand};
use std::path::PathBuf;
use std::process::ExitCode;

mod bench;
mod cli;

#[derive(Parser)]
#[command(name = "sgm", version, about = "SGM: distributed multi-robot SLAM by scene-graph matching")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run a scenario (a library name or a TOML file; default quickstart) and write its report.
    Run {
        /// quickstart, outdoor_two_robots, indoor_three_robots, team_of_eight, team_of_sixteen, or a path.
        scenario: Option<String>,
        /// Report directory (default: a fresh folder under runs/).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Override the scenario's seed.
        #[arg(long)]
        seed: Option<u64>,
        /// No progress bar.
        #[arg(long)]
        quiet: bool,
        /// Also write each robot's sensor streams as a ROS 1 bag (DIR/NAME.bag).
        #[arg(long, value_name = "DIR")]
        bag_out: Option<PathBuf>,
        /// Do not write the team's result as a ROS 1 bag (result.bag in the report directory).
        #[arg(long)]
        no_result_bag: bool,
        /// How many robots run at once (default: every core). The report is the same for any
        /// number; more than the machine's cores is cut to them.
        #[arg(long, value_name = "N")]
        threads: Option<usize>,
    },
    /// Run one robot as a ROS 1 node (rosrust); ROS remappings (`__ns:=/alpha`, `a:=b`) may follow.
    Ros {
        #[command(flatten)]
        robot: cli::ros_cmd::RobotArgs,
        /// Start even with a public team key (the built-in default, or one printed in the book or
        /// the shipped configurations), with a warning: for development on a private network
        /// only. Without it such a key is refused; set comms.team_key_file to a key of your own.
        #[arg(long)]
        development_key: bool,
        /// ROS remapping arguments, read by rosrust.
        #[arg(trailing_var_arg = true, allow_hyphen_values = true, hide = true)]
        remappings: Vec<String>,
    },
    /// SGM's LiDAR-inertial odometry alone on one robot's ROS 1 bag or ROS 2 recording (its
    /// clouds, with their points' times, and its IMU on ros.topics.imu); writes the trajectory
    /// as TUM.
    Odometry {
        #[command(flatten)]
        robot: cli::ros_cmd::RobotArgs,
        /// The robot's ROS 1 bag or ROS 2 recording (rosbag2 directory, .mcap or .db3).
        #[arg(long)]
        bag: PathBuf,
        /// Where the trajectory goes (TUM: stamp x y z qx qy qz qw, odom_from_body).
        #[arg(long)]
        out: PathBuf,
    },
    /// Replay recorded missions (one ROS 1 bag or ROS 2 recording per robot) with no ROS master,
    /// and write the report.
    Replay {
        /// A robot's ROS 1 bag or ROS 2 recording (a rosbag2 directory, or its .mcap or .db3
        /// file alone), by what the path holds; give one per robot, in the order of the
        /// configuration's [[robots]].
        #[arg(long = "bag", required = true, value_name = "BAG")]
        bags: Vec<PathBuf>,
        /// Scenario file or library name giving the robots, their configuration, the radio
        /// and the [ros] topics (default: the defaults, robots named after the bag files).
        #[arg(long)]
        config: Option<String>,
        /// Report directory (default: a fresh folder under runs/).
        #[arg(long)]
        out: Option<PathBuf>,
        /// No progress bar.
        #[arg(long)]
        quiet: bool,
        /// Do not write the team's result as a ROS 1 bag (result.bag in the report directory).
        #[arg(long)]
        no_result_bag: bool,
        /// How many robots run at once (default: every core). The report is the same for any
        /// number; more than the machine's cores is cut to them.
        #[arg(long, value_name = "N")]
        threads: Option<usize>,
    },
    /// Check a robot's inputs (topics, frames, mounts from tf, stamps, classes) from a bag or a
    /// live master, with a verdict per input; ROS remappings (`points:=cloud`, `__ns:=/alpha`)
    /// may follow. Exit status 1 when an input fails.
    Doctor {
        #[command(flatten)]
        robot: cli::ros_cmd::RobotArgs,
        /// A bag of the robot's inputs (ROS 1, or a ROS 2 recording: rosbag2 directory, .mcap or .db3).
        #[arg(long, conflicts_with = "live", required_unless_present = "live")]
        bag: Option<PathBuf>,
        /// Listen to the robot's topics on the master (ROS_MASTER_URI) instead.
        #[arg(long)]
        live: bool,
        /// With --live: how long to listen, s.
        #[arg(long, default_value_t = 10.0)]
        duration: f64,
        /// Print the report as JSON.
        #[arg(long)]
        json: bool,
        /// ROS remapping arguments, read by rosrust (with --live).
        #[arg(trailing_var_arg = true, allow_hyphen_values = true, hide = true)]
        remappings: Vec<String>,
    },
    /// Match two object graphs; prints one JSON object (p_local = T · p_remote).
    Match {
        /// The local robot's objects (JSON).
        local: PathBuf,
        /// The remote robot's objects (JSON).
        remote: PathBuf,
        /// Configuration file (TOML, section [matcher]); SGM__MATCHER__* variables override it.
        #[arg(long)]
        config: Option<PathBuf>,
    },
    /// Optimise a pose graph (g2o); several files load as one multi-robot graph.
    Optimize {
        /// g2o file(s).
        #[arg(required = true)]
        inputs: Vec<PathBuf>,
        /// Write the optimised graph here (g2o).
        #[arg(short = 'o', long = "output")]
        output: Option<PathBuf>,
        /// Robust kernel on the between factors.
        #[arg(long, value_enum, default_value_t = RobustArg::None)]
        robust: RobustArg,
        /// Print exactly one JSON object.
        #[arg(long)]
        json: bool,
        /// Gauss–Newton instead of Levenberg–Marquardt.
        #[arg(long)]
        gauss_newton: bool,
    },
    /// Register SOURCE to TARGET (PCD files); prints one JSON object (p_target = T · p_source).
    Icp {
        source: PathBuf,
        target: PathBuf,
        #[arg(long, value_enum, default_value_t = IcpMethodArg::PointToPlane)]
        method: IcpMethodArg,
        /// Largest correspondence distance, m.
        #[arg(long, default_value_t = 1.0, allow_negative_numbers = true)]
        max_distance: f64,
        /// Voxel size for downsampling both clouds (0: none), m.
        #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
        voxel: f64,
        /// Initial guess x,y,z,roll,pitch,yaw (m, rad).
        #[arg(long, allow_hyphen_values = true)]
        init: Option<String>,
        /// Converged when a step rotates less than this, rad.
        #[arg(long, default_value_t = 1e-6)]
        rotation_epsilon: f64,
        /// ... and translates less than this, m.
        #[arg(long, default_value_t = 1e-6)]
        translation_epsilon: f64,
    },
    /// Convert a PCD file between ascii, binary and binary_compressed.
    PcdConvert {
        input: PathBuf,
        output: PathBuf,
        #[arg(long, value_enum, default_value_t = PcdFormatArg::BinaryCompressed)]
        format: PcdFormatArg,
    },
    /// Encode a PCD cloud with the keyframe codec; prints its size and error as JSON.
    EncodeCloud {
        cloud: PathBuf,
        /// Quantum, m.
        #[arg(long, default_value_t = 0.01, allow_negative_numbers = true)]
        resolution: f64,
    },
    /// Benchmarks that reproduce the paper's experiments.
    Bench {
        #[command(subcommand)]
        which: BenchCommand,
    },
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum PcdFormatArg {
    Ascii,
    Binary,
    BinaryCompressed,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum IcpMethodArg {
    PointToPoint,
    PointToPlane,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum RobustArg {
    None,
    Huber,
    Cauchy,
    Gnc,
}

#[derive(Subcommand)]
enum BenchCommand {
    /// Paper §V-A, Tables 1 and 2, plus false claims on non-overlapping pairs.
    Matching {
        /// Repetitions per table cell (the paper uses 20).
        #[arg(long, default_value_t = 20)]
        reps: usize,
        /// Seed of the first repetition.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Also write the tables as JSON to this file.
        #[arg(long)]
        json: Option<PathBuf>,
        /// Matcher configuration (TOML, section [matcher]); SGM__MATCHER__* variables override it.
        #[arg(long)]
        config: Option<PathBuf>,
        /// Do not run the dense paper formulation (its columns then read "–").
        #[arg(long)]
        skip_dense: bool,
        /// Which graphs carry the "Err" position error (the paper does not say).
        #[arg(long, value_enum, default_value_t = bench::matching::ErrorOnArg::Both)]
        error_on: bench::matching::ErrorOnArg,
        /// Repetitions per cell of the hard families (repeated layouts, hundreds of objects:
        /// up to 0.3 s a pair); default: --reps.
        #[arg(long)]
        hard_reps: Option<usize>,
    },
    /// Paper §V-C, Table 4: message sizes per type on outdoor_two_robots and
    /// indoor_three_robots, against raw point-cloud sharing.
    Messages {
        /// Cut each mission to this many simulated seconds.
        #[arg(long)]
        duration: Option<f64>,
        /// Also write the table as JSON to this file.
        #[arg(long)]
        json: Option<PathBuf>,
    },
    /// Paper §V-B, Table 3: team ATE of SGM against Swarm-SC (Scan Context association), no
    /// association, and raw sharing to a central server, on outdoor_two_robots and
    /// indoor_three_robots.
    Baselines {
        /// Cut each mission to this many simulated seconds.
        #[arg(long)]
        duration: Option<f64>,
        /// Also write the table as JSON to this file.
        #[arg(long)]
        json: Option<PathBuf>,
    },
    /// Success and error against mislabel rate, trajectory overlap and centroid noise; bytes
    /// against team size (2–16 robots).
    Sweeps {
        /// Cut each mission to this many simulated seconds and sweep fewer values.
        #[arg(long)]
        duration: Option<f64>,
        /// Also write the tables as JSON to this file.
        #[arg(long)]
        json: Option<PathBuf>,
        /// Draw the plots (PNG) into this directory.
        #[arg(long)]
        plots: Option<PathBuf>,
    },
    /// What each effect of the unkind world (terrain, legged gait, Livox pattern, sweeps, the
    /// IMU's deskew, the camera's mount and timing, calibration errors) costs outdoor_two_robots,
    /// alone and all together (legged_campus).
    Realism {
        /// Cut each mission to this many simulated seconds.
        #[arg(long)]
        duration: Option<f64>,
        /// Only the effects whose names contain this.
        #[arg(long)]
        only: Option<String>,
        /// Run each effect with the scenario's seed and the seeds after it, this many in all.
        #[arg(long, default_value_t = 1)]
        seeds: u64,
        /// Also write the table as JSON to this file.
        #[arg(long)]
        json: Option<PathBuf>,
    },
    /// SGM's LiDAR-inertial front end on the simulated sweeps and IMU of outdoor, indoor,
    /// legged and handheld scenarios: drift (KITTI's metric) against the synthetic odometry,
    /// CPU time per frame.
    Odometry {
        /// Cut each mission to this many simulated seconds.
        #[arg(long)]
        duration: Option<f64>,
        /// Only the scenarios whose names contain this.
        #[arg(long)]
        only: Option<String>,
        /// Also write the table as JSON to this file.
        #[arg(long)]
        json: Option<PathBuf>,
        /// Write each scenario's sweeps, IMU and truth as a ROS 1 bag (and our estimate and
        /// the truth as TUM files) to DIR/SCENARIO/, for KISS-ICP (benches/compare_kiss_icp.sh).
        #[arg(long, value_name = "DIR")]
        bag_out: Option<PathBuf>,
    },
    /// Wrong inter-robot closures, 0–90 % of them, gross and subtle: team ATE against the clean
    /// run, and how many the back end (PCM, then GNC-TLS) rejected.
    Outliers {
        /// The library scenario (or scenario file) to run.
        #[arg(long, default_value = "faults/clean")]
        scenario: String,
        /// Cut each mission to this many simulated seconds.
        #[arg(long)]
        duration: Option<f64>,
        /// Also write the table as JSON to this file.
        #[arg(long)]
        json: Option<PathBuf>,
    },
    /// Every bench above but realism in one report (report.md, report.json and plots) in --out;
    /// the outliers bench on faults/clean.
    All {
        #[arg(long, default_value = "bench-report")]
        out: PathBuf,
        /// Matching repetitions per table cell (the paper uses 20).
        #[arg(long, default_value_t = 20)]
        reps: usize,
        /// Cut each mission to this many simulated seconds and sweep fewer values.
        #[arg(long)]
        duration: Option<f64>,
    },
}

/// Prints a bench's section and writes its JSON; the exit status.
fn emit(name: &str, section: anyhow::Result<bench::Section>, json: Option<&std::path::Path>) -> ExitCode {
    match section.and_then(|s| s.emit(json)) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("sgm bench {name}: {e:#}");
            ExitCode::FAILURE
        }
    }
}

/// Log lines go to stderr, filtered by `RUST_LOG` (default: warnings, and the node's own
/// information for `sgm ros`).
fn init_logging(command: &Command) {
    // The doctor says what it finds in its report; the log would say it twice.
    let default = match command {
        Command::Ros { .. } => "info",
        Command::Doctor { .. } => "error",
        _ => "warn",
    };
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(default));
    tracing_subscriber::fmt().with_env_filter(filter).with_writer(std::io::stderr).init();
}

fn main() -> ExitCode {
    // Before the first allocation that matters: resident memory then follows what is held.
    sgm_scenarios::memory::keep_large_blocks_out_of_the_heap();
    let cli = Cli::parse();
    init_logging(&cli.command);
    match cli.command {
        Command::Run { scenario, out, seed, quiet, bag_out, no_result_bag, threads } => {
            let result_bag = !no_result_bag;
            let options = cli::run_cmd::Options { scenario, out, seed, quiet, bag_out, result_bag, threads };
            match cli::run_cmd::execute(options) {
                Ok(()) => ExitCode::SUCCESS,
                Err(e) => {
                    eprintln!("sgm run: {e:#}");
                    ExitCode::from(2)
                }
            }
        }
        Command::Ros { robot, development_key, remappings: _ } => {
            match cli::ros_cmd::execute(cli::ros_cmd::Options { robot, development_key }) {
                Ok(()) => ExitCode::SUCCESS,
                Err(e) => {
                    eprintln!("sgm ros: {e:#}");
                    ExitCode::from(2)
                }
            }
        }
        Command::Replay { bags, config, out, quiet, no_result_bag, threads } => {
            let result_bag = !no_result_bag;
            match cli::replay_cmd::execute(cli::replay_cmd::Options { bags, config, out, quiet, result_bag, threads }) {
                Ok(()) => ExitCode::SUCCESS,
                Err(e) => {
                    eprintln!("sgm replay: {e:#}");
                    ExitCode::from(2)
                }
            }
        }
        Command::Doctor { robot, bag, live, duration, json, remappings: _ } => {
            let options = cli::doctor_cmd::Options { robot, bag, live, duration_s: duration, json };
            match cli::doctor_cmd::execute(options) {
                Ok(true) => ExitCode::SUCCESS,
                Ok(false) => ExitCode::from(1),
                Err(e) => {
                    eprintln!("sgm doctor: {e:#}");
                    ExitCode::from(2)
                }
            }
        }
        Command::Odometry { robot, bag, out } => {
            match cli::odometry_cmd::execute(cli::odometry_cmd::Options { robot, bag, out }) {
                Ok(()) => ExitCode::SUCCESS,
                Err(e) => {
                    eprintln!("sgm odometry: {e:#}");
                    ExitCode::from(2)
                }
            }
        }
        Command::Match { local, remote, config } => cli::match_cmd::run(&local, &remote, config.as_deref()),
        Command::Optimize { inputs, output, robust, json, gauss_newton } => {
            use sgm_model::optim::robust::RobustKernel;
            let robust = match robust {
                RobustArg::None => RobustKernel::None,
                RobustArg::Huber => RobustKernel::Huber,
                RobustArg::Cauchy => RobustKernel::Cauchy,
                RobustArg::Gnc => RobustKernel::Gnc,
            };
            cli::optimize_cmd::run(cli::optimize_cmd::Options { inputs, output, robust, json, gauss_newton })
        }
        Command::PcdConvert { input, output, format } => {
            use sgm_model::pcd::DataFormat;
            let format = match format {
                PcdFormatArg::Ascii => DataFormat::Ascii,
                PcdFormatArg::Binary => DataFormat::Binary,
                PcdFormatArg::BinaryCompressed => DataFormat::BinaryCompressed,
            };
            cli::pcd_convert_cmd::run(&input, &output, format)
        }
        Command::Icp { source, target, method, max_distance, voxel, init, rotation_epsilon, translation_epsilon } => {
            use sgm_model::perception::icp::IcpMethod;
            let method = match method {
                IcpMethodArg::PointToPoint => IcpMethod::PointToPoint,
                IcpMethodArg::PointToPlane => IcpMethod::PointToPlane,
            };
            cli::icp_cmd::run(cli::icp_cmd::Options {
                source,
                target,
                method,
                max_distance,
                voxel,
                init,
                rotation_epsilon,
                translation_epsilon,
            })
        }
        Command::EncodeCloud { cloud, resolution } => cli::encode_cloud_cmd::run(&cloud, resolution),
        Command::Bench {
            which: BenchCommand::Matching { reps, seed, json, config, skip_dense, error_on, hard_reps },
        } => {
            let options = bench::matching::Options { reps, seed, config, skip_dense, error_on, hard_reps };
            emit("matching", bench::matching::run(options), json.as_deref())
        }
        Command::Bench { which: BenchCommand::Messages { duration, json } } => {
            emit("messages", bench::messages::run_bench(duration), json.as_deref())
        }
        Command::Bench { which: BenchCommand::Baselines { duration, json } } => {
            emit("baselines", bench::baselines::run_bench(duration), json.as_deref())
        }
        Command::Bench { which: BenchCommand::Sweeps { duration, json, plots } } => {
            let options = bench::sweeps::Options { duration, plots };
            emit("sweeps", bench::sweeps::run_bench(&options), json.as_deref())
        }
        Command::Bench { which: BenchCommand::Outliers { scenario, duration, json } } => {
            emit("outliers", bench::outliers::run_bench(&scenario, duration), json.as_deref())
        }
        Command::Bench { which: BenchCommand::Realism { duration, only, seeds, json } } => {
            let options = bench::realism::Options { duration, only: only.as_deref(), seeds };
            emit("realism", bench::realism::run_bench(&options), json.as_deref())
        }
        Command::Bench { which: BenchCommand::Odometry { duration, only, json, bag_out } } => {
            let options = bench::odometry::Options { duration, only: only.as_deref(), bag_out: bag_out.as_deref() };
            emit("odometry", bench::odometry::run_bench(&options), json.as_deref())
        }
        Command::Bench { which: BenchCommand::All { out, reps, duration } } => {
            match bench::all::run_bench(bench::all::Options { out, reps, duration }) {
                Ok(()) => ExitCode::SUCCESS,
                Err(e) => {
                    eprintln!("sgm bench all: {e:#}");
                    ExitCode::FAILURE
                }
            }
        }
    }
}
