//! Plane rectangles: per plane, the minimum-area rectangle around its faces' projections
//! (rotating calipers on the convex hull), which gives the plane's frame and its quad.

use glam::{Vec2, Vec3};

use crate::planes::PlaneSet;

/// A plane's quad: `origin + x·x_axis + y·y_axis` for x ∈ [0, width], y ∈ [0, height].
/// `x_axis × y_axis = normal`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlaneRectangle {
    pub origin: [f32; 3],
    pub x_axis: [f32; 3],
    pub y_axis: [f32; 3],
    pub normal: [f32; 3],
    pub width: f32,
    pub height: f32,
}

impl PlaneRectangle {
    /// The four corners: origin, +x, +x+y, +y.
    pub fn corners(&self) -> [Vec3; 4] {
        let (origin, x, y) = (
            Vec3::from(self.origin),
            Vec3::from(self.x_axis) * self.width,
            Vec3::from(self.y_axis) * self.height,
        );
        [origin, origin + x, origin + x + y, origin + y]
    }
}

/// The rectangle of every plane of `planes`, in plane order.
pub fn plane_rectangles(
    positions: &[[f32; 3]],
    triangles: &[[u32; 3]],
    planes: &PlaneSet,
) -> Vec<PlaneRectangle> {
    planes
        .planes
        .iter()
        .map(|plane| {
            let normal = Vec3::from(plane.normal);
            let u = normal.any_orthonormal_vector();
            let v = normal.cross(u);
            let points: Vec<Vec2> = plane
                .faces
                .iter()
                .flat_map(|&face| triangles[face as usize])
                .map(|vertex| {
                    let p = Vec3::from(positions[vertex as usize]);
                    Vec2::new(p.dot(u), p.dot(v))
                })
                .collect();
            let (axis, min, max) = minimum_area_rectangle(&convex_hull(points));
            let x_axis = u * axis.x + v * axis.y;
            let y_axis = normal.cross(x_axis);
            let on_plane = normal * plane.distance;
            PlaneRectangle {
                origin: (on_plane + x_axis * min.x + y_axis * min.y).to_array(),
                x_axis: x_axis.to_array(),
                y_axis: y_axis.to_array(),
                normal: normal.to_array(),
                width: (max.x - min.x).max(0.0),
                height: (max.y - min.y).max(0.0),
            }
        })
        .collect()
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
        let iterator: Box<dyn Iterator<Item = &Vec2>> = if pass == 0 {
            Box::new(points.iter())
        } else {
            Box::new(points.iter().rev())
        };
        for &point in iterator {
            while hull.len() >= start + 2
                && cross(hull[hull.len() - 2], hull[hull.len() - 1], point) <= 0.0
            {
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
