//! Paths named inside inputs (an MTL's map, a material's texture, an asset's name), resolved
//! lexically against the folder that names them, without touching the file system.

use std::path::{Component, Path, PathBuf};

/// Resolves `.` and `..` lexically; `None` when the path is absolute or climbs out of its base.
pub fn normalize_relative_path(path: &Path) -> Option<PathBuf> {
    let text = path.to_string_lossy().replace('\\', "/");
    let mut parts: Vec<String> = Vec::new();
    for component in Path::new(&text).components() {
        match component {
            Component::CurDir => {}
            Component::ParentDir => {
                parts.pop()?;
            }
            Component::Normal(part) => parts.push(part.to_string_lossy().into_owned()),
            Component::RootDir | Component::Prefix(_) => return None,
        }
    }
    Some(parts.iter().collect())
}
