//! Textures: the vocabulary every kind shares (`TextureSlot`, the source maps a material names;
//! `SurfaceKind`, the packed GPU surfaces), and decoded source textures: PNG, JPEG, TGA, BMP or
//! GIF bytes to RGBA8 pixels, with size and memory limits checked from the header, so that a
//! decompression bomb is an error, not an out-of-memory crash.

pub mod format;
pub mod color;
pub mod mips;
pub mod fingerprint;
pub mod fill;
pub mod distance_alpha;
pub mod bc1;
pub mod bc4;
pub mod ispc;
pub mod encode;
pub mod quality;
pub mod container;
pub mod preview;
pub mod tail;
pub mod channel_packing;

use std::fmt;
use std::io::Cursor;
use std::path::Path;
use std::sync::Arc;

use serde::{Deserialize, Serialize};

use base::diagnostic::Diagnostic;

/// Largest accepted width or height.
pub(crate) const MAX_TEXTURE_SIDE: u32 = 16384;
/// Largest accepted decoder allocation.
pub(crate) const MAX_DECODE_BYTES: u64 = 1 << 30;

/// Memory the stages after decoding need per texel of a texture, at their peak: the decoded
/// and packed RGBA8 levels, the mip filter's linear-light float texels (two sets of four `f32`
/// for colour with alpha) and the levels it makes, the blocks and their decoded check, the
/// preview. A whole `cirrus build` of one 8192² albedo peaks at 29 bytes per texel opaque and 44
/// alpha-tested (1.8 and 2.8 GiB); the estimate leaves room for a second map decoded meanwhile.
pub(crate) const WORKING_SET_BYTES_PER_TEXEL: u64 = 64;

/// Default budget of one texture's working set: textures up to about 8192² pass.
pub(crate) const DEFAULT_TEXTURE_MEMORY: u64 = 4 << 30;

/// How much memory one texture may cost.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct TextureLimits {
    /// Bytes one texture's working set may take (`WORKING_SET_BYTES_PER_TEXEL` per texel).
    pub working_set: u64,
}

impl Default for TextureLimits {
    fn default() -> Self {
        TextureLimits { working_set: DEFAULT_TEXTURE_MEMORY }
    }
}

impl TextureLimits {
    /// The bytes a `width` × `height` texture's bake needs at its peak.
    pub fn working_set_of(width: u32, height: u32) -> u64 {
        u64::from(width) * u64::from(height) * WORKING_SET_BYTES_PER_TEXEL
    }

    /// Refuses a `width` × `height` texture whose working set exceeds the budget, from its
    /// header, before anything is decoded.
    pub fn check(&self, file: &Path, width: u32, height: u32) -> Result<(), Diagnostic> {
        let needed = TextureLimits::working_set_of(width, height);
        if needed <= self.working_set {
            return Ok(());
        }
        let mib = |bytes: u64| bytes.div_ceil(1 << 20);
        Err(Diagnostic::new(
            file,
            format!(
                "the image is {width}×{height}: baking it needs about {} MiB, more than the texture memory budget of \
                    {} MiB \
                 (raise it with `limits: (texture_memory_mib: {})` in the pipeline file, or use a smaller image)",
                mib(needed),
                mib(self.working_set),
                mib(needed).next_power_of_two()
            ),
        ))
    }
}

/// The source maps a material can name.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub enum TextureSlot {
    Albedo,
    Opacity,
    Normal,
    Metallic,
    Roughness,
    Ao,
}

impl TextureSlot {
    pub fn name(self) -> &'static str {
        match self {
            TextureSlot::Albedo => "albedo",
            TextureSlot::Opacity => "opacity",
            TextureSlot::Normal => "normal",
            TextureSlot::Metallic => "metallic",
            TextureSlot::Roughness => "roughness",
            TextureSlot::Ao => "ao",
        }
    }

    /// Colour maps are sRGB; data maps are linear.
    pub fn is_srgb(self) -> bool {
        self == TextureSlot::Albedo
    }
}

/// The three textures of a baked material.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub enum SurfaceKind {
    Albedo,
    Mra,
    Normal,
    /// Billboard clouds only: the surface's distance from its plane over ±ε.
    Height,
    /// Ambient occlusion: the fraction of the hemisphere open to the sky (grey, linear).
    Ao,
}

impl SurfaceKind {
    /// The surfaces of a baked material.
    pub const MATERIAL: [SurfaceKind; 3] = [SurfaceKind::Albedo, SurfaceKind::Mra, SurfaceKind::Normal];
    /// The surfaces of a billboard-cloud atlas.
    pub const BILLBOARD: [SurfaceKind; 4] =
        [SurfaceKind::Albedo, SurfaceKind::Mra, SurfaceKind::Normal, SurfaceKind::Height];

    pub fn name(self) -> &'static str {
        match self {
            SurfaceKind::Albedo => "albedo",
            SurfaceKind::Mra => "mra",
            SurfaceKind::Normal => "normal",
            SurfaceKind::Height => "height",
            SurfaceKind::Ao => "ao",
        }
    }

    /// The source maps this surface is packed from.
    pub fn slots(self) -> &'static [TextureSlot] {
        match self {
            SurfaceKind::Albedo => &[TextureSlot::Albedo, TextureSlot::Opacity],
            SurfaceKind::Mra => &[TextureSlot::Metallic, TextureSlot::Roughness, TextureSlot::Ao],
            SurfaceKind::Normal => &[TextureSlot::Normal],
            SurfaceKind::Height => &[],
            SurfaceKind::Ao => &[TextureSlot::Ao],
        }
    }

    /// How many channels (from R) carry data: the channels that quality is measured on.
    pub fn channels(self) -> usize {
        match self {
            SurfaceKind::Albedo => 4,
            SurfaceKind::Mra => 3,
            SurfaceKind::Normal => 2,
            SurfaceKind::Height | SurfaceKind::Ao => 1,
        }
    }

    pub fn is_srgb(self) -> bool {
        self == SurfaceKind::Albedo
    }
}

/// An RGBA8 image, shared without copying. Equality is by content hash.
#[derive(Clone)]
pub struct Texture {
    pub width: u32,
    pub height: u32,
    pub pixels: Arc<Vec<u8>>,
    pub hash: blake3::Hash,
}

impl Texture {
    pub fn new(width: u32, height: u32, pixels: Vec<u8>) -> Texture {
        assert_eq!(pixels.len(), (width * height * 4) as usize, "RGBA8 pixel count");
        // The same hash either way; large images hash on every core (atlas surfaces are 16 MB).
        let hash = if pixels.len() >= 1 << 20 {
            blake3::Hasher::new().update_rayon(&pixels).finalize()
        } else {
            blake3::hash(&pixels)
        };
        Texture { width, height, pixels: Arc::new(pixels), hash }
    }

    /// A one-colour texture of `width` × `height`.
    pub fn constant(width: u32, height: u32, rgba: [u8; 4]) -> Texture {
        Texture::new(width, height, rgba.repeat((width * height) as usize))
    }

    pub fn texel(&self, x: u32, y: u32) -> [u8; 4] {
        let index = ((y * self.width + x) * 4) as usize;
        [self.pixels[index], self.pixels[index + 1], self.pixels[index + 2], self.pixels[index + 3]]
    }
}

impl PartialEq for Texture {
    fn eq(&self, other: &Self) -> bool {
        self.width == other.width && self.height == other.height && self.hash == other.hash
    }
}

impl Eq for Texture {}

impl fmt::Debug for Texture {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Texture({}x{}, {})", self.width, self.height, &self.hash.to_hex()[..12])
    }
}

/// Reads only the header of the image `bytes`: its size, or why it cannot be decoded or is
/// beyond `limits`.
pub fn probe_texture(file: &Path, bytes: &[u8], limits: TextureLimits) -> Result<(u32, u32), Diagnostic> {
    let reader = image_reader(file, bytes)?;
    let (width, height) = reader
        .into_dimensions()
        .map_err(|error| Diagnostic::new(file, format!("cannot read the image header: {error}")))?;
    if width > MAX_TEXTURE_SIDE || height > MAX_TEXTURE_SIDE {
        return Err(Diagnostic::new(
            file,
            format!("the image is {width}×{height}: the decoder takes sides of at most {MAX_TEXTURE_SIDE} texels"),
        ));
    }
    limits.check(file, width, height)?;
    if is_truncated_jpeg(bytes) {
        return Err(Diagnostic::new(file, TRUNCATED_JPEG));
    }
    Ok((width, height))
}

const TRUNCATED_JPEG: &str = "the JPEG is truncated (its image data has no end-of-image marker): re-export it";

/// Whether `bytes` are a JPEG whose entropy-coded data stops before the end-of-image marker.
/// The decoder fills what is missing with grey and reports no error, so the check is ours: walk
/// the marker segments to the first scan, then look for EOI (`FF D9`, which byte stuffing keeps
/// out of scan data). Thumbnails inside APP segments are skipped with their segment.
fn is_truncated_jpeg(bytes: &[u8]) -> bool {
    if !bytes.starts_with(&[0xFF, 0xD8]) {
        return false;
    }
    let mut at = 2;
    loop {
        let Some(&[prefix, marker]) = bytes.get(at..at + 2).map(|pair| <&[u8; 2]>::try_from(pair).expect("two bytes"))
        else {
            return true;
        };
        if prefix != 0xFF {
            // Not a marker where one must be: malformed, which the decoder reports itself.
            return false;
        }
        match marker {
            0xFF => at += 1,
            0xDA => return !bytes[at..].windows(2).any(|pair| pair == [0xFF, 0xD9]),
            0xD9 => return false,
            0x01 | 0xD0..=0xD7 => at += 2,
            _ => {
                let Some(length) = bytes.get(at + 2..at + 4).map(|pair| u16::from_be_bytes([pair[0], pair[1]])) else {
                    return true;
                };
                at += 2 + usize::from(length);
            }
        }
    }
}

/// Decodes the image `bytes` read from `file`; the format comes from the bytes, else the
/// extension. The header is checked against `limits` before anything is decoded.
pub fn decode_texture(file: &Path, bytes: &[u8], limits: TextureLimits) -> Result<Texture, Diagnostic> {
    probe_texture(file, bytes, limits)?;
    let mut reader = image_reader(file, bytes)?;
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(MAX_TEXTURE_SIDE);
    limits.max_image_height = Some(MAX_TEXTURE_SIDE);
    limits.max_alloc = Some(MAX_DECODE_BYTES);
    reader.limits(limits);
    let image = reader.decode().map_err(|error| {
        let message = match error {
            image::ImageError::Limits(_) => {
                format!(
                    "the image is larger than the decoder limits (sides of {MAX_TEXTURE_SIDE} texels, {} MiB)",
                    MAX_DECODE_BYTES >> 20
                )
            }
            other => format!("cannot decode the image: {other}"),
        };
        Diagnostic::new(file, message)
    })?;
    if image.width() == 0 || image.height() == 0 {
        return Err(Diagnostic::new(file, "the image is empty"));
    }
    let rgba = image.into_rgba8();
    Ok(Texture::new(rgba.width(), rgba.height(), rgba.into_raw()))
}

/// Checks that `bytes` are the image `file`'s extension names (PNG, JPEG, TGA, BMP or GIF; the
/// bytes' own signature must agree) and decode whole within `limits`: what a file copied into
/// the output as an image must pass, so that a map named `x.png` is never anything else.
pub fn check_image_file(file: &Path, bytes: &[u8], limits: TextureLimits) -> Result<(), Diagnostic> {
    let Some(named) = image::ImageFormat::from_path(file).ok().filter(|&format| decodable(format)) else {
        return Err(Diagnostic::new(file, format!("its name is not that of {DECODABLE}")));
    };
    let found = image::guess_format(bytes).ok();
    if found.is_some_and(|found| found != named) || (found.is_none() && named != image::ImageFormat::Tga) {
        let what = found.map_or_else(|| "not an image".to_string(), |found| format!("a {found:?} image"));
        return Err(Diagnostic::new(file, format!("it is named as a {named:?} image but is {what}")));
    }
    decode_texture(file, bytes, limits).map(|_| ())
}

fn image_reader<'a>(file: &Path, bytes: &'a [u8]) -> Result<image::ImageReader<Cursor<&'a [u8]>>, Diagnostic> {
    let mut reader = image::ImageReader::new(Cursor::new(bytes))
        .with_guessed_format()
        .map_err(|error| Diagnostic::new(file, format!("cannot read the image: {error}")))?;
    let not_decodable = || Diagnostic::new(file, format!("not {DECODABLE}"));
    if reader.format().is_none() {
        reader.set_format(image::ImageFormat::from_path(file).map_err(|_| not_decodable())?);
    }
    if !reader.format().is_some_and(decodable) {
        return Err(not_decodable());
    }
    Ok(reader)
}

/// The image formats cirrus decodes, and how messages name them.
fn decodable(format: image::ImageFormat) -> bool {
    use image::ImageFormat::{Bmp, Gif, Jpeg, Png, Tga};
    matches!(format, Png | Jpeg | Tga | Bmp | Gif)
}

const DECODABLE: &str = "a PNG, JPEG, TGA, BMP or GIF image";

/// An opacity map as one grey value in every channel (alpha included, so alpha-aware mips keep
/// its coverage): the alpha channel when the image has transparency (an
/// RGBA texture used as `map_d`, as foliage exporters write), else its red channel.
pub fn opacity_channel(texture: &Texture) -> Texture {
    let use_alpha = texture.pixels.chunks_exact(4).any(|texel| texel[3] < 255);
    let pixels = texture
        .pixels
        .chunks_exact(4)
        .flat_map(|texel| {
            let value = if use_alpha { texel[3] } else { texel[0] };
            [value, value, value, value]
        })
        .collect();
    Texture::new(texture.width, texture.height, pixels)
}

/// One 16-bit value per texel (a bake's map) as an RGBA8 grey texture, rounded to 8 bits (for
/// the texture tail: BC4 reads red).
pub fn grey16_texture(width: u32, height: u32, values: &[u16]) -> Texture {
    let pixels = values
        .iter()
        .flat_map(|&value| {
            let grey = ((value as u32 * 255 + 32767) / 65535) as u8;
            [grey, grey, grey, 255]
        })
        .collect();
    Texture::new(width, height, pixels)
}
