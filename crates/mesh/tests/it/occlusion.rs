//! Ambient occlusion at a point against the analytic cases of DESIGN §7, over the one BVH:
//! an open plane, a disc overhead, an infinite parallel plane with a finite ray length; and the
//! BVH's hits (nearest, skipped source triangle, back faces).

use glam::Vec3;
use mesh::occlusion::{occlusion_at, OcclusionSettings, RayDistribution};
use mesh::rays::{build_triangle_bvh, offset_ray_origin, BackFaces, TriangleBvh};

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
    let radius =
        radius * (std::f32::consts::TAU / (sides as f32 * (std::f32::consts::TAU / sides as f32).sin())).sqrt();
    for side in 0..sides {
        let angle = std::f32::consts::TAU * side as f32 / sides as f32;
        positions.push([radius * angle.cos(), radius * angle.sin(), z]);
    }
    for side in 0..sides {
        triangles.push([centre, centre + 1 + (side + 1) % sides, centre + 1 + side]);
    }
}

fn settings(rays: u32, max_distance: f32, distribution: RayDistribution) -> OcclusionSettings {
    OcclusionSettings { rays, distribution, max_distance, back_faces: BackFaces::PassThrough, ground_plane: None }
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
            assert!(
                (visibility - expected).abs() < 0.002,
                "h {height} r {radius} {distribution:?}: {visibility} vs {expected}"
            );
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
            assert!(
                (visibility - expected).abs() < 0.002,
                "h {height} R {reach} {distribution:?}: {visibility} vs {expected}"
            );
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
    assert!(
        blocked.hit.is_some_and(|(triangle, distance)| triangle >= 2 && (distance - 1.0).abs() < 1e-4),
        "{blocked:?}"
    );
    let through = bvh.cast(origin, Vec3::Z, f32::INFINITY, 0, BackFaces::PassThrough);
    assert_eq!(through.hit, None);
    assert!(through.nearest_is_back_face);
    // Under a ceiling facing away, every ray's nearest surface is a back face.
    let occlusion = occlusion_at(
        &bvh,
        Vec3::new(0.01, 0.02, 0.0),
        Vec3::Z,
        0,
        &settings(256, f32::INFINITY, RayDistribution::Cosine),
        1,
    );
    assert_eq!((occlusion.visibility, occlusion.back_face_rays, occlusion.probe_rays), (1.0, 32, 32));
    // The source triangle is skipped; its neighbour in the same plane is never hit.
    let along = bvh.cast(origin, Vec3::new(1.0, 1.0, 0.0).normalize(), f32::INFINITY, 0, BackFaces::Block);
    assert_eq!(along.hit, None, "a ray along the floor's plane, just above it");
}

/// A small deterministic generator (SplitMix64) for the random scenes below.
struct Random(u64);

impl Random {
    fn unit(&mut self) -> f32 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        ((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 24) as f32
    }

    fn point(&mut self, scale: f32) -> Vec3 {
        Vec3::new(self.unit(), self.unit(), self.unit()) * scale
    }
}

/// Möller–Trumbore against one triangle, the definition the BVH's hits must agree with:
/// (distance, faces away from the ray).
fn brute_force_hit(corners: [Vec3; 3], origin: Vec3, direction: Vec3, max_distance: f32) -> Option<(f32, bool)> {
    let (edge1, edge2) = (corners[1] - corners[0], corners[2] - corners[0]);
    let p = direction.cross(edge2);
    let det = edge1.dot(p);
    if det == 0.0 {
        return None;
    }
    let t = origin - corners[0];
    let (u, q) = (t.dot(p) / det, t.cross(edge1));
    let (v, distance) = (direction.dot(q) / det, edge2.dot(q) / det);
    (u >= 0.0 && v >= 0.0 && u + v <= 1.0 && distance > 0.0 && distance < max_distance).then_some((distance, det < 0.0))
}

#[test]
fn the_bvh_finds_what_testing_every_triangle_finds_with_either_kernel() {
    // A soup of 3,000 random triangles of mixed sizes in a cube, with degenerate ones, a stack
    // of 40 coincident ones and a far outlier, and rays in random and axis-aligned directions
    // (negative zeros included).
    let mut random = Random(7);
    let (mut positions, mut triangles) = (Vec::new(), Vec::new());
    for index in 0..3000u32 {
        let size = [0.02, 0.2, 2.0][index as usize % 3];
        let corner = random.point(10.0);
        let mut corners = [corner, corner + random.point(size), corner + random.point(size)];
        if index % 97 == 0 {
            corners[2] = corners[1];
        }
        if index % 75 == 0 {
            corners = [Vec3::new(5.0, 5.0, 5.0), Vec3::new(6.0, 5.0, 5.5), Vec3::new(5.0, 6.0, 5.2)];
        }
        if index == 1234 {
            corners = corners.map(|corner| corner + Vec3::splat(1e4));
        }
        positions.extend(corners.map(|corner| corner.to_array()));
        triangles.push([3 * index, 3 * index + 1, 3 * index + 2]);
    }
    let corners_of = |triangle: usize| triangles[triangle].map(|vertex| Vec3::from(positions[vertex as usize]));
    let bvhs = [
        ("best", build_triangle_bvh(&positions, &triangles)),
        ("portable", build_triangle_bvh(&positions, &triangles).without_avx2()),
    ];
    // `-Vec3::X` is (-1, -0, -0): zero components with their sign bit set, as a negated normal has.
    let axes = [Vec3::X, Vec3::NEG_X, -Vec3::X, Vec3::Y, Vec3::NEG_Y, -Vec3::Y, Vec3::Z, Vec3::NEG_Z, -Vec3::Z];
    let (mut rays, mut disagreements) = (0, 0);
    for index in 0..4000usize {
        let origin = random.point(12.0) - Vec3::ONE;
        let direction = if index % 4 == 0 {
            axes[index / 4 % axes.len()]
        } else {
            (random.point(2.0) - Vec3::ONE).try_normalize().unwrap_or(Vec3::X)
        };
        let max_distance = if index % 3 == 0 { 4.0 } else { f32::INFINITY };
        let skip = if index % 5 == 0 { index as u32 % 3000 } else { u32::MAX };
        for back_faces in [BackFaces::Block, BackFaces::PassThrough] {
            // The expected nearest front hit and nearest back hit, testing every triangle.
            let (mut front, mut back) = (None::<(u32, f32)>, f32::INFINITY);
            for triangle in 0..triangles.len() {
                if triangle as u32 == skip {
                    continue;
                }
                let Some((distance, faces_away)) =
                    brute_force_hit(corners_of(triangle), origin, direction, max_distance)
                else {
                    continue;
                };
                if back_faces == BackFaces::PassThrough && faces_away {
                    back = back.min(distance);
                } else if front.is_none_or(|(_, nearest)| distance < nearest) {
                    front = Some((triangle as u32, distance));
                }
            }
            // Both kernels give the same answers to the bit (the AVX2 one where this CPU has it).
            let [best, portable] = bvhs.each_ref().map(|(_, bvh)| {
                (
                    bvh.cast(origin, direction, max_distance, skip, back_faces),
                    bvh.blocked(origin, direction, max_distance, skip, back_faces),
                )
            });
            assert_eq!(best, portable, "ray {index} {back_faces:?}: the kernels differ");
            for (name, bvh) in &bvhs {
                rays += 1;
                let cast = bvh.cast(origin, direction, max_distance, skip, back_faces);
                let blocked = bvh.blocked(origin, direction, max_distance, skip, back_faces);
                let same_hit = match (cast.hit, front) {
                    (None, None) => true,
                    // Coincident triangles: any of them at the same distance.
                    (Some((_, found)), Some((_, expected))) => (found - expected).abs() <= 1e-4 * expected.max(1.0),
                    _ => false,
                };
                let expected_back = back < front.map_or(f32::INFINITY, |(_, distance)| distance);
                if !same_hit || blocked != front.is_some() || cast.nearest_is_back_face != expected_back {
                    disagreements += 1;
                    eprintln!(
                        "{name}: ray {index} {back_faces:?}: {cast:?} blocked {blocked}, \
                         expected {front:?} back {expected_back}"
                    );
                }
            }
        }
    }
    // Where a ray grazes an edge, single-precision Möller–Trumbore may round either way against
    // the reference's division: one in 2,000 at most.
    assert!(disagreements * 2000 <= rays, "{disagreements} of {rays} rays disagree with testing every triangle");
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
        let (tangent, _) = mesh::occlusion::orthonormal_frame(normal);
        for tilt in [1e-3f32, 1e-2, 0.1, 1.0] {
            let direction = (tangent + normal * tilt).normalize();
            let result = bvh.cast(origin, direction, f32::INFINITY, u32::MAX, BackFaces::Block);
            assert_eq!(result.hit, None, "scale {scale} tilt {tilt}");
        }
    }
}

/// A floor with boxes of several sizes on it (every box a closed, outward-facing cube).
fn cluttered_floor() -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
    let (mut positions, mut triangles) = (Vec::new(), Vec::new());
    square(100.0, 0.0, false, &mut positions, &mut triangles);
    for (x, y, side, height) in
        [(1.5f32, 0.0f32, 1.0f32, 2.0f32), (-1.0, 1.2, 0.6, 0.8), (0.2, -1.6, 1.4, 0.5), (-1.8, -1.0, 0.4, 3.0)]
    {
        let first = positions.len() as u32;
        let h = side / 2.0;
        for z in [0.0, height] {
            positions.extend([[x - h, y - h, z], [x + h, y - h, z], [x + h, y + h, z], [x - h, y + h, z]]);
        }
        let quads = [[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]];
        for [a, b, c, d] in quads {
            triangles.extend([[first + a, first + b, first + c], [first + a, first + c, first + d]]);
        }
    }
    (positions, triangles)
}

#[test]
fn occlusion_converges_256_rays_within_40_db_of_16384_and_error_falls_at_least_as_n_to_the_minus_0_6() {
    let (positions, triangles) = cluttered_floor();
    let bvh = build_triangle_bvh(&positions, &triangles);
    // 400 floor points between the boxes (a 20 × 20 grid), each its own sequence shift.
    let points: Vec<Vec3> = (0..400)
        .map(|index| Vec3::new(-2.5 + 0.25 * (index % 20) as f32, -2.5 + 0.25 * (index / 20) as f32, 0.0))
        .collect();
    let bake = |rays: u32| -> Vec<f32> {
        let settings = settings(rays, f32::INFINITY, RayDistribution::Cosine);
        points
            .iter()
            .enumerate()
            .map(|(index, &point)| occlusion_at(&bvh, point, Vec3::Z, 0, &settings, index as u32).visibility)
            .collect()
    };
    let reference = bake(16_384);
    let rmse = |rays: u32| -> f64 {
        let values = bake(rays);
        (values.iter().zip(&reference).map(|(a, b)| ((a - b) as f64).powi(2)).sum::<f64>() / values.len() as f64).sqrt()
    };
    let counts = [16u32, 64, 256, 1024];
    let errors: Vec<f64> = counts.iter().map(|&rays| rmse(rays)).collect();
    let psnr_256 = 20.0 * (1.0 / errors[2]).log10();
    assert!(psnr_256 >= 40.0, "256 rays: {psnr_256:.1} dB against 16,384 ({errors:?})");
    // The least-squares slope of log RMSE against log N.
    let xs: Vec<f64> = counts.iter().map(|&n| (n as f64).ln()).collect();
    let ys: Vec<f64> = errors.iter().map(|e| e.ln()).collect();
    let (mean_x, mean_y) = (xs.iter().sum::<f64>() / 4.0, ys.iter().sum::<f64>() / 4.0);
    let slope = xs.iter().zip(&ys).map(|(x, y)| (x - mean_x) * (y - mean_y)).sum::<f64>()
        / xs.iter().map(|x| (x - mean_x).powi(2)).sum::<f64>();
    assert!(slope <= -0.6, "RMSE slope {slope:.2} ({errors:?})");
}

#[test]
fn occlusion_is_the_same_whatever_the_thread_count() {
    use rayon::prelude::*;
    let (positions, triangles) = cluttered_floor();
    let bvh = build_triangle_bvh(&positions, &triangles);
    let settings = settings(64, 2.0, RayDistribution::Cosine);
    let bake = |threads: usize| -> Vec<u32> {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| {
            (0..2000u32)
                .into_par_iter()
                .map(|index| {
                    let point = Vec3::new(-2.5 + 0.05 * (index % 100) as f32, -2.5 + 0.25 * (index / 100) as f32, 0.0);
                    occlusion_at(&bvh, point, Vec3::Z, 0, &settings, index).visibility.to_bits()
                })
                .collect()
        })
    };
    assert_eq!(bake(1), bake(3));
}

#[test]
fn a_wall_over_an_infinite_ground_plane_sees_half_its_hemisphere() {
    // A vertical wall facing +X; the ground (y = 0) blocks every ray that goes down.
    let positions = [[0.0f32, 1.0, -1.0], [0.0, 1.0, 1.0], [0.0, 3.0, 1.0], [0.0, 3.0, -1.0]];
    let bvh = build_triangle_bvh(&positions, &[[0, 2, 1], [0, 3, 2]]);
    assert!(Vec3::from(bvh.geometric_normal(0)).dot(Vec3::X) > 0.99);
    for distribution in [RayDistribution::Cosine, RayDistribution::Uniform] {
        let settings = OcclusionSettings { ground_plane: Some(0.0), ..settings(65_536, f32::INFINITY, distribution) };
        let visibility = occlusion_at(&bvh, Vec3::new(0.0, 2.0, 0.1), Vec3::X, 0, &settings, 3).visibility;
        assert!((visibility - 0.5).abs() < 0.002, "{distribution:?}: {visibility}");
    }
}

#[test]
fn texels_bake_the_occlusion_of_their_surface_point_and_tiles_bake_what_the_whole_image_does() {
    use mesh::occlusion::{build_occluders, occlusion_of_texels, Casting};
    use mesh::uv_raster::{rasterize_uv, TexelRegion};
    // A UV-mapped floor (4 × 4, UVs over [0, 1]², normals up) under a disc.
    let mut positions = vec![[-2.0f32, 0.0, 2.0], [2.0, 0.0, 2.0], [2.0, 0.0, -2.0], [-2.0, 0.0, -2.0]];
    let uvs = [[0.0f32, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
    let mut triangles = vec![[0u32, 1, 2], [0, 2, 3]];
    // The disc over the floor, in the XZ plane at y = 1, facing down.
    let (mut disc_positions, mut disc_triangles) = (Vec::new(), Vec::new());
    disc(1.0, 1.0, &mut disc_positions, &mut disc_triangles);
    let first = positions.len() as u32;
    positions.extend(disc_positions.iter().map(|&[x, y, z]| [x, z, -y]));
    triangles.extend(disc_triangles.iter().map(|&[a, b, c]| [a + first, b + first, c + first]));
    let normals: Vec<[f32; 3]> = positions.iter().map(|_| [0.0, 1.0, 0.0]).collect();
    let bvh = build_triangle_bvh(&positions, &triangles);
    assert!(Vec3::from(bvh.geometric_normal(0)).dot(Vec3::Y) > 0.99, "the floor faces up");
    let settings = settings(1024, f32::INFINITY, RayDistribution::Cosine);
    let size = 16u32;
    let whole = TexelRegion { x: 0, y: 0, width: size, height: size };
    let coverage = rasterize_uv(&uvs, &triangles, &[0, 1], (size, size), whole);
    let occluders = build_occluders(&positions, &triangles, None);
    let baked = occlusion_of_texels(
        &occluders,
        &positions,
        &normals,
        &triangles,
        &coverage,
        size,
        Casting { settings: &settings, should_stop: &base::stop::never },
    )
    .unwrap();
    // Texel (8, 8): its centre (u, v) = (0.53125, 0.46875) is floor point (0.125, 0, 0.125), seed 8 × 16 + 8.
    let sample = coverage.sample(8, 8).unwrap();
    let expected = occlusion_at(&bvh, Vec3::new(0.125, 0.0, 0.125), Vec3::Y, sample.triangle, &settings, 8 * size + 8);
    let texel = baked[8 * size as usize + 8].unwrap();
    assert!((texel.visibility - expected.visibility).abs() < 1e-6, "{texel:?} vs {expected:?}");
    assert!(texel.visibility < 0.6 && baked[0].unwrap().visibility > 0.9, "under the disc darker than the corner");
    // Four tiles bake the same bits.
    for (x, y) in [(0, 0), (8, 0), (0, 8), (8, 8)] {
        let region = TexelRegion { x, y, width: 8, height: 8 };
        let tile = rasterize_uv(&uvs, &triangles, &[0, 1], (size, size), region);
        let tile_baked = occlusion_of_texels(
            &occluders,
            &positions,
            &normals,
            &triangles,
            &tile,
            size,
            Casting { settings: &settings, should_stop: &base::stop::never },
        )
        .unwrap();
        for row in 0..8 {
            for column in 0..8 {
                let in_whole = baked[((y + row) * size + x + column) as usize].map(|o| o.visibility.to_bits());
                assert_eq!(tile_baked[(row * 8 + column) as usize].map(|o| o.visibility.to_bits()), in_whole);
            }
        }
    }
}
