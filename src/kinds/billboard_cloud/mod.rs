//! The `BillboardCloud` kind: a mesh turned into a cloud of textured quads (planes → rectangles
//! → layout → per-group renders → atlas) whose four atlas surfaces end in the shared texture
//! tail, plus `lod.obj` / `lod.mtl`; and `cirrus preview`, which compares the source with the
//! baked LOD.
//!
//! Jobs: `layout` (mesh, planes and layout on a worker, wave 0), then the LOD and, when some
//! atlas surface is not in the cache, the loads the renders need (`render-memo`, one `upload`
//! per material texture, the surfaces' last encodings) followed by one `render` per render group
//! (wave 1), then the four atlas surfaces through the tail (wave 2).

pub mod planes;
pub mod rectangles;
pub mod layout;
pub mod render_groups;
pub mod atlas;
pub mod lod_mesh;
pub mod lod_preview;
pub mod queries;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::cache::CacheKey;
use crate::config::{AssetConfig, PipelineConfig};
use crate::db::{Asset, Db, StageRun, DECODE};
use crate::diagnostic::{display_path, Diagnostic};
use crate::kinds::mesh_queries::{loaded_mesh, mesh_textures, LoadedMesh};
use crate::kinds::{check_texture_file, tail_instances, AssetOutputs, Job, Kind, Read, StageInstance, SurfaceId, Task};
use crate::summary::ErrorSummary;
use crate::texture::tail::TailSettings;
use crate::texture::{SurfaceKind, Texture, TextureSlot};
use queries::{billboard_layout, billboard_planes, lod_files, render_label};
use queries::{ATLAS, LAYOUT, LOD, PLANES, RENDER};

pub struct BillboardCloud;

fn atlas_surfaces() -> [SurfaceId; 4] {
    SurfaceKind::BILLBOARD.map(|surface| SurfaceId { group: String::new(), surface })
}

/// Every (material, slot) whose texture the renders sample, in material order.
fn material_texture_slots(loaded: &LoadedMesh) -> Vec<(usize, TextureSlot)> {
    if loaded.mesh.uvs.is_none() {
        return Vec::new();
    }
    let materials = loaded.mesh.materials.iter().enumerate();
    materials.flat_map(|(index, material)| material.maps.keys().map(move |&slot| (index, slot))).collect()
}

impl Kind for BillboardCloud {
    const NAME: &'static str = "BillboardCloud";

    fn files_to_read(db: &dyn Db, asset: Asset) -> Vec<PathBuf> {
        let mut files = crate::kinds::mesh_queries::mesh_files(db, asset);
        files.extend(mesh_textures(db, asset).iter().cloned());
        files
    }

    fn first_jobs(db: &dyn Db, asset: Asset) -> Vec<Job> {
        vec![Job { asset, task: Task::Step("layout", 0), after: 0, label: asset.name(db).clone() }]
    }

    fn run_step(db: &dyn Db, asset: Asset, step: &'static str, index: u32) -> Result<Vec<Job>, Diagnostic> {
        let name = asset.name(db);
        match step {
            "layout" => {
                let layout = billboard_layout(db, asset)?;
                let lod = Job { asset, task: Task::Step("lod", 0), after: 1, label: format!("{name}/lod") };
                let surfaces = atlas_surfaces();
                let surface_jobs =
                    surfaces.clone().map(|surface| Job { asset, label: surface.label(name), task: Task::Surface(surface), after: 2 });
                // Renders are needed only for surfaces the persistent cache does not hold.
                if surfaces.iter().all(|surface| crate::kinds::tail_queries::surface_in_cache(db, asset, surface)) {
                    return Ok([lod].into_iter().chain(surface_jobs).collect());
                }
                // Renders are likely (unless every group is in the render memo): the GPU starts
                // on its own thread, and the slow loads (the render memo, the textures, the
                // surfaces' last encodings) run as jobs of their own before the renders, on
                // every worker, instead of one after the other inside the first render.
                crate::gpu::start_gpu_in_background();
                let mut jobs = vec![Job { asset, task: Task::Step("render-memo", 0), after: 1, label: format!("{name}/render-memo") }];
                jobs.extend(surfaces.iter().map(|surface| Job {
                    asset,
                    task: Task::LoadPreviousEncoding(surface.clone()),
                    after: 1,
                    label: surface.label(name),
                }));
                let uploads = material_texture_slots(&*loaded_mesh(db, asset)?).len() as u32;
                jobs.extend((0..uploads).map(|texture| Job {
                    asset,
                    task: Task::Step("upload", texture),
                    after: 1,
                    label: format!("{name}/upload{texture}"),
                }));
                jobs.push(lod);
                let groups = 0..layout.render_groups.len() as u32;
                jobs.extend(groups.map(|group| Job {
                    asset,
                    task: Task::Step("render", group),
                    after: 1,
                    label: format!("{name}/render{group}"),
                }));
                jobs.extend(surface_jobs);
                Ok(jobs)
            }
            "render-memo" => {
                queries::stored_renders(db, asset);
                Ok(Vec::new())
            }
            "upload" => {
                // Errors are the renders' to report.
                let loaded = loaded_mesh(db, asset)?;
                if let Some(&(material, slot)) = material_texture_slots(&loaded).get(index as usize) {
                    if let (Ok(Some(levels)), Ok(gpu)) =
                        (queries::material_texture_mips(db, asset, material as u32, slot), crate::gpu::gpu())
                    {
                        gpu.upload_material_mips(&levels, slot, queries::billboard_alpha_cutoff(db, asset));
                    }
                }
                Ok(Vec::new())
            }
            "render" => queries::plane_images(db, asset, index).map(|_| Vec::new()),
            "lod" => lod_files(db, asset).map(|_| Vec::new()),
            other => unreachable!("the billboard kind schedules no step `{other}`"),
        }
    }

    fn stage_instances(db: &dyn Db, asset: Asset, output_folder: &Path, errors: &[Diagnostic]) -> Vec<StageInstance> {
        let name = asset.name(db);
        let main_file = asset.main_file(db);
        let mesh_label = display_path(main_file);
        let failed = !errors.is_empty();
        let report = output_folder.join("report.json");
        let mut mesh = crate::kinds::mesh_queries::mesh_instance(db, asset);
        mesh.writes.push(report.clone());
        let planes = StageInstance::new(PLANES, name, &mesh_label).reads_stage(&mesh);
        let layout = StageInstance::new(LAYOUT, name, &mesh_label).reads_stage(&mesh).reads_stage(&planes);
        let mut atlas = StageInstance::new(ATLAS, name, &mesh_label).reads_stage(&layout);
        let mut lod = StageInstance::new(LOD, name, &mesh_label).reads_stage(&layout);
        lod.writes = vec![output_folder.join("lod.obj"), output_folder.join("lod.mtl")];
        let mut instances = vec![mesh.clone(), planes.clone(), layout.clone()];
        let mut decodes = BTreeMap::new();
        if let (Ok(loaded), Ok(plane_layout)) = (loaded_mesh(db, asset), billboard_layout(db, asset)) {
            for group in &plane_layout.render_groups {
                let label = render_label(name, &loaded.mesh, group);
                let instance = label.strip_prefix(&format!("{name}/")).unwrap_or(&label).to_string();
                let mut render = StageInstance::new(RENDER, label, instance).reads_stage(&mesh).reads_stage(&planes).reads_stage(&layout);
                if loaded.mesh.uvs.is_some() {
                    for &material in &group.materials {
                        for path in loaded.mesh.materials[material as usize].maps.values() {
                            let label = display_path(path);
                            render.reads.push(Read::Stage(DECODE, label.clone()));
                            decodes.entry(label).or_insert_with(|| {
                                let mut decode = StageInstance::new(DECODE, display_path(path), display_path(path));
                                decode.reads.push(Read::File(path.clone()));
                                decode.shared = true;
                                decode
                            });
                        }
                    }
                }
                atlas = atlas.reads_stage(&render);
                instances.push(render);
            }
        }
        let container = asset.settings(db).encode.container;
        let mut tails = Vec::new();
        for surface in atlas_surfaces() {
            let [mips, encode, mut write] = tail_instances(name, &surface, &atlas, surface.artifact_paths(output_folder, container));
            write.writes.push(report.clone());
            tails.extend([mips, encode, write]);
        }
        atlas.writes.push(report.clone());
        instances.push(atlas);
        instances.extend(tails);
        instances.push(lod);
        instances.extend(decodes.into_values());
        for instance in &mut instances {
            instance.failed = failed;
        }
        instances
    }

    fn outputs(db: &dyn Db, asset: Asset, output_folder: &Path, errors: &mut Vec<Diagnostic>, runs: &[StageRun]) -> AssetOutputs {
        crate::kinds::outputs_unless_failed(errors, || billboard_outputs(db, asset, output_folder, runs))
    }

    /// The mesh loads with its material libraries, and every texture its materials name is
    /// readable and within the limits; warnings are reported as problems too.
    fn check(config: &PipelineConfig, asset: &AssetConfig) -> Vec<Diagnostic> {
        let main_file = &config.source.join(asset.source.main_file());
        let (mesh, mut problems) = match crate::kinds::check_mesh_file(config, main_file) {
            Ok(loaded) => loaded,
            Err(diagnostic) => return vec![diagnostic],
        };
        let textures: std::collections::BTreeSet<&PathBuf> = mesh.materials.iter().flat_map(|material| material.maps.values()).collect();
        for path in textures {
            if let Err(message) = check_texture_file(config, path) {
                problems.push(Diagnostic::new(path, message));
            }
        }
        problems
    }

    fn surface_image(db: &dyn Db, asset: Asset, surface: &SurfaceId) -> Result<Arc<Texture>, Diagnostic> {
        queries::atlas_surface(db, asset, surface.surface)
    }

    fn tail_settings(db: &dyn Db, asset: Asset, surface: &SurfaceId) -> Result<TailSettings, Diagnostic> {
        let settings = asset.settings(db);
        let encode = &settings.encode;
        Ok(crate::kinds::tail_settings_from(
            encode,
            surface.surface,
            encode.format_of(surface.surface),
            (surface.surface == SurfaceKind::Albedo).then_some(settings.billboard.alpha_cutoff),
        ))
    }

    fn surface_recipe_key(db: &dyn Db, asset: Asset, _surface: &SurfaceId) -> Result<Option<CacheKey>, Diagnostic> {
        Ok(Some(queries::atlas_recipe_key(db, asset)))
    }

    fn surface_parts_key(db: &dyn Db, asset: Asset, surface: &SurfaceId) -> Result<Option<CacheKey>, Diagnostic> {
        queries::atlas_surface_parts_key(db, asset, surface.surface).map(Some)
    }
}

/// The files of a baked billboard cloud: LOD mesh, textures, previews, report.
fn billboard_outputs(db: &dyn Db, asset: Asset, output_folder: &Path, runs: &[StageRun]) -> Result<AssetOutputs, Diagnostic> {
    let (obj, mtl) = (*lod_files(db, asset)?).clone();
    let loaded = loaded_mesh(db, asset)?;
    let planes = billboard_planes(db, asset)?;
    let layout = billboard_layout(db, asset)?;
    let mut outputs = AssetOutputs::default();
    outputs.files.push((output_folder.join("lod.obj"), obj.into_bytes().into()));
    outputs.files.push((output_folder.join("lod.mtl"), mtl.into_bytes().into()));
    let container = asset.settings(db).encode.container;
    let mut surfaces = Vec::new();
    for surface in atlas_surfaces() {
        let artifacts = crate::kinds::tail_queries::surface_artifacts(db, asset, surface.clone())?;
        let [texture_path, preview_path] = surface.artifact_paths(output_folder, container);
        outputs.files.push((texture_path, artifacts.texture_file.clone()));
        outputs.files.push((preview_path, artifacts.preview_png.clone()));
        surfaces.push(artifacts.info.clone());
    }
    let settings = asset.settings(db);
    let name = asset.name(db);
    let stage_ms = crate::kinds::asset_stage_ms(name, runs);
    let atlas_coverage = queries::atlas_coverage_fraction(db, asset)?;
    let report = serde_json::json!({
        "asset": name,
        "kind": BillboardCloud::NAME,
        "mesh": display_path(asset.main_file(db)),
        "faces": planes.face_count,
        "planes": planes.planes.len(),
        "quads": layout.layout.placements.len(),
        "triangles": 2 * layout.layout.placements.len(),
        // The quad budget (none: ε decides) and the ε it was met with.
        "budget_quads": settings.billboard.budget.map(crate::config::LodBudget::quads),
        // Faces of solid materials drawn on another plane's quad too (crack filling).
        "faces_also_drawn": layout.rectangles.iter().map(|rectangle| rectangle.also_drawn.len()).sum::<usize>(),
        "alpha_cutoff": settings.billboard.alpha_cutoff,
        "epsilon": planes.epsilon_fraction,
        "epsilon_world": planes.epsilon,
        "max_error_world": planes.max_error,
        "atlas": {
            "width": layout.layout.width,
            "height": layout.layout.height,
            "texel_density": layout.layout.texel_density,
            "screen_size": settings.billboard.screen_size,
            "occupancy": (layout.layout.occupancy * 1e4).round() / 1e4,
            "coverage": atlas_coverage,
        },
        "surfaces": surfaces,
        "stage_ms": stage_ms,
        "warnings": loaded.warnings.iter().map(ErrorSummary::from).collect::<Vec<_>>(),
    });
    outputs.report = Some(serde_json::to_vec_pretty(&report).expect("reports serialise"));
    Ok(outputs)
}

/// What `cirrus preview` renders.
#[derive(Clone, Debug)]
pub struct PreviewOptions {
    pub asset: String,
    pub settings: lod_preview::PreviewSettings,
    /// Where `contact_sheet.png` and `metrics.json` go (project-relative or absolute).
    pub out: PathBuf,
}

#[derive(Debug, thiserror::Error)]
pub enum PreviewError {
    #[error(transparent)]
    Build(#[from] crate::project::BuildError),
    #[error("asset `{0}` is not a BillboardCloud: only billboard clouds have a LOD to preview")]
    NotBillboard(String),
    #[error("asset `{name}` failed to bake:\n{errors}")]
    Failed { name: String, errors: String },
    #[error("{0}")]
    Artifact(Diagnostic),
    #[error(transparent)]
    Gpu(#[from] crate::gpu::GpuError),
    #[error("cannot write the preview: {0}")]
    Write(std::io::Error),
}

/// `cirrus preview`: bakes the asset if needed, then renders it and its source from the view
/// directions and writes the contact sheet and the metrics.
pub fn preview(project: &mut crate::project::Project, options: &PreviewOptions) -> Result<lod_preview::PreviewMetrics, PreviewError> {
    let build = crate::project::BuildOptions { only_assets: vec![options.asset.clone()], ..Default::default() };
    let summary = project.build(&build, &|_| {})?;
    let asset = &summary.assets[0];
    if asset.kind != BillboardCloud::NAME {
        return Err(PreviewError::NotBillboard(options.asset.clone()));
    }
    if asset.status != crate::summary::AssetStatus::Ok {
        let errors = asset.errors.iter().map(|error| format!("  {}: {}", error.file, error.message)).collect::<Vec<_>>().join("\n");
        return Err(PreviewError::Failed { name: options.asset.clone(), errors });
    }
    let input = project.asset_input(&options.asset).expect("a built asset has an input");
    let db = project.database();
    let loaded = loaded_mesh(db, input).map_err(PreviewError::Artifact)?;
    let source = source_view_mesh(db, input, &loaded).map_err(PreviewError::Artifact)?;
    let cutoff = input.settings(db).billboard.alpha_cutoff;
    let config = project.config();
    let folder = config.output.join(&options.asset);
    let lod = read_lod_view_mesh(&config.root, &folder, cutoff).map_err(PreviewError::Artifact)?;
    let positions = &loaded.mesh.positions;
    let (min, max) = positions.iter().fold((glam::Vec3::splat(f32::INFINITY), glam::Vec3::splat(f32::NEG_INFINITY)), |(min, max), &p| {
        (min.min(glam::Vec3::from(p)), max.max(glam::Vec3::from(p)))
    });
    let center = 0.5 * (min + max);
    let radius = positions.iter().map(|&p| glam::Vec3::from(p).distance(center)).fold(0.0, f32::max);
    let gpu = crate::gpu::gpu()?;
    let preview = lod_preview::preview(gpu, &source, &lod, center.to_array(), radius, options.settings)?;
    let out = config.root.join(&options.out);
    let mut metrics = serde_json::to_vec_pretty(&preview.metrics).expect("metrics serialise");
    metrics.push(b'\n');
    crate::artifacts::write_if_changed(&out.join("contact_sheet.png"), &preview.contact_sheet).map_err(PreviewError::Write)?;
    crate::artifacts::write_if_changed(&out.join("metrics.json"), &metrics).map_err(PreviewError::Write)?;
    Ok(preview.metrics)
}

/// The baked LOD in `folder` (relative to `root`) as an engine loads it: `lod.obj` with the
/// decoded levels of `albedo.ktx2` and `normal.ktx2`, alpha-tested at `alpha_cutoff`.
pub fn read_lod_view_mesh(root: &Path, folder: &Path, alpha_cutoff: f32) -> Result<crate::gpu::ViewMesh, Diagnostic> {
    let read = |file: &str| -> Result<(PathBuf, Vec<u8>), Diagnostic> {
        let path = folder.join(file);
        let bytes = crate::artifacts::read_artifact(root, &path)?;
        Ok((path, bytes))
    };
    lod_preview::lod_view_mesh(&lod_preview::LodFiles {
        obj: read("lod.obj")?,
        albedo_ktx2: read("albedo.ktx2")?,
        normal_ktx2: read("normal.ktx2")?,
        alpha_cutoff,
    })
}

/// The source mesh with its decoded maps (mipmapped as for rendering).
fn source_view_mesh(db: &dyn Db, input: Asset, loaded: &LoadedMesh) -> Result<crate::gpu::ViewMesh, Diagnostic> {
    use crate::texture::TextureSlot;
    let cutoff = input.settings(db).billboard.alpha_cutoff;
    let mut materials = Vec::new();
    for material in &loaded.mesh.materials {
        let levels = |slot: TextureSlot, kind: SurfaceKind| -> Result<Option<Arc<Vec<crate::texture::Texture>>>, Diagnostic> {
            let Some(path) = material.maps.get(&slot).filter(|_| loaded.mesh.uvs.is_some()) else { return Ok(None) };
            let Some(file) = crate::db::asset_file(db, input, path.clone()) else { return Ok(None) };
            let texture =
                if slot == TextureSlot::Opacity { crate::db::opacity_texture(db, file)? } else { crate::db::decoded_texture(db, file)? };
            // The reference keeps alpha-tested coverage at every distance, as the bake does.
            let alpha_cutoff = matches!(slot, TextureSlot::Albedo | TextureSlot::Opacity).then_some(cutoff);
            Ok(Some(Arc::new(crate::texture::mips::mip_chain(&texture, crate::texture::mips::MipSettings { kind, alpha_cutoff }))))
        };
        materials.push(crate::gpu::ViewMaterial {
            albedo: levels(TextureSlot::Albedo, SurfaceKind::Albedo)?,
            opacity: levels(TextureSlot::Opacity, SurfaceKind::Albedo)?,
            normal: levels(TextureSlot::Normal, SurfaceKind::Normal)?,
            normal_has_z: true,
            albedo_factor: [material.albedo_factor[0], material.albedo_factor[1], material.albedo_factor[2], material.opacity],
            alpha_cutoff: cutoff,
        });
    }
    Ok(crate::gpu::ViewMesh {
        batches: render_groups::face_batches(&loaded.mesh, &loaded.tangents, 0..loaded.mesh.triangles.len() as u32),
        materials,
    })
}
