//! Octahedral impostors on the GPU, through `shaders/impostor.wgsl`: its reference renderer (one
//! camera-facing polygon blending three frames with a parallax step), and its frame selection run
//! over a list of directions in a compute pass, so that the shader engines copy is checked
//! against the reference (`mesh::octahedral`) on the device that runs it.

use super::{Gpu, GpuError, ALBEDO_FORMAT, DATA_FORMAT, VIEW_BACKGROUND};
use mesh::octahedral::FrameGrid;
use texture::Texture;

/// An impostor as the reference renderer draws it: its frame grid, its atlases (each a mip
/// chain, level 0 first, as `impostor::ImpostorFrames` describes them) and bounding sphere.
#[derive(Clone, Debug)]
pub struct ImpostorDraw {
    pub grid: FrameGrid,
    pub albedo: Vec<Texture>,
    pub normal: Vec<Texture>,
    pub depth: Vec<Texture>,
    pub center: [f32; 3],
    pub radius: f32,
    pub alpha_cutoff: f32,
    /// The part of the sphere's image each frame shows (`impostor::frame_rects`); empty: every
    /// frame shows all of it.
    pub rects: Vec<[f32; 4]>,
    /// The polygon it is drawn as (`impostor::view_hull`); none: the sphere's square.
    pub hull: Option<[[f32; 2]; 8]>,
}

/// What `impostor.wgsl`'s renderer reads of the view.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct ImpostorViewUniform {
    view_projection: [[f32; 4]; 4],
    eye: [f32; 4],
    light: [f32; 4],
}

/// What it reads of the impostor.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct ImpostorUniform {
    sphere: [f32; 4],
    grid: [u32; 4],
    params: [f32; 4],
    /// The eight points of the polygon drawn, two a vector.
    hull: [[f32; 4]; 4],
}

/// A compute entry point over `impostor.wgsl`: one invocation per direction, writing its three
/// frames and (bit-cast) weights.
const BLEND_ENTRY: &str = r#"
struct Query { frames: u32, hemi: u32, count: u32, unused: u32 }
@group(1) @binding(0) var<storage, read> query: Query;
@group(1) @binding(1) var<storage, read> directions: array<vec4<f32>>;
@group(1) @binding(2) var<storage, read_write> blends: array<vec4<u32>>;

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

/// The impostor pipelines: `view.wgsl`'s `fs_impostor` (a frame's albedo and normal + depth)
/// and `impostor.wgsl`'s reference renderer with its sampler.
pub(super) struct ImpostorPipelines {
    pub frame: super::view_render::MapPipelines,
    view: wgpu::RenderPipeline,
    sampler: wgpu::Sampler,
}

/// The direction towards the eye (object to eye, unit length) of an orthographic camera: the one
/// that moves no point across the image, pointing where depth falls.
fn orthographic_eye(view_projection: [[f32; 4]; 4]) -> glam::Vec3 {
    let row =
        |index: usize| glam::Vec3::new(view_projection[0][index], view_projection[1][index], view_projection[2][index]);
    let eye = row(0).cross(row(1)).normalize_or(glam::Vec3::Z);
    if row(2).dot(eye) > 0.0 {
        -eye
    } else {
        eye
    }
}

impl Gpu {
    /// The impostor pipelines, made on first use.
    pub(super) fn impostor_pipelines(&self) -> &ImpostorPipelines {
        self.impostor.get_or_init(|| {
            let frame = self.view_pipelines.for_entry("fs_impostor", &[ALBEDO_FORMAT, DATA_FORMAT]);
            let module = self.device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("impostor.wgsl"),
                source: wgpu::ShaderSource::Wgsl(include_str!("../../../shaders/impostor.wgsl").into()),
            });
            let view = self.device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some("impostor"),
                layout: None,
                vertex: wgpu::VertexState {
                    module: &module,
                    entry_point: Some("impostor_vs"),
                    compilation_options: Default::default(),
                    buffers: &[],
                },
                fragment: Some(wgpu::FragmentState {
                    module: &module,
                    entry_point: Some("impostor_fs"),
                    compilation_options: Default::default(),
                    targets: &[Some(ALBEDO_FORMAT.into())],
                }),
                primitive: wgpu::PrimitiveState { cull_mode: None, ..Default::default() },
                depth_stencil: None,
                multisample: wgpu::MultisampleState::default(),
                multiview_mask: None,
                cache: None,
            });
            let sampler = self.device.create_sampler(&wgpu::SamplerDescriptor {
                label: Some("impostor frames"),
                mag_filter: wgpu::FilterMode::Linear,
                min_filter: wgpu::FilterMode::Linear,
                ..Default::default()
            });
            ImpostorPipelines { frame, view, sampler }
        })
    }

    /// Renders `impostor` under the orthographic camera `view_projection` into a `size`² RGBA8
    /// image, as `render_view` renders a mesh: sRGB colour lit by `light` on mid-grey, alpha 255
    /// where the impostor is drawn.
    pub fn render_impostor_view(
        &self,
        impostor: &ImpostorDraw,
        view_projection: [[f32; 4]; 4],
        light: [f32; 3],
        size: u32,
    ) -> Result<Vec<u8>, GpuError> {
        super::one_view(|each| self.render_impostor_views(impostor, &[view_projection], light, size, each))
    }

    /// [`Gpu::render_impostor_view`] under each of `view_projections`, drawn in batches as
    /// [`Gpu::render_views`] draws a mesh's: each image goes to `each` with its view's index.
    pub fn render_impostor_views(
        &self,
        impostor: &ImpostorDraw,
        view_projections: &[[[f32; 4]; 4]],
        light: [f32; 3],
        size: u32,
        mut each: impl FnMut(usize, Vec<u8>),
    ) -> Result<(), GpuError> {
        self.catching_device_errors(|| {
            let ImpostorPipelines { view: pipeline, sampler, .. } = self.impostor_pipelines();
            let [cx, cy, cz] = impostor.center;
            // How many times an atlas's side halves the albedo atlas's (`impostor_smaller_lod`).
            let halvings = |atlas: &[Texture]| match (impostor.albedo.first(), atlas.first()) {
                (Some(albedo), Some(atlas)) => (albedo.width as f32 / atlas.width.max(1) as f32).log2(),
                _ => 0.0,
            };
            let uniform = ImpostorUniform {
                sphere: [cx, cy, cz, impostor.radius],
                grid: [impostor.grid.frames, u32::from(impostor.grid.is_hemi()), 0, 0],
                params: [impostor.alpha_cutoff, halvings(&impostor.normal), halvings(&impostor.depth), 0.0],
                hull: {
                    let hull = impostor.hull.unwrap_or(mesh::octahedral::SQUARE_HULL);
                    std::array::from_fn(|pair| {
                        [hull[2 * pair][0], hull[2 * pair][1], hull[2 * pair + 1][0], hull[2 * pair + 1][1]]
                    })
                },
            };
            let impostor_buffer = self.constants_buffer(bytemuck::bytes_of(&uniform));
            let full = vec![mesh::octahedral::FULL_FRAME; impostor.grid.frame_count() as usize];
            let rects = if impostor.rects.len() == full.len() { &impostor.rects } else { &full };
            let rects_buffer = self.constants_buffer(bytemuck::cast_slice(rects));
            // Uploaded once per content: every view of the same impostor shares them.
            let albedo = self.levels_view(&impostor.albedo, true);
            let normal = self.levels_view(&impostor.normal, false);
            let depth = self.levels_view(&impostor.depth, false);
            let record = |encoder: &mut wgpu::CommandEncoder, index: usize| {
                let view_projection = view_projections[index];
                let [x, y, z] = orthographic_eye(view_projection).to_array();
                let view = ImpostorViewUniform { view_projection, eye: [x, y, z, 0.0], light: super::extend(light) };
                let view_buffer = self.constants_buffer(bytemuck::bytes_of(&view));
                let group = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some("impostor"),
                    layout: &pipeline.get_bind_group_layout(0),
                    entries: &[
                        wgpu::BindGroupEntry { binding: 0, resource: view_buffer.as_entire_binding() },
                        wgpu::BindGroupEntry { binding: 1, resource: impostor_buffer.as_entire_binding() },
                        wgpu::BindGroupEntry { binding: 2, resource: wgpu::BindingResource::Sampler(sampler) },
                        wgpu::BindGroupEntry { binding: 3, resource: wgpu::BindingResource::TextureView(&albedo) },
                        wgpu::BindGroupEntry { binding: 4, resource: wgpu::BindingResource::TextureView(&normal) },
                        wgpu::BindGroupEntry { binding: 5, resource: wgpu::BindingResource::TextureView(&depth) },
                        wgpu::BindGroupEntry { binding: 6, resource: rects_buffer.as_entire_binding() },
                    ],
                });
                let target = self.target(size, size, ALBEDO_FORMAT);
                let target_view = target.create_view(&Default::default());
                let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                    label: Some("impostor"),
                    color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                        view: &target_view,
                        depth_slice: None,
                        resolve_target: None,
                        ops: wgpu::Operations {
                            load: wgpu::LoadOp::Clear(VIEW_BACKGROUND),
                            store: wgpu::StoreOp::Store,
                        },
                    })],
                    ..Default::default()
                });
                pass.set_pipeline(pipeline);
                pass.set_bind_group(0, &group, &[]);
                // The polygon as a fan of six triangles.
                pass.draw(0..18, 0..1);
                drop(pass);
                vec![target]
            };
            self.draw_in_batches((view_projections.len(), size, 1), &base::stop::never, record, |index, mut images| {
                each(index, images.remove(0))
            })
        })
    }

    /// The frames and weights `impostor_blend` gives for each of `directions` on `grid`.
    pub fn impostor_blends(&self, grid: FrameGrid, directions: &[[f32; 3]]) -> Result<Vec<[(u32, f32); 3]>, GpuError> {
        if directions.is_empty() {
            return Ok(Vec::new());
        }
        let source = format!("{}\n{BLEND_ENTRY}", include_str!("../../../shaders/impostor.wgsl"));
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
        let query = [grid.frames, u32::from(grid.is_hemi()), directions.len() as u32, 0];
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
        let unused = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("impostor blend: the renderer's group, unused"),
            layout: &pipeline.get_bind_group_layout(0),
            entries: &[],
        });
        let bind_group = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("impostor blend"),
            layout: &pipeline.get_bind_group_layout(1),
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
            pass.set_bind_group(0, &unused, &[]);
            pass.set_bind_group(1, &bind_group, &[]);
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

/// A LOD level as an engine draws it: a mesh with its materials, or an impostor through
/// `impostor.wgsl`.
#[derive(Clone, Debug)]
pub enum LevelView {
    Mesh(super::ViewMesh),
    Impostor(ImpostorDraw),
}

impl Gpu {
    /// Renders `level` under the orthographic camera `view_projection` into a `size`² RGBA8 image
    /// (see [`Gpu::render_view`]).
    pub fn render_level_view(
        &self,
        level: &LevelView,
        view_projection: [[f32; 4]; 4],
        light: [f32; 3],
        size: u32,
    ) -> Result<Vec<u8>, GpuError> {
        super::one_view(|each| self.render_level_views(level, &[view_projection], light, size, each))
    }

    /// [`Gpu::render_level_view`] under each of `view_projections`, drawn in batches: each image
    /// goes to `each` with its view's index, in order.
    pub fn render_level_views(
        &self,
        level: &LevelView,
        view_projections: &[[[f32; 4]; 4]],
        light: [f32; 3],
        size: u32,
        each: impl FnMut(usize, Vec<u8>),
    ) -> Result<(), GpuError> {
        match level {
            LevelView::Mesh(mesh) => self.render_views(mesh, view_projections, light, size, each),
            LevelView::Impostor(impostor) => self.render_impostor_views(impostor, view_projections, light, size, each),
        }
    }
}
