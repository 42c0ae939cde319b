//! `sgm match LOCAL.json REMOTE.json [--config FILE]`.
//!
//! Output (one JSON object on stdout, exit 0):
//! `{"success": true, "T": [[4×4]], "matches": [[local_id, remote_id], ...], "score": f64, "time_ms": f64}`
//! with p_local = T · p_remote (rigid; roll and pitch too when the frames are tilted,
//! `matcher.max_tilt_deg`); on refusal `"success": false` and `"reason"`, no `T`.
//! Bad input: exit 2, one line on stderr naming the file and the fault, nothing on stdout.

use serde_json::json;
use sgm_model::matching::{match_graphs, MatchOutcome};
use sgm_scenarios::object_file::{graphs_from_files, ObjectFile};
use sgm_scenarios::settings::load_matcher_config;
use std::path::Path;
use std::process::ExitCode;
use std::time::Instant;

pub fn run(local: &Path, remote: &Path, config: Option<&Path>) -> ExitCode {
    let input = (|| -> Result<_, String> {
        let config = load_matcher_config(config).map_err(|e| e.to_string())?;
        let local_file = ObjectFile::load(local).map_err(|e| e.to_string())?;
        let remote_file = ObjectFile::load(remote).map_err(|e| e.to_string())?;
        let (l, r, labels) = graphs_from_files(&local_file, &remote_file, &config).map_err(|e| e.to_string())?;
        Ok((config, l, r, labels))
    })();
    let (config, local_graph, remote_graph, labels) = match input {
        Ok(v) => v,
        Err(message) => {
            eprintln!("sgm match: {message}");
            return ExitCode::from(2);
        }
    };
    let start = Instant::now();
    let report = match_graphs(&local_graph, &remote_graph, &labels, &config);
    let time_ms = start.elapsed().as_secs_f64() * 1e3;
    let output = match &report.outcome {
        MatchOutcome::Aligned(a) => {
            let m = a.local_from_remote.to_homogeneous();
            let rows: Vec<[f64; 4]> = (0..4).map(|r| [m[(r, 0)], m[(r, 1)], m[(r, 2)], m[(r, 3)]]).collect();
            let matches: Vec<[u32; 2]> = a.matches.iter().map(|m| [m.local.0, m.remote.0]).collect();
            json!({"success": true, "T": rows, "matches": matches, "score": a.significance, "time_ms": time_ms})
        }
        MatchOutcome::Refused(r) => json!({
            "success": false,
            "reason": r.reason.to_string(),
            "matches": [],
            "score": r.significance,
            "time_ms": time_ms,
        }),
    };
    if super::stdout::emit("match", &output.to_string()) {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(2)
    }
}
