//! Reading sources (an IO edge): file contents with their hashes, and the files of the source
//! folder that `rules` turn into assets.

use std::path::{Path, PathBuf};

use crate::config::PipelineConfig;
use crate::db::{FileContents, FileRead};

/// Largest source file read (textures, meshes, materials).
pub const MAX_SOURCE_BYTES: u64 = 512 << 20;

/// Reads `relative` (to the project folder `root`), or says why it cannot be read.
pub fn read_source(root: &Path, relative: &Path) -> FileRead {
    let path = root.join(relative);
    let metadata = std::fs::metadata(&path).map_err(describe_io_error)?;
    if metadata.is_dir() {
        return Err("is a folder, not a file".to_string());
    }
    if metadata.len() > MAX_SOURCE_BYTES {
        return Err(format!("is larger than {} MiB", MAX_SOURCE_BYTES >> 20));
    }
    std::fs::read(&path).map(FileContents::new).map_err(describe_io_error)
}

fn describe_io_error(error: std::io::Error) -> String {
    match error.kind() {
        std::io::ErrorKind::NotFound => "file not found".to_string(),
        std::io::ErrorKind::PermissionDenied => "permission denied".to_string(),
        _ => format!("cannot read: {error}"),
    }
}

/// Files below the source folder that match a rule, relative to the source folder, sorted.
pub fn rule_matches(config: &PipelineConfig) -> Vec<PathBuf> {
    if config.rules.is_empty() {
        return Vec::new();
    }
    let source = config.source_dir();
    let output = config.output_dir();
    let mut found = Vec::new();
    let mut folders = vec![source.clone()];
    while let Some(folder) = folders.pop() {
        let Ok(entries) = std::fs::read_dir(&folder) else {
            continue;
        };
        for entry in entries.flatten() {
            let path = entry.path();
            let Ok(kind) = entry.file_type() else {
                continue;
            };
            if kind.is_dir() {
                if path != output {
                    folders.push(path);
                }
            } else if let Ok(relative) = path.strip_prefix(&source) {
                let relative = PathBuf::from(relative.to_string_lossy().replace('\\', "/"));
                if config.rules.iter().any(|rule| rule.matcher.is_match(&relative)) {
                    found.push(relative);
                }
            }
        }
    }
    found.sort();
    found
}
