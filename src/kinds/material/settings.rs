//! The `Material` kind's own settings: its `report` section as `pipeline.ron` writes it
//! (overrides) and as it resolves (settings). It also reads the `billboard` section's
//! `alpha_cutoff` (an alpha-tested albedo's) and the shared `encode`. A leaf.

use serde::{Deserialize, Serialize};

/// What a report says beyond the defaults.
#[derive(Clone, Debug, Default, PartialEq, Eq, Hash, Serialize)]
pub struct ReportSettings {
    /// Each surface also encoded (level 0) in the other formats it may take, with their PSNR and
    /// bits per texel, so that a format can be chosen with figures (costs an encode each).
    pub compare_formats: bool,
}

#[derive(Deserialize, Default, Clone)]
#[serde(deny_unknown_fields)]
pub(crate) struct ReportOverrides {
    pub compare_formats: Option<bool>,
}

/// A `Material` asset's own settings.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Settings {
    pub report: ReportSettings,
    /// The alpha test of an alpha-tested albedo (the `billboard` section's `alpha_cutoff`).
    pub alpha_cutoff: f32,
    /// The `AmbientOcclusion` asset the material takes its AO maps from, by asset name: per
    /// asset, never a default.
    pub ao_source: Option<String>,
}
