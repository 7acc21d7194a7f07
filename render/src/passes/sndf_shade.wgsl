// Deferred shading of S-NDFs on the GPU (the same sums as Sndf::shade_linear on the
// host): per texel, the bins' albedo sums times the per-bin albedo factors plus their
// counts times the per-bin highlights, over the rays, plus the background's share of the
// rays that hit nothing; then sRGB-encoded into RGBA8.
//
// The Rust twin of ShadeParams is in sndf.rs.

struct ShadeParams {
    width: u32,
    height: u32,
    bins: u32,
    rays: f32,
    // rgb: linear background.
    background: vec4<f32>,
    // 0: texels in rows; 1: in 64x64-texel tiles of 8x8 blocks, tiles_x tiles per row
    // (as sndf_accumulate.wgsl stores them).
    tiled: u32,
    tiles_x: u32,
    pad0: u32,
    pad1: u32,
};

@group(0) @binding(0) var<uniform> params: ShadeParams;
// Two per bin: the albedo factor (rgb) and the highlight (rgb).
@group(0) @binding(1) var<storage, read> table: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> hist: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read_write> pixels: array<u32>;

fn to_srgb(c: f32) -> f32 {
    if c <= 0.0031308 {
        return c * 12.92;
    }
    return 1.055 * pow(c, 1.0 / 2.4) - 0.055;
}

// One invocation per texel, in 8x8 blocks over the image (a 1-D dispatch would pass
// the 65535 workgroups per dimension at 4 Mi texels).
@compute @workgroup_size(8, 8)
fn shade(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= params.width || id.y >= params.height {
        return;
    }
    let t = id.y * params.width + id.x;
    let b2 = params.bins * params.bins;
    var texel = t;
    if params.tiled == 1u {
        let x = t % params.width;
        let y = t / params.width;
        let lx = x % 64u;
        let ly = y % 64u;
        let slot = (y / 64u) * params.tiles_x + x / 64u;
        texel = slot * 4096u + ((ly / 8u) * 8u + lx / 8u) * 64u + (ly % 8u) * 8u + lx % 8u;
    }
    var c = vec3<f32>(0.0);
    var hits = 0.0;
    for (var i = 0u; i < b2; i++) {
        let h = hist[texel * b2 + i];
        c += h.xyz * table[2u * i].xyz + h.w * table[2u * i + 1u].xyz;
        hits += h.w;
    }
    let miss = max(1.0 - hits / params.rays, 0.0);
    let lin = clamp(c / params.rays + miss * params.background.xyz, vec3<f32>(0.0), vec3<f32>(1.0));
    pixels[t] = pack4x8unorm(vec4<f32>(to_srgb(lin.x), to_srgb(lin.y), to_srgb(lin.z), 1.0));
}
