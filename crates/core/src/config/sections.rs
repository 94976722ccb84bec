//! What the kinds' settings files share: how a merge reports a bad value (`Check`, with the
//! text's position), a page's size checks, the deserializer of an explicit `None`, and the alpha
//! test two kinds read. A leaf: it imports no kind and nothing of `config` above it.

use serde::{Deserialize, Deserializer};

/// Where a settings merge reports a bad value: at the key, searched from the asset's entry.
pub trait Check {
    fn error_at_key(&mut self, key: &str, anchor: usize, message: &str);
}

/// A page's `max_size` and `padding` (a billboard atlas, a texture atlas), checked.
pub fn page_size_overrides(
    check: &mut dyn Check,
    max_size: Option<u32>,
    padding: Option<u32>,
    anchor: usize,
    size: &mut u32,
    pad: &mut u32,
) {
    if let Some(max_size) = max_size {
        if !(16..=16384).contains(&max_size) || max_size % 4 != 0 {
            check.error_at_key("max_size", anchor, "max_size must be a multiple of 4 between 16 and 16384");
        }
        *size = max_size;
    }
    if let Some(padding) = padding {
        if padding > 64 {
            check.error_at_key("padding", anchor, "padding must be at most 64 texels");
        }
        *pad = padding;
    }
}

/// `Some(None)` is an explicit `None` in the file; `None` is "not given".
pub fn explicit<'de, D, T>(deserializer: D) -> Result<Option<Option<T>>, D::Error>
where
    D: Deserializer<'de>,
    T: Deserialize<'de>,
{
    Option::<T>::deserialize(deserializer).map(Some)
}

/// The alpha test of an alpha-tested albedo, which two kinds read (a `Material`'s albedo, a
/// `BillboardCloud`'s atlases): `alpha_cutoff`, written in the `billboard` section.
#[derive(Deserialize, Default, Clone)]
#[serde(rename = "billboard", deny_unknown_fields)]
pub struct AlphaTestOverrides {
    pub alpha_cutoff: Option<f32>,
}

/// The `billboard` section of `defaults:` as a kind that reads only its alpha test sees it (the
/// section's other fields are the billboard cloud's, which checks them).
#[derive(Deserialize, Default, Clone)]
pub struct AlphaTestOfDefaults {
    pub alpha_cutoff: Option<f32>,
}

/// The alpha cutoff every kind starts from.
pub const DEFAULT_ALPHA_CUTOFF: f32 = 0.5;

/// `alpha_cutoff` merged over `cutoff`, checked.
pub fn merge_alpha_cutoff(check: &mut dyn Check, cutoff: &mut f32, given: Option<f32>, anchor: usize) {
    if let Some(given) = given {
        if !(0.0..=1.0).contains(&given) {
            check.error_at_key("alpha_cutoff", anchor, "alpha_cutoff must be in [0, 1]");
        }
        *cutoff = given;
    }
}
