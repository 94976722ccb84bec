//! The local cache folder's upkeep (an IO edge): when each entry was last used, what the folder
//! holds, the last build's hit and miss counts, and `cirrus cache gc` (least recently used first).
//!
//! An entry's modification time is when it was last used: a hit sets it to now (entries are
//! never modified in place, only written whole and renamed), so that a collection keeps what
//! builds still read. Deleting an entry another process is reading is harmless: it reads the
//! whole file it opened, and a later lookup is a miss that recomputes it.

use std::path::{Path, PathBuf};
use std::time::SystemTime;

use super::remote::RemoteCounts;

/// Records that the entry at `path` was used now (for `gc`); a read-only cache keeps its times.
pub fn mark_used(path: &Path) {
    if let Ok(file) = std::fs::File::options().append(true).open(path) {
        let _ = file.set_modified(SystemTime::now());
    }
}

/// One entry file of a cache folder.
#[derive(Clone, Debug)]
pub struct EntryFile {
    pub path: PathBuf,
    /// The entry's stage (its folder).
    pub stage: String,
    pub bytes: u64,
    pub last_used: SystemTime,
}

/// Every entry file under `folder` (`<stage>/<xx>/<rest>`), skipping what is not one (the
/// last build's counts, temporary files of writes in progress, anything a user put there).
pub fn entry_files(folder: &Path) -> Vec<EntryFile> {
    let mut entries = Vec::new();
    let Ok(stages) = std::fs::read_dir(folder) else { return entries };
    for stage in stages.flatten() {
        let Ok(stage_type) = stage.file_type() else { continue };
        if !stage_type.is_dir() {
            continue;
        }
        let stage_name = stage.file_name().to_string_lossy().into_owned();
        let Ok(shards) = std::fs::read_dir(stage.path()) else { continue };
        for shard in shards.flatten() {
            let shard_name = shard.file_name();
            let shard_is_hex =
                shard_name.len() == 2 && shard_name.to_string_lossy().bytes().all(|byte| byte.is_ascii_hexdigit());
            if !shard_is_hex || !shard.file_type().is_ok_and(|kind| kind.is_dir()) {
                continue;
            }
            let Ok(files) = std::fs::read_dir(shard.path()) else { continue };
            for file in files.flatten() {
                let name = file.file_name();
                let is_entry = name.len() == 62 && name.to_string_lossy().bytes().all(|byte| byte.is_ascii_hexdigit());
                let Ok(metadata) = file.metadata() else { continue };
                if !is_entry || !metadata.is_file() {
                    continue;
                }
                entries.push(EntryFile {
                    path: file.path(),
                    stage: stage_name.clone(),
                    bytes: metadata.len(),
                    last_used: metadata.modified().unwrap_or(SystemTime::UNIX_EPOCH),
                });
            }
        }
    }
    entries
}

/// What `gc` did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Collected {
    pub deleted_entries: u64,
    pub deleted_bytes: u64,
    pub kept_entries: u64,
    pub kept_bytes: u64,
}

/// Deletes the least recently used entries until the folder's entries take at most `max_bytes`.
pub fn collect_garbage(folder: &Path, max_bytes: u64) -> Collected {
    let mut entries = entry_files(folder);
    // Most recently used first; the path breaks ties, so the order is the same on every run.
    entries.sort_by(|a, b| b.last_used.cmp(&a.last_used).then_with(|| a.path.cmp(&b.path)));
    let mut collected = Collected::default();
    for entry in entries {
        if collected.kept_bytes + entry.bytes <= max_bytes {
            collected.kept_bytes += entry.bytes;
            collected.kept_entries += 1;
            continue;
        }
        match std::fs::remove_file(&entry.path) {
            Ok(()) => {
                collected.deleted_bytes += entry.bytes;
                collected.deleted_entries += 1;
            }
            // Gone already (another collection), or not ours to delete: it stays counted.
            Err(error) if error.kind() == std::io::ErrorKind::NotFound => {}
            Err(error) => {
                tracing::warn!("cannot delete cache entry {}: {error}", entry.path.display());
                collected.kept_bytes += entry.bytes;
                collected.kept_entries += 1;
            }
        }
    }
    forget_deleted_key_parts(folder);
    collected
}

/// Rewrites each stage's key parts without the entries no longer there (each key once).
fn forget_deleted_key_parts(folder: &Path) {
    let Ok(files) = std::fs::read_dir(folder.join(KEY_PARTS_FOLDER)) else { return };
    for file in files.flatten() {
        let name = file.file_name().to_string_lossy().into_owned();
        let Some(stage) = name.strip_suffix(".jsonl") else { continue };
        let mut seen = std::collections::HashSet::new();
        let mut kept = String::new();
        for (key, parts) in recorded_key_parts(folder, stage) {
            let present = key.len() == 64 && folder.join(stage).join(&key[..2]).join(&key[2..]).is_file();
            if present && seen.insert(key.clone()) {
                kept.push_str(&serde_json::to_string(&(key, parts)).expect("parts serialise"));
                kept.push('\n');
            }
        }
        if let Err(error) =
            crate::files::write_atomically(&file.path(), |file| std::io::Write::write_all(file, kept.as_bytes()))
        {
            tracing::warn!("cannot rewrite {}: {error}", file.path().display());
        }
    }
}

/// The file that holds the last build's counts.
const LAST_BUILD_FILE: &str = "last-build.json";

/// What the last build that used a cache folder recorded there.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LastBuild {
    pub revision: u64,
    pub counts: CacheCounts,
    /// The shared store's URL, when there was one.
    pub remote: Option<String>,
    /// Per asset the build looked into, each stage instance (`stage(instance)`) and its status
    /// in that build.
    pub assets: Vec<LastBuildAsset>,
    /// The assets the build passed over: nothing they read had changed (the build record).
    #[serde(default)]
    pub unchanged: Vec<String>,
    /// The lookups that found no entry, local or remote.
    #[serde(default)]
    pub misses: Vec<Miss>,
}

/// Misses a build records at most.
pub const MAX_RECORDED_MISSES: usize = 4096;

/// A lookup that found no entry: the asset whose job made it, the entry's stage, its key and the
/// key's parts (described).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Miss {
    pub asset: Option<String>,
    pub stage: String,
    pub key: String,
    pub parts: Vec<String>,
}

/// The folder of the key parts of stored entries, one JSON line per entry and stage file.
const KEY_PARTS_FOLDER: &str = "key-parts";

/// Records the parts of a stored entry's key (a line appended to `key-parts/<stage>.jsonl`; a
/// line under 4 KiB is appended whole even with another process appending).
pub fn record_key_parts(folder: &Path, stage: &str, key: super::key::CacheKey, parts: &[String]) {
    let mut line = serde_json::to_string(&(key.0.to_hex().as_str(), parts)).expect("parts serialise");
    line.push('\n');
    let path = folder.join(KEY_PARTS_FOLDER).join(format!("{stage}.jsonl"));
    let written = std::fs::create_dir_all(folder.join(KEY_PARTS_FOLDER))
        .and_then(|()| std::fs::File::options().create(true).append(true).open(&path))
        .and_then(|mut file| std::io::Write::write_all(&mut file, line.as_bytes()));
    if let Err(error) = written {
        tracing::debug!("cannot record key parts in {}: {error}", path.display());
    }
}

/// The recorded key parts of a stage's stored entries (unreadable lines skipped).
pub fn recorded_key_parts(folder: &Path, stage: &str) -> Vec<(String, Vec<String>)> {
    let path = folder.join(KEY_PARTS_FOLDER).join(format!("{stage}.jsonl"));
    let Ok(bytes) = crate::files::read_regular_file(&path, 256 << 20) else { return Vec::new() };
    String::from_utf8_lossy(&bytes).lines().filter_map(|line| serde_json::from_str(line).ok()).collect()
}

#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LastBuildAsset {
    pub name: String,
    pub stages: Vec<(String, String)>,
}

/// Records the last build's counts (written whole and renamed, like every entry).
pub fn write_last_build(folder: &Path, last: &LastBuild) {
    let path = folder.join(LAST_BUILD_FILE);
    let json = serde_json::to_vec(last).expect("counts serialise");
    if let Err(error) = crate::files::write_atomically(&path, |file| std::io::Write::write_all(file, &json)) {
        tracing::warn!("cannot write {}: {error}", path.display());
    }
}

/// The last build's counts, if a build recorded them.
pub fn read_last_build(folder: &Path) -> Option<LastBuild> {
    let bytes = crate::files::read_regular_file(&folder.join(LAST_BUILD_FILE), 16 << 20).ok()?;
    serde_json::from_slice(&bytes).ok()
}

/// What the caches did in one build: local hits and misses (a local miss may still be a remote
/// hit), and the shared store's counts when there is one.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct CacheCounts {
    pub local_hits: u64,
    pub local_misses: u64,
    pub remote: Option<RemoteCounts>,
}
