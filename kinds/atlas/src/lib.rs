//! The `Atlas` kind (DESIGN §3.5): textures named by globs, trimmed, equal ones merged, packed
//! onto pages (`packing::max_rects`), each page composited (`page`) and sent through the shared
//! tail as `atlas.ktx2` / `atlas_N.ktx2`, with the table `atlas.json` (`table`). The last layout
//! is the packer's hint (`pack_pages_keeping`), so an edit moves nothing; the last page is the
//! composite's start, so an edit re-composites its own rectangle.

// The machinery this kind builds on, under the names its files use (`crate::db`, …).
use cirrus_core::{cache, config, db, diagnostic, gpu, kinds, mesh, packing, sources, summary, texture};

pub mod settings;
pub mod page;
pub mod preview;
pub mod queries;
pub mod remap;
pub mod table;

use crate::summary::ArtifactRole;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::cache::CacheKey;
use crate::config::{AssetConfig, PipelineConfig};
use crate::db::{Asset, Db, StageRun, DECODE};
use crate::diagnostic::{display_path, Diagnostic};
use crate::kinds::checks::check_texture_file;
use crate::kinds::source_copies::{material_copy_paths, output_materials, MaterialPlaces, OutputMaterial};
use crate::kinds::{
    tail_instances, AssetOutputs, Job, Kind, Read, StageInstance, SurfaceFn, SurfaceId, SurfacePart, SurfacePlan, Task,
};
use crate::texture::{SurfaceKind, Texture};

use crate::settings::Settings as Own;
use queries::{
    atlas_layout, atlas_layout_and_change, atlas_mesh_files, atlas_page, atlas_texture_files, mesh_library_paths,
    mesh_map_paths, page_group, page_label, page_recipe_key, page_stem, remapped_mesh, remapped_mesh_file,
    remapped_mesh_path, COMPOSITE, LAYOUT, REACH, REMAP, TRIM,
};
use table::{AtlasPage, Table};

pub struct Atlas;

/// The kind, as `pipeline.ron` and the driver name it.
pub const KIND: crate::config::AssetKind =
    crate::config::AssetKind::new(<settings::Settings as crate::config::KindEntry>::NAME, &QUESTIONS);
const QUESTIONS: crate::kinds::KindQuestions = crate::kinds::KindQuestions::of::<Atlas>();

/// The tail surface of page `page`.
fn page_surface(page: u32) -> SurfaceId {
    SurfaceId { group: page_group(page), surface: SurfaceKind::Albedo, part: SurfacePart { index: page, item: None } }
}

/// The page a surface of this kind is.
fn surface_page(surface: &SurfaceId) -> u32 {
    surface.part.index
}

/// A page's texture and preview files.
fn page_files(output_folder: &Path, page: u32, container: crate::config::Container) -> [PathBuf; 2] {
    let stem = page_stem(page);
    [output_folder.join(format!("{stem}.{}", container.extension())), output_folder.join(format!("{stem}.png"))]
}

/// The atlas kind's steps: the layout (then its pages and meshes), and one mesh's remap.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Step {
    Layout,
    /// The `mesh`-th of the asset's meshes.
    Remap {
        mesh: u32,
    },
}

impl crate::kinds::KindStep for Step {
    type Kind = Atlas;

    fn sort(&self) -> &'static str {
        match self {
            Step::Layout => "layout",
            Step::Remap { .. } => "remap",
        }
    }
}

impl Kind for Atlas {
    fn files_to_read(db: &dyn Db, asset: Asset) -> Vec<PathBuf> {
        let mut files: Vec<PathBuf> = asset.listed(db).iter().flatten().cloned().collect();
        for mesh in atlas_mesh_files(db, asset) {
            files.extend(mesh_library_paths(db, asset, mesh));
            // The maps they name: a remapped mesh must not point at a texture that is gone.
            files.extend(mesh_map_paths(db, asset, mesh));
        }
        files.sort();
        files.dedup();
        files
    }

    fn first_jobs(db: &dyn Db, asset: Asset) -> Vec<Job> {
        vec![Job { asset, task: Task::step(Step::Layout), after: 0, label: asset.name(db).clone() }]
    }

    type Step = Step;

    fn run_step(db: &dyn Db, asset: Asset, step: &Step) -> Result<Vec<Job>, Diagnostic> {
        match *step {
            Step::Layout => {
                let layout = atlas_layout(db, asset)?;
                let name = asset.name(db);
                let pages = (0..layout.packing.pages.len() as u32).map(|page| Job {
                    asset,
                    task: Task::Surface(page_surface(page)),
                    after: 1,
                    label: page_surface(page).label(name),
                });
                let meshes = atlas_mesh_files(db, asset).iter().enumerate().map(|(index, mesh)| Job {
                    asset,
                    task: Task::step(Step::Remap { mesh: index as u32 }),
                    after: 1,
                    label: format!("{name}/meshes/{}", display_path(&remapped_mesh_path(db, asset, mesh))),
                });
                Ok(pages.chain(meshes).collect())
            }
            // The mesh's own failure is reported by `outputs` (the other meshes are written).
            Step::Remap { mesh } => {
                let _ = remapped_mesh(db, asset, atlas_mesh_files(db, asset)[mesh as usize].clone());
                Ok(Vec::new())
            }
        }
    }

    fn stage_instances(db: &dyn Db, asset: Asset, output_folder: &Path, errors: &[Diagnostic]) -> Vec<StageInstance> {
        let name = asset.name(db);
        let report = output_folder.join("report.json");
        let mut pack = StageInstance::new(LAYOUT, name, name);
        let mut instances = Vec::new();
        // Where each mesh's UVs reach: an entry keeps at least that much of its texture.
        let meshes = atlas_mesh_files(db, asset);
        let mut reaches = Vec::new();
        for mesh in meshes {
            let relative = display_path(&remapped_mesh_path(db, asset, mesh));
            let mut reach = StageInstance::new(REACH, format!("{name}/meshes/{relative}"), format!("reach/{relative}"));
            reach.reads.push(Read::File(mesh.clone()));
            reach.reads.extend(mesh_library_paths(db, asset, mesh).into_iter().map(Read::File));
            pack = pack.reads_stage(&reach);
            reaches.push(reach);
        }
        let reached = queries::mesh_uv_reach(db, asset);
        for path in atlas_texture_files(db, asset) {
            let label = display_path(path);
            let mut decode = StageInstance::new(DECODE, &label, &label);
            decode.reads.push(Read::File(path.clone()));
            decode.shared = true;
            let mut trim = StageInstance::new(TRIM, &label, &label).reads_stage(&decode);
            trim.shared = true;
            if reached.contains_key(path) {
                for reach in &reaches {
                    trim = trim.reads_stage(reach);
                }
            }
            pack = pack.reads_stage(&trim);
            instances.extend([decode, trim]);
        }
        instances.extend(reaches);
        pack.writes = vec![output_folder.join("atlas.json"), report.clone()];
        let container = asset.settings(db).encode.container;
        let layout = atlas_layout(db, asset).ok();
        let mut tails = Vec::new();
        for (page, layout) in
            layout.iter().flat_map(|layout| (0..layout.packing.pages.len() as u32).map(move |page| (page, layout)))
        {
            // A page reads the layout, and the texels of its own entries only.
            let mut composite =
                StageInstance::new(COMPOSITE, page_label(name, page), page_group(page)).reads_stage(&pack);
            for (entry, _) in
                layout.entries.iter().zip(&layout.packing.placements).filter(|(_, place)| place.page == page)
            {
                composite.reads.push(Read::Stage(DECODE, display_path(&entry.file)));
            }
            let [mips, encode, mut write] =
                tail_instances(name, &page_surface(page), &composite, &page_files(output_folder, page, container));
            write.writes.push(report.clone());
            tails.extend([composite, mips, encode, write]);
        }
        for mesh in meshes {
            let relative = remapped_mesh_path(db, asset, mesh);
            let label = format!("{name}/meshes/{}", display_path(&relative));
            let mut remap =
                StageInstance::new(REMAP, &label, format!("meshes/{}", display_path(&relative))).reads_stage(&pack);
            remap.reads.push(Read::File(mesh.clone()));
            remap.reads.extend(mesh_library_paths(db, asset, mesh).into_iter().map(Read::File));
            let file = output_folder.join(remapped_mesh_file(db, asset, mesh));
            remap.writes = vec![
                file.clone(),
                file.with_extension("gltf"),
                file.with_extension("bin"),
                output_folder.join("atlas.mtl"),
                report.clone(),
            ];
            // The copies of the maps its materials keep (the bark's, beside the atlased leaves).
            if let Ok(remapped) = remapped_mesh(db, asset, mesh.clone()) {
                let chosen: Vec<OutputMaterial> =
                    remapped.materials.iter().map(|material| output_material(output_folder, material)).collect();
                remap.writes.extend(material_copy_paths(db, asset, output_folder, &chosen));
            }
            tails.push(remap);
        }
        instances.insert(0, pack);
        instances.extend(tails);
        // A mesh that could not be remapped fails its own stage; any other error fails them all.
        let mesh_error = |error: &Diagnostic| meshes.contains(&error.file);
        let others_failed = errors.iter().any(|error| !mesh_error(error));
        for instance in &mut instances {
            let fails_mesh = |error: &Diagnostic, path: &PathBuf| &error.file == path && mesh_error(error);
            let own_mesh_failed = instance.stage == REMAP
                && instance
                    .reads
                    .iter()
                    .any(|read| matches!(read, Read::File(path) if errors.iter().any(|error| fails_mesh(error, path))));
            instance.failed = others_failed || own_mesh_failed;
        }
        instances
    }

    fn outputs(
        db: &dyn Db,
        asset: Asset,
        output_folder: &Path,
        errors: &mut Vec<Diagnostic>,
        runs: &[StageRun],
    ) -> AssetOutputs {
        if !errors.is_empty() {
            return AssetOutputs::default();
        }
        match atlas_outputs(db, asset, output_folder, runs, errors) {
            Ok(outputs) => outputs,
            Err(diagnostic) => {
                errors.push(diagnostic);
                AssetOutputs::default()
            }
        }
    }

    /// Every texture the globs match is readable and within the limits (globs that match
    /// nothing are an error); every mesh loads, and its materials that use atlased maps keep
    /// their UVs inside [0, 1].
    fn check(config: &PipelineConfig, asset: &AssetConfig) -> Vec<Diagnostic> {
        let [textures, meshes] = &asset.source.glob_lists[..] else { return Vec::new() };
        let files = crate::sources::glob_matches(config, textures);
        if files.is_empty() {
            return vec![Diagnostic::new(
                &config.source,
                format!("atlas `{}`: no texture matches {textures:?}", asset.name),
            )];
        }
        let mut problems: Vec<Diagnostic> = files
            .iter()
            .filter_map(|path| check_texture_file(config, path).err().map(|message| Diagnostic::new(path, message)))
            .collect();
        for mesh_file in crate::sources::glob_matches(config, meshes) {
            let (mesh, warnings) = match crate::kinds::checks::check_mesh_file(config, &mesh_file) {
                Ok(loaded) => loaded,
                Err(diagnostic) => {
                    problems.push(diagnostic);
                    continue;
                }
            };
            problems.extend(warnings);
            let mut used = vec![false; mesh.materials.len()];
            for &material in &mesh.triangle_materials {
                used[material as usize] = true;
            }
            for (index, material) in mesh.materials.iter().enumerate().filter(|(index, _)| used[*index]) {
                let Some(atlased) = material.maps.values().find(|path| files.contains(path)) else { continue };
                let name = display_path(atlased.strip_prefix(&config.source).unwrap_or(atlased));
                if let Err(error) = remap::repeating_uvs(&mesh, index, &name) {
                    problems.push(Diagnostic::new(&mesh_file, error.to_string()));
                }
            }
            let atlased = |map: &Path| files.iter().any(|file| file == map);
            problems.extend(crate::kinds::checks::check_copied_maps(config, &mesh_file, &mesh, |map| !atlased(map)));
            if asset.settings.own::<Own>().pack.trim {
                problems.extend(uvs_beyond_trim(config, &mesh_file, &mesh, &files));
            }
        }
        problems
    }

    fn surface_plan(db: &dyn Db, asset: Asset, _surface: &SurfaceId) -> Result<SurfacePlan, Diagnostic> {
        let encode = &asset.settings(db).encode;
        let settings = crate::kinds::tail_settings_from(encode, SurfaceKind::Albedo, encode.albedo, None);
        let image: SurfaceFn<Arc<Texture>> = |db, asset, surface| atlas_page(db, asset, surface_page(surface));
        let recipe: SurfaceFn<Option<CacheKey>> =
            |db, asset, surface| page_recipe_key(db, asset, surface_page(surface)).map(Some);
        Ok(SurfacePlan::new(settings, recipe, image))
    }

    fn preview(
        db: &dyn Db,
        asset: Asset,
        config: &PipelineConfig,
        options: &crate::kinds::PreviewOptions,
    ) -> Result<crate::kinds::PreviewReport, crate::kinds::PreviewError> {
        preview::preview(db, asset, config, options)
    }
}

/// Warnings for the textures whose transparent border a mesh's UVs reach: the entry keeps those
/// texels too (trimming them would move the remapped UVs off the rectangle).
fn uvs_beyond_trim(
    config: &PipelineConfig,
    mesh_file: &Path,
    mesh: &crate::mesh::Mesh,
    files: &[PathBuf],
) -> Vec<Diagnostic> {
    let mut warnings = Vec::new();
    for (texture, reach) in remap::material_uv_reach(mesh, |path| files.iter().any(|file| file == path)) {
        let Ok(contents) = crate::sources::read_source(&config.root, &config.source, &texture) else { continue };
        let Ok(bytes) = contents.bytes() else { continue };
        let Ok(decoded) = crate::texture::decode_texture(&texture, &bytes, config.limits.texture) else {
            continue;
        };
        let trimmed = page::opaque_bounds(&decoded);
        let wanted = page::uv_texel_rect(reach.u, reach.v, [decoded.width, decoded.height]);
        if !trimmed.contains(wanted) {
            let kept = trimmed.union(wanted);
            warnings.push(
                Diagnostic::new(
                    mesh_file,
                    format!(
                        "its UVs (u ∈ [{}, {}], v ∈ [{}, {}]) reach the transparent border of `{}`: the atlas \
                        keeps {}×{} texels at ({}, {}) of it, not the {}×{} at ({}, {}) trimming alone would keep",
                        reach.u[0],
                        reach.u[1],
                        reach.v[0],
                        reach.v[1],
                        display_path(texture.strip_prefix(&config.source).unwrap_or(&texture)),
                        kept.width,
                        kept.height,
                        kept.x,
                        kept.y,
                        trimmed.width,
                        trimmed.height,
                        trimmed.x,
                        trimmed.y
                    ),
                )
                .as_warning(),
            );
        }
    }
    warnings
}

/// The pages, their previews, `atlas.json` and the report.
fn atlas_outputs(
    db: &dyn Db,
    asset: Asset,
    output_folder: &Path,
    runs: &[StageRun],
    errors: &mut Vec<Diagnostic>,
) -> Result<AssetOutputs, Diagnostic> {
    let laid_out = atlas_layout_and_change(db, asset)?;
    let (layout, change) = (&laid_out.0, &laid_out.1);
    let container = asset.settings(db).encode.container;
    let mut outputs = AssetOutputs::default();
    let mut pages = Vec::new();
    let mut surfaces = Vec::new();
    for (page, &(width, height)) in layout.packing.pages.iter().enumerate() {
        let page = page as u32;
        let artifacts = crate::kinds::tail_queries::surface_artifacts(db, asset, page_surface(page))?;
        let [texture_path, preview_path] = page_files(output_folder, page, container);
        pages.push(AtlasPage {
            file: display_path(texture_path.strip_prefix(output_folder).unwrap_or(&texture_path)),
            width,
            height,
        });
        outputs.add(texture_path, ArtifactRole::Texture, artifacts.texture_file.clone());
        outputs.add(preview_path, ArtifactRole::Image, artifacts.preview_png.clone());
        surfaces.push(artifacts.info.clone());
    }
    let entries = queries::atlas_table_entries(layout);
    let table = Table { pages, entries };
    outputs.add(output_folder.join("atlas.json"), ArtifactRole::Table, table.to_json().into_bytes().into());
    let mut warnings = Vec::new();
    let meshes = mesh_outputs(db, asset, output_folder, &mut outputs, errors, &mut warnings);
    let report = serde_json::json!({
        "asset": asset.name(db),
        "kind": KIND.name(),
        "entries": layout.entries.len(),
        "textures": atlas_texture_files(db, asset).len(),
        "pages": layout.packing.pages,
        "occupancy": (layout.packing.occupancy() * 1e4).round() / 1e4,
        "layout": change,
        // Entries that keep more than their opaque texels, because a mesh's UVs reach there.
        "kept_for_meshes": layout.entries.iter().filter_map(|entry| {
            let trimmed = entry.trimmed?;
            Some(serde_json::json!({
                "entry": entry.name,
                "trimmed": [trimmed.x, trimmed.y, trimmed.width, trimmed.height],
                "kept": [entry.trim.x, entry.trim.y, entry.trim.width, entry.trim.height],
            }))
        }).collect::<Vec<_>>(),
        "meshes": meshes,
        "warnings": warnings.iter().map(crate::summary::ErrorSummary::from).collect::<Vec<_>>(),
        "surfaces": surfaces,
        "stage_ms": crate::kinds::asset_stage_ms(asset.name(db), runs),
    });
    outputs.report = Some(serde_json::to_vec_pretty(&report).expect("reports serialise"));
    outputs.warnings = warnings.iter().map(crate::summary::ErrorSummary::from).collect();
    Ok(outputs)
}

/// The remapped meshes and `atlas.mtl` (one material per name): a mesh that cannot be remapped
/// (repeating UVs, two rectangles in one material, a material named like another mesh's but
/// different) fails alone with its diagnostic; the others are written, their load warnings
/// gathered in `warnings` (for the report). Gives the meshes written.
fn mesh_outputs(
    db: &dyn Db,
    asset: Asset,
    output_folder: &Path,
    outputs: &mut AssetOutputs,
    errors: &mut Vec<Diagnostic>,
    warnings: &mut Vec<Diagnostic>,
) -> Vec<String> {
    let meshes = atlas_mesh_files(db, asset);
    if meshes.is_empty() {
        return Vec::new();
    }
    let mut materials: std::collections::BTreeMap<String, (remap::RemappedMaterial, PathBuf)> =
        std::collections::BTreeMap::new();
    let mut written = Vec::new();
    for mesh in meshes {
        let remapped = match remapped_mesh(db, asset, mesh.clone()) {
            Ok(remapped) => remapped,
            Err(diagnostic) => {
                errors.push(diagnostic);
                continue;
            }
        };
        let clash = remapped.materials.iter().find_map(|material| {
            let (other, other_mesh) = materials.get(&material.material.name)?;
            (other != material).then(|| (material.material.name.clone(), other_mesh.clone()))
        });
        if let Some((name, other_mesh)) = clash {
            errors.push(Diagnostic::new(
                mesh,
                format!(
                    "mesh `{}`: material `{name}` differs from the material of that name in `{}`; atlas.mtl holds one \
                        material per name (rename one)",
                    display_path(mesh),
                    display_path(&other_mesh)
                ),
            ));
            continue;
        }
        for material in &remapped.materials {
            materials.entry(material.material.name.clone()).or_insert_with(|| (material.clone(), mesh.clone()));
        }
        let file = remapped_mesh_file(db, asset, mesh);
        let obj_path = output_folder.join(&file);
        if outputs.files.iter().any(|(written, _, _)| *written == obj_path) {
            errors.push(Diagnostic::new(
                mesh,
                format!(
                    "mesh `{}` would be written as `{}`, the name another mesh of the asset takes (folders \
                        join the name with `-`): rename one",
                    display_path(mesh),
                    display_path(&file)
                ),
            ));
            continue;
        }
        warnings.extend(remapped.warnings.iter().cloned());
        let places = MaterialPlaces { source: mesh, mtl_folder: output_folder, gltf_folder: output_folder };
        let chosen: Vec<OutputMaterial> =
            remapped.materials.iter().map(|material| output_material(output_folder, material)).collect();
        let named = output_materials(db, asset, output_folder, outputs, &chosen, &places);
        warnings.extend(named.warnings);
        if !named.errors.is_empty() {
            errors.extend(named.errors);
            continue;
        }
        let stem = obj_path.file_stem().map_or_else(|| "mesh".into(), |stem| stem.to_string_lossy().into_owned());
        let gltf = crate::mesh::gltf::gltf_files(
            &remapped.geometry.mesh(&stem, &named.gltf),
            &format!("{stem}.bin"),
            crate::mesh::gltf::GENERATOR,
        );
        outputs.add(obj_path.clone(), ArtifactRole::Mesh, remapped.obj.clone().into_bytes().into());
        outputs.add(obj_path.with_extension("gltf"), ArtifactRole::Gltf, gltf.gltf.into());
        outputs.add(obj_path.with_extension("bin"), ArtifactRole::GltfBuffer, gltf.bin.into());
        written.push(display_path(&file));
    }
    let chosen: Vec<OutputMaterial> =
        materials.values().map(|(material, _)| output_material(output_folder, material)).collect();
    let places = MaterialPlaces { source: asset.main_file(db), mtl_folder: output_folder, gltf_folder: output_folder };
    // (Its maps are the meshes' own, whose problems the meshes' calls above reported.)
    let named = output_materials(db, asset, output_folder, outputs, &chosen, &places);
    let mut mtl = format!("# cirrus: materials of the meshes remapped onto atlas `{}`\n\n", asset.name(db));
    mtl.push_str(&named.mtl);
    outputs.add(output_folder.join("atlas.mtl"), ArtifactRole::Mtl, mtl.into_bytes().into());
    // Each mesh's glTF and the shared MTL name the same maps: one warning per problem.
    let mut seen = std::collections::HashSet::new();
    warnings.retain(|warning| seen.insert((warning.file.clone(), warning.message.clone())));
    written
}

/// A remapped material as the output names it: its atlased maps are the page's image.
fn output_material<'a>(output_folder: &Path, material: &'a remap::RemappedMaterial) -> OutputMaterial<'a> {
    let baked = match material.page {
        Some(page) => material
            .atlased
            .iter()
            .map(|&slot| (slot, output_folder.join(format!("{}.png", page_stem(page)))))
            .collect(),
        None => Default::default(),
    };
    OutputMaterial { material: &material.material, baked }
}
