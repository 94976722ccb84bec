//! Writing artifacts (an IO edge): every file goes to a temporary name and is renamed into place,
//! only when its bytes changed; `manifest.json` lists each artifact with its hash and the
//! revision that produced it.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::config::PipelineConfig;
use crate::diagnostic::display_path;
use crate::files::{write_if_changed, TEMPORARY_PREFIX};

/// Deletes the temporary files that killed builds left under `output_dir`: regular files named
/// with `TEMPORARY_PREFIX`, untouched for a minute (another process may be writing a fresh one);
/// symbolic links are not followed. Returns how many were deleted.
pub(crate) fn sweep_temporary_files(output_dir: &Path) -> usize {
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
/// timings (`stage_ms`, and `timings`: any other figure measured in the run), which differ on
/// every run: such a report is not rewritten, so a batch that changed nothing else lists no
/// artifact.
pub(crate) fn same_report_on_disk(path: &Path, report: &[u8]) -> Option<Vec<u8>> {
    let existing = crate::files::read_regular_file(path, 64 << 20).ok()?;
    let without_timings = |bytes: &[u8]| -> Option<serde_json::Value> {
        let mut value: serde_json::Value = serde_json::from_slice(bytes).ok()?;
        let object = value.as_object_mut()?;
        object.remove("stage_ms");
        object.remove("timings");
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
    /// What the file's values mean, where its kind says (a height map: `distance` with
    /// `center` and `magnitude`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub meaning: Option<serde_json::Value>,
    /// What the file is (absent in manifests written before roles).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub role: Option<crate::summary::ArtifactRole>,
}

/// `<output>/manifest.json`: paths are relative to the project folder, with `/` separators.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Manifest {
    pub revision: u64,
    pub artifacts: BTreeMap<String, ManifestEntry>,
}

/// Largest `manifest.json` read back (a million artifacts take about 200 MB).
const MAX_MANIFEST_BYTES: u64 = 256 << 20;

pub(crate) fn manifest_path(output_dir: &Path) -> PathBuf {
    output_dir.join("manifest.json")
}

/// The manifest of the last build, or an empty one (parsed as it is read). One that is there but
/// cannot be read, is too large or is not a manifest is warned about: the build writes a new one.
pub(crate) fn load_manifest(output_dir: &Path) -> Manifest {
    let instead = "this build writes a new one (artifacts it does not list are left alone)";
    crate::files::read_own_json(&manifest_path(output_dir), MAX_MANIFEST_BYTES, instead)
}

pub(crate) fn save_manifest(output_dir: &Path, manifest: &Manifest) -> std::io::Result<bool> {
    let mut bytes = serde_json::to_vec_pretty(manifest).expect("manifest serialises");
    bytes.push(b'\n');
    write_if_changed(&manifest_path(output_dir), &bytes)
}

/// Records an artifact in the manifest; true when the entry is new or its bytes changed.
pub(crate) fn record_artifact(
    manifest: &mut Manifest,
    revision: u64,
    asset: &str,
    path: &str,
    hash: &str,
    meaning: Option<&serde_json::Value>,
    role: Option<crate::summary::ArtifactRole>,
) -> bool {
    let unchanged = manifest.artifacts.get(path).is_some_and(|entry| {
        entry.hash == hash && entry.asset == asset && entry.meaning.as_ref() == meaning && entry.role == role
    });
    if !unchanged {
        let meaning = meaning.cloned();
        let entry = ManifestEntry { asset: asset.to_string(), hash: hash.to_string(), revision, meaning, role };
        manifest.artifacts.insert(path.to_string(), entry);
    }
    !unchanged
}

/// The manifest's artifact paths of an asset whose folder (project-relative) is `folder`: a
/// range of the sorted manifest (asset folders never nest), not a pass over every entry.
pub(crate) fn artifacts_of(manifest: &Manifest, asset: &str, folder: &Path) -> Vec<String> {
    let prefix = format!("{}/", display_path(folder));
    let below = manifest.artifacts.range(prefix.clone()..).take_while(|(path, _)| path.starts_with(&prefix));
    below.filter(|(_, entry)| entry.asset == asset).map(|(path, _)| path.clone()).collect()
}

/// Deletes the artifacts at `doomed` (manifest paths), file and manifest entry; returns the
/// paths deleted. `manifest.json` is a file on disk that anyone may have edited: a listed path
/// is deleted only when it lies inside the output folder and the file there is the one cirrus
/// wrote (its blake3 matches the entry). Any other entry is dropped from the manifest with a
/// warning, its file left alone.
pub(crate) fn remove_artifacts(config: &PipelineConfig, manifest: &mut Manifest, doomed: Vec<String>) -> Vec<String> {
    let mut removed = Vec::new();
    for path in doomed {
        let Some(entry) = manifest.artifacts.remove(&path) else { continue };
        match stale_artifact_file(config, &path, &entry.hash) {
            Ok(Some(file)) => match std::fs::remove_file(&file) {
                Ok(()) => {
                    remove_empty_folders(&config.root.join(&config.output), &file);
                    removed.push(path);
                }
                Err(error) => tracing::warn!("cannot delete the stale artifact {path}: {error}"),
            },
            Ok(None) => removed.push(path),
            Err(why) => tracing::warn!("manifest.json lists `{path}`, which is not deleted: {why}"),
        }
    }
    removed
}

/// Removes the folders that held `file` (below `output`) once they are empty: a removed
/// asset, material or level leaves no empty folder behind. `remove_dir` refuses a folder that
/// still holds anything, so nothing else is touched.
fn remove_empty_folders(output: &Path, file: &Path) {
    let mut folder = file.parent();
    while let Some(current) = folder.filter(|current| current.starts_with(output) && *current != output) {
        if std::fs::remove_dir(current).is_err() {
            return;
        }
        folder = current.parent();
    }
}

/// The file of a stale artifact that may be deleted (`None` when it is gone already), or why it
/// must not be: outside the output folder, not a regular file, or not the bytes cirrus wrote.
fn stale_artifact_file(config: &PipelineConfig, path: &str, hash: &str) -> Result<Option<PathBuf>, String> {
    let normalized = base::paths::normalize_relative_path(Path::new(path));
    let inside_output = normalized.as_ref().is_some_and(|normalized| {
        display_path(normalized) == path && normalized.starts_with(&config.output) && normalized != &config.output
    });
    if !inside_output {
        return Err(format!("it is not a path inside the output folder `{}`", display_path(&config.output)));
    }
    let file = config.root.join(path);
    let metadata = match std::fs::symlink_metadata(&file) {
        Ok(metadata) => metadata,
        Err(error) if error.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(error) => return Err(error.to_string()),
    };
    if !metadata.is_file() {
        return Err("it is not a regular file (cirrus writes only regular files)".to_string());
    }
    // A symbolic link among the folders could lead outside the output folder.
    let output = config.output_dir().canonicalize().map_err(|error| error.to_string())?;
    let folder = file.parent().and_then(|folder| folder.canonicalize().ok());
    if !folder.is_some_and(|folder| folder.starts_with(&output)) {
        return Err("its folder resolves outside the output folder".to_string());
    }
    let bytes = crate::files::read_regular_file(&file, crate::files::MAX_SOURCE_BYTES)?;
    if blake3::hash(&bytes).to_hex().as_str() != hash {
        return Err("its bytes are not the ones cirrus wrote there (edited or replaced since)".to_string());
    }
    Ok(Some(file))
}
