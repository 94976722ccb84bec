//! Per-plane textures: how a plane's rectangles split into render stages (by the materials
//! their faces use), what one rectangle's render is made of (its faces, grouped by material, as
//! vertices with normals, UVs and tangents) and which source textures it reads. The rendering
//! itself is `gpu::Gpu::render_rectangles`.

use std::collections::BTreeMap;

use crate::mesh::Mesh;
use crate::rectangles::PlaneRectangle;

/// Samples per texel along each axis of the plane renders: two, brought down with a
/// distance-field alpha, put cut-out edges between texels where the samples put them (at 256
/// quads, mean IoU: oak 0.896 → 0.904, ash 0.808 → 0.829, bush 0.852 → 0.857).
pub(crate) const PLANE_SUPERSAMPLING: u32 = 2;

/// The largest side a supersampled render may have: WebGPU's guaranteed texture size, so that
/// every adapter renders the same; a larger rectangle renders one sample per texel.
pub(crate) const MAX_SUPERSAMPLED_SIDE: u32 = 8192;

/// The supersampling of a rectangle of `width` × `height` texels.
pub(crate) fn plane_supersampling(width: u32, height: u32) -> u32 {
    if width.max(height).max(1).saturating_mul(PLANE_SUPERSAMPLING) <= MAX_SUPERSAMPLED_SIDE {
        PLANE_SUPERSAMPLING
    } else {
        1
    }
}

/// The materials a rectangle's faces use, in index order.
pub(crate) fn plane_materials(mesh: &Mesh, plane: &PlaneRectangle) -> Vec<u32> {
    crate::planes::materials_of_faces(&plane.faces, &mesh.triangle_materials)
}

/// One render stage: the rectangles of one plane whose faces use the same set of materials, so
/// that an edit of one material's texture re-renders only the rectangles that show it.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RenderGroup {
    pub plane: u32,
    /// Material indices, ascending.
    pub materials: Vec<u32>,
    /// Rectangle indices, ascending.
    pub rectangles: Vec<u32>,
}

/// The render groups of `rectangles` (which come plane by plane): per plane, one group per
/// distinct material set, in order of each set's first rectangle.
pub fn render_groups(mesh: &Mesh, rectangles: &[PlaneRectangle]) -> Vec<RenderGroup> {
    let mut groups: Vec<RenderGroup> = Vec::new();
    let mut plane_start = 0;
    for (index, rectangle) in rectangles.iter().enumerate() {
        if groups.last().is_some_and(|group| group.plane != rectangle.plane) {
            plane_start = groups.len();
        }
        let materials = plane_materials(mesh, rectangle);
        match groups[plane_start..].iter_mut().find(|group| group.materials == materials) {
            Some(group) => group.rectangles.push(index as u32),
            None => groups.push(RenderGroup { plane: rectangle.plane, materials, rectangles: vec![index as u32] }),
        }
    }
    groups
}

/// The most texels of one render batch: a few submissions per level instead of one per render
/// group (on llvmpipe each submission costs about a millisecond whatever its size, and the oak
/// has 1,245 groups), small enough that two workers share a level's renders evenly.
pub(crate) const RENDER_BATCH_TEXELS: u64 = 1 << 19;

/// The render groups in batches rendered together: groups of one material set (so that an edit
/// of a material's texture re-renders only batches of groups that show it), in layout order,
/// each batch up to [`RENDER_BATCH_TEXELS`] (a larger group is a batch alone). `texels(group)`
/// is the group's size in texels.
pub(crate) fn render_batches(groups: &[RenderGroup], texels: impl Fn(&RenderGroup) -> u64) -> Vec<Vec<u32>> {
    let mut open: BTreeMap<&[u32], (Vec<u32>, u64)> = BTreeMap::new();
    let mut batches: Vec<Vec<u32>> = Vec::new();
    for (index, group) in groups.iter().enumerate() {
        let size = texels(group);
        let (batch, batch_texels) = open.entry(group.materials.as_slice()).or_default();
        if !batch.is_empty() && *batch_texels + size > RENDER_BATCH_TEXELS {
            batches.push(std::mem::take(batch));
            *batch_texels = 0;
        }
        batch.push(index as u32);
        *batch_texels += size;
    }
    batches.extend(open.into_values().map(|(batch, _)| batch).filter(|batch| !batch.is_empty()));
    batches.sort_by_key(|batch| batch[0]);
    batches
}

/// A render group's name in logs, summaries and the graph: `plane12:bark+leaves`.
pub fn render_group_label(mesh: &Mesh, group: &RenderGroup) -> String {
    let names: Vec<&str> =
        group.materials.iter().map(|&material| mesh.materials[material as usize].name.as_str()).collect();
    format!("plane{}:{}", group.plane, names.join("+"))
}
