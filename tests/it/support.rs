//! Test support: temporary projects with generated textures, builds through the library and the
//! binary, and readers for the written containers.

use std::path::{Path, PathBuf};

use cirrus::pipeline::load_pipeline;
use cirrus::project::{BuildOptions, Project, ProjectOptions};
use cirrus::summary::BuildSummary;
use cirrus::texture::Texture;

/// Every file under `folder`, at any depth, sorted.
pub fn files_under(folder: &Path) -> Vec<PathBuf> {
    let mut files = Vec::new();
    let mut folders = vec![folder.to_path_buf()];
    while let Some(current) = folders.pop() {
        for entry in std::fs::read_dir(&current).unwrap().flatten() {
            let path = entry.path();
            if path.is_dir() {
                folders.push(path);
            } else {
                files.push(path);
            }
        }
    }
    files.sort();
    files
}

/// A project in a temporary folder: `pipeline.ron` at its root, sources under `assets/`.
pub struct TempProject {
    pub dir: tempfile::TempDir,
}

impl TempProject {
    pub fn new(pipeline: &str) -> TempProject {
        let dir = tempfile::tempdir().expect("temporary folder");
        std::fs::write(dir.path().join("pipeline.ron"), pipeline).expect("write pipeline");
        TempProject { dir }
    }

    pub fn root(&self) -> &Path {
        self.dir.path()
    }

    pub fn path(&self, relative: &str) -> PathBuf {
        self.dir.path().join(relative)
    }

    pub fn write(&self, relative: &str, bytes: impl AsRef<[u8]>) {
        let path = self.path(relative);
        std::fs::create_dir_all(path.parent().expect("has a folder")).expect("create folder");
        std::fs::write(path, bytes).expect("write file");
    }

    /// Copies every file under `from` (at any depth) to the folder `to` of the project.
    pub fn copy_folder(&self, from: &Path, to: &str) {
        for file in files_under(from) {
            let relative = file.strip_prefix(from).unwrap().to_string_lossy().to_string();
            self.write(&format!("{to}/{relative}"), std::fs::read(&file).unwrap());
        }
    }

    pub fn read(&self, relative: &str) -> Vec<u8> {
        std::fs::read(self.path(relative)).unwrap_or_else(|error| panic!("read {relative}: {error}"))
    }

    pub fn open(&self) -> Project {
        let config = load_pipeline(&self.path("pipeline.ron")).expect("valid pipeline");
        Project::open(config, ProjectOptions::default())
    }

    /// Runs the `cirrus` binary in the project folder.
    pub fn run_cli(&self, arguments: &[&str]) -> std::process::Output {
        std::process::Command::new(env!("CARGO_BIN_EXE_cirrus"))
            .args(arguments)
            .current_dir(self.root())
            .output()
            .expect("run cirrus")
    }
}

pub fn build(project: &mut Project) -> BuildSummary {
    project.build(&BuildOptions::default(), &|_| {}).expect("build runs")
}

/// A deterministic RGBA8 PNG: smooth gradients plus a pattern, seeded by `seed`.
pub fn pattern_png(width: u32, height: u32, seed: u32) -> Vec<u8> {
    let mut pixels = Vec::with_capacity((width * height * 4) as usize);
    for y in 0..height {
        for x in 0..width {
            let fx = x as f32 / width as f32;
            let fy = y as f32 / height as f32;
            let s = seed as f32;
            let r = 0.5 + 0.4 * (fx * 6.0 + s).sin() * (fy * 3.0).cos();
            let g = 0.5 + 0.4 * (fy * 5.0 + s * 0.7).sin();
            let b = 0.5 + 0.4 * ((fx + fy) * 4.0 + s * 1.3).cos();
            pixels.extend_from_slice(&[r, g, b].map(|c| (c * 255.0) as u8));
            pixels.push(255);
        }
    }
    png_bytes(width, height, &pixels)
}

/// An RGBA8 PNG with an alpha-tested mask: soft-edged discs and thin semi-opaque lines (the thin
/// features that plain box-filtered mips lose).
pub fn cutout_png(width: u32, height: u32) -> Vec<u8> {
    let mut pixels = Vec::with_capacity((width * height * 4) as usize);
    for y in 0..height {
        for x in 0..width {
            let (cx, cy) = ((x % 32) as f32 - 15.5, (y % 32) as f32 - 15.5);
            let disc = ((9.0 - (cx * cx + cy * cy).sqrt()) / 3.0 + 0.5).clamp(0.0, 1.0);
            let varying = 0.6 + 0.3 * ((x * 7 + y * 13) % 17) as f32 / 16.0;
            let line = if x % 32 == 30 || y % 16 == 7 { varying } else { 0.0 };
            let alpha = (disc.max(line) * 255.0) as u8;
            pixels.extend_from_slice(&[40, (120 + x % 100) as u8, 30, alpha]);
        }
    }
    png_bytes(width, height, &pixels)
}

pub fn png_bytes(width: u32, height: u32, rgba: &[u8]) -> Vec<u8> {
    let mut bytes = Vec::new();
    image::ImageEncoder::write_image(
        image::codecs::png::PngEncoder::new(&mut bytes),
        rgba,
        width,
        height,
        image::ExtendedColorType::Rgba8,
    )
    .expect("encode PNG");
    bytes
}

pub fn decode_png(bytes: &[u8]) -> Texture {
    let image = image::load_from_memory(bytes).expect("decode PNG").into_rgba8();
    Texture::new(image.width(), image.height(), image.into_raw())
}

/// The fields of a KTX2 file that tests check.
#[derive(Debug)]
pub struct Ktx2 {
    pub vk_format: u32,
    pub width: u32,
    pub height: u32,
    pub supercompression: u32,
    /// (offset, length, uncompressed length) per level, level 0 first.
    pub levels: Vec<(u64, u64, u64)>,
    pub dfd: Vec<u8>,
    /// The key/value data, in file order.
    pub key_values: Vec<(String, String)>,
}

pub fn read_ktx2(bytes: &[u8]) -> Ktx2 {
    assert_eq!(&bytes[..12], &cirrus::texture::container::KTX2_IDENTIFIER, "KTX2 identifier");
    let u32_at = |offset: usize| u32::from_le_bytes(bytes[offset..offset + 4].try_into().unwrap());
    let u64_at = |offset: usize| u64::from_le_bytes(bytes[offset..offset + 8].try_into().unwrap());
    let level_count = u32_at(40).max(1) as usize;
    let levels = (0..level_count).map(|level| {
        let at = 80 + level * 24;
        (u64_at(at), u64_at(at + 8), u64_at(at + 16))
    });
    let (dfd_offset, dfd_length) = (u32_at(48) as usize, u32_at(52) as usize);
    let (kvd_offset, kvd_length) = (u32_at(56) as usize, u32_at(60) as usize);
    let mut key_values = Vec::new();
    let mut at = kvd_offset;
    while at + 4 <= kvd_offset + kvd_length {
        let length = u32_at(at) as usize;
        let pair = &bytes[at + 4..at + 4 + length];
        let split = pair.iter().position(|&byte| byte == 0).expect("a key ends with NUL");
        let value = pair[split + 1..].strip_suffix(&[0]).unwrap_or(&pair[split + 1..]);
        key_values
            .push((String::from_utf8(pair[..split].to_vec()).unwrap(), String::from_utf8(value.to_vec()).unwrap()));
        at += (4 + length).next_multiple_of(4);
    }
    Ktx2 {
        key_values,
        vk_format: u32_at(12),
        width: u32_at(20),
        height: u32_at(24),
        supercompression: u32_at(44),
        levels: levels.collect(),
        dfd: bytes[dfd_offset..dfd_offset + dfd_length].to_vec(),
    }
}

/// The block data of one KTX2 level (decompressed when the file is zstd-supercompressed).
pub fn ktx2_level(bytes: &[u8], ktx2: &Ktx2, level: usize) -> Vec<u8> {
    let (offset, length, uncompressed) = ktx2.levels[level];
    let data = &bytes[offset as usize..(offset + length) as usize];
    if ktx2.supercompression == 2 {
        zstd::bulk::decompress(data, uncompressed as usize).expect("zstd level")
    } else {
        data.to_vec()
    }
}

/// The PSNR of texel pairs read back against their sources, gathered pair by pair.
#[derive(Default)]
pub struct PsnrSum {
    squared: u64,
    count: u64,
}

impl PsnrSum {
    /// Adds the first `channels` channels of one pair.
    pub fn add(&mut self, expected: [u8; 4], actual: [u8; 4], channels: usize) {
        self.squared +=
            (0..channels).map(|channel| (expected[channel] as i64 - actual[channel] as i64).pow(2) as u64).sum::<u64>();
        self.count += channels as u64;
    }

    /// In dB (a large finite figure when every pair is equal).
    pub fn psnr(&self) -> f64 {
        10.0 * (255.0f64 * 255.0 / (self.squared as f64 / self.count.max(1) as f64).max(1e-9)).log10()
    }
}

/// The viewer example's options for a headless run on `folder` that writes `screenshot`, with
/// `arguments` (after the program name) in front.
pub fn headless_viewer_options(arguments: &[&str], screenshot: &Path, folder: &Path) -> crate::viewer::Options {
    let words = ["viewer", "--headless"].into_iter().chain(arguments.iter().copied()).map(str::to_string);
    let paths = ["--screenshot".to_string(), screenshot.display().to_string(), folder.display().to_string()];
    <crate::viewer::Options as clap::Parser>::try_parse_from(words.chain(paths)).expect("viewer options")
}

/// The lines a headless viewer run on the project's `folder` prints, with `arguments` (its
/// screenshot is the project's `shot.png`).
pub fn headless_viewer_lines(project: &TempProject, folder: &str, arguments: &[&str]) -> Vec<String> {
    let options = headless_viewer_options(arguments, &project.path("shot.png"), &project.path(folder));
    let mut lines = Vec::new();
    crate::viewer::run(&options, &mut |line| lines.push(line)).expect("the viewer runs");
    lines
}

/// The bundled bush (`examples/assets/trees/bush_2.obj`) as cirrus loads it.
pub fn bundled_bush() -> cirrus::mesh::Mesh {
    let obj = std::fs::read(Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/assets/trees/bush_2.obj"))
        .expect("the bundled bush");
    cirrus::mesh::load_mesh(Path::new("bush_2.obj"), &obj, &Default::default(), Path::new(""))
        .expect("the bundled bush loads")
        .0
}
