//! A billboard cloud's LOD levels: what each level is asked for (a cloud's budget, ε and atlas,
//! a reduced mesh's triangles, or an impostor's frames), its folder and its label. One level without `lods` (the
//! asset's folder); one per entry of a chain (`lod0/`, `lod1/`, …), each meant for half the
//! screen size of the one before.

use crate::config::Settings;
use crate::kinds::billboard_cloud::settings::{LodLevel, Settings as Own};
use crate::mesh::reduce::TriangleBudget;
use crate::packing::PageSettings;

/// What one level of a billboard cloud is asked for.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LevelSettings {
    pub planes: super::planes::PlaneSettings,
    pub texel_density: Option<f32>,
    pub screen_size: Option<u32>,
    /// The largest side its atlas may take.
    pub max_atlas_size: u32,
    /// A reduced level's triangles (none: a billboard cloud, which the fields above describe,
    /// or an impostor).
    pub reduced: Option<TriangleBudget>,
    /// An impostor level's frames (none: a billboard cloud or a reduced mesh).
    pub impostor: Option<crate::impostor::ImpostorSettings>,
}

/// The levels an asset bakes: one per budget of its chain, else one.
pub fn level_count(settings: &Settings) -> u32 {
    settings.own::<Own>().billboard.lods.len().max(1) as u32
}

/// Whether the asset bakes a LOD chain (each level in a folder of its own).
pub(crate) fn is_chain(settings: &Settings) -> bool {
    !settings.own::<Own>().billboard.lods.is_empty()
}

/// What level `level` is asked for. A chain's level N halves level N − 1's screen size or texel
/// density; with neither, its atlas's largest side is `max_size / 2^N` (at least 64 texels,
/// a multiple of 4). Level 0, and the one level of an asset without a chain, take the settings
/// as they are.
pub(crate) fn settings_for(settings: &Settings, level: u32) -> LevelSettings {
    let billboard = &settings.own::<Own>().billboard;
    let entry = billboard.lods.get(level as usize).copied();
    let budget = match entry {
        Some(entry) => entry.cloud_budget(),
        None => billboard.budget,
    };
    let halvings = level.min(31);
    let max_size = settings.own::<Own>().atlas.max_size;
    let max_atlas_size = if billboard.screen_size.is_none() && billboard.texel_density.is_none() {
        ((max_size >> halvings).max(64.min(max_size))) & !3
    } else {
        max_size
    };
    LevelSettings {
        planes: super::planes::PlaneSettings {
            epsilon: billboard.epsilon,
            max_planes: billboard.max_planes,
            max_quads: budget.map(crate::config::LodBudget::quads),
        },
        texel_density: billboard.texel_density.map(|density| density / (1u64 << halvings) as f32),
        screen_size: billboard.screen_size.map(|pixels| (pixels >> halvings).max(4)),
        max_atlas_size,
        reduced: match entry {
            Some(LodLevel::Reduced(triangles)) => Some(triangles),
            _ => None,
        },
        impostor: match entry {
            Some(LodLevel::Impostor { frames, hemi, size }) => Some(impostor_settings(frames, hemi, size)),
            _ => None,
        },
    }
}

/// An impostor level's frames: `frames` a side, each `size / frames` texels (down to a multiple
/// of 4, whole blocks), on the hemi- or full octahedron.
pub(crate) fn impostor_settings(frames: u32, hemi: bool, size: u32) -> crate::impostor::ImpostorSettings {
    use crate::mesh::octahedral::FrameGrid;
    let frames = frames.max(2);
    crate::impostor::ImpostorSettings { grid: FrameGrid::new(frames, hemi), frame_size: ((size / frames) & !3).max(4) }
}

/// Whether level `level` is a reduced mesh (no planes, atlas or renders).
pub(crate) fn is_reduced(settings: &Settings, level: u32) -> bool {
    settings_for(settings, level).reduced.is_some()
}

/// Whether level `level` is an impostor (its frames' atlases, no planes).
pub(crate) fn is_impostor(settings: &Settings, level: u32) -> bool {
    settings_for(settings, level).impostor.is_some()
}

/// Whether level `level` is a billboard cloud (planes, layout, renders, atlas).
pub(crate) fn is_cloud(settings: &Settings, level: u32) -> bool {
    let level = settings_for(settings, level);
    level.reduced.is_none() && level.impostor.is_none()
}

/// The atlas settings of a level: the asset's, with the level's largest side.
pub(crate) fn level_atlas_settings(atlas: &PageSettings, level: &LevelSettings) -> PageSettings {
    PageSettings { max_size: level.max_atlas_size, ..atlas.clone() }
}

/// The folder a level's files go to, inside the asset's: `lod<N>` in a chain, else none.
pub fn level_folder(settings: &Settings, level: u32) -> String {
    if is_chain(settings) {
        format!("lod{level}")
    } else {
        String::new()
    }
}

/// The level of a chain folder name (`lod2` → 2); the asset's own folder is level 0.
pub fn level_of_folder(folder: &str) -> Option<u32> {
    if folder.is_empty() {
        return Some(0);
    }
    folder.strip_prefix("lod")?.parse().ok()
}

/// A level's stage label: the asset's name, or `asset/lod<N>` in a chain.
pub fn label(asset_name: &str, folder: &str) -> String {
    if folder.is_empty() {
        asset_name.to_string()
    } else {
        format!("{asset_name}/{folder}")
    }
}
