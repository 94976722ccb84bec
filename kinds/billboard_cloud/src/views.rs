//! A baked billboard-cloud level read back as an engine draws it (from the disk or from a
//! build's outputs): an impostor through `impostor.json`, a cloud's `lod.obj` with its decoded
//! atlas, a reduced level's `lod.obj` with its maps. The preview, the viewer and the chain's
//! switch measurements draw what these return.

use std::path::{Path, PathBuf};

use super::{impostor_level, lod_mesh, lod_preview};
use crate::diagnostic::Diagnostic;
use crate::kinds::BakedFiles;

/// The baked LOD in `folder` (relative to `root`) as an engine draws it: an impostor through
/// `impostor.json` (`impostor_level::read_impostor_view`), else the level's mesh
/// (`read_lod_view_mesh`).
pub fn read_level_view(root: &Path, folder: &Path, alpha_cutoff: f32) -> Result<crate::gpu::LevelView, Diagnostic> {
    level_view(&BakedFiles::Disk(root), folder, alpha_cutoff)
}

/// The LOD in `folder` of `files` as an engine draws it (see [`read_level_view`]).
pub(crate) fn level_view(
    files: &BakedFiles,
    folder: &Path,
    alpha_cutoff: f32,
) -> Result<crate::gpu::LevelView, Diagnostic> {
    if files.exists(&folder.join("impostor.json")) {
        return impostor_level::read_impostor_view(files, folder).map(crate::gpu::LevelView::Impostor);
    }
    read_lod_view_mesh(files, folder, alpha_cutoff).map(crate::gpu::LevelView::Mesh)
}

/// The baked LOD mesh in `folder` of `files` as an engine loads it: a billboard cloud's
/// `lod.obj` with the decoded levels of `albedo.ktx2` and `normal.ktx2`, alpha-tested at
/// `alpha_cutoff`; a reduced level's `lod.obj` with its `lod.mtl` and the maps that names (in
/// its `materials/`, each read from its BC-decoded KTX2), alpha-tested at `alpha_cutoff`.
fn read_lod_view_mesh(
    files: &BakedFiles,
    folder: &Path,
    alpha_cutoff: f32,
) -> Result<crate::gpu::ViewMesh, Diagnostic> {
    let read = |file: &str| -> Result<(PathBuf, Vec<u8>), Diagnostic> {
        let path = folder.join(file);
        let bytes = files.read(&path)?;
        Ok((path, bytes))
    };
    let obj = read("lod.obj")?;
    if !obj.1.starts_with(lod_mesh::CLOUD_HEADER.as_bytes()) {
        let limits = crate::texture::TextureLimits::default();
        let maps = crate::kinds::MapFiles::BlockCompressedTwins;
        return crate::kinds::mesh_view_from_files(files, &obj.0, (folder, limits), (alpha_cutoff, maps));
    }
    lod_preview::lod_view_mesh(&lod_preview::LodFiles {
        obj,
        albedo_ktx2: read(&texture_file(files, folder, "albedo"))?,
        normal_ktx2: read(&texture_file(files, folder, "normal"))?,
        alpha_cutoff,
    })
}

/// The name of the texture `stem` in `folder` of `files`, in whichever container the build
/// wrote it (KTX2 when there is none, for the message).
fn texture_file(files: &BakedFiles, folder: &Path, stem: &str) -> String {
    let names = ["ktx2", "dds", "pvr"].map(|extension| format!("{stem}.{extension}"));
    names.iter().find(|name| files.exists(&folder.join(name))).cloned().unwrap_or_else(|| names[0].clone())
}
