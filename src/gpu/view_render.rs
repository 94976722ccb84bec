//! The preview renderer: a mesh with mipmapped materials under an orthographic camera
//! (`shaders/view.wgsl`), for `cirrus preview` and the viewer.

use std::sync::Arc;

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
    /// Renders `mesh` under an orthographic camera into a `size`² RGBA8 image (sRGB colour on a
    /// mid-grey background; alpha 255 where a surface was drawn, 0 elsewhere).
    pub fn render_view(
        &self,
        mesh: &ViewMesh,
        view_projection: [[f32; 4]; 4],
        light: [f32; 3],
        size: u32,
    ) -> Result<Vec<u8>, GpuError> {
        self.render_views(mesh, &[view_projection], light, size).map(|mut images| images.remove(0))
    }

    /// [`Gpu::render_view`] under each of `view_projections`, drawn in batches (one image each,
    /// in order).
    pub fn render_views(
        &self,
        mesh: &ViewMesh,
        view_projections: &[[[f32; 4]; 4]],
        light: [f32; 3],
        size: u32,
    ) -> Result<Vec<Vec<u8>>, GpuError> {
        let cameras: Vec<CameraUniform> = view_projections
            .iter()
            .map(|&view_projection| CameraUniform { view_projection, light: extend(light) })
            .collect();
        let views =
            self.draw_views(mesh, &cameras, size, (&self.view_pipeline, &[(ALBEDO_FORMAT, VIEW_BACKGROUND)]))?;
        Ok(views.into_iter().map(|mut images| images.remove(0)).collect())
    }

    /// Renders impostor frames of `mesh` (`view.wgsl`'s `fs_impostor`), one under each of
    /// `view_projections`, each into two `size`² RGBA8 images: the unlit sRGB albedo with alpha
    /// 255 where drawn, and the world-space normal as `0.5 + 0.5 n` with the depth (0 at the
    /// projection's near plane, 255 at its far one) in alpha; both 0 where nothing was drawn.
    pub fn render_impostor_frames(
        &self,
        mesh: &ViewMesh,
        view_projections: &[[[f32; 4]; 4]],
        size: u32,
    ) -> Result<Vec<[Vec<u8>; 2]>, GpuError> {
        let cameras: Vec<CameraUniform> = view_projections
            .iter()
            .map(|&view_projection| CameraUniform { view_projection, light: [0.0; 4] })
            .collect();
        let targets = [(ALBEDO_FORMAT, wgpu::Color::TRANSPARENT), (DATA_FORMAT, wgpu::Color::TRANSPARENT)];
        let views = self.draw_views(mesh, &cameras, size, (&self.impostor_pipelines().frame, &targets))?;
        Ok(views
            .into_iter()
            .map(|mut images| {
                let normal_depth = images.pop().unwrap_or_default();
                [images.pop().unwrap_or_default(), normal_depth]
            })
            .collect())
    }

    /// Draws `mesh` with `pipeline` under each of `cameras` into one `size`² target per format
    /// (cleared to its colour), depth-tested, in batches of [`views_per_batch`]; returns each
    /// view's targets' pixels. The mesh's vertices and materials are bound once for all views.
    fn draw_views(
        &self,
        mesh: &ViewMesh,
        cameras: &[CameraUniform],
        size: u32,
        (pipeline, formats): (&wgpu::RenderPipeline, &[(wgpu::TextureFormat, wgpu::Color)]),
    ) -> Result<Vec<Vec<Vec<u8>>>, GpuError> {
        self.catching_device_errors(|| {
            let mut draws = Vec::new();
            for (material_index, vertices) in &mesh.batches {
                if vertices.is_empty() {
                    continue;
                }
                let buffer = self.vertex_buffer(vertices);
                draws.push((buffer, vertices.len() as u32, self.view_material_group(&mesh.materials[*material_index])));
            }
            let mut images = Vec::with_capacity(cameras.len());
            for batch in cameras.chunks(views_per_batch(size, formats.len())) {
                let mut encoder = self.device.create_command_encoder(&Default::default());
                let mut targets: Vec<wgpu::Texture> = Vec::with_capacity(batch.len() * formats.len());
                for camera in batch {
                    let camera_buffer = self.constants_buffer(bytemuck::bytes_of(camera));
                    let camera_group = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
                        label: Some("camera"),
                        layout: &self.frame_layout,
                        entries: &[wgpu::BindGroupEntry { binding: 0, resource: camera_buffer.as_entire_binding() }],
                    });
                    let view_targets: Vec<wgpu::Texture> =
                        formats.iter().map(|&(format, _)| self.target(size, size, format)).collect();
                    let views: Vec<wgpu::TextureView> =
                        view_targets.iter().map(|target| target.create_view(&Default::default())).collect();
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
                    pass.set_pipeline(pipeline);
                    pass.set_bind_group(0, &camera_group, &[]);
                    for (buffer, count, group) in &draws {
                        pass.set_bind_group(1, group, &[]);
                        pass.set_vertex_buffer(0, buffer.slice(..));
                        pass.draw(0..*count, 0..1);
                    }
                    drop(pass);
                    targets.extend(view_targets);
                }
                let targets: Vec<&wgpu::Texture> = targets.iter().collect();
                let mut pixels = self.read_back(encoder, &targets)?.into_iter();
                for _ in batch {
                    images.push(pixels.by_ref().take(formats.len()).collect());
                }
            }
            Ok(images)
        })
    }

    fn view_material_group(&self, material: &ViewMaterial) -> wgpu::BindGroup {
        let flag = |present: bool| if present { 1.0 } else { 0.0 };
        let uniform = ViewMaterialUniform {
            albedo: material.albedo_factor,
            flags: [
                flag(material.albedo.is_some()),
                flag(material.opacity.is_some()),
                flag(material.normal.is_some()),
                flag(material.normal_has_z),
            ],
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
