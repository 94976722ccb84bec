//! The PN-triangle library against the paper's properties: a patch interpolates its corners
//! and their normals, a flat triangle stays flat, a sphere's PN surface is closer to the sphere
//! than its facets; tessellation (and displacement) of a closed mesh stays closed, split
//! normals and UV seams included.

use glam::Vec3;
use mesh::pn_triangles::{boundary_edge_count, displaced, pn_patch, tessellate, PnInput};

#[test]
fn a_patch_interpolates_its_corners_and_their_normals() {
    let p = [Vec3::new(0.0, 0.0, 0.0), Vec3::new(1.0, 0.2, 0.0), Vec3::new(0.1, -0.3, 1.0)];
    let n = [
        Vec3::new(0.3, 1.0, 0.1).normalize(),
        Vec3::new(-0.2, 1.0, 0.4).normalize(),
        Vec3::new(0.0, 0.8, -0.6).normalize(),
    ];
    let patch = pn_patch(p, n);
    for corner in 0..3 {
        let mut weights = [0.0; 3];
        weights[corner] = 1.0;
        assert_eq!(patch.position(weights), p[corner], "corner {corner}");
        assert!((patch.normal(weights) - n[corner]).length() < 1e-6, "normal {corner}");
    }
    // The mid-edge point is not the chord's: the patch bends.
    assert!((patch.position([0.5, 0.5, 0.0]) - (p[0] + p[1]) / 2.0).length() > 1e-3);
}

#[test]
fn a_flat_triangle_stays_flat() {
    let p = [Vec3::new(0.0, 1.0, 0.0), Vec3::new(2.0, 1.0, 0.5), Vec3::new(0.3, 1.0, 1.5)];
    let normal = (p[2] - p[0]).cross(p[1] - p[0]).normalize();
    let patch = pn_patch(p, [normal; 3]);
    for a in 0..=10 {
        for b in 0..=10 - a {
            let weights = [(10 - a - b) as f32 / 10.0, a as f32 / 10.0, b as f32 / 10.0];
            assert!((patch.position(weights).y - 1.0).abs() < 1e-6, "{weights:?}");
            assert!((patch.normal(weights) - normal).length() < 1e-6, "{weights:?}");
        }
    }
}

/// An octahedron subdivided `steps` times onto the unit sphere, normals radial.
fn sphere(steps: u32) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
    let mut positions: Vec<Vec3> = vec![Vec3::X, Vec3::NEG_X, Vec3::Y, Vec3::NEG_Y, Vec3::Z, Vec3::NEG_Z];
    let mut triangles = vec![[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]];
    for _ in 0..steps {
        let mut middles = std::collections::HashMap::new();
        let mut next = Vec::new();
        for [a, b, c] in triangles {
            let mut middle = |i: u32, j: u32| {
                *middles.entry((i.min(j), i.max(j))).or_insert_with(|| {
                    positions.push(((positions[i as usize] + positions[j as usize]) / 2.0).normalize());
                    positions.len() as u32 - 1
                })
            };
            let (ab, bc, ca) = (middle(a, b), middle(b, c), middle(c, a));
            next.extend([[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]]);
        }
        triangles = next;
    }
    (positions.into_iter().map(Into::into).collect(), triangles)
}

#[test]
fn a_spheres_pn_surface_is_closer_to_the_sphere_than_its_facets() {
    let (positions, triangles) = sphere(1);
    let input = PnInput { positions: &positions, normals: &positions, uvs: None, triangles: &triangles };
    let pn = tessellate(&input, 8);
    // The facets at the same barycentric points.
    let mut flat = Vec::new();
    for triangle in &triangles {
        let [a, b, c] = triangle.map(|vertex| Vec3::from(positions[vertex as usize]));
        for i in 0..=8 {
            for j in 0..=8 - i {
                let (u, v) = (i as f32 / 8.0, j as f32 / 8.0);
                flat.push((a * (1.0 - u - v) + b * u + c * v).to_array());
            }
        }
    }
    let radial_error = |mesh: &[[f32; 3]]| {
        let squares: f64 = mesh.iter().map(|&p| (Vec3::from(p).length() as f64 - 1.0).powi(2)).sum();
        (squares / mesh.len() as f64).sqrt()
    };
    let (pn_error, flat_error) = (radial_error(&pn.positions), radial_error(&flat));
    assert!(pn_error < flat_error / 4.0, "PN {pn_error} against facets {flat_error}");
    assert_eq!(pn.triangles.len(), triangles.len() * 64);
}

/// A cube with a normal and a UV rectangle per face (24 vertices): every edge a hard edge and
/// a UV seam.
/// Positions, normals, UVs, triangles.
type MeshArrays = (Vec<[f32; 3]>, Vec<[f32; 3]>, Vec<[f32; 2]>, Vec<[u32; 3]>);

fn split_cube() -> MeshArrays {
    let (mut positions, mut normals, mut uvs, mut triangles) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for axis in 0..3 {
        for sign in [-1.0f32, 1.0] {
            let mut normal = Vec3::ZERO;
            normal[axis] = sign;
            let (u, v) = normal.any_orthonormal_pair();
            let first = positions.len() as u32;
            let face = (axis * 2 + (sign > 0.0) as usize) as f32;
            for (s, t) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
                positions.push((normal + u * s + v * t).to_array());
                normals.push(normal.to_array());
                uvs.push([(face + (s + 1.0) / 2.0 * 0.9) / 6.0, (t + 1.0) / 2.0]);
            }
            let (a, b) = if u.cross(v).dot(normal) > 0.0 { ([0, 1, 2], [0, 2, 3]) } else { ([0, 2, 1], [0, 3, 2]) };
            triangles.push(a.map(|corner| first + corner));
            triangles.push(b.map(|corner| first + corner));
        }
    }
    (positions, normals, uvs, triangles)
}

#[test]
fn closed_meshes_stay_closed_through_tessellation_and_displacement_split_normals_and_seams_included() {
    let (positions, normals, uvs, triangles) = split_cube();
    assert_eq!(boundary_edge_count(&positions, &triangles), 0, "the cube is closed");
    let input = PnInput { positions: &positions, normals: &normals, uvs: Some(&uvs), triangles: &triangles };
    for level in [1, 2, 5, 8] {
        let pn = tessellate(&input, level);
        assert_eq!(boundary_edge_count(&pn.positions, &pn.triangles), 0, "level {level}");
        // A height that differs across every seam: each position still moves once.
        let moved = displaced(&pn, |[u, v]| 0.1 * (u * 37.0).sin() * (v * 11.0).cos());
        assert_eq!(boundary_edge_count(&moved.positions, &moved.triangles), 0, "level {level} displaced");
        // Hard edges stay hard: the shading normals at a cube corner differ by face.
        let corner = Vec3::from(positions[0]);
        let corner_normals: std::collections::BTreeSet<[u32; 3]> = (0..pn.positions.len())
            .filter(|&vertex| Vec3::from(pn.positions[vertex]) == corner)
            .map(|vertex| pn.normals[vertex].map(f32::to_bits))
            .collect();
        assert_eq!(corner_normals.len(), 3, "three faces meet at a corner, each with its normal");
    }
    // The corners' averaged normal bulges the faces outward.
    let pn = tessellate(&input, 4);
    let centre_of_top =
        pn.positions.iter().map(|&p| Vec3::from(p)).filter(|p| p.x.abs() < 1e-6 && p.z.abs() < 1e-6 && p.y > 0.0);
    assert!(centre_of_top.into_iter().all(|p| p.y > 1.01), "the face centre moved out");
}
