//! Billboard-cloud planes (Décoret, Durand, Sillion, Dorsey, SIGGRAPH 2003): a greedy,
//! density-based choice of planes in discretised (θ, φ, ρ) space such that every face lies
//! within ε of the plane it is assigned to. No face is ever dropped.

mod budget_refinement;
mod ladder;

use glam::Vec3;
use rayon::prelude::*;

pub use budget_refinement::SEAM_WEIGHT;
use budget_refinement::{close_seams, edge_neighbours, mean_seam_gap, refine_planes_for_budget};
pub use ladder::{ladder_epsilon, search_epsilon_ladder, LadderProbe, BUDGET_LADDER_STEPS};

/// Plane-selection settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlaneSettings {
    /// ε as a fraction of the bounding-sphere radius.
    pub epsilon: f32,
    pub max_planes: Option<u32>,
    /// With a quad budget, ε is searched for (`epsilon` is ignored): see
    /// [`select_planes_within_budget`].
    pub max_quads: Option<u32>,
}

/// One plane: points `x` with `normal · x = distance`, and the faces assigned to it.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Plane {
    pub normal: [f32; 3],
    pub distance: f32,
    pub faces: Vec<u32>,
}

/// The result of plane selection.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PlaneSet {
    pub planes: Vec<Plane>,
    /// ε in world units.
    pub epsilon: f32,
    /// ε as a fraction of the bounding-sphere radius (the setting, or the one a budget found).
    pub epsilon_fraction: f32,
    /// The largest distance of a vertex of an assigned face from its plane (≤ ε unless capped,
    /// or refined under a budget).
    pub max_error: f32,
    /// The faces' mean distance from their planes (each face's mean vertex distance, weighted by
    /// its area), in world units: what the views see on average.
    pub mean_error: f32,
    /// Where two faces sharing an edge lie on different planes, the edge drawn on each plane
    /// lands in two places: the mean distance between them over such edges, weighted by edge
    /// length, in world units (0 when every shared edge stays on one plane). A trunk split
    /// across planes at different depths shows this gap as a step.
    pub seam_gap: f32,
    pub face_count: usize,
}

const THETA_BINS: usize = 24;
const PHI_BINS: usize = 12;
const PENALTY: f32 = 10.0;
const REFINEMENT_STEPS: usize = 6;
/// Faces a refinement evaluates candidate directions on (the final offset uses them all).
const REFINEMENT_SAMPLE: usize = 768;
/// Below this many faces a per-plane filter runs on the calling thread: the greedy loop runs it
/// a few times per plane (the oak: 1,012 planes), and waking the pool for a few microseconds of
/// work cost more than the work (a fifth of the planes stage was the scheduler's).
const PARALLEL_FACES: usize = 16_384;
/// Below this many faces in a refinement's sample, its nine candidate directions are scored on
/// the calling thread.
const PARALLEL_SAMPLE: usize = 256;
/// Below this many removed faces (× the θ rows), a density update runs on the calling thread.
const PARALLEL_REMOVALS: usize = 64;

/// The indices of `indices` that `keep` holds, in order: on the thread pool for large sets.
fn filter_faces(indices: &[u32], keep: impl Fn(u32) -> bool + Sync + Send) -> Vec<u32> {
    if indices.len() < PARALLEL_FACES {
        indices.iter().copied().filter(|&index| keep(index)).collect()
    } else {
        indices.par_iter().copied().filter(|&index| keep(index)).collect()
    }
}

/// Rounds of moving faces to their nearest plane and refitting after the greedy selection.
const REASSIGNMENT_ROUNDS: usize = 6;

/// The plane-space grid: directions over the upper hemisphere (a plane and its flip are one
/// plane), offsets ρ over [-R, R] around the bounding-sphere centre.
struct Grid {
    center: Vec3,
    radius: f32,
    epsilon: f32,
    rho_bins: usize,
    /// cos θ and sin θ of the THETA_BINS + 1 corner rows, and sin φ and cos φ of the
    /// PHI_BINS + 1 corner columns: a corner direction is (sin φ cos θ, sin φ sin θ, cos φ), so a
    /// vertex's offset along it is sin φ (x cos θ + y sin θ) + z cos φ, which vectorises over φ.
    theta_cos_sin: Vec<(f32, f32)>,
    sin_phi: [f32; PHI_BINS + 1],
    cos_phi: [f32; PHI_BINS + 1],
    /// Centre direction of each direction bin, THETA_BINS × PHI_BINS.
    centers: Vec<Vec3>,
}

/// The sphere ε is a fraction of: centred on the bounding box, through the farthest vertex (an
/// impostor's frames and the preview frame the same sphere).
pub(crate) fn bounding_sphere(positions: &[[f32; 3]]) -> (Vec3, f32) {
    let (min, max) =
        positions.iter().fold((Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)), |(min, max), &p| {
            (min.min(Vec3::from(p)), max.max(Vec3::from(p)))
        });
    let center = 0.5 * (min + max);
    let radius = positions.iter().map(|&p| Vec3::from(p).distance(center)).fold(0.0, f32::max).max(1e-6);
    (center, radius)
}

/// The radius of the mesh's bounding sphere (the one ε is a fraction of).
pub fn bounding_sphere_radius(positions: &[[f32; 3]]) -> f32 {
    bounding_sphere(positions).1
}

/// A region of plane space: θ, φ and ρ ranges.
#[derive(Clone, Copy, Debug)]
struct Region {
    theta: (f32, f32),
    phi: (f32, f32),
    rho: (f32, f32),
}

fn direction(theta: f32, phi: f32) -> Vec3 {
    Vec3::new(phi.sin() * theta.cos(), phi.sin() * theta.sin(), phi.cos())
}

impl Region {
    fn corners(&self) -> [Vec3; 4] {
        [
            direction(self.theta.0, self.phi.0),
            direction(self.theta.1, self.phi.0),
            direction(self.theta.0, self.phi.1),
            direction(self.theta.1, self.phi.1),
        ]
    }
}

/// A face relative to the grid centre: vertices, area and unit normal.
#[derive(Clone, Copy)]
struct Face {
    vertices: [Vec3; 3],
    area: f32,
    normal: Vec3,
}

impl Face {
    /// The interval of plane offsets ρ for which a plane of direction in `corners` can hold
    /// all three vertices within ε (`None` when empty).
    fn valid_rho(&self, corners: &[Vec3; 4], epsilon: f32) -> Option<(f32, f32)> {
        let mut low = f32::NEG_INFINITY;
        let mut high = f32::INFINITY;
        for vertex in &self.vertices {
            let dots = corners.map(|corner| vertex.dot(corner));
            let (min, max) = dots.iter().fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &d| (a.min(d), b.max(d)));
            low = low.max(min - epsilon);
            high = high.min(max + epsilon);
        }
        (low <= high).then_some((low, high))
    }

    fn distance_to(&self, normal: Vec3, rho: f32) -> f32 {
        self.vertices.iter().map(|vertex| (vertex.dot(normal) - rho).abs()).fold(0.0, f32::max)
    }

    fn mean_distance_to(&self, normal: Vec3, rho: f32) -> f32 {
        self.vertices.iter().map(|vertex| (vertex.dot(normal) - rho).abs()).sum::<f32>() / 3.0
    }
}

impl Grid {
    fn new(positions: &[[f32; 3]], epsilon_fraction: f32) -> Grid {
        let (center, radius) = bounding_sphere(positions);
        let epsilon = epsilon_fraction * radius;
        let rho_bins = ((2.0 * radius / epsilon).ceil() as usize).clamp(16, 256);
        let theta_cos_sin = (0..=THETA_BINS).map(|t| (Grid::theta(t).cos(), Grid::theta(t).sin())).collect();
        let sin_phi = std::array::from_fn(|p| Grid::phi(p).sin());
        let cos_phi = std::array::from_fn(|p| Grid::phi(p).cos());
        let mut centers = Vec::with_capacity(THETA_BINS * PHI_BINS);
        for t in 0..THETA_BINS {
            for p in 0..PHI_BINS {
                centers.push(direction(Grid::theta(t) + 0.5 * Grid::theta(1), Grid::phi(p) + 0.5 * Grid::phi(1)));
            }
        }
        Grid { center, radius, epsilon, rho_bins, theta_cos_sin, sin_phi, cos_phi, centers }
    }

    fn theta(index: usize) -> f32 {
        index as f32 * std::f32::consts::TAU / THETA_BINS as f32
    }

    fn phi(index: usize) -> f32 {
        index as f32 * std::f32::consts::FRAC_PI_2 / PHI_BINS as f32
    }

    fn rho_of(&self, bin: usize) -> f32 {
        -self.radius + (bin as f32) * 2.0 * self.radius / self.rho_bins as f32
    }

    /// The bin holding offset `rho`, clamped to the grid (a truncating cast is the floor here:
    /// negative positions clamp to bin 0 either way).
    fn rho_bin(&self, rho: f32) -> usize {
        let position = ((rho + self.radius) * self.rho_bins as f32 / (2.0 * self.radius)).max(0.0);
        (position as usize).min(self.rho_bins - 1)
    }

    fn bins(&self) -> usize {
        THETA_BINS * PHI_BINS * self.rho_bins
    }

    fn region(&self, bin: usize) -> Region {
        let direction_bin = bin / self.rho_bins;
        let rho_bin = bin % self.rho_bins;
        let (t, p) = (direction_bin / PHI_BINS, direction_bin % PHI_BINS);
        Region {
            theta: (Grid::theta(t), Grid::theta(t + 1)),
            phi: (Grid::phi(p), Grid::phi(p + 1)),
            rho: (self.rho_of(rho_bin), self.rho_of(rho_bin + 1)),
        }
    }

    /// The ρ bins `face` contributes to in each φ bin of direction row `t` (θ bin `t`): where
    /// a valid plane exists, and just in front of the face (the side its normal points to).
    fn row_ranges(&self, face: &Face, t: usize) -> [BinRanges; PHI_BINS] {
        let mut ranges = [BinRanges::EMPTY; PHI_BINS];
        if face.area <= 0.0 {
            return ranges;
        }
        // Per direction bin, the offsets a plane through every vertex can take: for each vertex,
        // the range of its offsets over the bin's four corner directions, intersected over the
        // vertices and widened by ε. Flat arrays, so the loops vectorise.
        const ROW: usize = PHI_BINS + 1;
        let (mut lows, mut highs) = ([f32::NEG_INFINITY; PHI_BINS], [f32::INFINITY; PHI_BINS]);
        let ((cos_row, sin_row), (cos_next, sin_next)) = (self.theta_cos_sin[t], self.theta_cos_sin[t + 1]);
        for vertex in &face.vertices {
            let (along_row, along_next) =
                (vertex.x * cos_row + vertex.y * sin_row, vertex.x * cos_next + vertex.y * sin_next);
            let (mut row, mut next) = ([0.0f32; ROW], [0.0f32; ROW]);
            for p in 0..ROW {
                row[p] = self.sin_phi[p] * along_row + vertex.z * self.cos_phi[p];
                next[p] = self.sin_phi[p] * along_next + vertex.z * self.cos_phi[p];
            }
            for p in 0..PHI_BINS {
                let (a, b, c, d) = (row[p], row[p + 1], next[p], next[p + 1]);
                lows[p] = lows[p].max(a.min(b).min(c.min(d)));
                highs[p] = highs[p].min(a.max(b).max(c.max(d)));
            }
        }
        for (p, range) in ranges.iter_mut().enumerate() {
            // max/min commute with the rounding of ±ε: the same values as widening per vertex.
            let (low, high) = (lows[p] - self.epsilon, highs[p] + self.epsilon);
            if low > high {
                continue;
            }
            let cosine = face.normal.dot(self.centers[t * PHI_BINS + p]);
            let (front_low, front_high) =
                if cosine >= 0.0 { (high, high + self.epsilon) } else { (low - self.epsilon, low) };
            *range = BinRanges {
                valid: (self.rho_bin(low) as u8, self.rho_bin(high) as u8),
                front: (self.rho_bin(front_low) as u8, self.rho_bin(front_high) as u8),
            };
        }
        ranges
    }

    /// Adds `sign` × the density contribution of `face` to direction row `t` (`valid` and
    /// `front` are that row's slices, `ranges` the face's from `row_ranges`): area × |cos| to
    /// every bin where a valid plane exists, and to the bins just in front of the face (weighted
    /// by PENALTY when scoring).
    fn contribute_to_row(
        &self,
        face: &Face,
        ranges: &[BinRanges],
        sign: f32,
        t: usize,
        valid: &mut [f32],
        front: &mut [f32],
    ) {
        for (p, range) in ranges.iter().enumerate() {
            let (first, end) = (range.valid.0 as usize, range.valid.1 as usize);
            if first > end {
                continue;
            }
            let weight = sign * face.area * face.normal.dot(self.centers[t * PHI_BINS + p]).abs();
            let base = p * self.rho_bins;
            valid[base + first..=base + end].iter_mut().for_each(|density| *density += weight);
            for bin in range.front.0 as usize..=range.front.1 as usize {
                if bin < first || bin > end {
                    front[base + bin] += weight;
                }
            }
        }
    }
}

/// One face's ρ bins in one direction bin (first and last, inclusive): where a valid plane
/// exists, and just in front of the face. ρ has at most 256 bins.
#[derive(Clone, Copy)]
struct BinRanges {
    valid: (u8, u8),
    front: (u8, u8),
}

impl BinRanges {
    const EMPTY: BinRanges = BinRanges { valid: (u8::MAX, 0), front: (u8::MAX, 0) };
}

/// Per bin: the area of faces a plane in the bin can hold, and of faces it would lie just in
/// front of.
#[derive(Clone)]
struct Density {
    valid: Vec<f32>,
    front: Vec<f32>,
}

impl Density {
    fn zero(bins: usize) -> Density {
        Density { valid: vec![0.0; bins], front: vec![0.0; bins] }
    }

    /// The density of all `faces`, and the ρ bins each face contributes to (kept, so removing
    /// the faces of a chosen plane does not redo the geometry). In parallel over θ rows: every
    /// bin sums its faces in their order, so the densities (and the planes) are the same on
    /// every run.
    fn of_faces(grid: &Grid, faces: &[Face]) -> (Density, Vec<BinRanges>) {
        let mut density = Density::zero(grid.bins());
        let mut ranges = vec![BinRanges::EMPTY; THETA_BINS * faces.len() * PHI_BINS];
        let row = PHI_BINS * grid.rho_bins;
        if !faces.is_empty() {
            density
                .valid
                .par_chunks_mut(row)
                .zip(density.front.par_chunks_mut(row))
                .zip(ranges.par_chunks_mut(faces.len() * PHI_BINS))
                .enumerate()
                .for_each(|(t, ((valid, front), ranges))| {
                    for (face, ranges) in faces.iter().zip(ranges.chunks_exact_mut(PHI_BINS)) {
                        ranges.copy_from_slice(&grid.row_ranges(face, t));
                        grid.contribute_to_row(face, ranges, 1.0, t, valid, front);
                    }
                });
        }
        (density, ranges)
    }

    /// Subtracts the contributions of the faces `removed` (indices into the faces `ranges` were
    /// computed for), in parallel over θ rows.
    fn remove_faces(&mut self, grid: &Grid, faces: &[Face], ranges: &[BinRanges], removed: &[u32]) {
        let row = PHI_BINS * grid.rho_bins;
        let per_row = faces.len() * PHI_BINS;
        let remove_from_row = |(t, (valid, front)): (usize, (&mut [f32], &mut [f32]))| {
            for &index in removed {
                let start = t * per_row + index as usize * PHI_BINS;
                grid.contribute_to_row(&faces[index as usize], &ranges[start..start + PHI_BINS], -1.0, t, valid, front);
            }
        };
        if removed.len() < PARALLEL_REMOVALS {
            self.valid.chunks_mut(row).zip(self.front.chunks_mut(row)).enumerate().for_each(remove_from_row);
        } else {
            self.valid.par_chunks_mut(row).zip(self.front.par_chunks_mut(row)).enumerate().for_each(remove_from_row);
        }
    }

    /// The densest bin: valid area minus the near-tangent penalty; where every bin is
    /// penalised below zero (dense foliage), the bin with the most valid area.
    fn best_bin(&self) -> Option<usize> {
        let argmax = |score: &dyn Fn(usize) -> f32| {
            (0..self.valid.len()).max_by(|&a, &b| score(a).total_cmp(&score(b)).then(b.cmp(&a)))
        };
        let penalised = |bin: usize| self.valid[bin] - PENALTY * self.front[bin];
        let best = argmax(&penalised)?;
        if penalised(best) > 0.0 {
            return Some(best);
        }
        let best = argmax(&|bin| self.valid[bin])?;
        (self.valid[best] > 1e-12).then_some(best)
    }
}

/// Chooses planes for the triangles of a mesh. `face_materials` holds each triangle's material
/// (empty: one material); faces only move between planes that already hold their material,
/// see `reassign_to_nearest_planes`. Deterministic for the same input.
pub fn select_planes(
    positions: &[[f32; 3]],
    triangles: &[[u32; 3]],
    face_materials: &[u32],
    settings: PlaneSettings,
) -> PlaneSet {
    let (grid, faces) = grid_and_faces(positions, triangles, settings.epsilon);
    let cap = settings.max_planes.map_or(usize::MAX, |cap| cap as usize);
    let greedy = greedy_planes(&grid, &faces, cap);
    finish_planes(&grid, &faces, greedy, triangles, face_materials, settings.epsilon, Finish::WithinEpsilon)
}

/// How a greedy pass is finished into a plane set.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Finish {
    /// Every face stays within ε of its plane (unless `max_planes` left it over).
    WithinEpsilon,
    /// A budget of `planes` planes: the ε it found only seeds them, and k-planes rounds then move
    /// faces and planes to lower the error the views see (see `refine_planes_for_budget`).
    Budget { planes: usize, seam_weight: f32 },
}

/// The plane set of a greedy pass: faces it left over go to the plane that moves them least,
/// then rounds of moving faces to their nearest plane and refitting; under a budget, then the
/// k-planes refinement.
fn finish_planes(
    grid: &Grid,
    faces: &[Face],
    greedy: GreedyPlanes,
    triangles: &[[u32; 3]],
    face_materials: &[u32],
    epsilon_fraction: f32,
    finish: Finish,
) -> PlaneSet {
    let GreedyPlanes { mut planes, assigned } = greedy;
    // Faces left over (degenerate ones, or beyond `max_planes`): to the plane that moves them least.
    if planes.is_empty() {
        planes.push(largest_face_plane_any(faces));
    }
    for index in 0..faces.len() as u32 {
        if assigned[index as usize] {
            continue;
        }
        let face = &faces[index as usize];
        let best = (0..planes.len())
            .min_by(|&a, &b| {
                face.distance_to(planes[a].0, planes[a].1).total_cmp(&face.distance_to(planes[b].0, planes[b].1))
            })
            .expect("at least one plane");
        planes[best].2.push(index);
    }

    let face_materials: Vec<u32> =
        (0..faces.len()).map(|face| face_materials.get(face).copied().unwrap_or(0)).collect();
    reassign_to_nearest_planes(faces, &face_materials, &mut planes, grid.epsilon);
    let neighbours = edge_neighbours(triangles);
    if let Finish::Budget { planes: cap, seam_weight } = finish {
        refine_planes_for_budget(faces, &face_materials, &mut planes, cap);
        if seam_weight > 0.0 {
            close_seams(faces, &face_materials, &neighbours, &mut planes, seam_weight);
        }
    }
    let seam_gap = mean_seam_gap(faces, &neighbours, &planes);

    let (mut max_error, mut weighted_error, mut area) = (0.0f32, 0.0f64, 0.0f64);
    let planes = planes
        .into_iter()
        .filter(|(_, _, members)| !members.is_empty())
        .map(|(normal, rho, mut members)| {
            members.sort_unstable();
            for &index in &members {
                let face = &faces[index as usize];
                max_error = max_error.max(face.distance_to(normal, rho));
                weighted_error += face.area as f64 * face.mean_distance_to(normal, rho) as f64;
                area += face.area as f64;
            }
            Plane { normal: normal.to_array(), distance: rho + normal.dot(grid.center), faces: members }
        })
        .collect();
    let mean_error = if area > 0.0 { (weighted_error / area) as f32 } else { 0.0 };
    PlaneSet {
        planes,
        epsilon: grid.epsilon,
        epsilon_fraction,
        max_error,
        mean_error,
        seam_gap,
        face_count: faces.len(),
    }
}

/// The plane-space grid for ε (a fraction of the bounding-sphere radius) and the mesh's faces
/// relative to its centre.
fn grid_and_faces(positions: &[[f32; 3]], triangles: &[[u32; 3]], epsilon_fraction: f32) -> (Grid, Vec<Face>) {
    let grid = Grid::new(positions, epsilon_fraction);
    let faces: Vec<Face> = triangles
        .iter()
        .map(|triangle| {
            let vertices = triangle.map(|index| Vec3::from(positions[index as usize]) - grid.center);
            let cross = (vertices[1] - vertices[0]).cross(vertices[2] - vertices[0]);
            Face { vertices, area: 0.5 * cross.length(), normal: cross.normalize_or_zero() }
        })
        .collect();
    (grid, faces)
}

/// What the greedy pass chose: each plane (normal, offset from the grid centre, faces within ε
/// of it), and which faces those hold.
struct GreedyPlanes {
    planes: Vec<(Vec3, f32, Vec<u32>)>,
    assigned: Vec<bool>,
}

impl GreedyPlanes {
    /// Whether every face of positive area lies on a chosen plane.
    fn holds_every_face(&self, faces: &[Face]) -> bool {
        faces.iter().zip(&self.assigned).all(|(face, &assigned)| assigned || face.area <= 0.0)
    }
}

/// The greedy pass of Décoret et al.: the densest bin of plane space, refined and fitted, takes
/// every remaining face within ε of it; its faces leave the density; until no face remains or
/// `cap` planes are chosen.
fn greedy_planes(grid: &Grid, faces: &[Face], cap: usize) -> GreedyPlanes {
    let (mut density, ranges) = Density::of_faces(grid, faces);
    let mut assigned = vec![false; faces.len()];
    let mut remaining: Vec<u32> = (0..faces.len() as u32).filter(|&index| faces[index as usize].area > 0.0).collect();
    let mut planes: Vec<(Vec3, f32, Vec<u32>)> = Vec::new();
    while !remaining.is_empty() && planes.len() < cap {
        let region = density.best_bin().map(|bin| grid.region(bin));
        let (normal, rho) = region
            .and_then(|region| refine(grid, faces, &remaining, region))
            .unwrap_or_else(|| largest_face_plane(faces, &remaining));
        let holds = |(normal, rho): (Vec3, f32)| -> Vec<u32> {
            filter_faces(&remaining, |index| faces[index as usize].distance_to(normal, rho) <= grid.epsilon)
        };
        let (mut normal, mut rho) = (normal, rho);
        let mut members = holds((normal, rho));
        if members.is_empty() {
            // Numerical corner case: the refined plane holds nothing; use a face's own plane.
            (normal, rho) = largest_face_plane(faces, &remaining);
            members = holds((normal, rho));
        }
        // Every member stays within ε of the fitted plane, so it holds a superset of them.
        (normal, rho) = fit_plane(faces, &members, normal, rho, grid.epsilon);
        members = holds((normal, rho));
        density.remove_faces(grid, faces, &ranges, &members);
        for &index in &members {
            assigned[index as usize] = true;
        }
        planes.push((normal, rho, members));
        remaining.retain(|&index| !assigned[index as usize]);
    }
    GreedyPlanes { planes, assigned }
}

/// The budget search stops at a fitting step whose greedy pass needs at least this fraction of
/// the budget's planes (the refinement seeds the rest). On the corpus bush's LOD chain
/// [512, 128, 32] this takes the three planes stages from 4.6 s to 1.6 s, each level's mean IoU
/// within 0.003 of the smallest step's.
const BUDGET_ENOUGH_PLANES: f32 = 0.9;

/// A probe of the budget search: the greedy pass at one ladder step, with what it ran on.
struct LadderStep {
    step: u32,
    grid: Grid,
    faces: Vec<Face>,
    greedy: GreedyPlanes,
    epsilon_fraction: f32,
}

/// The most faithful planes a quad budget allows: every plane is at least one quad, so the
/// smallest ε of the ladder for which the greedy selection needs at most `max_quads` planes
/// (see [`search_epsilon_ladder`]; each probe runs the greedy pass alone, stopped at the cap).
/// When even the largest ε needs more planes, the planes are capped at `max_quads` there. The
/// planes' clusters are merged down to the budget afterwards
/// (`rectangles::merge_rectangles_to_budget`).
pub fn select_planes_within_budget(
    positions: &[[f32; 3]],
    triangles: &[[u32; 3]],
    face_materials: &[u32],
    max_quads: u32,
    max_planes: Option<u32>,
    seam_weight: f32,
) -> PlaneSet {
    let cap = max_planes.map_or(max_quads, |planes| planes.min(max_quads)).max(1);
    let greedy_at = |step: u32| {
        let epsilon_fraction = ladder_epsilon(step);
        let (grid, faces) = grid_and_faces(positions, triangles, epsilon_fraction);
        let greedy = greedy_planes(&grid, &faces, cap as usize);
        LadderStep { step, grid, faces, greedy, epsilon_fraction }
    };
    // The fitting probe of the step found is finished into the plane set: the smallest, or the
    // last probed when it had enough planes.
    let mut fitting: Vec<LadderStep> = Vec::new();
    let enough = (BUDGET_ENOUGH_PLANES * cap as f32).ceil();
    let found = search_epsilon_ladder(cap as f32, enough, |step| {
        let probed = greedy_at(step);
        let (faces, greedy) = (&probed.faces, &probed.greedy);
        let fits = greedy.holds_every_face(faces);
        // The faces left over need at least as many planes again as the last plane's faces go
        // into them (the greedy planes shrink as they go).
        let left_over = greedy.assigned.iter().zip(faces).filter(|(&held, face)| !held && face.area > 0.0).count();
        let last_plane_faces = greedy.planes.last().map_or(1, |(_, _, members)| members.len().max(1));
        let planes = greedy.planes.len() as f32 + (left_over as f32 / last_plane_faces as f32).ceil();
        if fits {
            fitting.push(probed);
        }
        LadderProbe { fits, planes }
    });
    let chosen = match found {
        Some(step) => fitting.into_iter().find(|probed| probed.step == step).expect("the answer was probed and fits"),
        None => greedy_at(BUDGET_LADDER_STEPS),
    };
    let finish = Finish::Budget { planes: cap as usize, seam_weight };
    finish_planes(
        &chosen.grid,
        &chosen.faces,
        chosen.greedy,
        triangles,
        face_materials,
        chosen.epsilon_fraction,
        finish,
    )
}

/// Moves every face to the plane nearest it among those holding its material, then fits the
/// planes to their new members, for up to REASSIGNMENT_ROUNDS rounds, and ends with one last
/// move so each face sits on its nearest such plane. The greedy selection gives a chosen plane
/// every remaining face within ε, so a face often lies nearly ε from an early plane while a
/// later plane passes right through it, and in a view at an angle to the plane a face drawn on
/// its plane is displaced by up to that distance. A face only ever moves to a strictly nearer
/// plane, so no face ends farther from its plane than the greedy selection left it (within ε,
/// unless capped). Faces never bring a material to a plane that had none of it: a plane's
/// render groups, and the renders a texture edit invalidates, stay those of the greedy
/// selection or fewer. Planes left without faces are dropped by the caller. Deterministic:
/// every face decides alone, ties keep the current plane.
fn reassign_to_nearest_planes(
    faces: &[Face],
    face_materials: &[u32],
    planes: &mut [(Vec3, f32, Vec<u32>)],
    epsilon: f32,
) {
    let mut assignment = plane_of_each_face(faces.len(), planes);
    for round in 0..=REASSIGNMENT_ROUNDS {
        if !move_faces_to_better_planes(faces, face_materials, planes, &mut assignment, Face::distance_to) {
            return;
        }
        list_members(planes, &assignment);
        if round == REASSIGNMENT_ROUNDS {
            return;
        }
        planes
            .par_iter_mut()
            .for_each(|(normal, rho, members)| (*normal, *rho) = fit_plane(faces, members, *normal, *rho, epsilon));
    }
}

/// Each face's plane (usize::MAX: none; a face listed by several planes: the last).
fn plane_of_each_face(face_count: usize, planes: &[(Vec3, f32, Vec<u32>)]) -> Vec<usize> {
    let mut assignment = vec![usize::MAX; face_count];
    for (plane, (_, _, members)) in planes.iter().enumerate() {
        for &index in members {
            assignment[index as usize] = plane;
        }
    }
    assignment
}

/// The materials `faces` use (`face_materials` per face; empty: one material), ascending.
pub(crate) fn materials_of_faces(faces: &[u32], face_materials: &[u32]) -> Vec<u32> {
    let mut materials: Vec<u32> =
        faces.iter().map(|&face| face_materials.get(face as usize).copied().unwrap_or(0)).collect();
    materials.sort_unstable();
    materials.dedup();
    materials
}

/// The planes a face may move to: normal, offset and the (sorted) materials each holds.
struct Candidates<'a> {
    normals: &'a [Vec3],
    offsets: &'a [f32],
    materials: &'a [Vec<u32>],
}

/// One round of moves: every face with a plane (`assignment`, indices into `planes`) goes to the
/// plane holding its material where `cost` is strictly below that on its own plane, the lowest
/// (see `better_plane`); each face decides alone, in parallel. Whether any face moved. The
/// planes' member lists are left as they were (see `list_members`).
fn move_faces_to_better_planes(
    faces: &[Face],
    face_materials: &[u32],
    planes: &[(Vec3, f32, Vec<u32>)],
    assignment: &mut [usize],
    cost: impl Fn(&Face, Vec3, f32) -> f32 + Sync,
) -> bool {
    let normals: Vec<Vec3> = planes.iter().map(|plane| plane.0).collect();
    let offsets: Vec<f32> = planes.iter().map(|plane| plane.1).collect();
    let materials: Vec<Vec<u32>> =
        planes.iter().map(|(_, _, members)| materials_of_faces(members, face_materials)).collect();
    let candidates = Candidates { normals: &normals, offsets: &offsets, materials: &materials };
    let moved: Vec<Option<usize>> = faces
        .par_iter()
        .zip(&*assignment)
        .enumerate()
        .map(|(index, (face, &current))| {
            (current != usize::MAX)
                .then(|| better_plane(face, face_materials[index], current, &candidates, &cost))
                .flatten()
        })
        .collect();
    let mut changed = false;
    for (slot, moved) in assignment.iter_mut().zip(moved) {
        if let Some(plane) = moved {
            *slot = plane;
            changed = true;
        }
    }
    changed
}

/// Rewrites every plane's members from `assignment` (faces in ascending order; usize::MAX: none).
fn list_members(planes: &mut [(Vec3, f32, Vec<u32>)], assignment: &[usize]) {
    for plane in planes.iter_mut() {
        plane.2.clear();
    }
    for (index, &plane) in assignment.iter().enumerate() {
        if plane != usize::MAX {
            planes[plane].2.push(index as u32);
        }
    }
}

/// The plane holding `material` where `cost` of `face` is strictly below that on plane
/// `current`, the lowest, if any (ties keep the earlier plane). `cost` must be at least the
/// distance of the face's centroid from the plane (true of the largest and of the mean vertex
/// distance), so the exact cost is computed only for planes that pass near the face.
fn better_plane(
    face: &Face,
    material: u32,
    current: usize,
    candidates: &Candidates,
    cost: &impl Fn(&Face, Vec3, f32) -> f32,
) -> Option<usize> {
    let centroid = (face.vertices[0] + face.vertices[1] + face.vertices[2]) / 3.0;
    let mut best_cost = cost(face, candidates.normals[current], candidates.offsets[current]);
    let mut best = None;
    for (plane, (&normal, &offset)) in candidates.normals.iter().zip(candidates.offsets).enumerate() {
        if (normal.dot(centroid) - offset).abs() >= best_cost || plane == current {
            continue;
        }
        let plane_cost = cost(face, normal, offset);
        if plane_cost < best_cost && candidates.materials[plane].binary_search(&material).is_ok() {
            (best_cost, best) = (plane_cost, Some(plane));
        }
    }
    best
}

/// Refines a dense region to the best plane near it: candidate directions around the region's
/// centre (narrowing each round) and, per direction, the offset ρ covered by the most face area
/// with exact validity (every vertex within ε), less the near-tangent penalty.
fn refine(grid: &Grid, faces: &[Face], remaining: &[u32], region: Region) -> Option<(Vec3, f32)> {
    // The validity set of the region and its neighbours (loose test: hull over the corners).
    let grown = Region {
        theta: (
            region.theta.0 - 0.5 * (region.theta.1 - region.theta.0),
            region.theta.1 + 0.5 * (region.theta.1 - region.theta.0),
        ),
        phi: (
            (region.phi.0 - 0.5 * (region.phi.1 - region.phi.0)).max(0.0),
            region.phi.1 + 0.5 * (region.phi.1 - region.phi.0),
        ),
        rho: (region.rho.0 - grid.epsilon, region.rho.1 + grid.epsilon),
    };
    let corners = grown.corners();
    let set: Vec<u32> = filter_faces(remaining, |index| {
        faces[index as usize]
            .valid_rho(&corners, grid.epsilon)
            .is_some_and(|(low, high)| low <= grown.rho.1 && high >= grown.rho.0)
    });
    if set.is_empty() {
        return None;
    }
    // Directions are searched on an evenly strided sample of large sets.
    let stride = set.len().div_ceil(REFINEMENT_SAMPLE);
    let sample: Vec<u32> = set.iter().copied().step_by(stride).collect();
    let (mut theta, mut phi) = (0.5 * (region.theta.0 + region.theta.1), 0.5 * (region.phi.0 + region.phi.1));
    let (mut step_theta, mut step_phi) = (0.5 * (region.theta.1 - region.theta.0), 0.5 * (region.phi.1 - region.phi.0));
    let mut best: Option<(f32, Vec3, f32)> = None;
    let mut events = Vec::with_capacity(set.len() * 4);
    for _ in 0..REFINEMENT_STEPS {
        let (center_theta, center_phi) = (theta, phi);
        let candidates: Vec<(f32, f32)> = (-1..=1)
            .flat_map(|dt| (-1..=1).map(move |dp| (dt, dp)))
            .map(|(dt, dp)| {
                (
                    center_theta + dt as f32 * step_theta,
                    (center_phi + dp as f32 * step_phi).clamp(0.0, std::f32::consts::FRAC_PI_2),
                )
            })
            .collect();
        let score = |events: &mut Vec<u64>, &(candidate_theta, candidate_phi): &(f32, f32)| {
            let normal = direction(candidate_theta, candidate_phi);
            best_offset(faces, &sample, normal, grid.epsilon, events)
                .map(|(score, _)| (score, candidate_theta, candidate_phi))
        };
        let scored: Vec<Option<(f32, f32, f32)>> = if sample.len() < PARALLEL_SAMPLE {
            candidates.iter().map(|candidate| score(&mut events, candidate)).collect()
        } else {
            candidates.par_iter().map_init(Vec::new, score).collect()
        };
        // In candidate order, so ties resolve the same way on every run.
        for (score, candidate_theta, candidate_phi) in scored.into_iter().flatten() {
            if best.is_none_or(|(best_score, _, _)| score > best_score) {
                best = Some((score, direction(candidate_theta, candidate_phi), 0.0));
                (theta, phi) = (candidate_theta, candidate_phi);
            }
        }
        step_theta *= 0.5;
        step_phi *= 0.5;
    }
    let (_, normal, _) = best?;
    best_offset(faces, &set, normal, grid.epsilon, &mut events).map(|(_, rho)| (normal, rho))
}

/// The plane nearest its faces among those that still hold each of them within ε.
/// The greedy search takes the first offset of the densest interval, which leaves some face a
/// whole ε from the plane. The fit is area-weighted least squares over the vertices. Its normal
/// is used when every face stays within ε of it. Otherwise the fit tries halfway to the found
/// normal, then the found normal itself, and only the offset moves. The offset is the weighted
/// mean, clamped to the interval where every face stays valid.
fn fit_plane(faces: &[Face], members: &[u32], normal: Vec3, rho: f32, epsilon: f32) -> (Vec3, f32) {
    let total: f32 = members.iter().map(|&index| faces[index as usize].area).sum();
    if members.is_empty() || total <= 0.0 {
        return (normal, rho);
    }
    let mean = members.iter().fold(Vec3::ZERO, |sum, &index| {
        let face = &faces[index as usize];
        sum + face.area / 3.0 * (face.vertices[0] + face.vertices[1] + face.vertices[2])
    }) / total;
    let mut covariance = glam::Mat3::ZERO;
    for &index in members {
        let face = &faces[index as usize];
        for vertex in face.vertices {
            let d = vertex - mean;
            covariance += face.area / 3.0 * glam::Mat3::from_cols(d * d.x, d * d.y, d * d.z);
        }
    }
    // The smallest eigenvector of the covariance, by power iteration on (trace − covariance),
    // started from the found normal.
    let shifted =
        glam::Mat3::from_diagonal(Vec3::splat(covariance.x_axis.x + covariance.y_axis.y + covariance.z_axis.z))
            - covariance;
    let mut fitted = normal;
    for _ in 0..32 {
        fitted = (shifted * fitted).normalize_or_zero();
    }
    if fitted.dot(normal) < 0.0 {
        fitted = -fitted;
    }
    let candidates = [fitted, (fitted + normal).normalize_or_zero(), normal];
    for candidate in candidates.into_iter().filter(|candidate| candidate.is_finite() && *candidate != Vec3::ZERO) {
        let (mut low, mut high) = (f32::NEG_INFINITY, f32::INFINITY);
        for &index in members {
            let dots = faces[index as usize].vertices.map(|vertex| vertex.dot(candidate));
            low = low.max(dots[0].max(dots[1]).max(dots[2]) - epsilon);
            high = high.min(dots[0].min(dots[1]).min(dots[2]) + epsilon);
        }
        if low <= high {
            return (candidate, mean.dot(candidate).clamp(low, high));
        }
    }
    (normal, rho)
}

/// For planes of direction `normal`: the offset with the largest covered area (exact validity)
/// minus the penalty of faces it lies just in front of, and that score. `None` when no face of
/// `set` can lie on such a plane.
fn best_offset(faces: &[Face], set: &[u32], normal: Vec3, epsilon: f32, events: &mut Vec<u64>) -> Option<(f32, f32)> {
    events.clear();
    for &index in set {
        let face = &faces[index as usize];
        let dots = face.vertices.map(|vertex| vertex.dot(normal));
        let low = dots.iter().fold(f32::NEG_INFINITY, |a, &d| a.max(d)) - epsilon;
        let high = dots.iter().fold(f32::INFINITY, |a, &d| a.min(d)) + epsilon;
        if low > high {
            continue;
        }
        let cosine = face.normal.dot(normal);
        let weight = face.area * cosine.abs();
        events.push(event_key(low, weight));
        events.push(event_key(high, -weight));
        let (front_low, front_high) = if cosine >= 0.0 { (high, high + epsilon) } else { (low - epsilon, low) };
        events.push(event_key(front_low, -PENALTY * weight));
        events.push(event_key(front_high, PENALTY * weight));
    }
    if events.is_empty() {
        return None;
    }
    // By offset, openings before closings at the same offset so touching intervals overlap.
    events.sort_unstable();
    let (mut sum, mut best) = (0.0f32, None::<(f32, f32)>);
    for &key in events.iter() {
        let (offset, delta) = event_of_key(key);
        sum += delta;
        if best.is_none_or(|(score, _)| sum > score) {
            best = Some((sum, offset));
        }
    }
    best.filter(|(score, _)| *score > 0.0)
}

/// An (offset, delta) event as one integer whose order is offset ascending, then delta
/// descending (the order of `f32::total_cmp`): sorting integers is several times faster than
/// sorting pairs of floats, and equal keys are equal events, so the sums are the same every run.
fn event_key(offset: f32, delta: f32) -> u64 {
    ((total_order_bits(offset) as u64) << 32) | !total_order_bits(delta) as u64
}

fn event_of_key(key: u64) -> (f32, f32) {
    (from_total_order_bits((key >> 32) as u32), from_total_order_bits(!(key as u32)))
}

/// The bits of `value` as an unsigned integer ordered like `f32::total_cmp`.
fn total_order_bits(value: f32) -> u32 {
    let bits = value.to_bits();
    if bits & 0x8000_0000 != 0 {
        !bits
    } else {
        bits | 0x8000_0000
    }
}

fn from_total_order_bits(ordered: u32) -> f32 {
    f32::from_bits(if ordered & 0x8000_0000 != 0 { ordered & 0x7fff_ffff } else { !ordered })
}

/// The supporting plane of the largest remaining face (always valid for it).
fn largest_face_plane(faces: &[Face], remaining: &[u32]) -> (Vec3, f32) {
    let index = remaining
        .iter()
        .copied()
        .max_by(|&a, &b| faces[a as usize].area.total_cmp(&faces[b as usize].area).then(b.cmp(&a)))
        .expect("non-empty");
    let face = &faces[index as usize];
    (face.normal, face.vertices[0].dot(face.normal))
}

fn largest_face_plane_any(faces: &[Face]) -> (Vec3, f32, Vec<u32>) {
    let all: Vec<u32> = (0..faces.len() as u32).collect();
    let (normal, rho) =
        if faces.iter().any(|face| face.area > 0.0) { largest_face_plane(faces, &all) } else { (Vec3::Z, 0.0) };
    (normal, rho, Vec::new())
}
