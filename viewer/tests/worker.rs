//! The render thread without a window: progressive S-NDF refinement, re-lighting without
//! sampling, latest-wins requests, and screenshots that equal the headless renderer's.

use std::path::{Path, PathBuf};
use std::sync::mpsc::RecvTimeoutError;
use std::time::Duration;

use mdlod_preprocess::convert::{convert_frame, ConvertOptions};
use mdlod_preprocess::{Frame, NoProgress, SpeciesName};
use mdlod_render::{camera_for, render_image, BackendChoice, GpuContext, Renderer, RgbaImage};
use mdlod_viewer::state::{Action, FrameInfo, Mode, ViewerState};
use mdlod_viewer::worker::{GpuMemory, Reply, Request, Worker, SNDF_BATCH};

fn backends() -> BackendChoice {
    BackendChoice::FromEnv
}

/// A small FCC block with two species, converted by the real converter.
fn make_file(dir: &Path) -> PathBuf {
    make_block(dir, 5)
}

/// An FCC block of `n³` cells with two species.
fn make_block(dir: &Path, n: usize) -> PathBuf {
    block_file(
        dir,
        n,
        &["Cu", "Ag"],
        None,
        |i| u16::from(i % 7 == 0),
        "block.mdlod",
    )
}

/// An FCC block of `n³` cells whose atom `i` is of species `names[kind(i)]` (radius
/// `radius`, or the name's), converted by the real converter to `dir/file`.
fn block_file(
    dir: &Path,
    n: usize,
    names: &[&str],
    radius: Option<f32>,
    kind: impl Fn(usize) -> u16,
    file: &str,
) -> PathBuf {
    let positions = mdlod_datasets::fcc_block([n, n, n], 3.615);
    let species_index = (0..positions.len()).map(kind).collect();
    let species = names
        .iter()
        .map(|n| SpeciesName {
            name: n.to_string(),
            numeric_type: false,
            radius,
            ..Default::default()
        })
        .collect();
    let frame = Frame {
        positions,
        species_index,
        species,
        ..Default::default()
    };
    let path = dir.join(file);
    convert_frame(&frame, None, &path, &ConvertOptions::default(), &NoProgress).unwrap();
    path
}

fn state(path: &Path, size: [u32; 2]) -> ViewerState {
    let f = mdlod_format::MdlodFile::open(path).unwrap();
    let camera = camera_for(&f, &Default::default(), size[0], size[1]).unwrap();
    ViewerState::new(
        vec![FrameInfo {
            path: path.to_path_buf(),
            timestep: None,
        }],
        camera,
        mdlod_render::data_bounds(&f),
        size,
    )
}

/// The next image reply (errors fail the test).
fn next_image(w: &Worker) -> (u64, RgbaImage, u32, bool) {
    loop {
        match w.rx.recv_timeout(Duration::from_secs(120)) {
            Ok(Reply::Image {
                id,
                image,
                stats,
                refined,
                ..
            }) => return (id, image, stats.spp, refined),
            Ok(Reply::Error { message, .. }) => panic!("{message}"),
            Ok(Reply::Written { result, .. }) => result.unwrap(),
            Ok(Reply::Bounds { .. }) => {}
            Err(RecvTimeoutError::Timeout) => panic!("no image in 120 s"),
            Err(e) => panic!("{e}"),
        }
    }
}

fn render(w: &Worker, s: &ViewerState, id: u64) {
    w.send(Request::Render {
        id,
        path: s.frames[0].path.clone(),
        opts: s.render_options(s.size),
        shade: s.settings.shade_lights(),
        interactive: false,
        coarsen: 0,
        sphere_error_px: 1.0,
    });
}

/// The block of `make_block(dir, 3)` with label species (palette colours by their place
/// in the list), listed in `order`, in a file of its own.
fn make_labelled(dir: &Path, order: [&str; 2]) -> PathBuf {
    // Every seventh atom is NC3, wherever the list puts it.
    let nc3 = u16::from(order[0] != "NC3");
    block_file(
        dir,
        3,
        &order,
        Some(1.2),
        |i| if i % 7 == 0 { nc3 } else { 1 - nc3 },
        &format!("{}.mdlod", order.join("-")),
    )
}

/// A trajectory's frames keep each species' look, as `mdlod render DIR` draws them: two
/// frames that list the same beads in another order (each file's palette follows its
/// list) draw the same image; without the trajectory's looks they would swap colours.
#[test]
fn a_trajectory_keeps_its_species_colours_from_frame_to_frame() {
    let dir = tempfile::tempdir().unwrap();
    let a = make_labelled(dir.path(), ["NC3", "PO4"]);
    let b = make_labelled(dir.path(), ["PO4", "NC3"]);
    let frames: Vec<FrameInfo> = [&a, &b]
        .iter()
        .map(|p| FrameInfo {
            path: p.to_path_buf(),
            timestep: None,
        })
        .collect();
    let looks = mdlod_viewer::trajectory_looks(&frames);
    let names: Vec<&str> = looks.iter().map(|s| s.name.as_str()).collect();
    assert_eq!(names, ["NC3", "PO4"]);
    let s = state(&a, [48, 36]);
    let draw = |w: &Worker, path: &Path, id: u64| {
        w.send(Request::Render {
            id,
            path: path.to_path_buf(),
            opts: s.render_options(s.size),
            shade: s.settings.shade_lights(),
            interactive: false,
            coarsen: 0,
            sphere_error_px: 1.0,
        });
        let (got, image, _, _) = next_image(w);
        assert_eq!(got, id);
        image
    };
    let w = Worker::start(backends(), GpuMemory::Direct, looks, || {}).unwrap();
    let (first, second) = (draw(&w, &a, 1), draw(&w, &b, 2));
    assert_eq!(first.data, second.data);
    // Each file alone draws its own palette: the frames differ.
    let plain = Worker::start(backends(), GpuMemory::Direct, vec![], || {}).unwrap();
    assert_ne!(draw(&plain, &a, 1).data, draw(&plain, &b, 2).data);
}

#[test]
fn sndfs_refine_while_still_and_relight_without_sampling() {
    let dir = tempfile::tempdir().unwrap();
    let path = make_file(dir.path());
    let mut s = state(&path, [64, 48]);
    s.apply(&Action::Mode { mode: Mode::Sndf });
    s.settings.sndf_iterations = 3 * SNDF_BATCH;
    let w = Worker::start(backends(), GpuMemory::Direct, vec![], || {}).unwrap();
    render(&w, &s, 1);
    // Refinement goes on by itself, batch after batch, until the target.
    let mut spps = vec![];
    let refined = loop {
        let (id, image, spp, refined) = next_image(&w);
        assert_eq!(id, 1);
        spps.push(spp);
        if refined {
            break image;
        }
    };
    assert_eq!(spps, vec![SNDF_BATCH, 2 * SNDF_BATCH, 3 * SNDF_BATCH]);
    let sampled = w.points_sampled();
    assert!(sampled > 0);
    // The same view under another light: a new image at once, no particle sampled.
    s.apply(&Action::Light {
        index: 0,
        direction: [1.0, 0.0, 0.2],
    });
    render(&w, &s, 2);
    let (id, relit, spp, done) = next_image(&w);
    assert_eq!((id, spp, done), (2, 3 * SNDF_BATCH, true));
    assert_eq!(w.points_sampled(), sampled, "re-lighting sampled particles");
    assert_ne!(relit.data, refined.data);
    // Re-lit equals sampling afresh under that light, through the headless path (the
    // same batches).
    let out = dir.path().join("shot.png");
    w.send(Request::Screenshot {
        path: path.clone(),
        opts: s.render_options(s.size),
        shade: s.settings.shade_lights(),
        out: out.clone(),
    });
    match w.rx.recv_timeout(Duration::from_secs(120)).unwrap() {
        Reply::Written { result, .. } => result.unwrap(),
        _ => panic!("expected the screenshot"),
    }
    // The window's S-NDFs stay on the GPU and are shaded there; the screenshot's are
    // shaded on the host: equal to rounding.
    let shot = RgbaImage::load_png(&out).unwrap();
    let worst = shot
        .data
        .iter()
        .zip(&relit.data)
        .map(|(a, b)| a.abs_diff(*b))
        .max()
        .unwrap();
    assert!(
        worst <= 1,
        "the screenshot differs from the window by {worst}"
    );
    // A moved camera starts over.
    s.apply(&Action::Orbit { dx: 40.0, dy: 0.0 });
    render(&w, &s, 3);
    let (id, _, spp, _) = next_image(&w);
    assert_eq!((id, spp), (3, SNDF_BATCH));
    assert!(w.points_sampled() > sampled);
}

#[test]
fn the_newest_render_request_wins_and_frames_match_the_headless_renderer() {
    let dir = tempfile::tempdir().unwrap();
    let path = make_file(dir.path());
    let mut s = state(&path, [80, 60]);
    let w = Worker::start(backends(), GpuMemory::Direct, vec![], || {}).unwrap();
    // Three requests at once: only the last is drawn.
    for (id, dx) in [(1, 10.0), (2, 20.0), (3, 30.0)] {
        s.apply(&Action::Orbit { dx, dy: 0.0 });
        render(&w, &s, id);
    }
    let (id, image, _, refined) = next_image(&w);
    assert_eq!((id, refined), (3, true));
    assert!(matches!(
        w.rx.recv_timeout(Duration::from_millis(300)),
        Err(RecvTimeoutError::Timeout)
    ));
    let renderer = Renderer::new(GpuContext::with_backends(backends()).unwrap());
    let f = mdlod_format::MdlodFile::open(&path).unwrap();
    let (headless, _) = render_image(&renderer, &f, &s.render_options([80, 60])).unwrap();
    assert_eq!(image.data, headless.data);
    // A missing file is an error naming it, and the thread goes on.
    w.send(Request::Render {
        id: 4,
        path: dir.path().join("missing.mdlod"),
        opts: s.render_options([8, 8]),
        shade: s.settings.shade_lights(),
        interactive: false,
        coarsen: 0,
        sphere_error_px: 1.0,
    });
    match w.rx.recv_timeout(Duration::from_secs(60)).unwrap() {
        Reply::Error { id, message } => {
            assert_eq!(id, 4);
            assert!(message.contains("missing.mdlod"), "{message}")
        }
        _ => panic!("expected an error"),
    }
    render(&w, &s, 5);
    assert_eq!(next_image(&w).0, 5);
    // An S-MIP pool keeps 2×2 bins at least (one bin is no normal distribution): a pool
    // too large for them holds fewer tiles.
    use mdlod_viewer::worker::fitting_pool;
    let (b, tiles) = fitting_pool(&renderer, 1 << 20, 8);
    assert_eq!(b, 2);
    assert!((1..1 << 20).contains(&tiles), "{tiles}");
    assert_eq!(fitting_pool(&renderer, 4, 8), (8, 4));
    // S-NDF bins shrink to what one buffer of the adapter holds.
    use mdlod_viewer::worker::fitting_bins;
    assert_eq!(fitting_bins(&renderer, 16, 16, 8), 8);
    let b = fitting_bins(&renderer, 8192, 8192, 8);
    let limits = renderer.ctx.device.limits();
    assert!(b < 8);
    assert!(
        b == 1
            || 8192u64 * 8192 * u64::from(b * b) * 16
                <= limits
                    .max_storage_buffer_binding_size
                    .min(limits.max_buffer_size)
    );
}

/// With a GPU pool, frames stream in every mode but S-NDFs: the first image comes from
/// what is resident, later ones refine as pages arrive, and the last equals the direct
/// render.
#[test]
fn streamed_frames_refine_to_the_direct_image() {
    use mdlod_viewer::state::Mode;
    let dir = tempfile::tempdir().unwrap();
    let path = make_file(dir.path());
    let mut s = state(&path, [80, 60]);
    s.apply(&Action::Orbit { dx: 25.0, dy: 10.0 });
    let renderer = Renderer::new(GpuContext::with_backends(backends()).unwrap());
    let f = mdlod_format::MdlodFile::open(&path).unwrap();
    let w = Worker::start(backends(), GpuMemory::Pool(64 << 20), vec![], || {}).unwrap();
    for (id, mode) in [(1, Mode::Standard), (2, Mode::Splat), (3, Mode::Iso)] {
        s.settings.mode = mode;
        render(&w, &s, id);
        let mut frames = 0;
        let last = loop {
            match w.rx.recv_timeout(Duration::from_secs(120)).unwrap() {
                Reply::Image {
                    id: got,
                    image,
                    stats,
                    refined,
                    ..
                } => {
                    assert_eq!(got, id);
                    frames += 1;
                    let (resident, capacity, _) = stats.streaming.expect("a streamed frame");
                    assert!(resident <= capacity);
                    if refined {
                        break image;
                    }
                }
                Reply::Error { message, .. } => panic!("{message}"),
                Reply::Written { .. } => panic!("nothing was asked to be written"),
                Reply::Bounds { .. } => {}
            }
        };
        if mode == Mode::Iso {
            // Packed like the splats (by flux), so their pool serves it, full already.
            assert_eq!(frames, 1, "{mode:?} reuses the splats' pages");
        } else {
            // Packed differently from the mode before: a new pool, from the top node.
            assert!(
                frames >= 2,
                "{mode:?}: the first frame had nothing resident yet"
            );
        }
        let (direct, _) = render_image(&renderer, &f, &s.render_options([80, 60])).unwrap();
        assert!(
            last.data == direct.data,
            "{mode:?}: differs from the direct render"
        );
    }
}

/// Orthographic S-NDF views come from the S-MIP: a pan samples only the tiles that come
/// into view, a pan while dragging shows at once (one iteration on the new tiles),
/// re-lighting samples no particle, and an orbit while dragging is a sphere preview.
#[test]
fn orthographic_sndf_views_pan_over_cached_smip_tiles() {
    let dir = tempfile::tempdir().unwrap();
    // Large enough that a column of tiles culls most of it.
    let path = make_block(dir.path(), 12);
    let mut s = state(&path, [128, 96]);
    s.apply(&Action::Projection { orthographic: true });
    // Close in, so that the data fills the view and what pans in.
    s.apply(&Action::Zoom { factor: 3.0 });
    s.apply(&Action::Mode { mode: Mode::Sndf });
    s.settings.sndf_iterations = 2 * SNDF_BATCH;
    let w = Worker::start(backends(), GpuMemory::Direct, vec![], || {}).unwrap();
    let until_refined = |id: u64| -> (RgbaImage, Vec<u32>) {
        let mut spps = vec![];
        loop {
            let (got, image, spp, refined) = next_image(&w);
            assert_eq!(got, id);
            spps.push(spp);
            if refined {
                return (image, spps);
            }
        }
    };
    render(&w, &s, 1);
    let (first, spps) = until_refined(1);
    assert_eq!(spps, vec![SNDF_BATCH, 2 * SNDF_BATCH]);
    let view_cost = w.points_sampled();
    assert!(view_cost > 0);
    // A drag: the image comes at once from the cached tiles plus one iteration of the
    // column that came into view.
    s.apply(&Action::Pan { dx: -70.0, dy: 0.0 });
    w.send(Request::Render {
        id: 2,
        path: path.clone(),
        opts: s.interactive_options(s.size, 1.0),
        shade: s.settings.shade_lights(),
        interactive: true,
        coarsen: 0,
        sphere_error_px: 1.0,
    });
    let (id, moving, spp, refined) = next_image(&w);
    assert_eq!((id, spp, refined), (2, 1, false));
    assert_ne!(moving.data, first.data);
    // Dragging on with slow frames: a level coarser (the preview's texels are two
    // pixels wide), still at once.
    s.apply(&Action::Pan { dx: -6.0, dy: 0.0 });
    w.send(Request::Render {
        id: 20,
        path: path.clone(),
        opts: s.interactive_options(s.size, 1.0),
        shade: s.settings.shade_lights(),
        interactive: true,
        coarsen: 1,
        sphere_error_px: 1.0,
    });
    let (id, coarse, _, refined) = next_image(&w);
    assert_eq!((id, refined), (20, false));
    assert_eq!((coarse.width, coarse.height), (128, 96));
    s.apply(&Action::Pan { dx: 6.0, dy: 0.0 });
    // Released: the new tiles refine to the target.
    render(&w, &s, 3);
    let (panned, _) = until_refined(3);
    let pan_cost = w.points_sampled() - view_cost;
    assert!(
        pan_cost > 0 && pan_cost < view_cost,
        "a pan sampled {pan_cost} particle samples, the whole view {view_cost}"
    );
    // The pixels still in view did not change: the image moved by 70 pixels.
    for y in 0..96 {
        for x in 0..58 {
            let (a, b) = (first.pixel(x + 70, y), panned.pixel(x, y));
            assert!(
                a.iter().zip(b).all(|(p, q)| p.abs_diff(q) <= 1),
                "({x}, {y}): {a:?} vs {b:?}"
            );
        }
    }
    // Saved S-NDFs are the view's S-MIP tiles; shaded without a GPU they give the
    // picture in the window.
    let saved = dir.path().join("tiles.sndf");
    w.send(Request::SaveSndf { out: saved.clone() });
    match w.rx.recv_timeout(Duration::from_secs(60)).unwrap() {
        Reply::Written { result, .. } => result.unwrap(),
        _ => panic!("expected the saved file"),
    }
    let lit = dir.path().join("tiles.png");
    mdlod_render::shade_file(
        &saved,
        &lit,
        &s.settings.shade_lights(),
        s.render_options(s.size).background,
        mdlod_render::ShadeLevel::Display,
    )
    .unwrap();
    let lit = RgbaImage::load_png(&lit).unwrap();
    let differ = lit
        .data
        .iter()
        .zip(&panned.data)
        .filter(|(a, b)| a.abs_diff(**b) > 1)
        .count();
    assert!(
        differ <= 16,
        "{differ} channel values differ from the window's"
    );
    // Another light: no particle sampled.
    let before = w.points_sampled();
    s.apply(&Action::Light {
        index: 0,
        direction: [1.0, 0.0, 0.2],
    });
    render(&w, &s, 4);
    let (relit, _) = until_refined(4);
    assert_eq!(w.points_sampled(), before);
    assert_ne!(relit.data, panned.data);
    // An orbit while dragging leaves the S-MIP's frame: a one-sample sphere preview.
    s.apply(&Action::Orbit { dx: 30.0, dy: 0.0 });
    w.send(Request::Render {
        id: 5,
        path: path.clone(),
        opts: s.interactive_options(s.size, 1.0),
        shade: s.settings.shade_lights(),
        interactive: true,
        coarsen: 0,
        sphere_error_px: 1.0,
    });
    let (id, _, spp, refined) = next_image(&w);
    assert_eq!((id, spp, refined), (5, 1, false));
    // Released: a new S-MIP for the new direction.
    render(&w, &s, 6);
    let (_, spps) = until_refined(6);
    assert_eq!(spps, vec![SNDF_BATCH, 2 * SNDF_BATCH]);
}

#[test]
fn zooming_in_past_the_smip_level_0_samples_a_finer_level() {
    let dir = tempfile::tempdir().unwrap();
    let path = make_file(dir.path());
    let mut s = state(&path, [64, 48]);
    s.apply(&Action::Projection { orthographic: true });
    s.apply(&Action::Mode { mode: Mode::Sndf });
    s.settings.sndf_iterations = SNDF_BATCH;
    let until_refined = |w: &Worker, id: u64| -> RgbaImage {
        loop {
            let (got, image, _, refined) = next_image(w);
            assert_eq!(got, id);
            if refined {
                return image;
            }
        }
    };
    let w = Worker::start(backends(), GpuMemory::Direct, vec![], || {}).unwrap();
    render(&w, &s, 1);
    until_refined(&w, 1);
    // Zoomed in: the S-MIP begun at the wider view must not show its level 0 enlarged.
    s.apply(&Action::Zoom { factor: 4.0 });
    render(&w, &s, 2);
    let zoomed = until_refined(&w, 2);
    let fresh = Worker::start(backends(), GpuMemory::Direct, vec![], || {}).unwrap();
    render(&fresh, &s, 1);
    let direct = until_refined(&fresh, 1);
    let differ = zoomed
        .data
        .iter()
        .zip(&direct.data)
        .filter(|(a, b)| a.abs_diff(**b) > 1)
        .count();
    assert!(
        differ <= 16,
        "{differ} channel values differ from a fresh view's"
    );
}

/// A render thread drawing a long frame (an S-NDF screenshot of many seconds on a
/// software device) of `path` into `dir/slow.png`, and that file's path.
fn drawing_a_long_frame(dir: &Path, path: &Path) -> (Worker, PathBuf) {
    let mut s = state(path, [64, 48]);
    s.apply(&Action::Mode { mode: Mode::Sndf });
    s.settings.sndf_iterations = 64;
    let w = Worker::start(backends(), GpuMemory::Direct, vec![], || {}).unwrap();
    let out = dir.join("slow.png");
    w.send(Request::Screenshot {
        path: path.to_path_buf(),
        opts: s.render_options([1024, 768]),
        shade: s.settings.shade_lights(),
        out: out.clone(),
    });
    std::thread::sleep(Duration::from_millis(50));
    (w, out)
}

#[test]
fn an_abandoned_render_thread_is_not_waited_for() {
    let dir = tempfile::tempdir().unwrap();
    let path = make_file(dir.path());
    let (mut w, out) = drawing_a_long_frame(dir.path(), &path);
    // A script timed out: the window closes without waiting for it.
    w.abandon();
    let t0 = std::time::Instant::now();
    drop(w);
    assert!(t0.elapsed() < Duration::from_millis(500));
    assert!(!out.exists(), "the drop waited for the frame");
}

/// The next reply within `ms` milliseconds, if any.
fn reply_within(w: &Worker, ms: u64) -> Option<Reply> {
    match w.rx.recv_timeout(Duration::from_millis(ms)) {
        Ok(r) => Some(r),
        Err(RecvTimeoutError::Timeout) => None,
        Err(e) => panic!("{e}"),
    }
}

/// The next image: id, whether a preview, whether refined, the cut's screen error.
fn next_frame(w: &Worker) -> (u64, bool, bool, f32) {
    loop {
        match reply_within(w, 120_000).expect("no reply in 120 s") {
            Reply::Image {
                id,
                interactive,
                refined,
                stats,
                ..
            } => return (id, interactive, refined, stats.error_px),
            Reply::Error { message, .. } => panic!("{message}"),
            Reply::Written { .. } => panic!("nothing was asked to be written"),
            Reply::Bounds { .. } => {}
        }
    }
}

/// No image comes any more (of an older view refining on, say).
fn quiet(w: &Worker) {
    if let Some(r) = reply_within(w, 700) {
        match r {
            Reply::Image { id, .. } => panic!("an image of request {id} came after the last"),
            Reply::Error { id, message } => panic!("request {id}: {message}"),
            _ => panic!("an unexpected reply"),
        }
    }
}

/// A request ends whatever an older one left refining: no image of an old view follows
/// the new one (S-NDF batches after a switch to the standard mode, S-MIP tiles after an
/// orbit's sphere preview), and the orbit's preview is drawn at the preview's error.
#[test]
fn a_new_request_ends_the_refinement_of_an_older_view() {
    let dir = tempfile::tempdir().unwrap();
    let path = make_file(dir.path());
    let mut s = state(&path, [64, 48]);
    let w = Worker::start(backends(), GpuMemory::Direct, vec![], || {}).unwrap();
    s.apply(&Action::Mode { mode: Mode::Sndf });
    // Far more rays than the test waits for.
    s.settings.sndf_iterations = 4096;
    render(&w, &s, 1);
    // The render thread reports the bounds of the file it opened first.
    match reply_within(&w, 120_000).expect("a reply") {
        Reply::Bounds {
            path: p,
            bounds,
            boxes,
        } => {
            assert_eq!(p, path);
            // What `mdlod render` fits: the drawn spheres' bounds and the clusters.
            let f = mdlod_format::MdlodFile::open(&path).unwrap();
            assert_eq!((bounds, boxes), mdlod_viewer::framing(&f));
            assert_eq!(bounds, mdlod_render::data_bounds(&f));
        }
        _ => panic!("expected the bounds first"),
    }
    assert_eq!(next_frame(&w).0, 1);
    s.apply(&Action::Mode {
        mode: Mode::Standard,
    });
    render(&w, &s, 2);
    loop {
        let (id, _, refined, _) = next_frame(&w);
        if id == 2 {
            assert!(refined);
            break;
        }
        assert_eq!(id, 1, "a batch of the S-NDF view already under way");
    }
    quiet(&w);
    // An orthographic S-NDF view refining tile by tile, then an orbit's sphere preview.
    s.apply(&Action::Mode { mode: Mode::Sndf });
    s.apply(&Action::Projection { orthographic: true });
    render(&w, &s, 3);
    assert_eq!(next_frame(&w).0, 3);
    s.apply(&Action::Orbit { dx: 40.0, dy: 0.0 });
    w.send(Request::Render {
        id: 4,
        path: path.clone(),
        opts: s.interactive_options(s.size, 100.0),
        shade: s.settings.shade_lights(),
        interactive: true,
        coarsen: 0,
        sphere_error_px: s.sphere_preview_error(100.0),
    });
    loop {
        let (id, interactive, refined, error_px) = next_frame(&w);
        if id == 4 {
            assert!(interactive && !refined);
            // Clusters drawn as one sphere (at the settled 1 px: only particles).
            assert!(error_px > 1.0, "the orbit's preview at {error_px} px");
            break;
        }
        assert_eq!(id, 3, "a batch of the S-MIP view already under way");
    }
    quiet(&w);
}

/// With a GPU pool: streamed previews say they are previews (the window adapts their
/// screen error), and a released S-NDF drag is not followed by the preview's spheres.
#[test]
fn streamed_previews_are_previews_and_end_with_the_drag() {
    let dir = tempfile::tempdir().unwrap();
    let path = make_file(dir.path());
    let mut s = state(&path, [80, 60]);
    s.apply(&Action::Mode { mode: Mode::Sndf });
    s.settings.sndf_iterations = 2 * SNDF_BATCH;
    let w = Worker::start(backends(), GpuMemory::Pool(64 << 20), vec![], || {}).unwrap();
    // Dragging a perspective S-NDF view: streamed sphere previews.
    s.apply(&Action::Orbit { dx: 25.0, dy: 10.0 });
    w.send(Request::Render {
        id: 1,
        path: path.clone(),
        opts: s.interactive_options(s.size, 1.0),
        shade: s.settings.shade_lights(),
        interactive: true,
        coarsen: 0,
        sphere_error_px: 1.0,
    });
    let (id, interactive, refined, _) = next_frame(&w);
    assert_eq!((id, interactive, refined), (1, true, false));
    // Released: the S-NDF view, and nothing of the preview after it.
    render(&w, &s, 2);
    let mut seen_new = false;
    loop {
        let (id, interactive, refined, _) = next_frame(&w);
        if id == 2 {
            seen_new = true;
            if refined {
                break;
            }
        } else {
            assert!(!seen_new, "a streamed preview came after the S-NDF image");
            assert_eq!((id, interactive), (1, true));
        }
    }
    quiet(&w);
}

/// A file keeping two attributes: the panel's choice of the second colours by it, the
/// image the headless renderer gives with `--attribute` (and differs from the first's).
#[test]
fn the_viewer_colours_by_the_attribute_chosen() {
    let dir = tempfile::tempdir().unwrap();
    let positions = mdlod_datasets::fcc_block([4, 4, 4], 3.615);
    let n = positions.len();
    let frame = Frame {
        species_index: vec![0; n],
        species: vec![SpeciesName {
            name: "Cu".into(),
            ..Default::default()
        }],
        attribute: Some(mdlod_preprocess::Attribute {
            name: "x".into(),
            values: positions.iter().map(|p| p[0]).collect(),
        }),
        positions: positions.clone(),
        ..Default::default()
    };
    let path = dir.path().join("two.mdlod");
    mdlod_preprocess::convert::convert_frame_with(
        &frame,
        &[mdlod_preprocess::Attribute {
            name: "z".into(),
            values: positions.iter().map(|p| p[2]).collect(),
        }],
        None,
        &path,
        &ConvertOptions::default(),
        &NoProgress,
    )
    .unwrap();
    let mut s = state(&path, [64, 48]);
    s.attributes = vec!["x".into(), "z".into()];
    s.apply(&Action::ColourMap {
        map: Some(mdlod_render::ColourMap::Viridis),
    });
    let w = Worker::start(backends(), GpuMemory::Direct, vec![], || {}).unwrap();
    render(&w, &s, 1);
    let (_, by_x, _, _) = next_image(&w);
    s.apply(&Action::Attribute {
        name: Some("z".into()),
    });
    render(&w, &s, 2);
    let (id, by_z, _, _) = next_image(&w);
    assert_eq!(id, 2);
    assert_ne!(by_x.data, by_z.data);
    let renderer = Renderer::new(GpuContext::with_backends(backends()).unwrap());
    let opts = s.render_options([64, 48]);
    assert_eq!(opts.style.attribute.as_deref(), Some("z"));
    let f = mdlod_render::open_styled(&path, &opts.style).unwrap();
    let (headless, _) = render_image(&renderer, &f, &opts).unwrap();
    assert_eq!(by_z.data, headless.data);
}

/// `image`'s colour channels averaged over `k`×`k` blocks.
fn shrink(image: &RgbaImage, k: u32) -> Vec<f64> {
    let (w, h) = (image.width / k, image.height / k);
    let mut out = vec![0.0; (w * h * 3) as usize];
    for y in 0..h * k {
        for x in 0..w * k {
            for c in 0..3 {
                let i = ((y * image.width + x) * 4 + c) as usize;
                out[(((y / k) * w + x / k) * 3 + c) as usize] +=
                    f64::from(image.data[i]) / f64::from(k * k);
            }
        }
    }
    out
}

/// Mean absolute difference per channel (0-255).
fn difference(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).sum::<f64>() / a.len() as f64
}

/// A preview coarsened to 8 px or more is drawn a quarter of the window's size on each
/// side, and shows what a frame of the window's size at that error shows, shrunk.
#[test]
fn coarse_previews_are_drawn_smaller_and_show_the_full_size_picture() {
    let dir = tempfile::tempdir().unwrap();
    let path = make_block(dir.path(), 8);
    let s = state(&path, [160, 128]);
    let w = Worker::start(backends(), GpuMemory::Direct, vec![], || {}).unwrap();
    let preview = |s: &ViewerState, id| {
        w.send(Request::Render {
            id,
            path: path.clone(),
            opts: s.interactive_options(s.size, 8.0),
            shade: s.settings.shade_lights(),
            interactive: true,
            coarsen: 0,
            sphere_error_px: 8.0,
        });
        next_image(&w).1
    };
    let image = preview(&s, 1);
    assert_eq!((image.width, image.height), (40, 32));
    let renderer = Renderer::new(GpuContext::with_backends(backends()).unwrap());
    let f = mdlod_format::MdlodFile::open(&path).unwrap();
    let mut full = s.render_options(s.size);
    full.error_px = 8.0;
    let (big, _) = render_image(&renderer, &f, &full).unwrap();
    // Compared in blocks of 16×16 of the window's pixels, where the preview's sampling of
    // spheres a pixel wide averages out.
    let big = shrink(&big, 16);
    let same = difference(&shrink(&image, 4), &big);
    // The metric tells views apart: the preview of an orbited view against it.
    let mut turned = s.clone();
    turned.apply(&Action::Orbit { dx: 60.0, dy: 30.0 });
    let other = difference(&shrink(&preview(&turned, 2), 4), &big);
    assert!(same < 6.0 && other > 3.0 * same, "{same} against {other}");
}

/// A closing window's render thread ends once its frame is drawn (and its device is
/// dropped before the process exits), within the wait it is given; a frame that takes
/// longer is not waited for.
#[test]
fn a_closing_window_waits_for_an_idle_render_thread_but_not_a_long_frame() {
    let dir = tempfile::tempdir().unwrap();
    let path = make_file(dir.path());
    let s = state(&path, [64, 48]);
    let mut w = Worker::start(backends(), GpuMemory::Direct, vec![], || {}).unwrap();
    render(&w, &s, 1);
    assert!(w.finish_within(Duration::from_secs(60)));
    let t0 = std::time::Instant::now();
    drop(w);
    assert!(t0.elapsed() < Duration::from_millis(100));
    // A long frame in progress: the wait ends at its limit.
    let (mut w, out) = drawing_a_long_frame(dir.path(), &path);
    let t0 = std::time::Instant::now();
    assert!(!w.finish_within(Duration::from_millis(200)));
    drop(w);
    assert!(t0.elapsed() < Duration::from_millis(700));
    assert!(!out.exists(), "the close waited for the frame");
}

/// A signed attribute under a diverging map is shown over the range a still of the frame
/// shows, centred on 0, not over the frame's own range.
#[test]
fn a_diverging_map_is_centred_on_zero_as_a_still_centres_it() {
    let dir = tempfile::tempdir().unwrap();
    let positions = mdlod_datasets::fcc_block([4, 4, 4], 3.615);
    let n = positions.len();
    // Charges from -0.95 to +0.45: the frame's own range puts the map's middle at -0.25.
    let values = (0..n)
        .map(|i| -0.95 + 1.4 * i as f32 / (n - 1) as f32)
        .collect();
    let frame = Frame {
        positions,
        species_index: vec![0; n],
        species: vec![SpeciesName {
            name: "C".into(),
            ..Default::default()
        }],
        attribute: Some(mdlod_preprocess::frame::Attribute {
            name: "q".into(),
            values,
        }),
        ..Default::default()
    };
    let path = dir.path().join("q.mdlod");
    convert_frame(&frame, None, &path, &ConvertOptions::default(), &NoProgress).unwrap();
    let mut s = state(&path, [64, 48]);
    s.apply(&Action::ColourMap {
        map: Some(mdlod_render::ColourMap::CoolWarm),
    });
    let w = Worker::start(backends(), GpuMemory::Direct, vec![], || {}).unwrap();
    render(&w, &s, 1);
    let (_, image, _, _) = next_image(&w);
    let renderer = Renderer::new(GpuContext::with_backends(backends()).unwrap());
    let f = mdlod_format::MdlodFile::open(&path).unwrap();
    let mut centred = s.render_options(s.size);
    centred.style.attribute_range = Some([-0.95, 0.95]);
    let (still, _) = render_image(&renderer, &f, &centred).unwrap();
    assert_eq!(image.data, still.data);
    let (own_range, _) = render_image(&renderer, &f, &s.render_options(s.size)).unwrap();
    assert_ne!(image.data, own_range.data);
}

/// A trajectory's first view frames its first and its last frame together: a pour's
/// grains fall from the top of the box to a pile at its bottom, and a view of the first
/// frame alone cut the pile off (a single frame is framed alone).
#[test]
fn the_first_view_frames_a_trajectorys_first_and_last_frames() {
    let dir = tempfile::tempdir().unwrap();
    let frame_at = |z: f32, name: &str| {
        let positions: Vec<[f32; 3]> = (0..200)
            .map(|i| {
                [
                    (i % 10) as f32,
                    ((i / 10) % 10) as f32,
                    z + (i / 100) as f32,
                ]
            })
            .collect();
        let frame = Frame {
            species_index: vec![0; positions.len()],
            positions,
            species: vec![SpeciesName {
                name: "1".into(),
                numeric_type: true,
                ..Default::default()
            }],
            ..Default::default()
        };
        let path = dir.path().join(name);
        convert_frame(&frame, None, &path, &ConvertOptions::default(), &NoProgress).unwrap();
        FrameInfo {
            path,
            timestep: None,
        }
    };
    let frames = vec![
        frame_at(40.0, "a.mdlod"),
        frame_at(20.0, "b.mdlod"),
        frame_at(0.0, "c.mdlod"),
    ];
    let first = mdlod_format::MdlodFile::open(&frames[0].path).unwrap();
    let alone = mdlod_viewer::first_view_bounds(&first, &frames[..1]);
    assert!(alone.min.z > 39.0 && alone.max.z < 42.0, "{alone:?}");
    let both = mdlod_viewer::first_view_bounds(&first, &frames);
    assert!(both.min.z < 0.0 && both.max.z > 41.0, "{both:?}");
    assert_eq!((both.min.x, both.max.x), (alone.min.x, alone.max.x));
    // A last frame that does not open is left out.
    std::fs::write(&frames[2].path, b"not a file").unwrap();
    assert_eq!(mdlod_viewer::first_view_bounds(&first, &frames), alone);
}

/// A file's first view in the viewer is the camera `mdlod render` fits with default
/// options (it was the bounding box's fit, 17 % farther on a granular bed), and so is
/// `fit` once the render thread has reported the frame's framing.
#[test]
fn the_first_view_and_fit_are_those_render_fits() {
    let dir = tempfile::tempdir().unwrap();
    let path = make_file(dir.path());
    let frames = vec![FrameInfo {
        path: path.clone(),
        timestep: None,
    }];
    let f = mdlod_format::MdlodFile::open(&path).unwrap();
    let view = mdlod_render::ViewSpec::default().resolved(&f);
    let (w, h) = (320, 240);
    let (bounds, boxes) = mdlod_viewer::first_view_framing(&f, &frames);
    let first = mdlod_render::camera_for_framing(&bounds, &boxes, &view, w, h).unwrap();
    let rendered = camera_for(&f, &view, w, h).unwrap();
    assert_eq!(first, rendered);
    // `fit` after an orbit: render's fit from the new direction.
    let mut s = ViewerState::new(frames, first, bounds, [w, h]);
    s.set_frame_bounds(&path, bounds, boxes);
    s.apply(&Action::Orbit { dx: 60.0, dy: 0.0 });
    s.apply(&Action::Zoom { factor: 3.0 });
    s.apply(&Action::Fit);
    let turned = mdlod_render::ViewSpec::Orbit {
        azimuth_deg: s.camera.azimuth_deg,
        elevation_deg: s.camera.elevation_deg,
        zoom: 1.0,
        projection: s.camera.projection,
    };
    let want = camera_for(&f, &turned, w, h).unwrap();
    assert!(
        (s.camera.distance - want.distance).abs() <= 1e-4 * want.distance
            && (s.camera.target - want.target).length() <= 1e-4 * want.distance,
        "{:?} against {want:?}",
        s.camera
    );
}
