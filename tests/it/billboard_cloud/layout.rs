//! Rectangles and layout: minimum-area frames around each plane's faces, and atlas packing
//! without overlaps, with padding, block alignment and the size rules.

use cirrus::kinds::billboard_cloud::layout::{layout_rectangles, Layout};
use cirrus::kinds::billboard_cloud::planes::{select_planes, PlaneSettings};
use cirrus::kinds::billboard_cloud::rectangles::{convex_hull, minimum_area_rectangle, plane_rectangles};
use cirrus::packing::PageSettings;
use glam::{Vec2, Vec3};

#[test]
fn the_minimum_area_rectangle_of_a_rotated_square_is_the_square() {
    let angle = 0.5f32;
    let rotate = |p: Vec2| Vec2::new(p.x * angle.cos() - p.y * angle.sin(), p.x * angle.sin() + p.y * angle.cos());
    let mut points: Vec<Vec2> = [[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0], [1.0, 1.0], [0.5, 1.5]]
        .iter()
        .map(|&[x, y]| rotate(Vec2::new(x, y)))
        .collect();
    points.push(rotate(Vec2::new(1.0, 0.0)));
    let hull = convex_hull(points);
    assert_eq!(hull.len(), 4, "interior and collinear points dropped");
    let (_, min, max) = minimum_area_rectangle(&hull);
    let area = (max.x - min.x) * (max.y - min.y);
    assert!((area - 4.0).abs() < 1e-4, "area {area}");
}

#[test]
fn plane_rectangles_frame_every_face_of_their_plane() {
    let positions: Vec<[f32; 3]> =
        (0..8).map(|i| [(i & 1) as f32 * 2.0, ((i >> 1) & 1) as f32, ((i >> 2) & 1) as f32 * 3.0]).collect();
    let quads = [[0u32, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]];
    let triangles: Vec<[u32; 3]> = quads.iter().flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]]).collect();
    let planes =
        select_planes(&positions, &triangles, &[], PlaneSettings { epsilon: 0.02, max_planes: None, max_quads: None });
    let rectangles = plane_rectangles(&positions, &triangles, &planes);
    let mut areas: Vec<f32> = rectangles.iter().map(|r| r.frame.width * r.frame.height).collect();
    areas.sort_by(f32::total_cmp);
    for (area, expected) in areas.iter().zip([2.0, 2.0, 3.0, 3.0, 6.0, 6.0]) {
        assert!((area - expected).abs() < 1e-3, "areas {areas:?}");
    }
    for (plane, rectangle) in planes.planes.iter().zip(&rectangles) {
        let (x, y, n) = (
            Vec3::from(rectangle.frame.x_axis),
            Vec3::from(rectangle.frame.y_axis),
            Vec3::from(rectangle.frame.normal),
        );
        assert!((x.cross(y) - n).length() < 1e-4, "right-handed frame");
        for vertex in plane.faces.iter().flat_map(|&face| triangles[face as usize]) {
            let local = Vec3::from(positions[vertex as usize]) - Vec3::from(rectangle.frame.origin);
            let (u, v) = (local.dot(x), local.dot(y));
            assert!(
                u > -1e-3 && u < rectangle.frame.width + 1e-3 && v > -1e-3 && v < rectangle.frame.height + 1e-3,
                "inside: {u} {v}"
            );
        }
    }
}

fn check_layout(layout: &Layout, settings: &PageSettings) {
    let padding = settings.padding;
    for (index, a) in layout.placements.iter().enumerate() {
        assert!(a.width % 4 == 0 && a.height % 4 == 0, "whole blocks: {a:?}");
        let (aw, ah) = if a.rotated { (a.height, a.width) } else { (a.width, a.height) };
        assert!(
            a.x >= padding
                && a.y >= padding
                && a.x + aw + padding <= layout.width
                && a.y + ah + padding <= layout.height,
            "inside with padding: {a:?}"
        );
        for b in &layout.placements[index + 1..] {
            let (bw, bh) = if b.rotated { (b.height, b.width) } else { (b.width, b.height) };
            // Each rectangle owns `padding` texels on every side: the padded cells are disjoint.
            let apart = a.x + aw + padding <= b.x - padding
                || b.x + bw + padding <= a.x - padding
                || a.y + ah + padding <= b.y - padding
                || b.y + bh + padding <= a.y - padding;
            assert!(apart, "overlap (padding included): {a:?} {b:?}");
        }
    }
    let used: u64 = layout.placements.iter().map(|p| p.width as u64 * p.height as u64).sum();
    let occupancy = used as f32 / (layout.width as f32 * layout.height as f32);
    assert!(
        (layout.occupancy - occupancy).abs() < 1e-6,
        "reported occupancy {} is the real one {occupancy}",
        layout.occupancy
    );
    if settings.power_of_two {
        assert!(layout.width.is_power_of_two() && layout.height.is_power_of_two());
    }
    assert!(layout.width <= settings.max_size && layout.height <= settings.max_size);
}

#[test]
fn layouts_have_no_overlaps_keep_padding_and_scale_density_at_max_size() {
    let sizes: Vec<(f32, f32)> =
        (0..150).map(|i| (0.2 + (i * 37 % 11) as f32 * 0.3, 0.1 + (i * 53 % 7) as f32 * 0.5)).collect();
    let settings = PageSettings { max_size: 1024, padding: 4, power_of_two: true };
    let layout = layout_rectangles(&sizes, &settings, Some(20.0));
    check_layout(&layout, &settings);
    assert_eq!(layout.texel_density, 20.0, "fits at the asked density");
    assert!(layout.placements.iter().any(|p| p.rotated), "rotation is used");
    let small = PageSettings { max_size: 256, padding: 2, power_of_two: false };
    let scaled = layout_rectangles(&sizes, &small, Some(20.0));
    check_layout(&scaled, &small);
    assert!(scaled.texel_density < 20.0, "density scaled down at max_size");
    let derived = layout_rectangles(&sizes, &settings, None);
    check_layout(&derived, &settings);
    assert!(derived.width == 1024 || derived.height == 1024, "no density given: fill max_size");
    // As densely as the packer can: the density is searched to within 0.2 %, not in 5 % steps
    // from 80 % of the atlas (which capped occupancy at 80 %).
    assert!(derived.occupancy > 0.74, "occupancy {} (0.69 in 5 % steps)", derived.occupancy);
    assert!(
        layout_rectangles(&sizes, &settings, Some(derived.texel_density * 1.01)).texel_density
            < derived.texel_density * 1.01
    );
}

#[test]
fn lod_obj_loads_back_with_every_quad_inside_its_atlas_placement() {
    use cirrus::kinds::billboard_cloud::lod_mesh::{lod_mesh, lod_mtl};
    let positions: Vec<[f32; 3]> =
        (0..8).map(|i| [(i & 1) as f32 * 2.0, ((i >> 1) & 1) as f32, ((i >> 2) & 1) as f32 * 3.0]).collect();
    let quads = [[0u32, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]];
    let triangles: Vec<[u32; 3]> = quads.iter().flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]]).collect();
    let planes =
        select_planes(&positions, &triangles, &[], PlaneSettings { epsilon: 0.02, max_planes: None, max_quads: None });
    let rectangles = plane_rectangles(&positions, &triangles, &planes);
    let settings = PageSettings { max_size: 256, padding: 4, power_of_two: true };
    let layout = layout_rectangles(
        &rectangles.iter().map(|r| (r.frame.width, r.frame.height)).collect::<Vec<_>>(),
        &settings,
        None,
    );
    let (obj, mtl) = (lod_mesh(&rectangles, &layout, "box"), lod_mtl("box", "mra"));
    assert!(mtl.contains("newmtl box") && mtl.contains("map_Kd albedo.png"));
    let (models, _) = tobj::load_obj_buf(
        &mut obj.as_bytes(),
        &tobj::LoadOptions { single_index: true, triangulate: true, ..Default::default() },
        |_| Ok((Vec::new(), Default::default())),
    )
    .expect("lod.obj parses");
    let mesh = &models[0].mesh;
    assert_eq!(mesh.indices.len(), 6 * 6, "two triangles per plane");
    for (plane, placement) in layout.placements.iter().enumerate() {
        let (w, h) =
            if placement.rotated { (placement.height, placement.width) } else { (placement.width, placement.height) };
        for corner in 0..4 {
            let vertex = mesh.indices.iter().map(|&i| i as usize).find(|&i| {
                let p = [mesh.positions[i * 3], mesh.positions[i * 3 + 1], mesh.positions[i * 3 + 2]];
                Vec3::from(p).distance(rectangles[plane].corners()[corner]) < 1e-5 && {
                    let (u, v) = (mesh.texcoords[i * 2], mesh.texcoords[i * 2 + 1]);
                    let (x, y) = (u * layout.width as f32, (1.0 - v) * layout.height as f32);
                    x >= placement.x as f32 - 1e-3
                        && x <= (placement.x + w) as f32 + 1e-3
                        && y >= placement.y as f32 - 1e-3
                        && y <= (placement.y + h) as f32 + 1e-3
                }
            });
            assert!(vertex.is_some(), "plane {plane} corner {corner} has a UV inside its placement");
        }
    }
}
