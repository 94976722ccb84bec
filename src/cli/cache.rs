//! `cirrus cache stats | explain | gc`: what the local cache folder holds, what the last build
//! found where and why a stage ran, and bounding the folder (least recently used first).

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::Subcommand;

use super::output::{load_pipeline_or_report, out, outln, EXIT_USAGE};
use crate::cache::upkeep::{collect_garbage, entry_files, read_last_build, recorded_key_parts, LastBuild, Miss};
use crate::diagnostic::display_path;
use crate::project::ProjectOptions;

/// `cirrus cache`: what it is asked.
#[derive(Debug, Subcommand)]
pub enum CacheCommand {
    /// Local entries and bytes, and the last build's hits and misses, local and remote.
    Stats {
        /// The pipeline file.
        #[arg(long, default_value = "pipeline.ron")]
        pipeline: PathBuf,
    },
    /// For each stage of an asset: where its result was found, or which part of its key
    /// differs from the nearest entry.
    Explain {
        /// The pipeline file.
        #[arg(long, default_value = "pipeline.ron")]
        pipeline: PathBuf,
        #[arg(long)]
        asset: String,
    },
    /// Deletes the least recently used local entries until the folder holds at most BYTES
    /// (suffixes K, M, G: 1024-based).
    Gc {
        /// The pipeline file.
        #[arg(long, default_value = "pipeline.ron")]
        pipeline: PathBuf,
        #[arg(long, value_name = "BYTES", value_parser = parse_byte_size)]
        max_size: u64,
    },
}

/// `500M`, `2G`, `1048576`: bytes with an optional 1024-based suffix.
fn parse_byte_size(text: &str) -> Result<u64, String> {
    let text = text.trim();
    let (digits, shift) = match text.char_indices().last() {
        Some((at, 'k' | 'K')) => (&text[..at], 10),
        Some((at, 'm' | 'M')) => (&text[..at], 20),
        Some((at, 'g' | 'G')) => (&text[..at], 30),
        Some((at, 't' | 'T')) => (&text[..at], 40),
        _ => (text, 0),
    };
    let value: u64 =
        digits.trim().parse().map_err(|_| format!("`{text}` is not a size in bytes (e.g. 1048576, 500M, 2G)"))?;
    value.checked_mul(1 << shift).ok_or_else(|| format!("`{text}` is too large"))
}

pub fn run(command: CacheCommand, options: ProjectOptions) -> ExitCode {
    match command {
        CacheCommand::Stats { pipeline } => with_cache_folder(&pipeline, |folder, config| {
            let remote = options.remote_cache.apply(config.remote_cache.as_ref());
            out!("{}", stats_text(folder, remote.as_ref().map(|remote| remote.url.as_str())));
            ExitCode::SUCCESS
        }),
        CacheCommand::Explain { pipeline, asset } => with_cache_folder(&pipeline, |folder, config| {
            if !last_build_names(folder).contains(&asset) {
                if let Err(error) =
                    crate::project::require_assets(std::slice::from_ref(&asset), &config.assets, &pipeline)
                {
                    eprintln!("error: {error}");
                    return ExitCode::from(EXIT_USAGE);
                }
            }
            match explain_text(folder, &asset) {
                Some(text) => {
                    out!("{text}");
                    ExitCode::SUCCESS
                }
                None => {
                    eprintln!(
                        "error: no build has recorded `{asset}` in {} yet: run `cirrus build` first",
                        display_path(folder)
                    );
                    ExitCode::from(EXIT_USAGE)
                }
            }
        }),
        CacheCommand::Gc { pipeline, max_size } => with_cache_folder(&pipeline, |folder, _| {
            let collected = collect_garbage(folder, max_size);
            outln!(
                "deleted {} entries ({}), kept {} entries ({}) in {}",
                collected.deleted_entries,
                human_bytes(collected.deleted_bytes),
                collected.kept_entries,
                human_bytes(collected.kept_bytes),
                display_path(folder)
            );
            ExitCode::SUCCESS
        }),
    }
}

/// Runs `body` with the pipeline's local cache folder (`<output>/.cirrus/cache`).
fn with_cache_folder(
    pipeline: &Path,
    body: impl FnOnce(&Path, &crate::config::PipelineConfig) -> ExitCode,
) -> ExitCode {
    let config = match load_pipeline_or_report(pipeline) {
        Ok(config) => config,
        Err(code) => return code,
    };
    body(&config.cache_dir(), &config)
}

fn last_build_names(folder: &Path) -> Vec<String> {
    let names = |last: LastBuild| last.assets.into_iter().map(|asset| asset.name).chain(last.unchanged).collect();
    read_last_build(folder).map(names).unwrap_or_default()
}

/// `cirrus cache stats`: entries and bytes per stage, then the last build's counts.
pub(crate) fn stats_text(folder: &Path, remote: Option<&str>) -> String {
    let mut text = String::new();
    let entries = entry_files(folder);
    let mut per_stage: BTreeMap<&str, (u64, u64)> = BTreeMap::new();
    for entry in &entries {
        let figures = per_stage.entry(entry.stage.as_str()).or_default();
        figures.0 += 1;
        figures.1 += entry.bytes;
    }
    let total: u64 = entries.iter().map(|entry| entry.bytes).sum();
    let _ = writeln!(text, "local cache {}: {} entries, {}", display_path(folder), entries.len(), human_bytes(total));
    for (stage, (count, bytes)) in &per_stage {
        let _ = writeln!(text, "  {stage:<20} {count:>7} entries {:>10}", human_bytes(*bytes));
    }
    let _ = writeln!(text, "shared cache: {}", remote.unwrap_or("none"));
    match read_last_build(folder) {
        None => {
            let _ = writeln!(text, "last build: none recorded");
        }
        Some(last) => {
            let counts = last.counts;
            let _ = writeln!(text, "last build (revision {}):", last.revision);
            let _ = writeln!(text, "  local: {} hits, {} misses", counts.local_hits, counts.local_misses);
            match (counts.remote, &last.remote) {
                (Some(remote), Some(url)) => {
                    let _ = writeln!(
                        text,
                        "  remote {url}: {} hits, {} misses ({} corrupt), {} downloaded; {} uploads ({}), {} already \
                            there; {} errors",
                        remote.hits,
                        remote.misses,
                        remote.corrupt,
                        human_bytes(remote.bytes_downloaded),
                        remote.uploads,
                        human_bytes(remote.bytes_uploaded),
                        remote.already_present,
                        remote.errors
                    );
                }
                _ => {
                    let _ = writeln!(text, "  remote: none");
                }
            }
            let mut statuses: BTreeMap<&str, usize> = BTreeMap::new();
            for (_, status) in last.assets.iter().flat_map(|asset| &asset.stages) {
                *statuses.entry(status.as_str()).or_default() += 1;
            }
            let statuses: Vec<String> = statuses.iter().map(|(status, count)| format!("{count} {status}")).collect();
            let _ = writeln!(text, "  stages: {}", statuses.join(", "));
            if !last.unchanged.is_empty() {
                let _ = writeln!(text, "  assets passed over (nothing they read changed): {}", last.unchanged.len());
            }
        }
    }
    text
}

/// `cirrus cache explain --asset NAME`: every stage instance of the asset in the last build,
/// where its result came from.
pub(crate) fn explain_text(folder: &Path, asset: &str) -> Option<String> {
    let last = read_last_build(folder)?;
    if last.unchanged.iter().any(|name| name == asset) {
        return Some(format!(
            "{asset} in the build of revision {}: passed over: the build record showed that nothing it reads had \
             changed and its artifacts were as written, so no stage was asked for a result\n",
            last.revision
        ));
    }
    let recorded = last.assets.iter().find(|recorded| recorded.name == asset)?;
    let mut text = String::new();
    let _ = writeln!(text, "{asset} in the build of revision {}:", last.revision);
    for (stage, status) in &recorded.stages {
        let said = match status.as_str() {
            "ran" => "ran: no cache held its result",
            "cached" => "cached: from memory or the local cache",
            "remote" => "remote: from the shared cache",
            "failed" => "failed",
            other => other,
        };
        let _ = writeln!(text, "  {stage}: {said}");
    }
    let mut seen = std::collections::HashSet::new();
    let misses: Vec<&Miss> = last
        .misses
        .iter()
        .filter(|miss| miss.asset.as_deref() == Some(asset) && seen.insert((miss.stage.as_str(), miss.key.as_str())))
        .collect();
    // Entries this build stored after missing them are not what an earlier build left.
    let missed_keys: std::collections::HashSet<&str> = last.misses.iter().map(|miss| miss.key.as_str()).collect();
    if !misses.is_empty() {
        let _ = writeln!(text, "cache lookups that found nothing, with the nearest stored entry of the same stage:");
    }
    let mut recorded: BTreeMap<&str, Vec<(String, Vec<String>)>> = BTreeMap::new();
    for miss in misses {
        let candidates = recorded.entry(miss.stage.as_str()).or_insert_with(|| recorded_key_parts(folder, &miss.stage));
        let earlier: Vec<&(String, Vec<String>)> =
            candidates.iter().filter(|(key, _)| !missed_keys.contains(key.as_str())).collect();
        let _ = writeln!(
            text,
            "  {} {}: {}",
            miss.stage,
            &miss.key[..16.min(miss.key.len())],
            nearest_difference(miss, &earlier)
        );
    }
    Some(text)
}

/// Which parts of a missed key differ from the stored key of the same stage that shares the
/// most parts with it (part numbers from 1; the stage name and version are parts 1 and 2).
fn nearest_difference(miss: &Miss, candidates: &[&(String, Vec<String>)]) -> String {
    let shared = |parts: &[String]| parts.iter().zip(&miss.parts).filter(|(a, b)| a == b).count();
    let nearest = candidates
        .iter()
        .filter(|(key, _)| key != &miss.key)
        .max_by_key(|(_, parts)| (shared(parts), parts.len() == miss.parts.len()));
    let Some((key, parts)) = nearest else { return "no stored entry of this stage to compare with".to_string() };
    let mut differences = Vec::new();
    for index in 0..parts.len().max(miss.parts.len()) {
        let (now, then) = (miss.parts.get(index), parts.get(index));
        if now != then {
            let show = |part: Option<&String>| part.map_or("(none)".to_string(), Clone::clone);
            differences.push(format!("part {} is {} (the entry has {})", index + 1, show(now), show(then)));
        }
    }
    let listed = differences.len().min(4);
    let more = if differences.len() > listed {
        format!(", and {} more parts", differences.len() - listed)
    } else {
        String::new()
    };
    format!("nearest {}: {}{more}", &key[..16.min(key.len())], differences[..listed].join("; "))
}

/// Bytes in the largest unit that keeps the figure at or above 1 (1024-based).
pub(crate) fn human_bytes(bytes: u64) -> String {
    const UNITS: [&str; 5] = ["B", "KiB", "MiB", "GiB", "TiB"];
    let mut value = bytes as f64;
    let mut unit = 0;
    while value >= 1024.0 && unit + 1 < UNITS.len() {
        value /= 1024.0;
        unit += 1;
    }
    if unit == 0 {
        format!("{bytes} B")
    } else {
        format!("{value:.1} {}", UNITS[unit])
    }
}
