//! The process's memory budget as the driver spends it: what each asset is estimated to need
//! while it bakes and to keep after, the groups a build bakes and publishes one after another so
//! that what a group holds until it publishes fits the budget, and which assets the daemon keeps
//! the intermediates of (those baked last, as far as the budget's share for them goes).

use std::collections::{HashSet, VecDeque};

/// What a build holds of an asset from its bake until its group publishes, per texel of its
/// source images: its source bytes (compressed, about 3 B a texel for noisy maps), its finished
/// files (about 1.4 B: block-compressed levels and a preview) and the asset's share of the
/// salsa graph. Measured on `make_level`'s Materials: 4.0 to 5.4 B a texel over a whole build.
const HELD_BYTES_PER_TEXEL: u64 = 6;

/// What the daemon keeps of an asset whose intermediates it keeps, per texel of its source
/// images (decoded maps, packed images, mip chains, blocks, the last encodings): measured 14.5
/// to 15.3 B on `make_level`'s Materials.
const KEPT_BYTES_PER_TEXEL: u64 = 16;

/// The least an asset is counted for, whatever its sources and what its kind says it makes.
const LEAST_ASSET_BYTES: u64 = 8 << 20;

/// The LRU capacity that bounds nothing but still records every use (salsa's 0 records none, so
/// that memos made under it could never be evicted later).
pub(super) const UNBOUNDED_MEMOS: usize = usize::MAX >> 1;

/// What the driver estimates of an asset from the files its kind reads.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct AssetCost {
    /// Bytes held from its bake until its group publishes.
    pub held: u64,
    /// Bytes its intermediates take when they are kept.
    pub kept: u64,
    /// Surfaces it makes (before its first bake: one per source image, at least one).
    pub surfaces: usize,
    /// Source images it decodes.
    pub images: usize,
}

impl AssetCost {
    /// The estimate for an asset whose source files hold `texels` texels in `images` images and
    /// `bytes` bytes in all, and whose kind holds `made` bytes for the images it makes itself
    /// (`Kind::made_bytes`).
    pub fn of_sources(texels: u64, images: usize, bytes: u64, made: u64) -> AssetCost {
        AssetCost {
            held: (texels * HELD_BYTES_PER_TEXEL + bytes + made).max(LEAST_ASSET_BYTES),
            kept: (texels * KEPT_BYTES_PER_TEXEL + bytes + made).max(LEAST_ASSET_BYTES),
            surfaces: images.max(1),
            images,
        }
    }
}

/// How the budget is shared (of `budget` bytes): a quarter for the intermediates the daemon
/// keeps, half for what a group of assets holds until it publishes, and a quarter for the
/// work in flight (the textures being filtered and encoded, themselves bounded by
/// `texture_memory_mib`) and the process itself.
#[derive(Clone, Debug)]
pub struct MemoryPolicy {
    budget: u64,
    /// The assets baked so far, the last baked first, with their estimates.
    recent: VecDeque<(String, AssetCost)>,
}

impl MemoryPolicy {
    pub fn new(budget: u64) -> MemoryPolicy {
        MemoryPolicy { budget, recent: VecDeque::new() }
    }

    /// The budget in bytes.
    pub fn budget(&self) -> u64 {
        self.budget
    }

    pub fn set_budget(&mut self, budget: u64) {
        self.budget = budget;
    }

    /// What a group of assets may hold until it publishes.
    pub fn group_share(&self) -> u64 {
        self.budget / 2
    }

    /// What the work in flight may take at once: the textures being filtered and encoded (the
    /// ceiling of the process's texture memory, whatever `texture_memory_mib` allows).
    pub fn in_flight_share(&self) -> u64 {
        self.budget / 4
    }

    /// What the kept intermediates may take.
    pub fn kept_share(&self) -> u64 {
        self.budget / 4
    }

    /// The assets to keep the intermediates of while `group` bakes: the group's (its last
    /// first), then those baked last, as many as the kept share holds (recency decides: an older asset is not kept
    /// in place of a newer one that does not fit).
    pub fn kept_with(&self, group: &[(String, AssetCost)]) -> HashSet<String> {
        let mut kept = HashSet::new();
        let mut bytes = 0u64;
        for (name, cost) in group.iter().rev().chain(self.recent.iter()) {
            if kept.contains(name) {
                continue;
            }
            if bytes + cost.kept > self.kept_share() {
                break;
            }
            bytes += cost.kept;
            kept.insert(name.clone());
        }
        kept
    }

    /// The surfaces and the source images of the assets `kept` (names of assets baked): what
    /// each function's memos of surfaces, and of decoded images, are bounded to.
    pub fn kept_memos(&self, kept: &HashSet<String>) -> (usize, usize) {
        let counted = self.recent.iter().filter(|(name, _)| kept.contains(name));
        counted.fold((0, 0), |(surfaces, images), (_, cost)| (surfaces + cost.surfaces, images + cost.images))
    }

    /// Notes that `group` was baked (its assets are now the last baked).
    pub fn baked(&mut self, group: &[(String, AssetCost)]) {
        let names: HashSet<&String> = group.iter().map(|(name, _)| name).collect();
        self.recent.retain(|(name, _)| !names.contains(name));
        // The group's last asset is the last baked.
        for entry in group {
            self.recent.push_front(entry.clone());
        }
        // Only as many as the kept share could ever hold are worth remembering.
        let least = LEAST_ASSET_BYTES.min(self.kept_share().max(1));
        let most = (self.kept_share() / least) as usize + group.len();
        self.recent.truncate(most);
    }
}
