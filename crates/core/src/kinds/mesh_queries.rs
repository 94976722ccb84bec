//! The one mesh stage, shared by every kind whose asset reads OBJs (the billboard cloud, ambient
//! occlusion, height): an OBJ and the MTL files it names loaded into a `mesh::Mesh` with vertex
//! tangents, kept in the persistent cache by the content of what it read. Thin glue over
//! `mesh::load_mesh`; one instance per OBJ (the asset's main file, or another it names: a
//! height bake's high mesh).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::cache::{CacheEntry, CacheKey};
use crate::db::{
    asset_file, from_pod_blob, key_with_files, load_cached, pod_blob, read_contents, record_cache_hit, stage_key,
    store_cached, timed, Asset, Db, SourceFile, Stage,
};
use crate::diagnostic::Diagnostic;

// Mesh 2: `map_d` naming the albedo texture is not applied a second time. 3: each triangle's
// OBJ object. 4: a map's path relative to the MTL file that names it, not to the OBJ.
pub const MESH: Stage = Stage { name: "mesh", version: 4 };

/// An OBJ's input.
fn mesh_source(db: &dyn Db, asset: Asset, obj: &Path) -> Result<SourceFile, Diagnostic> {
    asset_file(db, asset, obj.to_path_buf()).ok_or_else(|| Diagnostic::new(obj, "was not read"))
}

/// The MTL files an OBJ of the asset names (project-relative), read or not.
#[salsa::tracked(returns(clone))]
pub fn mesh_library_paths_of(db: &dyn Db, asset: Asset, obj: PathBuf) -> Arc<Vec<PathBuf>> {
    let Ok(file) = mesh_source(db, asset, &obj) else { return Arc::default() };
    let Some(bytes) = file.contents(db).as_ref().ok().and_then(|contents| contents.bytes().ok()) else {
        return Arc::default();
    };
    Arc::new(crate::mesh::material_libraries(&obj, &bytes, asset.source_root(db)))
}

/// An OBJ and the MTL files it names: what its mesh stage reads.
pub fn mesh_files_of(db: &dyn Db, asset: Asset, obj: &Path) -> Vec<PathBuf> {
    let mut files = vec![obj.to_path_buf()];
    files.extend(mesh_library_paths_of(db, asset, obj.to_path_buf()).iter().cloned());
    files
}

/// The main OBJ and the MTL files it names.
pub fn mesh_files(db: &dyn Db, asset: Asset) -> Vec<PathBuf> {
    mesh_files_of(db, asset, asset.main_file(db))
}

/// The MTL files an OBJ names, as far as read, by project-relative path.
#[salsa::tracked(returns(clone))]
pub fn mesh_libraries_of(db: &dyn Db, asset: Asset, obj: PathBuf) -> Arc<BTreeMap<PathBuf, SourceFile>> {
    let paths = mesh_library_paths_of(db, asset, obj);
    Arc::new(paths.iter().filter_map(|path| Some((path.clone(), asset_file(db, asset, path.clone())?))).collect())
}

/// The bytes of the MTL files an OBJ of the asset names, as `mesh::load_mesh` takes them (a
/// missing or unreadable one absent or `None`).
pub fn library_bytes(db: &dyn Db, asset: Asset, obj: &Path) -> BTreeMap<PathBuf, Option<Vec<u8>>> {
    mesh_libraries_of(db, asset, obj.to_path_buf())
        .iter()
        .map(|(path, file)| {
            (
                path.clone(),
                file.contents(db).as_ref().ok().and_then(|contents| contents.bytes().ok()).map(|bytes| bytes.to_vec()),
            )
        })
        .collect()
}

/// The texture files the main mesh's materials name (cheap: the MTL files only).
#[salsa::tracked(returns(clone))]
pub fn mesh_textures(db: &dyn Db, asset: Asset) -> Arc<Vec<PathBuf>> {
    let obj = asset.main_file(db);
    Arc::new(crate::mesh::texture_paths(&library_bytes(db, asset, obj), asset.source_root(db)))
}

/// A loaded mesh with its vertex tangents and load warnings.
#[derive(Debug, PartialEq)]
pub struct LoadedMesh {
    pub mesh: crate::mesh::Mesh,
    pub tangents: Vec<[f32; 4]>,
    pub warnings: Vec<Diagnostic>,
}

/// The content address of what a mesh stage reads: the OBJ and its MTL files (paths relative
/// to the source folder, and bytes); the mesh names its textures relative to that folder too
/// in the cache (see `db::load_cached`).
#[salsa::tracked(returns(copy))]
pub fn mesh_cache_key(db: &dyn Db, asset: Asset, obj: PathBuf) -> CacheKey {
    let key = stage_key(MESH);
    let libraries = mesh_libraries_of(db, asset, obj.clone());
    let files = mesh_source(db, asset, &obj).ok().into_iter().chain(libraries.values().copied());
    key_with_files(db, key, files).finish()
}

/// A mesh stage's label: the asset's name for its main OBJ, `asset/<path>` for another.
pub fn mesh_label(db: &dyn Db, asset: Asset, obj: &Path) -> String {
    let name = asset.name(db);
    if obj == asset.main_file(db) {
        name.clone()
    } else {
        format!("{name}/{}", crate::diagnostic::display_path(obj))
    }
}

/// What a mesh entry holds beside its arrays.
#[derive(serde::Serialize, serde::Deserialize)]
struct MeshEntry {
    materials: Vec<crate::mesh::MeshMaterial>,
    objects: Vec<String>,
    warnings: Vec<Diagnostic>,
    uvs: bool,
}

fn loaded_mesh_entry(loaded: &LoadedMesh) -> CacheEntry {
    let mesh = &loaded.mesh;
    let metadata = MeshEntry {
        materials: mesh.materials.clone(),
        objects: mesh.objects.clone(),
        warnings: loaded.warnings.clone(),
        uvs: mesh.uvs.is_some(),
    };
    CacheEntry::new(
        &metadata,
        vec![
            pod_blob(&mesh.positions),
            pod_blob(&mesh.normals),
            mesh.uvs.as_deref().map(pod_blob).unwrap_or_default(),
            pod_blob(&mesh.triangles),
            pod_blob(&mesh.triangle_materials),
            pod_blob(&loaded.tangents),
            pod_blob(&mesh.triangle_objects),
        ],
        false,
    )
}

fn loaded_mesh_from_entry(entry: CacheEntry) -> Option<LoadedMesh> {
    let (metadata, [positions, normals, uvs, triangles, triangle_materials, tangents, triangle_objects]) =
        entry.parts::<MeshEntry, 7>()?;
    let mesh = crate::mesh::Mesh {
        positions: from_pod_blob(&positions)?,
        normals: from_pod_blob(&normals)?,
        uvs: if metadata.uvs { Some(from_pod_blob(&uvs)?) } else { None },
        triangles: from_pod_blob(&triangles)?,
        triangle_materials: from_pod_blob(&triangle_materials)?,
        materials: metadata.materials,
        triangle_objects: from_pod_blob(&triangle_objects)?,
        objects: metadata.objects,
    };
    Some(LoadedMesh { mesh, tangents: from_pod_blob(&tangents)?, warnings: metadata.warnings })
}

/// The asset's main mesh (stage `mesh`).
pub fn loaded_mesh(db: &dyn Db, asset: Asset) -> Result<Arc<LoadedMesh>, Diagnostic> {
    loaded_mesh_of(db, asset, asset.main_file(db).clone())
}

/// A mesh of the asset (stage `mesh`): OBJ + MTL loaded, tangents computed.
#[salsa::tracked(returns(clone))]
pub fn loaded_mesh_of(db: &dyn Db, asset: Asset, obj: PathBuf) -> Result<Arc<LoadedMesh>, Diagnostic> {
    let file = mesh_source(db, asset, &obj)?;
    let contents = read_contents(db, file)?;
    // A missing MTL is a warning (its materials fall back to defaults); one that is there but
    // cannot be read (not a regular file, no permission) fails the mesh, naming why.
    for (path, library) in mesh_libraries_of(db, asset, obj.clone()).iter() {
        if let Err(why) = library.contents(db) {
            if !why.is_not_found() {
                return Err(Diagnostic::new(path, why.clone()));
            }
        }
    }
    let name = &mesh_label(db, asset, &obj);
    let cache_key = mesh_cache_key(db, asset, obj.clone());
    if let Some(loaded) = load_cached(db, MESH.name, cache_key, loaded_mesh_from_entry) {
        record_cache_hit(db, MESH, name);
        return Ok(Arc::new(loaded));
    }
    let libraries = library_bytes(db, asset, &obj);
    let loaded = timed(db, MESH, name, || {
        let (mesh, warnings) =
            crate::mesh::load_mesh(file.path(db), &contents.bytes()?, &libraries, asset.source_root(db))?;
        let tangents = match &mesh.uvs {
            Some(uvs) => crate::mesh::vertex_tangents(&mesh.positions, &mesh.normals, uvs, &mesh.triangles),
            None => Vec::new(),
        };
        Ok(LoadedMesh { mesh, tangents, warnings })
    })?;
    store_cached(db, MESH.name, cache_key, || loaded_mesh_entry(&loaded));
    Ok(Arc::new(loaded))
}

/// The main mesh stage's instance: labelled by the asset, reading the OBJ and its MTL files.
pub fn mesh_instance(db: &dyn Db, asset: Asset) -> crate::kinds::StageInstance {
    mesh_instance_of(db, asset, asset.main_file(db))
}

/// The instance of the mesh stage of one OBJ of the asset (see `mesh_label`).
pub fn mesh_instance_of(db: &dyn Db, asset: Asset, obj: &Path) -> crate::kinds::StageInstance {
    let mut mesh =
        crate::kinds::StageInstance::new(MESH, mesh_label(db, asset, obj), crate::diagnostic::display_path(obj));
    mesh.reads.push(crate::kinds::Read::File(obj.to_path_buf()));
    mesh.reads.extend(
        mesh_libraries_of(db, asset, obj.to_path_buf()).keys().map(|path| crate::kinds::Read::File(path.clone())),
    );
    mesh
}

/// A triangle mesh a kind writes (a tessellated mesh, a reduced level) as one cache entry:
/// `metadata` (the kind's figures), the OBJ text and the glTF geometry's arrays.
pub fn written_mesh_entry<T: serde::Serialize>(
    metadata: &T,
    obj: &[u8],
    geometry: &crate::mesh::gltf::GltfGeometry,
) -> CacheEntry {
    CacheEntry::new(
        metadata,
        vec![
            obj.to_vec(),
            pod_blob(&geometry.positions),
            pod_blob(&geometry.normals),
            pod_blob(&geometry.uvs),
            pod_blob(&geometry.triangles),
            pod_blob(&geometry.triangle_materials),
            pod_blob(&geometry.tangents),
        ],
        true,
    )
}

/// What [`written_mesh_entry`] stored: the metadata, the OBJ text and the geometry.
pub fn written_mesh_from_entry<T: serde::de::DeserializeOwned>(
    entry: CacheEntry,
) -> Option<(T, Arc<[u8]>, crate::mesh::gltf::GltfGeometry)> {
    let (metadata, [obj, positions, normals, uvs, corners, materials, tangents]) = entry.parts::<T, 7>()?;
    let geometry = crate::mesh::gltf::GltfGeometry {
        positions: from_pod_blob(&positions)?,
        normals: from_pod_blob(&normals)?,
        uvs: from_pod_blob(&uvs)?,
        triangles: from_pod_blob(&corners)?,
        triangle_materials: from_pod_blob(&materials)?,
        tangents: from_pod_blob(&tangents)?,
    };
    Some((metadata, obj.into(), geometry))
}
