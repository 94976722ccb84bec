//! The `Atlas` kind's settings: its `pack` section as `pipeline.ron` writes it (overrides), as it
//! resolves (settings), and its checks. A leaf: it imports only `config/sections`.

use serde::{Deserialize, Serialize};

use crate::config::sections::{page_size_overrides, Check};

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
pub(crate) struct PackOverrides {
    pub max_size: Option<u32>,
    pub padding: Option<u32>,
    pub rotate: Option<bool>,
    pub trim: Option<bool>,
    pub power_of_two: Option<bool>,
    pub pages: Option<u32>,
}

pub(crate) fn merge_pack(check: &mut dyn Check, settings: &mut PackSettings, pack: &PackOverrides, anchor: usize) {
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
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Settings {
    pub pack: PackSettings,
}
