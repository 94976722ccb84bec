//! Writing artifacts (an IO edge): every file goes to a temporary name and is renamed into place,
//! only when its bytes changed; `manifest.json` lists each artifact with its hash and the
//! revision that produced it.

use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

/// The name prefix of temporary files (artifacts and cache entries before their rename); files
/// with it that a killed build left behind are swept by `sweep_temporary_files`.
pub const TEMPORARY_PREFIX: &str = ".cirrus-tmp-";

/// Writes `bytes` to `path` atomically unless the file already holds exactly these bytes.
/// Returns whether the file changed.
pub fn write_if_changed(path: &Path, bytes: &[u8]) -> std::io::Result<bool> {
    // Read back at most the new length (a longer file differs anyway); a FIFO or device put in
    // place of an artifact is not read (it would block) but replaced.
    if let Ok(existing) = crate::sources::read_regular_file(path, bytes.len() as u64) {
        if existing == bytes {
            return Ok(false);
        }
    }
    let folder = path.parent().unwrap_or(Path::new("."));
    std::fs::create_dir_all(folder)?;
    let mut temporary = tempfile::Builder::new().prefix(TEMPORARY_PREFIX).tempfile_in(folder)?;
    #[cfg(unix)]
    {
        // Artifacts are read by engines and tools running as other users: rw-r--r--, not the
        // temporary file's private default.
        use std::os::unix::fs::PermissionsExt;
        temporary.as_file().set_permissions(std::fs::Permissions::from_mode(0o644))?;
    }
    temporary.write_all(bytes)?;
    temporary.as_file().sync_data()?;
    temporary.persist(path).map_err(|error| error.error)?;
    Ok(true)
}

/// Deletes the temporary files that killed builds left under `output_dir`: regular files named
/// with `TEMPORARY_PREFIX`, untouched for a minute (another process may be writing a fresh one);
/// symbolic links are not followed. Returns how many were deleted.
pub fn sweep_temporary_files(output_dir: &Path) -> usize {
    let mut swept = 0;
    let mut folders = vec![output_dir.to_path_buf()];
    while let Some(folder) = folders.pop() {
        let Ok(entries) = std::fs::read_dir(&folder) else { continue };
        for entry in entries.flatten() {
            let Ok(kind) = entry.file_type() else { continue };
            if kind.is_dir() {
                folders.push(entry.path());
            } else if kind.is_file()
                && entry.file_name().to_string_lossy().starts_with(TEMPORARY_PREFIX)
                && entry
                    .metadata()
                    .and_then(|metadata| metadata.modified())
                    .is_ok_and(|modified| modified.elapsed().is_ok_and(|age| age > std::time::Duration::from_secs(60)))
            {
                swept += usize::from(std::fs::remove_file(entry.path()).is_ok());
            }
        }
    }
    swept
}

/// The bytes of the `report.json` at `path` when they say the same as `report` apart from the
/// timings (`stage_ms`), which differ on every run: such a report is not rewritten, so a batch
/// that changed nothing else lists no artifact.
pub fn same_report_on_disk(path: &Path, report: &[u8]) -> Option<Vec<u8>> {
    let existing = crate::sources::read_regular_file(path, 64 << 20).ok()?;
    let without_timings = |bytes: &[u8]| -> Option<serde_json::Value> {
        let mut value: serde_json::Value = serde_json::from_slice(bytes).ok()?;
        value.as_object_mut()?.remove("stage_ms");
        Some(value)
    };
    (without_timings(&existing)? == without_timings(report)?).then_some(existing)
}

/// One artifact in the manifest.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ManifestEntry {
    pub asset: String,
    /// blake3 hex digest of the file.
    pub hash: String,
    /// The revision that last changed the file's bytes.
    pub revision: u64,
}

/// `<output>/manifest.json`: paths are relative to the project folder, with `/` separators.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Manifest {
    pub revision: u64,
    pub artifacts: BTreeMap<String, ManifestEntry>,
}

/// Largest `manifest.json` read back (a million artifacts take about 200 MB).
const MAX_MANIFEST_BYTES: u64 = 256 << 20;

pub fn manifest_path(output_dir: &Path) -> PathBuf {
    output_dir.join("manifest.json")
}

/// The manifest of the last build, or an empty one.
pub fn load_manifest(output_dir: &Path) -> Manifest {
    crate::sources::read_regular_file(&manifest_path(output_dir), MAX_MANIFEST_BYTES)
        .ok()
        .and_then(|bytes| serde_json::from_slice(&bytes).ok())
        .unwrap_or_default()
}

pub fn save_manifest(output_dir: &Path, manifest: &Manifest) -> std::io::Result<bool> {
    let mut bytes = serde_json::to_vec_pretty(manifest).expect("manifest serialises");
    bytes.push(b'\n');
    write_if_changed(&manifest_path(output_dir), &bytes)
}

/// The baked LOD in `folder` (relative to `root`) as an engine loads it: `lod.obj` with the
/// decoded levels of `albedo.ktx2` and `normal.ktx2`, alpha-tested at `alpha_cutoff`.
pub fn read_lod_view_mesh(root: &Path, folder: &Path, alpha_cutoff: f32) -> Result<crate::gpu::ViewMesh, crate::diagnostic::Diagnostic> {
    let read = |file: &str| -> Result<(PathBuf, Vec<u8>), crate::diagnostic::Diagnostic> {
        let path = folder.join(file);
        let bytes = std::fs::read(root.join(&path))
            .map_err(|error| crate::diagnostic::Diagnostic::new(&path, format!("cannot read the baked artifact: {error}")))?;
        Ok((path, bytes))
    };
    crate::lod_preview::lod_view_mesh(&crate::lod_preview::LodFiles {
        obj: read("lod.obj")?,
        albedo_ktx2: read("albedo.ktx2")?,
        normal_ktx2: read("normal.ktx2")?,
        alpha_cutoff,
    })
}
