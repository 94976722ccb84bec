//! Plane rectangles: each plane's faces split into clusters that lie apart on the plane (a plane
//! holds faces anywhere in its ε-slab: one quad around all of them would be mostly empty), and per
//! cluster the minimum-area rectangle of the projections (rotating calipers on the convex hull),
//! which gives the quad's frame; then the faces of solid materials each quad draws besides its
//! own, to close cracks between planes.

use rayon::prelude::*;

use glam::{Vec2, Vec3};

use crate::gpu::RectangleFrame;
use crate::planes::PlaneSet;

/// A quad on a plane, `frame` (`origin + x·x_axis + y·y_axis` for x ∈ [0, width],
/// y ∈ [0, height], `x_axis × y_axis = normal`), holding `faces` (of plane `plane`).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PlaneRectangle {
    pub plane: u32,
    pub faces: Vec<u32>,
    /// Faces of other planes drawn on this one too (see [`add_crack_filling_faces`]).
    pub also_drawn: Vec<u32>,
    pub frame: RectangleFrame,
}

impl PlaneRectangle {
    /// The four corners: origin, +x, +x+y, +y.
    pub fn corners(&self) -> [Vec3; 4] {
        let frame = &self.frame;
        let (origin, x, y) =
            (Vec3::from(frame.origin), Vec3::from(frame.x_axis) * frame.width, Vec3::from(frame.y_axis) * frame.height);
        [origin, origin + x, origin + x + y, origin + y]
    }
}

/// A plane's in-plane axes (any, fixed per normal) and its faces' projection onto them.
fn plane_projection<'a>(positions: &'a [[f32; 3]], normal: Vec3) -> (Vec3, Vec3, impl Fn(u32) -> Vec2 + 'a) {
    let u = normal.any_orthonormal_vector();
    let v = normal.cross(u);
    (u, v, move |vertex: u32| {
        let p = Vec3::from(positions[vertex as usize]);
        Vec2::new(p.dot(u), p.dot(v))
    })
}

/// The minimum-area rectangle of `faces` (of plane `plane_index`) on their plane.
fn cluster_rectangle(
    positions: &[[f32; 3]],
    triangles: &[[u32; 3]],
    planes: &PlaneSet,
    plane_index: usize,
    faces: Vec<u32>,
) -> PlaneRectangle {
    let plane = &planes.planes[plane_index];
    let normal = Vec3::from(plane.normal);
    let (u, v, project) = plane_projection(positions, normal);
    let points: Vec<Vec2> = faces.iter().flat_map(|&face| triangles[face as usize]).map(project).collect();
    let (axis, min, max) = minimum_area_rectangle(&convex_hull(points));
    let x_axis = u * axis.x + v * axis.y;
    let y_axis = normal.cross(x_axis);
    let on_plane = normal * plane.distance;
    PlaneRectangle {
        plane: plane_index as u32,
        faces,
        also_drawn: Vec::new(),
        frame: RectangleFrame {
            origin: (on_plane + x_axis * min.x + y_axis * min.y).to_array(),
            x_axis: x_axis.to_array(),
            y_axis: y_axis.to_array(),
            normal: normal.to_array(),
            width: (max.x - min.x).max(0.0),
            height: (max.y - min.y).max(0.0),
        },
    }
}

/// The rectangles of every plane of `planes`, in plane order, clusters within a plane ordered by
/// their first face. Faces closer than `2ε` on the plane share a rectangle.
pub fn plane_rectangles(positions: &[[f32; 3]], triangles: &[[u32; 3]], planes: &PlaneSet) -> Vec<PlaneRectangle> {
    let mut rectangles = Vec::new();
    for (plane_index, plane) in planes.planes.iter().enumerate() {
        let (_, _, project) = plane_projection(positions, Vec3::from(plane.normal));
        for faces in clusters(&plane.faces, triangles, &project, 2.0 * planes.epsilon.max(1e-6)) {
            rectangles.push(cluster_rectangle(positions, triangles, planes, plane_index, faces));
        }
    }
    rectangles
}

/// Merges rectangles of one plane, two at a time, until there are at most `max_quads` (or one
/// per plane): each time the pair whose merged rectangle adds the least area to the two it
/// replaces, so the atlas grows as little as the budget allows. Deterministic (ties go to the
/// first pair); plane order and, within a plane, the order of first faces are kept.
pub fn merge_rectangles_to_budget(
    positions: &[[f32; 3]],
    triangles: &[[u32; 3]],
    planes: &PlaneSet,
    rectangles: Vec<PlaneRectangle>,
    max_quads: usize,
) -> Vec<PlaneRectangle> {
    let area = |rectangle: &PlaneRectangle| rectangle.frame.width as f64 * rectangle.frame.height as f64;
    let merged_faces = |a: &PlaneRectangle, b: &PlaneRectangle| {
        let mut faces: Vec<u32> = a.faces.iter().chain(&b.faces).copied().collect();
        faces.sort_unstable();
        faces
    };
    let mut by_plane: Vec<Vec<PlaneRectangle>> = vec![Vec::new(); planes.planes.len()];
    for rectangle in rectangles {
        by_plane[rectangle.plane as usize].push(rectangle);
    }
    let mut count: usize = by_plane.iter().map(Vec::len).sum();
    // Per plane, its best pair: (added area, first, second, merged rectangle).
    type Best = Option<(f64, usize, usize, PlaneRectangle)>;
    let best_pair = |plane: usize, members: &[PlaneRectangle]| -> Best {
        let mut best: Best = None;
        for first in 0..members.len() {
            for second in first + 1..members.len() {
                let merged = cluster_rectangle(
                    positions,
                    triangles,
                    planes,
                    plane,
                    merged_faces(&members[first], &members[second]),
                );
                let added = area(&merged) - area(&members[first]) - area(&members[second]);
                if best.as_ref().is_none_or(|(least, ..)| added < *least) {
                    best = Some((added, first, second, merged));
                }
            }
        }
        best
    };
    let mut bests: Vec<Best> =
        by_plane.par_iter().enumerate().map(|(plane, members)| best_pair(plane, members)).collect();
    while count > max_quads {
        let chosen = (0..bests.len())
            .filter(|&plane| bests[plane].is_some())
            .min_by(|&a, &b| bests[a].as_ref().unwrap().0.total_cmp(&bests[b].as_ref().unwrap().0).then(a.cmp(&b)));
        let Some(plane) = chosen else { break };
        let (_, first, second, merged) = bests[plane].take().expect("chosen");
        let members = &mut by_plane[plane];
        members.remove(second);
        members[first] = merged;
        count -= 1;
        bests[plane] = best_pair(plane, members);
    }
    by_plane.into_iter().flatten().collect()
}

/// The mesh as [`add_crack_filling_faces`] needs it.
pub struct CrackFillingInput<'a> {
    pub positions: &'a [[f32; 3]],
    pub triangles: &'a [[u32; 3]],
    pub face_materials: &'a [u32],
    /// Per material: a solid surface (the MTL declares no cut-out: no `map_d`, `d` = 1).
    pub solid_materials: &'a [bool],
}

/// Draws faces of solid materials also on the rectangles of other planes that they lie within
/// ε of, overlap, and whose faces already use their material, when they share a vertex with a
/// face of that plane. A solid surface split between planes (a trunk's faces around its axis)
/// otherwise shows cracks where the planes meet at an angle to the view: each plane holds only
/// its own strip of the surface, displaced by up to ε. Cracks open only where the surface
/// passes from one plane to the other; a face farther from that seam drawn twice only thickens
/// the surface (under a budget, where ε is large, on the corpus trees at 256 quads it cost
/// 0.001 to 0.006 of mean IoU).
/// Cut-out foliage is left alone: its gaps are real, and duplicates would only thicken it. The
/// materials of each rectangle, hence its render group, do not change.
pub fn add_crack_filling_faces(input: &CrackFillingInput, planes: &PlaneSet, rectangles: &mut [PlaneRectangle]) {
    let epsilon = planes.epsilon;
    let mut own_plane = vec![u32::MAX; input.triangles.len()];
    for (index, plane) in planes.planes.iter().enumerate() {
        for &face in &plane.faces {
            own_plane[face as usize] = index as u32;
        }
    }
    let mut rectangles_of_plane: Vec<Vec<usize>> = vec![Vec::new(); planes.planes.len()];
    let mut materials_of_rectangle: Vec<Vec<u32>> = Vec::with_capacity(rectangles.len());
    for (index, rectangle) in rectangles.iter().enumerate() {
        rectangles_of_plane[rectangle.plane as usize].push(index);
        materials_of_rectangle.push(crate::planes::materials_of_faces(&rectangle.faces, input.face_materials));
    }
    // The planes of the faces around each position.
    let (position_ids, distinct_positions) = crate::mesh::position_ids(input.positions);
    let mut planes_at_position: Vec<Vec<u32>> = vec![Vec::new(); distinct_positions];
    for (face, triangle) in input.triangles.iter().enumerate() {
        if own_plane[face] == u32::MAX {
            continue;
        }
        for &vertex in triangle {
            let around = &mut planes_at_position[position_ids[vertex as usize] as usize];
            if !around.contains(&own_plane[face]) {
                around.push(own_plane[face]);
            }
        }
    }
    let touches_plane = |face: u32, plane: u32| {
        input.triangles[face as usize]
            .iter()
            .any(|&vertex| planes_at_position[position_ids[vertex as usize] as usize].contains(&plane))
    };
    let solid_faces: Vec<u32> = (0..input.triangles.len() as u32)
        .filter(|&face| {
            input.solid_materials.get(input.face_materials[face as usize] as usize).copied().unwrap_or(false)
        })
        .collect();
    let pairs: Vec<(usize, u32)> = solid_faces
        .par_iter()
        .flat_map_iter(|&face| {
            let corners = input.triangles[face as usize].map(|vertex| Vec3::from(input.positions[vertex as usize]));
            let centroid = (corners[0] + corners[1] + corners[2]) / 3.0;
            let radius = corners.iter().map(|corner| corner.distance(centroid)).fold(0.0, f32::max);
            let material = input.face_materials[face as usize];
            let mut found = Vec::new();
            for (index, plane) in planes.planes.iter().enumerate() {
                let normal = Vec3::from(plane.normal);
                if index as u32 == own_plane[face as usize]
                    || (normal.dot(centroid) - plane.distance).abs() > epsilon + radius
                {
                    continue;
                }
                if corners.iter().any(|corner| (normal.dot(*corner) - plane.distance).abs() > epsilon)
                    || !touches_plane(face, index as u32)
                {
                    continue;
                }
                for &rectangle_index in &rectangles_of_plane[index] {
                    let rectangle = &rectangles[rectangle_index];
                    if materials_of_rectangle[rectangle_index].binary_search(&material).is_err() {
                        continue;
                    }
                    let (origin, x_axis, y_axis) = (
                        Vec3::from(rectangle.frame.origin),
                        Vec3::from(rectangle.frame.x_axis),
                        Vec3::from(rectangle.frame.y_axis),
                    );
                    let (mut low, mut high) = (Vec2::splat(f32::INFINITY), Vec2::splat(f32::NEG_INFINITY));
                    for corner in corners {
                        let on_plane = Vec2::new((corner - origin).dot(x_axis), (corner - origin).dot(y_axis));
                        (low, high) = (low.min(on_plane), high.max(on_plane));
                    }
                    if high.x >= 0.0
                        && high.y >= 0.0
                        && low.x <= rectangle.frame.width
                        && low.y <= rectangle.frame.height
                    {
                        found.push((rectangle_index, face));
                    }
                }
            }
            found
        })
        .collect();
    for (rectangle, face) in pairs {
        rectangles[rectangle].also_drawn.push(face);
    }
}

/// Groups faces whose projected bounding boxes come within `gap` of each other (union-find over
/// a grid of `gap`-sized cells). Each group is sorted; groups are ordered by their first face.
fn clusters(faces: &[u32], triangles: &[[u32; 3]], project: &dyn Fn(u32) -> Vec2, gap: f32) -> Vec<Vec<u32>> {
    let boxes: Vec<(Vec2, Vec2)> = faces
        .iter()
        .map(|&face| {
            let corners = triangles[face as usize].map(project);
            let min = corners.iter().fold(Vec2::splat(f32::INFINITY), |a, &c| a.min(c));
            let max = corners.iter().fold(Vec2::splat(f32::NEG_INFINITY), |a, &c| a.max(c));
            (min, max)
        })
        .collect();
    let mut parent: Vec<usize> = (0..faces.len()).collect();
    let root = crate::mesh::union_find_root;
    let cell = |value: f32| (value / gap).floor() as i64;
    let mut owners: std::collections::HashMap<(i64, i64), usize> = std::collections::HashMap::new();
    for (index, (min, max)) in boxes.iter().enumerate() {
        // Cells the box grown by half the gap touches; faces sharing a cell are joined.
        let (x0, x1, y0, y1) =
            (cell(min.x - 0.5 * gap), cell(max.x + 0.5 * gap), cell(min.y - 0.5 * gap), cell(max.y + 0.5 * gap));
        let too_many = (x1 - x0 + 1).saturating_mul(y1 - y0 + 1) > 4096;
        let step = if too_many { ((x1 - x0 + 1).max(y1 - y0 + 1) / 64).max(1) } else { 1 };
        let mut x = x0;
        while x <= x1 {
            let mut y = y0;
            while y <= y1 {
                match owners.get(&(x, y)) {
                    Some(&other) => {
                        let (a, b) = (root(&mut parent, index), root(&mut parent, other));
                        if a != b {
                            parent[a.max(b)] = a.min(b);
                        }
                    }
                    None => {
                        owners.insert((x, y), index);
                    }
                }
                y += step;
            }
            x += step;
        }
    }
    let mut groups: std::collections::BTreeMap<usize, Vec<u32>> = std::collections::BTreeMap::new();
    for (index, &face) in faces.iter().enumerate() {
        let group = root(&mut parent, index);
        groups.entry(group).or_default().push(face);
    }
    let mut groups: Vec<Vec<u32>> = groups
        .into_values()
        .map(|mut group| {
            group.sort_unstable();
            group
        })
        .collect();
    groups.sort_by_key(|group| group[0]);
    groups
}

/// Andrew's monotone chain; counter-clockwise, no collinear points.
pub fn convex_hull(mut points: Vec<Vec2>) -> Vec<Vec2> {
    points.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)));
    points.dedup();
    if points.len() < 3 {
        return points;
    }
    let cross = |o: Vec2, a: Vec2, b: Vec2| (a - o).perp_dot(b - o);
    let mut hull: Vec<Vec2> = Vec::with_capacity(points.len() * 2);
    for pass in 0..2 {
        let start = hull.len();
        let iterator: Box<dyn Iterator<Item = &Vec2>> =
            if pass == 0 { Box::new(points.iter()) } else { Box::new(points.iter().rev()) };
        for &point in iterator {
            while hull.len() >= start + 2 && cross(hull[hull.len() - 2], hull[hull.len() - 1], point) <= 0.0 {
                hull.pop();
            }
            hull.push(point);
        }
        hull.pop();
    }
    hull
}

/// The minimum-area enclosing rectangle of a convex polygon (one side is collinear with a hull
/// edge): its X direction (unit) and the min/max of the points in the (X, Y = perp X) frame.
pub fn minimum_area_rectangle(hull: &[Vec2]) -> (Vec2, Vec2, Vec2) {
    let frame = |axis: Vec2| {
        let perpendicular = axis.perp();
        let mut min = Vec2::splat(f32::INFINITY);
        let mut max = Vec2::splat(f32::NEG_INFINITY);
        for point in hull {
            let local = Vec2::new(point.dot(axis), point.dot(perpendicular));
            min = min.min(local);
            max = max.max(local);
        }
        (axis, min, max)
    };
    if hull.len() < 3 {
        let axis = match hull {
            [a, b] if (*b - *a).length() > 0.0 => (*b - *a).normalize(),
            _ => Vec2::X,
        };
        return frame(axis);
    }
    // Every hull edge direction is a candidate; the calipers' minimum is among them.
    (0..hull.len())
        .filter_map(|index| (hull[(index + 1) % hull.len()] - hull[index]).try_normalize())
        .map(frame)
        .min_by(|a, b| {
            let area = |(_, min, max): &(Vec2, Vec2, Vec2)| (max.x - min.x) * (max.y - min.y);
            area(a).total_cmp(&area(b))
        })
        .unwrap_or_else(|| frame(Vec2::X))
}
