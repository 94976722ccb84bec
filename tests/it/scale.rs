//! A level's worth of assets (the synthetic level of `examples/make_level.rs`): an edit costs
//! what it touches, and the build record (source metadata beside content hashes, baked assets'
//! fingerprints) never makes a changed file look unchanged, survives a killed build and is
//! rebuilt when damaged.

use std::path::Path;
use std::time::{Duration, SystemTime};

use cirrus::record::{BuildRecord, FileStamp};

use crate::make_level::{noise_png, write_level, LevelSettings};
use crate::support::{build, TempProject};

/// `cirrus build --summary json` in `folder`: the summary.
fn build_process(folder: &Path, arguments: &[&str]) -> serde_json::Value {
    let output = std::process::Command::new(env!("CARGO_BIN_EXE_cirrus"))
        .args(["build", "--summary", "json"])
        .args(arguments)
        .current_dir(folder)
        .output()
        .expect("run cirrus");
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    serde_json::from_slice(&output.stdout).expect("summary JSON")
}

/// `asset:stage(instance)` of every stage that ran, per the summary.
fn ran(summary: &serde_json::Value) -> Vec<String> {
    let mut ran = Vec::new();
    for asset in summary["assets"].as_array().expect("assets") {
        for stage in asset["stages"].as_array().expect("stages").iter().filter(|stage| stage["status"] == "ran") {
            ran.push(format!("{}:{}({})", asset["name"], stage["stage"], stage["instance"]));
        }
    }
    ran
}

#[test]
fn a_one_texture_edit_in_a_level_of_a_thousand_assets_runs_only_that_assets_stages() {
    let dir = tempfile::tempdir().unwrap();
    let level = write_level(dir.path(), &LevelSettings { assets: 1000, ..Default::default() }).unwrap();
    assert_eq!(level.counts, [900, 70, 30]);
    let config = cirrus::pipeline::load_pipeline(&level.pipeline).unwrap();
    let mut project = cirrus::project::Project::open(config.clone(), Default::default());
    let cold = build(&mut project);
    assert!(cold.all_ok(), "{}", cold.to_text());
    assert_eq!(cold.assets.len(), 1000);
    project.take_executed_stages();

    // Material 500's albedo (64²) gets new texels.
    let albedo = dir.path().join(&level.albedo_maps[500]);
    std::fs::write(&albedo, noise_png(64, 64, 3, 4242)).unwrap();
    let summary = build(&mut project);
    assert!(summary.all_ok());
    let executed = project.take_executed_stages();
    assert!(!executed.is_empty());
    assert!(executed.iter().all(|stage| stage.contains("m00500")), "{executed:?}");
    let rebuilt: Vec<&str> = summary
        .assets
        .iter()
        .filter(|asset| asset.stages.iter().any(|stage| stage.status == cirrus::summary::StageStatus::Ran))
        .map(|asset| asset.name.as_str())
        .collect();
    assert_eq!(rebuilt, ["materials/g005/m00500"]);
    assert!(summary.changed.iter().all(|artifact| artifact.asset == "materials/g005/m00500"));
    assert!(summary.changed.iter().any(|artifact| artifact.artifact.ends_with("albedo.ktx2")), "{:?}", summary.changed);

    // A new process: the same edit again is passed over everywhere but in that asset.
    std::fs::write(&albedo, noise_png(64, 64, 3, 4343)).unwrap();
    let summary = build_process(dir.path(), &[]);
    let ran = ran(&summary);
    assert!(!ran.is_empty() && ran.iter().all(|stage| stage.contains("m00500")), "{ran:?}");
    // And a no-op process runs nothing, whatever the level's size.
    assert!(self::ran(&build_process(dir.path(), &[])).is_empty());
    // The graph of a passed-over asset comes from the record and names its files and artifacts.
    let graph = project.graph();
    assert!(graph.has_asset("materials/g007/m00700"));
    let downstream = graph.downstream("assets/textures/g007/m00700_normal.png");
    assert!(downstream.iter().any(|node| node.ends_with("m00700/normal.ktx2")), "{downstream:?}");
}

/// A BMP (its size fixed by its dimensions: an edit keeps the file's length).
fn bmp(seed: u8) -> Vec<u8> {
    let image = image::RgbImage::from_fn(16, 16, |x, y| image::Rgb([x as u8 * 16, y as u8 * 16, seed]));
    let mut bytes = Vec::new();
    image::DynamicImage::ImageRgb8(image)
        .write_to(&mut std::io::Cursor::new(&mut bytes), image::ImageFormat::Bmp)
        .unwrap();
    bytes
}

fn bmp_project() -> TempProject {
    let project = TempProject::new(
        r#"Pipeline(source: "assets", output: "baked", assets: [Material(name: "wall", material: "wall.mymaterial")])"#,
    );
    project.write(
        "assets/wall.mymaterial",
        "Material $wall { Texture (attrib = \"diffuse\") {string {\"wall.bmp\"}} Param (attrib = \"roughness\") {float {0.5}} }\n",
    );
    project.write("assets/wall.bmp", bmp(0));
    project
}

/// Sets a file's modification time.
fn set_modified(path: &Path, time: SystemTime) {
    std::fs::File::options().write(true).open(path).unwrap().set_modified(time).unwrap();
}

#[test]
fn a_touched_file_runs_nothing_and_a_changed_one_is_caught_even_with_its_mtime_put_back() {
    let project = bmp_project();
    let texture = project.path("assets/wall.bmp");
    assert!(!ran(&build_process(project.root(), &[])).is_empty());

    // Touched: new metadata, the same bytes. Nothing runs, nothing is rewritten.
    let manifest = project.read("baked/manifest.json");
    set_modified(&texture, SystemTime::now() - Duration::from_secs(60));
    assert!(ran(&build_process(project.root(), &[])).is_empty());
    assert_eq!(project.read("baked/manifest.json"), manifest);

    // Changed within the racy window (just after the build that recorded it), same length, the
    // modification time put back as some tools do.
    let albedo = project.read("baked/wall/wall/albedo.ktx2");
    let modified = std::fs::metadata(&texture).unwrap().modified().unwrap();
    std::fs::write(&texture, bmp(1)).unwrap();
    set_modified(&texture, modified);
    assert_eq!(std::fs::metadata(&texture).unwrap().len() as usize, bmp(0).len());
    assert!(ran(&build_process(project.root(), &[])).iter().any(|stage| stage.contains("decode")));
    assert_ne!(project.read("baked/wall/wall/albedo.ktx2"), albedo);

    // Outside the racy window: the record trusts the file's metadata (it is no longer racy)...
    std::thread::sleep(Duration::from_millis(2100));
    build_process(project.root(), &[]);
    let record = BuildRecord::load(&project.path("baked"));
    let recorded = &record.files[Path::new("assets/wall.bmp")];
    assert!(!recorded.racy, "{recorded:?}");
    // ...and a change with the modification time put back still moves its change time.
    let albedo = project.read("baked/wall/wall/albedo.ktx2");
    let modified = std::fs::metadata(&texture).unwrap().modified().unwrap();
    std::fs::write(&texture, bmp(2)).unwrap();
    set_modified(&texture, modified);
    assert!(ran(&build_process(project.root(), &[])).iter().any(|stage| stage.contains("decode")));
    assert_ne!(project.read("baked/wall/wall/albedo.ktx2"), albedo);

    // --verify hashes everything: the same result, nothing runs.
    assert!(ran(&build_process(project.root(), &["--verify"])).is_empty());
    // The text summary counts the assets passed over instead of listing them.
    let text = project.run_cli(&["build"]);
    let text = String::from_utf8_lossy(&text.stdout);
    assert!(text.starts_with("ok     1 asset(s) unchanged: nothing they read moved"), "{text}");
}

#[test]
fn a_stamp_recorded_within_the_racy_window_is_never_trusted() {
    let now = cirrus::record::now();
    let second = 1_000_000_000;
    let stamp = |modified: i64, changed: i64| FileStamp { size: 10, modified, changed, file: 7, device: 1 };
    let hash = blake3::hash(b"texels");
    let mut record = BuildRecord::default();
    let path = Path::new("assets/a.png");

    // Modified a moment before it was recorded (a coarse file system's tick): hashed again.
    record.remember_file(path, stamp(now - second / 2, now - second / 2), hash, now);
    assert_eq!(record.trusted_hash(path, &stamp(now - second / 2, now - second / 2)), None);
    // Its change time counts too (a tool that put the modification time back).
    record.remember_file(path, stamp(now - 60 * second, now - second), hash, now);
    assert_eq!(record.trusted_hash(path, &stamp(now - 60 * second, now - second)), None);
    // A clock set back: a time after the recording is racy as well.
    record.remember_file(path, stamp(now + 60 * second, now + 60 * second), hash, now);
    assert_eq!(record.trusted_hash(path, &stamp(now + 60 * second, now + 60 * second)), None);
    // Older than the window: trusted while every field of the stamp is the same.
    let old = stamp(now - 60 * second, now - 60 * second);
    record.remember_file(path, old, hash, now);
    assert_eq!(record.trusted_hash(path, &old), Some(hash));
    for moved in [
        FileStamp { size: 11, ..old },
        FileStamp { modified: old.modified + 1, ..old },
        FileStamp { changed: old.changed + 1, ..old },
        FileStamp { file: 8, ..old },
        FileStamp { device: 2, ..old },
    ] {
        assert_eq!(record.trusted_hash(path, &moved), None, "{moved:?}");
    }
}

#[test]
fn the_record_survives_a_killed_build_and_is_rebuilt_when_damaged() {
    let dir = tempfile::tempdir().unwrap();
    write_level(dir.path(), &LevelSettings { assets: 60, ..Default::default() }).unwrap();
    // Killed mid-build, at a few moments.
    for delay_ms in [150, 400] {
        let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_cirrus"))
            .arg("build")
            .current_dir(dir.path())
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap();
        std::thread::sleep(Duration::from_millis(delay_ms));
        child.kill().unwrap();
        child.wait().unwrap();
        if let Ok(bytes) = std::fs::read(dir.path().join("baked/.cirrus/record.json")) {
            serde_json::from_slice::<serde_json::Value>(&bytes).expect("a whole record or none");
        }
    }
    let summary = build_process(dir.path(), &[]);
    assert!(summary["assets"].as_array().unwrap().iter().all(|asset| asset["status"] == "ok"), "{summary}");
    let manifest = std::fs::read(dir.path().join("baked/manifest.json")).unwrap();
    assert!(ran(&build_process(dir.path(), &[])).is_empty());

    // A damaged record: the build says so, asks every stage (all from the cache), writes a
    // whole record again, and the next build passes every asset over.
    std::fs::write(dir.path().join("baked/.cirrus/record.json"), b"{\"version\":1,\"files\":{\"x\":").unwrap();
    let output = std::process::Command::new(env!("CARGO_BIN_EXE_cirrus"))
        .args(["build", "--summary", "json"])
        .current_dir(dir.path())
        .output()
        .unwrap();
    assert!(output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("record.json is damaged"), "{stderr}");
    let summary: serde_json::Value = serde_json::from_slice(&output.stdout).unwrap();
    assert!(ran(&summary).is_empty(), "{:?}", ran(&summary));
    assert_eq!(std::fs::read(dir.path().join("baked/manifest.json")).unwrap(), manifest);
    assert!(ran(&build_process(dir.path(), &[])).is_empty());
    let stats = std::process::Command::new(env!("CARGO_BIN_EXE_cirrus"))
        .args(["cache", "stats"])
        .current_dir(dir.path())
        .output()
        .unwrap();
    let stats = String::from_utf8_lossy(&stats.stdout);
    assert!(stats.contains("assets passed over (nothing they read changed): 60"), "{stats}");

    // A record that names files outside the source folder (edited by hand or by an attacker):
    // that asset is not trusted, and is checked through its stages again. (First every file out
    // of the racy window, so that the other assets read nothing.)
    std::thread::sleep(Duration::from_millis(2100));
    build_process(dir.path(), &[]);
    let path = dir.path().join("baked/.cirrus/record.json");
    let mut record: serde_json::Value = serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    let asset = &mut record["assets"]["materials/g000/m00001"];
    asset["files"].as_array_mut().unwrap().push("assets/../pipeline.ron".into());
    std::fs::write(&path, serde_json::to_vec(&record).unwrap()).unwrap();
    let output = std::process::Command::new(env!("CARGO_BIN_EXE_cirrus"))
        .args(["-v", "build"])
        .current_dir(dir.path())
        .output()
        .unwrap();
    assert!(output.status.success());
    // Its three files are read to bake it again; the file the record named outside is not.
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("59 asset(s) passed over, 1 looked into; 3 source file(s) read"), "{stderr}");
    let record: serde_json::Value = serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    let files = record["assets"]["materials/g000/m00001"]["files"].as_array().unwrap();
    assert!(files.iter().all(|file| !file.as_str().unwrap().contains("..")), "{files:?}");
}

#[test]
fn the_daemon_starts_on_a_baked_level_without_reading_its_sources_and_an_edit_reads_only_its_assets_files() {
    let dir = tempfile::tempdir().unwrap();
    let level = write_level(dir.path(), &LevelSettings { assets: 60, ..Default::default() }).unwrap();
    build_process(dir.path(), &[]);
    // Out of the racy window, so that the record trusts every file's metadata.
    std::thread::sleep(Duration::from_millis(2100));
    build_process(dir.path(), &[]);
    let mut daemon = std::process::Command::new(env!("CARGO_BIN_EXE_cirrus"))
        .args(["-v", "watch", "--debounce-ms", "50"])
        .current_dir(dir.path())
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let (lines, receive) = std::sync::mpsc::channel();
    let stderr = daemon.stderr.take().unwrap();
    std::thread::spawn(move || {
        for line in std::io::BufRead::lines(std::io::BufReader::new(stderr)).map_while(Result::ok) {
            let _ = lines.send(line);
        }
    });
    let next_read_count = || loop {
        let line = receive.recv_timeout(Duration::from_secs(120)).expect("the daemon logs each build");
        if let Some(read) = line.split("source file(s) read").next().filter(|_| line.contains("source file(s) read")) {
            break (line.clone(), read.rsplit(' ').nth(1).unwrap().parse::<usize>().unwrap());
        }
    };
    let (ready, read) = next_read_count();
    assert!(ready.contains("60 asset(s) passed over, 0 looked into"), "{ready}");
    assert_eq!(read, 0, "{ready}");
    std::fs::write(dir.path().join(&level.albedo_maps[3]), noise_png(64, 64, 3, 99)).unwrap();
    let (edit, read) = next_read_count();
    assert!(edit.contains("59 asset(s) passed over, 1 looked into"), "{edit}");
    // The edited map, and the material file and normal map its asset reads.
    assert_eq!(read, 3, "{edit}");
    daemon.kill().unwrap();
    daemon.wait().unwrap();
}
