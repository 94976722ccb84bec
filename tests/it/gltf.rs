//! The glTF files cirrus writes, read by what reads them in real life: the Khronos
//! glTF-Validator (npm `gltf-validator`, run by Node) and trimesh (pip, in a virtual
//! environment; both installed into the target folder when `.ci/run` has not), and the
//! documents' own numbers against the OBJ they stand beside.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

use crate::support::{decode_png, files_under, TempProject};

/// The validator's npm version (pinned: its reports are what the tests read).
const VALIDATOR_VERSION: &str = "2.0.0-dev.3.10";

/// Validates each file given on the command line, resolving its images and buffers beside it;
/// prints one JSON array of `{ file, issues }`.
const VALIDATE_SCRIPT: &str = r#"
const validator = require('gltf-validator');
const fs = require('fs');
const path = require('path');
(async () => {
  const results = [];
  for (const file of process.argv.slice(2)) {
    const report = await validator.validateBytes(new Uint8Array(fs.readFileSync(file)), {
      uri: path.basename(file),
      maxIssues: 100,
      externalResourceFunction: (uri) => new Promise((resolve, reject) => {
        fs.readFile(path.resolve(path.dirname(file), decodeURIComponent(uri)),
          (error, data) => error ? reject(error.toString()) : resolve(new Uint8Array(data)));
      }),
    });
    results.push({ file, issues: report.issues });
  }
  console.log(JSON.stringify(results));
})().catch((error) => { console.error(error); process.exit(1); });
"#;

/// The folder holding `node_modules/gltf-validator` and the script: `CIRRUS_GLTF_VALIDATOR`,
/// else one under the target folder, installed with npm once per test run.
fn validator_folder() -> PathBuf {
    static FOLDER: OnceLock<Result<PathBuf, String>> = OnceLock::new();
    let found = FOLDER.get_or_init(|| {
        let folder = std::env::var_os("CIRRUS_GLTF_VALIDATOR")
            .map(PathBuf::from)
            .unwrap_or_else(|| Path::new(env!("CARGO_TARGET_TMPDIR")).join("gltf-validator"));
        if !folder.join("node_modules/gltf-validator/package.json").is_file() {
            std::fs::create_dir_all(&folder).map_err(|error| error.to_string())?;
            let output = Command::new("npm")
                .args(["install", "--silent", "--no-audit", "--no-fund", "--prefix"])
                .arg(&folder)
                .arg(format!("gltf-validator@{VALIDATOR_VERSION}"))
                .output()
                .map_err(|error| format!("npm: {error}"))?;
            if !output.status.success() {
                return Err(format!("npm install failed: {}", String::from_utf8_lossy(&output.stderr)));
            }
        }
        std::fs::write(folder.join("validate.js"), VALIDATE_SCRIPT).map_err(|error| error.to_string())?;
        Ok(folder)
    });
    match found {
        Ok(folder) => folder.clone(),
        Err(why) => panic!(
            "the glTF tests need Node and npm's gltf-validator@{VALIDATOR_VERSION}, installed into target/tmp on first \
             use (Debian/Ubuntu: `apt-get install nodejs npm`; `.ci/run` installs them): {why}"
        ),
    }
}

/// The validator's infos, but for those every `MSFT_lod` chain gets: the extension is not one it
/// validates, and the nodes only the extension names look unused.
fn infos(issues: &serde_json::Value) -> u64 {
    let messages = issues["messages"].as_array().cloned().unwrap_or_default();
    let chain = messages.iter().any(|message| {
        message["code"] == "UNSUPPORTED_EXTENSION"
            && message["message"].as_str().is_some_and(|text| text.contains("MSFT_lod"))
    });
    let excused = |message: &serde_json::Value| {
        chain
            && (message["code"] == "UNSUPPORTED_EXTENSION"
                || (message["code"] == "UNUSED_OBJECT"
                    && message["pointer"].as_str().is_some_and(|pointer| pointer.starts_with("/nodes/"))))
    };
    let excused = messages.iter().filter(|message| message["severity"] == 2 && excused(message)).count() as u64;
    issues["numInfos"].as_u64().expect("numInfos") - excused
}

/// The validator's issues of each file: (file, errors, warnings, infos (see [`infos`]), messages).
fn validate(files: &[PathBuf]) -> Vec<(PathBuf, u64, u64, u64, String)> {
    let folder = validator_folder();
    let output = Command::new("node").arg(folder.join("validate.js")).args(files).output().expect("node runs");
    assert!(output.status.success(), "the validator failed: {}", String::from_utf8_lossy(&output.stderr));
    let results: serde_json::Value = serde_json::from_slice(&output.stdout).expect("the validator's JSON");
    results
        .as_array()
        .expect("one result per file")
        .iter()
        .map(|result| {
            let issues = &result["issues"];
            (
                PathBuf::from(result["file"].as_str().expect("file")),
                issues["numErrors"].as_u64().expect("numErrors"),
                issues["numWarnings"].as_u64().expect("numWarnings"),
                infos(issues),
                issues["messages"].to_string(),
            )
        })
        .collect()
}

/// trimesh's and its image reader's pip versions (pinned: what the test reads is theirs).
const TRIMESH_PACKAGES: [&str; 3] = ["trimesh==5.2.0", "numpy==2.4.6", "pillow==13.0.0"];

/// Loads each OBJ or glTF given on the command line as a user would (`trimesh.load`, its own
/// resolver beside the file); prints one JSON array of `{ file, error }` or `{ file,
/// geometries: [{ name, faces, material, image: [w, h] or null }] }`.
const TRIMESH_SCRIPT: &str = r#"
import json, sys, trimesh
results = []
for path in sys.argv[1:]:
    try:
        scene = trimesh.load(path, force="scene")
    except Exception as error:
        results.append({"file": path, "error": repr(error)})
        continue
    geometries = []
    for name, geometry in scene.geometry.items():
        material = getattr(geometry.visual, "material", None)
        image = getattr(material, "image", None) or getattr(material, "baseColorTexture", None)
        geometries.append({"name": name, "faces": len(geometry.faces), "material": getattr(material, "name", None),
                           "image": list(image.size) if image is not None else None})
    results.append({"file": path, "geometries": geometries})
print(json.dumps(results))
"#;

/// The Python with trimesh: `CIRRUS_TRIMESH` (a virtual environment), else one under the target
/// folder, made with pip once per test run.
fn trimesh_python() -> PathBuf {
    static PYTHON: OnceLock<Result<PathBuf, String>> = OnceLock::new();
    let found = PYTHON.get_or_init(|| {
        let venv = std::env::var_os("CIRRUS_TRIMESH")
            .map(PathBuf::from)
            .unwrap_or_else(|| Path::new(env!("CARGO_TARGET_TMPDIR")).join("trimesh"));
        let python = venv.join("bin/python");
        let installed = Command::new(&python).args(["-c", "import trimesh, PIL"]).output();
        if !installed.is_ok_and(|output| output.status.success()) {
            let run = |command: &mut Command| -> Result<(), String> {
                let output = command.output().map_err(|error| error.to_string())?;
                output
                    .status
                    .success()
                    .then_some(())
                    .ok_or_else(|| String::from_utf8_lossy(&output.stderr).into_owned())
            };
            run(Command::new("python3").args(["-m", "venv"]).arg(&venv))?;
            run(Command::new(venv.join("bin/pip")).args(["install", "--quiet"]).args(TRIMESH_PACKAGES))?;
        }
        Ok(python)
    });
    match found {
        Ok(python) => python.clone(),
        Err(why) => panic!(
            "the glTF tests need Python's venv and pip for {TRIMESH_PACKAGES:?} (`.ci/run` installs them): {why}"
        ),
    }
}

/// Moves the output folder `baked` somewhere else (the sources out of reach), then checks that
/// every file an OBJ, MTL or glTF names lies inside it (no `..`, nothing absolute) and that
/// trimesh loads every OBJ and glTF with an image on every geometry's material.
fn output_moved_elsewhere_loads_in_trimesh(baked: &Path) {
    let elsewhere = tempfile::tempdir().unwrap();
    let moved = elsewhere.path().join("shipped");
    std::fs::create_dir(&moved).unwrap();
    for file in files_under(baked) {
        let relative = file.strip_prefix(baked).unwrap();
        if relative.starts_with(".cirrus") {
            continue;
        }
        std::fs::create_dir_all(moved.join(relative).parent().unwrap()).unwrap();
        std::fs::copy(&file, moved.join(relative)).unwrap();
    }
    let mut named = 0;
    for file in files_under(&moved) {
        let extension = file.extension().map(|extension| extension.to_string_lossy().into_owned());
        let names: Vec<String> = match extension.as_deref() {
            Some("obj" | "mtl") => std::fs::read_to_string(&file)
                .unwrap()
                .lines()
                .filter(|line| ["mtllib ", "map_", "norm ", "bump "].iter().any(|start| line.starts_with(start)))
                .filter_map(|line| line.split_whitespace().last().map(str::to_string))
                .collect(),
            Some("gltf") => {
                let document: serde_json::Value = serde_json::from_slice(&std::fs::read(&file).unwrap()).unwrap();
                ["images", "buffers"]
                    .iter()
                    .flat_map(|list| document[list].as_array().cloned().unwrap_or_default())
                    .filter_map(|item| item["uri"].as_str().map(str::to_string))
                    .collect()
            }
            _ => continue,
        };
        for name in names {
            assert!(!name.contains("..") && !name.starts_with('/'), "{}: names `{name}`", file.display());
            assert!(file.parent().unwrap().join(&name).is_file(), "{}: `{name}` is missing", file.display());
            named += 1;
        }
    }
    assert!(named > 50, "{named} references checked");
    let mut meshes = files_named(&moved, "obj");
    meshes.extend(files_named(&moved, "gltf"));
    let output = Command::new(trimesh_python()).arg("-c").arg(TRIMESH_SCRIPT).args(&meshes).output().unwrap();
    assert!(output.status.success(), "trimesh: {}", String::from_utf8_lossy(&output.stderr));
    let results: serde_json::Value = serde_json::from_slice(&output.stdout).expect("trimesh's JSON");
    assert_eq!(results.as_array().unwrap().len(), meshes.len());
    for result in results.as_array().unwrap() {
        let geometries = result["geometries"].as_array().unwrap_or_else(|| panic!("{result}"));
        assert!(!geometries.is_empty(), "{result}");
        for geometry in geometries {
            assert!(geometry["image"].is_array(), "{}: a material without its image: {geometry}", result["file"]);
        }
    }
}

fn files_named(folder: &Path, extension: &str) -> Vec<PathBuf> {
    let mut found = files_under(folder);
    found.retain(|path| path.extension().is_some_and(|found| found == extension));
    found
}

#[test]
fn every_gltf_of_the_bundled_project_passes_the_khronos_validator_and_the_output_loads_in_trimesh_once_moved() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let project = TempProject::new(&std::fs::read_to_string(root.join("pipeline.ron")).unwrap());
    std::os::unix::fs::symlink(root.join("examples"), project.path("examples")).unwrap();
    let output = project.run_cli(&["build"]);
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    let documents = files_named(&project.path("baked"), "gltf");
    // The bush and the five levels of its chain (a reduced mesh, three billboard clouds, an
    // impostor).
    let billboard_levels = documents.iter().filter(|path| path.ends_with("lod.gltf")).count();
    assert_eq!(billboard_levels, 6, "a lod.gltf in every level: {documents:?}");
    assert!(documents.contains(&project.path("baked/bush_lods/lods.gltf")), "the chain as one document");
    // Every material of the Material assets as a swatch, alpha-tested where its albedo is.
    let swatches = documents.iter().filter(|path| path.ends_with("material.gltf")).count();
    assert_eq!(swatches, 5, "{documents:?}");
    let alpha_mode = |relative: &str| {
        let document: serde_json::Value = serde_json::from_slice(&project.read(relative)).unwrap();
        document["materials"][0]["alphaMode"].as_str().unwrap_or("OPAQUE").to_string()
    };
    assert_eq!(alpha_mode("baked/materials/oak_leaves/oak_leaves/material.gltf"), "MASK");
    assert_eq!(alpha_mode("baked/steel/painted_steel/material.gltf"), "OPAQUE");
    // A material is a tiling texture set: sampled REPEAT; a billboard atlas CLAMP.
    let wrap = |relative: &str| {
        let document: serde_json::Value = serde_json::from_slice(&project.read(relative)).unwrap();
        document["samplers"][0]["wrapS"].as_u64().unwrap()
    };
    assert_eq!(wrap("baked/steel/painted_steel/material.gltf"), 10497);
    assert_eq!(wrap("baked/bush/lod.gltf"), 33071);
    for (file, errors, warnings, infos, messages) in validate(&documents) {
        assert_eq!((errors, warnings), (0, 0), "{}: {messages}", file.display());
        // The LODs not even an info (an atlas page may have the sides its settings allow).
        if file.ends_with("lod.gltf") || file.ends_with("lods.gltf") {
            assert_eq!(infos, 0, "{}: {messages}", file.display());
        }
    }

    // The chain: its first level's node names the others (MSFT_lod), each level's buffer is the
    // lod.bin beside that level's lod.gltf, and the switch coverages are the report's.
    let chain: serde_json::Value = serde_json::from_slice(&project.read("baked/bush_lods/lods.gltf")).unwrap();
    assert_eq!(chain["scenes"][0]["nodes"], serde_json::json!([0]));
    assert_eq!(chain["nodes"][0]["extensions"]["MSFT_lod"]["ids"], serde_json::json!([1, 2, 3, 4]));
    assert_eq!(chain["extensionsUsed"], serde_json::json!(["MSFT_lod"]));
    for (level, buffer) in chain["buffers"].as_array().unwrap().iter().enumerate() {
        let bin = project.read(&format!("baked/bush_lods/lod{level}/lod.bin"));
        assert_eq!(buffer["uri"], format!("lod{level}/lod.bin"));
        assert_eq!(buffer["byteLength"].as_u64().unwrap() as usize, bin.len());
    }
    let report: serde_json::Value = serde_json::from_slice(&project.read("baked/bush_lods/report.json")).unwrap();
    let coverage = &chain["nodes"][0]["extras"]["MSFT_screencoverage"];
    assert_eq!(coverage, &report["screen_coverage"]);
    let coverage: Vec<f64> = coverage.as_array().unwrap().iter().map(|value| value.as_f64().unwrap()).collect();
    assert_eq!(coverage.len(), 5);
    assert!(coverage.windows(2).all(|pair| pair[0] >= pair[1]) && coverage[4] == 0.0, "{coverage:?}");
    assert!(coverage[0] > coverage[3], "{coverage:?}");
    // The impostor's quad carries its description, as impostor.json has it.
    let impostor: serde_json::Value =
        serde_json::from_slice(&project.read("baked/bush_lods/lod4/impostor.json")).unwrap();
    assert_eq!(chain["meshes"][4]["extras"]["cirrus_impostor"], impostor);
    assert_eq!((&impostor["frames"], &impostor["hemi"]), (&serde_json::json!(8), &serde_json::json!(false)));
    // The reduced level draws the bush's own materials over their packed maps in its
    // materials/ (tiling: repeated), named from the chain's document and from the level's own.
    let images: Vec<&str> =
        chain["images"].as_array().unwrap().iter().map(|image| image["uri"].as_str().unwrap()).collect();
    assert!(images.contains(&"lod0/materials/leaves/albedo.png"), "{images:?}");
    assert!(images.contains(&"lod0/materials/bark/orm.png"), "{images:?}");
    let level: serde_json::Value = serde_json::from_slice(&project.read("baked/bush_lods/lod0/lod.gltf")).unwrap();
    let uri = level["images"][0]["uri"].as_str().unwrap();
    assert!(uri.starts_with("materials/") && project.path("baked/bush_lods/lod0").join(uri).is_file(), "{uri}");
    assert_eq!(level["samplers"][0]["wrapS"], 10497, "REPEAT");
    // The atlas-remapped bush and the tessellated cow, beside their OBJs.
    for document in ["baked/foliage/trees-bush_2.gltf", "baked/spot_height/tessellated.gltf"] {
        assert!(documents.contains(&project.path(document)), "{document}: {documents:?}");
    }
    output_moved_elsewhere_loads_in_trimesh(&project.path("baked"));
    // The validator reads the images: one it cannot find is an error.
    let orm = project.path("baked/bush/orm.png");
    std::fs::rename(&orm, orm.with_extension("moved")).unwrap();
    let (_, errors, _, _, messages) = validate(&[project.path("baked/bush/lod.gltf")]).remove(0);
    assert_eq!(errors, 1, "{messages}");
    assert!(messages.contains("orm.png"), "{messages}");
}

/// The numbers of an accessor of `document` (floats, `components` each).
fn float_accessor(document: &serde_json::Value, bin: &[u8], accessor: u64, components: usize) -> Vec<Vec<f32>> {
    let accessor = &document["accessors"][accessor as usize];
    let view = &document["bufferViews"][accessor["bufferView"].as_u64().unwrap() as usize];
    let offset = view["byteOffset"].as_u64().unwrap_or(0) as usize;
    let count = accessor["count"].as_u64().unwrap() as usize;
    let floats: &[f32] = bytemuck::cast_slice(&bin[offset..offset + count * components * 4]);
    floats.chunks_exact(components).map(<[f32]>::to_vec).collect()
}

#[test]
fn a_billboard_lod_s_gltf_draws_the_obj_s_quads_with_gltf_s_uv_origin_an_alpha_test_and_an_orm_image() {
    let project = TempProject::new(
        r#"Pipeline(source: "assets", output: "baked", assets: [
            BillboardCloud(name: "bush", mesh: "trees/bush_2.obj", atlas: (max_size: 256)),
        ])"#,
    );
    let trees = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/assets/trees");
    std::fs::create_dir_all(project.path("assets")).unwrap();
    std::os::unix::fs::symlink(trees, project.path("assets/trees")).unwrap();
    let output = project.run_cli(&["build"]);
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    let document: serde_json::Value = serde_json::from_slice(&project.read("baked/bush/lod.gltf")).unwrap();
    let bin = project.read("baked/bush/lod.bin");
    assert_eq!(document["buffers"][0]["uri"], "lod.bin");
    assert_eq!(document["buffers"][0]["byteLength"].as_u64().unwrap() as usize, bin.len());
    let material = &document["materials"][0];
    assert_eq!(
        (&material["alphaMode"], &material["alphaCutoff"], &material["doubleSided"]),
        (&"MASK".into(), &0.5.into(), &true.into())
    );
    let image_of = |texture: &serde_json::Value| {
        let source = document["textures"][texture["index"].as_u64().unwrap() as usize]["source"].as_u64().unwrap();
        document["images"][source as usize]["uri"].as_str().unwrap().to_string()
    };
    let pbr = &material["pbrMetallicRoughness"];
    assert_eq!(image_of(&pbr["baseColorTexture"]), "albedo.png");
    assert_eq!(image_of(&pbr["metallicRoughnessTexture"]), "orm.png");
    assert_eq!(image_of(&material["occlusionTexture"]), "orm.png");
    assert_eq!(image_of(&material["normalTexture"]), "normal.png");

    // The same corners as the OBJ's, and its UVs with v flipped (glTF's origin is the top left).
    let obj = String::from_utf8(project.read("baked/bush/lod.obj")).unwrap();
    let numbers = |prefix: &str| -> Vec<Vec<f32>> {
        obj.lines()
            .filter_map(|line| line.strip_prefix(prefix))
            .map(|rest| rest.split_whitespace().map(|number| number.parse().unwrap()).collect())
            .collect()
    };
    let attributes = &document["meshes"][0]["primitives"][0]["attributes"];
    let positions = float_accessor(&document, &bin, attributes["POSITION"].as_u64().unwrap(), 3);
    let uvs = float_accessor(&document, &bin, attributes["TEXCOORD_0"].as_u64().unwrap(), 2);
    let tangents = float_accessor(&document, &bin, attributes["TANGENT"].as_u64().unwrap(), 4);
    assert_eq!(positions, numbers("v "));
    let obj_uvs = numbers("vt ");
    assert_eq!(uvs.len(), obj_uvs.len());
    for (gltf, obj) in uvs.iter().zip(&obj_uvs) {
        assert_eq!(gltf[0], obj[0]);
        assert!((gltf[1] - (1.0 - obj[1])).abs() < 1e-6, "{gltf:?} against the OBJ's {obj:?}");
    }
    assert!(tangents.iter().all(|tangent| tangent[3] == 1.0), "bitangent = normal × tangent");

    // The KTX2 atlas states the orientation the glTF's UVs assume: rows from the top.
    let ktx2 = crate::support::read_ktx2(&project.read("baked/bush/albedo.ktx2"));
    let keys: Vec<&str> = ktx2.key_values.iter().map(|(key, _)| key.as_str()).collect();
    assert_eq!(keys, ["KTXorientation", "KTXwriter"], "sorted, as KTX2 requires");
    assert_eq!(ktx2.key_values[0].1, "rd");

    // orm.png is mra.png with metallic and occlusion swapped, opaque.
    let (mra, orm) = (decode_png(&project.read("baked/bush/mra.png")), decode_png(&project.read("baked/bush/orm.png")));
    assert_eq!((orm.width, orm.height), (mra.width, mra.height));
    for (orm, mra) in orm.pixels.chunks_exact(4).zip(mra.pixels.chunks_exact(4)) {
        assert_eq!(orm, [mra[2], mra[1], mra[0], 255]);
    }
}

#[test]
fn a_chain_gives_way_to_its_next_level_at_that_level_s_switch_size() {
    use cirrus::kinds::billboard_cloud::lod_mesh::{screen_coverage, COVERAGE_VIEWPORT};
    let (width, height) = COVERAGE_VIEWPORT;
    let switch_sizes = [256u32, 128, 64];
    let coverage = screen_coverage(&switch_sizes);
    assert_eq!(coverage.len(), 3);
    assert_eq!(coverage[2], 0.0, "the last level is shown down to nothing");
    for level in 0..2 {
        // The diameter in pixels of the disc whose area share is that coverage: the next
        // level's switch size.
        let pixels = (coverage[level] * width * height / std::f32::consts::FRAC_PI_4).sqrt();
        assert!((pixels - switch_sizes[level + 1] as f32).abs() < 1e-3, "level {level}: {coverage:?}");
    }
    // 128 px on 1920 × 1080: π/4 · 128² / 2073600.
    assert!((coverage[0] - 0.0062056).abs() < 1e-6, "{coverage:?}");
    // A next level that holds at any size takes over at once (coverage 1, the most there is); a
    // level that never holds (0) is never shown, and neither is anything after it.
    assert_eq!(screen_coverage(&[256, 100_000]), [1.0, 0.0]);
    assert_eq!(screen_coverage(&[256, 0, 64]), [0.0, 0.0, 0.0]);
}

#[test]
fn packing_orm_writes_the_packed_surface_in_gltf_s_order_under_its_own_name() {
    // The same bush and steel material baked with `packing: Mra` (the default) and `Orm`: the
    // ORM bake writes orm.ktx2 + orm.png and no mra.*, its orm.png is the MRA bake's orm.png
    // texel for texel, the BC1 keeps its PSNR, and lod.mtl and the glTFs name orm.png.
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let pipeline = std::fs::read_to_string(root.join("pipeline.ron")).unwrap();
    let bake = |pipeline: &str| {
        let project = TempProject::new(pipeline);
        std::os::unix::fs::symlink(root.join("examples"), project.path("examples")).unwrap();
        let output = project.run_cli(&["build", "--asset", "bush", "--asset", "steel"]);
        assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
        project
    };
    let mra = bake(&pipeline);
    let orm_pipeline = pipeline.replace("container: Ktx2),", "container: Ktx2, packing: Orm),");
    assert_ne!(orm_pipeline, pipeline);
    let orm = bake(&orm_pipeline);
    for (folder, container) in [("baked/bush", "ktx2"), ("baked/steel/painted_steel", "dds")] {
        assert!(orm.path(&format!("{folder}/orm.{container}")).is_file(), "{folder}");
        assert!(!orm.path(&format!("{folder}/mra.{container}")).exists());
        assert!(!orm.path(&format!("{folder}/mra.png")).exists(), "{folder}");
        let (ours, theirs) = (orm.read(&format!("{folder}/orm.png")), mra.read(&format!("{folder}/orm.png")));
        assert_eq!(decode_png(&ours).pixels, decode_png(&theirs).pixels, "{folder}");
    }
    let surface_psnr = |project: &TempProject| -> f64 {
        let report: serde_json::Value = serde_json::from_slice(&project.read("baked/bush/report.json")).unwrap();
        let surfaces = report["surfaces"].as_array().unwrap().clone();
        surfaces.iter().find(|surface| surface["surface"] == "Mra").unwrap()["psnr_db"].as_f64().unwrap()
    };
    assert!((surface_psnr(&orm) - surface_psnr(&mra)).abs() < 0.5, "{} {}", surface_psnr(&orm), surface_psnr(&mra));
    let mtl = String::from_utf8(orm.read("baked/bush/lod.mtl")).unwrap();
    assert!(mtl.contains("map_Pr orm.png\nmap_ao orm.png\n"), "{mtl}");
    let documents = [orm.path("baked/bush/lod.gltf"), orm.path("baked/steel/painted_steel/material.gltf")];
    for (file, errors, warnings, _, messages) in validate(&documents) {
        assert_eq!((errors, warnings), (0, 0), "{}: {messages}", file.display());
        assert!(std::fs::read_to_string(&file).unwrap().contains("\"uri\": \"orm.png\""), "{}", file.display());
    }
}

#[test]
fn mikktspace_tangents_follow_u_and_their_sign_follows_a_mirrored_uv() {
    // A square facing +Z, UVs in the OBJ's convention (v up): the tangent points along +u and the
    // bitangent (w · normal × tangent) along +v, so a mirrored u flips both the tangent and w.
    let positions = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]];
    let normals = [[0.0, 0.0, 1.0]; 4];
    let triangles = [[0, 1, 2], [0, 2, 3]];
    let tangents = |uvs: &[[f32; 2]]| cirrus::mesh::mikktspace_tangents(&positions, &normals, uvs, &triangles);
    let close = |a: [f32; 4], b: [f32; 4]| a.iter().zip(b).all(|(a, b)| (a - b).abs() < 1e-5);
    for tangent in tangents(&[[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]) {
        assert!(close(tangent, [1.0, 0.0, 0.0, 1.0]), "{tangent:?}");
    }
    for tangent in tangents(&[[1.0, 0.0], [0.0, 0.0], [0.0, 1.0], [1.0, 1.0]]) {
        assert!(close(tangent, [-1.0, 0.0, 0.0, -1.0]), "{tangent:?}");
    }
}
