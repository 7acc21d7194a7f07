//! The interactive viewer, `mdlod view`: a window over the same renderer `mdlod render`
//! uses headless.
//!
//! How it works:
//! - [`state`]: the camera, mode, lights and timestep as plain data; every input, from
//!   the mouse, keys, panel or a script, is an [`state::Action`] applied there. The state
//!   turns into the [`mdlod_render::RenderOptions`] of `mdlod render`, so a screenshot is
//!   the headless image of the same view.
//! - [`worker`]: a render thread that owns the GPU renderer and the mapped files;
//!   latest-wins render requests, progressive S-NDF refinement while the view is still,
//!   re-shading without sampling when only the lights change, prefetch of the next
//!   timestep. The window never waits for it.
//! - `app`: the window (eframe: winit, egui-winit, egui-wgpu), which shows the render
//!   thread's images, previews at an adapted screen error while the user drags, and
//!   plays scripts (`--script`): JSON arrays of actions with screenshots, which is how
//!   the viewer is tested under Xvfb.
//!
//! Frames travel from the render thread to the window as images on the host, one copy
//! per frame; the render thread has its own device, so a slow frame never stalls the
//! interface.

mod app;
pub mod state;
pub mod worker;

use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use mdlod_format::MdlodFile;
use mdlod_render::{BackendChoice, ViewSpec};

pub use state::{Action, FrameInfo, Mode, ViewerState};

/// What can go wrong opening the viewer.
#[derive(Debug, thiserror::Error)]
pub enum ViewerError {
    #[error("{path}: {message}")]
    DataSet { path: PathBuf, message: String },
    #[error(transparent)]
    Format(#[from] mdlod_format::FormatError),
    #[error(transparent)]
    Render(#[from] mdlod_render::RenderError),
    #[error("script {path}: {message}")]
    Script { path: PathBuf, message: String },
    #[error("the window: {0}")]
    Window(String),
    #[error("{0}")]
    Failed(String),
}

/// What to say when the window cannot open: where no display is named (a cluster node,
/// an ssh session without forwarding), what to do instead of the toolkit's own message,
/// which points into its source.
fn window_error(message: &str) -> String {
    let named = |v: &str| std::env::var_os(v).is_some_and(|d| !d.is_empty());
    if cfg!(target_os = "linux") && !named("DISPLAY") && !named("WAYLAND_DISPLAY") {
        "no display to open it on (neither DISPLAY nor WAYLAND_DISPLAY is set): run the \
         viewer in a desktop session, over ssh -X, or under a virtual display (xvfb-run \
         mdlod view ...); `mdlod render` makes images with no window"
            .to_string()
    } else {
        message.to_string()
    }
}

/// How to open the viewer.
#[derive(Clone, Debug)]
pub struct ViewerOptions {
    /// A `.mdlod` file, or a batch directory with `dataset.json`.
    pub path: PathBuf,
    /// Window size (logical pixels).
    pub window: [u32; 2],
    pub view: Option<PathBuf>,
    pub mode: Mode,
    pub backends: BackendChoice,
    /// Sphere frames through a fixed GPU page pool, or each frame's cut uploaded.
    pub gpu_memory: worker::GpuMemory,
    /// Play these actions, then close; the first error fails the run.
    pub script: Option<PathBuf>,
    /// Longest a script may run.
    pub script_timeout: Duration,
}

/// The frames of a `.mdlod` file or of a batch directory (its `dataset.json`, in the
/// manifest's order).
pub fn frames_of(path: &Path) -> Result<Vec<FrameInfo>, ViewerError> {
    if !path.is_dir() {
        return Ok(vec![FrameInfo {
            path: path.to_path_buf(),
            timestep: None,
        }]);
    }
    let manifest = path.join("dataset.json");
    let err = |message: String| ViewerError::DataSet {
        path: manifest.clone(),
        message,
    };
    let text =
        mdlod_format::files::read_capped_string(&manifest, mdlod_format::files::MANIFEST_BYTES)
            .map_err(|e| err(e.to_string()))?;
    let json: serde_json::Value = serde_json::from_str(&text).map_err(|e| err(e.to_string()))?;
    let frames = json
        .get("frames")
        .and_then(|f| f.as_array())
        .ok_or_else(|| err("no \"frames\" list".into()))?;
    let mut out = vec![];
    for (i, f) in frames.iter().enumerate() {
        let file = f
            .get("file")
            .and_then(|v| v.as_str())
            .ok_or_else(|| err(format!("frame {i}: no \"file\"")))?;
        out.push(FrameInfo {
            path: path.join(file),
            timestep: f.get("timestep").and_then(|v| v.as_u64()),
        });
    }
    if out.is_empty() {
        return Err(err("the data set has no frames".into()));
    }
    out.sort_by_key(|f| f.timestep);
    Ok(out)
}

/// What the first view frames: the material, less atoms lost far from it
/// ([`mdlod_render::fit_bounds`]), as `mdlod render` fits it, of the first frame and, in
/// a trajectory, of the last too, so that what settles or spreads (a pour, a sediment, a
/// blast) stays in view as the frames are stepped through. (`mdlod render DIR` frames
/// every frame; opening every one of thousands would hold up the window.) A last frame
/// that does not open is left out here and says so when it is shown.
pub fn first_view_bounds(first: &MdlodFile, frames: &[FrameInfo]) -> mdlod_render::Bounds {
    first_view_framing(first, frames).0
}

/// [`first_view_bounds`] and the boxes that frame them: the first frame's clusters and,
/// in a trajectory, the last's ([`framing`]), so that a file's first view is the one
/// `mdlod render` fits.
pub fn first_view_framing(
    first: &MdlodFile,
    frames: &[FrameInfo],
) -> (mdlod_render::Bounds, Vec<mdlod_render::Framed>) {
    let (bounds, mut boxes) = framing(first);
    match frames.last().filter(|_| frames.len() > 1) {
        Some(last) => match MdlodFile::open(&last.path) {
            Ok(f) => {
                let (b, more) = framing(&f);
                boxes.extend(more);
                let union = mdlod_render::Bounds::new(bounds.min.min(b.min), bounds.max.max(b.max));
                (union, boxes)
            }
            Err(_) => (bounds, boxes),
        },
        None => (bounds, boxes),
    }
}

/// What a fitted view of `file` frames, as `mdlod render` fits it with default options:
/// the bounds of the drawn spheres, less particles far from the rest
/// ([`mdlod_render::fit_for`]), and the boxes of its clusters inside them
/// ([`mdlod_render::framing_boxes`]), which frame data that does not fill its box.
pub fn framing(file: &MdlodFile) -> (mdlod_render::Bounds, Vec<mdlod_render::Framed>) {
    let opts = mdlod_render::RenderOptions::default();
    let bounds = mdlod_render::fit_for(file, &opts).bounds;
    let boxes = mdlod_render::framing_boxes(file, &opts, &bounds);
    (bounds, boxes)
}

/// The looks each species name keeps over a trajectory's frames, as `mdlod render DIR`
/// gives them ([`mdlod_render::style::trajectory_looks`]); none for one file. Every
/// frame's file is opened for its species table (about a millisecond each); a frame that
/// cannot be opened is left out here and named when it is shown.
pub fn trajectory_looks(frames: &[FrameInfo]) -> Vec<mdlod_format::meta::Species> {
    if frames.len() < 2 {
        return Vec::new();
    }
    let tables: Vec<Vec<mdlod_format::meta::Species>> = frames
        .iter()
        .filter_map(|f| MdlodFile::open(&f.path).ok())
        .map(|f| f.metadata().species.clone())
        .collect();
    mdlod_render::style::trajectory_looks(&tables.iter().map(Vec::as_slice).collect::<Vec<_>>())
}

/// Opens the window and runs until it closes (or the script ends).
pub fn run(opts: ViewerOptions) -> Result<(), ViewerError> {
    let script = match &opts.script {
        Some(p) => {
            let err = |message: String| ViewerError::Script {
                path: p.clone(),
                message,
            };
            // (A script is a list of actions: far below the manifests' cap.)
            let text =
                mdlod_format::files::read_capped_string(p, mdlod_format::files::MANIFEST_BYTES)
                    .map_err(|e| err(e.to_string()))?;
            let actions = state::parse_script(&text).map_err(err)?;
            Some(app::Script::new(actions, opts.script_timeout))
        }
        None => None,
    };
    let frames = frames_of(&opts.path)?;
    let first = MdlodFile::open(&frames[0].path)?;
    let [w, h] = opts.window;
    let view = match &opts.view {
        Some(p) => ViewSpec::File(p.clone()),
        // Square on to flat (two-dimensional) data.
        None => ViewSpec::default().resolved(&first),
    };
    let (bounds, boxes) = first_view_framing(&first, &frames);
    let camera = mdlod_render::camera_for_framing(&bounds, &boxes, &view, w, h)?;
    let looks = trajectory_looks(&frames);
    let mut state = ViewerState::new(frames, camera, bounds, [w, h]);
    // (A trajectory's first view frames its last frame too; `F` fits the frame shown.)
    if state.frames.len() == 1 {
        state.framing = boxes;
    }
    state.settings.mode = opts.mode;
    let meta = first.metadata();
    state.species = match looks.is_empty() {
        true => &meta.species,
        false => &looks,
    }
    .iter()
    .map(|s| (s.name.clone(), s.colour))
    .collect();
    state.attributes = first
        .attribute_names()
        .iter()
        .map(|n| n.to_string())
        .collect();
    drop(first);
    // The render thread and its device start before the window opens, so that a
    // machine without a device gets the renderer's clear error. Its replies wake the
    // window once there is one.
    let window: Arc<Mutex<Option<eframe::egui::Context>>> = Arc::new(Mutex::new(None));
    let wake = window.clone();
    let worker = worker::Worker::start(opts.backends, opts.gpu_memory, looks, move || {
        if let Some(ctx) = wake.lock().unwrap_or_else(|e| e.into_inner()).as_ref() {
            ctx.request_repaint();
        }
    })?;
    let outcome = Arc::new(Mutex::new(None));
    let result = outcome.clone();
    let native = eframe::NativeOptions {
        viewport: eframe::egui::ViewportBuilder::default()
            .with_inner_size([w as f32 + app::PANEL_WIDTH, h as f32])
            .with_title(format!("mdlod: {}", opts.path.display())),
        renderer: eframe::Renderer::Wgpu,
        ..Default::default()
    };
    let title = format!("mdlod: {}", opts.path.display());
    eframe::run_native(
        &title,
        native,
        Box::new(move |cc| {
            *window.lock().unwrap_or_else(|e| e.into_inner()) = Some(cc.egui_ctx.clone());
            Ok(Box::new(app::ViewerApp::new(
                state, worker, script, outcome,
            )))
        }),
    )
    .map_err(|e| ViewerError::Window(window_error(&e.to_string())))?;
    let failure = result.lock().unwrap_or_else(|e| e.into_inner()).take();
    match failure {
        Some(message) => Err(ViewerError::Failed(message)),
        None => Ok(()),
    }
}
