//! The configuration's error, and the range checks that produce it.

use sgm_model::perception::colour_ids::PaletteError;
use sgm_model::perception::label_map::LabelMapError;

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

pub(super) fn check(ok: bool, key: &str, value: impl ToString, allowed: &str) -> Result<(), ConfigError> {
    if ok {
        Ok(())
    } else {
        Err(ConfigError::Invalid { key: key.into(), value: value.to_string(), allowed: allowed.into() })
    }
}

pub(super) fn positive(v: f64) -> bool {
    v.is_finite() && v > 0.0
}

pub(super) fn non_negative(v: f64) -> bool {
    v.is_finite() && v >= 0.0
}
