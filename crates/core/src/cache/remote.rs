//! The shared cache's remote half (an IO edge): the disk cache's entries, byte for byte, on an
//! object store (S3-compatible through `object_store`, or a folder or an in-memory store behind
//! the same trait), fetched on a local miss and uploaded after a local store.
//!
//! - **Where.** An entry lives at `<prefix>/<stage>/<first two hex digits>/<the rest>`, the
//!   local cache's own layout, so one store serves every checkout folder and every machine.
//! - **Verified.** What comes back is the local entry format: its header names the stage and
//!   key it was stored under and it ends with the blake3 of everything before it. It is checked
//!   as it streams into a temporary file of the local cache (`StreamCheck`: never held whole in
//!   memory), then decoded before anything uses it, so a corrupt, truncated or foreign object is
//!   a miss. A key found corrupt is overwritten by the next upload of it; every other upload is
//!   a conditional create (`If-None-Match: *` on S3), so machines racing on a key are harmless.
//! - **Signed, with a team key.** With `CIRRUS_CACHE_KEY` set, an object is the entry followed
//!   by a keyed blake3 of it, under `<prefix>/signed/`: one without a good signature is a miss,
//!   so write access to the store is not enough to ship a bake.
//! - **Never in the way.** Every request has a short deadline: a download's answer and each of
//!   its chunks within `STALL_TIMEOUT`, an upload within `upload_timeout` of its size. The first
//!   request of a build is a probe (a `HEAD` that must answer within `PROBE_TIMEOUT`, and on a
//!   read-only machine a listing, which a web server that is no store fails); a store that does not answer,
//!   or any request that fails other than by "not found", is a warning, and the store is left
//!   alone for `RETRY_AFTER`, so a build goes on locally and a daemon uses the store again
//!   when it comes back.
//! - **Memos stay local.** Entries whose stage ends in `-memo` are an identity's last result,
//!   overwritten on every run (see the module docs of `cache`); they are never shared.

use std::collections::HashSet;
use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use object_store::path::Path as StorePath;
use object_store::{ObjectStore, ObjectStoreExt, PutMode, PutOptions, PutPayload};

use super::key::CacheKey;

/// Whether a machine may add entries to the shared store.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Deserialize, serde::Serialize)]
pub enum RemoteCacheMode {
    /// Fetch and upload (build machines, CI).
    #[default]
    ReadWrite,
    /// Fetch only (artists' machines).
    ReadOnly,
}

impl RemoteCacheMode {
    /// `read-write` / `read-only` (the command line's and `CIRRUS_REMOTE_CACHE_MODE`'s words),
    /// or the names `pipeline.ron` uses.
    pub fn parse(text: &str) -> Option<RemoteCacheMode> {
        match text {
            "read-write" | "ReadWrite" => Some(RemoteCacheMode::ReadWrite),
            "read-only" | "ReadOnly" => Some(RemoteCacheMode::ReadOnly),
            _ => None,
        }
    }
}

/// Where the shared entries live, as a URL names it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum RemoteLocation {
    /// `s3://bucket/prefix`: endpoint, region and credentials from the AWS environment variables.
    S3 { bucket: String, prefix: String },
    /// `file:///absolute/folder`: a shared folder (a network mount) through the same code.
    Folder(PathBuf),
    /// `memory://name`: a store that lives as long as the process (tests).
    Memory(String),
}

/// The shared cache a build uses: where, and whether it may upload.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RemoteCacheSettings {
    /// The URL as the user wrote it (for messages).
    pub url: String,
    pub location: RemoteLocation,
    pub mode: RemoteCacheMode,
}

/// Parses a shared cache URL; the error says what is wrong with it. Credentials never come
/// from the URL (nor from `pipeline.ron`): a URL with a user, password or query is refused.
pub fn parse_remote_url(url: &str) -> Result<RemoteLocation, String> {
    let Some((scheme, rest)) = url.split_once("://") else {
        return Err(format!("`{url}` is not a URL: write s3://bucket/prefix, file:///folder or memory://name"));
    };
    if rest.contains(['?', '#']) {
        return Err(format!("`{url}` has a query or fragment; settings come from the AWS environment variables"));
    }
    match scheme {
        "s3" => {
            let (bucket, prefix) = rest.split_once('/').unwrap_or((rest, ""));
            if bucket.contains('@') || bucket.contains(':') {
                return Err(format!(
                    "`{url}` names credentials or a port; they come from AWS_ACCESS_KEY_ID, AWS_SECRET_ACCESS_KEY and \
                        AWS_ENDPOINT_URL"
                ));
            }
            let bucket_ok = (3..=63).contains(&bucket.len())
                && bucket
                    .bytes()
                    .all(|byte| byte.is_ascii_lowercase() || byte.is_ascii_digit() || byte == b'-' || byte == b'.');
            if !bucket_ok {
                return Err(format!(
                    "`{bucket}` is not an S3 bucket name (3 to 63 lowercase letters, digits, `-` and `.`)"
                ));
            }
            let prefix = prefix.trim_matches('/');
            if prefix.split('/').any(|part| part == "." || part == "..") || prefix.contains("//") {
                return Err(format!("`{url}`: the prefix may not hold `.`, `..` or empty parts"));
            }
            Ok(RemoteLocation::S3 { bucket: bucket.to_string(), prefix: prefix.to_string() })
        }
        "file" => {
            let path = PathBuf::from(rest);
            if !path.is_absolute() {
                return Err(format!("`{url}`: a file URL names an absolute folder (file:///srv/cirrus-cache)"));
            }
            Ok(RemoteLocation::Folder(path))
        }
        "memory" if !rest.is_empty() => Ok(RemoteLocation::Memory(rest.to_string())),
        _ => Err(format!("`{url}`: the shared cache is an s3://, file:// or memory:// URL")),
    }
}

/// The command line's (or the environment's) word on the shared cache, over `pipeline.ron`'s.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct RemoteCacheOverride {
    /// `Some(None)`: no shared cache (`--remote-cache off`); `Some(Some(…))`: this one.
    pub location: Option<Option<(String, RemoteLocation)>>,
    pub mode: Option<RemoteCacheMode>,
}

impl RemoteCacheOverride {
    /// From `--remote-cache URL|off` and `--remote-cache-mode read-only|read-write`; an error
    /// starts with the flag it is about.
    pub fn parse(url: Option<&str>, mode: Option<&str>) -> Result<RemoteCacheOverride, String> {
        let location = match url {
            None => None,
            Some("") => {
                return Err("--remote-cache: it is empty (an unset shell variable?): name a URL (s3://bucket/prefix, \
                     file:///folder) or `off`"
                    .into())
            }
            Some("off" | "none") => Some(None),
            Some(url) => {
                Some(Some((url.to_string(), parse_remote_url(url).map_err(|why| format!("--remote-cache: {why}"))?)))
            }
        };
        let mode = match mode {
            None => None,
            Some("") => {
                return Err(
                    "--remote-cache-mode: the mode is empty (an unset shell variable?): read-write or read-only".into(),
                )
            }
            Some(text) => Some(RemoteCacheMode::parse(text).ok_or_else(|| {
                format!("--remote-cache-mode: `{text}` is not a shared cache mode: read-write or read-only")
            })?),
        };
        Ok(RemoteCacheOverride { location, mode })
    }

    /// The shared cache a build uses: the override's, else the pipeline's, in the override's
    /// mode if it names one.
    pub fn apply(&self, pipeline: Option<&RemoteCacheSettings>) -> Option<RemoteCacheSettings> {
        let mut settings = match &self.location {
            Some(None) => return None,
            Some(Some((url, location))) => RemoteCacheSettings {
                url: url.clone(),
                location: location.clone(),
                mode: pipeline.map(|settings| settings.mode).unwrap_or_default(),
            },
            None => pipeline?.clone(),
        };
        if let Some(mode) = self.mode {
            settings.mode = mode;
        }
        Some(settings)
    }
}

/// Why a shared cache could not be opened (before any request is made).
#[derive(Debug, thiserror::Error)]
#[error("shared cache `{url}`: {why}")]
pub struct RemoteCacheError {
    pub url: String,
    pub why: String,
}

/// A request that gets no answer within this is a store that does not answer.
const PROBE_TIMEOUT: Duration = Duration::from_millis(750);
/// How long a download may wait for its answer or for its next bytes: a store frozen mid-build
/// costs that build this long, not a transfer's whole allowance.
const STALL_TIMEOUT: Duration = Duration::from_secs(5);
/// The longest any one request may take (the HTTP client's own limit).
const REQUEST_TIMEOUT: Duration = Duration::from_secs(600);

/// How long an upload of `bytes` may take: `STALL_TIMEOUT`, plus the time at 4 MiB/s (a put is
/// one request, whose progress cannot be watched).
fn upload_timeout(bytes: u64) -> Duration {
    (STALL_TIMEOUT + Duration::from_secs_f64(bytes as f64 / f64::from(4u32 << 20))).min(REQUEST_TIMEOUT)
}
/// How long a store that failed is left alone.
pub const RETRY_AFTER: Duration = Duration::from_secs(10);

/// What the store did in one build (see `RemoteStore::take_counts`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct RemoteCounts {
    pub hits: u64,
    pub misses: u64,
    /// Objects that were there but failed verification (then a miss).
    pub corrupt: u64,
    pub uploads: u64,
    /// Uploads refused because another machine had created the key first.
    pub already_present: u64,
    pub bytes_downloaded: u64,
    pub bytes_uploaded: u64,
    /// Requests that failed (then the store is left alone for a while).
    pub errors: u64,
}

#[derive(Default)]
struct Counters {
    hits: AtomicU64,
    misses: AtomicU64,
    corrupt: AtomicU64,
    uploads: AtomicU64,
    already_present: AtomicU64,
    bytes_downloaded: AtomicU64,
    bytes_uploaded: AtomicU64,
    errors: AtomicU64,
}

/// Whether the store is used.
enum Health {
    /// Not asked yet since it was opened or last failed: the next request probes it.
    Untried,
    Answering,
    /// Failed at this time: left alone until `RETRY_AFTER` has passed.
    Failed(Instant),
}

/// The shared store, its runtime and what it did.
pub struct RemoteStore {
    runtime: tokio::runtime::Runtime,
    /// The largest object fetched: a larger one is no entry this project could have made.
    max_object_bytes: u64,
    /// What the upload tasks hold (never the runtime, which must not be dropped on its own threads).
    shared: Arc<Shared>,
    uploads: Mutex<Vec<tokio::task::JoinHandle<()>>>,
}

struct Shared {
    settings: RemoteCacheSettings,
    store: Arc<dyn ObjectStore>,
    prefix: StorePath,
    /// The team's key (`CIRRUS_CACHE_KEY`): objects are then signed entries, in a folder of
    /// their own (`signed/`), and an object without a good signature is a miss.
    signing: Option<[u8; 32]>,
    health: Mutex<Health>,
    counters: Counters,
    /// Keys whose object failed verification: the next upload overwrites them.
    corrupt_keys: Mutex<HashSet<(String, CacheKey)>>,
}

impl std::fmt::Debug for RemoteStore {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "RemoteStore({})", self.shared.settings.url)
    }
}

/// In-memory stores by name, so that two projects in one process share one.
fn memory_store(name: &str) -> Arc<dyn ObjectStore> {
    static STORES: Mutex<Vec<(String, Arc<dyn ObjectStore>)>> = Mutex::new(Vec::new());
    let mut stores = STORES.lock().expect("memory stores lock");
    if let Some((_, store)) = stores.iter().find(|(stored, _)| stored == name) {
        return store.clone();
    }
    let store: Arc<dyn ObjectStore> = Arc::new(object_store::memory::InMemory::new());
    stores.push((name.to_string(), store.clone()));
    store
}

/// Installs the TLS provider of every HTTPS client in the process (rustls on `ring`, see
/// Cargo.toml): an object-store client built without one panics. Installing twice is harmless.
pub fn install_tls_provider() {
    let _ = rustls::crypto::ring::default_provider().install_default();
}

impl RemoteStore {
    /// Opens the store without contacting it (the first request does).
    pub fn open(settings: RemoteCacheSettings) -> Result<RemoteStore, RemoteCacheError> {
        let error = |why: String| RemoteCacheError { url: settings.url.clone(), why };
        let (store, prefix): (Arc<dyn ObjectStore>, String) = match &settings.location {
            RemoteLocation::S3 { bucket, prefix } => {
                check_endpoint_environment().map_err(error)?;
                install_tls_provider();
                let client = object_store::ClientOptions::new()
                    .with_connect_timeout(PROBE_TIMEOUT)
                    .with_timeout(REQUEST_TIMEOUT)
                    .with_allow_http(true);
                let retry = object_store::RetryConfig {
                    max_retries: 1,
                    retry_timeout: Duration::from_secs(2),
                    backoff: object_store::BackoffConfig {
                        init_backoff: Duration::from_millis(50),
                        max_backoff: Duration::from_millis(200),
                        base: 2.0,
                    },
                };
                let store = object_store::aws::AmazonS3Builder::from_env()
                    .with_bucket_name(bucket)
                    .with_client_options(client)
                    .with_retry(retry)
                    .build()
                    .map_err(|why| error(why.to_string()))?;
                (Arc::new(store), prefix.clone())
            }
            RemoteLocation::Folder(folder) => {
                std::fs::create_dir_all(folder)
                    .map_err(|why| error(format!("cannot create {}: {why}", folder.display())))?;
                let store = object_store::local::LocalFileSystem::new_with_prefix(folder)
                    .map_err(|why| error(why.to_string()))?;
                (Arc::new(store), String::new())
            }
            RemoteLocation::Memory(name) => (memory_store(name), String::new()),
        };
        let signing = signing_key_from_environment().map_err(error)?;
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .thread_name("cirrus-remote-cache")
            .enable_all()
            .build()
            .map_err(|why| error(format!("cannot start its IO threads: {why}")))?;
        let shared = Shared {
            settings,
            store,
            prefix: StorePath::from(prefix),
            signing,
            health: Mutex::new(Health::Untried),
            counters: Counters::default(),
            corrupt_keys: Mutex::default(),
        };
        Ok(RemoteStore {
            runtime,
            max_object_bytes: DEFAULT_MAX_OBJECT_BYTES,
            shared: Arc::new(shared),
            uploads: Mutex::default(),
        })
    }

    /// The same store, refusing objects larger than `bytes` without downloading them.
    pub fn with_object_limit(self, bytes: u64) -> RemoteStore {
        RemoteStore { max_object_bytes: bytes, ..self }
    }

    pub fn settings(&self) -> &RemoteCacheSettings {
        &self.shared.settings
    }
}

/// The environment variable holding the team's key for signed entries.
const CACHE_KEY_VARIABLE: &str = "CIRRUS_CACHE_KEY";

/// The shortest key taken (a passphrase or, better, `openssl rand -hex 32`).
const MIN_CACHE_KEY_CHARS: usize = 32;

/// The signing key `CIRRUS_CACHE_KEY` gives (derived from its text), none when it is not set.
fn signing_key_from_environment() -> Result<Option<[u8; 32]>, String> {
    let Some(text) = std::env::var_os(CACHE_KEY_VARIABLE) else { return Ok(None) };
    let text = text.to_string_lossy();
    let text = text.trim();
    if text.chars().count() < MIN_CACHE_KEY_CHARS {
        return Err(format!(
            "{CACHE_KEY_VARIABLE} is {} characters long: a team key needs at least {MIN_CACHE_KEY_CHARS} (make one \
             with `openssl rand -hex 32`)",
            text.chars().count()
        ));
    }
    Ok(Some(blake3::derive_key("cirrus 2026-12 shared cache entry signing", text.as_bytes())))
}

/// Why a fetched object is no entry (then a miss, and the key is overwritten by its next upload).
#[derive(Debug)]
pub enum Unverified {
    /// Larger than any entry can be (its size, refused before a byte is read).
    TooLarge(u64),
    /// Not the entry of this stage and key, cut short, or its checksum (or signature) is wrong.
    Corrupt,
}

impl Shared {
    fn object_path(&self, stage: &str, key: CacheKey) -> StorePath {
        let hex = key.0.to_hex();
        let mut path = self.prefix.clone();
        if self.signing.is_some() {
            path = path.join("signed");
        }
        for part in [stage, &hex[..2], &hex[2..]] {
            path = path.clone().join(part);
        }
        path
    }

    /// Whether a request may be made now: probes a store not asked yet (or whose pause is over).
    fn usable(&self, runtime: &tokio::runtime::Runtime) -> bool {
        let mut health = self.health.lock().expect("remote health lock");
        match *health {
            Health::Answering => return true,
            Health::Failed(when) if when.elapsed() < RETRY_AFTER => return false,
            _ => {}
        }
        // The probe: a HEAD of an object that need not exist (not found is an answer).
        let probe = self.prefix.clone().join("cirrus-probe");
        // The client panics on some inputs (an endpoint it cannot make a request of): that is
        // a store that fails, not a build that aborts.
        let answer = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            runtime.block_on(async { tokio::time::timeout(PROBE_TIMEOUT, self.store.head(&probe)).await })
        }));
        let failure = match answer {
            Err(panic) => Some(format!("its client failed: {}", panic_text(&panic))),
            Ok(Err(_)) => Some(format!("no answer within {} ms", PROBE_TIMEOUT.as_millis())),
            Ok(Ok(Ok(_))) | Ok(Ok(Err(object_store::Error::NotFound { .. }))) => None,
            Ok(Ok(Err(error))) => Some(short_error(&error)),
        };
        match failure {
            None => {
                if self.settings.mode == RemoteCacheMode::ReadOnly {
                    self.warn_unless_listing(runtime);
                }
                *health = Health::Answering;
                true
            }
            Some(why) => {
                self.counters.errors.fetch_add(1, Ordering::Relaxed);
                tracing::warn!(
                    "shared cache {} is not answering ({why}); building locally, trying again in {} s",
                    self.settings.url,
                    RETRY_AFTER.as_secs()
                );
                *health = Health::Failed(Instant::now());
                false
            }
        }
    }

    /// A read-only machine never uploads, so a store that answers the probe but is no S3 store
    /// (`AWS_ENDPOINT_URL` naming a web server: every object "not found") would only miss,
    /// silently. Listing the prefix tells: a warning when it fails (the store is still used: a
    /// read-only credential may lack the right to list).
    fn warn_unless_listing(&self, runtime: &tokio::runtime::Runtime) {
        static WARNED: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);
        let listing = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            runtime.block_on(async {
                tokio::time::timeout(PROBE_TIMEOUT, self.store.list_with_delimiter(Some(&self.prefix))).await
            })
        }));
        let why = match listing {
            Ok(Ok(Ok(_))) => return,
            Ok(Ok(Err(error))) => short_error(&error),
            Ok(Err(_)) => format!("no answer within {} ms", PROBE_TIMEOUT.as_millis()),
            Err(panic) => panic_text(&panic),
        };
        if !WARNED.swap(true, Ordering::Relaxed) {
            tracing::warn!(
                "shared cache {} answers, but listing it failed ({why}): if AWS_ENDPOINT_URL is not an S3 endpoint, \
                 every lookup of this read-only machine misses",
                self.settings.url
            );
        }
    }

    /// Marks the store failed after a request went wrong.
    fn failed(&self, doing: &str, error: &str) {
        self.counters.errors.fetch_add(1, Ordering::Relaxed);
        let mut health = self.health.lock().expect("remote health lock");
        if !matches!(*health, Health::Failed(_)) {
            tracing::warn!(
                "shared cache {}: {doing} failed ({error}); building locally, trying again in {} s",
                self.settings.url,
                RETRY_AFTER.as_secs()
            );
        }
        *health = Health::Failed(Instant::now());
    }
}

/// What a caught panic said.
fn panic_text(panic: &Box<dyn std::any::Any + Send>) -> String {
    panic
        .downcast_ref::<String>()
        .cloned()
        .or_else(|| panic.downcast_ref::<&str>().map(|text| text.to_string()))
        .unwrap_or_else(|| "a panic".into())
}

/// The environment variables that name an S3 endpoint (`object_store` reads them all).
const ENDPOINT_VARIABLES: [&str; 3] = ["AWS_ENDPOINT_URL", "AWS_ENDPOINT", "AWS_ENDPOINT_URL_S3"];

/// Whether the S3 endpoint the environment names (if any) is a URL a client can use:
/// `http://` or `https://` with a host. `object_store` accepts any text there and panics on the
/// first request.
pub fn check_endpoint_environment() -> Result<(), String> {
    for variable in ENDPOINT_VARIABLES {
        let Some(value) = std::env::var_os(variable) else { continue };
        let value = value.to_string_lossy();
        // (The URL parser trims spaces that the S3 client then chokes on.)
        if value.trim() != value {
            return Err(format!(
                "{variable}=`{value}` has spaces around it; give the endpoint alone, e.g. http://127.0.0.1:8333"
            ));
        }
        let parsed = url::Url::parse(&value).map_err(|why| why.to_string()).and_then(|url| {
            if !matches!(url.scheme(), "http" | "https") {
                Err(format!("its scheme is `{}`, not http or https", url.scheme()))
            } else if url.host_str().is_none_or(str::is_empty) {
                Err("it names no host".to_string())
            } else {
                Ok(())
            }
        });
        if let Err(why) = parsed {
            return Err(format!(
                "{variable}=`{value}` is not an endpoint URL ({why}); give e.g. http://127.0.0.1:8333 or unset it"
            ));
        }
    }
    Ok(())
}

/// The object limit of a store opened without one: the local cache's largest entry.
const DEFAULT_MAX_OBJECT_BYTES: u64 = 4 << 30;

/// The largest entry a project with `texture_working_set` bytes per texture can make: an image
/// entry holds at most about 8 bytes per texel of the largest texture (whose bake may take 64),
/// and a mesh entry about twice its source file (at most `files::MAX_SOURCE_BYTES`).
pub fn largest_entry_bytes(texture_working_set: u64) -> u64 {
    (texture_working_set / 8).max(2 * crate::files::MAX_SOURCE_BYTES)
}

/// Whether entries of `stage` are shared at all (memos are not).
pub fn shares(stage: &str) -> bool {
    !stage.ends_with("-memo")
}

impl RemoteStore {
    /// Streams the object stored under `stage` and `key` into a temporary file in `folder`,
    /// verifying it as it arrives: it must start with `header` (the entry's stage and key), its
    /// last 32 bytes must be the blake3 of the rest (the entry's checksum), and with a team key
    /// it must end with its signature (a keyed blake3 of the entry, not written to the file). So
    /// an object is never held in memory whole, and one that is no entry costs at most its
    /// bytes on disk until it shows. `None` when there is none, the store is not answering or
    /// entries of `stage` are not shared; `Some(Err)` when the object is no entry (counted).
    pub fn fetch_to_file(
        &self,
        stage: &str,
        key: CacheKey,
        header: &[u8],
        folder: &std::path::Path,
    ) -> Option<Result<tempfile::NamedTempFile, Unverified>> {
        let shared = &self.shared;
        if !shares(stage) || shared.corrupt_keys.lock().expect("corrupt keys lock").contains(&(stage.to_string(), key))
        {
            // A key found corrupt is not fetched again: it is computed and overwritten.
            return None;
        }
        if !shared.usable(&self.runtime) {
            return None;
        }
        let path = shared.object_path(stage, key);
        let limit = self.max_object_bytes;
        let temporary = std::fs::create_dir_all(folder)
            .and_then(|()| tempfile::Builder::new().prefix(crate::files::TEMPORARY_PREFIX).tempfile_in(folder));
        let mut temporary = match temporary {
            Ok(temporary) => temporary,
            Err(error) => {
                tracing::warn!("cannot write a cache entry into {}: {error}", folder.display());
                return None;
            }
        };
        // Each step (the answer, then each chunk) must come within `STALL_TIMEOUT`.
        let fetched = self.runtime.block_on(async {
            use futures_util::StreamExt;
            let result = match tokio::time::timeout(STALL_TIMEOUT, shared.store.get(&path)).await {
                Ok(Ok(result)) => result,
                Ok(Err(error)) => return Ok(Err(error)),
                Err(elapsed) => return Err(elapsed),
            };
            let size = result.meta.size;
            if size > limit {
                return Ok(Ok(Err(Unverified::TooLarge(size))));
            }
            let mut check = StreamCheck::new(header, shared.signing.as_ref(), size);
            let mut stream = result.into_stream();
            while let Some(chunk) = tokio::time::timeout(STALL_TIMEOUT, stream.next()).await? {
                let chunk = match chunk {
                    Ok(chunk) => chunk,
                    Err(error) => return Ok(Err(error)),
                };
                if let Err(unverified) = check.take(&chunk, temporary.as_file_mut()) {
                    return Ok(Ok(Err(unverified)));
                }
            }
            Ok(Ok(check.finish(temporary.as_file_mut()).map(|()| check.received)))
        });
        match fetched {
            Ok(Ok(Ok(received))) => {
                shared.counters.bytes_downloaded.fetch_add(received, Ordering::Relaxed);
                Some(Ok(temporary))
            }
            Ok(Ok(Err(unverified))) => {
                let why = match unverified {
                    Unverified::TooLarge(size) => {
                        format!("is {size} bytes, more than an entry can be ({limit}); not downloaded")
                    }
                    Unverified::Corrupt => "failed verification".to_string(),
                };
                self.unverified(stage, key, &why);
                Some(Err(unverified))
            }
            Ok(Err(object_store::Error::NotFound { .. })) => {
                shared.counters.misses.fetch_add(1, Ordering::Relaxed);
                None
            }
            Ok(Err(error)) => {
                shared.failed("a download", &short_error(&error));
                None
            }
            Err(_) => {
                shared.failed("a download", &format!("nothing came for {} s", STALL_TIMEOUT.as_secs()));
                None
            }
        }
    }

    /// Counts a fetched object that verified (a hit) or did not (corrupt: a miss, and the key
    /// is overwritten by its next upload).
    pub fn verified(&self, stage: &str, key: CacheKey, good: bool) {
        if good {
            self.shared.counters.hits.fetch_add(1, Ordering::Relaxed);
        } else {
            self.unverified(stage, key, "failed verification");
        }
    }

    /// Counts an object that is no entry (`why`, said once): a miss, and the key is overwritten by
    /// its next upload.
    fn unverified(&self, stage: &str, key: CacheKey, why: &str) {
        let shared = &self.shared;
        shared.counters.corrupt.fetch_add(1, Ordering::Relaxed);
        shared.counters.misses.fetch_add(1, Ordering::Relaxed);
        tracing::warn!(
            "shared cache {}: the {stage} entry {} {why}; computing it",
            shared.settings.url,
            &key.0.to_hex()[..16]
        );
        shared.corrupt_keys.lock().expect("corrupt keys lock").insert((stage.to_string(), key));
    }

    /// Whether this machine uploads entries of `stage` (read-write mode, a shared stage).
    pub fn uploads(&self, stage: &str) -> bool {
        self.shared.settings.mode == RemoteCacheMode::ReadWrite && shares(stage)
    }

    /// Uploads an entry's bytes in the background (read-write stores only): a conditional
    /// create, or an overwrite of a key found corrupt. `wait_for_uploads` waits for them.
    pub fn upload(&self, stage: &str, key: CacheKey, bytes: Vec<u8>) {
        if !self.uploads(stage) || !self.shared.usable(&self.runtime) {
            return;
        }
        let overwrite = self.shared.corrupt_keys.lock().expect("corrupt keys lock").remove(&(stage.to_string(), key));
        let mode = if overwrite { PutMode::Overwrite } else { PutMode::Create };
        let mut bytes = bytes;
        if let Some(signing) = &self.shared.signing {
            let signature = blake3::keyed_hash(signing, &bytes);
            bytes.extend_from_slice(signature.as_bytes());
        }
        let (remote, path, length) = (self.shared.clone(), self.shared.object_path(stage, key), bytes.len() as u64);
        let task = self.runtime.spawn(async move {
            let options = PutOptions { mode, ..Default::default() };
            let put = tokio::time::timeout(
                upload_timeout(length),
                remote.store.put_opts(&path, PutPayload::from(bytes), options),
            )
            .await;
            match put {
                Ok(Ok(_)) => {
                    remote.counters.uploads.fetch_add(1, Ordering::Relaxed);
                    remote.counters.bytes_uploaded.fetch_add(length, Ordering::Relaxed);
                }
                Ok(Err(object_store::Error::AlreadyExists { .. } | object_store::Error::Precondition { .. })) => {
                    remote.counters.already_present.fetch_add(1, Ordering::Relaxed);
                }
                Ok(Err(error)) => remote.failed("an upload", &short_error(&error)),
                Err(_) => remote
                    .failed("an upload", &format!("no answer within {:.0} s", upload_timeout(length).as_secs_f64())),
            }
        });
        self.uploads.lock().expect("uploads lock").push(task);
    }

    /// Waits for the uploads still running (each has its own deadline).
    pub fn wait_for_uploads(&self) {
        let uploads = std::mem::take(&mut *self.uploads.lock().expect("uploads lock"));
        self.runtime.block_on(async {
            for upload in uploads {
                let _ = upload.await;
            }
        });
    }

    /// What the store did since the last call.
    pub fn take_counts(&self) -> RemoteCounts {
        let take = |counter: &AtomicU64| counter.swap(0, Ordering::Relaxed);
        let counters = &self.shared.counters;
        RemoteCounts {
            hits: take(&counters.hits),
            misses: take(&counters.misses),
            corrupt: take(&counters.corrupt),
            uploads: take(&counters.uploads),
            already_present: take(&counters.already_present),
            bytes_downloaded: take(&counters.bytes_downloaded),
            bytes_uploaded: take(&counters.bytes_uploaded),
            errors: take(&counters.errors),
        }
    }
}

/// The checks of [`RemoteStore::fetch_to_file`] over an object's bytes as they arrive: the
/// header first, then the checksum (and signature) over all but the last 32 (64) bytes, which
/// are held back until the end; every byte but the signature goes to the file.
struct StreamCheck<'a> {
    header: &'a [u8],
    announced: u64,
    received: u64,
    body: blake3::Hasher,
    signed: Option<blake3::Hasher>,
    /// The last bytes received, not yet hashed (the checksum and the signature, at the end).
    held: Vec<u8>,
}

impl<'a> StreamCheck<'a> {
    fn new(header: &'a [u8], signing: Option<&[u8; 32]>, announced: u64) -> StreamCheck<'a> {
        StreamCheck {
            header,
            announced,
            received: 0,
            body: blake3::Hasher::new(),
            signed: signing.map(blake3::Hasher::new_keyed),
            held: Vec::new(),
        }
    }

    /// How many trailing bytes are held back: the checksum, and the signature when signed.
    fn trailer(&self) -> usize {
        if self.signed.is_some() {
            64
        } else {
            32
        }
    }

    fn take(&mut self, chunk: &[u8], file: &mut std::fs::File) -> Result<(), Unverified> {
        use std::io::Write;
        let start = self.received as usize;
        self.received += chunk.len() as u64;
        if self.received > self.announced {
            return Err(Unverified::Corrupt);
        }
        // The header, as far as it reaches into this chunk.
        if start < self.header.len() {
            let end = self.header.len().min(start + chunk.len());
            if chunk[..end - start] != self.header[start..end] {
                return Err(Unverified::Corrupt);
            }
        }
        self.held.extend_from_slice(chunk);
        let ready = self.held.len().saturating_sub(self.trailer());
        if ready > 0 {
            let bytes = &self.held[..ready];
            self.body.update(bytes);
            if let Some(signed) = &mut self.signed {
                signed.update(bytes);
            }
            file.write_all(bytes).map_err(|_| Unverified::Corrupt)?;
            self.held.drain(..ready);
        }
        Ok(())
    }

    /// Checks the held trailer and writes the entry's checksum to the file.
    fn finish(&mut self, file: &mut std::fs::File) -> Result<(), Unverified> {
        use std::io::Write;
        if self.held.len() != self.trailer() || self.received < self.header.len() as u64 {
            return Err(Unverified::Corrupt);
        }
        let (checksum, signature) = self.held.split_at(32);
        if self.body.finalize().as_bytes() != checksum {
            return Err(Unverified::Corrupt);
        }
        if let Some(signed) = &mut self.signed {
            signed.update(checksum);
            if signed.finalize().as_bytes() != signature {
                return Err(Unverified::Corrupt);
            }
        }
        file.write_all(checksum).and_then(|()| file.flush()).map_err(|_| Unverified::Corrupt)
    }
}

/// An object store error in one line (its sources joined), without the response body.
fn short_error(error: &object_store::Error) -> String {
    let text = error.to_string();
    let line = text.lines().next().unwrap_or_default();
    let mut line: String = line.chars().take(240).collect();
    if line.len() < text.len() {
        line.push('…');
    }
    line
}
