//! BC4 blocks (one channel; BC5 is two of them) encoded near the best the format allows, judged
//! as a GPU decodes them: the D3D specification's float palette (entries interpolated in float,
//! not rounded to 8 bits), scored exactly in integers scaled by 35 (every entry of both modes is
//! a whole number of 35ths). Both modes: eight interpolated values when `e0 > e1`; six and the
//! constants 0 and 255 when `e0 <= e1`.
//!
//! The search: seeds (the block's range and its least-squares ends, the six-value mode's near 0
//! and 255, palettes on a whole-number grid anchored at either end, the range spanning only some
//! entries so that clusters take every other one, each of those refined by least squares; and at
//! `Slow` a coarse grid over ends within half the range of the block's), scored one pair per
//! 256-bit vector of the 16 values (AVX2 where the CPU has it, the same sums without), then a
//! pattern search from the best (moves of halving steps on either end or both, and the
//! least-squares ends of each step's assignment). `Exhaustive` scores every pair, pruned by a
//! bound: the true optimum, for references and tests. Pure: 16 values in, 8 bytes out.

use crate::format::EncodeQuality;

/// How hard a block is searched.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Bc4Search {
    /// The range's ends and the grid palettes, no pattern search.
    Quick,
    /// Every seed but the coarse grid, then a pattern search of steps 4, 2, 1 from the best and
    /// from the other mode's best when that is close.
    Basic,
    /// Every seed with the coarse grid, then a pattern search of steps 16 to 1 from the best of
    /// each mode.
    Slow,
    /// Every endpoint pair of both modes: the true optimum.
    Exhaustive,
}

impl Bc4Search {
    /// The search for an encoder quality setting.
    pub fn for_quality(quality: EncodeQuality) -> Bc4Search {
        match quality {
            EncodeQuality::UltraFast | EncodeQuality::VeryFast | EncodeQuality::Fast => Bc4Search::Quick,
            EncodeQuality::Basic => Bc4Search::Basic,
            EncodeQuality::Slow => Bc4Search::Slow,
            EncodeQuality::Exhaustive => Bc4Search::Exhaustive,
        }
    }
}

/// What block errors are scaled by: the float palette's entries are whole numbers of 35ths, so
/// 35² × the squared error is a whole number.
pub const BC4_ERROR_SCALE: u32 = 35 * 35;

/// The palette of `e0`, `e1` in index order, as the D3D specification interpolates it (in
/// float), times 35.
#[inline(always)]
fn palette35(e0: u8, e1: u8) -> [i32; 8] {
    let (a, b) = (e0 as i32, e1 as i32);
    if a > b {
        let mix = |k: i32| 5 * ((7 - k) * a + k * b);
        [mix(0), mix(7), mix(1), mix(2), mix(3), mix(4), mix(5), mix(6)]
    } else {
        let mix = |k: i32| 7 * ((5 - k) * a + k * b);
        [mix(0), mix(5), mix(1), mix(2), mix(3), mix(4), 0, 255 * 35]
    }
}

/// The eight values a block with endpoints `e0`, `e1` decodes to on a GPU (in index order).
pub fn bc4_float_palette(e0: u8, e1: u8) -> [f32; 8] {
    palette35(e0, e1).map(|entry| entry as f32 / 35.0)
}

/// The block's bytes: endpoints, then each value's nearest palette index (3 bits each).
fn block_bytes(values: &[u8; 16], e0: u8, e1: u8) -> [u8; 8] {
    let palette = palette35(e0, e1);
    // Each value's first nearest entry, entry by entry over all 16 lanes (one vector pass).
    let (mut nearest, mut distance) = ([0u8; 16], [i32::MAX; 16]);
    for (index, &entry) in palette.iter().enumerate() {
        for lane in 0..16 {
            let difference = (values[lane] as i32 * 35 - entry).abs();
            if difference < distance[lane] {
                (distance[lane], nearest[lane]) = (difference, index as u8);
            }
        }
    }
    let indices = nearest.iter().enumerate().fold(0u64, |bits, (texel, &index)| bits | (index as u64) << (3 * texel));
    let mut bytes = [0u8; 8];
    bytes[0] = e0;
    bytes[1] = e1;
    bytes[2..8].copy_from_slice(&indices.to_le_bytes()[..6]);
    bytes
}

/// The ends (high, low), rounded, that fit `values` best in the least-squares sense for the
/// entries they take under `e0`, `e1` (the six-value mode's constants 0 and 255 left out); none
/// when the values all take one entry. The sums are whole numbers (entry numbers `k` and values),
/// so they are exact, and the loop is one vector pass where the CPU has them.
#[inline(always)]
fn least_squares_ends(values: &[u8; 16], e0: u8, e1: u8) -> Option<(i32, i32)> {
    let eight = e0 > e1;
    let (low, high) = (e0.min(e1) as i32, e0.max(e1) as i32);
    if high <= low {
        return None;
    }
    let steps = if eight { 7 } else { 5 };
    let (range, scale) = (high - low, steps as f32 / (high - low) as f32);
    // Sums over the values on interpolated entries, entry k at low + k range / steps.
    let (mut count, mut sum_k, mut sum_kk, mut sum_v, mut sum_vk) = (0i32, 0i32, 0i32, 0i32, 0i32);
    for &value in values {
        let value = value as i32;
        let k = (((value - low) as f32 * scale).round() as i32).clamp(0, steps);
        // In the six-value mode a value nearer 0 or 255 than its entry takes the constant
        // (compared in steps-ths, exactly).
        let kept = i32::from(eight || steps * value.min(255 - value) >= (steps * (value - low) - k * range).abs());
        (count, sum_k, sum_kk) = (count + kept, sum_k + kept * k, sum_kk + kept * k * k);
        (sum_v, sum_vk) = (sum_v + kept * value, sum_vk + kept * value * k);
    }
    let spread = count * sum_kk - sum_k * sum_k;
    if spread == 0 {
        return None;
    }
    let slope = (steps * (count * sum_vk - sum_k * sum_v)) as f32 / spread as f32;
    let low = (sum_v as f32 - slope * sum_k as f32 / steps as f32) / count as f32;
    Some(((low + slope).round() as i32, low.round() as i32))
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

/// The best endpoints found and their error (× [`BC4_ERROR_SCALE`]).
#[derive(Clone, Copy)]
struct Candidate {
    e0: u8,
    e1: u8,
    error: u32,
}

/// Room for every seed of `Slow` (its coarse grid is at most 2 × 9² pairs).
const MAX_CANDIDATES: usize = 256;

/// Candidate endpoint pairs of one block (on the stack).
struct Candidates {
    pairs: [(u8, u8); MAX_CANDIDATES],
    count: usize,
}

impl Candidates {
    fn new() -> Candidates {
        Candidates { pairs: [(0, 0); MAX_CANDIDATES], count: 0 }
    }

    fn as_slice(&self) -> &[(u8, u8)] {
        &self.pairs[..self.count]
    }

    /// Adds the pair with ends `high` and `low` in the eight- or six-value mode, when valid.
    #[inline(always)]
    fn add(&mut self, high: i32, low: i32, eight: bool) {
        let Some(pair) = endpoint_pair(high, low, eight).filter(|_| self.count < MAX_CANDIDATES) else { return };
        self.pairs[self.count] = pair;
        self.count += 1;
    }

    /// Drops the pairs `seen` holds (adding the others to it), keeping their order.
    #[inline(always)]
    fn retain_unseen(&mut self, seen: &mut SeenPairs) {
        let mut kept = 0;
        for index in 0..self.count {
            let pair = self.pairs[index];
            if seen.insert(pair) {
                self.pairs[kept] = pair;
                kept += 1;
            }
        }
        self.count = kept;
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

/// The pairs one pattern search has scored: an open-addressed set of `e0 << 8 | e1` (a search
/// scores well under a hundred).
struct SeenPairs {
    slots: [u16; 256],
    filled: [bool; 256],
}

impl SeenPairs {
    fn new() -> SeenPairs {
        SeenPairs { slots: [0; 256], filled: [false; 256] }
    }

    /// Adds the pair; false when it was there already (or the set is full: then it is scored).
    #[inline(always)]
    fn insert(&mut self, (e0, e1): (u8, u8)) -> bool {
        let key = (e0 as u16) << 8 | e1 as u16;
        let mut slot = (key.wrapping_mul(0x9E37) >> 8) as usize;
        for _ in 0..256 {
            if !self.filled[slot] {
                (self.slots[slot], self.filled[slot]) = (key, true);
                return true;
            }
            if self.slots[slot] == key {
                return false;
            }
            slot = (slot + 1) & 255;
        }
        true
    }
}

/// One pair's error on the block's values (times 35, 16-bit lanes), without vector intrinsics.
#[inline(always)]
fn pair_error(values: &[i16; 16], e0: u8, e1: u8) -> u32 {
    let palette = palette35(e0, e1);
    let mut nearest = [u16::MAX; 16];
    for &entry in &palette {
        for lane in 0..16 {
            nearest[lane] = nearest[lane].min(values[lane].abs_diff(entry as i16));
        }
    }
    nearest.iter().map(|&difference| difference as u32 * difference as u32).sum()
}

/// Keeps in `best` the best of `pairs`, one pair per vector of the 16 values.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn score_avx2(values: &[i16; 16], pairs: &[(u8, u8)], best: &mut Candidate) {
    use std::arch::x86_64::*;
    // Safety: the caller checked the CPU has AVX2; 16 × i16 is one 256-bit load.
    let lanes = _mm256_loadu_si256(values.as_ptr() as *const __m256i);
    for &(e0, e1) in pairs {
        let palette = palette35(e0, e1);
        let mut nearest = _mm256_abs_epi16(_mm256_sub_epi16(lanes, _mm256_set1_epi16(palette[0] as i16)));
        for &entry in &palette[1..] {
            let difference = _mm256_abs_epi16(_mm256_sub_epi16(lanes, _mm256_set1_epi16(entry as i16)));
            nearest = _mm256_min_epu16(nearest, difference);
        }
        // Differences are at most 255 × 35, so two squares fit an i32.
        let squares = _mm256_madd_epi16(nearest, nearest);
        let four = _mm_add_epi32(_mm256_castsi256_si128(squares), _mm256_extracti128_si256(squares, 1));
        let two = _mm_add_epi32(four, _mm_shuffle_epi32(four, 0b01_00_11_10));
        let one = _mm_add_epi32(two, _mm_shuffle_epi32(two, 0b10_11_00_01));
        let error = _mm_cvtsi128_si32(one) as u32;
        if error < best.error {
            *best = Candidate { e0, e1, error };
        }
    }
}

/// Keeps in `best[0]` the best eight-value pair of `pairs` and in `best[1]` the best six-value
/// one (the first of equals), and in `found_at` where in the seed list each was found (`pairs`
/// starts at seed `offset`).
#[inline(always)]
fn score_by_mode<const AVX2: bool>(
    values: &[i16; 16],
    (pairs, offset): (&[(u8, u8)], usize),
    best: &mut [Candidate; 2],
    found_at: &mut [usize; 2],
) {
    for (index, &(e0, e1)) in pairs.iter().enumerate() {
        let mode = usize::from(e0 <= e1);
        let before = best[mode].error;
        score::<AVX2>(values, &[(e0, e1)], &mut best[mode]);
        if best[mode].error < before {
            found_at[mode] = offset + index;
        }
    }
}

/// The best seed of each mode so far (eight-value first) and where in the seed list each was
/// found, the seeds scored as they come.
struct SeedScores {
    modes: [Candidate; 2],
    found_at: [usize; 2],
    scored: usize,
}

impl SeedScores {
    fn new(max: u8, min: u8) -> SeedScores {
        let modes = [Candidate { e0: max, e1: min, error: u32::MAX }, Candidate { e0: 0, e1: 0, error: u32::MAX }];
        SeedScores { modes, found_at: [usize::MAX; 2], scored: 0 }
    }

    /// Scores the seeds added since the last call; the best so far when it is exact.
    #[inline(always)]
    fn score_new<const AVX2: bool>(&mut self, values: &[i16; 16], seeds: &Candidates) -> Option<Candidate> {
        let new = (&seeds.as_slice()[self.scored..], self.scored);
        score_by_mode::<AVX2>(values, new, &mut self.modes, &mut self.found_at);
        self.scored = seeds.count;
        Some(self.best()).filter(|best| best.error == 0)
    }

    /// The first of equals in seed order, as one scoring of every seed would keep.
    fn best(&self) -> Candidate {
        let six_first = (self.modes[1].error, self.found_at[1]) < (self.modes[0].error, self.found_at[0]);
        self.modes[usize::from(six_first)]
    }
}

/// Keeps in `best` the best of `pairs` (the first of equals, on every path).
#[inline(always)]
fn score<const AVX2: bool>(values: &[i16; 16], pairs: &[(u8, u8)], best: &mut Candidate) {
    #[cfg(target_arch = "x86_64")]
    if AVX2 {
        // Safety: `AVX2` is set only where the CPU has it (see `encode_bc4_block`).
        return unsafe { score_avx2(values, pairs, best) };
    }
    for &(e0, e1) in pairs {
        let error = pair_error(values, e0, e1);
        if error < best.error {
            *best = Candidate { e0, e1, error };
        }
    }
}

/// Encodes one block of 16 values (rows top to bottom) with `search` (see the module's text).
pub fn encode_bc4_block(values: &[u8; 16], search: Bc4Search) -> [u8; 8] {
    #[cfg(target_arch = "x86_64")]
    if base::isa::avx2_allowed() {
        // Safety: the CPU has AVX2.
        return unsafe { encode_avx2(values, search) };
    }
    encode_block::<false>(values, search)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn encode_avx2(values: &[u8; 16], search: Bc4Search) -> [u8; 8] {
    encode_block::<true>(values, search)
}

/// Within this of 0 or 255, a block is also seeded in the six-value mode (at `Slow`, always).
const EXTREME: u8 = 24;

// Long: the seeds of each search level, then the pattern search, in the order the module's
// text gives them; split, each part would take most of the same block state as arguments.
#[inline(always)]
fn encode_block<const AVX2: bool>(values: &[u8; 16], search: Bc4Search) -> [u8; 8] {
    let (min, max) = values.iter().fold((255u8, 0u8), |(low, high), &value| (low.min(value), high.max(value)));
    if min == max {
        return block_bytes(values, min, min);
    }
    let lanes: [i16; 16] = values.map(|value| value as i16 * 35);
    if search == Bc4Search::Exhaustive {
        let best = optimum::<AVX2>(&lanes);
        return block_bytes(values, best.e0, best.e1);
    }
    let (quick, slow) = (search == Bc4Search::Quick, search == Bc4Search::Slow);
    let range = (max - min) as i32;
    let mut seeds = Candidates::new();
    seeds.add_window(max as i32, min as i32, if quick { 0 } else { 1 }, true);
    // Palettes on a whole-number grid (a step of 1, 2, … between entries) anchored at either end:
    // exact for blocks of a few distinct values, which the float palette does not round.
    for (steps, eight) in [(7, true), (5, false)] {
        for step in [(range / steps).max(1), (range + steps - 1) / steps] {
            seeds.add(min as i32 + steps * step, min as i32, eight);
            seeds.add(max as i32, max as i32 - steps * step, eight);
        }
    }
    let mut scoring = SeedScores::new(max, min);
    // A block the first seeds fit exactly (two values, or a few on a whole-number grid: most of
    // an atlas's fill) keeps the first exact one: no later seed or step is strictly better, so
    // the result is the one the whole search gives.
    if let Some(exact) = scoring.score_new::<AVX2>(&lanes, &seeds).filter(|_| !quick) {
        return block_bytes(values, exact.e0, exact.e1);
    }
    if !quick {
        if let Some((high, low)) = least_squares_ends(values, max, min) {
            seeds.add_window(high, low, 1, true);
        }
        if slow || min <= EXTREME || max >= 255 - EXTREME {
            let inner = values
                .iter()
                .filter(|&&value| value != 0 && value != 255)
                .fold((255u8, 0u8), |(low, high), &value| (low.min(value), high.max(value)));
            if inner.0 <= inner.1 {
                seeds.add_window(inner.1 as i32, inner.0 as i32, 1, false);
                if let Some((high, low)) = least_squares_ends(values, inner.0, inner.1) {
                    seeds.add_window(high, low, 1, false);
                }
            }
        }
        if let Some(exact) = scoring.score_new::<AVX2>(&lanes, &seeds) {
            return block_bytes(values, exact.e0, exact.e1);
        }
        // The range spanning entries `first` to `first + span` only (a block of a few clusters
        // fits every other entry better than all of them), each refined by least squares.
        for (steps, eight, shortest) in [(7, true, 4), (5, false, 3)] {
            for span in shortest..steps {
                for first in 0..=steps - span {
                    let low = min as i32 - (2 * first * range + span) / (2 * span);
                    let high = min as i32 + (2 * (steps - first) * range + span) / (2 * span);
                    let Some((e0, e1)) = endpoint_pair(high, low, eight) else { continue };
                    seeds.add(high, low, eight);
                    if let Some((high, low)) = least_squares_ends(values, e0, e1) {
                        seeds.add(high, low, eight);
                    }
                }
            }
        }
    }
    if slow {
        // A coarse grid over ends within half the range (and 8) of the block's.
        let reach = range / 2 + 8;
        let step = (reach / 3).max(1);
        for eight in [true, false] {
            for high in (max as i32 - reach..=max as i32 + reach).step_by(step as usize) {
                for low in (min as i32 - reach..=min as i32 + reach).step_by(step as usize) {
                    seeds.add(high, low, eight);
                }
            }
        }
    }
    scoring.score_new::<AVX2>(&lanes, &seeds);
    let (modes, mut best) = (scoring.modes, scoring.best());
    if quick {
        return block_bytes(values, best.e0, best.e1);
    }
    // The pattern search starts from the best seed and from the best of the other mode (at
    // `Basic`, only when it is within twice the best's error: a local search from a far one
    // rarely wins). On the corpus the second start takes the worst channel from 0.66 dB under
    // the optimum to 0.17.
    let other = modes[usize::from(best.e0 > best.e1)];
    let close = slow || (other.error as u64) < 2 * best.error as u64;
    let starts = [Some(best), (other.error < u32::MAX && close).then_some(other)];
    let mut near = Candidates::new();
    let steps: &[i32] = if slow { &[16, 8, 4, 2, 1] } else { &[4, 2, 1] };
    for mut at in starts.into_iter().flatten() {
        let eight = at.e0 > at.e1;
        // A pair scored before in this start's search is no better than `at`: not scored again.
        let mut seen = SeenPairs::new();
        seen.insert((at.e0, at.e1));
        for &step in steps {
            for _ in 0..8 {
                let before = at.error;
                if before == 0 {
                    break;
                }
                let (high, low) = if eight { (at.e0 as i32, at.e1 as i32) } else { (at.e1 as i32, at.e0 as i32) };
                near.count = 0;
                for (high_move, low_move) in [(1, 0), (-1, 0), (0, 1), (0, -1), (1, 1), (-1, -1), (1, -1), (-1, 1)] {
                    near.add(high + high_move * step, low + low_move * step, eight);
                }
                if let Some((high, low)) = least_squares_ends(values, at.e0, at.e1) {
                    near.add(high, low, eight);
                }
                near.retain_unseen(&mut seen);
                score::<AVX2>(&lanes, near.as_slice(), &mut at);
                if at.error >= before {
                    break;
                }
            }
        }
        if at.error < best.error {
            best = at;
        }
    }
    block_bytes(values, best.e0, best.e1)
}

/// The best of every endpoint pair of both modes; a pair whose range leaves values farther from
/// it than the best error so far is not scored.
#[inline(always)]
fn optimum<const AVX2: bool>(lanes: &[i16; 16]) -> Candidate {
    let mut best = Candidate { e0: 0, e1: 0, error: u32::MAX };
    let mut batch = Candidates::new();
    for e0 in 0..=255u8 {
        for e1 in 0..=255u8 {
            let (low, high, six) = (e0.min(e1) as i32 * 35, e0.max(e1) as i32 * 35, e0 <= e1);
            let mut bound = 0u32;
            for &value in lanes {
                let value = value as i32;
                let outside = if value < low {
                    low - value
                } else if value > high {
                    value - high
                } else {
                    0
                };
                // The six-value mode also has 0 and 255.
                let outside = if six { outside.min(value).min(255 * 35 - value) } else { outside };
                bound += (outside * outside) as u32;
            }
            if bound >= best.error {
                continue;
            }
            batch.pairs[batch.count] = (e0, e1);
            batch.count += 1;
            if batch.count == MAX_CANDIDATES {
                score::<AVX2>(lanes, batch.as_slice(), &mut best);
                batch.count = 0;
            }
        }
    }
    score::<AVX2>(lanes, batch.as_slice(), &mut best);
    best
}

/// The smallest error (× [`BC4_ERROR_SCALE`], float palette) of any endpoint pair of either
/// mode: the true optimum the encoder is measured against (slow: about a millisecond a block).
pub fn bc4_optimum(values: &[u8; 16]) -> u32 {
    bc4_block_error(values, &encode_bc4_block(values, Bc4Search::Exhaustive))
}

/// The 16 values (rows top to bottom) a GPU decodes `bytes` to, × 35.
pub fn bc4_decode_scaled(bytes: &[u8; 8]) -> [i32; 16] {
    let palette = palette35(bytes[0], bytes[1]);
    let indices = u64::from_le_bytes([bytes[2], bytes[3], bytes[4], bytes[5], bytes[6], bytes[7], 0, 0]);
    std::array::from_fn(|texel| palette[(indices >> (3 * texel) & 7) as usize])
}

/// The squared error of a block's values under encoded `bytes`, decoded with the float palette
/// as a GPU decodes it, × [`BC4_ERROR_SCALE`].
pub fn bc4_block_error(values: &[u8; 16], bytes: &[u8; 8]) -> u32 {
    let decoded = bc4_decode_scaled(bytes);
    values.iter().zip(decoded).map(|(&value, decoded)| (value as i32 * 35 - decoded).pow(2) as u32).sum()
}
