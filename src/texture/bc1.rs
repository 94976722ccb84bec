//! BC1 blocks refined after the ISPC encoder: from its endpoints, least-squares endpoints for the
//! palette entries the texels take (quantised to 5:6:5), then single steps of each endpoint
//! channel while the error falls, every candidate scored with the decoder's own integer
//! arithmetic (`bcdec`'s), four-colour mode only (the block stays opaque). Pure: 16 RGB texels
//! and a block in, a block as good or better out.

/// The four colours of endpoints `c0 > c1` (5:6:5), as `bcdec` decodes them.
fn palette(c0: u16, c1: u16) -> [[i32; 3]; 4] {
    let unpack = |c: u16| [(c as i32 >> 11) & 31, (c as i32 >> 5) & 63, c as i32 & 31];
    let (a, b) = (unpack(c0), unpack(c1));
    let expand = |v: [i32; 3]| [(v[0] * 527 + 23) >> 6, (v[1] * 259 + 33) >> 6, (v[2] * 527 + 23) >> 6];
    let third = |x: [i32; 3], y: [i32; 3]| {
        [
            ((2 * x[0] + y[0]) * 351 + 61) >> 7,
            ((2 * x[1] + y[1]) * 2763 + 1039) >> 11,
            ((2 * x[2] + y[2]) * 351 + 61) >> 7,
        ]
    };
    [expand(a), expand(b), third(a, b), third(b, a)]
}

/// The summed squared error of `texels` under endpoints `c0 > c1`, and each texel's index.
fn error_and_indices(texels: &[[u8; 3]; 16], c0: u16, c1: u16) -> (u32, u32) {
    let colours = palette(c0, c1);
    let (mut total, mut indices) = (0u32, 0u32);
    for (texel, rgb) in texels.iter().enumerate() {
        let mut best = (u32::MAX, 0u32);
        for (index, colour) in colours.iter().enumerate() {
            let error: i32 = (0..3).map(|channel| (rgb[channel] as i32 - colour[channel]).pow(2)).sum();
            if (error as u32) < best.0 {
                best = (error as u32, index as u32);
            }
        }
        total += best.0;
        indices |= best.1 << (2 * texel);
    }
    (total, indices)
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

/// The block refined from `start` (an encoded BC1 block of the same texels): never worse than
/// `start` under `bcdec`'s decoding; a block in the three-colour mode is kept as it is.
pub fn refine_bc1_block(texels: &[[u8; 3]; 16], start: [u8; 8]) -> [u8; 8] {
    let (c0, c1) = (u16::from_le_bytes([start[0], start[1]]), u16::from_le_bytes([start[2], start[3]]));
    if c0 <= c1 {
        return start;
    }
    let (mut error, mut indices) = error_and_indices(texels, c0, c1);
    let start_indices = u32::from_le_bytes([start[4], start[5], start[6], start[7]]);
    let start_error = {
        let colours = palette(c0, c1);
        texels
            .iter()
            .enumerate()
            .map(|(texel, rgb)| {
                let colour = colours[(start_indices >> (2 * texel) & 3) as usize];
                (0..3).map(|channel| (rgb[channel] as i32 - colour[channel]).pow(2) as u32).sum::<u32>()
            })
            .sum::<u32>()
    };
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
    // Single steps of each endpoint channel while the error falls.
    loop {
        let before = error;
        for end in 0..2 {
            for channel in 0..3 {
                for step in [-1, 1] {
                    let mut ends = [unpack(best.0), unpack(best.1)];
                    ends[end][channel] += step;
                    let Some((a, b)) = four_colour(pack(ends[0]), pack(ends[1])) else { continue };
                    let (candidate_error, candidate_indices) = error_and_indices(texels, a, b);
                    if candidate_error < error {
                        (error, indices, best) = (candidate_error, candidate_indices, (a, b));
                    }
                }
            }
        }
        if error >= before || error == 0 {
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
