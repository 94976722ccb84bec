//! BC4 blocks (one channel; BC5 is two of them) encoded close to the best the format allows:
//! both modes (eight interpolated values when `e0 > e1`; six and the constants 0 and 255 when
//! `e0 <= e1`, tried where a block reaches near 0 or 255). One batch of candidate endpoint
//! pairs (a window around the block's range, and next to the least-squares ends of the palette
//! entries its values take) is scored 32 at a time in byte lanes (AVX2 where the CPU has it),
//! then pairs next to the least-squares ends of the best one's entries while that finds better;
//! every candidate is scored with the decoder's own integer palette (`bcdec`'s), so the error
//! the search sees is the error the texture has. The windowed exhaustive optimum it is measured
//! against is here too. Pure: 16 values in, 8 bytes out.

/// How hard a block is searched: the window of endpoints tried around the block's range
/// (± values) and whether the best is refined by least-squares rounds afterwards.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Bc4Search {
    pub window: i32,
    pub refine: bool,
}

impl Bc4Search {
    /// The search for an encoder quality setting.
    pub fn for_quality(quality: crate::texture::format::EncodeQuality) -> Bc4Search {
        use crate::texture::format::EncodeQuality;
        match quality {
            EncodeQuality::UltraFast | EncodeQuality::VeryFast => Bc4Search { window: 0, refine: false },
            EncodeQuality::Fast => Bc4Search { window: 1, refine: false },
            EncodeQuality::Basic => Bc4Search { window: 1, refine: true },
            EncodeQuality::Slow => Bc4Search { window: 3, refine: true },
        }
    }
}

/// The eight values a block with endpoints `e0`, `e1` decodes to, as `bcdec` computes them
/// (16-bit fixed-point weights, rounded).
pub(crate) fn bc4_palette(e0: u8, e1: u8) -> [u8; 8] {
    let (a, b) = (e0 as u32, e1 as u32);
    let mix = |wa: u32, wb: u32| ((wa * a + wb * b + 32768) >> 16) as u8;
    if a > b {
        let w = [9363, 18724, 28086, 37450, 46812, 56173];
        [e0, e1, mix(w[5], w[0]), mix(w[4], w[1]), mix(w[3], w[2]), mix(w[2], w[3]), mix(w[1], w[4]), mix(w[0], w[5])]
    } else {
        let w = [13107, 26215, 39321, 52429];
        [e0, e1, mix(w[3], w[0]), mix(w[2], w[1]), mix(w[1], w[2]), mix(w[0], w[3]), 0, 255]
    }
}

/// The palette of `e0`, `e1` in ascending order.
#[inline(always)]
fn ascending_palette(e0: u8, e1: u8) -> [i32; 8] {
    let p = bc4_palette(e0, e1).map(|value| value as i32);
    if e0 > e1 {
        [p[1], p[7], p[6], p[5], p[4], p[3], p[2], p[0]]
    } else {
        [p[6], p[0], p[2], p[3], p[4], p[5], p[1], p[7]]
    }
}

/// The block's bytes: endpoints, then each value's nearest palette index (3 bits each).
fn block_bytes(values: &[u8; 16], e0: u8, e1: u8) -> [u8; 8] {
    let palette = bc4_palette(e0, e1);
    let mut indices = 0u64;
    for (texel, &value) in values.iter().enumerate() {
        let nearest = (0..8)
            .min_by_key(|&index| {
                let difference = value as i32 - palette[index] as i32;
                difference * difference
            })
            .expect("eight entries");
        indices |= (nearest as u64) << (3 * texel);
    }
    let mut bytes = [0u8; 8];
    bytes[0] = e0;
    bytes[1] = e1;
    bytes[2..8].copy_from_slice(&indices.to_le_bytes()[..6]);
    bytes
}

/// The endpoints that fit `sorted` best in the least-squares sense for the palette entries its
/// values take under `e0`, `e1` (each interpolated entry a fixed mix of the two ends; the six-value
/// mode's constants 0 and 255 left out), as (high end, low end), rounded; none when the values
/// all take one entry.
fn least_squares_ends(sorted: &[u8; 16], e0: u8, e1: u8) -> Option<(i32, i32)> {
    let eight = e0 > e1;
    let palette = ascending_palette(e0, e1);
    // The weight of e0 in each entry of the ascending palette (negative: a constant).
    let weights: [f32; 8] = if eight {
        [0.0, 1.0 / 7.0, 2.0 / 7.0, 3.0 / 7.0, 4.0 / 7.0, 5.0 / 7.0, 6.0 / 7.0, 1.0]
    } else {
        [-1.0, 1.0, 0.8, 0.6, 0.4, 0.2, 0.0, -1.0]
    };
    let (mut aa, mut ab, mut bb, mut av, mut bv) = (0.0f32, 0.0f32, 0.0f32, 0.0f32, 0.0f32);
    let mut entry = 0;
    for &value in sorted {
        let value_i = value as i32;
        while entry < 7 && palette[entry] + palette[entry + 1] <= 2 * value_i {
            entry += 1;
        }
        let w = weights[entry];
        if w < 0.0 {
            continue;
        }
        let (a, b, v) = (w, 1.0 - w, value as f32);
        aa += a * a;
        ab += a * b;
        bb += b * b;
        av += a * v;
        bv += b * v;
    }
    let determinant = aa * bb - ab * ab;
    if determinant.abs() < 1e-6 {
        return None;
    }
    let e0_fit = (av * bb - bv * ab) / determinant;
    let e1_fit = (bv * aa - av * ab) / determinant;
    let (e0_fit, e1_fit) = (e0_fit.round() as i32, e1_fit.round() as i32);
    Some(if eight { (e0_fit, e1_fit) } else { (e1_fit, e0_fit) })
}

/// Within this of 0 or 255, a block is also tried in the six-value mode.
const EXTREME: u8 = 24;

/// The best endpoints found and their error.
#[derive(Clone, Copy)]
struct Candidate {
    e0: u8,
    e1: u8,
    error: u32,
}

/// The bytes `e0`, `e1` of ends `high` and `low` in the eight-value (`e0 > e1`) or six-value
/// (`e0 <= e1`) mode; none when they are out of range or cannot be in that mode.
fn endpoint_pair(high: i32, low: i32, eight: bool) -> Option<(u8, u8)> {
    if !(0..=255).contains(&high) || !(0..=255).contains(&low) {
        return None;
    }
    match eight {
        true if high > low => Some((high as u8, low as u8)),
        false if low <= high => Some((low as u8, high as u8)),
        _ => None,
    }
}

/// Candidate endpoint pairs of one block, scored 32 at a time.
struct Candidates {
    pairs: [(u8, u8); MAX_CANDIDATES],
    count: usize,
}

const MAX_CANDIDATES: usize = 96;

impl Candidates {
    fn new() -> Candidates {
        Candidates { pairs: [(0, 0); MAX_CANDIDATES], count: 0 }
    }

    /// Adds the pair with ends `high` and `low` in the eight-value (`e0 > e1`) or six-value
    /// (`e0 <= e1`) mode, when it is a valid one.
    fn add(&mut self, high: i32, low: i32, eight: bool) {
        let Some(pair) = endpoint_pair(high, low, eight).filter(|_| self.count < MAX_CANDIDATES) else { return };
        self.pairs[self.count] = pair;
        self.count += 1;
    }

    /// Every pair within `window` of the ends `high`, `low`.
    fn add_window(&mut self, high: i32, low: i32, window: i32, eight: bool) {
        for high in high - window..=high + window {
            for low in low - window..=low + window {
                self.add(high, low, eight);
            }
        }
    }
}

/// Every pair's palette (512 KiB, made once).
fn palette_table() -> &'static [[u8; 8]] {
    static TABLE: std::sync::OnceLock<Vec<[u8; 8]>> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| (0..65536u32).map(|pair| bc4_palette((pair >> 8) as u8, pair as u8)).collect())
}

/// Candidates scored at once: one byte lane each.
const LANES: usize = 32;

/// The errors of up to 32 candidate pairs on a block's values: per value, the nearest entry of
/// each lane's palette by absolute difference (bytes: 32 lanes to a 256-bit vector), squared
/// and summed. Written lane-wise so that it vectorises (AVX2 where the CPU has it: see
/// `best_candidate`).
#[inline(always)]
fn errors_of_lanes(values: &[u8; 16], pairs: &[(u8, u8)]) -> [u32; LANES] {
    let table = palette_table();
    let mut palettes = [[0u8; LANES]; 8];
    for (lane, &(e0, e1)) in pairs.iter().enumerate().take(LANES) {
        let palette = table[(e0 as usize) << 8 | e1 as usize];
        for entry in 0..8 {
            palettes[entry][lane] = palette[entry];
        }
    }
    let mut totals = [0u32; LANES];
    for &value in values {
        let mut nearest = [u8::MAX; LANES];
        for palette in &palettes {
            for lane in 0..LANES {
                nearest[lane] = nearest[lane].min(value.abs_diff(palette[lane]));
            }
        }
        for lane in 0..LANES {
            let difference = nearest[lane] as u32;
            totals[lane] += difference * difference;
        }
    }
    totals
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn best_candidate_avx2(values: &[u8; 16], candidates: &Candidates, best: &mut Candidate) {
    best_candidate_with(values, candidates, best)
}

/// Keeps in `best` the best of `candidates`.
#[inline(always)]
fn best_candidate_with(values: &[u8; 16], candidates: &Candidates, best: &mut Candidate) {
    for chunk in candidates.pairs[..candidates.count].chunks(LANES) {
        let errors = errors_of_lanes(values, chunk);
        for (lane, &(e0, e1)) in chunk.iter().enumerate() {
            if errors[lane] < best.error {
                *best = Candidate { e0, e1, error: errors[lane] };
            }
        }
    }
}

fn best_candidate(values: &[u8; 16], candidates: &Candidates, best: &mut Candidate) {
    #[cfg(target_arch = "x86_64")]
    if crate::isa::avx2_allowed() {
        // Safety: the CPU has AVX2.
        return unsafe { best_candidate_avx2(values, candidates, best) };
    }
    best_candidate_with(values, candidates, best)
}

/// Encodes one block of 16 values (rows top to bottom): the pairs within `search.window` of the
/// block's range (and, where the block reaches near 0 or 255, of its range without those in the
/// six-value mode), then the pairs next to the least-squares ends of the best one's entries,
/// while that finds better.
pub fn encode_bc4_block(values: &[u8; 16], search: Bc4Search) -> [u8; 8] {
    let mut sorted = *values;
    sorted.sort_unstable();
    let (min, max) = (sorted[0], sorted[15]);
    if min == max {
        return block_bytes(values, min, min);
    }
    let mut best = Candidate { e0: max, e1: min, error: u32::MAX };
    // One batch: the window around the range, and next to the least-squares ends of the
    // entries the values take under it; the same in the six-value mode near 0 or 255.
    let mut candidates = Candidates::new();
    candidates.add_window(max as i32, min as i32, search.window, true);
    if let Some((high, low)) = least_squares_ends(&sorted, max, min) {
        candidates.add_window(high, low, 1, true);
    }
    if min <= EXTREME || max >= 255 - EXTREME {
        let inner = sorted
            .iter()
            .filter(|&&value| value != 0 && value != 255)
            .fold((255u8, 0u8), |(low, high), &value| (low.min(value), high.max(value)));
        if inner.0 <= inner.1 {
            candidates.add_window(inner.1 as i32, inner.0 as i32, search.window, false);
            if let Some((high, low)) = least_squares_ends(&sorted, inner.0, inner.1) {
                candidates.add_window(high, low, 1, false);
            }
        }
    }
    best_candidate(values, &candidates, &mut best);
    // Then next to the least-squares ends of the best pair's entries, while that finds better.
    for _ in 0..if search.refine { 2 } else { 0 } {
        let before = best.error;
        let eight = best.e0 > best.e1;
        let Some((high, low)) = least_squares_ends(&sorted, best.e0, best.e1) else { break };
        let mut near = Candidates::new();
        near.add_window(high, low, 1, eight);
        best_candidate(values, &near, &mut best);
        if best.error >= before || best.error == 0 {
            break;
        }
    }
    block_bytes(values, best.e0, best.e1)
}

/// The smallest summed squared error of any endpoint pair of either mode whose ends lie within
/// `window` of the block's range (or of its range without 0 and 255): the reference the encoder
/// is measured against (slow: every pair of the window).
pub fn bc4_windowed_optimum(values: &[u8; 16], window: i32) -> u32 {
    let (min, max) = values.iter().fold((255u8, 0u8), |(min, max), &value| (min.min(value), max.max(value)));
    let inner = values
        .iter()
        .filter(|&&value| value != 0 && value != 255)
        .fold((255u8, 0u8), |(low, high), &value| (low.min(value), high.max(value)));
    let mut best = Candidate { e0: min, e1: max, error: u32::MAX };
    let mut batch = Candidates::new();
    for (high_start, low_start) in [(max as i32, min as i32), (inner.1 as i32, inner.0 as i32)] {
        for high in high_start - window..=high_start + window {
            for low in low_start - window..=low_start + window {
                if batch.count + 2 > MAX_CANDIDATES {
                    best_candidate(values, &batch, &mut best);
                    batch = Candidates::new();
                }
                batch.add(high, low, true);
                batch.add(high, low, false);
            }
        }
    }
    best_candidate(values, &batch, &mut best);
    best.error
}

/// The summed squared error of a block's values under encoded `bytes` (decoded as `bcdec`
/// does).
pub fn bc4_block_error(values: &[u8; 16], bytes: &[u8; 8]) -> u32 {
    let palette = bc4_palette(bytes[0], bytes[1]);
    let mut indices = u64::from_le_bytes([bytes[2], bytes[3], bytes[4], bytes[5], bytes[6], bytes[7], 0, 0]);
    let mut total = 0;
    for &value in values {
        let difference = value as i32 - palette[(indices & 7) as usize] as i32;
        total += (difference * difference) as u32;
        indices >>= 3;
    }
    total
}
