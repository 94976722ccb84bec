//! Height assets: the PN-triangle library (`pn`: the paper's properties, crack-free
//! tessellation), the maps and what a build writes (`bake`: a known offset along normals, a
//! relief seen from above, the bundled pair's distances, bad input), and which stages an edit
//! re-runs (`incremental`). Meshes are OBJ text made here from height fields.

mod bake;
mod incremental;

use crate::support::TempProject;

/// A height field over [-1, 1]² in XZ, `cells`² cells of two triangles (split along the
/// diagonal from the cell's lowest x and z corner), `y = height(x, z)`; UVs `((x + 1) / 2,
/// (z + 1) / 2)` and up normals when asked.
pub fn height_field_obj(cells: u32, height: impl Fn(f32, f32) -> f32, uvs: bool, up_normals: bool) -> String {
    let mut obj = String::from("mtllib field.mtl\n");
    let side = cells + 1;
    for row in 0..side {
        for column in 0..side {
            let (x, z) = (-1.0 + 2.0 * column as f32 / cells as f32, -1.0 + 2.0 * row as f32 / cells as f32);
            obj.push_str(&format!("v {x} {} {z}\n", height(x, z)));
            if uvs {
                obj.push_str(&format!("vt {} {}\n", (x + 1.0) / 2.0, (z + 1.0) / 2.0));
            }
        }
    }
    if up_normals {
        obj.push_str("vn 0 1 0\n");
    }
    obj.push_str("usemtl field\n");
    let corner = |index: u32| match (uvs, up_normals) {
        (true, true) => format!("{0}/{0}/1", index + 1),
        (true, false) => format!("{0}/{0}", index + 1),
        (false, true) => format!("{0}//1", index + 1),
        (false, false) => format!("{}", index + 1),
    };
    for row in 0..cells {
        for column in 0..cells {
            let a = row * side + column;
            let (b, c, d) = (a + 1, a + side + 1, a + side);
            obj.push_str(&format!("f {} {} {}\n", corner(a), corner(c), corner(b)));
            obj.push_str(&format!("f {} {} {}\n", corner(a), corner(d), corner(c)));
        }
    }
    obj
}

/// The height field's surface at `(x, z)`: linear over the triangle of the cell that holds it.
pub fn height_field_at(cells: u32, height: impl Fn(f32, f32) -> f32, x: f64, z: f64) -> f64 {
    let step = 2.0 / cells as f64;
    let (column, row) =
        (((x + 1.0) / step).floor().min(cells as f64 - 1.0), ((z + 1.0) / step).floor().min(cells as f64 - 1.0));
    let (fx, fz) = ((x + 1.0) / step - column, (z + 1.0) / step - row);
    let at = |i: f64, j: f64| height((-1.0 + (column + i) * step) as f32, (-1.0 + (row + j) * step) as f32) as f64;
    let (a, b, c, d) = (at(0.0, 0.0), at(1.0, 0.0), at(1.0, 1.0), at(0.0, 1.0));
    if fz <= fx {
        a + fx * (b - a) + fz * (c - b)
    } else {
        a + fz * (d - a) + fx * (c - d)
    }
}

/// A project with one Height asset `relief` over `high.obj` and `low.obj`, `settings` inside
/// the asset (e.g. `height: (size: 64)`).
pub fn height_project(high: &str, low: &str, settings: &str) -> TempProject {
    let project = TempProject::new(&format!(
        r#"Pipeline(source: "assets", output: "baked", assets: [
            Height(name: "relief", high: "high.obj", low: "low.obj", {settings}),
        ])"#
    ));
    project.write("assets/high.obj", high);
    project.write("assets/low.obj", low);
    project.write("assets/field.mtl", "newmtl field\nKd 0.5 0.5 0.5\n");
    project
}

/// A 16-bit greyscale PNG's values.
pub fn png16_values(bytes: &[u8]) -> (u32, Vec<u16>) {
    let image = image::load_from_memory(bytes).unwrap();
    assert_eq!(image.color(), image::ColorType::L16, "a 16-bit grey PNG");
    let image = image.into_luma16();
    (image.width(), image.into_raw())
}

/// A map's values as distances, by the mapping its report gives.
pub fn distances(report: &serde_json::Value, values: &[u16]) -> Vec<f64> {
    let (center, magnitude) = (report["center"].as_f64().unwrap(), report["magnitude"].as_f64().unwrap());
    values.iter().map(|&value| (value as f64 / 65535.0 - center) * magnitude).collect()
}
