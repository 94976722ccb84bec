//! The Height kind's tracked functions: thin glue between the database and the pure parts
//! (`bake`, `mesh::pn_triangles`, `mesh::surface_distance`, `gpu::top_down_render`). Both meshes
//! come from the shared mesh stage; the high mesh's BVH is built once; each map (measured from
//! the low surface, and for a displaced tessellation from the PN surface) is one stage kept in
//! the persistent cache by what it reads; the tessellation reads only the low mesh and
//! `level`; the displaced mesh and the distances are cached by the keys of what they read.

use std::path::PathBuf;
use std::sync::Arc;

use glam::Vec3;

use super::bake::{bake_along_normals, bake_top_down, HeightMap, LowSurface, RayReach, RayStart};
use super::settings::{HeightProjection, HeightSettings, TessellateSettings};
use crate::cache::{CacheEntry, CacheKey};
use crate::db::{
    from_pod_blob, hash_of_parts, load_cached, pod_blob, record_cache_hit, stage_key, store_cached, timed, Asset,
    ByHash, Db, Stage,
};
use crate::diagnostic::Diagnostic;
use crate::kinds::mesh_queries::{loaded_mesh, loaded_mesh_of, LoadedMesh};
use crate::kinds::mesh_queries::{written_mesh_entry, written_mesh_from_entry};
use crate::mesh::pn_triangles::{averaged_normals, pn_patch, tessellate, PnInput, PnMesh, PnPatch};
use crate::mesh::rays::{build_triangle_bvh, TriangleBvh};
use crate::mesh::surface_distance::{area_weighted_samples, surface_distance, SurfaceDistance};
use crate::settings::Settings as Own;

pub const BVH: Stage = Stage { name: "bvh", version: 1 };
/// 2: a flat map (heights within 1e-4 of the search) centred, its noise not stretched.
pub(crate) const BAKE: Stage = Stage { name: "bake", version: 2 };
pub(crate) const TESSELLATE: Stage = Stage { name: "tessellate", version: 1 };
/// 2: its cache entry holds the glTF geometry, MikkTSpace tangents included.
pub(crate) const DISPLACE: Stage = Stage { name: "displace", version: 2 };
pub(crate) const DISTANCE: Stage = Stage { name: "distance", version: 1 };

/// Points sampled on each surface for the distances, each way.
pub(crate) const DISTANCE_SAMPLES: usize = 100_000;

/// Which surface a map's rays leave from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub(crate) enum MapReference {
    /// The low mesh (`height.png`).
    Low,
    /// The low mesh's PN surface (`height_pn.png`, what the tessellation is displaced by).
    Pn,
}

/// Which mesh a distance to the high mesh is measured for.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Measured {
    Low,
    Pn,
    Displaced,
}

impl Measured {
    pub fn name(self) -> &'static str {
        match self {
            Measured::Low => "low",
            Measured::Pn => "pn",
            Measured::Displaced => "displaced",
        }
    }
}

/// A map's stage label: the asset's name for the low map, `asset/pn` for the PN one.
pub(crate) fn map_label(asset_name: &str, reference: MapReference) -> String {
    match reference {
        MapReference::Low => asset_name.to_string(),
        MapReference::Pn => format!("{asset_name}/pn"),
    }
}

#[salsa::tracked(returns(clone))]
pub(crate) fn height_settings(db: &dyn Db, asset: Asset) -> HeightSettings {
    asset.settings(db).own::<Own>().height.clone()
}

#[salsa::tracked(returns(clone))]
pub(crate) fn tessellate_settings(db: &dyn Db, asset: Asset) -> Option<TessellateSettings> {
    asset.settings(db).own::<Own>().tessellate
}

/// The high mesh's project-relative path (the settings hold it relative to the source folder).
pub(crate) fn high_path(db: &dyn Db, asset: Asset) -> PathBuf {
    asset.source_root(db).join(&asset.settings(db).own::<Own>().high_mesh)
}

/// A mesh with the hash of its geometry and its bounding-box diagonal.
#[derive(Debug, PartialEq)]
pub(crate) struct MeshGeometry {
    pub loaded: Arc<LoadedMesh>,
    /// blake3 of positions, normals, UVs and triangles.
    pub hash: blake3::Hash,
    pub diagonal: f32,
    /// The triangles whose UVs a map covers (materials that have UVs), ascending.
    pub baked: Vec<u32>,
}

fn mesh_geometry(
    loaded: Arc<LoadedMesh>,
    path: &std::path::Path,
    which: &str,
) -> Result<Arc<MeshGeometry>, Diagnostic> {
    let mesh = &loaded.mesh;
    if mesh.triangles.is_empty() {
        return Err(Diagnostic::new(path, format!("the {which} mesh has no triangles")));
    }
    let hash = hash_of_parts(&[
        bytemuck::cast_slice(&mesh.positions),
        bytemuck::cast_slice(&mesh.normals),
        mesh.uvs.as_deref().map_or(&[][..], bytemuck::cast_slice),
        bytemuck::cast_slice(&mesh.triangles),
    ]);
    let (low, high) =
        mesh.triangles.iter().flatten().fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(low, high), &vertex| {
            let position = Vec3::from(mesh.positions[vertex as usize]);
            if position.is_finite() {
                (low.min(position), high.max(position))
            } else {
                (low, high)
            }
        });
    let diagonal = (high - low).length();
    if !(diagonal.is_finite() && diagonal > 0.0) {
        return Err(Diagnostic::new(path, format!("the {which} mesh has no extent (all its vertices at one point)")));
    }
    let baked = (0..mesh.triangles.len() as u32)
        .filter(|&triangle| {
            let material = &mesh.materials[mesh.triangle_materials[triangle as usize] as usize];
            !material.name.ends_with(crate::mesh::WITHOUT_UVS_SUFFIX)
        })
        .collect();
    Ok(Arc::new(MeshGeometry { loaded, hash, diagonal, baked }))
}

#[salsa::tracked(returns(clone))]
pub(crate) fn low_geometry(db: &dyn Db, asset: Asset) -> Result<Arc<MeshGeometry>, Diagnostic> {
    mesh_geometry(loaded_mesh(db, asset)?, asset.main_file(db), "low")
}

#[salsa::tracked(returns(clone))]
pub(crate) fn high_geometry(db: &dyn Db, asset: Asset) -> Result<Arc<MeshGeometry>, Diagnostic> {
    let path = high_path(db, asset);
    mesh_geometry(loaded_mesh_of(db, asset, path.clone())?, &path, "high")
}

/// A BVH compared by the geometry it was built from.
pub(crate) type HashedBvh = ByHash<TriangleBvh>;

/// The high mesh's BVH (stage `bvh`): built only when a map or a distance must be computed.
#[salsa::tracked(returns(clone))]
pub(crate) fn high_bvh(db: &dyn Db, asset: Asset) -> Result<Arc<HashedBvh>, Diagnostic> {
    let high = high_geometry(db, asset)?;
    let mesh = &high.loaded.mesh;
    let bvh = timed(db, BVH, asset.name(db), || build_triangle_bvh(&mesh.positions, &mesh.triangles));
    Ok(Arc::new(HashedBvh { hash: high.hash, value: bvh }))
}

/// The low mesh's PN patches, each from its corners' averaged normals (the geometry's).
pub(crate) fn pn_patches(low: &MeshGeometry) -> Vec<PnPatch> {
    let mesh = &low.loaded.mesh;
    let input = PnInput { positions: &mesh.positions, normals: &mesh.normals, uvs: None, triangles: &mesh.triangles };
    let (position_ids, averaged) = averaged_normals(&input);
    mesh.triangles
        .iter()
        .map(|corners| {
            pn_patch(
                corners.map(|vertex| Vec3::from(mesh.positions[vertex as usize])),
                corners.map(|vertex| averaged[position_ids[vertex as usize] as usize]),
            )
        })
        .collect()
}

fn projection_name(projection: HeightProjection) -> &'static str {
    match projection {
        HeightProjection::Normals => "Normals",
        HeightProjection::TopDown => "TopDown",
    }
}

/// How a map is measured: the low map follows `projection`; the PN map is always along normals.
fn map_projection(settings: &HeightSettings, reference: MapReference) -> HeightProjection {
    match reference {
        MapReference::Low => settings.projection,
        MapReference::Pn => HeightProjection::Normals,
    }
}

/// What a map reads, as a key: its settings and both meshes' geometry (not their materials).
#[salsa::tracked(returns(clone))]
pub(crate) fn map_key(db: &dyn Db, asset: Asset, reference: MapReference) -> Result<CacheKey, Diagnostic> {
    let settings = height_settings(db, asset);
    let reference_name = match reference {
        MapReference::Low => "low",
        MapReference::Pn => "pn",
    };
    let projection = map_projection(&settings, reference);
    // A top-down map is rendered on the GPU: its driver family is part of what made it.
    let gpu = (projection == HeightProjection::TopDown).then(crate::gpu::adapter_family);
    Ok(stage_key(BAKE)
        .part(projection_name(projection))
        .part(&gpu.map(str::to_string))
        .part(reference_name)
        .part(&settings.size)
        .part(&settings.frontal)
        .part(&settings.rear)
        .part(&low_geometry(db, asset)?.hash)
        .part(&high_geometry(db, asset)?.hash)
        .finish())
}

/// A finished map and its 16-bit PNG.
#[derive(Debug, PartialEq)]
pub(crate) struct HeightMapFiles {
    pub map: HeightMap,
    pub png16: Arc<[u8]>,
}

const MAP_ENTRY: &str = "height-map";

/// A map (stage `bake`): from the persistent cache, else rays along the normals or two
/// top-down renders; filled, with its 16-bit PNG.
#[salsa::tracked(returns(clone))]
pub(crate) fn height_map(
    db: &dyn Db,
    asset: Asset,
    reference: MapReference,
) -> Result<Arc<HeightMapFiles>, Diagnostic> {
    let key = map_key(db, asset, reference)?;
    let label = map_label(asset.name(db), reference);
    if let Some(files) = load_cached(db, MAP_ENTRY, key, map_from_entry) {
        record_cache_hit(db, BAKE, &label);
        return Ok(Arc::new(files));
    }
    let settings = height_settings(db, asset);
    let low = low_geometry(db, asset)?;
    let high = high_geometry(db, asset)?;
    let low_path = asset.main_file(db);
    let map = match map_projection(&settings, reference) {
        HeightProjection::Normals => {
            let mesh = &low.loaded.mesh;
            let Some(uvs) = mesh.uvs.as_deref() else {
                let why = match reference {
                    MapReference::Low => "a Normals height bake needs its UV layout",
                    MapReference::Pn => "a displaced tessellation reads its height map in UV space",
                };
                return Err(Diagnostic::new(
                    low_path,
                    format!("the low mesh has no texture coordinates (`vt` in the OBJ): {why}"),
                ));
            };
            let bvh = high_bvh(db, asset)?;
            let patches = (reference == MapReference::Pn).then(|| pn_patches(&low));
            let start = patches.as_deref().map_or(RayStart::Flat, RayStart::Pn);
            let surface = LowSurface {
                positions: &mesh.positions,
                normals: &mesh.normals,
                uvs,
                triangles: &mesh.triangles,
                baked: &low.baked,
            };
            let reach = RayReach { frontal: settings.frontal * low.diagonal, rear: settings.rear * low.diagonal };
            timed(db, BAKE, &label, || {
                bake_along_normals(&bvh.value, &surface, start, settings.size, reach, low.diagonal * 1e-6)
            })
        }
        HeightProjection::TopDown => {
            let gpu = crate::gpu::gpu().map_err(|error| Diagnostic::new(low_path, error.to_string()))?;
            timed(db, BAKE, &label, || -> Result<HeightMap, Diagnostic> {
                let clock = std::time::Instant::now();
                let footprint = top_down_footprint(&low, &high);
                let render = |geometry: &MeshGeometry, path: &std::path::Path| {
                    let mesh = &geometry.loaded.mesh;
                    gpu.render_top_down(&mesh.positions, &mesh.triangles, footprint, settings.size)
                        .map_err(|error| Diagnostic::new(path, error.to_string()))
                };
                let low_heights = render(&low, low_path)?;
                let high_heights = render(&high, &high_path(db, asset))?;
                let span = footprint.high_y - footprint.low_y;
                Ok(bake_top_down(
                    settings.size,
                    &high_heights,
                    &low_heights,
                    span,
                    clock.elapsed().as_secs_f64() * 1000.0,
                ))
            })?
        }
    };
    if map.measured_texels == 0
        && map.missed_texels == 0
        && map_projection(&settings, reference) == HeightProjection::Normals
    {
        // No texel cast a ray at all: the UV layout covers none, whatever the high mesh is.
        return Err(Diagnostic::new(
            low_path,
            format!(
                "the low mesh's UVs cover no texel of the {size}² map: its triangles have no area in UV space (are its \
                 `vt` all equal?)",
                size = settings.size
            ),
        ));
    }
    if map.measured_texels == 0 {
        let message = match map_projection(&settings, reference) {
            HeightProjection::Normals => format!(
                "no ray from the low mesh met the high mesh within frontal {} and rear {} of the diagonal: do the two \
                    meshes overlap?",
                settings.frontal, settings.rear
            ),
            HeightProjection::TopDown => {
                "seen from above, the high mesh covers none of the low mesh: do the two meshes overlap?".to_string()
            }
        };
        return Err(Diagnostic::new(high_path(db, asset), message));
    }
    let png16: Arc<[u8]> = crate::texture::preview::png16_grey(&map.values16(), map.size, map.size).into();
    let files = HeightMapFiles { map, png16 };
    store_cached(db, MAP_ENTRY, key, || map_entry(&files));
    Ok(Arc::new(files))
}

/// The low mesh's XZ footprint, with the Y range of both meshes.
fn top_down_footprint(low: &MeshGeometry, high: &MeshGeometry) -> crate::gpu::top_down_render::Footprint {
    let bounds = |mesh: &crate::mesh::Mesh| {
        mesh.positions
            .iter()
            .map(|&position| Vec3::from(position))
            .filter(|position| position.is_finite())
            .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(low, high), position| (low.min(position), high.max(position)))
    };
    let (low_min, low_max) = bounds(&low.loaded.mesh);
    let (high_min, high_max) = bounds(&high.loaded.mesh);
    let (bottom, top) = (low_min.y.min(high_min.y), low_max.y.max(high_max.y));
    let margin = (top - bottom).max(low.diagonal * 1e-3) * 0.01;
    crate::gpu::top_down_render::Footprint {
        min: [low_min.x, low_min.z],
        max: [low_max.x, low_max.z],
        low_y: bottom - margin,
        high_y: top + margin,
    }
}

/// What a height map entry holds beside its distances, states and 16-bit PNG.
#[derive(serde::Serialize, serde::Deserialize)]
struct MapEntry {
    size: u32,
    range: [f32; 2],
    measured_texels: u64,
    missed_texels: u64,
    search_span: f32,
    bake_ms: f64,
}

fn map_entry(files: &HeightMapFiles) -> CacheEntry {
    let map = &files.map;
    let metadata = MapEntry {
        size: map.size,
        range: map.range,
        measured_texels: map.measured_texels,
        missed_texels: map.missed_texels,
        search_span: map.search_span,
        bake_ms: map.bake_ms,
    };
    CacheEntry::new(&metadata, vec![pod_blob(&map.distances), map.states.clone(), files.png16.to_vec()], true)
}

fn map_from_entry(entry: CacheEntry) -> Option<HeightMapFiles> {
    let (metadata, [distances, states, png16]) = entry.parts::<MapEntry, 3>()?;
    let size = metadata.size;
    let distances: Vec<f32> = from_pod_blob(&distances)?;
    let texels = size as usize * size as usize;
    (distances.len() == texels && states.len() == texels).then_some(())?;
    let map = HeightMap {
        size,
        distances,
        states,
        range: metadata.range,
        measured_texels: metadata.measured_texels,
        missed_texels: metadata.missed_texels,
        search_span: metadata.search_span,
        bake_ms: metadata.bake_ms,
    };
    Some(HeightMapFiles { map, png16: png16.into() })
}

/// A tessellated mesh compared by the hash of its vertices and triangles.
pub(crate) type HashedMesh = ByHash<PnMesh>;

fn hashed(mesh: PnMesh) -> Arc<HashedMesh> {
    let hash = hash_of_parts(&[
        bytemuck::cast_slice(&mesh.positions),
        bytemuck::cast_slice(&mesh.normals),
        bytemuck::cast_slice(&mesh.uvs),
        bytemuck::cast_slice(&mesh.triangles),
    ]);
    Arc::new(HashedMesh { hash, value: mesh })
}

fn level_of(db: &dyn Db, asset: Asset) -> Result<TessellateSettings, Diagnostic> {
    tessellate_settings(db, asset).ok_or_else(|| Diagnostic::new(asset.main_file(db), "the asset does not tessellate"))
}

/// The most triangles a tessellated mesh may have (its OBJ text is about 90 bytes a triangle).
pub(crate) const MAX_TESSELLATED_TRIANGLES: u64 = 4_000_000;

/// The low mesh on its PN surface, `level` segments per edge (stage `tessellate`).
#[salsa::tracked(returns(clone))]
pub(crate) fn pn_mesh(db: &dyn Db, asset: Asset) -> Result<Arc<HashedMesh>, Diagnostic> {
    let settings = level_of(db, asset)?;
    let low = low_geometry(db, asset)?;
    let mesh = &low.loaded.mesh;
    let triangles = mesh.triangles.len() as u64 * settings.level as u64 * settings.level as u64;
    if triangles > MAX_TESSELLATED_TRIANGLES {
        let message = format!(
            "level {} would tessellate the low mesh's {} triangles into {triangles}, more than the \
                {MAX_TESSELLATED_TRIANGLES} a tessellated mesh may have: lower `level`",
            settings.level,
            mesh.triangles.len()
        );
        return Err(Diagnostic::new(asset.main_file(db), message));
    }
    let input = PnInput {
        positions: &mesh.positions,
        normals: &mesh.normals,
        uvs: mesh.uvs.as_deref(),
        triangles: &mesh.triangles,
    };
    Ok(timed(db, TESSELLATE, asset.name(db), || hashed(tessellate(&input, settings.level))))
}

/// What the final tessellated mesh reads: the tessellation's settings, the low mesh, and when
/// displaced the PN map's key.
#[salsa::tracked(returns(clone))]
pub(crate) fn output_mesh_key(db: &dyn Db, asset: Asset) -> Result<CacheKey, Diagnostic> {
    let settings = level_of(db, asset)?;
    let key = stage_key(DISPLACE)
        .part(&TESSELLATE.version)
        .part(&settings.level)
        .part(&settings.displace)
        .part(&low_geometry(db, asset)?.hash);
    Ok(if settings.displace { key.part(&map_key(db, asset, MapReference::Pn)?.0) } else { key }.finish())
}

/// The PN mesh displaced by the PN map (stage `displace`; the PN mesh itself without `displace`).
#[salsa::tracked(returns(clone))]
pub(crate) fn output_mesh(db: &dyn Db, asset: Asset) -> Result<Arc<HashedMesh>, Diagnostic> {
    let settings = level_of(db, asset)?;
    let pn = pn_mesh(db, asset)?;
    if !settings.displace {
        return Ok(pn);
    }
    let map = height_map(db, asset, MapReference::Pn)?;
    Ok(timed(db, DISPLACE, asset.name(db), || {
        hashed(crate::mesh::pn_triangles::displaced(&pn.value, |uv| map.map.sample(uv)))
    }))
}

/// The final tessellated mesh as OBJ text (`mtllib tessellated.mtl`), with its counts, and its
/// geometry for the glTF (whose image names the outputs give: they follow the maps' contents).
#[derive(Debug, PartialEq)]
pub(crate) struct TessellatedFiles {
    pub obj: Arc<[u8]>,
    pub vertices: u64,
    pub triangles: u64,
    pub geometry: crate::mesh::gltf::GltfGeometry,
}

const MESH_ENTRY: &str = "height-tessellated";

/// What a tessellated mesh entry holds beside its OBJ.
#[derive(serde::Serialize, serde::Deserialize)]
struct MeshEntry {
    vertices: u64,
    triangles: u64,
}

/// The final mesh's OBJ (from the persistent cache, else `output_mesh`).
#[salsa::tracked(returns(clone))]
pub(crate) fn tessellated_files(db: &dyn Db, asset: Asset) -> Result<Arc<TessellatedFiles>, Diagnostic> {
    let key = output_mesh_key(db, asset)?;
    let from_entry = |entry: CacheEntry| {
        let (MeshEntry { vertices, triangles }, obj, geometry) = written_mesh_from_entry(entry)?;
        Some(TessellatedFiles { obj, vertices, triangles, geometry })
    };
    if let Some(files) = load_cached(db, MESH_ENTRY, key, from_entry) {
        record_cache_hit(db, DISPLACE, asset.name(db));
        return Ok(Arc::new(files));
    }
    let output = output_mesh(db, asset)?;
    let low = low_geometry(db, asset)?;
    let mesh = &output.value;
    let materials: Vec<u32> =
        mesh.source_triangles.iter().map(|&triangle| low.loaded.mesh.triangle_materials[triangle as usize]).collect();
    let names: Vec<String> = low.loaded.mesh.materials.iter().map(|material| material.name.clone()).collect();
    let obj = crate::mesh::obj_text::obj_text(
        &crate::mesh::obj_text::ObjMesh {
            positions: &mesh.positions,
            normals: &mesh.normals,
            uvs: &mesh.uvs,
            triangles: &mesh.triangles,
            triangle_materials: &materials,
            material_names: &names,
        },
        &format!("{} tessellated by cirrus", asset.name(db)),
        "tessellated.mtl",
    );
    let files = TessellatedFiles {
        obj: obj.into_bytes().into(),
        vertices: mesh.positions.len() as u64,
        triangles: mesh.triangles.len() as u64,
        geometry: crate::mesh::gltf::GltfGeometry {
            positions: mesh.positions.clone(),
            normals: mesh.normals.clone(),
            uvs: mesh.uvs.clone(),
            triangles: mesh.triangles.clone(),
            triangle_materials: materials,
            tangents: Vec::new(),
        }
        .with_tangents(),
    };
    store_cached(db, MESH_ENTRY, key, || {
        let metadata = MeshEntry { vertices: files.vertices, triangles: files.triangles };
        written_mesh_entry(&metadata, &files.obj, &files.geometry)
    });
    Ok(Arc::new(files))
}

/// A distance stage's label: `asset/low`, `asset/pn`, `asset/displaced`.
pub(crate) fn distance_label(asset_name: &str, measured: Measured) -> String {
    format!("{asset_name}/{}", measured.name())
}

const DISTANCE_ENTRY: &str = "height-distance";

/// The distance between a mesh and the high one (stage `distance`), over the high mesh's
/// bounding-box diagonal; cached by what both meshes are made from.
#[salsa::tracked(returns(clone))]
pub(crate) fn distance_to_high(
    db: &dyn Db,
    asset: Asset,
    measured: Measured,
) -> Result<Option<SurfaceDistance>, Diagnostic> {
    let low_hash = low_geometry(db, asset)?.hash;
    let mesh_key = match measured {
        Measured::Low => stage_key(DISTANCE).part(&low_hash).finish().0,
        Measured::Pn => stage_key(TESSELLATE).part(&level_of(db, asset)?.level).part(&low_hash).finish().0,
        Measured::Displaced => output_mesh_key(db, asset)?.0,
    };
    let key = stage_key(DISTANCE)
        .part(measured.name())
        .part(&(DISTANCE_SAMPLES as u64))
        .part(&mesh_key)
        .part(&high_geometry(db, asset)?.hash)
        .finish();
    let label = distance_label(asset.name(db), measured);
    let from_entry = |entry: CacheEntry| entry.parts::<Option<[f64; 2]>, 0>().map(|(figures, [])| figures);
    if let Some(figures) = load_cached(db, DISTANCE_ENTRY, key, from_entry) {
        record_cache_hit(db, DISTANCE, &label);
        return Ok(figures.map(|[rms, hausdorff]| SurfaceDistance { rms, hausdorff }));
    }
    let high = high_geometry(db, asset)?;
    let bvh = high_bvh(db, asset)?;
    // The measured mesh, borrowed from the stage that holds it.
    let (low, tessellated);
    let (positions, triangles) = match measured {
        Measured::Low => {
            low = low_geometry(db, asset)?;
            (&low.loaded.mesh.positions, &low.loaded.mesh.triangles)
        }
        Measured::Pn | Measured::Displaced => {
            tessellated = if measured == Measured::Pn { pn_mesh(db, asset)? } else { output_mesh(db, asset)? };
            (&tessellated.value.positions, &tessellated.value.triangles)
        }
    };
    let distance = timed(db, DISTANCE, &label, || {
        let mesh_bvh = build_triangle_bvh(positions, triangles);
        let mesh_samples = area_weighted_samples(positions, triangles, DISTANCE_SAMPLES);
        let high_mesh = &high.loaded.mesh;
        let high_samples = area_weighted_samples(&high_mesh.positions, &high_mesh.triangles, DISTANCE_SAMPLES);
        surface_distance(&mesh_samples, &mesh_bvh, &high_samples, &bvh.value, high.diagonal)
    });
    store_cached(db, DISTANCE_ENTRY, key, || {
        CacheEntry::new(&distance.map(|distance| [distance.rms, distance.hausdorff]), Vec::new(), false)
    });
    Ok(distance)
}
