//! What a build writes when its input is hostile or broken (hardening, fourth round): a map
//! linked to a file that is not an image, a failed asset's last good outputs, names too long
//! for the file system.

use crate::support::{build, files_under, pattern_png, TempProject};

/// Path → bytes of every file under `folder` of the project (the cache and the record left out).
fn snapshot(project: &TempProject, folder: &str) -> std::collections::BTreeMap<String, Vec<u8>> {
    let root = project.path(folder);
    if !root.exists() {
        return Default::default();
    }
    files_under(&root)
        .into_iter()
        .filter(|path| !path.components().any(|part| part.as_os_str() == ".cirrus"))
        .filter(|path| !path.ends_with("manifest.json"))
        .map(|path| (path.strip_prefix(project.root()).unwrap().display().to_string(), std::fs::read(&path).unwrap()))
        .collect()
}

/// An atlas of one texture with one mesh, whose material names `extra` after its `map_Kd`.
fn atlas_with_mesh(extra: &str) -> TempProject {
    let project = TempProject::new(
        r#"Pipeline(source: "src", output: "baked", assets: [
            Atlas(name: "props", textures: ["props/*.png"], meshes: ["props/*.obj"], pack: (max_size: 256)),
        ])"#,
    );
    project.write("src/props/plank.png", pattern_png(64, 32, 1));
    project.write("src/props/props.mtl", format!("newmtl plank\nKd 1 1 1\nmap_Kd plank.png\n{extra}"));
    project.write(
        "src/props/plank.obj",
        "mtllib props.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nusemtl plank\nf 1/1 2/2 3/3\n",
    );
    project
}

#[test]
fn a_map_linked_to_a_file_that_is_not_its_image_is_refused_at_its_mtl_line_and_never_copied() {
    // `map_Pr ../other/x.png`, where `src/other/x.png` links to a password file: it used to be
    // copied into `baked/props/maps/` and named by `atlas.mtl`, the glTF and the manifest.
    let project = atlas_with_mesh("map_Pr ../other/x.png\n");
    project.write("secrets/passwd", "root:x:0:0:root:/root:/bin/bash\n");
    std::fs::create_dir_all(project.path("src/other")).unwrap();
    std::os::unix::fs::symlink(project.path("secrets/passwd"), project.path("src/other/x.png")).unwrap();
    let summary = build(&mut project.open());
    let text = summary.to_text();
    assert!(!summary.all_ok(), "{text}");
    assert!(text.contains("props.mtl:4:1"), "the MTL statement is named: {text}");
    assert!(text.contains("`other/x.png`") && text.contains("is not an image"), "{text}");
    for (path, bytes) in snapshot(&project, "baked") {
        assert!(!String::from_utf8_lossy(&bytes).contains("root:x:0:0"), "{path} holds the linked file");
    }
    assert!(!project.path("baked/props/maps").exists());
    // `cirrus check` says so before any build.
    let check = project.run_cli(&["check"]);
    let said = String::from_utf8_lossy(&check.stdout).to_string() + &String::from_utf8_lossy(&check.stderr);
    assert!(said.contains("props.mtl:4:1") && said.contains("would not be copied"), "{said}");
    assert!(!check.status.success(), "{said}");

    // A link to a real image (a shared library of textures) is the user's, and is copied.
    std::fs::remove_file(project.path("src/other/x.png")).unwrap();
    project.write("library/roughness.png", pattern_png(16, 16, 4));
    std::os::unix::fs::symlink(project.path("library/roughness.png"), project.path("src/other/x.png")).unwrap();
    let summary = build(&mut project.open());
    assert!(summary.all_ok(), "{}", summary.to_text());
    let copies = files_under(&project.path("baked/props/maps"));
    assert_eq!(copies.len(), 1, "{copies:?}");
    assert_eq!(std::fs::read(&copies[0]).unwrap(), project.read("library/roughness.png"));

    // A PNG named `.jpg` is not the image its name says either.
    project.write("src/props/props.mtl", "newmtl plank\nKd 1 1 1\nmap_Kd plank.png\nmap_Pr rough.jpg\n");
    project.write("src/props/rough.jpg", pattern_png(16, 16, 5));
    let summary = build(&mut project.open());
    assert!(summary.to_text().contains("named as a Jpeg image but is a Png image"), "{}", summary.to_text());
}

#[test]
fn a_failed_asset_keeps_every_last_good_output_and_a_first_failing_build_writes_nothing() {
    let project = TempProject::new(
        r#"Pipeline(source: "assets", output: "baked", assets: [Material(name: "rock", material: "rock.mymaterial")])"#,
    );
    project.write("assets/albedo.png", pattern_png(32, 32, 1));
    project.write("assets/normal.png", b"not a png");
    project.write(
        "assets/rock.mymaterial",
        "Material $rock {\n  Texture (attrib = \"diffuse\") {string {\"albedo.png\"}}\n  Texture (attrib = \"normal\") {string {\"normal.png\"}}\n}\n",
    );
    let summary = build(&mut project.open());
    assert!(!summary.all_ok());
    assert_eq!(snapshot(&project, "baked/rock"), Default::default(), "a failing first build writes nothing");

    project.write("assets/normal.png", pattern_png(32, 32, 2));
    assert!(build(&mut project.open()).all_ok());
    let good = snapshot(&project, "baked/rock");
    assert!(good.keys().any(|path| path.ends_with("material.gltf")), "{:?}", good.keys());
    // The normal map breaks, and the albedo changes: nothing of the asset is rewritten, the
    // glTF (which would lose its normal texture) included.
    project.write("assets/normal.png", b"broken again");
    project.write("assets/albedo.png", pattern_png(32, 32, 3));
    let summary = build(&mut project.open());
    assert!(!summary.all_ok());
    assert_eq!(snapshot(&project, "baked/rock"), good, "every last good output is kept");
}

#[test]
fn a_copied_map_whose_name_is_too_long_fails_its_asset_before_anything_is_rewritten() {
    let long = "r".repeat(240);
    let project = atlas_with_mesh("");
    assert!(build(&mut project.open()).all_ok());
    let good = snapshot(&project, "baked/props");
    // `<stem>.<16 hex digits>.png`: 261 bytes, past the file system's 255.
    project.write(&format!("src/maps/{long}.png"), pattern_png(16, 16, 6));
    project
        .write("src/props/props.mtl", format!("newmtl plank\nKd 1 1 1\nmap_Kd plank.png\nmap_Pr ../maps/{long}.png\n"));
    let summary = build(&mut project.open());
    let text = summary.to_text();
    assert!(!summary.all_ok(), "{text}");
    assert!(text.contains("longer than 255 bytes"), "{text}");
    assert_eq!(snapshot(&project, "baked/props"), good, "atlas.mtl and the glTF still name what exists");
    let leftovers: Vec<_> = files_under(&project.path("baked"))
        .into_iter()
        .filter(|path| path.file_name().is_some_and(|name| name.to_string_lossy().starts_with(".cirrus-tmp")))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
}
