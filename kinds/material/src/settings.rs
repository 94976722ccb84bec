//! The `Material` kind's part of `pipeline.ron`: its entry (`Material(name: …, material: …)`), its
//! `report` section as written (overrides) and as it resolves (settings), the alpha test it
//! shares with billboard clouds (`config/sections`), and its `ao_source`. A leaf.

use serde::{Deserialize, Serialize};

use crate::config::sections::{merge_alpha_cutoff, AlphaTestOfDefaults, AlphaTestOverrides, Check};
use crate::config::{AssetReference, AssetSource, EncodeOverrides, EntryCheck, KindEntry};

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
#[derive(Clone, Debug, PartialEq)]
pub struct Settings {
    pub report: ReportSettings,
    /// The alpha test of an alpha-tested albedo (the `billboard` section's `alpha_cutoff`).
    pub alpha_cutoff: f32,
    /// The `AmbientOcclusion` asset the material takes its AO maps from, by asset name: per
    /// asset, never a default.
    pub ao_source: Option<String>,
}

/// A `Material` entry as `pipeline.ron` writes it.
#[derive(Deserialize)]
#[serde(rename = "Material", deny_unknown_fields)]
pub struct Entry {
    name: String,
    material: String,
    /// An `AmbientOcclusion` asset whose maps replace the materials' `ao` textures.
    #[serde(default)]
    ao_source: Option<String>,
    #[serde(default)]
    report: ReportOverrides,
    /// Only its `alpha_cutoff` (an alpha-tested albedo's).
    #[serde(default)]
    billboard: AlphaTestOverrides,
    #[serde(default)]
    encode: EncodeOverrides,
}

/// The sections of `defaults:` a material reads.
#[derive(Deserialize, Default)]
#[serde(rename = "defaults")]
pub struct Defaults {
    #[serde(default)]
    report: ReportOverrides,
    #[serde(default)]
    billboard: AlphaTestOfDefaults,
}

impl KindEntry for Settings {
    const NAME: &'static str = "Material";
    const FIELDS: &'static [&'static str] = &["report", "ao_source", "billboard"];
    const DEFAULTS: &'static [&'static str] = &["report", "billboard"];
    type Entry = Entry;
    type Defaults = Defaults;

    fn defaults(written: &Defaults, check: &mut dyn Check) -> Settings {
        let mut settings = Settings {
            report: ReportSettings::default(),
            alpha_cutoff: crate::config::sections::DEFAULT_ALPHA_CUTOFF,
            ao_source: None,
        };
        merge(check, &mut settings, &written.report, written.billboard.alpha_cutoff, 0);
        settings
    }

    fn name_and_encode(entry: &Entry) -> (&str, &EncodeOverrides) {
        (&entry.name, &entry.encode)
    }

    fn resolve(entry: &Entry, defaults: &Settings, check: &mut EntryCheck<'_, '_>) -> Option<(AssetSource, Settings)> {
        let material = check.source_path(&entry.material)?;
        let mut settings = defaults.clone();
        let anchor = check.anchor();
        merge(check, &mut settings, &entry.report, entry.billboard.alpha_cutoff, anchor);
        settings.ao_source = entry.ao_source.clone();
        Some((AssetSource::of_file(check.kind(), material), settings))
    }

    fn reads_asset(&self) -> Option<AssetReference<'_>> {
        let asset = self.ao_source.as_deref()?;
        Some(AssetReference { field: "ao_source", asset, kind: "AmbientOcclusion" })
    }
}

fn merge(check: &mut dyn Check, settings: &mut Settings, report: &ReportOverrides, cutoff: Option<f32>, at: usize) {
    settings.report.compare_formats = report.compare_formats.unwrap_or(settings.report.compare_formats);
    merge_alpha_cutoff(check, &mut settings.alpha_cutoff, cutoff, at);
}
