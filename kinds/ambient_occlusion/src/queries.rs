//! The AmbientOcclusion kind's tracked functions: thin glue between the database and the pure
//! bake (`bake`, `mesh::occlusion`). The mesh is the shared mesh stage; the occluders' BVHs are
//! built once per mesh; each UV tile of each material is a stage instance keyed by what it
//! reads (its own triangles, and with a finite `max_distance` the occluders within reach), so
//! an edit re-bakes only the tiles it can change; each material's map is put together from its
//! tiles, filled, and sent through the shared texture tail.

use std::sync::Arc;

use glam::Vec3;

use super::bake::{
    assemble_map, bake_tile_from_vertices, bake_tile_with_rays, map_png16, material_tiles, occluders_within_reach,
    tile_triangles, triangle_boxes, AoMap, BakeMesh, TileBake, TileId,
};
use super::settings::{AoMode, AoOccluders, AoSettings};
use crate::cache::{CacheEntry, CacheKey};
use crate::db::{
    from_pod_blob, hash_of_parts, load_cached, pod_blob, recall, record_cache_hit, remember, stage_key, stoppable,
    store_cached, timed, Asset, ByHash, Db, Stage,
};
use crate::diagnostic::Diagnostic;
use crate::kinds::mesh_queries::{loaded_mesh, LoadedMesh};
use crate::mesh::occlusion::{build_occluders, occlusion_of_vertices, Occluders, OcclusionSettings};
use crate::mesh::rays::BackFaces;
use crate::mesh::uv_raster::TexelRegion;
use crate::settings::Settings as Own;

pub const BVH: Stage = Stage { name: "bvh", version: 1 };
pub(crate) const VERTICES: Stage = Stage { name: "vertices", version: 1 };
pub(crate) const BAKE: Stage = Stage { name: "bake", version: 1 };
pub(crate) const FILL: Stage = Stage { name: "fill", version: 1 };

/// One material of the mesh that is baked: its index, the folder its map is written to, and
/// its triangles (ascending).
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct BakedMaterial {
    pub index: u32,
    pub name: String,
    /// `name` made safe as one folder name, unique in the asset.
    pub folder: String,
    pub triangles: Vec<u32>,
}

/// The mesh as the bake reads it, with the settings resolved against its size.
#[derive(Debug, PartialEq)]
pub(crate) struct BakeGeometry {
    pub loaded: Arc<LoadedMesh>,
    pub materials: Vec<BakedMaterial>,
    pub boxes: Vec<[Vec3; 2]>,
    /// The rays' settings: `max_distance` in mesh units, the ground plane at the lowest Y.
    pub occlusion: OcclusionSettings,
    /// How far a vertex's rays start off its surface (per-vertex mode), in mesh units.
    pub vertex_offset: f32,
    /// Each triangle's occluder group when objects occlude only themselves.
    pub groups: Option<Vec<u32>>,
    /// The hash of every position, normal, UV, triangle and group: what a bake with an
    /// unbounded reach reads.
    pub whole_hash: blake3::Hash,
}

impl BakeGeometry {
    pub fn bake_mesh(&self) -> BakeMesh<'_> {
        let mesh = &self.loaded.mesh;
        BakeMesh {
            positions: &mesh.positions,
            normals: &mesh.normals,
            uvs: mesh.uvs.as_deref().unwrap_or(&[]),
            triangles: &mesh.triangles,
            groups: self.groups.as_deref(),
        }
    }

    pub fn material(&self, index: u32) -> Option<&BakedMaterial> {
        self.materials.iter().find(|material| material.index == index)
    }
}

/// A material name made into one safe folder name (letters, digits, `_`, `-`, `.`; never `.` or
/// `..`), made unique among `taken`.
fn material_folder(name: &str, taken: &[String]) -> String {
    let mut folder: String =
        name.chars().map(|c| if c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.') { c } else { '_' }).collect();
    if folder.is_empty() || folder.chars().all(|c| c == '.') {
        folder = format!("material{}", folder.len());
    }
    let mut unique = folder.clone();
    let mut counter = 2;
    while taken.iter().any(|other| other.eq_ignore_ascii_case(&unique)) {
        unique = format!("{folder}_{counter}");
        counter += 1;
    }
    unique
}

#[salsa::tracked(returns(clone))]
pub fn ao_settings(db: &dyn Db, asset: Asset) -> AoSettings {
    asset.settings(db).own::<Own>().ao.clone()
}

/// Each triangle's occluder group (its OBJ object) when objects occlude only themselves and
/// there are several; none when every triangle occludes every point.
#[salsa::tracked(returns(clone))]
pub(crate) fn occluder_groups(db: &dyn Db, asset: Asset) -> Result<Option<Arc<Vec<u32>>>, Diagnostic> {
    let loaded = loaded_mesh(db, asset)?;
    let mesh = &loaded.mesh;
    let self_only = ao_settings(db, asset).occluders == AoOccluders::SelfOnly;
    Ok((self_only && mesh.objects.len() > 1).then(|| Arc::new(mesh.triangle_objects.clone())))
}

/// The mesh and settings of the bake: a mesh without texture coordinates is an error naming it.
#[salsa::tracked(returns(clone))]
pub(crate) fn bake_geometry(db: &dyn Db, asset: Asset) -> Result<Arc<BakeGeometry>, Diagnostic> {
    let loaded = loaded_mesh(db, asset)?;
    let settings = ao_settings(db, asset);
    let mesh = &loaded.mesh;
    let path = asset.main_file(db);
    let Some(uvs) = &mesh.uvs else {
        return Err(Diagnostic::new(
            path,
            "the mesh has no texture coordinates: an AO bake needs a UV layout (`vt` in the OBJ)",
        ));
    };
    let mut materials: Vec<BakedMaterial> = Vec::new();
    for (index, material) in mesh.materials.iter().enumerate() {
        if material.name.ends_with(crate::mesh::WITHOUT_UVS_SUFFIX) {
            continue;
        }
        let triangles: Vec<u32> = (0..mesh.triangles.len() as u32)
            .filter(|&triangle| mesh.triangle_materials[triangle as usize] == index as u32)
            .collect();
        if triangles.is_empty() {
            continue;
        }
        let taken: Vec<String> = materials.iter().map(|material| material.folder.clone()).collect();
        let folder = material_folder(&material.name, &taken);
        materials.push(BakedMaterial { index: index as u32, name: material.name.clone(), folder, triangles });
    }
    let boxes = triangle_boxes(&mesh.positions, &mesh.triangles);
    let (low, high) =
        boxes.iter().fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(low, high), [a, b]| (low.min(*a), high.max(*b)));
    let diagonal = (high - low).length().max(f32::MIN_POSITIVE);
    let occlusion = OcclusionSettings {
        rays: settings.rays,
        distribution: settings.distribution,
        max_distance: settings.max_distance.map_or(f32::INFINITY, |fraction| fraction * diagonal),
        back_faces: if settings.ignore_backfaces { BackFaces::PassThrough } else { BackFaces::Block },
        ground_plane: settings.ground_plane.then_some(low.y),
    };
    let groups = occluder_groups(db, asset)?.as_deref().cloned();
    if let Some(warning) = super::bake::long_bake_warning(path, mesh, &settings, crate::schedule::cores()) {
        tracing::warn!("{warning}");
    }
    let whole_hash = hash_of_parts(&[
        bytemuck::cast_slice(&mesh.positions),
        bytemuck::cast_slice(&mesh.normals),
        bytemuck::cast_slice(uvs),
        bytemuck::cast_slice(&mesh.triangles),
        groups.as_deref().map_or(&[][..], bytemuck::cast_slice),
    ]);
    Ok(Arc::new(BakeGeometry {
        loaded: loaded.clone(),
        materials,
        boxes,
        occlusion,
        vertex_offset: diagonal * 1e-4,
        groups,
        whole_hash,
    }))
}

/// The occluders' BVHs, compared by the geometry they were built from.
pub(crate) type OccluderSet = ByHash<Occluders>;

/// The BVHs the rays are cast against (stage `bvh`): built only when some tile must bake, from
/// the positions and the groups alone (a settings change builds nothing).
#[salsa::tracked(returns(clone))]
pub(crate) fn occluder_set(db: &dyn Db, asset: Asset) -> Result<Arc<OccluderSet>, Diagnostic> {
    let loaded = loaded_mesh(db, asset)?;
    let groups = occluder_groups(db, asset)?;
    let mesh = &loaded.mesh;
    let mut hasher = blake3::Hasher::new();
    hasher.update(bytemuck::cast_slice(&mesh.positions));
    hasher.update(bytemuck::cast_slice(&mesh.triangles));
    hasher.update(bytemuck::cast_slice(groups.as_deref().map_or(&[][..], |groups| &groups[..])));
    let occluders = timed(db, BVH, asset.name(db), || {
        build_occluders(&mesh.positions, &mesh.triangles, groups.as_deref().map(|groups| &groups[..]))
    });
    Ok(Arc::new(OccluderSet { hash: hasher.finalize(), value: occluders }))
}

/// The occlusion settings' parts of a key.
fn occlusion_key(key: crate::cache::CacheKeyBuilder, settings: &OcclusionSettings) -> crate::cache::CacheKeyBuilder {
    let distribution = match settings.distribution {
        crate::mesh::occlusion::RayDistribution::Cosine => "Cosine",
        crate::mesh::occlusion::RayDistribution::Uniform => "Uniform",
    };
    key.part(&settings.rays)
        .part(distribution)
        .part(&settings.max_distance)
        .part(&(settings.back_faces == BackFaces::PassThrough))
        .part(&settings.ground_plane)
}

/// Per-vertex visibility (stage `vertices`, per-vertex mode): rays from every vertex, cached
/// by the whole mesh and the settings.
#[derive(Debug, PartialEq)]
pub(crate) struct VertexVisibility(pub Vec<f32>);

#[salsa::tracked(returns(clone))]
pub(crate) fn vertex_visibility(db: &dyn Db, asset: Asset) -> Result<Arc<VertexVisibility>, Diagnostic> {
    let geometry = bake_geometry(db, asset)?;
    let key = occlusion_key(stage_key(VERTICES).part(&geometry.whole_hash), &geometry.occlusion)
        .part(&geometry.vertex_offset)
        .finish();
    let name = asset.name(db);
    if let Some(values) =
        load_cached(db, VERTICES.name, key, |entry| from_pod_blob::<f32>(&entry.into_blobs::<1>()?[0]))
    {
        record_cache_hit(db, VERTICES, name);
        return Ok(Arc::new(VertexVisibility(values)));
    }
    let occluders = occluder_set(db, asset)?;
    let mesh = &geometry.loaded.mesh;
    let values: Vec<f32> = timed(db, VERTICES, name, || {
        stoppable(db, |should_stop| {
            occlusion_of_vertices(
                &occluders.value,
                &mesh.positions,
                &mesh.normals,
                &mesh.triangles,
                geometry.vertex_offset,
                crate::mesh::occlusion::Casting { settings: &geometry.occlusion, should_stop },
            )
        })
        .into_iter()
        .map(|occlusion| occlusion.map_or(1.0, |occlusion| occlusion.visibility))
        .collect()
    });
    store_cached(db, VERTICES.name, key, || CacheEntry::of_blobs(vec![pod_blob(&values)], true));
    Ok(Arc::new(VertexVisibility(values)))
}

/// The materials' tiles, in material then row order.
#[salsa::tracked(returns(clone))]
pub(crate) fn all_tiles(db: &dyn Db, asset: Asset) -> Result<Arc<Vec<TileId>>, Diagnostic> {
    let geometry = bake_geometry(db, asset)?;
    let size = ao_settings(db, asset).size;
    Ok(Arc::new(geometry.materials.iter().flat_map(|material| material_tiles(material.index, size)).collect()))
}

/// A tile's stage label: `asset/material/tile_c_r`.
pub(crate) fn tile_label(asset_name: &str, folder: &str, tile: TileId) -> String {
    format!("{asset_name}/{folder}/{}", tile.name())
}

/// A material's stage label: `asset/material`.
pub(crate) fn material_label(asset_name: &str, folder: &str) -> String {
    format!("{asset_name}/{folder}")
}

fn material_of<'a>(
    geometry: &'a BakeGeometry,
    path: &std::path::Path,
    material: u32,
) -> Result<&'a BakedMaterial, Diagnostic> {
    geometry.material(material).ok_or_else(|| Diagnostic::new(path, format!("no baked material {material}")))
}

/// What a tile reads, as a key (cheap: no rays): the map size, the tile, the mode's settings,
/// its own triangles' UVs, positions and normals, and the occluders it can reach (all of them,
/// as one hash, when the reach is unbounded) or, per vertex, its corners' visibility.
#[salsa::tracked(returns(clone))]
pub(crate) fn tile_key(db: &dyn Db, asset: Asset, tile: TileId) -> Result<CacheKey, Diagnostic> {
    let geometry = bake_geometry(db, asset)?;
    let settings = ao_settings(db, asset);
    let material = material_of(&geometry, asset.main_file(db), tile.material)?;
    let mesh = geometry.bake_mesh();
    let region = tile.region(settings.size);
    let own = tile_triangles(&mesh, &material.triangles, settings.size, region);
    let mut hasher = blake3::Hasher::new();
    for &triangle in &own {
        for vertex in mesh.triangles[triangle as usize] {
            let vertex = vertex as usize;
            hasher.update(bytemuck::cast_slice(&mesh.uvs[vertex]));
            hasher.update(bytemuck::cast_slice(&mesh.positions[vertex]));
            hasher.update(bytemuck::cast_slice(&mesh.normals[vertex]));
        }
    }
    let mode = match settings.mode {
        AoMode::Texels => "Texels",
        AoMode::Vertices => "Vertices",
    };
    let key = stage_key(BAKE).part(&settings.size).part(&[region.x, region.y, region.width, region.height]).part(mode);
    let key = match settings.mode {
        AoMode::Texels => {
            let key = occlusion_key(key, &geometry.occlusion).part(&hasher.finalize());
            if geometry.occlusion.max_distance.is_finite() {
                let mut occluders = blake3::Hasher::new();
                for triangle in occluders_within_reach(&mesh, &geometry.boxes, &own, geometry.occlusion.max_distance) {
                    let group = mesh.groups.map_or(0, |groups| groups[triangle as usize]);
                    occluders.update(&group.to_le_bytes());
                    for vertex in mesh.triangles[triangle as usize] {
                        occluders.update(bytemuck::cast_slice(&mesh.positions[vertex as usize]));
                    }
                }
                key.part("within reach").part(&occluders.finalize())
            } else {
                key.part("whole mesh").part(&geometry.whole_hash)
            }
        }
        AoMode::Vertices => {
            let visibility = vertex_visibility(db, asset)?;
            for &triangle in &own {
                for vertex in mesh.triangles[triangle as usize] {
                    hasher.update(&visibility.0[vertex as usize].to_le_bytes());
                }
            }
            key.part(&hasher.finalize())
        }
    };
    Ok(key.finish())
}

const TILE_ENTRY: &str = "ao-tile";

/// What a tile entry holds beside its values and states.
#[derive(serde::Serialize, serde::Deserialize)]
struct TileEntry {
    /// x, y, width, height.
    region: [u32; 4],
    overlapping: u32,
    rays: u64,
    bake_ms: f64,
}

fn tile_entry(tile: &TileBake) -> CacheEntry {
    let region = tile.region;
    let metadata = TileEntry {
        region: [region.x, region.y, region.width, region.height],
        overlapping: tile.overlapping,
        rays: tile.rays,
        bake_ms: tile.bake_ms,
    };
    CacheEntry::new(&metadata, vec![pod_blob(&tile.values), tile.states.clone()], true)
}

fn tile_from_entry(entry: CacheEntry) -> Option<TileBake> {
    let (metadata, [values, states]) = entry.parts::<TileEntry, 2>()?;
    let region = metadata.region;
    let region = TexelRegion { x: region[0], y: region[1], width: region[2], height: region[3] };
    let values: Vec<u16> = from_pod_blob(&values)?;
    let texels = region.width as usize * region.height as usize;
    (values.len() == texels && states.len() == texels).then_some(())?;
    Some(TileBake {
        region,
        values,
        states,
        overlapping: metadata.overlapping,
        rays: metadata.rays,
        bake_ms: metadata.bake_ms,
    })
}

/// One tile baked (stage `bake`): the last bake of the tile when its key is unchanged (an edit
/// out of its reach), else from the persistent cache, else rays (or per-vertex values).
#[salsa::tracked(returns(clone))]
pub(crate) fn ao_tile(db: &dyn Db, asset: Asset, tile: TileId) -> Result<Arc<TileBake>, Diagnostic> {
    let key = tile_key(db, asset, tile)?;
    let geometry = bake_geometry(db, asset)?;
    let material = material_of(&geometry, asset.main_file(db), tile.material)?;
    let label = tile_label(asset.name(db), &material.folder, tile);
    let memo_name = crate::db::Memo::<(CacheKey, Arc<TileBake>)>::new("ao-tile", &label);
    if let Some(memo) = recall(db, &memo_name).filter(|memo| memo.0 == key) {
        return Ok(memo.1.clone());
    }
    let bake = match load_cached(db, TILE_ENTRY, key, tile_from_entry) {
        Some(bake) => {
            record_cache_hit(db, BAKE, &label);
            Arc::new(bake)
        }
        None => {
            let settings = ao_settings(db, asset);
            let mesh = geometry.bake_mesh();
            let region = tile.region(settings.size);
            let own = tile_triangles(&mesh, &material.triangles, settings.size, region);
            let bake = match settings.mode {
                AoMode::Texels => {
                    let occluders = occluder_set(db, asset)?;
                    timed(db, BAKE, &label, || {
                        stoppable(db, |should_stop| {
                            bake_tile_with_rays(
                                &occluders.value,
                                &mesh,
                                &own,
                                settings.size,
                                region,
                                &geometry.occlusion,
                                should_stop,
                            )
                        })
                    })
                }
                AoMode::Vertices => {
                    let visibility = vertex_visibility(db, asset)?;
                    timed(db, BAKE, &label, || {
                        bake_tile_from_vertices(&mesh, &own, settings.size, region, &visibility.0)
                    })
                }
            };
            store_cached(db, TILE_ENTRY, key, || tile_entry(&bake));
            Arc::new(bake)
        }
    };
    remember(db, &memo_name, Arc::new((key, bake.clone())));
    Ok(bake)
}

/// What a material's map is made of: the fill's version, the map size and every tile's key.
#[salsa::tracked(returns(clone))]
pub(crate) fn ao_map_key(db: &dyn Db, asset: Asset, material: u32) -> Result<CacheKey, Diagnostic> {
    let size = ao_settings(db, asset).size;
    let mut key = stage_key(FILL).part(&size);
    for tile in material_tiles(material, size) {
        key = key.part(&tile_key(db, asset, tile)?.0);
    }
    Ok(key.finish())
}

/// A material's finished map and its 16-bit PNG.
#[derive(Debug, PartialEq)]
pub(crate) struct AoMapFiles {
    pub map: AoMap,
    pub png16: Arc<[u8]>,
}

const MAP_ENTRY: &str = "ao-map";

/// A material's map (stage `fill`): its tiles put together and filled, and the 16-bit PNG.
#[salsa::tracked(returns(clone))]
pub fn ao_map(db: &dyn Db, asset: Asset, material: u32) -> Result<Arc<AoMapFiles>, Diagnostic> {
    let key = ao_map_key(db, asset, material)?;
    let geometry = bake_geometry(db, asset)?;
    let label = material_label(asset.name(db), &material_of(&geometry, asset.main_file(db), material)?.folder);
    if let Some(files) = load_cached(db, MAP_ENTRY, key, map_from_entry) {
        record_cache_hit(db, FILL, &label);
        return Ok(Arc::new(files));
    }
    let size = ao_settings(db, asset).size;
    let tiles = material_tiles(material, size)
        .into_iter()
        .map(|tile| ao_tile(db, asset, tile))
        .collect::<Result<Vec<_>, _>>()?;
    let files = timed(db, FILL, &label, || {
        let map = assemble_map(size, &tiles.iter().map(|tile| &**tile).collect::<Vec<_>>());
        let png16 = map_png16(&map).into();
        AoMapFiles { map, png16 }
    });
    store_cached(db, MAP_ENTRY, key, || map_entry(&files));
    Ok(Arc::new(files))
}

/// What a map entry holds beside its values and 16-bit PNG.
#[derive(serde::Serialize, serde::Deserialize)]
struct MapEntry {
    size: u32,
    baked_texels: u64,
    invalid_texels: u64,
    overlapping_texels: u64,
    rays: u64,
    bake_ms: f64,
}

fn map_entry(files: &AoMapFiles) -> CacheEntry {
    let map = &files.map;
    let metadata = MapEntry {
        size: map.size,
        baked_texels: map.baked_texels,
        invalid_texels: map.invalid_texels,
        overlapping_texels: map.overlapping_texels,
        rays: map.rays,
        bake_ms: map.bake_ms,
    };
    CacheEntry::new(&metadata, vec![pod_blob(&map.values), files.png16.to_vec()], true)
}

fn map_from_entry(entry: CacheEntry) -> Option<AoMapFiles> {
    let (metadata, [values, png16]) = entry.parts::<MapEntry, 2>()?;
    let size = metadata.size;
    let values: Vec<u16> = from_pod_blob(&values)?;
    (values.len() == size as usize * size as usize).then_some(())?;
    let map = AoMap {
        size,
        values,
        baked_texels: metadata.baked_texels,
        invalid_texels: metadata.invalid_texels,
        overlapping_texels: metadata.overlapping_texels,
        rays: metadata.rays,
        bake_ms: metadata.bake_ms,
    };
    Some(AoMapFiles { map, png16: png16.into() })
}
