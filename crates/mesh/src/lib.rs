//! Meshes: OBJ + MTL (through `tobj`) turned into one triangle list with positions, normals
//! (computed where missing), optional UVs and a material per triangle, each material with the
//! maps of DESIGN §2.2 and constant fallbacks. Pure: the driver serves the MTL bytes.

pub mod gltf;
pub mod obj_text;
pub mod occlusion;
pub mod pn_triangles;
pub mod octahedral;
pub mod reduce;
pub mod surface_distance;
mod ray_kernels;
pub mod rays;
pub mod uv_raster;

use std::collections::BTreeMap;
use std::io::BufReader;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use base::diagnostic::Diagnostic;
use base::paths::normalize_relative_path;
use texture::TextureSlot;

/// Appended to the name of the copy of a material that faces without texture coordinates use
/// (they take its constants, not its maps).
pub const WITHOUT_UVS_SUFFIX: &str = " (no UVs)";

/// One material of a mesh.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MeshMaterial {
    pub name: String,
    /// `Kd`: multiplies the albedo map, or is the albedo without one (linear RGB).
    pub albedo_factor: [f32; 3],
    /// `d`: constant opacity.
    pub opacity: f32,
    pub metallic: f32,
    pub roughness: f32,
    /// Texture maps, project-relative paths.
    pub maps: BTreeMap<TextureSlot, PathBuf>,
    /// The MTL declares a cut-out surface: a `map_d`, or `d` below 1.
    #[serde(default)]
    pub cut_out: bool,
    /// The options a map's statement gave before its file name (`-s 2 2 1`, `-bm 0.5`), by slot.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub map_options: BTreeMap<TextureSlot, String>,
}

impl Default for MeshMaterial {
    fn default() -> Self {
        MeshMaterial {
            name: "default".into(),
            albedo_factor: [0.8; 3],
            opacity: 1.0,
            metallic: 0.0,
            roughness: 1.0,
            maps: BTreeMap::new(),
            cut_out: false,
            map_options: BTreeMap::new(),
        }
    }
}

/// A triangle mesh with one index per corner into shared vertex arrays.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct Mesh {
    pub positions: Vec<[f32; 3]>,
    pub normals: Vec<[f32; 3]>,
    /// Per vertex; `None` when the file has no texture coordinates (constant colours are baked).
    pub uvs: Option<Vec<[f32; 2]>>,
    pub triangles: Vec<[u32; 3]>,
    /// Index into `materials` per triangle.
    pub triangle_materials: Vec<u32>,
    pub materials: Vec<MeshMaterial>,
    /// Index into `objects` per triangle: the OBJ object (`o`) or group (`g`) it was written in.
    pub triangle_objects: Vec<u32>,
    /// The OBJ's objects by name, in file order (one unnamed object when it names none).
    pub objects: Vec<String>,
}

/// The root of `index`'s set in a union-find forest (`parent[i] == i` at a root), halving the
/// path on the way up.
pub fn union_find_root(parent: &mut [usize], mut index: usize) -> usize {
    while parent[index] != index {
        parent[index] = parent[parent[index]];
        index = parent[index];
    }
    index
}

/// Per vertex, the id of its position among the distinct positions (by exact coordinates: a
/// seam in the normals or texture coordinates splits vertices, not the surface), and how many
/// distinct positions there are.
pub fn position_ids(positions: &[[f32; 3]]) -> (Vec<u32>, usize) {
    let mut ids: std::collections::HashMap<[u32; 3], u32> = std::collections::HashMap::new();
    let per_vertex = positions
        .iter()
        .map(|position| {
            let next = ids.len() as u32;
            *ids.entry(position.map(f32::to_bits)).or_insert(next)
        })
        .collect();
    (per_vertex, ids.len())
}

/// Each material's triangles (indices, in order) of a mesh with `triangle_count` triangles:
/// one list per material (at least one); a triangle past the end of `triangle_materials` is the
/// first material's, one naming a material past the last is the last's.
pub(crate) fn triangles_by_material(
    triangle_materials: &[u32],
    triangle_count: usize,
    material_count: usize,
) -> Vec<Vec<usize>> {
    let mut by_material: Vec<Vec<usize>> = vec![Vec::new(); material_count.max(1)];
    let last = by_material.len() - 1;
    for triangle in 0..triangle_count {
        let material = triangle_materials.get(triangle).map_or(0, |&material| (material as usize).min(last));
        by_material[material].push(triangle);
    }
    by_material
}

/// The `mtllib` files an OBJ names, resolved (project-relative) next to it; those outside the
/// source folder `source_root` are left out (`load_mesh` then warns that they are not found).
pub fn material_libraries(obj_file: &Path, obj_bytes: &[u8], source_root: &Path) -> Vec<PathBuf> {
    let text = String::from_utf8_lossy(obj_bytes);
    let folder = obj_file.parent().unwrap_or(Path::new(""));
    let mut libraries = Vec::new();
    for line in text.lines() {
        let line = line.trim_start();
        if let Some(rest) = line.strip_prefix("mtllib") {
            if rest.starts_with(char::is_whitespace) {
                if let Some(path) = normalize_relative_path(&folder.join(rest.trim().replace('\\', "/"))) {
                    if path.starts_with(source_root) && !libraries.contains(&path) {
                        libraries.push(path);
                    }
                }
            }
        }
    }
    libraries
}

/// Loads the OBJ `obj_bytes` read from `obj_file`; `libraries` serves the bytes of the MTL files
/// that `material_libraries` named (a missing one is `None`: its materials fall back to
/// defaults with a warning). Texture paths must stay inside `source_root`.
// Long: one pass over tobj's models, whose per-model checks (index bounds, UVs, normals,
// objects without UVs) share the running offsets of the merged arrays.
pub fn load_mesh(
    obj_file: &Path,
    obj_bytes: &[u8],
    libraries: &BTreeMap<PathBuf, Option<Vec<u8>>>,
    source_root: &Path,
) -> Result<(Mesh, Vec<Diagnostic>), Diagnostic> {
    let text = decode_text(obj_file, obj_bytes)?;
    let folder = obj_file.parent().unwrap_or(Path::new("")).to_path_buf();
    let warnings = std::cell::RefCell::new(Vec::new());
    // The MTL file that defined each material, for warnings that name it.
    let material_files = std::cell::RefCell::new(BTreeMap::<String, PathBuf>::new());
    let options = tobj::LoadOptions { single_index: true, triangulate: true, ignore_points: true, ignore_lines: true };
    let loader = |name: &Path| -> tobj::MTLLoadResult {
        let written = name.to_string_lossy().replace('\\', "/");
        let path = normalize_relative_path(&folder.join(&written)).filter(|path| path.starts_with(source_root));
        let Some(path) = path else {
            warnings.borrow_mut().push(Diagnostic::new(
                obj_file,
                format!(
                    "material library \"{written}\" lies outside the source folder; ignored, default materials used"
                ),
            ));
            return Err(tobj::LoadError::OpenFileFailed);
        };
        match libraries.get(&path) {
            Some(Some(bytes)) => load_mtl(bytes)
                .inspect(|(materials, _)| {
                    let mut files = material_files.borrow_mut();
                    for material in materials {
                        files.entry(material.name.clone()).or_insert_with(|| path.clone());
                    }
                })
                .inspect_err(|error| {
                    warnings
                        .borrow_mut()
                        .push(Diagnostic::new(&path, format!("malformed MTL ({error}); its materials use defaults")));
                }),
            _ => {
                warnings.borrow_mut().push(Diagnostic::new(
                    obj_file,
                    format!(
                        "material library {} not found; default materials used",
                        base::diagnostic::display_path(&path)
                    ),
                ));
                Err(tobj::LoadError::OpenFileFailed)
            }
        }
    };
    let loaded = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        tobj::load_obj_buf(&mut BufReader::new(text.as_bytes()), &options, loader)
    }));
    let (models, materials) = match loaded {
        Ok(Ok(result)) => result,
        Ok(Err(error)) => {
            let message = format!("malformed OBJ: {error}");
            return Err(match obj_error_line(&text, &error) {
                Some(line) => Diagnostic::at(obj_file, base::diagnostic::TextPosition { line, column: 1 }, message),
                None => Diagnostic::new(obj_file, message),
            });
        }
        Err(_) => return Err(Diagnostic::new(obj_file, "malformed OBJ: the parser failed on this file")),
    };
    let mut warnings = warnings.into_inner();
    let material_files = material_files.into_inner();
    let tobj_materials = materials.unwrap_or_default();
    let mut materials: Vec<MeshMaterial> = Vec::new();
    for material in &tobj_materials {
        let library = material_files.get(&material.name).cloned().unwrap_or_else(|| obj_file.to_path_buf());
        materials.push(mesh_material(material, &library, source_root, &mut warnings));
    }
    let default_material = materials.len() as u32;
    materials.push(MeshMaterial::default());
    warnings.extend(undefined_material_uses(obj_file, &text, &tobj_materials));

    let mut mesh = Mesh { uvs: Some(Vec::new()), ..Mesh::default() };
    let mut all_normals = true;
    // Objects without texture coordinates (their vertices get UV 0, their faces a copy of their
    // material without maps); when no object has any, the mesh has no UVs at all.
    let mut objects_without_uvs = Vec::new();
    let mut faces_without_uvs = Vec::new();
    for model in &models {
        let source = &model.mesh;
        let base = mesh.positions.len() as u32;
        let vertex_count = source.positions.len() / 3;
        for (index, position) in source.positions.chunks_exact(3).enumerate() {
            if position.iter().any(|c| !c.is_finite()) {
                return Err(Diagnostic::new(
                    obj_file,
                    format!("object `{}`: vertex {} has a non-finite position", model.name, index + 1),
                ));
            }
            mesh.positions.push([position[0], position[1], position[2]]);
        }
        let has_normals = source.normals.len() == source.positions.len();
        all_normals &= has_normals;
        if has_normals {
            mesh.normals.extend(source.normals.chunks_exact(3).map(|n| [n[0], n[1], n[2]]));
        } else {
            mesh.normals.extend(std::iter::repeat_n([0.0; 3], vertex_count));
        }
        let uvs = mesh.uvs.get_or_insert_with(Vec::new);
        let has_uvs = source.texcoords.len() == vertex_count * 2;
        if has_uvs {
            uvs.extend(source.texcoords.chunks_exact(2).map(|uv| [uv[0], uv[1]]));
        } else {
            uvs.extend(std::iter::repeat_n([0.0; 2], vertex_count));
            if !source.indices.is_empty() {
                objects_without_uvs.push(model.name.clone());
            }
        }
        let material = source.material_id.map_or(default_material, |id| (id as u32).min(default_material));
        // tobj starts a model at each `usemtl` too, under the object's name.
        let object = match mesh.objects.iter().position(|name| name == &model.name) {
            Some(object) => object as u32,
            None => {
                mesh.objects.push(model.name.clone());
                mesh.objects.len() as u32 - 1
            }
        };
        for triangle in source.indices.chunks_exact(3) {
            if triangle.iter().any(|&index| index as usize >= vertex_count) {
                return Err(Diagnostic::new(
                    obj_file,
                    format!("object `{}`: a face index is out of range", model.name),
                ));
            }
            if !has_uvs {
                faces_without_uvs.push(mesh.triangles.len());
            }
            mesh.triangles.push([base + triangle[0], base + triangle[1], base + triangle[2]]);
            mesh.triangle_materials.push(material);
            mesh.triangle_objects.push(object);
        }
    }
    if mesh.triangles.is_empty() {
        return Err(Diagnostic::new(obj_file, "the OBJ has no faces"));
    }
    check_scale(obj_file, &mesh)?;
    if faces_without_uvs.len() == mesh.triangles.len() {
        mesh.uvs = None;
        warnings.extend(without_maps_for_want_of_uvs(obj_file, &mut materials, &mesh.triangle_materials));
    } else if !faces_without_uvs.is_empty() {
        for name in &objects_without_uvs {
            warnings.push(Diagnostic::new(
                obj_file,
                format!(
                    "object `{name}` has no texture coordinates: its faces take their materials' constants, not \
                    their maps (and are not baked in UV space)"
                ),
            ));
        }
        // Each material those faces use, once more without maps.
        let mut without_maps: BTreeMap<u32, u32> = BTreeMap::new();
        for face in faces_without_uvs {
            let material = mesh.triangle_materials[face];
            let copy = *without_maps.entry(material).or_insert_with(|| {
                let mut copy = materials[material as usize].clone();
                copy.name = format!("{}{WITHOUT_UVS_SUFFIX}", copy.name);
                copy.maps.clear();
                materials.push(copy);
                materials.len() as u32 - 1
            });
            mesh.triangle_materials[face] = copy;
        }
    }
    if !all_normals || mesh.normals.iter().any(|n| !n.iter().all(|c| c.is_finite()) || n == &[0.0; 3]) {
        compute_normals(&mut mesh);
    }
    if mesh.uvs.as_ref().is_some_and(|uvs| uvs.iter().any(|uv| !uv[0].is_finite() || !uv[1].is_finite())) {
        // A `nan` or `inf` in a `vt` line is bad input, not a mesh without texture coordinates.
        let message = "a texture coordinate (`vt`) is not a finite number";
        return Err(match first_non_finite_statement(&text, "vt") {
            Some(position) => Diagnostic::at(obj_file, position, message),
            None => Diagnostic::new(obj_file, message),
        });
    }
    mesh.materials = materials;
    Ok((mesh, warnings))
}

/// The maps of every material of `materials` that `triangle_materials` uses dropped, for a mesh
/// without texture coordinates (nothing could place them), and a warning naming those that had
/// any (`None`: none had): their faces take the constants, as an object without UVs in a mesh
/// with them does.
fn without_maps_for_want_of_uvs(
    obj_file: &Path,
    materials: &mut [MeshMaterial],
    triangle_materials: &[u32],
) -> Option<Diagnostic> {
    let used: std::collections::BTreeSet<u32> = triangle_materials.iter().copied().collect();
    let mut named = Vec::new();
    for index in used {
        let material = &mut materials[index as usize];
        if !material.maps.is_empty() {
            named.push(format!("`{}`", material.name));
            material.maps.clear();
            material.map_options.clear();
        }
    }
    (!named.is_empty()).then(|| {
        Diagnostic::new(
            obj_file,
            format!(
                "the OBJ has no texture coordinates: the maps of {} are not drawn (nor read); its faces take \
                 their materials' constants",
                named.join(", ")
            ),
        )
    })
}

/// Where the first `keyword` statement (`vt`, `v`) with a number that is not finite starts.
fn first_non_finite_statement(text: &str, keyword: &str) -> Option<base::diagnostic::TextPosition> {
    let mut offset = 0;
    for line in text.split_inclusive('\n') {
        let mut words = line.split_whitespace();
        if words.next() == Some(keyword) && words.any(|word| word.parse::<f32>().is_ok_and(|value| !value.is_finite()))
        {
            let indent = line.len() - line.trim_start().len();
            return Some(base::diagnostic::TextPosition::of_byte_offset(text, offset + indent));
        }
        offset += line.len();
    }
    None
}

/// Per material of `mesh` whose triangles use texture coordinates outside [0, 1] (beyond
/// `1e-4`): the material, how many of its triangles do, of how many, and the UV range
/// `[u_min, u_max, v_min, v_max]`. A bake in UV space covers [0, 1]: those texels are not in it.
pub fn uvs_outside_unit_square(mesh: &Mesh) -> Vec<(usize, usize, usize, [f32; 4])> {
    let Some(uvs) = mesh.uvs.as_deref() else { return Vec::new() };
    let mut per_material: BTreeMap<usize, (usize, usize, [f32; 4])> = BTreeMap::new();
    for (triangle, &material) in mesh.triangles.iter().zip(&mesh.triangle_materials) {
        let entry = per_material.entry(material as usize).or_insert((
            0,
            0,
            [f32::INFINITY, f32::NEG_INFINITY, f32::INFINITY, f32::NEG_INFINITY],
        ));
        entry.1 += 1;
        let mut outside = false;
        for &vertex in triangle {
            let [u, v] = uvs[vertex as usize];
            outside |= !(-1e-4..=1.0 + 1e-4).contains(&u) || !(-1e-4..=1.0 + 1e-4).contains(&v);
            entry.2 = [entry.2[0].min(u), entry.2[1].max(u), entry.2[2].min(v), entry.2[3].max(v)];
        }
        entry.0 += usize::from(outside);
    }
    per_material
        .into_iter()
        .filter(|(_, (outside, _, _))| *outside > 0)
        .map(|(material, (outside, total, range))| (material, outside, total, range))
        .collect()
}

/// The warnings of [`uvs_outside_unit_square`] for a mesh baked in UV space.
pub fn uvs_outside_warnings(obj_file: &Path, mesh: &Mesh) -> Vec<Diagnostic> {
    uvs_outside_unit_square(mesh)
        .into_iter()
        .map(|(material, outside, total, [u_min, u_max, v_min, v_max])| {
            Diagnostic::new(
                obj_file,
                format!(
                    "material `{}`: {outside} of its {total} triangles have texture coordinates outside [0, 1] (u ∈ \
                        [{u_min}, {u_max}], v ∈ [{v_min}, {v_max}]): a map covers [0, 1] only, so the parts outside \
                        are not baked",
                    mesh.materials[material].name
                ),
            )
        })
        .collect()
}

fn decode_text<'a>(file: &Path, bytes: &'a [u8]) -> Result<std::borrow::Cow<'a, str>, Diagnostic> {
    // UTF-16 with a byte-order mark (some exporters write it).
    if bytes.len() >= 2 && (bytes[..2] == [0xFE, 0xFF] || bytes[..2] == [0xFF, 0xFE]) {
        let big_endian = bytes[0] == 0xFE;
        let units: Vec<u16> = bytes[2..]
            .chunks_exact(2)
            .map(|pair| {
                if big_endian {
                    u16::from_be_bytes([pair[0], pair[1]])
                } else {
                    u16::from_le_bytes([pair[0], pair[1]])
                }
            })
            .collect();
        return String::from_utf16(&units)
            .map(std::borrow::Cow::Owned)
            .map_err(|_| Diagnostic::new(file, "invalid UTF-16 text"));
    }
    let bytes = bytes.strip_prefix(&[0xEF, 0xBB, 0xBF]).unwrap_or(bytes);
    Ok(String::from_utf8_lossy(bytes))
}

/// Parses MTL bytes with tobj, whose parser panics on a colour statement with fewer than three
/// numbers (`Kd 0.5 3`): such a file is a parse error before tobj sees it, and any other panic
/// is one too.
fn load_mtl(bytes: &[u8]) -> tobj::MTLLoadResult {
    let text = String::from_utf8_lossy(bytes);
    let short_colour = text.lines().any(|line| {
        let mut words = line.split_whitespace();
        matches!(words.next(), Some("Ka" | "Kd" | "Ks" | "Ke")) && words.count() < 3
    });
    if short_colour {
        return Err(tobj::LoadError::MaterialParseError);
    }
    std::panic::catch_unwind(|| tobj::load_mtl_buf(&mut BufReader::new(text.as_bytes())))
        .unwrap_or(Err(tobj::LoadError::MaterialParseError))
}

/// Largest bounding-box diagonal accepted, in world units: the stages compute in single
/// precision, and squared distances of larger meshes overflow it.
pub(crate) const MAX_MESH_EXTENT: f64 = 1e9;
/// Smallest bounding-box diagonal accepted: areas and squared distances of smaller meshes fall
/// below single precision's normal range.
pub(crate) const MIN_MESH_EXTENT: f64 = 1e-6;

/// Refuses meshes that single precision cannot bake: coordinates so large or so small that the
/// stages' squared distances overflow or vanish, and meshes whose every face has zero area.
fn check_scale(obj_file: &Path, mesh: &Mesh) -> Result<(), Diagnostic> {
    let (mut min, mut max) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for &index in mesh.triangles.iter().flatten() {
        let position = mesh.positions[index as usize];
        for axis in 0..3 {
            min[axis] = min[axis].min(f64::from(position[axis]));
            max[axis] = max[axis].max(f64::from(position[axis]));
        }
    }
    let extent = (0..3).map(|axis| (max[axis] - min[axis]).powi(2)).sum::<f64>().sqrt();
    if extent > MAX_MESH_EXTENT {
        return Err(Diagnostic::new(
            obj_file,
            format!(
                "the mesh spans {extent:.3e} units, more than the {MAX_MESH_EXTENT:.0e} that single precision can \
                bake: scale it down"
            ),
        ));
    }
    let area: f64 = mesh
        .triangles
        .iter()
        .map(|triangle| {
            let [a, b, c] = triangle.map(|index| glam::DVec3::from(mesh.positions[index as usize].map(f64::from)));
            0.5 * (b - a).cross(c - a).length()
        })
        .sum();
    if area == 0.0 {
        return Err(Diagnostic::new(obj_file, "every face of the mesh has zero area: there is nothing to bake"));
    }
    if extent < MIN_MESH_EXTENT {
        return Err(Diagnostic::new(
            obj_file,
            format!(
                "the mesh spans {extent:.3e} units, less than the {MIN_MESH_EXTENT:.0e} that single precision can \
                bake: scale it up"
            ),
        ));
    }
    Ok(())
}

/// The line a tobj error comes from (tobj does not say): the first statement of the kind the
/// error names that fails the same test, found by scanning the text again. `None` when the
/// error names no statement or no line fails the test.
fn obj_error_line(text: &str, error: &tobj::LoadError) -> Option<u32> {
    use tobj::LoadError;
    let floats = |words: &[&str], count: usize| {
        words.len() >= count && words[..count].iter().all(|word| word.parse::<f32>().is_ok())
    };
    let totals = text.lines().fold([0i64; 3], |mut totals, line| {
        match line.split_whitespace().next() {
            Some("v") => totals[0] += 1,
            Some("vt") => totals[1] += 1,
            Some("vn") => totals[2] += 1,
            _ => {}
        }
        totals
    });
    let mut seen = [0i64; 3];
    for (index, line) in text.lines().enumerate() {
        let words: Vec<&str> = line.split_whitespace().collect();
        let Some((&keyword, arguments)) = words.split_first() else { continue };
        let failing = match (keyword, error) {
            ("v", LoadError::PositionParseError) => !floats(arguments, 3),
            ("vt", LoadError::TexcoordParseError) => !floats(arguments, 2),
            ("vn", LoadError::NormalParseError) => !floats(arguments, 3),
            ("f", LoadError::InvalidPolygon) => arguments.len() < 3,
            (
                "f",
                LoadError::FaceParseError
                | LoadError::FaceVertexOutOfBounds
                | LoadError::FaceTexCoordOutOfBounds
                | LoadError::FaceNormalOutOfBounds,
            ) => arguments.iter().any(|vertex| {
                vertex.split('/').enumerate().any(|(slot, index)| {
                    let checked = match error {
                        LoadError::FaceVertexOutOfBounds => slot == 0,
                        LoadError::FaceTexCoordOutOfBounds => slot == 1,
                        LoadError::FaceNormalOutOfBounds => slot == 2,
                        _ => slot < 3,
                    };
                    // Positive indices may point forward (checked against the file's total),
                    // negative ones back from here.
                    let valid = |value: i64| {
                        (value > 0 && value <= totals[slot.min(2)]) || (value < 0 && -value <= seen[slot.min(2)])
                    };
                    checked
                        && !(index.is_empty() && slot > 0)
                        && index.parse::<i64>().map_or(true, |value| !valid(value))
                })
            }),
            _ => false,
        };
        if failing {
            return Some(index as u32 + 1);
        }
        match keyword {
            "v" => seen[0] += 1,
            "vt" => seen[1] += 1,
            "vn" => seen[2] += 1,
            _ => {}
        }
    }
    None
}

/// A warning for each `usemtl` that names no material of the MTL libraries (tobj silently gives
/// those faces the default material).
fn undefined_material_uses(obj_file: &Path, text: &str, materials: &[tobj::Material]) -> Vec<Diagnostic> {
    let mut warned = std::collections::BTreeSet::new();
    let mut warnings = Vec::new();
    for (index, line) in text.lines().enumerate() {
        let Some(name) = line
            .trim_start()
            .strip_prefix("usemtl")
            .filter(|rest| rest.starts_with(char::is_whitespace))
            .map(str::trim)
        else {
            continue;
        };
        if !name.is_empty()
            && !materials.iter().any(|material| material.name == name)
            && warned.insert(name.to_string())
        {
            warnings.push(Diagnostic::at(
                obj_file,
                base::diagnostic::TextPosition { line: index as u32 + 1, column: 1 },
                format!(
                    "`usemtl {name}` names no material of the mesh's MTL files: those faces use the default material"
                ),
            ));
        }
    }
    warnings
}

fn mesh_material(
    material: &tobj::Material,
    library: &Path,
    source_root: &Path,
    warnings: &mut Vec<Diagnostic>,
) -> MeshMaterial {
    let mut result = MeshMaterial { name: material.name.clone(), ..MeshMaterial::default() };
    if let Some(diffuse) = material.diffuse {
        result.albedo_factor = diffuse.map(|c| c.clamp(0.0, 1.0));
    }
    if let Some(dissolve) = material.dissolve {
        result.opacity = dissolve.clamp(0.0, 1.0);
    }
    result.cut_out = result.opacity < 1.0 || material.dissolve_texture.is_some();
    let unknown = |key: &str| material.unknown_param.get(key).cloned();
    if let Some(value) = unknown("Pm").and_then(|v| v.trim().parse::<f32>().ok()) {
        result.metallic = value.clamp(0.0, 1.0);
    }
    if let Some(value) = unknown("Pr").and_then(|v| v.trim().parse::<f32>().ok()) {
        result.roughness = value.clamp(0.0, 1.0);
    }
    let statements = [
        (TextureSlot::Albedo, material.diffuse_texture.clone()),
        (TextureSlot::Opacity, material.dissolve_texture.clone()),
        (TextureSlot::Normal, unknown("norm").or_else(|| material.normal_texture.clone())),
        (TextureSlot::Metallic, unknown("map_Pm")),
        (TextureSlot::Roughness, unknown("map_Pr")),
        (TextureSlot::Ao, unknown("map_ao").or_else(|| unknown("map_AO"))),
    ];
    // A map's path is relative to the MTL file that names it (as Blender, three.js's MTLLoader and
    // Assimp read it; the same folder as the OBJ's unless `mtllib` names another).
    let folder = library.parent().unwrap_or(Path::new(""));
    for (slot, statement) in statements {
        let Some(statement) = statement else { continue };
        let Some((options, file)) = texture_statement_parts(&statement) else {
            continue;
        };
        match normalize_relative_path(&folder.join(file.replace('\\', "/"))) {
            Some(path) if path.starts_with(source_root) => {
                result.maps.insert(slot, path);
                if !options.is_empty() {
                    result.map_options.insert(slot, options);
                }
            }
            _ => warnings.push(Diagnostic::new(
                library,
                format!("material `{}`: texture \"{file}\" leaves the source folder; ignored", material.name),
            )),
        }
    }
    // `map_d` naming the albedo texture itself (foliage exporters write that): the albedo's
    // alpha is the opacity; applying it twice would square it.
    if result
        .maps
        .get(&TextureSlot::Opacity)
        .is_some_and(|opacity| result.maps.get(&TextureSlot::Albedo) == Some(opacity))
    {
        result.maps.remove(&TextureSlot::Opacity);
    }
    result
}

/// An MTL texture statement's options (their words joined by spaces, empty without any) and
/// file name.
pub(crate) fn texture_statement_parts(statement: &str) -> Option<(String, String)> {
    let arguments = |option: &str| -> usize {
        match option {
            "-blendu" | "-blendv" | "-cc" | "-clamp" | "-imfchan" | "-texres" | "-bm" | "-boost" | "-type" => 1,
            "-mm" => 2,
            "-o" | "-s" | "-t" => 3,
            _ => 0,
        }
    };
    let words: Vec<&str> = statement.split_whitespace().collect();
    let mut index = 0;
    while index < words.len()
        && words[index].starts_with('-')
        && words[index].len() > 1
        && !words[index][1..].starts_with(|c: char| c.is_ascii_digit())
    {
        let count = arguments(words[index]);
        index += 1;
        // Options with a variable number of numbers (-o, -s, -t take 1 to 3).
        let mut taken = 0;
        while taken < count && index < words.len() - 1 && (count == 1 || words[index].parse::<f32>().is_ok()) {
            index += 1;
            taken += 1;
        }
    }
    let file = words.get(index..)?.join(" ");
    (!file.is_empty()).then(|| (words[..index].join(" "), file))
}

/// Area-weighted vertex normals.
fn compute_normals(mesh: &mut Mesh) {
    // Each vertex's own faces (area-weighted), then the faces of the other vertices at the same
    // position whose normals lie within 60° of that: a UV seam (vertices split by their UVs
    // only) stays smooth, a hard edge (a box's corner) stays hard.
    let face_normals: Vec<glam::Vec3> = mesh
        .triangles
        .iter()
        .map(|triangle| {
            let [a, b, c] = triangle.map(|index| glam::Vec3::from(mesh.positions[index as usize]));
            (b - a).cross(c - a)
        })
        .collect();
    let mut own = vec![glam::Vec3::ZERO; mesh.positions.len()];
    for (triangle, face) in mesh.triangles.iter().zip(&face_normals) {
        for &index in triangle {
            own[index as usize] += *face;
        }
    }
    let mut at_position: std::collections::HashMap<[u32; 3], Vec<u32>> = std::collections::HashMap::new();
    for (index, position) in mesh.positions.iter().enumerate() {
        at_position.entry(position.map(f32::to_bits)).or_default().push(index as u32);
    }
    let mut normals = own.clone();
    for shared in at_position.values().filter(|shared| shared.len() > 1) {
        for &index in shared {
            let reference = own[index as usize].normalize_or_zero();
            for &other in shared.iter().filter(|&&other| other != index) {
                let neighbour = own[other as usize];
                if neighbour.normalize_or_zero().dot(reference) > 0.5 {
                    normals[index as usize] += neighbour;
                }
            }
        }
    }
    mesh.normals = normals.into_iter().map(|n| n.try_normalize().unwrap_or(glam::Vec3::Z).to_array()).collect();
}

/// The texture files the materials of an OBJ's MTL libraries name (project-relative, sorted),
/// without parsing the OBJ itself: what a billboard cloud reads besides its mesh.
pub fn texture_paths(libraries: &BTreeMap<PathBuf, Option<Vec<u8>>>, source_root: &Path) -> Vec<PathBuf> {
    let mut paths = Vec::new();
    let mut ignored = Vec::new();
    for (library, bytes) in libraries {
        let Some(Ok((materials, _))) = bytes.as_deref().map(load_mtl) else {
            continue;
        };
        for material in &materials {
            paths.extend(mesh_material(material, library, source_root, &mut ignored).maps.into_values());
        }
    }
    paths.sort();
    paths.dedup();
    paths
}

/// The MTL statements each map slot is read from (`mesh_material`, through tobj for the
/// normal map's `map_Bump` and `bump`); the first is the one cirrus writes (`obj_text`).
pub(crate) const MAP_STATEMENTS: [(TextureSlot, &[&str]); 6] = [
    (TextureSlot::Albedo, &["map_Kd"]),
    (TextureSlot::Opacity, &["map_d"]),
    (TextureSlot::Normal, &["norm", "map_Bump", "map_bump", "bump"]),
    (TextureSlot::Metallic, &["map_Pm"]),
    (TextureSlot::Roughness, &["map_Pr"]),
    (TextureSlot::Ao, &["map_ao", "map_AO"]),
];

/// The MTL statements `slot`'s map is read from ([`MAP_STATEMENTS`]).
pub(crate) fn map_keywords(slot: TextureSlot) -> &'static [&'static str] {
    MAP_STATEMENTS.iter().find(|(of, _)| *of == slot).map_or(&[], |(_, keywords)| keywords)
}

/// Where the MTL libraries name `slot`'s map of material `material`: the library and the
/// statement's position, for diagnostics about that map.
pub fn map_statement(
    libraries: &BTreeMap<PathBuf, Option<Vec<u8>>>,
    material: &str,
    slot: TextureSlot,
) -> Option<(PathBuf, base::diagnostic::TextPosition)> {
    let keywords = map_keywords(slot);
    libraries.iter().find_map(|(library, bytes)| {
        let text = String::from_utf8_lossy(bytes.as_deref()?);
        let mut current = None;
        let mut offset = 0;
        for line in text.split_inclusive('\n') {
            let start = offset;
            offset += line.len();
            let mut words = line.split_whitespace();
            match words.next() {
                Some("newmtl") => current = Some(words.collect::<Vec<_>>().join(" ")),
                Some(keyword) if keywords.contains(&keyword) && current.as_deref() == Some(material) => {
                    let indent = line.len() - line.trim_start().len();
                    let position = base::diagnostic::TextPosition::of_byte_offset(&text, start + indent);
                    return Some((library.clone(), position));
                }
                _ => {}
            }
        }
        None
    })
}

/// Per-vertex MikkTSpace tangents (xyz, handedness in w: bitangent = w · normal × tangent),
/// the frame normal-map bakers and glTF loaders use, from UVs in the OBJ's convention (v up:
/// what glTF's `TANGENT` means with its flipped v). MikkTSpace frames face corners; a vertex
/// whose corners it frames differently keeps its first corner's, and a vertex of no triangle
/// (or a mesh MikkTSpace refuses, or whose corners' UVs are all degenerate) the UV-derivative
/// frame of [`vertex_tangents`].
pub fn mikktspace_tangents(
    positions: &[[f32; 3]],
    normals: &[[f32; 3]],
    uvs: &[[f32; 2]],
    triangles: &[[u32; 3]],
) -> Vec<[f32; 4]> {
    struct Corners<'a> {
        positions: &'a [[f32; 3]],
        normals: &'a [[f32; 3]],
        uvs: &'a [[f32; 2]],
        triangles: &'a [[u32; 3]],
        tangents: Vec<Option<[f32; 4]>>,
    }
    impl bevy_mikktspace::Geometry for Corners<'_> {
        fn num_faces(&self) -> usize {
            self.triangles.len()
        }
        fn num_vertices_of_face(&self, _face: usize) -> usize {
            3
        }
        fn position(&self, face: usize, corner: usize) -> [f32; 3] {
            self.positions[self.triangles[face][corner] as usize]
        }
        fn normal(&self, face: usize, corner: usize) -> [f32; 3] {
            self.normals[self.triangles[face][corner] as usize]
        }
        fn tex_coord(&self, face: usize, corner: usize) -> [f32; 2] {
            self.uvs[self.triangles[face][corner] as usize]
        }
        fn set_tangent(&mut self, frame: Option<bevy_mikktspace::TangentSpace>, face: usize, corner: usize) {
            // A corner whose UVs are degenerate gets a zero tangent: not a frame (glTF's tangents
            // are unit vectors), so another corner's or the fallback frames the vertex.
            let framed = frame.map(|frame| frame.tangent_encoded()).filter(|&[x, y, z, _]| {
                let length = glam::Vec3::new(x, y, z).length();
                length.is_finite() && length > 0.5
            });
            if let Some(tangent) = framed {
                self.tangents[self.triangles[face][corner] as usize].get_or_insert(tangent);
            }
        }
    }
    let fallback = vertex_tangents(positions, normals, uvs, triangles);
    let mut corners = Corners { positions, normals, uvs, triangles, tangents: vec![None; positions.len()] };
    if bevy_mikktspace::generate_tangents(&mut corners).is_err() {
        return fallback;
    }
    corners.tangents.into_iter().zip(fallback).map(|(tangent, fallback)| tangent.unwrap_or(fallback)).collect()
}

/// Per-vertex tangents (xyz, handedness in w) from UV derivatives, for normal mapping (a mesh
/// without UVs, which draws no map: +x everywhere).
pub fn vertex_tangents(
    positions: &[[f32; 3]],
    normals: &[[f32; 3]],
    uvs: &[[f32; 2]],
    triangles: &[[u32; 3]],
) -> Vec<[f32; 4]> {
    if uvs.len() < positions.len() {
        return vec![[1.0, 0.0, 0.0, 1.0]; positions.len()];
    }
    let mut tangents = vec![glam::Vec3::ZERO; positions.len()];
    let mut bitangents = vec![glam::Vec3::ZERO; positions.len()];
    for triangle in triangles {
        let [a, b, c] = triangle.map(|index| index as usize);
        let (p0, p1, p2) =
            (glam::Vec3::from(positions[a]), glam::Vec3::from(positions[b]), glam::Vec3::from(positions[c]));
        let (t0, t1, t2) = (glam::Vec2::from(uvs[a]), glam::Vec2::from(uvs[b]), glam::Vec2::from(uvs[c]));
        let (e1, e2, d1, d2) = (p1 - p0, p2 - p0, t1 - t0, t2 - t0);
        let determinant = d1.x * d2.y - d2.x * d1.y;
        if determinant.abs() < 1e-12 {
            continue;
        }
        let r = 1.0 / determinant;
        let tangent = (e1 * d2.y - e2 * d1.y) * r;
        let bitangent = (e2 * d1.x - e1 * d2.x) * r;
        for index in [a, b, c] {
            tangents[index] += tangent;
            bitangents[index] += bitangent;
        }
    }
    tangents
        .iter()
        .zip(&bitangents)
        .zip(normals)
        .map(|((&tangent, &bitangent), &normal)| {
            let normal = glam::Vec3::from(normal);
            let orthogonal = (tangent - normal * normal.dot(tangent))
                .try_normalize()
                .unwrap_or_else(|| normal.any_orthonormal_vector());
            let handedness = if normal.cross(orthogonal).dot(bitangent) < 0.0 { -1.0 } else { 1.0 };
            [orthogonal.x, orthogonal.y, orthogonal.z, handedness]
        })
        .collect()
}
