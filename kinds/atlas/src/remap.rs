//! Meshes remapped onto the atlas (DESIGN §3.5): each material whose maps are atlas entries (or
//! aliases of one) gets its UVs moved onto that texture's place on the page (its
//! `table::UvTransform`) and its maps pointed at the page; the OBJ is written again (positions,
//! normals, remapped UVs, faces by material) and the materials go into one `atlas.mtl`. Pure:
//! the kind's queries serve the mesh and the table.

use std::collections::{BTreeMap, HashMap};
use std::fmt::Write as _;
use std::path::Path;

use crate::mesh::{Mesh, MeshMaterial};
use crate::texture::TextureSlot;

use super::table::{AtlasEntry, UvTransform};

/// UVs this far outside [0, 1] still count as inside (exporters' rounding).
const UV_TOLERANCE: f32 = 1e-4;

/// A material of a remapped mesh, as `atlas.mtl` writes it.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub(crate) struct RemappedMaterial {
    pub material: MeshMaterial,
    /// The atlas page its atlased maps now point at, and which maps those are.
    pub page: Option<u32>,
    pub atlased: Vec<TextureSlot>,
}

/// A mesh remapped onto the atlas: the new OBJ's text and its materials.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub(crate) struct RemappedMesh {
    pub obj: String,
    pub materials: Vec<RemappedMaterial>,
    /// The same mesh for glTF: a vertex per (OBJ vertex, UV) pair, triangles numbering
    /// `materials`.
    pub geometry: crate::mesh::gltf::GltfGeometry,
    /// What loading or remapping the mesh warned of (a missing MTL, a map leaving the source
    /// folder, map options the atlas cannot keep).
    #[serde(default)]
    pub warnings: Vec<crate::diagnostic::Diagnostic>,
}

/// Why a mesh cannot be remapped.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub(crate) enum RemapError {
    #[error(
        "material `{material}` has UVs u ∈ [{u_min}, {u_max}], v ∈ [{v_min}, {v_max}] on the atlased texture \
            `{entry}`: repeating UVs (outside [0, 1]) cannot be remapped onto an atlas rectangle"
    )]
    RepeatingUvs { material: String, entry: String, u_min: f32, u_max: f32, v_min: f32, v_max: f32 },
    #[error(
        "material `{material}` uses the atlased textures `{first}` and `{second}`, which lie in different \
        rectangles or at different places in one: one UV set cannot address both"
    )]
    TwoRectangles { material: String, first: String, second: String },
    /// `why`: the read error (not found, a folder, a FIFO or device, too large…).
    #[error(
        "material `{material}` maps `{texture}`, which cannot be read ({why}): the remapped mesh would point at a \
         missing file"
    )]
    MissingMap { material: String, texture: String, why: String },
}

/// A texture a remapped material may name: an atlas entry's own texture or one of its aliases,
/// with where its coordinates land on the page.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct RemapTarget {
    /// The texture's path relative to the source folder.
    pub name: String,
    pub page: u32,
    pub transform: UvTransform,
}

/// Every texture the table can address: each entry's own, then its aliases.
pub(crate) fn remap_targets(entries: &[AtlasEntry]) -> Vec<RemapTarget> {
    let mut targets = Vec::new();
    for entry in entries {
        targets.push(RemapTarget { name: entry.name.clone(), page: entry.page, transform: entry.transform() });
        for alias in &entry.aliases {
            targets.push(RemapTarget {
                name: alias.name.clone(),
                page: entry.page,
                transform: alias.transform(entry.rotated),
            });
        }
    }
    targets
}

/// The target (index into the targets) a material's maps are in, and which of its maps those are.
pub(crate) type MaterialEntry = Option<(usize, Vec<TextureSlot>)>;

/// For each material of `mesh` that some triangle uses, the target its atlased maps are in
/// (`target_of` finds the target of a project-relative texture path), with the slots that are;
/// `None` for materials without atlased maps and for materials no triangle uses (a shared MTL's
/// other materials are none of this mesh's business).
pub(crate) fn material_entries(
    mesh: &Mesh,
    targets: &[RemapTarget],
    target_of: impl Fn(&Path) -> Option<usize>,
) -> Result<Vec<MaterialEntry>, RemapError> {
    let mut used = vec![false; mesh.materials.len()];
    for &material in &mesh.triangle_materials {
        if let Some(used) = used.get_mut(material as usize) {
            *used = true;
        }
    }
    let mut found = Vec::new();
    for (material, used) in mesh.materials.iter().zip(used) {
        let mut chosen: Option<(usize, Vec<TextureSlot>)> = None;
        for (&slot, path) in material.maps.iter().filter(|_| used) {
            let Some(target) = target_of(path) else { continue };
            match &mut chosen {
                None => chosen = Some((target, vec![slot])),
                Some((first, slots))
                    if targets[*first].page == targets[target].page
                        && targets[*first].transform == targets[target].transform =>
                {
                    slots.push(slot)
                }
                Some((first, _)) => {
                    return Err(RemapError::TwoRectangles {
                        material: material.name.clone(),
                        first: targets[*first].name.clone(),
                        second: targets[target].name.clone(),
                    })
                }
            }
        }
        found.push(chosen);
    }
    Ok(found)
}

/// The scale and offset an atlased map's options give its texture coordinates (`-s`, `-o`:
/// `uv × scale + offset`), and the options the atlas cannot keep (every other one).
fn map_transform(options: &str) -> ([f32; 2], [f32; 2], Vec<String>) {
    let (mut scale, mut offset, mut dropped) = ([1.0f32; 2], [0.0f32; 2], Vec::new());
    let words: Vec<&str> = options.split_whitespace().collect();
    let mut index = 0;
    while index < words.len() {
        let option = words[index];
        index += 1;
        let numbers: Vec<f32> = words[index..].iter().map_while(|word| word.parse::<f32>().ok()).take(3).collect();
        index += numbers.len();
        match option {
            "-s" if !numbers.is_empty() => scale = [numbers[0], numbers.get(1).copied().unwrap_or(1.0)],
            "-o" if !numbers.is_empty() => offset = [numbers[0], numbers.get(1).copied().unwrap_or(0.0)],
            _ => {
                // An option's non-numeric argument (`-clamp on`, `-imfchan r`) is dropped with it.
                let mut words_of_option = vec![option.to_string()];
                words_of_option.extend(numbers.iter().map(f32::to_string));
                if numbers.is_empty() && index < words.len() && !words[index].starts_with('-') {
                    words_of_option.push(words[index].to_string());
                    index += 1;
                }
                dropped.push(words_of_option.join(" "));
            }
        }
    }
    (scale, offset, dropped)
}

/// The texture coordinates of an atlased material before the remap: its UVs with its atlased
/// map's `-s` and `-o` applied (what the texture is sampled at), and the options dropped. The
/// slots of one material share a UV set: the first atlased slot's options stand for all.
fn material_uv_transform(
    material: &MeshMaterial,
    slots: &[TextureSlot],
) -> (impl Fn([f32; 2]) -> [f32; 2], Vec<String>) {
    let options = slots.iter().find_map(|slot| material.map_options.get(slot)).cloned().unwrap_or_default();
    let (scale, offset, dropped) = map_transform(&options);
    (move |[u, v]: [f32; 2]| [u * scale[0] + offset[0], v * scale[1] + offset[1]], dropped)
}

/// The mesh with the UVs of atlased materials moved onto their textures' places, written as
/// OBJ text naming `mtl`; fails on the first atlased material with UVs outside
/// [0, 1] (after its map's `-s` and `-o`). Gives warnings for map options it drops.
pub(crate) fn remap_mesh(
    mesh: &Mesh,
    targets: &[RemapTarget],
    material_entries: &[MaterialEntry],
    material_library: &str,
    header: &str,
) -> Result<RemappedMesh, RemapError> {
    let uvs = mesh.uvs.as_deref().unwrap_or(&[]);
    // Every atlased material's UV range first: the whole mesh fails or none of it.
    let mut warnings = Vec::new();
    let mut sampled_at = Vec::with_capacity(material_entries.len());
    for (material, chosen) in material_entries.iter().enumerate() {
        let Some((target, slots)) = chosen else {
            sampled_at.push(None);
            continue;
        };
        let (transform, dropped) = material_uv_transform(&mesh.materials[material], slots);
        repeating_uvs_through(mesh, material, &targets[*target].name, &transform)?;
        if !dropped.is_empty() {
            warnings.push(format!(
                "material `{}`: the map options {} of `{}` do not apply to an atlas rectangle and are dropped",
                mesh.materials[material].name,
                dropped.iter().map(|option| format!("`{option}`")).collect::<Vec<_>>().join(", "),
                targets[*target].name
            ));
        }
        sampled_at.push(Some(transform));
    }
    let mut obj = String::new();
    let _ = writeln!(obj, "# {header}\nmtllib {material_library}");
    for [x, y, z] in &mesh.positions {
        let _ = writeln!(obj, "v {x} {y} {z}");
    }
    for [x, y, z] in &mesh.normals {
        let _ = writeln!(obj, "vn {x} {y} {z}");
    }
    // One UV per (vertex, material) of an atlased material, one per vertex elsewhere: a vertex
    // shared by materials on different textures, or by atlased and other materials, gets one
    // UV for each.
    let mut uv_index: HashMap<(u32, Option<u32>), u32> = HashMap::new();
    let mut faces_by_material: BTreeMap<u32, Vec<[(u32, u32); 3]>> = BTreeMap::new();
    let has_uvs = mesh.uvs.is_some();
    let mut geometry = crate::mesh::gltf::GltfGeometry::default();
    let mut gltf_materials = Vec::with_capacity(mesh.triangles.len());
    for (triangle, &material) in mesh.triangles.iter().zip(&mesh.triangle_materials) {
        let chosen =
            material_entries.get(material as usize).and_then(|chosen| chosen.as_ref().map(|(target, _)| *target));
        let corners = triangle.map(|vertex| {
            let next = uv_index.len() as u32;
            let uv = *uv_index.entry((vertex, chosen.map(|_| material))).or_insert_with(|| {
                let uv = uvs.get(vertex as usize).copied().unwrap_or([0.0, 0.0]);
                let [u, v] = match (chosen, sampled_at.get(material as usize).and_then(Option::as_ref)) {
                    (Some(target), Some(transform)) => {
                        let [u, v] = transform(uv);
                        targets[target]
                            .transform
                            .page_uv([u.clamp(0.0, 1.0) as f64, v.clamp(0.0, 1.0) as f64])
                            .map(|c| c as f32)
                    }
                    _ => uv,
                };
                if has_uvs {
                    let _ = writeln!(obj, "vt {u} {v}");
                    geometry.uvs.push([u, v]);
                }
                geometry.positions.push(mesh.positions[vertex as usize]);
                geometry.normals.push(mesh.normals.get(vertex as usize).copied().unwrap_or([0.0, 0.0, 1.0]));
                next
            });
            (vertex, uv)
        });
        geometry.triangles.push(corners.map(|(_, uv)| uv));
        gltf_materials.push(material);
        faces_by_material.entry(material).or_default().push(corners);
    }
    // Triangles number the used materials, as `materials` below lists them.
    let used: Vec<u32> = faces_by_material.keys().copied().collect();
    geometry.triangle_materials =
        gltf_materials.iter().map(|material| used.binary_search(material).unwrap_or(0) as u32).collect();
    let geometry = geometry.with_tangents();
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
            page: chosen.as_ref().map(|(target, _)| targets[*target].page),
            atlased: chosen.as_ref().map(|(_, slots)| slots.clone()).unwrap_or_default(),
        })
        .collect();
    let warnings =
        warnings.into_iter().map(|message| crate::diagnostic::Diagnostic::new(Path::new(header), message)).collect();
    Ok(RemappedMesh { obj, materials, geometry, warnings })
}

/// The texture coordinates a material of a mesh uses on an atlased texture: their range.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub(crate) struct UvReach {
    pub u: [f32; 2],
    pub v: [f32; 2],
}

impl UvReach {
    pub fn union(self, other: UvReach) -> UvReach {
        UvReach {
            u: [self.u[0].min(other.u[0]), self.u[1].max(other.u[1])],
            v: [self.v[0].min(other.v[0]), self.v[1].max(other.v[1])],
        }
    }
}

/// Fails when the triangles of material `material` (index into the mesh's materials) use UVs
/// outside [0, 1]: they repeat the texture, which an atlas rectangle cannot (`entry` names the
/// atlased texture in the message).
pub(crate) fn repeating_uvs(mesh: &Mesh, material: usize, entry: &str) -> Result<(), RemapError> {
    repeating_uvs_through(mesh, material, entry, &|uv| uv)
}

/// [`repeating_uvs`] of the coordinates `transform` makes of the UVs (a map's `-s` and `-o`).
fn repeating_uvs_through(
    mesh: &Mesh,
    material: usize,
    entry: &str,
    transform: &dyn Fn([f32; 2]) -> [f32; 2],
) -> Result<(), RemapError> {
    let Some(range) = material_uv_range(mesh, material, transform) else { return Ok(()) };
    let outside = |low: f32, high: f32| low < -UV_TOLERANCE || high > 1.0 + UV_TOLERANCE;
    if outside(range[0], range[1]) || outside(range[2], range[3]) {
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

/// `[u_min, u_max, v_min, v_max]` of the finite texture coordinates (through `transform`) of a
/// material's triangles; `None` when it has none.
fn material_uv_range(mesh: &Mesh, material: usize, transform: &dyn Fn([f32; 2]) -> [f32; 2]) -> Option<[f32; 4]> {
    let uvs = mesh.uvs.as_deref().unwrap_or(&[]);
    let mut range = [f32::INFINITY, f32::NEG_INFINITY, f32::INFINITY, f32::NEG_INFINITY];
    for (triangle, _) in
        mesh.triangles.iter().zip(&mesh.triangle_materials).filter(|(_, &used)| used as usize == material)
    {
        for &vertex in triangle {
            let [u, v] = transform(uvs.get(vertex as usize).copied().unwrap_or([0.0, 0.0]));
            if u.is_finite() && v.is_finite() {
                range = [range[0].min(u), range[1].max(u), range[2].min(v), range[3].max(v)];
            }
        }
    }
    (range[0] <= range[1]).then_some(range)
}

/// Where the materials of `mesh` that some triangle uses sample each texture `atlased` accepts
/// (any slot): the range of their texture coordinates (after the map's `-s` and `-o`), per
/// texture, over the materials that map it.
pub(crate) fn material_uv_reach(mesh: &Mesh, atlased: impl Fn(&Path) -> bool) -> Vec<(std::path::PathBuf, UvReach)> {
    let mut reach: BTreeMap<std::path::PathBuf, UvReach> = BTreeMap::new();
    for (index, material) in mesh.materials.iter().enumerate() {
        let slots: Vec<TextureSlot> =
            material.maps.iter().filter(|(_, path)| atlased(path)).map(|(&slot, _)| slot).collect();
        if slots.is_empty() {
            continue;
        }
        let (transform, _) = material_uv_transform(material, &slots);
        let Some([u_min, u_max, v_min, v_max]) = material_uv_range(mesh, index, &transform) else { continue };
        let range = UvReach { u: [u_min, u_max], v: [v_min, v_max] };
        for slot in slots {
            let path = material.maps[&slot].clone();
            reach.entry(path).and_modify(|known| *known = known.union(range)).or_insert(range);
        }
    }
    reach.into_iter().collect()
}
