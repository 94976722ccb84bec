//! What a build hands its groups of assets, and what baking them gives back (see `groups`).

use std::collections::HashMap;

use crate::config::AssetConfig;
use crate::db::{Asset, StageRun};
use crate::schedule::{CancelFlag, Progress};

/// What every group of a build shares.
pub(super) struct Baking<'a> {
    /// Every asset of the pipeline (for the assets read by those baked).
    pub all_assets: &'a [AssetConfig],
    /// The revision the build publishes under.
    pub next_revision: u64,
    pub progress: &'a (dyn Fn(Progress) + Sync),
    pub cancel: &'a CancelFlag,
}

/// What baking in groups did.
pub(super) struct GroupsBaked {
    /// The assets baked, by name (for the fingerprints of those that read another's).
    pub built: HashMap<String, Asset>,
    /// Every stage run of every group.
    pub runs: Vec<StageRun>,
    /// How many groups were baked and published.
    pub groups: usize,
    /// Whether the build was cancelled (after `groups` groups).
    pub cancelled: bool,
}
