//! Triangle LODs (`mesh::reduce`): budgets held, material borders kept in place, leaf cards
//! thinned a few at a time with their drawn area bounded, the loss in px-shift units, the same
//! result every run.

use std::path::Path;

use mesh::reduce::{reduce_mesh, ReduceSettings, ReducedMesh, TriangleBudget};
use mesh::{Mesh, MeshMaterial};

/// The bundled bush with its MTL (its `leaves` are cut out: `map_d`).
fn bush_with_materials() -> Mesh {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/assets");
    let obj_path = Path::new("trees/bush_2.obj");
    let obj = std::fs::read(root.join(obj_path)).expect("the bundled bush");
    let libraries = mesh::material_libraries(obj_path, &obj, Path::new(""))
        .into_iter()
        .map(|library| {
            let bytes = std::fs::read(root.join(&library)).ok();
            (library, bytes)
        })
        .collect();
    let (mesh, _) = mesh::load_mesh(obj_path, &obj, &libraries, Path::new("")).expect("loads");
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
            let allowed = mesh::reduce::budget_triangles(budget, source);
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
fn leaf_cards_thin_a_few_at_a_time_and_the_leaf_area_drawn_is_bounded() {
    let bush = bush_with_materials();
    let mut last_kept = usize::MAX;
    for ratio in [0.5f32, 0.25, 0.1] {
        let reduced = reduce(&bush, TriangleBudget::Ratio(ratio));
        let (cards, kept) = reduced.cards;
        let (source_area, area) = reduced.cut_out_area;
        println!(
            "bush at {ratio}: {} of {} triangles, {kept} of {cards} cards, \
             leaf area {:.3} of the source's, error {:.4}",
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
        // The largest cards are kept and grow (by the fourth root of the area ratio): the leaf
        // area drawn is at least the square root of the ratio, never more than the source's.
        let drawn = area / source_area;
        assert!(
            drawn >= (ratio as f64).sqrt() && drawn <= 1.0 + 1e-9,
            "leaf area {drawn:.3} of the source's at {ratio}"
        );
    }
}

#[test]
fn the_same_mesh_reduces_to_the_same_mesh() {
    let bush = bush_with_materials();
    assert_eq!(reduce(&bush, TriangleBudget::Ratio(0.2)), reduce(&bush, TriangleBudget::Ratio(0.2)));
}

/// `mesh` as the preview draws it, with the bundled textures its materials name.
fn bush_view(mesh: &Mesh) -> gpu::ViewMesh {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/assets");
    let uvs = mesh.uvs.clone().unwrap_or_default();
    let tangents = mesh::mikktspace_tangents(&mesh.positions, &mesh.normals, &uvs, &mesh.triangles);
    render::preview::mesh_view(mesh, &tangents, 0.5, |material, slot| {
        let Some(path) = material.maps.get(&slot) else { return Ok(None) };
        let bytes = std::fs::read(root.join(path)).map_err(|error| error.to_string())?;
        let texture = texture::decode_texture(path, &bytes, Default::default()).map_err(|error| error.to_string())?;
        Ok::<_, String>(Some(std::sync::Arc::new(texture)))
    })
    .expect("the bush's textures")
}

#[test]
fn a_triangle_lod_of_the_bush_is_measured_in_pixel_shift_units() {
    // The loss of a level, 1 - IoU over the 26 views at 16 samples per pixel, in units of what
    // moving the source one pixel costs it (issue 40): the cards thinned and grown keep the
    // bush's silhouette, where collapsing each card on its own would empty it.
    let bush = bush_with_materials();
    let source = bush_view(&bush);
    let (center, radius) = render::preview::bounding_sphere(&source);
    let gpu = gpu::gpu().expect("a GPU adapter (llvmpipe in CI)");
    let settings = render::preview::PreviewSettings { views: 26, size: 128, samples_per_axis: 4 };
    let mut last_loss = 0.0;
    for ratio in [0.5f32, 0.25, 0.1] {
        let reduced = reduce(&bush, TriangleBudget::Ratio(ratio));
        let lod = gpu::LevelView::Mesh(bush_view(&reduced.mesh));
        let preview = render::preview::preview(gpu, &source, &lod, center, radius, settings).expect("renders");
        let metrics = &preview.metrics;
        let loss = (1.0 - metrics.mean_iou) / (1.0 - metrics.source_shift_iou);
        println!(
            "bush at {ratio} ({} triangles) at 128 px: mean IoU {:.4}, {loss:.2} px-shift units \
             (one pixel costs the source {:.4}), missed {:.3}, extra {:.3}",
            reduced.mesh.triangles.len(),
            metrics.mean_iou,
            1.0 - metrics.source_shift_iou,
            metrics.mean_missed,
            metrics.mean_extra
        );
        assert!(loss >= last_loss, "fewer triangles lose more");
        // Bounds a little above what it measures (0.47, 1.11, 1.80): the cards kept evenly over
        // space instead of the largest measured 0.95, 1.34, 1.91.
        let bound = match ratio {
            0.5 => 0.55,
            0.25 => 1.25,
            _ => 1.9,
        };
        assert!(loss <= bound, "{loss:.2} px-shift units at {ratio}");
        last_loss = loss;
    }
}

/// An OBJ of `text` with no material library.
fn obj_mesh(text: &str) -> Mesh {
    let (mesh, _) =
        mesh::load_mesh(Path::new("a.obj"), text.as_bytes(), &Default::default(), Path::new("")).expect("loads");
    mesh
}

#[test]
fn small_and_degenerate_meshes_keep_at_least_one_real_triangle() {
    // A lone triangle beside degenerate ones: the simplifier collapses it, the largest of the
    // group's own triangles is kept instead; a ratio never leaves a level empty.
    let lone = obj_mesh("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 2 2 2\nf 1 2 3\nf 1 1 2\nf 4 4 4\n");
    let reduced = reduce(&lone, TriangleBudget::Ratio(0.01));
    let kept: Vec<[[f32; 3]; 3]> = reduced
        .mesh
        .triangles
        .iter()
        .map(|triangle| triangle.map(|corner| reduced.mesh.positions[corner as usize]))
        .collect();
    assert_eq!(kept, vec![[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]]);
    // A box's four sides (no vertex the simplifier may move): its smallest triangles dropped,
    // the rest kept, and the error says how deep the hole is.
    let mut sides = String::new();
    for (index, [(x0, z0), (x1, z1)]) in
        [[(0.0, 0.0), (1.0, 0.0)], [(1.0, 0.0), (1.0, 1.0)], [(1.0, 1.0), (0.0, 1.0)], [(0.0, 1.0), (0.0, 0.0)]]
            .into_iter()
            .enumerate()
    {
        sides.push_str(&format!("v {x0} 0 {z0}\nv {x1} 0 {z1}\nv {x1} 4 {z1}\nv {x0} 4 {z0}\n"));
        let b = index * 4 + 1;
        sides.push_str(&format!("f {} {} {}\nf {} {} {}\n", b, b + 1, b + 2, b, b + 2, b + 3));
    }
    let reduced = reduce(&obj_mesh(&sides), TriangleBudget::Triangles(6));
    assert_eq!(reduced.mesh.triangles.len(), 6, "six of the eight side triangles");
    assert!(reduced.error > 0.4, "a dropped 1 × 4 triangle leaves a hole half its diagonal deep: {}", reduced.error);
}
