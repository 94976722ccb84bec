//! The pure parts of a height bake (DESIGN §3.4): the signed distance from the low surface (or
//! its PN surface) to the high one along the surface's normal, per texel of the low mesh's UV
//! space (`Normals`), or the difference of two top-down depth renders (`TopDown`); texels with
//! no measure filled from their nearest measured texel; the map quantised to 16 bits with the
//! mapping `distance = (value − center) × magnitude`; the map sampled bilinearly at a UV (the
//! displacement of a tessellated vertex).

use glam::Vec3;
use rayon::prelude::*;

use crate::mesh::pn_triangles::PnPatch;
use crate::mesh::rays::{BackFaces, TriangleBvh};
use crate::mesh::uv_raster::{rasterize_uv, TexelRegion};

/// The low mesh as the rays leave it.
#[derive(Clone, Copy)]
pub(crate) struct LowSurface<'a> {
    pub positions: &'a [[f32; 3]],
    pub normals: &'a [[f32; 3]],
    pub uvs: &'a [[f32; 2]],
    pub triangles: &'a [[u32; 3]],
    /// The triangles whose UVs the map covers (ascending).
    pub baked: &'a [u32],
}

/// Where the rays of a `Normals` bake leave from.
#[derive(Clone, Copy)]
pub(crate) enum RayStart<'a> {
    /// The low surface, along its interpolated normals (`height.png`).
    Flat,
    /// Each low triangle's PN patch, along its PN normal (the map a PN-tessellated mesh is
    /// displaced by), one patch per triangle.
    Pn(&'a [PnPatch]),
}

/// How far along the normal the high surface is looked for: `frontal` outward, `rear` inward
/// (mesh units).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct RayReach {
    pub frontal: f32,
    pub rear: f32,
}

/// What one texel holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub(crate) enum HeightTexel {
    /// Not on the surface: filled.
    Empty = 0,
    Measured = 1,
    /// On the surface, but no high surface within reach: filled.
    Missed = 2,
}

/// A finished height map: a signed distance per texel (mesh units, every texel filled), each
/// texel's state, and figures.
#[derive(Clone, Debug)]
pub(crate) struct HeightMap {
    pub size: u32,
    pub distances: Vec<f32>,
    pub states: Vec<u8>,
    /// The smallest and largest measured distance (0, 0 when none).
    pub range: [f32; 2],
    pub measured_texels: u64,
    pub missed_texels: u64,
    /// How far the bake looked for the high surface, end to end (mesh units): a measured range
    /// under [`FLAT_FRACTION`] of it is noise on a flat map, not relief.
    pub search_span: f32,
    /// How long its bake took (not part of its equality).
    pub bake_ms: f64,
}

/// Heights that span less than this fraction of the search span are a flat map: the high mesh
/// lies on the low one (float noise of the rays, about 1e-7 of the mesh's size, is far below).
pub(crate) const FLAT_FRACTION: f32 = 1e-4;

impl PartialEq for HeightMap {
    fn eq(&self, other: &Self) -> bool {
        let bits = |values: &[f32]| values.iter().map(|value| value.to_bits()).collect::<Vec<_>>();
        self.size == other.size && self.states == other.states && bits(&self.distances) == bits(&other.distances)
    }
}

impl HeightMap {
    /// Assembles a map from per-texel measures (`None` on the surface with no hit; texels off
    /// the surface are `covered = false`), filling every unmeasured texel from its nearest
    /// measured one.
    pub(crate) fn from_measures(
        size: u32,
        measures: &[Option<f32>],
        covered: &[bool],
        search_span: f32,
        bake_ms: f64,
    ) -> HeightMap {
        let mut states = vec![HeightTexel::Empty as u8; measures.len()];
        let mut drawn = vec![0.0f32; measures.len()];
        let mut sources = Vec::new();
        let (mut low, mut high) = (f32::INFINITY, f32::NEG_INFINITY);
        for (texel, (measure, &on_surface)) in measures.iter().zip(covered).enumerate() {
            match measure {
                Some(distance) if on_surface && distance.is_finite() => {
                    states[texel] = HeightTexel::Measured as u8;
                    drawn[texel] = *distance;
                    sources.push(texel as u32);
                    (low, high) = (low.min(*distance), high.max(*distance));
                }
                _ if on_surface => states[texel] = HeightTexel::Missed as u8,
                _ => {}
            }
        }
        let measured_texels = sources.len() as u64;
        let missed_texels = states.iter().filter(|&&state| state == HeightTexel::Missed as u8).count() as u64;
        let distances = if sources.is_empty() {
            (low, high) = (0.0, 0.0);
            drawn
        } else {
            let sources = crate::texture::fill::texel_sources(size, size, sources);
            crate::texture::fill::fill_values(&drawn, &sources)
        };
        HeightMap { size, distances, states, range: [low, high], measured_texels, missed_texels, search_span, bake_ms }
    }

    /// Whether the measured heights are flat: they span less than [`FLAT_FRACTION`] of the
    /// search span.
    pub(crate) fn is_flat(&self) -> bool {
        self.range[1] - self.range[0] < FLAT_FRACTION * self.search_span
    }

    /// The mapping of its 16-bit values: the measured range spread over 0..=65535; a flat map's
    /// middle at the middle value and the whole search span over the range, so that its noise
    /// is not stretched into relief.
    pub(crate) fn quantization(&self) -> Quantization {
        let [low, high] = self.range.map(f64::from);
        if self.is_flat() {
            let magnitude = f64::from(self.search_span).max(1e-30);
            return Quantization { center: 0.5 - 0.5 * (low + high) / magnitude, magnitude };
        }
        let magnitude = if high > low { high - low } else { low.abs().max(1e-30) };
        Quantization { center: -low / magnitude, magnitude }
    }

    /// The 16-bit values under `quantization`.
    pub(crate) fn values16(&self) -> Vec<u16> {
        let quantization = self.quantization();
        self.distances.iter().map(|&distance| quantization.value(distance)).collect()
    }

    /// The distance at `uv` (OBJ convention: V up), bilinear between texel centres, clamped at
    /// the map's edges.
    pub fn sample(&self, [u, v]: [f32; 2]) -> f32 {
        let size = self.size as f32;
        let x = (u * size - 0.5).clamp(0.0, size - 1.0);
        let y = ((1.0 - v) * size - 0.5).clamp(0.0, size - 1.0);
        let (x0, y0) = (x.floor() as u32, y.floor() as u32);
        let (x1, y1) = ((x0 + 1).min(self.size - 1), (y0 + 1).min(self.size - 1));
        let (fx, fy) = (x - x0 as f32, y - y0 as f32);
        let at = |x: u32, y: u32| self.distances[(y * self.size + x) as usize];
        let top = at(x0, y0) * (1.0 - fx) + at(x1, y0) * fx;
        let bottom = at(x0, y1) * (1.0 - fx) + at(x1, y1) * fx;
        let value = top * (1.0 - fy) + bottom * fy;
        if value.is_finite() {
            value
        } else {
            0.0
        }
    }
}

/// `distance = (value − center) × magnitude`, `value` in [0, 1] (the 16-bit value / 65535).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub(crate) struct Quantization {
    pub center: f64,
    pub magnitude: f64,
}

impl Quantization {
    pub fn value(&self, distance: f32) -> u16 {
        let value = distance as f64 / self.magnitude + self.center;
        (value.clamp(0.0, 1.0) * 65535.0).round() as u16
    }
}

/// The signed distance along `direction` from `point` to the high surface nearest it within
/// `reach` (positive outward), both faces counting. Each way's ray starts a hair behind the
/// point, so that a high surface lying exactly on the low one is found.
pub(crate) fn distance_along(
    high: &TriangleBvh,
    point: Vec3,
    direction: Vec3,
    reach: RayReach,
    hair: f32,
) -> Option<f32> {
    let outward = (reach.frontal > 0.0)
        .then(|| high.cast(point - direction * hair, direction, reach.frontal + hair, u32::MAX, BackFaces::Block).hit)
        .flatten()
        .map(|(_, distance)| distance - hair);
    let inward = (reach.rear > 0.0)
        .then(|| high.cast(point + direction * hair, -direction, reach.rear + hair, u32::MAX, BackFaces::Block).hit)
        .flatten()
        .map(|(_, distance)| hair - distance);
    match (outward, inward) {
        (Some(out), Some(into)) => Some(if out.abs() <= into.abs() { out } else { into }),
        (one, other) => one.or(other),
    }
}

/// A `Normals` bake: per texel of the low mesh's `size`² UV space, the distance to the high
/// surface along the surface's normal (the low surface's, or its PN surface's).
pub(crate) fn bake_along_normals(
    high: &TriangleBvh,
    low: &LowSurface,
    start: RayStart,
    size: u32,
    reach: RayReach,
    hair: f32,
) -> HeightMap {
    let clock = std::time::Instant::now();
    let region = TexelRegion { x: 0, y: 0, width: size, height: size };
    let coverage = rasterize_uv(low.uvs, low.triangles, low.baked, (size, size), region);
    let measures: Vec<Option<f32>> = coverage
        .samples
        .par_iter()
        .map(|sample| {
            let sample = (*sample)?;
            let (point, normal) = match start {
                RayStart::Flat => {
                    let corners = low.triangles[sample.triangle as usize];
                    let interpolate = |values: &[[f32; 3]]| {
                        corners.iter().zip(sample.barycentric).fold(Vec3::ZERO, |sum, (&vertex, weight)| {
                            sum + Vec3::from(values[vertex as usize]) * weight
                        })
                    };
                    let mut normal = interpolate(low.normals).normalize_or_zero();
                    if normal == Vec3::ZERO {
                        let [a, b, c] = corners.map(|vertex| Vec3::from(low.positions[vertex as usize]));
                        normal = (b - a).cross(c - a).normalize_or_zero();
                    }
                    (interpolate(low.positions), normal)
                }
                RayStart::Pn(patches) => {
                    let patch = &patches[sample.triangle as usize];
                    (patch.position(sample.barycentric), patch.normal(sample.barycentric))
                }
            };
            if normal == Vec3::ZERO || !point.is_finite() {
                return None;
            }
            distance_along(high, point, normal, reach, hair)
        })
        .collect();
    let covered: Vec<bool> = coverage.samples.iter().map(Option::is_some).collect();
    HeightMap::from_measures(
        size,
        &measures,
        &covered,
        reach.frontal + reach.rear,
        clock.elapsed().as_secs_f64() * 1000.0,
    )
}

/// A `TopDown` bake: the high render minus the low one per texel (both relative to one
/// footprint), measured where both surfaces are.
pub(crate) fn bake_top_down(
    size: u32,
    high: &[Option<f32>],
    low: &[Option<f32>],
    search_span: f32,
    bake_ms: f64,
) -> HeightMap {
    let measures: Vec<Option<f32>> = high.iter().zip(low).map(|(high, low)| Some((*high)? - (*low)?)).collect();
    let covered: Vec<bool> = low.iter().map(Option::is_some).collect();
    HeightMap::from_measures(size, &measures, &covered, search_span, bake_ms)
}
