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
        let camera = CameraUniform { view_projection, light: extend(light) };
        self.draw_view(mesh, camera, size, (&self.view_pipeline, &[(ALBEDO_FORMAT, VIEW_BACKGROUND)]))
            .map(|mut images| images.remove(0))
    }

    /// Renders an impostor frame of `mesh` (`view.wgsl`'s `fs_impostor`) into two `size`² RGBA8
    /// images: the unlit sRGB albedo with alpha 255 where drawn, and the world-space normal as
    /// `0.5 + 0.5 n` with the depth (0 at the projection's near plane, 255 at its far one) in
    /// alpha; both 0 where nothing was drawn.
    pub fn render_impostor_frame(
        &self,
        mesh: &ViewMesh,
        view_projection: [[f32; 4]; 4],
        size: u32,
    ) -> Result<[Vec<u8>; 2], GpuError> {
        let camera = CameraUniform { view_projection, light: [0.0; 4] };
        let targets = [(ALBEDO_FORMAT, wgpu::Color::TRANSPARENT), (DATA_FORMAT, wgpu::Color::TRANSPARENT)];
        let mut images = self.draw_view(mesh, camera, size, (&self.impostor_pipelines().frame, &targets))?;
        let normal_depth = images.pop().unwrap_or_default();
        Ok([images.pop().unwrap_or_default(), normal_depth])
    }

    /// Draws `mesh` with `pipeline` into one `size`² target per format (cleared to its colour),
    /// depth-tested; returns each target's pixels.
    fn draw_view(
        &self,
        mesh: &ViewMesh,
        camera: CameraUniform,
        size: u32,
        (pipeline, formats): (&wgpu::RenderPipeline, &[(wgpu::TextureFormat, wgpu::Color)]),
    ) -> Result<Vec<Vec<u8>>, GpuError> {
        self.catching_device_errors(|| {
            let camera_buffer = self.constants_buffer(bytemuck::bytes_of(&camera));
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
            let mut draws = Vec::new();
            for (material_index, vertices) in &mesh.batches {
                if vertices.is_empty() {
                    continue;
                }
                let buffer = self.vertex_buffer(vertices);
                draws.push((buffer, vertices.len() as u32, self.view_material_group(&mesh.materials[*material_index])));
            }
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
            let mut encoder = self.device.create_command_encoder(&Default::default());
            {
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
            }
            let targets: Vec<&wgpu::Texture> = targets.iter().collect();
            self.read_back(encoder, &targets)
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
