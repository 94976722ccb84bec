//! `cirrus preview` of an Atlas: each mesh it remapped, as an engine loads it (the OBJ under
//! `meshes/`, `atlas.mtl`, the page PNGs and whatever maps the MTL still names), beside the
//! source mesh with its own textures, from the 26 view directions (`crate::preview`). A remap
//! that samples the wrong texels (off its rectangle, a neighbour's leaves) or moves the alpha
//! test shows in the sheet and in the figures: the same mesh with the same texels scores an IoU
//! of 1.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::config::PipelineConfig;
use crate::db::{Asset, Db};
use crate::diagnostic::{display_path, Diagnostic};
use crate::gpu::ViewMesh;
use crate::kinds::{PreviewError, PreviewOptions, PreviewReport, PreviewRow};
use crate::texture::{Texture, TextureLimits, TextureSlot};

use super::queries::{atlas_mesh_files, remapped_mesh_file, remapped_mesh_path};

/// The alpha test of both renders: the usual cutoff of an OBJ's cut-out maps (an MTL has none
/// of its own; three.js's and glTF's `alphaCutoff` default is 0.5 too).
const ALPHA_CUTOFF: f32 = 0.5;

/// Renders every remapped mesh of the atlas `asset` beside its source; writes each one's sheet
/// and metrics to `<out>/<mesh path without .obj>/`.
pub(super) fn preview(
    db: &dyn Db,
    asset: Asset,
    config: &PipelineConfig,
    options: &PreviewOptions,
) -> Result<PreviewReport, PreviewError> {
    if options.lod.is_some() || options.stand_in != crate::kinds::billboard_cloud::lod_preview::StandIn::Baked {
        return Err(PreviewError::Option(format!(
            "asset `{}` is an Atlas: `--lod` and `--stand-in` are for BillboardCloud assets",
            options.asset
        )));
    }
    let meshes = atlas_mesh_files(db, asset);
    if meshes.is_empty() {
        return Err(PreviewError::Option(format!(
            "asset `{}` is an Atlas that remaps no mesh: its preview draws the meshes named by `meshes: [...]`",
            options.asset
        )));
    }
    let limits = config.limits.texture;
    let gpu = crate::gpu::gpu()?;
    let mut rows = Vec::new();
    for mesh in meshes {
        let relative = remapped_mesh_path(db, asset, mesh);
        let remapped_obj = config.output.join(&options.asset).join(remapped_mesh_file(db, asset, mesh));
        let source =
            mesh_view_from_files(&config.root, mesh, &config.source, limits).map_err(PreviewError::Artifact)?;
        // The remapped mesh may name anything inside the project, as an engine would read it.
        let remapped =
            mesh_view_from_files(&config.root, &remapped_obj, Path::new(""), limits).map_err(PreviewError::Artifact)?;
        let (center, radius) = crate::preview::bounding_sphere(&source);
        let mut compared = crate::preview::preview_chain(gpu, &source, &[&remapped], center, radius, options.settings)?;
        let compared = compared.levels.remove(0);
        let folder = options.out.join(relative.with_extension(""));
        crate::kinds::write_preview(&config.root.join(&folder), &compared)?;
        rows.push(PreviewRow {
            label: Some(format!("{} remapped", display_path(&relative))),
            metrics: compared.metrics,
            folder,
        });
    }
    Ok(PreviewReport { rows, chain_sheet: None })
}

/// The OBJ at `obj` (project-relative) with the MTL files and maps it names, read from under
/// `root` as an engine reads them; paths must stay inside `source_root`.
fn mesh_view_from_files(
    root: &Path,
    obj: &Path,
    source_root: &Path,
    limits: TextureLimits,
) -> Result<ViewMesh, Diagnostic> {
    let read = |path: &Path| {
        crate::files::read_regular_file(&root.join(path), crate::files::MAX_SOURCE_BYTES)
            .map_err(|error| Diagnostic::new(path, format!("cannot read: {error}")))
    };
    let bytes = read(obj)?;
    let libraries: BTreeMap<PathBuf, Option<Vec<u8>>> = crate::mesh::material_libraries(obj, &bytes, source_root)
        .into_iter()
        .map(|path| {
            let bytes = read(&path).ok();
            (path, bytes)
        })
        .collect();
    let (mesh, _) = crate::mesh::load_mesh(obj, &bytes, &libraries, source_root)?;
    let uvs = mesh.uvs.as_deref().unwrap_or(&[]);
    let tangents = crate::mesh::vertex_tangents(&mesh.positions, &mesh.normals, uvs, &mesh.triangles);
    // Each file decoded once (a page is a material's albedo and opacity, and several materials').
    let decoded: std::cell::RefCell<BTreeMap<PathBuf, Arc<Texture>>> = Default::default();
    crate::preview::mesh_view(&mesh, &tangents, ALPHA_CUTOFF, |material, slot| {
        let Some(path) = material.maps.get(&slot).filter(|_| mesh.uvs.is_some()) else { return Ok(None) };
        let known = decoded.borrow().get(path).cloned();
        let texture = match known {
            Some(texture) => texture,
            None => Arc::new(crate::texture::decode_texture(path, &read(path)?, limits)?),
        };
        decoded.borrow_mut().insert(path.clone(), texture.clone());
        Ok(Some(match slot {
            TextureSlot::Opacity => Arc::new(crate::texture::opacity_channel(&texture)),
            _ => texture,
        }))
    })
}
