//! Meshes written back as text: an OBJ (positions, normals, UVs, faces by material) and the MTL
//! statements of a material, its maps named as seen from the MTL's folder. Pure: the kinds
//! that write meshes (the atlas's remap, the height's tessellation) hand the bytes to the
//! artifacts edge.

use std::fmt::Write as _;
use std::path::{Component, Path, PathBuf};

use super::MeshMaterial;
use texture::TextureSlot;

/// The MTL statement a map slot is written as (the first it is read from).
fn slot_keyword(slot: TextureSlot) -> &'static str {
    super::map_keywords(slot).first().copied().unwrap_or("map_Kd")
}

/// One material's MTL statements, each map's file named by `map_file`.
pub fn mtl_material_text(source: &MeshMaterial, map_file: impl Fn(TextureSlot, &Path) -> String) -> String {
    let mut text = String::new();
    let [r, g, b] = source.albedo_factor;
    let _ = writeln!(text, "newmtl {}\nKd {r} {g} {b}", source.name);
    if source.opacity < 1.0 {
        let _ = writeln!(text, "d {}", source.opacity);
    }
    let _ = writeln!(text, "Pr {}\nPm {}", source.roughness, source.metallic);
    for (&slot, path) in &source.maps {
        let _ = writeln!(text, "{} {}", slot_keyword(slot), map_file(slot, path));
    }
    // A cut-out whose opacity is its albedo's alpha (the loader drops a `map_d` naming the
    // albedo's own file): the alpha test stays.
    if source.cut_out && !source.maps.contains_key(&TextureSlot::Opacity) {
        if let Some(albedo) = source.maps.get(&TextureSlot::Albedo) {
            let _ = writeln!(text, "map_d {}", map_file(TextureSlot::Albedo, albedo));
        }
    }
    text
}

/// `to` as seen from the folder `from` (both relative to the same folder, or both absolute);
/// `to` itself when one is absolute and the other not.
pub fn relative_path(from: &Path, to: &Path) -> PathBuf {
    if from.is_absolute() != to.is_absolute() {
        return to.to_path_buf();
    }
    let from: Vec<Component> = from.components().filter(|component| *component != Component::CurDir).collect();
    let to_components: Vec<Component> = to.components().filter(|component| *component != Component::CurDir).collect();
    let common = from.iter().zip(&to_components).take_while(|(a, b)| a == b).count();
    let mut path = PathBuf::new();
    for _ in common..from.len() {
        path.push("..");
    }
    for component in &to_components[common..] {
        path.push(component.as_os_str());
    }
    path
}

/// A triangle mesh as an OBJ writes it.
pub struct ObjMesh<'a> {
    pub positions: &'a [[f32; 3]],
    pub normals: &'a [[f32; 3]],
    /// Per vertex, or empty.
    pub uvs: &'a [[f32; 2]],
    pub triangles: &'a [[u32; 3]],
    /// Each triangle's index into `material_names`.
    pub triangle_materials: &'a [u32],
    pub material_names: &'a [String],
}

/// The OBJ text of `mesh`: a header comment, `mtllib`, one `v`/`vn`(/`vt`) per vertex, faces
/// grouped by material in the materials' order.
pub fn obj_text(mesh: &ObjMesh, header: &str, material_library: &str) -> String {
    let mut obj = String::with_capacity(mesh.positions.len() * 90 + mesh.triangles.len() * 40);
    let _ = writeln!(obj, "# {header}\nmtllib {material_library}");
    for [x, y, z] in mesh.positions {
        let _ = writeln!(obj, "v {x} {y} {z}");
    }
    for [x, y, z] in mesh.normals {
        let _ = writeln!(obj, "vn {x} {y} {z}");
    }
    for [u, v] in mesh.uvs {
        let _ = writeln!(obj, "vt {u} {v}");
    }
    let by_material =
        super::triangles_by_material(mesh.triangle_materials, mesh.triangles.len(), mesh.material_names.len());
    for (material, triangles) in by_material.iter().enumerate() {
        if triangles.is_empty() {
            continue;
        }
        if let Some(name) = mesh.material_names.get(material) {
            let _ = writeln!(obj, "usemtl {name}");
        }
        for &triangle in triangles {
            obj.push('f');
            for vertex in mesh.triangles[triangle] {
                let index = vertex + 1;
                if mesh.uvs.is_empty() {
                    let _ = write!(obj, " {index}//{index}");
                } else {
                    let _ = write!(obj, " {index}/{index}/{index}");
                }
            }
            obj.push('\n');
        }
    }
    obj
}

/// The statements of an OBJ that a mesh written back by [`obj_text`] does not keep: its object
/// and group names (`o`, `g`: the faces are grouped by material) and its lines and points (`l`,
/// `p`), as one message each with the first statement's line; none when there are none.
pub fn obj_statements_not_kept(text: &str) -> Vec<(u32, String)> {
    let mut found: Vec<(&str, u32, usize)> = Vec::new();
    for (number, line) in text.lines().enumerate() {
        let Some(keyword) = line.split_whitespace().next() else { continue };
        if !matches!(keyword, "o" | "g" | "l" | "p") {
            continue;
        }
        match found.iter_mut().find(|(seen, _, _)| *seen == keyword) {
            Some((_, _, count)) => *count += 1,
            None => found.push((keyword, number as u32 + 1, 1)),
        }
    }
    found
        .into_iter()
        .map(|(keyword, line, count)| {
            let what = match keyword {
                "o" | "g" => "names (the written mesh groups its faces by material)",
                _ => "elements (the written mesh keeps triangles only)",
            };
            (line, format!("{count} `{keyword}` statement(s) are not kept: {what}"))
        })
        .collect()
}

/// The statements of material `material` in an MTL file's `text` that [`mtl_material_text`]
/// does not write (it writes `Kd`, `d`, `Pr`, `Pm` and the maps cirrus reads): the line of the
/// first one and the list of their keywords, or none.
pub fn mtl_statements_not_kept(text: &str, material: &str) -> Option<(u32, Vec<String>)> {
    const KEPT: [&str; 6] = ["newmtl", "Kd", "d", "Tr", "Pr", "Pm"];
    let kept = |keyword: &str| {
        KEPT.contains(&keyword) || super::MAP_STATEMENTS.iter().any(|(_, keywords)| keywords.contains(&keyword))
    };
    let mut current = None;
    let mut first = None;
    let mut keywords: Vec<String> = Vec::new();
    for (number, line) in text.lines().enumerate() {
        let mut words = line.split_whitespace();
        let Some(keyword) = words.next() else { continue };
        if keyword.starts_with('#') {
            continue;
        }
        if keyword == "newmtl" {
            current = Some(words.collect::<Vec<_>>().join(" "));
            continue;
        }
        if current.as_deref() != Some(material) || kept(keyword) {
            continue;
        }
        first.get_or_insert(number as u32 + 1);
        if !keywords.iter().any(|seen| seen == keyword) {
            keywords.push(keyword.to_string());
        }
    }
    first.map(|line| (line, keywords))
}
