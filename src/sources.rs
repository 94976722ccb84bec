//! Reading sources (an IO edge): file contents with their hashes, and the files of the source
//! folder that `rules` turn into assets.

use std::path::{Path, PathBuf};

use crate::config::PipelineConfig;
use crate::db::{FileContents, FileRead};

/// Largest source file read (textures, meshes, materials).
pub const MAX_SOURCE_BYTES: u64 = 512 << 20;

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
) -> Result<(FileContents, crate::record::FileStamp), String> {
    if !root.join(source).is_dir() {
        return Err(format!("the source folder {} does not exist", crate::diagnostic::display_path(source)));
    }
    read_regular_file_with_metadata(&root.join(relative), MAX_SOURCE_BYTES)
        .map(|(bytes, metadata)| (FileContents::new(bytes), crate::record::FileStamp::of(&metadata)))
        .map_err(|why| {
            if why == FILE_NOT_FOUND {
                format!("{FILE_NOT_FOUND}{}", similar_file_hint(root, source, relative))
            } else {
                why
            }
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

/// Reads the file at `path` when it is a regular file (symbolic links followed) of at most
/// `limit` bytes. FIFOs, devices, sockets and folders are refused without blocking: the file is
/// opened non-blocking and checked on the open handle, and at most `limit + 1` bytes are read,
/// whatever the metadata says (`/proc` files and growing files report other sizes).
pub fn read_regular_file(path: &Path, limit: u64) -> Result<Vec<u8>, String> {
    read_regular_file_with_metadata(path, limit).map(|(bytes, _)| bytes)
}

/// [`read_regular_file`], with the metadata of the open file, taken before its bytes are read.
pub fn read_regular_file_with_metadata(path: &Path, limit: u64) -> Result<(Vec<u8>, std::fs::Metadata), String> {
    use std::io::Read;
    let mut options = std::fs::OpenOptions::new();
    options.read(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        // Opening a FIFO for reading blocks until a writer appears; non-blocking, it does not.
        options.custom_flags(libc::O_NONBLOCK);
    }
    let file = options.open(path).map_err(describe_io_error)?;
    let metadata = file.metadata().map_err(describe_io_error)?;
    if metadata.is_dir() {
        return Err("is a folder, not a file".to_string());
    }
    if !metadata.is_file() {
        return Err("is not a regular file (a FIFO, socket or device)".to_string());
    }
    if metadata.len() > limit {
        return Err(format!("is larger than {}", describe_bytes(limit)));
    }
    let mut bytes = Vec::with_capacity(metadata.len() as usize);
    (&file).take(limit + 1).read_to_end(&mut bytes).map_err(describe_io_error)?;
    if bytes.len() as u64 > limit {
        return Err(format!("is larger than {}", describe_bytes(limit)));
    }
    Ok((bytes, metadata))
}

fn describe_bytes(bytes: u64) -> String {
    if bytes >= 1 << 20 {
        format!("{} MiB", bytes >> 20)
    } else {
        format!("{bytes} bytes")
    }
}

/// What `read_source` says of a file that does not exist.
pub const FILE_NOT_FOUND: &str = "file not found";

fn describe_io_error(error: std::io::Error) -> String {
    match error.kind() {
        std::io::ErrorKind::NotFound => FILE_NOT_FOUND.to_string(),
        std::io::ErrorKind::PermissionDenied => "permission denied".to_string(),
        std::io::ErrorKind::IsADirectory => "is a folder, not a file".to_string(),
        _ => format!("cannot read: {error}"),
    }
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
        let Some(path) = crate::config::normalize_relative_path(&config.source.join(plain)) else { continue };
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
