//! The `BillboardCloud` kind's part of `pipeline.ron`: its entry (`BillboardCloud(name: …, mesh:
//! …)`), its `billboard` and `atlas` sections as written (overrides), as they resolve (settings),
//! and their checks. A leaf: it imports only the libraries and `config`'s shared parts.

use serde::{Deserialize, Serialize};

use crate::config::sections::{explicit, merge_alpha_cutoff, page_size_overrides, Check};
use crate::config::{AssetSource, EncodeOverrides, EntryCheck, KindEntry};
use crate::mesh::reduce::TriangleBudget;
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
    /// A LOD chain: one level per entry, most detailed first, each baked into `lod<N>/`: a
    /// billboard cloud at a budget, or the mesh reduced. Level N is meant for half the screen
    /// size of level N − 1: its `screen_size` or `texel_density` is halved, and without either
    /// its atlas's largest side is `max_size / 2^N` (at least 64). Empty: one LOD (`budget`, or
    /// ε) in the asset's folder.
    pub lods: Vec<LodLevel>,
    /// What an `Auto` level bakes and measures besides the reduced triangles.
    pub auto: AutoCandidates,
    pub alpha_cutoff: f32,
}

/// The billboard clouds and impostors an `Auto` level bakes as candidates (each where it fits
/// the level's bytes), beside the source's triangles reduced. By default one of each: 64 quads
/// and 8 × 8 frames. Searching 16, 64 and 256 quads and 8 and 12 frames, the four-level chains
/// (2 MiB, 512, 128 and 32 KiB) of the corpus oak, ash and bush and the bundled bush picked
/// these or the triangles at every level, as they do with the default; each more costs its
/// bake and its measuring (the oak's chain: 7.0 s by default, 12.2 s with all five).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct AutoCandidates {
    /// Billboard clouds of these many quads (ascending, each once).
    pub quads: Vec<u32>,
    /// Full-sphere impostors of these many frames a side (ascending, each once).
    pub impostor_frames: Vec<u32>,
}

impl Default for AutoCandidates {
    fn default() -> AutoCandidates {
        AutoCandidates { quads: vec![64], impostor_frames: vec![8] }
    }
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

/// One level of a LOD chain: a billboard cloud within a budget, or the source's triangles
/// reduced (`mesh::reduce`: meshoptimizer, leaf cards thinned whole).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum LodLevel {
    /// A billboard cloud of at most this many quads.
    Quads(u32),
    /// A billboard cloud of at most this many triangles (two per quad).
    Triangles(u32),
    /// The source mesh with at most `Triangles(n)` or `Ratio(r)` of its triangles.
    Reduced(TriangleBudget),
    /// An octahedral impostor: the mesh seen from `frames × frames` directions on the upper
    /// half of the sphere (`hemi`) or all of it, in atlases of at most `size` texels a side;
    /// drawn as one camera-facing quad by `shaders/impostor.wgsl`.
    Impostor { frames: u32, hemi: bool, size: u32 },
    /// The candidate that holds furthest among those whose bytes on the GPU fit `max_bytes`
    /// (`levels::auto_candidates`: the billboard clouds and impostors of [`AutoCandidates`] and
    /// the source's triangles reduced, each with the largest albedo that fits beside its other
    /// surfaces, these stored up to four times smaller a side), each baked and measured against
    /// the source as the chain's levels are.
    Auto { max_bytes: u64 },
}

/// The bounds of an `Auto` level's bytes.
pub(crate) const AUTO_BYTES: std::ops::RangeInclusive<u64> = 32 * 1024..=1 << 30;

/// The most frames a side an impostor may have.
pub(crate) const MAX_IMPOSTOR_FRAMES: u32 = 32;
/// The smallest side of an impostor's frame, in texels.
pub(crate) const MIN_IMPOSTOR_FRAME: u32 = 16;

impl LodLevel {
    /// The budget of a billboard-cloud level (none: a reduced one).
    pub fn cloud_budget(self) -> Option<LodBudget> {
        match self {
            LodLevel::Quads(quads) => Some(LodBudget::Quads(quads)),
            LodLevel::Triangles(triangles) => Some(LodBudget::Triangles(triangles)),
            LodLevel::Reduced(_) | LodLevel::Impostor { .. } | LodLevel::Auto { .. } => None,
        }
    }

    /// The triangles the level may draw, where the settings alone say (not a ratio).
    fn triangles(self) -> Option<u64> {
        match self {
            LodLevel::Quads(quads) => Some(2 * quads as u64),
            LodLevel::Triangles(triangles) => Some(triangles as u64 / 2 * 2),
            LodLevel::Reduced(TriangleBudget::Triangles(triangles)) => Some(triangles as u64),
            LodLevel::Reduced(TriangleBudget::Ratio(_)) => None,
            // One camera-facing quad.
            LodLevel::Impostor { .. } => Some(2),
            LodLevel::Auto { .. } => None,
        }
    }

    /// The level as `pipeline.ron` writes it.
    fn written(self) -> String {
        match self {
            LodLevel::Impostor { frames, hemi, size } => {
                format!("Impostor(frames: {frames}, hemi: {hemi}, size: {size})")
            }
            LodLevel::Auto { max_bytes } => format!("Auto(max_bytes: {max_bytes})"),
            _ => ron::to_string(&self).unwrap_or_else(|_| format!("{self:?}")),
        }
    }
}

/// Whether `next` asks for less than `previous`: fewer triangles where both counts are known,
/// a smaller ratio between two ratios, a smaller atlas between two impostors; a ratio beside a
/// count cannot be compared before the mesh is read and passes.
fn asks_for_less(previous: LodLevel, next: LodLevel) -> bool {
    match (previous, next) {
        // Two impostors (one quad each): the next one's atlas is smaller.
        (LodLevel::Impostor { size: previous, .. }, LodLevel::Impostor { size: next, .. }) => next < previous,
        (LodLevel::Auto { max_bytes: previous }, LodLevel::Auto { max_bytes: next }) => next < previous,
        (LodLevel::Reduced(TriangleBudget::Ratio(previous)), LodLevel::Reduced(TriangleBudget::Ratio(next))) => {
            next < previous
        }
        _ => match (previous.triangles(), next.triangles()) {
            (Some(previous), Some(next)) => next < previous,
            _ => true,
        },
    }
}

/// What is wrong with one level of a chain on its own, if anything.
fn level_problem(level: LodLevel) -> Option<String> {
    match level {
        LodLevel::Reduced(TriangleBudget::Triangles(triangles))
            if !(1..=MAX_REDUCED_TRIANGLES).contains(&triangles) =>
        {
            Some(format!("{}: a reduced level keeps between 1 and {MAX_REDUCED_TRIANGLES} triangles", level.written()))
        }
        LodLevel::Reduced(TriangleBudget::Ratio(ratio)) if !(ratio > 0.0 && ratio < 1.0) => {
            Some(format!("{}: a reduced level keeps a ratio in (0, 1) of the source's triangles", level.written()))
        }
        LodLevel::Impostor { frames, .. } if !(2..=MAX_IMPOSTOR_FRAMES).contains(&frames) => {
            Some(format!("{}: an impostor has 2 to {MAX_IMPOSTOR_FRAMES} frames a side", level.written()))
        }
        LodLevel::Impostor { size, .. } if !(64..=8192).contains(&size) => {
            Some(format!("{}: an impostor's atlas is 64 to 8192 texels a side", level.written()))
        }
        LodLevel::Auto { max_bytes } if !AUTO_BYTES.contains(&max_bytes) => Some(format!(
            "{}: an automatic level's bytes are {} to {}",
            level.written(),
            AUTO_BYTES.start(),
            AUTO_BYTES.end()
        )),
        LodLevel::Impostor { frames, size, .. } if size / frames < MIN_IMPOSTOR_FRAME => Some(format!(
            "{}: {frames} frames a side leave {} texels a frame in {size}; give each at least \
            {MIN_IMPOSTOR_FRAME} (fewer frames or a larger size)",
            level.written(),
            size / frames
        )),
        _ => None,
    }
}

/// The largest triangle count a reduced level may ask for.
pub(crate) const MAX_REDUCED_TRIANGLES: u32 = 100_000_000;

#[derive(Deserialize, Default, Clone)]
#[serde(deny_unknown_fields)]
pub struct BillboardOverrides {
    pub epsilon: Option<f32>,
    #[serde(default, deserialize_with = "explicit")]
    pub max_planes: Option<Option<u32>>,
    #[serde(default, deserialize_with = "explicit")]
    pub budget: Option<Option<LodBudget>>,
    #[serde(default, deserialize_with = "explicit")]
    pub texel_density: Option<Option<f32>>,
    #[serde(default, deserialize_with = "explicit")]
    pub screen_size: Option<Option<u32>>,
    pub lods: Option<Vec<LodLevel>>,
    pub auto: Option<AutoOverrides>,
    pub alpha_cutoff: Option<f32>,
}

#[derive(Deserialize, Default, Clone)]
#[serde(deny_unknown_fields)]
pub struct AutoOverrides {
    pub quads: Option<Vec<u32>>,
    pub impostor_frames: Option<Vec<u32>>,
}

#[derive(Deserialize, Default, Clone)]
#[serde(deny_unknown_fields)]
pub struct AtlasOverrides {
    pub max_size: Option<u32>,
    pub padding: Option<u32>,
    pub power_of_two: Option<bool>,
}

fn merge_billboard(
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
        let clouds = lods.iter().filter_map(|level| level.cloud_budget());
        if clouds.clone().any(|budget| !(1..=1_000_000).contains(&budget.quads())) {
            check.error_at_key(
                "lods",
                anchor,
                "each level must allow between 1 and 1000000 quads (Triangles: at least 2)",
            );
        }
        for problem in lods.iter().filter_map(|&level| level_problem(level)) {
            check.error_at_key("lods", anchor, &problem);
        }
        if lods.is_empty() {
            check.error_at_key(
                "lods",
                anchor,
                "a LOD chain needs at least one level (`lods: [Quads(256), Quads(64)]`); leave `lods` out for a \
                    single LOD",
            );
        }
        if lods.windows(2).any(|pair| !asks_for_less(pair[0], pair[1])) {
            let written: Vec<String> = lods.iter().map(|level| level.written()).collect();
            check.error_at_key(
                "lods",
                anchor,
                &format!(
                    "a LOD chain goes from the most detailed level to the least: each level must draw fewer \
                    triangles than the one before, an impostor after an impostor a smaller atlas, an automatic \
                    level after an automatic one fewer bytes ({})",
                    written.join(", ")
                ),
            );
        }
        settings.lods = lods.clone();
    }
    if let Some(auto) = &billboard.auto {
        merge_auto(check, &mut settings.auto, auto, anchor);
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
    merge_alpha_cutoff(check, &mut settings.alpha_cutoff, billboard.alpha_cutoff, anchor);
}

fn merge_auto(check: &mut dyn Check, settings: &mut AutoCandidates, auto: &AutoOverrides, anchor: usize) {
    let lists = [
        (&auto.quads, &mut settings.quads, "quads", 1..=1_000_000u32),
        (&auto.impostor_frames, &mut settings.impostor_frames, "impostor_frames", 2..=MAX_IMPOSTOR_FRAMES),
    ];
    for (given, list, name, range) in lists {
        let Some(given) = given else { continue };
        if let Some(outside) = given.iter().find(|count| !range.contains(count)) {
            let message =
                format!("auto.{name} must each be between {} and {} (not {outside})", range.start(), range.end());
            check.error_at_key("auto", anchor, &message);
        }
        if given.windows(2).any(|pair| pair[0] >= pair[1]) {
            let message = format!("auto.{name} must go up, each count once (each names its candidate): {given:?}");
            check.error_at_key("auto", anchor, &message);
        }
        *list = given.clone();
    }
}

fn merge_atlas(check: &mut dyn Check, settings: &mut PageSettings, atlas: &AtlasOverrides, anchor: usize) {
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
            auto: AutoCandidates::default(),
            alpha_cutoff: crate::config::sections::DEFAULT_ALPHA_CUTOFF,
        }
    }
}

/// The billboard atlas's page by default.
pub fn default_billboard_atlas() -> PageSettings {
    PageSettings { max_size: 2048, padding: 4, power_of_two: true }
}

/// A `BillboardCloud` asset's own settings.
#[derive(Clone, Debug, PartialEq)]
pub struct Settings {
    pub billboard: BillboardSettings,
    pub atlas: PageSettings,
}

/// A `BillboardCloud` entry as `pipeline.ron` writes it.
#[derive(Deserialize)]
#[serde(rename = "BillboardCloud", deny_unknown_fields)]
pub struct Entry {
    name: String,
    mesh: String,
    #[serde(default)]
    billboard: BillboardOverrides,
    #[serde(default)]
    atlas: AtlasOverrides,
    #[serde(default)]
    encode: EncodeOverrides,
}

/// The sections of `defaults:` a billboard cloud reads.
#[derive(Deserialize, Default)]
#[serde(rename = "defaults")]
pub struct Defaults {
    #[serde(default)]
    billboard: BillboardOverrides,
    #[serde(default)]
    atlas: AtlasOverrides,
}

impl KindEntry for Settings {
    const NAME: &'static str = "BillboardCloud";
    const FIELDS: &'static [&'static str] = &["billboard", "atlas"];
    const DEFAULTS: &'static [&'static str] = &["billboard", "atlas"];
    type Entry = Entry;
    type Defaults = Defaults;

    fn defaults(written: &Defaults, check: &mut dyn Check) -> Settings {
        let mut settings = Settings { billboard: BillboardSettings::default(), atlas: default_billboard_atlas() };
        merge(check, &mut settings, &written.billboard, &written.atlas, 0);
        settings
    }

    fn name_and_encode(entry: &Entry) -> (&str, &EncodeOverrides) {
        (&entry.name, &entry.encode)
    }

    fn resolve(entry: &Entry, defaults: &Settings, check: &mut EntryCheck<'_, '_>) -> Option<(AssetSource, Settings)> {
        let mesh = check.source_path(&entry.mesh)?;
        let mut settings = defaults.clone();
        let anchor = check.anchor();
        merge(check, &mut settings, &entry.billboard, &entry.atlas, anchor);
        // Each atlas surface goes through the texture tail: the same budget holds.
        check.surface_budget("atlas", settings.atlas.max_size, "max_size");
        Some((AssetSource::of_file(check.kind(), mesh), settings))
    }
}

fn merge(
    check: &mut dyn Check,
    settings: &mut Settings,
    billboard: &BillboardOverrides,
    atlas: &AtlasOverrides,
    at: usize,
) {
    merge_billboard(check, &mut settings.billboard, billboard, at);
    merge_atlas(check, &mut settings.atlas, atlas, at);
}
