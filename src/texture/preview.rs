//! PNG previews of uncompressed packed surfaces, for people to look at.

use crate::texture::Texture;

/// Encodes an RGBA8 texture as PNG bytes (deterministic).
pub fn preview_png(texture: &Texture) -> Vec<u8> {
    let mut bytes = Vec::new();
    let encoder = image::codecs::png::PngEncoder::new_with_quality(
        &mut bytes,
        image::codecs::png::CompressionType::Fast,
        image::codecs::png::FilterType::Adaptive,
    );
    image::ImageEncoder::write_image(encoder, &texture.pixels, texture.width, texture.height, image::ExtendedColorType::Rgba8)
        .expect("PNG encoding into memory cannot fail for a valid RGBA8 buffer");
    bytes
}
