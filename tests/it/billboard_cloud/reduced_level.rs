//! Reduced levels of a LOD chain (`lods: [Reduced(Triangles(30)), Quads(4)]`): the mesh under its
//! triangle budget in `lod0/` over its materials' maps packed and block-compressed by the tail,
//! no planes, atlas or renders for it; a map edit encodes that map again without reducing again;
//! a restart runs nothing; the preview and the viewer show the level with its own materials.

use std::collections::BTreeSet;

use cirrus::config::BlockFormat;
use cirrus::texture::quality::decode_blocks;

use crate::billboard_cloud::chain::chain_project;
use crate::support::{build, ktx2_level, pattern_png, read_ktx2, PsnrSum};

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
fn a_reduced_level_keeps_its_budget_over_its_maps_block_compressed_and_a_map_edit_reduces_nothing() {
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
    // Each of its maps packed and encoded once: bark albedo and normal, the leaf's albedo.
    assert_eq!((count("maps(tree/lod0/materials/"), count("encode(tree/lod0/materials/")), (3, 3), "{executed:?}");
    let obj = project.read("baked/tree/lod0/lod.obj");
    let triangles = faces(&obj);
    assert!(triangles <= 30 && triangles > 0, "{triangles} triangles for a budget of 30");
    let report: serde_json::Value = serde_json::from_slice(&project.read("baked/tree/report.json")).unwrap();
    let level = &report["levels"][0];
    assert_eq!(level["representation"], "reduced");
    assert_eq!(level["budget"], serde_json::json!({ "triangles": 30 }));
    assert_eq!(level["triangles"], triangles);
    assert_eq!(report["levels"][1]["representation"], "billboard_cloud");
    // The MTL names each material's packed maps in materials/<name>/: a PNG for loaders, a KTX2
    // beside it for the GPU, both marked as the level's; the leaf's albedo carries its cut-out.
    let manifest: serde_json::Value = serde_json::from_slice(&project.read("baked/manifest.json")).unwrap();
    let mtl = project.read("baked/tree/lod0/lod.mtl");
    let maps = mtl_maps(&mtl);
    let expected = ["materials/bark/albedo.png", "materials/bark/normal.png", "materials/leaves/albedo.png"];
    assert_eq!(maps, expected.iter().map(|map| map.to_string()).collect::<BTreeSet<_>>());
    assert!(
        String::from_utf8_lossy(&mtl).contains("map_d materials/leaves/albedo.png"),
        "{}",
        String::from_utf8_lossy(&mtl)
    );
    let (mut bytes, mut gpu_bytes) = (obj.len() + mtl.len(), project.read("baked/tree/lod0/lod.bin").len() as u64);
    // Each at its source's size (the level's largest side is 256): bark 32², its normal map 4²,
    // the leaf 64².
    for (map, side) in expected.iter().zip([32, 4, 64]) {
        let texture = format!("baked/tree/lod0/{}", map.replace(".png", ".ktx2"));
        for path in [format!("baked/tree/lod0/{map}"), texture.clone()] {
            assert_eq!(manifest["artifacts"][&path]["meaning"], serde_json::json!({ "lod": 0 }), "{path}");
        }
        let file = project.read(&texture);
        let ktx2 = read_ktx2(&file);
        assert_eq!((ktx2.width, ktx2.height), (side, side), "{texture}");
        bytes += file.len();
        gpu_bytes += ktx2.levels.iter().map(|level| level.2).sum::<u64>();
    }
    assert_eq!(level["bytes"], bytes, "the mesh, its MTL and its textures");
    assert_eq!(level["gpu_bytes"], gpu_bytes, "the glTF's buffer and the textures with their mips");
    // The bark as the GPU decodes it, against its source.
    let albedo = project.read("baked/tree/lod0/materials/bark/albedo.ktx2");
    let ktx2 = read_ktx2(&albedo);
    let decoded = decode_blocks(BlockFormat::Bc7, &ktx2_level(&albedo, &ktx2, 0), 32, 32);
    let source = image::load_from_memory(&project.read("assets/bark.png")).unwrap().to_rgba8();
    let mut psnr = PsnrSum::default();
    for (expected, actual) in source.pixels().zip(decoded.pixels.chunks_exact(4)) {
        psnr.add(expected.0, actual.try_into().unwrap(), 3);
    }
    assert!(psnr.psnr() > 35.0, "the bark's albedo at {:.1} dB", psnr.psnr());

    // A bark edit: the bark's albedo alone is packed and encoded again; nothing is reduced
    // again and the mesh and its MTL are the same.
    project.write("assets/bark.png", pattern_png(32, 32, 7));
    let summary = build(&mut cirrus);
    assert!(summary.all_ok(), "{}", summary.to_text());
    let executed = cirrus.take_executed_stages();
    let level_runs: Vec<&String> = executed.iter().filter(|run| run.contains("tree/lod0")).collect();
    assert!(
        !level_runs.is_empty() && level_runs.iter().all(|run| run.contains("tree/lod0/materials/bark/albedo")),
        "{executed:?}"
    );
    assert_eq!(project.read("baked/tree/lod0/lod.obj"), obj);
    assert_eq!(project.read("baked/tree/lod0/lod.mtl"), mtl);
    assert_ne!(project.read("baked/tree/lod0/materials/bark/albedo.ktx2"), albedo);

    // A restart runs nothing: the reduced level and its maps are in the persistent cache.
    let mut restarted = project.open();
    let summary = build(&mut restarted);
    assert!(summary.all_ok(), "{}", summary.to_text());
    assert_eq!(restarted.take_executed_stages(), Vec::<String>::new());
    // A new budget re-runs that level's mesh only, from the cache's mesh (its maps are the
    // same), and measures it again (the source's textures decoded to render the source beside
    // it).
    let pipeline = String::from_utf8(project.read("pipeline.ron")).unwrap();
    std::fs::write(project.path("pipeline.ron"), pipeline.replace("Reduced(Triangles(30))", "Reduced(Ratio(0.25))"))
        .unwrap();
    restarted.reconfigure(cirrus::pipeline::load_pipeline(&project.path("pipeline.ron")).unwrap());
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

#[test]
fn a_reduced_level_s_maps_stay_in_its_folder_whatever_its_materials_are_named() {
    // Names that climb out of the folder, and that collide once made safe for a path.
    let project = chain_project("[Reduced(Ratio(0.5)), Quads(4)]");
    let renamed = |file: &str| {
        let text = String::from_utf8(project.read(file)).unwrap();
        let text = text.replace("mtl bark", "mtl ../../bark").replace("mtl leaves", "mtl .._.._bark");
        project.write(file, text);
    };
    renamed("assets/tree.obj");
    renamed("assets/tree.mtl");
    let summary = build(&mut project.open());
    assert!(summary.all_ok(), "{}", summary.to_text());
    let maps = mtl_maps(&project.read("baked/tree/lod0/lod.mtl"));
    let expected =
        ["materials/______bark/albedo.png", "materials/______bark/normal.png", "materials/______bark_1/albedo.png"];
    assert_eq!(maps, expected.iter().map(|map| map.to_string()).collect::<BTreeSet<_>>());
    for map in expected {
        assert!(project.path(&format!("baked/tree/lod0/{map}")).is_file(), "{map}");
        assert!(project.path(&format!("baked/tree/lod0/{}", map.replace(".png", ".ktx2"))).is_file(), "{map}");
    }
    // Nothing was written above the level's folder.
    let stray: Vec<_> =
        ["baked/bark", "baked/tree/bark", "bark"].iter().filter(|path| project.path(path).exists()).collect();
    assert!(stray.is_empty(), "{stray:?}");
}

#[test]
fn a_mesh_without_texture_coordinates_reduces_to_its_constants() {
    // Forty cards without `vt`: their material's map cannot be drawn, so no level bakes maps.
    let project = crate::support::TempProject::new(
        r#"Pipeline(source: "assets", output: "baked", assets: [
            BillboardCloud(name: "cards", mesh: "cards.obj", billboard: (lods: [Reduced(Ratio(0.5)), Auto(max_bytes: 65536)])),
        ])"#,
    );
    let mut obj = String::from("mtllib cards.mtl\nusemtl bark\n");
    for card in 0..40 {
        let (angle, height) = (card as f32 * 0.3, card as f32 * 0.05);
        let (x, z) = (angle.cos(), angle.sin());
        for (dx, dy) in [(0.0, 0.0), (0.2, 0.0), (0.2, 0.3), (0.0, 0.3)] {
            obj.push_str(&format!("v {} {} {z}\n", x + dx, height + dy));
        }
        let first = card * 4 + 1;
        obj.push_str(&format!("f {first} {} {}\nf {first} {} {}\n", first + 1, first + 2, first + 2, first + 3));
    }
    project.write("assets/cards.obj", obj);
    project.write("assets/cards.mtl", "newmtl bark\nKd 0.5 0.4 0.3\nmap_Kd bark.png\n");
    // The map is never read: a missing one fails nothing, and the build says why it is unused.
    let summary = build(&mut project.open());
    assert!(summary.all_ok(), "{}", summary.to_text());
    let warnings: Vec<&str> = summary.assets[0].warnings.iter().map(|warning| warning.message.as_str()).collect();
    assert!(
        warnings.contains(
            &"the OBJ has no texture coordinates: the maps of `bark` are not drawn (nor read); its faces take their \
              materials' constants"
        ),
        "{warnings:?}"
    );
    project.write("assets/bark.png", pattern_png(8, 8, 3));
    let summary = build(&mut project.open());
    assert!(summary.all_ok(), "{}", summary.to_text());
    assert!(mtl_maps(&project.read("baked/cards/lod0/lod.mtl")).is_empty());
    assert!(!project.path("baked/cards/lod0/materials").exists());
    let report: serde_json::Value = serde_json::from_slice(&project.read("baked/cards/report.json")).unwrap();
    let level = &report["levels"][0];
    assert_eq!(level["surfaces"], serde_json::json!([]));
    assert_eq!(level["gpu_bytes"], project.read("baked/cards/lod0/lod.bin").len());
    // The reduced level is measured as the others are (half the cards hold at small sizes).
    assert!(level["holds_to"].as_u64().is_some_and(|size| size >= 16), "{level}");
}
