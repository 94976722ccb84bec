//! The `Atlas` kind's part of `pipeline.ron`: its entry (`Atlas(name: …, textures: […])`), its
//! `pack` section as written (overrides), as it resolves (settings), and its checks. A leaf: it
//! imports only `config`'s shared parts.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use crate::config::sections::{page_size_overrides, Check};
use crate::config::{AssetSource, EncodeOverrides, EntryCheck, KindEntry};

/// How an `Atlas` asset packs its textures onto pages.
#[derive(Clone, Debug, PartialEq, Eq, Hash, Serialize)]
pub struct PackSettings {
    pub max_size: u32,
    pub padding: u32,
    pub rotate: bool,
    pub trim: bool,
    pub power_of_two: bool,
    pub pages: u32,
}

#[derive(Deserialize, Default, Clone)]
#[serde(deny_unknown_fields)]
pub struct PackOverrides {
    pub max_size: Option<u32>,
    pub padding: Option<u32>,
    pub rotate: Option<bool>,
    pub trim: Option<bool>,
    pub power_of_two: Option<bool>,
    pub pages: Option<u32>,
}

fn merge_pack(check: &mut dyn Check, settings: &mut PackSettings, pack: &PackOverrides, anchor: usize) {
    page_size_overrides(check, pack.max_size, pack.padding, anchor, &mut settings.max_size, &mut settings.padding);
    if let Some(pages) = pack.pages {
        if !(1..=64).contains(&pages) {
            check.error_at_key("pages", anchor, "pages must be between 1 and 64");
        }
        settings.pages = pages;
    }
    settings.rotate = pack.rotate.unwrap_or(settings.rotate);
    settings.trim = pack.trim.unwrap_or(settings.trim);
    settings.power_of_two = pack.power_of_two.unwrap_or(settings.power_of_two);
}

impl Default for PackSettings {
    fn default() -> PackSettings {
        PackSettings { max_size: 4096, padding: 4, rotate: true, trim: true, power_of_two: false, pages: 4 }
    }
}

/// An `Atlas` asset's own settings.
#[derive(Clone, Debug, PartialEq)]
pub struct Settings {
    pub pack: PackSettings,
}

/// An `Atlas` entry as `pipeline.ron` writes it: named by globs, not by a file.
#[derive(Deserialize)]
#[serde(rename = "Atlas", deny_unknown_fields)]
pub struct Entry {
    name: String,
    textures: Vec<String>,
    #[serde(default)]
    meshes: Vec<String>,
    #[serde(default)]
    pack: PackOverrides,
    #[serde(default)]
    encode: EncodeOverrides,
}

/// The sections of `defaults:` an atlas reads.
#[derive(Deserialize, Default)]
#[serde(rename = "defaults")]
pub struct Defaults {
    #[serde(default)]
    pack: PackOverrides,
}

impl KindEntry for Settings {
    const NAME: &'static str = "Atlas";
    const FIELDS: &'static [&'static str] = &["pack"];
    const DEFAULTS: &'static [&'static str] = &["pack"];
    const RULE_REFUSAL: Option<&'static str> = Some("an Atlas is listed under `assets` with its globs");
    type Entry = Entry;
    type Defaults = Defaults;

    fn defaults(written: &Defaults, check: &mut dyn Check) -> Settings {
        let mut settings = Settings { pack: PackSettings::default() };
        merge_pack(check, &mut settings.pack, &written.pack, 0);
        settings
    }

    fn name_and_encode(entry: &Entry) -> (&str, &EncodeOverrides) {
        (&entry.name, &entry.encode)
    }

    fn resolve(entry: &Entry, defaults: &Settings, check: &mut EntryCheck<'_, '_>) -> Option<(AssetSource, Settings)> {
        let mut settings = defaults.clone();
        let anchor = check.anchor();
        merge_pack(check, &mut settings.pack, &entry.pack, anchor);
        if entry.textures.is_empty() {
            let message = format!("asset `{}`: an atlas needs at least one texture glob", check.name());
            let name = check.name().to_string();
            check.error_at_value(&name, &message);
        }
        for glob in entry.textures.iter().chain(&entry.meshes) {
            check.glob(glob);
        }
        let glob_lists = vec![entry.textures.clone(), entry.meshes.clone()];
        Some((AssetSource { kind: check.kind(), main_file: PathBuf::new(), glob_lists }, settings))
    }
}
