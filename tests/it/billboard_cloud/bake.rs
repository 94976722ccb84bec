//! Billboard clouds through the build: artifacts on disk, and incrementality from salsa's event
//! log (a bark texture edit re-renders only the rectangles holding bark; the LOD mesh is
//! untouched; an encode setting re-runs only encoders; a mesh edit re-runs everything).

use std::collections::BTreeSet;
use std::path::Path;

use crate::support::{build, cutout_png, pattern_png, TempProject};

/// A small tree: a box trunk of bark quads and a crown of leaf cards at several orientations.
fn tree_obj(leaf_tilt: f32) -> String {
    let mut obj = String::from("mtllib tree.mtl\n");
    let mut vertices = 0;
    let mut quad = |obj: &mut String, corners: [[f32; 3]; 4], material: &str| {
        obj.push_str(&format!("usemtl {material}\n"));
        for [x, y, z] in corners {
            obj.push_str(&format!("v {x} {y} {z}\n"));
        }
        for [u, v] in [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]] {
            obj.push_str(&format!("vt {u} {v}\n"));
        }
        let b = vertices + 1;
        obj.push_str(&format!("f {}/{} {}/{} {}/{} {}/{}\n", b, b, b + 1, b + 1, b + 2, b + 2, b + 3, b + 3));
        vertices += 4;
    };
    let (r, h) = (0.3, 4.0);
    for [a, b] in [[[-r, -r], [r, -r]], [[r, -r], [r, r]], [[r, r], [-r, r]], [[-r, r], [-r, -r]]] {
        quad(&mut obj, [[a[0], 0.0, a[1]], [b[0], 0.0, b[1]], [b[0], h, b[1]], [a[0], h, a[1]]], "bark");
    }
    for index in 0..24 {
        let angle = index as f32 * 0.9;
        let (cx, cy, cz) = (1.5 * angle.cos(), 3.0 + (index % 4) as f32 * 0.5, 1.5 * angle.sin());
        let (dx, dz) = (0.4 * (angle + leaf_tilt).cos(), 0.4 * (angle + leaf_tilt).sin());
        quad(
            &mut obj,
            [
                [cx - dx, cy - 0.4, cz - dz],
                [cx + dx, cy - 0.4, cz + dz],
                [cx + dx, cy + 0.4, cz + dz],
                [cx - dx, cy + 0.4, cz - dz],
            ],
            "leaves",
        );
    }
    obj
}

pub(crate) fn tree_project() -> TempProject {
    let project = TempProject::new(
        r#"Pipeline(source: "assets", output: "baked", assets: [
            BillboardCloud(name: "tree", mesh: "tree.obj", atlas: (max_size: 256, padding: 2)),
        ])"#,
    );
    project.write("assets/tree.obj", tree_obj(0.0));
    project.write(
        "assets/tree.mtl",
        "newmtl bark\nKd 1 1 1\nmap_Kd bark.png\nnorm bark_normal.png\nPm 0\nPr 0.9\n\nnewmtl leaves\nKd 1 1 1\nmap_Kd leaf.png\nmap_d leaf.png\nPr 0.6\n",
    );
    project.write("assets/bark.png", pattern_png(32, 32, 1));
    project.write("assets/bark_normal.png", crate::support::png_bytes(4, 4, &[128, 128, 255, 255].repeat(16)));
    project.write("assets/leaf.png", cutout_png(64, 64));
    project
}

/// The render stages (one per plane and material set) that show `material`, recomputed with the
/// pure stages.
fn render_stages_showing(project: &TempProject, material: &str) -> BTreeSet<String> {
    let obj = project.read("assets/tree.obj");
    let libraries =
        [(Path::new("assets/tree.mtl").to_path_buf(), Some(project.read("assets/tree.mtl")))].into_iter().collect();
    let (mesh, _) =
        cirrus::mesh::load_mesh(Path::new("assets/tree.obj"), &obj, &libraries, Path::new("assets")).expect("loads");
    let planes = cirrus::kinds::billboard_cloud::planes::select_planes(
        &mesh.positions,
        &mesh.triangles,
        &mesh.triangle_materials,
        cirrus::kinds::billboard_cloud::planes::PlaneSettings { epsilon: 0.02, max_planes: None, max_quads: None },
    );
    let rectangles =
        cirrus::kinds::billboard_cloud::rectangles::plane_rectangles(&mesh.positions, &mesh.triangles, &planes);
    let index = mesh.materials.iter().position(|m| m.name == material).expect("material") as u32;
    cirrus::kinds::billboard_cloud::render_groups::render_groups(&mesh, &rectangles)
        .iter()
        .filter(|group| group.materials.contains(&index))
        .map(|group| {
            format!("render(tree/{})", cirrus::kinds::billboard_cloud::render_groups::render_group_label(&mesh, group))
        })
        .collect()
}

#[test]
fn a_billboard_cloud_bakes_its_lod_and_atlas() {
    let project = tree_project();
    let summary = build(&mut project.open());
    assert!(summary.all_ok(), "{}", summary.to_text());
    let report: serde_json::Value = serde_json::from_slice(&project.read("baked/tree/report.json")).expect("report");
    assert_eq!(report["faces"], 56);
    assert!(report["max_error_world"].as_f64().unwrap() <= report["epsilon_world"].as_f64().unwrap() * 1.0001);
    assert!(
        report["atlas"]["coverage"].as_f64().unwrap() > 0.05,
        "the atlas holds rendered texels: {}",
        report["atlas"]
    );
    for surface in ["albedo", "mra", "normal", "height"] {
        let ktx2 = crate::support::read_ktx2(&project.read(&format!("baked/tree/{surface}.ktx2")));
        assert_eq!(
            (ktx2.width, ktx2.height),
            (report["atlas"]["width"].as_u64().unwrap() as u32, report["atlas"]["height"].as_u64().unwrap() as u32)
        );
    }
    assert_eq!(crate::support::read_ktx2(&project.read("baked/tree/height.ktx2")).vk_format, 139, "BC4");
}

#[test]
fn a_bark_texture_edit_rerenders_only_bark_planes_and_leaves_the_lod_alone() {
    let project = tree_project();
    let mut cirrus = project.open();
    build(&mut cirrus);
    cirrus.take_executed_stages();
    let lod = project.read("baked/tree/lod.obj");
    let leaves_before = project.read("baked/tree/mra.ktx2");

    project.write("assets/bark.png", pattern_png(32, 32, 7));
    let summary = build(&mut cirrus);
    assert!(summary.all_ok(), "{}", summary.to_text());
    let executed: BTreeSet<String> = cirrus.take_executed_stages().into_iter().collect();
    let mut expected = render_stages_showing(&project, "bark");
    let leaf_only: Vec<String> = render_stages_showing(&project, "leaves").difference(&expected).cloned().collect();
    assert!(!expected.is_empty() && !leaf_only.is_empty(), "the fixture has bark render stages and leaf-only ones");
    expected.extend(
        ["decode(assets/bark.png)", "atlas(tree)", "mips(tree/albedo)", "encode(tree/albedo)", "write(tree/albedo)"]
            .map(String::from),
    );
    assert_eq!(executed, expected, "exactly the render stages showing bark, the atlas and the albedo surface's tail");
    assert_eq!(project.read("baked/tree/lod.obj"), lod, "lod.obj is untouched by texture edits");
    assert_eq!(project.read("baked/tree/mra.ktx2"), leaves_before, "mra did not change");
    // Re-filtering and re-encoding only what changed bakes what a clean build of the edited
    // sources bakes.
    let clean = tree_project();
    clean.write("assets/bark.png", pattern_png(32, 32, 7));
    build(&mut clean.open());
    for artifact in ["albedo.ktx2", "mra.ktx2", "normal.ktx2", "height.ktx2", "lod.obj"] {
        let path = format!("baked/tree/{artifact}");
        assert!(project.read(&path) == clean.read(&path), "{artifact} differs from a clean build's");
    }

    // An encode setting re-runs only the encoder that reads it.
    let pipeline = String::from_utf8(project.read("pipeline.ron")).unwrap();
    std::fs::write(
        project.path("pipeline.ron"),
        pipeline
            .replace("atlas: (max_size: 256, padding: 2)", "atlas: (max_size: 256, padding: 2), encode: (mra: Bc7)"),
    )
    .unwrap();
    cirrus.reconfigure(cirrus::pipeline::load_pipeline(&project.path("pipeline.ron")).unwrap());
    build(&mut cirrus);
    // The bark edit found the mra surface in the cache by its parts without compositing it:
    // it is composited now, with the same texels, so its mips do not run again.
    assert_eq!(
        cirrus.take_executed_stages(),
        ["atlas(tree)", "encode(tree/mra)", "write(tree/mra)"],
        "the mips are the same"
    );

    // A mesh edit re-runs everything downstream of it.
    project.write("assets/tree.obj", tree_obj(0.3));
    build(&mut cirrus);
    let executed = cirrus.take_executed_stages();
    for stage in [
        "mesh(tree)",
        "planes(tree)",
        "layout(tree)",
        "atlas(tree)",
        "lod(tree)",
        "encode(tree/albedo)",
        "encode(tree/height)",
    ] {
        assert!(executed.iter().any(|e| e == stage), "{stage} re-ran after a mesh edit: {executed:?}");
    }
    assert_ne!(project.read("baked/tree/lod.obj"), lod, "a new LOD mesh");
}

#[test]
fn an_unchanged_billboard_cloud_runs_no_stage_in_process_or_after_a_restart() {
    let project = tree_project();
    let mut cirrus = project.open();
    build(&mut cirrus);
    cirrus.take_executed_stages();
    let again = build(&mut cirrus);
    assert_eq!(cirrus.take_executed_stages(), Vec::<String>::new());
    let mut restarted = project.open();
    let summary = build(&mut restarted);
    assert_eq!(restarted.take_executed_stages(), Vec::<String>::new(), "the persistent cache has it");
    for stage in &summary.assets[0].stages {
        assert_eq!(stage.status, cirrus::summary::StageStatus::Cached, "{stage:?}");
    }
    assert_eq!(summary.revision, again.revision);
}

#[test]
fn preview_of_the_bundled_bush_writes_a_contact_sheet_and_metrics() {
    let project = TempProject::new(
        r#"Pipeline(source: "assets", output: "baked", assets: [
            BillboardCloud(name: "bush", mesh: "trees/bush_2.obj", atlas: (max_size: 1024)),
        ])"#,
    );
    let trees = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/assets/trees");
    std::fs::create_dir_all(project.path("assets")).unwrap();
    std::os::unix::fs::symlink(trees, project.path("assets/trees")).unwrap();
    // As CI jobs and services run it: no session variables. Mesa's Wayland probe must not greet
    // the user with "error: XDG_RUNTIME_DIR is invalid or not set".
    let output = std::process::Command::new(env!("CARGO_BIN_EXE_cirrus"))
        .args(["preview", "--asset", "bush"])
        .current_dir(project.root())
        .env_remove("XDG_RUNTIME_DIR")
        .env_remove("WAYLAND_DISPLAY")
        .output()
        .unwrap();
    assert_eq!(output.status.code(), Some(0), "{}", String::from_utf8_lossy(&output.stderr));
    assert!(
        !String::from_utf8_lossy(&output.stderr).contains("XDG_RUNTIME_DIR"),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let metrics: serde_json::Value =
        serde_json::from_slice(&project.read("baked/bush/preview/metrics.json")).expect("metrics.json");
    let views = metrics["views"].as_array().expect("views");
    assert_eq!(views.len(), 26);
    let directions: BTreeSet<String> = views.iter().map(|view| view["direction"].to_string()).collect();
    assert_eq!(directions.len(), 26, "26 distinct directions");
    // Per view, what the LOD misses and draws beyond the source (fractions of the source's
    // silhouette) are the two sides of its IoU: (1 − missed) / (1 + extra).
    for view in views {
        let (iou, missed, extra) =
            (view["iou"].as_f64().unwrap(), view["missed"].as_f64().unwrap(), view["extra"].as_f64().unwrap());
        assert!((iou - (1.0 - missed) / (1.0 + extra)).abs() < 1e-9 && missed > 0.0 && extra > 0.0, "{view}");
    }
    assert!(
        metrics["mean_missed"].as_f64().unwrap() > 0.0 && metrics["mean_extra"].as_f64().unwrap() > 0.0,
        "{metrics}"
    );
    let mean = metrics["mean_iou"].as_f64().unwrap();
    println!("bundled bush, 1024² atlas: mean IoU {mean:.3}, {} samples per pixel", metrics["samples_per_pixel"]);
    assert_eq!(metrics["samples_per_pixel"], 16);
    // The bar of DESIGN §7.
    assert!(mean >= 0.85, "mean IoU {mean}");
    assert!(metrics["min_iou"].as_f64().unwrap() <= mean && metrics["mean_psnr"].as_f64().unwrap() > 20.0);
    // What a pixel of displacement costs the bush's lacy silhouette (a solid disc of the view's
    // size would keep about 0.99).
    let shift = metrics["source_shift_iou"].as_f64().unwrap();
    assert!((0.6..0.95).contains(&shift), "the source against itself moved 1 pixel: IoU {shift}");
    let sheet = image::load_from_memory(&project.read("baked/bush/preview/contact_sheet.png")).expect("PNG");
    assert_eq!(
        (sheet.width(), sheet.height()),
        (4 * 2 * 256 + 3 * 8, 7 * 256 + 6 * 8),
        "source | LOD pairs, four per row"
    );
    assert_eq!(project.run_cli(&["preview", "--asset", "nope"]).status.code(), Some(2));
}

#[test]
fn a_stand_in_moves_each_face_onto_its_plane_as_asked() {
    use cirrus::kinds::billboard_cloud::lod_preview::{stand_in_position, StandIn};
    // A face tilted against the plane z = 1: its corners at heights 0, 2 and 4 above it.
    let corners = [[0.0, 0.0, 1.0], [1.0, 0.0, 3.0], [0.0, 1.0, 5.0]];
    let plane = Some(([0.0, 0.0, 1.0], 1.0));
    let at = |stand_in, corner| stand_in_position(stand_in, corners, corner, plane);
    for corner in 0..3 {
        assert_eq!(at(StandIn::Baked, corner), corners[corner]);
        assert_eq!(
            stand_in_position(StandIn::Projected, corners, corner, None),
            corners[corner],
            "a face without a plane stays"
        );
        // Projected: onto the plane, straight down.
        assert_eq!(at(StandIn::Projected, corner), [corners[corner][0], corners[corner][1], 1.0]);
        // Translated: the whole face down by its mean height (2), keeping its shape and tilt.
        assert_eq!(at(StandIn::Translated, corner), [corners[corner][0], corners[corner][1], corners[corner][2] - 2.0]);
    }
}

#[test]
fn a_preview_with_a_stand_in_tells_what_the_planes_cost_from_what_the_atlas_costs() {
    // Two unit squares 0.4 apart in depth and one budget quad: one plane through both, so every
    // view at an angle sees them drawn displaced. Stacked, they are parallel to the plane between
    // them: projecting them onto it is translating them, and a flat colour loses little in the
    // atlas, so the baked LOD scores about what its plane allows. Side by side, the plane that
    // fits them best is tilted: projected, they are also foreshortened.
    let stacked =
        "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 0.4\nv 1 0 0.4\nv 1 1 0.4\nv 0 1 0.4\nf 1 2 3 4\nf 5 6 7 8\n";
    let side_by_side = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 1.2 0 0.4\nv 2.2 0 0.4\nv 2.2 1 0.4\nv 1.2 1 0.4\nf 1 2 3 4\nf 5 6 7 8\n";
    let mut figures = Vec::new();
    for obj in [stacked, side_by_side] {
        let project = TempProject::new(
            r#"Pipeline(source: "assets", output: "baked", assets: [
                BillboardCloud(name: "squares", mesh: "squares.obj", billboard: (budget: Some(Quads(1))), atlas: (max_size: 512)),
            ])"#,
        );
        project.write("assets/squares.obj", obj);
        let mut ious = Vec::new();
        for stand_in in ["baked", "projected", "translated"] {
            let output = project.run_cli(&["preview", "--asset", "squares", "--stand-in", stand_in, "--size", "64"]);
            assert_eq!(output.status.code(), Some(0), "{}", String::from_utf8_lossy(&output.stderr));
            let stdout = String::from_utf8_lossy(&output.stdout);
            assert_eq!(
                stdout.contains(&format!("source faces {stand_in} onto the planes")),
                stand_in != "baked",
                "{stdout}"
            );
            let folder = if stand_in == "baked" { "preview".to_string() } else { format!("preview_{stand_in}") };
            let metrics: serde_json::Value =
                serde_json::from_slice(&project.read(&format!("baked/squares/{folder}/metrics.json"))).unwrap();
            ious.push(metrics["mean_iou"].as_f64().unwrap());
        }
        let report: serde_json::Value = serde_json::from_slice(&project.read("baked/squares/report.json")).unwrap();
        assert_eq!(report["quads"], 1);
        assert_eq!(project.run_cli(&["preview", "--asset", "squares", "--stand-in", "nope"]).status.code(), Some(2));
        figures.push(ious);
    }
    println!(
        "two squares on one plane, mean IoU (baked, projected, translated): stacked {:?}, side by side {:?}",
        figures[0], figures[1]
    );
    let (&[baked, projected, translated], &[_, tilted_projected, tilted_translated]) =
        (&figures[0][..], &figures[1][..])
    else {
        unreachable!()
    };
    assert!(projected < 0.95, "the squares are drawn displaced: {figures:?}");
    assert!((projected - translated).abs() < 0.01, "parallel faces: projecting is translating: {figures:?}");
    assert!((baked - projected).abs() < 0.05, "a flat colour costs the atlas little: {figures:?}");
    assert!(tilted_translated > tilted_projected + 0.1, "a tilted plane foreshortens what it projects: {figures:?}");
}

/// A trunk along y: `rings` rings of `segments` vertices, tapering from radius 0.35 to 0.2 over
/// height 6 and twisting by a third of a segment per ring (as generated trees are), open ends.
fn trunk_obj(segments: usize, rings: usize) -> String {
    let mut obj = String::from("mtllib trunk.mtl\nusemtl bark\n");
    for ring in 0..=rings {
        let t = ring as f32 / rings as f32;
        let radius = 0.35 - 0.15 * t;
        for index in 0..=segments {
            let angle = (index as f32 + ring as f32 / 3.0) / segments as f32 * std::f32::consts::TAU;
            obj.push_str(&format!(
                "v {} {} {}\nvt {} {t}\n",
                radius * angle.cos(),
                6.0 * t,
                radius * angle.sin(),
                index as f32 / segments as f32
            ));
        }
    }
    let vertex = |ring: usize, index: usize| ring * (segments + 1) + index + 1;
    for ring in 0..rings {
        for index in 0..segments {
            let [a, b, c, d] =
                [vertex(ring, index), vertex(ring, index + 1), vertex(ring + 1, index + 1), vertex(ring + 1, index)];
            obj.push_str(&format!("f {a}/{a} {d}/{d} {c}/{c} {b}/{b}\n"));
        }
    }
    obj
}

#[test]
fn a_solid_trunk_split_between_planes_shows_no_cracks() {
    // The same trunk, solid, and declared cut-out (`d` just below 1: every texel still passes
    // the cutoff), which keeps each face on its own plane only.
    let mut figures = Vec::new();
    for declaration in ["", "d 0.999\n"] {
        let project = TempProject::new(
            r#"Pipeline(source: "assets", output: "baked", assets: [
                BillboardCloud(name: "trunk", mesh: "trunk.obj", atlas: (max_size: 512)),
            ])"#,
        );
        project.write("assets/trunk.obj", trunk_obj(12, 8));
        project.write("assets/trunk.mtl", format!("newmtl bark\nKd 0.4 0.3 0.2\n{declaration}map_Kd bark.png\n"));
        project.write("assets/bark.png", pattern_png(32, 32, 1));
        let output = project.run_cli(&["preview", "--asset", "trunk"]);
        assert_eq!(output.status.code(), Some(0), "{}", String::from_utf8_lossy(&output.stderr));
        let report: serde_json::Value = serde_json::from_slice(&project.read("baked/trunk/report.json")).unwrap();
        let metrics: serde_json::Value =
            serde_json::from_slice(&project.read("baked/trunk/preview/metrics.json")).unwrap();
        figures.push((
            report["planes"].as_u64().unwrap(),
            report["faces_also_drawn"].as_u64().unwrap(),
            metrics["mean_iou"].as_f64().unwrap(),
            metrics["min_iou"].as_f64().unwrap(),
        ));
    }
    println!(
        "trunk (planes, faces also drawn, mean IoU, min IoU): solid {:?}, declared cut-out {:?}",
        figures[0], figures[1]
    );
    let [(planes, also_drawn, solid_mean, solid_min), (_, cut_out_also_drawn, cut_out_mean, cut_out_min)] = figures[..]
    else {
        unreachable!()
    };
    assert!(planes >= 3 && also_drawn > 0 && cut_out_also_drawn == 0, "{figures:?}");
    // Cracks show most where the view is at an angle to two planes: the worst view gains most.
    assert!(solid_min > cut_out_min + 0.1 && solid_mean > cut_out_mean, "{figures:?}");
}

#[test]
fn crack_filling_draws_a_face_only_on_planes_it_meets() {
    // The bundled bush at 64 quads, every material taken as solid: ε is large under a budget,
    // and a face within ε of another plane is drawn there only when it shares a vertex (by
    // position) with a face of that plane, where the surface passes from one plane to the other.
    let bush = crate::support::bundled_bush();
    let (positions, triangles) = (&bush.positions, &bush.triangles);
    let planes = cirrus::kinds::billboard_cloud::planes::select_planes_within_budget(
        positions,
        triangles,
        &bush.triangle_materials,
        64,
        None,
        cirrus::kinds::billboard_cloud::planes::SEAM_WEIGHT,
    );
    let rectangles = cirrus::kinds::billboard_cloud::rectangles::plane_rectangles(positions, triangles, &planes);
    let mut rectangles = cirrus::kinds::billboard_cloud::rectangles::merge_rectangles_to_budget(
        positions, triangles, &planes, rectangles, 64,
    );
    let solid_materials = vec![true; bush.materials.len().max(1)];
    let input = cirrus::kinds::billboard_cloud::rectangles::CrackFillingInput {
        positions,
        triangles,
        face_materials: &bush.triangle_materials,
        solid_materials: &solid_materials,
    };
    cirrus::kinds::billboard_cloud::rectangles::add_crack_filling_faces(&input, &planes, &mut rectangles);
    let corners_of = |face: u32| triangles[face as usize].map(|vertex| positions[vertex as usize].map(f32::to_bits));
    let mut also_drawn = 0;
    for rectangle in &rectangles {
        let plane = &planes.planes[rectangle.plane as usize];
        let plane_corners: BTreeSet<[u32; 3]> = plane.faces.iter().flat_map(|&face| corners_of(face)).collect();
        for &face in &rectangle.also_drawn {
            assert!(!plane.faces.contains(&face), "face {face} is drawn twice on its own plane");
            assert!(
                corners_of(face).iter().any(|corner| plane_corners.contains(corner)),
                "face {face} does not meet plane {}",
                rectangle.plane
            );
            also_drawn += 1;
        }
    }
    println!("bush at 64 quads: {also_drawn} faces also drawn of {}", triangles.len());
    assert!(also_drawn > 0, "crack filling still draws the faces at the seams");
}

/// The stages of `asset` in a `build --summary json` printed on stdout: (stage, instance) → status.
fn stage_statuses(output: &std::process::Output, asset: &str) -> Vec<(String, String, String)> {
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    let summary: serde_json::Value = serde_json::from_slice(&output.stdout).expect("summary JSON");
    let asset = summary["assets"].as_array().unwrap().iter().find(|entry| entry["name"] == asset).expect("the asset");
    asset["stages"]
        .as_array()
        .unwrap()
        .iter()
        .map(|stage| {
            let text = |key: &str| stage[key].as_str().unwrap().to_string();
            (text("stage"), text("instance"), text("status"))
        })
        .collect()
}

#[test]
fn after_a_restart_a_leaf_colour_edit_reuses_mesh_planes_layout_lod_and_the_unchanged_encodes() {
    let project = TempProject::new(
        r#"Pipeline(source: "assets", output: "baked", assets: [
            BillboardCloud(name: "bush", mesh: "trees/bush_2.obj", atlas: (max_size: 512)),
        ])"#,
    );
    let trees = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/assets/trees");
    let textures =
        ["aspen_color.png", "oak_color_1k.jpg", "oak_normal_1k.jpg", "oak_roughness_1k.jpg", "oak_ao_1k.jpg"];
    for file in ["bush_2.obj".to_string(), "bush_2.mtl".to_string()]
        .into_iter()
        .chain(textures.map(|texture| format!("textures/{texture}")))
    {
        project.write(&format!("assets/trees/{file}"), std::fs::read(trees.join(&file)).unwrap());
    }
    let first = stage_statuses(&project.run_cli(&["build", "--summary", "json"]), "bush");
    assert!(first.iter().all(|(_, _, status)| status == "ran"), "{first:?}");

    // Another process after a colour edit of the leaves (alpha kept, so coverage is the same).
    let leaves = image::load_from_memory(&project.read("assets/trees/textures/aspen_color.png")).unwrap().into_rgba8();
    let (width, height) = leaves.dimensions();
    let recoloured: Vec<u8> =
        leaves.into_raw().chunks_exact(4).flat_map(|texel| [texel[1], texel[0], texel[2], texel[3]]).collect();
    project.write("assets/trees/textures/aspen_color.png", crate::support::png_bytes(width, height, &recoloured));
    let second = stage_statuses(&project.run_cli(&["build", "--summary", "json"]), "bush");
    let status = |stage: &str, instance: Option<&str>| -> BTreeSet<String> {
        second
            .iter()
            .filter(|(name, this_instance, _)| {
                name == stage && instance.is_none_or(|instance| instance == this_instance)
            })
            .map(|(_, _, status)| status.clone())
            .collect()
    };
    let cached = BTreeSet::from(["cached".to_string()]);
    let ran = BTreeSet::from(["ran".to_string()]);
    for stage in ["mesh", "planes", "layout", "lod"] {
        assert_eq!(status(stage, None), cached, "{stage}: {second:?}");
    }
    // Plane images come from the render memo, except the render groups that show the leaves.
    for (_, instance, state) in second.iter().filter(|(stage, _, _)| stage == "render") {
        let shows_leaves = instance
            .split(':')
            .nth(1)
            .is_some_and(|materials| materials.split('+').any(|material| material == "leaves"));
        assert_eq!(state, if shows_leaves { "ran" } else { "cached" }, "render({instance})");
    }
    assert_eq!(status("render", None).len(), 2, "the bush has render groups with and without leaves");
    assert_eq!(status("atlas", None), ran);
    // The unchanged textures' mip chains come from the cache: only the leaves are decoded.
    for (_, instance, state) in second.iter().filter(|(stage, _, _)| stage == "decode") {
        assert_eq!(state, if instance.ends_with("aspen_color.png") { "ran" } else { "cached" }, "decode({instance})");
    }
    assert_eq!(status("encode", Some("albedo")), ran, "the leaves' colour is in the albedo");
    for surface in ["mra", "normal", "height"] {
        assert_eq!(status("encode", Some(surface)), cached, "{surface}: {second:?}");
    }
}

#[test]
fn a_failed_artifact_write_keeps_the_last_good_report() {
    let project = tree_project();
    // A folder where an artifact goes: that write fails.
    std::fs::create_dir_all(project.path("baked/tree/albedo.png/in_the_way")).unwrap();
    let summary = build(&mut project.open());
    let tree = summary.assets.iter().find(|asset| asset.name == "tree").unwrap();
    assert!(tree.errors.iter().any(|error| error.file == "baked/tree/albedo.png"), "{}", summary.to_text());
    assert!(!project.path("baked/tree/report.json").exists(), "no report describes files that are not there");
    std::fs::remove_dir_all(project.path("baked/tree/albedo.png")).unwrap();
    assert!(build(&mut project.open()).all_ok());
    assert!(project.path("baked/tree/report.json").exists());
}

#[test]
fn memo_entries_that_do_not_fit_are_misses_and_the_bake_equals_a_clean_one() {
    let project = tree_project();
    build(&mut project.open());
    // Replace every memo with a well-formed entry (valid checksum) whose contents do not fit:
    // images of the wrong size, blocks and errors that do not match their levels.
    let cache_folder = project.path("baked/.cirrus/cache");
    let cache = cirrus::cache::DiskCache::new(&cache_folder);
    let mut replaced = 0;
    for stage in ["render-memo", "encoding-memo", "atlas-fill", "source-mips"] {
        for prefix in std::fs::read_dir(cache_folder.join(stage)).unwrap().flatten() {
            for entry in std::fs::read_dir(prefix.path()).unwrap().flatten() {
                let hex = format!("{}{}", prefix.file_name().to_string_lossy(), entry.file_name().to_string_lossy());
                let key = cirrus::cache::CacheKey(blake3::Hash::from_hex(&hex).unwrap());
                let mut real = cache.load(stage, key).unwrap();
                if stage == "render-memo" {
                    // Every group of the real memo, each with one 1×1 image.
                    let groups: Vec<(String, Vec<(u32, u32)>)> =
                        serde_json::from_value(real.metadata["groups"].clone()).unwrap();
                    real.metadata = serde_json::json!({ "groups": groups.iter().map(|(group, _)| (group, [(1, 1)])).collect::<Vec<_>>() });
                    real.blobs = vec![vec![7; groups.len() * 16]];
                } else if stage == "atlas-fill" {
                    // A source for every texel, all far outside the atlas.
                    real.blobs = vec![vec![0xff; real.blobs[0].len()]];
                } else if stage == "source-mips" {
                    // A chain whose levels do not halve.
                    real.metadata = serde_json::json!(vec![(1, 1); real.blobs.len()]);
                } else {
                    // The real fingerprints and levels, with block data and errors that do
                    // not fit them.
                    let levels = real.metadata["levels"].as_array().unwrap().len();
                    for blob in &mut real.blobs[2 + levels..] {
                        blob.truncate(3);
                    }
                }
                cache.store(stage, key, real);
                replaced += 1;
            }
        }
    }
    cache.flush();
    // A render memo per material set the planes show (two), one encoding memo (the BC7
    // albedo), one fill, and three source mip chains (bark colour and normal, leaf colour: its
    // `map_d` names the same file).
    assert_eq!(replaced, 7);

    // A new process after a one-texel bark edit renders and encodes what it must, and bakes what
    // a clean build of the edited sources bakes. (Without the checks, the render memo's groups
    // panic the atlas; the encoding memo's blocks go unused here because the edit changes most
    // blocks, and its check guards edits that change few.)
    let mut bark = image::load_from_memory(&pattern_png(32, 32, 1)).unwrap().into_rgba8();
    bark.put_pixel(5, 5, image::Rgba([255, 0, 0, 255]));
    let bark = crate::support::png_bytes(32, 32, bark.as_raw());
    project.write("assets/bark.png", &bark);
    let summary = build(&mut project.open());
    assert!(summary.all_ok(), "{}", summary.to_text());
    let clean = tree_project();
    clean.write("assets/bark.png", &bark);
    build(&mut clean.open());
    for artifact in ["albedo.ktx2", "mra.ktx2", "normal.ktx2", "height.ktx2", "lod.obj"] {
        let path = format!("baked/tree/{artifact}");
        assert!(project.read(&path) == clean.read(&path), "{artifact} differs from a clean build's");
    }
}
