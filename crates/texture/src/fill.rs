//! The one fill of uncovered texels, shared by every kind that lays images out on a page (the
//! billboard atlas, the texture atlas) or bakes into UV space (ambient occlusion): each
//! uncovered texel copies the nearest covered one, so that filtering and mips never pull in a
//! dark or foreign fringe.

use rayon::prelude::*;

/// For every texel, the covered texel it takes its values from: itself where covered, the
/// nearest covered texel elsewhere. Empty when nothing is covered.
#[derive(Clone, Debug, PartialEq)]
pub struct TexelSources(pub Vec<u32>);

impl TexelSources {
    /// Each texel's source as an offset from the texel itself (wrapping): zero where covered and
    /// small nearby, so the list compresses to a few percent of its size.
    pub fn to_offsets(&self) -> Vec<u32> {
        self.0.par_iter().enumerate().map(|(texel, &source)| source.wrapping_sub(texel as u32)).collect()
    }

    /// The sources back from `to_offsets`, for an image of `texels` texels; `None` when the
    /// count is wrong or a source lies outside the image (a damaged or hand-made cache entry).
    pub fn from_offsets(offsets: &[u32], texels: usize) -> Option<TexelSources> {
        if offsets.len() != texels {
            return None;
        }
        let sources: Vec<u32> =
            offsets.par_iter().enumerate().map(|(texel, &offset)| offset.wrapping_add(texel as u32)).collect();
        sources.par_iter().all(|&source| (source as usize) < texels).then_some(TexelSources(sources))
    }
}

/// Where every texel of a `width` × `height` image takes its values from (see [`TexelSources`]):
/// the nearest of the `covered` texels (indices, ascending), breadth-first from all of them at
/// once; empty when none is covered.
pub fn texel_sources(width: u32, height: u32, covered: impl IntoIterator<Item = u32>) -> TexelSources {
    const UNREACHED: u32 = u32::MAX;
    const BORDER: u32 = u32::MAX - 1;
    let (width, height) = (width as usize, height as usize);
    // The search runs on a grid with a one-texel border that counts as already reached, so a
    // texel's four neighbours are ±1 and ±stride with no bounds tests. Each cell holds the
    // (unpadded) index of the covered texel it copies from.
    let stride = width + 2;
    let mut source = vec![UNREACHED; stride * (height + 2)];
    source[..stride].fill(BORDER);
    source[(height + 1) * stride..].fill(BORDER);
    for row in 1..=height {
        source[row * stride] = BORDER;
        source[row * stride + width + 1] = BORDER;
    }
    let mut queue: Vec<u32> = Vec::with_capacity(width * height);
    for index in covered.into_iter().map(|index| index as usize) {
        let padded = (index / width + 1) * stride + index % width + 1;
        source[padded] = index as u32;
        queue.push(padded as u32);
    }
    if queue.is_empty() {
        return TexelSources(Vec::new());
    }
    // Breadth-first from every covered texel at once, neighbours in the order left, right, up,
    // down: each uncovered texel takes the source of the texel that reached it first.
    let mut next = 0;
    while let Some(&cell) = queue.get(next) {
        next += 1;
        let cell = cell as usize;
        let from = source[cell];
        for neighbour in [cell - 1, cell + 1, cell - stride, cell + stride] {
            if source[neighbour] == UNREACHED {
                source[neighbour] = from;
                queue.push(neighbour as u32);
            }
        }
    }
    TexelSources(
        (0..height)
            .flat_map(|row| source[(row + 1) * stride + 1..(row + 1) * stride + 1 + width].iter().copied())
            .collect(),
    )
}

/// The fill itself: every texel of a `width`-wide RGBA8 image takes the values of the texel
/// `sources` names in `drawn` (rows in parallel); with `clear_filled_alpha`, texels that are not
/// their own source get alpha 0 (nothing is drawn there).
pub fn fill_from_sources(drawn: &[u8], width: u32, sources: &TexelSources, clear_filled_alpha: bool) -> Vec<u8> {
    let mut pixels = vec![0u8; drawn.len()];
    let row = width as usize * 4;
    pixels.par_chunks_mut(row.max(4)).enumerate().for_each(|(y, row_pixels)| {
        let first = y * width as usize;
        for (x, texel) in row_pixels.chunks_exact_mut(4).enumerate() {
            let from = sources.0[first + x] as usize;
            texel.copy_from_slice(&drawn[from * 4..][..4]);
            if clear_filled_alpha && from != first + x {
                texel[3] = 0;
            }
        }
    });
    pixels
}

/// The fill of a one-value-per-texel image (a bake's 16-bit values): every texel takes the
/// value of the texel `sources` names.
pub fn fill_values<T: Copy + Send + Sync>(drawn: &[T], sources: &TexelSources) -> Vec<T> {
    sources.0.par_iter().map(|&source| drawn[source as usize]).collect()
}
