// S-NDF accumulation (Ibrahim et al. 2017, section 4): after each sampling iteration has
// drawn the nearest hit's view-space normal and albedo into a G-buffer (one jittered ray
// per texel), every texel adds that sample to its histogram over the normals: bins x bins
// cells of one of three parametrisations (binning 0: projected normals (n.x, n.y) in
// [-1, 1]^2; 1: spherical coordinates, azimuth and polar angle over the hemisphere facing
// the viewer; 2: Lambert azimuthal equal-area about the view axis, the hemisphere onto
// the unit disk). Each bin keeps
// the sum of the albedos that landed in it (rgb) and their count (a): colour-weighted
// sums stay linear under averaging, so per-particle colours shade exactly. A texel whose
// ray hit nothing adds nothing; its coverage is the total count over the iterations.
//
// Storage: the histograms live in 64x64-texel tiles (the S-MIP's tiles, see smip.rs).
// The sampled rectangle is tiles_x tiles wide; `pages` maps each of its tiles to a slot
// of the tile pool, or to NO_SLOT for a tile that is not being sampled (its texels add
// nothing). Within a slot, texels are kept in 8x8 blocks so that one workgroup's writes
// stay within 64 KiB at 8x8 bins: texel (lx, ly) of a tile is number
// ((ly / 8) * 8 + lx / 8) * 64 + (ly % 8) * 8 + lx % 8.
//
// In a perspective view each texel's normals are binned in the frame of its own ray
// (tan_half, the tangents of half the field of view, not zero): the shortest rotation
// that turns the direction towards the eye at the texel's centre onto +z, so that the
// hemisphere of normals its ray can see is the one the binning covers (sndf.rs,
// TexelView::bin_frame). Zeros bin in the camera's frame (orthographic views, S-MIP tiles).
//
// Several iterations per pass: the G-buffer is an array of `layers` layers, one
// iteration each, and a texel adds all of them to its histogram at once, so a texel's
// bins are read and written once per `layers` iterations.
//
// The Rust twin of Params is in sndf.rs.

const TILE: u32 = 64u;
const NO_SLOT: u32 = 0xffffffffu;

struct Params {
    width: u32,
    height: u32,
    bins: u32,
    binning: u32,
    layers: u32,
    tiles_x: u32,
    tan_half: vec2<f32>,
};

@group(0) @binding(0) var<storage, read> params: Params;
@group(0) @binding(1) var normals: texture_2d_array<f32>;
@group(0) @binding(2) var albedos: texture_2d_array<f32>;
@group(0) @binding(3) var<storage, read_write> hist: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read> pages: array<u32>;

// The normal's cell coordinates in [0, 1]^2 (clamped by the caller).
fn bin_coords(n: vec3<f32>) -> vec2<f32> {
    if params.binning == 1u {
        let phi = atan2(n.y, n.x);
        let theta = acos(clamp(n.z, -1.0, 1.0));
        return vec2<f32>(phi / 6.28318531 + 0.5, theta / 1.57079633);
    }
    if params.binning == 2u {
        let k = sqrt(2.0 / max(1.0 + n.z, 1e-6)) / 1.41421356;
        return (n.xy * k + 1.0) * 0.5;
    }
    return (n.xy + 1.0) * 0.5;
}

// The unit direction towards the eye through the centre of `texel`; +z when binning in
// the camera's frame.
fn towards_eye(texel: vec2<u32>) -> vec3<f32> {
    if params.tan_half.x <= 0.0 {
        return vec3<f32>(0.0, 0.0, 1.0);
    }
    let uv = (vec2<f32>(texel) + 0.5) / vec2<f32>(f32(params.width), f32(params.height)) * 2.0 - 1.0;
    // u to the right, v up (texel rows go down).
    return normalize(vec3<f32>(-uv.x * params.tan_half.x, uv.y * params.tan_half.y, 1.0));
}

// `n` turned into the frame of the ray towards the eye `e`: Rodrigues' rotation of e onto
// +z about k = e x z (|k| = sin, e.z = cos > 0); the identity for e = +z.
fn to_ray_frame(n: vec3<f32>, e: vec3<f32>) -> vec3<f32> {
    let k = vec3<f32>(e.y, -e.x, 0.0);
    return n * e.z + cross(k, n) + k * (dot(k, n) / (1.0 + e.z));
}

@compute @workgroup_size(8, 8)
fn accumulate(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= params.width || id.y >= params.height {
        return;
    }
    let slot = pages[(id.y / TILE) * params.tiles_x + id.x / TILE];
    if slot == NO_SLOT {
        return;
    }
    let lx = id.x % TILE;
    let ly = id.y % TILE;
    let local = ((ly / 8u) * 8u + lx / 8u) * 64u + (ly % 8u) * 8u + lx % 8u;
    let b = params.bins;
    let fb = f32(b);
    let base = (slot * TILE * TILE + local) * b * b;
    let eye = towards_eye(id.xy);
    for (var l = 0u; l < params.layers; l++) {
        let n = textureLoad(normals, vec2<i32>(id.xy), i32(l), 0);
        if n.w < 0.5 {
            continue;
        }
        let a = textureLoad(albedos, vec2<i32>(id.xy), i32(l), 0);
        let c = clamp(bin_coords(to_ray_frame(n.xyz, eye)), vec2<f32>(0.0), vec2<f32>(1.0));
        let bx = min(u32(c.x * fb), b - 1u);
        let by = min(u32(c.y * fb), b - 1u);
        let i = base + by * b + bx;
        hist[i] = hist[i] + vec4<f32>(a.xyz, 1.0);
    }
}
