// Rays through pixel centres, shared by the small-sphere raster (small_spheres.wgsl) and
// the sphere pass's resolve of it (sphere_raycast.wgsl). Follows points.wgsl.

// `RasterUniforms` in sphere_raycast.rs: the image, and which spheres the compute raster
// draws.
struct Raster {
    // Image width and height in pixels.
    size: vec2<u32>,
    // Points of the cut.
    points: u32,
    // Largest side, in pixel centres, of a sphere's screen box that the compute raster
    // draws; larger spheres are drawn as impostor quads.
    max_side: u32,
    // Invocations per row of the dispatch (workgroups along x times 64).
    row: u32,
    pad0: u32,
    pad1: u32,
    pad2: u32,
};

// A view-space ray: origin and unit direction.
struct Ray {
    origin: vec3<f32>,
    dir: vec3<f32>,
};

// The ray through the image point `pix` (pixels from the top left corner; pixel centres
// at +0.5) of an image of `size` pixels, for the (possibly jittered) projection of
// `frame`: the inverse of the projection for the matrices the camera makes (perspective:
// x and y scaled and shifted by z; orthographic: scaled and shifted).
fn pixel_ray(pix: vec2<f32>, size: vec2<f32>) -> Ray {
    let ndc = vec2<f32>(pix.x / size.x * 2.0 - 1.0, 1.0 - pix.y / size.y * 2.0);
    let p = frame.clip_from_view;
    var ray: Ray;
    if frame.params.x > 0.5 {
        ray.origin = vec3<f32>((ndc.x - p[3].x) / p[0].x, (ndc.y - p[3].y) / p[1].y, 0.0);
        ray.dir = vec3<f32>(0.0, 0.0, -1.0);
    } else {
        ray.origin = vec3<f32>(0.0);
        ray.dir = normalize(vec3<f32>((ndc.x + p[2].x) / p[0].x, (ndc.y + p[2].y) / p[1].y, -1.0));
    }
    return ray;
}

// Where `ray` enters the sphere of view-space centre `c` and radius `r`: x, the distance
// along the ray; y, the discriminant (negative on a miss, then x is the closest approach).
// Measured from the ray's point closest to the centre, so that it stays accurate for
// small spheres far from the eye.
fn ray_sphere(ray: Ray, c: vec3<f32>, r: f32) -> vec2<f32> {
    let tc = dot(c - ray.origin, ray.dir);
    let q = c - (ray.origin + tc * ray.dir);
    let disc = r * r - dot(q, q);
    return vec2<f32>(tc - sqrt(max(disc, 0.0)), disc);
}

// The depth-buffer value (NDC z) of a view-space point.
fn ndc_depth(p: vec3<f32>) -> f32 {
    let clip = frame.clip_from_view * vec4<f32>(p, 1.0);
    return clip.z / clip.w;
}
