//! Passing over what did not move: an asset's fingerprint, whether the build record holds it
//! unchanged (its artifacts as written), the daemon's clean set, and writing the record.

use super::*;

impl Project {
    /// The assets that read `path` are no longer known to be clean.
    pub(super) fn unclean_readers_of(&mut self, path: &Path) {
        for reader in self.readers.get(path).into_iter().flatten() {
            self.clean.remove(reader);
        }
    }

    /// Marks an asset clean: passed over without a fingerprint until a file it reads changes
    /// (the daemon), or until the next build (which starts afresh).
    pub(super) fn mark_clean(&mut self, name: &str) {
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
    pub(super) fn keep_clean_for(&mut self, list: &Arc<AssetList>) {
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

    /// The files of the source folder that an asset's globs list (none for most kinds).
    pub(super) fn listed_sources(&self, config: &AssetConfig) -> Vec<Vec<PathBuf>> {
        let lists = config.source.glob_lists();
        lists.into_iter().map(|globs| crate::sources::glob_matches(&self.config, globs)).collect()
    }

    /// The hash of an asset's configuration with the pipeline-wide settings its outputs depend
    /// on (most assets share their rule's settings: each distinct one is formatted once).
    pub(super) fn config_hash(&mut self, config: &AssetConfig) -> blake3::Hash {
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
            None => (self.record.assets.get(&config.name)?.files.clone(), self.listed_sources(config)),
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
                crate::files::read_regular_file(&file, crate::files::MAX_SOURCE_BYTES)
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

    /// Writes what the daemon keeps in memory between idle moments: the manifest and the
    /// build record, each when it changed since it was last written.
    pub(crate) fn save_deferred(&mut self) {
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
    pub(super) fn save_record(&mut self) {
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

    /// Drops the record's assets that left the pipeline and the files no recorded asset reads.
    pub(super) fn prune_record(&mut self, all_assets: &[AssetConfig]) {
        let names: HashSet<&str> = all_assets.iter().map(|asset| asset.name.as_str()).collect();
        let before = (self.record.assets.len(), self.record.files.len());
        self.record.assets.retain(|name, _| names.contains(name.as_str()));
        let read: HashSet<&PathBuf> = self.record.assets.values().flat_map(|asset| asset.files.iter()).collect();
        let files = std::mem::take(&mut self.record.files);
        self.record.files = files.into_iter().filter(|(path, _)| read.contains(path)).collect();
        self.record_changed |= before != (self.record.assets.len(), self.record.files.len());
    }
}

/// What identifies this executable in fingerprints: its version and its file's size and
/// modification time, so that a rebuilt cirrus (whose stages may bake otherwise) trusts no
/// fingerprint an older one recorded. Unknown: a value no record holds.
pub(super) fn executable_identity() -> blake3::Hash {
    let file = std::env::current_exe().ok().and_then(|path| Some((FileStamp::read(&path)?, path)));
    let text = match file {
        Some((stamp, path)) => {
            format!("{}|{}|{}|{}", env!("CARGO_PKG_VERSION"), path.display(), stamp.size, stamp.modified)
        }
        None => format!("unknown|{}", crate::record::now()),
    };
    blake3::hash(text.as_bytes())
}
