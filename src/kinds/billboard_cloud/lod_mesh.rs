//! The LOD mesh: `lod.obj` + `lod.mtl` text, two triangles per rectangle (a cluster of a plane's
//! faces) with UVs into the atlas and
//! the plane's normal. Depends on planes and layout only: a texture edit does not rewrite it.

use std::fmt::Write;

use crate::kinds::billboard_cloud::layout::Layout;
use crate::kinds::billboard_cloud::rectangles::PlaneRectangle;

/// The OBJ and MTL text of the billboard cloud; `material` names the atlas material.
pub fn lod_mesh(rectangles: &[PlaneRectangle], layout: &Layout, material: &str) -> (String, String) {
    let mut obj = String::new();
    let planes = rectangles.iter().map(|rectangle| rectangle.plane).collect::<std::collections::BTreeSet<_>>().len();
    let _ = writeln!(
        obj,
        "# cirrus billboard cloud: {} quads on {planes} planes, atlas {}x{}",
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
    let mtl = format!(
        "# cirrus billboard cloud material (alpha-tested, double-sided)\nnewmtl {material}\nKd 1 1 1\nmap_Kd \
            albedo.png\nmap_d albedo.png\nnorm normal.png\nmap_Pr mra.png\nmap_ao mra.png\n"
    );
    (obj, mtl)
}
