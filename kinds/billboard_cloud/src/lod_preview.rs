//! The billboard cloud's side of `cirrus preview`: what stands for the source beside it (the
//! baked LOD as an engine loads it, or the source's faces moved onto the cloud's planes). The
//! rendering and the comparison are `crate::preview`'s.

use glam::Vec3;

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::Arc;

use crate::diagnostic::Diagnostic;
use crate::gpu::{ViewMaterial, ViewMesh};
use crate::texture::Texture;

/// What stands beside the source (defined with the preview's options, which every kind reads).
pub use crate::kinds::StandIn;

/// Where `stand_in` draws corner `corner` of the face `corners` whose plane is the points `x`
/// with `normal · x = distance` (`Baked` and a face without a plane: where it is).
pub fn stand_in_position(
    stand_in: StandIn,
    corners: [[f32; 3]; 3],
    corner: usize,
    plane: Option<([f32; 3], f32)>,
) -> [f32; 3] {
    let Some((normal, distance)) = plane else { return corners[corner] };
    let normal = Vec3::from(normal);
    let point = Vec3::from(corners[corner]);
    let offset = |point: Vec3| point.dot(normal) - distance;
    let moved = match stand_in {
        StandIn::Baked => point,
        StandIn::Projected => point - offset(point) * normal,
        StandIn::Translated => {
            point - corners.iter().map(|&corner| offset(Vec3::from(corner))).sum::<f32>() / 3.0 * normal
        }
    };
    moved.to_array()
}

/// The files of a baked LOD, each with its path (for messages) and bytes.
pub struct LodFiles {
    pub obj: (PathBuf, Vec<u8>),
    /// The albedo and normal textures, in any container cirrus writes.
    pub albedo_ktx2: (PathBuf, Vec<u8>),
    pub normal_ktx2: (PathBuf, Vec<u8>),
    pub alpha_cutoff: f32,
}

/// The baked LOD as an engine sees it: `lod.obj` with the decoded KTX2 atlas levels (BC-decoded,
/// so renders show the compression), alpha-tested and double-sided.
pub fn lod_view_mesh(files: &LodFiles) -> Result<ViewMesh, Diagnostic> {
    let (obj_path, obj_bytes) = &files.obj;
    let folder = obj_path.parent().map(PathBuf::from).unwrap_or_default();
    let (mesh, _) = crate::mesh::load_mesh(obj_path, obj_bytes, &BTreeMap::new(), &folder)?;
    let decode = |(path, bytes): &(PathBuf, Vec<u8>)| crate::texture::quality::decoded_container_levels(path, bytes);
    // BC5 holds X and Y only; the shader rebuilds Z from them.
    let normal = decode(&files.normal_ktx2)?
        .into_iter()
        .map(|level| {
            let pixels: Vec<u8> = level.pixels.chunks_exact(4).flat_map(|texel| [texel[0], texel[1], 0, 255]).collect();
            Texture::new(level.width, level.height, pixels)
        })
        .collect();
    let material = ViewMaterial {
        albedo: Some(Arc::new(decode(&files.albedo_ktx2)?)),
        opacity: None,
        normal: Some(Arc::new(normal)),
        normal_has_z: false,
        albedo_factor: [1.0; 4],
        alpha_cutoff: files.alpha_cutoff,
    };
    let uvs = mesh.uvs.as_deref().unwrap_or(&[]);
    let tangents = crate::mesh::vertex_tangents(&mesh.positions, &mesh.normals, uvs, &mesh.triangles);
    // Loaded without its MTL, every face has the default material, 0: the one view material.
    let batches = crate::gpu::face_batches(&mesh, &tangents, 0..mesh.triangles.len() as u32);
    Ok(ViewMesh { batches, materials: vec![material] })
}
