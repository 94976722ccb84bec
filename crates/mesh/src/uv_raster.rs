//! The one UV rasteriser: which triangle covers each texel of a mesh's UV space, and the point
//! of that triangle a bake samples there. Conservative (every texel a triangle touches is
//! covered) and orientation-agnostic (mirrored islands have the other winding). A texel whose
//! centre lies in a triangle samples the centre; a texel a triangle only touches samples the
//! triangle's point nearest the centre, so that no ray starts outside the surface. Overlapping
//! UVs (a texel centre inside two triangles that share no vertex) are counted; the first
//! triangle keeps the texel. Pure: UVs and triangles in, samples out; any region of the image
//! at a time (a tile), with the same result as the whole image there.

/// A rectangle of texels: columns `x..x + width`, rows `y..y + height` (row 0 at the top, which
/// is V = 1 in OBJ's convention).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TexelRegion {
    pub x: u32,
    pub y: u32,
    pub width: u32,
    pub height: u32,
}

/// Where a texel samples the surface: a triangle (index into the mesh's triangles) and
/// barycentric weights of its corners (non-negative, summing to 1).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TexelSample {
    pub triangle: u32,
    pub barycentric: [f32; 3],
    /// The texel centre lies inside the triangle (else the sample is its nearest point).
    pub centre_inside: bool,
}

/// The samples of one region, row by row, and how many of its texels overlap.
#[derive(Clone, Debug, PartialEq)]
pub struct UvCoverage {
    pub region: TexelRegion,
    pub samples: Vec<Option<TexelSample>>,
    /// Texels whose centre lies inside two (or more) triangles that share no vertex.
    pub overlapping: u32,
}

impl UvCoverage {
    pub fn sample(&self, x: u32, y: u32) -> Option<TexelSample> {
        let region = self.region;
        self.samples[((y - region.y) * region.width + (x - region.x)) as usize]
    }
}

/// Signed twice-area of the triangle (a, b, c).
fn cross(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> f64 {
    (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
}

/// Barycentric weights of `point` in the triangle `corners` (of signed twice-area `area`).
fn barycentric(corners: &[[f64; 2]; 3], area: f64, point: [f64; 2]) -> [f64; 3] {
    [
        cross(corners[1], corners[2], point) / area,
        cross(corners[2], corners[0], point) / area,
        cross(corners[0], corners[1], point) / area,
    ]
}

/// The point of segment `a`–`b` nearest `point`.
fn nearest_on_segment(a: [f64; 2], b: [f64; 2], point: [f64; 2]) -> [f64; 2] {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let length = dx * dx + dy * dy;
    let t =
        if length > 0.0 { (((point[0] - a[0]) * dx + (point[1] - a[1]) * dy) / length).clamp(0.0, 1.0) } else { 0.0 };
    [a[0] + t * dx, a[1] + t * dy]
}

/// Whether the triangle touches the square `[x, x + 1] × [y, y + 1]` (separating axes: the
/// square's two, and each edge's normal).
fn touches_square(corners: &[[f64; 2]; 3], x: f64, y: f64) -> bool {
    let square = [[x, y], [x + 1.0, y], [x + 1.0, y + 1.0], [x, y + 1.0]];
    for edge in 0..3 {
        let (a, b, c) = (corners[edge], corners[(edge + 1) % 3], corners[(edge + 2) % 3]);
        // The side of the edge the triangle lies on; the square must reach it.
        let side = cross(a, b, c).signum();
        if square.iter().all(|&corner| cross(a, b, corner) * side < 0.0) {
            return false;
        }
    }
    true
}

/// The samples of `region` in a `width` × `height` UV space, from the triangles `selected`
/// (indices into `triangles`, whose corners index `uvs`), in their order: the first triangle
/// whose interior holds a texel centre keeps the texel; a texel no interior holds goes to the
/// first triangle that touches it.
pub fn rasterize_uv(
    uvs: &[[f32; 2]],
    triangles: &[[u32; 3]],
    selected: &[u32],
    (width, height): (u32, u32),
    region: TexelRegion,
) -> UvCoverage {
    let mut samples: Vec<Option<TexelSample>> = vec![None; region.width as usize * region.height as usize];
    let mut overlapped = vec![false; samples.len()];
    let (right, bottom) = (region.x + region.width, region.y + region.height);
    for &triangle in selected {
        let Some(corner_indices) = triangles.get(triangle as usize) else { continue };
        let Some(corners) = corner_indices
            .iter()
            .map(|&vertex| {
                let [u, v] = *uvs.get(vertex as usize)?;
                (u.is_finite() && v.is_finite()).then_some([u as f64 * width as f64, (1.0 - v as f64) * height as f64])
            })
            .collect::<Option<Vec<_>>>()
        else {
            continue;
        };
        let corners: [[f64; 2]; 3] = [corners[0], corners[1], corners[2]];
        let area = cross(corners[0], corners[1], corners[2]);
        if area == 0.0 {
            continue;
        }
        let min_x = corners.iter().map(|c| c[0]).fold(f64::INFINITY, f64::min).floor().max(region.x as f64) as u32;
        let min_y = corners.iter().map(|c| c[1]).fold(f64::INFINITY, f64::min).floor().max(region.y as f64) as u32;
        let max_x = corners.iter().map(|c| c[0]).fold(f64::NEG_INFINITY, f64::max).ceil().min(right as f64);
        let max_y = corners.iter().map(|c| c[1]).fold(f64::NEG_INFINITY, f64::max).ceil().min(bottom as f64);
        if max_x <= min_x as f64 || max_y <= min_y as f64 {
            continue;
        }
        for y in min_y..max_y as u32 {
            for x in min_x..max_x as u32 {
                let centre = [x as f64 + 0.5, y as f64 + 0.5];
                let weights = barycentric(&corners, area, centre);
                let inside = weights.iter().all(|&weight| weight >= 0.0);
                if !inside && !touches_square(&corners, x as f64, y as f64) {
                    continue;
                }
                let index = ((y - region.y) * region.width + (x - region.x)) as usize;
                let slot = &mut samples[index];
                match slot {
                    Some(existing) if existing.centre_inside => {
                        let shares_vertex =
                            triangles[existing.triangle as usize].iter().any(|vertex| corner_indices.contains(vertex));
                        overlapped[index] |= inside && !shares_vertex;
                        continue;
                    }
                    Some(_) if !inside => continue,
                    _ => {}
                }
                let weights = if inside {
                    weights
                } else {
                    let nearest = (0..3)
                        .map(|edge| nearest_on_segment(corners[edge], corners[(edge + 1) % 3], centre))
                        .min_by(|a, b| {
                            let distance = |p: &[f64; 2]| (p[0] - centre[0]).powi(2) + (p[1] - centre[1]).powi(2);
                            distance(a).total_cmp(&distance(b))
                        })
                        .expect("three edges");
                    barycentric(&corners, area, nearest).map(|weight| weight.max(0.0))
                };
                let sum: f64 = weights.iter().sum();
                let barycentric = weights.map(|weight| (weight / sum) as f32);
                *slot = Some(TexelSample { triangle, barycentric, centre_inside: inside });
            }
        }
    }
    let overlapping = overlapped.iter().filter(|&&overlapped| overlapped).count() as u32;
    UvCoverage { region, samples, overlapping }
}
