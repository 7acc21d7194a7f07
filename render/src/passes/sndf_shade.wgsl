// Deferred shading of S-NDFs on the GPU (the same sums as Sndf::shade_linear on the
// host): per texel, the bins' albedo sums times the per-bin albedo factors plus their
// counts times the per-bin highlights, over the rays, plus the background's share of the
// rays that hit nothing; then sRGB-encoded into RGBA8. With a grid of view directions the
// texel interpolates its highlights, and, binned along each texel's ray, its albedo
// factors too, between the four grid points around it.
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
    // View directions per axis of the grid; 1: the view axis for every texel.
    grid: u32,
    // 1: binned along each texel's ray; the grid holds both entries of every bin.
    ray_frame: u32,
};

@group(0) @binding(0) var<storage, read> params: ShadeParams;
// Two per bin: the albedo factor (rgb) and the highlight (rgb) towards the view axis;
// then, with a grid, grid x grid view directions (rows from the image's top left
// corner), interpolated bilinearly per texel: each the highlights (bins^2 entries) or,
// binned along rays, the albedo factor and highlight of each bin (2 bins^2).
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
    // The texel's four grid points and weights (as grid_weights in sndf.rs).
    var at = vec4<u32>(0u);
    var w = vec4<f32>(1.0, 0.0, 0.0, 0.0);
    let g = params.grid;
    if g > 1u {
        let last = f32(g - 1u);
        let f = clamp(
            (vec2<f32>(f32(id.x), f32(id.y)) + 0.5)
                / vec2<f32>(f32(params.width), f32(params.height)) * last,
            vec2<f32>(0.0),
            vec2<f32>(last),
        );
        let k = min(vec2<u32>(floor(f)), vec2<u32>(g - 2u));
        let t = f - vec2<f32>(k);
        let base = 2u * b2;
        // Entries per grid point.
        let per = select(b2, 2u * b2, params.ray_frame == 1u);
        at = base + per * vec4<u32>(
            k.y * g + k.x,
            k.y * g + k.x + 1u,
            (k.y + 1u) * g + k.x,
            (k.y + 1u) * g + k.x + 1u,
        );
        w = vec4<f32>((1.0 - t.x) * (1.0 - t.y), t.x * (1.0 - t.y), (1.0 - t.x) * t.y, t.x * t.y);
    }
    var c = vec3<f32>(0.0);
    var hits = 0.0;
    for (var i = 0u; i < b2; i++) {
        let h = hist[texel * b2 + i];
        var a = table[2u * i].xyz;
        var s = table[2u * i + 1u].xyz;
        if g > 1u && params.ray_frame == 1u {
            let j = 2u * i;
            a = w.x * table[at.x + j].xyz + w.y * table[at.y + j].xyz
                + w.z * table[at.z + j].xyz + w.w * table[at.w + j].xyz;
            s = w.x * table[at.x + j + 1u].xyz + w.y * table[at.y + j + 1u].xyz
                + w.z * table[at.z + j + 1u].xyz + w.w * table[at.w + j + 1u].xyz;
        } else if g > 1u {
            s = w.x * table[at.x + i].xyz + w.y * table[at.y + i].xyz
                + w.z * table[at.z + i].xyz + w.w * table[at.w + i].xyz;
        }
        c += h.xyz * a + h.w * s;
        hits += h.w;
    }
    let miss = max(1.0 - hits / params.rays, 0.0);
    let lin = clamp(c / params.rays + miss * params.background.xyz, vec3<f32>(0.0), vec3<f32>(1.0));
    pixels[t] = pack4x8unorm(vec4<f32>(to_srgb(lin.x), to_srgb(lin.y), to_srgb(lin.z), 1.0));
}
