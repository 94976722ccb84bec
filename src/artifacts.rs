//! Writing artifacts (an IO edge): every file goes to a temporary name and is renamed into place,
//! only when its bytes changed; `manifest.json` lists each artifact with its hash and the
//! revision that produced it.

use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

/// Writes `bytes` to `path` atomically unless the file already holds exactly these bytes.
/// Returns whether the file changed.
pub fn write_if_changed(path: &Path, bytes: &[u8]) -> std::io::Result<bool> {
    if let Ok(existing) = std::fs::read(path) {
        if existing == bytes {
            return Ok(false);
        }
    }
    let folder = path.parent().unwrap_or(Path::new("."));
    std::fs::create_dir_all(folder)?;
    let mut temporary = tempfile::Builder::new().prefix(".cirrus-tmp-").tempfile_in(folder)?;
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

pub fn manifest_path(output_dir: &Path) -> PathBuf {
    output_dir.join("manifest.json")
}

/// The manifest of the last build, or an empty one.
pub fn load_manifest(output_dir: &Path) -> Manifest {
    std::fs::read(manifest_path(output_dir)).ok().and_then(|bytes| serde_json::from_slice(&bytes).ok()).unwrap_or_default()
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
