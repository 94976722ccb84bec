//! AO bakes end to end: the files of DESIGN §3.3 and their report, the BC4 map against the
//! 16-bit one, occluders, the ground plane, the fill, seams, mirrored islands, texels inside
//! geometry, the per-vertex mode and bad meshes.

use cirrus::config::BlockFormat;
use cirrus::texture::quality::decode_blocks;

use super::{ao_project, floor_and_box, read_png16, Part};
use crate::support::{build, ktx2_level, read_ktx2, TempProject};

/// The 16-bit map of material `material` of asset `scene`.
fn ao_map(project: &TempProject, material: &str) -> (u32, Vec<u16>) {
    read_png16(&project.read(&format!("baked/scene/{material}/ao.png")))
}

fn visibility(map: &(u32, Vec<u16>), x: u32, y: u32) -> f32 {
    map.1[(y * map.0 + x) as usize] as f32 / 65535.0
}

fn report(project: &TempProject) -> serde_json::Value {
    serde_json::from_slice(&project.read("baked/scene/report.json")).unwrap()
}

#[test]
fn a_box_on_a_floor_darkens_the_floor_around_it_and_every_file_is_written() {
    let project = ao_project(&floor_and_box(false), "size: 64, rays: 256, occluders: AllMeshes");
    let summary = build(&mut project.open());
    assert!(summary.all_ok(), "{}", summary.to_text());
    let floor = ao_map(&project, "floor");
    assert_eq!((floor.0, floor.1.len()), (64, 64 * 64));
    // Texel (x, y) is floor point (-2 + (x + 0.5) / 16, 0, -2 + (y + 0.5) / 16) (V up is −Z).
    let corner = visibility(&floor, 1, 1);
    let beside_the_box = visibility(&floor, 32, 22); // 0.47 from the middle, 0.03 from the box's −z face
    let under_the_box = visibility(&floor, 32, 32);
    assert!(corner > 0.9, "an open corner: {corner}");
    assert!(beside_the_box < 0.7 && beside_the_box > 0.3, "beside a wall about half is open: {beside_the_box}");
    // Under the box the floor is inside it (its rays leave through the box's back faces): those
    // texels are invalid and take the values of the floor beside the box.
    assert!(under_the_box < 0.7, "under the box: {under_the_box}");

    let report = report(&project);
    assert_eq!(report["kind"], "AmbientOcclusion");
    assert_eq!(report["mode"], "Texels");
    let materials = report["materials"].as_array().unwrap();
    let names: Vec<&str> = materials.iter().map(|material| material["name"].as_str().unwrap()).collect();
    assert_eq!(names, ["floor", "box"]);
    let floor_report = &materials[0];
    assert_eq!(floor_report["texels_baked"], 64 * 64, "the floor's UVs cover its whole map");
    assert_eq!(floor_report["rays_cast"], 64 * 64 * 256);
    let invalid = floor_report["invalid_texels"].as_u64().unwrap();
    assert!((240..=300).contains(&invalid), "the box stands on a sixteenth of the floor: {invalid} invalid texels");
    assert_eq!(floor_report["overlap_fraction"], 0.0);
    assert!(floor_report["rays_per_second"].as_f64().unwrap() > 0.0);
    // The asset's rate: both materials' rays over the wall time their tiles spanned together, so
    // at least the rays over the summed tile times of either material alone would give.
    let asset_rate = report["timings"]["rays_per_second"].as_f64().unwrap();
    let slowest =
        materials.iter().map(|material| material["rays_per_second"].as_f64().unwrap()).fold(f64::INFINITY, f64::min);
    assert!(asset_rate > slowest * 0.5, "asset {asset_rate} rays/s, slowest material {slowest}");
    assert_eq!(floor_report["texture"]["format"], "Bc4");
    assert_eq!(floor_report["texture"]["levels"], 7);

    // The BC4 map decodes to the 16-bit map's 8 bits, near the limit of 8-bit BC4 on smooth AO.
    let bytes = project.read("baked/scene/floor/ao.ktx2");
    let ktx2 = read_ktx2(&bytes);
    assert_eq!((ktx2.width, ktx2.height, ktx2.levels.len()), (64, 64, 7));
    let decoded = decode_blocks(BlockFormat::Bc4, &ktx2_level(&bytes, &ktx2, 0), 64, 64);
    let squared: f64 = floor
        .1
        .iter()
        .enumerate()
        .map(|(texel, &value)| (value as f64 / 257.0 - decoded.pixels[texel * 4] as f64).powi(2))
        .sum::<f64>()
        / floor.1.len() as f64;
    let psnr = 10.0 * (255.0f64 * 255.0 / squared.max(1e-12)).log10();
    assert!(psnr > 40.0, "BC4 against the 16-bit map: {psnr:.1} dB");
}

#[test]
fn each_object_occludes_only_itself_by_default_and_the_ground_plane_occludes_too() {
    // SelfOnly: the box is another object, so the floor under it is open.
    let project = ao_project(&floor_and_box(false), "size: 32, rays: 64");
    assert!(build(&mut project.open()).all_ok());
    let floor = ao_map(&project, "floor");
    assert!(floor.1.iter().all(|&value| value == u16::MAX), "nothing occludes a lone floor");

    // A lone box on the ground plane: its bottom face lies on the floor (closed), its sides see
    // the floor below their horizon.
    let project = ao_project(&floor_and_box(false)[1..], "size: 96, rays: 256, ground_plane: true");
    assert!(build(&mut project.open()).all_ok());
    let map = ao_map(&project, "box");
    // The UV columns of the faces: +z is the first sixth, −y the last; V = 0 is the bottom row.
    for row in [1, 48, 94] {
        let side = visibility(&map, 8, row);
        assert!((0.45..0.55).contains(&side), "a wall over an infinite floor sees half its sky at any height: {side}");
    }
    let bottom_face = visibility(&map, 88, 48);
    assert_eq!(bottom_face, 0.0, "the face on the floor is closed");
}

#[test]
fn every_texel_outside_the_islands_takes_a_baked_value_so_no_mip_reaches_background() {
    // A floor mapped onto the middle of its map only, under a box (AllMeshes): dark and light
    // texels, and a wide border no triangle touches.
    let parts = vec![
        Part::new("floor", "floor").floor(2.0, 0.0, 4, [0.26, 0.26, 0.74, 0.74], false),
        Part::new("box", "box").cuboid([-0.5, 0.0, -0.5], [0.5, 1.0, 0.5], [0.0, 0.0, 1.0, 1.0]),
    ];
    let project = ao_project(&parts, "size: 64, rays: 64, occluders: AllMeshes");
    assert!(build(&mut project.open()).all_ok());
    let (size, values) = ao_map(&project, "floor");
    let island = |x: u32, y: u32| (16..48).contains(&x) && (16..48).contains(&y);
    let baked: std::collections::BTreeSet<u16> = (0..size * size)
        .filter(|texel| island(texel % size, texel / size))
        .map(|texel| values[texel as usize])
        .collect();
    for texel in (0..size * size).filter(|texel| !island(texel % size, texel / size)) {
        assert!(
            baked.contains(&values[texel as usize]),
            "texel {texel} holds {}, no baked value",
            values[texel as usize]
        );
    }
    // Each border texel next to the island copies the island's edge texel beside it.
    for y in 16..48 {
        assert_eq!(values[(y * size + 15) as usize], values[(y * size + 16) as usize]);
        assert_eq!(values[(y * size + 48) as usize], values[(y * size + 47) as usize]);
    }
    assert_eq!(report(&project)["materials"][0]["texels_baked"], 32 * 32);
}

#[test]
fn texels_on_both_sides_of_a_uv_seam_agree_on_a_sphere() {
    // A sphere resting on the ground plane: its occlusion depends on latitude only, so the two
    // texels of a row at U = 0 and U = 1 (one seam apart on the surface, mirror images across
    // it) must agree.
    let parts = vec![Part::new("ball", "ball").sphere([0.0, 1.0, 0.0], 1.0, 32, 16)];
    let project = ao_project(&parts, "size: 32, rays: 16384, ground_plane: true");
    assert!(build(&mut project.open()).all_ok());
    let map = ao_map(&project, "ball");
    let mut worst = 0.0f32;
    for row in 2..30 {
        let (left, right) = (visibility(&map, 0, row), visibility(&map, 31, row));
        worst = worst.max((left - right).abs());
    }
    assert!(worst <= 1.0 / 255.0, "across the seam texels differ by up to {worst}");
    // And the sphere is darker towards the ground.
    assert!(visibility(&map, 0, 28) < visibility(&map, 0, 4) - 0.2);
}

#[test]
fn a_mirrored_island_bakes_the_same_surface_mirrored() {
    let straight = ao_project(&floor_and_box(false), "size: 32, rays: 1024, occluders: AllMeshes");
    let mirrored = ao_project(&floor_and_box(true), "size: 32, rays: 1024, occluders: AllMeshes");
    for project in [&straight, &mirrored] {
        assert!(build(&mut project.open()).all_ok());
    }
    let (a, b) = (ao_map(&straight, "floor"), ao_map(&mirrored, "floor"));
    assert_eq!(report(&mirrored)["materials"][0]["texels_baked"], 32 * 32, "the mirrored island is covered");
    let mut worst = 0.0f32;
    for y in 0..32 {
        for x in 0..32 {
            worst = worst.max((visibility(&a, x, y) - visibility(&b, 31 - x, y)).abs());
        }
    }
    assert!(worst < 0.05, "the mirrored bake differs from the straight one by up to {worst}");
}

#[test]
fn texels_inside_geometry_are_invalid_and_filled_unless_back_faces_block() {
    // A floor inside a closed box: its rays meet the box's inner (back) faces.
    let parts = vec![
        Part::new("floor", "floor").floor(0.5, 0.5, 2, [0.01, 0.01, 0.49, 0.49], false),
        Part::new("box", "box").cuboid([-1.0, 0.0, -1.0], [1.0, 2.0, 1.0], [0.0, 0.5, 1.0, 1.0]),
    ];
    let project = ao_project(&parts, "size: 32, rays: 64, occluders: AllMeshes");
    assert!(build(&mut project.open()).all_ok());
    let floor_report = &report(&project)["materials"][0];
    assert_eq!(floor_report["name"], "floor");
    assert_eq!(floor_report["invalid_texels"], 16 * 16, "every floor texel is inside the box");
    assert_eq!(floor_report["texels_baked"], 16 * 16, "the floor's texels were baked (and found inside)");

    let project = ao_project(&parts, "size: 32, rays: 64, occluders: AllMeshes, ignore_backfaces: false");
    assert!(build(&mut project.open()).all_ok());
    assert_eq!(report(&project)["materials"][0]["invalid_texels"], 0);
    let floor = ao_map(&project, "floor");
    assert_eq!(visibility(&floor, 8, 24), 0.0, "the box's inside closes the floor's sky");
}

#[test]
fn the_per_vertex_mode_interpolates_vertex_occlusion_across_each_triangle() {
    // The floor's grid points lie every 0.5; the box's faces 0.1 beyond the nearest of them.
    let parts = vec![
        Part::new("floor", "floor").floor(2.0, 0.0, 8, [0.0, 0.0, 1.0, 1.0], false),
        Part::new("box", "box").cuboid([-0.4, 0.0, -0.4], [0.4, 1.0, 0.4], [0.0, 0.0, 1.0, 1.0]),
    ];
    let project = ao_project(&parts, "size: 64, rays: 256, occluders: AllMeshes, mode: Vertices");
    let summary = build(&mut project.open());
    assert!(summary.all_ok(), "{}", summary.to_text());
    let ran: Vec<&str> = summary.assets[0].stages.iter().map(|stage| stage.stage.as_str()).collect();
    assert!(ran.contains(&"vertices"), "{ran:?}");
    let report = report(&project);
    assert_eq!(report["mode"], "Vertices");
    // The floor's 9 × 9 grid points are doubled per cell: 8² cells × 4 corners.
    assert_eq!(report["materials"][0]["rays_cast"], 8 * 8 * 4 * 256);
    assert!(report["materials"][0]["rays_per_second"].is_null());
    let floor = ao_map(&project, "floor");
    assert!(visibility(&floor, 0, 0) > 0.9, "the corner is open");
    // Texel (24, 32) is floor point (-0.47, 0, 0.03), beside grid point (-0.5, 0, 0), 0.1 from
    // the box's −x face: about half its sky is closed.
    let near_the_box = visibility(&floor, 24, 32);
    assert!((0.4..0.8).contains(&near_the_box), "{near_the_box}");
}

#[test]
fn meshes_without_uvs_or_with_bad_numbers_fail_with_a_message_naming_the_file() {
    let project = TempProject::new(
        r#"Pipeline(source: "assets", output: "baked", assets: [
            AmbientOcclusion(name: "plain", mesh: "plain.obj"),
            AmbientOcclusion(name: "nan", mesh: "nan.obj"),
            AmbientOcclusion(name: "flat", mesh: "flat.obj", ao: (size: 16, rays: 8)),
        ])"#,
    );
    project.write("assets/plain.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
    project.write("assets/nan.obj", "v 0 0 0\nv nan 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3\n");
    // Degenerate triangles (a point, a line, and one with a degenerate UV) beside a good one.
    project.write(
        "assets/flat.obj",
        "v 0 0 0\nv 1 0 0\nv 0 0 -1\nv 2 0 0\nvt 0 0\nvt 1 0\nvt 0 1\nvt 0.5 0.5\n\
         f 1/1 2/2 3/3\nf 1/1 1/1 1/1\nf 1/1 2/2 4/3\nf 1/4 2/4 3/4\n",
    );
    let summary = build(&mut project.open());
    let errors = |name: &str| {
        let asset = summary.assets.iter().find(|asset| asset.name == name).unwrap();
        asset.errors.iter().map(|error| format!("{}: {}", error.file, error.message)).collect::<Vec<_>>()
    };
    assert_eq!(
        errors("plain"),
        ["assets/plain.obj: the mesh has no texture coordinates: an AO bake needs a UV layout (`vt` in the OBJ)"]
    );
    let nan = errors("nan");
    assert!(nan.len() == 1 && nan[0].starts_with("assets/nan.obj: ") && nan[0].contains("non-finite"), "{nan:?}");
    assert!(errors("flat").is_empty(), "{:?}", errors("flat"));
    assert!(project.path("baked/flat/default/ao.ktx2").exists());
    // `check` says the same without baking.
    let output = project.run_cli(&["check"]);
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(stdout.contains("assets/plain.obj: the mesh has no texture coordinates"), "{stdout}");
}

#[test]
fn degenerate_uvs_fail_and_a_non_finite_one_is_named_with_its_line() {
    let project = TempProject::new(
        r#"Pipeline(source: "assets", output: "baked", assets: [
            AmbientOcclusion(name: "point", mesh: "point.obj", ao: (size: 16, rays: 8)),
            AmbientOcclusion(name: "nan", mesh: "nan_uv.obj", ao: (size: 16, rays: 8)),
        ])"#,
    );
    // Every corner at one UV: nothing of the map is covered (it used to bake all white, ok).
    project
        .write("assets/point.obj", "v 0 0 0\nv 1 0 0\nv 0 0 -1\nv 1 0 -1\nvt 0.5 0.5\nf 1/1 2/1 3/1\nf 2/1 4/1 3/1\n");
    // One `nan` among the texture coordinates (it used to read "the mesh has no texture coordinates").
    project.write("assets/nan_uv.obj", "v 0 0 0\nv 1 0 0\nv 0 0 -1\nvt 0 0\n  vt nan 0\nvt 0 1\nf 1/1 2/2 3/3\n");
    let summary = build(&mut project.open());
    let errors = |name: &str| {
        let asset = summary.assets.iter().find(|asset| asset.name == name).unwrap();
        asset
            .errors
            .iter()
            .map(|error| match (error.line, error.column) {
                (Some(line), Some(column)) => format!("{}:{line}:{column}: {}", error.file, error.message),
                _ => format!("{}: {}", error.file, error.message),
            })
            .collect::<Vec<_>>()
    };
    let point = errors("point");
    assert!(point.len() == 1 && point[0].contains("point.obj") && point[0].contains("covers no texel"), "{point:?}");
    assert!(!project.path("baked/point/default/ao.png").exists());
    assert_eq!(errors("nan"), ["assets/nan_uv.obj:5:3: a texture coordinate (`vt`) is not a finite number"]);
}

#[test]
fn uvs_outside_the_unit_square_are_reported() {
    let project = TempProject::new(
        r#"Pipeline(source: "assets", output: "baked", assets: [
            AmbientOcclusion(name: "wide", mesh: "wide.obj", ao: (size: 16, rays: 8)),
        ])"#,
    );
    project.write(
        "assets/wide.obj",
        "v 0 0 0\nv 1 0 0\nv 0 0 -1\nv 1 0 -1\nvt 0 0\nvt 1 0\nvt 0 1\nvt 1.5 1\nf 1/1 2/2 3/3\nf 2/2 4/4 3/3\n",
    );
    let summary = build(&mut project.open());
    assert!(summary.all_ok(), "{}", summary.to_text());
    let warnings = report_of(&project, "wide")["warnings"].to_string();
    assert!(
        warnings.contains("1 of its 2 triangles have texture coordinates outside [0, 1]")
            && warnings.contains("u ∈ [0, 1.5]"),
        "{warnings}"
    );
    // `build` prints them under the asset too, and its JSON summary carries them.
    let text = summary.to_text();
    assert!(
        text.contains("warning: assets/wide.obj: material `default`")
            || text.contains("warning: assets/wide.obj: material"),
        "{text}"
    );
    let output = project.run_cli(&["build", "--summary", "json"]);
    let json: serde_json::Value = serde_json::from_slice(&output.stdout).unwrap();
    assert!(json["assets"][0]["warnings"][0]["message"].as_str().unwrap().contains("outside [0, 1]"), "{json}");
}

fn report_of(project: &TempProject, asset: &str) -> serde_json::Value {
    serde_json::from_slice(&project.read(&format!("baked/{asset}/report.json"))).unwrap()
}
