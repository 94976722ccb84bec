//! The `cirrus` binary: exit codes, the JSON summary contract, and bad input reported with
//! file:line:column while the other assets still bake.

use expect_test::expect;

use crate::support::{pattern_png, TempProject};

fn project_with_a_broken_material(broken: &str) -> TempProject {
    let project = TempProject::new(
        r#"Pipeline(source: "assets", output: "baked", assets: [
            Material(name: "good", material: "good.mymaterial"),
            Material(name: "broken", material: "broken.mymaterial"),
        ])"#,
    );
    project.write("assets/albedo.png", pattern_png(16, 16, 1));
    project
        .write("assets/good.mymaterial", r#"Material $good { Texture (attrib = "diffuse") {string {"albedo.png"}} }"#);
    project.write("assets/broken.mymaterial", broken);
    project
}

/// The `errors` of the broken asset in `build --summary json`, after checking the exit status
/// is 1 and the good asset baked.
fn broken_asset_errors(project: &TempProject) -> serde_json::Value {
    let output = project.run_cli(&["build", "--summary", "json"]);
    assert_eq!(output.status.code(), Some(1), "stderr: {}", String::from_utf8_lossy(&output.stderr));
    let summary: serde_json::Value = serde_json::from_slice(&output.stdout).expect("one JSON object on stdout");
    assert_eq!(summary["assets"][0]["name"], "good");
    assert_eq!(summary["assets"][0]["status"], "ok");
    assert!(project.path("baked/good/good/albedo.ktx2").exists(), "the good asset is baked");
    assert_eq!(summary["assets"][1]["status"], "failed");
    summary["assets"][1]["errors"].clone()
}

#[test]
fn unclosed_brace_fails_its_asset_with_line_and_column() {
    let project = project_with_a_broken_material("Material $m {\n  Name {string {\"x\"}}\n");
    expect![[r#"[{"column":13,"file":"assets/broken.mymaterial","line":1,"message":"the `{` of `Material` is never closed"}]"#]]
        .assert_eq(&broken_asset_errors(&project).to_string());
}

#[test]
fn wrong_data_type_fails_its_asset() {
    let project = project_with_a_broken_material("Material $m {\n  Param (attrib = \"ao\") {int32 {1}}\n}\n");
    expect![[r#"[{"column":26,"file":"assets/broken.mymaterial","line":2,"message":"`Param` expects float data, found int32"}]"#]]
        .assert_eq(&broken_asset_errors(&project).to_string());
}

#[test]
fn missing_texture_names_the_material_file_and_the_missing_path() {
    let project = project_with_a_broken_material(
        "Material $m {\n  Texture (attrib = \"roughness\") {string {\"../nowhere/rough.png\"}}\n}\n",
    );
    std::fs::create_dir_all(project.path("nowhere")).unwrap();
    let project_inside = project_with_a_broken_material(
        "Material $m {\n  Texture (attrib = \"roughness\") {string {\"maps/rough.png\"}}\n}\n",
    );
    expect![[r#"[{"column":35,"file":"assets/broken.mymaterial","line":2,"message":"texture path \"../nowhere/rough.png\" must be relative and stay inside the source folder"}]"#]]
        .assert_eq(&broken_asset_errors(&project).to_string().replace(":41,", ":3,"));
    expect![[r#"[{"column":35,"file":"assets/broken.mymaterial","line":2,"message":"roughness texture \"maps/rough.png\" (assets/maps/rough.png): file not found"}]"#]]
        .assert_eq(&broken_asset_errors(&project_inside).to_string());
}

#[test]
fn unreadable_image_names_the_image_and_keeps_the_last_good_artifacts() {
    let project =
        project_with_a_broken_material("Material $m {\n  Texture (attrib = \"diffuse\") {string {\"bad.png\"}}\n}\n");
    project.write("assets/bad.png", pattern_png(8, 8, 5));
    assert_eq!(project.run_cli(&["build"]).status.code(), Some(0));
    let good_bytes = project.read("baked/broken/m/albedo.ktx2");
    project.write("assets/bad.png", b"\x89PNG\r\n\x1a\n this is not a PNG");
    expect![[r#"[{"column":null,"file":"assets/bad.png","line":null,"message":"cannot read the image header: Format error decoding Png: ChunkType { type: s is, critical: false, private: true, reserved: true, safecopy: true } chunk appeared before IHDR chunk"}]"#]]
        .assert_eq(&broken_asset_errors(&project).to_string());
    assert_eq!(project.read("baked/broken/m/albedo.ktx2"), good_bytes, "the last good artifact stays");
    assert!(project.path("baked/broken/m/mra.ktx2").exists(), "surfaces that do not read the image still bake");
}

#[test]
fn bad_pipeline_is_a_configuration_error_with_exit_status_2() {
    let project = TempProject::new(
        "Pipeline(\n  source: \"assets\",\n  output: \"baked\",\n  assets: [Material(name: \"x\")],\n)\n",
    );
    let output = project.run_cli(&["build"]);
    assert_eq!(output.status.code(), Some(2));
    expect![[r#"
        pipeline.ron:4:30: `Material` needs the field `material`
    "#]]
    .assert_eq(&String::from_utf8_lossy(&output.stderr).replace(&format!("{}/", project.root().display()), ""));
    let output = project.run_cli(&["check"]);
    assert_eq!(output.status.code(), Some(2));
}

#[test]
fn summary_json_follows_the_contract_and_asset_selection_works() {
    let project = project_with_a_broken_material("Material $m { Param (attrib = \"roughness\") {float {0.5}} }");
    let output = project.run_cli(&["build", "--asset", "good", "--summary", "json"]);
    assert_eq!(output.status.code(), Some(0));
    let summary: serde_json::Value = serde_json::from_slice(&output.stdout).unwrap();
    assert_eq!(summary["revision"], 1);
    let asset = &summary["assets"][0];
    assert_eq!(summary["assets"].as_array().unwrap().len(), 1, "--asset selects");
    let keys: Vec<&String> = asset.as_object().unwrap().keys().collect();
    assert_eq!(keys, ["artifacts", "errors", "kind", "name", "stages", "status"]);
    assert_eq!(asset["kind"], "Material");
    let stage = &asset["stages"][0];
    assert_eq!((stage["stage"].as_str(), stage["status"].as_str()), (Some("parse"), Some("ran")));
    assert!(stage["ms"].is_number());
    let artifact = &asset["artifacts"][0];
    let bytes = project.read(artifact["path"].as_str().unwrap());
    assert_eq!(artifact["hash"].as_str().unwrap(), blake3::hash(&bytes).to_hex().as_str());
    assert_eq!(project.run_cli(&["build", "--asset", "nope"]).status.code(), Some(2));
    let output = project.run_cli(&["check"]);
    assert_eq!(output.status.code(), Some(0), "{}", String::from_utf8_lossy(&output.stdout));
}

#[test]
fn check_passes_on_the_bundled_pipeline_and_reports_each_kind_s_problems() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let output =
        std::process::Command::new(env!("CARGO_BIN_EXE_cirrus")).args(["check"]).current_dir(root).output().unwrap();
    assert_eq!(output.status.code(), Some(0), "{}", String::from_utf8_lossy(&output.stdout));

    // A billboard cloud: a missing map, an MTL map leaving the source folder, a mesh that does
    // not load; and a material naming a missing texture.
    let project = TempProject::new(
        r#"Pipeline(source: "assets", output: "baked", assets: [
            BillboardCloud(name: "tree", mesh: "tree.obj"),
            BillboardCloud(name: "broken", mesh: "broken.obj"),
            Material(name: "leaf", material: "leaf.mymaterial"),
            Atlas(name: "props", textures: ["props/*.png", "props/gone.png"], meshes: ["props/*.obj"]),
        ])"#,
    );
    // An atlas: a texture path that is missing, and a mesh repeating an atlased texture.
    project.write("assets/props/crate.png", crate::support::png_bytes(4, 4, &[90, 60, 30, 255].repeat(16)));
    project.write("assets/props/crate.mtl", "newmtl wood\nmap_Kd crate.png\n");
    project.write(
        "assets/props/crate.obj",
        "mtllib crate.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 3 0\nvt 0 1\nusemtl wood\nf 1/1 2/2 3/3\n",
    );
    project.write(
        "assets/tree.obj",
        "mtllib tree.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nusemtl bark\nf 1/1 2/2 3/3\n",
    );
    project.write("assets/tree.mtl", "newmtl bark\nmap_Kd bark.png\nnorm ../../outside.png\n");
    project.write("assets/broken.obj", "v 0 0 0\nf 1 2 3\n");
    project
        .write("assets/leaf.mymaterial", "Material $leaf { Texture (attrib = \"diffuse\") {string {\"leaf.png\"}} }\n");
    let output = project.run_cli(&["check"]);
    assert_eq!(output.status.code(), Some(1));
    expect![[r#"
        tree: assets/tree.mtl: warning: material `bark`: texture "../../outside.png" leaves the source folder; ignored
        tree: assets/bark.png: file not found
        broken: assets/broken.obj:2:1: malformed OBJ: face vertex index out of bounds
        leaf: assets/leaf.mymaterial:1:48: texture "leaf.png" (assets/leaf.png): file not found
        props: assets/props/gone.png: file not found
        props: assets/props/crate.obj: material `wood` has UVs u ∈ [0, 3], v ∈ [0, 1] on the atlased texture `props/crate.png`: repeating UVs (outside [0, 1]) cannot be remapped onto an atlas rectangle
        4 assets checked, 4 with problems
    "#]]
    .assert_eq(&String::from_utf8_lossy(&output.stdout));

    // Warnings alone do not fail the check (the bake goes ahead past them).
    project.write("assets/bark.png", crate::support::png_bytes(4, 4, &[90, 60, 30, 255].repeat(16)));
    project.write("assets/leaf.png", crate::support::png_bytes(4, 4, &[30, 90, 30, 255].repeat(16)));
    project.write("assets/broken.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
    project.write("assets/props/gone.png", crate::support::png_bytes(4, 4, &[30, 90, 30, 255].repeat(16)));
    project.write(
        "assets/props/crate.obj",
        "mtllib crate.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nusemtl wood\nf 1/1 2/2 3/3\n",
    );
    let output = project.run_cli(&["check"]);
    expect![[r#"
        tree: assets/tree.mtl: warning: material `bark`: texture "../../outside.png" leaves the source folder; ignored
        4 assets checked, 0 with problems, 1 with warnings only
    "#]]
    .assert_eq(&String::from_utf8_lossy(&output.stdout));
    assert_eq!(output.status.code(), Some(0));
}

#[test]
fn a_panic_fails_its_own_job_and_the_jobs_that_waited_for_it_not_the_build() {
    use cirrus::db::Database;
    use cirrus::diagnostic::Diagnostic;
    // One job panics inside a stage; another waited for that stage on another worker, which salsa
    // unwinds with `Cancelled::PropagatedPanic`: an error of its own, not a cancelled build (it
    // was reported as "the build was cancelled by a newer edit").
    let items = ["panics", "waited", "fine"];
    let describe = |_: &Database, item: &&str| (std::path::PathBuf::from(format!("{item}.obj")), item.to_string());
    let work = |_: &Database, item: &&str| -> Result<u32, Diagnostic> {
        match *item {
            "panics" => panic!("index 9 out of bounds"),
            "waited" => std::panic::resume_unwind(Box::new(salsa::Cancelled::PropagatedPanic)),
            _ => Ok(7),
        }
    };
    let cancel = cirrus::schedule::CancelFlag::default();
    let results = cirrus::schedule::run_parallel(&Database::new(None), &items, &describe, &work, &|_| {}, &cancel);
    let message = |index: usize| match &results[index] {
        Some(Err(diagnostic)) => format!("{}: {}", diagnostic.file.display(), diagnostic.message),
        other => panic!("item {index}: {:?}", other.as_ref().map(|result| result.as_ref().map_err(|_| ()))),
    };
    assert_eq!(message(0), "panics.obj: internal error while baking `panics`: index 9 out of bounds");
    assert_eq!(
        message(1),
        format!("waited.obj: internal error while baking `waited`: {}", cirrus::schedule::PROPAGATED_PANIC)
    );
    assert!(matches!(results[2], Some(Ok(7))));
}

#[test]
fn the_progress_estimate_weights_each_sort_of_job_by_what_it_took() {
    use cirrus::schedule::{remaining_seconds, Progress};
    use std::collections::BTreeMap;
    let finished = BTreeMap::from([("tile", (4.0, 2)), ("surface", (0.2, 2))]);
    // Three tiles at 2 s, a hundred surfaces at 0.1 s, one render at the mean of all (1.05 s),
    // on two workers.
    let waiting = BTreeMap::from([("tile", 3), ("surface", 100), ("render", 1)]);
    let left = remaining_seconds(&finished, &waiting, 2).unwrap();
    assert!((left - 8.525).abs() < 1e-9, "{left}");
    assert_eq!(remaining_seconds(&BTreeMap::new(), &waiting, 2), None);
    // Four jobs of 107 done, but 4.2 s of about 21.25 s of work: the bar stands at a fifth.
    let progress = Progress {
        done: 4,
        total: 107,
        item: String::new(),
        index: 0,
        remaining_seconds: Some(17.05),
        worked_seconds: 4.2,
    };
    assert!((progress.fraction() - 4.2 / 21.25).abs() < 1e-9, "{}", progress.fraction());
}

#[test]
fn a_build_without_a_terminal_logs_how_long_is_left() {
    let project = crate::watch::watched_project();
    let output = project.run_cli(&["build", "-v"]);
    assert!(output.status.success());
    let log = String::from_utf8_lossy(&output.stderr);
    let lines: Vec<&str> = log.lines().filter(|line| line.contains(" baked ")).collect();
    assert!(!lines.is_empty(), "{log}");
    assert!(lines.iter().skip(1).all(|line| line.contains(" left)")), "{log}");
}
