//! Cut-out images given a distance-field alpha (Green 2007, "Improved alpha-tested
//! magnification") from a supersampled coverage: alpha is 0.5 plus the signed distance from the
//! texel's centre to the edge of the covered samples, so that a bilinear fetch tested against
//! 0.5 puts the edge where the samples put it, between texels, instead of on the staircase of
//! one coverage test per texel. The colours are the texels' own (shaded once per texel); only
//! the coverage is sampled finer.

use rayon::prelude::*;

/// The signed distance (in texels) that maps to alpha 0 and 1: the ramp spans one texel either
/// side of the edge, which is all that bilinear filtering between two neighbours reads.
pub(crate) const DISTANCE_SPREAD_TEXELS: f32 = 1.0;

/// Images of fewer samples are brought down on the calling thread: a billboard's render groups
/// are mostly a few thousand texels, and handing each pass to the thread pool and waiting for
/// it cost more than the pass (the oak's 1,245 renders spent 2.7 s so).
const PARALLEL_SAMPLES: usize = 1 << 18;

/// How far (in texels) a texel with alpha but no colour of its own looks for texels with one.
const BORROW_REACH: usize = 3;

/// Texel images with the coverage of their samples, to be given a distance alpha.
#[derive(Debug)]
pub struct DistanceAlpha<'a, 'b> {
    /// RGBA8 images of `width` × `height` texels each, shaded at the texels' centres; the first
    /// one's alpha is non-zero where a face covered the centre (the texel has a colour).
    pub surfaces: &'a mut [&'b mut [u8]],
    pub width: u32,
    pub height: u32,
    /// Samples per texel along each axis.
    pub factor: u32,
    /// `width × factor` by `height × factor` samples, rows from the top: where a face passes the
    /// alpha test.
    pub covered: &'a [bool],
    /// The first surface's colour is sRGB-encoded: it is averaged in linear light.
    pub first_surface_srgb: bool,
}

/// `f` of every row in `rows`, in order: on the thread pool when `parallel`, else here.
fn map_rows<T: Send>(rows: std::ops::Range<usize>, parallel: bool, f: impl Fn(usize) -> T + Sync + Send) -> Vec<T> {
    if parallel {
        rows.into_par_iter().map(f).collect()
    } else {
        rows.map(f).collect()
    }
}

/// Gives the first surface the distance alpha of the covered samples (see the module), moved
/// so that the magnified shape keeps the samples' area. A texel whose alpha becomes 0 is 0 in
/// every surface; one with alpha but no colour of its own (its centre uncovered, its edge
/// within the ramp) takes the mean of its neighbours that have one, in every surface. Factor 1
/// leaves the surfaces as they are.
pub fn apply_distance_alpha(input: &mut DistanceAlpha) {
    let factor = input.factor.max(1) as usize;
    if factor == 1 {
        return;
    }
    let (width, height) = (input.width as usize, input.height as usize);
    let (sample_width, sample_height) = (width * factor, height * factor);
    assert_eq!(input.covered.len(), sample_width * sample_height, "one coverage value per sample");
    assert!(input.surfaces.iter().all(|surface| surface.len() == width * height * 4), "RGBA8 surfaces of the texels");
    let parallel = input.covered.len() >= PARALLEL_SAMPLES;
    let reach = (DISTANCE_SPREAD_TEXELS * factor as f32).ceil() as usize + 1;
    let distances = signed_sample_distances(input.covered, sample_width, sample_height, reach);
    let texel_distances: Vec<f32> = map_rows(0..height, parallel, |row| {
        (0..width).map(|column| centre_distance(&distances, sample_width, factor, row, column)).collect::<Vec<_>>()
    })
    .concat();
    drop(distances);
    let covered_samples = input.covered.iter().filter(|&&inside| inside).count();
    let offset = area_keeping_offset(&texel_distances, (width, height), factor, reach as f32, covered_samples);
    let ramp = 2.0 * DISTANCE_SPREAD_TEXELS * factor as f32;
    let alphas: Vec<u8> = texel_distances
        .iter()
        .map(|&distance| ((0.5 + (distance + offset) / ramp).clamp(0.0, 1.0) * 255.0).round() as u8)
        .collect();

    let srgb = input.first_surface_srgb;
    let decode = |surface: usize, channel: usize, byte: u8| -> f32 {
        if srgb && surface == 0 && channel < 3 {
            crate::color::srgb_u8_to_linear(byte)
        } else {
            f32::from(byte)
        }
    };
    let encode = |surface: usize, channel: usize, value: f32| -> u8 {
        if srgb && surface == 0 && channel < 3 {
            crate::color::linear_to_srgb_u8(value)
        } else {
            value.round().clamp(0.0, 255.0) as u8
        }
    };
    let surfaces = &mut *input.surfaces;
    let has_colour: Vec<bool> = surfaces[0].chunks_exact(4).map(|texel| texel[3] != 0).collect();
    // Texels with alpha but no colour of their own borrow their neighbours' (read before any
    // texel changes); then every texel keeps its colour with the new alpha, or is cleared.
    let mut borrowed: Vec<(usize, Vec<u8>)> = Vec::new();
    for texel in (0..width * height).filter(|&texel| alphas[texel] != 0 && !has_colour[texel]) {
        let (row, column) = (texel / width, texel % width);
        // The nearest ring of texels around it that has some with a colour (a sliver of covered
        // samples may cover no texel centre near it).
        let Some(neighbours) = (1..=BORROW_REACH).find_map(|reach| {
            let ring: Vec<usize> = (row.saturating_sub(reach)..(row + reach + 1).min(height))
                .flat_map(|other_row| {
                    (column.saturating_sub(reach)..(column + reach + 1).min(width))
                        .map(move |other_column| (other_row, other_column))
                })
                .filter(|&(other_row, other_column)| {
                    other_row.abs_diff(row).max(other_column.abs_diff(column)) == reach
                })
                .map(|(other_row, other_column)| other_row * width + other_column)
                .filter(|&other| has_colour[other])
                .collect();
            (!ring.is_empty()).then_some(ring)
        }) else {
            continue;
        };
        let mut values = Vec::with_capacity(surfaces.len() * 4);
        for (surface, image) in surfaces.iter().enumerate() {
            for channel in 0..4 {
                let sum: f32 =
                    neighbours.iter().map(|&other| decode(surface, channel, image[other * 4 + channel])).sum();
                values.push(encode(surface, channel, sum / neighbours.len() as f32));
            }
        }
        borrowed.push((texel, values));
    }
    for (surface, image) in surfaces.iter_mut().enumerate() {
        for (texel, values) in image.chunks_exact_mut(4).enumerate() {
            if alphas[texel] == 0 || !has_colour[texel] {
                values.fill(0);
            } else if surface == 0 {
                values[3] = alphas[texel];
            }
        }
    }
    for (texel, values) in &borrowed {
        for (surface, image) in surfaces.iter_mut().enumerate() {
            image[texel * 4..][..4].copy_from_slice(&values[surface * 4..][..4]);
        }
        surfaces[0][texel * 4 + 3] = alphas[*texel];
    }
}

/// The distance (in samples, at most half a texel either way) to add to every texel's so that
/// the magnified shape keeps the area of the covered samples: bilinear filtering of a distance
/// field rounds corners and drops the middle of strokes thinner than a texel, so unmoved, the
/// shape that passes the alpha test shrinks (discs of 1.3 to 3.1 texels lose 6 % of their
/// area). The filtered distance is taken at every sample's centre (clamped at the border, as
/// the image's edge is no edge of the shape), and the offset lets exactly as many of them pass
/// as there are covered samples.
///
/// Samples whose four texels are all `far` inside filter to exactly `far` (the weights are
/// binary fractions that sum to 1), the largest value there is: they are counted, not stored,
/// so that only samples near an edge are sorted.
fn area_keeping_offset(
    texel_distances: &[f32],
    (width, height): (usize, usize),
    factor: usize,
    far: f32,
    covered_samples: usize,
) -> f32 {
    if covered_samples == 0 {
        return 0.0;
    }
    let at = |column: i64, row: i64| {
        texel_distances[row.clamp(0, height as i64 - 1) as usize * width + column.clamp(0, width as i64 - 1) as usize]
    };
    // Each sample column's texel column to its left and its weight toward the right one; the
    // samples of one texel column read the same four texels, tested once for all of them.
    let sample_columns: Vec<(i64, f32)> = (0..width * factor)
        .map(|sample_column| {
            let x = (sample_column as f32 + 0.5) / factor as f32 - 0.5;
            (x.floor() as i64, x - x.floor())
        })
        .collect();
    // Per row of samples: the filtered distances of the samples near an edge (some texel
    // around them neither far outside nor far inside), and the count of those far inside.
    let rows = map_rows(0..height * factor, width * height * factor * factor >= PARALLEL_SAMPLES, |sample_row| {
        let y = (sample_row as f32 + 0.5) / factor as f32 - 0.5;
        let (row, fy) = (y.floor() as i64, y - y.floor());
        let mut near_edge = Vec::new();
        let mut deep = 0usize;
        for same_column in sample_columns.chunk_by(|a, b| a.0 == b.0) {
            let column = same_column[0].0;
            let corners = [at(column, row), at(column + 1, row), at(column, row + 1), at(column + 1, row + 1)];
            if corners.iter().all(|&corner| corner <= -far) {
                continue;
            }
            if corners.iter().all(|&corner| corner == far) {
                deep += same_column.len();
                continue;
            }
            near_edge.extend(same_column.iter().map(|&(_, fx)| {
                corners[0] * (1.0 - fx) * (1.0 - fy)
                    + corners[1] * fx * (1.0 - fy)
                    + corners[2] * (1.0 - fx) * fy
                    + corners[3] * fx * fy
            }));
        }
        (near_edge, deep)
    });
    let deep: usize = rows.iter().map(|(_, deep)| deep).sum();
    let mut filtered: Vec<f32> = rows.into_iter().flat_map(|(near_edge, _)| near_edge).collect();
    if covered_samples > filtered.len() + deep {
        return 0.0;
    }
    // Zero after the offset falls halfway between the covered_samples-th largest filtered
    // distance, which passes, and the next, which does not (ascending: the samples near an
    // edge, then `deep` values of `far`).
    let index = filtered.len() + deep - covered_samples;
    let (last_passing, first_failing) = match index.cmp(&filtered.len()) {
        std::cmp::Ordering::Less => {
            let (below, last_passing, _) = filtered.select_nth_unstable_by(index, f32::total_cmp);
            (*last_passing, below.iter().copied().fold(-far, f32::max))
        }
        std::cmp::Ordering::Equal => (far, filtered.iter().copied().fold(-far, f32::max)),
        std::cmp::Ordering::Greater => (far, far),
    };
    let half_texel = factor as f32 / 2.0;
    (-(last_passing + first_failing) / 2.0).clamp(-half_texel, half_texel)
}

/// The signed distance at a texel's centre (in samples): the mean of the samples' distances
/// around it (the four nearest for an even factor, the middle one for an odd one).
fn centre_distance(
    distances: &[f32],
    sample_width: usize,
    factor: usize,
    texel_row: usize,
    texel_column: usize,
) -> f32 {
    let (first_row, first_column) = (texel_row * factor, texel_column * factor);
    let middle = factor / 2;
    if factor % 2 == 1 {
        return distances[(first_row + middle) * sample_width + first_column + middle];
    }
    let mut sum = 0.0;
    for row in first_row + middle - 1..=first_row + middle {
        for column in first_column + middle - 1..=first_column + middle {
            sum += distances[row * sample_width + column];
        }
    }
    sum / 4.0
}

/// Every sample's signed distance to the edge between covered and uncovered samples, in
/// samples (positive inside): the Euclidean distance to the nearest sample of the other kind,
/// less half a sample step along the way to it, at most `reach` either way. The image's border
/// is no edge: a shape cut by it keeps its alpha up to it. Exact within the reach: a row pass
/// finds each sample's nearest other kind along its row, then a column pass takes the nearest
/// over the rows within the reach (whole rows at a time, in small integers, so that it runs
/// in vector lanes).
pub fn signed_sample_distances(covered: &[bool], width: usize, height: usize, reach: usize) -> Vec<f32> {
    assert_eq!(covered.len(), width * height, "one coverage value per sample");
    assert!(reach <= 10, "squared distances fit in a byte");
    let parallel = covered.len() >= PARALLEL_SAMPLES;
    let far = reach as u8 + 1;
    // Along each row: the distance to the nearest sample of the other kind (at most `far`).
    let along_rows: Vec<u8> = map_rows(0..height, parallel, |row| {
        let row = &covered[row * width..][..width];
        let mut distance = vec![far; width];
        let mut last_of = [None::<usize>, None::<usize>];
        for (column, &inside) in row.iter().enumerate() {
            if let Some(other) = last_of[usize::from(!inside)] {
                distance[column] = distance[column].min((column - other).min(far as usize) as u8);
            }
            last_of[usize::from(inside)] = Some(column);
        }
        last_of = [None, None];
        for column in (0..width).rev() {
            let inside = row[column];
            if let Some(other) = last_of[usize::from(!inside)] {
                distance[column] = distance[column].min((other - column).min(far as usize) as u8);
            }
            last_of[usize::from(inside)] = Some(column);
        }
        distance
    })
    .concat();
    // The distance of a nearest other-kind sample `rows` rows and `across` columns away: the
    // edge lies half a sample step before it, along the way to it.
    let distance_of = |rows: u8, across: u8| -> f32 {
        let (rows, across) = (f32::from(rows), f32::from(across));
        let length = (rows * rows + across * across).sqrt();
        let steps = rows.max(across).max(1.0);
        (length * (1.0 - 0.5 / steps)).min(reach as f32)
    };
    let table: Vec<f32> = (0..=far).flat_map(|rows| (0..=far).map(move |across| distance_of(rows, across))).collect();
    map_rows(0..height, parallel, |row| {
        let own = &covered[row * width..][..width];
        // Per column: the nearest (squared distance, rows apart, columns apart) so far; rows
        // are taken in order and only a strictly nearer one replaces the last.
        let mut nearest_squared = vec![far * far; width];
        let mut nearest_rows = vec![far; width];
        let mut nearest_across = vec![0u8; width];
        for other_row in row.saturating_sub(reach)..(row + reach + 1).min(height) {
            let rows_apart = other_row.abs_diff(row) as u8;
            let other = &covered[other_row * width..][..width];
            let along = &along_rows[other_row * width..][..width];
            for column in 0..width {
                let across = if other[column] != own[column] { 0 } else { along[column] };
                let squared = rows_apart * rows_apart + across * across;
                if squared < nearest_squared[column] {
                    nearest_squared[column] = squared;
                    nearest_rows[column] = rows_apart;
                    nearest_across[column] = across;
                }
            }
        }
        (0..width)
            .map(|column| {
                let distance =
                    table[nearest_rows[column] as usize * (far as usize + 1) + nearest_across[column] as usize];
                if own[column] {
                    distance
                } else {
                    -distance
                }
            })
            .collect::<Vec<_>>()
    })
    .concat()
}
