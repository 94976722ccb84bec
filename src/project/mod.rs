//! The build driver, which names no kind: reads each asset's sources into salsa inputs (only
//! when their bytes changed, asking the asset's kind which files it reads until nothing new
//! turns up), runs the kinds' jobs on worker threads with database clones, writes the artifacts
//! and the manifest, and reports what ran: the summary and the graph both come from the stage
//! instances each kind declares.

use std::collections::{BTreeMap, BTreeSet, HashMap, HashSet};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use salsa::Setter;

use crate::artifacts::{remove_artifacts, Manifest};
use crate::cache::DiskCache;
use crate::config::{AssetConfig, PipelineConfig};
use crate::db::{Asset, Database, Db, SourceFile, StageRun};
use crate::diagnostic::{display_path, Diagnostic};
use crate::kinds::stage_node_id;
use crate::record::{FileStamp, InstanceRecord};
use crate::summary::{AssetStatus, BuildSummary};

pub use crate::schedule::{CancelFlag, Progress};

mod asset_list;
pub mod batch;
mod baking;
mod budget;
mod clean;
mod graph;
mod groups;
use baking::{Baking, GroupsBaked};
mod publish;
mod publish_state;
mod skip_record;
mod source_files;
mod summaries;
mod unchanged;

// The project's parts, each a type of its own (public so that the tests read each alone).
pub use asset_list::{list_assets, AssetList, AssetLists};
pub use budget::{AssetCost, MemoryPolicy};
pub use clean::CleanAssets;
pub use publish_state::PublishState;
use publish_state::{BakedAsset, BuildNews};
pub use skip_record::SkipRecord;
use summaries::runs_by_asset;

/// How a project is opened.
#[derive(Clone, Debug)]
pub struct ProjectOptions {
    /// Keep stage results on disk under `<output>/.cirrus/cache` across runs.
    pub persistent_cache: bool,
    /// When source files are read again.
    pub source_reading: SourceReading,
    /// The command line's word on the shared cache (`pipeline.ron`'s `cache` otherwise).
    pub remote_cache: crate::cache::remote::RemoteCacheOverride,
    /// Hash every source file and every artifact instead of trusting the build record's
    /// metadata (`cirrus build --verify`).
    pub verify: bool,
    /// What the process keeps of a build beyond its outputs.
    pub retention: crate::db::Retention,
    /// The command line's memory budget in bytes (`--memory-mib`), over `pipeline.ron`'s.
    pub memory_budget: Option<u64>,
}

impl Default for ProjectOptions {
    fn default() -> Self {
        ProjectOptions {
            persistent_cache: true,
            source_reading: SourceReading::EveryBuild,
            remote_cache: Default::default(),
            verify: false,
            retention: Default::default(),
            memory_budget: None,
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
    /// Leave the assets that the record let the build pass over out of the summary (the daemon,
    /// whose batches report what changed, so that a batch costs what its edit costs).
    pub omit_unchanged: bool,
}

/// Per asset: its errors and the labels of its jobs that failed.
type JobFailures = HashMap<Asset, (Vec<Diagnostic>, HashSet<String>)>;

/// `Err(UnknownAsset)`, with the closest known name, for the first of `names` that names none
/// of `assets`.
pub(crate) fn require_assets(names: &[String], assets: &[AssetConfig], pipeline: &Path) -> Result<(), BuildError> {
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
    #[error("asset `{name}` failed to bake:\n{errors}")]
    Failed { name: String, errors: String },
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
    /// The stage instances of the assets the last build looked into, for the graph while no
    /// input changed since (the daemon's log after each batch asks for it without a second sync).
    built_instances: HashMap<String, Vec<InstanceRecord>>,
    /// How many times an asset's input was synced (its files listed and set): see
    /// [`Project::assets_synced`].
    syncs: u64,
    options: ProjectOptions,
    /// The build record, and what decides from it that an asset is passed over.
    skip: SkipRecord,
    /// Content hashes (or why a file cannot be read) of files that have no salsa input, valid
    /// while the file is in `fresh`.
    known: HashMap<PathBuf, Result<blake3::Hash, crate::files::ReadError>>,
    /// The manifest as last read or written.
    published: PublishState,
    /// The asset list (the daemon keeps it until an edit may change it).
    asset_lists: AssetLists,
    /// The daemon's assets known to be as the record holds them, and each file's readers.
    clean: CleanAssets,
    /// Source files read (and hashed) since the last build finished.
    files_read: usize,
    /// What `file_hash` read of files without an input, for `source_file` to take instead of
    /// reading them again (emptied when a build ends).
    unclaimed: HashMap<PathBuf, crate::db::FileRead>,
    /// The memory budget, and the assets baked last (whose intermediates the daemon keeps).
    memory: MemoryPolicy,
    /// The assets whose intermediates are kept now (see `MemoryPolicy::kept_with`).
    kept: HashSet<String>,
    /// How many groups the last build baked (see `groups`).
    last_groups: usize,
}

/// The memory budget in force: the command line's, else `pipeline.ron`'s, else half the
/// machine's memory.
fn memory_budget(config: &PipelineConfig, options: &ProjectOptions) -> u64 {
    options.memory_budget.or(config.limits.memory).unwrap_or_else(crate::memory::default_budget)
}

/// Bump when what enters an asset's fingerprint changes.
const FINGERPRINT_VERSION: u32 = 1;

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
        let published = PublishState::load(&config.output_dir());
        // (A daemon writes the manifest when idle, and the revision of every batch at once.)
        let revision = published.revision().max(crate::record::saved_revision(&config.output_dir()));
        let skip = SkipRecord::load(&config);
        if !published.had_file() && !skip.record().assets.is_empty() {
            tracing::warn!(
                "{} is missing: this build writes a new one (artifacts it does not list are left alone)",
                display_path(&crate::artifacts::manifest_path(&config.output))
            );
        }
        // Only a build that was interrupted leaves temporary files: the output folder is walked
        // for them only then.
        if crate::record::interrupted_build(&config.output_dir()) {
            let swept = crate::artifacts::sweep_temporary_files(&config.output_dir());
            if swept > 0 {
                tracing::info!("deleted {swept} temporary file(s) left by an interrupted build");
            }
        }
        let across_builds = options.source_reading == SourceReading::WhenInvalidated;
        let memory = MemoryPolicy::new(memory_budget(&config, &options));
        crate::schedule::TEXTURE_MEMORY.set_ceiling(memory.in_flight_share());
        let mut project = Project {
            config,
            db: Database::with_retention(cache, options.retention),
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
            built_instances: HashMap::new(),
            syncs: 0,
            options,
            skip,
            known: HashMap::new(),
            published,
            asset_lists: AssetLists::default(),
            clean: CleanAssets::new(across_builds),
            files_read: 0,
            unclaimed: HashMap::new(),
            memory,
            kept: HashSet::new(),
            last_groups: 0,
        };
        project.sync_limits();
        // Memos record their uses from the first build on, so that the budget can evict them.
        project.set_memo_capacity(budget::UNBOUNDED_MEMOS, budget::UNBOUNDED_MEMOS);
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

    /// The salsa input of an asset of the pipeline, read now if a build passed it over.
    /// Builds the asset `name` alone (when it is not baked already) and returns its input, for a
    /// command that reads what the asset's stages made (`cirrus preview`); an asset that failed
    /// to bake is an error listing its problems.
    pub fn built_asset(&mut self, name: &str) -> Result<Asset, BuildError> {
        let build = BuildOptions { only_assets: vec![name.to_string()], ..Default::default() };
        let summary = self.build(&build, &|_| {})?;
        let asset = &summary.assets[0];
        if asset.status != crate::summary::AssetStatus::Ok {
            let errors = asset
                .errors
                .iter()
                .map(|error| format!("  {}: {}", error.file, error.message))
                .collect::<Vec<_>>()
                .join("\n");
            return Err(BuildError::Failed { name: name.to_string(), errors });
        }
        Ok(self.asset_input(name).expect("a built asset has an input"))
    }

    /// How many groups of assets the last build baked and published one after another (1 when
    /// its assets fit the memory budget together).
    pub fn groups_baked(&self) -> usize {
        self.last_groups
    }

    /// The assets whose intermediates the process keeps now, sorted.
    pub fn kept_assets(&self) -> Vec<String> {
        let mut kept: Vec<String> = self.kept.iter().cloned().collect();
        kept.sort();
        kept
    }

    /// The bytes of source files held in memory now (the others are read back when needed).
    pub fn source_bytes_in_memory(&self) -> u64 {
        let kept = self.files.values().filter_map(|file| file.contents(&self.db).as_ref().ok());
        kept.filter(|contents| contents.is_kept()).map(|contents| contents.len).sum()
    }

    /// How many times an asset's input was synced since the project opened: each costs the
    /// kind's file lists and a look at every file the asset reads (the daemon's tests count them).
    pub fn assets_synced(&self) -> u64 {
        self.syncs
    }

    pub(crate) fn asset_input(&mut self, name: &str) -> Option<Asset> {
        if let Some(&asset) = self.assets.get(name) {
            return Some(asset);
        }
        let listed = self.asset_list_and_conflicts();
        let config = listed.0.iter().find(|asset| asset.name == name)?;
        let asset = self.sync_asset(config);
        let all = listed.0.clone();
        self.sync_registry(&all, &[(config.clone(), asset)]);
        Some(asset)
    }

    /// Uses up a revision without a build (the daemon numbers a configuration error's batch).
    pub(crate) fn skip_revision(&mut self) {
        self.revision += 1;
    }

    /// Every source file read so far (project-relative), and every file that the record says
    /// a baked asset reads.
    pub(crate) fn source_paths(&self) -> BTreeSet<PathBuf> {
        let recorded = self.skip.record().assets.values().flat_map(|asset| asset.files.iter());
        self.files.keys().chain(recorded).cloned().collect()
    }

    /// The source files of the named assets: read by their inputs, or by the record.
    pub(crate) fn source_paths_of(&self, names: &HashSet<String>) -> BTreeSet<PathBuf> {
        let mut paths = BTreeSet::new();
        for name in names {
            if let Some(&asset) = self.assets.get(name) {
                paths.extend(asset.files(&self.db).keys().cloned());
            }
            if let Some(record) = self.skip.asset(name) {
                paths.extend(record.files.iter().cloned());
            }
        }
        paths
    }

    /// Those of `paths` (source files a build read) that are not as the build read them: written,
    /// created or deleted since. The daemon asks after each batch, since an edit to a file that
    /// no asset read yet (a texture a new material names) is not watched for until the batch
    /// that reads it ends, and its event may have come and gone meanwhile.
    pub(crate) fn moved_since_read(&self, paths: &BTreeSet<PathBuf>) -> Vec<PathBuf> {
        paths
            .iter()
            .filter(|path| {
                // A file the build could not read had no stamp then (the record may hold an older
                // one): it moved if it is there now.
                let read_failed = match self.files.get(*path) {
                    Some(file) => file.contents(&self.db).is_err(),
                    None => matches!(self.known.get(*path), Some(Err(_))),
                };
                let read = self.skip.record().files.get(*path).map(|file| file.stamp).filter(|_| !read_failed);
                FileStamp::read(&self.config.root.join(path)) != read
            })
            .cloned()
            .collect()
    }

    /// Marks every source file as possibly changed (after a watcher overflow or error).
    pub fn invalidate_all_sources(&mut self) {
        self.fresh.clear();
        self.built_instances.clear();
        self.clean.clear();
        self.asset_lists.forget();
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
        self.memory.set_budget(memory_budget(&config, &self.options));
        crate::schedule::TEXTURE_MEMORY.set_ceiling(self.memory.in_flight_share());
        self.config = config;
        self.asset_lists.forget();
        self.built_instances.clear();
        self.skip.forget_settings_hashes();
        self.clean.clear();
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
    pub(crate) fn asset_list(&self) -> Vec<AssetConfig> {
        self.asset_list_and_conflicts().0.clone()
    }

    /// The assets of the pipeline, and a warning for each rule-matched file that does not
    /// become an asset because its name is reserved or collides with another asset's folder.
    /// The daemon keeps them until an edit may change them (see `refresh_sources`); a build
    /// lists them afresh.
    pub(crate) fn asset_list_and_conflicts(&self) -> Arc<AssetList> {
        self.asset_lists.get(&self.config, self.source_reading == SourceReading::WhenInvalidated)
    }

    /// Forgets the kept asset list when `path` (project-relative) may change it.
    fn forget_asset_list_for(&mut self, path: &Path) {
        let known = self.files.contains_key(path) || self.skip.record().files.contains_key(path);
        self.asset_lists.forget_for(&self.config, path, known);
    }

    /// The asset's input, its settings and every file its kind reads, set only where changed.
    fn sync_asset(&mut self, config: &AssetConfig) -> Asset {
        self.syncs += 1;
        let kind = config.source.kind();
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
        let listed = self.listed_sources(config);
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
            let Some(source) = config.settings.reads_asset() else { continue };
            if registry.contains_key(source) {
                continue;
            }
            if let Some(read) = all_assets.iter().find(|asset| asset.name == source) {
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
        let listed = self.asset_list_and_conflicts();
        let (all_assets, conflicts) = (&listed.0, &listed.1);
        for conflict in conflicts {
            tracing::warn!("{conflict}");
        }
        require_assets(&options.only_assets, all_assets, &self.config.file)?;
        self.clean.keep_for(&listed);
        self.built_instances.clear();
        let selected: Vec<&AssetConfig> = all_assets
            .iter()
            .filter(|asset| options.only_assets.is_empty() || options.only_assets.contains(&asset.name))
            .collect();

        let cancel = options.cancel.clone().unwrap_or_default();
        if self.source_reading == SourceReading::EveryBuild {
            self.fresh.clear();
            self.clean.clear();
        }
        let output_dir = self.config.output_dir();
        let mut manifest = self.take_manifest();
        // Assets whose fingerprint and artifacts are as the record has them are passed over:
        // no input, no stage, no file read.
        let mut dirty = Vec::new();
        let mut unchanged = Vec::new();
        for config in selected {
            if cancel.is_raised() {
                self.db.take_runs();
                self.keep_manifest(manifest);
                return Err(BuildError::Cancelled);
            }
            if self.unchanged_asset(config, all_assets, &manifest) {
                unchanged.push(config);
                continue;
            }
            dirty.push(config);
        }
        let next_revision = manifest.revision.max(self.revision) + 1;
        let mut news = BuildNews { changed: options.always_new_revision, ..Default::default() };
        let baking = Baking { all_assets, next_revision, progress, cancel: &cancel };
        let GroupsBaked { built, runs, groups, cancelled } =
            self.bake_in_groups(dirty, &baking, &mut manifest, &mut news);
        self.last_groups = groups;
        if cancelled && groups == 0 {
            self.db.take_runs();
            self.keep_manifest(manifest);
            return Err(BuildError::Cancelled);
        }
        if cancelled {
            tracing::info!("the build was cancelled after {groups} group(s) of assets were published");
        }
        let BuildNews { mut changed, mut changed_artifacts, mut removed_artifacts, mut summaries, statuses } = news;
        for config in unchanged.iter().filter(|_| !options.omit_unchanged) {
            summaries.push(self.passed_over_summary(config, &manifest));
        }
        if !options.omit_unchanged {
            // In the pipeline's order.
            let order: HashMap<&str, usize> =
                all_assets.iter().enumerate().map(|(index, config)| (config.name.as_str(), index)).collect();
            summaries.sort_by_key(|summary| order.get(summary.name.as_str()).copied());
        }
        if options.only_assets.is_empty() && !cancelled {
            removed_artifacts.extend(self.remove_departed(&listed, &mut manifest));
        }
        // A failure is news too: its batch gets a revision of its own, so that a client that
        // subscribes after it (with `since` = the revision before) still hears of it.
        changed |=
            !removed_artifacts.is_empty() || summaries.iter().any(|summary| summary.status == AssetStatus::Failed);
        if changed {
            self.save_build_manifest(&mut manifest, next_revision, &mut summaries);
        }
        self.revision = manifest.revision;
        self.sources_changed_since_build = false;
        let (passed, looked, read) = (unchanged.len(), built.len(), std::mem::take(&mut self.files_read));
        tracing::info!("{passed} asset(s) passed over, {looked} looked into; {read} source file(s) read");
        self.unclaimed.clear();
        // The daemon saves the record when it is idle (`save_record`): a record older than the
        // artifacts only costs the next start some checking. (It leaves files that no asset reads
        // any more in the record: pruning costs a pass over every file.)
        if self.source_reading == SourceReading::EveryBuild {
            if options.only_assets.is_empty() {
                self.skip.prune(all_assets);
            }
            self.save_record();
        }
        if groups > 0 {
            crate::record::end_writing(&output_dir);
        }
        self.write_last_build(&summaries, &unchanged, manifest.revision);
        self.record_runs(&runs, manifest.revision);
        self.last_statuses = statuses;
        self.last_revision = Some(manifest.revision);
        changed_artifacts.sort_by(|a, b| a.path.cmp(&b.path));
        let revision = manifest.revision;
        self.keep_manifest(manifest);
        Ok(BuildSummary { revision, assets: summaries, changed: changed_artifacts, removed: removed_artifacts })
    }

    /// Runs the first jobs of `assets` and those they schedule; this build's stage runs and, per
    /// asset, its errors and the labels of its jobs that failed. `None` when cancelled.
    #[allow(clippy::type_complexity)]
    fn run_asset_jobs(
        &mut self,
        assets: &[(AssetConfig, Asset)],
        progress: &(dyn Fn(Progress) + Sync),
        cancel: &CancelFlag,
    ) -> Option<(Vec<StageRun>, JobFailures, HashMap<Asset, usize>)> {
        if let Some(cache) = self.db.disk_cache() {
            // This build's hits and misses start here.
            cache.take_counts();
            cache.take_misses();
        }
        let first_jobs =
            assets.iter().flat_map(|(_, asset)| asset.kind(&self.db).first_jobs(&self.db, *asset)).collect();
        let finished = crate::schedule::run_jobs(&self.db, first_jobs, &crate::kinds::run_job, progress, cancel);
        let runs = self.db.take_runs();
        crate::gpu::wait_for_gpu_start();
        if let Some(cache) = self.db.disk_cache() {
            // Entries written in the background are on disk before the build reports.
            cache.flush();
        }
        let finished = finished.filter(|_| !cancel.is_raised())?;
        let mut failures: JobFailures = HashMap::new();
        let mut surfaces: HashMap<Asset, usize> = HashMap::new();
        for (job, result) in finished {
            if matches!(job.task, crate::kinds::Task::Surface(_)) {
                *surfaces.entry(job.asset).or_default() += 1;
            }
            if let Err(diagnostic) = result {
                let (errors, labels) = failures.entry(job.asset).or_default();
                if !errors.contains(&diagnostic) {
                    errors.push(diagnostic);
                }
                labels.insert(job.label);
            }
        }
        Some((runs, failures, surfaces))
    }

    /// Each asset's outputs as its kind makes them from the finished stages, with its errors;
    /// `None` when the build was cancelled meanwhile.
    #[allow(clippy::type_complexity)]
    fn asset_outputs(
        &self,
        assets: &[(AssetConfig, Asset)],
        runs: &[StageRun],
        mut failures: JobFailures,
        cancel: &CancelFlag,
    ) -> Option<Vec<BakedAsset>> {
        let mut all_outputs = Vec::with_capacity(assets.len());
        let mut asset_runs = runs_by_asset(runs, assets.iter().map(|(config, _)| config.name.as_str()));
        for (config, asset) in assets {
            if cancel.is_raised() {
                return None;
            }
            let (mut errors, failed_jobs) = failures.remove(asset).unwrap_or_default();
            let folder = self.config.output.join(&config.name);
            let runs = asset_runs.remove(config.name.as_str()).unwrap_or_default();
            let outputs = asset.kind(&self.db).outputs(&self.db, *asset, &folder, &mut errors, &runs);
            all_outputs.push(BakedAsset { errors, failed_jobs, folder, outputs });
        }
        (!cancel.is_raised()).then_some(all_outputs)
    }

    /// Removes the artifacts of assets that left the pipeline (not of those that a vanished
    /// source folder took along: they failed, and keep their last good artifacts); only a new
    /// asset list can have lost assets, so the daemon looks once per list. Returns what it removed.
    fn remove_departed(&mut self, listed: &Arc<AssetList>, manifest: &mut Manifest) -> Vec<String> {
        let checked =
            self.source_reading == SourceReading::WhenInvalidated && self.asset_lists.departures_checked(listed);
        if checked || !self.config.source_dir().is_dir() {
            return Vec::new();
        }
        self.asset_lists.note_departures_checked(listed);
        let names: HashSet<&str> = listed.0.iter().map(|asset| asset.name.as_str()).collect();
        let gone = manifest.artifacts.iter().filter(|(_, entry)| !names.contains(entry.asset.as_str()));
        let gone = gone.map(|(path, _)| path.clone()).collect();
        remove_artifacts(&self.config, manifest, gone)
    }

    /// The manifest on disk: the one kept when its file did not change since.
    fn take_manifest(&mut self) -> Manifest {
        self.published.take(&self.config.output_dir())
    }

    /// Keeps the manifest as it is on disk now, for the next [`Project::take_manifest`].
    fn keep_manifest(&mut self, manifest: Manifest) {
        self.published.keep(&self.config.output_dir(), manifest);
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
    pub(crate) fn check_assets(&self, only: &[String]) -> Result<Vec<(String, Vec<Diagnostic>)>, BuildError> {
        let listed = self.asset_list_and_conflicts();
        let (assets, conflicts) = listed.as_ref().clone();
        require_assets(only, &assets, &self.config.file)?;
        // Rule-matched files that do not become assets are reported under `rules`.
        let conflicts =
            conflicts.into_iter().filter(|_| only.is_empty()).map(|conflict| ("rules".to_string(), vec![conflict]));
        Ok(assets
            .into_iter()
            .filter(|asset| only.is_empty() || only.contains(&asset.name))
            .map(|asset| {
                let problems = asset.source.kind().check(&self.config, &asset);
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

    /// Writes an asset's `files` (project-relative paths) as one: each changed one is staged beside
    /// its place first, and only when all are is each renamed into place, in order; a file that
    /// cannot be staged leaves every one as it was. A report that differs only in its timings is
    /// kept. Records what is in place (path → blake3 hex) in `produced`.
    fn write_artifacts(
        &self,
        files: &[(&PathBuf, &[u8])],
        errors: &mut Vec<Diagnostic>,
        produced: &mut BTreeMap<String, String>,
    ) {
        let mut staged = Vec::new();
        let mut unchanged = Vec::new();
        for &(path, bytes) in files {
            let absolute = self.config.root.join(path);
            if path.file_name().is_some_and(|name| name == "report.json") {
                if let Some(existing) = crate::artifacts::same_report_on_disk(&absolute, bytes) {
                    unchanged.push((display_path(path), blake3::hash(&existing).to_hex().to_string()));
                    continue;
                }
            }
            let hash = blake3::hash(bytes).to_hex().to_string();
            match crate::files::stage_if_changed(&absolute, bytes) {
                Ok(Some(file)) => staged.push((path, hash, file)),
                Ok(None) => unchanged.push((display_path(path), hash)),
                Err(error) => errors.push(Diagnostic::new(path, format!("cannot write the artifact: {error}"))),
            }
        }
        if !errors.is_empty() {
            return;
        }
        produced.extend(unchanged);
        for (path, hash, file) in staged {
            if let Err(error) = file.commit() {
                errors.push(Diagnostic::new(path, format!("cannot write the artifact: {error}")));
                return;
            }
            produced.insert(display_path(path), hash);
        }
    }
}

/// The graph node id of a source file.
pub(crate) fn file_node_id(path: &Path) -> String {
    display_path(path)
}
