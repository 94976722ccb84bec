//! The per-asset settings a validated `pipeline.ron` resolves to: what each kind reads (billboard,
//! atlas, packing, AO, height, tessellation, encoding, report), with their defaults.

use std::path::PathBuf;

use serde::Serialize;

pub use crate::kinds::ambient_occlusion::settings::*;
pub use crate::kinds::atlas::settings::*;
pub use crate::kinds::billboard_cloud::settings::*;
pub use crate::kinds::height::settings::*;
pub use crate::kinds::material::settings::*;
pub use crate::packing::PageSettings;
pub use crate::texture::format::{BlockFormat, Container, EncodeQuality};

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
            billboard: BillboardSettings::default(),
            atlas: default_billboard_atlas(),
            pack: PackSettings::default(),
            ao: AoSettings::default(),
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
            height: HeightSettings::default(),
            tessellate: None,
            high_mesh: None,
            report: ReportSettings::default(),
        }
    }
}
