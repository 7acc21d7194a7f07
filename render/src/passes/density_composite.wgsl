// Ray casting through one stack of density slices (Falk et al. 2010, sections 3.3-3.4):
// front-to-back compositing with a transfer function, or the first crossing of the
// iso-value, into a per-pixel state that carries over to the next stack. Rays that are
// done are counted out of `active`, which the host reads to end the frame early.
//
// Follows density_common.wgsl.

@group(0) @binding(0) var<storage, read> dens: Density;
@group(0) @binding(1) var slice_a: texture_2d<f32>;
@group(0) @binding(2) var slice_b: texture_2d<f32>;
@group(0) @binding(3) var<storage, read_write> rays: array<Ray>;
@group(0) @binding(4) var<storage, read_write> active_rays: atomic<u32>;
// The colour map's table, linear RGB evenly over [0, 1] (density.rs's `colour_table`).
@group(0) @binding(5) var<storage, read> lut: array<vec4<f32>>;

const OPAQUE: f32 = 0.99;

fn transfer_colour(t: f32) -> vec3<f32> {
    let u = clamp(t, 0.0, 1.0);
    let s0 = vec3<f32>(0.02, 0.05, 0.45);
    let s1 = vec3<f32>(0.75, 0.08, 0.06);
    let s2 = vec3<f32>(1.0, 0.85, 0.25);
    if u < 0.5 {
        return mix(s0, s1, u * 2.0);
    }
    return mix(s1, s2, u * 2.0 - 1.0);
}

// The colour map at place v on the attribute's scale, between the table's entries.
fn map_colour(v: f32) -> vec3<f32> {
    let last = arrayLength(&lut) - 1u;
    let x = clamp(v, 0.0, 1.0) * f32(last);
    let i = min(u32(floor(x)), last - 1u);
    return mix(lut[i].xyz, lut[i + 1u].xyz, x - f32(i));
}

fn shade(gradient: vec3<f32>, dir: vec3<f32>) -> vec3<f32> {
    var n = vec3<f32>(0.0);
    if dot(gradient, gradient) > 0.0 {
        n = -normalize(gradient);
    }
    return dens.albedo.xyz * (0.25 + 0.75 * max(dot(n, -dir), 0.0));
}

@compute @workgroup_size(8, 8)
fn cs_composite(@builtin(global_invocation_id) id: vec3<u32>) {
    let w = u32(dens.size.x);
    let h = u32(dens.size.y);
    if id.x >= w || id.y >= h {
        return;
    }
    let i = id.y * w + id.x;
    var ray = rays[i];
    if ray.state.x > 0.5 {
        return;
    }
    let ray_ = pixel_ray(vec2<f32>(f32(id.x) + 0.5, f32(id.y) + 0.5));
    let origin = ray_[0];
    let dir = ray_[1];
    // A ray that has left the box of the points' supports (or never meets it) is done.
    // (A zero component, an axis-aligned orthographic view, takes a tiny one instead:
    // WGSL leaves 1 / 0 and 0 * inf undefined.)
    let inv = 1.0 / select(dir, vec3<f32>(1e-30), abs(dir) < vec3<f32>(1e-30));
    let t0 = (dens.pad[0].xyz - origin) * inv;
    let t1 = (dens.pad[1].xyz - origin) * inv;
    let t_enter = max(max(min(t0.x, t1.x), min(t0.y, t1.y)), min(t0.z, t1.z));
    let t_exit = min(min(max(t0.x, t1.x), max(t0.y, t1.y)), max(t0.z, t1.z));
    if t_exit < t_enter || dens.slicing.x > t_exit {
        ray.state.x = 1.0;
        rays[i] = ray;
        return;
    }
    let a = textureLoad(slice_a, vec2<i32>(id.xy), 0);
    let b = textureLoad(slice_b, vec2<i32>(id.xy), 0);
    let gradients = dens.mode.y > 0.5;
    let valued = dens.flags.w == 1u;
    let n = u32(dens.mode.x);
    for (var k = 0u; k < n; k++) {
        let lambda = dens.slicing.x + f32(k) * dens.slicing.y;
        let p = origin + dir * lambda;
        var s = vec4<f32>(0.0);
        // The mean place on the attribute's scale here (a volume coloured by it).
        var value = 0.0;
        if gradients {
            if k == 0u {
                s = a;
            } else {
                s = b;
            }
        } else if valued {
            var pair = a;
            if k >= 2u {
                pair = b;
            }
            let j = (k & 1u) * 2u;
            s = vec4<f32>(0.0, 0.0, 0.0, pair[j]);
            if pair[j] > 0.0 {
                value = pair[j + 1u] / pair[j];
            }
        } else {
            var v = a[k & 3u];
            if k >= 4u {
                v = b[k & 3u];
            }
            s = vec4<f32>(0.0, 0.0, 0.0, v);
        }
        if dens.flags.x == 1u && dot(dens.clip.xyz, p) > dens.clip.w {
            s = vec4<f32>(0.0);
        }
        if dens.size.z <= 0.0 {
            // Direct volume rendering.
            let t = transfer_t(s.w);
            let alpha = 1.0 - exp(-dens.albedo.w * t * dens.slicing.y * dens.slicing.w);
            let c = select(transfer_colour(t), map_colour(value), valued);
            ray.colour = vec4<f32>(
                ray.colour.xyz + (1.0 - ray.colour.w) * alpha * c,
                ray.colour.w + (1.0 - ray.colour.w) * alpha,
            );
            if ray.colour.w >= OPAQUE {
                ray.state.x = 1.0;
                break;
            }
        } else {
            let iso = dens.size.z;
            if ray.state.z > 0.5 {
                let p0 = ray.prev.w;
                if p0 < iso && s.w >= iso {
                    let t = (iso - p0) / (s.w - p0);
                    ray.state.y = lambda - dens.slicing.y + t * dens.slicing.y;
                    ray.state.w = 1.0;
                    ray.colour = vec4<f32>(shade(mix(ray.prev.xyz, s.xyz, t), dir), 1.0);
                    ray.state.x = 1.0;
                    break;
                }
            } else if s.w >= iso {
                ray.state.y = lambda;
                ray.state.w = 1.0;
                ray.colour = vec4<f32>(shade(s.xyz, dir), 1.0);
                ray.state.x = 1.0;
                break;
            }
            ray.prev = s;
            ray.state.z = 1.0;
        }
    }
    rays[i] = ray;
    if ray.state.x < 0.5 {
        atomicAdd(&active_rays, 1u);
    }
}
