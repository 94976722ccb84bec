//! The inner loops of ray casting, eight lanes at a time: a ray against a node's eight child
//! boxes (slab test) and against a packet of eight triangles (Möller–Trumbore). Two versions of
//! each with the same hits to the bit: AVX2 + FMA (x86-64 CPUs that have it, chosen at run time)
//! and portable (two four-lane halves in glam's `Vec4`: SSE2 on x86-64, NEON on ARM). Only the
//! box test fuses multiply-adds, and boxes are padded, so no rounding there changes a hit.

use glam::{Vec3, Vec4};

/// Lanes of a node and of a triangle packet.
pub(crate) const WIDTH: usize = 8;

/// Eight child boxes as planes `[min x, max x, min y, max y, min z, max z]`, each eight lanes
/// (an empty lane has min +∞ and max −∞, which no ray enters), and what each child is.
#[derive(Clone, Copy)]
#[repr(C, align(64))]
pub struct Node {
    pub planes: [[f32; WIDTH]; 6],
    pub children: [u32; WIDTH],
}

/// Eight triangles as a corner and two edges, by axis (an empty lane has zero edges, which no
/// ray hits), and their mesh indices (`u32::MAX` in empty lanes).
#[derive(Clone, Copy)]
#[repr(C, align(32))]
pub(crate) struct Packet {
    pub corner: [[f32; WIDTH]; 3],
    pub edge1: [[f32; WIDTH]; 3],
    pub edge2: [[f32; WIDTH]; 3],
    pub triangles: [u32; WIDTH],
}

/// A ray as the kernels read it.
pub(crate) struct PreparedRay {
    pub origin: Vec3,
    pub direction: Vec3,
    /// 1 / direction, with zero components replaced by tiny ones of the same sign.
    pub inverse: Vec3,
    /// origin × inverse, so that a plane's distance is plane × inverse − this.
    pub origin_scaled: Vec3,
    /// Per axis, the index in `Node::planes` of the plane the ray meets first.
    pub near_plane: [usize; 3],
}

impl PreparedRay {
    pub fn new(origin: Vec3, direction: Vec3) -> PreparedRay {
        let nonzero = |value: f32| if value.abs() < 1e-20 { 1e-20f32.copysign(value) } else { value };
        let inverse = Vec3::new(1.0 / nonzero(direction.x), 1.0 / nonzero(direction.y), 1.0 / nonzero(direction.z));
        PreparedRay {
            origin,
            direction,
            inverse,
            origin_scaled: origin * inverse,
            // By the inverse's sign: a zero component keeps its sign bit there (−0 → −tiny).
            near_plane: [(inverse.x < 0.0) as usize, 2 + (inverse.y < 0.0) as usize, 4 + (inverse.z < 0.0) as usize],
        }
    }
}

/// What a ray met in a packet: per lane, the distance (meaningful where hit), and as bit masks
/// the lanes hit within (0, `max_distance`) and the lanes whose triangle faces away from the
/// ray (the geometric normal, by winding, along the ray).
pub(crate) struct PacketHits {
    pub distances: [f32; WIDTH],
    pub hits: u32,
    pub back_faces: u32,
}

/// One version of the two loops.
///
/// # Safety
///
/// The AVX2 version may only run on a CPU that has AVX2 and FMA (see [`Avx2::available`]);
/// the portable version runs anywhere.
pub(crate) trait Kernels {
    /// The distance at which the ray enters each child box, and the mask of the children it
    /// enters before `max_distance`.
    unsafe fn node(node: &Node, ray: &PreparedRay, max_distance: f32) -> ([f32; WIDTH], u32);
    unsafe fn packet(packet: &Packet, ray: &PreparedRay, max_distance: f32) -> PacketHits;
}

/// The kernels in plain four-lane vectors: any CPU.
pub(crate) struct Portable;

impl Kernels for Portable {
    #[inline(always)]
    unsafe fn node(node: &Node, ray: &PreparedRay, max_distance: f32) -> ([f32; WIDTH], u32) {
        let mut entries = [0.0; WIDTH];
        let mut mask = 0;
        for half in 0..2 {
            let lanes = half * 4..half * 4 + 4;
            let mut near = Vec4::ZERO;
            let mut far = Vec4::splat(max_distance);
            for axis in 0..3 {
                let near_plane = ray.near_plane[axis];
                let inverse = Vec4::splat(ray.inverse[axis]);
                let scaled = Vec4::splat(ray.origin_scaled[axis]);
                near = near.max(Vec4::from_slice(&node.planes[near_plane][lanes.clone()]) * inverse - scaled);
                far = far.min(Vec4::from_slice(&node.planes[near_plane ^ 1][lanes.clone()]) * inverse - scaled);
            }
            near.write_to_slice(&mut entries[lanes]);
            mask |= near.cmple(far).bitmask() << (half * 4);
        }
        (entries, mask)
    }

    #[inline(always)]
    unsafe fn packet(packet: &Packet, ray: &PreparedRay, max_distance: f32) -> PacketHits {
        let mut result = PacketHits { distances: [0.0; WIDTH], hits: 0, back_faces: 0 };
        let splat = |value: Vec3| [Vec4::splat(value.x), Vec4::splat(value.y), Vec4::splat(value.z)];
        let ([dx, dy, dz], origin) = (splat(ray.direction), splat(ray.origin));
        for half in 0..2 {
            let lanes = half * 4..half * 4 + 4;
            let load =
                |values: &[[f32; WIDTH]; 3]| values.each_ref().map(|axis| Vec4::from_slice(&axis[lanes.clone()]));
            let ([cx, cy, cz], [e1x, e1y, e1z], [e2x, e2y, e2z]) =
                (load(&packet.corner), load(&packet.edge1), load(&packet.edge2));
            // p = d × e2; det = e1 · p (negative where the triangle faces away).
            let (px, py, pz) = (dy * e2z - dz * e2y, dz * e2x - dx * e2z, dx * e2y - dy * e2x);
            let det = e1x * px + e1y * py + e1z * pz;
            let inverse = Vec4::ONE / det;
            let (tx, ty, tz) = (origin[0] - cx, origin[1] - cy, origin[2] - cz);
            let u = (tx * px + ty * py + tz * pz) * inverse;
            // q = t × e1
            let (qx, qy, qz) = (ty * e1z - tz * e1y, tz * e1x - tx * e1z, tx * e1y - ty * e1x);
            let v = (dx * qx + dy * qy + dz * qz) * inverse;
            let distance = (e2x * qx + e2y * qy + e2z * qz) * inverse;
            let hit = det.cmpne(Vec4::ZERO)
                & u.cmpge(Vec4::ZERO)
                & v.cmpge(Vec4::ZERO)
                & (u + v).cmple(Vec4::ONE)
                & distance.cmpgt(Vec4::ZERO)
                & distance.cmplt(Vec4::splat(max_distance));
            distance.write_to_slice(&mut result.distances[lanes]);
            result.hits |= hit.bitmask() << (half * 4);
            result.back_faces |= det.cmplt(Vec4::ZERO).bitmask() << (half * 4);
        }
        result
    }
}

/// The kernels in AVX2 + FMA registers: eight lanes in one instruction.
#[cfg(target_arch = "x86_64")]
pub struct Avx2;

#[cfg(target_arch = "x86_64")]
impl Avx2 {
    /// Whether this CPU can run them.
    pub(crate) fn available() -> bool {
        base::isa::avx2_allowed()
    }
}

#[cfg(target_arch = "x86_64")]
impl Kernels for Avx2 {
    #[inline(always)]
    unsafe fn node(node: &Node, ray: &PreparedRay, max_distance: f32) -> ([f32; WIDTH], u32) {
        use std::arch::x86_64::*;
        let mut near = _mm256_setzero_ps();
        let mut far = _mm256_set1_ps(max_distance);
        for axis in 0..3 {
            let near_plane = ray.near_plane[axis];
            let inverse = _mm256_set1_ps(ray.inverse[axis]);
            let scaled = _mm256_set1_ps(ray.origin_scaled[axis]);
            let entry = _mm256_fmsub_ps(_mm256_loadu_ps(node.planes[near_plane].as_ptr()), inverse, scaled);
            let exit = _mm256_fmsub_ps(_mm256_loadu_ps(node.planes[near_plane ^ 1].as_ptr()), inverse, scaled);
            near = _mm256_max_ps(near, entry);
            far = _mm256_min_ps(far, exit);
        }
        let mask = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(near, far)) as u32;
        let mut entries = [0.0; WIDTH];
        _mm256_storeu_ps(entries.as_mut_ptr(), near);
        (entries, mask)
    }

    /// The same operations in the same order as the portable version (no fused multiply-add),
    /// so that hits and distances are the same to the bit on any CPU.
    #[inline(always)]
    unsafe fn packet(packet: &Packet, ray: &PreparedRay, max_distance: f32) -> PacketHits {
        use std::arch::x86_64::*;
        let load = |values: &[f32; WIDTH]| _mm256_loadu_ps(values.as_ptr());
        let (add, sub, mul) = (|a, b| _mm256_add_ps(a, b), |a, b| _mm256_sub_ps(a, b), |a, b| _mm256_mul_ps(a, b));
        let dot = |ax, ay, az, bx, by, bz| add(add(mul(ax, bx), mul(ay, by)), mul(az, bz));
        let (dx, dy, dz) =
            (_mm256_set1_ps(ray.direction.x), _mm256_set1_ps(ray.direction.y), _mm256_set1_ps(ray.direction.z));
        let (e1x, e1y, e1z) = (load(&packet.edge1[0]), load(&packet.edge1[1]), load(&packet.edge1[2]));
        let (e2x, e2y, e2z) = (load(&packet.edge2[0]), load(&packet.edge2[1]), load(&packet.edge2[2]));
        let px = sub(mul(dy, e2z), mul(dz, e2y));
        let py = sub(mul(dz, e2x), mul(dx, e2z));
        let pz = sub(mul(dx, e2y), mul(dy, e2x));
        let det = dot(e1x, e1y, e1z, px, py, pz);
        let inverse = _mm256_div_ps(_mm256_set1_ps(1.0), det);
        let tx = sub(_mm256_set1_ps(ray.origin.x), load(&packet.corner[0]));
        let ty = sub(_mm256_set1_ps(ray.origin.y), load(&packet.corner[1]));
        let tz = sub(_mm256_set1_ps(ray.origin.z), load(&packet.corner[2]));
        let u = mul(dot(tx, ty, tz, px, py, pz), inverse);
        let qx = sub(mul(ty, e1z), mul(tz, e1y));
        let qy = sub(mul(tz, e1x), mul(tx, e1z));
        let qz = sub(mul(tx, e1y), mul(ty, e1x));
        let v = mul(dot(dx, dy, dz, qx, qy, qz), inverse);
        let distance = mul(dot(e2x, e2y, e2z, qx, qy, qz), inverse);
        let zero = _mm256_setzero_ps();
        let inside = _mm256_and_ps(
            _mm256_and_ps(_mm256_cmp_ps::<_CMP_GE_OQ>(u, zero), _mm256_cmp_ps::<_CMP_GE_OQ>(v, zero)),
            _mm256_and_ps(
                _mm256_cmp_ps::<_CMP_LE_OQ>(_mm256_add_ps(u, v), _mm256_set1_ps(1.0)),
                _mm256_cmp_ps::<_CMP_NEQ_OQ>(det, zero),
            ),
        );
        let within = _mm256_and_ps(
            _mm256_cmp_ps::<_CMP_GT_OQ>(distance, zero),
            _mm256_cmp_ps::<_CMP_LT_OQ>(distance, _mm256_set1_ps(max_distance)),
        );
        let mut result = PacketHits {
            distances: [0.0; WIDTH],
            hits: _mm256_movemask_ps(_mm256_and_ps(inside, within)) as u32,
            back_faces: _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LT_OQ>(det, zero)) as u32,
        };
        _mm256_storeu_ps(result.distances.as_mut_ptr(), distance);
        result
    }
}
