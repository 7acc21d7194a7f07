// Supersampling: the jittered sample images are summed with weight 1/N in single
// precision, ping-ponging between two float targets (each pass reads the sum so far and
// writes it plus the new sample into the other; the first pass writes the weighted
// sample alone), and the sum is finally copied into the sRGB output (the format does
// the encoding). One full-screen triangle, no vertex buffer.
//
// Not additive blending into a half-float target: each sum rounds to 11 bits there,
// and adding the same small value N times rounds the same way every time (a flat
// background at 256 samples came out 4/255 too dark).

struct Params {
    // x: weight of the source image.
    weight: vec4<f32>,
};

@group(0) @binding(0) var src: texture_2d<f32>;
@group(0) @binding(1) var<storage, read> params: Params;
// The sum so far (bound, and unread, in the first and resolve passes too).
@group(0) @binding(2) var sum: texture_2d<f32>;

@vertex
fn vs_fullscreen(@builtin(vertex_index) vi: u32) -> @builtin(position) vec4<f32> {
    let uv = vec2<f32>(f32((vi << 1u) & 2u), f32(vi & 2u));
    return vec4<f32>(uv * 2.0 - 1.0, 0.0, 1.0);
}

@fragment
fn fs_weighted(@builtin(position) pos: vec4<f32>) -> @location(0) vec4<f32> {
    return textureLoad(src, vec2<i32>(pos.xy), 0) * params.weight.x;
}

@fragment
fn fs_sum(@builtin(position) pos: vec4<f32>) -> @location(0) vec4<f32> {
    let p = vec2<i32>(pos.xy);
    return textureLoad(sum, p, 0) + textureLoad(src, p, 0) * params.weight.x;
}
