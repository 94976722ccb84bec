//! The one mesh stage, shared by every kind whose asset is an OBJ (the billboard cloud, ambient
//! occlusion): the OBJ and the MTL files it names loaded into a `mesh::Mesh` with vertex
//! tangents, kept in the persistent cache by the content of what it read. Thin glue over
//! `mesh::load_mesh`; the asset's main file is the OBJ.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::Arc;

use crate::cache::{CacheEntry, CacheKey};
use crate::db::{
    asset_file, from_pod_blob, key_with_files, load_cached, pod_blob, read_contents, record_cache_hit, stage_key, store_cached, timed,
    Asset, Db, SourceFile, Stage,
};
use crate::diagnostic::Diagnostic;

// Mesh 2: `map_d` naming the albedo texture is not applied a second time. 3: each triangle's
// OBJ object.
pub const MESH: Stage = Stage { name: "mesh", version: 3 };

/// The OBJ's input.
fn mesh_source(db: &dyn Db, asset: Asset) -> Result<SourceFile, Diagnostic> {
    let path = asset.main_file(db);
    asset_file(db, asset, path.clone()).ok_or_else(|| Diagnostic::new(path, "was not read"))
}

/// The MTL files the OBJ names (project-relative), read or not.
#[salsa::tracked(returns(clone))]
pub fn mesh_library_paths(db: &dyn Db, asset: Asset) -> Arc<Vec<PathBuf>> {
    let Ok(file) = mesh_source(db, asset) else { return Arc::default() };
    let Ok(contents) = file.contents(db) else { return Arc::default() };
    Arc::new(crate::mesh::material_libraries(asset.main_file(db), &contents.bytes, asset.source_root(db)))
}

/// The OBJ and the MTL files it names: what the mesh stage reads.
pub fn mesh_files(db: &dyn Db, asset: Asset) -> Vec<PathBuf> {
    let mut files = vec![asset.main_file(db).clone()];
    files.extend(mesh_library_paths(db, asset).iter().cloned());
    files
}

/// The MTL files the OBJ names, as far as read, by project-relative path.
#[salsa::tracked(returns(clone))]
pub fn mesh_libraries(db: &dyn Db, asset: Asset) -> Arc<BTreeMap<PathBuf, SourceFile>> {
    let paths = mesh_library_paths(db, asset);
    Arc::new(paths.iter().filter_map(|path| Some((path.clone(), asset_file(db, asset, path.clone())?))).collect())
}

fn library_bytes(db: &dyn Db, asset: Asset) -> BTreeMap<PathBuf, Option<Vec<u8>>> {
    mesh_libraries(db, asset)
        .iter()
        .map(|(path, file)| (path.clone(), file.contents(db).as_ref().ok().map(|contents| contents.bytes.to_vec())))
        .collect()
}

/// The texture files the mesh's materials name (cheap: the MTL files only).
#[salsa::tracked(returns(clone))]
pub fn mesh_textures(db: &dyn Db, asset: Asset) -> Arc<Vec<PathBuf>> {
    Arc::new(crate::mesh::texture_paths(asset.main_file(db), &library_bytes(db, asset), asset.source_root(db)))
}

/// A loaded mesh with its vertex tangents and load warnings.
#[derive(Debug, PartialEq)]
pub struct LoadedMesh {
    pub mesh: crate::mesh::Mesh,
    pub tangents: Vec<[f32; 4]>,
    pub warnings: Vec<Diagnostic>,
}

/// The content address of what the mesh stage reads: the OBJ and its MTL files (paths and
/// bytes), and the source folder texture paths must stay in.
#[salsa::tracked(returns(copy))]
pub fn mesh_cache_key(db: &dyn Db, asset: Asset) -> CacheKey {
    let key = stage_key(MESH).part(asset.source_root(db));
    let libraries = mesh_libraries(db, asset);
    let files = mesh_source(db, asset).ok().into_iter().chain(libraries.values().copied());
    key_with_files(db, key, files).finish()
}

fn loaded_mesh_entry(loaded: &LoadedMesh) -> CacheEntry {
    let mesh = &loaded.mesh;
    CacheEntry {
        metadata: serde_json::json!({
            "materials": mesh.materials,
            "objects": mesh.objects,
            "warnings": loaded.warnings,
            "uvs": mesh.uvs.is_some(),
        }),
        blobs: vec![
            pod_blob(&mesh.positions),
            pod_blob(&mesh.normals),
            mesh.uvs.as_deref().map(pod_blob).unwrap_or_default(),
            pod_blob(&mesh.triangles),
            pod_blob(&mesh.triangle_materials),
            pod_blob(&loaded.tangents),
            pod_blob(&mesh.triangle_objects),
        ],
        compress: false,
    }
}

fn loaded_mesh_from_entry(entry: CacheEntry) -> Option<LoadedMesh> {
    let [positions, normals, uvs, triangles, triangle_materials, tangents, triangle_objects]: [Vec<u8>; 7] = entry.blobs.try_into().ok()?;
    let mesh = crate::mesh::Mesh {
        positions: from_pod_blob(&positions)?,
        normals: from_pod_blob(&normals)?,
        uvs: if entry.metadata.get("uvs")?.as_bool()? { Some(from_pod_blob(&uvs)?) } else { None },
        triangles: from_pod_blob(&triangles)?,
        triangle_materials: from_pod_blob(&triangle_materials)?,
        materials: serde_json::from_value(entry.metadata.get("materials")?.clone()).ok()?,
        triangle_objects: from_pod_blob(&triangle_objects)?,
        objects: serde_json::from_value(entry.metadata.get("objects")?.clone()).ok()?,
    };
    let warnings = serde_json::from_value(entry.metadata.get("warnings")?.clone()).ok()?;
    Some(LoadedMesh { mesh, tangents: from_pod_blob(&tangents)?, warnings })
}

/// The mesh (stage `mesh`): OBJ + MTL loaded, tangents computed.
#[salsa::tracked(returns(clone))]
pub fn loaded_mesh(db: &dyn Db, asset: Asset) -> Result<Arc<LoadedMesh>, Diagnostic> {
    let file = mesh_source(db, asset)?;
    let contents = read_contents(db, file)?;
    // A missing MTL is a warning (its materials fall back to defaults); one that is there but
    // cannot be read (not a regular file, no permission) fails the mesh, naming why.
    for (path, library) in mesh_libraries(db, asset).iter() {
        if let Err(why) = library.contents(db) {
            if why != crate::sources::FILE_NOT_FOUND {
                return Err(Diagnostic::new(path, why.clone()));
            }
        }
    }
    let name = asset.name(db);
    let cache_key = mesh_cache_key(db, asset);
    if let Some(loaded) = load_cached(db, MESH.name, cache_key, loaded_mesh_from_entry) {
        record_cache_hit(db, MESH, name);
        return Ok(Arc::new(loaded));
    }
    let libraries = library_bytes(db, asset);
    let loaded = timed(db, MESH, name, || {
        let (mesh, warnings) = crate::mesh::load_mesh(file.path(db), &contents.bytes, &libraries, asset.source_root(db))?;
        let tangents = match &mesh.uvs {
            Some(uvs) => crate::mesh::vertex_tangents(&mesh.positions, &mesh.normals, uvs, &mesh.triangles),
            None => Vec::new(),
        };
        Ok(LoadedMesh { mesh, tangents, warnings })
    })?;
    store_cached(db, MESH.name, cache_key, || loaded_mesh_entry(&loaded));
    Ok(Arc::new(loaded))
}

/// The mesh stage's instance: labelled by the asset, reading the OBJ and its MTL files.
pub fn mesh_instance(db: &dyn Db, asset: Asset) -> crate::kinds::StageInstance {
    let main_file = asset.main_file(db);
    let mut mesh = crate::kinds::StageInstance::new(MESH, asset.name(db), crate::diagnostic::display_path(main_file));
    mesh.reads.push(crate::kinds::Read::File(main_file.clone()));
    mesh.reads.extend(mesh_libraries(db, asset).keys().map(|path| crate::kinds::Read::File(path.clone())));
    mesh
}
