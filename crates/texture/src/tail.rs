//! The texture tail every kind's surfaces end in: mip chain → block compression (reusing the
//! tiles and blocks an edit left alone) → PSNR from per-block errors → container → PNG preview.
//! Pure functions over plain data, in three steps so that a setting reaches only the step that
//! reads it; `PreviousEncoding` is what one run leaves for the next to reuse (results equal a
//! full run).

use std::sync::Arc;

use crate::color::has_transparency;
use crate::container::write_container;
use crate::encode::{encode_levels_stoppable, BlockEncodeSettings, EncodedTexture, HiddenBlocks, PreviousBlocks};
use crate::fingerprint::BlockFingerprints;
use crate::format::{BlockFormat, Container, EncodeQuality, Packing};
use crate::mips::{mip_chain_reusing, MipReuse, MipSettings, PreviousChain};
use crate::preview::preview_png;
use crate::quality::{alpha_test_threshold, block_errors_reusing, BlockErrors, Measure};
use crate::{SurfaceKind, Texture};
use base::stop::{ShouldStop, Stopped};

/// Everything the tail of one surface reads besides its image.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TailSettings {
    pub surface: SurfaceKind,
    pub format: BlockFormat,
    pub quality: EncodeQuality,
    pub mips: bool,
    /// The alpha-test cutoff applied when an albedo surface has transparency.
    pub alpha_cutoff: Option<f32>,
    pub container: Container,
    pub zstd: Option<i32>,
    /// The channel order a packed surface is encoded in (its image is made in `Mra`).
    pub packing: Packing,
}

/// The settings of the mip step alone (so that an encoder setting does not re-filter).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MipStepSettings {
    pub surface: SurfaceKind,
    pub mips: bool,
    pub alpha_cutoff: Option<f32>,
}

impl TailSettings {
    pub fn mip_step(&self) -> MipStepSettings {
        MipStepSettings { surface: self.surface, mips: self.mips, alpha_cutoff: self.alpha_cutoff }
    }
}

/// A surface's mip chain (level 0 first) and whether its alpha is tested.
#[derive(Clone, Debug)]
pub struct MipLevels {
    pub levels: Arc<Vec<Texture>>,
    pub alpha_tested: bool,
    /// The fingerprints of level 0's blocks (what the next bake compares instead of texels).
    pub level0_blocks: Arc<BlockFingerprints>,
    /// What the next chain of the same surface can reuse.
    pub reuse: Option<Arc<MipReuse>>,
}

impl PartialEq for MipLevels {
    fn eq(&self, other: &Self) -> bool {
        self.levels == other.levels && self.alpha_tested == other.alpha_tested
    }
}

/// A block-compressed surface with its per-block errors and PSNR (level 0 against the image).
#[derive(Clone, Debug)]
pub struct EncodedSurface {
    pub settings: BlockEncodeSettings,
    /// The hash of the hidden blocks it was encoded with (see [`HiddenBlocks`]).
    pub hidden: Option<blake3::Hash>,
    pub texture: EncodedTexture,
    pub block_errors: Arc<BlockErrors>,
    /// Rounded to 0.01 dB.
    pub psnr_db: f64,
}

impl PartialEq for EncodedSurface {
    fn eq(&self, other: &Self) -> bool {
        self.settings == other.settings
            && self.hidden == other.hidden
            && self.texture == other.texture
            && self.psnr_db == other.psnr_db
    }
}

/// What one surface is written as, with the figures its report needs.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SurfaceInfo {
    pub surface: SurfaceKind,
    pub format: BlockFormat,
    pub srgb: bool,
    pub container: Container,
    pub width: u32,
    pub height: u32,
    pub levels: u32,
    pub bytes: u64,
    /// What the format costs: bits per texel of each level (4 for BC1 and BC4, 8 for the others).
    pub bits_per_texel: u32,
    pub psnr_db: f64,
    pub alpha_tested: bool,
    /// Alpha-tested surfaces: the colour's PSNR over the texels the alpha test shows on the
    /// uncompressed surface (RGB, level 0), rounded to 0.01 dB: what an engine shows.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub visible_psnr_db: Option<f64>,
    /// Alpha-tested surfaces: where the test passes on the decoded level 0 against where it
    /// passes on the uncompressed one, as an intersection over union (rounded to 1e-5).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub alpha_test_iou: Option<f64>,
}

/// The files of one surface: the texture container and a PNG preview of the image; for a
/// packed metallic / roughness / AO surface also the PNG glTF reads (see [`orm_texture`]).
#[derive(Clone, Debug, PartialEq)]
pub struct SurfaceArtifacts {
    pub info: SurfaceInfo,
    pub texture_file: Arc<[u8]>,
    pub preview_png: Arc<[u8]>,
    pub orm_png: Option<Arc<[u8]>>,
}

/// A packed `mra` image (R metallic, G roughness, B occlusion) in the order glTF's materials
/// read (R occlusion, G roughness, B metallic), opaque.
pub fn orm_texture(mra: &Texture) -> Texture {
    let pixels = mra.pixels.chunks_exact(4).flat_map(|texel| [texel[2], texel[1], texel[0], 255]).collect();
    Texture::new(mra.width, mra.height, pixels)
}

/// An image with its red and blue channels swapped (`mra` ↔ `orm`), alpha kept.
pub fn swap_red_and_blue(image: &Texture) -> Texture {
    let pixels = image.pixels.chunks_exact(4).flat_map(|texel| [texel[2], texel[1], texel[0], texel[3]]).collect();
    Texture::new(image.width, image.height, pixels)
}

/// The last encoding of a surface, so that the next one filters again only the mip tiles and
/// encodes again only the blocks that changed. Level 0 is kept as block fingerprints only: it
/// is the largest level (16 of 28 MB on the oak's atlas), and a new process loads this.
#[derive(Clone, Debug)]
pub struct PreviousEncoding {
    pub level0_blocks: Arc<BlockFingerprints>,
    /// Levels 1 and below.
    pub lower_levels: Vec<Texture>,
    pub mip_reuse: Option<Arc<MipReuse>>,
    pub encoded: EncodedSurface,
}

impl PreviousEncoding {
    /// What a bake of `mips` encoded as `encoded` leaves for the next (sharing their buffers).
    pub fn of(mips: &MipLevels, encoded: &EncodedSurface) -> PreviousEncoding {
        PreviousEncoding {
            level0_blocks: mips.level0_blocks.clone(),
            lower_levels: mips.levels[1..].to_vec(),
            mip_reuse: mips.reuse.clone(),
            encoded: encoded.clone(),
        }
    }
}

/// The mip chain of `image`, reusing the previous chain's unchanged tiles.
pub fn tail_mips(image: &Texture, settings: MipStepSettings, previous: Option<&PreviousEncoding>) -> MipLevels {
    let alpha_tested = settings.surface == SurfaceKind::Albedo && has_transparency(image);
    let level0_blocks = Arc::new(BlockFingerprints::of(image));
    if !settings.mips {
        return MipLevels { levels: Arc::new(vec![image.clone()]), alpha_tested, level0_blocks, reuse: None };
    }
    let mip_settings =
        MipSettings { kind: settings.surface, alpha_cutoff: settings.alpha_cutoff.filter(|_| alpha_tested) };
    let previous = previous.and_then(|previous| {
        Some(PreviousChain {
            level0_blocks: &previous.level0_blocks,
            lower_levels: &previous.lower_levels,
            reuse: previous.mip_reuse.as_deref()?,
        })
    });
    let (levels, reuse) = mip_chain_reusing(image, &level0_blocks, mip_settings, previous);
    MipLevels { levels: Arc::new(levels), alpha_tested, level0_blocks, reuse: reuse.map(Arc::new) }
}

/// Block-compresses a mip chain, reusing the previous encoding's blocks where the texels are
/// unchanged, and measures level 0's error per block (again only where something changed); an
/// alpha-tested surface also what its alpha test at `alpha_cutoff` shows.
pub fn tail_encode(
    mips: &MipLevels,
    surface: SurfaceKind,
    (format, quality): (BlockFormat, EncodeQuality),
    (alpha_cutoff, hidden): (Option<f32>, Option<&HiddenBlocks>),
    (previous, stop): (Option<&PreviousEncoding>, ShouldStop),
) -> Result<EncodedSurface, Stopped> {
    let settings = BlockEncodeSettings { format, quality, alpha: mips.alpha_tested, srgb: surface.is_srgb() };
    let hidden_hash = hidden.map(|hidden| hidden.hash);
    let previous =
        previous.filter(|previous| previous.encoded.settings == settings && previous.encoded.hidden == hidden_hash);
    let texture = encode_levels_stoppable(
        &mips.levels,
        &mips.level0_blocks,
        (settings, hidden),
        previous.map(|previous| PreviousBlocks {
            level0_blocks: &previous.level0_blocks,
            lower_levels: &previous.lower_levels,
            encoded: &previous.encoded.texture,
        }),
        stop,
    )?;
    let image = &mips.levels[0];
    let block_errors = block_errors_reusing(
        format,
        &texture.levels[0],
        image,
        &mips.level0_blocks,
        Measure {
            channels: surface.channels(),
            alpha_threshold: alpha_cutoff.filter(|_| mips.alpha_tested).map(alpha_test_threshold),
        },
        previous.map(|previous| {
            (&*previous.level0_blocks, &previous.encoded.texture.levels[0][..], &*previous.encoded.block_errors)
        }),
    );
    let psnr_db = (block_errors.psnr(image.width, image.height) * 100.0).round() / 100.0;
    Ok(EncodedSurface { settings, hidden: hidden_hash, texture, block_errors: Arc::new(block_errors), psnr_db })
}

/// What a surface would measure in another format: its cost and level 0's PSNR.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct FormatFigure {
    pub format: BlockFormat,
    pub bits_per_texel: u32,
    pub psnr_db: f64,
}

/// Level 0 of a surface (`mips`) encoded in each of `formats` and decoded again: what each
/// would cost and give (`cirrus report: (compare_formats: true)`).
pub fn format_comparison(
    mips: &MipLevels,
    surface: SurfaceKind,
    formats: &[BlockFormat],
    quality: EncodeQuality,
) -> Vec<FormatFigure> {
    let image = &mips.levels[0];
    formats
        .iter()
        .map(|&format| {
            let settings = BlockEncodeSettings { format, quality, alpha: mips.alpha_tested, srgb: surface.is_srgb() };
            let encoded = crate::encode::encode_level(image, settings);
            let decoded = crate::quality::decode_blocks(format, &encoded, image.width, image.height);
            let psnr_db = crate::quality::psnr(image, &decoded, surface.channels());
            FormatFigure {
                format,
                bits_per_texel: crate::encode::bits_per_texel(format),
                psnr_db: (psnr_db * 100.0).round() / 100.0,
            }
        })
        .collect()
}

/// The container file and PNG preview of an encoded surface (and for a packed surface in `Mra`
/// order, glTF's `orm.png`).
pub fn tail_write(
    image: &Texture,
    (surface, packing): (SurfaceKind, Packing),
    encoded: &EncodedSurface,
    container: Container,
    zstd: Option<i32>,
) -> SurfaceArtifacts {
    let texture_file: Arc<[u8]> = write_container(&encoded.texture, container, zstd).into();
    let cut_out = encoded.block_errors.cut_out_quality();
    let info = SurfaceInfo {
        surface,
        format: encoded.texture.format,
        srgb: encoded.texture.srgb,
        container,
        width: encoded.texture.width,
        height: encoded.texture.height,
        levels: encoded.texture.levels.len() as u32,
        bytes: texture_file.len() as u64,
        bits_per_texel: crate::encode::bits_per_texel(encoded.texture.format),
        psnr_db: encoded.psnr_db,
        alpha_tested: encoded.settings.alpha,
        visible_psnr_db: cut_out.map(|quality| (quality.visible_psnr_db * 100.0).round() / 100.0),
        alpha_test_iou: cut_out.map(|quality| (quality.alpha_test_iou * 1e5).round() / 1e5),
    };
    // A surface packed in ORM order is glTF's image itself (its preview, `orm.png`).
    let orm_png =
        (surface == SurfaceKind::Mra && packing == Packing::Mra).then(|| preview_png(&orm_texture(image)).into());
    SurfaceArtifacts { info, texture_file, preview_png: preview_png(image).into(), orm_png }
}
