//! The plane renderer of billboard clouds: a plane's rectangles stacked in shared targets,
//! rendered in one submission with `shaders/plane.wgsl` into albedo, normal, mra and height.

use std::sync::Arc;

use bytemuck::{Pod, Zeroable};

use super::*;
use texture::distance_alpha::DistanceAlpha;
use texture::TextureSlot;

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

/// A material as the renderer sees it: its maps as mip chains (level 0 the decoded map, made by
/// `texture::mips::mip_chain` with [`material_mip_settings`] for the slot; any may be missing)
/// and constants.
#[derive(Clone, Debug, Default)]
pub struct RenderMaterial {
    pub albedo: Option<Arc<Vec<Texture>>>,
    pub opacity: Option<Arc<Vec<Texture>>>,
    pub normal: Option<Arc<Vec<Texture>>>,
    pub metallic: Option<Arc<Vec<Texture>>>,
    pub roughness: Option<Arc<Vec<Texture>>>,
    pub ao: Option<Arc<Vec<Texture>>>,
    /// Linear RGB factor and constant opacity.
    pub albedo_factor: [f32; 4],
    pub metallic_value: f32,
    pub roughness_value: f32,
    pub ao_value: f32,
}

/// Where a rectangle lies in the mesh's space: `x_axis × y_axis = normal`, `width` along
/// `x_axis` and `height` along `y_axis` from `origin`.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RectangleFrame {
    pub origin: [f32; 3],
    pub x_axis: [f32; 3],
    pub y_axis: [f32; 3],
    pub normal: [f32; 3],
    pub width: f32,
    pub height: f32,
}

/// What one plane render needs: its faces (three vertices each) grouped by material.
#[derive(Clone, Debug)]
pub struct PlaneRenderInput<'a> {
    pub frame: RectangleFrame,
    pub epsilon: f32,
    pub alpha_cutoff: f32,
    /// The images' size in texels.
    pub width: u32,
    pub height: u32,
    /// Samples per texel along each axis: the faces are rendered at this many times the size,
    /// then brought down with a distance-field alpha (`texture::distance_alpha`); 1 renders the
    /// texels themselves, alpha 1 where a face covers the texel's centre.
    pub supersampling: u32,
    /// (material index, that material's triangles' vertices).
    pub batches: Vec<(usize, Vec<RenderVertex>)>,
    pub materials: &'a [RenderMaterial],
}

/// The four images of one plane, RGBA8, rows from the top (the plane's +Y edge), one after the
/// other in a shared buffer: albedo (sRGB-encoded colour; alpha 1 where a face covers the texel,
/// 0 elsewhere, or the distance alpha of a supersampled render: 0 where nothing is near),
/// normal, mra and height. The buffer may hold other planes' images too (a render
/// memo read from disk holds a whole set of them), so that loading images copies nothing.
#[derive(Clone, Debug)]
pub struct PlaneImages {
    pub width: u32,
    pub height: u32,
    buffer: Arc<Vec<u8>>,
    offset: usize,
}

impl PlaneImages {
    /// The surfaces in buffer order.
    pub(crate) const SURFACES: [SurfaceKind; 4] =
        [SurfaceKind::Albedo, SurfaceKind::Normal, SurfaceKind::Mra, SurfaceKind::Height];

    /// The bytes of one `width` × `height` plane's four images.
    pub fn byte_len(width: u32, height: u32) -> usize {
        Self::SURFACES.len() * Self::surface_len(width, height)
    }

    fn surface_len(width: u32, height: u32) -> usize {
        width as usize * height as usize * 4
    }

    /// The images that start at `offset` in `buffer` (the four surfaces in [`Self::SURFACES`]
    /// order); `None` when the buffer ends before them.
    pub fn in_buffer(width: u32, height: u32, buffer: Arc<Vec<u8>>, offset: usize) -> Option<PlaneImages> {
        let end = offset.checked_add(Self::byte_len(width, height))?;
        (end <= buffer.len()).then_some(PlaneImages { width, height, buffer, offset })
    }

    /// All four images, in [`Self::SURFACES`] order.
    pub fn bytes(&self) -> &[u8] {
        &self.buffer[self.offset..][..Self::byte_len(self.width, self.height)]
    }

    /// The image of `surface`.
    pub fn surface(&self, surface: SurfaceKind) -> &[u8] {
        let index = Self::SURFACES.iter().position(|&kind| kind == surface).expect("every surface kind has an image");
        let length = Self::surface_len(self.width, self.height);
        &self.bytes()[index * length..][..length]
    }
}

/// Images are equal by size and contents, wherever their buffers lie.
impl PartialEq for PlaneImages {
    fn eq(&self, other: &Self) -> bool {
        (self.width, self.height) == (other.width, other.height) && self.bytes() == other.bytes()
    }
}

/// How the renders filter a material's texture for `slot`: colour and opacity maps with
/// coverage-preserving mips at the cutoff, the others as data.
pub fn material_mip_settings(slot: TextureSlot, alpha_cutoff: f32) -> MipSettings {
    match slot {
        TextureSlot::Albedo | TextureSlot::Opacity => {
            MipSettings { kind: SurfaceKind::Albedo, alpha_cutoff: Some(alpha_cutoff) }
        }
        TextureSlot::Normal => MipSettings { kind: SurfaceKind::Normal, alpha_cutoff: None },
        TextureSlot::Metallic | TextureSlot::Roughness | TextureSlot::Ao => {
            MipSettings { kind: SurfaceKind::Mra, alpha_cutoff: None }
        }
    }
}

/// An uploaded chain: its level 0's content, its colour space and its cutoff.
fn upload_key(level0: &Texture, settings: MipSettings) -> UploadKey {
    (level0.hash, settings.kind == SurfaceKind::Albedo, settings.alpha_cutoff.map_or(u32::MAX, f32::to_bits))
}

/// Colour maps are sampled as sRGB, the others as data.
fn view_format(settings: MipSettings) -> wgpu::TextureFormat {
    if settings.kind == SurfaceKind::Albedo {
        ALBEDO_FORMAT
    } else {
        DATA_FORMAT
    }
}

impl Gpu {
    /// Uploads the mip chain of a material's texture for `slot` (made with
    /// [`material_mip_settings`], level 0 first) ahead of the renders that use it, once per
    /// content: a kind can upload on every worker while other work runs.
    pub fn upload_material_mips(&self, levels: &[Texture], slot: TextureSlot, alpha_cutoff: f32) {
        self.material_texture_view(levels, slot, alpha_cutoff);
    }

    /// A material's mip chain for `slot` on the GPU (uploaded once per content).
    fn material_texture_view(
        &self,
        levels: &[Texture],
        slot: TextureSlot,
        alpha_cutoff: f32,
    ) -> Arc<wgpu::TextureView> {
        let settings = material_mip_settings(slot, alpha_cutoff);
        self.cached_upload(upload_key(&levels[0], settings), || {
            upload(&self.device, &self.queue, levels, view_format(settings))
        })
    }

    /// Renders the rectangles of one plane (or any set of rectangles): each under its own
    /// orthographic camera, side by side in shared targets (rows of rectangles, tallest first),
    /// in as few submissions and read-backs as the targets' size allows. On llvmpipe a
    /// submission costs about a millisecond whatever it draws.
    ///
    /// Every rectangle is shaded once per texel; one with supersampling is also rendered at its
    /// samples through the alpha test alone (one byte per sample, no depth), and its texels'
    /// alpha becomes the distance alpha of those samples (`texture::distance_alpha`). Shading
    /// every sample cost four times the fragments, read-backs and resolve work for colours that
    /// differ only along edges.
    pub fn render_rectangles(&self, inputs: &[PlaneRenderInput]) -> Result<Vec<PlaneImages>, GpuError> {
        let mut order: Vec<usize> = (0..inputs.len()).collect();
        // Stacks of one supersampling each, tallest rectangles first.
        order
            .sort_by_key(|&index| (inputs[index].supersampling.max(1), std::cmp::Reverse(inputs[index].height.max(1))));
        let mut images: Vec<Option<PlaneImages>> = vec![None; inputs.len()];
        let mut rest = &order[..];
        while !rest.is_empty() {
            let factor = inputs[rest[0]].supersampling.max(1);
            let side_limit = self.max_texture_size / factor;
            let row_width = rest
                .iter()
                .map(|&index| inputs[index].width.max(1))
                .max()
                .unwrap_or(1)
                .max(STACK_ROW_TEXELS)
                .min(side_limit);
            let mut stack = Vec::new();
            let (mut x, mut y, mut row_height, mut width) = (0u32, 0u32, 0u32, 0u32);
            for &index in rest {
                let input = &inputs[index];
                if input.supersampling.max(1) != factor {
                    break;
                }
                let (rectangle_width, rectangle_height) = (input.width.max(1), input.height.max(1));
                if x > 0 && x + rectangle_width > row_width {
                    (x, y, row_height) = (0, y + row_height, 0);
                }
                let bottom = y + rectangle_height.max(row_height);
                let too_big = bottom > side_limit || row_width as u64 * bottom as u64 > MAX_STACK_TEXELS;
                if !stack.is_empty() && too_big {
                    break;
                }
                stack.push((index, x, y));
                x += rectangle_width;
                row_height = row_height.max(rectangle_height);
                width = width.max(x);
            }
            let height = y + row_height;
            let placed: Vec<(&PlaneRenderInput, u32, u32)> =
                stack.iter().map(|&(index, x, y)| (&inputs[index], x, y)).collect();
            let rendered = self.catching_device_errors(|| self.render_stack(&placed, (width, height), factor))?;
            for (&(index, _, _), image) in stack.iter().zip(rendered) {
                images[index] = Some(image);
            }
            rest = &rest[stack.len()..];
        }
        Ok(images.into_iter().map(|image| image.expect("every rectangle is rendered")).collect())
    }

    /// One submission: each input rendered at its place (x, y) in targets of `texels` (width,
    /// height), and, with a supersampling `factor` above 1, its coverage at `factor` times the
    /// place in a coverage target `factor` times the size.
    // Long: one command encoder from the targets' creation to the read-back, whose buffers and
    // bind groups must outlive the submission; split, each part would pass them all along.
    fn render_stack(
        &self,
        inputs: &[(&PlaneRenderInput, u32, u32)],
        texels: (u32, u32),
        factor: u32,
    ) -> Result<Vec<PlaneImages>, GpuError> {
        let (width, height) = texels;
        let mut targets: Vec<wgpu::Texture> = [ALBEDO_FORMAT, DATA_FORMAT, DATA_FORMAT, DATA_FORMAT]
            .iter()
            .map(|&format| self.target(width, height, format))
            .collect();
        let views: Vec<wgpu::TextureView> =
            targets.iter().map(|texture| texture.create_view(&Default::default())).collect();
        let depth_texture = self.target(width, height, DEPTH_FORMAT);
        let depth = depth_texture.create_view(&Default::default());
        let coverage_texture = (factor > 1).then(|| self.target(width * factor, height * factor, COVERAGE_FORMAT));
        let coverage_view = coverage_texture.as_ref().map(|texture| texture.create_view(&Default::default()));

        struct PlacedDraws {
            /// Where the rectangle lies in the texel targets, and its size in texels.
            x: u32,
            y: u32,
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
        let mut placed = Vec::with_capacity(inputs.len());
        for &(input, x, y) in inputs {
            let rectangle = &input.frame;
            let frame = FrameUniform {
                origin: extend(rectangle.origin),
                x_axis: extend(rectangle.x_axis),
                y_axis: extend(rectangle.y_axis),
                normal: extend(rectangle.normal),
                size: [
                    rectangle.width.max(1e-6),
                    rectangle.height.max(1e-6),
                    input.epsilon.max(1e-6),
                    input.alpha_cutoff,
                ],
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
            placed.push(PlacedDraws {
                x,
                y,
                width: input.width.max(1),
                height: input.height.max(1),
                frame_buffer,
                frame_group,
                draws,
            });
        }

        let vertex_buffer = (!all_vertices.is_empty()).then(|| self.vertex_buffer(&all_vertices));
        let mut encoder = self.device.create_command_encoder(&Default::default());
        let clear =
            wgpu::Operations { load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT), store: wgpu::StoreOp::Store };
        // A rectangle's draws under the camera that maps its clip square onto its place in a
        // target `scale` times the texels' size.
        let draw_rectangle = |pass: &mut wgpu::RenderPass, rectangle: &PlacedDraws, scale: u32| {
            let (x, y, width, height) =
                (rectangle.x * scale, rectangle.y * scale, rectangle.width * scale, rectangle.height * scale);
            pass.set_viewport(x as f32, y as f32, width as f32, height as f32, 0.0, 1.0);
            pass.set_scissor_rect(x, y, width, height);
            pass.set_bind_group(0, &rectangle.frame_group, &[]);
            for (vertices, group) in &rectangle.draws {
                pass.set_bind_group(1, group.as_ref(), &[]);
                pass.draw(vertices.clone(), 0..1);
            }
        };
        {
            let attachments: Vec<Option<wgpu::RenderPassColorAttachment>> = views
                .iter()
                .map(|view| {
                    Some(wgpu::RenderPassColorAttachment { view, depth_slice: None, resolve_target: None, ops: clear })
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
            for rectangle in &placed {
                draw_rectangle(&mut pass, rectangle, 1);
            }
        }
        if let Some(view) = &coverage_view {
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("plane coverage"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view,
                    depth_slice: None,
                    resolve_target: None,
                    ops: clear,
                })],
                ..Default::default()
            });
            pass.set_pipeline(&self.coverage_pipeline);
            if let Some(buffer) = &vertex_buffer {
                pass.set_vertex_buffer(0, buffer.slice(..));
            }
            for rectangle in &placed {
                draw_rectangle(&mut pass, rectangle, factor);
            }
        }
        targets.extend(coverage_texture);
        let mut stack = self.read_back(encoder, &targets.iter().collect::<Vec<_>>())?;
        let coverage = if factor > 1 { stack.pop().expect("the coverage target is read back") } else { Vec::new() };
        // Free device memory now rather than whenever wgpu next triages destroyed resources.
        targets.iter().for_each(wgpu::Texture::destroy);
        depth_texture.destroy();
        for rectangle in &placed {
            rectangle.frame_buffer.destroy();
        }
        if let Some(buffer) = &vertex_buffer {
            buffer.destroy();
        }
        // Each rectangle's texels of the four targets, one after the other in a buffer of its own.
        let images = placed
            .iter()
            .map(|rectangle| {
                let (x, y, rectangle_width, rectangle_height) =
                    (rectangle.x as usize, rectangle.y as usize, rectangle.width as usize, rectangle.height as usize);
                let mut pixels = Vec::with_capacity(PlaneImages::byte_len(rectangle.width, rectangle.height));
                for image in &stack {
                    for row in y..y + rectangle_height {
                        pixels.extend_from_slice(&image[(row * width as usize + x) * 4..][..rectangle_width * 4]);
                    }
                }
                if factor > 1 {
                    let scale = factor as usize;
                    let (sample_width, coverage_width) = (rectangle_width * scale, width as usize * scale);
                    let mut covered = Vec::with_capacity(sample_width * rectangle_height * scale);
                    for row in y * scale..(y + rectangle_height) * scale {
                        covered.extend(
                            coverage[row * coverage_width + x * scale..][..sample_width].iter().map(|&byte| byte != 0),
                        );
                    }
                    let length = pixels.len() / PlaneImages::SURFACES.len();
                    let mut surfaces: Vec<&mut [u8]> = pixels.chunks_exact_mut(length).collect();
                    texture::distance_alpha::apply_distance_alpha(&mut DistanceAlpha {
                        surfaces: &mut surfaces,
                        width: rectangle.width,
                        height: rectangle.height,
                        factor,
                        covered: &covered,
                        first_surface_srgb: true,
                    });
                }
                PlaneImages::in_buffer(rectangle.width, rectangle.height, Arc::new(pixels), 0)
                    .expect("the buffer holds four images")
            })
            .collect();
        Ok(images)
    }

    fn material_group(&self, material: &RenderMaterial, alpha_cutoff: f32) -> Arc<wgpu::BindGroup> {
        let flag = |levels: &Option<Arc<Vec<Texture>>>| if levels.is_some() { 1.0 } else { 0.0 };
        let uniform = MaterialUniform {
            albedo: material.albedo_factor,
            params: [material.metallic_value, material.roughness_value, material.ao_value, 0.0],
            has_a: [flag(&material.albedo), flag(&material.opacity), flag(&material.normal), flag(&material.metallic)],
            has_b: [flag(&material.roughness), flag(&material.ao), 0.0, 0.0],
        };
        let mut key = blake3::Hasher::new();
        key.update(bytemuck::bytes_of(&uniform));
        key.update(&alpha_cutoff.to_bits().to_le_bytes());
        for texture in [
            &material.albedo,
            &material.opacity,
            &material.normal,
            &material.metallic,
            &material.roughness,
            &material.ao,
        ] {
            key.update(texture.as_ref().map_or(&[0u8; 32], |levels| levels[0].hash.as_bytes()));
        }
        let key = key.finalize();
        if let Some(group) = self.material_groups.lock().expect("material groups").get(&key) {
            return group.clone();
        }
        let buffer = self.constants_buffer(bytemuck::bytes_of(&uniform));
        let views: Vec<Arc<wgpu::TextureView>> = [
            (&material.albedo, TextureSlot::Albedo),
            (&material.opacity, TextureSlot::Opacity),
            (&material.normal, TextureSlot::Normal),
            (&material.metallic, TextureSlot::Metallic),
            (&material.roughness, TextureSlot::Roughness),
            (&material.ao, TextureSlot::Ao),
        ]
        .into_iter()
        .map(|(texture, slot)| match texture {
            Some(texture) => self.material_texture_view(texture, slot, alpha_cutoff),
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
        let group = Arc::new(self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("material"),
            layout: &self.material_layout,
            entries: &entries,
        }));
        self.material_groups.lock().expect("material groups").insert(key, group.clone());
        group
    }
}
