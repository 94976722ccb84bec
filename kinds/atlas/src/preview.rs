//! `cirrus preview` of an Atlas: each mesh it remapped, as an engine loads it (the OBJ under
//! `meshes/`, `atlas.mtl`, the page PNGs and whatever maps the MTL still names), beside the
//! source mesh with its own textures, from the 26 view directions (`crate::preview`). A remap
//! that samples the wrong texels (off its rectangle, a neighbour's leaves) or moves the alpha
//! test shows in the sheet and in the figures: the same mesh with the same texels scores an IoU
//! of 1.

use std::path::Path;

use crate::config::PipelineConfig;
use crate::db::{Asset, Db};
use crate::diagnostic::display_path;
use crate::kinds::{mesh_view_from_files, BakedFiles, PreviewError, PreviewOptions, PreviewReport, PreviewRow};

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
    if options.lod.is_some() || options.stand_in != crate::kinds::StandIn::Baked {
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
        let source = mesh_view_from_files(
            &BakedFiles::Disk(&config.root),
            mesh,
            (&config.source, limits),
            (ALPHA_CUTOFF, crate::kinds::MapFiles::AsNamed),
        )
        .map_err(PreviewError::Artifact)?;
        // The remapped mesh may name anything inside the project, as an engine would read it.
        let remapped = mesh_view_from_files(
            &BakedFiles::Disk(&config.root),
            &remapped_obj,
            (Path::new(""), limits),
            (ALPHA_CUTOFF, crate::kinds::MapFiles::AsNamed),
        )
        .map_err(PreviewError::Artifact)?;
        let (center, radius) = cirrus_core::preview::bounding_sphere(&source);
        let remapped = crate::gpu::LevelView::Mesh(remapped);
        let mut compared =
            cirrus_core::preview::preview_chain(gpu, &source, &[&remapped], center, radius, options.settings)?;
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
