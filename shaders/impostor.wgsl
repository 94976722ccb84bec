// Octahedral impostors: which frames of a `frames × frames` grid an impostor seen from a
// direction blends, and with what weights. The same arithmetic as cirrus's reference,
// `src/mesh/octahedral.rs` (a GPU test compares the two on thousands of directions); copy these
// functions into an engine's impostor shader.
//
// Conventions: +Y up; `direction` points from the object to the eye (need not be unit length).
// Frames sit at the grid's points: frame `j * frames + i` is seen from
// `impostor_decode(vec2(i, j) / (frames - 1))`. `hemi` chooses the hemi-octahedron (upper half of
// the sphere; views from below use the horizon's frames) or the full octahedron. A direction's
// grid cell is split along its anti-diagonal (on the full octahedron, in the two quadrants where
// the equator runs the other way, along its main diagonal); the three frames at the corners of
// the half that holds it blend with its barycentric weights (they sum to 1; a frame's own direction gives it
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
    // The full octahedron's cells split along the equator's direction in their quadrant.
    let centre = (cell + 0.5) / last - 0.5;
    if !hemi && centre.x * centre.y < 0.0 {
        if fraction.x >= fraction.y {
            return ImpostorBlend(
                vec3<u32>(base, base + 1u, base + frames + 1u),
                vec3<f32>(1.0 - fraction.x, fraction.x - fraction.y, fraction.y),
            );
        }
        return ImpostorBlend(
            vec3<u32>(base, base + frames, base + frames + 1u),
            vec3<f32>(1.0 - fraction.y, fraction.y - fraction.x, fraction.x),
        );
    }
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

// The image axes of the frame seen from `direction` (object to eye): a right-handed camera with
// world +Y up (-Z up within 0.1° of straight above or below). `mesh::octahedral::frame_axes`.
struct ImpostorAxes {
    right: vec3<f32>,
    up: vec3<f32>,
}

fn impostor_frame_axes(direction_in: vec3<f32>) -> ImpostorAxes {
    let direction = normalize(direction_in);
    let forward = -direction;
    var hint = vec3<f32>(0.0, 1.0, 0.0);
    if abs(direction.y) > 0.999998 {
        hint = vec3<f32>(0.0, 0.0, -1.0);
    }
    let right = normalize(cross(forward, hint));
    return ImpostorAxes(right, cross(right, forward));
}

// ---------------------------------------------------------------------------------------------
// A reference renderer (cirrus's preview draws impostors with it): one camera-facing polygon
// over the bounding sphere (`hull` of `impostor.json`: an octagon holding the mesh's outline from
// every direction, or the sphere's square); each fragment samples the three frames of the view's
// blend, each at the point of the view ray that meets that frame's depth (one parallax step), and
// blends their albedo and normal by weight and coverage, alpha-tested at the cutoff.
//
// Atlases: frame `j * frames + i` at column `i`, row `j`, each with its mips; albedo (sRGB,
// coverage in alpha), normal (`0.5 + 0.5 n` in RG, in the frame's axes: x right, y up, z towards
// the frame's eye, rebuilt from x and y, as a tangent-space normal map stores it: BC5), depth (R:
// 0 at the sphere's near side, 1 at its far side, along the frame's direction: BC4). Each frame
// shows the part `impostor_rects[frame]` = (u0, v0, u1, v1) of the sphere's image (u along the
// frame's right, v down its up axis, 0..1 across the sphere): the mesh's bounds from that
// direction (`frame_rects` in impostor.json); (0, 0, 1, 1) is the whole sphere.

struct ImpostorView {
    view_projection: mat4x4<f32>,
    // xyz: object to eye (an orthographic camera's direction)
    eye: vec4<f32>,
    // xyz: towards the light
    light: vec4<f32>,
}

struct ImpostorParams {
    // xyz: the bounding sphere's centre, w: its radius
    sphere: vec4<f32>,
    // frames per side, 1 for a hemi-octahedron, unused, unused
    grid: vec4<u32>,
    // alpha cutoff; how many times the normal atlas's side and the depth atlas's halve the albedo
    // atlas's (0, 1 or 2: log2 of the ratio of the sides); unused
    params: vec4<f32>,
    // The polygon drawn, eight points [x, y] two a vector (xy, zw), in the view's right and up
    // axes through the sphere's centre, in units of its radius: a fitted octagon, or the
    // sphere's square (its last points repeated).
    hull: array<vec4<f32>, 4>,
}

@group(0) @binding(0) var<storage, read> impostor_view: ImpostorView;
@group(0) @binding(1) var<storage, read> impostor: ImpostorParams;
@group(0) @binding(2) var impostor_sampler: sampler;
@group(0) @binding(3) var albedo_atlas: texture_2d<f32>;
@group(0) @binding(4) var normal_atlas: texture_2d<f32>;
@group(0) @binding(5) var depth_atlas: texture_2d<f32>;
@group(0) @binding(6) var<storage, read> impostor_rects: array<vec4<f32>>;

// What the vertex stage passes on: the point drawn, and what is the same at every fragment of a
// view (the three frames of its blend, their weights, and each frame's direction and image axes),
// worked out once a vertex instead of once a fragment.
struct ImpostorVertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) world: vec3<f32>,
    @location(1) @interpolate(flat) frames: vec3<u32>,
    @location(2) @interpolate(flat) weights: vec3<f32>,
    @location(3) @interpolate(flat) direction0: vec3<f32>,
    @location(4) @interpolate(flat) right0: vec3<f32>,
    @location(5) @interpolate(flat) up0: vec3<f32>,
    @location(6) @interpolate(flat) direction1: vec3<f32>,
    @location(7) @interpolate(flat) right1: vec3<f32>,
    @location(8) @interpolate(flat) up1: vec3<f32>,
    @location(9) @interpolate(flat) direction2: vec3<f32>,
    @location(10) @interpolate(flat) right2: vec3<f32>,
    @location(11) @interpolate(flat) up2: vec3<f32>,
}

// One frame of a view's blend, as the fragment stage reads it.
struct ImpostorFrame {
    index: u32,
    weight: f32,
    // where it was rendered from (unit, object to eye)
    direction: vec3<f32>,
    axes: ImpostorAxes,
}

// Point `k` (0..8) of the polygon drawn.
fn impostor_hull_point(k: u32) -> vec2<f32> {
    let pair = impostor.hull[k / 2u];
    return select(pair.xy, pair.zw, k % 2u == 1u);
}

// Frame `frame`'s direction and axes.
fn impostor_frame(frame: u32, weight: f32) -> ImpostorFrame {
    let frames = impostor.grid.x;
    let cell = vec2<f32>(f32(frame % frames), f32(frame / frames));
    let direction = impostor_decode(cell / f32(frames - 1u), impostor.grid.y != 0u);
    return ImpostorFrame(frame, weight, direction, impostor_frame_axes(direction));
}

// 18 vertices: the polygon as a fan of six triangles (0, t + 1, t + 2).
@vertex
fn impostor_vs(@builtin(vertex_index) index: u32) -> ImpostorVertexOut {
    let triangle = index / 3u;
    let corner_of_triangle = index % 3u;
    let point = select(triangle + corner_of_triangle, 0u, corner_of_triangle == 0u);
    let axes = impostor_frame_axes(impostor_view.eye.xyz);
    let corner = impostor_hull_point(point);
    let world = impostor.sphere.xyz + (axes.right * corner.x + axes.up * corner.y) * impostor.sphere.w;
    var out: ImpostorVertexOut;
    out.clip = impostor_view.view_projection * vec4<f32>(world, 1.0);
    out.world = world;
    let blend = impostor_blend(impostor_view.eye.xyz, impostor.grid.x, impostor.grid.y != 0u);
    out.frames = blend.frames;
    out.weights = blend.weights;
    let first = impostor_frame(blend.frames.x, blend.weights.x);
    let second = impostor_frame(blend.frames.y, blend.weights.y);
    let third = impostor_frame(blend.frames.z, blend.weights.z);
    out.direction0 = first.direction;
    out.right0 = first.axes.right;
    out.up0 = first.axes.up;
    out.direction1 = second.direction;
    out.right1 = second.axes.right;
    out.up1 = second.axes.up;
    out.direction2 = third.direction;
    out.right2 = third.axes.right;
    out.up2 = third.axes.up;
    return out;
}

// Frame `k` (0..3) of the view's blend, from the vertex stage's outputs.
fn impostor_blend_frame(input: ImpostorVertexOut, k: u32) -> ImpostorFrame {
    switch k {
        case 0u: {
            let axes = ImpostorAxes(input.right0, input.up0);
            return ImpostorFrame(input.frames.x, input.weights.x, input.direction0, axes);
        }
        case 1u: {
            let axes = ImpostorAxes(input.right1, input.up1);
            return ImpostorFrame(input.frames.y, input.weights.y, input.direction1, axes);
        }
        default: {
            let axes = ImpostorAxes(input.right2, input.up2);
            return ImpostorFrame(input.frames.z, input.weights.z, input.direction2, axes);
        }
    }
}

// A point of the sphere's image (0..1) in frame `frame`'s own image (0..1 across the part it
// shows).
fn impostor_in_rect(frame: u32, uv: vec2<f32>) -> vec2<f32> {
    let rect = impostor_rects[frame];
    return (uv - rect.xy) / max(rect.zw - rect.xy, vec2<f32>(1e-6));
}

// The mip level of an atlas whose side is the albedo atlas's halved `halvings` times that shows
// what level `lod` of the albedo atlas shows: the normal and depth atlases may be stored at a half
// or a quarter of the albedo's side (the same frames, the same coordinates), their level 0 being
// the albedo's level 1 or 2 (`impostor.params`).
fn impostor_smaller_lod(halvings: f32, lod: f32) -> f32 {
    return max(lod - halvings, 0.0);
}

// `shown_frame`'s texel under the view ray through `world`, in the frame's own image (0..1):
// where the ray crosses the frame's plane through the centre, then (parallax) where it meets the
// depth the frame shows there (the depth atlas read at mip level `depth_lod`), twice; outside
// 0..1 when the ray leaves the frame.
fn impostor_frame_uv(shown_frame: ImpostorFrame, world: vec3<f32>, depth_lod: f32) -> vec2<f32> {
    let frames = impostor.grid.x;
    let frame = shown_frame.index;
    let cell = vec2<f32>(f32(frame % frames), f32(frame / frames));
    let direction = shown_frame.direction;
    let axes = shown_frame.axes;
    let radius = impostor.sphere.w;
    let eye = normalize(impostor_view.eye.xyz);
    let start = world - impostor.sphere.xyz;
    let along = max(dot(eye, direction), 0.05);
    // The ray is start - t eye; a point of it at height h along the frame's direction has
    // t = (dot(start, direction) - h) / along.
    var point = start - eye * (dot(start, direction) / along);
    var uv = impostor_in_rect(frame, vec2<f32>(dot(point, axes.right), -dot(point, axes.up)) / (2.0 * radius) + 0.5);
    for (var step = 0; step < 2; step = step + 1) {
        let texel = (cell + clamp(uv, vec2<f32>(0.0), vec2<f32>(1.0))) / f32(frames);
        let shown = textureSampleLevel(depth_atlas, impostor_sampler, texel, depth_lod).r;
        let height = radius - 2.0 * radius * shown;
        point = start - eye * ((dot(start, direction) - height) / along);
        uv = impostor_in_rect(frame, vec2<f32>(dot(point, axes.right), -dot(point, axes.up)) / (2.0 * radius) + 0.5);
    }
    return uv;
}

@fragment
fn impostor_fs(input: ImpostorVertexOut) -> @location(0) vec4<f32> {
    let frames = impostor.grid.x;
    // Frame texels per screen pixel across the whole sphere (taken before any branch); each
    // frame's mip level scales it by the share of the sphere's image the frame shows.
    let frame_texels = f32(textureDimensions(albedo_atlas).x) / f32(frames);
    let pixel = max(length(dpdx(input.world)), length(dpdy(input.world)));
    let texels_per_pixel = pixel * frame_texels / (2.0 * impostor.sphere.w);
    var albedo = vec3<f32>(0.0);
    var normal = vec3<f32>(0.0);
    var coverage = 0.0;
    for (var k = 0u; k < 3u; k = k + 1u) {
        let shown_frame = impostor_blend_frame(input, k);
        let frame = shown_frame.index;
        let rect = impostor_rects[frame];
        let shown = max(min(rect.z - rect.x, rect.w - rect.y), 1e-6);
        let lod = max(log2(texels_per_pixel / shown), 0.0);
        let uv = impostor_frame_uv(shown_frame, input.world, impostor_smaller_lod(impostor.params.z, lod));
        if any(uv < vec2<f32>(0.0)) || any(uv > vec2<f32>(1.0)) {
            continue;
        }
        let cell = vec2<f32>(f32(frame % frames), f32(frame / frames));
        let at = (cell + uv) / f32(frames);
        let colour = textureSampleLevel(albedo_atlas, impostor_sampler, at, lod);
        let xy = textureSampleLevel(normal_atlas, impostor_sampler, at, impostor_smaller_lod(impostor.params.y, lod)).xy
            * 2.0 - 1.0;
        let z = sqrt(max(1.0 - dot(xy, xy), 0.0));
        let axes = shown_frame.axes;
        let weight = shown_frame.weight * colour.a;
        albedo += colour.rgb * weight;
        normal += (axes.right * xy.x + axes.up * xy.y + shown_frame.direction * z) * weight;
        coverage += weight;
    }
    if coverage < impostor.params.x || coverage <= 0.0 {
        discard;
    }
    let n = normalize(normal);
    let light = 0.35 + 0.65 * abs(dot(n, normalize(impostor_view.light.xyz)));
    return vec4<f32>(albedo / coverage * light, 1.0);
}
