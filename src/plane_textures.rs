//! Per-plane textures: what one plane's render is made of (its faces, grouped by material, as
//! vertices with normals, UVs and tangents) and which source textures it reads. The rendering
//! itself is `gpu::Gpu::render_rectangles`.

use std::collections::BTreeMap;
use std::path::PathBuf;

use crate::gpu::RenderVertex;
use crate::mesh::Mesh;
use crate::rectangles::PlaneRectangle;

/// The materials a rectangle's faces use, in index order.
pub fn plane_materials(mesh: &Mesh, plane: &PlaneRectangle) -> Vec<u32> {
    let mut materials: Vec<u32> = plane.faces.iter().map(|&face| mesh.triangle_materials[face as usize]).collect();
    materials.sort_unstable();
    materials.dedup();
    materials
}

/// The texture files a plane's render reads: the maps of the materials its faces use.
pub fn plane_texture_paths(mesh: &Mesh, plane: &PlaneRectangle) -> Vec<PathBuf> {
    if mesh.uvs.is_none() {
        return Vec::new();
    }
    let mut paths: Vec<PathBuf> =
        plane_materials(mesh, plane).iter().flat_map(|&material| mesh.materials[material as usize].maps.values().cloned()).collect();
    paths.sort();
    paths.dedup();
    paths
}

/// The plane's faces as vertex batches per material (three vertices per triangle).
pub fn plane_batches(mesh: &Mesh, tangents: &[[f32; 4]], plane: &PlaneRectangle) -> Vec<(usize, Vec<RenderVertex>)> {
    let mut batches: BTreeMap<usize, Vec<RenderVertex>> = BTreeMap::new();
    for &face in &plane.faces {
        let material = mesh.triangle_materials[face as usize] as usize;
        let batch = batches.entry(material).or_default();
        for vertex in mesh.triangles[face as usize] {
            let vertex = vertex as usize;
            batch.push(RenderVertex {
                position: mesh.positions[vertex],
                normal: mesh.normals[vertex],
                uv: mesh.uvs.as_ref().map_or([0.0, 0.0], |uvs| uvs[vertex]),
                tangent: tangents.get(vertex).copied().unwrap_or([1.0, 0.0, 0.0, 1.0]),
            });
        }
    }
    batches.into_iter().collect()
}
