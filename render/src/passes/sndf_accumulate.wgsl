// S-NDF accumulation (Ibrahim et al. 2017, section 4): after each sampling iteration has
// drawn the nearest hit's view-space normal and albedo into a G-buffer (one jittered ray
// per texel), every texel adds that sample to its histogram over the projected normal
// disk: bins x bins "projected normals" cells of (n.x, n.y) in [-1, 1]^2. Each bin keeps
// the sum of the albedos that landed in it (rgb) and their count (a): colour-weighted
// sums stay linear under averaging, so per-particle colours shade exactly. A texel whose
// ray hit nothing adds nothing; its coverage is the total count over the iterations.
//
// The Rust twin of Params is in sndf.rs.

struct Params {
    width: u32,
    height: u32,
    bins: u32,
    pad: u32,
};

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var normals: texture_2d<f32>;
@group(0) @binding(2) var albedos: texture_2d<f32>;
@group(0) @binding(3) var<storage, read_write> hist: array<vec4<f32>>;

@compute @workgroup_size(8, 8)
fn accumulate(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= params.width || id.y >= params.height {
        return;
    }
    let n = textureLoad(normals, vec2<i32>(id.xy), 0);
    if n.w < 0.5 {
        return;
    }
    let a = textureLoad(albedos, vec2<i32>(id.xy), 0);
    let b = params.bins;
    let fb = f32(b);
    let bx = min(u32(clamp((n.x + 1.0) * 0.5, 0.0, 1.0) * fb), b - 1u);
    let by = min(u32(clamp((n.y + 1.0) * 0.5, 0.0, 1.0) * fb), b - 1u);
    let i = (id.y * params.width + id.x) * b * b + by * b + bx;
    hist[i] = hist[i] + vec4<f32>(a.xyz, 1.0);
}
