//! PNG previews of uncompressed packed surfaces, for people to look at, and the one PNG
//! encoder (16-bit maps use it too).

use crate::Texture;

/// Encodes an RGBA8 texture as PNG bytes (deterministic).
pub fn preview_png(texture: &Texture) -> Vec<u8> {
    png_bytes(&texture.pixels, texture.width, texture.height, image::ExtendedColorType::Rgba8)
}

/// Encodes `samples` (native-endian for 16-bit colour types) as PNG bytes: fast compression,
/// adaptive filters, deterministic.
pub fn png_bytes(samples: &[u8], width: u32, height: u32, color: image::ExtendedColorType) -> Vec<u8> {
    let mut bytes = Vec::new();
    let encoder = image::codecs::png::PngEncoder::new_with_quality(
        &mut bytes,
        image::codecs::png::CompressionType::Fast,
        image::codecs::png::FilterType::Adaptive,
    );
    image::ImageEncoder::write_image(encoder, samples, width, height, color)
        .expect("PNG encoding into memory cannot fail for a buffer of the right size");
    bytes
}

/// A 16-bit greyscale PNG of one value per texel (a bake's map).
pub fn png16_grey(values: &[u16], width: u32, height: u32) -> Vec<u8> {
    let samples: Vec<u8> = values.iter().flat_map(|value| value.to_ne_bytes()).collect();
    png_bytes(&samples, width, height, image::ExtendedColorType::L16)
}

/// A PNG's bytes without its colour-space and pixel-size chunks (`iCCP`, `cHRM`, `gAMA`, `sRGB`,
/// `pHYs`): the same pixels, which glTF reads as sRGB (colour) or linear (data) whatever a
/// profile says, and which the glTF validator flags when a profile is there. `None` when the
/// bytes are not a well-formed chunk sequence (then the file is copied as it is).
pub fn png_without_colour_chunks(bytes: &[u8]) -> Option<Vec<u8>> {
    const SIGNATURE: &[u8] = b"\x89PNG\r\n\x1a\n";
    const DROPPED: [&[u8; 4]; 5] = [b"iCCP", b"cHRM", b"gAMA", b"sRGB", b"pHYs"];
    let mut rest = bytes.strip_prefix(SIGNATURE)?;
    let mut kept = SIGNATURE.to_vec();
    while !rest.is_empty() {
        let length = u32::from_be_bytes(rest.get(..4)?.try_into().ok()?) as usize;
        let chunk = rest.get(..length.checked_add(12)?)?;
        if !DROPPED.iter().any(|name| &chunk[4..8] == *name) {
            kept.extend_from_slice(chunk);
        }
        rest = &rest[chunk.len()..];
        if &chunk[4..8] == b"IEND" {
            break;
        }
    }
    Some(kept)
}
