//! The GPU: the only holder of the wgpu device (created once, lazily, so material-only builds
//! need no adapter), and the per-plane texture renderer of billboard clouds.

use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock};

use bytemuck::{Pod, Zeroable};

use crate::mips::{mip_chain, MipSettings};
use crate::rectangles::PlaneRectangle;
use crate::texture::SurfaceKind;
use crate::texture::Texture;

#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum GpuError {
    #[error("no GPU adapter: wgpu found no Vulkan, Metal, DX12 or GL device ({0}). Billboard clouds render their textures on the GPU; on Linux without a GPU install a software Vulkan driver, e.g. `apt-get install mesa-vulkan-drivers` (llvmpipe)")]
    NoAdapter(String),
    #[error("the GPU device could not be created: {0}")]
    Device(String),
    #[error("GPU rendering failed: {0}")]
    Render(String),
}

/// The device and everything created once for it.
pub struct Gpu {
    instance: wgpu::Instance,
    adapter: wgpu::Adapter,
    device: wgpu::Device,
    queue: wgpu::Queue,
    pub adapter_name: String,
    /// The largest render target side the device allows.
    max_texture_size: u32,
    pipeline: wgpu::RenderPipeline,
    frame_layout: wgpu::BindGroupLayout,
    material_layout: wgpu::BindGroupLayout,
    sampler: wgpu::Sampler,
    white: wgpu::TextureView,
    /// Uploaded source textures by content hash and colour space.
    /// A cell per key, so that threads wanting the same new texture upload it once.
    uploads: Mutex<HashMap<UploadKey, Arc<std::sync::OnceLock<Arc<wgpu::TextureView>>>>>,
    view_pipeline: wgpu::RenderPipeline,
    view_material_layout: wgpu::BindGroupLayout,
    /// Material bind groups by content (constants, texture hashes, cutoff).
    material_groups: Mutex<HashMap<blake3::Hash, Arc<wgpu::BindGroup>>>,
}

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

/// A window the viewer presents rendered images on (see [`Gpu::window_surface`]).
pub struct WindowSurface {
    surface: wgpu::Surface<'static>,
    config: wgpu::SurfaceConfiguration,
    pipeline: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
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

/// Mesa's Vulkan drivers probe for a Wayland display when the GPU starts, and libwayland prints
/// "error: XDG_RUNTIME_DIR is invalid or not set in the environment." when that variable is
/// unset (a CI job, an SSH session, a service): users read "error" and think the bake failed.
/// Without `XDG_RUNTIME_DIR` and `WAYLAND_DISPLAY` there is no compositor to reach anyway, so the
/// variable is pointed at a folder that does not exist, and the probe fails quietly.
///
/// Call it first in `main`, while the process has one thread: setting the environment while
/// other threads may read it is a data race in the C library.
pub fn quiet_wayland_probe() {
    if std::env::var_os("XDG_RUNTIME_DIR").is_none() && std::env::var_os("WAYLAND_DISPLAY").is_none() {
        std::env::set_var("XDG_RUNTIME_DIR", std::env::temp_dir().join("cirrus-no-wayland-session"));
    }
}

static GPU: OnceLock<Result<Gpu, GpuError>> = OnceLock::new();

/// The shared GPU, created on first use.
pub fn gpu() -> Result<&'static Gpu, GpuError> {
    GPU.get_or_init(|| pollster::block_on(Gpu::new())).as_ref().map_err(Clone::clone)
}

/// An uploaded texture: content hash, sRGB, and the alpha cutoff bits or level count.
type UploadKey = (blake3::Hash, bool, u32);

const ALBEDO_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8UnormSrgb;
const DATA_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;
const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;
/// Texels of one stack of plane rectangles (about 40 MB of targets and as much to read back).
const MAX_STACK_TEXELS: u64 = 2048 * 1024;

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct FrameUniform {
    origin: [f32; 4],
    x_axis: [f32; 4],
    y_axis: [f32; 4],
    normal: [f32; 4],
    size: [f32; 4],
}

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct MaterialUniform {
    albedo: [f32; 4],
    params: [f32; 4],
    has_a: [f32; 4],
    has_b: [f32; 4],
}

/// One vertex of a plane's faces.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct RenderVertex {
    pub position: [f32; 3],
    pub normal: [f32; 3],
    pub uv: [f32; 2],
    pub tangent: [f32; 4],
}

/// A material as the renderer sees it: decoded maps (any may be missing) and constants.
#[derive(Clone, Debug, Default)]
pub struct RenderMaterial {
    pub albedo: Option<Arc<Texture>>,
    pub opacity: Option<Arc<Texture>>,
    pub normal: Option<Arc<Texture>>,
    pub metallic: Option<Arc<Texture>>,
    pub roughness: Option<Arc<Texture>>,
    pub ao: Option<Arc<Texture>>,
    /// Linear RGB factor and constant opacity.
    pub albedo_factor: [f32; 4],
    pub metallic_value: f32,
    pub roughness_value: f32,
    pub ao_value: f32,
}

/// What one plane render needs: its faces (three vertices each) grouped by material.
#[derive(Clone, Debug)]
pub struct PlaneRenderInput<'a> {
    pub rectangle: &'a PlaneRectangle,
    pub epsilon: f32,
    pub alpha_cutoff: f32,
    pub width: u32,
    pub height: u32,
    /// (material index, that material's triangles' vertices).
    pub batches: Vec<(usize, Vec<RenderVertex>)>,
    pub materials: &'a [RenderMaterial],
}

/// The four images of one plane, RGBA8, rows from the top (the plane's +Y edge).
#[derive(Clone, Debug, PartialEq)]
pub struct PlaneImages {
    pub width: u32,
    pub height: u32,
    /// sRGB-encoded colour; alpha 1 where a face covers the texel, 0 elsewhere.
    pub albedo: Vec<u8>,
    pub normal: Vec<u8>,
    pub mra: Vec<u8>,
    pub height_map: Vec<u8>,
}

impl Gpu {
    async fn new() -> Result<Gpu, GpuError> {
        let instance = wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle());
        let adapter = instance
            .request_adapter(&wgpu::RequestAdapterOptions {
                power_preference: wgpu::PowerPreference::HighPerformance,
                ..Default::default()
            })
            .await
            .map_err(|error| GpuError::NoAdapter(error.to_string()))?;
        let adapter_name = format!("{} ({:?})", adapter.get_info().name, adapter.get_info().backend);
        let (device, queue) = adapter
            .request_device(&wgpu::DeviceDescriptor {
                label: Some("cirrus"),
                required_features: wgpu::Features::empty(),
                required_limits: wgpu::Limits::downlevel_defaults().using_resolution(adapter.limits()),
                ..Default::default()
            })
            .await
            .map_err(|error| GpuError::Device(error.to_string()))?;
        let shader = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("plane.wgsl"),
            source: wgpu::ShaderSource::Wgsl(include_str!("../shaders/plane.wgsl").into()),
        });
        // Per-draw constants (frames, cameras, materials) live in read-only storage buffers, not
        // uniform buffers: lavapipe inlines uniform-buffer contents into the shader and
        // JIT-compiles a new variant on every rebind, and keeps them all. On the oak that was
        // 4,220 compiles, about 1.6 MB kept per render group and 2.4 GB peak.
        let constants_entry = |binding| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Storage { read_only: true },
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        };
        let frame_layout =
            device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some("frame"), entries: &[constants_entry(0)] });
        let mut material_entries = vec![
            constants_entry(0),
            wgpu::BindGroupLayoutEntry {
                binding: 1,
                visibility: wgpu::ShaderStages::FRAGMENT,
                ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
                count: None,
            },
        ];
        for binding in 2..8 {
            material_entries.push(wgpu::BindGroupLayoutEntry {
                binding,
                visibility: wgpu::ShaderStages::FRAGMENT,
                ty: wgpu::BindingType::Texture {
                    sample_type: wgpu::TextureSampleType::Float { filterable: true },
                    view_dimension: wgpu::TextureViewDimension::D2,
                    multisampled: false,
                },
                count: None,
            });
        }
        let material_layout =
            device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some("material"), entries: &material_entries });
        let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("plane"),
            bind_group_layouts: &[Some(&frame_layout), Some(&material_layout)],
            ..Default::default()
        });
        let targets: Vec<Option<wgpu::ColorTargetState>> =
            [ALBEDO_FORMAT, DATA_FORMAT, DATA_FORMAT, DATA_FORMAT].iter().map(|&format| Some(format.into())).collect();
        let pipeline = mesh_pipeline(&device, "plane", &layout, &shader, &targets);
        let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("trilinear repeat"),
            address_mode_u: wgpu::AddressMode::Repeat,
            address_mode_v: wgpu::AddressMode::Repeat,
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            mipmap_filter: wgpu::MipmapFilterMode::Linear,
            ..Default::default()
        });
        let white = upload(&device, &queue, &[Texture::constant(1, 1, [255; 4])], DATA_FORMAT);
        let view_shader = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("view.wgsl"),
            source: wgpu::ShaderSource::Wgsl(include_str!("../shaders/view.wgsl").into()),
        });
        let view_material_layout = device
            .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some("view material"), entries: &material_entries[..5] });
        let view_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("view"),
            bind_group_layouts: &[Some(&frame_layout), Some(&view_material_layout)],
            ..Default::default()
        });
        let view_pipeline = mesh_pipeline(&device, "view", &view_layout, &view_shader, &[Some(ALBEDO_FORMAT.into())]);
        Ok(Gpu {
            instance,
            adapter,
            max_texture_size: device.limits().max_texture_dimension_2d,
            device,
            queue,
            adapter_name,
            pipeline,
            frame_layout,
            material_layout,
            sampler,
            white,
            uploads: Mutex::new(HashMap::new()),
            view_pipeline,
            view_material_layout,
            material_groups: Mutex::new(HashMap::new()),
        })
    }

    /// A source texture on the GPU with its mip chain (uploaded once per content).
    fn texture_view(&self, texture: &Texture, kind: SurfaceKind, alpha_cutoff: Option<f32>) -> Arc<wgpu::TextureView> {
        let srgb = kind == SurfaceKind::Albedo;
        let key = (texture.hash, srgb, alpha_cutoff.map_or(u32::MAX, f32::to_bits));
        self.cached_upload(key, || {
            let levels = mip_chain(texture, MipSettings { kind, alpha_cutoff });
            upload(&self.device, &self.queue, &levels, if srgb { ALBEDO_FORMAT } else { DATA_FORMAT })
        })
    }

    /// The upload cached under `key`, made by `make` by the first thread that asks for it; other
    /// threads asking meanwhile wait for it instead of uploading it again.
    fn cached_upload(&self, key: UploadKey, make: impl FnOnce() -> wgpu::TextureView) -> Arc<wgpu::TextureView> {
        let cell = self.uploads.lock().expect("upload cache").entry(key).or_default().clone();
        cell.get_or_init(|| Arc::new(make())).clone()
    }

    /// Renders the rectangles of one plane (or any set of rectangles): each under its own
    /// orthographic camera, stacked in shared targets, in as few submissions and read-backs as
    /// the stack size allows. Per-submission latency, not shading, dominates small renders.
    pub fn render_rectangles(&self, inputs: &[PlaneRenderInput]) -> Result<Vec<PlaneImages>, GpuError> {
        let mut images = Vec::with_capacity(inputs.len());
        let mut chunk_start = 0;
        while chunk_start < inputs.len() {
            // Rectangles are stacked from the top; a stack holds at least one of them.
            let (mut chunk_end, mut stack_width, mut stack_height) = (chunk_start, 0u32, 0u32);
            while let Some(input) = inputs.get(chunk_end) {
                let (width, height) = (input.width.max(1), input.height.max(1));
                let (grown_width, grown_height) = (stack_width.max(width), stack_height + height);
                let too_big = grown_height > self.max_texture_size || grown_width as u64 * grown_height as u64 > MAX_STACK_TEXELS;
                if chunk_end > chunk_start && too_big {
                    break;
                }
                (stack_width, stack_height) = (grown_width, grown_height);
                chunk_end += 1;
            }
            images.extend(self.render_stack(&inputs[chunk_start..chunk_end], stack_width, stack_height)?);
            chunk_start = chunk_end;
        }
        Ok(images)
    }

    /// One submission: `inputs` rendered one below the other into `width` × `height` targets.
    fn render_stack(&self, inputs: &[PlaneRenderInput], width: u32, height: u32) -> Result<Vec<PlaneImages>, GpuError> {
        let targets: Vec<wgpu::Texture> =
            [ALBEDO_FORMAT, DATA_FORMAT, DATA_FORMAT, DATA_FORMAT].iter().map(|&format| self.target(width, height, format)).collect();
        let views: Vec<wgpu::TextureView> = targets.iter().map(|texture| texture.create_view(&Default::default())).collect();
        let depth_texture = self.target(width, height, DEPTH_FORMAT);
        let depth = depth_texture.create_view(&Default::default());

        struct StackedDraws {
            top: u32,
            width: u32,
            height: u32,
            frame_buffer: wgpu::Buffer,
            frame_group: wgpu::BindGroup,
            /// Vertex range in the stack's one vertex buffer, and the material.
            draws: Vec<(std::ops::Range<u32>, Arc<wgpu::BindGroup>)>,
        }
        // Every draw of the stack reads one vertex buffer: one buffer to create and fill per
        // submission instead of one per draw.
        let mut all_vertices: Vec<RenderVertex> = Vec::new();
        let mut stacked = Vec::with_capacity(inputs.len());
        let mut top = 0;
        for input in inputs {
            let rectangle = &input.rectangle;
            let frame = FrameUniform {
                origin: extend(rectangle.origin),
                x_axis: extend(rectangle.x_axis),
                y_axis: extend(rectangle.y_axis),
                normal: extend(rectangle.normal),
                size: [rectangle.width.max(1e-6), rectangle.height.max(1e-6), input.epsilon.max(1e-6), input.alpha_cutoff],
            };
            let frame_buffer = self.constants_buffer(bytemuck::bytes_of(&frame));
            let frame_group = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("frame"),
                layout: &self.frame_layout,
                entries: &[wgpu::BindGroupEntry { binding: 0, resource: frame_buffer.as_entire_binding() }],
            });
            let mut draws = Vec::new();
            for (material_index, vertices) in &input.batches {
                if vertices.is_empty() {
                    continue;
                }
                let material = &input.materials[*material_index];
                let first = all_vertices.len() as u32;
                all_vertices.extend_from_slice(vertices);
                draws.push((first..all_vertices.len() as u32, self.material_group(material, input.alpha_cutoff)));
            }
            let (rectangle_width, rectangle_height) = (input.width.max(1), input.height.max(1));
            stacked.push(StackedDraws { top, width: rectangle_width, height: rectangle_height, frame_buffer, frame_group, draws });
            top += rectangle_height;
        }

        let vertex_buffer = (!all_vertices.is_empty()).then(|| self.vertex_buffer(&all_vertices));
        let mut encoder = self.device.create_command_encoder(&Default::default());
        {
            let attachments: Vec<Option<wgpu::RenderPassColorAttachment>> = views
                .iter()
                .map(|view| {
                    Some(wgpu::RenderPassColorAttachment {
                        view,
                        depth_slice: None,
                        resolve_target: None,
                        ops: wgpu::Operations { load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT), store: wgpu::StoreOp::Store },
                    })
                })
                .collect();
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("plane rectangles"),
                color_attachments: &attachments,
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view: &depth,
                    depth_ops: Some(wgpu::Operations { load: wgpu::LoadOp::Clear(1.0), store: wgpu::StoreOp::Discard }),
                    stencil_ops: None,
                }),
                ..Default::default()
            });
            pass.set_pipeline(&self.pipeline);
            if let Some(buffer) = &vertex_buffer {
                pass.set_vertex_buffer(0, buffer.slice(..));
            }
            for rectangle in &stacked {
                // The camera's clip square maps onto this rectangle's rows of the stack only.
                pass.set_viewport(0.0, rectangle.top as f32, rectangle.width as f32, rectangle.height as f32, 0.0, 1.0);
                pass.set_scissor_rect(0, rectangle.top, rectangle.width, rectangle.height);
                pass.set_bind_group(0, &rectangle.frame_group, &[]);
                for (vertices, group) in &rectangle.draws {
                    pass.set_bind_group(1, group.as_ref(), &[]);
                    pass.draw(vertices.clone(), 0..1);
                }
            }
        }
        let stack = self.read_back(encoder, &targets, width, height)?;
        // Free device memory now rather than whenever wgpu next triages destroyed resources.
        targets.iter().for_each(wgpu::Texture::destroy);
        depth_texture.destroy();
        for rectangle in &stacked {
            rectangle.frame_buffer.destroy();
        }
        if let Some(buffer) = &vertex_buffer {
            buffer.destroy();
        }
        let rows = |image: &[u8], rectangle: &StackedDraws| -> Vec<u8> {
            let row_bytes = rectangle.width as usize * 4;
            let mut pixels = Vec::with_capacity(row_bytes * rectangle.height as usize);
            for row in rectangle.top..rectangle.top + rectangle.height {
                let start = row as usize * width as usize * 4;
                pixels.extend_from_slice(&image[start..start + row_bytes]);
            }
            pixels
        };
        Ok(stacked
            .iter()
            .map(|rectangle| PlaneImages {
                width: rectangle.width,
                height: rectangle.height,
                albedo: rows(&stack[0], rectangle),
                normal: rows(&stack[1], rectangle),
                mra: rows(&stack[2], rectangle),
                height_map: rows(&stack[3], rectangle),
            })
            .collect())
    }

    /// Renders `mesh` under an orthographic camera into a `size`² RGBA8 image (sRGB colour on a
    /// mid-grey background; alpha 255 where a surface was drawn, 0 elsewhere).
    pub fn render_view(&self, mesh: &ViewMesh, view_projection: [[f32; 4]; 4], light: [f32; 3], size: u32) -> Result<Vec<u8>, GpuError> {
        let camera = CameraUniform { view_projection, light: extend(light) };
        let camera_buffer = self.constants_buffer(bytemuck::bytes_of(&camera));
        let camera_group = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("camera"),
            layout: &self.frame_layout,
            entries: &[wgpu::BindGroupEntry { binding: 0, resource: camera_buffer.as_entire_binding() }],
        });
        let target = self.target(size, size, ALBEDO_FORMAT);
        let view = target.create_view(&Default::default());
        let depth = self.target(size, size, DEPTH_FORMAT).create_view(&Default::default());
        let mut draws = Vec::new();
        for (material_index, vertices) in &mesh.batches {
            if vertices.is_empty() {
                continue;
            }
            let buffer = self.vertex_buffer(vertices);
            draws.push((buffer, vertices.len() as u32, self.view_material_group(&mesh.materials[*material_index])));
        }
        let mut encoder = self.device.create_command_encoder(&Default::default());
        {
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("view"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: &view,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(wgpu::Color { r: 0.214, g: 0.214, b: 0.214, a: 0.0 }),
                        store: wgpu::StoreOp::Store,
                    },
                })],
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view: &depth,
                    depth_ops: Some(wgpu::Operations { load: wgpu::LoadOp::Clear(1.0), store: wgpu::StoreOp::Discard }),
                    stencil_ops: None,
                }),
                ..Default::default()
            });
            pass.set_pipeline(&self.view_pipeline);
            pass.set_bind_group(0, &camera_group, &[]);
            for (buffer, count, group) in &draws {
                pass.set_bind_group(1, group, &[]);
                pass.set_vertex_buffer(0, buffer.slice(..));
                pass.draw(0..*count, 0..1);
            }
        }
        self.read_back(encoder, &[target], size, size).map(|mut images| images.remove(0))
    }

    /// A surface on `window` (anything wgpu can present to, e.g. an `Arc<winit::window::Window>`)
    /// that shows images from [`Gpu::render_view`]: used by the viewer example.
    pub fn window_surface(
        &self,
        window: impl Into<wgpu::SurfaceTarget<'static>>,
        width: u32,
        height: u32,
    ) -> Result<WindowSurface, GpuError> {
        let surface =
            self.instance.create_surface(window).map_err(|error| GpuError::Render(format!("cannot create a window surface: {error}")))?;
        let capabilities = surface.get_capabilities(&self.adapter);
        // Formats that store the image's bytes as they are come first; an sRGB one decodes in the shader.
        let preference = [
            wgpu::TextureFormat::Bgra8Unorm,
            wgpu::TextureFormat::Rgba8Unorm,
            wgpu::TextureFormat::Bgra8UnormSrgb,
            wgpu::TextureFormat::Rgba8UnormSrgb,
        ];
        let format = preference
            .into_iter()
            .find(|format| capabilities.formats.contains(format))
            .ok_or_else(|| GpuError::Render(format!("the window offers no 8-bit RGBA surface format ({:?})", capabilities.formats)))?;
        let mut config = surface
            .get_default_config(&self.adapter, width.max(1), height.max(1))
            .ok_or_else(|| GpuError::Render(format!("the adapter {} cannot present to this window", self.adapter_name)))?;
        config.format = format;
        config.view_formats = vec![];
        surface.configure(&self.device, &config);
        let shader = self.device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("present.wgsl"),
            source: wgpu::ShaderSource::Wgsl(include_str!("../shaders/present.wgsl").into()),
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
    /// window is smaller, on the images' background grey where it is larger). A frame the surface cannot give right now is skipped.
    pub fn present_image(&self, surface: &mut WindowSurface, rgba: &[u8], size: u32) -> Result<(), GpuError> {
        let frame = match surface.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(frame) | wgpu::CurrentSurfaceTexture::Suboptimal(frame) => frame,
            wgpu::CurrentSurfaceTexture::Outdated | wgpu::CurrentSurfaceTexture::Lost => {
                surface.surface.configure(&self.device, &surface.config);
                return Ok(());
            }
            wgpu::CurrentSurfaceTexture::Timeout | wgpu::CurrentSurfaceTexture::Occluded => return Ok(()),
            wgpu::CurrentSurfaceTexture::Validation => return Err(GpuError::Render("the window surface failed validation".into())),
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
                    ops: wgpu::Operations { load: wgpu::LoadOp::Clear(wgpu::Color::BLACK), store: wgpu::StoreOp::Store },
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
        let views: Vec<Arc<wgpu::TextureView>> = [(&material.albedo, true), (&material.opacity, false), (&material.normal, false)]
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
            entries.push(wgpu::BindGroupEntry { binding: 2 + index as u32, resource: wgpu::BindingResource::TextureView(view) });
        }
        self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("view material"),
            layout: &self.view_material_layout,
            entries: &entries,
        })
    }

    /// A texture with explicit mip levels on the GPU (uploaded once per content).
    fn levels_view(&self, levels: &[Texture], srgb: bool) -> Arc<wgpu::TextureView> {
        let key = (levels[0].hash, srgb, levels.len() as u32);
        self.cached_upload(key, || upload(&self.device, &self.queue, levels, if srgb { ALBEDO_FORMAT } else { DATA_FORMAT }))
    }

    /// Submits `encoder` after copying `targets` out, and returns their RGBA8 pixels.
    fn read_back(
        &self,
        mut encoder: wgpu::CommandEncoder,
        targets: &[wgpu::Texture],
        width: u32,
        height: u32,
    ) -> Result<Vec<Vec<u8>>, GpuError> {
        let padded_row = (width * 4).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
        let readbacks: Vec<wgpu::Buffer> = targets
            .iter()
            .map(|texture| {
                let buffer = self.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("readback"),
                    size: (padded_row * height) as u64,
                    usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
                    mapped_at_creation: false,
                });
                encoder.copy_texture_to_buffer(
                    texture.as_image_copy(),
                    wgpu::TexelCopyBufferInfo {
                        buffer: &buffer,
                        layout: wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(padded_row), rows_per_image: Some(height) },
                    },
                    wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
                );
                buffer
            })
            .collect();
        let submission = self.queue.submit(Some(encoder.finish()));
        for buffer in &readbacks {
            buffer.slice(..).map_async(wgpu::MapMode::Read, |_| {});
        }
        // Wait for this submission only: other threads' renders stay in flight meanwhile.
        self.device
            .poll(wgpu::PollType::Wait { submission_index: Some(submission), timeout: None })
            .map_err(|error| GpuError::Render(error.to_string()))?;
        let mut images = Vec::with_capacity(targets.len());
        for buffer in &readbacks {
            let mapped = buffer.slice(..).get_mapped_range().map_err(|error| GpuError::Render(format!("{error:?}")))?;
            let mut pixels = Vec::with_capacity((width * height * 4) as usize);
            for row in 0..height as usize {
                let start = row * padded_row as usize;
                pixels.extend_from_slice(&mapped[start..start + width as usize * 4]);
            }
            drop(mapped);
            buffer.unmap();
            buffer.destroy();
            images.push(pixels);
        }
        Ok(images)
    }

    /// A read-only storage buffer of per-draw constants (see `constants_entry` in `Gpu::new`).
    fn constants_buffer(&self, bytes: &[u8]) -> wgpu::Buffer {
        self.filled_buffer("constants", bytes, wgpu::BufferUsages::STORAGE)
    }

    fn vertex_buffer(&self, vertices: &[RenderVertex]) -> wgpu::Buffer {
        self.filled_buffer("vertices", bytemuck::cast_slice(vertices), wgpu::BufferUsages::VERTEX)
    }

    fn filled_buffer(&self, label: &str, bytes: &[u8], usage: wgpu::BufferUsages) -> wgpu::Buffer {
        use wgpu::util::DeviceExt;
        self.device.create_buffer_init(&wgpu::util::BufferInitDescriptor { label: Some(label), contents: bytes, usage })
    }

    fn target(&self, width: u32, height: u32, format: wgpu::TextureFormat) -> wgpu::Texture {
        self.device.create_texture(&wgpu::TextureDescriptor {
            label: Some("target"),
            size: wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        })
    }

    fn material_group(&self, material: &RenderMaterial, alpha_cutoff: f32) -> Arc<wgpu::BindGroup> {
        let flag = |texture: &Option<Arc<Texture>>| if texture.is_some() { 1.0 } else { 0.0 };
        let uniform = MaterialUniform {
            albedo: material.albedo_factor,
            params: [material.metallic_value, material.roughness_value, material.ao_value, 0.0],
            has_a: [flag(&material.albedo), flag(&material.opacity), flag(&material.normal), flag(&material.metallic)],
            has_b: [flag(&material.roughness), flag(&material.ao), 0.0, 0.0],
        };
        let mut key = blake3::Hasher::new();
        key.update(bytemuck::bytes_of(&uniform));
        key.update(&alpha_cutoff.to_bits().to_le_bytes());
        for texture in [&material.albedo, &material.opacity, &material.normal, &material.metallic, &material.roughness, &material.ao] {
            key.update(texture.as_ref().map_or(&[0u8; 32], |texture| texture.hash.as_bytes()));
        }
        let key = key.finalize();
        if let Some(group) = self.material_groups.lock().expect("material groups").get(&key) {
            return group.clone();
        }
        let buffer = self.constants_buffer(bytemuck::bytes_of(&uniform));
        let views: Vec<Arc<wgpu::TextureView>> = [
            (&material.albedo, SurfaceKind::Albedo, Some(alpha_cutoff)),
            (&material.opacity, SurfaceKind::Albedo, Some(alpha_cutoff)),
            (&material.normal, SurfaceKind::Normal, None),
            (&material.metallic, SurfaceKind::Mra, None),
            (&material.roughness, SurfaceKind::Mra, None),
            (&material.ao, SurfaceKind::Mra, None),
        ]
        .into_iter()
        .map(|(texture, kind, cutoff)| match texture {
            Some(texture) => self.texture_view(texture, kind, cutoff),
            None => Arc::new(self.white.clone()),
        })
        .collect();
        let mut entries = vec![
            wgpu::BindGroupEntry { binding: 0, resource: buffer.as_entire_binding() },
            wgpu::BindGroupEntry { binding: 1, resource: wgpu::BindingResource::Sampler(&self.sampler) },
        ];
        for (index, view) in views.iter().enumerate() {
            entries.push(wgpu::BindGroupEntry { binding: 2 + index as u32, resource: wgpu::BindingResource::TextureView(view) });
        }
        let group = Arc::new(self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("material"),
            layout: &self.material_layout,
            entries: &entries,
        }));
        self.material_groups.lock().expect("material groups").insert(key, group.clone());
        group
    }
}

/// A pipeline drawing `RenderVertex` triangles double-sided with a depth test: the one shape
/// both the plane bake and the preview use.
fn mesh_pipeline(
    device: &wgpu::Device,
    label: &str,
    layout: &wgpu::PipelineLayout,
    shader: &wgpu::ShaderModule,
    targets: &[Option<wgpu::ColorTargetState>],
) -> wgpu::RenderPipeline {
    let attributes = wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x3, 2 => Float32x2, 3 => Float32x4];
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some(label),
        layout: Some(layout),
        vertex: wgpu::VertexState {
            module: shader,
            entry_point: Some("vs_main"),
            compilation_options: Default::default(),
            buffers: &[Some(wgpu::VertexBufferLayout {
                array_stride: std::mem::size_of::<RenderVertex>() as u64,
                step_mode: wgpu::VertexStepMode::Vertex,
                attributes: &attributes,
            })],
        },
        fragment: Some(wgpu::FragmentState {
            module: shader,
            entry_point: Some("fs_main"),
            compilation_options: Default::default(),
            targets,
        }),
        primitive: wgpu::PrimitiveState { cull_mode: None, ..Default::default() },
        depth_stencil: Some(wgpu::DepthStencilState {
            format: DEPTH_FORMAT,
            depth_write_enabled: Some(true),
            depth_compare: Some(wgpu::CompareFunction::LessEqual),
            stencil: Default::default(),
            bias: Default::default(),
        }),
        multisample: wgpu::MultisampleState::default(),
        multiview_mask: None,
        cache: None,
    })
}

fn extend([x, y, z]: [f32; 3]) -> [f32; 4] {
    [x, y, z, 0.0]
}

/// Uploads a mip chain (level 0 first) as one texture.
fn upload(device: &wgpu::Device, queue: &wgpu::Queue, levels: &[Texture], format: wgpu::TextureFormat) -> wgpu::TextureView {
    let texture = device.create_texture(&wgpu::TextureDescriptor {
        label: Some("source"),
        size: wgpu::Extent3d { width: levels[0].width, height: levels[0].height, depth_or_array_layers: 1 },
        mip_level_count: levels.len() as u32,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format,
        usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        view_formats: &[],
    });
    for (level, image) in levels.iter().enumerate() {
        queue.write_texture(
            wgpu::TexelCopyTextureInfo {
                texture: &texture,
                mip_level: level as u32,
                origin: wgpu::Origin3d::ZERO,
                aspect: wgpu::TextureAspect::All,
            },
            &image.pixels,
            wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(image.width * 4), rows_per_image: Some(image.height) },
            wgpu::Extent3d { width: image.width, height: image.height, depth_or_array_layers: 1 },
        );
    }
    texture.create_view(&Default::default())
}
