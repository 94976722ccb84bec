//! The per-asset settings a validated `pipeline.ron` resolves to: what each kind reads (billboard,
//! atlas, packing, AO, height, tessellation, encoding, report), with their defaults.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

pub use crate::packing::PageSettings;
pub use crate::texture::format::{BlockFormat, Container, EncodeQuality};

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

/// How an `Atlas` asset packs its textures onto pages.
#[derive(Clone, Debug, PartialEq, Eq, Hash, Serialize)]
pub struct PackSettings {
    pub max_size: u32,
    pub padding: u32,
    pub rotate: bool,
    pub trim: bool,
    pub power_of_two: bool,
    pub pages: u32,
}

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

/// The block formats a kind of surface may be encoded to (the first is the default).
pub(crate) fn allowed_formats(surface: crate::texture::SurfaceKind) -> &'static [BlockFormat] {
    use crate::texture::SurfaceKind;
    match surface {
        SurfaceKind::Albedo => &[BlockFormat::Bc7, BlockFormat::Bc3, BlockFormat::Bc1],
        SurfaceKind::Mra => &[BlockFormat::Bc1, BlockFormat::Bc7],
        SurfaceKind::Normal => &[BlockFormat::Bc5, BlockFormat::Bc7],
        SurfaceKind::Height | SurfaceKind::Ao => &[BlockFormat::Bc4],
    }
}

/// What a report says beyond the defaults.
#[derive(Clone, Debug, Default, PartialEq, Eq, Hash, Serialize)]
pub struct ReportSettings {
    /// Each surface also encoded (level 0) in the other formats it may take, with their PSNR and
    /// bits per texel, so that a format can be chosen with figures (costs an encode each).
    pub compare_formats: bool,
}

#[derive(Clone, Debug, PartialEq, Eq, Hash, Serialize)]
pub struct EncodeSettings {
    pub albedo: BlockFormat,
    pub mra: BlockFormat,
    pub normal: BlockFormat,
    pub height: BlockFormat,
    pub ao: BlockFormat,
    pub mips: bool,
    pub container: Container,
    /// zstd supercompression level for KTX2 (`None`: no supercompression).
    pub zstd: Option<i32>,
    pub quality: EncodeQuality,
}

impl EncodeSettings {
    /// The block format of one kind of surface.
    pub(crate) fn format_of(&self, surface: crate::texture::SurfaceKind) -> BlockFormat {
        match surface {
            crate::texture::SurfaceKind::Albedo => self.albedo,
            crate::texture::SurfaceKind::Mra => self.mra,
            crate::texture::SurfaceKind::Normal => self.normal,
            crate::texture::SurfaceKind::Height => self.height,
            crate::texture::SurfaceKind::Ao => self.ao,
        }
    }
}

/// Every setting of one asset, defaults and overrides merged.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Settings {
    pub billboard: BillboardSettings,
    pub atlas: PageSettings,
    pub pack: PackSettings,
    pub ao: AoSettings,
    pub encode: EncodeSettings,
    /// The `AmbientOcclusion` asset a `Material` takes its AO maps from (`ao_source`), by
    /// asset name: per asset, never a default.
    pub ao_source: Option<String>,
    pub height: HeightSettings,
    /// A `Height` asset's tessellated mesh (per asset, never a default; none: no tessellation).
    pub tessellate: Option<TessellateSettings>,
    /// The high mesh a `Height` asset measures (source-relative; per asset, never a default).
    pub high_mesh: Option<PathBuf>,
    pub report: ReportSettings,
}

impl Default for Settings {
    fn default() -> Settings {
        Settings {
            billboard: BillboardSettings {
                epsilon: 0.02,
                max_planes: None,
                budget: None,
                texel_density: None,
                screen_size: None,
                lods: Vec::new(),
                alpha_cutoff: 0.5,
            },
            atlas: PageSettings { max_size: 2048, padding: 4, power_of_two: true },
            pack: PackSettings { max_size: 4096, padding: 4, rotate: true, trim: true, power_of_two: false, pages: 4 },
            ao: AoSettings {
                size: 1024,
                rays: 256,
                mode: AoMode::Texels,
                distribution: crate::mesh::occlusion::RayDistribution::Cosine,
                max_distance: None,
                occluders: AoOccluders::SelfOnly,
                ignore_backfaces: true,
                ground_plane: false,
                padding: 16,
            },
            encode: EncodeSettings {
                albedo: BlockFormat::Bc7,
                mra: BlockFormat::Bc1,
                normal: BlockFormat::Bc5,
                height: BlockFormat::Bc4,
                ao: BlockFormat::Bc4,
                mips: true,
                container: Container::Ktx2,
                zstd: None,
                quality: EncodeQuality::Basic,
            },
            ao_source: None,
            height: HeightSettings { projection: HeightProjection::Normals, size: 1024, frontal: 0.02, rear: 0.02 },
            tessellate: None,
            high_mesh: None,
            report: ReportSettings::default(),
        }
    }
}
