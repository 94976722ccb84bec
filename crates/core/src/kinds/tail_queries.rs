//! The tracked functions of the shared texture tail (thin glue over `texture::tail`): every
//! kind's surfaces run through them, keyed by asset and `SurfaceId` (salsa interns the pair).
//! The persistent cache is asked up to three times: by the surface's recipe (its kind's cheap key
//! of what the image is made of, so a restart needs no image), then by its parts when the kind
//! has them (what the image is put together from, so an edit that leaves them alone composites
//! nothing), then by the image's content (so an edit that leaves a surface's texels alone
//! encodes nothing).

use std::sync::Arc;

use crate::cache::{CacheEntry, CacheKey, CacheKeyBuilder};
use crate::db::{
    forget, load_cached, recall, record_cache_hit, remember, store_cached, store_cached_in_background, timed, Asset,
    Db, Retention, Stage,
};
use crate::diagnostic::Diagnostic;
use crate::kinds::surface::{SurfaceId, SurfacePlan};
use crate::texture::encode::HiddenBlocks;
use crate::texture::fingerprint::BlockFingerprints;
use crate::texture::format::Packing;
use crate::texture::tail::{
    tail_encode, tail_mips, tail_write, EncodedSurface, MipLevels, MipStepSettings, PreviousEncoding, SurfaceArtifacts,
    TailSettings,
};
use crate::texture::{SurfaceKind, Texture};

// Versions: mips 2: coverage-preserving mips for albedo and opacity sources; 3: transparent
// texels of albedo mips keep their footprint's colour; 4: no coverage scaling when all or none
// of level 0 passes the cutoff. Encode 3: fully transparent BC7 blocks use the fastest profile;
// 4, 5: as mips 3, 4; 6: BC4 and BC5 by cirrus's own search (`texture::bc4`); 7: BC1 blocks
// refined (`texture::bc1`); 8: the cut-out edges of alpha-tested BC7 at the very fast profile.
pub const MIPS: Stage = Stage { name: "mips", version: 4 };
pub const ENCODE: Stage = Stage { name: "encode", version: 9 };
pub const WRITE: Stage = Stage { name: "write", version: 2 };

/// The cache entry of a finished surface (under its recipe key and under its content key).
const SURFACE_ENTRY: &str = "surface";
// 4: the surface's figures include bits per texel; 5: and an alpha-tested one's visible PSNR
// and alpha-test IoU.
const SURFACE_ENTRY_VERSION: u32 = 6;
/// The entry under a surface's recipe key: the content key of its files.
const SURFACE_RECIPE_ENTRY: &str = "surface-recipe";

/// Bounds what the tail's memos hold (images, mips, blocks, finished files) to the `surfaces`
/// surfaces used last (salsa's LRU, applied at each new revision and by
/// `trigger_lru_eviction`): an evicted memo keeps its dependencies, and its surface is made
/// again (the persistent cache gives back its files) only when asked for. 0: unbounded.
pub fn keep_memos(db: &mut dyn Db, surfaces: usize) {
    surface_image::set_lru_capacity(db, surfaces);
    tail_image::set_lru_capacity(db, surfaces);
    hidden_blocks::set_lru_capacity(db, surfaces);
    surface_mips::set_lru_capacity(db, surfaces);
    surface_blocks::set_lru_capacity(db, surfaces);
    surface_format_comparison::set_lru_capacity(db, surfaces);
    surface_files::set_lru_capacity(db, surfaces);
    surface_artifacts::set_lru_capacity(db, surfaces);
}

/// The kind's plan of a surface: the tail's one question to the kind about it.
#[salsa::tracked(returns(clone))]
pub fn surface_plan(db: &dyn Db, asset: Asset, surface: SurfaceId) -> Result<SurfacePlan, Diagnostic> {
    asset.kind(db).surface_plan(db, asset, &surface)
}

#[salsa::tracked(returns(clone))]
pub fn tail_settings(db: &dyn Db, asset: Asset, surface: SurfaceId) -> Result<TailSettings, Diagnostic> {
    surface_plan(db, asset, surface).map(|plan| plan.settings)
}

#[salsa::tracked(returns(clone))]
fn mip_step_settings(db: &dyn Db, asset: Asset, surface: SurfaceId) -> Result<MipStepSettings, Diagnostic> {
    tail_settings(db, asset, surface).map(|settings| settings.mip_step())
}

#[salsa::tracked(returns(clone))]
fn encode_step_settings(
    db: &dyn Db,
    asset: Asset,
    surface: SurfaceId,
) -> Result<(crate::config::BlockFormat, crate::config::EncodeQuality, Option<f32>), Diagnostic> {
    tail_settings(db, asset, surface).map(|settings| (settings.format, settings.quality, settings.alpha_cutoff))
}

#[salsa::tracked(returns(clone))]
fn write_step_settings(
    db: &dyn Db,
    asset: Asset,
    surface: SurfaceId,
) -> Result<(crate::config::Container, Option<i32>), Diagnostic> {
    tail_settings(db, asset, surface).map(|settings| (settings.container, settings.zstd))
}

/// The surface's image, made by its kind.
#[salsa::tracked(returns(clone), lru = 0)]
pub fn surface_image(db: &dyn Db, asset: Asset, surface: SurfaceId) -> Result<Arc<Texture>, Diagnostic> {
    (surface_plan(db, asset, surface.clone())?.image)(db, asset, &surface)
}

/// The image the tail filters and encodes: the kind's, in the channel order of the asset's
/// `packing` (kinds make packed surfaces in `Mra`).
#[salsa::tracked(returns(clone), lru = 0)]
fn tail_image(db: &dyn Db, asset: Asset, surface: SurfaceId) -> Result<Arc<Texture>, Diagnostic> {
    let image = surface_image(db, asset, surface.clone())?;
    in_tail_order(db, asset, &surface, image)
}

fn in_tail_order(
    db: &dyn Db,
    asset: Asset,
    surface: &SurfaceId,
    image: Arc<Texture>,
) -> Result<Arc<Texture>, Diagnostic> {
    let packing = tail_settings(db, asset, surface.clone())?.packing;
    Ok(match (surface.surface, packing) {
        (SurfaceKind::Mra, Packing::Orm) => Arc::new(crate::texture::tail::swap_red_and_blue(&image)),
        _ => image,
    })
}

/// The tail's image of a surface for its files: memoized where the process builds again, else
/// made by the kind for this use and dropped with it (see [`Retention`]).
fn files_image(db: &dyn Db, asset: Asset, surface: &SurfaceId) -> Result<Arc<Texture>, Diagnostic> {
    match db.retention(asset) {
        Retention::KeepForNextBuild => tail_image(db, asset, surface.clone()),
        Retention::OutputsOnly => {
            let image = (surface_plan(db, asset, surface.clone())?.image)(db, asset, surface)?;
            in_tail_order(db, asset, surface, image)
        }
    }
}

/// The blocks of the surface that its asset's alpha test hides (see [`HiddenBlocks`]): from the
/// alpha of the albedo that cuts it out, when that albedo is alpha-tested. Equal masks compare
/// equal, so an edit of the albedo's colours alone re-encodes nothing here.
#[salsa::tracked(returns(clone), lru = 0)]
fn hidden_blocks(db: &dyn Db, asset: Asset, surface: SurfaceId) -> Result<Option<Arc<HiddenBlocks>>, Diagnostic> {
    hidden_blocks_of(db, asset, &surface, &*tail_image(db, asset, surface.clone())?)
}

/// The hidden blocks of `surface`, whose image is `image`.
fn hidden_blocks_of(
    db: &dyn Db,
    asset: Asset,
    surface: &SurfaceId,
    image: &Texture,
) -> Result<Option<Arc<HiddenBlocks>>, Diagnostic> {
    let Some(albedo) = surface_plan(db, asset, surface.clone())?.cutting else { return Ok(None) };
    if tail_settings(db, asset, albedo.clone())?.alpha_cutoff.is_none() {
        return Ok(None);
    }
    let sizes = match mip_step_settings(db, asset, surface.clone())?.mips {
        true => crate::texture::mips::chain_sizes(image.width, image.height),
        false => vec![(image.width, image.height)],
    };
    let hidden = match albedo == *surface {
        true => HiddenBlocks::of_alpha(image, &sizes),
        false => HiddenBlocks::of_alpha(&*files_image(db, asset, &albedo)?, &sizes),
    };
    Ok(hidden.map(Arc::new))
}

/// The cache key part that names a surface's hidden blocks (empty when it has none).
fn hidden_key(hidden: Option<&HiddenBlocks>) -> String {
    hidden.map_or_else(String::new, |hidden| hidden.hash.to_hex().to_string())
}

/// A `width` × `height` texture's working set reserved from the process's texture memory budget
/// (held over pure work only: no query may run while it is held).
fn texture_memory(db: &dyn Db, width: u32, height: u32) -> crate::schedule::MemoryReservation<'static> {
    let bytes = crate::texture::TextureLimits::working_set_of(width, height);
    crate::schedule::TEXTURE_MEMORY.reserve(bytes, crate::db::texture_limits(db).working_set)
}

/// The mip chain (stage `mips`), re-filtering only the tiles that changed since the last run.
#[salsa::tracked(returns(clone), lru = 0)]
pub fn surface_mips(db: &dyn Db, asset: Asset, surface: SurfaceId) -> Result<Arc<MipLevels>, Diagnostic> {
    make_mips(db, asset, &surface, &*tail_image(db, asset, surface.clone())?).map(Arc::new)
}

fn make_mips(db: &dyn Db, asset: Asset, surface: &SurfaceId, image: &Texture) -> Result<MipLevels, Diagnostic> {
    let settings = mip_step_settings(db, asset, surface.clone())?;
    let label = surface.label(asset.name(db));
    let previous = previous_encoding(db, &label);
    let _memory = texture_memory(db, image.width, image.height);
    Ok(timed(db, MIPS, &label, || tail_mips(image, settings, previous.as_deref())))
}

/// The blocks and their PSNR (stage `encode`), re-encoding only the blocks that changed.
#[salsa::tracked(returns(clone), lru = 0)]
pub fn surface_blocks(db: &dyn Db, asset: Asset, surface: SurfaceId) -> Result<Arc<EncodedSurface>, Diagnostic> {
    let mips = surface_mips(db, asset, surface.clone())?;
    let hidden = hidden_blocks(db, asset, surface.clone())?;
    make_blocks(db, asset, &surface, &mips, hidden.as_deref()).map(Arc::new)
}

fn make_blocks(
    db: &dyn Db,
    asset: Asset,
    surface: &SurfaceId,
    mips: &MipLevels,
    hidden: Option<&HiddenBlocks>,
) -> Result<EncodedSurface, Diagnostic> {
    let (format, quality, alpha_cutoff) = encode_step_settings(db, asset, surface.clone())?;
    let label = surface.label(asset.name(db));
    let previous = previous_encoding(db, &label);
    let memory = texture_memory(db, mips.levels[0].width, mips.levels[0].height);
    // Cancellable between tasks of blocks: an 8192² atlas takes seconds to encode.
    let encoded = timed(db, ENCODE, &label, || {
        crate::db::stoppable(db, |should_stop| {
            let encoding = (previous.as_deref(), should_stop);
            tail_encode(mips, surface.surface, (format, quality), (alpha_cutoff, hidden), encoding)
        })
    });
    drop(memory);
    let remembered = Arc::new(PreviousEncoding::of(mips, &encoded));
    if memo_worth_storing(format) {
        let memo = remembered.clone();
        store_cached_in_background(db, ENCODING_MEMO, encoding_memo_key(&label), move || encoding_entry(&memo));
    }
    match db.retention(asset) {
        Retention::KeepForNextBuild => remember(db, &encoding_memo_name(&label), remembered),
        Retention::OutputsOnly => forget(db, &encoding_memo_name(&label)),
    }
    Ok(encoded)
}

/// The surface in the other formats its kind allows, when the asset's report asks
/// (`report: (compare_formats: true)`): level 0 encoded and measured again in each (not a
/// stage of the build: only the report reads it).
#[salsa::tracked(returns(clone), lru = 0)]
pub fn surface_format_comparison(
    db: &dyn Db,
    asset: Asset,
    surface: SurfaceId,
) -> Result<Arc<Vec<crate::texture::tail::FormatFigure>>, Diagnostic> {
    let (format, quality, _) = encode_step_settings(db, asset, surface.clone())?;
    let others: Vec<crate::config::BlockFormat> =
        crate::config::allowed_formats(surface.surface).iter().copied().filter(|&other| other != format).collect();
    if others.is_empty() {
        return Ok(Arc::default());
    }
    let mips = surface_mips(db, asset, surface.clone())?;
    Ok(Arc::new(crate::texture::tail::format_comparison(&mips, surface.surface, &others, quality)))
}

/// The container and preview (stage `write`), with the content key they are cached under; from
/// the persistent cache when a surface with the same texels and settings was baked before. Where
/// the process builds again, the image, mips and blocks are memoized; else they are made here
/// and dropped with the files (see [`Retention`]).
#[salsa::tracked(returns(clone), lru = 0)]
pub fn surface_files(
    db: &dyn Db,
    asset: Asset,
    surface: SurfaceId,
) -> Result<(Arc<SurfaceArtifacts>, CacheKey), Diagnostic> {
    let settings = tail_settings(db, asset, surface.clone())?;
    let label = surface.label(asset.name(db));
    let keeping = db.retention(asset) == Retention::KeepForNextBuild;
    let image = files_image(db, asset, &surface)?;
    let hidden = match keeping {
        true => hidden_blocks(db, asset, surface.clone())?,
        false => hidden_blocks_of(db, asset, &surface, &image)?,
    };
    let content_key = content_key(&settings, &image, &hidden_key(hidden.as_deref()));
    if let Some(artifacts) = load_cached(db, SURFACE_ENTRY, content_key, artifacts_from_entry) {
        record_cache_hit(db, WRITE, &label);
        return Ok((Arc::new(artifacts), content_key));
    }
    let encoded = match keeping {
        true => surface_blocks(db, asset, surface.clone())?,
        false => {
            let mips = make_mips(db, asset, &surface, &image)?;
            Arc::new(make_blocks(db, asset, &surface, &mips, hidden.as_deref())?)
        }
    };
    let (container, zstd) = write_step_settings(db, asset, surface.clone())?;
    let packing = settings.packing;
    let artifacts =
        timed(db, WRITE, &label, || tail_write(&image, (surface.surface, packing), &encoded, container, zstd));
    store_cached(db, SURFACE_ENTRY, content_key, || artifacts_entry(&artifacts));
    Ok((Arc::new(artifacts), content_key))
}

/// A surface's finished files: from the persistent cache by its recipe when the kind can name
/// one (then no image is made), else by its parts (then the image is not put together), else
/// through the tail.
#[salsa::tracked(returns(clone), lru = 0)]
pub fn surface_artifacts(db: &dyn Db, asset: Asset, surface: SurfaceId) -> Result<Arc<SurfaceArtifacts>, Diagnostic> {
    let plan = surface_plan(db, asset, surface.clone())?;
    let settings = &plan.settings;
    let recipe_key = recipe_key(db, asset, &surface, settings)?;
    if let Some(artifacts) = recipe_key.and_then(|key| artifacts_by_recipe(db, key)) {
        record_cache_hit(db, WRITE, &surface.label(asset.name(db)));
        return Ok(Arc::new(artifacts));
    }
    let parts_key = (plan.parts)(db, asset, &surface)?.map(|parts| surface_key(settings).part(&parts.0).finish());
    let from_parts =
        parts_key.and_then(|key| artifacts_by_recipe(db, key).map(|artifacts| (Arc::new(artifacts), None)));
    let (artifacts, content) = match from_parts {
        Some(found) => {
            record_cache_hit(db, WRITE, &surface.label(asset.name(db)));
            found
        }
        None => {
            let (artifacts, content) = surface_files(db, asset, surface.clone())?;
            (artifacts, Some(content))
        }
    };
    // Both keys name the content entry from now on (found by parts: the content key is the
    // one the parts' entry names).
    let content = match content {
        Some(content) => content,
        None => match parts_key.and_then(|key| recipe_target(db, key)) {
            Some(content) => content,
            None => return Ok(artifacts),
        },
    };
    for key in [recipe_key, parts_key].into_iter().flatten() {
        store_cached(db, SURFACE_RECIPE_ENTRY, key, || {
            CacheEntry::new(&content.0.to_hex().to_string(), Vec::new(), false)
        });
    }
    Ok(artifacts)
}

/// The content key a recipe (or parts) entry names.
fn recipe_target(db: &dyn Db, key: CacheKey) -> Option<CacheKey> {
    load_cached(db, SURFACE_RECIPE_ENTRY, key, |entry| {
        let (content, []) = entry.parts::<String, 0>()?;
        Some(CacheKey(blake3::Hash::from_hex(content).ok()?))
    })
}

/// The files a recipe (or parts) entry leads to.
fn artifacts_by_recipe(db: &dyn Db, key: CacheKey) -> Option<SurfaceArtifacts> {
    recipe_target(db, key).and_then(|content| load_cached(db, SURFACE_ENTRY, content, artifacts_from_entry))
}

/// Whether the persistent cache holds the surface's files under its recipe (a kind can then
/// skip making the image).
pub fn surface_in_cache(db: &dyn Db, asset: Asset, surface: &SurfaceId) -> bool {
    let (Some(cache), Ok(settings)) = (db.disk_cache(), tail_settings(db, asset, surface.clone())) else {
        return false;
    };
    match recipe_key(db, asset, surface, &settings) {
        Ok(Some(key)) => cache.contains(SURFACE_RECIPE_ENTRY, key),
        _ => false,
    }
}

/// The key of a surface's entry by its kind's recipe (none when the kind names none).
fn recipe_key(
    db: &dyn Db,
    asset: Asset,
    surface: &SurfaceId,
    settings: &TailSettings,
) -> Result<Option<CacheKey>, Diagnostic> {
    let recipe = (surface_plan(db, asset, surface.clone())?.recipe)(db, asset, surface)?;
    Ok(recipe.map(|recipe| surface_key(settings).part(&recipe.0).finish()))
}

/// The key of a surface's files by the texels of its image (and the blocks its asset's alpha
/// test hides, `hidden`: see [`hidden_key`]).
fn content_key(settings: &TailSettings, image: &Texture, hidden: &str) -> CacheKey {
    let key = surface_key(settings).part(&image.width).part(&image.height).part(&image.hash);
    match hidden {
        // Surfaces without hidden blocks keep the keys they had before hiding.
        "" => key.finish(),
        hidden => key.part(hidden).finish(),
    }
}

/// The start of both keys of a surface entry: the tail's versions and every tail setting.
fn surface_key(settings: &TailSettings) -> CacheKeyBuilder {
    let key = CacheKeyBuilder::new(SURFACE_ENTRY, SURFACE_ENTRY_VERSION)
        .part(&[MIPS.version, ENCODE.version, WRITE.version])
        .part(&settings.surface)
        .part(&settings.format)
        .part(crate::texture::encode::encoder_family(settings.format))
        .part(&settings.quality)
        .part(&settings.mips)
        .part(&settings.alpha_cutoff)
        .part(&settings.container)
        .part(&settings.zstd);
    // Keys of packed surfaces in the first order stay what they were before the setting.
    match (settings.surface, settings.packing) {
        (SurfaceKind::Mra, Packing::Orm) => key.part(&settings.packing),
        _ => key,
    }
}

/// Parts: the container, the preview, and the glTF image (empty when the surface has none).
fn artifacts_entry(artifacts: &SurfaceArtifacts) -> CacheEntry {
    let orm_png = artifacts.orm_png.as_deref().map_or_else(Vec::new, <[u8]>::to_vec);
    CacheEntry::new(
        &artifacts.info,
        vec![artifacts.texture_file.to_vec(), artifacts.preview_png.to_vec(), orm_png],
        false,
    )
}

fn artifacts_from_entry(entry: CacheEntry) -> Option<SurfaceArtifacts> {
    let (info, [texture_file, preview_png, orm_png]): (crate::texture::tail::SurfaceInfo, _) = entry.parts()?;
    // Empty for a surface written in ORM order already (its preview is the glTF's image).
    let orm_png = (info.surface == SurfaceKind::Mra && !orm_png.is_empty()).then(|| orm_png.into());
    Some(SurfaceArtifacts { info, texture_file: texture_file.into(), preview_png: preview_png.into(), orm_png })
}

/// The memo of a surface's last encoding on disk: not a content address but the surface's
/// identity (asset, surface, tail settings), overwritten by every encode, so that a new process
/// re-encodes only the blocks an edit changed. Results equal a full encode either way.
const ENCODING_MEMO: &str = "encoding-memo";
/// 4: level 0 as block fingerprints; 5: with the alpha test's figures per block; 6: with the
/// hidden blocks' hash.
const ENCODING_MEMO_VERSION: u32 = 6;

/// Whether a surface's last encoding is kept on disk: for BC7 only, whose encoder is the slow
/// one (on the oak's 2048² albedo, re-encoding from scratch after a restart costs about 0.9 s;
/// the memo, 16 MB, is written in the background). The other formats
/// encode a whole atlas in about 0.1 s, less than writing and reading their memo would cost.
fn memo_worth_storing(format: crate::config::BlockFormat) -> bool {
    format == crate::config::BlockFormat::Bc7
}

/// By the surface's label (and the kernels' output family) alone: settings are not part of the
/// key (reading them would make the mips depend on encoder settings); the steps reuse only what
/// was made with their settings.
fn encoding_memo_key(label: &str) -> CacheKey {
    CacheKeyBuilder::new(ENCODING_MEMO, ENCODING_MEMO_VERSION)
        .part(&[MIPS.version, ENCODE.version])
        .part(crate::texture::ispc::output_family())
        .part(label)
        .finish()
}

/// Loads the surface's last encoding into this process ahead of its tail (no-op when it is
/// here already or the memo holds none).
pub fn load_previous_encoding(db: &dyn Db, asset: Asset, surface: &SurfaceId) {
    previous_encoding(db, &surface.label(asset.name(db)));
}

/// The surface's last encoding: from this process, else from the memo on disk.
fn previous_encoding(db: &dyn Db, label: &str) -> Option<Arc<PreviousEncoding>> {
    if let Some(previous) = recall(db, &encoding_memo_name(label)) {
        return Some(previous);
    }
    let previous = Arc::new(load_cached(db, ENCODING_MEMO, encoding_memo_key(label), encoding_from_entry)?);
    remember(db, &encoding_memo_name(label), previous.clone());
    Some(previous)
}

/// The in-process memo's name for a surface's last encoding.
fn encoding_memo_name(label: &str) -> crate::db::Memo<PreviousEncoding> {
    crate::db::Memo::new(ENCODING_MEMO, label)
}

/// What an encoding memo holds beside its blocks, levels and errors.
#[derive(serde::Serialize, serde::Deserialize)]
struct EncodingEntry {
    /// The lower mip levels' sizes (level 0's is `width` × `height`).
    levels: Vec<(u32, u32)>,
    reuse: Option<crate::texture::mips::MipReuse>,
    settings: crate::texture::encode::BlockEncodeSettings,
    width: u32,
    height: u32,
    psnr_db: f64,
    channels: usize,
    alpha_threshold: Option<u8>,
    /// The hidden blocks' hash (hex), when it was encoded with some.
    hidden: Option<String>,
}

fn encoding_entry(previous: &PreviousEncoding) -> CacheEntry {
    let (blocks, encoded) = (&previous.level0_blocks, &previous.encoded);
    let metadata = EncodingEntry {
        levels: previous.lower_levels.iter().map(|level| (level.width, level.height)).collect(),
        reuse: previous.mip_reuse.as_deref().cloned(),
        settings: encoded.settings,
        width: encoded.texture.width,
        height: encoded.texture.height,
        psnr_db: encoded.psnr_db,
        channels: encoded.block_errors.channels,
        alpha_threshold: encoded.block_errors.cut_out.as_ref().map(|(threshold, _)| *threshold),
        hidden: encoded.hidden.map(|hash| hash.to_hex().to_string()),
    };
    let mut blobs = vec![crate::db::pod_blob(&blocks.texels), crate::db::pod_blob(&blocks.alphas)];
    blobs.extend(previous.lower_levels.iter().map(|level| level.pixels.to_vec()));
    blobs.extend(encoded.texture.levels.iter().map(|level| level.to_vec()));
    blobs.push(crate::db::pod_blob(&encoded.block_errors.errors));
    blobs.push(crate::db::pod_blob(encoded.block_errors.cut_out.as_ref().map_or(&[][..], |(_, blocks)| blocks)));
    // Uncompressed: fingerprints and blocks hardly compress, and writing 16 MB costs less than
    // compressing it (measured on the oak's albedo).
    CacheEntry::new(&metadata, blobs, false)
}

fn encoding_from_entry(entry: CacheEntry) -> Option<PreviousEncoding> {
    let (metadata, blobs) = entry.metadata_and_blobs::<EncodingEntry>()?;
    let EncodingEntry { levels: sizes, reuse, settings, width, height, .. } = metadata;
    let level_count = sizes.len() + 1;
    if blobs.len() != 2 + sizes.len() + level_count + 2 {
        return None;
    }
    let mut blobs = blobs.into_iter();
    let texels = crate::db::from_pod_blob::<u64>(&blobs.next()?)?;
    let alphas = crate::db::from_pod_blob::<u64>(&blobs.next()?)?;
    let level0_blocks = BlockFingerprints { width, height, texels, alphas };
    let mut lower_levels = Vec::new();
    for &(level_width, level_height) in &sizes {
        let pixels = blobs.next()?;
        if pixels.len() != level_width as usize * level_height as usize * 4 {
            return None;
        }
        lower_levels.push(Texture::new(level_width, level_height, pixels));
    }
    let encoded_levels: Vec<Arc<[u8]>> = blobs.by_ref().take(level_count).map(Arc::from).collect();
    let errors = crate::db::from_pod_blob::<u32>(&blobs.next()?)?;
    let cut_out_blocks = crate::db::from_pod_blob::<crate::texture::quality::CutOutBlock>(&blobs.next()?)?;
    let cut_out = match metadata.alpha_threshold {
        Some(threshold) if cut_out_blocks.len() == errors.len() => Some((threshold, cut_out_blocks)),
        None if cut_out_blocks.is_empty() => None,
        _ => return None,
    };
    // Fingerprints, block data and errors must fit the levels (a hand-made entry is a miss,
    // never a panic).
    let blocks = |(width, height): (u32, u32)| width.div_ceil(4) as usize * height.div_ceil(4) as usize;
    let block_bytes = crate::texture::encode::block_bytes(settings.format);
    let all_sizes: Vec<(u32, u32)> = std::iter::once((width, height)).chain(sizes.iter().copied()).collect();
    if all_sizes.iter().zip(&encoded_levels).any(|(&size, level)| level.len() != blocks(size) * block_bytes)
        || errors.len() != blocks((width, height))
        || level0_blocks.texels.len() != blocks((width, height))
        || level0_blocks.alphas.len() != blocks((width, height))
    {
        return None;
    }
    let texture = crate::texture::encode::EncodedTexture::from_levels(
        settings.format,
        settings.srgb,
        width,
        height,
        encoded_levels,
    );
    let block_errors =
        crate::texture::quality::BlockErrors { format: settings.format, channels: metadata.channels, errors, cut_out };
    Some(PreviousEncoding {
        level0_blocks: Arc::new(level0_blocks),
        lower_levels,
        mip_reuse: reuse.map(Arc::new),
        encoded: EncodedSurface {
            settings,
            hidden: metadata.hidden.as_deref().and_then(|hash| blake3::Hash::from_hex(hash).ok()),
            texture,
            block_errors: Arc::new(block_errors),
            psnr_db: metadata.psnr_db,
        },
    })
}
