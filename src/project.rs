//! The build driver: reads sources into salsa inputs (only when their bytes changed), runs the
//! stages of every asset on worker threads with database clones, writes the artifacts and the
//! manifest, and says what ran. It is the one place where the pipeline meets the disk.

use std::collections::{BTreeMap, BTreeSet, HashMap, HashSet};
use std::panic::AssertUnwindSafe;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

use salsa::plumbing::AsId;
use salsa::Setter;

use crate::artifacts::{load_manifest, record_artifact, remove_artifacts, save_manifest, write_if_changed, Manifest};
use crate::cache::DiskCache;
use crate::cache::{CacheEntry, CacheKey};
use crate::config::{AssetConfig, AssetSource, PipelineConfig, Settings};
use crate::db::Db;
use crate::db::{
    atlas_surface_artifacts, billboard_cache_key, billboard_layout, lod_files, material_file, mesh_textures, plane_images,
    surface_artifacts, AtlasSurfaceKey, BillboardAsset, Database, MaterialAsset, PlaneKey, SourceFile, Stage, StageRun, SurfaceArtifacts,
    SurfaceKey,
};
use crate::diagnostic::{display_path, Diagnostic};
use crate::kinds::material::definition::MaterialFile;
use crate::sources::{read_source, rule_matches};
use crate::summary::{
    ArtifactSummary, AssetStatus, AssetSummary, BuildSummary, ChangedArtifact, ErrorSummary, MaterialReport, MaterialReportEntry,
    StageStatus, StageSummary, SurfaceReport,
};
use crate::texture::SurfaceKind;

/// How a project is opened.
#[derive(Clone, Debug)]
pub struct ProjectOptions {
    /// Keep stage results on disk under `<output>/.cirrus/cache` across runs.
    pub persistent_cache: bool,
    /// When source files are read again.
    pub source_reading: SourceReading,
}

impl Default for ProjectOptions {
    fn default() -> Self {
        ProjectOptions { persistent_cache: true, source_reading: SourceReading::EveryBuild }
    }
}

/// When a build reads a source file it has read before.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SourceReading {
    /// Every build reads (and hashes) every source again: `cirrus build`.
    EveryBuild,
    /// Only files named by `Project::invalidate_sources` since they were last read: the daemon,
    /// whose watcher says what changed.
    WhenInvalidated,
}

/// What one build covers.
#[derive(Clone, Debug, Default)]
pub struct BuildOptions {
    /// Build only these assets (all when empty).
    pub only_assets: Vec<String>,
    /// Raised by another thread to stop the build (salsa cancellation of its workers); the build
    /// then returns `BuildError::Cancelled` and writes nothing.
    pub cancel: Option<CancelFlag>,
    /// Give this build a revision of its own even when it changed no artifact (the daemon's
    /// batches are numbered by it).
    pub always_new_revision: bool,
}

/// A flag that cancels a running build when raised.
#[derive(Clone, Debug, Default)]
pub struct CancelFlag(Arc<std::sync::atomic::AtomicBool>);

impl CancelFlag {
    pub fn raise(&self) {
        self.0.store(true, Ordering::SeqCst);
    }

    pub fn lower(&self) {
        self.0.store(false, Ordering::SeqCst);
    }

    pub fn is_raised(&self) -> bool {
        self.0.load(Ordering::SeqCst)
    }
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
    #[error("the build was cancelled by a newer edit")]
    Cancelled,
}

/// An open project: the pipeline, the salsa database and the inputs created so far.
pub struct Project {
    config: PipelineConfig,
    db: Database,
    files: HashMap<PathBuf, SourceFile>,
    assets: HashMap<String, MaterialAsset>,
    surfaces: HashMap<(String, String, SurfaceKind), SurfaceKey>,
    billboards: HashMap<String, BillboardAsset>,
    plane_keys: HashMap<(String, u32), PlaneKey>,
    atlas_surface_keys: HashMap<(String, SurfaceKind), AtlasSurfaceKey>,
    /// Readable names of input ids, for the event log.
    labels: HashMap<salsa::Id, String>,
    source_reading: SourceReading,
    /// Files read since they were last invalidated (see `SourceReading::WhenInvalidated`).
    fresh: HashSet<PathBuf>,
    /// Per graph node id (`stage(instance)` or a file's path): the revision of its last run or
    /// content change, and its last duration.
    history: HashMap<String, (u64, f64)>,
    /// The summary of the last finished build, for the graph's node states.
    last_summary: Option<BuildSummary>,
    /// The manifest revision of the last build (or of the manifest found on disk).
    revision: u64,
    /// A source input was created or set since the last finished build (also by `graph`).
    sources_changed_since_build: bool,
}

/// One asset's share of a build.
struct AssetPlan {
    config: AssetConfig,
    main_file: PathBuf,
    input: Option<MaterialAsset>,
    parsed: Option<Arc<MaterialFile>>,
    surfaces: Vec<(String, SurfaceKind, SurfaceKey)>,
    billboard: Option<BillboardPlan>,
    errors: Vec<Diagnostic>,
}

/// A billboard cloud's share of a build.
struct BillboardPlan {
    input: BillboardAsset,
    cache_key: CacheKey,
    /// The artifacts, when the persistent cache had them (then no stage runs).
    files: Option<BillboardFiles>,
    plane_keys: Vec<PlaneKey>,
    surface_keys: Vec<AtlasSurfaceKey>,
}

/// A baked billboard cloud: file names (inside the asset folder) and bytes, and its plane count.
#[derive(Clone, Debug)]
struct BillboardFiles {
    files: Vec<(String, Vec<u8>)>,
    /// The render stages' names (`plane12:bark`), for the summary of a cached asset.
    render_labels: Vec<String>,
}

const BILLBOARD_CACHE_STAGE: &str = "billboard";

impl Project {
    pub fn open(config: PipelineConfig, options: ProjectOptions) -> Project {
        let cache = options.persistent_cache.then(|| DiskCache::new(config.output_dir().join(".cirrus").join("cache")));
        let revision = load_manifest(&config.output_dir()).revision;
        let swept = crate::artifacts::sweep_temporary_files(&config.output_dir());
        if swept > 0 {
            tracing::info!("deleted {swept} temporary file(s) left by an interrupted build");
        }
        let mut project = Project {
            config,
            db: Database::new(cache),
            files: HashMap::new(),
            assets: HashMap::new(),
            surfaces: HashMap::new(),
            billboards: HashMap::new(),
            plane_keys: HashMap::new(),
            atlas_surface_keys: HashMap::new(),
            labels: HashMap::new(),
            source_reading: options.source_reading,
            fresh: HashSet::new(),
            history: HashMap::new(),
            last_summary: None,
            revision,
            sources_changed_since_build: false,
        };
        project.sync_limits();
        project
    }

    fn next_revision(&self) -> u64 {
        self.revision + 1
    }

    /// The revision of the last build (the manifest's).
    pub fn revision(&self) -> u64 {
        self.revision
    }

    /// Uses up a revision without a build (the daemon numbers a configuration error's batch).
    pub fn skip_revision(&mut self) {
        self.revision += 1;
    }

    /// Every source file read so far (project-relative).
    pub fn source_paths(&self) -> BTreeSet<PathBuf> {
        self.files.keys().cloned().collect()
    }

    /// Marks source files as changed on disk: the next build reads them again.
    pub fn invalidate_sources<'a>(&mut self, paths: impl IntoIterator<Item = &'a Path>) {
        for path in paths {
            self.fresh.remove(path);
        }
    }

    /// Reads `paths` again now; true when any of them is new to the project or its bytes changed,
    /// or another input changed since the last finished build (so that a touch with identical
    /// bytes costs no build).
    pub fn refresh_sources<'a>(&mut self, paths: impl IntoIterator<Item = &'a Path>) -> bool {
        let mut changed = self.sources_changed_since_build;
        for path in paths {
            let Some(&file) = self.files.get(path) else {
                changed = true;
                continue;
            };
            let before = file.contents(&self.db).clone();
            self.fresh.remove(path);
            self.source_file(path);
            changed |= file.contents(&self.db) != &before;
        }
        changed
    }

    /// Marks every source file as possibly changed (after a watcher overflow or error).
    pub fn invalidate_all_sources(&mut self) {
        self.fresh.clear();
    }

    /// Whether `path` (project-relative) is a source file some asset read.
    pub fn is_source(&self, path: &Path) -> bool {
        self.files.contains_key(path)
    }

    pub fn config(&self) -> &PipelineConfig {
        &self.config
    }

    /// Replaces the pipeline; settings changes reach only the stages that read them.
    pub fn reconfigure(&mut self, config: PipelineConfig) {
        self.config = config;
        self.sync_limits();
    }

    /// Sets the pipeline-wide limits input when they changed (setters never compare).
    fn sync_limits(&mut self) {
        let texture = self.config.limits.texture;
        match crate::db::PipelineLimits::try_get(&self.db) {
            Some(limits) if limits.texture(&self.db) == texture => {}
            Some(limits) => {
                limits.set_texture(&mut self.db).to(texture);
            }
            None => {
                crate::db::PipelineLimits::new(&self.db, texture);
            }
        }
    }

    /// The assets of the pipeline: the listed ones, then files matching `rules`.
    pub fn asset_list(&self) -> Vec<AssetConfig> {
        self.asset_list_and_conflicts().0
    }

    /// The assets of the pipeline, and a warning for each rule-matched file that does not
    /// become an asset because its name is reserved or collides with another asset's folder.
    pub fn asset_list_and_conflicts(&self) -> (Vec<AssetConfig>, Vec<Diagnostic>) {
        let mut assets = self.config.assets.clone();
        let mut conflicts = Vec::new();
        for relative in rule_matches(&self.config) {
            let Some(asset) = self.config.asset_for_rule_match(&relative) else { continue };
            let file = self.config.source.join(&relative);
            if let Some(reserved) = crate::config::reserved_asset_name(&asset.name) {
                conflicts.push(Diagnostic::new(file, format!("warning: matches a rule but is not baked: {reserved}")));
            } else if let Some(other) = assets.iter().find(|other| crate::config::asset_folders_collide(&other.name, &asset.name)) {
                conflicts.push(Diagnostic::new(
                    file,
                    format!(
                        "warning: matches a rule but is not baked: its asset name `{}` collides with the asset `{}` ({})",
                        asset.name,
                        other.name,
                        display_path(&self.config.source.join(other.source.main_file()))
                    ),
                ));
            } else {
                assets.push(asset);
            }
        }
        (assets, conflicts)
    }

    /// Bakes the assets, writing only artifacts whose bytes changed.
    pub fn build(&mut self, options: &BuildOptions, progress: &(dyn Fn(Progress) + Sync)) -> Result<BuildSummary, BuildError> {
        let (all_assets, conflicts) = self.asset_list_and_conflicts();
        for conflict in &conflicts {
            tracing::warn!("{conflict}");
        }
        for name in &options.only_assets {
            if !all_assets.iter().any(|asset| &asset.name == name) {
                return Err(BuildError::UnknownAsset { name: name.clone(), pipeline: display_path(&self.config.file) });
            }
        }
        let selected: Vec<AssetConfig> = all_assets
            .iter()
            .filter(|asset| options.only_assets.is_empty() || options.only_assets.contains(&asset.name))
            .cloned()
            .collect();

        let cancel = options.cancel.clone().unwrap_or_default();
        let mut plans = Vec::new();
        for asset in selected {
            if cancel.is_raised() {
                self.db.take_runs();
                return Err(BuildError::Cancelled);
            }
            plans.push(self.plan_asset(asset));
        }
        let keys: Vec<SurfaceKey> = plans.iter().flat_map(|plan| plan.surfaces.iter().map(|(_, _, key)| *key)).collect();
        let describe_surface = |db: &Database, key: SurfaceKey| {
            let asset = key.asset(db);
            (asset.file(db).path(db).clone(), format!("{}/{}/{}", asset.name(db), key.material(db), key.surface(db).name()))
        };
        let results = self.run_parallel(&keys, &describe_surface, &|db, key| surface_artifacts(db, key), progress, &cancel);
        if !cancel.is_raised() {
            self.bake_billboards(&mut plans, progress, &cancel);
        }
        let runs = self.db.take_runs();
        if cancel.is_raised() {
            return Err(BuildError::Cancelled);
        }
        let results: Vec<Result<Arc<SurfaceArtifacts>, Diagnostic>> =
            results.into_iter().map(|result| result.expect("not cancelled")).collect();

        let output_dir = self.config.output_dir();
        let mut manifest = load_manifest(&output_dir);
        let next_revision = manifest.revision.max(self.revision) + 1;
        let mut changed = options.always_new_revision;
        let mut changed_artifacts = Vec::new();
        let mut removed_artifacts = Vec::new();
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
                let path = self.config.output.join(&plan.config.name).join("report.json");
                self.write_artifact(&path, &bytes, &mut plan.errors, &mut produced);
            }
            if let Some(files) = plan.billboard.as_ref().and_then(|billboard| billboard.files.clone()) {
                let folder = self.config.output.join(&plan.config.name);
                // The report comes last and describes the files above: it is written only when
                // they all are (a failed write keeps the last good report with its files).
                let mut all_written = true;
                for (name, bytes) in &files.files {
                    if name == "report.json" && !all_written {
                        continue;
                    }
                    all_written &= self.write_artifact(&folder.join(name), bytes, &mut plan.errors, &mut produced);
                }
            }
            let asset_folder = format!("{}/", display_path(&self.config.output.join(&plan.config.name)));
            for (path, hash) in &produced {
                if record_artifact(&mut manifest, next_revision, &plan.config.name, path, hash) {
                    changed = true;
                    changed_artifacts.push(ChangedArtifact {
                        asset: plan.config.name.clone(),
                        artifact: path.strip_prefix(&asset_folder).unwrap_or(path).to_string(),
                        path: path.clone(),
                        hash: hash.clone(),
                    });
                }
            }
            if plan.errors.is_empty() {
                // A fully baked asset owns exactly what it produced: drop stale artifacts.
                let name = &plan.config.name;
                removed_artifacts.extend(remove_artifacts(&self.config, &mut manifest, |path, entry| {
                    &entry.asset == name && !produced.contains_key(path)
                }));
            }
            summaries.push(self.asset_summary(plan, &surface_results, &runs, &manifest));
        }
        if options.only_assets.is_empty() && self.config.source_dir().is_dir() {
            // Artifacts of assets that left the pipeline (not of those that a vanished source
            // folder took along: they failed, and keep their last good artifacts).
            let names: BTreeSet<&str> = all_assets.iter().map(|asset| asset.name.as_str()).collect();
            removed_artifacts.extend(remove_artifacts(&self.config, &mut manifest, |_, entry| !names.contains(entry.asset.as_str())));
        }
        // A failure is news too: its batch gets a revision of its own, so that a client that
        // subscribes after it (with `since` = the revision before) still hears of it.
        changed |= !removed_artifacts.is_empty() || summaries.iter().any(|summary| summary.status == AssetStatus::Failed);
        if changed {
            manifest.revision = next_revision;
            if let Err(error) = save_manifest(&output_dir, &manifest) {
                // Without the manifest, the next build cannot tell its artifacts from the user's
                // files: every asset of this build fails, so scripts and CI notice.
                let file = display_path(&self.config.output.join("manifest.json"));
                tracing::error!("cannot write {file}: {error}");
                for summary in &mut summaries {
                    summary.status = AssetStatus::Failed;
                    summary.errors.push(ErrorSummary {
                        file: file.clone(),
                        line: None,
                        column: None,
                        message: format!("cannot write the manifest: {error}"),
                    });
                }
            }
        }
        self.revision = manifest.revision;
        self.sources_changed_since_build = false;
        for run in runs.iter().filter(|run| !run.from_cache) {
            if let Some(label) = self.labels.get(&run.key) {
                let entry = self.history.entry(stage_node_id(run.stage, label)).or_insert((0, 0.0));
                if entry.0 != manifest.revision {
                    *entry = (manifest.revision, 0.0);
                }
                entry.1 += run.ms;
            }
        }
        changed_artifacts.sort_by(|a, b| a.path.cmp(&b.path));
        let summary =
            BuildSummary { revision: manifest.revision, assets: summaries, changed: changed_artifacts, removed: removed_artifacts };
        self.last_summary = Some(summary.clone());
        Ok(summary)
    }

    /// Validates every asset's sources without baking (see `check`), and reports rule-matched
    /// files that do not become assets.
    pub fn check(&self) -> Vec<(String, Vec<Diagnostic>)> {
        let (assets, conflicts) = self.asset_list_and_conflicts();
        // Rule-matched files that do not become assets are reported under `rules`.
        let conflicts = conflicts.into_iter().map(|conflict| ("rules".to_string(), vec![conflict]));
        assets
            .into_iter()
            .map(|asset| {
                let main_file = self.config.source.join(asset.source.main_file());
                let problems = match &asset.source {
                    AssetSource::BillboardCloud { .. } => crate::check::check_billboard(&self.config, &main_file),
                    AssetSource::Material { .. } => crate::check::check_material(&self.config, &main_file),
                };
                (asset.name, problems)
            })
            .chain(conflicts)
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
                let label = self.labels.get(&executed.key).cloned().unwrap_or_else(|| format!("{:?}", executed.key));
                Some(format!("{}({label})", stage.name()))
            })
            .collect();
        executed.sort();
        executed
    }

    /// The salsa input of a file, read from disk now; set again only when its bytes changed.
    fn source_file(&mut self, path: &Path) -> SourceFile {
        if self.source_reading == SourceReading::WhenInvalidated && self.fresh.contains(path) {
            if let Some(&file) = self.files.get(path) {
                return file;
            }
        }
        let contents = read_source(&self.config.root, &self.config.source, path);
        self.fresh.insert(path.to_path_buf());
        match self.files.get(path) {
            Some(&file) => {
                if file.contents(&self.db) != &contents {
                    let _previous = file.set_contents(&mut self.db).to(contents);
                    self.history.insert(file_node_id(path), (self.next_revision(), 0.0));
                    self.sources_changed_since_build = true;
                }
                file
            }
            None => {
                let file = SourceFile::new(&self.db, path.to_path_buf(), contents);
                self.history.insert(file_node_id(path), (self.next_revision(), 0.0));
                self.sources_changed_since_build = true;
                self.labels.insert(file.as_id(), display_path(path));
                self.files.insert(path.to_path_buf(), file);
                file
            }
        }
    }

    fn material_asset(&mut self, name: &str, file: SourceFile, settings: &Settings) -> MaterialAsset {
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
                let asset = MaterialAsset::new(&self.db, name.to_string(), source_root, file, settings.clone(), Arc::new(BTreeMap::new()));
                self.labels.insert(asset.as_id(), display_path(file.path(&self.db)));
                self.assets.insert(name.to_string(), asset);
                asset
            }
        }
    }

    fn surface_key(&mut self, asset_name: &str, asset: MaterialAsset, material: &str, surface: SurfaceKind) -> SurfaceKey {
        let id = (asset_name.to_string(), material.to_string(), surface);
        if let Some(&key) = self.surfaces.get(&id) {
            if key.asset(&self.db) == asset {
                return key;
            }
        }
        let key = SurfaceKey::new(&self.db, asset, material.to_string(), surface);
        self.labels.insert(key.as_id(), format!("{asset_name}/{material}/{}", surface.name()));
        self.surfaces.insert(id, key);
        key
    }

    /// Reads an asset's sources into inputs and parses it: everything up to the surface stages.
    fn plan_asset(&mut self, config: AssetConfig) -> AssetPlan {
        let main_file = self.config.source.join(config.source.main_file());
        let mut plan =
            AssetPlan { config, main_file, input: None, parsed: None, surfaces: Vec::new(), billboard: None, errors: Vec::new() };
        match plan.config.source.clone() {
            AssetSource::BillboardCloud { .. } => match self.plan_billboard(&plan.config, &plan.main_file) {
                Ok(billboard) => plan.billboard = Some(billboard),
                Err(diagnostic) => plan.errors.push(diagnostic),
            },
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
                            for surface in SurfaceKind::MATERIAL {
                                let key = self.surface_key(&plan.config.name, input, &material.name, surface);
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

    /// Reads a billboard cloud's sources into inputs; from the persistent cache when it has the
    /// result, else runs mesh → planes → layout here and prepares the per-plane and per-surface keys.
    fn plan_billboard(&mut self, config: &AssetConfig, main_file: &Path) -> Result<BillboardPlan, Diagnostic> {
        let mesh_file = self.source_file(main_file);
        let obj_bytes = mesh_file
            .contents(&self.db)
            .as_ref()
            .map(|contents| contents.bytes.clone())
            .map_err(|error| Diagnostic::new(main_file, error.clone()))?;
        let mut libraries = BTreeMap::new();
        for library in crate::mesh::material_libraries(main_file, &obj_bytes, &self.config.source) {
            let file = self.source_file(&library);
            libraries.insert(library, file);
        }
        let source_root = self.config.source.clone();
        let input = match self.billboards.get(&config.name) {
            Some(&input) => {
                if input.mesh_file(&self.db) != mesh_file {
                    input.set_mesh_file(&mut self.db).to(mesh_file);
                }
                if **input.libraries(&self.db) != libraries {
                    input.set_libraries(&mut self.db).to(Arc::new(libraries));
                }
                if input.settings(&self.db) != &config.settings {
                    input.set_settings(&mut self.db).to(config.settings.clone());
                }
                if input.source_root(&self.db) != &source_root {
                    input.set_source_root(&mut self.db).to(source_root);
                }
                input
            }
            None => {
                let input = BillboardAsset::new(
                    &self.db,
                    config.name.clone(),
                    source_root,
                    mesh_file,
                    Arc::new(libraries),
                    Arc::new(BTreeMap::new()),
                    config.settings.clone(),
                    Arc::new(Vec::new()),
                );
                self.labels.insert(input.as_id(), config.name.clone());
                self.billboards.insert(config.name.clone(), input);
                input
            }
        };
        let mut textures = BTreeMap::new();
        for path in mesh_textures(&self.db, input).iter() {
            let file = self.source_file(path);
            textures.insert(path.clone(), file);
        }
        if **input.textures(&self.db) != textures {
            input.set_textures(&mut self.db).to(Arc::new(textures));
        }
        let cache_key = billboard_cache_key(&self.db, input);
        let files = self.load_billboard(cache_key);
        let mut plan = BillboardPlan { input, cache_key, files, plane_keys: Vec::new(), surface_keys: Vec::new() };
        if plan.files.is_some() {
            return Ok(plan);
        }
        let layout = billboard_layout(&self.db, input)?;
        // One render stage per render group (a plane's rectangles showing the same materials).
        let loaded = crate::db::loaded_mesh(&self.db, input)?;
        for (index, group) in layout.render_groups.iter().enumerate() {
            let index = index as u32;
            let key = *self.plane_keys.entry((config.name.clone(), index)).or_insert_with(|| PlaneKey::new(&self.db, input, index));
            let label = crate::kinds::billboard_cloud::render_groups::render_group_label(&loaded.mesh, group);
            self.labels.insert(key.as_id(), format!("{}/{label}", config.name));
            plan.plane_keys.push(key);
        }
        if **input.plane_keys(&self.db) != plan.plane_keys {
            input.set_plane_keys(&mut self.db).to(Arc::new(plan.plane_keys.clone()));
        }
        for surface in SurfaceKind::BILLBOARD {
            let key = *self
                .atlas_surface_keys
                .entry((config.name.clone(), surface))
                .or_insert_with(|| AtlasSurfaceKey::new(&self.db, input, surface));
            self.labels.insert(key.as_id(), format!("{}/{}", config.name, surface.name()));
            plan.surface_keys.push(key);
        }
        Ok(plan)
    }

    fn load_billboard(&self, key: CacheKey) -> Option<BillboardFiles> {
        let entry = self.db.disk_cache()?.load(BILLBOARD_CACHE_STAGE, key)?;
        let names: Vec<String> = serde_json::from_value(entry.metadata.get("files")?.clone()).ok()?;
        let render_labels: Vec<String> = serde_json::from_value(entry.metadata.get("renders")?.clone()).ok()?;
        (names.len() == entry.blobs.len()).then(|| BillboardFiles { files: names.into_iter().zip(entry.blobs).collect(), render_labels })
    }

    /// Renders the planes and encodes the atlases of the billboard clouds the cache did not have,
    /// then assembles their files (and stores them in the persistent cache).
    fn bake_billboards(&self, plans: &mut [AssetPlan], progress: &(dyn Fn(Progress) + Sync), cancel: &CancelFlag) {
        let pending: Vec<usize> =
            (0..plans.len()).filter(|&index| plans[index].billboard.as_ref().is_some_and(|plan| plan.files.is_none())).collect();
        if pending.is_empty() {
            return;
        }
        let labels = &self.labels;
        let describe_plane = |db: &Database, key: PlaneKey| {
            let asset = key.asset(db);
            let label = labels.get(&key.as_id()).cloned().unwrap_or_else(|| format!("{}/render{}", asset.name(db), key.index(db)));
            (asset.mesh_file(db).path(db).clone(), label)
        };
        let plane_keys: Vec<PlaneKey> =
            pending.iter().flat_map(|&index| plans[index].billboard.as_ref().expect("pending").plane_keys.clone()).collect();
        let rendered = self.run_parallel(&plane_keys, &describe_plane, &|db, key| plane_images(db, key).map(|_| ()), progress, cancel);
        let Some(rendered) = rendered.into_iter().collect::<Option<Vec<_>>>() else { return };
        let describe_surface = |db: &Database, key: AtlasSurfaceKey| {
            let asset = key.asset(db);
            (asset.mesh_file(db).path(db).clone(), format!("{}/{}", asset.name(db), key.surface(db).name()))
        };
        let mut surface_keys = Vec::new();
        for &index in &pending {
            let plan = plans[index].billboard.as_ref().expect("pending");
            let render_failed =
                plan.plane_keys.iter().any(|key| rendered[plane_keys.iter().position(|other| other == key).expect("listed")].is_err());
            if !render_failed {
                surface_keys.extend(plan.surface_keys.iter().copied());
            }
        }
        let encoded = self.run_parallel(&surface_keys, &describe_surface, &|db, key| atlas_surface_artifacts(db, key), progress, cancel);
        let Some(encoded) = encoded.into_iter().collect::<Option<Vec<_>>>() else { return };
        for &index in &pending {
            let plan = &mut plans[index];
            let billboard = plan.billboard.as_mut().expect("pending");
            for (key, result) in plane_keys.iter().zip(&rendered) {
                if let (true, Err(diagnostic)) = (billboard.plane_keys.contains(key), result) {
                    if !plan.errors.contains(diagnostic) {
                        plan.errors.push(diagnostic.clone());
                    }
                }
            }
            let mut surfaces = Vec::new();
            for (key, result) in surface_keys.iter().zip(&encoded) {
                if !billboard.surface_keys.contains(key) {
                    continue;
                }
                match result {
                    Ok(artifacts) => surfaces.push(artifacts.clone()),
                    Err(diagnostic) => plan.errors.push(diagnostic.clone()),
                }
            }
            if !plan.errors.is_empty() || surfaces.len() != SurfaceKind::BILLBOARD.len() {
                continue;
            }
            match self.assemble_billboard(billboard, &surfaces) {
                Ok(files) => {
                    if let Some(cache) = self.db.disk_cache() {
                        let metadata = serde_json::json!({ "files": files.files.iter().map(|(name, _)| name).collect::<Vec<_>>(), "renders": files.render_labels });
                        cache.store(
                            BILLBOARD_CACHE_STAGE,
                            billboard.cache_key,
                            &CacheEntry { metadata, blobs: files.files.iter().map(|(_, bytes)| bytes.clone()).collect() },
                        );
                    }
                    billboard.files = Some(files);
                }
                Err(diagnostic) => plan.errors.push(diagnostic),
            }
        }
    }

    /// The files of a freshly baked billboard cloud: LOD mesh, textures, previews, report.
    fn assemble_billboard(&self, plan: &BillboardPlan, surfaces: &[Arc<SurfaceArtifacts>]) -> Result<BillboardFiles, Diagnostic> {
        let db = &self.db;
        let input = plan.input;
        let (obj, mtl) = (*lod_files(db, input)?).clone();
        let loaded = crate::db::loaded_mesh(db, input)?;
        let planes = crate::db::billboard_planes(db, input)?;
        let layout = billboard_layout(db, input)?;
        let atlas = crate::db::billboard_atlas(db, input)?;
        let mut files = vec![("lod.obj".to_string(), obj.into_bytes()), ("lod.mtl".to_string(), mtl.into_bytes())];
        for artifacts in surfaces {
            let name = artifacts.info.surface.name();
            files.push((format!("{name}.{}", artifacts.info.container.extension()), artifacts.texture_file.to_vec()));
            files.push((format!("{name}.png"), artifacts.preview_png.to_vec()));
        }
        let settings = input.settings(db);
        let report = serde_json::json!({
            "asset": input.name(db),
            "kind": "BillboardCloud",
            "mesh": display_path(input.mesh_file(db).path(db)),
            "faces": planes.face_count,
            "planes": planes.planes.len(),
            "quads": layout.layout.placements.len(),
            // Faces of solid materials drawn on another plane's quad too (crack filling).
            "faces_also_drawn": layout.rectangles.iter().map(|rectangle| rectangle.also_drawn.len()).sum::<usize>(),
            "alpha_cutoff": settings.billboard.alpha_cutoff,
            "epsilon": settings.billboard.epsilon,
            "epsilon_world": planes.epsilon,
            "max_error_world": planes.max_error,
            "atlas": {
                "width": layout.layout.width,
                "height": layout.layout.height,
                "texel_density": layout.layout.texel_density,
                "occupancy": (layout.layout.occupancy * 1e4).round() / 1e4,
                "coverage": (atlas.coverage * 1e4).round() / 1e4,
            },
            "surfaces": surfaces.iter().map(|artifacts| &artifacts.info).collect::<Vec<_>>(),
            "stage_ms": self.billboard_stage_ms(plan),
            "warnings": loaded.warnings.iter().map(ErrorSummary::from).collect::<Vec<_>>(),
        });
        let mut report_bytes = serde_json::to_vec_pretty(&report).expect("reports serialise");
        report_bytes.push(b'\n');
        files.push(("report.json".to_string(), report_bytes));
        let render_labels = layout
            .render_groups
            .iter()
            .map(|group| crate::kinds::billboard_cloud::render_groups::render_group_label(&loaded.mesh, group))
            .collect();
        Ok(BillboardFiles { files, render_labels })
    }

    /// Milliseconds per stage spent on this billboard cloud by the runs logged so far.
    fn billboard_stage_ms(&self, plan: &BillboardPlan) -> BTreeMap<&'static str, f64> {
        let ids: BTreeSet<salsa::Id> = std::iter::once(plan.input.as_id())
            .chain(plan.plane_keys.iter().map(|key| key.as_id()))
            .chain(plan.surface_keys.iter().map(|key| key.as_id()))
            .collect();
        let mut totals = BTreeMap::new();
        for run in self.db.peek_runs() {
            if ids.contains(&run.key) && !run.from_cache {
                *totals.entry(run.stage.name()).or_insert(0.0) += (run.ms * 10.0).round() / 10.0;
            }
        }
        totals
    }

    /// Runs `work` for every item on worker threads, each with its own database clone; a panic
    /// fails only its item. `describe` names an item's file (for that failure) and progress label.
    /// Raising `cancel` stops the workers: those inside a query unwind with `salsa::Cancelled`
    /// (their clones' cancellation tokens), the rest take no new item; unfinished items are `None`.
    fn run_parallel<T: Copy + Send + Sync, R: Send>(
        &self,
        items: &[T],
        describe: &(dyn Fn(&Database, T) -> (PathBuf, String) + Sync),
        work: &(dyn Fn(&Database, T) -> Result<R, Diagnostic> + Sync),
        progress: &(dyn Fn(Progress) + Sync),
        cancel: &CancelFlag,
    ) -> Vec<Option<Result<R, Diagnostic>>> {
        let results: Mutex<Vec<Option<Result<R, Diagnostic>>>> = Mutex::new((0..items.len()).map(|_| None).collect());
        let next = AtomicUsize::new(0);
        let done = AtomicUsize::new(0);
        let running = AtomicUsize::new(0);
        let workers = std::thread::available_parallelism().map_or(2, |count| count.get()).min(items.len().max(1));
        let clones: Vec<Database> = (0..workers).map(|_| self.db.clone()).collect();
        let tokens: Vec<salsa::CancellationToken> = clones.iter().map(salsa::Database::cancellation_token).collect();
        std::thread::scope(|scope| {
            for db in clones {
                let (results, next, done, running) = (&results, &next, &done, &running);
                running.fetch_add(1, Ordering::SeqCst);
                scope.spawn(move || {
                    loop {
                        if cancel.is_raised() {
                            break;
                        }
                        let index = next.fetch_add(1, Ordering::Relaxed);
                        let Some(&item) = items.get(index) else { break };
                        let result = match std::panic::catch_unwind(AssertUnwindSafe(|| work(&db, item))) {
                            Ok(result) => result,
                            Err(panic) if panic.is::<salsa::Cancelled>() => break,
                            Err(panic) => {
                                let message = panic
                                    .downcast_ref::<String>()
                                    .cloned()
                                    .or_else(|| panic.downcast_ref::<&str>().map(|text| text.to_string()))
                                    .unwrap_or_else(|| "unknown panic".to_string());
                                let (file, label) = describe(&db, item);
                                Err(Diagnostic::new(file, format!("internal error while baking `{label}`: {message}")))
                            }
                        };
                        results.lock().expect("results lock")[index] = Some(result);
                        let finished = done.fetch_add(1, Ordering::Relaxed) + 1;
                        progress(Progress { done: finished, total: items.len(), item: describe(&db, item).1 });
                    }
                    // The clone is dropped here, before the writer can set the next inputs.
                    drop(db);
                    running.fetch_sub(1, Ordering::SeqCst);
                });
            }
            // Watch for cancellation while the workers run; pass it on to their queries.
            while running.load(Ordering::SeqCst) > 0 {
                if cancel.is_raised() {
                    tokens.iter().for_each(salsa::CancellationToken::cancel);
                    break;
                }
                std::thread::sleep(std::time::Duration::from_millis(2));
            }
        });
        results.into_inner().expect("results lock")
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
                let texture_path = folder.join(format!("{}.{}", surface.name(), artifacts.info.container.extension()));
                let preview_path = folder.join(format!("{}.png", surface.name()));
                let written = self.write_artifact(&texture_path, &artifacts.texture_file, &mut plan.errors, produced)
                    & self.write_artifact(&preview_path, &artifacts.preview_png, &mut plan.errors, produced);
                if !written {
                    // The report describes only files that are on disk.
                    continue;
                }
                surfaces.push(SurfaceReport {
                    path: display_path(&texture_path),
                    preview: display_path(&preview_path),
                    info: artifacts.info.clone(),
                });
            }
            materials.push(MaterialReportEntry { name: material.name.clone(), display_name: material.display_name.clone(), surfaces });
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

    /// Writes one artifact (project-relative `path`) if its bytes changed and records its hash;
    /// false when it could not be written. A report that differs only in its timings is kept.
    fn write_artifact(&self, path: &Path, bytes: &[u8], errors: &mut Vec<Diagnostic>, produced: &mut BTreeMap<String, String>) -> bool {
        let absolute = self.config.root.join(path);
        if path.file_name().is_some_and(|name| name == "report.json") {
            if let Some(existing) = crate::artifacts::same_report_on_disk(&absolute, bytes) {
                produced.insert(display_path(path), blake3::hash(&existing).to_hex().to_string());
                return true;
            }
        }
        match write_if_changed(&absolute, bytes) {
            Ok(_) => {
                produced.insert(display_path(path), blake3::hash(bytes).to_hex().to_string());
                true
            }
            Err(error) => {
                errors.push(Diagnostic::new(path, format!("cannot write the artifact: {error}")));
                false
            }
        }
    }

    /// The stage instances of a billboard cloud: ran when this build ran them, cached when memory
    /// or the persistent cache had them, failed for the ones an error left undone.
    fn billboard_stage_summaries(&self, plan: &AssetPlan, billboard: &BillboardPlan, runs: &[StageRun]) -> Vec<StageSummary> {
        let failed = !plan.errors.is_empty();
        let status = |stage: Stage, id: salsa::Id| -> (StageStatus, f64) {
            let ran: Vec<&StageRun> = runs.iter().filter(|run| run.stage == stage && run.key == id && !run.from_cache).collect();
            match (ran.is_empty(), failed) {
                (false, _) => (StageStatus::Ran, ran.iter().fold(0.0, |total, run| total + run.ms)),
                (true, true) => (StageStatus::Failed, 0.0),
                (true, false) => (StageStatus::Cached, 0.0),
            }
        };
        let id = billboard.input.as_id();
        let mut stages = Vec::new();
        let summary = |stage: Stage, instance: String, key: salsa::Id| {
            let (status, ms) = status(stage, key);
            StageSummary { stage: stage.name(), instance, status, ms }
        };
        let mesh = display_path(&plan.main_file);
        for stage in [Stage::Mesh, Stage::Planes, Stage::Layout] {
            stages.push(summary(stage, mesh.clone(), id));
        }
        let cached_labels = billboard.files.as_ref().map_or(&[][..], |files| files.render_labels.as_slice());
        let render_count = cached_labels.len().max(billboard.plane_keys.len());
        let name_prefix = format!("{}/", plan.config.name);
        for index in 0..render_count {
            let key = billboard
                .plane_keys
                .get(index)
                .map(|key| key.as_id())
                .or_else(|| self.plane_keys.get(&(plan.config.name.clone(), index as u32)).map(|key| key.as_id()));
            let (status, ms) = match key {
                Some(key) => status(Stage::Render, key),
                None => (if failed { StageStatus::Failed } else { StageStatus::Cached }, 0.0),
            };
            let instance = cached_labels
                .get(index)
                .cloned()
                .or_else(|| {
                    key.and_then(|key| self.labels.get(&key)).map(|label| label.strip_prefix(&name_prefix).unwrap_or(label).to_string())
                })
                .unwrap_or_else(|| format!("render{index}"));
            stages.push(StageSummary { stage: Stage::Render.name(), instance, status, ms });
        }
        stages.push(summary(Stage::Atlas, mesh.clone(), id));
        for surface in SurfaceKind::BILLBOARD {
            let key = self.atlas_surface_keys.get(&(plan.config.name.clone(), surface)).map_or(id, |key| key.as_id());
            stages.push(summary(Stage::Encode, surface.name().to_string(), key));
        }
        stages.push(summary(Stage::Lod, mesh, id));
        stages
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
            let ran: Vec<&StageRun> = runs.iter().filter(|run| run.stage == stage && run.key == id).collect();
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
            stages.push(StageSummary { stage: Stage::Parse.name(), instance: display_path(&plan.main_file), status, ms });
            for (path, file) in input.textures(&self.db).iter() {
                let failed = plan.errors.iter().any(|error| &error.file == path);
                let (status, ms) = status_of(Stage::Decode, file.as_id(), failed);
                stages.push(StageSummary { stage: Stage::Decode.name(), instance: display_path(path), status, ms });
            }
        }
        if let Some(billboard) = &plan.billboard {
            stages.extend(self.billboard_stage_summaries(plan, billboard, runs));
        }
        for ((material, surface, key), result) in plan.surfaces.iter().zip(results) {
            for stage in [Stage::Pack, Stage::Mips, Stage::Encode, Stage::Write] {
                let (status, ms) = status_of(stage, key.as_id(), result.is_err());
                stages.push(StageSummary { stage: stage.name(), instance: format!("{material}/{}", surface.name()), status, ms });
            }
        }
        let artifacts = manifest
            .artifacts
            .iter()
            .filter(|(_, entry)| entry.asset == plan.config.name)
            .map(|(path, entry)| ArtifactSummary { path: path.clone(), hash: entry.hash.clone() })
            .collect();
        AssetSummary {
            name: plan.config.name.clone(),
            kind: match plan.config.source {
                AssetSource::Material { .. } => "Material",
                AssetSource::BillboardCloud { .. } => "BillboardCloud",
            },
            status: if plan.errors.is_empty() { AssetStatus::Ok } else { AssetStatus::Failed },
            stages,
            artifacts,
            errors: plan.errors.iter().map(ErrorSummary::from).collect(),
        }
    }
}

/// The graph node id of a source file.
pub fn file_node_id(path: &Path) -> String {
    display_path(path)
}

/// What `cirrus preview` renders.
#[derive(Clone, Debug)]
pub struct PreviewOptions {
    pub asset: String,
    pub settings: crate::kinds::billboard_cloud::lod_preview::PreviewSettings,
    /// Where `contact_sheet.png` and `metrics.json` go (project-relative or absolute).
    pub out: PathBuf,
}

#[derive(Debug, thiserror::Error)]
pub enum PreviewError {
    #[error(transparent)]
    Build(#[from] BuildError),
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

impl Project {
    /// Bakes `asset` if needed, then renders it and its source from the view directions.
    pub fn preview(
        &mut self,
        options: &PreviewOptions,
    ) -> Result<crate::kinds::billboard_cloud::lod_preview::PreviewMetrics, PreviewError> {
        let summary = self.build(&BuildOptions { only_assets: vec![options.asset.clone()], ..Default::default() }, &|_| {})?;
        let asset = &summary.assets[0];
        if asset.kind != "BillboardCloud" {
            return Err(PreviewError::NotBillboard(options.asset.clone()));
        }
        if asset.status != AssetStatus::Ok {
            let errors = asset.errors.iter().map(|error| format!("  {}: {}", error.file, error.message)).collect::<Vec<_>>().join("\n");
            return Err(PreviewError::Failed { name: options.asset.clone(), errors });
        }
        let input = self.billboards[&options.asset];
        let loaded = crate::db::loaded_mesh(&self.db, input).map_err(PreviewError::Artifact)?;
        let source = self.source_view_mesh(input, &loaded).map_err(PreviewError::Artifact)?;
        let cutoff = input.settings(&self.db).billboard.alpha_cutoff;
        let folder = self.config.output.join(&options.asset);
        let lod = crate::artifacts::read_lod_view_mesh(&self.config.root, &folder, cutoff).map_err(PreviewError::Artifact)?;
        let positions = &loaded.mesh.positions;
        let (min, max) =
            positions.iter().fold((glam::Vec3::splat(f32::INFINITY), glam::Vec3::splat(f32::NEG_INFINITY)), |(min, max), &p| {
                (min.min(glam::Vec3::from(p)), max.max(glam::Vec3::from(p)))
            });
        let center = 0.5 * (min + max);
        let radius = positions.iter().map(|&p| glam::Vec3::from(p).distance(center)).fold(0.0, f32::max);
        let gpu = crate::gpu::gpu()?;
        let preview = crate::kinds::billboard_cloud::lod_preview::preview(gpu, &source, &lod, center.to_array(), radius, options.settings)?;
        let out = self.config.root.join(&options.out);
        let mut metrics = serde_json::to_vec_pretty(&preview.metrics).expect("metrics serialise");
        metrics.push(b'\n');
        write_if_changed(&out.join("contact_sheet.png"), &preview.contact_sheet).map_err(PreviewError::Write)?;
        write_if_changed(&out.join("metrics.json"), &metrics).map_err(PreviewError::Write)?;
        Ok(preview.metrics)
    }

    /// The source mesh with its decoded maps (mipmapped as for rendering).
    fn source_view_mesh(&self, input: BillboardAsset, loaded: &crate::db::LoadedMesh) -> Result<crate::gpu::ViewMesh, Diagnostic> {
        use crate::texture::TextureSlot;
        let db = &self.db;
        let cutoff = input.settings(db).billboard.alpha_cutoff;
        let mut materials = Vec::new();
        for material in &loaded.mesh.materials {
            let levels = |slot: TextureSlot, kind: SurfaceKind| -> Result<Option<Arc<Vec<crate::texture::Texture>>>, Diagnostic> {
                let Some(path) = material.maps.get(&slot).filter(|_| loaded.mesh.uvs.is_some()) else { return Ok(None) };
                let Some(&file) = input.textures(db).get(path) else { return Ok(None) };
                let texture = if slot == TextureSlot::Opacity {
                    crate::db::opacity_texture(db, file)?
                } else {
                    crate::db::decoded_texture(db, file)?
                };
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
        let all_faces = crate::kinds::billboard_cloud::rectangles::PlaneRectangle {
            plane: 0,
            faces: (0..loaded.mesh.triangles.len() as u32).collect(),
            also_drawn: Vec::new(),
            origin: [0.0; 3],
            x_axis: [1.0, 0.0, 0.0],
            y_axis: [0.0, 1.0, 0.0],
            normal: [0.0, 0.0, 1.0],
            width: 0.0,
            height: 0.0,
        };
        Ok(crate::gpu::ViewMesh {
            batches: crate::kinds::billboard_cloud::render_groups::plane_batches(&loaded.mesh, &loaded.tangents, &all_faces),
            materials,
        })
    }
}

/// The graph id of a stage instance, as the event log names it: `stage(label)`.
fn stage_node_id(stage: Stage, label: &str) -> String {
    format!("{}({label})", stage.name())
}

impl Project {
    /// The dependency graph of every asset: source files, stage instances (per surface, per
    /// plane) and artifacts, with an edge for each read a stage function makes. Reads the
    /// sources and runs the stages up to the layout where needed (to know the planes).
    pub fn graph(&mut self) -> crate::graph::Graph {
        use crate::graph::{GraphBuilder, Node, NodeKind};
        let mut graph = GraphBuilder::default();
        let statuses = self.last_stage_statuses();
        let last_revision = self.last_summary.as_ref().map(|summary| summary.revision);
        let manifest = load_manifest(&self.config.output_dir());
        let stage = |graph: &mut GraphBuilder, history: &HashMap<String, (u64, f64)>, asset: &str, stage: Stage, label: &str| {
            let id = stage_node_id(stage, label);
            let last = history.get(&id);
            // Stages a summary does not list (a billboard's texture decodes): from the history.
            let (state, ms) = statuses.get(&id).cloned().unwrap_or(match (last_revision, last) {
                (None, _) => ("pending", None),
                (Some(revision), Some((ran, ms))) if *ran == revision => ("ran", Some((ms * 10.0).round() / 10.0)),
                (Some(_), _) => ("cached", None),
            });
            graph.node(Node {
                id: id.clone(),
                kind: NodeKind::Stage,
                label: id.clone(),
                // A decoded texture is shared by every asset that reads the file.
                asset: (stage != Stage::Decode).then(|| asset.to_string()),
                revision: last.map(|(revision, _)| *revision),
                ms: ms.or(last.map(|(_, ms)| (ms * 10.0).round() / 10.0)),
                state: state.to_string(),
            });
            id
        };
        let artifact = |graph: &mut GraphBuilder, asset: &str, path: &Path, from: &[&String]| {
            let id = display_path(path);
            let entry = manifest.artifacts.get(&id);
            graph.node(Node {
                id: id.clone(),
                kind: NodeKind::Artifact,
                label: id.clone(),
                asset: Some(asset.to_string()),
                revision: entry.map(|entry| entry.revision),
                ms: None,
                state: if entry.is_some() { "written" } else { "pending" }.to_string(),
            });
            for stage in from {
                graph.edge(stage, &id);
            }
        };
        for asset in self.asset_list() {
            let plan = self.plan_asset(asset);
            let name = plan.config.name.clone();
            let main_file = self.file_node(&mut graph, &plan.main_file);
            let asset_folder = self.config.output.join(&name);
            if plan.input.is_some() {
                let parse = stage(&mut graph, &self.history, &name, Stage::Parse, &display_path(&plan.main_file));
                graph.edge(&main_file, &parse);
                let mut writes = Vec::new();
                if let Some(parsed) = &plan.parsed {
                    let container = plan.config.settings.encode.container;
                    for material in &parsed.materials {
                        for surface in SurfaceKind::MATERIAL {
                            let label = format!("{name}/{}/{}", material.name, surface.name());
                            let [pack, mips, encode, write] = [Stage::Pack, Stage::Mips, Stage::Encode, Stage::Write]
                                .map(|kind| stage(&mut graph, &self.history, &name, kind, &label));
                            for slot in surface.slots() {
                                let Some(reference) = material.textures.get(slot) else { continue };
                                let file = self.file_node(&mut graph, &reference.path);
                                let decode = stage(&mut graph, &self.history, &name, Stage::Decode, &display_path(&reference.path));
                                graph.edge(&file, &decode);
                                graph.edge(&decode, &pack);
                                // The write stage hashes its sources for the persistent cache key.
                                graph.edge(&file, &write);
                            }
                            for reader in [&pack, &mips, &write] {
                                graph.edge(&parse, reader);
                            }
                            graph.edge(&pack, &mips);
                            graph.edge(&mips, &encode);
                            graph.edge(&encode, &write);
                            graph.edge(&pack, &write);
                            let folder = asset_folder.join(&material.name);
                            artifact(&mut graph, &name, &folder.join(format!("{}.{}", surface.name(), container.extension())), &[&write]);
                            artifact(&mut graph, &name, &folder.join(format!("{}.png", surface.name())), &[&write]);
                            writes.push(write);
                        }
                    }
                }
                let mut report_sources: Vec<&String> = writes.iter().collect();
                report_sources.push(&parse);
                artifact(&mut graph, &name, &asset_folder.join("report.json"), &report_sources);
            }
            if let Some(billboard) = &plan.billboard {
                self.billboard_graph(&mut graph, &name, billboard.input, &main_file, &stage, &artifact);
            }
        }
        graph.finish()
    }

    #[allow(clippy::type_complexity)]
    fn billboard_graph(
        &self,
        graph: &mut crate::graph::GraphBuilder,
        name: &str,
        input: BillboardAsset,
        mesh_file: &str,
        stage: &dyn Fn(&mut crate::graph::GraphBuilder, &HashMap<String, (u64, f64)>, &str, Stage, &str) -> String,
        artifact: &dyn Fn(&mut crate::graph::GraphBuilder, &str, &Path, &[&String]),
    ) {
        let db = &self.db;
        let [mesh, planes, layout, atlas, lod] =
            [Stage::Mesh, Stage::Planes, Stage::Layout, Stage::Atlas, Stage::Lod].map(|kind| stage(graph, &self.history, name, kind, name));
        graph.edge(mesh_file, &mesh);
        for library in input.libraries(db).keys() {
            let file = self.file_node(graph, library);
            graph.edge(&file, &mesh);
        }
        graph.edge(&mesh, &planes);
        graph.edge(&mesh, &layout);
        graph.edge(&planes, &layout);
        graph.edge(&layout, &lod);
        graph.edge(&layout, &atlas);
        let folder = self.config.output.join(name);
        artifact(graph, name, &folder.join("lod.obj"), &[&lod]);
        artifact(graph, name, &folder.join("lod.mtl"), &[&lod]);
        let mut report_sources = vec![mesh.clone(), planes.clone(), layout.clone(), atlas.clone()];
        if let (Ok(loaded), Ok(plane_layout)) = (crate::db::loaded_mesh(db, input), billboard_layout(db, input)) {
            for group in &plane_layout.render_groups {
                let label = crate::kinds::billboard_cloud::render_groups::render_group_label(&loaded.mesh, group);
                let render = stage(graph, &self.history, name, Stage::Render, &format!("{name}/{label}"));
                for reader in [&mesh, &planes, &layout] {
                    graph.edge(reader, &render);
                }
                graph.edge(&render, &atlas);
                if loaded.mesh.uvs.is_none() {
                    continue;
                }
                for &material in &group.materials {
                    for path in loaded.mesh.materials[material as usize].maps.values() {
                        let file = self.file_node(graph, path);
                        let decode = stage(graph, &self.history, name, Stage::Decode, &display_path(path));
                        graph.edge(&file, &decode);
                        graph.edge(&decode, &render);
                    }
                }
            }
        }
        let container = input.settings(db).encode.container;
        for surface in SurfaceKind::BILLBOARD {
            let encode = stage(graph, &self.history, name, Stage::Encode, &format!("{name}/{}", surface.name()));
            graph.edge(&atlas, &encode);
            artifact(graph, name, &folder.join(format!("{}.{}", surface.name(), container.extension())), &[&encode]);
            artifact(graph, name, &folder.join(format!("{}.png", surface.name())), &[&encode]);
            report_sources.push(encode);
        }
        artifact(graph, name, &folder.join("report.json"), &report_sources.iter().collect::<Vec<_>>());
    }

    /// Adds the node of a source file; returns its id.
    fn file_node(&self, graph: &mut crate::graph::GraphBuilder, path: &Path) -> String {
        let id = file_node_id(path);
        let present = self.files.get(path).is_some_and(|file| file.contents(&self.db).is_ok());
        graph.node(crate::graph::Node {
            id: id.clone(),
            kind: crate::graph::NodeKind::File,
            label: id.clone(),
            asset: None,
            revision: self.history.get(&id).map(|(revision, _)| *revision),
            ms: None,
            state: if present { "present" } else { "missing" }.to_string(),
        });
        id
    }

    /// Stage node id → (state, milliseconds) from the last build's summary.
    fn last_stage_statuses(&self) -> HashMap<String, (&'static str, Option<f64>)> {
        let mut statuses = HashMap::new();
        let Some(summary) = &self.last_summary else { return statuses };
        for asset in &summary.assets {
            for stage_summary in &asset.stages {
                let Some(stage) = Stage::ALL.iter().copied().find(|stage| stage.name() == stage_summary.stage) else { continue };
                let label = match (asset.kind, stage) {
                    ("Material", Stage::Parse | Stage::Decode) => stage_summary.instance.clone(),
                    ("BillboardCloud", Stage::Mesh | Stage::Planes | Stage::Layout | Stage::Atlas | Stage::Lod) => asset.name.clone(),
                    _ => format!("{}/{}", asset.name, stage_summary.instance),
                };
                let state = match stage_summary.status {
                    StageStatus::Ran => "ran",
                    StageStatus::Cached => "cached",
                    StageStatus::Failed => "failed",
                };
                let ms = (stage_summary.status == StageStatus::Ran).then_some((stage_summary.ms * 10.0).round() / 10.0);
                statuses.insert(stage_node_id(stage, &label), (state, ms));
            }
        }
        statuses
    }
}
