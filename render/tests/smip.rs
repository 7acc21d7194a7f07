//! The virtual S-MIP on a real device (lavapipe in CI): tile reuse on pan, down-sampling
//! on zoom-out, LRU eviction in a tiny pool, re-lighting without particles, and the
//! composite pass against host shading of the same texels.

mod common;

use std::sync::OnceLock;

use common::golden::compare;
use common::*;
use mdlod_format::MdlodFile;
use mdlod_render::smip::{Smip, SmipConfig, SmipFrame, TileKey};
use mdlod_render::sndf::{Binning, ShadeLights, Sndf, TILE};
use mdlod_render::{
    camera_for, BackendChoice, Camera, GpuContext, Lighting, PointStyle, Projection, Renderer,
    RgbaImage, ViewSpec,
};

const BINS: u32 = 4;
const BG: [f32; 3] = [0.1, 0.1, 0.1];

fn new_renderer() -> Renderer {
    let backends = if std::env::var_os("WGPU_BACKEND").is_some() {
        BackendChoice::FromEnv
    } else {
        BackendChoice::Only(wgpu::Backends::VULKAN)
    };
    match GpuContext::with_backends(backends) {
        Ok(ctx) => Renderer::new(ctx),
        Err(e) => panic!("{e}"),
    }
}

fn renderer() -> &'static Renderer {
    static R: OnceLock<Renderer> = OnceLock::new();
    R.get_or_init(new_renderer)
}

fn file() -> (tempfile::TempDir, MdlodFile) {
    let (d, _p, f) = make_file(&fcc_frame(6), small_build(), &[]);
    (d, f)
}

/// An orthographic view of the whole block, `size` pixels square.
fn view(f: &MdlodFile, size: u32) -> Camera {
    camera_for(
        f,
        &ViewSpec::Orbit {
            azimuth_deg: 30.0,
            elevation_deg: 20.0,
            zoom: 1.0,
            projection: Projection::Orthographic,
        },
        size,
        size,
    )
    .unwrap()
}

/// The frame whose level 0 is `camera`'s pixels (no extra refinement for small spheres).
fn frame(camera: &Camera, size: u32) -> SmipFrame {
    SmipFrame::new(
        camera,
        size,
        size,
        1.0,
        0.0,
        BINS,
        Binning::default(),
        "fcc".into(),
    )
    .unwrap()
}

fn smip(pool_tiles: u32) -> Smip {
    Smip::new(
        renderer(),
        BINS,
        SmipConfig {
            pool_tiles,
            error_px: 0.0,
            ..Default::default()
        },
    )
    .unwrap()
}

fn lights() -> ShadeLights {
    ShadeLights::from(&Lighting::default())
}

/// Pixel size of `camera` in a `size`-pixel-high image.
fn pixel(camera: &Camera, size: u32) -> f32 {
    camera.view_height_at_target() / size as f32
}

fn shade(r: &Renderer, s: &Smip, camera: &Camera, w: u32, h: u32) -> RgbaImage {
    s.shade(r, camera, w, h, &lights(), BG).unwrap().0
}

/// Level-`level` texels of tiles `[x0, x1) × [y0, y1)` as one S-NDF image (all tiles
/// must have equal rays).
fn assemble(r: &Renderer, s: &Smip, level: u32, rect: [i32; 4]) -> Sndf {
    let [x0, x1, y0, y1] = rect;
    let (w, h) = ((x1 - x0) as u32 * TILE, (y1 - y0) as u32 * TILE);
    let b2 = (BINS * BINS) as usize;
    let mut hist = vec![[0f32; 4]; (w * h) as usize * b2];
    let mut rays = None;
    for ty in y0..y1 {
        for tx in x0..x1 {
            let tile = s
                .read_tile(
                    r,
                    TileKey {
                        level,
                        x: tx,
                        y: ty,
                    },
                )
                .unwrap()
                .expect("resident");
            let (data, r) = (tile.hist, tile.rays);
            assert!(rays.is_none() || rays == Some(r));
            rays = Some(r);
            for ly in 0..TILE {
                for lx in 0..TILE {
                    let (x, y) = ((tx - x0) as u32 * TILE + lx, (ty - y0) as u32 * TILE + ly);
                    let src = (ly * TILE + lx) as usize * b2;
                    let dst = (y * w + x) as usize * b2;
                    hist[dst..dst + b2].copy_from_slice(&data[src..src + b2]);
                }
            }
        }
    }
    Sndf {
        width: w,
        height: h,
        bins: BINS,
        binning: Binning::default(),
        rays: rays.unwrap(),
        hist,
        gpu_time: None,
        view: mdlod_render::sndf::TexelView::Axis,
    }
}

fn max_diff(a: &RgbaImage, b: &RgbaImage) -> u8 {
    assert_eq!((a.width, a.height), (b.width, b.height));
    a.data
        .iter()
        .zip(&b.data)
        .map(|(x, y)| x.abs_diff(*y))
        .max()
        .unwrap()
}

fn crop(img: &RgbaImage, x0: u32, y0: u32, w: u32, h: u32) -> RgbaImage {
    let mut out = RgbaImage::new(w, h);
    for y in 0..h {
        for x in 0..w {
            out.set_pixel(x, y, img.pixel(x0 + x, y0 + y));
        }
    }
    out
}

/// The composite pass at one level's texel centres equals host shading of the same
/// texels, and re-lighting it under another light touches no particle.
#[test]
fn the_smip_shades_like_the_host_and_relights_without_particles() {
    let (_d, f) = file();
    let size = 128;
    let camera = view(&f, size);
    let fr = frame(&camera, size);
    // A renderer of its own: its particle counter sees no other test.
    let own = new_renderer();
    let r = &own;
    let mut s = Smip::new(
        r,
        BINS,
        SmipConfig {
            pool_tiles: 16,
            error_px: 0.0,
            ..Default::default()
        },
    )
    .unwrap();
    let stats = s
        .prepare(r, &f, &fr, &camera, size, size, 4, &PointStyle::default())
        .unwrap();
    assert_eq!((stats.level, stats.blend), (0, 0.0));
    assert_eq!((stats.needed, stats.sampled, stats.rects), (4, 4, 1));
    assert!(stats.particle_samples > 0);
    let reference = assemble(r, &s, 0, [0, 2, 0, 2]);
    assert_eq!(reference.rays, 4);
    let gpu = shade(r, &s, &camera, size, size);
    let host = reference.shade_with(&lights(), BG);
    assert!(max_diff(&gpu, &host) <= 1, "{}", max_diff(&gpu, &host));
    // The data is in view: not all background.
    assert!(host.data.chunks(4).any(|p| p[0] > 60));

    let before = r.points_sampled();
    let other = ShadeLights::from(&Lighting {
        direction_view: glam::Vec3::new(0.9, -0.3, 0.3).normalize(),
        ..Lighting::default()
    });
    let (relit, _) = s.shade(r, &camera, size, size, &other, BG).unwrap();
    assert_eq!(r.points_sampled(), before, "re-lighting sampled particles");
    let host = reference.shade_with(&other, BG);
    assert!(max_diff(&relit, &host) <= 1);
    assert!(max_diff(&relit, &gpu) > 20, "the new light shows");
}

/// A pan reuses the tiles still in view and samples only the new ones; the overlap is
/// the same pixels, shifted; the whole equals a fresh S-MIP of the panned view.
#[test]
fn panning_samples_only_the_newly_visible_tiles() {
    let (_d, f) = file();
    let size = 128;
    let camera = view(&f, size);
    let fr = frame(&camera, size);
    let mut s = smip(16);
    let r = renderer();
    let style = PointStyle::default();
    let first = s
        .prepare(r, &f, &fr, &camera, size, size, 4, &style)
        .unwrap();
    let a = shade(r, &s, &camera, size, size);
    // Right by 40 pixels (not a whole tile): tiles x = 0..3 needed, x = 2 is new.
    let mut panned = camera.clone();
    panned.pan(40.0 * pixel(&camera, size), 0.0);
    let second = s
        .prepare(r, &f, &fr, &panned, size, size, 4, &style)
        .unwrap();
    assert_eq!(second.needed, 6);
    assert_eq!((second.reused, second.sampled), (4, 2));
    assert!(!second.invalidated);
    assert!(second.particle_samples < first.particle_samples);
    let b = shade(r, &s, &panned, size, size);
    assert!(max_diff(&crop(&a, 40, 0, 88, size), &crop(&b, 0, 0, 88, size)) <= 1);
    // A fresh cache of the same frame sampling the panned view at once agrees.
    let mut fresh = smip(16);
    fresh
        .prepare(r, &f, &fr, &panned, size, size, 4, &style)
        .unwrap();
    let c = shade(r, &fresh, &panned, size, size);
    let (bad, _) = compare(&c, &b, 2);
    assert!(bad <= (size * size / 200) as usize, "{bad} pixels differ");
    // Panning back needs nothing new.
    let back = s
        .prepare(r, &f, &fr, &camera, size, size, 4, &style)
        .unwrap();
    assert_eq!((back.sampled, back.particle_samples), (0, 0));
    assert!(
        shade(r, &s, &camera, size, size).data == a.data,
        "the same tiles shade alike"
    );
}

/// A level bias shows the view from a coarser level: a quarter of the tiles (with their
/// margin), the same picture blurred, and the coarser level made from the cached finer
/// tiles when they are there.
#[test]
fn a_level_bias_shows_a_coarser_level() {
    let (_d, f) = file();
    let size = 128;
    let camera = view(&f, size);
    let fr = frame(&camera, size);
    let r = renderer();
    let style = PointStyle::default();
    let mut s = smip(32);
    s.set_level_bias(1);
    let coarse = s
        .prepare(r, &f, &fr, &camera, size, size, 4, &style)
        .unwrap();
    assert_eq!((coarse.level, coarse.blend, coarse.needed), (1, 0.0, 1));
    let blurred = shade(r, &s, &camera, size, size);
    s.set_level_bias(0);
    s.prepare(r, &f, &fr, &camera, size, size, 4, &style)
        .unwrap();
    let sharp = shade(r, &s, &camera, size, size);
    // Close on the whole (a blurred copy), not equal.
    let mean = |a: &RgbaImage, b: &RgbaImage| {
        a.data
            .iter()
            .zip(&b.data)
            .map(|(x, y)| f64::from(x.abs_diff(*y)))
            .sum::<f64>()
            / a.data.len() as f64
    };
    let d = mean(&blurred, &sharp);
    assert!(d > 0.1 && d < 12.0, "mean difference {d}");
    // Back to the bias: the coarse tile is derived again from the four sharp ones.
    let mut fresh = smip(32);
    fresh
        .prepare(r, &f, &fr, &camera, size, size, 4, &style)
        .unwrap();
    fresh.set_level_bias(1);
    let st = fresh
        .prepare(r, &f, &fr, &camera, size, size, 4, &style)
        .unwrap();
    assert_eq!((st.downsampled, st.sampled), (1, 0));
}

/// Zooming out by two serves the coarser level by down-sampling cached tiles, exactly
/// the 2×2 sums of the host's down-sampling, with four times the rays.
#[test]
fn zooming_out_downsamples_cached_tiles_exactly() {
    let (_d, f) = file();
    let size = 128;
    let camera = view(&f, size);
    let fr = frame(&camera, size);
    let mut s = smip(32);
    let r = renderer();
    let style = PointStyle::default();
    s.prepare(r, &f, &fr, &camera, size, size, 3, &style)
        .unwrap();
    let mut out = camera.clone();
    out.zoom(0.5);
    let stats = s.prepare(r, &f, &fr, &out, size, size, 3, &style).unwrap();
    assert_eq!((stats.level, stats.blend), (1, 0.0));
    // Level-1 texels [-32, 96) in both axes: tiles -1..2, of which (0, 0) has all four
    // children cached.
    assert_eq!((stats.needed, stats.downsampled, stats.sampled), (9, 1, 8));
    let tile = s
        .read_tile(
            r,
            TileKey {
                level: 1,
                x: 0,
                y: 0,
            },
        )
        .unwrap()
        .unwrap();
    let (parent, rays) = (tile.hist, tile.rays);
    assert_eq!(rays, 12);
    let host = assemble(r, &s, 0, [0, 2, 0, 2]).downsample();
    assert_eq!(host.rays, rays);
    for (g, h) in parent.iter().zip(&host.hist) {
        for k in 0..4 {
            assert!(
                (g[k] - h[k]).abs() <= 1e-5 * h[k].abs().max(1.0),
                "{g:?} vs {h:?}"
            );
        }
    }
    let _ = shade(r, &s, &out, size, size);
}

/// Between two levels the composite blends them trilinearly: with the view's corner on
/// the S-MIP's origin, a zoom-out by 1.5 equals the host's trilinear shading of the same
/// level-0 texels (down-sampled on the host), and the coarser level comes from cached
/// tiles.
#[test]
fn fractional_zoom_is_trilinear_between_levels() {
    let (_d, f) = file();
    let size = 128;
    let camera = view(&f, size);
    let fr = frame(&camera, size);
    let mut s = smip(32);
    let r = renderer();
    let style = PointStyle::default();
    // Level 0 over 256×256 texels from the origin: the view and three pans of it.
    let p = pixel(&camera, size);
    for (dx, dy) in [(0.0, 0.0), (128.0, 0.0), (0.0, 128.0), (128.0, 128.0)] {
        let mut q = camera.clone();
        q.pan(dx * p, -dy * p);
        s.prepare(r, &f, &fr, &q, size, size, 2, &style).unwrap();
    }
    assert_eq!(s.resident(), 16);
    // The zoomed view: pixels 1.5 texels wide, corner on the origin.
    let mut z = camera.clone();
    z.zoom(1.0 / 1.5);
    let zp = pixel(&z, size);
    let shift = 64.0 * zp - 64.0 * p;
    z.pan(shift, -shift);
    let stats = s.prepare(r, &f, &fr, &z, size, size, 2, &style).unwrap();
    assert_eq!(stats.level, 0);
    assert!(
        (stats.blend - 1.5f32.log2()).abs() < 1e-3,
        "{}",
        stats.blend
    );
    // Level 1 (tiles 0..2) from the cached level 0, nothing sampled.
    assert_eq!((stats.downsampled, stats.sampled), (4, 0), "{stats:?}");
    let gpu = shade(r, &s, &z, size, size);
    let level0 = assemble(r, &s, 0, [0, 4, 0, 4]);
    // Both clamp at the edge of the texels they hold; compare from the second pixel on
    // all the same (the host clamps at its 256-texel image, the S-MIP at its tiles).
    let host = level0.shade_zoomed(&lights(), BG, 1.5);
    let (host, gpu) = (
        crop(&host, 1, 1, size - 1, size - 1),
        crop(&gpu, 1, 1, size - 1, size - 1),
    );
    let (bad, _) = compare(&host, &gpu, 2);
    assert!(bad <= (size * size / 500) as usize, "{bad} pixels differ");
}

/// A pool that holds exactly one view's tiles evicts on every pan, yet gives the same
/// images as a large pool; a view larger than the pool is an error naming its size.
#[test]
fn a_tiny_pool_evicts_and_still_gives_the_same_images() {
    let (_d, f) = file();
    let size = 128;
    let camera = view(&f, size);
    let fr = frame(&camera, size);
    let (mut tiny, mut large) = (smip(4), smip(32));
    let r = renderer();
    let style = PointStyle::default();
    let p = pixel(&camera, size);
    let mut evicted = 0;
    for dx in [0.0, 128.0, 64.0, 0.0] {
        let mut v = camera.clone();
        v.pan(dx * p, 0.0);
        evicted += tiny
            .prepare(r, &f, &fr, &v, size, size, 3, &style)
            .unwrap()
            .evicted;
        large
            .prepare(r, &f, &fr, &v, size, size, 3, &style)
            .unwrap();
        assert_eq!(tiny.resident(), 4);
        let (a, b) = (
            shade(r, &tiny, &v, size, size),
            shade(r, &large, &v, size, size),
        );
        // Tiles sampled again after eviction come from other rectangles (another
        // rasterization of the same texels): equal up to a few edge pixels.
        let (bad, _) = compare(&a, &b, 2);
        assert!(
            bad <= (size * size / 200) as usize,
            "pan {dx}: {bad} pixels differ"
        );
    }
    assert!(evicted >= 8, "{evicted}");
    // A zoom-out in a pool of ten: the nine coarser tiles, one down-sampled from four
    // cached children that are evicted once it is made.
    let mut ten = smip(10);
    ten.prepare(r, &f, &fr, &camera, size, size, 3, &style)
        .unwrap();
    let mut out = camera.clone();
    out.zoom(0.5);
    let st = ten
        .prepare(r, &f, &fr, &out, size, size, 3, &style)
        .unwrap();
    assert_eq!((st.needed, st.downsampled, st.sampled), (9, 1, 8));
    assert_eq!(ten.resident(), 10);
    let mut wide = camera.clone();
    wide.pan(10.0 * p, 10.0 * p);
    let e = tiny
        .prepare(r, &f, &fr, &wide, size, size, 3, &style)
        .unwrap_err()
        .to_string();
    assert!(e.contains("4 tiles"), "{e}");
}

/// Refinement continues each tile's sub-pixel sequence: 2 iterations then 3 equal 5 at
/// once. A new view direction or particle radius drops every tile.
#[test]
fn refinement_adds_up_and_a_new_direction_invalidates() {
    let (_d, f) = file();
    let size = 128;
    let camera = view(&f, size);
    let fr = frame(&camera, size);
    let r = renderer();
    let style = PointStyle::default();
    let (mut a, mut b) = (smip(16), smip(16));
    a.prepare(r, &f, &fr, &camera, size, size, 2, &style)
        .unwrap();
    let st = a.refine(r, &f, &camera, size, size, 3, 5, &style).unwrap();
    assert_eq!(st.sampled, 4);
    // At the target, nothing more is sampled.
    let st = a.refine(r, &f, &camera, size, size, 3, 5, &style).unwrap();
    assert_eq!((st.sampled, st.particle_samples), (0, 0));
    b.prepare(r, &f, &fr, &camera, size, size, 5, &style)
        .unwrap();
    let (ta, tb) = (
        assemble(r, &a, 0, [0, 2, 0, 2]),
        assemble(r, &b, 0, [0, 2, 0, 2]),
    );
    assert_eq!((ta.rays, tb.rays), (5, 5));
    for (x, y) in ta.hist.iter().zip(&tb.hist) {
        for k in 0..4 {
            assert!((x[k] - y[k]).abs() <= 1e-4 * y[k].abs().max(1.0));
        }
    }
    let mut turned = camera.clone();
    turned.orbit(20.0, 0.0);
    let turned_frame = frame(&turned, size);
    assert!(!fr.fits(&turned));
    let st = a
        .prepare(r, &f, &turned_frame, &turned, size, size, 2, &style)
        .unwrap();
    assert!(st.invalidated);
    assert_eq!((st.reused, st.sampled), (0, st.needed));
    // The old frame's view no longer fits.
    assert!(a.shade(r, &camera, size, size, &lights(), BG).is_err());
    // Another radius (the caller's content of the frame) drops every tile too.
    let mut scaled = turned_frame.clone();
    scaled.content = "fcc radius x1.5".into();
    let st = a
        .prepare(r, &f, &scaled, &turned, size, size, 2, &style)
        .unwrap();
    assert!(st.invalidated);
    assert_eq!(st.reused, 0);
}

/// The host's composite of exported tiles equals the GPU's (the CPU reference of the
/// composite pass), at a level's texel centres and between two levels; a `.sndf` file
/// of the tiles shades the same after a round trip, and a coarser level made on the
/// host from the stored tiles matches the GPU's down-sampling.
#[test]
fn exported_tiles_shade_on_the_host_as_on_the_gpu() {
    use mdlod_render::smip::shade_tiles;
    let (_d, f) = file();
    let size = 128;
    let camera = view(&f, size);
    let fr = frame(&camera, size);
    let r = renderer();
    let style = PointStyle::default();
    let mut s = smip(32);
    let mut zoomed = camera.clone();
    zoomed.zoom(1.0 / 1.3);
    for v in [&camera, &zoomed] {
        s.prepare(r, &f, &fr, v, size, size, 3, &style).unwrap();
        let gpu = shade(r, &s, v, size, size);
        let tiles = s.export(r, v, size, size).unwrap();
        let host = shade_tiles(&tiles, v, size, size, &lights(), BG).unwrap();
        let (bad, _) = compare(&gpu, &host, 1);
        assert!(bad <= 4, "{bad} pixels differ by more than 1");
        assert!(gpu.data.chunks(4).any(|p| p[0] > 60), "the data is in view");
    }
    // The file form: written, read, shaded without a GPU.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("tiles.sndf");
    let tiles = s.export(r, &camera, size, size).unwrap();
    let view_json = serde_json::to_value(mdlod_render::ViewFile::from_camera(&camera)).unwrap();
    tiles
        .to_data(size, size, view_json, None)
        .save(&path)
        .unwrap();
    let out = dir.path().join("lit.png");
    let lit = |level| {
        mdlod_render::shade_file(&path, &out, &lights(), BG, level).unwrap();
        RgbaImage::load_png(&out).unwrap()
    };
    let direct = shade(r, &s, &camera, size, size);
    let (bad, _) = compare(&direct, &lit(mdlod_render::ShadeLevel::Display), 1);
    assert!(bad <= 4, "{bad}");
    // Headers the tiles cannot serve: errors naming the file, no panic.
    let good = mdlod_format::sndf::SndfData::load(&path).unwrap();
    let bad = dir.path().join("bad.sndf");
    let mut huge = good.clone();
    (huge.header.width, huge.header.height) = (65536, 65536);
    let mut persp = good.clone();
    persp.header.view["projection"] = "perspective".into();
    for (d, want) in [(huge, "at most"), (persp, "frame")] {
        d.save(&bad).unwrap();
        let e =
            mdlod_render::shade_file(&bad, &out, &lights(), BG, mdlod_render::ShadeLevel::Display)
                .unwrap_err()
                .to_string();
        assert!(e.contains(want) && e.contains("bad.sndf"), "{e}");
    }
    // One level coarser: 64×64, from tiles the host down-samples, as the GPU would.
    let coarse = lit(mdlod_render::ShadeLevel::Level(1));
    assert_eq!((coarse.width, coarse.height), (64, 64));
    s.set_level_bias(1);
    s.prepare(r, &f, &fr, &camera, size, size, 3, &style)
        .unwrap();
    s.set_level_bias(0);
    // The same view in 64×64 pixels shows level 1, which the GPU down-sampled.
    let gpu_coarse = shade(r, &s, &camera, 64, 64);
    let (bad, _) = compare(&gpu_coarse, &coarse, 1);
    assert!(bad <= 8, "{bad}");
}
