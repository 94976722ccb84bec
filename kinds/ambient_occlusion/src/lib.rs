//! The `AmbientOcclusion` kind (DESIGN §3.3): ambient occlusion baked into an OBJ's UV space,
//! one map per material (`<asset>/<material>/ao.png` 16-bit, `ao.ktx2` BC4 through the shared
//! tail). Rays from every texel's surface point (`mode: Texels`) or from the vertices
//! (`mode: Vertices`, the seed's method), UV tiles as stage instances (`bake`), each map put
//! together and filled (`fill`).
//!
//! Jobs: `plan` (wave 0: the mesh), then one tail job per material, whose image asks for the
//! map, which asks for its tiles. Stage instances: `mesh` → `bvh` (→ `vertices`) → a `bake` per
//! tile → a `fill` per material → `mips → encode → write`.

// The machinery this kind builds on, under the names its files use (`crate::db`, …).
use cirrus_core::{cache, config, db, diagnostic, kinds, mesh, schedule, stop, summary, texture};

pub mod settings;
pub mod bake;
pub mod queries;

use crate::summary::ArtifactRole;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use serde::Serialize;

use crate::cache::CacheKey;
use crate::config::{AssetConfig, PipelineConfig};
use crate::db::{Asset, Db, StageRun};
use crate::diagnostic::{display_path, Diagnostic};
use crate::kinds::mesh_queries::mesh_instance;
use crate::kinds::Read;
use crate::kinds::{tail_instances, AssetOutputs, Job, Kind, StageInstance, SurfaceFn, SurfaceId, SurfacePlan, Task};
use crate::settings::Settings as Own;
use crate::summary::ErrorSummary;
use crate::texture::tail::SurfaceInfo;
use crate::texture::{SurfaceKind, Texture};
use bake::material_tiles;
use queries::{
    ao_map, ao_map_key, ao_settings, bake_geometry, material_label, tile_label, BakeGeometry, BAKE, BVH, FILL, VERTICES,
};
use settings::AoMode;

pub struct AmbientOcclusion;

/// The kind, as `pipeline.ron` and the driver name it.
pub const KIND: crate::config::AssetKind =
    crate::config::AssetKind::new(<settings::Settings as crate::config::KindEntry>::NAME, &QUESTIONS);
const QUESTIONS: crate::kinds::KindQuestions = crate::kinds::KindQuestions::of::<AmbientOcclusion>();

/// The tail surface of a baked material.
fn material_surface(folder: &str) -> SurfaceId {
    SurfaceId::new(folder, SurfaceKind::Ao)
}

/// The baked material a tail surface is.
fn surface_material(db: &dyn Db, asset: Asset, surface: &SurfaceId) -> Result<(Arc<BakeGeometry>, u32), Diagnostic> {
    let geometry = bake_geometry(db, asset)?;
    // By folder (the tail's surfaces), else by name (another asset reading the map).
    let materials = &geometry.materials;
    let found = materials
        .iter()
        .find(|material| material.folder == surface.group)
        .or_else(|| materials.iter().find(|material| material.name == surface.group));
    let index = found.map(|material| material.index);
    let index = index
        .ok_or_else(|| Diagnostic::new(asset.main_file(db), format!("the mesh has no material `{}`", surface.group)))?;
    Ok((geometry, index))
}

/// The AO kind's one step: load the mesh, then schedule each material's map.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Step {
    Plan,
}

impl crate::kinds::KindStep for Step {
    type Kind = AmbientOcclusion;

    fn sort(&self) -> &'static str {
        "plan"
    }
}

/// What an AO bake holds per texel of its map at its peak, beyond the mesh: its rays' results,
/// the filled map and what the tail makes of it. Measured on the bundled cow: `cirrus build`
/// peaks at 22 MiB at `size: 512` and 86 MiB at 2048, 17 B a texel more.
const HELD_BYTES_PER_MAP_TEXEL: u64 = 17;

impl Kind for AmbientOcclusion {
    fn files_to_read(db: &dyn Db, asset: Asset) -> Vec<PathBuf> {
        crate::kinds::mesh_queries::mesh_files(db, asset)
    }

    /// One map of `size`² (a mesh of several materials bakes one each: the estimate does not
    /// read the mesh); none in `Vertices` mode.
    fn made_bytes(db: &dyn Db, asset: Asset) -> u64 {
        let settings = ao_settings(db, asset);
        match settings.mode {
            AoMode::Vertices => 0,
            _ => u64::from(settings.size).pow(2) * HELD_BYTES_PER_MAP_TEXEL,
        }
    }

    fn first_jobs(db: &dyn Db, asset: Asset) -> Vec<Job> {
        vec![Job { asset, task: Task::step(Step::Plan), after: 0, label: asset.name(db).clone() }]
    }

    type Step = Step;

    fn run_step(db: &dyn Db, asset: Asset, _step: &Step) -> Result<Vec<Job>, Diagnostic> {
        let geometry = bake_geometry(db, asset)?;
        let name = asset.name(db);
        Ok(geometry
            .materials
            .iter()
            .map(|material| {
                let surface = material_surface(&material.folder);
                Job { asset, label: surface.label(name), task: Task::Surface(surface), after: 1 }
            })
            .collect())
    }

    fn stage_instances(db: &dyn Db, asset: Asset, output_folder: &Path, errors: &[Diagnostic]) -> Vec<StageInstance> {
        let name = asset.name(db);
        let report = output_folder.join("report.json");
        let mut mesh = mesh_instance(db, asset);
        mesh.writes.push(report.clone());
        let mut instances = vec![mesh.clone()];
        if let Ok(geometry) = bake_geometry(db, asset) {
            let settings = ao_settings(db, asset);
            let bvh = StageInstance::new(BVH, name, name).reads_stage(&mesh);
            let rays = match settings.mode {
                AoMode::Texels => bvh.clone(),
                AoMode::Vertices => StageInstance::new(VERTICES, name, name).reads_stage(&bvh),
            };
            instances.push(bvh.clone());
            if settings.mode == AoMode::Vertices {
                instances.push(rays.clone());
            }
            let encode = &asset.settings(db).encode;
            for material in &geometry.materials {
                let mut fill = StageInstance::new(FILL, material_label(name, &material.folder), &material.folder);
                for tile in material_tiles(material.index, settings.size) {
                    let label = tile_label(name, &material.folder, tile);
                    let instance = format!("{}/{}", material.folder, tile.name());
                    let tile = StageInstance::new(BAKE, label, instance).reads_stage(&mesh).reads_stage(&rays);
                    fill = fill.reads_stage(&tile);
                    instances.push(tile);
                }
                let surface = material_surface(&material.folder);
                let [mips, encode, mut write] =
                    tail_instances(name, &surface, &fill, &surface.artifact_paths(output_folder, encode));
                write.writes.push(report.clone());
                instances.extend([fill, mips, encode, write]);
            }
        }
        for instance in &mut instances {
            instance.failed = !errors.is_empty();
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
        crate::kinds::outputs_unless_failed(errors, || ao_outputs(db, asset, output_folder, runs))
    }

    /// The mesh loads with its material libraries and has texture coordinates; load warnings
    /// are reported as problems too.
    fn check(config: &PipelineConfig, asset: &AssetConfig) -> Vec<Diagnostic> {
        let main_file = &config.source.join(asset.source.main_file());
        let (mesh, mut problems) = match crate::kinds::checks::check_mesh_file(config, main_file) {
            Ok(loaded) => loaded,
            Err(diagnostic) => return vec![diagnostic],
        };
        if mesh.uvs.is_none() {
            problems.push(Diagnostic::new(
                main_file,
                "the mesh has no texture coordinates: an AO bake needs a UV layout (`vt` in the OBJ)",
            ));
        }
        problems.extend(
            crate::mesh::uvs_outside_warnings(main_file, &mesh).iter().map(crate::diagnostic::Diagnostic::as_warning),
        );
        let long_bake =
            bake::long_bake_warning(main_file, &mesh, &asset.settings.own::<Own>().ao, crate::schedule::cores());
        problems.extend(long_bake.as_ref().map(crate::diagnostic::Diagnostic::as_warning));
        problems
    }

    fn surface_plan(db: &dyn Db, asset: Asset, surface: &SurfaceId) -> Result<SurfacePlan, Diagnostic> {
        let encode = &asset.settings(db).encode;
        let settings =
            crate::kinds::tail_settings_from(encode, surface.surface, encode.format_of(surface.surface), None);
        let image: SurfaceFn<Arc<Texture>> = |db, asset, surface| {
            let (_, material) = surface_material(db, asset, surface)?;
            Ok(Arc::new(bake::map_texture(&ao_map(db, asset, material)?.map)))
        };
        let recipe: SurfaceFn<Option<CacheKey>> = |db, asset, surface| {
            let (_, material) = surface_material(db, asset, surface)?;
            ao_map_key(db, asset, material).map(Some)
        };
        Ok(SurfacePlan::new(settings, recipe, image))
    }

    fn provided_surface_stage(db: &dyn Db, asset: Asset, surface: &SurfaceId) -> Result<Option<Read>, Diagnostic> {
        if surface.surface != SurfaceKind::Ao {
            return Ok(None);
        }
        let (geometry, material) = surface_material(db, asset, surface)?;
        let folder = geometry.material(material).map(|material| material.folder.clone()).unwrap_or_default();
        Ok(Some(Read::Stage(FILL, queries::material_label(asset.name(db), &folder))))
    }
}

/// `report.json` of an AO bake.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub(crate) struct AoReport {
    pub asset: String,
    pub kind: &'static str,
    pub mesh: String,
    pub mode: AoMode,
    pub rays_per_texel: u32,
    /// `max_distance` in mesh units (none: unbounded).
    pub max_distance: Option<f32>,
    pub materials: Vec<AoMaterialReport>,
    /// Figures of this build's work (not compared when deciding to rewrite the report).
    pub timings: AoTimings,
    pub stage_ms: std::collections::BTreeMap<String, f64>,
    pub warnings: Vec<ErrorSummary>,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub(crate) struct AoMaterialReport {
    pub name: String,
    pub folder: String,
    /// The 16-bit map.
    pub png: String,
    pub texels_baked: u64,
    /// Texels inside geometry (most of their probe rays met back faces): filled, not baked.
    pub invalid_texels: u64,
    /// Of the baked texels, those that two triangles with no shared vertex claim.
    pub overlap_fraction: f64,
    pub rays_cast: u64,
    /// Rays per second of the material's tile bakes, over their summed time (a tile bakes on
    /// every core, but materials bake at once and share them: the asset's `rays_per_second`
    /// `timings.rays_per_second`
    /// is the machine's rate); none per vertex.
    pub rays_per_second: Option<f64>,
    pub texture: AoSurfaceReport,
}

/// What this build's tile bakes took.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub(crate) struct AoTimings {
    /// Rays per second of this build's tile bakes, all materials together, over the wall time
    /// from the first tile's start to the last tile's end (none when no tile baked).
    pub rays_per_second: Option<f64>,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub(crate) struct AoSurfaceReport {
    pub path: String,
    #[serde(flatten)]
    pub info: SurfaceInfo,
}

/// The rays of this build's tile bakes over the wall time they spanned together.
fn bake_rays_per_second(
    db: &dyn Db,
    asset: Asset,
    geometry: &BakeGeometry,
    runs: &[StageRun],
) -> Result<Option<f64>, Diagnostic> {
    let name = asset.name(db);
    let bakes: std::collections::HashMap<&str, &StageRun> = runs
        .iter()
        .filter(|run| run.stage == BAKE.name && !run.from_cache)
        .map(|run| (run.label.as_str(), run))
        .collect();
    let size = ao_settings(db, asset).size;
    let (mut rays, mut first, mut last) = (0u64, None::<std::time::Instant>, None::<std::time::Instant>);
    for material in &geometry.materials {
        for tile in material_tiles(material.index, size) {
            let Some(run) = bakes.get(tile_label(name, &material.folder, tile).as_str()) else { continue };
            rays += queries::ao_tile(db, asset, tile)?.rays;
            let end = run.started + std::time::Duration::from_secs_f64(run.ms / 1000.0);
            first = Some(first.map_or(run.started, |first| first.min(run.started)));
            last = Some(last.map_or(end, |last| last.max(end)));
        }
    }
    let seconds = match (first, last) {
        (Some(first), Some(last)) => (last - first).as_secs_f64(),
        _ => 0.0,
    };
    Ok((rays > 0 && seconds > 0.0).then(|| (rays as f64 / seconds).round()))
}

fn ao_outputs(db: &dyn Db, asset: Asset, output_folder: &Path, runs: &[StageRun]) -> Result<AssetOutputs, Diagnostic> {
    let geometry = bake_geometry(db, asset)?;
    let settings = ao_settings(db, asset);
    let encode = &asset.settings(db).encode;
    let mut outputs = AssetOutputs::default();
    let mut materials = Vec::new();
    for material in &geometry.materials {
        let surface = material_surface(&material.folder);
        let artifacts = crate::kinds::tail_queries::surface_artifacts(db, asset, surface.clone())?;
        let files = ao_map(db, asset, material.index)?;
        let [texture_path, png_path] = surface.artifact_paths(output_folder, encode);
        outputs.add(texture_path.clone(), ArtifactRole::Texture, artifacts.texture_file.clone());
        outputs.add(png_path.clone(), ArtifactRole::Image, files.png16.clone());
        let map = &files.map;
        if map.baked_texels == 0 {
            return Err(Diagnostic::new(
                asset.main_file(db),
                format!(
                    "material `{}`: its UV layout covers no texel of the {}² map (every triangle's texture \
                        coordinates are degenerate or lie outside [0, 1]): there is nothing to bake",
                    material.name, settings.size
                ),
            ));
        }
        // Per vertex, the rays are cast from the material's vertices, not its texels.
        let rays_cast = match settings.mode {
            AoMode::Texels => map.rays,
            AoMode::Vertices => {
                let triangles = &geometry.loaded.mesh.triangles;
                let mut vertices: Vec<u32> =
                    material.triangles.iter().flat_map(|&triangle| triangles[triangle as usize]).collect();
                vertices.sort_unstable();
                vertices.dedup();
                vertices.len() as u64 * settings.rays as u64
            }
        };
        let round = |value: f64, places: i32| (value * 10f64.powi(places)).round() / 10f64.powi(places);
        materials.push(AoMaterialReport {
            name: material.name.clone(),
            folder: material.folder.clone(),
            png: display_path(&png_path),
            texels_baked: map.baked_texels,
            invalid_texels: map.invalid_texels,
            overlap_fraction: if map.baked_texels == 0 {
                0.0
            } else {
                round(map.overlapping_texels as f64 / map.baked_texels as f64, 5)
            },
            rays_cast,
            rays_per_second: (map.rays > 0 && map.bake_ms > 0.0)
                .then(|| round(map.rays as f64 / (map.bake_ms / 1000.0), 0)),
            texture: AoSurfaceReport { path: display_path(&texture_path), info: artifacts.info.clone() },
        });
    }
    let name = asset.name(db);
    let report = AoReport {
        asset: name.clone(),
        kind: KIND.name(),
        mesh: display_path(asset.main_file(db)),
        mode: settings.mode,
        rays_per_texel: settings.rays,
        max_distance: geometry.occlusion.max_distance.is_finite().then_some(geometry.occlusion.max_distance),
        materials,
        timings: AoTimings { rays_per_second: bake_rays_per_second(db, asset, &geometry, runs)? },
        stage_ms: crate::kinds::asset_stage_ms(name, runs)
            .into_iter()
            .map(|(stage, ms)| (stage.to_string(), ms))
            .collect(),
        warnings: geometry
            .loaded
            .warnings
            .iter()
            .chain(&crate::mesh::uvs_outside_warnings(asset.main_file(db), &geometry.loaded.mesh))
            .chain(&bake::long_bake_warning(
                asset.main_file(db),
                &geometry.loaded.mesh,
                &settings,
                crate::schedule::cores(),
            ))
            .map(ErrorSummary::from)
            .collect(),
    };
    outputs.report = Some(serde_json::to_vec_pretty(&report).expect("reports serialise"));
    outputs.warnings = report.warnings;
    Ok(outputs)
}
