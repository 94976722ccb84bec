//! The web example (`examples/web`: three.js from npm, GLTFLoader + KTX2Loader, subscribed over
//! WebSocket) driven by headless Chromium (Debian `chromium`, through the DevTools protocol)
//! against a live `cirrus watch`: its screenshot of the bush LOD against cirrus's own preview
//! render of the same view, and how long a leaf-texture edit takes to reach the page.

use std::io::{BufRead, BufReader, Read};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use serde_json::{json, Value};

use crate::support::{decode_png, TempProject};
use crate::watch::Daemon;

/// Preview image side and samples per axis: the page draws `SIZE × SAMPLES` pixels square, and
/// both sides resolve them as cirrus's preview does (a pixel is inside when half its samples are).
const SIZE: u32 = 256;
const SAMPLES: u32 = 4;
/// The view: the first of the preview's 26 directions.
const DIRECTION: [f32; 3] = [-1.0, 0.0, 0.0];

/// `examples/web` with three.js installed (`npm install` once per test run when `.ci/run` has not).
fn web_example() -> PathBuf {
    let folder = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/web");
    if !folder.join("node_modules/three/package.json").is_file() {
        let output = Command::new("npm")
            .args(["install", "--no-audit", "--no-fund", "--silent", "--prefix"])
            .arg(&folder)
            .output()
            .expect("npm runs (the web test needs Node and npm: Debian/Ubuntu `apt-get install nodejs npm`)");
        assert!(output.status.success(), "npm install: {}", String::from_utf8_lossy(&output.stderr));
    }
    folder
}

/// A process killed when dropped.
struct Killed(Child);

impl Drop for Killed {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Starts `command` and returns it with the first line of its output (stdout or stderr) that
/// contains `marker`.
fn start_until(command: &mut Command, marker: &str, from_stderr: bool) -> (Killed, String) {
    let mut child = command.stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().expect("start");
    let stream: Box<dyn Read + Send> =
        if from_stderr { Box::new(child.stderr.take().unwrap()) } else { Box::new(child.stdout.take().unwrap()) };
    let (sender, receiver) = std::sync::mpsc::channel();
    let marker = marker.to_string();
    std::thread::spawn(move || {
        for line in BufReader::new(stream).lines().map_while(Result::ok) {
            if line.contains(&marker) {
                let _ = sender.send(line);
            }
        }
    });
    let line = receiver.recv_timeout(Duration::from_secs(60)).expect("the process printed its address");
    (Killed(child), line)
}

/// The Chromium to run: `CIRRUS_CHROMIUM`, else `chromium`, `chromium-browser`, `google-chrome` or
/// `google-chrome-stable` on the `PATH`, else one installed from npm into `target/tmp/chromium`
/// (`tools/install-chromium.sh`, once), so that the README's test command needs no Chromium
/// installed by hand. Fails naming what to install when none can be had.
fn chromium() -> Command {
    static FOUND: std::sync::OnceLock<Result<(PathBuf, Option<PathBuf>), String>> = std::sync::OnceLock::new();
    let found = FOUND.get_or_init(|| {
        if let Some(path) = std::env::var_os("CIRRUS_CHROMIUM").filter(|path| !path.is_empty()) {
            return Ok((PathBuf::from(path), None));
        }
        let on_path =
            ["chromium", "chromium-browser", "google-chrome", "google-chrome-stable"].iter().find_map(|name| {
                std::env::split_paths(&std::env::var_os("PATH").unwrap_or_default())
                    .map(|folder| folder.join(name))
                    .find(|path| path.is_file())
            });
        if let Some(path) = on_path {
            return Ok((path, None));
        }
        let root = Path::new(env!("CARGO_MANIFEST_DIR"));
        let folder = root.join("target/tmp/chromium");
        if !folder.join("chromium").is_file() {
            let installed = Command::new("bash").arg(root.join("tools/install-chromium.sh")).arg(&folder).output();
            match installed {
                Ok(output) if output.status.success() => {}
                Ok(output) => return Err(String::from_utf8_lossy(&output.stderr).into_owned()),
                Err(error) => return Err(error.to_string()),
            }
        }
        Ok((folder.join("chromium"), Some(folder)))
    });
    match found {
        Ok((path, None)) => Command::new(path),
        Ok((path, Some(folder))) => {
            let mut command = Command::new(path);
            command.env("LD_LIBRARY_PATH", folder.join("lib")).env("FONTCONFIG_PATH", folder.join("fonts"));
            command
        }
        Err(why) => panic!(
            "the web test needs Chromium and found none: no CIRRUS_CHROMIUM, no chromium or google-chrome on the \
             PATH, and installing it from npm (tools/install-chromium.sh, which needs Node, npm and tar) failed: \
             {why}\nInstall it (Debian/Ubuntu: `apt-get install chromium`) or set CIRRUS_CHROMIUM to a Chromium or \
             Chrome executable."
        ),
    }
}

/// A DevTools-protocol session on one page of headless Chromium.
struct Browser {
    _process: Killed,
    socket: tungstenite::WebSocket<TcpStream>,
    session: String,
    next_id: u64,
}

impl Browser {
    fn open(url: &str, size: u32) -> Browser {
        let profile = tempfile::tempdir().unwrap().keep();
        let (process, line) = start_until(
            chromium()
                .args(["--headless=new", "--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader"])
                .args(["--hide-scrollbars", "--remote-debugging-port=0", "--no-first-run"])
                .arg(format!("--window-size={size},{size}"))
                .arg(format!("--user-data-dir={}", profile.display())),
            "DevTools listening on ",
            true,
        );
        let address = line.split("DevTools listening on ").nth(1).unwrap().trim().to_string();
        let host = address.trim_start_matches("ws://").split('/').next().unwrap().to_string();
        let stream = TcpStream::connect(&host).unwrap();
        stream.set_read_timeout(Some(Duration::from_secs(120))).unwrap();
        let (socket, _) = tungstenite::client(address.as_str(), stream).expect("DevTools WebSocket");
        let mut browser = Browser { _process: process, socket, session: String::new(), next_id: 0 };
        let target = browser.call("Target.createTarget", json!({ "url": url }))["targetId"].clone();
        let attached = browser.call("Target.attachToTarget", json!({ "targetId": target, "flatten": true }));
        browser.session = attached["sessionId"].as_str().unwrap().to_string();
        // The page's viewport the size of its canvas (the window's frame takes some of the window).
        let metrics = json!({ "width": size, "height": size, "deviceScaleFactor": 1, "mobile": false });
        browser.call("Emulation.setDeviceMetricsOverride", metrics);
        browser
    }

    /// Sends a DevTools command (to the page once attached) and returns its result.
    fn call(&mut self, method: &str, params: Value) -> Value {
        self.next_id += 1;
        let mut message = json!({ "id": self.next_id, "method": method, "params": params });
        if !self.session.is_empty() {
            message["sessionId"] = json!(self.session);
        }
        self.socket.send(tungstenite::Message::text(message.to_string())).unwrap();
        loop {
            let tungstenite::Message::Text(text) = self.socket.read().expect("a DevTools message") else { continue };
            let reply: Value = serde_json::from_str(text.as_str()).unwrap();
            if reply["id"] == self.next_id {
                assert!(reply["error"].is_null(), "{method}: {reply}");
                return reply["result"].clone();
            }
        }
    }

    /// The value of a JavaScript expression on the page.
    fn evaluate(&mut self, expression: &str) -> Value {
        let result = self.call("Runtime.evaluate", json!({ "expression": expression, "returnByValue": true }));
        result["result"]["value"].clone()
    }

    /// Waits until the page has drawn a revision newer than `after`; gives it.
    fn wait_for_drawn_revision(&mut self, after: i64, limit: Duration) -> i64 {
        let started = Instant::now();
        loop {
            let drawn = self.evaluate("window.cirrus ? window.cirrus.drawnRevision : -1").as_i64().unwrap_or(-1);
            if drawn > after {
                return drawn;
            }
            let errors = self.evaluate("window.cirrus ? window.cirrus.errors : []");
            assert!(errors.as_array().is_none_or(Vec::is_empty), "the page failed to load: {errors}");
            assert!(started.elapsed() < limit, "the page drew nothing after revision {after} in {limit:?}");
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    fn screenshot(&mut self) -> cirrus::texture::Texture {
        let shot = self.call("Page.captureScreenshot", json!({ "format": "png" }));
        decode_png(&decode_base64(shot["data"].as_str().unwrap()))
    }
}

fn decode_base64(text: &str) -> Vec<u8> {
    let value = |byte: u8| -> u32 {
        match byte {
            b'A'..=b'Z' => (byte - b'A') as u32,
            b'a'..=b'z' => (byte - b'a' + 26) as u32,
            b'0'..=b'9' => (byte - b'0' + 52) as u32,
            b'+' => 62,
            _ => 63,
        }
    };
    let bytes: Vec<u8> = text.bytes().filter(|byte| *byte != b'=' && !byte.is_ascii_whitespace()).collect();
    let mut out = Vec::with_capacity(bytes.len() * 3 / 4);
    for chunk in bytes.chunks(4) {
        let bits = chunk.iter().enumerate().fold(0u32, |bits, (index, &byte)| bits | value(byte) << (18 - 6 * index));
        out.extend(&bits.to_be_bytes()[1..chunk.len()]);
    }
    out
}

/// The page's silhouette resolved like cirrus's preview: `SIZE`² pixels, each inside when at
/// least half of its `SAMPLES`² screenshot pixels are not the magenta background.
fn screenshot_silhouette(shot: &cirrus::texture::Texture) -> Vec<bool> {
    let wide = (SIZE * SAMPLES) as usize;
    assert_eq!((shot.width as usize, shot.height as usize), (wide, wide));
    let background = |texel: &[u8]| texel[0] > 200 && texel[1] < 60 && texel[2] > 200;
    (0..(SIZE * SIZE) as usize)
        .map(|pixel| {
            let (x, y) = (pixel % SIZE as usize, pixel / SIZE as usize);
            let mut covered = 0;
            for sy in 0..SAMPLES as usize {
                for sx in 0..SAMPLES as usize {
                    let index = ((y * SAMPLES as usize + sy) * wide + x * SAMPLES as usize + sx) * 4;
                    covered += usize::from(!background(&shot.pixels[index..index + 4]));
                }
            }
            2 * covered >= (SAMPLES * SAMPLES) as usize
        })
        .collect()
}

fn iou(a: &[bool], b: &[bool]) -> f64 {
    let both = a.iter().zip(b).filter(|(a, b)| **a && **b).count();
    let either = a.iter().zip(b).filter(|(a, b)| **a || **b).count();
    both as f64 / either.max(1) as f64
}

/// The bush's source mesh's bounding sphere as the preview frames it
/// (`cirrus::preview::bounding_sphere` of the mesh as the preview draws it).
fn source_sphere(project: &TempProject) -> ([f32; 3], f32) {
    let bytes = project.read("assets/trees/bush_2.obj");
    let (mesh, _) =
        cirrus::mesh::load_mesh(Path::new("bush_2.obj"), &bytes, &Default::default(), Path::new("")).unwrap();
    let uvs = mesh.uvs.clone().unwrap_or_default();
    let tangents = cirrus::mesh::mikktspace_tangents(&mesh.positions, &mesh.normals, &uvs, &mesh.triangles);
    let view = cirrus::preview::mesh_view(&mesh, &tangents, 0.5, |_, _| Ok::<_, ()>(None)).unwrap();
    cirrus::preview::bounding_sphere(&view)
}

/// cirrus's preview render of the baked LOD (`lod.obj` with its decoded KTX2 atlas) from
/// `DIRECTION`: which pixels are inside its silhouette.
fn preview_silhouette(project: &TempProject, center: [f32; 3], radius: f32) -> Vec<bool> {
    use cirrus::kinds::billboard_cloud::lod_preview::{lod_view_mesh, LodFiles};
    let file = |name: &str| (project.path(&format!("baked/bush/{name}")), project.read(&format!("baked/bush/{name}")));
    let files = LodFiles {
        obj: file("lod.obj"),
        albedo_ktx2: file("albedo.ktx2"),
        normal_ktx2: file("normal.ktx2"),
        alpha_cutoff: 0.5,
    };
    let mesh = lod_view_mesh(&files).unwrap();
    let matrix = cirrus::preview::view_projection(center, radius, DIRECTION);
    let gpu = cirrus::gpu::gpu().expect("a GPU adapter (llvmpipe in CI)");
    let samples = gpu.render_view(&mesh, matrix, cirrus::preview::preview_light(), SIZE * SAMPLES).unwrap();
    let view = cirrus::preview::resolve_samples(&samples, SIZE, SAMPLES);
    (0..(SIZE * SIZE) as usize).map(|pixel| view.in_silhouette(pixel)).collect()
}

/// The mean colour of the silhouette's screenshot pixels.
fn mean_colour(shot: &cirrus::texture::Texture) -> [f64; 3] {
    let inside: Vec<&[u8]> =
        shot.pixels.chunks_exact(4).filter(|texel| !(texel[0] > 200 && texel[1] < 60 && texel[2] > 200)).collect();
    [0, 1, 2].map(|channel| inside.iter().map(|texel| texel[channel] as f64).sum::<f64>() / inside.len().max(1) as f64)
}

#[test]
fn the_web_example_draws_the_bush_lod_as_the_preview_does_and_reloads_it_after_a_leaf_edit() {
    let web = web_example();
    let project = TempProject::new(
        r#"Pipeline(source: "assets", output: "baked", assets: [
            BillboardCloud(name: "bush", mesh: "trees/bush_2.obj", atlas: (max_size: 1024)),
        ])"#,
    );
    project.copy_folder(&Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/assets/trees"), "assets/trees");
    let daemon = Daemon::start(&project);
    let mut client = daemon.connect();
    client.subscribe(Some(0));
    let first = client.batch();
    assert!(first["failed"].as_array().unwrap().is_empty(), "{first}");
    let (_server, line) = start_until(
        Command::new("node").arg(web.join("serve.js")).args(["--port", "0", "--root"]).arg(project.root()),
        "cirrus web example: ",
        false,
    );
    let page = line.split_whitespace().find(|word| word.starts_with("http://")).unwrap().to_string();
    let (center, radius) = source_sphere(&project);
    let csv = |values: [f32; 3]| values.map(|value| value.to_string()).join(",");
    let url = format!(
        "{page}?ws=ws://{}/&asset=bush&size={}&center={}&radius={radius}&dir={}",
        daemon.address,
        SIZE * SAMPLES,
        csv(center),
        csv(DIRECTION)
    );
    let mut browser = Browser::open(&url, SIZE * SAMPLES);
    let drawn = browser.wait_for_drawn_revision(0, Duration::from_secs(120));
    let shot = browser.screenshot();
    let page_silhouette = screenshot_silhouette(&shot);
    let preview = preview_silhouette(&project, center, radius);
    let overlap = iou(&page_silhouette, &preview);
    let inside = page_silhouette.iter().filter(|inside| **inside).count();
    println!("web example: the bush LOD in three.js against cirrus's preview: IoU {overlap:.4} ({inside} pixels)");
    assert!(inside > 2000, "the page drew the bush: {inside} pixels");
    assert!(overlap >= 0.97, "IoU {overlap}");

    // A leaf-texture edit (the aspen card tinted red) reaches the page: the next drawn revision
    // shows redder leaves in the same silhouette.
    let before = mean_colour(&shot);
    let leaves = project.path("assets/trees/textures/aspen_color.png");
    let mut tinted = image::open(&leaves).unwrap().into_rgba8();
    for texel in tinted.pixels_mut() {
        texel.0[0] = texel.0[0].saturating_add(120);
        texel.0[1] /= 2;
    }
    let edited = Instant::now();
    tinted.save(&leaves).unwrap();
    let redrawn = browser.wait_for_drawn_revision(drawn, Duration::from_secs(120));
    let latency = edited.elapsed();
    let after_shot = browser.screenshot();
    // Kept for people to look at: the page before and after the edit.
    for (name, shot) in [("web-bush-before.png", &shot), ("web-bush-after.png", &after_shot)] {
        let path = Path::new(env!("CARGO_TARGET_TMPDIR")).join(name);
        std::fs::write(path, cirrus::texture::preview::preview_png(shot)).unwrap();
    }
    let after = mean_colour(&after_shot);
    println!(
        "web example: leaf edit → page drew revision {redrawn} in {:.0} ms; mean colour {before:?} → {after:?}",
        latency.as_secs_f64() * 1000.0
    );
    assert!(after[0] - after[1] > before[0] - before[1] + 10.0, "{before:?} → {after:?}");
    assert!(iou(&screenshot_silhouette(&after_shot), &page_silhouette) >= 0.97);
    // The bound: the bake of the bush (about 3 s on two cores with llvmpipe) and the reload.
    assert!(latency < Duration::from_secs(60), "{latency:?}");
    // The subscribed client kept the daemon's batches flowing to a reader until here.
    drop(client);
}
