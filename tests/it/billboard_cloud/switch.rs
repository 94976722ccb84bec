//! A chain's switch sizes: every level measured against the source as an engine draws it (26
//! views, 16 samples a pixel, screen sizes 16 px up to the level before's switch size, until its
//! first failure after 16 px), the largest size at which it holds within one px-shift unit, written to `report.json`, `lods.json` and `lods.gltf`'s
//! `MSFT_screencoverage`; the same figures `cirrus preview` gives; measured again only for the
//! levels an edit changed.

use cirrus::kinds::billboard_cloud::lod_mesh::{shown_levels, ShownLevels};
use cirrus::preview::{never_shown_levels, switch_sizes, Hold, NeverShown, SizeFigures, HOLD_LOSS, HOLD_SIZES};

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
    let written: Vec<u32> = levels.iter().map(|entry| entry["switch_size"].as_u64().unwrap() as u32).collect();
    let mut switch = Vec::new();
    for (level, entry) in levels.iter().enumerate() {
        let measured: Vec<SizeFigures> = serde_json::from_value(entry["measured"].clone()).unwrap();
        let holds_to = entry["holds_to"].as_u64().map(|size| size as u32);
        // From 16 px up to the level before's switch size (it is never shown larger), until the
        // first failure after 16 px.
        let cap = if level == 0 { u32::MAX } else { written[level - 1] };
        let held = |figures: &SizeFigures| figures.loss_px_shift.is_none_or(|loss| loss <= HOLD_LOSS);
        let sizes: Vec<u32> = measured.iter().map(|figures| figures.size).collect();
        let allowed: Vec<u32> = HOLD_SIZES.into_iter().filter(|&size| size <= cap).collect();
        assert_eq!(sizes, allowed[..sizes.len()], "lod{level}: {entry}");
        let first_failure = measured.iter().skip(1).position(|figures| !held(figures)).map(|at| at + 1);
        match first_failure {
            Some(at) => assert_eq!(sizes.len(), at + 1, "lod{level}: measured past a failure: {entry}"),
            None => assert_eq!(sizes.len(), allowed.len(), "lod{level}: stopped while holding: {entry}"),
        }
        let expected_hold = measured.iter().rfind(|figures| held(figures)).map(|figures| figures.size);
        assert_eq!(holds_to, expected_hold, "lod{level}: {entry}");
        for figures in &measured {
            assert!((0.0..=1.0).contains(&figures.mean_iou) && figures.mean_psnr > 10.0, "lod{level}: {entry}");
        }
        switch.push(Hold { measured, holds_to, outranked_at: None });
    }
    // Each level's switch size: where it holds, never above the level before's.
    let expected = switch_sizes(&switch);
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
    cirrus.reconfigure(cirrus::pipeline::load_pipeline(&project.path("pipeline.ron")).unwrap());
    let summary = build(&mut cirrus);
    assert!(summary.all_ok(), "{}", summary.to_text());
    let executed = cirrus.take_executed_stages();
    assert!(executed.contains(&"switch(tree)".to_string()), "{executed:?}");
    assert!(
        executed.iter().all(|run| run.contains("tree/lod2") || run == "switch(tree)"),
        "only level 2 and the switch ran: {executed:?}"
    );
    let after = report_levels(&project);
    for level in [0, 1] {
        assert_eq!(after[level]["measured"], before[level]["measured"], "lod{level}");
    }
    // Level 3 is measured up to level 2's switch size: again only if that changed.
    if after[2]["switch_size"] == before[2]["switch_size"] {
        assert_eq!(after[3]["measured"], before[3]["measured"]);
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
    let hold = |holds_to: Option<u32>| Hold { measured: Vec::new(), holds_to, outranked_at: None };
    // A level that holds further than the one before switches where that one does; one that
    // never holds (not even at 16 px) is never shown, nor is anything after it.
    let holds = [hold(Some(256)), hold(Some(128)), hold(Some(256)), hold(None), hold(Some(32))];
    assert_eq!(switch_sizes(&holds), [256, 128, 128, 0, 0]);
    assert_eq!(switch_sizes(&[]), Vec::<u32>::new());
    // Level 1 is never shown (level 2 takes over wherever it would be), nor are levels 3 and 4.
    assert_eq!(
        never_shown_levels(&switch_sizes(&holds)),
        [(1, NeverShown::NextHoldsAsFar(128)), (3, NeverShown::HoldsAtNoSize), (4, NeverShown::HoldsAtNoSize)]
    );
    assert_eq!(never_shown_levels(&[256, 128, 64, 32]), []);
    // 16 samples a pixel where pixels are few, 4 where a render would pass 512 texels across.
    let samples: Vec<u32> = HOLD_SIZES.iter().map(|&size| cirrus::preview::hold_samples_per_axis(size)).collect();
    assert_eq!(samples, [4, 4, 4, 2, 2]);
    assert!(HOLD_SIZES.iter().zip(&samples).all(|(size, samples)| size * samples <= 512 && size * samples >= 64));
}

/// The part of a headless viewer line that says what it shows, and the sphere's size on screen.
fn shown_and_pixels(line: &str) -> (String, f32) {
    let shown = line.split_once(": ").unwrap().1.split_once(" of ").unwrap().0.to_string();
    let pixels = line.split_once("the sphere ").unwrap().1.split_once(" px").unwrap().0.parse().unwrap();
    (shown, pixels)
}

/// What the viewer says it shows for `shown` (a fade's share as a whole percentage, so within a
/// point of what the line's rounded size gives).
fn described(shown: ShownLevels) -> (String, Option<f32>) {
    match shown.fading_into {
        None => (format!("lod{}", shown.level), None),
        Some((next, share)) => (format!("lod{} fading into lod{next}", shown.level), Some(100.0 * share)),
    }
}

/// What a viewer line says it shows (as `described`).
fn line_shows(shown: &str) -> (String, Option<f32>) {
    match shown.split_once(" (") {
        None => (shown.to_string(), None),
        Some((levels, share)) => (levels.to_string(), share.trim_end_matches("%)").parse().ok()),
    }
}

#[test]
fn the_viewer_switches_levels_by_the_switch_sizes_with_a_dithered_cross_fade() {
    let project = chain_project(CHAIN);
    build(&mut project.open());
    let lods: serde_json::Value = serde_json::from_slice(&project.read("baked/tree/lods.json")).unwrap();
    let switch: Vec<u32> =
        lods["levels"].as_array().unwrap().iter().map(|level| level["switch_size"].as_u64().unwrap() as u32).collect();

    // Zooming out from 400 px across, a step of 1.25 at a time: each view shows what the switch
    // sizes choose, and the chain goes from level 0 to the last level that holds somewhere.
    let size = 96u32;
    let zoom = format!("{}", 400.0 / size as f32);
    let steps = "-".repeat(18);
    let press = format!("--press={steps}");
    let arguments = ["--size", "96", "--zoom", zoom.as_str(), press.as_str()];
    let lines = crate::support::headless_viewer_lines(&project, "baked/tree", &arguments);
    assert_eq!(lines.len(), 19, "{lines:#?}");
    let mut levels_seen = Vec::new();
    for line in &lines {
        let (shown, pixels) = shown_and_pixels(line);
        let ((levels, share), (expected_levels, expected_share)) =
            (line_shows(&shown), described(shown_levels(&switch, pixels)));
        assert_eq!(levels, expected_levels, "{line}");
        assert_eq!(share.is_some(), expected_share.is_some(), "{line}");
        assert!((share.unwrap_or(0.0) - expected_share.unwrap_or(0.0)).abs() <= 1.5, "{line}");
        levels_seen.push(shown_levels(&switch, pixels).level);
    }
    assert!(levels_seen.windows(2).all(|pair| pair[0] <= pair[1]), "{levels_seen:?}");
    assert_eq!(levels_seen[0], 0);
    let last_holding = switch.iter().rposition(|&size| size > 0).unwrap() as u32;
    assert_eq!(*levels_seen.last().unwrap(), last_holding, "{lines:#?}");

    // Inside a band, each pixel comes from one of the two levels, as the dither says.
    let level = (1..switch.len()).find(|&level| switch[level] > 0 && switch[level] < switch[level - 1]).unwrap();
    let zoom = switch[level] as f32 / 1.1 / size as f32;
    let shown = shown_levels(&switch, size as f32 * zoom);
    let Some((next, share)) = shown.fading_into else { panic!("{shown:?} at {}", size as f32 * zoom) };
    let zoom = format!("{zoom}");
    let screenshot = |extra: &[&str]| {
        let mut arguments = vec!["--size", "96", "--zoom", zoom.as_str()];
        arguments.extend_from_slice(extra);
        crate::support::headless_viewer_lines(&project, "baked/tree", &arguments);
        image::load_from_memory(&project.read("shot.png")).unwrap().to_rgba8().into_raw()
    };
    let faded = screenshot(&[]);
    let (from, into) = (screenshot(&["--lod", &shown.level.to_string()]), screenshot(&["--lod", &next.to_string()]));
    assert_eq!(faded, cirrus::preview::dithered_cross_fade(&from, &into, size, share));
    let differing = (0..faded.len() / 4).filter(|&pixel| from[4 * pixel..][..4] != into[4 * pixel..][..4]);
    let taken = differing.clone().filter(|&pixel| faded[4 * pixel..][..4] == into[4 * pixel..][..4]).count();
    let share_taken = taken as f32 / differing.count().max(1) as f32;
    assert!((share_taken - share).abs() < 0.1, "{share_taken} of the differing pixels from lod{next}, {share} asked");

    // A digit pins a level at any size, A lets the sizes choose again.
    let lines = crate::support::headless_viewer_lines(&project, "baked/tree", &["--size", "96", "--press", "3a"]);
    assert!(lines[1].starts_with("showing lod3: lod3 of 4, 2 triangles") && !lines[1].contains("switching"));
    assert!(lines[2].starts_with("switching by size: lod0 of 4, ") && lines[2].contains("96.0 px across"));
}

#[test]
fn a_chain_shows_each_level_below_its_switch_size_fading_in_over_the_band() {
    let switch = [256, 128, 128, 32, 0];
    let shown = |pixels: f32| shown_levels(&switch, pixels);
    assert_eq!(shown(1000.0), ShownLevels { level: 0, fading_into: None });
    assert_eq!(shown(128.0), ShownLevels { level: 1, fading_into: None }, "at the switch size: none of level 2 yet");
    // 128 → 102.4: level 2 takes over; level 1, with the same switch size, is never alone.
    let fading = |pixels: f32, (level, next, share): (u32, u32, f32)| {
        let shown = shown(pixels);
        let (shown_next, shown_share) = shown.fading_into.unwrap_or_else(|| panic!("{shown:?} at {pixels}"));
        assert_eq!((shown.level, shown_next), (level, next), "at {pixels}");
        assert!((shown_share - share).abs() < 1e-5, "{shown:?} at {pixels}");
    };
    fading(115.2, (1, 2, 0.5));
    fading(125.44, (1, 2, 0.1));
    assert_eq!(shown(102.4), ShownLevels { level: 2, fading_into: None });
    fading(28.8, (2, 3, 0.5));
    // A level that never holds is never shown.
    assert_eq!(shown(1.0), ShownLevels { level: 3, fading_into: None });
    assert_eq!(shown_levels(&[], 10.0), ShownLevels { level: 0, fading_into: None });
}

#[test]
fn a_chain_in_dds_or_pvr_is_measured_and_previewed_as_in_ktx2() {
    // Every level's textures read back from whichever container the build writes: the same
    // blocks, so the same figures.
    let chain = "[Quads(4), Impostor(frames: 4, hemi: false, size: 64)]";
    let ktx2 = chain_project(chain);
    build(&mut ktx2.open());
    let measured = |project: &crate::support::TempProject| -> Vec<serde_json::Value> {
        report_levels(project).iter().map(|level| level["measured"].clone()).collect()
    };
    for container in ["Dds", "Pvr"] {
        let project = chain_project(chain);
        let pipeline = String::from_utf8(project.read("pipeline.ron")).unwrap();
        let pipeline =
            pipeline.replace("atlas: (max_size", &format!("encode: (container: {container}), atlas: (max_size"));
        std::fs::write(project.path("pipeline.ron"), pipeline).unwrap();
        let summary = build(&mut project.open());
        assert!(summary.all_ok(), "{container}: {}", summary.to_text());
        let extension = container.to_lowercase();
        assert!(project.path(&format!("baked/tree/lod0/albedo.{extension}")).is_file());
        assert_eq!(measured(&project), measured(&ktx2), "{container}");
        let output = project.run_cli(&["preview", "--asset", "tree", "--size", "32", "--views", "2"]);
        assert_eq!(output.status.code(), Some(0), "{container}: {}", String::from_utf8_lossy(&output.stderr));
    }
}
