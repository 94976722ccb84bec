//! Writes a synthetic level: a project of many small assets in the proportions of a game level,
//! for the `scale` bench and the scale tests (and for anyone who wants to see cirrus on a
//! project of thousands of assets).
//!
//!     cargo run --release --example make_level -- target/level --assets 1000
//!     cargo run --release -- build --pipeline target/level/pipeline.ron
//!
//! With `--material-side N`, every asset is a `Material` whose albedo and normal maps (and
//! roughness, one in four) are N² (the `level-memory` bench: a level's worth of texels).
//!
//! Of every 100 assets, 90 are `Material`s (`materials/gNNN/mNNNNN.mymaterial`: an albedo and a
//! normal map, 64², one material in ten at 256² and one in four with a roughness map too, one in
//! five sharing a grime detail map with 49 others), 7 are `AmbientOcclusion` bakes of a rock
//! (`rocks/gNNN/rNNNNN.obj`: a displaced sphere of 384 triangles, a 64² map at 16 rays) and 3
//! are `BillboardCloud`s of a plant (`plants/gNNN/pNNNNN.obj`: a trunk and 16 alpha-tested leaf
//! cards with their own 64² textures, at most 8 planes on a 128² atlas). Three `rules` find
//! them all; folders hold 100 files each. Every file is its own (seeded by its index), so no
//! two assets share a cache entry by accident. The same settings always write the same bytes.

use std::io;
use std::path::{Path, PathBuf};

/// How large a level to write.
#[derive(Clone, Debug, Default)]
pub struct LevelSettings {
    /// How many assets (rounded to whole kinds: 90 % materials, 7 % rocks, 3 % plants).
    pub assets: usize,
    /// Every asset a `Material` with maps of this side (none: the mix above, 64² and 256² maps).
    pub material_side: Option<u32>,
}

/// What was written: the files a bench or test edits.
#[derive(Clone, Debug, Default)]
pub struct Level {
    /// `pipeline.ron`.
    pub pipeline: PathBuf,
    /// Each material's albedo map (project-relative to the level folder), in asset order.
    pub albedo_maps: Vec<PathBuf>,
    /// How many assets of each kind: materials, rocks, plants.
    pub counts: [usize; 3],
}

/// The number of materials, rocks and plants of a level of `assets` assets.
pub fn level_counts(assets: usize) -> [usize; 3] {
    let rocks = assets * 7 / 100;
    let plants = assets * 3 / 100;
    [assets - rocks - plants, rocks, plants]
}

/// Writes the level into `folder` (created; files already there are overwritten).
pub fn write_level(folder: &Path, settings: &LevelSettings) -> io::Result<Level> {
    let counts = match settings.material_side {
        Some(_) => [settings.assets, 0, 0],
        None => level_counts(settings.assets),
    };
    let source = folder.join("assets");
    std::fs::create_dir_all(&source)?;
    std::fs::write(folder.join("pipeline.ron"), PIPELINE)?;
    let mut level = Level { pipeline: folder.join("pipeline.ron"), counts, ..Default::default() };
    for grime in 0..counts[0].div_ceil(250) {
        write(
            &source.join(format!("textures/shared/grime{grime:03}.png")),
            &noise_png(64, 64, 3, 7_000 + grime as u64),
        )?;
    }
    for index in 0..counts[0] {
        level.albedo_maps.push(write_material(&source, index, settings.material_side)?);
    }
    for index in 0..counts[1] {
        write_rock(&source, index)?;
    }
    for index in 0..counts[2] {
        write_plant(&source, index)?;
    }
    Ok(level)
}

/// The pipeline of every level: three rules, defaults sized for many small assets.
const PIPELINE: &str = r#"// A synthetic level written by `cargo run --example make_level`.
Pipeline(
    source: "assets",
    output: "baked",
    defaults: (
        billboard: (max_planes: Some(8)),
        atlas: (max_size: 128),
        ao: (size: 64, rays: 16),
    ),
    assets: [],
    rules: [
        (glob: "materials/**/*.mymaterial", kind: Material),
        (glob: "rocks/**/*.obj", kind: AmbientOcclusion),
        (glob: "plants/**/*.obj", kind: BillboardCloud),
    ],
)
"#;

/// `group/index` folder and file stem of the `index`th file of a kind.
fn grouped(prefix: &str, index: usize) -> (String, String) {
    (format!("g{:03}", index / 100), format!("{prefix}{index:05}"))
}

/// One material file and its maps (`side`² where given); returns its albedo map's path (relative
/// to the level).
fn write_material(source: &Path, index: usize, side: Option<u32>) -> io::Result<PathBuf> {
    let (group, stem) = grouped("m", index);
    let size = side.unwrap_or(if index % 10 == 9 { 256 } else { 64 });
    let seed = index as u64 * 16;
    let textures = format!("textures/{group}");
    let albedo = format!("{textures}/{stem}_albedo.png");
    write(&source.join(&albedo), &noise_png(size, size, 3, seed))?;
    write(&source.join(format!("{textures}/{stem}_normal.png")), &normal_png(size, seed + 1))?;
    let mut text = format!(
        "Material ${stem}\n{{\n    Name {{string {{\"{stem}\"}}}}\n    Param (attrib = \"metallic\") {{float {{0.0}}}}\n    \
         Texture (attrib = \"diffuse\") {{string {{\"../../{textures}/{stem}_albedo.png\"}}}}\n    \
         Texture (attrib = \"normal\") {{string {{\"../../{textures}/{stem}_normal.png\"}}}}\n"
    );
    if index.is_multiple_of(4) {
        write(&source.join(format!("{textures}/{stem}_roughness.png")), &noise_png(size, size, 1, seed + 2))?;
        text +=
            &format!("    Texture (attrib = \"roughness\") {{string {{\"../../{textures}/{stem}_roughness.png\"}}}}\n");
    } else {
        text += "    Param (attrib = \"roughness\") {float {0.6}}\n";
    }
    if index.is_multiple_of(5) {
        text += &format!(
            "    Texture (attrib = \"ao\") {{string {{\"../../textures/shared/grime{:03}.png\"}}}}\n",
            index / 250
        );
    }
    text += "}\n";
    write(&source.join(format!("materials/{group}/{stem}.mymaterial")), text.as_bytes())?;
    Ok(PathBuf::from("assets").join(albedo))
}

/// A rock: a sphere of 16 × 12 quads displaced by seeded bumps, UVs by longitude and latitude.
fn write_rock(source: &Path, index: usize) -> io::Result<()> {
    let (group, stem) = grouped("r", index);
    let mut random = Random(0x5eed_0000 + index as u64);
    let bumps: Vec<([f32; 3], f32)> = (0..6).map(|_| (random.unit_vector(), random.between(-0.25, 0.25))).collect();
    let (columns, rows) = (16, 12);
    let mut obj = format!("mtllib {stem}.mtl\no rock\n");
    for row in 0..=rows {
        for column in 0..=columns {
            let (u, v) = (column as f32 / columns as f32, row as f32 / rows as f32);
            let (theta, phi) = (u * std::f32::consts::TAU, v * std::f32::consts::PI);
            let direction = [phi.sin() * theta.cos(), phi.cos(), phi.sin() * theta.sin()];
            let radius = 1.0
                + bumps.iter().map(|(centre, height)| height * dot(direction, *centre).max(0.0).powi(4)).sum::<f32>();
            let [x, y, z] = direction.map(|d| d * radius);
            obj += &format!("v {x:.5} {y:.5} {z:.5}\nvt {:.5} {:.5}\n", u * 0.98 + 0.01, v * 0.98 + 0.01);
        }
    }
    obj += "usemtl rock\n";
    let vertex = |row: usize, column: usize| row * (columns + 1) + column + 1;
    for row in 0..rows {
        for column in 0..columns {
            let [a, b, c, d] =
                [vertex(row, column), vertex(row, column + 1), vertex(row + 1, column + 1), vertex(row + 1, column)];
            obj += &format!("f {a}/{a} {c}/{c} {b}/{b}\nf {a}/{a} {d}/{d} {c}/{c}\n");
        }
    }
    let folder = source.join(format!("rocks/{group}"));
    write(&folder.join(format!("{stem}.obj")), obj.as_bytes())?;
    write(&folder.join(format!("{stem}.mtl")), b"newmtl rock\nKd 0.5 0.5 0.5\n")
}

/// A plant: a four-sided trunk and 16 leaf cards around its top, each card two triangles;
/// its bark and leaf textures are its own.
fn write_plant(source: &Path, index: usize) -> io::Result<()> {
    let (group, stem) = grouped("p", index);
    let mut random = Random(0x91a7_0000 + index as u64);
    let folder = source.join(format!("plants/{group}"));
    write(&folder.join(format!("{stem}_bark.png")), &noise_png(64, 64, 3, 9_000_000 + index as u64))?;
    write(&folder.join(format!("{stem}_leaf.png")), &leaf_png(64, 9_500_000 + index as u64))?;
    let mut obj = format!("mtllib {stem}.mtl\no plant\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n");
    let mut vertices = 0;
    let mut quad = |obj: &mut String, corners: [[f32; 3]; 4], material: &str| {
        for [x, y, z] in corners {
            *obj += &format!("v {x:.4} {y:.4} {z:.4}\n");
        }
        let v = vertices;
        *obj += &format!(
            "usemtl {material}\nf {}/1 {}/2 {}/3\nf {}/1 {}/3 {}/4\n",
            v + 1,
            v + 2,
            v + 3,
            v + 1,
            v + 3,
            v + 4
        );
        vertices += 4;
    };
    let (width, height) = (0.08, 1.2);
    for side in 0..4 {
        let angle = |k: usize| k as f32 * std::f32::consts::FRAC_PI_2;
        let (a, b) = (angle(side), angle(side + 1));
        let at = |angle: f32, y: f32| [width * angle.cos(), y, width * angle.sin()];
        quad(&mut obj, [at(a, 0.0), at(b, 0.0), at(b, height), at(a, height)], "bark");
    }
    for _ in 0..16 {
        let centre = [random.between(-0.5, 0.5), random.between(0.9, 1.6), random.between(-0.5, 0.5)];
        let angle = random.between(0.0, std::f32::consts::TAU);
        let (dx, dz) = (0.2 * angle.cos(), 0.2 * angle.sin());
        let tilt = random.between(-0.1, 0.1);
        let [x, y, z] = centre;
        quad(
            &mut obj,
            [
                [x - dx, y - 0.2 + tilt, z - dz],
                [x + dx, y - 0.2 - tilt, z + dz],
                [x + dx, y + 0.2 - tilt, z + dz],
                [x - dx, y + 0.2 + tilt, z - dz],
            ],
            "leaves",
        );
    }
    write(&folder.join(format!("{stem}.obj")), obj.as_bytes())?;
    let mtl = format!(
        "newmtl bark\nKd 0.6 0.5 0.4\nmap_Kd {stem}_bark.png\n\nnewmtl leaves\nKd 0.5 0.8 0.4\nmap_Kd {stem}_leaf.png\nmap_d {stem}_leaf.png\n"
    );
    write(&folder.join(format!("{stem}.mtl")), mtl.as_bytes())
}

/// Writes `bytes` to `path`, creating its folder.
fn write(path: &Path, bytes: &[u8]) -> io::Result<()> {
    if let Some(parent) = path.parent() {
        std::fs::create_dir_all(parent)?;
    }
    std::fs::write(path, bytes)
}

fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// SplitMix64: seeded, the same numbers on every machine.
struct Random(u64);

impl Random {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    fn between(&mut self, low: f32, high: f32) -> f32 {
        low + (high - low) * (self.next() >> 40) as f32 / (1u64 << 24) as f32
    }

    fn unit_vector(&mut self) -> [f32; 3] {
        loop {
            let v = [self.between(-1.0, 1.0), self.between(-1.0, 1.0), self.between(-1.0, 1.0)];
            let length = dot(v, v).sqrt();
            if (0.1..=1.0).contains(&length) {
                return v.map(|c| c / length);
            }
        }
    }
}

/// A smooth seeded pattern (a few blobs of colour over a base tone, with fine grain), as PNG
/// with `channels` channels (1 or 3).
pub fn noise_png(width: u32, height: u32, channels: u8, seed: u64) -> Vec<u8> {
    let mut random = Random(seed);
    let base: [f32; 3] = [random.between(40.0, 200.0), random.between(40.0, 200.0), random.between(40.0, 200.0)];
    let blobs: Vec<(f32, f32, f32, [f32; 3])> = (0..5)
        .map(|_| {
            let colour = [random.between(-60.0, 60.0), random.between(-60.0, 60.0), random.between(-60.0, 60.0)];
            (random.between(0.0, 1.0), random.between(0.0, 1.0), random.between(0.05, 0.3), colour)
        })
        .collect();
    let mut pixels = Vec::with_capacity((width * height) as usize * channels as usize);
    for y in 0..height {
        for x in 0..width {
            let (u, v) = (x as f32 / width as f32, y as f32 / height as f32);
            let mut colour = base;
            for (cu, cv, radius, delta) in &blobs {
                let weight = (-((u - cu).powi(2) + (v - cv).powi(2)) / (radius * radius)).exp();
                for c in 0..3 {
                    colour[c] += weight * delta[c];
                }
            }
            let grain = random.between(-8.0, 8.0);
            let texel = colour.map(|c| (c + grain).clamp(0.0, 255.0) as u8);
            pixels.extend_from_slice(&texel[..channels as usize]);
        }
    }
    let colour = if channels == 1 { image::ExtendedColorType::L8 } else { image::ExtendedColorType::Rgb8 };
    encode_png(width, height, &pixels, colour)
}

/// A tangent-space normal map of seeded bumps.
fn normal_png(size: u32, seed: u64) -> Vec<u8> {
    let mut random = Random(seed);
    let bumps: Vec<(f32, f32, f32)> =
        (0..8).map(|_| (random.between(0.0, 1.0), random.between(0.0, 1.0), random.between(-1.0, 1.0))).collect();
    let mut pixels = Vec::with_capacity((size * size * 3) as usize);
    for y in 0..size {
        for x in 0..size {
            let (u, v) = (x as f32 / size as f32, y as f32 / size as f32);
            let (mut dx, mut dy) = (0.0f32, 0.0f32);
            for (cu, cv, strength) in &bumps {
                let weight = strength * (-((u - cu).powi(2) + (v - cv).powi(2)) * 40.0).exp();
                dx += weight * (u - cu) * 8.0;
                dy += weight * (v - cv) * 8.0;
            }
            let length = (dx * dx + dy * dy + 1.0).sqrt();
            let n = [dx / length, dy / length, 1.0 / length];
            pixels.extend(n.map(|c| ((c * 0.5 + 0.5) * 255.0).round() as u8));
        }
    }
    encode_png(size, size, &pixels, image::ExtendedColorType::Rgb8)
}

/// A leaf: an opaque ellipse on a transparent square, its green seeded.
fn leaf_png(size: u32, seed: u64) -> Vec<u8> {
    let mut random = Random(seed);
    let green = [random.between(30.0, 90.0), random.between(110.0, 190.0), random.between(20.0, 70.0)];
    let mut pixels = Vec::with_capacity((size * size * 4) as usize);
    for y in 0..size {
        for x in 0..size {
            let (u, v) = ((x as f32 + 0.5) / size as f32 - 0.5, (y as f32 + 0.5) / size as f32 - 0.5);
            let inside = (u / 0.3).powi(2) + (v / 0.48).powi(2) <= 1.0;
            let shade = random.between(-10.0, 10.0);
            let [r, g, b] = green.map(|c| (c + shade).clamp(0.0, 255.0) as u8);
            pixels.extend_from_slice(&[r, g, b, if inside { 255 } else { 0 }]);
        }
    }
    encode_png(size, size, &pixels, image::ExtendedColorType::Rgba8)
}

fn encode_png(width: u32, height: u32, pixels: &[u8], colour: image::ExtendedColorType) -> Vec<u8> {
    use image::ImageEncoder;
    let mut bytes = Vec::new();
    image::codecs::png::PngEncoder::new(&mut bytes).write_image(pixels, width, height, colour).expect("PNG in memory");
    bytes
}

#[allow(dead_code)]
fn main() {
    let mut arguments = std::env::args().skip(1);
    let mut folder = None;
    let mut settings = LevelSettings { assets: 1000, material_side: None };
    while let Some(argument) = arguments.next() {
        match argument.as_str() {
            "--assets" => settings.assets = arguments.next().and_then(|n| n.parse().ok()).expect("--assets N"),
            "--material-side" => {
                settings.material_side = Some(arguments.next().and_then(|n| n.parse().ok()).expect("--material-side N"))
            }
            _ => folder = Some(PathBuf::from(argument)),
        }
    }
    let folder = folder.expect("usage: make_level FOLDER [--assets N] [--material-side N]");
    let level = write_level(&folder, &settings).expect("writing the level");
    let [materials, rocks, plants] = level.counts;
    println!(
        "{}: {materials} materials, {rocks} rocks, {plants} plants; build it with \
         `cirrus build --pipeline {}`",
        folder.display(),
        level.pipeline.display()
    );
}
