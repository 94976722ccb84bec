//! Every slot's files of a baked billboard cloud (added to the asset's outputs), each slot's
//! part of the report and its mesh for the chain's document: a cloud level's here, a reduced
//! level's (`reduced_outputs`) and an impostor's (`impostor_level`) beside it.

use std::path::Path;

use super::queries::{billboard_layout, billboard_planes, lod_files};
use super::report::{CloudAtlas, CloudFigures, LevelDetail, LevelFigures, LevelReport, Representation, SurfaceFigures};
use super::{impostor_level, levels, lod_mesh, queries, reduced, reduced_outputs, report, surfaces};
use crate::db::{Asset, Db};
use crate::diagnostic::Diagnostic;
use crate::kinds::AssetOutputs;
use crate::summary::ArtifactRole;

/// Every slot's files (added to `outputs` under `output_folder`, meaning the chain's level, and
/// for a candidate its name), each slot's part of the report, and each one's mesh for the
/// chain's document.
pub(super) fn level_files(
    db: &dyn Db,
    asset: Asset,
    output_folder: &Path,
    outputs: &mut AssetOutputs,
) -> Result<(Vec<LevelReport>, Vec<ChainMesh>), Diagnostic> {
    let settings = asset.settings(db);
    let mut reports = Vec::new();
    let mut meshes = Vec::new();
    for (slot, spec) in levels::slots(settings).into_iter().enumerate() {
        let (slot, first_file) = (slot as u32, outputs.files.len());
        let (mut report, mesh) = if levels::is_reduced(settings, slot) {
            let (report, mesh) = reduced_outputs::reduced_level_outputs(db, asset, slot, output_folder, outputs)?;
            (report, ChainMesh::Reduced(mesh))
        } else if levels::is_impostor(settings, slot) {
            let (report, quad) = impostor_level::impostor_level_outputs(db, asset, slot, output_folder, outputs)?;
            (report, ChainMesh::Impostor(quad))
        } else {
            level_outputs(db, asset, slot, output_folder, outputs)?
        };
        report.level = spec.level;
        // The manifest and the hot-reload batches name each file's level.
        if levels::is_chain(settings) {
            let meaning = report::file_meaning(spec.level, spec.candidate.as_deref());
            for (path, _, _) in &outputs.files[first_file..] {
                outputs.meanings.insert(path.clone(), meaning.clone());
            }
        }
        meshes.push(mesh);
        reports.push(report);
    }
    Ok((reports, meshes))
}

/// One billboard-cloud level's files (added to `outputs`), its part of the report (what it
/// draws, the error it was made with, its atlas, its surfaces, and the bytes an engine loads:
/// `lod.obj`, `lod.mtl` and the four textures; previews aside) and its mesh for the chain.
fn level_outputs(
    db: &dyn Db,
    asset: Asset,
    level: u32,
    output_folder: &Path,
    outputs: &mut AssetOutputs,
) -> Result<(LevelReport, ChainMesh), Diagnostic> {
    let settings = asset.settings(db);
    let folder = levels::level_folder(settings, level);
    let level_settings = queries::level_settings(db, asset, level);
    let obj = (*lod_files(db, asset, level)?).clone();
    let mtl = lod_mesh::lod_mtl("billboard_cloud", settings.encode.packing.stem());
    let planes = billboard_planes(db, asset, level)?;
    let layout = billboard_layout(db, asset, level)?;
    let level_folder = output_folder.join(&folder);
    let mut bytes = obj.len() + mtl.len();
    outputs.add(level_folder.join("lod.obj"), ArtifactRole::Mesh, obj.into_bytes().into());
    outputs.add(level_folder.join("lod.mtl"), ArtifactRole::Mtl, mtl.into_bytes().into());
    let gltf = queries::lod_gltf(db, asset, level)?;
    // What the GPU holds: the glTF's vertex and index buffer and the textures with their mips.
    let mut gpu_bytes = gltf.bin.len() as u64;
    outputs.add(level_folder.join("lod.gltf"), ArtifactRole::Gltf, gltf.gltf.clone().into());
    outputs.add(level_folder.join("lod.bin"), ArtifactRole::GltfBuffer, gltf.bin.clone().into());
    let written = surfaces::write_level_surfaces(db, asset, level, output_folder, outputs)?;
    bytes += written.bytes;
    gpu_bytes += written.gpu_bytes;
    let atlas_coverage = queries::atlas_coverage_fraction(db, asset, level)?;
    let chain = lod_mesh::lod_gltf_mesh(&layout.rectangles, &layout.layout, queries::billboard_alpha_cutoff(db, asset));
    let cloud = CloudFigures {
        planes: planes.planes.len(),
        quads: layout.layout.placements.len(),
        budget_quads: level_settings.planes.max_quads,
        faces_also_drawn: layout.rectangles.iter().map(|rectangle| rectangle.also_drawn.len()).sum(),
        epsilon: planes.epsilon_fraction,
        epsilon_world: planes.epsilon,
        max_error_world: planes.max_error,
        mean_error_world: planes.mean_error,
        seam_gap_world: planes.seam_gap,
        atlas: CloudAtlas {
            width: layout.layout.width,
            height: layout.layout.height,
            texel_density: layout.layout.texel_density,
            screen_size: level_settings.screen_size,
            occupancy: (layout.layout.occupancy * 1e4).round() / 1e4,
            coverage: atlas_coverage,
        },
    };
    let figures = LevelFigures {
        representation: Representation::BillboardCloud,
        triangles: 2 * layout.layout.placements.len() as u64,
        bytes: bytes as u64,
        gpu_bytes,
        surfaces: SurfaceFigures::of(written.infos),
        detail: LevelDetail::Cloud(cloud),
    };
    let report = LevelReport::new(level, folder, figures);
    Ok((report, ChainMesh::Cloud(Box::new(chain))))
}

pub(super) enum ChainMesh {
    Cloud(Box<lod_mesh::LodGltfMesh>),
    Reduced(reduced::ReducedGltf),
    Impostor(impostor_level::ImpostorGltf),
}
