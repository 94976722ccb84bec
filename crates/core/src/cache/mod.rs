//! The persistent stage cache: results stored on disk under a content address (stage, stage
//! version, settings and input hashes), so a restart with unchanged sources runs no stage.
//! Entries are written to a temporary file and renamed into place; a corrupt or unreadable entry
//! is a miss, never an error. Each entry records its stage and key, so an entry file that sits
//! under another key (copied or swapped by hand) is a miss too, never another result.
//!
//! # Keys
//!
//! A key is the blake3 hash of an explicit byte encoding, the same on every machine and in every
//! checkout folder, whatever the source folder is called (no `Debug` text, no absolute paths,
//! file paths relative to the pipeline's `source` folder), so that a cache can be shared. The
//! values follow suit: in an entry's metadata every string that is a path below the source
//! folder is written `$source/…` and read back below the reader's own (`db::load_cached`).
//!
//! - the prefix `cirrus-cache-v2\0`, then the entry's stage name and format version;
//! - then each part, in the order the table says, as `u64` little-endian length + bytes, where a
//!   part's bytes are: integers little-endian (`u32`, `i32`); `f32` by its bit pattern; `bool` as
//!   one byte; strings as UTF-8; paths relative to the source folder with `/` separators; enums by their
//!   names as written in `pipeline.ron` (`Bc7`, `Ktx2`, …) or their artifact names (`albedo`);
//!   `Option` as a tag byte (0 none, 1 some) then the value; arrays, tuples and settings structs
//!   as their fields in declaration order, each a part of its own; content as its blake3 hash.
//!
//! Each entry folder (key name, version): its parts, in order, and what it holds.
//!
//! - `parse` (`parse`, `PARSE`): the `.mymaterial` content hash; its path. Holds the parsed material file.
//! - `surface-recipe` (`surface`, 5): the tail's parts (below); the kind's recipe key. Holds the content key of the
//!   surface's files.
//! - `surface` (`surface`, 5): the tail's parts; the image's width, height and content hash. Holds the container file
//!   and PNG preview.
//! - `encoding-memo` (`encoding-memo`, 5): mips and encode versions; the surface's label (`asset/material/surface`,
//!   `asset/surface`). Holds a BC7 surface's last encoding: level 0's block fingerprints, the other levels, the blocks,
//!   the errors and, alpha-tested, each block's alpha-test figures (a memo: overwritten).
//! - `mesh` (`mesh`, `MESH`): per file the mesh stage reads (the OBJ, then its MTL files), its path and its content
//!   hash or read error. Holds the loaded mesh (with each triangle's OBJ object) and tangents.
//! - `planes` (`planes`, `PLANES`): the `mesh` key; ε; max planes option. Holds the plane set.
//! - `layout` (`layout`, `LAYOUT`): the `planes` key; atlas settings (max size, padding, power of two); texel density
//!   option. Holds rectangles, layout, render groups.
//! - `lod` (`lod`, `LOD`): the `layout` key. Holds `lod.obj`, `lod.mtl`.
//! - `reduce` (`reduce`, `REDUCE`): the `mesh` key; `triangles` and a count or `ratio` and a fraction; the error bound.
//!   Holds a reduced level's figures, `lod.obj` and its glTF geometry (with tangents).
//! - `render-memo` (`render-memo`, `RENDER`): the `layout` key; a material set. Holds the images of every render group
//!   that shows that set, each under its group key (a memo: overwritten).
//! - `atlas` (`atlas-coverage`, 1): the billboard atlas recipe key. Holds the atlas's coverage fraction (for the
//!   report).
//! - `atlas-fill` (`atlas-fill`, 1): the coverage's content hash (atlas size, then every drawn texel's atlas texel,
//!   plane and plane texel as `u32`). Holds the fill search's source of every atlas texel (as offsets).
//! - `surface-recipe` (`surface`, 5): the tail's parts; the atlas surface's parts key (below). Holds the content key of
//!   the surface's files.
//! - `trim` (`trim`, `TRIM`): the trim setting; the texture memory budget (`u64`); the texture file's path and content
//!   hash or read error. Holds an atlas texture's size, kept rectangle, kept texels' hash, translucency.
//! - `trim` (`trim`, `TRIM`), kept: `kept`; the kept rectangle (x, y, width, height); the texture file's path and
//!   content hash or read error; the texture memory budget. Holds a texture kept to a rectangle its meshes' UVs reach:
//!   size, rectangle, kept texels' hash, translucency.
//! - `reach` (`reach`, `REACH`): the atlas's texture paths; the OBJ's and its MTL files' paths and content hashes.
//!   Holds per texture the mesh's materials map, the range of their UVs.
//! - `layout` (`layout`, `atlas::LAYOUT`): `atlas`; the pack settings key (`atlas-settings`, 1: max size, padding,
//!   pages; rotate, power of two, trim); the file count; per texture file its path and content hash or read error; the
//!   blake3 of the meshes' UV reach as JSON (paths `$source/…`). Holds an atlas layout (entries with their aliases,
//!   pages, placements) and how it came from the last one.
//! - `atlas-layout-memo` (`atlas-layout-memo`, `atlas::LAYOUT`): the asset's name; the pack settings key. Holds the
//!   asset's last layout, the packer's hint (a memo: overwritten).
//! - `atlas-page-memo` (`atlas-page-memo`, `COMPOSITE`): the page's name (`atlas-page:asset/pageN`). Holds a page's
//!   last composite: its entries (placement, kept hash, translucency), the page, the fill sources as offsets (a memo:
//!   overwritten).
//! - `remap` (`remap`, `REMAP`): the blake3 of the layout's JSON (paths `$source/…`); the textures its materials name
//!   that are missing; the OBJ's and its MTL files' paths and content hashes. Holds a remapped mesh's OBJ text and
//!   materials.
//! - `vertices` (`vertices`, `VERTICES`): the mesh's content hash (positions, normals, UVs, triangles, groups); rays;
//!   distribution; max distance in mesh units; back faces pass through; ground plane option; the vertex offset. Holds
//!   an AO asset's visibility per vertex (`f32`).
//! - `ao-tile` (`bake`, `BAKE`): the map size; the tile's region (x, y, width, height); the mode (`Texels`,
//!   `Vertices`); per texel the occlusion settings as for `vertices`, the hash of its own triangles' corners (UV,
//!   position and normal bits), then `within reach` and the hash of the occluders within reach (group, corner
//!   positions) or `whole mesh` and the mesh's content hash; per vertex the hash of its own triangles' corners and of
//!   their visibility. Holds a baked tile: 16-bit values, texel states, overlap count, rays, bake time.
//! - `ao-map` (`fill`, `FILL`): the map size; every tile key of the material, in row order. Holds a material's filled
//!   map (16-bit), its 16-bit PNG and its figures.
//! - `height-map` (`bake`, `height::BAKE`): the projection (`Normals`, `TopDown`); for `TopDown` (a GPU render) the
//!   GPU's driver family as an option (`gpu::adapter_family`), else none; `low` or `pn`; the map size; frontal; rear
//!   (fractions of the diagonal); the low and the high mesh's geometry hash (positions, normals, UVs, triangles). Holds
//!   a filled height map (`f32` distances), texel states, its 16-bit PNG, range and counts.
//! - `height-tessellated` (`displace`, `DISPLACE`): the tessellate version; level; displace; the low geometry hash;
//!   when displaced, the `pn` map's key. Holds `tessellated.obj` and its counts.
//! - `height-distance` (`distance`, `DISTANCE`): `low`, `pn` or `displaced`; samples per surface (`u64`); the measured
//!   mesh's key (low: `distance` and the low geometry hash; pn: `tessellate`, level, the low geometry hash; displaced:
//!   the `height-tessellated` key); the high geometry hash. Holds RMS and Hausdorff distance over the high mesh's
//!   diagonal, or none.
//! - `source-mips` (`source-mips`, 1): decode and mips versions; the texture file's content hash; the material slot;
//!   the filter kind; the alpha cutoff bits (or `u32::MAX`). Holds the mip chain the renders sample.
//!
//! The tail's parts: the mips, encode and write versions; the surface name; block format;
//! encoder quality; mips; alpha cutoff option; container; zstd level option.
//!
//! Recipe keys (what a surface's image is made of, cheap to compute, so that a surface in the
//! cache needs no image): a material surface's is (`pack`, `PACK`), the surface name, the
//! material's constants (albedo ×4, metallic, roughness, ao, alpha cutoff option), per slot of
//! the surface the source's content hash or `none`; a billboard cloud's atlas surfaces share
//! (`atlas`, `ATLAS`), the render version, the GPU's driver family (`gpu::adapter_family`:
//! backend, vendor id, driver, e.g. `Vulkan/0x10005/llvmpipe`), the `layout` key, the alpha cutoff, per texture the
//! materials name its path and content hash or read error. A render group's key: (`render`,
//! `RENDER`), the GPU's driver family, the `layout` key, the group's index, the alpha cutoff, per texture of the
//! group's
//! materials its path and content hash or read error. An atlas surface's parts key, asked when
//! its recipe misses (after the renders, before compositing): (`atlas-parts`, 1), the atlas
//! version, the `layout` key, the alpha cutoff, the surface, the coverage's content hash, and
//! the hash of that surface's image of every render group (width, height, bytes). An atlas
//! page's recipe: (`composite`, `COMPOSITE`), the page number, its width and height, the padding,
//! the trim setting, then per entry on the page its placement (x, y, width, height; rotated), its
//! trim rectangle (x, y, width, height), and its file's path and content hash.
//!
//! Memos are not content addresses but an identity's last result, overwritten on every run:
//! they only let the next run skip work, and what they hold is checked against the current
//! inputs (group keys, settings, block fingerprints) before any of it is reused. Plane images
//! and the last encodings are stored this way because they are large (on the oak, 37 MB of
//! images in one entry per material set instead of 1,245 entries, which made a full bake 1.0 s
//! slower; 16 MB per atlas surface, kept for BC7 only, the one slow encoder).
//!
//! Blobs of images are zstd-compressed (level 1, in 4 MiB frames compressed and decompressed in
//! parallel straight into each blob's buffer; surface files and encoding memos are stored as
//! they are); entries are streamed to their file with the checksum computed on the way; entries
//! of 1 MiB or more, and memos gathered from shared images, are made and written on a thread of
//! their own, and the build waits for them before it reports.
//!
//! Bump an entry's version (or a stage's) whenever its result changes for the same parts.
//!
//! # The shared cache
//!
//! With `cache: (remote: Some("s3://bucket/prefix"))` (or `--remote-cache`), the same entries,
//! byte for byte, also live on an object store (`remote`): a local miss asks it (a verified
//! hit is copied here), and what is stored here is uploaded (read-write mode). Memos (stages
//! ending in `-memo`) stay local. Keys hold no absolute path and no machine-specific value but
//! the GPU's driver family, in the keys of what comes off the GPU. `upkeep` keeps the folder:
//! an entry's modification time is its last use, `cirrus cache gc` deletes the least recently
//! used, and each build records its hits and misses for `cirrus cache stats`. A key builder
//! keeps a short description of each part; stored entries' descriptions are appended to
//! `key-parts/<stage>.jsonl` and a build records its misses with theirs, so that `cirrus cache
//! explain` can say which part of a missed key differs from the nearest stored one.

use std::cell::Cell;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

use rayon::prelude::*;

pub mod key;
pub mod remote;
pub mod upkeep;

pub use key::{CacheKey, CacheKeyBuilder, KeyPart};
use remote::RemoteStore;
pub use upkeep::CacheCounts;

/// Largest cache entry read back.
const MAX_ENTRY_BYTES: u64 = 4 << 30;

/// A cache folder: one file per entry, a header line of JSON followed by binary blobs; behind
/// it, optionally, the shared store (`remote`), asked on a local miss and given what is stored.
#[derive(Clone, Debug)]
pub struct DiskCache {
    folder: PathBuf,
    /// Writes of large entries still running on their own threads (see `flush`).
    pending: Arc<std::sync::Mutex<Vec<std::thread::JoinHandle<()>>>>,
    remote: Option<Arc<RemoteStore>>,
    counters: Arc<LocalCounters>,
    /// The misses of this build (see `take_misses`).
    misses: Arc<std::sync::Mutex<Vec<upkeep::Miss>>>,
}

#[derive(Debug, Default)]
struct LocalCounters {
    hits: AtomicU64,
    misses: AtomicU64,
}

thread_local! {
    /// The asset whose job runs on this thread (for the misses a build records).
    static CURRENT_ASSET: std::cell::RefCell<Option<String>> = const { std::cell::RefCell::new(None) };
    /// Set when a load on this thread was served by the shared store; taken by the stage that
    /// records the hit (`take_remote_hit`), so that the build summary can say `remote`.
    static REMOTE_HIT: Cell<bool> = const { Cell::new(false) };
}

/// Runs `body` with lookups on this thread attributed to `asset` (a job of that asset).
pub fn with_asset<T>(asset: &str, body: impl FnOnce() -> T) -> T {
    let previous = CURRENT_ASSET.with(|current| current.replace(Some(asset.to_string())));
    let result = body();
    CURRENT_ASSET.with(|current| *current.borrow_mut() = previous);
    result
}

/// Whether a load on this thread was served by the shared store since the last call.
pub fn take_remote_hit() -> bool {
    REMOTE_HIT.with(|hit| hit.replace(false))
}

/// Entries at least this large (before compression) are compressed and written on a thread of
/// their own, so that the stage that made them goes on (the build waits for them at its end).
const BACKGROUND_STORE_BYTES: usize = 1 << 20;

/// One cache entry: small metadata plus large binary parts.
#[derive(Clone, Debug, PartialEq)]
pub struct CacheEntry {
    /// A stage's own serde struct as JSON: stages make and read it through [`CacheEntry::new`]
    /// and [`CacheEntry::parts`]; it is public for tools and tests that forge damaged entries.
    pub metadata: serde_json::Value,
    pub blobs: Vec<Vec<u8>>,
    /// Compress the body (images with uniform areas); false for blobs that are compressed
    /// already (KTX2 with zstd, PNG), where it would cost time and save nothing.
    pub compress: bool,
}

/// The one codec of cache entries: a stage's metadata is its own serde struct (read back by
/// type, not by field name), its large data are blobs.
impl CacheEntry {
    /// An entry of `metadata` (serialised as JSON) beside `blobs`; `compress` for bodies that
    /// compress (images with uniform areas), not for blobs compressed already.
    pub fn new(metadata: &impl serde::Serialize, blobs: Vec<Vec<u8>>, compress: bool) -> CacheEntry {
        CacheEntry { metadata: serde_json::to_value(metadata).expect("cache metadata serialises"), blobs, compress }
    }

    /// An entry of blobs alone.
    pub fn of_blobs(blobs: Vec<Vec<u8>>, compress: bool) -> CacheEntry {
        CacheEntry { metadata: serde_json::Value::Null, blobs, compress }
    }

    /// The metadata as `T` and exactly `N` blobs; none when the entry has another shape (a hand-
    /// made or older entry is a miss, never a panic).
    pub fn parts<T: serde::de::DeserializeOwned, const N: usize>(self) -> Option<(T, [Vec<u8>; N])> {
        let metadata = T::deserialize(&self.metadata).ok()?;
        Some((metadata, self.blobs.try_into().ok()?))
    }

    /// Exactly `N` blobs (of an entry made by [`CacheEntry::of_blobs`]).
    pub fn into_blobs<const N: usize>(self) -> Option<[Vec<u8>; N]> {
        self.blobs.try_into().ok()
    }

    /// The metadata as `T` and every blob (for entries whose blob count the metadata tells).
    pub fn metadata_and_blobs<T: serde::de::DeserializeOwned>(self) -> Option<(T, Vec<Vec<u8>>)> {
        Some((T::deserialize(&self.metadata).ok()?, self.blobs))
    }
}

impl DiskCache {
    pub fn new(folder: impl Into<PathBuf>) -> DiskCache {
        DiskCache {
            folder: folder.into(),
            pending: Default::default(),
            remote: None,
            counters: Default::default(),
            misses: Default::default(),
        }
    }

    /// The same folder with a shared store behind it.
    pub fn with_remote(self, remote: RemoteStore) -> DiskCache {
        DiskCache { remote: Some(Arc::new(remote)), ..self }
    }

    pub fn remote(&self) -> Option<&RemoteStore> {
        self.remote.as_deref()
    }

    /// The lookups that found nothing, local or remote, since the last call (at most
    /// `upkeep::MAX_RECORDED_MISSES`), with their keys' parts.
    pub fn take_misses(&self) -> Vec<upkeep::Miss> {
        std::mem::take(&mut *self.misses.lock().expect("misses lock"))
    }

    /// What the caches did since the last call (a build's figures).
    pub fn take_counts(&self) -> CacheCounts {
        CacheCounts {
            local_hits: self.counters.hits.swap(0, Ordering::Relaxed),
            local_misses: self.counters.misses.swap(0, Ordering::Relaxed),
            remote: self.remote.as_ref().map(|remote| remote.take_counts()),
        }
    }

    pub fn folder(&self) -> &Path {
        &self.folder
    }

    fn entry_path(&self, stage: &str, key: CacheKey) -> PathBuf {
        let hex = key.0.to_hex();
        self.folder.join(stage).join(&hex[..2]).join(&hex[2..])
    }

    /// Whether an entry exists under `key`: a local file (it may still turn out corrupt when
    /// loaded), or a verified object of the shared store, which is then copied here.
    pub fn contains(&self, stage: &str, key: CacheKey) -> bool {
        self.entry_path(stage, key).is_file() || self.fetch_remote(stage, key).is_some()
    }

    /// The entry under `key`: the local file, else the shared store's object (verified, then
    /// kept here); `None` when neither has a good one.
    pub fn load(&self, stage: &str, key: CacheKey) -> Option<CacheEntry> {
        let path = self.entry_path(stage, key);
        let local = crate::files::read_regular_file(&path, MAX_ENTRY_BYTES)
            .ok()
            .and_then(|bytes| decode_entry(&bytes, stage, key));
        if local.is_some() {
            self.counters.hits.fetch_add(1, Ordering::Relaxed);
            upkeep::mark_used(&path);
            return local;
        }
        self.counters.misses.fetch_add(1, Ordering::Relaxed);
        let fetched = self.fetch_remote(stage, key);
        if fetched.is_none() {
            let mut misses = self.misses.lock().expect("misses lock");
            if misses.len() < upkeep::MAX_RECORDED_MISSES {
                misses.push(upkeep::Miss {
                    asset: CURRENT_ASSET.with(|current| current.borrow().clone()),
                    stage: stage.to_string(),
                    key: key.0.to_hex().to_string(),
                    parts: key::key_parts::of(key).map(|parts| parts.to_vec()).unwrap_or_default(),
                });
            }
        }
        fetched
    }

    /// The shared store's entry under `key`, verified as it streams into the local folder
    /// (`RemoteStore::fetch_to_file`), then decoded from there as a local entry is.
    fn fetch_remote(&self, stage: &str, key: CacheKey) -> Option<CacheEntry> {
        let remote = self.remote.as_ref()?;
        let path = self.entry_path(stage, key);
        let folder = path.parent().expect("entry paths have a folder");
        let temporary = remote.fetch_to_file(stage, key, &entry_header(stage, key), folder)?.ok()?;
        let entry = crate::files::read_regular_file(temporary.path(), MAX_ENTRY_BYTES)
            .ok()
            .and_then(|bytes| decode_entry(&bytes, stage, key));
        remote.verified(stage, key, entry.is_some());
        let entry = entry?;
        if let Err(error) = temporary.persist(&path) {
            tracing::warn!("cannot write cache entry {}: {}", path.display(), error.error);
        }
        REMOTE_HIT.with(|hit| hit.set(true));
        Some(entry)
    }

    /// Stores an entry; failures (full disk, permissions) only cost a future miss. Large entries
    /// are written in the background: call `flush` before relying on them being on disk.
    pub fn store(&self, stage: &str, key: CacheKey, entry: CacheEntry) {
        if entry_size(&entry) < BACKGROUND_STORE_BYTES {
            self.write_entry(stage, key, &entry);
        } else {
            self.store_in_background(stage, key, move || entry);
        }
    }

    /// Makes an entry and stores it on a thread of its own (for large entries whose making,
    /// such as gathering images into one blob, would hold up the stage); see `flush`.
    pub fn store_in_background(&self, stage: &str, key: CacheKey, make: impl FnOnce() -> CacheEntry + Send + 'static) {
        let (cache, stage) = (self.clone(), stage.to_string());
        let write = std::thread::spawn(move || cache.write_entry(&stage, key, &make()));
        self.pending.lock().expect("pending writes lock").push(write);
    }

    /// Writes an entry (temporary file, then rename) and gives its bytes to the shared store.
    fn write_entry(&self, stage: &str, key: CacheKey, entry: &CacheEntry) {
        let path = self.entry_path(stage, key);
        if let Err(error) = crate::files::write_atomically(&path, |file| write_entry_to(file, stage, key, entry)) {
            tracing::warn!("cannot write cache entry {}: {error}", path.display());
            return;
        }
        if let Some(parts) = key::key_parts::of(key) {
            upkeep::record_key_parts(&self.folder, stage, key, &parts);
        }
        if let Some(remote) = self.remote.as_ref().filter(|remote| remote.uploads(stage)) {
            // The file as written (the page cache has it): the object is the entry, byte for byte.
            match crate::files::read_regular_file(&path, MAX_ENTRY_BYTES) {
                Ok(bytes) => remote.upload(stage, key, bytes),
                Err(error) => tracing::warn!("cannot read back cache entry {}: {error}", path.display()),
            }
        }
    }

    /// Waits for the entries still being written, and for their uploads.
    pub fn flush(&self) {
        let pending = std::mem::take(&mut *self.pending.lock().expect("pending writes lock"));
        for write in pending {
            let _ = write.join();
        }
        if let Some(remote) = &self.remote {
            remote.wait_for_uploads();
        }
    }
}

fn entry_size(entry: &CacheEntry) -> usize {
    entry.blobs.iter().map(Vec::len).sum()
}

/// The header of an entry: format, then the stage and key it was stored under.
fn entry_header(stage: &str, key: CacheKey) -> Vec<u8> {
    let mut header = b"CIRRUSC4".to_vec();
    header.extend_from_slice(&(stage.len() as u64).to_le_bytes());
    header.extend_from_slice(stage.as_bytes());
    header.extend_from_slice(key.0.as_bytes());
    header
}

/// zstd level of entry bodies: the fastest, because most bytes are images with large uniform
/// areas (a fill, transparent texels), which it already shrinks severalfold.
const ENTRY_ZSTD_LEVEL: i32 = 1;

/// Blobs are compressed in frames of this many bytes, in parallel (a 40 MB render memo
/// compresses and decompresses on every core), and decompressed straight into their own
/// buffers (no body to copy them out of).
const ENTRY_FRAME_BYTES: usize = 4 << 20;

/// Header; whether blobs are compressed; the metadata (JSON); the blobs, each as its length
/// and then its bytes, or its zstd frames (count, then each frame's stored length and bytes);
/// and a blake3 checksum of everything before it. Written straight to `file` as it is made
/// (a 30 MB entry is never gathered into one buffer first).
fn write_entry_to(file: &mut std::fs::File, stage: &str, key: CacheKey, entry: &CacheEntry) -> std::io::Result<()> {
    let mut writer =
        ChecksummedWriter { inner: std::io::BufWriter::with_capacity(1 << 20, file), hasher: blake3::Hasher::new() };
    let metadata = serde_json::to_vec(&entry.metadata).expect("JSON values serialise");
    writer.write(&entry_header(stage, key))?;
    writer.write(&[entry.compress as u8])?;
    writer.write(&(metadata.len() as u64).to_le_bytes())?;
    writer.write(&metadata)?;
    writer.write(&(entry.blobs.len() as u64).to_le_bytes())?;
    if entry.compress {
        let frames: Vec<&[u8]> = entry.blobs.iter().flat_map(|blob| blob.chunks(ENTRY_FRAME_BYTES)).collect();
        let compressed: Vec<Vec<u8>> = frames
            .par_iter()
            .map(|frame| zstd::bulk::compress(frame, ENTRY_ZSTD_LEVEL).expect("zstd compresses in memory"))
            .collect();
        let mut compressed = compressed.into_iter();
        for blob in &entry.blobs {
            let frame_count = blob.len().div_ceil(ENTRY_FRAME_BYTES);
            writer.write(&(blob.len() as u64).to_le_bytes())?;
            writer.write(&(frame_count as u64).to_le_bytes())?;
            for frame in compressed.by_ref().take(frame_count) {
                writer.write(&(frame.len() as u64).to_le_bytes())?;
                writer.write(&frame)?;
            }
        }
    } else {
        for blob in &entry.blobs {
            writer.write(&(blob.len() as u64).to_le_bytes())?;
            writer.write(blob)?;
        }
    }
    let checksum = writer.hasher.finalize();
    writer.inner.write_all(checksum.as_bytes())?;
    writer.inner.flush()
}

/// A buffered file writer that hashes what it writes.
struct ChecksummedWriter<W: Write> {
    inner: std::io::BufWriter<W>,
    hasher: blake3::Hasher,
}

impl<W: Write> ChecksummedWriter<W> {
    fn write(&mut self, bytes: &[u8]) -> std::io::Result<()> {
        if bytes.len() >= 1 << 20 {
            self.hasher.update_rayon(bytes);
        } else {
            self.hasher.update(bytes);
        }
        self.inner.write_all(bytes)
    }
}

fn decode_entry(bytes: &[u8], stage: &str, key: CacheKey) -> Option<CacheEntry> {
    let (body, checksum) = bytes.split_at_checked(bytes.len().checked_sub(32)?)?;
    if blake3::hash(body).as_bytes() != checksum {
        return None;
    }
    let mut reader = EntryReader(body.strip_prefix(entry_header(stage, key).as_slice())?);
    let compress = match reader.bytes(1)? {
        [0] => false,
        [1] => true,
        _ => return None,
    };
    let metadata_length = reader.length()?;
    let metadata = serde_json::from_slice(reader.bytes(metadata_length)?).ok()?;
    let blob_count = reader.length()?;
    let mut blobs = Vec::with_capacity(blob_count.min(64));
    let mut total = 0usize;
    for _ in 0..blob_count {
        let length = reader.length()?;
        total = total.checked_add(length).filter(|&total| total as u64 <= MAX_ENTRY_BYTES)?;
        if compress {
            let frame_count = reader.length()?;
            if frame_count != length.div_ceil(ENTRY_FRAME_BYTES) {
                return None;
            }
            let mut frames = Vec::with_capacity(frame_count);
            for _ in 0..frame_count {
                let frame_length = reader.length()?;
                frames.push(reader.bytes(frame_length)?);
            }
            blobs.push(decompress_frames(&frames, length)?);
        } else {
            blobs.push(reader.bytes(length)?.to_vec());
        }
    }
    reader.0.is_empty().then_some(CacheEntry { metadata, blobs, compress })
}

/// Reads an entry's parts in order; `None` past its end.
struct EntryReader<'a>(&'a [u8]);

impl<'a> EntryReader<'a> {
    fn bytes(&mut self, count: usize) -> Option<&'a [u8]> {
        let (head, tail) = self.0.split_at_checked(count)?;
        self.0 = tail;
        Some(head)
    }

    /// A little-endian u64 length, at most `MAX_ENTRY_BYTES`.
    fn length(&mut self) -> Option<usize> {
        let length = u64::from_le_bytes(self.bytes(8)?.try_into().ok()?);
        (length <= MAX_ENTRY_BYTES).then_some(length as usize)
    }
}

/// A blob of `length` bytes from its zstd frames (each `ENTRY_FRAME_BYTES` long but the
/// last), decompressed in parallel into one buffer; `None` when a frame does not fit.
fn decompress_frames(frames: &[&[u8]], length: usize) -> Option<Vec<u8>> {
    let mut blob = vec![0u8; length];
    let all_fit = blob.par_chunks_mut(ENTRY_FRAME_BYTES).zip(frames).all(|(output, frame)| {
        let mut decoder = zstd::bulk::Decompressor::new().expect("zstd decompressor");
        matches!(decoder.decompress_to_buffer(frame, output), Ok(written) if written == output.len())
    });
    all_fit.then_some(blob)
}
