//! A LOD chain's reduced levels (`lods: [Reduced(Ratio(0.5)), …]`, and an `Auto` level's
//! `reduced<N>` candidate): the source's triangles brought under a budget (`mesh::reduce`),
//! written as `lod.obj` + `lod.mtl` and `lod.gltf` + `lod.bin`, each material over its maps
//! packed (albedo + opacity, mra, normal: `texture::channel_packing`) and block-compressed by
//! the one texture tail into the level's `materials/<name>/`, each at most the level's largest
//! side, an `Auto` candidate's as large as its bytes allow beside its mesh (`allot_maps`). The
//! pure steps from mesh to files (`reduce_level`), maps and materials; the tracked functions
//! are `reduced_queries`', the stage instances and files `reduced_outputs`'.

use std::sync::Arc;

use super::levels;
use crate::kinds::{SurfaceId, SurfacePart};
use crate::mesh::gltf::{GltfMaterial, GltfMesh};
use crate::mesh::MeshMaterial;
use crate::texture::{SurfaceKind, TextureSlot};

/// The files a reduced level writes into its folder (beside its maps).
pub(super) const LEVEL_FILES: [&str; 4] = ["lod.obj", "lod.mtl", "lod.gltf", "lod.bin"];

/// The folder of a reduced level's maps, inside the level's: `materials/<name>/`.
pub(crate) const MATERIALS_FOLDER: &str = "materials";

/// The deviation (a fraction of the mesh's largest extent) up to which a reduced level's
/// simplifier prefers stopping to reaching its budget.
pub(crate) const REDUCE_MAX_ERROR: f32 = 0.01;

/// The source maps a material's `surface` is packed from, in `surface.slots()` order (none
/// where it has no such map or no UVs to draw it with).
pub(crate) fn surface_sources(material: &MeshMaterial, surface: SurfaceKind) -> Vec<Option<&std::path::PathBuf>> {
    surface.slots().iter().map(|slot| material.maps.get(slot)).collect()
}

/// The surfaces a material's maps make: the albedo (with its opacity), the packed metallic /
/// roughness / AO, the normal; only those with at least one map (the others stay the MTL's
/// constants).
pub(crate) fn material_surfaces(material: &MeshMaterial) -> Vec<SurfaceKind> {
    SurfaceKind::MATERIAL
        .into_iter()
        .filter(|&surface| surface_sources(material, surface).iter().any(Option::is_some))
        .collect()
}

/// One material a reduced level draws, and its maps.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct MaterialMaps {
    /// Its index among the source mesh's materials.
    pub material: u32,
    /// Its folder under the level's `materials/`: its name made safe for a path, and unique.
    pub folder: String,
    /// Each surface its maps make ([`material_surfaces`]), with how many times its stored side
    /// halves the side it is packed at (a level of its mip chain, `texture::mips::reduced_level`).
    pub surfaces: Vec<(SurfaceKind, u32)>,
}

/// The materials a reduced level draws (those its triangles use, in the source's order) and
/// their maps' sizes.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct ReducedMaps {
    pub materials: Vec<MaterialMaps>,
    /// The largest side a map may take ([`allot_maps`]).
    pub side: u32,
}

impl ReducedMaps {
    /// Every map surface of the level in slot `slot` and folder `folder`, with its halvings: a
    /// surface's group is `<folder>/materials/<material folder>`, its part the slot and the
    /// material's index among the source's.
    pub fn surfaces(&self, folder: &str, slot: u32) -> Vec<(SurfaceId, u32)> {
        let mut surfaces = Vec::new();
        for material in &self.materials {
            let group = format!("{folder}/{MATERIALS_FOLDER}/{}", material.folder);
            let part = SurfacePart { index: slot, item: Some(material.material) };
            for &(surface, halvings) in &material.surfaces {
                surfaces.push((SurfaceId { group: group.clone(), surface, part }, halvings));
            }
        }
        surfaces
    }

    /// The maps of material `material` (its index among the source's), if the level draws it.
    pub fn of_material(&self, material: u32) -> Option<&MaterialMaps> {
        self.materials.iter().find(|maps| maps.material == material)
    }

    /// The halvings of material `material`'s `surface`, if the level has that map.
    pub fn halvings(&self, material: u32, surface: SurfaceKind) -> Option<u32> {
        let maps = self.of_material(material)?;
        maps.surfaces.iter().find(|(kind, _)| *kind == surface).map(|&(_, halvings)| halvings)
    }

    /// Each triangle's material as the level's documents number them (its place among the used).
    pub fn triangle_materials(&self, source: &[u32]) -> Vec<u32> {
        let used: Vec<u32> = self.materials.iter().map(|material| material.material).collect();
        source.iter().map(|material| used.binary_search(material).unwrap_or(0) as u32).collect()
    }
}

/// Folder names for materials named `names`: each name's letters, digits, `-` and `_` (others
/// become `_`; an empty name `material`), with `_<index>` after a name an earlier one took.
pub(crate) fn material_folders(names: &[&str]) -> Vec<String> {
    let mut taken = std::collections::BTreeSet::new();
    names
        .iter()
        .enumerate()
        .map(|(index, name)| {
            let safe: String =
                name.chars().map(|c| if c.is_ascii_alphanumeric() || c == '-' || c == '_' { c } else { '_' }).collect();
            let safe = if safe.is_empty() { "material".to_string() } else { safe };
            let folder = if taken.contains(&safe) { format!("{safe}_{index}") } else { safe };
            taken.insert(folder.clone());
            folder
        })
        .collect()
}

/// The smallest side a reduced `Auto` candidate's maps are tried at.
const MIN_MAP_SIDE: u32 = 16;

/// How a reduced level's maps are sized: each material's `surfaces` with the size it is packed
/// at; the largest side any may take (`max_side`); an `Auto` candidate's bytes on the GPU left
/// beside its mesh (`bytes`, none elsewhere), `bytes_of` a `width` × `height` surface's.
pub(crate) struct MapSizing<'a> {
    pub surfaces: &'a [Vec<(SurfaceKind, (u32, u32))>],
    pub max_side: u32,
    pub bytes: Option<u64>,
}

/// The side of a reduced level's maps and each material surface's halvings ([`MapSizing`]):
/// every map at most `max_side`; with bytes, the largest power-of-two side (down to
/// [`MIN_MAP_SIDE`]) at which the albedos fit with the other surfaces up to four times smaller
/// (`levels::allot_surfaces`, as a candidate's atlas). None fit: the smallest, which the
/// candidate's bytes then report as over its budget.
pub(crate) fn allot_maps(
    sizing: &MapSizing,
    bytes_of: impl Fn(SurfaceKind, u32, u32) -> u64,
) -> (u32, Vec<Vec<(SurfaceKind, u32)>>) {
    let halvings_at = |size: (u32, u32), side: u32| {
        let largest = size.0.max(size.1);
        (0..32).find(|&halvings| largest >> halvings <= side.max(1)).unwrap_or(31)
    };
    let stored = |size: (u32, u32), halvings: u32| {
        let sizes = crate::texture::mips::chain_sizes(size.0, size.1);
        sizes[(halvings as usize).min(sizes.len() - 1)]
    };
    let at = |side: u32, levels: &levels::SurfaceHalvings| -> Vec<Vec<(SurfaceKind, u32)>> {
        sizing
            .surfaces
            .iter()
            .map(|surfaces| {
                surfaces
                    .iter()
                    .map(|&(surface, size)| (surface, halvings_at(size, side >> levels.of(surface))))
                    .collect()
            })
            .collect()
    };
    let kinds: Vec<SurfaceKind> = SurfaceKind::MATERIAL
        .into_iter()
        .filter(|kind| sizing.surfaces.iter().flatten().any(|(s, _)| s == kind))
        .collect();
    let Some(bytes) = sizing.bytes else { return (sizing.max_side, at(sizing.max_side, &Default::default())) };
    let bytes_at = |surface: SurfaceKind, side: u32| -> u64 {
        let surfaces = sizing.surfaces.iter().flatten().filter(|(kind, _)| *kind == surface);
        surfaces
            .map(|&(_, size)| {
                let (width, height) = stored(size, halvings_at(size, side));
                bytes_of(surface, width, height)
            })
            .sum()
    };
    let mut side = 1u32 << sizing.max_side.max(1).ilog2();
    loop {
        if let Some(levels) = levels::allot_surfaces(&kinds, side, u32::MAX, bytes_at, bytes) {
            return (side, at(side, &levels));
        }
        if side / 2 < MIN_MAP_SIDE {
            let smallest = levels::SurfaceHalvings { mra: 2, normal: 2, height: 2 };
            return (side, at(side, &smallest));
        }
        side /= 2;
    }
}

/// The mesh (OBJ and glTF geometry) and figures a reduced level's files are made of, its
/// glTF materials over its packed maps, each triangle's among them.
pub(crate) struct ReducedGltf {
    pub level: Arc<ReducedLevel>,
    pub materials: Vec<GltfMaterial>,
    pub triangle_materials: Vec<u32>,
}

impl ReducedGltf {
    pub fn mesh(&self) -> GltfMesh<'_> {
        GltfMesh {
            triangle_materials: &self.triangle_materials,
            ..self.level.geometry.mesh("reduced", &self.materials)
        }
    }
}

/// A reduced level's `lod.mtl` text and glTF materials: each used material of `materials` with
/// its constants over its packed maps in `materials/<folder>/` (`packed`: the stem of its mra
/// surface, `mra` or `orm`; glTF reads `orm.png`). The albedo carries the opacity in its alpha
/// (a cut-out's `map_d` names it too).
pub(crate) fn packed_materials(
    materials: &[MeshMaterial],
    maps: &ReducedMaps,
    packed: &str,
) -> (String, Vec<GltfMaterial>) {
    let mut mtl = String::from("# cirrus reduced level: maps packed and block-compressed (KTX2 beside each PNG)\n");
    let mut gltf = Vec::new();
    for material_maps in &maps.materials {
        let source = &materials[material_maps.material as usize];
        let has = |surface: SurfaceKind| material_maps.surfaces.iter().any(|(kind, _)| *kind == surface);
        let file = |stem: &str| format!("{MATERIALS_FOLDER}/{}/{stem}.png", material_maps.folder);
        let mut kept = MeshMaterial {
            maps: Default::default(),
            cut_out: source.cut_out || source.maps.contains_key(&TextureSlot::Opacity),
            map_options: Default::default(),
            ..source.clone()
        };
        let mut keep = |slot: TextureSlot, name: String| {
            if let Some(options) = source.map_options.get(&slot) {
                kept.map_options.insert(slot, options.clone());
            }
            kept.maps.insert(slot, name.into());
        };
        if has(SurfaceKind::Albedo) {
            keep(TextureSlot::Albedo, file("albedo"));
        }
        if has(SurfaceKind::Normal) {
            keep(TextureSlot::Normal, file("normal"));
        }
        if has(SurfaceKind::Mra) {
            keep(TextureSlot::Roughness, file(packed));
            keep(TextureSlot::Ao, file(packed));
        }
        mtl.push('\n');
        mtl.push_str(&crate::mesh::obj_text::mtl_material_text(&kept, |_, path| crate::diagnostic::display_path(path)));
        kept.maps.remove(&TextureSlot::Roughness);
        kept.maps.remove(&TextureSlot::Ao);
        let (mut material, _) =
            crate::mesh::gltf::material_from_mtl(&kept, |_, path| Some(crate::diagnostic::display_path(path)));
        if has(SurfaceKind::Mra) {
            // The packed image holds the constants where a map was missing.
            material.occlusion = Some(file("orm"));
            material.metallic_roughness = Some(file("orm"));
            (material.metallic_factor, material.roughness_factor) = (1.0, 1.0);
        }
        gltf.push(material);
    }
    (mtl, gltf)
}

/// What a reduced level drew, against its source.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub(crate) struct ReducedFigures {
    pub triangles: u64,
    pub vertices: u64,
    /// The simplifier's largest deviation, a fraction of the mesh's largest extent, and in
    /// world units.
    pub error: f32,
    pub error_world: f32,
    /// The source's leaf cards and those kept.
    pub cards: (u64, u64),
    /// The leaf area drawn (cut-out materials' triangles) in the source and the level.
    pub cut_out_area: (f64, f64),
}

/// A reduced level's `lod.obj` (`mtllib lod.mtl`), the geometry of its glTF (whose image names
/// the outputs give: copies of the maps, named by content) and its figures.
#[derive(Debug, PartialEq)]
pub(crate) struct ReducedLevel {
    pub obj: Arc<[u8]>,
    pub geometry: crate::mesh::gltf::GltfGeometry,
    pub figures: ReducedFigures,
}

/// `mesh` reduced to `budget` as a level's files.
pub(crate) fn reduce_level(mesh: &crate::mesh::Mesh, budget: crate::mesh::reduce::TriangleBudget) -> ReducedLevel {
    let settings = crate::mesh::reduce::ReduceSettings { budget, max_error: REDUCE_MAX_ERROR };
    let reduced = crate::mesh::reduce::reduce_mesh(mesh, &settings);
    let extent = crate::mesh::reduce::mesh_extent(&mesh.positions);
    let out = &reduced.mesh;
    let names: Vec<String> = out.materials.iter().map(|material| material.name.clone()).collect();
    let uvs = out.uvs.as_deref().unwrap_or(&[]);
    let obj = crate::mesh::obj_text::obj_text(
        &crate::mesh::obj_text::ObjMesh {
            positions: &out.positions,
            normals: &out.normals,
            uvs,
            triangles: &out.triangles,
            triangle_materials: &out.triangle_materials,
            material_names: &names,
        },
        &format!("reduced by cirrus (meshoptimizer): {} of {} triangles", out.triangles.len(), mesh.triangles.len()),
        "lod.mtl",
    );
    let geometry = crate::mesh::gltf::GltfGeometry {
        positions: out.positions.clone(),
        normals: out.normals.clone(),
        uvs: uvs.to_vec(),
        triangles: out.triangles.clone(),
        triangle_materials: out.triangle_materials.clone(),
        tangents: Vec::new(),
    }
    .with_tangents();
    let figures = ReducedFigures {
        triangles: out.triangles.len() as u64,
        vertices: out.positions.len() as u64,
        error: reduced.error,
        error_world: reduced.error * extent,
        cards: (reduced.cards.0 as u64, reduced.cards.1 as u64),
        cut_out_area: reduced.cut_out_area,
    };
    ReducedLevel { obj: obj.into_bytes().into(), geometry, figures }
}
