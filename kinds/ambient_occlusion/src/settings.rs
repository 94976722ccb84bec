//! The `AmbientOcclusion` kind's part of `pipeline.ron`: its entry (`AmbientOcclusion(name: …,
//! mesh: …)`), its `ao` section as written (overrides), as it resolves (settings), and its
//! checks. A leaf: it imports only the libraries and `config`'s shared parts.

use serde::{Deserialize, Serialize};

use crate::config::sections::{explicit, Check};
use crate::config::{AssetSource, EncodeOverrides, EntryCheck, KindEntry};
use crate::mesh::occlusion::RayDistribution;

/// How an `AmbientOcclusion` asset bakes: per texel (rays from every texel's surface point) or
/// per vertex (the seed's method: rays from the vertices, interpolated across each triangle).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum AoMode {
    Texels,
    Vertices,
}

/// What occludes an `AmbientOcclusion` asset's points: each OBJ object only itself, or every
/// object of the OBJ.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum AoOccluders {
    SelfOnly,
    AllMeshes,
}

/// How an `AmbientOcclusion` asset is baked (DESIGN §3.3).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct AoSettings {
    /// Width and height of each material's map, in texels.
    pub size: u32,
    pub rays: u32,
    pub mode: AoMode,
    pub distribution: crate::mesh::occlusion::RayDistribution,
    /// Hits farther than this fraction of the mesh's bounding-box diagonal do not occlude.
    pub max_distance: Option<f32>,
    pub occluders: AoOccluders,
    /// Rays pass through back faces (and texels that see mostly back faces are inside geometry).
    pub ignore_backfaces: bool,
    /// An infinite floor under the mesh (at its lowest Y) occludes too.
    pub ground_plane: bool,
    /// The gutter around each UV island that takes the island's edge values (every texel is
    /// filled, so this is a floor, always met).
    pub padding: u32,
}

#[derive(Deserialize, Default, Clone)]
#[serde(deny_unknown_fields)]
pub struct AoOverrides {
    pub size: Option<u32>,
    pub rays: Option<u32>,
    pub mode: Option<AoMode>,
    pub distribution: Option<RayDistribution>,
    #[serde(default, deserialize_with = "explicit")]
    pub max_distance: Option<Option<f32>>,
    pub occluders: Option<AoOccluders>,
    pub ignore_backfaces: Option<bool>,
    pub ground_plane: Option<bool>,
    pub padding: Option<u32>,
}

fn merge_ao(check: &mut dyn Check, settings: &mut AoSettings, ao: &AoOverrides, anchor: usize) {
    if let Some(size) = ao.size {
        if !(16..=16384).contains(&size) || size % 4 != 0 {
            check.error_at_key("size", anchor, "size must be a multiple of 4 between 16 and 16384");
        }
        settings.size = size;
    }
    if let Some(rays) = ao.rays {
        if !(1..=1 << 20).contains(&rays) {
            check.error_at_key("rays", anchor, "rays must be between 1 and 1048576");
        }
        settings.rays = rays;
    }
    if let Some(max_distance) = ao.max_distance {
        if max_distance.is_some_and(|distance| !(distance > 0.0 && distance.is_finite())) {
            check.error_at_key(
                "max_distance",
                anchor,
                "max_distance must be a positive fraction of the bounding-box diagonal",
            );
        }
        settings.max_distance = max_distance;
    }
    if let Some(padding) = ao.padding {
        if padding > 256 {
            check.error_at_key("padding", anchor, "padding must be at most 256 texels");
        }
        settings.padding = padding;
    }
    settings.mode = ao.mode.unwrap_or(settings.mode);
    settings.distribution = ao.distribution.unwrap_or(settings.distribution);
    settings.occluders = ao.occluders.unwrap_or(settings.occluders);
    settings.ignore_backfaces = ao.ignore_backfaces.unwrap_or(settings.ignore_backfaces);
    settings.ground_plane = ao.ground_plane.unwrap_or(settings.ground_plane);
}

impl Default for AoSettings {
    fn default() -> AoSettings {
        AoSettings {
            size: 1024,
            rays: 256,
            mode: AoMode::Texels,
            distribution: RayDistribution::Cosine,
            max_distance: None,
            occluders: AoOccluders::SelfOnly,
            ignore_backfaces: true,
            ground_plane: false,
            padding: 16,
        }
    }
}

/// An `AmbientOcclusion` asset's own settings.
#[derive(Clone, Debug, PartialEq)]
pub struct Settings {
    pub ao: AoSettings,
}

/// An `AmbientOcclusion` entry as `pipeline.ron` writes it.
#[derive(Deserialize)]
#[serde(rename = "AmbientOcclusion", deny_unknown_fields)]
pub struct Entry {
    name: String,
    mesh: String,
    #[serde(default)]
    ao: AoOverrides,
    #[serde(default)]
    encode: EncodeOverrides,
}

/// The sections of `defaults:` an AO bake reads.
#[derive(Deserialize, Default)]
#[serde(rename = "defaults")]
pub struct Defaults {
    #[serde(default)]
    ao: AoOverrides,
}

impl KindEntry for Settings {
    const NAME: &'static str = "AmbientOcclusion";
    const FIELDS: &'static [&'static str] = &["ao"];
    const DEFAULTS: &'static [&'static str] = &["ao"];
    type Entry = Entry;
    type Defaults = Defaults;

    fn defaults(written: &Defaults, check: &mut dyn Check) -> Settings {
        let mut settings = Settings { ao: AoSettings::default() };
        merge_ao(check, &mut settings.ao, &written.ao, 0);
        settings
    }

    fn name_and_encode(entry: &Entry) -> (&str, &EncodeOverrides) {
        (&entry.name, &entry.encode)
    }

    fn resolve(entry: &Entry, defaults: &Settings, check: &mut EntryCheck<'_, '_>) -> Option<(AssetSource, Settings)> {
        let mesh = check.source_path(&entry.mesh)?;
        let mut settings = defaults.clone();
        let anchor = check.anchor();
        merge_ao(check, &mut settings.ao, &entry.ao, anchor);
        // Each material's AO map goes through the texture tail: the same budget holds.
        check.surface_budget("AO map", settings.ao.size, "size");
        Some((AssetSource::of_file(check.kind(), mesh), settings))
    }
}
