//! A wgpu viewer for a baked billboard-cloud LOD, as an engine would load it: `lod.obj` with its
//! KTX2 atlas (BC-decoded, alpha-tested, double-sided), reloaded whenever `cirrus watch` reports a
//! batch that rewrote one of its files.
//!
//!     cargo run --release -- watch                      # in one terminal
//!     cargo run --release --example viewer -- baked/bush --connect 127.0.0.1:7878
//!
//! opens a window (drag to orbit, wheel to zoom, R to reload, 0–9 to show that level of a LOD
//! chain, Esc to quit). For machines without a display, `--headless --screenshot FILE` renders
//! into a PNG instead and rewrites it after every reload; `--reloads N` exits after N reloads,
//! and `--press KEYS` presses keys after loading (scripts and tests use them).

use std::io::{BufRead, BufReader, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use cirrus::gpu::{Gpu, LevelView, WindowSurface};
use clap::Parser;
use glam::Vec3;

#[derive(Parser, Debug, Clone)]
#[command(about = "Shows a baked billboard-cloud LOD and reloads it on cirrus watch events")]
pub struct Options {
    /// The asset's output folder: holds lod.obj, albedo.ktx2, normal.ktx2 and report.json, or a
    /// chain's lod0/, lod1/, … each with its lod.obj and atlas.
    folder: PathBuf,
    /// The level of a LOD chain to show first (keys 0–9 switch).
    #[arg(long, default_value_t = 0)]
    lod: u32,
    /// Keys to press after loading, one character each (e.g. `20`: level 2, then level 0); a
    /// headless viewer writes its screenshot again after each.
    #[arg(long, default_value = "")]
    press: String,
    /// The hot-reload server of `cirrus watch` (see PROTOCOL.md); without it nothing reloads.
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

/// The shown LOD: its mesh, framing, and what the user did to the camera.
struct Scene {
    /// The asset's output folder.
    folder: PathBuf,
    /// The levels of its LOD chain (0: not a chain) and the one shown.
    levels: u32,
    level: u32,
    alpha_cutoff: f32,
    mesh: LevelView,
    center: [f32; 3],
    radius: f32,
    camera: Camera,
}

impl Scene {
    fn load(options: &Options) -> Result<Scene, String> {
        let alpha_cutoff = options.alpha_cutoff.unwrap_or_else(|| report_alpha_cutoff(&options.folder).unwrap_or(0.5));
        let levels =
            (0..10).take_while(|level| options.folder.join(format!("lod{level}/lod.gltf")).is_file()).count() as u32;
        if options.lod > 0 && options.lod >= levels {
            return Err(format!("{} has no LOD level {}", options.folder.display(), options.lod));
        }
        let folder = options.folder.clone();
        let level_folder = level_folder(&folder, levels, options.lod);
        let mesh = cirrus::kinds::billboard_cloud::read_level_view(Path::new("."), &level_folder, alpha_cutoff)
            .map_err(|error| error.to_string())?;
        let (center, radius) = match &mesh {
            LevelView::Mesh(mesh) => cirrus::preview::bounding_sphere(mesh),
            LevelView::Impostor(impostor) => (impostor.center, impostor.radius),
        };
        let camera = Camera { yaw: 0.6, pitch: 0.25, zoom: 1.0 };
        Ok(Scene { folder, levels, level: options.lod, alpha_cutoff, mesh, center, radius, camera })
    }

    /// Loads the shown level's artifacts again; on failure the old mesh stays and the error is
    /// returned.
    fn reload(&mut self) -> Result<(), String> {
        let folder = level_folder(&self.folder, self.levels, self.level);
        self.mesh = cirrus::kinds::billboard_cloud::read_level_view(Path::new("."), &folder, self.alpha_cutoff)
            .map_err(|error| error.to_string())?;
        Ok(())
    }

    /// Whether a batch's files (relative to the asset's folder) touch the shown level.
    fn shows_any(&self, files: &[String]) -> bool {
        let shown = level_folder(Path::new(""), self.levels, self.level);
        // A name without a folder in a chain is the resync marker, which touches every level.
        files
            .iter()
            .any(|file| Path::new(file).parent().is_none_or(|parent| parent.as_os_str().is_empty() || parent == shown))
    }

    /// What a key does: R reloads, a digit shows that level of the chain; `None` for other keys.
    /// The camera stays where it was, so levels compare from the same view.
    fn press(&mut self, key: &str) -> Option<Result<String, String>> {
        if key.eq_ignore_ascii_case("r") {
            return Some(self.reload().map(|()| "reloaded".to_string()));
        }
        let level = key.parse::<u32>().ok().filter(|_| key.len() == 1)?;
        if self.levels == 0 {
            return Some(Err(format!("key {key}: {} is not a LOD chain", self.folder.display())));
        }
        if level >= self.levels {
            return Some(Err(format!("key {key}: no level {level}, the chain has lod0 to lod{}", self.levels - 1)));
        }
        let previous = std::mem::replace(&mut self.level, level);
        Some(match self.reload() {
            Ok(()) => Ok(format!("showing lod{level}")),
            Err(error) => {
                self.level = previous;
                Err(format!("cannot show lod{level}, keeping lod{previous}: {error}"))
            }
        })
    }

    /// A `size`² RGBA8 image of the LOD (mid-grey background, alpha 0 there).
    fn render(&self, gpu: &Gpu, size: u32) -> Result<Vec<u8>, String> {
        let matrix = self.camera.view_projection(self.center, self.radius);
        gpu.render_level_view(&self.mesh, matrix, cirrus::preview::preview_light(), size)
            .map_err(|error| error.to_string())
    }
}

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
    report(write_screenshot(gpu, &scene, options.size, screenshot, "loaded")?);
    for key in options.press.chars() {
        match scene.press(&key.to_string()) {
            Some(Ok(what)) => report(write_screenshot(gpu, &scene, options.size, screenshot, &what)?),
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
                report(format!("r{revision}: {} changed, not the level shown (lod{})", files.join(", "), scene.level))
            }
            ViewerEvent::Reload { revision, files } => match scene.reload() {
                Ok(()) => {
                    reloads += 1;
                    report(write_screenshot(
                        gpu,
                        &scene,
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
fn write_screenshot(gpu: &Gpu, scene: &Scene, size: u32, path: &Path, what: &str) -> Result<String, String> {
    let mut pixels = scene.render(gpu, size)?;
    let covered = pixels.chunks_exact(4).filter(|texel| texel[3] > 0).count();
    for texel in pixels.chunks_exact_mut(4) {
        texel[3] = 255;
    }
    let png = cirrus::texture::preview::preview_png(&cirrus::texture::Texture::new(size, size, pixels));
    cirrus::files::write_if_changed(path, &png).map_err(|error| format!("cannot write {}: {error}", path.display()))?;
    let triangles = match &scene.mesh {
        LevelView::Mesh(mesh) => mesh.batches.iter().map(|(_, vertices)| vertices.len() / 3).sum::<usize>(),
        // One camera-facing quad.
        LevelView::Impostor(_) => 2,
    };
    let coverage = 100.0 * covered as f64 / (size as f64 * size as f64);
    let level = if scene.levels > 0 { format!("lod{} of {}, ", scene.level, scene.levels) } else { String::new() };
    Ok(format!(
        "{what}: {level}{triangles} triangles, {coverage:.1}% of the view covered; screenshot {}",
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
        if !["lod.obj", "lod.mtl", "albedo.ktx2", "normal.ktx2"].contains(&name.as_str()) {
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
        let level = if self.scene.levels > 0 { format!(" lod{}", self.scene.level) } else { String::new() };
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
                (self.report)(format!(
                    "r{revision}: {} changed, not the level shown (lod{})",
                    files.join(", "),
                    self.scene.level
                ));
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
                self.scene.camera.zoom = (self.scene.camera.zoom * 1.1f32.powf(steps)).clamp(0.2, 20.0);
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
