//! The `Material` kind: a `.mymaterial` file and the texture maps it names, packed into albedo,
//! mra and normal surfaces per material that end in the shared texture tail.
//!
//! Jobs: `parse` (wave 0), then one tail job per material × surface. Stage instances: `parse`,
//! a `decode` per texture, then per surface `pack → mips → encode → write`.

// The machinery this kind builds on, under the names its files use (`crate::db`, …).
use cirrus_core::{cache, config, db, diagnostic, kinds, mesh, openddl, sources, summary, texture};

pub mod settings;
pub mod definition;
pub mod queries;

use crate::mesh::gltf::{swatch_files, GltfAlpha, GltfMaterial, GltfWrap};
use crate::summary::ArtifactRole;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use serde::Serialize;

use crate::cache::CacheKey;
use crate::config::{AssetConfig, PipelineConfig};
use crate::db::{Asset, Db, StageRun, DECODE};
use crate::diagnostic::{display_path, Diagnostic};
use crate::kinds::checks::check_texture_file;
use crate::kinds::{
    tail_instances, AssetOutputs, Job, Kind, Read, StageInstance, SurfaceFn, SurfaceId, SurfacePlan, Task,
};
use crate::settings::Settings as Own;
use crate::summary::ErrorSummary;
use crate::texture::tail::SurfaceInfo;
use crate::texture::{SurfaceKind, Texture};
use queries::{material_file, referenced_textures, surface_recipe, MapSource, PACK, PARSE};

pub struct Material;

/// The kind, as `pipeline.ron` and the driver name it.
pub const KIND: crate::config::AssetKind =
    crate::config::AssetKind::new(<settings::Settings as crate::config::KindEntry>::NAME, &QUESTIONS);
const QUESTIONS: crate::kinds::KindQuestions = crate::kinds::KindQuestions::of::<Material>();

/// The surfaces of every material of the asset, in file order.
fn surfaces(parsed: &definition::MaterialFile) -> Vec<SurfaceId> {
    let materials = parsed.materials.iter();
    materials
        .flat_map(|material| SurfaceKind::MATERIAL.map(|surface| SurfaceId::new(material.name.clone(), surface)))
        .collect()
}

/// The material kind's one step: parse the material file, then schedule its surfaces.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Step {
    Parse,
}

impl crate::kinds::KindStep for Step {
    type Kind = Material;

    fn sort(&self) -> &'static str {
        "parse"
    }
}

impl Kind for Material {
    fn keep_memos(db: &mut dyn Db, surfaces: usize) {
        queries::keep_memos(db, surfaces);
    }

    fn files_to_read(db: &dyn Db, asset: Asset) -> Vec<PathBuf> {
        let mut files = vec![asset.main_file(db).clone()];
        if let Ok(parsed) = material_file(db, asset) {
            files.extend(referenced_textures(&parsed));
        }
        files
    }

    fn first_jobs(db: &dyn Db, asset: Asset) -> Vec<Job> {
        vec![Job { asset, task: Task::step(Step::Parse), after: 0, label: display_path(asset.main_file(db)) }]
    }

    type Step = Step;

    fn run_step(db: &dyn Db, asset: Asset, _step: &Step) -> Result<Vec<Job>, Diagnostic> {
        let parsed = material_file(db, asset)?;
        for warning in &parsed.warnings {
            tracing::warn!("{warning}");
        }
        let name = asset.name(db);
        Ok(surfaces(&parsed)
            .into_iter()
            .map(|surface| Job { asset, label: surface.label(name), task: Task::Surface(surface), after: 1 })
            .collect())
    }

    fn stage_instances(db: &dyn Db, asset: Asset, output_folder: &Path, errors: &[Diagnostic]) -> Vec<StageInstance> {
        let main_file = asset.main_file(db);
        let main_label = display_path(main_file);
        let parsed = material_file(db, asset);
        let mut parse = StageInstance::new(PARSE, &main_label, &main_label);
        parse.reads.push(Read::File(main_file.clone()));
        parse.failed = parsed.is_err();
        let report = output_folder.join("report.json");
        parse.writes.push(report.clone());
        let mut instances = vec![parse.clone()];
        let Ok(parsed) = parsed else { return instances };
        for path in referenced_textures(&parsed) {
            let label = display_path(&path);
            let mut decode = StageInstance::new(DECODE, &label, &label);
            decode.reads.push(Read::File(path.clone()));
            decode.shared = true;
            decode.failed = errors.iter().any(|error| error.file == path);
            instances.push(decode);
        }
        let encode = &asset.settings(db).encode;
        let name = asset.name(db);
        for surface in surfaces(&parsed) {
            let mut pack = StageInstance::new(PACK, surface.label(name), surface.instance()).reads_stage(&parse);
            if let Ok(recipe) = surface_recipe(db, asset, surface.clone()) {
                for source in recipe.sources.iter().flatten() {
                    pack.reads.push(match source {
                        MapSource::File(file) => Read::Stage(DECODE, display_path(file.path(db))),
                        // Another asset's map (`ao_source`): the edge between the two assets.
                        MapSource::Asset { stage, .. } => stage.clone(),
                    });
                }
            } else if let Some(material) = parsed.materials.iter().find(|material| material.name == surface.group) {
                for slot in surface.surface.slots() {
                    if let Some(reference) = material.textures.get(slot) {
                        pack.reads.push(Read::Stage(DECODE, display_path(&reference.path)));
                    }
                }
            }
            let folder = surface.folder(output_folder);
            let [mut mips, encode, mut write] =
                tail_instances(name, &surface, &pack, &surface.written_files(output_folder, encode));
            // The alpha cutoff of an albedo's mips comes from the material's constants.
            mips = mips.reads_stage(&parse);
            write.writes.push(report.clone());
            // The material's glTF swatch, written with its albedo.
            if surface.surface == SurfaceKind::Albedo {
                write.writes.extend([folder.join("material.gltf"), folder.join("material.bin")]);
            }
            instances.extend([pack, mips, encode, write]);
        }
        instances
    }

    fn outputs(
        db: &dyn Db,
        asset: Asset,
        output_folder: &Path,
        errors: &mut Vec<Diagnostic>,
        _runs: &[StageRun],
    ) -> AssetOutputs {
        let Ok(parsed) = material_file(db, asset) else { return AssetOutputs::default() };
        let encode = &asset.settings(db).encode;
        let mut outputs = AssetOutputs::default();
        let mut materials = Vec::new();
        for material in &parsed.materials {
            let mut reports = Vec::new();
            let mut swatch = GltfMaterial {
                name: material.name.clone(),
                base_colour_factor: [1.0; 4],
                metallic_factor: 1.0,
                roughness_factor: 1.0,
                base_colour: None,
                normal: None,
                occlusion: None,
                metallic_roughness: None,
                alpha: GltfAlpha::Opaque,
                double_sided: false,
                // A material is a tiling texture set.
                wrap: GltfWrap::Repeat,
            };
            for surface in SurfaceKind::MATERIAL {
                let id = SurfaceId::new(material.name.clone(), surface);
                let Ok(artifacts) = crate::kinds::tail_queries::surface_artifacts(db, asset, id.clone()) else {
                    continue;
                };
                let [texture_path, preview_path] = id.artifact_paths(output_folder, encode);
                let other_formats = if asset.settings(db).own::<Own>().report.compare_formats {
                    crate::kinds::tail_queries::surface_format_comparison(db, asset, id.clone())
                        .ok()
                        .map(|figures| figures.to_vec())
                } else {
                    None
                };
                reports.push(SurfaceReport {
                    path: display_path(&texture_path),
                    preview: display_path(&preview_path),
                    info: artifacts.info.clone(),
                    other_formats,
                });
                outputs.add(texture_path, ArtifactRole::Texture, artifacts.texture_file.clone());
                outputs.add(preview_path.clone(), ArtifactRole::Image, artifacts.preview_png.clone());
                let preview_name = || preview_path.file_name().map(|name| name.to_string_lossy().to_string());
                match surface {
                    SurfaceKind::Albedo => {
                        swatch.base_colour = preview_name();
                        if artifacts.info.alpha_tested {
                            let tail = crate::kinds::tail_queries::tail_settings(db, asset, id.clone());
                            let cutoff = tail.ok().and_then(|tail| tail.alpha_cutoff);
                            (swatch.alpha, swatch.double_sided) = (GltfAlpha::Mask(cutoff.unwrap_or(0.5)), true);
                        }
                    }
                    SurfaceKind::Normal => swatch.normal = preview_name(),
                    // `orm.png`: the preview itself when packed in ORM order, else written beside.
                    SurfaceKind::Mra => {
                        swatch.occlusion = Some("orm.png".into());
                        swatch.metallic_roughness = Some("orm.png".into());
                    }
                    _ => {}
                }
                if let Some(orm_png) = &artifacts.orm_png {
                    outputs.add(id.folder(output_folder).join("orm.png"), ArtifactRole::Image, orm_png.clone());
                }
            }
            // The material as glTF: a swatch square an engine or viewer can load as it is.
            let folder = SurfaceId::new(material.name.clone(), SurfaceKind::Albedo).folder(output_folder);
            let files = swatch_files(swatch, "material.bin", crate::mesh::gltf::GENERATOR);
            outputs.add(folder.join("material.gltf"), ArtifactRole::Gltf, files.gltf.into());
            outputs.add(folder.join("material.bin"), ArtifactRole::GltfBuffer, files.bin.into());
            materials.push(MaterialReportEntry {
                name: material.name.clone(),
                display_name: material.display_name.clone(),
                surfaces: reports,
            });
        }
        let report = MaterialReport {
            asset: asset.name(db).clone(),
            kind: KIND.name(),
            file: display_path(asset.main_file(db)),
            materials,
            warnings: parsed.warnings.iter().map(ErrorSummary::from).collect(),
            errors: errors.iter().map(ErrorSummary::from).collect(),
        };
        outputs.report = Some(serde_json::to_vec_pretty(&report).expect("reports serialise"));
        outputs.warnings = report.warnings;
        outputs
    }

    /// The material file parses, and every texture it names is readable and within the limits;
    /// warnings are reported as problems too.
    fn check(config: &PipelineConfig, asset: &AssetConfig) -> Vec<Diagnostic> {
        let main_file = &config.source.join(asset.source.main_file());
        let contents = match crate::sources::read_source(&config.root, &config.source, main_file) {
            Ok(contents) => contents,
            Err(error) => return vec![Diagnostic::new(main_file, error)],
        };
        let parsed =
            match contents.bytes().and_then(|bytes| definition::parse_material_file(main_file, &bytes, &config.source))
            {
                Ok(parsed) => parsed,
                Err(diagnostic) => return vec![diagnostic],
            };
        let mut problems: Vec<Diagnostic> = parsed.warnings.iter().map(Diagnostic::as_warning).collect();
        for reference in parsed.materials.iter().flat_map(|material| material.textures.values()) {
            if let Err(message) = check_texture_file(config, &reference.path) {
                let message =
                    format!("texture \"{}\" ({}): {message}", reference.written, display_path(&reference.path));
                problems.push(Diagnostic::at(main_file, reference.position, message));
            }
        }
        problems
    }

    fn surface_plan(db: &dyn Db, asset: Asset, surface: &SurfaceId) -> Result<SurfacePlan, Diagnostic> {
        let settings = asset.settings(db);
        let encode = &settings.encode;
        let alpha_cutoff = match surface.surface {
            SurfaceKind::Albedo => {
                let recipe = surface_recipe(db, asset, surface.clone())?;
                Some(recipe.constants.alpha_cutoff.unwrap_or(settings.own::<Own>().alpha_cutoff))
            }
            _ => None,
        };
        let settings =
            crate::kinds::tail_settings_from(encode, surface.surface, encode.format_of(surface.surface), alpha_cutoff);
        let image: SurfaceFn<Arc<Texture>> = queries::surface_for_tail;
        let recipe: SurfaceFn<Option<CacheKey>> =
            |db, asset, surface| queries::surface_recipe_key(db, asset, surface.clone()).map(Some);
        Ok(SurfacePlan::new(settings, recipe, image))
    }
}

/// `report.json` of a material asset.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub(crate) struct MaterialReport {
    pub asset: String,
    pub kind: &'static str,
    pub file: String,
    pub materials: Vec<MaterialReportEntry>,
    pub warnings: Vec<ErrorSummary>,
    pub errors: Vec<ErrorSummary>,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub(crate) struct MaterialReportEntry {
    pub name: String,
    pub display_name: Option<String>,
    pub surfaces: Vec<SurfaceReport>,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub(crate) struct SurfaceReport {
    pub path: String,
    pub preview: String,
    #[serde(flatten)]
    pub info: SurfaceInfo,
    /// With `report: (compare_formats: true)`: what the other formats the surface may take
    /// would cost (bits per texel) and give (level 0's PSNR).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub other_formats: Option<Vec<crate::texture::tail::FormatFigure>>,
}
