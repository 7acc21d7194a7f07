// S-MIP down-sampling (Ibrahim et al. 2017, section 6.1.2): a tile of level L + 1 from
// the 2x2 tiles of level L beneath it. Each parent texel sums the bins of its 2x2 child
// texels (the sum of four S-NDFs with four times the rays is their average, and sums of
// colour-weighted bins stay exact). Child c covers the parent's quadrant (c % 2, c / 2).
//
// Texels within a tile are kept in 8x8 blocks, as sndf_accumulate.wgsl stores them. The
// Rust twin of DownParams is in smip.rs.

const TILE: u32 = 64u;

struct DownParams {
    bins: u32,
    parent: u32,
    pad0: u32,
    pad1: u32,
    children: vec4<u32>,
};

@group(0) @binding(0) var<storage, read> params: DownParams;
@group(0) @binding(1) var<storage, read_write> pool: array<vec4<f32>>;

fn texel_index(lx: u32, ly: u32) -> u32 {
    return ((ly / 8u) * 8u + lx / 8u) * 64u + (ly % 8u) * 8u + lx % 8u;
}

@compute @workgroup_size(8, 8)
fn downsample(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= TILE || id.y >= TILE {
        return;
    }
    let half = TILE / 2u;
    let child = params.children[(id.y / half) * 2u + id.x / half];
    let cx = (id.x % half) * 2u;
    let cy = (id.y % half) * 2u;
    let b2 = params.bins * params.bins;
    let dst = (params.parent * TILE * TILE + texel_index(id.x, id.y)) * b2;
    let s0 = (child * TILE * TILE + texel_index(cx, cy)) * b2;
    let s1 = (child * TILE * TILE + texel_index(cx + 1u, cy)) * b2;
    let s2 = (child * TILE * TILE + texel_index(cx, cy + 1u)) * b2;
    let s3 = (child * TILE * TILE + texel_index(cx + 1u, cy + 1u)) * b2;
    for (var i = 0u; i < b2; i++) {
        pool[dst + i] = pool[s0 + i] + pool[s1 + i] + pool[s2 + i] + pool[s3 + i];
    }
}
