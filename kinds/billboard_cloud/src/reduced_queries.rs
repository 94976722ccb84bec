//! The BillboardCloud kind's tracked functions for a reduced level's maps (stage `maps`): which
//! materials it draws and at what sizes (`reduced::allot_maps`), and each map surface's image
//! and cache key, for the texture tail. Thin glue over `reduced` and `texture::channel_packing`.

use std::sync::Arc;

use super::queries::{billboard_alpha_cutoff, level_settings, reduced_level, MAPS};
use crate::cache::CacheKey;
use crate::db::{asset_file, decoded_texture, stage_key, timed, Asset, Db, SourceFile};
use crate::diagnostic::Diagnostic;
use crate::kinds::mesh_queries::loaded_mesh;
use crate::texture::{SurfaceKind, Texture};

/// Bounds the reduced levels' map memos to the `surfaces` used last (see `queries::keep_memos`).
pub(crate) fn keep_memos(db: &mut dyn Db, surfaces: usize) {
    reduced_maps::set_lru_capacity(db, surfaces);
    packed_map_levels::set_lru_capacity(db, surfaces);
}

/// The materials a reduced level draws and the sizes of their maps (`reduced::allot_maps`): each
/// at most the level's largest side, an `Auto` candidate's as large as its bytes allow beside
/// its mesh. Read from the maps' headers, not their texels.
#[salsa::tracked(returns(clone), lru = 0)]
pub(crate) fn reduced_maps(
    db: &dyn Db,
    asset: Asset,
    level: u32,
) -> Result<Arc<crate::reduced::ReducedMaps>, Diagnostic> {
    use crate::reduced::{allot_maps, material_folders, material_surfaces, surface_sources, MapSizing};
    let loaded = loaded_mesh(db, asset)?;
    let reduced = reduced_level(db, asset, level)?;
    let mut used = reduced.geometry.triangle_materials.clone();
    used.sort_unstable();
    used.dedup();
    used.retain(|&material| (material as usize) < loaded.mesh.materials.len());
    let materials: Vec<&crate::mesh::MeshMaterial> =
        used.iter().map(|&material| &loaded.mesh.materials[material as usize]).collect();
    let names: Vec<&str> = materials.iter().map(|material| material.name.as_str()).collect();
    let folders = material_folders(&names);
    let limits = crate::db::texture_limits(db);
    let mut sizes = Vec::new();
    for material in &materials {
        let mut surfaces = Vec::new();
        for surface in material_surfaces(material).into_iter().filter(|_| loaded.mesh.uvs.is_some()) {
            let (mut width, mut height) = (0, 0);
            for path in surface_sources(material, surface).into_iter().flatten() {
                let Some(file) = asset_file(db, asset, path.clone()) else { continue };
                let contents = crate::db::read_contents(db, file)?;
                let (w, h) = crate::texture::probe_texture(path, &contents.bytes()?, limits)?;
                (width, height) = (width.max(w), height.max(h));
            }
            if width > 0 {
                surfaces.push((surface, (width, height)));
            }
        }
        sizes.push(surfaces);
    }
    let settings = level_settings(db, asset, level);
    // An `Auto` candidate's maps share its bytes with its mesh (its glTF buffer, which holds
    // tangents when a map is a normal map).
    let bytes = settings.max_bytes.map(|max_bytes| {
        let normal_mapped = sizes.iter().flatten().any(|(surface, _)| *surface == SurfaceKind::Normal);
        max_bytes.saturating_sub(reduced.geometry.buffer_bytes(normal_mapped))
    });
    let encode = &asset.settings(db).encode;
    let bytes_of = |surface: SurfaceKind, width: u32, height: u32| {
        crate::texture::encode::gpu_bytes(width, height, Some(encode.format_of(surface)))
    };
    let sizing = MapSizing { surfaces: &sizes, max_side: settings.max_atlas_size, bytes };
    let (side, halvings) = allot_maps(&sizing, bytes_of);
    let materials = used
        .iter()
        .zip(folders)
        .zip(halvings)
        .map(|((&material, folder), surfaces)| crate::reduced::MaterialMaps { material, folder, surfaces })
        .collect();
    Ok(Arc::new(crate::reduced::ReducedMaps { materials, side }))
}

/// The source mesh's materials: equal after an edit of its geometry alone, so that a reduced
/// level's maps, which read them, are not made again for it.
#[salsa::tracked(returns(clone))]
pub(crate) fn source_materials(db: &dyn Db, asset: Asset) -> Result<Arc<Vec<crate::mesh::MeshMaterial>>, Diagnostic> {
    Ok(Arc::new(loaded_mesh(db, asset)?.mesh.materials.clone()))
}

/// The source maps a reduced level's map surface `surface` of material `material` is packed
/// from, and the constants where one is missing.
fn map_recipe(
    db: &dyn Db,
    asset: Asset,
    material: &crate::mesh::MeshMaterial,
    surface: SurfaceKind,
) -> (Vec<Option<SourceFile>>, crate::texture::channel_packing::PackConstants) {
    let sources = crate::reduced::surface_sources(material, surface)
        .into_iter()
        .map(|path| path.and_then(|path| asset_file(db, asset, path.clone())))
        .collect();
    // The MTL's `Kd` and `d` stay factors over the albedo; metallic and roughness are packed.
    let constants = crate::texture::channel_packing::PackConstants {
        albedo: [1.0; 4],
        metallic: material.metallic,
        roughness: material.roughness,
        ao: 1.0,
    };
    (sources, constants)
}

/// What a reduced level's map surface is made of: the stage's version, the surface, its
/// halvings, the constants and each source map's content.
pub(crate) fn reduced_map_key(
    db: &dyn Db,
    asset: Asset,
    (material, halvings): (u32, u32),
    surface: SurfaceKind,
) -> Result<CacheKey, Diagnostic> {
    let materials = source_materials(db, asset)?;
    let (sources, constants) = map_recipe(db, asset, &materials[material as usize], surface);
    let mut key = stage_key(MAPS).part(&surface).part(&halvings).part(&constants.albedo).part(&constants.metallic);
    key = key.part(&constants.roughness).part(&map_alpha_cutoff(db, asset, surface));
    for source in sources {
        key = match source {
            Some(file) => key.part(&crate::db::read_contents(db, file)?.hash),
            None => key.part("none"),
        };
    }
    Ok(key.finish())
}

/// A reduced level's map surface (stage `maps`): material `material`'s source maps packed as
/// `surface`, stored `halvings` levels down its mip chain (from [`packed_map_levels`], shared by
/// every reduced level and candidate that stores it smaller).
pub(crate) fn reduced_map_image(
    db: &dyn Db,
    asset: Asset,
    (material, halvings): (u32, u32),
    surface: &crate::kinds::SurfaceId,
) -> Result<Arc<Texture>, Diagnostic> {
    let label = surface.label(asset.name(db));
    let levels = match halvings {
        0 => Arc::new(Vec::new()),
        _ => packed_map_levels(db, asset, material, surface.surface)?,
    };
    // A map smaller than 2^halvings a side stops at its 1 × 1 level, as its chain does.
    match levels.get((halvings as usize).saturating_sub(1)).or(levels.last()) {
        Some(level) => timed(db, MAPS, &label, || Ok(level.clone())),
        None => {
            let sources = map_sources(db, asset, material, surface.surface)?;
            timed(db, MAPS, &label, || Ok(Arc::new(packed_map(surface.surface, &sources))))
        }
    }
}

/// Every level below level 0 of the mip chain of material `material`'s source maps packed as
/// `surface` ([`packed_map`]; `mips::mip_chain`, whose level `k` is `mips::reduced_level`'s at
/// `k` halvings): packed and filtered once for every reduced level and candidate of a chain that
/// stores the map smaller than its sources (the bundled bush's four-level chain packed each of
/// its four maps three times). Level 0 is not kept: the levels below it hold a third of its
/// texels.
#[salsa::tracked(returns(clone), lru = 0)]
pub(crate) fn packed_map_levels(
    db: &dyn Db,
    asset: Asset,
    material: u32,
    surface: SurfaceKind,
) -> Result<Arc<Vec<Arc<Texture>>>, Diagnostic> {
    let material_name = &source_materials(db, asset)?[material as usize].name;
    let label = format!("{}/materials/{material_name}/{}", asset.name(db), surface.name());
    let sources = map_sources(db, asset, material, surface)?;
    let alpha_cutoff = map_alpha_cutoff(db, asset, surface);
    timed(db, PACK, &label, || {
        let settings = crate::texture::mips::MipSettings { kind: surface, alpha_cutoff };
        let chain = crate::texture::mips::mip_chain(&packed_map(surface, &sources), settings);
        Ok(Arc::new(chain.into_iter().skip(1).map(Arc::new).collect()))
    })
}

/// The packing and mip chain behind the reduced levels' maps stored smaller than their sources
/// ([`packed_map_levels`]), once per material and surface: a stage of its own for the log and
/// the stage times, never cached on its own (each level's map is, under `maps`).
const PACK: crate::db::Stage = crate::db::Stage { name: "pack", version: 1 };

/// The decoded source maps a map surface is packed from, and the constants where one is missing.
type MapSources = (Vec<Option<Arc<Texture>>>, crate::texture::channel_packing::PackConstants);

/// Material `material`'s source maps that `surface` is packed from ([`map_recipe`]), decoded.
fn map_sources(db: &dyn Db, asset: Asset, material: u32, surface: SurfaceKind) -> Result<MapSources, Diagnostic> {
    let materials = source_materials(db, asset)?;
    let (sources, constants) = map_recipe(db, asset, &materials[material as usize], surface);
    // The opacity's channel is taken by the packing.
    let decoded = sources.into_iter().map(|source| source.map(|file| decoded_texture(db, file)).transpose());
    Ok((decoded.collect::<Result<Vec<_>, _>>()?, constants))
}

/// `sources` packed as `surface` (`texture::channel_packing`).
fn packed_map(surface: SurfaceKind, (sources, constants): &MapSources) -> Texture {
    let sources: Vec<Option<&Texture>> = sources.iter().map(|texture| texture.as_deref()).collect();
    crate::texture::channel_packing::pack_surface(surface, &sources, constants)
}

/// The alpha test a reduced level's map surface keeps its coverage for when it is stored smaller
/// than its sources (an albedo's: the cards' leaves would thin out level by level without it).
fn map_alpha_cutoff(db: &dyn Db, asset: Asset, surface: SurfaceKind) -> Option<f32> {
    (surface == SurfaceKind::Albedo).then(|| billboard_alpha_cutoff(db, asset))
}
