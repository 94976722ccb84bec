//! The skip record: the build record (source files' stamps and hashes, each baked asset's
//! fingerprint, files, artifacts and stage instances) with what decides from it that an asset
//! can be passed over: this executable's identity, each distinct settings' hash, and the
//! assets whose artifacts this process wrote or checked.

use std::collections::HashSet;
use std::path::{Path, PathBuf};

use crate::artifacts::Manifest;
use crate::config::{AssetConfig, PipelineConfig};
use crate::diagnostic::display_path;
use crate::record::{AssetRecord, BuildRecord, FileStamp};

/// The build record and what the project knows beside it (see the module's words).
pub struct SkipRecord {
    record: BuildRecord,
    /// The record differs from the one on disk.
    changed: bool,
    /// What identifies this executable in fingerprints (a rebuilt cirrus trusts no record).
    identity: blake3::Hash,
    /// The hash of each distinct asset settings seen (most assets share their rule's), with the
    /// pipeline-wide values that enter fingerprints.
    settings_hashes: Vec<(crate::config::Settings, blake3::Hash)>,
    /// Assets whose artifacts this process wrote or checked against the record: the daemon,
    /// which holds the output folder's lock, does not check them again.
    trusted_artifacts: HashSet<String>,
}

impl SkipRecord {
    /// The record in `config`'s output folder (empty when there is none), holding only paths
    /// inside its source and output folders.
    pub fn load(config: &PipelineConfig) -> SkipRecord {
        let mut record = BuildRecord::load(&config.output_dir());
        record.keep_within(&config.source, &config.output);
        SkipRecord {
            record,
            changed: false,
            identity: executable_identity(),
            settings_hashes: Vec::new(),
            trusted_artifacts: HashSet::new(),
        }
    }

    pub fn record(&self) -> &BuildRecord {
        &self.record
    }

    pub fn identity(&self) -> blake3::Hash {
        self.identity
    }

    /// The recorded entry of the asset `name`.
    pub fn asset(&self, name: &str) -> Option<&AssetRecord> {
        self.record.assets.get(name)
    }

    /// Records a source file's stamp and hash as read at `seen_at`.
    pub fn remember_file(&mut self, path: &Path, stamp: FileStamp, hash: blake3::Hash, seen_at: i64) {
        self.changed |= self.record.remember_file(path, stamp, hash, seen_at);
    }

    /// Records a baked asset (clean, with its fingerprint); its artifacts are as this process
    /// wrote them.
    pub fn insert_asset(&mut self, name: &str, record: AssetRecord) {
        self.record.assets.insert(name.to_string(), record);
        self.changed = true;
        self.trusted_artifacts.insert(name.to_string());
    }

    /// Forgets an asset (failed, or its manifest could not be written): it is baked again.
    pub fn remove_asset(&mut self, name: &str) {
        self.changed |= self.record.assets.remove(name).is_some();
        self.trusted_artifacts.remove(name);
    }

    /// The hash of an asset's configuration with `pipeline`'s settings its outputs depend on
    /// (most assets share their rule's settings: each distinct one is formatted once).
    pub fn config_hash(&mut self, config: &AssetConfig, pipeline: &PipelineConfig) -> blake3::Hash {
        let settings = match self.settings_hashes.iter().find(|(seen, _)| *seen == config.settings) {
            Some((_, hash)) => *hash,
            None => {
                let text = format!(
                    "{:?}|{:?}|{:?}|{:?}|{}",
                    config.settings,
                    pipeline.source,
                    pipeline.output,
                    pipeline.limits,
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

    /// Forgets the settings' hashes (the pipeline-wide values in them may have changed).
    pub fn forget_settings_hashes(&mut self) {
        self.settings_hashes.clear();
    }

    /// Whether the asset `name`'s artifacts were written or checked by this process.
    pub fn trusts(&self, name: &str) -> bool {
        self.trusted_artifacts.contains(name)
    }

    /// Whether every artifact the asset `name` wrote is still in `root` as written (by its
    /// metadata, or its bytes' hash with `verify`) and listed in `manifest` as its; if so, it is
    /// trusted from now on.
    pub fn check_artifacts(&mut self, name: &str, manifest: &Manifest, root: &Path, verify: bool) -> bool {
        let Some(record) = self.record.assets.get(name) else { return false };
        let intact = record.artifacts.iter().all(|(path, stamp)| {
            let Some(entry) = manifest.artifacts.get(path).filter(|entry| entry.asset == name) else {
                return false;
            };
            let file = root.join(path);
            if verify {
                crate::files::read_regular_file(&file, crate::files::MAX_SOURCE_BYTES)
                    .is_ok_and(|bytes| blake3::hash(&bytes).to_hex().as_str() == entry.hash)
            } else {
                FileStamp::read(&file) == Some(*stamp)
            }
        });
        if intact {
            self.trusted_artifacts.insert(name.to_string());
        }
        intact
    }

    /// Writes the record into `config`'s output folder when it changed since it was last written.
    pub fn save(&mut self, config: &PipelineConfig) {
        if !self.changed {
            return;
        }
        match self.record.save(&config.output_dir()) {
            Ok(()) => self.changed = false,
            Err(error) => tracing::warn!(
                "cannot write {}: {error} (the next build hashes its sources again)",
                display_path(&crate::record::record_path(&config.output))
            ),
        }
    }

    /// Drops the record's assets that are not in `all_assets` and the files no recorded asset
    /// reads.
    pub fn prune(&mut self, all_assets: &[AssetConfig]) {
        let names: HashSet<&str> = all_assets.iter().map(|asset| asset.name.as_str()).collect();
        let before = (self.record.assets.len(), self.record.files.len());
        self.record.assets.retain(|name, _| names.contains(name.as_str()));
        let read: HashSet<&PathBuf> = self.record.assets.values().flat_map(|asset| asset.files.iter()).collect();
        let files = std::mem::take(&mut self.record.files);
        self.record.files = files.into_iter().filter(|(path, _)| read.contains(path)).collect();
        self.changed |= before != (self.record.assets.len(), self.record.files.len());
    }

    /// The files each recorded asset reads, by asset name.
    pub fn files_of(&self, name: &str) -> Vec<PathBuf> {
        self.record.assets.get(name).map(|record| record.files.clone()).unwrap_or_default()
    }

    /// The hash the record holds for `path` if its metadata is `stamp` (not racy).
    pub fn trusted_hash(&self, path: &Path, stamp: &FileStamp) -> Option<blake3::Hash> {
        self.record.trusted_hash(path, stamp)
    }
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
