//! The per-asset settings a validated `pipeline.ron` resolves to: the shared `encode` section and
//! the asset's kind's own settings, held without naming the kind (`KindSettings`), read back with
//! `Settings::own`.

use super::encode::EncodeSettings;
use super::entry::{KindEntry, KindSettings};

/// Every setting of one asset, defaults and overrides merged: the shared `encode` section and
/// its kind's own.
#[derive(Clone, Debug, PartialEq)]
pub struct Settings {
    pub encode: EncodeSettings,
    pub kind: KindSettings,
}

impl Settings {
    /// The asset's kind's own settings (`settings.own::<billboard_cloud::settings::Settings>()`).
    pub fn own<T: KindEntry>(&self) -> &T {
        self.kind.downcast().expect("an asset's settings are of its kind")
    }

    /// The other asset whose output this one reads (a Material's `ao_source`), if any.
    pub fn reads_asset(&self) -> Option<&str> {
        self.kind.reference().map(|reference| reference.asset)
    }
}
