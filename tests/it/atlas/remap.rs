//! Meshes remapped onto the atlas: sampled through the page they show what they showed through
//! their own textures (turned entries included); repeating UVs fail their mesh alone.

use cirrus::texture::Texture;

use crate::support::{build, decode_png, pattern_png, PsnrSum, TempProject};

/// A two-triangle quad over UVs `[u0, u1] × [v0, v1]` with material `material` of `props.mtl`.
fn quad_obj(material: &str, [u0, v0, u1, v1]: [f32; 4]) -> String {
    format!(
        "mtllib props.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt {u0} {v0}\nvt {u1} {v0}\nvt {u1} {v1}\nvt {u0} {v1}\nusemtl {material}\nf 1/1 2/2 3/3\nf 1/1 3/3 4/4\n"
    )
}

fn remap_project() -> TempProject {
    let project = TempProject::new(
        r#"Pipeline(source: "assets", output: "baked", assets: [
            Atlas(name: "props", textures: ["props/*.png"], meshes: ["props/*.obj"], pack: (max_size: 512, padding: 4)),
        ])"#,
    );
    // A long thin texture (the packer turns such ones when that packs better) and a square one.
    project.write("assets/props/plank.png", pattern_png(120, 16, 1));
    project.write("assets/props/crate.png", pattern_png(64, 64, 2));
    project.write("assets/props/rope.png", pattern_png(16, 100, 3));
    project.write(
        "assets/props/props.mtl",
        "newmtl plank\nKd 1 1 1\nmap_Kd plank.png\nnewmtl crate\nKd 1 1 1\nmap_Kd crate.png\nnewmtl rope\nmap_Kd rope.png\n",
    );
    project.write("assets/props/plank.obj", quad_obj("plank", [0.0, 0.0, 1.0, 1.0]));
    project.write("assets/props/crate.obj", quad_obj("crate", [0.1, 0.2, 0.9, 0.7]));
    project.write("assets/props/rope.obj", quad_obj("rope", [0.0, 0.0, 1.0, 1.0]));
    project
}

/// The texel of `texture` under `uv` (OBJ convention: v up), nearest.
fn sample(texture: &Texture, [u, v]: [f32; 2]) -> [u8; 4] {
    let x = ((u * texture.width as f32).floor() as u32).min(texture.width - 1);
    let y = (((1.0 - v) * texture.height as f32).floor() as u32).min(texture.height - 1);
    texture.texel(x, y)
}

#[test]
fn a_remapped_mesh_sampled_through_the_atlas_shows_what_it_showed_through_its_own_texture() {
    let project = remap_project();
    let summary = build(&mut project.open());
    assert!(summary.all_ok(), "{}", summary.to_text());
    let table: serde_json::Value = serde_json::from_slice(&project.read("baked/props/atlas.json")).unwrap();
    assert!(table["entries"].as_array().unwrap().iter().any(|entry| entry["rotated"] == true), "some entry is turned: {table}");
    let page = decode_png(&project.read("baked/props/atlas.png"));
    let mtl = String::from_utf8(project.read("baked/props/atlas.mtl")).unwrap();
    assert!(mtl.contains("newmtl plank") && mtl.contains("map_Kd atlas.png"), "{mtl}");
    for (mesh, texture) in [("plank", "plank.png"), ("crate", "crate.png"), ("rope", "rope.png")] {
        let source = decode_png(&project.read(&format!("assets/props/{texture}")));
        let original = tobj::load_obj_buf(
            &mut project.read(&format!("assets/props/{mesh}.obj")).as_slice(),
            &tobj::LoadOptions { single_index: true, triangulate: true, ..Default::default() },
            |_| Err(tobj::LoadError::OpenFileFailed),
        )
        .unwrap()
        .0;
        let remapped_text = project.read(&format!("baked/props/meshes/props/{mesh}.obj"));
        assert!(String::from_utf8_lossy(&remapped_text).contains("mtllib ../../atlas.mtl"));
        let remapped = tobj::load_obj_buf(
            &mut remapped_text.as_slice(),
            &tobj::LoadOptions { single_index: true, triangulate: true, ..Default::default() },
            |_| Err(tobj::LoadError::OpenFileFailed),
        )
        .unwrap()
        .0;
        // The same point of each triangle (barycentric grid, away from texel edges) in both.
        let uv_at = |model: &tobj::Model, triangle: usize, weights: [f32; 3]| -> [f32; 2] {
            let mesh = &model.mesh;
            let mut uv = [0.0f32; 2];
            for (corner, weight) in weights.iter().enumerate() {
                let vertex = mesh.indices[triangle * 3 + corner] as usize;
                uv[0] += weight * mesh.texcoords[vertex * 2];
                uv[1] += weight * mesh.texcoords[vertex * 2 + 1];
            }
            uv
        };
        let mut sum = PsnrSum::default();
        for triangle in 0..2 {
            for i in 1..20 {
                for j in 1..(20 - i) {
                    let weights = [i as f32 / 20.0, j as f32 / 20.0, 1.0 - (i + j) as f32 / 20.0];
                    let expected = sample(&source, uv_at(&original[0], triangle, weights));
                    let actual = sample(&page, uv_at(&remapped[0], triangle, weights));
                    sum.add(expected, actual, 3);
                }
            }
        }
        let psnr = sum.psnr();
        assert!(psnr > 30.0, "{mesh}: {psnr:.1} dB");
    }
}

#[test]
fn a_mesh_with_repeating_uvs_fails_alone_naming_mesh_material_and_range_and_the_others_are_written() {
    let project = remap_project();
    project.write("assets/props/crate.obj", quad_obj("crate", [-0.5, 0.0, 2.0, 1.0]));
    let summary = build(&mut project.open());
    let props = &summary.assets[0];
    let messages: Vec<String> = props.errors.iter().map(|error| format!("{}: {}", error.file, error.message)).collect();
    assert_eq!(messages.len(), 1, "{messages:?}");
    let message = &messages[0];
    for part in ["assets/props/crate.obj", "material `crate`", "u ∈ [-0.5, 2]", "v ∈ [0, 1]", "repeating UVs"] {
        assert!(message.contains(part), "{part} not in {message}");
    }
    assert!(project.path("baked/props/meshes/props/plank.obj").is_file());
    assert!(project.path("baked/props/meshes/props/rope.obj").is_file());
    assert!(!project.path("baked/props/meshes/props/crate.obj").exists());
    assert!(project.path("baked/props/atlas.ktx2").is_file());
    // Fixed, it is written.
    project.write("assets/props/crate.obj", quad_obj("crate", [0.0, 0.0, 1.0, 1.0]));
    assert!(build(&mut project.open()).all_ok());
    assert!(project.path("baked/props/meshes/props/crate.obj").is_file());
}

#[test]
fn a_texel_edit_rewrites_neither_the_table_nor_the_meshes() {
    let project = remap_project();
    let mut cirrus = project.open();
    assert!(build(&mut cirrus).all_ok());
    cirrus.take_executed_stages();
    let mesh = project.read("baked/props/meshes/props/plank.obj");
    project.write("assets/props/plank.png", pattern_png(120, 16, 9));
    assert!(build(&mut cirrus).all_ok());
    let ran = cirrus.take_executed_stages();
    assert!(ran.iter().all(|stage| !stage.starts_with("remap")), "{ran:?}");
    assert!(ran.contains(&"composite(props/page0)".to_string()), "{ran:?}");
    assert_eq!(project.read("baked/props/meshes/props/plank.obj"), mesh);
}

#[test]
fn a_mesh_whose_material_library_is_missing_is_written_with_its_warning_in_the_report() {
    let project = remap_project();
    project.write("assets/props/lost.obj", quad_obj("plank", [0.0, 0.0, 1.0, 1.0]).replace("props.mtl", "lost.mtl"));
    let summary = build(&mut project.open());
    assert!(summary.all_ok(), "{}", summary.to_text());
    assert!(project.path("baked/props/meshes/props/lost.obj").is_file());
    let report: serde_json::Value = serde_json::from_slice(&project.read("baked/props/report.json")).unwrap();
    let warnings = report["warnings"].to_string();
    assert!(warnings.contains("lost.mtl") && warnings.contains("not found"), "{report}");
}
