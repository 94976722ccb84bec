//! A LOD chain's switch measurements (stage `switch`) and choices: how far each slot holds
//! against the source as an engine draws it (`chain_holds`, `measure_chain`), and the slot shown
//! as each level (an `Auto` level's chosen candidate: `chosen_slot`).

use std::path::Path;
use std::sync::Arc;

use super::queries::{billboard_alpha_cutoff, source_view_mesh, with_mesh_textures, SWITCH};
use super::report::LevelReport;
use super::settings::Settings as Own;
use super::{level_outputs, levels, planes, settings, views};
use crate::cache::CacheEntry;
use crate::db::{load_cached, record_cache_hit, stage_key, timed, Asset, Db};
use crate::diagnostic::Diagnostic;
use crate::kinds::mesh_queries::{loaded_mesh, mesh_cache_key};
use crate::kinds::{AssetOutputs, BakedFiles};

/// How far each level of a chain holds against the source (stage `switch`, `measure_chain`),
/// level by level: a level is measured only up to the level before's switch size (it is never
/// shown larger), so each level's sizes wait for the level before's choice. A level's figures
/// (those of its candidates, measured together: each one's depends on the others', which may
/// outrank it, `preview::holds`) are kept in the persistent cache under the hash of every file
/// its slots write (as engines draw them), the source's mesh and textures, the cutoff, the sizes
/// measured and the GPU family, the source rendered once per view and size for all levels; an
/// edit measures again only the levels it changed and those whose sizes it changed.
#[salsa::tracked(returns(clone))]
pub(crate) fn chain_holds(db: &dyn Db, asset: Asset) -> Result<Arc<Vec<crate::preview::Hold>>, Diagnostic> {
    let mut files = crate::kinds::AssetOutputs::default();
    let (reports, _) = level_outputs::level_files(db, asset, std::path::Path::new(""), &mut files)?;
    let source_key = stage_key(SWITCH)
        .part(crate::gpu::adapter_family())
        .part(&mesh_cache_key(db, asset, asset.main_file(db).clone()).0)
        .part(&billboard_alpha_cutoff(db, asset));
    let source_key = with_mesh_textures(db, asset, source_key);
    let settings = asset.settings(db);
    let slots = levels::slots(settings);
    let level_key = |level_slots: &[u32], sizes: &[u32]| {
        let key = sizes.iter().fold(stage_key(SWITCH).part(&source_key.0), |key, size| key.part(size));
        level_slots
            .iter()
            .fold(key, |key, &slot| {
                let folder = std::path::PathBuf::from(levels::level_folder(settings, slot));
                let slot_files = files.files.iter().filter(|(path, _, _)| path.starts_with(&folder));
                slot_files.fold(key.part(&slot), |key, (path, _, bytes)| key.part(path).part(&blake3::hash(bytes)))
            })
            .finish()
    };
    let label = asset.name(db);
    let from_entry = |entry: CacheEntry| entry.parts::<Vec<crate::preview::Hold>, 0>().map(|(holds, [])| holds);
    let mut holds: Vec<crate::preview::Hold> = slots.iter().map(|_| crate::preview::Hold::unmeasured()).collect();
    let (mut ran, mut shown_up_to) = (false, u32::MAX);
    // The source's renders, shared by the levels' measurements.
    let mut source_views = crate::preview::SourceViews::default();
    for level in 0..levels::level_count(settings) {
        let sizes: Vec<u32> = crate::preview::HOLD_SIZES.into_iter().filter(|&size| size <= shown_up_to).collect();
        // A candidate over its level's bytes is never chosen: it is not measured; nor is a level
        // after one that is never shown.
        let level_slots: Vec<u32> = (0..slots.len() as u32)
            .filter(|&slot| slots[slot as usize].level == level && !sizes.is_empty())
            .filter(|&slot| !over_budget(db, asset, slot, &reports[slot as usize]))
            .collect();
        if !level_slots.is_empty() {
            let key = level_key(&level_slots, &sizes);
            let cached =
                load_cached(db, SWITCH.name, key, from_entry).filter(|cached| cached.len() == level_slots.len());
            let measured = match cached {
                Some(measured) => measured,
                None => {
                    ran = true;
                    let measured = timed(db, SWITCH, label, || {
                        let measured_slots = (level_slots.as_slice(), sizes.as_slice());
                        measure_chain(db, asset, &files, measured_slots, &mut source_views)
                    })?;
                    crate::db::store_cached(db, SWITCH.name, key, || CacheEntry::new(&measured, Vec::new(), true));
                    measured
                }
            };
            for (slot, hold) in level_slots.into_iter().zip(measured) {
                holds[slot as usize] = hold;
            }
        }
        let chosen = chosen_slot(db, asset, level, (&reports, &holds))?;
        shown_up_to = holds[chosen as usize].holds_to.unwrap_or(0).min(shown_up_to);
    }
    if !ran {
        record_cache_hit(db, SWITCH, label);
    }
    Ok(Arc::new(holds))
}

/// The slot shown as each level of the chain (`chosen_slot`).
pub(super) fn chosen_slots(
    db: &dyn Db,
    asset: Asset,
    reports: &[LevelReport],
    holds: &[crate::preview::Hold],
) -> Result<Vec<u32>, Diagnostic> {
    (0..levels::level_count(asset.settings(db))).map(|level| chosen_slot(db, asset, level, (reports, holds))).collect()
}

/// The slot shown as level `level` of the chain: its own, or the `Auto` level's chosen
/// candidate: among those whose bytes on the GPU fit, the one that holds to the largest screen
/// size, then the one that loses least there, then the one with the fewest bytes.
pub(crate) fn chosen_slot(
    db: &dyn Db,
    asset: Asset,
    level: u32,
    (reports, holds): (&[LevelReport], &[crate::preview::Hold]),
) -> Result<u32, Diagnostic> {
    let settings = asset.settings(db);
    if let Some(slot) = levels::chain_slot(settings, level) {
        return Ok(slot);
    }
    let max_bytes = auto_bytes(settings, level).unwrap_or(u64::MAX);
    let slots = levels::slots(settings);
    let fitting = (0..slots.len())
        .filter(|&slot| slots[slot].level == level && !over_budget(db, asset, slot as u32, &reports[slot]));
    let rank = |slot: &usize| {
        let hold = &holds[*slot];
        let at = hold.measured.iter().find(|figures| Some(figures.size) == hold.holds_to).or(hold.measured.first());
        let loss = at.and_then(|figures| figures.loss_px_shift).unwrap_or(0.0);
        (std::cmp::Reverse(hold.holds_to), ordered(loss), reports[*slot].figures.gpu_bytes, *slot)
    };
    fitting.min_by_key(rank).map(|slot| slot as u32).ok_or_else(|| {
        Diagnostic::new(
            asset.main_file(db),
            format!("lod{level}: no candidate fits in {max_bytes} bytes on the GPU (give Auto more bytes)"),
        )
    })
}

/// The bytes of level `level` when it is an `Auto` level.
pub(super) fn auto_bytes(settings: &crate::config::Settings, level: u32) -> Option<u64> {
    match settings.own::<Own>().billboard.lods.get(level as usize) {
        Some(&settings::LodLevel::Auto { max_bytes }) => Some(max_bytes),
        _ => None,
    }
}

/// Whether slot `slot` is a candidate whose bytes on the GPU (its `report`'s) pass its `Auto`
/// level's.
pub(crate) fn over_budget(db: &dyn Db, asset: Asset, slot: u32, report: &LevelReport) -> bool {
    let settings = asset.settings(db);
    let Some(spec) = levels::slots(settings).into_iter().nth(slot as usize).filter(|spec| spec.candidate.is_some())
    else {
        return false;
    };
    let max_bytes = auto_bytes(settings, spec.level).unwrap_or(u64::MAX);
    report.figures.gpu_bytes > max_bytes
}

/// A loss as an integer that orders as the loss does (in millionths of a px-shift unit).
fn ordered(loss: f64) -> i64 {
    (loss * 1e6).round() as i64
}

/// How far each of a chain's slots `measured` holds against its source (stage `switch`): as an
/// engine draws them, read from the build's `files` (`level_files` under an empty folder), over
/// the 26 views at each of `sizes` (`preview::HOLD_SIZES` up to a cap).
pub(crate) fn measure_chain(
    db: &dyn Db,
    asset: Asset,
    files: &AssetOutputs,
    (measured, sizes): (&[u32], &[u32]),
    source_views: &mut crate::preview::SourceViews,
) -> Result<Vec<crate::preview::Hold>, Diagnostic> {
    let settings = asset.settings(db);
    let cutoff = settings.own::<Own>().billboard.alpha_cutoff;
    let loaded = loaded_mesh(db, asset)?;
    let source = source_view_mesh(db, asset, &loaded)?;
    let view = |level: u32| {
        let folder = levels::level_folder(settings, level);
        views::level_view(&BakedFiles::Outputs(files), Path::new(&folder), cutoff)
    };
    let views = measured.iter().map(|&level| view(level)).collect::<Result<Vec<_>, _>>()?;
    let (center, radius) = planes::bounding_sphere(&loaded.mesh.positions);
    let main_file = asset.main_file(db);
    let gpu = crate::gpu::gpu().map_err(|error| Diagnostic::new(main_file, error.to_string()))?;
    let views: Vec<&crate::gpu::LevelView> = views.iter().collect();
    crate::preview::holds(gpu, &source, &views, (center.to_array(), radius), sizes, source_views)
        .map_err(|error| Diagnostic::new(main_file, format!("measuring the chain: {error}")))
}
