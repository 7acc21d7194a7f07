//! The image-space density volume against its CPU twin (`density::reference`, the same
//! rays, slices, kernel and compositing in plain loops): density values through the
//! transfer function, iso-surface positions (and one analytic iso-sphere), clipping that
//! removes samples but not particles, and early ray termination.

mod common;

use std::sync::OnceLock;

use common::*;
use glam::Vec3;
use mdlod_format::MdlodFile;
use mdlod_render::density::{reference, DensityPoint, DensitySettings};
use mdlod_render::{
    camera_for, traverse, BackendChoice, Camera, GpuContext, OcclusionMode, Projection,
    RenderError, Renderer, TraversalSettings, ViewSpec,
};

fn renderer() -> &'static Renderer {
    static R: OnceLock<Renderer> = OnceLock::new();
    R.get_or_init(|| match GpuContext::with_backends(backends()) {
        Ok(ctx) => Renderer::new(ctx),
        Err(e) => panic!("{e}"),
    })
}

fn backends() -> BackendChoice {
    if std::env::var_os("WGPU_BACKEND").is_some() {
        BackendChoice::FromEnv
    } else {
        BackendChoice::Only(wgpu::Backends::VULKAN)
    }
}

/// A renderer of its own, which has drawn no density frame (no stack hint).
fn renderer_without_hints() -> Renderer {
    Renderer::new(GpuContext::with_backends(backends()).unwrap())
}

fn camera(f: &MdlodFile, projection: Projection, w: u32, h: u32) -> Camera {
    camera_zoom(f, projection, w, h, 1.3)
}

fn camera_zoom(f: &MdlodFile, projection: Projection, w: u32, h: u32, zoom: f32) -> Camera {
    camera_for(
        f,
        &ViewSpec::Orbit {
            azimuth_deg: 35.0,
            elevation_deg: 25.0,
            zoom,
            projection,
        },
        w,
        h,
    )
    .unwrap()
}

/// Every particle of `f` (no level of detail).
fn all_points(f: &MdlodFile, camera: &Camera, w: u32, h: u32) -> mdlod_render::DrawList {
    traverse(
        camera,
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
    )
}

/// Renders on the GPU and on the CPU; returns both colour buffers, both hit buffers and
/// the frame's stack counts.
#[allow(clippy::type_complexity)]
fn both(
    f: &MdlodFile,
    camera: &Camera,
    w: u32,
    h: u32,
    s: &DensitySettings,
    cpu_points: Option<&[DensityPoint]>,
) -> (Vec<[f32; 4]>, Vec<[f32; 4]>, Vec<f32>, Vec<f32>, (u32, u32)) {
    let draw = all_points(f, camera, w, h);
    let frame = renderer()
        .render_density(f, camera, &draw, w, h, s)
        .unwrap();
    let albedo = Vec3::from(f.metadata().species[0].colour);
    let points = cpu_points.unwrap_or(&frame.points);
    let r = reference(points, camera, w, h, s, &frame.slicing, albedo);
    (
        frame.rgba,
        r.rgba,
        frame.hit,
        r.hit,
        (frame.stacks_run, frame.stacks),
    )
}

/// The largest difference of two colour buffers; a NaN on either side counts as infinite
/// (`f32::max` would skip it).
fn max_diff(a: &[[f32; 4]], b: &[[f32; 4]]) -> f32 {
    assert_eq!(a.len(), b.len(), "the buffers differ in length");
    assert!(!a.is_empty(), "empty buffers");
    a.iter()
        .zip(b)
        .flat_map(|(p, q)| (0..4).map(move |k| (p[k] - q[k]).abs()))
        .map(|d| if d.is_nan() { f32::INFINITY } else { d })
        .fold(0.0, f32::max)
}

#[test]
fn density_volume_matches_the_cpu_ray_marcher() {
    let (_d, _p, f) = make_file(&fcc_frame(3), small_build(), &[]);
    let (w, h) = (40u32, 30u32);
    for projection in [Projection::Perspective, Projection::Orthographic] {
        let cam = camera(&f, projection, w, h);
        let s = DensitySettings {
            slices: 64,
            opacity: 1.5,
            ..Default::default()
        };
        let (gpu, cpu, _, _, _) = both(&f, &cam, w, h, &s, None);
        let lit = cpu.iter().filter(|p| p[3] > 0.05).count();
        assert!(
            lit > (w * h / 10) as usize,
            "{projection:?}: only {lit} pixels see the block"
        );
        let d = max_diff(&gpu, &cpu);
        assert!(d < 0.01, "{projection:?}: GPU and CPU differ by {d}");
    }
}

/// The transfer function over the density's logarithm (SPH and n-body data): the GPU
/// follows the CPU twin; with the top of the scale far above the data's density, a
/// linear scale leaves the block nearly clear while the log scale shows it; and a
/// bottom above the data's density shows nothing.
#[test]
fn a_log_transfer_function_matches_the_cpu_ray_marcher() {
    let (_d, _p, f) = make_file(&fcc_frame(3), small_build(), &[]);
    let (w, h) = (40u32, 30u32);
    let cam = camera(&f, Projection::Perspective, w, h);
    let linear = DensitySettings {
        slices: 64,
        opacity: 1.5,
        density_max: 50.0,
        ..Default::default()
    };
    let log = DensitySettings {
        log: true,
        density_min: 50.0 * 1e-4,
        ..linear
    };
    let mean_alpha = |rgba: &[[f32; 4]]| rgba.iter().map(|p| p[3]).sum::<f32>() / rgba.len() as f32;
    let (gpu_log, cpu_log, _, _, _) = both(&f, &cam, w, h, &log, None);
    let d = max_diff(&gpu_log, &cpu_log);
    assert!(d < 0.01, "log scale: GPU and CPU differ by {d}");
    let (gpu_lin, cpu_lin, _, _, _) = both(&f, &cam, w, h, &linear, None);
    assert!(max_diff(&gpu_lin, &cpu_lin) < 0.01);
    let (a_log, a_lin) = (mean_alpha(&gpu_log), mean_alpha(&gpu_lin));
    assert!(
        a_log > 0.2 && a_log > 5.0 * a_lin,
        "mean opacity {a_log} on a log scale against {a_lin} on a linear one"
    );
    // A bottom of the scale above every density the block reaches: clear.
    let above = DensitySettings {
        density_min: 40.0,
        ..linear
    };
    let (gpu, cpu, _, _, _) = both(&f, &cam, w, h, &above, None);
    assert!(max_diff(&gpu, &cpu) < 0.01);
    assert!(mean_alpha(&gpu) == 0.0, "{}", mean_alpha(&gpu));
}

/// An orthographic view shows the same volume wherever its eye is along the view axis:
/// with the eye inside the data (a view zoomed in), what lies between the near plane and
/// the eye's plane is drawn too.
#[test]
fn an_orthographic_volume_does_not_depend_on_where_the_eye_is_along_the_axis() {
    let (_d, _p, f) = make_file(&fcc_frame(3), small_build(), &[]);
    let (w, h) = (40u32, 30u32);
    let outside = camera(&f, Projection::Orthographic, w, h);
    // A quarter of the distance, the same view height: the eye is inside the block.
    let mut inside = outside.clone();
    inside.distance *= 0.25;
    let half = (inside.fov_y_deg.to_radians() * 0.5).tan() * 4.0;
    inside.fov_y_deg = 2.0 * half.atan().to_degrees();
    let inside = camera_for(&f, &ViewSpec::Camera(inside), w, h).unwrap();
    assert!(inside.near < 0.0, "the eye is not inside the data");
    assert!((inside.view_height_at_target() - outside.view_height_at_target()).abs() < 1e-3);
    let s = DensitySettings {
        slices: 64,
        opacity: 1.5,
        ..Default::default()
    };
    let (far, _, _, _, _) = both(&f, &outside, w, h, &s, None);
    let (near, cpu, _, _, _) = both(&f, &inside, w, h, &s, None);
    let lit = far.iter().filter(|p| p[3] > 0.05).count();
    assert!(
        lit > (w * h / 10) as usize,
        "only {lit} pixels see the block"
    );
    let d = max_diff(&near, &far);
    assert!(d < 0.01, "the eye inside the data changes the image by {d}");
    assert!(max_diff(&near, &cpu) < 0.01);
}

/// A volume whose per-pixel ray state does not fit one buffer binding is refused with a
/// message that says so, not a GPU validation error.
#[test]
fn a_volume_too_large_for_one_binding_is_refused_with_its_size() {
    let (_d, _p, f) = make_file(&fcc_frame(2), small_build(), &[]);
    let limits = renderer().ctx.device.limits();
    let most = limits
        .max_storage_buffer_binding_size
        .min(limits.max_buffer_size);
    let per_ray = std::mem::size_of::<mdlod_render::passes::density::RayGpu>() as u64;
    let side = u64::from(limits.max_texture_dimension_2d);
    let (w, h) = (side.min(4096), (most / per_ray) / side.min(4096) + 1);
    if h > side {
        eprintln!("this adapter binds {most} bytes: no image is too large for the ray state");
        return;
    }
    let (w, h) = (w as u32, h as u32);
    let cam = camera(&f, Projection::Perspective, w, h);
    let draw = all_points(&f, &cam, w, h);
    match renderer().render_density(&f, &cam, &draw, w, h, &DensitySettings::default()) {
        Err(RenderError::InvalidOptions(m)) => {
            assert!(
                m.contains("ray state") && m.contains(&format!("{w}x{h}")),
                "{m}"
            )
        }
        other => panic!("{w}x{h}: {:?}", other.map(|_| ())),
    }
}

/// A view inside a block: the particles just outside the view add density inside it
/// (their kernels reach 2.5 radii), so the cut keeps them, and the volume is the one
/// every particle of the file makes.
#[test]
fn kernels_reaching_into_the_view_from_outside_it_add_their_density() {
    let (_d, _p, f) = make_file(&fcc_frame(8), small_build(), &[]);
    let (w, h) = (40u32, 30u32);
    let s = DensitySettings {
        slices: 64,
        opacity: 0.1,
        ..Default::default()
    };
    let cut_of = |camera: &Camera, support_scale: f32| {
        traverse(
            camera,
            &f,
            &TraversalSettings {
                viewport: [w, h],
                error_px: 0.0,
                budget_points: u64::MAX,
                occlusion: OcclusionMode::Off,
                support_scale,
                hidden: mdlod_render::HiddenSet::default(),
                clip: Default::default(),
            },
        )
    };
    let everything = cut_of(&camera_zoom(&f, Projection::Perspective, w, h, 0.5), 0.0);
    assert_eq!(everything.particles, f.particle_count());
    let every_point = mdlod_render::density::density_points(&f, &everything, None);
    for projection in [Projection::Perspective, Projection::Orthographic] {
        let cam = camera_zoom(&f, projection, w, h, 6.0);
        let albedo = Vec3::from(f.metadata().species[0].colour);
        // Culled by the particles' boxes (the kernels ignored), then by the kernels.
        let mut differences = Vec::new();
        for support_scale in [0.0, s.kernel_scale] {
            let cut = cut_of(&cam, support_scale);
            assert!(
                cut.particles < f.particle_count(),
                "{projection:?}: nothing culled at {support_scale}"
            );
            let frame = renderer().render_density(&f, &cam, &cut, w, h, &s).unwrap();
            let all = reference(&every_point, &cam, w, h, &s, &frame.slicing, albedo);
            differences.push(max_diff(&frame.rgba, &all.rgba));
        }
        assert!(
            differences[1] < 1e-4 && differences[0] > 1e-3,
            "{projection:?}: the cut's volume differs from every particle's by {} culled by \
             boxes, {} by kernels",
            differences[0],
            differences[1]
        );
    }
}

/// An axis-aligned orthographic view (every ray's direction has zero components) matches
/// the CPU ray marcher, and an empty cut is a transparent frame.
#[test]
fn axis_aligned_rays_and_an_empty_cut_composite_cleanly() {
    let (_d, _p, f) = make_file(&fcc_frame(3), small_build(), &[]);
    let (w, h) = (40u32, 30u32);
    let cam = camera_for(
        &f,
        &ViewSpec::Orbit {
            azimuth_deg: 0.0,
            elevation_deg: 0.0,
            zoom: 1.3,
            projection: Projection::Orthographic,
        },
        w,
        h,
    )
    .unwrap();
    let s = DensitySettings {
        slices: 64,
        opacity: 1.5,
        ..Default::default()
    };
    let (gpu, cpu, _, _, _) = both(&f, &cam, w, h, &s, None);
    assert!(cpu.iter().filter(|p| p[3] > 0.05).count() > (w * h / 10) as usize);
    let d = max_diff(&gpu, &cpu);
    assert!(d < 0.01, "GPU and CPU differ by {d}");
    let empty = renderer()
        .render_density(&f, &cam, &mdlod_render::DrawList::default(), w, h, &s)
        .unwrap();
    assert!(empty.rgba.iter().all(|p| p[3] == 0.0), "an empty cut drew");
}

/// A volume fraction does not depend on the length unit: the same block in units 10¹³
/// times smaller (stars in metres have radii of 10⁹ and more; a coarse node's reaches
/// 10¹³) gives the same volume, on the GPU and the CPU, with no power of a radius
/// overflowing single precision.
#[test]
fn the_volume_does_not_depend_on_the_length_unit() {
    let (w, h) = (40u32, 30u32);
    let s = DensitySettings {
        slices: 64,
        opacity: 1.5,
        ..Default::default()
    };
    let volume = |scale: f32| {
        let mut frame = fcc_frame(3);
        for p in &mut frame.positions {
            *p = p.map(|c| c * scale);
        }
        let radii = [("Cu", 1.28 * scale), ("Ag", 1.44 * scale)];
        let (_d, _p, f) = make_file(&frame, small_build(), &radii);
        let cam = camera(&f, Projection::Perspective, w, h);
        let (gpu, cpu, _, _, _) = both(&f, &cam, w, h, &s, None);
        (gpu, cpu)
    };
    let (gpu, cpu) = volume(1.0);
    assert!(cpu.iter().filter(|p| p[3] > 0.05).count() > (w * h / 10) as usize);
    // Units 10^13 times smaller (stars in metres, against light years) and 10^10 times
    // larger (atoms in metres). At 10^-8 and below every kernel's screen box once took
    // the whole screen (an absolute epsilon on the view depth): the same image, a
    // hundred times slower.
    for scale in [1e13, 1e-10] {
        let (big_gpu, big_cpu) = volume(scale);
        let finite = |v: &[[f32; 4]]| v.iter().flatten().all(|c| c.is_finite());
        assert!(
            finite(&big_gpu) && finite(&big_cpu),
            "{scale}: a value is not finite"
        );
        let (dg, dc) = (max_diff(&big_gpu, &gpu), max_diff(&big_cpu, &cpu));
        assert!(
            dg < 0.01 && dc < 0.01,
            "in units {scale} times the volume differs by {dg} (GPU), {dc} (CPU)"
        );
    }
}

/// The pixels where both sides hit the iso-surface, each with the GPU's hit point in
/// world space, and the largest difference of their colours between GPU and CPU.
fn surface_hits(
    cam: &Camera,
    (w, h): (u32, u32),
    (gpu, cpu): (&[[f32; 4]], &[[f32; 4]]),
    (gh, ch): (&[f32], &[f32]),
) -> (Vec<(usize, Vec3)>, f32) {
    let mut worst = 0.0f32;
    let mut hits = Vec::new();
    for i in 0..(w * h) as usize {
        if !(gh[i].is_finite() && ch[i].is_finite()) {
            continue;
        }
        let diff = (0..3)
            .map(|k| (gpu[i][k] - cpu[i][k]).abs())
            .fold(0.0, f32::max);
        worst = worst.max(diff);
        let (o, v) = mdlod_render::density::pixel_ray(
            cam,
            (i as u32 % w) as f32 + 0.5,
            (i as u32 / w) as f32 + 0.5,
            w,
            h,
        );
        hits.push((i, o + v * gh[i]));
    }
    (hits, worst)
}

#[test]
fn iso_surface_matches_the_cpu_ray_marcher() {
    let (_d, _p, f) = make_file(&cloud_frame(300, 3), small_build(), &[]);
    let (w, h) = (40u32, 30u32);
    for projection in [Projection::Perspective, Projection::Orthographic] {
        let cam = camera(&f, projection, w, h);
        let s = DensitySettings {
            iso: Some(0.05),
            slices: 96,
            ..Default::default()
        };
        let (gpu, cpu, gh, ch, _) = both(&f, &cam, w, h, &s, None);
        let hits = ch.iter().filter(|v| v.is_finite()).count();
        assert!(
            hits > 20,
            "{projection:?}: the surface covers {hits} pixels"
        );
        let mut disagree = 0;
        let mut worst = 0.0f32;
        for (a, b) in gh.iter().zip(&ch) {
            match (a.is_finite(), b.is_finite()) {
                (true, true) => worst = worst.max((a - b).abs()),
                (false, false) => {}
                _ => disagree += 1,
            }
        }
        assert!(
            disagree * 100 <= hits,
            "{projection:?}: {disagree} pixels hit on one side only"
        );
        assert!(
            worst < 1e-2,
            "{projection:?}: surface distances differ by {worst}"
        );
        let mut colour = 0.0f32;
        for (i, (a, b)) in gh.iter().zip(&ch).enumerate() {
            if a.is_finite() && b.is_finite() {
                colour = colour.max(
                    (0..3)
                        .map(|k| (gpu[i][k] - cpu[i][k]).abs())
                        .fold(0.0, f32::max),
                );
            }
        }
        assert!(colour < 0.02, "{projection:?}: shading differs by {colour}");
    }
}

#[test]
fn the_iso_surface_takes_each_species_colour_where_it_lies() {
    // A copper half and a silver half of one block: far from the interface the surface
    // has the species' own colour (chromaticity), between them a blend, and the GPU's
    // colour pass equals the CPU's weighted albedos.
    let mut frame = fcc_frame(4);
    let mid = 2.0 * 3.615;
    frame.species_index = frame
        .positions
        .iter()
        .map(|p| u16::from(p[0] > mid))
        .collect();
    let (_d, _p, f) = make_file(&frame, small_build(), &[]);
    let (w, h) = (48u32, 36u32);
    let cam = camera_zoom(&f, Projection::Perspective, w, h, 1.1);
    let s = DensitySettings {
        iso: Some(0.3),
        slices: 128,
        ..Default::default()
    };
    let (gpu, cpu, gh, ch, _) = both(&f, &cam, w, h, &s, None);
    let albedo: Vec<Vec3> = f
        .metadata()
        .species
        .iter()
        .map(|s| Vec3::from(s.colour))
        .collect();
    assert!(
        (albedo[0].normalize() - albedo[1].normalize()).length() > 0.05,
        "the species need different colours: {albedo:?}"
    );
    let (mut seen, mut worst_hue) = ([0usize; 2], 0.0f32);
    let support = s.kernel_scale * f.metadata().species[1].radius;
    let (hits, worst) = surface_hits(&cam, (w, h), (&gpu, &cpu), (&gh, &ch));
    for (i, p) in hits {
        let x = p.x;
        let side = if x < mid - support {
            0
        } else if x > mid + support {
            1
        } else {
            continue;
        };
        seen[side] += 1;
        let c = Vec3::new(gpu[i][0], gpu[i][1], gpu[i][2]);
        worst_hue = worst_hue.max((c.normalize() - albedo[side].normalize()).length());
    }
    assert!(
        seen[0] > 20 && seen[1] > 20,
        "surface pixels far from the interface: {seen:?}"
    );
    assert!(worst < 0.02, "GPU and CPU colours differ by {worst}");
    assert!(
        worst_hue < 0.01,
        "a pure species' surface is off its colour by {worst_hue}"
    );
}

#[test]
fn an_iso_surface_coloured_by_the_attribute_shows_its_value_where_it_lies() {
    // A block whose attribute is each atom's x: the GPU's colour pass equals the CPU's
    // weighted places on the scale, and away from the block's x faces each hit's colour
    // is the map's at the hit's own x (a linear field's kernel mean where the kernel
    // sees both sides), to within the slice spacing and the lattice's steps.
    let mut frame = fcc_frame(4);
    let xs: Vec<f32> = frame.positions.iter().map(|p| p[0]).collect();
    frame.attribute = Some(mdlod_preprocess::Attribute {
        name: "x".into(),
        values: xs.clone(),
    });
    let (lo, hi) = xs
        .iter()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(l, h), &x| {
            (l.min(x), h.max(x))
        });
    let (_d, _p, f) = make_file(&frame, small_build(), &[]);
    let (w, h) = (48u32, 36u32);
    let cam = camera_zoom(&f, Projection::Perspective, w, h, 1.1);
    let map = mdlod_render::ColourMap::Viridis;
    let s = DensitySettings {
        iso: Some(0.3),
        slices: 128,
        colour_map: Some(map),
        ..Default::default()
    };
    let (gpu, cpu, gh, ch, _) = both(&f, &cam, w, h, &s, None);
    // The map's places, finely, by direction (the shading scales a colour).
    let table: Vec<(f32, Vec3)> = (0..=1000)
        .map(|k| {
            let t = k as f32 / 1000.0;
            (t, Vec3::from(map.colour(t)).normalize())
        })
        .collect();
    let place = |c: Vec3| {
        let c = c.normalize();
        table
            .iter()
            .min_by(|a, b| (a.1 - c).length().total_cmp(&(b.1 - c).length()))
            .map(|e| e.0)
            .unwrap()
    };
    let reach = s.kernel_scale * f.metadata().species[0].radius;
    let (mut inner, mut worst_place) = (0usize, 0.0f32);
    let (hits, worst) = surface_hits(&cam, (w, h), (&gpu, &cpu), (&gh, &ch));
    for (i, p) in hits {
        let x = p.x;
        if x < lo + reach || x > hi - reach {
            continue;
        }
        inner += 1;
        let c = Vec3::new(gpu[i][0], gpu[i][1], gpu[i][2]);
        worst_place = worst_place.max((place(c) - (x - lo) / (hi - lo)).abs());
    }
    assert!(inner > 40, "{inner} surface pixels away from the x faces");
    assert!(worst < 0.02, "GPU and CPU colours differ by {worst}");
    assert!(
        worst_place < 0.08,
        "a hit's colour is off its x's place on the scale by {worst_place}"
    );
}

#[test]
fn a_volume_coloured_by_the_attribute_matches_the_cpu_ray_marcher_and_its_values() {
    // Two blobs apart, the attribute 0 in one and 1 in the other: the GPU's volume equals
    // the CPU's, and each blob's pixels take the map's colour at its end of the scale
    // (their opacity the density's, so the colour's direction is the map's).
    let mut frame = cloud_frame(300, 3);
    let mid = frame.positions.iter().map(|p| p[0]).sum::<f32>() / 300.0;
    for p in frame.positions.iter_mut() {
        p[0] += if p[0] < mid { -60.0 } else { 60.0 };
    }
    let values: Vec<f32> = frame
        .positions
        .iter()
        .map(|p| f32::from(u8::from(p[0] > mid)))
        .collect();
    frame.attribute = Some(mdlod_preprocess::Attribute {
        name: "side".into(),
        values,
    });
    let (_d, _p, f) = make_file(&frame, small_build(), &[]);
    let (w, h) = (48u32, 24u32);
    let cam = camera(&f, Projection::Orthographic, w, h);
    let map = mdlod_render::ColourMap::Viridis;
    let s = DensitySettings {
        slices: 96,
        colour_map: Some(map),
        ..Default::default()
    };
    let (gpu, cpu, _, _, _) = both(&f, &cam, w, h, &s, None);
    let worst = max_diff(&gpu, &cpu);
    assert!(worst < 0.01, "GPU and CPU volumes differ by {worst}");
    let ends = [0.0f32, 1.0].map(|t| Vec3::from(map.colour(t)).normalize());
    // Per end of the scale: the pixels that take its colour, and their columns.
    let (mut seen, mut columns, mut opaque) = ([0usize; 2], [Vec::new(), Vec::new()], 0);
    for (i, px) in gpu.iter().enumerate() {
        if px[3] < 0.2 {
            continue;
        }
        let c = Vec3::new(px[0], px[1], px[2]).normalize();
        let d = ends.map(|e| (c - e).length());
        let end = usize::from(d[1] < d[0]);
        opaque += 1;
        // (A ray through both blobs mixes their colours.)
        if d[end] < 0.02 {
            seen[end] += 1;
            columns[end].push(i as u32 % w);
        }
    }
    assert!(
        (seen[0] + seen[1]) * 10 >= opaque * 8,
        "{seen:?} of {opaque} opaque pixels take one end's colour"
    );
    // The two colours are the two blobs: apart, each on its own side.
    let (a, b) = (&columns[0], &columns[1]);
    let apart = a.iter().max() < b.iter().min() || b.iter().max() < a.iter().min();
    assert!(apart, "the colours' columns overlap: {a:?} {b:?}");
    assert!(
        seen[0] > 10 && seen[1] > 10,
        "opaque pixels per blob: {seen:?}"
    );
}

#[test]
fn a_single_particle_makes_an_iso_sphere_of_the_kernel_radius() {
    // φ(r) = V m 315/(64 π h³) (1 − r²/h²)³ with m = 1, V = 4/3 π r_ref³, r = 1, h = 2.5:
    // the iso-value 0.2 lies at r_iso = h sqrt(1 − (0.2 / φ(0))^(1/3)).
    let (_d, _p, f) = make_file(
        &spheres_frame(&[[5.0, 5.0, 5.0]]),
        small_build(),
        &[("X", 1.0)],
    );
    let (w, h) = (33u32, 33u32);
    // (The view fits the particle's sphere, at 1.3 × 90 % of the image; the iso-sphere,
    // 1.17 times as wide, is kept whole at 0.85.)
    let cam = camera_zoom(&f, Projection::Orthographic, w, h, 0.85);
    let s = DensitySettings {
        iso: Some(0.2),
        slices: 400,
        ..Default::default()
    };
    let draw = all_points(&f, &cam, w, h);
    let frame = renderer()
        .render_density(&f, &cam, &draw, w, h, &s)
        .unwrap();
    let kh = 2.5f32;
    let peak =
        4.0 / 3.0 * std::f32::consts::PI * 315.0 / (64.0 * std::f32::consts::PI * kh.powi(3));
    let r_iso = kh * (1.0 - (0.2 / peak).cbrt()).sqrt();
    let centre = mdlod_render::density::ray_distance(&cam, Vec3::splat(5.0));
    let hit = frame.hit[(16 * w + 16) as usize];
    // The centre pixel's ray passes within half a pixel of the particle.
    let px = cam.view_height_at_target() / h as f32;
    assert!(
        (centre - hit - r_iso).abs() < 0.01 + px * px / r_iso,
        "surface at {} from the centre, expected {r_iso}",
        centre - hit
    );
    // The silhouette's area matches the disk of radius r_iso.
    let covered = frame.hit.iter().filter(|v| v.is_finite()).count() as f32;
    let disk = std::f32::consts::PI * (r_iso / px).powi(2);
    assert!(
        (covered - disk).abs() < 0.1 * disk + 4.0,
        "{covered} pixels, disk {disk}"
    );
}

#[test]
fn clipping_removes_samples_not_particles() {
    // Two particles either side of the plane x = 5: density inside the kept half-space
    // near the plane includes the particle beyond it.
    let (_d, _p, f) = make_file(
        &spheres_frame(&[[4.2, 5.0, 5.0], [5.8, 5.0, 5.0], [3.0, 5.0, 5.0]]),
        small_build(),
        &[("X", 1.0)],
    );
    let (w, h) = (32u32, 24u32);
    let cam = camera(&f, Projection::Perspective, w, h);
    let s = DensitySettings {
        slices: 64,
        opacity: 3.0,
        clip: Some([1.0, 0.0, 0.0, 5.0]),
        ..Default::default()
    };
    let (gpu, cpu, _, _, _) = both(&f, &cam, w, h, &s, None);
    let d = max_diff(&gpu, &cpu);
    assert!(d < 0.01, "GPU and CPU differ by {d}");
    // Clipping the particles instead (dropping the one beyond the plane) is visibly wrong.
    let draw = all_points(&f, &cam, w, h);
    let frame = renderer()
        .render_density(&f, &cam, &draw, w, h, &s)
        .unwrap();
    let inside: Vec<DensityPoint> = frame
        .points
        .iter()
        .copied()
        .filter(|p| p.position.x <= 5.0)
        .collect();
    let albedo = Vec3::ONE;
    let wrong = reference(&inside, &cam, w, h, &s, &frame.slicing, albedo);
    assert!(
        max_diff(&cpu, &wrong.rgba) > 0.05,
        "the particle beyond the plane adds nothing"
    );
    // And the clip removes what lies beyond the plane.
    let unclipped = DensitySettings { clip: None, ..s };
    let (full, _, _, _, _) = both(&f, &cam, w, h, &unclipped, None);
    assert!(max_diff(&full, &gpu) > 0.05);
}

#[test]
fn rays_stop_once_opaque_and_the_next_frame_runs_their_stacks_at_once() {
    let (_d, _p, f) = make_file(&fcc_frame(5), small_build(), &[]);
    let (w, h) = (24u32, 18u32);
    // Zoomed into the block: every ray meets dense matter at once.
    let cam = camera_zoom(&f, Projection::Orthographic, w, h, 4.0);
    let s = DensitySettings {
        slices: 256,
        opacity: 50.0,
        ..Default::default()
    };
    let (gpu, cpu, _, _, (run, all)) = both(&f, &cam, w, h, &s, None);
    assert!(run <= all / 2, "{run} of {all} stacks run");
    assert!(gpu.iter().all(|p| p[3] >= 0.99), "a ray stayed open");
    assert!(max_diff(&gpu, &cpu) < 0.01);

    // Frame-to-frame coherence lives in the renderer: one of this test's own, so that
    // other tests' frames give it no hint.
    let mut renderer = renderer_without_hints();
    let log = std::sync::Arc::new(Recorded::default());
    renderer.set_progress(Some(log.clone()));
    let draw = all_points(&f, &cam, w, h);
    let render = |s: &DensitySettings| renderer.render_density(&f, &cam, &draw, w, h, s).unwrap();
    let first = render(&s);
    // Reported as stacks are composited: those run of the frame's total, then ended.
    assert_eq!(
        log.take(),
        [(
            "density stacks".to_owned(),
            Some(u64::from(first.stacks)),
            u64::from(first.stacks_run),
            true
        )]
    );
    assert_eq!(first.stacks_hint, None);
    assert_eq!(first.readbacks, first.stacks_run.div_ceil(8));
    assert!(first.readbacks >= 2, "{} stacks run", first.stacks_run);
    assert!(first.stacks_needed <= first.stacks_run);
    // The same view again: the stacks the first needed, in one batch, the same picture
    // (its checkpoints, finer near the end, may find fewer needed).
    let second = render(&s);
    assert_eq!(second.stacks_hint, Some(first.stacks_needed));
    assert_eq!(
        (second.readbacks, second.stacks_run),
        (1, first.stacks_needed)
    );
    assert!(second.rgba == first.rgba, "the hint changed the picture");
    assert!(second.stacks_needed <= first.stacks_needed);
    // A thinner medium needs more stacks than the hint: the frame goes on past it and
    // is the picture a renderer without a hint makes.
    let thin = DensitySettings { opacity: 2.0, ..s };
    let third = render(&thin);
    assert_eq!(third.stacks_hint, Some(second.stacks_needed));
    assert!(third.stacks_needed > second.stacks_needed && third.readbacks >= 2);
    let fresh = renderer_without_hints()
        .render_density(&f, &cam, &draw, w, h, &thin)
        .unwrap();
    assert!(
        third.rgba == fresh.rgba,
        "stopping late or early changed the picture"
    );
    // And a view needing fewer stacks than its hint stops at the checkpoints.
    let fourth = render(&s);
    assert_eq!(fourth.stacks_hint, Some(third.stacks_needed));
    assert!(fourth.stacks_needed < third.stacks_needed);
    assert!(fourth.rgba == first.rgba);
}

/// A cut drawn in batches (as one larger than a storage binding is) gives the density
/// volume and the iso-surface one batch gives: the batches hold the depth-sorted points
/// in order, and each stack draws its interval of them batch by batch.
#[test]
fn a_cut_in_batches_gives_the_volume_of_one_batch() {
    let (_d, _p, f) = make_file(&fcc_frame(6), small_build(), &[]);
    let (w, h) = (48u32, 36u32);
    let cam = camera(&f, Projection::Perspective, w, h);
    let draw = all_points(&f, &cam, w, h);
    let mut batched = renderer_without_hints();
    batched.set_batch_points(Some(97));
    assert!(draw.batches(97, usize::MAX).len() >= 8);
    for s in [
        DensitySettings {
            slices: 48,
            opacity: 1.5,
            ..Default::default()
        },
        DensitySettings {
            iso: Some(0.05),
            slices: 48,
            ..Default::default()
        },
    ] {
        let one = renderer_without_hints()
            .render_density(&f, &cam, &draw, w, h, &s)
            .unwrap();
        let many = batched.render_density(&f, &cam, &draw, w, h, &s).unwrap();
        batched.clear_density_hint();
        assert!(one.rgba.iter().filter(|p| p[3] > 0.05).count() > (w * h / 10) as usize);
        assert!(one.rgba == many.rgba, "iso {:?}: colours differ", s.iso);
        let same_hits = one
            .hit
            .iter()
            .zip(&many.hit)
            .all(|(a, b)| a == b || (a.is_nan() && b.is_nan()));
        assert!(same_hits, "iso {:?}: hits differ", s.iso);
        assert_eq!(one.splatted, many.splatted);
    }
}

/// A coarse cut keeps the volume fraction of its particles: a representative spreads its
/// particles' volume over the space they fill (support `(r_ref ρ²)^{1/3}`), where a
/// support of `ρ`, which grows as `√n`, smeared a solid's density out past its surface
/// (at 16 px: a fifth of the solid's density one and a half cells outside a copper block,
/// two thirds of it left at its surface). Measured on the CPU twin inside the block, in
/// its surface layer and outside it; the GPU draws such cuts as the CPU does.
#[test]
fn coarse_cuts_keep_the_volume_fraction_of_their_particles() {
    use mdlod_render::density::{density_at, density_points};
    let (_d, _p, f) = make_file(&fcc_frame(8), small_build(), &[("Cu", 1.28), ("Ag", 1.44)]);
    let (w, h) = (40u32, 30u32);
    let cam = camera(&f, Projection::Perspective, w, h);
    let s = DensitySettings {
        slices: 64,
        opacity: 1.5,
        ..Default::default()
    };
    let (r_ref, cell) = (1.44, 3.615);
    let side = 8.0 * cell;
    // 3×3 samples across a plane, `at` along z (and the same on the other axes outside).
    let grid = |lo: f32, hi: f32| move |i: usize| lo + (hi - lo) * (i as f32 + 0.5) / 3.0;
    let core: Vec<Vec3> = (0..27)
        .map(|i| {
            let c = grid(2.5 * cell, side - 2.5 * cell);
            Vec3::new(c(i % 3), c(i / 3 % 3), c(i / 9))
        })
        .collect();
    let t = grid(0.0, side);
    let surface: Vec<Vec3> = (0..9)
        .map(|i| Vec3::new(t(i % 3), t(i / 3), side - 0.5 * cell))
        .collect();
    let outside: Vec<Vec3> = (0..6 * 9)
        .map(|i| {
            let (face, a, b) = (i / 9, t(i % 3), t(i / 3 % 3));
            let o = if face % 2 == 0 {
                -1.5 * cell
            } else {
                side + 1.5 * cell
            };
            match face / 2 {
                0 => Vec3::new(o, a, b),
                1 => Vec3::new(a, o, b),
                _ => Vec3::new(a, b, o),
            }
        })
        .collect();
    let mean = |draw: &mdlod_render::DrawList, at: &[Vec3]| {
        let points = density_points(&f, draw, None);
        at.iter()
            .map(|&p| density_at(&points, p, &s, r_ref).0)
            .sum::<f32>()
            / at.len() as f32
    };
    let all = all_points(&f, &cam, w, h);
    let (core0, surface0) = (mean(&all, &core), mean(&all, &surface));
    assert!(core0 > 0.6 && surface0 > 0.6, "{core0} {surface0}");
    assert_eq!(mean(&all, &outside), 0.0);
    let mut clusters_only = false;
    for error_px in [8.0, 16.0] {
        let draw = traverse(
            &cam,
            &f,
            &TraversalSettings {
                viewport: [w, h],
                error_px,
                budget_points: u64::MAX,
                occlusion: OcclusionMode::Off,
                support_scale: s.kernel_scale,
                hidden: mdlod_render::HiddenSet::default(),
                clip: Default::default(),
            },
        );
        assert!(draw.representatives > 100, "{error_px} px");
        clusters_only |= draw.particles == 0;
        let (c, sf, o) = (
            mean(&draw, &core),
            mean(&draw, &surface),
            mean(&draw, &outside),
        );
        let at = format!(
            "{error_px} px ({} clusters, {} particles): core {c}, surface {sf}, outside {o}, \
             particles' {core0}, {surface0}, 0",
            draw.representatives, draw.particles
        );
        assert!((c / core0 - 1.0).abs() < 0.1, "{at}");
        assert!(sf > 0.8 * surface0, "{at}");
        assert!(o < 0.02, "{at}");
        let frame = renderer()
            .render_density(&f, &cam, &draw, w, h, &s)
            .unwrap();
        let albedo = Vec3::from(f.metadata().species[0].colour);
        let cpu = reference(&frame.points, &cam, w, h, &s, &frame.slicing, albedo);
        let d = max_diff(&frame.rgba, &cpu.rgba);
        assert!(d < 0.01, "{error_px} px: GPU and CPU differ by {d}");
    }
    assert!(clusters_only);
}

/// The traversal keeps every node whose kernels reach into the view: the density
/// anywhere in a zoomed view of a cut of clusters is the same as from the same cut with
/// nothing culled (without the margin it differs near the view's edges). The data mixes
/// small and large particles, whose clusters' supports `(r_ref ρ²)^{1/3}` may exceed
/// their flux radii; the samples do not isolate that term of the margin.
#[test]
fn culling_keeps_every_cluster_whose_kernel_reaches_the_view() {
    use mdlod_render::density::{density_at, density_points};
    // Copper at 0.3 among silver at 1.44: clusters of a few copper atoms have ρ < r_ref.
    let (_d, _p, f) = make_file(&fcc_frame(8), small_build(), &[("Cu", 0.3), ("Ag", 1.44)]);
    let (w, h) = (40u32, 30u32);
    let cam = camera_zoom(&f, Projection::Perspective, w, h, 3.0);
    let s = DensitySettings::default();
    let cut = |support_scale: f32| {
        traverse(
            &cam,
            &f,
            &TraversalSettings {
                viewport: [w, h],
                error_px: 8.0,
                budget_points: u64::MAX,
                occlusion: OcclusionMode::Off,
                support_scale,
                hidden: mdlod_render::HiddenSet::default(),
                clip: Default::default(),
            },
        )
    };
    let (culled, whole) = (cut(s.kernel_scale), cut(1e6));
    assert!(culled.points < whole.points, "nothing was culled");
    assert!(culled.representatives > 0);
    let (a, b) = (
        density_points(&f, &culled, None),
        density_points(&f, &whole, None),
    );
    let clip = cam.clip_from_world([w, h], glam::Vec2::ZERO);
    let side = 8.0 * 3.615;
    let mut seen = 0;
    for i in 0..20 * 20 * 20 {
        let p = Vec3::new(
            side * ((i % 20) as f32 + 0.5) / 20.0,
            side * ((i / 20 % 20) as f32 + 0.5) / 20.0,
            side * ((i / 400) as f32 + 0.5) / 20.0,
        );
        let q = clip * p.extend(1.0);
        if !(q.w > 0.0 && q.x.abs() < q.w && q.y.abs() < q.w) {
            continue;
        }
        let (x, y) = (density_at(&a, p, &s, 1.44).0, density_at(&b, p, &s, 1.44).0);
        assert!(
            (x - y).abs() <= 1e-5 * (1.0 + y.abs()),
            "{p}: {x} against {y}"
        );
        seen += usize::from(y > 0.0);
    }
    assert!(seen > 100, "{seen} samples with density in the view");
}
