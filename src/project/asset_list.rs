//! The pipeline's asset list: the listed assets, then the files the rules match that become
//! assets (a warning for each that cannot: a reserved name, a folder that collides), kept by
//! the daemon until an edit may change it, and which list's departed assets were last removed.

use std::cell::RefCell;
use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::config::{AssetConfig, PipelineConfig};
use crate::diagnostic::{display_path, Diagnostic};
use crate::sources::rule_matches;

/// The assets of the pipeline, and the rule-matched files that do not become assets.
pub type AssetList = (Vec<AssetConfig>, Vec<Diagnostic>);

/// The asset list as the project keeps it.
#[derive(Debug, Default)]
pub struct AssetLists {
    /// The daemon's asset list, until an edit may change it.
    kept: RefCell<Option<Arc<AssetList>>>,
    /// The asset list whose departed assets' artifacts were last removed.
    departures_checked: Option<Arc<AssetList>>,
}

impl AssetLists {
    /// The asset list of `config`: the one kept when `keep` (the daemon) and there is one, else
    /// listed afresh (and kept).
    pub fn get(&self, config: &PipelineConfig, keep: bool) -> Arc<AssetList> {
        let mut kept = self.kept.borrow_mut();
        if let Some(list) = kept.as_ref().filter(|_| keep) {
            return list.clone();
        }
        let list = Arc::new(list_assets(config));
        *kept = Some(list.clone());
        list
    }

    /// Forgets the kept list: the next one is listed afresh.
    pub fn forget(&mut self) {
        *self.kept.get_mut() = None;
    }

    /// Forgets the kept list when `path` (project-relative; `known` when some asset reads it)
    /// may change it: a file that a rule matches, or one no asset reads (new, or a folder).
    pub fn forget_for(&mut self, config: &PipelineConfig, path: &Path, known: bool) {
        if config.rules.is_empty() {
            return;
        }
        let matched = path.strip_prefix(&config.source).is_ok_and(|relative| {
            let relative = PathBuf::from(display_path(relative));
            config.rules.iter().any(|rule| rule.matcher.is_match(&relative))
        });
        if !known || matched {
            self.forget();
        }
    }

    /// Whether `list`'s departed assets were looked for already (only a new list can have lost
    /// assets, so the daemon looks once per list).
    pub fn departures_checked(&self, list: &Arc<AssetList>) -> bool {
        self.departures_checked.as_ref().is_some_and(|checked| Arc::ptr_eq(checked, list))
    }

    /// Notes that `list`'s departed assets were looked for.
    pub fn note_departures_checked(&mut self, list: &Arc<AssetList>) {
        self.departures_checked = Some(list.clone());
    }
}

/// The assets of `config`: the listed ones, then files matching its rules, with a warning for
/// each rule-matched file that does not become an asset.
pub fn list_assets(config: &PipelineConfig) -> AssetList {
    let mut assets = config.assets.clone();
    let mut conflicts = Vec::new();
    let mut folders = crate::config::AssetFolders::default();
    let mut by_name: HashMap<String, usize> = HashMap::new();
    for (index, asset) in assets.iter().enumerate() {
        folders.insert(&asset.name);
        by_name.insert(asset.name.clone(), index);
    }
    let listed_files: HashSet<&Path> = config.assets.iter().map(|asset| asset.source.main_file()).collect();
    for relative in rule_matches(config) {
        if listed_files.contains(relative.as_path()) {
            continue;
        }
        let Some(asset) = config.rule_asset(&relative) else { continue };
        let file = config.source.join(&relative);
        if let Some(reserved) = crate::config::reserved_asset_name(&asset.name) {
            conflicts.push(Diagnostic::new(file, format!("matches a rule but is not baked: {reserved}")).as_warning());
        } else if let Some(other) = folders.collision(&asset.name).map(|name| &assets[by_name[name]]) {
            let message = format!(
                "matches a rule but is not baked: its asset name `{}` collides with the asset `{}` ({})",
                asset.name,
                other.name,
                display_path(&config.source.join(other.source.main_file()))
            );
            conflicts.push(Diagnostic::new(file, message).as_warning());
        } else {
            folders.insert(&asset.name);
            by_name.insert(asset.name.clone(), assets.len());
            assets.push(asset);
        }
    }
    (assets, conflicts)
}
