//! The top-down depth renderer (`shaders/top_down.wgsl`): a mesh seen orthographically along −Y
//! over an XZ footprint, the highest surface's Y per texel (the `Height` kind's `TopDown`
//! projection). Texel centres sample, as the UV rasteriser's do.

use bytemuck::{Pod, Zeroable};

use super::*;

/// Texels no triangle covers hold this.
const ABSENT: f64 = -3.0e38;

/// What a top-down render covers: X from `min[0]` to `max[0]` across, Z from `min[1]` to
/// `max[1]` down, and the Y range the heights lie in.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Footprint {
    pub min: [f32; 2],
    pub max: [f32; 2],
    pub low_y: f32,
    pub high_y: f32,
}

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct FootprintUniform {
    area: [f32; 4],
    heights: [f32; 4],
}

pub(super) fn top_down_pipeline(device: &wgpu::Device, frame_layout: &wgpu::BindGroupLayout) -> wgpu::RenderPipeline {
    let shader = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("top_down.wgsl"),
        source: wgpu::ShaderSource::Wgsl(include_str!("../../../shaders/top_down.wgsl").into()),
    });
    let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some("top down"),
        bind_group_layouts: &[Some(frame_layout)],
        ..Default::default()
    });
    let attributes = wgpu::vertex_attr_array![0 => Float32x3];
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some("top down"),
        layout: Some(&layout),
        vertex: wgpu::VertexState {
            module: &shader,
            entry_point: Some("vs_main"),
            compilation_options: Default::default(),
            buffers: &[Some(wgpu::VertexBufferLayout {
                array_stride: 12,
                step_mode: wgpu::VertexStepMode::Vertex,
                attributes: &attributes,
            })],
        },
        fragment: Some(wgpu::FragmentState {
            module: &shader,
            entry_point: Some("fs_main"),
            compilation_options: Default::default(),
            targets: &[Some(HEIGHT_FORMAT.into())],
        }),
        primitive: wgpu::PrimitiveState { cull_mode: None, ..Default::default() },
        depth_stencil: Some(wgpu::DepthStencilState {
            format: DEPTH_FORMAT,
            depth_write_enabled: Some(true),
            depth_compare: Some(wgpu::CompareFunction::Less),
            stencil: Default::default(),
            bias: Default::default(),
        }),
        multisample: wgpu::MultisampleState::default(),
        multiview_mask: None,
        cache: None,
    })
}

pub(super) const HEIGHT_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::R32Float;

impl Gpu {
    /// The highest surface's Y above `footprint.low_y` at every texel centre of a `size`² grid
    /// over `footprint` (row by row, row 0 at the lowest Z), none where no triangle covers the
    /// centre. Relative, so that two renders over one footprint subtract without losing bits.
    pub fn render_top_down(
        &self,
        positions: &[[f32; 3]],
        triangles: &[[u32; 3]],
        footprint: Footprint,
        size: u32,
    ) -> Result<Vec<Option<f32>>, GpuError> {
        self.catching_device_errors(|| {
            if size == 0 || size > self.max_texture_size {
                return Err(GpuError::Render(format!(
                    "a {size}² top-down render exceeds the device's {} texels",
                    self.max_texture_size
                )));
            }
            let span = |low: f32, high: f32| if high > low { 1.0 / (high - low) } else { 1.0 };
            let uniform = FootprintUniform {
                area: [
                    footprint.min[0],
                    footprint.min[1],
                    span(footprint.min[0], footprint.max[0]),
                    span(footprint.min[1], footprint.max[1]),
                ],
                heights: [footprint.low_y, span(footprint.low_y, footprint.high_y) * 0.999_9, 0.0, 0.0],
            };
            let constants = self.constants_buffer(bytemuck::bytes_of(&uniform));
            let group = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("footprint"),
                layout: &self.frame_layout,
                entries: &[wgpu::BindGroupEntry { binding: 0, resource: constants.as_entire_binding() }],
            });
            let corners: Vec<[f32; 3]> = triangles
                .iter()
                .flat_map(|triangle| {
                    triangle.map(|vertex| positions.get(vertex as usize).copied().unwrap_or([f32::NAN; 3]))
                })
                .filter(|corner| corner.iter().all(|c| c.is_finite()))
                .collect();
            let target = self.target(size, size, HEIGHT_FORMAT);
            let view = target.create_view(&Default::default());
            let depth = self.target(size, size, DEPTH_FORMAT).create_view(&Default::default());
            let mut encoder = self.device.create_command_encoder(&Default::default());
            {
                let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                    label: Some("top down"),
                    color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                        view: &view,
                        depth_slice: None,
                        resolve_target: None,
                        ops: wgpu::Operations {
                            load: wgpu::LoadOp::Clear(wgpu::Color { r: ABSENT, g: 0.0, b: 0.0, a: 0.0 }),
                            store: wgpu::StoreOp::Store,
                        },
                    })],
                    depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                        view: &depth,
                        depth_ops: Some(wgpu::Operations {
                            load: wgpu::LoadOp::Clear(1.0),
                            store: wgpu::StoreOp::Store,
                        }),
                        stencil_ops: None,
                    }),
                    ..Default::default()
                });
                if corners.len() >= 3 {
                    let buffer =
                        self.filled_buffer("positions", bytemuck::cast_slice(&corners), wgpu::BufferUsages::VERTEX);
                    pass.set_pipeline(&self.top_down_pipeline);
                    pass.set_bind_group(0, &group, &[]);
                    pass.set_vertex_buffer(0, buffer.slice(..));
                    pass.draw(0..(corners.len() / 3 * 3) as u32, 0..1);
                }
            }
            let [pixels]: [Vec<u8>; 1] = self.read_back(encoder, &[&target])?.try_into().expect("one target");
            Ok(pixels
                .chunks_exact(4)
                .map(|bytes| {
                    let relative = f32::from_ne_bytes(bytes.try_into().expect("four bytes"));
                    (relative > (ABSENT / 2.0) as f32).then_some(relative)
                })
                .collect())
        })
    }
}
