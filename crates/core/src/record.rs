//! The build record (an IO edge), `<output>/.cirrus/record.json`: each source file's metadata
//! (size, modification and change times, file id) beside its content hash, so that a build
//! reads and hashes only the files whose metadata moved (git's index, cargo's fingerprints),
//! and each baked asset's fingerprint beside what it wrote and which stages it has, so that a
//! build passes over an asset none of whose inputs changed without asking salsa anything.
//!
//! Metadata never makes a changed file look unchanged: a file whose modification or change time
//! lies within [`RACY_SECONDS`] of the moment its metadata was recorded may have changed again
//! within the same timestamp tick (coarse file systems count in 1 s or 2 s), so it is "racy" and
//! hashed again on every build until it is older (git's racy-clean rule). The change time is
//! set by the kernel on every write and cannot be put back by a tool that restores the
//! modification time. A record that cannot be read is rebuilt: every file is hashed once.

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use std::time::SystemTime;

use serde::{Deserialize, Serialize};

/// A file whose metadata changed within this many seconds of the moment it was recorded is
/// hashed again on the next build (two seconds: FAT's modification-time granularity).
pub const RACY_SECONDS: i64 = 2;

/// What a file's metadata says of it: equal stamps mean an unchanged file (outside the racy
/// window). Stored as an array of its five numbers.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(from = "(u64, i64, i64, u64, u64)", into = "(u64, i64, i64, u64, u64)")]
pub struct FileStamp {
    pub size: u64,
    /// Modification time, nanoseconds since the Unix epoch.
    pub modified: i64,
    /// Change time (inode change, set by the kernel on every write), nanoseconds; 0 where the
    /// platform has none.
    pub changed: i64,
    /// The file's id (inode) and device; 0 where the platform has none.
    pub file: u64,
    pub device: u64,
}

impl From<(u64, i64, i64, u64, u64)> for FileStamp {
    fn from((size, modified, changed, file, device): (u64, i64, i64, u64, u64)) -> FileStamp {
        FileStamp { size, modified, changed, file, device }
    }
}

impl From<FileStamp> for (u64, i64, i64, u64, u64) {
    fn from(stamp: FileStamp) -> Self {
        (stamp.size, stamp.modified, stamp.changed, stamp.file, stamp.device)
    }
}

impl FileStamp {
    pub fn of(metadata: &std::fs::Metadata) -> FileStamp {
        #[cfg(unix)]
        {
            use std::os::unix::fs::MetadataExt;
            FileStamp {
                size: metadata.len(),
                modified: metadata.mtime().saturating_mul(1_000_000_000).saturating_add(metadata.mtime_nsec()),
                changed: metadata.ctime().saturating_mul(1_000_000_000).saturating_add(metadata.ctime_nsec()),
                file: metadata.ino(),
                device: metadata.dev(),
            }
        }
        #[cfg(not(unix))]
        {
            let modified = metadata.modified().ok().map_or(0, nanoseconds_since_epoch);
            FileStamp { size: metadata.len(), modified, changed: 0, file: 0, device: 0 }
        }
    }

    /// The stamp of the file at `path` now (symbolic links followed, as reads follow them).
    pub fn read(path: &Path) -> Option<FileStamp> {
        std::fs::metadata(path).ok().filter(std::fs::Metadata::is_file).map(|metadata| FileStamp::of(&metadata))
    }

    /// Whether the file may change again without its stamp changing: its last modification or
    /// change lies within the racy window of `recorded_at` (or after it: a clock set back).
    fn is_racy(&self, recorded_at: i64) -> bool {
        let latest = self.modified.max(self.changed);
        latest.saturating_add(RACY_SECONDS * 1_000_000_000) >= recorded_at
    }
}

fn nanoseconds_since_epoch(time: SystemTime) -> i64 {
    match time.duration_since(SystemTime::UNIX_EPOCH) {
        Ok(after) => after.as_nanos().min(i64::MAX as u128) as i64,
        Err(before) => -(before.duration().as_nanos().min(i64::MAX as u128) as i64),
    }
}

/// Now, as the record counts time.
pub fn now() -> i64 {
    nanoseconds_since_epoch(SystemTime::now())
}

/// One source file as last seen: its stamp, its content's blake3, and whether the stamp was
/// racy when taken (then the hash is checked again next time).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RecordedFile {
    pub stamp: FileStamp,
    #[serde(with = "hex_hash")]
    pub hash: blake3::Hash,
    pub racy: bool,
}

/// One stage instance of a baked asset, as the summary and the graph name it (short field
/// names: a level's record holds tens of thousands).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct InstanceRecord {
    #[serde(rename = "s")]
    pub stage: String,
    #[serde(rename = "l")]
    pub label: String,
    /// Its name in the summary; absent when it is the label.
    #[serde(rename = "i", default, skip_serializing_if = "Option::is_none")]
    instance: Option<String>,
    /// Node ids it reads: source files (`f`) and other instances (`s`).
    #[serde(rename = "r", default, skip_serializing_if = "Vec::is_empty")]
    pub reads: Vec<ReadRecord>,
    /// Artifacts made from its result (project-relative).
    #[serde(rename = "w", default, skip_serializing_if = "Vec::is_empty")]
    pub writes: Vec<String>,
    #[serde(rename = "x", default, skip_serializing_if = "std::ops::Not::not")]
    pub shared: bool,
}

impl InstanceRecord {
    pub fn new(
        stage: String,
        label: String,
        instance: String,
        reads: Vec<ReadRecord>,
        writes: Vec<String>,
        shared: bool,
    ) -> Self {
        let instance = (instance != label).then_some(instance);
        InstanceRecord { stage, label, instance, reads, writes, shared }
    }

    /// Its name in the build summary.
    pub fn instance(&self) -> &str {
        self.instance.as_deref().unwrap_or(&self.label)
    }
}

/// Only what the build summary needs of an instance (parsed without the reads and writes).
#[derive(Deserialize)]
struct SummaryInstance {
    #[serde(rename = "s")]
    stage: String,
    #[serde(rename = "l")]
    label: String,
    #[serde(rename = "i", default)]
    instance: Option<String>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum ReadRecord {
    /// A source file's project-relative path.
    #[serde(rename = "f")]
    File(String),
    /// Another instance's node id, `stage(label)`.
    #[serde(rename = "s")]
    Stage(String),
}

/// A baked asset as its last successful build left it.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct AssetRecord {
    /// The blake3 of everything its outputs depend on (see the driver's `asset_fingerprint`).
    #[serde(with = "hex_hash")]
    pub fingerprint: blake3::Hash,
    /// The source files it read (project-relative), each of which enters the fingerprint.
    pub files: Vec<PathBuf>,
    /// Each artifact it wrote (project-relative), with the stamp it had when written.
    pub artifacts: BTreeMap<String, FileStamp>,
    /// Its stage instances (`InstanceRecord`s), kept as JSON text: a build reads them only for
    /// the assets it reports or dumps.
    instances: Box<serde_json::value::RawValue>,
    /// The warnings of its build summary.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub warnings: Vec<crate::summary::ErrorSummary>,
}

impl AssetRecord {
    pub fn new(
        fingerprint: blake3::Hash,
        files: Vec<PathBuf>,
        artifacts: BTreeMap<String, FileStamp>,
        instances: &[InstanceRecord],
        warnings: Vec<crate::summary::ErrorSummary>,
    ) -> AssetRecord {
        let instances = serde_json::value::to_raw_value(instances).expect("instances serialise");
        AssetRecord { fingerprint, files, artifacts, instances, warnings }
    }

    /// Its stage instances, with their reads and writes.
    pub fn instances(&self) -> Vec<InstanceRecord> {
        serde_json::from_str(self.instances.get()).unwrap_or_default()
    }

    /// Its stage instances' stage and summary names.
    pub fn stages(&self) -> Vec<(String, String)> {
        let instances: Vec<SummaryInstance> = serde_json::from_str(self.instances.get()).unwrap_or_default();
        instances.into_iter().map(|instance| (instance.stage, instance.instance.unwrap_or(instance.label))).collect()
    }
}

impl PartialEq for AssetRecord {
    fn eq(&self, other: &Self) -> bool {
        (self.fingerprint, &self.files, &self.artifacts, self.instances.get(), &self.warnings)
            == (other.fingerprint, &other.files, &other.artifacts, other.instances.get(), &other.warnings)
    }
}

/// What `record.json` holds.
#[derive(Default, Serialize, Deserialize)]
pub struct BuildRecord {
    version: u32,
    pub files: HashMap<PathBuf, RecordedFile>,
    pub assets: HashMap<String, AssetRecord>,
}

/// The record's format version: a record of another version is rebuilt.
const RECORD_VERSION: u32 = 1;

/// Largest `record.json` read back (about 2 KB per asset: 256 MiB is over 100,000 assets). It is
/// parsed as it is read, never held whole.
const MAX_RECORD_BYTES: u64 = 256 << 20;

pub fn record_path(output_dir: &Path) -> PathBuf {
    output_dir.join(".cirrus").join("record.json")
}

/// The last revision a daemon issued (`<output>/.cirrus/revision`), written with every batch:
/// the daemon writes the manifest, which holds it too, only when idle.
fn revision_path(output_dir: &Path) -> PathBuf {
    output_dir.join(".cirrus").join("revision")
}

pub fn save_revision(output_dir: &Path, revision: u64) {
    if let Err(error) = crate::files::write_if_changed(&revision_path(output_dir), revision.to_string().as_bytes()) {
        tracing::warn!("cannot write {}: {error}", revision_path(output_dir).display());
    }
}

/// The revision of [`save_revision`] (0 when none or unreadable).
pub fn saved_revision(output_dir: &Path) -> u64 {
    let bytes = crate::files::read_regular_file(&revision_path(output_dir), 64).unwrap_or_default();
    String::from_utf8_lossy(&bytes).trim().parse().unwrap_or(0)
}

/// The marker a build leaves while it writes: found by the next process, it says that a build
/// was interrupted (and may have left temporary files to sweep).
fn marker_path(output_dir: &Path) -> PathBuf {
    output_dir.join(".cirrus").join("building")
}

/// Marks the output folder as being written (see [`interrupted_build`]).
pub fn begin_writing(output_dir: &Path) {
    let marker = marker_path(output_dir);
    if let Some(folder) = marker.parent() {
        let _ = std::fs::create_dir_all(folder);
    }
    let _ = std::fs::write(marker, std::process::id().to_string());
}

/// Clears the mark of [`begin_writing`].
pub fn end_writing(output_dir: &Path) {
    let _ = std::fs::remove_file(marker_path(output_dir));
}

/// Whether a build may have been interrupted while writing into `output_dir`: its marker is
/// there, or there is no record (a first build, or one from before the record).
pub fn interrupted_build(output_dir: &Path) -> bool {
    marker_path(output_dir).exists() || !record_path(output_dir).exists()
}

impl BuildRecord {
    /// The record in `output_dir`, or an empty one (none yet, or unreadable: then it is rebuilt,
    /// every source hashed once, every asset checked through its stages).
    pub fn load(output_dir: &Path) -> BuildRecord {
        let instead = "rebuilding it (every source is hashed once)";
        let record: BuildRecord = crate::files::read_own_json(&record_path(output_dir), MAX_RECORD_BYTES, instead);
        if record.version == RECORD_VERSION {
            record
        } else {
            BuildRecord::default()
        }
    }

    /// Writes the record (temporary file + rename: a build killed meanwhile leaves the last one).
    pub fn save(&mut self, output_dir: &Path) -> std::io::Result<()> {
        self.version = RECORD_VERSION;
        let bytes = serde_json::to_vec(self).expect("the record serialises");
        crate::files::write_if_changed(&record_path(output_dir), &bytes).map(|_| ())
    }

    /// Drops what a record edited by hand (or by an attacker) could use to make a build look at
    /// files elsewhere: an asset whose files are not plain paths inside `source`, or whose
    /// artifacts are not plain paths inside `output`, and such files (project-relative folders).
    pub fn keep_within(&mut self, source: &Path, output: &Path) {
        let plain_inside = |path: &Path, folder: &Path| {
            path.starts_with(folder)
                && path.components().all(|component| matches!(component, std::path::Component::Normal(_)))
        };
        self.files.retain(|path, _| plain_inside(path, source));
        self.assets.retain(|_, asset| {
            asset.files.iter().all(|file| plain_inside(file, source))
                && asset.artifacts.keys().all(|artifact| plain_inside(Path::new(artifact), output))
        });
    }

    /// The content hash the record holds for `path` when its metadata is `stamp` and was not
    /// racy when recorded.
    pub fn trusted_hash(&self, path: &Path, stamp: &FileStamp) -> Option<blake3::Hash> {
        let recorded = self.files.get(path)?;
        (recorded.stamp == *stamp && !recorded.racy).then_some(recorded.hash)
    }

    /// Records a file's stamp and hash, seen at `seen_at` (taken before the stamp); true when
    /// the record changed.
    pub fn remember_file(&mut self, path: &Path, stamp: FileStamp, hash: blake3::Hash, seen_at: i64) -> bool {
        let racy = stamp.is_racy(seen_at);
        let recorded = RecordedFile { stamp, hash, racy };
        let changed = self.files.get(path) != Some(&recorded);
        if changed {
            self.files.insert(path.to_path_buf(), recorded);
        }
        changed
    }
}

/// A blake3 hash as 64 hex digits.
mod hex_hash {
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(hash: &blake3::Hash, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_str(hash.to_hex().as_str())
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(deserializer: D) -> Result<blake3::Hash, D::Error> {
        let text = <std::borrow::Cow<'de, str>>::deserialize(deserializer)?;
        blake3::Hash::from_hex(text.as_bytes()).map_err(serde::de::Error::custom)
    }
}
