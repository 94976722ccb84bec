//! Triangle LODs: a mesh brought under a triangle budget by meshoptimizer's attribute-aware
//! simplifier (normals and UVs weighed, material and object borders locked), with foliage cards
//! thinned as whole cards, the largest kept, and the kept ones grown toward the leaf area
//! drawn, instead of each card collapsing on its own (meshoptimizer's issue #1093).

use std::collections::BTreeMap;

use glam::Vec3;
use meshopt::{SimplifyOptions, SimplifyVertex, VertexDataAdapter};

use super::{position_ids, union_find_root, Mesh};

/// How many triangles a reduced mesh may have.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum TriangleBudget {
    /// At most this many.
    Triangles(u32),
    /// At most this fraction of the source's (rounded down, but at least one).
    Ratio(f32),
}

/// How a mesh is reduced.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReduceSettings {
    pub budget: TriangleBudget,
    /// The deviation (a fraction of the mesh's largest extent) up to which the simplifier
    /// prefers stopping to reaching the budget; past it the budget wins.
    pub max_error: f32,
}

/// Connected parts of cut-out materials with at most this many triangles are cards (leaves,
/// fronds, grass blades): thinned as whole cards, not collapsed.
pub const CARD_TRIANGLES: usize = 8;

/// A kept card grows at most this much along each side (four times its area).
pub const MAX_CARD_GROWTH: f32 = 2.0;

/// Kept cards grow along each side by (all cards' area / kept cards' area) to this power: 0.5
/// would keep the leaf area drawn, but cards overlap, so the silhouette shrinks less than the
/// area and cards grown that much stick out of it. Measured on the bundled bush at 128 px, 26
/// views (loss in px-shift units at 0.5 / 0.25 / 0.1 of the triangles): power 0, no growth,
/// 0.37 / 1.08 / 2.00; 0.25: 0.47 / 1.11 / 1.80; 0.5: 0.58 / 1.18 / 1.65.
pub const CARD_GROWTH_EXPONENT: f64 = 0.25;

/// A mesh under its budget and what it kept.
#[derive(Clone, Debug, PartialEq)]
pub struct ReducedMesh {
    pub mesh: Mesh,
    /// The simplifier's largest deviation, as a fraction of the mesh's largest extent (0 when
    /// nothing but cards was reduced).
    pub error: f32,
    /// The cards of the source and those kept.
    pub cards: (usize, usize),
    /// The area of the cut-out materials' triangles (the leaf area drawn) in the source and in
    /// the reduced mesh.
    pub cut_out_area: (f64, f64),
}

/// The triangle count a budget allows for a mesh of `triangles`.
pub fn budget_triangles(budget: TriangleBudget, triangles: usize) -> usize {
    match budget {
        TriangleBudget::Triangles(count) => (count as usize).min(triangles),
        // At least one triangle of a mesh that has any: a ratio's level is never empty.
        TriangleBudget::Ratio(ratio) if ratio > 0.0 => {
            ((ratio.min(1.0) as f64 * triangles as f64).floor() as usize).clamp(1.min(triangles), triangles)
        }
        TriangleBudget::Ratio(_) => 0,
    }
}

/// `mesh` with at most the budget's triangles (see the module). Cards get their share of the
/// budget by triangle count: simplified within the error bound, then the largest kept whole
/// (see [`thin_cards`]); the rest is simplified per material and object, with the vertices they
/// share locked so that no border moves; what the simplifier cannot bring under its share with
/// the error bound it takes without one, then by its sloppy (topology-free) pass, then by
/// dropping its smallest triangles.
pub fn reduce_mesh(mesh: &Mesh, settings: &ReduceSettings) -> ReducedMesh {
    let triangle_count = mesh.triangles.len();
    let target = budget_triangles(settings.budget, triangle_count);
    let (ids, count) = position_ids(&mesh.positions);
    let cards = find_cards(mesh, (&ids, count));
    let card_triangles: usize = cards.iter().map(|card| card.triangles.len()).sum();
    let source_cut_out = cut_out_area(mesh, &mesh.positions, 0..triangle_count);
    if target >= triangle_count {
        return ReducedMesh {
            mesh: mesh.clone(),
            error: 0.0,
            cards: (cards.len(), cards.len()),
            cut_out_area: (source_cut_out, source_cut_out),
        };
    }
    // The cards' share of the budget, in proportion to their triangles. The simplifier first
    // takes from each card what it can within the error bound (a card of several triangles
    // keeps its outline in fewer); the cards still over their share are thinned whole.
    let card_budget = (target as f64 * card_triangles as f64 / triangle_count as f64).floor() as usize;
    let mut cards = cards;
    let card_list: Vec<usize> = cards.iter().flat_map(|card| card.triangles.iter().copied()).collect();
    let (simplified_cards, card_error) =
        simplify_groups(mesh, (&ids, count), &card_list, card_budget, (settings.max_error, Reach::WithinError));
    let mut card_of_vertex: Vec<Option<usize>> = vec![None; mesh.positions.len()];
    for (index, card) in cards.iter().enumerate() {
        for &triangle in &card.triangles {
            for corner in mesh.triangles[triangle] {
                card_of_vertex[corner as usize] = Some(index);
            }
        }
    }
    for (corners, source) in simplified_cards {
        if let Some(card) = card_of_vertex[corners[0] as usize] {
            cards[card].simplified.push((corners, source));
        }
    }
    let (kept_cards, positions) = thin_cards(mesh, &cards, card_budget);
    let mut in_card = vec![false; triangle_count];
    for &triangle in &card_list {
        in_card[triangle] = true;
    }
    let solid: Vec<usize> = (0..triangle_count).filter(|&triangle| !in_card[triangle]).collect();
    let kept_card_triangles: Vec<([u32; 3], usize)> =
        kept_cards.iter().flat_map(|&card| cards[card].simplified.iter().copied()).collect();
    let solid_budget = target.saturating_sub(kept_card_triangles.len());
    let (solid_triangles, solid_error) =
        simplify_groups(mesh, (&ids, count), &solid, solid_budget, (settings.max_error, Reach::Budget));
    let error = solid_error.max(if kept_cards.is_empty() { 0.0 } else { card_error });
    let mut kept: Vec<([u32; 3], usize)> = solid_triangles;
    kept.extend(kept_card_triangles);
    kept.sort_by_key(|&(_, source)| source);
    let reduced = compact_mesh(mesh, &positions, &kept);
    let reduced_cut_out = cut_out_area(&reduced, &reduced.positions, 0..reduced.triangles.len());
    ReducedMesh {
        mesh: reduced,
        error,
        cards: (cards.len(), kept_cards.len()),
        cut_out_area: (source_cut_out, reduced_cut_out),
    }
}

/// A card: a connected part of cut-out triangles small enough to be thinned whole.
struct Card {
    triangles: Vec<usize>,
    centre: Vec3,
    area: f64,
    /// What the error-bounded simplification left of it, each with a source triangle.
    simplified: Vec<([u32; 3], usize)>,
}

/// The cards of `mesh`: its connected parts (by shared positions) of at most
/// [`CARD_TRIANGLES`] triangles, all of cut-out materials.
fn find_cards(mesh: &Mesh, (ids, count): (&[u32], usize)) -> Vec<Card> {
    let mut parent: Vec<usize> = (0..count).collect();
    let position = |corner: u32| ids[corner as usize] as usize;
    for triangle in &mesh.triangles {
        let first = union_find_root(&mut parent, position(triangle[0]));
        for &corner in &triangle[1..] {
            let other = union_find_root(&mut parent, position(corner));
            parent[other] = first;
        }
    }
    let mut parts: BTreeMap<usize, Vec<usize>> = BTreeMap::new();
    for (index, triangle) in mesh.triangles.iter().enumerate() {
        parts.entry(union_find_root(&mut parent, position(triangle[0]))).or_default().push(index);
    }
    parts
        .into_values()
        .filter(|triangles| {
            triangles.len() <= CARD_TRIANGLES && triangles.iter().all(|&triangle| is_cut_out(mesh, triangle))
        })
        .map(|triangles| {
            let corners: Vec<Vec3> = triangles
                .iter()
                .flat_map(|&triangle| {
                    mesh.triangles[triangle].map(|corner| Vec3::from(mesh.positions[corner as usize]))
                })
                .collect();
            let centre = corners.iter().copied().sum::<Vec3>() / corners.len() as f32;
            let area = triangles.iter().map(|&triangle| triangle_area(&mesh.positions, mesh.triangles[triangle])).sum();
            Card { triangles, centre, area, simplified: Vec::new() }
        })
        .collect()
}

/// The cards kept within `budget` triangles of what the simplifier left of them (indices into
/// `cards`), the largest first, and the mesh's positions with each kept card grown about its
/// centre by [`CARD_GROWTH_EXPONENT`] (at most [`MAX_CARD_GROWTH`] along a side).
fn thin_cards(mesh: &Mesh, cards: &[Card], budget: usize) -> (Vec<usize>, Vec<[f32; 3]>) {
    let mut positions = mesh.positions.clone();
    let total: usize = cards.iter().map(|card| card.simplified.len()).sum();
    if total == 0 || budget == 0 {
        return (Vec::new(), positions);
    }
    // The largest cards first (as the simplifier itself drops the cheapest, smallest ones):
    // on the bundled bush at 128 px this kept 0.37 px-shift units of loss at half the
    // triangles where cards kept evenly over space lost 0.77.
    let mut order: Vec<usize> = (0..cards.len()).filter(|&card| !cards[card].simplified.is_empty()).collect();
    order.sort_by(|&a, &b| cards[b].area.total_cmp(&cards[a].area).then(a.cmp(&b)));
    let mut used = 0usize;
    let mut kept = Vec::new();
    for card in order {
        let size = cards[card].simplified.len();
        if used + size <= budget {
            used += size;
            kept.push(card);
        }
    }
    let all_area: f64 = cards.iter().map(|card| card.area).sum();
    let kept_area: f64 = kept.iter().map(|&card| cards[card].area).sum();
    if kept_area > 0.0 {
        let growth = ((all_area / kept_area).powf(CARD_GROWTH_EXPONENT) as f32).clamp(1.0, MAX_CARD_GROWTH);
        let mut grown = vec![false; positions.len()];
        for &card in &kept {
            let centre = cards[card].centre;
            for (triangle, _) in &cards[card].simplified {
                for &corner in triangle {
                    if !std::mem::replace(&mut grown[corner as usize], true) {
                        let position = Vec3::from(positions[corner as usize]);
                        positions[corner as usize] = (centre + (position - centre) * growth).to_array();
                    }
                }
            }
        }
    }
    kept.sort_unstable();
    (kept, positions)
}

/// How far [`simplify_groups`] goes toward its budget.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Reach {
    /// As far as the error bound lets it (the result may be over the budget).
    WithinError,
    /// Under the budget, past the error bound when it must.
    Budget,
}

/// The triangles `solid` (indices into the mesh's) simplified toward `budget` triangles in all:
/// each material-and-object group toward its share, the vertices that groups share locked.
/// Each kept triangle with the index of a source triangle of its group (for its material and
/// object), and the largest deviation as a fraction of the mesh's extent.
fn simplify_groups(
    mesh: &Mesh,
    (ids, count): (&[u32], usize),
    solid: &[usize],
    budget: usize,
    (max_error, reach): (f32, Reach),
) -> (Vec<([u32; 3], usize)>, f32) {
    if solid.is_empty() {
        return (Vec::new(), 0.0);
    }
    let mut groups: BTreeMap<(u32, u32), Vec<usize>> = BTreeMap::new();
    for &triangle in solid {
        let material = mesh.triangle_materials.get(triangle).copied().unwrap_or(0);
        let object = mesh.triangle_objects.get(triangle).copied().unwrap_or(0);
        groups.entry((material, object)).or_default().push(triangle);
    }
    // A vertex (by position) used by two groups lies on their border: locked.
    let mut group_of_position: Vec<Option<usize>> = vec![None; count];
    let mut shared = vec![false; count];
    for (group, triangles) in groups.values().enumerate() {
        for &triangle in triangles {
            for corner in mesh.triangles[triangle] {
                let id = ids[corner as usize] as usize;
                match group_of_position[id] {
                    None => group_of_position[id] = Some(group),
                    Some(other) if other != group => shared[id] = true,
                    Some(_) => {}
                }
            }
        }
    }
    let locks: Vec<SimplifyVertex> =
        ids.iter().map(|&id| if shared[id as usize] { SimplifyVertex::Lock } else { SimplifyVertex::None }).collect();
    let extent = mesh_extent(&mesh.positions).max(1e-12);
    let position_bytes: &[u8] = bytemuck::cast_slice(&mesh.positions);
    let vertices = VertexDataAdapter::new(position_bytes, 12, 0).expect("12-byte positions");
    // Normals and UVs beside each vertex, weighed as meshoptimizer's demo weighs them.
    let uvs = mesh.uvs.as_deref();
    let attributes: Vec<f32> = (0..mesh.positions.len())
        .flat_map(|vertex| {
            let normal = mesh.normals.get(vertex).copied().unwrap_or([0.0; 3]);
            let uv = uvs.and_then(|uvs| uvs.get(vertex)).copied().unwrap_or([0.0; 2]);
            [normal[0], normal[1], normal[2], uv[0], uv[1]]
        })
        .collect();
    let weights = [0.5, 0.5, 0.5, 1.0, 1.0];
    let total = solid.len();
    let mut kept = Vec::new();
    let mut error = 0.0f32;
    for triangles in groups.values() {
        let share = (budget as f64 * triangles.len() as f64 / total as f64).floor() as usize;
        let indices: Vec<u32> = triangles.iter().flat_map(|&triangle| mesh.triangles[triangle]).collect();
        // Errors are absolute (in the mesh's units): relative ones would be to each group's
        // own extent.
        let simplify = |absolute_error: f32, reached: &mut f32| {
            meshopt::simplify_with_attributes_and_locks(
                &indices,
                &vertices,
                &attributes,
                &weights,
                5,
                &locks,
                share * 3,
                absolute_error,
                SimplifyOptions::Sparse | SimplifyOptions::ErrorAbsolute,
                Some(reached),
            )
        };
        let mut reached = 0.0f32;
        let mut result = simplify(max_error * extent, &mut reached);
        if reach == Reach::WithinError {
            error = error.max(reached / extent);
            kept.extend(result.chunks_exact(3).map(|corners| ([corners[0], corners[1], corners[2]], triangles[0])));
            continue;
        }
        if result.len() > share * 3 {
            result = simplify(f32::MAX, &mut reached);
        }
        if result.len() > share * 3 {
            let mut sloppy_error = 0.0f32;
            let sloppy = meshopt::simplify_sloppy(&result, &vertices, share * 3, f32::MAX, Some(&mut sloppy_error));
            // The sloppy pass can take a small group (a box's sides, all corners and borders) to
            // nothing: it is kept only when it leaves at least half the share.
            if sloppy.len() >= share / 2 * 3 {
                result = sloppy;
                reached = reached.max(sloppy_error * extent);
            }
        }
        if result.is_empty() && share > 0 {
            // Collapsed to nothing (a lone triangle beside degenerate ones): the largest of the
            // group's own triangles instead.
            result = indices.clone();
        }
        let mut group_kept: Vec<[u32; 3]> =
            result.chunks_exact(3).map(|corners| [corners[0], corners[1], corners[2]]).collect();
        if group_kept.len() > share {
            reached = reached.max(keep_largest(&mesh.positions, &mut group_kept, share));
        }
        error = error.max(reached / extent);
        kept.extend(group_kept.into_iter().map(|corners| (corners, triangles[0])));
    }
    (kept, error)
}

/// Keeps the `count` largest of `triangles` (in their order); gives the depth of the deepest hole
/// the others leave (half the longest side of the largest one dropped).
fn keep_largest(positions: &[[f32; 3]], triangles: &mut Vec<[u32; 3]>, count: usize) -> f32 {
    let mut by_area: Vec<usize> = (0..triangles.len()).collect();
    by_area.sort_by(|&a, &b| triangle_area(positions, triangles[b]).total_cmp(&triangle_area(positions, triangles[a])));
    let mut keep = vec![false; triangles.len()];
    for &index in &by_area[..count.min(triangles.len())] {
        keep[index] = true;
    }
    let mut hole = 0.0f32;
    for &index in by_area.iter().skip(count) {
        let corners = triangles[index].map(|corner| Vec3::from(positions[corner as usize]));
        let longest = (0..3).map(|side| corners[side].distance(corners[(side + 1) % 3])).fold(0.0f32, f32::max);
        hole = hole.max(0.5 * longest);
    }
    let mut index = 0;
    triangles.retain(|_| {
        index += 1;
        keep[index - 1]
    });
    hole
}

/// The source mesh's vertices that `kept` uses (at `positions`), renumbered in order of first
/// use; each kept triangle takes its source triangle's material and object.
fn compact_mesh(mesh: &Mesh, positions: &[[f32; 3]], kept: &[([u32; 3], usize)]) -> Mesh {
    let mut new_index: Vec<Option<u32>> = vec![None; mesh.positions.len()];
    let mut used: Vec<usize> = Vec::new();
    let triangles: Vec<[u32; 3]> = kept
        .iter()
        .map(|(corners, _)| {
            corners.map(|corner| {
                *new_index[corner as usize].get_or_insert_with(|| {
                    used.push(corner as usize);
                    used.len() as u32 - 1
                })
            })
        })
        .collect();
    let pick =
        |values: &[[f32; 3]]| used.iter().map(|&vertex| values.get(vertex).copied().unwrap_or([0.0; 3])).collect();
    Mesh {
        positions: pick(positions),
        normals: pick(&mesh.normals),
        uvs: mesh.uvs.as_ref().map(|uvs| used.iter().map(|&vertex| uvs[vertex]).collect()),
        triangles,
        triangle_materials: kept
            .iter()
            .map(|&(_, source)| mesh.triangle_materials.get(source).copied().unwrap_or(0))
            .collect(),
        materials: mesh.materials.clone(),
        triangle_objects: kept
            .iter()
            .map(|&(_, source)| mesh.triangle_objects.get(source).copied().unwrap_or(0))
            .collect(),
        objects: mesh.objects.clone(),
    }
}

/// The summed area of the cut-out materials' triangles among `triangles`.
fn cut_out_area(mesh: &Mesh, positions: &[[f32; 3]], triangles: std::ops::Range<usize>) -> f64 {
    triangles
        .filter(|&triangle| is_cut_out(mesh, triangle))
        .map(|triangle| triangle_area(positions, mesh.triangles[triangle]))
        .sum()
}

/// Whether triangle `triangle` of `mesh` is of a cut-out material.
fn is_cut_out(mesh: &Mesh, triangle: usize) -> bool {
    let material = mesh.triangle_materials.get(triangle).copied().unwrap_or(0) as usize;
    mesh.materials.get(material).is_some_and(|material| material.cut_out)
}

fn triangle_area(positions: &[[f32; 3]], [a, b, c]: [u32; 3]) -> f64 {
    let [a, b, c] = [a, b, c].map(|corner| Vec3::from(positions[corner as usize]).as_dvec3());
    0.5 * (b - a).cross(c - a).length()
}

/// The largest side of the mesh's bounding box.
pub fn mesh_extent(positions: &[[f32; 3]]) -> f32 {
    let (low, high) = positions.iter().fold((Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)), |(low, high), &p| {
        (low.min(Vec3::from(p)), high.max(Vec3::from(p)))
    });
    (high - low).max_element().max(0.0)
}
