//! The invariants of ARCHITECTURE.md that a grep can check: every file says what it is for, and
//! salsa, wgpu, notify, sockets and file-system IO stay in the modules that own them.

use std::path::{Path, PathBuf};

fn rust_files(folder: &str) -> Vec<PathBuf> {
    let mut files = Vec::new();
    let mut folders = vec![Path::new(env!("CARGO_MANIFEST_DIR")).join(folder)];
    while let Some(folder) = folders.pop() {
        for entry in std::fs::read_dir(&folder).unwrap().flatten() {
            let path = entry.path();
            if path.is_dir() {
                folders.push(path);
            } else if path.extension().is_some_and(|extension| extension == "rs") {
                files.push(path);
            }
        }
    }
    files.sort();
    files
}

/// The path of a file under `src/` (`watch.rs`, `gpu/mod.rs`).
fn module(path: &Path) -> String {
    path.strip_prefix(Path::new(env!("CARGO_MANIFEST_DIR")).join("src")).unwrap().to_string_lossy().into_owned()
}

/// The code of a file without its comments (doc comments name salsa and wgpu freely).
fn code(path: &Path) -> String {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .filter(|line| !line.trim_start().starts_with("//"))
        .collect::<Vec<_>>()
        .join("\n")
}

/// The modules under `src/` whose code contains any of `needles`.
fn modules_using(needles: &[&str]) -> Vec<String> {
    rust_files("src")
        .iter()
        .filter(|path| needles.iter().any(|needle| code(path).contains(needle)))
        .map(|path| module(path))
        .collect()
}

#[test]
fn every_file_starts_by_saying_what_it_is_for() {
    let files: Vec<PathBuf> =
        ["src", "tests", "benches", "examples"].iter().flat_map(|folder| rust_files(folder)).collect();
    assert!(files.len() > 40);
    let silent: Vec<&PathBuf> =
        files.iter().filter(|path| !std::fs::read_to_string(path).unwrap().starts_with("//!")).collect();
    assert!(silent.is_empty(), "files without a `//!` line first: {silent:?}");
}

#[test]
fn salsa_wgpu_notify_sockets_and_file_io_stay_in_their_modules() {
    let salsa = modules_using(&["salsa::", "#[salsa"]);
    let glue = |module: &String| {
        ["db.rs", "schedule.rs"].contains(&module.as_str())
            || module.starts_with("project/")
            || module.ends_with("queries.rs")
    };
    assert!(
        salsa.iter().all(glue),
        "salsa outside the database, the driver, the scheduler and the kinds' queries.rs: {salsa:?}"
    );
    assert!(
        salsa.iter().any(|module| module == "kinds/material/queries.rs"),
        "the check sees the kinds' queries: {salsa:?}"
    );
    let wgpu = modules_using(&["wgpu::"]);
    assert!(
        !wgpu.is_empty() && wgpu.iter().all(|module| module.starts_with("gpu/")),
        "only gpu/ holds the wgpu device: {wgpu:?}"
    );
    assert_eq!(modules_using(&["notify::", "notify_debouncer"]), ["watch.rs"], "only watch touches notify");
    assert_eq!(
        modules_using(&["std::net::Tcp", "TcpListener", "TcpStream"]),
        ["server.rs"],
        "only server touches sockets"
    );
    let io = modules_using(&["std::fs", " File::", "OpenOptions", "canonicalize", "read_dir"]);
    let edges = [
        "artifacts.rs",
        "cache/mod.rs",
        "cache/remote.rs",
        "cache/upkeep.rs",
        "config.rs",
        "record.rs",
        "sources.rs",
        "watch.rs",
    ];
    assert!(io.iter().all(|module| edges.contains(&module.as_str())), "file-system IO outside the edges: {io:?}");
    assert_eq!(
        modules_using(&["object_store::", "tokio::"]),
        ["cache/remote.rs"],
        "only the shared cache's remote half talks to a store"
    );
}

#[test]
fn the_driver_and_the_machinery_name_no_kind() {
    let machinery = [
        "project/mod.rs",
        "project/graph.rs",
        "project/source_files.rs",
        "project/summaries.rs",
        "project/unchanged.rs",
        "record.rs",
        "schedule.rs",
        "db.rs",
        "cache/mod.rs",
        "cache/remote.rs",
        "cache/upkeep.rs",
        "summary.rs",
        "graph.rs",
        "artifacts.rs",
        "sources.rs",
        "cli_cache.rs",
    ];
    for module in machinery {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("src").join(module);
        let code = code(&path).to_lowercase();
        for kind in ["material", "billboard", "planes", "atlas"] {
            assert!(!code.contains(kind), "{module} names `{kind}`");
        }
    }
}
