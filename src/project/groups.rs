//! Baking in groups that fit the memory budget: the next group read from the assets to bake,
//! what is kept of each before it bakes (the daemon's kept assets, the memos' capacities), and
//! what is let go once it published (source bytes, evicted memos, freed heap pages).

use std::collections::{HashMap, HashSet};

use super::baking::{Baking, GroupsBaked};
use super::budget::{AssetCost, UNBOUNDED_MEMOS};
use super::publish_state::BuildNews;
use super::summaries::RunIndex;
use super::{Project, SourceReading};
use crate::artifacts::Manifest;
use crate::config::AssetConfig;
use crate::db::{Asset, Retention, SourceFile};

/// A group of assets to bake together: each with its input and its estimate.
pub(super) type Group = Vec<(AssetConfig, Asset, AssetCost)>;

impl Project {
    /// Bakes `dirty` in groups that fit the memory budget, each published (and its memory let go)
    /// before the next is read; `cirrus build` writes the manifest and the record after each, so
    /// that a build killed between groups leaves every published asset whole and listed. A cancel
    /// stops it between groups or within one (whose assets are then not published).
    pub(super) fn bake_in_groups(
        &mut self,
        dirty: Vec<&AssetConfig>,
        baking: &Baking<'_>,
        manifest: &mut Manifest,
        news: &mut BuildNews,
    ) -> GroupsBaked {
        let mut baked = GroupsBaked { built: HashMap::new(), runs: Vec::new(), groups: 0, cancelled: false };
        let mut pending = dirty.into_iter().peekable();
        let mut carried = None;
        while carried.is_some() || pending.peek().is_some() {
            let group = self.next_group(&mut pending, &mut carried);
            if baking.cancel.is_raised() {
                baked.cancelled = true;
                break;
            }
            self.prepare_memory(&group);
            let assets: Vec<(AssetConfig, Asset)> =
                group.iter().map(|(config, asset, _)| (config.clone(), *asset)).collect();
            self.sync_registry(baking.all_assets, &assets);
            let Some((runs, failures, surfaces)) = self.run_asset_jobs(&assets, baking.progress, baking.cancel) else {
                baked.cancelled = true;
                break;
            };
            let run_index = RunIndex::new(&runs);
            // Every asset's files of the group are put together before any is written: an edit
            // meanwhile (a folder of sources deleted) still cancels the group, and nothing of it
            // is published.
            let Some(all_outputs) = self.asset_outputs(&assets, &runs, failures, baking.cancel) else {
                baked.cancelled = true;
                break;
            };
            baked.built.extend(assets.iter().map(|(config, asset)| (config.name.clone(), *asset)));
            // Each baked asset's fingerprint, of the files its input read.
            let fingerprints: Vec<Option<blake3::Hash>> = assets
                .iter()
                .map(|(config, _)| self.current_fingerprint(config, baking.all_assets, &baked.built, 0))
                .collect();
            if baked.groups == 0 {
                crate::record::begin_writing(&self.config.output_dir());
            }
            baked.groups += 1;
            let revision = baking.next_revision;
            for ((config, asset), (outputs, fingerprint)) in
                assets.iter().zip(all_outputs.into_iter().zip(fingerprints))
            {
                self.publish_asset(config, *asset, outputs, fingerprint, &run_index, manifest, revision, news);
            }
            baked.runs.extend(runs);
            let more = carried.is_some() || pending.peek().is_some();
            if more && self.source_reading == SourceReading::EveryBuild {
                // What a build killed now leaves: each published asset whole and listed, the
                // record passing over it next time.
                self.save_build_manifest(manifest, revision, &mut []);
                self.save_record();
            }
            self.release_memory(&group, &surfaces);
        }
        baked
    }

    /// The next group of `pending` (and of the asset `carried` over from the last call, which
    /// did not fit it): assets are read (synced) one by one until what they hold while baking
    /// would pass the group's share of the budget. An asset that alone needs more still bakes,
    /// alone, with a warning that names it.
    pub(super) fn next_group<'a>(
        &mut self,
        pending: &mut std::iter::Peekable<impl Iterator<Item = &'a AssetConfig>>,
        carried: &mut Option<(AssetConfig, Asset, AssetCost)>,
    ) -> Group {
        let share = self.memory.group_share();
        let mut group: Group = carried.take().into_iter().collect();
        let mut held: u64 = group.iter().map(|(_, _, cost)| cost.held).sum();
        while group.len() == 1 || held < share {
            if group.len() == 1 && held > share {
                let (config, _, cost) = &group[0];
                tracing::warn!(
                    "asset `{}` needs about {} MiB while it bakes, more than half the memory budget of {} MiB: \
                     it bakes alone (raise `limits: (memory_mib: …)` or `--memory-mib`)",
                    config.name,
                    cost.held >> 20,
                    self.memory.budget() >> 20
                );
                break;
            }
            let Some(config) = pending.next() else { break };
            let asset = self.sync_asset(config);
            let cost = self.asset_cost(asset);
            if !group.is_empty() && held + cost.held > share {
                *carried = Some((config.clone(), asset, cost));
                break;
            }
            held += cost.held;
            group.push((config.clone(), asset, cost));
        }
        group
    }

    /// The estimate of an asset from its source files: the texels of those that are images (from
    /// their headers), and their bytes.
    fn asset_cost(&self, asset: Asset) -> AssetCost {
        let limits = self.config.limits.texture;
        let (mut texels, mut images, mut bytes) = (0u64, 0usize, 0u64);
        for (path, file) in asset.files(&self.db).iter() {
            let Ok(contents) = file.contents(&self.db) else { continue };
            bytes += contents.len;
            let Ok(kept) = contents.bytes() else { continue };
            if let Ok((width, height)) = crate::texture::probe_texture(path, &kept, limits) {
                texels += u64::from(width) * u64::from(height);
                images += 1;
            }
        }
        let made = asset.kind(&self.db).made_bytes(&self.db, asset);
        tracing::debug!("asset `{}`: {texels} source texels, {} MiB made", asset.name(&self.db), made >> 20);
        AssetCost::of_sources(texels, images, bytes, made)
    }

    /// Bounds each function's memos of large values to `surfaces` (the tail's and every kind's
    /// per surface) and `images` (the decoded source images).
    pub(super) fn set_memo_capacity(&mut self, surfaces: usize, images: usize) {
        crate::kinds::tail_queries::keep_memos(&mut self.db, surfaces);
        crate::db::keep_decoded(&mut self.db, images);
        for kind in crate::kinds::entries::ALL {
            kind.keep_memos(&mut self.db, surfaces);
        }
    }

    /// Bounds the memos to `surfaces` and `images` (at least one each: salsa's 0 would stop
    /// recording uses) and evicts those past the bound now.
    fn evict_memos_past(&mut self, surfaces: usize, images: usize) {
        self.set_memo_capacity(surfaces.max(1), images.max(1));
        salsa::Database::trigger_lru_eviction(&mut self.db);
    }

    /// Before `group` bakes: where the process keeps intermediates, which assets keep them (the
    /// group's and those baked last, as far as the budget's share for them goes).
    pub(super) fn prepare_memory(&mut self, group: &Group) {
        let costs: Vec<(String, AssetCost)> =
            group.iter().map(|(config, _, cost)| (config.name.clone(), *cost)).collect();
        let kept = match self.options.retention {
            Retention::KeepForNextBuild => self.memory.kept_with(&costs),
            Retention::OutputsOnly => HashSet::new(),
        };
        let dropped: Vec<String> = self.kept.difference(&kept).cloned().collect();
        let kept_inputs = kept.iter().filter_map(|name| self.assets.get(name).copied()).collect();
        self.db.keep_only(Some(kept_inputs), &dropped);
        // The sources of the assets no longer kept are let go too, but for those that a kept
        // asset or one of the group reads as well.
        let dropped_assets: Vec<Asset> = dropped.iter().filter_map(|name| self.assets.get(name).copied()).collect();
        let group_assets = group.iter().map(|(_, asset, _)| *asset);
        self.release_sources(
            &dropped_assets,
            kept.iter().filter_map(|name| self.assets.get(name).copied()).chain(group_assets),
        );
        if !dropped.is_empty() {
            // Their intermediates go before the group makes its own: otherwise the last group's
            // kept assets and this group's would be held together until it publishes (a daemon's
            // first batch held twice the kept share at its peak).
            let staying: HashSet<String> = self.kept.intersection(&kept).cloned().collect();
            let (surfaces, images) = self.memory.kept_memos(&staying);
            self.evict_memos_past(surfaces, images);
        }
        self.kept = kept;
    }

    /// Lets go of the bytes of the source files of `assets` (read back when a stage needs them),
    /// but for those that one of `staying` reads too (a texture two materials share): a stage of
    /// a kept asset never reads its sources back from disk.
    fn release_sources(&self, assets: &[Asset], staying: impl Iterator<Item = Asset>) {
        if assets.is_empty() {
            return;
        }
        let held: HashSet<SourceFile> =
            staying.flat_map(|asset| asset.files(&self.db).values().copied().collect::<Vec<_>>()).collect();
        for asset in assets {
            for file in asset.files(&self.db).values().filter(|file| !held.contains(file)) {
                if let Ok(contents) = file.contents(&self.db) {
                    contents.release();
                }
            }
        }
    }

    /// After `group` published (its assets' surface jobs counted in `surfaces`): the source bytes
    /// of its assets that keep no intermediates are let go (read back when a stage needs them
    /// again), salsa evicts the memos past the kept assets' (all of them while every asset is
    /// kept), and the heaps hand freed pages back.
    pub(super) fn release_memory(&mut self, group: &Group, surfaces: &HashMap<Asset, usize>) {
        let costs: Vec<(String, AssetCost)> = group
            .iter()
            .map(|(config, asset, cost)| {
                let surfaces = surfaces.get(asset).copied().unwrap_or(cost.surfaces);
                (config.name.clone(), AssetCost { surfaces, ..*cost })
            })
            .collect();
        self.memory.baked(&costs);
        let let_go: Vec<Asset> = group
            .iter()
            .filter(|(config, _, _)| !self.kept.contains(&config.name))
            .map(|(_, asset, _)| *asset)
            .collect();
        self.release_sources(&let_go, self.kept.iter().filter_map(|name| self.assets.get(name).copied()));
        // Salsa's LRU counts memos, not bytes, and each function its own: those of surfaces are
        // bounded to the kept assets' surfaces, the decoded images to their images; every memo
        // stays while the process keeps every asset.
        let every_asset_kept = self.assets.keys().all(|name| self.kept.contains(name));
        let (surfaces, images) = match every_asset_kept {
            true => (UNBOUNDED_MEMOS, UNBOUNDED_MEMOS),
            false => self.memory.kept_memos(&self.kept),
        };
        self.evict_memos_past(surfaces, images);
        crate::memory::release_freed_memory();
        tracing::debug!(
            "group of {} asset(s) published: {} kept, memos of {surfaces} surfaces and {images} images, {} MiB of \
             source bytes in memory, \
             {} MiB resident",
            group.len(),
            self.kept.len(),
            self.source_bytes_in_memory() >> 20,
            crate::memory::resident_bytes().unwrap_or(0) >> 20
        );
    }
}
