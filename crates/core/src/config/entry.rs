//! What a kind declares of `pipeline.ron` (`KindEntry`: its entry under `assets:`, the sections of
//! `defaults:` it reads, its settings and how they resolve), its settings held without their
//! type (`KindSettings`), what it checks an entry through (`EntryCheck`: positions, paths, globs,
//! the texture budget), and the list of every kind's entries that `kind_list` makes
//! (`EntryKinds`, in `kinds`). Names no kind.

use std::any::Any;
use std::fmt::{self, Debug};
use std::path::PathBuf;
use std::sync::Arc;

use serde::de::DeserializeOwned;

use super::encode::EncodeOverrides;
use super::sections::Check;
use super::{AssetKind, AssetSource};

/// A kind's part of `pipeline.ron`, implemented by its settings type (`kinds/<kind>/settings.rs`).
pub trait KindEntry: Clone + PartialEq + Debug + Send + Sync + 'static {
    /// The kind's name, as `pipeline.ron` writes it (its `AssetKind`'s).
    const NAME: &'static str;
    /// The settings fields its entry may carry besides `name`, its files and `encode` (for the
    /// error of one written on a kind that does not read it).
    const FIELDS: &'static [&'static str];
    /// The sections of `defaults:` it reads.
    const DEFAULTS: &'static [&'static str];
    /// Why a rule cannot make assets of this kind, if it cannot.
    const RULE_REFUSAL: Option<&'static str> = None;

    /// One entry under `assets:` as written (`Material(name: …, material: …)`), its fields denied
    /// where unknown.
    type Entry: DeserializeOwned;
    /// `defaults:` as the kind sees it: the sections it reads, as written; the others are
    /// skipped (their readers check them).
    type Defaults: DeserializeOwned + Default;

    /// The settings `defaults:` make of the kind's own defaults (and an asset a rule makes gets).
    fn defaults(written: &Self::Defaults, check: &mut dyn Check) -> Self;

    /// The entry's name and `encode` section, which the shared part checks and merges.
    fn name_and_encode(entry: &Self::Entry) -> (&str, &EncodeOverrides);

    /// The entry's source and settings over `defaults`, checked; none where a path is unusable.
    fn resolve(entry: &Self::Entry, defaults: &Self, check: &mut EntryCheck<'_, '_>) -> Option<(AssetSource, Self)>;

    /// The other asset whose output an asset of these settings reads, if any.
    fn reads_asset(&self) -> Option<AssetReference<'_>> {
        None
    }
}

/// What a kind checks its entry through: errors at a key or a value searched from the entry,
/// source paths and globs, the texture budget.
pub struct EntryCheck<'a, 'text> {
    pub(super) check: &'a mut super::Validation<'text>,
    pub(super) anchor: usize,
    pub(super) name: &'a str,
    pub(super) kind: AssetKind,
}

impl EntryCheck<'_, '_> {
    /// The asset's name.
    pub fn name(&self) -> &str {
        self.name
    }

    /// The asset's kind.
    pub fn kind(&self) -> AssetKind {
        self.kind
    }

    /// Where the entry starts, for the merges of its sections.
    pub fn anchor(&self) -> usize {
        self.anchor
    }

    pub fn error_at_value(&mut self, value: &str, message: &str) {
        self.check.error_at_value(value, self.anchor, message);
    }

    /// A file path relative to the source folder that stays inside it.
    pub fn source_path(&mut self, value: &str) -> Option<PathBuf> {
        self.check.source_path(value, self.anchor)
    }

    /// A glob over the source folder, checked (an error names it when bad).
    pub fn glob(&mut self, glob: &str) {
        if let Err(error) = super::source_glob(glob) {
            self.check.error_at_value(glob, self.anchor, &format!("bad glob: {error}"));
        }
    }

    /// Each surface of `side`² goes through the texture tail: an error when one needs more than
    /// the texture budget (`what`: "an atlas", `setting`: the key that sets `side`).
    pub fn surface_budget(&mut self, what: &str, side: u32, setting: &str) {
        let budget = self.check.limits.texture.working_set;
        let needed = crate::texture::TextureLimits::working_set_of(side, side);
        if needed > budget {
            let name = self.name;
            let message = format!(
                "asset `{name}`: a {side}² {what} needs about {} MiB per surface, more than the texture memory \
                 budget of {} MiB (lower {setting} or raise `limits: (texture_memory_mib: …)`)",
                needed >> 20,
                budget >> 20
            );
            self.check.error_at_value(name, self.anchor, &message);
        }
    }
}

impl Check for EntryCheck<'_, '_> {
    fn error_at_key(&mut self, key: &str, anchor: usize, message: &str) {
        self.check.error_at_key(key, anchor, message);
    }
}

/// Every kind's entry, as the list of kinds makes it (`kinds::Entries`).
pub trait EntryKinds {
    /// An entry under `assets:` of any kind (`#[serde(rename = "Asset")]`: errors call it so).
    type Entry: DeserializeOwned;
    /// A kind's name as a rule's `kind:` is written (`#[serde(rename = "AssetKind")]`), and the
    /// kind it names.
    type KindName: DeserializeOwned + Copy + Into<AssetKind>;
    /// Each kind with the fields its entries may carry and the sections of `defaults:` it reads.
    const KINDS: &'static [KindFields];

    /// Each kind's defaults (`Validation::kind_defaults`).
    fn defaults(validation: &mut super::Validation<'_>) -> Vec<KindSettings>;

    /// One entry resolved over its kind's `defaults` (`Validation::resolve_entry`).
    fn resolve(
        validation: &mut super::Validation<'_>,
        entry: &Self::Entry,
        defaults: &[KindSettings],
        names: &mut super::AssetFolders,
    ) -> Option<super::AssetConfig>;
}

/// A kind's `KindEntry` constants, listed.
#[derive(Clone, Copy, Debug)]
pub struct KindFields {
    pub kind: AssetKind,
    pub fields: &'static [&'static str],
    pub defaults: &'static [&'static str],
    pub rule_refusal: Option<&'static str>,
}

impl KindFields {
    /// Kind `kind`'s, whose settings are `T`.
    pub const fn of<T: KindEntry>(kind: AssetKind) -> KindFields {
        KindFields { kind, fields: T::FIELDS, defaults: T::DEFAULTS, rule_refusal: T::RULE_REFUSAL }
    }
}

/// Another asset an asset's settings name, whose output it reads: by which field, and the kind
/// that asset must be.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct AssetReference<'a> {
    pub field: &'static str,
    pub asset: &'a str,
    /// The name of the kind it must be.
    pub kind: &'static str,
}

/// One asset's kind's own settings, of whichever kind (cheap to clone: shared).
#[derive(Clone)]
pub struct KindSettings(Arc<dyn ErasedSettings>);

impl KindSettings {
    pub fn new<T: KindEntry>(settings: T) -> KindSettings {
        KindSettings(Arc::new(settings))
    }

    /// The name of the kind whose settings these are.
    pub fn kind_name(&self) -> &'static str {
        self.0.kind_name()
    }

    pub fn reference(&self) -> Option<AssetReference<'_>> {
        self.0.reads_asset()
    }

    /// The settings as kind `T`'s, if they are.
    pub fn downcast<T: KindEntry>(&self) -> Option<&T> {
        self.0.as_any().downcast_ref()
    }
}

impl PartialEq for KindSettings {
    fn eq(&self, other: &KindSettings) -> bool {
        Arc::ptr_eq(&self.0, &other.0) || self.0.equals(other.0.as_any())
    }
}

impl fmt::Debug for KindSettings {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        // As the enum of kinds it stands for printed: `Material(Settings { … })` (the record's
        // configuration hash is made of this text).
        f.debug_tuple(self.0.kind_name()).field(&self.0.as_debug()).finish()
    }
}

/// A kind's settings seen without their type.
trait ErasedSettings: Send + Sync {
    fn as_any(&self) -> &dyn Any;
    fn as_debug(&self) -> &dyn fmt::Debug;
    fn equals(&self, other: &dyn Any) -> bool;
    fn kind_name(&self) -> &'static str;
    fn reads_asset(&self) -> Option<AssetReference<'_>>;
}

impl<T: KindEntry> ErasedSettings for T {
    fn as_any(&self) -> &dyn Any {
        self
    }

    fn as_debug(&self) -> &dyn fmt::Debug {
        self
    }

    fn equals(&self, other: &dyn Any) -> bool {
        other.downcast_ref::<T>() == Some(self)
    }

    fn kind_name(&self) -> &'static str {
        T::NAME
    }

    fn reads_asset(&self) -> Option<AssetReference<'_>> {
        KindEntry::reads_asset(self)
    }
}
