//! Passing over what did not move: an asset's fingerprint, whether the build record holds it
//! unchanged (its artifacts as written), the daemon's clean set, and writing the record.

use std::collections::HashMap;
use std::path::PathBuf;

use super::{Project, SourceReading, FINGERPRINT_VERSION};
use crate::artifacts::Manifest;
use crate::config::AssetConfig;
use crate::db::Asset;
use crate::diagnostic::display_path;

impl Project {
    /// Marks an asset clean (`CleanAssets::mark`), indexed under the files its input or its
    /// record says it reads.
    pub(super) fn mark_clean(&mut self, name: &str) {
        let (assets, db, skip) = (&self.assets, &self.db, &self.skip);
        self.clean.mark(name, || match assets.get(name) {
            Some(&asset) => asset.files(db).keys().cloned().collect(),
            None => skip.files_of(name),
        });
    }

    /// The files of the source folder that an asset's globs list (none for most kinds).
    pub(super) fn listed_sources(&self, config: &AssetConfig) -> Vec<Vec<PathBuf>> {
        let lists = config.source.glob_lists();
        lists.into_iter().map(|globs| crate::sources::glob_matches(&self.config, globs)).collect()
    }

    /// The fingerprint of an asset that reads `files` and lists `listed`: everything its outputs
    /// depend on (this executable, the CPU kernels' level, its configuration and the pipeline's
    /// limits and folders, each file's content hash or why it cannot be read, and the
    /// fingerprint of the asset whose output it reads). `None` when that asset has none.
    pub(super) fn fingerprint(
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
        hasher.update(self.skip.identity().as_bytes());
        let config_hash = self.skip.config_hash(config, &self.config);
        hasher.update(config_hash.as_bytes());
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
                Err(why) => hasher.update(b"!").update(why.to_string().as_bytes()).update(b"\0"),
            };
        }
        if let Some(source) = config.settings.reads_asset() {
            let read = all_assets.iter().find(|asset| asset.name == source)?;
            hasher.update(self.current_fingerprint(read, all_assets, built, depth + 1)?.as_bytes());
        }
        Some(hasher.finalize())
    }

    /// An asset's fingerprint now: of the files its input reads when this build baked it, else
    /// of the files the record says it reads (`None` when it has no record: never baked, or
    /// failed).
    pub(super) fn current_fingerprint(
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
            None => (self.skip.asset(&config.name)?.files.clone(), self.listed_sources(config)),
        };
        self.fingerprint(config, &files, &listed, all_assets, built, depth)
    }

    /// Whether an asset can be passed over: the record holds it, its fingerprint is the same,
    /// and every artifact it wrote is still there as written (by its metadata, or its bytes'
    /// hash with `--verify`) and listed in the manifest as its.
    pub(super) fn unchanged_asset(
        &mut self,
        config: &AssetConfig,
        all_assets: &[AssetConfig],
        manifest: &Manifest,
    ) -> bool {
        // Nothing this asset reads changed since it was last found unchanged (an asset that
        // reads another's output, or lists its sources by glob, is checked every time).
        let checked_every_time = config.settings.reads_asset().is_some() || !config.source.glob_lists().is_empty();
        if !checked_every_time && self.clean.contains(&config.name) {
            return true;
        }
        let Some(recorded) = self.skip.asset(&config.name).map(|record| record.fingerprint) else {
            return false;
        };
        if self.current_fingerprint(config, all_assets, &HashMap::new(), 0) != Some(recorded) {
            return false;
        }
        if self.source_reading == SourceReading::WhenInvalidated && self.skip.trusts(&config.name) {
            self.mark_clean(&config.name);
            return true;
        }
        let intact = self.skip.check_artifacts(&config.name, manifest, &self.config.root, self.options.verify);
        if intact {
            self.mark_clean(&config.name);
        }
        intact
    }

    /// Writes what the daemon keeps in memory between idle moments: the manifest and the
    /// build record, each when it changed since it was last written.
    pub(crate) fn save_deferred(&mut self) {
        self.published.save(&self.config.output_dir(), &self.config.output.join("manifest.json"));
        self.save_record();
    }

    /// Writes the build record when it changed since it was last written (never without the
    /// persistent cache).
    pub(super) fn save_record(&mut self) {
        if self.options.persistent_cache {
            self.skip.save(&self.config);
        }
    }
}
