//! `sgm encode-cloud CLOUD.pcd [--resolution M]`: encodes the finite points of a PCD file with
//! the keyframe codec and prints `{"points": n, "bytes": n, "bytes_per_point": f64, "max_error": f64}`.
//! Bad files: exit 2 and a message naming the file.

use serde_json::json;
use sgm_model::pcd::read_pcd;
use sgm_model::wire::cloud_codec::encode;
use std::path::Path;
use std::process::ExitCode;

/// Largest PCD file read, bytes.
const MAX_FILE_BYTES: u64 = 4 << 30;

pub fn run(path: &Path, resolution_m: f64) -> ExitCode {
    let result = (|| -> Result<_, String> {
        let meta = std::fs::metadata(path).map_err(|e| format!("cannot read: {e}"))?;
        if meta.len() > MAX_FILE_BYTES {
            return Err(format!("{} bytes, more than the limit of {MAX_FILE_BYTES}", meta.len()));
        }
        let bytes = std::fs::read(path).map_err(|e| format!("cannot read: {e}"))?;
        let cloud = read_pcd(&bytes).map_err(|e| e.to_string())?;
        let points = cloud.finite_points().map_err(|e| e.to_string())?;
        encode(&points, resolution_m).map_err(|e| e.to_string())
    })();
    match result {
        Ok(encoded) => {
            let out = json!({
                "points": encoded.points,
                "bytes": encoded.bytes.len(),
                "bytes_per_point": encoded.bytes_per_point(),
                "max_error": encoded.max_error_m,
            });
            if super::stdout::emit("encode-cloud", &out.to_string()) {
                ExitCode::SUCCESS
            } else {
                ExitCode::from(2)
            }
        }
        Err(message) => {
            eprintln!("sgm encode-cloud: {}: {message}", path.display());
            ExitCode::from(2)
        }
    }
}
