//! The invariants of ARCHITECTURE.md that a grep can check and no Cargo.toml states: every file
//! says what it is for; salsa, notify, sockets and file-system IO stay in the application modules
//! that own them (the libraries under crates/ have no salsa, wgpu or notify unless their
//! Cargo.toml names it); the application's modules form a stack.

use std::path::{Path, PathBuf};

fn rust_files(folder: &str) -> Vec<PathBuf> {
    let mut files = crate::support::files_under(&Path::new(env!("CARGO_MANIFEST_DIR")).join(folder));
    files.retain(|path| path.extension().is_some_and(|extension| extension == "rs"));
    files
}

/// A file's name as a module of the application, whose three parts keep the names they had
/// as one crate: `src/` (the application) and `crates/core/src/` (the machinery) from their roots
/// (`watch.rs`, `db.rs`, `kinds/mod.rs`; the machinery's root is `core.rs`), a kind's
/// `kinds/<kind>/src/` as `kinds/<kind>/` (its `lib.rs` as `mod.rs`); a library's file from the
/// repository's root (`crates/mesh/src/lib.rs`).
fn module(path: &Path) -> String {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let relative = path.strip_prefix(root).unwrap().to_string_lossy().replace('\\', "/");
    if relative == "crates/core/src/lib.rs" {
        return "core.rs".to_string();
    }
    if let Some(file) = relative.strip_prefix("src/").or_else(|| relative.strip_prefix("crates/core/src/")) {
        return file.to_string();
    }
    if let Some((kind, file)) = relative.strip_prefix("kinds/").and_then(|rest| rest.split_once("/src/")) {
        return format!("kinds/{kind}/{}", if file == "lib.rs" { "mod.rs" } else { file });
    }
    relative
}

/// The Rust files of the application (`src/`, `crates/core/src/`, `kinds/*/src/`).
fn application_files() -> Vec<PathBuf> {
    let mut files = rust_files("src");
    files.extend(rust_files("crates/core/src"));
    files.extend(rust_files("kinds").into_iter().filter(|path| module(path).starts_with("kinds/")));
    files
}

/// The Rust files of the application and of the libraries (`crates/*/src/`).
fn source_files() -> Vec<PathBuf> {
    let mut files = application_files();
    files.extend(rust_files("crates").into_iter().filter(|path| module(path).contains("/src/")));
    files
}

/// The file of an application module (`db.rs`, `project/mod.rs`).
fn file_of(name: &str) -> PathBuf {
    application_files().into_iter().find(|path| module(path) == name).unwrap_or_else(|| panic!("no module {name}"))
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

/// The modules under `src/` and the libraries' files whose code contains any of `needles`.
fn modules_using(needles: &[&str]) -> Vec<String> {
    source_files()
        .iter()
        .filter(|path| needles.iter().any(|needle| code(path).contains(needle)))
        .map(|path| module(path))
        .collect()
}

#[test]
fn every_file_starts_by_saying_what_it_is_for() {
    let files: Vec<PathBuf> = ["src", "crates", "kinds", "tests", "benches", "examples"]
        .iter()
        .flat_map(|folder| rust_files(folder))
        .collect();
    assert!(files.len() > 40);
    let silent: Vec<&PathBuf> =
        files.iter().filter(|path| !std::fs::read_to_string(path).unwrap().starts_with("//!")).collect();
    assert!(silent.is_empty(), "files without a `//!` line first: {silent:?}");
}

#[test]
fn salsa_notify_sockets_and_file_io_stay_in_their_modules() {
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
        "files.rs",
        // The process's own memory and the machine's (`/proc`).
        "memory.rs",
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
        "cli/cache.rs",
    ];
    for module in machinery {
        let code = code(&file_of(module));
        let lower = code.to_lowercase();
        for kind in ["material", "billboard", "planes", "atlas", "ambient", "occlusion"] {
            assert!(!lower.contains(kind), "{module} names `{kind}`");
        }
        // `height` is also a texture's; the kind is named by its type or its module.
        for kind in ["Height", "kinds::height", "AmbientOcclusion", "BillboardCloud"] {
            assert!(!code.contains(kind), "{module} names `{kind}`");
        }
    }
}

/// The modules (files under `src/`, `a/mod.rs` as `a`) each module's code names: every
/// `crate::a::b` path (and each path inside `crate::{…}` or `crate::a::{…}`) resolved to the
/// longest module it reaches, every `super::` path likewise, and each child module a parent
/// names (`mod x;` and `x::`).
fn module_imports() -> std::collections::BTreeMap<String, std::collections::BTreeSet<String>> {
    use std::collections::{BTreeMap, BTreeSet};
    let name_of = |path: &Path| -> String {
        let name = module(path);
        let name = name.strip_suffix(".rs").unwrap_or(&name);
        name.strip_suffix("/mod").unwrap_or(name).to_string()
    };
    let files = application_files();
    let modules: BTreeSet<String> = files.iter().map(|path| name_of(path)).collect();
    let resolve = |segments: &[&str]| -> Option<String> {
        (1..=segments.len()).rev().map(|n| segments[..n].join("/")).find(|candidate| modules.contains(candidate))
    };
    let is_segment = |text: &str| {
        !text.is_empty() && text.bytes().all(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || b == b'_')
    };
    // The paths a `use` tree starting at `text` names, each as its leading lowercase segments.
    fn paths(text: &str, is_segment: &dyn Fn(&str) -> bool) -> Vec<Vec<String>> {
        let mut prefix = Vec::new();
        let mut rest = text;
        loop {
            let end = rest.find(|c: char| !(c.is_ascii_alphanumeric() || c == '_')).unwrap_or(rest.len());
            let (word, after) = rest.split_at(end);
            if let Some(after) = after.strip_prefix("::") {
                if is_segment(word) {
                    prefix.push(word.to_string());
                    rest = after;
                    continue;
                }
            }
            // A macro's path (`crate::kinds::$folder::…`) names no module the scan can tell.
            if word.is_empty() && rest.starts_with('$') {
                return Vec::new();
            }
            if word.is_empty() && rest.starts_with('{') {
                let mut depth = 0;
                let mut items = Vec::new();
                let mut start = 1;
                for (index, c) in rest.char_indices() {
                    match c {
                        '{' => depth += 1,
                        '}' => {
                            depth -= 1;
                            if depth == 0 {
                                items.push(&rest[start..index]);
                                break;
                            }
                        }
                        ',' if depth == 1 => {
                            items.push(&rest[start..index]);
                            start = index + 1;
                        }
                        _ => {}
                    }
                }
                return items
                    .iter()
                    .flat_map(|item| paths(item.trim(), is_segment))
                    .map(|tail| prefix.iter().cloned().chain(tail).collect())
                    .collect();
            }
            if is_segment(word) {
                prefix.push(word.to_string());
            }
            return vec![prefix];
        }
    }
    let mut imports: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for path in &files {
        let module = name_of(path);
        let code = code(path);
        let is_folder_module =
            path.file_name().is_some_and(|name| name == "mod.rs" || name == "lib.rs" || name == "main.rs");
        let parent: Vec<&str> = if is_folder_module {
            module.split('/').collect()
        } else {
            module.split('/').rev().skip(1).collect::<Vec<_>>().into_iter().rev().collect()
        };
        let mut named = BTreeSet::new();
        // A kind's `crate::` is its own crate (`kinds/<kind>`), whose root names the machinery's
        // modules (`crate::db`) as they are.
        let own_crate: Vec<&str> =
            if module.starts_with("kinds/") { module.split('/').take(2).collect() } else { vec![] };
        for (at, _) in code.match_indices("crate::") {
            for segments in paths(&code[at + "crate::".len()..], &is_segment) {
                let segments: Vec<&str> = segments.iter().map(String::as_str).collect();
                let own: Vec<&str> = own_crate.iter().copied().chain(segments.iter().copied()).collect();
                let own_module = !own_crate.is_empty()
                    && (segments.is_empty() || modules.contains(&own[..own_crate.len() + 1].join("/")));
                named.extend(if own_module { resolve(&own) } else { resolve(&segments) });
            }
        }
        // `super::` is the parent of a folder's own module (`a/b/mod.rs`: `a`), and the folder
        // of any other file (`a/b/c.rs`: `a/b`).
        let up = if is_folder_module { &parent[..parent.len().saturating_sub(1)] } else { &parent[..] };
        for (at, _) in code.match_indices("super::") {
            for segments in paths(&code[at + "super::".len()..], &is_segment) {
                let full: Vec<&str> = up.iter().copied().chain(segments.iter().map(String::as_str)).collect();
                named.extend(resolve(&full).or_else(|| (!up.is_empty()).then(|| up.join("/"))));
            }
        }
        for line in code.lines() {
            let line = line.trim_start().trim_start_matches("pub ").trim_start_matches("pub(crate) ");
            let Some(child) = line.strip_prefix("mod ").and_then(|rest| rest.strip_suffix(';')) else { continue };
            let child_module = if module == "lib" || module == "core" {
                child.to_string()
            } else {
                format!("{}/{child}", parent.join("/"))
            };
            // A path that starts with the child (`x::…`, `self::x::…`), not one that passes
            // through it (`crate::a::x::…`, resolved above).
            let starts_a_path = |(at, _): (usize, &str)| {
                let before = code[..at].strip_suffix("self::").unwrap_or(&code[..at]);
                !before.ends_with(|c: char| c == ':' || c == '_' || c.is_ascii_alphanumeric())
            };
            if modules.contains(&child_module) && code.match_indices(&format!("{child}::")).any(starts_a_path) {
                named.insert(child_module);
            }
        }
        named.remove(&module);
        named.remove("lib");
        named.remove("core");
        imports.insert(module, named);
    }
    imports
}

/// The strongly connected components of the import graph with more than one module (Tarjan).
fn import_cycles(imports: &std::collections::BTreeMap<String, std::collections::BTreeSet<String>>) -> Vec<Vec<String>> {
    use std::collections::BTreeMap;
    struct Search<'a> {
        imports: &'a BTreeMap<String, std::collections::BTreeSet<String>>,
        index: BTreeMap<&'a str, usize>,
        low: BTreeMap<&'a str, usize>,
        stack: Vec<&'a str>,
        cycles: Vec<Vec<String>>,
    }
    impl<'a> Search<'a> {
        fn visit(&mut self, module: &'a str) {
            let index = self.index.len();
            self.index.insert(module, index);
            self.low.insert(module, index);
            self.stack.push(module);
            for next in self.imports.get(module).into_iter().flatten() {
                if !self.index.contains_key(next.as_str()) {
                    self.visit(next);
                    let low = self.low[module].min(self.low[next.as_str()]);
                    self.low.insert(module, low);
                } else if self.stack.contains(&next.as_str()) {
                    let low = self.low[module].min(self.index[next.as_str()]);
                    self.low.insert(module, low);
                }
            }
            if self.low[module] == self.index[module] {
                let at = self.stack.iter().rposition(|&m| m == module).unwrap();
                let component: Vec<String> = self.stack.drain(at..).map(str::to_string).collect();
                if component.len() > 1 {
                    self.cycles.push(component);
                }
            }
        }
    }
    let mut search =
        Search { imports, index: BTreeMap::new(), low: BTreeMap::new(), stack: Vec::new(), cycles: Vec::new() };
    for module in imports.keys() {
        if !search.index.contains_key(module.as_str()) {
            search.visit(module);
        }
    }
    search.cycles
}

#[test]
fn the_modules_form_a_straight_stack() {
    let imports = module_imports();
    assert!(imports.len() > 60, "the import graph sees the modules: {}", imports.len());
    // No loop anywhere in the import graph: each module names only those below it (a folder's
    // parts never name their folder's module back, through `super::` or otherwise).
    let cycles: Vec<Vec<String>> = import_cycles(&imports);
    assert!(cycles.is_empty(), "import loops: {cycles:?}");
    // The search finds a loop where there is one (a folder's part naming its module back).
    let mut looped = imports.clone();
    looped.get_mut("kinds/billboard_cloud/planes").expect("a leaf").insert("kinds/billboard_cloud".to_string());
    let found = import_cycles(&looped);
    assert!(found.iter().any(|cycle| cycle.contains(&"kinds/billboard_cloud/planes".to_string())), "{found:?}");
    // Each kind's settings file (its `pipeline.ron` entry, sections and settings) is a leaf under
    // its folder: it imports only the libraries, `config`'s shared parts and other settings files.
    let settings_leaf = |module: &str| module.starts_with("kinds/") && module.ends_with("/settings");
    let settings_files: Vec<&String> = imports.keys().filter(|module| settings_leaf(module)).collect();
    assert!(settings_files.len() >= 5, "every kind has its settings file: {settings_files:?}");
    for module in settings_files {
        let allowed = |n: &&String| settings_leaf(n) || n.starts_with("config") || n.as_str() == "files";
        let bad: Vec<&String> = imports[module].iter().filter(|n| !allowed(n)).collect();
        assert!(bad.is_empty(), "the settings leaf {module} imports {bad:?}");
    }
    // The database and the scheduler name no kind and no driver; nothing below the shell runs the
    // driver; the configuration names no kind at all (the kinds' entries reach it as
    // `EntryKinds`, which `pipeline` passes in).
    let config_modules: Vec<&String> = imports.keys().filter(|module| module.starts_with("config")).collect();
    assert!(config_modules.len() >= 6, "config's files are seen: {config_modules:?}");
    let below_the_kinds = ["db", "schedule", "cache", "sources", "artifacts", "record"];
    for module in below_the_kinds.iter().copied().chain(config_modules.iter().map(|module| module.as_str())) {
        let bad: Vec<&String> = imports[module]
            .iter()
            .filter(|n| {
                // Below the kinds a settings leaf may be named (its types); config names none.
                let named_kind = n.starts_with("kinds") && (module.starts_with("config") || !settings_leaf(n));
                named_kind || n.starts_with("project") || n.as_str() == "pipeline"
            })
            .collect();
        assert!(bad.is_empty(), "{module} imports {bad:?}");
    }
    for (module, named) in &imports {
        if module.starts_with("kinds") {
            assert!(!named.iter().any(|n| n.starts_with("project")), "{module} runs the driver");
        }
    }
}

#[test]
fn no_line_of_src_is_wider_than_120_columns() {
    let mut wide = Vec::new();
    for path in source_files() {
        for (index, line) in std::fs::read_to_string(&path).unwrap().lines().enumerate() {
            if line.chars().count() > 120 {
                wide.push(format!("{}:{}", module(&path), index + 1));
            }
        }
    }
    assert!(wide.is_empty(), "lines over 120 columns: {wide:?}");
}

/// Each function of `code` (by its `fn` line) with its length in lines, to its closing brace.
fn function_lengths(code: &str) -> Vec<(usize, usize)> {
    let lines: Vec<&str> = code.lines().collect();
    let mut found = Vec::new();
    for (start, line) in lines.iter().enumerate() {
        let trimmed = line.trim_start();
        let declaration = ["fn ", "pub fn ", "pub(crate) fn ", "pub(super) fn ", "async fn ", "pub async fn "];
        if !declaration.iter().any(|prefix| trimmed.starts_with(prefix)) {
            continue;
        }
        let mut depth = 0i32;
        let mut opened = false;
        for (end, line) in lines.iter().enumerate().skip(start) {
            // Braces inside strings and character literals do not count.
            let mut in_string = false;
            let mut previous = ' ';
            for c in line.split("//").next().unwrap_or("").chars() {
                match c {
                    '"' if previous != '\\' && previous != '\'' => in_string = !in_string,
                    '{' if !in_string && previous != '\'' => {
                        depth += 1;
                        opened = true;
                    }
                    '}' if !in_string && previous != '\'' => depth -= 1,
                    _ => {}
                }
                previous = c;
            }
            if opened && depth == 0 {
                found.push((start, end - start + 1));
                break;
            }
            if !opened && line.trim_end().ends_with(';') {
                break;
            }
        }
    }
    found
}

#[test]
fn no_function_is_over_120_lines_without_a_reason_written_above_it() {
    let mut unexplained = Vec::new();
    let mut explained = 0;
    for path in source_files() {
        let text = std::fs::read_to_string(&path).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        for (start, length) in function_lengths(&text) {
            if length <= 120 {
                continue;
            }
            // A `// Long:` comment among the comments and attributes right above the `fn`.
            let above = lines[..start].iter().rev().take_while(|line| {
                let line = line.trim_start();
                line.starts_with("//") || line.starts_with("#[")
            });
            if above.clone().any(|line| line.trim_start().starts_with("// Long:")) {
                explained += 1;
            } else {
                unexplained.push(format!("{}:{} ({length} lines)", module(&path), start + 1));
            }
        }
    }
    // The check sees long functions (some are explained).
    assert!(explained > 0, "no long function found: the scan is broken");
    assert!(unexplained.is_empty(), "functions over 120 lines without a `// Long:` reason: {unexplained:?}");
}
