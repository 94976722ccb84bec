//! PN triangles (Vlachos, Peters, Boyd, Mitchell, "Curved PN Triangles", I3D 2001): a cubic
//! Bézier patch per triangle from its corners' positions and normals (ten control points
//! `b_ijk` with the paper's `w_ij`), a quadratic normal field (six `n_ijk` with the paper's
//! `v_ij`), and a mesh tessellated into `level` segments per edge and optionally displaced along
//! the PN normal. Crack-free where normals are split (hard edges, UV seams): the geometry uses
//! one averaged normal per position (the PN-AEN idea), every point on an edge is computed once
//! from the edge alone, and a displaced point shared by two triangles reads the height at one
//! UV. Pure: positions, normals, UVs and triangles in, a tessellated mesh out.

use std::collections::HashMap;

use glam::Vec3;

/// The cubic patch and quadratic normal field of one triangle. Control points in the paper's
/// order: `b300, b030, b003, b210, b120, b021, b012, b102, b201, b111`; normals
/// `n200, n020, n002, n110, n011, n101`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PnPatch {
    pub b: [Vec3; 10],
    pub n: [Vec3; 6],
}

/// `w_ij = (P_j − P_i) · N_i`: how far `P_j` lies along `N_i`.
fn w(p_i: Vec3, p_j: Vec3, n_i: Vec3) -> f32 {
    (p_j - p_i).dot(n_i)
}

/// The edge control point next to `P_i` on the edge `P_i P_j`: `(2 P_i + P_j − w_ij N_i) / 3`.
fn edge_control(p_i: Vec3, p_j: Vec3, n_i: Vec3) -> Vec3 {
    (2.0 * p_i + p_j - w(p_i, p_j, n_i) * n_i) / 3.0
}

/// The mid-edge normal `n_ij`: `N_i + N_j − v_ij (P_j − P_i)` normalised, with
/// `v_ij = 2 (P_j − P_i) · (N_i + N_j) / ((P_j − P_i) · (P_j − P_i))` (the normals reflected
/// across the plane through the edge's middle, perpendicular to it). Symmetric in `i`, `j`.
fn mid_edge_normal(p_i: Vec3, p_j: Vec3, n_i: Vec3, n_j: Vec3) -> Vec3 {
    let edge = p_j - p_i;
    let length_squared = edge.dot(edge);
    let v = if length_squared > 0.0 { 2.0 * edge.dot(n_i + n_j) / length_squared } else { 0.0 };
    let normal = (n_i + n_j - v * edge).normalize_or_zero();
    if normal == Vec3::ZERO {
        (n_i + n_j).normalize_or_zero()
    } else {
        normal
    }
}

/// The patch of a triangle with corners `p` and unit normals `n` (the paper's `P1, P2, P3`,
/// `N1, N2, N3`).
pub fn pn_patch(p: [Vec3; 3], n: [Vec3; 3]) -> PnPatch {
    let [p1, p2, p3] = p;
    let [n1, n2, n3] = n;
    let b210 = edge_control(p1, p2, n1);
    let b120 = edge_control(p2, p1, n2);
    let b021 = edge_control(p2, p3, n2);
    let b012 = edge_control(p3, p2, n3);
    let b102 = edge_control(p3, p1, n3);
    let b201 = edge_control(p1, p3, n1);
    let e = (b210 + b120 + b021 + b012 + b102 + b201) / 6.0;
    let v = (p1 + p2 + p3) / 3.0;
    let b111 = e + (e - v) / 2.0;
    PnPatch {
        b: [p1, p2, p3, b210, b120, b021, b012, b102, b201, b111],
        n: [
            n1,
            n2,
            n3,
            mid_edge_normal(p1, p2, n1, n2),
            mid_edge_normal(p2, p3, n2, n3),
            mid_edge_normal(p3, p1, n3, n1),
        ],
    }
}

impl PnPatch {
    /// The point at barycentric weights `[w, u, v]` of corners 1, 2, 3:
    /// `Σ b_ijk 3!/(i! j! k!) w^i u^j v^k`.
    pub fn position(&self, [w, u, v]: [f32; 3]) -> Vec3 {
        let b = &self.b;
        b[0] * (w * w * w)
            + b[1] * (u * u * u)
            + b[2] * (v * v * v)
            + b[3] * (3.0 * w * w * u)
            + b[4] * (3.0 * w * u * u)
            + b[5] * (3.0 * u * u * v)
            + b[6] * (3.0 * u * v * v)
            + b[7] * (3.0 * w * v * v)
            + b[8] * (3.0 * w * w * v)
            + b[9] * (6.0 * w * u * v)
    }

    /// The unit normal at `[w, u, v]`: the paper's quadratic
    /// `n200 w² + n020 u² + n002 v² + n110 w u + n011 u v + n101 w v`, normalised.
    pub fn normal(&self, [w, u, v]: [f32; 3]) -> Vec3 {
        let n = &self.n;
        (n[0] * (w * w) + n[1] * (u * u) + n[2] * (v * v) + n[3] * (w * u) + n[4] * (u * v) + n[5] * (w * v))
            .normalize_or_zero()
    }
}

/// The point and unit normal at `t` along the PN edge from `(p_a, n_a)` to `(p_b, n_b)`: the
/// patch restricted to an edge depends on that edge alone, so two triangles sharing it get the
/// same curve (computed here once, in one order, so to the bit).
pub(crate) fn pn_edge_point(p_a: Vec3, n_a: Vec3, p_b: Vec3, n_b: Vec3, t: f32) -> (Vec3, Vec3) {
    let s = 1.0 - t;
    let (b_a, b_b) = (edge_control(p_a, p_b, n_a), edge_control(p_b, p_a, n_b));
    let position = p_a * (s * s * s) + b_a * (3.0 * s * s * t) + b_b * (3.0 * s * t * t) + p_b * (t * t * t);
    let n_ab = mid_edge_normal(p_a, p_b, n_a, n_b);
    let normal = (n_a * (s * s) + n_ab * (s * t) + n_b * (t * t)).normalize_or_zero();
    (position, normal)
}

/// A mesh as the tessellator reads it.
#[derive(Clone, Copy)]
pub struct PnInput<'a> {
    pub positions: &'a [[f32; 3]],
    /// Unit vertex normals (may differ between vertices at one position: hard edges).
    pub normals: &'a [[f32; 3]],
    pub uvs: Option<&'a [[f32; 2]]>,
    pub triangles: &'a [[u32; 3]],
}

/// One id per distinct position (by exact coordinates), and per id the average of the distinct
/// normals its vertices carry (the geometry's normal there; a face-area average where those
/// cancel out).
pub fn averaged_normals(input: &PnInput) -> (Vec<u32>, Vec<Vec3>) {
    let (position_ids, distinct_positions) = super::position_ids(input.positions);
    let mut seen: HashMap<(u32, [u32; 3]), ()> = HashMap::new();
    let mut sums = vec![Vec3::ZERO; distinct_positions];
    for (vertex, normal) in input.normals.iter().enumerate() {
        let id = position_ids[vertex];
        if seen.insert((id, normal.map(f32::to_bits)), ()).is_none() {
            sums[id as usize] += Vec3::from(*normal);
        }
    }
    let mut area_sums = vec![Vec3::ZERO; distinct_positions];
    for triangle in input.triangles {
        let [a, b, c] = triangle.map(|vertex| Vec3::from(input.positions[vertex as usize]));
        let face = (b - a).cross(c - a);
        for &vertex in triangle {
            area_sums[position_ids[vertex as usize] as usize] += face;
        }
    }
    let averaged = sums
        .iter()
        .zip(&area_sums)
        .map(|(sum, area)| {
            let normal = sum.normalize_or_zero();
            if normal == Vec3::ZERO {
                area.normalize_or_zero()
            } else {
                normal
            }
        })
        .collect();
    (position_ids, averaged)
}

/// A tessellated mesh. Vertices are shared between triangles wherever the input's are (the same
/// corners, the same edge); along a split edge each side has its own vertices, at the same
/// positions to the bit.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PnMesh {
    pub positions: Vec<[f32; 3]>,
    /// Shading normals: the PN normal field of the input's own (split) normals.
    pub normals: Vec<[f32; 3]>,
    /// Texture coordinates interpolated in each input triangle (empty when the input has none).
    pub uvs: Vec<[f32; 2]>,
    pub triangles: Vec<[u32; 3]>,
    /// The input triangle each triangle lies in.
    pub source_triangles: Vec<u32>,
    /// The direction a vertex is displaced along: the PN normal of the averaged normals, the
    /// same for every vertex at one position.
    pub displace_normals: Vec<[f32; 3]>,
    /// The UV a vertex reads its displacement at: one per position (that of the first triangle
    /// reaching it), so both sides of a UV seam move alike.
    pub displace_uvs: Vec<[f32; 2]>,
}

/// One vertex of a tessellation, before it joins the mesh.
struct TessellatedVertex {
    point: Vec3,
    shading: Vec3,
    uv: Option<glam::Vec2>,
    direction: Vec3,
    displace_uv: glam::Vec2,
}

impl PnMesh {
    /// Appends a vertex; returns its index.
    fn push_vertex(&mut self, vertex: &TessellatedVertex) -> u32 {
        self.positions.push(vertex.point.into());
        self.normals.push(vertex.shading.into());
        if let Some(uv) = vertex.uv {
            self.uvs.push(uv.into());
        }
        self.displace_normals.push(vertex.direction.into());
        self.displace_uvs.push(vertex.displace_uv.into());
        self.positions.len() as u32 - 1
    }
}

/// Where a tessellated corner or edge vertex lies, for sharing it: by the input's vertices (one
/// vertex per attribute set) or by position ids (one geometry per position).
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
enum GridKey {
    Corner(u32),
    /// Ends (ordered), and the step from the first end.
    Edge(u32, u32, u32),
}

/// A grid point `(a, b)` of a triangle tessellated into `level` segments (barycentric
/// `[(level − a − b), a, b] / level` of corners 0, 1, 2): which corner, edge or interior point it
/// is, as (end, end, steps from the first end) for edges.
fn grid_place(a: u32, b: u32, level: u32) -> Place {
    match (a, b) {
        (0, 0) => Place::Corner(0),
        (a, 0) if a == level => Place::Corner(1),
        (0, b) if b == level => Place::Corner(2),
        (a, 0) => Place::Edge(0, 1, a),
        (0, b) => Place::Edge(0, 2, b),
        (a, b) if a + b == level => Place::Edge(1, 2, b),
        _ => Place::Interior,
    }
}

enum Place {
    Corner(usize),
    Edge(usize, usize, u32),
    Interior,
}

/// The key of an edge point by two ends' ids (ordered so that both triangles agree) and steps.
fn edge_key(first: u32, second: u32, steps: u32, level: u32) -> (u32, u32, u32, bool) {
    if first <= second {
        (first, second, steps, false)
    } else {
        (second, first, level - steps, true)
    }
}

/// Tessellates every triangle of `input` into `level`² triangles on its PN patch.
pub fn tessellate(input: &PnInput, level: u32) -> PnMesh {
    let level = level.max(1);
    let (position_ids, averaged) = averaged_normals(input);
    let vertex = |index: u32| Vec3::from(input.positions[index as usize]);
    let normal = |index: u32| Vec3::from(input.normals[index as usize]).normalize_or_zero();
    let uv = |index: u32| input.uvs.map_or(glam::Vec2::ZERO, |uvs| glam::Vec2::from(uvs[index as usize]));
    let mut mesh = PnMesh::default();
    // Geometry by position: point, displacement normal, displacement UV.
    let mut geometry: HashMap<GridKey, (Vec3, Vec3, glam::Vec2)> = HashMap::new();
    let mut vertices: HashMap<GridKey, u32> = HashMap::new();
    let per_side = level as usize + 1;
    let mut grid = vec![0u32; per_side * per_side];
    for (triangle_index, corners) in input.triangles.iter().enumerate() {
        let triangle_index = triangle_index as u32;
        let p = corners.map(vertex);
        let ids = corners.map(|corner| position_ids[corner as usize]);
        let geometry_patch = pn_patch(p, ids.map(|id| averaged[id as usize]));
        let shading_patch = pn_patch(p, corners.map(normal));
        let uvs = corners.map(uv);
        for a in 0..=level {
            for b in 0..=level - a {
                let weights = [(level - a - b) as f32 / level as f32, a as f32 / level as f32, b as f32 / level as f32];
                let here_uv = uvs[0] * weights[0] + uvs[1] * weights[1] + uvs[2] * weights[2];
                // Where the vertex is shared (corners and edges, by the input's vertices; none
                // inside a triangle), and its geometry: by position, computed once, at corners
                // and edges; straight from the patch inside.
                let (vertex_key, (point, direction, displace_uv), shading) = match grid_place(a, b, level) {
                    Place::Corner(corner) => {
                        let geometry = *geometry.entry(GridKey::Corner(ids[corner])).or_insert((
                            p[corner],
                            averaged[ids[corner] as usize],
                            here_uv,
                        ));
                        (Some(GridKey::Corner(corners[corner])), geometry, normal(corners[corner]))
                    }
                    Place::Edge(from, to, steps) => {
                        let (first, second, steps_from_first, _) = edge_key(corners[from], corners[to], steps, level);
                        let (id_first, id_second, id_steps, flipped) = edge_key(ids[from], ids[to], steps, level);
                        let (end_a, end_b) = if flipped { (to, from) } else { (from, to) };
                        let t = id_steps as f32 / level as f32;
                        let shading = {
                            let (lo, hi) = if corners[from] <= corners[to] { (from, to) } else { (to, from) };
                            let t = steps_from_first as f32 / level as f32;
                            pn_edge_point(p[lo], normal(corners[lo]), p[hi], normal(corners[hi]), t).1
                        };
                        let geometry =
                            *geometry.entry(GridKey::Edge(id_first, id_second, id_steps)).or_insert_with(|| {
                                let (point, direction) = pn_edge_point(
                                    p[end_a],
                                    averaged[ids[end_a] as usize],
                                    p[end_b],
                                    averaged[ids[end_b] as usize],
                                    t,
                                );
                                (point, direction, here_uv)
                            });
                        (Some(GridKey::Edge(first, second, steps_from_first)), geometry, shading)
                    }
                    Place::Interior => {
                        let geometry = (geometry_patch.position(weights), geometry_patch.normal(weights), here_uv);
                        (None, geometry, shading_patch.normal(weights))
                    }
                };
                let vertex =
                    TessellatedVertex { point, shading, uv: input.uvs.map(|_| here_uv), direction, displace_uv };
                let index = match vertex_key {
                    Some(key) => *vertices.entry(key).or_insert_with(|| mesh.push_vertex(&vertex)),
                    None => mesh.push_vertex(&vertex),
                };
                grid[a as usize * per_side + b as usize] = index;
            }
        }
        let at = |a: u32, b: u32| grid[a as usize * per_side + b as usize];
        for a in 0..level {
            for b in 0..level - a {
                mesh.triangles.push([at(a, b), at(a + 1, b), at(a, b + 1)]);
                mesh.source_triangles.push(triangle_index);
                if a + b + 1 < level {
                    mesh.triangles.push([at(a + 1, b), at(a + 1, b + 1), at(a, b + 1)]);
                    mesh.source_triangles.push(triangle_index);
                }
            }
        }
    }
    mesh
}

/// The tessellated mesh moved along its displacement normals by `height(displace_uv)` per
/// vertex, with shading normals recomputed from the moved faces (area-weighted, shared by the
/// vertices at one position with one shading normal, so hard edges stay hard and UV seams smooth).
pub fn displaced(mesh: &PnMesh, height: impl Fn([f32; 2]) -> f32 + Sync) -> PnMesh {
    use rayon::prelude::*;
    let positions: Vec<[f32; 3]> = (0..mesh.positions.len())
        .into_par_iter()
        .map(|vertex| {
            let offset = height(mesh.displace_uvs[vertex]);
            (Vec3::from(mesh.positions[vertex]) + Vec3::from(mesh.displace_normals[vertex]) * offset).into()
        })
        .collect();
    let normals = smooth_normals(&positions, &mesh.normals, &mesh.triangles);
    PnMesh { positions, normals, ..mesh.clone() }
}

/// Area-weighted face normals summed per (position, input normal) and normalised; a vertex
/// whose faces cancel keeps its input normal.
pub(crate) fn smooth_normals(positions: &[[f32; 3]], normals: &[[f32; 3]], triangles: &[[u32; 3]]) -> Vec<[f32; 3]> {
    let mut groups: HashMap<([u32; 3], [u32; 3]), u32> = HashMap::new();
    let group_of: Vec<u32> = positions
        .iter()
        .zip(normals)
        .map(|(position, normal)| {
            let next = groups.len() as u32;
            *groups.entry((position.map(f32::to_bits), normal.map(f32::to_bits))).or_insert(next)
        })
        .collect();
    let mut sums = vec![Vec3::ZERO; groups.len()];
    for triangle in triangles {
        let [a, b, c] = triangle.map(|vertex| Vec3::from(positions[vertex as usize]));
        let face = (b - a).cross(c - a);
        for &vertex in triangle {
            sums[group_of[vertex as usize] as usize] += face;
        }
    }
    group_of
        .iter()
        .zip(normals)
        .map(|(&group, &normal)| {
            let sum = sums[group as usize].normalize_or_zero();
            if sum == Vec3::ZERO {
                normal
            } else {
                sum.into()
            }
        })
        .collect()
}

/// Edges used by exactly one triangle after welding vertices by exact position: 0 for a closed
/// (watertight) surface.
pub fn boundary_edge_count(positions: &[[f32; 3]], triangles: &[[u32; 3]]) -> usize {
    let mut ids: HashMap<[u32; 3], u32> = HashMap::new();
    let welded: Vec<u32> = positions
        .iter()
        .map(|position| {
            let next = ids.len() as u32;
            *ids.entry(position.map(f32::to_bits)).or_insert(next)
        })
        .collect();
    let mut uses: HashMap<(u32, u32), u32> = HashMap::new();
    for triangle in triangles {
        for corner in 0..3 {
            let (a, b) = (welded[triangle[corner] as usize], welded[triangle[(corner + 1) % 3] as usize]);
            if a != b {
                *uses.entry((a.min(b), a.max(b))).or_default() += 1;
            }
        }
    }
    uses.values().filter(|&&count| count == 1).count()
}
