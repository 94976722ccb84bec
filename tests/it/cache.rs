//! The persistent cache's keys: an explicit encoding, pinned here, and the same keys for the
//! same project baked from two folders (what a shared cache needs).

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use cirrus::cache::CacheKeyBuilder;
use cirrus::config::{BlockFormat, Container, EncodeQuality};
use cirrus::kinds::billboard_cloud::settings::{default_billboard_atlas, BillboardSettings};
use expect_test::expect;

use crate::support::build;

/// The entry files under `<output>/.cirrus/cache`, relative to it: `stage/xx/rest-of-the-key`.
fn cache_entries(output: &Path) -> BTreeSet<PathBuf> {
    let root = output.join(".cirrus/cache");
    crate::support::files_under(&root).iter().map(|path| path.strip_prefix(&root).unwrap().to_path_buf()).collect()
}

#[test]
fn keys_have_a_pinned_encoding() {
    let (billboard, atlas) = (BillboardSettings::default(), default_billboard_atlas());
    let key = CacheKeyBuilder::new("example", 3)
        .part(&billboard.epsilon)
        .part(&billboard.max_planes)
        .part(&atlas.power_of_two)
        .part(&cirrus::texture::SurfaceKind::Normal)
        .part(&(BlockFormat::Bc5, EncodeQuality::Slow))
        .part(&(Container::Dds, Some(19)))
        .part(Path::new("assets/textures/bark.png"))
        .part(&blake3::hash(b"texture bytes"))
        .finish();
    // A change here changes every key: every cache (local and shared) misses once. Make it on
    // purpose, with the module docs' table.
    expect!["a4916876e99f00ea9b5f2eacbe793e7d1377e774b26e076b6c993ad85f319f0e"].assert_eq(&key.0.to_hex());
}

#[test]
fn the_same_project_in_two_folders_has_the_same_keys() {
    let first = crate::material::bake::material_project("");
    let second = crate::material::bake::material_project("");
    assert_ne!(first.root(), second.root());
    assert!(build(&mut first.open()).all_ok());
    assert!(build(&mut second.open()).all_ok());
    let entries = cache_entries(&first.path("baked"));
    assert!(
        entries.iter().any(|entry| entry.starts_with("surface"))
            && entries.iter().any(|entry| entry.starts_with("parse")),
        "{entries:?}"
    );
    assert_eq!(entries, cache_entries(&second.path("baked")));
}

#[test]
fn two_builds_on_one_cache_folder_at_once_leave_it_whole() {
    // Two checkouts whose local caches are one folder (the second's is a link to the first's).
    let first = crate::material::bake::material_project("");
    let second = crate::material::bake::material_project("");
    std::fs::create_dir_all(first.path("baked/.cirrus/cache")).unwrap();
    std::fs::create_dir_all(second.path("baked/.cirrus")).unwrap();
    std::os::unix::fs::symlink(first.path("baked/.cirrus/cache"), second.path("baked/.cirrus/cache")).unwrap();
    let spawn = |project: &crate::support::TempProject| {
        std::process::Command::new(env!("CARGO_BIN_EXE_cirrus"))
            .args(["build", "--summary", "json"])
            .current_dir(project.root())
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap()
    };
    let (one, two) = (spawn(&first), spawn(&second));
    let (one, two) = (one.wait_with_output().unwrap(), two.wait_with_output().unwrap());
    assert!(
        one.status.success() && two.status.success(),
        "{}\n{}",
        String::from_utf8_lossy(&one.stderr),
        String::from_utf8_lossy(&two.stderr)
    );
    // No temporary file is left, and every entry is whole: a third checkout on the same folder
    // runs nothing and writes what the first two wrote.
    let entries = cache_entries(&first.path("baked"));
    assert!(entries.iter().all(|entry| !entry.to_string_lossy().contains(".cirrus-tmp")), "{entries:?}");
    let third = crate::material::bake::material_project("");
    std::fs::create_dir_all(third.path("baked/.cirrus")).unwrap();
    std::os::unix::fs::symlink(first.path("baked/.cirrus/cache"), third.path("baked/.cirrus/cache")).unwrap();
    let summary = build(&mut third.open());
    let ran: Vec<_> = summary
        .assets
        .iter()
        .flat_map(|asset| &asset.stages)
        .filter(|stage| stage.status == cirrus::summary::StageStatus::Ran)
        .collect();
    assert!(ran.is_empty(), "{ran:?}");
    for path in ["baked/bark/oak_bark/albedo.ktx2", "baked/bark/oak_bark/normal.ktx2", "baked/mixed/leaf/albedo.ktx2"] {
        assert_eq!(third.read(path), first.read(path), "{path}");
        assert_eq!(second.read(path), first.read(path), "{path}");
    }
}

#[test]
fn cache_stats_explain_and_gc_tell_and_bound_the_local_folder() {
    let project = crate::material::bake::material_project("");
    let stats = |project: &crate::support::TempProject| {
        String::from_utf8_lossy(&project.run_cli(&["cache", "stats"]).stdout).into_owned()
    };
    assert!(
        stats(&project).contains("0 entries, 0 B") && stats(&project).contains("last build: none recorded"),
        "{}",
        stats(&project)
    );
    assert!(build(&mut project.open()).all_ok());
    let cold = stats(&project);
    assert!(
        cold.contains("last build (revision 1):")
            && cold.contains(" misses")
            && cold.contains("remote: none")
            && cold.contains(" ran"),
        "{cold}"
    );
    let explain =
        String::from_utf8_lossy(&project.run_cli(&["cache", "explain", "--asset", "bark"]).stdout).into_owned();
    assert!(explain.contains("encode(oak_bark/albedo): ran: no cache held its result"), "{explain}");
    assert!(build(&mut project.open()).all_ok());
    let explain =
        String::from_utf8_lossy(&project.run_cli(&["cache", "explain", "--asset", "bark"]).stdout).into_owned();
    // Nothing it reads changed: the build record let the rebuild pass it over.
    assert!(explain.contains("bark in the build of revision 1: passed over") && !explain.contains("ran:"), "{explain}");
    let unknown = project.run_cli(&["cache", "explain", "--asset", "nope"]);
    assert_eq!(unknown.status.code(), Some(2));

    // gc: the least recently used go first. Age every entry but the parsed materials'.
    let root = project.path("baked/.cirrus/cache");
    let entries = cirrus::cache::upkeep::entry_files(&root);
    let old = std::time::SystemTime::now() - std::time::Duration::from_secs(3600);
    for entry in entries.iter().filter(|entry| entry.stage != "parse") {
        std::fs::File::options().append(true).open(&entry.path).unwrap().set_modified(old).unwrap();
    }
    let keep: u64 = entries.iter().filter(|entry| entry.stage == "parse").map(|entry| entry.bytes).sum();
    let output = project.run_cli(&["cache", "gc", "--max-size", &keep.to_string()]);
    assert!(output.status.success());
    let said = String::from_utf8_lossy(&output.stdout);
    assert!(said.starts_with(&format!("deleted {} entries", entries.len() - 2)), "{said}");
    let left = cirrus::cache::upkeep::entry_files(&root);
    assert!(left.len() == 2 && left.iter().all(|entry| entry.stage == "parse"), "{left:?}");
    // A hit marks an entry used: a restart that reads the parsed materials keeps them newest.
    // (Without the build record, which would let it pass over every asset, it asks every stage:
    // the rest is baked and stored again.)
    std::fs::remove_file(project.path("baked/.cirrus/record.json")).unwrap();
    assert!(build(&mut project.open()).all_ok());
    let bad = project.run_cli(&["cache", "gc", "--max-size", "lots"]);
    assert_eq!(bad.status.code(), Some(2));

    // After an edit, explain names the key part that differs from what an earlier build stored.
    project.write("assets/textures/metal.png", crate::support::pattern_png(64, 64, 9));
    assert!(build(&mut project.open()).all_ok());
    let explain =
        String::from_utf8_lossy(&project.run_cli(&["cache", "explain", "--asset", "mixed"]).stdout).into_owned();
    let line = explain
        .lines()
        .find(|line| line.trim_start().starts_with("surface-recipe "))
        .unwrap_or_else(|| panic!("{explain}"));
    assert!(
        line.contains(": nearest ") && line.contains(" is hash ") && line.contains("(the entry has hash "),
        "{explain}"
    );
}

/// The bundled project with its source folder named `folder` (the pipeline's `source` and
/// every file moved there), its bush's atlas kept small so that the bake is quick.
fn bundled_project_in(folder: &str) -> crate::support::TempProject {
    let pipeline = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("pipeline.ron"))
        .unwrap()
        .replace("source: \"examples/assets\"", &format!("source: \"{folder}\""))
        .replace("atlas: (max_size: 1024)", "atlas: (max_size: 256)");
    let project = crate::support::TempProject::new(&pipeline);
    project.copy_folder(&Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/assets"), folder);
    project
}

#[test]
fn a_project_whose_source_folder_is_named_otherwise_shares_every_entry_and_bakes_the_same_bytes() {
    // Keys hold paths relative to the source folder, and cached values name files relative to
    // it: a teammate whose checkout calls the folder `assets` is served every stage by a cache
    // filled under `src`, and bakes the same bytes.
    let first = bundled_project_in("src");
    let summary = build(&mut first.open());
    assert!(summary.all_ok(), "{}", summary.to_text());
    let second = bundled_project_in("assets");
    let copy = |from: &Path, to: &Path| {
        let mut folders = vec![from.to_path_buf()];
        while let Some(folder) = folders.pop() {
            for entry in std::fs::read_dir(&folder).unwrap().flatten() {
                let path = entry.path();
                let target = to.join(path.strip_prefix(from).unwrap());
                if path.is_dir() {
                    std::fs::create_dir_all(&target).unwrap();
                    folders.push(path);
                } else {
                    std::fs::copy(&path, &target).unwrap();
                }
            }
        }
    };
    std::fs::create_dir_all(second.path("baked/.cirrus/cache")).unwrap();
    copy(&first.path("baked/.cirrus/cache"), &second.path("baked/.cirrus/cache"));
    let summary = build(&mut second.open());
    assert!(summary.all_ok(), "{}", summary.to_text());
    let ran: Vec<String> = summary
        .assets
        .iter()
        .flat_map(|asset| {
            asset
                .stages
                .iter()
                .filter(|stage| stage.status == cirrus::summary::StageStatus::Ran)
                .map(move |stage| format!("{}:{}({})", asset.name, stage.stage, stage.instance))
        })
        .collect();
    assert!(ran.is_empty(), "stages ran although another folder name baked them: {ran:?}");
    let artifacts = |project: &crate::support::TempProject| -> Vec<(String, Vec<u8>)> {
        let mut files = Vec::new();
        let mut folders = vec![project.path("baked")];
        while let Some(folder) = folders.pop() {
            for entry in std::fs::read_dir(&folder).unwrap().flatten() {
                let path = entry.path();
                let relative = path.strip_prefix(project.path("baked")).unwrap().to_string_lossy().to_string();
                if relative.starts_with(".cirrus") || relative == "manifest.json" {
                    continue;
                }
                if path.is_dir() {
                    folders.push(path);
                } else {
                    files.push((relative, std::fs::read(&path).unwrap()));
                }
            }
        }
        files.sort();
        files
    };
    let (first_files, second_files) = (artifacts(&first), artifacts(&second));
    assert_eq!(
        first_files.iter().map(|(name, _)| name).collect::<Vec<_>>(),
        second_files.iter().map(|(name, _)| name).collect::<Vec<_>>()
    );
    // Reports say how long each stage took (the second bake's came from the cache), and name the
    // source folder (the mesh); MTL files name it where a path leads out of `baked/`.
    let without_times = |bytes: &[u8], folder: &str| -> String {
        let text = String::from_utf8_lossy(bytes).replace(&format!("{folder}/"), "SOURCE/");
        match serde_json::from_str::<serde_json::Value>(&text) {
            Ok(mut report) => {
                fn strip(value: &mut serde_json::Value) {
                    match value {
                        serde_json::Value::Object(fields) => {
                            fields.remove("stage_ms");
                            fields.remove("timings");
                            fields.values_mut().for_each(strip);
                        }
                        serde_json::Value::Array(items) => items.iter_mut().for_each(strip),
                        _ => {}
                    }
                }
                strip(&mut report);
                report.to_string()
            }
            Err(_) => text,
        }
    };
    for ((name, first_bytes), (_, second_bytes)) in first_files.iter().zip(&second_files) {
        if first_bytes != second_bytes {
            assert_eq!(
                without_times(first_bytes, "src"),
                without_times(second_bytes, "assets"),
                "{name} differs beyond timings and the folder's name"
            );
        }
    }
}
