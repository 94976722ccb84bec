//! A billboard-cloud asset's surfaces in the texture tail, level by level: which a level has (a
//! cloud's four atlas surfaces, an impostor's three, a reduced level's maps), the slot and
//! material each belongs to, whether a level must render, and a level's surfaces written into
//! the asset's outputs.

use std::collections::BTreeMap;
use std::path::Path;

use super::{levels, queries, reduced_queries};
use crate::cache::CacheKey;
use crate::db::{Asset, Db, DECODE};
use crate::diagnostic::{display_path, Diagnostic};
use crate::kinds::{AssetOutputs, Read, StageInstance, SurfaceId, SurfacePart};
use crate::summary::ArtifactRole;
use crate::texture::SurfaceKind;

/// A level's surfaces: a cloud's four atlas surfaces, an impostor's three (their group is the
/// level's folder, their part the level's slot); a reduced level's maps, up to three a material
/// (`reduced::ReducedMaps`; none before its mesh is made, or when it fails).
pub(super) fn level_surfaces(db: &dyn Db, asset: Asset, level: u32) -> Vec<SurfaceId> {
    let settings = asset.settings(db);
    let folder = levels::level_folder(settings, level);
    if levels::is_reduced(settings, level) {
        let Ok(maps) = reduced_queries::reduced_maps(db, asset, level) else { return Vec::new() };
        return maps.surfaces(&folder, level).into_iter().map(|(surface, _)| surface).collect();
    }
    let kinds: &[SurfaceKind] =
        if levels::is_impostor(settings, level) { &levels::IMPOSTOR_SURFACES } else { &SurfaceKind::BILLBOARD };
    let part = SurfacePart { index: level, item: None };
    kinds.iter().map(|&surface| SurfaceId { group: folder.clone(), surface, part }).collect()
}

/// `key` for `surface` of `level` when the surface is stored smaller than it is made (its
/// halvings), else `key` itself (so that the keys of surfaces at their full size stay as they
/// were).
pub(super) fn with_halvings(db: &dyn Db, asset: Asset, level: u32, surface: &SurfaceId, key: CacheKey) -> CacheKey {
    match queries::level_settings(db, asset, level).surface_halvings.of(surface.surface) {
        0 => key,
        halvings => crate::db::stage_key(queries::SURFACE_HALVINGS).part(&key.0).part(&halvings).finish(),
    }
}

/// The slot a surface belongs to (its part's index), one the asset still has.
pub(super) fn slot_of_surface(db: &dyn Db, asset: Asset, surface: &SurfaceId) -> Result<u32, Diagnostic> {
    let slot = surface.part.index;
    match slot < levels::slot_count(asset.settings(db)) {
        true => Ok(slot),
        false => Err(Diagnostic::new(asset.main_file(db), format!("no LOD level `{}`", surface.group))),
    }
}

/// A reduced level's map surface: its material (the part's item) and halvings; none for the
/// surfaces of other levels.
pub(super) fn reduced_map_of(db: &dyn Db, asset: Asset, surface: &SurfaceId) -> Result<Option<(u32, u32)>, Diagnostic> {
    let level = slot_of_surface(db, asset, surface)?;
    let Some(material) = surface.part.item.filter(|_| levels::is_reduced(asset.settings(db), level)) else {
        return Ok(None);
    };
    let maps = reduced_queries::reduced_maps(db, asset, level)?;
    let halvings = maps.halvings(material, surface.surface).ok_or_else(|| {
        let folder = levels::level_folder(asset.settings(db), level);
        Diagnostic::new(asset.main_file(db), format!("no map `{}` in {folder}", surface.instance()))
    })?;
    Ok(Some((material, halvings)))
}

/// Whether some of a level's atlas surfaces are not in the persistent cache (so it renders; a
/// reduced level never does).
pub(super) fn level_renders(db: &dyn Db, asset: Asset, level: u32) -> bool {
    !levels::is_reduced(asset.settings(db), level)
        && !level_surfaces(db, asset, level)
            .iter()
            .all(|surface| crate::kinds::tail_queries::surface_in_cache(db, asset, surface))
}

/// `stage` reads the decode of the texture `path` (added to `decodes`, shared by every level).
pub(super) fn read_decode(stage: &mut StageInstance, path: &Path, decodes: &mut BTreeMap<String, StageInstance>) {
    let label = display_path(path);
    stage.reads.push(Read::Stage(DECODE, label.clone()));
    decodes.entry(label).or_insert_with(|| {
        let mut decode = StageInstance::new(DECODE, display_path(path), display_path(path));
        decode.reads.push(Read::File(path.to_path_buf()));
        decode.shared = true;
        decode
    });
}

/// What a level's surfaces wrote: the texture files' bytes, their bytes on the GPU (every mip),
/// each surface's figures, and each one's texture and preview file names.
pub(super) struct LevelSurfaces {
    pub bytes: usize,
    pub gpu_bytes: u64,
    pub infos: Vec<crate::texture::tail::SurfaceInfo>,
    pub names: Vec<(String, String)>,
}

/// Adds a level's surfaces from the tail (textures, previews, a cloud's `orm.png`) to `outputs`.
pub(super) fn write_level_surfaces(
    db: &dyn Db,
    asset: Asset,
    level: u32,
    output_folder: &Path,
    outputs: &mut AssetOutputs,
) -> Result<LevelSurfaces, Diagnostic> {
    let encode = &asset.settings(db).encode;
    let mut written = LevelSurfaces { bytes: 0, gpu_bytes: 0, infos: Vec::new(), names: Vec::new() };
    let name = |path: &Path| path.file_name().map(|name| name.to_string_lossy().into_owned()).unwrap_or_default();
    for surface in level_surfaces(db, asset, level) {
        let artifacts = crate::kinds::tail_queries::surface_artifacts(db, asset, surface.clone())?;
        let [texture_path, preview_path] = surface.artifact_paths(output_folder, encode);
        written.bytes += artifacts.texture_file.len();
        // Each at its own size: an `Auto` candidate's surfaces may be smaller than its albedo.
        let (width, height) = (artifacts.info.width, artifacts.info.height);
        written.gpu_bytes += crate::texture::encode::gpu_bytes(width, height, Some(encode.format_of(surface.surface)));
        written.names.push((name(&texture_path), name(&preview_path)));
        let orm_path = preview_path.with_file_name("orm.png");
        outputs.add(texture_path, ArtifactRole::Texture, artifacts.texture_file.clone());
        outputs.add(preview_path, ArtifactRole::Image, artifacts.preview_png.clone());
        if let Some(orm_png) = &artifacts.orm_png {
            outputs.add(orm_path, ArtifactRole::Image, orm_png.clone());
        }
        written.infos.push(artifacts.info.clone());
    }
    Ok(written)
}
