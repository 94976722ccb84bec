//! Every kind's `pipeline.ron` entry, made from the one list of kinds (`kind_list.rs`): the enum an
//! entry under `assets:` reads as (`AssetEntry`, one variant per kind holding its `Entry`) and the
//! `config::EntryKinds` that the pipeline is read with (`Entries`), a rule's `kind:` names (`KindName`)
//! and every kind (`ALL`).

use crate::config::{
    AssetConfig, AssetFolders, AssetKind, EntryKinds, KindEntry, KindFields, KindSettings, Validation,
};

/// `AssetEntry` and `Entries` of the one list of kinds.
macro_rules! entries {
    ($($name:ident => $folder:ident),* $(,)?) => {
        /// An entry under `assets:`, of any kind (`Material(name: …, …)`).
        #[derive(serde::Deserialize)]
        #[serde(rename = "Asset")]
        pub enum AssetEntry {
            $($name(<crate::kinds::$folder::settings::Settings as KindEntry>::Entry)),*
        }

        /// A kind's name as a rule's `kind:` is written (`kind: Material`).
        #[derive(Clone, Copy, serde::Deserialize)]
        #[serde(rename = "AssetKind")]
        pub enum KindName {
            $($name),*
        }

        impl From<KindName> for AssetKind {
            fn from(name: KindName) -> AssetKind {
                match name {
                    $(KindName::$name => crate::kinds::$folder::KIND),*
                }
            }
        }

        /// Every kind, in the list's order.
        pub const ALL: &[AssetKind] = &[$(crate::kinds::$folder::KIND),*];

        /// The entries of every kind, as `pipeline.ron` is read with them.
        pub struct Entries;

        impl EntryKinds for Entries {
            type Entry = AssetEntry;
            type KindName = KindName;
            const KINDS: &'static [KindFields] = &[
                $(KindFields::of::<crate::kinds::$folder::settings::Settings>(crate::kinds::$folder::KIND)),*
            ];

            fn defaults(validation: &mut Validation<'_>) -> Vec<KindSettings> {
                vec![$(validation.kind_defaults::<crate::kinds::$folder::settings::Settings>()),*]
            }

            fn resolve(
                validation: &mut Validation<'_>,
                entry: &AssetEntry,
                defaults: &[KindSettings],
                names: &mut AssetFolders,
            ) -> Option<AssetConfig> {
                match entry {
                    $(AssetEntry::$name(entry) => {
                        validation.resolve_entry::<crate::kinds::$folder::settings::Settings>(entry, defaults, names)
                    })*
                }
            }
        }
    };
}

with_kinds!(entries);
