//! Octahedral impostors baked from a mesh: one orthographic frame per direction of a
//! [`FrameGrid`] (`mesh::octahedral`), each the bounding sphere seen from that direction, laid
//! out in one atlas per surface (frame `j · frames + i` at column `i`, row `j`): the unlit albedo
//! with its coverage in alpha, the normal in the frame's own axes (as a tangent-space normal map
//! stores it, so that it travels as BC5), and the depth across the sphere (as a height map, BC4).
//! Each frame shows only the part of the sphere's image the mesh covers from its direction
//! (`frame_rects`), so the mesh fills the frame's texels.

use glam::Vec3;

use gpu::{Gpu, GpuError, ViewMesh};
use mesh::octahedral::{frame_axes, frame_rect_view_projection, FrameGrid, SQUARE_HULL};
use texture::fill::{fill_from_sources, texel_sources};
use texture::Texture;

/// What an impostor is baked at.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct ImpostorSettings {
    pub grid: FrameGrid,
    /// Each frame's side in texels.
    pub frame_size: u32,
}

/// A baked impostor: its frames' atlases and the sphere they frame. Texels no surface covers
/// take the values of the nearest covered texel of their frame (alpha stays 0), so that
/// filtering and mips pull in no fringe.
#[derive(Clone, Debug, PartialEq)]
pub struct ImpostorFrames {
    pub settings: ImpostorSettings,
    pub center: Vec3,
    pub radius: f32,
    /// sRGB albedo, alpha the share of the texel the mesh covers.
    pub albedo: Texture,
    /// The normal in the frame's axes (x right, y up, z towards the frame's eye, never below 0)
    /// as `0.5 + 0.5 n` in RGB; alpha 255.
    pub normal: Texture,
    /// The depth along the frame's direction in R (0 at the sphere's near side, 255 at its far
    /// side), repeated in G and B; alpha 255.
    pub depth: Texture,
    /// The part of the sphere's image each frame shows (`frame_rects`).
    pub rects: Vec<[f32; 4]>,
}

/// The part of the sphere's image (`[u0, v0, u1, v1]`, as `mesh::octahedral::
/// frame_rect_view_projection` takes it) that each frame of `settings.grid` shows: the bounds
/// of `points` (the corners of the mesh's faces) seen from the frame's direction, widened by a
/// texel and a half of the frame on each side and kept inside the sphere's image. No points:
/// the whole image.
pub fn frame_rects(points: &[Vec3], sphere: (Vec3, f32), settings: ImpostorSettings) -> Vec<[f32; 4]> {
    frame_rects_with_margin(points, sphere, settings.grid, settings.frame_size)
}

/// [`frame_rects`] of `grid` with the margins of frames of `margin_frame` texels (the smallest
/// of the sizes that share one render: see [`reduced_frames`]).
pub fn frame_rects_with_margin(
    points: &[Vec3],
    (center, radius): (Vec3, f32),
    grid: mesh::octahedral::FrameGrid,
    margin_frame: u32,
) -> Vec<[f32; 4]> {
    let radius = radius.max(1e-6);
    let margin_frame = margin_frame.max(1) as f32;
    (0..grid.frame_count())
        .map(|frame| {
            let direction = grid.frame_direction(frame);
            let (right, up) = frame_axes(direction);
            let (mut low, mut high) = ([f32::INFINITY; 2], [f32::NEG_INFINITY; 2]);
            for &point in points {
                let offset = point - center;
                let uv = [offset.dot(right) / (2.0 * radius) + 0.5, 0.5 - offset.dot(up) / (2.0 * radius)];
                for axis in 0..2 {
                    low[axis] = low[axis].min(uv[axis]);
                    high[axis] = high[axis].max(uv[axis]);
                }
            }
            if !(low[0] <= high[0] && low[1] <= high[1]) {
                return mesh::octahedral::FULL_FRAME;
            }
            let mut rect = [0.0f32; 4];
            for axis in 0..2 {
                // At least two texels of the whole image wide, then a texel and a half more each
                // side of what it becomes.
                let middle = 0.5 * (low[axis] + high[axis]);
                let extent = (high[axis] - low[axis]).max(2.0 / margin_frame);
                let margin = extent * 1.5 / margin_frame;
                rect[axis] = (middle - 0.5 * extent - margin).max(0.0);
                rect[axis + 2] = (middle + 0.5 * extent + margin).min(1.0);
            }
            rect
        })
        .collect()
}

/// Directions the outline of [`view_hull`] is taken from (a Fibonacci sphere: about 6° apart).
const HULL_DIRECTIONS: usize = 1024;

/// How far [`view_hull`] stands off the outlines it saw, as a fraction of the radius: the
/// directions between its samples, and the parallax step's reach past the mesh.
const HULL_MARGIN: f32 = 0.03;

/// The polygon a camera-facing impostor is drawn as, instead of the bounding sphere's square:
/// eight points `[x, y]` (counter-clockwise, some may coincide) in the view's right and up axes
/// (`mesh::octahedral::frame_axes` of the direction to the eye) through the sphere's centre,
/// in units of its radius, within the square `[-1, 1]²`. It is the octagon of the slabs `x`,
/// `y`, `x + y` and `x − y` that holds the outline of `points` (the mesh's vertices) seen from
/// every one of [`HULL_DIRECTIONS`] directions, widened by [`HULL_MARGIN`]: a tree's narrow
/// crown and empty corners are no longer drawn and discarded. No points: the square.
pub fn view_hull(points: &[Vec3], (center, radius): (Vec3, f32)) -> [[f32; 2]; 8] {
    use rayon::prelude::*;
    if points.is_empty() {
        return SQUARE_HULL;
    }
    let radius = radius.max(1e-6);
    let golden = std::f32::consts::PI * (3.0 - 5f32.sqrt());
    // Per slab (x, y, x + y, x − y) the most and the least (as the most of the negation).
    let extremes = (0..HULL_DIRECTIONS)
        .into_par_iter()
        .map(|index| {
            let y = 1.0 - 2.0 * (index as f32 + 0.5) / HULL_DIRECTIONS as f32;
            let ring = (1.0 - y * y).max(0.0).sqrt();
            let angle = golden * index as f32;
            let (right, up) = frame_axes(Vec3::new(ring * angle.cos(), y, ring * angle.sin()));
            let mut most = [f32::NEG_INFINITY; 8];
            for &point in points {
                let offset = (point - center) / radius;
                let (x, y) = (offset.dot(right), offset.dot(up));
                for (slot, value) in [x, y, x + y, x - y].into_iter().enumerate() {
                    most[2 * slot] = most[2 * slot].max(value);
                    most[2 * slot + 1] = most[2 * slot + 1].max(-value);
                }
            }
            most
        })
        .reduce(|| [f32::NEG_INFINITY; 8], |a, b| std::array::from_fn(|slot| a[slot].max(b[slot])));
    let diagonal = HULL_MARGIN * std::f32::consts::SQRT_2;
    let (x_max, x_min) = ((extremes[0] + HULL_MARGIN).min(1.0), (-extremes[1] - HULL_MARGIN).max(-1.0));
    let (y_max, y_min) = ((extremes[2] + HULL_MARGIN).min(1.0), (-extremes[3] - HULL_MARGIN).max(-1.0));
    let (s_max, s_min, t_max, t_min) =
        (extremes[4] + diagonal, -extremes[5] - diagonal, extremes[6] + diagonal, -extremes[7] - diagonal);
    if !(x_min < x_max && y_min < y_max) {
        return SQUARE_HULL;
    }
    let clamp = |[x, y]: [f32; 2]| [x.clamp(x_min, x_max), y.clamp(y_min, y_max)];
    [
        [x_max, x_max - t_max],
        [x_max, s_max - x_max],
        [s_max - y_max, y_max],
        [t_min + y_max, y_max],
        [x_min, x_min - t_min],
        [x_min, s_min - x_min],
        [s_min - y_min, y_min],
        [t_max + y_min, y_min],
    ]
    .map(clamp)
}

/// Renders every frame of `settings.grid` of `mesh` (whose bounding sphere is `center`,
/// `radius`) into the atlases.
pub fn bake_impostor(
    gpu: &Gpu,
    mesh: &ViewMesh,
    sphere: (Vec3, f32),
    settings: ImpostorSettings,
) -> Result<ImpostorFrames, GpuError> {
    bake_impostor_with_margin(gpu, mesh, sphere, (settings, settings.frame_size), &base::stop::never)
}

/// [`bake_impostor`] with the frames' margins of `margin_frame`-texel frames
/// ([`frame_rects_with_margin`]), for frames that smaller ones are reduced from; between batches
/// of frames `should_stop` may end it (`GpuError::Stopped`).
pub fn bake_impostor_with_margin(
    gpu: &Gpu,
    mesh: &ViewMesh,
    (center, radius): (Vec3, f32),
    (settings, margin_frame): (ImpostorSettings, u32),
    should_stop: base::stop::ShouldStop,
) -> Result<ImpostorFrames, GpuError> {
    let ImpostorSettings { grid, frame_size } = settings;
    let side = (grid.frames * frame_size) as usize;
    let mut atlases = [(); 3].map(|_| vec![0u8; side * side * 4]);
    let corners: Vec<Vec3> = mesh
        .batches
        .iter()
        .flat_map(|(_, vertices)| vertices.iter().map(|vertex| Vec3::from(vertex.position)))
        .collect();
    let rects = frame_rects_with_margin(&corners, (center, radius), grid, margin_frame);
    let directions: Vec<Vec3> = (0..grid.frame_count()).map(|frame| grid.frame_direction(frame)).collect();
    let cameras: Vec<[[f32; 4]; 4]> = directions
        .iter()
        .zip(&rects)
        .map(|(&direction, &rect)| frame_rect_view_projection(center, radius, direction, rect).to_cols_array_2d())
        .collect();
    let samples = frame_samples_per_axis(frame_size);
    gpu.render_impostor_frames(
        mesh,
        &cameras,
        (frame_size * samples, should_stop),
        |frame, [albedo, normal_depth]| {
            let (albedo, normal_depth) = resolve_frame(&albedo, &normal_depth, frame_size, samples);
            let images = frame_surfaces(&albedo, &normal_depth, directions[frame], frame_size);
            let frame = frame as u32;
            let (column, row) =
                ((frame % grid.frames * frame_size) as usize, (frame / grid.frames * frame_size) as usize);
            let row_bytes = frame_size as usize * 4;
            for (atlas, image) in atlases.iter_mut().zip(&images) {
                for y in 0..frame_size as usize {
                    let at = ((row + y) * side + column) * 4;
                    atlas[at..at + row_bytes].copy_from_slice(&image[y * row_bytes..][..row_bytes]);
                }
            }
        },
    )?;
    let [albedo, normal, depth] = atlases.map(|pixels| Texture::new(side as u32, side as u32, pixels));
    Ok(ImpostorFrames { settings, center, radius, albedo, normal, depth, rects })
}

/// `frames` at frames `factor` times smaller: each atlas reduced as its mip chain reduces it
/// (`texture::mips::reduced_by`: colour in linear light and weighted by alpha, the albedo's
/// alpha-tested coverage at `alpha_cutoff` kept, normals renormalised, depth averaged; a factor
/// that is no power of two in one box filter). A frame's side is a multiple of `factor`, so no
/// texel mixes two frames; the rects stay `frames`'s. The same views at a smaller size without
/// rendering them again: on a software adapter a render of the oak costs about 3 ms at 64²
/// (its 13,806 triangles set up), an impostor frame 12 ms at 256² and 26 at 512².
pub fn reduced_frames(frames: &ImpostorFrames, factor: u32, alpha_cutoff: f32) -> ImpostorFrames {
    use texture::mips::{reduced_by, MipSettings};
    use texture::SurfaceKind;
    let reduce = |image: &Texture, kind: SurfaceKind, alpha_cutoff: Option<f32>| {
        reduced_by(image, MipSettings { kind, alpha_cutoff }, factor)
    };
    let settings =
        ImpostorSettings { frame_size: (frames.settings.frame_size / factor.max(1)).max(1), ..frames.settings };
    ImpostorFrames {
        settings,
        albedo: reduce(&frames.albedo, SurfaceKind::Albedo, Some(alpha_cutoff)),
        normal: reduce(&frames.normal, SurfaceKind::Normal, None),
        depth: reduce(&frames.depth, SurfaceKind::Height, None),
        center: frames.center,
        radius: frames.radius,
        rects: frames.rects.clone(),
    }
}

/// Samples per texel along each axis a frame is rendered with: 4 (16 samples) up to 64-texel
/// frames, then fewer so that a render stays near 256 texels a side (80 texels: 3; 128: 2), and
/// never under 2. A frame's texel covers many of the source's (its leaf cards are a few texels
/// wide): rendered at its own size, alpha-tested materials sample their maps' small mips and
/// lose their leaves. A render costs its texels (an oak frame on llvmpipe: 26 ms at 512², 12 at
/// 256²); frames reduced from a large one (`reduced_frames`) still get 16 samples a texel or
/// more. On the oak's `Auto` chain this took the impostor stage from 3.8 to 2.4 s of work; the
/// impostor candidates' losses moved by −0.05 to +0.10 px-shift units, the picks did not.
pub fn frame_samples_per_axis(frame_size: u32) -> u32 {
    (256 / frame_size.max(1)).clamp(2, 4)
}

/// A frame rendered at `samples`² samples per texel brought to `size`² texels: alpha the share
/// of samples covered, colour (in linear light), normal and depth the mean of the covered ones.
fn resolve_frame(albedo: &[u8], normal_depth: &[u8], size: u32, samples: u32) -> (Vec<u8>, Vec<u8>) {
    if samples == 1 {
        return (albedo.to_vec(), normal_depth.to_vec());
    }
    use texture::color::{linear_to_srgb_u8, srgb_u8_to_linear};
    let (size, samples) = (size as usize, samples as usize);
    let sampled_row = size * samples;
    let mut resolved = (vec![0u8; size * size * 4], vec![0u8; size * size * 4]);
    for y in 0..size {
        for x in 0..size {
            let (mut colour, mut normal, mut depth, mut covered) = ([0.0f32; 3], Vec3::ZERO, 0.0f32, 0usize);
            for sample_y in y * samples..(y + 1) * samples {
                for sample_x in x * samples..(x + 1) * samples {
                    let at = (sample_y * sampled_row + sample_x) * 4;
                    if albedo[at + 3] == 0 {
                        continue;
                    }
                    covered += 1;
                    for channel in 0..3 {
                        colour[channel] += srgb_u8_to_linear(albedo[at + channel]);
                    }
                    let texel = &normal_depth[at..at + 4];
                    normal += Vec3::new(texel[0] as f32, texel[1] as f32, texel[2] as f32) / 127.5 - Vec3::ONE;
                    depth += texel[3] as f32;
                }
            }
            if covered == 0 {
                continue;
            }
            let at = (y * size + x) * 4;
            let share = covered as f32 / (samples * samples) as f32;
            let colour = colour.map(|sum| linear_to_srgb_u8(sum / covered as f32));
            resolved.0[at..at + 4].copy_from_slice(&[colour[0], colour[1], colour[2], (share * 255.0).round() as u8]);
            let normal = (normal.normalize_or(Vec3::Z) * 127.5 + Vec3::splat(127.5)).round();
            let depth = (depth / covered as f32).round() as u8;
            resolved.1[at..at + 4].copy_from_slice(&[normal.x as u8, normal.y as u8, normal.z as u8, depth]);
        }
    }
    resolved
}

/// One frame's albedo, frame-space normal and depth images, filled, from the frame renderer's
/// albedo and world-space normal + depth (seen from `direction`).
fn frame_surfaces(albedo: &[u8], normal_depth: &[u8], direction: Vec3, size: u32) -> [Vec<u8>; 3] {
    let (right, up) = frame_axes(direction);
    let toward = direction.normalize();
    let mut normal = vec![0u8; normal_depth.len()];
    let mut depth = vec![0u8; normal_depth.len()];
    for ((source, normal), depth) in
        normal_depth.chunks_exact(4).zip(normal.chunks_exact_mut(4)).zip(depth.chunks_exact_mut(4))
    {
        let world = Vec3::new(source[0] as f32, source[1] as f32, source[2] as f32) / 127.5 - Vec3::ONE;
        // Facing away from the frame's eye only where a normal map tilts it past the silhouette.
        let seen = Vec3::new(world.dot(right), world.dot(up), world.dot(toward).max(0.0)).normalize_or(Vec3::Z);
        let encoded = (seen * 127.5 + Vec3::splat(127.5)).round().clamp(Vec3::ZERO, Vec3::splat(255.0));
        normal.copy_from_slice(&[encoded.x as u8, encoded.y as u8, encoded.z as u8, 255]);
        depth.copy_from_slice(&[source[3], source[3], source[3], 255]);
    }
    let covered = albedo.chunks_exact(4).enumerate().filter(|(_, texel)| texel[3] > 0).map(|(at, _)| at as u32);
    let sources = texel_sources(size, size, covered);
    if sources.0.is_empty() {
        return [albedo.to_vec(), normal, depth];
    }
    [
        fill_from_sources(albedo, size, &sources, true),
        fill_from_sources(&normal, size, &sources, false),
        fill_from_sources(&depth, size, &sources, false),
    ]
}
