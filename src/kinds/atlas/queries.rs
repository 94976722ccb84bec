//! The atlas kind's tracked functions: thin glue from the asset's listed textures through the
//! pure steps (decode → trim → aliases → pack → page composite) to the shared tail.

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::Arc;

use crate::cache::CacheKey;
use crate::db::{asset_file, cached_json, decoded_texture, key_with_files, stage_key, timed, Asset, Db, Stage};
use crate::diagnostic::{display_path, Diagnostic};
use crate::packing::max_rects::{pack_pages, PagePacking, PageSettings};
use crate::texture::Texture;

use super::page::{composite_page, crop, opaque_bounds, TrimRect};

pub const LAYOUT: Stage = Stage { name: "layout", version: 2 };
pub const COMPOSITE: Stage = Stage { name: "composite", version: 1 };

/// One rectangle of the atlas: the texture it shows (its file, trimmed to `trim`), and the other
/// textures with the same pixels.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LayoutEntry {
    /// The source path relative to the source folder (the first in name order of its aliases).
    pub name: String,
    pub aliases: Vec<String>,
    /// The texture file it shows, project-relative.
    pub file: PathBuf,
    pub source_size: [u32; 2],
    pub trim: TrimRect,
}

/// The entries and where each went (`packing.placements` in entry order): all the table needs,
/// kept in the persistent cache so that a restart with nothing changed decodes nothing.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct AtlasLayout {
    pub entries: Vec<LayoutEntry>,
    pub packing: PagePacking,
}

/// The asset's texture files (matches of its `textures` globs), project-relative, sorted.
pub fn atlas_texture_files(db: &dyn Db, asset: Asset) -> &[PathBuf] {
    asset.listed(db).first().map_or(&[], Vec::as_slice)
}

/// What the layout is made of: every texture file's content, the source folder (entry names
/// are relative to it) and the pack settings.
#[salsa::tracked(returns(copy))]
pub fn layout_key(db: &dyn Db, asset: Asset) -> CacheKey {
    let pack = &asset.settings(db).pack;
    let key = stage_key(LAYOUT).part("atlas").part(asset.source_root(db)).part(&[pack.max_size, pack.padding, pack.pages]).part(&[
        pack.rotate,
        pack.trim,
        pack.power_of_two,
    ]);
    let files = atlas_texture_files(db, asset).iter().filter_map(|path| asset_file(db, asset, path.clone())).collect::<Vec<_>>();
    key_with_files(db, key.part(&(files.len() as u32)), files).finish()
}

/// Every texture decoded, trimmed when asked, equal ones merged, and packed onto pages (stage
/// `layout`); from the persistent cache when the textures and settings were laid out before.
#[salsa::tracked(returns(clone))]
pub fn atlas_layout(db: &dyn Db, asset: Asset) -> Result<Arc<AtlasLayout>, Diagnostic> {
    cached_json(db, LAYOUT, asset.name(db), layout_key(db, asset), || compute_atlas_layout(db, asset)).map(Arc::new)
}

fn compute_atlas_layout(db: &dyn Db, asset: Asset) -> Result<AtlasLayout, Diagnostic> {
    let settings = asset.settings(db).pack.clone();
    let files = atlas_texture_files(db, asset);
    let source_root = asset.source_root(db).clone();
    if files.is_empty() {
        return Err(Diagnostic::new(&source_root, format!("atlas `{}`: no texture matches its globs", asset.name(db))));
    }
    let mut entries: Vec<LayoutEntry> = Vec::new();
    let mut sizes: Vec<(u32, u32)> = Vec::new();
    let mut by_content: HashMap<(blake3::Hash, u32, u32), usize> = HashMap::new();
    for path in files {
        let texture = entry_texture(db, asset, path)?;
        let name = display_path(path.strip_prefix(&source_root).unwrap_or(path));
        let trim =
            if settings.trim { opaque_bounds(&texture) } else { TrimRect { x: 0, y: 0, width: texture.width, height: texture.height } };
        let kept = crop(&texture, trim);
        match by_content.get(&(kept.hash, kept.width, kept.height)) {
            Some(&entry) => entries[entry].aliases.push(name),
            None => {
                by_content.insert((kept.hash, kept.width, kept.height), entries.len());
                entries.push(LayoutEntry {
                    name,
                    aliases: Vec::new(),
                    file: path.clone(),
                    source_size: [texture.width, texture.height],
                    trim,
                });
                sizes.push((kept.width, kept.height));
            }
        }
    }
    let page_settings = PageSettings {
        max_size: settings.max_size,
        padding: settings.padding,
        rotate: settings.rotate,
        power_of_two: settings.power_of_two,
        pages: settings.pages,
    };
    let packing = timed(db, LAYOUT, asset.name(db), || pack_pages(&sizes, &page_settings)).map_err(|error| {
        let named = match &error {
            crate::packing::max_rects::PackError::TooLarge { index, .. } => format!("{}: {error}", entries[*index].name),
            _ => error.to_string(),
        };
        Diagnostic::new(&source_root, format!("atlas `{}`: {named}", asset.name(db)))
    })?;
    Ok(AtlasLayout { entries, packing })
}

/// A texture of the atlas, decoded.
fn entry_texture(db: &dyn Db, asset: Asset, path: &PathBuf) -> Result<Arc<Texture>, Diagnostic> {
    let file = asset_file(db, asset, path.clone()).ok_or_else(|| Diagnostic::new(path, "file not found"))?;
    decoded_texture(db, file)
}

/// One page with its entries in place (stage `composite`).
#[salsa::tracked(returns(clone))]
pub fn atlas_page(db: &dyn Db, asset: Asset, page: u32) -> Result<Arc<Texture>, Diagnostic> {
    let layout = atlas_layout(db, asset)?;
    let Some(&(width, height)) = layout.packing.pages.get(page as usize) else {
        return Err(Diagnostic::new(asset.source_root(db), format!("atlas page {page} no longer exists")));
    };
    let mut kept = Vec::new();
    for (entry, place) in layout.entries.iter().zip(&layout.packing.placements).filter(|(_, place)| place.page == page) {
        kept.push((crop(&*entry_texture(db, asset, &entry.file)?, entry.trim), place.placement));
    }
    let entries: Vec<(&Texture, crate::packing::Placement)> = kept.iter().map(|(texture, placement)| (texture, *placement)).collect();
    let padding = asset.settings(db).pack.padding;
    Ok(Arc::new(timed(db, COMPOSITE, &page_label(asset.name(db), page), || composite_page(width, height, &entries, padding))))
}

/// What a page is made of, cheap to compute: the layout's key (every texture, the settings)
/// and the page, so that a page already in the persistent cache needs no composite.
pub fn page_recipe_key(db: &dyn Db, asset: Asset, page: u32) -> CacheKey {
    stage_key(COMPOSITE).part(&layout_key(db, asset).0).part(&page).finish()
}

/// A page's name inside the asset: `page0`, `page1`, ….
pub fn page_group(page: u32) -> String {
    format!("page{page}")
}

/// The label of a page's composite: `asset/page0`.
pub fn page_label(asset_name: &str, page: u32) -> String {
    format!("{asset_name}/{}", page_group(page))
}

/// A page's texture file name: `atlas` for the first page, `atlas_N` for the others.
pub fn page_stem(page: u32) -> String {
    if page == 0 {
        "atlas".to_string()
    } else {
        format!("atlas_{page}")
    }
}
