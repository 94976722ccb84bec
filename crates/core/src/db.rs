//! The database, which names no kind: source files and assets as salsa inputs, the stage
//! vocabulary (`Stage`, `StageRun`: what ran, under which instance label), the shared decode
//! stage, the boundary to the persistent cache (`cached_json`, key helpers), and the database
//! with its run log and the previous encodings that let a surface's next encode reuse blocks.

use std::any::Any;
use std::collections::{BTreeMap, HashMap};
use std::fmt;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::Instant;

use crate::cache::{CacheEntry, CacheKey, CacheKeyBuilder, DiskCache};
use crate::config::AssetKind;
use crate::config::Settings;
use crate::diagnostic::{display_path, Diagnostic};
use crate::texture::{decode_texture, Texture};

/// The bytes of a source file and their blake3 hash. Equality is by hash.
///
/// The bytes may be let go (`release`) once no stage in memory needs them, and are read back from
/// the file when a stage asks again ([`FileContents::bytes`]): the hash, which is what salsa
/// compares, stays. Clones share the bytes.
#[derive(Clone)]
pub struct FileContents {
    pub hash: blake3::Hash,
    /// How many bytes the file holds.
    pub len: u64,
    bytes: Arc<Mutex<Option<Arc<[u8]>>>>,
    /// The file to read the bytes back from (none: they cannot be let go).
    origin: Option<PathBuf>,
    /// Whether reading them back failed once (a stage that asked then failed, and its error is
    /// memoized: the driver sets the file's input anew, even to equal bytes, so that it runs again).
    read_back_failed: Arc<std::sync::atomic::AtomicBool>,
}

impl FileContents {
    pub fn new(bytes: Vec<u8>) -> FileContents {
        let hash = blake3::hash(&bytes);
        let len = bytes.len() as u64;
        let bytes = Arc::new(Mutex::new(Some(bytes.into())));
        FileContents { hash, len, bytes, origin: None, read_back_failed: Arc::default() }
    }

    /// The bytes read from `origin` (an absolute path), which may be let go and read back.
    pub fn from_file(bytes: Vec<u8>, origin: PathBuf) -> FileContents {
        FileContents { origin: Some(origin), ..FileContents::new(bytes) }
    }

    /// The bytes: those kept, else read back from the file. The driver reads back every file of
    /// the assets it bakes before their stages run, so a stage reads from disk only where a
    /// query reaches past them; a file gone or changed meanwhile fails the stage that asked,
    /// with a diagnostic naming it (the watcher's event, or the next build, bakes it again).
    pub fn bytes(&self) -> Result<Arc<[u8]>, Diagnostic> {
        let mut kept = self.bytes.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
        if let Some(bytes) = &*kept {
            return Ok(bytes.clone());
        }
        let origin = self.origin.as_ref().expect("bytes without a file are never let go");
        let failed = |message: String| {
            self.read_back_failed.store(true, std::sync::atomic::Ordering::Relaxed);
            Diagnostic::new(origin, message)
        };
        let read = crate::files::read_regular_file_with_metadata(origin, crate::files::MAX_SOURCE_BYTES)
            .map_err(|why| failed(format!("cannot read it again: {why}")))?
            .0;
        if blake3::hash(&read) != self.hash {
            return Err(failed("changed while it was being baked; the next build bakes it again".to_string()));
        }
        let bytes: Arc<[u8]> = read.into();
        *kept = Some(bytes.clone());
        Ok(bytes)
    }

    /// Lets go of the bytes (when they came from a file): the next [`FileContents::bytes`] reads
    /// them back.
    pub fn release(&self) {
        if self.origin.is_some() {
            *self.bytes.lock().unwrap_or_else(|poisoned| poisoned.into_inner()) = None;
        }
    }

    /// Whether reading the bytes back ever failed (see `read_back_failed`).
    pub fn read_back_failed(&self) -> bool {
        self.read_back_failed.load(std::sync::atomic::Ordering::Relaxed)
    }

    /// Whether the bytes are in memory now.
    pub fn is_kept(&self) -> bool {
        self.bytes.lock().unwrap_or_else(|poisoned| poisoned.into_inner()).is_some()
    }
}

impl PartialEq for FileContents {
    fn eq(&self, other: &Self) -> bool {
        self.hash == other.hash
    }
}

impl Eq for FileContents {}

impl fmt::Debug for FileContents {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "FileContents({} bytes, {})", self.len, &self.hash.to_hex()[..12])
    }
}

/// A file's contents, or why it could not be read.
pub type FileRead = Result<FileContents, crate::files::ReadError>;

/// Pipeline-wide limits, one per database (set by the driver from `pipeline.ron`).
#[salsa::input(singleton, debug)]
pub struct PipelineLimits {
    #[returns(copy)]
    pub texture: crate::texture::TextureLimits,
}

/// The texture limits in force (the defaults before the driver set any).
pub fn texture_limits(db: &dyn Db) -> crate::texture::TextureLimits {
    PipelineLimits::try_get(db).map_or_else(Default::default, |limits| limits.texture(db))
}

/// The pipeline's source folder, relative to its project folder (set by the driver, one per
/// database): cache keys and cached values hold paths relative to it, so that the same project
/// with its source folder named otherwise shares every entry.
#[salsa::input(singleton, debug)]
pub struct SourceFolder {
    #[returns(ref)]
    pub path: PathBuf,
}

/// The source folder in force (empty before the driver set one).
pub fn source_folder(db: &dyn Db) -> PathBuf {
    SourceFolder::try_get(db).map_or_else(PathBuf::new, |folder| folder.path(db).clone())
}

/// `path` (project-relative) relative to the source folder, as cache keys name files.
pub fn source_relative(db: &dyn Db, path: &std::path::Path) -> PathBuf {
    let folder = source_folder(db);
    path.strip_prefix(&folder).map_or_else(|_| path.to_path_buf(), std::path::Path::to_path_buf)
}

/// Cached values name files relative to the source folder: `$source/…` in a JSON string stands
/// for the source folder of whoever reads the entry.
const SOURCE_PLACEHOLDER: &str = "$source";

/// `value` with every string that is the source folder's path, or a path below it, written
/// with the placeholder instead of the folder (`to_placeholder`), or back (`from_placeholder`).
fn relocate(value: &mut serde_json::Value, from: &str, to: &str) {
    let moved = |text: &str| -> Option<String> {
        if text == from {
            Some(to.to_string())
        } else {
            text.strip_prefix(from).filter(|rest| rest.starts_with('/')).map(|rest| format!("{to}{rest}"))
        }
    };
    match value {
        serde_json::Value::String(text) => {
            if let Some(moved) = moved(text) {
                *text = moved;
            }
        }
        serde_json::Value::Array(items) => items.iter_mut().for_each(|item| relocate(item, from, to)),
        serde_json::Value::Object(fields) => {
            // Maps keyed by path serialise their keys as strings too.
            if fields.keys().any(|key| moved(key).is_some()) {
                *fields = std::mem::take(fields)
                    .into_iter()
                    .map(|(key, field)| (moved(&key).unwrap_or(key), field))
                    .collect();
            }
            fields.values_mut().for_each(|field| relocate(field, from, to));
        }
        _ => {}
    }
}

/// A hash of `value` as JSON with paths relative to the source folder (for a key part made of
/// a stage result that names files).
pub fn relocatable_hash(db: &dyn Db, value: &impl serde::Serialize) -> blake3::Hash {
    let mut json = serde_json::to_value(value).expect("stage results serialise");
    let folder = display_path(&source_folder(db));
    if !folder.is_empty() {
        relocate(&mut json, &folder, SOURCE_PLACEHOLDER);
    }
    blake3::hash(json.to_string().as_bytes())
}

fn to_placeholder(folder: &std::path::Path, entry: &mut CacheEntry) {
    let folder = display_path(folder);
    if !folder.is_empty() {
        relocate(&mut entry.metadata, &folder, SOURCE_PLACEHOLDER);
    }
}

fn from_placeholder(folder: &std::path::Path, entry: &mut CacheEntry) {
    let folder = display_path(folder);
    if !folder.is_empty() {
        relocate(&mut entry.metadata, SOURCE_PLACEHOLDER, &folder);
    }
}

/// A source file; `path` is relative to the folder of `pipeline.ron`.
#[salsa::input(debug)]
pub struct SourceFile {
    #[returns(ref)]
    pub path: PathBuf,
    #[returns(ref)]
    pub contents: FileRead,
}

/// An asset of any kind: its settings and every source file it reads (the driver reads the
/// files its kind asks for, and asks again until nothing new turns up).
#[salsa::input(debug)]
pub struct Asset {
    #[returns(ref)]
    pub name: String,
    #[returns(copy)]
    pub kind: AssetKind,
    /// The source folder (relative to the project) that referenced files must stay inside.
    #[returns(ref)]
    pub source_root: PathBuf,
    /// The file the pipeline names (`material:`, `mesh:`), project-relative.
    #[returns(ref)]
    pub main_file: PathBuf,
    #[returns(ref)]
    pub settings: Settings,
    /// Every file read for this asset, by project-relative path.
    #[returns(ref)]
    pub files: Arc<BTreeMap<PathBuf, SourceFile>>,
    /// For each glob list of the asset's source (`AssetSource::glob_lists`: kinds that name
    /// their sources by glob), the files below the source folder that match it,
    /// project-relative and sorted: the driver lists them.
    #[returns(ref)]
    pub listed: Arc<Vec<Vec<PathBuf>>>,
}

/// The assets of the build by name, for an asset that reads another's output (a `Material`'s
/// `ao_source`): set by the driver, one per database.
#[salsa::input(singleton, debug)]
pub struct AssetRegistry {
    #[returns(ref)]
    pub assets: Arc<BTreeMap<String, Asset>>,
}

/// The asset of the build named `name`, if any.
pub fn asset_named(db: &dyn Db, name: &str) -> Option<Asset> {
    AssetRegistry::try_get(db).and_then(|registry| registry.assets(db).get(name).copied())
}

/// The input of one file the asset read (cuts off when other files join or leave the asset).
#[salsa::tracked(returns(copy))]
pub fn asset_file(db: &dyn Db, asset: Asset, path: PathBuf) -> Option<SourceFile> {
    asset.files(db).get(&path).copied()
}

/// Whether a file could be read: a stage that needs only that (not the bytes) is left alone by
/// edits of the file.
#[salsa::tracked(returns(copy))]
pub fn file_readable(db: &dyn Db, file: SourceFile) -> bool {
    file.contents(db).is_ok()
}

/// Why a file could not be read (none: it could), with the same firewall as [`file_readable`]:
/// an edit of a readable file changes nothing here.
#[salsa::tracked(returns(clone))]
pub fn file_read_error(db: &dyn Db, file: SourceFile) -> Option<String> {
    file.contents(db).as_ref().err().map(ToString::to_string)
}

pub fn read_contents(db: &dyn Db, file: SourceFile) -> Result<&FileContents, Diagnostic> {
    file.contents(db).as_ref().map_err(|error| Diagnostic::new(file.path(db), error.clone()))
}

/// A user-facing stage: its name (in summaries, the graph and the event log) and the version
/// that enters its cache keys. Bump the version whenever its output changes for the same inputs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Stage {
    pub name: &'static str,
    pub version: u32,
}

/// Decoding a source image (shared by every asset that reads the file).
pub const DECODE: Stage = Stage { name: "decode", version: 1 };

/// One execution of a stage body in this process.
#[derive(Clone, Debug, PartialEq)]
pub struct StageRun {
    pub stage: &'static str,
    /// The stage instance, as its kind labels it (`first/one/mra`, `tree/plane3:bark`).
    pub label: String,
    pub ms: f64,
    /// When the body began (for the wall time that runs in parallel span together).
    pub started: Instant,
    /// The result came from the persistent cache; the stage itself did no work.
    pub from_cache: bool,
    /// That result came from the shared store (the local cache did not have it).
    pub from_remote: bool,
}

#[derive(Default)]
struct Logs {
    runs: Mutex<Vec<StageRun>>,
}

#[salsa::db]
pub trait Db: salsa::Database {
    fn disk_cache(&self) -> Option<&DiskCache>;
    fn record_run(&self, run: StageRun);
    /// What a stage kept of its last run in this process under `name` (see [`recall`]).
    fn recalled(&self, name: &str) -> Option<Arc<dyn Any + Send + Sync>>;
    fn remember(&self, name: &str, value: Arc<dyn Any + Send + Sync>);
    /// Drops what [`Db::remember`] kept under `name`.
    fn forget(&self, name: &str);
    /// What the process keeps of `asset`'s build beyond its outputs.
    fn retention(&self, asset: Asset) -> Retention;
}

/// What a process keeps in memory of a build beyond its outputs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Retention {
    /// The intermediates a next build reuses (surface images, mip chains, blocks, the last
    /// encodings, decoded maps): the daemon, and any project that builds again.
    #[default]
    KeepForNextBuild,
    /// Only what the build publishes: `cirrus build`, whose process ends with the build (a next
    /// process finds the last encodings in the persistent cache). The surface job makes what it
    /// needs outside salsa's memos (its reads still go through tracked queries, so it reruns when
    /// they change) and drops it with the files: a many-texture build's memory grows by each
    /// texture's source bytes and files, not by its intermediates.
    OutputsOnly,
}

#[salsa::db]
#[derive(Clone)]
pub struct Database {
    storage: salsa::Storage<Self>,
    cache: Option<DiskCache>,
    logs: Arc<Logs>,
    memos: Arc<Mutex<HashMap<String, Arc<dyn Any + Send + Sync>>>>,
    retention: Retention,
    /// With `KeepForNextBuild`: the assets whose intermediates are kept (all when `None`); the
    /// others are baked as `OutputsOnly` bakes them (the driver's memory policy).
    kept: Arc<std::sync::RwLock<Option<std::collections::HashSet<Asset>>>>,
}

impl Database {
    pub fn new(cache: Option<DiskCache>) -> Database {
        Database::with_retention(cache, Retention::default())
    }

    pub fn with_retention(cache: Option<DiskCache>, retention: Retention) -> Database {
        Database {
            storage: salsa::Storage::default(),
            cache,
            logs: Arc::default(),
            memos: Arc::default(),
            retention,
            kept: Arc::default(),
        }
    }

    /// Keeps the intermediates of `assets` only (of every asset when `None`) from now on, where
    /// the database keeps any, and forgets the memos (see [`remember`]) of the assets named in
    /// `dropped`. Salsa's memos of those assets go as their functions' LRU evicts them.
    pub fn keep_only(&self, assets: Option<std::collections::HashSet<Asset>>, dropped: &[String]) {
        *self.kept.write().unwrap_or_else(|poisoned| poisoned.into_inner()) = assets;
        let mut memos = self.memos.lock().expect("memo lock");
        // A memo's name is `kind:identity`, and a surface's identity starts with its asset's name.
        let folders: Vec<String> = dropped.iter().map(|asset| format!("{asset}/")).collect();
        memos.retain(|name, _| {
            let identity = name.split_once(':').map_or(name.as_str(), |(_, identity)| identity);
            let of_dropped = |(asset, folder): (&String, &String)| identity == asset || identity.starts_with(folder);
            !dropped.iter().zip(&folders).any(of_dropped)
        });
    }

    /// Uses another persistent cache from now on (the pipeline's output or shared cache changed).
    pub fn replace_disk_cache(&mut self, cache: Option<DiskCache>) {
        self.cache = cache;
    }

    /// The names of what stages keep in memory for their next run (see [`remember`]), sorted.
    pub fn kept_memos(&self) -> Vec<String> {
        let mut names: Vec<String> = self.memos.lock().expect("memo lock").keys().cloned().collect();
        names.sort();
        names
    }

    /// The stage bodies that ran since the last call, with their durations.
    pub fn take_runs(&self) -> Vec<StageRun> {
        std::mem::take(&mut *self.logs.runs.lock().expect("log lock"))
    }
}

#[salsa::db]
impl salsa::Database for Database {}

#[salsa::db]
impl Db for Database {
    fn disk_cache(&self) -> Option<&DiskCache> {
        self.cache.as_ref()
    }

    fn record_run(&self, run: StageRun) {
        self.logs.runs.lock().expect("log lock").push(run);
    }

    fn recalled(&self, name: &str) -> Option<Arc<dyn Any + Send + Sync>> {
        self.memos.lock().expect("memo lock").get(name).cloned()
    }

    fn remember(&self, name: &str, value: Arc<dyn Any + Send + Sync>) {
        self.memos.lock().expect("memo lock").insert(name.to_string(), value);
    }

    fn forget(&self, name: &str) {
        self.memos.lock().expect("memo lock").remove(name);
    }

    fn retention(&self, asset: Asset) -> Retention {
        match self.retention {
            Retention::OutputsOnly => Retention::OutputsOnly,
            Retention::KeepForNextBuild => {
                let kept = self.kept.read().unwrap_or_else(|poisoned| poisoned.into_inner());
                match &*kept {
                    Some(kept) if !kept.contains(&asset) => Retention::OutputsOnly,
                    _ => Retention::KeepForNextBuild,
                }
            }
        }
    }
}

/// A memo's key: its kind (`encoding-memo`) and identity (a surface's label), and the type of
/// what it holds, so that a memo is read back as what was kept under it.
pub struct Memo<T> {
    name: String,
    holds: std::marker::PhantomData<fn() -> T>,
}

impl<T: Any + Send + Sync> Memo<T> {
    pub fn new(kind: &str, identity: impl std::fmt::Display) -> Memo<T> {
        Memo { name: format!("{kind}:{identity}"), holds: std::marker::PhantomData }
    }

    /// `kind:identity`, as the memo's disk entries name it too.
    pub fn name(&self) -> &str {
        &self.name
    }
}

/// What a stage kept of its last run in this process (its last encoding, layout or page).
/// Salsa does not track these memos: a stage reads one to do less work for the same result,
/// or (the atlas layout) as the hint its design asks for.
pub fn recall<T: Any + Send + Sync>(db: &dyn Db, memo: &Memo<T>) -> Option<Arc<T>> {
    db.recalled(&memo.name)?.downcast::<T>().ok()
}

/// Keeps `value` for the next run of the stage (see [`recall`]).
pub fn remember<T: Any + Send + Sync>(db: &dyn Db, memo: &Memo<T>, value: Arc<T>) {
    db.remember(&memo.name, value);
}

/// Drops what was kept under `memo`.
pub fn forget<T: Any + Send + Sync>(db: &dyn Db, memo: &Memo<T>) {
    db.forget(&memo.name);
}

/// Runs a stage body, timing it and recording the run under `label`.
pub fn timed<T>(db: &dyn Db, stage: Stage, label: &str, body: impl FnOnce() -> T) -> T {
    // A remote hit on the way to running is not this stage's result.
    crate::cache::take_remote_hit();
    let start = Instant::now();
    let result = body();
    let ms = start.elapsed().as_secs_f64() * 1000.0;
    // With its end time from the log's clock: where each stage ran, for the schedule's profile.
    tracing::debug!("stage {} {label} ran {ms:.1} ms", stage.name);
    db.record_run(StageRun {
        stage: stage.name,
        label: label.to_string(),
        ms,
        started: start,
        from_cache: false,
        from_remote: false,
    });
    result
}

/// Runs one body that does the work of several instances of a stage (`labels`, each with its
/// share of the work), recording a run for each with its share of the time.
pub fn timed_together<T>(db: &dyn Db, stage: Stage, labels: &[(String, f64)], body: impl FnOnce() -> T) -> T {
    crate::cache::take_remote_hit();
    let start = Instant::now();
    let result = body();
    let ms = start.elapsed().as_secs_f64() * 1000.0;
    tracing::debug!("stage {} ({} instances together) ran {ms:.1} ms", stage.name, labels.len());
    let total: f64 = labels.iter().map(|(_, share)| share).sum();
    for (label, share) in labels {
        db.record_run(StageRun {
            stage: stage.name,
            label: label.clone(),
            ms: if total > 0.0 { ms * share / total } else { ms / labels.len() as f64 },
            started: start,
            from_cache: false,
            from_remote: false,
        });
    }
    result
}

/// Records that a stage's result came from the persistent cache, and whether the shared store
/// Runs long `work` that asks its [`ShouldStop`](crate::stop::ShouldStop) between units (points,
/// batches of rays): a cancellation of this database (a newer edit under `watch`) stops it within
/// a unit, and the query unwinds as salsa's cancellation does, leaving no result behind.
pub fn stoppable<T>(db: &dyn Db, work: impl FnOnce(crate::stop::ShouldStop) -> Result<T, crate::stop::Stopped>) -> T {
    let token = db.cancellation_token();
    let should_stop = move || token.is_cancelled();
    match work(&should_stop) {
        Ok(value) => value,
        Err(crate::stop::Stopped) => {
            db.unwind_if_revision_cancelled();
            std::panic::resume_unwind(Box::new(salsa::Cancelled::Local))
        }
    }
}

/// served it (a load on this thread since the last record, see `cache::take_remote_hit`).
pub fn record_cache_hit(db: &dyn Db, stage: Stage, label: &str) {
    let from_remote = crate::cache::take_remote_hit();
    db.record_run(StageRun {
        stage: stage.name,
        label: label.to_string(),
        ms: 0.0,
        started: Instant::now(),
        from_cache: true,
        from_remote,
    });
}

/// Bounds the decoded textures kept to the `files` used last (see `tail_queries::keep_memos`).
pub fn keep_decoded(db: &mut dyn Db, files: usize) {
    decoded_texture::set_lru_capacity(db, files);
    opacity_texture::set_lru_capacity(db, files);
}

/// A source texture decoded to RGBA8 (the decode stage, labelled by the file's path).
#[salsa::tracked(returns(clone), lru = 0)]
pub fn decoded_texture(db: &dyn Db, file: SourceFile) -> Result<Arc<Texture>, Diagnostic> {
    decode_source(db, file)
}

/// A source texture decoded for a surface that is made from it: memoized where the process
/// builds again, else decoded for this use and dropped once the surface is made (a file that
/// feeds several surfaces is then decoded by each: see [`Retention::OutputsOnly`]).
pub fn decoded_for_surface(db: &dyn Db, asset: Asset, file: SourceFile) -> Result<Arc<Texture>, Diagnostic> {
    match db.retention(asset) {
        Retention::KeepForNextBuild => decoded_texture(db, file),
        Retention::OutputsOnly => decode_source(db, file),
    }
}

fn decode_source(db: &dyn Db, file: SourceFile) -> Result<Arc<Texture>, Diagnostic> {
    let contents = read_contents(db, file)?;
    let limits = texture_limits(db);
    let path = file.path(db);
    timed(db, DECODE, &display_path(path), || decode_texture(path, &contents.bytes()?, limits).map(Arc::new))
}

/// A source texture as an opacity map (alpha if it has transparency, else red), decoded once.
#[salsa::tracked(returns(clone), lru = 0)]
pub fn opacity_texture(db: &dyn Db, file: SourceFile) -> Result<Arc<Texture>, Diagnostic> {
    let texture = decoded_texture(db, file)?;
    Ok(Arc::new(crate::texture::opacity_channel(&texture)))
}

// ---------------------------------------------------------------------------------------------
// the persistent cache boundary

pub fn load_cached<T>(
    db: &dyn Db,
    entry: &str,
    key: CacheKey,
    decode: impl FnOnce(CacheEntry) -> Option<T>,
) -> Option<T> {
    let mut loaded = db.disk_cache()?.load(entry, key)?;
    from_placeholder(&source_folder(db), &mut loaded);
    decode(loaded)
}

pub fn store_cached(db: &dyn Db, entry: &str, key: CacheKey, make: impl FnOnce() -> CacheEntry) {
    if let Some(cache) = db.disk_cache() {
        let mut made = make();
        to_placeholder(&source_folder(db), &mut made);
        cache.store(entry, key, made);
    }
}

/// Like `store_cached`, but the entry is also made on the cache's background thread (`make`
/// owns what it needs: `Arc`s of the images it gathers).
pub fn store_cached_in_background(
    db: &dyn Db,
    entry: &str,
    key: CacheKey,
    make: impl FnOnce() -> CacheEntry + Send + 'static,
) {
    if let Some(cache) = db.disk_cache() {
        let folder = source_folder(db);
        cache.store_in_background(entry, key, move || {
            let mut made = make();
            to_placeholder(&folder, &mut made);
            made
        });
    }
}

/// A stage result stored as JSON metadata under the stage's name (parsed materials, plane sets,
/// layouts: small, exact with `float_roundtrip`): loaded (a cache hit of `stage` for `label`), or
/// computed and stored.
pub fn cached_json<T: serde::Serialize + serde::de::DeserializeOwned>(
    db: &dyn Db,
    stage: Stage,
    label: &str,
    key: CacheKey,
    compute: impl FnOnce() -> Result<T, Diagnostic>,
) -> Result<T, Diagnostic> {
    if let Some(value) = load_cached(db, stage.name, key, |entry| entry.parts::<T, 0>().map(|(value, [])| value)) {
        record_cache_hit(db, stage, label);
        return Ok(value);
    }
    let value = compute()?;
    store_cached(db, stage.name, key, || CacheEntry::new(&value, Vec::new(), true));
    Ok(value)
}

/// A key builder for `stage` (its name and version).
pub fn stage_key(stage: Stage) -> CacheKeyBuilder {
    CacheKeyBuilder::new(stage.name, stage.version)
}

/// Adds each file's path (relative to the source folder) and its content hash (or why it could
/// not be read) to a key.
pub fn key_with_files(
    db: &dyn Db,
    key: CacheKeyBuilder,
    files: impl IntoIterator<Item = SourceFile>,
) -> CacheKeyBuilder {
    files.into_iter().fold(key, |key, file| {
        let key = key.part(&source_relative(db, file.path(db)));
        match file.contents(db) {
            Ok(contents) => key.part(&contents.hash),
            Err(error) => key.part(&error.to_string()),
        }
    })
}

/// Plain values as raw bytes, for cache blobs (little-endian on every machine cirrus runs on).
/// A stage result compared by the hash of what it was made from (a BVH, a tessellated mesh):
/// exact, cheap equality for salsa's early cutoff on a value that has none of its own.
pub struct ByHash<T> {
    pub hash: blake3::Hash,
    pub value: T,
}

impl<T> PartialEq for ByHash<T> {
    fn eq(&self, other: &Self) -> bool {
        self.hash == other.hash
    }
}

impl<T> fmt::Debug for ByHash<T> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "ByHash({})", &self.hash.to_hex()[..12])
    }
}

/// The blake3 of a list of byte strings, each prefixed by its length, so that no two lists
/// hash alike by moving bytes from one part to the next.
pub fn hash_of_parts(parts: &[&[u8]]) -> blake3::Hash {
    let mut hasher = blake3::Hasher::new();
    for part in parts {
        hasher.update(&(part.len() as u64).to_le_bytes());
        hasher.update(part);
    }
    hasher.finalize()
}

pub fn pod_blob<T: bytemuck::Pod>(values: &[T]) -> Vec<u8> {
    bytemuck::cast_slice(values).to_vec()
}

pub fn from_pod_blob<T: bytemuck::Pod>(bytes: &[u8]) -> Option<Vec<T>> {
    bytes.len().is_multiple_of(std::mem::size_of::<T>()).then(|| bytemuck::pod_collect_to_vec(bytes))
}
