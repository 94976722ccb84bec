//! A build's summary pieces: each asset's stage runs and their statuses, its artifacts.

use std::collections::{BTreeSet, HashMap, HashSet};

use crate::artifacts::Manifest;
use crate::db::StageRun;
use crate::diagnostic::Diagnostic;
use crate::kinds::StageInstance;
use crate::summary::{ArtifactSummary, StageStatus, StageSummary};

/// The stage runs labelled by each asset's name or below it (`name/…`): what its kind's report
/// may time. One pass over the runs, each label looked up at each of its `/`.
pub(super) fn runs_by_asset<'a>(
    runs: &[StageRun],
    names: impl Iterator<Item = &'a str>,
) -> HashMap<&'a str, Vec<StageRun>> {
    let names: HashSet<&str> = names.collect();
    let mut by_asset: HashMap<&str, Vec<StageRun>> = HashMap::new();
    for run in runs {
        let label = run.label.as_str();
        let prefixes = label.match_indices('/').map(|(at, _)| &label[..at]).chain([label]);
        if let Some(name) = prefixes.filter_map(|prefix| names.get(prefix)).next() {
            by_asset.entry(name).or_default().push(run.clone());
        }
    }
    by_asset
}

/// What a build's stage runs say of each stage instance (`(stage, label)`), gathered once per
/// build so that each asset's summary looks up only its own instances.
#[derive(Default)]
pub(super) struct RunIndex<'a> {
    instances: HashMap<(&'a str, &'a str), InstanceRuns>,
}

#[derive(Clone, Copy, Default)]
struct InstanceRuns {
    /// Milliseconds of the bodies that ran (not from a cache).
    ran_ms: Option<f64>,
    local_hit: bool,
    remote_hit: bool,
}

impl<'a> RunIndex<'a> {
    pub(super) fn new(runs: &'a [StageRun]) -> RunIndex<'a> {
        let mut index = RunIndex::default();
        for run in runs {
            let entry = index.instances.entry((run.stage, run.label.as_str())).or_default();
            match (run.from_cache, run.from_remote) {
                (false, _) => *entry.ran_ms.get_or_insert(0.0) += run.ms,
                (true, true) => entry.remote_hit = true,
                (true, false) => entry.local_hit = true,
            }
        }
        index
    }

    fn get(&self, instance: &StageInstance) -> InstanceRuns {
        self.instances.get(&(instance.stage.name, instance.label.as_str())).copied().unwrap_or_default()
    }
}

/// The summary of each stage instance: ran when this build ran it, failed when the asset
/// failed before it had a result (its kind says, or its job failed), remote when its result
/// came from the shared cache, cached otherwise. A stage that needed no result of its own
/// (what it feeds was found in a cache) is remote when every cache hit of its asset in this
/// build came from the shared cache, and cached otherwise.
pub(super) fn stage_summaries(
    instances: &[StageInstance],
    runs: &RunIndex,
    (errors, failed_jobs): (&[Diagnostic], &HashSet<String>),
) -> Vec<StageSummary> {
    let asset_failed = !errors.is_empty();
    // A stage that ran and failed: it is marked failed and reads the file an error names (the
    // OBJ a mesh stage could not parse), so that the summary's `failed` counts it.
    let failed_here = |instance: &StageInstance| {
        instance.failed
            && instance.reads.iter().any(
                |read| matches!(read, crate::kinds::Read::File(path) if errors.iter().any(|error| &error.file == path)),
            )
    };
    let facts: Vec<InstanceRuns> = instances.iter().map(|instance| runs.get(instance)).collect();
    let any_hit = facts.iter().any(|facts| facts.local_hit || facts.remote_hit);
    let every_hit_remote = any_hit && !facts.iter().any(|facts| facts.local_hit);
    instances
        .iter()
        .zip(facts)
        .map(|(instance, facts)| {
            let (status, ms) = match facts.ran_ms {
                Some(ms) if asset_failed && failed_here(instance) => (StageStatus::Failed, ms),
                Some(ms) => (StageStatus::Ran, ms),
                None if asset_failed && (instance.failed || failed_jobs.contains(&instance.label)) => {
                    (StageStatus::Failed, 0.0)
                }
                None if !facts.local_hit && (facts.remote_hit || every_hit_remote) => (StageStatus::Remote, 0.0),
                None => (StageStatus::Cached, 0.0),
            };
            StageSummary { stage: instance.stage.name.to_string(), instance: instance.instance.clone(), status, ms }
        })
        .collect()
}

/// The artifacts the manifest lists for an asset, of the `paths` that may be its (sorted).
pub(super) fn asset_artifacts<'a>(
    manifest: &Manifest,
    asset: &str,
    paths: impl Iterator<Item = &'a String>,
) -> Vec<ArtifactSummary> {
    let paths: BTreeSet<&String> = paths.collect();
    let entries = paths.into_iter().filter_map(|path| Some((path, manifest.artifacts.get(path)?)));
    let entries = entries.filter(|(_, entry)| entry.asset == asset);
    entries.map(|(path, entry)| ArtifactSummary { path: path.clone(), hash: entry.hash.clone() }).collect()
}
