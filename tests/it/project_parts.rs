//! The driver's parts read alone: the daemon's clean set and readers index, the asset list
//! with its rules' conflicts, the publish state's manifest and the skip record.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use cirrus::project::{list_assets, AssetLists, CleanAssets, PublishState, SkipRecord};

/// A pipeline of `assets:` in a project at `root` whose `rules:` take `props/*.obj`.
fn pipeline(root: &Path, assets: &str) -> cirrus::config::PipelineConfig {
    let text = format!(
        r#"Pipeline(source: "assets", output: "baked",
            rules: [(glob: "props/*.obj", kind: BillboardCloud)],
            assets: [{assets}])"#
    );
    let file = root.join("pipeline.ron");
    std::fs::write(&file, &text).unwrap();
    cirrus::pipeline::load_pipeline(&file).expect("a valid pipeline")
}

#[test]
fn an_edit_makes_exactly_the_assets_that_read_the_file_unclean() {
    let mut clean = CleanAssets::new(true);
    clean.mark("tree", || vec![PathBuf::from("assets/tree.obj"), PathBuf::from("assets/bark.png")]);
    clean.mark("log", || vec![PathBuf::from("assets/log.obj"), PathBuf::from("assets/bark.png")]);
    clean.unclean_readers_of(Path::new("assets/tree.obj"));
    assert!(!clean.contains("tree") && clean.contains("log"));
    clean.unclean_readers_of(Path::new("assets/unread.png"));
    assert!(clean.contains("log"));
    clean.unclean_readers_of(Path::new("assets/bark.png"));
    assert!(!clean.contains("log"));
    // A build that starts afresh every time indexes no readers (it never asks for them).
    let mut every_build = CleanAssets::new(false);
    every_build.mark("tree", || panic!("no readers are asked for"));
    every_build.unclean_readers_of(Path::new("assets/tree.obj"));
    assert!(every_build.contains("tree"), "cleared by the next build, not by an edit");
}

#[test]
fn a_new_asset_list_keeps_clean_only_the_assets_configured_as_before() {
    let root = tempfile::tempdir().unwrap();
    let before = pipeline(
        root.path(),
        r#"Material(name: "bark", material: "bark.mymaterial"), Material(name: "steel", material: "steel.mymaterial")"#,
    );
    let after = pipeline(
        root.path(),
        r#"Material(name: "bark", material: "bark.mymaterial"),
           Material(name: "steel", material: "steel.mymaterial", encode: (container: Dds))"#,
    );
    let (before, after) = (Arc::new(list_assets(&before)), Arc::new(list_assets(&after)));
    let mut clean = CleanAssets::new(true);
    clean.keep_for(&before);
    clean.mark("bark", Vec::new);
    clean.mark("steel", Vec::new);
    clean.keep_for(&before);
    assert!(clean.contains("bark") && clean.contains("steel"), "the same list keeps them all");
    clean.keep_for(&after);
    assert!(clean.contains("bark") && !clean.contains("steel"), "steel's settings changed");
}

#[test]
fn the_asset_list_takes_the_rules_files_warns_of_collisions_and_is_kept_until_an_edit_may_change_it() {
    let root = tempfile::tempdir().unwrap();
    std::fs::create_dir_all(root.path().join("assets/props")).unwrap();
    for file in ["props/crate.obj", "props/bush.obj"] {
        std::fs::write(root.path().join("assets").join(file), "v 0 0 0\n").unwrap();
    }
    let config = pipeline(root.path(), r#"Material(name: "props/crate", material: "crate.mymaterial")"#);
    let (assets, conflicts) = list_assets(&config);
    let names: Vec<&str> = assets.iter().map(|asset| asset.name.as_str()).collect();
    assert_eq!(names, ["props/crate", "props/bush"]);
    assert_eq!(conflicts.len(), 1, "{conflicts:?}");
    let warning = conflicts[0].to_string();
    assert!(
        warning.contains("assets/props/crate.obj") && warning.contains("collides with the asset `props/crate`"),
        "{warning}"
    );
    let mut lists = AssetLists::default();
    let kept = lists.get(&config, true);
    assert!(Arc::ptr_eq(&kept, &lists.get(&config, true)), "the daemon keeps its list");
    assert!(!Arc::ptr_eq(&kept, &lists.get(&config, false)), "a build lists afresh");
    let kept = lists.get(&config, true);
    lists.forget_for(&config, Path::new("assets/crate.mymaterial"), true);
    assert!(Arc::ptr_eq(&kept, &lists.get(&config, true)), "a known file no rule matches keeps it");
    lists.forget_for(&config, Path::new("assets/props/tree.obj"), false);
    assert!(!Arc::ptr_eq(&kept, &lists.get(&config, true)), "a file a rule matches may add an asset");
    assert!(!lists.departures_checked(&kept));
    lists.note_departures_checked(&kept);
    assert!(lists.departures_checked(&kept));
}

#[test]
fn the_publish_state_reads_the_manifest_again_only_when_its_file_changed() {
    let output = tempfile::tempdir().unwrap();
    let mut state = PublishState::load(output.path());
    assert_eq!((state.revision(), state.had_file()), (0, false));
    let mut manifest = state.take(output.path());
    manifest.revision = 7;
    state.keep(output.path(), manifest);
    state.mark_unsaved();
    assert_eq!(state.take(output.path()).revision, 7, "an unsaved manifest is the one kept");
    let manifest = cirrus::artifacts::Manifest { revision: 7, ..Default::default() };
    state.keep(output.path(), manifest);
    state.save(output.path(), Path::new("baked/manifest.json"));
    let written = std::fs::read_to_string(output.path().join("manifest.json")).expect("saved");
    assert!(written.contains("\"revision\": 7"), "{written}");
    // Written by another process meanwhile: read again.
    std::fs::write(output.path().join("manifest.json"), written.replace("\"revision\": 7", "\"revision\": 9")).unwrap();
    assert_eq!(state.take(output.path()).revision, 9);
}

#[test]
fn the_skip_record_hashes_each_configuration_and_keeps_only_the_assets_of_the_pipeline() {
    let root = tempfile::tempdir().unwrap();
    let config = pipeline(
        root.path(),
        r#"Material(name: "bark", material: "bark.mymaterial"), Material(name: "steel", material: "bark.mymaterial")"#,
    );
    let mut skip = SkipRecord::load(&config);
    assert!(skip.record().assets.is_empty());
    let (bark, steel) = (&config.assets[0], &config.assets[1]);
    let hash = skip.config_hash(bark, &config);
    assert_eq!(hash, skip.config_hash(bark, &config));
    assert_ne!(hash, skip.config_hash(steel, &config), "the name enters the hash");
    let record = |file: &str| {
        let files = vec![PathBuf::from(file)];
        cirrus::record::AssetRecord::new(hash, files, Default::default(), &[], Vec::new())
    };
    skip.insert_asset("bark", record("assets/bark.mymaterial"));
    skip.insert_asset("gone", record("assets/gone.mymaterial"));
    assert!(skip.trusts("bark"));
    skip.prune(&config.assets);
    assert!(skip.asset("bark").is_some() && skip.asset("gone").is_none());
    assert_eq!(skip.files_of("bark"), [PathBuf::from("assets/bark.mymaterial")]);
    skip.save(&config);
    let reloaded = SkipRecord::load(&config);
    assert_eq!(reloaded.asset("bark").map(|record| record.fingerprint), Some(hash), "saved and read back");
    assert!(!reloaded.trusts("bark"), "a new process trusts no artifact before it checks it");
    skip.remove_asset("bark");
    assert!(skip.asset("bark").is_none() && !skip.trusts("bark"));
}
