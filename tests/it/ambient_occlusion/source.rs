//! An AmbientOcclusion asset as another asset's source: a `Material` with `ao_source` takes each
//! material's AO from the AO bake's map of the same name (its own `ao` texture set aside), and
//! re-packs when the bake changes; the graph shows the edge; a name the AO mesh lacks is an
//! error naming it.

use expect_test::expect;

use super::{floor_and_box, read_png16, scene_files};
use crate::support::{build, decode_png, TempProject};

/// The floor-and-box scene baked as `scene`, and a Material asset `mat` whose `floor` and `box`
/// materials name `ao_source: Some("scene")`; the floor's own `ao` texture is white.
fn project_with_ao_source(materials: &str) -> TempProject {
    let project = TempProject::new(
        r#"Pipeline(source: "assets", output: "baked", assets: [
            AmbientOcclusion(name: "scene", mesh: "scene.obj", ao: (size: 64, rays: 16, occluders: AllMeshes)),
            Material(name: "mat", material: "mat.mymaterial", ao_source: Some("scene")),
        ])"#,
    );
    let (obj, mtl) = scene_files(&floor_and_box(false));
    project.write("assets/scene.obj", obj);
    project.write("assets/scene.mtl", mtl);
    project.write("assets/white.png", crate::support::png_bytes(4, 4, &[255; 64]));
    project.write("assets/mat.mymaterial", materials);
    project
}

const MATERIALS: &str = r#"
Material $floor { Param (attrib = "roughness") {float {0.5}} Texture (attrib = "ao") {string {"white.png"}} }
Material $box { Param (attrib = "metallic") {float {1.0}} }
"#;

#[test]
fn a_material_takes_each_materials_ao_from_the_bake_of_the_same_name() {
    let project = project_with_ao_source(MATERIALS);
    let mut cirrus = project.open();
    let summary = build(&mut cirrus);
    assert!(summary.all_ok(), "{summary:?}");
    for material in ["floor", "box"] {
        let (size, ao) = read_png16(&project.read(&format!("baked/scene/{material}/ao.png")));
        let mra = decode_png(&project.read(&format!("baked/mat/{material}/mra.png")));
        assert_eq!((mra.width, mra.height), (size, size), "{material}: the AO map's size (the only map)");
        for (texel, &value) in ao.iter().enumerate() {
            let expected = (value as u32 * 255 + 32767) / 65535;
            let blue = mra.pixels[texel * 4 + 2] as u32;
            assert!(blue.abs_diff(expected) <= 1, "{material} texel {texel}: AO {blue}, the bake's {expected}");
        }
        // Real occlusion, not the white texture: the floor around the box, the box's foot.
        let darkest = (0..ao.len()).map(|texel| mra.pixels[texel * 4 + 2]).min().unwrap();
        assert!(darkest < 200, "{material}: darkest AO {darkest}");
    }
    let mra = decode_png(&project.read("baked/mat/floor/mra.png"));
    assert_eq!(mra.pixels[1], 128, "the floor's roughness constant stays");

    // Building the material alone bakes the AO it reads (without writing the bake's files).
    let alone = project_with_ao_source(MATERIALS);
    let output = alone.run_cli(&["build", "--asset", "mat"]);
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    assert_eq!(alone.read("baked/mat/box/mra.png"), project.read("baked/mat/box/mra.png"));
    assert!(!alone.path("baked/scene").exists(), "only the asset asked for is written");
}

#[test]
fn rebaking_the_source_repacks_only_the_mra_surfaces_that_read_it_and_the_graph_shows_the_edge() {
    let project = project_with_ao_source(MATERIALS);
    let mut cirrus = project.open();
    assert!(build(&mut cirrus).all_ok());
    let graph = cirrus.graph();
    for material in ["floor", "box"] {
        let edge = (format!("fill(scene/{material})"), format!("pack(mat/{material}/mra)"));
        assert!(
            graph.edges.iter().any(|found| (&found.from, &found.to) == (&edge.0, &edge.1)),
            "{edge:?} in the graph"
        );
    }
    assert!(!graph
        .edges
        .iter()
        .any(|edge| edge.from == "decode(assets/white.png)" && edge.to == "pack(mat/floor/mra)"));
    cirrus.take_executed_stages();

    let pipeline = String::from_utf8(project.read("pipeline.ron")).unwrap();
    std::fs::write(project.path("pipeline.ron"), pipeline.replace("rays: 16", "rays: 32")).unwrap();
    cirrus.reconfigure(cirrus::pipeline::load_pipeline(&project.path("pipeline.ron")).unwrap());
    assert!(build(&mut cirrus).all_ok());
    let material_stages: Vec<String> =
        cirrus.take_executed_stages().into_iter().filter(|stage| stage.contains("(mat/")).collect();
    expect![[r#"
        [
            "encode(mat/box/mra)",
            "encode(mat/floor/mra)",
            "mips(mat/box/mra)",
            "mips(mat/floor/mra)",
            "pack(mat/box/mra)",
            "pack(mat/floor/mra)",
            "write(mat/box/mra)",
            "write(mat/floor/mra)",
        ]
    "#]]
    .assert_debug_eq(&material_stages);
}

#[test]
fn a_material_the_ao_mesh_lacks_is_an_error_naming_both_and_its_asset_writes_nothing() {
    let project = project_with_ao_source(&format!(
        "{MATERIALS}Material $roof {{ Param (attrib = \"metallic\") {{float {{0.0}}}} }}\n"
    ));
    let mut cirrus = project.open();
    let summary = build(&mut cirrus);
    let scene = summary.assets.iter().find(|asset| asset.name == "scene").unwrap();
    assert!(scene.errors.is_empty(), "the AO bake itself is fine: {:?}", scene.errors);
    let mat = summary.assets.iter().find(|asset| asset.name == "mat").unwrap();
    let messages: Vec<String> = mat.errors.iter().map(|error| format!("{}: {}", error.file, error.message)).collect();
    expect![[r#"
        [
            "assets/scene.obj: ao_source `scene` of `mat`: the mesh has no material `roof`",
        ]
    "#]]
    .assert_debug_eq(&messages);
    // A failed asset keeps its last good outputs, all of them: on a first build, none.
    assert!(!project.path("baked/mat").exists(), "nothing of the failed asset is written");
}
