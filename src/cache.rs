//! The persistent stage cache: results stored on disk under a content address (stage, stage
//! version, settings and input hashes), so a restart with unchanged sources runs no stage.
//! Entries are written to a temporary file and renamed into place; a corrupt or unreadable entry
//! is a miss, never an error.

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
        let bytes = std::fs::read(self.entry_path(stage, key)).ok()?;
        decode_entry(&bytes)
    }

    /// Stores an entry; failures (full disk, permissions) only cost a future miss.
    pub fn store(&self, stage: &str, key: CacheKey, entry: &CacheEntry) {
        let path = self.entry_path(stage, key);
        let result = (|| -> std::io::Result<()> {
            let folder = path.parent().expect("entry paths have a folder");
            std::fs::create_dir_all(folder)?;
            let mut temporary = tempfile::NamedTempFile::new_in(folder)?;
            temporary.write_all(&encode_entry(entry))?;
            temporary.persist(&path).map_err(|error| error.error)?;
            Ok(())
        })();
        if let Err(error) = result {
            tracing::warn!("cannot write cache entry {}: {error}", path.display());
        }
    }
}

fn encode_entry(entry: &CacheEntry) -> Vec<u8> {
    let metadata = serde_json::to_vec(&entry.metadata).expect("JSON values serialise");
    let mut bytes = Vec::new();
    bytes.extend_from_slice(b"CIRRUSC1");
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

fn decode_entry(bytes: &[u8]) -> Option<CacheEntry> {
    let (body, checksum) = bytes.split_at_checked(bytes.len().checked_sub(32)?)?;
    if blake3::hash(body).as_bytes() != checksum {
        return None;
    }
    let mut rest = body.strip_prefix(b"CIRRUSC1")?;
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
