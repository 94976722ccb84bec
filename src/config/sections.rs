//! What the kinds' settings files share: how a merge reports a bad value (`Check`, with the
//! text's position), a page's size checks, and the deserializer of an explicit `None`. A leaf:
//! it imports no kind and nothing of `config` above it.

use serde::{Deserialize, Deserializer};

/// Where a settings merge reports a bad value: at the key, searched from the asset's entry.
pub(crate) trait Check {
    fn error_at_key(&mut self, key: &str, anchor: usize, message: &str);
}

/// A page's `max_size` and `padding` (a billboard atlas, a texture atlas), checked.
pub(crate) fn page_size_overrides(
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
pub(crate) fn explicit<'de, D, T>(deserializer: D) -> Result<Option<Option<T>>, D::Error>
where
    D: Deserializer<'de>,
    T: Deserialize<'de>,
{
    Option::<T>::deserialize(deserializer).map(Some)
}
