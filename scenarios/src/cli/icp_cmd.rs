//! `sgm icp SOURCE.pcd TARGET.pcd [--method point-to-point|point-to-plane] [--max-distance M]
//! [--voxel M] [--init x,y,z,roll,pitch,yaw] [--rotation-epsilon R] [--translation-epsilon T]`: one JSON object
//! `{"converged", "T", "fitness", "rmse", "iterations", "time_ms"}` with p_target = T · p_source.
//! Bad files or arguments: exit 2 and a message naming what is wrong.

use serde_json::json;
use sgm_model::geometry::pose_from_rpy_translation;
use sgm_model::pcd::read_pcd;
use sgm_model::perception::icp::{register, IcpConfig, IcpMethod};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

const MAX_FILE_BYTES: u64 = 4 << 30;

pub struct Options {
    pub source: PathBuf,
    pub target: PathBuf,
    pub method: IcpMethod,
    pub max_distance: f64,
    pub voxel: f64,
    pub init: Option<String>,
    pub rotation_epsilon: f64,
    pub translation_epsilon: f64,
}

fn load(path: &Path) -> Result<Vec<nalgebra::Point3<f64>>, String> {
    let named = |m: String| format!("{}: {m}", path.display());
    let meta = std::fs::metadata(path).map_err(|e| named(format!("cannot read: {e}")))?;
    if meta.len() > MAX_FILE_BYTES {
        return Err(named(format!("{} bytes, more than the limit of {MAX_FILE_BYTES}", meta.len())));
    }
    let bytes = std::fs::read(path).map_err(|e| named(format!("cannot read: {e}")))?;
    read_pcd(&bytes).and_then(|c| c.finite_points()).map_err(|e| named(e.to_string()))
}

fn parse_init(text: &str) -> Result<sgm_model::geometry::Pose3, String> {
    let values: Vec<f64> = text
        .split(',')
        .map(|v| v.trim().parse::<f64>().map_err(|_| format!("--init: {v:?} is not a number")))
        .collect::<Result<_, _>>()?;
    if values.len() != 6 || values.iter().any(|v| !v.is_finite()) {
        return Err("--init needs six finite numbers: x,y,z,roll,pitch,yaw (metres, radians)".into());
    }
    Ok(pose_from_rpy_translation(
        values[3],
        values[4],
        values[5],
        nalgebra::Vector3::new(values[0], values[1], values[2]),
    ))
}

pub fn run(options: Options) -> ExitCode {
    let prepared = (|| -> Result<_, String> {
        let init = match &options.init {
            Some(text) => parse_init(text)?,
            None => sgm_model::geometry::Pose3::identity(),
        };
        if !options.max_distance.is_finite() || options.max_distance <= 0.0 {
            return Err(format!("--max-distance {} must be finite and > 0", options.max_distance));
        }
        for (name, v) in
            [("--rotation-epsilon", options.rotation_epsilon), ("--translation-epsilon", options.translation_epsilon)]
        {
            if !v.is_finite() || v <= 0.0 {
                return Err(format!("{name} {v} must be finite and > 0"));
            }
        }
        if !options.voxel.is_finite() || options.voxel < 0.0 {
            return Err(format!("--voxel {} must be finite and ≥ 0", options.voxel));
        }
        Ok((load(&options.source)?, load(&options.target)?, init))
    })();
    let (source, target, init) = match prepared {
        Ok(v) => v,
        Err(message) => {
            eprintln!("sgm icp: {message}");
            return ExitCode::from(2);
        }
    };
    let config = IcpConfig {
        method: options.method,
        max_correspondence_distance_m: options.max_distance,
        voxel_m: options.voxel,
        convergence_rotation_rad: options.rotation_epsilon,
        convergence_translation_m: options.translation_epsilon,
        ..IcpConfig::default()
    };
    let start = Instant::now();
    let result = register(&source, &target, &init, &config);
    let time_ms = start.elapsed().as_secs_f64() * 1e3;
    match result {
        Ok(r) => {
            let m = r.target_from_source.to_homogeneous();
            let rows: Vec<[f64; 4]> = (0..4).map(|i| [m[(i, 0)], m[(i, 1)], m[(i, 2)], m[(i, 3)]]).collect();
            let rmse = if r.rmse_m.is_finite() { json!(r.rmse_m) } else { json!(null) };
            let out = json!({"converged": r.converged, "T": rows, "fitness": r.fitness, "rmse": rmse, "iterations": r.iterations, "time_ms": time_ms});
            if super::stdout::emit("icp", &out.to_string()) {
                ExitCode::SUCCESS
            } else {
                ExitCode::from(2)
            }
        }
        Err(e) => {
            eprintln!("sgm icp: {e}");
            ExitCode::from(2)
        }
    }
}
