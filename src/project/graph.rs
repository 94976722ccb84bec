//! The dependency graph of the project (or of some assets): from the kinds' stage instances,
//! or from the record for assets it holds unchanged.

use std::collections::HashSet;
use std::path::Path;

use super::Project;
use crate::diagnostic::display_path;
use crate::kinds::{stage_node_id, Read, StageInstance};
use crate::record::{InstanceRecord, ReadRecord};

impl Project {
    /// The dependency graph of every asset: source files, stage instances and artifacts, with
    /// an edge for each read a stage function makes (the same stage instances the summary lists).
    /// Reads the sources and runs the stages that tell the instances (a billboard cloud's
    /// layout) where needed.
    pub fn graph(&mut self) -> crate::graph::Graph {
        self.graph_of_assets(None)
    }

    /// [`Project::graph`] of the named assets only (all when `None`).
    pub fn graph_of_assets(&mut self, only: Option<&HashSet<String>>) -> crate::graph::Graph {
        use crate::graph::{GraphBuilder, Node, NodeKind};
        let mut graph = GraphBuilder::default();
        let manifest = self.take_manifest();
        let listed = self.asset_list_and_conflicts();
        self.clean.keep_for(&listed);
        let list = &listed.0;
        // An asset that the record holds as it is now: its instances from there; any other
        // through its kind (which may read its sources and run the stages that tell them).
        // The last build's instances hold while no input changed since it finished.
        let last_build_holds = !self.sources_changed_since_build;
        let mut all_instances: Vec<(String, Vec<InstanceRecord>)> = Vec::new();
        let mut synced = Vec::new();
        for config in list.iter().filter(|config| only.is_none_or(|only| only.contains(&config.name))) {
            if let Some(instances) = self.built_instances.get(&config.name).filter(|_| last_build_holds) {
                all_instances.push((config.name.clone(), instances.clone()));
            } else if self.unchanged_asset(config, list, &manifest) {
                let record = self.skip.asset(&config.name).expect("an unchanged asset is recorded");
                all_instances.push((config.name.clone(), record.instances()));
            } else {
                synced.push((config.clone(), self.sync_asset(config)));
            }
        }
        self.sync_registry(list, &synced);
        for (config, asset) in synced {
            let folder = self.config.output.join(&config.name);
            let instances = asset.kind(&self.db).stage_instances(&self.db, asset, &folder, &[]);
            all_instances.push((config.name, instances.iter().map(instance_record).collect()));
        }
        let runs = self.db.take_runs();
        self.record_runs(&runs, self.revision);
        for (asset, instances) in &all_instances {
            for instance in instances {
                let id = stage_node_id(&instance.stage, &instance.label);
                let last = self.history.get(&id);
                // Instances without a status in the last summary: from the history.
                let (state, ms) = self.last_statuses.get(&id).cloned().unwrap_or(match (self.last_revision, last) {
                    (None, _) => ("pending", None),
                    (Some(revision), Some((ran, ms))) if *ran == revision => ("ran", Some((ms * 10.0).round() / 10.0)),
                    (Some(_), _) => ("cached", None),
                });
                graph.node(Node {
                    id: id.clone(),
                    kind: NodeKind::Stage,
                    label: id.clone(),
                    asset: (!instance.shared).then(|| asset.clone()),
                    revision: last.map(|(revision, _)| *revision),
                    ms: ms.or(last.map(|(_, ms)| (ms * 10.0).round() / 10.0)),
                    state: state.to_string(),
                });
                for read in &instance.reads {
                    let from = match read {
                        ReadRecord::File(path) => self.file_node(&mut graph, path),
                        ReadRecord::Stage(id) => id.clone(),
                    };
                    graph.edge(&from, &id);
                }
                for artifact in &instance.writes {
                    let artifact = artifact.clone();
                    let entry = manifest.artifacts.get(&artifact);
                    graph.node(Node {
                        id: artifact.clone(),
                        kind: NodeKind::Artifact,
                        label: artifact.clone(),
                        asset: Some(asset.clone()),
                        revision: entry.map(|entry| entry.revision),
                        ms: None,
                        state: if entry.is_some() { "written" } else { "pending" }.to_string(),
                    });
                    graph.edge(&id, &artifact);
                }
            }
        }
        self.keep_manifest(manifest);
        graph.finish()
    }

    /// Adds the node of a source file; returns its id.
    pub(super) fn file_node(&self, graph: &mut crate::graph::GraphBuilder, path: &str) -> String {
        let id = path.to_string();
        let path = Path::new(path);
        let present = match self.files.get(path) {
            Some(file) => file.contents(&self.db).is_ok(),
            None => matches!(self.known.get(path), Some(Ok(_))) || self.skip.record().files.contains_key(path),
        };
        graph.node(crate::graph::Node {
            id: id.clone(),
            kind: crate::graph::NodeKind::File,
            label: id.clone(),
            asset: None,
            revision: self.history.get(&id).map(|(revision, _)| *revision),
            ms: None,
            state: if present { "present" } else { "missing" }.to_string(),
        });
        id
    }
}

/// A stage instance as the record keeps it (owned names, reads as graph node ids).
pub(super) fn instance_record(instance: &StageInstance) -> InstanceRecord {
    let reads = instance.reads.iter().map(|read| match read {
        Read::File(path) => ReadRecord::File(display_path(path)),
        Read::Stage(stage, label) => ReadRecord::Stage(stage_node_id(stage.name, label)),
    });
    InstanceRecord::new(
        instance.stage.name.to_string(),
        instance.label.clone(),
        instance.instance.clone(),
        reads.collect(),
        instance.writes.iter().map(|path| display_path(path)).collect(),
        instance.shared,
    )
}
