//! Ambient occlusion at a surface point: the cosine-weighted fraction of the hemisphere above
//! it from which nothing within `max_distance` blocks the sky. Rays follow a low-discrepancy
//! sequence (R2, Roberts 2018) shifted per sample point by a hash of its index (Cranley–Patterson
//! rotation), so results are deterministic and converge faster than random rays; directions are
//! cosine-distributed (or uniform, weighted by the cosine). Pure: over [`TriangleBvh`].

use glam::Vec3;

use super::rays::{build_triangle_bvh, offset_ray_origin, BackFaces, TriangleBvh};
use base::stop::{ShouldStop, Stopped};

/// The rays a point casts and when to stop casting them.
#[derive(Clone, Copy)]
pub struct Casting<'a> {
    pub settings: &'a OcclusionSettings,
    pub should_stop: ShouldStop<'a>,
}

/// How many rays a point casts between two asks whether to stop (each point asks before its
/// first ray): a point of a million rays stops within about a millisecond of being asked.
const RAYS_BETWEEN_STOP_CHECKS: u32 = 4096;

/// How ray directions are spread over the hemisphere.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum RayDistribution {
    /// Denser towards the normal (importance sampling of the cosine): the default.
    Cosine,
    /// Even over the hemisphere, each ray weighted by its cosine.
    Uniform,
}

/// How a point's occlusion is measured.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OcclusionSettings {
    pub rays: u32,
    pub distribution: RayDistribution,
    /// Hits farther than this do not occlude (`f32::INFINITY` for any).
    pub max_distance: f32,
    /// Whether rays pass through back faces (else back faces occlude like front faces).
    pub back_faces: BackFaces,
    /// The height (Y, OBJ's up) of an infinite floor that occludes too, if any.
    pub ground_plane: Option<f32>,
}

/// The occlusion of one point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Occlusion {
    /// 1 where the whole hemisphere is open, 0 where it is fully blocked.
    pub visibility: f32,
    /// Of the `probe_rays` (the first rays, up to [`INSIDE_PROBE_RAYS`], when rays pass through
    /// back faces), those whose nearest surface was a back face: more than half, and the point
    /// is inside geometry.
    pub back_face_rays: u32,
    pub probe_rays: u32,
}

/// How many of a point's rays also look for the nearest surface (a full nearest-hit query)
/// to tell whether the point is inside geometry; the others only ask whether anything blocks
/// them (an any-hit query, about twice as fast on the flight helmet).
pub(crate) const INSIDE_PROBE_RAYS: u32 = 32;

/// The `index`-th point of the R2 sequence in [0, 1)².
pub fn r2_point(index: u32) -> [f64; 2] {
    // 1/φ₂ and 1/φ₂², φ₂ the plastic number (the real root of x³ = x + 1).
    const A1: f64 = 0.754_877_666_246_692_8;
    const A2: f64 = 0.569_840_290_998_053_3;
    let index = index as f64;
    [(0.5 + A1 * index).fract(), (0.5 + A2 * index).fract()]
}

/// A well-mixed 32-bit hash (the finaliser of MurmurHash3).
fn mix(mut value: u32) -> u32 {
    value ^= value >> 16;
    value = value.wrapping_mul(0x85eb_ca6b);
    value ^= value >> 13;
    value = value.wrapping_mul(0xc2b2_ae35);
    value ^ (value >> 16)
}

/// The shift of the sequence for the sample point `seed` (its texel or vertex index).
pub fn sequence_shift(seed: u32) -> [f64; 2] {
    let first = mix(seed ^ 0x9e37_79b9);
    let second = mix(first ^ 0x7f4a_7c15);
    [first as f64 / 4_294_967_296.0, second as f64 / 4_294_967_296.0]
}

/// The first coordinate of the `index`-th R2 point and the cosine and sine of 2π times its
/// second, for every index up to the rays asked for: computed once per thread, so that a ray
/// costs no trigonometry (the per-point shift of the second coordinate is a rotation of the
/// point's frame, see [`occlusion_from`]).
fn with_sequence_table<T>(rays: u32, use_table: impl FnOnce(&[(f64, f32, f32)]) -> T) -> T {
    thread_local! {
        static TABLE: std::cell::RefCell<Vec<(f64, f32, f32)>> = const { std::cell::RefCell::new(Vec::new()) };
    }
    TABLE.with(|table| {
        let mut table = table.borrow_mut();
        for index in table.len() as u32..rays {
            let [radial, turn] = r2_point(index);
            let (sin, cos) = (std::f64::consts::TAU * turn).sin_cos();
            table.push((radial, cos as f32, sin as f32));
        }
        use_table(&table[..rays as usize])
    })
}

/// A direction in the frame whose Z is the normal, from the first coordinate of a point of
/// [0, 1)² and the cosine and sine of 2π times its second, and its weight.
fn local_direction(radial: f64, cos_turn: f32, sin_turn: f32, distribution: RayDistribution) -> (Vec3, f32) {
    match distribution {
        RayDistribution::Cosine => {
            let radius = radial.sqrt() as f32;
            let z = (1.0 - radial).max(0.0).sqrt() as f32;
            (Vec3::new(radius * cos_turn, radius * sin_turn, z), 1.0)
        }
        RayDistribution::Uniform => {
            let z = 1.0 - radial;
            let radius = (1.0 - z * z).max(0.0).sqrt() as f32;
            // Uniform density 1/2π against the cosine-weighted measure cos/π: weight 2 cos.
            (Vec3::new(radius * cos_turn, radius * sin_turn, z as f32), (2.0 * z) as f32)
        }
    }
}

/// An orthonormal frame around a unit normal (Duff et al., "Building an Orthonormal Basis,
/// Revisited", 2017).
pub fn orthonormal_frame(normal: Vec3) -> (Vec3, Vec3) {
    let sign = 1.0f32.copysign(normal.z);
    let a = -1.0 / (sign + normal.z);
    let b = normal.x * normal.y * a;
    (
        Vec3::new(1.0 + sign * normal.x * normal.x * a, sign * b, -sign * normal.x),
        Vec3::new(b, sign + normal.y * normal.y * a, -normal.y),
    )
}

/// The occlusion at `point` on triangle `triangle` (whose rays skip it), over the hemisphere
/// of the unit `normal`, with the sequence shifted by `seed`.
pub fn occlusion_at(
    bvh: &TriangleBvh,
    point: Vec3,
    normal: Vec3,
    triangle: u32,
    settings: &OcclusionSettings,
    seed: u32,
) -> Occlusion {
    occlusion_from(bvh, point, normal, normal, triangle, seed, Casting { settings, should_stop: &base::stop::never })
        .expect("never stops")
}

/// [`occlusion_at`] with the ray origins moved off the surface along `offset_normal` (the
/// geometric normal on the hemisphere's side) and the hemisphere around `normal`.
fn occlusion_from(
    bvh: &TriangleBvh,
    point: Vec3,
    offset_normal: Vec3,
    normal: Vec3,
    triangle: u32,
    seed: u32,
    casting: Casting,
) -> Result<Occlusion, Stopped> {
    let origin = offset_ray_origin(point, offset_normal);
    let (tangent, bitangent) = orthonormal_frame(normal);
    let shift = sequence_shift(seed);
    // Shifting the second coordinate by s turns every direction by 2πs about the normal: the
    // frame turns instead, once per point.
    let (sin_shift, cos_shift) = (std::f64::consts::TAU * shift[1]).sin_cos();
    let (sin_shift, cos_shift) = (sin_shift as f32, cos_shift as f32);
    let (tangent, bitangent) =
        (tangent * cos_shift + bitangent * sin_shift, bitangent * cos_shift - tangent * sin_shift);
    with_sequence_table(casting.settings.rays, |table| {
        occlusion_along(bvh, origin, [tangent, bitangent, normal], shift[0], table, triangle, casting)
    })
}

/// The occlusion from `origin` over the hemisphere of the frame `[tangent, bitangent, normal]`
/// along the rays of `table` with the first coordinate shifted by `radial_shift`.
fn occlusion_along(
    bvh: &TriangleBvh,
    origin: Vec3,
    [tangent, bitangent, normal]: [Vec3; 3],
    radial_shift: f64,
    table: &[(f64, f32, f32)],
    triangle: u32,
    Casting { settings, should_stop }: Casting,
) -> Result<Occlusion, Stopped> {
    let (mut open, mut total, mut back_face_rays) = (0.0f64, 0.0f64, 0u32);
    for (ray, &(radial, cos_turn, sin_turn)) in (0u32..).zip(table) {
        if ray % RAYS_BETWEEN_STOP_CHECKS == 0 && should_stop() {
            return Err(Stopped);
        }
        // Both in [0, 1): the sum wraps at most once.
        let radial = radial + radial_shift;
        let radial = if radial >= 1.0 { radial - 1.0 } else { radial };
        let (local, weight) = local_direction(radial, cos_turn, sin_turn, settings.distribution);
        let direction = (tangent * local.x + bitangent * local.y + normal * local.z).normalize_or_zero();
        // The floor is solid below: a downward ray meets it within reach (at once from an
        // origin that its offset moved just under a face lying on the floor).
        let below_ground = settings
            .ground_plane
            .is_some_and(|ground| direction.y < 0.0 && (origin.y - ground) / -direction.y <= settings.max_distance);
        let open_ray = !below_ground
            && match settings.back_faces {
                // The probes: a nearest-hit query, which also tells a back face in front.
                BackFaces::PassThrough if ray < INSIDE_PROBE_RAYS => {
                    let result = bvh.cast(origin, direction, settings.max_distance, triangle, BackFaces::PassThrough);
                    back_face_rays += result.nearest_is_back_face as u32;
                    result.hit.is_none()
                }
                // The others: the first blocking face found ends the ray.
                back_faces => !bvh.blocked(origin, direction, settings.max_distance, triangle, back_faces),
            };
        if open_ray {
            open += weight as f64;
        }
        // Normalised by the weights drawn (a ratio estimator): exact for an open or a closed
        // hemisphere, and less noisy than dividing by the ray count for uniform rays.
        total += weight as f64;
    }
    let visibility = if total > 0.0 { (open / total).clamp(0.0, 1.0) as f32 } else { 1.0 };
    let probe_rays =
        if settings.back_faces == BackFaces::PassThrough { settings.rays.min(INSIDE_PROBE_RAYS) } else { 0 };
    Ok(Occlusion { visibility, back_face_rays, probe_rays })
}

/// What occludes a mesh's points: one BVH over every triangle, or one per group of triangles
/// (an OBJ's objects, when each occludes only itself).
pub struct Occluders {
    groups: Vec<TriangleBvh>,
    /// Per mesh triangle: its group and its index in that group's BVH.
    placement: Vec<(u32, u32)>,
}

impl Occluders {
    /// The BVH a point on mesh triangle `triangle` casts its rays against, and the triangle's
    /// index there.
    fn of(&self, triangle: u32) -> (&TriangleBvh, u32) {
        let (group, local) = self.placement[triangle as usize];
        (&self.groups[group as usize], local)
    }
}

/// The occluders of a mesh: every triangle occludes every point, or with `groups` (a group per
/// triangle) a triangle occludes only the points of its own group.
pub fn build_occluders(positions: &[[f32; 3]], triangles: &[[u32; 3]], groups: Option<&[u32]>) -> Occluders {
    use rayon::prelude::*;
    let Some(groups) = groups else {
        let placement = (0..triangles.len() as u32).map(|triangle| (0, triangle)).collect();
        return Occluders { groups: vec![build_triangle_bvh(positions, triangles)], placement };
    };
    let group_count = groups.iter().copied().max().map_or(0, |max| max as usize + 1);
    let mut members: Vec<Vec<[u32; 3]>> = vec![Vec::new(); group_count];
    let mut placement = Vec::with_capacity(triangles.len());
    for (triangle, &group) in triangles.iter().zip(groups) {
        placement.push((group, members[group as usize].len() as u32));
        members[group as usize].push(*triangle);
    }
    let groups = members.par_iter().map(|triangles| build_triangle_bvh(positions, triangles)).collect();
    Occluders { groups, placement }
}

/// The occlusion of every covered texel of a UV coverage (see `uv_raster`): each texel's point
/// and normal interpolated over its triangle from `positions` and unit vertex `normals` (the
/// hemisphere's axis; rays leave on its side of the geometric surface), its sequence shifted by
/// its index in the `width`-wide image, so that a tile bakes what the whole image bakes there.
pub fn occlusion_of_texels(
    occluders: &Occluders,
    positions: &[[f32; 3]],
    normals: &[[f32; 3]],
    triangles: &[[u32; 3]],
    coverage: &super::uv_raster::UvCoverage,
    width: u32,
    casting: Casting,
) -> Result<Vec<Option<Occlusion>>, Stopped> {
    use rayon::prelude::*;
    let region = coverage.region;
    coverage
        .samples
        .par_iter()
        .enumerate()
        .map(|(index, sample)| {
            let Some(sample) = *sample else { return Ok(None) };
            let corners = triangles[sample.triangle as usize];
            let interpolate = |values: &[[f32; 3]]| {
                corners
                    .iter()
                    .zip(sample.barycentric)
                    .fold(Vec3::ZERO, |sum, (&vertex, weight)| sum + Vec3::from(values[vertex as usize]) * weight)
            };
            let point = interpolate(positions);
            let (bvh, local) = occluders.of(sample.triangle);
            let geometric = Vec3::from(bvh.geometric_normal(local));
            let mut normal = interpolate(normals).normalize_or_zero();
            if normal == Vec3::ZERO {
                normal = geometric;
            }
            // The origin leaves the surface on the hemisphere's side.
            let side = if geometric.dot(normal) < 0.0 { -geometric } else { geometric };
            let (x, y) = (region.x + index as u32 % region.width, region.y + index as u32 / region.width);
            let seed = y * width + x;
            occlusion_from(bvh, point, side, normal, local, seed, casting).map(Some)
        })
        .collect()
}

/// The occlusion at every vertex of a mesh (the seed's per-vertex bake, libigl's
/// `ambient_occlusion`): rays from the vertex moved `offset` along its unit normal, no
/// triangle skipped, the sequence shifted by the vertex index. Vertices no triangle uses get
/// none.
pub fn occlusion_of_vertices(
    occluders: &Occluders,
    positions: &[[f32; 3]],
    normals: &[[f32; 3]],
    triangles: &[[u32; 3]],
    offset: f32,
    casting: Casting,
) -> Result<Vec<Option<Occlusion>>, Stopped> {
    use rayon::prelude::*;
    // Each vertex casts against the occluders of the first triangle that uses it.
    let mut first_triangle = vec![u32::MAX; positions.len()];
    for (index, triangle) in triangles.iter().enumerate() {
        for &vertex in triangle {
            if let Some(first) = first_triangle.get_mut(vertex as usize) {
                if *first == u32::MAX {
                    *first = index as u32;
                }
            }
        }
    }
    (0..positions.len())
        .into_par_iter()
        .map(|vertex| {
            let triangle = first_triangle[vertex];
            if triangle == u32::MAX {
                return Ok(None);
            }
            let (bvh, local) = occluders.of(triangle);
            let normal = Vec3::from(normals[vertex]).normalize_or_zero();
            let normal = if normal == Vec3::ZERO { Vec3::from(bvh.geometric_normal(local)) } else { normal };
            let point = Vec3::from(positions[vertex]) + normal * offset;
            occlusion_from(bvh, point, normal, normal, u32::MAX, vertex as u32, casting).map(Some)
        })
        .collect()
}
