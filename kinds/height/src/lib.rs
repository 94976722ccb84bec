//! The `Height` kind (DESIGN §3.4): a height map from a high and a low mesh (`height.png` 16-bit,
//! `height.ktx2` BC4 through the shared tail, and the mapping `distance = (value − center) ×
//! magnitude`), measured along the low surface's normals per texel of its UV space (`Normals`)
//! or from two top-down depth renders (`TopDown`); optionally the low mesh tessellated on its
//! PN triangles and displaced by a second map measured from the PN surface
//! (`tessellated.obj` + `.mtl`, and `height_pn.png`); the distance to the high mesh of the low,
//! PN and displaced meshes in `report.json`.
//!
//! Jobs: `plan` (wave 0: both meshes), then the map's tail and the tessellation (wave 1).
//! Stage instances: `mesh` ×2 → `bvh` → `bake` (→ `mips → encode → write`); `tessellate` →
//! `bake(pn)` → `displace`; `distance` per measured mesh.

// The machinery this kind builds on, under the names its files use (`crate::db`, …).
use cirrus_core::{cache, config, db, diagnostic, gpu, kinds, mesh, summary, texture};

pub mod settings;
pub mod bake;
pub mod queries;

use crate::kinds::source_copies::{material_copy_paths, used_materials};
use crate::summary::ArtifactRole;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use serde::Serialize;

use crate::cache::CacheKey;
use crate::config::{AssetConfig, PipelineConfig};
use crate::db::{Asset, Db, StageRun};
use crate::diagnostic::{display_path, Diagnostic};
use crate::kinds::mesh_queries::{mesh_files_of, mesh_instance_of};
use crate::kinds::{tail_instances, AssetOutputs, Job, Kind, StageInstance, SurfaceFn, SurfaceId, SurfacePlan, Task};
use crate::mesh::surface_distance::SurfaceDistance;
use crate::settings::Settings as Own;
use crate::summary::ErrorSummary;
use crate::texture::tail::SurfaceInfo;
use crate::texture::{SurfaceKind, Texture};
use bake::Quantization;
use queries::{
    distance_label, distance_to_high, height_map, height_settings, high_geometry, high_path, low_geometry, map_key,
    map_label, tessellate_settings, tessellated_files, MapReference, Measured, BAKE, BVH, DISPLACE, DISTANCE,
    TESSELLATE,
};
use settings::HeightProjection;

pub struct Height;

/// The kind, as `pipeline.ron` and the driver name it.
pub const KIND: crate::config::AssetKind =
    crate::config::AssetKind::new(<settings::Settings as crate::config::KindEntry>::NAME, &QUESTIONS);
const QUESTIONS: crate::kinds::KindQuestions = crate::kinds::KindQuestions::of::<Height>();

/// The map's tail surface: the asset's own `height`.
fn height_surface() -> SurfaceId {
    SurfaceId::new(String::new(), SurfaceKind::Height)
}

/// The meshes measured against the high one, as the settings ask.
fn measured_meshes(db: &dyn Db, asset: Asset) -> Vec<Measured> {
    match tessellate_settings(db, asset) {
        None => vec![Measured::Low],
        Some(settings) if settings.displace => vec![Measured::Low, Measured::Pn, Measured::Displaced],
        Some(_) => vec![Measured::Low, Measured::Pn],
    }
}

/// The height kind's steps: both meshes (then the map and the rest), the tessellation, and one
/// measured mesh's distance to the high one.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Step {
    Plan,
    Tessellate,
    /// The `mesh`-th measured mesh.
    Distance {
        mesh: u32,
    },
}

impl crate::kinds::KindStep for Step {
    type Kind = Height;

    fn sort(&self) -> &'static str {
        match self {
            Step::Plan => "plan",
            Step::Tessellate => "tessellate",
            Step::Distance { .. } => "distance",
        }
    }
}

/// What a height bake holds per texel of its map at its peak, beyond its meshes: each texel's
/// surface point, ray and distance, the map and what the tail makes of it. Measured on the
/// bundled cow pair: `cirrus build` peaks at 70 MiB at `size: 512` and 264 MiB at 2048, 52 B a
/// texel more.
const HELD_BYTES_PER_MAP_TEXEL: u64 = 52;

impl Kind for Height {
    /// Its map of `size`².
    fn made_bytes(db: &dyn Db, asset: Asset) -> u64 {
        u64::from(queries::height_settings(db, asset).size).pow(2) * HELD_BYTES_PER_MAP_TEXEL
    }

    fn files_to_read(db: &dyn Db, asset: Asset) -> Vec<PathBuf> {
        let mut files = mesh_files_of(db, asset, asset.main_file(db));
        files.extend(mesh_files_of(db, asset, &high_path(db, asset)));
        // The low mesh's maps: the tessellated mesh's MTL and glTF name copies of them.
        if tessellate_settings(db, asset).is_some() {
            files.extend(crate::kinds::mesh_queries::mesh_textures(db, asset).iter().cloned());
        }
        files.sort();
        files.dedup();
        files
    }

    fn first_jobs(db: &dyn Db, asset: Asset) -> Vec<Job> {
        vec![Job { asset, task: Task::step(Step::Plan), after: 0, label: asset.name(db).clone() }]
    }

    type Step = Step;

    fn run_step(db: &dyn Db, asset: Asset, step: &Step) -> Result<Vec<Job>, Diagnostic> {
        let name = asset.name(db);
        match *step {
            Step::Plan => {
                low_geometry(db, asset)?;
                high_geometry(db, asset)?;
                let surface = height_surface();
                let mut jobs = vec![Job { asset, label: surface.label(name), task: Task::Surface(surface), after: 1 }];
                for (index, measured) in measured_meshes(db, asset).into_iter().enumerate() {
                    jobs.push(Job {
                        asset,
                        label: distance_label(name, measured),
                        task: Task::step(Step::Distance { mesh: index as u32 }),
                        after: 1,
                    });
                }
                if tessellate_settings(db, asset).is_some() {
                    jobs.push(Job {
                        asset,
                        label: format!("{name}/tessellated"),
                        task: Task::step(Step::Tessellate),
                        after: 1,
                    });
                }
                Ok(jobs)
            }
            Step::Tessellate => tessellated_files(db, asset).map(|_| Vec::new()),
            Step::Distance { mesh } => match measured_meshes(db, asset).get(mesh as usize) {
                Some(&measured) => distance_to_high(db, asset, measured).map(|_| Vec::new()),
                None => Ok(Vec::new()),
            },
        }
    }

    fn stage_instances(db: &dyn Db, asset: Asset, output_folder: &Path, errors: &[Diagnostic]) -> Vec<StageInstance> {
        let name = asset.name(db);
        let report = output_folder.join("report.json");
        let low = mesh_instance_of(db, asset, asset.main_file(db));
        let high = mesh_instance_of(db, asset, &high_path(db, asset));
        let bvh = StageInstance::new(BVH, name, name).reads_stage(&high);
        let settings = height_settings(db, asset);
        let mut map = StageInstance::new(BAKE, map_label(name, MapReference::Low), "height").reads_stage(&low);
        map = match settings.projection {
            HeightProjection::Normals => map.reads_stage(&bvh),
            HeightProjection::TopDown => map.reads_stage(&high),
        };
        let surface = height_surface();
        let encode = &asset.settings(db).encode;
        let [mips, encode, mut write] =
            tail_instances(name, &surface, &map, &surface.artifact_paths(output_folder, encode));
        write.writes.push(report.clone());
        let mut instances = vec![low.clone(), high.clone(), bvh.clone(), map, mips, encode, write];
        let distance = |measured: Measured, mesh: &StageInstance| {
            let mut instance =
                StageInstance::new(DISTANCE, distance_label(name, measured), format!("distance/{}", measured.name()))
                    .reads_stage(mesh)
                    .reads_stage(&bvh);
            instance.writes.push(report.clone());
            instance
        };
        let low_distance = distance(Measured::Low, &low);
        let mut more = vec![low_distance];
        if let Some(tessellate) = tessellate_settings(db, asset) {
            let pn = StageInstance::new(TESSELLATE, name, "tessellate").reads_stage(&low);
            let mut displace = StageInstance::new(DISPLACE, name, "displace").reads_stage(&pn);
            displace.writes = ["tessellated.obj", "tessellated.mtl", "tessellated.gltf", "tessellated.bin"]
                .map(|file| output_folder.join(file))
                .to_vec();
            // The copies of the maps its materials name.
            if let Ok(low) = low_geometry(db, asset) {
                let mesh = &low.loaded.mesh;
                let chosen = used_materials(&mesh.materials, &mesh.triangle_materials).1;
                displace.writes.extend(material_copy_paths(db, asset, output_folder, &chosen));
            }
            more.push(distance(Measured::Pn, &pn));
            if tessellate.displace {
                let pn_map = StageInstance::new(BAKE, map_label(name, MapReference::Pn), "height_pn")
                    .reads_stage(&low)
                    .reads_stage(&bvh);
                let mut pn_map_written = pn_map.clone();
                pn_map_written.writes.push(output_folder.join("height_pn.png"));
                displace = displace.reads_stage(&pn_map);
                more.push(distance(Measured::Displaced, &displace));
                instances.push(pn_map_written);
            }
            instances.push(pn);
            instances.push(displace);
        }
        instances.extend(more);
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
        crate::kinds::outputs_unless_failed(errors, || height_outputs(db, asset, output_folder, runs))
    }

    /// Both meshes load with their material libraries; a Normals bake or a displaced
    /// tessellation needs the low mesh's UVs.
    fn check(config: &PipelineConfig, asset: &AssetConfig) -> Vec<Diagnostic> {
        let low_file = &config.source.join(asset.source.main_file());
        let mut problems = Vec::new();
        match crate::kinds::checks::check_mesh_file(config, low_file) {
            Ok((mesh, warnings)) => {
                problems.extend(warnings);
                if asset.settings.own::<Own>().tessellate.is_some() {
                    problems.extend(crate::kinds::checks::check_copied_maps(config, low_file, &mesh, |_| true));
                }
                let settings = &asset.settings;
                let needs_uvs = settings.own::<Own>().height.projection == HeightProjection::Normals
                    || settings.own::<Own>().tessellate.is_some_and(|tessellate| tessellate.displace);
                if mesh.triangles.is_empty() {
                    problems.push(Diagnostic::new(low_file, "the low mesh has no triangles"));
                } else if needs_uvs && mesh.uvs.is_none() {
                    problems.push(Diagnostic::new(
                        low_file,
                        "the low mesh has no texture coordinates (`vt` in the OBJ): a Normals height bake and a \
                            displaced tessellation need its UV layout",
                    ));
                } else if settings.own::<Own>().height.projection == HeightProjection::Normals {
                    problems.extend(
                        crate::mesh::uvs_outside_warnings(low_file, &mesh)
                            .iter()
                            .map(crate::diagnostic::Diagnostic::as_warning),
                    );
                }
            }
            Err(diagnostic) => problems.push(diagnostic),
        }
        {
            let high = &asset.settings.own::<Own>().high_mesh;
            let high_file = &config.source.join(high);
            match crate::kinds::checks::check_mesh_file(config, high_file) {
                Ok((mesh, warnings)) => {
                    problems.extend(warnings);
                    if mesh.triangles.is_empty() {
                        problems.push(Diagnostic::new(high_file, "the high mesh has no triangles"));
                    }
                }
                Err(diagnostic) => problems.push(diagnostic),
            }
        }
        problems
    }

    fn surface_plan(db: &dyn Db, asset: Asset, surface: &SurfaceId) -> Result<SurfacePlan, Diagnostic> {
        let encode = &asset.settings(db).encode;
        let settings =
            crate::kinds::tail_settings_from(encode, surface.surface, encode.format_of(surface.surface), None);
        let image: SurfaceFn<Arc<Texture>> = |db, asset, _| {
            let files = height_map(db, asset, MapReference::Low)?;
            let map = &files.map;
            Ok(Arc::new(crate::texture::grey16_texture(map.size, map.size, &map.values16())))
        };
        let recipe: SurfaceFn<Option<CacheKey>> = |db, asset, _| map_key(db, asset, MapReference::Low).map(Some);
        Ok(SurfacePlan::new(settings, recipe, image))
    }
}

/// `report.json` of a height bake.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub(crate) struct HeightReport {
    pub asset: String,
    pub kind: &'static str,
    pub high: String,
    pub low: String,
    pub projection: HeightProjection,
    /// The rays' reach in mesh units (`Normals`).
    pub frontal: f32,
    pub rear: f32,
    pub map: HeightMapReport,
    /// The map the tessellation is displaced by, measured from the PN surface.
    pub pn_map: Option<HeightMapReport>,
    pub tessellated: Option<TessellatedReport>,
    /// Distances to the high mesh over its bounding-box diagonal: samples by area, both ways.
    pub distance: DistanceReport,
    pub stage_ms: std::collections::BTreeMap<String, f64>,
    pub warnings: Vec<ErrorSummary>,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub(crate) struct HeightMapReport {
    /// The 16-bit map.
    pub png: String,
    pub size: u32,
    /// `distance = (value − center) × magnitude`, value = the 16-bit value / 65535.
    #[serde(flatten)]
    pub quantization: Quantization,
    /// The smallest and largest measured distance, mesh units.
    pub range: [f32; 2],
    pub measured_texels: u64,
    /// Texels on the surface with no high surface within reach: filled.
    pub missed_texels: u64,
    /// The heights span less than `bake::FLAT_FRACTION` of the search: the high mesh lies on
    /// the low one, and the map is flat (its values sit at the middle, noise unstretched).
    pub flat: bool,
    pub texture: Option<HeightTextureReport>,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub(crate) struct HeightTextureReport {
    pub path: String,
    #[serde(flatten)]
    pub info: SurfaceInfo,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub(crate) struct TessellatedReport {
    pub obj: String,
    pub gltf: String,
    pub level: u32,
    pub displace: bool,
    pub vertices: u64,
    pub triangles: u64,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub(crate) struct DistanceReport {
    pub samples_per_surface: usize,
    pub low: Option<SurfaceDistance>,
    pub pn: Option<SurfaceDistance>,
    pub pn_displaced: Option<SurfaceDistance>,
}

fn map_report(files: &queries::HeightMapFiles, png: &Path, texture: Option<HeightTextureReport>) -> HeightMapReport {
    let map = &files.map;
    HeightMapReport {
        png: display_path(png),
        size: map.size,
        quantization: map.quantization(),
        range: map.range,
        measured_texels: map.measured_texels,
        missed_texels: map.missed_texels,
        flat: map.is_flat(),
        texture,
    }
}

/// The warning of a flat map: what the heights span, against the search.
fn flat_map_warning(files: &queries::HeightMapFiles, high: &Path, which: &str) -> Option<ErrorSummary> {
    let map = &files.map;
    map.is_flat().then(|| {
        let middle = 0.5 * (map.range[0] + map.range[1]);
        let what = if middle.abs() < bake::FLAT_FRACTION * map.search_span {
            "the high mesh lies on the low one".to_string()
        } else {
            format!("the high surface lies at a constant {middle} from the low one")
        };
        ErrorSummary::from(&Diagnostic::new(
            high,
            format!(
                "the {which} map is flat: every measured height lies within {:e} of the others (under {} of \
                    the {:e} searched): {what}, and the map holds no relief (its values sit at the middle of the \
                    16-bit range, not stretched over noise)",
                map.range[1] - map.range[0],
                bake::FLAT_FRACTION,
                map.search_span
            ),
        ))
    })
}

fn height_outputs(
    db: &dyn Db,
    asset: Asset,
    output_folder: &Path,
    runs: &[StageRun],
) -> Result<AssetOutputs, Diagnostic> {
    let settings = height_settings(db, asset);
    let encode = &asset.settings(db).encode;
    let low = low_geometry(db, asset)?;
    let mut outputs = AssetOutputs::default();
    let surface = height_surface();
    let artifacts = crate::kinds::tail_queries::surface_artifacts(db, asset, surface.clone())?;
    let map = height_map(db, asset, MapReference::Low)?;
    let [texture_path, png_path] = surface.artifact_paths(output_folder, encode);
    outputs.add(texture_path.clone(), ArtifactRole::Texture, artifacts.texture_file.clone());
    outputs.add(png_path.clone(), ArtifactRole::Image, map.png16.clone());
    let meaning = |files: &queries::HeightMapFiles| serde_json::json!({ "distance": files.map.quantization() });
    outputs.meanings.insert(png_path.clone(), meaning(&map));
    outputs.meanings.insert(texture_path.clone(), meaning(&map));
    let texture = HeightTextureReport { path: display_path(&texture_path), info: artifacts.info.clone() };
    let low_map_report = map_report(&map, &png_path, Some(texture));
    let mut pn_map_report = None;
    let mut tessellated = None;
    let mut material_warnings = Vec::new();
    if let Some(tessellate) = tessellate_settings(db, asset) {
        if tessellate.displace {
            let pn_map = height_map(db, asset, MapReference::Pn)?;
            let pn_png = output_folder.join("height_pn.png");
            outputs.add(pn_png.clone(), ArtifactRole::Image, pn_map.png16.clone());
            outputs.meanings.insert(pn_png.clone(), meaning(&pn_map));
            pn_map_report = Some(map_report(&pn_map, &pn_png, None));
        }
        let files = tessellated_files(db, asset)?;
        let obj_path = output_folder.join("tessellated.obj");
        outputs.add(obj_path.clone(), ArtifactRole::Mesh, files.obj.clone());
        let gltf_path =
            tessellated_gltf(db, asset, output_folder, &files, &low.loaded.mesh, &mut outputs, &mut material_warnings)?;
        tessellated = Some(TessellatedReport {
            obj: display_path(&obj_path),
            gltf: display_path(&gltf_path),
            level: tessellate.level,
            displace: tessellate.displace,
            vertices: files.vertices,
            triangles: files.triangles,
        });
    }
    let measured = measured_meshes(db, asset);
    let distance_of = |which: Measured| -> Result<Option<SurfaceDistance>, Diagnostic> {
        if measured.contains(&which) {
            distance_to_high(db, asset, which)
        } else {
            Ok(None)
        }
    };
    let distance = DistanceReport {
        samples_per_surface: queries::DISTANCE_SAMPLES,
        low: distance_of(Measured::Low)?,
        pn: distance_of(Measured::Pn)?,
        pn_displaced: distance_of(Measured::Displaced)?,
    };
    let name = asset.name(db);
    let high = high_geometry(db, asset)?;
    let mut warnings: Vec<ErrorSummary> = low.loaded.warnings.iter().map(ErrorSummary::from).collect();
    warnings.extend(high.loaded.warnings.iter().map(ErrorSummary::from));
    if settings.projection == HeightProjection::Normals {
        warnings.extend(
            crate::mesh::uvs_outside_warnings(asset.main_file(db), &low.loaded.mesh).iter().map(ErrorSummary::from),
        );
    }
    warnings.extend(flat_map_warning(&*height_map(db, asset, MapReference::Low)?, &high_path(db, asset), "height"));
    warnings.extend(material_warnings.iter().map(ErrorSummary::from));
    let report = HeightReport {
        asset: name.clone(),
        kind: KIND.name(),
        high: display_path(&high_path(db, asset)),
        low: display_path(asset.main_file(db)),
        projection: settings.projection,
        frontal: settings.frontal * low.diagonal,
        rear: settings.rear * low.diagonal,
        map: low_map_report,
        pn_map: pn_map_report,
        tessellated,
        distance,
        stage_ms: crate::kinds::asset_stage_ms(name, runs)
            .into_iter()
            .map(|(stage, ms)| (stage.to_string(), ms))
            .collect(),
        warnings,
    };
    outputs.report = Some(serde_json::to_vec_pretty(&report).expect("reports serialise"));
    outputs.warnings = report.warnings;
    Ok(outputs)
}

/// `tessellated.mtl`, `tessellated.gltf` and its `tessellated.bin`: the tessellated mesh's used
/// materials over copies of their maps in the output (`source_copies`). Gives the glTF's path,
/// or the first map that is not the image its name says.
fn tessellated_gltf(
    db: &dyn Db,
    asset: Asset,
    output_folder: &Path,
    files: &queries::TessellatedFiles,
    low: &crate::mesh::Mesh,
    outputs: &mut AssetOutputs,
    warnings: &mut Vec<Diagnostic>,
) -> Result<PathBuf, Diagnostic> {
    use crate::kinds::source_copies::{written_materials, MaterialPlaces};
    let geometry = &files.geometry;
    let places = MaterialPlaces { source: asset.main_file(db), mtl_folder: output_folder, gltf_folder: output_folder };
    let written = written_materials(
        db,
        asset,
        output_folder,
        outputs,
        (&low.materials, &geometry.triangle_materials),
        &places,
        warnings,
    );
    if let Some(error) = written.errors.into_iter().next() {
        return Err(error);
    }
    outputs.add(output_folder.join("tessellated.mtl"), ArtifactRole::Mtl, written.mtl.into_bytes().into());
    let mesh = crate::mesh::gltf::GltfMesh {
        triangle_materials: &written.triangle_materials,
        ..geometry.mesh(asset.name(db), &written.gltf)
    };
    let gltf = crate::mesh::gltf::gltf_files(&mesh, "tessellated.bin", crate::mesh::gltf::GENERATOR);
    let gltf_path = output_folder.join("tessellated.gltf");
    outputs.add(gltf_path.clone(), ArtifactRole::Gltf, gltf.gltf.into());
    outputs.add(output_folder.join("tessellated.bin"), ArtifactRole::GltfBuffer, gltf.bin.into());
    Ok(gltf_path)
}
