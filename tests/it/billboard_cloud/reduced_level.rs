//! Reduced levels of a LOD chain (`lods: [Reduced(Triangles(30)), Quads(4)]`): the mesh under its
//! triangle budget in `lod0/` over copies of its maps, no planes, atlas or renders for it; a map
//! edit copies the map again and rewrites the MTL without reducing again; a restart runs nothing;
//! the preview and the viewer show the level with its own materials.

use std::collections::BTreeSet;

use crate::billboard_cloud::chain::chain_project;
use crate::support::{build, pattern_png};

/// Faces of an OBJ.
fn faces(obj: &[u8]) -> usize {
    String::from_utf8_lossy(obj).lines().filter(|line| line.starts_with("f ")).count()
}

/// The files an MTL's map statements name.
fn mtl_maps(mtl: &[u8]) -> BTreeSet<String> {
    String::from_utf8_lossy(mtl)
        .lines()
        .filter(|line| line.starts_with("map_") || line.starts_with("norm "))
        .filter_map(|line| line.split_whitespace().last().map(str::to_string))
        .collect()
}

#[test]
fn a_reduced_level_keeps_its_budget_over_copies_of_its_maps_and_a_map_edit_reduces_nothing() {
    let project = chain_project("[Reduced(Triangles(30)), Quads(4)]");
    let mut cirrus = project.open();
    let summary = build(&mut cirrus);
    assert!(summary.all_ok(), "{}", summary.to_text());
    let executed = cirrus.take_executed_stages();
    let count = |stage: &str| executed.iter().filter(|run| run.starts_with(stage)).count();
    assert_eq!(
        (count("mesh(tree)"), count("reduce(tree/lod0)"), count("planes(tree/lod1)")),
        (1, 1, 1),
        "{executed:?}"
    );
    for stage in ["planes(tree/lod0)", "layout(tree/lod0)", "render(tree/lod0", "atlas(tree/lod0)", "lod(tree/lod0)"] {
        assert_eq!(count(stage), 0, "a reduced level has no {stage}: {executed:?}");
    }
    let obj = project.read("baked/tree/lod0/lod.obj");
    let triangles = faces(&obj);
    assert!(triangles <= 30 && triangles > 0, "{triangles} triangles for a budget of 30");
    let report: serde_json::Value = serde_json::from_slice(&project.read("baked/tree/report.json")).unwrap();
    let level = &report["levels"][0];
    assert_eq!(level["representation"], "reduced");
    assert_eq!(level["budget"], serde_json::json!({ "triangles": 30 }));
    assert_eq!(level["triangles"], triangles);
    assert_eq!(report["levels"][1]["representation"], "billboard_cloud");
    // Every map the level's MTL names is a copy in its own maps/, marked as the level's.
    let manifest: serde_json::Value = serde_json::from_slice(&project.read("baked/manifest.json")).unwrap();
    let maps = mtl_maps(&project.read("baked/tree/lod0/lod.mtl"));
    assert_eq!(maps.len(), 3, "bark, its normal map and the leaf: {maps:?}");
    let mut bytes = obj.len() + project.read("baked/tree/lod0/lod.mtl").len();
    for map in &maps {
        assert!(map.starts_with("maps/"), "{map}");
        let path = format!("baked/tree/lod0/{map}");
        bytes += project.read(&path).len();
        assert_eq!(manifest["artifacts"][&path]["meaning"], serde_json::json!({ "lod": 0 }), "{path}");
    }
    assert_eq!(level["bytes"], bytes, "the mesh, its MTL and its maps");
    // What the GPU holds: the glTF's buffer and the maps as RGBA8 with full mip chains (bark
    // 32², its normal map 4², the leaf 64²).
    let rgba8 = |side: u64| (0..=side.ilog2()).map(|level| (side >> level).pow(2) * 4).sum::<u64>();
    let buffer = project.read("baked/tree/lod0/lod.bin").len() as u64;
    assert_eq!(level["gpu_bytes"], buffer + rgba8(32) + rgba8(4) + rgba8(64));
    let bark_copy = maps.iter().find(|map| map.starts_with("maps/bark.")).unwrap().clone();
    assert_eq!(project.read(&format!("baked/tree/lod0/{bark_copy}")), project.read("assets/bark.png"));

    // A bark edit: the bark is copied again under a new name and the MTL names it; nothing is
    // reduced again and the mesh is the same.
    project.write("assets/bark.png", pattern_png(32, 32, 7));
    let summary = build(&mut cirrus);
    assert!(summary.all_ok(), "{}", summary.to_text());
    let executed = cirrus.take_executed_stages();
    assert!(executed.iter().all(|run| !run.contains("tree/lod0")), "{executed:?}");
    assert_eq!(project.read("baked/tree/lod0/lod.obj"), obj);
    let edited = mtl_maps(&project.read("baked/tree/lod0/lod.mtl"));
    let new_bark = edited.iter().find(|map| map.starts_with("maps/bark.")).unwrap();
    assert_ne!(new_bark, &bark_copy);
    assert_eq!(project.read(&format!("baked/tree/lod0/{new_bark}")), project.read("assets/bark.png"));
    assert!(!project.path(&format!("baked/tree/lod0/{bark_copy}")).exists(), "the stale copy is deleted");

    // A restart runs nothing: the reduced level is in the persistent cache.
    let mut restarted = project.open();
    let summary = build(&mut restarted);
    assert!(summary.all_ok(), "{}", summary.to_text());
    assert_eq!(restarted.take_executed_stages(), Vec::<String>::new());
    // A new budget re-runs that level only, from the cache's mesh, and measures it again (the
    // source's textures decoded to render the source beside it).
    let pipeline = String::from_utf8(project.read("pipeline.ron")).unwrap();
    std::fs::write(project.path("pipeline.ron"), pipeline.replace("Reduced(Triangles(30))", "Reduced(Ratio(0.25))"))
        .unwrap();
    restarted.reconfigure(cirrus::config::load_pipeline(&project.path("pipeline.ron")).unwrap());
    build(&mut restarted);
    let mut executed = restarted.take_executed_stages();
    executed.sort();
    assert_eq!(
        executed,
        [
            "decode(assets/bark.png)",
            "decode(assets/bark_normal.png)",
            "decode(assets/leaf.png)",
            "reduce(tree/lod0)",
            "switch(tree)"
        ]
    );
    assert!(faces(&project.read("baked/tree/lod0/lod.obj")) <= 56 / 4);
}

#[test]
fn the_preview_and_the_viewer_show_a_reduced_level_with_its_own_materials() {
    let project = chain_project("[Reduced(Ratio(0.5)), Quads(4)]");
    let output = project.run_cli(&["preview", "--asset", "tree", "--size", "48", "--samples", "2"]);
    assert_eq!(output.status.code(), Some(0), "{}", String::from_utf8_lossy(&output.stderr));
    let iou = [0, 1].map(|level| {
        let metrics: serde_json::Value =
            serde_json::from_slice(&project.read(&format!("baked/tree/preview/lod{level}/metrics.json"))).unwrap();
        assert_eq!(metrics["views"].as_array().unwrap().len(), 26);
        metrics["mean_iou"].as_f64().unwrap()
    });
    assert!(iou[0] > 0.6 && iou[0] > iou[1], "half the triangles look more like the tree than four quads: {iou:?}");

    let lines = crate::support::headless_viewer_lines(&project, "baked/tree", &["--size", "96", "--press", "1"]);
    let triangles = faces(&project.read("baked/tree/lod0/lod.obj"));
    assert!(lines[0].starts_with(&format!("loaded: lod0 of 2, {triangles} triangles")), "{lines:?}");
    assert!(lines[1].starts_with("showing lod1: lod1 of 2, "), "{lines:?}");
}
