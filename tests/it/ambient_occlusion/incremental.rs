//! Which stages an AO edit re-runs (the stage bodies that ran, as the event log names them):
//! `rays` re-bakes the tiles, an encoder setting only re-encodes, and with a finite
//! `max_distance` a mesh edit re-bakes only the tiles within reach of it, with the same bytes
//! as a full bake of the edited mesh, in the same process and after a restart.

use expect_test::expect;

use super::{ao_project, floor_and_box, scene_files, Part};
use crate::support::{build, TempProject};

fn reconfigure(project: &TempProject, cirrus: &mut cirrus::project::Project, from: &str, to: &str) {
    let pipeline = String::from_utf8(project.read("pipeline.ron")).unwrap();
    assert!(pipeline.contains(from), "{pipeline}");
    std::fs::write(project.path("pipeline.ron"), pipeline.replace(from, to)).unwrap();
    cirrus.reconfigure(cirrus::pipeline::load_pipeline(&project.path("pipeline.ron")).unwrap());
}

#[test]
fn rays_rebake_every_tile_and_an_encoder_setting_only_reencodes() {
    let project = ao_project(&floor_and_box(false), "size: 256, rays: 8, occluders: AllMeshes");
    let mut cirrus = project.open();
    assert!(build(&mut cirrus).all_ok());
    cirrus.take_executed_stages();
    reconfigure(&project, &mut cirrus, "rays: 8", "rays: 16");
    assert!(build(&mut cirrus).all_ok());
    expect![[r#"
        [
            "bake(scene/box/tile_0_0)",
            "bake(scene/box/tile_0_1)",
            "bake(scene/box/tile_1_0)",
            "bake(scene/box/tile_1_1)",
            "bake(scene/floor/tile_0_0)",
            "bake(scene/floor/tile_0_1)",
            "bake(scene/floor/tile_1_0)",
            "bake(scene/floor/tile_1_1)",
            "encode(scene/box/ao)",
            "encode(scene/floor/ao)",
            "fill(scene/box)",
            "fill(scene/floor)",
            "mips(scene/box/ao)",
            "mips(scene/floor/ao)",
            "write(scene/box/ao)",
            "write(scene/floor/ao)",
        ]
    "#]]
    .assert_debug_eq(&cirrus.take_executed_stages());
    let report: serde_json::Value = serde_json::from_slice(&project.read("baked/scene/report.json")).unwrap();
    assert_eq!(report["rays_per_texel"], 16);

    reconfigure(&project, &mut cirrus, "occluders: AllMeshes", "occluders: AllMeshes), encode: (quality: Slow");
    assert!(build(&mut cirrus).all_ok());
    expect![[r#"
        [
            "encode(scene/box/ao)",
            "encode(scene/floor/ao)",
            "write(scene/box/ao)",
            "write(scene/floor/ao)",
        ]
    "#]]
    .assert_debug_eq(&cirrus.take_executed_stages());
}

/// Two floors with a box each, 8 units apart: the left pair on the left half of each map (tile
/// column 0 of a 256² map), the right pair on the right half (column 1). `right_box_top` is the
/// height of the right box.
fn two_islands(right_box_top: f32) -> Vec<Part> {
    let mut left = Part::new("left", "ground").floor(2.0, 0.0, 4, [0.01, 0.01, 0.49, 0.99], false);
    let mut right = Part::new("right", "ground").floor(2.0, 0.0, 4, [0.51, 0.01, 0.99, 0.99], false);
    for (vertex, _) in &mut left.vertices {
        vertex[0] -= 4.0;
    }
    for (vertex, _) in &mut right.vertices {
        vertex[0] += 4.0;
    }
    vec![
        left,
        right,
        Part::new("left_box", "box").cuboid([-4.5, 0.0, -0.5], [-3.5, 1.0, 0.5], [0.0, 0.0, 0.49, 1.0]),
        Part::new("right_box", "box").cuboid([3.5, 0.0, -0.5], [4.5, right_box_top, 0.5], [0.51, 0.0, 1.0, 1.0]),
    ]
}

const REACH: &str = "size: 256, rays: 16, occluders: AllMeshes, max_distance: Some(0.1)";

#[test]
fn with_a_finite_reach_a_mesh_edit_rebakes_only_the_tiles_near_it_with_a_full_bakes_bytes() {
    let project = ao_project(&two_islands(1.0), REACH);
    let mut cirrus = project.open();
    assert!(build(&mut cirrus).all_ok());
    cirrus.take_executed_stages();
    // Lower the right box (the mesh's bounding box, and so the reach in units, stays the same).
    let (edited_obj, _) = scene_files(&two_islands(0.7));
    project.write("assets/scene.obj", &edited_obj);
    cirrus.invalidate_all_sources();
    assert!(build(&mut cirrus).all_ok());
    let in_process = cirrus.take_executed_stages();
    expect![[r#"
        [
            "bake(scene/box/tile_1_0)",
            "bake(scene/box/tile_1_1)",
            "bake(scene/ground/tile_1_0)",
            "bake(scene/ground/tile_1_1)",
            "bvh(scene)",
            "encode(scene/box/ao)",
            "encode(scene/ground/ao)",
            "fill(scene/box)",
            "fill(scene/ground)",
            "mesh(scene)",
            "mips(scene/box/ao)",
            "mips(scene/ground/ao)",
            "write(scene/box/ao)",
            "write(scene/ground/ao)",
        ]
    "#]]
    .assert_debug_eq(&in_process);

    // A full bake of the edited mesh in a folder of its own writes the same bytes.
    let fresh = ao_project(&two_islands(0.7), REACH);
    assert!(build(&mut fresh.open()).all_ok());
    for file in ["ground/ao.png", "ground/ao.ktx2", "box/ao.png", "box/ao.ktx2"] {
        assert!(
            project.read(&format!("baked/scene/{file}")) == fresh.read(&format!("baked/scene/{file}")),
            "{file} differs"
        );
    }

    // After a restart the persistent cache does the same: the far tiles are found by their keys.
    let restarted = ao_project(&two_islands(1.0), REACH);
    assert!(build(&mut restarted.open()).all_ok());
    restarted.write("assets/scene.obj", &edited_obj);
    let mut again = restarted.open();
    assert!(build(&mut again).all_ok());
    let after_restart: Vec<String> =
        again.take_executed_stages().into_iter().filter(|stage| !stage.starts_with("write(")).collect();
    let expected: Vec<String> = in_process.iter().filter(|stage| !stage.starts_with("write(")).cloned().collect();
    assert_eq!(after_restart, expected);
    for file in ["ground/ao.png", "box/ao.png"] {
        assert!(
            restarted.read(&format!("baked/scene/{file}")) == fresh.read(&format!("baked/scene/{file}")),
            "{file} differs"
        );
    }
}
