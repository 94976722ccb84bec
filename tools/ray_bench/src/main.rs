//! Rays per second of the BVH crates that could cast cirrus's AO rays — `obvhs` (its compressed
//! wide BVH and its own traversal) and `bvh` (binary SAH tree) — against cirrus's one BVH
//! (`mesh::rays`: obvhs's builder collapsed to eight-wide nodes and packets, AVX2 or portable
//! kernels), on the same rays: from every `step`-th triangle's centroid, 256 cosine-distributed
//! directions of the R2 sequence shifted per point, as the AO bake casts them. One thread, so
//! the figures are per core. Every library's answers are checked against obvhs's.
//!
//! cargo run --release --manifest-path tools/ray_bench/Cargo.toml -- MESH.obj [STEP]

use std::path::Path;
use std::time::Instant;

use cirrus::mesh::rays::{build_triangle_bvh, offset_ray_origin, BackFaces};
use glam::{Vec3, Vec3A};

fn load(obj: &Path) -> cirrus::mesh::Mesh {
    let folder = obj.parent().expect("the OBJ's folder");
    let bytes = std::fs::read(obj).expect("the OBJ");
    let libraries = cirrus::mesh::material_libraries(obj, &bytes, folder)
        .into_iter()
        .map(|path| {
            let contents = std::fs::read(&path).ok();
            (path, contents)
        })
        .collect();
    cirrus::mesh::load_mesh(obj, &bytes, &libraries, folder).expect("the mesh loads").0
}

struct TestRay {
    origin: Vec3,
    direction: Vec3,
    /// The triangle the ray leaves from (skipped).
    triangle: u32,
}

fn ao_rays(mesh: &cirrus::mesh::Mesh, rays_per_point: u32, step: usize) -> Vec<TestRay> {
    use cirrus::mesh::occlusion::{orthonormal_frame, r2_point, sequence_shift};
    let mut rays = Vec::new();
    for (index, triangle) in mesh.triangles.iter().enumerate().step_by(step) {
        let corners = triangle.map(|vertex| Vec3::from(mesh.positions[vertex as usize]));
        let normal = (corners[1] - corners[0]).cross(corners[2] - corners[0]).normalize_or_zero();
        if normal == Vec3::ZERO {
            continue;
        }
        let origin = offset_ray_origin((corners[0] + corners[1] + corners[2]) / 3.0, normal);
        let (tangent, bitangent) = orthonormal_frame(normal);
        let shift = sequence_shift(index as u32);
        for ray in 0..rays_per_point {
            let base = r2_point(ray);
            let point = [(base[0] + shift[0]).fract(), (base[1] + shift[1]).fract()];
            let (sin, cos) = (std::f64::consts::TAU * point[1]).sin_cos();
            let (radius, z) = (point[0].sqrt(), (1.0 - point[0]).max(0.0).sqrt());
            let local = Vec3::new((radius * cos) as f32, (radius * sin) as f32, z as f32);
            let direction = (tangent * local.x + bitangent * local.y + normal * local.z).normalize_or_zero();
            rays.push(TestRay { origin, direction, triangle: index as u32 });
        }
    }
    rays
}

/// Runs `query` on every ray on this thread; prints rays per second and returns the answers.
fn measure(label: &str, rays: &[TestRay], query: impl Fn(&TestRay) -> bool) -> Vec<bool> {
    let start = Instant::now();
    let answers: Vec<bool> = rays.iter().map(query).collect();
    let seconds = start.elapsed().as_secs_f64();
    let hits = answers.iter().filter(|&&hit| hit).count();
    println!("  {label:<44} {:>6.2} M rays/s/core  ({:.1} % hit)", rays.len() as f64 / seconds / 1e6, 100.0 * hits as f64 / rays.len() as f64);
    answers
}

fn disagreements(answers: &[bool], reference: &[bool]) -> usize {
    answers.iter().zip(reference).filter(|(answer, expected)| answer != expected).count()
}

fn main() {
    let arguments: Vec<String> = std::env::args().collect();
    let obj = Path::new(arguments.get(1).expect("usage: ray_bench MESH.obj [STEP]"));
    let step: usize = arguments.get(2).map_or(8, |step| step.parse().expect("STEP is a number"));
    let mesh = load(obj);
    let rays = ao_rays(&mesh, 256, step);
    println!(
        "{}: {} triangles; {} rays (256 from every {step}th triangle's centroid); cirrus kernels: {}",
        obj.display(),
        mesh.triangles.len(),
        rays.len(),
        if cirrus::mesh::rays::avx2_available() { "AVX2 + FMA" } else { "portable" }
    );

    let triangles: Vec<obvhs::triangle::Triangle> = mesh
        .triangles
        .iter()
        .map(|triangle| {
            let [v0, v1, v2] = triangle.map(|vertex| Vec3A::from(mesh.positions[vertex as usize]));
            obvhs::triangle::Triangle { v0, v1, v2 }
        })
        .collect();
    let normals: Vec<Vec3A> = triangles.iter().map(|triangle| triangle.compute_normal()).collect();
    let start = Instant::now();
    let cwbvh = obvhs::cwbvh::builder::build_cwbvh_from_tris(
        &triangles,
        obvhs::BvhBuildParams::slow_build(),
        &mut std::time::Duration::default(),
    );
    let ordered: Vec<obvhs::rt_triangle::RtTriangle> =
        cwbvh.primitive_indices.iter().map(|&index| obvhs::rt_triangle::RtTriangle::from(&triangles[index as usize])).collect();
    println!("build: obvhs CWBVH {:.0} ms", start.elapsed().as_secs_f64() * 1e3);
    let start = Instant::now();
    let cirrus_bvh = build_triangle_bvh(&mesh.positions, &mesh.triangles);
    println!("build: cirrus {:.0} ms", start.elapsed().as_secs_f64() * 1e3);
    let cirrus_portable = build_triangle_bvh(&mesh.positions, &mesh.triangles).without_avx2();
    let start = Instant::now();
    let mut shapes: Vec<Shape> = mesh
        .triangles
        .iter()
        .enumerate()
        .map(|(index, triangle)| Shape { corners: triangle.map(|vertex| Vec3::from(mesh.positions[vertex as usize])), node: 0, index: index as u32 })
        .collect();
    let binary = bvh::bvh::Bvh::build(&mut shapes);
    println!("build: bvh {:.0} ms", start.elapsed().as_secs_f64() * 1e3);

    // obvhs: the traversal cirrus used before (any hit: the first that counts ends the ray).
    let obvhs_blocked = |ray: &TestRay, back_faces: BackFaces| {
        let obvhs_ray = obvhs::ray::Ray::new(ray.origin.into(), ray.direction.into(), 0.0, f32::INFINITY);
        let direction = Vec3A::from(ray.direction);
        !cwbvh.ray_traverse_miss(obvhs_ray, |obvhs_ray, id| {
            let triangle = cwbvh.primitive_indices[id];
            let passes = back_faces == BackFaces::PassThrough && normals[triangle as usize].dot(direction) > 0.0;
            if triangle == ray.triangle || passes {
                f32::INFINITY
            } else {
                ordered[id].intersect(obvhs_ray)
            }
        })
    };
    let obvhs_nearest = |ray: &TestRay| {
        let obvhs_ray = obvhs::ray::Ray::new(ray.origin.into(), ray.direction.into(), 0.0, f32::INFINITY);
        let direction = Vec3A::from(ray.direction);
        let mut hit = obvhs::ray::RayHit::none();
        cwbvh.ray_traverse(obvhs_ray, &mut hit, |obvhs_ray, id| {
            let triangle = cwbvh.primitive_indices[id];
            if triangle == ray.triangle || normals[triangle as usize].dot(direction) > 0.0 {
                f32::INFINITY
            } else {
                ordered[id].intersect(obvhs_ray)
            }
        })
    };
    for (label, back_faces) in [("any hit, back faces pass (AO's default)", BackFaces::PassThrough), ("any hit, back faces block", BackFaces::Block)]
    {
        println!("{label}:");
        let pass = back_faces == BackFaces::PassThrough;
        let reference = measure("obvhs 0.4 CWBVH (ray_traverse_miss)", &rays, |ray| obvhs_blocked(ray, back_faces));
        let answers = measure("bvh 0.13 (traverse_iterator)", &rays, |ray| {
            let query = bvh::ray::Ray::new(nalgebra::Point3::from(ray.origin.to_array()), nalgebra::Vector3::from(ray.direction.to_array()));
            binary.traverse_iterator(&query, &shapes).any(|shape| shape.index != ray.triangle && shape.hit(ray, pass))
        });
        println!("    disagrees with obvhs on {} rays", disagreements(&answers, &reference));
        for (name, bvh) in [("cirrus (best kernels)", &cirrus_bvh), ("cirrus (portable kernels)", &cirrus_portable)] {
            let answers = measure(name, &rays, |ray| bvh.blocked(ray.origin, ray.direction, f32::INFINITY, ray.triangle, back_faces));
            println!("    disagrees with obvhs on {} rays", disagreements(&answers, &reference));
        }
    }
    println!("nearest hit, back faces pass:");
    let reference = measure("obvhs 0.4 CWBVH (ray_traverse)", &rays, obvhs_nearest);
    for (name, bvh) in [("cirrus (best kernels)", &cirrus_bvh), ("cirrus (portable kernels)", &cirrus_portable)] {
        let answers =
            measure(name, &rays, |ray| bvh.cast(ray.origin, ray.direction, f32::INFINITY, ray.triangle, BackFaces::PassThrough).hit.is_some());
        println!("    disagrees with obvhs on {} rays", disagreements(&answers, &reference));
    }
}

/// A triangle for the `bvh` crate, with the same Möller–Trumbore test as cirrus's kernels.
struct Shape {
    corners: [Vec3; 3],
    node: usize,
    index: u32,
}

impl Shape {
    fn hit(&self, ray: &TestRay, pass_back_faces: bool) -> bool {
        let [corner, second, third] = self.corners;
        let (edge1, edge2) = (second - corner, third - corner);
        let p = ray.direction.cross(edge2);
        let det = edge1.dot(p);
        if det == 0.0 || (pass_back_faces && det < 0.0) {
            return false;
        }
        let t = ray.origin - corner;
        let (u, q) = (t.dot(p) / det, t.cross(edge1));
        let (v, distance) = (ray.direction.dot(q) / det, edge2.dot(q) / det);
        u >= 0.0 && v >= 0.0 && u + v <= 1.0 && distance > 0.0
    }
}

impl bvh::aabb::Bounded<f32, 3> for Shape {
    fn aabb(&self) -> bvh::aabb::Aabb<f32, 3> {
        let mut aabb = bvh::aabb::Aabb::empty();
        for corner in self.corners {
            aabb.grow_mut(&nalgebra::Point3::from(corner.to_array()));
        }
        aabb
    }
}

impl bvh::bounding_hierarchy::BHShape<f32, 3> for Shape {
    fn set_bh_node_index(&mut self, index: usize) {
        self.node = index;
    }

    fn bh_node_index(&self) -> usize {
        self.node
    }
}
