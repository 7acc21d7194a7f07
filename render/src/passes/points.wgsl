// Shared by the passes that draw the points of a cut (sphere_raycast.wgsl, splat.wgsl):
// the per-frame uniforms, the bindings of the packed cut and the decoding of one point.
// Each pass's source is this file followed by its own.
//
// The Rust twins of the structs below are in sphere_raycast.rs.

struct Frame {
    clip_from_view: mat4x4<f32>,
    view_from_world: mat4x4<f32>,
    // xyz: unit vector towards the light, in view space.
    light_dir_view: vec4<f32>,
    // x: ambient, y: diffuse, z: specular, w: shininess.
    material: vec4<f32>,
    // x: 1 for orthographic, 0 for perspective; y: H = (2^bits - 1) / 2.
    params: vec4<f32>,
    // x: position bits (8 or 16), y: species count.
    counts: vec4<u32>,
    // rgb: the light's colour (linear), scaling its diffuse and specular terms.
    light_colour: vec4<f32>,
};

struct Range {
    base: vec3<f32>,
    word_offset: u32,
    scale: vec3<f32>,
    attr_offset: u32,
    first_point: u32,
    kind: u32,
    // Index of the range's first point within the block at word_offset / attr_offset.
    point_offset: u32,
    pad: u32,
};

const KIND_PARTICLE: u32 = 0u;
const KIND_INTENSITY: u32 = 2u;
const KIND_SIZED: u32 = 3u;
const KIND_PARTICLE_INTENSITY: u32 = 4u;

@group(0) @binding(0) var<storage, read> frame: Frame;
@group(0) @binding(1) var<storage, read> positions: array<u32>;
@group(0) @binding(2) var<storage, read> attrs: array<u32>;
@group(0) @binding(3) var<storage, read> ranges: array<Range>;
@group(0) @binding(4) var<storage, read> point_range: array<u32>;
// rgb: linear albedo, w: radius.
@group(0) @binding(5) var<storage, read> species: array<vec4<f32>>;

fn u16_at(base_word: u32, h: u32) -> u32 {
    let w = positions[base_word + (h >> 1u)];
    return (w >> ((h & 1u) * 16u)) & 0xffffu;
}

fn u8_at(base_word: u32, b: u32) -> u32 {
    let w = positions[base_word + (b >> 2u)];
    return (w >> ((b & 3u) * 8u)) & 0xffu;
}

fn quantized(r: Range, j: u32) -> vec3<f32> {
    let k = 3u * j;
    if frame.counts.x == 16u {
        return vec3<f32>(
            f32(u16_at(r.word_offset, k)),
            f32(u16_at(r.word_offset, k + 1u)),
            f32(u16_at(r.word_offset, k + 2u)),
        );
    }
    return vec3<f32>(
        f32(u8_at(r.word_offset, k)),
        f32(u8_at(r.word_offset, k + 1u)),
        f32(u8_at(r.word_offset, k + 2u)),
    );
}

// One point of the cut: world position, radius, linear albedo.
struct Point {
    world: vec3<f32>,
    radius: f32,
    albedo: vec3<f32>,
    // A representative of several particles (any range kind but particles).
    cluster: bool,
};

// Point `ii` (instance index) of the packed cut, decoded as every reader does:
// world = base + scale * (q - H).
fn load_point(ii: u32) -> Point {
    let r = ranges[point_range[ii]];
    let j = ii - r.first_point + r.point_offset;
    let q = quantized(r, j);
    var p: Point;
    p.world = r.base + r.scale * (q - vec3<f32>(frame.params.y));
    p.cluster = r.kind != KIND_PARTICLE && r.kind != KIND_SIZED
        && r.kind != KIND_PARTICLE_INTENSITY;
    if r.kind == KIND_PARTICLE {
        let h = r.attr_offset * 2u + j;
        let s = min((attrs[h >> 1u] >> ((h & 1u) * 16u)) & 0xffffu, frame.counts.y - 1u);
        let sp = species[s];
        p.radius = sp.w;
        p.albedo = sp.xyz;
    } else if r.kind == KIND_SIZED {
        // A particle of its own size: species index, then radius.
        let s = min(attrs[r.attr_offset + 2u * j], frame.counts.y - 1u);
        p.radius = bitcast<f32>(attrs[r.attr_offset + 2u * j + 1u]);
        p.albedo = species[s].xyz;
    } else if r.kind == KIND_INTENSITY || r.kind == KIND_PARTICLE_INTENSITY {
        p.radius = bitcast<f32>(attrs[r.attr_offset + 2u * j]);
        p.albedo = vec3<f32>(bitcast<f32>(attrs[r.attr_offset + 2u * j + 1u]));
    } else {
        p.radius = bitcast<f32>(attrs[r.attr_offset + 2u * j]);
        p.albedo = srgb_to_linear(unpack4x8unorm(attrs[r.attr_offset + 2u * j + 1u]).xyz);
    }
    return p;
}

// A colour packed as sRGB bytes (`style::pack_colour`) as linear light.
fn srgb_to_linear(c: vec3<f32>) -> vec3<f32> {
    let dark = c / 12.92;
    let bright = pow((c + vec3<f32>(0.055)) / 1.055, vec3<f32>(2.4));
    return select(bright, dark, c <= vec3<f32>(0.04045));
}
