// Octahedral impostors: which frames of a `frames × frames` grid an impostor seen from a
// direction blends, and with what weights. The same arithmetic as cirrus's reference,
// `src/mesh/octahedral.rs` (a GPU test compares the two on thousands of directions); copy these
// functions into an engine's impostor shader.
//
// Conventions: +Y up; `direction` points from the object to the eye (need not be unit length).
// Frames sit at the grid's points: frame `j * frames + i` is seen from
// `impostor_decode(vec2(i, j) / (frames - 1))`. `hemi` chooses the hemi-octahedron (upper half of
// the sphere; views from below use the horizon's frames) or the full octahedron. A direction's
// grid cell is split along its anti-diagonal; the three frames at the corners of the half that
// holds it blend with its barycentric weights (they sum to 1; a frame's own direction gives it
// weight 1).

struct ImpostorBlend {
    frames: vec3<u32>,
    weights: vec3<f32>,
}

// 1 for 0 and above, -1 below (`sign` would give 0 at 0).
fn impostor_sign(value: f32) -> f32 {
    return select(-1.0, 1.0, value >= 0.0);
}

// The direction's point in the unit square.
fn impostor_encode(direction_in: vec3<f32>, hemi: bool) -> vec2<f32> {
    var direction = direction_in;
    if hemi {
        direction.y = max(direction.y, 0.0);
    }
    let sum = abs(direction.x) + abs(direction.y) + abs(direction.z);
    if sum <= 0.0 {
        return vec2<f32>(0.5, 0.5);
    }
    let d = direction / sum;
    var square: vec2<f32>;
    if hemi {
        square = vec2<f32>(d.x + d.z, d.x - d.z);
    } else if d.y >= 0.0 {
        square = vec2<f32>(d.x, d.z);
    } else {
        square = vec2<f32>((1.0 - abs(d.z)) * impostor_sign(d.x), (1.0 - abs(d.x)) * impostor_sign(d.z));
    }
    return clamp(square * 0.5 + 0.5, vec2<f32>(0.0, 0.0), vec2<f32>(1.0, 1.0));
}

// The unit direction of a point of the unit square (`impostor_encode`'s inverse): where frame
// (i, j) was rendered from, at uv = (i, j) / (frames - 1).
fn impostor_decode(uv: vec2<f32>, hemi: bool) -> vec3<f32> {
    let square = clamp(uv, vec2<f32>(0.0, 0.0), vec2<f32>(1.0, 1.0)) * 2.0 - 1.0;
    var direction: vec3<f32>;
    if hemi {
        let x = 0.5 * (square.x + square.y);
        let z = 0.5 * (square.x - square.y);
        direction = vec3<f32>(x, 1.0 - abs(x) - abs(z), z);
    } else {
        let y = 1.0 - abs(square.x) - abs(square.y);
        if y >= 0.0 {
            direction = vec3<f32>(square.x, y, square.y);
        } else {
            direction = vec3<f32>(
                (1.0 - abs(square.y)) * impostor_sign(square.x),
                y,
                (1.0 - abs(square.x)) * impostor_sign(square.y),
            );
        }
    }
    return normalize(direction);
}

// The three frames seen from `direction` and their weights.
fn impostor_blend(direction: vec3<f32>, frames: u32, hemi: bool) -> ImpostorBlend {
    let last = f32(frames - 1u);
    let grid = impostor_encode(direction, hemi) * last;
    let cell = min(floor(grid), vec2<f32>(last - 1.0, last - 1.0));
    let fraction = grid - cell;
    let base = u32(cell.y) * frames + u32(cell.x);
    if fraction.x + fraction.y <= 1.0 {
        return ImpostorBlend(
            vec3<u32>(base, base + 1u, base + frames),
            vec3<f32>(1.0 - fraction.x - fraction.y, fraction.x, fraction.y),
        );
    }
    return ImpostorBlend(
        vec3<u32>(base + frames + 1u, base + 1u, base + frames),
        vec3<f32>(fraction.x + fraction.y - 1.0, 1.0 - fraction.y, 1.0 - fraction.x),
    );
}
