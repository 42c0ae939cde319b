//! `sgm`: the SGM command line.
//!
//! * `sgm match LOCAL.json REMOTE.json [--config FILE]`: match two object graphs (stable contract).
//! * `sgm bench matching [--reps N] [--seed S]`: the paper's Tables 1–2 protocol.

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
    /// Benchmarks that reproduce the paper's experiments.
    Bench {
        #[command(subcommand)]
        which: BenchCommand,
    },
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
    },
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match cli.command {
        Command::Match { local, remote, config } => cli::match_cmd::run(&local, &remote, config.as_deref()),
        Command::Bench { which: BenchCommand::Matching { reps, seed, json, config, skip_dense, error_on } } => {
            match bench::matching::run(bench::matching::Options { reps, seed, json, config, skip_dense, error_on }) {
                Ok(()) => ExitCode::SUCCESS,
                Err(e) => {
                    eprintln!("sgm bench matching: {e:#}");
                    ExitCode::FAILURE
                }
            }
        }
    }
}
