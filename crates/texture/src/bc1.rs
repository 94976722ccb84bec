//! BC1 blocks refined after the ISPC encoder: from its endpoints, least-squares endpoints for the
//! palette entries the texels take (quantised to 5:6:5), then steps of one endpoint channel, or of
//! both ends' same channel together, while the error falls; four-colour mode only (the block stays
//! opaque). Every candidate is scored as a GPU decodes it: the D3D specification's float palette
//! (endpoints r/31, g/63, b/31, the two interpolated colours a third of the way in float, not
//! rounded to 8 bits as decoder libraries do). Pure: 16 RGB texels and a block in, a block as
//! good or better out.

/// The four colours of endpoints `c0 > c1` (5:6:5), as a GPU decodes them (0 to 255, float).
pub fn bc1_float_palette(c0: u16, c1: u16) -> [[f32; 3]; 4] {
    let expand = |c: u16| {
        let [r, g, b] = unpack(c);
        [r as f32 * (255.0 / 31.0), g as f32 * (255.0 / 63.0), b as f32 * (255.0 / 31.0)]
    };
    let (a, b) = (expand(c0), expand(c1));
    let third = |x: [f32; 3], y: [f32; 3]| std::array::from_fn(|channel| (2.0 * x[channel] + y[channel]) / 3.0);
    [a, b, third(a, b), third(b, a)]
}

/// The summed squared error of `texels` under endpoints `c0 > c1` (float palette), and each
/// texel's index.
fn error_and_indices(texels: &[[u8; 3]; 16], c0: u16, c1: u16) -> (f32, u32) {
    let colours = bc1_float_palette(c0, c1);
    let (mut total, mut indices) = (0f32, 0u32);
    for (texel, rgb) in texels.iter().enumerate() {
        let mut best = (f32::MAX, 0u32);
        for (index, colour) in colours.iter().enumerate() {
            let error: f32 = (0..3).map(|channel| (rgb[channel] as f32 - colour[channel]).powi(2)).sum();
            if error < best.0 {
                best = (error, index as u32);
            }
        }
        total += best.0;
        indices |= best.1 << (2 * texel);
    }
    (total, indices)
}

/// The four colours of an encoded block as a GPU decodes them (`c0 <= c1`: the three-colour
/// mode, whose fourth is black).
pub fn bc1_block_float_palette(block: &[u8; 8]) -> [[f32; 3]; 4] {
    let (c0, c1) = (u16::from_le_bytes([block[0], block[1]]), u16::from_le_bytes([block[2], block[3]]));
    let mut colours = bc1_float_palette(c0, c1);
    if c0 <= c1 {
        colours[2] = std::array::from_fn(|channel| (colours[0][channel] + colours[1][channel]) / 2.0);
        colours[3] = [0.0; 3];
    }
    colours
}

/// The summed squared error of `texels` under a BC1 block (float palette; `c0 <= c1` is the
/// three-colour mode: the two ends, their mean and black).
fn block_error(texels: &[[u8; 3]; 16], block: &[u8; 8]) -> f32 {
    let colours = bc1_block_float_palette(block);
    let indices = u32::from_le_bytes([block[4], block[5], block[6], block[7]]);
    texels
        .iter()
        .enumerate()
        .map(|(texel, rgb)| {
            let colour = colours[(indices >> (2 * texel) & 3) as usize];
            (0..3).map(|channel| (rgb[channel] as f32 - colour[channel]).powi(2)).sum::<f32>()
        })
        .sum()
}

fn pack(channels: [i32; 3]) -> u16 {
    ((channels[0].clamp(0, 31) as u16) << 11)
        | ((channels[1].clamp(0, 63) as u16) << 5)
        | channels[2].clamp(0, 31) as u16
}

fn unpack(c: u16) -> [i32; 3] {
    [(c as i32 >> 11) & 31, (c as i32 >> 5) & 63, c as i32 & 31]
}

/// Endpoints that fit the texels best in the least-squares sense for `indices`, quantised.
fn least_squares_ends(texels: &[[u8; 3]; 16], indices: u32) -> Option<(u16, u16)> {
    const WEIGHTS: [f32; 4] = [1.0, 0.0, 2.0 / 3.0, 1.0 / 3.0];
    let (mut aa, mut ab, mut bb) = (0.0f32, 0.0f32, 0.0f32);
    let (mut av, mut bv) = ([0.0f32; 3], [0.0f32; 3]);
    for (texel, rgb) in texels.iter().enumerate() {
        let w = WEIGHTS[(indices >> (2 * texel) & 3) as usize];
        let (a, b) = (w, 1.0 - w);
        aa += a * a;
        ab += a * b;
        bb += b * b;
        for channel in 0..3 {
            av[channel] += a * rgb[channel] as f32;
            bv[channel] += b * rgb[channel] as f32;
        }
    }
    let determinant = aa * bb - ab * ab;
    if determinant.abs() < 1e-6 {
        return None;
    }
    let scale = [31.0 / 255.0, 63.0 / 255.0, 31.0 / 255.0];
    let end = |first: &[f32; 3], second: &[f32; 3], first_weight: f32, cross: f32| -> [i32; 3] {
        std::array::from_fn(|channel| {
            ((first[channel] * first_weight - second[channel] * cross) / determinant * scale[channel]).round() as i32
        })
    };
    Some((pack(end(&av, &bv, bb, ab)), pack(end(&bv, &av, aa, ab))))
}

/// Orders endpoints for the four-colour mode (`c0 > c1`); equal ones cannot be.
fn four_colour(c0: u16, c1: u16) -> Option<(u16, u16)> {
    match c0.cmp(&c1) {
        std::cmp::Ordering::Greater => Some((c0, c1)),
        std::cmp::Ordering::Less => Some((c1, c0)),
        std::cmp::Ordering::Equal => None,
    }
}

/// The best four-colour endpoints of a block whose texels take one value in two channels: the
/// varying channel's ends searched within 8 steps of its quantised range, the constant channels
/// at their nearest 5:6:5 value on both ends (so all four colours share them, and only the
/// varying channel decides the indices); none for other blocks.
fn one_channel_fit(texels: &[[u8; 3]; 16]) -> Option<(f32, u32, (u16, u16))> {
    let constant = |channel: usize| texels.iter().all(|texel| texel[channel] == texels[0][channel]);
    let varying: Vec<usize> = (0..3).filter(|&channel| !constant(channel)).collect();
    let &[channel] = varying.as_slice() else { return None };
    let top = [31, 63, 31][channel];
    let scale = 255.0 / top as f32;
    let quantise = |value: u8| (value as f32 / scale).round() as i32;
    let values: [f32; 16] = texels.map(|texel| texel[channel] as f32);
    let (low, high) = values.iter().fold((f32::MAX, 0f32), |(low, high), &value| (low.min(value), high.max(value)));
    let (low, high) = (quantise(low as u8), quantise(high as u8));
    let mut best: Option<(f32, i32, i32)> = None;
    for high_end in (high - 8).max(1)..=(high + 8).min(top) {
        for low_end in (low - 8).max(0)..=(low + 8).min(high_end - 1) {
            // The varying channel's four levels, as the float palette interpolates them.
            let (a, b) = (high_end as f32 * scale, low_end as f32 * scale);
            let levels = [a, b, (2.0 * a + b) / 3.0, (a + 2.0 * b) / 3.0];
            let bound = best.map_or(f32::MAX, |(best_error, _, _)| best_error);
            let mut error = 0f32;
            for &value in &values {
                error += levels.iter().map(|&level| (value - level) * (value - level)).fold(f32::MAX, f32::min);
                if error >= bound {
                    break;
                }
            }
            if error < bound {
                best = Some((error, high_end, low_end));
            }
        }
    }
    let (_, high_end, low_end) = best?;
    let base: [i32; 3] = std::array::from_fn(|c| (texels[0][c] as f32 * [31.0, 63.0, 31.0][c] / 255.0).round() as i32);
    let (mut first, mut second) = (base, base);
    (first[channel], second[channel]) = (high_end, low_end);
    let (a, b) = four_colour(pack(first), pack(second))?;
    let (error, indices) = error_and_indices(texels, a, b);
    Some((error, indices, (a, b)))
}

/// The block refined from `start` (an encoded BC1 block of the same texels): never worse than
/// `start` under the float palette. A block in the three-colour mode is kept as it is, but for
/// one colour written in it (`c0 == c1`, as the ISPC encoder writes flat blocks): it is searched
/// in the four-colour mode too, where a step between two 5:6:5 colours lands nearer.
pub fn refine_bc1_block(texels: &[[u8; 3]; 16], start: [u8; 8]) -> [u8; 8] {
    let (c0, c1) = (u16::from_le_bytes([start[0], start[1]]), u16::from_le_bytes([start[2], start[3]]));
    if c0 < c1 {
        return start;
    }
    let start_error = block_error(texels, &start);
    let (mut error, mut indices) = if c0 > c1 { error_and_indices(texels, c0, c1) } else { (f32::MAX, 0) };
    let mut best = (c0, c1);
    // Least-squares ends of the entries the texels take, while they help.
    for _ in 0..2 {
        let Some((a, b)) = least_squares_ends(texels, indices) else { break };
        let Some((a, b)) = four_colour(a, b) else { break };
        let (candidate_error, candidate_indices) = error_and_indices(texels, a, b);
        if candidate_error >= error {
            break;
        }
        (error, indices, best) = (candidate_error, candidate_indices, (a, b));
    }
    // A block that varies in one channel only (packed maps with two constant channels): every
    // pair of that channel's ends near its range, the others at their nearest value.
    if let Some((candidate_error, candidate_indices, ends)) = one_channel_fit(texels) {
        if candidate_error < error {
            (error, indices, best) = (candidate_error, candidate_indices, ends);
        }
    }
    // Steps of one endpoint channel, or of both ends' same channel together (a block whose
    // colours vary along one channel moves its line's two ends at once), while the error falls.
    const MOVES: [[i32; 2]; 8] = [[-1, 0], [1, 0], [0, -1], [0, 1], [1, 1], [-1, -1], [1, -1], [-1, 1]];
    loop {
        let before = error;
        for channel in 0..3 {
            for [move0, move1] in MOVES {
                let mut ends = [unpack(best.0), unpack(best.1)];
                ends[0][channel] += move0;
                ends[1][channel] += move1;
                let Some((a, b)) = four_colour(pack(ends[0]), pack(ends[1])) else { continue };
                let (candidate_error, candidate_indices) = error_and_indices(texels, a, b);
                if candidate_error < error {
                    (error, indices, best) = (candidate_error, candidate_indices, (a, b));
                }
            }
        }
        if error >= before || error == 0.0 {
            break;
        }
    }
    if error >= start_error {
        return start;
    }
    let mut block = [0u8; 8];
    block[..2].copy_from_slice(&best.0.to_le_bytes());
    block[2..4].copy_from_slice(&best.1.to_le_bytes());
    block[4..].copy_from_slice(&indices.to_le_bytes());
    block
}
