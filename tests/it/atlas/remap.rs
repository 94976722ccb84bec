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
    assert!(
        table["entries"].as_array().unwrap().iter().any(|entry| entry["rotated"] == true),
        "some entry is turned: {table}"
    );
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
        let remapped_text = project.read(&format!("baked/props/props-{mesh}.obj"));
        assert!(String::from_utf8_lossy(&remapped_text).contains("mtllib atlas.mtl\n"));
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
fn a_mesh_with_repeating_uvs_fails_its_asset_naming_mesh_material_and_range_and_nothing_is_written_until_fixed() {
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
    // A failed asset keeps its last good outputs, all of them: on a first build, none.
    assert!(!project.path("baked/props").exists());
    // Fixed, every mesh is written.
    project.write("assets/props/crate.obj", quad_obj("crate", [0.0, 0.0, 1.0, 1.0]));
    assert!(build(&mut project.open()).all_ok());
    for mesh in ["crate", "plank", "rope"] {
        assert!(project.path(&format!("baked/props/props-{mesh}.obj")).is_file(), "{mesh}");
    }
    assert!(project.path("baked/props/atlas.ktx2").is_file());
}

#[test]
fn a_texel_edit_rewrites_neither_the_table_nor_the_meshes() {
    let project = remap_project();
    let mut cirrus = project.open();
    assert!(build(&mut cirrus).all_ok());
    cirrus.take_executed_stages();
    let mesh = project.read("baked/props/props-plank.obj");
    project.write("assets/props/plank.png", pattern_png(120, 16, 9));
    assert!(build(&mut cirrus).all_ok());
    let ran = cirrus.take_executed_stages();
    assert!(ran.iter().all(|stage| !stage.starts_with("remap")), "{ran:?}");
    assert!(ran.contains(&"composite(props/page0)".to_string()), "{ran:?}");
    assert_eq!(project.read("baked/props/props-plank.obj"), mesh);
}

#[test]
fn a_map_the_output_names_is_copied_in_by_content_and_an_edit_renames_the_copy_without_a_remap() {
    // The bush's bark keeps its own maps: atlas.mtl and the glTF name copies under maps/, named
    // by their contents' hash; the source edited, the next build names (and writes) a new copy,
    // removes the old one and remaps nothing.
    let project = bundled_foliage();
    let mut cirrus = project.open();
    assert!(build(&mut cirrus).all_ok());
    cirrus.take_executed_stages();
    let copy_named = |mtl: &str| -> String {
        let line = mtl.lines().find(|line| line.starts_with("map_Kd maps/oak_color_1k.")).expect("the bark's copy");
        line.trim_start_matches("map_Kd ").to_string()
    };
    let first = copy_named(&String::from_utf8(project.read("baked/foliage/atlas.mtl")).unwrap());
    let source = project.read("assets/trees/textures/oak_color_1k.jpg");
    assert_eq!(first, format!("maps/oak_color_1k.{}.jpg", &blake3::hash(&source).to_hex()[..16]));
    assert_eq!(project.read(&format!("baked/foliage/{first}")), source, "a JPEG is copied byte for byte");
    let gltf = String::from_utf8(project.read("baked/foliage/trees-bush_2.gltf")).unwrap();
    assert!(gltf.contains(&format!("\"uri\": \"{first}\"")), "{gltf}");

    project.write("assets/trees/textures/oak_color_1k.jpg", project.read("assets/trees/textures/oak_ao_1k.jpg"));
    assert!(build(&mut cirrus).all_ok());
    let ran = cirrus.take_executed_stages();
    assert!(ran.iter().all(|stage| !stage.starts_with("remap")), "{ran:?}");
    let second = copy_named(&String::from_utf8(project.read("baked/foliage/atlas.mtl")).unwrap());
    assert_ne!(second, first);
    assert_eq!(project.read(&format!("baked/foliage/{second}")), project.read("assets/trees/textures/oak_ao_1k.jpg"));
    assert!(!project.path(&format!("baked/foliage/{first}")).exists(), "the old copy is gone");
    let gltf = String::from_utf8(project.read("baked/foliage/trees-bush_2.gltf")).unwrap();
    assert!(gltf.contains(&second) && !gltf.contains(&first), "{gltf}");
}

#[test]
fn a_mesh_whose_material_library_is_missing_is_written_with_its_warning_in_the_report() {
    let project = remap_project();
    project.write("assets/props/lost.obj", quad_obj("plank", [0.0, 0.0, 1.0, 1.0]).replace("props.mtl", "lost.mtl"));
    let summary = build(&mut project.open());
    assert!(summary.all_ok(), "{}", summary.to_text());
    assert!(project.path("baked/props/props-lost.obj").is_file());
    let report: serde_json::Value = serde_json::from_slice(&project.read("baked/props/report.json")).unwrap();
    let warnings = report["warnings"].to_string();
    assert!(warnings.contains("lost.mtl") && warnings.contains("not found"), "{report}");
}

/// The triangles of `material` in an OBJ's text (tobj, one index per corner) as UV triples.
fn material_uv_triangles(obj: &[u8], mtl: Option<&[u8]>, material: &str) -> Vec<[[f32; 2]; 3]> {
    let (models, materials) = tobj::load_obj_buf(
        &mut &obj[..],
        &tobj::LoadOptions { single_index: true, triangulate: true, ..Default::default() },
        |_| match mtl {
            Some(mtl) => tobj::load_mtl_buf(&mut &mtl[..]),
            None => Err(tobj::LoadError::OpenFileFailed),
        },
    )
    .expect("the OBJ loads");
    let materials = materials.expect("its MTL loads");
    let wanted = materials.iter().position(|candidate| candidate.name == material).expect("the material exists");
    let mut triangles = Vec::new();
    for model in models.iter().filter(|model| model.mesh.material_id == Some(wanted)) {
        let mesh = &model.mesh;
        for corners in mesh.indices.chunks_exact(3) {
            let uv = |vertex: u32| [mesh.texcoords[vertex as usize * 2], mesh.texcoords[vertex as usize * 2 + 1]];
            triangles.push([uv(corners[0]), uv(corners[1]), uv(corners[2])]);
        }
    }
    triangles
}

/// Points of a triangle on a barycentric grid (`steps` per edge, away from the corners).
fn triangle_points(triangle: &[[f32; 2]; 3], steps: usize) -> Vec<[f32; 2]> {
    let mut points = Vec::new();
    for i in 1..steps {
        for j in 1..(steps - i) {
            let weights = [i as f32 / steps as f32, j as f32 / steps as f32, 1.0 - (i + j) as f32 / steps as f32];
            let mut point = [0.0f32; 2];
            for (corner, weight) in triangle.iter().zip(weights) {
                point[0] += weight * corner[0];
                point[1] += weight * corner[1];
            }
            points.push(point);
        }
    }
    points
}

/// The bundled foliage asset as `pipeline.ron` bakes it: the two leaf cards and the bush.
fn bundled_foliage() -> TempProject {
    let project = TempProject::new(
        r#"Pipeline(source: "assets", output: "baked", assets: [
            Atlas(name: "foliage", textures: ["textures/leaves/*.png", "trees/textures/aspen_color.png"], meshes: ["trees/bush_2.obj"],
                  pack: (max_size: 2048)),
        ])"#,
    );
    let bundled = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/assets");
    for file in [
        "textures/leaves/oak_leaves.png",
        "trees/bush_2.obj",
        "trees/bush_2.mtl",
        "trees/textures/aspen_color.png",
        "trees/textures/oak_color_1k.jpg",
        "trees/textures/oak_normal_1k.jpg",
        "trees/textures/oak_roughness_1k.jpg",
        "trees/textures/oak_ao_1k.jpg",
    ] {
        project.write(&format!("assets/{file}"), std::fs::read(bundled.join(file)).expect("bundled file"));
    }
    project
}

#[test]
fn the_bundled_bush_remapped_onto_foliage_samples_only_its_own_texels_with_its_own_alpha_test() {
    // The leaf cards' UVs span the whole aspen texture, whose left and right thirds are
    // transparent: trimmed to its opaque texels, the remapped UVs reached v = −0.21, a quarter
    // of the leaf area sampled off the page or the oak leaves beside it, and 8.9 % of the points
    // passed the alpha test differently from the source.
    let project = bundled_foliage();
    let summary = build(&mut project.open());
    assert!(summary.all_ok(), "{}", summary.to_text());
    let table: serde_json::Value = serde_json::from_slice(&project.read("baked/foliage/atlas.json")).unwrap();
    let entry = table["entries"]
        .as_array()
        .unwrap()
        .iter()
        .find(|entry| entry["name"] == "trees/textures/aspen_color.png")
        .unwrap();
    let page = decode_png(&project.read("baked/foliage/atlas.png"));
    let [x, y, width, height] = ["x", "y", "width", "height"].map(|key| entry[key].as_f64().unwrap() as f32);
    let (page_width, page_height) = (page.width as f32, page.height as f32);
    let inside = |[u, v]: [f32; 2]| {
        let (column, row) = (u * page_width, (1.0 - v) * page_height);
        column >= x - 0.01 && column <= x + width + 0.01 && row >= y - 0.01 && row <= y + height + 0.01
    };
    let source = decode_png(&project.read("assets/trees/textures/aspen_color.png"));
    let mtl = project.read("assets/trees/bush_2.mtl");
    let original = material_uv_triangles(&project.read("assets/trees/bush_2.obj"), Some(&mtl), "leaves");
    let atlas_mtl = project.read("baked/foliage/atlas.mtl");
    let remapped = material_uv_triangles(&project.read("baked/foliage/trees-bush_2.obj"), Some(&atlas_mtl), "leaves");
    assert_eq!(original.len(), remapped.len());
    let (mut points, mut outside, mut disagreeing) = (0usize, 0usize, 0usize);
    for (before, after) in original.iter().zip(&remapped) {
        for (source_uv, page_uv) in triangle_points(before, 8).into_iter().zip(triangle_points(after, 8)) {
            points += 1;
            if !inside(page_uv) {
                outside += 1;
                continue;
            }
            let (from_source, from_page) = (sample(&source, source_uv)[3] >= 128, sample(&page, page_uv)[3] >= 128);
            disagreeing += usize::from(from_source != from_page);
        }
    }
    assert_eq!(outside, 0, "{outside} of {points} leaf points sample outside the aspen's rectangle");
    let disagreement = disagreeing as f64 / points as f64;
    // Nearest texels on either side of a turned, moved grid: a few points on alpha edges differ.
    assert!(disagreement < 0.01, "{:.2} % of the leaf points pass the alpha test differently", disagreement * 100.0);
    let report: serde_json::Value = serde_json::from_slice(&project.read("baked/foliage/report.json")).unwrap();
    assert_eq!(
        report["kept_for_meshes"],
        serde_json::json!([{"entry": "trees/textures/aspen_color.png", "trimmed": [260, 0, 503, 1024], "kept": [0, 0, 1024, 1024]}])
    );
    let check = project.run_cli(&["check"]);
    let text = String::from_utf8_lossy(&check.stdout);
    assert!(check.status.success(), "{text}");
    assert!(text.contains("reach the transparent border of `trees/textures/aspen_color.png`"), "{text}");
}

#[test]
fn the_preview_draws_the_remapped_bush_as_its_source_from_every_side() {
    // `cirrus preview` of an Atlas renders each remapped mesh as an engine loads it (the OBJ,
    // atlas.mtl, the page PNG, the bark maps it still names) beside its source from the 26
    // directions. With the remapped UVs of the trimmed aspen (v down to −0.21, before the entry
    // kept what the UVs reach), the leaf cards drew the oak leaves and empty page.
    let project = bundled_foliage();
    let output = project.run_cli(&["preview", "--asset", "foliage"]);
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert_eq!(output.status.code(), Some(0), "{stdout}{}", String::from_utf8_lossy(&output.stderr));
    assert!(stdout.contains("trees/bush_2.obj remapped: 26 views, 16 samples per pixel: mean IoU"), "{stdout}");
    let metrics: serde_json::Value =
        serde_json::from_slice(&project.read("baked/foliage/preview/trees/bush_2/metrics.json")).unwrap();
    let (mean_iou, min_iou, psnr) = (
        metrics["mean_iou"].as_f64().unwrap(),
        metrics["min_iou"].as_f64().unwrap(),
        metrics["mean_psnr"].as_f64().unwrap(),
    );
    println!("bundled bush remapped onto foliage: mean IoU {mean_iou:.3}, min {min_iou:.3}, PSNR {psnr:.2} dB");
    // The same faces with the same texels: what differs is the page's mip levels (its
    // neighbours and padding filtered in) against the source's own.
    assert!(mean_iou >= 0.97 && min_iou >= 0.96 && psnr >= 40.0, "{metrics}");
    // From above, the side the leaf cards face.
    let above = metrics["views"]
        .as_array()
        .unwrap()
        .iter()
        .find(|view| view["direction"] == serde_json::json!([0.0, 1.0, 0.0]));
    assert!(above.unwrap()["iou"].as_f64().unwrap() >= 0.97, "{above:?}");
    let sheet = image::load_from_memory(&project.read("baked/foliage/preview/trees/bush_2/contact_sheet.png")).unwrap();
    assert_eq!((sheet.width(), sheet.height()), (4 * 2 * 256 + 3 * 8, 7 * 256 + 6 * 8));

    // Options that are a billboard cloud's, and an asset without a mesh to draw.
    let output = project.run_cli(&["preview", "--asset", "foliage", "--lod", "1"]);
    assert_eq!(output.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&output.stderr).contains("`--lod` and `--stand-in` are for BillboardCloud"));
    project.write(
        "pipeline.ron",
        r#"Pipeline(source: "assets", output: "baked", assets: [Atlas(name: "leaves", textures: ["textures/leaves/*.png"])])"#,
    );
    let output = project.run_cli(&["preview", "--asset", "leaves"]);
    assert_eq!(output.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&output.stderr).contains("remaps no mesh"), "{output:?}");
}

/// A `size`² texture whose middle `core`² texels are a pattern and the rest transparent.
fn bordered_png(size: u32, core: u32, seed: u32) -> Vec<u8> {
    let pattern = decode_png(&pattern_png(core, core, seed));
    let border = (size - core) / 2;
    let mut pixels = vec![0u8; (size * size * 4) as usize];
    for row in 0..core {
        for column in 0..core {
            let texel = pattern.texel(column, row);
            pixels[(((row + border) * size + column + border) * 4) as usize..][..4]
                .copy_from_slice(&[texel[0], texel[1], texel[2], 255]);
        }
    }
    crate::support::png_bytes(size, size, &pixels)
}

#[test]
fn aliases_with_other_canvases_get_their_own_transform_and_their_meshes_sample_their_texels() {
    // The same 16² pixels in a 32² canvas (border 8) and a 24² one (border 4): one rectangle,
    // two transforms. Each quad's UVs cover its texture's opaque core only.
    let project = TempProject::new(
        r#"Pipeline(source: "assets", output: "baked", assets: [
            Atlas(name: "props", textures: ["props/*.png"], meshes: ["props/*.obj"], pack: (max_size: 256, padding: 2)),
        ])"#,
    );
    project.write("assets/props/big.png", bordered_png(32, 16, 5));
    project.write("assets/props/small.png", bordered_png(24, 16, 5));
    project.write("assets/props/props.mtl", "newmtl big\nmap_Kd big.png\nnewmtl small\nmap_Kd small.png\n");
    project.write("assets/props/big.obj", quad_obj("big", [8.0 / 32.0, 8.0 / 32.0, 24.0 / 32.0, 24.0 / 32.0]));
    project.write("assets/props/small.obj", quad_obj("small", [4.0 / 24.0, 4.0 / 24.0, 20.0 / 24.0, 20.0 / 24.0]));
    let summary = build(&mut project.open());
    assert!(summary.all_ok(), "{}", summary.to_text());
    let table: serde_json::Value = serde_json::from_slice(&project.read("baked/props/atlas.json")).unwrap();
    let entries = table["entries"].as_array().unwrap();
    assert_eq!(entries.len(), 1, "one rectangle: {table}");
    let alias = &entries[0]["aliases"][0];
    assert_eq!(alias["name"], "props/small.png");
    assert_eq!(
        (alias["source_size"].clone(), alias["trim_offset"].clone()),
        (serde_json::json!([24, 24]), serde_json::json!([4, 4]))
    );
    assert_eq!(
        (entries[0]["source_size"].clone(), entries[0]["trim_offset"].clone()),
        (serde_json::json!([32, 32]), serde_json::json!([8, 8]))
    );
    assert_ne!(alias["uv_scale"], entries[0]["uv_scale"]);
    let page = decode_png(&project.read("baked/props/atlas.png"));
    let mtl = project.read("baked/props/atlas.mtl");
    for mesh in ["big", "small"] {
        let source = decode_png(&project.read(&format!("assets/props/{mesh}.png")));
        let before = material_uv_triangles(
            &project.read(&format!("assets/props/{mesh}.obj")),
            Some(&project.read("assets/props/props.mtl")),
            mesh,
        );
        let after = material_uv_triangles(&project.read(&format!("baked/props/props-{mesh}.obj")), Some(&mtl), mesh);
        let mut sum = PsnrSum::default();
        for (before, after) in before.iter().zip(&after) {
            for (source_uv, page_uv) in triangle_points(before, 12).into_iter().zip(triangle_points(after, 12)) {
                sum.add(sample(&source, source_uv), sample(&page, page_uv), 4);
            }
        }
        assert!(sum.psnr() > 30.0, "{mesh}: {:.1} dB", sum.psnr());
    }
}

#[test]
fn a_remapped_mesh_whose_texture_is_deleted_fails_naming_it_and_the_last_good_outputs_stay() {
    let project = remap_project();
    assert!(build(&mut project.open()).all_ok());
    std::fs::remove_file(project.path("assets/props/crate.png")).unwrap();
    let summary = build(&mut project.open());
    let messages: Vec<String> =
        summary.assets[0].errors.iter().map(|error| format!("{}: {}", error.file, error.message)).collect();
    assert_eq!(messages.len(), 1, "{messages:?}");
    for part in ["assets/props/crate.obj", "material `crate`", "props/crate.png", "cannot be read (file not found"] {
        assert!(messages[0].contains(part), "{part} not in {}", messages[0]);
    }
    assert!(project.path("baked/props/props-plank.obj").is_file());
    assert!(project.path("baked/props/props-crate.obj").is_file(), "the failed asset keeps its last good outputs");
}

#[test]
fn a_material_no_triangle_uses_does_not_fail_a_mesh_that_shares_its_library() {
    // `both` maps two textures that lie in two rectangles: a mesh that uses it cannot be
    // remapped, the ones that only share the library can.
    let project = remap_project();
    let mtl = String::from_utf8(project.read("assets/props/props.mtl")).unwrap();
    project.write("assets/props/props.mtl", format!("{mtl}newmtl both\nmap_Kd plank.png\nmap_d crate.png\n"));
    let summary = build(&mut project.open());
    assert!(summary.all_ok(), "{}", summary.to_text());
    project.write("assets/props/both.obj", quad_obj("both", [0.0, 0.0, 1.0, 1.0]));
    let summary = build(&mut project.open());
    let messages: Vec<String> =
        summary.assets[0].errors.iter().map(|error| format!("{}: {}", error.file, error.message)).collect();
    assert_eq!(messages.len(), 1, "{messages:?}");
    assert!(messages[0].contains("both.obj") && messages[0].contains("material `both`"), "{messages:?}");
}

#[test]
fn scale_and_offset_options_of_an_atlased_map_are_kept_in_the_remapped_uvs_and_others_are_reported() {
    let project = remap_project();
    project.write(
        "assets/props/props.mtl",
        "newmtl plank\nmap_Kd plank.png\nnewmtl crate\nmap_Kd -s 0.5 0.5 1 -o 0.25 0.5 0 -bm 0.3 crate.png\nnewmtl rope\nmap_Kd rope.png\n",
    );
    let summary = build(&mut project.open());
    assert!(summary.all_ok(), "{}", summary.to_text());
    let page = decode_png(&project.read("baked/props/atlas.png"));
    let source = decode_png(&project.read("assets/props/crate.png"));
    let before = material_uv_triangles(
        &project.read("assets/props/crate.obj"),
        Some(&project.read("assets/props/props.mtl")),
        "crate",
    );
    let after = material_uv_triangles(
        &project.read("baked/props/props-crate.obj"),
        Some(&project.read("baked/props/atlas.mtl")),
        "crate",
    );
    let mut sum = PsnrSum::default();
    for (before, after) in before.iter().zip(&after) {
        for (uv, page_uv) in triangle_points(before, 12).into_iter().zip(triangle_points(after, 12)) {
            // What the source shows: the texture at uv × s + o.
            sum.add(sample(&source, [uv[0] * 0.5 + 0.25, uv[1] * 0.5 + 0.5]), sample(&page, page_uv), 4);
        }
    }
    assert!(sum.psnr() > 30.0, "{:.1} dB", sum.psnr());
    let report: serde_json::Value = serde_json::from_slice(&project.read("baked/props/report.json")).unwrap();
    let warnings = report["warnings"].to_string();
    assert!(
        warnings.contains("material `crate`") && warnings.contains("`-bm 0.3`") && warnings.contains("dropped"),
        "{report}"
    );
}
