//! `sgm pcd-convert IN.pcd OUT.pcd [--format ascii|binary|binary-compressed]`: rewrites a PCD
//! file (every field kept) for PCL / CloudCompare users and scripts. Bad input: exit 2.

use sgm_model::pcd::{read_pcd, write_pcd, DataFormat};
use std::path::Path;
use std::process::ExitCode;

pub fn run(input: &Path, output: &Path, format: DataFormat) -> ExitCode {
    let cloud = std::fs::read(input)
        .map_err(|e| format!("cannot read: {e}"))
        .and_then(|b| read_pcd(&b).map_err(|e| e.to_string()));
    let cloud = match cloud {
        Ok(c) => c,
        Err(message) => {
            eprintln!("sgm pcd-convert: {}: {message}", input.display());
            return ExitCode::from(2);
        }
    };
    let tmp = output.with_extension("pcd.tmp");
    if let Err(e) = std::fs::write(&tmp, write_pcd(&cloud, format)).and_then(|_| std::fs::rename(&tmp, output)) {
        eprintln!("sgm pcd-convert: {}: cannot write: {e}", output.display());
        return ExitCode::FAILURE;
    }
    ExitCode::SUCCESS
}
