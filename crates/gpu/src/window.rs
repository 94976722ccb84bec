//! Window surfaces for the viewer example: an image from the view renderer presented
//! centred in a window (`shaders/present.wgsl`).

use super::*;

/// A window the viewer presents rendered images on (see [`Gpu::window_surface`]).
pub struct WindowSurface {
    surface: wgpu::Surface<'static>,
    config: wgpu::SurfaceConfiguration,
    pipeline: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
}

impl Gpu {
    /// A surface on `window` (anything wgpu can present to, e.g. an `Arc<winit::window::Window>`)
    /// that shows images from [`Gpu::render_view`]: used by the viewer example.
    pub fn window_surface(
        &self,
        window: impl Into<wgpu::SurfaceTarget<'static>>,
        width: u32,
        height: u32,
    ) -> Result<WindowSurface, GpuError> {
        let surface = self
            .instance
            .create_surface(window)
            .map_err(|error| GpuError::Render(format!("cannot create a window surface: {error}")))?;
        let capabilities = surface.get_capabilities(&self.adapter);
        // Formats that store the image's bytes as they are come first; an sRGB one decodes in the shader.
        let preference = [
            wgpu::TextureFormat::Bgra8Unorm,
            wgpu::TextureFormat::Rgba8Unorm,
            wgpu::TextureFormat::Bgra8UnormSrgb,
            wgpu::TextureFormat::Rgba8UnormSrgb,
        ];
        let format = preference.into_iter().find(|format| capabilities.formats.contains(format)).ok_or_else(|| {
            GpuError::Render(format!("the window offers no 8-bit RGBA surface format ({:?})", capabilities.formats))
        })?;
        let mut config = surface.get_default_config(&self.adapter, width.max(1), height.max(1)).ok_or_else(|| {
            GpuError::Render(format!("the adapter {} cannot present to this window", self.adapter_name))
        })?;
        config.format = format;
        config.view_formats = vec![];
        surface.configure(&self.device, &config);
        let shader = self.device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("present.wgsl"),
            source: wgpu::ShaderSource::Wgsl(include_str!("../../../shaders/present.wgsl").into()),
        });
        let layout = self.device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("present"),
            entries: &[
                wgpu::BindGroupLayoutEntry {
                    binding: 0,
                    visibility: wgpu::ShaderStages::FRAGMENT,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Storage { read_only: true },
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                    count: None,
                },
                wgpu::BindGroupLayoutEntry {
                    binding: 1,
                    visibility: wgpu::ShaderStages::FRAGMENT,
                    ty: wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Float { filterable: false },
                        view_dimension: wgpu::TextureViewDimension::D2,
                        multisampled: false,
                    },
                    count: None,
                },
            ],
        });
        let pipeline_layout = self.device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("present"),
            bind_group_layouts: &[Some(&layout)],
            ..Default::default()
        });
        let pipeline = self.device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("present"),
            layout: Some(&pipeline_layout),
            vertex: wgpu::VertexState {
                module: &shader,
                entry_point: Some("vs_main"),
                compilation_options: Default::default(),
                buffers: &[],
            },
            fragment: Some(wgpu::FragmentState {
                module: &shader,
                entry_point: Some("fs_main"),
                compilation_options: Default::default(),
                targets: &[Some(format.into())],
            }),
            primitive: Default::default(),
            depth_stencil: None,
            multisample: Default::default(),
            multiview_mask: None,
            cache: None,
        });
        Ok(WindowSurface { surface, config, pipeline, layout })
    }

    /// Follows a window resize.
    pub fn resize_window_surface(&self, surface: &mut WindowSurface, width: u32, height: u32) {
        surface.config.width = width.max(1);
        surface.config.height = height.max(1);
        surface.surface.configure(&self.device, &surface.config);
    }

    /// Shows a `size`² image from [`Gpu::render_view`] centred in the window (cropped where the
    /// window is smaller, on the images' background grey where it is larger). A frame the surface cannot give right
    /// now is skipped.
    pub fn present_image(&self, surface: &mut WindowSurface, rgba: &[u8], size: u32) -> Result<(), GpuError> {
        let frame = match surface.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(frame) | wgpu::CurrentSurfaceTexture::Suboptimal(frame) => frame,
            wgpu::CurrentSurfaceTexture::Outdated | wgpu::CurrentSurfaceTexture::Lost => {
                surface.surface.configure(&self.device, &surface.config);
                return Ok(());
            }
            wgpu::CurrentSurfaceTexture::Timeout | wgpu::CurrentSurfaceTexture::Occluded => return Ok(()),
            wgpu::CurrentSurfaceTexture::Validation => {
                return Err(GpuError::Render("the window surface failed validation".into()))
            }
        };
        let image = upload(&self.device, &self.queue, &[Texture::new(size, size, rgba.to_vec())], DATA_FORMAT);
        let offset = [
            (size as f32 - surface.config.width as f32) / 2.0,
            (size as f32 - surface.config.height as f32) / 2.0,
            if surface.config.format.is_srgb() { 1.0 } else { 0.0 },
            0.0,
        ];
        let uniform = self.constants_buffer(bytemuck::bytes_of(&offset));
        let group = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("present"),
            layout: &surface.layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: uniform.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 1, resource: wgpu::BindingResource::TextureView(&image) },
            ],
        });
        let view = frame.texture.create_view(&Default::default());
        let mut encoder = self.device.create_command_encoder(&Default::default());
        {
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("present"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: &view,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(wgpu::Color::BLACK),
                        store: wgpu::StoreOp::Store,
                    },
                })],
                ..Default::default()
            });
            pass.set_pipeline(&surface.pipeline);
            pass.set_bind_group(0, &group, &[]);
            pass.draw(0..3, 0..1);
        }
        self.queue.submit([encoder.finish()]);
        self.queue.present(frame);
        Ok(())
    }
}
