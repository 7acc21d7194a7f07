// Additive, flux-preserving splats (Hopf et al. 2003, sections 4 and 7), for SPH- and
// astrophysics-like data where particles add light rather than hide each other.
//
// Each point deposits its radiant flux, pi * r_px^2 * colour (its disk's area on screen
// in pixels times its colour; for a representative r = sqrt(area_sum), so that a cluster
// carries exactly its particles' flux, Eq. 1), spread by a normalised Gaussian of
// sigma = max(r_px / 2, 0.7 px) truncated at 3.5 sigma. A point smaller than a pixel
// therefore keeps its energy while its peak brightness falls with r_px^2: Eq. 3's alpha
// attenuation. The sum over the image of every point's weights is 1 to within 3e-4
// (a Gaussian sampled at unit spacing with sigma >= 0.7), so the image's total flux is
// the sum of the points' fluxes. Blending is additive into a 32-bit float target; tone
// mapping happens on the host.
//
// Sorted over-blending (`fs_over`, Hopf et al. section 6) draws the same footprints as
// translucent discs composited back to front with the over operator (the host orders the
// points): alpha = opacity * exp(-d^2 / 2 sigma^2), attenuated by the square of the
// diameter in pixels below one pixel (Eq. 3), colour premultiplied.
//
// Follows points.wgsl. Frame.material here: x, y = image width and height in pixels,
// z = intensity scale, w = opacity (over-blending).

const TRUNCATION: f32 = 3.5;
const MIN_SIGMA_PX: f32 = 0.7;
// sqrt(2 pi) * erf(3.5 / sqrt(2)): a unit Gaussian's mass inside the truncation.
const AXIS_MASS: f32 = 2.50546287;
const EXACT_BELOW: f32 = 32.0;

// Sum over pixel centres (i + 0.5) within the truncation of exp(-(x - c)^2 / 2 sigma^2).
fn axis_sum(c: f32, sigma: f32) -> f32 {
    if sigma >= EXACT_BELOW {
        return AXIS_MASS * sigma;
    }
    let limit = TRUNCATION * sigma;
    let inv = 1.0 / (2.0 * sigma * sigma);
    var sum = 0.0;
    let first = ceil(c - 0.5 - limit);
    let span = floor(c - 0.5 + limit) - first + 1.0;
    // Counted, not stepped: past 2^24 px (a splat far off screen) x + 1 == x. An
    // infinite or NaN centre has no pixels.
    if !(span > 0.0 && span <= 2.0 * limit + 2.0) {
        return 0.0;
    }
    let n = u32(span);
    for (var k = 0u; k < n; k++) {
        let d = first + f32(k) + 0.5 - c;
        sum += exp(-d * d * inv);
    }
    return sum;
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
    let sigma = max(0.5 * r_px, MIN_SIGMA_PX);
    let flux = 3.14159265 * r_px * r_px * frame.material.z;
    let ndc = clip.xy / clip.w;
    out.center_px = vec2<f32>((ndc.x + 1.0) * 0.5 * size.x, (1.0 - ndc.y) * 0.5 * size.y);
    let norm = 1.0 / (axis_sum(out.center_px.x, sigma) * axis_sum(out.center_px.y, sigma));
    out.energy = vec4<f32>(pt.albedo * flux, flux) * norm;
    let diameter = 2.0 * r_px;
    out.albedo_alpha = vec4<f32>(pt.albedo, frame.material.w * min(diameter * diameter, 1.0));
    out.sigma = sigma;
    let corner = vec2<f32>(f32(vi & 1u), f32((vi >> 1u) & 1u)) * 2.0 - 1.0;
    // One pixel wider than the truncation square, which the fragment stage enforces
    // exactly: rasterization rounding must not drop its edge pixels.
    let half_ndc = vec2<f32>(2.0, 2.0) * (TRUNCATION * sigma + 1.0) / size;
    out.clip = vec4<f32>((ndc + corner * half_ndc) * clip.w, 0.5 * clip.w, clip.w);
    return out;
}

@fragment
fn fs_main(in: VsOut) -> @location(0) vec4<f32> {
    let d = in.clip.xy - in.center_px;
    let s2 = in.sigma * in.sigma;
    let limit = TRUNCATION * in.sigma;
    if abs(d.x) > limit || abs(d.y) > limit {
        discard;
    }
    return in.energy * exp(-dot(d, d) / (2.0 * s2));
}

@fragment
fn fs_over(in: VsOut) -> @location(0) vec4<f32> {
    let d = in.clip.xy - in.center_px;
    let limit = TRUNCATION * in.sigma;
    if abs(d.x) > limit || abs(d.y) > limit {
        discard;
    }
    let a = in.albedo_alpha.w * exp(-dot(d, d) / (2.0 * in.sigma * in.sigma));
    return vec4<f32>(in.albedo_alpha.xyz * a, a);
}
