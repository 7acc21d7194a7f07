//! The render thread: it owns the GPU renderer and the open files, so that loading,
//! traversal and drawing never block the window. The window sends [`Request`]s and
//! shows the [`Reply`] images as they come.
//!
//! - Render requests are latest-wins: when several wait, only the newest is drawn.
//! - In S-NDF mode a still view refines by itself: after each batch of iterations, if
//!   no new request waits, the thread samples the next batch (continuing the sub-pixel
//!   sequence) into the S-NDFs, which stay on the GPU, shades them there and sends the
//!   image, until the target count. A request for the same view with other lights only
//!   re-shades the S-NDFs: no particle is sampled (see [`Worker::points_sampled`]).
//! - Orthographic S-NDF views go through a virtual S-MIP ([`mdlod_render::smip`]) that
//!   outlives the view: a pan or zoom samples only the tiles that come into view (one
//!   iteration while the user drags, then refined tile by tile), and zooming out
//!   down-samples the cached tiles. Zooming in past the S-MIP's level 0 starts a new
//!   S-MIP with a finer level 0 once the view is still (dragging previews the old level
//!   0 enlarged). An orbit starts a new S-MIP: while dragging, those frames are sphere
//!   previews, as in perspective.
//! - Only the newest request's view refines: a request ends what an older one left
//!   refining (S-NDF batches, S-MIP tiles, streamed pages), so no image of an older view
//!   follows it.
//! - Screenshots and saved S-NDFs run in order between frames; of the prefetches only
//!   the newest runs, after the render request.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::mpsc::{channel, Receiver, Sender, TryRecvError};
use std::sync::Arc;
use std::time::{Duration, Instant};

use mdlod_format::MdlodFile;
use mdlod_render::camera::Bounds;
use mdlod_render::renderer::ResidentSndf;
use mdlod_render::smip::{Smip, SmipConfig, SmipFrame};
use mdlod_render::sndf::{ShadeLights, Sndf, SndfSettings};
use mdlod_render::{
    render_image, render_image_keeping, traverse, BackendChoice, ColourMap, GpuContext, KeptCut,
    RenderError, RenderMode, RenderOptions, Renderer, RgbaImage, ViewFile,
};

/// Iterations in each progressive S-NDF batch.
pub const SNDF_BATCH: u32 = 4;

/// What the window asks of the render thread.
pub enum Request {
    /// Draw `opts` of the file at `path`. `shade` is the S-NDF shading (S-NDF mode);
    /// `interactive` frames are quick previews while the view moves.
    Render {
        id: u64,
        path: PathBuf,
        opts: RenderOptions,
        shade: ShadeLights,
        interactive: bool,
        /// While the user drags an orthographic S-NDF view: show it this many S-MIP
        /// levels coarser than its pixels (a quarter of the texels per level).
        coarsen: u32,
        /// The screen error of the sphere preview drawn instead of an orthographic S-NDF
        /// view whose drag left the S-MIP's frame (an orbit); `opts.error_px` stays the
        /// S-MIP's own.
        sphere_error_px: f32,
    },
    /// Open a file ahead of need (the next timestep).
    Prefetch(PathBuf),
    /// Render `opts` of `path` through the headless path and write a PNG.
    Screenshot {
        path: PathBuf,
        opts: RenderOptions,
        shade: ShadeLights,
        out: PathBuf,
    },
    /// Write the current S-NDFs (with their camera) as a `.sndf` file.
    SaveSndf {
        out: PathBuf,
    },
    Quit,
}

/// Numbers for the status panel.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FrameStats {
    /// Wall time of the frame on the render thread (traversal, drawing, readback).
    pub frame_ms: f32,
    pub gpu_ms: Option<f32>,
    /// Samples per pixel reached (S-NDF rays so far, or the supersampling count).
    pub spp: u32,
    pub particles: u64,
    pub representatives: u64,
    pub error_px: f32,
    pub gpu_bytes: u64,
    pub adapter: String,
    /// Streaming: pages resident, pages the pool holds, page loads in flight.
    pub streaming: Option<(usize, usize, usize)>,
    /// S-NDF mode: bins per axis sampled (fewer than asked when the adapter's buffers
    /// are too small for the view).
    pub bins: Option<u32>,
}

/// What the render thread sends back.
pub enum Reply {
    Image {
        id: u64,
        image: RgbaImage,
        stats: FrameStats,
        interactive: bool,
        /// The image is as refined as this request asks (all S-NDF iterations, the
        /// supersampling, the final cut).
        refined: bool,
    },
    /// The bounds of the data of `path` and the boxes that frame it, as `mdlod render`
    /// fits them ([`mdlod_render::fit_for`], [`mdlod_render::framing_boxes`]), sent when a
    /// render request opens another file (fitting and zooming use the shown frame's).
    Bounds {
        path: PathBuf,
        bounds: Bounds,
        boxes: Vec<mdlod_render::Framed>,
    },
    /// A screenshot or S-NDF file was written (or not).
    Written {
        out: PathBuf,
        result: Result<(), String>,
    },
    /// Render request `id` failed: no more images of it come.
    Error { id: u64, message: String },
}

/// The S-NDFs of one view, refined batch by batch on the GPU (they stay there: each
/// batch adds its rays in place, shading reads them there, and only the image comes
/// back).
struct Progressive {
    id: u64,
    path: PathBuf,
    file: Arc<MdlodFile>,
    /// The request's options (lights aside, what was sampled).
    opts: RenderOptions,
    shade: ShadeLights,
    camera: mdlod_render::Camera,
    draw: mdlod_render::DrawList,
    settings: SndfSettings,
    resident: Option<ResidentSndf>,
    target: u32,
}

impl Progressive {
    fn rays(&self) -> u32 {
        self.resident.as_ref().map_or(0, |s| s.rays)
    }
}

/// An orthographic S-NDF view shown from the S-MIP, refined tile by tile.
struct TiledView {
    id: u64,
    path: PathBuf,
    file: Arc<MdlodFile>,
    opts: RenderOptions,
    shade: ShadeLights,
    camera: mdlod_render::Camera,
    /// Rays per texel wanted, and the fewest the view's tiles have.
    target: u32,
    rays: u32,
    /// Spheres per iteration of the last sampling.
    points: u64,
    /// S-MIP levels coarser than the view's own (while dragging).
    coarsen: u32,
}

/// The window's handle on the render thread.
pub struct Worker {
    tx: Sender<Request>,
    pub rx: Receiver<Reply>,
    thread: Option<std::thread::JoinHandle<()>>,
    sampled: Arc<std::sync::atomic::AtomicU64>,
}

impl Worker {
    /// Starts the render thread, which opens its own GPU device (on `backends`) and
    /// keeps it: the device is created, used and dropped on that one thread, which some
    /// drivers need. Returns the device's error when there is none. `wake` is called
    /// after each reply (the window repaints).
    pub fn start(
        backends: BackendChoice,
        gpu_memory: GpuMemory,
        looks: Vec<mdlod_format::meta::Species>,
        wake: impl Fn() + Send + 'static,
    ) -> Result<Worker, RenderError> {
        let (tx, requests) = channel();
        let (replies, rx) = channel();
        let (ready_tx, ready) = channel();
        let sampled = Arc::new(std::sync::atomic::AtomicU64::new(0));
        let counter = sampled.clone();
        let thread = std::thread::Builder::new()
            .name("mdlod render".into())
            .spawn(move || {
                let ctx = match GpuContext::with_backends(backends) {
                    Ok(c) => {
                        let _ = ready_tx.send(Ok(()));
                        c
                    }
                    Err(e) => {
                        let _ = ready_tx.send(Err(e));
                        return;
                    }
                };
                let renderer = Renderer::new(ctx);
                let mut state = Thread {
                    renderer: &renderer,
                    gpu_memory,
                    stream: None,
                    files: FileCache::new(FILES_KEPT),
                    attribute: None,
                    bounds_sent: None,
                    cut: None,
                    range: None,
                    looks,
                    progressive: None,
                    smip: None,
                    tiled: None,
                    replies,
                    wake: Box::new(wake),
                    counter,
                };
                state.run(requests);
            })
            .map_err(|e| {
                RenderError::InvalidOptions(format!("cannot start the render thread: {e}"))
            })?;
        let started = ready.recv().unwrap_or_else(|_| {
            Err(RenderError::InvalidOptions(
                "the render thread ended before opening a device".into(),
            ))
        });
        if let Err(e) = started {
            let _ = thread.join();
            return Err(e);
        }
        Ok(Worker {
            tx,
            rx,
            thread: Some(thread),
            sampled,
        })
    }

    /// The process is about to end (a script timed out): dropping the handle then asks
    /// the thread to quit but does not wait for the frame it is drawing (one renderer
    /// call, which cannot be interrupted, may take many seconds); the thread ends with
    /// the process.
    pub fn abandon(&mut self) {
        // A dropped join handle detaches the thread: nothing is left to wait for.
        self.thread = None;
    }

    /// The window is closing: asks the thread to quit and waits at most `limit` for it
    /// to end, and abandons it ([`Worker::abandon`]) past that. A thread that ends in
    /// time has dropped its device before the process runs its exit handlers: a driver
    /// still unloading on the render thread while they ran crashed the process at exit
    /// (lavapipe: 1 exit in 30 was a segmentation fault). Returns whether it ended.
    pub fn finish_within(&mut self, limit: Duration) -> bool {
        let _ = self.tx.send(Request::Quit);
        let t0 = Instant::now();
        while self.thread.as_ref().is_some_and(|t| !t.is_finished()) {
            if t0.elapsed() >= limit {
                self.abandon();
                return false;
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
        true
    }

    pub fn send(&self, r: Request) {
        // The thread only ends on Quit or when the window is gone.
        let _ = self.tx.send(r);
    }

    /// Particle samples drawn so far by the render thread (points × rays).
    pub fn points_sampled(&self) -> u64 {
        self.sampled.load(std::sync::atomic::Ordering::Relaxed)
    }
}

impl Drop for Worker {
    fn drop(&mut self) {
        let _ = self.tx.send(Request::Quit);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// When sphere frames stream node data through a fixed GPU pool instead of uploading
/// each frame's cut.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GpuMemory {
    /// Upload each frame's cut (within the sphere budget).
    Direct,
    /// A pool of this many bytes, least recently used pages evicted.
    Pool(u64),
    /// A pool of this many bytes for files larger than the pool, else direct.
    Auto(u64),
}

/// A streamed view still filling in.
struct Streaming<'r> {
    path: PathBuf,
    renderer: mdlod_render::StreamingRenderer<'r>,
    /// The request being refined: id, options, whether it is a preview.
    pending: Option<(u64, RenderOptions, bool)>,
}

/// A file, a look (log scale, colour map) and the colour range chosen for them.
type KeptRange = (Arc<MdlodFile>, (bool, ColourMap), Option<[f32; 2]>);

struct Thread<'r> {
    renderer: &'r Renderer,
    gpu_memory: GpuMemory,
    stream: Option<Streaming<'r>>,
    /// Open files with the attribute each was opened for.
    files: FileCache<(Option<String>, Arc<MdlodFile>)>,
    /// The attribute the last render coloured by: a prefetch opens the next frame so.
    attribute: Option<String>,
    /// The file whose bounds the window was sent last.
    bounds_sent: Option<PathBuf>,
    /// The last direct frame's cut, and the file it is of: a frame of the same view under
    /// other lights or colours draws it again without a traversal.
    cut: Option<(Arc<MdlodFile>, KeptCut)>,
    /// The colour range chosen for a file and a look (log scale, map): see
    /// `with_default_range`.
    range: Option<KeptRange>,
    /// A trajectory's species looks ([`mdlod_render::style::trajectory_looks`]; empty
    /// for one file): each frame's file chose its colours alone.
    looks: Vec<mdlod_format::meta::Species>,
    progressive: Option<Progressive>,
    /// The S-MIP cache of orthographic S-NDF views, and the view it shows.
    smip: Option<Smip>,
    tiled: Option<TiledView>,
    replies: Sender<Reply>,
    wake: Box<dyn Fn() + Send>,
    counter: Arc<std::sync::atomic::AtomicU64>,
}

impl<'r> Thread<'r> {
    fn reply(&self, r: Reply) {
        self.counter.store(
            self.renderer.points_sampled(),
            std::sync::atomic::Ordering::Relaxed,
        );
        let _ = self.replies.send(r);
        (self.wake)();
    }

    /// The file at `path` with `attribute` in the first's place (`None`: as it is), kept
    /// open for the next request; another attribute opens it again.
    fn file(&mut self, path: &Path, attribute: Option<&str>) -> Result<Arc<MdlodFile>, String> {
        if let Some((a, f)) = self.files.get(path) {
            if a.as_deref() == attribute {
                return Ok(f);
            }
        }
        let style = mdlod_render::PointStyle {
            attribute: attribute.map(str::to_string),
            ..Default::default()
        };
        // (The reader's errors name the file.)
        let f = mdlod_render::open_styled(path, &style).map_err(|e| e.to_string())?;
        // (Once per file: the cache keeps it open for the next frame.)
        mdlod_render::check_before_drawing(&f).map_err(|e| e.to_string())?;
        let f = Arc::new(f);
        self.files.insert(
            path.to_path_buf(),
            (attribute.map(str::to_string), f.clone()),
        );
        Ok(f)
    }

    /// Colours by the attribute over the range `mdlod render` shows a file's values over
    /// where none is set ([`mdlod_render::default_range_of`]): a diverging map centred on
    /// 0, a log scale from the smallest positive value (a signed charge took cool-warm's
    /// white at the middle of its range, not at 0). Kept per file and look: a log
    /// scale's floor reads up to 2^20 values, which every preview frame would repeat.
    fn with_default_range(&mut self, opts: &mut RenderOptions, file: &Arc<MdlodFile>) {
        // A trajectory's frame keeps its species' looks over the frames, as `mdlod render
        // DIR` draws them (their colours flickered from timestep to timestep).
        if !self.looks.is_empty() {
            opts.style.species = mdlod_render::style::frame_styles(
                &file.metadata().species,
                &self.looks,
                &opts.style.species,
                opts.style.colour_map.is_some(),
                opts.style.palette,
            );
        }
        let Some(map) = opts.style.colour_map else {
            return;
        };
        if opts.style.attribute_range.is_some() {
            return;
        }
        let look = (opts.style.log_scale, map);
        let range = match &self.range {
            Some((f, l, r)) if Arc::ptr_eq(f, file) && *l == look => *r,
            _ => {
                let r =
                    mdlod_render::default_range_of(file, &opts.style, true, false).map(|(r, _)| r);
                self.range = Some((file.clone(), look, r));
                r
            }
        };
        opts.style.attribute_range = range;
    }

    fn run(&mut self, requests: Receiver<Request>) {
        let mut pending: Vec<Request> = Vec::new();
        loop {
            // Block only when there is nothing to refine.
            if pending.is_empty() {
                let refining = self
                    .progressive
                    .as_ref()
                    .is_some_and(|p| p.rays() < p.target)
                    || self.tiled.as_ref().is_some_and(|t| t.rays < t.target)
                    || self.stream.as_ref().is_some_and(|s| s.pending.is_some());
                if refining {
                    match requests.try_recv() {
                        Ok(r) => pending.push(r),
                        Err(TryRecvError::Empty) => {
                            if self.stream.as_ref().is_some_and(|s| s.pending.is_some()) {
                                self.stream_step();
                            } else if self.tiled.is_some() {
                                self.tiled_step();
                            } else {
                                self.refine_step();
                            }
                            continue;
                        }
                        Err(TryRecvError::Disconnected) => return,
                    }
                } else {
                    match requests.recv() {
                        Ok(r) => pending.push(r),
                        Err(_) => return,
                    }
                }
            }
            pending.extend(requests.try_iter());
            for r in plan(std::mem::take(&mut pending)) {
                match r {
                    Request::Quit => return,
                    Request::Render {
                        id,
                        path,
                        opts,
                        shade,
                        interactive,
                        coarsen,
                        sphere_error_px,
                    } => self.render(
                        id,
                        &path,
                        opts,
                        shade,
                        Preview {
                            interactive,
                            coarsen,
                            sphere_error_px,
                        },
                    ),
                    Request::Prefetch(path) => {
                        let attribute = self.attribute.clone();
                        let _ = self.file(&path, attribute.as_deref());
                    }
                    Request::Screenshot {
                        path,
                        opts,
                        shade,
                        out,
                    } => {
                        let result = self.screenshot(&path, &opts, &shade, &out);
                        self.reply(Reply::Written { out, result });
                    }
                    Request::SaveSndf { out } if self.tiled.is_some() => {
                        let result = self.save_tiled(&out);
                        self.reply(Reply::Written { out, result });
                    }
                    Request::SaveSndf { out } => {
                        let result = match &self.progressive {
                            Some(Progressive {
                                resident: Some(resident),
                                camera,
                                path,
                                ..
                            }) => self
                                .renderer
                                .read_resident(resident)
                                .map_err(|e| e.to_string())
                                .and_then(|sndf| save_sndf(&sndf, camera, path, &out)),
                            _ => Err("no S-NDFs sampled yet: switch to the S-NDF mode".into()),
                        };
                        self.reply(Reply::Written { out, result });
                    }
                }
            }
        }
    }

    fn render(
        &mut self,
        id: u64,
        path: &Path,
        opts: RenderOptions,
        shade: ShadeLights,
        preview: Preview,
    ) {
        let t0 = Instant::now();
        let Preview {
            interactive,
            coarsen,
            sphere_error_px,
        } = preview;
        // Only this request refines from now on: whatever an older one left would keep
        // sending images of its view. The S-MIP and the streaming pool are caches and
        // stay; the progressive S-NDFs stay only for a re-shade of the same view.
        self.tiled = None;
        let mut previous = self.progressive.take();
        if let Some(s) = self.stream.as_mut() {
            s.pending = None;
        }
        let error = |e: &dyn std::fmt::Display| Reply::Error {
            id,
            message: format!("{}: {e}", path.display()),
        };
        self.attribute = opts.style.attribute.clone();
        let file = match self.file(path, opts.style.attribute.as_deref()) {
            Ok(f) => f,
            Err(message) => return self.reply(Reply::Error { id, message }),
        };
        if self.bounds_sent.as_deref() != Some(path) {
            self.bounds_sent = Some(path.to_path_buf());
            let (bounds, boxes) = crate::framing(&file);
            self.reply(Reply::Bounds {
                path: path.to_path_buf(),
                bounds,
                boxes,
            });
        }
        let mut opts = opts;
        self.with_default_range(&mut opts, &file);
        if let RenderMode::Sndf { .. } = opts.mode {
            let camera = match mdlod_render::camera_for(&file, &opts.view, opts.width, opts.height)
            {
                Ok(c) => c,
                Err(e) => return self.reply(error(&e)),
            };
            if camera.projection == mdlod_render::Projection::Orthographic {
                // The perspective view's S-NDFs are freed before the S-MIP's pool is made
                // (an orthographic view never re-shades them).
                drop(previous.take());
                let coarsen = if interactive { coarsen } else { 0 };
                match self.tiled_render(
                    id,
                    path,
                    &file,
                    &opts,
                    &shade,
                    camera,
                    coarsen,
                    interactive,
                ) {
                    Ok(true) => return,
                    // A preview of a new direction: spheres, below, at the preview's
                    // error (the S-MIP's is the settled one).
                    Ok(false) => sphere_fallback(&mut opts, sphere_error_px),
                    Err(e) => {
                        self.tiled = None;
                        return self.reply(error(&e));
                    }
                }
            }
        }
        if let RenderMode::Sndf { iterations, .. } = opts.mode {
            if let Some(mut p) =
                previous.filter(|p| p.path == path && same_sampling(&p.opts, &opts))
            {
                // The same view under other lights: re-shade, sample nothing.
                p.id = id;
                p.target = iterations;
                p.shade = shade;
                p.opts = opts;
                self.progressive = Some(p);
                self.show_progress(t0);
                return;
            }
            match sndf_setup(self.renderer, &file, &opts) {
                Ok((camera, draw, settings)) => {
                    self.progressive = Some(Progressive {
                        id,
                        path: path.to_path_buf(),
                        file,
                        opts,
                        shade,
                        camera,
                        draw,
                        settings,
                        resident: None,
                        target: iterations,
                    });
                    self.refine_step();
                }
                Err(e) => self.reply(error(&e)),
            }
            return;
        }
        drop(previous);
        if !matches!(opts.mode, RenderMode::Sndf { .. }) {
            let pool = match self.gpu_memory {
                GpuMemory::Direct => None,
                GpuMemory::Pool(b) => Some(b),
                GpuMemory::Auto(b) => std::fs::metadata(path)
                    .is_ok_and(|m| m.len() > b)
                    .then_some(b),
            };
            if let Some(pool) = pool {
                return self.stream_start(id, path, file, opts, interactive, pool);
            }
        }
        self.stream = None;
        let (cut_of, kept) = self
            .cut
            .get_or_insert_with(|| (file.clone(), KeptCut::default()));
        if !Arc::ptr_eq(cut_of, &file) {
            *cut_of = file.clone();
            kept.clear();
        }
        match render_image_keeping(self.renderer, &file, &opts, kept) {
            Ok((image, report)) => {
                let stats = FrameStats {
                    frame_ms: t0.elapsed().as_secs_f32() * 1e3,
                    gpu_ms: report.gpu_time.map(|d| d.as_secs_f32() * 1e3),
                    spp: report.spp,
                    particles: report.particles_drawn,
                    representatives: report.nodes_drawn,
                    error_px: report.error_px,
                    gpu_bytes: report.gpu_data_bytes + report.gpu_target_bytes,
                    adapter: report.adapter.clone(),
                    streaming: None,
                    bins: None,
                };
                self.reply(Reply::Image {
                    id,
                    image,
                    stats,
                    interactive,
                    refined: !interactive,
                });
            }
            Err(e) => self.reply(error(&e)),
        }
    }

    /// Draws a streamed view: what is resident now, asking for the rest; later steps
    /// draw again as pages arrive, until the view is complete.
    fn stream_start(
        &mut self,
        id: u64,
        path: &Path,
        file: Arc<MdlodFile>,
        opts: RenderOptions,
        interactive: bool,
        pool: u64,
    ) {
        // A pool holds its pages packed for one mode's passes and one look.
        let (style, look) = mdlod_render::page_style(&opts);
        if self
            .stream
            .as_ref()
            .is_none_or(|s| s.path != path || s.renderer.style() != (style, &look))
        {
            self.stream = None;
            match mdlod_render::StreamingRenderer::with_style(
                self.renderer,
                file,
                pool,
                mdlod_render::streaming::PAGE_POINTS,
                style,
                &look,
            ) {
                Ok(r) => {
                    self.stream = Some(Streaming {
                        path: path.to_path_buf(),
                        renderer: r,
                        pending: None,
                    })
                }
                Err(e) => {
                    return self.reply(Reply::Error {
                        id,
                        message: format!("{}: {e}", path.display()),
                    })
                }
            }
        }
        if let Some(s) = self.stream.as_mut() {
            s.pending = Some((id, opts, interactive));
        }
        self.stream_step();
    }

    /// One streamed frame of the pending view.
    fn stream_step(&mut self) {
        let Some(s) = self.stream.as_mut() else {
            return;
        };
        let Some((id, opts, interactive)) = s.pending.clone() else {
            return;
        };
        if s.renderer.frames_drawn() > 0 {
            // Give the loader a moment when the last frame asked for pages.
            s.renderer
                .wait_for_loads(std::time::Duration::from_millis(50));
        }
        // The frame's own time (the wait is not the frame's: previews adapt to it).
        let t0 = Instant::now();
        match mdlod_render::render_stream_frame(self.renderer, &mut s.renderer, &opts) {
            Ok((image, report, stats)) => {
                let settled = stats.settled();
                if settled {
                    s.pending = None;
                }
                let stats = FrameStats {
                    frame_ms: t0.elapsed().as_secs_f32() * 1e3,
                    gpu_ms: report.gpu_time.map(|d| d.as_secs_f32() * 1e3),
                    spp: opts.spp,
                    particles: report.particles_drawn,
                    representatives: report.nodes_drawn,
                    error_px: report.error_px,
                    gpu_bytes: report.gpu_data_bytes + report.gpu_target_bytes,
                    adapter: report.adapter.clone(),
                    streaming: Some((stats.resident_pages, stats.capacity_pages, stats.pending)),
                    bins: None,
                };
                self.reply(Reply::Image {
                    id,
                    image,
                    stats,
                    interactive,
                    refined: settled && !interactive,
                });
            }
            Err(e) => {
                let path = s.path.display().to_string();
                self.stream = None;
                self.reply(Reply::Error {
                    id,
                    message: format!("{path}: {e}"),
                });
            }
        }
    }

    /// Shows an orthographic S-NDF view from the S-MIP: tiles already cached are reused,
    /// new ones sampled with one iteration while the user drags (else a batch). Returns
    /// false, doing nothing, for a drag that left the S-MIP's frame (an orbit): the
    /// caller draws a sphere preview instead.
    #[allow(clippy::too_many_arguments)]
    fn tiled_render(
        &mut self,
        id: u64,
        path: &Path,
        file: &Arc<MdlodFile>,
        opts: &RenderOptions,
        shade: &ShadeLights,
        camera: mdlod_render::Camera,
        coarsen: u32,
        interactive: bool,
    ) -> Result<bool, String> {
        let t0 = Instant::now();
        let RenderMode::Sndf {
            iterations,
            bins,
            binning,
        } = opts.mode
        else {
            return Ok(false);
        };
        let (w, h) = (opts.width, opts.height);
        // Room for the view's tiles at two levels, and as many again to pan back to.
        let want = 4 * (w.div_ceil(64) + 2) * (h.div_ceil(64) + 2);
        let (bins, pool_tiles) = fitting_pool(self.renderer, want, bins);
        if self.smip.as_ref().is_none_or(|s| {
            s.bins() != bins || s.capacity() != pool_tiles || s.config().error_px != opts.error_px
        }) {
            self.smip = None;
            self.smip = Some(
                Smip::new(
                    self.renderer,
                    bins,
                    SmipConfig {
                        pool_tiles,
                        error_px: opts.error_px,
                        ..Default::default()
                    },
                )
                .map_err(|e| e.to_string())?,
            );
        }
        let smip = self.smip.as_mut().expect("just made");
        smip.set_level_bias(coarsen);
        // What the tiles depend on besides the direction (the screen error is the
        // cache's own setting: a new one makes a new cache above).
        let content = format!("{} {:?} {}", path.display(), opts.style, binning.name());
        // A still view zoomed in past level 0 needs a finer frame: the S-MIP has no level
        // below 0, so it would show level 0 enlarged for good (a drag may preview it).
        let pixel = f64::from(camera.view_height_at_target()) / f64::from(h.max(1));
        let frame = match smip.frame() {
            Some(f)
                if f.fits(&camera)
                    && f.content == content
                    && f.bins == bins
                    && (interactive || !finer_than_level0(f, pixel)) =>
            {
                f.clone()
            }
            _ if interactive => return Ok(false),
            _ => SmipFrame::new(
                &camera,
                w,
                h,
                mdlod_render::smip::min_radius(file, &opts.style),
                1.0,
                bins,
                binning,
                content,
            )
            .map_err(|e| e.to_string())?,
        };
        let first = if interactive { 1 } else { SNDF_BATCH };
        let stats = smip
            .prepare(
                self.renderer,
                file,
                &frame,
                &camera,
                w,
                h,
                first.min(iterations.max(1)),
                &opts.style,
            )
            .map_err(|e| e.to_string())?;
        let rays = smip.view_rays(&camera, w, h).map_err(|e| e.to_string())?;
        self.tiled = Some(TiledView {
            id,
            path: path.to_path_buf(),
            file: file.clone(),
            opts: opts.clone(),
            shade: shade.clone(),
            camera,
            target: if interactive { 0 } else { iterations },
            rays,
            points: stats.points,
            coarsen,
        });
        self.show_tiled(t0, interactive);
        Ok(true)
    }

    /// Adds the next batch of rays to the S-MIP view's tiles and shows it.
    fn tiled_step(&mut self) {
        let t0 = Instant::now();
        let (Some(t), Some(smip)) = (self.tiled.as_mut(), self.smip.as_mut()) else {
            self.tiled = None;
            return;
        };
        let (w, h) = (t.opts.width, t.opts.height);
        smip.set_level_bias(t.coarsen);
        let refined = smip
            .refine(
                self.renderer,
                &t.file,
                &t.camera,
                w,
                h,
                SNDF_BATCH,
                t.target,
                &t.opts.style,
            )
            .and_then(|stats| {
                t.points = t.points.max(stats.points);
                smip.view_rays(&t.camera, w, h)
            });
        match refined {
            Ok(rays) => {
                // A view that cannot progress (nothing left to sample) is done.
                t.rays = if rays > t.rays { rays } else { t.target };
                self.show_tiled(t0, false);
            }
            Err(e) => {
                let (id, path) = (t.id, t.path.display().to_string());
                self.tiled = None;
                self.reply(Reply::Error {
                    id,
                    message: format!("{path}: {e}"),
                });
            }
        }
    }

    /// Shades the S-MIP view under its lights and sends the image.
    fn show_tiled(&mut self, t0: Instant, interactive: bool) {
        let (Some(t), Some(smip)) = (self.tiled.as_ref(), self.smip.as_mut()) else {
            return;
        };
        smip.set_level_bias(t.coarsen);
        let (w, h) = (t.opts.width, t.opts.height);
        match smip.shade(self.renderer, &t.camera, w, h, &t.shade, t.opts.background) {
            Ok((image, gpu)) => {
                let stats = FrameStats {
                    frame_ms: t0.elapsed().as_secs_f32() * 1e3,
                    gpu_ms: gpu.map(|d| d.as_secs_f32() * 1e3),
                    spp: t.rays,
                    particles: t.points,
                    representatives: 0,
                    error_px: t.opts.error_px,
                    gpu_bytes: smip.pool_bytes(),
                    adapter: self.renderer.ctx.adapter_name().to_string(),
                    streaming: None,
                    bins: Some(smip.bins()),
                };
                let reply = Reply::Image {
                    id: t.id,
                    image,
                    stats,
                    interactive,
                    refined: !interactive && t.rays >= t.target,
                };
                self.reply(reply);
            }
            Err(e) => {
                let (id, path) = (t.id, t.path.display().to_string());
                self.tiled = None;
                self.reply(Reply::Error {
                    id,
                    message: format!("{path}: {e}"),
                });
            }
        }
    }

    /// Saves the S-MIP tiles the view shows, with their frame and the view: the file
    /// `mdlod shade` lights into the picture in the window.
    fn save_tiled(&mut self, out: &Path) -> Result<(), String> {
        let (Some(t), Some(smip)) = (self.tiled.as_ref(), self.smip.as_mut()) else {
            return Err("no S-NDFs sampled yet: switch to the S-NDF mode".into());
        };
        let (w, h) = (t.opts.width, t.opts.height);
        smip.set_level_bias(t.coarsen);
        let tiles = smip
            .export(self.renderer, &t.camera, w, h)
            .map_err(|e| e.to_string())?;
        let view =
            serde_json::to_value(ViewFile::from_camera(&t.camera)).map_err(|e| e.to_string())?;
        tiles
            .to_data(w, h, view, Some(t.path.display().to_string()))
            .save(out)
            .map_err(|e| e.to_string())
    }

    /// Samples the next batch of the progressive S-NDFs and shows them.
    fn refine_step(&mut self) {
        let t0 = Instant::now();
        let Some(p) = self.progressive.as_mut() else {
            return;
        };
        let n = SNDF_BATCH.min(p.target.saturating_sub(p.rays())).max(1);
        let renderer = self.renderer;
        let batch = match &mut p.resident {
            Some(r) => Ok(r),
            None => renderer
                .resident_sndf(&p.file, &p.camera, &p.draw, &p.settings, &p.opts.style)
                .map(|r| p.resident.insert(r)),
        }
        .and_then(|r| renderer.refine_resident(r, n));
        match batch {
            Ok(_) => self.show_progress(t0),
            Err(e) => {
                let (id, path) = (p.id, p.path.display().to_string());
                self.progressive = None;
                self.reply(Reply::Error {
                    id,
                    message: format!("{path}: {e}"),
                });
            }
        }
    }

    /// Shades the progressive S-NDFs under their lights and sends the image.
    fn show_progress(&mut self, t0: Instant) {
        let Some(p) = self.progressive.as_ref() else {
            return;
        };
        let Some(resident) = &p.resident else {
            return;
        };
        let image = match self
            .renderer
            .shade_resident(resident, &p.shade, p.opts.background)
        {
            Ok((image, _)) => image,
            Err(e) => {
                let (id, path) = (p.id, p.path.display().to_string());
                self.progressive = None;
                return self.reply(Reply::Error {
                    id,
                    message: format!("{path}: {e}"),
                });
            }
        };
        let stats = FrameStats {
            frame_ms: t0.elapsed().as_secs_f32() * 1e3,
            gpu_ms: None,
            spp: resident.rays,
            particles: p.draw.particles,
            representatives: p.draw.representatives,
            error_px: p.draw.error_px,
            gpu_bytes: resident.gpu_bytes(),
            adapter: self.renderer.ctx.adapter_name().to_string(),
            streaming: None,
            bins: Some(resident.bins),
        };
        let reply = Reply::Image {
            id: p.id,
            image,
            stats,
            interactive: false,
            refined: resident.rays >= p.target,
        };
        self.reply(reply);
    }

    /// A screenshot through the headless path: the image `mdlod render` gives for the
    /// same options (S-NDFs sampled in the viewer's batches, shaded under its lights).
    fn screenshot(
        &mut self,
        path: &Path,
        opts: &RenderOptions,
        shade: &ShadeLights,
        out: &Path,
    ) -> Result<(), String> {
        let file = self.file(path, opts.style.attribute.as_deref())?;
        let mut opts = opts.clone();
        self.with_default_range(&mut opts, &file);
        let opts = &opts;
        let image = match opts.mode {
            RenderMode::Sndf { iterations, .. } => {
                let (sndf, _) = sample_progressively(self.renderer, &file, opts, iterations)?;
                sndf.shade_with(shade, opts.background)
            }
            _ => {
                render_image(self.renderer, &file, opts)
                    .map_err(|e| format!("{}: {e}", path.display()))?
                    .0
            }
        };
        image
            .save_png(out)
            .map_err(|e| format!("{}: {e}", out.display()))
    }
}

/// How a render request previews a moving view.
#[derive(Clone, Copy, Debug)]
struct Preview {
    interactive: bool,
    coarsen: u32,
    sphere_error_px: f32,
}

/// An orthographic S-NDF preview the S-MIP cannot show (an orbit) becomes a sphere
/// preview at the preview's screen error.
fn sphere_fallback(opts: &mut RenderOptions, sphere_error_px: f32) {
    opts.mode = RenderMode::Spheres;
    if sphere_error_px.is_finite() {
        opts.error_px = opts.error_px.max(sphere_error_px);
    }
}

/// The order a batch of waiting requests runs in: only the newest render request is
/// drawn (latest wins), screenshots and saved S-NDFs run in order, and only the newest
/// prefetch runs, last (after the frame to show, which the window waits for). With a
/// quit among them, nothing is drawn or prefetched.
fn plan(pending: Vec<Request>) -> Vec<Request> {
    if pending.iter().any(|r| matches!(r, Request::Quit)) {
        // The window is gone: no frame will be shown, and what is to be written is.
        return pending
            .into_iter()
            .filter(|r| !matches!(r, Request::Render { .. } | Request::Prefetch(_)))
            .collect();
    }
    let newest = pending
        .iter()
        .rposition(|r| matches!(r, Request::Render { .. }));
    let mut prefetch = None;
    let mut out = Vec::with_capacity(pending.len());
    for (i, r) in pending.into_iter().enumerate() {
        match r {
            Request::Render { .. } if Some(i) != newest => {}
            Request::Prefetch(_) => prefetch = Some(r),
            r => out.push(r),
        }
    }
    out.extend(prefetch);
    out
}

/// Files the render thread keeps open: the shown frame and a few neighbours.
const FILES_KEPT: usize = 4;

/// The open files, by path; the least recently used one is dropped for a new one when
/// the cache is full.
struct FileCache<T> {
    entries: HashMap<PathBuf, (T, u64)>,
    capacity: usize,
    clock: u64,
}

impl<T: Clone> FileCache<T> {
    fn new(capacity: usize) -> Self {
        FileCache {
            entries: HashMap::new(),
            capacity: capacity.max(1),
            clock: 0,
        }
    }

    fn get(&mut self, path: &Path) -> Option<T> {
        self.clock += 1;
        let clock = self.clock;
        self.entries.get_mut(path).map(|(v, used)| {
            *used = clock;
            v.clone()
        })
    }

    fn insert(&mut self, path: PathBuf, value: T) {
        self.clock += 1;
        if !self.entries.contains_key(&path) && self.entries.len() >= self.capacity {
            let oldest = self
                .entries
                .iter()
                .min_by_key(|(_, (_, used))| *used)
                .map(|(p, _)| p.clone());
            if let Some(p) = oldest {
                self.entries.remove(&p);
            }
        }
        self.entries.insert(path, (value, self.clock));
    }
}

/// Whether two S-NDF requests sample the same thing (they may differ in lights).
fn same_sampling(a: &RenderOptions, b: &RenderOptions) -> bool {
    let strip = |o: &RenderOptions| {
        let mut o = o.clone();
        o.lighting = Default::default();
        o.background = [0.0; 3];
        if let RenderMode::Sndf { iterations, .. } = &mut o.mode {
            *iterations = 0;
        }
        o
    };
    strip(a) == strip(b)
}

/// Opens no window: the S-NDFs `iterations` rays deep of `opts`'s view of `file`,
/// sampled in batches of [`SNDF_BATCH`] exactly as the viewer refines (for tests and
/// screenshots).
pub fn sample_progressively(
    renderer: &Renderer,
    file: &MdlodFile,
    opts: &RenderOptions,
    iterations: u32,
) -> Result<(Sndf, mdlod_render::Camera), String> {
    let (camera, draw, settings) = sndf_setup(renderer, file, opts)?;
    let mut sndf: Option<Sndf> = None;
    let mut done = 0;
    while done < iterations {
        let n = SNDF_BATCH.min(iterations - done);
        let batch = renderer
            .sample_sndf_styled(
                file,
                &camera,
                &draw,
                &SndfSettings {
                    iterations: n,
                    ..settings
                },
                done,
                &opts.style,
            )
            .map_err(|e| e.to_string())?;
        match &mut sndf {
            None => sndf = Some(batch),
            Some(s) => {
                s.add(&batch);
            }
        }
        done += n;
    }
    sndf.map(|s| (s, camera))
        .ok_or_else(|| "no S-NDF iterations asked for".to_string())
}

fn sndf_setup(
    renderer: &Renderer,
    file: &MdlodFile,
    opts: &RenderOptions,
) -> Result<(mdlod_render::Camera, mdlod_render::DrawList, SndfSettings), String> {
    let RenderMode::Sndf { bins, binning, .. } = opts.mode else {
        return Err("not the S-NDF mode".into());
    };
    let bins = fitting_bins(renderer, opts.width, opts.height, bins);
    // The cut `render --mode sndf` draws (whole-pixel occlusion, none for styles that
    // change sizes).
    let (camera, traversal, _) =
        mdlod_render::frame_setup(file, opts).map_err(|e| e.to_string())?;
    let draw = traverse(&camera, file, &traversal);
    file.node_error().map_err(|e| e.to_string())?;
    Ok((
        camera,
        draw,
        SndfSettings {
            width: opts.width,
            height: opts.height,
            iterations: 0,
            bins,
            binning,
        },
    ))
}

/// The most bins per axis, at most `bins`, halving, whose histograms of a `width` ×
/// `height` view fit one buffer of the adapter (software drivers allow 128 MiB).
pub fn fitting_bins(renderer: &Renderer, width: u32, height: u32, bins: u32) -> u32 {
    let max = renderer.binding_bytes();
    let mut b = bins.max(1);
    while b > 1 && mdlod_render::sndf::sndf_buffer_bytes(width, height, b) > max {
        b /= 2;
    }
    b
}

/// The most bins per axis, at most `bins`, halving, but not below 2×2 (one bin holds no
/// normals to re-light: a large window's S-MIP was one flat colour), at which a pool of
/// `tiles` S-MIP tiles fits one buffer of the adapter, and the pool's size in tiles
/// (fewer when even 2×2 bins do not fit them all).
pub fn fitting_pool(renderer: &Renderer, tiles: u32, bins: u32) -> (u32, u32) {
    let max = renderer.binding_bytes();
    let tile = mdlod_render::sndf::tile_bytes;
    let mut b = bins.max(1);
    while b > 2 && u64::from(tiles) * tile(b) > max {
        b /= 2;
    }
    let fit = u32::try_from(max / tile(b)).unwrap_or(u32::MAX);
    (b, tiles.min(fit).max(1))
}

/// Whether pixels `pixel` world units wide are finer than `frame`'s level 0 (beyond
/// rounding): the S-MIP would show them its level 0 enlarged.
pub fn finer_than_level0(frame: &SmipFrame, pixel: f64) -> bool {
    pixel < frame.texel0 * (1.0 - 1e-3)
}

/// Saves S-NDFs with their camera.
pub fn save_sndf(
    sndf: &Sndf,
    camera: &mdlod_render::Camera,
    source: &Path,
    out: &Path,
) -> Result<(), String> {
    let view = serde_json::to_value(ViewFile::from_camera(camera)).map_err(|e| e.to_string())?;
    sndf.to_data(view, Some(source.display().to_string()))
        .save(out)
        .map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn render(id: u64) -> Request {
        Request::Render {
            id,
            path: "a.mdlod".into(),
            opts: RenderOptions::default(),
            shade: crate::state::Settings::default().shade_lights(),
            interactive: false,
            coarsen: 0,
            sphere_error_px: 1.0,
        }
    }

    /// What `plan` runs, as text.
    fn names(requests: &[Request]) -> Vec<String> {
        requests
            .iter()
            .map(|r| match r {
                Request::Render { id, .. } => format!("render {id}"),
                Request::Prefetch(p) => format!("prefetch {}", p.display()),
                Request::Screenshot { out, .. } => format!("screenshot {}", out.display()),
                Request::SaveSndf { out } => format!("save {}", out.display()),
                Request::Quit => "quit".into(),
            })
            .collect()
    }

    #[test]
    fn only_the_newest_prefetch_runs_and_after_the_frame_to_show() {
        let pending = vec![
            Request::Prefetch("1.mdlod".into()),
            render(1),
            Request::Prefetch("2.mdlod".into()),
            Request::SaveSndf {
                out: "a.sndf".into(),
            },
            Request::Prefetch("3.mdlod".into()),
            render(2),
        ];
        assert_eq!(
            names(&plan(pending)),
            ["save a.sndf", "render 2", "prefetch 3.mdlod"]
        );
        assert_eq!(
            names(&plan(vec![Request::Prefetch("1.mdlod".into())])),
            ["prefetch 1.mdlod"]
        );
        // A closing window draws nothing more, but what it asked to be written is.
        let pending = vec![
            render(1),
            Request::SaveSndf {
                out: "a.sndf".into(),
            },
            Request::Quit,
            Request::Prefetch("3.mdlod".into()),
            render(2),
        ];
        assert_eq!(names(&plan(pending)), ["save a.sndf", "quit"]);
    }

    #[test]
    fn the_file_cache_drops_the_least_recently_used_file() {
        let mut cache = FileCache::new(3);
        for (i, p) in ["a", "b", "c"].into_iter().enumerate() {
            cache.insert(p.into(), i);
        }
        // "a" is shown again: "b" is now the oldest.
        assert_eq!(cache.get(Path::new("a")), Some(0));
        cache.insert("d".into(), 3);
        assert_eq!(cache.get(Path::new("b")), None);
        assert_eq!(cache.get(Path::new("a")), Some(0));
        assert_eq!(cache.get(Path::new("c")), Some(2));
        assert_eq!(cache.get(Path::new("d")), Some(3));
        // Inserting a file again replaces it without dropping another.
        cache.insert("d".into(), 4);
        assert_eq!(cache.entries.len(), 3);
        assert_eq!(cache.get(Path::new("a")), Some(0));
    }

    #[test]
    fn an_orbiting_orthographic_sndf_preview_is_drawn_at_the_preview_error() {
        let mut opts = RenderOptions {
            error_px: 1.0,
            mode: RenderMode::Sndf {
                iterations: 64,
                bins: 8,
                binning: Default::default(),
            },
            ..Default::default()
        };
        sphere_fallback(&mut opts, 12.0);
        assert_eq!(opts.mode, RenderMode::Spheres);
        assert_eq!(opts.error_px, 12.0);
        // Never finer than asked, nor a bad error.
        sphere_fallback(&mut opts, 0.5);
        sphere_fallback(&mut opts, f32::NAN);
        assert_eq!(opts.error_px, 12.0);
    }
}
