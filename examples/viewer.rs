//! A wgpu viewer for a baked billboard-cloud LOD, as an engine would load it: `lod.obj` with its
//! KTX2 atlas (BC-decoded, alpha-tested, double-sided), reloaded whenever `cirrus watch` reports a
//! batch that rewrote one of its files.
//!
//!     cargo run --release -- watch                      # in one terminal
//!     cargo run --release --example viewer -- baked/bush --connect 127.0.0.1:7878
//!
//! opens a window (drag to orbit, wheel or + and - to zoom, R to reload, Esc to quit). A LOD
//! chain shows the level its `lods.json` switch sizes choose for the size on screen, fading the
//! next one in with a dither over the band below each switch size; 0–9 pin a level, A unpins.
//! For machines without a display, `--headless --screenshot FILE` renders into a PNG instead and
//! rewrites it after every reload; `--reloads N` exits after N reloads, and `--press KEYS`
//! presses keys after loading (scripts and tests use them).

use std::io::{BufRead, BufReader, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use cirrus::gpu::{Gpu, LevelView, WindowSurface};
use cirrus::kinds::billboard_cloud::lod_mesh::{shown_levels, ShownLevels};
use clap::Parser;
use glam::Vec3;
use std::collections::BTreeMap;

#[derive(Parser, Debug, Clone)]
#[command(about = "Shows a baked billboard-cloud LOD and reloads it on cirrus watch events")]
pub struct Options {
    /// The asset's output folder: holds lod.obj, albedo.ktx2, normal.ktx2 and report.json, or a
    /// chain's lod0/, lod1/, … each with its lod.obj and atlas.
    folder: PathBuf,
    /// Pin this level of a LOD chain (keys 0–9 pin another, A unpins); without it a chain with
    /// `lods.json` shows the level its switch sizes choose for the sphere's size on screen,
    /// cross-fading (dithered) over the band below each switch size.
    #[arg(long)]
    lod: Option<u32>,
    /// The camera's zoom: at 1 the bounding sphere fills the image's side (+ and - change it).
    #[arg(long, default_value_t = 1.0)]
    zoom: f32,
    /// Keys to press after loading, one character each (e.g. `20`: level 2, then level 0); a
    /// headless viewer writes its screenshot again after each.
    #[arg(long, default_value = "")]
    press: String,
    /// The hot-reload server of `cirrus watch` (see docs/PROTOCOL.md); without it nothing reloads.
    #[arg(long)]
    connect: Option<String>,
    /// Render into --screenshot instead of a window.
    #[arg(long, requires = "screenshot")]
    headless: bool,
    /// The PNG a headless viewer writes (again after every reload).
    #[arg(long)]
    screenshot: Option<PathBuf>,
    /// Side of the headless image, in pixels.
    #[arg(long, default_value_t = 768)]
    size: u32,
    /// Exit after this many reloads.
    #[arg(long)]
    reloads: Option<u32>,
    /// Alpha-test threshold; by default the `alpha_cutoff` of the asset's report.json.
    #[arg(long)]
    alpha_cutoff: Option<f32>,
}

/// What the connection thread tells the viewer.
#[derive(Debug)]
enum ViewerEvent {
    /// A batch (or a resync) rewrote files of the shown asset.
    Reload { revision: u64, files: Vec<String> },
    /// A batch reported problems with the shown asset; its last good artifacts stay.
    Failed { revision: u64, messages: Vec<String> },
    /// A batch that changed nothing shown here.
    Unrelated { revision: u64 },
}

/// The orbit camera around the LOD's bounding sphere.
#[derive(Clone, Copy, Debug)]
struct Camera {
    yaw: f32,
    pitch: f32,
    zoom: f32,
}

impl Camera {
    fn view_projection(&self, center: [f32; 3], radius: f32) -> [[f32; 4]; 4] {
        let (center, radius) = (Vec3::from(center), radius.max(1e-6));
        let direction =
            Vec3::new(self.pitch.cos() * self.yaw.sin(), self.pitch.sin(), self.pitch.cos() * self.yaw.cos());
        let view = glam::camera::rh::view::look_at_mat4(center + direction * 2.0 * radius, center, Vec3::Y);
        let extent = radius / self.zoom;
        (glam::camera::rh::proj::directx::orthographic(-extent, extent, -extent, extent, 0.5 * radius, 3.5 * radius)
            * view)
            .to_cols_array_2d()
    }
}

/// The shown LOD: its levels (loaded as they are shown), framing, and what the user did to the
/// camera.
struct Scene {
    /// The asset's output folder.
    folder: PathBuf,
    /// The levels of its LOD chain (0: not a chain).
    levels: u32,
    /// Each level's switch size from the chain's `lods.json` (empty without one).
    switch_sizes: Vec<u32>,
    /// The level a key (or `--lod`) pinned; `None`: chosen by the switch sizes as the camera
    /// moves.
    pinned: Option<u32>,
    alpha_cutoff: f32,
    loaded: BTreeMap<u32, LevelView>,
    center: [f32; 3],
    radius: f32,
    camera: Camera,
}

impl Scene {
    fn load(options: &Options) -> Result<Scene, String> {
        let alpha_cutoff = options.alpha_cutoff.unwrap_or_else(|| report_alpha_cutoff(&options.folder).unwrap_or(0.5));
        let levels =
            (0..10).take_while(|level| options.folder.join(format!("lod{level}/lod.gltf")).is_file()).count() as u32;
        if options.lod.is_some_and(|level| level > 0 && level >= levels) {
            return Err(format!("{} has no LOD level {}", options.folder.display(), options.lod.unwrap_or(0)));
        }
        let switch_sizes = if levels > 0 { chain_switch_sizes(&options.folder)? } else { Vec::new() };
        let pinned = match options.lod {
            Some(level) => Some(level),
            None if switch_sizes.len() == levels as usize && levels > 0 => None,
            None => Some(0),
        };
        let camera = Camera { yaw: 0.6, pitch: 0.25, zoom: options.zoom };
        let mut scene = Scene {
            folder: options.folder.clone(),
            levels,
            switch_sizes,
            pinned,
            alpha_cutoff,
            loaded: BTreeMap::new(),
            center: [0.0; 3],
            radius: 1.0,
            camera,
        };
        // The sphere of level 0 frames every level.
        let (center, radius) = match scene.view(0)? {
            LevelView::Mesh(mesh) => cirrus::preview::bounding_sphere(mesh),
            LevelView::Impostor(impostor) => (impostor.center, impostor.radius),
        };
        (scene.center, scene.radius) = (center, radius);
        let shown = scene.shown(options.size);
        scene.view(shown.level)?;
        Ok(scene)
    }

    /// Level `level`, loaded from its artifacts the first time it is asked for.
    fn view(&mut self, level: u32) -> Result<&LevelView, String> {
        if !self.loaded.contains_key(&level) {
            let folder = level_folder(&self.folder, self.levels, level);
            let view = cirrus::kinds::billboard_cloud::read_level_view(Path::new("."), &folder, self.alpha_cutoff)
                .map_err(|error| error.to_string())?;
            self.loaded.insert(level, view);
        }
        Ok(&self.loaded[&level])
    }

    /// The bounding sphere's diameter on a `side`² image, in pixels (the camera is orthographic
    /// and frames the sphere at zoom 1).
    fn pixels_across(&self, side: u32) -> f32 {
        side as f32 * self.camera.zoom
    }

    /// What is shown on a `side`² image: the pinned level, or the chain's choice at the size the
    /// sphere has there.
    fn shown(&self, side: u32) -> ShownLevels {
        match self.pinned {
            Some(level) => ShownLevels { level, fading_into: None },
            None => shown_levels(&self.switch_sizes, self.pixels_across(side)),
        }
    }

    /// Loads every level shown so far again; on failure the old ones stay and the error is
    /// returned.
    fn reload(&mut self) -> Result<(), String> {
        let mut reloaded = BTreeMap::new();
        for &level in self.loaded.keys() {
            let folder = level_folder(&self.folder, self.levels, level);
            let view = cirrus::kinds::billboard_cloud::read_level_view(Path::new("."), &folder, self.alpha_cutoff)
                .map_err(|error| format!("lod{level}: {error}"))?;
            reloaded.insert(level, view);
        }
        self.loaded = reloaded;
        Ok(())
    }

    /// Whether a batch's files (relative to the asset's folder) touch a level shown so far.
    fn shows_any(&self, files: &[String]) -> bool {
        let shown: Vec<PathBuf> =
            self.loaded.keys().map(|&level| level_folder(Path::new(""), self.levels, level)).collect();
        // A name without a folder in a chain is the resync marker, which touches every level.
        files.iter().any(|file| {
            Path::new(file)
                .parent()
                .is_none_or(|parent| parent.as_os_str().is_empty() || shown.iter().any(|folder| parent == folder))
        })
    }

    /// What a key does: R reloads, a digit pins that level of the chain, A lets the switch sizes
    /// choose again, + and - zoom in and out; `None` for other keys. The camera stays where it
    /// was, so levels compare from the same view.
    fn press(&mut self, key: &str) -> Option<Result<String, String>> {
        if key.eq_ignore_ascii_case("r") {
            return Some(self.reload().map(|()| "reloaded".to_string()));
        }
        if key == "+" || key == "-" {
            let factor = if key == "+" { ZOOM_STEP } else { 1.0 / ZOOM_STEP };
            self.camera.zoom = (self.camera.zoom * factor).clamp(MIN_ZOOM, MAX_ZOOM);
            return Some(Ok(format!("zoom {:.3}", self.camera.zoom)));
        }
        if key.eq_ignore_ascii_case("a") {
            if self.switch_sizes.len() != self.levels as usize || self.levels == 0 {
                return Some(Err(format!("key {key}: {} has no lods.json to switch by", self.folder.display())));
            }
            self.pinned = None;
            return Some(Ok("switching by size".to_string()));
        }
        let level = key.parse::<u32>().ok().filter(|_| key.len() == 1)?;
        if self.levels == 0 {
            return Some(Err(format!("key {key}: {} is not a LOD chain", self.folder.display())));
        }
        if level >= self.levels {
            return Some(Err(format!("key {key}: no level {level}, the chain has lod0 to lod{}", self.levels - 1)));
        }
        let previous = self.pinned.map_or("the level chosen by size".to_string(), |level| format!("lod{level}"));
        Some(match self.view(level) {
            Ok(_) => {
                self.pinned = Some(level);
                Ok(format!("showing lod{level}"))
            }
            Err(error) => Err(format!("cannot show lod{level}, keeping {previous}: {error}")),
        })
    }

    /// A `size`² RGBA8 image of what is shown (mid-grey background, alpha 0 there): one level, or
    /// two cross-faded by dithering.
    fn render(&mut self, gpu: &Gpu, size: u32) -> Result<Vec<u8>, String> {
        let matrix = self.camera.view_projection(self.center, self.radius);
        let shown = self.shown(size);
        let render = |scene: &mut Scene, level: u32| -> Result<Vec<u8>, String> {
            let view = scene.view(level)?;
            gpu.render_level_view(view, matrix, cirrus::preview::preview_light(), size)
                .map_err(|error| error.to_string())
        };
        let image = render(self, shown.level)?;
        match shown.fading_into {
            Some((next, share)) => {
                let next_image = render(self, next)?;
                Ok(cirrus::preview::dithered_cross_fade(&image, &next_image, size, share))
            }
            None => Ok(image),
        }
    }
}

/// Each level's switch size from the chain's `lods.json` in `folder` (empty without the file).
fn chain_switch_sizes(folder: &Path) -> Result<Vec<u32>, String> {
    let path = folder.join("lods.json");
    let Ok(bytes) = std::fs::read(&path) else { return Ok(Vec::new()) };
    let document: serde_json::Value =
        serde_json::from_slice(&bytes).map_err(|error| format!("{}: {error}", path.display()))?;
    let levels = document["levels"].as_array().ok_or_else(|| format!("{}: no `levels`", path.display()))?;
    levels
        .iter()
        .map(|level| {
            let size = level["switch_size"].as_u64().and_then(|size| u32::try_from(size).ok());
            size.ok_or_else(|| format!("{}: a level without a `switch_size`", path.display()))
        })
        .collect()
}

/// How much a + or - key zooms, and how far the zoom goes.
const ZOOM_STEP: f32 = 1.25;
const MIN_ZOOM: f32 = 0.005;
const MAX_ZOOM: f32 = 20.0;

/// The folder of a level: the asset's own, or its `lod<N>/` in a chain of `levels` levels.
fn level_folder(folder: &Path, levels: u32, level: u32) -> PathBuf {
    if levels == 0 {
        folder.to_path_buf()
    } else {
        folder.join(format!("lod{level}"))
    }
}

fn report_alpha_cutoff(folder: &Path) -> Option<f32> {
    let report: serde_json::Value = serde_json::from_slice(&std::fs::read(folder.join("report.json")).ok()?).ok()?;
    report["alpha_cutoff"].as_f64().map(|cutoff| cutoff as f32)
}

#[allow(dead_code)] // The integration tests include this file as a module and call `run`.
fn main() -> std::process::ExitCode {
    cirrus::gpu::quiet_wayland_probe();
    let options = Options::parse();
    match run(&options, &mut |line| {
        println!("{line}");
        std::io::stdout().flush().ok();
    }) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("viewer: {error}");
            std::process::ExitCode::FAILURE
        }
    }
}

/// Runs the viewer; `report` receives one line per thing it did (loaded, reloaded, failed).
pub fn run(options: &Options, report: &mut dyn FnMut(String)) -> Result<(), String> {
    let gpu = cirrus::gpu::gpu().map_err(|error| error.to_string())?;
    let scene = Scene::load(options).map_err(|error| format!("cannot load the LOD: {error}"))?;
    if options.headless {
        run_headless(gpu, scene, options, report)
    } else {
        run_window(gpu, scene, options, report)
    }
}

/// Renders into the screenshot, then again after every reload until `--reloads` is reached (or
/// at once when there is no server to follow).
fn run_headless(gpu: &Gpu, mut scene: Scene, options: &Options, report: &mut dyn FnMut(String)) -> Result<(), String> {
    let screenshot = options.screenshot.as_deref().ok_or("--headless needs --screenshot FILE")?;
    report(write_screenshot(gpu, &mut scene, options.size, screenshot, "loaded")?);
    for key in options.press.chars() {
        match scene.press(&key.to_string()) {
            Some(Ok(what)) => report(write_screenshot(gpu, &mut scene, options.size, screenshot, &what)?),
            Some(Err(error)) => report(error),
            None => report(format!("key {key} does nothing")),
        }
    }
    let Some(address) = options.connect.clone() else { return Ok(()) };
    let (sender, receiver) = std::sync::mpsc::channel();
    let folder = options.folder.clone();
    std::thread::spawn(move || follow_server(&address, &folder, &mut |event| sender.send(event).is_ok()));
    let mut reloads = 0;
    while options.reloads.is_none_or(|limit| reloads < limit) {
        let Ok(event) = receiver.recv() else { return Err("the connection thread stopped".into()) };
        match event {
            ViewerEvent::Reload { revision, files } if !scene.shows_any(&files) => {
                let shown = scene.shown(options.size).level;
                report(format!("r{revision}: {} changed, not the level shown (lod{shown})", files.join(", ")))
            }
            ViewerEvent::Reload { revision, files } => match scene.reload() {
                Ok(()) => {
                    reloads += 1;
                    report(write_screenshot(
                        gpu,
                        &mut scene,
                        options.size,
                        screenshot,
                        &format!("reloaded r{revision} ({})", files.join(", ")),
                    )?);
                }
                Err(error) => report(format!("r{revision}: cannot reload, keeping the last LOD: {error}")),
            },
            ViewerEvent::Failed { revision, messages } => report(failed_line(revision, &messages)),
            ViewerEvent::Unrelated { revision } => report(format!("r{revision}: nothing shown here changed")),
        }
    }
    Ok(())
}

fn failed_line(revision: u64, messages: &[String]) -> String {
    format!("r{revision}: the asset failed, keeping the last LOD:\n  {}", messages.join("\n  "))
}

/// Writes an opaque PNG of the scene; returns a line saying what it shows.
fn write_screenshot(gpu: &Gpu, scene: &mut Scene, size: u32, path: &Path, what: &str) -> Result<String, String> {
    let mut pixels = scene.render(gpu, size)?;
    let covered = pixels.chunks_exact(4).filter(|texel| texel[3] > 0).count();
    for texel in pixels.chunks_exact_mut(4) {
        texel[3] = 255;
    }
    let png = cirrus::texture::preview::preview_png(&cirrus::texture::Texture::new(size, size, pixels));
    cirrus::files::write_if_changed(path, &png).map_err(|error| format!("cannot write {}: {error}", path.display()))?;
    let shown = scene.shown(size);
    let triangles = match scene.view(shown.level)? {
        LevelView::Mesh(mesh) => mesh.batches.iter().map(|(_, vertices)| vertices.len() / 3).sum::<usize>(),
        // One camera-facing quad.
        LevelView::Impostor(_) => 2,
    };
    let coverage = 100.0 * covered as f64 / (size as f64 * size as f64);
    let level = match (scene.levels, shown.fading_into) {
        (0, _) => String::new(),
        (levels, None) => format!("lod{} of {levels}, ", shown.level),
        (levels, Some((next, share))) => {
            format!("lod{} fading into lod{next} ({:.0}%) of {levels}, ", shown.level, 100.0 * share)
        }
    };
    let switching = match scene.pinned {
        None => format!("; switching by size, the sphere {:.1} px across", scene.pixels_across(size)),
        Some(_) => String::new(),
    };
    Ok(format!(
        "{what}: {level}{triangles} triangles, {coverage:.1}% of the view covered; screenshot {}{switching}",
        path.display()
    ))
}

/// Subscribes to the daemon and turns its batches into viewer events, reconnecting with `since`
/// when the daemon restarts. Returns when `deliver` says nobody listens any more.
fn follow_server(address: &str, folder: &Path, deliver: &mut dyn FnMut(ViewerEvent) -> bool) {
    let folder = std::fs::canonicalize(folder).unwrap_or_else(|_| folder.to_path_buf());
    let mut since: Option<u64> = None;
    loop {
        match TcpStream::connect(address) {
            Ok(stream) => {
                if !follow_connection(stream, &folder, &mut since, deliver) {
                    return;
                }
                eprintln!("viewer: connection to {address} lost, reconnecting");
            }
            Err(error) => eprintln!("viewer: cannot connect to {address}: {error}"),
        }
        std::thread::sleep(Duration::from_secs(1));
    }
}

/// One connection's events; false when `deliver` refused one.
fn follow_connection(
    mut stream: TcpStream,
    folder: &Path,
    since: &mut Option<u64>,
    deliver: &mut dyn FnMut(ViewerEvent) -> bool,
) -> bool {
    let request = serde_json::json!({ "type": "subscribe", "since": *since });
    if stream.write_all(format!("{request}\n").as_bytes()).is_err() {
        return true;
    }
    // Artifact paths in batches are relative to the pipeline's folder; the shown folder ends with
    // the same components. A chain's files are one folder deeper (`lod1/albedo.ktx2`). A reduced
    // level's map edit rewrites its `lod.mtl` (the copies are named by content).
    let relative = |path: &str| -> Option<String> {
        let path = Path::new(path);
        let (parent, name) = (path.parent()?, path.file_name()?.to_string_lossy().into_owned());
        // The meshes, an impostor's description, and the textures a level draws in any container.
        let texture = name.split_once('.').is_some_and(|(stem, extension)| {
            ["albedo", "normal", "height"].contains(&stem) && ["ktx2", "dds", "pvr"].contains(&extension)
        });
        if !texture && !["lod.obj", "lod.mtl", "impostor.json"].contains(&name.as_str()) {
            return None;
        }
        if folder.ends_with(parent) {
            return Some(name);
        }
        let level = parent.file_name()?.to_string_lossy();
        let is_level = cirrus::kinds::billboard_cloud::levels::level_of_folder(&level).is_some();
        (is_level && folder.ends_with(parent.parent()?)).then(|| format!("{level}/{name}"))
    };
    for line in BufReader::new(stream).lines() {
        let Ok(line) = line else { return true };
        let Ok(event) = serde_json::from_str::<serde_json::Value>(&line) else { continue };
        let revision = event["revision"].as_u64().unwrap_or(0);
        let delivered = match event["type"].as_str() {
            Some("hello") if since.is_none() => {
                // The daemon's current artifacts may be newer than what was loaded at start.
                *since = Some(revision);
                true
            }
            Some("resync") => deliver(ViewerEvent::Reload { revision, files: vec!["everything (resync)".into()] }),
            Some("batch") => {
                *since = Some(revision);
                let mut files: Vec<String> = event["changed"]
                    .as_array()
                    .into_iter()
                    .flatten()
                    .filter_map(|changed| changed["path"].as_str())
                    .chain(event["removed"].as_array().into_iter().flatten().filter_map(|removed| removed.as_str()))
                    .filter_map(relative)
                    .collect();
                files.sort();
                let messages: Vec<String> = event["failed"]
                    .as_array()
                    .into_iter()
                    .flatten()
                    .filter(|failed| failed["asset"].as_str().is_some_and(|asset| folder.ends_with(asset)))
                    .map(|failed| {
                        let line = failed["line"].as_u64().map(|line| format!(":{line}")).unwrap_or_default();
                        format!(
                            "{}{line}: {}",
                            failed["file"].as_str().unwrap_or("?"),
                            failed["message"].as_str().unwrap_or("?")
                        )
                    })
                    .collect();
                if !messages.is_empty() {
                    deliver(ViewerEvent::Failed { revision, messages })
                } else if !files.is_empty() {
                    deliver(ViewerEvent::Reload { revision, files })
                } else {
                    deliver(ViewerEvent::Unrelated { revision })
                }
            }
            _ => true,
        };
        if !delivered {
            return false;
        }
    }
    true
}

/// The windowed viewer: winit's event loop, with reload events from the connection thread.
fn run_window(
    gpu: &'static Gpu,
    scene: Scene,
    options: &Options,
    report: &mut dyn FnMut(String),
) -> Result<(), String> {
    let event_loop = winit::event_loop::EventLoop::<ViewerEvent>::with_user_event().build().map_err(|error| {
        format!("cannot open a window ({error}); on a machine without a display use --headless --screenshot FILE")
    })?;
    if let Some(address) = options.connect.clone() {
        let proxy = event_loop.create_proxy();
        let folder = options.folder.clone();
        std::thread::spawn(move || follow_server(&address, &folder, &mut |event| proxy.send_event(event).is_ok()));
    }
    let mut app =
        WindowApp { gpu, scene, window: None, surface: None, drag_from: None, cursor: (0.0, 0.0), error: None, report };
    event_loop.run_app(&mut app).map_err(|error| error.to_string())?;
    app.error.map_or(Ok(()), Err)
}

struct WindowApp<'a> {
    gpu: &'static Gpu,
    report: &'a mut dyn FnMut(String),
    scene: Scene,
    window: Option<Arc<winit::window::Window>>,
    surface: Option<WindowSurface>,
    /// Where a left-button drag started, with the camera then.
    drag_from: Option<((f64, f64), Camera)>,
    cursor: (f64, f64),
    error: Option<String>,
}

impl WindowApp<'_> {
    fn title(&self, status: &str) -> String {
        let side = self.window.as_ref().map_or(768, |window| {
            let size = window.inner_size();
            size.width.min(size.height).max(1)
        });
        let level = if self.scene.levels > 0 { format!(" lod{}", self.scene.shown(side).level) } else { String::new() };
        format!("cirrus viewer: {}{level} ({status})", self.scene.folder.display())
    }

    fn fail(&mut self, event_loop: &winit::event_loop::ActiveEventLoop, error: String) {
        self.error = Some(error);
        event_loop.exit();
    }
}

impl winit::application::ApplicationHandler<ViewerEvent> for WindowApp<'_> {
    fn resumed(&mut self, event_loop: &winit::event_loop::ActiveEventLoop) {
        if self.window.is_some() {
            return;
        }
        let attributes = winit::window::Window::default_attributes()
            .with_title(self.title("loaded"))
            .with_inner_size(winit::dpi::LogicalSize::new(960.0, 720.0));
        let window = match event_loop.create_window(attributes) {
            Ok(window) => Arc::new(window),
            Err(error) => return self.fail(event_loop, format!("cannot create a window: {error}")),
        };
        let size = window.inner_size();
        match self.gpu.window_surface(window.clone(), size.width, size.height) {
            Ok(surface) => self.surface = Some(surface),
            Err(error) => return self.fail(event_loop, error.to_string()),
        }
        window.request_redraw();
        self.window = Some(window);
    }

    fn user_event(&mut self, _event_loop: &winit::event_loop::ActiveEventLoop, event: ViewerEvent) {
        let status = match event {
            ViewerEvent::Reload { revision, files } if !self.scene.shows_any(&files) => {
                let shown = self.scene.shown(768).level;
                (self.report)(format!("r{revision}: {} changed, not the level shown (lod{shown})", files.join(", ")));
                format!("r{revision}")
            }
            ViewerEvent::Reload { revision, files } => match self.scene.reload() {
                Ok(()) => {
                    (self.report)(format!("reloaded r{revision} ({})", files.join(", ")));
                    format!("r{revision}")
                }
                Err(error) => {
                    (self.report)(format!("r{revision}: cannot reload, keeping the last LOD: {error}"));
                    format!("r{revision}: reload failed")
                }
            },
            ViewerEvent::Failed { revision, messages } => {
                (self.report)(failed_line(revision, &messages));
                format!("r{revision}: FAILED, showing the last good LOD")
            }
            ViewerEvent::Unrelated { revision } => format!("r{revision}"),
        };
        if let Some(window) = &self.window {
            window.set_title(&self.title(&status));
            window.request_redraw();
        }
    }

    fn window_event(
        &mut self,
        event_loop: &winit::event_loop::ActiveEventLoop,
        _id: winit::window::WindowId,
        event: winit::event::WindowEvent,
    ) {
        use winit::event::{ElementState, MouseButton, MouseScrollDelta, WindowEvent};
        use winit::keyboard::{Key, NamedKey};
        let Some(window) = self.window.clone() else { return };
        match event {
            WindowEvent::CloseRequested => event_loop.exit(),
            WindowEvent::KeyboardInput { event, .. } if event.state == ElementState::Pressed => {
                match event.logical_key.as_ref() {
                    Key::Named(NamedKey::Escape) => event_loop.exit(),
                    Key::Character(key) => match self.scene.press(key) {
                        Some(Ok(what)) => {
                            window.set_title(&self.title(&what));
                            window.request_redraw();
                        }
                        Some(Err(error)) => (self.report)(error),
                        None => {}
                    },
                    _ => {}
                }
            }
            WindowEvent::Resized(size) => {
                if let Some(surface) = &mut self.surface {
                    self.gpu.resize_window_surface(surface, size.width, size.height);
                }
                window.request_redraw();
            }
            WindowEvent::MouseInput { state, button: MouseButton::Left, .. } => {
                self.drag_from = (state == ElementState::Pressed).then_some((self.cursor, self.scene.camera));
            }
            WindowEvent::CursorMoved { position, .. } => {
                self.cursor = (position.x, position.y);
                if let Some(((x0, y0), camera)) = self.drag_from {
                    let height = window.inner_size().height.max(1) as f64;
                    self.scene.camera.yaw = camera.yaw - (3.0 * (position.x - x0) / height) as f32;
                    self.scene.camera.pitch =
                        (camera.pitch + (3.0 * (position.y - y0) / height) as f32).clamp(-1.5, 1.5);
                    window.request_redraw();
                }
            }
            WindowEvent::MouseWheel { delta, .. } => {
                let steps = match delta {
                    MouseScrollDelta::LineDelta(_, y) => y,
                    MouseScrollDelta::PixelDelta(position) => position.y as f32 / 40.0,
                };
                self.scene.camera.zoom = (self.scene.camera.zoom * 1.1f32.powf(steps)).clamp(MIN_ZOOM, MAX_ZOOM);
                window.set_title(&self.title(&format!("zoom {:.3}", self.scene.camera.zoom)));
                window.request_redraw();
            }
            WindowEvent::RedrawRequested => {
                let size = window.inner_size();
                let side = size.width.min(size.height).max(1);
                let result = self.scene.render(self.gpu, side).and_then(|image| {
                    let surface = self.surface.as_mut().expect("a surface exists with the window");
                    self.gpu.present_image(surface, &image, side).map_err(|error| error.to_string())
                });
                if let Err(error) = result {
                    self.fail(event_loop, error);
                }
            }
            _ => {}
        }
    }
}
