// Shared by density.wgsl and density_composite.wgsl: one stack's slicing (the Rust twin
// is `DensityGpu` in density.rs), the per-pixel ray state (`RayGpu`) and the ray through
// a pixel. Each pass binds its own `dens: Density` uniform.

struct Density {
    // Columns: right (w: half-width at unit depth, or in world units when orthographic),
    // up (w: half-height likewise), back, eye (w: 1 for orthographic); world space.
    basis: mat4x4<f32>,
    // x: distance of the stack's first slice, y: slice step, z: kernel scale, w: 1 / r_ref.
    slicing: vec4<f32>,
    // x: slices in this stack, y: 1 with gradients (2 slices of rho + gradient) or 0
    // (8 slices of rho), z: reference volume 4/3 pi r_ref^3, w: density at the bottom
    // of the transfer function.
    mode: vec4<f32>,
    // xy: image size in pixels; z: iso-value (0: direct volume rendering); w: density
    // shown at the top of the transfer function.
    size: vec4<f32>,
    // xyz: clip plane normal, w: its offset (samples with n.p > w are left out).
    clip: vec4<f32>,
    // x: 1 when the clip plane is on; y: the stack's index; z: 1 for a transfer
    // function over the density's logarithm; w: 1 for a volume coloured by the
    // attribute (4 slices of rho and the sum of rho times each point's place on the
    // attribute's scale, its albedo's first channel).
    flags: vec4<u32>,
    // xyz: iso-surface albedo; w: absorption (opacity per r_ref at the top density).
    albedo: vec4<f32>,
    // 0, 1: the box of the points' supports (xyz); the rest unused (a 256-byte stride).
    pad: array<vec4<f32>, 6>,
};

// The ray through pixel centre `px`: origin and unit direction, world space, from the
// camera's basis (density.rs's `pixel_ray` is the CPU twin). The origin is the eye in
// perspective views, the point of the ray in the eye's plane (view z = 0) in
// orthographic ones.
fn pixel_ray(px: vec2<f32>) -> array<vec3<f32>, 2> {
    let ndc = vec2<f32>(2.0 * px.x / dens.size.x - 1.0, 1.0 - 2.0 * px.y / dens.size.y);
    let b = dens.basis;
    let across = b[0].xyz * (ndc.x * b[0].w) + b[1].xyz * (ndc.y * b[1].w);
    if b[3].w > 0.5 {
        return array<vec3<f32>, 2>(b[3].xyz + across, -b[2].xyz);
    }
    return array<vec3<f32>, 2>(b[3].xyz, normalize(across - b[2].xyz));
}

// A pixel's ray state between stacks (the composite pass writes it; the iso-surface's
// colour pass reads the hits).
struct Ray {
    // Premultiplied colour and opacity.
    colour: vec4<f32>,
    // The previous sample: gradient and density (iso mode).
    prev: vec4<f32>,
    // x: 1 when done, y: iso hit distance, z: 1 once a previous sample exists, w: 1 on
    // an iso hit.
    state: vec4<f32>,
};

// Where density `phi` falls on the transfer function, in [0, 1]: linearly between the
// bottom (mode.w) and the top (size.w), or by its logarithm (density.rs's `transfer_t`
// is the CPU twin).
fn transfer_t(phi: f32) -> f32 {
    let lo = dens.mode.w;
    let hi = dens.size.w;
    if dens.flags.z == 1u {
        if phi <= lo {
            return 0.0;
        }
        return clamp(log(phi / lo) / log(hi / lo), 0.0, 1.0);
    }
    return clamp((phi - lo) / (hi - lo), 0.0, 1.0);
}
