//! The impostor shader's frame selection run on the GPU: `shaders/impostor.wgsl`'s
//! `impostor_blend` over a list of directions, in a compute pass, so that the shader engines
//! copy is checked against the reference (`mesh::octahedral`) on the device that runs it.

use super::{Gpu, GpuError};
use crate::mesh::octahedral::{FrameGrid, Sphere};

/// A compute entry point over `impostor.wgsl`: one invocation per direction, writing its three
/// frames and (bit-cast) weights.
const BLEND_ENTRY: &str = r#"
struct Query { frames: u32, hemi: u32, count: u32, unused: u32 }
@group(0) @binding(0) var<storage, read> query: Query;
@group(0) @binding(1) var<storage, read> directions: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read_write> blends: array<vec4<u32>>;

@compute @workgroup_size(64)
fn blend_main(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= query.count {
        return;
    }
    let blend = impostor_blend(directions[id.x].xyz, query.frames, query.hemi != 0u);
    blends[2u * id.x] = vec4<u32>(blend.frames, 0u);
    blends[2u * id.x + 1u] = bitcast<vec4<u32>>(vec4<f32>(blend.weights, 0.0));
}
"#;

impl Gpu {
    /// The frames and weights `impostor_blend` gives for each of `directions` on `grid`.
    pub fn impostor_blends(&self, grid: FrameGrid, directions: &[[f32; 3]]) -> Result<Vec<[(u32, f32); 3]>, GpuError> {
        if directions.is_empty() {
            return Ok(Vec::new());
        }
        let source = format!("{}\n{BLEND_ENTRY}", include_str!("../../shaders/impostor.wgsl"));
        let scope = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let module = self.device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("impostor blend"),
            source: wgpu::ShaderSource::Wgsl(source.into()),
        });
        let pipeline = self.device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("impostor blend"),
            layout: None,
            module: &module,
            entry_point: Some("blend_main"),
            compilation_options: Default::default(),
            cache: None,
        });
        let query = [grid.frames, u32::from(grid.sphere == Sphere::Hemi), directions.len() as u32, 0];
        let query = self.filled_buffer("impostor query", bytemuck::cast_slice(&query), wgpu::BufferUsages::STORAGE);
        let padded: Vec<[f32; 4]> = directions.iter().map(|&[x, y, z]| [x, y, z, 0.0]).collect();
        let inputs =
            self.filled_buffer("impostor directions", bytemuck::cast_slice(&padded), wgpu::BufferUsages::STORAGE);
        let size = (directions.len() * 32) as u64;
        let outputs = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("impostor blends"),
            size,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let readback = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("impostor readback"),
            size,
            usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
            mapped_at_creation: false,
        });
        let bind_group = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("impostor blend"),
            layout: &pipeline.get_bind_group_layout(0),
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: query.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 1, resource: inputs.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 2, resource: outputs.as_entire_binding() },
            ],
        });
        if let Some(error) = pollster::block_on(scope.pop()) {
            return Err(GpuError::Render(format!("shaders/impostor.wgsl: {error}")));
        }
        let mut encoder = self.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
        {
            let mut pass =
                encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: None, timestamp_writes: None });
            pass.set_pipeline(&pipeline);
            pass.set_bind_group(0, &bind_group, &[]);
            pass.dispatch_workgroups((directions.len() as u32).div_ceil(64), 1, 1);
        }
        encoder.copy_buffer_to_buffer(&outputs, 0, &readback, 0, size);
        let submission = self.queue.submit(Some(encoder.finish()));
        readback.slice(..).map_async(wgpu::MapMode::Read, |_| {});
        self.device
            .poll(wgpu::PollType::Wait { submission_index: Some(submission), timeout: None })
            .map_err(|error| GpuError::Render(error.to_string()))?;
        let mapped = readback.slice(..).get_mapped_range().map_err(|error| GpuError::Render(format!("{error:?}")))?;
        let words: &[u32] = bytemuck::cast_slice(&mapped);
        let blends = words
            .chunks_exact(8)
            .map(|blend| std::array::from_fn(|corner| (blend[corner], f32::from_bits(blend[4 + corner]))))
            .collect();
        drop(mapped);
        readback.unmap();
        Ok(blends)
    }
}
