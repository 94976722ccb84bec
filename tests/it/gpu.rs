//! The per-plane renderer on the GPU (the software Vulkan adapter in CI): coverage, alpha test,
//! colour, the normal in the plane's frame and the height over ±ε.

use std::sync::Arc;

use cirrus::gpu::{gpu, PlaneRenderInput, RenderMaterial, RenderVertex};
use cirrus::rectangles::PlaneRectangle;
use cirrus::texture::Texture;

fn vertex(position: [f32; 3], uv: [f32; 2]) -> RenderVertex {
    RenderVertex { position, normal: [0.0, 0.0, 1.0], uv, tangent: [1.0, 0.0, 0.0, 1.0] }
}

#[test]
fn a_plane_render_covers_its_faces_cuts_alpha_and_encodes_normal_and_height() {
    let gpu = gpu().expect("a GPU adapter (install mesa-vulkan-drivers for the software one)");
    println!("adapter: {}", gpu.adapter_name);
    // The plane z = 0 over [0, 2] × [0, 1]; a quad over its left half, 0.05 above it (ε = 0.1).
    let rectangle = PlaneRectangle {
        plane: 0,
        faces: vec![0, 1],
        origin: [0.0; 3],
        x_axis: [1.0, 0.0, 0.0],
        y_axis: [0.0, 1.0, 0.0],
        normal: [0.0, 0.0, 1.0],
        width: 2.0,
        height: 1.0,
    };
    let quad = [
        vertex([0.0, 0.0, 0.05], [0.0, 0.0]),
        vertex([1.0, 0.0, 0.05], [1.0, 0.0]),
        vertex([1.0, 1.0, 0.05], [1.0, 1.0]),
        vertex([0.0, 0.0, 0.05], [0.0, 0.0]),
        vertex([1.0, 1.0, 0.05], [1.0, 1.0]),
        vertex([0.0, 1.0, 0.05], [0.0, 1.0]),
    ];
    // Opaque top half, transparent bottom half (texture rows run down, UV v up).
    let mut pixels = Vec::new();
    for y in 0..8 {
        for _ in 0..8 {
            pixels.extend_from_slice(&[255, 255, 255, if y < 4 { 255 } else { 0 }]);
        }
    }
    let material = RenderMaterial {
        albedo: Some(Arc::new(Texture::new(8, 8, pixels))),
        albedo_factor: [1.0, 0.0, 0.0, 1.0],
        metallic_value: 0.0,
        roughness_value: 0.5,
        ao_value: 1.0,
        ..Default::default()
    };
    let materials = [material];
    let input = PlaneRenderInput {
        rectangle: &rectangle,
        epsilon: 0.1,
        alpha_cutoff: 0.5,
        width: 64,
        height: 32,
        batches: vec![(0, quad.to_vec())],
        materials: &materials,
    };
    let images = gpu.render_rectangles(std::slice::from_ref(&input)).expect("renders").remove(0);
    let texel = |image: &[u8], x: usize, y: usize| -> [u8; 4] { image[(y * 64 + x) * 4..][..4].try_into().unwrap() };
    // Top-left quarter: covered (opaque texture half is the top, UV v ≥ 0.5).
    assert_eq!(texel(&images.albedo, 10, 5), [255, 0, 0, 255], "red, opaque");
    assert_eq!(texel(&images.albedo, 10, 28)[3], 0, "bottom half cut by the alpha test");
    assert_eq!(texel(&images.albedo, 50, 5)[3], 0, "right half: no face");
    let normal = texel(&images.normal, 10, 5);
    assert!(normal[0].abs_diff(128) <= 1 && normal[1].abs_diff(128) <= 1 && normal[2] >= 254, "flat normal: {normal:?}");
    let mra = texel(&images.mra, 10, 5);
    // 0.5 × 255 = 127.5 rounds either way (llvmpipe 128, NVIDIA 127).
    assert!(mra[0] == 0 && mra[1].abs_diff(128) <= 1 && mra[2] == 255, "metallic 0, roughness 0.5, AO 1: {mra:?}");
    let height = texel(&images.height_map, 10, 5)[0];
    assert!(height.abs_diff(191) <= 1, "0.05 over ε 0.1 → 0.75: {height}");

    // Stacked in one submission under a wider rectangle with another camera, each rectangle
    // gets exactly the images it gets alone.
    let wide = PlaneRectangle { origin: [-0.5, -0.25, 0.0], width: 3.0, height: 2.0, ..rectangle.clone() };
    let second = PlaneRenderInput { rectangle: &wide, width: 96, height: 64, ..input.clone() };
    let stacked = gpu.render_rectangles(&[second.clone(), input.clone()]).expect("renders");
    assert_eq!(stacked.len(), 2);
    assert_eq!(stacked[1], images, "the first rectangle, second in the stack");
    assert_eq!(stacked[0], gpu.render_rectangles(&[second]).expect("renders").remove(0), "the wide rectangle");
    assert!(stacked[0].albedo.chunks_exact(4).any(|texel| texel[3] == 255), "the wide rectangle sees the quad too");
}
