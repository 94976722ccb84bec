//! glTF 2.0 documents of triangle meshes: a `.gltf` JSON (made with `gltf-json`) and the `.bin`
//! it names, with positions, normals, optional tangents and UVs, one primitive per material,
//! and metallic-roughness materials whose maps are image files beside the document.
//!
//! Conventions (stated once, here and in docs/outputs.md): UVs as glTF has them, origin at the
//! image's top left (the OBJ's `v` is flipped, `1 − v`); normal maps +Y up (OpenGL, glTF), in
//! the tangent frame of each vertex's `TANGENT` (w = +1: bitangent = normal × tangent); one
//! packed image for occlusion (R), roughness (G) and metallic (B), as glTF reads it. Pure: the
//! kinds hand the bytes to the artifacts edge.

use std::collections::BTreeMap;
use std::path::Path;

use gltf_json as json;
use json::validation::Checked::Valid;
use json::validation::USize64;

use crate::MeshMaterial;
use texture::TextureSlot;

/// How a material's alpha is used.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum GltfAlpha {
    Opaque,
    /// Alpha-tested at this cutoff (glTF's `MASK`).
    Mask(f32),
    /// Blended by the base colour's alpha (glTF's `BLEND`): an MTL's `d` below 1.
    Blend,
}

/// How a material's maps are sampled past their edges.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GltfWrap {
    /// Clamped to the edge texel: an atlas, whose UVs stay inside it.
    Clamp,
    /// Repeated: an OBJ material's maps (tiling bark, UVs past 1), unless its MTL says `-clamp on`.
    Repeat,
}

/// What the documents cirrus writes name as their generator.
pub const GENERATOR: &str = concat!("cirrus ", env!("CARGO_PKG_VERSION"));

/// A metallic-roughness material; maps are URIs relative to the `.gltf` file.
#[derive(Clone, Debug, PartialEq)]
pub struct GltfMaterial {
    pub name: String,
    /// Linear RGBA factor (multiplies the base colour map).
    pub base_colour_factor: [f32; 4],
    pub metallic_factor: f32,
    pub roughness_factor: f32,
    pub base_colour: Option<String>,
    pub normal: Option<String>,
    /// Occlusion from the image's R channel.
    pub occlusion: Option<String>,
    /// Roughness from the image's G channel, metallic from its B (times the factors).
    pub metallic_roughness: Option<String>,
    pub alpha: GltfAlpha,
    pub double_sided: bool,
    pub wrap: GltfWrap,
}

/// The glTF material of an OBJ material (`MeshMaterial`), each map's URI given by `uri` (`None`:
/// leave it out), and what glTF cannot say of it. The albedo map is the base colour, its alpha
/// the cut-out's (`MASK` at 0.5, double-sided) or `d` below 1 blended; `norm` the normal map;
/// `map_ao` the occlusion (R of a grey map); `map_Pr` the roughness (G of a grey map) when the
/// metallic is a constant 0, since glTF reads metallic from the same image's B. A separate
/// opacity map, or a roughness map beside a metallic map or a non-zero metallic, would need
/// the maps packed into one image: the material keeps their factors, and a note says so.
pub fn material_from_mtl(
    material: &MeshMaterial,
    mut uri: impl FnMut(TextureSlot, &Path) -> Option<String>,
) -> (GltfMaterial, Vec<String>) {
    let mut map = |slot: TextureSlot| material.maps.get(&slot).and_then(|path| uri(slot, path));
    let mut notes = Vec::new();
    let [r, g, b] = material.albedo_factor;
    let base_colour = map(TextureSlot::Albedo);
    let alpha = if material.cut_out && material.opacity >= 1.0 && base_colour.is_some() {
        GltfAlpha::Mask(0.5)
    } else if material.opacity < 1.0 {
        GltfAlpha::Blend
    } else {
        GltfAlpha::Opaque
    };
    if let Some(opacity) = material.maps.get(&TextureSlot::Opacity) {
        notes.push(format!(
            "material `{}`: its opacity map `{}` is not its albedo's alpha, and glTF reads alpha from the base \
                colour only: the glTF material is {}",
            material.name,
            base::diagnostic::display_path(opacity),
            if alpha == GltfAlpha::Opaque { "opaque" } else { "alpha-tested by the albedo's alpha" }
        ));
    }
    let roughness = map(TextureSlot::Roughness);
    let metallic = map(TextureSlot::Metallic);
    let metallic_roughness = match (&roughness, &metallic) {
        (Some(roughness), None) if material.metallic == 0.0 => Some(roughness.clone()),
        (None, None) => None,
        _ => {
            notes.push(format!(
                "material `{}`: its roughness and metallic maps would need packing into one image for glTF; the \
                    glTF material has their factors (roughness {}, metallic {}) instead",
                material.name, material.roughness, material.metallic
            ));
            None
        }
    };
    let gltf = GltfMaterial {
        name: material.name.clone(),
        base_colour_factor: [r, g, b, material.opacity],
        metallic_factor: material.metallic,
        roughness_factor: if metallic_roughness.is_some() { 1.0 } else { material.roughness },
        base_colour,
        normal: map(TextureSlot::Normal),
        occlusion: map(TextureSlot::Ao),
        metallic_roughness,
        alpha,
        double_sided: matches!(alpha, GltfAlpha::Mask(_)),
        wrap: if material.map_options.values().any(|options| clamps(options)) {
            GltfWrap::Clamp
        } else {
            GltfWrap::Repeat
        },
    };
    (gltf, notes)
}

/// Whether an MTL map's options (`-clamp on -s 2 2 1`) clamp its UVs.
fn clamps(options: &str) -> bool {
    let words: Vec<&str> = options.split_whitespace().collect();
    words.windows(2).any(|pair| pair[0] == "-clamp" && pair[1].eq_ignore_ascii_case("on"))
}

/// A triangle mesh as the document stores it.
#[derive(Clone, Copy, Debug)]
pub struct GltfMesh<'a> {
    pub name: &'a str,
    pub positions: &'a [[f32; 3]],
    /// Per vertex, unit length.
    pub normals: &'a [[f32; 3]],
    /// Per vertex (xyz unit length, w ±1), or empty.
    pub tangents: &'a [[f32; 4]],
    /// Per vertex in the OBJ's convention (origin bottom left), or empty.
    pub uvs: &'a [[f32; 2]],
    pub triangles: &'a [[u32; 3]],
    /// Each triangle's index into `materials`.
    pub triangle_materials: &'a [u32],
    pub materials: &'a [GltfMaterial],
    /// What the mesh's `extras` say (an impostor's description), if anything.
    pub extras: Option<&'a serde_json::Value>,
}

/// The geometry of a [`GltfMesh`], owned: what a stage keeps (in its cache entry) so that the
/// document can be written again with other image names without the stage.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct GltfGeometry {
    pub positions: Vec<[f32; 3]>,
    pub normals: Vec<[f32; 3]>,
    /// Per vertex in the OBJ's convention, or empty.
    pub uvs: Vec<[f32; 2]>,
    pub triangles: Vec<[u32; 3]>,
    pub triangle_materials: Vec<u32>,
    /// Per vertex when there are UVs (see [`GltfGeometry::with_tangents`]), else empty.
    #[serde(default)]
    pub tangents: Vec<[f32; 4]>,
}

impl GltfGeometry {
    /// The geometry with its tangents when it has UVs: MikkTSpace's (`mesh::mikktspace_tangents`),
    /// the frame glTF loaders would make and the source normal maps were baked in, so that no
    /// loader has to make its own.
    pub fn with_tangents(mut self) -> GltfGeometry {
        if !self.uvs.is_empty() {
            self.tangents = super::mikktspace_tangents(&self.positions, &self.normals, &self.uvs, &self.triangles);
        }
        self
    }

    /// The bytes of the buffer [`gltf_files`] writes for this geometry (positions, normals, UVs,
    /// tangents where `normal_mapped` and it has them, `u32` indices), before writing it.
    pub fn buffer_bytes(&self, normal_mapped: bool) -> u64 {
        let tangents = if normal_mapped { 16 * self.tangents.len() } else { 0 };
        let vertices = 12 * (self.positions.len() + self.normals.len()) + 8 * self.uvs.len() + tangents;
        (vertices + 12 * self.triangles.len()) as u64
    }

    /// The mesh over this geometry drawn with `materials`: with its tangents when one of them
    /// has a normal map.
    pub fn mesh<'a>(&'a self, name: &'a str, materials: &'a [GltfMaterial]) -> GltfMesh<'a> {
        let normal_mapped = materials.iter().any(|material| material.normal.is_some());
        GltfMesh {
            name,
            positions: &self.positions,
            normals: &self.normals,
            tangents: if normal_mapped { &self.tangents } else { &[] },
            uvs: &self.uvs,
            triangles: &self.triangles,
            triangle_materials: &self.triangle_materials,
            materials,
            extras: None,
        }
    }
}

/// The two files of a document.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct GltfFiles {
    pub gltf: Vec<u8>,
    pub bin: Vec<u8>,
}

/// The document of `mesh`, its buffer named `bin_uri` (relative to the `.gltf`).
pub fn gltf_files(mesh: &GltfMesh, bin_uri: &str, generator: &str) -> GltfFiles {
    let mut root = new_root(generator);
    let (node, bin) = push_mesh(&mut root, mesh, bin_uri, "");
    set_scene(&mut root, node);
    GltfFiles { gltf: document_bytes(&root), bin }
}

/// One level of a chain: its mesh, and the folder (relative to the chain's document) that holds
/// its `.bin` and images.
#[derive(Clone, Copy, Debug)]
pub struct GltfLevel<'a> {
    pub mesh: GltfMesh<'a>,
    pub folder: &'a str,
}

/// A LOD chain as one document (`MSFT_lod`): the first level's node in the scene, naming the
/// others' nodes in order, with `screen_coverage` (one value per level: the least screen
/// coverage at which each is shown) in its extras as `MSFT_screencoverage`. Each level's
/// buffer is `<folder>/<bin_name>`, the very bytes [`gltf_files`] writes for it there.
pub fn gltf_chain(levels: &[GltfLevel], bin_name: &str, screen_coverage: &[f32], generator: &str) -> Vec<u8> {
    let mut root = new_root(generator);
    let nodes: Vec<json::Index<json::Node>> = levels
        .iter()
        .map(|level| push_mesh(&mut root, &level.mesh, &format!("{}/{bin_name}", level.folder), level.folder).0)
        .collect();
    if let Some((&first, others)) = nodes.split_first() {
        let ids: Vec<u32> = others.iter().map(|node| node.value() as u32).collect();
        let node = &mut root.nodes[first.value()];
        let mut extensions = json::extensions::scene::Node::default();
        extensions.others.insert("MSFT_lod".into(), serde_json::json!({ "ids": ids }));
        node.extensions = Some(extensions);
        node.extras = Some(
            serde_json::value::to_raw_value(&serde_json::json!({ "MSFT_screencoverage": screen_coverage }))
                .expect("extras serialise"),
        );
        root.extensions_used.push("MSFT_lod".into());
        set_scene(&mut root, first);
    }
    document_bytes(&root)
}

/// A relative path as a URI reference: bytes other than unreserved ones and `/` percent-encoded
/// (a space in a file name is `%20` to a glTF loader).
fn uri_of(path: &str) -> String {
    let mut uri = String::with_capacity(path.len());
    for byte in path.bytes() {
        if byte.is_ascii_alphanumeric() || b"-._~/".contains(&byte) {
            uri.push(byte as char);
        } else {
            uri.push_str(&format!("%{byte:02X}"));
        }
    }
    uri
}

fn new_root(generator: &str) -> json::Root {
    json::Root {
        asset: json::Asset { generator: Some(generator.to_string()), ..Default::default() },
        ..Default::default()
    }
}

/// The document's one scene, holding `node`.
fn set_scene(root: &mut json::Root, node: json::Index<json::Node>) {
    let scene = root.push(json::Scene { extensions: None, extras: Default::default(), name: None, nodes: vec![node] });
    root.scene = Some(scene);
}

fn document_bytes(root: &json::Root) -> Vec<u8> {
    json::serialize::to_vec_pretty(root).expect("a glTF document serialises")
}

/// Adds `mesh` (a node, its mesh, materials and images under `folder`) with a buffer of its own
/// named `bin_uri`; returns the node and the buffer's bytes.
fn push_mesh(
    root: &mut json::Root,
    mesh: &GltfMesh,
    bin_uri: &str,
    folder: &str,
) -> (json::Index<json::Node>, Vec<u8>) {
    let mut bin = Vec::new();
    let buffer = json::Index::new(root.buffers.len() as u32);
    root.buffers.push(json::Buffer {
        byte_length: USize64(0),
        name: None,
        uri: Some(uri_of(bin_uri)),
        extensions: None,
        extras: Default::default(),
    });
    let mut attributes = BTreeMap::new();
    let position = vertex_accessor(root, &mut bin, buffer, mesh.positions, json::accessor::Type::Vec3, true);
    attributes.insert(Valid(json::mesh::Semantic::Positions), position);
    let normal = vertex_accessor(root, &mut bin, buffer, mesh.normals, json::accessor::Type::Vec3, false);
    attributes.insert(Valid(json::mesh::Semantic::Normals), normal);
    if !mesh.tangents.is_empty() {
        let tangent = vertex_accessor(root, &mut bin, buffer, mesh.tangents, json::accessor::Type::Vec4, false);
        attributes.insert(Valid(json::mesh::Semantic::Tangents), tangent);
    }
    if !mesh.uvs.is_empty() {
        let flipped: Vec<[f32; 2]> = mesh.uvs.iter().map(|&[u, v]| [u, 1.0 - v]).collect();
        let uv = vertex_accessor(root, &mut bin, buffer, &flipped, json::accessor::Type::Vec2, false);
        attributes.insert(Valid(json::mesh::Semantic::TexCoords(0)), uv);
    }
    let materials: Vec<json::Index<json::Material>> =
        mesh.materials.iter().map(|material| push_material(root, material, folder)).collect();
    // One primitive per material that has triangles, in the materials' order.
    let by_material = super::triangles_by_material(mesh.triangle_materials, mesh.triangles.len(), mesh.materials.len());
    let mut primitives = Vec::new();
    for (material, triangles) in by_material.iter().enumerate().filter(|(_, triangles)| !triangles.is_empty()) {
        let indices: Vec<u32> = triangles.iter().flat_map(|&triangle| mesh.triangles[triangle]).collect();
        let target = Some(json::buffer::Target::ElementArrayBuffer);
        let view = push_view(root, &mut bin, buffer, bytemuck::cast_slice(&indices), target);
        let accessor =
            root.push(accessor(view, indices.len(), json::accessor::ComponentType::U32, json::accessor::Type::Scalar));
        // A primitive whose material has no normal map leaves the tangents out (the validator's
        // UNUSED_MESH_TANGENT).
        let mut attributes = attributes.clone();
        if mesh.materials.get(material).is_some_and(|material| material.normal.is_none()) {
            attributes.remove(&Valid(json::mesh::Semantic::Tangents));
        }
        primitives.push(json::mesh::Primitive {
            attributes,
            extensions: None,
            extras: Default::default(),
            indices: Some(accessor),
            material: materials.get(material).copied(),
            mode: Valid(json::mesh::Mode::Triangles),
            targets: None,
        });
    }
    let gltf_mesh = root.push(json::Mesh {
        extensions: None,
        extras: mesh.extras.map(|extras| serde_json::value::to_raw_value(extras).expect("extras serialise")),
        name: Some(mesh.name.to_string()),
        primitives,
        weights: None,
    });
    root.buffers[buffer.value()].byte_length = USize64::from(bin.len());
    let node = root.push(json::Node { mesh: Some(gltf_mesh), name: Some(mesh.name.to_string()), ..Default::default() });
    (node, bin)
}

/// Appends `bytes` (padded to 4) to the buffer as a view of its own.
fn push_view(
    root: &mut json::Root,
    bin: &mut Vec<u8>,
    buffer: json::Index<json::Buffer>,
    bytes: &[u8],
    target: Option<json::buffer::Target>,
) -> json::Index<json::buffer::View> {
    let offset = bin.len();
    bin.extend_from_slice(bytes);
    bin.resize(bin.len().next_multiple_of(4), 0);
    root.push(json::buffer::View {
        buffer,
        byte_length: USize64::from(bytes.len()),
        byte_offset: Some(USize64::from(offset)),
        byte_stride: None,
        name: None,
        target: target.map(Valid),
        extensions: None,
        extras: Default::default(),
    })
}

/// A float vertex attribute (`N` components) in a view of its own; positions carry their
/// bounds, as glTF requires.
fn vertex_accessor<const N: usize>(
    root: &mut json::Root,
    bin: &mut Vec<u8>,
    buffer: json::Index<json::Buffer>,
    values: &[[f32; N]],
    type_: json::accessor::Type,
    bounds: bool,
) -> json::Index<json::Accessor> {
    let view = push_view(root, bin, buffer, bytemuck::cast_slice(values), Some(json::buffer::Target::ArrayBuffer));
    let (min, max) = if bounds && !values.is_empty() {
        let mut min = [f32::INFINITY; N];
        let mut max = [f32::NEG_INFINITY; N];
        for value in values {
            for component in 0..N {
                min[component] = min[component].min(value[component]);
                max[component] = max[component].max(value[component]);
            }
        }
        (Some(json::Value::from(min.to_vec())), Some(json::Value::from(max.to_vec())))
    } else {
        (None, None)
    };
    root.push(json::Accessor { min, max, ..accessor(view, values.len(), json::accessor::ComponentType::F32, type_) })
}

/// An accessor of `count` elements over all of `view`, without bounds.
fn accessor(
    view: json::Index<json::buffer::View>,
    count: usize,
    component: json::accessor::ComponentType,
    type_: json::accessor::Type,
) -> json::Accessor {
    json::Accessor {
        buffer_view: Some(view),
        byte_offset: None,
        count: USize64::from(count),
        component_type: Valid(json::accessor::GenericComponentType(component)),
        extensions: None,
        extras: Default::default(),
        type_: Valid(type_),
        min: None,
        max: None,
        name: None,
        normalized: false,
        sparse: None,
    }
}

/// A texture of the image at `path` sampled with `wrap` (one image per URI, one texture per image
/// and wrap, one sampler per wrap).
fn push_texture(root: &mut json::Root, path: &str, wrap: GltfWrap) -> json::Index<json::Texture> {
    let uri = uri_of(path);
    let mode = match wrap {
        GltfWrap::Clamp => json::texture::WrappingMode::ClampToEdge,
        GltfWrap::Repeat => json::texture::WrappingMode::Repeat,
    };
    let sampler = match root.samplers.iter().position(|sampler| sampler.wrap_s == Valid(mode)) {
        Some(index) => json::Index::new(index as u32),
        None => root.push(json::texture::Sampler {
            mag_filter: Some(Valid(json::texture::MagFilter::Linear)),
            min_filter: Some(Valid(json::texture::MinFilter::LinearMipmapLinear)),
            wrap_s: Valid(mode),
            wrap_t: Valid(mode),
            ..Default::default()
        }),
    };
    let image = root.images.iter().position(|image| image.uri.as_deref() == Some(&*uri));
    if let Some(image) = image {
        let same = root.textures.iter().position(|texture| {
            texture.source.value() == image && texture.sampler.map(|found| found.value()) == Some(sampler.value())
        });
        if let Some(index) = same {
            return json::Index::new(index as u32);
        }
    }
    let image = match image {
        Some(index) => json::Index::new(index as u32),
        None => root.push(json::Image {
            buffer_view: None,
            mime_type: None,
            name: None,
            uri: Some(uri),
            extensions: None,
            extras: Default::default(),
        }),
    };
    root.push(json::Texture {
        name: None,
        sampler: Some(sampler),
        source: image,
        extensions: None,
        extras: Default::default(),
    })
}

/// `material`, its images named as seen from the document (`folder` + their URI).
fn push_material(root: &mut json::Root, material: &GltfMaterial, folder: &str) -> json::Index<json::Material> {
    let info = |root: &mut json::Root, uri: &Option<String>| {
        uri.as_deref().map(|uri| json::texture::Info {
            index: push_texture(
                root,
                &if folder.is_empty() { uri.to_string() } else { format!("{folder}/{uri}") },
                material.wrap,
            ),
            tex_coord: 0,
            extensions: None,
            extras: Default::default(),
        })
    };
    let base_color_texture = info(root, &material.base_colour);
    let metallic_roughness_texture = info(root, &material.metallic_roughness);
    let occlusion = info(root, &material.occlusion);
    let normal_texture = info(root, &material.normal).map(|info| json::material::NormalTexture {
        index: info.index,
        scale: 1.0,
        tex_coord: 0,
        extensions: None,
        extras: Default::default(),
    });
    let occlusion_texture = occlusion.map(|info| json::material::OcclusionTexture {
        index: info.index,
        strength: json::material::StrengthFactor(1.0),
        tex_coord: 0,
        extensions: None,
        extras: Default::default(),
    });
    let (alpha_mode, alpha_cutoff) = match material.alpha {
        GltfAlpha::Opaque => (json::material::AlphaMode::Opaque, None),
        GltfAlpha::Mask(cutoff) => (json::material::AlphaMode::Mask, Some(json::material::AlphaCutoff(cutoff))),
        GltfAlpha::Blend => (json::material::AlphaMode::Blend, None),
    };
    root.push(json::Material {
        alpha_cutoff,
        alpha_mode: Valid(alpha_mode),
        double_sided: material.double_sided,
        name: Some(material.name.clone()),
        pbr_metallic_roughness: json::material::PbrMetallicRoughness {
            base_color_factor: json::material::PbrBaseColorFactor(material.base_colour_factor),
            base_color_texture,
            metallic_factor: json::material::StrengthFactor(material.metallic_factor),
            roughness_factor: json::material::StrengthFactor(material.roughness_factor),
            metallic_roughness_texture,
            extensions: None,
            extras: Default::default(),
        },
        normal_texture,
        occlusion_texture,
        ..Default::default()
    })
}

/// A material on its own: a 1 × 1 square in the XY plane facing +Z (tangent +X), its UVs over
/// the whole image, drawn with `material`; the document's buffer is `bin_uri`.
pub fn swatch_files(material: GltfMaterial, bin_uri: &str, generator: &str) -> GltfFiles {
    let name = material.name.clone();
    let mesh = GltfMesh {
        name: &name,
        positions: &[[-0.5, -0.5, 0.0], [0.5, -0.5, 0.0], [0.5, 0.5, 0.0], [-0.5, 0.5, 0.0]],
        normals: &[[0.0, 0.0, 1.0]; 4],
        tangents: &[[1.0, 0.0, 0.0, 1.0]; 4],
        uvs: &[[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]],
        triangles: &[[0, 1, 2], [0, 2, 3]],
        triangle_materials: &[],
        materials: std::slice::from_ref(&material),
        extras: None,
    };
    gltf_files(&mesh, bin_uri, generator)
}
