//! The build driver: reads sources into salsa inputs (only when their bytes changed), runs the
//! stages of every asset on worker threads with database clones, writes the artifacts and the
//! manifest, and says what ran. It is the one place where the pipeline meets the disk.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::panic::AssertUnwindSafe;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

use salsa::plumbing::AsId;
use salsa::Setter;

use crate::artifacts::{load_manifest, save_manifest, write_if_changed, Manifest, ManifestEntry};
use crate::cache::DiskCache;
use crate::config::{AssetConfig, AssetSource, PipelineConfig, Settings};
use crate::db::{
    material_file, surface_artifacts, Database, MaterialAsset, SourceFile, Stage, StageRun,
    SurfaceArtifacts, SurfaceKey,
};
use crate::diagnostic::{display_path, Diagnostic};
use crate::material_definition::MaterialFile;
use crate::sources::{read_source, rule_matches};
use crate::summary::{
    ArtifactSummary, AssetStatus, AssetSummary, BuildSummary, ErrorSummary, MaterialReport,
    MaterialReportEntry, StageStatus, StageSummary, SurfaceReport,
};
use crate::surface::SurfaceKind;

/// How a project is opened.
#[derive(Clone, Debug)]
pub struct ProjectOptions {
    /// Keep stage results on disk under `<output>/.cirrus/cache` across runs.
    pub persistent_cache: bool,
}

impl Default for ProjectOptions {
    fn default() -> Self {
        ProjectOptions {
            persistent_cache: true,
        }
    }
}

/// What one build covers.
#[derive(Clone, Debug, Default)]
pub struct BuildOptions {
    /// Build only these assets (all when empty).
    pub only_assets: Vec<String>,
}

/// Progress of the stage work of a build, for progress bars and logs.
#[derive(Clone, Debug)]
pub struct Progress {
    pub done: usize,
    pub total: usize,
    /// What just finished, e.g. `bark/oak_bark/albedo`.
    pub item: String,
}

#[derive(Debug, thiserror::Error)]
pub enum BuildError {
    #[error("no asset named `{name}` in {pipeline}")]
    UnknownAsset { name: String, pipeline: String },
}

/// An open project: the pipeline, the salsa database and the inputs created so far.
pub struct Project {
    config: PipelineConfig,
    db: Database,
    files: HashMap<PathBuf, SourceFile>,
    assets: HashMap<String, MaterialAsset>,
    surfaces: HashMap<(String, String, SurfaceKind), SurfaceKey>,
    /// Readable names of input ids, for the event log.
    labels: HashMap<salsa::Id, String>,
}

/// One asset's share of a build.
struct AssetPlan {
    config: AssetConfig,
    main_file: PathBuf,
    input: Option<MaterialAsset>,
    parsed: Option<Arc<MaterialFile>>,
    surfaces: Vec<(String, SurfaceKind, SurfaceKey)>,
    errors: Vec<Diagnostic>,
}

impl Project {
    pub fn open(config: PipelineConfig, options: ProjectOptions) -> Project {
        let cache = options
            .persistent_cache
            .then(|| DiskCache::new(config.output_dir().join(".cirrus").join("cache")));
        Project {
            config,
            db: Database::new(cache),
            files: HashMap::new(),
            assets: HashMap::new(),
            surfaces: HashMap::new(),
            labels: HashMap::new(),
        }
    }

    pub fn config(&self) -> &PipelineConfig {
        &self.config
    }

    /// Replaces the pipeline; settings changes reach only the stages that read them.
    pub fn reconfigure(&mut self, config: PipelineConfig) {
        self.config = config;
    }

    /// The assets of the pipeline: the listed ones, then files matching `rules`.
    pub fn asset_list(&self) -> Vec<AssetConfig> {
        let mut assets = self.config.assets.clone();
        let mut names: BTreeSet<String> = assets.iter().map(|asset| asset.name.clone()).collect();
        for relative in rule_matches(&self.config) {
            if let Some(asset) = self.config.asset_for_rule_match(&relative) {
                if names.insert(asset.name.clone()) {
                    assets.push(asset);
                }
            }
        }
        assets
    }

    /// Bakes the assets, writing only artifacts whose bytes changed.
    pub fn build(
        &mut self,
        options: &BuildOptions,
        progress: &(dyn Fn(Progress) + Sync),
    ) -> Result<BuildSummary, BuildError> {
        let all_assets = self.asset_list();
        for name in &options.only_assets {
            if !all_assets.iter().any(|asset| &asset.name == name) {
                return Err(BuildError::UnknownAsset {
                    name: name.clone(),
                    pipeline: display_path(&self.config.file),
                });
            }
        }
        let selected: Vec<AssetConfig> = all_assets
            .iter()
            .filter(|asset| {
                options.only_assets.is_empty() || options.only_assets.contains(&asset.name)
            })
            .cloned()
            .collect();

        let mut plans: Vec<AssetPlan> = selected
            .into_iter()
            .map(|asset| self.plan_asset(asset))
            .collect();
        let keys: Vec<SurfaceKey> = plans
            .iter()
            .flat_map(|plan| plan.surfaces.iter().map(|(_, _, key)| *key))
            .collect();
        let results = self.run_surfaces(&keys, progress);
        let runs = self.db.take_runs();

        let output_dir = self.config.output_dir();
        let mut manifest = load_manifest(&output_dir);
        let next_revision = manifest.revision + 1;
        let mut changed = false;
        let mut summaries = Vec::new();
        let mut results = results.into_iter();
        for plan in &mut plans {
            let surface_results: Vec<_> = results.by_ref().take(plan.surfaces.len()).collect();
            // Project-relative artifact path → blake3 hex of what this build wrote there.
            let mut produced = BTreeMap::new();
            for result in &surface_results {
                if let Err(diagnostic) = result {
                    if !plan.errors.contains(diagnostic) {
                        plan.errors.push(diagnostic.clone());
                    }
                }
            }
            if let Some(report) = self.write_surfaces(plan, &surface_results, &mut produced) {
                let mut bytes = serde_json::to_vec_pretty(&report).expect("reports serialise");
                bytes.push(b'\n');
                let path = self
                    .config
                    .output
                    .join(&plan.config.name)
                    .join("report.json");
                self.write_artifact(&path, &bytes, &mut plan.errors, &mut produced);
            }
            for (path, hash) in &produced {
                changed |=
                    record_artifact(&mut manifest, next_revision, &plan.config.name, path, hash);
            }
            if plan.errors.is_empty() {
                // A fully baked asset owns exactly what it produced: drop stale artifacts.
                let name = &plan.config.name;
                changed |= remove_artifacts(&self.config.root, &mut manifest, |path, entry| {
                    &entry.asset == name && !produced.contains_key(path)
                });
            }
            summaries.push(self.asset_summary(plan, &surface_results, &runs, &manifest));
        }
        if options.only_assets.is_empty() {
            // Artifacts of assets that left the pipeline.
            let names: BTreeSet<&str> =
                all_assets.iter().map(|asset| asset.name.as_str()).collect();
            changed |= remove_artifacts(&self.config.root, &mut manifest, |_, entry| {
                !names.contains(entry.asset.as_str())
            });
        }
        if changed {
            manifest.revision = next_revision;
            if let Err(error) = save_manifest(&output_dir, &manifest) {
                tracing::error!(
                    "cannot write {}: {error}",
                    display_path(&crate::artifacts::manifest_path(&output_dir))
                );
            }
        }
        Ok(BuildSummary {
            revision: manifest.revision,
            assets: summaries,
        })
    }

    /// Validates every asset's sources without baking: the material files parse, and every
    /// texture they name exists and has a readable image header.
    pub fn check(&self) -> Vec<(String, Vec<Diagnostic>)> {
        self.asset_list()
            .into_iter()
            .map(|asset| {
                let main_file = self.config.source.join(asset.source.main_file());
                let mut problems = Vec::new();
                match &asset.source {
                    AssetSource::BillboardCloud { .. } => problems.push(Diagnostic::new(
                        &main_file,
                        format!("asset `{}`: BillboardCloud assets are not baked by this version of cirrus yet", asset.name),
                    )),
                    AssetSource::Material { .. } => match read_source(&self.config.root, &main_file) {
                        Err(error) => problems.push(Diagnostic::new(&main_file, error)),
                        Ok(contents) => match crate::material_definition::parse_material_file(&main_file, &contents.bytes, &self.config.source) {
                            Err(diagnostic) => problems.push(diagnostic),
                            Ok(parsed) => {
                                problems.extend(parsed.warnings.iter().cloned().map(|mut warning| {
                                    warning.message = format!("warning: {}", warning.message);
                                    warning
                                }));
                                for reference in parsed.materials.iter().flat_map(|material| material.textures.values()) {
                                    let probed = read_source(&self.config.root, &reference.path)
                                        .map_err(|error| format!("texture \"{}\" ({}): {error}", reference.written, display_path(&reference.path)))
                                        .and_then(|contents| {
                                            crate::texture::probe_texture(&reference.path, &contents.bytes).map_err(|diagnostic| diagnostic.to_string())
                                        });
                                    if let Err(message) = probed {
                                        problems.push(Diagnostic::at(&main_file, reference.position, message));
                                    }
                                }
                            }
                        },
                    },
                }
                (asset.name, problems)
            })
            .collect()
    }

    /// The stage functions salsa executed since the last call, as `stage(instance)`, sorted.
    pub fn take_executed_stages(&self) -> Vec<String> {
        let mut executed: Vec<String> = self
            .db
            .take_executed()
            .into_iter()
            .filter_map(|executed| {
                let stage = Stage::of_function(&executed.function)?;
                let label = self
                    .labels
                    .get(&executed.key)
                    .cloned()
                    .unwrap_or_else(|| format!("{:?}", executed.key));
                Some(format!("{}({label})", stage.name()))
            })
            .collect();
        executed.sort();
        executed
    }

    /// The salsa input of a file, read from disk now; set again only when its bytes changed.
    fn source_file(&mut self, path: &Path) -> SourceFile {
        let contents = read_source(&self.config.root, path);
        match self.files.get(path) {
            Some(&file) => {
                if file.contents(&self.db) != &contents {
                    let _previous = file.set_contents(&mut self.db).to(contents);
                }
                file
            }
            None => {
                let file = SourceFile::new(&self.db, path.to_path_buf(), contents);
                self.labels.insert(file.as_id(), display_path(path));
                self.files.insert(path.to_path_buf(), file);
                file
            }
        }
    }

    fn material_asset(
        &mut self,
        name: &str,
        file: SourceFile,
        settings: &Settings,
    ) -> MaterialAsset {
        let source_root = self.config.source.clone();
        match self.assets.get(name) {
            Some(&asset) => {
                if asset.file(&self.db) != file {
                    asset.set_file(&mut self.db).to(file);
                }
                if asset.settings(&self.db) != settings {
                    asset.set_settings(&mut self.db).to(settings.clone());
                }
                if asset.source_root(&self.db) != &source_root {
                    asset.set_source_root(&mut self.db).to(source_root);
                }
                asset
            }
            None => {
                let asset = MaterialAsset::new(
                    &self.db,
                    name.to_string(),
                    source_root,
                    file,
                    settings.clone(),
                    Arc::new(BTreeMap::new()),
                );
                self.labels
                    .insert(asset.as_id(), display_path(file.path(&self.db)));
                self.assets.insert(name.to_string(), asset);
                asset
            }
        }
    }

    fn surface_key(
        &mut self,
        asset_name: &str,
        asset: MaterialAsset,
        material: &str,
        surface: SurfaceKind,
    ) -> SurfaceKey {
        let id = (asset_name.to_string(), material.to_string(), surface);
        if let Some(&key) = self.surfaces.get(&id) {
            if key.asset(&self.db) == asset {
                return key;
            }
        }
        let key = SurfaceKey::new(&self.db, asset, material.to_string(), surface);
        self.labels.insert(
            key.as_id(),
            format!("{asset_name}/{material}/{}", surface.name()),
        );
        self.surfaces.insert(id, key);
        key
    }

    /// Reads an asset's sources into inputs and parses it: everything up to the surface stages.
    fn plan_asset(&mut self, config: AssetConfig) -> AssetPlan {
        let main_file = self.config.source.join(config.source.main_file());
        let mut plan = AssetPlan {
            config,
            main_file,
            input: None,
            parsed: None,
            surfaces: Vec::new(),
            errors: Vec::new(),
        };
        match plan.config.source.clone() {
            AssetSource::BillboardCloud { .. } => {
                plan.errors.push(Diagnostic::new(
                    &plan.main_file,
                    format!("asset `{}`: BillboardCloud assets are not baked by this version of cirrus yet", plan.config.name),
                ));
            }
            AssetSource::Material { .. } => {
                let file = self.source_file(&plan.main_file);
                let input = self.material_asset(&plan.config.name, file, &plan.config.settings);
                plan.input = Some(input);
                match material_file(&self.db, input) {
                    Err(diagnostic) => plan.errors.push(diagnostic),
                    Ok(parsed) => {
                        for warning in &parsed.warnings {
                            tracing::warn!("{warning}");
                        }
                        let mut textures = BTreeMap::new();
                        for material in &parsed.materials {
                            for reference in material.textures.values() {
                                let file = self.source_file(&reference.path);
                                textures.insert(reference.path.clone(), file);
                            }
                        }
                        if **input.textures(&self.db) != textures {
                            input.set_textures(&mut self.db).to(Arc::new(textures));
                        }
                        for material in &parsed.materials {
                            for surface in SurfaceKind::ALL {
                                let key = self.surface_key(
                                    &plan.config.name,
                                    input,
                                    &material.name,
                                    surface,
                                );
                                plan.surfaces.push((material.name.clone(), surface, key));
                            }
                        }
                        plan.parsed = Some(parsed);
                    }
                }
            }
        }
        plan
    }

    /// Runs the surface stages of `keys` on worker threads, each with its own database clone.
    fn run_surfaces(
        &self,
        keys: &[SurfaceKey],
        progress: &(dyn Fn(Progress) + Sync),
    ) -> Vec<Result<Arc<SurfaceArtifacts>, Diagnostic>> {
        let results: Mutex<Vec<Option<Result<Arc<SurfaceArtifacts>, Diagnostic>>>> =
            Mutex::new(vec![None; keys.len()]);
        let next = AtomicUsize::new(0);
        let done = AtomicUsize::new(0);
        let workers = std::thread::available_parallelism()
            .map_or(2, |count| count.get())
            .min(keys.len().max(1));
        std::thread::scope(|scope| {
            for _ in 0..workers {
                let db = self.db.clone();
                let (results, next, done) = (&results, &next, &done);
                scope.spawn(move || loop {
                    let index = next.fetch_add(1, Ordering::Relaxed);
                    let Some(&key) = keys.get(index) else { break };
                    let result =
                        std::panic::catch_unwind(AssertUnwindSafe(|| surface_artifacts(&db, key)))
                            .unwrap_or_else(|panic| {
                                let message = panic
                                    .downcast_ref::<String>()
                                    .cloned()
                                    .or_else(|| {
                                        panic.downcast_ref::<&str>().map(|text| text.to_string())
                                    })
                                    .unwrap_or_else(|| "unknown panic".to_string());
                                let file = key.asset(&db).file(&db).path(&db).clone();
                                Err(Diagnostic::new(
                                    file,
                                    format!(
                                        "internal error while baking `{}`: {message}",
                                        key.material(&db)
                                    ),
                                ))
                            });
                    results.lock().expect("results lock")[index] = Some(result);
                    let finished = done.fetch_add(1, Ordering::Relaxed) + 1;
                    let item = format!(
                        "{}/{}/{}",
                        key.asset(&db).name(&db),
                        key.material(&db),
                        key.surface(&db).name()
                    );
                    progress(Progress {
                        done: finished,
                        total: keys.len(),
                        item,
                    });
                });
            }
        });
        results
            .into_inner()
            .expect("results lock")
            .into_iter()
            .map(|result| result.expect("every key ran"))
            .collect()
    }

    /// Writes the texture and preview of every baked surface; returns the asset's report.
    fn write_surfaces(
        &self,
        plan: &mut AssetPlan,
        results: &[Result<Arc<SurfaceArtifacts>, Diagnostic>],
        produced: &mut BTreeMap<String, String>,
    ) -> Option<MaterialReport> {
        let parsed = plan.parsed.clone()?;
        let asset_dir = self.config.output.join(&plan.config.name);
        let mut materials = Vec::new();
        for material in &parsed.materials {
            let mut surfaces = Vec::new();
            for ((material_name, surface, _), result) in plan.surfaces.iter().zip(results) {
                let Ok(artifacts) = result else { continue };
                if material_name != &material.name {
                    continue;
                }
                let folder = asset_dir.join(material_name);
                let texture_path = folder.join(format!(
                    "{}.{}",
                    surface.name(),
                    artifacts.info.container.extension()
                ));
                let preview_path = folder.join(format!("{}.png", surface.name()));
                self.write_artifact(
                    &texture_path,
                    &artifacts.texture_file,
                    &mut plan.errors,
                    produced,
                );
                self.write_artifact(
                    &preview_path,
                    &artifacts.preview_png,
                    &mut plan.errors,
                    produced,
                );
                surfaces.push(SurfaceReport {
                    path: display_path(&texture_path),
                    preview: display_path(&preview_path),
                    info: artifacts.info.clone(),
                });
            }
            materials.push(MaterialReportEntry {
                name: material.name.clone(),
                display_name: material.display_name.clone(),
                surfaces,
            });
        }
        Some(MaterialReport {
            asset: plan.config.name.clone(),
            kind: "Material",
            file: display_path(&plan.main_file),
            materials,
            warnings: parsed.warnings.iter().map(ErrorSummary::from).collect(),
            errors: plan.errors.iter().map(ErrorSummary::from).collect(),
        })
    }

    /// Writes one artifact (project-relative `path`) if its bytes changed and records its hash.
    fn write_artifact(
        &self,
        path: &Path,
        bytes: &[u8],
        errors: &mut Vec<Diagnostic>,
        produced: &mut BTreeMap<String, String>,
    ) {
        match write_if_changed(&self.config.root.join(path), bytes) {
            Ok(_) => {
                produced.insert(display_path(path), blake3::hash(bytes).to_hex().to_string());
            }
            Err(error) => errors.push(Diagnostic::new(
                path,
                format!("cannot write the artifact: {error}"),
            )),
        }
    }

    fn asset_summary(
        &self,
        plan: &AssetPlan,
        results: &[Result<Arc<SurfaceArtifacts>, Diagnostic>],
        runs: &[StageRun],
        manifest: &Manifest,
    ) -> AssetSummary {
        let status_of = |stage: Stage, id: salsa::Id, failed: bool| -> (StageStatus, f64) {
            if failed {
                return (StageStatus::Failed, 0.0);
            }
            let ran: Vec<&StageRun> = runs
                .iter()
                .filter(|run| run.stage == stage && run.key == id)
                .collect();
            let ms = ran.iter().fold(0.0, |total, run| total + run.ms);
            if ran.iter().any(|run| !run.from_cache) {
                (StageStatus::Ran, ms)
            } else {
                (StageStatus::Cached, ms)
            }
        };
        let mut stages = Vec::new();
        if let Some(input) = plan.input {
            let parse_failed = plan.parsed.is_none();
            let (status, ms) = status_of(Stage::Parse, input.as_id(), parse_failed);
            stages.push(StageSummary {
                stage: Stage::Parse.name(),
                instance: display_path(&plan.main_file),
                status,
                ms,
            });
            for (path, file) in input.textures(&self.db).iter() {
                let failed = plan.errors.iter().any(|error| &error.file == path);
                let (status, ms) = status_of(Stage::Decode, file.as_id(), failed);
                stages.push(StageSummary {
                    stage: Stage::Decode.name(),
                    instance: display_path(path),
                    status,
                    ms,
                });
            }
        }
        for ((material, surface, key), result) in plan.surfaces.iter().zip(results) {
            for stage in [Stage::Pack, Stage::Mips, Stage::Encode, Stage::Write] {
                let (status, ms) = status_of(stage, key.as_id(), result.is_err());
                stages.push(StageSummary {
                    stage: stage.name(),
                    instance: format!("{material}/{}", surface.name()),
                    status,
                    ms,
                });
            }
        }
        let artifacts = manifest
            .artifacts
            .iter()
            .filter(|(_, entry)| entry.asset == plan.config.name)
            .map(|(path, entry)| ArtifactSummary {
                path: path.clone(),
                hash: entry.hash.clone(),
            })
            .collect();
        AssetSummary {
            name: plan.config.name.clone(),
            kind: match plan.config.source {
                AssetSource::Material { .. } => "Material",
                AssetSource::BillboardCloud { .. } => "BillboardCloud",
            },
            status: if plan.errors.is_empty() {
                AssetStatus::Ok
            } else {
                AssetStatus::Failed
            },
            stages,
            artifacts,
            errors: plan.errors.iter().map(ErrorSummary::from).collect(),
        }
    }
}

/// Records an artifact in the manifest; true when the entry is new or its bytes changed.
fn record_artifact(
    manifest: &mut Manifest,
    revision: u64,
    asset: &str,
    path: &str,
    hash: &str,
) -> bool {
    let unchanged = manifest
        .artifacts
        .get(path)
        .is_some_and(|entry| entry.hash == hash && entry.asset == asset);
    if !unchanged {
        manifest.artifacts.insert(
            path.to_string(),
            ManifestEntry {
                asset: asset.to_string(),
                hash: hash.to_string(),
                revision,
            },
        );
    }
    !unchanged
}

/// Deletes the artifacts `doomed` selects, file and manifest entry; true when any was removed.
fn remove_artifacts(
    root: &Path,
    manifest: &mut Manifest,
    doomed: impl Fn(&str, &ManifestEntry) -> bool,
) -> bool {
    let paths: Vec<String> = manifest
        .artifacts
        .iter()
        .filter(|(path, entry)| doomed(path, entry))
        .map(|(path, _)| path.clone())
        .collect();
    for path in &paths {
        let _ = std::fs::remove_file(root.join(path));
        manifest.artifacts.remove(path);
    }
    !paths.is_empty()
}
