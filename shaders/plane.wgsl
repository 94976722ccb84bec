// Per-plane texture bake: an orthographic camera on one billboard plane's frame renders that
// plane's faces into albedo + alpha, normal (in the plane's tangent frame), metallic /
// roughness / AO, and height (signed distance from the plane over ±ε).

struct Frame {
    origin: vec4f,
    x_axis: vec4f,
    y_axis: vec4f,
    normal: vec4f,
    // width, height (world units), epsilon, alpha cutoff
    size: vec4f,
}

struct Material {
    // rgb: albedo factor (linear), a: constant opacity
    albedo: vec4f,
    // metallic, roughness, ao, unused
    params: vec4f,
    // 1.0 where the map exists: albedo, opacity, normal, metallic
    has_a: vec4f,
    // roughness, ao, has uvs, unused
    has_b: vec4f,
}

// Constants in read-only storage buffers, not uniform ones: lavapipe would compile a shader
// variant for every rebound uniform buffer (see `constants_entry` in gpu.rs).
@group(0) @binding(0) var<storage, read> frame: Frame;
@group(1) @binding(0) var<storage, read> material: Material;
@group(1) @binding(1) var linear_sampler: sampler;
@group(1) @binding(2) var albedo_map: texture_2d<f32>;
@group(1) @binding(3) var opacity_map: texture_2d<f32>;
@group(1) @binding(4) var normal_map: texture_2d<f32>;
@group(1) @binding(5) var metallic_map: texture_2d<f32>;
@group(1) @binding(6) var roughness_map: texture_2d<f32>;
@group(1) @binding(7) var ao_map: texture_2d<f32>;

struct VertexIn {
    @location(0) position: vec3f,
    @location(1) normal: vec3f,
    @location(2) uv: vec2f,
    @location(3) tangent: vec4f,
}

struct VertexOut {
    @builtin(position) clip: vec4f,
    @location(0) normal: vec3f,
    @location(1) uv: vec2f,
    @location(2) tangent: vec4f,
    @location(3) distance: f32,
}

@vertex
fn vs_main(input: VertexIn) -> VertexOut {
    let local = input.position - frame.origin.xyz;
    let x = dot(local, frame.x_axis.xyz) / frame.size.x * 2.0 - 1.0;
    let y = dot(local, frame.y_axis.xyz) / frame.size.y * 2.0 - 1.0;
    let distance = dot(local, frame.normal.xyz);
    // Nearest to the viewer on the +normal side wins the depth test.
    let depth = clamp(0.5 - distance / (2.0 * frame.size.z), 0.0, 1.0);
    var out: VertexOut;
    out.clip = vec4f(x, y, depth, 1.0);
    out.normal = input.normal;
    out.uv = vec2f(input.uv.x, 1.0 - input.uv.y);
    out.tangent = input.tangent;
    out.distance = distance;
    return out;
}

struct Targets {
    @location(0) albedo: vec4f,
    @location(1) normal: vec4f,
    @location(2) mra: vec4f,
    @location(3) height: vec4f,
}

fn sample_or(map: texture_2d<f32>, has: f32, uv: vec2f, fallback: vec4f) -> vec4f {
    let value = textureSample(map, linear_sampler, uv);
    return select(fallback, value, has > 0.5);
}

fn albedo_at(uv: vec2f) -> vec4f {
    return sample_or(albedo_map, material.has_a.x, uv, vec4f(1.0)) * vec4f(material.albedo.rgb, 1.0);
}

fn opacity_at(uv: vec2f, albedo: vec4f) -> f32 {
    return albedo.a * sample_or(opacity_map, material.has_a.y, uv, vec4f(1.0)).a * material.albedo.a;
}

// Coverage alone, at several samples per texel (the distance-field alpha's edges): the same
// alpha test as `fs_main`, one byte written, no depth, so that it costs a fraction of the
// full shading that runs once per texel.
@fragment
fn fs_coverage(input: VertexOut) -> @location(0) vec4f {
    let albedo = albedo_at(input.uv);
    if (opacity_at(input.uv, albedo) < frame.size.w) {
        discard;
    }
    return vec4f(1.0);
}

@fragment
fn fs_main(input: VertexOut) -> Targets {
    let uv = input.uv;
    let albedo = albedo_at(uv);
    let opacity = opacity_at(uv, albedo);
    if (opacity < frame.size.w) {
        discard;
    }
    var n = normalize(input.normal);
    if (material.has_a.z > 0.5) {
        let t = normalize(input.tangent.xyz - n * dot(n, input.tangent.xyz));
        let b = cross(n, t) * input.tangent.w;
        let mapped = textureSample(normal_map, linear_sampler, uv).xyz * 2.0 - 1.0;
        n = normalize(t * mapped.x + b * mapped.y + n * mapped.z);
    }
    // Expressed in the plane's frame, facing out of the plane (double-sided sources).
    var plane_normal = vec3f(dot(n, frame.x_axis.xyz), dot(n, frame.y_axis.xyz), dot(n, frame.normal.xyz));
    if (plane_normal.z < 0.0) {
        plane_normal = -plane_normal;
    }
    let metallic = sample_or(metallic_map, material.has_a.w, uv, vec4f(material.params.x)).r;
    let roughness = sample_or(roughness_map, material.has_b.x, uv, vec4f(material.params.y)).r;
    let ao = sample_or(ao_map, material.has_b.y, uv, vec4f(material.params.z)).r;
    var out: Targets;
    out.albedo = vec4f(albedo.rgb, 1.0);
    out.normal = vec4f(normalize(plane_normal) * 0.5 + 0.5, 1.0);
    out.mra = vec4f(metallic, roughness, ao, 1.0);
    out.height = vec4f(clamp(input.distance / frame.size.z * 0.5 + 0.5, 0.0, 1.0), 0.0, 0.0, 1.0);
    return out;
}
