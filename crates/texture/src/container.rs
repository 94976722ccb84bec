//! Texture files: block-compressed levels wrapped in KTX2 (with its data format descriptor and
//! optional zstd supercompression), DDS (DX10 header) or PVR v3.

use crate::encode::{block_bytes, EncodedTexture};
use crate::format::{BlockFormat, Container};

/// Writes `texture` in `container`; `zstd_level` applies to KTX2 only.
pub fn write_container(texture: &EncodedTexture, container: Container, zstd_level: Option<i32>) -> Vec<u8> {
    match container {
        Container::Ktx2 => write_ktx2(texture, zstd_level),
        Container::Dds => write_dds(texture),
        Container::Pvr => write_pvr(texture),
    }
}

pub const KTX2_IDENTIFIER: [u8; 12] = [0xAB, b'K', b'T', b'X', b' ', b'2', b'0', 0xBB, b'\r', b'\n', 0x1A, b'\n'];

/// Vulkan's `VkFormat` value of a block format.
pub fn vk_format(format: BlockFormat, srgb: bool) -> u32 {
    match (format, srgb) {
        (BlockFormat::Bc1, false) => 131, // VK_FORMAT_BC1_RGB_UNORM_BLOCK
        (BlockFormat::Bc1, true) => 132,  // VK_FORMAT_BC1_RGB_SRGB_BLOCK
        (BlockFormat::Bc3, false) => 137, // VK_FORMAT_BC3_UNORM_BLOCK
        (BlockFormat::Bc3, true) => 138,  // VK_FORMAT_BC3_SRGB_BLOCK
        (BlockFormat::Bc4, _) => 139,     // VK_FORMAT_BC4_UNORM_BLOCK
        (BlockFormat::Bc5, _) => 141,     // VK_FORMAT_BC5_UNORM_BLOCK
        (BlockFormat::Bc7, false) => 145, // VK_FORMAT_BC7_UNORM_BLOCK
        (BlockFormat::Bc7, true) => 146,  // VK_FORMAT_BC7_SRGB_BLOCK
    }
}

/// The Khronos basic data format descriptor block of a block format.
fn data_format_descriptor(format: BlockFormat, srgb: bool) -> Vec<u8> {
    // (channel id, bit offset, bit length) per sample; KHR_DF_MODEL_* colour model.
    let (model, samples): (u8, &[(u8, u16, u8)]) = match format {
        BlockFormat::Bc1 => (128, &[(0, 0, 63)]),               // BC1A, COLOR
        BlockFormat::Bc3 => (130, &[(15, 0, 63), (0, 64, 63)]), // BC3, ALPHA then COLOR
        BlockFormat::Bc4 => (131, &[(0, 0, 63)]),               // BC4, DATA
        BlockFormat::Bc5 => (132, &[(0, 0, 63), (1, 64, 63)]),  // BC5, RED then GREEN
        BlockFormat::Bc7 => (134, &[(0, 0, 127)]),              // BC7, COLOR
    };
    let block_size = 24 + 16 * samples.len() as u32;
    let mut dfd = Vec::new();
    push_u32(&mut dfd, 4 + block_size); // dfdTotalSize
    push_u32(&mut dfd, 0); // vendorId KHRONOS (17 bits) | descriptorType BASICFORMAT (15 bits)
    push_u32(&mut dfd, 2 | (block_size << 16)); // versionNumber 1.3 | descriptorBlockSize
    let transfer: u32 = if srgb { 2 } else { 1 }; // KHR_DF_TRANSFER_SRGB / LINEAR
    let primaries: u32 = 1; // KHR_DF_PRIMARIES_BT709
    push_u32(&mut dfd, model as u32 | (primaries << 8) | (transfer << 16)); // flags: straight alpha
    dfd.extend_from_slice(&[3, 3, 0, 0]); // texelBlockDimension 4×4×1×1, stored minus one
    let bytes_plane0 = block_bytes(format) as u8;
    dfd.extend_from_slice(&[bytes_plane0, 0, 0, 0, 0, 0, 0, 0]);
    for &(channel, offset, length) in samples {
        push_u32(&mut dfd, offset as u32 | ((length as u32) << 16) | ((channel as u32) << 24));
        push_u32(&mut dfd, 0); // samplePosition 0,0,0,0
        push_u32(&mut dfd, 0); // sampleLower
        push_u32(&mut dfd, u32::MAX); // sampleUpper
    }
    dfd
}

fn write_ktx2(texture: &EncodedTexture, zstd_level: Option<i32>) -> Vec<u8> {
    let level_count = texture.levels.len();
    let header_size = 12 + 9 * 4 + 4 * 4 + 2 * 8;
    let level_index_size = level_count * 24;
    let dfd = data_format_descriptor(texture.format, texture.srgb);
    let mut kvd = Vec::new();
    // Keys in byte order, as the specification requires. Rows are stored top to bottom, columns
    // left to right: "rd", the orientation glTF and the PNG previews share.
    push_key_value(&mut kvd, "KTXorientation", "rd");
    push_key_value(&mut kvd, "KTXwriter", &format!("cirrus {}", env!("CARGO_PKG_VERSION")));
    let dfd_offset = header_size + level_index_size;
    let kvd_offset = dfd_offset + dfd.len();
    let mut data_start = kvd_offset + kvd.len();

    // Level payloads (supercompressed when asked); stored smallest level first.
    let payloads: Vec<Vec<u8>> = texture
        .levels
        .iter()
        .map(|level| match zstd_level {
            Some(compression) => {
                zstd::bulk::compress(level, compression).expect("zstd compression of an in-memory buffer")
            }
            None => level.to_vec(),
        })
        .collect();
    let alignment = if zstd_level.is_some() { 1 } else { lcm(block_bytes(texture.format), 4) };
    let mut offsets = vec![0usize; level_count];
    let mut cursor = data_start;
    for level in (0..level_count).rev() {
        cursor = cursor.next_multiple_of(alignment);
        if level == level_count - 1 {
            data_start = cursor;
        }
        offsets[level] = cursor;
        cursor += payloads[level].len();
    }

    let mut file = Vec::with_capacity(cursor);
    file.extend_from_slice(&KTX2_IDENTIFIER);
    push_u32(&mut file, vk_format(texture.format, texture.srgb));
    push_u32(&mut file, 1); // typeSize
    push_u32(&mut file, texture.width);
    push_u32(&mut file, texture.height);
    push_u32(&mut file, 0); // pixelDepth
    push_u32(&mut file, 0); // layerCount
    push_u32(&mut file, 1); // faceCount
    push_u32(&mut file, level_count as u32);
    push_u32(&mut file, if zstd_level.is_some() { 2 } else { 0 }); // supercompressionScheme
    push_u32(&mut file, dfd_offset as u32);
    push_u32(&mut file, dfd.len() as u32);
    push_u32(&mut file, kvd_offset as u32);
    push_u32(&mut file, kvd.len() as u32);
    push_u64(&mut file, 0); // sgdByteOffset
    push_u64(&mut file, 0); // sgdByteLength
    for level in 0..level_count {
        push_u64(&mut file, offsets[level] as u64);
        push_u64(&mut file, payloads[level].len() as u64);
        push_u64(&mut file, texture.levels[level].len() as u64);
    }
    file.extend_from_slice(&dfd);
    file.extend_from_slice(&kvd);
    debug_assert!(file.len() <= data_start);
    for level in (0..level_count).rev() {
        file.resize(offsets[level], 0);
        file.extend_from_slice(&payloads[level]);
    }
    file
}

fn push_key_value(kvd: &mut Vec<u8>, key: &str, value: &str) {
    let length = key.len() + 1 + value.len() + 1;
    push_u32(kvd, length as u32);
    kvd.extend_from_slice(key.as_bytes());
    kvd.push(0);
    kvd.extend_from_slice(value.as_bytes());
    kvd.push(0);
    kvd.resize(kvd.len().next_multiple_of(4), 0);
}

/// DXGI_FORMAT value of a block format.
pub(crate) fn dxgi_format(format: BlockFormat, srgb: bool) -> u32 {
    match (format, srgb) {
        (BlockFormat::Bc1, false) => 71,
        (BlockFormat::Bc1, true) => 72,
        (BlockFormat::Bc3, false) => 77,
        (BlockFormat::Bc3, true) => 78,
        (BlockFormat::Bc4, _) => 80,
        (BlockFormat::Bc5, _) => 83,
        (BlockFormat::Bc7, false) => 98,
        (BlockFormat::Bc7, true) => 99,
    }
}

fn write_dds(texture: &EncodedTexture) -> Vec<u8> {
    const DDSD_CAPS: u32 = 0x1;
    const DDSD_HEIGHT: u32 = 0x2;
    const DDSD_WIDTH: u32 = 0x4;
    const DDSD_PIXELFORMAT: u32 = 0x1000;
    const DDSD_MIPMAPCOUNT: u32 = 0x20000;
    const DDSD_LINEARSIZE: u32 = 0x80000;
    const DDPF_FOURCC: u32 = 0x4;
    const DDSCAPS_COMPLEX: u32 = 0x8;
    const DDSCAPS_TEXTURE: u32 = 0x1000;
    const DDSCAPS_MIPMAP: u32 = 0x400000;
    let level_count = texture.levels.len() as u32;
    let mut file = Vec::new();
    file.extend_from_slice(b"DDS ");
    push_u32(&mut file, 124);
    push_u32(&mut file, DDSD_CAPS | DDSD_HEIGHT | DDSD_WIDTH | DDSD_PIXELFORMAT | DDSD_MIPMAPCOUNT | DDSD_LINEARSIZE);
    push_u32(&mut file, texture.height);
    push_u32(&mut file, texture.width);
    push_u32(&mut file, texture.levels[0].len() as u32); // pitchOrLinearSize
    push_u32(&mut file, 0); // depth
    push_u32(&mut file, level_count);
    file.extend_from_slice(&[0u8; 44]); // reserved1
    push_u32(&mut file, 32); // pixel format size
    push_u32(&mut file, DDPF_FOURCC);
    file.extend_from_slice(b"DX10");
    file.extend_from_slice(&[0u8; 20]); // bit count and masks
    let complex = if level_count > 1 { DDSCAPS_COMPLEX | DDSCAPS_MIPMAP } else { 0 };
    push_u32(&mut file, DDSCAPS_TEXTURE | complex);
    file.extend_from_slice(&[0u8; 16]); // caps2, caps3, caps4, reserved2
    push_u32(&mut file, dxgi_format(texture.format, texture.srgb));
    push_u32(&mut file, 3); // D3D10_RESOURCE_DIMENSION_TEXTURE2D
    push_u32(&mut file, 0); // miscFlag
    push_u32(&mut file, 1); // arraySize
    push_u32(&mut file, 0); // miscFlags2: alpha mode unknown (straight)
    for level in &texture.levels {
        file.extend_from_slice(level);
    }
    file
}

/// PVR v3 pixel format ids of the compressed formats.
pub(crate) fn pvr_format(format: BlockFormat) -> u64 {
    match format {
        BlockFormat::Bc1 => 7,
        BlockFormat::Bc3 => 11,
        BlockFormat::Bc4 => 12,
        BlockFormat::Bc5 => 13,
        BlockFormat::Bc7 => 15,
    }
}

pub const PVR3_VERSION: u32 = 0x03525650;

fn write_pvr(texture: &EncodedTexture) -> Vec<u8> {
    let mut file = Vec::new();
    push_u32(&mut file, PVR3_VERSION);
    push_u32(&mut file, 0); // flags: not premultiplied
    push_u64(&mut file, pvr_format(texture.format));
    push_u32(&mut file, if texture.srgb { 1 } else { 0 }); // colour space
    push_u32(&mut file, 0); // channel type: unsigned byte normalised
    push_u32(&mut file, texture.height);
    push_u32(&mut file, texture.width);
    push_u32(&mut file, 1); // depth
    push_u32(&mut file, 1); // surfaces
    push_u32(&mut file, 1); // faces
    push_u32(&mut file, texture.levels.len() as u32);
    push_u32(&mut file, 0); // metadata size
    for level in &texture.levels {
        file.extend_from_slice(level);
    }
    file
}

fn push_u32(buffer: &mut Vec<u8>, value: u32) {
    buffer.extend_from_slice(&value.to_le_bytes());
}

fn push_u64(buffer: &mut Vec<u8>, value: u64) {
    buffer.extend_from_slice(&value.to_le_bytes());
}

fn lcm(a: usize, b: usize) -> usize {
    let gcd = |mut a: usize, mut b: usize| {
        while b != 0 {
            (a, b) = (b, a % b);
        }
        a
    };
    a / gcd(a, b) * b
}

/// A KTX2, DDS or PVR file read back: its block format and the block data of every level (level
/// 0 first).
#[derive(Clone, Debug, PartialEq)]
pub struct Ktx2Texture {
    pub format: BlockFormat,
    pub srgb: bool,
    pub width: u32,
    pub height: u32,
    pub levels: Vec<Vec<u8>>,
}

/// Reads a block-compressed texture in any container `write_container` writes (told apart by
/// their first bytes): KTX2, DDS with its DX10 header, PVR v3.
pub fn read_container(bytes: &[u8]) -> Result<Ktx2Texture, String> {
    if bytes.starts_with(&KTX2_IDENTIFIER) {
        return read_ktx2(bytes);
    }
    let u32_at = |offset: usize| {
        bytes.get(offset..offset + 4).map(|b| u32::from_le_bytes(b.try_into().expect("4 bytes"))).ok_or("truncated")
    };
    let formats = [BlockFormat::Bc1, BlockFormat::Bc3, BlockFormat::Bc4, BlockFormat::Bc5, BlockFormat::Bc7]
        .into_iter()
        .flat_map(|format| [(format, false), (format, true)]);
    let (format, srgb, width, height, level_count, data_start) = if bytes.starts_with(b"DDS ") {
        if u32_at(84)? != u32::from_le_bytes(*b"DX10") {
            return Err("a DDS file without the DX10 header".into());
        }
        let dxgi = u32_at(128)?;
        let (format, srgb) = formats
            .clone()
            .find(|&(format, srgb)| dxgi_format(format, srgb) == dxgi)
            .ok_or_else(|| format!("unsupported DXGI format {dxgi}"))?;
        (format, srgb, u32_at(16)?, u32_at(12)?, u32_at(28)?.max(1), 148usize)
    } else if u32_at(0) == Ok(PVR3_VERSION) {
        let pixel_format = u64::from(u32_at(8)?) | (u64::from(u32_at(12)?) << 32);
        let srgb = u32_at(16)? == 1;
        let (format, _) = formats
            .clone()
            .find(|&(format, _)| pvr_format(format) == pixel_format)
            .ok_or_else(|| format!("unsupported PVR pixel format {pixel_format}"))?;
        (format, srgb, u32_at(28)?, u32_at(24)?, u32_at(44)?.max(1), 52usize + u32_at(48)? as usize)
    } else {
        return Err("not a KTX2, DDS or PVR file".into());
    };
    if width == 0 || height == 0 || width > 1 << 16 || height > 1 << 16 || level_count > 17 {
        return Err(format!("{width}×{height} with {level_count} levels: not a texture cirrus writes"));
    }
    let block_bytes = if matches!(format, BlockFormat::Bc1 | BlockFormat::Bc4) { 8 } else { 16 };
    let mut levels = Vec::with_capacity(level_count as usize);
    let mut at = data_start;
    for level in 0..level_count {
        let (level_width, level_height) = ((width >> level).max(1), (height >> level).max(1));
        let length = level_width.div_ceil(4) as usize * level_height.div_ceil(4) as usize * block_bytes;
        let data = bytes.get(at..at + length).ok_or("a level lies outside the file")?;
        levels.push(data.to_vec());
        at += length;
    }
    Ok(Ktx2Texture { format, srgb, width, height, levels })
}

/// Reads a block-compressed KTX2 file as written by `write_container` (BC formats, one face and
/// layer, optional zstd supercompression).
pub fn read_ktx2(bytes: &[u8]) -> Result<Ktx2Texture, String> {
    if bytes.len() < 80 || bytes[..12] != KTX2_IDENTIFIER {
        return Err("not a KTX2 file".into());
    }
    let u32_at = |offset: usize| u32::from_le_bytes(bytes[offset..offset + 4].try_into().expect("4 bytes"));
    let u64_at =
        |offset: usize| bytes.get(offset..offset + 8).map(|b| u64::from_le_bytes(b.try_into().expect("8 bytes")));
    let vk_format = u32_at(12);
    let (format, srgb) = [BlockFormat::Bc1, BlockFormat::Bc3, BlockFormat::Bc4, BlockFormat::Bc5, BlockFormat::Bc7]
        .into_iter()
        .flat_map(|format| [(format, false), (format, true)])
        .find(|&(format, srgb)| self::vk_format(format, srgb) == vk_format)
        .ok_or_else(|| format!("unsupported vkFormat {vk_format}"))?;
    let (width, height, level_count, scheme) = (u32_at(20), u32_at(24), u32_at(40).max(1) as usize, u32_at(44));
    let mut levels = Vec::with_capacity(level_count);
    for level in 0..level_count {
        let at = 80 + level * 24;
        let (offset, length, uncompressed) = match (u64_at(at), u64_at(at + 8), u64_at(at + 16)) {
            (Some(offset), Some(length), Some(uncompressed)) => {
                (offset as usize, length as usize, uncompressed as usize)
            }
            _ => return Err("truncated level index".into()),
        };
        let data = bytes.get(offset..offset.saturating_add(length)).ok_or("a level lies outside the file")?;
        levels.push(match scheme {
            0 => data.to_vec(),
            2 => zstd::bulk::decompress(data, uncompressed).map_err(|error| format!("zstd: {error}"))?,
            other => return Err(format!("unsupported supercompression scheme {other}")),
        });
    }
    Ok(Ktx2Texture { format, srgb, width, height, levels })
}
