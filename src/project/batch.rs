//! The daemon's batch as one call of the driver: the files the watcher says changed read again,
//! the build (when some bytes changed, or the daemon asks), the sources it read handed back to
//! be watched and checked for edits made while it baked, and the graph of what it looked into.

use std::collections::HashSet;
use std::path::PathBuf;
use std::time::Instant;

use super::{BuildError, BuildOptions, CancelFlag, Project};
use crate::summary::BuildSummary;

/// One batch of the daemon.
pub struct BatchRequest<'a> {
    /// The files the watcher says changed (project-relative).
    pub changed: &'a [PathBuf],
    /// Build even when no file's bytes changed (the first batch, a new pipeline, a rescan).
    pub rebuild: bool,
    /// The daemon's first batch: it bakes what the record does not hold, every source it reads
    /// is watched from now on, and it gets a new revision only when something changed.
    pub first: bool,
    /// Raised by the watcher when a newer edit arrives.
    pub cancel: CancelFlag,
}

/// What the daemon is told while a batch runs, in order.
pub trait BatchHooks {
    /// The build starts, for the edit of `changed`.
    fn started(&mut self, changed: &[PathBuf]);
    /// Files the batch reads or read: watched from now on. Told before the build (the assets'
    /// main files, when rules may add assets) and after it (every file it read), each time
    /// before the files are checked, so that an edit after the check is an event the daemon
    /// keeps.
    fn watch(&mut self, files: Vec<PathBuf>);
    /// The build's summary and its milliseconds, before the graph is made (the engine hears
    /// first; the log waits for the graph).
    fn built(&mut self, summary: &BuildSummary, ms: f64);
}

/// How a batch ended.
pub enum BatchOutcome {
    /// Touched with identical bytes: nothing was built.
    Unchanged,
    /// A newer edit cancelled it; the next batch covers its edits too.
    Cancelled,
    /// The build could not run (the error is logged).
    Failed(BuildError),
    /// Published: the summary, the graph of the assets it looked into, the milliseconds it
    /// took, and `moved`, files it read that are no longer as it read them.
    Published { summary: BuildSummary, graph: crate::graph::Graph, ms: f64, moved: Vec<PathBuf> },
}

impl Project {
    /// Runs one batch of the daemon (see [`BatchRequest`]), telling `hooks` as it goes.
    pub fn bake_batch(&mut self, request: &BatchRequest, hooks: &mut dyn BatchHooks) -> BatchOutcome {
        let changed = self.refresh_sources(request.changed.iter().map(PathBuf::as_path));
        if !changed && !request.rebuild {
            tracing::debug!("{} file(s) touched with identical bytes: nothing to do", request.changed.len());
            return BatchOutcome::Unchanged;
        }
        hooks.started(request.changed);
        // The files this build is about to read count as sources already: a folder of new
        // rule-matched files deleted while they bake (one event for the folder) cancels it.
        // (Without rules no asset is new to the watcher: no walk of the source folder.)
        if !self.config.rules.is_empty() {
            let source = &self.config.source;
            hooks.watch(self.asset_list().iter().map(|asset| source.join(asset.source.main_file())).collect());
        }
        let start = Instant::now();
        let options = BuildOptions {
            cancel: Some(request.cancel.clone()),
            always_new_revision: !request.first,
            omit_unchanged: true,
            ..Default::default()
        };
        let summary = match self.build(&options, &|_| {}) {
            Ok(summary) => summary,
            Err(BuildError::Cancelled) => return BatchOutcome::Cancelled,
            Err(error) => return BatchOutcome::Failed(error),
        };
        let ms = start.elapsed().as_secs_f64() * 1e3;
        // The summary lists the assets this batch looked into (the others were passed over):
        // their files join the watched sources, and then are checked.
        let rebuilt: HashSet<String> = summary.assets.iter().map(|asset| asset.name.clone()).collect();
        let sources = if request.first { self.source_paths() } else { self.source_paths_of(&rebuilt) };
        hooks.watch(sources.iter().cloned().collect());
        let moved = self.moved_since_read(&sources);
        hooks.built(&summary, ms);
        let graph = self.graph_of_assets(Some(&rebuilt));
        BatchOutcome::Published { summary, graph, ms, moved }
    }
}
