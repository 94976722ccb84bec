//! Which stages a Height edit re-runs (the stage bodies that ran, as the event log names
//! them): a high-mesh edit re-bakes both maps and re-displaces, `level` re-tessellates only, an
//! encoder setting re-encodes only; the edited bake equals a clean build of the edited sources.

use expect_test::expect;

use super::{height_field_obj, height_project};
use crate::support::{build, TempProject};

fn reconfigure(project: &TempProject, cirrus: &mut cirrus::project::Project, from: &str, to: &str) {
    let pipeline = String::from_utf8(project.read("pipeline.ron")).unwrap();
    assert!(pipeline.contains(from), "{pipeline}");
    std::fs::write(project.path("pipeline.ron"), pipeline.replace(from, to)).unwrap();
    cirrus.reconfigure(cirrus::pipeline::load_pipeline(&project.path("pipeline.ron")).unwrap());
}

/// Bumps of `amplitude` (an amplitude alone scales every distance alike: the 16-bit map stays
/// the same and only its magnitude changes) shifted by `phase`.
fn bumps(amplitude: f32, phase: f32) -> String {
    height_field_obj(24, move |x, z| 0.02 + amplitude * (4.0 * x + phase).sin() * (3.0 * z).cos(), false, false)
}

#[test]
fn high_mesh_level_and_encoder_edits_rerun_only_their_stages() {
    let low = height_field_obj(4, |_, _| 0.0, true, true);
    let project =
        height_project(&bumps(0.02, 0.0), &low, "height: (size: 64), tessellate: Some((level: 4, displace: true))");
    let mut cirrus = project.open();
    assert!(build(&mut cirrus).all_ok());
    cirrus.take_executed_stages();

    project.write("assets/high.obj", bumps(0.03, 0.5));
    cirrus.invalidate_all_sources();
    assert!(build(&mut cirrus).all_ok());
    expect![[r#"
        [
            "bake(relief)",
            "bake(relief/pn)",
            "bvh(relief)",
            "displace(relief)",
            "distance(relief/displaced)",
            "distance(relief/low)",
            "distance(relief/pn)",
            "encode(relief/height)",
            "mesh(relief/assets/high.obj)",
            "mips(relief/height)",
            "write(relief/height)",
        ]
    "#]]
    .assert_debug_eq(&cirrus.take_executed_stages());
    let edited = (project.read("baked/relief/tessellated.obj"), project.read("baked/relief/height_pn.png"));

    reconfigure(&project, &mut cirrus, "level: 4", "level: 6");
    assert!(build(&mut cirrus).all_ok());
    expect![[r#"
        [
            "displace(relief)",
            "distance(relief/displaced)",
            "distance(relief/pn)",
            "tessellate(relief)",
        ]
    "#]]
    .assert_debug_eq(&cirrus.take_executed_stages());

    reconfigure(&project, &mut cirrus, "tessellate:", "encode: (quality: Slow), tessellate:");
    assert!(build(&mut cirrus).all_ok());
    expect![[r#"
        [
            "encode(relief/height)",
            "write(relief/height)",
        ]
    "#]]
    .assert_debug_eq(&cirrus.take_executed_stages());

    // The high-mesh edit's result equals a clean bake of the edited sources.
    let clean =
        height_project(&bumps(0.03, 0.5), &low, "height: (size: 64), tessellate: Some((level: 4, displace: true))");
    assert!(build(&mut clean.open()).all_ok());
    assert_eq!((clean.read("baked/relief/tessellated.obj"), clean.read("baked/relief/height_pn.png")), edited);
}
