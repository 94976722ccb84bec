//! A LOD chain's impostor levels (`lods: [..., Impostor(frames: 8, hemi: true, size: 1024)]`):
//! the mesh's frames (`impostor::bake_impostor`, stage `impostor`) as three surfaces through the
//! texture tail (`albedo`, `normal` in each frame's axes, `height` holding the depth), described
//! in `impostor.json` for engines and drawn by `shaders/impostor.wgsl`; `lod.gltf` carries one
//! quad showing the front frame (for a loader without the shader) with the description in the
//! mesh's `extras`. Reading a level back as an engine does (`read_impostor_view`) serves the
//! preview and the viewer.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::levels;
use super::queries::{level_label, IMPOSTOR};
use super::report::{ImpostorFigures, LevelDetail, LevelFigures, LevelReport, Representation, Side, SurfaceFigures};
use crate::db::{Asset, Db};
use crate::diagnostic::Diagnostic;
use crate::kinds::mesh_queries::mesh_textures;
use crate::kinds::{AssetOutputs, StageInstance};
use crate::mesh::gltf::{GltfAlpha, GltfMaterial, GltfMesh, GltfWrap};
use crate::mesh::octahedral::FrameGrid;
use crate::summary::ArtifactRole;
use crate::texture::Texture;

/// The description of an impostor level an engine reads (`impostor.json`, and the `extras` of
/// its `lod.gltf` mesh as `cirrus_impostor`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImpostorDescription {
    /// The shader that draws it (its functions are the reference for engine ports).
    pub shader: String,
    /// Frames a side; frame `j · frames + i` is at column `i`, row `j` of every atlas, seen
    /// from `impostor_decode(vec2(i, j) / (frames − 1), hemi)`.
    pub frames: u32,
    /// The upper half of the sphere (views from below use the horizon's frames), else all of it.
    pub hemi: bool,
    /// Each frame's side in texels; the albedo atlas is `frames · frame_size` a side, the normal
    /// and depth atlases that or a half or a quarter of it (as their files say: a level of the
    /// same frames' mip chain, sampled with the same coordinates and the mip level offset by
    /// the ratio of the sides).
    pub frame_size: u32,
    /// The bounding sphere each frame shows, filling it.
    pub center: [f32; 3],
    pub radius: f32,
    pub alpha_cutoff: f32,
    /// The atlases, relative to this file: albedo (sRGB, coverage in alpha), the normal in the
    /// frame's axes (x right, y up, z towards the frame's eye, rebuilt from x and y) and the depth
    /// (0 at the sphere's near side, 1 at its far side, in the red channel).
    pub albedo: String,
    pub normal: String,
    pub depth: String,
    /// The part `[u0, v0, u1, v1]` of the sphere's image each frame shows (u along the frame's
    /// right, v down its up axis, 0 to 1 across the sphere): the mesh's bounds from the frame's
    /// direction, so the mesh fills the frame. Absent: every frame shows the whole sphere.
    #[serde(default)]
    pub frame_rects: Vec<[f32; 4]>,
    /// The polygon to draw instead of the sphere's square (`impostor::view_hull`): eight points
    /// `[x, y]`, counter-clockwise (some may coincide), in the view's right and up axes through
    /// the centre, in units of the radius; drawn as a fan (0, k, k + 1). It holds the mesh's
    /// outline from every direction, so it cuts overdraw, not the impostor. Absent: the square.
    #[serde(default)]
    pub hull: Vec<[f32; 2]>,
}

impl ImpostorDescription {
    /// The frame grid it describes.
    pub fn grid(&self) -> FrameGrid {
        FrameGrid::new(self.frames, self.hemi)
    }
}

/// An impostor level's `impostor` stage instance: it reads the mesh stage and every texture the
/// materials name (their decodes, added to `decodes`) and writes the level's description and
/// quad; the level's surfaces read it.
pub(crate) fn impostor_instance(
    db: &dyn Db,
    asset: Asset,
    level: u32,
    (output_folder, mesh): (&Path, &StageInstance),
    decodes: &mut std::collections::BTreeMap<String, StageInstance>,
) -> StageInstance {
    let folder = levels::level_folder(asset.settings(db), level);
    let mut impostor = StageInstance::new(IMPOSTOR, level_label(db, asset, level), &folder).reads_stage(mesh);
    impostor.writes = IMPOSTOR_FILES.map(|file| output_folder.join(&folder).join(file)).to_vec();
    // Frames reduced from another level's read that level's render.
    if let Some(render) = super::queries::impostor_render(db, asset, level).filter(|render| render.source != level) {
        impostor.reads.push(crate::kinds::Read::Stage(IMPOSTOR, level_label(db, asset, render.source).clone()));
    }
    for path in mesh_textures(db, asset).iter() {
        super::surfaces::read_decode(&mut impostor, path, decodes);
    }
    impostor
}

/// The files an impostor level writes beside its surfaces' textures.
const IMPOSTOR_FILES: [&str; 3] = ["impostor.json", "lod.gltf", "lod.bin"];

/// An impostor level's quad as the chain's document draws it.
pub(crate) struct ImpostorGltf {
    positions: Vec<[f32; 3]>,
    uvs: Vec<[f32; 2]>,
    material: GltfMaterial,
    extras: serde_json::Value,
}

impl ImpostorGltf {
    pub fn mesh(&self) -> GltfMesh<'_> {
        GltfMesh {
            name: "impostor",
            positions: &self.positions,
            normals: &[[0.0, 0.0, 1.0]; 4],
            tangents: &[[1.0, 0.0, 0.0, 1.0]; 4],
            uvs: &self.uvs,
            triangles: &[[0, 1, 2], [0, 2, 3]],
            triangle_materials: &[],
            materials: std::slice::from_ref(&self.material),
            extras: Some(&self.extras),
        }
    }
}

/// The frame seen from closest to +Z (the front), on `grid`.
fn front_frame(grid: FrameGrid) -> u32 {
    (0..grid.frame_count())
        .max_by(|&a, &b| grid.frame_direction(a).z.total_cmp(&grid.frame_direction(b).z))
        .unwrap_or(0)
}

/// The quad of an impostor described by `description`: the bounding sphere's square facing +Z
/// through its centre, showing the front frame of the atlases `images` (albedo and normal, as the
/// tail's previews name them).
fn impostor_gltf(description: &ImpostorDescription, images: [Option<String>; 2]) -> ImpostorGltf {
    let grid = description.grid();
    let frame = front_frame(grid);
    let frames = grid.frames as f32;
    let (column, row) = ((frame % grid.frames) as f32, (frame / grid.frames) as f32);
    // OBJ's convention (origin bottom left): the frame's image rows run down.
    let (u0, u1, v0, v1) = (column / frames, (column + 1.0) / frames, 1.0 - (row + 1.0) / frames, 1.0 - row / frames);
    let ([x, y, z], r) = (description.center, description.radius);
    let [albedo, normal] = images;
    ImpostorGltf {
        positions: vec![[x - r, y - r, z], [x + r, y - r, z], [x + r, y + r, z], [x - r, y + r, z]],
        uvs: vec![[u0, v0], [u1, v0], [u1, v1], [u0, v1]],
        material: GltfMaterial {
            name: "impostor".into(),
            base_colour_factor: [1.0; 4],
            metallic_factor: 0.0,
            roughness_factor: 1.0,
            base_colour: albedo,
            normal,
            occlusion: None,
            metallic_roughness: None,
            alpha: GltfAlpha::Mask(description.alpha_cutoff),
            double_sided: true,
            wrap: GltfWrap::Clamp,
        },
        // Read back from its JSON, so that its numbers are written as `impostor.json` has them.
        extras: serde_json::json!({
            "cirrus_impostor": serde_json::to_string(description)
                .ok()
                .and_then(|text| serde_json::from_str::<serde_json::Value>(&text).ok())
        }),
    }
}

/// An impostor level's files (added to `outputs`), its part of the report, and its quad for the
/// chain's document.
pub(super) fn impostor_level_outputs(
    db: &dyn Db,
    asset: Asset,
    level: u32,
    output_folder: &Path,
    outputs: &mut AssetOutputs,
) -> Result<(LevelReport, ImpostorGltf), Diagnostic> {
    let settings = asset.settings(db);
    let folder = levels::level_folder(settings, level);
    let level_folder = output_folder.join(&folder);
    let Some(impostor) = levels::settings_for(settings, level).impostor else {
        return Err(Diagnostic::new(asset.main_file(db), format!("lod{level} is not an impostor level")));
    };
    let loaded = crate::kinds::mesh_queries::loaded_mesh(db, asset)?;
    let (center, radius) = super::planes::bounding_sphere(&loaded.mesh.positions);
    let side = impostor.grid.frames * impostor.frame_size;
    let corners: Vec<glam::Vec3> = loaded
        .mesh
        .triangles
        .iter()
        .flat_map(|triangle| triangle.map(|corner| glam::Vec3::from(loaded.mesh.positions[corner as usize])))
        .collect();
    let margin_frame =
        super::queries::impostor_render(db, asset, level).map_or(impostor.frame_size, |render| render.margin_frame);
    let frame_rects = crate::impostor::frame_rects_with_margin(&corners, (center, radius), impostor.grid, margin_frame);
    let written = super::surfaces::write_level_surfaces(db, asset, level, output_folder, outputs)?;
    let (mut bytes, mut gpu_bytes) = (written.bytes, written.gpu_bytes);
    let name = |index: usize| written.names.get(index).cloned().unwrap_or_default();
    let [(albedo, albedo_png), (normal, normal_png), (depth, _)] = [0, 1, 2].map(name);
    let description = ImpostorDescription {
        shader: "shaders/impostor.wgsl".into(),
        frames: impostor.grid.frames,
        hemi: impostor.grid.is_hemi(),
        frame_size: impostor.frame_size,
        center: center.to_array(),
        radius,
        alpha_cutoff: super::queries::billboard_alpha_cutoff(db, asset),
        albedo,
        normal,
        depth,
        frame_rects,
        hull: super::queries::impostor_hull(db, asset)?.to_vec(),
    };
    let json = serde_json::to_vec_pretty(&description).expect("descriptions serialise");
    let quad = impostor_gltf(&description, [Some(albedo_png), Some(normal_png)]);
    let gltf = crate::mesh::gltf::gltf_files(&quad.mesh(), "lod.bin", crate::mesh::gltf::GENERATOR);
    gpu_bytes += gltf.bin.len() as u64;
    bytes += json.len() + gltf.bin.len();
    outputs.add(level_folder.join("impostor.json"), ArtifactRole::Table, json.into());
    outputs.add(level_folder.join("lod.gltf"), ArtifactRole::Gltf, gltf.gltf.into());
    outputs.add(level_folder.join("lod.bin"), ArtifactRole::GltfBuffer, gltf.bin.into());
    let detail = ImpostorFigures {
        frames: impostor.grid.frames,
        hemi: impostor.grid.is_hemi(),
        frame_size: impostor.frame_size,
        atlas: Side { width: side, height: side },
    };
    let figures = LevelFigures {
        representation: Representation::Impostor,
        // The shader draws the hull as a fan of six (the glTF's quad, for loaders without it: 2).
        triangles: 6,
        // The bytes an engine loads: the three textures, the description and the quad's buffer.
        bytes: bytes as u64,
        gpu_bytes,
        surfaces: SurfaceFigures::of(written.infos),
        detail: LevelDetail::Impostor(detail),
    };
    let report = LevelReport::new(level, folder, figures);
    Ok((report, quad))
}

/// The impostor level baked into `folder` of `files` as an engine draws it: its description and
/// the decoded levels of its three KTX2 textures (BC-decoded, so that renders show the
/// compression).
pub(crate) fn read_impostor_view(
    files: &crate::kinds::BakedFiles,
    folder: &Path,
) -> Result<crate::gpu::ImpostorDraw, Diagnostic> {
    let read = |file: &str| -> Result<(PathBuf, Vec<u8>), Diagnostic> {
        let path = folder.join(file);
        let bytes = files.read(&path)?;
        Ok((path, bytes))
    };
    let (path, json) = read("impostor.json")?;
    let description: ImpostorDescription = serde_json::from_slice(&json).map_err(|error| {
        let position = crate::diagnostic::TextPosition { line: error.line() as u32, column: error.column() as u32 };
        Diagnostic::at(&path, position, format!("not an impostor description: {error}"))
    })?;
    let grid = description.grid();
    if !(2..=super::settings::MAX_IMPOSTOR_FRAMES).contains(&grid.frames) {
        return Err(Diagnostic::new(
            &path,
            format!("{} frames a side: an impostor has 2 to {}", grid.frames, super::settings::MAX_IMPOSTOR_FRAMES),
        ));
    }
    let rects = &description.frame_rects;
    let inside = |rect: &[f32; 4]| {
        rect.iter().all(|value| (0.0..=1.0).contains(value)) && rect[0] < rect[2] && rect[1] < rect[3]
    };
    if !rects.is_empty() && (rects.len() != grid.frame_count() as usize || !rects.iter().all(inside)) {
        return Err(Diagnostic::new(
            &path,
            format!(
                "`frame_rects` needs one [u0, v0, u1, v1] within 0..1 (u0 < u1, v0 < v1) for each of the {} frames",
                grid.frame_count()
            ),
        ));
    }
    let hull = &description.hull;
    if !hull.is_empty() && (hull.len() != 8 || !hull.iter().flatten().all(|value| (-1.0..=1.0).contains(value))) {
        return Err(Diagnostic::new(&path, "`hull` needs eight [x, y] points within -1..1 (or none: the square)"));
    }
    let mut textures = Vec::new();
    for name in [&description.albedo, &description.normal, &description.depth] {
        if Path::new(name).components().count() != 1 {
            return Err(Diagnostic::new(&path, format!("`{name}`: an impostor's textures lie beside its description")));
        }
        let (texture_path, bytes) = read(name)?;
        let levels = crate::texture::quality::decoded_container_levels(&texture_path, &bytes)?;
        // The albedo at the frames' size; the normal and depth at it or halved up to twice.
        let side = grid.frames * description.frame_size;
        let sides: Vec<u32> = match name == &description.albedo {
            true => vec![side],
            false => (0..=2).map(|halvings| side >> halvings).filter(|&side| side >= grid.frames).collect(),
        };
        let fits = |level: &Texture| {
            level.width == level.height && sides.contains(&level.width) && level.width.is_multiple_of(grid.frames)
        };
        if !levels.first().is_some_and(fits) {
            let sizes = sides.iter().map(|side| format!("{side}²")).collect::<Vec<_>>().join(", ");
            return Err(Diagnostic::new(
                &texture_path,
                format!("{} frames of {} texels need a texture of {sizes}", grid.frames, description.frame_size),
            ));
        }
        textures.push(levels);
    }
    let [albedo, normal, depth]: [Vec<Texture>; 3] = textures.try_into().expect("three textures");
    Ok(crate::gpu::ImpostorDraw {
        grid,
        albedo,
        normal,
        depth,
        center: description.center,
        radius: description.radius,
        alpha_cutoff: description.alpha_cutoff,
        rects: description.frame_rects,
        hull: description.hull.try_into().ok(),
    })
}
