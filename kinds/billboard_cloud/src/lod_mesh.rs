//! The LOD mesh: `lod.obj` + `lod.mtl` text and `lod.gltf` + `lod.bin`, two triangles per
//! rectangle (a cluster of a plane's faces) with UVs into the atlas, the plane's normal and (glTF)
//! its x axis as the tangent of the atlas's normal map. Depends on planes and layout only: a
//! texture edit does not rewrite it.

use std::fmt::Write;

use crate::layout::Layout;
use crate::mesh::gltf::{gltf_files, GltfAlpha, GltfFiles, GltfMaterial, GltfMesh, GltfWrap, GENERATOR};
use crate::rectangles::PlaneRectangle;

/// How a billboard cloud's `lod.obj` begins (a reduced level's does not).
pub const CLOUD_HEADER: &str = "# cirrus billboard cloud";

/// The OBJ text of the billboard cloud (`mtllib lod.mtl`); `material` names the atlas material.
pub fn lod_mesh(rectangles: &[PlaneRectangle], layout: &Layout, material: &str) -> String {
    let mut obj = String::new();
    let planes = rectangles.iter().map(|rectangle| rectangle.plane).collect::<std::collections::BTreeSet<_>>().len();
    let _ = writeln!(
        obj,
        "{CLOUD_HEADER}: {} quads on {planes} planes, atlas {}x{}",
        rectangles.len(),
        layout.width,
        layout.height
    );
    let _ = writeln!(obj, "mtllib lod.mtl");
    let _ = writeln!(obj, "o {material}");
    let _ = writeln!(obj, "usemtl {material}");
    let corner_st = [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)];
    for (rectangle, placement) in rectangles.iter().zip(&layout.placements) {
        for corner in rectangle.corners() {
            let _ = writeln!(obj, "v {} {} {}", corner.x, corner.y, corner.z);
        }
        for (s, t) in corner_st {
            let [u, v] = placement.uv(s, t, layout.width, layout.height);
            let _ = writeln!(obj, "vt {u} {v}");
        }
        let [x, y, z] = rectangle.frame.normal;
        let _ = writeln!(obj, "vn {x} {y} {z}");
    }
    for index in 0..rectangles.len() {
        let (v, n) = (index * 4 + 1, index + 1);
        let _ = writeln!(obj, "f {}/{}/{n} {}/{}/{n} {}/{}/{n}", v, v, v + 1, v + 1, v + 2, v + 2);
        let _ = writeln!(obj, "f {}/{}/{n} {}/{}/{n} {}/{}/{n}", v, v, v + 2, v + 2, v + 3, v + 3);
    }
    obj
}

/// The `lod.mtl` of the atlas material `material`, its packed map `<packed>.png` (`mra` or
/// `orm`, as the asset's `encode: (packing: …)` names it).
pub fn lod_mtl(material: &str, packed: &str) -> String {
    format!(
        "# cirrus billboard cloud material (alpha-tested, double-sided)\nnewmtl {material}\nKd 1 1 1\nmap_Kd \
            albedo.png\nmap_d albedo.png\nnorm normal.png\nmap_Pr {packed}.png\nmap_ao {packed}.png\n"
    )
}

/// The glTF of a level: [`lod_gltf_mesh`] in `lod.gltf` naming `lod.bin`.
pub fn lod_gltf(rectangles: &[PlaneRectangle], layout: &Layout, alpha_cutoff: f32) -> GltfFiles {
    gltf_files(&lod_gltf_mesh(rectangles, layout, alpha_cutoff).mesh(), "lod.bin", GENERATOR)
}

/// A level's quads as glTF draws them (owned; [`LodGltfMesh::mesh`] lends them).
pub struct LodGltfMesh {
    positions: Vec<[f32; 3]>,
    normals: Vec<[f32; 3]>,
    tangents: Vec<[f32; 4]>,
    uvs: Vec<[f32; 2]>,
    triangles: Vec<[u32; 3]>,
    material: GltfMaterial,
}

impl LodGltfMesh {
    pub fn mesh(&self) -> GltfMesh<'_> {
        GltfMesh {
            name: "billboard_cloud",
            positions: &self.positions,
            normals: &self.normals,
            tangents: &self.tangents,
            uvs: &self.uvs,
            triangles: &self.triangles,
            triangle_materials: &[],
            materials: std::slice::from_ref(&self.material),
            extras: None,
        }
    }
}

/// The billboard cloud for glTF: the same quads as the OBJ, one alpha-tested, double-sided
/// material over `albedo.png`, `normal.png` (in each quad's frame: tangent = the plane's x
/// axis, bitangent its y axis) and `orm.png`.
pub fn lod_gltf_mesh(rectangles: &[PlaneRectangle], layout: &Layout, alpha_cutoff: f32) -> LodGltfMesh {
    let corner_st = [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)];
    let vertices = rectangles.len() * 4;
    let (mut positions, mut normals) = (Vec::with_capacity(vertices), Vec::with_capacity(vertices));
    let (mut tangents, mut uvs) = (Vec::with_capacity(vertices), Vec::with_capacity(vertices));
    let mut triangles = Vec::with_capacity(rectangles.len() * 2);
    for (rectangle, placement) in rectangles.iter().zip(&layout.placements) {
        let first = positions.len() as u32;
        for (corner, (s, t)) in rectangle.corners().into_iter().zip(corner_st) {
            positions.push(corner.to_array());
            normals.push(rectangle.frame.normal);
            let [x, y, z] = rectangle.frame.x_axis;
            tangents.push([x, y, z, 1.0]);
            uvs.push(placement.uv(s, t, layout.width, layout.height));
        }
        triangles.push([first, first + 1, first + 2]);
        triangles.push([first, first + 2, first + 3]);
    }
    let material = GltfMaterial {
        name: "billboard_cloud".into(),
        base_colour_factor: [1.0; 4],
        metallic_factor: 1.0,
        roughness_factor: 1.0,
        base_colour: Some("albedo.png".into()),
        normal: Some("normal.png".into()),
        occlusion: Some("orm.png".into()),
        metallic_roughness: Some("orm.png".into()),
        alpha: GltfAlpha::Mask(alpha_cutoff),
        double_sided: true,
        wrap: GltfWrap::Clamp,
    };
    LodGltfMesh { positions, normals, tangents, uvs, triangles, material }
}

/// The viewport a chain's switch coverages are stated for: 1920 × 1080 pixels.
pub const COVERAGE_VIEWPORT: (f32, f32) = (1920.0, 1080.0);

/// A chain's `MSFT_screencoverage`: for each level, the least screen coverage at which it is
/// shown, as Babylon.js reads it (the share of the viewport's area the object covers, here its
/// bounding sphere's disc on a [`COVERAGE_VIEWPORT`]). Level `i` gives way where the object is
/// `switch_sizes[i + 1]` pixels across (the measured switch sizes, `preview::switch_sizes`); the
/// last level is shown down to nothing (0). Non-increasing, at most 1.
pub fn screen_coverage(switch_sizes: &[u32]) -> Vec<f32> {
    let (width, height) = COVERAGE_VIEWPORT;
    let mut coverage: Vec<f32> = switch_sizes
        .iter()
        .skip(1)
        .map(|&pixels| (std::f32::consts::FRAC_PI_4 * pixels as f32 * pixels as f32 / (width * height)).min(1.0))
        .collect();
    coverage.push(0.0);
    for index in 1..coverage.len() {
        coverage[index] = coverage[index].min(coverage[index - 1]);
    }
    coverage
}

/// How far below a switch size the next level fades in: over sizes from `S` down to
/// `S / FADE_BAND` the next level takes over a growing share of the pixels (a dithered
/// cross-fade), and below that it is shown alone.
pub const FADE_BAND: f32 = 1.25;

/// What a chain shows at a screen size: one level, or one fading into the next.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShownLevels {
    pub level: u32,
    /// The next level and its share of the pixels, in (0, 1).
    pub fading_into: Option<(u32, f32)>,
}

/// The levels a chain with `switch_sizes` (each level's, `preview::switch_sizes`) shows when its
/// bounding sphere is `pixels` across: the last level whose switch size is at least `pixels`
/// (level 0 above every switch size), fading in over the band below its switch size (from the
/// level before).
pub fn shown_levels(switch_sizes: &[u32], pixels: f32) -> ShownLevels {
    let chosen = (1..switch_sizes.len()).rev().find(|&level| pixels <= switch_sizes[level] as f32);
    let Some(level) = chosen else { return ShownLevels { level: 0, fading_into: None } };
    let switch = switch_sizes[level] as f32;
    let band_end = switch / FADE_BAND;
    if pixels > band_end {
        let share = ((switch - pixels) / (switch - band_end)).clamp(0.0, 1.0);
        if share > 0.0 && share < 1.0 {
            return ShownLevels { level: level as u32 - 1, fading_into: Some((level as u32, share)) };
        }
        if share == 0.0 {
            return ShownLevels { level: level as u32 - 1, fading_into: None };
        }
    }
    ShownLevels { level: level as u32, fading_into: None }
}
