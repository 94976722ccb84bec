//! The source files an asset's artifacts name without baking them (the maps of an OBJ material
//! that an MTL or glTF passes on as they are), copied into the asset's output folder, so that
//! nothing under the output names a path outside it and `baked/` can move on its own; and the
//! MTL and glTF materials of a mesh over those copies.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use crate::db::{Asset, Db};
use crate::diagnostic::{display_path, Diagnostic};
use crate::kinds::AssetOutputs;
use crate::mesh::gltf::GltfMaterial;
use crate::mesh::obj_text::{mtl_material_text, relative_path};
use crate::mesh::MeshMaterial;
use crate::summary::ArtifactRole;
use crate::texture::TextureSlot;

/// The folder of an asset's output that holds the copies.
pub const SOURCE_COPIES: &str = "maps";

/// Where [`copy_source`] puts the source file `path` (project-relative): `<output_folder>/maps/`
/// `<stem>.<hash>.<extension>`, the hash the first 16 hex digits of its contents' BLAKE3, so one
/// file is copied once however many materials name it, and an edit gives a new name (no engine
/// keeps a stale copy). The stem keeps letters, digits, `-` and `_` (others become `_`), so the
/// name is a plain glTF URI. `None` when the file cannot be read.
pub fn source_copy_path(db: &dyn Db, asset: Asset, output_folder: &Path, path: &Path) -> Option<PathBuf> {
    source_copy(db, asset, output_folder, path).map(|(copy, _)| copy)
}

/// [`source_copy_path`] and the source's contents.
fn source_copy<'db>(
    db: &'db dyn Db,
    asset: Asset,
    output_folder: &Path,
    path: &Path,
) -> Option<(PathBuf, &'db crate::db::FileContents)> {
    let file = crate::db::asset_file(db, asset, path.to_path_buf())?;
    let contents = crate::db::read_contents(db, file).ok()?;
    let plain = |text: &str| -> String {
        text.chars().map(|c| if c.is_ascii_alphanumeric() || c == '-' || c == '_' { c } else { '_' }).collect()
    };
    let stem = plain(&path.file_stem().map_or_else(|| "map".into(), |stem| stem.to_string_lossy()));
    let hash = contents.hash.to_hex();
    let name = match path.extension() {
        Some(extension) => format!("{stem}.{}.{}", &hash[..16], plain(&extension.to_string_lossy())),
        None => format!("{stem}.{}", &hash[..16]),
    };
    Some((output_folder.join(SOURCE_COPIES).join(name), contents))
}

/// Why a source file was not copied into the output.
enum NotCopied {
    /// It cannot be read (missing, or not a regular file).
    Unreadable,
    /// It is not the image its name says (a link to a file of another kind, a broken image).
    NotAnImage(Diagnostic),
}

/// Copies the source file `path` into the asset's output ([`source_copy_path`]), once, after
/// checking that it is the image its extension names and decodes (`check_image_file`: a map is
/// never a copy of some other file that a link leads to); a PNG loses its colour-space chunks
/// on the way (`png_without_colour_chunks`: the same pixels). Gives the copy's path.
fn copy_source(
    db: &dyn Db,
    asset: Asset,
    output_folder: &Path,
    outputs: &mut AssetOutputs,
    path: &Path,
) -> Result<PathBuf, NotCopied> {
    let (copy, contents) = source_copy(db, asset, output_folder, path).ok_or(NotCopied::Unreadable)?;
    if !outputs.files.iter().any(|(written, _, _)| *written == copy) {
        let relative = crate::db::source_relative(db, path);
        let bytes = contents.bytes().map_err(|_| NotCopied::Unreadable)?;
        crate::texture::check_image_file(&relative, &bytes, crate::db::texture_limits(db))
            .map_err(NotCopied::NotAnImage)?;
        let plain_png = crate::texture::preview::png_without_colour_chunks(&bytes);
        outputs.add(copy.clone(), ArtifactRole::Image, plain_png.map_or_else(|| bytes.clone(), Into::into));
    }
    Ok(copy)
}

/// The copies [`output_materials`] makes of `materials`' maps (those `baked` does not stand in
/// for), for the graph's stage instances.
pub fn material_copy_paths(
    db: &dyn Db,
    asset: Asset,
    output_folder: &Path,
    materials: &[OutputMaterial],
) -> Vec<PathBuf> {
    let mut paths: Vec<PathBuf> = materials
        .iter()
        .flat_map(|OutputMaterial { material, baked }| {
            material.maps.iter().filter(|(slot, _)| !baked.contains_key(slot)).map(|(_, path)| path)
        })
        .filter_map(|path| source_copy_path(db, asset, output_folder, path))
        .collect();
    paths.sort();
    paths.dedup();
    paths
}

/// One material of a mesh the asset writes, and the maps an artifact of the asset stands in for
/// (an atlas page: project-relative paths in the output) instead of the material's own.
pub struct OutputMaterial<'a> {
    pub material: &'a MeshMaterial,
    pub baked: BTreeMap<TextureSlot, PathBuf>,
}

/// The materials of a mesh as the output names them: each map either what `baked` gives or a
/// copy of the source (`copy_source`); a map that cannot be read is left out with a warning, one
/// that is not the image its name says is an error naming the MTL statement.
pub struct OutputMaterials {
    /// Each material's statements, maps relative to `mtl_folder`.
    pub mtl: String,
    /// The glTF materials, maps relative to `gltf_folder`: PNG and JPEG images only (what glTF
    /// core reads); a map of another format is left out with a warning.
    pub gltf: Vec<GltfMaterial>,
    pub warnings: Vec<Diagnostic>,
    pub errors: Vec<Diagnostic>,
    /// Every file the materials name (copies and `baked` artifacts), once, in order.
    pub maps: Vec<PathBuf>,
}

/// Where a mesh's materials are named from: the source file the warnings name, and the folders
/// (project-relative) of the MTL and of the glTF that name the maps.
pub struct MaterialPlaces<'a> {
    pub source: &'a Path,
    pub mtl_folder: &'a Path,
    pub gltf_folder: &'a Path,
}

/// [`OutputMaterials`] of `materials`, named from `places`.
pub fn output_materials(
    db: &dyn Db,
    asset: Asset,
    output_folder: &Path,
    outputs: &mut AssetOutputs,
    materials: &[OutputMaterial],
    places: &MaterialPlaces,
) -> OutputMaterials {
    let MaterialPlaces { source, mtl_folder, gltf_folder } = *places;
    let mut result = OutputMaterials {
        mtl: String::new(),
        gltf: Vec::new(),
        warnings: Vec::new(),
        errors: Vec::new(),
        maps: Vec::new(),
    };
    for OutputMaterial { material, baked } in materials {
        let mut resolved: BTreeMap<TextureSlot, PathBuf> = BTreeMap::new();
        for (&slot, path) in &material.maps {
            if let Some(artifact) = baked.get(&slot) {
                resolved.insert(slot, artifact.clone());
                continue;
            }
            match copy_source(db, asset, output_folder, outputs, path) {
                Ok(copy) => {
                    resolved.insert(slot, copy);
                }
                Err(NotCopied::NotAnImage(problem)) => {
                    result.errors.push(not_an_image(db, asset, source, material, slot, &problem));
                }
                Err(NotCopied::Unreadable) => result.warnings.push(Diagnostic::new(
                    source,
                    format!(
                        "material `{}`: its {} map `{}` cannot be read and is left out of the output's materials",
                        material.name,
                        slot.name(),
                        display_path(&crate::db::source_relative(db, path))
                    ),
                )),
            }
        }
        result.maps.extend(resolved.values().cloned());
        let kept = MeshMaterial {
            maps: material
                .maps
                .iter()
                .filter(|(slot, _)| resolved.contains_key(slot))
                .map(|(slot, path)| (*slot, path.clone()))
                .collect(),
            ..(*material).clone()
        };
        if !result.mtl.is_empty() {
            result.mtl.push('\n');
        }
        let map_file = |slot, _: &Path| display_path(&relative_path(mtl_folder, &resolved[&slot]));
        result.mtl.push_str(&mtl_material_text(&kept, map_file));
        let mut not_gltf = Vec::new();
        let (gltf, notes) = crate::mesh::gltf::material_from_mtl(&kept, |slot, _| {
            let path = &resolved[&slot];
            let readable = path
                .extension()
                .map(|extension| extension.to_ascii_lowercase())
                .is_some_and(|extension| extension == "png" || extension == "jpg" || extension == "jpeg");
            if !readable {
                not_gltf.push(format!("`{}`", display_path(path)));
                return None;
            }
            Some(display_path(&relative_path(gltf_folder, path)))
        });
        if !not_gltf.is_empty() {
            result.warnings.push(Diagnostic::new(
                source,
                format!(
                    "material `{}`: glTF reads PNG and JPEG images only; its glTF material leaves out {}",
                    material.name,
                    not_gltf.join(", ")
                ),
            ));
        }
        result.warnings.extend(notes.into_iter().map(|note| Diagnostic::new(source, note)));
        result.gltf.push(gltf);
    }
    result.maps.sort();
    result.maps.dedup();
    result
}

/// The error for a map of `material` that is not the image its name says, at the MTL statement
/// that names it when `source` (an OBJ) has one.
fn not_an_image(
    db: &dyn Db,
    asset: Asset,
    source: &Path,
    material: &MeshMaterial,
    slot: TextureSlot,
    problem: &Diagnostic,
) -> Diagnostic {
    let message = format!(
        "material `{}`: its {} map `{}` is not copied into the output: {}",
        material.name,
        slot.name(),
        display_path(&problem.file),
        problem.message
    );
    let is_obj = source.extension().is_some_and(|extension| extension.eq_ignore_ascii_case("obj"));
    let libraries = if is_obj { crate::kinds::mesh_queries::library_bytes(db, asset, source) } else { BTreeMap::new() };
    map_diagnostic(&libraries, (material, slot), source, message)
}

/// `message` about `slot`'s map of `material`, at the MTL statement of `libraries` that names
/// it, else on `fallback` (the mesh): how a build and `cirrus check` both name a bad map.
pub fn map_diagnostic(
    libraries: &BTreeMap<PathBuf, Option<Vec<u8>>>,
    (material, slot): (&MeshMaterial, TextureSlot),
    fallback: &Path,
    message: String,
) -> Diagnostic {
    match crate::mesh::map_statement(libraries, &material.name, slot) {
        Some((library, position)) => Diagnostic::at(library, position, message),
        None => Diagnostic::new(fallback, message),
    }
}

/// The materials a mesh's triangles use (`triangle_materials`, indices into `materials`), their
/// numbers in order, and as the output names them (each over copies of its maps).
pub fn used_materials<'a>(
    materials: &'a [MeshMaterial],
    triangle_materials: &[u32],
) -> (Vec<u32>, Vec<OutputMaterial<'a>>) {
    let mut used: Vec<u32> = triangle_materials.to_vec();
    used.sort_unstable();
    used.dedup();
    let chosen = used
        .iter()
        .filter_map(|&index| materials.get(index as usize))
        .map(|material| OutputMaterial { material, baked: Default::default() })
        .collect();
    (used, chosen)
}

/// The used materials of a mesh the asset writes as an OBJ beside an MTL and a glTF, over copies
/// of their maps: the MTL's text, the glTF materials and each triangle's number among them.
pub struct WrittenMaterials {
    pub mtl: String,
    pub gltf: Vec<GltfMaterial>,
    pub triangle_materials: Vec<u32>,
    /// Maps that are not the images their names say (`OutputMaterials::errors`).
    pub errors: Vec<Diagnostic>,
}

/// [`WrittenMaterials`] of a mesh whose triangles draw `triangle_materials` (indices into
/// `materials`), named from `places`; the copies go to `outputs`, the warnings to `warnings`.
pub fn written_materials(
    db: &dyn Db,
    asset: Asset,
    output_folder: &Path,
    outputs: &mut AssetOutputs,
    (materials, triangle_materials): (&[MeshMaterial], &[u32]),
    places: &MaterialPlaces,
    warnings: &mut Vec<Diagnostic>,
) -> WrittenMaterials {
    let (used, chosen) = used_materials(materials, triangle_materials);
    let named = output_materials(db, asset, output_folder, outputs, &chosen, places);
    warnings.extend(named.warnings);
    let triangle_materials =
        triangle_materials.iter().map(|material| used.binary_search(material).unwrap_or(0) as u32).collect();
    WrittenMaterials { mtl: named.mtl, gltf: named.gltf, triangle_materials, errors: named.errors }
}
