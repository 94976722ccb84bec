//! The persistent stage cache: results stored on disk under a content address (stage, stage
//! version, settings and input hashes), so a restart with unchanged sources runs no stage.
//! Entries are written to a temporary file and renamed into place; a corrupt or unreadable entry
//! is a miss, never an error. Each entry records its stage and key, so an entry file that sits
//! under another key (copied or swapped by hand) is a miss too, never another result.

use std::io::Write;
use std::path::{Path, PathBuf};

/// A content address: the blake3 hash of everything a stage result depends on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct CacheKey(pub blake3::Hash);

/// Builds a `CacheKey` from a stage name, its version and every input that can change its result.
pub struct CacheKeyBuilder(blake3::Hasher);

impl CacheKeyBuilder {
    pub fn new(stage: &str, version: u32) -> CacheKeyBuilder {
        let mut hasher = blake3::Hasher::new();
        hasher.update(b"cirrus-cache-v1\0");
        hasher.update(stage.as_bytes());
        hasher.update(&version.to_le_bytes());
        CacheKeyBuilder(hasher)
    }

    pub fn bytes(mut self, bytes: &[u8]) -> Self {
        self.0.update(&(bytes.len() as u64).to_le_bytes());
        self.0.update(bytes);
        self
    }

    /// Adds a value by its `Debug` text: settings and small plain-data inputs.
    pub fn debug(self, value: &impl std::fmt::Debug) -> Self {
        self.bytes(format!("{value:?}").as_bytes())
    }

    pub fn finish(self) -> CacheKey {
        CacheKey(self.0.finalize())
    }
}

/// Largest cache entry read back.
const MAX_ENTRY_BYTES: u64 = 4 << 30;

/// A cache folder: one file per entry, a header line of JSON followed by binary blobs.
#[derive(Clone, Debug)]
pub struct DiskCache {
    folder: PathBuf,
}

/// One cache entry: small metadata plus large binary parts.
#[derive(Clone, Debug, PartialEq)]
pub struct CacheEntry {
    pub metadata: serde_json::Value,
    pub blobs: Vec<Vec<u8>>,
}

impl DiskCache {
    pub fn new(folder: impl Into<PathBuf>) -> DiskCache {
        DiskCache { folder: folder.into() }
    }

    pub fn folder(&self) -> &Path {
        &self.folder
    }

    fn entry_path(&self, stage: &str, key: CacheKey) -> PathBuf {
        let hex = key.0.to_hex();
        self.folder.join(stage).join(&hex[..2]).join(&hex[2..])
    }

    pub fn load(&self, stage: &str, key: CacheKey) -> Option<CacheEntry> {
        let bytes = crate::sources::read_regular_file(&self.entry_path(stage, key), MAX_ENTRY_BYTES).ok()?;
        decode_entry(&bytes, stage, key)
    }

    /// Stores an entry; failures (full disk, permissions) only cost a future miss.
    pub fn store(&self, stage: &str, key: CacheKey, entry: &CacheEntry) {
        let path = self.entry_path(stage, key);
        let result = (|| -> std::io::Result<()> {
            let folder = path.parent().expect("entry paths have a folder");
            std::fs::create_dir_all(folder)?;
            let mut temporary = tempfile::Builder::new().prefix(crate::artifacts::TEMPORARY_PREFIX).tempfile_in(folder)?;
            temporary.write_all(&encode_entry(stage, key, entry))?;
            temporary.persist(&path).map_err(|error| error.error)?;
            Ok(())
        })();
        if let Err(error) = result {
            tracing::warn!("cannot write cache entry {}: {error}", path.display());
        }
    }
}

/// The header of an entry: format, then the stage and key it was stored under.
fn entry_header(stage: &str, key: CacheKey) -> Vec<u8> {
    let mut header = b"CIRRUSC2".to_vec();
    header.extend_from_slice(&(stage.len() as u64).to_le_bytes());
    header.extend_from_slice(stage.as_bytes());
    header.extend_from_slice(key.0.as_bytes());
    header
}

fn encode_entry(stage: &str, key: CacheKey, entry: &CacheEntry) -> Vec<u8> {
    let metadata = serde_json::to_vec(&entry.metadata).expect("JSON values serialise");
    let mut bytes = entry_header(stage, key);
    bytes.extend_from_slice(&(metadata.len() as u64).to_le_bytes());
    bytes.extend_from_slice(&metadata);
    bytes.extend_from_slice(&(entry.blobs.len() as u64).to_le_bytes());
    for blob in &entry.blobs {
        bytes.extend_from_slice(&(blob.len() as u64).to_le_bytes());
        bytes.extend_from_slice(blob);
    }
    let checksum = blake3::hash(&bytes);
    bytes.extend_from_slice(checksum.as_bytes());
    bytes
}

fn decode_entry(bytes: &[u8], stage: &str, key: CacheKey) -> Option<CacheEntry> {
    let (body, checksum) = bytes.split_at_checked(bytes.len().checked_sub(32)?)?;
    if blake3::hash(body).as_bytes() != checksum {
        return None;
    }
    let mut rest = body.strip_prefix(entry_header(stage, key).as_slice())?;
    let mut take = |count: usize| -> Option<&[u8]> {
        let (head, tail) = rest.split_at_checked(count)?;
        rest = tail;
        Some(head)
    };
    let metadata_length = u64::from_le_bytes(take(8)?.try_into().ok()?) as usize;
    let metadata = serde_json::from_slice(take(metadata_length)?).ok()?;
    let blob_count = u64::from_le_bytes(take(8)?.try_into().ok()?) as usize;
    let mut blobs = Vec::with_capacity(blob_count.min(64));
    for _ in 0..blob_count {
        let length = u64::from_le_bytes(take(8)?.try_into().ok()?) as usize;
        blobs.push(take(length)?.to_vec());
    }
    Some(CacheEntry { metadata, blobs })
}
