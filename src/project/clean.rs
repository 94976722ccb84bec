//! The daemon's clean set and its readers index: the assets known to be as the build record
//! holds them (passed over without a fingerprint), and for each source file the assets that
//! read it, so that an edit of a file makes exactly its readers unclean.

use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use super::asset_list::AssetList;

/// The assets known to be clean and the files each reads (see the module's words).
#[derive(Debug, Default)]
pub struct CleanAssets {
    clean: HashSet<String>,
    /// The asset list the clean assets were found clean for.
    list: Option<Arc<AssetList>>,
    /// The assets that read each source file (may name an asset that no longer reads it, which
    /// only costs that asset a fingerprint).
    readers: HashMap<PathBuf, Vec<String>>,
    /// Whether assets stay clean across builds (the daemon); else every build starts afresh
    /// and no readers are indexed.
    across_builds: bool,
}

impl CleanAssets {
    /// An empty set; `across_builds` for the daemon, whose watcher says which files changed.
    pub fn new(across_builds: bool) -> CleanAssets {
        CleanAssets { across_builds, ..CleanAssets::default() }
    }

    pub fn contains(&self, name: &str) -> bool {
        self.clean.contains(name)
    }

    /// Marks an asset clean: passed over without a fingerprint until a file it reads (`reads`,
    /// asked only when it is new here and the set lasts across builds) changes, or until the
    /// next build when it does not last.
    pub fn mark(&mut self, name: &str, reads: impl FnOnce() -> Vec<PathBuf>) {
        if !self.clean.insert(name.to_string()) || !self.across_builds {
            return;
        }
        for file in reads() {
            let readers = self.readers.entry(file).or_default();
            if !readers.iter().any(|reader| reader == name) {
                readers.push(name.to_string());
            }
        }
    }

    /// The asset is no longer known to be clean (it was baked again, or failed).
    pub fn remove(&mut self, name: &str) {
        self.clean.remove(name);
    }

    /// The assets that read `path` are no longer known to be clean.
    pub fn unclean_readers_of(&mut self, path: &Path) {
        for reader in self.readers.get(path).into_iter().flatten() {
            self.clean.remove(reader);
        }
    }

    /// No asset is known to be clean (a new configuration, a watcher that lost events, a build
    /// that starts afresh).
    pub fn clear(&mut self) {
        self.clean.clear();
    }

    /// Keeps the clean assets whose configuration is the same in `list` as in the list they
    /// were found clean for.
    pub fn keep_for(&mut self, list: &Arc<AssetList>) {
        match &self.list {
            Some(old) if Arc::ptr_eq(old, list) => return,
            Some(old) => {
                let before: HashMap<&str, _> = old.0.iter().map(|asset| (asset.name.as_str(), asset)).collect();
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
        self.list = Some(list.clone());
    }
}
