//! Benchmark (`cargo bench [-- materials|packing|planes|billboard|watch|atlas|occlusion|ao|height]`): material-bake
//! throughput next to the raw encoder's, no-op rebuild and warm restart next to a full bake, the
//! page packer's time and occupancy beside Python `rectpack`, plane selection speed,
//! billboard-cloud bake time, memory, edit re-bake and fidelity per ε, the daemon's edit latency,
//! burst handling and warm restart (`watch`), the texture atlas's full bake and one-texture edit
//! (`atlas`), a LOD chain's time beside a single bake and its levels' fidelity
//! (`billboard-chain`), occlusion rays per second (`occlusion`), and the AmbientOcclusion kind's bake of the
//! flight helmet with its quality beside per-vertex bakes (`ao`), the Height kind's distances
//! and times on the bundled and a corpus pair (`height`), and the block encoders' throughput and
//! the oak full bake at each instruction-set level this CPU runs (`isa`), and the oak full bake
//! against a shared cache on a local SeaweedFS server (`shared-cache`), and the oak's full bake
//! as a process beside another build's binary, alternating (`oak-bake`), and a synthetic level
//! of 100, 1,000 and 10,000 assets: cold, no-op, one-texture edit, `graph`, `check`, peak
//! memory and the daemon's ready time and edit-to-batch latency (`scale`), and levels of 16, 64
//! and 256 materials with 1024² maps and of 8 corpus trees as Auto chains: the peak and idle
//! memory of a cold build and a cold daemon (`level-memory`). Prints figures.

use std::path::Path;
use std::time::Instant;

#[path = "../tests/it/seaweed.rs"]
#[allow(dead_code)]
mod seaweed;

#[path = "../examples/make_level.rs"]
#[allow(dead_code)]
mod make_level;

use cirrus::config::{BlockFormat, EncodeQuality};
use cirrus::pipeline::load_pipeline;
use cirrus::project::{BuildOptions, Project, ProjectOptions};
use cirrus::texture::encode::BlockEncodeSettings;
use cirrus::texture::mips::{mip_chain, MipSettings};
use cirrus::texture::SurfaceKind;
use cirrus::texture::Texture;
use rayon::prelude::*;

fn main() {
    cirrus::gpu::quiet_wayland_probe();
    let repository = Path::new(env!("CARGO_MANIFEST_DIR"));
    let corpus = repository.join("../shared/assets");
    let mut sources = vec![("bundled examples", repository.join("examples/assets"), "materials/*.mymaterial")];
    if corpus.join("materials").is_dir() {
        sources.push(("corpus", corpus.clone(), "materials/*.mymaterial"));
    }
    // `cargo bench -- NAME` runs only the sections whose name contains NAME.
    let filter: Vec<String> = std::env::args().skip(1).filter(|argument| !argument.starts_with('-')).collect();
    let wanted = |section: &str| filter.is_empty() || filter.iter().any(|name| section.contains(name.as_str()));
    if wanted("materials") {
        for (label, source, glob) in sources {
            bench_project(label, &source.canonicalize().expect("source folder"), glob);
        }
    }
    if wanted("packing") {
        bench_packing(repository);
    }
    if corpus.join("meshes").is_dir() {
        if wanted("planes") {
            bench_planes(&corpus);
        }
        if wanted("billboard") {
            bench_billboards(&corpus);
        }
        if wanted("billboard-quality") {
            bench_billboard_quality(&corpus);
        }
        if wanted("billboard-budget") {
            bench_billboard_budget(&corpus);
        }
        if wanted("billboard-chain") {
            bench_billboard_chain(&corpus);
        }
        if wanted("billboard-auto") {
            bench_billboard_auto(repository, &corpus);
        }
        if wanted("watch") {
            bench_watch(&corpus);
        }
    }
    if corpus.join("pbr").is_dir() && wanted("atlas") {
        bench_atlas(&corpus);
    }
    if corpus.join("meshes").is_dir() && wanted("occlusion") {
        bench_occlusion(&corpus);
    }
    if corpus.join("meshes").is_dir() && wanted("ao") {
        bench_ambient_occlusion(&corpus);
    }
    if wanted("height") {
        bench_height(repository);
    }
    if corpus.join("trees").is_dir() && wanted("isa") {
        bench_isa(&corpus);
    }
    if corpus.join("trees").is_dir() && wanted("oak-bake") {
        bench_oak_bake(&corpus);
    }
    if corpus.join("trees").is_dir() && wanted("shared-cache") {
        bench_shared_cache(&corpus);
    }
    if wanted("scale") {
        bench_scale();
    }
    if wanted("memory") {
        bench_memory();
    }
    if wanted("level-memory") {
        bench_level_memory(&corpus);
    }
}

/// Peak memory of `cirrus build` over 1 and 4 materials with a 2048² albedo each (a PNG of
/// `make_level`'s noise): what one more large texture adds to a one-shot build (the build keeps
/// its outputs until it publishes them, and no intermediate: `Retention::OutputsOnly`).
fn bench_memory() {
    const SIDE: u32 = 2048;
    println!("memory: cirrus build, {SIDE}² albedo per material; CPU ISA {}", cirrus::isa::detected_isa().name());
    let mut peaks = Vec::new();
    for count in [1usize, 4] {
        let dir = tempfile::tempdir().expect("temporary folder");
        let mut assets = String::new();
        for index in 0..count {
            let folder = dir.path().join("assets");
            std::fs::create_dir_all(&folder).expect("folder");
            std::fs::write(folder.join(format!("t{index}.png")), make_level::noise_png(SIDE, SIDE, 3, index as u64))
                .expect("png");
            let material =
                format!("Material $t{index} {{ Texture (attrib = \"diffuse\") {{string {{\"t{index}.png\"}}}} }}");
            std::fs::write(folder.join(format!("t{index}.mymaterial")), material).expect("material");
            assets.push_str(&format!("Material(name: \"t{index}\", material: \"t{index}.mymaterial\"),\n"));
        }
        let pipeline = format!("Pipeline(source: \"assets\", output: \"baked\", assets: [\n{assets}])");
        std::fs::write(dir.path().join("pipeline.ron"), pipeline).expect("pipeline");
        let (seconds, peak_mib) = timed_process(dir.path(), &["build"]);
        println!("  {count} material(s): peak {peak_mib:.0} MiB, {seconds:.2} s");
        peaks.push(peak_mib);
    }
    let per_texture = (peaks[1] - peaks[0]) / 3.0;
    let per_texel = per_texture * 1024.0 * 1024.0 / f64::from(SIDE * SIDE);
    println!("  each more texture: {per_texture:.0} MiB ({per_texel:.1} bytes per texel)");
}

/// Memory over a level's worth of texels: levels of `Material` assets with 1024² albedo and
/// normal maps, one in four with a roughness map too (`CIRRUS_BENCH_LEVEL_MEMORY`: the asset
/// counts, 16, 64 and 256 unless set), then 8 corpus trees as `BillboardCloud` Auto chains
/// (where the corpus is there), under a memory budget (`CIRRUS_BENCH_MEMORY_MIB`, 1024 unless
/// set; `0`: none given, the default of half the machine's memory). Each level: `cirrus build`
/// cold (wall, peak RSS and its bytes per source texel), then `cirrus watch` on the same level
/// unbaked (no output, no cache) until its first batch (wall, peak RSS, and RSS when idle 2 s
/// after it), then, for the Materials, one-texture edits in that daemon: the first three assets'
/// albedos in turn (baked first, so evicted longest ago where the level does not fit), each
/// written anew, to its batch (median and worst).
fn bench_level_memory(corpus: &Path) {
    const SIDE: u32 = 1024;
    let sizes = level_sizes("CIRRUS_BENCH_LEVEL_MEMORY", &[16, 64, 256]);
    let budget: u64 = std::env::var("CIRRUS_BENCH_MEMORY_MIB").ok().and_then(|mib| mib.parse().ok()).unwrap_or(1024);
    let budget_arguments = match budget {
        0 => Vec::new(),
        mib => vec!["--memory-mib".to_string(), mib.to_string()],
    };
    println!(
        "level-memory: Material assets with {SIDE}² albedo and normal maps (one in four a roughness map), budget {}; \
         CPU ISA {}, {} threads",
        if budget == 0 { "the default".to_string() } else { format!("{budget} MiB") },
        cirrus::isa::detected_isa().name(),
        rayon::current_num_threads()
    );
    for assets in sizes {
        let dir = tempfile::tempdir().expect("temporary folder");
        let folder = dir.path();
        let settings = make_level::LevelSettings { assets, material_side: Some(SIDE) };
        let level = make_level::write_level(folder, &settings).expect("level written");
        let maps = 2 * assets + assets.div_ceil(4);
        let texels = maps as f64 * f64::from(SIDE * SIDE);
        let edits = (0..3)
            .map(|index| {
                (folder.join(&level.albedo_maps[index]), make_level::noise_png(SIDE, SIDE, 3, 7_777 + index as u64))
            })
            .collect();
        let figures = level_memory(folder, &budget_arguments, edits);
        println!("  {assets} assets ({:.0} M source texels): {}", texels / 1e6, figures.to_text(texels));
    }
    if corpus.join("trees").is_dir() {
        let (dir, texels) = tree_level(corpus, 8);
        let figures = level_memory(dir.path(), &budget_arguments, Vec::new());
        println!(
            "  8 trees (oak, ash, bush, each a 3-level Auto chain; {:.1} M source texels): {}",
            texels / 1e6,
            figures.to_text(texels)
        );
    }
}

/// What `level_memory` measured of a level.
struct LevelMemory {
    build: f64,
    build_peak: f64,
    first_batch: f64,
    daemon_peak: f64,
    idle: f64,
    /// The one-texture edits' median and worst seconds (none: no edit).
    edit: Option<(f64, f64)>,
}

impl LevelMemory {
    /// One line of figures, with the peaks per source texel of a level of `texels`.
    fn to_text(&self, texels: f64) -> String {
        let per_texel = |mib: f64| mib * 1024.0 * 1024.0 / texels;
        let edit = self
            .edit
            .map(|(median, worst)| format!("; one-texture edit {median:.2} s (worst {worst:.2})"))
            .unwrap_or_default();
        format!(
            "build {:.1} s, peak {:.0} MiB ({:.1} B/texel); watch, unbaked: first batch {:.1} s, peak {:.0} MiB \
             ({:.1} B/texel), idle {:.0} MiB{edit}",
            self.build,
            self.build_peak,
            per_texel(self.build_peak),
            self.first_batch,
            self.daemon_peak,
            per_texel(self.daemon_peak),
            self.idle,
        )
    }
}

/// A cold `cirrus build` of the project in `folder`, then, its output removed, a cold `cirrus
/// watch` until its first batch, idle 2 s, and each of `edits` (a file and its new bytes)
/// written in turn, each to its batch.
fn level_memory(folder: &Path, budget_arguments: &[String], edits: Vec<(std::path::PathBuf, Vec<u8>)>) -> LevelMemory {
    let build_arguments: Vec<&str> =
        std::iter::once("build").chain(budget_arguments.iter().map(String::as_str)).collect();
    let (build, build_peak) = timed_process(folder, &build_arguments);
    std::fs::remove_dir_all(folder.join("baked")).expect("output removed");
    let start = Instant::now();
    let mut daemon = WatchedDaemon::start_with(folder, budget_arguments);
    daemon.batch();
    let first_batch = start.elapsed().as_secs_f64();
    let status_file = format!("/proc/{}/status", daemon.child.id());
    let daemon_peak = peak_memory_kib(&status_file) as f64 / 1024.0;
    std::thread::sleep(std::time::Duration::from_secs(2));
    let idle = status_kib(&status_file, "VmRSS:") as f64 / 1024.0;
    let edit_times: Vec<f64> = edits
        .into_iter()
        .map(|(path, bytes)| {
            let start = Instant::now();
            std::fs::write(&path, bytes).expect("edited file written");
            daemon.batch();
            start.elapsed().as_secs_f64()
        })
        .collect();
    let edit = (!edit_times.is_empty()).then(|| median_and_worst(edit_times));
    LevelMemory { build, build_peak, first_batch, daemon_peak, idle, edit }
}

/// A project of `trees` corpus trees (oak, ash and bush in turn) as `BillboardCloud` Auto chains
/// of three levels (2 MiB, 512 KiB, 128 KiB), each tree's OBJ scaled by 1 + 0.05·i so that no tree
/// is a cache hit of another, and the texels of the source images its trees read.
fn tree_level(corpus: &Path, trees: usize) -> (tempfile::TempDir, f64) {
    const MODELS: [&str; 3] = ["oak_medium", "ash_small", "bush_2"];
    let mut assets = String::new();
    let mut scaled = Vec::new();
    for index in 0..trees {
        let model = MODELS[index % MODELS.len()];
        scaled.push((format!("trees/{model}_{index}.obj"), model, 1.0 + 0.05 * index as f32));
        assets.push_str(&format!(
            "BillboardCloud(name: \"{model}_{index}\", mesh: \"trees/{model}_{index}.obj\", billboard: (lods: \
             [Auto(max_bytes: 2097152), Auto(max_bytes: 524288), Auto(max_bytes: 131072)])),\n"
        ));
    }
    let dir = tree_project(corpus, &assets);
    for (path, model, scale) in scaled {
        let source = std::fs::read_to_string(corpus.join(format!("trees/{model}.obj"))).expect("tree OBJ");
        std::fs::write(dir.path().join("assets").join(path), scaled_obj(&source, scale)).expect("scaled OBJ");
    }
    // Each tree reads its bark's 1k maps (colour, normal, roughness, AO) and its leaf card.
    let mut texels = 0.0;
    for index in 0..trees {
        let leaf = ["oak_color.png", "ash_color.png", "aspen_color.png"][index % MODELS.len()];
        let leaf = image::image_dimensions(corpus.join("trees/textures").join(leaf)).expect("leaf card");
        texels += 4.0 * 1024.0 * 1024.0 + f64::from(leaf.0 * leaf.1);
    }
    (dir, texels)
}

/// An OBJ's text with every vertex position (`v x y z`) multiplied by `scale`.
fn scaled_obj(source: &str, scale: f32) -> String {
    let mut scaled = String::with_capacity(source.len());
    for line in source.lines() {
        match line.strip_prefix("v ") {
            Some(position) => {
                let coordinates: Vec<String> = position
                    .split_whitespace()
                    .map(|value| {
                        value.parse::<f32>().map(|value| (value * scale).to_string()).unwrap_or(value.to_string())
                    })
                    .collect();
                scaled.push_str(&format!("v {}", coordinates.join(" ")));
            }
            None => scaled.push_str(line),
        }
        scaled.push('\n');
    }
    scaled
}

/// The level sizes (asset counts) the environment variable `variable` lists (`16,64`), else
/// `default`.
fn level_sizes(variable: &str, default: &[usize]) -> Vec<usize> {
    std::env::var(variable)
        .ok()
        .map(|sizes| sizes.split(',').filter_map(|size| size.trim().parse().ok()).collect())
        .unwrap_or_else(|| default.to_vec())
}

/// A process's wall seconds and peak resident memory (MiB), its stdout discarded.
fn timed_process(folder: &Path, arguments: &[&str]) -> (f64, f64) {
    let start = Instant::now();
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_cirrus"))
        .args(arguments)
        .current_dir(folder)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .expect("run cirrus");
    let status_file = format!("/proc/{}/status", child.id());
    let mut peak_kib = 0u64;
    let status = loop {
        if let Some(status) = child.try_wait().expect("child") {
            break status;
        }
        peak_kib = peak_kib.max(peak_memory_kib(&status_file));
        std::thread::sleep(std::time::Duration::from_millis(2));
    };
    assert!(status.success(), "cirrus {arguments:?} failed in {}", folder.display());
    (start.elapsed().as_secs_f64(), peak_kib as f64 / 1024.0)
}

/// `VmHWM` of a `/proc/<pid>/status` file, in KiB (0 once the process is gone).
fn peak_memory_kib(status_file: &str) -> u64 {
    status_kib(status_file, "VmHWM:")
}

/// A field of a `/proc/<pid>/status` file in KiB (`VmHWM:`, `VmRSS:`; 0 once the process is gone).
fn status_kib(status_file: &str, field: &str) -> u64 {
    let Ok(status) = std::fs::read_to_string(status_file) else { return 0 };
    let line = status.lines().find(|line| line.starts_with(field));
    line.and_then(|line| line.split_whitespace().nth(1)?.parse().ok()).unwrap_or(0)
}

/// Median and largest of some figures.
fn median_and_worst(mut figures: Vec<f64>) -> (f64, f64) {
    figures.sort_by(f64::total_cmp);
    (figures[figures.len() / 2], figures[figures.len() - 1])
}

/// The figures of one level size.
struct ScaleFigures {
    assets: usize,
    cold: f64,
    cold_peak_mib: f64,
    first_no_op: f64,
    no_op: f64,
    edit: f64,
    graph: f64,
    check: f64,
    ready: f64,
    daemon_edit: (f64, f64),
    daemon_build: (f64, f64),
    daemon_peak_mib: f64,
}

/// The synthetic level of `examples/make_level.rs` at 100, 1,000 and 10,000 assets (or the
/// sizes in `CIRRUS_BENCH_SCALE`, comma-separated), each measured as whole processes on the
/// same machine in one run: the cold build, a no-op build (the first, whose sources are still
/// within the record's racy window when the level was just written, and the median of three
/// later ones), a one-texture edit (median of three, a 64² albedo each time another material's),
/// `graph --format json` and `check`, peak memory; then the daemon: the time to its first batch
/// on the baked level (ready) and the latency from writing a 64² albedo to the batch event,
/// median and worst of 20 edits.
fn bench_scale() {
    let sizes = level_sizes("CIRRUS_BENCH_SCALE", &[100, 1_000, 10_000]);
    println!(
        "scale: synthetic levels (90 % materials with 64² maps, one in ten 256², 7 % AO rocks, 3 % billboard plants); \
         CPU ISA {}{}, {} threads",
        cirrus::isa::detected_isa().name(),
        std::env::var("CIRRUS_ISA")
            .map(|isa| format!(" (processes limited to {isa} by CIRRUS_ISA)"))
            .unwrap_or_default(),
        rayon::current_num_threads()
    );
    let mut all = Vec::new();
    for assets in sizes {
        let dir = tempfile::tempdir().expect("temporary folder");
        let start = Instant::now();
        let level = make_level::write_level(dir.path(), &make_level::LevelSettings { assets, ..Default::default() })
            .expect("level written");
        let written = start.elapsed().as_secs_f64();
        let folder = dir.path();
        let (cold, cold_peak_mib) = timed_process(folder, &["build"]);
        let (first_no_op, _) = timed_process(folder, &["build"]);
        let no_op = median_and_worst((0..3).map(|_| timed_process(folder, &["build"]).0).collect()).0;
        // Materials whose albedo is 64² (one in ten is 256²).
        let small: Vec<&std::path::PathBuf> =
            level.albedo_maps.iter().enumerate().filter(|(index, _)| index % 10 != 9).map(|(_, path)| path).collect();
        let mut edits = 0u64;
        let edit_texture = |edits: &mut u64| {
            let path = folder.join(small[(*edits as usize * 7919) % small.len()]);
            *edits += 1;
            std::fs::write(&path, make_level::noise_png(64, 64, 3, 1_000_000 + *edits)).expect("edit");
        };
        let edit = median_and_worst(
            (0..3)
                .map(|_| {
                    edit_texture(&mut edits);
                    timed_process(folder, &["build"]).0
                })
                .collect(),
        )
        .0;
        let (graph, _) = timed_process(folder, &["graph", "--format", "json"]);
        let (check, _) = timed_process(folder, &["check"]);

        let start = Instant::now();
        let mut daemon = WatchedDaemon::start(folder);
        daemon.batch();
        let ready = start.elapsed().as_secs_f64();
        let (mut latencies, mut builds) = (Vec::new(), Vec::new());
        for _ in 0..20 {
            let start = Instant::now();
            edit_texture(&mut edits);
            let batch = daemon.batch();
            latencies.push(start.elapsed().as_secs_f64() * 1e3);
            builds.push(batch["ms"].as_f64().unwrap_or(0.0));
        }
        let daemon_peak_mib = peak_memory_kib(&format!("/proc/{}/status", daemon.child.id())) as f64 / 1024.0;
        drop(daemon);
        let figures = ScaleFigures {
            assets,
            cold,
            cold_peak_mib,
            first_no_op,
            no_op,
            edit,
            graph,
            check,
            ready,
            daemon_edit: median_and_worst(latencies),
            daemon_build: median_and_worst(builds),
            daemon_peak_mib,
        };
        println!(
            "scale: {assets} assets (written in {written:.1} s): cold {:.1} s ({:.1} ms/asset, peak {:.0} MiB = {:.0} KiB/asset); \
             no-op {:.2} s (first, racy sources re-hashed: {:.2} s); one-texture edit {:.2} s; graph {:.2} s; check {:.2} s",
            figures.cold,
            figures.cold * 1e3 / assets as f64,
            figures.cold_peak_mib,
            figures.cold_peak_mib * 1024.0 / assets as f64,
            figures.no_op,
            figures.first_no_op,
            figures.edit,
            figures.graph,
            figures.check
        );
        println!(
            "scale: {assets} assets, daemon: ready {:.2} s; 64² texture edit → batch event median {:.0} ms, worst {:.0} ms \
             (its build: median {:.0} ms, worst {:.0} ms); daemon peak {:.0} MiB",
            figures.ready,
            figures.daemon_edit.0,
            figures.daemon_edit.1,
            figures.daemon_build.0,
            figures.daemon_build.1,
            figures.daemon_peak_mib
        );
        all.push(figures);
    }
    if let (Some(small), Some(large)) =
        (all.iter().find(|f| f.assets == 1_000), all.iter().find(|f| f.assets == 10_000))
    {
        println!(
            "scale: bars at 10,000 assets: no-op {:.2} s (≤ 1 s), edit {:.2} s (≤ 1.5 s), daemon edit-to-batch median {:.0} ms \
             (≤ 150 ms), graph {:.2} s (≤ 2 s); 1,000 → 10,000: no-op ×{:.1}, edit ×{:.1} (≤ 12), cold per asset \
             {:.1} → {:.1} ms (not growing)",
            large.no_op,
            large.edit,
            large.daemon_edit.0,
            large.graph,
            large.no_op / small.no_op,
            large.edit / small.edit,
            small.cold * 1e3 / small.assets as f64,
            large.cold * 1e3 / large.assets as f64
        );
    }
}

/// The page packer on 1,000 textures of mixed sizes (1 to 512 texels a side, mostly small, any
/// aspect): median time of a pack with the atlas defaults, and occupancy beside Python
/// `rectpack`'s best variant on the same sizes (rounded up to whole blocks, no padding, rotation
/// on) when a `python3` that imports `rectpack` is on the PATH or named by `CIRRUS_BENCH_PYTHON`.
fn bench_packing(repository: &Path) {
    use cirrus::packing::max_rects::{pack_pages, PageSettings};
    let mut state = 0x5eed_u64;
    let mut next = move || {
        state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (state >> 33) as u32
    };
    let sizes: Vec<(u32, u32)> = (0..1000)
        .map(|_| {
            let scale = 1u32 << (next() % 9);
            (1 + next() % (2 * scale).min(512), 1 + next() % (2 * scale).min(512))
        })
        .collect();
    let settings = PageSettings { max_size: 8192, padding: 4, rotate: true, power_of_two: false, pages: 1 };
    let mut times = Vec::new();
    let mut packing = None;
    for _ in 0..7 {
        let start = Instant::now();
        packing = Some(pack_pages(&sizes, &settings).expect("1,000 textures fit one 8192² page"));
        times.push(start.elapsed().as_secs_f64() * 1000.0);
    }
    times.sort_by(f64::total_cmp);
    let packing = packing.expect("packed");
    println!(
        "packing: 1,000 textures of mixed sizes, padding 4, rotation on: {:.1} ms median of 7 (bar ≤ 50 ms), {:?} page, content occupancy {:.3}",
        times[3],
        packing.pages[0],
        packing.occupancy()
    );
    // Beside rectpack: sizes in whole blocks, no padding.
    let blocks: Vec<(u32, u32)> = sizes.iter().map(|&(w, h)| (w.div_ceil(4) * 4, h.div_ceil(4) * 4)).collect();
    let bare = PageSettings { padding: 0, ..settings };
    let start = Instant::now();
    let ours = pack_pages(&blocks, &bare).expect("fits");
    let ours_ms = start.elapsed().as_secs_f64() * 1000.0;
    let python = std::env::var("CIRRUS_BENCH_PYTHON").unwrap_or_else(|_| "python3".to_string());
    let script = repository.join("benches/rectpack_occupancy.py");
    let child = std::process::Command::new(&python)
        .arg(&script)
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn();
    let rectpack = child.ok().and_then(|mut child| {
        use std::io::Write;
        let json = serde_json::to_string(&blocks.iter().map(|&(w, h)| [w, h]).collect::<Vec<_>>()).expect("sizes");
        child.stdin.take().expect("stdin").write_all(json.as_bytes()).ok()?;
        let output = child.wait_with_output().ok()?;
        output.status.success().then(|| serde_json::from_slice::<serde_json::Value>(&output.stdout).ok()).flatten()
    });
    let beside = match rectpack {
        Some(result) => format!(
            "rectpack's best {:.3} ({}, {:.0} s over every variant)",
            result["occupancy"].as_f64().unwrap_or(0.0),
            result["variant"].as_str().unwrap_or("?"),
            result["seconds"].as_f64().unwrap_or(0.0)
        ),
        None => format!("rectpack not measured: `{python}` cannot run {} (pip install rectpack)", script.display()),
    };
    println!(
        "packing: the same sizes in whole blocks, no padding: cirrus {:.3} on {:?} ({ours_ms:.1} ms) beside {beside}",
        ours.occupancy(),
        ours.pages[0]
    );
}

/// A running `cirrus watch` on a project folder, and a client subscribed to it.
struct WatchedDaemon {
    child: std::process::Child,
    reader: std::io::BufReader<std::net::TcpStream>,
}

impl WatchedDaemon {
    const DEBOUNCE_MS: u64 = 50;

    fn start(folder: &Path) -> WatchedDaemon {
        WatchedDaemon::start_with(folder, &[])
    }

    /// A daemon with more arguments (`--memory-mib 1024`).
    fn start_with(folder: &Path, more: &[String]) -> WatchedDaemon {
        use std::io::{BufRead, Write};
        let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_cirrus"))
            .args(["watch", "--listen", "127.0.0.1:0", "--debounce-ms", &WatchedDaemon::DEBOUNCE_MS.to_string()])
            .args(more)
            .current_dir(folder)
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .expect("start cirrus watch");
        let mut stderr = std::io::BufReader::new(child.stderr.take().expect("stderr"));
        let mut line = String::new();
        let address = loop {
            line.clear();
            assert!(stderr.read_line(&mut line).expect("daemon output") > 0, "daemon exited");
            if let Some(address) = line.trim().strip_prefix("cirrus watch: hot-reload server on ") {
                break address.to_string();
            }
        };
        std::thread::spawn(move || std::io::copy(&mut stderr, &mut std::io::sink()));
        let mut stream = std::net::TcpStream::connect(address).expect("connect");
        stream.write_all(b"{\"type\":\"subscribe\",\"since\":0}\n").unwrap();
        WatchedDaemon { child, reader: std::io::BufReader::new(stream) }
    }

    fn batch(&mut self) -> serde_json::Value {
        use std::io::BufRead;
        loop {
            let mut line = String::new();
            assert!(self.reader.read_line(&mut line).expect("daemon message") > 0, "daemon closed the connection");
            let message: serde_json::Value = serde_json::from_str(&line).expect("JSON");
            if message["type"] == "batch" {
                return message;
            }
        }
    }
}

impl Drop for WatchedDaemon {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// The daemon: write-to-event latency of edits on the oak next to its full bake, a 300-file
/// burst, and a warm restart.
fn bench_watch(corpus: &Path) {
    let dir = tree_project(
        corpus,
        r#"BillboardCloud(name: "oak", mesh: "trees/oak_medium.obj"), Material(name: "bark", material: "materials/bark.mymaterial")"#,
    );
    let materials = dir.path().join("assets/materials");
    std::fs::create_dir_all(&materials).unwrap();
    std::fs::write(
        materials.join("bark.mymaterial"),
        "Material $bark {\n  Texture (attrib = \"diffuse\") {string {\"../trees/textures/oak_color_1k.jpg\"}}\n  Texture (attrib = \"normal\") {string {\"../trees/textures/oak_normal_1k.jpg\"}}\n  Param (attrib = \"roughness\") {float {0.7}}\n}\n",
    )
    .unwrap();
    let start = Instant::now();
    let mut daemon = WatchedDaemon::start(dir.path());
    let first = daemon.batch();
    let full = start.elapsed().as_secs_f64();
    println!(
        "watch: debounce window {} ms; first build (oak + bark material, cold) {:.2} s, daemon says {:.0} ms",
        WatchedDaemon::DEBOUNCE_MS,
        full,
        first["ms"].as_f64().unwrap()
    );

    let bark = dir.path().join("assets/trees/textures/oak_color_1k.jpg");
    let mut image = image::open(&bark).unwrap().into_rgb8();
    let mut latencies = Vec::new();
    for round in 0..3u8 {
        image.get_pixel_mut(10, 10).0 = [255, round * 40, 0];
        let mut bytes = Vec::new();
        image::DynamicImage::ImageRgb8(image.clone())
            .write_to(&mut std::io::Cursor::new(&mut bytes), image::ImageFormat::Jpeg)
            .unwrap();
        let start = Instant::now();
        std::fs::write(&bark, &bytes).unwrap();
        let batch = daemon.batch();
        latencies.push((
            start.elapsed().as_secs_f64() * 1e3,
            batch["ms"].as_f64().unwrap(),
            batch["changed"].as_array().unwrap().len(),
        ));
    }
    for (latency, build, changed) in &latencies {
        println!(
            "watch: oak bark-texture edit → batch event {latency:.0} ms (build {build:.0} ms, {changed} artifacts) vs full bake {:.0} ms",
            full * 1e3
        );
    }
    for (round, value) in ["0.5", "0.3", "0.9"].iter().enumerate() {
        let text = std::fs::read_to_string(materials.join("bark.mymaterial")).unwrap();
        let edited = text.replace(
            &text[text.find("{float {").unwrap()..text.find("}}\n}").unwrap() + 2],
            &format!("{{float {{{value}}}}}"),
        );
        let start = Instant::now();
        std::fs::write(materials.join("bark.mymaterial"), edited).unwrap();
        let batch = daemon.batch();
        println!(
            "watch: .mymaterial edit {round} → batch event {:.0} ms (build {:.0} ms, {} artifacts)",
            start.elapsed().as_secs_f64() * 1e3,
            batch["ms"].as_f64().unwrap(),
            batch["changed"].as_array().unwrap().len()
        );
    }
    let mtl = dir.path().join("assets/trees/oak_medium.mtl");
    let text = std::fs::read_to_string(&mtl).unwrap();
    let start = Instant::now();
    std::fs::write(&mtl, text.replacen("Kd ", "Kd 0.7 0.6 0.5 # was ", 1)).unwrap();
    let batch = daemon.batch();
    println!(
        "watch: oak MTL edit (the tree's material file) → batch event {:.0} ms (build {:.0} ms, {} artifacts)",
        start.elapsed().as_secs_f64() * 1e3,
        batch["ms"].as_f64().unwrap(),
        batch["changed"].as_array().unwrap().len()
    );
    drop(daemon);

    // Warm restart: a new daemon over the baked project and its persistent cache.
    let start = Instant::now();
    let mut daemon = WatchedDaemon::start(dir.path());
    let batch = daemon.batch();
    println!(
        "watch: warm restart to first batch {:.0} ms ({} artifacts changed) vs full bake {:.0} ms",
        start.elapsed().as_secs_f64() * 1e3,
        batch["changed"].as_array().unwrap().len(),
        full * 1e3
    );

    // A branch checkout: 300 new material files matching a rule.
    let burst_dir = tempfile::tempdir().unwrap();
    let assets = burst_dir.path().join("assets/burst");
    std::fs::create_dir_all(&assets).unwrap();
    std::fs::copy(corpus.join("trees/textures/oak_ao_1k.jpg"), burst_dir.path().join("assets/ao.jpg")).unwrap();
    std::fs::write(
        burst_dir.path().join("pipeline.ron"),
        r#"Pipeline(source: "assets", output: "baked", assets: [], rules: [(glob: "burst/*.mymaterial", kind: Material)])"#,
    )
    .unwrap();
    let mut daemon = WatchedDaemon::start(burst_dir.path());
    daemon.batch();
    let start = Instant::now();
    for index in 0..300 {
        std::fs::write(
            assets.join(format!("m{index:03}.mymaterial")),
            format!("Material $m {{ Texture (attrib = \"ao\") {{string {{\"../ao.jpg\"}}}} Param (attrib = \"roughness\") {{float {{{}}}}} }}\n", index as f32 / 300.0),
        )
        .unwrap();
    }
    let written = start.elapsed().as_secs_f64() * 1e3;
    let mut reports = std::collections::BTreeSet::new();
    let mut batches = 0;
    while reports.len() < 300 {
        let batch = daemon.batch();
        batches += 1;
        for changed in batch["changed"].as_array().unwrap() {
            let path = changed["path"].as_str().unwrap();
            if path.ends_with("/report.json") {
                reports.insert(path.to_string());
            }
        }
    }
    println!(
        "watch: 300-file burst (written in {written:.0} ms) → {batches} batches, all 300 assets baked in {:.0} ms, none missed",
        start.elapsed().as_secs_f64() * 1e3
    );
}

/// A writable copy of the corpus trees in a temporary project with `assets` (pipeline text).
fn tree_project(corpus: &Path, assets: &str) -> tempfile::TempDir {
    let dir = tempfile::tempdir().expect("temporary folder");
    let trees = dir.path().join("assets/trees");
    std::fs::create_dir_all(trees.join("textures")).unwrap();
    for entry in std::fs::read_dir(corpus.join("trees"))
        .unwrap()
        .chain(std::fs::read_dir(corpus.join("trees/textures")).unwrap())
        .flatten()
    {
        if entry.path().is_file() {
            let relative = entry.path().strip_prefix(corpus.join("trees")).unwrap().to_path_buf();
            std::fs::copy(entry.path(), trees.join(relative)).unwrap();
        }
    }
    std::fs::write(
        dir.path().join("pipeline.ron"),
        format!(r#"Pipeline(source: "assets", output: "baked", assets: [{assets}])"#),
    )
    .unwrap();
    dir
}

/// Runs `cirrus build --summary json` in `folder` as a child process: wall seconds, peak
/// resident memory in MiB, and the summary.
fn build_process(folder: &Path) -> (f64, f64, serde_json::Value) {
    build_process_in(folder, &[], &[])
}

/// `build_process` with extra arguments before `build` (`--isa avx2`) and environment variables.
fn build_process_in(
    folder: &Path,
    global_arguments: &[&str],
    environment: &[(&str, String)],
) -> (f64, f64, serde_json::Value) {
    build_process_of(Path::new(env!("CARGO_BIN_EXE_cirrus")), folder, global_arguments, environment)
}

/// `binary build --summary json` in `folder`: wall seconds, peak memory (MiB), the summary.
fn build_process_of(
    binary: &Path,
    folder: &Path,
    global_arguments: &[&str],
    environment: &[(&str, String)],
) -> (f64, f64, serde_json::Value) {
    let start = Instant::now();
    let mut child = std::process::Command::new(binary)
        .args(global_arguments)
        .envs(environment.iter().map(|(name, value)| (name, value)))
        .args(["build", "--summary", "json"])
        .current_dir(folder)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .expect("run cirrus");
    let status_file = format!("/proc/{}/status", child.id());
    let mut stdout = child.stdout.take().expect("stdout");
    let reader = std::thread::spawn(move || {
        let mut bytes = Vec::new();
        std::io::Read::read_to_end(&mut stdout, &mut bytes).expect("summary");
        bytes
    });
    let mut peak_kib = 0u64;
    while child.try_wait().expect("child").is_none() {
        if let Ok(status) = std::fs::read_to_string(&status_file) {
            if let Some(line) = status.lines().find(|line| line.starts_with("VmHWM:")) {
                peak_kib = peak_kib.max(line.split_whitespace().nth(1).and_then(|kib| kib.parse().ok()).unwrap_or(0));
            }
        }
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    let seconds = start.elapsed().as_secs_f64();
    let summary = serde_json::from_slice(&reader.join().expect("reader")).expect("summary JSON");
    (seconds, peak_kib as f64 / 1024.0, summary)
}

/// How many stage instances ran, per stage, in an asset's summary.
fn stages_that_ran(asset: &serde_json::Value) -> std::collections::BTreeMap<String, usize> {
    let mut ran = std::collections::BTreeMap::new();
    for stage in asset["stages"].as_array().expect("stages").iter().filter(|stage| stage["status"] == "ran") {
        *ran.entry(stage["stage"].as_str().expect("stage name").to_string()).or_default() += 1;
    }
    ran
}

/// Turns one texel of a texture file red-ish (`step` picks the shade), keeping its size.
fn edit_one_texel(path: &Path, step: u8) {
    let mut image = image::open(path).expect("texture").into_rgba8();
    image.get_pixel_mut(10, 10).0 = [255, step.wrapping_mul(50), 0, 255];
    image.save(path).expect("save texture");
}

/// A texture atlas of the corpus's PBR sets and the flight helmet's maps (48 files, 8 of 1024²
/// and the rest 512², the helmet's maps equal to the sets' and so aliases) onto 4096² pages:
/// the full bake and a one-texture edit, each as a separate process, then in process.
fn bench_atlas(corpus: &Path) {
    let dir = tempfile::tempdir().expect("temporary folder");
    for folder in ["pbr", "meshes/flight_helmet"] {
        for entry in walk_files(&corpus.join(folder)) {
            let relative = entry.strip_prefix(corpus).unwrap();
            if matches!(relative.extension().and_then(|e| e.to_str()), Some("png" | "jpg")) {
                let target = dir.path().join("assets").join(relative);
                std::fs::create_dir_all(target.parent().unwrap()).unwrap();
                std::fs::copy(&entry, target).unwrap();
            }
        }
    }
    std::fs::write(
        dir.path().join("pipeline.ron"),
        r#"Pipeline(source: "assets", output: "baked", assets: [
            Atlas(name: "props", textures: ["pbr/**/*.png", "pbr/**/*.jpg", "meshes/flight_helmet/*.png"], pack: (max_size: 4096)),
        ])"#,
    )
    .unwrap();
    let (full, peak, _) = build_process(dir.path());
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("baked/props/report.json")).unwrap()).unwrap();
    println!(
        "atlas: {} textures, {} entries → pages {} occupancy {}: full bake (process) {:.2} s, peak memory {:.0} MiB",
        report["textures"], report["entries"], report["pages"], report["occupancy"], full, peak
    );
    println!("atlas: full bake stage ms {}", report["stage_ms"]);
    // A 512² PNG on the largest page (the worst place for an edit: most neighbours), and no
    // alias's (an edit that splits an alias adds an entry, and so moves work elsewhere).
    let table: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("baked/props/atlas.json")).unwrap()).unwrap();
    let on_first_page = table["entries"]
        .as_array()
        .unwrap()
        .iter()
        .find(|entry| {
            let alone = entry["aliases"].as_array().is_some_and(|aliases| aliases.is_empty());
            entry["page"] == 0 && entry["width"] == 512 && alone && entry["name"].as_str().unwrap().ends_with(".png")
        })
        .expect("a 512² PNG on page 0 without aliases");
    let edited = dir.path().join("assets").join(on_first_page["name"].as_str().unwrap());
    let page_entries = table["entries"].as_array().unwrap().iter().filter(|entry| entry["page"] == 0).count();
    println!("atlas: editing {} (page 0 holds {page_entries} entries)", on_first_page["name"]);
    edit_one_texel(&edited, 0);
    let (edit, _, summary) = build_process(dir.path());
    println!(
        "atlas: one-texture edit as a separate process: {:.0} ms vs full bake {:.0} ms: {:.1} % (bar ≤ 10 %); stages that ran: {:?}",
        edit * 1e3,
        full * 1e3,
        100.0 * edit / full,
        stages_that_ran(&summary["assets"][0])
    );

    let mut project = Project::open(
        load_pipeline(&dir.path().join("pipeline.ron")).unwrap(),
        ProjectOptions { persistent_cache: false, ..Default::default() },
    );
    let start = Instant::now();
    project.build(&BuildOptions::default(), &|_| {}).unwrap();
    let full = start.elapsed().as_secs_f64();
    let mut edits = Vec::new();
    let mut ran = None;
    for step in 1..6u8 {
        edit_one_texel(&edited, step);
        let start = Instant::now();
        let built = project.build(&BuildOptions::default(), &|_| {}).unwrap();
        edits.push(start.elapsed().as_secs_f64());
        ran.get_or_insert_with(|| stages_that_ran(&serde_json::to_value(&built.assets[0]).expect("summary")));
    }
    let mut sorted = edits.clone();
    sorted.sort_by(f64::total_cmp);
    println!(
        "atlas: one-texture edit in process, median of 5: {:.0} ms vs full bake {:.0} ms: {:.1} % (bar ≤ 10 %); all {:?} ms; stages that ran first: {:?}",
        sorted[2] * 1e3,
        full * 1e3,
        100.0 * sorted[2] / full,
        edits.iter().map(|seconds| (seconds * 1e3).round() as u32).collect::<Vec<_>>(),
        ran.expect("five edits")
    );
}

/// Occlusion rays on the flight helmet (94,722 triangles): BVH build time, then 256 cosine rays
/// from the centroid of every 4th triangle along its normal, on every core, with rays passing
/// through back faces (nearest-hit queries) and with back faces blocking (any-hit queries):
/// rays per second per core.
fn bench_occlusion(corpus: &Path) {
    use cirrus::mesh::occlusion::{occlusion_at, OcclusionSettings, RayDistribution};
    use cirrus::mesh::rays::{build_triangle_bvh, BackFaces, TriangleBvh};
    let mesh = flight_helmet(corpus);
    let start = Instant::now();
    let best = build_triangle_bvh(&mesh.positions, &mesh.triangles);
    let build_ms = start.elapsed().as_secs_f64() * 1e3;
    let portable = build_triangle_bvh(&mesh.positions, &mesh.triangles).without_avx2();
    let points: Vec<(u32, glam::Vec3, glam::Vec3)> = (0..mesh.triangles.len() as u32)
        .step_by(4)
        .filter_map(|triangle| {
            let normal = glam::Vec3::from(best.geometric_normal(triangle));
            (normal != glam::Vec3::ZERO).then(|| {
                let corners =
                    mesh.triangles[triangle as usize].map(|vertex| glam::Vec3::from(mesh.positions[vertex as usize]));
                (triangle, (corners[0] + corners[1] + corners[2]) / 3.0, normal)
            })
        })
        .collect();
    let threads = rayon::current_num_threads() as f64;
    println!(
        "occlusion: flight helmet {} triangles, BVH built in {build_ms:.0} ms (obvhs PLOC, collapsed to 8-wide); {} triangle centroids × 256 rays on {threads} threads; kernels: {}",
        mesh.triangles.len(),
        points.len(),
        if cirrus::mesh::rays::avx2_available() { "AVX2 + FMA" } else { "portable (no AVX2 on this CPU)" }
    );
    for (label, bvh) in [("best kernels", &best), ("portable kernels", &portable)] {
        for (faces, back_faces) in
            [("back faces pass (the AO default)", BackFaces::PassThrough), ("back faces block", BackFaces::Block)]
        {
            let settings = OcclusionSettings {
                rays: 256,
                distribution: RayDistribution::Cosine,
                max_distance: f32::INFINITY,
                back_faces,
                ground_plane: None,
            };
            let bake = |bvh: &TriangleBvh| {
                points
                    .par_iter()
                    .map(|&(triangle, point, normal)| {
                        occlusion_at(bvh, point, normal, triangle, &settings, triangle).visibility as f64
                    })
                    .sum::<f64>()
            };
            let start = Instant::now();
            let visibility = bake(bvh);
            let seconds = start.elapsed().as_secs_f64();
            println!(
                "occlusion: {label}, {faces}: {:.2} M rays/s/core, mean visibility {:.3}",
                (points.len() * 256) as f64 / seconds / threads / 1e6,
                visibility / points.len() as f64
            );
        }
    }
}

/// The flight helmet (94,722 triangles, 6 materials) loaded with its MTL.
fn flight_helmet(corpus: &Path) -> cirrus::mesh::Mesh {
    let folder = corpus.join("meshes/flight_helmet");
    let obj = folder.join("FlightHelmet.obj");
    let bytes = std::fs::read(&obj).expect("flight helmet OBJ");
    let libraries = cirrus::mesh::material_libraries(&obj, &bytes, &folder)
        .into_iter()
        .map(|path| {
            let contents = std::fs::read(&path).ok();
            (path, contents)
        })
        .collect();
    cirrus::mesh::load_mesh(&obj, &bytes, &libraries, &folder).expect("flight helmet loads").0
}

/// The AmbientOcclusion kind on the flight helmet: a 1024², 256-ray bake of its six materials as
/// a separate process (wall time, peak memory, rays per second), the same in per-vertex mode,
/// then quality at equal rays on 128² maps (every object occluding every other): per texel, per
/// vertex (cirrus's mode), and per vertex the libigl way (one set of uniformly random directions
/// shared by every vertex, flipped into its hemisphere, unweighted), each against a 2,048-ray
/// per-texel bake of the same texels, as PSNR over the baked texels.
fn bench_ambient_occlusion(corpus: &Path) {
    for (mode, bar) in [("Texels", " (bar ≤ 60 s on 2 cores)"), ("Vertices", "")] {
        let dir = tempfile::tempdir().expect("temporary folder");
        let folder = dir.path().join("assets");
        std::fs::create_dir_all(&folder).unwrap();
        for file in ["FlightHelmet.obj", "FlightHelmet.mtl"] {
            std::fs::copy(corpus.join("meshes/flight_helmet").join(file), folder.join(file)).unwrap();
        }
        std::fs::write(
            dir.path().join("pipeline.ron"),
            format!(
                r#"Pipeline(source: "assets", output: "baked", assets: [
                    AmbientOcclusion(name: "helmet", mesh: "FlightHelmet.obj", ao: (size: 1024, rays: 256, mode: {mode})),
                ])"#
            ),
        )
        .unwrap();
        let (seconds, peak_mib, summary) = build_process(dir.path());
        assert_eq!(summary["assets"][0]["status"], "ok", "{summary}");
        let report: serde_json::Value =
            serde_json::from_slice(&std::fs::read(dir.path().join("baked/helmet/report.json")).unwrap()).unwrap();
        let materials = report["materials"].as_array().unwrap();
        let sum = |key: &str| materials.iter().map(|material| material[key].as_f64().unwrap_or(0.0)).sum::<f64>();
        // Rays per second of wall time (the tiles of two materials bake at once, each on every
        // core, so summed stage times would count the time twice); per vertex, of the
        // `vertices` stage.
        let bake_seconds =
            if mode == "Texels" { seconds } else { report["stage_ms"]["vertices"].as_f64().unwrap_or(0.0) / 1e3 };
        println!(
            "ao: flight helmet {mode}, 6 × 1024², 256 rays: {seconds:.1} s wall{bar}, peak memory {peak_mib:.0} MiB; {:.0} texels, {:.1} M rays ({:.2} M rays/s over {bake_seconds:.1} s, {:.2} M/s/core); stage ms {}",
            sum("texels_baked"),
            sum("rays_cast") / 1e6,
            sum("rays_cast") / bake_seconds.max(1e-9) / 1e6,
            sum("rays_cast") / bake_seconds.max(1e-9) / 1e6 / rayon::current_num_threads() as f64,
            report["stage_ms"]
        );
    }

    use cirrus::kinds::ambient_occlusion::bake::{
        bake_tile_from_vertices, bake_tile_with_rays, BakeMesh, TexelState, TileBake,
    };
    use cirrus::mesh::occlusion::{
        build_occluders, occlusion_of_vertices, Casting, OcclusionSettings, RayDistribution,
    };
    use cirrus::mesh::rays::{build_triangle_bvh, BackFaces};
    use cirrus::mesh::uv_raster::TexelRegion;
    let mesh = flight_helmet(corpus);
    let uvs = mesh.uvs.clone().expect("the helmet has UVs");
    let bake_mesh = BakeMesh {
        positions: &mesh.positions,
        normals: &mesh.normals,
        uvs: &uvs,
        triangles: &mesh.triangles,
        groups: None,
    };
    let occluders = build_occluders(&mesh.positions, &mesh.triangles, None);
    let bvh = build_triangle_bvh(&mesh.positions, &mesh.triangles);
    let settings = |rays| OcclusionSettings {
        rays,
        distribution: RayDistribution::Cosine,
        max_distance: f32::INFINITY,
        back_faces: BackFaces::PassThrough,
        ground_plane: None,
    };
    let (low, high) =
        mesh.positions.iter().fold((glam::Vec3::INFINITY, glam::Vec3::NEG_INFINITY), |(low, high), &position| {
            (low.min(position.into()), high.max(position.into()))
        });
    let offset = (high - low).length() * 1e-4;
    let size = 128;
    let region = TexelRegion { x: 0, y: 0, width: size, height: size };
    let materials: Vec<Vec<u32>> = (0..mesh.materials.len() as u32)
        .map(|material| {
            (0..mesh.triangles.len() as u32)
                .filter(|&triangle| mesh.triangle_materials[triangle as usize] == material)
                .collect()
        })
        .filter(|triangles: &Vec<u32>| !triangles.is_empty())
        .collect();
    let texel_bake = |rays| -> (Vec<TileBake>, f64) {
        let start = Instant::now();
        let tiles = materials
            .iter()
            .map(|own| {
                bake_tile_with_rays(&occluders, &bake_mesh, own, size, region, &settings(rays), &cirrus::stop::never)
                    .unwrap()
            })
            .collect();
        (tiles, start.elapsed().as_secs_f64())
    };
    let vertex_maps = |visibility: &[f32]| -> Vec<TileBake> {
        materials.iter().map(|own| bake_tile_from_vertices(&bake_mesh, own, size, region, visibility)).collect()
    };
    let (reference, reference_seconds) = texel_bake(2048);
    let psnr = |tiles: &[TileBake]| {
        let (mut squared, mut count) = (0.0f64, 0u64);
        for (tile, reference) in tiles.iter().zip(&reference) {
            for texel in 0..reference.values.len() {
                if reference.states[texel] == TexelState::Baked as u8 && tile.states[texel] != TexelState::Empty as u8 {
                    squared += ((tile.values[texel] as f64 - reference.values[texel] as f64) / 65535.0).powi(2);
                    count += 1;
                }
            }
        }
        10.0 * (1.0 / (squared / count as f64).max(1e-12)).log10()
    };
    let (texels, texel_seconds) = texel_bake(256);
    let start = Instant::now();
    let visibility: Vec<f32> = occlusion_of_vertices(
        &occluders,
        &mesh.positions,
        &mesh.normals,
        &mesh.triangles,
        offset,
        Casting { settings: &settings(256), should_stop: &cirrus::stop::never },
    )
    .unwrap()
    .into_iter()
    .map(|occlusion| occlusion.map_or(1.0, |occlusion| occlusion.visibility))
    .collect();
    let vertices = vertex_maps(&visibility);
    let vertex_seconds = start.elapsed().as_secs_f64();
    // libigl's `ambient_occlusion`: the same random directions for every point, flipped into its
    // hemisphere, every hit counted (both faces), unweighted.
    let start = Instant::now();
    let mut state = 0x1234_5678_u64;
    let mut random = move || {
        state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let directions: Vec<glam::Vec3> = (0..256)
        .map(|_| {
            let (z, phi) = (2.0 * random() - 1.0, std::f64::consts::TAU * random());
            let radius = (1.0 - z * z).max(0.0).sqrt();
            glam::Vec3::new((radius * phi.cos()) as f32, (radius * phi.sin()) as f32, z as f32)
        })
        .collect();
    let libigl: Vec<f32> = (0..mesh.positions.len())
        .into_par_iter()
        .map(|vertex| {
            let normal = glam::Vec3::from(mesh.normals[vertex]).normalize_or_zero();
            let origin = glam::Vec3::from(mesh.positions[vertex]) + normal * offset;
            let hits = directions
                .iter()
                .filter(|&&direction| {
                    let direction = if direction.dot(normal) < 0.0 { -direction } else { direction };
                    bvh.blocked(origin, direction, f32::INFINITY, u32::MAX, BackFaces::Block)
                })
                .count();
            1.0 - hits as f32 / directions.len() as f32
        })
        .collect();
    let libigl_maps = vertex_maps(&libigl);
    let libigl_seconds = start.elapsed().as_secs_f64();
    println!(
        "ao: quality at 256 rays on the helmet's 6 × 128² maps against a 2,048-ray per-texel bake ({reference_seconds:.1} s): per texel {:.1} dB in {texel_seconds:.2} s; per vertex (cirrus, R2 cosine) {:.1} dB in {vertex_seconds:.2} s; per vertex libigl-style (shared uniform random directions) {:.1} dB in {libigl_seconds:.2} s",
        psnr(&texels),
        psnr(&vertices),
        psnr(&libigl_maps)
    );
}

/// Every file under a folder, recursively, sorted.
fn walk_files(folder: &Path) -> Vec<std::path::PathBuf> {
    let mut files = Vec::new();
    let mut pending = vec![folder.to_path_buf()];
    while let Some(folder) = pending.pop() {
        for entry in std::fs::read_dir(&folder).expect("corpus folder").flatten() {
            let path = entry.path();
            if path.is_dir() {
                pending.push(path);
            } else {
                files.push(path);
            }
        }
    }
    files.sort();
    files
}

/// Billboard clouds: the oak's full bake (child process: wall time, peak memory, stage
/// breakdown), a bark-texture edit next to it, and plane count and IoU per tree and ε.
fn bench_billboards(corpus: &Path) {
    let dir = tree_project(corpus, r#"BillboardCloud(name: "oak", mesh: "trees/oak_medium.obj")"#);
    let (full, peak_mib, _) = build_process(dir.path());
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("baked/oak/report.json")).unwrap()).unwrap();
    println!(
        "billboard: oak_medium full bake (process) {:.2} s wall (bar ≤ 5 s), peak memory {:.0} MiB (bar ≤ 1536), {} planes → atlas {}x{}",
        full, peak_mib, report["planes"], report["atlas"]["width"], report["atlas"]["height"]
    );
    println!("billboard: oak stage ms {}", report["stage_ms"]);

    // The same bark edit as a separate process after that full bake (a batch build, CI, a
    // restarted daemon): only the persistent cache carries over.
    let bark = dir.path().join("assets/trees/textures/oak_color_1k.jpg");
    let mut image = image::open(&bark).unwrap().into_rgb8();
    image.get_pixel_mut(10, 10).0 = [255, 0, 0];
    image.save(&bark).unwrap();
    let (edit, _, summary) = build_process(dir.path());
    let ran = stages_that_ran(&summary["assets"][0]);
    println!(
        "billboard: oak bark-texture edit as a separate process: {:.0} ms vs full bake {:.0} ms: {:.1} % (bar ≤ 25 %); stages that ran: {ran:?}",
        edit * 1e3,
        full * 1e3,
        100.0 * edit / full
    );

    // Bark-texture edits, in process, after a full bake: five in a row (a different texel
    // each time), so the figure is what an artist saving repeatedly sees, first edit included.
    let dir = tree_project(corpus, r#"BillboardCloud(name: "oak", mesh: "trees/oak_medium.obj")"#);
    let mut project = Project::open(
        load_pipeline(&dir.path().join("pipeline.ron")).unwrap(),
        ProjectOptions { persistent_cache: false, ..Default::default() },
    );
    let start = Instant::now();
    project.build(&BuildOptions::default(), &|_| {}).unwrap();
    let full = start.elapsed().as_secs_f64();
    let bark = dir.path().join("assets/trees/textures/oak_color_1k.jpg");
    let mut edits = Vec::new();
    let mut summary = None;
    for edit in 0..5u8 {
        let mut image = image::open(&bark).unwrap().into_rgb8();
        image.get_pixel_mut(10, 10).0 = [255, edit * 50, 0];
        image.save(&bark).unwrap();
        let start = Instant::now();
        let built = project.build(&BuildOptions::default(), &|_| {}).unwrap();
        edits.push(start.elapsed().as_secs_f64());
        summary.get_or_insert(built);
    }
    let summary = summary.expect("five edits");
    let first = edits[0];
    let mut sorted = edits.clone();
    sorted.sort_by(f64::total_cmp);
    let edit = sorted[sorted.len() / 2];
    let renders = summary.assets[0]
        .stages
        .iter()
        .filter(|stage| stage.stage == "render" && stage.status == cirrus::summary::StageStatus::Ran)
        .count();
    println!(
        "billboard: oak bark-texture edit, median of 5: {:.0} ms vs full bake {:.0} ms in process: {:.1} % (bar ≤ 20 %); first edit {:.0} ms ({:.1} %); all {:?} ms; {renders} of {} render stages (planes × material sets) re-ran",
        edit * 1e3,
        full * 1e3,
        100.0 * edit / full,
        first * 1e3,
        100.0 * first / full,
        edits.iter().map(|seconds| (seconds * 1e3).round() as u32).collect::<Vec<_>>(),
        summary.assets[0].stages.iter().filter(|stage| stage.stage == "render").count()
    );
    let mut edit_ms = std::collections::BTreeMap::<&str, f64>::new();
    for stage in summary.assets[0].stages.iter().filter(|stage| stage.status == cirrus::summary::StageStatus::Ran) {
        *edit_ms.entry(stage.stage.as_str()).or_default() += stage.ms;
    }
    let edit_ms: Vec<String> = edit_ms.iter().map(|(stage, ms)| format!("{stage} {ms:.0}")).collect();
    println!("billboard: first bark edit stage ms (summed over threads): {}", edit_ms.join(", "));
}

/// Plane counts and mean silhouette IoU of each corpus tree at three ε: with 16 samples per pixel
/// (the preview default), and with one (aliased: the figure reported before the default changed).
fn bench_billboard_quality(corpus: &Path) {
    for tree in ["oak_medium", "ash_small", "bush_2"] {
        let mut figures = Vec::new();
        for epsilon in [0.01, 0.02, 0.04] {
            let (dir, mut project, options) = tree_preview(corpus, tree, &format!("epsilon: {epsilon}"));
            let metrics = preview_one_level(&mut project, &options);
            let one_sample = cirrus::preview::PreviewSettings { samples_per_axis: 1, ..Default::default() };
            let aliased =
                preview_one_level(&mut project, &cirrus::kinds::PreviewOptions { settings: one_sample, ..options });
            let report: serde_json::Value =
                serde_json::from_slice(&std::fs::read(dir.path().join("baked/tree/report.json")).unwrap()).unwrap();
            figures.push(format!(
                "ε {epsilon}: {} planes, mean IoU {:.3} (1 sample per pixel: {:.3})",
                report["planes"], metrics.mean_iou, aliased.mean_iou
            ));
        }
        println!("billboard: {tree}: {}", figures.join("; "));
    }
}

/// A corpus tree as a BillboardCloud with `billboard` settings (the text inside `billboard:
/// (…)`), opened without the persistent cache, and the options of its preview.
fn tree_preview(
    corpus: &Path,
    tree: &str,
    billboard: &str,
) -> (tempfile::TempDir, Project, cirrus::kinds::PreviewOptions) {
    let dir = tree_project(
        corpus,
        &format!(r#"BillboardCloud(name: "tree", mesh: "trees/{tree}.obj", billboard: ({billboard}))"#),
    );
    let project = Project::open(
        load_pipeline(&dir.path().join("pipeline.ron")).unwrap(),
        ProjectOptions { persistent_cache: false, ..Default::default() },
    );
    let options = cirrus::kinds::PreviewOptions {
        asset: "tree".into(),
        settings: Default::default(),
        out: "preview".into(),
        lod: None,
        stand_in: Default::default(),
    };
    (dir, project, options)
}

/// The preview metrics of an asset with one LOD.
fn preview_one_level(
    project: &mut Project,
    options: &cirrus::kinds::PreviewOptions,
) -> cirrus::preview::PreviewMetrics {
    let mut levels = {
        let input = project.built_asset(&options.asset).expect("the asset builds");
        cirrus::kinds::billboard_cloud::preview_levels(project.database(), input, project.config(), options)
    }
    .expect("preview");
    assert_eq!(levels.len(), 1, "one level");
    levels.remove(0).1
}

/// Mean silhouette IoU (16 samples per pixel) of each corpus tree's LOD at 32 to 512 quads: with
/// `budget: Some(Quads(n))`, and beside it what ε alone gives within the same count (the
/// smallest ε, found by bisection, whose cloud has at most n quads: what a user raising ε
/// until the LOD fits would get); plane-selection time of the budget's search. Each loss also in
/// units of the source's 1-pixel-shift loss, and beside the budget's LOD the source's faces
/// moved onto its planes (`StandIn`): projected (the cloud's geometry with exact textures) and
/// translated (displacement alone), the ceiling no texture work can pass.
fn bench_billboard_budget(corpus: &Path) {
    use cirrus::kinds::billboard_cloud::lod_preview::StandIn;
    use cirrus::kinds::billboard_cloud::planes::{select_planes, PlaneSettings};
    use cirrus::kinds::billboard_cloud::rectangles::plane_rectangles;
    use cirrus::kinds::PreviewOptions;
    for tree in ["oak_medium", "ash_small", "bush_2"] {
        let obj = std::fs::read(corpus.join(format!("trees/{tree}.obj"))).unwrap();
        let (mesh, _) =
            cirrus::mesh::load_mesh(Path::new("tree.obj"), &obj, &Default::default(), Path::new("")).unwrap();
        let quads_at = |epsilon: f32| {
            let planes = select_planes(
                &mesh.positions,
                &mesh.triangles,
                &mesh.triangle_materials,
                PlaneSettings { epsilon, max_planes: None, max_quads: None },
            );
            plane_rectangles(&mesh.positions, &mesh.triangles, &planes).len()
        };
        let mut figures = Vec::new();
        let mut source_shift_iou = 0.0;
        for quads in [32usize, 64, 128, 256, 512] {
            // The smallest ε whose cloud fits, by bisection on log ε.
            let (mut low, mut high) = (0.002f32.ln(), 0.5f32.ln());
            for _ in 0..9 {
                let middle = 0.5 * (low + high);
                if quads_at(middle.exp()) <= quads {
                    high = middle;
                } else {
                    low = middle;
                }
            }
            let epsilon_alone = high.exp();
            let mut row = format!("{quads} quads:");
            for (label, settings) in
                [("budget", format!("budget: Some(Quads({quads}))")), ("ε alone", format!("epsilon: {epsilon_alone}"))]
            {
                let (dir, mut project, options) = tree_preview(corpus, tree, &settings);
                let metrics = preview_one_level(&mut project, &options);
                let report: serde_json::Value =
                    serde_json::from_slice(&std::fs::read(dir.path().join("baked/tree/report.json")).unwrap()).unwrap();
                // The mean error in preview pixels: the views frame the bounding sphere (2R) in
                // their 256 pixels.
                let mean_error_radii = report["mean_error_world"].as_f64().unwrap_or(0.0)
                    / report["epsilon_world"].as_f64().unwrap_or(1.0)
                    * report["epsilon"].as_f64().unwrap_or(0.0);
                row.push_str(&format!(
                    " {label} IoU {:.3} (missed {:.3}, extra {:.3}; {} quads, {} planes, ε {:.4}, mean error {:.4} R = {:.2} px, planes stage {:.0} ms)",
                    metrics.mean_iou,
                    metrics.mean_missed,
                    metrics.mean_extra,
                    report["quads"],
                    report["planes"],
                    report["epsilon"].as_f64().unwrap_or(0.0),
                    mean_error_radii,
                    mean_error_radii * 128.0,
                    report["stage_ms"]["planes"].as_f64().unwrap_or(0.0)
                ));
                source_shift_iou = metrics.source_shift_iou;
                // What the planes alone allow: the source's own faces moved onto them, with their
                // own textures; and the loss in units of what a 1-pixel shift of the source costs,
                // which is how meshes of different lacework compare.
                let in_shifts = |iou: f64| (1.0 - iou) / (1.0 - source_shift_iou).max(1e-9);
                row.push_str(&format!(" loss {:.2} px-shifts", in_shifts(metrics.mean_iou)));
                if label == "budget" {
                    for stand_in in [StandIn::Projected, StandIn::Translated] {
                        let stood_in = preview_one_level(&mut project, &PreviewOptions { stand_in, ..options.clone() });
                        row.push_str(&format!(
                            ", faces {} onto its planes IoU {:.3} ({:.2} px-shifts)",
                            stand_in.name(),
                            stood_in.mean_iou,
                            in_shifts(stood_in.mean_iou)
                        ));
                    }
                }
                row.push(';');
            }
            figures.push(row);
        }
        println!(
            "billboard-budget: {tree} (the source against itself moved 1 pixel: IoU {source_shift_iou:.3}): {}",
            figures.join(" ")
        );
    }
}

/// How many times the chain-that-chooses bench bakes the default search's chain and the single
/// default bake for its bar (medians).
const AUTO_BAR_RUNS: usize = 3;

/// Chains that choose (issue 40): per tree (the corpus oak, ash and bush, and the bundled bush)
/// a four-level chain `Auto(2 MiB), Auto(512 KiB), Auto(128 KiB), Auto(32 KiB)` baked as a
/// process beside one default bake (bar ≤ 3×, medians of [`AUTO_BAR_RUNS`] runs), with its
/// picks and switch sizes; then every candidate of the first three levels (the budgets) beside
/// the source over the 26 views at 64, 256 and 1024 px (16, 4 and 1 samples a pixel;
/// `CIRRUS_BENCH_AUTO_1024_SAMPLES=4` measures 1024 px at 16 too): loss in px-shift units and
/// PSNR, the pick starred, a candidate over its bytes marked. Bars: the pick within 0.005 IoU of
/// the best candidate; at 64 px and 128 KiB the pick holds (≤ 1 px-shift unit).
fn bench_billboard_auto(repository: &Path, corpus: &Path) {
    const BUDGETS: [(&str, u64); 4] =
        [("2 MiB", 2 << 20), ("512 KiB", 512 << 10), ("128 KiB", 128 << 10), ("32 KiB", 32 << 10)];
    // 1024 px at one sample a pixel unless `CIRRUS_BENCH_AUTO_1024_SAMPLES` (per axis) asks for
    // more: at 4 (16 a pixel, 4096² renders) llvmpipe takes 7–9 min a tree.
    let samples_1024 = std::env::var("CIRRUS_BENCH_AUTO_1024_SAMPLES").ok().and_then(|samples| samples.parse().ok());
    let sizes: [(u32, u32); 3] = [(64, 4), (256, 2), (1024, samples_1024.unwrap_or(1).clamp(1, 4))];
    println!("billboard-auto: CPU ISA {}, GPU {}", cirrus::isa::detected_isa().name(), cirrus::gpu::adapter_family());
    let bundled = repository.join("examples/assets");
    let trees = [("corpus", corpus, "oak_medium"), ("corpus", corpus, "ash_small"), ("corpus", corpus, "bush_2")];
    for (label, source, tree) in trees.into_iter().chain([("bundled", bundled.as_path(), "bush_2")]) {
        let single = tree_project(source, &format!(r#"BillboardCloud(name: "tree", mesh: "trees/{tree}.obj")"#));
        let lods: Vec<String> = BUDGETS.iter().map(|(_, bytes)| format!("Auto(max_bytes: {bytes})")).collect();
        // The default search (64 quads, 8 × 8 frames, the reduced triangles), then the wide one.
        let mut chains = Vec::new();
        let mut single_seconds = 0.0;
        for (search, auto) in [("default", ""), ("wide", ", auto: (quads: [16, 64, 256], impostor_frames: [8, 12])")] {
            let chain = tree_project(
                source,
                &format!(
                    r#"BillboardCloud(name: "tree", mesh: "trees/{tree}.obj", billboard: (lods: [{}]{auto}))"#,
                    lods.join(", ")
                ),
            );
            // The bar's two bakes, each from scratch, taken in turns: the median of three runs
            // each (this machine's runs of one build differ by ±10 %, the bar's margin).
            let runs = if search == "default" { AUTO_BAR_RUNS } else { 1 };
            let (mut single_runs, mut chain_runs, mut chain_mib) = (Vec::new(), Vec::new(), 0.0f64);
            for _ in 0..runs {
                if search == "default" {
                    let _ = std::fs::remove_dir_all(single.path().join("baked"));
                    single_runs.push(build_process(single.path()).0);
                }
                let _ = std::fs::remove_dir_all(chain.path().join("baked"));
                let (seconds, mib, _) = build_process(chain.path());
                chain_runs.push(seconds);
                chain_mib = chain_mib.max(mib);
            }
            if !single_runs.is_empty() {
                let runs: Vec<String> = chain_runs
                    .iter()
                    .zip(&single_runs)
                    .map(|(chain, single)| format!("{chain:.2}/{single:.2} s"))
                    .collect();
                println!("billboard-auto: {label} {tree}: chain/default bake, run by run: {}", runs.join(", "));
                single_seconds = median_and_worst(single_runs).0;
            }
            let chain_seconds = median_and_worst(chain_runs).0;
            let report: serde_json::Value =
                serde_json::from_slice(&std::fs::read(chain.path().join("baked/tree/report.json")).unwrap()).unwrap();
            let levels = report["levels"].as_array().expect("levels").clone();
            let picks: Vec<String> =
                levels.iter().map(|level| level["auto"]["chosen"].as_str().unwrap_or("-").to_string()).collect();
            let switch: Vec<u64> = levels.iter().map(|level| level["switch_size"].as_u64().unwrap_or(0)).collect();
            println!(
                "billboard-auto: {label} {tree}: four Auto levels, {search} search, {chain_seconds:.2} s ({}; \
                 {chain_mib:.0} MiB, switch stage {:.1} s of work) vs one default bake {single_seconds:.2} s \
                 (median of {AUTO_BAR_RUNS}): {:.2}× (bar ≤ 3×); \
                 picks {picks:?}, switch sizes {switch:?} px",
                if runs == 1 { "one run".to_string() } else { format!("median of {runs}") },
                report["stage_ms"]["switch"].as_f64().unwrap_or(0.0) / 1e3,
                chain_seconds / single_seconds
            );
            chains.push((chain, levels, picks));
        }
        // Every candidate of the wide search measured; the default search's picks starred, the
        // wide one's marked + where they differ, each judged against the best of all.
        let (chain, levels, wide_picks) = chains.pop().expect("the wide search");
        let (_, default_levels, picks) = chains.pop().expect("the default search");
        // How far up the screen sizes each of the default chain's levels is shown: a pick is
        // made once for every size, so at a size its level is never shown it may rank below
        // another candidate.
        let shown_to: Vec<u64> =
            default_levels.iter().map(|level| level["switch_size"].as_u64().unwrap_or(0)).collect();
        let mut project = Project::open(load_pipeline(&chain.path().join("pipeline.ron")).unwrap(), Default::default());
        let input = project.built_asset("tree").expect("the chain builds");
        for (size, samples_per_axis) in sizes {
            let settings = cirrus::preview::PreviewSettings { views: 26, size, samples_per_axis };
            let start = Instant::now();
            let slots =
                cirrus::kinds::billboard_cloud::preview_slots(project.database(), input, project.config(), settings)
                    .expect("preview");
            let seconds = start.elapsed().as_secs_f64();
            for (level, (budget, bytes)) in BUDGETS.iter().enumerate().take(3) {
                let entry = |name: &str| {
                    let candidates = levels[level]["auto"]["candidates"].as_array().cloned().unwrap_or_default();
                    candidates.into_iter().find(|candidate| candidate["name"] == name).unwrap_or_default()
                };
                let mut row = Vec::new();
                let (mut best, mut picked) = (0.0f64, None);
                for (_, folder, metrics) in slots.iter().filter(|(slot_level, _, _)| *slot_level == level as u32) {
                    let name = folder.rsplit('/').next().unwrap_or(folder);
                    let over = entry(name)["gpu_bytes"].as_u64().unwrap_or(0) > *bytes;
                    let loss = metrics.loss_px_shift.unwrap_or(0.0);
                    let mark = if over {
                        " (over)"
                    } else if name == picks[level] {
                        "*"
                    } else if name == wide_picks[level] {
                        "+"
                    } else {
                        ""
                    };
                    row.push(format!("{name}{mark} {loss:.2} u/{:.1} dB", metrics.mean_psnr));
                    if !over {
                        best = best.max(metrics.mean_iou);
                    }
                    if name == picks[level] {
                        picked = Some((metrics.mean_iou, loss));
                    }
                }
                let verdict = match picked {
                    Some((iou, loss)) => format!(
                        "pick {} the best IoU by {:.3}{}{}",
                        if iou >= best - 0.005 { "within 0.005 of" } else { "BELOW" },
                        best - iou,
                        if size == 64 && *bytes == 128 << 10 {
                            format!("; holds at 64 px: {}", if loss <= 1.0 { "yes" } else { "NO" })
                        } else {
                            String::new()
                        },
                        match shown_to.get(level) {
                            Some(&shown) if u64::from(size) > shown => format!(" (the level is shown to {shown} px)"),
                            _ => String::new(),
                        }
                    ),
                    None => "no pick".to_string(),
                };
                println!("billboard-auto:   {tree} {budget} at {size} px: {}; {verdict}", row.join(", "));
            }
            println!("billboard-auto:   ({size} px: {} slots measured in {seconds:.1} s)", slots.len());
            if let Some(screen) = cirrus::preview::screen_samples_per_axis(size) {
                screening_check(&project, input, (size, screen), &slots);
            }
        }
    }
}

/// The `switch` stage's screening at `size` px (`preview::holds`) checked on every slot of a
/// built chain measured there (`measured`, at the stage's own samples): each slot measured
/// again at `screen_samples` a side, and counted where the screening would misjudge it: fail it
/// though it holds measured, or let it hold (at most `SCREEN_HOLD_LOSS`) though it fails (bar:
/// never), with the range of the measured loss over the screened one.
fn screening_check(
    project: &Project,
    input: cirrus::db::Asset,
    (size, screen_samples): (u32, u32),
    measured: &[(u32, String, cirrus::preview::PreviewMetrics)],
) {
    let settings = cirrus::preview::PreviewSettings { views: 26, size, samples_per_axis: screen_samples };
    let screened = cirrus::kinds::billboard_cloud::preview_slots(project.database(), input, project.config(), settings)
        .expect("preview");
    let (mut misjudged, mut ratios) = (Vec::new(), Vec::new());
    for ((_, folder, screen), (_, _, metrics)) in screened.iter().zip(measured) {
        let (Some(screen_loss), Some(loss)) = (screen.loss_px_shift, metrics.loss_px_shift) else { continue };
        let held = loss <= cirrus::preview::HOLD_LOSS;
        if (screen_loss > cirrus::preview::HOLD_LOSS && held)
            || (screen_loss <= cirrus::preview::SCREEN_HOLD_LOSS && !held)
        {
            misjudged.push(format!("{folder} ({screen_loss:.2} screened, {loss:.2} measured)"));
        }
        if screen_loss > 0.05 {
            ratios.push(loss / screen_loss);
        }
    }
    let (low, high) =
        ratios.iter().fold((f64::INFINITY, 0.0f64), |(low, high), &ratio| (low.min(ratio), high.max(ratio)));
    println!(
        "billboard-auto:   screening at {size} px, {} sample(s) a pixel: {} of {} slots misjudged against {} \
         samples (failed though they hold, or held at most {:.2} though they fail; bar: none){}; measured loss / \
         screened loss {low:.2}–{high:.2} over the {} losing over 0.05",
        screen_samples * screen_samples,
        misjudged.len(),
        screened.len(),
        measured.first().map_or(0, |(_, _, metrics)| metrics.samples_per_pixel),
        cirrus::preview::SCREEN_HOLD_LOSS,
        if misjudged.is_empty() { String::new() } else { format!(": {}", misjudged.join(", ")) },
        ratios.len()
    );
}

/// A three-level LOD chain (512, 128 and 32 quads) of each corpus tree as a process, beside a
/// single default bake (ε 0.02) of the same tree (bar: chain ≤ 2×); each level's quads, ε,
/// atlas, bytes and mean IoU (16 samples per pixel).
fn bench_billboard_chain(corpus: &Path) {
    const CHAIN: &str = "lods: [Quads(512), Quads(128), Quads(32)]";
    for tree in ["oak_medium", "ash_small", "bush_2"] {
        let single = tree_project(corpus, &format!(r#"BillboardCloud(name: "tree", mesh: "trees/{tree}.obj")"#));
        let (single_seconds, single_mib, _) = build_process(single.path());
        let chain = tree_project(
            corpus,
            &format!(r#"BillboardCloud(name: "tree", mesh: "trees/{tree}.obj", billboard: ({CHAIN}))"#),
        );
        let (chain_seconds, chain_mib, _) = build_process(chain.path());
        let report: serde_json::Value =
            serde_json::from_slice(&std::fs::read(chain.path().join("baked/tree/report.json")).unwrap()).unwrap();
        println!(
            "billboard-chain: {tree}: chain [512, 128, 32] {chain_seconds:.2} s ({chain_mib:.0} MiB) vs single default bake {single_seconds:.2} s ({single_mib:.0} MiB): {:.2}× (bar ≤ 2×); stage ms {}",
            chain_seconds / single_seconds,
            report["stage_ms"]
        );
        let (_dir, mut project, options) = tree_preview(corpus, tree, CHAIN);
        let levels = {
            let input = project.built_asset(&options.asset).expect("the asset builds");
            cirrus::kinds::billboard_cloud::preview_levels(project.database(), input, project.config(), &options)
        }
        .expect("preview");
        for ((level, metrics), entry) in levels.iter().zip(report["levels"].as_array().expect("levels")) {
            // Level N is meant for half the screen size of level N − 1: also seen at that size.
            let size = options.settings.size >> level;
            let settings = cirrus::preview::PreviewSettings { size, ..options.settings };
            let at_its_size = preview_one_level(
                &mut project,
                &cirrus::kinds::PreviewOptions { settings, lod: Some(*level), ..options.clone() },
            );
            println!(
                "billboard-chain: {tree}: lod{level}: {} quads (budget {}), ε {:.4}, atlas {}×{}, {:.2} MB, mean IoU {:.3} at {} px, {:.3} at {size} px",
                entry["quads"],
                entry["budget_quads"],
                entry["epsilon"].as_f64().unwrap_or(0.0),
                entry["atlas"]["width"],
                entry["atlas"]["height"],
                entry["bytes"].as_f64().unwrap_or(0.0) / 1e6,
                metrics.mean_iou,
                options.settings.size,
                at_its_size.mean_iou
            );
        }
    }
}

/// Plane selection: faces per second on the flight helmet, plane counts of the trees per ε.
fn bench_planes(corpus: &Path) {
    use cirrus::kinds::billboard_cloud::planes::{select_planes, PlaneSettings};
    let load = |file: &str| {
        let bytes = std::fs::read(corpus.join(file)).expect("mesh");
        let libraries = cirrus::mesh::material_libraries(Path::new(file), &bytes, Path::new(""))
            .into_iter()
            .map(|library| {
                let bytes = std::fs::read(corpus.join(&library)).ok();
                (library, bytes)
            })
            .collect();
        cirrus::mesh::load_mesh(Path::new(file), &bytes, &libraries, Path::new("")).expect("mesh loads").0
    };
    let helmet = load("meshes/flight_helmet/FlightHelmet.obj");
    let start = Instant::now();
    let set = select_planes(
        &helmet.positions,
        &helmet.triangles,
        &helmet.triangle_materials,
        PlaneSettings { epsilon: 0.02, max_planes: None, max_quads: None },
    );
    let seconds = start.elapsed().as_secs_f64();
    println!(
        "planes: flight helmet, {} faces → {} planes in {:.0} ms: {:.0} faces/s (bar ≥ 100k)",
        set.face_count,
        set.planes.len(),
        seconds * 1e3,
        set.face_count as f64 / seconds
    );
    for tree in ["trees/oak_medium.obj", "trees/ash_small.obj", "trees/bush_2.obj"] {
        let mesh = load(tree);
        let counts: Vec<String> = [0.01, 0.02, 0.04]
            .iter()
            .map(|&epsilon| {
                let start = Instant::now();
                let set = select_planes(
                    &mesh.positions,
                    &mesh.triangles,
                    &mesh.triangle_materials,
                    PlaneSettings { epsilon, max_planes: None, max_quads: None },
                );
                format!("ε {epsilon}: {} planes ({:.0} ms)", set.planes.len(), start.elapsed().as_secs_f64() * 1e3)
            })
            .collect();
        println!("planes: {tree} ({} faces): {}", mesh.triangles.len(), counts.join(", "));
    }
}

fn bench_project(label: &str, source: &Path, glob: &str) {
    let dir = tempfile::tempdir().expect("temporary folder");
    std::os::unix::fs::symlink(source, dir.path().join("assets")).expect("link sources");
    let pipeline = dir.path().join("pipeline.ron");
    std::fs::write(
        &pipeline,
        format!(r#"Pipeline(source: "assets", output: "baked", rules: [(glob: "{glob}", kind: Material)])"#),
    )
    .unwrap();
    let open = || Project::open(load_pipeline(&pipeline).expect("pipeline"), ProjectOptions::default());

    let mut project = open();
    let start = Instant::now();
    let summary = project.build(&BuildOptions::default(), &|_| {}).expect("build");
    let full = start.elapsed().as_secs_f64();
    assert!(summary.all_ok(), "{}", summary.to_text());
    let start = Instant::now();
    project.build(&BuildOptions::default(), &|_| {}).expect("build");
    let no_op = start.elapsed().as_secs_f64();
    drop(project);
    let start = Instant::now();
    let warm = open().build(&BuildOptions::default(), &|_| {}).expect("build");
    let restart = start.elapsed().as_secs_f64();
    assert!(warm
        .assets
        .iter()
        .all(|asset| asset.stages.iter().all(|stage| stage.status == cirrus::summary::StageStatus::Cached)));

    // The raw encoder on the same packed surfaces (mips prepared outside the timing).
    let mut chains = Vec::new();
    for report in glob_reports(&dir.path().join("baked")) {
        let report: serde_json::Value = serde_json::from_slice(&std::fs::read(report).unwrap()).unwrap();
        for material in report["materials"].as_array().unwrap() {
            for surface in material["surfaces"].as_array().unwrap() {
                let preview = image::open(dir.path().join(surface["preview"].as_str().unwrap())).unwrap().into_rgba8();
                let texture = Texture::new(preview.width(), preview.height(), preview.into_raw());
                let kind = match surface["surface"].as_str().unwrap() {
                    "Albedo" => SurfaceKind::Albedo,
                    "Mra" => SurfaceKind::Mra,
                    _ => SurfaceKind::Normal,
                };
                let format: BlockFormat = serde_json::from_value(surface["format"].clone()).unwrap();
                let alpha = surface["alpha_tested"].as_bool().unwrap();
                let levels = mip_chain(&texture, MipSettings { kind, alpha_cutoff: alpha.then_some(0.5) });
                chains.push((
                    levels,
                    BlockEncodeSettings { format, quality: EncodeQuality::Basic, alpha, srgb: kind.is_srgb() },
                ));
            }
        }
    }
    let texels: f64 =
        chains.iter().flat_map(|(levels, _)| levels.iter().map(|level| (level.width * level.height) as f64)).sum();
    let start = Instant::now();
    for (levels, settings) in &chains {
        for level in levels {
            std::hint::black_box(raw_encode_level(level, *settings));
        }
    }
    let raw = start.elapsed().as_secs_f64();
    let bake_rate = texels / full / 1e6;
    let raw_rate = texels / raw / 1e6;
    println!("{label}: {} surfaces, {:.1} Mpix encoded (all mip levels)", chains.len(), texels / 1e6);
    println!(
        "  full bake        {:>8.1} ms  {bake_rate:>6.2} Mpix/s (decode + pack + mips + encode + write)",
        full * 1e3
    );
    println!(
        "  raw encoder      {:>8.1} ms  {raw_rate:>6.2} Mpix/s (the encoders directly on the same levels: intel_tex_2, cirrus's BC1 refinement and BC4)",
        raw * 1e3
    );
    println!("  bake / raw       {:>8.2} ×   (bar ≥ 0.8)", bake_rate / raw_rate);
    println!(
        "  no-op rebuild    {:>8.1} ms  {:>6.1} % of the full bake (bar ≤ 5 %)",
        no_op * 1e3,
        100.0 * no_op / full
    );
    println!(
        "  warm restart     {:>8.1} ms  {:>6.1} % of the full bake (bar ≤ 5 %)",
        restart * 1e3,
        100.0 * restart / full
    );
}

/// The raw encoder: `intel_tex_2` over the whole level in parallel strips of 8 block rows, no
/// gathering and no deduplication (levels are padded to whole blocks by repeating the edge).
fn raw_encode_level(level: &Texture, settings: BlockEncodeSettings) -> Vec<u8> {
    let (blocks_x, blocks_y) = (level.width.div_ceil(4) as usize, level.height.div_ceil(4) as usize);
    let channels = match settings.format {
        BlockFormat::Bc4 => 1,
        BlockFormat::Bc5 => 2,
        _ => 4,
    };
    let mut padded = Vec::with_capacity(blocks_x * 4 * blocks_y * 4 * channels);
    for y in 0..blocks_y * 4 {
        for x in 0..blocks_x * 4 {
            let source =
                ((y.min(level.height as usize - 1) * level.width as usize) + x.min(level.width as usize - 1)) * 4;
            padded.extend_from_slice(&level.pixels[source..source + channels]);
        }
    }
    let block_size = cirrus::texture::encode::block_bytes(settings.format);
    let (row_bytes, block_row_bytes) = (blocks_x * 4 * channels, blocks_x * block_size);
    let mut output = vec![0u8; blocks_x * blocks_y * block_size];
    if matches!(settings.format, BlockFormat::Bc4 | BlockFormat::Bc5) {
        // cirrus's own BC4 search, as the bake runs it, each block straight from the level.
        let search = cirrus::texture::bc4::Bc4Search::for_quality(settings.quality);
        output.par_chunks_mut(block_size).enumerate().for_each(|(block, bytes)| {
            let (bx, by) = (block % blocks_x, block / blocks_x);
            for (channel, bytes) in bytes.chunks_exact_mut(8).enumerate() {
                let values: [u8; 16] = std::array::from_fn(|texel| {
                    padded[((by * 4 + texel / 4) * blocks_x * 4 + bx * 4 + texel % 4) * channels + channel]
                });
                bytes.copy_from_slice(&cirrus::texture::bc4::encode_bc4_block(&values, search));
            }
        });
        return output;
    }
    let bc7 = if settings.alpha {
        intel_tex_2::bc7::alpha_basic_settings()
    } else {
        intel_tex_2::bc7::opaque_basic_settings()
    };
    output.par_chunks_mut(block_row_bytes * 8).zip(padded.par_chunks(row_bytes * 32)).for_each(|(blocks, data)| {
        let (width, height, stride) = ((blocks_x * 4) as u32, (data.len() / row_bytes) as u32, row_bytes as u32);
        match settings.format {
            BlockFormat::Bc1 => intel_tex_2::bc1::compress_blocks_into(
                &intel_tex_2::RgbaSurface { data, width, height, stride },
                blocks,
            ),
            BlockFormat::Bc3 => intel_tex_2::bc3::compress_blocks_into(
                &intel_tex_2::RgbaSurface { data, width, height, stride },
                blocks,
            ),
            BlockFormat::Bc4 => {
                intel_tex_2::bc4::compress_blocks_into(&intel_tex_2::RSurface { data, width, height, stride }, blocks)
            }
            BlockFormat::Bc5 => {
                intel_tex_2::bc5::compress_blocks_into(&intel_tex_2::RgSurface { data, width, height, stride }, blocks)
            }
            BlockFormat::Bc7 => intel_tex_2::bc7::compress_blocks_into(
                &bc7,
                &intel_tex_2::RgbaSurface { data, width, height, stride },
                blocks,
            ),
        }
    });
    if settings.format == BlockFormat::Bc1
        && !matches!(settings.quality, EncodeQuality::UltraFast | EncodeQuality::VeryFast)
    {
        // cirrus's refinement of each block, as the bake runs it.
        output.par_chunks_mut(8).enumerate().for_each(|(block, bytes)| {
            let (bx, by) = (block % blocks_x, block / blocks_x);
            let texels: [[u8; 3]; 16] = std::array::from_fn(|texel| {
                let at = ((by * 4 + texel / 4) * blocks_x * 4 + bx * 4 + texel % 4) * 4;
                [padded[at], padded[at + 1], padded[at + 2]]
            });
            let refined = cirrus::texture::bc1::refine_bc1_block(&texels, bytes.try_into().expect("eight bytes"));
            bytes.copy_from_slice(&refined);
        });
    }
    output
}

fn glob_reports(folder: &Path) -> Vec<std::path::PathBuf> {
    let mut found = Vec::new();
    let mut folders = vec![folder.to_path_buf()];
    while let Some(folder) = folders.pop() {
        for entry in std::fs::read_dir(folder).unwrap().flatten() {
            let path = entry.path();
            if path.is_dir() {
                folders.push(path);
            } else if path.file_name().is_some_and(|name| name == "report.json") {
                found.push(path);
            }
        }
    }
    found.sort();
    found
}

/// The Height kind (DESIGN §3.4) at a 1024² map and level 8 on the bundled pair and on the
/// corpus pair `tools/make_height_pair.py` makes from the flight helmet's hose (under
/// `target/height_pairs/hose`; the section says how to make it when it is missing): the
/// distances to the high mesh of the low, PN and displaced meshes against the bars, and what
/// the bake, the tessellation and the measures took.
fn bench_height(repository: &Path) {
    let pairs = [
        ("bundled spot", repository.join("examples/assets/meshes/spot_height"), "spot"),
        ("corpus hose", repository.join("target/height_pairs/hose"), "hose"),
    ];
    for (label, folder, name) in pairs {
        if !folder.join(format!("{name}_low.obj")).is_file() {
            println!(
                "height: {label}: no pair in {}: make it with the second command in tools/make_height_pair.py",
                folder.display()
            );
            continue;
        }
        let dir = tempfile::tempdir().expect("temporary folder");
        std::os::unix::fs::symlink(folder.canonicalize().unwrap(), dir.path().join("assets")).unwrap();
        std::fs::write(
            dir.path().join("pipeline.ron"),
            format!(
                r#"Pipeline(source: "assets", output: "baked", assets: [
                    Height(name: "pair", high: "{name}_high.obj", low: "{name}_low.obj", height: (size: 1024),
                           tessellate: Some((level: 8, displace: true))),
                ])"#
            ),
        )
        .unwrap();
        let (seconds, peak_mib, summary) = build_process(dir.path());
        assert_eq!(summary["assets"][0]["status"], "ok", "{summary}");
        let report: serde_json::Value =
            serde_json::from_slice(&std::fs::read(dir.path().join("baked/pair/report.json")).unwrap()).unwrap();
        let distance = &report["distance"];
        let figure = |mesh: &str, what: &str| distance[mesh][what].as_f64().unwrap_or(f64::NAN);
        let (rms_ratio, hausdorff_ratio) = (
            figure("pn_displaced", "rms") / figure("low", "rms"),
            figure("pn_displaced", "hausdorff") / figure("low", "hausdorff"),
        );
        let met = |ratio: f64, bar: f64| if ratio <= bar { "met" } else { "MISSED" };
        println!(
            "height: {label}: RMS low {:.5} / PN {:.5} / PN+displaced {:.5} ({:.3}× low, bar ≤ 0.25: {}); Hausdorff low {:.5} / PN {:.5} / PN+displaced {:.5} ({:.3}× low, bar ≤ 0.5: {}) (over the high diagonal, {} samples each way)",
            figure("low", "rms"),
            figure("pn", "rms"),
            figure("pn_displaced", "rms"),
            rms_ratio,
            met(rms_ratio, 0.25),
            figure("low", "hausdorff"),
            figure("pn", "hausdorff"),
            figure("pn_displaced", "hausdorff"),
            hausdorff_ratio,
            met(hausdorff_ratio, 0.5),
            distance["samples_per_surface"],
        );
        let stage = |name: &str| report["stage_ms"][name].as_f64().unwrap_or(0.0);
        println!(
            "height: {label}: whole build {seconds:.2} s wall, peak {peak_mib:.0} MiB; bake of both 1024² maps {:.0} ms ({} texels measured, {} missed), tessellation {:.0} ms + displacement {:.0} ms ({} triangles), distances {:.0} ms, mesh loads {:.0} ms, BVH {:.0} ms, mips + encode {:.0} ms",
            stage("bake"),
            report["map"]["measured_texels"],
            report["map"]["missed_texels"],
            stage("tessellate"),
            stage("displace"),
            report["tessellated"]["triangles"],
            stage("distance"),
            stage("mesh"),
            stage("bvh"),
            stage("mips") + stage("encode"),
        );
    }
}

/// What each instruction-set level gives (`crate::isa`; levels above this CPU's are skipped): the
/// block encoders' throughput per format on the oak's baked atlas surfaces (2048², all mip
/// levels, encoded as the bake encodes them), whether the bytes equal the top level's, and the oak
/// full bake as a process with `--isa` (wall time, and its encode and render stages summed over
/// threads).
fn bench_isa(corpus: &Path) {
    use cirrus::isa::{detected_isa, limit_isa, IsaLevel};
    let cpu = detected_isa();
    let levels: Vec<IsaLevel> = IsaLevel::ALL.into_iter().filter(|&level| level <= cpu).rev().collect();
    println!("isa: this CPU runs up to {cpu}; levels measured: {levels:?}");
    let dir = tree_project(corpus, r#"BillboardCloud(name: "oak", mesh: "trees/oak_medium.obj")"#);
    let (seconds, _, _) = build_process(dir.path());
    println!("isa: oak full bake at {cpu} (process) {seconds:.2} s (to make the surfaces)");
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("baked/oak/report.json")).unwrap()).unwrap();
    let mut surfaces = Vec::new();
    for surface in report["surfaces"].as_array().unwrap() {
        let name = surface["surface"].as_str().unwrap().to_string();
        let image = image::open(dir.path().join("baked/oak").join(format!("{}.png", name.to_lowercase())))
            .unwrap()
            .into_rgba8();
        let texture = Texture::new(image.width(), image.height(), image.into_raw());
        let kind = match name.as_str() {
            "Albedo" => SurfaceKind::Albedo,
            "Mra" => SurfaceKind::Mra,
            "Height" => SurfaceKind::Height,
            _ => SurfaceKind::Normal,
        };
        let alpha = surface["alpha_tested"].as_bool().unwrap();
        let format: BlockFormat = serde_json::from_value(surface["format"].clone()).unwrap();
        let levels = mip_chain(&texture, MipSettings { kind, alpha_cutoff: alpha.then_some(0.5) });
        let settings = BlockEncodeSettings { format, quality: EncodeQuality::Basic, alpha, srgb: kind.is_srgb() };
        surfaces.push((name, levels, settings));
    }
    let mut reference: Vec<Vec<u8>> = Vec::new();
    for &level in &levels {
        limit_isa(level);
        let mut figures = Vec::new();
        for (index, (name, chain, settings)) in surfaces.iter().enumerate() {
            let texels: f64 = chain.iter().map(|level| (level.width * level.height) as f64).sum();
            let mut best = f64::INFINITY;
            let mut bytes = Vec::new();
            for _ in 0..3 {
                let start = Instant::now();
                let encoded = cirrus::texture::encode::encode_levels(chain, *settings);
                best = best.min(start.elapsed().as_secs_f64());
                bytes = encoded.levels.iter().flat_map(|level| level.iter().copied()).collect();
            }
            if reference.len() <= index {
                reference.push(bytes.clone());
            }
            let same = if reference[index] == bytes { "same bytes" } else { "bytes differ" };
            figures.push(format!("{name} {:?} {:.1} Mpix/s ({same})", settings.format, texels / best / 1e6));
        }
        println!("isa: {level}: {}", figures.join(", "));
        // cirrus's BC4 search at each quality on the normal surface (BC5: two channels).
        if let Some((_, chain, settings)) = surfaces.iter().find(|(name, _, _)| name == "Normal") {
            let texels: f64 = chain.iter().map(|level| 2.0 * (level.width * level.height) as f64).sum();
            let qualities = [EncodeQuality::Fast, EncodeQuality::Basic, EncodeQuality::Slow].map(|quality| {
                let settings = BlockEncodeSettings { format: BlockFormat::Bc5, quality, ..*settings };
                let start = Instant::now();
                std::hint::black_box(cirrus::texture::encode::encode_levels(chain, settings));
                let cores = rayon::current_num_threads() as f64;
                format!("{quality:?} {:.1}", texels / start.elapsed().as_secs_f64() / 1e6 / cores)
            });
            println!("isa: {level}: BC4 search, M channel texels/s per core: {}", qualities.join(", "));
        }
    }
    limit_isa(IsaLevel::Avx512);
    for &level in &levels {
        let mut walls = Vec::new();
        let mut stages = String::new();
        for _ in 0..2 {
            std::fs::remove_dir_all(dir.path().join("baked/.cirrus")).unwrap();
            let (seconds, _, summary) = build_process_in(dir.path(), &["--isa", level.name()], &[]);
            walls.push(seconds);
            // From the summary: the report keeps the timings of the build that last changed it.
            let mut stage_ms = std::collections::BTreeMap::<String, f64>::new();
            for stage in
                summary["assets"][0]["stages"].as_array().unwrap().iter().filter(|stage| stage["status"] == "ran")
            {
                *stage_ms.entry(stage["stage"].as_str().unwrap().to_string()).or_default() +=
                    stage["ms"].as_f64().unwrap();
            }
            stages = ["encode", "render", "mips"]
                .map(|stage| format!("{stage} {:.0} ms", stage_ms.get(stage).copied().unwrap_or(0.0)))
                .join(", ");
        }
        println!(
            "isa: oak full bake (process, --isa {level}): {:.2} s best of {:?} (bar ≤ 5 s); last run's stages summed over threads: {stages}",
            walls.iter().copied().fold(f64::INFINITY, f64::min),
            walls.iter().map(|seconds| format!("{seconds:.2}")).collect::<Vec<_>>()
        );
    }
}

/// The oak full bake (as a process, best of two) with a shared cache on a `weed mini` server on
/// loopback: cold without a store, cold uploading to it, from the warm store with an empty local
/// cache, fully local, and against a store that refuses connections and one that accepts them
/// and never answers (the bar: at most 1 s over the local build); the bytes uploaded.
fn bench_shared_cache(corpus: &Path) {
    let server = seaweed::SeaweedServer::start();
    let bucket = server.bucket();
    let dir = tree_project(corpus, r#"BillboardCloud(name: "oak", mesh: "trees/oak_medium.obj")"#);
    let clear = || {
        let _ = std::fs::remove_dir_all(dir.path().join("baked"));
    };
    let best = |runs: &mut dyn FnMut() -> f64| (0..2).map(|_| runs()).fold(f64::INFINITY, f64::min);
    let remote = ["--remote-cache", "s3://cirrus/bench"];
    let cold = best(&mut || {
        clear();
        build_process(dir.path()).0
    });
    clear();
    let uploading = build_process_in(dir.path(), &remote, &server.environment()).0;
    let objects = bucket.objects("bench");
    let uploaded: usize = objects.values().map(Vec::len).sum();
    let warm = best(&mut || {
        clear();
        build_process_in(dir.path(), &remote, &server.environment()).0
    });
    let local = best(&mut || build_process_in(dir.path(), &remote, &server.environment()).0);
    println!(
        "shared-cache: oak full bake (process): cold without a store {cold:.2} s, cold uploading {uploading:.2} s ({} objects, {:.1} MiB), from the store with an empty local cache {warm:.2} s, fully local {local:.2} s",
        objects.len(),
        uploaded as f64 / (1 << 20) as f64
    );
    // A closed port, and one that accepts connections and never answers.
    let closed = std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
    let silent = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let silent_port = silent.local_addr().unwrap().port();
    std::thread::spawn(move || {
        let mut held = Vec::new();
        for stream in silent.incoming().flatten() {
            held.push(stream);
        }
    });
    for (label, port) in [("refusing connections", closed), ("silent", silent_port)] {
        let environment = [
            ("AWS_ACCESS_KEY_ID", "x".to_string()),
            ("AWS_SECRET_ACCESS_KEY", "y".to_string()),
            ("AWS_ENDPOINT_URL", format!("http://127.0.0.1:{port}")),
            ("AWS_REGION", "us-east-1".to_string()),
        ];
        let away = best(&mut || {
            clear();
            build_process_in(dir.path(), &remote, &environment).0
        });
        println!(
            "shared-cache: oak cold with a store {label}: {away:.2} s, {:+.2} s over the cold build without one (bar ≤ 1 s)",
            away - cold
        );
    }
}

/// What one bake process cost: wall and CPU seconds, peak resident memory in MiB, the summary.
struct ProcessFigures {
    wall: f64,
    cpu: f64,
    peak_mib: f64,
    summary: serde_json::Value,
}

/// CPU seconds of every child process reaped so far (user + system).
fn children_cpu_seconds() -> f64 {
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    // SAFETY: getrusage writes the struct it is given.
    unsafe { libc::getrusage(libc::RUSAGE_CHILDREN, &mut usage) };
    let seconds = |time: libc::timeval| time.tv_sec as f64 + time.tv_usec as f64 / 1e6;
    seconds(usage.ru_utime) + seconds(usage.ru_stime)
}

/// `binary build --summary json` in `folder` with `global_arguments` before `build`, cold
/// (the output folder removed first): wall, CPU and peak memory of the process.
fn cold_bake(binary: &Path, folder: &Path, global_arguments: &[&str]) -> ProcessFigures {
    let _ = std::fs::remove_dir_all(folder.join("baked"));
    let cpu_before = children_cpu_seconds();
    let (wall, peak_mib, summary) = build_process_of(binary, folder, global_arguments, &[]);
    ProcessFigures { wall, cpu: children_cpu_seconds() - cpu_before, peak_mib, summary }
}

/// The oak's full bake (default settings, cold, as a process, llvmpipe or whatever adapter the
/// machine has) by this build and by a baseline binary (`CIRRUS_BENCH_BASELINE`, e.g. the
/// commit before a change, built with `tools/build_baseline.sh REV`), runs alternating, three
/// each, at `--isa avx2` (where both binaries know the flag and the CPU has AVX2) and native:
/// wall median (min–max), CPU, peak memory, stage sums over threads, then each build's mean
/// IoU (26 views) and the albedo's PSNR, visible-texel PSNR and alpha-test IoU, and this build's
/// albedo beside bc7enc's on the same surface.
fn bench_oak_bake(corpus: &Path) {
    let current = Path::new(env!("CARGO_BIN_EXE_cirrus")).to_path_buf();
    // Baselines: other builds' binaries, separated as PATH is (`:` on Unix).
    let baselines: Vec<std::path::PathBuf> = std::env::var_os("CIRRUS_BENCH_BASELINE")
        .map(|paths| std::env::split_paths(&paths).collect())
        .unwrap_or_default();
    if baselines.is_empty() {
        println!("oak-bake: no baseline (set CIRRUS_BENCH_BASELINE to other builds' cirrus, `:`-separated, e.g. from tools/build_baseline.sh REV)");
    }
    let binaries: Vec<(String, std::path::PathBuf)> = std::iter::once(("this build".to_string(), current))
        .chain(baselines.into_iter().map(|path| (format!("baseline {}", path.display()), path)))
        .collect();
    let knows_isa = |binary: &Path| {
        std::process::Command::new(binary)
            .arg("--help")
            .output()
            .is_ok_and(|output| String::from_utf8_lossy(&output.stdout).contains("--isa"))
    };
    let cpu = cirrus::isa::detected_isa();
    let dir = tree_project(corpus, r#"BillboardCloud(name: "oak", mesh: "trees/oak_medium.obj")"#);
    println!("oak-bake: CPU up to {cpu}, 2 workers as the machine gives; adapter {}", cirrus::gpu::adapter_family());
    let mut settings: Vec<Vec<&str>> = Vec::new();
    if cpu >= cirrus::isa::IsaLevel::Avx2 {
        settings.push(vec!["--isa", "avx2"]);
    }
    settings.push(Vec::new());
    for arguments in &settings {
        let label = if arguments.is_empty() { format!("native ({cpu})") } else { arguments.join(" ") };
        let mut runs: Vec<Vec<ProcessFigures>> = binaries.iter().map(|_| Vec::new()).collect();
        for _ in 0..3 {
            for (index, (_, binary)) in binaries.iter().enumerate() {
                if !arguments.is_empty() && !knows_isa(binary) {
                    continue;
                }
                runs[index].push(cold_bake(binary, dir.path(), arguments));
            }
        }
        for ((name, _), runs) in binaries.iter().zip(&runs) {
            if runs.is_empty() {
                println!("oak-bake: {label}: {name}: this binary has no --isa; not measured");
                continue;
            }
            let mut walls: Vec<f64> = runs.iter().map(|run| run.wall).collect();
            walls.sort_by(f64::total_cmp);
            let mean = |value: fn(&ProcessFigures) -> f64| runs.iter().map(value).sum::<f64>() / runs.len() as f64;
            let mut stages = std::collections::BTreeMap::<String, f64>::new();
            for run in runs {
                for stage in run.summary["assets"][0]["stages"]
                    .as_array()
                    .expect("stages")
                    .iter()
                    .filter(|stage| stage["status"] == "ran")
                {
                    *stages.entry(stage["stage"].as_str().expect("stage").to_string()).or_default() +=
                        stage["ms"].as_f64().unwrap_or(0.0) / runs.len() as f64;
                }
            }
            let stages: Vec<String> = stages.iter().map(|(stage, ms)| format!("{stage} {ms:.0}")).collect();
            println!(
                "oak-bake: {label}: {name}: wall {:.2} s ({:.2}–{:.2}), CPU {:.1} s, peak {:.0} MiB; stage ms summed over threads: {}",
                walls[walls.len() / 2],
                walls[0],
                walls[walls.len() - 1],
                mean(|run| run.cpu),
                mean(|run| run.peak_mib),
                stages.join(", ")
            );
        }
    }
    // Fidelity of what each build baked (native), from its own preview.
    for (name, binary) in &binaries {
        cold_bake(binary, dir.path(), &[]);
        let preview = std::process::Command::new(binary)
            .args(["preview", "--asset", "oak"])
            .current_dir(dir.path())
            .output()
            .expect("preview");
        let metrics: serde_json::Value = std::fs::read(dir.path().join("baked/oak/preview/metrics.json"))
            .ok()
            .and_then(|bytes| serde_json::from_slice(&bytes).ok())
            .unwrap_or_else(|| {
                panic!("{name}'s preview wrote no metrics: {}", String::from_utf8_lossy(&preview.stderr))
            });
        let report: serde_json::Value =
            serde_json::from_slice(&std::fs::read(dir.path().join("baked/oak/report.json")).expect("report"))
                .expect("JSON");
        let albedo = report["surfaces"]
            .as_array()
            .expect("surfaces")
            .iter()
            .find(|surface| surface["surface"] == "Albedo")
            .expect("albedo");
        println!(
            "oak-bake: {name}: mean IoU {:.4} (26 views), mean PSNR {:.2} dB; albedo PSNR {} dB (all texels, RGBA), visible {} dB (RGB where the alpha test passes), alpha-test IoU {}",
            metrics["mean_iou"].as_f64().unwrap_or(f64::NAN),
            metrics["mean_psnr"].as_f64().unwrap_or(f64::NAN),
            albedo["psnr_db"],
            albedo.get("visible_psnr_db").map_or("—".to_string(), |value| value.to_string()),
            albedo.get("alpha_test_iou").map_or("—".to_string(), |value| value.to_string()),
        );
        if name == "this build" {
            println!("oak-bake: {}", bc7_beside_bc7enc(&dir.path().join("baked/oak/albedo.png")));
        }
    }
}

/// `benches/bc_reference.py bc7-visible` on a baked alpha-tested surface: cirrus's BC7 and
/// bc7enc's at its top level on the same surface, where the alpha test passes, through the
/// `python3` on the PATH or `CIRRUS_BENCH_PYTHON` (with `etcpak` and `texture2ddecoder`).
fn bc7_beside_bc7enc(png: &Path) -> String {
    let python = std::env::var("CIRRUS_BENCH_PYTHON").unwrap_or_else(|_| "python3".to_string());
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("benches/bc_reference.py");
    match std::process::Command::new(&python).arg(&script).arg("bc7-visible").arg(png).output() {
        Ok(output) if output.status.success() => String::from_utf8_lossy(&output.stdout).trim().to_string(),
        _ => format!(
            "bc7enc not measured: `{python}` cannot run {} bc7-visible (pip install etcpak texture2ddecoder pillow numpy)",
            script.display()
        ),
    }
}
