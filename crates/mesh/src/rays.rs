//! The one BVH: a mesh's triangles for the rays of the bakes (ambient occlusion, height): the
//! nearest hit within a distance, skipping the triangle a ray leaves from, telling front faces
//! from back faces, or only whether anything blocks a ray; and the robust offset of a ray's
//! origin off its surface. `obvhs` builds a binary tree (PLOC with spatial splits and
//! reinsertion), which is collapsed here into nodes of eight boxes with leaves of eight-triangle
//! packets, traversed by the kernels of `ray_kernels` (AVX2 where the CPU has it). Measured on
//! the flight helmet's AO rays, this casts about twice as many rays per second as obvhs's own
//! compressed wide BVH (see the `occlusion` bench). Pure: plain positions and triangles in, hits
//! out.

use std::mem::MaybeUninit;

use glam::{IVec3, Vec3, Vec3A};
use obvhs::bvh2::builder::build_bvh2_from_tris;
use obvhs::bvh2::Bvh2;
use obvhs::triangle::Triangle;
use obvhs::BvhBuildParams;

use super::ray_kernels::{Kernels, Node, Packet, Portable, PreparedRay, WIDTH};

/// A child reference with this bit set is a leaf: the index of one packet.
const LEAF: u32 = 1 << 31;
/// A node's unused child slot.
const EMPTY: u32 = u32::MAX;
/// Traversal stacks up to this many entries live on the thread's stack.
const INLINE_STACK: usize = 128;

/// The triangles of a mesh and a BVH over them.
pub struct TriangleBvh {
    /// Node 0 is the root (none when there are no triangles).
    nodes: Vec<Node>,
    packets: Vec<Packet>,
    /// Each triangle's geometric normal, by mesh index (unit; zero for a degenerate one).
    normals: Vec<Vec3A>,
    /// The most entries a traversal stack can hold (depth × (WIDTH − 1) + 1).
    stack_size: usize,
    /// Whether the AVX2 kernels run (the CPU has AVX2 and FMA).
    avx2: bool,
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
    let triangles: Vec<Triangle> =
        triangles.iter().map(|&[a, b, c]| Triangle { v0: vertex(a), v1: vertex(b), v2: vertex(c) }).collect();
    let normals = triangles.iter().map(|triangle| triangle.compute_normal()).collect();
    let mut bvh =
        TriangleBvh { nodes: Vec::new(), packets: Vec::new(), normals, stack_size: 1, avx2: avx2_available() };
    if !triangles.is_empty() {
        // Fuller leaves than obvhs's default (a traversal cost of 3): eight-lane packets make a
        // leaf's triangles cheap next to a node's (about 4 % more rays per second).
        let params = BvhBuildParams {
            max_prims_per_leaf: WIDTH as u32,
            collapse_traversal_cost: 8.0,
            ..BvhBuildParams::slow_build()
        };
        let binary = build_bvh2_from_tris(&triangles, params, &mut std::time::Duration::default());
        let depth = collapse_into_wide_nodes(&mut bvh, &binary, &triangles);
        bvh.stack_size = depth * (WIDTH - 1) + 1;
    }
    bvh
}

/// Whether this CPU runs the AVX2 kernels (x86-64 with AVX2 and FMA); the portable ones otherwise.
pub fn avx2_available() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        super::ray_kernels::Avx2::available()
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

fn empty_node() -> Node {
    let mut planes = [[0.0; WIDTH]; 6];
    for axis in 0..3 {
        planes[2 * axis] = [f32::INFINITY; WIDTH];
        planes[2 * axis + 1] = [f32::NEG_INFINITY; WIDTH];
    }
    Node { planes, children: [EMPTY; WIDTH] }
}

/// Puts a child box in a node's slot, widened by a millionth of its size so that rounding in
/// the slab test never loses a grazing ray.
fn set_child(node: &mut Node, slot: usize, min: Vec3A, max: Vec3A, reference: u32) {
    let pad = (max - min).max_element().max(0.0) * 1e-6 + f32::MIN_POSITIVE;
    for axis in 0..3 {
        node.planes[2 * axis][slot] = min[axis] - pad;
        node.planes[2 * axis + 1][slot] = max[axis] + pad;
    }
    node.children[slot] = reference;
}

/// The box around some triangles.
fn bounds_of(triangles: &[Triangle], members: &[u32]) -> (Vec3A, Vec3A) {
    members.iter().fold((Vec3A::INFINITY, Vec3A::NEG_INFINITY), |(min, max), &member| {
        let triangle = &triangles[member as usize];
        (min.min(triangle.v0).min(triangle.v1).min(triangle.v2), max.max(triangle.v0).max(triangle.v1).max(triangle.v2))
    })
}

/// The reference to a leaf of up to `WIDTH` triangles: one packet.
fn packet_leaf(bvh: &mut TriangleBvh, triangles: &[Triangle], members: &[u32]) -> u32 {
    let mut packet = Packet {
        corner: [[0.0; WIDTH]; 3],
        edge1: [[0.0; WIDTH]; 3],
        edge2: [[0.0; WIDTH]; 3],
        triangles: [u32::MAX; WIDTH],
    };
    for (lane, &member) in members.iter().enumerate() {
        let triangle = &triangles[member as usize];
        let (edge1, edge2) = (triangle.v1 - triangle.v0, triangle.v2 - triangle.v0);
        for axis in 0..3 {
            packet.corner[axis][lane] = triangle.v0[axis];
            packet.edge1[axis][lane] = edge1[axis];
            packet.edge2[axis][lane] = edge2[axis];
        }
        packet.triangles[lane] = member;
    }
    bvh.packets.push(packet);
    LEAF | (bvh.packets.len() as u32 - 1)
}

/// The reference to a binary leaf's triangles: a packet, or (for more than `WIDTH`, which the
/// builder is asked not to make) a subtree of packets. Returns it and its depth in nodes.
fn leaf_reference(bvh: &mut TriangleBvh, triangles: &[Triangle], members: &[u32]) -> (u32, usize) {
    if members.len() <= WIDTH {
        return (packet_leaf(bvh, triangles, members), 0);
    }
    let slot = bvh.nodes.len();
    bvh.nodes.push(empty_node());
    let group = members.len().div_ceil(WIDTH);
    let mut depth = 0;
    for (lane, group) in members.chunks(group).enumerate() {
        let (reference, group_depth) = leaf_reference(bvh, triangles, group);
        let (min, max) = bounds_of(triangles, group);
        set_child(&mut bvh.nodes[slot], lane, min, max, reference);
        depth = depth.max(group_depth);
    }
    (slot as u32, depth + 1)
}

/// Collapses `binary` into nodes of `WIDTH` children (each node opens its largest inner
/// descendant until it has `WIDTH`); returns the depth in nodes. Iterative, so that a deep
/// binary tree cannot overflow the thread's stack.
fn collapse_into_wide_nodes(bvh: &mut TriangleBvh, binary: &Bvh2, triangles: &[Triangle]) -> usize {
    let leaf_members = |index: u32| {
        let node = &binary.nodes[index as usize];
        &binary.primitive_indices[node.first_index as usize..(node.first_index + node.prim_count) as usize]
    };
    bvh.nodes.push(empty_node());
    let root = &binary.nodes[0];
    if root.is_leaf() {
        let (reference, depth) = leaf_reference(bvh, triangles, leaf_members(0));
        set_child(&mut bvh.nodes[0], 0, root.aabb.min, root.aabb.max, reference);
        return depth + 1;
    }
    let mut deepest = 0;
    // (binary inner node, its wide node, that node's depth)
    let mut work = vec![(0u32, 0usize, 1usize)];
    while let Some((index, slot, depth)) = work.pop() {
        deepest = deepest.max(depth);
        let first = binary.nodes[index as usize].first_index;
        let mut members = vec![first, first + 1];
        while members.len() < WIDTH {
            let area = |member: &u32| binary.nodes[*member as usize].aabb.half_area();
            let largest_inner = members
                .iter()
                .enumerate()
                .filter(|(_, member)| !binary.nodes[**member as usize].is_leaf())
                .max_by(|a, b| area(a.1).total_cmp(&area(b.1)))
                .map(|(position, _)| position);
            let Some(position) = largest_inner else { break };
            let opened = binary.nodes[members.swap_remove(position) as usize].first_index;
            members.extend([opened, opened + 1]);
        }
        for (lane, member) in members.into_iter().enumerate() {
            let node = &binary.nodes[member as usize];
            let reference = if node.is_leaf() {
                let (reference, leaf_depth) = leaf_reference(bvh, triangles, leaf_members(member));
                deepest = deepest.max(depth + leaf_depth);
                reference
            } else {
                bvh.nodes.push(empty_node());
                let child = bvh.nodes.len() - 1;
                work.push((member, child, depth + 1));
                child as u32
            };
            set_child(&mut bvh.nodes[slot], lane, node.aabb.min, node.aabb.max, reference);
        }
    }
    deepest
}

/// A traversal stack over slots its caller owns: on the thread's stack when the tree is
/// shallow enough (always, but for pathological meshes), else on the heap (see
/// [`stack_slots`]). No closure: one would not inherit the AVX2 of the traversal around it.
struct Stack<'a, T: Copy> {
    slots: &'a mut [MaybeUninit<T>],
    top: usize,
}

/// The slots of a stack of `size`: `inline` when large enough, else `heap`, grown to fit.
#[inline(always)]
fn stack_slots<'a, T: Copy>(
    size: usize,
    inline: &'a mut [MaybeUninit<T>; INLINE_STACK],
    heap: &'a mut Vec<MaybeUninit<T>>,
) -> &'a mut [MaybeUninit<T>] {
    if size <= INLINE_STACK {
        inline
    } else {
        heap.resize(size, MaybeUninit::uninit());
        heap
    }
}

impl<T: Copy> Stack<'_, T> {
    #[inline(always)]
    fn push(&mut self, value: T) {
        self.slots[self.top].write(value);
        self.top += 1;
    }

    #[inline(always)]
    fn pop(&mut self) -> Option<T> {
        if self.top == 0 {
            return None;
        }
        self.top -= 1;
        // Safety: every slot below `top` was written by `push` (or `insert_sorted`).
        Some(unsafe { self.slots[self.top].assume_init() })
    }
}

impl Stack<'_, (u32, f32)> {
    /// Pushes an entry among those pushed since `base`, keeping them in decreasing distance so
    /// that the nearest is popped first.
    #[inline(always)]
    fn insert_sorted(&mut self, base: usize, entry: (u32, f32)) {
        let mut position = self.top;
        while position > base {
            // Safety: slots from `base` to `top` were written.
            let below = unsafe { self.slots[position - 1].assume_init() };
            if below.1 >= entry.1 {
                break;
            }
            self.slots[position].write(below);
            position -= 1;
        }
        self.slots[position].write(entry);
        self.top += 1;
    }
}

/// Whether anything that counts blocks the ray before `max_distance`: the first such hit ends
/// the traversal.
#[inline(always)]
unsafe fn blocked_with<K: Kernels>(
    bvh: &TriangleBvh,
    ray: &PreparedRay,
    max_distance: f32,
    skip: u32,
    back_faces: BackFaces,
) -> bool {
    let (mut inline, mut heap) = ([MaybeUninit::uninit(); INLINE_STACK], Vec::new());
    let mut stack = Stack { slots: stack_slots(bvh.stack_size, &mut inline, &mut heap), top: 0 };
    stack.push(0u32);
    while let Some(reference) = stack.pop() {
        if reference & LEAF != 0 {
            let packet = &bvh.packets[(reference & !LEAF) as usize];
            let found = K::packet(packet, ray, max_distance);
            let mut hits = found.hits;
            if back_faces == BackFaces::PassThrough {
                hits &= !found.back_faces;
            }
            while hits != 0 {
                let lane = hits.trailing_zeros() as usize;
                hits &= hits - 1;
                if packet.triangles[lane] != skip {
                    return true;
                }
            }
            continue;
        }
        let node = &bvh.nodes[reference as usize];
        let (_, mut entered) = K::node(node, ray, max_distance);
        while entered != 0 {
            let lane = entered.trailing_zeros() as usize;
            entered &= entered - 1;
            stack.push(node.children[lane]);
        }
    }
    false
}

/// The nearest hit that counts before `max_distance`, children visited nearest first.
#[inline(always)]
unsafe fn cast_with<K: Kernels>(
    bvh: &TriangleBvh,
    ray: &PreparedRay,
    max_distance: f32,
    skip: u32,
    back_faces: BackFaces,
) -> RayResult {
    let (mut inline, mut heap) = ([MaybeUninit::uninit(); INLINE_STACK], Vec::new());
    let mut stack = Stack { slots: stack_slots(bvh.stack_size, &mut inline, &mut heap), top: 0 };
    stack.push((0u32, 0.0f32));
    let mut nearest = max_distance;
    let mut hit = None;
    let mut nearest_back = f32::INFINITY;
    while let Some((reference, entry)) = stack.pop() {
        if entry > nearest {
            continue;
        }
        if reference & LEAF != 0 {
            let packet = &bvh.packets[(reference & !LEAF) as usize];
            let found = K::packet(packet, ray, nearest);
            let mut hits = found.hits;
            while hits != 0 {
                let lane = hits.trailing_zeros() as usize;
                hits &= hits - 1;
                let (triangle, distance) = (packet.triangles[lane], found.distances[lane]);
                if triangle == skip {
                    continue;
                }
                if back_faces == BackFaces::PassThrough && found.back_faces & (1 << lane) != 0 {
                    nearest_back = nearest_back.min(distance);
                } else if distance < nearest {
                    nearest = distance;
                    hit = Some((triangle, distance));
                }
            }
            continue;
        }
        let node = &bvh.nodes[reference as usize];
        let (entries, mut entered) = K::node(node, ray, nearest);
        let base = stack.top;
        while entered != 0 {
            let lane = entered.trailing_zeros() as usize;
            entered &= entered - 1;
            stack.insert_sorted(base, (node.children[lane], entries[lane]));
        }
    }
    // `nearest` is the nearest front hit's distance, or `max_distance` (beyond every back hit found).
    RayResult { hit, nearest_is_back_face: nearest_back < nearest }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn blocked_avx2(
    bvh: &TriangleBvh,
    ray: &PreparedRay,
    max_distance: f32,
    skip: u32,
    back_faces: BackFaces,
) -> bool {
    blocked_with::<super::ray_kernels::Avx2>(bvh, ray, max_distance, skip, back_faces)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn cast_avx2(
    bvh: &TriangleBvh,
    ray: &PreparedRay,
    max_distance: f32,
    skip: u32,
    back_faces: BackFaces,
) -> RayResult {
    cast_with::<super::ray_kernels::Avx2>(bvh, ray, max_distance, skip, back_faces)
}

impl TriangleBvh {
    /// A triangle's geometric normal (unit, by its winding; zero when degenerate).
    pub fn geometric_normal(&self, triangle: u32) -> [f32; 3] {
        self.normals[triangle as usize].into()
    }

    /// The same BVH traversed by the portable kernels even where AVX2 is available (to check
    /// that both give the same hits).
    pub fn without_avx2(mut self) -> TriangleBvh {
        self.avx2 = false;
        self
    }

    /// Casts a ray from `origin` along `direction` (unit) up to `max_distance`, skipping the
    /// triangle `skip` (the one the ray leaves from; `u32::MAX` for none).
    pub fn cast(
        &self,
        origin: Vec3,
        direction: Vec3,
        max_distance: f32,
        skip: u32,
        back_faces: BackFaces,
    ) -> RayResult {
        if self.nodes.is_empty() {
            return RayResult { hit: None, nearest_is_back_face: false };
        }
        let ray = PreparedRay::new(origin, direction);
        #[cfg(target_arch = "x86_64")]
        if self.avx2 {
            // Safety: `avx2` is set only where the CPU has AVX2 and FMA.
            return unsafe { cast_avx2(self, &ray, max_distance, skip, back_faces) };
        }
        // Safety: the portable kernels run on any CPU.
        unsafe { cast_with::<Portable>(self, &ray, max_distance, skip, back_faces) }
    }

    /// The mesh's point nearest `point` within `max_distance`: its triangle and distance
    /// (degenerate triangles are skipped). Children are visited nearest box first.
    pub fn nearest_point(&self, point: Vec3, max_distance: f32) -> Option<(u32, f32)> {
        if self.nodes.is_empty() {
            return None;
        }
        let mut best = max_distance * max_distance;
        let mut found = None;
        let mut stack: Vec<(u32, f32)> = Vec::with_capacity(self.stack_size);
        stack.push((0, 0.0));
        while let Some((reference, squared)) = stack.pop() {
            if squared > best {
                continue;
            }
            if reference & LEAF != 0 {
                let packet = &self.packets[(reference & !LEAF) as usize];
                for lane in 0..WIDTH {
                    let triangle = packet.triangles[lane];
                    if triangle == u32::MAX || self.normals[triangle as usize] == Vec3A::ZERO {
                        continue;
                    }
                    let axis =
                        |planes: &[[f32; WIDTH]; 3]| Vec3::new(planes[0][lane], planes[1][lane], planes[2][lane]);
                    let corner = axis(&packet.corner);
                    let nearest = closest_point_on_triangle(
                        point,
                        corner,
                        corner + axis(&packet.edge1),
                        corner + axis(&packet.edge2),
                    );
                    let squared = (nearest - point).length_squared();
                    if squared < best || (found.is_none() && squared <= best) {
                        best = squared;
                        found = Some(triangle);
                    }
                }
                continue;
            }
            let node = &self.nodes[reference as usize];
            let base = stack.len();
            for lane in 0..WIDTH {
                if node.children[lane] == EMPTY {
                    continue;
                }
                let mut squared = 0.0;
                for axis in 0..3 {
                    let (low, high) = (node.planes[2 * axis][lane], node.planes[2 * axis + 1][lane]);
                    let outside = (low - point[axis]).max(point[axis] - high).max(0.0);
                    squared += outside * outside;
                }
                if squared <= best {
                    stack.push((node.children[lane], squared));
                }
            }
            // Farthest first on the stack, so the nearest box is popped first.
            stack[base..].sort_unstable_by(|a, b| b.1.total_cmp(&a.1));
        }
        found.map(|triangle| (triangle, best.sqrt()))
    }

    /// Whether any face that counts (`back_faces`) lies within `max_distance` along the ray:
    /// traversal stops at the first such hit found, the cheap query of occlusion that needs no
    /// distance.
    pub fn blocked(&self, origin: Vec3, direction: Vec3, max_distance: f32, skip: u32, back_faces: BackFaces) -> bool {
        if self.nodes.is_empty() {
            return false;
        }
        let ray = PreparedRay::new(origin, direction);
        #[cfg(target_arch = "x86_64")]
        if self.avx2 {
            // Safety: `avx2` is set only where the CPU has AVX2 and FMA.
            return unsafe { blocked_avx2(self, &ray, max_distance, skip, back_faces) };
        }
        // Safety: the portable kernels run on any CPU.
        unsafe { blocked_with::<Portable>(self, &ray, max_distance, skip, back_faces) }
    }
}

/// The point of triangle `a b c` nearest `p` (Ericson, "Real-Time Collision Detection", 5.1.5).
pub fn closest_point_on_triangle(p: Vec3, a: Vec3, b: Vec3, c: Vec3) -> Vec3 {
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return a + ab * (d1 / (d1 - d3));
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return a + ac * (d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    }
    let denominator = 1.0 / (va + vb + vc);
    a + ab * (vb * denominator) + ac * (vc * denominator)
}

/// A ray origin moved off the surface at `point` along `normal` (the side the ray leaves
/// towards) by a few units in the last place of each coordinate (Wächter and Binder, "A Fast
/// and Robust Method for Avoiding Self-Intersection", Ray Tracing Gems, 2019): far enough that
/// the ray does not hit its own surface, near enough for any scale, no fixed epsilon.
pub fn offset_ray_origin(point: Vec3, normal: Vec3) -> Vec3 {
    const ORIGIN: f32 = 1.0 / 32.0;
    const FLOAT_SCALE: f32 = 1.0 / 65536.0;
    const INT_SCALE: f32 = 256.0;
    let offset =
        IVec3::new((INT_SCALE * normal.x) as i32, (INT_SCALE * normal.y) as i32, (INT_SCALE * normal.z) as i32);
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
