//! `sgm optimize IN.g2o [IN2.g2o …] [-o OUT.g2o] [--robust none|huber|cauchy|gnc] [--json]`.
//!
//! Several inputs load as one multi-robot graph (an inter-robot edge present in both robots'
//! files counts once). The first pose is held by a prior, as in GTSAM's examples, unless the
//! files `FIX` vertices. Errors are GTSAM's ½ Σ ‖r‖²_Σ. With `--json`, exactly one object on
//! stdout: `{"initial_error", "final_error", "iterations", "time_ms", "rejected"}`.
//! Malformed files: exit 2, the file, line number and fault on stderr.

use serde_json::json;
use sgm_model::optim::g2o::{read_g2o, write_g2o, G2oGraph};
use sgm_model::optim::graph::PoseGraph;
use sgm_model::optim::graph::{GTSAM_PRIOR_SIGMAS_2D, GTSAM_PRIOR_SIGMAS_3D};
use sgm_model::optim::manifold::Manifold;
use sgm_model::optim::robust::RobustKernel;
use sgm_model::optim::solver::{LmParams, Summary};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

/// Largest g2o file read, bytes.
const MAX_FILE_BYTES: u64 = 1 << 30;

pub struct Options {
    pub inputs: Vec<PathBuf>,
    pub output: Option<PathBuf>,
    pub robust: RobustKernel,
    pub json: bool,
    pub gauss_newton: bool,
}

fn read(path: &Path) -> Result<String, String> {
    let meta = std::fs::metadata(path).map_err(|e| format!("{}: cannot read: {e}", path.display()))?;
    if meta.len() > MAX_FILE_BYTES {
        return Err(format!("{}: {} bytes, more than the limit of {MAX_FILE_BYTES}", path.display(), meta.len()));
    }
    std::fs::read_to_string(path).map_err(|e| format!("{}: cannot read: {e}", path.display()))
}

fn anchor_and_solve<G: Manifold<D>, const D: usize>(
    graph: &mut PoseGraph<G, D>,
    sigmas: [f64; D],
    params: &LmParams,
    robust: RobustKernel,
) -> Result<(Summary, Vec<usize>), String> {
    if !graph.fixed.iter().any(|f| *f) && !graph.values.is_empty() {
        graph.add_prior_at_current(0, sigmas);
    }
    let (summary, rejected) =
        sgm_model::optim::robust::optimize_robust(graph, params, robust).map_err(|e| e.to_string())?;
    Ok((summary, rejected))
}

pub fn run(options: Options) -> ExitCode {
    let texts: Result<Vec<String>, String> = options.inputs.iter().map(|p| read(p)).collect();
    let texts = match texts {
        Ok(t) => t,
        Err(message) => {
            eprintln!("sgm optimize: {message}");
            return ExitCode::from(2);
        }
    };
    let refs: Vec<&str> = texts.iter().map(String::as_str).collect();
    let mut graph = match read_g2o(&refs) {
        Ok(g) => g,
        Err((file, e)) => {
            eprintln!("sgm optimize: {}: {e}", options.inputs[file].display());
            return ExitCode::from(2);
        }
    };
    let params = LmParams { gauss_newton: options.gauss_newton, ..LmParams::default() };
    let start = Instant::now();
    let result = match &mut graph {
        G2oGraph::Planar(g) => anchor_and_solve(g, GTSAM_PRIOR_SIGMAS_2D, &params, options.robust),
        G2oGraph::Spatial(g) => anchor_and_solve(g, GTSAM_PRIOR_SIGMAS_3D, &params, options.robust),
    };
    let time_ms = start.elapsed().as_secs_f64() * 1e3;
    let (summary, rejected) = match result {
        Ok(r) => r,
        Err(message) => {
            eprintln!("sgm optimize: {message}");
            return ExitCode::FAILURE;
        }
    };
    if let Some(path) = &options.output {
        if let Err(e) = write_atomically(path, &write_g2o(&graph)) {
            eprintln!("sgm optimize: {}: cannot write: {e}", path.display());
            return ExitCode::FAILURE;
        }
    }
    let text = if options.json {
        let out = json!({
            "initial_error": summary.initial_error,
            "final_error": summary.final_error,
            "iterations": summary.iterations,
            "time_ms": time_ms,
            "rejected": rejected,
        });
        out.to_string()
    } else {
        let mut text = format!(
            "initial error {:.6}\nfinal error   {:.6}\niterations    {}{}\ntime          {time_ms:.1} ms",
            summary.initial_error,
            summary.final_error,
            summary.iterations,
            if summary.converged { "" } else { " (not converged)" }
        );
        if !rejected.is_empty() {
            text.push_str(&format!("\nrejected      {} edges: {:?}", rejected.len(), rejected));
        }
        text
    };
    if super::stdout::emit("optimize", &text) {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(2)
    }
}

/// Writes to a temporary file beside `path`, then renames: a reader never sees half a file.
fn write_atomically(path: &Path, text: &str) -> std::io::Result<()> {
    let tmp = path.with_extension("g2o.tmp");
    std::fs::write(&tmp, text)?;
    std::fs::rename(&tmp, path)
}
