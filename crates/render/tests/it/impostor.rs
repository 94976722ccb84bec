//! Octahedral impostor frames (`mesh::octahedral`, `shaders/impostor.wgsl`): the frames' view
//! directions and the three frames blended from a direction, against hand-computed ones; the
//! weights continuous and 1 at a frame's own direction; and the shader, run on the GPU, picking
//! the same frames with the same weights as the reference.

use std::collections::BTreeMap;

use glam::Vec3;
use mesh::octahedral::{decode, encode, FrameGrid, Sphere};

fn close(a: Vec3, b: Vec3) -> bool {
    a.distance(b) < 1e-5
}

#[test]
fn frames_are_seen_from_the_grid_s_points_on_the_hemi_and_the_full_octahedron() {
    let hemi = FrameGrid { frames: 3, sphere: Sphere::Hemi };
    let diagonal = std::f32::consts::FRAC_1_SQRT_2;
    let expected_hemi = [
        (0, Vec3::new(-1.0, 0.0, 0.0)),
        (1, Vec3::new(-diagonal, 0.0, diagonal)),
        (2, Vec3::new(0.0, 0.0, 1.0)),
        (4, Vec3::Y),
        (6, Vec3::new(0.0, 0.0, -1.0)),
        (8, Vec3::X),
    ];
    for (frame, direction) in expected_hemi {
        assert!(close(hemi.frame_direction(frame), direction), "hemi frame {frame}: {}", hemi.frame_direction(frame));
    }
    let full = FrameGrid { frames: 3, sphere: Sphere::Full };
    let expected_full = [
        (0, Vec3::NEG_Y),
        (1, Vec3::NEG_Z),
        (2, Vec3::NEG_Y),
        (3, Vec3::NEG_X),
        (4, Vec3::Y),
        (5, Vec3::X),
        (7, Vec3::Z),
        (8, Vec3::NEG_Y),
    ];
    for (frame, direction) in expected_full {
        assert!(close(full.frame_direction(frame), direction), "full frame {frame}: {}", full.frame_direction(frame));
    }
    // Views from below on a hemi-octahedron use the horizon's frames.
    assert!(close(decode(encode(Vec3::new(1.0, -5.0, 0.0), Sphere::Hemi), Sphere::Hemi), Vec3::X));
}

#[test]
fn a_direction_blends_the_three_frames_of_its_half_cell_by_barycentric_weights() {
    let hemi = FrameGrid { frames: 3, sphere: Sphere::Hemi };
    // (1, 3, 0) / 4 → square (0.25, 0.25) → grid (1.25, 1.25): the lower half of cell (1, 1).
    let blend = hemi.blend(Vec3::new(1.0, 3.0, 0.0));
    assert_eq!(blend, [(4, 0.5), (5, 0.25), (7, 0.25)]);
    // (1, 1, 0) / 2 → grid (1.5, 1.5): on the cell's anti-diagonal, between frames 5 and 7.
    assert_eq!(hemi.blend(Vec3::new(1.0, 1.0, 0.0)), [(4, 0.0), (5, 0.5), (7, 0.5)]);
    // (3, 1, 0) / 4 → square (0.75, 0.75) → grid (1.75, 1.75): the upper half, toward frame 8.
    assert_eq!(hemi.blend(Vec3::new(3.0, 1.0, 0.0)), [(8, 0.5), (5, 0.25), (7, 0.25)]);
    // On the full octahedron, where the equator runs along a cell's main diagonal, the cell
    // splits along it: (−0.25, 0.25, 0.5) → square (−0.25, 0.5) → grid (0.75, 1.5), cell (0, 1).
    let coarse = FrameGrid { frames: 3, sphere: Sphere::Full };
    assert_eq!(coarse.blend(Vec3::new(-0.25, 0.25, 0.5)), [(3, 0.25), (4, 0.25), (7, 0.5)]);
    let full = FrameGrid { frames: 5, sphere: Sphere::Full };
    // Straight down on the full octahedron: the grid's corner frame alone.
    let down = full.blend(Vec3::NEG_Y);
    let weight_of = |blend: [(u32, f32); 3], frame: u32| -> f32 {
        blend.iter().filter(|(found, _)| *found == frame).map(|(_, weight)| weight).sum()
    };
    assert_eq!(weight_of(down, 24), 1.0, "{down:?}");
}

/// Each frame's weight in a blend (frames of weight 0 left out).
fn weights(blend: [(u32, f32); 3]) -> BTreeMap<u32, f32> {
    let mut weights = BTreeMap::new();
    for (frame, weight) in blend {
        *weights.entry(frame).or_insert(0.0) += weight;
    }
    weights.retain(|_, weight| weight.abs() > 1e-6);
    weights
}

/// Each seen direction's weight in a blend (a frame's direction rounded to 1e-4), so that
/// frames seen from the same direction count as one.
fn by_direction(grid: FrameGrid, blend: [(u32, f32); 3]) -> BTreeMap<[i32; 3], f32> {
    let mut weights = BTreeMap::new();
    for (frame, weight) in blend {
        let key = grid.frame_direction(frame).to_array().map(|value| (value * 1e4).round() as i32);
        *weights.entry(key).or_insert(0.0) += weight;
    }
    weights.retain(|_, weight| weight.abs() > 1e-6);
    weights
}

/// Directions all over the sphere (a golden-angle spiral), the axes, and every frame's own.
fn directions(grid: FrameGrid, count: usize) -> Vec<Vec3> {
    let golden = std::f32::consts::PI * (3.0 - 5f32.sqrt());
    let mut directions: Vec<Vec3> = (0..count)
        .map(|index| {
            let y = 1.0 - 2.0 * (index as f32 + 0.5) / count as f32;
            let radius = (1.0 - y * y).sqrt();
            let angle = golden * index as f32;
            Vec3::new(radius * angle.cos(), y, radius * angle.sin())
        })
        .collect();
    directions.extend([Vec3::X, Vec3::NEG_X, Vec3::Y, Vec3::NEG_Y, Vec3::Z, Vec3::NEG_Z]);
    directions.extend((0..grid.frame_count()).map(|frame| grid.frame_direction(frame)));
    directions
}

#[test]
fn weights_sum_to_one_are_one_at_a_frame_s_own_direction_and_move_smoothly() {
    for sphere in [Sphere::Hemi, Sphere::Full] {
        let grid = FrameGrid { frames: 8, sphere };
        // (The full octahedron's border frames come in pairs, and its corners in fours, seen
        // from the same direction: one of them takes it.)
        for frame in 0..grid.frame_count() {
            let direction = grid.frame_direction(frame);
            let blend = weights(grid.blend(direction));
            let whole = blend.iter().find(|(_, weight)| (*weight - 1.0).abs() < 1e-4);
            assert!(
                whole.is_some_and(|(&found, _)| close(grid.frame_direction(found), direction)),
                "{sphere:?} frame {frame}: {blend:?}"
            );
        }
        for direction in directions(grid, 2000) {
            let blend = grid.blend(direction);
            let sum: f32 = blend.iter().map(|(_, weight)| weight).sum();
            assert!((sum - 1.0).abs() < 1e-5 && blend.iter().all(|&(_, weight)| weight >= -1e-6), "{blend:?}");
            assert!(blend.iter().all(|&(frame, _)| frame < grid.frame_count()), "{blend:?}");
            // A small turn of the view moves each frame's weight a little (no frame pops in);
            // but for a view from well below a hemi-octahedron, whose horizon frame follows
            // the view's bearing, which a small turn under the pole swings far.
            if sphere == Sphere::Hemi && direction.y < -0.5 {
                continue;
            }
            // (Frames are told apart by direction: across the full octahedron's folded border the
            // same views are its mirrored frames.)
            let turned = by_direction(grid, grid.blend(direction + Vec3::new(1e-3, 0.0, 1e-3)));
            let here = by_direction(grid, blend);
            for frame in here.keys().chain(turned.keys()) {
                let change = (here.get(frame).unwrap_or(&0.0) - turned.get(frame).unwrap_or(&0.0)).abs();
                assert!(change < 0.05, "{sphere:?} {direction}: {here:?} → {turned:?}");
            }
            if sphere == Sphere::Full || direction.y >= 0.0 {
                let back = decode(encode(direction, sphere), sphere);
                assert!(back.distance(direction.normalize()) < 1e-4, "{direction} → {back}");
            }
        }
    }
}

#[test]
fn the_shader_picks_the_same_frames_with_the_same_weights_as_the_reference() {
    let gpu = gpu::gpu().expect("a GPU adapter (llvmpipe in CI)");
    for (frames, sphere) in [(8, Sphere::Hemi), (12, Sphere::Full), (2, Sphere::Full)] {
        let grid = FrameGrid { frames, sphere };
        let directions = directions(grid, 4000);
        let arrays: Vec<[f32; 3]> = directions.iter().map(|direction| direction.to_array()).collect();
        let shader = gpu.impostor_blends(grid, &arrays).expect("the shader runs");
        assert_eq!(shader.len(), directions.len());
        for (direction, blend) in directions.iter().zip(shader) {
            let (gpu_weights, reference) = (weights(blend), weights(grid.blend(*direction)));
            let seen: std::collections::BTreeSet<&u32> = gpu_weights.keys().chain(reference.keys()).collect();
            for frame in seen {
                let difference = (gpu_weights.get(frame).unwrap_or(&0.0) - reference.get(frame).unwrap_or(&0.0)).abs();
                assert!(
                    difference < 1e-4,
                    "{frames}×{frames} {sphere:?} {direction}: GPU {gpu_weights:?}, reference {reference:?}"
                );
            }
        }
    }
}

/// A view of the OBJ `text` (no materials: one plain, opaque one).
fn view_of(text: &str) -> gpu::ViewMesh {
    let (mesh, _) =
        mesh::load_mesh(std::path::Path::new("a.obj"), text.as_bytes(), &Default::default(), std::path::Path::new(""))
            .expect("loads");
    render::preview::mesh_view(&mesh, &[], 0.5, |_, _| Ok::<_, ()>(None)).expect("a view")
}

/// A unit sphere at the origin, `rings` × `2 rings` quads.
fn sphere_obj(rings: u32) -> String {
    let mut obj = String::new();
    let segments = 2 * rings;
    for ring in 0..=rings {
        let polar = std::f32::consts::PI * ring as f32 / rings as f32;
        for segment in 0..segments {
            let azimuth = std::f32::consts::TAU * segment as f32 / segments as f32;
            let (x, y, z) = (polar.sin() * azimuth.cos(), polar.cos(), polar.sin() * azimuth.sin());
            obj.push_str(&format!("v {x} {y} {z}\nvn {x} {y} {z}\n"));
        }
    }
    for ring in 0..rings {
        for segment in 0..segments {
            let at = |ring: u32, segment: u32| ring * segments + segment % segments + 1;
            let [a, b, c, d] =
                [at(ring, segment), at(ring, segment + 1), at(ring + 1, segment + 1), at(ring + 1, segment)];
            obj.push_str(&format!("f {a}//{a} {b}//{b} {c}//{c}\nf {a}//{a} {c}//{c} {d}//{d}\n"));
        }
    }
    obj
}

/// An axis-aligned box's OBJ faces from `low` to `high`, its vertices numbered from `first`.
fn box_obj(low: [f32; 3], high: [f32; 3], first: u32) -> String {
    let mut obj = String::new();
    for corner in 0..8 {
        let pick = |axis: usize| if corner >> axis & 1 == 1 { high[axis] } else { low[axis] };
        obj.push_str(&format!("v {} {} {}\n", pick(0), pick(1), pick(2)));
    }
    for [a, b, c, d] in [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]] {
        let [a, b, c, d] = [a, b, c, d].map(|corner| first + corner);
        obj.push_str(&format!("f {a} {b} {c}\nf {a} {c} {d}\n"));
    }
    obj
}

/// One frame's texels (RGBA8 rows) cut out of an atlas.
fn frame_texels(atlas: &texture::Texture, grid: FrameGrid, size: u32, frame: u32) -> Vec<[u8; 4]> {
    let (column, row) = (frame % grid.frames * size, frame / grid.frames * size);
    let mut texels = Vec::new();
    for y in row..row + size {
        for x in column..column + size {
            let at = ((y * atlas.width + x) * 4) as usize;
            texels.push(atlas.pixels[at..at + 4].try_into().unwrap());
        }
    }
    texels
}

#[test]
fn a_sphere_s_frames_each_show_a_disc_facing_the_frame_s_direction_nearest_at_its_centre() {
    let gpu = gpu::gpu().expect("a GPU adapter (llvmpipe in CI)");
    let (grid, size) = (FrameGrid { frames: 4, sphere: Sphere::Hemi }, 64);
    let settings = render::impostor::ImpostorSettings { grid, frame_size: size };
    let frames = render::impostor::bake_impostor(gpu, &view_of(&sphere_obj(32)), (Vec3::ZERO, 1.0), settings).unwrap();
    assert_eq!((frames.albedo.width, frames.normal.height, frames.depth.height), (4 * 64, 4 * 64, 4 * 64));
    for frame in 0..grid.frame_count() {
        let albedo = frame_texels(&frames.albedo, grid, size, frame);
        let covered = albedo.iter().filter(|texel| texel[3] > 127).count() as f64 / albedo.len() as f64;
        assert!((covered - std::f64::consts::FRAC_PI_4).abs() < 0.03, "frame {frame}: {covered:.3} covered");
        // Normals in the frame's axes: towards the eye at the centre, to the left near the left rim.
        let (normals, depths) =
            (frame_texels(&frames.normal, grid, size, frame), frame_texels(&frames.depth, grid, size, frame));
        let normal_at = |at: u32| {
            let texel = normals[at as usize];
            Vec3::new(texel[0] as f32, texel[1] as f32, texel[2] as f32) / 127.5 - Vec3::ONE
        };
        let (centre, edge) = (size / 2 * size + size / 2, size / 2 * size + 4);
        assert!(normal_at(centre).normalize().distance(Vec3::Z) < 0.06, "frame {frame}: normal {}", normal_at(centre));
        assert!(normal_at(edge).x < -0.8, "frame {frame}: near the left rim the normal is {}", normal_at(edge));
        assert!(
            depths[centre as usize][0] <= 4,
            "frame {frame}: the sphere's nearest point has depth {:?}",
            depths[centre as usize]
        );
        assert!(
            depths[edge as usize][0] > 60,
            "frame {frame}: near the rim the depth is {:?} (about half way)",
            depths[edge as usize]
        );
        // Outside the disc, the nearest covered texel's values; albedo's alpha stays 0.
        assert_eq!(albedo[0][3], 0);
        assert!(depths[0][0] > 100, "frame {frame}: the corner takes the rim's depth, {:?}", depths[0]);
    }
}

#[test]
fn a_frame_s_image_axes_are_the_reference_s() {
    // A bar along x with a block on its +x end.
    let mut obj = box_obj([-1.0, -0.1, -0.1], [1.0, 0.1, 0.1], 1);
    obj.push_str(&box_obj([0.6, -0.4, -0.4], [1.0, 0.4, 0.4], 9));
    let gpu = gpu::gpu().expect("a GPU adapter (llvmpipe in CI)");
    let (grid, size) = (FrameGrid { frames: 3, sphere: Sphere::Hemi }, 32);
    let settings = render::impostor::ImpostorSettings { grid, frame_size: size };
    let frames = render::impostor::bake_impostor(gpu, &view_of(&obj), (Vec3::ZERO, 1.5), settings).unwrap();
    for frame in [2, 4, 6] {
        // From +z, from above and from −z: the block shows where the frame's right axis puts +x.
        let (right, _) = mesh::octahedral::frame_axes(grid.frame_direction(frame));
        let texels = frame_texels(&frames.albedo, grid, size, frame);
        let covered_in = |columns: std::ops::Range<u32>| {
            (0..size)
                .flat_map(|y| columns.clone().map(move |x| (y * size + x) as usize))
                .filter(|&at| texels[at][3] > 127)
                .count()
        };
        let (left, right_half) = (covered_in(0..size / 2), covered_in(size / 2..size));
        if right.x > 0.5 {
            assert!(right_half > left + 20, "frame {frame}: {left} left, {right_half} right");
        } else {
            assert!(left > right_half + 20, "frame {frame}: {left} left, {right_half} right");
        }
    }
    // A post along y with a block on its top, seen from the horizon: the block in the top rows
    // (rows run down the image, against the frame's up axis).
    let mut obj = box_obj([-0.1, -1.0, -0.1], [0.1, 1.0, 0.1], 1);
    obj.push_str(&box_obj([-0.4, 0.6, -0.4], [0.4, 1.0, 0.4], 9));
    let frames = render::impostor::bake_impostor(gpu, &view_of(&obj), (Vec3::ZERO, 1.5), settings).unwrap();
    for frame in [0, 2, 6, 8] {
        let texels = frame_texels(&frames.albedo, grid, size, frame);
        let covered_rows = |rows: std::ops::Range<u32>| {
            rows.flat_map(|y| (0..size).map(move |x| (y * size + x) as usize)).filter(|&at| texels[at][3] > 127).count()
        };
        let (top, bottom) = (covered_rows(0..size / 2), covered_rows(size / 2..size));
        assert!(top > bottom + 20, "frame {frame}: {top} covered in the top half, {bottom} in the bottom");
    }
}

/// Each of the 26 preview views' silhouette IoU between `source` and its impostor baked on
/// `grid` at `frame_size`, both drawn at 128 px.
fn impostor_ious(source: &gpu::ViewMesh, grid: FrameGrid, frame_size: u32) -> Vec<f64> {
    let gpu = gpu::gpu().expect("a GPU adapter (llvmpipe in CI)");
    let (center, radius) = render::preview::bounding_sphere(source);
    let settings = render::impostor::ImpostorSettings { grid, frame_size };
    let frames = render::impostor::bake_impostor(gpu, source, (Vec3::from(center), radius), settings).unwrap();
    let draw = gpu::ImpostorDraw {
        grid,
        albedo: vec![frames.albedo],
        normal: vec![frames.normal],
        depth: vec![frames.depth],
        center,
        radius,
        alpha_cutoff: 0.5,
        rects: frames.rects,
        hull: None,
    };
    let light = render::preview::preview_light();
    render::preview::view_directions()
        .into_iter()
        .map(|direction| {
            let camera = render::preview::view_projection(center, radius, direction);
            let source = gpu.render_view(source, camera, light, 128).unwrap();
            let impostor = gpu.render_impostor_view(&draw, camera, light, 128).unwrap();
            let (mut both, mut either) = (0usize, 0usize);
            for (a, b) in source.chunks_exact(4).zip(impostor.chunks_exact(4)) {
                both += usize::from(a[3] > 0 && b[3] > 0);
                either += usize::from(a[3] > 0 || b[3] > 0);
            }
            both as f64 / either.max(1) as f64
        })
        .collect()
}

#[test]
fn an_impostor_of_a_sphere_and_of_a_box_matches_its_source_from_every_preview_view() {
    // A hemi-octahedron is for things seen from above: its sphere is held to the views at or
    // above the horizon. Odd frame counts put the axis views on frames; the others fall between.
    let sphere = view_of(&sphere_obj(32));
    let hemi = impostor_ious(&sphere, FrameGrid { frames: 8, sphere: Sphere::Hemi }, 128);
    let above: Vec<f64> = hemi
        .iter()
        .zip(render::preview::view_directions())
        .filter(|(_, direction)| direction[1] >= 0.0)
        .map(|(&iou, _)| iou)
        .collect();
    let full = impostor_ious(&sphere, FrameGrid { frames: 11, sphere: Sphere::Full }, 128);
    let cube = view_of(&box_obj([-1.0, -0.6, -0.8], [1.0, 0.6, 0.8], 1));
    let cube = impostor_ious(&cube, FrameGrid { frames: 11, sphere: Sphere::Full }, 128);
    assert_eq!(above.len(), 17);
    assert!(above.iter().all(|&iou| iou > 0.95), "hemi sphere: {above:?}");
    // (Measured: at least 0.948, the rim a pixel off where the parallax step meets its steep
    // depth; the hemi sphere at least 0.953, the box 0.951.)
    assert!(full.iter().all(|&iou| iou > 0.94), "full sphere: {full:?}");
    assert!(cube.iter().all(|&iou| iou > 0.95), "box: {cube:?}");
}

#[test]
fn each_frame_shows_the_mesh_s_bounds_from_its_direction() {
    // A pole 0.1 wide and 2 tall in a sphere of radius 1.5: seen from the side, its frame is
    // the pole's width and height (over the sphere's 3), a texel and a half of margin each side;
    // from above, its square section (widened to two texels of the whole image).
    let settings =
        render::impostor::ImpostorSettings { grid: FrameGrid { frames: 3, sphere: Sphere::Full }, frame_size: 32 };
    let mut corners = Vec::new();
    for x in [-0.05, 0.05] {
        for y in [-1.0, 1.0] {
            for z in [-0.05, 0.05] {
                corners.push(Vec3::new(x, y, z));
            }
        }
    }
    let rects = render::impostor::frame_rects(&corners, (Vec3::ZERO, 1.5), settings);
    assert_eq!(rects.len(), 9);
    let expected = |width: f32, height: f32| {
        // At least two texels of the whole image.
        let side = |extent: f32| {
            let extent = extent.max(2.0 / 32.0);
            let margin = extent * 1.5 / 32.0;
            [0.5 - extent / 2.0 - margin, 0.5 + extent / 2.0 + margin]
        };
        let ([u0, u1], [v0, v1]) = (side(width / 3.0), side(height / 3.0));
        [u0, v0, u1, v1]
    };
    let close = |a: [f32; 4], b: [f32; 4]| a.iter().zip(b).all(|(a, b)| (a - b).abs() < 1e-5);
    // Frame 4 looks from straight above (the full octahedron's centre); frame 1 (i = 1, j = 0)
    // from the horizon along -Z, frame 3 along -X.
    assert!(close(rects[4], expected(0.1, 0.1)), "from above: {:?}", rects[4]);
    for frame in [1, 3] {
        assert!(close(rects[frame], expected(0.1, 2.0)), "frame {frame}: {:?}", rects[frame]);
    }
    // No points: the whole image; points out to the sphere: clamped to it.
    assert!(render::impostor::frame_rects(&[], (Vec3::ZERO, 1.5), settings)
        .iter()
        .all(|rect| *rect == [0.0, 0.0, 1.0, 1.0]));
    let far = [Vec3::new(-1.5, -1.5, -1.5), Vec3::new(1.5, 1.5, 1.5)];
    assert!(render::impostor::frame_rects(&far, (Vec3::ZERO, 1.5), settings)
        .iter()
        .all(|rect| *rect == [0.0, 0.0, 1.0, 1.0]));

    // Baked, a pole 0.2 wide fills its side frames (the whole sphere's image would leave it 6 %
    // of the texels), and its impostor keeps its silhouette: from every view but those between
    // frames looking down its length, where three frames' tilted poles blend (ghosting).
    let gpu = gpu::gpu().expect("a GPU adapter (llvmpipe in CI)");
    let pole = view_of(&box_obj([-0.1, -1.0, -0.1], [0.1, 1.0, 0.1], 1));
    let grid = FrameGrid { frames: 9, sphere: Sphere::Full };
    let settings = render::impostor::ImpostorSettings { grid, frame_size: 32 };
    let frames = render::impostor::bake_impostor(gpu, &pole, (Vec3::ZERO, 1.5), settings).unwrap();
    // Frame (4, 0) looks along -Z from the horizon.
    let side = frame_texels(&frames.albedo, grid, 32, 4);
    let covered = side.iter().filter(|texel| texel[3] > 127).count() as f64 / side.len() as f64;
    assert!(covered > 0.7, "{covered} of the side frame covered");
    let ious = impostor_ious(&pole, grid, 32);
    let mean = ious.iter().sum::<f64>() / ious.len() as f64;
    assert!(mean > 0.85 && ious.iter().all(|&iou| iou > 0.6), "pole: mean {mean}, {ious:?}");
}

/// `levels`' every level upsampled twice (each texel repeated 2 × 2): level `k` then holds
/// what level `k + 1` of a chain twice the size holds.
fn doubled(levels: &[texture::Texture]) -> Vec<texture::Texture> {
    levels
        .iter()
        .map(|level| {
            let (width, height) = (level.width * 2, level.height * 2);
            let pixels = (0..width * height)
                .flat_map(|at| {
                    let (x, y) = (at % width / 2, at / width / 2);
                    let texel = ((y * level.width + x) * 4) as usize;
                    level.pixels[texel..texel + 4].to_vec()
                })
                .collect();
            texture::Texture::new(width, height, pixels)
        })
        .collect()
}

#[test]
fn normal_and_depth_atlases_stored_at_half_the_albedo_s_side_draw_as_the_full_ones() {
    // An `Auto` candidate may store an impostor's normal and depth at a half or a quarter of
    // its albedo's side: level 0 of the stored chain is level 1 or 2 of the full one. The
    // shader offsets their mip level by the ratio of the sides, so where every pixel reads
    // level 1 or below (a 32-texel frame drawn 12 pixels across), the draw is the full one's.
    use texture::mips::{mip_chain, MipSettings};
    use texture::SurfaceKind;
    let gpu = gpu::gpu().expect("a GPU adapter (llvmpipe in CI)");
    let sphere = view_of(&sphere_obj(16));
    let (center, radius) = render::preview::bounding_sphere(&sphere);
    let grid = FrameGrid { frames: 8, sphere: Sphere::Full };
    let settings = render::impostor::ImpostorSettings { grid, frame_size: 32 };
    let frames = render::impostor::bake_impostor(gpu, &sphere, (Vec3::from(center), radius), settings).unwrap();
    let chain = |texture: &texture::Texture, kind| mip_chain(texture, MipSettings { kind, alpha_cutoff: None });
    let albedo = mip_chain(&frames.albedo, MipSettings { kind: SurfaceKind::Albedo, alpha_cutoff: Some(0.5) });
    let (normal, depth) = (chain(&frames.normal, SurfaceKind::Normal), chain(&frames.depth, SurfaceKind::Height));
    let draw = |normal: Vec<texture::Texture>, depth: Vec<texture::Texture>| gpu::ImpostorDraw {
        grid,
        albedo: albedo.clone(),
        normal,
        depth,
        center,
        radius,
        alpha_cutoff: 0.5,
        rects: frames.rects.clone(),
        hull: None,
    };
    let full = draw(normal.clone(), depth.clone());
    let halved = draw(normal[1..].to_vec(), depth[1..].to_vec());
    let quartered = draw(normal[2..].to_vec(), depth[2..].to_vec());
    // What a shader that sampled them at the albedo's level would draw: the full side, one
    // level coarser.
    let coarser = draw(doubled(&normal[1..]), doubled(&depth[1..]));
    let light = render::preview::preview_light();
    let mut coarser_differs = 0;
    for direction in render::preview::view_directions() {
        let camera = render::preview::view_projection(center, radius, direction);
        let reference = gpu.render_impostor_view(&full, camera, light, 12).unwrap();
        let differing = |a: &[u8], b: &[u8]| a.iter().zip(b).filter(|(a, b)| a != b).count();
        let half = gpu.render_impostor_view(&halved, camera, light, 12).unwrap();
        assert_eq!(differing(&half, &reference), 0, "{direction:?}: bytes that differ at 12 px");
        let coarse = gpu.render_impostor_view(&coarser, camera, light, 12).unwrap();
        coarser_differs += usize::from(reference.iter().zip(&coarse).any(|(a, b)| a.abs_diff(*b) > 2));
        // A quarter side reads level 2 where the draw reads level 1: equal where it reads 2.
        let (reference, quarter) = (
            gpu.render_impostor_view(&full, camera, light, 6).unwrap(),
            gpu.render_impostor_view(&quartered, camera, light, 6).unwrap(),
        );
        assert_eq!(differing(&quarter, &reference), 0, "{direction:?}: bytes that differ at 6 px");
    }
    assert!(coarser_differs >= 20, "one level coarser shows in {coarser_differs} of 26 views");
}

/// The area of a polygon of points `[x, y]` in order (the shoelace formula).
fn polygon_area(points: &[[f32; 2]]) -> f32 {
    let mut twice = 0.0;
    for (index, &[x0, y0]) in points.iter().enumerate() {
        let [x1, y1] = points[(index + 1) % points.len()];
        twice += x0 * y1 - x1 * y0;
    }
    twice.abs() / 2.0
}

#[test]
fn an_impostor_drawn_as_its_fitted_hull_shows_what_its_square_shows_with_less_overdraw() {
    // A pole (tall and thin: its outline from any direction is narrow) and a sphere (round: the
    // octagon only cuts the square's corners).
    let gpu = gpu::gpu().expect("a GPU adapter (llvmpipe in CI)");
    let grid = FrameGrid { frames: 8, sphere: Sphere::Full };
    let pole = view_of(&box_obj([-0.2, -1.0, -0.2], [0.2, 1.0, 0.2], 1));
    let sphere = view_of(&sphere_obj(16));
    for (name, source, most_area) in [("pole", &pole, 0.40), ("sphere", &sphere, 0.92)] {
        let (center, radius) = render::preview::bounding_sphere(source);
        let points: Vec<Vec3> = source
            .batches
            .iter()
            .flat_map(|(_, vertices)| vertices.iter().map(|vertex| Vec3::from(vertex.position)))
            .collect();
        let hull = render::impostor::view_hull(&points, (Vec3::from(center), radius));
        let area = polygon_area(&hull) / 4.0;
        assert!(area <= most_area, "{name}: the hull covers {area:.3} of the square");
        assert!(hull.iter().flatten().all(|value| (-1.0..=1.0).contains(value)), "{name}: {hull:?}");
        let settings = render::impostor::ImpostorSettings { grid, frame_size: 32 };
        let frames = render::impostor::bake_impostor(gpu, source, (Vec3::from(center), radius), settings).unwrap();
        let draw = |hull| gpu::ImpostorDraw {
            grid,
            albedo: vec![frames.albedo.clone()],
            normal: vec![frames.normal.clone()],
            depth: vec![frames.depth.clone()],
            center,
            radius,
            alpha_cutoff: 0.5,
            rects: frames.rects.clone(),
            hull,
        };
        let (square, fitted) = (draw(None), draw(Some(hull)));
        let light = render::preview::preview_light();
        for direction in render::preview::view_directions() {
            let camera = render::preview::view_projection(center, radius, direction);
            let whole = gpu.render_impostor_view(&square, camera, light, 96).unwrap();
            let cut = gpu.render_impostor_view(&fitted, camera, light, 96).unwrap();
            let shown = gpu.render_view(source, camera, light, 96).unwrap();
            // The hull only takes away what the source does not show (the parallax step's
            // strays past the outline: 31 pixels of the pole seen from above), and draws the
            // rest in the same colour but for rounding (the fan's triangles interpolate apart).
            for ((a, b), source) in whole.chunks_exact(4).zip(cut.chunks_exact(4)).zip(shown.chunks_exact(4)) {
                assert!(a[3] == b[3] || (b[3] == 0 && source[3] == 0), "{name} from {direction:?}: {a:?} {b:?}");
                assert!(b[3] == 0 || a.iter().zip(b).all(|(x, y)| x.abs_diff(*y) <= 1), "{name}: {a:?} {b:?}");
            }
        }
    }
}

#[test]
fn frames_reduced_five_times_from_a_larger_render_keep_each_frame_s_coverage_within_it() {
    let gpu = gpu::gpu().expect("a GPU adapter (llvmpipe in CI)");
    let grid = FrameGrid { frames: 4, sphere: Sphere::Hemi };
    let settings = render::impostor::ImpostorSettings { grid, frame_size: 40 };
    // Rendered at 40 texels a frame with the margins of 8-texel frames, as a chain's 12 × 12
    // impostors at 80 and 16 texels share one render.
    let view = view_of(&sphere_obj(32));
    let large =
        render::impostor::bake_impostor_with_margin(gpu, &view, (Vec3::ZERO, 1.0), (settings, 8), &base::stop::never)
            .unwrap();
    let small = render::impostor::reduced_frames(&large, 5, 0.5);
    assert_eq!(small.settings.frame_size, 8);
    assert_eq!((small.albedo.width, small.normal.width, small.depth.height), (32, 32, 32));
    assert_eq!(small.rects, large.rects);
    let covered =
        |texels: &[[u8; 4]]| texels.iter().filter(|texel| texel[3] > 127).count() as f64 / texels.len() as f64;
    for frame in 0..grid.frame_count() {
        let (large_texels, small_texels) =
            (frame_texels(&large.albedo, grid, 40, frame), frame_texels(&small.albedo, grid, 8, frame));
        // The disc keeps its share of the frame to within a texel of the 64 (the coverage is
        // kept over the whole atlas), and stays inside its frame: the corners are still empty.
        let (large_share, small_share) = (covered(&large_texels), covered(&small_texels));
        assert!((large_share - small_share).abs() < 1.5 / 64.0, "frame {frame}: {large_share:.3} -> {small_share:.3}");
        for corner in [0, 7, 56, 63] {
            assert_eq!(small_texels[corner][3], 0, "frame {frame}: corner {corner} {:?}", small_texels[corner]);
        }
        assert!(small_texels[4 * 8 + 4][3] > 127, "frame {frame}: the centre {:?}", small_texels[4 * 8 + 4]);
        // Depth is the mean of the footprint: the nearest point stays near the centre.
        let depths = frame_texels(&small.depth, grid, 8, frame);
        assert!(depths[4 * 8 + 4][0] < 40, "frame {frame}: depth at the centre {:?}", depths[4 * 8 + 4]);
    }
}

#[test]
fn views_drawn_in_batches_are_those_drawn_one_at_a_time_and_sizes_sharing_a_render_measure_as_alone() {
    use render::preview::{hold_samples_per_axis, view_directions, view_projection, PreviewSettings};
    let gpu = gpu::gpu().expect("a GPU adapter (llvmpipe in CI)");
    let source = view_of(&sphere_obj(12));
    let (center, radius) = render::preview::bounding_sphere(&source);
    let light = render::preview::preview_light();
    // Three views at 1024²: more than one batch (`gpu::views_per_batch`), the last one short.
    let cameras: Vec<[[f32; 4]; 4]> =
        view_directions().into_iter().take(3).map(|direction| view_projection(center, radius, direction)).collect();
    assert!(gpu::views_per_batch(1024, 1) < cameras.len());
    // Each image as the batches hand it over.
    let (mut batched, mut frames) = (Vec::new(), Vec::new());
    gpu.render_views(&source, &cameras, light, 1024, |_, image| batched.push(image)).unwrap();
    gpu.render_impostor_frames(&source, &cameras, (1024, &base::stop::never), |_, images| frames.push(images)).unwrap();
    assert_eq!((batched.len(), frames.len()), (3, 3));
    for ((&camera, image), frame) in cameras.iter().zip(&batched).zip(&frames) {
        assert_eq!(*image, gpu.render_view(&source, camera, light, 1024).unwrap());
        let mut alone = Vec::new();
        gpu.render_impostor_frames(&source, &[camera], (1024, &base::stop::never), |_, [albedo, _]| alone = albedo)
            .unwrap();
        assert_eq!(frame[0], alone);
        assert!(image.chunks_exact(4).any(|pixel| pixel[3] > 0) && frame[1].chunks_exact(4).any(|texel| texel[3] > 0));
    }

    // A box inside the sphere against it at 64 and 128 px, which render at one side (256²):
    // measured together from the same renders, each size's figures are those it gets alone.
    assert_eq!(64 * hold_samples_per_axis(64), 128 * hold_samples_per_axis(128));
    let lod = gpu::LevelView::Mesh(view_of(&box_obj([-0.7; 3], [0.7; 3], 1)));
    let mut sources = render::preview::SourceViews::default();
    let holds = render::preview::holds(gpu, &source, &[&lod], (center, radius), &[64, 128], &mut sources).unwrap();
    assert_eq!(holds[0].measured.iter().map(|figures| figures.size).collect::<Vec<_>>(), [64, 128]);
    for figures in &holds[0].measured {
        let settings =
            PreviewSettings { views: 26, size: figures.size, samples_per_axis: hold_samples_per_axis(figures.size) };
        let alone = render::preview::compare_only(gpu, &source, &[&lod], (center, radius), settings).unwrap();
        assert!(alone[0].mean_iou < 0.95, "the box is not the sphere: {}", alone[0].mean_iou);
        assert_eq!((figures.mean_iou, figures.loss_px_shift), (alone[0].mean_iou, alone[0].loss_px_shift));
        assert_eq!(figures.mean_psnr, alone[0].mean_psnr);
    }
}

#[test]
fn a_lod_failing_its_screening_at_one_sample_a_pixel_is_not_rendered_at_more_nor_one_left_alone_passing_it() {
    use render::preview::{hold_samples_per_axis, screen_samples_per_axis, PreviewSettings, HOLD_SIZES};
    // Only 256 px, whose own renders (2 × 2 samples) are 512², is screened: at one sample a pixel,
    // from the 256² renders of 64 and 128 px.
    let screens: Vec<Option<u32>> = HOLD_SIZES.iter().map(|&size| screen_samples_per_axis(size)).collect();
    assert_eq!(screens, [None, None, None, None, Some(1)]);
    let gpu = gpu::gpu().expect("a GPU adapter (llvmpipe in CI)");
    let source = view_of(&sphere_obj(12));
    let sphere = render::preview::bounding_sphere(&source);
    // The sphere itself, and the sphere 0.7 % smaller: its loss grows with the size, within one
    // px-shift unit at 128 px, past it at 256.
    let mut smaller = source.clone();
    for (_, vertices) in &mut smaller.batches {
        for vertex in vertices.iter_mut() {
            vertex.position =
                std::array::from_fn(|axis| sphere.0[axis] + 0.993 * (vertex.position[axis] - sphere.0[axis]));
        }
    }
    let (same, smaller) = (gpu::LevelView::Mesh(source.clone()), gpu::LevelView::Mesh(smaller));
    // Each measured alone (the sphere would outrank the smaller one), the source's renders shared.
    let mut sources = render::preview::SourceViews::default();
    let mut hold = |lod: &gpu::LevelView| {
        let holds = render::preview::holds(gpu, &source, &[lod], sphere, &[64, 128, 256], &mut sources).unwrap();
        let figures: Vec<(u32, u32)> =
            holds[0].measured.iter().map(|figures| (figures.size, figures.samples_per_pixel)).collect();
        (holds[0].clone(), figures)
    };
    // The smaller sphere holds at 128 px, fails its screening at 256 and is measured no further.
    let (failed, sampled) = hold(&smaller);
    assert_eq!(sampled, [(64, 16), (128, 4), (256, 1)]);
    assert_eq!(failed.holds_to, Some(128));
    let screen = PreviewSettings { views: 26, size: 256, samples_per_axis: 1 };
    let alone = render::preview::compare_only(gpu, &source, &[&smaller], sphere, screen).unwrap();
    let last = failed.measured.last().unwrap();
    assert!(alone[0].loss_px_shift.unwrap() > 1.0, "{:?}", alone[0].loss_px_shift);
    assert_eq!((last.mean_iou, last.loss_px_shift), (alone[0].mean_iou, alone[0].loss_px_shift));
    // Where it is measured at 256 px as it would be unscreened (2 × 2), it loses more still.
    let measured = PreviewSettings { samples_per_axis: hold_samples_per_axis(256), ..screen };
    let unscreened = render::preview::compare_only(gpu, &source, &[&smaller], sphere, measured).unwrap();
    assert!(unscreened[0].loss_px_shift.unwrap() > 1.0, "{:?}", unscreened[0].loss_px_shift);
    // The sphere itself, alone, loses nothing at its screening: it holds there.
    let (held, sampled) = hold(&same);
    assert_eq!(sampled, [(64, 16), (128, 4), (256, 1)]);
    assert_eq!(held.holds_to, Some(256));
    // Beside the sphere 0.02 % smaller (neither outranks the other), both are measured at 2 × 2:
    // each is ranked at the samples of the other.
    let mut nearly = source.clone();
    for (_, vertices) in &mut nearly.batches {
        for vertex in vertices.iter_mut() {
            vertex.position =
                std::array::from_fn(|axis| sphere.0[axis] + 0.9998 * (vertex.position[axis] - sphere.0[axis]));
        }
    }
    let nearly = gpu::LevelView::Mesh(nearly);
    let both = render::preview::holds(gpu, &source, &[&same, &nearly], sphere, &[64, 128, 256], &mut sources).unwrap();
    for hold in &both {
        let sampled: Vec<(u32, u32)> =
            hold.measured.iter().map(|figures| (figures.size, figures.samples_per_pixel)).collect();
        assert_eq!(sampled, [(64, 16), (128, 4), (256, 4)], "{hold:?}");
        assert_eq!(hold.holds_to, Some(256));
    }
    assert!(both[1].measured[2].loss_px_shift > both[0].measured[2].loss_px_shift);
}
