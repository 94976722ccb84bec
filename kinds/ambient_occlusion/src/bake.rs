//! The pure parts of an AO bake (DESIGN §3.3): each material's map cut into tiles, what a tile
//! reads (its own triangles, and with a finite `max_distance` only the occluders within reach
//! of them, hashed so that an edit elsewhere leaves the tile alone), a tile baked from rays or
//! from per-vertex values, and the map put together from its tiles and filled.

use glam::Vec3;

use crate::mesh::occlusion::{occlusion_of_texels, Casting, Occluders, OcclusionSettings};
use crate::mesh::rays::BackFaces;
use crate::mesh::uv_raster::{rasterize_uv, TexelRegion};
use crate::stop::{ShouldStop, Stopped};

/// Tiles are squares of this many texels (fewer at the map's right and bottom edges).
pub(crate) const TILE_SIZE: u32 = 128;

/// One tile of one material's map: the material's index in the mesh, the tile's column and row.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub(crate) struct TileId {
    pub material: u32,
    pub column: u32,
    pub row: u32,
}

impl TileId {
    /// The tile's texels in a `size`² map.
    pub fn region(self, size: u32) -> TexelRegion {
        let (x, y) = (self.column * TILE_SIZE, self.row * TILE_SIZE);
        TexelRegion { x, y, width: TILE_SIZE.min(size - x), height: TILE_SIZE.min(size - y) }
    }

    /// The tile's name inside its material: `tile_<column>_<row>`.
    pub fn name(self) -> String {
        format!("tile_{}_{}", self.column, self.row)
    }
}

/// The tiles of material `material`'s `size`² map, row by row.
pub(crate) fn material_tiles(material: u32, size: u32) -> Vec<TileId> {
    let count = size.div_ceil(TILE_SIZE);
    (0..count).flat_map(|row| (0..count).map(move |column| TileId { material, column, row })).collect()
}

/// The mesh data a bake reads, plain.
#[derive(Clone, Copy)]
pub struct BakeMesh<'a> {
    pub positions: &'a [[f32; 3]],
    pub normals: &'a [[f32; 3]],
    pub uvs: &'a [[f32; 2]],
    pub triangles: &'a [[u32; 3]],
    /// Each triangle's occluder group (its OBJ object when each object occludes only itself).
    pub groups: Option<&'a [u32]>,
}

/// Whether a triangle's UVs, in texel space of a `size`² map, reach into `region` (the same
/// test as the rasteriser's bounding box: a triangle that fails it covers none of the region).
fn uv_box_meets(mesh: &BakeMesh, triangle: u32, size: u32, region: TexelRegion) -> bool {
    let corners = mesh.triangles[triangle as usize].map(|vertex| mesh.uvs[vertex as usize]);
    if corners.iter().flatten().any(|c| !c.is_finite()) {
        return false;
    }
    let xs = corners.map(|uv| uv[0] as f64 * size as f64);
    let ys = corners.map(|uv| (1.0 - uv[1] as f64) * size as f64);
    let (min_x, max_x) =
        (xs.iter().copied().fold(f64::INFINITY, f64::min), xs.iter().copied().fold(f64::NEG_INFINITY, f64::max));
    let (min_y, max_y) =
        (ys.iter().copied().fold(f64::INFINITY, f64::min), ys.iter().copied().fold(f64::NEG_INFINITY, f64::max));
    max_x.ceil() > region.x as f64
        && min_x.floor() < (region.x + region.width) as f64
        && max_y.ceil() > region.y as f64
        && min_y.floor() < (region.y + region.height) as f64
}

/// The triangles of `material_triangles` (ascending) whose UVs reach into the tile: the only
/// ones the tile's rasterisation keeps, in the same order.
pub(crate) fn tile_triangles(mesh: &BakeMesh, material_triangles: &[u32], size: u32, region: TexelRegion) -> Vec<u32> {
    material_triangles.iter().copied().filter(|&triangle| uv_box_meets(mesh, triangle, size, region)).collect()
}

/// Each triangle's axis-aligned bounding box.
pub(crate) fn triangle_boxes(positions: &[[f32; 3]], triangles: &[[u32; 3]]) -> Vec<[Vec3; 2]> {
    triangles
        .iter()
        .map(|triangle| {
            let corners = triangle.map(|vertex| Vec3::from(positions[vertex as usize]));
            [corners[0].min(corners[1]).min(corners[2]), corners[0].max(corners[1]).max(corners[2])]
        })
        .collect()
}

/// The occluders a tile's rays can reach: every triangle (of the own triangles' groups, when
/// triangles occlude only their group) whose box meets the own triangles' box grown by `reach`
/// (with a margin for the rays' origin offsets), in ascending order.
pub(crate) fn occluders_within_reach(mesh: &BakeMesh, boxes: &[[Vec3; 2]], own: &[u32], reach: f32) -> Vec<u32> {
    let Some(&first) = own.first() else { return Vec::new() };
    let [mut low, mut high] = boxes[first as usize];
    for &triangle in own {
        low = low.min(boxes[triangle as usize][0]);
        high = high.max(boxes[triangle as usize][1]);
    }
    let scale = low.abs().max(high.abs()).max_element().max(1.0);
    let grow = reach * 1.0001 + scale * 1e-5;
    let (low, high) = (low - Vec3::splat(grow), high + Vec3::splat(grow));
    let own_groups: Vec<u32> = match mesh.groups {
        Some(groups) => {
            let mut own_groups: Vec<u32> = own.iter().map(|&triangle| groups[triangle as usize]).collect();
            own_groups.sort_unstable();
            own_groups.dedup();
            own_groups
        }
        None => Vec::new(),
    };
    (0..boxes.len() as u32)
        .filter(|&triangle| {
            let [box_low, box_high] = boxes[triangle as usize];
            let in_group =
                mesh.groups.is_none_or(|groups| own_groups.binary_search(&groups[triangle as usize]).is_ok());
            in_group && box_low.cmple(high).all() && box_high.cmpge(low).all()
        })
        .collect()
}

/// What a texel of a tile holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum TexelState {
    /// No triangle of the material touches it: filled from its neighbours.
    Empty = 0,
    Baked = 1,
    /// Inside geometry (most of its probe rays met back faces first): filled like `Empty`.
    Invalid = 2,
}

/// A baked tile: 16-bit visibility per texel (65535 = open sky) and each texel's state.
#[derive(Clone, Debug)]
pub struct TileBake {
    pub region: TexelRegion,
    pub values: Vec<u16>,
    pub states: Vec<u8>,
    /// Texels whose centre lies in two triangles that share no vertex.
    pub overlapping: u32,
    pub rays: u64,
    /// How long its bake took (not part of its equality).
    pub bake_ms: f64,
}

impl PartialEq for TileBake {
    fn eq(&self, other: &Self) -> bool {
        self.region == other.region
            && self.values == other.values
            && self.states == other.states
            && self.overlapping == other.overlapping
            && self.rays == other.rays
    }
}

impl TileBake {
    pub fn count(&self, state: TexelState) -> u32 {
        self.states.iter().filter(|&&texel| texel == state as u8).count() as u32
    }
}

/// A visibility in [0, 1] as 16 bits.
pub(crate) fn unorm16(visibility: f32) -> u16 {
    (visibility.clamp(0.0, 1.0) * 65535.0).round() as u16
}

/// Bakes a tile with rays: every covered texel's occlusion (see `occlusion_of_texels`), texels
/// inside geometry marked invalid when rays pass through back faces.
pub fn bake_tile_with_rays(
    occluders: &Occluders,
    mesh: &BakeMesh,
    own: &[u32],
    size: u32,
    region: TexelRegion,
    settings: &OcclusionSettings,
    should_stop: ShouldStop,
) -> Result<TileBake, Stopped> {
    let start = std::time::Instant::now();
    let coverage = rasterize_uv(mesh.uvs, mesh.triangles, own, (size, size), region);
    let occlusion = occlusion_of_texels(
        occluders,
        mesh.positions,
        mesh.normals,
        mesh.triangles,
        &coverage,
        size,
        Casting { settings, should_stop },
    )?;
    let mut values = vec![0u16; occlusion.len()];
    let mut states = vec![TexelState::Empty as u8; occlusion.len()];
    let mut rays = 0u64;
    for ((texel, value), state) in occlusion.iter().zip(&mut values).zip(&mut states) {
        let Some(texel) = texel else { continue };
        rays += settings.rays as u64;
        let inside = settings.back_faces == BackFaces::PassThrough && texel.back_face_rays * 2 > texel.probe_rays;
        *state = if inside { TexelState::Invalid } else { TexelState::Baked } as u8;
        if !inside {
            *value = unorm16(texel.visibility);
        }
    }
    Ok(TileBake {
        region,
        values,
        states,
        overlapping: coverage.overlapping,
        rays,
        bake_ms: start.elapsed().as_secs_f64() * 1000.0,
    })
}

/// Bakes a tile from per-vertex visibility (`None` where a vertex has none): each covered
/// texel interpolates its triangle's corners.
pub fn bake_tile_from_vertices(
    mesh: &BakeMesh,
    own: &[u32],
    size: u32,
    region: TexelRegion,
    vertex_visibility: &[f32],
) -> TileBake {
    let start = std::time::Instant::now();
    let coverage = rasterize_uv(mesh.uvs, mesh.triangles, own, (size, size), region);
    let mut values = vec![0u16; coverage.samples.len()];
    let mut states = vec![TexelState::Empty as u8; coverage.samples.len()];
    for ((sample, value), state) in coverage.samples.iter().zip(&mut values).zip(&mut states) {
        let Some(sample) = sample else { continue };
        let corners = mesh.triangles[sample.triangle as usize];
        let visibility: f32 = corners
            .iter()
            .zip(sample.barycentric)
            .map(|(&vertex, weight)| vertex_visibility[vertex as usize] * weight)
            .sum();
        *value = unorm16(visibility);
        *state = TexelState::Baked as u8;
    }
    TileBake {
        region,
        values,
        states,
        overlapping: coverage.overlapping,
        rays: 0,
        bake_ms: start.elapsed().as_secs_f64() * 1000.0,
    }
}

/// A material's finished map: 16-bit visibility with every texel filled, and its figures.
#[derive(Clone, Debug)]
pub(crate) struct AoMap {
    pub size: u32,
    pub values: Vec<u16>,
    /// Texels rays were cast from (those found inside geometry included).
    pub baked_texels: u64,
    pub invalid_texels: u64,
    pub overlapping_texels: u64,
    pub rays: u64,
    /// The tiles' bake times summed (not part of its equality).
    pub bake_ms: f64,
}

impl PartialEq for AoMap {
    fn eq(&self, other: &Self) -> bool {
        (self.size, &self.values, self.baked_texels, self.invalid_texels, self.overlapping_texels, self.rays)
            == (
                other.size,
                &other.values,
                other.baked_texels,
                other.invalid_texels,
                other.overlapping_texels,
                other.rays,
            )
    }
}

/// The map put together from its tiles, every texel that is not baked (empty, or inside
/// geometry) taking its nearest baked texel's value (`texture::fill`), so that no mip and no
/// bilinear tap reaches background; all open (65535) when nothing is baked.
pub(crate) fn assemble_map(size: u32, tiles: &[&TileBake]) -> AoMap {
    let mut values = vec![0u16; size as usize * size as usize];
    let mut fill_sources = Vec::new();
    let mut map = AoMap {
        size,
        values: Vec::new(),
        baked_texels: 0,
        invalid_texels: 0,
        overlapping_texels: 0,
        rays: 0,
        bake_ms: 0.0,
    };
    for tile in tiles {
        let region = tile.region;
        for row in 0..region.height {
            for column in 0..region.width {
                let from = (row * region.width + column) as usize;
                let to = (region.y + row) * size + region.x + column;
                values[to as usize] = tile.values[from];
                if tile.states[from] == TexelState::Baked as u8 {
                    fill_sources.push(to);
                }
            }
        }
        map.baked_texels += (tile.count(TexelState::Baked) + tile.count(TexelState::Invalid)) as u64;
        map.invalid_texels += tile.count(TexelState::Invalid) as u64;
        map.overlapping_texels += tile.overlapping as u64;
        map.rays += tile.rays;
        map.bake_ms += tile.bake_ms;
    }
    fill_sources.sort_unstable();
    let sources = crate::texture::fill::texel_sources(size, size, fill_sources);
    map.values = if sources.0.is_empty() {
        vec![u16::MAX; values.len()]
    } else {
        crate::texture::fill::fill_values(&values, &sources)
    };
    map
}

/// The map as an RGBA8 grey texture (for the texture tail: BC4 reads red).
pub(crate) fn map_texture(map: &AoMap) -> crate::texture::Texture {
    crate::texture::grey16_texture(map.size, map.size, &map.values)
}

/// The map as a 16-bit greyscale PNG.
pub(crate) fn map_png16(map: &AoMap) -> Vec<u8> {
    crate::texture::preview::png16_grey(&map.values, map.size, map.size)
}

/// Rays one core casts per second on a typical mesh, for the estimate of a bake's time (the
/// flight helmet: 5.4–7.7 M on AVX-512; a little less on AVX2 and on denser meshes).
pub(crate) const ESTIMATED_RAYS_PER_SECOND_PER_CORE: f64 = 4.0e6;

/// A bake estimated to take longer than this gets a warning with the estimate.
pub(crate) const LONG_BAKE_SECONDS: f64 = 300.0;

/// The rays a bake casts, estimated from the mesh: per material, the texels its UV triangles
/// cover (their area, at most the whole map) times `rays`; per vertex in `Vertices` mode.
pub(crate) fn estimated_rays(mesh: &crate::mesh::Mesh, settings: &super::settings::AoSettings) -> u64 {
    let Some(uvs) = &mesh.uvs else { return 0 };
    if settings.mode == super::settings::AoMode::Vertices {
        return mesh.positions.len() as u64 * u64::from(settings.rays);
    }
    let mut areas = vec![0.0f64; mesh.materials.len()];
    for (triangle, &material) in mesh.triangles.iter().zip(&mesh.triangle_materials) {
        let [a, b, c] = triangle.map(|vertex| uvs[vertex as usize].map(f64::from));
        let area = ((b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1])).abs() / 2.0;
        if let Some(sum) = areas.get_mut(material as usize) {
            *sum += if area.is_finite() { area } else { 0.0 };
        }
    }
    let texels = areas.iter().map(|area| area.min(1.0) * f64::from(settings.size).powi(2)).sum::<f64>();
    (texels * f64::from(settings.rays)) as u64
}

/// A warning when the bake is estimated to take longer than [`LONG_BAKE_SECONDS`] on `cores`
/// cores, with the estimate and what makes it shorter.
pub(crate) fn long_bake_warning(
    file: &std::path::Path,
    mesh: &crate::mesh::Mesh,
    settings: &super::settings::AoSettings,
    cores: usize,
) -> Option<crate::diagnostic::Diagnostic> {
    let rays = estimated_rays(mesh, settings);
    let seconds = rays as f64 / (ESTIMATED_RAYS_PER_SECOND_PER_CORE * cores.max(1) as f64);
    (seconds > LONG_BAKE_SECONDS).then(|| {
        crate::diagnostic::Diagnostic::new(
            file,
            format!(
                "about {:.1} G rays at `rays: {}`: the bake takes about {} on {cores} cores; fewer rays (256 is \
                    plenty for most maps) or a smaller `size` bake sooner",
                rays as f64 / 1e9,
                settings.rays,
                crate::summary::rough_duration(seconds)
            ),
        )
    })
}
