//! Configuration: built-in defaults, then a TOML file, then `SGM__SECTION__KEY` environment
//! variables, loaded with the `config` crate and validated before use.

use sgm_actors::config::{layered, ConfigError};
use sgm_model::matching::MatcherConfig;
use std::path::Path;

/// A configuration that cannot be loaded or is out of range. Names the source and the key.
#[derive(Debug, thiserror::Error)]
pub enum SettingsError {
    #[error("{path}: {message}")]
    Load { path: String, message: String },
    #[error("{0}")]
    Invalid(#[from] sgm_model::matching::MatcherConfigError),
}

/// Loads the `[matcher]` section.
pub fn load_matcher_config(path: Option<&Path>) -> Result<MatcherConfig, SettingsError> {
    let source_name = path.map(|p| p.display().to_string()).unwrap_or_else(|| "environment".into());
    let merged = layered(None, path, "SGM").map_err(|e| match e {
        ConfigError::Load { source_name, message } => SettingsError::Load { path: source_name, message },
        other => SettingsError::Load { path: source_name.clone(), message: other.to_string() },
    })?;
    let matcher: MatcherConfig = match merged.get::<MatcherConfig>("matcher") {
        Ok(m) => m,
        Err(config::ConfigError::NotFound(_)) => MatcherConfig::default(),
        Err(e) => return Err(SettingsError::Load { path: source_name, message: e.to_string() }),
    };
    matcher.validate()?;
    Ok(matcher)
}
