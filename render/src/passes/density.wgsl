// Image-space density slices (Falk et al. 2010, section 3.2): every point splats its
// metaball kernel into a stack of slices along the view rays, perspective-correctly:
// each fragment evaluates the kernel at its own ray's sampling positions. Additive
// blending into two float targets sums the points.
//
// Follows points.wgsl. Group 1 holds the stack's slicing (density.rs, `DensityGpu`).

struct Density {
    world_from_clip: mat4x4<f32>,
    // xyz: the eye (perspective ray origin); w: 1 for orthographic.
    eye: vec4<f32>,
    // x: distance of the stack's first slice, y: slice step, z: kernel scale, w: 1 / r_ref.
    slicing: vec4<f32>,
    // x: slices in this stack, y: 1 with gradients (2 slices of rho + gradient) or 0
    // (8 slices of rho), z: reference volume 4/3 pi r_ref^3.
    mode: vec4<f32>,
    // xy: image size in pixels; z: iso-value (iso mode) ; w: density shown at the top of
    // the transfer function.
    size: vec4<f32>,
    // xyz: clip plane normal, w: its offset (samples with n.p > w are left out).
    clip: vec4<f32>,
    // x: 1 when the clip plane is on; y: the stack's index.
    flags: vec4<u32>,
    // xyz: iso-surface albedo; w: absorption (opacity per r_ref at the top density).
    albedo: vec4<f32>,
    pad: array<vec4<f32>, 5>,
};

@group(1) @binding(0) var<uniform> dens: Density;

const PI: f32 = 3.14159265;

struct SplatOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) @interpolate(flat) center: vec3<f32>,
    @location(1) @interpolate(flat) h: f32,
    @location(2) @interpolate(flat) mass: f32,
};

// The ray through pixel centre `px`: origin and unit direction, world space.
fn pixel_ray(px: vec2<f32>) -> array<vec3<f32>, 2> {
    let ndc = vec2<f32>(2.0 * px.x / dens.size.x - 1.0, 1.0 - 2.0 * px.y / dens.size.y);
    let n4 = dens.world_from_clip * vec4<f32>(ndc, 0.0, 1.0);
    let f4 = dens.world_from_clip * vec4<f32>(ndc, 1.0, 1.0);
    let near = n4.xyz / n4.w;
    let far = f4.xyz / f4.w;
    let dir = normalize(far - near);
    var origin = dens.eye.xyz;
    if dens.eye.w > 0.5 {
        let vz = (frame.view_from_world * vec4<f32>(near, 1.0)).z;
        origin = near + dir * vz;
    }
    return array<vec3<f32>, 2>(origin, dir);
}

@vertex
fn vs_splat(@builtin(vertex_index) vi: u32, @builtin(instance_index) ii: u32) -> SplatOut {
    let pt = load_point(ii);
    var out: SplatOut;
    out.center = pt.world;
    out.h = dens.slicing.z * pt.radius;
    let m = pt.radius * dens.slicing.w;
    out.mass = m * m;
    // The screen box of the support sphere: its world box's corners, projected. A box
    // reaching behind the eye covers the whole screen.
    let clip_from_world = frame.clip_from_view * frame.view_from_world;
    var lo = vec2<f32>(1e30);
    var hi = vec2<f32>(-1e30);
    var behind = false;
    for (var c = 0u; c < 8u; c++) {
        let s = vec3<f32>(f32(c & 1u), f32((c >> 1u) & 1u), f32((c >> 2u) & 1u)) * 2.0 - 1.0;
        let q = clip_from_world * vec4<f32>(pt.world + s * out.h, 1.0);
        if q.w <= 1e-6 {
            behind = true;
        } else {
            lo = min(lo, q.xy / q.w);
            hi = max(hi, q.xy / q.w);
        }
    }
    if behind {
        lo = vec2<f32>(-1.0);
        hi = vec2<f32>(1.0);
    }
    // Half a pixel wider: rasterization must not drop the edge pixels.
    let pad = vec2<f32>(1.0) / dens.size.xy;
    lo = max(lo - pad, vec2<f32>(-1.0));
    hi = min(hi + pad, vec2<f32>(1.0));
    let corner = vec2<f32>(f32(vi & 1u), f32((vi >> 1u) & 1u));
    out.clip = vec4<f32>(mix(lo, hi, corner), 0.5, 1.0);
    return out;
}

struct SliceOut {
    @location(0) a: vec4<f32>,
    @location(1) b: vec4<f32>,
};

@fragment
fn fs_splat(in: SplatOut) -> SliceOut {
    let ray = pixel_ray(in.clip.xy);
    let h2 = in.h * in.h;
    let norm = dens.mode.z * in.mass * 315.0 / (64.0 * PI * h2 * in.h);
    var out: SliceOut;
    out.a = vec4<f32>(0.0);
    out.b = vec4<f32>(0.0);
    let n = u32(dens.mode.x);
    if dens.mode.y > 0.5 {
        // Two slices of (gradient, density).
        for (var k = 0u; k < n; k++) {
            let p = ray[0] + ray[1] * (dens.slicing.x + f32(k) * dens.slicing.y);
            let d = p - in.center;
            let r2 = dot(d, d);
            var v = vec4<f32>(0.0);
            if r2 < h2 {
                let t = 1.0 - r2 / h2;
                v = vec4<f32>(d * (-6.0 * norm / h2 * t * t), norm * t * t * t);
            }
            if k == 0u {
                out.a = v;
            } else {
                out.b = v;
            }
        }
    } else {
        var rho = array<f32, 8>(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
        for (var k = 0u; k < n; k++) {
            let p = ray[0] + ray[1] * (dens.slicing.x + f32(k) * dens.slicing.y);
            let d = p - in.center;
            let r2 = dot(d, d);
            if r2 < h2 {
                let t = 1.0 - r2 / h2;
                rho[k] = norm * t * t * t;
            }
        }
        out.a = vec4<f32>(rho[0], rho[1], rho[2], rho[3]);
        out.b = vec4<f32>(rho[4], rho[5], rho[6], rho[7]);
    }
    return out;
}
