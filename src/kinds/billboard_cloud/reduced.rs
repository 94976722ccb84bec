//! A LOD chain's reduced levels (`lods: [Reduced(Ratio(0.5)), …]`): the source's triangles
//! brought under a budget (`mesh::reduce`), written as `lod.obj` + `lod.mtl` and `lod.gltf` +
//! `lod.bin` over the source's materials, whose maps are copied into the level's `maps/` (named
//! by content; in the level's folder, since loaders refuse paths out of a file's folder); the
//! pure step from mesh to files (`reduce_level`), their stage instance and report (the preview
//! and the viewer load the level as an engine does, `kinds::mesh_view_from_files`).

use std::path::Path;
use std::sync::Arc;

use super::levels;
use super::queries::{level_label, reduced_level, REDUCE};
use crate::db::{Asset, Db};
use crate::diagnostic::Diagnostic;
use crate::kinds::mesh_queries::loaded_mesh;
use crate::kinds::source_copies::{material_copy_paths, used_materials, written_materials, MaterialPlaces};
use crate::kinds::{AssetOutputs, StageInstance};
use crate::mesh::gltf::{GltfMaterial, GltfMesh};
use crate::summary::ArtifactRole;

/// The files a reduced level writes into its folder (beside the copies of the maps).
const LEVEL_FILES: [&str; 4] = ["lod.obj", "lod.mtl", "lod.gltf", "lod.bin"];

/// A reduced level's `reduce` stage instance: it reads the mesh stage and writes the level's
/// files and the copies of the maps its materials name.
pub(crate) fn reduce_instance(
    db: &dyn Db,
    asset: Asset,
    level: u32,
    output_folder: &Path,
    mesh: &StageInstance,
) -> StageInstance {
    let folder = levels::level_folder(asset.settings(db), level);
    let level_folder = output_folder.join(&folder);
    let mut reduce = StageInstance::new(REDUCE, level_label(db, asset, level), &folder).reads_stage(mesh);
    reduce.writes = LEVEL_FILES.map(|file| level_folder.join(file)).to_vec();
    if let (Ok(loaded), Ok(reduced)) = (loaded_mesh(db, asset), reduced_level(db, asset, level)) {
        let chosen = used_materials(&loaded.mesh.materials, &reduced.geometry.triangle_materials).1;
        reduce.writes.extend(material_copy_paths(db, asset, &level_folder, &chosen));
    }
    reduce
}

/// A reduced level as the chain's document draws it: its geometry and its used materials (maps
/// relative to the level's folder).
pub(crate) struct ReducedGltf {
    pub level: Arc<ReducedLevel>,
    pub materials: Vec<GltfMaterial>,
    pub triangle_materials: Vec<u32>,
}

impl ReducedGltf {
    pub fn mesh(&self) -> GltfMesh<'_> {
        GltfMesh {
            triangle_materials: &self.triangle_materials,
            ..self.level.geometry.mesh("reduced", &self.materials)
        }
    }
}

/// A reduced level's files (added to `outputs`, its material warnings to `warnings`), its part
/// of the report and its mesh for the chain's document.
pub(crate) fn reduced_level_outputs(
    db: &dyn Db,
    asset: Asset,
    level: u32,
    output_folder: &Path,
    (outputs, warnings): (&mut AssetOutputs, &mut Vec<Diagnostic>),
) -> Result<(serde_json::Value, ReducedGltf), Diagnostic> {
    let settings = asset.settings(db);
    let folder = levels::level_folder(settings, level);
    let level_folder = output_folder.join(&folder);
    let loaded = loaded_mesh(db, asset)?;
    let reduced = reduced_level(db, asset, level)?;
    let places = MaterialPlaces { source: asset.main_file(db), mtl_folder: &level_folder, gltf_folder: &level_folder };
    let written = written_materials(
        db,
        asset,
        &level_folder,
        outputs,
        (&loaded.mesh.materials, &reduced.geometry.triangle_materials),
        &places,
        warnings,
    );
    let copies = written.maps;
    let chain =
        ReducedGltf { level: reduced.clone(), materials: written.gltf, triangle_materials: written.triangle_materials };
    let gltf = crate::mesh::gltf::gltf_files(&chain.mesh(), "lod.bin", crate::mesh::gltf::GENERATOR);
    let mtl = written.mtl.into_bytes();
    // The bytes an engine loads: the mesh, its material library and the maps it names.
    let (mut map_bytes, mut gpu_bytes) = (0, gltf.bin.len() as u64);
    for (path, _, contents) in outputs.files.iter().filter(|(path, _, _)| copies.contains(path)) {
        map_bytes += contents.len();
        // The copies are uploaded as they are: RGBA8, mips made on load.
        if let Ok((width, height)) = crate::texture::probe_texture(path, contents, Default::default()) {
            gpu_bytes += crate::texture::encode::gpu_bytes(width, height, None);
        }
    }
    let bytes = reduced.obj.len() + mtl.len() + map_bytes;
    outputs.add(level_folder.join("lod.obj"), ArtifactRole::Mesh, reduced.obj.clone());
    outputs.add(level_folder.join("lod.mtl"), ArtifactRole::Mtl, mtl.into());
    outputs.add(level_folder.join("lod.gltf"), ArtifactRole::Gltf, gltf.gltf.into());
    outputs.add(level_folder.join("lod.bin"), ArtifactRole::GltfBuffer, gltf.bin.into());
    let figures = &reduced.figures;
    let budget = match levels::settings_for(settings, level).reduced {
        Some(crate::mesh::reduce::TriangleBudget::Triangles(count)) => serde_json::json!({ "triangles": count }),
        Some(crate::mesh::reduce::TriangleBudget::Ratio(ratio)) => serde_json::json!({ "ratio": ratio }),
        None => serde_json::Value::Null,
    };
    let (source_area, kept_area) = figures.cut_out_area;
    let report = serde_json::json!({
        "level": level,
        "folder": folder,
        "representation": "reduced",
        "budget": budget,
        "triangles": figures.triangles,
        "vertices": figures.vertices,
        // The simplifier's largest deviation: a fraction of the mesh's largest extent, and in
        // world units.
        "error": figures.error,
        "error_world": figures.error_world,
        "cards": { "source": figures.cards.0, "kept": figures.cards.1 },
        // The leaf area drawn (cut-out materials), against the source's.
        "leaf_area": if source_area > 0.0 { Some(((kept_area / source_area) * 1e4).round() / 1e4) } else { None },
        "maps": copies.iter().map(|path| crate::diagnostic::display_path(path)).collect::<Vec<_>>(),
        "bytes": bytes,
        // What the GPU holds: the glTF's vertex and index buffer and the maps with their mips.
        "gpu_bytes": gpu_bytes,
    });
    Ok((report, chain))
}

/// What a reduced level drew, against its source.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub(crate) struct ReducedFigures {
    pub triangles: u64,
    pub vertices: u64,
    /// The simplifier's largest deviation, a fraction of the mesh's largest extent, and in
    /// world units.
    pub error: f32,
    pub error_world: f32,
    /// The source's leaf cards and those kept.
    pub cards: (u64, u64),
    /// The leaf area drawn (cut-out materials' triangles) in the source and the level.
    pub cut_out_area: (f64, f64),
}

/// A reduced level's `lod.obj` (`mtllib lod.mtl`), the geometry of its glTF (whose image names
/// the outputs give: copies of the maps, named by content) and its figures.
#[derive(Debug, PartialEq)]
pub(crate) struct ReducedLevel {
    pub obj: Arc<[u8]>,
    pub geometry: crate::mesh::gltf::GltfGeometry,
    pub figures: ReducedFigures,
}

/// `mesh` reduced to `budget` as a level's files.
pub(crate) fn reduce_level(mesh: &crate::mesh::Mesh, budget: crate::mesh::reduce::TriangleBudget) -> ReducedLevel {
    let settings = crate::mesh::reduce::ReduceSettings { budget, max_error: super::queries::REDUCE_MAX_ERROR };
    let reduced = crate::mesh::reduce::reduce_mesh(mesh, &settings);
    let extent = crate::mesh::reduce::mesh_extent(&mesh.positions);
    let out = &reduced.mesh;
    let names: Vec<String> = out.materials.iter().map(|material| material.name.clone()).collect();
    let uvs = out.uvs.as_deref().unwrap_or(&[]);
    let obj = crate::mesh::obj_text::obj_text(
        &crate::mesh::obj_text::ObjMesh {
            positions: &out.positions,
            normals: &out.normals,
            uvs,
            triangles: &out.triangles,
            triangle_materials: &out.triangle_materials,
            material_names: &names,
        },
        &format!("reduced by cirrus (meshoptimizer): {} of {} triangles", out.triangles.len(), mesh.triangles.len()),
        "lod.mtl",
    );
    let geometry = crate::mesh::gltf::GltfGeometry {
        positions: out.positions.clone(),
        normals: out.normals.clone(),
        uvs: uvs.to_vec(),
        triangles: out.triangles.clone(),
        triangle_materials: out.triangle_materials.clone(),
        tangents: Vec::new(),
    }
    .with_tangents();
    let figures = ReducedFigures {
        triangles: out.triangles.len() as u64,
        vertices: out.positions.len() as u64,
        error: reduced.error,
        error_world: reduced.error * extent,
        cards: (reduced.cards.0 as u64, reduced.cards.1 as u64),
        cut_out_area: reduced.cut_out_area,
    };
    ReducedLevel { obj: obj.into_bytes().into(), geometry, figures }
}
