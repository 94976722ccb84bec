//! Impostor levels of a LOD chain (`lods: [Quads(4), Impostor(frames: 4, hemi: false, size: 128)]`):
//! the frames baked once through the texture tail into `lod1/` with `impostor.json` and a quad
//! glTF that describes it; a bark edit bakes them again, a restart nothing; the preview and the
//! viewer draw the level through `shaders/impostor.wgsl`.

use crate::billboard_cloud::chain::chain_project;
use crate::support::{build, pattern_png};

const CHAIN: &str = "[Quads(4), Impostor(frames: 8, hemi: false, size: 256)]";

/// A BC texture's bytes on the GPU with its full mip chain, `side`² at level 0.
fn bc_bytes(side: u32, block_bytes: u64) -> u64 {
    (0..=side.ilog2()).map(|level| ((side >> level).div_ceil(4) as u64).pow(2) * block_bytes).sum()
}

#[test]
fn an_impostor_level_bakes_its_frames_through_the_tail_once_and_again_after_a_bark_edit() {
    let project = chain_project(CHAIN);
    let mut cirrus = project.open();
    let summary = build(&mut cirrus);
    assert!(summary.all_ok(), "{}", summary.to_text());
    let executed = cirrus.take_executed_stages();
    let count = |executed: &[String], stage: &str| executed.iter().filter(|run| run.starts_with(stage)).count();
    assert_eq!(count(&executed, "impostor(tree/lod1)"), 1, "{executed:?}");
    for stage in ["planes(tree/lod1)", "layout(tree/lod1)", "render(tree/lod1", "atlas(tree/lod1)", "lod(tree/lod1)"] {
        assert_eq!(count(&executed, stage), 0, "an impostor has no {stage}: {executed:?}");
    }
    // Three surfaces through the tail: BC7 albedo, BC5 normal, BC4 depth, 4 × 32 texels a side.
    for surface in ["albedo", "normal", "height"] {
        let ktx2 = crate::support::read_ktx2(&project.read(&format!("baked/tree/lod1/{surface}.ktx2")));
        assert_eq!((ktx2.width, ktx2.height), (256, 256), "{surface}");
    }
    let description: serde_json::Value =
        serde_json::from_slice(&project.read("baked/tree/lod1/impostor.json")).unwrap();
    let report: serde_json::Value = serde_json::from_slice(&project.read("baked/tree/report.json")).unwrap();
    let level = &report["levels"][1];
    assert_eq!(level["representation"], "impostor");
    assert_eq!(
        (level["frames"].as_u64(), level["frame_size"].as_u64(), level["hemi"].as_bool()),
        (Some(8), Some(32), Some(false))
    );
    assert_eq!(level["triangles"], 6, "the hull's fan");
    // The fitted hull: eight points within the sphere's square, cutting some of it.
    let hull: Vec<[f32; 2]> = serde_json::from_value(description["hull"].clone()).unwrap();
    assert_eq!(hull.len(), 8);
    assert!(hull.iter().flatten().all(|value| (-1.0..=1.0).contains(value)), "{hull:?}");
    let twice_area: f32 = (0..8).map(|k| hull[k][0] * hull[(k + 1) % 8][1] - hull[(k + 1) % 8][0] * hull[k][1]).sum();
    assert!(twice_area / 2.0 < 0.9 * 4.0, "the hull covers {} of the square", twice_area / 8.0);
    assert_eq!(
        (&description["frames"], &description["frame_size"], &description["hemi"], &description["depth"]),
        (&serde_json::json!(8), &serde_json::json!(32), &serde_json::json!(false), &serde_json::json!("height.ktx2"))
    );
    // The quad's glTF carries the description and shows the front frame's texels.
    let gltf: serde_json::Value = serde_json::from_slice(&project.read("baked/tree/lod1/lod.gltf")).unwrap();
    assert_eq!(gltf["meshes"][0]["extras"]["cirrus_impostor"], description);
    assert_eq!(gltf["materials"][0]["alphaMode"], "MASK");
    // What the GPU holds: the three textures with their mips and the quad's buffer.
    let buffer = project.read("baked/tree/lod1/lod.bin").len() as u64;
    assert_eq!(level["gpu_bytes"], 2 * bc_bytes(256, 16) + bc_bytes(256, 8) + buffer);
    let manifest: serde_json::Value = serde_json::from_slice(&project.read("baked/manifest.json")).unwrap();
    for file in ["impostor.json", "albedo.ktx2", "lod.gltf"] {
        let path = format!("baked/tree/lod1/{file}");
        assert_eq!(manifest["artifacts"][&path]["meaning"], serde_json::json!({ "lod": 1 }), "{path}");
    }

    // A bark edit renders the frames again (the bark shows in them) and the cloud's bark renders.
    project.write("assets/bark.png", pattern_png(32, 32, 7));
    let summary = build(&mut cirrus);
    assert!(summary.all_ok(), "{}", summary.to_text());
    let executed = cirrus.take_executed_stages();
    assert_eq!(count(&executed, "impostor(tree/lod1)"), 1, "{executed:?}");
    assert_eq!(count(&executed, "mesh(tree)"), 0, "{executed:?}");
    // A restart runs nothing: the surfaces are in the persistent cache under the frames' recipe.
    let mut restarted = project.open();
    let summary = build(&mut restarted);
    assert!(summary.all_ok(), "{}", summary.to_text());
    assert_eq!(restarted.take_executed_stages(), Vec::<String>::new());
}

#[test]
fn the_preview_and_the_viewer_draw_an_impostor_level_through_its_shader() {
    let project = chain_project(CHAIN);
    let output = project.run_cli(&["preview", "--asset", "tree", "--size", "48", "--samples", "2"]);
    assert_eq!(output.status.code(), Some(0), "{}", String::from_utf8_lossy(&output.stderr));
    let metrics: serde_json::Value =
        serde_json::from_slice(&project.read("baked/tree/preview/lod1/metrics.json")).unwrap();
    assert_eq!(metrics["views"].as_array().unwrap().len(), 26);
    let iou = metrics["mean_iou"].as_f64().unwrap();
    let cloud: serde_json::Value =
        serde_json::from_slice(&project.read("baked/tree/preview/lod0/metrics.json")).unwrap();
    let cloud = cloud["mean_iou"].as_f64().unwrap();
    // (Measured: 0.632 against the four quads' 0.554 at 48 px.)
    assert!(iou > 0.6 && iou > cloud, "the impostor's silhouette follows the tree's: {iou} (four quads: {cloud})");

    let lines = crate::support::headless_viewer_lines(&project, "baked/tree", &["--size", "96", "--press", "1"]);
    assert!(lines[1].starts_with("showing lod1: lod1 of 2, 2 triangles"), "{lines:?}");
    let covered: f64 = lines[1].split(", ").nth(2).and_then(|part| part.split('%').next()).unwrap().parse().unwrap();
    assert!(covered > 5.0, "{lines:?}");
}

#[test]
fn an_impostor_description_with_a_broken_hull_is_refused_with_its_file_named() {
    let project = chain_project(CHAIN);
    let output = project.run_cli(&["build"]);
    assert_eq!(output.status.code(), Some(0), "{}", String::from_utf8_lossy(&output.stderr));
    let path = "baked/tree/lod1/impostor.json";
    let mut description: serde_json::Value = serde_json::from_slice(&project.read(path)).unwrap();
    description["hull"] = serde_json::json!([[0.0, 0.0], [2.0, 0.0], [0.0, 1.0]]);
    project.write(path, serde_json::to_vec(&description).unwrap());
    // The viewer reads the level as an engine would, from the files as they are, says why it
    // cannot show it and keeps the level it shows.
    let options = crate::support::headless_viewer_options(
        &["--size", "32", "--press", "1"],
        &project.path("shot.png"),
        &project.path("baked/tree"),
    );
    let mut lines = Vec::new();
    crate::viewer::run(&options, &mut |line| lines.push(line)).expect("the viewer keeps running");
    let refused = lines.iter().find(|line| line.starts_with("cannot show lod1")).expect("lod1 is refused");
    assert!(refused.contains("lod1/impostor.json: `hull` needs eight [x, y] points"), "{lines:?}");
}
