//! The command line: `build`, `watch`, `graph`, `preview`, `check` and `cache`, their options, output and exit codes
//! (0: every asset baked, 1: some asset failed, 2: usage or configuration error).

mod cache;
mod output;

use std::io::IsTerminal;
use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand, ValueEnum};

use crate::cache::remote::RemoteCacheOverride;
use crate::project::{BuildOptions, Progress, Project, ProjectOptions};
use cache::CacheCommand;
pub(crate) use output::{load_pipeline_or_report, out, outln, EXIT_ASSET_FAILED, EXIT_USAGE};

#[derive(Debug, Parser)]
#[command(
    name = "cirrus",
    version,
    about = "Incremental asset pipeline: billboard-cloud LODs and baked, block-compressed materials"
)]
pub struct Cli {
    /// More log output (-v: info, -vv: debug, -vvv: trace). RUST_LOG overrides it.
    #[arg(short, long, action = clap::ArgAction::Count, global = true)]
    pub verbose: u8,
    /// The shared cache, over `cache: (remote: …)` of the pipeline: s3://bucket/prefix,
    /// file:///folder, or `off`. Endpoint, region and credentials come from the AWS_*
    /// environment variables.
    #[arg(long, value_name = "URL", env = "CIRRUS_REMOTE_CACHE", global = true)]
    pub remote_cache: Option<String>,
    /// read-write (build machines, CI) or read-only (artists' machines), over the pipeline's `mode`.
    #[arg(long, value_name = "MODE", env = "CIRRUS_REMOTE_CACHE_MODE", global = true)]
    pub remote_cache_mode: Option<String>,
    /// Run the CPU kernels (block encoders, ray casting) and the software renderer at most at
    /// this instruction-set level: sse2, sse4, avx2 or avx512 (the default: the CPU's best).
    /// For measuring what a machine without AVX-512 gets, or ruling out a wide kernel.
    #[arg(long, value_name = "LEVEL", env = "CIRRUS_ISA", global = true)]
    pub isa: Option<crate::isa::IsaLevel>,
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Bake every asset (or those named) once; unchanged inputs do no work.
    Build {
        /// The pipeline file.
        #[arg(long, default_value = "pipeline.ron")]
        pipeline: PathBuf,
        /// Bake only this asset (repeatable).
        #[arg(long = "asset", value_name = "NAME")]
        assets: Vec<String>,
        /// How to print the result on stdout.
        #[arg(long, value_enum, default_value_t = SummaryFormat::Text)]
        summary: SummaryFormat,
        /// Hash every source file and artifact instead of trusting their metadata (size,
        /// modification and change times, file id) as the build record holds it.
        #[arg(long)]
        verify: bool,
        /// The memory the process may keep resident, in MiB (over `limits: (memory_mib: …)`;
        /// default: half the machine's memory).
        #[arg(long, value_name = "MIB", value_parser = memory_mib_parser())]
        memory_mib: Option<u64>,
    },
    /// Render a baked mesh beside its source from many directions (a billboard cloud's LODs, an
    /// atlas's remapped meshes): contact sheets and metrics.
    Preview {
        /// The pipeline file.
        #[arg(long, default_value = "pipeline.ron")]
        pipeline: PathBuf,
        /// The BillboardCloud asset, or Atlas asset with `meshes`.
        #[arg(long)]
        asset: String,
        /// How many of the 26 cube directions to render.
        #[arg(long, default_value_t = 26, value_parser = clap::value_parser!(u32).range(1..=26))]
        views: u32,
        /// Image size in pixels (square).
        #[arg(long, default_value_t = 256, value_parser = clap::value_parser!(u32).range(16..=2048))]
        size: u32,
        /// Samples per pixel along each axis (4: 16 samples); a pixel is in a silhouette when at
        /// least half of its samples are covered.
        #[arg(long, default_value_t = 4, value_parser = clap::value_parser!(u32).range(1..=4))]
        samples: u32,
        /// Output folder (default: <output>/<asset>/preview, or preview_<stand-in>).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Only this level of a LOD chain (default: every level, and the chain's contact sheet).
        #[arg(long, value_name = "N")]
        lod: Option<u32>,
        /// What stands beside the source: the baked LOD, or the source's own faces moved onto
        /// the LOD's planes with their own textures, to tell what the planes cost from what the
        /// atlas costs: `projected` (each corner onto its face's plane: the cloud's geometry) or
        /// `translated` (each face along its plane's normal, keeping its shape: displacement
        /// alone).
        #[arg(long, value_parser = stand_in_parser(), default_value = "baked")]
        stand_in: crate::kinds::StandIn,
    },
    /// Bake, then watch the sources and re-bake what each edit invalidated; tell engines over TCP.
    Watch {
        /// The pipeline file.
        #[arg(long, default_value = "pipeline.ron")]
        pipeline: PathBuf,
        /// The hot-reload server's address, e.g. 127.0.0.1:7878 or localhost:7878 (default:
        /// `server` of the pipeline). The protocol has no authentication: keep it on loopback.
        #[arg(long, value_name = "ADDR", value_parser = crate::config::resolve_socket_address)]
        listen: Option<std::net::SocketAddr>,
        /// A web page's origin (`https://editor.example:8443`) allowed to open a WebSocket, besides
        /// pages served from this machine (loopback); repeat for more, `*` for every page.
        #[arg(long, value_name = "ORIGIN", value_parser = parse_origin)]
        allow_origin: Vec<String>,
        /// Events closer together than this many milliseconds become one batch.
        #[arg(long, default_value_t = 50, value_name = "MS")]
        debounce_ms: u64,
        /// The memory the process may keep resident, in MiB (over `limits: (memory_mib: …)`;
        /// default: half the machine's memory).
        #[arg(long, value_name = "MIB", value_parser = memory_mib_parser())]
        memory_mib: Option<u64>,
    },
    /// Print the dependency graph: source files, stage instances and artifacts, with timings.
    Graph {
        /// The pipeline file.
        #[arg(long, default_value = "pipeline.ron")]
        pipeline: PathBuf,
        /// Only this asset and the files that feed it.
        #[arg(long)]
        asset: Option<String>,
        #[arg(long, value_enum, default_value_t = crate::graph::GraphFormat::Dot)]
        format: crate::graph::GraphFormat,
    },
    /// Validate the pipeline and every asset's sources without baking.
    Check {
        /// The pipeline file.
        #[arg(long, default_value = "pipeline.ron")]
        pipeline: PathBuf,
        /// Check only this asset (repeatable).
        #[arg(long = "asset", value_name = "NAME")]
        assets: Vec<String>,
        /// Print one JSON object instead of text: `{"assets":[{"name","problems":[{"file",
        /// "line","column","severity","message"}]}],"checked","failed","warned"}`.
        #[arg(long)]
        json: bool,
    },
    /// The stage cache: what the last build found where, why a stage missed, and bounding the
    /// local folder.
    Cache {
        #[command(subcommand)]
        command: CacheCommand,
    },
}

/// A web page's origin as browsers send it: `http(s)://host[:port]`, no path (or `*`).
fn parse_origin(text: &str) -> Result<String, String> {
    let origin = text.trim().trim_end_matches('/');
    let host = origin.strip_prefix("http://").or_else(|| origin.strip_prefix("https://"));
    match host {
        _ if origin == "*" => Ok(origin.to_string()),
        Some(host) if !host.is_empty() && !host.contains(['/', '?', '#', ' ']) => Ok(origin.to_string()),
        _ => Err(format!(
            "`{text}` is not a page's origin: write it as a browser sends it, e.g. https://editor.example:8443"
        )),
    }
}

/// The preview's stand-ins on the command line, by name (`kinds::StandIn` knows nothing of clap).
fn stand_in_parser() -> impl clap::builder::TypedValueParser<Value = crate::kinds::StandIn> {
    use crate::kinds::StandIn;
    use clap::builder::TypedValueParser;
    clap::builder::PossibleValuesParser::new(StandIn::ALL.map(StandIn::name))
        .map(|name| StandIn::ALL.into_iter().find(|stand_in| stand_in.name() == name).expect("a listed stand-in"))
}

/// The graph formats on the command line (`graph` is a data module and knows nothing of clap).
impl ValueEnum for crate::graph::GraphFormat {
    fn value_variants<'a>() -> &'a [Self] {
        &crate::graph::GraphFormat::ALL
    }

    fn to_possible_value(&self) -> Option<clap::builder::PossibleValue> {
        Some(clap::builder::PossibleValue::new(self.name()))
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum SummaryFormat {
    Text,
    Json,
}

pub(crate) fn init_logging(verbose: u8) {
    let default = match verbose {
        0 => "warn",
        1 => "info",
        2 => "debug",
        _ => "trace",
    };
    // notify warns "Unable to remove the path from the watches" when the source folder it
    // watched is deleted (its watch went with it); the daemon watches the folder again and says
    // so itself.
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(format!("{default},salsa=warn,notify=error")));
    // Colour only for a person at a terminal: logs redirected to a file or a pipe stay plain
    // text (and `NO_COLOR` turns colour off anywhere).
    let ansi = std::io::stderr().is_terminal() && std::env::var_os("NO_COLOR").is_none();
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_target(false)
        .with_ansi(ansi)
        .try_init();
}

/// A file grown past `ulimit -f` fails its write (`EFBIG`, reported like any failed write)
/// instead of the signal killing the process without a word.
fn ignore_file_size_signal() {
    #[cfg(unix)]
    // SAFETY: setting a signal's disposition to SIG_IGN touches no memory of this process.
    unsafe {
        libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
    }
}

/// The environment variables that stand for flags, and the flag each stands for.
const FLAG_VARIABLES: [(&str, &str); 3] = [
    ("CIRRUS_ISA", "--isa"),
    ("CIRRUS_REMOTE_CACHE", "--remote-cache"),
    ("CIRRUS_REMOTE_CACHE_MODE", "--remote-cache-mode"),
];

/// The command line, or the usage exit status after saying why not. A flag's environment
/// variable set to nothing (`CIRRUS_ISA=`, often an unset shell variable passed on) is refused
/// under its own name, before the parser would blame the flag.
pub fn parse_command_line() -> Result<Cli, ExitCode> {
    for (variable, flag) in FLAG_VARIABLES {
        if std::env::var_os(variable).is_some_and(|value| value.is_empty()) {
            eprintln!("error: {variable} is set but empty (it stands for {flag}): unset it or give it a value");
            return Err(ExitCode::from(EXIT_USAGE));
        }
    }
    Ok(Cli::parse())
}

pub fn run(cli: Cli) -> ExitCode {
    let status = run_command(cli);
    if output::stdout_failed() && status == ExitCode::SUCCESS {
        return ExitCode::from(EXIT_ASSET_FAILED);
    }
    status
}

/// The worker threads: `RAYON_NUM_THREADS` when it asks for at most this machine's cores, else
/// one per core (thousands of threads on a few cores only spin: `RAYON_NUM_THREADS=2000` took a
/// two-core build from 8 s to past two minutes).
fn configure_threads() {
    let cores = std::thread::available_parallelism().map_or(2, |count| count.get());
    let asked = std::env::var("RAYON_NUM_THREADS").ok();
    let threads = match asked.as_deref().map(|text| text.trim().parse::<usize>()) {
        None | Some(Ok(0)) => cores,
        Some(Ok(threads)) if threads <= cores => threads,
        Some(Ok(threads)) => {
            tracing::warn!(
                "RAYON_NUM_THREADS={threads} is more than this machine's {cores} cores: cirrus works on \
                {cores} threads"
            );
            cores
        }
        Some(Err(_)) => {
            tracing::warn!(
                "RAYON_NUM_THREADS={:?} is not a number of threads: cirrus works on {cores} threads",
                asked.unwrap_or_default()
            );
            cores
        }
    };
    // Fails only when the pool exists already (a second `run` in one process): that one stays.
    let _ = rayon::ThreadPoolBuilder::new().num_threads(threads).build_global();
}

/// `--memory-mib`: a budget within `limits: (memory_mib: …)`'s range.
fn memory_mib_parser() -> clap::builder::RangedU64ValueParser<u64> {
    let range = crate::config::MEMORY_MIB_RANGE;
    clap::value_parser!(u64).range(*range.start()..=*range.end())
}

fn run_command(cli: Cli) -> ExitCode {
    ignore_file_size_signal();
    crate::memory::configure_allocator();
    init_logging(cli.verbose);
    configure_threads();
    let remote_cache = match RemoteCacheOverride::parse(cli.remote_cache.as_deref(), cli.remote_cache_mode.as_deref()) {
        Ok(remote_cache) => remote_cache,
        Err(why) => {
            eprintln!("error: {why}");
            return ExitCode::from(EXIT_USAGE);
        }
    };
    let options = ProjectOptions { remote_cache: remote_cache.clone(), ..Default::default() };
    match cli.command {
        Command::Build { pipeline, assets, summary, verify, memory_mib } => {
            // The process ends with the build: it keeps no intermediate for a next one.
            let retention = crate::db::Retention::OutputsOnly;
            let memory_budget = memory_mib.map(|mib| mib << 20);
            build(pipeline, assets, summary, ProjectOptions { verify, retention, memory_budget, ..options })
        }
        Command::Check { pipeline, assets, json } => check(pipeline, &assets, json),
        Command::Cache { command } => cache::run(command, options),
        Command::Watch { pipeline, listen, allow_origin, debounce_ms, memory_mib } => {
            let debounce = std::time::Duration::from_millis(debounce_ms);
            let settings = crate::watch::WatchSettings {
                pipeline,
                listen,
                allowed_origins: allow_origin,
                debounce,
                max_builds: None,
                remote_cache,
                memory_budget: memory_mib.map(|mib| mib << 20),
            };
            match crate::watch::watch(&settings) {
                Ok(()) => ExitCode::SUCCESS,
                Err(error) => {
                    eprintln!("error: {error}");
                    ExitCode::from(EXIT_USAGE)
                }
            }
        }
        Command::Graph { pipeline, asset, format } => graph(pipeline, asset, format, options),
        Command::Preview { pipeline, asset, views, size, samples, out, lod, stand_in } => {
            let settings = crate::preview::PreviewSettings { views: views as usize, size, samples_per_axis: samples };
            preview(pipeline, asset, settings, out, lod, stand_in, options)
        }
    }
}

fn build(pipeline: PathBuf, assets: Vec<String>, format: SummaryFormat, options: ProjectOptions) -> ExitCode {
    let config = match load_pipeline_or_report(&pipeline) {
        Ok(config) => config,
        Err(code) => return code,
    };
    // A shared cache on S3 with an endpoint no client can use is a configuration error: the
    // build would otherwise run without the cache it was told to use.
    let remote = options.remote_cache.apply(config.remote_cache.as_ref());
    if let Some(settings) =
        remote.filter(|settings| matches!(settings.location, crate::cache::remote::RemoteLocation::S3 { .. }))
    {
        if let Err(why) = crate::cache::remote::check_endpoint_environment() {
            eprintln!("error: shared cache {}: {why}", settings.url);
            return ExitCode::from(EXIT_USAGE);
        }
    }
    let mut project = Project::open(config, options);
    // The bar moves with the estimated time of the work, not the count of jobs (a few AO tiles
    // or renders outweigh hundreds of surfaces), and says about how long is left.
    let bar = std::io::stderr().is_terminal().then(|| {
        let bar = indicatif::ProgressBar::new(1000);
        bar.set_style(
            indicatif::ProgressStyle::with_template("{spinner} [{elapsed_precise}] {bar:30} {wide_msg}")
                .expect("valid progress template"),
        );
        bar
    });
    let report_progress = |progress: Progress| {
        let left = progress
            .remaining_seconds
            .map(|seconds| format!(", about {} left", crate::summary::rough_duration(seconds)))
            .unwrap_or_default();
        match &bar {
            Some(bar) => {
                bar.set_position((progress.fraction() * 1000.0) as u64);
                bar.set_message(format!("{}/{} jobs{left}: {}", progress.done, progress.total, progress.item));
            }
            None => tracing::info!("baked {} ({}/{}{left})", progress.item, progress.done, progress.total),
        }
    };
    let result = project.build(&BuildOptions { only_assets: assets, ..Default::default() }, &report_progress);
    if let Some(bar) = &bar {
        bar.finish_and_clear();
    }
    let summary = match result {
        Ok(summary) => summary,
        Err(error) => {
            eprintln!("error: {error}");
            return ExitCode::from(EXIT_USAGE);
        }
    };
    match format {
        SummaryFormat::Json => outln!("{}", summary.to_json()),
        SummaryFormat::Text => out!("{}", summary.to_text()),
    }
    // The process ends here: freeing every memo one by one would only delay the exit (about
    // 7 ms on the oak). The cache's background writes finished inside `build`.
    std::mem::forget(project);
    if summary.all_ok() {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(EXIT_ASSET_FAILED)
    }
}

fn check(pipeline: PathBuf, only: &[String], json: bool) -> ExitCode {
    let config = match load_pipeline_or_report(&pipeline) {
        Ok(config) => config,
        Err(code) => return code,
    };
    let project = Project::open(config, ProjectOptions { persistent_cache: false, ..Default::default() });
    let problems = match project.check_assets(only) {
        Ok(problems) => problems,
        Err(error) => {
            eprintln!("error: {error}");
            return ExitCode::from(EXIT_USAGE);
        }
    };
    // Warnings are printed but do not fail the check: the bake goes ahead past them.
    let checked = problems.iter().filter(|(asset, _)| asset != "rules").count();
    let failed = problems
        .iter()
        .filter(|(_, diagnostics)| diagnostics.iter().any(|diagnostic| !diagnostic.is_warning()))
        .count();
    let warned = problems
        .iter()
        .filter(|(_, diagnostics)| {
            !diagnostics.is_empty() && diagnostics.iter().all(crate::diagnostic::Diagnostic::is_warning)
        })
        .count();
    if json {
        let assets: Vec<serde_json::Value> = problems
            .iter()
            .map(|(asset, diagnostics)| {
                let problems: Vec<serde_json::Value> = diagnostics
                    .iter()
                    .map(|diagnostic| {
                        serde_json::json!({
                            "file": crate::diagnostic::display_path(&diagnostic.file),
                            "line": diagnostic.line(),
                            "column": diagnostic.column(),
                            "severity": if diagnostic.is_warning() { "warning" } else { "error" },
                            "message": diagnostic.message,
                        })
                    })
                    .collect();
                serde_json::json!({ "name": asset, "problems": problems })
            })
            .collect();
        outln!("{}", serde_json::json!({ "assets": assets, "checked": checked, "failed": failed, "warned": warned }));
    } else {
        for (asset, diagnostics) in &problems {
            for diagnostic in diagnostics {
                outln!("{asset}: {diagnostic}");
            }
        }
        if warned == 0 {
            outln!("{checked} assets checked, {failed} with problems");
        } else {
            outln!("{checked} assets checked, {failed} with problems, {warned} with warnings only");
        }
    }
    if failed == 0 {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(EXIT_ASSET_FAILED)
    }
}

fn preview(
    pipeline: PathBuf,
    asset: String,
    settings: crate::preview::PreviewSettings,
    out: Option<PathBuf>,
    lod: Option<u32>,
    stand_in: crate::kinds::StandIn,
    options: ProjectOptions,
) -> ExitCode {
    let config = match load_pipeline_or_report(&pipeline) {
        Ok(config) => config,
        Err(code) => return code,
    };
    // A stand-in's sheets go beside the baked LOD's, not over them.
    let folder = match stand_in {
        crate::kinds::StandIn::Baked => "preview".to_string(),
        other => format!("preview_{}", other.name()),
    };
    let out = out.unwrap_or_else(|| config.output.join(&asset).join(folder));
    let mut project = Project::open(config, options);
    let options = crate::kinds::PreviewOptions { asset, settings, out, lod, stand_in };
    let previewed = project.built_asset(&options.asset).map_err(PreviewFailure::Build).and_then(|input| {
        let db = project.database();
        input.kind(db).preview(db, input, project.config(), &options).map_err(PreviewFailure::Preview)
    });
    let report = match previewed {
        Ok(report) => report,
        Err(error) => {
            eprintln!("error: {error}");
            let usage = match &error {
                PreviewFailure::Build(crate::project::BuildError::UnknownAsset { .. }) => true,
                PreviewFailure::Build(_) => false,
                PreviewFailure::Preview(error) => error.is_usage(),
            };
            return ExitCode::from(if usage { EXIT_USAGE } else { EXIT_ASSET_FAILED });
        }
    };
    let stand_in = match stand_in {
        crate::kinds::StandIn::Baked => String::new(),
        other => format!("source faces {} onto the planes: ", other.name()),
    };
    for row in &report.rows {
        let metrics = &row.metrics;
        outln!(
            "{}{stand_in}{} views, {} per pixel: mean IoU {:.3}{}, min IoU {:.3} (missed {:.1} %, extra {:.1} % of the \
                source's silhouette), mean PSNR {:.2} dB; the source against itself moved 1 pixel: IoU {:.3}",
            row.label.as_ref().map(|label| format!("{label}: ")).unwrap_or_default(),
            metrics.views.len(),
            match metrics.samples_per_pixel {
                1 => "1 sample".to_string(),
                samples => format!("{samples} samples"),
            },
            metrics.mean_iou,
            metrics.loss_px_shift.map(|loss| format!(" ({loss:.2} px-shift units)")).unwrap_or_default(),
            metrics.min_iou,
            100.0 * metrics.mean_missed,
            100.0 * metrics.mean_extra,
            metrics.mean_psnr,
            metrics.source_shift_iou
        );
    }
    let folders: Vec<String> =
        report.rows.iter().map(|row| crate::diagnostic::display_path(&row.folder).to_string()).collect();
    match &report.chain_sheet {
        Some(sheet) => outln!(
            "wrote {} (each view: the source, then {}) and contact_sheet.png, metrics.json under {}",
            crate::diagnostic::display_path(sheet),
            report.rows.iter().filter_map(|row| row.label.clone()).collect::<Vec<_>>().join(", "),
            folders.join(", ")
        ),
        None => outln!("wrote contact_sheet.png and metrics.json under {}", folders.join(", ")),
    }
    ExitCode::SUCCESS
}

/// Why `cirrus preview` could not render: the asset did not build, or its preview failed.
#[derive(Debug, thiserror::Error)]
enum PreviewFailure {
    #[error(transparent)]
    Build(crate::project::BuildError),
    #[error(transparent)]
    Preview(crate::kinds::PreviewError),
}

fn graph(
    pipeline: PathBuf,
    asset: Option<String>,
    format: crate::graph::GraphFormat,
    options: ProjectOptions,
) -> ExitCode {
    let config = match load_pipeline_or_report(&pipeline) {
        Ok(config) => config,
        Err(code) => return code,
    };
    let mut project = Project::open(config, options);
    if let Err(error) = crate::project::require_assets(asset.as_slice(), &project.asset_list(), &pipeline) {
        eprintln!("error: {error}");
        return ExitCode::from(EXIT_USAGE);
    }
    // A build first (cached work costs nothing), so that nodes carry their states and timings.
    let summary = match project.build(&BuildOptions { omit_unchanged: true, ..Default::default() }, &|_| {}) {
        Ok(summary) => summary,
        Err(error) => {
            eprintln!("error: {error}");
            return ExitCode::from(EXIT_USAGE);
        }
    };
    let graph = match &asset {
        Some(name) => project.graph_of_assets(Some(&[name.clone()].into())).for_asset(name),
        None => project.graph(),
    };
    out!("{}", graph.render(format));
    // As after `build`: the process ends, nothing to free one by one.
    std::mem::forget(project);
    std::mem::forget(graph);
    if summary.all_ok() {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(EXIT_ASSET_FAILED)
    }
}
