//! Incrementality, from salsa's event log: after each edit, exactly the stages that read the
//! edited input run again, and a restart over the persistent cache runs none.

use cirrus::summary::StageStatus;
use expect_test::expect;

use crate::support::{build, pattern_png, TempProject};

/// `asset: stage(instance)` of every stage the build summary says ran.
fn ran_stages(summary: &cirrus::summary::BuildSummary) -> Vec<String> {
    summary
        .assets
        .iter()
        .flat_map(|asset| {
            let ran = asset.stages.iter().filter(|stage| stage.status == StageStatus::Ran);
            ran.map(|stage| format!("{}: {}({})", asset.name, stage.stage, stage.instance))
        })
        .collect()
}

/// Two assets; `ao_a.png` feeds `first/one` and `second/three`, `ao_b.png` feeds `first/two`.
fn two_asset_project(albedo_format: &str) -> TempProject {
    let project = TempProject::new(&format!(
        r#"Pipeline(source: "assets", output: "baked", defaults: (encode: (albedo: {albedo_format})), assets: [
            Material(name: "first", material: "first.mymaterial"),
            Material(name: "second", material: "second.mymaterial"),
        ])"#
    ));
    for (index, name) in ["albedo", "normal", "ao_a", "ao_b", "normal_b"].iter().enumerate() {
        project.write(&format!("assets/{name}.png"), pattern_png(32, 32, index as u32));
    }
    project.write(
        "assets/first.mymaterial",
        r#"Material $one {
            Texture (attrib = "diffuse") {string {"albedo.png"}}
            Texture (attrib = "normal") {string {"normal.png"}}
            Texture (attrib = "ao") {string {"ao_a.png"}}
        }
        Material $two { Texture (attrib = "ao") {string {"ao_b.png"}} }"#,
    );
    // A colour and a roughness constant of its own, so that its surfaces are not served from
    // the cache entries of `one` or `two` (surfaces with equal texels share an entry).
    project.write(
        "assets/second.mymaterial",
        r#"Material $three {
            Texture (attrib = "ao") {string {"ao_a.png"}}
            Color (attrib = "diffuse") {float[3] {{0.2, 0.4, 0.6}}}
            Param (attrib = "roughness") {float {0.5}}
        }"#,
    );
    project
}

#[test]
fn editing_an_ao_map_reencodes_only_the_mra_surfaces_that_use_it() {
    let project = two_asset_project("Bc7");
    let mut cirrus = project.open();
    build(&mut cirrus);
    cirrus.take_executed_stages();
    project.write("assets/ao_a.png", pattern_png(32, 32, 99));
    let summary = build(&mut cirrus);
    assert!(summary.all_ok());
    expect![[r#"
        [
            "decode(assets/ao_a.png)",
            "encode(first/one/mra)",
            "encode(second/three/mra)",
            "mips(first/one/mra)",
            "mips(second/three/mra)",
            "pack(first/one/mra)",
            "pack(second/three/mra)",
            "write(first/one/mra)",
            "write(second/three/mra)",
        ]
    "#]]
    .assert_debug_eq(&cirrus.take_executed_stages());
    let ran = ran_stages(&summary);
    assert_eq!(
        ran.len(),
        10,
        "the summary agrees with the event log (the shared decode is listed under both assets): {ran:?}"
    );
}

#[test]
fn identical_bytes_and_a_no_op_rebuild_run_nothing() {
    let project = two_asset_project("Bc7");
    let mut cirrus = project.open();
    let first = build(&mut cirrus);
    cirrus.take_executed_stages();
    project.write("assets/ao_a.png", pattern_png(32, 32, 2)); // the same bytes again
    let second = build(&mut cirrus);
    assert_eq!(cirrus.take_executed_stages(), Vec::<String>::new());
    assert_eq!(second.revision, first.revision, "nothing changed on disk");
}

#[test]
fn changing_a_texture_path_in_a_material_file_rebuilds_only_that_surface() {
    let project = two_asset_project("Bc7");
    let mut cirrus = project.open();
    build(&mut cirrus);
    cirrus.take_executed_stages();
    let text = String::from_utf8(project.read("assets/first.mymaterial")).unwrap();
    project.write("assets/first.mymaterial", text.replace("\"normal.png\"", "\"normal_b.png\""));
    build(&mut cirrus);
    expect![[r#"
        [
            "decode(assets/normal_b.png)",
            "encode(first/one/normal)",
            "mips(first/one/normal)",
            "pack(first/one/normal)",
            "parse(assets/first.mymaterial)",
            "write(first/one/normal)",
        ]
    "#]]
    .assert_debug_eq(&cirrus.take_executed_stages());
}

#[test]
fn changing_a_setting_reruns_only_the_stages_that_read_it() {
    let project = two_asset_project("Bc7");
    let mut cirrus = project.open();
    build(&mut cirrus);
    cirrus.take_executed_stages();
    let pipeline = String::from_utf8(project.read("pipeline.ron")).unwrap();
    std::fs::write(project.path("pipeline.ron"), pipeline.replace("albedo: Bc7", "albedo: Bc3")).unwrap();
    cirrus.reconfigure(cirrus::pipeline::load_pipeline(&project.path("pipeline.ron")).unwrap());
    build(&mut cirrus);
    expect![[r#"
        [
            "encode(first/one/albedo)",
            "encode(first/two/albedo)",
            "encode(second/three/albedo)",
            "write(first/one/albedo)",
            "write(first/two/albedo)",
            "write(second/three/albedo)",
        ]
    "#]]
    .assert_debug_eq(&cirrus.take_executed_stages());
    let albedo = project.read("baked/first/one/albedo.ktx2");
    assert_eq!(crate::support::read_ktx2(&albedo).vk_format, 138, "BC3 sRGB now");
}

#[test]
fn a_restart_with_unchanged_sources_runs_no_stage() {
    let project = two_asset_project("Bc7");
    build(&mut project.open());
    let mut restarted = project.open();
    let summary = build(&mut restarted);
    for asset in &summary.assets {
        for stage in &asset.stages {
            assert_eq!(stage.status, StageStatus::Cached, "{} {} {}", asset.name, stage.stage, stage.instance);
        }
    }
    // No stage body runs: the parse and every surface come from the persistent cache.
    assert_eq!(restarted.take_executed_stages(), Vec::<String>::new());
    // A changed file after the restart re-runs only its dependants.
    project.write("assets/ao_b.png", pattern_png(32, 32, 77));
    let mut again = project.open();
    let summary = build(&mut again);
    let ran = ran_stages(&summary);
    expect![[r#"
        [
            "first: decode(assets/ao_b.png)",
            "first: pack(two/mra)",
            "first: mips(two/mra)",
            "first: encode(two/mra)",
            "first: write(two/mra)",
        ]
    "#]]
    .assert_debug_eq(&ran);
}

#[test]
fn a_build_that_keeps_only_its_outputs_writes_the_same_files_and_the_next_process_reuses_its_encodings() {
    use cirrus::db::Retention;
    use cirrus::project::{Project, ProjectOptions};
    let open = |project: &TempProject, retention| {
        let config = cirrus::pipeline::load_pipeline(&project.path("pipeline.ron")).expect("valid pipeline");
        Project::open(config, ProjectOptions { retention, ..Default::default() })
    };
    let surfaces = ["one/albedo.ktx2", "one/normal.ktx2", "one/mra.ktx2", "two/mra.ktx2", "one/albedo.png"];
    let files = |project: &TempProject| surfaces.map(|file| project.read(&format!("baked/first/{file}")));
    let (kept, outputs_only) = (two_asset_project("Bc7"), two_asset_project("Bc7"));
    let mut keeping = open(&kept, Retention::KeepForNextBuild);
    build(&mut keeping);
    let mut one_shot = open(&outputs_only, Retention::OutputsOnly);
    build(&mut one_shot);
    assert_eq!(files(&kept), files(&outputs_only), "the same files either way");
    // What the daemon keeps for its next build (the last encoding of each surface), `cirrus
    // build` drops with its files: a many-texture build grows by its outputs alone.
    let encodings = |project: &Project| {
        project.database().kept_memos().into_iter().filter(|name| name.starts_with("encoding-memo")).count()
    };
    assert!(encodings(&keeping) >= 4, "{:?}", keeping.database().kept_memos());
    assert_eq!(encodings(&one_shot), 0, "{:?}", one_shot.database().kept_memos());

    // The next process re-encodes an edited albedo from the encodings on disk: the same files
    // as a build from nothing.
    let mut pixels = crate::support::decode_png(&pattern_png(32, 32, 0)).pixels.to_vec();
    pixels[..16].copy_from_slice(&[255, 0, 0, 255, 0, 255, 0, 255, 0, 0, 255, 255, 9, 9, 9, 255]);
    let edited = crate::support::png_bytes(32, 32, &pixels);
    outputs_only.write("assets/albedo.png", &edited);
    let summary = build(&mut open(&outputs_only, Retention::OutputsOnly));
    assert!(ran_stages(&summary).contains(&"first: encode(one/albedo)".to_string()), "{:?}", ran_stages(&summary));
    let fresh = two_asset_project("Bc7");
    fresh.write("assets/albedo.png", &edited);
    build(&mut open(&fresh, Retention::OutputsOnly));
    assert_eq!(files(&fresh), files(&outputs_only));
    assert_ne!(files(&fresh)[0], files(&kept)[0], "the edit shows");
}
