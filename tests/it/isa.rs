//! `--isa` (`CIRRUS_ISA`): the CPU kernels held at a lower instruction-set level, as a machine
//! without AVX-512 or AVX2 runs them. cirrus's BC4/BC5 give the same bytes at every level; the
//! ISPC kernels (BC1, BC7) give other bytes below AVX2 at the same quality, so their cache
//! entries carry the kernels' output family and a shared cache never mixes them.

use std::collections::BTreeMap;

use cirrus::isa::{detected_isa, IsaLevel};

use crate::support::TempProject;

/// Each surface of the project's reports: path → (format, PSNR).
fn surfaces(project: &TempProject) -> BTreeMap<String, (String, f64)> {
    let mut surfaces = BTreeMap::new();
    for asset in ["bark", "mixed"] {
        let report: serde_json::Value =
            serde_json::from_slice(&project.read(&format!("baked/{asset}/report.json"))).unwrap();
        for material in report["materials"].as_array().unwrap() {
            for surface in material["surfaces"].as_array().unwrap() {
                let entry = (surface["format"].as_str().unwrap().to_string(), surface["psnr_db"].as_f64().unwrap());
                surfaces.insert(surface["path"].as_str().unwrap().to_string(), entry);
            }
        }
    }
    surfaces
}

/// `cirrus [arguments] build --summary json`: how many stage instances ran, per stage.
fn build_at(project: &TempProject, arguments: &[&str]) -> BTreeMap<String, usize> {
    let mut all = arguments.to_vec();
    all.extend(["build", "--summary", "json"]);
    let output = project.run_cli(&all);
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    let summary: serde_json::Value = serde_json::from_slice(&output.stdout).unwrap();
    let mut ran = BTreeMap::new();
    for asset in summary["assets"].as_array().unwrap() {
        for stage in asset["stages"].as_array().unwrap().iter().filter(|stage| stage["status"] == "ran") {
            *ran.entry(stage["stage"].as_str().unwrap().to_string()).or_default() += 1;
        }
    }
    ran
}

#[test]
fn a_lower_instruction_set_level_bakes_the_same_quality_and_keeps_its_own_entries() {
    let native = crate::material::bake::material_project("");
    build_at(&native, &[]);
    let (native_surfaces, native_bytes) = (surfaces(&native), crate::watch::output_hashes(&native));
    assert!(
        native_surfaces.values().any(|(format, _)| format == "Bc7")
            && native_surfaces.values().any(|(format, _)| format == "Bc5")
    );

    // The same sources baked at SSE2 in another folder: BC4/BC5 byte for byte, BC1/BC7 within a
    // tenth of a dB of the native bake.
    let portable = crate::material::bake::material_project("");
    build_at(&portable, &["--isa", "sse2"]);
    let portable_bytes = crate::watch::output_hashes(&portable);
    for (path, (format, psnr)) in surfaces(&portable) {
        let (_, native_psnr) = &native_surfaces[&path];
        if format == "Bc4" || format == "Bc5" {
            assert_eq!(portable_bytes[&path], native_bytes[&path], "{path} ({format})");
        }
        assert!(
            (psnr - native_psnr).abs() <= 0.1,
            "{path} ({format}): {psnr} dB at sse2, {native_psnr} dB at {}",
            detected_isa()
        );
    }

    // At AVX2 on a machine that has it: the same family as AVX-512, so its bake is the native
    // one, byte for byte; SSE2's entries were not taken for it.
    if detected_isa() >= IsaLevel::Avx2 {
        let ran = build_at(&portable, &["--isa", "avx2"]);
        assert!(ran.contains_key("encode"), "the BC1/BC7 surfaces are encoded again: {ran:?}");
        assert_eq!(crate::watch::output_hashes(&portable), native_bytes);
        assert_eq!(build_at(&native, &["--isa", "avx2"]), BTreeMap::new(), "AVX2 takes the AVX-512 entries");
    }
}

#[test]
fn an_unknown_instruction_set_level_is_a_usage_error() {
    let project = crate::material::bake::material_project("");
    let output = project.run_cli(&["--isa", "avx3", "build"]);
    assert_eq!(output.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("`avx3` is not an instruction-set level (sse2, sse4, avx2 or avx512)"), "{stderr}");
}
