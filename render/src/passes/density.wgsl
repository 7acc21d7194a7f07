// Image-space density slices (Falk et al. 2010, section 3.2): every point splats its
// metaball kernel into a stack of slices along the view rays, perspective-correctly:
// each fragment evaluates the kernel at its own ray's sampling positions. Additive
// blending into two float targets sums the points.
//
// Follows points.wgsl and density_common.wgsl. Group 1 holds the stack's slicing; group
// 2 the rays' states, for the iso-surface's colour pass (`fs_colour`).

@group(1) @binding(0) var<storage, read> dens: Density;


struct SplatOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) @interpolate(flat) center: vec3<f32>,
    @location(1) @interpolate(flat) h: f32,
    @location(2) @interpolate(flat) mass: f32,
    @location(3) @interpolate(flat) albedo: vec3<f32>,
};

@vertex
fn vs_splat(@builtin(vertex_index) vi: u32, @builtin(instance_index) ii: u32) -> SplatOut {
    let pt = load_point(ii);
    var out: SplatOut;
    out.center = pt.world;
    // slicing.w = 1 / r_ref. A particle's support is its radius; a representative's
    // the radius of its particles' volume, r_ref (rho / r_ref)^(2/3), and its
    // `sqrt(mass)` (density::fraction's x) 1 (density::DensityPoint).
    let x = pt.radius * dens.slicing.w;
    if pt.cluster {
        out.h = dens.slicing.z * pow(x, 2.0 / 3.0) / dens.slicing.w;
        out.mass = 1.0;
    } else {
        out.h = dens.slicing.z * pt.radius;
        out.mass = x * x;
    }
    out.albedo = pt.albedo;
    // The screen box of the support sphere: its world box's corners, projected. A box
    // reaching behind the eye covers the whole screen.
    let clip_from_world = frame.clip_from_view * frame.view_from_world;
    var lo = vec2<f32>(1e30);
    var hi = vec2<f32>(-1e30);
    var behind = false;
    for (var c = 0u; c < 8u; c++) {
        let s = vec3<f32>(f32(c & 1u), f32((c >> 1u) & 1u), f32((c >> 2u) & 1u)) * 2.0 - 1.0;
        let q = clip_from_world * vec4<f32>(pt.world + s * out.h, 1.0);
        // Behind the eye, or on its plane: w is the view depth in world units (1 in
        // orthographic views), so no fixed epsilon (data in metres spans 10^-10).
        if q.w <= 0.0 {
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
    var out: SliceOut;
    out.a = vec4<f32>(0.0);
    out.b = vec4<f32>(0.0);
    if !(in.h > 0.0) {
        return out;
    }
    // V m W(0, h) = (4/3)(315/64) (r_ref / r) / k^3 (density::fraction): no power of a
    // large radius, which would overflow (stars in metres). sqrt(mass) = r / r_ref.
    let norm = dens.mode.z / sqrt(in.mass);
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
        // Eight slices of rho, or four of (rho, rho times the point's place on the
        // attribute's scale).
        var rho = array<f32, 8>(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
        let valued = dens.flags.w == 1u;
        for (var k = 0u; k < n; k++) {
            let p = ray[0] + ray[1] * (dens.slicing.x + f32(k) * dens.slicing.y);
            let d = p - in.center;
            let r2 = dot(d, d);
            if r2 < h2 {
                let t = 1.0 - r2 / h2;
                let f = norm * t * t * t;
                if valued {
                    rho[2u * k] = f;
                    rho[2u * k + 1u] = f * in.albedo.x;
                } else {
                    rho[k] = f;
                }
            }
        }
        out.a = vec4<f32>(rho[0], rho[1], rho[2], rho[3]);
        out.b = vec4<f32>(rho[4], rho[5], rho[6], rho[7]);
    }
    return out;
}

@group(2) @binding(0) var<storage, read> hits: array<Ray>;

// The iso-surface's colour, once the hits are known: every point adds its albedo
// weighted by mass times kernel at its pixels' hit positions, and its weight, so the
// host divides the sums (`density::colour_at` on the CPU).
@fragment
fn fs_colour(in: SplatOut) -> @location(0) vec4<f32> {
    let px = vec2<u32>(in.clip.xy);
    let ray = hits[px.y * u32(dens.size.x) + px.x];
    if ray.state.w < 0.5 {
        discard;
    }
    let r = pixel_ray(in.clip.xy);
    let d = r[0] + r[1] * ray.state.y - in.center;
    let h2 = in.h * in.h;
    let r2 = dot(d, d);
    if r2 >= h2 {
        discard;
    }
    let t = 1.0 - r2 / h2;
    // m W up to constant factors, which cancel in the division: t^3 / r, as
    // density::colour_at (no power of a large radius).
    let w = t * t * t / sqrt(in.mass);
    return vec4<f32>(in.albedo * w, w);
}
