//! Reading sources (an IO edge): file contents with their hashes, and the files of the source
//! folder that `rules` turn into assets.

use std::path::{Path, PathBuf};

use crate::config::PipelineConfig;
use crate::db::{FileContents, FileRead};
use crate::files::{read_regular_file_with_metadata, ReadError, MAX_SOURCE_BYTES};

/// Reads `relative` (to the project folder `root`), a file inside the source folder `source`
/// (project-relative too), or says why it cannot be read.
///
/// Paths written inside source files (`mtllib`, texture references) are untrusted and checked
/// to stay inside the source folder before they get here. Symbolic links placed in the source
/// folder are the user's own choice (a shared texture library linked in) and are followed,
/// wherever they lead; what they lead to must still be a regular file within the size limit.
pub fn read_source(root: &Path, source: &Path, relative: &Path) -> FileRead {
    read_source_stamped(root, source, relative).map(|(contents, _)| contents)
}

/// [`read_source`], with the stamp of the file that was read (taken on the open file before
/// reading it, so that a write meanwhile leaves the record a stamp that no longer matches).
pub fn read_source_stamped(
    root: &Path,
    source: &Path,
    relative: &Path,
) -> Result<(FileContents, crate::record::FileStamp), ReadError> {
    if !root.join(source).is_dir() {
        return Err(ReadError::NoSourceFolder(source.to_path_buf()));
    }
    let absolute = root.join(relative);
    read_regular_file_with_metadata(&absolute, MAX_SOURCE_BYTES)
        .map(|(bytes, metadata)| {
            let absolute = std::path::absolute(&absolute).unwrap_or(absolute);
            (FileContents::from_file(bytes, absolute), crate::record::FileStamp::of(&metadata))
        })
        .map_err(|why| match why {
            ReadError::NotFound { .. } => ReadError::NotFound { hint: similar_file_hint(root, source, relative) },
            why => why,
        })
}

/// ` (did you mean `trees/bush_2.obj`?)` when the missing file's folder holds a file whose name
/// is a slip away (`bush2.obj`), as the pipeline would name it (relative to `source`).
fn similar_file_hint(root: &Path, source: &Path, relative: &Path) -> String {
    let (Some(parent), Some(name)) = (relative.parent(), relative.file_name().and_then(|name| name.to_str())) else {
        return String::new();
    };
    let Ok(entries) = std::fs::read_dir(root.join(parent)) else { return String::new() };
    let names: Vec<String> =
        entries.take(10_000).filter_map(|entry| entry.ok()?.file_name().into_string().ok()).collect();
    let Some(closest) = crate::diagnostic::closest(name, names.iter().map(String::as_str)) else {
        return String::new();
    };
    let suggestion = parent.join(closest);
    let suggestion = suggestion.strip_prefix(source).unwrap_or(&suggestion);
    format!(" (did you mean `{}`?)", crate::diagnostic::display_path(suggestion))
}

/// Files below the source folder that match a rule, relative to the source folder, sorted.
pub fn rule_matches(config: &PipelineConfig) -> Vec<PathBuf> {
    if config.rules.is_empty() {
        return Vec::new();
    }
    source_files_where(config, |relative| config.rules.iter().any(|rule| rule.matcher.is_match(relative)))
}

/// Files below the source folder that match one of `globs` (over paths relative to it),
/// project-relative, sorted: the files an asset named by globs reads. A plain path (no glob
/// characters) is listed even when it is missing, so that reading it names it.
pub fn glob_matches(config: &PipelineConfig, globs: &[String]) -> Vec<PathBuf> {
    let matchers: Vec<globset::GlobMatcher> =
        globs.iter().filter_map(|glob| crate::config::source_glob(glob).ok()).collect();
    if matchers.is_empty() {
        return Vec::new();
    }
    let found = source_files_where(config, |relative| matchers.iter().any(|matcher| matcher.is_match(relative)));
    let mut files: Vec<PathBuf> = found.into_iter().map(|relative| config.source.join(relative)).collect();
    for plain in globs.iter().filter(|glob| !glob.contains(['*', '?', '[', ']', '{', '}'])) {
        let Some(path) = base::paths::normalize_relative_path(&config.source.join(plain)) else { continue };
        if path.starts_with(&config.source) && !files.contains(&path) {
            files.push(path);
        }
    }
    files.sort();
    files
}

/// Files below the source folder (not below the output folder) for which `wanted` holds of
/// their path relative to the source folder (`/`-separated), sorted. Links are not followed.
fn source_files_where(config: &PipelineConfig, wanted: impl Fn(&Path) -> bool) -> Vec<PathBuf> {
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
                if wanted(&relative) {
                    found.push(relative);
                }
            }
        }
    }
    found.sort();
    found
}
