//! AmbientOcclusion assets: what they write and how it reads back (`bake`), which stages an
//! edit re-runs (`incremental`), and a bake as a Material's AO source (`source`). Scenes are OBJ
//! text made here from quads, boxes and spheres.

mod bake;
mod incremental;
mod source;

use crate::support::TempProject;

/// One OBJ object with one material: vertices (position, UV) and counter-clockwise triangles.
#[derive(Clone, Default)]
pub struct Part {
    pub object: String,
    pub material: String,
    pub vertices: Vec<([f32; 3], [f32; 2])>,
    pub triangles: Vec<[u32; 3]>,
}

impl Part {
    pub fn new(object: &str, material: &str) -> Part {
        Part { object: object.into(), material: material.into(), ..Part::default() }
    }

    /// A quad of corners `a b c d` (counter-clockwise seen from its front) with UVs over the
    /// rectangle `uv` = [u0, v0, u1, v1] (a at (u0, v0), c at (u1, v1)).
    pub fn quad(mut self, corners: [[f32; 3]; 4], uv: [f32; 4]) -> Part {
        let first = self.vertices.len() as u32;
        let uvs = [[uv[0], uv[1]], [uv[2], uv[1]], [uv[2], uv[3]], [uv[0], uv[3]]];
        self.vertices.extend(corners.into_iter().zip(uvs));
        self.triangles.extend([[first, first + 1, first + 2], [first, first + 2, first + 3]]);
        self
    }

    /// A floor square of half-width `half` at height `y`, facing up, split into `cells`² quads,
    /// its UVs over `uv`; with `mirrored`, U runs the other way (the island's winding flips).
    pub fn floor(mut self, half: f32, y: f32, cells: u32, uv: [f32; 4], mirrored: bool) -> Part {
        for row in 0..cells {
            for column in 0..cells {
                let at = |i: u32, j: u32| {
                    let (s, t) = (i as f32 / cells as f32, j as f32 / cells as f32);
                    let u = if mirrored { uv[2] - s * (uv[2] - uv[0]) } else { uv[0] + s * (uv[2] - uv[0]) };
                    ([-half + 2.0 * half * s, y, half - 2.0 * half * t], [u, uv[1] + t * (uv[3] - uv[1])])
                };
                let first = self.vertices.len() as u32;
                self.vertices.extend([
                    at(column, row),
                    at(column + 1, row),
                    at(column + 1, row + 1),
                    at(column, row + 1),
                ]);
                self.triangles.extend([[first, first + 1, first + 2], [first, first + 2, first + 3]]);
            }
        }
        self
    }

    /// A box from `low` to `high`, faces outward, each face on its own sixth of the UV rectangle
    /// `uv` (cut into columns).
    pub fn cuboid(mut self, low: [f32; 3], high: [f32; 3], uv: [f32; 4]) -> Part {
        let [x0, y0, z0] = low;
        let [x1, y1, z1] = high;
        let faces = [
            [[x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]], // +z
            [[x1, y0, z0], [x0, y0, z0], [x0, y1, z0], [x1, y1, z0]], // -z
            [[x1, y0, z1], [x1, y0, z0], [x1, y1, z0], [x1, y1, z1]], // +x
            [[x0, y0, z0], [x0, y0, z1], [x0, y1, z1], [x0, y1, z0]], // -x
            [[x0, y1, z1], [x1, y1, z1], [x1, y1, z0], [x0, y1, z0]], // +y
            [[x0, y0, z0], [x1, y0, z0], [x1, y0, z1], [x0, y0, z1]], // -y
        ];
        let width = (uv[2] - uv[0]) / 6.0;
        for (index, face) in faces.into_iter().enumerate() {
            let u0 = uv[0] + width * index as f32;
            self = self.quad(face, [u0 + width * 0.05, uv[1], u0 + width * 0.95, uv[3]]);
        }
        self
    }

    /// A UV sphere (`segments` around, `rings` from pole to pole) with its seam at U = 0 / 1,
    /// where the vertices are doubled.
    pub fn sphere(mut self, centre: [f32; 3], radius: f32, segments: u32, rings: u32) -> Part {
        let first = self.vertices.len() as u32;
        for ring in 0..=rings {
            let theta = std::f32::consts::PI * ring as f32 / rings as f32;
            for segment in 0..=segments {
                // The seam's doubled vertices share their position exactly, as an exporter writes
                // one `v` with two `vt`.
                let phi = std::f32::consts::TAU * (segment % segments) as f32 / segments as f32;
                let position = [
                    centre[0] + radius * theta.sin() * phi.cos(),
                    centre[1] + radius * theta.cos(),
                    centre[2] - radius * theta.sin() * phi.sin(),
                ];
                self.vertices.push((position, [segment as f32 / segments as f32, 1.0 - ring as f32 / rings as f32]));
            }
        }
        let row = segments + 1;
        for ring in 0..rings {
            for segment in 0..segments {
                let a = first + ring * row + segment;
                let (b, c, d) = (a + 1, a + row + 1, a + row);
                // Counter-clockwise seen from outside; the pole rows' degenerate halves are left out.
                if ring != 0 {
                    self.triangles.push([a, d, b]);
                }
                if ring != rings - 1 {
                    self.triangles.push([b, d, c]);
                }
            }
        }
        self
    }
}

/// The OBJ text of `parts` (naming `scene.mtl`) and the MTL defining their materials.
pub fn scene_files(parts: &[Part]) -> (String, String) {
    let mut obj = String::from("mtllib scene.mtl\n");
    let mut base = 1;
    for part in parts {
        obj.push_str(&format!("o {}\nusemtl {}\n", part.object, part.material));
        for (position, uv) in &part.vertices {
            obj.push_str(&format!("v {} {} {}\nvt {} {}\n", position[0], position[1], position[2], uv[0], uv[1]));
        }
        for triangle in &part.triangles {
            let [a, b, c] = triangle.map(|vertex| vertex + base);
            obj.push_str(&format!("f {a}/{a} {b}/{b} {c}/{c}\n"));
        }
        base += part.vertices.len() as u32;
    }
    let mut materials: Vec<&str> = parts.iter().map(|part| part.material.as_str()).collect();
    materials.dedup();
    let mtl = materials.iter().map(|material| format!("newmtl {material}\nKd 0.8 0.8 0.8\n")).collect();
    (obj, mtl)
}

/// A project with one AmbientOcclusion asset `scene` over `assets/scene.obj` made of `parts`,
/// with the `ao: (...)` settings given.
pub fn ao_project(parts: &[Part], ao_settings: &str) -> TempProject {
    let project = TempProject::new(&format!(
        r#"Pipeline(source: "assets", output: "baked", assets: [
            AmbientOcclusion(name: "scene", mesh: "scene.obj", ao: ({ao_settings})),
        ])"#
    ));
    let (obj, mtl) = scene_files(parts);
    project.write("assets/scene.obj", obj);
    project.write("assets/scene.mtl", mtl);
    project
}

/// A 16-bit greyscale PNG's size and samples.
pub fn read_png16(bytes: &[u8]) -> (u32, Vec<u16>) {
    let image = image::load_from_memory_with_format(bytes, image::ImageFormat::Png).expect("a PNG");
    assert_eq!(image.color(), image::ColorType::L16, "ao.png is 16-bit grey");
    let image = image.into_luma16();
    (image.width(), image.into_raw())
}

/// The floor-and-box scene: a 4 × 4 floor (`floor`, 8² cells, UVs over the whole square) with a
/// unit box standing on its middle (`box`, its own object).
pub fn floor_and_box(mirrored: bool) -> Vec<Part> {
    vec![
        Part::new("floor", "floor").floor(2.0, 0.0, 8, [0.0, 0.0, 1.0, 1.0], mirrored),
        Part::new("box", "box").cuboid([-0.5, 0.0, -0.5], [0.5, 1.0, 0.5], [0.0, 0.0, 1.0, 1.0]),
    ]
}
