//! An output file a run or a replay writes (a sensor bag, the result bag) that could not be
//! written, naming the file.

use std::path::{Path, PathBuf};

#[derive(Debug, thiserror::Error)]
#[error("{}: {source}", path.display())]
pub struct OutputError {
    pub path: PathBuf,
    #[source]
    pub source: std::io::Error,
}

impl OutputError {
    /// A closure for `map_err` that names `path`.
    pub fn at(path: &Path) -> impl Fn(std::io::Error) -> Self + '_ {
        move |source| Self { path: path.to_path_buf(), source }
    }
}
