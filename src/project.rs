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
use crate::record::{AssetRecord, BuildRecord, FileStamp, InstanceRecord, ReadRecord};
use crate::sources::{read_source_stamped, rule_matches};
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
    /// Hash every source file and every artifact instead of trusting the build record's
    /// metadata (`cirrus build --verify`).
    pub verify: bool,
}

impl Default for ProjectOptions {
    fn default() -> Self {
        ProjectOptions {
            persistent_cache: true,
            source_reading: SourceReading::EveryBuild,
            remote_cache: Default::default(),
            verify: false,
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
    /// The build record: source files' metadata and hashes, baked assets' fingerprints.
    record: BuildRecord,
    /// The record differs from the one on disk.
    record_changed: bool,
    /// Content hashes (or why a file cannot be read) of files that have no salsa input, valid
    /// while the file is in `fresh`.
    known: HashMap<PathBuf, Result<blake3::Hash, String>>,
    /// Assets whose artifacts this process wrote or checked against the record: the daemon,
    /// which holds the output folder's lock, does not check them again.
    trusted_artifacts: HashSet<String>,
    /// What identifies this executable in fingerprints (a rebuilt cirrus trusts no record).
    identity: blake3::Hash,
    /// The hash of each distinct asset settings seen (most assets share their rule's), with the
    /// pipeline-wide values that enter fingerprints.
    settings_hashes: Vec<(crate::config::Settings, blake3::Hash)>,
    /// The manifest as last read or written, with the stamp its file had then: read again only
    /// when the file changed meanwhile.
    manifest: Option<(Option<FileStamp>, Manifest)>,
    /// The daemon's asset list, until an edit may change it.
    asset_list_kept: std::cell::RefCell<Option<Arc<AssetList>>>,
    /// The daemon's assets known to be as the record holds them, for the asset list in
    /// `clean_list`: passed over without a fingerprint until a file they read changes.
    clean: HashSet<String>,
    clean_list: Option<Arc<AssetList>>,
    /// The assets that read each source file (for `clean`; may name an asset that no longer
    /// reads it, which only costs that asset a fingerprint).
    readers: HashMap<PathBuf, Vec<String>>,
    /// The asset list whose departed assets' artifacts were last removed.
    departures_checked: Option<Arc<AssetList>>,
    /// The manifest kept in memory differs from the file (the daemon writes it when idle).
    manifest_unsaved: bool,
    /// Source files read (and hashed) since the last build finished.
    files_read: usize,
    /// What `file_hash` read of files without an input, for `source_file` to take instead of
    /// reading them again (emptied when a build ends).
    unclaimed: HashMap<PathBuf, crate::db::FileRead>,
}

/// The assets of the pipeline, and the rule-matched files that do not become assets.
type AssetList = (Vec<AssetConfig>, Vec<Diagnostic>);

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
        let manifest = load_manifest(&config.output_dir());
        // (A daemon writes the manifest when idle, and the revision of every batch at once.)
        let revision = manifest.revision.max(crate::record::saved_revision(&config.output_dir()));
        let manifest_stamp = FileStamp::read(&crate::artifacts::manifest_path(&config.output_dir()));
        let mut record = BuildRecord::load(&config.output_dir());
        record.keep_within(&config.source, &config.output);
        // Only a build that was interrupted leaves temporary files: the output folder is walked
        // for them only then.
        if crate::record::interrupted_build(&config.output_dir()) {
            let swept = crate::artifacts::sweep_temporary_files(&config.output_dir());
            if swept > 0 {
                tracing::info!("deleted {swept} temporary file(s) left by an interrupted build");
            }
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
            record,
            record_changed: false,
            known: HashMap::new(),
            trusted_artifacts: HashSet::new(),
            identity: executable_identity(),
            settings_hashes: Vec::new(),
            manifest: Some((manifest_stamp, manifest)),
            asset_list_kept: Default::default(),
            clean: HashSet::new(),
            clean_list: None,
            readers: HashMap::new(),
            departures_checked: None,
            manifest_unsaved: false,
            files_read: 0,
            unclaimed: HashMap::new(),
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

    /// The salsa input of an asset of the pipeline, read now if a build passed it over.
    pub fn asset_input(&mut self, name: &str) -> Option<Asset> {
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
    pub fn skip_revision(&mut self) {
        self.revision += 1;
    }

    /// Every source file read so far (project-relative), and every file that the record says
    /// a baked asset reads.
    pub fn source_paths(&self) -> BTreeSet<PathBuf> {
        let recorded = self.record.assets.values().flat_map(|asset| asset.files.iter());
        self.files.keys().chain(recorded).cloned().collect()
    }

    /// The source files of the named assets: read by their inputs, or by the record.
    pub fn source_paths_of(&self, names: &HashSet<String>) -> BTreeSet<PathBuf> {
        let mut paths = BTreeSet::new();
        for name in names {
            if let Some(&asset) = self.assets.get(name) {
                paths.extend(asset.files(&self.db).keys().cloned());
            }
            if let Some(record) = self.record.assets.get(name) {
                paths.extend(record.files.iter().cloned());
            }
        }
        paths
    }

    /// Marks source files as changed on disk: the next build reads them again.
    pub fn invalidate_sources<'a>(&mut self, paths: impl IntoIterator<Item = &'a Path>) {
        for path in paths {
            self.forget_asset_list_for(path);
            self.unclean_readers_of(path);
            self.fresh.remove(path);
        }
    }

    /// Reads `paths` again now; true when any of them is new to the project or its bytes changed,
    /// or another input changed since the last finished build (so that a touch with identical
    /// bytes costs no build).
    pub fn refresh_sources<'a>(&mut self, paths: impl IntoIterator<Item = &'a Path>) -> bool {
        let mut changed = self.sources_changed_since_build;
        for path in paths {
            self.forget_asset_list_for(path);
            self.unclean_readers_of(path);
            let before = self.last_known_hash(path);
            self.fresh.remove(path);
            let after = self.file_hash(path);
            changed |= before != Some(after);
        }
        changed
    }

    /// The content hash last seen of a file (its input's, or the record's), if any.
    fn last_known_hash(&self, path: &Path) -> Option<Result<blake3::Hash, String>> {
        match self.files.get(path) {
            Some(file) => Some(file.contents(&self.db).as_ref().map(|contents| contents.hash).map_err(Clone::clone)),
            None => self.known.get(path).cloned().or_else(|| self.record.files.get(path).map(|file| Ok(file.hash))),
        }
    }

    /// The content hash of a source file (or why it cannot be read): its input's when it has
    /// one, else the record's when the file's metadata did not move since it was recorded (not
    /// racy, no `--verify`), else read and hashed now (and recorded).
    fn file_hash(&mut self, path: &Path) -> Result<blake3::Hash, String> {
        if self.files.contains_key(path) {
            let file = self.source_file(path);
            return file.contents(&self.db).as_ref().map(|contents| contents.hash).map_err(Clone::clone);
        }
        if self.fresh.contains(path) {
            if let Some(known) = self.known.get(path) {
                return known.clone();
            }
        }
        let seen_at = crate::record::now();
        if !self.options.verify {
            let trusted = FileStamp::read(&self.config.root.join(path))
                .and_then(|stamp| self.record.trusted_hash(path, &stamp))
                .filter(|_| self.config.source_dir().is_dir());
            if let Some(hash) = trusted {
                self.fresh.insert(path.to_path_buf());
                self.known.insert(path.to_path_buf(), Ok(hash));
                return Ok(hash);
            }
        }
        self.files_read += 1;
        let recorded = self.record.files.get(path).map(|file| file.hash);
        let read = read_source_stamped(&self.config.root, &self.config.source, path).map(|(contents, stamp)| {
            self.record_changed |= self.record.remember_file(path, stamp, contents.hash, seen_at);
            contents
        });
        let hash = read.as_ref().map(|contents| contents.hash).map_err(Clone::clone);
        self.fresh.insert(path.to_path_buf());
        self.known.insert(path.to_path_buf(), hash.clone());
        // A file whose bytes changed is read again by the asset about to be baked: these bytes,
        // until the build ends (not those of a file merely touched).
        if hash.as_ref().ok() != recorded.as_ref() {
            self.unclaimed.insert(path.to_path_buf(), read);
        }
        hash
    }

    /// Marks every source file as possibly changed (after a watcher overflow or error).
    pub fn invalidate_all_sources(&mut self) {
        self.fresh.clear();
        self.clean.clear();
        *self.asset_list_kept.get_mut() = None;
    }

    /// The assets that read `path` are no longer known to be clean.
    fn unclean_readers_of(&mut self, path: &Path) {
        for reader in self.readers.get(path).into_iter().flatten() {
            self.clean.remove(reader);
        }
    }

    /// Marks an asset clean: passed over without a fingerprint until a file it reads changes
    /// (the daemon), or until the next build (which starts afresh).
    fn mark_clean(&mut self, name: &str) {
        if !self.clean.insert(name.to_string()) || self.source_reading != SourceReading::WhenInvalidated {
            return;
        }
        let files: Vec<PathBuf> = match self.assets.get(name) {
            Some(&asset) => asset.files(&self.db).keys().cloned().collect(),
            None => self.record.assets.get(name).map(|record| record.files.clone()).unwrap_or_default(),
        };
        for file in files {
            let readers = self.readers.entry(file).or_default();
            if !readers.iter().any(|reader| reader == name) {
                readers.push(name.to_string());
            }
        }
    }

    /// Keeps the clean assets whose configuration is the same in `list` as in the list they
    /// were found clean for.
    fn keep_clean_for(&mut self, list: &Arc<AssetList>) {
        match &self.clean_list {
            Some(old) if Arc::ptr_eq(old, list) => return,
            Some(old) => {
                let before: HashMap<&str, &AssetConfig> =
                    old.0.iter().map(|asset| (asset.name.as_str(), asset)).collect();
                let same: HashSet<&str> = list
                    .0
                    .iter()
                    .filter(|asset| before.get(asset.name.as_str()).is_some_and(|old| *old == *asset))
                    .map(|asset| asset.name.as_str())
                    .collect();
                self.clean.retain(|name| same.contains(name.as_str()));
            }
            None => self.clean.clear(),
        }
        self.clean_list = Some(list.clone());
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
        *self.asset_list_kept.get_mut() = None;
        self.settings_hashes.clear();
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
    pub fn asset_list(&self) -> Vec<AssetConfig> {
        self.asset_list_and_conflicts().0.clone()
    }

    /// The assets of the pipeline, and a warning for each rule-matched file that does not
    /// become an asset because its name is reserved or collides with another asset's folder.
    /// The daemon keeps them until an edit may change them (see `refresh_sources`); a build
    /// lists them afresh.
    pub fn asset_list_and_conflicts(&self) -> Arc<AssetList> {
        let mut kept = self.asset_list_kept.borrow_mut();
        if let Some(list) = kept.as_ref().filter(|_| self.source_reading == SourceReading::WhenInvalidated) {
            return list.clone();
        }
        let list = Arc::new(self.list_assets());
        *kept = Some(list.clone());
        list
    }

    /// Forgets the kept asset list when `path` (project-relative) may change it: a file that
    /// a rule matches, or one no asset reads (new, or a folder).
    fn forget_asset_list_for(&mut self, path: &Path) {
        if self.config.rules.is_empty() {
            return;
        }
        let known = self.files.contains_key(path) || self.record.files.contains_key(path);
        let matched = path.strip_prefix(&self.config.source).is_ok_and(|relative| {
            let relative = PathBuf::from(display_path(relative));
            self.config.rules.iter().any(|rule| rule.matcher.is_match(&relative))
        });
        if !known || matched {
            *self.asset_list_kept.get_mut() = None;
        }
    }

    fn list_assets(&self) -> AssetList {
        let mut assets = self.config.assets.clone();
        let mut conflicts = Vec::new();
        let mut folders = crate::config::AssetFolders::default();
        let mut by_name: HashMap<String, usize> = HashMap::new();
        for (index, asset) in assets.iter().enumerate() {
            folders.insert(&asset.name);
            by_name.insert(asset.name.clone(), index);
        }
        let listed_files: HashSet<&Path> = self.config.assets.iter().map(|asset| asset.source.main_file()).collect();
        for relative in rule_matches(&self.config) {
            if listed_files.contains(relative.as_path()) {
                continue;
            }
            let Some(asset) = self.config.rule_asset(&relative) else { continue };
            let file = self.config.source.join(&relative);
            if let Some(reserved) = crate::config::reserved_asset_name(&asset.name) {
                conflicts.push(Diagnostic::new(file, format!("warning: matches a rule but is not baked: {reserved}")));
            } else if let Some(other) = folders.collision(&asset.name).map(|name| &assets[by_name[name]]) {
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
                folders.insert(&asset.name);
                by_name.insert(asset.name.clone(), assets.len());
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

    /// The files of the source folder that an asset's globs list (none for most kinds).
    fn listed_sources(&self, config: &AssetConfig) -> Vec<Vec<PathBuf>> {
        let lists = config.source.glob_lists();
        lists.into_iter().map(|globs| crate::sources::glob_matches(&self.config, globs)).collect()
    }

    /// The hash of an asset's configuration with the pipeline-wide settings its outputs depend
    /// on (most assets share their rule's settings: each distinct one is formatted once).
    fn config_hash(&mut self, config: &AssetConfig) -> blake3::Hash {
        let settings = match self.settings_hashes.iter().find(|(seen, _)| *seen == config.settings) {
            Some((_, hash)) => *hash,
            None => {
                let text = format!(
                    "{:?}|{:?}|{:?}|{:?}|{}",
                    config.settings,
                    self.config.source,
                    self.config.output,
                    self.config.limits,
                    crate::isa::kernel_isa().name()
                );
                let hash = blake3::hash(text.as_bytes());
                if self.settings_hashes.len() >= 64 {
                    self.settings_hashes.remove(0);
                }
                self.settings_hashes.push((config.settings.clone(), hash));
                hash
            }
        };
        let mut hasher = blake3::Hasher::new();
        hasher.update(settings.as_bytes()).update(config.name.as_bytes()).update(b"\0");
        hasher.update(format!("{:?}", config.source).as_bytes());
        hasher.finalize()
    }

    /// The fingerprint of an asset that reads `files` and lists `listed`: everything its outputs
    /// depend on (this executable, the CPU kernels' level, its configuration and the pipeline's
    /// limits and folders, each file's content hash or why it cannot be read, and the
    /// fingerprint of the asset whose output it reads). `None` when that asset has none.
    fn fingerprint(
        &mut self,
        config: &AssetConfig,
        files: &[PathBuf],
        listed: &[Vec<PathBuf>],
        all_assets: &[AssetConfig],
        built: &HashMap<String, Asset>,
        depth: usize,
    ) -> Option<blake3::Hash> {
        let mut hasher = blake3::Hasher::new();
        hasher.update(&FINGERPRINT_VERSION.to_le_bytes());
        hasher.update(self.identity.as_bytes());
        hasher.update(self.config_hash(config).as_bytes());
        for list in listed {
            hasher.update(&(list.len() as u64).to_le_bytes());
            for path in list {
                hasher.update(display_path(path).as_bytes()).update(b"\0");
            }
        }
        hasher.update(&(files.len() as u64).to_le_bytes());
        for path in files {
            hasher.update(display_path(path).as_bytes()).update(b"\0");
            match self.file_hash(path) {
                Ok(hash) => hasher.update(b"=").update(hash.as_bytes()),
                Err(why) => hasher.update(b"!").update(why.as_bytes()).update(b"\0"),
            };
        }
        if let Some(source) = &config.settings.ao_source {
            let read = all_assets.iter().find(|asset| &asset.name == source)?;
            hasher.update(self.current_fingerprint(read, all_assets, built, depth + 1)?.as_bytes());
        }
        Some(hasher.finalize())
    }

    /// An asset's fingerprint now: of the files its input reads when this build baked it, else
    /// of the files the record says it reads (`None` when it has no record: never baked, or
    /// failed).
    fn current_fingerprint(
        &mut self,
        config: &AssetConfig,
        all_assets: &[AssetConfig],
        built: &HashMap<String, Asset>,
        depth: usize,
    ) -> Option<blake3::Hash> {
        if depth > 4 {
            return None;
        }
        let (files, listed) = match built.get(&config.name) {
            Some(&asset) => (asset.files(&self.db).keys().cloned().collect(), (**asset.listed(&self.db)).clone()),
            None => (self.record.assets.get(&config.name)?.files.clone(), self.listed_sources(config)),
        };
        self.fingerprint(config, &files, &listed, all_assets, built, depth)
    }

    /// Whether an asset can be passed over: the record holds it, its fingerprint is the same,
    /// and every artifact it wrote is still there as written (by its metadata, or its bytes'
    /// hash with `--verify`) and listed in the manifest as its.
    fn unchanged_asset(&mut self, config: &AssetConfig, all_assets: &[AssetConfig], manifest: &Manifest) -> bool {
        // Nothing this asset reads changed since it was last found unchanged (an asset that
        // reads another's output, or lists its sources by glob, is checked every time).
        let checked_every_time = config.settings.ao_source.is_some() || !config.source.glob_lists().is_empty();
        if !checked_every_time && self.clean.contains(&config.name) {
            return true;
        }
        let Some(recorded) = self.record.assets.get(&config.name).map(|record| record.fingerprint) else {
            return false;
        };
        if self.current_fingerprint(config, all_assets, &HashMap::new(), 0) != Some(recorded) {
            return false;
        }
        if self.source_reading == SourceReading::WhenInvalidated && self.trusted_artifacts.contains(&config.name) {
            self.mark_clean(&config.name);
            return true;
        }
        let record = &self.record.assets[&config.name];
        let intact = record.artifacts.iter().all(|(path, stamp)| {
            let Some(entry) = manifest.artifacts.get(path).filter(|entry| entry.asset == config.name) else {
                return false;
            };
            let file = self.config.root.join(path);
            if self.options.verify {
                crate::sources::read_regular_file(&file, crate::sources::MAX_SOURCE_BYTES)
                    .is_ok_and(|bytes| blake3::hash(&bytes).to_hex().as_str() == entry.hash)
            } else {
                FileStamp::read(&file) == Some(*stamp)
            }
        });
        if intact {
            self.trusted_artifacts.insert(config.name.clone());
            self.mark_clean(&config.name);
        }
        intact
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
        let listed = self.asset_list_and_conflicts();
        let (all_assets, conflicts) = (&listed.0, &listed.1);
        for conflict in conflicts {
            tracing::warn!("{conflict}");
        }
        require_assets(&options.only_assets, all_assets, &self.config.file)?;
        self.keep_clean_for(&listed);
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
        let mut assets = Vec::new();
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
            let asset = self.sync_asset(config);
            assets.push((config.clone(), asset));
        }
        self.sync_registry(all_assets, &assets);
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
        let Some(finished) = finished.filter(|_| !cancel.is_raised()) else {
            self.keep_manifest(manifest);
            return Err(BuildError::Cancelled);
        };
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

        let run_index = RunIndex::new(&runs);
        let next_revision = manifest.revision.max(self.revision) + 1;
        let mut changed = options.always_new_revision;
        let mut changed_artifacts = Vec::new();
        let mut removed_artifacts = Vec::new();
        let mut summaries = Vec::new();
        let mut statuses = HashMap::new();
        // Every asset's files are put together before any is written: an edit meanwhile (a
        // folder of sources deleted) still cancels the build, and nothing of it is published.
        let mut all_outputs = Vec::with_capacity(assets.len());
        let mut asset_runs = runs_by_asset(&runs, assets.iter().map(|(config, _)| config.name.as_str()));
        for (config, asset) in &assets {
            if cancel.is_raised() {
                self.keep_manifest(manifest);
                return Err(BuildError::Cancelled);
            }
            let (mut errors, failed_jobs) = failures.remove(asset).unwrap_or_default();
            let folder = self.config.output.join(&config.name);
            let runs = asset_runs.remove(config.name.as_str()).unwrap_or_default();
            let outputs = asset.kind(&self.db).outputs(&self.db, *asset, &folder, &mut errors, &runs);
            all_outputs.push((errors, failed_jobs, folder, outputs));
        }
        if cancel.is_raised() {
            self.keep_manifest(manifest);
            return Err(BuildError::Cancelled);
        }
        // Each baked asset's fingerprint, of the files its input read.
        let built: HashMap<String, Asset> =
            assets.iter().map(|(config, asset)| (config.name.clone(), *asset)).collect();
        let fingerprints: Vec<Option<blake3::Hash>> =
            assets.iter().map(|(config, _)| self.current_fingerprint(config, all_assets, &built, 0)).collect();
        let writing = !assets.is_empty();
        if writing {
            crate::record::begin_writing(&output_dir);
        }
        for (((config, asset), (mut errors, failed_jobs, folder, outputs)), fingerprint) in
            assets.iter().zip(all_outputs).zip(fingerprints)
        {
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
            let listed = crate::artifacts::artifacts_of(&manifest, &config.name, &folder);
            if errors.is_empty() {
                // A fully baked asset owns exactly what it produced: drop stale artifacts.
                let stale = listed.iter().filter(|path| !produced.contains_key(*path)).cloned().collect();
                removed_artifacts.extend(remove_artifacts(&self.config, &mut manifest, stale));
            }
            let instances = kind.stage_instances(&self.db, *asset, &folder, &errors);
            let stages = stage_summaries(&instances, &run_index, !errors.is_empty(), &failed_jobs);
            for (instance, stage) in instances.iter().zip(&stages) {
                let state = stage.status.name();
                let ms = (stage.status == StageStatus::Ran).then_some((stage.ms * 10.0).round() / 10.0);
                statuses.insert(instance.node_id(), (state, ms));
            }
            // The record lets the next build pass over this asset while nothing it reads moves.
            self.record_changed = true;
            self.trusted_artifacts.remove(&config.name);
            match fingerprint.filter(|_| errors.is_empty()) {
                Some(fingerprint) => {
                    let artifacts = produced
                        .keys()
                        .filter_map(|path| Some((path.clone(), FileStamp::read(&self.config.root.join(path))?)))
                        .collect();
                    let files = asset.files(&self.db).keys().cloned().collect();
                    let records: Vec<InstanceRecord> = instances.iter().map(instance_record).collect();
                    let record = AssetRecord::new(fingerprint, files, artifacts, &records, warnings.clone());
                    self.record.assets.insert(config.name.clone(), record);
                    self.trusted_artifacts.insert(config.name.clone());
                    self.clean.remove(&config.name);
                    self.mark_clean(&config.name);
                }
                None => {
                    self.record.assets.remove(&config.name);
                    self.clean.remove(&config.name);
                }
            }
            summaries.push(AssetSummary {
                name: config.name.clone(),
                kind: kind.name(),
                status: if errors.is_empty() { AssetStatus::Ok } else { AssetStatus::Failed },
                stages,
                artifacts: asset_artifacts(&manifest, &config.name, listed.iter().chain(produced.keys())),
                errors: errors.iter().map(ErrorSummary::from).collect(),
                warnings,
                passed_over: false,
            });
        }
        for config in unchanged.iter().filter(|_| !options.omit_unchanged) {
            let record = &self.record.assets[&config.name];
            let listed =
                crate::artifacts::artifacts_of(&manifest, &config.name, &self.config.output.join(&config.name));
            let stages = record.stages().into_iter().map(|(stage, instance)| StageSummary {
                stage,
                instance,
                status: StageStatus::Cached,
                ms: 0.0,
            });
            summaries.push(AssetSummary {
                name: config.name.clone(),
                kind: AssetKind::of(&config.source).name(),
                status: AssetStatus::Ok,
                stages: stages.collect(),
                artifacts: asset_artifacts(&manifest, &config.name, listed.iter()),
                errors: Vec::new(),
                warnings: record.warnings.clone(),
                passed_over: true,
            });
        }
        if !options.omit_unchanged {
            // In the pipeline's order.
            let order: HashMap<&str, usize> =
                all_assets.iter().enumerate().map(|(index, config)| (config.name.as_str(), index)).collect();
            summaries.sort_by_key(|summary| order.get(summary.name.as_str()).copied());
        }
        let departures_unchecked = self.source_reading == SourceReading::EveryBuild
            || !self.departures_checked.as_ref().is_some_and(|checked| Arc::ptr_eq(checked, &listed));
        if options.only_assets.is_empty() && departures_unchecked && self.config.source_dir().is_dir() {
            // Artifacts of assets that left the pipeline (not of those that a vanished source
            // folder took along: they failed, and keep their last good artifacts). Only a new
            // asset list can have lost assets.
            self.departures_checked = Some(listed.clone());
            let names: HashSet<&str> = all_assets.iter().map(|asset| asset.name.as_str()).collect();
            let gone = manifest.artifacts.iter().filter(|(_, entry)| !names.contains(entry.asset.as_str()));
            let gone = gone.map(|(path, _)| path.clone()).collect();
            removed_artifacts.extend(remove_artifacts(&self.config, &mut manifest, gone));
        }
        // A failure is news too: its batch gets a revision of its own, so that a client that
        // subscribes after it (with `since` = the revision before) still hears of it.
        changed |=
            !removed_artifacts.is_empty() || summaries.iter().any(|summary| summary.status == AssetStatus::Failed);
        if changed && self.source_reading == SourceReading::WhenInvalidated {
            // The daemon: the manifest waits for an idle moment (`save_deferred`); the revision,
            // which must never be issued twice, is written now.
            manifest.revision = next_revision;
            self.manifest_unsaved = true;
            crate::record::save_revision(&output_dir, next_revision);
        } else if changed {
            manifest.revision = next_revision;
            if let Err(error) = save_manifest(&output_dir, &manifest) {
                // Without the manifest, the next build cannot tell its artifacts from the user's
                // files: every asset of this build fails, so scripts and CI notice.
                let file = display_path(&self.config.output.join("manifest.json"));
                tracing::error!("cannot write {file}: {error}");
                for summary in &mut summaries {
                    self.record.assets.remove(&summary.name);
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
        tracing::info!(
            "{} asset(s) passed over, {} looked into; {} source file(s) read",
            unchanged.len(),
            assets.len(),
            self.files_read
        );
        self.files_read = 0;
        self.unclaimed.clear();
        // (The daemon leaves files that no asset reads any more in the record: pruning costs a
        // pass over every file.)
        if options.only_assets.is_empty() && self.source_reading == SourceReading::EveryBuild {
            self.prune_record(all_assets);
        }
        // The daemon saves the record when it is idle (`save_record`): a record older than the
        // artifacts only costs the next start some checking.
        if self.source_reading == SourceReading::EveryBuild {
            self.save_record();
        }
        if writing {
            crate::record::end_writing(&output_dir);
        }
        if let Some(cache) = self.db.disk_cache() {
            // The assets passed over are named, not listed stage by stage.
            let passed_over: HashSet<&str> = unchanged.iter().map(|config| config.name.as_str()).collect();
            let assets = summaries
                .iter()
                .filter(|asset| !passed_over.contains(asset.name.as_str()))
                .map(|asset| crate::cache::upkeep::LastBuildAsset {
                    name: asset.name.clone(),
                    stages: asset
                        .stages
                        .iter()
                        .map(|stage| (stage_node_id(&stage.stage, &stage.instance), stage.status.name().to_string()))
                        .collect(),
                })
                .collect();
            let last = crate::cache::upkeep::LastBuild {
                revision: manifest.revision,
                counts: cache.take_counts(),
                remote: cache.remote().map(|remote| remote.settings().url.clone()),
                assets,
                unchanged: unchanged.iter().map(|config| config.name.clone()).collect(),
                misses: cache.take_misses(),
            };
            crate::cache::upkeep::write_last_build(cache.folder(), &last);
        }
        self.record_runs(&runs, manifest.revision);
        self.last_statuses = statuses;
        self.last_revision = Some(manifest.revision);
        changed_artifacts.sort_by(|a, b| a.path.cmp(&b.path));
        let revision = manifest.revision;
        self.keep_manifest(manifest);
        Ok(BuildSummary { revision, assets: summaries, changed: changed_artifacts, removed: removed_artifacts })
    }

    /// Writes what the daemon keeps in memory between idle moments: the manifest and the
    /// build record, each when it changed since it was last written.
    pub fn save_deferred(&mut self) {
        if self.manifest_unsaved {
            if let Some((_, manifest)) = self.manifest.take() {
                if let Err(error) = save_manifest(&self.config.output_dir(), &manifest) {
                    tracing::error!(
                        "cannot write {}: {error}",
                        display_path(&self.config.output.join("manifest.json"))
                    );
                }
                self.keep_manifest(manifest);
            }
            self.manifest_unsaved = false;
        }
        self.save_record();
    }

    /// Writes the build record when it changed since it was last written.
    fn save_record(&mut self) {
        if !self.record_changed || !self.options.persistent_cache {
            return;
        }
        match self.record.save(&self.config.output_dir()) {
            Ok(()) => self.record_changed = false,
            Err(error) => tracing::warn!(
                "cannot write {}: {error} (the next build hashes its sources again)",
                display_path(&crate::record::record_path(&self.config.output))
            ),
        }
    }

    /// The manifest on disk: the one kept when its file did not change since.
    fn take_manifest(&mut self) -> Manifest {
        let output_dir = self.config.output_dir();
        let stamp = FileStamp::read(&crate::artifacts::manifest_path(&output_dir));
        match self.manifest.take() {
            // Unsaved (the daemon's), or as the file still is.
            Some((_, manifest)) if self.manifest_unsaved => manifest,
            Some((kept, manifest)) if kept == stamp && stamp.is_some() => manifest,
            _ => load_manifest(&output_dir),
        }
    }

    /// Keeps the manifest as it is on disk now, for the next [`Project::take_manifest`].
    fn keep_manifest(&mut self, manifest: Manifest) {
        let stamp = FileStamp::read(&crate::artifacts::manifest_path(&self.config.output_dir()));
        self.manifest = Some((stamp, manifest));
    }

    /// Drops the record's assets that left the pipeline and the files no recorded asset reads.
    fn prune_record(&mut self, all_assets: &[AssetConfig]) {
        let names: HashSet<&str> = all_assets.iter().map(|asset| asset.name.as_str()).collect();
        let before = (self.record.assets.len(), self.record.files.len());
        self.record.assets.retain(|name, _| names.contains(name.as_str()));
        let read: HashSet<&PathBuf> = self.record.assets.values().flat_map(|asset| asset.files.iter()).collect();
        let files = std::mem::take(&mut self.record.files);
        self.record.files = files.into_iter().filter(|(path, _)| read.contains(path)).collect();
        self.record_changed |= before != (self.record.assets.len(), self.record.files.len());
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
        let contents = match self.unclaimed.remove(path).filter(|_| self.fresh.contains(path)) {
            Some(read) => read,
            None => {
                let seen_at = crate::record::now();
                self.files_read += 1;
                read_source_stamped(&self.config.root, &self.config.source, path).map(|(contents, stamp)| {
                    self.record_changed |= self.record.remember_file(path, stamp, contents.hash, seen_at);
                    contents
                })
            }
        };
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
        self.graph_of_assets(None)
    }

    /// [`Project::graph`] of the named assets only (all when `None`).
    pub fn graph_of_assets(&mut self, only: Option<&HashSet<String>>) -> crate::graph::Graph {
        use crate::graph::{GraphBuilder, Node, NodeKind};
        let mut graph = GraphBuilder::default();
        let manifest = self.take_manifest();
        let listed = self.asset_list_and_conflicts();
        self.keep_clean_for(&listed);
        let list = &listed.0;
        // An asset that the record holds as it is now: its instances from there; any other
        // through its kind (which may read its sources and run the stages that tell them).
        let mut all_instances: Vec<(String, Vec<InstanceRecord>)> = Vec::new();
        let mut synced = Vec::new();
        for config in list.iter().filter(|config| only.is_none_or(|only| only.contains(&config.name))) {
            if self.unchanged_asset(config, list, &manifest) {
                all_instances.push((config.name.clone(), self.record.assets[&config.name].instances()));
            } else {
                synced.push((config.clone(), self.sync_asset(config)));
            }
        }
        self.sync_registry(list, &synced);
        for (config, asset) in synced {
            let folder = self.config.output.join(&config.name);
            let instances = asset.kind(&self.db).stage_instances(&self.db, asset, &folder, &[]);
            all_instances.push((config.name, instances.iter().map(instance_record).collect()));
        }
        let runs = self.db.take_runs();
        self.record_runs(&runs, self.revision);
        for (asset, instances) in &all_instances {
            for instance in instances {
                let id = stage_node_id(&instance.stage, &instance.label);
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
                        ReadRecord::File(path) => self.file_node(&mut graph, path),
                        ReadRecord::Stage(id) => id.clone(),
                    };
                    graph.edge(&from, &id);
                }
                for artifact in &instance.writes {
                    let artifact = artifact.clone();
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
        self.keep_manifest(manifest);
        graph.finish()
    }

    /// Adds the node of a source file; returns its id.
    fn file_node(&self, graph: &mut crate::graph::GraphBuilder, path: &str) -> String {
        let id = path.to_string();
        let path = Path::new(path);
        let present = match self.files.get(path) {
            Some(file) => file.contents(&self.db).is_ok(),
            None => matches!(self.known.get(path), Some(Ok(_))) || self.record.files.contains_key(path),
        };
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

/// A stage instance as the record keeps it (owned names, reads as graph node ids).
fn instance_record(instance: &StageInstance) -> InstanceRecord {
    let reads = instance.reads.iter().map(|read| match read {
        Read::File(path) => ReadRecord::File(display_path(path)),
        Read::Stage(stage, label) => ReadRecord::Stage(stage_node_id(stage.name, label)),
    });
    InstanceRecord::new(
        instance.stage.name.to_string(),
        instance.label.clone(),
        instance.instance.clone(),
        reads.collect(),
        instance.writes.iter().map(|path| display_path(path)).collect(),
        instance.shared,
    )
}

/// What identifies this executable in fingerprints: its version and its file's size and
/// modification time, so that a rebuilt cirrus (whose stages may bake otherwise) trusts no
/// fingerprint an older one recorded. Unknown: a value no record holds.
fn executable_identity() -> blake3::Hash {
    let file = std::env::current_exe().ok().and_then(|path| Some((FileStamp::read(&path)?, path)));
    let text = match file {
        Some((stamp, path)) => {
            format!("{}|{}|{}|{}", env!("CARGO_PKG_VERSION"), path.display(), stamp.size, stamp.modified)
        }
        None => format!("unknown|{}", crate::record::now()),
    };
    blake3::hash(text.as_bytes())
}

/// The stage runs labelled by each asset's name or below it (`name/…`): what its kind's report
/// may time. One pass over the runs, each label looked up at each of its `/`.
fn runs_by_asset<'a>(runs: &[StageRun], names: impl Iterator<Item = &'a str>) -> HashMap<&'a str, Vec<StageRun>> {
    let names: HashSet<&str> = names.collect();
    let mut by_asset: HashMap<&str, Vec<StageRun>> = HashMap::new();
    for run in runs {
        let label = run.label.as_str();
        let prefixes = label.match_indices('/').map(|(at, _)| &label[..at]).chain([label]);
        if let Some(name) = prefixes.filter_map(|prefix| names.get(prefix)).next() {
            by_asset.entry(name).or_default().push(run.clone());
        }
    }
    by_asset
}

/// What a build's stage runs say of each stage instance (`(stage, label)`), gathered once per
/// build so that each asset's summary looks up only its own instances.
#[derive(Default)]
struct RunIndex<'a> {
    instances: HashMap<(&'a str, &'a str), InstanceRuns>,
}

#[derive(Clone, Copy, Default)]
struct InstanceRuns {
    /// Milliseconds of the bodies that ran (not from a cache).
    ran_ms: Option<f64>,
    local_hit: bool,
    remote_hit: bool,
}

impl<'a> RunIndex<'a> {
    fn new(runs: &'a [StageRun]) -> RunIndex<'a> {
        let mut index = RunIndex::default();
        for run in runs {
            let entry = index.instances.entry((run.stage, run.label.as_str())).or_default();
            match (run.from_cache, run.from_remote) {
                (false, _) => *entry.ran_ms.get_or_insert(0.0) += run.ms,
                (true, true) => entry.remote_hit = true,
                (true, false) => entry.local_hit = true,
            }
        }
        index
    }

    fn get(&self, instance: &StageInstance) -> InstanceRuns {
        self.instances.get(&(instance.stage.name, instance.label.as_str())).copied().unwrap_or_default()
    }
}

/// The summary of each stage instance: ran when this build ran it, failed when the asset
/// failed before it had a result (its kind says, or its job failed), remote when its result
/// came from the shared cache, cached otherwise. A stage that needed no result of its own
/// (what it feeds was found in a cache) is remote when every cache hit of its asset in this
/// build came from the shared cache, and cached otherwise.
fn stage_summaries(
    instances: &[StageInstance],
    runs: &RunIndex,
    asset_failed: bool,
    failed_jobs: &HashSet<String>,
) -> Vec<StageSummary> {
    let facts: Vec<InstanceRuns> = instances.iter().map(|instance| runs.get(instance)).collect();
    let any_hit = facts.iter().any(|facts| facts.local_hit || facts.remote_hit);
    let every_hit_remote = any_hit && !facts.iter().any(|facts| facts.local_hit);
    instances
        .iter()
        .zip(facts)
        .map(|(instance, facts)| {
            let (status, ms) = match facts.ran_ms {
                Some(ms) => (StageStatus::Ran, ms),
                None if asset_failed && (instance.failed || failed_jobs.contains(&instance.label)) => {
                    (StageStatus::Failed, 0.0)
                }
                None if !facts.local_hit && (facts.remote_hit || every_hit_remote) => (StageStatus::Remote, 0.0),
                None => (StageStatus::Cached, 0.0),
            };
            StageSummary { stage: instance.stage.name.to_string(), instance: instance.instance.clone(), status, ms }
        })
        .collect()
}

/// The artifacts the manifest lists for an asset, of the `paths` that may be its (sorted).
fn asset_artifacts<'a>(
    manifest: &Manifest,
    asset: &str,
    paths: impl Iterator<Item = &'a String>,
) -> Vec<ArtifactSummary> {
    let paths: BTreeSet<&String> = paths.collect();
    let entries = paths.into_iter().filter_map(|path| Some((path, manifest.artifacts.get(path)?)));
    let entries = entries.filter(|(_, entry)| entry.asset == asset);
    entries.map(|(path, entry)| ArtifactSummary { path: path.clone(), hash: entry.hash.clone() }).collect()
}

/// The graph node id of a source file.
pub fn file_node_id(path: &Path) -> String {
    display_path(path)
}
