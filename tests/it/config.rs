//! `pipeline.ron`: defaults and per-asset overrides, rules, and (data-driven) the messages of
//! every malformed pipeline in `tests/fixtures/pipeline_errors`.

use std::path::Path;

use cirrus::config::{AssetSource, BlockFormat, Container};
use cirrus::pipeline::parse_pipeline;

#[test]
fn defaults_apply_and_assets_override_them() {
    let text = r#"Pipeline(
        source: "assets", output: "out",
        defaults: (encode: (mra: Bc7, zstd: Some(5))),
        assets: [
            Material(name: "bark", material: "materials/bark.mymaterial", encode: (container: Dds, zstd: None)),
            BillboardCloud(name: "oak", mesh: "trees/oak.obj", billboard: (epsilon: 0.03, max_planes: 12)),
        ],
        rules: [(glob: "materials/**/*.mymaterial", kind: Material)],
    )"#;
    let config = parse_pipeline(Path::new("project/pipeline.ron"), text).expect("valid");
    assert_eq!(config.root, Path::new("project"));
    assert_eq!(config.source_dir(), Path::new("project/assets"));
    let bark = &config.assets[0];
    assert_eq!(bark.source, AssetSource::of_file(cirrus::kinds::material::KIND, "materials/bark.mymaterial"));
    assert_eq!(bark.settings.encode.mra, BlockFormat::Bc7, "from defaults");
    assert_eq!(bark.settings.encode.container, Container::Dds, "asset override");
    assert_eq!(bark.settings.encode.zstd, None, "an explicit None overrides a default");
    assert_eq!(bark.settings.encode.albedo, BlockFormat::Bc7, "built-in default");
    let oak = &config.assets[1];
    let billboard = &oak.settings.own::<cirrus::kinds::billboard_cloud::settings::Settings>().billboard;
    assert_eq!(billboard.epsilon, 0.03);
    assert_eq!(billboard.max_planes, Some(12));
    assert_eq!(oak.settings.encode.zstd, Some(5));
    let rule_asset = config.asset_for_rule_match(Path::new("materials/metal/steel.mymaterial")).expect("rule matches");
    assert_eq!(rule_asset.name, "materials/metal/steel");
    assert!(config.asset_for_rule_match(Path::new("materials/bark.mymaterial")).is_none(), "explicit asset wins");
    assert!(config.asset_for_rule_match(Path::new("textures/bark.png")).is_none());
}

/// Every `tests/fixtures/pipeline_errors/*.ron` fails with the messages in its `.expected` file.
#[test]
fn malformed_pipelines_report_file_line_and_column() {
    let folder = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/pipeline_errors");
    let mut files: Vec<_> =
        std::fs::read_dir(&folder).expect("fixture folder").flatten().map(|entry| entry.path()).collect();
    files.retain(|path| path.extension().is_some_and(|extension| extension == "ron"));
    files.sort();
    assert!(files.len() >= 6, "fixtures present");
    for path in files {
        let text = std::fs::read_to_string(&path).expect("fixture");
        let error = parse_pipeline(Path::new("pipeline.ron"), &text).expect_err("the fixture is malformed");
        expect_test::expect_file![path.with_extension("expected")].assert_eq(&format!("{error}\n"));
    }
}

/// The alpha test is a setting two kinds read: `defaults:`'s `billboard.alpha_cutoff` reaches
/// materials and billboard clouds, each entry may override it, and an asset a rule makes gets
/// its kind's defaults.
#[test]
fn the_shared_alpha_test_reaches_both_kinds_that_read_it() {
    use cirrus::kinds::{billboard_cloud, material};
    let text = r#"Pipeline(
        source: "assets", output: "out",
        defaults: (billboard: (alpha_cutoff: 0.25, epsilon: 0.05), report: (compare_formats: true)),
        assets: [
            Material(name: "bark", material: "bark.mymaterial"),
            Material(name: "leaf", material: "leaf.mymaterial", billboard: (alpha_cutoff: 0.75)),
            BillboardCloud(name: "oak", mesh: "oak.obj"),
        ],
        rules: [(glob: "**/*.mymaterial", kind: Material), (glob: "**/*.obj", kind: BillboardCloud)],
    )"#;
    let config = parse_pipeline(Path::new("pipeline.ron"), text).expect("valid");
    let cutoff = |index: usize| config.assets[index].settings.own::<material::settings::Settings>().alpha_cutoff;
    assert_eq!((cutoff(0), cutoff(1)), (0.25, 0.75));
    let oak = config.assets[2].settings.own::<billboard_cloud::settings::Settings>();
    assert_eq!((oak.billboard.alpha_cutoff, oak.billboard.epsilon), (0.25, 0.05));
    let rock = config.asset_for_rule_match(Path::new("rock.mymaterial")).expect("a rule makes it");
    let rock = rock.settings.own::<material::settings::Settings>();
    assert_eq!((rock.alpha_cutoff, rock.report.compare_formats), (0.25, true));
    let pine = config.asset_for_rule_match(Path::new("pine.obj")).expect("a rule makes it");
    assert_eq!(pine.settings.own::<billboard_cloud::settings::Settings>().billboard.epsilon, 0.05);
}
