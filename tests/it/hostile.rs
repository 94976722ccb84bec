//! Hostile and clumsy input: every way found to make cirrus delete a user's file, hang, abort or
//! exhaust memory, and the smaller ways to let bad input through. Each test reproduces one report
//! of the hardening issue; the process-level ones run the `cirrus` binary with a deadline, so that
//! a hang or an abort fails the test instead of the test run.

use std::collections::BTreeSet;
use std::path::Path;
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use cirrus::pipeline::{load_pipeline, parse_pipeline};

use crate::support::{build, pattern_png, TempProject};
use crate::watch::{changed_paths, output_hashes, watched_project, Client, Daemon};

/// Runs `cirrus ARGS` in the project folder; fails the test when it runs past `limit` (a hang).
fn run_with_deadline(project: &TempProject, arguments: &[&str], limit: Duration) -> Output {
    let mut command = Command::new(env!("CARGO_BIN_EXE_cirrus"));
    command.args(arguments).current_dir(project.root()).stdout(Stdio::piped());
    run_command_with_deadline(&mut command, limit)
}

/// Runs `command` (its stdout set by the caller) with stdin closed and stderr captured; fails the
/// test when it runs past `limit`.
fn run_command_with_deadline(command: &mut Command, limit: Duration) -> Output {
    let mut child = command.stdin(Stdio::null()).stderr(Stdio::piped()).spawn().expect("run cirrus");
    let start = Instant::now();
    while child.try_wait().expect("status").is_none() {
        if start.elapsed() > limit {
            let _ = child.kill();
            let output = child.wait_with_output().expect("output");
            panic!(
                "`{command:?}` still ran after {limit:?}: it hangs\nstderr: {}",
                String::from_utf8_lossy(&output.stderr)
            );
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    child.wait_with_output().expect("output")
}

fn text(output: &Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&output.stdout), String::from_utf8_lossy(&output.stderr))
}

/// A one-material project over small generated textures (quick to bake).
fn material_project() -> TempProject {
    let project = TempProject::new(
        r#"Pipeline(source: "assets", output: "baked", assets: [
            Material(name: "rock", material: "rock.mymaterial"),
            Material(name: "moss", material: "moss.mymaterial"),
        ])"#,
    );
    project.write("assets/albedo.png", pattern_png(32, 32, 1));
    project.write("assets/normal.png", pattern_png(32, 32, 2));
    project.write(
        "assets/rock.mymaterial",
        "Material $rock {\n  Texture (attrib = \"diffuse\") {string {\"albedo.png\"}}\n  Texture (attrib = \"normal\") {string {\"normal.png\"}}\n}\n",
    );
    project.write(
        "assets/moss.mymaterial",
        "Material $moss { Texture (attrib = \"diffuse\") {string {\"albedo.png\"}} }\n",
    );
    project
}

/// The client's next batch; on a time-out, fails with the daemon's log.
fn next_batch(daemon: &Daemon, client: &mut Client) -> serde_json::Value {
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| client.batch())) {
        Ok(batch) => batch,
        Err(_) => panic!("no batch from the daemon; its log:\n{}", daemon.log.lock().unwrap()),
    }
}

fn make_fifo(path: &Path) {
    let _ = std::fs::remove_file(path);
    let status = Command::new("mkfifo").arg(path).status().expect("mkfifo");
    assert!(status.success(), "mkfifo {}", path.display());
}

fn manifest(project: &TempProject) -> serde_json::Value {
    serde_json::from_slice(&project.read("baked/manifest.json")).expect("manifest is JSON")
}

// ---------------------------------------------------------------------------------------------
// severe

#[test]
fn stale_artifact_cleanup_deletes_only_files_cirrus_wrote_inside_the_output_folder() {
    let project = material_project();
    let outside = tempfile::tempdir().unwrap();
    let absolute_victim = outside.path().join("victim.txt");
    std::fs::write(&absolute_victim, "keep me").unwrap();
    project.write("victim.txt", "keep me");
    project.write("assets/notes.txt", "keep me");
    project.write("baked/handmade.txt", "keep me");
    project.write("baked/stale.txt", "cirrus wrote this");
    assert!(build(&mut project.open()).all_ok());

    // A manifest edited by hand (or by an attacker): entries of an asset that left the pipeline.
    let mut edited = manifest(&project);
    let entry = |hash: &str| serde_json::json!({"asset": "gone", "hash": hash, "revision": 1});
    let real = |path: &str| blake3::hash(&project.read(path)).to_hex().to_string();
    let artifacts = edited["artifacts"].as_object_mut().unwrap();
    for path in ["baked/../victim.txt", "assets/notes.txt", "pipeline.ron", "victim.txt"] {
        let on_disk = path.replace("baked/../", "");
        artifacts.insert(path.to_string(), entry(&real(&on_disk)));
    }
    let absolute = absolute_victim.to_string_lossy().into_owned();
    artifacts.insert(absolute.clone(), entry(blake3::hash(b"keep me").to_hex().as_str()));
    // Inside the output folder, but not the bytes cirrus recorded: a user's file.
    artifacts.insert("baked/handmade.txt".into(), entry("0000"));
    // Inside the output folder with the recorded bytes: a real stale artifact, deleted.
    artifacts.insert("baked/stale.txt".into(), entry(&real("baked/stale.txt")));
    project.write("baked/manifest.json", serde_json::to_vec_pretty(&edited).unwrap());

    let output = run_with_deadline(&project, &["build"], Duration::from_secs(120));
    assert!(output.status.success(), "{}", text(&output));
    for kept in ["victim.txt", "assets/notes.txt", "pipeline.ron", "baked/handmade.txt"] {
        assert!(project.path(kept).exists(), "{kept} was deleted");
    }
    assert!(absolute_victim.exists(), "an absolute path listed in the manifest was deleted");
    assert!(!project.path("baked/stale.txt").exists(), "a real stale artifact is still removed");
    assert!(text(&output).contains("not deleted"), "the refusals are reported: {}", text(&output));
    let after = manifest(&project);
    assert!(
        after["artifacts"]
            .as_object()
            .unwrap()
            .keys()
            .all(|path| path.starts_with("baked/rock/") || path.starts_with("baked/moss/")),
        "refused entries leave the manifest: {after}"
    );
}

#[test]
fn structures_nested_ten_thousand_deep_fail_with_a_position_instead_of_aborting() {
    let project = material_project();
    let depth = 10_000;
    let nested = format!("{}{}", "Extra {\n".repeat(depth), "}".repeat(depth));
    project.write("assets/moss.mymaterial", format!("Material $moss {{ {nested} }}\n"));
    for command in ["build", "check"] {
        let output = run_with_deadline(&project, &[command], Duration::from_secs(60));
        let printed = text(&output);
        assert_eq!(output.status.code(), Some(1), "`{command}` exits 1, not an abort: {printed}");
        assert!(printed.contains("assets/moss.mymaterial:100:"), "`{command}` names the file and line: {printed}");
        assert!(printed.contains("nested too deeply"), "{printed}");
    }
    assert!(project.path("baked/rock/rock/albedo.ktx2").exists(), "the other asset still bakes");

    // pipeline.ron and the protocol's JSON have their parsers' own limits.
    let deep_ron =
        format!("Pipeline(source: \"assets\", output: \"baked\", assets: {}{})", "[".repeat(depth), "]".repeat(depth));
    let error = parse_pipeline(Path::new("pipeline.ron"), &deep_ron).expect_err("too deep");
    assert!(error.to_string().contains("pipeline.ron:1:"), "{error}");
    let deep_json = format!("{}{}", "[".repeat(depth), "]".repeat(depth));
    assert!(cirrus::server::parse_request(deep_json.as_bytes()).is_err());
}

#[test]
fn fifos_and_devices_as_inputs_are_refused_without_blocking() {
    let project = material_project();
    make_fifo(&project.path("assets/normal.png"));
    let output = run_with_deadline(&project, &["build"], Duration::from_secs(60));
    let printed = text(&output);
    assert_eq!(output.status.code(), Some(1), "{printed}");
    assert!(printed.contains("assets/normal.png") && printed.contains("not a regular file"), "{printed}");
    assert!(project.path("baked/moss/moss/albedo.ktx2").exists(), "the other asset still bakes");
    let output = run_with_deadline(&project, &["check"], Duration::from_secs(60));
    assert!(text(&output).contains("not a regular file"), "{}", text(&output));

    // A FIFO as the material file, as a rule-matched file and as a mesh with a FIFO `mtllib`.
    let project = TempProject::new(
        r#"Pipeline(source: "assets", output: "baked", assets: [
            Material(name: "fifo", material: "fifo.mymaterial"),
            BillboardCloud(name: "tree", mesh: "tree.obj"),
        ], rules: [(glob: "rules/*.mymaterial", kind: Material)])"#,
    );
    std::fs::create_dir_all(project.path("assets/rules")).unwrap();
    make_fifo(&project.path("assets/fifo.mymaterial"));
    make_fifo(&project.path("assets/rules/pipe.mymaterial"));
    make_fifo(&project.path("assets/tree.obj"));
    let output = run_with_deadline(&project, &["build"], Duration::from_secs(60));
    let printed = text(&output);
    assert_eq!(output.status.code(), Some(1), "{printed}");
    for file in ["assets/fifo.mymaterial", "assets/rules/pipe.mymaterial", "assets/tree.obj"] {
        assert!(printed.contains(&format!("{file}: is not a regular file")), "{file}: {printed}");
    }
    std::fs::remove_file(project.path("assets/tree.obj")).unwrap();
    project.write("assets/tree.obj", "mtllib tree.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
    make_fifo(&project.path("assets/tree.mtl"));
    let output = run_with_deadline(&project, &["build", "--asset", "tree"], Duration::from_secs(60));
    assert!(text(&output).contains("assets/tree.mtl: is not a regular file"), "{}", text(&output));

    // A symbolic link to /dev/zero (endless bytes) is refused, not read into memory.
    let project = material_project();
    std::fs::remove_file(project.path("assets/normal.png")).unwrap();
    std::os::unix::fs::symlink("/dev/zero", project.path("assets/normal.png")).unwrap();
    let output = run_with_deadline(&project, &["build"], Duration::from_secs(60));
    let printed = text(&output);
    assert_eq!(output.status.code(), Some(1), "{printed}");
    assert!(printed.contains("assets/normal.png") && printed.contains("not a regular file"), "{printed}");

    // The pipeline file itself.
    let project = TempProject::new("");
    std::fs::remove_file(project.path("pipeline.ron")).unwrap();
    make_fifo(&project.path("pipeline.ron"));
    let output = run_with_deadline(&project, &["check"], Duration::from_secs(60));
    assert_eq!(output.status.code(), Some(2), "{}", text(&output));
    assert!(text(&output).contains("not a regular file"), "{}", text(&output));
}

#[test]
fn a_missing_source_folder_fails_the_assets_and_the_daemon_waits_for_it() {
    let project = watched_project();
    std::fs::rename(project.path("assets"), project.path("elsewhere")).unwrap();
    let mut daemon = Daemon::start(&project);
    let mut client = daemon.connect();
    client.subscribe(Some(0));
    let batch = next_batch(&daemon, &mut client);
    let failed = batch["failed"].as_array().unwrap();
    assert!(!failed.is_empty(), "{batch}");
    assert!(
        failed.iter().all(|entry| entry["message"].as_str().unwrap().contains("source folder assets does not exist")),
        "{batch}"
    );
    assert!(daemon.alive(), "watch keeps running without its source folder");

    // The folder appears: everything bakes.
    std::fs::rename(project.path("elsewhere"), project.path("assets")).unwrap();
    let batch = next_batch(&daemon, &mut client);
    assert_eq!(batch["failed"], serde_json::json!([]), "{batch}");
    assert!(changed_paths(&project, &batch).contains(&"baked/rock/rock/albedo.ktx2".to_string()), "{batch}");

    // A typo in `source` while running: a failure batch, the daemon keeps its clients.
    let pipeline = String::from_utf8(project.read("pipeline.ron")).unwrap();
    project.write("pipeline.ron", pipeline.replace(r#"source: "assets""#, r#"source: "asets""#));
    let batch = next_batch(&daemon, &mut client);
    assert!(batch["failed"][0]["message"].as_str().unwrap().contains("source folder asets does not exist"), "{batch}");
    assert!(daemon.alive());
    project.write("pipeline.ron", &pipeline);
    let batch = next_batch(&daemon, &mut client);
    assert_eq!(batch["failed"], serde_json::json!([]), "{batch}");
    // And it hears edits again.
    project.write("assets/ao.png", pattern_png(32, 32, 9));
    let batch = next_batch(&daemon, &mut client);
    assert!(changed_paths(&project, &batch).contains(&"baked/rock/rock/mra.ktx2".to_string()), "{batch}");
}

// ---------------------------------------------------------------------------------------------
// high

#[test]
fn an_output_folder_that_is_holds_or_lies_inside_the_source_is_refused() {
    for (source, output) in
        [("assets", "."), ("assets", ""), ("assets", "./"), ("src", "src/.."), ("src", "src"), ("src", "src/baked")]
    {
        let text = format!(r#"Pipeline(source: "{source}", output: "{output}")"#);
        let error = parse_pipeline(Path::new("pipeline.ron"), &text)
            .expect_err(&format!("output {output:?} beside source {source:?}"));
        assert!(
            error.to_string().contains("pipeline.ron:1:") && error.to_string().contains("output folder must not"),
            "{error}"
        );
    }
    // Through a symbolic link: `out` is the source folder under another name.
    let project = TempProject::new(r#"Pipeline(source: "assets", output: "out")"#);
    std::fs::create_dir_all(project.path("assets")).unwrap();
    std::os::unix::fs::symlink(project.path("assets"), project.path("out")).unwrap();
    let error = load_pipeline(&project.path("pipeline.ron")).expect_err("output is the source through a link");
    assert!(error.to_string().contains("output folder must not be the source folder"), "{error}");
}

#[test]
fn the_daemon_hears_its_source_folder_again_after_it_is_deleted_or_moved_and_back() {
    let project = watched_project();
    // An asset listed in pipeline.ron whose file lies in a subfolder.
    let pipeline = String::from_utf8(project.read("pipeline.ron")).unwrap();
    project.write(
        "pipeline.ron",
        pipeline.replace(
            "assets: [",
            "assets: [\n            Material(name: \"stone\", material: \"sub/stone.mymaterial\"),",
        ),
    );
    project.write(
        "assets/sub/stone.mymaterial",
        "Material $stone { Texture (attrib = \"diffuse\") {string {\"../albedo.png\"}} }\n",
    );
    let daemon = Daemon::start(&project);
    let mut client = daemon.connect();
    client.subscribe(Some(0));
    next_batch(&daemon, &mut client);

    // Renamed away and back (a sync tool, an archive unpacked in place).
    std::fs::rename(project.path("assets"), project.path("assets.moved")).unwrap();
    let batch = next_batch(&daemon, &mut client);
    assert!(!batch["failed"].as_array().unwrap().is_empty(), "the assets fail while their folder is gone: {batch}");
    std::fs::rename(project.path("assets.moved"), project.path("assets")).unwrap();
    let batch = next_batch(&daemon, &mut client);
    assert_eq!(batch["failed"], serde_json::json!([]), "{batch}");
    project.write("assets/ao.png", pattern_png(32, 32, 11));
    let batch = next_batch(&daemon, &mut client);
    assert!(
        changed_paths(&project, &batch).contains(&"baked/rock/rock/mra.ktx2".to_string()),
        "heard after a move: {batch}"
    );

    // Deleted and created again.
    let saved = tempfile::tempdir().unwrap();
    let copy = |from: &Path, to: &Path| {
        let status = Command::new("cp").arg("-r").arg(from).arg(to).status().unwrap();
        assert!(status.success());
    };
    copy(&project.path("assets"), &saved.path().join("assets"));
    std::fs::remove_dir_all(project.path("assets")).unwrap();
    let batch = next_batch(&daemon, &mut client);
    assert!(!batch["failed"].as_array().unwrap().is_empty(), "{batch}");
    copy(&saved.path().join("assets"), project.root());
    let batch = next_batch(&daemon, &mut client);
    assert_eq!(batch["failed"], serde_json::json!([]), "{batch}");
    project.write("assets/ao.png", pattern_png(32, 32, 12));
    let batch = next_batch(&daemon, &mut client);
    assert!(
        changed_paths(&project, &batch).contains(&"baked/rock/rock/mra.ktx2".to_string()),
        "heard after re-creation: {batch}"
    );

    // A subfolder moved away (one event, none per file) fails the listed asset inside it.
    std::fs::rename(project.path("assets/sub"), saved.path().join("sub")).unwrap();
    let batch = next_batch(&daemon, &mut client);
    let failed: Vec<&str> =
        batch["failed"].as_array().unwrap().iter().filter_map(|entry| entry["asset"].as_str()).collect();
    assert_eq!(failed, ["stone"], "{batch}");
    assert!(project.path("baked/stone/stone/albedo.ktx2").exists(), "its last good artifacts stay");
}

#[test]
fn textures_whose_working_set_exceeds_the_budget_fail_from_their_header() {
    // A 16384² PNG header (the decode limit admits it; its working set is 16 GiB).
    let mut huge = Vec::new();
    let encoder = image::codecs::png::PngEncoder::new(&mut huge);
    let row = vec![0u8; 16384 * 4];
    // Writing 1 GiB of pixels would be slow: a valid header with one row of data is enough,
    // since the budget is checked before decoding.
    let _ = image::ImageEncoder::write_image(encoder, &row, 16384, 1, image::ExtendedColorType::Rgba8);
    let height_offset = 16 + 4; // signature (8) + IHDR length and type (8) + width (4)
    huge[height_offset..height_offset + 4].copy_from_slice(&16384u32.to_be_bytes());
    let crc = crc32(&huge[12..29]);
    huge[29..33].copy_from_slice(&crc.to_be_bytes());
    let error =
        cirrus::texture::probe_texture(Path::new("huge.png"), &huge, Default::default()).expect_err("over budget");
    assert!(error.to_string().contains("16384×16384") && error.to_string().contains("texture_memory_mib"), "{error}");

    // The budget is a setting: 16 MiB refuses a 1024² texture (64 MiB), admits 256² (4 MiB).
    let project = TempProject::new(
        r#"Pipeline(source: "assets", output: "baked", limits: (texture_memory_mib: 16), assets: [
            Material(name: "big", material: "big.mymaterial"),
            Material(name: "small", material: "small.mymaterial"),
        ])"#,
    );
    project.write("assets/big.png", pattern_png(1024, 1024, 1));
    project.write("assets/small.png", pattern_png(256, 256, 2));
    project.write("assets/big.mymaterial", "Material $big { Texture (attrib = \"diffuse\") {string {\"big.png\"}} }");
    project.write(
        "assets/small.mymaterial",
        "Material $small { Texture (attrib = \"diffuse\") {string {\"small.png\"}} }",
    );
    let summary = build(&mut project.open());
    let big = summary.assets.iter().find(|asset| asset.name == "big").unwrap();
    assert!(
        big.errors.iter().any(|error| error.message.contains("texture memory budget of 16 MiB")),
        "{}",
        summary.to_text()
    );
    assert!(
        summary.assets.iter().find(|asset| asset.name == "small").unwrap().status == cirrus::summary::AssetStatus::Ok
    );
    let output = run_with_deadline(&project, &["check"], Duration::from_secs(60));
    assert!(text(&output).contains("texture memory budget"), "check reports it too: {}", text(&output));

    // A billboard atlas is a texture too: 16384² is over the default budget, 8192² within it.
    let atlas = |side: u32| {
        format!(
            r#"Pipeline(source: "a", output: "b", assets: [BillboardCloud(name: "t", mesh: "t.obj", atlas: (max_size: {side}))])"#
        )
    };
    let error = parse_pipeline(Path::new("pipeline.ron"), &atlas(16384)).expect_err("over budget");
    assert!(error.to_string().contains("a 16384² atlas needs about 16384 MiB per surface"), "{error}");
    assert!(parse_pipeline(Path::new("pipeline.ron"), &atlas(8192)).is_ok());
}

/// CRC-32 (PNG's polynomial), for patching a chunk header.
fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &byte in bytes {
        crc ^= u32::from(byte);
        for _ in 0..8 {
            crc = if crc & 1 == 1 { (crc >> 1) ^ 0xEDB8_8320 } else { crc >> 1 };
        }
    }
    !crc
}

// ---------------------------------------------------------------------------------------------
// moderate

#[test]
fn a_truncated_jpeg_fails_instead_of_baking_grey() {
    let project = material_project();
    let jpeg =
        std::fs::read(Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/assets/textures/bark_oak/albedo.jpg"))
            .unwrap();
    project.write("assets/albedo.jpg", &jpeg[..jpeg.len() / 2]);
    project.write("assets/whole.jpg", &jpeg);
    project.write(
        "assets/moss.mymaterial",
        "Material $moss { Texture (attrib = \"diffuse\") {string {\"albedo.jpg\"}} }\n",
    );
    project.write(
        "assets/rock.mymaterial",
        "Material $rock { Texture (attrib = \"diffuse\") {string {\"whole.jpg\"}} }\n",
    );
    let summary = build(&mut project.open());
    let moss = summary.assets.iter().find(|asset| asset.name == "moss").unwrap();
    assert!(
        moss.errors.iter().any(|error| error.file == "assets/albedo.jpg" && error.message.contains("truncated")),
        "{}",
        summary.to_text()
    );
    assert_eq!(
        summary.assets.iter().find(|asset| asset.name == "rock").unwrap().status,
        cirrus::summary::AssetStatus::Ok,
        "a whole JPEG bakes"
    );
    // A truncated PNG fails in the decoder.
    let png = pattern_png(64, 64, 3);
    let error = cirrus::texture::decode_texture(Path::new("cut.png"), &png[..png.len() - 40], Default::default())
        .expect_err("truncated PNG");
    assert!(error.to_string().starts_with("cut.png: "), "{error}");
}

fn load_obj(
    obj: &str,
    mtl: Option<&str>,
) -> Result<(cirrus::mesh::Mesh, Vec<cirrus::diagnostic::Diagnostic>), cirrus::diagnostic::Diagnostic> {
    let obj_path = Path::new("assets/m.obj");
    let mut libraries = std::collections::BTreeMap::new();
    for library in cirrus::mesh::material_libraries(obj_path, obj.as_bytes(), Path::new("assets")) {
        libraries.insert(library, mtl.map(|text| text.as_bytes().to_vec()));
    }
    cirrus::mesh::load_mesh(obj_path, obj.as_bytes(), &libraries, Path::new("assets"))
}

#[test]
fn a_map_path_is_relative_to_the_mtl_file_that_names_it() {
    // As Blender, three.js's MTLLoader and Assimp (its issue #2355, the conformance suite's
    // `mtl_different_folder.obj`) read it; the OBJ's folder was used, so an MTL in another
    // folder, like the atlas.mtl that cirrus writes above its remapped meshes, named textures
    // that are not there.
    let obj_path = Path::new("assets/meshes/m.obj");
    let obj =
        b"mtllib ../materials/m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nusemtl bark\nf 1/1 2/2 3/3\n";
    let mtl = b"newmtl bark\nmap_Kd textures/bark.png\nnorm ../bark_normal.png\n".to_vec();
    let libraries: std::collections::BTreeMap<_, _> =
        cirrus::mesh::material_libraries(obj_path, obj, Path::new("assets"))
            .into_iter()
            .map(|library| (library, Some(mtl.clone())))
            .collect();
    assert_eq!(libraries.keys().collect::<Vec<_>>(), [Path::new("assets/materials/m.mtl")]);
    let (mesh, warnings) = cirrus::mesh::load_mesh(obj_path, obj, &libraries, Path::new("assets")).expect("loads");
    assert!(warnings.is_empty(), "{warnings:?}");
    let maps: Vec<&Path> = mesh.materials[0].maps.values().map(|path| path.as_path()).collect();
    assert_eq!(maps, [Path::new("assets/materials/textures/bark.png"), Path::new("assets/bark_normal.png")]);
    assert_eq!(
        cirrus::mesh::texture_paths(&libraries, Path::new("assets")),
        [Path::new("assets/bark_normal.png"), Path::new("assets/materials/textures/bark.png")]
    );
}

#[test]
fn an_object_without_uvs_keeps_the_other_objects_textured() {
    let mtl = "newmtl bark\nmap_Kd bark.png\n";
    let obj = "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\n\
               o trunk\nusemtl bark\nf 1/1 2/2 3/3\n\
               o branch\nv 0 0 1\nv 1 0 1\nv 0 1 1\nusemtl bark\nf 4 5 6\n";
    let (mesh, warnings) = load_obj(obj, Some(mtl)).expect("loads");
    assert!(mesh.uvs.is_some(), "the textured object keeps its UVs");
    let material_of = |face: usize| &mesh.materials[mesh.triangle_materials[face] as usize];
    assert!(!material_of(0).maps.is_empty(), "trunk keeps its maps");
    assert!(material_of(1).maps.is_empty(), "branch bakes constants");
    assert_eq!(material_of(1).albedo_factor, material_of(0).albedo_factor);
    assert!(
        warnings.iter().any(|warning| warning.message.contains("object `branch` has no texture coordinates")),
        "{warnings:?}"
    );
}

#[test]
fn asset_names_that_share_a_folder_or_name_cirrus_files_are_refused() {
    let cases = [
        (r#"("a/b", "a//b")"#, "names the folder `a/b`: write `a/b`"),
        (r#"("a/b", "a/./b")"#, "names the folder `a/b`: write `a/b`"),
        (r#"("x", "x/m")"#, "would share a folder"),
        (r#"("manifest.json", "ok")"#, "is reserved"),
        (r#"(".cirrus", "ok")"#, "is reserved"),
    ];
    for (names, expected) in cases {
        let (first, second) = names.trim_matches(|c| c == '(' || c == ')').split_once(", ").unwrap();
        let text = format!(
            r#"Pipeline(source: "assets", output: "baked", assets: [
                Material(name: {first}, material: "a.mymaterial"),
                Material(name: {second}, material: "b.mymaterial"),
            ])"#
        );
        let error = parse_pipeline(Path::new("pipeline.ron"), &text).expect_err(names);
        assert!(error.to_string().contains(expected), "{names}: {error}");
        assert!(error.to_string().contains("pipeline.ron:"), "{error}");
    }

    // A rule-matched file whose name collides is reported, not silently dropped.
    let project = material_project();
    let pipeline = String::from_utf8(project.read("pipeline.ron")).unwrap();
    project.write("pipeline.ron", pipeline.replace("])", "], rules: [(glob: \"**/*.mymaterial\", kind: Material)])"));
    project.write("assets/rock/extra.mymaterial", "Material $x { }\n");
    let output = run_with_deadline(&project, &["check"], Duration::from_secs(60));
    assert!(
        text(&output).contains("rules: assets/rock/extra.mymaterial: warning: matches a rule but is not baked"),
        "{}",
        text(&output)
    );

    // A manifest that cannot be written fails the build.
    let project = material_project();
    std::fs::create_dir_all(project.path("baked/manifest.json/in_the_way")).unwrap();
    let output = run_with_deadline(&project, &["build"], Duration::from_secs(60));
    assert_eq!(output.status.code(), Some(1), "{}", text(&output));
    assert!(text(&output).contains("cannot write the manifest"), "{}", text(&output));
}

#[test]
fn material_libraries_and_textures_outside_the_source_folder_are_not_read() {
    let obj = "mtllib ../../etc/passwd\nmtllib ../pipeline.ron\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
    assert!(cirrus::mesh::material_libraries(Path::new("assets/m.obj"), obj.as_bytes(), Path::new("assets")).is_empty());
    let (_, warnings) = load_obj(obj, None).expect("loads with default materials");
    assert_eq!(
        warnings.iter().filter(|warning| warning.message.contains("lies outside the source folder")).count(),
        2,
        "{warnings:?}"
    );

    // Symbolic links placed in the source folder are the user's (a shared library linked in):
    // followed wherever they lead, as long as they lead to a regular file.
    let project = material_project();
    project.write("library/shared.png", pattern_png(8, 8, 5));
    std::fs::remove_file(project.path("assets/normal.png")).unwrap();
    std::os::unix::fs::symlink(project.path("library/shared.png"), project.path("assets/normal.png")).unwrap();
    std::fs::rename(project.path("assets/albedo.png"), project.path("assets/real_albedo.png")).unwrap();
    std::os::unix::fs::symlink("real_albedo.png", project.path("assets/albedo.png")).unwrap();
    let summary = build(&mut project.open());
    assert!(summary.all_ok(), "{}", summary.to_text());
}

#[test]
fn server_addresses_take_host_names_and_a_public_one_is_warned_about() {
    let config = parse_pipeline(
        Path::new("pipeline.ron"),
        r#"Pipeline(source: "a", output: "b", server: Some("localhost:7878"))"#,
    )
    .unwrap();
    assert_eq!(config.server.map(|address| (address.ip().is_loopback(), address.port())), Some((true, 7878)));
    let error =
        parse_pipeline(Path::new("pipeline.ron"), r#"Pipeline(source: "a", output: "b", server: Some("localhost"))"#)
            .unwrap_err();
    assert!(error.to_string().contains("localhost:7878"), "{error}");

    let project = watched_project();
    let daemon = Daemon::start_with(&project, &["--listen", "0.0.0.0:0"]);
    let mut client = daemon.connect();
    client.subscribe(Some(0));
    client.batch();
    let log = daemon.log.lock().unwrap().clone();
    assert!(log.contains("no authentication"), "{log}");
    drop(daemon);
    let daemon = Daemon::start_with(&project, &["--listen", "localhost:0"]);
    daemon.connect();
}

#[test]
fn a_cache_entry_moved_under_another_key_is_a_miss_not_another_result() {
    let project = material_project();
    assert!(build(&mut project.open()).all_ok());
    let good = output_hashes(&project);
    // Swap every pair of entries of the final stage: each now sits under another surface's key.
    let entries = crate::support::files_under(&project.path("baked/.cirrus/cache"));
    assert!(entries.len() >= 2, "{entries:?}");
    let contents: Vec<Vec<u8>> = entries.iter().map(|path| std::fs::read(path).unwrap()).collect();
    for (index, path) in entries.iter().enumerate() {
        std::fs::write(path, &contents[(index + 1) % contents.len()]).unwrap();
    }
    std::fs::remove_dir_all(project.path("baked/rock")).unwrap();
    std::fs::remove_dir_all(project.path("baked/moss")).unwrap();
    let summary = build(&mut project.open());
    assert!(summary.all_ok(), "{}", summary.to_text());
    assert_eq!(output_hashes(&project), good, "every artifact as before: swapped entries were misses");
}

#[test]
fn meshes_too_large_too_small_or_flat_for_single_precision_fail_with_a_diagnostic() {
    let triangle = |scale: &str| format!("v 0 0 0\nv {scale} 0 0\nv 0 {scale} 0\nf 1 2 3\n");
    let error = load_obj(&triangle("1e30"), None).expect_err("too large");
    assert!(error.message.contains("scale it down"), "{error}");
    let error = load_obj(&triangle("1e-30"), None).expect_err("too small");
    assert!(error.message.contains("scale it up"), "{error}");
    let error = load_obj("v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n", None).expect_err("zero area");
    assert!(error.message.contains("zero area"), "{error}");
    assert!(load_obj(&triangle("1e3"), None).is_ok());
}

// ---------------------------------------------------------------------------------------------
// low

#[test]
fn the_cheap_low_ones() {
    // A byte-order mark in pipeline.ron.
    assert!(parse_pipeline(Path::new("pipeline.ron"), "\u{feff}Pipeline(source: \"a\", output: \"b\")").is_ok());

    // `usemtl` of a material no MTL defines is warned about, with its line.
    let (_, warnings) =
        load_obj("mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl nope\nf 1 2 3\n", Some("newmtl bark\n")).unwrap();
    let warning = warnings.iter().find(|warning| warning.message.contains("usemtl nope")).expect("a warning");
    assert_eq!((warning.file.as_path(), warning.line()), (Path::new("assets/m.obj"), Some(5)));

    // OBJ errors carry their line.
    for (obj, line) in [
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 9\n", 5),
        ("v 0 0 0\nv 1 oops 0\n", 2),
        ("v 0 0 0\nvt 0 0\nf 1/1 1/7 1/1\n", 3),
    ] {
        let error = load_obj(obj, None).expect_err(obj);
        assert_eq!(error.line(), Some(line), "{error}");
        assert!(error.message.starts_with("malformed OBJ: "), "{error}");
    }

    // MTL warnings name the MTL file.
    let (_, warnings) = load_obj(
        "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl bark\nf 1 2 3\n",
        Some("newmtl bark\nmap_Kd ../../x.png\n"),
    )
    .unwrap();
    assert!(
        warnings
            .iter()
            .any(|warning| warning.file == Path::new("assets/m.mtl")
                && warning.message.contains("leaves the source folder")),
        "{warnings:?}"
    );

    // Temporary files that a killed build left behind are swept (once they are a minute old).
    let project = material_project();
    project.write("baked/rock/.cirrus-tmp-old", "partial");
    project.write("baked/rock/.cirrus-tmp-fresh", "partial");
    let status = Command::new("touch")
        .args(["-d", "2 minutes ago"])
        .arg(project.path("baked/rock/.cirrus-tmp-old"))
        .status()
        .unwrap();
    assert!(status.success());
    build(&mut project.open());
    assert!(!project.path("baked/rock/.cirrus-tmp-old").exists());
    assert!(project.path("baked/rock/.cirrus-tmp-fresh").exists(), "a fresh one may belong to a running build");
}

#[test]
fn protocol_edges_since_from_the_future_unknown_graph_assets_and_too_many_clients() {
    let project = watched_project();
    let daemon = Daemon::start(&project);
    let mut client = daemon.connect();
    client.subscribe(Some(0));
    let revision = client.batch()["revision"].as_u64().unwrap();

    let mut late = daemon.connect();
    late.subscribe(Some(revision + 100));
    let message = late.receive();
    assert_eq!(message["type"], "resync", "{message}");
    assert!(message["message"].as_str().unwrap().contains("newer than the daemon's revision"), "{message}");

    client.send(r#"{"type":"graph","format":"json","asset":"nope"}"#);
    let message = client.receive();
    assert_eq!(message["type"], "error", "{message}");
    assert!(message["message"].as_str().unwrap().contains("no asset named `nope`"), "{message}");

    let mut crowd = Vec::new();
    // Each sends a request at once, as a JSON-lines client may: served without the 150 ms the
    // daemon waits for a silent client's first byte (a WebSocket's upgrade), so the crowd
    // arrives before any of it has been idle for the 5 s that would free its slot.
    let refused = (0..80).any(|_| {
        let mut stream = std::net::TcpStream::connect(&daemon.address).unwrap();
        std::io::Write::write_all(&mut stream, b"{\"type\":\"ping\"}\n").unwrap();
        stream.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
        let mut reader = std::io::BufReader::new(stream.try_clone().unwrap());
        let mut line = String::new();
        std::io::BufRead::read_line(&mut reader, &mut line).unwrap();
        crowd.push(stream);
        line.contains("too many clients")
    });
    assert!(refused, "connections beyond the cap are refused");
    drop(crowd);
}

#[test]
fn an_asset_taken_out_of_the_pipeline_leaves_no_empty_folder_behind() {
    // Its artifacts are deleted as stale; the folders that held them went with them only when
    // they were empty: the other asset's folder and anything else in the output stay.
    let project = material_project();
    assert!(build(&mut project.open()).all_ok());
    assert!(project.path("baked/moss/moss").is_dir());
    project.write("baked/notes.txt", "someone's file");
    let pipeline = std::fs::read_to_string(project.path("pipeline.ron")).unwrap();
    project.write("pipeline.ron", pipeline.replace(r#"Material(name: "moss", material: "moss.mymaterial"),"#, ""));
    assert!(build(&mut project.open()).all_ok());
    assert!(!project.path("baked/moss").exists(), "the removed asset's folder is gone");
    assert!(project.path("baked/rock/rock/albedo.ktx2").is_file());
    assert!(project.path("baked/notes.txt").is_file());
}

#[test]
fn half_open_websocket_handshakes_cannot_pile_up_threads_and_the_daemon_serves_again_after_them() {
    // 100 connections that send the `G` of an upgrade and stall: each used to hold a thread of
    // its own for the 5 s handshake timeout. At most `max_clients` (64) may be opening at once;
    // the others are closed at once, and when the stalled ones time out a client is served.
    let project = watched_project();
    let mut daemon = Daemon::start(&project);
    let mut client = daemon.connect();
    client.subscribe(Some(0));
    client.batch();
    let threads = |daemon: &Daemon| -> usize {
        let status = std::fs::read_to_string(format!("/proc/{}/status", daemon.child.id())).unwrap();
        let line = status.lines().find(|line| line.starts_with("Threads:")).unwrap().to_string();
        line.split_whitespace().nth(1).unwrap().parse().unwrap()
    };
    let before = threads(&daemon);
    let stalled: Vec<std::net::TcpStream> = (0..100)
        .map(|_| {
            let mut stream = std::net::TcpStream::connect(&daemon.address).unwrap();
            std::io::Write::write_all(&mut stream, b"G").unwrap();
            stream
        })
        .collect();
    std::thread::sleep(Duration::from_millis(500));
    let during = threads(&daemon);
    assert!(during <= before + 64, "{before} threads before, {during} with 100 stalled handshakes");
    let closed = stalled
        .iter()
        .filter(|stream| {
            stream.set_read_timeout(Some(Duration::from_millis(20))).unwrap();
            matches!(std::io::Read::read(&mut &**stream, &mut [0u8; 1]), Ok(0))
        })
        .count();
    assert!(closed >= 30, "{closed} of 100 stalled connections closed at once");
    let started = Instant::now();
    let served = loop {
        let mut stream = std::net::TcpStream::connect(&daemon.address).unwrap();
        std::io::Write::write_all(&mut stream, b"{\"type\":\"ping\"}\n").unwrap();
        stream.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
        let mut line = String::new();
        let _ = std::io::BufRead::read_line(&mut std::io::BufReader::new(stream), &mut line);
        if line.contains("\"hello\"") {
            break started.elapsed();
        }
        assert!(started.elapsed() < Duration::from_secs(30), "no client served 30 s after the stalled handshakes");
        std::thread::sleep(Duration::from_millis(200));
    };
    println!(
        "half-open handshakes: {before} → {during} threads, {closed} closed at once, served again after {served:?}"
    );
    drop(stalled);
    assert!(daemon.alive());
}

/// Runs `cirrus ARGS` with `environment`, polling its peak resident memory (MiB): the output and
/// the peak.
fn run_measuring_memory(
    project: &TempProject,
    arguments: &[&str],
    environment: &[(&str, &str)],
    limit: Duration,
) -> (Output, u64) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_cirrus"))
        .args(arguments)
        .envs(environment.iter().copied())
        .current_dir(project.root())
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run cirrus");
    let status_file = format!("/proc/{}/status", child.id());
    let (start, mut peak_kib) = (Instant::now(), 0u64);
    while child.try_wait().expect("status").is_none() {
        if let Some(line) = std::fs::read_to_string(&status_file)
            .ok()
            .and_then(|status| status.lines().find(|line| line.starts_with("VmHWM:")).map(str::to_string))
        {
            peak_kib = peak_kib.max(line.split_whitespace().nth(1).and_then(|kib| kib.parse().ok()).unwrap_or(0));
        }
        assert!(start.elapsed() < limit, "`cirrus {}` still ran after {limit:?}", arguments.join(" "));
        std::thread::sleep(Duration::from_millis(10));
    }
    (child.wait_with_output().expect("output"), peak_kib / 1024)
}

#[test]
fn a_shared_store_object_larger_than_any_entry_is_refused_without_being_read() {
    // Three 3 GiB objects in a file:// store took a build to 12 GB and 68 s: each was read
    // whole before its checksum said it was no entry. Sparse files cost no disk here.
    let store = tempfile::tempdir().unwrap();
    let project = material_project();
    let pipeline = std::fs::read_to_string(project.path("pipeline.ron")).unwrap();
    let with_store = pipeline.replacen(
        "Pipeline(",
        &format!("Pipeline(cache: (remote: Some(\"file://{}\")), ", store.path().display()),
        1,
    );
    project.write("pipeline.ron", with_store);
    let (output, _) = run_measuring_memory(&project, &["build"], &[], Duration::from_secs(120));
    assert!(output.status.success(), "{}", text(&output));
    let mut objects = crate::support::files_under(store.path());
    objects.retain(|path| !path.to_string_lossy().contains("cirrus-probe"));
    assert!(objects.len() >= 3, "the build uploaded its entries: {objects:?}");
    for object in &objects {
        let file = std::fs::OpenOptions::new().write(true).open(object).unwrap();
        file.set_len(3 << 30).unwrap();
    }
    std::fs::remove_dir_all(project.path("baked")).unwrap();
    let (output, peak_mib) = run_measuring_memory(&project, &["build"], &[], Duration::from_secs(120));
    assert!(output.status.success(), "{}", text(&output));
    assert!(peak_mib < 400, "peak {peak_mib} MiB: an oversized object was read");
    assert!(text(&output).contains("more than an entry can be"), "{}", text(&output));
    // One warning per object: its size, not also "failed verification".
    assert!(!text(&output).contains("failed verification"), "{}", text(&output));
    assert!(project.path("baked/rock/rock/albedo.ktx2").is_file());
}

#[test]
fn a_malformed_s3_endpoint_is_a_configuration_error_not_a_panic_and_the_daemon_bakes_locally() {
    let project = material_project();
    let pipeline = std::fs::read_to_string(project.path("pipeline.ron")).unwrap();
    project.write(
        "pipeline.ron",
        pipeline.replacen("Pipeline(", "Pipeline(cache: (remote: Some(\"s3://bucket/prefix\")), ", 1),
    );
    let credentials = [("AWS_ACCESS_KEY_ID", "a"), ("AWS_SECRET_ACCESS_KEY", "b"), ("AWS_REGION", "us-east-1")];
    for endpoint in ["notaurl", "http://[::1", "ftp://example.com", ""] {
        let mut environment = credentials.to_vec();
        environment.push(("AWS_ENDPOINT_URL", endpoint));
        let (output, _) = run_measuring_memory(&project, &["build"], &environment, Duration::from_secs(60));
        assert_eq!(output.status.code(), Some(2), "{endpoint}: {}", text(&output));
        let message = text(&output);
        assert!(
            message.contains(&format!("AWS_ENDPOINT_URL=`{endpoint}` is not an endpoint URL"))
                && !message.contains("panicked"),
            "{message}"
        );
    }
    // The daemon warns and bakes without the store.
    let mut environment = credentials.to_vec();
    environment.push(("AWS_ENDPOINT_URL", "notaurl"));
    let mut child = Command::new(env!("CARGO_BIN_EXE_cirrus"))
        .args(["watch", "--listen", "127.0.0.1:0"])
        .envs(environment)
        .current_dir(project.root())
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run the daemon");
    let start = Instant::now();
    while !project.path("baked/rock/rock/albedo.ktx2").is_file() && start.elapsed() < Duration::from_secs(60) {
        assert!(child.try_wait().unwrap().is_none(), "the daemon exited");
        std::thread::sleep(Duration::from_millis(50));
    }
    let _ = child.kill();
    let output = child.wait_with_output().unwrap();
    let log = String::from_utf8_lossy(&output.stderr);
    assert!(project.path("baked/rock/rock/albedo.ktx2").is_file(), "{log}");
    assert!(log.contains("not an endpoint URL") && !log.contains("panicked"), "{log}");
}

#[test]
fn an_ao_bake_of_minutes_is_warned_about_and_a_fix_under_watch_cancels_it_within_seconds() {
    use crate::ambient_occlusion::{ao_project, floor_and_box};
    // 256² maps at a million rays a texel: hours on two cores.
    let project = ao_project(&floor_and_box(false), "size: 256, rays: 1048576, occluders: AllMeshes");
    let check = text(&run_with_deadline(&project, &["check"], Duration::from_secs(60)));
    assert!(check.contains("at `rays: 1048576`: the bake takes about") && check.contains(" h on "), "{check}");

    let daemon = Daemon::start(&project);
    let mut client = daemon.connect();
    client.subscribe(Some(0));
    // The first build is inside its tiles now; the user lowers the rays.
    std::thread::sleep(Duration::from_secs(3));
    let pipeline = String::from_utf8(project.read("pipeline.ron")).unwrap();
    project.write("pipeline.ron", pipeline.replace("rays: 1048576", "rays: 16"));
    let edited = Instant::now();
    let batch = next_batch(&daemon, &mut client);
    let waited = edited.elapsed();
    assert_eq!(batch["failed"], serde_json::json!([]), "{batch}");
    assert!(waited < Duration::from_secs(30), "the fix waited {waited:?} for the long tiles");
    let log = daemon.log.lock().unwrap().clone();
    assert!(log.contains("build cancelled by a newer edit"), "{log}");
    let report: serde_json::Value = serde_json::from_slice(&project.read("baked/scene/report.json")).unwrap();
    assert_eq!(report["rays_per_texel"], 16);
}

#[test]
fn texture_work_on_many_threads_holds_no_more_than_one_budget_at_once() {
    use std::sync::atomic::{AtomicU64, Ordering};
    let budget = cirrus::schedule::MemoryBudget::new();
    let (held, most) = (AtomicU64::new(0), AtomicU64::new(0));
    std::thread::scope(|scope| {
        for _ in 0..8 {
            scope.spawn(|| {
                let _reservation = budget.reserve(600, 1000);
                let now = held.fetch_add(600, Ordering::SeqCst) + 600;
                most.fetch_max(now, Ordering::SeqCst);
                std::thread::sleep(Duration::from_millis(10));
                held.fetch_sub(600, Ordering::SeqCst);
            });
        }
    });
    assert_eq!(most.load(Ordering::SeqCst), 600, "two 600-byte working sets never share a 1000-byte budget");
    // A working set larger than the budget still runs when it is alone.
    drop(budget.reserve(5000, 1000));
    assert_eq!(budget.reserved(), 0);
}

#[test]
fn a_full_stdout_a_file_size_limit_and_thousands_of_threads_give_messages_not_crashes() {
    let binary = env!("CARGO_BIN_EXE_cirrus");
    // The summary written to a full device: a message and exit 1, not a panic (101).
    let project = material_project();
    let full = std::fs::File::create("/dev/full").expect("/dev/full");
    let output = run_command_with_deadline(
        Command::new(binary).arg("build").current_dir(project.root()).stdout(full),
        Duration::from_secs(60),
    );
    assert_eq!(output.status.code(), Some(1), "{}", text(&output));
    assert!(text(&output).contains("could not write to standard output: No space left on device"), "{}", text(&output));
    assert!(project.path("baked/rock/rock/albedo.ktx2").is_file(), "the artifacts were baked");

    // Files limited to 16 KiB (`ulimit -f`) and a 256² albedo (its BC7 file is larger): the
    // writes past the limit fail with a message; no signal kills the process.
    let project = material_project();
    project.write("assets/albedo.png", pattern_png(256, 256, 1));
    let output = run_command_with_deadline(
        Command::new("sh")
            .args(["-c", &format!("ulimit -f 16 && exec '{binary}' build")])
            .current_dir(project.root())
            .stdout(Stdio::piped()),
        Duration::from_secs(60),
    );
    assert_eq!(output.status.code(), Some(1), "killed by a signal? {:?}\n{}", output.status, text(&output));
    assert!(text(&output).contains("File too large"), "{}", text(&output));

    // Far more threads than cores: warned about and capped, the build finishes as usual.
    let project = material_project();
    let output = run_command_with_deadline(
        Command::new(binary)
            .arg("build")
            .env("RAYON_NUM_THREADS", "2000")
            .current_dir(project.root())
            .stdout(Stdio::piped()),
        Duration::from_secs(60),
    );
    assert!(output.status.success(), "{}", text(&output));
    assert!(text(&output).contains("RAYON_NUM_THREADS=2000 is more than this machine's"), "{}", text(&output));
}

#[test]
fn the_daemon_hears_a_source_folder_deleted_and_created_again_at_once() {
    let project = watched_project();
    let daemon = Daemon::start(&project);
    let mut client = daemon.connect();
    client.subscribe(Some(0));
    next_batch(&daemon, &mut client);
    let saved = tempfile::tempdir().unwrap();
    let status = Command::new("cp").arg("-r").arg(project.path("assets")).arg(saved.path()).status().unwrap();
    assert!(status.success());
    for (round, gap) in [0, 50, 150, 400, 700].into_iter().enumerate() {
        // A branch switch: the folder goes and comes back within a second.
        std::fs::remove_dir_all(project.path("assets")).unwrap();
        std::thread::sleep(Duration::from_millis(gap));
        let status =
            Command::new("cp").arg("-r").arg(saved.path().join("assets")).arg(project.root()).status().unwrap();
        assert!(status.success());
        std::thread::sleep(Duration::from_millis(400));
        project.write("assets/ao.png", pattern_png(32, 32, 20 + round as u32));
        let mut heard = false;
        while !heard {
            let batch = next_batch(&daemon, &mut client);
            heard = changed_paths(&project, &batch).contains(&"baked/rock/rock/mra.ktx2".to_string());
        }
    }
}

#[test]
fn the_daemon_prints_a_plain_line_per_batch_into_a_log_that_is_not_a_terminal() {
    let project = watched_project();
    let daemon = Daemon::start(&project);
    let mut client = daemon.connect();
    client.subscribe(Some(0));
    next_batch(&daemon, &mut client);
    project.write("assets/ao.png", pattern_png(32, 32, 30));
    next_batch(&daemon, &mut client);
    // The line follows the batch's publication.
    let start = Instant::now();
    while daemon.log.lock().unwrap().matches("cirrus watch: batch r").count() < 2
        && start.elapsed() < Duration::from_secs(10)
    {
        std::thread::sleep(Duration::from_millis(20));
    }
    let log = daemon.log.lock().unwrap().clone();
    assert!(!log.contains('\u{1b}'), "colour codes in a log that is not a terminal:\n{log}");
    let batch_lines: Vec<&str> = log.lines().filter(|line| line.starts_with("cirrus watch: batch r")).collect();
    assert_eq!(batch_lines.len(), 2, "{log}");
    assert!(
        batch_lines[1].contains("1 file(s) changed, 1 asset(s) rebuilt") && batch_lines[1].ends_with(" ms"),
        "{}",
        batch_lines[1]
    );
}

#[test]
fn idle_connections_filling_every_slot_give_way_to_a_new_client() {
    let project = material_project();
    let daemon = Daemon::start(&project);
    let mut first = daemon.connect();
    first.subscribe(Some(0));
    next_batch(&daemon, &mut first);
    // 70 connections that never say a word: every slot but the subscriber's is taken.
    let crowd: Vec<std::net::TcpStream> =
        (0..70).map(|_| std::net::TcpStream::connect(&daemon.address).unwrap()).collect();
    std::thread::sleep(Duration::from_millis(5500));
    // Past the grace, a newcomer gets an idle one's slot and its batches.
    let mut late = daemon.connect();
    late.subscribe(Some(0));
    let batch = next_batch(&daemon, &mut late);
    assert_eq!(batch["revision"], 1, "{batch}");
    project.write("assets/normal.png", pattern_png(32, 32, 9));
    assert_eq!(next_batch(&daemon, &mut late)["revision"], 2);
    assert_eq!(next_batch(&daemon, &mut first)["revision"], 2, "the subscriber kept its slot");
    drop(crowd);
}

#[test]
fn a_second_daemon_on_one_output_folder_is_refused_naming_the_first() {
    let project = material_project();
    let daemon = Daemon::start(&project);
    let output = run_command_with_deadline(
        Command::new(env!("CARGO_BIN_EXE_cirrus"))
            .args(["watch", "--listen", "127.0.0.1:0"])
            .current_dir(project.root())
            .stdout(Stdio::piped()),
        Duration::from_secs(30),
    );
    assert_eq!(output.status.code(), Some(2), "{}", text(&output));
    let message = text(&output);
    let pid = format!("pid {}", daemon.child.id());
    assert!(message.contains("another `cirrus watch`") && message.contains(&pid), "{message}");
    assert!(message.contains(&format!("listening on {}", daemon.address)), "{message}");
    // Reconfigured to another output folder, it holds that one and lets the old one go.
    let mut client = daemon.connect();
    client.subscribe(Some(0));
    next_batch(&daemon, &mut client);
    let pipeline = String::from_utf8(project.read("pipeline.ron")).unwrap();
    project.write("pipeline.ron", pipeline.replace(r#"output: "baked""#, r#"output: "baked2""#));
    next_batch(&daemon, &mut client);
    let free = |folder: &str| {
        let lock = project.path(&format!("{folder}/.cirrus/watch.lock"));
        Command::new("flock").arg("-n").arg(&lock).arg("true").status().expect("flock(1)").success()
    };
    assert!(free("baked") && !free("baked2"), "the lock moved with the output folder");
    project.write("pipeline.ron", &pipeline);
    next_batch(&daemon, &mut client);
    // Once the first is gone, the folder is free.
    drop(daemon);
    let again = Daemon::start(&project);
    assert!(again.address.starts_with("127.0.0.1:"));
}

#[test]
fn misspelled_files_and_asset_names_get_the_closest_existing_one() {
    let project = material_project();
    let pipeline = String::from_utf8(project.read("pipeline.ron")).unwrap();
    project.write("pipeline.ron", pipeline.replace("material: \"rock.mymaterial\"", "material: \"rocks.mymaterial\""));
    let check = text(&run_with_deadline(&project, &["check"], Duration::from_secs(30)));
    assert!(check.contains("assets/rocks.mymaterial: file not found (did you mean `rock.mymaterial`?)"), "{check}");
    let build = text(&run_with_deadline(&project, &["build", "--asset", "mos"], Duration::from_secs(30)));
    assert!(build.contains("no asset named `mos`") && build.contains("(did you mean `moss`?)"), "{build}");
    // Nothing close: no guess.
    let build = text(&run_with_deadline(&project, &["build", "--asset", "granite"], Duration::from_secs(30)));
    assert!(build.contains("no asset named `granite`") && !build.contains("did you mean"), "{build}");
}

#[test]
fn a_flag_variable_set_to_nothing_is_refused_under_its_own_name() {
    let project = material_project();
    let mut command = Command::new(env!("CARGO_BIN_EXE_cirrus"));
    command.arg("check").env("CIRRUS_ISA", "").current_dir(project.root()).stdout(Stdio::piped());
    let output = run_command_with_deadline(&mut command, Duration::from_secs(30));
    assert_eq!(output.status.code(), Some(2), "{}", text(&output));
    assert!(text(&output).contains("CIRRUS_ISA is set but empty (it stands for --isa)"), "{}", text(&output));
    let output = run_with_deadline(&project, &["--remote-cache", "", "build"], Duration::from_secs(30));
    assert_eq!(output.status.code(), Some(2), "{}", text(&output));
    assert!(text(&output).contains("--remote-cache: it is empty"), "{}", text(&output));
}

#[test]
fn check_answers_in_json_and_for_one_asset() {
    let project = material_project();
    project.write(
        "assets/moss.mymaterial",
        "Material $moss { Texture (attrib = \"diffuse\") {string {\"missing.png\"}} }\n",
    );
    let output = run_with_deadline(&project, &["check", "--json"], Duration::from_secs(30));
    assert_eq!(output.status.code(), Some(1), "{}", text(&output));
    let json: serde_json::Value =
        serde_json::from_slice(&output.stdout).unwrap_or_else(|error| panic!("{error}: {}", text(&output)));
    assert_eq!(
        (json["checked"].clone(), json["failed"].clone()),
        (serde_json::json!(2), serde_json::json!(1)),
        "{json}"
    );
    let moss = json["assets"].as_array().unwrap().iter().find(|asset| asset["name"] == "moss").unwrap();
    assert_eq!(moss["problems"][0]["severity"], "error", "{json}");
    assert!(moss["problems"][0]["message"].as_str().unwrap().contains("missing.png"), "{json}");
    // One asset: only it is checked.
    let output = run_with_deadline(&project, &["check", "--asset", "rock"], Duration::from_secs(30));
    assert!(output.status.success(), "{}", text(&output));
    assert!(text(&output).contains("1 assets checked, 0 with problems"), "{}", text(&output));
    let output = run_with_deadline(&project, &["check", "--asset", "mos"], Duration::from_secs(30));
    assert_eq!(output.status.code(), Some(2));
    assert!(text(&output).contains("(did you mean `moss`?)"), "{}", text(&output));
}

#[test]
fn rule_matched_files_deleted_while_they_bake_leave_at_once_and_what_was_published_is_withdrawn() {
    fn files_under(folder: &Path) -> usize {
        let Ok(entries) = std::fs::read_dir(folder) else { return 0 };
        entries.flatten().map(|entry| if entry.path().is_dir() { files_under(&entry.path()) } else { 1 }).sum()
    }
    let paths = |batch: &serde_json::Value, key: &str| -> Vec<String> {
        let entries = batch[key].as_array().cloned().unwrap_or_default();
        entries
            .iter()
            .filter_map(|entry| entry.as_str().or_else(|| entry["path"].as_str()).map(str::to_string))
            .collect()
    };
    let project = watched_project();
    let daemon = Daemon::start(&project);
    let mut client = daemon.connect();
    client.subscribe(Some(0));
    next_batch(&daemon, &mut client);
    for index in 0..300 {
        project.write(
            &format!("assets/extra/gone/burst_{index:03}.mymaterial"),
            format!("Material $m {{ Texture (attrib = \"diffuse\") {{string {{\"../../albedo.png\"}}}} Param (attrib = \"roughness\") {{float {{{}}}}} }}\n", index as f32 / 300.0),
        );
    }
    // The rule takes them in: the daemon bakes them; the folder goes while it does.
    let pipeline = String::from_utf8(project.read("pipeline.ron")).unwrap();
    project.write("pipeline.ron", pipeline.replace("extra/*.mymaterial", "extra/**/*.mymaterial"));
    std::thread::sleep(Duration::from_millis(400));
    std::fs::remove_dir_all(project.path("assets/extra/gone")).unwrap();
    let deleted = Instant::now();
    let (mut published, mut withdrawn) = (BTreeSet::new(), BTreeSet::new());
    loop {
        let batch = next_batch(&daemon, &mut client);
        published.extend(paths(&batch, "changed").into_iter().filter(|path| path.starts_with("baked/extra/gone/")));
        withdrawn.extend(paths(&batch, "removed"));
        if files_under(&project.path("baked/extra/gone")) == 0 || deleted.elapsed() > Duration::from_secs(15) {
            break;
        }
    }
    let log = daemon.log.lock().unwrap().clone();
    assert_eq!(
        files_under(&project.path("baked/extra/gone")),
        0,
        "the deleted assets' artifacts are gone within 15 s\n{log}"
    );
    assert!(deleted.elapsed() < Duration::from_secs(5), "they went {:?} after the deletion\n{log}", deleted.elapsed());
    let never_withdrawn: Vec<&String> = published.difference(&withdrawn).collect();
    assert!(never_withdrawn.is_empty(), "published as changed, never as removed: {never_withdrawn:?}");
}

#[test]
fn an_impostor_level_of_minutes_is_warned_about_and_an_edit_back_under_watch_cancels_it_within_seconds() {
    // 32 × 32 frames of 256² (rendered at 512²) into an 8192² atlas: the impostor stage alone ran
    // 147 s on llvmpipe, and an edit back to a cheap level waited 224 s for its batch.
    let costly = "billboard: (lods: [Impostor(frames: 32, hemi: false, size: 8192)])";
    let pipeline = |lods: &str| {
        format!(
            r#"Pipeline(source: "assets", output: "baked", assets: [
                BillboardCloud(name: "bush", mesh: "trees/bush_2.obj", atlas: (max_size: 512), {lods}),
            ])"#
        )
    };
    let project = TempProject::new(&pipeline(costly));
    project.copy_folder(&Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/assets/trees"), "assets/trees");
    let check = text(&run_with_deadline(&project, &["check"], Duration::from_secs(60)));
    assert!(check.contains("lod0 `Impostor(frames:32,hemi:false,size:8192)`: renders and encodes about"), "{check}");
    assert!(check.contains("× the median of the other levels"), "{check}");
    // The bundled chain's levels are not warned about.
    project.write(
        "pipeline.ron",
        pipeline("billboard: (lods: [Reduced(Ratio(0.5)), Quads(64), Impostor(frames: 8, hemi: false, size: 512)])"),
    );
    let check = text(&run_with_deadline(&project, &["check"], Duration::from_secs(60)));
    assert!(!check.contains("renders and encodes about"), "{check}");

    project.write("pipeline.ron", pipeline(costly));
    let daemon = Daemon::start(&project);
    let mut client = daemon.connect();
    client.subscribe(Some(0));
    // The first build is rendering frames now; the user takes the level back.
    std::thread::sleep(Duration::from_secs(8));
    project.write("pipeline.ron", pipeline("billboard: (lods: [Impostor(frames: 8, hemi: false, size: 512)])"));
    let edited = Instant::now();
    let batch = next_batch(&daemon, &mut client);
    let waited = edited.elapsed();
    assert_eq!(batch["failed"], serde_json::json!([]), "{batch}");
    let log = daemon.log.lock().unwrap().clone();
    assert!(log.contains("build cancelled by a newer edit"), "{log}");
    assert!(waited < Duration::from_secs(60), "the edit back waited {waited:?} for the costly frames");
    println!("an edit back during the 32 × 32 impostor's frames was baked {waited:?} later");
    let report: serde_json::Value = serde_json::from_slice(&project.read("baked/bush/report.json")).unwrap();
    assert_eq!(report["levels"][0]["frames"], 8, "{report}");
}

#[test]
fn a_huge_build_record_is_parsed_as_it_is_read_or_refused_by_its_size_without_being_read() {
    let project = material_project();
    assert!(build(&mut project.open()).all_ok());
    let record = project.path("baked/.cirrus/record.json");
    // 200 MB of whitespace inside a valid record: parsed as it streams, never held whole (it was
    // read whole, then parsed: the bytes alone were 200 MB).
    let mut padded = b"{".to_vec();
    padded.resize(200 << 20, b' ');
    padded.extend_from_slice(br#""version":1,"files":{},"assets":{}}"#);
    std::fs::write(&record, &padded).unwrap();
    drop(padded);
    let (output, padded_peak) = run_measuring_memory(&project, &["build"], &[], Duration::from_secs(120));
    assert!(output.status.success(), "{}", text(&output));
    // 600 MB (sparse: nothing is written to disk), over the 256 MiB limit: not read at all.
    let file = std::fs::File::create(&record).unwrap();
    file.set_len(600 << 20).unwrap();
    drop(file);
    let (output, huge_peak) = run_measuring_memory(&project, &["build"], &[], Duration::from_secs(120));
    assert!(output.status.success(), "{}", text(&output));
    assert!(text(&output).contains("record.json is larger than 256 MiB; rebuilding it"), "{}", text(&output));
    println!("build record of 200 MB padding: peak {padded_peak} MiB; of 600 MB: peak {huge_peak} MiB");
    assert!(padded_peak < 120 && huge_peak < 120, "peaks {padded_peak} and {huge_peak} MiB");
}

#[test]
fn a_garbage_truncated_or_deleted_manifest_is_warned_about_and_the_revision_never_goes_back() {
    let project = material_project();
    let revision = |project: &TempProject| manifest(project)["revision"].as_u64().unwrap();
    for seed in 0..5 {
        project.write("assets/albedo.png", pattern_png(32, 32, 10 + seed));
        assert!(build(&mut project.open()).all_ok());
    }
    let mut last = revision(&project);
    assert!(last >= 5, "{last}");
    let manifest_path = project.path("baked/manifest.json");
    let whole = std::fs::read(&manifest_path).unwrap();
    let damages: [(&str, Option<Vec<u8>>); 3] = [
        ("is damaged (not valid JSON of its kind", Some(b"garbage".to_vec())),
        ("is damaged (not valid JSON of its kind", Some(whole[..whole.len() / 2].to_vec())),
        ("is missing", None),
    ];
    for (seed, (said, damage)) in damages.into_iter().enumerate() {
        match damage {
            Some(bytes) => std::fs::write(&manifest_path, bytes).unwrap(),
            None => std::fs::remove_file(&manifest_path).unwrap(),
        }
        project.write("assets/albedo.png", pattern_png(32, 32, 20 + seed as u32));
        let output = run_with_deadline(&project, &["build"], Duration::from_secs(60));
        assert!(output.status.success(), "{}", text(&output));
        assert!(text(&output).contains(&format!("baked/manifest.json {said}")), "{said}: {}", text(&output));
        let now = revision(&project);
        assert!(now > last, "the revision went from {last} to {now}");
        last = now;
    }
}

/// `material_project` over a `file://` shared store in `store`.
fn project_with_store(store: &Path) -> TempProject {
    let project = material_project();
    let pipeline = std::fs::read_to_string(project.path("pipeline.ron")).unwrap();
    let with_store =
        pipeline.replacen("Pipeline(", &format!("Pipeline(cache: (remote: Some(\"file://{}\")), ", store.display()), 1);
    project.write("pipeline.ron", with_store);
    project
}

/// The shared store's entry objects (the store's own probe left out).
fn store_objects(store: &Path) -> Vec<std::path::PathBuf> {
    let mut objects = crate::support::files_under(store);
    objects.retain(|path| !path.to_string_lossy().contains("cirrus-probe"));
    objects
}

#[test]
fn a_shared_store_object_that_is_no_entry_is_verified_as_it_streams_to_disk_not_held_in_memory() {
    // An object under the size limit (1 GiB) whose bytes are no entry used to be read whole into
    // memory before its checksum said so: three 1,000 MB objects took a build to 2.03 GB.
    let store = tempfile::tempdir().unwrap();
    let project = project_with_store(store.path());
    assert!(run_with_deadline(&project, &["build"], Duration::from_secs(60)).status.success());
    let objects = store_objects(store.path());
    assert!(objects.len() >= 3, "{objects:?}");
    // The largest keeps its header (stage and key) and grows to 600 MB of zeros (sparse).
    let largest = objects.iter().max_by_key(|object| std::fs::metadata(object).unwrap().len()).unwrap();
    std::fs::OpenOptions::new().write(true).open(largest).unwrap().set_len(600 << 20).unwrap();
    std::fs::remove_dir_all(project.path("baked")).unwrap();
    let (output, peak_mib) = run_measuring_memory(&project, &["build"], &[], Duration::from_secs(120));
    assert!(output.status.success(), "{}", text(&output));
    assert!(text(&output).contains("failed verification"), "{}", text(&output));
    println!("a 600 MB object that is no entry: build peak {peak_mib} MiB");
    assert!(peak_mib < 200, "peak {peak_mib} MiB: the object was held in memory");
    let leftovers: Vec<_> = crate::support::files_under(&project.path("baked"))
        .into_iter()
        .filter(|path| path.to_string_lossy().contains(".cirrus-tmp"))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
    assert!(project.path("baked/rock/rock/albedo.ktx2").is_file());
}

#[test]
fn with_a_team_key_only_entries_signed_with_it_are_used_and_a_forged_one_is_a_miss() {
    let key = ("CIRRUS_CACHE_KEY", "0123456789abcdef0123456789abcdef-team-key");
    let run = |project: &TempProject, environment: &[(&str, &str)]| {
        let mut command = Command::new(env!("CARGO_BIN_EXE_cirrus"));
        command.args(["build", "-v"]).envs(environment.iter().copied()).current_dir(project.root());
        let output = run_command_with_deadline(&mut command, Duration::from_secs(120));
        assert!(output.status.success(), "{}", text(&output));
        text(&output)
    };
    let store = tempfile::tempdir().unwrap();
    let first = project_with_store(store.path());
    run(&first, &[key]);
    let signed = store_objects(&store.path().join("signed"));
    assert!(!signed.is_empty() && store_objects(store.path()).len() == signed.len(), "only signed objects");
    let clean_albedo = first.read("baked/rock/rock/albedo.ktx2");

    // Someone with write access (but not the key) replaces every entry with another project's,
    // its blake3 checksum made anew: an unsigned machine would take it.
    let other_store = tempfile::tempdir().unwrap();
    let other = project_with_store(other_store.path());
    other.write("assets/albedo.png", pattern_png(32, 32, 77));
    run(&other, &[]);
    for object in &signed {
        let relative = object.strip_prefix(store.path().join("signed")).unwrap();
        if let Ok(mut forged) = std::fs::read(other_store.path().join(relative)) {
            let body = forged.len() - 32;
            let checksum = blake3::hash(&forged[..body]);
            forged[body..].copy_from_slice(checksum.as_bytes());
            // A signature of the right length, made without the key.
            forged.extend_from_slice(blake3::hash(&forged).as_bytes());
            std::fs::write(object, forged).unwrap();
        }
    }
    let second = project_with_store(store.path());
    let said = run(&second, &[key]);
    assert!(said.contains("failed verification"), "{said}");
    assert_eq!(second.read("baked/rock/rock/albedo.ktx2"), clean_albedo, "the forged entries were not used");

    // A third machine with the key is served by what the second uploaded over the forgeries.
    let third = project_with_store(store.path());
    let said = run(&third, &[key]);
    assert!(!said.contains("failed verification"), "{said}");
    assert_eq!(third.read("baked/rock/rock/albedo.ktx2"), clean_albedo);

    // A key too short to be one is a configuration error, not a silent unsigned cache.
    let mut command = Command::new(env!("CARGO_BIN_EXE_cirrus"));
    command.arg("build").env("CIRRUS_CACHE_KEY", "hunter2").current_dir(third.root());
    let said = text(&run_command_with_deadline(&mut command, Duration::from_secs(60)));
    assert!(said.contains("CIRRUS_CACHE_KEY is 7 characters long"), "{said}");
}

/// An atlas of one texture and the mesh `m/<mesh>` over it, whose MTL is `mtl` after `map_Kd`.
fn atlas_mesh_project(mesh: &str, obj_extra: &str, mtl_extra: &str) -> TempProject {
    let project = TempProject::new(
        r#"Pipeline(source: "assets", output: "baked", assets: [
            Atlas(name: "at", textures: ["m/*.png"], meshes: ["m/*.obj"]),
        ])"#,
    );
    project.write("assets/m/x.png", pattern_png(16, 16, 3));
    project.write("assets/m/a.mtl", format!("newmtl a\nKd 1 1 1\nmap_Kd x.png\n{mtl_extra}"));
    project.write(
        &format!("assets/m/{mesh}"),
        format!(
            "mtllib a.mtl\n{obj_extra}v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nusemtl a\nf 1/1 2/2 3/3\n"
        ),
    );
    project
}

#[test]
fn the_fourth_rounds_low_ones() {
    // What the remapped OBJ and atlas.mtl leave out is warned about, at its line.
    let project =
        atlas_mesh_project("m.obj", "o tree\ng trunk\nl 1 2\n", "Ks 0.5 0.5 0.5\nNs 20\nillum 2\nmap_Ks s.png\n");
    let summary = build(&mut project.open());
    assert!(summary.all_ok(), "{}", summary.to_text());
    let report = String::from_utf8(project.read("baked/at/report.json")).unwrap();
    for said in ["1 `o` statement(s) are not kept", "1 `g` statement(s)", "1 `l` statement(s)"] {
        assert!(report.contains(said), "{said}: {report}");
    }
    assert!(report.contains("material `a`: `Ks`, `Ns`, `illum`, `map_Ks` are not written to atlas.mtl"), "{report}");

    // A mesh named `..obj` keeps its extension (it was written as `m-..`).
    let project = atlas_mesh_project("..obj", "", "");
    assert!(build(&mut project.open()).all_ok());
    assert!(project.path("baked/at/m-..obj").is_file());
    assert!(!project.path("baked/at/m-..").exists());

    // A map linked to a device or a folder says so (it was "does not exist").
    for (target, said) in [("/dev/zero", "is not a regular file"), ("/tmp", "is a folder")] {
        let project = atlas_mesh_project("m.obj", "", "map_Pr r.png\n");
        std::os::unix::fs::symlink(target, project.path("assets/m/r.png")).unwrap();
        let said_text = build(&mut project.open()).to_text();
        assert!(said_text.contains(said) && !said_text.contains("does not exist"), "{target}: {said_text}");
    }

    // An atlas glob that climbs out of the source folder is named as such.
    let error = parse_pipeline(
        Path::new("pipeline.ron"),
        r#"Pipeline(source: "assets", output: "baked", assets: [Atlas(name: "at", textures: ["../other/*.png"])])"#,
    )
    .unwrap_err()
    .to_string();
    assert!(error.contains("`../other/*.png` leads outside the source folder"), "{error}");

    // An OBJ that does not parse counts its stage failed in the summary (it said `0 failed`).
    let project = TempProject::new(
        r#"Pipeline(source: "assets", output: "baked", assets: [AmbientOcclusion(name: "ao", mesh: "bad.obj")])"#,
    );
    project.write("assets/bad.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 99\n");
    let said_text = build(&mut project.open()).to_text();
    assert!(said_text.contains("1 failed") && said_text.contains("bad.obj:4:1"), "{said_text}");

    // A 1 × 262144 image is over the side limit, not "16384² texels".
    let project = material_project();
    project.write("assets/albedo.png", crate::support::png_bytes(1, 262_144, &vec![255u8; 262_144 * 4]));
    let said_text = build(&mut project.open()).to_text();
    assert!(
        said_text.contains("the decoder takes sides of at most 16384 texels") && !said_text.contains("16384²"),
        "{said_text}"
    );

    // `--remote-cache-mode bogus` names its own flag.
    let said = text_of(&project.run_cli(&["build", "--remote-cache-mode", "bogus"]));
    assert!(said.contains("error: --remote-cache-mode: `bogus` is not a shared cache mode"), "{said}");

    // A space around AWS_ENDPOINT_URL is a clear error, not a panic inside the S3 client.
    let project = material_project();
    let mut command = Command::new(env!("CARGO_BIN_EXE_cirrus"));
    command
        .args(["build", "--remote-cache", "s3://bucket/prefix"])
        .env("AWS_ENDPOINT_URL", " http://127.0.0.1:9")
        .current_dir(project.root());
    let said = text_of(&run_command_with_deadline(&mut command, Duration::from_secs(60)));
    assert!(said.contains("has spaces around it") && !said.contains("panicked"), "{said}");
}

fn text_of(output: &Output) -> String {
    text(output)
}

#[test]
fn the_low_mesh_of_a_height_bake_whose_uvs_are_all_equal_is_blamed_not_the_overlap() {
    let project = TempProject::new(
        r#"Pipeline(source: "assets", output: "baked", assets: [Height(name: "h", high: "high.obj", low: "low.obj")])"#,
    );
    let quad = |y: f32, vt: &str| {
        format!("v 0 {y} 0\nv 1 {y} 0\nv 1 {y} 1\nv 0 {y} 1\n{vt}vn 0 1 0\nf 1/1/1 2/2/1 3/3/1\nf 1/1/1 3/3/1 4/4/1\n")
    };
    project.write("assets/high.obj", quad(0.05, "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"));
    project.write("assets/low.obj", quad(0.0, "vt 0.5 0.5\nvt 0.5 0.5\nvt 0.5 0.5\nvt 0.5 0.5\n"));
    let text = build(&mut project.open()).to_text();
    assert!(text.contains("the low mesh's UVs cover no texel"), "{text}");
    assert!(!text.contains("do the two meshes overlap"), "{text}");
}

#[test]
fn a_read_only_machine_whose_endpoint_is_no_s3_store_is_warned_that_every_lookup_misses() {
    // A web server that answers 404 to everything: the HEAD probe took it for a store.
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let address = listener.local_addr().unwrap();
    std::thread::spawn(move || {
        for stream in listener.incoming().flatten() {
            let mut stream = stream;
            let mut request = [0u8; 4096];
            let _ = std::io::Read::read(&mut stream, &mut request);
            let body = "<html>not here</html>";
            let reply = format!(
                "HTTP/1.1 404 Not Found\r\nContent-Type: text/html\r\nContent-Length: {}\r\nConnection: close\r\n\r\n{body}",
                body.len()
            );
            let _ = std::io::Write::write_all(&mut stream, reply.as_bytes());
        }
    });
    let project = material_project();
    let mut command = Command::new(env!("CARGO_BIN_EXE_cirrus"));
    command
        .args(["build", "--remote-cache", "s3://bucket/prefix", "--remote-cache-mode", "read-only"])
        .env("AWS_ENDPOINT_URL", format!("http://{address}"))
        .env("AWS_ACCESS_KEY_ID", "x")
        .env("AWS_SECRET_ACCESS_KEY", "y")
        .env("AWS_REGION", "us-east-1")
        .current_dir(project.root());
    let output = run_command_with_deadline(&mut command, Duration::from_secs(60));
    let said = text(&output);
    assert!(output.status.success(), "{said}");
    assert!(said.contains("answers, but listing it failed") && said.contains("every lookup"), "{said}");
}
