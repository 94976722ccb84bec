//! The `encode` section every kind's entry and `defaults:` may carry: as written (overrides), as
//! it resolves (settings), the formats each surface may take, and its checks. A leaf.

use serde::Deserialize;

use super::sections::{explicit, Check};
pub use crate::packing::PageSettings;
pub use crate::texture::format::{BlockFormat, Container, EncodeQuality};

/// The block formats a kind of surface may be encoded to (the first is the default).
pub fn allowed_formats(surface: crate::texture::SurfaceKind) -> &'static [BlockFormat] {
    use crate::texture::SurfaceKind;
    match surface {
        SurfaceKind::Albedo => &[BlockFormat::Bc7, BlockFormat::Bc3, BlockFormat::Bc1],
        SurfaceKind::Mra => &[BlockFormat::Bc1, BlockFormat::Bc7],
        SurfaceKind::Normal => &[BlockFormat::Bc5, BlockFormat::Bc7],
        SurfaceKind::Height | SurfaceKind::Ao => &[BlockFormat::Bc4],
    }
}

#[derive(Clone, Debug, PartialEq, Eq, Hash)]
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
    /// The packed surface's channel order (`mra.*` or `orm.*`); glTF gets ORM either way.
    pub packing: crate::texture::format::Packing,
}

impl EncodeSettings {
    /// The block format of one kind of surface.
    pub fn format_of(&self, surface: crate::texture::SurfaceKind) -> BlockFormat {
        match surface {
            crate::texture::SurfaceKind::Albedo => self.albedo,
            crate::texture::SurfaceKind::Mra => self.mra,
            crate::texture::SurfaceKind::Normal => self.normal,
            crate::texture::SurfaceKind::Height => self.height,
            crate::texture::SurfaceKind::Ao => self.ao,
        }
    }
}

impl Default for EncodeSettings {
    fn default() -> EncodeSettings {
        EncodeSettings {
            albedo: BlockFormat::Bc7,
            mra: BlockFormat::Bc1,
            normal: BlockFormat::Bc5,
            height: BlockFormat::Bc4,
            ao: BlockFormat::Bc4,
            mips: true,
            container: Container::Ktx2,
            zstd: None,
            quality: EncodeQuality::Basic,
            packing: crate::texture::format::Packing::Mra,
        }
    }
}

/// The `encode` section as `pipeline.ron` writes it, under `defaults:` and in every entry.
#[derive(Deserialize, Default, Clone)]
#[serde(deny_unknown_fields)]
pub struct EncodeOverrides {
    pub albedo: Option<BlockFormat>,
    pub mra: Option<BlockFormat>,
    pub normal: Option<BlockFormat>,
    pub height: Option<BlockFormat>,
    pub ao: Option<BlockFormat>,
    pub mips: Option<bool>,
    pub container: Option<Container>,
    #[serde(default, deserialize_with = "explicit")]
    pub zstd: Option<Option<i32>>,
    pub quality: Option<EncodeQuality>,
    pub packing: Option<crate::texture::format::Packing>,
}

/// `encode` merged over `settings`, checked.
pub fn merge_encode(check: &mut dyn Check, settings: &mut EncodeSettings, encode: &EncodeOverrides, at: usize) {
    use crate::texture::SurfaceKind;
    let surfaces: [(&str, Option<BlockFormat>, &[BlockFormat], &mut BlockFormat); 5] = [
        ("albedo", encode.albedo, allowed_formats(SurfaceKind::Albedo), &mut settings.albedo),
        ("mra", encode.mra, allowed_formats(SurfaceKind::Mra), &mut settings.mra),
        ("normal", encode.normal, allowed_formats(SurfaceKind::Normal), &mut settings.normal),
        ("height", encode.height, allowed_formats(SurfaceKind::Height), &mut settings.height),
        ("ao", encode.ao, allowed_formats(SurfaceKind::Ao), &mut settings.ao),
    ];
    let mut format_errors = Vec::new();
    for (key, value, allowed, target) in surfaces {
        if let Some(format) = value {
            if !allowed.contains(&format) {
                format_errors.push((key, format!("{format:?} cannot hold the {key} surface; use one of {allowed:?}")));
            }
            *target = format;
        }
    }
    for (key, message) in format_errors {
        check.error_at_key(key, at, &message);
    }
    if let Some(mips) = encode.mips {
        settings.mips = mips;
    }
    if let Some(container) = encode.container {
        settings.container = container;
    }
    if let Some(zstd) = encode.zstd {
        if zstd.is_some_and(|level| !(1..=22).contains(&level)) {
            check.error_at_key("zstd", at, "zstd level must be between 1 and 22");
        }
        settings.zstd = zstd;
    }
    if let Some(quality) = encode.quality {
        settings.quality = quality;
    }
    if let Some(packing) = encode.packing {
        settings.packing = packing;
    }
}
