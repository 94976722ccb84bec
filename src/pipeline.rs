//! `pipeline.ron` read with every kind's entry: `config`'s shared reading, given the list of
//! kinds' entries (`kinds::entries::Entries`). What the driver, the shell and the tests call.

use std::path::Path;

use crate::config::{ConfigError, PipelineConfig};
use crate::kinds::entries::Entries;

/// Reads and validates `pipeline.ron` at `file` (see `config::load_pipeline_with`).
pub fn load_pipeline(file: &Path) -> Result<PipelineConfig, ConfigError> {
    crate::config::load_pipeline_with::<Entries>(file)
}

/// Parses and validates the text of a `pipeline.ron` that lives at `file`.
pub fn parse_pipeline(file: &Path, text: &str) -> Result<PipelineConfig, ConfigError> {
    crate::config::parse_pipeline_with::<Entries>(file, text)
}
