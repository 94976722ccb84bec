//! LODs by budget (`billboard: (budget: Some(Quads(n)))`): the quads in `lod.obj` never exceed
//! the budget, on the bundled bush and on a mesh that is hard to cover (hundreds of disjoint,
//! randomly turned parts), and every face still lies on exactly one quad.

use std::path::Path;

use cirrus::kinds::billboard_cloud::planes::{select_planes, select_planes_within_budget, PlaneSettings, SEAM_WEIGHT};
use cirrus::kinds::billboard_cloud::rectangles::{merge_rectangles_to_budget, plane_rectangles};

use crate::support::{build, TempProject};

/// Quads in an LOD's OBJ (two triangles each).
fn lod_quads(obj: &[u8]) -> usize {
    String::from_utf8_lossy(obj).lines().filter(|line| line.starts_with("f ")).count() / 2
}

/// Every face of the mesh on exactly one of the budget's rectangles, and no more rectangles
/// than the budget.
fn assert_budget_covers_every_face(
    positions: &[[f32; 3]],
    triangles: &[[u32; 3]],
    materials: &[u32],
    quads: u32,
) -> f32 {
    let planes = select_planes_within_budget(positions, triangles, materials, quads, None, SEAM_WEIGHT);
    assert!(planes.planes.len() <= quads as usize, "{} planes for {quads} quads", planes.planes.len());
    let rectangles = merge_rectangles_to_budget(
        positions,
        triangles,
        &planes,
        plane_rectangles(positions, triangles, &planes),
        quads as usize,
    );
    assert!(rectangles.len() <= quads as usize, "{} rectangles for {quads} quads", rectangles.len());
    let mut drawn = vec![0u32; triangles.len()];
    for rectangle in &rectangles {
        for &face in &rectangle.faces {
            drawn[face as usize] += 1;
        }
    }
    assert!(drawn.iter().all(|&count| count == 1), "every face on exactly one quad");
    planes.epsilon_fraction
}

/// 300 small boxes, each turned its own way, scattered in a cube: no plane holds two of them.
fn scattered_boxes() -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
    let (mut positions, mut triangles) = (Vec::new(), Vec::new());
    let mut state = 12345u64;
    let mut random = move || {
        state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (state >> 40) as f32 / (1u64 << 24) as f32
    };
    for _ in 0..300 {
        let centre = glam::Vec3::new(random(), random(), random()) * 10.0;
        let turn = glam::Quat::from_euler(glam::EulerRot::XYZ, random() * 6.3, random() * 6.3, random() * 6.3);
        let first = positions.len() as u32;
        for corner in 0..8 {
            let local =
                glam::Vec3::new((corner & 1) as f32, ((corner >> 1) & 1) as f32, ((corner >> 2) & 1) as f32) - 0.5;
            positions.push((centre + turn * (local * 0.2)).to_array());
        }
        for [a, b, c, d] in [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]] {
            triangles.push([first + a, first + b, first + c]);
            triangles.push([first + a, first + c, first + d]);
        }
    }
    (positions, triangles)
}

#[test]
fn a_budget_bounds_the_quads_and_every_face_stays_drawn() {
    let (positions, triangles) = scattered_boxes();
    for quads in [1, 12, 40, 200] {
        assert_budget_covers_every_face(&positions, &triangles, &[], quads);
    }
    // A bigger budget never needs a larger ε.
    let bush = crate::support::bundled_bush();
    let epsilons: Vec<f32> = [16, 64, 256]
        .into_iter()
        .map(|quads| assert_budget_covers_every_face(&bush.positions, &bush.triangles, &bush.triangle_materials, quads))
        .collect();
    assert!(epsilons.windows(2).all(|pair| pair[1] <= pair[0]), "{epsilons:?}");
}

/// The area-weighted mean of |cos| between each face's normal and its plane's (1: every face
/// drawn unforeshortened).
fn mean_alignment(
    positions: &[[f32; 3]],
    triangles: &[[u32; 3]],
    planes: &cirrus::kinds::billboard_cloud::planes::PlaneSet,
) -> f64 {
    let (mut sum, mut area) = (0.0f64, 0.0f64);
    for plane in &planes.planes {
        for &face in &plane.faces {
            let [a, b, c] = triangles[face as usize].map(|vertex| glam::Vec3::from(positions[vertex as usize]));
            let cross = (b - a).cross(c - a);
            sum += cross.normalize_or_zero().dot(glam::Vec3::from(plane.normal)).abs() as f64
                * 0.5
                * cross.length() as f64;
            area += 0.5 * cross.length() as f64;
        }
    }
    sum / area
}

#[test]
fn a_budgets_planes_are_refined_past_the_greedy_selection() {
    // The bush at 64 quads: the smallest fitting ε gives the greedy pass fewer planes than the
    // budget allows; the refinement fills the budget and moves faces and planes so that faces
    // lie nearer their planes and more nearly parallel to them than at that ε alone.
    let bush = crate::support::bundled_bush();
    let (positions, triangles, materials) = (&bush.positions, &bush.triangles, &bush.triangle_materials);
    let budget = select_planes_within_budget(positions, triangles, materials, 64, None, SEAM_WEIGHT);
    let settings = PlaneSettings { epsilon: budget.epsilon_fraction, max_planes: None, max_quads: None };
    let at_epsilon = select_planes(positions, triangles, materials, settings);
    assert!(at_epsilon.planes.len() < 64, "the greedy pass alone fills the budget: {}", at_epsilon.planes.len());
    assert_eq!(budget.planes.len(), 64, "the refinement seeds planes up to the budget");
    assert!(
        budget.mean_error < 0.95 * at_epsilon.mean_error,
        "mean error {} refined against {} at ε alone",
        budget.mean_error,
        at_epsilon.mean_error
    );
    let (refined, greedy) =
        (mean_alignment(positions, triangles, &budget), mean_alignment(positions, triangles, &at_epsilon));
    assert!(refined > greedy + 0.03, "mean |cos| {refined} refined against {greedy} at ε alone");
    assert!(budget.max_error > budget.epsilon, "the refinement is not held to ε");
    assert_budget_covers_every_face(positions, triangles, materials, 64);
}

#[test]
fn a_budgets_planes_keep_adjacent_faces_together_where_splitting_them_opens_a_step() {
    // Where two faces sharing an edge lie on planes at different depths, the edge is drawn in
    // two places: a trunk split so shows a step in every view at an angle. On the bundled bush
    // at 64 quads, closing seams takes the mean gap at such edges down by a fifth or more and
    // costs the faces' mean distance from their planes at most a tenth.
    let bush = crate::support::bundled_bush();
    let (positions, triangles, materials) = (&bush.positions, &bush.triangles, &bush.triangle_materials);
    let closed = select_planes_within_budget(positions, triangles, materials, 64, None, SEAM_WEIGHT);
    let open = select_planes_within_budget(positions, triangles, materials, 64, None, 0.0);
    println!(
        "seam gap {} closed, {} open; mean error {} closed, {} open",
        closed.seam_gap, open.seam_gap, closed.mean_error, open.mean_error
    );
    assert!(
        closed.seam_gap > 0.0 && closed.seam_gap < 0.8 * open.seam_gap,
        "seam gap {} closed, {} open",
        closed.seam_gap,
        open.seam_gap
    );
    assert!(
        closed.mean_error < 1.1 * open.mean_error,
        "mean error {} closed, {} open",
        closed.mean_error,
        open.mean_error
    );
    assert_budget_covers_every_face(positions, triangles, materials, 64);
}

#[test]
fn a_budgeted_bake_writes_at_most_that_many_quads() {
    let project = TempProject::new(
        r#"Pipeline(source: "examples/assets", output: "baked", assets: [
            BillboardCloud(name: "bush16", mesh: "trees/bush_2.obj", billboard: (budget: Some(Quads(16))), atlas: (max_size: 256)),
            BillboardCloud(name: "bush48", mesh: "trees/bush_2.obj", billboard: (budget: Some(Triangles(96))), atlas: (max_size: 256)),
        ])"#,
    );
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    std::os::unix::fs::symlink(root.join("examples"), project.path("examples")).unwrap();
    let summary = build(&mut project.open());
    assert!(summary.all_ok(), "{}", summary.to_text());
    for (name, quads) in [("bush16", 16), ("bush48", 48)] {
        let lod = lod_quads(&project.read(&format!("baked/{name}/lod.obj")));
        let report: serde_json::Value =
            serde_json::from_slice(&project.read(&format!("baked/{name}/report.json"))).unwrap();
        assert!(lod <= quads && lod > 0, "{name}: {lod} quads");
        assert_eq!(report["quads"], lod, "{name}");
        assert_eq!(report["budget_quads"], quads, "{name}");
        // The refinement lets a face leave its ε-slab; on average they lie well within it.
        assert!(report["mean_error_world"].as_f64().unwrap() < report["epsilon_world"].as_f64().unwrap(), "{report}");
        assert!(
            report["max_error_world"].as_f64().unwrap() >= report["mean_error_world"].as_f64().unwrap(),
            "{report}"
        );
    }
}

#[test]
fn the_atlas_follows_the_screen_size_the_lod_is_meant_for() {
    let project = TempProject::new(
        r#"Pipeline(source: "examples/assets", output: "baked", assets: [
            BillboardCloud(name: "far", mesh: "trees/bush_2.obj", billboard: (budget: Some(Quads(64)), screen_size: Some(64))),
            BillboardCloud(name: "near", mesh: "trees/bush_2.obj", billboard: (budget: Some(Quads(64)), screen_size: Some(512))),
        ])"#,
    );
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    std::os::unix::fs::symlink(root.join("examples"), project.path("examples")).unwrap();
    let summary = build(&mut project.open());
    assert!(summary.all_ok(), "{}", summary.to_text());
    let bush = crate::support::bundled_bush();
    let diameter = 2.0 * cirrus::kinds::billboard_cloud::planes::bounding_sphere_radius(&bush.positions) as f64;
    let mut sides = Vec::new();
    for (name, pixels) in [("far", 64.0), ("near", 512.0)] {
        let report: serde_json::Value =
            serde_json::from_slice(&project.read(&format!("baked/{name}/report.json"))).unwrap();
        let atlas = &report["atlas"];
        // One texel per pixel at that size (lowered only if the atlas would pass max_size).
        let density = atlas["texel_density"].as_f64().unwrap();
        let side = atlas["width"].as_u64().unwrap().max(atlas["height"].as_u64().unwrap());
        let wanted = pixels / diameter;
        let exact = (density - wanted).abs() < 1e-3 * density;
        assert!(
            exact || (side == 2048 && density < wanted),
            "{name}: {density} texels per unit for {pixels} px over {diameter}"
        );
        sides.push(side);
    }
    assert!(sides[0] * 4 <= sides[1], "an LOD meant for 64 px gets a far smaller atlas than one for 512: {sides:?}");
}

#[test]
fn the_epsilon_search_finds_the_smallest_fitting_step_in_few_probes() {
    use cirrus::kinds::billboard_cloud::planes::{
        ladder_epsilon, search_epsilon_ladder, LadderProbe, BUDGET_LADDER_STEPS,
    };
    // Plane counts that follow a power of ε, failing probes reporting less than the truth (as
    // the estimate from the faces the capped planes hold does).
    let mut probes_per_search = Vec::new();
    for alpha in [0.7f32, 1.3, 2.2, 3.5] {
        for cap in [1u32, 4, 32, 64, 512, 5000] {
            let count = |step: u32| (20.0 * ladder_epsilon(step).powf(-alpha)).floor();
            let expected = (0..=BUDGET_LADDER_STEPS).find(|&step| count(step) <= cap as f32);
            let mut probes = 0;
            let found = search_epsilon_ladder(cap as f32, f32::INFINITY, |step| {
                probes += 1;
                let planes = count(step);
                let fits = planes <= cap as f32;
                LadderProbe { fits, planes: if fits { planes } else { cap as f32 + 0.5 * (planes - cap as f32) } }
            });
            assert_eq!(found, expected, "α {alpha}, cap {cap}");
            probes_per_search.push(probes);
        }
    }
    let mean = probes_per_search.iter().sum::<u32>() as f32 / probes_per_search.len() as f32;
    assert!(
        mean <= 6.0 && probes_per_search.iter().all(|&probes| probes <= 12),
        "bisection takes 9 or 10: {probes_per_search:?}"
    );
    // Any boundary, with counts that say nothing: never wrong, never more than twice bisection.
    for boundary in [0, 1, 2, 100, 255, 256, 257, 400, 511, 512, 513] {
        let mut probes = 0;
        let found = search_epsilon_ladder(50.0, f32::INFINITY, |step| {
            probes += 1;
            LadderProbe { fits: step >= boundary, planes: if step >= boundary { 50.0 } else { 51.0 } }
        });
        assert_eq!(found, (boundary <= BUDGET_LADDER_STEPS).then_some(boundary), "boundary {boundary}");
        assert!(probes <= 20, "boundary {boundary}: {probes} probes");
    }
    // Enough planes end the search: a fitting step with at least 90 % of the cap, in fewer probes.
    let (mut exact_probes, mut enough_probes) = (0, 0);
    for alpha in [0.7f32, 1.3, 2.2, 3.5] {
        for cap in [32u32, 64, 512, 5000] {
            let count = |step: u32| (20.0 * ladder_epsilon(step).powf(-alpha)).floor();
            let search = |enough: f32, probes: &mut u32| {
                search_epsilon_ladder(cap as f32, enough, |step| {
                    *probes += 1;
                    LadderProbe { fits: count(step) <= cap as f32, planes: count(step) }
                })
            };
            let (smallest, found) =
                (search(f32::INFINITY, &mut exact_probes), search((0.9 * cap as f32).ceil(), &mut enough_probes));
            let (Some(smallest), Some(found)) = (smallest, found) else {
                assert_eq!((smallest, found), (None, None), "α {alpha}, cap {cap}");
                continue;
            };
            assert!(count(found) <= cap as f32, "α {alpha}, cap {cap}: step {found} does not fit");
            assert!(
                found == smallest || count(found) >= (0.9 * cap as f32).ceil(),
                "α {alpha}, cap {cap}: {} planes",
                count(found)
            );
        }
    }
    println!("{enough_probes} probes with enough planes, {exact_probes} for the smallest step");
    assert!(
        enough_probes < exact_probes,
        "{enough_probes} probes with enough planes, {exact_probes} for the smallest step"
    );
}
