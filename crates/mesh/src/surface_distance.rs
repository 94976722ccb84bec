//! How far apart two surfaces are (DESIGN §3.4's report): points sampled on each by area, each
//! point's distance to the nearest point of the other (through the one BVH), and the figures
//! both ways together, RMS and the largest (a sampled Hausdorff distance). Pure.

use glam::Vec3;
use rayon::prelude::*;

use super::rays::TriangleBvh;

/// `count` points on the triangles, each triangle getting points in proportion to its area:
/// stratified along the cumulative area, and placed inside the triangle by the R2 sequence, so
/// the same mesh always gives the same points.
pub fn area_weighted_samples(positions: &[[f32; 3]], triangles: &[[u32; 3]], count: usize) -> Vec<Vec3> {
    let corners = |triangle: &[u32; 3]| triangle.map(|vertex| Vec3::from(positions[vertex as usize]));
    let mut cumulative = Vec::with_capacity(triangles.len());
    let mut total = 0.0f64;
    for triangle in triangles {
        let [a, b, c] = corners(triangle);
        let area = 0.5 * (b - a).cross(c - a).length() as f64;
        total += if area.is_finite() { area } else { 0.0 };
        cumulative.push(total);
    }
    if total <= 0.0 {
        return Vec::new();
    }
    (0..count)
        .into_par_iter()
        .map(|index| {
            let target = (index as f64 + 0.5) / count as f64 * total;
            let triangle = cumulative.partition_point(|&sum| sum <= target).min(triangles.len() - 1);
            let [a, b, c] = corners(&triangles[triangle]);
            let [mut u, mut v] = super::occlusion::r2_point(index as u32).map(|x| x as f32);
            if u + v > 1.0 {
                (u, v) = (1.0 - u, 1.0 - v);
            }
            a + (b - a) * u + (c - a) * v
        })
        .collect()
}

/// Distances between two surfaces, as fractions of a length (the bounding-box diagonal).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct SurfaceDistance {
    /// Root mean square of every sample's distance, both ways.
    pub rms: f64,
    /// The largest sample distance either way.
    pub hausdorff: f64,
}

/// Each sample's distance to the nearest point of `target` (none when it has no triangles).
pub fn distances_to(samples: &[Vec3], target: &TriangleBvh) -> Option<Vec<f32>> {
    samples.par_iter().map(|&point| target.nearest_point(point, f32::INFINITY).map(|(_, distance)| distance)).collect()
}

/// The distance between surfaces `a` and `b` (their samples and BVHs), over `length`.
pub fn surface_distance(
    a_samples: &[Vec3],
    a: &TriangleBvh,
    b_samples: &[Vec3],
    b: &TriangleBvh,
    length: f32,
) -> Option<SurfaceDistance> {
    let a_to_b = distances_to(a_samples, b)?;
    let b_to_a = distances_to(b_samples, a)?;
    let all: Vec<f32> = a_to_b.into_iter().chain(b_to_a).collect();
    if all.is_empty() || length.is_nan() || length <= 0.0 {
        return None;
    }
    let squares: f64 = all.iter().map(|&distance| distance as f64 * distance as f64).sum();
    let largest = all.iter().copied().fold(0.0f32, f32::max) as f64;
    let round = |value: f64| (value * 1e7).round() / 1e7;
    Some(SurfaceDistance {
        rms: round((squares / all.len() as f64).sqrt() / length as f64),
        hausdorff: round(largest / length as f64),
    })
}
