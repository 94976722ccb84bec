// Preview renders: a mesh (the source, or a billboard-cloud LOD) under one orthographic camera,
// alpha-tested, double-sided, lit by one directional light plus ambient, on a neutral background.
// Alpha is 1 where a surface was drawn: the silhouette. `fs_impostor` draws an impostor's frame
// instead: unlit albedo, normal and depth.

struct Camera {
    view_projection: mat4x4f,
    // xyz: direction towards the light
    light: vec4f,
}

struct Material {
    // rgb: albedo factor (linear), a: constant opacity
    albedo: vec4f,
    // has albedo map, unused, unused, normal map stores z (else rebuilt)
    flags: vec4f,
    // alpha cutoff, unused...
    params: vec4f,
}

// Constants in read-only storage buffers, not uniform ones: lavapipe would compile a shader
// variant for every rebound uniform buffer (see `constants_entry` in gpu.rs).
@group(0) @binding(0) var<storage, read> camera: Camera;
@group(1) @binding(0) var<storage, read> material: Material;
@group(1) @binding(1) var linear_sampler: sampler;
@group(1) @binding(2) var albedo_map: texture_2d<f32>;
@group(1) @binding(3) var opacity_map: texture_2d<f32>;
@group(1) @binding(4) var normal_map: texture_2d<f32>;

// Whether the material has an opacity map and a normal map: a pipeline for each combination
// (`view_render::MapPipelines`, for `fs_main` and `fs_impostor` alike), so that a map the material
// lacks is not sampled at all (on llvmpipe every sample is a filtered fetch for each fragment,
// discarded ones included). An engine porting this shader reads the maps its material has.
override HAS_OPACITY_MAP: bool = true;
override HAS_NORMAL_MAP: bool = true;

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
}

@vertex
fn vs_main(input: VertexIn) -> VertexOut {
    var out: VertexOut;
    out.clip = camera.view_projection * vec4f(input.position, 1.0);
    out.normal = input.normal;
    out.uv = vec2f(input.uv.x, 1.0 - input.uv.y);
    out.tangent = input.tangent;
    return out;
}

// The surface at a fragment: its albedo (alpha-tested: discarded below the cutoff) and its
// shading normal, facing the camera.
struct Surface {
    albedo: vec3f,
    normal: vec3f,
}

fn surface(input: VertexOut, front: bool) -> Surface {
    let albedo_sample = textureSample(albedo_map, linear_sampler, input.uv);
    var mapped_opacity = 1.0;
    if (HAS_OPACITY_MAP) {
        mapped_opacity = textureSample(opacity_map, linear_sampler, input.uv).a;
    }
    let albedo = select(vec4f(1.0), albedo_sample, material.flags.x > 0.5) * vec4f(material.albedo.rgb, 1.0);
    let opacity = albedo.a * mapped_opacity * material.albedo.a;
    if (opacity < material.params.x) {
        discard;
    }
    var n = normalize(input.normal);
    if (HAS_NORMAL_MAP) {
        let normal_sample = textureSample(normal_map, linear_sampler, input.uv);
        let t = normalize(input.tangent.xyz - n * dot(n, input.tangent.xyz));
        let b = cross(n, t) * input.tangent.w;
        var mapped = normal_sample.xyz * 2.0 - 1.0;
        if (material.flags.w < 0.5) {
            mapped.z = sqrt(clamp(1.0 - mapped.x * mapped.x - mapped.y * mapped.y, 0.0, 1.0));
        }
        n = normalize(t * mapped.x + b * mapped.y + n * mapped.z);
    }
    if (!front) {
        n = -n;
    }
    return Surface(albedo.rgb, n);
}

@fragment
fn fs_main(input: VertexOut, @builtin(front_facing) front: bool) -> @location(0) vec4f {
    let drawn = surface(input, front);
    let light = 0.35 + 0.65 * abs(dot(drawn.normal, normalize(camera.light.xyz)));
    return vec4f(drawn.albedo * light, 1.0);
}

// An impostor frame: the unlit albedo (alpha 1 where drawn) and the normal (world space, as
// 0.5 + 0.5 n) with the depth (0 at the bounding sphere's near side, 1 at its far side).
struct FrameOut {
    @location(0) albedo: vec4f,
    @location(1) normal_depth: vec4f,
}

@fragment
fn fs_impostor(input: VertexOut, @builtin(front_facing) front: bool) -> FrameOut {
    let drawn = surface(input, front);
    var out: FrameOut;
    out.albedo = vec4f(drawn.albedo, 1.0);
    out.normal_depth = vec4f(drawn.normal * 0.5 + 0.5, input.clip.z);
    return out;
}
