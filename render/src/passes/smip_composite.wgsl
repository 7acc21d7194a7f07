// The S-MIP's output image (Ibrahim et al. 2017, sections 5 and 6.1): every pixel maps
// to continuous texel coordinates in two adjacent S-MIP levels; within each level the
// four nearest texels are shaded from their S-NDFs (the per-bin table of Eq. 12-14, as
// sndf_shade.wgsl does) and blended bilinearly, and the two levels linearly: trilinear
// filtering, on linear colours. Texels are found through each level's page table (a
// rectangle of tiles, each mapped to a slot of the tile pool); `rays` holds each slot's
// rays per texel, which differ between tiles sampled at different times.
//
// The Rust twins of Params and Level are in smip.rs.

const TILE: u32 = 64u;
const NO_SLOT: u32 = 0xffffffffu;

struct Level {
    // Texel coordinates of pixel (0, 0)'s centre, relative to the level's first tile.
    origin: vec2<f32>,
    // Texels per pixel.
    step: f32,
    // This level's share of the blend.
    weight: f32,
    // The page table's rectangle, in tiles.
    tiles: vec2<u32>,
    page_offset: u32,
    pad: u32,
};

struct Params {
    width: u32,
    height: u32,
    bins: u32,
    levels: u32,
    // rgb: linear background.
    background: vec4<f32>,
    level: array<Level, 2>,
};

@group(0) @binding(0) var<storage, read> params: Params;
// Two per bin: the albedo factor (rgb) and the highlight (rgb).
@group(0) @binding(1) var<storage, read> table: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> pool: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read> pages: array<u32>;
@group(0) @binding(4) var<storage, read> rays: array<f32>;
@group(0) @binding(5) var<storage, read_write> pixels: array<u32>;

fn texel_index(lx: u32, ly: u32) -> u32 {
    return ((ly / 8u) * 8u + lx / 8u) * 64u + (ly % 8u) * 8u + lx % 8u;
}

fn to_srgb(c: f32) -> f32 {
    if c <= 0.0031308 {
        return c * 12.92;
    }
    return 1.055 * pow(c, 1.0 / 2.4) - 0.055;
}

// The linear colour of texel (x, y) of level l.
fn shade_texel(l: u32, x: i32, y: i32) -> vec3<f32> {
    let lv = params.level[l];
    let cx = u32(clamp(x, 0, i32(lv.tiles.x * TILE) - 1));
    let cy = u32(clamp(y, 0, i32(lv.tiles.y * TILE) - 1));
    let slot = pages[lv.page_offset + (cy / TILE) * lv.tiles.x + cx / TILE];
    if slot == NO_SLOT {
        return params.background.xyz;
    }
    let b2 = params.bins * params.bins;
    let base = (slot * TILE * TILE + texel_index(cx % TILE, cy % TILE)) * b2;
    var c = vec3<f32>(0.0);
    var hits = 0.0;
    for (var i = 0u; i < b2; i++) {
        let h = pool[base + i];
        c += h.xyz * table[2u * i].xyz + h.w * table[2u * i + 1u].xyz;
        hits += h.w;
    }
    let r = max(rays[slot], 1.0);
    let miss = max(1.0 - hits / r, 0.0);
    return c / r + miss * params.background.xyz;
}

// Bilinear within level l at pixel (px, py)'s centre; texels of zero weight are skipped.
fn sample_level(l: u32, px: f32, py: f32) -> vec3<f32> {
    let lv = params.level[l];
    let t = lv.origin + vec2<f32>(px, py) * lv.step - vec2<f32>(0.5);
    let f = floor(t);
    let w = t - f;
    let i = vec2<i32>(f);
    var c = vec3<f32>(0.0);
    for (var k = 0u; k < 4u; k++) {
        let dx = k % 2u;
        let dy = k / 2u;
        let wx = select(1.0 - w.x, w.x, dx == 1u);
        let wy = select(1.0 - w.y, w.y, dy == 1u);
        if wx * wy > 0.0 {
            c += wx * wy * shade_texel(l, i.x + i32(dx), i.y + i32(dy));
        }
    }
    return c;
}

@compute @workgroup_size(8, 8)
fn composite(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= params.width || id.y >= params.height {
        return;
    }
    var c = vec3<f32>(0.0);
    for (var l = 0u; l < params.levels; l++) {
        let w = params.level[l].weight;
        if w > 0.0 {
            c += w * sample_level(l, f32(id.x), f32(id.y));
        }
    }
    let lin = clamp(c, vec3<f32>(0.0), vec3<f32>(1.0));
    pixels[id.y * params.width + id.x] =
        pack4x8unorm(vec4<f32>(to_srgb(lin.x), to_srgb(lin.y), to_srgb(lin.z), 1.0));
}
