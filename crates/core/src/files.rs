//! Reading and writing files safely: the leaf every IO edge (sources, artifacts, the cache, the
//! record) builds on.

use std::io::Write;
use std::path::{Path, PathBuf};

/// Largest source file read (textures, meshes, materials).
pub const MAX_SOURCE_BYTES: u64 = 512 << 20;

/// The name prefix of temporary files (artifacts and cache entries before their rename); files
/// with it that a killed build left behind are swept by `sweep_temporary_files`.
pub const TEMPORARY_PREFIX: &str = ".cirrus-tmp-";

/// Writes `bytes` to `path` atomically unless the file already holds exactly these bytes.
/// Returns whether the file changed.
pub fn write_if_changed(path: &Path, bytes: &[u8]) -> std::io::Result<bool> {
    match stage_if_changed(path, bytes)? {
        Some(staged) => staged.commit().map(|()| true),
        None => Ok(false),
    }
}

/// A file's new bytes written beside it under a temporary name, renamed into place by
/// [`StagedFile::commit`]; dropped uncommitted, it is deleted. Staging every file of an asset
/// before renaming any lets a failed write leave all of them as they were.
pub struct StagedFile {
    temporary: tempfile::TempPath,
    path: PathBuf,
}

impl StagedFile {
    /// Renames the file into place.
    pub fn commit(self) -> std::io::Result<()> {
        self.temporary.persist(&self.path).map_err(|error| error.error)
    }
}

/// The longest file name most file systems take (Linux's `NAME_MAX`, NTFS's and APFS's 255).
const MAX_FILE_NAME_BYTES: usize = 255;

/// Writes `bytes` beside `path` under a temporary name, unless `path` already holds exactly
/// these bytes (`None`). Refuses, before writing anything, a name longer than 255 bytes and a
/// folder in the file's place, so that the rename after cannot fail for them.
pub fn stage_if_changed(path: &Path, bytes: &[u8]) -> std::io::Result<Option<StagedFile>> {
    if path.file_name().is_some_and(|name| name.len() > MAX_FILE_NAME_BYTES) {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidFilename,
            format!("its file name is longer than {MAX_FILE_NAME_BYTES} bytes"),
        ));
    }
    // Read back at most the new length (a longer file differs anyway); a FIFO or device put in
    // place of an artifact is not read (it would block) but replaced.
    if let Ok(existing) = read_regular_file(path, bytes.len() as u64) {
        if existing == bytes {
            return Ok(None);
        }
    }
    if std::fs::symlink_metadata(path).is_ok_and(|metadata| metadata.is_dir()) {
        return Err(std::io::Error::new(std::io::ErrorKind::IsADirectory, "a folder is in its place"));
    }
    let mut temporary = temporary_file_in(path.parent().unwrap_or(Path::new(".")))?;
    #[cfg(unix)]
    {
        // Artifacts are read by engines and tools running as other users: rw-r--r--, not the
        // temporary file's private default.
        use std::os::unix::fs::PermissionsExt;
        temporary.as_file().set_permissions(std::fs::Permissions::from_mode(0o644))?;
    }
    temporary.write_all(bytes)?;
    temporary.as_file().sync_data()?;
    Ok(Some(StagedFile { temporary: temporary.into_temp_path(), path: path.to_path_buf() }))
}

/// Reads the file at `path` when it is a regular file (symbolic links followed) of at most
/// `limit` bytes. FIFOs, devices, sockets and folders are refused without blocking: the file is
/// opened non-blocking and checked on the open handle, and at most `limit + 1` bytes are read,
/// whatever the metadata says (`/proc` files and growing files report other sizes).
pub fn read_regular_file(path: &Path, limit: u64) -> Result<Vec<u8>, ReadError> {
    read_regular_file_with_metadata(path, limit).map(|(bytes, _)| bytes)
}

/// [`read_regular_file`], with the metadata of the open file, taken before its bytes are read.
pub fn read_regular_file_with_metadata(path: &Path, limit: u64) -> Result<(Vec<u8>, std::fs::Metadata), ReadError> {
    use std::io::Read;
    let (file, metadata) = open_regular_file(path, limit)?;
    let mut bytes = Vec::with_capacity(metadata.len() as usize);
    (&file).take(limit + 1).read_to_end(&mut bytes).map_err(ReadError::of)?;
    if bytes.len() as u64 > limit {
        return Err(ReadError::TooLarge { limit });
    }
    Ok((bytes, metadata))
}

/// Opens `path` for reading when it is a regular file of at most `limit` bytes by its metadata
/// (non-blocking, checked on the open handle: see [`read_regular_file`]).
fn open_regular_file(path: &Path, limit: u64) -> Result<(std::fs::File, std::fs::Metadata), ReadError> {
    let mut options = std::fs::OpenOptions::new();
    options.read(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        // Opening a FIFO for reading blocks until a writer appears; non-blocking, it does not.
        options.custom_flags(libc::O_NONBLOCK);
    }
    let file = options.open(path).map_err(ReadError::of)?;
    let metadata = file.metadata().map_err(ReadError::of)?;
    if metadata.is_dir() {
        return Err(ReadError::Folder);
    }
    if !metadata.is_file() {
        return Err(ReadError::NotRegular);
    }
    if metadata.len() > limit {
        return Err(ReadError::TooLarge { limit });
    }
    Ok((file, metadata))
}

/// Why a JSON file of cirrus's own (the manifest, the build record) was not read.
#[derive(Debug, thiserror::Error)]
enum JsonFileError {
    #[error("{0}")]
    Read(ReadError),
    #[error("is damaged (not valid JSON of its kind: {0})")]
    Malformed(serde_json::Error),
}

impl JsonFileError {
    fn is_not_found(&self) -> bool {
        matches!(self, JsonFileError::Read(error) if error.is_not_found())
    }
}

/// Parses the JSON file at `path` (a regular file of at most `limit` bytes) as it is read, so
/// that its bytes are never held whole beside what they parse to.
fn read_json_file<T: serde::de::DeserializeOwned>(path: &Path, limit: u64) -> Result<T, JsonFileError> {
    use std::io::Read;
    let (file, _) = open_regular_file(path, limit).map_err(JsonFileError::Read)?;
    let reader = std::io::BufReader::with_capacity(1 << 16, file.take(limit));
    serde_json::from_reader(reader).map_err(JsonFileError::Malformed)
}

/// A JSON file of cirrus's own (the manifest, the build record) through [`read_json_file`]: its
/// value, or the default when there is none, and with a warning naming the file, the problem
/// and what is done `instead` when it cannot be read or parsed.
pub fn read_own_json<T: serde::de::DeserializeOwned + Default>(path: &Path, limit: u64, instead: &str) -> T {
    match read_json_file(path, limit) {
        Ok(value) => value,
        Err(error) if error.is_not_found() => T::default(),
        Err(error) => {
            tracing::warn!("{} {error}; {instead}", crate::diagnostic::display_path(path));
            T::default()
        }
    }
}

fn describe_bytes(bytes: u64) -> String {
    if bytes >= 1 << 20 {
        format!("{} MiB", bytes >> 20)
    } else {
        format!("{bytes} bytes")
    }
}

/// Why a file could not be read (its text is what messages and fingerprints carry).
#[derive(Clone, Debug, PartialEq, Eq, Hash, thiserror::Error)]
pub enum ReadError {
    /// `hint` names a file with a similar name, when a source read found one.
    #[error("file not found{hint}")]
    NotFound { hint: String },
    #[error("permission denied")]
    PermissionDenied,
    #[error("is a folder, not a file")]
    Folder,
    #[error("is not a regular file (a FIFO, socket or device)")]
    NotRegular,
    #[error("is larger than {}", describe_bytes(*limit))]
    TooLarge { limit: u64 },
    /// The source folder a source read looked in (project-relative).
    #[error("the source folder {} does not exist", crate::diagnostic::display_path(.0))]
    NoSourceFolder(PathBuf),
    #[error("cannot read: {0}")]
    Other(String),
}

impl ReadError {
    fn of(error: std::io::Error) -> ReadError {
        match error.kind() {
            std::io::ErrorKind::NotFound => ReadError::NotFound { hint: String::new() },
            std::io::ErrorKind::PermissionDenied => ReadError::PermissionDenied,
            std::io::ErrorKind::IsADirectory => ReadError::Folder,
            _ => ReadError::Other(error.to_string()),
        }
    }

    pub fn is_not_found(&self) -> bool {
        matches!(self, ReadError::NotFound { .. })
    }

    /// Whether the message reads as the end of a sentence about the file (`the pipeline file
    /// is larger than 16 MiB`) rather than a reason (`permission denied`).
    pub fn is_predicate(&self) -> bool {
        matches!(self, ReadError::Folder | ReadError::NotRegular | ReadError::TooLarge { .. })
    }
}

impl From<ReadError> for String {
    fn from(error: ReadError) -> String {
        error.to_string()
    }
}

/// Writes a file through a temporary file in its folder renamed into place, so that readers
/// (other processes too) see the whole file or none.
pub fn write_atomically(
    path: &Path,
    write: impl FnOnce(&mut std::fs::File) -> std::io::Result<()>,
) -> std::io::Result<()> {
    let mut temporary = temporary_file_in(path.parent().expect("entry paths have a folder"))?;
    write(temporary.as_file_mut())?;
    temporary.persist(path).map_err(|error| error.error)?;
    Ok(())
}

/// A new temporary file in `folder` (created when missing), named with [`TEMPORARY_PREFIX`] so
/// that one a killed build leaves behind is swept.
fn temporary_file_in(folder: &Path) -> std::io::Result<tempfile::NamedTempFile> {
    std::fs::create_dir_all(folder)?;
    tempfile::Builder::new().prefix(TEMPORARY_PREFIX).tempfile_in(folder)
}
