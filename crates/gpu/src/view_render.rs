//! The preview renderer: a mesh with mipmapped materials under an orthographic camera
//! (`shaders/view.wgsl`), for `cirrus preview` and the viewer.

use std::sync::Arc;

use base::stop::ShouldStop;

use bytemuck::{Pod, Zeroable};

use super::*;

/// A material for preview renders: textures with their own mip levels (level 0 first).
#[derive(Clone, Debug, Default)]
pub struct ViewMaterial {
    pub albedo: Option<Arc<Vec<Texture>>>,
    pub opacity: Option<Arc<Vec<Texture>>>,
    pub normal: Option<Arc<Vec<Texture>>>,
    /// False for two-channel normal maps (BC5): the shader rebuilds z.
    pub normal_has_z: bool,
    /// Linear RGB factor and constant opacity.
    pub albedo_factor: [f32; 4],
    pub alpha_cutoff: f32,
}

/// A mesh for preview renders: vertex batches per material.
#[derive(Clone, Debug, Default)]
pub struct ViewMesh {
    pub batches: Vec<(usize, Vec<RenderVertex>)>,
    pub materials: Vec<ViewMaterial>,
}

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct CameraUniform {
    view_projection: [[f32; 4]; 4],
    light: [f32; 4],
}

/// The pipelines of one `view.wgsl` fragment entry point, one for each set of maps a material has
/// (its `HAS_OPACITY_MAP` and `HAS_NORMAL_MAP`), each made on first use: a map the material lacks
/// is not sampled. On llvmpipe a sample is a filtered fetch for every fragment, discarded ones
/// included: the oak's leaves have no normal map and its bark no opacity map.
pub(super) struct MapPipelines {
    shader: (wgpu::ShaderModule, &'static str),
    layout: wgpu::PipelineLayout,
    formats: Vec<wgpu::TextureFormat>,
    /// By `opacity map + 2 × normal map`.
    pipelines: [std::sync::OnceLock<wgpu::RenderPipeline>; 4],
}

impl MapPipelines {
    /// The pipelines of `shader`'s fragment entry point, drawing into one target per format,
    /// depth-tested.
    pub(super) fn new(
        shader: (wgpu::ShaderModule, &'static str),
        layout: wgpu::PipelineLayout,
        formats: &[wgpu::TextureFormat],
    ) -> MapPipelines {
        MapPipelines { shader, layout, formats: formats.to_vec(), pipelines: Default::default() }
    }

    /// The pipelines of another fragment entry point of the same shader, with the same layout.
    pub(super) fn for_entry(&self, entry: &'static str, formats: &[wgpu::TextureFormat]) -> MapPipelines {
        MapPipelines::new((self.shader.0.clone(), entry), self.layout.clone(), formats)
    }

    /// The pipeline that draws `material`.
    fn for_material(&self, device: &wgpu::Device, material: &ViewMaterial) -> &wgpu::RenderPipeline {
        let (opacity, normal) = (material.opacity.is_some(), material.normal.is_some());
        self.pipelines[opacity as usize + 2 * normal as usize].get_or_init(|| {
            let targets: Vec<Option<wgpu::ColorTargetState>> =
                self.formats.iter().map(|&format| Some(format.into())).collect();
            let constants =
                [("HAS_OPACITY_MAP", f64::from(u8::from(opacity))), ("HAS_NORMAL_MAP", f64::from(u8::from(normal)))];
            let (shader, entry) = (&self.shader.0, self.shader.1);
            let label = format!("{entry}, opacity map {opacity}, normal map {normal}");
            mesh_pipeline(device, &label, &self.layout, (shader, entry, &constants), &targets, Some(depth_test()))
        })
    }
}

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct ViewMaterialUniform {
    albedo: [f32; 4],
    flags: [f32; 4],
    params: [f32; 4],
}

/// The most bytes of render targets (colour and depth) one submission of a batch of views holds:
/// a batch's views are drawn one after another and read back together, one wait for the device
/// instead of one a view (on llvmpipe the same time: it draws the views one by one either way).
const BATCH_TARGET_BYTES: u64 = 16 << 20;

/// How many `size`² views, each with `targets` RGBA8 targets and a depth target, one submission
/// draws.
pub fn views_per_batch(size: u32, targets: usize) -> usize {
    let view_bytes = u64::from(size).pow(2) * 4 * (targets as u64 + 1);
    (BATCH_TARGET_BYTES / view_bytes.max(1)).max(1) as usize
}

impl Gpu {
    /// Draws `count` views, each `size`² with `targets` colour targets, in batches of
    /// [`views_per_batch`]: `record` records view `index`'s pass into its batch's encoder and
    /// returns its targets; each batch is read back at once, and each view's targets' pixels go to
    /// `each` with its index, in order, before the next batch is drawn (so that at most a batch's
    /// pixels are held). Before each batch, `should_stop` may end the work (`GpuError::Stopped`).
    pub(super) fn draw_in_batches(
        &self,
        (count, size, targets): (usize, u32, usize),
        should_stop: ShouldStop,
        mut record: impl FnMut(&mut wgpu::CommandEncoder, usize) -> Vec<wgpu::Texture>,
        mut each: impl FnMut(usize, Vec<Vec<u8>>),
    ) -> Result<(), GpuError> {
        let batch = views_per_batch(size, targets);
        for first in (0..count).step_by(batch) {
            if should_stop() {
                return Err(GpuError::Stopped);
            }
            let views = first..(first + batch).min(count);
            let mut encoder = self.device.create_command_encoder(&Default::default());
            let mut drawn: Vec<wgpu::Texture> = Vec::with_capacity(views.len() * targets);
            for index in views.clone() {
                drawn.extend(record(&mut encoder, index));
            }
            let drawn: Vec<&wgpu::Texture> = drawn.iter().collect();
            let mut pixels = self.read_back(encoder, &drawn)?.into_iter();
            for index in views {
                each(index, pixels.by_ref().take(targets).collect());
            }
        }
        Ok(())
    }

    /// Renders `mesh` under an orthographic camera into a `size`² RGBA8 image (sRGB colour on a
    /// mid-grey background; alpha 255 where a surface was drawn, 0 elsewhere).
    pub fn render_view(
        &self,
        mesh: &ViewMesh,
        view_projection: [[f32; 4]; 4],
        light: [f32; 3],
        size: u32,
    ) -> Result<Vec<u8>, GpuError> {
        super::one_view(|each| self.render_views(mesh, &[view_projection], light, size, each))
    }

    /// [`Gpu::render_view`] under each of `view_projections`, drawn in batches
    /// ([`Gpu::draw_in_batches`]): each image goes to `each` with its view's index, in order.
    pub fn render_views(
        &self,
        mesh: &ViewMesh,
        view_projections: &[[[f32; 4]; 4]],
        light: [f32; 3],
        size: u32,
        mut each: impl FnMut(usize, Vec<u8>),
    ) -> Result<(), GpuError> {
        let cameras: Vec<CameraUniform> = view_projections
            .iter()
            .map(|&view_projection| CameraUniform { view_projection, light: extend(light) })
            .collect();
        let pipeline = (&self.view_pipelines, [(ALBEDO_FORMAT, VIEW_BACKGROUND)].as_slice());
        let never = &base::stop::never;
        self.draw_views(mesh, &cameras, (size, never), pipeline, |index, mut images| each(index, images.remove(0)))
    }

    /// Renders impostor frames of `mesh` (`view.wgsl`'s `fs_impostor`), one under each of
    /// `view_projections`, each into two `size`² RGBA8 images: the unlit sRGB albedo with alpha
    /// 255 where drawn, and the world-space normal as `0.5 + 0.5 n` with the depth (0 at the
    /// projection's near plane, 255 at its far one) in alpha; both 0 where nothing was drawn.
    /// Drawn in batches: each frame's images go to `each` with its index, in order.
    pub fn render_impostor_frames(
        &self,
        mesh: &ViewMesh,
        view_projections: &[[[f32; 4]; 4]],
        (size, should_stop): (u32, ShouldStop),
        mut each: impl FnMut(usize, [Vec<u8>; 2]),
    ) -> Result<(), GpuError> {
        let cameras: Vec<CameraUniform> = view_projections
            .iter()
            .map(|&view_projection| CameraUniform { view_projection, light: [0.0; 4] })
            .collect();
        let targets = [(ALBEDO_FORMAT, wgpu::Color::TRANSPARENT), (DATA_FORMAT, wgpu::Color::TRANSPARENT)];
        let pipelines = (&self.impostor_pipelines().frame, &targets[..]);
        self.draw_views(mesh, &cameras, (size, should_stop), pipelines, |index, mut images| {
            let normal_depth = images.pop().unwrap_or_default();
            each(index, [images.pop().unwrap_or_default(), normal_depth])
        })
    }

    /// Draws `mesh` with `pipeline` under each of `cameras` into one `size`² target per format
    /// (cleared to its colour), depth-tested, in batches ([`Gpu::draw_in_batches`]); each view's
    /// targets' pixels go to `each`. The mesh's vertices and materials are bound once for all
    /// views; each view draws each material's triangles nearest first ([`front_to_back`]).
    fn draw_views(
        &self,
        mesh: &ViewMesh,
        cameras: &[CameraUniform],
        (size, should_stop): (u32, ShouldStop),
        (pipelines, formats): (&MapPipelines, &[(wgpu::TextureFormat, wgpu::Color)]),
        each: impl FnMut(usize, Vec<Vec<u8>>),
    ) -> Result<(), GpuError> {
        self.catching_device_errors(|| {
            let mut draws = Vec::new();
            for (material_index, vertices) in &mesh.batches {
                if vertices.is_empty() {
                    continue;
                }
                let buffer = self.vertex_buffer(vertices);
                let material = &mesh.materials[*material_index];
                let pipeline = pipelines.for_material(&self.device, material);
                draws.push((vertices, buffer, self.view_material_group(material), pipeline));
            }
            let record = |encoder: &mut wgpu::CommandEncoder, index: usize| {
                // Each batch's triangles nearest first under this view's camera.
                let orders: Vec<(wgpu::Buffer, u32)> = draws
                    .iter()
                    .map(|(vertices, ..)| {
                        let order = front_to_back(vertices, &cameras[index].view_projection);
                        let usage = wgpu::BufferUsages::INDEX;
                        (self.filled_buffer("triangle order", bytemuck::cast_slice(&order), usage), order.len() as u32)
                    })
                    .collect();
                let camera_buffer = self.constants_buffer(bytemuck::bytes_of(&cameras[index]));
                let camera_group = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some("camera"),
                    layout: &self.frame_layout,
                    entries: &[wgpu::BindGroupEntry { binding: 0, resource: camera_buffer.as_entire_binding() }],
                });
                let targets: Vec<wgpu::Texture> =
                    formats.iter().map(|&(format, _)| self.target(size, size, format)).collect();
                let views: Vec<wgpu::TextureView> =
                    targets.iter().map(|target| target.create_view(&Default::default())).collect();
                let depth = self.target(size, size, DEPTH_FORMAT).create_view(&Default::default());
                let color_attachments: Vec<Option<wgpu::RenderPassColorAttachment>> = views
                    .iter()
                    .zip(formats)
                    .map(|(view, &(_, clear))| {
                        Some(wgpu::RenderPassColorAttachment {
                            view,
                            depth_slice: None,
                            resolve_target: None,
                            ops: wgpu::Operations { load: wgpu::LoadOp::Clear(clear), store: wgpu::StoreOp::Store },
                        })
                    })
                    .collect();
                let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                    label: Some("view"),
                    color_attachments: &color_attachments,
                    depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                        view: &depth,
                        depth_ops: Some(wgpu::Operations {
                            load: wgpu::LoadOp::Clear(1.0),
                            store: wgpu::StoreOp::Discard,
                        }),
                        stencil_ops: None,
                    }),
                    ..Default::default()
                });
                pass.set_bind_group(0, &camera_group, &[]);
                for ((_, buffer, group, pipeline), (order, count)) in draws.iter().zip(&orders) {
                    pass.set_pipeline(pipeline);
                    pass.set_bind_group(1, group, &[]);
                    pass.set_vertex_buffer(0, buffer.slice(..));
                    pass.set_index_buffer(order.slice(..), wgpu::IndexFormat::Uint32);
                    pass.draw_indexed(0..*count, 0, 0..1);
                }
                drop(pass);
                targets
            };
            self.draw_in_batches((cameras.len(), size, formats.len()), should_stop, record, each)
        })
    }

    fn view_material_group(&self, material: &ViewMaterial) -> wgpu::BindGroup {
        let flag = |present: bool| if present { 1.0 } else { 0.0 };
        let uniform = ViewMaterialUniform {
            albedo: material.albedo_factor,
            flags: [flag(material.albedo.is_some()), 0.0, 0.0, flag(material.normal_has_z)],
            params: [material.alpha_cutoff, 0.0, 0.0, 0.0],
        };
        let buffer = self.constants_buffer(bytemuck::bytes_of(&uniform));
        let views: Vec<Arc<wgpu::TextureView>> =
            [(&material.albedo, true), (&material.opacity, false), (&material.normal, false)]
                .into_iter()
                .map(|(levels, srgb)| match levels {
                    Some(levels) => self.levels_view(levels, srgb),
                    None => Arc::new(self.white.clone()),
                })
                .collect();
        let mut entries = vec![
            wgpu::BindGroupEntry { binding: 0, resource: buffer.as_entire_binding() },
            wgpu::BindGroupEntry { binding: 1, resource: wgpu::BindingResource::Sampler(&self.sampler) },
        ];
        for (index, view) in views.iter().enumerate() {
            entries.push(wgpu::BindGroupEntry {
                binding: 2 + index as u32,
                resource: wgpu::BindingResource::TextureView(view),
            });
        }
        self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("view material"),
            layout: &self.view_material_layout,
            entries: &entries,
        })
    }

    /// A texture with explicit mip levels on the GPU (uploaded once per content).
    pub(super) fn levels_view(&self, levels: &[Texture], srgb: bool) -> Arc<wgpu::TextureView> {
        let key = (levels[0].hash, srgb, levels.len() as u32);
        self.cached_upload(key, || {
            upload(&self.device, &self.queue, levels, if srgb { ALBEDO_FORMAT } else { DATA_FORMAT })
        })
    }
}

/// The vertex indices of `vertices`' triangles (three vertices each, as drawn), nearest first
/// under the orthographic `view_projection` (by the depth of each triangle's centroid, in
/// [`DEPTH_STEPS`] steps between the nearest and the farthest; triangles in one step keep their
/// order). Drawn in this order, a fragment behind one already drawn fails the depth test before
/// its shader runs, alpha test included (llvmpipe tests depth early and writes it late when a
/// shader discards): the oak's preview renders (its four levels and the source, 26 views at
/// 512²) took 3.15–3.43 s against 3.48–3.78 s in the mesh's own order, and 3.72–4.54 s farthest
/// first. The image is the same but where two surfaces are at one depth.
pub fn front_to_back(vertices: &[RenderVertex], view_projection: &[[f32; 4]; 4]) -> Vec<u32> {
    let depth = |vertex: &RenderVertex| {
        let [x, y, z] = vertex.position;
        view_projection[0][2] * x + view_projection[1][2] * y + view_projection[2][2] * z
    };
    let depths: Vec<f32> = vertices.chunks_exact(3).map(|corners| corners.iter().map(depth).sum::<f32>()).collect();
    let (near, far) =
        depths.iter().fold((f32::INFINITY, f32::NEG_INFINITY), |(near, far), &depth| (near.min(depth), far.max(depth)));
    let scale = if far > near { (DEPTH_STEPS - 1) as f32 / (far - near) } else { 0.0 };
    let step = |depth: f32| (((depth - near) * scale) as usize).min(DEPTH_STEPS - 1);
    // A counting sort: each step's first place in the order.
    let mut starts = vec![0u32; DEPTH_STEPS + 1];
    for &depth in &depths {
        starts[step(depth) + 1] += 1;
    }
    for index in 0..DEPTH_STEPS {
        starts[index + 1] += starts[index];
    }
    let mut order = vec![0u32; depths.len() * 3];
    for (triangle, &depth) in depths.iter().enumerate() {
        let place = &mut starts[step(depth)];
        let first = 3 * triangle as u32;
        let at = 3 * *place as usize;
        order[at..at + 3].copy_from_slice(&[first, first + 1, first + 2]);
        *place += 1;
    }
    order
}

/// How finely [`front_to_back`] orders triangles by depth.
const DEPTH_STEPS: usize = 4096;
