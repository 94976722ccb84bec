//! The tracked functions of the shared texture tail (thin glue over `texture::tail`): every
//! kind's surfaces run through them, keyed by asset and `SurfaceId` (salsa interns the pair).
//! The persistent cache is asked twice: by the surface's recipe (its kind's cheap key of what
//! the image is made of, so a restart needs no image), then by the image's content (so an edit
//! that leaves a surface's texels alone encodes nothing).

use std::sync::Arc;

use crate::cache::{CacheEntry, CacheKeyBuilder};
use crate::db::{load_cached, record_cache_hit, store_cached, timed, Asset, Db, Stage};
use crate::diagnostic::Diagnostic;
use crate::kinds::SurfaceId;
use crate::texture::tail::{
    tail_encode, tail_mips, tail_write, EncodedSurface, MipLevels, MipStepSettings, PreviousEncoding, SurfaceArtifacts, TailSettings,
};
use crate::texture::Texture;

// Versions: mips 2: coverage-preserving mips for albedo and opacity sources; 3: transparent
// texels of albedo mips keep their footprint's colour; 4: no coverage scaling when all or none
// of level 0 passes the cutoff. Encode 3: fully transparent BC7 blocks use the fastest profile;
// 4, 5: as mips 3, 4.
pub const MIPS: Stage = Stage { name: "mips", version: 4 };
pub const ENCODE: Stage = Stage { name: "encode", version: 5 };
pub const WRITE: Stage = Stage { name: "write", version: 1 };

/// The cache entry of a finished surface (under its recipe key and under its content key).
const SURFACE_ENTRY: &str = "surface";
const SURFACE_ENTRY_VERSION: u32 = 3;

#[salsa::tracked(returns(clone))]
pub fn tail_settings(db: &dyn Db, asset: Asset, surface: SurfaceId) -> Result<TailSettings, Diagnostic> {
    asset.kind(db).tail_settings(db, asset, &surface)
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
) -> Result<(crate::config::BlockFormat, crate::config::EncodeQuality), Diagnostic> {
    tail_settings(db, asset, surface).map(|settings| (settings.format, settings.quality))
}

#[salsa::tracked(returns(clone))]
fn write_step_settings(db: &dyn Db, asset: Asset, surface: SurfaceId) -> Result<(crate::config::Container, Option<i32>), Diagnostic> {
    tail_settings(db, asset, surface).map(|settings| (settings.container, settings.zstd))
}

/// The surface's image, made by its kind.
#[salsa::tracked(returns(clone))]
pub fn surface_image(db: &dyn Db, asset: Asset, surface: SurfaceId) -> Result<Arc<Texture>, Diagnostic> {
    asset.kind(db).surface_image(db, asset, &surface)
}

/// The mip chain (stage `mips`), re-filtering only the tiles that changed since the last run.
#[salsa::tracked(returns(clone))]
pub fn surface_mips(db: &dyn Db, asset: Asset, surface: SurfaceId) -> Result<Arc<MipLevels>, Diagnostic> {
    let image = surface_image(db, asset, surface.clone())?;
    let settings = mip_step_settings(db, asset, surface.clone())?;
    let label = surface.label(asset.name(db));
    let previous = db.previous_encoding(&label);
    Ok(Arc::new(timed(db, MIPS, &label, || tail_mips(&image, settings, previous.as_ref()))))
}

/// The blocks and their PSNR (stage `encode`), re-encoding only the blocks that changed.
#[salsa::tracked(returns(clone))]
pub fn surface_blocks(db: &dyn Db, asset: Asset, surface: SurfaceId) -> Result<Arc<EncodedSurface>, Diagnostic> {
    let mips = surface_mips(db, asset, surface.clone())?;
    let (format, quality) = encode_step_settings(db, asset, surface.clone())?;
    let label = surface.label(asset.name(db));
    let previous = db.previous_encoding(&label);
    let encoded = timed(db, ENCODE, &label, || tail_encode(&mips, surface.surface, format, quality, previous.as_ref()));
    db.remember_encoding(&label, PreviousEncoding { mips: (*mips).clone(), encoded: encoded.clone() });
    Ok(Arc::new(encoded))
}

/// The container and preview (stage `write`); from the persistent cache when a surface with
/// the same texels and settings was baked before.
#[salsa::tracked(returns(clone))]
pub fn surface_files(db: &dyn Db, asset: Asset, surface: SurfaceId) -> Result<Arc<SurfaceArtifacts>, Diagnostic> {
    let image = surface_image(db, asset, surface.clone())?;
    let settings = tail_settings(db, asset, surface.clone())?;
    let label = surface.label(asset.name(db));
    let content_key = surface_key(&settings).part(&image.width).part(&image.height).part(&image.hash).finish();
    if let Some(artifacts) = load_cached(db, SURFACE_ENTRY, content_key, artifacts_from_entry) {
        record_cache_hit(db, WRITE, &label);
        return Ok(Arc::new(artifacts));
    }
    let encoded = surface_blocks(db, asset, surface.clone())?;
    let (container, zstd) = write_step_settings(db, asset, surface.clone())?;
    let artifacts = timed(db, WRITE, &label, || tail_write(&image, surface.surface, &encoded, container, zstd));
    store_cached(db, SURFACE_ENTRY, content_key, || artifacts_entry(&artifacts));
    Ok(Arc::new(artifacts))
}

/// A surface's finished files: from the persistent cache by its recipe when the kind can name
/// one (then no image is made), else through the tail.
#[salsa::tracked(returns(clone))]
pub fn surface_artifacts(db: &dyn Db, asset: Asset, surface: SurfaceId) -> Result<Arc<SurfaceArtifacts>, Diagnostic> {
    let settings = tail_settings(db, asset, surface.clone())?;
    let recipe_key = asset.kind(db).surface_recipe_key(db, asset, &surface)?.map(|recipe| surface_key(&settings).part(&recipe.0).finish());
    if let Some(key) = recipe_key {
        if let Some(artifacts) = load_cached(db, SURFACE_ENTRY, key, artifacts_from_entry) {
            record_cache_hit(db, WRITE, &surface.label(asset.name(db)));
            return Ok(Arc::new(artifacts));
        }
    }
    let artifacts = surface_files(db, asset, surface)?;
    if let Some(key) = recipe_key {
        store_cached(db, SURFACE_ENTRY, key, || artifacts_entry(&artifacts));
    }
    Ok(artifacts)
}

/// Whether the persistent cache holds the surface's files under its recipe (a kind can then
/// skip making the image).
pub fn surface_in_cache(db: &dyn Db, asset: Asset, surface: &SurfaceId) -> bool {
    let (Some(cache), Ok(settings)) = (db.disk_cache(), tail_settings(db, asset, surface.clone())) else { return false };
    match asset.kind(db).surface_recipe_key(db, asset, surface) {
        Ok(Some(recipe)) => cache.contains(SURFACE_ENTRY, surface_key(&settings).part(&recipe.0).finish()),
        _ => false,
    }
}

/// The start of both keys of a surface entry: the tail's versions and every tail setting.
fn surface_key(settings: &TailSettings) -> CacheKeyBuilder {
    CacheKeyBuilder::new(SURFACE_ENTRY, SURFACE_ENTRY_VERSION)
        .part(&[MIPS.version, ENCODE.version, WRITE.version])
        .part(&settings.surface)
        .part(&settings.format)
        .part(&settings.quality)
        .part(&settings.mips)
        .part(&settings.alpha_cutoff)
        .part(&settings.container)
        .part(&settings.zstd)
}

fn artifacts_entry(artifacts: &SurfaceArtifacts) -> CacheEntry {
    CacheEntry {
        metadata: serde_json::to_value(&artifacts.info).expect("surface info serialises"),
        blobs: vec![artifacts.texture_file.to_vec(), artifacts.preview_png.to_vec()],
    }
}

fn artifacts_from_entry(entry: CacheEntry) -> Option<SurfaceArtifacts> {
    let info = serde_json::from_value(entry.metadata).ok()?;
    let [texture_file, preview_png]: [Vec<u8>; 2] = entry.blobs.try_into().ok()?;
    Some(SurfaceArtifacts { info, texture_file: texture_file.into(), preview_png: preview_png.into() })
}
