//! The `BillboardCloud` kind: a mesh turned into a cloud of textured quads (planes → rectangles
//! → layout → per-group renders → atlas) whose four atlas surfaces end in the shared texture
//! tail, plus `lod.obj` / `lod.mtl`; and `cirrus preview`, which compares the source with the
//! baked LOD.
//!
//! A LOD chain (`lods: [Quads(512), Quads(128), …]`) bakes one level per budget into `lod<N>/`,
//! each with its own planes, layout, renders, atlas and `lod.obj`, all reading the one mesh
//! stage; without a chain the one level goes to the asset's folder.
//!
//! Jobs: one `layout` per level (mesh, planes and layout on a worker, wave 0), then the level's
//! LOD and, when some of its atlas surfaces are not in the cache, the loads the renders need
//! (`render-memo`, the surfaces' last encodings, and one `upload` per material texture from the
//! first level that renders) followed by one `render` per render group (wave 1), then the four
//! atlas surfaces through the tail (wave 2).

// The machinery this kind builds on, under the names its files use (`crate::db`, …).
use cirrus_core::{
    cache, config, db, diagnostic, files, gpu, impostor, kinds, mesh, packing, preview, stop, summary, texture,
};

pub mod settings;
pub mod planes;
pub mod rectangles;
pub mod layout;
pub mod render_groups;
pub mod atlas;
pub mod lod_mesh;
pub mod lod_preview;
pub mod levels;
mod report;
pub mod reduced;
pub mod queries;
mod reduced_queries;
mod surfaces;
mod reduced_outputs;
pub mod impostor_level;
mod views;
mod level_outputs;
mod chain_queries;
pub mod chain_outputs;

pub use views::read_level_view;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::cache::CacheKey;
use crate::config::{AssetConfig, PipelineConfig};
use crate::db::{Asset, Db, StageRun};
use crate::diagnostic::{display_path, Diagnostic};
use crate::kinds::checks::check_texture_file;
use crate::kinds::mesh_queries::{loaded_mesh, mesh_textures, LoadedMesh};
use crate::kinds::{
    tail_instances, AssetOutputs, Job, Kind, PreviewError, PreviewOptions, PreviewReport, PreviewRow, StageInstance,
    SurfaceId, SurfacePlan, Task,
};
use crate::settings::Settings as Own;
use crate::summary::ErrorSummary;
use crate::texture::{SurfaceKind, Texture, TextureSlot};
use queries::{billboard_layout, level_label, lod_files, render_label, source_view_mesh};
use queries::{ATLAS, LAYOUT, LOD, PLANES, RENDER};
use surfaces::{level_renders, level_surfaces, read_decode, reduced_map_of, slot_of_surface, with_halvings};

pub struct BillboardCloud;

/// The kind, as `pipeline.ron` and the driver name it.
pub const KIND: crate::config::AssetKind =
    crate::config::AssetKind::new(<settings::Settings as crate::config::KindEntry>::NAME, &QUESTIONS);
const QUESTIONS: crate::kinds::KindQuestions = crate::kinds::KindQuestions::of::<BillboardCloud>();

/// Every (material, slot) whose texture the renders sample, in material order.
fn material_texture_slots(loaded: &LoadedMesh) -> Vec<(usize, TextureSlot)> {
    if loaded.mesh.uvs.is_none() {
        return Vec::new();
    }
    let materials = loaded.mesh.materials.iter().enumerate();
    materials.flat_map(|(index, material)| material.maps.keys().map(move |&slot| (index, slot))).collect()
}

/// The billboard kind's steps, each of one LOD level: its planes and layout (then the rest), a
/// source texture's upload to the GPU, the render memo's load, one render batch, the LOD mesh.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Step {
    Layout {
        level: u32,
    },
    Upload {
        texture: u32,
    },
    RenderMemo {
        level: u32,
    },
    Render {
        level: u32,
        batch: u32,
    },
    Lod {
        level: u32,
    },
    /// A chain's levels measured against the source (its switch sizes).
    Switch,
}

impl crate::kinds::KindStep for Step {
    type Kind = BillboardCloud;

    fn sort(&self) -> &'static str {
        match self {
            Step::Layout { .. } => "layout",
            Step::Upload { .. } => "upload",
            Step::RenderMemo { .. } => "render-memo",
            Step::Render { .. } => "render",
            Step::Lod { .. } => "lod",
            Step::Switch => "switch",
        }
    }
}

/// What a billboard cloud holds from its bake until its group publishes per texel it renders
/// and packs (`levels::estimated_texels`, counted once per render and per encoded surface):
/// about 130 MiB for a corpus tree's three-level Auto chain of 53 M estimated texels, its
/// sources (5.2 M texels) counted apart.
const HELD_BYTES_PER_MADE_TEXEL: u64 = 2;

impl Kind for BillboardCloud {
    fn keep_memos(db: &mut dyn Db, surfaces: usize) {
        queries::keep_memos(db, surfaces);
        reduced_queries::keep_memos(db, surfaces);
    }

    /// Every level's renders and atlases (`levels::estimated_texels`, `cirrus check`'s measure),
    /// at `HELD_BYTES_PER_MADE_TEXEL`.
    fn made_bytes(db: &dyn Db, asset: Asset) -> u64 {
        let settings = asset.settings(db);
        let texels: u64 = (0..levels::slot_count(settings)).map(|slot| levels::estimated_texels(settings, slot)).sum();
        texels * HELD_BYTES_PER_MADE_TEXEL
    }

    fn files_to_read(db: &dyn Db, asset: Asset) -> Vec<PathBuf> {
        let mut files = crate::kinds::mesh_queries::mesh_files(db, asset);
        files.extend(mesh_textures(db, asset).iter().cloned());
        files
    }

    fn first_jobs(db: &dyn Db, asset: Asset) -> Vec<Job> {
        let levels = 0..levels::slot_count(asset.settings(db));
        let mut jobs: Vec<Job> = levels
            .clone()
            .map(|level| Job {
                asset,
                task: Task::step(Step::Layout { level }),
                after: 0,
                label: level_label(db, asset, level).clone(),
            })
            .collect();
        // When some level will render, the GPU starts, and for a cloud's renders the textures
        // are decoded, filtered and uploaded beside the planes (which run on one thread), not
        // after them.
        if levels.clone().any(|level| level_renders(db, asset, level)) {
            crate::gpu::start_gpu_in_background();
        }
        let settings = asset.settings(db);
        if levels.clone().any(|level| levels::is_cloud(settings, level) && level_renders(db, asset, level)) {
            let uploads = loaded_mesh(db, asset).map_or(0, |loaded| material_texture_slots(&loaded).len() as u32);
            let name = asset.name(db);
            jobs.extend((0..uploads).map(|texture| Job {
                asset,
                task: Task::step(Step::Upload { texture }),
                after: 0,
                label: format!("{name}/upload{texture}"),
            }));
        }
        jobs
    }

    type Step = Step;

    fn run_step(db: &dyn Db, asset: Asset, step: &Step) -> Result<Vec<Job>, Diagnostic> {
        let name = asset.name(db);
        match *step {
            Step::Layout { level } => {
                let mut jobs = level_jobs(db, asset, level)?;
                if level == 0 && levels::is_chain(asset.settings(db)) {
                    // The chain is measured once every level's surfaces are (wave 2).
                    let label = format!("{name}/switch");
                    jobs.push(Job { asset, task: Task::step(Step::Switch), after: 3, label });
                }
                Ok(jobs)
            }
            Step::RenderMemo { level } => {
                queries::stored_renders(db, asset, level);
                Ok(Vec::new())
            }
            Step::Upload { texture } => {
                // Errors are the renders' to report.
                let loaded = loaded_mesh(db, asset)?;
                if let Some(&(material, slot)) = material_texture_slots(&loaded).get(texture as usize) {
                    if let (Ok(Some(levels)), Ok(gpu)) =
                        (queries::material_texture_mips(db, asset, material as u32, slot), crate::gpu::gpu())
                    {
                        gpu.upload_material_mips(&levels, slot, queries::billboard_alpha_cutoff(db, asset));
                    }
                }
                Ok(Vec::new())
            }
            Step::Render { level, batch } => {
                let groups =
                    queries::level_render_batches(db, asset, level).get(batch as usize).cloned().unwrap_or_default();
                for group in groups {
                    queries::plane_images(db, asset, level, group)?;
                }
                Ok(Vec::new())
            }
            Step::Lod { level } => lod_files(db, asset, level).map(|_| Vec::new()),
            Step::Switch => {
                // A level's errors are its own jobs' to report (the outputs need every level).
                let _ = chain_queries::chain_holds(db, asset);
                Ok(Vec::new())
            }
        }
    }

    fn stage_instances(db: &dyn Db, asset: Asset, output_folder: &Path, errors: &[Diagnostic]) -> Vec<StageInstance> {
        let main_file = asset.main_file(db);
        let mesh_label = display_path(main_file);
        let failed = !errors.is_empty();
        let report = output_folder.join("report.json");
        let mut mesh = crate::kinds::mesh_queries::mesh_instance(db, asset);
        mesh.writes.push(report.clone());
        let mut instances = vec![mesh.clone()];
        let mut decodes = BTreeMap::new();
        // A chain's levels measured against the source: it reads the mesh and every level's
        // files, and writes the chain's documents.
        let mut switch = StageInstance::new(queries::SWITCH, asset.name(db), "lods").reads_stage(&mesh);
        for level in 0..levels::slot_count(asset.settings(db)) {
            let folder = levels::level_folder(asset.settings(db), level);
            let label = level_label(db, asset, level);
            let instance = if folder.is_empty() { mesh_label.clone() } else { folder.clone() };
            if levels::is_reduced(asset.settings(db), level) {
                let reduce = reduced_outputs::reduce_instances(
                    db,
                    asset,
                    level,
                    (output_folder, &report),
                    (&mesh, &mut decodes),
                );
                // `reduce`, then each map's `maps`, `mips`, `encode` and `write`: the switch reads
                // `reduce` and each `write`.
                switch = switch.reads_stage(&reduce[0]);
                switch = reduce[1..].iter().skip(3).step_by(4).fold(switch, |switch, write| switch.reads_stage(write));
                instances.extend(reduce);
                continue;
            }
            if levels::is_impostor(asset.settings(db), level) {
                let mut impostor =
                    impostor_level::impostor_instance(db, asset, level, (output_folder, &mesh), &mut decodes);
                impostor.writes.push(report.clone());
                let tails = level_tail_instances(db, asset, level, (output_folder, &report), &impostor);
                switch = reads_level_end(switch, &tails);
                instances.push(impostor);
                instances.extend(tails);
                continue;
            }
            let planes = StageInstance::new(PLANES, label, &instance).reads_stage(&mesh);
            let layout = StageInstance::new(LAYOUT, label, &instance).reads_stage(&mesh).reads_stage(&planes);
            let mut atlas = StageInstance::new(ATLAS, label, &instance).reads_stage(&layout);
            let mut lod = StageInstance::new(LOD, label, &instance).reads_stage(&layout);
            let level_folder = output_folder.join(&folder);
            lod.writes = ["lod.obj", "lod.mtl", "lod.gltf", "lod.bin"].map(|file| level_folder.join(file)).to_vec();
            instances.extend([planes.clone(), layout.clone()]);
            let renders = level_render_instances(db, asset, level, [&mesh, &planes, &layout], &mut decodes);
            for render in &renders {
                atlas = atlas.reads_stage(render);
            }
            instances.extend(renders);
            let tails = level_tail_instances(db, asset, level, (output_folder, &report), &atlas);
            switch = reads_level_end(switch.reads_stage(&lod), &tails);
            atlas.writes.push(report.clone());
            instances.push(atlas);
            instances.extend(tails);
            instances.push(lod);
        }
        if levels::is_chain(asset.settings(db)) {
            switch.writes = vec![output_folder.join("lods.gltf"), output_folder.join("lods.json"), report];
            if !failed {
                switch.writes.extend(chain_outputs::chosen_copies(db, asset, output_folder));
            }
            instances.push(switch);
        }
        instances.extend(decodes.into_values());
        for instance in &mut instances {
            instance.failed = failed;
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
        crate::kinds::outputs_unless_failed(errors, || billboard_outputs(db, asset, output_folder, runs))
    }

    /// The mesh loads with its material libraries, and every texture its materials name is
    /// readable and within the limits; warnings are reported as problems too.
    fn check(config: &PipelineConfig, asset: &AssetConfig) -> Vec<Diagnostic> {
        let main_file = &config.source.join(asset.source.main_file());
        let (mesh, mut problems) = match crate::kinds::checks::check_mesh_file(config, main_file) {
            Ok(loaded) => loaded,
            Err(diagnostic) => return vec![diagnostic],
        };
        let textures: std::collections::BTreeSet<&PathBuf> =
            mesh.materials.iter().flat_map(|material| material.maps.values()).collect();
        for path in textures {
            if let Err(message) = check_texture_file(config, path) {
                problems.push(Diagnostic::new(path, message));
            }
        }
        let costly = levels::costly_slot_warnings(&asset.settings);
        problems.extend(costly.into_iter().map(|message| Diagnostic::new(&config.file, message).as_warning()));
        problems
    }

    fn surface_plan(db: &dyn Db, asset: Asset, surface: &SurfaceId) -> Result<SurfacePlan, Diagnostic> {
        let settings = asset.settings(db);
        let encode = &settings.encode;
        let alpha_cutoff =
            (surface.surface == SurfaceKind::Albedo).then_some(settings.own::<Own>().billboard.alpha_cutoff);
        let tail =
            crate::kinds::tail_settings_from(encode, surface.surface, encode.format_of(surface.surface), alpha_cutoff);
        Ok(SurfacePlan {
            settings: tail,
            // The atlas's (and an impostor's) other surfaces are cut out by its albedo.
            cutting: (surface.surface != SurfaceKind::Albedo).then(|| surface.sibling(SurfaceKind::Albedo)),
            recipe: surface_recipe_key,
            parts: surface_parts_key,
            image: surface_image,
        })
    }

    fn preview(
        db: &dyn Db,
        asset: Asset,
        config: &PipelineConfig,
        options: &PreviewOptions,
    ) -> Result<PreviewReport, PreviewError> {
        let previewed = preview_levels(db, asset, config, options)?;
        let settings = asset.settings(db);
        let chain = previewed.len() > 1 || previewed.iter().any(|&(level, _)| level > 0) || options.lod.is_some();
        let several = previewed.len() > 1;
        let rows = previewed
            .into_iter()
            .map(|(level, metrics)| PreviewRow {
                label: chain.then(|| format!("lod{level}")),
                metrics,
                folder: options.out.join(levels::chain_folder(settings, level)),
            })
            .collect();
        Ok(PreviewReport { rows, chain_sheet: several.then(|| options.out.join("contact_sheet.png")) })
    }
}

/// The image of one of the asset's surfaces: a reduced level's map, an impostor's frames, a
/// cloud's atlas surface (each stored at its size, or at a level of its mip chain).
fn surface_image(db: &dyn Db, asset: Asset, surface: &SurfaceId) -> Result<Arc<Texture>, Diagnostic> {
    if let Some((material, halvings)) = reduced_map_of(db, asset, surface)? {
        return reduced_queries::reduced_map_image(db, asset, (material, halvings), surface);
    }
    let level = slot_of_surface(db, asset, surface)?;
    let halvings = queries::level_settings(db, asset, level).surface_halvings.of(surface.surface);
    // Stored at its size, or (an `Auto` candidate's) at a level of its mip chain.
    let stored = |image: &Texture| {
        let settings = crate::texture::mips::MipSettings { kind: surface.surface, alpha_cutoff: None };
        crate::texture::mips::reduced_level(image, settings, halvings)
    };
    if levels::is_impostor(asset.settings(db), level) {
        let frames = queries::impostor_frames(db, asset, level)?;
        return Ok(Arc::new(stored(match surface.surface {
            SurfaceKind::Normal => &frames.normal,
            SurfaceKind::Height => &frames.depth,
            _ => &frames.albedo,
        })));
    }
    let image = queries::atlas_surface(db, asset, level, surface.surface)?;
    Ok(match halvings {
        0 => image,
        _ => Arc::new(stored(&image)),
    })
}

/// What a surface's image is made of (`SurfacePlan::recipe`).
fn surface_recipe_key(db: &dyn Db, asset: Asset, surface: &SurfaceId) -> Result<Option<CacheKey>, Diagnostic> {
    if let Some((material, halvings)) = reduced_map_of(db, asset, surface)? {
        return reduced_queries::reduced_map_key(db, asset, (material, halvings), surface.surface).map(Some);
    }
    let level = slot_of_surface(db, asset, surface)?;
    let key = match levels::is_impostor(asset.settings(db), level) {
        true => queries::impostor_recipe_key(db, asset, level),
        false => queries::atlas_recipe_key(db, asset, level),
    };
    Ok(Some(with_halvings(db, asset, level, surface, key)))
}

/// What a cloud level's atlas surface is put together from (`SurfacePlan::parts`).
fn surface_parts_key(db: &dyn Db, asset: Asset, surface: &SurfaceId) -> Result<Option<CacheKey>, Diagnostic> {
    let level = slot_of_surface(db, asset, surface)?;
    if !levels::is_cloud(asset.settings(db), level) {
        return Ok(None);
    }
    let key = queries::atlas_surface_parts_key(db, asset, level, surface.surface)?;
    Ok(Some(with_halvings(db, asset, level, surface, key)))
}

/// The jobs after a level's first step: a reduced level's maps once its mesh is made (their
/// sizes may depend on it); an impostor's surfaces (which ask for its frames when the cache does
/// not hold them); a cloud's LOD, render loads, renders and surfaces once its layout is known.
fn level_jobs(db: &dyn Db, asset: Asset, level: u32) -> Result<Vec<Job>, Diagnostic> {
    let name = asset.name(db);
    if levels::is_reduced(asset.settings(db), level) {
        queries::reduced_level(db, asset, level)?;
    }
    if !levels::is_cloud(asset.settings(db), level) {
        return Ok(level_surfaces(db, asset, level)
            .into_iter()
            .map(|surface| Job { asset, label: surface.label(name), task: Task::Surface(surface), after: 1 })
            .collect());
    }
    let label = level_label(db, asset, level);
    billboard_layout(db, asset, level)?;
    let lod = Job { asset, task: Task::step(Step::Lod { level }), after: 1, label: format!("{label}/lod") };
    let surfaces = level_surfaces(db, asset, level);
    let surface_jobs = surfaces.iter().map(|surface| Job {
        asset,
        label: surface.label(name),
        task: Task::Surface(surface.clone()),
        after: 2,
    });
    // Renders are needed only for surfaces the persistent cache does not hold.
    if !level_renders(db, asset, level) {
        return Ok([lod].into_iter().chain(surface_jobs).collect());
    }
    // Renders are likely (unless every group is in the render memo): the slow loads
    // (the render memo, the surfaces' last encodings; the textures went with the
    // planes) run as jobs of their own before the renders, on every worker, instead
    // of one after the other inside the first render.
    let mut jobs = vec![Job {
        asset,
        task: Task::step(Step::RenderMemo { level }),
        after: 1,
        label: format!("{label}/render-memo"),
    }];
    jobs.extend(surfaces.iter().map(|surface| Job {
        asset,
        task: Task::LoadPreviousEncoding(surface.clone()),
        after: 1,
        label: surface.label(name),
    }));
    jobs.push(lod);
    let batches = 0..queries::level_render_batches(db, asset, level).len() as u32;
    jobs.extend(batches.map(|batch| Job {
        asset,
        task: Task::step(Step::Render { level, batch }),
        after: 1,
        label: format!("{label}/render{batch}"),
    }));
    jobs.extend(surface_jobs);
    Ok(jobs)
}

/// `switch` reads the last stage of each surface's tail in `tails` (`level_tail_instances`).
fn reads_level_end(switch: StageInstance, tails: &[StageInstance]) -> StageInstance {
    tails.iter().skip(2).step_by(3).fold(switch, |switch, write| switch.reads_stage(write))
}

/// The tail's stage instances of a level's surfaces, read from `image` (the atlas, the impostor's
/// frames); each write also writes the report.
fn level_tail_instances(
    db: &dyn Db,
    asset: Asset,
    level: u32,
    (output_folder, report): (&Path, &PathBuf),
    image: &StageInstance,
) -> Vec<StageInstance> {
    let encode_settings = &asset.settings(db).encode;
    let mut tails = Vec::new();
    for surface in level_surfaces(db, asset, level) {
        let written = surface.written_files(output_folder, encode_settings);
        let [mips, encode, mut write] = tail_instances(asset.name(db), &surface, image, &written);
        write.writes.push(report.clone());
        tails.extend([mips, encode, write]);
    }
    tails
}

/// A level's render stage instances, one per render group, each reading the decodes of its
/// materials' textures (added to `decodes`, shared by every level).
fn level_render_instances(
    db: &dyn Db,
    asset: Asset,
    level: u32,
    [mesh, planes, layout]: [&StageInstance; 3],
    decodes: &mut BTreeMap<String, StageInstance>,
) -> Vec<StageInstance> {
    let (Ok(loaded), Ok(plane_layout)) = (loaded_mesh(db, asset), billboard_layout(db, asset, level)) else {
        return Vec::new();
    };
    let prefix = format!("{}/", asset.name(db));
    let mut renders = Vec::new();
    for group in &plane_layout.render_groups {
        let label = render_label(level_label(db, asset, level), &loaded.mesh, group);
        let instance = label.strip_prefix(&prefix).unwrap_or(&label).to_string();
        let mut render =
            StageInstance::new(RENDER, label, instance).reads_stage(mesh).reads_stage(planes).reads_stage(layout);
        if loaded.mesh.uvs.is_some() {
            for &material in &group.materials {
                for path in loaded.mesh.materials[material as usize].maps.values() {
                    read_decode(&mut render, path, decodes);
                }
            }
        }
        renders.push(render);
    }
    renders
}

/// The files of a baked billboard cloud: each level's LOD mesh, textures and previews (an `Auto`
/// level's candidates in its `candidates/`, the chosen one's also in the level's folder), and the
/// report; a chain's `lods.gltf` and `lods.json` with the switch sizes measured on them.
fn billboard_outputs(
    db: &dyn Db,
    asset: Asset,
    output_folder: &Path,
    runs: &[StageRun],
) -> Result<AssetOutputs, Diagnostic> {
    let loaded = loaded_mesh(db, asset)?;
    let settings = asset.settings(db);
    let name = asset.name(db);
    let mut outputs = AssetOutputs::default();
    let (mut slot_reports, slot_meshes) = level_outputs::level_files(db, asset, output_folder, &mut outputs)?;
    // The mesh's warnings, then the chain's (a level never shown).
    outputs.warnings = loaded.warnings.iter().map(ErrorSummary::from).collect();
    let levels = if levels::is_chain(settings) {
        let (screen_coverage, levels) =
            chain_outputs::chain_files(db, asset, output_folder, (slot_reports.as_slice(), slot_meshes), &mut outputs)?;
        report::ReportLevels::Chain { screen_coverage, levels }
    } else {
        // One level: its figures are the asset's.
        let one = slot_reports.pop().ok_or_else(|| Diagnostic::new(asset.main_file(db), "no level to bake"))?;
        report::ReportLevels::One(one.figures)
    };
    let report = report::AssetReport {
        asset: name,
        kind: KIND.name(),
        mesh: display_path(asset.main_file(db)),
        faces: loaded.mesh.triangles.len(),
        alpha_cutoff: settings.own::<Own>().billboard.alpha_cutoff,
        levels,
        stage_ms: crate::kinds::asset_stage_ms(name, runs),
        warnings: outputs.warnings.clone(),
    };
    outputs.report = Some(report::sorted_json(&report));
    Ok(outputs)
}

/// `cirrus preview` of a baked asset (`input`, built by the caller): renders it and its source
/// from the view directions and writes the contact sheet and the metrics of each level asked
/// for (with several, also the chain sheet); returns each level's metrics.
pub fn preview_levels(
    db: &dyn Db,
    input: Asset,
    config: &PipelineConfig,
    options: &PreviewOptions,
) -> Result<Vec<(u32, crate::preview::PreviewMetrics)>, PreviewError> {
    if input.kind(db) != KIND {
        return Err(PreviewError::NotPreviewable { name: options.asset.clone(), kind: input.kind(db).name() });
    }
    let settings = input.settings(db);
    let level_count = levels::level_count(settings);
    let chosen: Vec<u32> = match options.lod {
        Some(level) if level >= level_count => {
            return Err(PreviewError::NoSuchLevel { name: options.asset.clone(), level, levels: level_count })
        }
        Some(level) => vec![level],
        None => (0..level_count).collect(),
    };
    let loaded = loaded_mesh(db, input).map_err(PreviewError::Artifact)?;
    let source = source_view_mesh(db, input, &loaded).map_err(PreviewError::Artifact)?;
    let cutoff = settings.own::<Own>().billboard.alpha_cutoff;
    let folder = config.output.join(&options.asset);
    let lods = chosen
        .iter()
        .map(|&level| match options.stand_in {
            // Reduced and impostor levels have no planes to stand in on: they are shown as baked.
            stand_in
                if stand_in == lod_preview::StandIn::Baked
                    || levels::chain_slot(settings, level).is_none_or(|slot| !levels::is_cloud(settings, slot)) =>
            {
                read_level_view(&config.root, &folder.join(levels::chain_folder(settings, level)), cutoff)
            }
            stand_in => {
                let slot = levels::chain_slot(settings, level).unwrap_or(level);
                let planes = queries::billboard_planes(db, input, slot)?;
                Ok(crate::gpu::LevelView::Mesh(crate::gpu::ViewMesh {
                    batches: faces_on_planes(&loaded, &planes, stand_in),
                    materials: source.materials.clone(),
                }))
            }
        })
        .collect::<Result<Vec<_>, _>>()
        .map_err(PreviewError::Artifact)?;
    // The sphere the impostors' frames show.
    let (center, radius) = planes::bounding_sphere(&loaded.mesh.positions);
    let gpu = crate::gpu::gpu()?;
    let lod_refs: Vec<&crate::gpu::LevelView> = lods.iter().collect();
    let preview = crate::preview::preview_chain(gpu, &source, &lod_refs, center.to_array(), radius, options.settings)?;
    let out = config.root.join(&options.out);
    let mut results = Vec::new();
    for (&level, level_preview) in chosen.iter().zip(preview.levels) {
        crate::kinds::write_preview(&out.join(levels::chain_folder(settings, level)), &level_preview)?;
        results.push((level, level_preview.metrics));
    }
    if chosen.len() > 1 {
        crate::files::write_if_changed(&out.join("contact_sheet.png"), &preview.chain_sheet)
            .map_err(PreviewError::Write)?;
    }
    Ok(results)
}

/// A built chain's every slot (each level, or each candidate of an `Auto` level: its folder)
/// beside the source over the views of `settings`, the source rendered once a view: what the
/// `billboard-auto` bench tabulates per budget and screen size. Nothing is written, no image kept.
pub fn preview_slots(
    db: &dyn Db,
    input: Asset,
    config: &PipelineConfig,
    settings: crate::preview::PreviewSettings,
) -> Result<Vec<(u32, String, crate::preview::PreviewMetrics)>, PreviewError> {
    let asset_settings = input.settings(db);
    let loaded = loaded_mesh(db, input).map_err(PreviewError::Artifact)?;
    let source = source_view_mesh(db, input, &loaded).map_err(PreviewError::Artifact)?;
    let cutoff = asset_settings.own::<Own>().billboard.alpha_cutoff;
    let asset_folder = config.output.join(input.name(db));
    let slots = levels::slots(asset_settings);
    let folders: Vec<String> = (0..slots.len() as u32).map(|slot| levels::level_folder(asset_settings, slot)).collect();
    let views = folders
        .iter()
        .map(|folder| read_level_view(&config.root, &asset_folder.join(folder), cutoff))
        .collect::<Result<Vec<_>, _>>()
        .map_err(PreviewError::Artifact)?;
    let (center, radius) = planes::bounding_sphere(&loaded.mesh.positions);
    let gpu = crate::gpu::gpu()?;
    let view_refs: Vec<&crate::gpu::LevelView> = views.iter().collect();
    let metrics = crate::preview::compare_only(gpu, &source, &view_refs, (center.to_array(), radius), settings)?;
    Ok(slots.iter().zip(folders).zip(metrics).map(|((slot, folder), metrics)| (slot.level, folder, metrics)).collect())
}

/// The source's faces as `stand_in` draws them on the planes of `planes`.
fn faces_on_planes(
    loaded: &LoadedMesh,
    planes: &planes::PlaneSet,
    stand_in: lod_preview::StandIn,
) -> Vec<(usize, Vec<crate::gpu::RenderVertex>)> {
    let mesh = &loaded.mesh;
    let mut plane_of_face = vec![None; mesh.triangles.len()];
    for plane in &planes.planes {
        for &face in &plane.faces {
            if let Some(slot) = plane_of_face.get_mut(face as usize) {
                *slot = Some((plane.normal, plane.distance));
            }
        }
    }
    crate::gpu::face_batches_placed(mesh, &loaded.tangents, 0..mesh.triangles.len() as u32, |face, corner| {
        let triangle = mesh.triangles[face as usize];
        lod_preview::stand_in_position(
            stand_in,
            triangle.map(|corner| mesh.positions[corner as usize]),
            corner,
            plane_of_face[face as usize],
        )
    })
}
