//! Publishing a build: each baked asset's artifacts written and listed in the manifest, its
//! summary, statuses and record; the summaries of the assets passed over; the manifest saved;
//! what the cache's `explain` reads of the build.

use std::collections::{BTreeMap, HashSet};
use std::path::PathBuf;

use super::graph::instance_record;
use super::publish_state::{BakedAsset, BuildNews};
use super::summaries::{asset_artifacts, stage_summaries, RunIndex};
use super::{Project, SourceReading};
use crate::artifacts::{record_artifact, remove_artifacts, save_manifest, Manifest};
use crate::config::AssetConfig;
use crate::db::{Asset, Db};
use crate::diagnostic::display_path;
use crate::kinds::stage_node_id;
use crate::record::{AssetRecord, FileStamp, InstanceRecord};
use crate::summary::ArtifactRole;
use crate::summary::{AssetStatus, AssetSummary, ChangedArtifact, ErrorSummary, StageStatus, StageSummary};

impl Project {
    /// Writes one baked asset's artifacts (the report last, only when every file was written),
    /// lists them in `manifest` under `next_revision`, removes its stale artifacts when it baked
    /// cleanly, and records its summary, stage statuses and (with a fingerprint, when clean) its
    /// record entry.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn publish_asset(
        &mut self,
        config: &AssetConfig,
        asset: Asset,
        baked: BakedAsset,
        fingerprint: Option<blake3::Hash>,
        run_index: &RunIndex,
        manifest: &mut Manifest,
        next_revision: u64,
        news: &mut BuildNews,
    ) {
        let BakedAsset { mut errors, failed_jobs, folder, outputs } = baked;
        // Writing is not interrupted (the manifest must list what was written), but an asset
        // baked from a source that went away meanwhile (a folder deleted while it baked, whose
        // event may not have arrived yet) is not published: the next build, which that
        // deletion asks for, removes what it had. (A failure is still reported.)
        if errors.is_empty() && !self.config.source_dir().join(config.source.main_file()).exists() {
            return;
        }
        let kind = asset.kind(&self.db);
        // Project-relative artifact path → blake3 hex of what this build wrote there.
        let mut produced = BTreeMap::new();
        let mut roles: BTreeMap<String, ArtifactRole> = BTreeMap::new();
        for (path, role, _) in &outputs.files {
            roles.insert(display_path(path), *role);
        }
        roles.insert(display_path(&folder.join("report.json")), ArtifactRole::Report);
        let warnings = outputs.warnings;
        // A failed asset keeps its last good artifacts, all of them: nothing of it is written.
        // Else every changed file is first written beside its place, and only when all are, each
        // is renamed into place, the report (which describes the others) last.
        if errors.is_empty() {
            let report = outputs.report.map(|mut report| {
                report.push(b'\n');
                (folder.join("report.json"), report)
            });
            let files = outputs.files.iter().map(|(path, _, bytes)| (path, &bytes[..]));
            let files: Vec<(&PathBuf, &[u8])> =
                files.chain(report.as_ref().map(|(path, bytes)| (path, &bytes[..]))).collect();
            self.write_artifacts(&files, &mut errors, &mut produced);
        }
        let asset_folder = format!("{}/", display_path(&folder));
        for (path, hash) in &produced {
            let meaning =
                outputs.meanings.iter().find(|(file, _)| display_path(file) == *path).map(|(_, meaning)| meaning);
            let role = roles.get(path).copied();
            if record_artifact(manifest, next_revision, &config.name, path, hash, meaning, role) {
                news.changed = true;
                news.changed_artifacts.push(ChangedArtifact {
                    role,
                    asset: config.name.clone(),
                    artifact: path.strip_prefix(&asset_folder).unwrap_or(path).to_string(),
                    path: path.clone(),
                    hash: hash.clone(),
                    meaning: meaning.cloned(),
                });
            }
        }
        let listed = crate::artifacts::artifacts_of(manifest, &config.name, &folder);
        if errors.is_empty() {
            // A fully baked asset owns exactly what it produced: drop stale artifacts.
            let stale = listed.iter().filter(|path| !produced.contains_key(*path)).cloned().collect();
            news.removed_artifacts.extend(remove_artifacts(&self.config, manifest, stale));
        }
        let instances = kind.stage_instances(&self.db, asset, &folder, &errors);
        let stages = stage_summaries(&instances, run_index, (&errors, &failed_jobs));
        for (instance, stage) in instances.iter().zip(&stages) {
            let state = stage.status.name();
            let ms = (stage.status == StageStatus::Ran).then_some((stage.ms * 10.0).round() / 10.0);
            news.statuses.insert(instance.node_id(), (state, ms));
        }
        let records: Vec<InstanceRecord> = instances.iter().map(instance_record).collect();
        // The record lets the next build pass over this asset while nothing it reads moves.
        match fingerprint.filter(|_| errors.is_empty()) {
            Some(fingerprint) => {
                let artifacts = produced
                    .keys()
                    .filter_map(|path| Some((path.clone(), FileStamp::read(&self.config.root.join(path))?)))
                    .collect();
                let files = asset.files(&self.db).keys().cloned().collect();
                let record = AssetRecord::new(fingerprint, files, artifacts, &records, warnings.clone());
                self.skip.insert_asset(&config.name, record);
                self.clean.remove(&config.name);
                self.mark_clean(&config.name);
            }
            None => {
                self.skip.remove_asset(&config.name);
                self.clean.remove(&config.name);
            }
        }
        self.built_instances.insert(config.name.clone(), records);
        news.summaries.push(AssetSummary {
            name: config.name.clone(),
            kind: kind.name(),
            status: if errors.is_empty() { AssetStatus::Ok } else { AssetStatus::Failed },
            stages,
            artifacts: asset_artifacts(manifest, &config.name, listed.iter().chain(produced.keys())),
            errors: errors.iter().map(ErrorSummary::from).collect(),
            warnings,
            passed_over: false,
        });
    }

    /// The summary of an asset the record let the build pass over.
    pub(super) fn passed_over_summary(&self, config: &AssetConfig, manifest: &Manifest) -> AssetSummary {
        let record = self.skip.asset(&config.name).expect("an asset passed over is recorded");
        let listed = crate::artifacts::artifacts_of(manifest, &config.name, &self.config.output.join(&config.name));
        let stages = record.stages().into_iter().map(|(stage, instance)| StageSummary {
            stage,
            instance,
            status: StageStatus::Cached,
            ms: 0.0,
        });
        AssetSummary {
            name: config.name.clone(),
            kind: config.source.kind().name(),
            status: AssetStatus::Ok,
            stages: stages.collect(),
            artifacts: asset_artifacts(manifest, &config.name, listed.iter()),
            errors: Vec::new(),
            warnings: record.warnings.clone(),
            passed_over: true,
        }
    }

    /// Gives a build that changed something its revision: the daemon writes the revision now and
    /// the manifest when idle; a build writes the manifest, and fails every asset when it cannot.
    pub(super) fn save_build_manifest(
        &mut self,
        manifest: &mut Manifest,
        next_revision: u64,
        summaries: &mut [AssetSummary],
    ) {
        let output_dir = self.config.output_dir();
        manifest.revision = next_revision;
        // The revision, which must never be issued twice, is also kept beside the record: a
        // manifest deleted or damaged by hand does not take it back.
        crate::record::save_revision(&output_dir, next_revision);
        if self.source_reading == SourceReading::WhenInvalidated {
            // The daemon: the manifest waits for an idle moment (`save_deferred`).
            self.published.mark_unsaved();
        } else if let Err(error) = save_manifest(&output_dir, manifest) {
            // Without the manifest, the next build cannot tell its artifacts from the user's
            // files: every asset of this build fails, so scripts and CI notice.
            let file = display_path(&self.config.output.join("manifest.json"));
            tracing::error!("cannot write {file}: {error}");
            for summary in summaries {
                self.skip.remove_asset(&summary.name);
                summary.status = AssetStatus::Failed;
                summary.errors.push(ErrorSummary {
                    file: file.clone(),
                    line: None,
                    column: None,
                    message: format!("cannot write the manifest: {error}"),
                });
            }
        }
    }

    /// What `cirrus cache explain` reads of this build: its counts, misses, and each asset's
    /// stage statuses (the assets passed over by name only).
    pub(super) fn write_last_build(&self, summaries: &[AssetSummary], unchanged: &[&AssetConfig], revision: u64) {
        if let Some(cache) = self.db.disk_cache() {
            // The assets passed over are named, not listed stage by stage.
            let passed_over: HashSet<&str> = unchanged.iter().map(|config| config.name.as_str()).collect();
            let assets = summaries
                .iter()
                .filter(|asset| !passed_over.contains(asset.name.as_str()))
                .map(|asset| crate::cache::upkeep::LastBuildAsset {
                    name: asset.name.clone(),
                    stages: asset
                        .stages
                        .iter()
                        .map(|stage| (stage_node_id(&stage.stage, &stage.instance), stage.status.name().to_string()))
                        .collect(),
                })
                .collect();
            let last = crate::cache::upkeep::LastBuild {
                revision,
                counts: cache.take_counts(),
                remote: cache.remote().map(|remote| remote.settings().url.clone()),
                assets,
                unchanged: unchanged.iter().map(|config| config.name.clone()).collect(),
                misses: cache.take_misses(),
            };
            crate::cache::upkeep::write_last_build(cache.folder(), &last);
        }
    }
}
