//! Asset names: which are valid, which are reserved for cirrus's own files in the output folder,
//! and which share a folder (indexed, so that thousands of rule-made assets are checked by lookup).

use std::collections::{HashMap, HashSet};
use std::path::Path;

use base::paths::normalize_relative_path;

pub(super) fn valid_asset_name(name: &str) -> bool {
    // Compared as text: `a//b` and `a/./b` are the same folder as `a/b` and would pass a path
    // comparison while escaping the duplicate check.
    !name.is_empty()
        && name.chars().all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.' | '/'))
        && normalize_relative_path(Path::new(name)).is_some_and(|path| crate::diagnostic::display_path(&path) == name)
}

/// Names of the output folder's own files: an asset named so would overwrite them.
pub const RESERVED_ASSET_NAMES: [&str; 2] = ["manifest.json", ".cirrus"];

/// Why an asset may not be called `name`, if it may not: its folder would be the manifest or
/// the cache, or its name starts with the temporary-file prefix.
pub fn reserved_asset_name(name: &str) -> Option<String> {
    let first = name.split('/').next().unwrap_or(name);
    if RESERVED_ASSET_NAMES.contains(&first) || first.starts_with(crate::files::TEMPORARY_PREFIX) {
        Some(format!("asset name `{name}` is reserved: `<output>/{first}` belongs to cirrus"))
    } else {
        None
    }
}

/// Asset names, indexed so that whether a new name's folder collides with one of theirs is a
/// handful of lookups, not a pass over every name: two names share artifacts when they are the
/// same or one folder lies inside the other (`x` and `x/m`: the stale-artifact cleanup of one
/// would delete the other's files).
#[derive(Default)]
pub struct AssetFolders {
    names: HashSet<String>,
    /// Each folder that holds a name's folder (`x` and `x/m` for `x/m/n`), with one such name.
    outer: HashMap<String, String>,
}

impl AssetFolders {
    /// A name already added that `name`'s folder collides with (itself included).
    pub fn collision(&self, name: &str) -> Option<&str> {
        if let Some(same) = self.names.get(name) {
            return Some(same);
        }
        let outers = name.match_indices('/').map(|(at, _)| &name[..at]);
        if let Some(outer) = outers.filter_map(|outer| self.names.get(outer)).next() {
            return Some(outer);
        }
        self.outer.get(name).map(String::as_str)
    }

    pub fn insert(&mut self, name: &str) {
        for (at, _) in name.match_indices('/') {
            self.outer.entry(name[..at].to_string()).or_insert_with(|| name.to_string());
        }
        self.names.insert(name.to_string());
    }
}
