//! Triangle LODs (`mesh::reduce`): budgets held, material borders kept in place, leaf cards
//! thinned evenly with their drawn area kept, the same result every run.

use std::path::Path;

use cirrus::mesh::reduce::{reduce_mesh, ReduceSettings, ReducedMesh, TriangleBudget};
use cirrus::mesh::{Mesh, MeshMaterial};

/// The bundled bush with its MTL (its `leaves` are cut out: `map_d`).
fn bush_with_materials() -> Mesh {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/assets");
    let obj_path = Path::new("trees/bush_2.obj");
    let obj = std::fs::read(root.join(obj_path)).expect("the bundled bush");
    let libraries = cirrus::mesh::material_libraries(obj_path, &obj, Path::new(""))
        .into_iter()
        .map(|library| {
            let bytes = std::fs::read(root.join(&library)).ok();
            (library, bytes)
        })
        .collect();
    let (mesh, _) = cirrus::mesh::load_mesh(obj_path, &obj, &libraries, Path::new("")).expect("loads");
    assert!(mesh.materials.iter().any(|material| material.cut_out), "the bush's leaves are cut out");
    mesh
}

fn reduce(mesh: &Mesh, budget: TriangleBudget) -> ReducedMesh {
    reduce_mesh(mesh, &ReduceSettings { budget, max_error: 0.01 })
}

/// A flat grid of `side` × `side` unit quads, material 0 left of x = side / 2 and 1 right of it,
/// sharing the vertices on that line.
fn two_material_grid(side: u32) -> Mesh {
    let mut mesh = Mesh::default();
    for y in 0..=side {
        for x in 0..=side {
            // A gentle bump, so that the simplifier has an error to weigh.
            let z = 0.05 * ((x as f32 * 0.7).sin() + (y as f32 * 0.5).cos());
            mesh.positions.push([x as f32, y as f32, z]);
            mesh.normals.push([0.0, 0.0, 1.0]);
        }
    }
    mesh.uvs = Some(mesh.positions.iter().map(|p| [p[0] / side as f32, p[1] / side as f32]).collect());
    let vertex = |x: u32, y: u32| y * (side + 1) + x;
    for y in 0..side {
        for x in 0..side {
            let material = u32::from(x >= side / 2);
            let (a, b, c, d) = (vertex(x, y), vertex(x + 1, y), vertex(x + 1, y + 1), vertex(x, y + 1));
            mesh.triangles.extend([[a, b, c], [a, c, d]]);
            mesh.triangle_materials.extend([material, material]);
            mesh.triangle_objects.extend([0, 0]);
        }
    }
    mesh.materials = vec![
        MeshMaterial { name: "left".into(), ..Default::default() },
        MeshMaterial { name: "right".into(), ..Default::default() },
    ];
    mesh.objects = vec!["grid".into()];
    mesh
}

#[test]
fn a_triangle_lod_never_exceeds_its_budget() {
    let bush = bush_with_materials();
    let grid = two_material_grid(40);
    for mesh in [&bush, &grid] {
        let source = mesh.triangles.len();
        for budget in [
            TriangleBudget::Ratio(0.5),
            TriangleBudget::Ratio(0.25),
            TriangleBudget::Ratio(0.1),
            TriangleBudget::Ratio(0.02),
            TriangleBudget::Triangles(100),
            TriangleBudget::Triangles(1),
            TriangleBudget::Triangles(0),
        ] {
            let allowed = cirrus::mesh::reduce::budget_triangles(budget, source);
            let reduced = reduce(mesh, budget);
            let kept = reduced.mesh.triangles.len();
            assert!(kept <= allowed, "{budget:?} of {source}: {kept} triangles");
            if allowed >= source / 10 {
                // Not an empty or token mesh where the budget leaves room.
                assert!(kept * 2 >= allowed, "{budget:?} of {source}: only {kept} triangles");
            }
            assert_eq!(reduced.mesh.triangle_materials.len(), kept);
            assert_eq!(reduced.mesh.triangle_objects.len(), kept);
            assert!(reduced
                .mesh
                .triangles
                .iter()
                .flatten()
                .all(|&corner| (corner as usize) < reduced.mesh.positions.len()));
        }
    }
}

#[test]
fn material_borders_stay_where_they_were() {
    let side = 40;
    let grid = two_material_grid(side);
    let reduced = reduce(&grid, TriangleBudget::Ratio(0.1));
    let mesh = &reduced.mesh;
    assert!(mesh.triangles.len() * 4 < grid.triangles.len(), "it reduced: {}", mesh.triangles.len());
    let border = (side / 2) as f32;
    for (triangle, &material) in mesh.triangles.iter().zip(&mesh.triangle_materials) {
        for corner in triangle {
            let x = mesh.positions[*corner as usize][0];
            match material {
                0 => assert!(x <= border, "a left triangle reaches x = {x}"),
                _ => assert!(x >= border, "a right triangle reaches x = {x}"),
            }
        }
    }
    // Every vertex of the border is still there, where it was.
    for source in grid.positions.iter().filter(|position| position[0] == border) {
        assert!(mesh.positions.contains(source), "border vertex {source:?} moved or went");
    }
}

#[test]
fn leaf_cards_thin_evenly_and_keep_the_leaf_area_drawn() {
    let bush = bush_with_materials();
    let mut last_kept = usize::MAX;
    for ratio in [0.5f32, 0.25, 0.1] {
        let reduced = reduce(&bush, TriangleBudget::Ratio(ratio));
        let (cards, kept) = reduced.cards;
        let (source_area, area) = reduced.cut_out_area;
        println!(
            "bush at {ratio}: {} of {} triangles, {kept} of {cards} cards, leaf area {:.3} of the source's, error {:.4}",
            reduced.mesh.triangles.len(),
            bush.triangles.len(),
            area / source_area,
            reduced.error
        );
        assert!(cards > 100, "the bush's leaves are cards: {cards}");
        // Cards go a few at a time, not all at once.
        let expected = ratio as f64 * cards as f64;
        assert!((kept as f64 - expected).abs() <= 0.1 * expected + 2.0, "{kept} of {cards} cards kept at {ratio}");
        assert!(kept < last_kept);
        last_kept = kept;
        // The kept cards grow to draw the leaf area of all of them, up to twice a side.
        let bound = (1.0 / ratio as f64).min(4.0) * ratio as f64;
        assert!(
            (area / source_area - bound).abs() < 0.1 * bound,
            "leaf area {:.3} of the source's at {ratio}",
            area / source_area
        );
    }
}

#[test]
fn the_same_mesh_reduces_to_the_same_mesh() {
    let bush = bush_with_materials();
    assert_eq!(reduce(&bush, TriangleBudget::Ratio(0.2)), reduce(&bush, TriangleBudget::Ratio(0.2)));
}
