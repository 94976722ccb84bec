//! Triangle LODs: a mesh brought under a triangle budget by meshoptimizer's attribute-aware
//! simplifier (normals and UVs weighed, material and object borders locked), with foliage cards
//! thinned as whole cards and the kept ones grown so that the leaf area drawn stays the
//! source's, instead of each card collapsing on its own (meshoptimizer's issue #1093).

use std::collections::BTreeMap;

use glam::Vec3;
use meshopt::{SimplifyOptions, SimplifyVertex, VertexDataAdapter};

use super::{position_ids, Mesh};

/// How many triangles a reduced mesh may have.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum TriangleBudget {
    /// At most this many.
    Triangles(u32),
    /// At most this fraction of the source's (rounded down).
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
        TriangleBudget::Ratio(ratio) => {
            ((ratio.clamp(0.0, 1.0) as f64 * triangles as f64).floor() as usize).min(triangles)
        }
    }
}

/// `mesh` with at most the budget's triangles (see the module). Cards get their share of the
/// budget by triangle count and are kept evenly over space (in the order of their centres along
/// a Morton curve); the rest is simplified per material and object, with the vertices they
/// share locked so that no border moves; what the simplifier cannot bring under its share with
/// the error bound it takes without one, then by its sloppy (topology-free) pass, then by
/// dropping its smallest triangles.
pub fn reduce_mesh(mesh: &Mesh, settings: &ReduceSettings) -> ReducedMesh {
    let triangle_count = mesh.triangles.len();
    let target = budget_triangles(settings.budget, triangle_count);
    let cards = find_cards(mesh);
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
    // The cards' share of the budget, in proportion to their triangles.
    let card_budget = (target as f64 * card_triangles as f64 / triangle_count as f64).floor() as usize;
    let (kept_cards, positions) = thin_cards(mesh, &cards, card_budget);
    let mut in_card = vec![false; triangle_count];
    for card in &cards {
        for &triangle in &card.triangles {
            in_card[triangle] = true;
        }
    }
    let solid: Vec<usize> = (0..triangle_count).filter(|&triangle| !in_card[triangle]).collect();
    let kept_card_triangles: Vec<usize> =
        kept_cards.iter().flat_map(|&card| cards[card].triangles.iter().copied()).collect();
    let solid_budget = target.saturating_sub(kept_card_triangles.len());
    let (solid_triangles, error) = simplify_solid(mesh, &solid, solid_budget, settings.max_error);
    let mut kept: Vec<([u32; 3], usize)> = solid_triangles;
    kept.extend(kept_card_triangles.iter().map(|&triangle| (mesh.triangles[triangle], triangle)));
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
}

/// The cards of `mesh`: its connected parts (by shared positions) of at most
/// [`CARD_TRIANGLES`] triangles, all of cut-out materials.
fn find_cards(mesh: &Mesh) -> Vec<Card> {
    let (ids, count) = position_ids(&mesh.positions);
    let mut parent: Vec<u32> = (0..count as u32).collect();
    fn root(parent: &mut [u32], mut node: u32) -> u32 {
        while parent[node as usize] != node {
            parent[node as usize] = parent[parent[node as usize] as usize];
            node = parent[node as usize];
        }
        node
    }
    for triangle in &mesh.triangles {
        let first = root(&mut parent, ids[triangle[0] as usize]);
        for &corner in &triangle[1..] {
            let other = root(&mut parent, ids[corner as usize]);
            parent[other as usize] = first;
        }
    }
    let mut parts: BTreeMap<u32, Vec<usize>> = BTreeMap::new();
    for (index, triangle) in mesh.triangles.iter().enumerate() {
        parts.entry(root(&mut parent, ids[triangle[0] as usize])).or_default().push(index);
    }
    let cut_out = |triangle: usize| {
        let material = mesh.triangle_materials.get(triangle).copied().unwrap_or(0) as usize;
        mesh.materials.get(material).is_some_and(|material| material.cut_out)
    };
    parts
        .into_values()
        .filter(|triangles| triangles.len() <= CARD_TRIANGLES && triangles.iter().all(|&triangle| cut_out(triangle)))
        .map(|triangles| {
            let corners: Vec<Vec3> = triangles
                .iter()
                .flat_map(|&triangle| {
                    mesh.triangles[triangle].map(|corner| Vec3::from(mesh.positions[corner as usize]))
                })
                .collect();
            let centre = corners.iter().copied().sum::<Vec3>() / corners.len() as f32;
            let area = triangles.iter().map(|&triangle| triangle_area(&mesh.positions, mesh.triangles[triangle])).sum();
            Card { triangles, centre, area }
        })
        .collect()
}

/// The cards kept within `budget` triangles (indices into `cards`), spread evenly over space,
/// and the mesh's positions with each kept card grown about its centre so that the kept cards'
/// area is the whole set's (at most [`MAX_CARD_GROWTH`] along a side).
fn thin_cards(mesh: &Mesh, cards: &[Card], budget: usize) -> (Vec<usize>, Vec<[f32; 3]>) {
    let mut positions = mesh.positions.clone();
    let total: usize = cards.iter().map(|card| card.triangles.len()).sum();
    if cards.is_empty() || budget == 0 {
        return (Vec::new(), positions);
    }
    // Cards in the order of their centres along a Morton curve over the cards' bounds; every
    // card whose running share of the budget reaches a whole card's triangles is kept.
    let (low, high) = cards.iter().fold((Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)), |(low, high), card| {
        (low.min(card.centre), high.max(card.centre))
    });
    let extent = (high - low).max(Vec3::splat(1e-12));
    let mut order: Vec<usize> = (0..cards.len()).collect();
    order.sort_by_key(|&card| (morton_code((cards[card].centre - low) / extent), card));
    let fraction = (budget as f64 / total as f64).min(1.0);
    let (mut credit, mut used) = (0.0f64, 0usize);
    let mut kept = Vec::new();
    for card in order {
        let size = cards[card].triangles.len();
        credit += fraction * size as f64;
        if credit >= size as f64 && used + size <= budget {
            credit -= size as f64;
            used += size;
            kept.push(card);
        }
    }
    let all_area: f64 = cards.iter().map(|card| card.area).sum();
    let kept_area: f64 = kept.iter().map(|&card| cards[card].area).sum();
    if kept_area > 0.0 {
        let growth = ((all_area / kept_area).sqrt() as f32).clamp(1.0, MAX_CARD_GROWTH);
        let mut grown = vec![false; positions.len()];
        for &card in &kept {
            let centre = cards[card].centre;
            for &triangle in &cards[card].triangles {
                for corner in mesh.triangles[triangle] {
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

/// Three bits per level of each coordinate in [0, 1], interleaved (ten levels).
fn morton_code(unit: Vec3) -> u32 {
    let quantise = |value: f32| (value.clamp(0.0, 1.0) * 1023.0) as u32;
    let (x, y, z) = (quantise(unit.x), quantise(unit.y), quantise(unit.z));
    (0..10).fold(0, |code, bit| {
        code | ((x >> bit) & 1) << (3 * bit) | ((y >> bit) & 1) << (3 * bit + 1) | ((z >> bit) & 1) << (3 * bit + 2)
    })
}

/// The triangles `solid` (indices into the mesh's) simplified toward `budget` triangles in all:
/// each material-and-object group toward its share, the vertices that groups share locked.
/// Each kept triangle with the index of a source triangle of its group (for its material and
/// object), and the largest deviation as a fraction of the mesh's extent.
fn simplify_solid(mesh: &Mesh, solid: &[usize], budget: usize, max_error: f32) -> (Vec<([u32; 3], usize)>, f32) {
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
    let (ids, count) = position_ids(&mesh.positions);
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
        if result.len() > share * 3 {
            result = simplify(f32::MAX, &mut reached);
        }
        if result.len() > share * 3 {
            let mut sloppy_error = 0.0f32;
            result = meshopt::simplify_sloppy(&result, &vertices, share * 3, f32::MAX, Some(&mut sloppy_error));
            reached = reached.max(sloppy_error * extent);
        }
        let mut group_kept: Vec<[u32; 3]> =
            result.chunks_exact(3).map(|corners| [corners[0], corners[1], corners[2]]).collect();
        if group_kept.len() > share {
            // The largest triangles, in their order.
            let mut by_area: Vec<usize> = (0..group_kept.len()).collect();
            by_area.sort_by(|&a, &b| {
                triangle_area(&mesh.positions, group_kept[b]).total_cmp(&triangle_area(&mesh.positions, group_kept[a]))
            });
            let mut keep = vec![false; group_kept.len()];
            for &index in &by_area[..share] {
                keep[index] = true;
            }
            let mut index = 0;
            group_kept.retain(|_| {
                index += 1;
                keep[index - 1]
            });
        }
        error = error.max(reached / extent);
        kept.extend(group_kept.into_iter().map(|corners| (corners, triangles[0])));
    }
    (kept, error)
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
        .filter(|&triangle| {
            let material = mesh.triangle_materials.get(triangle).copied().unwrap_or(0) as usize;
            mesh.materials.get(material).is_some_and(|material| material.cut_out)
        })
        .map(|triangle| triangle_area(positions, mesh.triangles[triangle]))
        .sum()
}

fn triangle_area(positions: &[[f32; 3]], [a, b, c]: [u32; 3]) -> f64 {
    let [a, b, c] = [a, b, c].map(|corner| Vec3::from(positions[corner as usize]).as_dvec3());
    0.5 * (b - a).cross(c - a).length()
}

/// The largest side of the mesh's bounding box.
fn mesh_extent(positions: &[[f32; 3]]) -> f32 {
    let (low, high) = positions.iter().fold((Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)), |(low, high), &p| {
        (low.min(Vec3::from(p)), high.max(Vec3::from(p)))
    });
    (high - low).max_element().max(0.0)
}
