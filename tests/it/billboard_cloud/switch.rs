//! A chain's switch sizes: every level measured against the source as an engine draws it (26
//! views, 16 samples a pixel, screen sizes 16 to 256 px), the largest size at which it holds
//! within one px-shift unit, written to `report.json`, `lods.json` and `lods.gltf`'s
//! `MSFT_screencoverage`; the same figures `cirrus preview` gives; measured again only for the
//! levels an edit changed.

use cirrus::preview::{switch_sizes, Hold, SizeFigures, HOLD_LOSS, HOLD_SIZES};

use crate::billboard_cloud::chain::chain_project;
use crate::support::{build, pattern_png};

const CHAIN: &str = "[Reduced(Ratio(0.5)), Quads(12), Quads(2), Impostor(frames: 4, hemi: false, size: 64)]";

fn report_levels(project: &crate::support::TempProject) -> Vec<serde_json::Value> {
    let report: serde_json::Value = serde_json::from_slice(&project.read("baked/tree/report.json")).unwrap();
    report["levels"].as_array().unwrap().clone()
}

#[test]
fn a_chain_s_levels_are_measured_and_their_switch_sizes_written_for_engines() {
    let project = chain_project(CHAIN);
    let mut cirrus = project.open();
    let summary = build(&mut cirrus);
    assert!(summary.all_ok(), "{}", summary.to_text());
    let executed = cirrus.take_executed_stages();
    assert_eq!(executed.iter().filter(|run| *run == "switch(tree)").count(), 1, "{executed:?}");

    let levels = report_levels(&project);
    let mut switch = Vec::new();
    for (level, entry) in levels.iter().enumerate() {
        let measured: Vec<SizeFigures> = serde_json::from_value(entry["measured"].clone()).unwrap();
        let holds_to = entry["holds_to"].as_u64().map(|size| size as u32);
        // From 16 px up, each size until the first the level fails at (or the largest).
        let sizes: Vec<u32> = measured.iter().map(|figures| figures.size).collect();
        assert_eq!(sizes, HOLD_SIZES[..sizes.len()], "lod{level}: {entry}");
        let held = |figures: &SizeFigures| figures.loss_px_shift.is_none_or(|loss| loss <= HOLD_LOSS);
        let (last, before) = measured.split_last().unwrap();
        assert!(before.iter().all(held), "lod{level}: measured past a failure: {entry}");
        if held(last) {
            assert_eq!(sizes.len(), HOLD_SIZES.len(), "lod{level}: stopped while holding: {entry}");
        }
        let expected_hold = measured.iter().take_while(|figures| held(figures)).last().map(|figures| figures.size);
        assert_eq!(holds_to, expected_hold, "lod{level}: {entry}");
        for figures in &measured {
            assert!((0.0..=1.0).contains(&figures.mean_iou) && figures.mean_psnr > 10.0, "lod{level}: {entry}");
        }
        switch.push(Hold { measured, holds_to });
    }
    // Each level's switch size: where it holds, never above the level before's.
    let expected = switch_sizes(&switch);
    let written: Vec<u32> = levels.iter().map(|entry| entry["switch_size"].as_u64().unwrap() as u32).collect();
    assert_eq!(written, expected);
    assert!(written.windows(2).all(|pair| pair[0] >= pair[1]), "{written:?}");
    // The half-reduced tree holds further than two quads.
    assert!(written[0] >= 64 && written[0] > written[2], "{written:?}");

    // lods.json: what an engine needs to switch, the same as the report's.
    let lods: serde_json::Value = serde_json::from_slice(&project.read("baked/tree/lods.json")).unwrap();
    assert_eq!(lods["asset"], "tree");
    assert!(lods["radius"].as_f64().unwrap() > 0.0 && lods["center"].as_array().unwrap().len() == 3);
    let entries = lods["levels"].as_array().unwrap();
    assert_eq!(entries.len(), 4);
    for (level, (entry, report)) in entries.iter().zip(&levels).enumerate() {
        assert_eq!(entry["level"], level);
        assert_eq!(entry["switch_size"], written[level]);
        for field in ["representation", "triangles", "gpu_bytes"] {
            assert_eq!(entry[field], report[field], "lod{level} {field}");
        }
        let gltf = entry["gltf"].as_str().unwrap();
        assert_eq!(gltf, format!("lod{level}/lod.gltf"));
        assert!(project.path(&format!("baked/tree/{gltf}")).is_file());
    }
    assert_eq!(
        entries.iter().map(|entry| entry["representation"].as_str().unwrap()).collect::<Vec<_>>(),
        ["reduced", "billboard_cloud", "billboard_cloud", "impostor"]
    );
    // lods.gltf switches where the levels do.
    let chain: serde_json::Value = serde_json::from_slice(&project.read("baked/tree/lods.gltf")).unwrap();
    let coverage: Vec<f32> =
        serde_json::from_value(chain["nodes"][0]["extras"]["MSFT_screencoverage"].clone()).unwrap();
    assert_eq!(coverage, cirrus::kinds::billboard_cloud::lod_mesh::screen_coverage(&written));
    let manifest: serde_json::Value = serde_json::from_slice(&project.read("baked/manifest.json")).unwrap();
    assert!(manifest["artifacts"]["baked/tree/lods.json"].is_object(), "{manifest}");

    // The preview of a level at one of the sizes gives the figures the build measured.
    let output = project.run_cli(&["preview", "--asset", "tree", "--lod", "2", "--size", "32"]);
    assert_eq!(output.status.code(), Some(0), "{}", String::from_utf8_lossy(&output.stderr));
    let metrics: serde_json::Value =
        serde_json::from_slice(&project.read("baked/tree/preview/lod2/metrics.json")).unwrap();
    let at_32 = &levels[2]["measured"][1];
    assert_eq!(at_32["size"], 32);
    for field in ["mean_iou", "mean_psnr", "loss_px_shift"] {
        let (built, previewed) = (at_32[field].as_f64().unwrap(), metrics[field].as_f64().unwrap());
        assert!((built - previewed).abs() < 1e-9, "{field}: {built} built, {previewed} previewed");
    }

    // A clean bake of the same project measures the same.
    let again = chain_project(CHAIN);
    build(&mut again.open());
    assert_eq!(again.read("baked/tree/lods.json"), project.read("baked/tree/lods.json"));
    assert_eq!(report_levels(&again), levels);
}

#[test]
fn an_edit_measures_again_only_the_levels_it_changed_and_a_restart_nothing() {
    let project = chain_project(CHAIN);
    let mut cirrus = project.open();
    build(&mut cirrus);
    cirrus.take_executed_stages();
    let before = report_levels(&project);

    // A new budget for level 2: the switch stage runs again, and the other levels' figures
    // come from the cache (the measure of level 2 alone shows in its figures only).
    let pipeline = String::from_utf8(project.read("pipeline.ron")).unwrap();
    std::fs::write(project.path("pipeline.ron"), pipeline.replace("Quads(2)", "Quads(3)")).unwrap();
    cirrus.reconfigure(cirrus::config::load_pipeline(&project.path("pipeline.ron")).unwrap());
    let summary = build(&mut cirrus);
    assert!(summary.all_ok(), "{}", summary.to_text());
    let executed = cirrus.take_executed_stages();
    assert!(executed.contains(&"switch(tree)".to_string()), "{executed:?}");
    assert!(
        executed.iter().all(|run| run.contains("tree/lod2") || run == "switch(tree)"),
        "only level 2 and the switch ran: {executed:?}"
    );
    let after = report_levels(&project);
    for level in [0, 1, 3] {
        assert_eq!(after[level]["measured"], before[level]["measured"], "lod{level}");
    }

    // A bark edit changes every level: each is measured again; a restart measures nothing.
    project.write("assets/bark.png", pattern_png(32, 32, 7));
    build(&mut cirrus);
    assert!(cirrus.take_executed_stages().contains(&"switch(tree)".to_string()));
    let mut restarted = project.open();
    let summary = build(&mut restarted);
    assert!(summary.all_ok(), "{}", summary.to_text());
    assert_eq!(restarted.take_executed_stages(), Vec::<String>::new());
}

#[test]
fn switch_sizes_follow_the_holds_and_never_rise_along_the_chain() {
    let hold = |holds_to: Option<u32>| Hold { measured: Vec::new(), holds_to };
    // A level that holds further than the one before switches where that one does; one that
    // never holds (not even at 16 px) is never shown, nor is anything after it.
    let holds = [hold(Some(256)), hold(Some(128)), hold(Some(256)), hold(None), hold(Some(32))];
    assert_eq!(switch_sizes(&holds), [256, 128, 128, 0, 0]);
    assert_eq!(switch_sizes(&[]), Vec::<u32>::new());
}
