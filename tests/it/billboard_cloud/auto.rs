//! Chains that choose (`lods: [Auto(max_bytes: 262144), Auto(max_bytes: 65536)]`): each level's
//! candidates (by default a billboard cloud of 64 quads and an 8 × 8 impostor; here mostly the
//! wider search of `auto: (quads: [16, 64, 256], impostor_frames: [8, 12])`, each with the
//! largest atlas its bytes allow, and the source's triangles reduced) baked into
//! `lod<N>/candidates/`, measured against the source, the one that holds furthest within the
//! bytes copied into `lod<N>/`; the same choice from a clean bake; a bark edit re-renders only
//! bark, in every candidate; widening the search bakes only the new candidate, narrowing it
//! again runs nothing and removes its files.

use std::collections::BTreeSet;

use crate::billboard_cloud::chain::{chain_project, renders_reading};
use crate::support::{build, pattern_png};

/// The chain, with every cloud and impostor the search may try: `billboard: (lods: …)` goes on.
const CHAIN: &str =
    "[Auto(max_bytes: 262144), Auto(max_bytes: 65536)], auto: (quads: [16, 64, 256], impostor_frames: [8, 12])";
const BYTES: [u64; 2] = [262144, 65536];

fn report(project: &crate::support::TempProject) -> serde_json::Value {
    serde_json::from_slice(&project.read("baked/tree/report.json")).unwrap()
}

/// The candidate the rule picks from a level's report: within the bytes, the one that holds to
/// the largest size, then the least loss there, then the fewest bytes.
fn best_candidate(auto: &serde_json::Value, max_bytes: u64) -> String {
    let candidates = auto["candidates"].as_array().unwrap();
    let rank = |candidate: &&serde_json::Value| {
        let holds_to = candidate["holds_to"].as_u64();
        let measured = candidate["measured"].as_array().unwrap();
        let at = measured.iter().find(|figures| figures["size"].as_u64() == holds_to).or(measured.first());
        let loss = at.and_then(|figures| figures["loss_px_shift"].as_f64()).unwrap_or(0.0);
        (std::cmp::Reverse(holds_to), (loss * 1e6).round() as i64, candidate["gpu_bytes"].as_u64())
    };
    let fitting = candidates.iter().filter(|candidate| candidate["gpu_bytes"].as_u64().unwrap() <= max_bytes);
    fitting.min_by_key(rank).unwrap()["name"].as_str().unwrap().to_string()
}

/// Checks that each of a level's `candidates` was measured from the smallest size up to its
/// first failure after it, or up to the size at which it was outranked: it held there, but lost
/// more than `OUTRANKED_RATIO` times the least loss of the candidates that held there (at least
/// `OUTRANKED_FLOOR`), or else up to the largest size the level was measured at. How many were
/// outranked.
fn measured_until_failed_or_outranked(candidates: &[serde_json::Value]) -> usize {
    use cirrus::preview::{Hold, HOLD_LOSS, HOLD_SIZES, OUTRANKED_FLOOR, OUTRANKED_RATIO};
    let holds: Vec<Hold> =
        candidates.iter().map(|candidate| serde_json::from_value(candidate.clone()).unwrap()).collect();
    let loss_at = |hold: &Hold, size: u32| {
        let figures = hold.measured.iter().find(|figures| figures.size == size)?;
        Some(figures.loss_px_shift.unwrap_or(0.0))
    };
    let largest = holds.iter().filter_map(|hold| hold.measured.last()).map(|figures| figures.size).max().unwrap();
    let mut outranked = 0;
    for (step, size) in HOLD_SIZES.into_iter().enumerate().filter(|&(_, size)| size <= largest) {
        let held = holds.iter().filter_map(|hold| loss_at(hold, size)).filter(|&loss| loss <= HOLD_LOSS);
        let bar = OUTRANKED_RATIO * held.fold(f64::MAX, f64::min).max(OUTRANKED_FLOOR);
        for (hold, candidate) in holds.iter().zip(candidates) {
            let Some(loss) = loss_at(hold, size) else { continue };
            let sizes: Vec<u32> = hold.measured.iter().map(|figures| figures.size).collect();
            assert_eq!(sizes, HOLD_SIZES[..sizes.len()], "{candidate}");
            let is_outranked = step > 0 && loss <= HOLD_LOSS && loss > bar;
            let stops = step > 0 && loss > HOLD_LOSS || is_outranked;
            let is_last = *sizes.last().unwrap() == size;
            assert_eq!(is_last, stops || size == largest, "measured at {size} px: {candidate}");
            assert_eq!(hold.outranked_at == Some(size), is_outranked, "at {size} px (bar {bar}): {candidate}");
            outranked += usize::from(is_outranked);
        }
    }
    outranked
}

#[test]
fn an_auto_level_keeps_the_candidate_that_holds_furthest_within_its_bytes() {
    let project = chain_project(CHAIN);
    let mut cirrus = project.open();
    let summary = build(&mut cirrus);
    assert!(summary.all_ok(), "{}", summary.to_text());
    let executed = cirrus.take_executed_stages();
    assert_eq!(executed.iter().filter(|run| *run == "mesh(tree)").count(), 1, "one mesh stage: {executed:?}");
    // One planes stage per quad count, shared by that count's candidates at every level.
    let planes: Vec<&String> = executed.iter().filter(|run| run.starts_with("planes(")).collect();
    assert_eq!(planes.len(), 3, "{planes:?}");
    assert!(planes.iter().all(|run| run.starts_with("planes(tree/lod0/")), "{planes:?}");

    let built = report(&project);
    let levels = built["levels"].as_array().unwrap();
    assert_eq!(levels.len(), 2);
    let manifest: serde_json::Value = serde_json::from_slice(&project.read("baked/manifest.json")).unwrap();
    let mut outranked = 0;
    for (level, (entry, max_bytes)) in levels.iter().zip(BYTES).enumerate() {
        let auto = &entry["auto"];
        assert_eq!(auto["max_bytes"], max_bytes);
        let candidates = auto["candidates"].as_array().unwrap();
        let names: Vec<&str> = candidates.iter().map(|candidate| candidate["name"].as_str().unwrap()).collect();
        assert!(names.contains(&"quads16") && names.iter().any(|name| name.starts_with("impostor")), "{names:?}");
        // Each candidate baked in its own folder, with its bytes on the GPU as the level reports
        // them, all within the level's bytes (one whose quads would not pack in an atlas the
        // bytes allow is not baked).
        for candidate in candidates {
            let folder = candidate["folder"].as_str().unwrap();
            assert_eq!(folder, format!("lod{level}/candidates/{}", candidate["name"].as_str().unwrap()));
            assert!(project.path(&format!("baked/tree/{folder}/lod.gltf")).is_file(), "{folder}");
            assert!(candidate["gpu_bytes"].as_u64().unwrap() <= max_bytes, "{candidate}");
            assert_eq!(
                manifest["artifacts"][&format!("baked/tree/{folder}/lod.gltf")]["meaning"],
                serde_json::json!({ "lod": level, "candidate": candidate["name"] })
            );
        }
        outranked += measured_until_failed_or_outranked(candidates);
        // The chosen one is the rule's, within the bytes, and its files are the level's.
        let chosen = auto["chosen"].as_str().unwrap();
        assert_eq!(chosen, best_candidate(auto, max_bytes), "lod{level}");
        assert!(entry["gpu_bytes"].as_u64().unwrap() <= max_bytes, "{entry}");
        let chosen_entry = candidates.iter().find(|candidate| candidate["name"] == chosen).unwrap();
        assert_eq!(entry["gpu_bytes"], chosen_entry["gpu_bytes"]);
        assert_eq!(entry["holds_to"], chosen_entry["holds_to"]);
        assert_eq!(entry["folder"], format!("lod{level}"));
        let chosen_folder = format!("baked/tree/lod{level}/candidates/{chosen}/");
        let chosen_files: Vec<&String> =
            manifest["artifacts"].as_object().unwrap().keys().filter(|path| path.starts_with(&chosen_folder)).collect();
        assert!(chosen_files.len() >= 6, "{chosen_files:?}");
        for candidate in chosen_files {
            let shown = format!("baked/tree/lod{level}/{}", &candidate[chosen_folder.len()..]);
            assert_eq!(project.read(&shown), project.read(candidate), "{shown}");
            assert_eq!(manifest["artifacts"][&shown]["meaning"], serde_json::json!({ "lod": level }));
        }
    }
    // The reduced candidates lose next to nothing: the others are measured no further once they
    // lose twice what those do.
    assert!(outranked > 0, "none outranked");
    // A level that the next one holds as far as is never shown, and the build says so.
    let switch: Vec<u64> = levels.iter().map(|level| level["switch_size"].as_u64().unwrap()).collect();
    let never_shown: Vec<&str> = summary.assets[0]
        .warnings
        .iter()
        .map(|warning| warning.message.as_str())
        .filter(|message| message.contains("never shown"))
        .collect();
    let expected: Vec<String> = (0..switch.len() - 1)
        .filter(|&level| switch[level] == switch[level + 1])
        .map(|level| {
            format!(
                "lod{level} of the chain is never shown, and costs its bytes for nothing: lod{} holds as far, up to {} \
                 px",
                level + 1,
                switch[level]
            )
        })
        .collect();
    assert_eq!(never_shown, expected, "switch sizes {switch:?}");
    // On the fixture both levels pick their triangles and hold to 256 px: lod0 is never shown.
    assert_eq!(expected.len(), 1, "switch sizes {switch:?}");
    // Engines see the chosen levels.
    let lods: serde_json::Value = serde_json::from_slice(&project.read("baked/tree/lods.json")).unwrap();
    for (entry, level) in lods["levels"].as_array().unwrap().iter().zip(levels) {
        assert_eq!(entry["representation"], level["representation"]);
        assert_eq!(entry["gpu_bytes"], level["gpu_bytes"]);
    }
    let lines = crate::support::headless_viewer_lines(&project, "baked/tree", &["--size", "64", "--press", "1"]);
    assert!(lines[1].starts_with("showing lod1: lod1 of 2, "), "{lines:?}");

    // A clean bake chooses the same, and measures the same.
    let again = chain_project(CHAIN);
    build(&mut again.open());
    assert_eq!(again.read("baked/tree/lods.json"), project.read("baked/tree/lods.json"));
    let rebuilt = report(&again);
    for (level, entry) in levels.iter().enumerate() {
        assert_eq!(rebuilt["levels"][level]["auto"], entry["auto"]);
    }
}

#[test]
fn a_bark_edit_rerenders_only_the_bark_of_every_candidate_and_a_restart_nothing() {
    let project = chain_project(CHAIN);
    let mut cirrus = project.open();
    build(&mut cirrus);
    cirrus.take_executed_stages();
    let (bark, leaves) =
        (renders_reading(&mut cirrus, "assets/bark.png"), renders_reading(&mut cirrus, "assets/leaf.png"));
    assert!(bark.iter().any(|render| render.contains("lod1/candidates/")), "{bark:?}");
    assert!(!leaves.is_subset(&bark), "some renders show leaves alone");

    project.write("assets/bark.png", pattern_png(32, 32, 7));
    let summary = build(&mut cirrus);
    assert!(summary.all_ok(), "{}", summary.to_text());
    let executed: BTreeSet<String> = cirrus.take_executed_stages().into_iter().collect();
    let renders: BTreeSet<String> = executed.iter().filter(|run| run.starts_with("render(")).cloned().collect();
    assert_eq!(renders, bark, "the bark's renders, in every candidate of every level");
    // The impostors show the bark too: every one is baked again, and the chain measured again.
    assert!(executed.iter().any(|run| run.starts_with("impostor(tree/lod0/candidates/")), "{executed:?}");
    // The reduced candidates (one a level) pack their bark's albedo again, not its normal map
    // nor the leaves, and reduce nothing (at the same size in both, one may find the other's in
    // the cache).
    let maps: Vec<&str> = executed.iter().filter(|run| run.starts_with("maps(")).map(String::as_str).collect();
    let bark_albedo = |run: &&str| {
        ["lod0/candidates/reduced1213", "lod1/candidates/reduced303"]
            .iter()
            .any(|folder| **run == format!("maps(tree/{folder}/materials/bark/albedo)"))
    };
    assert!(!maps.is_empty() && maps.iter().all(bark_albedo), "{maps:?}");
    // Those stored smaller than their source take their level from one packing and mip chain.
    let packs: Vec<&str> = executed.iter().filter(|run| run.starts_with("pack(")).map(String::as_str).collect();
    assert!(packs.iter().all(|run| *run == "pack(tree/materials/bark/albedo)") && packs.len() <= 1, "{packs:?}");
    assert!(!executed.iter().any(|run| run.starts_with("reduce(")), "{executed:?}");
    let bark = |level: &str| project.read(&format!("baked/tree/{level}/materials/bark/albedo.ktx2"));
    assert_eq!(bark("lod0/candidates/reduced1213"), bark("lod1/candidates/reduced303"));
    assert_eq!(
        crate::support::read_ktx2(&bark("lod0/candidates/reduced1213")).width,
        32,
        "the edited bark at its own size"
    );
    assert!(executed.contains("switch(tree)"));

    let mut restarted = project.open();
    let summary = build(&mut restarted);
    assert!(summary.all_ok(), "{}", summary.to_text());
    assert_eq!(restarted.take_executed_stages(), Vec::<String>::new());
}

/// The bundled bush (`examples/assets/trees/bush_2.obj`) built with `lods`, and its report.
fn built_bundled_bush(lods: &str) -> (crate::support::TempProject, serde_json::Value) {
    let (project, built, _) = built_bundled_bush_running(lods);
    (project, built)
}

/// [`built_bundled_bush`], and the stage instances its build ran.
fn built_bundled_bush_running(lods: &str) -> (crate::support::TempProject, serde_json::Value, Vec<String>) {
    let project = crate::support::TempProject::new(&format!(
        r#"Pipeline(source: "assets", output: "baked", assets: [
            BillboardCloud(name: "tree", mesh: "trees/bush_2.obj", billboard: (lods: {lods})),
        ])"#
    ));
    let trees = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/assets/trees");
    project.copy_folder(&trees, "assets/trees");
    let mut cirrus = project.open();
    let summary = build(&mut cirrus);
    assert!(summary.all_ok(), "{}", summary.to_text());
    let built = report(&project);
    (project, built, cirrus.take_executed_stages())
}

#[test]
fn reduced_candidates_storing_a_map_smaller_take_their_levels_from_one_packing_and_mip_chain() {
    // Two levels whose reduced candidates store the bush's 1024² maps at 512² or smaller.
    let (project, built, executed) = built_bundled_bush_running("[Auto(max_bytes: 524288), Auto(max_bytes: 131072)]");
    let reduced: Vec<String> = built["levels"]
        .as_array()
        .unwrap()
        .iter()
        .flat_map(|level| level["auto"]["candidates"].as_array().unwrap().clone())
        .filter(|candidate| candidate["representation"] == "reduced")
        .map(|candidate| candidate["folder"].as_str().unwrap().to_string())
        .collect();
    assert_eq!(reduced.len(), 2, "{built}");
    let runs = |stage: &str| -> Vec<String> {
        let mut runs: Vec<String> = executed.iter().filter(|run| run.starts_with(stage)).cloned().collect();
        runs.sort();
        runs
    };
    // Each candidate's maps made, from one packing and chain per material and map.
    let surfaces = ["bark/albedo", "bark/mra", "bark/normal", "leaves/albedo"];
    let mut maps: Vec<String> = reduced
        .iter()
        .flat_map(|folder| surfaces.map(|surface| format!("maps(tree/{folder}/materials/{surface})")))
        .collect();
    maps.sort();
    assert_eq!(runs("maps("), maps);
    assert_eq!(runs("pack("), surfaces.map(|surface| format!("pack(tree/materials/{surface})")));
    for folder in &reduced {
        let side = texture_side(&project, &format!("baked/tree/{folder}/materials/bark/albedo.ktx2"));
        assert!(side.0 < 1024, "{folder}: {side:?}");
    }
    // What that relies on: a chain's level k is the level a reduction by k halvings stores.
    let pixels =
        (0..64 * 64).flat_map(|index: u32| [(index * 7) as u8, (index / 3) as u8, 90, (index * 13 % 256) as u8]);
    let source = cirrus::texture::Texture::new(64, 64, pixels.collect());
    let settings =
        cirrus::texture::mips::MipSettings { kind: cirrus::texture::SurfaceKind::Albedo, alpha_cutoff: Some(0.5) };
    let chain = cirrus::texture::mips::mip_chain(&source, settings);
    for (halvings, level) in chain.iter().enumerate() {
        assert_eq!(cirrus::texture::mips::reduced_level(&source, settings, halvings as u32).pixels, level.pixels);
    }
}

#[test]
fn a_candidate_whose_quads_cannot_pack_in_its_bytes_is_not_baked() {
    // The bundled bush has planes enough for 256 quads: at 128 KiB they would need a 256² atlas
    // of at least one block each (317 KB), at 32 KiB 64 quads a 128² one (79 KB). Searched by
    // default: 64 quads and 8 × 8 frames.
    let (project, built) = built_bundled_bush("[Auto(max_bytes: 131072), Auto(max_bytes: 32768)]");
    let mut names = Vec::new();
    for (entry, max_bytes) in built["levels"].as_array().unwrap().iter().zip([131072u64, 32768]) {
        for candidate in entry["auto"]["candidates"].as_array().unwrap() {
            assert!(candidate["gpu_bytes"].as_u64().unwrap() <= max_bytes, "{candidate}");
        }
        let level: Vec<&str> = entry["auto"]["candidates"]
            .as_array()
            .unwrap()
            .iter()
            .map(|candidate| candidate["name"].as_str().unwrap())
            .collect();
        names.push(level.join(" "));
    }
    // Impostors of 16-texel frames fit (8 a side at 32 KiB) because their normal and depth are
    // stored at a half or a quarter of their albedo's side.
    // A reduced candidate keeps 128 KiB / 2 / 108 bytes a triangle = 606 triangles; at 32 KiB
    // it would keep too few (151) to be worth measuring.
    assert_eq!(names, ["quads64 impostor8 reduced606", "impostor8"]);

    // The two 8 × 8 impostors (frames of 32 and 16 texels) are one render of the same 64 views:
    // the smaller's frames show the same rects, and its albedo is the larger's next mip level
    // (each BC-decoded).
    let impostor = |level: u32, file: &str| project.read(&format!("baked/tree/lod{level}/candidates/impostor8/{file}"));
    let [large, small]: [serde_json::Value; 2] =
        [0, 1].map(|level| serde_json::from_slice(&impostor(level, "impostor.json")).unwrap());
    assert_eq!((&large["frame_size"], &small["frame_size"]), (&serde_json::json!(32), &serde_json::json!(16)));
    assert_eq!(large["frame_rects"], small["frame_rects"]);
    let decoded = |bytes: &[u8], level: usize| {
        let ktx2 = crate::support::read_ktx2(bytes);
        let (width, height) = (ktx2.width >> level, ktx2.height >> level);
        let blocks = crate::support::ktx2_level(bytes, &ktx2, level);
        cirrus::texture::quality::decode_blocks(cirrus::config::BlockFormat::Bc7, &blocks, width, height)
    };
    let (large_albedo, small_albedo) = (impostor(0, "albedo.ktx2"), impostor(1, "albedo.ktx2"));
    let (half, own) = (decoded(&large_albedo, 1), decoded(&small_albedo, 0));
    assert_eq!((half.width, half.height), (own.width, own.height));
    let mut psnr = crate::support::PsnrSum::default();
    for (a, b) in half.pixels.chunks_exact(4).zip(own.pixels.chunks_exact(4)) {
        psnr.add(a.try_into().unwrap(), b.try_into().unwrap(), 4);
    }
    assert!(psnr.psnr() > 30.0, "{:.1} dB", psnr.psnr());
}

/// The level 0 size of a baked texture file.
fn texture_side(project: &crate::support::TempProject, path: &str) -> (u32, u32) {
    let texture = crate::support::read_ktx2(&project.read(path));
    (texture.width, texture.height)
}

#[test]
fn an_auto_candidate_gives_its_bytes_to_its_albedo_first() {
    // 128 KiB for the bundled bush. With every surface at one side, a 16-quad cloud's atlas
    // would be 128² (albedo, packed, normal and height: 4.7 bytes a texel with mips) and an
    // 8-frame impostor's 128² (16-texel frames); with the albedo first, the cloud's albedo is
    // 256² and the impostor's frames 32 texels, the other surfaces at a half or a quarter side.
    let (project, built) =
        built_bundled_bush("[Auto(max_bytes: 131072)], auto: (quads: [16, 64], impostor_frames: [8])");
    let candidates = built["levels"][0]["auto"]["candidates"].as_array().unwrap();
    let folder = |name: &str| format!("baked/tree/lod0/candidates/{name}");
    for candidate in candidates {
        // Measured as an engine draws it, within its bytes counted at each file's own size.
        assert!(!candidate["measured"].as_array().unwrap().is_empty(), "{candidate}");
        assert!(candidate["gpu_bytes"].as_u64().unwrap() <= 131072, "{candidate}");
    }
    let quads = folder("quads16");
    assert_eq!(texture_side(&project, &format!("{quads}/albedo.ktx2")), (256, 256));
    let [normal, height, mra] =
        ["normal", "height", "mra"].map(|name| texture_side(&project, &format!("{quads}/{name}.ktx2")));
    assert_eq!(normal, (128, 128), "the normal wins back texels first");
    assert_eq!(height, (128, 128));
    assert_eq!(mra, (64, 64), "the packed surface last");
    let quads16 = candidates.iter().find(|candidate| candidate["name"] == "quads16").unwrap();
    let sides = serde_json::json!({ "albedo": 256, "mra": 64, "normal": 128, "height": 128 });
    assert_eq!(quads16["surface_sides"], sides, "the report lists each surface's side");

    let impostor = folder("impostor8");
    let description: serde_json::Value =
        serde_json::from_slice(&project.read(&format!("{impostor}/impostor.json"))).unwrap();
    assert_eq!(description["frame_size"], 32);
    assert_eq!(texture_side(&project, &format!("{impostor}/albedo.ktx2")), (256, 256));
    for name in ["normal", "height"] {
        assert_eq!(texture_side(&project, &format!("{impostor}/{name}.ktx2")), (128, 128), "{name}");
    }

    // The reduced candidate: at most 606 triangles, and its materials' maps (bark albedo, mra
    // and normal, the leaves' albedo, all 1024² in the source) at the side they share in the
    // bytes its mesh leaves (at 256 the two albedos alone would pass them), its bytes on the GPU
    // the glTF's buffer and the KTX2s'.
    let reduced = folder("reduced606");
    let obj = project.read(&format!("{reduced}/lod.obj"));
    let triangles = String::from_utf8_lossy(&obj).lines().filter(|line| line.starts_with("f ")).count();
    assert!(triangles <= 606 && triangles > 300, "{triangles}");
    let entry = candidates.iter().find(|candidate| candidate["name"] == "reduced606").unwrap();
    let maps = ["bark/albedo", "bark/mra", "bark/normal", "leaves/albedo"];
    let sides = serde_json::Value::Object(maps.iter().map(|map| (map.to_string(), serde_json::json!(128))).collect());
    assert_eq!(entry["surface_sides"], sides);
    let mut gpu_bytes = project.read(&format!("{reduced}/lod.bin")).len() as u64;
    for map in maps {
        let ktx2 = crate::support::read_ktx2(&project.read(&format!("{reduced}/materials/{map}.ktx2")));
        assert_eq!((ktx2.width, ktx2.height), (128, 128), "{map}");
        gpu_bytes += ktx2.levels.iter().map(|level| level.2).sum::<u64>();
    }
    assert_eq!(entry["gpu_bytes"], gpu_bytes);
}

#[test]
fn widening_the_search_bakes_only_the_new_candidate_and_narrowing_it_removes_its_files() {
    let (project, built) = built_bundled_bush("[Auto(max_bytes: 131072)]");
    let names = |built: &serde_json::Value| -> Vec<String> {
        let candidates = built["levels"][0]["auto"]["candidates"].as_array().unwrap();
        candidates.iter().map(|candidate| candidate["name"].as_str().unwrap().to_string()).collect()
    };
    assert_eq!(names(&built), ["quads64", "impostor8", "reduced606"]);
    let pipeline = String::from_utf8(project.read("pipeline.ron")).unwrap();
    let widened = pipeline
        .replace("(lods: [Auto(max_bytes: 131072)])", "(lods: [Auto(max_bytes: 131072)], auto: (quads: [16, 64]))");
    assert_ne!(widened, pipeline);

    // Widened: the 16-quad cloud is baked and the level measured again; nothing of the others.
    project.write("pipeline.ron", &widened);
    let mut cirrus = project.open();
    let summary = build(&mut cirrus);
    assert!(summary.all_ok(), "{}", summary.to_text());
    let executed = cirrus.take_executed_stages();
    let candidates: Vec<&String> = executed.iter().filter(|run| run.contains("/candidates/")).collect();
    assert!(!candidates.is_empty() && candidates.iter().all(|run| run.contains("/candidates/quads16")), "{executed:?}");
    assert!(executed.contains(&"switch(tree)".to_string()), "{executed:?}");
    assert_eq!(names(&report(&project)), ["quads16", "quads64", "impostor8", "reduced606"]);
    assert!(project.path("baked/tree/lod0/candidates/quads16/lod.gltf").is_file());

    // Narrowed again: every stage from the cache, and the 16-quad cloud's files gone.
    project.write("pipeline.ron", &pipeline);
    let mut cirrus = project.open();
    let summary = build(&mut cirrus);
    assert!(summary.all_ok(), "{}", summary.to_text());
    assert_eq!(cirrus.take_executed_stages(), Vec::<String>::new());
    assert_eq!(names(&report(&project)), ["quads64", "impostor8", "reduced606"]);
    assert!(!project.path("baked/tree/lod0/candidates/quads16").exists());
}
