//! `cirrus check`: an asset's sources validated without baking, one function per kind: they
//! read, parse and load as the build would, and every texture has a readable header within the
//! texture limits. Warnings are reported as problems too.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use crate::config::PipelineConfig;
use crate::diagnostic::{display_path, Diagnostic};
use crate::sources::read_source;

/// A material file parses, and every texture it names is readable and within the limits.
pub fn check_material(config: &PipelineConfig, main_file: &Path) -> Vec<Diagnostic> {
    let contents = match read_source(&config.root, &config.source, main_file) {
        Ok(contents) => contents,
        Err(error) => return vec![Diagnostic::new(main_file, error)],
    };
    let parsed = match crate::kinds::material::definition::parse_material_file(main_file, &contents.bytes, &config.source) {
        Ok(parsed) => parsed,
        Err(diagnostic) => return vec![diagnostic],
    };
    let mut problems: Vec<Diagnostic> = parsed.warnings.iter().map(as_warning).collect();
    for reference in parsed.materials.iter().flat_map(|material| material.textures.values()) {
        if let Err(message) = probe_texture_file(config, &reference.path) {
            let message = format!("texture \"{}\" ({}): {message}", reference.written, display_path(&reference.path));
            problems.push(Diagnostic::at(main_file, reference.position, message));
        }
    }
    problems
}

/// A mesh loads with its material libraries, and every texture its materials name is
/// readable and within the limits.
pub fn check_billboard(config: &PipelineConfig, main_file: &Path) -> Vec<Diagnostic> {
    let read = |path: &Path| read_source(&config.root, &config.source, path);
    let contents = match read(main_file) {
        Ok(contents) => contents,
        Err(error) => return vec![Diagnostic::new(main_file, error)],
    };
    let mut libraries = BTreeMap::new();
    for library in crate::mesh::material_libraries(main_file, &contents.bytes, &config.source) {
        let bytes = match read(&library) {
            Ok(contents) => Some(contents.bytes.to_vec()),
            Err(error) if error == crate::sources::FILE_NOT_FOUND => None,
            Err(error) => return vec![Diagnostic::new(&library, error)],
        };
        libraries.insert(library, bytes);
    }
    let (mesh, warnings) = match crate::mesh::load_mesh(main_file, &contents.bytes, &libraries, &config.source) {
        Ok(loaded) => loaded,
        Err(diagnostic) => return vec![diagnostic],
    };
    let mut problems: Vec<Diagnostic> = warnings.iter().map(as_warning).collect();
    let textures: BTreeSet<&PathBuf> = mesh.materials.iter().flat_map(|material| material.maps.values()).collect();
    for path in textures {
        if let Err(message) = probe_texture_file(config, path) {
            problems.push(Diagnostic::new(path, message));
        }
    }
    problems
}

/// Reads a texture's header: readable, decodable, within the texture limits.
fn probe_texture_file(config: &PipelineConfig, path: &Path) -> Result<(), String> {
    let contents = read_source(&config.root, &config.source, path)?;
    crate::texture::probe_texture(path, &contents.bytes, config.limits.texture).map(|_| ()).map_err(|diagnostic| diagnostic.message)
}

/// A warning reported by `check`: the diagnostic with its message marked.
fn as_warning(diagnostic: &Diagnostic) -> Diagnostic {
    Diagnostic { message: format!("warning: {}", diagnostic.message), ..diagnostic.clone() }
}
