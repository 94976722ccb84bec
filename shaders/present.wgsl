// Shows a rendered RGBA8 image in a window: a full-screen triangle that loads the image's texels
// centred on the window, the rest of the window in the images' background grey. The image holds sRGB-encoded bytes in an
// Rgba8Unorm texture; for an sRGB surface they are decoded first so the surface re-encodes them.

struct Present {
    // xy: image texel under window pixel (0, 0); z: 1 when the surface encodes sRGB itself.
    offset_and_decode: vec4<f32>,
};

// A storage buffer like every constant in cirrus (see `constants_entry` in gpu.rs).
@group(0) @binding(0) var<storage, read> present: Present;
@group(0) @binding(1) var image: texture_2d<f32>;

@vertex
fn vs_main(@builtin(vertex_index) index: u32) -> @builtin(position) vec4<f32> {
    let corner = vec2<f32>(f32((index << 1u) & 2u), f32(index & 2u));
    return vec4<f32>(corner * 2.0 - 1.0, 0.0, 1.0);
}

fn srgb_to_linear(encoded: vec3<f32>) -> vec3<f32> {
    let low = encoded / 12.92;
    let high = pow((encoded + 0.055) / 1.055, vec3<f32>(2.4));
    return select(high, low, encoded <= vec3<f32>(0.04045));
}

@fragment
fn fs_main(@builtin(position) position: vec4<f32>) -> @location(0) vec4<f32> {
    let size = vec2<i32>(textureDimensions(image));
    let texel = vec2<i32>(floor(position.xy + present.offset_and_decode.xy));
    var colour = vec3<f32>(128.0 / 255.0);
    if all(texel >= vec2<i32>(0)) && all(texel < size) {
        colour = textureLoad(image, texel, 0).rgb;
    }
    if present.offset_and_decode.z > 0.5 {
        return vec4<f32>(srgb_to_linear(colour), 1.0);
    }
    return vec4<f32>(colour, 1.0);
}
