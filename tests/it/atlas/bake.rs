//! Atlas assets end to end: `atlas.json` as DESIGN §3.5 has it, every entry read back from the
//! decoded page at its rectangle, aliases, new files joining by glob, and bad inputs.

use cirrus::config::BlockFormat;
use cirrus::texture::quality::decode_blocks;

use crate::support::{build, decode_png, ktx2_level, pattern_png, png_bytes, read_ktx2, PsnrSum, TempProject};

fn atlas_project() -> TempProject {
    let project = TempProject::new(
        r#"Pipeline(source: "assets", output: "baked", assets: [
            Atlas(name: "ui", textures: ["ui/*.png", "extra/*.png"], pack: (max_size: 512, padding: 4)),
        ])"#,
    );
    for (index, (width, height)) in [(64, 32), (20, 72), (36, 36), (120, 16)].into_iter().enumerate() {
        project.write(&format!("assets/ui/icon{index}.png"), pattern_png(width, height, index as u32 + 1));
    }
    // The same pixels under another name: one rectangle, two names.
    project.write("assets/ui/copy.png", pattern_png(36, 36, 3));
    // A sprite with a transparent border of 3 texels.
    let mut sprite = vec![0u8; 30 * 20 * 4];
    for y in 3..17 {
        for x in 3..27 {
            sprite[(y * 30 + x) * 4..][..4].copy_from_slice(&[200, (x * 8) as u8, (y * 12) as u8, 255]);
        }
    }
    project.write("assets/ui/sprite.png", png_bytes(30, 20, &sprite));
    project
}

#[test]
fn every_entry_reads_back_from_the_page_at_its_rectangle_and_aliases_share_one() {
    let project = atlas_project();
    let summary = build(&mut project.open());
    assert!(summary.all_ok(), "{}", summary.to_text());
    let table: serde_json::Value = serde_json::from_slice(&project.read("baked/ui/atlas.json")).unwrap();
    let entries = table["entries"].as_array().unwrap();
    let names: Vec<&str> = entries.iter().map(|entry| entry["name"].as_str().unwrap()).collect();
    assert_eq!(names, ["ui/copy.png", "ui/icon0.png", "ui/icon1.png", "ui/icon3.png", "ui/sprite.png"]);
    let copy = &entries[0];
    let alias = &copy["aliases"][0];
    assert_eq!(copy["aliases"].as_array().map(Vec::len), Some(1), "{copy}");
    assert_eq!(alias["name"], "ui/icon2.png");
    // Same canvas, same place in it: the entry's own transform.
    for key in ["source_size", "trim_offset", "uv_offset", "uv_scale"] {
        assert_eq!(alias[key], copy[key], "{key}");
    }
    let sprite = &entries[4];
    assert_eq!(
        (sprite["source_size"].clone(), sprite["trim_offset"].clone()),
        (serde_json::json!([30, 20]), serde_json::json!([3, 3]))
    );
    assert_eq!((sprite["width"].as_u64(), sprite["height"].as_u64()), (Some(24), Some(14)));
    // The page decoded from its blocks: each entry where the table says (BC7 on patterns).
    let page = &table["pages"][0];
    assert_eq!(page["file"], "atlas.ktx2");
    let bytes = project.read("baked/ui/atlas.ktx2");
    let ktx2 = read_ktx2(&bytes);
    assert_eq!(
        (ktx2.width as u64, ktx2.height as u64),
        (page["width"].as_u64().unwrap(), page["height"].as_u64().unwrap())
    );
    let decoded = decode_blocks(BlockFormat::Bc7, &ktx2_level(&bytes, &ktx2, 0), ktx2.width, ktx2.height);
    for entry in entries {
        let name = entry["name"].as_str().unwrap();
        let source = decode_png(&project.read(&format!("assets/{name}")));
        let [x, y, width, height] = ["x", "y", "width", "height"].map(|key| entry[key].as_u64().unwrap() as u32);
        let [trim_x, trim_y] = [0, 1].map(|axis| entry["trim_offset"][axis].as_u64().unwrap() as u32);
        let rotated = entry["rotated"].as_bool().unwrap();
        let mut sum = PsnrSum::default();
        for row in 0..height {
            for column in 0..width {
                let (page_x, page_y) = if rotated { (x + height - 1 - row, y + column) } else { (x + column, y + row) };
                sum.add(source.texel(column + trim_x, row + trim_y), decoded.texel(page_x, page_y), 4);
            }
        }
        let psnr = sum.psnr();
        assert!(psnr > 30.0, "{name}: {psnr:.1} dB");
    }
}

#[test]
fn a_new_file_matching_the_glob_joins_the_atlas_and_a_deleted_one_leaves() {
    let project = atlas_project();
    let mut cirrus = project.open();
    assert!(build(&mut cirrus).all_ok());
    project.write("assets/extra/big.png", pattern_png(40, 40, 9));
    assert!(build(&mut cirrus).all_ok());
    let table: serde_json::Value = serde_json::from_slice(&project.read("baked/ui/atlas.json")).unwrap();
    assert!(table["entries"].as_array().unwrap().iter().any(|entry| entry["name"] == "extra/big.png"));
    std::fs::remove_file(project.path("assets/ui/icon0.png")).unwrap();
    assert!(build(&mut cirrus).all_ok());
    let table: serde_json::Value = serde_json::from_slice(&project.read("baked/ui/atlas.json")).unwrap();
    assert!(!table["entries"].as_array().unwrap().iter().any(|entry| entry["name"] == "ui/icon0.png"));
}

#[test]
fn a_texture_larger_than_a_page_and_an_unreadable_one_are_named() {
    let project = atlas_project();
    project.write("assets/extra/big.png", pattern_png(600, 8, 9));
    let summary = build(&mut project.open());
    let ui = &summary.assets[0];
    assert!(
        ui.errors
            .iter()
            .any(|error| error.message.contains("extra/big.png") && error.message.contains("larger than a page")),
        "{}",
        summary.to_text()
    );
    project.write("assets/extra/big.png", b"not a png");
    let summary = build(&mut project.open());
    assert!(summary.assets[0].errors.iter().any(|error| error.file == "assets/extra/big.png"), "{}", summary.to_text());
}

#[test]
fn a_same_size_edit_recomposites_its_page_and_leaves_the_table_alone() {
    let project = atlas_project();
    let mut cirrus = project.open();
    assert!(build(&mut cirrus).all_ok());
    cirrus.take_executed_stages();
    let table = project.read("baked/ui/atlas.json");
    let written = std::fs::metadata(project.path("baked/ui/atlas.json")).unwrap().modified().unwrap();
    project.write("assets/ui/icon1.png", pattern_png(20, 72, 77));
    assert!(build(&mut cirrus).all_ok());
    expect_test::expect![[r#"
        [
            "composite(ui/page0)",
            "decode(assets/ui/icon1.png)",
            "encode(ui/page0/albedo)",
            "layout(ui)",
            "mips(ui/page0/albedo)",
            "trim(assets/ui/icon1.png)",
            "write(ui/page0/albedo)",
        ]
    "#]]
    .assert_debug_eq(&cirrus.take_executed_stages());
    assert_eq!(project.read("baked/ui/atlas.json"), table, "nothing moved");
    assert_eq!(
        std::fs::metadata(project.path("baked/ui/atlas.json")).unwrap().modified().unwrap(),
        written,
        "not rewritten"
    );
}

/// Each entry's name → (page, x, y, rotated) in a built `atlas.json`.
fn places(project: &TempProject) -> std::collections::BTreeMap<String, (u64, u64, u64, bool)> {
    let table: serde_json::Value = serde_json::from_slice(&project.read("baked/ui/atlas.json")).unwrap();
    table["entries"]
        .as_array()
        .unwrap()
        .iter()
        .map(|entry| {
            let number = |key: &str| entry[key].as_u64().unwrap();
            (
                entry["name"].as_str().unwrap().to_string(),
                (number("page"), number("x"), number("y"), entry["rotated"].as_bool().unwrap()),
            )
        })
        .collect()
}

#[test]
fn a_new_texture_goes_into_free_space_and_moves_nothing_also_after_a_restart() {
    let project = atlas_project();
    assert!(build(&mut project.open()).all_ok());
    let before = places(&project);
    let report: serde_json::Value = serde_json::from_slice(&project.read("baked/ui/report.json")).unwrap();
    assert_eq!(report["layout"]["how"], "fresh");
    // A new process: the last layout comes from the persistent cache's memo.
    project.write("assets/extra/big.png", pattern_png(4, 4, 9));
    assert!(build(&mut project.open()).all_ok());
    let after = places(&project);
    let report: serde_json::Value = serde_json::from_slice(&project.read("baked/ui/report.json")).unwrap();
    assert_eq!(report["layout"], serde_json::json!({"how": "kept", "placed": ["extra/big.png"], "moved": []}));
    assert!(after.contains_key("extra/big.png"));
    for (name, place) in &before {
        assert_eq!(after.get(name), Some(place), "{name} moved");
    }
    // Settings that change the cells give a fresh layout (the old one is no hint).
    let pipeline = std::fs::read_to_string(project.path("pipeline.ron")).unwrap().replace("padding: 4", "padding: 8");
    project.write("pipeline.ron", pipeline.as_bytes());
    assert!(build(&mut project.open()).all_ok());
    let report: serde_json::Value = serde_json::from_slice(&project.read("baked/ui/report.json")).unwrap();
    assert_eq!(report["layout"]["how"], "fresh");
}

#[test]
fn a_repack_happens_when_keeping_the_layout_would_waste_the_page_and_the_report_says_which_moved() {
    let project = atlas_project();
    let mut cirrus = project.open();
    assert!(build(&mut cirrus).all_ok());
    // The largest entries leave: the kept page would be mostly empty.
    for name in ["icon0", "icon3", "icon1"] {
        std::fs::remove_file(project.path(&format!("assets/ui/{name}.png"))).unwrap();
    }
    assert!(build(&mut cirrus).all_ok());
    let report: serde_json::Value = serde_json::from_slice(&project.read("baked/ui/report.json")).unwrap();
    assert_eq!(report["layout"]["how"], "repacked", "{report}");
    assert!(!report["layout"]["moved"].as_array().unwrap().is_empty(), "{report}");
}

#[test]
fn a_texture_named_by_plain_path_that_is_missing_is_named() {
    let project = atlas_project();
    let pipeline =
        std::fs::read_to_string(project.path("pipeline.ron")).unwrap().replace("\"extra/*.png\"", "\"extra/gone.png\"");
    project.write("pipeline.ron", pipeline.as_bytes());
    let summary = build(&mut project.open());
    let errors: Vec<String> =
        summary.assets[0].errors.iter().map(|error| format!("{}: {}", error.file, error.message)).collect();
    assert!(errors.iter().any(|error| error.starts_with("assets/extra/gone.png:")), "{errors:?}");
    project.write("assets/extra/gone.png", pattern_png(8, 8, 5));
    assert!(build(&mut project.open()).all_ok());
}

#[test]
fn palette_with_trns_16_bit_and_grey_alpha_pngs_read_back_from_the_page() {
    let project = TempProject::new(
        r#"Pipeline(source: "assets", output: "baked", assets: [
            Atlas(name: "mixed", textures: ["mixed/*.png"], pack: (max_size: 2048, trim: false)),
        ])"#,
    );
    // A palette PNG with tRNS alpha (the bundled aspen leaves).
    let leaves = std::fs::read(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/assets/trees/textures/aspen_color.png"),
    )
    .unwrap();
    project.write("assets/mixed/palette.png", &leaves);
    let encode = |image: image::DynamicImage| {
        let mut bytes = std::io::Cursor::new(Vec::new());
        image.write_to(&mut bytes, image::ImageFormat::Png).unwrap();
        bytes.into_inner()
    };
    let sixteen = image::ImageBuffer::from_fn(40, 24, |x, y| {
        image::Rgba([(x * 1600) as u16, (y * 2700) as u16, 40000u16, 65535u16])
    });
    project.write("assets/mixed/sixteen.png", encode(image::DynamicImage::ImageRgba16(sixteen)));
    let grey_alpha = image::ImageBuffer::from_fn(24, 36, |x, y| {
        image::LumaA([(x * 10 + y) as u8, if (x + y) % 3 == 0 { 0 } else { 200 }])
    });
    project.write("assets/mixed/grey_alpha.png", encode(image::DynamicImage::ImageLumaA8(grey_alpha)));
    let summary = build(&mut project.open());
    assert!(summary.all_ok(), "{}", summary.to_text());
    let table: serde_json::Value = serde_json::from_slice(&project.read("baked/mixed/atlas.json")).unwrap();
    let page = decode_png(&project.read("baked/mixed/atlas.png"));
    for entry in table["entries"].as_array().unwrap() {
        let name = entry["name"].as_str().unwrap();
        // The source as the image crate reads it, in 8-bit RGBA (16-bit rounds to the nearest).
        let source = image::load_from_memory(&project.read(&format!("assets/{name}"))).unwrap().into_rgba8();
        let [x, y, width, height] = ["x", "y", "width", "height"].map(|key| entry[key].as_u64().unwrap() as u32);
        assert_eq!((width, height), source.dimensions(), "{name}");
        let rotated = entry["rotated"].as_bool().unwrap();
        for row in 0..height {
            for column in 0..width {
                let (page_x, page_y) = if rotated { (x + height - 1 - row, y + column) } else { (x + column, y + row) };
                assert_eq!(
                    page.texel(page_x, page_y),
                    source.get_pixel(column, row).0,
                    "{name} texel ({column}, {row})"
                );
            }
        }
    }
}

#[test]
fn two_projects_with_their_files_written_in_shuffled_orders_bake_identical_bytes() {
    let sizes = [(64, 32), (20, 72), (36, 36), (120, 16), (8, 8), (44, 12), (16, 100), (30, 30)];
    let bake = |order: &[usize]| -> Vec<(String, Vec<u8>)> {
        let project = TempProject::new(
            r#"Pipeline(source: "assets", output: "baked", assets: [
                Atlas(name: "ui", textures: ["ui/**/*.png"], pack: (max_size: 256, padding: 2)),
            ])"#,
        );
        for &index in order {
            let (width, height) = sizes[index];
            // Names whose listing order differs from creation order, in two folders.
            project.write(
                &format!("assets/ui/{}/t{}.png", index % 2, 7 - index),
                pattern_png(width, height, index as u32),
            );
        }
        assert!(build(&mut project.open()).all_ok());
        ["atlas.json", "atlas.ktx2", "atlas.png", "atlas_1.ktx2"]
            .iter()
            .filter(|file| project.path(&format!("baked/ui/{file}")).exists())
            .map(|file| (file.to_string(), project.read(&format!("baked/ui/{file}"))))
            .collect()
    };
    let first = bake(&[0, 1, 2, 3, 4, 5, 6, 7]);
    let second = bake(&[5, 2, 7, 0, 3, 6, 1, 4]);
    assert!(first.len() >= 3);
    for ((name, a), (_, b)) in first.iter().zip(&second) {
        assert!(a == b, "{name} differs");
    }
}

#[test]
fn a_settings_change_reruns_only_the_stages_that_read_it() {
    let project = atlas_project();
    let mut cirrus = project.open();
    assert!(build(&mut cirrus).all_ok());
    cirrus.take_executed_stages();
    let pipeline = std::fs::read_to_string(project.path("pipeline.ron")).unwrap();
    // The block format: the encode and write of the page, nothing before them.
    project.write("pipeline.ron", pipeline.replace("padding: 4)", "padding: 4), encode: (albedo: Bc3)").as_bytes());
    cirrus.reconfigure(cirrus::pipeline::load_pipeline(&project.path("pipeline.ron")).unwrap());
    assert!(build(&mut cirrus).all_ok());
    expect_test::expect![[r#"
        [
            "encode(ui/page0/albedo)",
            "write(ui/page0/albedo)",
        ]
    "#]]
    .assert_debug_eq(&cirrus.take_executed_stages());
    // Trim off: every texture's trim, the layout and the page, no decode (in memory already).
    project.write(
        "pipeline.ron",
        pipeline.replace("padding: 4)", "padding: 4, trim: false), encode: (albedo: Bc3)").as_bytes(),
    );
    cirrus.reconfigure(cirrus::pipeline::load_pipeline(&project.path("pipeline.ron")).unwrap());
    assert!(build(&mut cirrus).all_ok());
    let ran = cirrus.take_executed_stages();
    assert!(ran.iter().all(|stage| !stage.starts_with("decode")), "{ran:?}");
    assert_eq!(ran.iter().filter(|stage| stage.starts_with("trim(")).count(), 6, "{ran:?}");
    assert!(ran.contains(&"layout(ui)".to_string()) && ran.contains(&"composite(ui/page0)".to_string()), "{ran:?}");
}
