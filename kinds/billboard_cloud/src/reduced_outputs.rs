//! A reduced level's stage instances (`reduce`, then each map's `maps` and the tail's) and its
//! files: `lod.obj` + `lod.mtl`, `lod.gltf` + `lod.bin`, its maps through the tail into
//! `materials/<name>/`, and its part of the report.

use std::path::Path;

use super::queries::{level_label, reduced_level, MAPS, REDUCE};
use super::reduced::{packed_materials, surface_sources, ReducedGltf, LEVEL_FILES};
use super::reduced_queries::reduced_maps;
use super::report::{Cards, LevelDetail, LevelFigures, LevelReport, ReducedBudget, Representation, SurfaceFigures};
use super::{levels, report, surfaces};
use crate::db::{Asset, Db};
use crate::diagnostic::Diagnostic;
use crate::kinds::mesh_queries::loaded_mesh;
use crate::kinds::{AssetOutputs, StageInstance};
use crate::summary::ArtifactRole;

/// A reduced level's stage instances: `reduce` (reads the mesh stage, writes the level's files),
/// and per surface of its maps `maps` (reads the MTL files, or an `Auto` candidate's `reduce`,
/// and the decodes of the surface's source maps, added to `decodes`) and the tail's.
pub(crate) fn reduce_instances(
    db: &dyn Db,
    asset: Asset,
    level: u32,
    (output_folder, report): (&Path, &std::path::PathBuf),
    (mesh, decodes): (&StageInstance, &mut std::collections::BTreeMap<String, StageInstance>),
) -> Vec<StageInstance> {
    let settings = asset.settings(db);
    let folder = levels::level_folder(settings, level);
    let level_folder = output_folder.join(&folder);
    let mut reduce = StageInstance::new(REDUCE, level_label(db, asset, level), &folder).reads_stage(mesh);
    reduce.writes = LEVEL_FILES.map(|file| level_folder.join(file)).to_vec();
    reduce.writes.push(report.clone());
    let mut instances = vec![reduce.clone()];
    let (Ok(loaded), Ok(maps)) = (loaded_mesh(db, asset), reduced_maps(db, asset, level)) else { return instances };
    let name = asset.name(db);
    // An `Auto` candidate's maps are sized by its mesh's bytes; the others' read only the
    // materials (the MTL files) and their maps.
    let sized_by_mesh = super::queries::level_settings(db, asset, level).max_bytes.is_some();
    let libraries = crate::kinds::mesh_queries::mesh_library_paths_of(db, asset, asset.main_file(db).clone());
    for (surface, _) in maps.surfaces(&folder, level) {
        let material = surface.part.item.unwrap_or_default();
        let mut pack = StageInstance::new(MAPS, surface.label(name), surface.instance());
        match sized_by_mesh {
            true => pack = pack.reads_stage(&reduce),
            false => pack.reads.extend(libraries.iter().map(|library| crate::kinds::Read::File(library.clone()))),
        }
        let sources = surface_sources(&loaded.mesh.materials[material as usize], surface.surface);
        for path in sources.into_iter().flatten() {
            surfaces::read_decode(&mut pack, path, decodes);
        }
        let written = surface.written_files(output_folder, &settings.encode);
        let [mips, encode, mut write] = crate::kinds::tail_instances(name, &surface, &pack, &written);
        write.writes.push(report.clone());
        instances.extend([pack, mips, encode, write]);
    }
    instances
}

/// A reduced level's files (added to `outputs`): its mesh, material library, glTF and maps
/// (through the tail); its part of the report and its mesh for the chain's document.
pub(crate) fn reduced_level_outputs(
    db: &dyn Db,
    asset: Asset,
    level: u32,
    output_folder: &Path,
    outputs: &mut AssetOutputs,
) -> Result<(LevelReport, ReducedGltf), Diagnostic> {
    let settings = asset.settings(db);
    let folder = levels::level_folder(settings, level);
    let level_folder = output_folder.join(&folder);
    let loaded = loaded_mesh(db, asset)?;
    let reduced = reduced_level(db, asset, level)?;
    let maps = reduced_maps(db, asset, level)?;
    let (mtl, materials) = packed_materials(&loaded.mesh.materials, &maps, settings.encode.packing.stem());
    let triangle_materials = maps.triangle_materials(&reduced.geometry.triangle_materials);
    let chain = ReducedGltf { level: reduced.clone(), materials, triangle_materials };
    let gltf = crate::mesh::gltf::gltf_files(&chain.mesh(), "lod.bin", crate::mesh::gltf::GENERATOR);
    let mtl = mtl.into_bytes();
    let bytes = reduced.obj.len() + mtl.len();
    // What the GPU holds: the glTF's vertex and index buffer, the maps with their mips.
    let gpu_bytes = gltf.bin.len() as u64;
    outputs.add(level_folder.join("lod.obj"), ArtifactRole::Mesh, reduced.obj.clone());
    outputs.add(level_folder.join("lod.mtl"), ArtifactRole::Mtl, mtl.into());
    outputs.add(level_folder.join("lod.gltf"), ArtifactRole::Gltf, gltf.gltf.into());
    outputs.add(level_folder.join("lod.bin"), ArtifactRole::GltfBuffer, gltf.bin.into());
    let written = surfaces::write_level_surfaces(db, asset, level, output_folder, outputs)?;
    // Each map's figures with its material's folder name.
    let surfaces: Vec<SurfaceFigures> = maps
        .surfaces(&folder, level)
        .iter()
        .zip(written.infos)
        .map(|((surface, _), info)| {
            let of_material = surface.part.item.and_then(|material| maps.of_material(material));
            let material = of_material.map_or(String::new(), |maps| maps.folder.clone());
            SurfaceFigures { info, material: Some(material) }
        })
        .collect();
    let figures = &reduced.figures;
    let budget = match levels::settings_for(settings, level).reduced {
        Some(crate::mesh::reduce::TriangleBudget::Triangles(count)) => Some(ReducedBudget::Triangles(count)),
        Some(crate::mesh::reduce::TriangleBudget::Ratio(ratio)) => Some(ReducedBudget::Ratio(ratio)),
        None => None,
    };
    let (source_area, kept_area) = figures.cut_out_area;
    let detail = report::ReducedFigures {
        budget,
        vertices: figures.vertices,
        error: figures.error,
        error_world: figures.error_world,
        cards: Cards { source: figures.cards.0, kept: figures.cards.1 },
        leaf_area: (source_area > 0.0).then(|| ((kept_area / source_area) * 1e4).round() / 1e4),
        map_side: maps.side,
    };
    let figures = LevelFigures {
        representation: Representation::Reduced,
        triangles: figures.triangles,
        bytes: (bytes + written.bytes) as u64,
        gpu_bytes: gpu_bytes + written.gpu_bytes,
        surfaces,
        detail: LevelDetail::Reduced(detail),
    };
    let report = LevelReport::new(level, folder, figures);
    Ok((report, chain))
}
