//! A LOD chain's own outputs, once every slot's files are made (`level_files`) and measured
//! (`chain_queries`): each level's part of the report (an `Auto` level's choice among its
//! candidates, the chosen one's files copied into its folder), and the chain's documents:
//! `lods.gltf` with its switch coverages, `lods.json` for engines.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use super::chain_queries::{auto_bytes, chain_holds, chosen_slots};
use super::level_outputs::{level_files, ChainMesh};
use super::report::{AutoReport, CandidateReport, LevelReport, LodsDocument, LodsLevel, SurfaceFigures, SwitchFigures};
use super::settings::Settings as Own;
use super::{levels, lod_mesh, planes, report, settings};
use crate::db::{Asset, Db};
use crate::diagnostic::Diagnostic;
use crate::kinds::mesh_queries::loaded_mesh;
use crate::kinds::AssetOutputs;
use crate::mesh::gltf::{gltf_chain, GltfLevel};
use crate::summary::ArtifactRole;

/// A chain's `lods.gltf` and `lods.json` (added to `outputs`, with a warning for each level never
/// shown), each level's part of the report (its chosen slot's, with its `Auto` choice and its
/// switch size) and the switch coverages, from every slot's part of the report and mesh
/// (`level_files`).
pub(super) fn chain_files(
    db: &dyn Db,
    asset: Asset,
    output_folder: &Path,
    (slot_reports, slot_meshes): (&[LevelReport], Vec<ChainMesh>),
    outputs: &mut AssetOutputs,
) -> Result<(Vec<f32>, Vec<LevelReport>), Diagnostic> {
    let settings = asset.settings(db);
    let holds = chain_holds(db, asset)?;
    let chosen = chosen_slots(db, asset, slot_reports, &holds)?;
    let mut meshes: Vec<Option<ChainMesh>> = slot_meshes.into_iter().map(Some).collect();
    let mut level_reports = Vec::new();
    let mut chain = Vec::new();
    let mut level_holds = Vec::new();
    for (level, &slot) in chosen.iter().enumerate() {
        let folder = levels::chain_folder(settings, level as u32);
        let mut level_report = slot_reports[slot as usize].clone();
        if let Some(auto) = auto_report(db, asset, level as u32, slot, (slot_reports, &holds)) {
            copy_candidate(outputs, output_folder, &levels::level_folder(settings, slot), &folder, level);
            level_report.folder = folder.clone();
            level_report.auto = Some(auto);
        }
        let mesh = meshes[slot as usize].take().expect("each level's own slot");
        chain.push(ChainLevel { folder, mesh });
        level_reports.push(level_report);
        level_holds.push(holds[slot as usize].clone());
    }
    let switch_sizes = crate::preview::switch_sizes(&level_holds);
    let never_shown = never_shown_warnings(asset.main_file(db), &switch_sizes);
    outputs.warnings.extend(never_shown.iter().map(crate::summary::ErrorSummary::from));
    let (document, coverage) = chain_document(&chain, &switch_sizes);
    outputs.add(output_folder.join("lods.gltf"), ArtifactRole::Gltf, document.into());
    for ((report, hold), &switch_size) in level_reports.iter_mut().zip(&level_holds).zip(&switch_sizes) {
        report.switch = Some(SwitchFigures { switch_size, holds_to: hold.holds_to, measured: hold.measured.clone() });
    }
    let loaded = loaded_mesh(db, asset)?;
    let sphere = planes::bounding_sphere(&loaded.mesh.positions);
    let lods_json = lods_document(asset.name(db), sphere, &level_reports);
    outputs.add(output_folder.join("lods.json"), ArtifactRole::Table, lods_json.into());
    Ok((coverage, level_reports))
}

/// An `Auto` level's part of the report (none for another level): its bytes, the candidate
/// chosen, and every candidate's bytes and figures.
fn auto_report(
    db: &dyn Db,
    asset: Asset,
    level: u32,
    chosen: u32,
    (reports, holds): (&[LevelReport], &[crate::preview::Hold]),
) -> Option<AutoReport> {
    let settings = asset.settings(db);
    let Some(settings::LodLevel::Auto { max_bytes }) = settings.own::<Own>().billboard.lods.get(level as usize) else {
        return None;
    };
    let slots = levels::slots(settings);
    let candidates = (0..slots.len())
        .filter(|&slot| slots[slot].level == level)
        .map(|slot| {
            // Each surface's side: the albedo's, the others' at a half or a quarter of it where
            // that let the albedo double (`levels::allot_surfaces`); a reduced level's by
            // material (`bark/albedo`).
            let side = |surface: &SurfaceFigures| {
                let kind = surface.info.surface.name();
                let name = match &surface.material {
                    Some(material) => format!("{material}/{kind}"),
                    None => kind.to_string(),
                };
                (name, surface.info.width)
            };
            let figures = &reports[slot].figures;
            CandidateReport {
                name: slots[slot].candidate.clone(),
                folder: levels::level_folder(settings, slot as u32),
                representation: figures.representation,
                surface_sides: figures.surfaces.iter().map(side).collect(),
                gpu_bytes: figures.gpu_bytes,
                hold: holds[slot].clone(),
            }
        })
        .collect();
    Some(AutoReport { max_bytes: *max_bytes, chosen: slots[chosen as usize].candidate.clone(), candidates })
}

/// The copies of the chosen candidates' files in their `Auto` levels' folders (`copy_candidate`):
/// what the `switch` stage writes beside the chain's documents.
pub(super) fn chosen_copies(db: &dyn Db, asset: Asset, output_folder: &Path) -> Vec<PathBuf> {
    let settings = asset.settings(db);
    if !(0..levels::level_count(settings)).any(|level| auto_bytes(settings, level).is_some()) {
        return Vec::new();
    }
    let mut outputs = AssetOutputs::default();
    let (Ok((reports, _)), Ok(holds)) = (level_files(db, asset, output_folder, &mut outputs), chain_holds(db, asset))
    else {
        return Vec::new();
    };
    let Ok(chosen) = chosen_slots(db, asset, &reports, &holds) else { return Vec::new() };
    let first_copy = outputs.files.len();
    for (level, &slot) in chosen.iter().enumerate() {
        if auto_bytes(settings, level as u32).is_some() {
            let (from, to) = (levels::level_folder(settings, slot), levels::chain_folder(settings, level as u32));
            copy_candidate(&mut outputs, output_folder, &from, &to, level);
        }
    }
    outputs.files.drain(first_copy..).map(|(path, _, _)| path).collect()
}

/// Adds copies of a chosen candidate's files (under `from`, inside `output_folder`) in its
/// level's folder `to`, meaning that level.
fn copy_candidate(outputs: &mut AssetOutputs, output_folder: &Path, from: &str, to: &str, level: usize) {
    let (from, to) = (output_folder.join(from), output_folder.join(to));
    let copies: Vec<(PathBuf, ArtifactRole, Arc<[u8]>)> = outputs
        .files
        .iter()
        .filter_map(|(path, role, bytes)| {
            let rest = path.strip_prefix(&from).ok()?;
            Some((to.join(rest), *role, bytes.clone()))
        })
        .collect();
    for (path, role, bytes) in copies {
        outputs.meanings.insert(path.clone(), report::file_meaning(level as u32, None));
        outputs.add(path, role, bytes);
    }
}

/// A warning (naming `file`, the asset's mesh) for each level of a chain with these switch
/// sizes that is never shown.
fn never_shown_warnings(file: &Path, switch_sizes: &[u32]) -> Vec<Diagnostic> {
    use crate::preview::NeverShown;
    crate::preview::never_shown_levels(switch_sizes)
        .into_iter()
        .map(|(level, why)| {
            let why = match why {
                NeverShown::HoldsAtNoSize => {
                    "it holds within one px-shift unit at no screen size measured (16 px and up)".to_string()
                }
                NeverShown::NextHoldsAsFar(size) => format!("lod{} holds as far, up to {size} px", level + 1),
            };
            Diagnostic::new(
                file,
                format!("lod{level} of the chain is never shown, and costs its bytes for nothing: {why}"),
            )
        })
        .collect()
}

/// A chain's `lods.json` for engines ([`LodsDocument`]): the bounding sphere whose diameter on
/// screen picks a level, and each level's glTF, representation, bytes and switch size (from
/// `reports`, the levels' parts of the report with their switch sizes).
fn lods_document(asset: &str, (center, radius): (glam::Vec3, f32), reports: &[LevelReport]) -> Vec<u8> {
    let levels = reports
        .iter()
        .map(|report| LodsLevel {
            level: report.level,
            gltf: format!("{}/lod.gltf", report.folder),
            representation: report.figures.representation,
            triangles: report.figures.triangles,
            gpu_bytes: report.figures.gpu_bytes,
            switch_size: report.switch.as_ref().map(|switch| switch.switch_size),
        })
        .collect();
    let document = LodsDocument {
        asset,
        center: center.to_array(),
        radius,
        switch_size_unit: "pixels across the bounding sphere on screen",
        levels,
    };
    let mut bytes = report::sorted_json(&document);
    bytes.push(b'\n');
    bytes
}

/// One level as the chain's document draws it.
struct ChainLevel {
    folder: String,
    mesh: ChainMesh,
}

/// A chain's `lods.gltf` (`MSFT_lod`, every level's `lod.bin` and images under its folder, the
/// switch coverages from the measured `switch_sizes`) and those coverages.
fn chain_document(levels: &[ChainLevel], switch_sizes: &[u32]) -> (Vec<u8>, Vec<f32>) {
    let gltf_levels: Vec<GltfLevel> = levels
        .iter()
        .map(|level| GltfLevel {
            mesh: match &level.mesh {
                ChainMesh::Cloud(mesh) => mesh.mesh(),
                ChainMesh::Reduced(mesh) => mesh.mesh(),
                ChainMesh::Impostor(quad) => quad.mesh(),
            },
            folder: &level.folder,
        })
        .collect();
    let coverage = lod_mesh::screen_coverage(switch_sizes);
    (gltf_chain(&gltf_levels, "lod.bin", &coverage, crate::mesh::gltf::GENERATOR), coverage)
}
