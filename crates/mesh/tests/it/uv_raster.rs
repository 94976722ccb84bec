//! The one UV rasteriser: conservative coverage with the nearest point of the triangle as the
//! sample of edge texels, both windings alike, overlaps counted, tiles equal to the whole.

use mesh::uv_raster::{rasterize_uv, TexelRegion, UvCoverage};

const SIZE: u32 = 32;

fn whole() -> TexelRegion {
    TexelRegion { x: 0, y: 0, width: SIZE, height: SIZE }
}

/// The UV point a sample stands for.
fn sample_uv(uvs: &[[f32; 2]], triangle: [u32; 3], barycentric: [f32; 3]) -> [f32; 2] {
    let mut uv = [0.0; 2];
    for corner in 0..3 {
        uv[0] += barycentric[corner] * uvs[triangle[corner] as usize][0];
        uv[1] += barycentric[corner] * uvs[triangle[corner] as usize][1];
    }
    uv
}

fn covered(coverage: &UvCoverage) -> usize {
    coverage.samples.iter().filter(|sample| sample.is_some()).count()
}

#[test]
fn interior_texels_sample_their_centre_and_edge_texels_the_nearest_point_of_the_triangle() {
    let uvs = [[0.1f32, 0.1], [0.83, 0.22], [0.3, 0.91]];
    let triangles = [[0u32, 1, 2]];
    let coverage = rasterize_uv(&uvs, &triangles, &[0], (SIZE, SIZE), whole());
    let (mut inside, mut edge) = (0, 0);
    for y in 0..SIZE {
        for x in 0..SIZE {
            let Some(sample) = coverage.sample(x, y) else { continue };
            assert!(sample.barycentric.iter().all(|&weight| weight >= 0.0), "({x}, {y}): {sample:?}");
            assert!((sample.barycentric.iter().sum::<f32>() - 1.0).abs() < 1e-5);
            let [u, v] = sample_uv(&uvs, triangles[0], sample.barycentric);
            let (px, py) = (u * SIZE as f32, (1.0 - v) * SIZE as f32);
            let (cx, cy) = (x as f32 + 0.5, y as f32 + 0.5);
            if sample.centre_inside {
                inside += 1;
                assert!((px - cx).abs() < 1e-4 && (py - cy).abs() < 1e-4, "({x}, {y}) samples its centre");
            } else {
                edge += 1;
                // The nearest point lies on the triangle's border, inside the texel's reach.
                assert!((px - cx).hypot(py - cy) <= std::f32::consts::SQRT_2 / 2.0 + 1e-4, "({x}, {y})");
            }
        }
    }
    // Twice the area in texels is about the interior count; the border adds the perimeter.
    let area = 0.5 * ((0.83 - 0.1) * (0.91 - 0.1) - (0.3 - 0.1) * (0.22 - 0.1)) * (SIZE * SIZE) as f32;
    assert!((inside as f32 - area).abs() < 0.1 * area, "{inside} interior texels for an area of {area}");
    assert!(edge > 0);
}

#[test]
fn both_windings_cover_alike_and_a_texel_smaller_triangle_still_covers_its_texel() {
    let uvs = [[0.1f32, 0.1], [0.83, 0.22], [0.3, 0.91]];
    let forward = rasterize_uv(&uvs, &[[0, 1, 2]], &[0], (SIZE, SIZE), whole());
    let mirrored = rasterize_uv(&uvs, &[[0, 2, 1]], &[0], (SIZE, SIZE), whole());
    for (a, b) in forward.samples.iter().zip(&mirrored.samples) {
        assert_eq!(a.is_some(), b.is_some());
        if let (Some(a), Some(b)) = (a, b) {
            assert_eq!(a.centre_inside, b.centre_inside);
            assert!(
                (a.barycentric[1] - b.barycentric[2]).abs() < 1e-5
                    && (a.barycentric[0] - b.barycentric[0]).abs() < 1e-5
            );
        }
    }
    // A sliver inside texel (5, 7), not over its centre: covered, sampled on its border.
    let tiny = [
        [5.1 / SIZE as f32, 1.0 - 7.1 / SIZE as f32],
        [5.3 / SIZE as f32, 1.0 - 7.1 / SIZE as f32],
        [5.1 / SIZE as f32, 1.0 - 7.3 / SIZE as f32],
    ];
    let coverage = rasterize_uv(&tiny, &[[0, 1, 2]], &[0], (SIZE, SIZE), whole());
    assert_eq!(covered(&coverage), 1);
    assert!(coverage.sample(5, 7).is_some_and(|sample| !sample.centre_inside));
}

#[test]
fn a_quad_covers_its_square_once_and_overlapping_islands_are_counted() {
    // A quad over texels 8..24 (two triangles sharing an edge): no overlap.
    let (low, high) = (8.0 / SIZE as f32, 24.0 / SIZE as f32);
    let mut uvs = vec![[low, low], [high, low], [high, high], [low, high]];
    let mut triangles = vec![[0u32, 1, 2], [0, 2, 3]];
    let quad = rasterize_uv(&uvs, &triangles, &[0, 1], (SIZE, SIZE), whole());
    assert_eq!(quad.overlapping, 0);
    assert_eq!(quad.samples.iter().filter(|sample| sample.is_some_and(|sample| sample.centre_inside)).count(), 16 * 16);
    // A second island over the quad's right half (its own vertices): 8 × 16 texels overlap,
    // and the first triangles keep them.
    let middle = 16.0 / SIZE as f32;
    uvs.extend([[middle, low], [high, low], [high, high], [middle, high]]);
    triangles.extend([[4, 5, 6], [4, 6, 7]]);
    let both = rasterize_uv(&uvs, &triangles, &[0, 1, 2, 3], (SIZE, SIZE), whole());
    assert_eq!(both.overlapping, 8 * 16);
    assert!(both.samples.iter().flatten().filter(|sample| sample.centre_inside).all(|sample| sample.triangle < 2));
}

#[test]
fn tiles_rasterised_one_by_one_equal_the_whole_image() {
    // A fan of four triangles, then an island of its own over their middle.
    let uvs = [[0.05f32, 0.1], [0.9, 0.15], [0.4, 0.95], [0.97, 0.8], [0.2, 0.5], [0.3, 0.3], [0.7, 0.3], [0.5, 0.7]];
    let triangles = [[0u32, 1, 2], [1, 3, 2], [0, 2, 4], [4, 1, 3], [5, 6, 7]];
    let selected = [0, 1, 2, 3, 4];
    let whole_image = rasterize_uv(&uvs, &triangles, &selected, (SIZE, SIZE), whole());
    let mut overlapping = 0;
    for tile_y in 0..4 {
        for tile_x in 0..4 {
            let region = TexelRegion { x: tile_x * 8, y: tile_y * 8, width: 8, height: 8 };
            let tile = rasterize_uv(&uvs, &triangles, &selected, (SIZE, SIZE), region);
            overlapping += tile.overlapping;
            for y in region.y..region.y + 8 {
                for x in region.x..region.x + 8 {
                    assert_eq!(tile.sample(x, y), whole_image.sample(x, y), "({x}, {y})");
                }
            }
        }
    }
    assert_eq!(overlapping, whole_image.overlapping);
    assert!(whole_image.overlapping > 0, "the island overlaps the fan");
}
