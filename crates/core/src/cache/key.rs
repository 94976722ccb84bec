//! Cache keys: a content address (`CacheKey`) built from a stage's name, its version and every
//! part its result depends on, each part with an explicit byte encoding (`KeyPart`: no `Debug`
//! text, no absolute paths), so that the same project in two folders, or on two machines, has the
//! same keys; the parts' descriptions are kept for `cirrus cache explain`.

use std::path::{Path, PathBuf};

/// A content address: the blake3 hash of everything a stage result depends on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct CacheKey(pub blake3::Hash);

/// Builds a `CacheKey` from a stage name, its version and every input that can change its
/// result; it also keeps a short description of each part, for `cirrus cache explain`.
pub struct CacheKeyBuilder {
    hasher: blake3::Hasher,
    parts: Vec<String>,
}

impl CacheKeyBuilder {
    pub fn new(stage: &str, version: u32) -> CacheKeyBuilder {
        let mut hasher = blake3::Hasher::new();
        hasher.update(b"cirrus-cache-v2\0");
        CacheKeyBuilder { hasher, parts: Vec::new() }.part(stage).part(&version)
    }

    /// Adds raw bytes as one part (length-prefixed).
    pub fn bytes(mut self, bytes: &[u8]) -> Self {
        self.hasher.update(&(bytes.len() as u64).to_le_bytes());
        self.hasher.update(bytes);
        if self.parts.len() < MAX_DESCRIBED_PARTS {
            self.parts.push(describe_part(bytes));
        }
        self
    }

    /// Adds a value in its key encoding (see the module docs).
    pub fn part(self, part: &(impl KeyPart + ?Sized)) -> Self {
        part.add_to(self)
    }

    pub fn finish(self) -> CacheKey {
        let key = CacheKey(self.hasher.finalize());
        key_parts::remember(key, self.parts);
        key
    }
}

/// Parts described per key (the rest still enter the hash).
const MAX_DESCRIBED_PARTS: usize = 256;

/// A part as a person can compare it: short text as it is, numbers, hashes by their start.
fn describe_part(bytes: &[u8]) -> String {
    if let Ok(text) = std::str::from_utf8(bytes) {
        if (2..=96).contains(&text.len()) && text.chars().all(|character| !character.is_control()) {
            return format!("`{text}`");
        }
    }
    match bytes.len() {
        0 => "(empty)".to_string(),
        1 => bytes[0].to_string(),
        4 => u32::from_le_bytes(bytes.try_into().expect("four bytes")).to_string(),
        8 => u64::from_le_bytes(bytes.try_into().expect("eight bytes")).to_string(),
        32 => format!("hash {}", &blake3::Hash::from_bytes(bytes.try_into().expect("32 bytes")).to_hex()[..16]),
        length => format!("{length} bytes, xxh3 {:016x}", xxhash_rust::xxh3::xxh3_64(bytes)),
    }
}

/// The parts of the keys made in this process, for the lookups a build records.
pub mod key_parts {
    use std::collections::HashMap;
    use std::sync::{Arc, Mutex};

    use crate::cache::key::CacheKey;

    /// Keys remembered at most; past it every key is forgotten and remembering starts again
    /// (explain then says less of the keys made before).
    const MAX_KEYS: usize = 1 << 18;

    static PARTS: Mutex<Option<HashMap<CacheKey, Arc<[String]>>>> = Mutex::new(None);

    pub fn remember(key: CacheKey, parts: Vec<String>) {
        let mut known = PARTS.lock().expect("key parts lock");
        let known = known.get_or_insert_with(HashMap::new);
        if known.len() >= MAX_KEYS {
            known.clear();
        }
        known.insert(key, parts.into());
    }

    pub fn of(key: CacheKey) -> Option<Arc<[String]>> {
        PARTS.lock().expect("key parts lock").as_ref()?.get(&key).cloned()
    }
}

/// A value with a fixed byte encoding in cache keys: one or more parts.
pub trait KeyPart {
    fn add_to(&self, key: CacheKeyBuilder) -> CacheKeyBuilder;
}

impl KeyPart for str {
    fn add_to(&self, key: CacheKeyBuilder) -> CacheKeyBuilder {
        key.bytes(self.as_bytes())
    }
}

impl KeyPart for String {
    fn add_to(&self, key: CacheKeyBuilder) -> CacheKeyBuilder {
        key.bytes(self.as_bytes())
    }
}

impl KeyPart for Path {
    fn add_to(&self, key: CacheKeyBuilder) -> CacheKeyBuilder {
        key.part(crate::diagnostic::display_path(self).as_str())
    }
}

impl KeyPart for PathBuf {
    fn add_to(&self, key: CacheKeyBuilder) -> CacheKeyBuilder {
        key.part(self.as_path())
    }
}

impl KeyPart for u32 {
    fn add_to(&self, key: CacheKeyBuilder) -> CacheKeyBuilder {
        key.bytes(&self.to_le_bytes())
    }
}

impl KeyPart for u64 {
    fn add_to(&self, key: CacheKeyBuilder) -> CacheKeyBuilder {
        key.bytes(&self.to_le_bytes())
    }
}

impl KeyPart for i32 {
    fn add_to(&self, key: CacheKeyBuilder) -> CacheKeyBuilder {
        key.bytes(&self.to_le_bytes())
    }
}

impl KeyPart for f32 {
    fn add_to(&self, key: CacheKeyBuilder) -> CacheKeyBuilder {
        key.bytes(&self.to_bits().to_le_bytes())
    }
}

impl KeyPart for bool {
    fn add_to(&self, key: CacheKeyBuilder) -> CacheKeyBuilder {
        key.bytes(&[u8::from(*self)])
    }
}

impl KeyPart for blake3::Hash {
    fn add_to(&self, key: CacheKeyBuilder) -> CacheKeyBuilder {
        key.bytes(self.as_bytes())
    }
}

impl<T: KeyPart> KeyPart for Option<T> {
    fn add_to(&self, key: CacheKeyBuilder) -> CacheKeyBuilder {
        match self {
            None => key.bytes(&[0]),
            Some(value) => key.bytes(&[1]).part(value),
        }
    }
}

impl<T: KeyPart, const N: usize> KeyPart for [T; N] {
    fn add_to(&self, key: CacheKeyBuilder) -> CacheKeyBuilder {
        self.iter().fold(key, |key, item| key.part(item))
    }
}

/// Slices enter with their length, so that `[a, b]` then `c` differs from `[a]` then `b, c`.
impl<T: KeyPart> KeyPart for [T] {
    fn add_to(&self, key: CacheKeyBuilder) -> CacheKeyBuilder {
        self.iter().fold(key.part(&(self.len() as u32)), |key, item| key.part(item))
    }
}

impl<A: KeyPart, B: KeyPart> KeyPart for (A, B) {
    fn add_to(&self, key: CacheKeyBuilder) -> CacheKeyBuilder {
        key.part(&self.0).part(&self.1)
    }
}

/// Enums enter keys by their names as `pipeline.ron` writes them (their `Debug` text is the
/// same today, but that is not a contract).
macro_rules! key_part_by_name {
    ($type:ty { $($variant:ident),* $(,)? }) => {
        impl KeyPart for $type {
            fn add_to(&self, key: CacheKeyBuilder) -> CacheKeyBuilder {
                key.part(match self { $(<$type>::$variant => stringify!($variant),)* })
            }
        }
    };
}

key_part_by_name!(crate::texture::format::BlockFormat { Bc1, Bc3, Bc4, Bc5, Bc7 });
key_part_by_name!(crate::texture::format::Container { Ktx2, Dds, Pvr });
key_part_by_name!(crate::texture::format::Packing { Mra, Orm });
key_part_by_name!(crate::texture::format::EncodeQuality { UltraFast, VeryFast, Fast, Basic, Slow, Exhaustive });

impl KeyPart for crate::texture::SurfaceKind {
    fn add_to(&self, key: CacheKeyBuilder) -> CacheKeyBuilder {
        key.part(self.name())
    }
}

/// An atlas page's settings (a billboard cloud's and an atlas's pack).
impl KeyPart for packing::PageSettings {
    fn add_to(&self, key: CacheKeyBuilder) -> CacheKeyBuilder {
        let packing::PageSettings { max_size, padding, power_of_two } = self;
        key.part(max_size).part(padding).part(power_of_two)
    }
}
