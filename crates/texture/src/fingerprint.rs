//! Fingerprints of a texture's 4×4 blocks: how the tail tells which blocks (and mip tiles) of a
//! surface changed since its last bake without keeping that bake's largest level (an xxh3 of a
//! block's 64 bytes and one of its 16 alphas are 16 bytes instead of 64).

use rayon::prelude::*;

use crate::Texture;

/// Per 4×4 block in row order: the 64-bit xxh3 of its texels and of its alphas (texels beyond
/// an edge count as zero). A changed block passes for unchanged with odds of 2⁻⁶⁴ per block.
#[derive(Clone, Debug, PartialEq)]
pub struct BlockFingerprints {
    pub width: u32,
    pub height: u32,
    pub texels: Vec<u64>,
    pub alphas: Vec<u64>,
}

impl BlockFingerprints {
    /// The fingerprints of every block of `texture`, block rows in parallel.
    pub fn of(texture: &Texture) -> BlockFingerprints {
        let (width, height) = (texture.width as usize, texture.height as usize);
        let (blocks_x, blocks_y) = (width.div_ceil(4), height.div_ceil(4));
        let (mut texels, mut alphas) = (vec![0u64; blocks_x * blocks_y], vec![0u64; blocks_x * blocks_y]);
        texels.par_chunks_mut(blocks_x.max(1)).zip(alphas.par_chunks_mut(blocks_x.max(1))).enumerate().for_each(
            |(by, (row_texels, row_alphas))| {
                for bx in 0..blocks_x {
                    let (mut block, mut block_alphas) = ([0u8; 64], [0u8; 16]);
                    let columns = bx * 4..(bx * 4 + 4).min(width);
                    for (row_in_block, y) in (by * 4..(by * 4 + 4).min(height)).enumerate() {
                        let source = &texture.pixels[(y * width + columns.start) * 4..(y * width + columns.end) * 4];
                        block[row_in_block * 16..][..source.len()].copy_from_slice(source);
                        for (column, texel) in source.chunks_exact(4).enumerate() {
                            block_alphas[row_in_block * 4 + column] = texel[3];
                        }
                    }
                    row_texels[bx] = xxhash_rust::xxh3::xxh3_64(&block);
                    row_alphas[bx] = xxhash_rust::xxh3::xxh3_64(&block_alphas);
                }
            },
        );
        BlockFingerprints { width: texture.width, height: texture.height, texels, alphas }
    }

    /// Blocks per row.
    pub fn blocks_x(&self) -> usize {
        self.width.div_ceil(4) as usize
    }

    /// Whether `self` and `other` are of textures of one size (so that blocks correspond).
    pub(crate) fn same_size(&self, other: &BlockFingerprints) -> bool {
        (self.width, self.height) == (other.width, other.height)
    }

    /// Whether block `number`'s texels differ from the same block of `other` (of the same size).
    pub fn block_changed(&self, other: &BlockFingerprints, number: usize) -> bool {
        self.texels[number] != other.texels[number]
    }

    /// Whether block `number`'s alphas differ from the same block of `other`.
    pub fn alpha_changed(&self, other: &BlockFingerprints, number: usize) -> bool {
        self.alphas[number] != other.alphas[number]
    }
}
