//! Preview renders of materials: each map a material has changes what is drawn, and a map it
//! lacks draws as a neutral one (the preview draws each set of maps with its own pipeline); a
//! view draws triangles nearest first, and the image does not depend on their order.

use std::sync::Arc;

use gpu::{RenderVertex, ViewMaterial, ViewMesh};
use texture::Texture;

/// A square facing +z at `z` (x and y from −1 to 1), UVs 0 to 1.
fn square(z: f32) -> Vec<RenderVertex> {
    let corner = |x: f32, y: f32, u: f32, v: f32| RenderVertex {
        position: [x, y, z],
        normal: [0.0, 0.0, 1.0],
        uv: [u, v],
        tangent: [1.0, 0.0, 0.0, 1.0],
    };
    let [a, b, c, d] = [
        corner(-1.0, -1.0, 0.0, 0.0),
        corner(1.0, -1.0, 1.0, 0.0),
        corner(1.0, 1.0, 1.0, 1.0),
        corner(-1.0, 1.0, 0.0, 1.0),
    ];
    vec![a, b, c, a, c, d]
}

/// A 16² map whose left half is `left` and right half `right` (one level).
fn halves(left: [u8; 4], right: [u8; 4]) -> Arc<Vec<Texture>> {
    let pixels = (0..16 * 16).flat_map(|index| if index % 16 < 8 { left } else { right }).collect();
    Arc::new(vec![Texture::new(16, 16, pixels)])
}

/// The pixels of `image` (RGBA8, `size`²) in the middle row, from left to right.
fn middle_row(image: &[u8], size: usize) -> Vec<[u8; 4]> {
    image[size / 2 * size * 4..(size / 2 + 1) * size * 4]
        .chunks_exact(4)
        .map(|pixel| pixel.try_into().unwrap())
        .collect()
}

#[test]
fn each_map_changes_the_render_and_a_missing_map_draws_as_a_neutral_one() {
    let gpu = gpu::gpu().expect("a GPU adapter (llvmpipe in CI)");
    let plain = ViewMaterial { albedo_factor: [0.8, 0.6, 0.4, 1.0], alpha_cutoff: 0.5, ..Default::default() };
    // Transparent on the left, opaque on the right; a normal tilted towards −x on the left.
    let holed = ViewMaterial { opacity: Some(halves([0; 4], [255; 4])), ..plain.clone() };
    let opaque = ViewMaterial { opacity: Some(halves([255; 4], [255; 4])), ..plain.clone() };
    let tilted = ViewMaterial {
        normal: Some(halves([38, 128, 218, 255], [128, 128, 255, 255])),
        normal_has_z: true,
        ..plain.clone()
    };
    let both = ViewMaterial { normal: tilted.normal.clone(), normal_has_z: true, ..holed.clone() };
    let size = 64;
    let camera = render::preview::view_projection([0.0; 3], 1.5, [0.0, 0.0, 1.0]);
    let light = [0.6, 0.0, 0.8];
    let draw = |materials: Vec<ViewMaterial>| {
        // Each material's square nearer the camera than the one before.
        let batches = (0..materials.len()).map(|index| (index, square(0.1 * index as f32))).collect();
        gpu.render_view(&ViewMesh { batches, materials }, camera, light, size).unwrap()
    };
    let plain_image = draw(vec![plain.clone()]);
    let row = |image: &[u8]| middle_row(image, size as usize);
    let (left, right) = (size as usize / 2 - 12, size as usize / 2 + 12);
    // The opacity map cuts the square's left half out; an opaque one changes nothing.
    let holed_row = row(&draw(vec![holed.clone()]));
    assert_eq!(holed_row[left][3], 0, "the opacity map's transparent half is not drawn");
    assert_eq!(holed_row[right], row(&plain_image)[right]);
    assert_eq!(draw(vec![opaque]), plain_image, "an opaque opacity map draws as none");
    // The normal map turns the left half away from the light: darker there, the same on the right.
    let tilted_row = row(&draw(vec![tilted]));
    assert!(
        tilted_row[left][0] < row(&plain_image)[left][0] - 20,
        "{:?} {:?}",
        tilted_row[left],
        row(&plain_image)[left]
    );
    assert_eq!(tilted_row[right][3], 255);
    // Both maps at once, and materials with different maps in one mesh, each drawn with its own:
    // the plain square shows through the hole of the red one in front of it.
    let both_row = row(&draw(vec![both]));
    assert_eq!((both_row[left][3], both_row[right][3]), (0, 255));
    let red = ViewMaterial { albedo_factor: [1.0, 0.0, 0.0, 1.0], ..holed };
    let mixed_row = row(&draw(vec![plain, red]));
    assert_eq!(mixed_row[left], row(&plain_image)[left], "the plain square shows through the hole");
    assert_eq!(mixed_row[right][1], 0, "the red square is in front on the right: {:?}", mixed_row[right]);
}

#[test]
fn a_view_draws_triangles_nearest_first_and_the_image_does_not_depend_on_their_order() {
    use gpu::front_to_back;
    // Three squares (two triangles each) at z 0.5, −0.5 and 0, listed in that order.
    let vertices: Vec<RenderVertex> = [0.5, -0.5, 0.0].into_iter().flat_map(square).collect();
    let from = |z: f32| render::preview::view_projection([0.0; 3], 1.5, [0.0, 0.0, z]);
    let triangles = |order: Vec<u32>| -> Vec<u32> {
        assert!(order.chunks_exact(3).all(|corners| corners[1] == corners[0] + 1 && corners[2] == corners[0] + 2));
        order.chunks_exact(3).map(|corners| corners[0] / 3).collect()
    };
    // From +z the square at 0.5 is nearest; triangles at one depth keep their order.
    assert_eq!(triangles(front_to_back(&vertices, &from(1.0))), [0, 1, 4, 5, 2, 3]);
    assert_eq!(triangles(front_to_back(&vertices, &from(-1.0))), [2, 3, 4, 5, 0, 1]);
    assert_eq!(triangles(front_to_back(&vertices[..6], &from(1.0))), [0, 1]);
    assert!(front_to_back(&[], &from(1.0)).is_empty());
    // A red square in front of a grey one, listed either way round: one image, red in front.
    let gpu = gpu::gpu().expect("a GPU adapter (llvmpipe in CI)");
    let material = |albedo_factor: [f32; 4]| ViewMaterial { albedo_factor, alpha_cutoff: 0.5, ..Default::default() };
    let materials = vec![material([0.5, 0.5, 0.5, 1.0]), material([1.0, 0.0, 0.0, 1.0])];
    let draw = |batches: Vec<(usize, Vec<RenderVertex>)>| {
        let mesh = ViewMesh { batches, materials: materials.clone() };
        gpu.render_view(&mesh, from(1.0), [0.0, 0.0, 1.0], 32).unwrap()
    };
    // The nearer square the narrower: the farther one shows at its sides.
    let one = |z: f32| {
        square(z).into_iter().map(move |mut vertex| {
            vertex.position[0] *= 1.0 - z;
            vertex
        })
    };
    let both: Vec<RenderVertex> = one(0.3).chain(one(-0.3)).collect();
    let reversed: Vec<RenderVertex> = one(-0.3).chain(one(0.3)).collect();
    let image = draw(vec![(1, both)]);
    assert_eq!(draw(vec![(1, reversed)]), image);
    let pixel = |image: &[u8], x: usize| image[(16 * 32 + x) * 4..(16 * 32 + x) * 4 + 3].to_vec();
    assert_eq!(pixel(&image, 16)[..2], [255, 0], "red in the middle");
    let (grey_first, red_first) = (
        draw(vec![(0, one(-0.3).collect()), (1, one(0.3).collect())]),
        draw(vec![(1, one(0.3).collect()), (0, one(-0.3).collect())]),
    );
    assert_eq!(grey_first, red_first);
    assert_eq!(pixel(&grey_first, 16)[..2], [255, 0], "red in the middle");
    let side = pixel(&grey_first, 28);
    assert!(side[0] == side[1] && side[0] > 0, "grey at the side: {side:?}");
}
