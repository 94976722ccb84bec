//! Plane selection: every face assigned once and within ε of its plane (unless capped),
//! coplanar faces share a plane, the cap holds, and the result is deterministic.

use cirrus::kinds::billboard_cloud::planes::{select_planes, PlaneSet, PlaneSettings};

fn settings(epsilon: f32) -> PlaneSettings {
    PlaneSettings { epsilon, max_planes: None, max_quads: None }
}

/// The largest distance of a vertex of each plane's faces from that plane, and a check that
/// every face is assigned exactly once.
fn check_assignment(positions: &[[f32; 3]], triangles: &[[u32; 3]], set: &PlaneSet) -> f32 {
    let mut seen = vec![0u32; triangles.len()];
    let mut worst = 0.0f32;
    for plane in &set.planes {
        let normal = glam::Vec3::from(plane.normal);
        assert!((normal.length() - 1.0).abs() < 1e-4, "unit normal");
        for &face in &plane.faces {
            seen[face as usize] += 1;
            for &vertex in &triangles[face as usize] {
                worst = worst.max((glam::Vec3::from(positions[vertex as usize]).dot(normal) - plane.distance).abs());
            }
        }
    }
    assert!(seen.iter().all(|&count| count == 1), "every face exactly once: {seen:?}");
    worst
}

fn cube() -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
    let positions = (0..8).map(|i| [(i & 1) as f32, ((i >> 1) & 1) as f32, ((i >> 2) & 1) as f32]).collect();
    let quads = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]];
    let triangles = quads.iter().flat_map(|q: &[u32; 4]| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]]).collect();
    (positions, triangles)
}

/// A deterministic soup of small triangles in a unit ball, plus one large quad.
fn soup(count: usize) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let mut random = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f32 / (1u64 << 53) as f32 * 2.0 - 1.0
    };
    let mut positions = Vec::new();
    let mut triangles = Vec::new();
    for _ in 0..count {
        let center = [random(), random(), random()];
        let base = positions.len() as u32;
        for _ in 0..3 {
            positions.push([center[0] + 0.05 * random(), center[1] + 0.05 * random(), center[2] + 0.05 * random()]);
        }
        triangles.push([base, base + 1, base + 2]);
    }
    (positions, triangles)
}

#[test]
fn a_cube_becomes_its_six_faces() {
    let (positions, triangles) = cube();
    let set = select_planes(&positions, &triangles, &[], settings(0.02));
    assert_eq!(set.planes.len(), 6);
    assert!(set.planes.iter().all(|plane| plane.faces.len() == 2), "each side's two triangles share a plane");
    assert!(check_assignment(&positions, &triangles, &set) <= set.epsilon * 1.0001);
}

#[test]
fn every_face_is_assigned_within_epsilon_and_selection_is_deterministic() {
    let (positions, triangles) = soup(2000);
    for epsilon in [0.01, 0.05] {
        let set = select_planes(&positions, &triangles, &[], settings(epsilon));
        let worst = check_assignment(&positions, &triangles, &set);
        assert!(worst <= set.epsilon * 1.0001, "ε = {epsilon}: {worst} > {}", set.epsilon);
        assert!((set.max_error - worst).abs() < 1e-5, "the reported error is the real one");
        assert_eq!(set, select_planes(&positions, &triangles, &[], settings(epsilon)), "deterministic");
    }
    let loose = select_planes(&positions, &triangles, &[], settings(0.05)).planes.len();
    let tight = select_planes(&positions, &triangles, &[], settings(0.01)).planes.len();
    assert!(loose < tight, "a larger ε needs fewer planes: {loose} vs {tight}");
}

#[test]
fn max_planes_caps_the_count_and_reports_the_achieved_error() {
    let (positions, triangles) = soup(500);
    let set = select_planes(
        &positions,
        &triangles,
        &[],
        PlaneSettings { epsilon: 0.02, max_planes: Some(8), max_quads: None },
    );
    assert!(set.planes.len() <= 8);
    let worst = check_assignment(&positions, &triangles, &set);
    assert!(worst > set.epsilon, "capped: some faces move further than ε");
    assert!((set.max_error - worst).abs() < 1e-5, "reported {} vs measured {worst}", set.max_error);
}

#[test]
fn degenerate_faces_are_kept() {
    let positions = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [2.0, 2.0, 2.0]];
    let triangles = vec![[0, 1, 2], [3, 3, 3], [0, 1, 1]];
    let set = select_planes(&positions, &triangles, &[], settings(0.02));
    check_assignment(&positions, &triangles, &set);
}

#[test]
fn a_plane_is_fitted_to_its_faces_not_left_at_the_edge_of_epsilon() {
    // A gently tilted, slightly bumpy sheet (bumps ±1 % of ε): one plane holds it all, and that
    // plane passes through the sheet instead of lying up to ε away from it.
    let (mut positions, mut triangles) = (Vec::new(), Vec::new());
    let epsilon = 0.05;
    for row in 0..=10 {
        for column in 0..=10 {
            let (x, y) = (column as f32 / 10.0, row as f32 / 10.0);
            let bump = if (row + column) % 2 == 0 { 0.0002 } else { -0.0002 };
            positions.push([x, y, 0.13 * x - 0.07 * y + bump]);
        }
    }
    for row in 0..10u32 {
        for column in 0..10u32 {
            let corner = row * 11 + column;
            triangles.push([corner, corner + 1, corner + 12]);
            triangles.push([corner, corner + 12, corner + 11]);
        }
    }
    let set = select_planes(&positions, &triangles, &[], settings(epsilon));
    assert_eq!(set.planes.len(), 1);
    let worst = check_assignment(&positions, &triangles, &set);
    assert!(worst < 0.05 * set.epsilon, "the sheet is {worst} from its plane (ε = {})", set.epsilon);
}

#[test]
fn every_face_ends_on_its_nearest_plane() {
    // The greedy selection hands a plane every remaining face within ε, even one that a later
    // plane passes right through; the reassignment moves it there, since a face drawn on its
    // plane is displaced by its distance in views at an angle to the plane.
    let (positions, triangles) = soup(600);
    let set = select_planes(&positions, &triangles, &[], settings(0.05));
    let distance = |face: u32, plane: &cirrus::kinds::billboard_cloud::planes::Plane| {
        let normal = glam::Vec3::from(plane.normal);
        triangles[face as usize]
            .iter()
            .map(|&vertex| (glam::Vec3::from(positions[vertex as usize]).dot(normal) - plane.distance).abs())
            .fold(0.0f32, f32::max)
    };
    let mut farther = 0;
    for plane in &set.planes {
        for &face in &plane.faces {
            let nearest = set.planes.iter().map(|other| distance(face, other)).fold(f32::INFINITY, f32::min);
            if distance(face, plane) > nearest + 1e-5 {
                farther += 1;
            }
        }
    }
    assert_eq!(farther, 0, "faces not on their nearest plane, of {} in {} planes", triangles.len(), set.planes.len());
    assert!(check_assignment(&positions, &triangles, &set) <= set.epsilon * 1.0001);
}

#[test]
fn faces_move_only_to_planes_that_hold_their_material() {
    // Moving a bark face onto a leaf plane would make that plane render bark too, so a bark
    // texture edit would re-render it. Two materials at random: with them given, fewer planes
    // mix materials than when selection ignores them.
    let (positions, triangles) = soup(600);
    let materials: Vec<u32> = (0..triangles.len() as u32).map(|face| (face * 7 + face / 3) % 2).collect();
    let mixed = |set: &PlaneSet| {
        set.planes
            .iter()
            .filter(|plane| {
                plane.faces.iter().any(|&f| materials[f as usize] == 0)
                    && plane.faces.iter().any(|&f| materials[f as usize] == 1)
            })
            .count()
    };
    let aware = select_planes(&positions, &triangles, &materials, settings(0.05));
    let blind = select_planes(&positions, &triangles, &[], settings(0.05));
    check_assignment(&positions, &triangles, &aware);
    assert!(
        mixed(&aware) < mixed(&blind),
        "planes mixing materials: {} aware of materials, {} blind",
        mixed(&aware),
        mixed(&blind)
    );
}
