//! What `cirrus check` asks of a kind's sources beyond parsing them, as a build would read them:
//! a texture's header, an OBJ with its MTL files, and the maps an asset would copy into its
//! output.

use std::path::{Path, PathBuf};

use crate::config::PipelineConfig;
use crate::diagnostic::{display_path, Diagnostic};

/// Reads a texture's header for `check`: readable, decodable, within the texture limits.
pub fn check_texture_file(config: &PipelineConfig, path: &Path) -> Result<(), String> {
    let contents = crate::sources::read_source(&config.root, &config.source, path)?;
    crate::texture::probe_texture(
        path,
        &contents.bytes().map_err(|diagnostic| diagnostic.message)?,
        config.limits.texture,
    )
    .map(|_| ())
    .map_err(|diagnostic| diagnostic.message)
}

/// The MTL files of the OBJ `mesh_file` (whose bytes are `obj`) for `cirrus check`, as a build
/// reads them: a missing one `None` (the load warns of it), an unreadable one an error.
fn check_mesh_libraries(
    config: &PipelineConfig,
    mesh_file: &Path,
    obj: &[u8],
) -> Result<std::collections::BTreeMap<PathBuf, Option<Vec<u8>>>, Diagnostic> {
    let mut libraries = std::collections::BTreeMap::new();
    for library in crate::mesh::material_libraries(mesh_file, obj, &config.source) {
        let bytes = match crate::sources::read_source(&config.root, &config.source, &library) {
            Ok(contents) => Some(contents.bytes()?.to_vec()),
            Err(error) if error.is_not_found() => None,
            Err(error) => return Err(Diagnostic::new(&library, error)),
        };
        libraries.insert(library, bytes);
    }
    Ok(libraries)
}

/// `cirrus check`'s word on the maps a mesh's used materials name that the asset copies into its
/// output (those `copied` says): each must be the image its name says, as a build requires
/// (`texture::check_image_file`); a problem names the MTL statement.
pub fn check_copied_maps(
    config: &PipelineConfig,
    mesh_file: &Path,
    mesh: &crate::mesh::Mesh,
    copied: impl Fn(&Path) -> bool,
) -> Vec<Diagnostic> {
    // The bytes of a source, none where it cannot be read (the build's warning, not check's).
    let read = |path: &Path| crate::sources::read_source(&config.root, &config.source, path).ok()?.bytes().ok();
    let Some(obj) = read(mesh_file) else { return Vec::new() };
    let libraries = check_mesh_libraries(config, mesh_file, &obj).unwrap_or_default();
    let (_, used) = super::source_copies::used_materials(&mesh.materials, &mesh.triangle_materials);
    let mut problems = Vec::new();
    for super::source_copies::OutputMaterial { material, .. } in used {
        for (&slot, path) in material.maps.iter().filter(|(_, path)| copied(path)) {
            // A map that cannot be read is the build's warning, not a copy's problem.
            let Some(bytes) = read(path) else { continue };
            let Err(problem) = crate::texture::check_image_file(path, &bytes, config.limits.texture) else {
                continue;
            };
            let message = format!(
                "material `{}`: its {} map `{}` would not be copied into the output: {}",
                material.name,
                slot.name(),
                display_path(path.strip_prefix(&config.source).unwrap_or(path)),
                problem.message
            );
            problems.push(super::source_copies::map_diagnostic(&libraries, (material, slot), mesh_file, message));
        }
    }
    problems
}

/// An OBJ of the source folder loaded for `cirrus check`, with the MTL files it names (a
/// missing MTL is a load warning, as in a build); the load warnings come back as warnings.
pub fn check_mesh_file(
    config: &PipelineConfig,
    mesh_file: &Path,
) -> Result<(crate::mesh::Mesh, Vec<Diagnostic>), Diagnostic> {
    let contents = crate::sources::read_source(&config.root, &config.source, mesh_file)
        .map_err(|error| Diagnostic::new(mesh_file, error))?;
    let obj = contents.bytes()?;
    let libraries = check_mesh_libraries(config, mesh_file, &obj)?;
    let (mesh, warnings) = crate::mesh::load_mesh(mesh_file, &obj, &libraries, &config.source)?;
    Ok((mesh, warnings.iter().map(Diagnostic::as_warning).collect()))
}
