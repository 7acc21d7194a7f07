// Additive, flux-preserving splats (Hopf et al. 2003, sections 4 and 7), for SPH- and
// astrophysics-like data where particles add light rather than hide each other.
//
// Each point deposits its radiant flux, pi * r_px^2 * colour (its disk's area on screen
// in pixels times its colour; for a representative r = sqrt(area_sum), so that a cluster
// carries exactly its particles' flux, Eq. 1), spread by a normalised round kernel: a
// Gaussian of sigma = max(r_px / 2, 0.7 px) cut at the radius R = 3.5 sigma and lowered
// by its value there, exp(-d^2 / 2 sigma^2) - exp(-R^2 / 2 sigma^2), so that it falls
// continuously to 0 on a circle (a square cut left every splat a hard-edged box on a log
// map, 0.2 % of its peak high). A point smaller than a pixel therefore keeps its energy
// while its peak brightness falls with r_px^2: Eq. 3's alpha attenuation. The kernel is
// normalised by its integral: a kernel continuous at its edge, sampled at the pixel
// centres, sums to its integral within 1.7e-4 from sigma = 1.5 px and within 1.1e-3
// below (0.7 to 1.5 px), depending on where the centre falls in its pixel, and exactly
// on average over those places, so an image of many splats keeps their total flux far
// closer. An exact sum pixel by pixel cost a third more time on the software
// rasterizer. Blending
// is additive into a 32-bit float target; tone mapping happens on the host.
//
// Sorted over-blending (`fs_over`, Hopf et al. section 6) draws the same footprints as
// translucent discs composited back to front with the over operator (the host orders the
// points): alpha = opacity times the kernel over its peak, attenuated by the square of
// the diameter in pixels below one pixel (Eq. 3), colour premultiplied.
//
// Follows points.wgsl. Frame.material here: x, y = image width and height in pixels,
// z = intensity scale, w = opacity (over-blending); frame.params.z = the Gaussian's sigma
// per projected radius (the kernel's reach in radii / 3.5).

const TRUNCATION: f32 = 3.5;
const MIN_SIGMA_PX: f32 = 0.7;
// exp(-TRUNCATION^2 / 2): the Gaussian's value at the cut, taken off the whole kernel.
const EDGE: f32 = 0.0021874911;

// The kernel at squared distance `d2` (px^2) from the centre: 0 from the cut on.
fn kernel(d2: f32, sigma: f32) -> f32 {
    let limit = TRUNCATION * sigma;
    if !(d2 < limit * limit) {
        return 0.0;
    }
    return exp(-d2 / (2.0 * sigma * sigma)) - EDGE;
}

// The kernel's integral over the plane, 2 pi sigma^2 (1 - EDGE) - pi R^2 EDGE: what its
// samples at the pixel centres sum to, without an exponential per pixel (splat.rs's
// `kernel_mass` is the CPU twin; see the header for how close).
fn kernel_mass(sigma: f32) -> f32 {
    let limit = TRUNCATION * sigma;
    return 6.28318531 * sigma * sigma * (1.0 - EDGE) - 3.14159265 * limit * limit * EDGE;
}

struct VsOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) @interpolate(flat) center_px: vec2<f32>,
    @location(1) @interpolate(flat) sigma: f32,
    // Flux per channel (rgb) and in total (a), already divided by the kernel's
    // normalisation.
    @location(2) @interpolate(flat) energy: vec4<f32>,
    // Over-blending: albedo and peak alpha.
    @location(3) @interpolate(flat) albedo_alpha: vec4<f32>,
};

@vertex
fn vs_main(@builtin(vertex_index) vi: u32, @builtin(instance_index) ii: u32) -> VsOut {
    let pt = load_point(ii);
    let clip = frame.clip_from_view * (frame.view_from_world * vec4<f32>(pt.world, 1.0));
    var out: VsOut;
    out.center_px = vec2<f32>(0.0);
    out.sigma = 1.0;
    out.energy = vec4<f32>(0.0);
    out.albedo_alpha = vec4<f32>(0.0);
    // Behind the eye or in front of the near plane: not drawn.
    if clip.w <= 0.0 || clip.z < 0.0 {
        out.clip = vec4<f32>(0.0, 0.0, -1.0, 1.0);
        return out;
    }
    let size = frame.material.xy;
    // Pixels per world unit at the point's depth (clip.w is the depth in perspective
    // views and 1 in orthographic ones).
    let ppw = frame.clip_from_view[1][1] * 0.5 * size.y / clip.w;
    let r_px = pt.radius * ppw;
    // params.z: sigma per projected radius (0.5 by default: the cut at 1.75 radii).
    let sigma = max(frame.params.z * r_px, MIN_SIGMA_PX);
    let flux = 3.14159265 * r_px * r_px * frame.material.z;
    let ndc = clip.xy / clip.w;
    out.center_px = vec2<f32>((ndc.x + 1.0) * 0.5 * size.x, (1.0 - ndc.y) * 0.5 * size.y);
    let norm = 1.0 / kernel_mass(sigma);
    out.energy = vec4<f32>(pt.albedo * flux, flux) * norm;
    let diameter = 2.0 * r_px;
    out.albedo_alpha = vec4<f32>(pt.albedo, frame.material.w * min(diameter * diameter, 1.0));
    out.sigma = sigma;
    let corner = vec2<f32>(f32(vi & 1u), f32((vi >> 1u) & 1u)) * 2.0 - 1.0;
    // One pixel wider than the cut's circle, which the fragment stage enforces exactly:
    // rasterization rounding must not drop its edge pixels.
    let half_ndc = vec2<f32>(2.0, 2.0) * (TRUNCATION * sigma + 1.0) / size;
    out.clip = vec4<f32>((ndc + corner * half_ndc) * clip.w, 0.5 * clip.w, clip.w);
    return out;
}

@fragment
fn fs_main(in: VsOut) -> @location(0) vec4<f32> {
    let d = in.clip.xy - in.center_px;
    let k = kernel(dot(d, d), in.sigma);
    if k <= 0.0 {
        discard;
    }
    return in.energy * k;
}

@fragment
fn fs_over(in: VsOut) -> @location(0) vec4<f32> {
    let d = in.clip.xy - in.center_px;
    let k = kernel(dot(d, d), in.sigma);
    if k <= 0.0 {
        discard;
    }
    let a = in.albedo_alpha.w * k / (1.0 - EDGE);
    return vec4<f32>(in.albedo_alpha.xyz * a, a);
}
