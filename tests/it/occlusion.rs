//! Ambient occlusion at a point against the analytic cases of DESIGN §7, over the one BVH:
//! an open plane, a disc overhead, an infinite parallel plane with a finite ray length; and the
//! BVH's hits (nearest, skipped source triangle, back faces).

use cirrus::mesh::occlusion::{occlusion_at, OcclusionSettings, RayDistribution};
use cirrus::mesh::rays::{build_triangle_bvh, offset_ray_origin, BackFaces, TriangleBvh};
use glam::Vec3;

/// A square of side `size` at height `z`, facing up (or down when `down`), centred on x = y = 0.
fn square(size: f32, z: f32, down: bool, positions: &mut Vec<[f32; 3]>, triangles: &mut Vec<[u32; 3]>) {
    let first = positions.len() as u32;
    let half = size / 2.0;
    positions.extend([[-half, -half, z], [half, -half, z], [half, half, z], [-half, half, z]]);
    let (a, b, c, d) = (first, first + 1, first + 2, first + 3);
    if down {
        triangles.extend([[a, c, b], [a, d, c]]);
    } else {
        triangles.extend([[a, b, c], [a, c, d]]);
    }
}

/// A disc of `radius` at height `z` as a 1,024-gon facing down.
fn disc(radius: f32, z: f32, positions: &mut Vec<[f32; 3]>, triangles: &mut Vec<[u32; 3]>) {
    let centre = positions.len() as u32;
    positions.push([0.0, 0.0, z]);
    let sides = 1024u32;
    // The polygon of the same area as the circle.
    let radius = radius * (std::f32::consts::TAU / (sides as f32 * (std::f32::consts::TAU / sides as f32).sin())).sqrt();
    for side in 0..sides {
        let angle = std::f32::consts::TAU * side as f32 / sides as f32;
        positions.push([radius * angle.cos(), radius * angle.sin(), z]);
    }
    for side in 0..sides {
        triangles.push([centre, centre + 1 + (side + 1) % sides, centre + 1 + side]);
    }
}

fn settings(rays: u32, max_distance: f32, distribution: RayDistribution) -> OcclusionSettings {
    OcclusionSettings { rays, distribution, max_distance, back_faces: BackFaces::PassThrough }
}

/// Visibility at the centre of the floor (triangle 0 of a 1000-wide square at z = 0).
fn visibility_at_floor(bvh: &TriangleBvh, settings: &OcclusionSettings) -> f32 {
    occlusion_at(bvh, Vec3::new(0.01, 0.02, 0.0), Vec3::Z, 0, settings, 7).visibility
}

#[test]
fn an_open_plane_is_fully_visible() {
    let (mut positions, mut triangles) = (Vec::new(), Vec::new());
    square(1000.0, 0.0, false, &mut positions, &mut triangles);
    let bvh = build_triangle_bvh(&positions, &triangles);
    for distribution in [RayDistribution::Cosine, RayDistribution::Uniform] {
        assert_eq!(visibility_at_floor(&bvh, &settings(65_536, f32::INFINITY, distribution)), 1.0, "{distribution:?}");
    }
}

#[test]
fn a_disc_overhead_leaves_h2_over_h2_plus_r2_within_0_002() {
    for (height, radius) in [(1.0f32, 1.0f32), (2.0, 0.5), (0.5, 3.0)] {
        let (mut positions, mut triangles) = (Vec::new(), Vec::new());
        square(1000.0, 0.0, false, &mut positions, &mut triangles);
        disc(radius, height, &mut positions, &mut triangles);
        let bvh = build_triangle_bvh(&positions, &triangles);
        let expected = height * height / (height * height + radius * radius);
        for distribution in [RayDistribution::Cosine, RayDistribution::Uniform] {
            let visibility = visibility_at_floor(&bvh, &settings(65_536, f32::INFINITY, distribution));
            assert!((visibility - expected).abs() < 0.002, "h {height} r {radius} {distribution:?}: {visibility} vs {expected}");
        }
    }
}

#[test]
fn an_infinite_plane_at_h_with_rays_of_length_r_leaves_h_over_r_squared_within_0_002() {
    for (height, reach) in [(1.0f32, 2.0f32), (0.25, 1.0), (3.0, 4.0)] {
        let (mut positions, mut triangles) = (Vec::new(), Vec::new());
        square(1000.0, 0.0, false, &mut positions, &mut triangles);
        square(10_000.0, height, true, &mut positions, &mut triangles);
        let bvh = build_triangle_bvh(&positions, &triangles);
        let expected = (height / reach).powi(2);
        for distribution in [RayDistribution::Cosine, RayDistribution::Uniform] {
            let visibility = visibility_at_floor(&bvh, &settings(65_536, reach, distribution));
            assert!((visibility - expected).abs() < 0.002, "h {height} R {reach} {distribution:?}: {visibility} vs {expected}");
        }
    }
}

#[test]
fn back_faces_block_or_let_rays_through_and_are_told_apart() {
    let (mut positions, mut triangles) = (Vec::new(), Vec::new());
    square(1000.0, 0.0, false, &mut positions, &mut triangles);
    // A ceiling facing up: rays from the floor meet its back face.
    square(1000.0, 1.0, false, &mut positions, &mut triangles);
    let bvh = build_triangle_bvh(&positions, &triangles);
    // Off the squares' diagonals (a ray exactly along a shared edge is no test of faces).
    let origin = offset_ray_origin(Vec3::new(0.01, 0.02, 0.0), Vec3::Z);
    let blocked = bvh.cast(origin, Vec3::Z, f32::INFINITY, 0, BackFaces::Block);
    assert!(blocked.hit.is_some_and(|(triangle, distance)| triangle >= 2 && (distance - 1.0).abs() < 1e-4), "{blocked:?}");
    let through = bvh.cast(origin, Vec3::Z, f32::INFINITY, 0, BackFaces::PassThrough);
    assert_eq!(through.hit, None);
    assert!(through.nearest_is_back_face);
    // Under a ceiling facing away, every ray's nearest surface is a back face.
    let occlusion = occlusion_at(&bvh, Vec3::new(0.01, 0.02, 0.0), Vec3::Z, 0, &settings(256, f32::INFINITY, RayDistribution::Cosine), 1);
    assert_eq!((occlusion.visibility, occlusion.back_face_rays), (1.0, 256));
    // The source triangle is skipped; its neighbour in the same plane is never hit.
    let along = bvh.cast(origin, Vec3::new(1.0, 1.0, 0.0).normalize(), f32::INFINITY, 0, BackFaces::Block);
    assert_eq!(along.hit, None, "a ray along the floor's plane, just above it");
}

#[test]
fn the_robust_offset_keeps_rays_off_their_own_surface_at_every_scale() {
    // A tilted triangle far from the origin and one near it: a ray leaving at a grazing angle
    // never hits the triangle it leaves from (were it not skipped) at any scale.
    for scale in [1e-3f32, 1.0, 1e3, 1e5] {
        let positions = [[0.0, 0.0, 0.0], [scale, 0.1 * scale, 0.3 * scale], [0.2 * scale, scale, -0.1 * scale]]
            .map(|[x, y, z]| [x + 3.0 * scale, y - 2.0 * scale, z + 5.0 * scale]);
        let bvh = build_triangle_bvh(&positions, &[[0, 1, 2]]);
        let normal = Vec3::from(bvh.geometric_normal(0));
        let centroid = (Vec3::from(positions[0]) + Vec3::from(positions[1]) + Vec3::from(positions[2])) / 3.0;
        let origin = offset_ray_origin(centroid, normal);
        let (tangent, _) = cirrus::mesh::occlusion::orthonormal_frame(normal);
        for tilt in [1e-3f32, 1e-2, 0.1, 1.0] {
            let direction = (tangent + normal * tilt).normalize();
            let result = bvh.cast(origin, direction, f32::INFINITY, u32::MAX, BackFaces::Block);
            assert_eq!(result.hit, None, "scale {scale} tilt {tilt}");
        }
    }
}
