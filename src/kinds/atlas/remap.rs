//! Meshes remapped onto the atlas (DESIGN §3.5): each material whose maps are atlas entries gets
//! its UVs moved onto that entry's rectangle (`AtlasEntry::page_uv`) and its maps pointed at the
//! page; the OBJ is written again (positions, normals, remapped UVs, faces by material) and the
//! materials go into one `atlas.mtl`. Pure: the kind's queries serve the mesh and the table.

use std::collections::{BTreeMap, HashMap};
use std::fmt::Write as _;
use std::path::Path;

use crate::mesh::{Mesh, MeshMaterial};
use crate::texture::TextureSlot;

use super::table::AtlasEntry;

/// UVs this far outside [0, 1] still count as inside (exporters' rounding).
const UV_TOLERANCE: f32 = 1e-4;

/// A material of a remapped mesh, as `atlas.mtl` writes it.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RemappedMaterial {
    pub material: MeshMaterial,
    /// The atlas page its atlased maps now point at, and which maps those are.
    pub page: Option<u32>,
    pub atlased: Vec<TextureSlot>,
}

/// A mesh remapped onto the atlas: the new OBJ's text and its materials.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RemappedMesh {
    pub obj: String,
    pub materials: Vec<RemappedMaterial>,
    /// What loading the mesh warned of (a missing MTL, a map leaving the source folder).
    #[serde(default)]
    pub warnings: Vec<crate::diagnostic::Diagnostic>,
}

/// Why a mesh cannot be remapped.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum RemapError {
    #[error(
        "material `{material}` has UVs u ∈ [{u_min}, {u_max}], v ∈ [{v_min}, {v_max}] on the atlased texture `{entry}`: repeating UVs (outside [0, 1]) cannot be remapped onto an atlas rectangle"
    )]
    RepeatingUvs { material: String, entry: String, u_min: f32, u_max: f32, v_min: f32, v_max: f32 },
    #[error("material `{material}` uses the atlased textures `{first}` and `{second}`, which lie in different rectangles: one UV set cannot address both")]
    TwoRectangles { material: String, first: String, second: String },
}

/// The atlas entry (index into the table's entries) a material's maps are in, and which of its
/// maps those are.
pub type MaterialEntry = Option<(usize, Vec<TextureSlot>)>;

/// For each material of `mesh`, the atlas entry its maps are in (`entry_of` finds the entry of
/// a project-relative texture path), with the slots that are.
pub fn material_entries(
    mesh: &Mesh,
    entries: &[AtlasEntry],
    entry_of: impl Fn(&Path) -> Option<usize>,
) -> Result<Vec<MaterialEntry>, RemapError> {
    let mut found = Vec::new();
    for material in &mesh.materials {
        let mut chosen: Option<(usize, Vec<TextureSlot>)> = None;
        for (&slot, path) in &material.maps {
            let Some(entry) = entry_of(path) else { continue };
            match &mut chosen {
                None => chosen = Some((entry, vec![slot])),
                Some((first, slots)) if *first == entry => slots.push(slot),
                Some((first, _)) => {
                    return Err(RemapError::TwoRectangles {
                        material: material.name.clone(),
                        first: entries[*first].name.clone(),
                        second: entries[entry].name.clone(),
                    })
                }
            }
        }
        found.push(chosen);
    }
    Ok(found)
}

/// The mesh with the UVs of atlased materials moved onto their entries, written as OBJ text
/// naming `material_library`; fails on the first atlased material with UVs outside [0, 1].
pub fn remap_mesh(
    mesh: &Mesh,
    entries: &[AtlasEntry],
    material_entries: &[MaterialEntry],
    material_library: &str,
    header: &str,
) -> Result<RemappedMesh, RemapError> {
    let uvs = mesh.uvs.as_deref().unwrap_or(&[]);
    // Every atlased material's UV range first: the whole mesh fails or none of it.
    for (material, chosen) in material_entries.iter().enumerate() {
        let Some((entry, _)) = chosen else { continue };
        repeating_uvs(mesh, material, &entries[*entry].name)?;
    }
    let mut obj = String::new();
    let _ = writeln!(obj, "# {header}\nmtllib {material_library}");
    for [x, y, z] in &mesh.positions {
        let _ = writeln!(obj, "v {x} {y} {z}");
    }
    for [x, y, z] in &mesh.normals {
        let _ = writeln!(obj, "vn {x} {y} {z}");
    }
    // One UV per (vertex, entry) used: a vertex shared by materials on different entries, or
    // by atlased and other materials, gets one UV for each.
    let mut uv_index: HashMap<(u32, Option<usize>), u32> = HashMap::new();
    let mut faces_by_material: BTreeMap<u32, Vec<[(u32, u32); 3]>> = BTreeMap::new();
    let has_uvs = mesh.uvs.is_some();
    for (triangle, &material) in mesh.triangles.iter().zip(&mesh.triangle_materials) {
        let entry = material_entries.get(material as usize).and_then(|chosen| chosen.as_ref().map(|(entry, _)| *entry));
        let corners = triangle.map(|vertex| {
            let next = uv_index.len() as u32;
            let uv = *uv_index.entry((vertex, entry)).or_insert_with(|| {
                let [u, v] = uvs.get(vertex as usize).copied().unwrap_or([0.0, 0.0]);
                let [u, v] = match entry {
                    Some(entry) => entries[entry].page_uv([u.clamp(0.0, 1.0) as f64, v.clamp(0.0, 1.0) as f64]).map(|c| c as f32),
                    None => [u, v],
                };
                if has_uvs {
                    let _ = writeln!(obj, "vt {u} {v}");
                }
                next
            });
            (vertex, uv)
        });
        faces_by_material.entry(material).or_default().push(corners);
    }
    for (material, faces) in &faces_by_material {
        let _ = writeln!(obj, "usemtl {}", mesh.materials[*material as usize].name);
        for face in faces {
            obj.push('f');
            for (vertex, uv) in face {
                if has_uvs {
                    let _ = write!(obj, " {0}/{1}/{0}", vertex + 1, uv + 1);
                } else {
                    let _ = write!(obj, " {0}//{0}", vertex + 1);
                }
            }
            obj.push('\n');
        }
    }
    let materials = mesh
        .materials
        .iter()
        .zip(material_entries)
        .enumerate()
        .filter(|(index, _)| faces_by_material.contains_key(&(*index as u32)))
        .map(|(_, (material, chosen))| RemappedMaterial {
            material: material.clone(),
            page: chosen.as_ref().map(|(entry, _)| entries[*entry].page),
            atlased: chosen.as_ref().map(|(_, slots)| slots.clone()).unwrap_or_default(),
        })
        .collect();
    Ok(RemappedMesh { obj, materials, warnings: Vec::new() })
}

/// Fails when the triangles of material `material` (index into the mesh's materials) use UVs
/// outside [0, 1]: they repeat the texture, which an atlas rectangle cannot (`entry` names the
/// atlased texture in the message).
pub fn repeating_uvs(mesh: &Mesh, material: usize, entry: &str) -> Result<(), RemapError> {
    let uvs = mesh.uvs.as_deref().unwrap_or(&[]);
    let mut range = [f32::INFINITY, f32::NEG_INFINITY, f32::INFINITY, f32::NEG_INFINITY];
    for (triangle, _) in mesh.triangles.iter().zip(&mesh.triangle_materials).filter(|(_, &used)| used as usize == material) {
        for &vertex in triangle {
            let [u, v] = uvs.get(vertex as usize).copied().unwrap_or([0.0, 0.0]);
            range = [range[0].min(u), range[1].max(u), range[2].min(v), range[3].max(v)];
        }
    }
    let outside = |low: f32, high: f32| low < -UV_TOLERANCE || high > 1.0 + UV_TOLERANCE;
    if range[0] <= range[1] && (outside(range[0], range[1]) || outside(range[2], range[3])) {
        return Err(RemapError::RepeatingUvs {
            material: mesh.materials[material].name.clone(),
            entry: entry.to_string(),
            u_min: range[0],
            u_max: range[1],
            v_min: range[2],
            v_max: range[3],
        });
    }
    Ok(())
}

/// One material of `atlas.mtl`: atlased maps name the page's image (`page_file`), the others
/// their source texture as seen from the MTL's folder (`path_from_mtl`).
pub fn mtl_material(material: &RemappedMaterial, page_file: impl Fn(u32) -> String, path_from_mtl: impl Fn(&Path) -> String) -> String {
    crate::mesh::obj_text::mtl_material_text(&material.material, |slot, path| match material.page {
        Some(page) if material.atlased.contains(&slot) => page_file(page),
        _ => path_from_mtl(path),
    })
}
