//! The serde mirror of `pipeline.ron`: what the file may say, before validation (every field
//! optional where a default applies; `deny_unknown_fields` throughout, so a typo is an error).
//! The shared parts are read with the entries and names of every kind (`Pipeline<Entry, Kind>`); each kind then
//! reads its own sections of `defaults:` (`KindDefaults`, one pass each).

use std::fmt;

use serde::de::{Deserializer, IgnoredAny, MapAccess, Visitor};
use serde::Deserialize;

use super::encode::EncodeOverrides;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Pipeline<Entry, Kind> {
    pub source: String,
    pub output: String,
    #[serde(default)]
    pub server: Option<String>,
    #[serde(default)]
    pub defaults: Defaults,
    #[serde(default = "Vec::new")]
    pub assets: Vec<Entry>,
    #[serde(default = "Vec::new")]
    pub rules: Vec<Rule<Kind>>,
    #[serde(default)]
    pub limits: Limits,
    #[serde(default)]
    pub cache: Cache,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct Cache {
    /// The shared cache's URL (`s3://bucket/prefix`).
    #[serde(default)]
    pub remote: Option<String>,
    pub mode: Option<crate::cache::remote::RemoteCacheMode>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct Limits {
    /// MiB one texture's working set may take.
    pub texture_memory_mib: Option<u64>,
    /// MiB the whole process may keep resident (`--memory-mib` wins).
    pub memory_mib: Option<u64>,
}

/// `defaults:` as the shared part reads it: the `encode` section, and the names of the others
/// (each checked against the sections some kind reads; each kind reads its own).
#[derive(Default)]
pub struct Defaults {
    pub encode: EncodeOverrides,
    pub sections: Vec<String>,
}

impl<'de> Deserialize<'de> for Defaults {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Defaults, D::Error> {
        struct DefaultsVisitor;
        impl<'de> Visitor<'de> for DefaultsVisitor {
            type Value = Defaults;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str("the defaults' sections, `(encode: (…), …)`")
            }
            fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Defaults, A::Error> {
                let mut defaults = Defaults::default();
                while let Some(SectionName(section)) = map.next_key()? {
                    if section == "encode" {
                        defaults.encode = map.next_value()?;
                    } else {
                        map.next_value::<IgnoredAny>()?;
                    }
                    defaults.sections.push(section);
                }
                Ok(defaults)
            }
        }
        deserializer.deserialize_struct("defaults", &[], DefaultsVisitor)
    }
}

/// A section's name, read as the identifier it is (ron reads no string there).
struct SectionName(String);

impl<'de> Deserialize<'de> for SectionName {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<SectionName, D::Error> {
        struct NameVisitor;
        impl Visitor<'_> for NameVisitor {
            type Value = SectionName;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str("a section's name")
            }
            fn visit_str<E: serde::de::Error>(self, name: &str) -> Result<SectionName, E> {
                Ok(SectionName(name.to_string()))
            }
        }
        deserializer.deserialize_identifier(NameVisitor)
    }
}

/// `pipeline.ron` as one kind reads it: only its sections of `defaults:`.
#[derive(Deserialize)]
#[serde(rename = "Pipeline")]
pub struct KindDefaults<Sections: Default> {
    #[serde(default)]
    pub defaults: Sections,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Rule<Kind> {
    pub glob: String,
    /// As written (the list of kinds' enum of names), then the kind it names.
    pub kind: Kind,
}
