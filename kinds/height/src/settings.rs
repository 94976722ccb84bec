//! The `Height` kind's part of `pipeline.ron`: its entry (`Height(name: …, high: …, low: …)`), its
//! `height` and `tessellate` sections as written (overrides), as they resolve (settings), and
//! their checks. A leaf: it imports only `config`'s shared parts.

use serde::{Deserialize, Serialize};

use crate::config::sections::Check;
use crate::config::{AssetSource, EncodeOverrides, EntryCheck, KindEntry};

/// How a `Height` asset measures its high mesh from its low one (DESIGN §3.4).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum HeightProjection {
    /// Per texel of the low mesh's UV space, along the low surface's interpolated normal.
    Normals,
    /// Orthographic depth along −Y over the low mesh's XZ footprint (terrain, relief).
    TopDown,
}

/// How a `Height` asset's map is baked.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct HeightSettings {
    pub projection: HeightProjection,
    /// Width and height of the map, in texels.
    pub size: u32,
    /// How far above the low surface (along its normal) the high one is looked for, as a
    /// fraction of the low mesh's bounding-box diagonal.
    pub frontal: f32,
    /// How far below the low surface, likewise.
    pub rear: f32,
}

/// A `Height` asset's tessellated mesh: `level` segments per edge, displaced or not.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize)]
pub struct TessellateSettings {
    pub level: u32,
    pub displace: bool,
}

#[derive(Deserialize, Default, Clone)]
#[serde(deny_unknown_fields)]
pub struct HeightOverrides {
    pub projection: Option<HeightProjection>,
    pub size: Option<u32>,
    pub frontal: Option<f32>,
    pub rear: Option<f32>,
}

#[derive(Deserialize, Default, Clone)]
#[serde(deny_unknown_fields)]
pub struct TessellateOverrides {
    pub level: Option<u32>,
    pub displace: Option<bool>,
}

fn merge_height(check: &mut dyn Check, settings: &mut HeightSettings, height: &HeightOverrides, anchor: usize) {
    if let Some(size) = height.size {
        if !(16..=16384).contains(&size) || size % 4 != 0 {
            check.error_at_key("size", anchor, "size must be a multiple of 4 between 16 and 16384");
        }
        settings.size = size;
    }
    for (key, value, target) in
        [("frontal", height.frontal, &mut settings.frontal), ("rear", height.rear, &mut settings.rear)]
    {
        if let Some(value) = value {
            if !(0.0..=1.0).contains(&value) {
                check.error_at_key(
                    key,
                    anchor,
                    &format!("{key} must be a fraction of the bounding-box diagonal in [0, 1]"),
                );
            }
            *target = value;
        }
    }
    if settings.frontal + settings.rear <= 0.0 {
        check.error_at_key("frontal", anchor, "frontal and rear cannot both be 0: the rays would have no length");
    }
    settings.projection = height.projection.unwrap_or(settings.projection);
}

fn tessellate_settings(check: &mut dyn Check, tessellate: &TessellateOverrides, anchor: usize) -> TessellateSettings {
    let level = tessellate.level.unwrap_or(8);
    if !(1..=64).contains(&level) {
        check.error_at_key("level", anchor, "level must be between 1 and 64 segments per edge");
    }
    TessellateSettings { level, displace: tessellate.displace.unwrap_or(true) }
}

impl Default for HeightSettings {
    fn default() -> HeightSettings {
        HeightSettings { projection: HeightProjection::Normals, size: 1024, frontal: 0.02, rear: 0.02 }
    }
}

/// A `Height` asset's own settings.
#[derive(Clone, Debug, PartialEq)]
pub struct Settings {
    pub height: HeightSettings,
    /// Its tessellated mesh (per asset, never a default; none: no tessellation).
    pub tessellate: Option<TessellateSettings>,
    /// The high mesh it measures (source-relative; per asset, never a default).
    pub high_mesh: std::path::PathBuf,
}

/// A `Height` entry as `pipeline.ron` writes it.
#[derive(Deserialize)]
#[serde(rename = "Height", deny_unknown_fields)]
pub struct Entry {
    name: String,
    high: String,
    low: String,
    #[serde(default)]
    height: HeightOverrides,
    #[serde(default)]
    tessellate: Option<TessellateOverrides>,
    #[serde(default)]
    encode: EncodeOverrides,
}

/// The sections of `defaults:` a height bake reads.
#[derive(Deserialize, Default)]
#[serde(rename = "defaults")]
pub struct Defaults {
    #[serde(default)]
    height: HeightOverrides,
}

impl KindEntry for Settings {
    const NAME: &'static str = "Height";
    const FIELDS: &'static [&'static str] = &["height", "tessellate"];
    const DEFAULTS: &'static [&'static str] = &["height"];
    const RULE_REFUSAL: Option<&'static str> = Some("a Height reads a high and a low mesh, listed under `assets`");
    type Entry = Entry;
    type Defaults = Defaults;

    fn defaults(written: &Defaults, check: &mut dyn Check) -> Settings {
        let mut settings =
            Settings { height: HeightSettings::default(), tessellate: None, high_mesh: std::path::PathBuf::new() };
        merge_height(check, &mut settings.height, &written.height, 0);
        settings
    }

    fn name_and_encode(entry: &Entry) -> (&str, &EncodeOverrides) {
        (&entry.name, &entry.encode)
    }

    fn resolve(entry: &Entry, defaults: &Settings, check: &mut EntryCheck<'_, '_>) -> Option<(AssetSource, Settings)> {
        let low = check.source_path(&entry.low)?;
        let mut settings = defaults.clone();
        let anchor = check.anchor();
        merge_height(check, &mut settings.height, &entry.height, anchor);
        settings.high_mesh = check.source_path(&entry.high)?;
        settings.tessellate =
            entry.tessellate.as_ref().map(|tessellate| tessellate_settings(check, tessellate, anchor));
        // The height map goes through the texture tail: the same budget holds.
        check.surface_budget("height map", settings.height.size, "size");
        Some((AssetSource::of_file(check.kind(), low), settings))
    }
}
