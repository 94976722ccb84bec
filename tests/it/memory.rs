//! The memory budget: a build in a small budget bakes in groups and writes the same bytes, a
//! build killed between groups leaves every asset whole and the next one finishes the rest, and
//! the daemon lets go of what it does not keep and bakes an edit of an evicted asset as a clean
//! build does.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use cirrus::db::Retention;
use cirrus::project::{AssetCost, MemoryPolicy, Project, ProjectOptions, SourceReading};

use crate::make_level::{noise_png, write_level, Level, LevelSettings};
use crate::support::{build, files_under, TempProject};

/// The smallest budget there is: a group holds 32 MiB, and every asset counts for at least 8.
const SMALL_BUDGET: u64 = 64 << 20;

fn level(folder: &Path, assets: usize, side: u32) -> Level {
    write_level(folder, &LevelSettings { assets, material_side: Some(side) }).expect("level written")
}

fn open(level: &Level, options: ProjectOptions) -> Project {
    let config = cirrus::pipeline::load_pipeline(&level.pipeline).expect("valid pipeline");
    Project::open(config, options)
}

/// Every artifact under `baked/` but the reports and the manifest (whose timings and hashes of
/// reports differ from run to run), by path.
fn artifacts(folder: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    let baked = folder.join("baked");
    files_under(&baked)
        .into_iter()
        .map(|path| path.strip_prefix(&baked).map(Path::to_path_buf).unwrap_or(path))
        .filter(|path| !path.starts_with(".cirrus"))
        .filter(|path| path.file_name().is_some_and(|name| name != "report.json" && name != "manifest.json"))
        .map(|path| {
            let bytes = std::fs::read(baked.join(&path)).expect("artifact read");
            (path, bytes)
        })
        .collect()
}

fn read_manifest(folder: &Path) -> cirrus::artifacts::Manifest {
    let bytes = std::fs::read(folder.join("baked/manifest.json")).expect("manifest read");
    serde_json::from_slice(&bytes).expect("manifest JSON")
}

fn one_shot(budget: Option<u64>) -> ProjectOptions {
    ProjectOptions { retention: Retention::OutputsOnly, memory_budget: budget, ..Default::default() }
}

#[test]
fn a_build_in_a_small_budget_bakes_in_groups_and_writes_the_same_bytes() {
    let (small, roomy) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let (small_level, roomy_level) = (level(small.path(), 10, 64), level(roomy.path(), 10, 64));
    let mut in_groups = open(&small_level, one_shot(Some(SMALL_BUDGET)));
    let summary = build(&mut in_groups);
    assert!(summary.all_ok(), "{}", summary.to_text());
    assert_eq!(summary.assets.len(), 10);
    // Four assets of at least 8 MiB each fill a group's 32 MiB: 10 assets bake in 3 groups.
    assert_eq!(in_groups.groups_baked(), 3);
    // A one-shot build lets go of every source's bytes once its group published.
    assert_eq!(in_groups.source_bytes_in_memory(), 0);
    let mut together = open(&roomy_level, one_shot(Some(4 << 30)));
    build(&mut together);
    assert_eq!(together.groups_baked(), 1);
    let (grouped, whole) = (artifacts(small.path()), artifacts(roomy.path()));
    assert!(grouped.len() >= 40, "{:?}", grouped.keys().collect::<Vec<_>>());
    assert_eq!(grouped.keys().collect::<Vec<_>>(), whole.keys().collect::<Vec<_>>());
    for (path, bytes) in &grouped {
        assert!(whole[path] == *bytes, "{} differs", path.display());
    }
    // The manifest lists every asset's artifacts, as one build would.
    let manifest = read_manifest(small.path());
    let listed: std::collections::BTreeSet<&str> =
        manifest.artifacts.values().map(|entry| entry.asset.as_str()).collect();
    assert_eq!(listed.len(), 10);
}

#[test]
fn a_build_killed_between_groups_leaves_every_asset_whole_and_the_next_finishes_the_rest() {
    let dir = tempfile::tempdir().unwrap();
    level(dir.path(), 16, 512);
    let manifest = dir.path().join("baked/manifest.json");
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_cirrus"))
        .args(["build", "--memory-mib", "64"])
        .current_dir(dir.path())
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .expect("run cirrus");
    // The first group's manifest is written before the second group starts.
    let started = std::time::Instant::now();
    while !manifest.exists() {
        assert!(child.try_wait().unwrap().is_none(), "the build ended before its first group was published");
        assert!(started.elapsed().as_secs() < 120, "no group published in 2 minutes");
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    child.kill().unwrap();
    child.wait().unwrap();

    // Each asset the manifest lists is whole: every artifact it lists is there, with the bytes
    // the manifest names; an asset with no report has nothing in place.
    let listed = read_manifest(dir.path());
    assert!(!listed.artifacts.is_empty());
    let mut listed_assets = std::collections::BTreeSet::new();
    for (path, entry) in &listed.artifacts {
        let bytes = std::fs::read(dir.path().join(path)).unwrap_or_else(|_| panic!("{path} is listed but missing"));
        assert_eq!(blake3::hash(&bytes).to_hex().to_string(), entry.hash, "{path}");
        listed_assets.insert(entry.asset.clone());
    }
    assert!(listed_assets.len() < 16, "the build was killed before its last group: {listed_assets:?}");

    // The next build (the same executable: its identity is in each asset's fingerprint) runs no
    // stage of the published assets and bakes the rest: the same bytes as a build that was never
    // interrupted.
    let output = std::process::Command::new(env!("CARGO_BIN_EXE_cirrus"))
        .args(["build", "--memory-mib", "64", "--summary", "json"])
        .current_dir(dir.path())
        .output()
        .expect("run cirrus");
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    let summary: serde_json::Value = serde_json::from_slice(&output.stdout).expect("summary JSON");
    let assets = summary["assets"].as_array().expect("assets");
    assert_eq!(assets.len(), 16);
    assert!(assets.iter().all(|asset| asset["status"] == "ok"), "{summary}");
    let passed_over: std::collections::BTreeSet<String> = assets
        .iter()
        .filter(|asset| {
            asset["stages"].as_array().is_some_and(|stages| stages.iter().all(|stage| stage["status"] != "ran"))
        })
        .map(|asset| asset["name"].as_str().expect("name").to_string())
        .collect();
    assert_eq!(passed_over, listed_assets);
    let clean = tempfile::tempdir().unwrap();
    let clean_level = self::level(clean.path(), 16, 512);
    build(&mut open(&clean_level, one_shot(None)));
    assert!(artifacts(dir.path()) == artifacts(clean.path()), "the finished build differs from a clean one");
}

#[test]
fn the_daemon_in_a_small_budget_keeps_the_last_assets_and_bakes_an_edit_of_an_evicted_one_as_a_clean_build() {
    let dir = tempfile::tempdir().unwrap();
    let level = level(dir.path(), 8, 64);
    let options = ProjectOptions {
        source_reading: SourceReading::WhenInvalidated,
        retention: Retention::KeepForNextBuild,
        memory_budget: Some(SMALL_BUDGET),
        ..Default::default()
    };
    let mut daemon = open(&level, options);
    let summary = build(&mut daemon);
    assert!(summary.all_ok(), "{}", summary.to_text());
    assert_eq!(daemon.groups_baked(), 2);
    // The budget's quarter (16 MiB) keeps two assets of 8: the last two baked.
    let names: Vec<String> = summary.assets.iter().map(|asset| asset.name.clone()).collect();
    assert_eq!(daemon.kept_assets(), names[6..].to_vec());
    let memos = daemon.database().kept_memos();
    assert!(memos.iter().all(|memo| names[6..].iter().any(|kept| memo.contains(&format!(":{kept}/")))), "{memos:?}");
    assert!(!memos.is_empty());
    // Only the kept assets' sources stay in memory.
    let kept_bytes = daemon.source_bytes_in_memory();
    assert!(kept_bytes > 0);
    let sources = files_under(&dir.path().join("assets"));
    let all_bytes: u64 = sources.iter().map(|path| std::fs::metadata(path).unwrap().len()).sum();
    assert!(kept_bytes < all_bytes / 2, "{kept_bytes} of {all_bytes}");

    // An edit of the first asset (evicted since) bakes that asset alone, to the bytes a clean
    // build of the edited level writes, and it is kept from then on.
    let edited = noise_png(64, 64, 3, 9_191);
    std::fs::write(dir.path().join(&level.albedo_maps[0]), &edited).unwrap();
    assert!(daemon.refresh_sources([level.albedo_maps[0].as_path()]));
    daemon.take_executed_stages();
    let summary = build(&mut daemon);
    assert!(summary.all_ok(), "{}", summary.to_text());
    let executed = daemon.take_executed_stages();
    let first = names[0].rsplit('/').next().expect("a name");
    assert!(!executed.is_empty() && executed.iter().all(|stage| stage.contains(first)), "{executed:?}");
    assert!(daemon.kept_assets().contains(&names[0]), "{:?}", daemon.kept_assets());
    let clean = tempfile::tempdir().unwrap();
    let clean_level = self::level(clean.path(), 8, 64);
    std::fs::write(clean.path().join(&clean_level.albedo_maps[0]), &edited).unwrap();
    build(&mut open(&clean_level, one_shot(None)));
    assert!(artifacts(dir.path()) == artifacts(clean.path()), "the edit baked otherwise than a clean build");
}

fn named(names: &[&str], mib: u64) -> Vec<(String, AssetCost)> {
    let cost = AssetCost { held: mib << 20, kept: mib << 20, surfaces: 2, images: 2 };
    names.iter().map(|name| (name.to_string(), cost)).collect()
}

fn sorted(kept: std::collections::HashSet<String>) -> Vec<String> {
    let mut kept: Vec<String> = kept.into_iter().collect();
    kept.sort();
    kept
}

#[test]
fn a_source_let_go_and_gone_from_disk_is_a_diagnostic_naming_it_never_a_panic() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("albedo.png");
    let bytes = noise_png(16, 16, 3, 1);
    std::fs::write(&path, &bytes).unwrap();
    let contents = cirrus::db::FileContents::from_file(bytes.clone(), path.clone());
    contents.release();
    assert!(!contents.is_kept());
    std::fs::remove_file(&path).unwrap();
    let gone = contents.bytes().expect_err("the file is gone");
    assert!(gone.to_string().contains("albedo.png: cannot read it again"), "{gone}");
    std::fs::write(&path, noise_png(16, 16, 3, 2)).unwrap();
    let changed = contents.bytes().expect_err("the file changed");
    assert!(
        changed.to_string().ends_with("albedo.png: changed while it was being baked; the next build bakes it again"),
        "{changed}"
    );
    // The driver sets such a file's input again, even to the same bytes (see `source_file`).
    assert!(contents.read_back_failed());
    std::fs::write(&path, &bytes).unwrap();
    assert_eq!(&*contents.bytes().expect("the same bytes again"), &bytes[..]);
}

#[test]
fn the_policy_keeps_the_last_baked_as_far_as_its_share_goes() {
    // A budget of 400 MiB keeps 100 MiB: two assets of 40.
    let mut policy = MemoryPolicy::new(400 << 20);
    policy.baked(&named(&["a", "b", "c"], 40));
    policy.baked(&named(&["d"], 40));
    // The group's asset, and the last baked before it.
    assert_eq!(sorted(policy.kept_with(&named(&["e"], 40))), ["d", "e"]);
    // Of a group, its last.
    assert_eq!(sorted(policy.kept_with(&named(&["x", "y", "z"], 40))), ["y", "z"]);
    // An asset baked again is the last baked.
    policy.baked(&named(&["a"], 40));
    let kept = policy.kept_with(&[]);
    assert_eq!(sorted(kept.clone()), ["a", "d"]);
    assert_eq!(policy.kept_memos(&kept), (4, 4));
    // One larger than the share is not kept.
    assert!(MemoryPolicy::new(100 << 20).kept_with(&named(&["big"], 30)).is_empty());
}

#[test]
fn a_billboard_clouds_renders_count_in_its_estimate_so_two_bushes_bake_in_two_groups() {
    // A bush's sources (four 1k bark maps and its leaf card) come to about 27 MiB held, so two
    // would fit the 64 MiB that a 128 MiB budget gives a group; what each renders and packs
    // (its planes' atlases, about 25 MiB more at 1024²) does not, and each bakes alone.
    let pipeline = |budget: &str| {
        format!(
            r#"Pipeline(source: "assets", output: "baked", limits: ({budget}), assets: [
                BillboardCloud(name: "bush_a", mesh: "trees/bush_a.obj", atlas: (max_size: 1024)),
                BillboardCloud(name: "bush_b", mesh: "trees/bush_b.obj", atlas: (max_size: 1024)),
            ])"#
        )
    };
    let bushes = |budget: &str| {
        let project = TempProject::new(&pipeline(budget));
        let trees = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/assets/trees");
        project.copy_folder(&trees, "assets/trees");
        let bush = std::fs::read(trees.join("bush_2.obj")).expect("bundled bush");
        project.write("assets/trees/bush_a.obj", &bush);
        project.write("assets/trees/bush_b.obj", &bush);
        project
    };
    bakes_in_two_groups_as_one_would(&bushes("memory_mib: 128"), &bushes("memory_mib: 4096"), "bush_b");
}

/// Builds `small` (two assets that its budget bakes in two groups) and `roomy` (the same in one
/// group), and asserts both write the same artifacts, `witness`'s among them.
fn bakes_in_two_groups_as_one_would(small: &TempProject, roomy: &TempProject, witness: &str) {
    let open = |project: &TempProject| {
        let config = cirrus::pipeline::load_pipeline(&project.path("pipeline.ron")).expect("valid pipeline");
        Project::open(config, one_shot(None))
    };
    let mut apart = open(small);
    let summary = build(&mut apart);
    assert!(summary.all_ok(), "{}", summary.to_text());
    assert_eq!(apart.groups_baked(), 2);
    let mut together = open(roomy);
    assert!(build(&mut together).all_ok());
    assert_eq!(together.groups_baked(), 1);
    let (grouped, whole) = (artifacts(small.root()), artifacts(roomy.root()));
    assert!(grouped.keys().any(|path| path.starts_with(witness)), "{:?}", grouped.keys().collect::<Vec<_>>());
    assert_eq!(grouped.keys().collect::<Vec<_>>(), whole.keys().collect::<Vec<_>>());
    for (path, bytes) in &grouped {
        assert!(whole[path] == *bytes, "{} differs", path.display());
    }
}

#[test]
fn the_budgets_share_for_work_in_flight_bounds_what_a_texture_limit_allows_and_work_alone_proceeds() {
    let memory = cirrus::schedule::MemoryBudget::new();
    memory.set_ceiling(10);
    let first = memory.reserve(6, 100);
    let (sent, received) = std::sync::mpsc::channel();
    std::thread::scope(|scope| {
        scope.spawn(|| {
            let _second = memory.reserve(6, 100);
            sent.send(memory.reserved()).expect("sent");
        });
        // 6 + 6 passes the ceiling of 10, though not the limit of 100: the second waits.
        assert!(received.recv_timeout(std::time::Duration::from_millis(200)).is_err());
        drop(first);
        assert_eq!(received.recv_timeout(std::time::Duration::from_secs(10)), Ok(6));
    });
    // Alone, a reservation larger than the ceiling still proceeds.
    let alone = memory.reserve(50, 100);
    assert_eq!(memory.reserved(), 50);
    drop(alone);
}

#[test]
fn an_ao_and_a_height_bake_count_their_maps_so_that_two_large_ones_bake_in_two_groups() {
    // At 2048² an AO map is held to need 68 MiB and a height map 208 MiB (17 and 52 B a texel,
    // measured): together more than the 256 MiB a 512 MiB budget gives a group, though their
    // meshes alone would fit it many times over.
    let pipeline = |budget: &str| {
        format!(
            r#"Pipeline(source: "assets", output: "baked", limits: ({budget}), assets: [
                AmbientOcclusion(name: "spot_ao", mesh: "meshes/spot/spot_triangulated_with_mtl.obj", ao: (size: 2048, rays: 16)),
                Height(name: "spot_height", high: "meshes/spot_height/spot_high.obj", low: "meshes/spot_height/spot_low.obj",
                       height: (size: 2048)),
            ])"#
        )
    };
    let project = |budget: &str| {
        let project = TempProject::new(&pipeline(budget));
        let meshes = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/assets/meshes");
        project.copy_folder(&meshes, "assets/meshes");
        project
    };
    bakes_in_two_groups_as_one_would(&project("memory_mib: 512"), &project("memory_mib: 4096"), "spot_height");
}
