//! The GPU: the only holder of the wgpu device (created once, lazily, so material-only builds
//! need no adapter), the pipelines and the helpers every renderer shares (uploads, buffers,
//! read-back). One file per renderer: `plane_render` (billboard planes), `view_render`
//! (preview views), `top_down_render` (a mesh's highest Y per texel, for height maps), `window`
//! (the viewer's window surfaces).

mod impostor;
mod plane_render;
pub mod top_down_render;
mod view_render;
pub use view_render::{front_to_back, views_per_batch};
mod window;

pub use impostor::{ImpostorDraw, LevelView};
pub use plane_render::{material_mip_settings, PlaneImages, PlaneRenderInput, RectangleFrame, RenderMaterial};
pub use view_render::{ViewMaterial, ViewMesh};
pub use window::WindowSurface;

use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock};

use bytemuck::{Pod, Zeroable};

use texture::mips::MipSettings;
use texture::SurfaceKind;
use texture::Texture;

#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum GpuError {
    #[error(
        "no GPU adapter: wgpu found no Vulkan, Metal, DX12 or GL device ({0}). Billboard clouds render their \
        textures on the GPU; on Linux without a GPU install a software Vulkan driver, e.g. \
        `apt-get install mesa-vulkan-drivers` (llvmpipe)"
    )]
    NoAdapter(String),
    #[error(
        "no GPU adapter can render cirrus's textures: {0}. On Linux without a GPU install a software Vulkan \
        driver, e.g. `apt-get install mesa-vulkan-drivers` (llvmpipe), or name another backend with WGPU_BACKEND"
    )]
    Unsupported(String),
    #[error("the GPU device could not be created: {0}")]
    Device(String),
    #[error("GPU rendering failed: {0}")]
    Render(String),
    /// The work's `ShouldStop` said so (a build cancelled by a newer edit); not a failure.
    #[error("stopped before it finished")]
    Stopped,
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
    /// The plane shader's alpha test alone (`fs_coverage`), into one byte per sample.
    coverage_pipeline: wgpu::RenderPipeline,
    frame_layout: wgpu::BindGroupLayout,
    material_layout: wgpu::BindGroupLayout,
    sampler: wgpu::Sampler,
    white: wgpu::TextureView,
    /// Uploaded source textures by content hash and colour space.
    /// A cell per key, so that threads wanting the same new texture upload it once.
    uploads: Mutex<HashMap<UploadKey, Arc<std::sync::OnceLock<Arc<wgpu::TextureView>>>>>,
    /// `view.wgsl`'s `fs_main`, for each set of maps a material has.
    view_pipelines: view_render::MapPipelines,
    /// The impostor pipelines, made on first use: a bake that draws no impostor compiles none.
    impostor: OnceLock<impostor::ImpostorPipelines>,
    view_material_layout: wgpu::BindGroupLayout,
    /// Material bind groups by content (constants, texture hashes, cutoff).
    material_groups: Mutex<HashMap<blake3::Hash, Arc<wgpu::BindGroup>>>,
    top_down_pipeline: wgpu::RenderPipeline,
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

/// Keeps Mesa's software renderer (llvmpipe, whose shaders LLVM compiles for this CPU) at or
/// below `level`, as `isa::limit_isa` keeps cirrus's own kernels: through Mesa's
/// `GALLIUM_OVERRIDE_CPU_CAPS`, unless the user set it. Hardware drivers ignore it.
///
/// Call it in `main`, while the process has one thread, as `quiet_wayland_probe`.
pub fn limit_software_renderer_isa(level: base::isa::IsaLevel) {
    use base::isa::IsaLevel;
    let caps = match level {
        IsaLevel::Avx512 => return,
        IsaLevel::Avx2 => "avx",
        IsaLevel::Sse4 => "sse4.1",
        IsaLevel::Portable => "sse2",
    };
    if level < base::isa::detected_isa() && std::env::var_os("GALLIUM_OVERRIDE_CPU_CAPS").is_none() {
        std::env::set_var("GALLIUM_OVERRIDE_CPU_CAPS", caps);
    }
}

static GPU: OnceLock<Result<Gpu, GpuError>> = OnceLock::new();

/// The shared GPU, created on first use.
pub fn gpu() -> Result<&'static Gpu, GpuError> {
    GPU.get_or_init(|| pollster::block_on(Gpu::new())).as_ref().map_err(Clone::clone)
}

/// The GPU's driver family, `backend/vendor id/driver` (`Vulkan/0x10005/llvmpipe`), or `none`:
/// a part of the cache keys of results that come off the GPU, whose bytes may differ from one
/// driver to another, so that a shared cache never hands one driver's renders to a machine
/// with another. Asked once per process, from the started GPU when there is one, else from an
/// adapter request without a device (the one `gpu()` would choose).
pub fn adapter_family() -> &'static str {
    static FAMILY: OnceLock<String> = OnceLock::new();
    FAMILY.get_or_init(|| {
        let family = |info: wgpu::AdapterInfo| format!("{:?}/{:#x}/{}", info.backend, info.vendor, info.driver);
        if let Some(Ok(gpu)) = GPU.get() {
            return family(gpu.adapter.get_info());
        }
        match pollster::block_on(choose_adapter(&new_instance())) {
            Ok(adapter) => family(adapter.get_info()),
            Err(_) => "none".to_string(),
        }
    })
}

/// The wgpu instance: every backend, or those `WGPU_BACKEND` names (`vulkan`, `gl`, …).
fn new_instance() -> wgpu::Instance {
    wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env())
}

/// The adapter `gpu()` and `adapter_family()` use: wgpu's high-performance choice when it can
/// render everything cirrus draws (see `adapter_shortfalls`), else the first other adapter that
/// can. An adapter that cannot (OpenGL ES drivers without float render targets or storage
/// buffers in vertex shaders) would fail pipeline creation, which wgpu treats as fatal.
async fn choose_adapter(instance: &wgpu::Instance) -> Result<wgpu::Adapter, GpuError> {
    let options =
        wgpu::RequestAdapterOptions { power_preference: wgpu::PowerPreference::HighPerformance, ..Default::default() };
    let preferred = instance.request_adapter(&options).await;
    let shortfalls_of = |adapter: &wgpu::Adapter| {
        adapter_shortfalls(
            &|format| adapter.get_texture_format_features(format).allowed_usages,
            adapter.get_downlevel_capabilities().flags,
        )
    };
    if let Ok(adapter) = &preferred {
        if shortfalls_of(adapter).is_empty() {
            return Ok(adapter.clone());
        }
    }
    // Listing every adapter wakes every backend (EGL complains on stderr without a display), so
    // only when the preferred one cannot serve.
    let mut refusals = Vec::new();
    let others = instance.enumerate_adapters(wgpu::Backends::all()).await;
    for adapter in preferred.as_ref().ok().cloned().into_iter().chain(others) {
        let shortfalls = shortfalls_of(&adapter);
        if shortfalls.is_empty() {
            return Ok(adapter);
        }
        let info = adapter.get_info();
        let refusal = format!("{} ({:?}) lacks {}", info.name, info.backend, shortfalls.join(", "));
        if !refusals.contains(&refusal) {
            refusals.push(refusal);
        }
    }
    match preferred {
        Err(error) if refusals.is_empty() => Err(GpuError::NoAdapter(error.to_string())),
        _ if refusals.is_empty() => Err(GpuError::NoAdapter("no adapter listed".into())),
        _ => Err(GpuError::Unsupported(refusals.join("; "))),
    }
}

/// What an adapter lacks of what cirrus's pipelines need, given the usages it allows per
/// texture format and its downlevel flags: render targets of every format drawn to (sampled
/// too where they are read back as textures), and read-only storage buffers in vertex and
/// fragment shaders (every pipeline's per-draw constants). Empty: it can render everything.
pub fn adapter_shortfalls(
    allowed_usages: &dyn Fn(wgpu::TextureFormat) -> wgpu::TextureUsages,
    flags: wgpu::DownlevelFlags,
) -> Vec<String> {
    let mut shortfalls = Vec::new();
    let render = wgpu::TextureUsages::RENDER_ATTACHMENT;
    let render_and_sample = render | wgpu::TextureUsages::TEXTURE_BINDING;
    for (format, needed) in [
        (ALBEDO_FORMAT, render_and_sample),
        (DATA_FORMAT, render_and_sample),
        (DEPTH_FORMAT, render),
        (COVERAGE_FORMAT, render),
        (top_down_render::HEIGHT_FORMAT, render),
    ] {
        if !allowed_usages(format).contains(needed) {
            shortfalls.push(format!("{format:?} render targets"));
        }
    }
    for (flag, what) in [
        (wgpu::DownlevelFlags::VERTEX_STORAGE, "storage buffers in vertex shaders"),
        (wgpu::DownlevelFlags::FRAGMENT_STORAGE, "storage buffers in fragment shaders"),
    ] {
        if !flags.contains(flag) {
            shortfalls.push(what.to_string());
        }
    }
    shortfalls
}

/// The thread `start_gpu_in_background` started, until someone waits for it.
static GPU_STARTER: Mutex<Option<std::thread::JoinHandle<()>>> = Mutex::new(None);

/// Starts creating the shared GPU on a thread of its own (about 50–80 ms on llvmpipe), for a
/// caller that knows it will render soon and has other work to do meanwhile; `gpu()` then waits
/// for it. Call `wait_for_gpu_start` before the process ends.
pub fn start_gpu_in_background() {
    let mut starter = GPU_STARTER.lock().expect("GPU starter lock");
    if GPU.get().is_none() && starter.is_none() {
        *starter = Some(std::thread::spawn(|| {
            let _ = gpu();
        }));
    }
}

/// Waits for a GPU start begun by `start_gpu_in_background` (so that the process never exits
/// while the driver is being set up).
pub fn wait_for_gpu_start() {
    let starter = GPU_STARTER.lock().expect("GPU starter lock").take();
    if let Some(starter) = starter {
        let _ = starter.join();
    }
}

/// An uploaded texture: content hash, sRGB, and the alpha cutoff bits or level count.
type UploadKey = (blake3::Hash, bool, u32);

const ALBEDO_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8UnormSrgb;
const DATA_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;
const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;
/// The mid-grey behind preview views (linear; alpha 0: not drawn).
const VIEW_BACKGROUND: wgpu::Color = wgpu::Color { r: 0.214, g: 0.214, b: 0.214, a: 0.0 };
/// Where a plane's faces pass the alpha test, one byte per sample of a supersampled render.
const COVERAGE_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::R8Unorm;
/// Texels of one stack of plane rectangles (about 40 MB of targets and as much to read back).
const MAX_STACK_TEXELS: u64 = 2048 * 1024;
/// The width of a stack's rows of plane rectangles (or its widest rectangle's).
const STACK_ROW_TEXELS: u32 = 1024;

/// One vertex of a plane's faces.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct RenderVertex {
    pub position: [f32; 3],
    pub normal: [f32; 3],
    pub uv: [f32; 2],
    pub tangent: [f32; 4],
}

/// `faces` as vertex batches per material (three vertices per triangle, in the order given): a
/// rectangle's own faces then those it also draws, or every face for a view of the mesh.
pub fn face_batches(
    mesh: &mesh::Mesh,
    tangents: &[[f32; 4]],
    faces: impl IntoIterator<Item = u32>,
) -> Vec<(usize, Vec<RenderVertex>)> {
    face_batches_placed(mesh, tangents, faces, |face, corner| {
        mesh.positions[mesh.triangles[face as usize][corner] as usize]
    })
}

/// [`face_batches`] with each corner drawn at `position(face, corner)` (corner 0 to 2) instead of
/// its vertex's position (normals, texture coordinates and tangents stay the vertex's).
pub fn face_batches_placed(
    mesh: &mesh::Mesh,
    tangents: &[[f32; 4]],
    faces: impl IntoIterator<Item = u32>,
    position: impl Fn(u32, usize) -> [f32; 3],
) -> Vec<(usize, Vec<RenderVertex>)> {
    let mut batches: std::collections::BTreeMap<usize, Vec<RenderVertex>> = std::collections::BTreeMap::new();
    for face in faces {
        let material = mesh.triangle_materials[face as usize] as usize;
        let batch = batches.entry(material).or_default();
        for (corner, vertex) in mesh.triangles[face as usize].into_iter().enumerate() {
            let index = vertex as usize;
            batch.push(RenderVertex {
                position: position(face, corner),
                normal: mesh.normals[index],
                uv: mesh.uvs.as_ref().map_or([0.0, 0.0], |uvs| uvs[index]),
                tangent: tangents.get(index).copied().unwrap_or([1.0, 0.0, 0.0, 1.0]),
            });
        }
    }
    batches.into_iter().collect()
}

impl Gpu {
    /// The device on the first adapter able to draw every target, with every pipeline.
    // Long: the device's creation and each pipeline's, written out once; a helper per pipeline
    // would take most of the same lines as arguments.
    async fn new() -> Result<Gpu, GpuError> {
        let instance = new_instance();
        let adapter = choose_adapter(&instance).await?;
        let adapter_name = format!("{} ({:?})", adapter.get_info().name, adapter.get_info().backend);
        tracing::info!(adapter = %adapter_name, "GPU");
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
            source: wgpu::ShaderSource::Wgsl(include_str!("../../../shaders/plane.wgsl").into()),
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
        let frame_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("frame"),
            entries: &[constants_entry(0)],
        });
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
        let material_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("material"),
            entries: &material_entries,
        });
        let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("plane"),
            bind_group_layouts: &[Some(&frame_layout), Some(&material_layout)],
            ..Default::default()
        });
        let targets: Vec<Option<wgpu::ColorTargetState>> =
            [ALBEDO_FORMAT, DATA_FORMAT, DATA_FORMAT, DATA_FORMAT].iter().map(|&format| Some(format.into())).collect();
        let pipeline =
            mesh_pipeline(&device, "plane", &layout, (&shader, "fs_main", &[]), &targets, Some(depth_test()));
        // Coverage is the union of every face's: no depth test.
        let coverage_pipeline = mesh_pipeline(
            &device,
            "plane coverage",
            &layout,
            (&shader, "fs_coverage", &[]),
            &[Some(COVERAGE_FORMAT.into())],
            None,
        );
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
            source: wgpu::ShaderSource::Wgsl(include_str!("../../../shaders/view.wgsl").into()),
        });
        let view_material_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("view material"),
            entries: &material_entries[..5],
        });
        let view_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("view"),
            bind_group_layouts: &[Some(&frame_layout), Some(&view_material_layout)],
            ..Default::default()
        });
        let view_pipelines = view_render::MapPipelines::new((view_shader, "fs_main"), view_layout, &[ALBEDO_FORMAT]);
        let top_down_pipeline = top_down_render::top_down_pipeline(&device, &frame_layout);
        Ok(Gpu {
            top_down_pipeline,
            instance,
            adapter,
            max_texture_size: device.limits().max_texture_dimension_2d,
            device,
            queue,
            adapter_name,
            pipeline,
            coverage_pipeline,
            frame_layout,
            material_layout,
            sampler,
            white,
            uploads: Mutex::new(HashMap::new()),
            view_pipelines,
            impostor: OnceLock::new(),
            view_material_layout,
            material_groups: Mutex::new(HashMap::new()),
        })
    }

    /// Runs `work` with the device's validation, out-of-memory and internal errors caught (on
    /// this thread) and returned as `GpuError::Render`: wgpu panics on an error no scope
    /// catches, and a render the device refuses (a target too large for its memory) must fail
    /// its asset, not end the process.
    fn catching_device_errors<T>(&self, work: impl FnOnce() -> Result<T, GpuError>) -> Result<T, GpuError> {
        let scopes = [wgpu::ErrorFilter::Internal, wgpu::ErrorFilter::OutOfMemory, wgpu::ErrorFilter::Validation]
            .map(|filter| self.device.push_error_scope(filter));
        let result = work();
        // Popped innermost first.
        let mut first_error = None;
        for scope in scopes.into_iter().rev() {
            let error = pollster::block_on(scope.pop());
            first_error = first_error.or(error);
        }
        match first_error {
            Some(error) => Err(GpuError::Render(error.to_string())),
            None => result,
        }
    }

    /// The upload cached under `key`, made by `make` by the first thread that asks for it; other
    /// threads asking meanwhile wait for it instead of uploading it again.
    fn cached_upload(&self, key: UploadKey, make: impl FnOnce() -> wgpu::TextureView) -> Arc<wgpu::TextureView> {
        let cell = self.uploads.lock().expect("upload cache").entry(key).or_default().clone();
        cell.get_or_init(|| Arc::new(make())).clone()
    }

    /// Submits `encoder` after copying `targets` out, and returns each one's pixels (rows
    /// without padding, as many bytes per texel as its format has).
    fn read_back(
        &self,
        mut encoder: wgpu::CommandEncoder,
        targets: &[&wgpu::Texture],
    ) -> Result<Vec<Vec<u8>>, GpuError> {
        let row_bytes = |texture: &wgpu::Texture| texture.width() * texture.format().block_copy_size(None).unwrap_or(4);
        let padded_row =
            |texture: &wgpu::Texture| row_bytes(texture).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
        let readbacks: Vec<wgpu::Buffer> = targets
            .iter()
            .map(|texture| {
                let buffer = self.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("readback"),
                    size: (padded_row(texture) * texture.height()) as u64,
                    usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
                    mapped_at_creation: false,
                });
                encoder.copy_texture_to_buffer(
                    texture.as_image_copy(),
                    wgpu::TexelCopyBufferInfo {
                        buffer: &buffer,
                        layout: wgpu::TexelCopyBufferLayout {
                            offset: 0,
                            bytes_per_row: Some(padded_row(texture)),
                            rows_per_image: Some(texture.height()),
                        },
                    },
                    texture.size(),
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
        for (buffer, texture) in readbacks.iter().zip(targets) {
            let mapped = buffer.slice(..).get_mapped_range().map_err(|error| GpuError::Render(format!("{error:?}")))?;
            let (row_bytes, padded_row) = (row_bytes(texture) as usize, padded_row(texture) as usize);
            let mut pixels = Vec::with_capacity(row_bytes * texture.height() as usize);
            for row in 0..texture.height() as usize {
                pixels.extend_from_slice(&mapped[row * padded_row..][..row_bytes]);
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
}

/// The depth test of the mesh pipelines: the nearest face wins.
fn depth_test() -> wgpu::DepthStencilState {
    wgpu::DepthStencilState {
        format: DEPTH_FORMAT,
        depth_write_enabled: Some(true),
        depth_compare: Some(wgpu::CompareFunction::LessEqual),
        stencil: Default::default(),
        bias: Default::default(),
    }
}

/// The image of a batched renderer (`render`, handed the callback that takes each view's image)
/// drawing a single view.
fn one_view(render: impl FnOnce(&mut dyn FnMut(usize, Vec<u8>)) -> Result<(), GpuError>) -> Result<Vec<u8>, GpuError> {
    let mut image = Vec::new();
    render(&mut |_, view| image = view)?;
    Ok(image)
}

/// A pipeline drawing `RenderVertex` triangles double-sided (with `depth`'s test, when given)
/// through the vertex shader `vs_main` and the fragment entry point named beside the shader, with
/// its overridable constants: the one shape the plane bake, its coverage and the preview use.
fn mesh_pipeline(
    device: &wgpu::Device,
    label: &str,
    layout: &wgpu::PipelineLayout,
    (shader, fragment_entry, constants): (&wgpu::ShaderModule, &str, &[(&str, f64)]),
    targets: &[Option<wgpu::ColorTargetState>],
    depth: Option<wgpu::DepthStencilState>,
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
            entry_point: Some(fragment_entry),
            compilation_options: wgpu::PipelineCompilationOptions { constants, ..Default::default() },
            targets,
        }),
        primitive: wgpu::PrimitiveState { cull_mode: None, ..Default::default() },
        depth_stencil: depth,
        multisample: wgpu::MultisampleState::default(),
        multiview_mask: None,
        cache: None,
    })
}

fn extend([x, y, z]: [f32; 3]) -> [f32; 4] {
    [x, y, z, 0.0]
}

/// Uploads a mip chain (level 0 first) as one texture.
fn upload(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    levels: &[Texture],
    format: wgpu::TextureFormat,
) -> wgpu::TextureView {
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
            wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(image.width * 4),
                rows_per_image: Some(image.height),
            },
            wgpu::Extent3d { width: image.width, height: image.height, depth_or_array_layers: 1 },
        );
    }
    texture.create_view(&Default::default())
}
