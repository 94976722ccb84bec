//! Previews: a mesh and what stands for it (a LOD, the same mesh remapped onto an atlas)
//! rendered from the 26 directions of a cube (face centres, edge midpoints, corners) under the
//! same orthographic camera and light, compared by silhouette IoU and PSNR, and laid out side by
//! side in a contact sheet. Several stand-ins of one source (a LOD chain's levels) are all
//! compared with the one source render of each view, and a chain sheet shows each view's source
//! beside every stand-in.
//!
//! Every pixel is resolved from several samples (4 × 4 by default): a pixel belongs to a
//! silhouette when at least half of its samples are covered, and its colour is their mean. With
//! one sample per pixel, foliage finer than a pixel makes the IoU measure aliasing: the source
//! against itself moved a quarter pixel along both image axes scored 0.850 (ash) and 0.835
//! (bush); with 16 samples, 0.905 and 0.886.

use glam::Vec3;
use serde::Serialize;

use rayon::prelude::*;

use std::sync::Arc;

use gpu::{Gpu, GpuError, ViewMaterial, ViewMesh};
use texture::mips::MipSettings;
use texture::{SurfaceKind, Texture, TextureSlot};

/// The 26 view directions, unit length: 6 face centres, 12 edge midpoints, 8 corners.
pub fn view_directions() -> Vec<[f32; 3]> {
    let mut directions = Vec::new();
    for nonzero in 1..=3 {
        for x in -1i32..=1 {
            for y in -1i32..=1 {
                for z in -1i32..=1 {
                    if [x, y, z].iter().filter(|&&c| c != 0).count() == nonzero {
                        directions.push(Vec3::new(x as f32, y as f32, z as f32).normalize().to_array());
                    }
                }
            }
        }
    }
    directions
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ViewMetrics {
    pub direction: [f32; 3],
    pub iou: f64,
    /// The source's silhouette pixels the LOD misses, and the LOD's pixels outside the source's
    /// silhouette, each as a fraction of the source's silhouette: a LOD that is too thin misses,
    /// one drawn displaced does both.
    pub missed: f64,
    pub extra: f64,
    pub psnr: f64,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PreviewMetrics {
    /// Samples per pixel behind each silhouette and colour (`samples_per_axis`²).
    pub samples_per_pixel: u32,
    pub views: Vec<ViewMetrics>,
    pub mean_iou: f64,
    pub min_iou: f64,
    pub mean_missed: f64,
    pub mean_extra: f64,
    pub mean_psnr: f64,
    /// The source's silhouette against itself moved one pixel (the mean of a move along each
    /// image axis), over the views: what a pixel of displacement costs this mesh's IoU. Lacy
    /// foliage loses more than a dense crown (corpus: oak 0.879, ash 0.785, bush 0.747), so LODs
    /// of different meshes drawn as displaced score different IoUs.
    pub source_shift_iou: f64,
    /// The LOD's loss in px-shift units: `1 − mean_iou` over the source's own loss when moved one
    /// pixel (`1 − source_shift_iou`); at most 1 means the LOD is as close to the source as the
    /// source is to itself a pixel away, at this view size (DESIGN §3.2). `None` when a pixel
    /// costs the source nothing (an empty view).
    pub loss_px_shift: Option<f64>,
}

/// The result of previewing one LOD: metrics and the contact sheet (PNG bytes).
pub struct Preview {
    pub metrics: PreviewMetrics,
    pub contact_sheet: Vec<u8>,
}

/// The result of previewing several LODs of one source: each one's preview, and the chain sheet
/// (each view's source, then every LOD, side by side; PNG bytes).
pub struct ChainPreview {
    pub levels: Vec<Preview>,
    pub chain_sheet: Vec<u8>,
}

/// How a preview renders: how many of the 26 directions, the image size, and how many samples
/// per pixel along each axis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PreviewSettings {
    pub views: usize,
    pub size: u32,
    pub samples_per_axis: u32,
}

impl Default for PreviewSettings {
    fn default() -> Self {
        PreviewSettings { views: 26, size: 256, samples_per_axis: 4 }
    }
}

/// Renders `source` and `lod` (a mesh or an impostor) from the first `settings.views`
/// directions, framing the sphere at `center` with `radius`.
pub fn preview(
    gpu: &Gpu,
    source: &ViewMesh,
    lod: &gpu::LevelView,
    center: [f32; 3],
    radius: f32,
    settings: PreviewSettings,
) -> Result<Preview, GpuError> {
    let mut chain = preview_chain(gpu, source, &[lod], center, radius, settings)?;
    Ok(chain.levels.remove(0))
}

/// Renders `source` and each of `lods` (meshes or impostors, as an engine draws them) from the
/// first `settings.views` directions (the source once per view), framing the sphere at `center`
/// with `radius`.
pub fn preview_chain(
    gpu: &Gpu,
    source: &ViewMesh,
    lods: &[&gpu::LevelView],
    center: [f32; 3],
    radius: f32,
    settings: PreviewSettings,
) -> Result<ChainPreview, GpuError> {
    // Per view: the source's image, then each LOD's.
    let mut views: Vec<Vec<Vec<u8>>> =
        vec![vec![Vec::new(); 1 + lods.len()]; view_directions().len().min(settings.views)];
    let mut keep = |slot: usize, view: usize, image: &[u8]| views[view][slot] = image.to_vec();
    let sphere = (center, radius);
    let mut metrics = compare_views(gpu, source, lods, sphere, &[settings], &mut SourceViews::default(), &mut keep)?;
    let metrics = metrics.pop().unwrap_or_default();
    let levels = metrics
        .into_iter()
        .enumerate()
        .map(|(level, metrics)| {
            let pairs: Vec<Vec<&[u8]>> =
                views.iter().map(|images| vec![images[0].as_slice(), images[1 + level].as_slice()]).collect();
            Preview { metrics, contact_sheet: contact_sheet(&pairs, settings.size) }
        })
        .collect();
    let groups: Vec<Vec<&[u8]>> = views.iter().map(|images| images.iter().map(Vec::as_slice).collect()).collect();
    Ok(ChainPreview { levels, chain_sheet: contact_sheet(&groups, settings.size) })
}

/// The source's views rendered so far (each with its one-pixel-shift IoU), by size, samples and
/// direction: measurements of one source in one framing that share them render each view once
/// (a chain measured level by level).
#[derive(Default)]
pub struct SourceViews {
    views: std::collections::HashMap<(u32, u32, usize), Arc<(ResolvedView, f64)>>,
}

/// Each of `lods` (meshes or impostors, as an engine draws them) against `source` from the
/// first `settings.views` directions, the source rendered once a view; no image is kept (at
/// 1024 px, a chain's views would take gigabytes).
pub fn compare_only(
    gpu: &Gpu,
    source: &ViewMesh,
    lods: &[&gpu::LevelView],
    (center, radius): ([f32; 3], f32),
    settings: PreviewSettings,
) -> Result<Vec<PreviewMetrics>, GpuError> {
    let mut sources = SourceViews::default();
    let mut metrics = compare_views(gpu, source, lods, (center, radius), &[settings], &mut sources, |_, _, _| {})?;
    Ok(metrics.pop().unwrap_or_default())
}

/// Renders `source` and each of `lods` from the first `settings.views` directions (the source
/// once per view; each in batches, `Gpu::render_views`) and compares them at each of
/// `resolutions`, which render at one side (`size × samples_per_axis`) and so share the renders
/// (64 px at 4 × 4 samples and 128 px at 2 × 2: both 256²); each image (slot 0: the source's,
/// `1 + k`: `lods[k]`'s) at `resolutions[0]` goes to `view_images` with its view's index, which
/// may keep it. Returns each resolution's metrics, one per LOD.
fn compare_views(
    gpu: &Gpu,
    source: &ViewMesh,
    lods: &[&gpu::LevelView],
    (center, radius): ([f32; 3], f32),
    resolutions: &[PreviewSettings],
    source_views: &mut SourceViews,
    mut view_images: impl FnMut(usize, usize, &[u8]),
) -> Result<Vec<Vec<PreviewMetrics>>, GpuError> {
    let Some(&first) = resolutions.first() else {
        return Ok(Vec::new());
    };
    let render_side = |settings: PreviewSettings| settings.size * settings.samples_per_axis.max(1);
    debug_assert!(resolutions.iter().all(|&settings| render_side(settings) == render_side(first)));
    let light = preview_light();
    let directions: Vec<[f32; 3]> = view_directions().into_iter().take(first.views).collect();
    let matrices: Vec<[[f32; 4]; 4]> =
        directions.iter().map(|&direction| view_projection(center, radius, direction)).collect();
    let key = |settings: PreviewSettings, index: usize| (settings.size, settings.samples_per_axis, index);
    let missing: Vec<usize> = (0..matrices.len())
        .filter(|&index| resolutions.iter().any(|&settings| !source_views.views.contains_key(&key(settings, index))))
        .collect();
    let missing_matrices: Vec<[[f32; 4]; 4]> = missing.iter().map(|&index| matrices[index]).collect();
    gpu.render_views(source, &missing_matrices, light, render_side(first), |position, image| {
        for &settings in resolutions {
            let view = resolve_samples(&image, settings.size, settings.samples_per_axis.max(1));
            let shift_iou = one_pixel_shift_iou(&view, settings.size);
            source_views.views.insert(key(settings, missing[position]), Arc::new((view, shift_iou)));
        }
    })?;
    // Each resolution's source views, in view order.
    let sources: Vec<Vec<Arc<(ResolvedView, f64)>>> = resolutions
        .iter()
        .map(|&settings| (0..matrices.len()).map(|index| source_views.views[&key(settings, index)].clone()).collect())
        .collect();
    for (index, view) in sources[0].iter().enumerate() {
        view_images(0, index, &view.0.rgba);
    }
    let mut metrics: Vec<Vec<PreviewMetrics>> = resolutions.iter().map(|_| Vec::with_capacity(lods.len())).collect();
    for (slot, lod) in lods.iter().enumerate() {
        // Each view compared at every resolution as it comes back from its batch.
        let mut level_metrics: Vec<Vec<ViewMetrics>> = resolutions.iter().map(|_| Vec::new()).collect();
        gpu.render_level_views(lod, &matrices, light, render_side(first), |index, image| {
            for (resolution, (settings, source_views)) in resolutions.iter().zip(&sources).enumerate() {
                let lod_view = resolve_samples(&image, settings.size, settings.samples_per_axis.max(1));
                let source_view = &source_views[index].0;
                let overlap = silhouette_overlap(source_view, &lod_view);
                level_metrics[resolution].push(ViewMetrics {
                    direction: directions[index],
                    iou: overlap.iou,
                    missed: overlap.missed,
                    extra: overlap.extra,
                    psnr: rgb_psnr(&source_view.rgba, &lod_view.rgba),
                });
                if resolution == 0 {
                    view_images(1 + slot, index, &lod_view.rgba);
                }
            }
        })?;
        let by_resolution = resolutions.iter().zip(&sources).zip(level_metrics).zip(&mut metrics);
        for (((settings, source_views), views), resolution_metrics) in by_resolution {
            let shift_ious: Vec<f64> = source_views.iter().map(|view| view.1).collect();
            let samples_per_pixel = settings.samples_per_axis * settings.samples_per_axis;
            resolution_metrics.push(summarise_views(views, samples_per_pixel, &shift_ious));
        }
    }
    Ok(metrics)
}

/// The screen sizes (bounding-sphere diameters in pixels) a LOD chain's levels are measured at,
/// smallest first.
pub const HOLD_SIZES: [u32; 5] = [16, 32, 64, 128, 256];

/// Samples per pixel along each axis when a LOD is measured at `size` pixels: 16 a pixel (4 × 4)
/// up to 64 px, then 4 (2 × 2), so that no render is over 512 texels across. A render's cost is
/// its texels (on a software adapter, 90 % of a chain's measuring is rasterising them), and at
/// 128 and 256 px a view holds 65,536 and 262,144 samples at 2 × 2, enough for its IoU; the
/// loss in px-shift units is against the source moved a pixel at the same samples.
pub fn hold_samples_per_axis(size: u32) -> u32 {
    (256 / size.max(1)).clamp(2, 4)
}

/// The most a LOD may lose, in px-shift units, and still hold at a screen size.
pub const HOLD_LOSS: f64 = 1.0;

/// The side (texels) of the renders a size whose own render is larger is screened at: at 256 px
/// a LOD is first measured at one sample a pixel, from the 256² renders of 64 and 128 px (see
/// [`holds`]).
pub const SCREEN_SIDE: u32 = 256;

/// The most a LOD may lose at its screening (px-shift units, at one sample a pixel) and hold
/// there without being measured at [`hold_samples_per_axis`], when it is the only one left to
/// measure ([`holds`]): [`HOLD_LOSS`] over 1.5, where every candidate of the four corpus and
/// bundled trees' wide searches at 256 px lost 1.04–1.32 times as much measured as screened.
pub const SCREEN_HOLD_LOSS: f64 = HOLD_LOSS / 1.5;

/// Samples per pixel along each axis when a LOD is screened at `size` pixels before it is
/// measured there ([`holds`]): `None` where its measurement renders at no more than
/// [`SCREEN_SIDE`] (nothing to save), or `size` does not divide it.
pub fn screen_samples_per_axis(size: u32) -> Option<u32> {
    let over = size * hold_samples_per_axis(size) > SCREEN_SIDE;
    (over && size <= SCREEN_SIDE && SCREEN_SIDE.is_multiple_of(size.max(1))).then(|| SCREEN_SIDE / size.max(1))
}

/// A LOD's figures at one screen size.
#[derive(Clone, Debug, PartialEq, Serialize, serde::Deserialize)]
pub struct SizeFigures {
    pub size: u32,
    /// The samples per pixel behind these figures: [`hold_samples_per_axis`]², or fewer where
    /// its screening ([`screen_samples_per_axis`]) decided the size and it was not measured there
    /// (see [`holds`]).
    pub samples_per_pixel: u32,
    /// `None` when a pixel costs the source nothing there (an empty view): it holds.
    pub loss_px_shift: Option<f64>,
    pub mean_iou: f64,
    pub mean_psnr: f64,
}

/// How far up the screen sizes a LOD holds against its source: its figures at each size
/// measured (smallest first, up to the first size after the smallest at which it loses more than
/// [`HOLD_LOSS`], or at which it was outranked), and the largest size at which it held (`None`:
/// at none).
#[derive(Clone, Debug, PartialEq, Serialize, serde::Deserialize)]
pub struct Hold {
    pub measured: Vec<SizeFigures>,
    pub holds_to: Option<u32>,
    /// The size after which it was measured no further though it held there: it lost more than
    /// [`OUTRANKED_RATIO`] times what the best LOD measured beside it lost (see [`holds`]).
    #[serde(default)]
    pub outranked_at: Option<u32>,
}

impl Hold {
    /// Nothing measured yet.
    pub fn unmeasured() -> Hold {
        Hold { measured: Vec::new(), holds_to: None, outranked_at: None }
    }
}

/// How many times the least loss among LODs measured together (competing for one level) a LOD
/// may lose at a size and still be measured at the next one. A LOD's loss grows with the screen
/// size about in proportion to its error in world units, so two LODs' losses keep their ratio:
/// on the corpus trees it moved by at most 1.3× between 64 and 1024 px (16× the size), and by
/// at most 1.35× between 32 and 256 px in the chains' own measuring; one that loses twice the
/// best never caught up with it.
pub const OUTRANKED_RATIO: f64 = 2.0;

/// The least loss (px-shift units) the outranking compares against: below it, figures are
/// noise (a few samples of 26 views), and no LOD is dropped for losing twice as little.
pub const OUTRANKED_FLOOR: f64 = 0.1;

/// How far each of `lods`, competing for one level of a chain, holds against `source` over `sizes`
/// (smallest first): every size renders the 26 views of the source once and of each LOD still
/// measured, sizes that render at one side ([`hold_samples_per_axis`]: 64 and 128 px, both 256²)
/// once for both, each then judged as if measured alone (the oak's chain: 1.2 s of its 8.5 s of
/// measuring saved, every figure the same). The loss grows with the size (a pixel gets smaller
/// against the same world error), so a LOD is measured no further once it fails, except at the
/// smallest size: there the oak chain's impostors and its 64-quad clouds at 512 KiB and 2 MiB lose
/// 0.92–1.00 units (0.33–0.67 at 32 px), because the source's leaf cards are a sample or two
/// across, drawn from the 1–4-texel levels of their maps' chains, which cannot keep a card's
/// coverage: the source thins out (against itself moved a pixel: IoU 0.32, 0.65 at 32 px), and a
/// level that keeps its foliage covers 170–207 % more than the source's silhouette. Drawing the
/// source from its maps' level 0 alone is no better reference: those levels then lost 0.24–0.50
/// units at 16 px, but the source's own triangles, drawn through their mips, lost 1.95 there and
/// 0.25–0.48 at every size from 32 px up (against 0.06–0.16). Nor, from the second size on, once it
/// is outranked: it held but lost more than [`OUTRANKED_RATIO`] times the least loss there (at
/// least [`OUTRANKED_FLOOR`]); whoever ranks them by how far they hold, then by their loss, would
/// not pick it (on the oak's 2 MiB level: five candidates losing 0.33–0.53 units at 32 px beside
/// triangles losing 0.06, whose renders at 64 to 256 px were half of a chain's measuring).
///
/// A size whose renders are larger than [`SCREEN_SIDE`] (256 px, at 2 × 2 samples: 512²) is
/// first screened at one sample a pixel from the renders of 64 and 128 px, which cost nothing
/// more; a LOD that loses more than [`HOLD_LOSS`] there fails there without its 512² renders,
/// figures and all at one sample a pixel (`SizeFigures::samples_per_pixel`), and the only LOD
/// left, if it loses at most [`SCREEN_HOLD_LOSS`], holds there the same way; every other LOD is
/// measured at 2 × 2 as before, so that candidates ranked by their loss at a size are ranked at
/// one sampling. What that relies on: a LOD loses more at 2 × 2 samples than at one (its
/// aliasing and the source's, moved a pixel, count in both the loss and the unit at one sample),
/// and not 1.5 times more: over every candidate of the wide searches of the corpus oak, ash and
/// bush and the bundled bush at 256 px, 1.04–1.32 times (76 slots, 0.05 units and more). The
/// `billboard-auto` bench prints that range and counts the candidates the screening would
/// misjudge either way (bar: none; none on those four). Their default chains then render nothing
/// at 512²: `switch` work 3.5–5.1 → 2.4–3.1 s, every pick and switch size the same.
pub fn holds(
    gpu: &Gpu,
    source: &ViewMesh,
    lods: &[&gpu::LevelView],
    (center, radius): ([f32; 3], f32),
    sizes: &[u32],
    source_views: &mut SourceViews,
) -> Result<Vec<Hold>, GpuError> {
    let mut holds: Vec<Hold> = lods.iter().map(|_| Hold::unmeasured()).collect();
    let mut stopped = vec![false; lods.len()];
    let resolution = |size: u32| PreviewSettings { views: 26, size, samples_per_axis: hold_samples_per_axis(size) };
    let render_side = |size: u32| size * hold_samples_per_axis(size);
    let figures = |settings: PreviewSettings, metrics: &PreviewMetrics| SizeFigures {
        size: settings.size,
        samples_per_pixel: metrics.samples_per_pixel,
        loss_px_shift: metrics.loss_px_shift,
        mean_iou: metrics.mean_iou,
        mean_psnr: metrics.mean_psnr,
    };
    let fails = |figures: &SizeFigures| figures.loss_px_shift.is_some_and(|loss| loss > HOLD_LOSS);
    // Each LOD's figures at the sizes it was screened at.
    let mut screened: Vec<Vec<SizeFigures>> = lods.iter().map(|_| Vec::new()).collect();
    let mut step = 0;
    while step < sizes.len() {
        let screen = |index: usize| screened[index].iter().find(|figures| figures.size == sizes[step]);
        // A LOD that failed its screening at this size fails here, measured no further.
        for index in 0..lods.len() {
            if let Some(failed) = screen(index).filter(|figures| fails(figures) && !stopped[index] && step > 0) {
                holds[index].measured.push(failed.clone());
                stopped[index] = true;
            }
        }
        let rendered: Vec<usize> = (0..lods.len()).filter(|&index| !stopped[index]).collect();
        if rendered.is_empty() {
            break;
        }
        // The only LOD left, losing so little at its screening that it holds here measured as well,
        // holds here: nothing to rank it against.
        let clear = |figures: &&SizeFigures| figures.loss_px_shift.is_none_or(|loss| loss <= SCREEN_HOLD_LOSS);
        if let [index] = rendered[..] {
            if let Some(held) = screen(index).filter(clear) {
                holds[index].measured.push(held.clone());
                holds[index].holds_to = Some(sizes[step]);
                step += 1;
                continue;
            }
        }
        // The sizes from this one on that render at its side: measured from the same renders, each
        // as if alone (a LOD stopped at one is not counted at the next); then the later sizes
        // screened at this side.
        let shared = sizes[step..].iter().take_while(|&&size| render_side(size) == render_side(sizes[step])).count();
        let mut resolutions: Vec<PreviewSettings> =
            sizes[step..step + shared].iter().map(|&size| resolution(size)).collect();
        resolutions.extend(sizes[step + shared..].iter().filter_map(|&size| {
            let samples_per_axis = screen_samples_per_axis(size)?;
            (size * samples_per_axis == render_side(sizes[step])).then_some(PreviewSettings {
                views: 26,
                size,
                samples_per_axis,
            })
        }));
        let levels: Vec<&gpu::LevelView> = rendered.iter().map(|&index| lods[index]).collect();
        let mut compared =
            compare_views(gpu, source, &levels, (center, radius), &resolutions, source_views, |_, _, _| {})?;
        for (screen_metrics, &settings) in compared.split_off(shared).into_iter().zip(&resolutions[shared..]) {
            for (&index, metrics) in rendered.iter().zip(&screen_metrics) {
                screened[index].push(figures(settings, metrics));
            }
        }
        for (size_metrics, &settings) in compared.into_iter().zip(&resolutions) {
            let measured: Vec<usize> = rendered.iter().copied().filter(|&index| !stopped[index]).collect();
            let size_figures = rendered.iter().copied().zip(size_metrics).filter(|(index, _)| measured.contains(index));
            for (index, metrics) in size_figures {
                let size_figures = figures(settings, &metrics);
                let held = !fails(&size_figures);
                holds[index].measured.push(size_figures);
                if held {
                    holds[index].holds_to = Some(settings.size);
                } else if step > 0 {
                    stopped[index] = true;
                }
            }
            if step > 0 {
                outrank(&mut holds, &measured, &mut stopped);
            }
            step += 1;
        }
    }
    Ok(holds)
}

/// Stops measuring the LODs of `measured` that held at the size just measured but lost more than
/// [`OUTRANKED_RATIO`] times the least loss of those that held there (see [`holds`]).
fn outrank(holds: &mut [Hold], measured: &[usize], stopped: &mut [bool]) {
    // Each LOD that held at the size just measured, with its loss there.
    let held: Vec<(usize, u32, f64)> = measured
        .iter()
        .filter_map(|&index| {
            let figures = holds[index].measured.last()?;
            let loss = figures.loss_px_shift.unwrap_or(0.0);
            (holds[index].holds_to == Some(figures.size)).then_some((index, figures.size, loss))
        })
        .collect();
    let Some(best) = held.iter().map(|&(_, _, loss)| loss).min_by(f64::total_cmp) else {
        return;
    };
    let bar = OUTRANKED_RATIO * best.max(OUTRANKED_FLOOR);
    for (index, size, _) in held.into_iter().filter(|&(_, _, loss)| loss > bar) {
        holds[index].outranked_at = Some(size);
        stopped[index] = true;
    }
}

/// A chain's switch sizes from how far each level holds: level `k` may stand in for level
/// `k − 1` (level 0: for the source) while the object's bounding sphere is at most `switch[k]`
/// pixels across: the largest size at which it held, and no more than the level before's (so
/// that a level is never shown closer than a more detailed one). 0: never (it held at no size
/// measured).
pub fn switch_sizes(holds: &[Hold]) -> Vec<u32> {
    let mut sizes: Vec<u32> = Vec::with_capacity(holds.len());
    for hold in holds {
        let before = sizes.last().copied().unwrap_or(u32::MAX);
        sizes.push(hold.holds_to.unwrap_or(0).min(before));
    }
    sizes
}

/// Why a level of a chain is never shown (see [`never_shown_levels`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NeverShown {
    /// It held within one px-shift unit at no size measured (its switch size is 0).
    HoldsAtNoSize,
    /// The next level holds as far, up to this size: it takes over wherever this one would show.
    NextHoldsAsFar(u32),
}

/// The levels of a chain with these `switch_sizes` (from [`switch_sizes`]) that are never shown,
/// and why: each costs its bytes and its bake for nothing.
pub fn never_shown_levels(switch_sizes: &[u32]) -> Vec<(usize, NeverShown)> {
    let next = |level: usize| switch_sizes.get(level + 1).copied();
    (0..switch_sizes.len())
        .filter_map(|level| match switch_sizes[level] {
            0 => Some((level, NeverShown::HoldsAtNoSize)),
            size if next(level) == Some(size) => Some((level, NeverShown::NextHoldsAsFar(size))),
            _ => None,
        })
        .collect()
}

/// Two renders of one view cross-faded as a screen-door (dithered) fade draws them: each pixel
/// of `from` and `into` (RGBA8, `size`² each) comes from `into` where the 4 × 4 ordered-dither
/// threshold at that pixel is below `share`, else from `from`; an engine gets the same by
/// discarding those pixels in each level's shader. `share` 0: `from`; 1: `into`.
pub fn dithered_cross_fade(from: &[u8], into: &[u8], size: u32, share: f32) -> Vec<u8> {
    const BAYER: [[u8; 4]; 4] = [[0, 8, 2, 10], [12, 4, 14, 6], [3, 11, 1, 9], [15, 7, 13, 5]];
    let mut image = from.to_vec();
    for (index, pixel) in image.chunks_exact_mut(4).enumerate() {
        let (x, y) = (index % size as usize, index / size as usize);
        let threshold = (BAYER[y % 4][x % 4] as f32 + 0.5) / 16.0;
        if threshold < share {
            pixel.copy_from_slice(&into[4 * index..4 * index + 4]);
        }
    }
    image
}

/// The mean and worst of one LOD's per-view figures.
fn summarise_views(views: Vec<ViewMetrics>, samples_per_pixel: u32, source_shift_ious: &[f64]) -> PreviewMetrics {
    let mean = |figure: fn(&ViewMetrics) -> f64| views.iter().map(figure).sum::<f64>() / views.len().max(1) as f64;
    let (mean_iou, mean_missed, mean_extra, mean_psnr) =
        (mean(|view| view.iou), mean(|view| view.missed), mean(|view| view.extra), mean(|view| view.psnr));
    let min_iou = views.iter().map(|view| view.iou).fold(1.0, f64::min);
    let source_shift_iou = source_shift_ious.iter().sum::<f64>() / source_shift_ious.len().max(1) as f64;
    let loss_px_shift = (source_shift_iou < 1.0).then(|| (1.0 - mean_iou) / (1.0 - source_shift_iou));
    PreviewMetrics {
        samples_per_pixel,
        views,
        mean_iou,
        min_iou,
        mean_missed,
        mean_extra,
        mean_psnr,
        source_shift_iou,
        loss_px_shift,
    }
}

/// A view resolved to its pixels: the sRGB colour (the mean of the pixel's samples, taken in
/// linear light; alpha 255 where any sample is covered) and how many samples are covered.
pub struct ResolvedView {
    pub rgba: Vec<u8>,
    pub covered: Vec<u16>,
    pub samples_per_pixel: u16,
}

impl ResolvedView {
    /// Whether pixel `index` is inside the silhouette: at least half of its samples covered.
    pub fn in_silhouette(&self, index: usize) -> bool {
        2 * self.covered[index] >= self.samples_per_pixel
    }
}

/// Box-resolves an RGBA image of `size × samples_per_axis` pixels square (from
/// [`Gpu::render_view`]: alpha 255 where a surface was drawn) into `size`² pixels.
pub fn resolve_samples(samples: &[u8], size: u32, samples_per_axis: u32) -> ResolvedView {
    let (size, per_axis) = (size as usize, samples_per_axis as usize);
    let sample_row = size * per_axis * 4;
    let mut rgba = vec![0u8; size * size * 4];
    let mut covered = vec![0u16; size * size];
    rgba.par_chunks_mut(size * 4).zip(covered.par_chunks_mut(size)).enumerate().for_each(
        |(y, (rgba_row, covered_row))| {
            for x in 0..size {
                let (mut linear, mut count) = ([0.0f32; 3], 0u16);
                for sample_y in y * per_axis..(y + 1) * per_axis {
                    let row = &samples[sample_y * sample_row..(sample_y + 1) * sample_row];
                    for sample in row[x * per_axis * 4..(x + 1) * per_axis * 4].chunks_exact(4) {
                        for (sum, &value) in linear.iter_mut().zip(sample) {
                            *sum += texture::color::srgb_u8_to_linear(value);
                        }
                        count += (sample[3] > 0) as u16;
                    }
                }
                let scale = 1.0 / (per_axis * per_axis) as f32;
                for (channel, sum) in linear.iter().enumerate() {
                    rgba_row[x * 4 + channel] = texture::color::linear_to_srgb_u8(sum * scale);
                }
                rgba_row[x * 4 + 3] = if count > 0 { 255 } else { 0 };
                covered_row[x] = count;
            }
        },
    );
    ResolvedView { rgba, covered, samples_per_pixel: (per_axis * per_axis) as u16 }
}

/// The light direction of every preview render.
pub fn preview_light() -> [f32; 3] {
    Vec3::new(0.4, 0.8, 0.45).normalize().to_array()
}

/// The orthographic camera of the previews: looking at `center` from `direction` (unit length),
/// framing the sphere of `radius`.
pub fn view_projection(center: [f32; 3], radius: f32, direction: [f32; 3]) -> [[f32; 4]; 4] {
    let (center, radius, direction) = (Vec3::from(center), radius.max(1e-6), Vec3::from(direction));
    let up = if direction.y.abs() > 0.9 { Vec3::Z } else { Vec3::Y };
    let view = glam::camera::rh::view::look_at_mat4(center + direction * 2.0 * radius, center, up);
    let projection =
        glam::camera::rh::proj::directx::orthographic(-radius, radius, -radius, radius, 0.5 * radius, 3.5 * radius);
    (projection * view).to_cols_array_2d()
}

/// The centre of the bounding box of `mesh`'s vertices and the radius around it that holds them.
pub fn bounding_sphere(mesh: &ViewMesh) -> ([f32; 3], f32) {
    let positions =
        || mesh.batches.iter().flat_map(|(_, vertices)| vertices.iter().map(|vertex| Vec3::from(vertex.position)));
    let (min, max) = positions()
        .fold((Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)), |(min, max), p| (min.min(p), max.max(p)));
    if min.x > max.x {
        return ([0.0; 3], 1.0);
    }
    let center = 0.5 * (min + max);
    (center.to_array(), positions().map(|p| p.distance(center)).fold(0.0, f32::max))
}

/// How the silhouette of `lod` overlaps that of `source`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SilhouetteOverlap {
    /// |S ∩ L| / |S ∪ L|; 1 when both are empty.
    pub iou: f64,
    /// |S \ L| / |S| and |L \ S| / |S| (0 when the source is empty).
    pub missed: f64,
    pub extra: f64,
}

/// The overlap of the silhouettes (pixels at least half covered) of `source` and `lod`.
pub fn silhouette_overlap(source: &ResolvedView, lod: &ResolvedView) -> SilhouetteOverlap {
    let (mut both, mut source_only, mut lod_only) = (0u64, 0u64, 0u64);
    for index in 0..source.covered.len().min(lod.covered.len()) {
        match (source.in_silhouette(index), lod.in_silhouette(index)) {
            (true, true) => both += 1,
            (true, false) => source_only += 1,
            (false, true) => lod_only += 1,
            (false, false) => {}
        }
    }
    let either = both + source_only + lod_only;
    let source_area = (both + source_only).max(1) as f64;
    SilhouetteOverlap {
        iou: if either == 0 { 1.0 } else { both as f64 / either as f64 },
        missed: source_only as f64 / source_area,
        extra: lod_only as f64 / source_area,
    }
}

/// The IoU of a `size`² view's silhouette with itself moved one pixel, the mean of a move along
/// x and one along y (1 for an empty silhouette).
pub fn one_pixel_shift_iou(view: &ResolvedView, size: u32) -> f64 {
    let size = size as usize;
    let inside = |x: usize, y: usize| x < size && y < size && view.in_silhouette(y * size + x);
    let mut ious = [0.0; 2];
    for (iou, (dx, dy)) in ious.iter_mut().zip([(1, 0), (0, 1)]) {
        let (mut both, mut either) = (0u64, 0u64);
        // Over the image grown by a pixel, so that nothing moved out of it is lost.
        for y in 0..=size {
            for x in 0..=size {
                let here = inside(x, y);
                let moved = x >= dx && y >= dy && inside(x - dx, y - dy);
                both += (here && moved) as u64;
                either += (here || moved) as u64;
            }
        }
        *iou = if either == 0 { 1.0 } else { both as f64 / either as f64 };
    }
    0.5 * (ious[0] + ious[1])
}

/// PSNR of the colour (background included), capped at 100 dB.
pub(crate) fn rgb_psnr(a: &[u8], b: &[u8]) -> f64 {
    let mut squared = 0u64;
    for (x, y) in a.chunks_exact(4).zip(b.chunks_exact(4)) {
        for channel in 0..3 {
            let difference = x[channel] as i64 - y[channel] as i64;
            squared += (difference * difference) as u64;
        }
    }
    let samples = (a.len() / 4 * 3).max(1) as f64;
    if squared == 0 {
        return 100.0;
    }
    (10.0 * (255.0f64 * 255.0 / (squared as f64 / samples)).log10()).min(100.0)
}

/// Groups of views side by side (source | LOD, or source | every level of a chain), as many
/// groups per row as make about eight images (fewer when there are fewer groups), 8 pixels
/// between groups, as an opaque PNG.
fn contact_sheet(groups: &[Vec<&[u8]>], size: u32) -> Vec<u8> {
    let per_group = groups.first().map_or(2, Vec::len).max(1);
    let per_row = (8 / per_group).min(groups.len()).max(1);
    let rows = groups.len().div_ceil(per_row).max(1);
    let group_width = per_group * size as usize;
    let (width, height) = (per_row * group_width + (per_row - 1) * 8, rows * size as usize + (rows - 1) * 8);
    let mut pixels = vec![255u8; width * height * 4];
    for (index, images) in groups.iter().enumerate() {
        let (row, column) = (index / per_row, index % per_row);
        for (half, image) in images.iter().enumerate() {
            let x0 = column * (group_width + 8) + half * size as usize;
            let y0 = row * (size as usize + 8);
            for y in 0..size as usize {
                for x in 0..size as usize {
                    let from = (y * size as usize + x) * 4;
                    let to = ((y0 + y) * width + x0 + x) * 4;
                    pixels[to..to + 3].copy_from_slice(&image[from..from + 3]);
                    pixels[to + 3] = 255;
                }
            }
        }
    }
    texture::preview::preview_png(&texture::Texture::new(width as u32, height as u32, pixels))
}

/// A material's decoded maps (full resolution) and factors, as a preview draws them.
pub struct MaterialMaps {
    pub albedo: Option<Arc<Texture>>,
    /// A separate opacity map (its red channel: see `texture::opacity_channel`).
    pub opacity: Option<Arc<Texture>>,
    /// A tangent-space normal map with X, Y and Z.
    pub normal: Option<Arc<Texture>>,
    /// The albedo's colour factor, and the opacity in alpha.
    pub albedo_factor: [f32; 4],
}

/// `maps` mipmapped for rendering, alpha-tested at `alpha_cutoff` with the coverage kept at every
/// level (as the bakes keep it).
pub fn view_material(maps: &MaterialMaps, alpha_cutoff: f32) -> ViewMaterial {
    let levels = |texture: &Option<Arc<Texture>>, kind: SurfaceKind, alpha_cutoff: Option<f32>| {
        texture.as_ref().map(|texture| Arc::new(texture::mips::mip_chain(texture, MipSettings { kind, alpha_cutoff })))
    };
    ViewMaterial {
        albedo: levels(&maps.albedo, SurfaceKind::Albedo, Some(alpha_cutoff)),
        opacity: levels(&maps.opacity, SurfaceKind::Albedo, Some(alpha_cutoff)),
        normal: levels(&maps.normal, SurfaceKind::Normal, None),
        normal_has_z: true,
        albedo_factor: maps.albedo_factor,
        alpha_cutoff,
    }
}

/// `mesh` as a preview draws it: every face, each material with the maps `map` gives for it
/// (`None`: the factor alone), alpha-tested at `alpha_cutoff`.
pub fn mesh_view<E>(
    mesh: &mesh::Mesh,
    tangents: &[[f32; 4]],
    alpha_cutoff: f32,
    map: impl Fn(&mesh::MeshMaterial, TextureSlot) -> Result<Option<Arc<Texture>>, E>,
) -> Result<ViewMesh, E> {
    let materials = mesh
        .materials
        .iter()
        .map(|material| {
            let [r, g, b] = material.albedo_factor;
            let maps = MaterialMaps {
                albedo: map(material, TextureSlot::Albedo)?,
                opacity: map(material, TextureSlot::Opacity)?,
                normal: map(material, TextureSlot::Normal)?,
                albedo_factor: [r, g, b, material.opacity],
            };
            Ok(view_material(&maps, alpha_cutoff))
        })
        .collect::<Result<Vec<_>, E>>()?;
    Ok(ViewMesh { batches: gpu::face_batches(mesh, tangents, 0..mesh.triangles.len() as u32), materials })
}
