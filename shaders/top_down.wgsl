// Top-down depth: a mesh seen orthographically along −Y over an XZ footprint, each texel
// keeping the highest surface's Y (relative to the footprint's lowest Y, for precision).
// Column x runs along +X, row y along +Z (row 0 at the footprint's lowest Z).

struct Footprint {
    // min x, min z, 1 / width, 1 / depth
    area: vec4f,
    // lowest y, 1 / (highest y − lowest y), unused, unused
    heights: vec4f,
}

// A read-only storage buffer, as every cirrus shader's constants (see `constants_entry`).
@group(0) @binding(0) var<storage, read> footprint: Footprint;

struct VertexOut {
    @builtin(position) clip: vec4f,
    @location(0) height: f32,
}

@vertex
fn vs_main(@location(0) position: vec3f) -> VertexOut {
    let x = (position.x - footprint.area.x) * footprint.area.z;
    let z = (position.z - footprint.area.y) * footprint.area.w;
    let height = position.y - footprint.heights.x;
    var out: VertexOut;
    // Highest first: depth 0 at the top of the range, 1 at its bottom.
    let depth = clamp(1.0 - height * footprint.heights.y, 0.0, 1.0);
    out.clip = vec4f(x * 2.0 - 1.0, 1.0 - z * 2.0, depth, 1.0);
    out.height = height;
    return out;
}

@fragment
fn fs_main(in: VertexOut) -> @location(0) vec4f {
    return vec4f(in.height, 0.0, 0.0, 1.0);
}
