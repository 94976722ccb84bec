//! The one BVH: a mesh's triangles in an `obvhs` compressed wide BVH (CWBVH), for the rays of
//! the bakes (ambient occlusion, height): the nearest hit within a distance, skipping the
//! triangle a ray leaves from, telling front faces from back faces; and the robust offset of a
//! ray's origin off its surface. Pure: plain positions and triangles in, hits out.

use glam::{IVec3, Vec3, Vec3A};
use obvhs::cwbvh::builder::build_cwbvh_from_tris;
use obvhs::cwbvh::CwBvh;
use obvhs::ray::{Ray, RayHit};
use obvhs::rt_triangle::RtTriangle;
use obvhs::triangle::Triangle;
use obvhs::BvhBuildParams;

/// The triangles of a mesh and a BVH over them.
pub struct TriangleBvh {
    bvh: CwBvh,
    /// The triangles in the BVH's primitive order (`bvh.primitive_indices` gives each one's
    /// mesh index), laid out for intersection.
    ordered: Vec<RtTriangle>,
    /// Each triangle's geometric normal, by mesh index (unit; zero for a degenerate one).
    normals: Vec<Vec3A>,
}

/// Which faces a ray's hits count on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BackFaces {
    /// Back faces block rays like front faces.
    Block,
    /// Rays pass through back faces (and report whether the nearest hit was one).
    PassThrough,
}

/// What a ray met: the nearest hit that counts within its distance, and whether a back face
/// lay nearer than any front face (or was the only hit) within that distance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RayResult {
    /// The triangle (index into the mesh's triangles) and distance of the nearest hit that
    /// counts, if any.
    pub hit: Option<(u32, f32)>,
    /// The nearest surface the ray met was a back face.
    pub nearest_is_back_face: bool,
}

/// Builds the BVH of `triangles` (indices into `positions`). Degenerate and non-finite
/// triangles are kept (they are never hit), so triangle indices stay the mesh's.
pub fn build_triangle_bvh(positions: &[[f32; 3]], triangles: &[[u32; 3]]) -> TriangleBvh {
    let vertex = |index: u32| {
        let position = positions.get(index as usize).copied().unwrap_or([0.0; 3]);
        let position = Vec3A::from(position);
        if position.is_finite() {
            position
        } else {
            Vec3A::ZERO
        }
    };
    let triangles: Vec<Triangle> = triangles.iter().map(|&[a, b, c]| Triangle { v0: vertex(a), v1: vertex(b), v2: vertex(c) }).collect();
    let normals = triangles.iter().map(|triangle| triangle.compute_normal()).collect();
    let bvh = if triangles.is_empty() {
        CwBvh::default()
    } else {
        build_cwbvh_from_tris(&triangles, BvhBuildParams::slow_build(), &mut std::time::Duration::default())
    };
    let ordered = bvh.primitive_indices.iter().map(|&index| RtTriangle::from(&triangles[index as usize])).collect();
    TriangleBvh { bvh, ordered, normals }
}

impl TriangleBvh {
    pub fn triangle_count(&self) -> usize {
        self.normals.len()
    }

    /// A triangle's geometric normal (unit, by its winding; zero when degenerate).
    pub fn geometric_normal(&self, triangle: u32) -> [f32; 3] {
        self.normals[triangle as usize].into()
    }

    /// Casts a ray from `origin` along `direction` (unit) up to `max_distance`, skipping the
    /// triangle `skip` (the one the ray leaves from; `u32::MAX` for none).
    pub fn cast(&self, origin: Vec3, direction: Vec3, max_distance: f32, skip: u32, back_faces: BackFaces) -> RayResult {
        if self.ordered.is_empty() {
            return RayResult { hit: None, nearest_is_back_face: false };
        }
        let ray = Ray::new(origin.into(), direction.into(), 0.0, max_distance);
        let direction = Vec3A::from(direction);
        let mut nearest_back = f32::INFINITY;
        let mut hit = RayHit::none();
        let found = self.bvh.ray_traverse(ray, &mut hit, |ray, id| {
            let triangle = self.bvh.primitive_indices[id];
            if triangle == skip {
                return f32::INFINITY;
            }
            let distance = self.ordered[id].intersect(ray);
            if !(distance >= ray.tmin && distance < ray.tmax) {
                return f32::INFINITY;
            }
            if back_faces == BackFaces::PassThrough && self.normals[triangle as usize].dot(direction) > 0.0 {
                nearest_back = nearest_back.min(distance);
                return f32::INFINITY;
            }
            distance
        });
        let hit = found.then(|| (self.bvh.primitive_indices[hit.primitive_id as usize], hit.t));
        let nearest_front = hit.map_or(f32::INFINITY, |(_, distance)| distance);
        RayResult { hit, nearest_is_back_face: nearest_back < nearest_front }
    }

    /// Whether any face that counts (`back_faces`) lies within `max_distance` along the ray:
    /// traversal stops at the first such hit found, the cheap query of occlusion that needs no
    /// distance.
    pub fn blocked(&self, origin: Vec3, direction: Vec3, max_distance: f32, skip: u32, back_faces: BackFaces) -> bool {
        if self.ordered.is_empty() {
            return false;
        }
        let ray = Ray::new(origin.into(), direction.into(), 0.0, max_distance);
        let direction = Vec3A::from(direction);
        !self.bvh.ray_traverse_miss(ray, |ray, id| {
            let triangle = self.bvh.primitive_indices[id];
            let passes = back_faces == BackFaces::PassThrough && self.normals[triangle as usize].dot(direction) > 0.0;
            if triangle == skip || passes {
                f32::INFINITY
            } else {
                self.ordered[id].intersect(ray)
            }
        })
    }
}

/// A ray origin moved off the surface at `point` along `normal` (the side the ray leaves
/// towards) by a few units in the last place of each coordinate (Wächter and Binder, "A Fast
/// and Robust Method for Avoiding Self-Intersection", Ray Tracing Gems, 2019): far enough that
/// the ray does not hit its own surface, near enough for any scale, no fixed epsilon.
pub fn offset_ray_origin(point: Vec3, normal: Vec3) -> Vec3 {
    const ORIGIN: f32 = 1.0 / 32.0;
    const FLOAT_SCALE: f32 = 1.0 / 65536.0;
    const INT_SCALE: f32 = 256.0;
    let offset = IVec3::new((INT_SCALE * normal.x) as i32, (INT_SCALE * normal.y) as i32, (INT_SCALE * normal.z) as i32);
    let step = |coordinate: f32, ulps: i32| {
        let ulps = if coordinate < 0.0 { -ulps } else { ulps };
        f32::from_bits((coordinate.to_bits() as i32).wrapping_add(ulps) as u32)
    };
    let moved = Vec3::new(step(point.x, offset.x), step(point.y, offset.y), step(point.z, offset.z));
    let pick = |coordinate: f32, moved: f32, normal: f32| {
        if coordinate.abs() < ORIGIN {
            coordinate + FLOAT_SCALE * normal
        } else {
            moved
        }
    };
    Vec3::new(pick(point.x, moved.x, normal.x), pick(point.y, moved.y, normal.y), pick(point.z, moved.z, normal.z))
}
