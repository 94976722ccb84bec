//! The daemon end to end: `cirrus watch` runs as a process on a temporary project, clients
//! connect over TCP, and files are edited the ways editors save them.

use std::collections::{BTreeMap, BTreeSet};
use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use serde_json::Value;

use crate::support::{pattern_png, TempProject};

/// A running `cirrus watch` and everything it printed on stderr.
pub struct Daemon {
    pub child: Child,
    pub address: String,
    pub log: Arc<Mutex<String>>,
}

impl Daemon {
    pub fn start(project: &TempProject) -> Daemon {
        Daemon::start_with(project, &["--listen", "127.0.0.1:0"])
    }

    /// Starts the daemon with `listen` arguments (`--listen ADDR`, or none for the pipeline's).
    pub fn start_with(project: &TempProject, listen: &[&str]) -> Daemon {
        Daemon::start_in_environment(project, listen, &[])
    }

    /// Starts the daemon with `arguments` after `watch` and extra environment variables.
    pub fn start_in_environment(project: &TempProject, arguments: &[&str], environment: &[(&str, String)]) -> Daemon {
        let mut child = Command::new(env!("CARGO_BIN_EXE_cirrus"))
            .arg("watch")
            .args(arguments)
            .envs(environment.iter().map(|(name, value)| (name, value)))
            .args(["--debounce-ms", "100", "-v"])
            .current_dir(project.root())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .expect("start cirrus watch");
        let log = Arc::new(Mutex::new(String::new()));
        let (address_sender, address_receiver) = std::sync::mpsc::channel();
        let stderr = child.stderr.take().expect("stderr");
        let log_writer = log.clone();
        std::thread::spawn(move || {
            for line in BufReader::new(stderr).lines().map_while(Result::ok) {
                if let Some(address) = line.strip_prefix("cirrus watch: hot-reload server on ") {
                    let _ = address_sender.send(address.to_string());
                }
                let mut log = log_writer.lock().unwrap();
                log.push_str(&line);
                log.push('\n');
            }
        });
        let address = address_receiver
            .recv_timeout(Duration::from_secs(60))
            .unwrap_or_else(|_| panic!("daemon did not start: {}", log.lock().unwrap()));
        Daemon { child, address, log }
    }

    pub fn connect(&self) -> Client {
        let stream = TcpStream::connect(&self.address).expect("connect to the daemon");
        stream.set_read_timeout(Some(Duration::from_secs(120))).unwrap();
        let mut client = Client { reader: BufReader::new(stream.try_clone().unwrap()), stream };
        let hello = client.receive();
        assert_eq!((hello["type"].as_str(), hello["protocol"].as_u64()), (Some("hello"), Some(2)), "{hello}");
        client
    }

    pub fn alive(&mut self) -> bool {
        self.child.try_wait().expect("daemon status").is_none()
    }
}

impl Drop for Daemon {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

pub struct Client {
    stream: TcpStream,
    reader: BufReader<TcpStream>,
}

impl Client {
    pub fn send(&mut self, line: &str) {
        self.stream.write_all(line.as_bytes()).expect("send");
        self.stream.write_all(b"\n").expect("send");
    }

    pub fn receive(&mut self) -> Value {
        let mut line = String::new();
        self.reader.read_line(&mut line).expect("a message from the daemon");
        serde_json::from_str(&line).unwrap_or_else(|error| panic!("not JSON ({error}): {line:?}"))
    }

    /// The next `batch` message (other messages in between are skipped).
    pub fn batch(&mut self) -> Value {
        loop {
            let message = self.receive();
            if message["type"] == "batch" {
                return message;
            }
        }
    }

    /// True when nothing arrives within `wait`.
    pub fn quiet_for(&mut self, wait: Duration) -> bool {
        self.stream.set_read_timeout(Some(wait)).unwrap();
        let mut byte = [0u8; 1];
        let quiet = self.reader.get_mut().peek(&mut byte).is_err() && self.reader.buffer().is_empty();
        self.stream.set_read_timeout(Some(Duration::from_secs(120))).unwrap();
        quiet
    }

    pub fn subscribe(&mut self, since: Option<u64>) {
        let since = since.map_or("null".to_string(), |revision| revision.to_string());
        self.send(&format!(r#"{{"type":"subscribe","since":{since}}}"#));
    }
}

/// Two materials from a rule and one listed asset, 32² textures: quick to bake.
pub fn watched_project() -> TempProject {
    let project = TempProject::new(
        r#"Pipeline(source: "assets", output: "baked", assets: [
            Material(name: "rock", material: "rock.mymaterial"),
        ], rules: [(glob: "extra/*.mymaterial", kind: Material)])"#,
    );
    for (index, name) in ["albedo", "normal", "ao", "roughness"].iter().enumerate() {
        project.write(&format!("assets/{name}.png"), pattern_png(32, 32, index as u32));
    }
    project.write(
        "assets/rock.mymaterial",
        "Material $rock {\n  Texture (attrib = \"diffuse\") {string {\"albedo.png\"}}\n  Texture (attrib = \"normal\") {string {\"normal.png\"}}\n  Texture (attrib = \"ao\") {string {\"ao.png\"}}\n  Texture (attrib = \"roughness\") {string {\"roughness.png\"}}\n}\n",
    );
    project.write(
        "assets/extra/moss.mymaterial",
        "Material $moss { Texture (attrib = \"diffuse\") {string {\"../albedo.png\"}} }\n",
    );
    project
}

/// Path → blake3 of every file under the output folder (the cache excluded).
pub fn output_hashes(project: &TempProject) -> BTreeMap<String, String> {
    let mut hashes = BTreeMap::new();
    let mut folders = vec![project.path("baked")];
    while let Some(folder) = folders.pop() {
        for entry in std::fs::read_dir(&folder).into_iter().flatten().flatten() {
            let path = entry.path();
            if path.is_dir() {
                if !path.ends_with(".cirrus") {
                    folders.push(path);
                }
            } else if !path.ends_with("manifest.json") {
                let relative = path.strip_prefix(project.root()).unwrap().to_string_lossy().replace('\\', "/");
                hashes.insert(relative, blake3::hash(&std::fs::read(&path).unwrap()).to_hex().to_string());
            }
        }
    }
    hashes
}

/// The paths of a batch's `changed`, after checking each file is complete and matches its hash.
pub fn changed_paths(project: &TempProject, batch: &Value) -> Vec<String> {
    let mut paths = Vec::new();
    for entry in batch["changed"].as_array().expect("changed") {
        let path = entry["path"].as_str().unwrap();
        let bytes = std::fs::read(project.path(path)).unwrap_or_else(|error| panic!("{path}: {error}"));
        assert_eq!(blake3::hash(&bytes).to_hex().as_str(), entry["hash"].as_str().unwrap(), "{path} matches its hash");
        assert!(path.ends_with(entry["artifact"].as_str().unwrap()), "{entry}");
        assert!(entry["role"].is_string(), "every changed file says what it is: {entry}");
        paths.push(path.to_string());
    }
    paths
}

/// The files whose hashes differ between two snapshots (new files included).
fn differing(before: &BTreeMap<String, String>, after: &BTreeMap<String, String>) -> Vec<String> {
    after.iter().filter(|(path, hash)| before.get(*path) != Some(hash)).map(|(path, _)| path.clone()).collect()
}

fn ao_variant(seed: u32) -> Vec<u8> {
    pattern_png(32, 32, 100 + seed)
}

#[test]
fn edits_become_one_batch_each_naming_exactly_the_changed_artifacts() {
    let project = watched_project();
    let daemon = Daemon::start(&project);
    let mut client = daemon.connect();
    client.subscribe(Some(0));
    let first = client.batch();
    assert_eq!(first["failed"], serde_json::json!([]), "{first}");
    let paths = changed_paths(&project, &first);
    assert!(
        paths.contains(&"baked/rock/rock/mra.ktx2".to_string())
            && paths.contains(&"baked/extra/moss/moss/albedo.ktx2".to_string()),
        "{paths:?}"
    );

    // In place.
    let before = output_hashes(&project);
    project.write("assets/ao.png", ao_variant(1));
    let batch = client.batch();
    let after = output_hashes(&project);
    assert_eq!(changed_paths(&project, &batch), differing(&before, &after));
    assert_eq!(
        changed_paths(&project, &batch),
        ["baked/rock/report.json", "baked/rock/rock/mra.ktx2", "baked/rock/rock/mra.png", "baked/rock/rock/orm.png"]
    );
    assert!(client.quiet_for(Duration::from_millis(600)), "one edit is one batch");

    // Written to a temporary file and renamed over the original.
    let before = after;
    project.write("assets/.ao.png.tmp", ao_variant(2));
    std::fs::rename(project.path("assets/.ao.png.tmp"), project.path("assets/ao.png")).unwrap();
    let batch = client.batch();
    let after = output_hashes(&project);
    assert_eq!(changed_paths(&project, &batch), differing(&before, &after));
    assert!(!batch["changed"].as_array().unwrap().is_empty());
    assert!(client.quiet_for(Duration::from_millis(600)), "a rename save is one batch");

    // Deleted and created again, with a backup file beside it (editors that keep `file~`).
    let before = after;
    std::fs::rename(project.path("assets/normal.png"), project.path("assets/normal.png~")).unwrap();
    project.write("assets/normal.png", pattern_png(32, 32, 77));
    let batch = client.batch();
    assert_eq!(batch["failed"], serde_json::json!([]), "{batch}");
    let after = output_hashes(&project);
    assert_eq!(changed_paths(&project, &batch), differing(&before, &after));
    assert_eq!(
        changed_paths(&project, &batch),
        ["baked/rock/report.json", "baked/rock/rock/normal.ktx2", "baked/rock/rock/normal.png"]
    );
    assert!(client.quiet_for(Duration::from_millis(600)), "a delete + create save is one batch");

    // A touch with identical bytes does nothing at all.
    project.write("assets/normal.png", pattern_png(32, 32, 77));
    assert!(client.quiet_for(Duration::from_millis(800)), "identical bytes make no batch");
}

/// A `state` answer's artifacts: path → hash.
fn state_hashes(state: &Value) -> BTreeMap<String, String> {
    let artifacts = state["artifacts"].as_array().unwrap_or_else(|| panic!("{state}"));
    artifacts
        .iter()
        .map(|entry| (entry["path"].as_str().unwrap().to_string(), entry["hash"].as_str().unwrap().to_string()))
        .collect()
}

#[test]
fn hello_names_the_output_ping_and_state_are_answered_and_each_build_is_announced_before_its_batch() {
    let project = watched_project();
    let daemon = Daemon::start(&project);
    let stream = std::net::TcpStream::connect(&daemon.address).unwrap();
    stream.set_read_timeout(Some(Duration::from_secs(120))).unwrap();
    let mut reader = BufReader::new(stream.try_clone().unwrap());
    let mut hello = String::new();
    reader.read_line(&mut hello).unwrap();
    let hello: Value = serde_json::from_str(&hello).unwrap();
    assert_eq!((hello["protocol"].as_u64(), hello["output"].as_str()), (Some(2), Some("baked")), "{hello}");
    drop((reader, stream));

    let mut client = daemon.connect();
    client.subscribe(Some(0));
    let first = client.batch()["revision"].as_u64().unwrap();
    client.send(r#"{"type":"ping"}"#);
    let pong = client.receive();
    assert_eq!((pong["type"].as_str(), pong["revision"].as_u64()), (Some("pong"), Some(first)), "{pong}");
    // An edit: first `building` (the edited files, the revision before), then its batch.
    project.write("assets/ao.png", ao_variant(5));
    let building = client.receive();
    assert_eq!(building["type"], "building", "{building}");
    assert_eq!(
        (building["revision"].as_u64(), &building["files"]),
        (Some(first), &serde_json::json!(["assets/ao.png"]))
    );
    let batch = client.receive();
    assert_eq!(batch["type"], "batch", "{batch}");
    assert!(batch["revision"].as_u64().unwrap() > first, "{batch}");

    // `state`: every artifact on disk with its hash, as `batch` names them.
    client.send(r#"{"type":"state"}"#);
    let state = client.receive();
    assert_eq!((state["type"].as_str(), state["revision"].as_u64()), (Some("state"), batch["revision"].as_u64()));
    let listed = state_hashes(&state);
    assert_eq!(listed, output_hashes(&project));
    let mra = state["artifacts"].as_array().unwrap().iter().find(|entry| entry["path"] == "baked/rock/rock/mra.ktx2");
    assert_eq!(mra.map(|entry| (&entry["asset"], &entry["artifact"])), Some((&"rock".into(), &"rock/mra.ktx2".into())));
    assert_eq!(mra.map(|entry| &entry["role"]), Some(&"texture".into()));

    // A daemon started on that output lists the same before its first batch is published (from
    // the manifest, which the first wrote once idle).
    wait_for_revision_after(&project, batch["revision"].as_u64().unwrap() - 1);
    drop(client);
    drop(daemon);
    let daemon = Daemon::start(&project);
    let mut client = daemon.connect();
    client.send(r#"{"type":"state"}"#);
    let state = client.receive();
    let relisted = state_hashes(&state);
    assert_eq!(relisted, listed, "{state}");
}

#[test]
fn a_websocket_client_on_the_same_port_gets_the_same_messages_and_a_json_lines_client_its_hello_as_before() {
    // A browser's way in: an HTTP upgrade on the daemon's one port, then one JSON message per
    // text frame each way (hello, ping / pong, subscribe, building, batch, state, errors).
    let project = watched_project();
    let daemon = Daemon::start(&project);
    let stream = TcpStream::connect(&daemon.address).unwrap();
    stream.set_read_timeout(Some(Duration::from_secs(120))).unwrap();
    let (mut socket, response) =
        tungstenite::client(format!("ws://{}/", daemon.address), stream).expect("the WebSocket handshake");
    assert_eq!(response.status(), 101);
    let receive = |socket: &mut tungstenite::WebSocket<TcpStream>| -> Value {
        loop {
            match socket.read().expect("a message") {
                tungstenite::Message::Text(text) => return serde_json::from_str(text.as_str()).unwrap(),
                tungstenite::Message::Close(frame) => panic!("closed: {frame:?}"),
                _ => {}
            }
        }
    };
    let hello = receive(&mut socket);
    assert_eq!((hello["type"].as_str(), hello["protocol"].as_u64()), (Some("hello"), Some(2)), "{hello}");
    let send = |socket: &mut tungstenite::WebSocket<TcpStream>, text: &str| {
        socket.send(tungstenite::Message::text(text)).expect("send");
    };
    send(&mut socket, r#"{"type":"subscribe","since":0}"#);
    let first = loop {
        let message = receive(&mut socket);
        if message["type"] == "batch" {
            break message["revision"].as_u64().unwrap();
        }
    };
    send(&mut socket, r#"{"type":"ping"}"#);
    assert_eq!(receive(&mut socket), serde_json::json!({"type": "pong", "revision": first}));
    send(&mut socket, "not json");
    assert_eq!(receive(&mut socket)["type"], "error");
    // An edit reaches the WebSocket as it reaches a JSON-lines client: building, then the batch.
    let mut lines = daemon.connect();
    lines.subscribe(Some(first));
    project.write("assets/ao.png", ao_variant(7));
    assert_eq!(receive(&mut socket)["type"], "building");
    let batch = receive(&mut socket);
    assert_eq!(batch["type"], "batch", "{batch}");
    assert_eq!(lines.batch(), batch, "the same batch over both");
    send(&mut socket, r#"{"type":"state"}"#);
    let state = receive(&mut socket);
    assert_eq!(state_hashes(&state), output_hashes(&project));
    socket.close(None).unwrap();
    // A JSON-lines client that sends first is served at once (no wait for a WebSocket's
    // request), and the daemon lives on.
    let mut stream = TcpStream::connect(&daemon.address).unwrap();
    stream.set_read_timeout(Some(Duration::from_secs(120))).unwrap();
    let started = Instant::now();
    stream.write_all(b"{\"type\":\"ping\"}\n").unwrap();
    let mut reader = BufReader::new(stream);
    let (mut hello, mut pong) = (String::new(), String::new());
    reader.read_line(&mut hello).unwrap();
    reader.read_line(&mut pong).unwrap();
    assert!(hello.contains("\"hello\"") && pong.contains("\"pong\""), "{hello}{pong}");
    assert!(started.elapsed() < Duration::from_millis(100), "{:?}", started.elapsed());
}

#[test]
fn broken_materials_fail_with_their_line_keep_their_artifacts_and_recover() {
    let project = watched_project();
    let daemon = Daemon::start(&project);
    let mut client = daemon.connect();
    client.subscribe(Some(0));
    client.batch();
    let good = output_hashes(&project);

    let text = String::from_utf8(project.read("assets/rock.mymaterial")).unwrap();
    project.write("assets/rock.mymaterial", text.replace("{string {\"ao.png\"}}", "{float {\"ao.png\"}}"));
    let batch = client.batch();
    let failed = batch["failed"].as_array().unwrap();
    assert_eq!(failed.len(), 1, "{batch}");
    assert_eq!(failed[0]["asset"], "rock");
    assert_eq!(failed[0]["file"], "assets/rock.mymaterial");
    assert_eq!(failed[0]["line"], 4, "{batch}");
    assert!(failed[0]["message"].as_str().unwrap().contains("float"), "{batch}");
    assert_eq!(output_hashes(&project), good, "the last good artifacts stay");

    project.write("assets/rock.mymaterial", text);
    let batch = client.batch();
    assert_eq!(batch["failed"], serde_json::json!([]), "recovered: {batch}");
    assert_eq!(batch["changed"], serde_json::json!([]), "same artifacts as before: {batch}");

    // A new file matching a rule becomes an asset.
    project.write(
        "assets/extra/lichen.mymaterial",
        "Material $lichen { Texture (attrib = \"diffuse\") {string {\"../ao.png\"}} }\n",
    );
    let batch = client.batch();
    let paths = changed_paths(&project, &batch);
    assert!(paths.contains(&"baked/extra/lichen/lichen/albedo.ktx2".to_string()), "{paths:?}");

    // A deleted input fails its asset, and its return recovers it.
    let albedo = project.read("assets/albedo.png");
    std::fs::remove_file(project.path("assets/albedo.png")).unwrap();
    let batch = client.batch();
    let mut failed: Vec<&str> =
        batch["failed"].as_array().unwrap().iter().map(|entry| entry["asset"].as_str().unwrap_or("")).collect();
    failed.sort();
    assert_eq!(failed, ["extra/moss", "rock"], "{batch}");
    assert!(batch["failed"][0]["message"].as_str().unwrap().contains("albedo.png"), "{batch}");
    project.write("assets/albedo.png", &albedo);
    let batch = client.batch();
    assert_eq!(batch["failed"], serde_json::json!([]), "{batch}");

    // Editing pipeline.ron reconfigures the running daemon: the rock asset becomes DDS.
    let pipeline = String::from_utf8(project.read("pipeline.ron")).unwrap();
    project.write(
        "pipeline.ron",
        pipeline
            .replace(r#"material: "rock.mymaterial")"#, r#"material: "rock.mymaterial", encode: (container: Dds))"#),
    );
    let batch = client.batch();
    let paths = changed_paths(&project, &batch);
    assert!(paths.contains(&"baked/rock/rock/albedo.dds".to_string()), "{paths:?}");
    assert!(batch["removed"].as_array().unwrap().iter().any(|path| path == "baked/rock/rock/albedo.ktx2"), "{batch}");
    assert!(!project.path("baked/rock/rock/albedo.ktx2").exists());

    // A broken pipeline.ron is reported with its position; the daemon keeps the last good one.
    project.write("pipeline.ron", "Pipeline(source: \"assets\",\n  output: 12)\n");
    let batch = client.batch();
    assert_eq!(batch["failed"][0]["stage"], "config", "{batch}");
    assert_eq!(batch["failed"][0]["file"], "pipeline.ron", "{batch}");
    assert_eq!(batch["failed"][0]["line"], 2, "{batch}");
    project.write("assets/ao.png", ao_variant(5));
    let batch = client.batch();
    assert!(changed_paths(&project, &batch).contains(&"baked/rock/rock/mra.dds".to_string()), "{batch}");
}

/// The manifest's revision once it passes `after` (the daemon writes it with every build).
fn wait_for_revision_after(project: &TempProject, after: u64) -> u64 {
    let deadline = Instant::now() + Duration::from_secs(120);
    loop {
        let revision = std::fs::read(project.path("baked/manifest.json"))
            .ok()
            .and_then(|bytes| serde_json::from_slice::<Value>(&bytes).ok())
            .and_then(|manifest| manifest["revision"].as_u64())
            .unwrap_or(0);
        if revision > after {
            return revision;
        }
        assert!(Instant::now() < deadline, "no build after revision {after}");
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[test]
fn reconnecting_with_since_replays_the_missed_batches() {
    let project = watched_project();
    let daemon = Daemon::start(&project);
    let mut client = daemon.connect();
    client.subscribe(Some(0));
    let seen = client.batch()["revision"].as_u64().unwrap();
    drop(client);

    project.write("assets/ao.png", ao_variant(1));
    let first_missed = wait_for_revision_after(&project, seen);
    project.write("assets/roughness.png", ao_variant(2));
    let second_missed = wait_for_revision_after(&project, first_missed);

    let mut client = daemon.connect();
    client.subscribe(Some(seen));
    let replayed = [client.batch(), client.batch()];
    assert_eq!(replayed.each_ref().map(|batch| batch["revision"].as_u64().unwrap()), [first_missed, second_missed]);
    // The older batch names files that the newer one replaced; the newer one matches the disk.
    assert!(
        replayed[0]["changed"].as_array().unwrap().iter().any(|entry| entry["path"] == "baked/rock/rock/mra.png"),
        "{}",
        replayed[0]
    );
    assert!(changed_paths(&project, &replayed[1]).contains(&"baked/rock/rock/mra.png".to_string()), "{}", replayed[1]);
    assert!(client.quiet_for(Duration::from_millis(300)), "nothing else replayed");

    // A client that saw everything gets nothing again.
    let mut current = daemon.connect();
    current.subscribe(Some(second_missed));
    assert!(current.quiet_for(Duration::from_millis(300)));
}

#[test]
fn garbage_and_abrupt_clients_do_not_harm_the_daemon() {
    let project = watched_project();
    let mut daemon = Daemon::start(&project);
    let mut observer = daemon.connect();
    observer.subscribe(Some(0));
    observer.batch();

    let mut rude = daemon.connect();
    rude.send("this is not json");
    assert_eq!(rude.receive()["type"], "error");
    rude.send(r#"{"type":"launch_missiles"}"#);
    assert_eq!(rude.receive()["type"], "error");
    rude.send(&"x".repeat(200_000));
    let reply = rude.receive();
    assert!(reply["message"].as_str().unwrap().contains("longer than"), "{reply}");
    rude.send(r#"{"type":"graph","format":"json"}"#);
    let graph = rude.receive();
    assert_eq!(graph["type"], "graph", "the same connection still works: {graph}");
    assert!(graph["graph"]["nodes"].as_array().unwrap().len() > 10);
    // Half a line, then gone; a client that vanishes without reading.
    rude.stream.write_all(br#"{"type":"subscr"#).unwrap();
    drop(rude);
    let mut silent = TcpStream::connect(&daemon.address).unwrap();
    silent.write_all(b"\xff\xfe\x00garbage without newline").unwrap();
    let mut buffer = [0u8; 16];
    let _ = silent.read(&mut buffer);
    drop(silent);

    project.write("assets/ao.png", ao_variant(9));
    let batch = observer.batch();
    assert!(!batch["changed"].as_array().unwrap().is_empty(), "{batch}");
    assert!(daemon.alive(), "daemon alive; log:\n{}", daemon.log.lock().unwrap());
}

#[test]
fn a_burst_of_300_new_files_becomes_a_few_batches_and_loses_none() {
    let project = watched_project();
    let daemon = Daemon::start(&project);
    let mut client = daemon.connect();
    client.subscribe(Some(0));
    client.batch();
    // A branch checkout: 300 new material files at once, each its own asset under the rule.
    for index in 0..300 {
        project.write(
            &format!("assets/extra/burst_{index:03}.mymaterial"),
            format!("Material $m {{ Texture (attrib = \"diffuse\") {{string {{\"../albedo.png\"}}}} Param (attrib = \"roughness\") {{float {{{}}}}} }}\n", index as f32 / 300.0),
        );
    }
    let mut reports = BTreeSet::new();
    let mut batches = 0;
    while reports.len() < 300 {
        let batch = client.batch();
        batches += 1;
        assert_eq!(batch["failed"], serde_json::json!([]), "{batch}");
        for path in changed_paths(&project, &batch) {
            if path.starts_with("baked/extra/burst_") && path.ends_with("/report.json") {
                reports.insert(path);
            }
        }
        assert!(batches <= 10, "300 files became more than 10 batches");
    }
    assert!(client.quiet_for(Duration::from_millis(500)));
    assert!(project.path("baked/extra/burst_299/m/mra.ktx2").exists());
}

#[test]
fn an_edit_during_a_build_cancels_it_and_the_next_build_uses_the_newest_bytes() {
    let project = watched_project();
    // A large albedo, so that its encode is still running when the second edit lands.
    project.write("assets/albedo.png", pattern_png(1024, 1024, 1));
    let daemon = Daemon::start(&project);
    let mut client = daemon.connect();
    client.subscribe(Some(0));
    client.batch();

    project.write("assets/albedo.png", pattern_png(1024, 1024, 2));
    std::thread::sleep(Duration::from_millis(250));
    let newest = pattern_png(1024, 1024, 3);
    project.write("assets/albedo.png", &newest);
    let mut last = client.batch();
    while !client.quiet_for(Duration::from_millis(1500)) {
        last = client.batch();
    }
    let log = daemon.log.lock().unwrap().clone();
    assert!(log.contains("build cancelled by a newer edit"), "the first build was cancelled:\n{log}");

    // What the daemon wrote last equals a fresh bake of the newest bytes.
    let reference = watched_project();
    reference.write("assets/albedo.png", &newest);
    let mut cirrus = reference.open();
    assert!(crate::support::build(&mut cirrus).all_ok());
    let expected = reference.read("baked/rock/rock/albedo.ktx2");
    assert_eq!(project.read("baked/rock/rock/albedo.ktx2"), expected);
    let albedo =
        last["changed"].as_array().unwrap().iter().find(|entry| entry["path"] == "baked/rock/rock/albedo.ktx2");
    assert_eq!(
        albedo.map(|entry| entry["hash"].clone()),
        Some(serde_json::json!(blake3::hash(&expected).to_hex().to_string())),
        "{last}"
    );
}

#[test]
fn the_viewer_keeps_the_last_good_lod_on_failure_and_reloads_on_a_texture_edit() {
    let project = crate::billboard_cloud::bake::tree_project();
    let daemon = Daemon::start(&project);
    let mut client = daemon.connect();
    client.subscribe(Some(0));
    assert!(client.batch()["failed"].as_array().unwrap().is_empty());

    let screenshot = project.path("shot.png");
    let arguments = ["--size", "192", "--reloads", "1", "--connect", &daemon.address];
    let options = crate::support::headless_viewer_options(&arguments, &screenshot, &project.path("baked/tree"));
    let lines = Arc::new(Mutex::new(Vec::<String>::new()));
    let viewer = {
        let lines = lines.clone();
        std::thread::spawn(move || crate::viewer::run(&options, &mut |line| lines.lock().unwrap().push(line)))
    };
    let wait_for_lines = |count: usize| {
        let start = Instant::now();
        while lines.lock().unwrap().len() < count {
            assert!(start.elapsed() < Duration::from_secs(120), "viewer said only {:?}", lines.lock().unwrap());
            std::thread::sleep(Duration::from_millis(20));
        }
    };
    wait_for_lines(1);
    // The viewer subscribes after loading; give it a moment to be listening before editing.
    std::thread::sleep(Duration::from_millis(500));
    let first = crate::support::decode_png(&std::fs::read(&screenshot).unwrap());

    // A broken mesh fails the asset: the viewer reports it and keeps showing the last LOD.
    let obj = project.read("assets/tree.obj");
    project.write("assets/tree.obj", "v 0 0 0\nf 1 2 3\n");
    client.batch();
    wait_for_lines(2);
    // Restored, the artifacts are byte for byte what they were: nothing to reload.
    project.write("assets/tree.obj", &obj);
    client.batch();
    wait_for_lines(3);
    // A bark texture edit rewrites the atlas: the viewer reloads and renders again.
    project.write("assets/bark.png", pattern_png(32, 32, 9));
    let batch = client.batch();
    let start = Instant::now();
    while !viewer.is_finished() {
        assert!(start.elapsed() < Duration::from_secs(120), "the viewer did not reload: {:?}", lines.lock().unwrap());
        std::thread::sleep(Duration::from_millis(20));
    }
    let result = viewer.join().expect("viewer thread");
    let lines = lines.lock().unwrap().clone();
    assert_eq!(result, Ok(()), "{lines:?}");
    let revision = batch["revision"].as_u64().unwrap();
    assert_eq!(lines.len(), 4, "{lines:?}");
    let numbers = |line: &str| -> (usize, f64) {
        let (triangles, rest) = line.split_once(": ").unwrap().1.split_once(" triangles, ").unwrap();
        (triangles.parse().unwrap(), rest.split('%').next().unwrap().parse().unwrap())
    };
    assert!(lines[0].starts_with("loaded: "), "{lines:?}");
    assert!(lines[1].contains(": the asset failed, keeping the last LOD:\n  assets/tree.obj"), "{lines:?}");
    assert!(lines[2].ends_with(": nothing shown here changed"), "{lines:?}");
    assert!(lines[3].starts_with(&format!("reloaded r{revision} (albedo.ktx2")), "{lines:?}");
    let ((triangles, coverage), (reloaded_triangles, reloaded_coverage)) = (numbers(&lines[0]), numbers(&lines[3]));
    let obj = String::from_utf8(project.read("baked/tree/lod.obj")).unwrap();
    assert_eq!(triangles, obj.lines().filter(|line| line.starts_with("f ")).count(), "every face of lod.obj is shown");
    assert_eq!(reloaded_triangles, triangles, "{lines:?}");
    // Only the colour changed; BC7 may move a few alpha-tested edge texels.
    assert!(
        coverage > 5.0 && (reloaded_coverage - coverage).abs() < 0.5,
        "a texture edit keeps the silhouette: {lines:?}"
    );
    let second = crate::support::decode_png(&std::fs::read(&screenshot).unwrap());
    let differing = first.pixels.chunks_exact(4).zip(second.pixels.chunks_exact(4)).filter(|(a, b)| a != b).count();
    assert!(differing > 100, "the reloaded bark shows in the screenshot ({differing} pixels differ)");
}

#[test]
fn a_texture_added_under_an_atlas_glob_joins_the_atlas_while_watching_and_leaves_when_deleted() {
    let project = TempProject::new(
        r#"Pipeline(source: "assets", output: "baked", assets: [
            Atlas(name: "icons", textures: ["icons/**/*.png"], pack: (max_size: 256)),
        ])"#,
    );
    project.write("assets/icons/a.png", pattern_png(16, 16, 1));
    let daemon = Daemon::start(&project);
    let mut client = daemon.connect();
    client.subscribe(Some(0));
    let first = client.batch();
    assert_eq!(first["failed"], serde_json::json!([]), "{first}");
    let entries = |project: &TempProject| -> Vec<String> {
        let table: Value = serde_json::from_slice(&project.read("baked/icons/atlas.json")).unwrap();
        table["entries"].as_array().unwrap().iter().map(|entry| entry["name"].as_str().unwrap().to_string()).collect()
    };
    assert_eq!(entries(&project), ["icons/a.png"]);
    // In a new folder, too: `**` crosses folders.
    project.write("assets/icons/more/b.png", pattern_png(24, 8, 2));
    let batch = client.batch();
    assert!(changed_paths(&project, &batch).contains(&"baked/icons/atlas.json".to_string()), "{batch}");
    assert_eq!(entries(&project), ["icons/a.png", "icons/more/b.png"]);
    std::fs::remove_file(project.path("assets/icons/a.png")).unwrap();
    let batch = client.batch();
    assert_eq!(batch["failed"], serde_json::json!([]), "{batch}");
    assert_eq!(entries(&project), ["icons/more/b.png"]);
}

/// Every file under the output folder (the cache and the manifest left out), reports without
/// their timings: what a clean build of the same sources must write too.
fn comparable_outputs(root: &std::path::Path) -> BTreeMap<String, String> {
    let mut outputs = BTreeMap::new();
    let baked = root.join("baked");
    if !baked.exists() {
        return outputs;
    }
    for path in crate::support::files_under(&baked) {
        let relative = path.strip_prefix(root).unwrap().to_string_lossy().replace('\\', "/");
        if relative.starts_with("baked/.cirrus/") || relative == "baked/manifest.json" {
            continue;
        }
        let bytes = std::fs::read(&path).unwrap();
        let value = if relative.ends_with("report.json") {
            let mut report: Value = serde_json::from_slice(&bytes).unwrap();
            report.as_object_mut().map(|object| object.remove("stage_ms"));
            report.to_string()
        } else {
            blake3::hash(&bytes).to_hex().to_string()
        };
        outputs.insert(relative, value);
    }
    outputs
}

#[test]
fn after_a_random_burst_of_creates_edits_deletes_and_renames_the_daemon_writes_what_a_clean_build_writes() {
    // Materials under a rule, each naming textures that may not exist yet: an edit of a texture
    // that no asset read yet used to be lost when it came during the batch that first read it
    // (30 materials created, their textures rewritten 0.3 s later: all 30 stale for good).
    let project = TempProject::new(
        r#"Pipeline(source: "assets", output: "baked", rules: [(glob: "extra/*.mymaterial", kind: Material)])"#,
    );
    let material = |texture: usize, other: usize| {
        format!(
            "Material $m {{\n  Texture (attrib = \"diffuse\") {{string {{\"../tex/t{texture}.png\"}}}}\n  Texture (attrib = \
             \"normal\") {{string {{\"../tex/t{other}.png\"}}}}\n}}\n"
        )
    };
    for index in 0..4 {
        project.write(&format!("assets/tex/t{index}.png"), pattern_png(16, 16, index as u32));
    }
    // Textures no asset reads yet, large enough that the batch reading them is still baking
    // when they are rewritten.
    for index in 0..30 {
        project.write(&format!("assets/tex/t{}.png", 100 + index), pattern_png(256, 256, 300 + index as u32));
    }
    project.write("assets/extra/m0.mymaterial", material(0, 1));
    let daemon = Daemon::start(&project);
    let mut client = daemon.connect();
    client.subscribe(Some(0));
    client.batch();
    // First the issue's sequence: 30 new materials over 30 textures no asset reads, the
    // textures rewritten 0.3 s later.
    for index in 0..30 {
        project.write(&format!("assets/extra/new{index}.mymaterial"), material(100 + index, 100 + index));
    }
    std::thread::sleep(Duration::from_millis(300));
    for index in 0..30 {
        project.write(&format!("assets/tex/t{}.png", 100 + index), pattern_png(256, 256, 500 + index as u32));
    }
    // Then a random burst over 40 material and 40 texture names (a fixed seed: the same every run).
    let mut seed = 0x2545_f491_4f6c_dd1du64;
    let mut next = |bound: usize| {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed % bound as u64) as usize
    };
    for step in 0..600 {
        let (material_name, texture) = (format!("assets/extra/m{}.mymaterial", next(40)), next(40));
        match next(10) {
            0..=2 => project.write(&material_name, material(texture, next(40))),
            3..=5 => project.write(&format!("assets/tex/t{texture}.png"), pattern_png(16, 16, step as u32)),
            6 => {
                let _ = std::fs::remove_file(project.path(&material_name));
            }
            7 => {
                let _ = std::fs::remove_file(project.path(&format!("assets/tex/t{texture}.png")));
            }
            8 => {
                let to = format!("assets/extra/m{}.mymaterial", next(40));
                let _ = std::fs::rename(project.path(&material_name), project.path(&to));
            }
            _ => {
                let to = format!("assets/tex/t{}.png", next(40));
                let _ = std::fs::rename(project.path(&format!("assets/tex/t{texture}.png")), project.path(&to));
            }
        }
        if next(8) == 0 {
            std::thread::sleep(Duration::from_millis(next(40) as u64));
        }
    }
    // Settled: no batch in flight (a `building` not yet followed by its `batch`: a batch of 50
    // assets takes 3 to 4 s on a busy 2-core machine, with no message meanwhile) and no message
    // for 3 s.
    let started = Instant::now();
    let mut building = false;
    while building || !client.quiet_for(Duration::from_secs(3)) {
        match client.receive()["type"].as_str() {
            Some("building") => building = true,
            Some("batch") => building = false,
            _ => {}
        }
        assert!(started.elapsed() < Duration::from_secs(180), "the daemon never settled");
    }
    let watched = comparable_outputs(project.root());
    let clean = TempProject::new(&String::from_utf8(project.read("pipeline.ron")).unwrap());
    clean.copy_folder(&project.path("assets"), "assets");
    let summary = crate::support::build(&mut clean.open());
    // An asset that fails keeps its last good outputs in the daemon, and has none in a clean
    // build: only the others compare.
    let failed: Vec<String> = summary
        .assets
        .iter()
        .filter(|asset| !asset.errors.is_empty())
        .map(|asset| format!("baked/extra/{}/", asset.name.trim_start_matches("extra/")))
        .collect();
    let compared = |outputs: BTreeMap<String, String>| -> BTreeMap<String, String> {
        outputs.into_iter().filter(|(path, _)| !failed.iter().any(|folder| path.starts_with(folder))).collect()
    };
    let (watched, expected) = (compared(watched), compared(comparable_outputs(clean.root())));
    for index in 0..30 {
        assert!(expected.contains_key(&format!("baked/extra/new{index}/report.json")), "new{index} bakes");
    }
    let missing: Vec<&String> = expected.keys().filter(|path| !watched.contains_key(*path)).collect();
    let extra: Vec<&String> = watched.keys().filter(|path| !expected.contains_key(*path)).collect();
    let differing: Vec<&String> = expected
        .iter()
        .filter(|(path, value)| watched.get(*path).is_some_and(|other| other != *value))
        .map(|(path, _)| path)
        .collect();
    assert!(
        missing.is_empty() && extra.is_empty() && differing.is_empty(),
        "the daemon's output differs from a clean build's ({} files): missing {missing:?}, extra {extra:?}, \
         differing {differing:?}\n{}",
        expected.len(),
        daemon.log.lock().unwrap().clone()
    );
    assert!(expected.len() > 100, "{} files", expected.len());
}
