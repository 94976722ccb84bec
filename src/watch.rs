//! `cirrus watch`: the daemon. The only module that touches `notify`. One thread (the caller's)
//! owns the project and its database and is the only writer; builds run on database clones on
//! worker threads, and a relevant edit during a build cancels it (salsa cancellation) so that the
//! next build starts from the newest inputs. Each finished build is logged and published to the
//! hot-reload server.

use std::collections::BTreeSet;
use std::io::Write as _;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::sync::mpsc::channel;
use std::sync::{Arc, RwLock};
use std::time::{Duration, Instant};

use notify::{EventKind, RecursiveMode};
use notify_debouncer_full::{new_debouncer, DebounceEventResult};

use crate::config::{ConfigError, PipelineConfig};
use crate::diagnostic::display_path;
use crate::pipeline::load_pipeline;
use crate::project::batch::{BatchHooks, BatchOutcome, BatchRequest};
use crate::project::{CancelFlag, Project, ProjectOptions, SourceReading};
use crate::server::{BatchEvent, FailedEntry, Server, ServerSettings};
use crate::summary::{AssetStatus, BuildSummary, StageStatus};

/// How the daemon runs.
#[derive(Clone, Debug)]
pub struct WatchSettings {
    pub pipeline: PathBuf,
    /// Overrides `server` of `pipeline.ron`.
    pub listen: Option<SocketAddr>,
    /// Web pages allowed to open a WebSocket besides loopback ones (`--allow-origin`).
    pub allowed_origins: Vec<String>,
    /// The debouncer's window: events closer than this become one batch.
    pub debounce: Duration,
    /// Stop after this many finished builds (tests and benchmarks); run forever when `None`.
    pub max_builds: Option<u64>,
    /// The command line's word on the shared cache.
    pub remote_cache: crate::cache::remote::RemoteCacheOverride,
    /// The command line's memory budget in bytes (`--memory-mib`).
    pub memory_budget: Option<u64>,
}

#[derive(Debug, thiserror::Error)]
pub enum WatchError {
    #[error(transparent)]
    Config(#[from] ConfigError),
    #[error(transparent)]
    Server(#[from] crate::server::ServerError),
    #[error("cannot watch {path}: {source}")]
    Watch { path: String, source: notify::Error },
    #[error("cannot resolve the project folder {path}: {source}")]
    Root { path: String, source: std::io::Error },
    #[error(
        "another `cirrus watch` ({holder}) bakes into {folder}: two daemons would issue the same revisions for \
        different batches; stop that one first"
    )]
    Locked { folder: String, holder: String },
    #[error("cannot lock the output folder {folder}: {source}")]
    Lock { folder: String, source: std::io::Error },
}

/// The daemon's hold on its output folder: `<output>/.cirrus/watch.lock`, locked (`flock`) for
/// as long as the daemon runs, holding its process id and server address for the next one to
/// name. The lock goes with the process, however it ends.
struct OutputLock {
    file: std::fs::File,
}

impl OutputLock {
    fn take(output: &Path) -> Result<OutputLock, WatchError> {
        use std::io::Read as _;
        let folder = display_path(output);
        let lock_error = |source| WatchError::Lock { folder: folder.clone(), source };
        let state = output.join(".cirrus");
        std::fs::create_dir_all(&state).map_err(lock_error)?;
        let mut file = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(state.join("watch.lock"))
            .map_err(lock_error)?;
        if !try_lock(&file).map_err(lock_error)? {
            let mut holder = String::new();
            let _ = file.read_to_string(&mut holder);
            let holder = holder.lines().collect::<Vec<_>>().join(", ");
            let holder = if holder.is_empty() { "starting".to_string() } else { holder };
            return Err(WatchError::Locked { folder, holder });
        }
        let mut lock = OutputLock { file };
        lock.describe(None);
        Ok(lock)
    }

    /// Writes who holds the lock: this process, and its server's address once it listens.
    fn describe(&mut self, address: Option<SocketAddr>) {
        use std::io::{Seek as _, Write as _};
        let mut text = format!("pid {}", std::process::id());
        if let Some(address) = address {
            text.push_str(&format!("\nlistening on {address}"));
        }
        let _ = self.file.set_len(0);
        let _ = self.file.seek(std::io::SeekFrom::Start(0));
        let _ = self.file.write_all(text.as_bytes());
    }
}

/// Takes an exclusive advisory lock on `file` without waiting: false when another holds it.
#[cfg(unix)]
fn try_lock(file: &std::fs::File) -> std::io::Result<bool> {
    use std::os::fd::AsRawFd;
    // SAFETY: flock on a descriptor this process owns; no memory is passed.
    if unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) } == 0 {
        return Ok(true);
    }
    let error = std::io::Error::last_os_error();
    if error.raw_os_error() == Some(libc::EWOULDBLOCK) {
        Ok(false)
    } else {
        Err(error)
    }
}

/// Elsewhere the folder is not locked (two daemons there are the user's to avoid).
#[cfg(not(unix))]
fn try_lock(_file: &std::fs::File) -> std::io::Result<bool> {
    Ok(true)
}

/// What the watcher thread needs to tell relevant events from noise, kept current by the owner.
struct EventFilter {
    /// Absolute project folder (the folder of `pipeline.ron`).
    root: PathBuf,
    /// Absolute `pipeline.ron`.
    pipeline: PathBuf,
    /// Absolute output folder: never a source.
    output: PathBuf,
    source: PathBuf,
    config: PipelineConfig,
    /// The globs of assets that name their sources by glob (compiled once per configuration).
    asset_globs: Vec<globset::GlobMatcher>,
    /// Every source file read so far, project-relative.
    sources: BTreeSet<PathBuf>,
}

/// The compiled globs of every asset that names its sources by glob.
fn asset_globs(config: &PipelineConfig) -> Vec<globset::GlobMatcher> {
    let globs = config.assets.iter().flat_map(|asset| asset.source.glob_lists()).flatten();
    globs.filter_map(|glob| crate::config::source_glob(glob).ok()).collect()
}

/// What an event on a path means to the daemon.
#[derive(Debug, PartialEq)]
enum Relevance {
    Noise,
    /// These project-relative files may have changed.
    Files(Vec<PathBuf>),
    /// The source folder or one of its parents was created, deleted or moved: the recursive watch
    /// must be armed again and every source read again.
    SourceFolder,
}

impl EventFilter {
    /// What a debounced batch of events tells the owner: nothing, files that may have changed,
    /// or that the source folder must be watched again.
    fn message(&self, events: &[notify_debouncer_full::DebouncedEvent]) -> Option<WatchMessage> {
        let mut changed = BTreeSet::new();
        for event in events.iter().filter(|event| !matches!(event.kind, EventKind::Access(_))) {
            let structural = matches!(
                event.kind,
                EventKind::Create(_) | EventKind::Remove(_) | EventKind::Modify(notify::event::ModifyKind::Name(_))
            );
            for path in &event.paths {
                match self.relevance(path, structural) {
                    Relevance::Noise => {}
                    Relevance::Files(files) => changed.extend(files),
                    Relevance::SourceFolder => return Some(WatchMessage::Rearm),
                }
            }
        }
        (!changed.is_empty()).then_some(WatchMessage::Changed(changed))
    }

    /// What an event on `path` means: files whose edit can change a build, or the source folder
    /// itself coming and going.
    /// `structural`: the event creates, removes or renames `path` (only those move the source
    /// folder).
    fn relevance(&self, path: &Path, structural: bool) -> Relevance {
        if path == self.pipeline {
            return Relevance::Files(self.pipeline.file_name().map(PathBuf::from).into_iter().collect());
        }
        if self.source.starts_with(path) && path.starts_with(&self.root) {
            return if structural { Relevance::SourceFolder } else { Relevance::Noise };
        }
        if path.starts_with(&self.output) {
            return Relevance::Noise;
        }
        let Ok(relative) = path.strip_prefix(&self.root) else { return Relevance::Noise };
        if self.sources.contains(relative) {
            return Relevance::Files(vec![relative.to_path_buf()]);
        }
        // A folder deleted or moved away takes the sources inside it along (one event, no
        // event per file).
        let inside: Vec<PathBuf> = self
            .sources
            .range(relative.to_path_buf()..)
            .take_while(|source| source.starts_with(relative))
            .cloned()
            .collect();
        if !inside.is_empty() {
            return Relevance::Files(inside);
        }
        let Ok(in_source) = path.strip_prefix(&self.source) else { return Relevance::Noise };
        let in_source = PathBuf::from(in_source.to_string_lossy().replace('\\', "/"));
        // A file a rule or an asset's glob matches joins (or leaves) the pipeline.
        let globbed = self.asset_globs.iter().any(|matcher| matcher.is_match(&in_source));
        // A new folder: files written into it before its watch was added send no event of their
        // own, so assets that list by glob look again.
        let new_folder = structural && !self.asset_globs.is_empty() && path.is_dir();
        if globbed || new_folder || self.config.rules.iter().any(|rule| rule.matcher.is_match(&in_source)) {
            Relevance::Files(vec![relative.to_path_buf()])
        } else {
            Relevance::Noise
        }
    }
}

/// What the watcher thread hands the owner.
enum WatchMessage {
    Changed(BTreeSet<PathBuf>),
    /// The watcher lost track (error or overflow): everything is read again.
    Rescan(String),
    /// The source folder (or a parent) was created, deleted or moved: watch it again, then read
    /// everything again.
    Rearm,
    /// A client asked for the graph: computed between batches, sent with its revision.
    Graph(std::sync::mpsc::SyncSender<(u64, crate::graph::Graph)>),
}

/// How long the daemon waits after a batch for the next edit before it writes the manifest and
/// the build record (`Project::save_deferred`), and how late they may be while edits keep coming.
const RECORD_SAVE_IDLE: Duration = Duration::from_secs(1);
const RECORD_SAVE_LATEST: Duration = Duration::from_secs(10);

/// Starts the daemon: the project opened on its output folder (locked), the hot-reload server,
/// the watcher and its filter. Returns the daemon and the watcher's messages.
fn start(settings: &WatchSettings) -> Result<(Daemon<'_>, std::sync::mpsc::Receiver<WatchMessage>), WatchError> {
    let config = load_pipeline(&settings.pipeline)?;
    let absolute = |path: &Path| {
        std::path::absolute(path)
            .and_then(|path| path.canonicalize())
            .map_err(|source| WatchError::Root { path: display_path(path), source })
    };
    let root = absolute(&config.root)?;
    let pipeline = root.join(config.file.file_name().unwrap_or_default());
    let mut output_lock = OutputLock::take(&root.join(&config.output))?;
    let project = Project::open(
        config.clone(),
        ProjectOptions {
            persistent_cache: true,
            source_reading: SourceReading::WhenInvalidated,
            remote_cache: settings.remote_cache.clone(),
            verify: false,
            retention: crate::db::Retention::KeepForNextBuild,
            memory_budget: settings.memory_budget,
        },
    );

    let listen = settings.listen.or(config.server);
    let server = match listen {
        Some(address) => {
            let manifest = crate::artifacts::load_manifest(&config.output_dir());
            let server_settings =
                ServerSettings { allowed_origins: settings.allowed_origins.clone(), ..ServerSettings::default() };
            Some(Server::start(address, server_settings, project.revision(), &config.output, &manifest)?)
        }
        None => None,
    };
    if let Some(server) = &server {
        output_lock.describe(Some(server.address()));
        tracing::info!("hot-reload server listening on {}", server.address());
        eprintln!("cirrus watch: hot-reload server on {}", server.address());
        if !server.address().ip().is_loopback() {
            tracing::warn!(
                "the hot-reload server listens on {}, beyond this machine: the protocol has no authentication, so any \
                 host that reaches this port can read artifact paths and the dependency graph; use 127.0.0.1 unless \
                 that is intended",
                server.address()
            );
        }
    }

    let filter = Arc::new(RwLock::new(EventFilter {
        output: root.join(&config.output),
        source: root.join(&config.source),
        root: root.clone(),
        pipeline: pipeline.clone(),
        config: config.clone(),
        asset_globs: asset_globs(&config),
        sources: BTreeSet::new(),
    }));
    let cancel = CancelFlag::default();
    let (sender, messages) = channel::<WatchMessage>();
    if let Some(server) = &server {
        let sender = std::sync::Mutex::new(sender.clone());
        server.set_graph_source(Arc::new(move || {
            let (reply, answer) = std::sync::mpsc::sync_channel(1);
            sender.lock().ok()?.send(WatchMessage::Graph(reply)).ok()?;
            answer.recv().ok()
        }));
    }
    let watcher_filter = filter.clone();
    let watcher_cancel = cancel.clone();
    let mut debouncer = new_debouncer(settings.debounce, None, move |result: DebounceEventResult| {
        let message = match result {
            Err(errors) => WatchMessage::Rescan(errors.iter().map(ToString::to_string).collect::<Vec<_>>().join("; ")),
            Ok(events) if events.iter().any(|event| event.need_rescan()) => {
                WatchMessage::Rescan("the watcher's event queue overflowed".into())
            }
            Ok(events) => {
                let Some(message) = watcher_filter.read().expect("event filter").message(&events) else { return };
                message
            }
        };
        // A build in flight is stale now: cancel it; the owner rebuilds from the newest inputs.
        watcher_cancel.raise();
        let _ = sender.send(message);
    })
    .map_err(|source| WatchError::Watch { path: display_path(&root), source })?;
    debouncer
        .watch(&root, RecursiveMode::NonRecursive)
        .map_err(|source| WatchError::Watch { path: display_path(&root), source })?;
    let watched = watch_folders(&mut debouncer, &root, &config, &[]);
    let daemon = Daemon { settings, root, pipeline, output_lock, project, server, filter, debouncer, watched, cancel };
    Ok((daemon, messages))
}

/// Runs the daemon until the process ends (or `max_builds` builds finished).
pub fn watch(settings: &WatchSettings) -> Result<(), WatchError> {
    let (mut daemon, messages) = start(settings)?;
    let mut builds = 0u64;
    let mut pending: BTreeSet<PathBuf> = BTreeSet::new();
    let mut first = true;
    // A build is owed even without changed bytes: the first one, and one after a cancellation.
    let mut force_build = true;
    let mut rearm = false;
    // Graph requests that arrived while a batch was being put together: answered after it.
    let mut last_saved = Instant::now();
    let mut graph_requests: Vec<std::sync::mpsc::SyncSender<(u64, crate::graph::Graph)>> = Vec::new();
    loop {
        for reply in graph_requests.drain(..) {
            let _ = reply.send((daemon.project.revision(), daemon.project.graph()));
        }
        if !first && pending.is_empty() {
            // Block for the next edit (the watcher gone ends the daemon); graph requests are
            // answered meanwhile, and the record is written once the daemon is idle.
            let Some(message) = wait_for_edit(&mut daemon.project, &messages, &mut last_saved) else {
                return Ok(());
            };
            rearm |= apply_message(message, &mut pending, &mut daemon.project, &mut graph_requests);
        }
        daemon.cancel.lower();
        // Messages that arrived in between belong to this build too.
        while let Ok(message) = messages.try_recv() {
            rearm |= apply_message(message, &mut pending, &mut daemon.project, &mut graph_requests);
        }
        if std::mem::take(&mut rearm) {
            // The old recursive watch may follow a folder that was moved away, or nothing at all.
            daemon.watched =
                watch_folders(&mut daemon.debouncer, &daemon.root, daemon.project.config(), &daemon.watched);
            force_build = true;
        }
        let mut reconfigured = false;
        if pending.remove(Path::new(daemon.pipeline.file_name().unwrap_or_default())) {
            reconfigured = reload_pipeline(&mut daemon);
            if !reconfigured && pending.is_empty() {
                continue;
            }
        }
        let changed_files: Vec<PathBuf> = std::mem::take(&mut pending).into_iter().collect();
        let rebuild = std::mem::take(&mut force_build) || reconfigured;
        let batch = bake_batch(&mut daemon, &changed_files, (rebuild, first));
        first &= matches!(batch, Batch::Unchanged);
        match batch {
            Batch::Unchanged => continue,
            // Files the batch read that moved meanwhile make the next batch at once.
            Batch::Published { moved } => pending.extend(moved),
            Batch::Cancelled => {
                // The next build covers this batch's edits too (their inputs are set already).
                pending.extend(changed_files);
                force_build = true;
                continue;
            }
            Batch::Failed => continue,
        }
        if last_saved.elapsed() > RECORD_SAVE_LATEST {
            daemon.project.save_deferred();
            last_saved = Instant::now();
        }
        builds += 1;
        if daemon.settings.max_builds.is_some_and(|max| builds >= max) {
            daemon.project.save_deferred();
            return Ok(());
        }
    }
}

type Debouncer = notify_debouncer_full::Debouncer<notify::RecommendedWatcher, notify_debouncer_full::RecommendedCache>;

/// What the daemon's owner thread holds between batches.
struct Daemon<'a> {
    settings: &'a WatchSettings,
    /// The project folder, absolute, and the pipeline file in it.
    root: PathBuf,
    pipeline: PathBuf,
    output_lock: OutputLock,
    project: Project,
    server: Option<Server>,
    filter: Arc<RwLock<EventFilter>>,
    debouncer: Debouncer,
    /// The folders watched now (see [`watch_folders`]).
    watched: Vec<(PathBuf, RecursiveMode)>,
    cancel: CancelFlag,
}

/// How a batch ended.
enum Batch {
    /// Touched with identical bytes: nothing to do.
    Unchanged,
    /// `moved`: files it read that are no longer as it read them.
    Published {
        moved: Vec<PathBuf>,
    },
    /// A newer edit cancelled it.
    Cancelled,
    Failed,
}

/// Blocks for the next edit; graph requests are answered meanwhile, and the manifest and the
/// record are written once the daemon is idle. `None` when the watcher is gone (the daemon ends).
fn wait_for_edit(
    project: &mut Project,
    messages: &std::sync::mpsc::Receiver<WatchMessage>,
    last_saved: &mut Instant,
) -> Option<WatchMessage> {
    let mut record_saved = false;
    loop {
        let received = if record_saved {
            messages.recv().map_err(|_| std::sync::mpsc::RecvTimeoutError::Disconnected)
        } else {
            messages.recv_timeout(RECORD_SAVE_IDLE)
        };
        match received {
            Ok(WatchMessage::Graph(reply)) => {
                let _ = reply.send((project.revision(), project.graph()));
            }
            Ok(message) => return Some(message),
            Err(std::sync::mpsc::RecvTimeoutError::Timeout) => {
                project.save_deferred();
                crate::memory::release_freed_memory();
                *last_saved = Instant::now();
                record_saved = true;
            }
            Err(std::sync::mpsc::RecvTimeoutError::Disconnected) => {
                project.save_deferred();
                return None;
            }
        }
    }
}

/// Loads the edited pipeline file; true when the daemon took it. A broken file (or a new output
/// folder that another daemon holds) keeps the last good configuration and is reported to the
/// subscribed clients as a failed batch.
fn reload_pipeline(daemon: &mut Daemon) -> bool {
    // A new output folder is locked before the configuration is taken; one that another
    // daemon holds is refused like a configuration error, keeping the old one.
    let loaded = load_pipeline(&daemon.project.config().file).and_then(|new_config| {
        if new_config.output == daemon.project.config().output {
            return Ok(new_config);
        }
        match OutputLock::take(&daemon.root.join(&new_config.output)) {
            Ok(mut lock) => {
                lock.describe(daemon.server.as_ref().map(Server::address));
                daemon.output_lock = lock;
                if let Some(server) = &daemon.server {
                    let manifest = crate::artifacts::load_manifest(&new_config.output_dir());
                    server.set_output(&new_config.output, &manifest);
                }
                Ok(new_config)
            }
            Err(error) => Err(crate::config::ConfigError {
                diagnostics: vec![crate::diagnostic::Diagnostic::new(&new_config.file, format!("`output`: {error}"))],
            }),
        }
    });
    match loaded {
        Ok(new_config) => {
            tracing::info!("{} changed: reconfigured", display_path(&new_config.file));
            if new_config.server != daemon.project.config().server && daemon.settings.listen.is_none() {
                tracing::warn!(
                    "`server` changed in {}: the hot-reload server keeps its address until `cirrus watch` restarts",
                    display_path(&new_config.file)
                );
            }
            daemon.watched = watch_folders(&mut daemon.debouncer, &daemon.root, &new_config, &daemon.watched);
            {
                let mut filter = daemon.filter.write().expect("event filter");
                filter.output = daemon.root.join(&new_config.output);
                filter.source = daemon.root.join(&new_config.source);
                filter.config = new_config.clone();
                filter.asset_globs = asset_globs(&new_config);
            }
            daemon.project.reconfigure(new_config);
            daemon.project.invalidate_all_sources();
            true
        }
        Err(error) => {
            tracing::error!("{error}");
            eprintln!("{error}");
            let failed = error
                .diagnostics
                .iter()
                .map(|diagnostic| FailedEntry {
                    asset: None,
                    stage: "config".into(),
                    message: diagnostic.message.clone(),
                    file: display_path(&diagnostic.file),
                    line: diagnostic.line(),
                    column: diagnostic.column(),
                })
                .collect();
            // Keep running on the last good configuration; report the broken file.
            if let Some(server) = &daemon.server {
                let batch = BatchEvent {
                    revision: daemon.project.revision() + 1,
                    changed: Vec::new(),
                    removed: Vec::new(),
                    failed,
                    ms: 0.0,
                };
                daemon.project.skip_revision();
                server.publish(&batch);
            }
            false
        }
    }
}

/// Builds the batch of `changed_files` and publishes it: the engine hears first, then the log
/// (with the graph of the assets the batch looked into).
fn bake_batch(daemon: &mut Daemon, changed_files: &[PathBuf], (rebuild, first): (bool, bool)) -> Batch {
    let request = BatchRequest { changed: changed_files, rebuild, first, cancel: daemon.cancel.clone() };
    let mut hooks = DaemonHooks { server: daemon.server.as_ref(), filter: &daemon.filter };
    let start = Instant::now();
    match daemon.project.bake_batch(&request, &mut hooks) {
        BatchOutcome::Unchanged => Batch::Unchanged,
        BatchOutcome::Cancelled => {
            let ms = start.elapsed().as_secs_f64() * 1e3;
            tracing::info!("build cancelled by a newer edit after {ms:.0} ms; restarting");
            Batch::Cancelled
        }
        BatchOutcome::Failed(error) => {
            tracing::error!("{error}");
            Batch::Failed
        }
        BatchOutcome::Published { summary, graph, ms, moved } => {
            if !moved.is_empty() {
                tracing::info!("{} file(s) the batch read changed while it baked: baking again", moved.len());
            }
            log_batch(&summary, changed_files, &graph, ms);
            Batch::Published { moved }
        }
    }
}

/// What a batch tells the daemon as it runs: the server hears that it started and, first, what
/// it built; the event filter keeps the files it reads.
struct DaemonHooks<'a> {
    server: Option<&'a Server>,
    filter: &'a RwLock<EventFilter>,
}

impl BatchHooks for DaemonHooks<'_> {
    fn started(&mut self, changed: &[PathBuf]) {
        if let Some(server) = self.server {
            server.building(&changed.iter().map(|file| display_path(file)).collect::<Vec<_>>());
        }
    }

    fn watch(&mut self, files: Vec<PathBuf>) {
        self.filter.write().expect("event filter").sources.extend(files);
    }

    fn built(&mut self, summary: &BuildSummary, ms: f64) {
        if let Some(server) = self.server {
            server.publish(&batch_event(summary, ms));
        }
    }
}

/// Applies a watcher message; true when the source folder must be watched again. A graph
/// request waits in `graph_requests` for the batch to finish.
fn apply_message(
    message: WatchMessage,
    pending: &mut BTreeSet<PathBuf>,
    project: &mut Project,
    graph_requests: &mut Vec<std::sync::mpsc::SyncSender<(u64, crate::graph::Graph)>>,
) -> bool {
    let rearm = matches!(message, WatchMessage::Rearm);
    match message {
        WatchMessage::Graph(reply) => graph_requests.push(reply),
        WatchMessage::Changed(paths) => pending.extend(paths),
        WatchMessage::Rescan(why) => {
            tracing::warn!("rescanning every source: {why}");
            project.invalidate_all_sources();
            pending.extend(project.source_paths());
        }
        WatchMessage::Rearm => {
            tracing::info!(
                "the source folder {} appeared, moved or vanished: watching it again",
                display_path(&project.config().source)
            );
            project.invalidate_all_sources();
            pending.extend(project.source_paths());
        }
    }
    rearm
}

/// Watches (again) the source folder recursively, and non-recursively each folder between the
/// project folder and it, so that the source folder's own creation, deletion or move is seen
/// (a recursive watch dies with its folder, and a folder that is missing cannot be watched).
/// The project folder itself is watched for the whole run (`pipeline.ron`). Folders that do not
/// exist are skipped, not errors: the daemon keeps running and reports the missing sources.
/// Returns the folders watched now.
fn watch_folders(
    debouncer: &mut notify_debouncer_full::Debouncer<
        notify::RecommendedWatcher,
        notify_debouncer_full::RecommendedCache,
    >,
    root: &Path,
    config: &PipelineConfig,
    previous: &[(PathBuf, RecursiveMode)],
) -> Vec<(PathBuf, RecursiveMode)> {
    for (path, _) in previous {
        let _ = debouncer.unwatch(path);
    }
    let source = root.join(&config.source);
    let mut wanted: Vec<(PathBuf, RecursiveMode)> = source
        .ancestors()
        .skip(1)
        .take_while(|folder| folder.starts_with(root) && *folder != root)
        .map(|folder| (folder.to_path_buf(), RecursiveMode::NonRecursive))
        .collect();
    wanted.reverse();
    wanted.push((source, RecursiveMode::Recursive));
    let mut watched = Vec::new();
    for (path, mode) in wanted {
        if !path.is_dir() {
            tracing::warn!("{} does not exist: its assets fail until it appears", display_path(&path));
            break;
        }
        match debouncer.watch(&path, mode) {
            Ok(()) => watched.push((path, mode)),
            Err(error) => tracing::warn!("cannot watch {}: {error}", display_path(&path)),
        }
    }
    watched
}

/// The batch message of a finished build.
pub(crate) fn batch_event(summary: &BuildSummary, ms: f64) -> BatchEvent {
    let mut failed = Vec::new();
    for asset in summary.assets.iter().filter(|asset| asset.status == AssetStatus::Failed) {
        let stage = asset
            .stages
            .iter()
            .find(|stage| stage.status == StageStatus::Failed)
            .map_or("parse", |stage| stage.stage.as_str());
        for error in &asset.errors {
            failed.push(FailedEntry {
                asset: Some(asset.name.clone()),
                stage: stage.to_string(),
                message: error.message.clone(),
                file: error.file.clone(),
                line: error.line,
                column: error.column,
            });
        }
    }
    BatchEvent {
        revision: summary.revision,
        changed: summary.changed.clone(),
        removed: summary.removed.clone(),
        failed,
        ms: (ms * 10.0).round() / 10.0,
    }
}

/// Logs what a batch changed, which stages ran and which edited file made them run.
fn log_batch(summary: &BuildSummary, changed_files: &[PathBuf], graph: &crate::graph::Graph, ms: f64) {
    let ran: Vec<String> = summary
        .assets
        .iter()
        .flat_map(|asset| {
            asset.stages.iter().filter(|stage| stage.status == StageStatus::Ran).map(move |stage| (asset, stage))
        })
        .map(|(asset, stage)| format!("{}:{}({})", asset.name, stage.stage, stage.instance))
        .collect();
    // One line per batch whatever the log level: the daemon is seen to work.
    let rebuilt =
        summary.assets.iter().filter(|asset| asset.stages.iter().any(|stage| stage.status == StageStatus::Ran)).count();
    let _ = writeln!(
        std::io::stderr(),
        "cirrus watch: batch r{}: {} file(s) changed, {rebuilt} asset(s) rebuilt, {} stage(s) ran, {} artifact(s) \
            changed, {} failed asset(s), {ms:.0} ms",
        summary.revision,
        changed_files.len(),
        ran.len(),
        summary.changed.len(),
        summary.assets.iter().filter(|asset| asset.status == AssetStatus::Failed).count()
    );
    for file in changed_files {
        let id = crate::project::file_node_id(file);
        let downstream = graph.downstream(&id);
        let stages: Vec<&String> = downstream.iter().filter(|node| node.contains('(')).collect();
        tracing::info!("  {id} changed: invalidates {} stage(s) downstream", stages.len());
        tracing::debug!("  {id} → {}", stages.iter().map(|stage| stage.as_str()).collect::<Vec<_>>().join(", "));
    }
    for stage in &ran {
        tracing::debug!("  ran {stage}");
    }
    for artifact in &summary.changed {
        tracing::info!("  wrote {} ({})", artifact.path, &artifact.hash[..12]);
    }
    for asset in summary.assets.iter().filter(|asset| asset.status == AssetStatus::Failed) {
        for error in &asset.errors {
            let position = error.line.map(|line| format!(":{line}")).unwrap_or_default();
            tracing::warn!("  {} failed: {}{position}: {}", asset.name, error.file, error.message);
        }
    }
}
