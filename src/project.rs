//! The build driver, which names no kind: reads each asset's sources into salsa inputs (only
//! when their bytes changed, asking the asset's kind which files it reads until nothing new
//! turns up), runs the kinds' jobs on worker threads with database clones, writes the artifacts
//! and the manifest, and reports what ran: the summary and the graph both come from the stage
//! instances each kind declares.

use std::collections::{BTreeMap, BTreeSet, HashMap, HashSet};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use salsa::Setter;

use crate::artifacts::{load_manifest, record_artifact, remove_artifacts, save_manifest, write_if_changed, Manifest};
use crate::cache::DiskCache;
use crate::config::{AssetConfig, PipelineConfig};
use crate::db::{Asset, Database, Db, SourceFile, StageRun};
use crate::diagnostic::{display_path, Diagnostic};
use crate::kinds::{stage_node_id, AssetKind, Read, StageInstance};
use crate::sources::{read_source, rule_matches};
use crate::summary::{
    ArtifactSummary, AssetStatus, AssetSummary, BuildSummary, ChangedArtifact, ErrorSummary, StageStatus, StageSummary,
};

pub use crate::schedule::{CancelFlag, Progress};

/// How a project is opened.
#[derive(Clone, Debug)]
pub struct ProjectOptions {
    /// Keep stage results on disk under `<output>/.cirrus/cache` across runs.
    pub persistent_cache: bool,
    /// When source files are read again.
    pub source_reading: SourceReading,
    /// The command line's word on the shared cache (`pipeline.ron`'s `cache` otherwise).
    pub remote_cache: crate::cache::remote::RemoteCacheOverride,
}

impl Default for ProjectOptions {
    fn default() -> Self {
        ProjectOptions {
            persistent_cache: true,
            source_reading: SourceReading::EveryBuild,
            remote_cache: Default::default(),
        }
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

/// `Err(UnknownAsset)`, with the closest known name, for the first of `names` that names none
/// of `assets`.
pub fn require_assets(names: &[String], assets: &[AssetConfig], pipeline: &Path) -> Result<(), BuildError> {
    let Some(name) = names.iter().find(|name| !assets.iter().any(|asset| &asset.name == *name)) else { return Ok(()) };
    let hint = crate::diagnostic::did_you_mean(name, assets.iter().map(|asset| asset.name.as_str()));
    Err(BuildError::UnknownAsset { name: name.clone(), pipeline: display_path(pipeline), hint })
}

#[derive(Debug, thiserror::Error)]
pub enum BuildError {
    #[error("no asset named `{name}` in {pipeline}{hint}")]
    UnknownAsset { name: String, pipeline: String, hint: String },
    #[error("the build was cancelled by a newer edit")]
    Cancelled,
}

/// How many times the driver asks a kind for the files it reads before giving up on a stable
/// answer (a material file, then its textures; an OBJ, its MTL files, then their textures).
const MAX_DISCOVERY_ROUNDS: usize = 8;

/// An open project: the pipeline, the salsa database and the inputs created so far.
pub struct Project {
    config: PipelineConfig,
    db: Database,
    files: HashMap<PathBuf, SourceFile>,
    assets: HashMap<String, Asset>,
    source_reading: SourceReading,
    /// Files read since they were last invalidated (every build starts afresh with
    /// `SourceReading::EveryBuild`).
    fresh: HashSet<PathBuf>,
    /// Per graph node id (`stage(instance)` or a file's path): the revision of its last run or
    /// content change, and its last duration.
    history: HashMap<String, (u64, f64)>,
    /// Per stage node id: its state and milliseconds in the last finished build.
    last_statuses: HashMap<String, (&'static str, Option<f64>)>,
    /// Whether a build has finished (the graph's nodes are `pending` before).
    last_revision: Option<u64>,
    /// `stage(label)` of every stage body that ran since `take_executed_stages`.
    executed: BTreeSet<String>,
    /// The manifest revision of the last build (or of the manifest found on disk).
    revision: u64,
    /// A source input was created or set since the last finished build (also by `graph`).
    sources_changed_since_build: bool,
    options: ProjectOptions,
}

/// The local cache under `<output>/.cirrus/cache`, with the shared store behind it when the
/// pipeline or the command line names one (one that cannot be opened is a warning).
fn open_disk_cache(config: &PipelineConfig, options: &ProjectOptions) -> Option<DiskCache> {
    if !options.persistent_cache {
        return None;
    }
    let local = DiskCache::new(config.cache_dir());
    Some(match options.remote_cache.apply(config.remote_cache.as_ref()).map(crate::cache::remote::RemoteStore::open) {
        None => local,
        Some(Ok(remote)) => {
            let limit = crate::cache::remote::largest_entry_bytes(config.limits.texture.working_set);
            local.with_remote(remote.with_object_limit(limit))
        }
        Some(Err(error)) => {
            tracing::warn!("{error}; building with the local cache only");
            local
        }
    })
}

impl Project {
    pub fn open(config: PipelineConfig, options: ProjectOptions) -> Project {
        let cache = open_disk_cache(&config, &options);
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
            source_reading: options.source_reading,
            fresh: HashSet::new(),
            history: HashMap::new(),
            last_statuses: HashMap::new(),
            last_revision: None,
            executed: BTreeSet::new(),
            revision,
            sources_changed_since_build: false,
            options,
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

    /// The database (read-only: the driver is its one writer).
    pub fn database(&self) -> &Database {
        &self.db
    }

    /// The salsa input of an asset the project has read.
    pub fn asset_input(&self, name: &str) -> Option<Asset> {
        self.assets.get(name).copied()
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
        let remote = |config: &PipelineConfig| self.options.remote_cache.apply(config.remote_cache.as_ref());
        if config.output != self.config.output || remote(&config) != remote(&self.config) {
            if let Some(cache) = self.db.disk_cache() {
                cache.flush();
            }
            self.db.replace_disk_cache(open_disk_cache(&config, &self.options));
        }
        self.config = config;
        self.sync_limits();
    }

    /// Sets the pipeline-wide inputs (limits, the source folder) when they changed (setters
    /// never compare).
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
        let source = self.config.source.clone();
        match crate::db::SourceFolder::try_get(&self.db) {
            Some(folder) if *folder.path(&self.db) == source => {}
            Some(folder) => {
                folder.set_path(&mut self.db).to(source);
            }
            None => {
                crate::db::SourceFolder::new(&self.db, source);
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
            } else if let Some(other) =
                assets.iter().find(|other| crate::config::asset_folders_collide(&other.name, &asset.name))
            {
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

    /// The asset's input, its settings and every file its kind reads, set only where changed.
    fn sync_asset(&mut self, config: &AssetConfig) -> Asset {
        let kind = AssetKind::of(&config.source);
        let main_file = self.config.source.join(config.source.main_file());
        let source_root = self.config.source.clone();
        let asset = match self.assets.get(&config.name) {
            Some(&asset) => {
                if asset.kind(&self.db) != kind {
                    asset.set_kind(&mut self.db).to(kind);
                }
                if asset.main_file(&self.db) != &main_file {
                    asset.set_main_file(&mut self.db).to(main_file);
                }
                if asset.settings(&self.db) != &config.settings {
                    asset.set_settings(&mut self.db).to(config.settings.clone());
                }
                if asset.source_root(&self.db) != &source_root {
                    asset.set_source_root(&mut self.db).to(source_root);
                }
                asset
            }
            None => {
                let asset = Asset::new(
                    &self.db,
                    config.name.clone(),
                    kind,
                    source_root,
                    main_file,
                    config.settings.clone(),
                    Arc::default(),
                    Arc::default(),
                );
                self.assets.insert(config.name.clone(), asset);
                asset
            }
        };
        // Sources named by globs: listed on every build, so that new files join and deleted
        // ones leave.
        let listed: Vec<Vec<PathBuf>> = config
            .source
            .glob_lists()
            .into_iter()
            .map(|globs| crate::sources::glob_matches(&self.config, globs))
            .collect();
        if **asset.listed(&self.db) != listed {
            asset.set_listed(&mut self.db).to(Arc::new(listed));
        }
        for _ in 0..MAX_DISCOVERY_ROUNDS {
            // The files known so far are read first: what they say decides what else is read.
            let known: Vec<PathBuf> = asset.files(&self.db).keys().cloned().collect();
            for path in known {
                self.source_file(&path);
            }
            let wanted = kind.files_to_read(&self.db, asset);
            let files: BTreeMap<PathBuf, SourceFile> =
                wanted.into_iter().map(|path| (path.clone(), self.source_file(&path))).collect();
            if **asset.files(&self.db) == files {
                break;
            }
            asset.set_files(&mut self.db).to(Arc::new(files));
        }
        asset
    }

    /// Names the built assets for those that read another's output (`ao_source`), syncing each
    /// asset read that this build does not bake itself (`--asset` leaving it out): its result
    /// is computed for the reader, its files are not written. Set only when it changed.
    fn sync_registry(&mut self, all_assets: &[AssetConfig], built: &[(AssetConfig, Asset)]) {
        let mut registry: BTreeMap<String, Asset> =
            built.iter().map(|(config, asset)| (config.name.clone(), *asset)).collect();
        for (config, _) in built {
            let Some(source) = &config.settings.ao_source else { continue };
            if registry.contains_key(source) {
                continue;
            }
            if let Some(read) = all_assets.iter().find(|asset| &asset.name == source) {
                let asset = self.sync_asset(read);
                registry.insert(read.name.clone(), asset);
            }
        }
        match crate::db::AssetRegistry::try_get(&self.db) {
            Some(current) if **current.assets(&self.db) == registry => {}
            Some(current) => {
                current.set_assets(&mut self.db).to(Arc::new(registry));
            }
            None => {
                crate::db::AssetRegistry::new(&self.db, Arc::new(registry));
            }
        }
    }

    /// Bakes the assets, writing only artifacts whose bytes changed.
    pub fn build(
        &mut self,
        options: &BuildOptions,
        progress: &(dyn Fn(Progress) + Sync),
    ) -> Result<BuildSummary, BuildError> {
        let (all_assets, conflicts) = self.asset_list_and_conflicts();
        for conflict in &conflicts {
            tracing::warn!("{conflict}");
        }
        require_assets(&options.only_assets, &all_assets, &self.config.file)?;
        let selected: Vec<AssetConfig> = all_assets
            .iter()
            .filter(|asset| options.only_assets.is_empty() || options.only_assets.contains(&asset.name))
            .cloned()
            .collect();

        let cancel = options.cancel.clone().unwrap_or_default();
        if self.source_reading == SourceReading::EveryBuild {
            self.fresh.clear();
        }
        let mut assets = Vec::new();
        for config in selected {
            if cancel.is_raised() {
                self.db.take_runs();
                return Err(BuildError::Cancelled);
            }
            let asset = self.sync_asset(&config);
            assets.push((config, asset));
        }
        self.sync_registry(&all_assets, &assets);
        if let Some(cache) = self.db.disk_cache() {
            // This build's hits and misses start here.
            cache.take_counts();
            cache.take_misses();
        }
        let first_jobs =
            assets.iter().flat_map(|(_, asset)| asset.kind(&self.db).first_jobs(&self.db, *asset)).collect();
        let finished = crate::schedule::run_jobs(&self.db, first_jobs, progress, &cancel);
        let runs = self.db.take_runs();
        crate::gpu::wait_for_gpu_start();
        if let Some(cache) = self.db.disk_cache() {
            // Entries written in the background are on disk before the build reports.
            cache.flush();
        }
        let Some(finished) = finished.filter(|_| !cancel.is_raised()) else { return Err(BuildError::Cancelled) };
        // Per asset: its errors, and the labels of its jobs that failed.
        let mut failures: HashMap<Asset, (Vec<Diagnostic>, HashSet<String>)> = HashMap::new();
        for (job, result) in finished {
            if let Err(diagnostic) = result {
                let (errors, labels) = failures.entry(job.asset).or_default();
                if !errors.contains(&diagnostic) {
                    errors.push(diagnostic);
                }
                labels.insert(job.label);
            }
        }

        let output_dir = self.config.output_dir();
        let mut manifest = load_manifest(&output_dir);
        let next_revision = manifest.revision.max(self.revision) + 1;
        let mut changed = options.always_new_revision;
        let mut changed_artifacts = Vec::new();
        let mut removed_artifacts = Vec::new();
        let mut summaries = Vec::new();
        let mut statuses = HashMap::new();
        // Every asset's files are put together before any is written: an edit meanwhile (a
        // folder of sources deleted) still cancels the build, and nothing of it is published.
        let mut all_outputs = Vec::with_capacity(assets.len());
        for (config, asset) in &assets {
            if cancel.is_raised() {
                return Err(BuildError::Cancelled);
            }
            let (mut errors, failed_jobs) = failures.remove(asset).unwrap_or_default();
            let folder = self.config.output.join(&config.name);
            let outputs = asset.kind(&self.db).outputs(&self.db, *asset, &folder, &mut errors, &runs);
            all_outputs.push((errors, failed_jobs, folder, outputs));
        }
        if cancel.is_raised() {
            return Err(BuildError::Cancelled);
        }
        for ((config, asset), (mut errors, failed_jobs, folder, outputs)) in assets.iter().zip(all_outputs) {
            // Writing is not interrupted (the manifest must list what was written), but an asset
            // baked from a source that went away meanwhile (a folder deleted while it baked, whose
            // event may not have arrived yet) is not published: the next build, which that
            // deletion asks for, removes what it had. (A failure is still reported.)
            if errors.is_empty() && !self.config.source_dir().join(config.source.main_file()).exists() {
                continue;
            }
            let kind = asset.kind(&self.db);
            // Project-relative artifact path → blake3 hex of what this build wrote there.
            let mut produced = BTreeMap::new();
            let mut all_written = true;
            for (path, bytes) in &outputs.files {
                all_written &= self.write_artifact(path, bytes, &mut errors, &mut produced);
            }
            let warnings = outputs.warnings;
            // The report comes last and describes the files above: it is written only when they
            // all are (a failed write keeps the last good report with its files).
            if let (Some(mut report), true) = (outputs.report, all_written) {
                report.push(b'\n');
                self.write_artifact(&folder.join("report.json"), &report, &mut errors, &mut produced);
            }
            let asset_folder = format!("{}/", display_path(&folder));
            for (path, hash) in &produced {
                let meaning =
                    outputs.meanings.iter().find(|(file, _)| display_path(file) == *path).map(|(_, meaning)| meaning);
                if record_artifact(&mut manifest, next_revision, &config.name, path, hash, meaning) {
                    changed = true;
                    changed_artifacts.push(ChangedArtifact {
                        asset: config.name.clone(),
                        artifact: path.strip_prefix(&asset_folder).unwrap_or(path).to_string(),
                        path: path.clone(),
                        hash: hash.clone(),
                        meaning: meaning.cloned(),
                    });
                }
            }
            if errors.is_empty() {
                // A fully baked asset owns exactly what it produced: drop stale artifacts.
                let name = &config.name;
                removed_artifacts.extend(remove_artifacts(&self.config, &mut manifest, |path, entry| {
                    &entry.asset == name && !produced.contains_key(path)
                }));
            }
            let instances = kind.stage_instances(&self.db, *asset, &folder, &errors);
            let stages = stage_summaries(&instances, &runs, !errors.is_empty(), &failed_jobs);
            for (instance, stage) in instances.iter().zip(&stages) {
                let state = stage.status.name();
                let ms = (stage.status == StageStatus::Ran).then_some((stage.ms * 10.0).round() / 10.0);
                statuses.insert(instance.node_id(), (state, ms));
            }
            summaries.push(AssetSummary {
                name: config.name.clone(),
                kind: kind.name(),
                status: if errors.is_empty() { AssetStatus::Ok } else { AssetStatus::Failed },
                stages,
                artifacts: asset_artifacts(&manifest, &config.name),
                errors: errors.iter().map(ErrorSummary::from).collect(),
                warnings,
            });
        }
        if options.only_assets.is_empty() && self.config.source_dir().is_dir() {
            // Artifacts of assets that left the pipeline (not of those that a vanished source
            // folder took along: they failed, and keep their last good artifacts).
            let names: BTreeSet<&str> = all_assets.iter().map(|asset| asset.name.as_str()).collect();
            removed_artifacts.extend(remove_artifacts(&self.config, &mut manifest, |_, entry| {
                !names.contains(entry.asset.as_str())
            }));
        }
        // A failure is news too: its batch gets a revision of its own, so that a client that
        // subscribes after it (with `since` = the revision before) still hears of it.
        changed |=
            !removed_artifacts.is_empty() || summaries.iter().any(|summary| summary.status == AssetStatus::Failed);
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
        if let Some(cache) = self.db.disk_cache() {
            let assets = summaries
                .iter()
                .map(|asset| crate::cache::upkeep::LastBuildAsset {
                    name: asset.name.clone(),
                    stages: asset
                        .stages
                        .iter()
                        .map(|stage| (stage_node_id(stage.stage, &stage.instance), stage.status.name().to_string()))
                        .collect(),
                })
                .collect();
            let last = crate::cache::upkeep::LastBuild {
                revision: manifest.revision,
                counts: cache.take_counts(),
                remote: cache.remote().map(|remote| remote.settings().url.clone()),
                assets,
                misses: cache.take_misses(),
            };
            crate::cache::upkeep::write_last_build(cache.folder(), &last);
        }
        self.record_runs(&runs, manifest.revision);
        self.last_statuses = statuses;
        self.last_revision = Some(manifest.revision);
        changed_artifacts.sort_by(|a, b| a.path.cmp(&b.path));
        Ok(BuildSummary {
            revision: manifest.revision,
            assets: summaries,
            changed: changed_artifacts,
            removed: removed_artifacts,
        })
    }

    /// Adds stage runs to the history (revision, milliseconds) and the executed log.
    fn record_runs(&mut self, runs: &[StageRun], revision: u64) {
        for run in runs.iter().filter(|run| !run.from_cache) {
            let id = stage_node_id(run.stage, &run.label);
            let entry = self.history.entry(id.clone()).or_insert((0, 0.0));
            if entry.0 != revision {
                *entry = (revision, 0.0);
            }
            entry.1 += run.ms;
            self.executed.insert(id);
        }
    }

    /// Validates every asset's sources without baking (its kind's `check`), and reports
    /// rule-matched files that do not become assets.
    pub fn check(&self) -> Vec<(String, Vec<Diagnostic>)> {
        self.check_assets(&[]).expect("no asset named")
    }

    /// [`Project::check`] of the assets named in `only` (every asset, and the rules' conflicts,
    /// when it is empty); an unknown name is an error, with the closest known one.
    pub fn check_assets(&self, only: &[String]) -> Result<Vec<(String, Vec<Diagnostic>)>, BuildError> {
        let (assets, conflicts) = self.asset_list_and_conflicts();
        require_assets(only, &assets, &self.config.file)?;
        // Rule-matched files that do not become assets are reported under `rules`.
        let conflicts =
            conflicts.into_iter().filter(|_| only.is_empty()).map(|conflict| ("rules".to_string(), vec![conflict]));
        Ok(assets
            .into_iter()
            .filter(|asset| only.is_empty() || only.contains(&asset.name))
            .map(|asset| {
                let problems = AssetKind::of(&asset.source).check(&self.config, &asset);
                (asset.name, problems)
            })
            .chain(conflicts)
            .collect())
    }

    /// The stage instances that ran since the last call, as `stage(instance)`, sorted.
    pub fn take_executed_stages(&mut self) -> Vec<String> {
        let runs = self.db.take_runs();
        self.record_runs(&runs, self.revision);
        std::mem::take(&mut self.executed).into_iter().collect()
    }

    /// The salsa input of a file, read from disk now; set again only when its bytes changed.
    fn source_file(&mut self, path: &Path) -> SourceFile {
        if self.fresh.contains(path) {
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
                self.files.insert(path.to_path_buf(), file);
                file
            }
        }
    }

    /// Writes one artifact (project-relative `path`) if its bytes changed and records its hash;
    /// false when it could not be written. A report that differs only in its timings is kept.
    fn write_artifact(
        &self,
        path: &Path,
        bytes: &[u8],
        errors: &mut Vec<Diagnostic>,
        produced: &mut BTreeMap<String, String>,
    ) -> bool {
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

    /// The dependency graph of every asset: source files, stage instances and artifacts, with
    /// an edge for each read a stage function makes (the same stage instances the summary lists).
    /// Reads the sources and runs the stages that tell the instances (a billboard cloud's
    /// layout) where needed.
    pub fn graph(&mut self) -> crate::graph::Graph {
        use crate::graph::{GraphBuilder, Node, NodeKind};
        let mut graph = GraphBuilder::default();
        let manifest = load_manifest(&self.config.output_dir());
        let list = self.asset_list();
        let assets: Vec<(AssetConfig, Asset)> =
            list.iter().map(|config| (config.clone(), self.sync_asset(config))).collect();
        self.sync_registry(&list, &assets);
        let mut all_instances = Vec::new();
        for (config, asset) in assets {
            let folder = self.config.output.join(&config.name);
            let instances = asset.kind(&self.db).stage_instances(&self.db, asset, &folder, &[]);
            all_instances.push((config.name, instances));
        }
        let runs = self.db.take_runs();
        self.record_runs(&runs, self.revision);
        for (asset, instances) in &all_instances {
            for instance in instances {
                let id = instance.node_id();
                let last = self.history.get(&id);
                // Instances without a status in the last summary: from the history.
                let (state, ms) = self.last_statuses.get(&id).cloned().unwrap_or(match (self.last_revision, last) {
                    (None, _) => ("pending", None),
                    (Some(revision), Some((ran, ms))) if *ran == revision => ("ran", Some((ms * 10.0).round() / 10.0)),
                    (Some(_), _) => ("cached", None),
                });
                graph.node(Node {
                    id: id.clone(),
                    kind: NodeKind::Stage,
                    label: id.clone(),
                    asset: (!instance.shared).then(|| asset.clone()),
                    revision: last.map(|(revision, _)| *revision),
                    ms: ms.or(last.map(|(_, ms)| (ms * 10.0).round() / 10.0)),
                    state: state.to_string(),
                });
                for read in &instance.reads {
                    let from = match read {
                        Read::File(path) => self.file_node(&mut graph, path),
                        Read::Stage(stage, label) => stage_node_id(stage.name, label),
                    };
                    graph.edge(&from, &id);
                }
                for path in &instance.writes {
                    let artifact = display_path(path);
                    let entry = manifest.artifacts.get(&artifact);
                    graph.node(Node {
                        id: artifact.clone(),
                        kind: NodeKind::Artifact,
                        label: artifact.clone(),
                        asset: Some(asset.clone()),
                        revision: entry.map(|entry| entry.revision),
                        ms: None,
                        state: if entry.is_some() { "written" } else { "pending" }.to_string(),
                    });
                    graph.edge(&id, &artifact);
                }
            }
        }
        graph.finish()
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
}

/// The summary of each stage instance: ran when this build ran it, failed when the asset
/// failed before it had a result (its kind says, or its job failed), remote when its result
/// came from the shared cache, cached otherwise. A stage that needed no result of its own
/// (what it feeds was found in a cache) is remote when every cache hit of its asset in this
/// build came from the shared cache, and cached otherwise.
fn stage_summaries(
    instances: &[StageInstance],
    runs: &[StageRun],
    asset_failed: bool,
    failed_jobs: &HashSet<String>,
) -> Vec<StageSummary> {
    let mut ran: HashMap<(&str, &str), f64> = HashMap::new();
    for run in runs.iter().filter(|run| !run.from_cache) {
        *ran.entry((run.stage, run.label.as_str())).or_insert(0.0) += run.ms;
    }
    let ids: HashSet<(&str, &str)> =
        instances.iter().map(|instance| (instance.stage.name, instance.label.as_str())).collect();
    let hits: Vec<&StageRun> =
        runs.iter().filter(|run| run.from_cache && ids.contains(&(run.stage, run.label.as_str()))).collect();
    let remote_hits: HashSet<(&str, &str)> =
        hits.iter().filter(|run| run.from_remote).map(|run| (run.stage, run.label.as_str())).collect();
    let every_hit_remote = !hits.is_empty() && hits.iter().all(|run| run.from_remote);
    let local_hits: HashSet<(&str, &str)> =
        hits.iter().filter(|run| !run.from_remote).map(|run| (run.stage, run.label.as_str())).collect();
    instances
        .iter()
        .map(|instance| {
            let id = (instance.stage.name, instance.label.as_str());
            let (status, ms) = match ran.get(&id) {
                Some(&ms) => (StageStatus::Ran, ms),
                None if asset_failed && (instance.failed || failed_jobs.contains(&instance.label)) => {
                    (StageStatus::Failed, 0.0)
                }
                None if !local_hits.contains(&id) && (remote_hits.contains(&id) || every_hit_remote) => {
                    (StageStatus::Remote, 0.0)
                }
                None => (StageStatus::Cached, 0.0),
            };
            StageSummary { stage: instance.stage.name, instance: instance.instance.clone(), status, ms }
        })
        .collect()
}

/// The artifacts the manifest lists for an asset.
fn asset_artifacts(manifest: &Manifest, asset: &str) -> Vec<ArtifactSummary> {
    let entries = manifest.artifacts.iter().filter(|(_, entry)| entry.asset == asset);
    entries.map(|(path, entry)| ArtifactSummary { path: path.clone(), hash: entry.hash.clone() }).collect()
}

/// The graph node id of a source file.
pub fn file_node_id(path: &Path) -> String {
    display_path(path)
}
