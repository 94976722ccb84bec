//! Every kind of the bundled pipeline through the same paces: a build whose JSON summary follows
//! the contract of DESIGN §6, a no-op rebuild and a restart in which no stage runs, `check`
//! passing, and a graph that holds every asset and every artifact written. A new kind added to
//! the bundled pipeline is held to all of it without a line here.

use std::collections::BTreeSet;
use std::path::Path;

use cirrus::graph::NodeKind;
use cirrus::pipeline::load_pipeline;
use cirrus::project::{Project, ProjectOptions};
use cirrus::summary::{AssetStatus, StageStatus};

use crate::support::{build, TempProject};

/// The bundled pipeline in a temporary folder (its `examples` linked in).
fn bundled_project() -> TempProject {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let project = TempProject::new(&std::fs::read_to_string(root.join("pipeline.ron")).unwrap());
    std::os::unix::fs::symlink(root.join("examples"), project.path("examples")).unwrap();
    project
}

fn open(project: &TempProject) -> Project {
    Project::open(load_pipeline(&project.path("pipeline.ron")).unwrap(), ProjectOptions::default())
}

#[test]
fn every_bundled_kind_builds_rebuilds_for_free_checks_and_shows_in_the_graph() {
    let project = bundled_project();
    let mut first = open(&project);
    let summary = build(&mut first);
    assert!(summary.all_ok(), "{}", summary.to_text());
    let kinds: BTreeSet<&str> = summary.assets.iter().map(|asset| asset.kind).collect();
    assert_eq!(
        kinds,
        BTreeSet::from(["AmbientOcclusion", "Atlas", "BillboardCloud", "Height", "Material"]),
        "every kind is bundled"
    );

    // The summary contract.
    let json: serde_json::Value = serde_json::from_str(&summary.to_json()).unwrap();
    assert!(json["revision"].as_u64().is_some_and(|revision| revision > 0));
    for asset in json["assets"].as_array().unwrap() {
        // `warnings` only where the asset's report has some (the spot's UVs reach past [0, 1]).
        let keys: Vec<&String> = asset.as_object().unwrap().keys().filter(|key| *key != "warnings").collect();
        assert_eq!(keys, ["artifacts", "errors", "kind", "name", "stages", "status"], "{asset}");
        for warning in asset["warnings"].as_array().into_iter().flatten() {
            let keys: Vec<&String> = warning.as_object().unwrap().keys().collect();
            assert_eq!(keys, ["column", "file", "line", "message"], "{warning}");
        }
        assert_eq!(asset["status"], "ok");
        assert!(!asset["artifacts"].as_array().unwrap().is_empty(), "{asset}");
        for artifact in asset["artifacts"].as_array().unwrap() {
            let bytes = project.read(artifact["path"].as_str().unwrap());
            assert_eq!(artifact["hash"].as_str().unwrap(), blake3::hash(&bytes).to_hex().as_str(), "{artifact}");
        }
        for stage in asset["stages"].as_array().unwrap() {
            let keys: Vec<&String> = stage.as_object().unwrap().keys().collect();
            assert_eq!(keys, ["instance", "ms", "stage", "status"], "{stage}");
            assert!(["ran", "cached"].contains(&stage["status"].as_str().unwrap()), "{stage}");
        }
    }

    // Every artifact in the manifest says what it is, the same as its file's name says.
    let manifest: serde_json::Value = serde_json::from_slice(&project.read("baked/manifest.json")).unwrap();
    for (path, entry) in manifest["artifacts"].as_object().unwrap() {
        let extension = Path::new(path).extension().unwrap().to_string_lossy().to_string();
        let expected = match extension.as_str() {
            "ktx2" | "dds" | "pvr" => "texture",
            // PNG the kinds make, and the copies of source maps an MTL or glTF names (`maps/`).
            "png" | "jpg" => "image",
            "obj" => "mesh",
            "mtl" => "mtl",
            "gltf" => "gltf",
            "bin" => "gltf_buffer",
            _ if path.ends_with("/report.json") => "report",
            _ if ["/atlas.json", "/impostor.json", "/lods.json"].iter().any(|name| path.ends_with(name)) => "table",
            _ => panic!("an artifact cirrus should not write: {path}"),
        };
        assert_eq!(entry["role"], expected, "{path}");
    }

    // A no-op rebuild in the same process, then a restart: no stage runs, nothing is written.
    for (label, project_handle) in [("no-op rebuild", &mut first), ("restart", &mut open(&project))] {
        let again = build(project_handle);
        assert!(again.all_ok(), "{label}: {}", again.to_text());
        let ran: Vec<String> = again
            .assets
            .iter()
            .flat_map(|asset| asset.stages.iter().map(move |stage| (asset, stage)))
            .filter(|(_, stage)| stage.status == StageStatus::Ran)
            .map(|(asset, stage)| format!("{}:{}({})", asset.name, stage.stage, stage.instance))
            .collect();
        assert!(ran.is_empty(), "{label} ran stages: {ran:?}");
        assert!(again.changed.is_empty(), "{label} wrote {:?}", again.changed);
    }

    // check passes, for every asset: warnings at most (the bundled bush's leaf cards reach the
    // transparent border of their texture, which the foliage atlas keeps for them).
    let problems: Vec<_> = first
        .check()
        .into_iter()
        .filter(|(_, problems)| problems.iter().any(|problem| !problem.is_warning()))
        .collect();
    assert!(problems.is_empty(), "{problems:?}");

    // The graph holds every asset and every artifact the build wrote.
    let graph = first.graph();
    for asset in &summary.assets {
        assert!(graph.has_asset(&asset.name), "{} is not in the graph", asset.name);
        assert_eq!(asset.status, AssetStatus::Ok);
        for artifact in &asset.artifacts {
            assert!(
                graph.nodes.iter().any(|node| node.kind == NodeKind::Artifact && node.id == artifact.path),
                "{} is not in the graph",
                artifact.path
            );
        }
    }
}
