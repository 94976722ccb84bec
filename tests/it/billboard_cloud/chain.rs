//! LOD chains (`billboard: (lods: [Quads(12), Quads(4)])`): each level within its budget in its
//! own folder with its own atlas, the one mesh stage shared, a bark edit re-rendering only the
//! bark of each level, a budget edit re-running only its level, the report and the manifest
//! naming each level, the preview per level with the chain's contact sheet, and the viewer
//! switching levels.

use std::collections::BTreeSet;

use crate::support::{build, pattern_png, TempProject};

/// The small tree of the bake tests as a two-level chain.
pub(crate) fn chain_project(lods: &str) -> TempProject {
    let project = crate::billboard_cloud::bake::tree_project();
    let pipeline = String::from_utf8(project.read("pipeline.ron")).unwrap();
    let pipeline = pipeline.replace(
        "atlas: (max_size: 256, padding: 2)",
        &format!("atlas: (max_size: 256, padding: 2), billboard: (lods: {lods})"),
    );
    std::fs::write(project.path("pipeline.ron"), pipeline).unwrap();
    project
}

/// Quads in an LOD's OBJ (two triangles each).
fn lod_quads(obj: &[u8]) -> usize {
    String::from_utf8_lossy(obj).lines().filter(|line| line.starts_with("f ")).count() / 2
}

#[test]
fn a_chain_bakes_each_level_within_its_budget_into_its_own_folder() {
    let project = chain_project("[Quads(12), Quads(4)]");
    let mut cirrus = project.open();
    let summary = build(&mut cirrus);
    assert!(summary.all_ok(), "{}", summary.to_text());
    let executed = cirrus.take_executed_stages();
    let count = |stage: &str| executed.iter().filter(|run| *run == stage).count();
    assert_eq!(count("mesh(tree)"), 1, "both levels read the one mesh stage: {executed:?}");
    for level in 0..2 {
        for stage in ["planes", "layout", "atlas", "lod"] {
            assert_eq!(count(&format!("{stage}(tree/lod{level})")), 1, "{stage} of lod{level}: {executed:?}");
        }
    }
    let report: serde_json::Value = serde_json::from_slice(&project.read("baked/tree/report.json")).unwrap();
    assert_eq!(report["faces"], 56);
    let manifest: serde_json::Value = serde_json::from_slice(&project.read("baked/manifest.json")).unwrap();
    let levels = report["levels"].as_array().expect("a report per level");
    assert_eq!(levels.len(), 2);
    for (level, budget, max_side) in [(0usize, 12usize, 256u64), (1, 4, 128)] {
        let entry = &levels[level];
        let quads = lod_quads(&project.read(&format!("baked/tree/lod{level}/lod.obj")));
        assert!(quads <= budget && quads > 0, "lod{level}: {quads} quads for a budget of {budget}");
        assert_eq!(
            (entry["level"].as_u64(), entry["folder"].as_str()),
            (Some(level as u64), Some(format!("lod{level}").as_str()))
        );
        assert_eq!(entry["quads"], quads);
        assert_eq!(entry["triangles"], 2 * quads);
        assert_eq!(entry["budget_quads"], budget);
        assert!(
            entry["max_error_world"].as_f64().unwrap() <= entry["epsilon_world"].as_f64().unwrap() * 1.0001,
            "{entry}"
        );
        // Level N without a screen size gets an atlas of at most max_size / 2^N a side.
        let (width, height) = (entry["atlas"]["width"].as_u64().unwrap(), entry["atlas"]["height"].as_u64().unwrap());
        assert!(width.max(height) <= max_side, "lod{level}: {width}×{height}");
        // The bytes an engine loads: the mesh, its material library and the four textures.
        let mut bytes = 0;
        for file in ["lod.obj", "lod.mtl", "albedo.ktx2", "mra.ktx2", "normal.ktx2", "height.ktx2"] {
            let path = format!("baked/tree/lod{level}/{file}");
            bytes += project.read(&path).len();
            assert_eq!(manifest["artifacts"][&path]["meaning"], serde_json::json!({ "lod": level }), "{path}");
        }
        assert_eq!(entry["bytes"], bytes, "lod{level}");
        // What the GPU holds: the glTF's buffer and every level of the four textures' blocks.
        let mut gpu_bytes = project.read(&format!("baked/tree/lod{level}/lod.bin")).len() as u64;
        for surface in ["albedo", "mra", "normal", "height"] {
            let ktx2 = crate::support::read_ktx2(&project.read(&format!("baked/tree/lod{level}/{surface}.ktx2")));
            assert_eq!(
                ktx2.levels.last().map(|_| (ktx2.width >> (ktx2.levels.len() - 1)).max(1)),
                Some(1),
                "a full chain"
            );
            gpu_bytes += ktx2.levels.iter().map(|&(_, _, uncompressed)| uncompressed).sum::<u64>();
        }
        assert_eq!(entry["gpu_bytes"], gpu_bytes, "lod{level}");
        let ktx2 = crate::support::read_ktx2(&project.read(&format!("baked/tree/lod{level}/albedo.ktx2")));
        assert_eq!((ktx2.width as u64, ktx2.height as u64), (width, height));
    }
    assert!(
        levels[1]["epsilon"].as_f64().unwrap() >= levels[0]["epsilon"].as_f64().unwrap(),
        "a smaller budget needs a larger ε"
    );
    // What the hot-reload batch says of each file: its level.
    let changed: Vec<_> = summary.changed.iter().filter(|artifact| artifact.artifact.starts_with("lod1/")).collect();
    assert!(changed.len() >= 6, "{changed:?}");
    assert!(changed.iter().all(|artifact| artifact.meaning == Some(serde_json::json!({ "lod": 1 }))), "{changed:?}");
    assert!(!project.path("baked/tree/lod.obj").exists(), "a chain writes its levels only");
}

/// The render stages the graph says read the decode of `texture`.
pub(crate) fn renders_reading(cirrus: &mut cirrus::project::Project, texture: &str) -> BTreeSet<String> {
    let graph = cirrus.graph();
    let decode = format!("decode({texture})");
    graph
        .edges
        .iter()
        .filter(|edge| edge.from == decode && edge.to.starts_with("render("))
        .map(|edge| edge.to.clone())
        .collect()
}

#[test]
fn a_bark_edit_rerenders_only_the_bark_of_each_level_and_a_budget_edit_only_its_level() {
    let project = chain_project("[Quads(12), Quads(4)]");
    let mut cirrus = project.open();
    build(&mut cirrus);
    cirrus.take_executed_stages();
    let bark_renders = renders_reading(&mut cirrus, "assets/bark.png");
    let leaf_renders = renders_reading(&mut cirrus, "assets/leaf.png");
    for level in 0..2 {
        let prefix = format!("render(tree/lod{level}/");
        assert!(bark_renders.iter().any(|render| render.starts_with(&prefix)), "lod{level} has bark: {bark_renders:?}");
        assert!(
            leaf_renders.difference(&bark_renders).any(|render| render.starts_with(&prefix)),
            "lod{level} has leaves alone"
        );
    }
    let lods = [0, 1].map(|level| project.read(&format!("baked/tree/lod{level}/lod.obj")));

    project.write("assets/bark.png", pattern_png(32, 32, 7));
    let summary = build(&mut cirrus);
    assert!(summary.all_ok(), "{}", summary.to_text());
    let executed: BTreeSet<String> = cirrus.take_executed_stages().into_iter().collect();
    let mut expected = bark_renders.clone();
    expected.insert("decode(assets/bark.png)".into());
    // Both levels changed: the chain is measured again.
    expected.insert("switch(tree)".into());
    for level in 0..2 {
        for stage in [
            "atlas(tree/lod{level})",
            "mips(tree/lod{level}/albedo)",
            "encode(tree/lod{level}/albedo)",
            "write(tree/lod{level}/albedo)",
        ] {
            expected.insert(stage.replace("{level}", &level.to_string()));
        }
    }
    assert_eq!(executed, expected, "each level's bark renders, atlas and albedo tail");
    for (level, lod) in lods.iter().enumerate() {
        assert_eq!(
            &project.read(&format!("baked/tree/lod{level}/lod.obj")),
            lod,
            "texture edits leave lod{level}'s mesh alone"
        );
    }

    // A new budget for level 1 re-runs level 1 only: level 0 keeps everything.
    let pipeline = String::from_utf8(project.read("pipeline.ron")).unwrap();
    std::fs::write(project.path("pipeline.ron"), pipeline.replace("Quads(4)", "Quads(2)")).unwrap();
    cirrus.reconfigure(cirrus::pipeline::load_pipeline(&project.path("pipeline.ron")).unwrap());
    let summary = build(&mut cirrus);
    assert!(summary.all_ok(), "{}", summary.to_text());
    let executed = cirrus.take_executed_stages();
    assert!(
        executed.iter().all(|run| run.contains("tree/lod1") || run == "switch(tree)"),
        "only level 1 (and the chain's measure) re-ran: {executed:?}"
    );
    assert!(executed.contains(&"planes(tree/lod1)".to_string()), "{executed:?}");
    assert!(lod_quads(&project.read("baked/tree/lod1/lod.obj")) <= 2);
    assert_eq!(project.read("baked/tree/lod0/lod.obj"), lods[0]);

    // The edited chain equals a clean bake of the same sources and settings.
    let clean = chain_project("[Quads(12), Quads(2)]");
    clean.write("assets/bark.png", pattern_png(32, 32, 7));
    build(&mut clean.open());
    for level in 0..2 {
        for file in ["lod.obj", "albedo.ktx2", "mra.ktx2", "normal.ktx2", "height.ktx2"] {
            let path = format!("baked/tree/lod{level}/{file}");
            assert!(project.read(&path) == clean.read(&path), "{path} differs from a clean build's");
        }
    }
}

#[test]
fn a_chain_restarts_with_no_stage_run() {
    let project = chain_project("[Quads(12), Quads(4), Quads(1)]");
    build(&mut project.open());
    let mut restarted = project.open();
    let summary = build(&mut restarted);
    assert!(summary.all_ok(), "{}", summary.to_text());
    assert_eq!(restarted.take_executed_stages(), Vec::<String>::new(), "the persistent cache holds every level");
    assert!(lod_quads(&project.read("baked/tree/lod2/lod.obj")) == 1);
}

#[test]
fn the_preview_compares_every_level_and_lays_the_chain_side_by_side() {
    let project = chain_project("[Quads(12), Quads(4)]");
    let output = project.run_cli(&["preview", "--asset", "tree", "--size", "48", "--samples", "2"]);
    assert_eq!(output.status.code(), Some(0), "{}", String::from_utf8_lossy(&output.stderr));
    let stdout = String::from_utf8_lossy(&output.stdout);
    let mut iou = Vec::new();
    for level in 0..2 {
        let metrics: serde_json::Value =
            serde_json::from_slice(&project.read(&format!("baked/tree/preview/lod{level}/metrics.json"))).unwrap();
        assert_eq!(metrics["views"].as_array().unwrap().len(), 26);
        iou.push(metrics["mean_iou"].as_f64().unwrap());
        let loss = (1.0 - iou[level]) / (1.0 - metrics["source_shift_iou"].as_f64().unwrap());
        assert!((metrics["loss_px_shift"].as_f64().unwrap() - loss).abs() < 1e-9, "{metrics}");
        assert!(
            stdout.contains(&format!(
                "lod{level}: 26 views, 4 samples per pixel: mean IoU {:.3} ({loss:.2} px-shift units)",
                iou[level]
            )),
            "{stdout}"
        );
        let sheet = image::load_from_memory(&project.read(&format!("baked/tree/preview/lod{level}/contact_sheet.png")))
            .unwrap();
        assert_eq!(
            (sheet.width(), sheet.height()),
            (4 * 2 * 48 + 3 * 8, 7 * 48 + 6 * 8),
            "source | lod{level} pairs, four to a row"
        );
    }
    assert!(
        iou[0] >= iou[1] - 0.02 && iou[1] > 0.3,
        "twelve quads look at least as much like the tree as four: {iou:?}"
    );
    // Each view: the source and both levels; two such groups per row.
    let sheet = image::load_from_memory(&project.read("baked/tree/preview/contact_sheet.png")).unwrap();
    assert_eq!((sheet.width(), sheet.height()), (2 * 3 * 48 + 8, 13 * 48 + 12 * 8));

    let output =
        project.run_cli(&["preview", "--asset", "tree", "--lod", "1", "--views", "1", "--size", "32", "--out", "one"]);
    assert_eq!(output.status.code(), Some(0), "{}", String::from_utf8_lossy(&output.stderr));
    assert!(project.path("one/lod1/metrics.json").is_file() && !project.path("one/lod0").exists());
    let sheet = image::load_from_memory(&project.read("one/lod1/contact_sheet.png")).unwrap();
    assert_eq!((sheet.width(), sheet.height()), (2 * 32, 32), "one view: one pair, no empty columns");
    let output = project.run_cli(&["preview", "--asset", "tree", "--lod", "2"]);
    assert_eq!(output.status.code(), Some(2));
    assert!(
        String::from_utf8_lossy(&output.stderr).contains("asset `tree` has no LOD level 2: it has 2 (0 to 1)"),
        "{output:?}"
    );
}

#[test]
fn the_viewer_switches_levels_with_the_digit_keys() {
    let project = chain_project("[Quads(12), Quads(4)]");
    build(&mut project.open());
    let lines = crate::support::headless_viewer_lines(&project, "baked/tree", &["--size", "96", "--press", "1x70"]);
    assert_eq!(lines.len(), 5, "{lines:?}");
    let triangles = |level: usize| 2 * lod_quads(&project.read(&format!("baked/tree/lod{level}/lod.obj")));
    assert!(lines[0].starts_with(&format!("loaded: lod0 of 2, {} triangles", triangles(0))), "{lines:?}");
    assert!(lines[1].starts_with(&format!("showing lod1: lod1 of 2, {} triangles", triangles(1))), "{lines:?}");
    assert_eq!(lines[2], "key x does nothing");
    assert_eq!(lines[3], "key 7: no level 7, the chain has lod0 to lod1");
    assert!(lines[4].starts_with(&format!("showing lod0: lod0 of 2, {} triangles", triangles(0))), "{lines:?}");
    assert!(project.path("shot.png").is_file());
}
