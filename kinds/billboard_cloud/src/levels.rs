//! A billboard cloud's LOD levels: what each level is asked for (a cloud's budget, ε and atlas,
//! a reduced mesh's triangles, or an impostor's frames), its folder and its label. One level without `lods` (the
//! asset's folder); one per entry of a chain (`lod0/`, `lod1/`, …), each meant for half the
//! screen size of the one before.

use crate::config::Settings;
use crate::mesh::reduce::TriangleBudget;
use crate::packing::PageSettings;
use crate::settings::{LodLevel, Settings as Own};
use crate::texture::SurfaceKind;

/// An impostor level's surfaces: albedo with coverage, the frames' normals, their depth (in the
/// height surface: a distance from the frame's centre plane, as a cloud's height is from its).
pub(crate) const IMPOSTOR_SURFACES: [SurfaceKind; 3] = [SurfaceKind::Albedo, SurfaceKind::Normal, SurfaceKind::Height];

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
    /// How many times each surface but the albedo halves the albedo's side (an `Auto`
    /// candidate's, see [`allot_surfaces`]; none elsewhere).
    pub surface_halvings: SurfaceHalvings,
    /// An `Auto` candidate's bytes on the GPU (its level's): what a reduced candidate's maps
    /// are sized by, once its mesh is made (none elsewhere).
    pub max_bytes: Option<u64>,
}

/// How many times each surface of a level but its albedo halves the albedo's side: it is stored
/// as that level of its mip chain (`texture::mips::reduced_level`), with the same UVs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SurfaceHalvings {
    pub mra: u32,
    pub normal: u32,
    pub height: u32,
}

impl SurfaceHalvings {
    /// The halvings of `surface` (the albedo's: none).
    pub fn of(self, surface: SurfaceKind) -> u32 {
        match surface {
            SurfaceKind::Mra => self.mra,
            SurfaceKind::Normal => self.normal,
            SurfaceKind::Height => self.height,
            SurfaceKind::Albedo | SurfaceKind::Ao => 0,
        }
    }

    fn of_mut(&mut self, surface: SurfaceKind) -> Option<&mut u32> {
        match surface {
            SurfaceKind::Mra => Some(&mut self.mra),
            SurfaceKind::Normal => Some(&mut self.normal),
            SurfaceKind::Height => Some(&mut self.height),
            SurfaceKind::Albedo | SurfaceKind::Ao => None,
        }
    }
}

/// The levels of an asset's chain (one without a chain).
pub fn level_count(settings: &Settings) -> u32 {
    settings.own::<Own>().billboard.lods.len().max(1) as u32
}

/// Whether the asset bakes a LOD chain (each level in a folder of its own).
pub(crate) fn is_chain(settings: &Settings) -> bool {
    !settings.own::<Own>().billboard.lods.is_empty()
}

/// One thing an asset bakes (its queries' `level` argument is its index in [`slots`]): a level
/// of its chain, or one candidate of an `Auto` level.
#[derive(Clone, Debug, PartialEq)]
pub struct Slot {
    /// The chain's level it is (or is a candidate for).
    pub level: u32,
    /// What it bakes (never `Auto`); `None`: the asset's one level without a chain (`budget`).
    pub bakes: Option<LodLevel>,
    /// A candidate's largest atlas side (none: the chain's halving rule).
    pub atlas_size: Option<u32>,
    /// A candidate's name: its folder under `lod<N>/candidates/`.
    pub candidate: Option<String>,
    /// A candidate's surfaces smaller than its albedo (none elsewhere).
    pub halvings: SurfaceHalvings,
    /// A candidate's bytes on the GPU (its `Auto` level's; none elsewhere).
    pub max_bytes: Option<u64>,
}

/// What an asset bakes: each level of its chain, an `Auto` level as its candidates
/// ([`auto_candidates`]); one level without a chain.
pub fn slots(settings: &Settings) -> Vec<Slot> {
    let lods = &settings.own::<Own>().billboard.lods;
    if lods.is_empty() {
        let one = Slot {
            level: 0,
            bakes: None,
            atlas_size: None,
            candidate: None,
            halvings: Default::default(),
            max_bytes: None,
        };
        return vec![one];
    }
    let mut slots = Vec::new();
    for (level, &entry) in lods.iter().enumerate() {
        match entry {
            LodLevel::Auto { max_bytes } => slots.extend(auto_candidates(settings, level as u32, max_bytes)),
            entry => slots.push(Slot {
                level: level as u32,
                bakes: Some(entry),
                atlas_size: None,
                candidate: None,
                halvings: Default::default(),
                max_bytes: None,
            }),
        }
    }
    slots
}

/// How many things an asset bakes ([`slots`]).
pub fn slot_count(settings: &Settings) -> u32 {
    slots(settings).len() as u32
}

/// The bytes on the GPU of a quad's vertex (position, normal, tangent, UV) and of its six
/// indices, at most: what a candidate's mesh is budgeted at.
const QUAD_MESH_BYTES: u64 = 4 * 48 + 6 * 4;

/// The share of an atlas the layout fills at best (75–80 % measured on the corpus oak).
const PACKED_SHARE: f64 = 0.75;

/// Whether `quads` rectangles of at least one BC block each, with `padding` texels around, pack
/// into a `side`² atlas. Where they do not, the layout falls back to an atlas as large as they
/// need (a 256-quad candidate planned at 64² came out at 256², 317 KB against its 128 KiB).
fn quads_pack(quads: u32, side: u32, padding: u32) -> bool {
    let cell = (4 + 2 * padding).div_ceil(4) as f64 * 4.0;
    quads as f64 * cell * cell <= PACKED_SHARE * side as f64 * side as f64
}

/// The most times a surface of an `Auto` candidate halves its albedo's side.
const MAX_SURFACE_HALVINGS: u32 = 2;

/// The order in which a candidate's surfaces besides its albedo win back texels: the normal
/// (lighting), the height (an impostor's depth, a cloud's relief), the packed surface.
const SURFACE_PRIORITY: [SurfaceKind; 3] = [SurfaceKind::Normal, SurfaceKind::Height, SurfaceKind::Mra];

/// How a candidate's `surfaces` share `max_bytes` (its mesh's bytes taken out) with the albedo at
/// `side`: every other surface at most `max_halvings` (and [`MAX_SURFACE_HALVINGS`]) times
/// smaller, then each, in [`SURFACE_PRIORITY`] order and one halving a round, as large as the
/// bytes allow. The albedo carries the coverage that the silhouette is cut from, which is what
/// a far level loses first (a 128 KiB cloud at 128² with every surface loses 2.8 px-shift units
/// on the oak at 64 px, at 256² 0.95). None when even the smallest do not fit.
pub fn allot_surfaces(
    surfaces: &[SurfaceKind],
    side: u32,
    max_halvings: u32,
    bytes_of: impl Fn(SurfaceKind, u32) -> u64,
    max_bytes: u64,
) -> Option<SurfaceHalvings> {
    let max_halvings = max_halvings.min(MAX_SURFACE_HALVINGS);
    let mut halvings = SurfaceHalvings::default();
    for &surface in surfaces {
        if let Some(value) = halvings.of_mut(surface) {
            *value = max_halvings;
        }
    }
    let bytes = |halvings: &SurfaceHalvings| -> u64 {
        surfaces.iter().map(|&surface| bytes_of(surface, side >> halvings.of(surface))).sum()
    };
    if bytes(&halvings) > max_bytes {
        return None;
    }
    for _ in 0..max_halvings {
        for surface in SURFACE_PRIORITY.into_iter().filter(|surface| surfaces.contains(surface)) {
            let mut larger = halvings;
            let Some(value) = larger.of_mut(surface) else { continue };
            if *value > 0 {
                *value -= 1;
                if bytes(&larger) <= max_bytes {
                    halvings = larger;
                }
            }
        }
    }
    Some(halvings)
}

/// The candidates of `level`, an `Auto` level of at most `max_bytes` on the GPU: the billboard
/// clouds and full-sphere impostors of the asset's `auto` settings (by default 64 quads and 8
/// frames a side; `settings::AutoCandidates`), each with the
/// largest power-of-two albedo (at least 64 texels, at most the asset's `max_size`; an
/// impostor's frames at least 16 texels) beside which its other surfaces fit, up to four times
/// smaller a side ([`allot_surfaces`]), with its quads, and in which its quads pack (see
/// [`quads_pack`]); and the source's triangles under half the bytes (at
/// [`REDUCED_TRIANGLE_BYTES`] a triangle), its maps sized by the rest once its mesh is made
/// (`reduced::allot_maps`). A candidate that fits at no size is left out.
pub fn auto_candidates(settings: &Settings, level: u32, max_bytes: u64) -> Vec<Slot> {
    use crate::texture::encode::gpu_bytes;
    let (max_size, padding) = (settings.own::<Own>().atlas.max_size, settings.own::<Own>().atlas.padding);
    let encode = &settings.encode;
    let bytes_of = |surface: SurfaceKind, side: u32| gpu_bytes(side, side, Some(encode.format_of(surface)));
    let sides = || (6..=13).rev().map(|power| 1u32 << power).filter(|&side| side <= max_size);
    let auto = &settings.own::<Own>().billboard.auto;
    let mut candidates = Vec::new();
    for &quads in &auto.quads {
        let Some(mesh_bytes) = max_bytes.checked_sub(quads as u64 * QUAD_MESH_BYTES) else { continue };
        let fits = |side: u32| {
            quads_pack(quads, side, padding)
                .then(|| allot_surfaces(&SurfaceKind::BILLBOARD, side, u32::MAX, bytes_of, mesh_bytes))
                .flatten()
        };
        if let Some((side, halvings)) = sides().find_map(|side| fits(side).map(|halvings| (side, halvings))) {
            candidates.push(Slot {
                level,
                bakes: Some(LodLevel::Quads(quads)),
                atlas_size: Some(side),
                candidate: Some(format!("quads{quads}")),
                halvings,
                max_bytes: Some(max_bytes),
            });
        }
    }
    for &frames in &auto.impostor_frames {
        let Some(mesh_bytes) = max_bytes.checked_sub(QUAD_MESH_BYTES) else { continue };
        // The largest frame (a multiple of 4 texels, of 8 or 16 where its other surfaces are
        // stored at a half or a quarter side, so that each frame keeps whole blocks in them).
        let fits = |side: u32| {
            (0..=MAX_SURFACE_HALVINGS)
                .filter_map(|max_halvings| {
                    let frame = side / frames / (4 << max_halvings) * (4 << max_halvings);
                    let surfaces = &IMPOSTOR_SURFACES;
                    (frame >= super::settings::MIN_IMPOSTOR_FRAME)
                        .then(|| allot_surfaces(surfaces, frames * frame, max_halvings, bytes_of, mesh_bytes))
                        .flatten()
                        .map(|halvings| (frame, halvings))
                })
                .max_by_key(|&(frame, _)| frame)
        };
        if let Some((side, (frame, halvings))) = sides().find_map(|side| fits(side).map(|fit| (side, fit))) {
            candidates.push(Slot {
                level,
                bakes: Some(LodLevel::Impostor { frames, hemi: false, size: frames * frame }),
                atlas_size: Some(side),
                candidate: Some(format!("impostor{frames}")),
                halvings,
                max_bytes: Some(max_bytes),
            });
        }
    }
    // The source's triangles under a budget that leaves its maps the other half of the bytes
    // (each at most `max_size` a side; sized once the mesh is made, `reduced::allot_maps`).
    let triangles = max_bytes / 2 / REDUCED_TRIANGLE_BYTES;
    if triangles >= MIN_AUTO_REDUCED_TRIANGLES {
        let triangles = triangles.min(super::settings::MAX_REDUCED_TRIANGLES as u64) as u32;
        candidates.push(Slot {
            level,
            bakes: Some(LodLevel::Reduced(TriangleBudget::Triangles(triangles))),
            atlas_size: Some(max_size),
            candidate: Some(format!("reduced{triangles}")),
            halvings: Default::default(),
            max_bytes: Some(max_bytes),
        });
    }
    candidates
}

/// The bytes on the GPU a reduced mesh's triangle is budgeted at: its three indices and two
/// vertices (position, normal, tangent, UV): a leaf card's two triangles have four corners.
const REDUCED_TRIANGLE_BYTES: u64 = 3 * 4 + 2 * 48;

/// The fewest triangles an `Auto` level's reduced candidate keeps: below it a tree is a trunk
/// and a few cards, which no level is better off with.
const MIN_AUTO_REDUCED_TRIANGLES: u64 = 256;

/// What slot `slot` (of [`slots`]) is asked for. A chain's level N halves level N − 1's screen
/// size or texel density; with neither, its atlas's largest side is `max_size / 2^N` (at least
/// 64 texels, a multiple of 4), a candidate's its own. Level 0, and the one level of an asset
/// without a chain, take the settings as they are.
pub(crate) fn settings_for(settings: &Settings, slot: u32) -> LevelSettings {
    let billboard = &settings.own::<Own>().billboard;
    let slot = slots(settings).into_iter().nth(slot as usize);
    let (level, entry, atlas_size, surface_halvings, max_bytes) = slot
        .map_or((0, None, None, Default::default(), None), |slot| {
            (slot.level, slot.bakes, slot.atlas_size, slot.halvings, slot.max_bytes)
        });
    let budget = match entry {
        Some(entry) => entry.cloud_budget(),
        None => billboard.budget,
    };
    let halvings = level.min(31);
    let max_size = settings.own::<Own>().atlas.max_size;
    let max_atlas_size = match atlas_size {
        Some(side) => side,
        None if billboard.screen_size.is_none() && billboard.texel_density.is_none() => {
            ((max_size >> halvings).max(64.min(max_size))) & !3
        }
        None => max_size,
    };
    LevelSettings {
        planes: super::planes::PlaneSettings {
            epsilon: billboard.epsilon,
            max_planes: billboard.max_planes,
            max_quads: budget.map(super::settings::LodBudget::quads),
        },
        // A candidate's atlas is its own: the density fills it.
        texel_density: billboard
            .texel_density
            .filter(|_| atlas_size.is_none())
            .map(|density| density / (1u64 << halvings) as f32),
        screen_size: billboard.screen_size.filter(|_| atlas_size.is_none()).map(|pixels| (pixels >> halvings).max(4)),
        max_atlas_size,
        reduced: match entry {
            Some(LodLevel::Reduced(triangles)) => Some(triangles),
            _ => None,
        },
        impostor: match entry {
            Some(LodLevel::Impostor { frames, hemi, size }) => Some(impostor_settings(frames, hemi, size)),
            _ => None,
        },
        surface_halvings,
        max_bytes,
    }
}

/// An impostor level's frames: `frames` a side, each `size / frames` texels (down to a multiple
/// of 4, whole blocks), on the hemi- or full octahedron.
pub(crate) fn impostor_settings(frames: u32, hemi: bool, size: u32) -> crate::impostor::ImpostorSettings {
    use crate::mesh::octahedral::FrameGrid;
    let frames = frames.max(2);
    crate::impostor::ImpostorSettings { grid: FrameGrid::new(frames, hemi), frame_size: ((size / frames) & !3).max(4) }
}

/// How an impostor slot's frames are made: rendered (`source` is the slot itself), or reduced
/// `factor` times a side from those of `source`, the slot with the same grid and the largest
/// frame that is a whole multiple of its own (`impostor::reduced_frames`: renders of the same
/// views run once). Every slot sharing a render keeps the margins of the smallest frame among
/// them (`margin_frame`, `impostor::frame_rects_with_margin`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ImpostorRender {
    pub source: u32,
    pub factor: u32,
    pub margin_frame: u32,
}

/// [`ImpostorRender`] of slot `slot` (none: not an impostor).
pub(crate) fn impostor_render(settings: &Settings, slot: u32) -> Option<ImpostorRender> {
    let own = settings_for(settings, slot).impostor?;
    let impostors: Vec<(u32, crate::impostor::ImpostorSettings)> =
        (0..slot_count(settings)).filter_map(|other| Some((other, settings_for(settings, other).impostor?))).collect();
    let source_of = |of: crate::impostor::ImpostorSettings| -> (u32, u32) {
        let multiple = |other: &crate::impostor::ImpostorSettings| {
            other.grid == of.grid && other.frame_size.is_multiple_of(of.frame_size)
        };
        impostors
            .iter()
            .filter(|(_, other)| multiple(other))
            .max_by_key(|(other_slot, other)| (other.frame_size, std::cmp::Reverse(*other_slot)))
            .map_or((slot, 1), |(other_slot, other)| (*other_slot, other.frame_size / of.frame_size))
    };
    let (source, factor) = source_of(own);
    let sharing = impostors.iter().filter(|(_, other)| other.grid == own.grid && source_of(*other).0 == source);
    let margin_frame = sharing.map(|(_, other)| other.frame_size).min().unwrap_or(own.frame_size);
    Some(ImpostorRender { source, factor, margin_frame })
}

/// The first billboard-cloud slot that asks for the same planes as `slot` (`slot` itself when
/// none before it does, or when it is not a cloud).
pub(crate) fn first_slot_with_planes(settings: &Settings, slot: u32) -> u32 {
    if !is_cloud(settings, slot) {
        return slot;
    }
    let planes = settings_for(settings, slot).planes;
    (0..slot).find(|&other| is_cloud(settings, other) && settings_for(settings, other).planes == planes).unwrap_or(slot)
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

/// The folder level `level` of the chain is written to, inside the asset's: `lod<N>` in a chain,
/// else none.
pub fn chain_folder(settings: &Settings, level: u32) -> String {
    if is_chain(settings) {
        format!("lod{level}")
    } else {
        String::new()
    }
}

/// The folder slot `slot`'s files go to, inside the asset's: its level's
/// ([`chain_folder`]), or for a candidate `lod<N>/candidates/<name>`.
pub fn level_folder(settings: &Settings, slot: u32) -> String {
    match slots(settings).into_iter().nth(slot as usize) {
        Some(Slot { level, candidate: Some(name), .. }) => format!("lod{level}/candidates/{name}"),
        Some(Slot { level, .. }) => chain_folder(settings, level),
        None => chain_folder(settings, slot),
    }
}

/// The slot that bakes level `level` of the chain itself (none for an `Auto` level, whose
/// candidates each have one).
pub(crate) fn chain_slot(settings: &Settings, level: u32) -> Option<u32> {
    let slots = slots(settings);
    slots.iter().position(|slot| slot.level == level && slot.candidate.is_none()).map(|slot| slot as u32)
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

/// Texels a slot renders and encodes, estimated from its settings alone (`cirrus check`'s
/// measure of what a level costs): an impostor renders each frame at its supersampling (unless
/// its frames are reduced from another slot's) and encodes three atlases; a cloud renders its
/// atlas (about once over) and encodes four; a reduced level encodes its maps (three at most a
/// side of the level's largest).
pub(crate) fn estimated_texels(settings: &Settings, slot: u32) -> u64 {
    let level = settings_for(settings, slot);
    let side = |side: u32| u64::from(side).pow(2);
    if let Some(impostor) = level.impostor {
        let atlas = side(impostor.grid.frames * impostor.frame_size);
        let rendered = match impostor_render(settings, slot) {
            Some(render) if render.source != slot => 0,
            _ => {
                let samples = crate::impostor::frame_samples_per_axis(impostor.frame_size);
                u64::from(impostor.grid.frame_count()) * side(impostor.frame_size * samples)
            }
        };
        return rendered + 3 * atlas;
    }
    match level.reduced {
        Some(_) => 3 * side(level.max_atlas_size),
        None => cloud_texels(level.max_atlas_size),
    }
}

/// A cloud's [`estimated_texels`] with an atlas of `side` a side: rendered about once over, and
/// its four surfaces encoded.
fn cloud_texels(side: u32) -> u64 {
    5 * u64::from(side).pow(2)
}

/// A slot estimated to cost more than this many times the median of the others (and of a plain
/// cloud at the asset's `max_size`), and more than [`COSTLY_SLOT_TEXELS`], is warned about.
const COSTLY_SLOT_FACTOR: u64 = 16;
const COSTLY_SLOT_TEXELS: u64 = 64 << 20;

/// `cirrus check`'s warnings about slots whose estimated cost ([`estimated_texels`]) is far
/// above the others': each names the slot, its cost beside theirs, and what costs less.
pub(crate) fn costly_slot_warnings(settings: &Settings) -> Vec<String> {
    let count = slot_count(settings);
    let costs: Vec<u64> = (0..count).map(|slot| estimated_texels(settings, slot)).collect();
    let plain_cloud = cloud_texels(settings.own::<Own>().atlas.max_size);
    let all_slots = slots(settings);
    let mut warnings = Vec::new();
    for (slot, &cost) in costs.iter().enumerate() {
        let mut others: Vec<u64> =
            costs.iter().enumerate().filter(|(other, _)| *other != slot).map(|(_, &cost)| cost).collect();
        others.push(plain_cloud);
        others.sort_unstable();
        let median = others[others.len() / 2].max(1);
        if cost <= COSTLY_SLOT_TEXELS || cost <= COSTLY_SLOT_FACTOR * median {
            continue;
        }
        let described = all_slots
            .get(slot)
            .and_then(|slot| slot.bakes)
            .map_or_else(String::new, |bakes| format!(" `{}`", ron::to_string(&bakes).unwrap_or_default()));
        let level = all_slots.get(slot).map_or(0, |slot| slot.level);
        warnings.push(format!(
            "lod{level}{described}: renders and encodes about {} M texels, {}× the median of the other levels and \
             of a plain cloud ({} M): its bake takes minutes where theirs take seconds; fewer frames or a smaller \
             `size` bake sooner",
            cost >> 20,
            cost / median,
            median >> 20
        ));
    }
    warnings
}
