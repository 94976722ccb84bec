//! The persistent cache's keys: an explicit encoding, pinned here, and the same keys for the
//! same project baked from two folders (what a shared cache needs).

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use cirrus::cache::CacheKeyBuilder;
use cirrus::config::{BlockFormat, Container, EncodeQuality, Settings};
use expect_test::expect;

use crate::support::build;

/// The entry files under `<output>/.cirrus/cache`, relative to it: `stage/xx/rest-of-the-key`.
fn cache_entries(output: &Path) -> BTreeSet<PathBuf> {
    let root = output.join(".cirrus/cache");
    let mut entries = BTreeSet::new();
    let mut folders = vec![root.clone()];
    while let Some(folder) = folders.pop() {
        for entry in std::fs::read_dir(&folder).unwrap().flatten() {
            if entry.file_type().unwrap().is_dir() {
                folders.push(entry.path());
            } else {
                entries.insert(entry.path().strip_prefix(&root).unwrap().to_path_buf());
            }
        }
    }
    entries
}

#[test]
fn keys_have_a_pinned_encoding() {
    let settings = Settings::default();
    let key = CacheKeyBuilder::new("example", 3)
        .part(&settings.billboard.epsilon)
        .part(&settings.billboard.max_planes)
        .part(&settings.atlas.power_of_two)
        .part(&cirrus::texture::SurfaceKind::Normal)
        .part(&(BlockFormat::Bc5, EncodeQuality::Slow))
        .part(&(Container::Dds, Some(19)))
        .part(Path::new("assets/textures/bark.png"))
        .part(&blake3::hash(b"texture bytes"))
        .finish();
    // A change here changes every key: every cache (local and shared) misses once. Make it on
    // purpose, with the module docs' table.
    expect!["a4916876e99f00ea9b5f2eacbe793e7d1377e774b26e076b6c993ad85f319f0e"].assert_eq(&key.0.to_hex());
}

#[test]
fn the_same_project_in_two_folders_has_the_same_keys() {
    let first = crate::material::bake::material_project("");
    let second = crate::material::bake::material_project("");
    assert_ne!(first.root(), second.root());
    assert!(build(&mut first.open()).all_ok());
    assert!(build(&mut second.open()).all_ok());
    let entries = cache_entries(&first.path("baked"));
    assert!(
        entries.iter().any(|entry| entry.starts_with("surface")) && entries.iter().any(|entry| entry.starts_with("parse")),
        "{entries:?}"
    );
    assert_eq!(entries, cache_entries(&second.path("baked")));
}
