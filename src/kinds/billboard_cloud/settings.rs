//! The `BillboardCloud` kind's settings: its `billboard` and `atlas` sections as `pipeline.ron`
//! writes them (overrides), as they resolve (settings), and their checks. A leaf: it imports
//! only the libraries and `config/sections`.

use serde::{Deserialize, Serialize};

use crate::config::sections::{explicit, page_size_overrides, Check};
use crate::packing::PageSettings;

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct BillboardSettings {
    pub epsilon: f32,
    pub max_planes: Option<u32>,
    /// The most the LOD may draw (a hard bound on `lod.obj`); with one, ε is searched for and
    /// `epsilon` is ignored.
    pub budget: Option<LodBudget>,
    pub texel_density: Option<f32>,
    /// The height in pixels at which the LOD is meant to be seen (its bounding sphere's
    /// diameter on screen): the atlas gets one texel per pixel there, `texel_density` =
    /// `screen_size / diameter` (none: `texel_density`, else the largest atlas).
    pub screen_size: Option<u32>,
    /// A LOD chain: one level per budget, most detailed first, each baked into `lod<N>/`. Level
    /// N is meant for half the screen size of level N − 1: its `screen_size` or `texel_density`
    /// is halved, and without either its atlas's largest side is `max_size / 2^N` (at least 64).
    /// Empty: one LOD (`budget`, or ε) in the asset's folder.
    pub lods: Vec<LodBudget>,
    pub alpha_cutoff: f32,
}

/// The most levels a LOD chain may have (the viewer switches them with keys 0–9).
pub(crate) const MAX_LOD_LEVELS: usize = 10;

/// What a billboard-cloud LOD may cost: quads (two triangles each) or triangles.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum LodBudget {
    Quads(u32),
    Triangles(u32),
}

impl LodBudget {
    /// The most quads the budget allows.
    pub fn quads(self) -> u32 {
        match self {
            LodBudget::Quads(quads) => quads,
            LodBudget::Triangles(triangles) => triangles / 2,
        }
    }
}

#[derive(Deserialize, Default, Clone)]
#[serde(deny_unknown_fields)]
pub(crate) struct BillboardOverrides {
    pub epsilon: Option<f32>,
    #[serde(default, deserialize_with = "explicit")]
    pub max_planes: Option<Option<u32>>,
    #[serde(default, deserialize_with = "explicit")]
    pub budget: Option<Option<LodBudget>>,
    #[serde(default, deserialize_with = "explicit")]
    pub texel_density: Option<Option<f32>>,
    #[serde(default, deserialize_with = "explicit")]
    pub screen_size: Option<Option<u32>>,
    pub lods: Option<Vec<LodBudget>>,
    pub alpha_cutoff: Option<f32>,
}

#[derive(Deserialize, Default, Clone)]
#[serde(deny_unknown_fields)]
pub(crate) struct AtlasOverrides {
    pub max_size: Option<u32>,
    pub padding: Option<u32>,
    pub power_of_two: Option<bool>,
}

pub(crate) fn merge_billboard(
    check: &mut dyn Check,
    settings: &mut BillboardSettings,
    billboard: &BillboardOverrides,
    anchor: usize,
) {
    if let Some(epsilon) = billboard.epsilon {
        if !(epsilon > 0.0 && epsilon < 1.0) {
            check.error_at_key(
                "epsilon",
                anchor,
                "epsilon must be in (0, 1): it is a fraction of the bounding-sphere radius",
            );
        }
        settings.epsilon = epsilon;
    }
    if let Some(max_planes) = billboard.max_planes {
        if max_planes == Some(0) {
            check.error_at_key("max_planes", anchor, "max_planes must be at least 1");
        }
        settings.max_planes = max_planes;
    }
    if let Some(budget) = billboard.budget {
        if budget.is_some_and(|budget| !(1..=1_000_000).contains(&budget.quads())) {
            check.error_at_key(
                "budget",
                anchor,
                "budget must allow between 1 and 1000000 quads (Triangles: at least 2)",
            );
        }
        settings.budget = budget;
    }
    if let Some(density) = billboard.texel_density {
        if density.is_some_and(|d| !(d > 0.0 && d.is_finite())) {
            check.error_at_key(
                "texel_density",
                anchor,
                "texel_density must be a positive number of texels per world unit",
            );
        }
        settings.texel_density = density;
    }
    if let Some(screen_size) = billboard.screen_size {
        if screen_size.is_some_and(|pixels| !(4..=16384).contains(&pixels)) {
            check.error_at_key("screen_size", anchor, "screen_size must be between 4 and 16384 pixels");
        }
        settings.screen_size = screen_size;
    }
    if let Some(lods) = &billboard.lods {
        if lods.len() > MAX_LOD_LEVELS {
            check.error_at_key("lods", anchor, &format!("a LOD chain has at most {MAX_LOD_LEVELS} levels"));
        }
        if lods.iter().any(|budget| !(1..=1_000_000).contains(&budget.quads())) {
            check.error_at_key(
                "lods",
                anchor,
                "each level must allow between 1 and 1000000 quads (Triangles: at least 2)",
            );
        }
        if lods.is_empty() {
            check.error_at_key(
                "lods",
                anchor,
                "a LOD chain needs at least one level (`lods: [Quads(256), Quads(64)]`); leave `lods` out for a \
                    single LOD",
            );
        }
        if lods.windows(2).any(|pair| pair[1].quads() >= pair[0].quads()) {
            let quads: Vec<String> = lods.iter().map(|budget| budget.quads().to_string()).collect();
            check.error_at_key(
                "lods",
                anchor,
                &format!(
                    "a LOD chain goes from the most detailed level to the least: each level must allow \
                    fewer quads than the one before ({})",
                    quads.join(", ")
                ),
            );
        }
        settings.lods = lods.clone();
    }
    if !settings.lods.is_empty() && settings.budget.is_some() {
        check.error_at_key("lods", anchor, "give budget or lods, not both: a chain's levels carry their own budgets");
    }
    if settings.screen_size.is_some() && settings.texel_density.is_some() {
        check.error_at_key(
            "screen_size",
            anchor,
            "give texel_density or screen_size, not both: each sets the atlas's texels per unit",
        );
    }
    if let Some(cutoff) = billboard.alpha_cutoff {
        if !(0.0..=1.0).contains(&cutoff) {
            check.error_at_key("alpha_cutoff", anchor, "alpha_cutoff must be in [0, 1]");
        }
        settings.alpha_cutoff = cutoff;
    }
}

pub(crate) fn merge_atlas(check: &mut dyn Check, settings: &mut PageSettings, atlas: &AtlasOverrides, anchor: usize) {
    page_size_overrides(check, atlas.max_size, atlas.padding, anchor, &mut settings.max_size, &mut settings.padding);
    if let Some(power_of_two) = atlas.power_of_two {
        settings.power_of_two = power_of_two;
    }
}

impl Default for BillboardSettings {
    fn default() -> BillboardSettings {
        BillboardSettings {
            epsilon: 0.02,
            max_planes: None,
            budget: None,
            texel_density: None,
            screen_size: None,
            lods: Vec::new(),
            alpha_cutoff: 0.5,
        }
    }
}

/// The billboard atlas's page by default.
pub fn default_billboard_atlas() -> PageSettings {
    PageSettings { max_size: 2048, padding: 4, power_of_two: true }
}

/// A `BillboardCloud` asset's own settings.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Settings {
    pub billboard: BillboardSettings,
    pub atlas: PageSettings,
}
