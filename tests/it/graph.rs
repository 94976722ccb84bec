//! The dependency-graph dump tells the truth: over the bundled pipeline, editing each file node
//! re-runs only stages the dump puts downstream of it, always the stages that read it directly,
//! and, for an edit that changes everything the file feeds, exactly the stages downstream.

use std::collections::BTreeSet;
use std::path::Path;

use cirrus::graph::{Graph, NodeKind};
use cirrus::pipeline::load_pipeline;
use cirrus::project::{Project, ProjectOptions};
use expect_test::expect;

use crate::support::{build, TempProject};

/// A copy of the repository's `pipeline.ron` and `examples/assets`.
fn bundled_project() -> TempProject {
    let project =
        TempProject::new(&std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("pipeline.ron")).unwrap());
    project.copy_folder(&Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/assets"), "examples/assets");
    project
}

fn stage_ids(graph: &Graph, ids: impl IntoIterator<Item = String>) -> BTreeSet<String> {
    let stages: BTreeSet<&str> =
        graph.nodes.iter().filter(|node| node.kind == NodeKind::Stage).map(|node| node.id.as_str()).collect();
    ids.into_iter().filter(|id| stages.contains(id.as_str())).collect()
}

/// Rewrites `file` so that everything it feeds changes; true when the edit is total in that sense
/// (false where early cutoff is expected to stop some downstream stage, e.g. an MTL colour edit
/// leaves the planes alone).
fn edit(project: &TempProject, file: &str) -> bool {
    let path = project.path(file);
    let text = || std::fs::read_to_string(&path).unwrap();
    match file.rsplit('.').next().unwrap() {
        "png" | "jpg" => {
            let mut image = image::open(&path).unwrap().into_rgba8();
            for pixel in image.pixels_mut() {
                pixel.0 = [255 - pixel.0[0], 255 - pixel.0[1], 255 - pixel.0[2], 255 - pixel.0[3]];
            }
            if file.ends_with(".jpg") {
                image::DynamicImage::ImageRgba8(image).into_rgb8().save(&path).unwrap();
            } else {
                image.save(&path).unwrap();
            }
            // A bark map of the bush feeds only some atlas surfaces; the rest cut off.
            !file.contains("/trees/textures/oak_")
        }
        "mymaterial" => {
            let edited = match Path::new(file).file_name().unwrap().to_str().unwrap() {
                "bark.mymaterial" => {
                    text().replace("bark_oak", "bark_swap").replace("bark_birch", "bark_oak").replace("bark_swap", "bark_birch")
                }
                "painted_steel.mymaterial" => text()
                    .replace("0.18, 0.22, 0.28", "0.5, 0.4, 0.3")
                    .replace("{float {1.0}}", "{float {0.5}}")
                    .replace("0.35", "0.6")
                    .replace("bark_oak/normal", "bark_birch/normal"),
                "oak_leaves.mymaterial" => {
                    text().replace("{float {0.5}}", "{float {0.3}}").replace("{float {0.8}}", "{float {0.4}}").replace(
                        "Param (attrib = \"metallic\")",
                        "Texture (attrib = \"normal\") {string {\"../textures/bark_birch/normal.jpg\"}}\n    Param (attrib = \"metallic\")",
                    )
                }
                "spot.mymaterial" => text().replace("{float {0.6}}", "{float {0.3}}"),
                other => panic!("no edit for {other}"),
            };
            assert_ne!(edited, text(), "{file} edited");
            std::fs::write(&path, edited).unwrap();
            // The cow's edit changes its roughness only: its albedo and normal cut off.
            !file.ends_with("spot.mymaterial")
        }
        "obj" => {
            // Stretch the mesh along x and its texture coordinates toward the origin: new
            // planes, rectangles, layout and renders, and new places its UVs reach.
            let edited: String = text()
                .lines()
                .map(|line| {
                    if let Some(rest) = line.strip_prefix("v ") {
                        let values: Vec<f32> = rest.split_whitespace().map(|value| value.parse().unwrap()).collect();
                        format!("v {} {} {}\n", values[0] * 1.3, values[1], values[2])
                    } else if let Some(rest) = line.strip_prefix("vt ") {
                        let values: Vec<f32> = rest.split_whitespace().map(|value| value.parse().unwrap()).collect();
                        format!("vt {} {}\n", values[0] * 0.9, values[1] * 0.9)
                    } else {
                        format!("{line}\n")
                    }
                })
                .collect();
            std::fs::write(&path, edited).unwrap();
            true
        }
        "mtl" => {
            let edited =
                text().replace("Kd 0.8078 0.8000 0.7451", "Kd 0.5 0.3 0.2").replace("Kd 1 1 1", "Kd 0.5 0.3 0.2");
            assert_ne!(edited, text(), "{file} edited");
            std::fs::write(&path, edited).unwrap();
            false
        }
        other => panic!("no edit for .{other} files"),
    }
}

#[test]
fn editing_a_file_reruns_the_stages_downstream_of_it_in_the_dump() {
    let project = bundled_project();
    let config = load_pipeline(&project.path("pipeline.ron")).unwrap();
    let mut cirrus = Project::open(config, ProjectOptions { persistent_cache: false, ..Default::default() });
    assert!(build(&mut cirrus).all_ok());
    let files: Vec<String> =
        cirrus.graph().nodes.iter().filter(|node| node.kind == NodeKind::File).map(|node| node.id.clone()).collect();
    expect![[r#"
        [
            "examples/assets/materials/bark.mymaterial",
            "examples/assets/materials/oak_leaves.mymaterial",
            "examples/assets/materials/painted_steel.mymaterial",
            "examples/assets/meshes/spot/spot.mtl",
            "examples/assets/meshes/spot/spot.mymaterial",
            "examples/assets/meshes/spot/spot_texture.png",
            "examples/assets/meshes/spot/spot_triangulated_with_mtl.obj",
            "examples/assets/meshes/spot_height/spot_high.obj",
            "examples/assets/meshes/spot_height/spot_low.mtl",
            "examples/assets/meshes/spot_height/spot_low.obj",
            "examples/assets/textures/bark_birch/albedo.jpg",
            "examples/assets/textures/bark_birch/ao.jpg",
            "examples/assets/textures/bark_birch/normal.jpg",
            "examples/assets/textures/bark_birch/roughness.jpg",
            "examples/assets/textures/bark_oak/albedo.jpg",
            "examples/assets/textures/bark_oak/ao.jpg",
            "examples/assets/textures/bark_oak/normal.jpg",
            "examples/assets/textures/bark_oak/roughness.jpg",
            "examples/assets/textures/leaves/oak_leaves.png",
            "examples/assets/trees/bush_2.mtl",
            "examples/assets/trees/bush_2.obj",
            "examples/assets/trees/textures/aspen_color.png",
            "examples/assets/trees/textures/oak_ao_1k.jpg",
            "examples/assets/trees/textures/oak_color_1k.jpg",
            "examples/assets/trees/textures/oak_normal_1k.jpg",
            "examples/assets/trees/textures/oak_roughness_1k.jpg",
        ]
    "#]]
    .assert_debug_eq(&files);

    for file in &files {
        let before = cirrus.graph();
        cirrus.take_executed_stages();
        let total = edit(&project, file);
        assert!(build(&mut cirrus).all_ok(), "{file} still bakes");
        let ran: BTreeSet<String> = cirrus.take_executed_stages().into_iter().collect();
        let after = cirrus.graph();
        cirrus.take_executed_stages();

        let old_nodes: BTreeSet<String> = before.nodes.iter().map(|node| node.id.clone()).collect();
        let new_nodes: BTreeSet<String> = after.nodes.iter().map(|node| node.id.clone()).collect();
        // Instances the edit created (new planes of a changed mesh) are judged by the new dump.
        let downstream: BTreeSet<String> = stage_ids(&before, before.downstream(file))
            .into_iter()
            .filter(|id| new_nodes.contains(id))
            .chain(stage_ids(&after, after.downstream(file)).into_iter().filter(|id| !old_nodes.contains(id)))
            .collect();
        let readers: BTreeSet<String> =
            stage_ids(&before, before.edges.iter().filter(|edge| &edge.from == file).map(|edge| edge.to.clone()));
        let hidden: Vec<&String> = ran.difference(&downstream).collect();
        assert!(hidden.is_empty(), "{file}: ran but not downstream in the dump: {hidden:?}");
        let missed: Vec<&String> = readers.difference(&ran).collect();
        assert!(missed.is_empty(), "{file}: reads it in the dump but did not run: {missed:?}");
        if total {
            let spurious: Vec<&String> = downstream.difference(&ran).collect();
            assert!(spurious.is_empty(), "{file}: downstream in the dump but did not run: {spurious:?}");
        }
    }
}

#[test]
fn graph_renders_as_dot_json_and_mermaid() {
    let project = TempProject::new(
        r#"Pipeline(source: "assets", output: "baked", assets: [Material(name: "m", material: "m.mymaterial")])"#,
    );
    project.write("assets/ao.png", crate::support::pattern_png(8, 8, 1));
    project.write("assets/m.mymaterial", r#"Material $m { Texture (attrib = "ao") {string {"ao.png"}} }"#);
    let output = project.run_cli(&["graph", "--format", "json"]);
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    let graph: serde_json::Value = serde_json::from_slice(&output.stdout).unwrap();
    let mut nodes: Vec<String> = graph["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|node| {
            format!(
                "{} {} {}",
                node["kind"].as_str().unwrap(),
                node["id"].as_str().unwrap(),
                node["state"].as_str().unwrap()
            )
        })
        .collect();
    nodes.sort();
    expect![[r#"
        [
            "artifact baked/m/m/albedo.ktx2 written",
            "artifact baked/m/m/albedo.png written",
            "artifact baked/m/m/material.bin written",
            "artifact baked/m/m/material.gltf written",
            "artifact baked/m/m/mra.ktx2 written",
            "artifact baked/m/m/mra.png written",
            "artifact baked/m/m/normal.ktx2 written",
            "artifact baked/m/m/normal.png written",
            "artifact baked/m/m/orm.png written",
            "artifact baked/m/report.json written",
            "file assets/ao.png present",
            "file assets/m.mymaterial present",
            "stage decode(assets/ao.png) ran",
            "stage encode(m/m/albedo) ran",
            "stage encode(m/m/mra) ran",
            "stage encode(m/m/normal) ran",
            "stage mips(m/m/albedo) ran",
            "stage mips(m/m/mra) ran",
            "stage mips(m/m/normal) ran",
            "stage pack(m/m/albedo) ran",
            "stage pack(m/m/mra) ran",
            "stage pack(m/m/normal) ran",
            "stage parse(assets/m.mymaterial) ran",
            "stage write(m/m/albedo) ran",
            "stage write(m/m/mra) ran",
            "stage write(m/m/normal) ran",
        ]
    "#]]
    .assert_debug_eq(&nodes);
    let edges = graph["edges"].as_array().unwrap();
    assert!(edges.iter().any(|edge| edge["from"] == "assets/ao.png" && edge["to"] == "decode(assets/ao.png)"));
    assert!(edges.iter().any(|edge| edge["from"] == "decode(assets/ao.png)" && edge["to"] == "pack(m/m/mra)"));
    assert!(!edges.iter().any(|edge| edge["from"] == "decode(assets/ao.png)" && edge["to"] == "pack(m/m/albedo)"));

    let dot = String::from_utf8(project.run_cli(&["graph", "--format", "dot"]).stdout).unwrap();
    assert!(
        dot.starts_with("digraph cirrus {") && dot.contains(r#""assets/ao.png" -> "decode(assets/ao.png)";"#),
        "{dot}"
    );
    let mermaid = String::from_utf8(project.run_cli(&["graph", "--format", "mermaid"]).stdout).unwrap();
    assert!(mermaid.starts_with("flowchart LR\n") && mermaid.contains(" --> "), "{mermaid}");
}

#[test]
fn the_graph_after_a_build_reads_that_builds_instances_without_syncing_the_assets_again() {
    // A material that fails (the record does not hold it) and an atlas named by glob (checked
    // on every build): both were synced again by the graph before it kept the build's instances.
    let project = TempProject::new(
        r#"Pipeline(source: "src", output: "out", assets: [
            Material(name: "broken", material: "broken.mymaterial"),
            Atlas(name: "leaves", textures: ["leaves/*.png"]),
        ])"#,
    );
    project.write("src/broken.mymaterial", "Material $m { Texture (attrib = \"diffuse\") {string {\"missing.png\"}} }");
    project.write("src/leaves/a.png", crate::support::pattern_png(32, 32, 1));
    project.write("src/leaves/b.png", crate::support::pattern_png(16, 16, 2));
    let config = load_pipeline(&project.path("pipeline.ron")).unwrap();
    let mut cirrus = Project::open(config, ProjectOptions { persistent_cache: false, ..Default::default() });
    let summary = build(&mut cirrus);
    assert!(!summary.all_ok(), "the material fails");
    let names = ["broken", "leaves"].iter().map(|name| name.to_string()).collect();
    let synced = cirrus.assets_synced();
    let graph = cirrus.graph_of_assets(Some(&names));
    assert_eq!(cirrus.assets_synced(), synced, "the graph synced no asset again");
    for stage in ["parse(src/broken.mymaterial)", "layout(leaves)"] {
        assert!(graph.nodes.iter().any(|node| node.id == stage), "{stage} in the graph");
    }
    assert!(graph.nodes.iter().any(|node| node.id == "src/leaves/b.png"), "the atlas's files in the graph");
    // Once an input changed, the build's instances may be stale: the graph looks again.
    project.write("src/leaves/a.png", crate::support::pattern_png(32, 32, 3));
    cirrus.refresh_sources([Path::new("src/leaves/a.png")]);
    let graph = cirrus.graph_of_assets(Some(&names));
    assert!(cirrus.assets_synced() > synced, "an input changed: the graph syncs");
    assert!(graph.nodes.iter().any(|node| node.id == "layout(leaves)"), "the atlas still in the graph");
}
