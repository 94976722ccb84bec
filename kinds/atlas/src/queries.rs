//! The atlas kind's tracked functions: thin glue from the asset's listed textures through the
//! pure steps (decode → trim → aliases → pack → page composite) to the shared tail, with the
//! last layout as the packer's hint and the last page as the composite's starting point.

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::Arc;

use crate::cache::{CacheEntry, CacheKey, CacheKeyBuilder};
use crate::db::{
    asset_file, cached_json, decoded_texture, key_with_files, load_cached, recall, remember, stage_key, store_cached,
    store_cached_in_background, texture_limits, timed, Asset, Db, SourceFile, Stage,
};
use crate::diagnostic::{display_path, Diagnostic};
use crate::packing::max_rects::{pack_pages_keeping, PackError, PagePacking, PagePlacement, PageSettings, Repack};
use crate::packing::Placement;
use crate::texture::fill::TexelSources;
use crate::texture::Texture;

use super::page::{
    composite_page_keeping_sources, crop, opaque_bounds, recomposite_page, uv_texel_rect, PageEntry, TrimRect,
};
use super::remap::UvReach;
use crate::settings::Settings as Own;

pub(crate) const TRIM: Stage = Stage { name: "trim", version: 1 };
/// 3: kept as a hint for the next layout; entries come from the trim stage. 4: an entry keeps
/// what the remapped meshes' UVs reach; aliases with their own canvases.
pub(crate) const LAYOUT: Stage = Stage { name: "layout", version: 4 };
/// Where the remapped meshes' UVs reach on each atlased texture.
pub const REACH: Stage = Stage { name: "reach", version: 1 };
pub(crate) const COMPOSITE: Stage = Stage { name: "composite", version: 2 };

/// What the layout needs of one texture file: its size, the rectangle trim keeps, and what
/// the kept texels are (equal ones make aliases).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub(crate) struct TrimmedTexture {
    pub source_size: [u32; 2],
    pub trim: TrimRect,
    /// blake3 of the kept texels.
    pub kept_hash: [u8; 32],
    /// Some kept texel is not fully opaque.
    pub translucent: bool,
}

/// One rectangle of the atlas: the texture it shows (its file, trimmed to `trim`), and the other
/// textures whose kept texels are the same pixels.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub(crate) struct LayoutEntry {
    /// The source path relative to the source folder (the first in name order of its aliases).
    pub name: String,
    pub aliases: Vec<LayoutAlias>,
    /// The texture file it shows, project-relative.
    pub file: PathBuf,
    pub source_size: [u32; 2],
    pub trim: TrimRect,
    /// What trimming transparent borders alone would keep, when the meshes' UVs made it keep
    /// more (`trim` then holds both).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub trimmed: Option<TrimRect>,
}

/// A texture that shares an entry's rectangle: its own name, canvas and where the shared texels
/// lie in it (two textures with the same pixels and different transparent borders).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub(crate) struct LayoutAlias {
    pub name: String,
    pub source_size: [u32; 2],
    pub trim: TrimRect,
}

/// The entries and where each went (`packing.placements` in entry order): all the table needs.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub(crate) struct AtlasLayout {
    pub entries: Vec<LayoutEntry>,
    pub packing: PagePacking,
}

/// How a layout came from the last one (for the report).
#[derive(Clone, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub(crate) struct LayoutChange {
    /// `fresh` (no earlier layout with these settings), `kept` (the earlier layout, new or
    /// resized entries put into free space) or `repacked` (kept would have been below 90 % of a
    /// fresh pack's occupancy, or could not take the new entries).
    pub how: String,
    /// Entries put into the kept layout's free space.
    pub placed: Vec<String>,
    /// Entries that were in the earlier layout and now lie elsewhere.
    pub moved: Vec<String>,
}

/// The asset's texture files (matches of its `textures` globs), project-relative, sorted.
pub(crate) fn atlas_texture_files(db: &dyn Db, asset: Asset) -> &[PathBuf] {
    asset.listed(db).first().map_or(&[], Vec::as_slice)
}

/// The packer's settings of the asset.
#[salsa::tracked(returns(copy))]
pub(crate) fn page_settings(db: &dyn Db, asset: Asset) -> PageSettings {
    let pack = &asset.settings(db).own::<Own>().pack;
    PageSettings {
        max_size: pack.max_size,
        padding: pack.padding,
        rotate: pack.rotate,
        power_of_two: pack.power_of_two,
        pages: pack.pages,
    }
}

/// Whether the asset trims transparent borders.
#[salsa::tracked(returns(copy))]
pub fn trims(db: &dyn Db, asset: Asset) -> bool {
    asset.settings(db).own::<Own>().pack.trim
}

/// A texture decoded, its kept rectangle found (stage `trim`, per file); from the persistent
/// cache when the file was trimmed before, so that a layout after a restart decodes nothing.
#[salsa::tracked(returns(clone))]
pub(crate) fn trimmed_texture(db: &dyn Db, file: SourceFile, trim: bool) -> Result<TrimmedTexture, Diagnostic> {
    let label = display_path(file.path(db));
    let key = key_with_files(db, stage_key(TRIM).part(&trim).part(&texture_limits(db).working_set), [file]).finish();
    cached_json(db, TRIM, &label, key, || {
        let texture = decoded_texture(db, file)?;
        Ok(timed(db, TRIM, &label, || trim_texture(&texture, trim)))
    })
}

/// The pure trim: the kept rectangle and what it holds.
fn trim_texture(texture: &Texture, trim: bool) -> TrimmedTexture {
    let rect = if trim {
        opaque_bounds(texture)
    } else {
        TrimRect { x: 0, y: 0, width: texture.width, height: texture.height }
    };
    kept_part(texture, rect)
}

fn kept_part(texture: &Texture, rect: TrimRect) -> TrimmedTexture {
    let kept = crop(texture, rect);
    TrimmedTexture {
        source_size: [texture.width, texture.height],
        trim: rect,
        kept_hash: *kept.hash.as_bytes(),
        translucent: kept.pixels.chunks_exact(4).any(|texel| texel[3] < 255),
    }
}

/// A texture kept to `rect` rather than to its trim (part of the stage `trim`, per file): where
/// a remapped mesh's UVs reach beyond the opaque texels.
#[salsa::tracked(returns(clone))]
pub(crate) fn kept_texture(db: &dyn Db, file: SourceFile, rect: TrimRect) -> Result<TrimmedTexture, Diagnostic> {
    let label = display_path(file.path(db));
    let key = key_with_files(db, stage_key(TRIM).part("kept").part(&[rect.x, rect.y, rect.width, rect.height]), [file]);
    cached_json(db, TRIM, &label, key.part(&texture_limits(db).working_set).finish(), || {
        let texture = decoded_texture(db, file)?;
        if rect.x + rect.width > texture.width || rect.y + rect.height > texture.height {
            return Err(Diagnostic::new(
                file.path(db),
                format!("the kept rectangle {rect:?} leaves the {}×{} texture", texture.width, texture.height),
            ));
        }
        Ok(timed(db, TRIM, &label, || kept_part(&texture, rect)))
    })
}

/// Where the asset's meshes sample each of its textures (stage `reach`): for every texture a
/// material of some mesh maps (any slot), the range of that material's triangles' texture
/// coordinates (finite ones), over every mesh and material. A mesh that does not load is the
/// remap's to report.
#[salsa::tracked(returns(clone))]
pub(crate) fn mesh_uv_reach(db: &dyn Db, asset: Asset) -> Arc<std::collections::BTreeMap<PathBuf, UvReach>> {
    let mut reach = std::collections::BTreeMap::new();
    let textures: std::collections::BTreeSet<&PathBuf> = atlas_texture_files(db, asset).iter().collect();
    for mesh in atlas_mesh_files(db, asset) {
        let Some(file) = asset_file(db, asset, mesh.clone()) else { continue };
        let Ok(contents) = file.contents(db) else { continue };
        let libraries = crate::kinds::mesh_queries::library_bytes(db, asset, mesh);
        let label = format!("{}/meshes/{}", asset.name(db), display_path(&remapped_mesh_path(db, asset, mesh)));
        // Keyed by the mesh, its libraries and which textures are atlased (by path).
        let library_files =
            mesh_library_paths(db, asset, mesh).into_iter().filter_map(|path| asset_file(db, asset, path));
        let atlased: Vec<String> =
            textures.iter().map(|path| display_path(&crate::db::source_relative(db, path))).collect();
        let key = key_with_files(db, stage_key(REACH).part(&atlased[..]), std::iter::once(file).chain(library_files))
            .finish();
        let found: Result<Vec<(PathBuf, UvReach)>, Diagnostic> = cached_json(db, REACH, &label, key, || {
            let obj = contents.bytes()?;
            Ok(timed(db, REACH, &label, || {
                let Ok((loaded, _)) = crate::mesh::load_mesh(mesh, &obj, &libraries, asset.source_root(db)) else {
                    return Vec::new();
                };
                super::remap::material_uv_reach(&loaded, |path| textures.contains(&path.to_path_buf()))
            }))
        });
        let found = found.unwrap_or_default();
        for (texture, range) in found {
            reach.entry(texture).and_modify(|known: &mut UvReach| *known = known.union(range)).or_insert(range);
        }
    }
    Arc::new(reach)
}

/// What the layout is made of: every texture file's content, the source folder (entry names
/// are relative to it) and the pack settings. The layout cached under it is the one made last
/// from these inputs (which earlier layout was its hint is not part of it).
#[salsa::tracked(returns(copy))]
pub(crate) fn layout_key(db: &dyn Db, asset: Asset) -> CacheKey {
    let key = stage_key(LAYOUT).part("atlas").part(&settings_key(db, asset).0);
    let files = atlas_texture_files(db, asset)
        .iter()
        .filter_map(|path| asset_file(db, asset, path.clone()))
        .collect::<Vec<_>>();
    let reach = crate::db::relocatable_hash(db, &*mesh_uv_reach(db, asset));
    key_with_files(db, key.part(&(files.len() as u32)), files).part(&reach).finish()
}

/// The pack and trim settings, as a key part.
fn settings_key(db: &dyn Db, asset: Asset) -> CacheKey {
    let settings = page_settings(db, asset);
    CacheKeyBuilder::new("atlas-settings", 1)
        .part(&[settings.max_size, settings.padding, settings.pages])
        .part(&[settings.rotate, settings.power_of_two, trims(db, asset)])
        .finish()
}

/// The layout and how it came from the last one (stage `layout`); from the persistent cache
/// when the same textures and settings were laid out before.
#[salsa::tracked(returns(clone))]
pub(crate) fn atlas_layout_and_change(
    db: &dyn Db,
    asset: Asset,
) -> Result<Arc<(AtlasLayout, LayoutChange)>, Diagnostic> {
    let laid_out = cached_json(db, LAYOUT, asset.name(db), layout_key(db, asset), || compute_atlas_layout(db, asset))?;
    remember_layout(db, asset, &laid_out.0);
    Ok(Arc::new(laid_out))
}

/// The layout alone: unchanged (and so not re-run downstream) when an edit moved nothing.
#[salsa::tracked(returns(clone))]
pub(crate) fn atlas_layout(db: &dyn Db, asset: Asset) -> Result<Arc<AtlasLayout>, Diagnostic> {
    atlas_layout_and_change(db, asset).map(|laid_out| Arc::new(laid_out.0.clone()))
}

fn compute_atlas_layout(db: &dyn Db, asset: Asset) -> Result<(AtlasLayout, LayoutChange), Diagnostic> {
    let settings = page_settings(db, asset);
    let files = atlas_texture_files(db, asset);
    let source_root = asset.source_root(db).clone();
    if files.is_empty() {
        return Err(Diagnostic::new(&source_root, format!("atlas `{}`: no texture matches its globs", asset.name(db))));
    }
    let mut entries: Vec<LayoutEntry> = Vec::new();
    let mut sizes: Vec<(u32, u32)> = Vec::new();
    let mut by_content: HashMap<([u8; 32], u32, u32), usize> = HashMap::new();
    let reach = mesh_uv_reach(db, asset);
    for path in files {
        let file = asset_file(db, asset, path.clone()).ok_or_else(|| Diagnostic::new(path, "file not found"))?;
        let kept = kept_for_meshes(db, asset, file, path, &reach)?;
        let name = display_path(path.strip_prefix(&source_root).unwrap_or(path));
        let content = (kept.texels.kept_hash, kept.texels.trim.width, kept.texels.trim.height);
        match by_content.get(&content) {
            Some(&entry) => entries[entry].aliases.push(LayoutAlias {
                name,
                source_size: kept.texels.source_size,
                trim: kept.texels.trim,
            }),
            None => {
                by_content.insert(content, entries.len());
                entries.push(LayoutEntry {
                    name,
                    aliases: Vec::new(),
                    file: path.clone(),
                    source_size: kept.texels.source_size,
                    trim: kept.texels.trim,
                    trimmed: kept.widened_from,
                });
                sizes.push((kept.texels.trim.width, kept.texels.trim.height));
            }
        }
    }
    let previous = previous_layout(db, asset);
    let hint = layout_hint(&entries, previous.as_deref());
    let previous_pages = previous.as_ref().map_or(&[][..], |previous| &previous.packing.pages[..]);
    let (packing, repack) =
        timed(db, LAYOUT, asset.name(db), || pack_pages_keeping(&sizes, &settings, previous_pages, &hint)).map_err(
            |error| {
                let named = match &error {
                    PackError::TooLarge { index, .. } => format!("{}: {error}", entries[*index].name),
                    _ => error.to_string(),
                };
                Diagnostic::new(&source_root, format!("atlas `{}`: {named}", asset.name(db)))
            },
        )?;
    let moved = entries
        .iter()
        .zip(&hint)
        .zip(&packing.placements)
        .filter(|((_, before), now)| before.is_some_and(|before| before != **now))
        .map(|((entry, _), _)| entry.name.clone())
        .collect();
    let change = match repack {
        _ if previous.is_none() => LayoutChange { how: "fresh".into(), placed: Vec::new(), moved },
        Repack::Kept { placed } => LayoutChange {
            how: "kept".into(),
            placed: placed.iter().map(|&index| entries[index].name.clone()).collect(),
            moved,
        },
        Repack::Repacked => LayoutChange { how: "repacked".into(), placed: Vec::new(), moved },
    };
    Ok((AtlasLayout { entries, packing }, change))
}

/// What an entry keeps of a texture: its trim, widened to what the asset's meshes' UVs reach on
/// it (a remapped mesh must find its texels on the page), and the trim alone when it was.
struct KeptTexels {
    texels: TrimmedTexture,
    widened_from: Option<TrimRect>,
}

fn kept_for_meshes(
    db: &dyn Db,
    asset: Asset,
    file: SourceFile,
    path: &PathBuf,
    reach: &std::collections::BTreeMap<PathBuf, UvReach>,
) -> Result<KeptTexels, Diagnostic> {
    let trimmed = trimmed_texture(db, file, trims(db, asset))?;
    let Some(range) = reach.get(path) else { return Ok(KeptTexels { texels: trimmed, widened_from: None }) };
    let wanted = uv_texel_rect(range.u, range.v, trimmed.source_size);
    if trimmed.trim.contains(wanted) {
        return Ok(KeptTexels { texels: trimmed, widened_from: None });
    }
    Ok(KeptTexels { texels: kept_texture(db, file, trimmed.trim.union(wanted))?, widened_from: Some(trimmed.trim) })
}

/// Each entry's place in the previous layout, found by any of its names (its own or an
/// alias's, so that a texture whose alias sorts first now keeps its rectangle).
fn layout_hint(entries: &[LayoutEntry], previous: Option<&AtlasLayout>) -> Vec<Option<PagePlacement>> {
    let Some(previous) = previous else { return vec![None; entries.len()] };
    let mut by_name: HashMap<&str, PagePlacement> = HashMap::new();
    for (entry, place) in previous.entries.iter().zip(&previous.packing.placements) {
        for name in std::iter::once(&entry.name).chain(entry.aliases.iter().map(|alias| &alias.name)) {
            by_name.insert(name, *place);
        }
    }
    let mut taken = std::collections::HashSet::new();
    entries
        .iter()
        .map(|entry| {
            let place = std::iter::once(&entry.name)
                .chain(entry.aliases.iter().map(|alias| &alias.name))
                .find_map(|name| by_name.get(name.as_str()).copied())?;
            // Two entries that were one (aliases whose pixels now differ): the first keeps it.
            taken.insert((place.page, place.placement.x, place.placement.y)).then_some(place)
        })
        .collect()
}

/// The memo of the asset's last layout: not a content address but the asset's name and its
/// pack settings (a layout made with other settings is no hint), overwritten by every layout.
const LAYOUT_MEMO: &str = "atlas-layout-memo";

fn layout_memo_key(db: &dyn Db, asset: Asset) -> CacheKey {
    CacheKeyBuilder::new(LAYOUT_MEMO, LAYOUT.version).part(asset.name(db)).part(&settings_key(db, asset).0).finish()
}

fn layout_memo_name(db: &dyn Db, asset: Asset) -> crate::db::Memo<AtlasLayout> {
    crate::db::Memo::new(LAYOUT_MEMO, format_args!("{}:{}", asset.name(db), settings_key(db, asset).0.to_hex()))
}

/// The asset's last layout with its settings: from this process, else from the memo on disk.
fn previous_layout(db: &dyn Db, asset: Asset) -> Option<Arc<AtlasLayout>> {
    if let Some(previous) = recall(db, &layout_memo_name(db, asset)) {
        return Some(previous);
    }
    load_cached(db, LAYOUT_MEMO, layout_memo_key(db, asset), |entry| entry.parts::<_, 0>().map(|(layout, [])| layout))
        .map(Arc::new)
}

fn remember_layout(db: &dyn Db, asset: Asset, layout: &AtlasLayout) {
    let name = layout_memo_name(db, asset);
    if recall(db, &name).is_some_and(|previous| *previous == *layout) {
        return;
    }
    remember(db, &name, Arc::new(layout.clone()));
    store_cached(db, LAYOUT_MEMO, layout_memo_key(db, asset), || CacheEntry::new(layout, Vec::new(), true));
}

/// The entries of one page: their layout entry, place, and trimmed texture facts.
fn page_entries(
    db: &dyn Db,
    asset: Asset,
    layout: &AtlasLayout,
    page: u32,
) -> Result<Vec<(LayoutEntry, PageEntry)>, Diagnostic> {
    let trim = trims(db, asset);
    let mut found = Vec::new();
    for (entry, place) in layout.entries.iter().zip(&layout.packing.placements).filter(|(_, place)| place.page == page)
    {
        let file =
            asset_file(db, asset, entry.file.clone()).ok_or_else(|| Diagnostic::new(&entry.file, "file not found"))?;
        let trimmed = match entry.trimmed {
            Some(_) => kept_texture(db, file, entry.trim)?,
            None => trimmed_texture(db, file, trim)?,
        };
        found.push((
            entry.clone(),
            PageEntry { placement: place.placement, kept_hash: trimmed.kept_hash, translucent: trimmed.translucent },
        ));
    }
    Ok(found)
}

/// One page with its entries in place (stage `composite`): starting from the page's last
/// composite when only some entries' texels changed (then only those are decoded and put
/// back), else from every entry.
#[salsa::tracked(returns(clone))]
pub(crate) fn atlas_page(db: &dyn Db, asset: Asset, page: u32) -> Result<Arc<Texture>, Diagnostic> {
    let layout = atlas_layout(db, asset)?;
    let Some(&(width, height)) = layout.packing.pages.get(page as usize) else {
        return Err(Diagnostic::new(asset.source_root(db), format!("atlas page {page} no longer exists")));
    };
    let padding = page_settings(db, asset).padding;
    let entries = page_entries(db, asset, &layout, page)?;
    let recipe: Vec<PageEntry> = entries.iter().map(|(_, entry)| *entry).collect();
    let memo_name = page_memo_name(asset.name(db), page);
    let label = page_label(asset.name(db), page);
    let previous = previous_page(db, &memo_name).filter(|previous| previous.fits(width, height, padding, &recipe));
    let (texture, sources) = match previous {
        Some(previous) => {
            let changed: Vec<usize> = (0..recipe.len())
                .filter(|&index| recipe[index].kept_hash != previous.entries[index].kept_hash)
                .collect();
            if changed.is_empty() {
                return Ok(Arc::new(previous.texture.clone()));
            }
            let mut kept = Vec::new();
            for &index in &changed {
                let (entry, _) = &entries[index];
                kept.push((index, crop(&*entry_texture(db, asset, &entry.file)?, entry.trim)));
            }
            let textures: Vec<(usize, &Texture)> = kept.iter().map(|(index, texture)| (*index, texture)).collect();
            let texture = timed(db, COMPOSITE, &label, || {
                recomposite_page(&previous.texture, &previous.sources, &recipe, &textures, padding)
            });
            (texture, previous.sources.clone())
        }
        None => {
            let mut kept = Vec::new();
            for (entry, page_entry) in &entries {
                kept.push((crop(&*entry_texture(db, asset, &entry.file)?, entry.trim), page_entry.placement));
            }
            let textures: Vec<(&Texture, Placement)> =
                kept.iter().map(|(texture, placement)| (texture, *placement)).collect();
            let (texture, sources) =
                timed(db, COMPOSITE, &label, || composite_page_keeping_sources(width, height, &textures, padding));
            (texture, Arc::new(sources))
        }
    };
    let memo = Arc::new(PageMemo { entries: recipe, padding, texture: texture.clone(), sources });
    remember(db, &memo_name, memo.clone());
    store_cached_in_background(db, PAGE_MEMO, page_memo_key(memo_name.name()), move || page_memo_entry(&memo));
    Ok(Arc::new(texture))
}

/// The memo of a page's last composite on disk: not a content address but the page's name,
/// overwritten by every composite, so that a new process after a texel edit decodes only the
/// entries that changed. Pages equal a fresh composite either way.
const PAGE_MEMO: &str = "atlas-page-memo";

fn page_memo_key(memo_name: &str) -> CacheKey {
    CacheKeyBuilder::new(PAGE_MEMO, COMPOSITE.version).part(memo_name).finish()
}

/// The page's last composite: from this process, else from the memo on disk.
fn previous_page(db: &dyn Db, memo_name: &crate::db::Memo<PageMemo>) -> Option<Arc<PageMemo>> {
    if let Some(previous) = recall(db, memo_name) {
        return Some(previous);
    }
    load_cached(db, PAGE_MEMO, page_memo_key(memo_name.name()), page_memo_from_entry).map(Arc::new)
}

fn page_memo_entry(memo: &PageMemo) -> CacheEntry {
    let entries: Vec<(Placement, String, bool)> = memo
        .entries
        .iter()
        .map(|entry| (entry.placement, blake3::Hash::from(entry.kept_hash).to_hex().to_string(), entry.translucent))
        .collect();
    let metadata =
        PageMemoEntry { entries, padding: memo.padding, width: memo.texture.width, height: memo.texture.height };
    let blobs = vec![memo.texture.pixels.to_vec(), crate::db::pod_blob(&memo.sources.to_offsets())];
    CacheEntry::new(&metadata, blobs, true)
}

/// What a page memo entry holds beside its pixels and fill offsets.
#[derive(serde::Serialize, serde::Deserialize)]
struct PageMemoEntry {
    /// Each entry's placement, kept texels' hash (hex) and whether it is translucent.
    entries: Vec<(Placement, String, bool)>,
    padding: u32,
    width: u32,
    height: u32,
}

fn page_memo_from_entry(entry: CacheEntry) -> Option<PageMemo> {
    let (metadata, [pixels, offsets]) = entry.parts::<PageMemoEntry, 2>()?;
    let PageMemoEntry { entries: listed, padding, width, height } = metadata;
    let mut entries = Vec::new();
    for (placement, hash, translucent) in listed {
        entries.push(PageEntry { placement, kept_hash: *blake3::Hash::from_hex(hash).ok()?.as_bytes(), translucent });
    }
    let texels = width as usize * height as usize;
    if pixels.len() != texels * 4 {
        return None;
    }
    let sources = TexelSources::from_offsets(&crate::db::from_pod_blob::<u32>(&offsets)?, texels)?;
    Some(PageMemo { entries, padding, texture: Texture::new(width, height, pixels), sources: Arc::new(sources) })
}

/// A page's last composite in this process: its entries, the page, and where each uncovered
/// texel takes its colour from (the same while the placements are).
struct PageMemo {
    entries: Vec<PageEntry>,
    padding: u32,
    texture: Texture,
    sources: Arc<TexelSources>,
}

impl PageMemo {
    /// Whether the page can start from this one: same size, padding, placements, and the same
    /// translucency (which decides the fill's alpha) of every entry.
    fn fits(&self, width: u32, height: u32, padding: u32, entries: &[PageEntry]) -> bool {
        (self.texture.width, self.texture.height, self.padding) == (width, height, padding)
            && self.entries.len() == entries.len()
            && self
                .entries
                .iter()
                .zip(entries)
                .all(|(a, b)| a.placement == b.placement && a.translucent == b.translucent)
    }
}

fn page_memo_name(asset_name: &str, page: u32) -> crate::db::Memo<PageMemo> {
    crate::db::Memo::new("atlas-page", page_label(asset_name, page))
}

/// A texture of the atlas, decoded.
fn entry_texture(db: &dyn Db, asset: Asset, path: &PathBuf) -> Result<Arc<Texture>, Diagnostic> {
    let file = asset_file(db, asset, path.clone()).ok_or_else(|| Diagnostic::new(path, "file not found"))?;
    decoded_texture(db, file)
}

/// What a page is made of, cheap to compute once the layout is known: the page's size, each
/// of its entries' place and file content, and the padding; so that a page already in the
/// persistent cache needs no composite, and an edit elsewhere leaves this page's key alone.
pub(crate) fn page_recipe_key(db: &dyn Db, asset: Asset, page: u32) -> Result<CacheKey, Diagnostic> {
    let layout = atlas_layout(db, asset)?;
    let Some(&(width, height)) = layout.packing.pages.get(page as usize) else {
        return Err(Diagnostic::new(asset.source_root(db), format!("atlas page {page} no longer exists")));
    };
    let mut key = stage_key(COMPOSITE)
        .part(&page)
        .part(&[width, height])
        .part(&page_settings(db, asset).padding)
        .part(&trims(db, asset));
    for (entry, place) in layout.entries.iter().zip(&layout.packing.placements).filter(|(_, place)| place.page == page)
    {
        let file =
            asset_file(db, asset, entry.file.clone()).ok_or_else(|| Diagnostic::new(&entry.file, "file not found"))?;
        let placement = place.placement;
        let trim = entry.trim;
        key = key
            .part(&[placement.x, placement.y, placement.width, placement.height])
            .part(&placement.rotated)
            .part(&[trim.x, trim.y, trim.width, trim.height]);
        key = key_with_files(db, key, [file]);
    }
    Ok(key.finish())
}

/// A page's name inside the asset: `page0`, `page1`, ….
pub(crate) fn page_group(page: u32) -> String {
    format!("page{page}")
}

/// The label of a page's composite: `asset/page0`.
pub(crate) fn page_label(asset_name: &str, page: u32) -> String {
    format!("{asset_name}/{}", page_group(page))
}

/// A page's texture file name: `atlas` for the first page, `atlas_N` for the others.
pub(crate) fn page_stem(page: u32) -> String {
    if page == 0 {
        "atlas".to_string()
    } else {
        format!("atlas_{page}")
    }
}

/// The asset's mesh files (matches of its `meshes` globs), project-relative, sorted.
pub(crate) fn atlas_mesh_files(db: &dyn Db, asset: Asset) -> &[PathBuf] {
    asset.listed(db).get(1).map_or(&[], Vec::as_slice)
}

/// The MTL files a mesh of the asset names (as far as its OBJ has been read).
pub(crate) fn mesh_library_paths(db: &dyn Db, asset: Asset, mesh: &std::path::Path) -> Vec<PathBuf> {
    crate::kinds::mesh_queries::mesh_library_paths_of(db, asset, mesh.to_path_buf()).to_vec()
}

/// The texture files a mesh's materials name (as far as its MTL files have been read).
pub(crate) fn mesh_map_paths(db: &dyn Db, asset: Asset, mesh: &std::path::Path) -> Vec<PathBuf> {
    crate::mesh::texture_paths(&crate::kinds::mesh_queries::library_bytes(db, asset, mesh), asset.source_root(db))
}

/// A mesh's path in the source folder with the extension `.obj`: what its stages are named by
/// (`foliage/meshes/trees/bush_2.obj`).
pub(crate) fn remapped_mesh_path(db: &dyn Db, asset: Asset, mesh: &std::path::Path) -> PathBuf {
    let relative = mesh.strip_prefix(asset.source_root(db)).unwrap_or(mesh);
    // By hand: `with_extension` makes `..obj` into `..` (its stem `.` is special to it).
    let name = relative.file_name().map_or_else(String::new, |name| name.to_string_lossy().into_owned());
    let stem = match name.rsplit_once('.') {
        Some((stem, _)) if !stem.is_empty() => stem,
        _ => name.as_str(),
    };
    relative.with_file_name(format!("{stem}.obj"))
}

/// A remapped mesh's file in the asset's output folder: [`remapped_mesh_path`] with its folders
/// joined to its name by `-` (`trees/bush_2.obj` → `trees-bush_2.obj`), beside `atlas.mtl`, the
/// pages and `maps/`, so that nothing it names lies above it (loaders such as trimesh refuse
/// a `..` in a material or image path). Its `.gltf` and `.bin` take the same stem.
pub(crate) fn remapped_mesh_file(db: &dyn Db, asset: Asset, mesh: &std::path::Path) -> PathBuf {
    let relative = remapped_mesh_path(db, asset, mesh);
    let parts: Vec<String> =
        relative.components().map(|component| component.as_os_str().to_string_lossy().into_owned()).collect();
    PathBuf::from(parts.join("-"))
}

/// The table the layout gives (entries in name order), as `atlas.json` has it.
pub(crate) fn atlas_table_entries(layout: &AtlasLayout) -> Vec<super::table::AtlasEntry> {
    use super::table::{AtlasAlias, AtlasEntry, UvTransform};
    let mut entries: Vec<AtlasEntry> = layout
        .entries
        .iter()
        .zip(&layout.packing.placements)
        .map(|(entry, place)| {
            let placement = place.placement;
            let page_size = layout.packing.pages[place.page as usize];
            let transform = UvTransform::of(&placement, entry.trim, entry.source_size, page_size);
            let aliases = entry
                .aliases
                .iter()
                .map(|alias| {
                    let transform = UvTransform::of(&placement, alias.trim, alias.source_size, page_size);
                    AtlasAlias {
                        name: alias.name.clone(),
                        source_size: alias.source_size,
                        trim_offset: [alias.trim.x, alias.trim.y],
                        uv_offset: transform.uv_offset,
                        uv_scale: transform.uv_scale,
                    }
                })
                .collect();
            AtlasEntry {
                name: entry.name.clone(),
                page: place.page,
                x: placement.x,
                y: placement.y,
                width: placement.width,
                height: placement.height,
                rotated: placement.rotated,
                source_size: entry.source_size,
                trim_offset: [entry.trim.x, entry.trim.y],
                uv_offset: transform.uv_offset,
                uv_scale: transform.uv_scale,
                aliases,
            }
        })
        .collect();
    entries.sort_by(|a, b| a.name.cmp(&b.name));
    entries
}

/// A mesh remapped onto the atlas (stage `remap`, per mesh): reads the OBJ, its MTL files and
/// the layout, so that texel edits that move nothing leave it alone; from the persistent cache
/// when the same files were remapped onto the same layout before.
#[salsa::tracked(returns(clone))]
pub(crate) fn remapped_mesh(
    db: &dyn Db,
    asset: Asset,
    mesh: PathBuf,
) -> Result<Arc<super::remap::RemappedMesh>, Diagnostic> {
    let layout = atlas_layout(db, asset)?;
    let label = format!("{}/meshes/{}", asset.name(db), display_path(&remapped_mesh_path(db, asset, &mesh)));
    let file = asset_file(db, asset, mesh.clone()).ok_or_else(|| Diagnostic::new(&mesh, "file not found"))?;
    let libraries: Vec<(PathBuf, Option<SourceFile>)> = mesh_library_paths(db, asset, &mesh)
        .into_iter()
        .map(|path| (path.clone(), asset_file(db, asset, path)))
        .collect();
    // Why each texture the mesh's materials name cannot be read, if it cannot (not its texels:
    // a texel edit leaves the remap alone).
    let map_files: HashMap<PathBuf, Option<String>> = mesh_map_paths(db, asset, &mesh)
        .into_iter()
        .map(|path| {
            let unreadable = match asset_file(db, asset, path.clone()) {
                Some(file) => crate::db::file_read_error(db, file),
                None => Some("file not found".to_string()),
            };
            (path, unreadable)
        })
        .collect();
    let mut missing: Vec<String> = map_files
        .iter()
        .filter_map(|(path, why)| {
            Some(format!("{}: {}", display_path(&crate::db::source_relative(db, path)), why.as_ref()?))
        })
        .collect();
    missing.sort();
    let key = stage_key(REMAP).part(&crate::db::relocatable_hash(db, &*layout)).part(&missing[..]);
    let key =
        key_with_files(db, key, std::iter::once(file).chain(libraries.iter().filter_map(|(_, file)| *file))).finish();
    cached_json(db, REMAP, &label, key, || {
        let obj = crate::db::read_contents(db, file)?.bytes()?;
        let library_bytes = crate::kinds::mesh_queries::library_bytes(db, asset, &mesh);
        timed(db, REMAP, &label, || {
            let (loaded, warnings) = crate::mesh::load_mesh(&mesh, &obj, &library_bytes, asset.source_root(db))?;
            let targets = super::remap::remap_targets(&atlas_table_entries(&layout));
            let by_path: HashMap<PathBuf, usize> = targets
                .iter()
                .enumerate()
                .map(|(index, target)| (asset.source_root(db).join(&target.name), index))
                .collect();
            let remap_error = |error: super::remap::RemapError| Diagnostic::new(&mesh, error.to_string());
            // A map of a used material that does not exist would leave the mesh pointing at it.
            for &material in loaded.triangle_materials.iter().collect::<std::collections::BTreeSet<_>>() {
                let Some(material) = loaded.materials.get(material as usize) else { continue };
                for path in material.maps.values() {
                    if let Some(Some(why)) = map_files.get(path) {
                        let texture = display_path(path.strip_prefix(asset.source_root(db)).unwrap_or(path));
                        return Err(remap_error(super::remap::RemapError::MissingMap {
                            material: material.name.clone(),
                            texture,
                            why: why.clone(),
                        }));
                    }
                }
            }
            let chosen = super::remap::material_entries(&loaded, &targets, |path| by_path.get(path).copied())
                .map_err(remap_error)?;
            let library = "atlas.mtl";
            let header = format!("cirrus: {} remapped onto atlas `{}`", display_path(&mesh), asset.name(db));
            let remapped =
                super::remap::remap_mesh(&loaded, &targets, &chosen, library, &header).map_err(remap_error)?;
            let remap_warnings =
                remapped.warnings.iter().map(|warning| Diagnostic::new(&mesh, warning.message.clone()));
            let not_kept = statements_not_kept(&mesh, &obj, &library_bytes, &remapped.materials);
            Ok(super::remap::RemappedMesh {
                warnings: warnings.into_iter().chain(remap_warnings).chain(not_kept).collect(),
                ..remapped
            })
        })
    })
    .map(Arc::new)
}

/// Warnings for what the remapped OBJ and `atlas.mtl` leave out of their sources: the OBJ's
/// object and group names, lines and points, and the MTL statements of its used materials that
/// `atlas.mtl` does not write (`Ks`, `Ns`, `illum`, `map_Ks`…), each at its first line.
fn statements_not_kept(
    mesh: &std::path::Path,
    obj: &[u8],
    libraries: &std::collections::BTreeMap<PathBuf, Option<Vec<u8>>>,
    materials: &[super::remap::RemappedMaterial],
) -> Vec<Diagnostic> {
    use crate::diagnostic::TextPosition;
    use crate::mesh::obj_text::{mtl_statements_not_kept, obj_statements_not_kept};
    let at = |line: u32| TextPosition { line, column: 1 };
    let mut warnings: Vec<Diagnostic> = obj_statements_not_kept(&String::from_utf8_lossy(obj))
        .into_iter()
        .map(|(line, message)| Diagnostic::at(mesh, at(line), message).as_warning())
        .collect();
    for material in materials {
        let name = &material.material.name;
        let found = libraries.iter().find_map(|(library, bytes)| {
            let text = String::from_utf8_lossy(bytes.as_deref()?);
            mtl_statements_not_kept(&text, name).map(|found| (library, found))
        });
        if let Some((library, (line, keywords))) = found {
            let keywords: Vec<String> = keywords.iter().map(|keyword| format!("`{keyword}`")).collect();
            let message = format!(
                "material `{name}`: {} are not written to atlas.mtl, which keeps Kd, d, Pr, Pm and the maps cirrus \
                 reads",
                keywords.join(", ")
            );
            warnings.push(Diagnostic::at(library, at(line), message).as_warning());
        }
    }
    warnings
}

/// 2: with the mesh's load warnings.
/// 3: UVs onto each texture's own place (aliases), maps' -s and -o kept, unused materials ignored.
/// 4: a map's path relative to the MTL file that names it.
/// 5: with the mesh's glTF geometry; beside `atlas.mtl` (`mtllib atlas.mtl`).
/// 6: the glTF geometry's tangents MikkTSpace's.
/// 7: warnings for the OBJ and MTL statements the output does not keep.
pub(crate) const REMAP: Stage = Stage { name: "remap", version: 7 };
