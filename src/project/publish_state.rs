//! The publish state: the manifest as last read or written (with the stamp its file had then,
//! so that it is read again only when the file changed meanwhile), and whether the copy in
//! memory is still to be written (the daemon writes it when idle); what a build hands its
//! publishing (each asset's outputs) and what publishing gathers.

use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};

use crate::artifacts::{load_manifest, manifest_path, save_manifest, Manifest};
use crate::diagnostic::{display_path, Diagnostic};
use crate::record::FileStamp;
use crate::summary::{AssetSummary, ChangedArtifact};

/// The manifest as the project keeps it between builds.
#[derive(Debug)]
pub struct PublishState {
    /// The manifest, taken out while a build publishes.
    manifest: Option<(Option<FileStamp>, Manifest)>,
    /// The manifest kept in memory differs from the file.
    unsaved: bool,
}

impl PublishState {
    /// The manifest in the output folder `output_dir` (an empty one when there is none).
    pub fn load(output_dir: &Path) -> PublishState {
        let stamp = FileStamp::read(&manifest_path(output_dir));
        PublishState { manifest: Some((stamp, load_manifest(output_dir))), unsaved: false }
    }

    /// The revision of the manifest kept (0 when it is taken out, or new).
    pub fn revision(&self) -> u64 {
        self.manifest.as_ref().map_or(0, |(_, manifest)| manifest.revision)
    }

    /// Whether the manifest file was there when it was last read or written.
    pub fn had_file(&self) -> bool {
        self.manifest.as_ref().is_some_and(|(stamp, _)| stamp.is_some())
    }

    /// The manifest for a build to publish into: the one kept when it is unsaved or its file did
    /// not change since, else the file's.
    pub fn take(&mut self, output_dir: &Path) -> Manifest {
        let stamp = FileStamp::read(&manifest_path(output_dir));
        match self.manifest.take() {
            Some((_, manifest)) if self.unsaved => manifest,
            Some((kept, manifest)) if kept == stamp && stamp.is_some() => manifest,
            _ => load_manifest(output_dir),
        }
    }

    /// Keeps `manifest` with the stamp its file has now, for the next [`PublishState::take`].
    pub fn keep(&mut self, output_dir: &Path, manifest: Manifest) {
        let stamp = FileStamp::read(&manifest_path(output_dir));
        self.manifest = Some((stamp, manifest));
    }

    /// The manifest kept now differs from its file, which waits for [`PublishState::save`].
    pub fn mark_unsaved(&mut self) {
        self.unsaved = true;
    }

    /// Writes the kept manifest into `output_dir` when it differs from its file (`shown` names
    /// the file in a message).
    pub fn save(&mut self, output_dir: &Path, shown: &Path) {
        if !self.unsaved {
            return;
        }
        if let Some((_, manifest)) = self.manifest.take() {
            if let Err(error) = save_manifest(output_dir, &manifest) {
                tracing::error!("cannot write {}: {error}", display_path(shown));
            }
            self.keep(output_dir, manifest);
        }
        self.unsaved = false;
    }
}

/// An asset's outputs as its kind made them, with its errors and the labels of its failed jobs.
pub(super) struct BakedAsset {
    pub errors: Vec<Diagnostic>,
    pub failed_jobs: HashSet<String>,
    pub folder: PathBuf,
    pub outputs: crate::kinds::AssetOutputs,
}

/// What a build's publishing gathers: whether anything changed, the artifacts it wrote and
/// removed, each asset's summary, and each stage instance's status for the graph.
#[derive(Default)]
pub(super) struct BuildNews {
    pub changed: bool,
    pub changed_artifacts: Vec<ChangedArtifact>,
    pub removed_artifacts: Vec<String>,
    pub summaries: Vec<AssetSummary>,
    pub statuses: HashMap<String, (&'static str, Option<f64>)>,
}
