// The small-sphere raster: one invocation per point of the cut. A sphere whose screen box
// spans at most `raster.max_side` pixel centres each way is drawn here: every pixel
// centre in the box whose ray enters the sphere offers the key (entry depth, complement
// of the point index) to its pixel with a 64-bit atomic maximum. Depth is reversed (1 at
// the near plane, 0 at the far one: `Camera::depth_clip_from_view`), so the nearest entry
// wins (ties: the lower point index). The sphere pass's resolve
// (`fs_resolve` in sphere_raycast.wgsl) then shades each pixel's winner. Larger spheres,
// and spheres reaching the near or far plane, are listed in `large` (with their count in
// the indirect draw's instance count) and drawn as impostor quads after the resolve,
// against the depth it wrote.
//
// Why: a sphere a pixel or two wide costs a rasterizer two triangles, a quad of
// fragments and the setup of each, for one or two pixels; here it costs a few ray tests.
//
// Follows points.wgsl and pixel_rays.wgsl. Needs 64-bit integers and their atomic
// minimum and maximum (SHADER_INT64, SHADER_INT64_ATOMIC_MIN_MAX).

@group(1) @binding(0) var<storage, read> raster: Raster;
@group(1) @binding(1) var<storage, read_write> visible: array<atomic<u64>>;
@group(1) @binding(2) var<storage, read_write> large: array<u32>;
// The indirect draw of the large spheres: vertex count, instance count, first vertex,
// first instance.
@group(1) @binding(3) var<storage, read_write> draw_args: array<atomic<u32>, 4>;

fn draw_as_impostor(ii: u32) {
    let k = atomicAdd(&draw_args[1], 1u);
    large[k] = ii;
}

@compute @workgroup_size(64)
fn cs_small_spheres(@builtin(global_invocation_id) gid: vec3<u32>) {
    let ii = gid.y * raster.row + gid.x;
    if ii >= raster.points {
        return;
    }
    let pt = load_point(ii);
    let c = (frame.view_from_world * vec4<f32>(pt.world, 1.0)).xyz;
    let r = pt.radius;
    let ortho = frame.params.x > 0.5;
    // Depths along the view axis of the sphere's near and far sides.
    let t0 = -c.z - r;
    let t1 = -c.z + r;
    // Wholly between the near and far planes (reversed depth: below 1 and above 0), in
    // front of the eye (NaN fails too).
    let inside = r > 0.0 && (ortho || t0 > 0.0) && ndc_depth(vec3<f32>(0.0, 0.0, -t0)) < 1.0
        && ndc_depth(vec3<f32>(0.0, 0.0, -t1)) > 0.0;
    if !inside {
        draw_as_impostor(ii);
        return;
    }
    // The sphere's view-aligned box, projected: x / t and y / t are monotone in each
    // coordinate, so the extremes come from the box's faces.
    let p = frame.clip_from_view;
    var lo: vec2<f32>;
    var hi: vec2<f32>;
    if ortho {
        lo = vec2<f32>(p[0].x, p[1].y) * (c.xy - vec2<f32>(r)) + p[3].xy;
        hi = vec2<f32>(p[0].x, p[1].y) * (c.xy + vec2<f32>(r)) + p[3].xy;
    } else {
        let a = c.xy - vec2<f32>(r);
        let b = c.xy + vec2<f32>(r);
        lo = vec2<f32>(p[0].x, p[1].y) * min(a / t0, a / t1) - p[2].xy;
        hi = vec2<f32>(p[0].x, p[1].y) * max(b / t0, b / t1) - p[2].xy;
    }
    let size = vec2<f32>(raster.size);
    // Pixels, y down; grown a little against rounding.
    let x0 = (lo.x + 1.0) * 0.5 * size.x - 0.01;
    let x1 = (hi.x + 1.0) * 0.5 * size.x + 0.01;
    let y0 = (1.0 - hi.y) * 0.5 * size.y - 0.01;
    let y1 = (1.0 - lo.y) * 0.5 * size.y + 0.01;
    // Pixel centres inside, clamped to the image.
    let i0 = max(ceil(x0 - 0.5), 0.0);
    let i1 = min(floor(x1 - 0.5), size.x - 1.0);
    let j0 = max(ceil(y0 - 0.5), 0.0);
    let j1 = min(floor(y1 - 0.5), size.y - 1.0);
    if !(i0 <= i1 && j0 <= j1) {
        // No pixel centre can see it.
        return;
    }
    let side = f32(raster.max_side);
    if i1 - i0 + 1.0 > side || j1 - j0 + 1.0 > side {
        draw_as_impostor(ii);
        return;
    }
    let w = raster.size.x;
    for (var j = u32(j0); j <= u32(j1); j++) {
        for (var i = u32(i0); i <= u32(i1); i++) {
            let ray = pixel_ray(vec2<f32>(f32(i) + 0.5, f32(j) + 0.5), size);
            let h = ray_sphere(ray, c, r);
            if h.y >= 0.0 {
                let z = clamp(ndc_depth(ray.origin + h.x * ray.dir), 0.0, 1.0);
                let key = (u64(bitcast<u32>(z)) << 32u) | u64(~ii);
                atomicMax(&visible[j * w + i], key);
            }
        }
    }
}
