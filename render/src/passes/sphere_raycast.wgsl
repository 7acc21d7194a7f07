// Sphere ray casting: one depth-correct impostor per point.
//
// Each point is an instance of a 4-vertex triangle strip. The vertex shader pulls the
// point's quantized position from `positions` (raw 8- or 16-bit words of the file,
// packed into u32), decodes it with its range's base and scale
// (world = base + scale * (q - H)), looks up radius and albedo (from the species table
// for particles, from the node record copy in `attrs` for representatives), and places a
// view-facing quad that covers the sphere's projection, in the plane touching the
// sphere's front. The fragment shader intersects the pixel's ray with the sphere, discards
// misses, writes the hit's depth and shades it (Lambert + Blinn-Phong, one directional
// light fixed in view space). Depth is reversed (`frame.clip_from_view` here is
// `Camera::depth_clip_from_view`: z/w is 1 at the near plane, 0 at the far one, and the
// test keeps the greater), which resolves a relative 10⁻⁷ of the depth at any distance.
// Since the hit is never nearer than the quad, the pipeline declares the written depth
// "less or equal" where the device allows it (`@early_depth_test(less_equal)`, added by
// sphere_raycast.rs), so fragments behind what is already drawn are rejected before they
// are shaded.
//
// Where the device has 64-bit atomics, spheres a few pixels wide are drawn by the compute
// raster of small_spheres.wgsl instead: `fs_resolve` (a full-screen triangle drawn first
// in the pass) shades each pixel's nearest small sphere and writes its depth, and
// `vs_listed` draws the remaining spheres as impostors, against that depth.
//
// Follows points.wgsl (uniforms, bindings, point decoding) and pixel_rays.wgsl.

// The compute raster's results, for `fs_resolve` and `vs_listed`.
@group(1) @binding(0) var<storage, read> raster: Raster;
// Per pixel, the winning key (reversed entry depth bits above, the complement of the
// point index below; 0: no small sphere), read as two 32-bit words, low first.
@group(1) @binding(1) var<storage, read> visible_words: array<vec2<u32>>;
// The points to draw as impostors.
@group(1) @binding(2) var<storage, read> large: array<u32>;

struct VsOut {
    @builtin(position) clip: vec4<f32>,
    // The quad point in view space; the pixel's ray passes through it.
    @location(0) view_pos: vec3<f32>,
    @location(1) @interpolate(flat) center: vec3<f32>,
    @location(2) @interpolate(flat) radius: f32,
    @location(3) @interpolate(flat) albedo: vec3<f32>,
};

@vertex
fn vs_main(@builtin(vertex_index) vi: u32, @builtin(instance_index) ii: u32) -> VsOut {
    return sphere_vertex(vi, ii);
}

// Instance `ii` of the impostors the compute raster left to this pass.
@vertex
fn vs_listed(@builtin(vertex_index) vi: u32, @builtin(instance_index) ii: u32) -> VsOut {
    return sphere_vertex(vi, large[ii]);
}

// Corner `vi` of the quad of point `ii`.
// The largest coordinate of `v` in size (1 for the zero vector, so that dividing by it
// leaves that unchanged).
fn max_component(v: vec3<f32>) -> f32 {
    let m = max(abs(v.x), max(abs(v.y), abs(v.z)));
    return select(1.0, m, m > 0.0);
}

// |v| without squaring its coordinates: view positions of stars in metres (10^20) square
// past single precision.
fn scaled_length(v: vec3<f32>) -> f32 {
    let m = max_component(v);
    return m * length(v / m);
}

fn sphere_vertex(vi: u32, ii: u32) -> VsOut {
    let pt = load_point(ii);
    let world = pt.world;
    let radius = pt.radius;
    let albedo = pt.albedo;

    let center = (frame.view_from_world * vec4<f32>(world, 1.0)).xyz;
    let corner = vec2<f32>(f32(vi & 1u), f32((vi >> 1u) & 1u)) * 2.0 - 1.0;
    var out: VsOut;
    out.center = center;
    out.radius = radius;
    out.albedo = albedo;
    var p: vec3<f32>;
    if frame.params.x > 0.5 {
        // Orthographic: the projection is a disk of the sphere's radius; the quad lies
        // in the plane touching the sphere's front.
        p = center + vec3<f32>(corner * radius, radius);
    } else {
        let d = scaled_length(center);
        if d <= radius * 1.0001 {
            // The eye is inside the sphere: draw nothing (a degenerate quad).
            out.clip = vec4<f32>(0.0, 0.0, -1.0, 1.0);
            out.view_pos = center;
            return out;
        }
        // A quad facing the eye in the plane touching the sphere's front, holding the
        // tangent cone's circle there. The whole sphere lies behind that plane, so every
        // hit is at least as deep as the quad point on its ray (conservative depth).
        let dir = center / d;
        let helper = select(vec3<f32>(0.0, 1.0, 0.0), vec3<f32>(1.0, 0.0, 0.0), abs(dir.y) > 0.9);
        let u = normalize(cross(helper, dir));
        let v = cross(dir, u);
        let front = d - radius;
        // sqrt(d² − r²) without the squares, which overflow past 1.8e19.
        let half_size = radius * front / (sqrt(d - radius) * sqrt(d + radius));
        p = dir * front + (u * corner.x + v * corner.y) * half_size;
    }
    out.view_pos = p;
    out.clip = frame.clip_from_view * vec4<f32>(p, 1.0);
    return out;
}

struct FsOut {
    @location(0) colour: vec4<f32>,
    @builtin(frag_depth) depth: f32,
};

// The pixel's ray against the fragment's sphere: the view-space hit, its unit normal and
// the ray direction, or a discard on a miss.
struct Hit {
    point: vec3<f32>,
    normal: vec3<f32>,
    dir: vec3<f32>,
};

fn ray_hit(in: VsOut) -> Hit {
    var dir: vec3<f32>;
    if frame.params.x > 0.5 {
        dir = vec3<f32>(0.0, 0.0, -1.0);
    } else {
        dir = normalize(in.view_pos / max_component(in.view_pos));
    }
    // Ray from the quad point (close to the sphere, so the quadratic stays well
    // conditioned far from the eye); t may be negative (in front of the quad).
    let oc = in.view_pos - in.center;
    let b = dot(oc, dir);
    let c = dot(oc, oc) - in.radius * in.radius;
    let disc = b * b - c;
    if disc < 0.0 {
        discard;
    }
    let t = -b - sqrt(disc);
    var h: Hit;
    h.point = in.view_pos + t * dir;
    h.normal = (h.point - in.center) / in.radius;
    h.dir = dir;
    return h;
}

// The hit's depth, never nearer than the quad itself (it only differs by rounding; nearer
// is greater in reversed depth): the promise that lets the GPU reject hidden fragments
// before shading them (EARLY_DEPTH).
fn hit_depth(in: VsOut, hit: Hit) -> f32 {
    let clip = frame.clip_from_view * vec4<f32>(hit.point, 1.0);
    return min(clamp(clip.z / clip.w, 0.0, 1.0), in.clip.z);
}

// Lambert + Blinn-Phong for unit normal `n`, unit vector towards the eye `v`.
fn shade(n: vec3<f32>, v: vec3<f32>, albedo: vec3<f32>) -> vec3<f32> {
    let l = frame.light_dir_view.xyz;
    let ndl = max(dot(n, l), 0.0);
    let h = normalize(l + v);
    let spec = select(0.0, pow(max(dot(n, h), 0.0), frame.material.w), ndl > 0.0);
    let c = frame.light_colour.xyz;
    return albedo * (frame.material.x + frame.material.y * ndl * c)
        + frame.material.z * spec * c;
}

@fragment
fn fs_main(in: VsOut) -> FsOut {
    let hit = ray_hit(in);
    var out: FsOut;
    out.colour = vec4<f32>(shade(hit.normal, -hit.dir, in.albedo), 1.0);
    out.depth = hit_depth(in, hit);
    return out;
}

// A triangle covering the image, for `fs_resolve`.
@vertex
fn vs_fullscreen(@builtin(vertex_index) vi: u32) -> @builtin(position) vec4<f32> {
    let uv = vec2<f32>(f32((vi << 1u) & 2u), f32(vi & 2u));
    return vec4<f32>(uv * 2.0 - 1.0, 0.0, 1.0);
}

// The pixel's nearest small sphere (the compute raster's winner): its unit normal, the
// unit vector towards the eye, its albedo and its depth; a discard where there is none.
struct Resolved {
    normal: vec3<f32>,
    towards_eye: vec3<f32>,
    albedo: vec3<f32>,
    depth: f32,
};

fn resolve_pixel(pos: vec4<f32>) -> Resolved {
    let v = visible_words[u32(pos.y) * raster.size.x + u32(pos.x)];
    if v.x == 0u && v.y == 0u {
        discard;
    }
    let pt = load_point(~v.x);
    let c = (frame.view_from_world * vec4<f32>(pt.world, 1.0)).xyz;
    let ray = pixel_ray(pos.xy, vec2<f32>(raster.size));
    // The raster found a hit; a grazing one may round to a miss here (then the ray's
    // closest approach stands in for it).
    let h = ray_sphere(ray, c, pt.radius);
    let hit = ray.origin + h.x * ray.dir;
    var r: Resolved;
    r.normal = normalize(hit - c);
    r.towards_eye = -ray.dir;
    r.albedo = pt.albedo;
    r.depth = clamp(ndc_depth(hit), 0.0, 1.0);
    return r;
}

// The pixel's nearest small sphere, shaded, at its depth.
@fragment
fn fs_resolve(@builtin(position) pos: vec4<f32>) -> FsOut {
    let r = resolve_pixel(pos);
    var out: FsOut;
    out.colour = vec4<f32>(shade(r.normal, r.towards_eye, r.albedo), 1.0);
    out.depth = r.depth;
    return out;
}

// S-NDF sampling: the nearest hit's view-space normal and the point's albedo, unshaded.
struct GBufferOut {
    @location(0) normal: vec4<f32>,
    @location(1) albedo: vec4<f32>,
    @builtin(frag_depth) depth: f32,
};

@fragment
fn fs_gbuffer(in: VsOut) -> GBufferOut {
    let hit = ray_hit(in);
    var out: GBufferOut;
    out.normal = vec4<f32>(hit.normal, 1.0);
    out.albedo = vec4<f32>(in.albedo, 1.0);
    out.depth = hit_depth(in, hit);
    return out;
}

// S-NDF sampling of the pixel's nearest small sphere.
@fragment
fn fs_resolve_gbuffer(@builtin(position) pos: vec4<f32>) -> GBufferOut {
    let r = resolve_pixel(pos);
    var out: GBufferOut;
    out.normal = vec4<f32>(r.normal, 1.0);
    out.albedo = vec4<f32>(r.albedo, 1.0);
    out.depth = r.depth;
    return out;
}
