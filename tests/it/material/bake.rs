//! Baking materials: every written texture decoded with `bcdec_rs` and compared with the
//! uncompressed packed surface (its PNG preview), mip chains, formats and container headers.

use cirrus::config::BlockFormat;
use cirrus::summary::AssetStatus;
use cirrus::texture::mips::texture_alpha_coverage;
use cirrus::texture::quality::{decode_blocks, psnr};

use crate::support::{build, cutout_png, decode_png, ktx2_level, pattern_png, read_ktx2, TempProject};

/// A project over the bundled oak bark (CC0), an alpha-tested cutout and a constants-only
/// material, with `extra_encode` added to the defaults.
pub fn material_project(extra_encode: &str) -> TempProject {
    let project = TempProject::new(&format!(
        r#"Pipeline(source: "assets", output: "baked", defaults: (encode: ({extra_encode})), assets: [
            Material(name: "bark", material: "materials/bark.mymaterial"),
            Material(name: "mixed", material: "materials/mixed.mymaterial"),
        ])"#
    ));
    let bark = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/assets/textures/bark_oak");
    for map in ["albedo", "normal", "roughness", "ao"] {
        project.write(
            &format!("assets/textures/oak/{map}.jpg"),
            std::fs::read(bark.join(format!("{map}.jpg"))).expect("bundled bark"),
        );
    }
    project.write(
        "assets/materials/bark.mymaterial",
        r#"Material $oak_bark {
            Texture (attrib = "diffuse") {string {"../textures/oak/albedo.jpg"}}
            Texture (attrib = "normal") {string {"../textures/oak/normal.jpg"}}
            Texture (attrib = "roughness") {string {"../textures/oak/roughness.jpg"}}
            Texture (attrib = "ao") {string {"../textures/oak/ao.jpg"}}
            Param (attrib = "metallic") {float {0}}
        }"#,
    );
    project.write("assets/textures/leaf.png", cutout_png(256, 128));
    project.write("assets/textures/metal.png", pattern_png(64, 64, 3));
    project.write("assets/textures/rough.png", pattern_png(128, 128, 4));
    project.write(
        "assets/materials/mixed.mymaterial",
        r#"Material $leaf {
            Texture (attrib = "diffuse") {string {"../textures/leaf.png"}}
            Param (attrib = "alpha_cutoff") {float {0.5}}
        }
        Material $plain {
            Color (attrib = "diffuse") {float[3] {{0.5, 0.25, 0.125}}}
            Texture (attrib = "metallic") {string {"../textures/metal.png"}}
            Texture (attrib = "roughness") {string {"../textures/rough.png"}}
        }"#,
    );
    project
}

#[test]
fn ktx2_surfaces_decode_within_the_psnr_bars_with_full_mip_chains() {
    let project = material_project("");
    let summary = build(&mut project.open());
    assert!(summary.all_ok(), "{}", summary.to_text());
    let cases = [
        ("bark/oak_bark", "albedo", 146, BlockFormat::Bc7, 42.0, 1024),
        ("bark/oak_bark", "mra", 131, BlockFormat::Bc1, 36.0, 1024),
        ("bark/oak_bark", "normal", 141, BlockFormat::Bc5, 42.0, 1024),
        ("mixed/leaf", "albedo", 146, BlockFormat::Bc7, 42.0, 256),
        ("mixed/plain", "mra", 131, BlockFormat::Bc1, 36.0, 128),
        ("mixed/plain", "albedo", 146, BlockFormat::Bc7, 42.0, 4),
    ];
    for (material, surface, vk_format, format, bar, width) in cases {
        let bytes = project.read(&format!("baked/{material}/{surface}.ktx2"));
        let ktx2 = read_ktx2(&bytes);
        assert_eq!(ktx2.vk_format, vk_format, "{material}/{surface} vkFormat");
        assert_eq!(ktx2.width, width, "{material}/{surface} width");
        let expected_levels = 32 - ktx2.width.max(ktx2.height).leading_zeros();
        assert_eq!(ktx2.levels.len() as u32, expected_levels, "{material}/{surface}: mips down to 1×1");
        let reference = decode_png(&project.read(&format!("baked/{material}/{surface}.png")));
        let decoded = decode_blocks(format, &ktx2_level(&bytes, &ktx2, 0), ktx2.width, ktx2.height);
        let channels = match surface {
            "albedo" => 4,
            "mra" => 3,
            _ => 2,
        };
        let measured = psnr(&reference, &decoded, channels);
        assert!(measured >= bar, "{material}/{surface}: {measured:.2} dB < {bar} dB");
        for level in 1..ktx2.levels.len() {
            let size = |side: u32| (side >> level).max(1).div_ceil(4) as u64;
            let block = if matches!(format, BlockFormat::Bc1 | BlockFormat::Bc4) { 8 } else { 16 };
            assert_eq!(ktx2.levels[level].2, size(ktx2.width) * size(ktx2.height) * block, "level {level} size");
        }
    }
}

#[test]
fn alpha_tested_albedo_keeps_its_coverage_down_the_mip_chain() {
    let project = material_project("");
    build(&mut project.open());
    let bytes = project.read("baked/mixed/leaf/albedo.ktx2");
    let ktx2 = read_ktx2(&bytes);
    let coverage = |level: usize| {
        let (width, height) = ((ktx2.width >> level).max(1), (ktx2.height >> level).max(1));
        texture_alpha_coverage(&decode_blocks(BlockFormat::Bc7, &ktx2_level(&bytes, &ktx2, level), width, height), 0.5)
    };
    let level0 = coverage(0);
    assert!(level0 > 0.2 && level0 < 0.7, "the fixture is partly transparent: {level0}");
    // Down to 32×16 texels; below that a periodic fixture leaves too few distinct alphas to split.
    for level in 1..=3 {
        let difference = (coverage(level) - level0).abs();
        assert!(difference < 0.05, "level {level}: coverage {} vs {level0}", coverage(level));
    }
    let report: serde_json::Value = serde_json::from_slice(&project.read("baked/mixed/report.json")).expect("report");
    assert_eq!(report["materials"][0]["surfaces"][0]["alpha_tested"], true);
}

#[test]
fn an_alpha_tested_albedo_reports_the_colour_where_the_test_passes_and_the_tests_agreement() {
    // What an engine shows of a cut-out: the colour where the alpha test passes, and whether it
    // passes where the uncompressed surface does. The report's figures must be those of the
    // written level 0, decoded and compared by hand here.
    let project = material_project("");
    build(&mut project.open());
    let report: serde_json::Value = serde_json::from_slice(&project.read("baked/mixed/report.json")).expect("report");
    let surfaces = report["materials"][0]["surfaces"].as_array().expect("surfaces");
    let albedo = surfaces.iter().find(|surface| surface["surface"] == "Albedo").expect("albedo");
    let bytes = project.read("baked/mixed/leaf/albedo.ktx2");
    let ktx2 = read_ktx2(&bytes);
    let decoded = decode_blocks(BlockFormat::Bc7, &ktx2_level(&bytes, &ktx2, 0), ktx2.width, ktx2.height);
    let source = decode_png(&project.read("baked/mixed/leaf/albedo.png"));
    let (mut squared, mut visible, mut either, mut both) = (0u64, 0u64, 0u64, 0u64);
    for (source, decoded) in source.pixels.chunks_exact(4).zip(decoded.pixels.chunks_exact(4)) {
        let (passes, decoded_passes) = (source[3] >= 128, decoded[3] >= 128);
        if passes {
            visible += 1;
            squared +=
                (0..3).map(|channel| (source[channel] as i64 - decoded[channel] as i64).pow(2) as u64).sum::<u64>();
        }
        either += u64::from(passes || decoded_passes);
        both += u64::from(passes && decoded_passes);
    }
    let visible_psnr = 10.0 * (255.0f64 * 255.0 / (squared as f64 / (visible * 3) as f64)).log10();
    let reported = albedo["visible_psnr_db"].as_f64().expect("an alpha-tested albedo reports its visible PSNR");
    assert!(
        (reported - visible_psnr).abs() <= 0.006,
        "visible PSNR {reported} against {visible_psnr:.3} measured here"
    );
    let iou = both as f64 / either as f64;
    let reported = albedo["alpha_test_iou"].as_f64().expect("and its alpha test's IoU");
    assert!((reported - iou).abs() <= 1e-5, "alpha-test IoU {reported} against {iou:.5}");
    assert!(iou > 0.9 && iou <= 1.0, "{iou}");
    // Surfaces without an alpha test have neither figure.
    let mra = surfaces.iter().find(|surface| surface["surface"] == "Mra").expect("mra");
    assert!(mra.get("visible_psnr_db").is_none() && mra.get("alpha_test_iou").is_none(), "{mra}");
}

#[test]
fn dds_and_pvr_containers_have_correct_headers() {
    for (container, check) in [("Dds", check_dds as fn(&[u8], u32, u32)), ("Pvr", check_pvr)] {
        let project = material_project(&format!("container: {container}"));
        let summary = build(&mut project.open());
        assert!(summary.all_ok(), "{}", summary.to_text());
        let extension = container.to_lowercase();
        check(&project.read(&format!("baked/bark/oak_bark/albedo.{extension}")), 1024, 11);
        check(&project.read(&format!("baked/mixed/plain/mra.{extension}")), 128, 8);
    }
}

fn check_dds(bytes: &[u8], width: u32, levels: u32) {
    let u32_at = |offset: usize| u32::from_le_bytes(bytes[offset..offset + 4].try_into().unwrap());
    assert_eq!(&bytes[..4], b"DDS ");
    assert_eq!(u32_at(4), 124, "header size");
    assert_eq!((u32_at(12), u32_at(16)), (width, width), "height, width");
    assert_eq!(u32_at(28), levels, "mip count");
    assert_eq!(&bytes[84..88], b"DX10");
    assert!([99, 71].contains(&u32_at(128)), "DXGI BC7 sRGB or BC1 unorm, got {}", u32_at(128));
    assert_eq!(u32_at(132), 3, "TEXTURE2D");
    let block = if u32_at(128) == 71 { 8 } else { 16 };
    let payload: u32 = (0..levels).map(|level| (width >> level).max(1).div_ceil(4).pow(2) * block).sum();
    assert_eq!(bytes.len() as u32, 148 + payload, "header plus every level");
}

fn check_pvr(bytes: &[u8], width: u32, levels: u32) {
    let u32_at = |offset: usize| u32::from_le_bytes(bytes[offset..offset + 4].try_into().unwrap());
    assert_eq!(u32_at(0), 0x03525650, "PVR v3 magic");
    let format = u32::from_le_bytes(bytes[8..12].try_into().unwrap());
    assert!([15, 7].contains(&format), "BC7 or BC1");
    assert_eq!(u32_at(16), if format == 15 { 1 } else { 0 }, "colour space: sRGB albedo, linear mra");
    assert_eq!((u32_at(24), u32_at(28)), (width, width));
    assert_eq!(u32_at(44), levels, "mip count");
    assert_eq!(u32_at(48), 0, "no metadata");
}

#[test]
fn zstd_supercompressed_ktx2_round_trips() {
    let project = material_project("zstd: Some(9)");
    build(&mut project.open());
    let bytes = project.read("baked/bark/oak_bark/normal.ktx2");
    let ktx2 = read_ktx2(&bytes);
    assert_eq!(ktx2.supercompression, 2, "zstd");
    assert!(ktx2.levels[0].1 < ktx2.levels[0].2, "level 0 is smaller supercompressed");
    let reference = decode_png(&project.read("baked/bark/oak_bark/normal.png"));
    let decoded = decode_blocks(BlockFormat::Bc5, &ktx2_level(&bytes, &ktx2, 0), 1024, 1024);
    assert!(psnr(&reference, &decoded, 2) >= 42.0);
    // The basic data format descriptor: BC5 colour model, linear transfer, 16-byte blocks.
    assert_eq!(ktx2.dfd[12], 132, "KHR_DF_MODEL_BC5");
    assert_eq!(ktx2.dfd[14], 1, "KHR_DF_TRANSFER_LINEAR");
    assert_eq!(ktx2.dfd[20], 16, "bytesPlane0");
}

#[test]
fn constants_fill_missing_maps_and_small_maps_are_resampled() {
    let project = material_project("");
    build(&mut project.open());
    let albedo = decode_png(&project.read("baked/mixed/plain/albedo.png"));
    assert_eq!((albedo.width, albedo.height), (4, 4), "no albedo map: one block of the constant");
    // Colour constants are linear; the sRGB surface stores them encoded.
    assert_eq!(albedo.texel(0, 0), [188, 137, 99, 255]);
    let mra = decode_png(&project.read("baked/mixed/plain/mra.png"));
    assert_eq!((mra.width, mra.height), (128, 128), "the largest source of the group");
    assert_eq!(mra.texel(5, 5)[2], 255, "AO defaults to 1");
    let metal = decode_png(&pattern_png(64, 64, 3));
    let (resampled, source) = (mra.texel(64, 64)[0] as i32, metal.texel(32, 32)[0] as i32);
    assert!((resampled - source).abs() <= 6, "metallic upsampled 2×: {resampled} vs {source}");
    let normal = decode_png(&project.read("baked/mixed/plain/normal.png"));
    assert_eq!(&normal.texel(0, 0)[..3], &[128, 128, 255], "flat normal");
}

#[test]
fn report_json_lists_every_surface_with_its_measured_psnr() {
    let project = material_project("");
    let summary = build(&mut project.open());
    assert_eq!(summary.assets[0].status, AssetStatus::Ok);
    let report: serde_json::Value = serde_json::from_slice(&project.read("baked/bark/report.json")).expect("report");
    let surfaces = report["materials"][0]["surfaces"].as_array().expect("surfaces");
    let names: Vec<&str> = surfaces.iter().map(|surface| surface["surface"].as_str().unwrap()).collect();
    assert_eq!(names, ["Albedo", "Mra", "Normal"]);
    for surface in surfaces {
        assert!(surface["psnr_db"].as_f64().unwrap() > 36.0);
        assert_eq!(surface["levels"], 11);
    }
    let manifest: serde_json::Value = serde_json::from_slice(&project.read("baked/manifest.json")).expect("manifest");
    let entry = &manifest["artifacts"]["baked/bark/oak_bark/albedo.ktx2"];
    assert_eq!(
        entry["hash"].as_str().unwrap(),
        blake3::hash(&project.read("baked/bark/oak_bark/albedo.ktx2")).to_hex().as_str()
    );
    assert_eq!(entry["revision"], 1);
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let mode = std::fs::metadata(project.path("baked/bark/oak_bark/albedo.ktx2")).unwrap().permissions().mode();
        assert_eq!(mode & 0o644, 0o644, "artifacts are readable by other users: {mode:o}");
    }
}

#[test]
fn re_encoding_only_changed_blocks_equals_a_full_encode() {
    use cirrus::config::EncodeQuality;
    use cirrus::texture::encode::{encode_levels, encode_levels_reusing, BlockEncodeSettings, PreviousBlocks};
    use cirrus::texture::fingerprint::BlockFingerprints;
    use cirrus::texture::mips::{mip_chain, MipSettings};
    use cirrus::texture::SurfaceKind;
    let before = decode_png(&pattern_png(96, 64, 1));
    let mut pixels = before.pixels.to_vec();
    for y in 20..27 {
        for x in 30..41 {
            pixels[(y * 96 + x) * 4..][..3].copy_from_slice(&[255, 0, 0]);
        }
    }
    let after = cirrus::texture::Texture::new(96, 64, pixels);
    for format in [BlockFormat::Bc1, BlockFormat::Bc3, BlockFormat::Bc4, BlockFormat::Bc5, BlockFormat::Bc7] {
        let settings = BlockEncodeSettings { format, quality: EncodeQuality::Basic, alpha: false, srgb: false };
        let chain = |texture| mip_chain(texture, MipSettings { kind: SurfaceKind::Mra, alpha_cutoff: None });
        let (old_levels, new_levels) = (chain(&before), chain(&after));
        let old = encode_levels(&old_levels, settings);
        let (old_blocks, new_blocks) = (BlockFingerprints::of(&old_levels[0]), BlockFingerprints::of(&new_levels[0]));
        let previous = PreviousBlocks { level0_blocks: &old_blocks, lower_levels: &old_levels[1..], encoded: &old };
        let reused = encode_levels_reusing(&new_levels, &new_blocks, (settings, None), Some(previous));
        assert_eq!(reused, encode_levels(&new_levels, settings), "{format:?}: reuse is exact");
        assert_ne!(reused, old, "{format:?}: the edit shows");
        // The PSNR from per-block errors, measured again only where blocks or texels changed.
        use cirrus::texture::quality::{block_errors_reusing, decode_blocks, psnr, Measure};
        let channels = 3;
        let measure = Measure { channels, alpha_threshold: Some(128) };
        let old_errors = block_errors_reusing(format, &old.levels[0], &old_levels[0], &old_blocks, measure, None);
        let fresh = block_errors_reusing(format, &reused.levels[0], &new_levels[0], &new_blocks, measure, None);
        let measure_again = |previous_errors| {
            block_errors_reusing(
                format,
                &reused.levels[0],
                &new_levels[0],
                &new_blocks,
                measure,
                Some((&old_blocks, &old.levels[0][..], previous_errors)),
            )
        };
        let reused_errors = measure_again(&old_errors);
        assert_eq!(reused_errors, fresh, "{format:?}");
        let decoded = decode_blocks(format, &reused.levels[0], 96, 64);
        if matches!(format, BlockFormat::Bc4 | BlockFormat::Bc5) {
            // Measured with the float palette, as a GPU decodes; `bcdec` rounds the entries.
            let (float, rounded) = (fresh.psnr(96, 64), psnr(&new_levels[0], &decoded, channels));
            assert!((float - rounded).abs() < 0.5, "{format:?}: {float} against bcdec's {rounded}");
        } else {
            assert_eq!(fresh.psnr(96, 64), psnr(&new_levels[0], &decoded, channels), "{format:?}");
        }
        // Errors planted in the previous measurement stay where nothing changed.
        let mut planted = old_errors.clone();
        planted.errors[0] += 1;
        let from_planted = measure_again(&planted);
        assert_eq!(from_planted.errors[0], fresh.errors[0] + 1, "{format:?}: block 0 is reused");
    }
}

#[test]
fn block_fingerprints_see_a_one_texel_change_in_its_block_alone_edge_blocks_included() {
    use cirrus::texture::fingerprint::BlockFingerprints;
    use cirrus::texture::Texture;
    // 10 × 7: the last block column is two texels wide, the last block row three high.
    let before = Texture::new(10, 7, (0..10 * 7 * 4).map(|byte| (byte * 37 % 251) as u8).collect());
    let old = BlockFingerprints::of(&before);
    assert_eq!((old.texels.len(), old.alphas.len()), (3 * 2, 3 * 2));
    for (x, y) in (0..7).flat_map(|y| (0..10).map(move |x| (x, y))) {
        for channel in [0, 3] {
            let mut pixels = before.pixels.to_vec();
            pixels[(y * 10 + x) * 4 + channel] ^= 1;
            let new = BlockFingerprints::of(&Texture::new(10, 7, pixels));
            let block = y / 4 * 3 + x / 4;
            let changed: Vec<usize> = (0..6).filter(|&number| new.block_changed(&old, number)).collect();
            assert_eq!(changed, [block], "texel ({x}, {y}), channel {channel}");
            let alpha_changed: Vec<usize> = (0..6).filter(|&number| new.alpha_changed(&old, number)).collect();
            assert_eq!(
                alpha_changed,
                if channel == 3 { vec![block] } else { vec![] },
                "texel ({x}, {y}), channel {channel}"
            );
        }
    }
}

#[test]
fn refiltering_only_changed_mip_tiles_equals_a_full_chain() {
    use cirrus::texture::fingerprint::BlockFingerprints;
    use cirrus::texture::mips::{mip_chain, mip_chain_reusing, MipSettings, PreviousChain};
    use cirrus::texture::SurfaceKind;
    use cirrus::texture::Texture;
    // The reusing chain of `texture` after `previous` (its levels and what it kept).
    let chain_after =
        |texture: &Texture, settings, previous: Option<(&[Texture], &cirrus::texture::mips::MipReuse)>| {
            let blocks = previous.map(|(levels, _)| BlockFingerprints::of(&levels[0]));
            let previous = previous.map(|(levels, reuse)| PreviousChain {
                level0_blocks: blocks.as_ref().unwrap(),
                lower_levels: &levels[1..],
                reuse,
            });
            mip_chain_reusing(texture, &BlockFingerprints::of(texture), settings, previous)
        };
    // 192 × 128: six 64² tiles. Cut-out albedo (coverage preserved), a normal map, plain data.
    let cutout = decode_png(&cutout_png(192, 128));
    let pattern = decode_png(&pattern_png(192, 128, 3));
    let edit = |texture: &Texture, region: std::ops::Range<usize>, change: &dyn Fn(&mut [u8])| {
        let mut pixels = texture.pixels.to_vec();
        for y in region.clone() {
            for x in 70..90 {
                change(&mut pixels[(y * 192 + x) * 4..][..4]);
            }
        }
        Texture::new(192, 128, pixels)
    };
    let cases = [
        (cutout.clone(), MipSettings { kind: SurfaceKind::Albedo, alpha_cutoff: Some(0.5) }),
        (pattern.clone(), MipSettings { kind: SurfaceKind::Normal, alpha_cutoff: None }),
        (pattern, MipSettings { kind: SurfaceKind::Mra, alpha_cutoff: None }),
    ];
    for (before, settings) in cases {
        let (old_levels, reuse) = chain_after(&before, settings, None);
        assert_eq!(old_levels, mip_chain(&before, settings));
        let reuse = reuse.expect("multiples of the tile size keep what the next chain reuses");
        // A colour edit in the tiles (1, 0) and (1, 1); then a second one on top of it.
        let recolour = |texel: &mut [u8]| texel[..3].copy_from_slice(&[200, 30, 90]);
        let after = edit(&before, 50..80, &recolour);
        let (levels, next) = chain_after(&after, settings, Some((&old_levels, &reuse)));
        assert_eq!(levels, mip_chain(&after, settings), "{settings:?}: the same levels as a full chain");
        assert_ne!(levels[3], old_levels[3], "{settings:?}: the edit shows");
        let again = edit(&after, 0..20, &|texel: &mut [u8]| texel[0] = 10);
        let (levels_again, _) = chain_after(&again, settings, Some((&levels, next.as_ref().unwrap())));
        assert_eq!(levels_again, mip_chain(&again, settings), "{settings:?}: reuse of a reused chain");
        // Unchanged tiles really come from the previous chain: a texel planted in its level 1
        // outside the edited tiles survives.
        let mut planted = old_levels.clone();
        let mut pixels = planted[1].pixels.to_vec();
        pixels[(5 * 96 + 5) * 4] ^= 0xff;
        planted[1] = Texture::new(96, 64, pixels);
        let (from_planted, _) = chain_after(&after, settings, Some((&planted, &reuse)));
        assert_eq!(from_planted[1].texel(5, 5), planted[1].texel(5, 5), "{settings:?}");
    }
    // An alpha edit moves whole levels' coverage scale: a full chain, still equal.
    let albedo = MipSettings { kind: SurfaceKind::Albedo, alpha_cutoff: Some(0.5) };
    let (old_levels, reuse) = chain_after(&cutout, albedo, None);
    let holes = edit(&cutout, 40..60, &|texel: &mut [u8]| texel[3] = 0);
    let (levels, _) = chain_after(&holes, albedo, Some((&old_levels, reuse.as_ref().unwrap())));
    assert_eq!(levels, mip_chain(&holes, albedo));
    // Without coverage preservation, alpha edits reuse too: more holes where some already
    // were, and a translucent albedo made partly opaque; each equal to a full chain.
    let translucent = MipSettings { kind: SurfaceKind::Albedo, alpha_cutoff: None };
    for (before, alpha) in [(&cutout, 0u8), (&edit(&cutout, 0..128, &|texel: &mut [u8]| texel[3] = 128), 255)] {
        let (old_levels, reuse) = chain_after(before, translucent, None);
        let after = edit(before, 40..60, &|texel: &mut [u8]| texel[3] = alpha);
        let (levels, _) = chain_after(&after, translucent, Some((&old_levels, reuse.as_ref().unwrap())));
        assert_eq!(levels, mip_chain(&after, translucent), "alpha {alpha}");
        assert_ne!(levels[2], old_levels[2], "alpha {alpha}: the edit shows");
        let mut planted = old_levels.clone();
        let mut pixels = planted[1].pixels.to_vec();
        pixels[(5 * 96 + 5) * 4] ^= 0xff;
        planted[1] = Texture::new(96, 64, pixels);
        let (from_planted, _) = chain_after(&after, translucent, Some((&planted, reuse.as_ref().unwrap())));
        assert_eq!(from_planted[1].texel(5, 5), planted[1].texel(5, 5), "alpha {alpha}: reused, not a full chain");
    }
    // Sizes that are not multiples of the tile keep nothing to reuse.
    assert!(chain_after(&Texture::constant(96, 64, [1, 2, 3, 255]), albedo, None).1.is_none());
}

#[test]
fn a_level_encodes_each_block_as_that_block_alone_repeated_blocks_included() {
    use cirrus::config::EncodeQuality;
    use cirrus::texture::encode::{block_bytes, encode_level, BlockEncodeSettings};
    use cirrus::texture::Texture;
    // 42 × 26: 11 × 7 blocks, the last column and row padded. Tiles repeat every 3 blocks, so
    // most blocks are duplicates (the encoder encodes each distinct block once).
    let (width, height) = (42usize, 26usize);
    let mut pixels = Vec::with_capacity(width * height * 4);
    for y in 0..height {
        for x in 0..width {
            let (u, v) = (x % 12, y % 4);
            let t = u * 8 + v * 16;
            pixels.extend_from_slice(&[t as u8, (t / 2 + 20) as u8, (200 - t) as u8, if u < 6 { 255 } else { 0 }]);
        }
    }
    pixels[(13 * width + 17) * 4] ^= 0xff; // one block unlike its repeats
    let texture = Texture::new(width as u32, height as u32, pixels);
    for format in [BlockFormat::Bc1, BlockFormat::Bc3, BlockFormat::Bc4, BlockFormat::Bc5, BlockFormat::Bc7] {
        let settings = BlockEncodeSettings { format, quality: EncodeQuality::Basic, alpha: true, srgb: false };
        let mut expected = Vec::new();
        for by in 0..height.div_ceil(4) {
            for bx in 0..width.div_ceil(4) {
                let mut block = Vec::new();
                for row in 0..4 {
                    for column in 0..4 {
                        let (x, y) = ((bx * 4 + column).min(width - 1), (by * 4 + row).min(height - 1));
                        block.extend_from_slice(&texture.pixels[(y * width + x) * 4..][..4]);
                    }
                }
                expected.extend(encode_level(&Texture::new(4, 4, block), settings));
            }
        }
        let encoded = encode_level(&texture, settings);
        assert_eq!(encoded.len(), 11 * 7 * block_bytes(format), "{format:?}");
        assert!(encoded == expected, "{format:?}: every block as encoded alone");
        let channels = match format {
            BlockFormat::Bc4 => 1,
            BlockFormat::Bc5 => 2,
            BlockFormat::Bc1 => 3,
            _ => 4,
        };
        let decoded = cirrus::texture::quality::decode_blocks(format, &encoded, width as u32, height as u32);
        let psnr = cirrus::texture::quality::psnr(&texture, &decoded, channels);
        assert!(psnr > 30.0, "{format:?}: blocks decode to the level: {psnr:.1} dB");
    }
}

#[test]
fn alpha_that_passes_the_cutoff_everywhere_is_not_rescaled_down_the_mip_chain() {
    use cirrus::texture::mips::{mip_chain, MipSettings};
    use cirrus::texture::SurfaceKind;
    // Coverage is 1 on every level already; scaling alpha toward the cutoff would only make it
    // fragile under filtering.
    for alpha in [255, 200] {
        let levels = mip_chain(
            &cirrus::texture::Texture::constant(16, 16, [90, 60, 40, alpha]),
            MipSettings { kind: SurfaceKind::Albedo, alpha_cutoff: Some(0.5) },
        );
        assert!(
            levels.iter().all(|level| level.texel(0, 0)[3] == alpha),
            "{alpha}: {:?}",
            levels.iter().map(|l| l.texel(0, 0)).collect::<Vec<_>>()
        );
    }
}

#[test]
fn transparent_albedo_texels_keep_their_colour_down_the_mip_chain() {
    use cirrus::texture::mips::{mip_chain, MipSettings};
    use cirrus::texture::SurfaceKind;
    use cirrus::texture::Texture;
    // Left half opaque red, right half transparent but filled green (as the atlas fill does).
    let mut pixels = Vec::new();
    for _y in 0..8 {
        for x in 0..8 {
            pixels.extend_from_slice(if x < 4 { &[200, 30, 30, 255] } else { &[40, 180, 40, 0] });
        }
    }
    let levels =
        mip_chain(&Texture::new(8, 8, pixels), MipSettings { kind: SurfaceKind::Albedo, alpha_cutoff: Some(0.5) });
    let level1 = &levels[1];
    let texel = |x: usize, y: usize| -> [u8; 4] { level1.pixels[(y * 4 + x) * 4..][..4].try_into().unwrap() };
    assert_eq!(texel(0, 1)[..3], [200, 30, 30], "opaque texels keep their colour");
    assert_eq!(texel(3, 1), [40, 180, 40, 0], "fully transparent texels keep the fill colour, not black");
}

#[test]
fn linear_to_srgb_bytes_round_like_the_formula() {
    use cirrus::texture::color::{linear_to_srgb_u8, srgb_u8_to_linear};
    let formula = |linear: f64| {
        let linear = linear.clamp(0.0, 1.0);
        let srgb = if linear <= 0.003_130_8 { linear * 12.92 } else { 1.055 * linear.powf(1.0 / 2.4) - 0.055 };
        (srgb * 255.0 + 0.5).floor() as u8
    };
    let mut mismatches = Vec::new();
    for step in 0..=2_000_000u32 {
        let linear = step as f32 / 2_000_000.0;
        if linear_to_srgb_u8(linear) != formula(linear as f64) {
            mismatches.push(linear);
        }
    }
    assert!(
        mismatches.is_empty(),
        "{} values differ, first {:?}",
        mismatches.len(),
        &mismatches[..mismatches.len().min(5)]
    );
    assert_eq!((linear_to_srgb_u8(-1.0), linear_to_srgb_u8(2.0), linear_to_srgb_u8(f32::NAN)), (0, 255, 0));
    for byte in 0..=255u8 {
        assert_eq!(linear_to_srgb_u8(srgb_u8_to_linear(byte)), byte, "round trip of {byte}");
    }
}

#[test]
fn the_report_gives_each_formats_cost_and_with_compare_formats_what_the_others_would_give() {
    let project = material_project("");
    let pipeline = String::from_utf8(project.read("pipeline.ron")).unwrap();
    std::fs::write(
        project.path("pipeline.ron"),
        pipeline.replace(
            r#"material: "materials/bark.mymaterial")"#,
            r#"material: "materials/bark.mymaterial", report: (compare_formats: true))"#,
        ),
    )
    .unwrap();
    let summary = build(&mut project.open());
    assert!(summary.all_ok(), "{}", summary.to_text());
    let report: serde_json::Value = serde_json::from_slice(&project.read("baked/bark/report.json")).expect("report");
    let surfaces = report["materials"][0]["surfaces"].as_array().expect("surfaces");
    let figures: Vec<String> = surfaces
        .iter()
        .map(|surface| {
            let others: Vec<String> = surface["other_formats"]
                .as_array()
                .expect("compared")
                .iter()
                .map(|other| format!("{} {} bpp", other["format"].as_str().unwrap(), other["bits_per_texel"]))
                .collect();
            format!(
                "{} {} bpp; others: {}",
                surface["format"].as_str().unwrap(),
                surface["bits_per_texel"],
                others.join(", ")
            )
        })
        .collect();
    expect_test::expect![[r#"
        [
            "Bc7 8 bpp; others: Bc3 8 bpp, Bc1 4 bpp",
            "Bc1 4 bpp; others: Bc7 8 bpp",
            "Bc5 8 bpp; others: Bc7 8 bpp",
        ]
    "#]]
    .assert_debug_eq(&figures);
    // BC7 costs mra twice BC1's bits and gives more.
    let mra = &surfaces[1];
    let bc7 = &mra["other_formats"][0];
    assert!(bc7["psnr_db"].as_f64().unwrap() > mra["psnr_db"].as_f64().unwrap(), "{mra}");
    // Without the setting, no comparison is made.
    let plain: serde_json::Value = serde_json::from_slice(&project.read("baked/mixed/report.json")).expect("report");
    assert!(plain["materials"][0]["surfaces"][0].get("other_formats").is_none());
}

#[test]
fn blocks_the_albedo_hides_are_encoded_fast_and_the_shown_ones_exactly_as_before() {
    use cirrus::config::EncodeQuality;
    use cirrus::texture::encode::{
        encode_level, encode_levels, encode_levels_reusing, BlockEncodeSettings, HiddenBlocks,
    };
    use cirrus::texture::fingerprint::BlockFingerprints;
    use cirrus::texture::mips::{chain_sizes, mip_chain, MipSettings};
    use cirrus::texture::SurfaceKind;
    // An albedo cut out on its left 26 columns (alpha 0) over a 70 × 40 surface of noise.
    let (width, height) = (70u32, 40u32);
    let albedo_pixels: Vec<u8> =
        (0..width * height).flat_map(|texel| [90, 120, 60, if texel % width < 26 { 0 } else { 255 }]).collect();
    let albedo = cirrus::texture::Texture::new(width, height, albedo_pixels);
    let surface = decode_png(&pattern_png(width, height, 7));
    let levels = mip_chain(&surface, MipSettings { kind: SurfaceKind::Height, alpha_cutoff: None });
    let sizes = chain_sizes(width, height);
    assert_eq!(sizes, levels.iter().map(|level| (level.width, level.height)).collect::<Vec<_>>());
    let hidden = HiddenBlocks::of_alpha(&albedo, &sizes).expect("some blocks are hidden");
    // Level 0: block columns 0..6 lie wholly in the cut-out columns (0..24), column 6 straddles.
    let blocks_x = 18;
    for (number, &is_hidden) in hidden.levels[0].iter().enumerate() {
        assert_eq!(is_hidden, number % blocks_x < 6, "level 0 block {number}");
    }
    // Level 1 (35 × 20): texel x reads level-0 columns 2x and 2x + 1; blocks 0..3 read 0..24.
    for (number, &is_hidden) in hidden.levels[1].iter().enumerate() {
        assert_eq!(is_hidden, number % 9 < 3, "level 1 block {number}");
    }
    // A level whose blocks all reach the shown columns hides nothing.
    assert!(hidden.levels[3].iter().all(|&is_hidden| !is_hidden), "level 3 (8 × 5) reads shown texels");
    let opaque = cirrus::texture::Texture::new(width, height, vec![255; (width * height * 4) as usize]);
    assert!(HiddenBlocks::of_alpha(&opaque, &sizes).is_none(), "an opaque albedo hides nothing");
    // A surface stored at half the albedo's size (an `Auto` candidate's normal) hides what the
    // albedo's level 1 hides; a size off the albedo's chain hides nothing.
    let halved = HiddenBlocks::of_alpha(&albedo, &sizes[1..]).expect("level 1 hides blocks");
    assert_eq!(halved.levels, hidden.levels[1..]);
    assert!(HiddenBlocks::of_alpha(&albedo, &chain_sizes(64, 40)).is_none(), "another size hides nothing");

    let fingerprints = BlockFingerprints::of(&levels[0]);
    for format in [BlockFormat::Bc1, BlockFormat::Bc4, BlockFormat::Bc5, BlockFormat::Bc7] {
        let settings = BlockEncodeSettings { format, quality: EncodeQuality::Basic, alpha: false, srgb: false };
        let fastest = BlockEncodeSettings { quality: EncodeQuality::UltraFast, ..settings };
        let plain = encode_levels(&levels, settings);
        let hiding = encode_levels_reusing(&levels, &fingerprints, (settings, Some(&hidden)), None);
        let size = cirrus::texture::encode::block_bytes(format);
        let mut differing = 0;
        for (index, level) in levels.iter().enumerate() {
            let quick = encode_level(level, fastest);
            for (number, &is_hidden) in hidden.levels[index].iter().enumerate() {
                let block = |bytes: &[u8]| bytes[number * size..][..size].to_vec();
                let expected = if is_hidden { block(&quick) } else { block(&plain.levels[index]) };
                assert_eq!(block(&hiding.levels[index]), expected, "{format:?} level {index} block {number}");
                differing += usize::from(block(&hiding.levels[index]) != block(&plain.levels[index]));
            }
        }
        // The fast setting is a different encoding of noise (the test can tell them apart).
        assert!(differing > 0, "{format:?}: hidden blocks encoded as before");
    }
}

#[test]
fn a_level_of_the_chain_made_alone_is_that_level_of_the_whole_chain() {
    use cirrus::texture::mips::{mip_chain, reduced_level, MipSettings};
    use cirrus::texture::SurfaceKind;
    // An alpha-tested albedo (coverage sought level by level) and a normal map, 256 × 128.
    let albedo = decode_png(&cutout_png(256, 128));
    let normal = decode_png(&pattern_png(256, 128, 7));
    for (texture, settings) in [
        (&albedo, MipSettings { kind: SurfaceKind::Albedo, alpha_cutoff: Some(0.5) }),
        (&normal, MipSettings { kind: SurfaceKind::Normal, alpha_cutoff: None }),
    ] {
        let chain = mip_chain(texture, settings);
        assert_eq!(chain.len(), 9);
        for halvings in 0..=10u32 {
            let alone = reduced_level(texture, settings, halvings);
            let level = &chain[(halvings as usize).min(chain.len() - 1)];
            assert_eq!((alone.width, alone.height), (level.width, level.height), "{settings:?} {halvings}");
            assert!(alone.pixels == level.pixels, "{settings:?}: level {halvings} differs");
        }
    }
}

#[test]
fn normal_maps_whose_texels_are_not_unit_vectors_are_renormalised_before_encoding_and_at_every_level() {
    // A JPEG normal map's texels are vectors of length 0.13–1.6 (the corpus barks): the shader
    // rebuilds Z assuming unit XY, so what BC5 stores must be the unit vector's X and Y, at
    // every mip level, never the raw channels.
    let (width, height) = (64u32, 64u32);
    let mut seed = 12345u32;
    let mut next = || {
        seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        (seed >> 8) as f32 / (1u32 << 24) as f32
    };
    let mut rgba = Vec::new();
    let mut unit = Vec::new();
    for y in 0..height {
        for x in 0..width {
            // A smooth field of directions, each at a random length.
            let (u, v) = (x as f32 / width as f32, y as f32 / height as f32);
            let direction = glam::Vec3::new((u * 6.0).sin() * 0.5, (v * 5.0).cos() * 0.5, 1.0).normalize();
            let length = 0.2 + 1.4 * next();
            let stored = (direction * length).clamp(glam::Vec3::splat(-1.0), glam::Vec3::ONE);
            let byte = |c: f32| ((c * 0.5 + 0.5) * 255.0).round() as u8;
            rgba.extend_from_slice(&[byte(stored.x), byte(stored.y), byte(stored.z), 255]);
            let decoded = glam::Vec3::new(byte(stored.x) as f32, byte(stored.y) as f32, byte(stored.z) as f32) / 127.5
                - glam::Vec3::ONE;
            unit.push(decoded.normalize());
        }
    }
    let project = TempProject::new(
        r#"Pipeline(source: "assets", output: "baked", assets: [Material(name: "n", material: "n.mymaterial")])"#,
    );
    project.write("assets/normal.png", crate::support::png_bytes(width, height, &rgba));
    project.write("assets/n.mymaterial", "Material $n { Texture (attrib = \"normal\") {string {\"normal.png\"}} }\n");
    assert!(build(&mut project.open()).all_ok());
    let bytes = project.read("baked/n/n/normal.ktx2");
    let ktx2 = read_ktx2(&bytes);
    let decode_xy = |texel: [u8; 4]| glam::Vec2::new(texel[0] as f32, texel[1] as f32) / 127.5 - glam::Vec2::ONE;
    // Level 0 against the unit vectors' X and Y.
    let level0 = decode_blocks(BlockFormat::Bc5, &ktx2_level(&bytes, &ktx2, 0), width, height);
    let mut squared = 0.0f64;
    for (index, normal) in unit.iter().enumerate() {
        let xy = decode_xy(level0.texel(index as u32 % width, index as u32 / width));
        squared += f64::from((xy - normal.truncate()).length_squared());
    }
    let psnr_unit = 10.0 * (4.0 / (squared / (2.0 * unit.len() as f64))).log10();
    assert!(psnr_unit > 40.0, "BC5 against the unit vectors' XY: {psnr_unit:.2} dB");
    // Every level rebuilds to a unit vector close to the mean direction of its footprint.
    for level in 0..ktx2.levels.len() {
        let (side_x, side_y) = ((width >> level).max(1), (height >> level).max(1));
        let decoded = decode_blocks(BlockFormat::Bc5, &ktx2_level(&bytes, &ktx2, level), side_x, side_y);
        let scale = width / side_x;
        let mut worst = 1.0f32;
        for y in 0..side_y {
            for x in 0..side_x {
                let xy = decode_xy(decoded.texel(x, y));
                assert!(xy.length_squared() <= 1.03, "level {level}: X² + Y² = {} at {x}, {y}", xy.length_squared());
                let rebuilt = xy.extend((1.0 - xy.length_squared()).max(0.0).sqrt());
                let mut mean = glam::Vec3::ZERO;
                for dy in 0..scale {
                    for dx in 0..scale {
                        mean += unit[((y * scale + dy) * width + x * scale + dx) as usize];
                    }
                }
                worst = worst.min(rebuilt.dot(mean.normalize()));
            }
        }
        assert!(
            worst > 0.97,
            "level {level}: a texel is {:.1}° off its footprint's direction",
            worst.acos().to_degrees()
        );
    }
}
