//! Bounded in-test fuzzing of every parser that reads user or client input: OpenDDL material
//! files, `pipeline.ron` validation, OBJ + MTL through the mesh stage, and the protocol's request
//! lines. A deterministic mutation generator (seeded, so a failure reproduces) grows inputs from
//! small valid and malformed seeds with the formats' own tokens; any panic fails the test and
//! prints the input. Each target runs for `CIRRUS_FUZZ_SECONDS` (default 3) and prints how many
//! inputs it tried; set it to a few hundred for a long run.

use std::collections::BTreeMap;
use std::panic::AssertUnwindSafe;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// xorshift64*: small, fast and deterministic.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    fn below(&mut self, bound: usize) -> usize {
        (self.next() % bound.max(1) as u64) as usize
    }
}

/// One mutation of `input`: bytes flipped, inserted, deleted, duplicated, format tokens
/// inserted, another seed spliced in, or the end cut off.
fn mutate(rng: &mut Rng, input: &[u8], seeds: &[Vec<u8>], tokens: &[&str]) -> Vec<u8> {
    let mut bytes = input.to_vec();
    for _ in 0..1 + rng.below(4) {
        let at = rng.below(bytes.len() + 1);
        match rng.below(8) {
            0 if !bytes.is_empty() => {
                let index = at.min(bytes.len() - 1);
                bytes[index] ^= 1 << rng.below(8);
            }
            1 => bytes.insert(at, rng.next() as u8),
            2 if !bytes.is_empty() => {
                let end = (at + rng.below(16)).min(bytes.len());
                bytes.drain(at.min(end)..end);
            }
            3 if !bytes.is_empty() => {
                let start = rng.below(bytes.len());
                let end = (start + 1 + rng.below(64)).min(bytes.len());
                let piece = bytes[start..end].repeat(1 + rng.below(8));
                bytes.splice(at..at, piece);
            }
            4 | 5 => {
                let token = tokens[rng.below(tokens.len())].as_bytes().repeat(1 + rng.below(3));
                bytes.splice(at..at, token);
            }
            6 => {
                let seed = &seeds[rng.below(seeds.len())];
                let start = rng.below(seed.len());
                let end = (start + rng.below(256)).min(seed.len());
                bytes.splice(at..at, seed[start..end].iter().copied());
            }
            _ => bytes.truncate(at),
        }
    }
    bytes.truncate(1 << 16);
    bytes
}

/// Feeds `target` seeds and their mutations (mutations of mutations too) for the fuzzing time;
/// returns how many inputs ran. `target` says whether it accepted the input: accepted inputs are
/// kept for more mutation (they reach deeper than the ones refused at their first token), and
/// one refused input in sixteen. A panic fails the test with the input that caused it.
fn fuzz(name: &str, seeds: Vec<Vec<u8>>, tokens: &[&str], target: impl Fn(&[u8]) -> bool) -> u64 {
    let seconds: u64 = std::env::var("CIRRUS_FUZZ_SECONDS").ok().and_then(|text| text.parse().ok()).unwrap_or(3);
    let deadline = Instant::now() + Duration::from_secs(seconds);
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15 ^ name.len() as u64);
    let mut pool = seeds.clone();
    let mut executions = 0u64;
    let mut failure = None;
    while Instant::now() < deadline && failure.is_none() {
        let parent = &pool[rng.below(pool.len())];
        let input = if executions < seeds.len() as u64 {
            seeds[executions as usize].clone()
        } else {
            mutate(&mut rng, parent, &seeds, tokens)
        };
        executions += 1;
        let accepted = match std::panic::catch_unwind(AssertUnwindSafe(|| target(&input))) {
            Ok(accepted) => accepted,
            Err(panic) => {
                let message = panic
                    .downcast_ref::<String>()
                    .cloned()
                    .or_else(|| panic.downcast_ref::<&str>().map(|text| text.to_string()));
                failure = Some((input, message.unwrap_or_default()));
                break;
            }
        };
        if accepted || rng.below(16) == 0 {
            if pool.len() < 4096 {
                pool.push(input);
            } else {
                let slot = rng.below(pool.len());
                pool[slot] = input;
            }
        }
    }
    if let Some((input, message)) = failure {
        panic!("{name}: panic `{message}` on input {:?}", String::from_utf8_lossy(&input));
    }
    println!("fuzz {name}: {executions} inputs in {seconds} s, no panic");
    executions
}

fn files_in(folder: &str, extension: &str) -> Vec<Vec<u8>> {
    let folder = Path::new(env!("CARGO_MANIFEST_DIR")).join(folder);
    let mut paths: Vec<PathBuf> = std::fs::read_dir(&folder)
        .unwrap_or_else(|error| panic!("{}: {error}", folder.display()))
        .flatten()
        .map(|entry| entry.path())
        .filter(|path| path.extension().is_some_and(|found| found == extension))
        .collect();
    paths.sort();
    paths.iter().map(|path| std::fs::read(path).unwrap()).collect()
}

#[test]
fn fuzz_openddl_material_files() {
    let mut seeds = files_in("examples/assets/materials", "mymaterial");
    seeds.extend(files_in("tests/fixtures/material_errors", "mymaterial"));
    let tokens = [
        "{",
        "}",
        "(",
        ")",
        "[",
        "]",
        ",",
        "=",
        "\"",
        "'",
        "\\",
        "\\u{10FFFF}",
        "\\x",
        "$m",
        "%l",
        "//",
        "/*",
        "*/",
        "\n",
        "\r\n",
        "Material",
        "Texture",
        "Param",
        "Color",
        "Name",
        "string",
        "float",
        "float[3]",
        "float[0]",
        "float[4294967296]",
        "int8",
        "half",
        "ref",
        "type",
        "bool",
        "attrib",
        "\"diffuse\"",
        "\"ao\"",
        "0x",
        "0b",
        "1e999",
        "-0",
        "nan",
        "1.5e-45",
        "../../../x",
        "\u{feff}",
    ];
    let executions = fuzz("openddl", seeds, &tokens, |bytes| {
        cirrus::kinds::material::definition::parse_material_file(
            Path::new("assets/m.mymaterial"),
            bytes,
            Path::new("assets"),
        )
        .is_ok()
    });
    assert!(executions > 0);
}

#[test]
fn fuzz_pipeline_validation() {
    let mut seeds = files_in("tests/fixtures/pipeline_errors", "ron");
    seeds.push(std::fs::read(Path::new(env!("CARGO_MANIFEST_DIR")).join("pipeline.ron")).unwrap());
    let tokens = [
        "(",
        ")",
        "[",
        "]",
        ",",
        ":",
        "\"",
        "Some(",
        "None",
        "true",
        "1e40",
        "-1",
        "0",
        "4294967296",
        "nan",
        "inf",
        "\"..\"",
        "\"/\"",
        "\"a//b\"",
        "Material(name: \"m\", material: \"m.mymaterial\")",
        "BillboardCloud(name: \"t\", mesh: \"t.obj\")",
        "rules: [(glob: \"**/*\", kind: Material)]",
        "server: Some(\"localhost:1\")",
        "limits: (texture_memory_mib: 0)",
        "epsilon:",
        "max_size:",
        "padding:",
        "zstd:",
        "\u{feff}",
        "//",
        "/*",
        "*/",
        "r#\"",
        "\\",
    ];
    let executions = fuzz("pipeline", seeds, &tokens, |bytes| {
        cirrus::pipeline::parse_pipeline(Path::new("pipeline.ron"), &String::from_utf8_lossy(bytes)).is_ok()
    });
    assert!(executions > 0);
}

#[test]
fn fuzz_obj_and_mtl_through_the_mesh_stage() {
    let obj = b"mtllib m.mtl\no cube\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvn 0 0 1\n\
usemtl bark\nf 1/1/1 2/2/1 3/3/1 4/4/1\no leaf\nv 0 0 1\nv 1 0 1\nv 0 1 1\nusemtl leaf\nf -3 -2 -1\nf 5 6 7\n"
        .to_vec();
    let mtl = b"newmtl bark\nKd 0.5 0.4 0.3\nmap_Kd -s 1 1 1 bark.png\nnorm bark_n.png\nPm 0\nPr 0.8\nmap_ao ao.png\n\
newmtl leaf\nd 0.5\nmap_d leaf.png\nmap_Kd leaf.png\n"
        .to_vec();
    let seeds = vec![[obj.as_slice(), b"\0", mtl.as_slice()].concat(), b"v 1 2 3\nf 1 1 1\n".to_vec(), b"\0".to_vec()];
    let tokens = [
        "v ", "vt ", "vn ", "f ", "o ", "g ", "s off", "usemtl ", "mtllib ", "newmtl ", "map_Kd ", "map_d ", "-1", "0",
        "/", "//", " 1e38", " -1e38", " nan", " inf", "\n", "\r\n", "\\", "../", "\t", "#", "Kd", "d", "Pm", "Pr",
        "-o", "-s", "-bm", "\u{feff}",
    ];
    let executions = fuzz("obj", seeds, &tokens, |bytes| {
        // One input carries the OBJ, then (after the first NUL) the MTL it names.
        let (obj, mtl) = match bytes.iter().position(|&byte| byte == 0) {
            Some(split) => (&bytes[..split], Some(bytes[split + 1..].to_vec())),
            None => (bytes, None),
        };
        let path = Path::new("assets/m.obj");
        let libraries: BTreeMap<PathBuf, Option<Vec<u8>>> =
            cirrus::mesh::material_libraries(path, obj, Path::new("assets"))
                .into_iter()
                .map(|library| (library, mtl.clone()))
                .collect();
        let _ = cirrus::mesh::texture_paths(&libraries, Path::new("assets"));
        let Ok((mesh, _)) = cirrus::mesh::load_mesh(path, obj, &libraries, Path::new("assets")) else { return false };
        // What later stages rely on: indices in range, one material per face.
        assert_eq!(mesh.triangles.len(), mesh.triangle_materials.len());
        assert!(mesh.triangles.iter().flatten().all(|&index| (index as usize) < mesh.positions.len()));
        assert!(mesh.triangle_materials.iter().all(|&material| (material as usize) < mesh.materials.len()));
        assert!(mesh.uvs.as_ref().is_none_or(|uvs| uvs.len() == mesh.positions.len()));
        true
    });
    assert!(executions > 0);
}

#[test]
fn fuzz_protocol_request_lines() {
    let seeds: Vec<Vec<u8>> = [
        r#"{"type":"subscribe","since":null}"#,
        r#"{"type":"subscribe","since":18446744073709551615}"#,
        r#"{"type":"graph","format":"dot","asset":"bark"}"#,
        r#"{"type":"graph"}"#,
        r#"not json"#,
    ]
    .iter()
    .map(|line| line.as_bytes().to_vec())
    .collect();
    let tokens = [
        "{",
        "}",
        "[",
        "]",
        "\"",
        ":",
        ",",
        "null",
        "-1",
        "1e400",
        "\"type\"",
        "\"since\"",
        "\\u0000",
        "\\ud800",
        "\u{feff}",
    ];
    let executions =
        fuzz("protocol", seeds, &tokens, |bytes| matches!(cirrus::server::parse_request(bytes), Ok(Some(_))));
    assert!(executions > 0);
}
