// Supersampling: each jittered sample image is added into a float accumulation target
// with weight 1/N (additive blending), and the sum is finally copied into the sRGB
// output (the format does the encoding). One full-screen triangle, no vertex buffer.

struct Params {
    // x: weight of the source image.
    weight: vec4<f32>,
};

@group(0) @binding(0) var src: texture_2d<f32>;
@group(0) @binding(1) var<uniform> params: Params;

@vertex
fn vs_fullscreen(@builtin(vertex_index) vi: u32) -> @builtin(position) vec4<f32> {
    let uv = vec2<f32>(f32((vi << 1u) & 2u), f32(vi & 2u));
    return vec4<f32>(uv * 2.0 - 1.0, 0.0, 1.0);
}

@fragment
fn fs_weighted(@builtin(position) pos: vec4<f32>) -> @location(0) vec4<f32> {
    return textureLoad(src, vec2<i32>(pos.xy), 0) * params.weight.x;
}
