//! The per-plane renderer on the GPU (the software Vulkan adapter in CI): coverage, alpha test,
//! colour, the normal in the plane's frame and the height over ±ε.

use std::sync::Arc;

use gpu::{gpu, PlaneRenderInput, RectangleFrame, RenderMaterial, RenderVertex};
use texture::{SurfaceKind, Texture};

fn vertex(position: [f32; 3], uv: [f32; 2]) -> RenderVertex {
    RenderVertex { position, normal: [0.0, 0.0, 1.0], uv, tangent: [1.0, 0.0, 0.0, 1.0] }
}

/// The plane z = 0 over [0, 2] × [0, 1].
fn plane_two_by_one() -> RectangleFrame {
    RectangleFrame {
        origin: [0.0; 3],
        x_axis: [1.0, 0.0, 0.0],
        y_axis: [0.0, 1.0, 0.0],
        normal: [0.0, 0.0, 1.0],
        width: 2.0,
        height: 1.0,
    }
}

/// Two triangles over [0, `right`] × [0, 1] at height `z`, UVs over [0, 1]².
fn quad_up_to(right: f32, z: f32) -> Vec<RenderVertex> {
    vec![
        vertex([0.0, 0.0, z], [0.0, 0.0]),
        vertex([right, 0.0, z], [1.0, 0.0]),
        vertex([right, 1.0, z], [1.0, 1.0]),
        vertex([0.0, 0.0, z], [0.0, 0.0]),
        vertex([right, 1.0, z], [1.0, 1.0]),
        vertex([0.0, 1.0, z], [0.0, 1.0]),
    ]
}

#[test]
fn a_plane_render_covers_its_faces_cuts_alpha_and_encodes_normal_and_height() {
    let gpu = gpu().expect("a GPU adapter (install mesa-vulkan-drivers for the software one)");
    println!("adapter: {}", gpu.adapter_name);
    // The plane z = 0 over [0, 2] × [0, 1]; a quad over its left half, 0.05 above it (ε = 0.1).
    let rectangle = plane_two_by_one();
    let quad = quad_up_to(1.0, 0.05);
    // Opaque top half, transparent bottom half (texture rows run down, UV v up).
    let mut pixels = Vec::new();
    for y in 0..8 {
        for _ in 0..8 {
            pixels.extend_from_slice(&[255, 255, 255, if y < 4 { 255 } else { 0 }]);
        }
    }
    let material = RenderMaterial {
        albedo: Some(Arc::new(texture::mips::mip_chain(
            &Texture::new(8, 8, pixels),
            gpu::material_mip_settings(texture::TextureSlot::Albedo, 0.5),
        ))),
        albedo_factor: [1.0, 0.0, 0.0, 1.0],
        metallic_value: 0.0,
        roughness_value: 0.5,
        ao_value: 1.0,
        ..Default::default()
    };
    let materials = [material];
    let input = PlaneRenderInput {
        frame: rectangle,
        epsilon: 0.1,
        alpha_cutoff: 0.5,
        width: 64,
        height: 32,
        supersampling: 1,
        batches: vec![(0, quad.clone())],
        materials: &materials,
    };
    let images = gpu.render_rectangles(std::slice::from_ref(&input)).expect("renders").remove(0);
    let texel = |image: &[u8], x: usize, y: usize| -> [u8; 4] { image[(y * 64 + x) * 4..][..4].try_into().unwrap() };
    // Top-left quarter: covered (opaque texture half is the top, UV v ≥ 0.5).
    assert_eq!(texel(images.surface(SurfaceKind::Albedo), 10, 5), [255, 0, 0, 255], "red, opaque");
    assert_eq!(texel(images.surface(SurfaceKind::Albedo), 10, 28)[3], 0, "bottom half cut by the alpha test");
    assert_eq!(texel(images.surface(SurfaceKind::Albedo), 50, 5)[3], 0, "right half: no face");
    let normal = texel(images.surface(SurfaceKind::Normal), 10, 5);
    assert!(
        normal[0].abs_diff(128) <= 1 && normal[1].abs_diff(128) <= 1 && normal[2] >= 254,
        "flat normal: {normal:?}"
    );
    let mra = texel(images.surface(SurfaceKind::Mra), 10, 5);
    // 0.5 × 255 = 127.5 rounds either way (llvmpipe 128, NVIDIA 127).
    assert!(mra[0] == 0 && mra[1].abs_diff(128) <= 1 && mra[2] == 255, "metallic 0, roughness 0.5, AO 1: {mra:?}");
    let height = texel(images.surface(SurfaceKind::Height), 10, 5)[0];
    assert!(height.abs_diff(191) <= 1, "0.05 over ε 0.1 → 0.75: {height}");

    // Stacked in one submission under a wider rectangle with another camera, each rectangle
    // gets exactly the images it gets alone.
    let wide = RectangleFrame { origin: [-0.5, -0.25, 0.0], width: 3.0, height: 2.0, ..rectangle };
    let second = PlaneRenderInput { frame: wide, width: 96, height: 64, ..input.clone() };
    let stacked = gpu.render_rectangles(&[second.clone(), input.clone()]).expect("renders");
    assert_eq!(stacked.len(), 2);
    assert_eq!(stacked[1], images, "the first rectangle, second in the stack");
    assert_eq!(stacked[0], gpu.render_rectangles(&[second]).expect("renders").remove(0), "the wide rectangle");
    assert!(
        stacked[0].surface(SurfaceKind::Albedo).chunks_exact(4).any(|texel| texel[3] == 255),
        "the wide rectangle sees the quad too"
    );
}

#[test]
fn a_supersampled_plane_render_puts_a_cut_out_edge_between_texels() {
    let gpu = gpu().expect("a GPU adapter (install mesa-vulkan-drivers for the software one)");
    // The plane z = 0 over [0, 2] × [0, 1] in 64 × 32 texels (32 per unit); a green quad over
    // x ≤ 0.99, so its right edge lies at texel 31.68, not on a texel boundary.
    let rectangle = plane_two_by_one();
    let quad = quad_up_to(0.99, 0.0);
    let materials = [RenderMaterial {
        albedo_factor: [0.0, 1.0, 0.0, 1.0],
        roughness_value: 0.5,
        ao_value: 1.0,
        ..Default::default()
    }];
    let input = |supersampling| PlaneRenderInput {
        frame: rectangle,
        epsilon: 0.1,
        alpha_cutoff: 0.5,
        width: 64,
        height: 32,
        supersampling,
        batches: vec![(0, quad.clone())],
        materials: &materials,
    };
    // Where a bilinear fetch along row 16 crosses alpha one half.
    let crossing = |images: &gpu::PlaneImages| -> f32 {
        let alpha: Vec<f32> =
            (0..64).map(|x| images.surface(SurfaceKind::Albedo)[(16 * 64 + x) * 4 + 3] as f32 / 255.0).collect();
        let last = (0..63).find(|&x| alpha[x] >= 0.5 && alpha[x + 1] < 0.5).expect("an edge along the row");
        last as f32 + 0.5 + (alpha[last] - 0.5) / (alpha[last] - alpha[last + 1])
    };
    let one = gpu.render_rectangles(&[input(1)]).expect("renders").remove(0);
    let four = gpu.render_rectangles(&[input(2)]).expect("renders").remove(0);
    assert_eq!((four.width, four.height), (64, 32), "brought down to the texels asked for");
    let (one_edge, four_edge) = (crossing(&one), crossing(&four));
    // One coverage test per texel: the edge halfway between texel centres 31.5 and 32.5; two
    // by two samples put it halfway between samples 31.25 and 31.75.
    assert!((one_edge - 32.0).abs() < 0.01, "one sample per texel: edge at {one_edge}");
    assert!((four_edge - 31.68).abs() < 0.25, "2 × 2 samples: edge at {four_edge}, the quad's at 31.68");
    // Inside, the texels are the quad's; well outside, nothing is drawn.
    let texel =
        |x: usize| -> [u8; 4] { four.surface(SurfaceKind::Albedo)[(16 * 64 + x) * 4..][..4].try_into().unwrap() };
    assert_eq!(texel(20), [0, 255, 0, 255]);
    assert_eq!(texel(31)[..3], [0, 255, 0], "the edge texel keeps the quad's colour");
    assert_eq!(texel(40), [0, 0, 0, 0]);
}

#[test]
fn a_resolved_pixel_is_in_the_silhouette_when_half_its_samples_are_covered() {
    use render::preview::{resolve_samples, silhouette_overlap, ResolvedView};
    // Two by two pixels of 4 × 4 samples: white where covered, black background. Covered samples
    // per pixel: 16, 8, 7, 0.
    let covered_per_pixel = [16, 8, 7, 0];
    let mut samples = vec![0u8; 8 * 8 * 4];
    for (pixel, &covered) in covered_per_pixel.iter().enumerate() {
        let (pixel_x, pixel_y) = (pixel % 2, pixel / 2);
        for sample in 0..covered {
            let (x, y) = (pixel_x * 4 + sample % 4, pixel_y * 4 + sample / 4);
            samples[(y * 8 + x) * 4..][..4].copy_from_slice(&[255, 255, 255, 255]);
        }
    }
    let view = resolve_samples(&samples, 2, 4);
    assert_eq!(view.covered, vec![16, 8, 7, 0]);
    assert_eq!((0..4).map(|pixel| view.in_silhouette(pixel)).collect::<Vec<_>>(), [true, true, false, false]);
    // Half the samples white is half the light: sRGB 188, not 128.
    assert_eq!(view.rgba[4..8], [188, 188, 188, 255]);
    assert_eq!(view.rgba[12..16], [0, 0, 0, 0]);
    let one_pixel = resolve_samples(&samples[..4 * 4 * 4], 1, 1);
    assert_eq!((one_pixel.covered[0], one_pixel.in_silhouette(0)), (1, true));
    assert_eq!(silhouette_overlap(&view, &view).iou, 1.0);
    // A LOD covering pixels 0 and 2 of the source's 0 and 1: one of the source's two pixels
    // missed, one pixel extra.
    let lod = ResolvedView { rgba: vec![0; 16], covered: vec![16, 0, 9, 0], samples_per_pixel: 16 };
    let overlap = silhouette_overlap(&view, &lod);
    assert_eq!((overlap.iou, overlap.missed, overlap.extra), (1.0 / 3.0, 0.5, 0.5));
}

#[test]
fn a_one_pixel_shift_costs_a_thin_silhouette_more_iou_than_a_solid_one() {
    use render::preview::{one_pixel_shift_iou, ResolvedView};
    // A 16-pixel view holding `inside` pixels, every sample of them covered.
    let view = |inside: &dyn Fn(usize, usize) -> bool| ResolvedView {
        rgba: vec![0; 16 * 16 * 4],
        covered: (0..16 * 16).map(|index| if inside(index % 16, index / 16) { 16 } else { 0 }).collect(),
        samples_per_pixel: 16,
    };
    // A 10 × 10 square moved one pixel either way: 90 pixels shared of 110 (at the edge of the
    // image too: nothing moved out of it is lost).
    let square = view(&|x, y| (6..16).contains(&x) && (6..16).contains(&y));
    assert!((one_pixel_shift_iou(&square, 16) - 90.0 / 110.0).abs() < 1e-12);
    // Five one-pixel strokes across the image: moved across them, nothing is shared; along
    // them, 15 of 16 pixels of each are. So a pixel of displacement costs lacy foliage more.
    let strokes = view(&|x, _| x % 3 == 0 && x < 15);
    assert!((one_pixel_shift_iou(&strokes, 16) - 0.5 * (15.0 / 17.0)).abs() < 1e-12);
    assert_eq!(one_pixel_shift_iou(&view(&|_, _| false), 16), 1.0);
}

/// A quad in the plane x = 0, seen along x, cut out by an alpha texture of 256² random texels
/// (70 % opaque) that spans 48 pixels of a 64-pixel view: detail finer than a pixel, as foliage
/// is at preview sizes.
fn speckled_quad(offset: f32) -> gpu::ViewMesh {
    use texture::mips::{mip_chain, MipSettings};
    let mut state = 12345u32;
    let mut pixels = Vec::new();
    for _ in 0..256 * 256 {
        state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        let alpha = if (state >> 8) % 10 < 7 { 255 } else { 0 };
        pixels.extend([60, 160, 60, alpha]);
    }
    let levels = mip_chain(
        &Texture::new(256, 256, pixels),
        MipSettings { kind: texture::SurfaceKind::Albedo, alpha_cutoff: Some(0.5) },
    );
    let corner = |y: f32, z: f32, uv: [f32; 2]| RenderVertex {
        position: [0.0, y + offset, z + offset],
        normal: [1.0, 0.0, 0.0],
        uv,
        tangent: [0.0, 1.0, 0.0, 1.0],
    };
    let (low, high) = (-0.75, 0.75);
    let vertices = vec![
        corner(low, low, [0.0, 0.0]),
        corner(high, low, [1.0, 0.0]),
        corner(high, high, [1.0, 1.0]),
        corner(low, low, [0.0, 0.0]),
        corner(high, high, [1.0, 1.0]),
        corner(low, high, [0.0, 1.0]),
    ];
    let material = gpu::ViewMaterial {
        albedo: Some(Arc::new(levels)),
        albedo_factor: [1.0; 4],
        alpha_cutoff: 0.5,
        ..Default::default()
    };
    gpu::ViewMesh { batches: vec![(0, vertices)], materials: vec![material] }
}

#[test]
fn sixteen_samples_per_pixel_keep_the_silhouette_iou_from_measuring_aliasing() {
    use render::preview::{preview, PreviewSettings};
    let gpu = gpu().expect("a GPU adapter (install mesa-vulkan-drivers for the software one)");
    // The same cut-out moved by a quarter pixel: a LOD could hardly be closer.
    let quarter_pixel = 0.25 * 2.0 / 64.0;
    let (source, moved) = (speckled_quad(0.0), gpu::LevelView::Mesh(speckled_quad(quarter_pixel)));
    let iou = |samples_per_axis| {
        let settings = PreviewSettings { views: 1, size: 64, samples_per_axis };
        let preview = preview(gpu, &source, &moved, [0.0; 3], 1.0, settings).expect("renders");
        assert_eq!(preview.metrics.samples_per_pixel, samples_per_axis * samples_per_axis);
        preview.metrics.mean_iou
    };
    let (one_sample, sixteen_samples) = (iou(1), iou(4));
    println!("quarter-pixel move: IoU {one_sample:.3} with 1 sample per pixel, {sixteen_samples:.3} with 16");
    assert!(sixteen_samples > 0.9 && sixteen_samples > one_sample + 0.1, "{one_sample} vs {sixteen_samples}");
}

#[test]
fn an_adapter_that_cannot_draw_every_target_is_refused_with_what_it_lacks() {
    use wgpu::{DownlevelFlags, TextureFormat, TextureUsages};
    // An OpenGL ES driver as wgpu reports it: R32Float sampled but not rendered to, no storage
    // buffers in vertex shaders. Choosing it used to panic in pipeline creation.
    let gl_like = |format: TextureFormat| match format {
        TextureFormat::R32Float => TextureUsages::TEXTURE_BINDING,
        _ => TextureUsages::all(),
    };
    let shortfalls = gpu::adapter_shortfalls(&gl_like, DownlevelFlags::all() - DownlevelFlags::VERTEX_STORAGE);
    assert_eq!(shortfalls, ["R32Float render targets", "storage buffers in vertex shaders"]);
    assert!(gpu::adapter_shortfalls(&|_| TextureUsages::all(), DownlevelFlags::all()).is_empty());
    // The adapter the tests run on passes the check (else `gpu()` would have refused it).
    gpu().expect("a GPU adapter (install mesa-vulkan-drivers for the software one)");
}

#[test]
fn a_render_the_device_refuses_is_an_error_and_the_device_still_renders() {
    let gpu = gpu().expect("a GPU adapter (install mesa-vulkan-drivers for the software one)");
    let quad = speckled_quad(0.0);
    let camera = render::preview::view_projection([0.0; 3], 1.0, [1.0, 0.0, 0.0]);
    // A 0-pixel target is invalid to wgpu, which panics on errors nothing catches.
    let refused = gpu.render_view(&quad, camera, [0.0, 0.0, 1.0], 0);
    assert!(matches!(&refused, Err(gpu::GpuError::Render(message)) if message.contains("imension")), "{refused:?}");
    let image = gpu.render_view(&quad, camera, [0.0, 0.0, 1.0], 16).expect("the next render");
    assert!(image.chunks_exact(4).any(|pixel| pixel[3] == 255), "the quad is drawn");
}
