//! Rendering tests on a real device: Vulkan (lavapipe on machines without a GPU) unless
//! `WGPU_BACKEND` names another backend. Images are small (≤ 256×256) and scenes have
//! ≤ 10^4 particles so that the whole file runs in seconds on a CPU rasterizer.

mod common;

use std::sync::{Arc, OnceLock};

use common::golden::{self, Tolerance};
use common::*;
use glam::{Mat4, Vec3, Vec4};
use mdlod_format::MdlodFile;
use mdlod_render::style::{pack_file_colour, unpack_colour};
use mdlod_render::{
    camera_for, render_image, render_image_keeping, render_to_png, traverse, BackendChoice, Camera,
    FrameSettings, GpuContext, OcclusionMode, Projection, RenderError, RenderOptions,
    RenderedFrame, Renderer, RgbaImage, TraversalSettings, ViewFile, ViewSpec,
};

/// The backends the tests use: `WGPU_BACKEND` when set, else Vulkan only (so that a
/// missing Vulkan driver fails loudly instead of silently falling back to GL).
fn backends() -> BackendChoice {
    if std::env::var_os("WGPU_BACKEND").is_some() {
        BackendChoice::FromEnv
    } else {
        BackendChoice::Only(wgpu::Backends::VULKAN)
    }
}

fn renderer() -> &'static Renderer {
    static R: OnceLock<Renderer> = OnceLock::new();
    R.get_or_init(|| match GpuContext::with_backends(backends()) {
        Ok(ctx) => Renderer::new(ctx),
        Err(e) => panic!("{e}"),
    })
}

fn opts(width: u32, height: u32) -> RenderOptions {
    RenderOptions {
        width,
        height,
        error_px: 0.0,
        budget: u64::MAX,
        background: [0.0, 0.0, 0.0],
        backends: backends(),
        ..Default::default()
    }
}

/// The cut of `f` for `camera` at `viewport` and `error_px`, with no budget.
fn cut(
    f: &MdlodFile,
    camera: &Camera,
    viewport: [u32; 2],
    error_px: f32,
    occlusion: OcclusionMode,
) -> mdlod_render::DrawList {
    traverse(
        camera,
        f,
        &TraversalSettings {
            viewport,
            error_px,
            budget_points: u64::MAX,
            occlusion,
            support_scale: 0.0,
            hidden: mdlod_render::HiddenSet::default(),
            clip: Default::default(),
        },
    )
}

/// Renders every particle of `f` with `camera` (near/far refitted), with depth.
fn render_all(f: &MdlodFile, camera: &Camera, w: u32, h: u32, spp: u32) -> RenderedFrame {
    let mut camera = camera.clone();
    camera.fit_depth_range(&mdlod_render::data_bounds(f));
    let draw = traverse(
        &camera,
        f,
        &TraversalSettings {
            viewport: [w, h],
            error_px: 0.0,
            budget_points: u64::MAX,
            occlusion: OcclusionMode::Off,
            support_scale: 0.0,
            hidden: mdlod_render::HiddenSet::default(),
            clip: Default::default(),
        },
    );
    renderer()
        .render(f, &camera, &draw, &depth_frame(w, h, spp))
        .unwrap()
}

/// Frame settings that read the depth back, on a black background.
fn depth_frame(w: u32, h: u32, spp: u32) -> FrameSettings {
    FrameSettings {
        width: w,
        height: h,
        spp,
        background_srgb: [0.0; 3],
        read_depth: true,
        ..Default::default()
    }
}

fn ortho_camera(target: Vec3, distance: f32) -> Camera {
    Camera {
        target,
        azimuth_deg: 0.0,
        elevation_deg: 0.0,
        distance,
        fov_y_deg: 90.0,
        projection: Projection::Orthographic,
        ..Default::default()
    }
}

#[test]
fn single_sphere_covers_its_projected_disk_area() {
    // Orthographic, fov 90°: the view is 2·distance world units high.
    let (_d, _p, f) = make_file(
        &spheres_frame(&[[1.0, 2.0, 3.0]]),
        small_build(),
        &[("X", 2.0)],
    );
    let size = 128u32;
    for distance in [3.0f32, 5.0, 12.0] {
        let cam = ortho_camera(
            Vec3::new(1.0, 2.0, 3.0) + Vec3::new(0.0, 0.13, -0.07),
            distance,
        );
        let frame = render_all(&f, &cam, size, size, 1);
        let depth = frame.depth.unwrap();
        let covered = depth.iter().filter(|&&d| d < 1.0).count() as f64;
        let r_px = 2.0 * f64::from(size) / (2.0 * f64::from(distance));
        let area = std::f64::consts::PI * r_px * r_px;
        // Pixel-centre sampling of a disk: the count deviates from πr² by far less than
        // 1% for radii of tens of pixels (Gauss circle problem: O(r^(2/3))).
        let tol = 0.01 * area + 2.0;
        assert!(
            (covered - area).abs() <= tol,
            "distance {distance}: {covered} pixels covered, disk area {area:.1} (±{tol:.1})"
        );
        // The colour image agrees with the depth image.
        let lit = frame
            .image
            .data
            .chunks_exact(4)
            .filter(|p| p[0] > 0 || p[1] > 0 || p[2] > 0)
            .count() as f64;
        assert_eq!(lit, covered);
    }
}

/// Without a background the pixels no sphere covers are transparent and the covered ones
/// opaque with the colours of the opaque image; with several samples a silhouette's
/// pixels are partly transparent, alpha the share of samples that hit, and their straight
/// colour that of the sphere's edge (not darkened towards a background).
#[test]
fn a_transparent_background_leaves_uncovered_pixels_clear_and_edges_partial() {
    let (_d, _p, f) = make_file(
        &spheres_frame(&[[1.0, 2.0, 3.0]]),
        small_build(),
        &[("X", 2.0)],
    );
    let size = 64u32;
    let mut cam = ortho_camera(Vec3::new(1.0, 2.0, 3.0), 5.0);
    cam.fit_depth_range(&mdlod_render::data_bounds(&f));
    let draw = cut(&f, &cam, [size, size], 0.0, OcclusionMode::Off);
    let frame = |spp: u32, transparent: bool, background: [f32; 3]| {
        let settings = FrameSettings {
            width: size,
            height: size,
            spp,
            background_srgb: background,
            transparent,
            ..Default::default()
        };
        renderer().render(&f, &cam, &draw, &settings).unwrap().image
    };
    let opaque = frame(1, false, [0.0; 3]);
    let clear = frame(1, true, [1.0, 0.0, 1.0]);
    let mut covered = 0;
    for (o, c) in opaque.data.chunks_exact(4).zip(clear.data.chunks_exact(4)) {
        if o[..3] == [0, 0, 0] {
            assert_eq!(c[3], 0, "an uncovered pixel is transparent");
        } else {
            covered += 1;
            assert_eq!(c, o, "a covered pixel keeps its colour, opaque");
        }
    }
    assert!(covered > 500, "{covered}");
    // Supersampled: partial alphas on the silhouette only, their colour the sphere's
    // own (over black, the same pixel is darker by its alpha).
    let soft = frame(16, true, [0.0; 3]);
    let over_black = frame(16, false, [0.0; 3]);
    let mut partial = 0;
    for (s, b) in soft
        .data
        .chunks_exact(4)
        .zip(over_black.data.chunks_exact(4))
    {
        let a = f32::from(s[3]) / 255.0;
        if s[3] == 0 || s[3] == 255 {
            continue;
        }
        partial += 1;
        for k in 0..3 {
            let straight = mdlod_render::renderer::srgb_to_linear(f32::from(s[k]) / 255.0);
            let dark = mdlod_render::renderer::srgb_to_linear(f32::from(b[k]) / 255.0);
            assert!(
                (straight * a - dark).abs() < 0.02,
                "channel {k}: straight {straight} at alpha {a}, over black {dark}"
            );
        }
    }
    let r_px = 2.0 * f64::from(size) / 10.0;
    assert!(
        partial as f64 > 2.0 * std::f64::consts::PI * r_px * 0.5,
        "{partial} partly covered pixels on a silhouette of radius {r_px} px"
    );
}

/// Nearest hit of the ray `o + t d` (`d` of unit length) with the spheres: `(t, graze)`
/// with `graze` the discriminant over r² of the sphere hit (0 at the silhouette), and the
/// smallest |discriminant| / r² over all spheres (small: some sphere is grazed or nearly
/// hit, and rasterization rounding may go either way). Measured from the ray's point
/// closest to each centre, as the shaders do, so that it holds far from the eye too.
fn cpu_hit(o: Vec3, d: Vec3, spheres: &[(Vec3, f32)]) -> (Option<(f32, f32)>, f32) {
    let mut best: Option<(f32, f32)> = None;
    let mut closest_call = f32::INFINITY;
    for &(c, r) in spheres {
        let tc = (c - o).dot(d);
        let q = c - (o + d * tc);
        let disc = r * r - q.dot(q);
        closest_call = closest_call.min((disc / (r * r)).abs());
        if disc < 0.0 {
            continue;
        }
        let t = tc - disc.sqrt();
        if best.is_none_or(|(bt, _)| t < bt) {
            best = Some((t, disc / (r * r)));
        }
    }
    (best, closest_call)
}

#[test]
fn hit_depth_matches_a_cpu_ray_sphere_intersection() {
    let mut rng = Rng::new(11);
    let centres: Vec<[f32; 3]> = (0..40)
        .map(|_| [0; 3].map(|_| 20.0 * rng.next_f32()))
        .collect();
    let (_d, _p, f) = make_file(&spheres_frame(&centres), small_build(), &[("X", 1.7)]);
    check_hit_depth(&f, |_| 1.7);
}

/// Particles of their own sizes (a polydisperse species, radii 0.4 to 3): each is drawn
/// at its own radius, to the depth a CPU ray cast against those radii finds.
#[test]
fn particles_of_their_own_sizes_are_drawn_at_their_own_radii() {
    let mut rng = Rng::new(12);
    let centres: Vec<[f32; 3]> = (0..40)
        .map(|_| [0; 3].map(|_| 20.0 * rng.next_f32()))
        .collect();
    let radii: Vec<f32> = (0..40).map(|_| 0.4 + 2.6 * rng.next_f32()).collect();
    let mut frame = spheres_frame(&centres);
    frame.species[0].radius = Some(1.7);
    frame.species[0].radius_range = Some((0.4, 3.0));
    frame.radii = Some(radii.clone());
    let (_d, _p, f) = make_file(&frame, small_build(), &[]);
    assert!(f.radii().is_some());
    // The file's radii are the input's, to 16 bits over their range.
    let last = f.level_count() - 1;
    let decoded = f.decode_level(last).unwrap();
    for (i, p) in decoded.iter().enumerate() {
        let k = centres
            .iter()
            .position(|c| Vec3::from(*c).distance(Vec3::from(*p)) < 1e-3)
            .unwrap();
        assert!((f.particle_radius(i) - radii[k]).abs() < 3e-5);
    }
    check_hit_depth(&f, |i| f.particle_radius(i));
}

/// Renders `f` (particles only on its finest level, no LOD: error 0) from two views and
/// compares each pixel's depth with a CPU ray cast against the particles at `radius_of`.
fn check_hit_depth(f: &MdlodFile, radius_of: impl Fn(usize) -> f32) {
    let last = f.level_count() - 1;
    let spheres: Vec<(Vec3, f32)> = f
        .decode_level(last)
        .unwrap()
        .into_iter()
        .enumerate()
        .map(|(i, p)| (Vec3::from(p), radius_of(i)))
        .collect();
    let (w, h) = (160u32, 120u32);
    for projection in [Projection::Perspective, Projection::Orthographic] {
        let mut cam = camera_for(
            f,
            &ViewSpec::Orbit {
                azimuth_deg: 35.0,
                elevation_deg: 25.0,
                zoom: 1.3,
                projection,
            },
            w,
            h,
        )
        .unwrap();
        cam.fit_depth_range(&mdlod_render::data_bounds(f));
        let frame = render_all(f, &cam, w, h, 1);
        let depth = frame.depth.unwrap();
        let clip_from_view = cam.clip_from_view(w as f32 / h as f32);
        let view_from_clip = clip_from_view.inverse();
        let view_from_world = cam.view_from_world();
        let view_spheres: Vec<(Vec3, f32)> = spheres
            .iter()
            .map(|&(c, r)| (view_from_world.transform_point3(c), r))
            .collect();
        let unproject = |m: &Mat4, x: f32, y: f32, z: f32| {
            let v = *m * Vec4::new(x, y, z, 1.0);
            v.truncate() / v.w
        };
        let (mut compared, mut hits) = (0, 0);
        for py in 0..h {
            for px in 0..w {
                let nx = 2.0 * (px as f32 + 0.5) / w as f32 - 1.0;
                let ny = 1.0 - 2.0 * (py as f32 + 0.5) / h as f32;
                let a = unproject(&view_from_clip, nx, ny, 0.0);
                let b = unproject(&view_from_clip, nx, ny, 1.0);
                let dir = (b - a).normalize();
                let gpu = depth[(py * w + px) as usize];
                let (hit, closest_call) = cpu_hit(a, dir, &view_spheres);
                if closest_call < 2e-2 {
                    // A grazing ray may go either way under rasterization rounding.
                    continue;
                }
                match hit {
                    Some((t, graze)) => {
                        let hit = a + dir * t;
                        let clip = clip_from_view * hit.extend(1.0);
                        let expected = clip.z / clip.w;
                        // Compare as view-space depth (linear, world units). The GPU's ray
                        // comes from an interpolated quad point (relative error ~1e-6..1e-5
                        // on real GPUs); near a silhouette depth amplifies a ray error by
                        // 1/sqrt(graze).
                        let gpu_view = unproject(&view_from_clip, nx, ny, gpu).z;
                        let tol = 1e-3 + 2e-5 * hit.z.abs() / graze.sqrt();
                        assert!(
                            (gpu_view - hit.z).abs() < tol,
                            "{projection:?} pixel ({px},{py}): GPU depth {gpu} (z {gpu_view}), \
                             CPU {expected} (z {}), tolerance {tol}, graze {graze}",
                            hit.z
                        );
                        compared += 1;
                        hits += 1;
                    }
                    None => {
                        assert_eq!(gpu, 1.0, "{projection:?} pixel ({px},{py}) should be empty");
                        compared += 1;
                    }
                }
            }
        }
        assert!(
            hits > 1000 && compared > (w * h) as usize * 9 / 10,
            "{hits} {compared}"
        );
    }
}

#[test]
fn golden_fcc_block_perspective_supersampled() {
    let (_d, _p, f) = make_file(&fcc_frame(5), small_build(), &[]);
    let mut o = opts(128, 128);
    o.spp = 4;
    o.background = [0.1, 0.12, 0.15];
    o.view = ViewSpec::Orbit {
        azimuth_deg: 35.0,
        elevation_deg: 25.0,
        zoom: 1.1,
        projection: Projection::Perspective,
    };
    // With occlusion culling (the default) and without it, the same golden image.
    let (img, report) = render_image(renderer(), &f, &o).unwrap();
    assert!(report.nodes_occluded > 0 && report.particles_drawn < 500);
    o.occlusion = false;
    let (all, all_report) = render_image(renderer(), &f, &o).unwrap();
    assert_eq!(all_report.particles_drawn, 500);
    for image in [&img, &all] {
        golden::check(
            "fcc_block_perspective_4spp",
            image,
            Tolerance {
                per_channel: 8,
                max_failing_share: 0.005,
            },
        );
    }
}

#[test]
fn golden_cloud_lod_orthographic() {
    let (_d, _p, f) = make_file(&cloud_frame(6000, 21), small_build(), &[]);
    let mut o = opts(160, 120);
    o.error_px = 6.0;
    o.background = [1.0, 1.0, 1.0];
    o.view = ViewSpec::Orbit {
        azimuth_deg: -60.0,
        elevation_deg: 40.0,
        zoom: 1.0,
        projection: Projection::Orthographic,
    };
    let (img, report) = render_image(renderer(), &f, &o).unwrap();
    assert!(
        report.nodes_drawn > 0 && report.particles_drawn > 0,
        "{report:?}"
    );
    golden::check(
        "cloud_lod_orthographic",
        &img,
        Tolerance {
            per_channel: 8,
            max_failing_share: 0.005,
        },
    );
}

fn mean_abs_diff(a: &RgbaImage, b: &RgbaImage) -> f64 {
    let s: u64 = a
        .data
        .iter()
        .zip(&b.data)
        .map(|(x, y)| u64::from(x.abs_diff(*y)))
        .sum();
    s as f64 / a.data.len() as f64
}

#[test]
fn supersampling_converges_to_the_reference() {
    let (_d, _p, f) = make_file(&fcc_frame(4), small_build(), &[]);
    let cam = camera_for(&f, &ViewSpec::default(), 96, 96).unwrap();
    let reference = render_all(&f, &cam, 96, 96, 64).image;
    let one = render_all(&f, &cam, 96, 96, 1).image;
    let sixteen = render_all(&f, &cam, 96, 96, 16).image;
    let (e1, e16) = (
        mean_abs_diff(&one, &reference),
        mean_abs_diff(&sixteen, &reference),
    );
    assert!(e16 < e1 * 0.5, "1 spp: {e1}, 16 spp: {e16}");
    assert!(e16 < 1.0, "16 spp differs from 64 spp by {e16} on average");
}

#[test]
fn many_samples_of_a_flat_background_average_to_that_background() {
    // The average of N equal samples is the sample. Summed by additive blending into a
    // half-float target, each step rounded the same way: 256 samples of 0.5 (sRGB) came
    // out 123 instead of 127, of 0.3 75 instead of 77.
    let (_d, _p, f) = make_file(&fcc_frame(2), small_build(), &[]);
    let mut cam = camera_for(&f, &ViewSpec::default(), 32, 32).unwrap();
    // The data covers a few pixels at the centre; the corners see the background.
    cam.distance *= 20.0;
    cam.fit_depth_range(&mdlod_render::data_bounds(&f));
    let draw = cut(&f, &cam, [32, 32], 0.0, OcclusionMode::Off);
    assert!(draw.points > 0);
    for bg in [[0.3f32, 0.5, 0.7], [0.11, 0.13, 0.17], [0.9, 0.95, 0.99]] {
        let frame = |spp| {
            let settings = FrameSettings {
                width: 32,
                height: 32,
                spp,
                background_srgb: bg,
                ..Default::default()
            };
            renderer().render(&f, &cam, &draw, &settings).unwrap().image
        };
        let one = frame(1);
        let corners = [(0, 0), (31, 0), (0, 31), (31, 31)];
        for &(x, y) in &corners {
            let p = one.pixel(x, y);
            for c in 0..3 {
                let expected = bg[c] * 255.0;
                assert!(
                    (f32::from(p[c]) - expected).abs() <= 0.5 + 1e-3,
                    "{p:?} {bg:?}"
                );
            }
        }
        for spp in [2, 3, 64, 256] {
            let many = frame(spp);
            for &(x, y) in &corners {
                assert_eq!(many.pixel(x, y), one.pixel(x, y), "{spp} spp, {bg:?}");
            }
        }
    }
}

#[test]
fn data_in_metres_or_light_years_renders_as_in_angstroms() {
    // The same block at 10^-10 (atoms in metres) and 5·10^17 scale (the eye 2·10^19 away,
    // as for stars in metres; the format's f32 area sums, Σ r², cap the radii there). The
    // view was fitted to a radius of at least 10^-6 (the atoms a dot), and lengths were
    // squared in single precision on the host and in the impostor shader (no image at
    // all past 10^19: the camera fit, the projection and every depth overflowed).
    let frame = fcc_frame(3);
    let image = |scale: f32| {
        let mut scaled = frame.clone();
        for p in &mut scaled.positions {
            *p = p.map(|v| v * scale);
        }
        let (_d, _p, f) = make_file(
            &scaled,
            small_build(),
            &[("Cu", 1.28 * scale), ("Ag", 1.44 * scale)],
        );
        let mut o = opts(96, 96);
        o.view = ViewSpec::Orbit {
            azimuth_deg: 30.0,
            elevation_deg: 20.0,
            zoom: 1.0,
            projection: Projection::Perspective,
        };
        render_image(renderer(), &f, &o).unwrap().0
    };
    let reference = image(1.0);
    let covered = reference.data.chunks(4).filter(|p| p[0] > 0).count();
    assert!(covered > 96 * 96 / 4, "{covered} pixels show the block");
    for scale in [1e-10, 5e17] {
        let other = image(scale);
        let differing = reference
            .data
            .chunks(4)
            .zip(other.data.chunks(4))
            .filter(|(a, b)| a.iter().zip(*b).any(|(x, y)| x.abs_diff(*y) > 8))
            .count();
        assert!(
            differing * 100 <= covered,
            "scale {scale}: {differing} of {covered} pixels differ"
        );
    }
}

#[test]
fn a_kept_cut_is_drawn_again_under_other_lights_and_chosen_anew_for_another_view() {
    // A cloud with occlusion culling and a coarse error, so that the cut is a real choice.
    let (_d, _p, f) = make_file(&cloud_frame(3000, 7), small_build(), &[]);
    let mut o = opts(64, 48);
    o.error_px = 4.0;
    o.background = [0.1, 0.2, 0.3];
    let mut kept = mdlod_render::KeptCut::default();
    let first = render_image_keeping(renderer(), &f, &o, &mut kept).unwrap();
    assert_eq!(kept.chosen(), 1);
    assert_eq!(
        first.0.data,
        render_image(renderer(), &f, &o).unwrap().0.data
    );
    // Other lights and background: the same cut, drawn as a fresh render draws it,
    // pixel for pixel.
    o.lighting.direction_view = Vec3::new(0.6, -0.3, 1.0).normalize();
    o.background = [1.0, 1.0, 1.0];
    let relit = render_image_keeping(renderer(), &f, &o, &mut kept).unwrap();
    assert_eq!(kept.chosen(), 1);
    assert_eq!(
        relit.0.data,
        render_image(renderer(), &f, &o).unwrap().0.data
    );
    assert_ne!(relit.0.data, first.0.data);
    assert_eq!(
        (relit.1.particles_drawn, relit.1.nodes_drawn),
        (first.1.particles_drawn, first.1.nodes_drawn)
    );
    // Another view, a finer error, a smaller image, or several samples per pixel (whose
    // occlusion culling counts only pixels every sample covers): a new cut.
    for change in 0..4 {
        let mut p = o.clone();
        match change {
            0 => {
                p.view = ViewSpec::Orbit {
                    azimuth_deg: 75.0,
                    elevation_deg: 10.0,
                    zoom: 1.0,
                    projection: Projection::Perspective,
                }
            }
            1 => p.error_px = 1.0,
            2 => p.width = 32,
            _ => p.spp = 4,
        }
        let (image, report) = render_image_keeping(renderer(), &f, &p, &mut kept).unwrap();
        assert_eq!(kept.chosen(), 2 + change);
        let (fresh, fresh_report) = render_image(renderer(), &f, &p).unwrap();
        assert_eq!(image.data, fresh.data, "change {change}");
        assert_eq!(report.particles_drawn, fresh_report.particles_drawn);
    }
}

#[test]
fn the_light_colour_tints_the_diffuse_and_specular_light() {
    // One white sphere filling the view, lit head-on: under a blue light its red and
    // green come from the (white) ambient light alone. The colour was not passed to the
    // sphere passes (the viewer's first light lit them white whatever its colour).
    let (_d, _p, f) = make_file(&spheres_frame(&[[0.0; 3]]), small_build(), &[("X", 2.0)]);
    let render = |colour: [f32; 3]| {
        let mut o = opts(48, 48);
        o.view = ViewSpec::Orbit {
            azimuth_deg: 0.0,
            elevation_deg: 0.0,
            zoom: 1.5,
            projection: Projection::Orthographic,
        };
        o.style.species = vec![mdlod_render::SpeciesStyle {
            name: "X".into(),
            colour: Some([1.0; 3]),
            ..Default::default()
        }];
        o.lighting = mdlod_render::Lighting {
            direction_view: Vec3::Z,
            colour,
            ambient: 0.2,
            diffuse: 0.6,
            specular: 0.0,
            ..Default::default()
        };
        render_image(renderer(), &f, &o).unwrap().0.pixel(24, 24)
    };
    let white = render([1.0; 3]);
    let blue = render([0.0, 0.0, 1.0]);
    // Linear 0.8 and 0.2 in sRGB: 231 and 124.
    for c in 0..3 {
        assert!(white[c].abs_diff(231) <= 2, "white light: {white:?}");
    }
    assert!(
        blue[0].abs_diff(124) <= 2 && blue[1].abs_diff(124) <= 2 && blue[2].abs_diff(231) <= 2,
        "blue light: {blue:?}"
    );
}

#[test]
fn view_file_and_orbit_options_give_the_same_image() {
    let (dir, _p, f) = make_file(&cloud_frame(800, 31), small_build(), &[]);
    let view = dir.path().join("view.json");
    std::fs::write(
        &view,
        r#"{"version": 1, "azimuth_deg": 10, "elevation_deg": -20, "zoom": 1.5}"#,
    )
    .unwrap();
    let mut a = opts(64, 64);
    a.view = ViewSpec::File(view.clone());
    let mut b = opts(64, 64);
    b.view = ViewSpec::Orbit {
        azimuth_deg: 10.0,
        elevation_deg: -20.0,
        zoom: 1.5,
        projection: Projection::Perspective,
    };
    let (ia, ra) = render_image(renderer(), &f, &a).unwrap();
    let (ib, _) = render_image(renderer(), &f, &b).unwrap();
    assert_eq!(ia, ib);
    // The report's camera saved as a view file reproduces the image too.
    ViewFile::from_camera(&ra.camera).save(&view).unwrap();
    let (ic, _) = render_image(renderer(), &f, &a).unwrap();
    assert_eq!(ia, ic);
}

#[test]
fn render_to_png_writes_the_image_and_reports() {
    let (dir, path, _f) = make_file(&cloud_frame(2000, 41), small_build(), &[]);
    let out = dir.path().join("out.png");
    let mut o = opts(64, 48);
    o.error_px = 3.0;
    o.spp = 2;
    let report = render_to_png(&path, &out, &o).unwrap();
    let img = RgbaImage::load_png(&out).unwrap();
    assert_eq!((img.width, img.height), (64, 48));
    assert!(report.particles_drawn + report.nodes_drawn > 0);
    assert!(!report.adapter.is_empty());
    assert_eq!((report.width, report.height, report.spp), (64, 48, 2));
    if renderer().ctx.timestamps() {
        assert!(
            report.gpu_time.is_some_and(|t| t.as_nanos() > 0),
            "{report:?}"
        );
    }
    // Something other than the background was drawn.
    assert!(img.data.chunks_exact(4).any(|p| p[..3] != [0, 0, 0]));
}

#[test]
fn invalid_options_are_errors_not_panics() {
    let (_d, _p, f) = make_file(&cloud_frame(100, 51), small_build(), &[]);
    for (w, h, spp, err) in [
        (0, 10, 1, 1.0),
        (10, 10, 0, 1.0),
        (10, 10, 1000, 1.0),
        (10, 10, 1, f32::NAN),
        (100_000, 10, 1, 1.0),
    ] {
        let mut o = opts(w, h);
        o.spp = spp;
        o.error_px = err;
        match render_image(renderer(), &f, &o) {
            Err(RenderError::InvalidOptions(_)) => {}
            other => panic!("{w}x{h} spp {spp} error {err}: {other:?}"),
        }
    }
    for bad in [
        Camera {
            distance: f32::NAN,
            ..Default::default()
        },
        Camera {
            distance: 0.0,
            ..Default::default()
        },
        Camera {
            fov_y_deg: 180.0,
            ..Default::default()
        },
    ] {
        let mut o = opts(16, 16);
        o.view = ViewSpec::Camera(bad);
        assert!(matches!(
            render_image(renderer(), &f, &o),
            Err(RenderError::InvalidOptions(_))
        ));
    }
}

#[test]
fn missing_adapter_is_a_clear_error() {
    let e = GpuContext::with_backends(BackendChoice::Only(wgpu::Backends::empty())).unwrap_err();
    assert!(matches!(e, RenderError::NoAdapter { .. }), "{e:?}");
    let msg = e.to_string();
    assert!(
        msg.contains("mesa-vulkan-drivers") && msg.contains("GPU driver"),
        "{msg}"
    );
    // Through the library entry point: the error, and no output file.
    let (dir, path, _f) = make_file(&cloud_frame(100, 61), small_build(), &[]);
    let out = dir.path().join("none.png");
    let mut o = opts(32, 32);
    o.backends = BackendChoice::Only(wgpu::Backends::empty());
    let e = render_to_png(&path, &out, &o).unwrap_err();
    assert!(matches!(e, RenderError::NoAdapter { .. }), "{e:?}");
    assert!(!out.exists());
}

/// Run by [`wgpu_backend_naming_an_absent_backend_is_a_clear_error`] in a child process
/// with `WGPU_BACKEND=dx12` (there is no DX12 on Linux).
#[test]
#[ignore = "run as a child process by wgpu_backend_naming_an_absent_backend_is_a_clear_error"]
fn child_render_with_absent_backend() {
    let (dir, path, _f) = make_file(&cloud_frame(100, 71), small_build(), &[]);
    let out = dir.path().join("none.png");
    let mut o = opts(32, 32);
    o.backends = BackendChoice::FromEnv;
    let e = render_to_png(&path, &out, &o).unwrap_err();
    let msg = e.to_string();
    assert!(matches!(e, RenderError::NoAdapter { .. }), "{e:?}");
    assert!(
        msg.contains("WGPU_BACKEND=dx12") && msg.contains("mesa-vulkan-drivers"),
        "{msg}"
    );
    assert!(!out.exists());
}

#[test]
#[cfg(not(windows))]
fn wgpu_backend_naming_an_absent_backend_is_a_clear_error() {
    let exe = std::env::current_exe().unwrap();
    let out = std::process::Command::new(exe)
        .args([
            "--exact",
            "child_render_with_absent_backend",
            "--ignored",
            "--nocapture",
            "--test-threads=1",
        ])
        .env("WGPU_BACKEND", "dx12")
        .output()
        .unwrap();
    let text =
        String::from_utf8_lossy(&out.stdout).to_string() + &String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "child failed:\n{text}");
    assert!(text.contains("1 passed"), "{text}");
}

/// Timings on a larger scene (not part of the normal run):
/// `cargo test -p mdlod-render --release --test gpu timing -- --ignored --nocapture`.
#[test]
#[ignore = "timing report, run by hand"]
fn timing_fcc_block() {
    let n: usize = std::env::var("MDLOD_TIMING_CELLS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(30);
    let t = std::time::Instant::now();
    let (dir, path, f) = make_file(&fcc_frame(n), Default::default(), &[]);
    eprintln!(
        "{} particles converted in {:.2?}",
        f.particle_count(),
        t.elapsed()
    );
    for (error_px, spp, zoom) in [
        (0.0, 1, 1.0),
        (1.0, 1, 1.0),
        (0.0, 4, 1.0),
        (0.0, 1, 0.1),
        (1.0, 1, 0.1),
        (4.0, 1, 0.1),
    ] {
        let mut o = opts(1280, 720);
        o.error_px = error_px;
        o.spp = spp;
        o.view = ViewSpec::Orbit {
            azimuth_deg: 30.0,
            elevation_deg: 20.0,
            zoom,
            projection: Projection::Perspective,
        };
        o.background = [1.0; 3];
        let out = dir
            .path()
            .join(format!("timing-{error_px}-{spp}-{zoom}.png"));
        let r = render_to_png(&path, &out, &o).unwrap();
        eprintln!(
            "zoom {zoom}, error {error_px} px, {spp} spp: {} particles + {} nodes in {} ranges; traversal \
             {:.2?}, GPU {:?}, total {:.2?} ({})",
            r.particles_drawn,
            r.nodes_drawn,
            r.ranges,
            r.traversal_time,
            r.gpu_time,
            r.total_time,
            r.adapter
        );
        if let Ok(keep) = std::env::var("MDLOD_TIMING_KEEP") {
            std::fs::copy(
                &out,
                std::path::Path::new(&keep).join(out.file_name().unwrap()),
            )
            .unwrap();
        }
    }
}

/// A close-up from straight above, orthographic, of the part of `f` around `target`.
fn corner_camera(f: &MdlodFile, w: u32, h: u32, target: Vec3) -> Camera {
    let view = ViewSpec::Orbit {
        azimuth_deg: 0.0,
        elevation_deg: 90.0,
        zoom: 5.0,
        projection: Projection::Orthographic,
    };
    let mut camera = camera_for(f, &view, w, h).unwrap();
    camera.target = target;
    camera
}

/// Sphere frames of `w` × `h`, one sample per pixel, on `background`.
fn stream_settings(w: u32, h: u32, background: [f32; 3]) -> FrameSettings {
    FrameSettings {
        width: w,
        height: h,
        spp: 1,
        background_srgb: background,
        ..Default::default()
    }
}

/// Renders frames of one view through `s` until the stream is complete.
fn converge(
    s: &mut mdlod_render::StreamingRenderer<'_>,
    camera: &Camera,
    traversal: &TraversalSettings,
    settings: &FrameSettings,
) -> (
    RenderedFrame,
    mdlod_render::DrawList,
    mdlod_render::StreamStats,
    usize,
) {
    for i in 1..=60 {
        let (frame, draw, stats) = s.render(camera, traversal, settings).unwrap();
        if stats.complete {
            return (frame, draw, stats, i);
        }
        s.wait_for_loads(std::time::Duration::from_secs(10));
    }
    panic!("the stream did not converge in 60 frames");
}

#[test]
fn streaming_with_a_tiny_pool_converges_to_the_unlimited_image() {
    use mdlod_render::StreamingRenderer;
    // Small pages, so that a small file has many.
    const PAGE: u32 = 16;
    let (_d, _p, f) = make_file(&fcc_frame(12), small_build(), &[]);
    let f = std::sync::Arc::new(f);
    let (w, h) = (160u32, 120u32);
    // A distant view of everything, and a close-up of one corner of the box.
    let far = camera_for(
        &f,
        &ViewSpec::Orbit {
            azimuth_deg: 30.0,
            elevation_deg: 20.0,
            zoom: 0.25,
            projection: Projection::Perspective,
        },
        w,
        h,
    )
    .unwrap();
    let corner = corner_camera(&f, w, h, Vec3::new(5.0, 5.0, 20.0));
    let views = [ViewSpec::Camera(far), ViewSpec::Camera(corner)];
    let mut o = opts(w, h);
    o.error_px = 5.0;
    o.background = [0.2, 0.2, 0.2];
    let settings = stream_settings(w, h, o.background);
    let mut references = vec![];
    let mut used = vec![];
    {
        let mut unlimited =
            StreamingRenderer::with_page_points(renderer(), f.clone(), 1 << 30, PAGE).unwrap();
        for v in &views {
            o.view = v.clone();
            let (reference, report) = render_image(renderer(), &f, &o).unwrap();
            let camera = camera_for(&f, v, w, h).unwrap();
            let traversal = TraversalSettings {
                viewport: [w, h],
                error_px: o.error_px,
                budget_points: report.budget,
                occlusion: OcclusionMode::PixelCentres,
                support_scale: 0.0,
                hidden: mdlod_render::HiddenSet::default(),
                clip: Default::default(),
            };
            let (frame, draw, stats, frames) =
                converge(&mut unlimited, &camera, &traversal, &settings);
            // The second frame of a still view requests its whole cut (the look-ahead):
            // complete on the third, however many levels the cut goes down.
            assert!(
                frames <= 3 && f.level_count() >= 5,
                "{frames} frames for {} levels",
                f.level_count()
            );
            assert_eq!(draw.particles, report.particles_drawn);
            assert_eq!(draw.representatives, report.nodes_drawn);
            assert_eq!(
                frame.image, reference,
                "unlimited pool differs from the direct render"
            );
            used.push(stats.used_pages);
            references.push((camera, traversal, reference));
        }
    }
    // A pool just large enough for the larger of the two cuts.
    let capacity = *used.iter().max().unwrap();
    let pool = capacity as u64 * StreamingRenderer::slot_bytes(f.position_bits(), PAGE);
    let mut tiny = StreamingRenderer::with_page_points(renderer(), f.clone(), pool, PAGE).unwrap();
    assert_eq!(tiny.capacity_pages(), capacity);
    assert!(
        (capacity as u64) * 3 < tiny.file_pages() * 2,
        "pool of {capacity} pages is not small against the file's {}",
        tiny.file_pages()
    );
    // The first frame has nothing resident: the top node stands for everything.
    let (camera, traversal, _) = &references[0];
    let (_, first, stats) = tiny.render(camera, traversal, &settings).unwrap();
    assert_eq!((first.points, first.deferred_nodes), (1, 1));
    assert!(stats.requested > 0 && !stats.complete);
    for round in 0..2 {
        for (i, (camera, traversal, reference)) in references.iter().enumerate() {
            let (frame, _, stats, frames) = converge(&mut tiny, camera, traversal, &settings);
            assert!(stats.resident_pages <= capacity);
            assert_eq!(
                &frame.image, reference,
                "round {round}, view {i}: tiny pool after {frames} frames"
            );
        }
    }
    let (_, _, stats) = tiny
        .render(&references[0].0, &references[0].1, &settings)
        .unwrap();
    assert!(
        stats.evicted_total > 0,
        "switching views should evict: {stats:?}"
    );
    drop(tiny);

    // A pool's cut larger than one batch (here made small: 31 points) is bound in
    // batches, its ranges split at page boundaries: the same pixels.
    let mut batched = Renderer::new(GpuContext::with_backends(backends()).unwrap());
    batched.set_batch_points(Some(31));
    let mut pool = StreamingRenderer::with_page_points(&batched, f.clone(), pool, PAGE).unwrap();
    for (i, (camera, traversal, reference)) in references.iter().enumerate() {
        let (frame, draw, _, _) = converge(&mut pool, camera, traversal, &settings);
        assert!(draw.points > 4 * 31, "view {i}: {} points", draw.points);
        assert_eq!(&frame.image, reference, "view {i}: batched pool");
    }
}

/// A pool just large enough for a view's cut under a point budget that binds: the
/// pages of coarser cuts drawn on the way must not keep the final cut's pages out.
#[test]
fn a_tight_pool_under_a_binding_budget_settles_on_the_direct_image() {
    use mdlod_render::StreamingRenderer;
    const PAGE: u32 = 16;
    let (_d, _p, f) = make_file(&fcc_frame(12), small_build(), &[]);
    let f = std::sync::Arc::new(f);
    let (w, h) = (160u32, 120u32);
    let view = ViewSpec::Orbit {
        azimuth_deg: 30.0,
        elevation_deg: 20.0,
        zoom: 0.6,
        projection: Projection::Perspective,
    };
    let mut o = opts(w, h);
    o.error_px = 1.0;
    o.view = view.clone();
    o.background = [0.2, 0.2, 0.2];
    let (_, full) = render_image(renderer(), &f, &o).unwrap();
    let settings = stream_settings(w, h, o.background);
    let camera = camera_for(&f, &view, w, h).unwrap();
    for (share, occlusion) in [
        (0.3, OcclusionMode::PixelCentres),
        (0.6, OcclusionMode::PixelCentres),
        (0.3, OcclusionMode::Off),
        (0.6, OcclusionMode::Off),
    ] {
        o.occlusion = occlusion != OcclusionMode::Off;
        o.budget = ((full.particles_drawn + full.nodes_drawn) as f64 * share) as u64;
        let (reference, report) = render_image(renderer(), &f, &o).unwrap();
        assert!(report.budget_limited, "share {share}, {occlusion:?}");
        let traversal = TraversalSettings {
            viewport: [w, h],
            error_px: o.error_px,
            budget_points: report.budget,
            occlusion,
            support_scale: 0.0,
            hidden: mdlod_render::HiddenSet::default(),
            clip: Default::default(),
        };
        let used = {
            let mut unlimited =
                StreamingRenderer::with_page_points(renderer(), f.clone(), 1 << 30, PAGE).unwrap();
            let (frame, _, stats, _) = converge(&mut unlimited, &camera, &traversal, &settings);
            assert!(
                frame.image == reference,
                "share {share}, {occlusion:?}: unlimited pool"
            );
            stats.used_pages
        };
        let pool = used as u64 * StreamingRenderer::slot_bytes(f.position_bits(), PAGE);
        let mut tight =
            StreamingRenderer::with_page_points(renderer(), f.clone(), pool, PAGE).unwrap();
        let mut last = None;
        for i in 1..=40 {
            let (frame, draw, stats) = tight.render(&camera, &traversal, &settings).unwrap();
            if stats.settled() {
                // Still reported as limited by the budget, as the direct render is.
                assert!(draw.budget_limited, "share {share}, {occlusion:?}");
                last = Some((frame, stats, i));
                break;
            }
            tight.wait_for_loads(std::time::Duration::from_secs(10));
        }
        let (frame, stats, frames) = last.expect("the tight pool did not settle in 40 frames");
        assert!(
            frame.image == reference,
            "share {share}, {occlusion:?}: tight pool of {used} pages settled after {frames} frames on \
             another image: {stats:?}"
        );
        assert!(stats.complete, "share {share}, {occlusion:?}: {stats:?}");
    }
}

/// A corrupt species index, found when its page is packed for the pool (opening reads no
/// particle data): the frame that installs it fails with the file and the particle
/// named, and the pool stays whole: the other pages that arrived with it are installed,
/// so a view that does not reach the particle still completes to the intact file's image.
#[test]
fn a_corrupt_page_is_an_error_naming_the_particle_and_the_pool_stays_whole() {
    use mdlod_format::SectionKind;
    use mdlod_render::StreamingRenderer;
    const PAGE: u32 = 16;
    let (_d, path, intact) = make_file(&fcc_frame(12), small_build(), &[]);
    let (w, h) = (160u32, 120u32);
    // The whole crystal, and a close-up of one corner from above.
    let whole = ViewSpec::Orbit {
        azimuth_deg: 30.0,
        elevation_deg: 20.0,
        zoom: 0.6,
        projection: Projection::Perspective,
    };
    let corner = corner_camera(&intact, w, h, Vec3::new(5.0, 5.0, 20.0));
    let mut o = opts(w, h);
    o.view = ViewSpec::Camera(corner.clone());
    let (reference, _) = render_image(renderer(), &intact, &o).unwrap();
    // A particle far from that corner gets species 999 (the file has one species).
    let last = intact.level_count() - 1;
    let positions = intact.decode_level(last).unwrap();
    let bad = positions
        .iter()
        .position(|p| p[0] > 35.0 && p[1] > 35.0)
        .unwrap();
    let species = intact
        .sections()
        .iter()
        .find(|s| SectionKind::from_code(s.kind) == Some(SectionKind::Species))
        .unwrap()
        .offset;
    drop(intact);
    let mut bytes = std::fs::read(&path).unwrap();
    let at = species as usize + 2 * bad;
    bytes[at..at + 2].copy_from_slice(&999u16.to_le_bytes());
    std::fs::write(&path, bytes).unwrap();
    let f = std::sync::Arc::new(MdlodFile::open(&path).unwrap());

    let mut pool =
        StreamingRenderer::with_page_points(renderer(), f.clone(), 1 << 30, PAGE).unwrap();
    let settings = stream_settings(w, h, o.background);
    let traversal = TraversalSettings {
        viewport: [w, h],
        error_px: 0.0,
        budget_points: u64::MAX,
        occlusion: OcclusionMode::PixelCentres,
        support_scale: 0.0,
        hidden: mdlod_render::HiddenSet::default(),
        clip: Default::default(),
    };
    let camera = camera_for(&f, &whole, w, h).unwrap();
    let mut error = None;
    for _ in 0..20 {
        match pool.render(&camera, &traversal, &settings) {
            Ok(_) => pool.wait_for_loads(std::time::Duration::from_secs(10)),
            Err(e) => {
                error = Some(e.to_string());
                break;
            }
        }
    }
    let error = error.expect("the corrupt page was drawn without an error");
    assert!(
        error.contains("t.mdlod")
            && error.contains(&format!("SPECIES, particle {bad}"))
            && error.contains("species index 999"),
        "{error}"
    );
    let traversal = TraversalSettings {
        error_px: o.error_px,
        budget_points: o.budget,
        ..traversal
    };
    for frames in 1..=20 {
        let (frame, _, stats) = pool.render(&corner, &traversal, &settings).unwrap();
        if stats.complete {
            assert!(frame.image == reference, "the corner after {frames} frames");
            return;
        }
        pool.wait_for_loads(std::time::Duration::from_secs(5));
    }
    panic!("the corner view did not complete in 20 frames after the corrupt page");
}

/// Renders `o` with and without occlusion culling: the images must be identical, and
/// the culled frame must draw fewer than `kept` of the spheres. Returns the culled
/// frame's report.
fn check_culling_changes_no_pixel(
    f: &MdlodFile,
    mut o: RenderOptions,
    kept: f64,
    what: &str,
) -> mdlod_render::RenderReport {
    o.occlusion = true;
    let (culled, r) = render_image(renderer(), f, &o).unwrap();
    o.occlusion = false;
    let (all, r_all) = render_image(renderer(), f, &o).unwrap();
    let drawn = |r: &mdlod_render::RenderReport| (r.particles_drawn + r.nodes_drawn) as f64;
    assert!(
        drawn(&r) < kept * drawn(&r_all),
        "{what}: {} of {} spheres drawn",
        drawn(&r),
        drawn(&r_all)
    );
    let (failing, _) = golden::compare(&all, &culled, 0);
    assert_eq!(failing, 0, "{what}: {failing} pixels differ");
    r
}

#[test]
fn occlusion_culling_changes_no_pixel() {
    let (_d, _p, f) = make_file(&fcc_frame(12), small_build(), &[]);
    check_culling_of_a_block(&f, 2.0 / 3.0, "");
}

/// [`check_culling_changes_no_pixel`] for a block seen from a corner, in perspective with
/// no error and orthographic at 3 px.
fn check_culling_of_a_block(f: &MdlodFile, kept: f64, what: &str) {
    for (error_px, projection) in [
        (0.0, Projection::Perspective),
        (3.0, Projection::Orthographic),
    ] {
        let mut o = opts(160, 120);
        o.error_px = error_px;
        o.view = ViewSpec::Orbit {
            azimuth_deg: 25.0,
            elevation_deg: 15.0,
            zoom: 1.3,
            projection,
        };
        check_culling_changes_no_pixel(f, o, kept, &format!("{what}{projection:?}"));
    }
}

/// Occlusion culling of particles of their own sizes (radii from 0.3 to 2.2 in a block):
/// the culling tests each against its own sphere, and the smallest bounds what
/// representatives reach, so no pixel changes.
#[test]
fn occlusion_culling_of_particles_of_their_own_sizes_changes_no_pixel() {
    let mut frame = fcc_frame(12);
    let mut rng = Rng::new(5);
    frame.radii = Some(
        (0..frame.positions.len())
            .map(|_| 0.3 + 1.9 * rng.next_f32())
            .collect(),
    );
    for s in &mut frame.species {
        s.radius = Some(1.25);
        s.radius_range = Some((0.3, 2.2));
    }
    let (_d, _p, f) = make_file(&frame, small_build(), &[]);
    assert!(f.radii().is_some());
    check_culling_of_a_block(&f, 0.9, "own sizes, ");
}

/// Hidden species, hidden values and clip planes keep occlusion culling: what they leave
/// out neither draws nor hides what is behind it, so the culled image is the unculled
/// one, pixel for pixel, with most of the block left out, at no error and at 3 px.
#[test]
fn occlusion_culling_with_hidden_and_clipped_particles_changes_no_pixel() {
    let mut frame = fcc_frame(14);
    let n = frame.positions.len();
    frame.attribute = Some(mdlod_preprocess::Attribute {
        name: "c_cna".into(),
        values: (0..n).map(|i| (i * 7 % 5) as f32 + 1.0).collect(),
    });
    let mid = frame.positions.iter().map(|p| p[0]).sum::<f32>() / n as f32;
    let (_d, _p, f) = make_file(&frame, small_build(), &[]);
    let hide_ag = mdlod_render::style::SpeciesStyle {
        name: "Ag".into(),
        hidden: true,
        ..Default::default()
    };
    let styles = [
        (
            "Ag hidden",
            mdlod_render::style::PointStyle {
                species: vec![hide_ag],
                ..Default::default()
            },
        ),
        (
            "values 1 to 2 hidden",
            mdlod_render::style::PointStyle {
                hidden_values: vec![[0.5, 2.5]],
                ..Default::default()
            },
        ),
        (
            "a half cut away",
            mdlod_render::style::PointStyle {
                clip: vec![[1.0, 0.0, 0.0, mid]],
                ..Default::default()
            },
        ),
    ];
    for (what, style) in styles {
        for error_px in [0.0, 3.0] {
            let mut o = opts(160, 120);
            o.error_px = error_px;
            o.view = ViewSpec::Orbit {
                azimuth_deg: 25.0,
                elevation_deg: 15.0,
                zoom: 1.3,
                projection: Projection::Perspective,
            };
            o.style = style.clone();
            let r = check_culling_changes_no_pixel(&f, o, 0.8, &format!("{what}, {error_px} px"));
            assert!(
                r.particles_occluded + r.nodes_occluded > 0,
                "{what}, {error_px} px: nothing culled"
            );
        }
    }
}

/// A hidden species past the traversal's 64-bit mask is hidden by the GPU alone, so the
/// traversal would take its particles for occluders: culling is off then, and the image
/// is the one without culling (it had holes where they stood).
#[test]
fn a_hidden_species_past_the_64th_keeps_every_pixel() {
    let mut frame = fcc_frame(10);
    let names: Vec<String> = (0..70).map(|k| format!("s{k}")).collect();
    let refs: Vec<&str> = names.iter().map(String::as_str).collect();
    frame.species = species(&refs);
    frame.species_index = (0..frame.positions.len())
        .map(|i| (i * 7 % 70) as u16)
        .collect();
    let (_d, _p, f) = make_file(&frame, small_build(), &[]);
    let mut o = opts(160, 120);
    o.error_px = 0.0;
    o.view = ViewSpec::Orbit {
        azimuth_deg: 25.0,
        elevation_deg: 15.0,
        zoom: 1.3,
        projection: Projection::Perspective,
    };
    o.style.species = vec![mdlod_render::style::SpeciesStyle {
        name: "s66".into(),
        hidden: true,
        ..Default::default()
    }];
    o.occlusion = true;
    let (culled, report) = render_image(renderer(), &f, &o).unwrap();
    o.occlusion = false;
    let (all, _) = render_image(renderer(), &f, &o).unwrap();
    let (failing, _) = golden::compare(&all, &culled, 0);
    assert_eq!(failing, 0, "{failing} pixels differ");
    assert_eq!(report.nodes_occluded + report.particles_occluded, 0);
}

#[test]
fn occlusion_culling_changes_no_pixel_where_particles_are_about_a_pixel_wide() {
    // Small spheres take the sample-by-sample test (one ray per pixel centre against the
    // recorded bounds): it must hide most of the block and still change no pixel.
    let (_d, _p, f) = make_file(&fcc_frame(30), small_build(), &[]);
    for (error_px, zoom) in [(0.0, 1.0), (2.0, 1.6)] {
        let mut o = opts(200, 150);
        o.error_px = error_px;
        o.view = ViewSpec::Orbit {
            azimuth_deg: 35.0,
            elevation_deg: 25.0,
            zoom,
            projection: Projection::Perspective,
        };
        let r = check_culling_changes_no_pixel(&f, o, 0.25, &format!("error {error_px}"));
        assert!(r.particles_occluded > 0);
    }
}

#[test]
fn occlusion_culling_changes_no_pixel_far_from_the_eye() {
    // A large data set seen whole puts spheres of a pixel or two thousands of radii from
    // the eye (6700 units for radius 1.28 in the 2×10^8 crater). A narrow field of view
    // puts this block's eye 6000 radii away: the culled image, through the small-sphere
    // raster and the impostors, must be the unculled one.
    let (_d, _p, f) = make_file(&fcc_frame(30), small_build(), &[]);
    for projection in [Projection::Perspective, Projection::Orthographic] {
        let camera = far_camera(&f, projection, 200.0 / 150.0);
        assert!(camera.distance > 7000.0, "{}", camera.distance);
        let mut o = opts(200, 150);
        o.error_px = 0.0;
        o.view = ViewSpec::Camera(camera);
        check_culling_changes_no_pixel(&f, o, 0.25, &format!("{projection:?}"));
    }
}

#[test]
fn spheres_far_off_keep_their_depth_order_with_the_eye_inside_the_data() {
    // With the eye inside the data's bounding sphere (any close-up), the near plane is
    // as close as 10⁻⁵ of the far one. A depth buffer holding z/w from 0 at near to 1 at
    // far then has steps of several units a thousand units away: a wall of red spheres
    // and a wall of smaller blue ones 3 units further (each blue sphere's front 5 units
    // behind a red one's, its outline inside the red one's) fell into the same steps, and
    // draw order or point order chose the colour. Reversed depth (1 at near, 0 at far)
    // keeps a relative 10⁻⁷ everywhere: no blue pixel may show. Spheres of 4 px go
    // through the compute raster, of 11 px through impostors.
    for (radius, w, h) in [(10.0f32, 160u32, 120u32), (25.0, 160, 120)] {
        let spacing = 1.5 * radius;
        let mut positions = vec![];
        let mut species_index = vec![];
        for wall in 0..2u16 {
            for i in -6..=6 {
                for j in -4..=4 {
                    let x = 1000.0 + 3.0 * f32::from(wall);
                    positions.push([x, i as f32 * spacing, j as f32 * spacing]);
                    species_index.push(wall);
                }
            }
        }
        // Behind the eye, outside the view: it puts the eye inside the data's bounds.
        positions.push([-50.0, 0.0, 0.0]);
        species_index.push(0);
        let frame = mdlod_preprocess::frame::Frame {
            positions,
            species_index,
            species: ["Front", "Back"]
                .iter()
                .map(|n| mdlod_preprocess::frame::SpeciesName {
                    name: n.to_string(),
                    numeric_type: false,
                    radius: None,
                    ..Default::default()
                })
                .collect(),
            ..Default::default()
        };
        let (_d, _p, f) = make_file(
            &frame,
            small_build(),
            &[("Front", radius), ("Back", radius - 2.0)],
        );
        let camera = Camera {
            target: Vec3::new(1000.0, 0.0, 0.0),
            azimuth_deg: 180.0,
            elevation_deg: 0.0,
            distance: 1000.0,
            fov_y_deg: 30.0,
            projection: Projection::Perspective,
            ..Default::default()
        };
        let mut o = opts(w, h);
        o.view = ViewSpec::Camera(camera);
        o.occlusion = false;
        let colour = |name: &str, c: [f32; 3]| mdlod_render::style::SpeciesStyle {
            name: name.into(),
            colour: Some(c),
            radius: None,
            hidden: false,
        };
        o.style.species = vec![
            colour("Front", [1.0, 0.0, 0.0]),
            colour("Back", [0.0, 0.0, 1.0]),
        ];
        let (image, _) = render_image(renderer(), &f, &o).unwrap();
        let (mut red, mut blue) = (0, 0);
        // (The highlights are white: a pixel is the colour that dominates it.)
        for p in image.data.chunks_exact(4) {
            red += usize::from(p[0] > 8 && p[0] > p[2]);
            blue += usize::from(p[2] > 8 && p[2] > p[0]);
        }
        assert!(red > 1000, "radius {radius}: {red} red pixels");
        assert_eq!(blue, 0, "radius {radius}: {blue} blue pixels ({red} red)");
    }
}

/// CPU reference of the splat pass: every point of the cut deposits
/// `π r_px² · colour` with the pass's normalised Gaussian.
fn splat_reference(
    f: &MdlodFile,
    camera: &Camera,
    draw: &mdlod_render::DrawList,
    w: u32,
    h: u32,
) -> Vec<[f64; 4]> {
    splat_reference_reaching(
        f,
        camera,
        draw,
        w,
        h,
        mdlod_render::passes::splat::DEFAULT_SUPPORT,
    )
}

/// [`splat_reference`] with kernels reaching `support` radii.
fn splat_reference_reaching(
    f: &MdlodFile,
    camera: &Camera,
    draw: &mdlod_render::DrawList,
    w: u32,
    h: u32,
    support: f32,
) -> Vec<[f64; 4]> {
    use mdlod_render::passes::splat::{splat_sigma_reaching, splat_weight, TRUNCATION};
    let clip_from_view = camera.clip_from_view(w as f32 / h as f32);
    let clip_from_world = clip_from_view * camera.view_from_world();
    let meta = f.metadata();
    let last = f.level_count() - 1;
    let mut img = vec![[0f64; 4]; (w * h) as usize];
    let spheres = drawn_spheres_with(f, draw, |n| n.area_sum.max(0.0).sqrt());
    for ((level, i), c, r) in spheres {
        let colour = if usize::from(level) == last {
            meta.species[usize::from(f.species()[i as usize])].colour
        } else {
            // The file's colour as the GPU is given it (the nearest sRGB byte).
            let n = &f.nodes()[f.levels()[usize::from(level)].node_first as usize + i as usize];
            unpack_colour(pack_file_colour(n.colour))
        };
        let clip = clip_from_world * c.extend(1.0);
        let ppw = clip_from_view.y_axis.y * 0.5 * h as f32 / clip.w;
        let r_px = r * ppw;
        let sigma = splat_sigma_reaching(r_px, support);
        let flux = std::f32::consts::PI * r_px * r_px;
        let (cx, cy) = (
            (clip.x / clip.w + 1.0) * 0.5 * w as f32,
            (1.0 - clip.y / clip.w) * 0.5 * h as f32,
        );
        let reach = TRUNCATION * sigma;
        let (x0, x1) = (
            (cx - reach).floor().max(0.0) as u32,
            ((cx + reach).ceil() as u32).min(w - 1),
        );
        let (y0, y1) = (
            (cy - reach).floor().max(0.0) as u32,
            ((cy + reach).ceil() as u32).min(h - 1),
        );
        for y in y0..=y1 {
            for x in x0..=x1 {
                let wgt = splat_weight(x as f32 + 0.5 - cx, y as f32 + 0.5 - cy, sigma);
                let px = &mut img[(y * w + x) as usize];
                for k in 0..3 {
                    px[k] += f64::from(wgt * flux * colour[k]);
                }
                px[3] += f64::from(wgt * flux);
            }
        }
    }
    img
}

/// A kernel reaching other than 1.75 radii (an SPH code's convention, `--kernel-scale`):
/// the GPU follows the CPU twin, the light is the same (each splat's is its disk's area),
/// and a wider kernel spreads it (a lower peak).
#[test]
fn splats_of_another_kernel_reach_match_the_cpu_reference_with_the_same_light() {
    // Radii of 3 units: splats of about a pixel.
    let radii = [("Cu", 3.0), ("Ag", 3.0), ("O", 3.0)];
    let (_d, _p, f) = make_file(&cloud_frame(1500, 3), small_build(), &radii);
    let (w, h) = (80u32, 60u32);
    let camera = camera_for(
        &f,
        &ViewSpec::Orbit {
            azimuth_deg: 40.0,
            elevation_deg: 30.0,
            zoom: 0.45,
            projection: Projection::Orthographic,
        },
        w,
        h,
    )
    .unwrap();
    let draw = cut(&f, &camera, [w, h], 0.0, OcclusionMode::Off);
    let blend = mdlod_render::SplatBlend::Additive {
        intensity: 1.0,
        by_attribute: false,
    };
    let look = Default::default();
    let packed = mdlod_render::renderer::PackedCut {
        renderer: renderer(),
        file: &f,
        style: mdlod_render::renderer::splat_style(blend),
        look: &look,
    };
    let splats =
        |support: f32| renderer().render_splats_from(&packed, &camera, &draw, w, h, blend, support);
    let source = |support: f32| {
        let frame = splats(support).unwrap();
        let cpu = splat_reference_reaching(&f, &camera, &draw, w, h, support);
        let peak = cpu.iter().map(|p| p[3]).fold(0.0, f64::max);
        for (i, (g, c)) in frame.hdr.iter().zip(&cpu).enumerate() {
            assert!(
                (f64::from(g[3]) - c[3]).abs() <= 1e-4 * peak + 1e-5,
                "reach {support}: pixel {i}: {} vs {}",
                g[3],
                c[3]
            );
        }
        (frame.total_flux()[3], peak)
    };
    // (Splats of about a pixel: a reach below 2.5 radii keeps their sigma at the
    // 0.7 px floor.)
    let (light, peak) = source(mdlod_render::passes::splat::DEFAULT_SUPPORT);
    let (wide_light, wide_peak) = source(5.0);
    assert!(
        (wide_light - light).abs() <= 2e-3 * light,
        "{wide_light} against {light}"
    );
    assert!(wide_peak < 0.8 * peak, "{wide_peak} against {peak}");
    assert!(splats(0.0).is_err());
}

#[test]
fn splats_match_the_cpu_reference_and_keep_the_flux_at_every_level() {
    let (_d, _p, f) = make_file(&cloud_frame(4000, 5), small_build(), &[]);
    let (w, h) = (96u32, 72u32);
    for projection in [Projection::Orthographic, Projection::Perspective] {
        let camera = camera_for(
            &f,
            &ViewSpec::Orbit {
                azimuth_deg: 40.0,
                elevation_deg: 30.0,
                zoom: 0.8,
                projection,
            },
            w,
            h,
        )
        .unwrap();
        let mut fluxes = vec![];
        // (Coarser still, a handful of splats wider than the image would lose flux off
        // its edges.)
        for error_px in [0.0, 6.0, 24.0] {
            let draw = cut(&f, &camera, [w, h], error_px, OcclusionMode::Off);
            let gpu = renderer()
                .render_splats(
                    &f,
                    &camera,
                    &draw,
                    w,
                    h,
                    mdlod_render::SplatBlend::Additive {
                        intensity: 1.0,
                        by_attribute: false,
                    },
                )
                .unwrap();
            let cpu = splat_reference(&f, &camera, &draw, w, h);
            let peak = cpu.iter().map(|p| p[3]).fold(0.0, f64::max);
            for (i, (g, c)) in gpu.hdr.iter().zip(&cpu).enumerate() {
                for k in 0..4 {
                    assert!(
                        (f64::from(g[k]) - c[k]).abs() <= 1e-4 * peak + 1e-5,
                        "{projection:?} {error_px} px: pixel {i} channel {k}: {} vs {}",
                        g[k],
                        c[k]
                    );
                }
            }
            let total = gpu.total_flux();
            let expected: f64 = cpu.iter().map(|p| p[3]).sum();
            assert!((total[3] - expected).abs() <= 1e-4 * expected);
            fluxes.push((error_px, draw.points, total));
        }
        // The whole data set is in view: the image's flux is the cut's flux, the same at
        // every level (exactly in orthographic views; in perspective a representative
        // sits at its particles' mean depth, so the pixels-per-unit factor differs a
        // little).
        // Per colour channel, representatives' mean colours are stored with 8 bits
        // (rounding by up to 0.5/255 of a channel), so colour fluxes get a looser bound
        // than the total.
        let tol = |k: usize| match (projection, k) {
            (Projection::Orthographic, 3) => 1e-3,
            (Projection::Orthographic, _) => 1e-2,
            (Projection::Perspective, _) => 2e-2,
        };
        let reference = fluxes[0].2;
        assert!(
            fluxes.last().unwrap().1 * 20 <= fluxes[0].1,
            "the coarsest cut is far coarser: {fluxes:?}"
        );
        for (error_px, points, total) in &fluxes {
            for k in 0..4 {
                let tol = tol(k);
                let rel = (total[k] - reference[k]).abs() / reference[k];
                assert!(
                    rel <= tol,
                    "{projection:?}: {error_px} px ({points} points): channel {k} flux off by {rel:.2e}"
                );
            }
        }
    }
}

#[test]
fn splat_mode_renders_tone_mapped() {
    let (_d, _p, f) = make_file(&cloud_frame(2000, 3), small_build(), &[]);
    let mut o = opts(64, 48);
    o.mode = mdlod_render::RenderMode::Splat {
        by_attribute: false,
    };
    o.error_px = 4.0;
    let (img, report) = render_image(renderer(), &f, &o).unwrap();
    let exposure = report.exposure.unwrap();
    assert!(exposure > 0.0 && report.total_flux.unwrap() > 0.0);
    // Black background, some lit pixels, none pure white at the automatic exposure.
    let lit = img.data.chunks_exact(4).filter(|p| p[0] > 10).count();
    assert!(lit > 100, "{lit} lit pixels");
    assert!(img
        .data
        .chunks_exact(4)
        .all(|p| p[0] < 255 || p[1] < 255 || p[2] < 255));
    // Twice the exposure: brighter everywhere it is lit.
    o.exposure = Some(2.0 * exposure);
    let (brighter, _) = render_image(renderer(), &f, &o).unwrap();
    let sum = |i: &RgbaImage| i.data.iter().map(|&v| u64::from(v)).sum::<u64>();
    assert!(sum(&brighter) > sum(&img));
}

#[test]
fn every_mode_but_sndfs_streams_through_a_small_pool_to_the_direct_image() {
    use mdlod_render::density::DensitySettings;
    use mdlod_render::{ColourMap, PointStyle, RenderMode, SpeciesStyle, StreamingRenderer};
    let mut frame = fcc_frame(14);
    let values: Vec<f32> = frame.positions.iter().map(|p| p[1].sin()).collect();
    frame.attribute = Some(mdlod_preprocess::Attribute {
        name: "e".into(),
        values,
    });
    let (_d, _p, f) = make_file(&frame, small_build(), &[]);
    let f = std::sync::Arc::new(f);
    let (w, h) = (64u32, 48u32);
    let error_px = 3.0;
    // A close-up of one corner of the block.
    let corner = corner_camera(&f, w, h, Vec3::new(6.0, 6.0, 45.0));
    let view = ViewSpec::Camera(corner);
    // A pool just large enough for the view's cut, well below the file: the view
    // completes, after frames that start from the top node alone. (The density volume's
    // cut is the largest: it keeps nodes outside the view whose kernels reach into it.)
    let (used, file_pages) = {
        let mut o = opts(w, h);
        o.error_px = error_px;
        o.view = view.clone();
        o.occlusion = false;
        o.mode = RenderMode::Density(DensitySettings::default());
        let (camera, traversal, _) = mdlod_render::frame_setup(&f, &o).unwrap();
        let mut s = StreamingRenderer::new(renderer(), f.clone(), 1 << 30).unwrap();
        let mut used = 0;
        for _ in 0..60 {
            let (_, stats) = s.prepare(&camera, &traversal).unwrap();
            used = stats.used_pages;
            if stats.complete {
                break;
            }
            s.wait_for_loads(std::time::Duration::from_secs(10));
        }
        (used as u64, s.file_pages())
    };
    assert!(used * 3 < file_pages * 2, "{used} of {file_pages} pages");
    let pool = used
        * StreamingRenderer::slot_bytes(f.position_bits(), mdlod_render::streaming::PAGE_POINTS);
    let colour_map = PointStyle {
        colour_map: Some(ColourMap::Magma),
        ..Default::default()
    };
    let hidden = PointStyle {
        species: vec![SpeciesStyle {
            name: "Ag".into(),
            hidden: true,
            ..Default::default()
        }],
        ..Default::default()
    };
    let iso = DensitySettings {
        iso: Some(0.3),
        slices: 48,
        ..Default::default()
    };
    let cases = [
        ("spheres, colour map", RenderMode::Spheres, colour_map),
        ("spheres, a hidden species", RenderMode::Spheres, hidden),
        (
            "additive splats",
            RenderMode::Splat {
                by_attribute: false,
            },
            PointStyle::default(),
        ),
        (
            "splats by attribute",
            RenderMode::Splat { by_attribute: true },
            PointStyle::default(),
        ),
        (
            "sorted splats",
            RenderMode::SplatOver {
                opacity: 0.6,
                order: Default::default(),
            },
            PointStyle::default(),
        ),
        (
            "density volume",
            RenderMode::Density(DensitySettings {
                slices: 48,
                ..Default::default()
            }),
            PointStyle::default(),
        ),
        (
            "iso-surface",
            RenderMode::Density(iso),
            PointStyle::default(),
        ),
    ];
    for (name, mode, style) in cases {
        let mut o = opts(w, h);
        o.error_px = error_px;
        o.view = view.clone();
        o.mode = mode;
        o.style = style;
        let (direct, d) = render_image(renderer(), &f, &o).unwrap();
        let (streamed, s) = mdlod_render::render_streaming(renderer(), f.clone(), &o, pool)
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        assert!(s.frames > 2, "{name}: {} frames", s.frames);
        assert!(
            !s.budget_limited && !s.pool_limited,
            "{name}: the pool should hold the cut"
        );
        assert_eq!(
            (s.particles_drawn, s.nodes_drawn),
            (d.particles_drawn, d.nodes_drawn),
            "{name}"
        );
        let (bad, _) = golden::compare(&direct, &streamed, 1);
        assert_eq!(bad, 0, "{name}: {bad} pixels differ from the direct image");
        // Not a blank picture (which any two paths would agree on).
        let corner = &direct.data[..4];
        let drawn = direct.data.chunks_exact(4).filter(|p| *p != corner).count();
        assert!(drawn > 100, "{name}: {drawn} pixels drawn");
    }
    // S-NDFs go out of core through the S-MIP instead.
    let mut o = opts(w, h);
    o.mode = RenderMode::Sndf {
        iterations: 1,
        bins: 4,
        binning: Default::default(),
    };
    let e = mdlod_render::render_streaming(renderer(), f.clone(), &o, pool)
        .unwrap_err()
        .to_string();
    assert!(e.contains("--tiles"), "{e}");
}

#[test]
fn sorted_over_blending_matches_a_cpu_compositor() {
    use mdlod_render::passes::splat::{over_alpha, TRUNCATION};
    use mdlod_render::traversal::{point_positions, sort_back_to_front_by, DepthOrder};
    let (_d, _p, f) = make_file(&cloud_frame(1500, 7), small_build(), &[]);
    let (w, h) = (80u32, 60u32);
    let camera = camera_for(&f, &ViewSpec::default(), w, h).unwrap();
    let clip_from_view = camera.clip_from_view(w as f32 / h as f32);
    let clip_from_world = clip_from_view * camera.view_from_world();
    let opacity = 0.7;
    let view = camera.view_from_world();
    let depth = |p: &Vec3| -view.transform_point3(*p).z;
    let mut exact = vec![];
    for (error_px, order) in [
        (0.0, DepthOrder::Points),
        (8.0, DepthOrder::Points),
        (0.0, DepthOrder::Clusters),
        (8.0, DepthOrder::Clusters),
    ] {
        let draw = cut(&f, &camera, [w, h], error_px, OcclusionMode::Off);
        let sorted = sort_back_to_front_by(&f, &draw, &camera, order);
        assert_eq!(sorted.points, draw.points);
        // The same points, one range each.
        let key = |d: &mdlod_render::DrawList| {
            let mut k: Vec<(u8, u32)> = d
                .ranges
                .iter()
                .flat_map(|r| (r.first..r.first + r.count).map(move |i| (r.level, i)))
                .collect();
            k.sort_unstable();
            k
        };
        assert_eq!(key(&sorted), key(&draw));
        assert!(sorted.ranges.iter().all(|r| r.count == 1));
        let depths: Vec<f32> = point_positions(&f, &sorted).iter().map(depth).collect();
        match order {
            // Back to front, point by point.
            DepthOrder::Points => assert!(depths.windows(2).all(|d| d[0] >= d[1])),
            // Cluster by cluster: each cluster's points together and back to front, the
            // clusters back to front by their centroids' depth (up to one bucket).
            DepthOrder::Clusters => {
                let mut cluster_of = std::collections::HashMap::new();
                for (k, r) in draw.ranges.iter().enumerate() {
                    for i in r.first..r.first + r.count {
                        cluster_of.insert((r.level, i), k);
                    }
                }
                let seq: Vec<usize> = sorted
                    .ranges
                    .iter()
                    .map(|r| cluster_of[&(r.level, r.first)])
                    .collect();
                let mut seen = std::collections::HashSet::new();
                let mut centroids = vec![];
                for (j, c) in seq.iter().enumerate() {
                    if j == 0 || seq[j - 1] != *c {
                        assert!(seen.insert(*c), "cluster {c} is split");
                        centroids.push(0.0f32);
                    } else {
                        assert!(depths[j - 1] >= depths[j], "cluster {c} out of order");
                    }
                }
                let mut at = 0;
                for c in centroids.iter_mut() {
                    let n = draw.ranges[seq[at]].count as usize;
                    *c = depths[at..at + n].iter().sum::<f32>() / n as f32;
                    at += n;
                }
                let (lo, hi) = centroids
                    .iter()
                    .fold((f32::INFINITY, f32::NEG_INFINITY), |(l, h), &c| {
                        (l.min(c), h.max(c))
                    });
                let bucket = (hi - lo) / centroids.len().max(1024) as f32;
                assert!(centroids.windows(2).all(|c| c[0] >= c[1] - 1.001 * bucket));
            }
        }

        let blend = mdlod_render::SplatBlend::Over { opacity };
        let gpu = renderer()
            .render_splats(&f, &camera, &sorted, w, h, blend)
            .unwrap();
        // The CPU compositor, in the same order.
        let meta = f.metadata();
        let last = f.level_count() - 1;
        let mut img = vec![[0f32; 4]; (w * h) as usize];
        for ((level, i), c, r) in drawn_spheres_with(&f, &sorted, |n| n.area_sum.max(0.0).sqrt()) {
            let colour = if usize::from(level) == last {
                meta.species[usize::from(f.species()[i as usize])].colour
            } else {
                let n = &f.nodes()[f.levels()[usize::from(level)].node_first as usize + i as usize];
                unpack_colour(pack_file_colour(n.colour))
            };
            let clip = clip_from_world * c.extend(1.0);
            let r_px = r * clip_from_view.y_axis.y * 0.5 * h as f32 / clip.w;
            let (cx, cy) = (
                (clip.x / clip.w + 1.0) * 0.5 * w as f32,
                (1.0 - clip.y / clip.w) * 0.5 * h as f32,
            );
            let reach = TRUNCATION * mdlod_render::passes::splat::splat_sigma(r_px);
            for y in
                ((cy - reach).floor().max(0.0) as u32)..=(((cy + reach).ceil() as u32).min(h - 1))
            {
                for x in ((cx - reach).floor().max(0.0) as u32)
                    ..=(((cx + reach).ceil() as u32).min(w - 1))
                {
                    let a = over_alpha(x as f32 + 0.5 - cx, y as f32 + 0.5 - cy, r_px, opacity);
                    let px = &mut img[(y * w + x) as usize];
                    for k in 0..3 {
                        px[k] = colour[k] * a + (1.0 - a) * px[k];
                    }
                    px[3] = a + (1.0 - a) * px[3];
                }
            }
        }
        for (i, (g, c)) in gpu.hdr.iter().zip(&img).enumerate() {
            for k in 0..4 {
                assert!(
                    // Single-precision rounding of the GPU's exp and blend over
                    // the layers of splats a pixel gathers.
                    (g[k] - c[k]).abs() <= 5e-4,
                    "{error_px} px: pixel {i} channel {k}: {} vs {}",
                    g[k],
                    c[k]
                );
            }
        }
        assert!(img.iter().filter(|p| p[3] > 0.5).count() > 200);
        // The order matters: front to back gives another picture.
        let mut reversed = sorted.clone();
        reversed.ranges.reverse();
        let wrong = renderer()
            .render_splats(&f, &camera, &reversed, w, h, blend)
            .unwrap();
        let differ = wrong
            .hdr
            .iter()
            .zip(&gpu.hdr)
            .filter(|(a, b)| (0..3).any(|k| (a[k] - b[k]).abs() > 0.02))
            .count();
        assert!(
            differ > 50,
            "{error_px} px: only {differ} pixels depend on the order"
        );
        // The hierarchy's order against the exact one: where clusters overlap in depth
        // their points do not interleave; few pixels show it.
        match order {
            DepthOrder::Points => exact.push(gpu.hdr),
            DepthOrder::Clusters => {
                let reference = &exact[usize::from(error_px > 0.0)];
                let differ = reference
                    .iter()
                    .zip(&gpu.hdr)
                    .filter(|(a, b)| (0..3).any(|k| (a[k] - b[k]).abs() > 0.02))
                    .count();
                eprintln!("{error_px} px: {differ} of {} pixels differ", w * h);
                assert!(
                    differ * 20 < (w * h) as usize,
                    "{error_px} px: the cluster order changes {differ} pixels"
                );
            }
        }
    }
}

#[test]
fn splats_by_attribute_keep_the_attribute_flux_at_every_level() {
    let mut frame = cloud_frame(3000, 11);
    let values: Vec<f32> = frame.positions.iter().map(|p| 0.1 * p[0] - 2.0).collect();
    frame.attribute = Some(mdlod_preprocess::Attribute {
        name: "e".into(),
        values,
    });
    let (_d, _p, f) = make_file(&frame, small_build(), &[]);
    let (w, h) = (96u32, 72u32);
    let camera = camera_for(
        &f,
        &ViewSpec::Orbit {
            azimuth_deg: 20.0,
            elevation_deg: 10.0,
            zoom: 0.8,
            projection: Projection::Orthographic,
        },
        w,
        h,
    )
    .unwrap();
    // Expected: every particle's disk area on screen times its attribute less the range's
    // low end, in the attribute's units (its quantized step times the range's width).
    let ppw = camera.clip_from_view(w as f32 / h as f32).y_axis.y * 0.5 * h as f32;
    let radii: Vec<f32> = f.metadata().species.iter().map(|s| s.radius).collect();
    let info = f.metadata().attribute.clone().unwrap();
    let width = f64::from(info.max - info.min);
    let expected: f64 = f
        .attribute()
        .unwrap()
        .iter()
        .zip(f.species())
        .map(|(&q, &s)| {
            let r = f64::from(radii[usize::from(s)] * ppw);
            std::f64::consts::PI * r * r * f64::from(q) / 65535.0 * width
        })
        .sum();
    let blend = mdlod_render::SplatBlend::Additive {
        intensity: 1.0,
        by_attribute: true,
    };
    for error_px in [0.0, 6.0, 24.0] {
        let draw = cut(&f, &camera, [w, h], error_px, OcclusionMode::Off);
        let s = renderer()
            .render_splats(&f, &camera, &draw, w, h, blend)
            .unwrap();
        let total = s.total_flux();
        // Grey: the three channels carry the same light.
        assert!((total[0] - total[2]).abs() <= 1e-6 * total[0]);
        let rel = (s.total_light() - expected).abs() / expected;
        assert!(
            rel < 1e-3,
            "{error_px} px ({} points): attribute flux off by {rel:.2e}",
            draw.points
        );
    }
    // Without an attribute there is nothing to take intensities from.
    let (_d2, _p2, plain) = make_file(&cloud_frame(300, 1), small_build(), &[]);
    let draw = traverse(&camera, &plain, &TraversalSettings::default());
    let e = renderer()
        .render_splats(&plain, &camera, &draw, w, h, blend)
        .unwrap_err()
        .to_string();
    assert!(e.contains("no per-particle attribute"), "{e}");
}

/// Splats lit by an attribute stored as its logarithm (`--attribute-log10`: eight
/// decades, as an SPH run's densities) light by the quantity itself: every level's
/// clusters keep the light of their particles, `10^v` times their area, to 1e-3 (a mean
/// of logarithms would lose most of it), and the faintest decades are not lost to 16-bit
/// steps as a linear column's would be.
#[test]
fn splats_by_a_logarithm_light_by_the_quantity_at_every_level() {
    let mut frame = cloud_frame(3000, 13);
    let n = frame.positions.len();
    let values: Vec<f32> = (0..n)
        .map(|i| 10f32.powf(-6.0 + 8.0 * ((i * 7919) % n) as f32 / n as f32))
        .collect();
    frame.attribute = Some(mdlod_preprocess::Attribute {
        name: "rho".into(),
        values,
    });
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("log.mdlod");
    let opts = mdlod_preprocess::convert::ConvertOptions {
        build: small_build(),
        attribute_log10: true,
        ..Default::default()
    };
    mdlod_preprocess::convert::convert_frame(
        &frame,
        None,
        &path,
        &opts,
        &mdlod_preprocess::NoProgress,
    )
    .unwrap();
    let f = MdlodFile::open(&path).unwrap();
    assert!(f.metadata().attribute_log10);
    let (w, h) = (96u32, 72u32);
    let camera = camera_for(
        &f,
        &ViewSpec::Orbit {
            azimuth_deg: 20.0,
            elevation_deg: 10.0,
            zoom: 0.8,
            projection: Projection::Orthographic,
        },
        w,
        h,
    )
    .unwrap();
    let ppw = camera.clip_from_view(w as f32 / h as f32).y_axis.y * 0.5 * h as f32;
    let radii: Vec<f32> = f.metadata().species.iter().map(|s| s.radius).collect();
    let info = f.metadata().attribute.clone().unwrap();
    let expected: f64 = f
        .attribute()
        .unwrap()
        .iter()
        .zip(f.species())
        .map(|(&q, &s)| {
            let r = f64::from(radii[usize::from(s)] * ppw);
            std::f64::consts::PI * r * r * 10f64.powf(f64::from(info.decode(q)))
        })
        .sum();
    let blend = mdlod_render::SplatBlend::Additive {
        intensity: 1.0,
        by_attribute: true,
    };
    for error_px in [0.0, 6.0, 24.0] {
        let draw = cut(&f, &camera, [w, h], error_px, OcclusionMode::Off);
        let s = renderer()
            .render_splats(&f, &camera, &draw, w, h, blend)
            .unwrap();
        let rel = (s.total_light() - expected).abs() / expected;
        assert!(
            rel < 1e-3,
            "{error_px} px ({} points): light off by {rel:.2e}",
            draw.points
        );
    }
}

/// Area of the part of the cell `[x0, x0 + c] × [y0, y0 + c]` inside the unit disk.
fn cell_in_disk(x0: f64, y0: f64, c: f64) -> f64 {
    const N: usize = 200;
    let mut inside = 0;
    for j in 0..N {
        for i in 0..N {
            let x = x0 + c * (i as f64 + 0.5) / N as f64;
            let y = y0 + c * (j as f64 + 0.5) / N as f64;
            inside += usize::from(x * x + y * y <= 1.0);
        }
    }
    c * c * inside as f64 / (N * N) as f64
}

#[test]
fn a_sphere_seen_orthographically_has_a_uniform_sndf_over_the_normal_disk() {
    // One sphere of radius 2 filling most of a 64×64 orthographic view: screen position
    // maps linearly to the projected normal, so the samples of all texels together are
    // uniform over the disk; each bin gets its share of the disk's area.
    let (_d, _p, f) = make_file(
        &spheres_frame(&[[0.0, 0.0, 0.0]]),
        small_build(),
        &[("X", 2.0)],
    );
    let cam = ortho_camera(Vec3::new(0.0, 0.0, 0.0), 2.5);
    let draw = cut(&f, &cam, [64, 64], 0.0, OcclusionMode::Off);
    let bins = 8u32;
    let sndf = renderer()
        .sample_sndf(
            &f,
            &cam,
            &draw,
            &mdlod_render::sndf::SndfSettings {
                width: 64,
                height: 64,
                iterations: 16,
                bins,
                binning: Default::default(),
            },
        )
        .unwrap();
    let mut counts = vec![0f64; (bins * bins) as usize];
    for p in sndf.hist.chunks_exact((bins * bins) as usize) {
        for (c, b) in counts.iter_mut().zip(p) {
            *c += f64::from(b[3]);
        }
    }
    let total: f64 = counts.iter().sum();
    // The sphere's disk is π·(2·64/5)² px, sampled 16 times per texel.
    let expected_total = std::f64::consts::PI * (2.0 * 64.0 / 5.0f64).powi(2) * 16.0;
    assert!(
        (total - expected_total).abs() < 0.01 * expected_total,
        "{total} vs {expected_total}"
    );
    let cell = 2.0 / f64::from(bins);
    for by in 0..bins {
        for bx in 0..bins {
            let share = cell_in_disk(
                -1.0 + cell * f64::from(bx),
                -1.0 + cell * f64::from(by),
                cell,
            ) / std::f64::consts::PI;
            let got = counts[(by * bins + bx) as usize] / total;
            // Monte Carlo error of ~10^4 stratified samples, and the disk's rim cells.
            assert!(
                (got - share).abs() <= 0.06 * share + 5e-4,
                "bin ({bx}, {by}): {got:.5} of the samples, {share:.5} of the disk"
            );
        }
    }
}

#[test]
fn relighting_sndfs_matches_supersampling_under_the_new_light_and_draws_no_particle() {
    let (_d, _p, f) = make_file(&fcc_frame(6), small_build(), &[]);
    let own = Renderer::new(GpuContext::with_backends(backends()).unwrap());
    let (w, h) = (64u32, 48u32);
    let mut o = opts(w, h);
    o.spp = 16;
    o.background = [0.1, 0.1, 0.1];
    o.view = ViewSpec::Orbit {
        azimuth_deg: 30.0,
        elevation_deg: 25.0,
        zoom: 1.0,
        projection: Projection::Orthographic,
    };
    let camera = camera_for(&f, &o.view, w, h).unwrap();
    let draw = cut(&f, &camera, [w, h], 0.0, OcclusionMode::WholePixels);
    use mdlod_render::sndf::Binning;
    for binning in [
        Binning::ProjectedNormals,
        Binning::Spherical,
        Binning::LambertEqualArea,
    ] {
        let before = own.points_sampled();
        let sndf = own
            .sample_sndf(
                &f,
                &camera,
                &draw,
                &mdlod_render::sndf::SndfSettings {
                    width: w,
                    height: h,
                    iterations: 16,
                    bins: 8,
                    binning,
                },
            )
            .unwrap();
        let sampled = own.points_sampled();
        assert_eq!(sampled - before, draw.points * 16);
        let mut previous: Option<RgbaImage> = None;
        for direction in [
            Vec3::new(-0.35, 0.45, 1.0),
            Vec3::new(0.8, -0.2, 0.4),
            Vec3::new(0.0, 1.0, 0.2),
        ] {
            let light = mdlod_render::Lighting {
                direction_view: direction.normalize(),
                ..Default::default()
            };
            let lights = mdlod_render::sndf::ShadeLights::from(&light);
            let relit = shaded_on_both(&own, &sndf, &lights, o.background);
            assert_eq!(own.points_sampled(), sampled, "re-lighting drew particles");
            o.lighting = light;
            let (reference, _) = render_image(renderer(), &f, &o).unwrap();
            let diff = mean_abs_diff(&relit, &reference);
            assert!(
                diff < 2.0,
                "{binning:?}, light {direction}: mean difference {diff:.2} of 255"
            );
            // The light matters: the previous light's image is far from this reference.
            if let Some(p) = previous.replace(relit) {
                let other = mean_abs_diff(&p, &reference);
                assert!(
                    other > 5.0 * diff.max(0.5),
                    "light {direction}: {other:.2} vs {diff:.2}"
                );
            }
        }
    }
}

/// In a perspective view each texel sees the particles along its own ray: the
/// highlights of re-lit S-NDFs follow it (as the ray caster's do), where shading every
/// texel as if seen along the view axis puts them elsewhere.
#[test]
fn relit_sndfs_of_a_wide_perspective_view_place_highlights_along_each_texels_ray() {
    let (_d, _p, f) = make_file(&fcc_frame(6), small_build(), &[]);
    let (w, h) = (96u32, 64u32);
    let mut camera = camera_for(&f, &opts(w, h).view, w, h).unwrap();
    // A 70° field of view at about the same framing as the default 30°, the block a
    // little smaller than the fit makes it.
    camera.distance *= (15f32.to_radians().tan() / 35f32.to_radians().tan()) * 1.05;
    camera.fov_y_deg = 70.0;
    let mut o = opts(w, h);
    o.spp = 16;
    o.background = [0.1, 0.1, 0.1];
    o.view = ViewSpec::Camera(camera.clone());
    let camera = camera_for(&f, &o.view, w, h).unwrap();
    let sndf = sampled(&f, &camera, [w, h], 16, 8);
    assert!(matches!(
        sndf.view,
        mdlod_render::sndf::TexelView::Perspective { .. }
    ));
    let light = mdlod_render::Lighting {
        direction_view: Vec3::new(0.6, 0.3, 1.0).normalize(),
        specular: 0.8,
        shininess: 24.0,
        ..Default::default()
    };
    let lights = mdlod_render::sndf::ShadeLights::from(&light);
    let relit = shaded_on_both(renderer(), &sndf, &lights, o.background);
    o.lighting = light;
    let (reference, _) = render_image(renderer(), &f, &o).unwrap();
    let along_rays = mean_abs_diff(&relit, &reference);
    let mut axis = sndf.clone();
    axis.view = mdlod_render::sndf::TexelView::Axis;
    let along_axis = mean_abs_diff(&axis.shade(&light, o.background), &reference);
    assert!(
        along_rays < 2.0 && along_axis > 1.5 * along_rays,
        "mean difference to the ray-cast image: {along_rays:.2} along each texel's ray, \
         {along_axis:.2} along the axis"
    );
}

/// In a 90° view the rays near the image's edges see normals facing away from the view
/// axis (a sphere's silhouette towards the centre of the image). Binned along each
/// texel's ray, re-lit S-NDFs keep the ray caster's brightness out to the edges; binned
/// in the camera's frame those normals were lit as their mirror images, a third too
/// bright near the edges under a headlight.
#[test]
fn sndfs_of_a_ninety_degree_view_keep_the_ray_casters_brightness_out_to_the_edges() {
    let (_d, _p, f) = make_file(&fcc_frame(6), small_build(), &[]);
    let (w, h) = (96u32, 64u32);
    let mut camera = camera_for(&f, &opts(w, h).view, w, h).unwrap();
    // Closer, so that the block fills the image's edges too.
    camera.distance *= (15f32.to_radians().tan() / 45f32.to_radians().tan()) * 0.8;
    camera.fov_y_deg = 90.0;
    let mut o = opts(w, h);
    o.spp = 16;
    o.background = [0.0, 0.0, 0.0];
    o.view = ViewSpec::Camera(camera.clone());
    o.lighting = mdlod_render::Lighting {
        direction_view: Vec3::Z,
        specular: 0.0,
        ..Default::default()
    };
    let camera = camera_for(&f, &o.view, w, h).unwrap();
    let sndf = sampled(&f, &camera, [w, h], 16, 8);
    assert!(sndf.view.binned_along_rays());
    let lights = mdlod_render::sndf::ShadeLights::from(&o.lighting);
    let relit = shaded_on_both(renderer(), &sndf, &lights, o.background);
    let (reference, _) = render_image(renderer(), &f, &o).unwrap();
    // Mean brightness of the outer band (a sixth of each side) and of the middle.
    let [edge, middle] = relit.band_and_middle_levels(6);
    let [edge_ref, middle_ref] = reference.band_and_middle_levels(6);
    assert!(
        edge_ref > 40.0,
        "the block must fill the edges: {edge_ref:.1}"
    );
    assert!(
        (edge - edge_ref).abs() < 0.03 * edge_ref
            && (middle - middle_ref).abs() < 0.03 * middle_ref,
        "mean level of the S-NDFs against ray casting: edges {edge:.1} / {edge_ref:.1}, \
         middle {middle:.1} / {middle_ref:.1}"
    );
}

/// The accumulation pass bins each texel's normal in the frame of its own ray exactly as
/// the CPU's [`TexelView::bin_frame`] says: one sphere filling a 90° view, one centred
/// ray per texel, and each texel's hit normal found by intersecting that ray with the
/// sphere on the CPU. Binned in the camera's frame instead, most texels' bins differ.
#[test]
fn the_accumulation_bins_each_normal_in_its_texels_ray_frame_as_the_cpu_does() {
    use mdlod_render::sndf::{bin_of, texel_point, Binning};
    let (_d, _p, f) = make_file(&spheres_frame(&[[0.0, 0.0, 0.0]]), small_build(), &[]);
    let r = f.metadata().species[0].radius;
    let (w, h, bins) = (48u32, 32u32, 8u32);
    let mut camera = camera_for(&f, &opts(w, h).view, w, h).unwrap();
    camera.target = Vec3::ZERO;
    camera.distance = 1.5 * r;
    camera.fov_y_deg = 90.0;
    let camera = camera_for(&f, &ViewSpec::Camera(camera), w, h).unwrap();
    let sndf = sampled(&f, &camera, [w, h], 1, bins);
    let centre = (camera.view_from_world() * Vec4::new(0.0, 0.0, 0.0, 1.0)).truncate();
    let (mut hits, mut along_rays, mut in_camera_frame) = (0, 0, 0);
    for y in 0..h {
        for x in 0..w {
            let (u, v) = texel_point(x, y, w, h);
            // The ray from the eye (the origin of view space) away from `towards_eye`.
            let d = -sndf.view.towards_eye(u, v);
            let b = d.dot(centre);
            let disc = b * b - (centre.length_squared() - r * r);
            let counted = sndf.texel(x, y).iter().position(|c| c[3] > 0.5);
            // Rays near the rim graze it: their hit normal is too sensitive to compare.
            if disc < 0.02 * r * r {
                continue;
            }
            let Some(bin) = counted else {
                panic!("texel ({x}, {y}) hits the sphere on the CPU but has no count");
            };
            let normal = ((b - disc.sqrt()) * d - centre) / r;
            let index = |(bx, by): (u32, u32)| (by * bins + bx) as usize;
            let frame = sndf.view.bin_frame_at(x, y, w, h);
            hits += 1;
            along_rays +=
                usize::from(index(bin_of(frame * normal, bins, Binning::default())) == bin);
            in_camera_frame += usize::from(index(bin_of(normal, bins, Binning::default())) == bin);
        }
    }
    assert!(hits > 500, "{hits} texels see the sphere");
    assert!(
        along_rays as f64 >= 0.97 * hits as f64 && (in_camera_frame as f64) < 0.8 * hits as f64,
        "of {hits} texels, {along_rays} binned as the CPU's ray frame says, \
         {in_camera_frame} as the camera's frame would"
    );
}

/// S-NDFs of `f` seen by `camera` (the cut of whole-pixel occlusion, as the sndf mode
/// takes), `iterations` rays per texel, `bins` projected-normal bins per axis.
fn sampled(
    f: &MdlodFile,
    camera: &Camera,
    [w, h]: [u32; 2],
    iterations: u32,
    bins: u32,
) -> mdlod_render::sndf::Sndf {
    let draw = cut(f, camera, [w, h], 0.0, OcclusionMode::WholePixels);
    let settings = mdlod_render::sndf::SndfSettings {
        width: w,
        height: h,
        iterations,
        bins,
        binning: Default::default(),
    };
    renderer().sample_sndf(f, camera, &draw, &settings).unwrap()
}

/// `sndf` shaded on the host, after checking that the GPU's shading pass gives the same
/// picture (to 1/255).
fn shaded_on_both(
    r: &Renderer,
    sndf: &mdlod_render::sndf::Sndf,
    lights: &mdlod_render::sndf::ShadeLights,
    background: [f32; 3],
) -> RgbaImage {
    let host = sndf.shade_with(lights, background);
    let (gpu, _) = r.shade_sndf(sndf, lights, background).unwrap();
    assert_eq!((gpu.width, gpu.height), (host.width, host.height));
    let worst = host
        .data
        .iter()
        .zip(&gpu.data)
        .map(|(a, b)| a.abs_diff(*b))
        .max()
        .unwrap_or(0);
    assert!(worst <= 1, "host and GPU shading differ by up to {worst}");
    host
}

/// Spheres a style draws larger than the file's radii reach past the data's bounds: the
/// near plane moves so that they are drawn, not clipped whole (an impostor lies at its
/// sphere's front).
#[test]
fn spheres_drawn_larger_than_the_data_bounds_are_not_clipped_by_the_near_plane() {
    let (_d, _p, f) = make_file(&spheres_frame(&[[0.0, 0.0, 0.0]]), small_build(), &[]);
    let (w, h) = (32u32, 24u32);
    let mut o = opts(w, h);
    o.background = [0.0, 0.0, 0.0];
    o.style.radius_scale = 4.0;
    let (image, report) = render_image(renderer(), &f, &o).unwrap();
    assert_eq!(report.particles_drawn, 1);
    let centre = &image.data[((h / 2 * w + w / 2) * 4) as usize..][..3];
    assert!(
        centre.iter().any(|&c| c > 0),
        "the sphere was clipped: {centre:?}"
    );
}

fn rmse(a: &RgbaImage, b: &RgbaImage) -> f64 {
    assert_eq!((a.width, a.height), (b.width, b.height));
    let n = a.data.len() as f64;
    (a.data
        .iter()
        .zip(&b.data)
        .map(|(&x, &y)| (f64::from(x) - f64::from(y)).powi(2))
        .sum::<f64>()
        / n)
        .sqrt()
}

#[test]
fn sndfs_of_more_texels_than_one_dispatch_row_holds_shade_on_the_gpu_as_on_the_host() {
    // 2100 × 2000 texels: more than the 65535 × 64 texels of a one-dimensional dispatch
    // of 64-texel workgroups. One bin each, so that the histograms fit one binding.
    let (width, height, rays) = (2100u32, 2000u32, 4u32);
    let hist: Vec<[f32; 4]> = (0..width * height)
        .map(|t| {
            let count = (t % (rays + 1)) as f32;
            let albedo = [(t % 7) as f32 / 6.0, (t % 11) as f32 / 10.0, 0.5];
            [
                albedo[0] * count,
                albedo[1] * count,
                albedo[2] * count,
                count,
            ]
        })
        .collect();
    let sndf = mdlod_render::sndf::Sndf {
        width,
        height,
        bins: 1,
        binning: mdlod_render::sndf::Binning::ProjectedNormals,
        rays,
        hist,
        gpu_time: None,
        view: mdlod_render::sndf::TexelView::Axis,
    };
    let lights = mdlod_render::sndf::ShadeLights::from(&mdlod_render::Lighting::default());
    let background = [0.2, 0.3, 0.4];
    let host = shaded_on_both(renderer(), &sndf, &lights, background);
    assert_eq!((host.width, host.height), (width, height));
}

#[test]
fn zoomed_out_sndfs_beat_supersampling_with_as_many_iterations() {
    // S-NDFs sampled once at 256×256 with K jittered rays per texel, then 2×2-averaged
    // into coarser S-MIP levels: at four zoom-out levels (4× to 32×, 64 to 8 pixels) the
    // shaded image is at least as close to a 64-spp reference of that size as K-spp
    // supersampling of it, and 1-spp ray casting is at least 5× farther. (Measured: S-NDF
    // RMSE 1.6-3.1 of 255, 4 spp 8.6-15, 1 spp 15-29.)
    let (_d, _p, f) = make_file(&fcc_frame(10), small_build(), &[]);
    let k = 4u32;
    let base = 256u32;
    let view = ViewSpec::Orbit {
        azimuth_deg: 33.0,
        elevation_deg: 27.0,
        zoom: 1.0,
        projection: Projection::Orthographic,
    };
    let camera = camera_for(&f, &view, base, base).unwrap();
    let draw = cut(&f, &camera, [base, base], 0.0, OcclusionMode::Off);
    let mut sndf = renderer()
        .sample_sndf(
            &f,
            &camera,
            &draw,
            &mdlod_render::sndf::SndfSettings {
                width: base,
                height: base,
                iterations: k,
                bins: 8,
                binning: Default::default(),
            },
        )
        .unwrap();
    let lighting = mdlod_render::Lighting::default();
    let background = [0.1, 0.1, 0.1];
    sndf = sndf.downsample();
    for level in 2..=5 {
        sndf = sndf.downsample();
        let size = base >> level;
        let shaded = sndf.shade(&lighting, background);
        let render = |spp: u32| {
            let mut o = opts(size, size);
            o.spp = spp;
            o.view = view.clone();
            o.background = background;
            o.lighting = lighting;
            render_image(renderer(), &f, &o).unwrap().0
        };
        let reference = render(64);
        let (e_sndf, e_k, e_1) = (
            rmse(&shaded, &reference),
            rmse(&render(k), &reference),
            rmse(&render(1), &reference),
        );
        eprintln!("level {level} ({size}px): S-NDF {e_sndf:.2}, {k} spp {e_k:.2}, 1 spp {e_1:.2}");
        assert!(
            e_sndf <= e_k,
            "level {level}: S-NDF {e_sndf:.2} vs {k} spp {e_k:.2}"
        );
        assert!(
            e_1 >= 5.0 * e_sndf,
            "level {level}: 1 spp {e_1:.2} vs S-NDF {e_sndf:.2}"
        );
    }
}

/// The default view of `f` at `w` × `h`, its cut at 0 px with whole-pixel occlusion,
/// and S-NDF settings of `iterations` iterations and 4 × 4 projected-normal bins.
fn sndf_scene(
    f: &MdlodFile,
    (w, h): (u32, u32),
    iterations: u32,
) -> (
    Camera,
    mdlod_render::DrawList,
    mdlod_render::sndf::SndfSettings,
) {
    let camera = camera_for(f, &opts(w, h).view, w, h).unwrap();
    let draw = cut(f, &camera, [w, h], 0.0, OcclusionMode::WholePixels);
    let settings = mdlod_render::sndf::SndfSettings {
        width: w,
        height: h,
        iterations,
        bins: 4,
        binning: Default::default(),
    };
    (camera, draw, settings)
}

/// S-NDFs kept on the GPU and refined there in batches (4, then 4) hold what one
/// sampling of 8 iterations holds, and their GPU shading equals the host's.
#[test]
fn resident_sndfs_refine_on_the_gpu_like_one_sampling() {
    let (_d, _p, f) = make_file(&fcc_frame(5), small_build(), &[]);
    let (w, h) = (80u32, 70u32);
    let (camera, draw, settings) = sndf_scene(&f, (w, h), 8);
    let r = renderer();
    let whole = r.sample_sndf(&f, &camera, &draw, &settings).unwrap();
    let mut resident = r
        .resident_sndf(&f, &camera, &draw, &settings, &Default::default())
        .unwrap();
    r.refine_resident(&mut resident, 4).unwrap();
    r.refine_resident(&mut resident, 4).unwrap();
    assert_eq!(resident.rays, 8);
    let back = r.read_resident(&resident).unwrap();
    assert_eq!((back.width, back.height, back.rays), (w, h, 8));
    for (a, b) in back.hist.iter().zip(&whole.hist) {
        for k in 0..4 {
            assert!(
                (a[k] - b[k]).abs() <= 1e-4 * b[k].abs().max(1.0),
                "{a:?} vs {b:?}"
            );
        }
    }
    let lights = mdlod_render::sndf::ShadeLights::from(&mdlod_render::Lighting::default());
    let (gpu, _) = r.shade_resident(&resident, &lights, [0.2; 3]).unwrap();
    let host = whole.shade_with(&lights, [0.2; 3]);
    let worst = gpu
        .data
        .iter()
        .zip(&host.data)
        .map(|(a, b)| a.abs_diff(*b))
        .max()
        .unwrap();
    assert!(worst <= 1, "GPU and host shading differ by {worst}");
    assert!(
        host.data.chunks(4).any(|p| p[0] > 80),
        "the data is in view"
    );
}

/// S-NDFs larger than one storage binding (lavapipe binds 128 MiB, and 640×360 texels
/// of 8×8 bins need 240 MiB) are accumulated in windows of tiles bound one after the
/// other, from one G-buffer per iteration: the histograms equal those of one binding,
/// and resident ones are shaded on the host with the GPU's result.
#[test]
fn sndfs_larger_than_one_binding_are_sampled_in_windows() {
    let (_d, _p, f) = make_file(&fcc_frame(5), small_build(), &[]);
    // 3 × 3 tiles of 64×64 texels; windows of 3 tiles: one row of tiles each.
    let (w, h) = (192u32, 192u32);
    let (camera, draw, settings) = sndf_scene(&f, (w, h), 3);
    let one = renderer();
    let mut windowed = Renderer::new(GpuContext::with_backends(backends()).unwrap());
    windowed.set_sndf_window_bytes(Some(3 * mdlod_render::sndf::tile_bytes(settings.bins)));
    let a = one.sample_sndf(&f, &camera, &draw, &settings).unwrap();
    let b = windowed.sample_sndf(&f, &camera, &draw, &settings).unwrap();
    // Every window (row of tiles) has sampled data.
    let row_bins = (w * 64 * settings.bins * settings.bins) as usize;
    for row in 0..3 {
        assert!(
            a.hist[row * row_bins..(row + 1) * row_bins]
                .iter()
                .any(|v| v[3] > 0.0),
            "row {row} of tiles holds no ray hit"
        );
    }
    assert!(a.hist == b.hist, "windowed histograms differ");

    let lights = mdlod_render::sndf::ShadeLights::from(&mdlod_render::Lighting::default());
    let resident = |r: &Renderer| {
        let mut s = r
            .resident_sndf(&f, &camera, &draw, &settings, &Default::default())
            .unwrap();
        r.refine_resident(&mut s, 3).unwrap();
        s
    };
    let (ra, rb) = (resident(one), resident(&windowed));
    assert!(!ra.windowed() && rb.windowed());
    let (ia, _) = one.shade_resident(&ra, &lights, [0.2; 3]).unwrap();
    let (ib, _) = windowed.shade_resident(&rb, &lights, [0.2; 3]).unwrap();
    let worst = ia
        .data
        .iter()
        .zip(&ib.data)
        .map(|(x, y)| x.abs_diff(*y))
        .max()
        .unwrap();
    assert_eq!(ia.data.len(), ib.data.len());
    assert!(worst <= 1, "windowed shading differs by {worst}");
}

/// Progressive refinement: S-NDFs sampled in batches (2, then 3, then 3 iterations of one
/// sub-pixel sequence) and added equal one sampling of all 8 iterations, and a batch of a
/// different view size is refused.
#[test]
fn sndf_batches_add_up_to_one_sampling() {
    let (_d, _p, f) = make_file(&fcc_frame(5), small_build(), &[]);
    let (w, h) = (48u32, 36u32);
    let (camera, draw, base) = sndf_scene(&f, (w, h), 8);
    let settings = |iterations| mdlod_render::sndf::SndfSettings { iterations, ..base };
    let r = renderer();
    let whole = r.sample_sndf(&f, &camera, &draw, &settings(8)).unwrap();
    let mut sum = r
        .sample_sndf_from(&f, &camera, &draw, &settings(2), 0)
        .unwrap();
    for first in [2, 5] {
        let batch = r
            .sample_sndf_from(&f, &camera, &draw, &settings(3), first)
            .unwrap();
        assert!(sum.add(&batch));
    }
    assert_eq!(sum.rays, 8);
    let mut hits = 0.0;
    for (a, b) in sum.hist.iter().zip(&whole.hist) {
        for k in 0..4 {
            assert!(
                (a[k] - b[k]).abs() <= 1e-4 * b[k].abs().max(1.0),
                "{a:?} vs {b:?}"
            );
        }
        hits += b[3];
    }
    assert!(hits > 0.0, "the view shows the data");
    // Not the same sequence: a batch restarting at iteration 0 differs somewhere.
    let restart = r
        .sample_sndf_from(&f, &camera, &draw, &settings(3), 0)
        .unwrap();
    let later = r
        .sample_sndf_from(&f, &camera, &draw, &settings(3), 2)
        .unwrap();
    assert_ne!(restart.hist, later.hist);
    let other = Renderer::sample_sndf(
        r,
        &f,
        &camera,
        &draw,
        &mdlod_render::sndf::SndfSettings {
            width: w / 2,
            ..settings(1)
        },
    )
    .unwrap();
    let before = sum.clone();
    assert!(!sum.add(&other));
    assert_eq!(sum, before);
}

/// Hiding a species draws exactly the picture of the data without it (every particle
/// drawn, the same camera; occlusion culling on), and a colour map draws a different one.
#[test]
fn a_hidden_species_leaves_the_picture_of_the_data_without_it() {
    use mdlod_render::{PointStyle, SpeciesStyle};
    let frame = fcc_frame(4);
    let mut copper = frame.clone();
    let keep: Vec<bool> = frame.species_index.iter().map(|&s| s == 0).collect();
    copper.positions = frame
        .positions
        .iter()
        .zip(&keep)
        .filter(|(_, k)| **k)
        .map(|(p, _)| *p)
        .collect();
    copper.species_index = vec![0; copper.positions.len()];
    let (_d, _p, f) = make_file(&frame, small_build(), &[]);
    let (_d2, _p2, g) = make_file(&copper, small_build(), &[]);
    let (w, h) = (96u32, 72u32);
    let camera = camera_for(&f, &ViewSpec::default(), w, h).unwrap();
    let mut o = opts(w, h);
    o.view = ViewSpec::Camera(camera);
    o.error_px = 0.0;
    let (all, _) = render_image(renderer(), &f, &o).unwrap();
    let (without, _) = render_image(renderer(), &g, &o).unwrap();
    o.style = PointStyle {
        species: vec![SpeciesStyle {
            name: "Ag".into(),
            hidden: true,
            ..Default::default()
        }],
        ..Default::default()
    };
    let (hidden, report) = render_image(renderer(), &f, &o).unwrap();
    assert!(
        report.nodes_occluded + report.particles_occluded > 0,
        "occlusion culling stays on for hiding styles"
    );
    assert!(differing(&all, &without, w, h) > 0.01, "silver atoms show");
    assert!(differing(&hidden, &without, w, h) < 0.002);
}

/// Hiding values (`--hide-attribute`) draws exactly the picture of the data without the
/// particles of those values, with a coarse cut too (clusters of kept particles only).
#[test]
fn hidden_values_leave_the_picture_of_the_data_without_them() {
    use mdlod_render::PointStyle;
    let mut frame = fcc_frame(4);
    let n = frame.positions.len();
    let values: Vec<f32> = (0..n).map(|i| (i % 3) as f32).collect();
    let keep: Vec<bool> = values.iter().map(|&v| v != 1.0).collect();
    frame.attribute = Some(mdlod_preprocess::Attribute {
        name: "c_cna".into(),
        values: values.clone(),
    });
    let mut kept = frame.clone();
    kept.positions = frame
        .positions
        .iter()
        .zip(&keep)
        .filter(|(_, k)| **k)
        .map(|(p, _)| *p)
        .collect();
    kept.species_index = frame
        .species_index
        .iter()
        .zip(&keep)
        .filter(|(_, k)| **k)
        .map(|(s, _)| *s)
        .collect();
    kept.attribute = Some(mdlod_preprocess::Attribute {
        name: "c_cna".into(),
        values: values.iter().copied().filter(|&v| v != 1.0).collect(),
    });
    let (_d, _p, f) = make_file(&frame, small_build(), &[]);
    let (_d2, _p2, g) = make_file(&kept, small_build(), &[]);
    let (w, h) = (96u32, 72u32);
    let camera = camera_for(&f, &ViewSpec::default(), w, h).unwrap();
    let mut o = opts(w, h);
    o.view = ViewSpec::Camera(camera);
    o.error_px = 0.0;
    let (all, _) = render_image(renderer(), &f, &o).unwrap();
    let (without, _) = render_image(renderer(), &g, &o).unwrap();
    o.style = PointStyle {
        hidden_values: vec![[0.5, 1.5]],
        ..Default::default()
    };
    let (hidden, report) = render_image(renderer(), &f, &o).unwrap();
    assert!(
        report.nodes_occluded + report.particles_occluded > 0,
        "occlusion culling stays on for hiding styles"
    );
    assert!(report.particles_drawn > 0);
    assert!(
        differing(&all, &without, w, h) > 0.01,
        "the hidden atoms show unhidden"
    );
    assert!(differing(&hidden, &without, w, h) < 0.002);
    // A file with no attribute refuses to hide by value.
    let (_d3, _p3, plain) = make_file(&fcc_frame(2), small_build(), &[]);
    let e = render_image(renderer(), &plain, &o)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("no per-particle attribute to hide particles by"),
        "{e}"
    );
}

/// The share of a `w` × `h` image's pixels whose colours differ by more than 2 in some
/// channel.
fn differing(a: &RgbaImage, b: &RgbaImage, w: u32, h: u32) -> f64 {
    a.data
        .chunks_exact(4)
        .zip(b.data.chunks_exact(4))
        .filter(|(p, q)| (0..3).any(|k| p[k].abs_diff(q[k]) > 2))
        .count() as f64
        / f64::from(w * h)
}

/// A renderer that draws every sphere as an impostor quad.
fn quads_renderer() -> &'static Renderer {
    static R: OnceLock<Renderer> = OnceLock::new();
    R.get_or_init(|| {
        let mut r = Renderer::new(GpuContext::with_backends(backends()).unwrap());
        assert!(!r.set_small_sphere_raster(false));
        r
    })
}

/// The compute raster of small spheres draws what impostor quads draw: the same pixels
/// and depths up to rounding on silhouettes, in perspective and orthographic views, with
/// one and with several jittered samples, and it hands the spheres too large for it to
/// the impostors.
#[test]
fn small_sphere_raster_draws_what_impostor_quads_draw() {
    let has = renderer()
        .ctx
        .device
        .features()
        .contains(mdlod_render::passes::sphere_raycast::SMALL_SPHERES_FEATURES);
    let wanted = std::env::var("MDLOD_SMALL_SPHERES").map_or(true, |v| v.trim() != "0");
    assert_eq!(renderer().small_sphere_raster(), has && wanted);
    if !renderer().small_sphere_raster() {
        eprintln!("the small-sphere raster is off on this device: nothing to compare");
        return;
    }
    let quads = quads_renderer();
    let (_d, _p, f) = make_file(&fcc_frame(30), small_build(), &[]);
    let (w, h) = (200, 150);
    for (zoom, projection, spp) in [
        (1.0, Projection::Perspective, 1),
        (1.0, Projection::Orthographic, 1),
        (1.0, Projection::Perspective, 4),
        (6.0, Projection::Perspective, 1),
        (6.0, Projection::Orthographic, 1),
    ] {
        let view = ViewSpec::Orbit {
            azimuth_deg: 35.0,
            elevation_deg: 25.0,
            zoom,
            projection,
        };
        let camera = camera_for(&f, &view, w, h).unwrap();
        let draw = cut(&f, &camera, [w, h], 0.0, OcclusionMode::Off);
        let settings = depth_frame(w, h, spp);
        let case = format!("zoom {zoom}, {projection:?}, {spp} spp");
        let small = renderer().render(&f, &camera, &draw, &settings).unwrap();
        let all_quads = quads.render(&f, &camera, &draw, &settings).unwrap();
        assert_eq!(all_quads.impostors, None);
        let impostors = small.impostors.unwrap();
        if zoom == 1.0 {
            assert_eq!(
                impostors, 0,
                "{case}: {impostors} of {} as quads",
                small.points
            );
        } else {
            assert!(
                impostors > 0 && impostors < small.points,
                "{case}: {impostors} of {} as quads",
                small.points
            );
        }
        let pixels = (w * h) as usize;
        let (failing, _) = golden::compare(&all_quads.image, &small.image, 2);
        assert!(failing * 1000 <= pixels, "{case}: {failing} pixels differ");
        let covered = all_quads
            .depth
            .as_ref()
            .unwrap()
            .iter()
            .filter(|&&d| d < 1.0)
            .count();
        assert!(covered * 4 > pixels, "{case}: {covered} pixels covered");
        let deeper = all_quads
            .depth
            .unwrap()
            .iter()
            .zip(small.depth.unwrap())
            .filter(|(a, b)| (*a - b).abs() > 1e-5)
            .count();
        assert!(deeper * 1000 <= pixels, "{case}: {deeper} depths differ");
    }
}

/// S-NDFs sampled through the compute raster of small spheres hold what those sampled
/// through impostor quads hold: the same samples in the same bins, up to a few
/// silhouette rays.
#[test]
fn small_sphere_raster_samples_the_sndfs_impostor_quads_sample() {
    if !renderer().small_sphere_raster() {
        eprintln!("the small-sphere raster is off on this device: nothing to compare");
        return;
    }
    let (_d, _p, f) = make_file(&fcc_frame(30), small_build(), &[]);
    let (w, h) = (120u32, 90u32);
    let (camera, draw, settings) = sndf_scene(&f, (w, h), 8);
    let small = renderer()
        .sample_sndf(&f, &camera, &draw, &settings)
        .unwrap();
    let quads = quads_renderer()
        .sample_sndf(&f, &camera, &draw, &settings)
        .unwrap();
    let total: f64 = quads.hist.iter().map(|b| f64::from(b[3])).sum();
    assert!(total > f64::from(w * h * 8) * 0.25, "{total} samples");
    let moved: f64 = small
        .hist
        .iter()
        .zip(&quads.hist)
        .map(|(a, b)| f64::from((a[3] - b[3]).abs()))
        .sum();
    assert!(moved <= total * 2e-3, "{moved} of {total} samples differ");
}

/// A cut drawn in many batches (as cuts larger than a storage binding are) draws exactly
/// what one batch draws. Spheres (each batch one submission into the same targets):
/// colour and depth, through the compute raster and through impostor quads, with
/// particles and representatives, with one and with several jittered samples. S-NDFs:
/// the same histograms. Splats (the batches in order in one pass): the same fluxes,
/// added up and composited.
#[test]
fn a_cut_drawn_in_batches_draws_what_one_batch_draws() {
    let batched = |small: bool| {
        let mut r = Renderer::new(GpuContext::with_backends(backends()).unwrap());
        r.set_small_sphere_raster(small);
        // An odd size, so batches end inside ranges.
        r.set_batch_points(Some(997));
        r
    };
    let (mut small_batched, quads_batched) = (batched(true), batched(false));
    // One of the two reports its passes (and waits for each submission to do so): the
    // same pixels either way.
    let log = Arc::new(Recorded::default());
    small_batched.set_progress(Some(log.clone()));
    assert!(small_batched.batch_limits().0 == 997 && quads_batched.batch_limits().0 == 997);
    let (_d, _p, f) = make_file(&fcc_frame(30), small_build(), &[]);
    let (w, h) = (200, 150);
    for (zoom, error_px, spp) in [(1.0, 0.0, 1), (6.0, 0.0, 1), (1.0, 12.0, 1), (1.0, 0.0, 3)] {
        let view = ViewSpec::Orbit {
            azimuth_deg: 35.0,
            elevation_deg: 25.0,
            zoom,
            projection: Projection::Perspective,
        };
        let camera = camera_for(&f, &view, w, h).unwrap();
        let draw = cut(&f, &camera, [w, h], error_px, OcclusionMode::Off);
        let batches = draw.batches(997, usize::MAX).len();
        assert!(batches >= 3, "{batches} batches");
        assert_eq!(
            draw.representatives > 0,
            error_px > 0.0,
            "{} representatives",
            draw.representatives
        );
        let settings = depth_frame(w, h, spp);
        for (one, many) in [
            (renderer(), &small_batched),
            (quads_renderer(), &quads_batched),
        ] {
            let case = format!(
                "zoom {zoom}, error {error_px} px, {spp} spp, raster {}, {batches} batches",
                many.small_sphere_raster()
            );
            let a = one.render(&f, &camera, &draw, &settings).unwrap();
            let b = many.render(&f, &camera, &draw, &settings).unwrap();
            if many.small_sphere_raster() {
                log.assert_one_stage("drawing", spp as u64 * batches as u64, &case);
            }
            assert_eq!(b.points, a.points, "{case}");
            assert_eq!(b.points as u64, draw.points, "{case}");
            if spp == 1 {
                // One sample binds, draws and drops each batch in turn: the points held
                // at a time are one batch's.
                assert!(
                    b.gpu_data_bytes * 2 <= a.gpu_data_bytes,
                    "{case}: {} bytes held, {} for the whole cut",
                    b.gpu_data_bytes,
                    a.gpu_data_bytes
                );
            }
            let (failing, _) = golden::compare(&a.image, &b.image, 0);
            assert_eq!(failing, 0, "{case}: pixels differ");
            assert!(a.depth == b.depth, "{case}: depths differ");
            assert!(
                a.depth
                    .as_ref()
                    .unwrap()
                    .iter()
                    .filter(|&&d| d < 1.0)
                    .count() as u32
                    * 4
                    > w * h,
                "{case}: too little drawn to compare"
            );
        }
    }
    // S-NDFs: every batch into the same G-buffer before each accumulation.
    let (camera, draw, settings) = sndf_scene(&f, (120, 90), 6);
    assert!(draw.batches(997, usize::MAX).len() >= 3);
    for (one, many) in [
        (renderer(), &small_batched),
        (quads_renderer(), &quads_batched),
    ] {
        let a = one.sample_sndf(&f, &camera, &draw, &settings).unwrap();
        let b = many.sample_sndf(&f, &camera, &draw, &settings).unwrap();
        if many.small_sphere_raster() {
            let submissions = 6 * draw.batches(997, usize::MAX).len() as u64;
            log.assert_one_stage("sampling", submissions, "S-NDFs");
        }
        let rays: f64 = a.hist.iter().map(|b| f64::from(b[3])).sum();
        assert!(rays > 120.0 * 90.0 * 6.0 * 0.25, "{rays} rays hit");
        assert!(
            a.hist == b.hist,
            "S-NDFs differ (raster {})",
            many.small_sphere_raster()
        );
    }
    // Splats, added up and composited back to front, in the same order.
    use mdlod_render::traversal::{sort_back_to_front_by, DepthOrder};
    use mdlod_render::SplatBlend;
    let (_d, _p, cloud) = make_file(&cloud_frame(6000, 3), small_build(), &[]);
    let camera = camera_for(&cloud, &ViewSpec::default(), w, h).unwrap();
    for error_px in [0.0, 6.0] {
        let draw = cut(&cloud, &camera, [w, h], error_px, OcclusionMode::Off);
        let sorted = sort_back_to_front_by(&cloud, &draw, &camera, DepthOrder::Points);
        for (blend, draw) in [
            (
                SplatBlend::Additive {
                    intensity: 1.0,
                    by_attribute: false,
                },
                &draw,
            ),
            (SplatBlend::Over { opacity: 0.6 }, &sorted),
        ] {
            assert!(draw.batches(997, usize::MAX).len() >= 3);
            let splat = |r: &Renderer| r.render_splats(&cloud, &camera, draw, w, h, blend).unwrap();
            let (a, b) = (splat(renderer()), splat(&small_batched));
            let batches = draw.batches(997, usize::MAX).len() as u64;
            log.assert_one_stage("splatting", batches, &format!("{blend:?}"));
            assert_eq!(b.points, a.points, "{blend:?}, error {error_px} px");
            // Each batch is bound, drawn and dropped in turn.
            assert!(
                b.gpu_data_bytes * 2 <= a.gpu_data_bytes,
                "{blend:?}: {} bytes held, {} for the whole cut",
                b.gpu_data_bytes,
                a.gpu_data_bytes
            );
            assert!(
                a.hdr == b.hdr,
                "{blend:?}, error {error_px} px: fluxes differ"
            );
            assert!(a.total_flux()[3] > 0.0);
        }
    }
    // Frames take the budget as given: no storage binding limits them.
    for mode in [
        mdlod_render::RenderMode::Spheres,
        mdlod_render::RenderMode::Splat {
            by_attribute: false,
        },
        mdlod_render::RenderMode::Sndf {
            iterations: 1,
            bins: 4,
            binning: Default::default(),
        },
    ] {
        let o = RenderOptions {
            mode,
            ..opts(64, 48)
        };
        let (_img, report) = render_image(renderer(), &f, &o).unwrap();
        assert_eq!(report.budget, u64::MAX);
    }
}
/// A constant attribute (equal-mass SPH particles) lights every splat alike: its value,
/// so a fine and a coarse cut both carry the disks' whole flux times the mass as light,
/// the projected mass (the particles were quantized to 0, black at full resolution,
/// while the clusters' means lit up). Two values, 1 and 4, light the splats by the
/// value less the range's low end in the attribute's units: 0 and 3, so the light is
/// the disks' area-weighted mean of 0 and 3 times the flux at every level (it was the
/// value mapped to [0, 1]: a third of that).
#[test]
fn a_constant_attribute_lights_every_splat_alike_at_every_level() {
    projected_light_is_the_value_times_the_flux(vec![2.5e-6f32; 2000]);
    projected_light_is_the_value_times_the_flux(
        (0..2000)
            .map(|i| if i % 2 == 0 { 1.0 } else { 4.0 })
            .collect(),
    );
}

fn projected_light_is_the_value_times_the_flux(values: Vec<f32>) {
    let mut frame = cloud_frame(2000, 3);
    frame.attribute = Some(mdlod_preprocess::Attribute {
        name: "mass".into(),
        values: values.clone(),
    });
    let (_d, _p, f) = make_file(&frame, small_build(), &[]);
    // The light per unit of flux: a constant's value, else the area-weighted mean of the
    // values less the smallest (the disks' flux is their area).
    let species = &f.metadata().species;
    let lo = values.iter().copied().fold(f32::INFINITY, f32::min);
    let constant = values.iter().all(|&v| v == lo);
    let (mut light, mut flux) = (0f64, 0f64);
    for (v, &s) in values.iter().zip(&frame.species_index) {
        let area = f64::from(species[usize::from(s)].radius).powi(2);
        light += area * f64::from(if constant { *v } else { v - lo });
        flux += area;
    }
    let per_flux = light / flux;
    let (w, h) = (64u32, 48u32);
    // Zoomed out a little: every splat of every level inside the image, whose flux would
    // otherwise fall past its edge.
    let view = ViewSpec::Orbit {
        azimuth_deg: 30.0,
        elevation_deg: 20.0,
        zoom: 0.7,
        // Orthographic: every disk its area on screen, whatever its distance.
        projection: Projection::Orthographic,
    };
    let camera = camera_for(&f, &view, w, h).unwrap();
    let blend = mdlod_render::SplatBlend::Additive {
        intensity: 1.0,
        by_attribute: true,
    };
    let mut lights = vec![];
    for error_px in [0.0, 8.0, 24.0] {
        let draw = cut(&f, &camera, [w, h], error_px, OcclusionMode::Off);
        let s = renderer()
            .render_splats(&f, &camera, &draw, w, h, blend)
            .unwrap();
        // The image's light, in the attribute's units (the accumulated intensities times
        // the light's unit).
        let t = s.total_flux();
        let light = s.total_light();
        assert!(
            t[3] > 0.0 && (light - per_flux * t[3]).abs() <= 1e-4 * per_flux * t[3],
            "{error_px} px ({} points): light {light} of flux {}, not {per_flux} times",
            draw.points,
            t[3]
        );
        lights.push(s.total_light());
    }
    for l in &lights[1..] {
        assert!((l - lights[0]).abs() <= 1e-3 * lights[0], "{lights:?}");
    }
    // The tone-mapped picture at full resolution is lit.
    let mut o = opts(w, h);
    o.mode = mdlod_render::RenderMode::Splat { by_attribute: true };
    let (img, _) = render_image(renderer(), &f, &o).unwrap();
    let lit = img.data.chunks_exact(4).filter(|p| p[0] > 40).count();
    assert!(lit > 50, "{lit} lit pixels");
}

/// The automatic exposure of attribute-lit splats is chosen from their light, as that of
/// species-lit ones is from theirs: an attribute mostly at 2 % of its range is as well
/// exposed as species light (it was exposed as the disks' flux: near black).
#[test]
fn the_automatic_exposure_of_attribute_splats_is_chosen_from_their_light() {
    let mut frame = cloud_frame(3000, 11);
    let values = (0..3000)
        .map(|i| match i {
            0 => 0.0,
            1 => 1.0,
            _ => 0.02,
        })
        .collect();
    frame.attribute = Some(mdlod_preprocess::Attribute {
        name: "w".into(),
        values,
    });
    let (_d, _p, f) = make_file(&frame, small_build(), &[]);
    let bright = |by_attribute: bool| {
        let mut o = opts(96, 72);
        o.mode = mdlod_render::RenderMode::Splat { by_attribute };
        o.error_px = 2.0;
        let (img, report) = render_image(renderer(), &f, &o).unwrap();
        // The 99th percentile of the lit pixels' brightest channel.
        let mut lit: Vec<u8> = img
            .data
            .chunks_exact(4)
            .map(|p| p[0].max(p[1]).max(p[2]))
            .filter(|&v| v > 0)
            .collect();
        assert!(lit.len() > 100, "{} lit pixels", lit.len());
        lit.sort_unstable();
        (lit[lit.len() * 99 / 100], report.exposure.unwrap())
    };
    let (species, species_exposure) = bright(false);
    let (attribute, attribute_exposure) = bright(true);
    assert!(species > 180, "species light: {species}");
    assert!(
        attribute > 180,
        "attribute light: {attribute} (exposure {attribute_exposure}, species \
         {species_exposure})"
    );
    assert!(attribute_exposure > 10.0 * species_exposure);
}
