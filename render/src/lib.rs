//! mdlod's renderer: reads a `.mdlod` file through `mdlod-format` and draws it.
//!
//! How it works, one frame:
//! 1. [`context`] opens a GPU device (honouring `WGPU_BACKEND`; a clear
//!    [`RenderError::NoAdapter`] when there is none).
//! 2. [`camera`] / [`view`] give the orbit camera (optionally from a JSON view file).
//! 3. [`traversal::traverse`] picks the cut through the hierarchy on the CPU: nodes no
//!    larger than `error_px` pixels on screen are drawn as their representative, larger
//!    ones are opened, up to a point budget; subtrees outside the view frustum are culled,
//!    and so are subtrees, clusters and particles hidden behind spheres already chosen
//!    ([`occlusion`]: the cut is walked nearest first against a conservative CPU depth
//!    pyramid, in tiles of the image on every core, so no visible pixel changes). The
//!    result is a list of contiguous point ranges.
//! 4. [`passes::sphere_raycast`] uploads those ranges' raw quantized positions and draws
//!    one ray-cast, depth-correct sphere per point, decoding positions on the GPU (spheres
//!    up to 8×8 pixels by a compute raster where the device has 64-bit atomics, the
//!    others as impostor quads); [`renderer`] runs it once per sample (jittered
//!    supersampling), averages and reads back an RGBA8 [`image::RgbaImage`].
//!
//! The other modes draw the same cut differently: [`passes::splat`] as additive or
//! sorted translucent splats, [`sndf`] as screen-space normal distributions shaded
//! after sampling, and [`density`] as an image-space density volume or iso-surface.
//!
//! [`streaming::StreamingRenderer`] draws the same cut out of core: the points live in a
//! fixed GPU page pool with least-recently-used eviction, filled by a loader thread
//! largest-on-screen first, and a subtree whose pages are missing is drawn by its
//! nearest resident ancestor until they arrive.
//!
//! [`render_to_png`] does all of it for the command line; [`render_image`] is the same
//! with an open file and renderer, for callers that draw several frames. Nothing here
//! prints: progress and results go back to the caller in a [`RenderReport`].

pub mod camera;
pub mod context;
pub mod density;
pub mod error;
pub mod font;
pub mod image;
pub mod label;
pub mod legend;
pub mod movie;
pub mod occlusion;
pub mod overlay;
pub mod passes;
pub mod renderer;
pub mod smip;
pub mod sndf;
pub mod streaming;
pub mod style;
pub mod traversal;
pub mod view;

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

pub use mdlod_format::reader::HiddenSet;
use mdlod_format::MdlodFile;
pub use mdlod_format::{NoProgress, Progress};

pub use camera::{Bounds, Camera, FitWindow, Framed, Projection};
pub use context::{BackendChoice, GpuContext};
pub use error::RenderError;
pub use glam;
pub use image::RgbaImage;
pub use occlusion::OcclusionMode;
pub use passes::sphere_raycast::{Lighting, PackStyle};
pub use renderer::{FrameSettings, RenderedFrame, Renderer, SplatBlend, SplatFrame};
pub use streaming::{StreamStats, StreamingRenderer};
pub use style::{ColourMap, PointStyle, SpeciesStyle};
pub use traversal::{
    traverse, traverse_shared, traverse_with, ClipPlanes, ClipSide, DepthOrder, DrawList,
    DrawRange, Residency, SharedResidency, TraversalSettings, MAX_CLIP_PLANES,
};
pub use view::ViewFile;

/// Where the camera comes from.
#[derive(Clone, Debug, PartialEq)]
pub enum ViewSpec {
    /// The data's own view: an [`ViewSpec::Orbit`] at azimuth 30°, elevation 20° for
    /// three-dimensional data; data whose particle centres all lie in one plane (a
    /// two-dimensional simulation) is faced square on instead, with its first remaining
    /// axis to the right ([`facing_angles`]). A `target` pans as a [`ViewSpec::View`]'s.
    /// [`frame_setup`] resolves it against the file drawn ([`ViewSpec::resolved`]); where
    /// no file is at hand it is the three-dimensional orbit.
    Default {
        zoom: f32,
        projection: Projection,
        target: Option<[f32; 3]>,
    },
    /// Orbit around the data's centre, at the distance where the data fits, divided by
    /// `zoom` (2 = twice as close).
    Orbit {
        azimuth_deg: f32,
        elevation_deg: f32,
        zoom: f32,
        projection: Projection,
    },
    /// A JSON view file (see [`view`]).
    File(PathBuf),
    /// A JSON view file with some of its settings changed (the command line's
    /// `--view v.json --azimuth 60`).
    FileWith(PathBuf, ViewChanges),
    /// An explicit camera (its near/far planes are refitted to the data).
    Camera(Camera),
    /// A view file's settings given in memory (the command line's angles with
    /// `--target`): what it leaves out (the distance, the target) is fitted, as for a
    /// [`ViewSpec::File`].
    View(ViewFile),
}

/// Changes to a view file's camera: angles replace the file's, a zoom multiplies its
/// zoom (2: twice as close as the view saved), `orthographic` switches the projection.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ViewChanges {
    pub azimuth_deg: Option<f32>,
    pub elevation_deg: Option<f32>,
    pub zoom: Option<f32>,
    pub orthographic: bool,
    /// The point looked at and orbited around, replacing the file's (a pan).
    pub target: Option<[f32; 3]>,
}

impl ViewChanges {
    /// Whether anything changes.
    pub fn is_empty(&self) -> bool {
        *self == ViewChanges::default()
    }

    /// Changes `v`; whether it changed.
    fn apply(&self, v: &mut ViewFile) -> bool {
        let before = v.clone();
        if let Some(a) = self.azimuth_deg {
            v.azimuth_deg = a;
        }
        if let Some(e) = self.elevation_deg {
            v.elevation_deg = e;
        }
        if let Some(z) = self.zoom {
            v.zoom *= z;
        }
        if self.orthographic {
            v.projection = Projection::Orthographic;
        }
        if let Some(t) = self.target {
            v.target = Some(t);
        }
        *v != before
    }
}

impl Default for ViewSpec {
    fn default() -> Self {
        ViewSpec::Default {
            zoom: 1.0,
            projection: Projection::Perspective,
            target: None,
        }
    }
}

/// The azimuth and elevation of the default view of three-dimensional data.
pub const DEFAULT_ANGLES: (f32, f32) = (30.0, 20.0);

impl ViewSpec {
    /// [`ViewSpec::Default`] made explicit for data flat across `flat_axis` (see
    /// [`flat_axis`]; `None`: three-dimensional data); any other view as it is.
    pub fn with_flat_axis(&self, flat_axis: Option<usize>) -> ViewSpec {
        if let ViewSpec::File(_) | ViewSpec::FileWith(..) = self {
            return match (self.angleless_file(), flat_axis) {
                (Some((v, changes)), Some(axis)) => Self::facing(v, changes, axis),
                _ => self.clone(),
            };
        }
        let ViewSpec::Default {
            zoom,
            projection,
            target,
        } = *self
        else {
            return self.clone();
        };
        let (azimuth_deg, elevation_deg) = flat_axis.map_or(DEFAULT_ANGLES, facing_angles);
        match target {
            None => ViewSpec::Orbit {
                azimuth_deg,
                elevation_deg,
                zoom,
                projection,
            },
            Some(t) => ViewSpec::View(ViewFile {
                projection,
                azimuth_deg,
                elevation_deg,
                zoom,
                target: Some(t),
                ..Default::default()
            }),
        }
    }

    /// Whether the view's angles depend on the data ([`ViewSpec::resolved`]): the
    /// default view, and a view file (it may give no angle).
    pub fn depends_on_data(&self) -> bool {
        matches!(
            self,
            ViewSpec::Default { .. } | ViewSpec::File(_) | ViewSpec::FileWith(..)
        )
    }

    /// [`ViewSpec::Default`] made explicit for `file`'s data; any other view as it is.
    pub fn resolved(&self, file: &MdlodFile) -> ViewSpec {
        match self {
            ViewSpec::Default { .. } => self.with_flat_axis(flat_axis(file)),
            // (The data is looked at only for a file that gives no angle.)
            ViewSpec::File(_) | ViewSpec::FileWith(..) => match self.angleless_file() {
                Some((v, changes)) => match flat_axis(file) {
                    Some(axis) => Self::facing(v, changes, axis),
                    None => self.clone(),
                },
                None => self.clone(),
            },
            _ => self.clone(),
        }
    }

    /// A view file's settings and the changes to them, where neither gives an angle (it
    /// then takes the default view's, as the command line's options do).
    fn angleless_file(&self) -> Option<(ViewFile, ViewChanges)> {
        let (path, changes) = match self {
            ViewSpec::File(path) => (path, ViewChanges::default()),
            ViewSpec::FileWith(path, changes) => (path, *changes),
            _ => return None,
        };
        if changes.azimuth_deg.is_some() || changes.elevation_deg.is_some() {
            return None;
        }
        Some((ViewFile::load_angleless(path)?, changes))
    }

    /// The view file `v`, with `changes`, facing a plane normal to `axis`.
    fn facing(mut v: ViewFile, changes: ViewChanges, axis: usize) -> ViewSpec {
        (v.azimuth_deg, v.elevation_deg) = facing_angles(axis);
        changes.apply(&mut v);
        ViewSpec::View(v)
    }
}

/// The axis (0 x, 1 y, 2 z) across which `file`'s data is flat, if it is: every
/// particle's centre in one plane normal to it (a two-dimensional simulation, or a single
/// atomic layer), whatever the particles' radii. Data on a line is flat across two axes:
/// the view then looks down z if z is one of them, else along y. `None` for
/// three-dimensional data, or a single point.
///
/// Files of up to [`FLAT_TEST_POINTS`] particles are tested on their particles; larger
/// ones on the representatives of their finest level of at most that many points (each a
/// weighted mean of particles, so in their plane when they are flat). A plane's
/// thickness up to [`FLAT_SLACK`] of the smallest species radius counts as flat: a relaxed
/// sheet's atoms stand 10⁻⁴ to 10⁻³ Å off its plane.
pub fn flat_axis(file: &MdlodFile) -> Option<usize> {
    let slack = file
        .metadata()
        .species
        .iter()
        .map(|s| s.radius)
        .filter(|r| r.is_finite() && *r > 0.0)
        .fold(f32::INFINITY, f32::min);
    let slack = if slack.is_finite() {
        FLAT_SLACK * slack
    } else {
        0.0
    };
    let levels = file.levels();
    let last = file.level_count().checked_sub(1)?;
    if levels[last].point_count <= FLAT_TEST_POINTS as u64 {
        let ranges = file.encoding_ranges(last).ok()?;
        let (pos, nodes, bits) = (file.positions(last), file.nodes(), file.position_bits());
        let points = ranges.into_iter().flat_map(|(node, range)| {
            let n = &nodes[node];
            range.filter(|&i| i < pos.len()).map(move |i| {
                glam::Vec3::from(mdlod_format::quantize::decode3(
                    pos.get(i),
                    n.centroid,
                    n.quant_scale,
                    bits,
                ))
            })
        });
        return flat_axis_within(points, slack);
    }
    let level = (0..last)
        .rev()
        .find(|&l| levels[l].point_count <= FLAT_TEST_POINTS as u64)?;
    flat_axis_within(
        file.level_nodes(level)
            .iter()
            .map(|n| glam::Vec3::from(n.centroid)),
        slack,
    )
}

/// The share of the smallest species radius a flat set of particles may stand off its
/// plane ([`flat_axis`]).
pub const FLAT_SLACK: f32 = 0.05;

/// The most points [`flat_axis`] looks at (a millisecond's work).
pub const FLAT_TEST_POINTS: usize = 1 << 16;

/// [`flat_axis`] of particles centred at `points`: an axis along which their centres
/// spread no more than 10⁻⁵ of their widest spread (and single precision's rounding), or
/// no more than `slack` (world units) while spreading more than a hundred times that
/// along another.
fn flat_axis_within(points: impl IntoIterator<Item = glam::Vec3>, slack: f32) -> Option<usize> {
    let (mut lo, mut hi) = (glam::Vec3::INFINITY, glam::Vec3::NEG_INFINITY);
    for p in points {
        lo = lo.min(p);
        hi = hi.max(p);
    }
    let extent = hi - lo;
    if !extent.is_finite() {
        return None;
    }
    let far = lo.abs().max(hi.abs()).max_element();
    let widest = extent.max_element();
    let slack = if widest > 100.0 * slack { slack } else { 0.0 };
    let tolerance = (1e-5 * widest).max(slack) + 8.0 * f32::EPSILON * far;
    let flat: Vec<usize> = (0..3).filter(|&k| extent[k] <= tolerance).collect();
    match flat[..] {
        [k] => Some(k),
        // On a line: looking down on it if it lies across z, else along y (the larger of
        // the two axes, as they are in order).
        [_, b] => Some(b),
        _ => None,
    }
}

/// The azimuth and elevation (degrees) that face a plane normal to `axis` square on:
/// z flat looks straight down with x to the right and y up; y flat looks along +y with x
/// to the right; x flat looks along −x with y to the right; the other axis up.
pub fn facing_angles(axis: usize) -> (f32, f32) {
    match axis {
        0 => (0.0, 0.0),
        1 => (-90.0, 0.0),
        _ => (-90.0, 90.0),
    }
}

/// What to render.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderOptions {
    pub width: u32,
    pub height: u32,
    pub view: ViewSpec,
    /// Samples per pixel (1 to [`renderer::MAX_SPP`]).
    pub spp: u32,
    /// Largest projected size, in pixels, of a cluster drawn as one sphere.
    pub error_px: f32,
    /// Most spheres to draw (clamped to what the GPU's buffers hold).
    pub budget: u64,
    /// Background colour, sRGB-encoded, each channel in [0, 1].
    pub background: [f32; 3],
    pub lighting: Lighting,
    /// Which backends to search for an adapter.
    pub backends: BackendChoice,
    /// Stream node data through a GPU pool of at most this many bytes (least recently
    /// used pages evicted) instead of uploading the whole cut; frames are drawn until
    /// everything the view needs has arrived.
    pub gpu_memory: Option<u64>,
    /// Leave out clusters hidden behind spheres already drawn (exact: no visible pixel
    /// changes; see [`occlusion`]). Sphere mode only.
    pub occlusion: bool,
    /// How points are drawn.
    pub mode: RenderMode,
    /// Splat modes: how far a splat's kernel reaches, in radii (the Gaussian's cut
    /// radius; σ = this / 3.5). [`passes::splat::DEFAULT_SUPPORT`] (1.75, σ = r / 2) by
    /// default; an SPH run's own kernel convention sets another (a smoothing length
    /// that is the kernel's full support: 1).
    pub splat_support: f32,
    /// Splat mode: tone-mapping exposure (light added per unit of flux); `None` picks one
    /// from the image.
    pub exposure: Option<f32>,
    /// Splat mode with a colour map ([`PointStyle::colour_map`]): the image's light at
    /// the map's ends ([`SplatFrame::colour_mapped`]); `None` takes it from the image.
    pub light_range: Option<[f32; 2]>,
    /// Sphere and S-NDF modes: the points' look (species colours, radii, hiding, colour
    /// by the attribute); see [`style`].
    pub style: PointStyle,
    /// Fit a fitted view to every particle, those far from the rest included (see
    /// [`fit_bounds`]).
    pub fit_all: bool,
    /// No background (sphere mode): see [`FrameSettings::transparent`].
    pub transparent: bool,
    /// Draw the simulation cell's edges over the image (see [`overlay`]): hidden behind
    /// the spheres in front of them; over splats and the volume, which have no depth.
    pub cell: Option<CellLines>,
    /// Report which species the cut shows ([`RenderReport::species_drawn`]; it reads up
    /// to every particle's species once).
    pub species_drawn: bool,
    /// Where a fitted view may place the data: the best of these parts of the image
    /// ([`Camera::fit_boxes_in`]), so that a legend drawn into a corner covers none of
    /// it. Empty: the whole image.
    pub fit_windows: Vec<FitWindow>,
    /// Additive splats: keep each pixel's light ([`RenderReport::light_map`]).
    pub keep_light_map: bool,
}

/// How the simulation cell's edges are drawn.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CellLines {
    /// sRGB.
    pub colour: [u8; 3],
    /// Width in pixels.
    pub width_px: f32,
}

/// How points are drawn.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum RenderMode {
    /// Opaque, depth-correct ray-cast spheres, shaded.
    #[default]
    Spheres,
    /// Additive, flux-preserving splats accumulated in floating point and tone mapped
    /// (SPH, astrophysics; see [`passes::splat`]); `by_attribute`: each point's light is
    /// its scalar attribute (mapped from the attribute's range to [0, 1], grey) instead of
    /// its species colour.
    Splat { by_attribute: bool },
    /// Translucent splats sorted back to front and composited with the over operator,
    /// for data that needs depth order; `opacity` is the splats' peak alpha.
    SplatOver {
        opacity: f32,
        order: traversal::DepthOrder,
    },
    /// S-NDFs sampled with `iterations` jittered rays per pixel into `bins × bins`
    /// bins of `binning`, then shaded from the S-NDFs alone (see [`sndf`]).
    Sndf {
        iterations: u32,
        bins: u32,
        binning: sndf::Binning,
    },
    /// The image-space density volume of the points (Falk et al. 2010): direct volume
    /// rendering through a transfer function, or an iso-surface (see [`density`]).
    Density(density::DensitySettings),
}

impl Default for RenderOptions {
    fn default() -> Self {
        RenderOptions {
            width: 1280,
            height: 720,
            view: ViewSpec::default(),
            spp: 1,
            error_px: 1.0,
            budget: 4_000_000,
            background: [1.0, 1.0, 1.0],
            lighting: Lighting::default(),
            backends: BackendChoice::FromEnv,
            gpu_memory: None,
            occlusion: true,
            mode: RenderMode::Spheres,
            splat_support: passes::splat::DEFAULT_SUPPORT,
            exposure: None,
            style: PointStyle::default(),
            fit_all: false,
            transparent: false,
            light_range: None,
            cell: None,
            species_drawn: false,
            fit_windows: Vec::new(),
            keep_light_map: false,
        }
    }
}

/// What a render did.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderReport {
    pub width: u32,
    pub height: u32,
    pub spp: u32,
    /// Particles (finest-level points) drawn.
    pub particles_drawn: u64,
    /// Particles of species the style hides (`--hide-species`), besides those drawn:
    /// left out of the cut (where a hidden species' index is 64 or more, which
    /// [`TraversalSettings::hidden_species`] cannot name, in the cut and drawn as
    /// nothing, among `particles_drawn`).
    pub particles_hidden: u64,
    /// Clusters drawn that still hold hidden species (their refinement stopped at the
    /// budget or at a node not yet resident).
    pub clusters_mixed: u64,
    /// Particles cut away by the style's clip planes ([`PointStyle::clip`]) from the
    /// clusters drawn (clusters wholly beyond a plane are left out whole, uncounted).
    pub particles_clipped: u64,
    /// Clusters drawn across a clip plane (their refinement stopped at the budget or at
    /// a node not yet resident): drawn whole.
    pub clusters_across: u64,
    /// With [`RenderOptions::species_drawn`]: which species (by index) the cut shows.
    pub species_drawn: Option<Vec<bool>>,
    /// Cluster representatives drawn.
    pub nodes_drawn: u64,
    /// Contiguous ranges drawn.
    pub ranges: usize,
    /// Nodes opened by the traversal.
    pub nodes_opened: u64,
    /// Nodes left out by occlusion culling: hidden behind drawn spheres, or seen by no
    /// sample at all (between pixel centres); see [`DrawList::occluded_nodes`].
    pub nodes_occluded: u64,
    /// Particles left out likewise: hidden, or between pixel centres.
    pub particles_occluded: u64,
    /// Largest projected size (px) of a representative drawn (0: only particles).
    pub error_px: f32,
    /// True when the point budget stopped refinement.
    pub budget_limited: bool,
    /// True when the streaming pool (GPU memory) could not hold the cut the view asked
    /// for, so that coarser nodes were drawn in its place.
    pub pool_limited: bool,
    /// The budget applied (the requested one, clamped to the GPU's limits).
    pub budget: u64,
    pub adapter: String,
    pub backend: String,
    /// The camera used (e.g. to save as a view file).
    pub camera: Camera,
    pub traversal_time: Duration,
    /// GPU time, when the adapter measures it.
    pub gpu_time: Option<Duration>,
    /// Wall time of the whole render (traversal, upload, drawing, readback).
    pub total_time: Duration,
    /// Frames drawn: 1, or with streaming, until the view was complete.
    pub frames: u32,
    /// With streaming: wall time until the first (coarse) frame was read back.
    pub first_frame_time: Option<Duration>,
    /// GPU memory of the last frame: point data (the uploaded cut, or the streaming
    /// pool) and render targets, in bytes.
    pub gpu_data_bytes: u64,
    pub gpu_target_bytes: u64,
    /// Splat mode: the tone-mapping exposure used and the image's total flux of light
    /// ([`SplatFrame::total_light`]: the attribute's light with attribute intensities).
    pub exposure: Option<f32>,
    pub total_flux: Option<f64>,
    /// Splat mode with a colour map: the image's light at the map's ends.
    pub light_range: Option<[f32; 2]>,
    /// Splat mode with a colour map: the light of its faintest and brightest lit pixels
    /// (past `light_range`'s ends, they take the end's colour).
    pub light_extent: Option<[f32; 2]>,
    /// Density mode: slice stacks run before every ray was done, of those the volume spans.
    pub density_stacks: Option<(u32, u32)>,
    /// Density: read-backs of the active rays (one per batch of stacks; one when the
    /// previous frame's stack count was right).
    pub density_readbacks: Option<u32>,
    /// Density mode: host work before the GPU passes (decoding, sorting, packing).
    pub density_host_time: Option<Duration>,
    /// Additive splats with [`RenderOptions::keep_light_map`]: each pixel's light
    /// ([`SplatFrame::light`]: the projected flux, or the projected attribute in its
    /// units), row by row from the image's top left.
    pub light_map: Option<Vec<f32>>,
}

/// Colours by name (sRGB, as `#rrggbb`): the basic ones, and the CSS names a figure's
/// colours are often given by (`lime`, `navy`, `gold`, ...), with CSS's values.
const NAMED_COLOURS: [(&str, &str); 27] = [
    ("black", "000000"),
    ("white", "ffffff"),
    ("grey", "808080"),
    ("gray", "808080"),
    ("red", "ff0000"),
    ("green", "00a000"),
    ("blue", "0000ff"),
    ("yellow", "ffff00"),
    ("cyan", "00ffff"),
    ("magenta", "ff00ff"),
    ("orange", "ff8000"),
    ("purple", "800080"),
    ("lime", "00ff00"),
    ("navy", "000080"),
    ("teal", "008080"),
    ("olive", "808000"),
    ("maroon", "800000"),
    ("silver", "c0c0c0"),
    ("gold", "ffd700"),
    ("pink", "ffc0cb"),
    ("brown", "a52a2a"),
    ("lightgrey", "d3d3d3"),
    ("lightgray", "d3d3d3"),
    ("darkgrey", "a9a9a9"),
    ("darkgray", "a9a9a9"),
    ("violet", "ee82ee"),
    ("indigo", "4b0082"),
];

/// Parses a colour as `#rrggbb`, `rrggbb`, CSS's short `#rgb` (`#f00`: `#ff0000`),
/// three numbers in [0, 1] separated by commas, or a name (`NAMED_COLOURS`: `red`,
/// `grey`, ...).
pub fn parse_colour(s: &str) -> Result<[f32; 3], RenderError> {
    let bad = || {
        let names: Vec<&str> = NAMED_COLOURS.iter().map(|(n, _)| *n).collect();
        RenderError::InvalidOptions(format!(
            "colour {s:?} (use #rrggbb, #rgb, r,g,b with each in 0..1, or one of {})",
            names.join(", ")
        ))
    };
    let t = s.trim();
    let t = NAMED_COLOURS
        .iter()
        .find(|(n, _)| n.eq_ignore_ascii_case(t))
        .map_or(t, |(_, hex)| hex);
    let hex = t.strip_prefix('#').unwrap_or(t);
    if hex.len() == 6 && hex.chars().all(|c| c.is_ascii_hexdigit()) {
        let v = u32::from_str_radix(hex, 16).map_err(|_| bad())?;
        return Ok([16, 8, 0].map(|sh| ((v >> sh) & 0xff) as f32 / 255.0));
    }
    // (Only with its `#`: three bare digits, `100`, are no colour.)
    if let Some(short) = t.strip_prefix('#') {
        if short.len() == 3 && short.chars().all(|c| c.is_ascii_hexdigit()) {
            let v = u32::from_str_radix(short, 16).map_err(|_| bad())?;
            return Ok([8, 4, 0].map(|sh| ((v >> sh) & 0xf) as f32 * 17.0 / 255.0));
        }
    }
    let parts: Vec<f32> = t
        .split(',')
        .map(|p| p.trim().parse::<f32>())
        .collect::<Result<_, _>>()
        .map_err(|_| bad())?;
    match parts[..] {
        [r, g, b] if [r, g, b].iter().all(|c| (0.0..=1.0).contains(c)) => Ok([r, g, b]),
        _ => Err(bad()),
    }
}

/// Where a log scale of the file's attribute starts when its range reaches 0 or below
/// (kinetic energies with frozen wall atoms at 0), instead of the
/// [`style::AttributeScale::LOG_DECADES`] floor that a few zeros would pull it down to:
/// in a file of at most 2^20 particles the smallest positive value of a particle; in a
/// larger one the smallest positive cluster mean on the deepest level of at most 65 536
/// clusters, a value the bulk of the data reaches. `None` without an attribute or a
/// positive value.
pub fn log_floor(file: &MdlodFile) -> Option<f32> {
    let info = file.metadata().attribute.as_ref()?;
    let levels = file.levels();
    let last = levels.len().checked_sub(1)?;
    if levels[last].point_count <= 1 << 20 {
        return file
            .attribute()?
            .iter()
            .map(|&q| info.decode(q))
            .filter(|&v| v > 0.0 && v.is_finite())
            .min_by(f32::total_cmp);
    }
    let level = (0..last)
        .rev()
        .find(|&l| levels[l].point_count <= 1 << 16)?;
    let first = usize::try_from(levels[level].node_first).ok()?;
    let count = usize::try_from(levels[level].point_count).ok()?;
    file.check_nodes(level, 0..count).ok()?;
    file.nodes()
        .get(first..first.checked_add(count)?)?
        .iter()
        .map(|n| n.attribute)
        .filter(|&a| a > 0.0 && a.is_finite())
        .min_by(f32::total_cmp)
}

/// The range `file`'s attribute is shown over where `style` gives none and the file's
/// own would mislead, and why ([`style::default_range`]): splats lit by the values
/// (`light`) from 0; where the values are drawn as colours or attribute splats
/// (`mapped`), a log scale from [`log_floor`] and a diverging colour map centred on 0.
/// `None` where the style gives a range, the file has no attribute, or its own range
/// serves. `mdlod render` and the viewer show a file's values over the same range.
pub fn default_range_of(
    file: &MdlodFile,
    style: &PointStyle,
    mapped: bool,
    light: bool,
) -> Option<([f32; 2], style::RangeChoice)> {
    if style.attribute_range.is_some() {
        return None;
    }
    let a = file.metadata().attribute.as_ref()?;
    // Hidden particles (a solvent, a gas's stars) take no part of the map.
    let shown = shown_attribute_range(file, style);
    let own = shown.unwrap_or([a.min, a.max]);
    let chosen = style::default_range(
        own,
        light,
        mapped,
        style.log_scale,
        style.colour_map,
        if style.log_scale {
            log_floor(file)
        } else {
            None
        },
    );
    match (chosen, shown) {
        (Some(c), _) => Some(c),
        // A diverging map over values of both signs keeps its white on 0 whatever is
        // drawn (a slab of one sign reaches to its largest magnitude on either side); over
        // a file of one sign (a potential energy) it spreads the values drawn, as the
        // file's own range would.
        (None, Some([lo, hi]))
            if mapped
                && style.colour_map.is_some_and(|m| m.is_diverging())
                && a.min < 0.0
                && a.max > 0.0 =>
        {
            let m = lo.abs().max(hi.abs());
            (m > 0.0 && m.is_finite()).then_some(([-m, m], style::RangeChoice::Centred))
        }
        (None, Some(range)) if (mapped || light) && range != [a.min, a.max] => {
            Some((range, style::RangeChoice::Shown))
        }
        _ => None,
    }
}

/// What a style draws of a file's attribute values ([`drawn_attribute`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum DrawnValues {
    /// Every particle: nothing hidden or cut away (or the file has no attribute).
    All,
    /// No particle.
    Nothing,
    /// Particles of one value only.
    One,
    /// Particles of values from the first to the second.
    Range([f32; 2]),
}

/// The attribute values of the particles `style` draws in the colour map's colours,
/// where it hides some (species, values), cuts some away (`clip`, each particle's
/// centre as the traversal cuts it) or gives species colours of their own under a
/// colour map ([`PointStyle::unmapped_mask`]): what a colour map spans by default, so
/// that hidden particles' values (a solvent's zero, the bulk beside a slab's defects)
/// and grey walls' (a granular run's resting wall atoms) do not stretch it. One pass
/// over the particles' species and values, and their positions where planes cut.
pub fn drawn_attribute(file: &MdlodFile, style: &PointStyle) -> DrawnValues {
    let mut hidden = style.hidden_set(file.metadata());
    hidden.species |= style.unmapped_mask(&file.metadata().species);
    let (Some(a), Some(values), Ok(clip)) = (
        file.metadata().attribute.as_ref(),
        file.attribute(),
        style.clip_planes(),
    ) else {
        return DrawnValues::All;
    };
    if hidden.is_empty() && clip.is_empty() {
        return DrawnValues::All;
    }
    let test = file.hidden_test(&hidden);
    let (mut lo, mut hi) = (u16::MAX, 0u16);
    let mut take = |i: usize| {
        if let Some(&q) = values.get(i) {
            lo = lo.min(q);
            hi = hi.max(q);
        }
    };
    let last = file.level_count().saturating_sub(1);
    match file.encoding_ranges(last) {
        Ok(runs) if !clip.is_empty() => {
            let clip = clip.for_file(file);
            let (pos, nodes, bits) = (file.positions(last), file.nodes(), file.position_bits());
            for (node, run) in runs {
                let Some(n) = nodes.get(node) else { continue };
                for i in run.filter(|&i| i < pos.len() && !file.hides_particle(&test, i)) {
                    let p = mdlod_format::quantize::decode3(
                        pos.get(i),
                        n.centroid,
                        n.quant_scale,
                        bits,
                    );
                    if clip.keeps(glam::Vec3::from(p)) {
                        take(i);
                    }
                }
            }
        }
        _ => (0..values.len())
            .filter(|&i| !file.hides_particle(&test, i))
            .for_each(&mut take),
    }
    match (lo, hi) {
        (lo, hi) if lo > hi => DrawnValues::Nothing,
        (lo, hi) if lo == hi => DrawnValues::One,
        // Each end as the shortest decimal its 16-bit step holds (1.5, not 1.4999896).
        (lo, hi) => {
            let half = (a.max - a.min) / 65535.0 / 2.0;
            DrawnValues::Range([
                shortest_within(a.decode(lo), half),
                shortest_within(a.decode(hi), half),
            ])
        }
    }
}

/// The range of [`drawn_attribute`], where the particles drawn span one (where they hold
/// one value, the file's range places it).
pub fn shown_attribute_range(file: &MdlodFile, style: &PointStyle) -> Option<[f32; 2]> {
    match drawn_attribute(file, style) {
        DrawnValues::Range(r) => Some(r),
        _ => None,
    }
}

/// The number with the fewest decimals within `tolerance` of `v` (`v` itself where none
/// with up to 7 is).
fn shortest_within(v: f32, tolerance: f32) -> f32 {
    (0..=7)
        .map(|d| {
            let scale = 10f64.powi(d);
            ((f64::from(v) * scale).round() / scale) as f32
        })
        .find(|r| (r - v).abs() <= tolerance)
        .unwrap_or(v)
}

/// The bounds of everything in the file (the top node's box).
pub fn data_bounds(file: &MdlodFile) -> Bounds {
    let top = &file.nodes()[0];
    Bounds::new(top.bounds_min, top.bounds_max)
}

/// The bounds of what a view hiding the particles of `hidden` (see
/// [`TraversalSettings::hidden`]) draws, for fitting the view to it: the union of
/// the boxes of the nodes holding shown species only, found by opening mixed nodes level
/// by level (at most [`SHOWN_BOUNDS_NODES`] of them; a mixed node not opened adds its
/// own box). A mixed node whose children are particles adds its shown particles'
/// spheres, where the particles are encoded relative to it (δn = 1; else its box).
/// `None` when nothing is hidden, or every particle is.
pub fn shown_bounds(file: &MdlodFile, hidden: HiddenSet) -> Option<Bounds> {
    if hidden.is_empty() {
        return None;
    }
    bounds_walk(file, hidden, None).map(|(b, _)| b)
}

/// The particles of node `n` (whose children are particles, encoded relative to it:
/// δn = 1) that `hidden` does not hide: position and radius (its own where the file
/// keeps one, else its species').
fn shown_particles<'a>(
    file: &'a MdlodFile,
    n: &'a mdlod_format::NodeRecord,
    hidden: HiddenSet,
) -> impl Iterator<Item = (glam::Vec3, f32)> + 'a {
    let last = file.level_count().saturating_sub(1);
    let (pos, species) = (file.positions(last), file.species());
    let test = file.hidden_test(&hidden);
    (n.child_first as usize..(n.child_first + n.child_count) as usize).filter_map(move |c| {
        if c >= pos.len() || c >= species.len() || file.hides_particle(&test, c) {
            return None;
        }
        let p = glam::Vec3::from(mdlod_format::quantize::decode3(
            pos.get(c),
            n.centroid,
            n.quant_scale,
            file.position_bits(),
        ));
        Some((p, file.particle_radius(c)))
    })
}

/// The most mixed nodes [`shown_bounds`] opens (a few milliseconds' work).
pub const SHOWN_BOUNDS_NODES: usize = 1 << 16;

/// What a fitted view is fitted to ([`fit_bounds`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FitBounds {
    /// The bounds the view fits.
    pub bounds: Bounds,
    /// Particles (of the species shown) left outside them: far from the rest.
    pub far_particles: u64,
    /// False when every particle is of a hidden species: `bounds` are then the whole
    /// file's, and a movie's fit leaves the frame out.
    pub shows_any: bool,
}

/// How far from the bulk a particle is left out of a fitted view: the bulk's box (the
/// 1st to 99th percentile of the data along each axis) grown on every side by this many
/// times its largest extent.
pub const FIT_MARGIN: f32 = 1.0;

/// Opens the `.mdlod` file at `path` with the attribute `style` reads in the first's
/// place ([`PointStyle::attribute`], [`MdlodFile::select_attribute`]): every reader of
/// the attribute (colours, splat light, hidden values, legends) then takes it.
pub fn open_styled(
    path: &Path,
    style: &PointStyle,
) -> Result<MdlodFile, mdlod_format::FormatError> {
    let mut file = MdlodFile::open(path)?;
    // Hidden values of another attribute than the colour's are chosen first: selecting
    // the colour's leaves the file that one alone.
    if let Some(name) = style
        .hide_by
        .as_deref()
        .filter(|_| !style.hidden_values.is_empty())
    {
        file = file.hide_by_attribute(name)?;
    }
    if !style.hidden_named.is_empty() {
        file = file.hide_by_attributes(&style.hide_names())?;
    }
    match &style.attribute {
        Some(name) => file.select_attribute(name),
        None => Ok(file),
    }
}

/// Files whose sections hold at most this many bytes have every checksum checked before
/// they are drawn ([`check_before_drawing`]): about 10 ms of hashing, against the
/// 0.1-0.3 s of drawing them.
pub const CHECKED_ON_OPEN: u64 = 64 << 20;

/// Files of at most this many bytes are verified whole before they are drawn
/// ([`MdlodFile::verify`]: every checksum, node and decoded point; about 10 ms, against
/// the 0.1-0.3 s of drawing them).
pub const VERIFIED_ON_OPEN: u64 = 16 << 20;

/// Checks a file about to be drawn, once per file (a caller that opens it again for its
/// metadata does not check it again): a small file whole, as `mdlod verify` does, so that
/// damage keeping the checksums right (a crafted file) is refused; a larger one's
/// checksums, so that a byte flipped on disk is an error, not a picture. Opening checks
/// no per-particle data (FORMAT.md, section 8).
pub fn check_before_drawing(file: &MdlodFile) -> Result<(), mdlod_format::FormatError> {
    let len = std::fs::metadata(file.path()).map_or(u64::MAX, |m| m.len());
    if len <= VERIFIED_ON_OPEN {
        file.verify()?;
    } else {
        file.check_checksums_up_to(CHECKED_ON_OPEN)?;
    }
    Ok(())
}

/// The bounds a fitted view frames: the shown data's ([`shown_bounds`], or the whole
/// file's), less particles far from the rest (lost atoms flying off a non-periodic box,
/// a sparse vapour around a droplet), which would shrink the material to a dot. A
/// particle is far when it lies outside the box of the bulk (the 1st to 99th percentile
/// along each axis, each cluster of the first level of at least 1024 counted
/// once) grown by [`FIT_MARGIN`] times its largest extent. The far ones are left out
/// only where that matters: when the whole shown data's bounding sphere is more than
/// twice the rest's; else (and with `all`) the bounds are the shown data's, and none
/// is counted far.
pub fn fit_bounds(file: &MdlodFile, hidden: HiddenSet, all: bool) -> FitBounds {
    let shown = shown_bounds(file, hidden);
    let shows_any = hidden.is_empty() || shown.is_some();
    let whole = shown.unwrap_or_else(|| data_bounds(file));
    let untrimmed = FitBounds {
        bounds: whole,
        far_particles: 0,
        shows_any,
    };
    if all || !shows_any {
        return untrimmed;
    }
    match trimmed_bounds(file, hidden) {
        Some(t) if t.far_particles > 0 && whole.radius() > 2.0 * t.bounds.radius() => t,
        _ => untrimmed,
    }
}

/// What a view fitted to the file frames under `opts` ([`fit_bounds`]). Hidden species
/// are left out of the fit (a solute without its solvent fills the image); the depth
/// range still holds all the data, as clusters holding hidden species may be drawn where
/// a budget stops the refinement, and so do far particles.
/// The fit frames the particles as `opts` draws them ([`drawn_reach`]), and with the cell
/// drawn ([`RenderOptions::cell`]) the cell too.
pub fn fit_for(file: &MdlodFile, opts: &RenderOptions) -> FitBounds {
    let hidden = opts.style.hidden_set(file.metadata());
    let fit = fit_bounds(file, hidden, opts.fit_all);
    // The spheres, splats or kernels as drawn, not the file's spheres. Where the
    // particles' own sizes span a decade and more, a splat's or kernel's reach past its
    // sphere counts up to a twentieth of the data's size: the largest of them (an SPH
    // halo's smoothing lengths, 10^4 of a galaxy's) would frame their faint wings and
    // leave the data a dot.
    let styled = drawn_reach(file, opts);
    let sphere = match opts.mode {
        RenderMode::Spheres | RenderMode::Sndf { .. } => styled,
        _ => styled_reach(file, opts, 1.0),
    };
    let mut wings = (styled - sphere).max(0.0);
    // Below a decade the cap grows as the square of the decade over the sizes' ratio, so
    // that the framing follows the ratio smoothly (a cap from 10 on alone put grains of
    // 0.5 to 4.99 mm and of 0.5 to 5 mm 3.5 % apart).
    let ratio = file
        .metadata()
        .radius
        .filter(|r| r.min > 0.0)
        .map(|r| f64::from(r.max) / f64::from(r.min));
    let extent = (fit.bounds.max - fit.bounds.min).max_element();
    if let Some(ratio) = ratio.filter(|_| extent.is_finite() && extent > 0.0) {
        let widen = (10.0 / ratio).max(1.0).powi(2) as f32;
        wings = wings.min(0.05 * extent * widen);
    }
    let reach = glam::Vec3::splat(sphere + wings);
    let drawn = Bounds::new(fit.bounds.min - reach, fit.bounds.max + reach);
    let bounds = if drawn.min.cmple(drawn.max).all() {
        drawn
    } else {
        fit.bounds
    };
    FitBounds {
        bounds: with_fitted_cell(bounds, file, opts, fit.far_particles > 0),
        ..fit
    }
}

/// `bounds` and, where `opts` draws the cell, the cell's box, less the faces that
/// particles left out of the fit as far from the rest (`trimmed`) stretched: a
/// shrink-wrapped cell follows a lost atom, and a view framing it made the material a
/// dot in every frame of a movie. Such a face is one the data reaches (within 1 % of
/// the cell's width) beyond the fitted bounds; it is still drawn.
fn with_fitted_cell(
    bounds: Bounds,
    file: &MdlodFile,
    opts: &RenderOptions,
    trimmed: bool,
) -> Bounds {
    let with = with_drawn_cell(bounds, file, opts);
    let (Some(_), Some(c), true) = (opts.cell, cell_bounds(file), trimmed) else {
        return with;
    };
    let whole = data_bounds(file);
    let (mut lo, mut hi) = (with.min, with.max);
    for k in 0..3 {
        let tol = 0.01 * (c.max[k] - c.min[k]);
        if c.min[k] < bounds.min[k] && whole.min[k] <= c.min[k] + tol {
            lo[k] = bounds.min[k];
        }
        if c.max[k] > bounds.max[k] && whole.max[k] >= c.max[k] - tol {
            hi[k] = bounds.max[k];
        }
    }
    Bounds::new(lo, hi)
}

/// The box around `file`'s simulation cell (its eight corners), where it has one.
/// `boxes` and, where `opts` draws the cell and there are boxes, its corners
/// ([`cell_corner_boxes`]).
fn with_cell_corners(
    mut boxes: Vec<Framed>,
    file: &MdlodFile,
    opts: &RenderOptions,
    fitted: &Bounds,
) -> Vec<Framed> {
    if opts.cell.is_some() && !boxes.is_empty() {
        boxes.extend(cell_corner_boxes(file, fitted).into_iter().map(Framed::Box));
    }
    boxes
}

/// The corners of the cell as boxes of no extent, within `fitted` (which leaves out faces
/// a lost atom stretched, [`fit_for`]): what a fit frames for the cell drawn (its bounding
/// box's corners lie outside a slanted cell, which then framed it small).
fn cell_corner_boxes(file: &MdlodFile, fitted: &Bounds) -> Vec<Bounds> {
    let Some(cell) = file.metadata().simulation_box.as_ref() else {
        return Vec::new();
    };
    // (Corners past single precision's range, of a box of 1e39, are not framed; the
    // others sort in a total order.)
    let mut corners: Vec<glam::Vec3> = overlay::cell_edges(cell)
        .iter()
        .flatten()
        .copied()
        .filter(|p| p.is_finite())
        .collect();
    corners.sort_by(|a, b| {
        (0..3)
            .map(|k| a[k].total_cmp(&b[k]))
            .find(|o| o.is_ne())
            .unwrap_or(std::cmp::Ordering::Equal)
    });
    corners.dedup();
    corners
        .into_iter()
        .map(|p| {
            let p = p.clamp(fitted.min, fitted.max);
            Bounds::new(p, p)
        })
        .collect()
}

/// The largest coordinate of a cell corner `--cell` draws: past it, differences of
/// single-precision coordinates (the cell's extent, the camera's distance) overflow.
pub const MAX_CELL_COORDINATE: f64 = 1e37;

/// Refuses to draw a cell (`opts.cell`) whose corners lie past
/// [`MAX_CELL_COORDINATE`] or are not numbers (a box of 1e39 a dump or a damaged file
/// gives), naming the box: a fit to it failed far from the data, and its corners broke
/// the sort that framed them.
fn check_cell(file: &MdlodFile, opts: &RenderOptions) -> Result<(), RenderError> {
    let (Some(_), Some(b)) = (opts.cell, file.metadata().simulation_box.as_ref()) else {
        return Ok(());
    };
    let corner = |i: f64, j: f64, k: f64| {
        [0, 1, 2].map(|d| b.origin[d] + i * b.a[d] + j * b.b[d] + k * b.c[d])
    };
    let far = (0..8)
        .flat_map(|n| {
            corner(
                f64::from(n & 1),
                f64::from((n >> 1) & 1),
                f64::from((n >> 2) & 1),
            )
        })
        .any(|v| v.is_nan() || v.abs() > MAX_CELL_COORDINATE);
    if far {
        return Err(RenderError::InvalidOptions(format!(
            "--cell: {}: the file's box (origin {:?}, a {:?}, b {:?}, c {:?}) reaches past \
             ±{MAX_CELL_COORDINATE:e}, where single precision cannot draw it: leave --cell out",
            file.path().display(),
            b.origin,
            b.a,
            b.b,
            b.c
        )));
    }
    Ok(())
}

pub fn cell_bounds(file: &MdlodFile) -> Option<Bounds> {
    let cell = file.metadata().simulation_box.as_ref()?;
    let (lo, hi) = overlay::cell_edges(cell).iter().flatten().fold(
        (glam::Vec3::INFINITY, glam::Vec3::NEG_INFINITY),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    );
    (lo.is_finite() && hi.is_finite()).then(|| Bounds::new(lo, hi))
}

/// The box `opts` draws `file`'s particles in: the top node's bounds (their spheres)
/// grown by how far the mode's footprint reaches past them ([`drawn_reach`]: a splat's
/// Gaussian, a density kernel's support).
pub fn drawn_bounds(file: &MdlodFile, opts: &RenderOptions) -> Option<Bounds> {
    let top = file.nodes().first()?;
    let reach = drawn_reach(file, opts).max(0.0);
    Some(Bounds::new(
        glam::Vec3::from(top.bounds_min) - reach,
        glam::Vec3::from(top.bounds_max) + reach,
    ))
}

/// How far past a particle's own sphere `opts` draws it: the style's radii (`--radius-scale`,
/// a species' radius) times what the mode's footprint reaches in radii (a splat's
/// truncated Gaussian, a density kernel's support), less the file's radius; the largest
/// over the species (negative where every species is drawn smaller than the file's
/// spheres).
fn drawn_reach(file: &MdlodFile, opts: &RenderOptions) -> f32 {
    styled_reach(file, opts, footprint(opts))
}

/// How far the mode's footprint reaches, in radii: a sphere's 1, a splat's truncated
/// Gaussian, a density kernel's support.
fn footprint(opts: &RenderOptions) -> f32 {
    match &opts.mode {
        RenderMode::Spheres | RenderMode::Sndf { .. } => 1.0,
        RenderMode::Splat { .. } | RenderMode::SplatOver { .. } => opts.splat_support,
        RenderMode::Density(d) => d.kernel_scale.max(1.0),
    }
}

/// The radius each species is drawn at under `opts`'s style (its own where the style
/// cannot be applied).
fn drawn_species_radii(file: &MdlodFile, opts: &RenderOptions) -> Vec<f32> {
    let species = &file.metadata().species;
    match opts.style.species_table(species) {
        Ok(table) => table.iter().map(|t| t[3]).collect(),
        Err(_) => species.iter().map(|s| s.radius).collect(),
    }
}

/// How far past the file's spheres the style's radii reach, each times `footprint`: the
/// largest over the species, 0 where the style cannot be applied.
fn styled_reach(file: &MdlodFile, opts: &RenderOptions, footprint: f32) -> f32 {
    let drawn = drawn_species_radii(file, opts);
    // Particles of their own sizes are drawn scaled as their species: the reach past
    // their spheres is largest at one end of the species' sizes.
    let reach = drawn
        .iter()
        .enumerate()
        .map(|(i, &r)| {
            let [lo, hi] = file.species_radius_span(i);
            let [drawn_lo, drawn_hi] = file.species_radius_span_at(i, r);
            (drawn_lo * footprint - lo).max(drawn_hi * footprint - hi)
        })
        .fold(f32::NEG_INFINITY, f32::max);
    if reach.is_finite() {
        reach
    } else {
        0.0
    }
}

/// Clusters the fit frames in place of the whole box `fitted` ([`fit_for`]'s): the boxes
/// of the first level of at least [`FRAMING_NODES`] nodes that hold a species shown, grown
/// as [`drawn_reach`] grows the bounds and clipped to `fitted` (so that atoms the fit
/// leaves out stay out), with the cell where it is drawn. A sphere of atoms, a droplet or
/// a disc seen obliquely then fills the image, where its box's empty corners made it
/// small. Clusters holding both shown and hidden species are opened, down to the level
/// above the particles and up to [`FRAMING_OPEN`] nodes. A file with too few clusters (a
/// molecule, a nanoparticle of a few hundred atoms: the particles and the top node) is
/// framed by its particles' own spheres, up to [`FRAMING_OPEN`] of them; empty beyond.
pub fn framing_boxes(file: &MdlodFile, opts: &RenderOptions, fitted: &Bounds) -> Vec<Framed> {
    use mdlod_format::reader::{BELOW_IN, BELOW_OUT};
    let levels = file.levels();
    let last = levels.len().saturating_sub(1);
    let Some(level) = (0..last).find(|&l| levels[l].point_count >= FRAMING_NODES) else {
        return particle_boxes(file, opts, fitted);
    };
    let Ok(count) = usize::try_from(levels[level].point_count) else {
        return Vec::new();
    };
    if file.check_nodes(level, 0..count).is_err() {
        return Vec::new();
    }
    let kind_of = species_kinds(file, opts.style.hidden_set(file.metadata()));
    let reach = glam::Vec3::splat(drawn_reach(file, opts).max(0.0));
    let clipped = |n: &mdlod_format::NodeRecord| {
        let lo = (glam::Vec3::from(n.bounds_min) - reach).max(fitted.min);
        let hi = (glam::Vec3::from(n.bounds_max) + reach).min(fitted.max);
        lo.cmple(hi).all().then(|| Bounds::new(lo, hi))
    };
    // Nodes holding shown and hidden species are opened (down to the level above the
    // particles, within a budget), so that a solute's fit is not its solvent's boxes.
    let mut work: Vec<(usize, usize)> = (0..count).map(|i| (level, i)).collect();
    let mut opened = 0usize;
    let mut boxes = Vec::new();
    while let Some((l, i)) = work.pop() {
        let Some(id) = usize::try_from(levels[l].node_first)
            .ok()
            .and_then(|f| f.checked_add(i))
        else {
            continue;
        };
        let Some(n) = file.nodes().get(id) else {
            continue;
        };
        let kind = kind_of(id);
        if kind & BELOW_OUT == 0 {
            continue;
        }
        let (cf, cc) = (n.child_first as usize, n.child_count as usize);
        let mixed = kind & BELOW_IN != 0;
        if mixed
            && l + 2 < levels.len()
            && opened + cc <= FRAMING_OPEN
            && file.check_nodes(l + 1, cf..cf + cc).is_ok()
        {
            opened += cc;
            work.extend((cf..cf + cc).map(|c| (l + 1, c)));
        } else if let Some(b) = clipped(n) {
            boxes.push(Framed::Box(b));
        }
    }
    with_cell_corners(boxes, file, opts, fitted)
}

/// [`framing_boxes`] of a file without a level of [`FRAMING_NODES`] clusters: each shown
/// particle's sphere as drawn (a ball: its outline, not its box's corners, fills the
/// image), those centred within `fitted` (so that atoms the fit leaves out stay out),
/// each no larger than `fitted` holds, with the cell where it is drawn.
fn particle_boxes(file: &MdlodFile, opts: &RenderOptions, fitted: &Bounds) -> Vec<Framed> {
    let last = file.levels().len().saturating_sub(1);
    let count = file.levels().last().map_or(0, |l| l.point_count);
    if last == 0 || count == 0 || count > FRAMING_OPEN as u64 {
        return Vec::new();
    }
    let Ok(points) = file.decode_level(last) else {
        return Vec::new();
    };
    let test = file.hidden_test(&opts.style.hidden_set(file.metadata()));
    // Each particle as drawn: its radius scaled as its species' is by the style, times
    // the mode's footprint (species scaled differently were framed by the largest
    // scale's reach, off centre).
    let drawn = drawn_species_radii(file, opts);
    let species = &file.metadata().species;
    let reach_of = footprint(opts);
    let drawn_radius = |i: usize| {
        let s = file.species().get(i).map(|&s| usize::from(s));
        let own = s.and_then(|s| species.get(s)).map_or(0.0, |sp| sp.radius);
        let styled = s.and_then(|s| drawn.get(s)).copied().unwrap_or(own);
        let r = if own > 0.0 {
            file.particle_radius(i) * (styled / own)
        } else {
            styled
        };
        r * reach_of
    };
    let boxes: Vec<Framed> = points
        .iter()
        .enumerate()
        .filter(|(i, _)| !file.hides_particle(&test, *i))
        .filter_map(|(i, p)| {
            let centre = glam::Vec3::from(*p);
            let inside = centre.cmpge(fitted.min).all() && centre.cmple(fitted.max).all();
            // Within `fitted`, as the boxes were clipped to it: it caps the reach of
            // kernels' wings ([`fit_for`]).
            let room = (centre - fitted.min).min(fitted.max - centre).min_element();
            inside.then(|| Framed::Ball {
                centre,
                radius: drawn_radius(i).min(room).max(0.0),
            })
        })
        .collect();
    with_cell_corners(boxes, file, opts, fitted)
}

/// The nodes a fit frames come from the first level with at least this many.
pub const FRAMING_NODES: u64 = 64;

/// The most nodes [`framing_boxes`] opens below mixed ones.
const FRAMING_OPEN: usize = 1 << 14;

/// `bounds` and, where `opts` draws the cell, the cell's box.
fn with_drawn_cell(bounds: Bounds, file: &MdlodFile, opts: &RenderOptions) -> Bounds {
    match (opts.cell, cell_bounds(file)) {
        (Some(_), Some(c)) => Bounds::new(bounds.min.min(c.min), bounds.max.max(c.max)),
        _ => bounds,
    }
}

/// Which species are below node `id` with the species of `hidden` hidden
/// ([`MdlodFile::species_below`]; every node's `BELOW_OUT` when none is).
fn species_kinds(file: &MdlodFile, hidden: HiddenSet) -> impl Fn(usize) -> u8 + '_ {
    use mdlod_format::reader::{BELOW_IN, BELOW_OUT};
    let kinds = (!hidden.is_empty()).then(|| file.hidden_below(&hidden));
    move |id| match &kinds {
        Some(k) => k.get(id).copied().unwrap_or(BELOW_IN | BELOW_OUT),
        None => BELOW_OUT,
    }
}

/// [`fit_bounds`] without its test of whether trimming matters; `None` where the file
/// has too few clusters to tell a bulk from its outliers.
fn trimmed_bounds(file: &MdlodFile, hidden: HiddenSet) -> Option<FitBounds> {
    use mdlod_format::reader::BELOW_OUT;
    let (nodes, levels) = (file.nodes(), file.levels());
    let last = levels.len().checked_sub(1)?;
    let kind_of = species_kinds(file, hidden);
    // What places the bulk: the centres of the clusters of the first level of at least
    // 1024, each counted once (the PCA splits cut clusters by count, so a level's
    // clusters hold about as many particles each); in a file without one (a few
    // thousand particles), the particles themselves. Not by area: particles of their own
    // sizes spanning decades (an SPH run's smoothing lengths) made the small, dense ones
    // "far" from the large ones' bulk.
    let mut sample: Vec<(glam::Vec3, f32)> = Vec::new();
    if let Some(level) = (0..last).find(|&l| levels[l].point_count >= 1024) {
        let first = usize::try_from(levels[level].node_first).ok()?;
        let count = usize::try_from(levels[level].point_count).ok()?;
        file.check_nodes(level, 0..count).ok()?;
        sample.extend(
            nodes
                .get(first..first.checked_add(count)?)?
                .iter()
                .enumerate()
                .filter(|(i, _)| kind_of(first + i) & BELOW_OUT != 0)
                .map(|(_, n)| {
                    let (a, b) = (
                        glam::Vec3::from(n.bounds_min),
                        glam::Vec3::from(n.bounds_max),
                    );
                    ((a + b) * 0.5, 1.0f32)
                }),
        );
    } else if file.delta_n() == 1 {
        let parents = last.checked_sub(1)?;
        let first = usize::try_from(levels[parents].node_first).ok()?;
        let count = usize::try_from(levels[parents].point_count).ok()?;
        file.check_nodes(parents, 0..count).ok()?;
        for n in nodes.get(first..first.checked_add(count)?)? {
            sample.extend(shown_particles(file, n, hidden).map(|(p, _)| (p, 1.0f32)));
        }
    }
    sample.retain(|(c, w)| c.is_finite() && w.is_finite());
    if sample.len() < 32 {
        return None;
    }
    let total: f64 = sample.iter().map(|s| f64::from(s.1)).sum();
    // The 1st and 99th weighted percentiles along `axis`, from one sort.
    let percentiles = |axis: usize| {
        let mut v: Vec<(f32, f32)> = sample.iter().map(|(c, w)| (c[axis], *w)).collect();
        v.sort_by(|a, b| a.0.total_cmp(&b.0));
        let at = |q: f64| {
            let mut sum = 0.0;
            v.iter()
                .find(|(_, w)| {
                    sum += f64::from(*w);
                    sum >= q * total
                })
                .or(v.last())
                .map_or(0.0, |p| p.0)
        };
        (at(0.01), at(0.99))
    };
    let [(x0, x1), (y0, y1), (z0, z1)] = [0, 1, 2].map(percentiles);
    let (lo, hi) = (glam::Vec3::new(x0, y0, z0), glam::Vec3::new(x1, y1, z1));
    // At least the smallest sphere's diameter (and a little more for rounding): a bulk
    // of no extent (particles piled on one spot) otherwise left every sphere that
    // reaches past its centre out as far, and the view was fitted to nothing. (Not the
    // largest: a few huge spheres among small ones are what the fit leaves out.)
    let smallest = file
        .metadata()
        .species
        .iter()
        .map(mdlod_format::meta::Species::smallest_radius)
        .filter(|r| r.is_finite() && *r > 0.0)
        .fold(f32::INFINITY, f32::min);
    let smallest = if smallest.is_finite() { smallest } else { 0.0 };
    let floor = 2.0 * smallest + 1e-6 * lo.abs().max(hi.abs()).max_element();
    let margin = glam::Vec3::splat(((hi - lo).max_element() * FIT_MARGIN).max(floor));
    let (bounds, far) = bounds_walk(file, hidden, Some([lo - margin, hi + margin]))?;
    Some(FitBounds {
        bounds,
        far_particles: far,
        shows_any: true,
    })
}

/// The bounds of the particles not of the species of `hidden` (a mask) within the box
/// `core` (everywhere without one), and how many lie outside it: from the top node
/// down, a node holding hidden species only is passed over, one inside `core` holding
/// shown species only adds its box, one wholly outside counts its particles, and any
/// other is opened (at most [`SHOWN_BOUNDS_NODES`] of them; one not opened adds its
/// box) down to the particles, decoded where they are encoded relative to it (δn = 1;
/// else its box). `None` when nothing is shown.
fn bounds_walk(
    file: &MdlodFile,
    hidden: HiddenSet,
    core: Option<[glam::Vec3; 2]>,
) -> Option<(Bounds, u64)> {
    use mdlod_format::reader::{BELOW_IN, BELOW_OUT};
    let (nodes, levels) = (file.nodes(), file.levels());
    let last = levels.len().checked_sub(1)?;
    let kind_of = species_kinds(file, hidden);
    let inside = |a: glam::Vec3, b: glam::Vec3| {
        core.is_none_or(|[lo, hi]| a.cmpge(lo).all() && b.cmple(hi).all())
    };
    let outside = |a: glam::Vec3, b: glam::Vec3| {
        core.is_some_and(|[lo, hi]| a.cmpgt(hi).any() || b.cmplt(lo).any())
    };
    let mut lo = glam::Vec3::splat(f32::INFINITY);
    let mut hi = glam::Vec3::splat(f32::NEG_INFINITY);
    let mut far = 0u64;
    let mut queue = std::collections::VecDeque::from([0usize]);
    let mut opened = 0usize;
    while let Some(id) = queue.pop_front() {
        let Some(n) = nodes.get(id) else { continue };
        let kind = kind_of(id);
        if kind & BELOW_OUT == 0 {
            continue; // Hidden species only.
        }
        let (bmin, bmax) = (
            glam::Vec3::from(n.bounds_min),
            glam::Vec3::from(n.bounds_max),
        );
        let mixed = kind & BELOW_IN != 0;
        if outside(bmin, bmax) {
            far += particles_below(file, id);
            continue;
        }
        if inside(bmin, bmax) && !mixed {
            lo = lo.min(bmin);
            hi = hi.max(bmax);
            continue;
        }
        let child_level = usize::from(n.level) + 1;
        if child_level == last && file.delta_n() == 1 && file.check_children(id).is_ok() {
            // The particles themselves, encoded relative to this node. Within a core, a
            // sphere reaching past a quarter of the core's size (an SPH void particle's
            // smoothing length, 30 times a galaxy's) frames that far only, counted as
            // far: a handful of them made the galaxy a dot.
            for (p, r) in shown_particles(file, n, hidden) {
                if inside(p, p) {
                    let reach = match core {
                        Some([a, b]) if r > 0.25 * (b - a).max_element() => {
                            far += 1;
                            0.25 * (b - a).max_element()
                        }
                        _ => r,
                    };
                    lo = lo.min(p - reach);
                    hi = hi.max(p + reach);
                } else {
                    far += 1;
                }
            }
            continue;
        }
        if child_level < last && opened < SHOWN_BOUNDS_NODES && file.check_children(id).is_ok() {
            opened += 1;
            let first = levels[child_level].node_first as usize;
            let children = n.child_first as usize..(n.child_first + n.child_count) as usize;
            queue.extend(children.map(|c| first + c));
            continue;
        }
        lo = lo.min(bmin);
        hi = hi.max(bmax);
    }
    (lo.is_finite() && hi.is_finite() && lo.cmple(hi).all()).then(|| (Bounds::new(lo, hi), far))
}

/// The particles below node `id`: its descendants on the last level, a contiguous range
/// from its first child's first child ... to its last child's last child. 0 where a
/// record on the way cannot be read.
fn particles_below(file: &MdlodFile, id: usize) -> u64 {
    let (nodes, levels) = (file.nodes(), file.levels());
    let last = levels.len().saturating_sub(1);
    let (mut a, mut b) = (id, id);
    loop {
        let (Some(na), Some(nb)) = (nodes.get(a), nodes.get(b)) else {
            return 0;
        };
        if file.check_children(a).is_err() || file.check_children(b).is_err() {
            return 0;
        }
        let child_level = usize::from(na.level) + 1;
        let (fa, lb) = (
            u64::from(na.child_first),
            u64::from(nb.child_first) + u64::from(nb.child_count),
        );
        if child_level >= last {
            return lb.saturating_sub(fa);
        }
        let Some(base) = levels.get(child_level).map(|l| l.node_first) else {
            return 0;
        };
        a = (base + fa) as usize;
        b = (base + lb.saturating_sub(1)) as usize;
    }
}

/// The largest image side any mode renders or samples, in pixels (adapters allow at
/// most this many per side, many fewer). Checked before the traversal, whose tiles and
/// occlusion buffers grow with the image.
pub const MAX_IMAGE_SIDE: u32 = 32768;

/// Checks an image size against [`MAX_IMAGE_SIDE`].
pub fn check_image_size(width: u32, height: u32) -> Result<(), RenderError> {
    if width == 0 || height == 0 || width > MAX_IMAGE_SIDE || height > MAX_IMAGE_SIDE {
        return Err(RenderError::InvalidOptions(format!(
            "image size {width}x{height} (width and height must each be 1 to {MAX_IMAGE_SIDE})"
        )));
    }
    Ok(())
}

/// Checks a camera built from finite inputs: its numbers finite and its depth range
/// usable (`near < far`, both finite), which a view very far from the data breaks (the
/// distance overflows, or the data's depth is lost in the distance's rounding).
fn check_built_camera(c: &Camera) -> Result<(), String> {
    let depth_ok = c.near.is_finite() && c.far.is_finite() && c.near < c.far;
    if !(c.distance.is_finite() && c.eye().is_finite() && depth_ok) {
        // Name the target too: a target far from the data (a view file's, --target)
        // leaves the data's depth to rounding at any distance.
        let num = |v: f32| match v == 0.0 || (1e-3..1e5).contains(&v.abs()) {
            true => format!("{v}"),
            false => format!("{v:e}"),
        };
        let t = c.target;
        return Err(format!(
            "the camera, {} from its target [{}, {}, {}], is too far from the data to draw \
             it (depth range {:e} to {:e} in single precision): bring it closer, or look at a \
             target near the data",
            num(c.distance),
            num(t.x),
            num(t.y),
            num(t.z),
            c.near,
            c.far
        ));
    }
    c.check()
}

/// Whether data within `bounds` can be framed in single precision: its extent finite
/// and its coordinates within ±10^30 (the converter refuses coordinates past ±10^37;
/// only a damaged or hostile file holds more).
pub fn drawable_bounds(bounds: &Bounds) -> bool {
    let (min, max) = (bounds.min, bounds.max);
    (max - min).as_dvec3().length() < f64::from(f32::MAX)
        && min.abs().max(max.abs()).max_element() <= 1e30
}

/// `e`, from building the camera that fits `view` to `file`'s data within `fitted`,
/// said of the file when the data spans more than single precision can draw (a camera
/// would stand at an infinite distance): no option given can mend that.
fn undrawable(file: &MdlodFile, fitted: &Bounds, view: &ViewSpec, e: RenderError) -> RenderError {
    let RenderError::InvalidOptions(message) = &e else {
        return e;
    };
    if matches!(view, ViewSpec::Camera(_)) || drawable_bounds(fitted) {
        return e;
    }
    RenderError::Data {
        path: file.path().to_path_buf(),
        message: format!(
            "the data's bounds, {}, span more than single precision can draw: {message}",
            bounds_text(fitted)
        ),
    }
}

/// Bounds as messages give them: `[x, y, z] to [x, y, z]`, in exponent form.
pub fn bounds_text(b: &Bounds) -> String {
    let (min, max) = (b.min, b.max);
    format!(
        "[{:e}, {:e}, {:e}] to [{:e}, {:e}, {:e}]",
        min.x, min.y, min.z, max.x, max.y, max.z
    )
}

/// The camera `view` gives for `file` and an image of `width` × `height`.
pub fn camera_for(
    file: &MdlodFile,
    view: &ViewSpec,
    width: u32,
    height: u32,
) -> Result<Camera, RenderError> {
    // The camera a render with default options takes ([`frame_setup`]): the material's
    // fit, framed by its clusters.
    let opts = RenderOptions {
        view: view.clone(),
        width,
        height,
        ..Default::default()
    };
    Ok(frame_setup(file, &opts)?.0)
}

/// [`camera_for`] data within `bounds` (the union of several files' bounds, to frame a
/// whole trajectory alike).
pub fn camera_for_bounds(
    bounds: &Bounds,
    view: &ViewSpec,
    width: u32,
    height: u32,
) -> Result<Camera, RenderError> {
    camera_in(bounds, view, width, height)
}

/// [`camera_for`] data within `bounds`.
fn camera_in(
    bounds: &Bounds,
    view: &ViewSpec,
    width: u32,
    height: u32,
) -> Result<Camera, RenderError> {
    camera_for_framing(bounds, &[], view, width, height)
}

/// [`camera_for_bounds`] framing `boxes` inside `bounds` where the view is fitted
/// ([`Camera::fit_boxes`]; [`framing_boxes`] gives a file's): a still's clusters, or a
/// trajectory's frames'.
pub fn camera_for_framing(
    bounds: &Bounds,
    boxes: &[Framed],
    view: &ViewSpec,
    width: u32,
    height: u32,
) -> Result<Camera, RenderError> {
    camera_for_framing_in(bounds, boxes, view, width, height, &[])
}

/// [`camera_for_framing`] fitting into the best of `windows` of the image (none: the
/// whole image; [`RenderOptions::fit_windows`]).
pub fn camera_for_framing_in(
    bounds: &Bounds,
    boxes: &[Framed],
    view: &ViewSpec,
    width: u32,
    height: u32,
    windows: &[FitWindow],
) -> Result<Camera, RenderError> {
    let windows = if windows.is_empty() {
        &[FitWindow::WHOLE][..]
    } else {
        windows
    };
    let bounds = *bounds;
    let aspect = width.max(1) as f32 / height.max(1) as f32;
    Ok(match view {
        ViewSpec::Default { .. } => {
            // No file to ask whether the data is flat: the three-dimensional view.
            return camera_for_framing_in(
                &bounds,
                boxes,
                &view.with_flat_axis(None),
                width,
                height,
                windows,
            );
        }
        ViewSpec::Orbit {
            azimuth_deg,
            elevation_deg,
            zoom,
            projection,
        } => {
            if !(zoom.is_finite() && *zoom > 0.0) {
                return Err(RenderError::InvalidOptions(format!(
                    "zoom {zoom} (must be positive and finite)"
                )));
            }
            for (what, v) in [("azimuth", azimuth_deg), ("elevation", elevation_deg)] {
                if !v.is_finite() {
                    return Err(RenderError::InvalidOptions(format!(
                        "{what} {v}° (must be a finite angle)"
                    )));
                }
            }
            // Past the pole the view would turn over: say so instead of clamping.
            if !(-90.0..=90.0).contains(elevation_deg) {
                return Err(RenderError::InvalidOptions(format!(
                    "elevation {elevation_deg}° (must be -90 to 90: 90 looks straight down; \
                     for the other side, add 180 to the azimuth)"
                )));
            }
            let v = ViewFile {
                projection: *projection,
                azimuth_deg: *azimuth_deg,
                elevation_deg: *elevation_deg,
                zoom: *zoom,
                ..Default::default()
            };
            let c = v.to_camera_framing_in(&bounds, boxes, aspect, windows);
            check_built_camera(&c)
                .map_err(|e| RenderError::InvalidOptions(format!("zoom {zoom:e}: {e}")))?;
            c
        }
        ViewSpec::File(path) | ViewSpec::FileWith(path, _) => {
            let mut v = ViewFile::load(path)?;
            if let ViewSpec::FileWith(_, changes) = view {
                if changes.apply(&mut v) {
                    v.check().map_err(|e| {
                        RenderError::InvalidOptions(format!("{} changed: {e}", path.display()))
                    })?;
                }
            }
            let c = v.to_camera_framing_in(&bounds, boxes, aspect, windows);
            check_built_camera(&c).map_err(|message| RenderError::View {
                path: path.clone(),
                message,
            })?;
            c
        }
        ViewSpec::View(v) => {
            v.check().map_err(RenderError::InvalidOptions)?;
            let c = v.to_camera_framing_in(&bounds, boxes, aspect, windows);
            check_built_camera(&c).map_err(RenderError::InvalidOptions)?;
            c
        }
        ViewSpec::Camera(c) => {
            c.check().map_err(RenderError::InvalidOptions)?;
            let mut c = c.clone();
            c.fit_depth_range(&bounds);
            check_built_camera(&c).map_err(RenderError::InvalidOptions)?;
            c
        }
    })
}

/// The checks of [`frame_setup`] that need no file: the image size, the screen error,
/// the exposure.
fn check_numbers(opts: &RenderOptions) -> Result<(), RenderError> {
    check_image_size(opts.width, opts.height)?;
    if !(opts.error_px.is_finite() && opts.error_px >= 0.0) {
        return Err(RenderError::InvalidOptions(format!(
            "screen error {} px (must be a finite number, 0 or more)",
            opts.error_px
        )));
    }
    if let Some(e) = opts.exposure.filter(|e| !(e.is_finite() && *e > 0.0)) {
        return Err(RenderError::InvalidOptions(format!(
            "exposure {e} (must be a finite number above 0)"
        )));
    }
    Ok(())
}

/// The camera, traversal and frame settings `opts` asks for, checked (for callers that
/// drive a [`StreamingRenderer`] themselves, like the viewer).
pub fn frame_setup(
    file: &MdlodFile,
    opts: &RenderOptions,
) -> Result<(Camera, TraversalSettings, FrameSettings), RenderError> {
    check_numbers(opts)?;
    check_cell(file, opts)?;
    // The default view (and a view file giving no angle) faces flat data square on.
    let resolved;
    let opts = if opts.view.depends_on_data() {
        resolved = RenderOptions {
            view: opts.view.resolved(file),
            ..opts.clone()
        };
        &resolved
    } else {
        opts
    };
    if opts.transparent
        && matches!(
            opts.mode,
            RenderMode::Splat { .. } | RenderMode::Sndf { .. }
        )
    {
        return Err(RenderError::InvalidOptions(
            "a transparent background is drawn in the spheres, splat-over, density and iso \
             modes (additive splats add light to a background, S-NDFs shade onto one)"
                .into(),
        ));
    }
    // The splats and the volume draw no style's species table, which the spheres use to
    // draw a species past the first 64 as nothing: the traversal's mask must name it.
    let styled = matches!(opts.mode, RenderMode::Spheres | RenderMode::Sndf { .. });
    let species = &file.metadata().species;
    if let Some(s) = species.iter().skip(64).find(|s| {
        !styled
            && opts
                .style
                .species
                .iter()
                .any(|st| st.hidden && st.name == s.name)
    }) {
        return Err(RenderError::InvalidOptions(format!(
            "species {:?} is hidden, but the splat and volume modes hide only a file's first \
             64 species (it is species {} of {})",
            s.name,
            species.iter().position(|x| x.name == s.name).unwrap_or(0) + 1,
            species.len()
        )));
    }
    // Every mode's style, checked whole here (the packers check the styles they draw
    // with, which in the splat and volume modes are not the user's).
    opts.style.validate().map_err(RenderError::InvalidOptions)?;
    if !opts.style.hidden_values.is_empty() && file.hiding_attribute().is_none() {
        return Err(RenderError::InvalidOptions(
            "the file has no per-particle attribute to hide particles by (a file keeps the \
             one dump column `mdlod convert --attribute COLUMN` names, e.g. --attribute c_cna)"
                .into(),
        ));
    }
    // A camera given whole (the viewer's, every frame) fits nothing: its depth range
    // takes the data's bounds, and the fit is not computed.
    let fitted = match opts.view {
        ViewSpec::Camera(_) => data_bounds(file),
        _ => fit_for(file, opts).bounds,
    };
    // The clusters of a coarse level frame data that does not fill its box.
    let boxes = match opts.view {
        ViewSpec::Camera(_) => Vec::new(),
        _ => framing_boxes(file, opts, &fitted),
    };
    let mut camera = camera_for_framing_in(
        &fitted,
        &boxes,
        &opts.view,
        opts.width,
        opts.height,
        &opts.fit_windows,
    )
    .map_err(|e| undrawable(file, &fitted, &opts.view, e))?;
    // The depth range holds all the data, and the cell where it is drawn.
    let depth = with_drawn_cell(data_bounds(file), file, opts);
    if fitted != depth {
        camera.fit_depth_range(&depth);
    }
    // The data's bounds hold the particles' own spheres; a style that draws them larger
    // reaches past them, and a sphere in front of the near plane is clipped whole (its
    // quad lies at its front). The depth range grows by as much.
    let extra = styled_reach(file, opts, 1.0);
    if extra > 0.0 {
        let reach = glam::Vec3::splat(extra);
        camera.fit_depth_range(&Bounds::new(depth.min - reach, depth.max + reach));
    }
    let traversal = TraversalSettings {
        viewport: [opts.width, opts.height],
        error_px: opts.error_px,
        budget_points: opts.budget.max(1),
        occlusion: if !opts.occlusion
            || !opts.style.culls(&file.metadata().species)
            || matches!(
                opts.mode,
                RenderMode::Splat { .. } | RenderMode::SplatOver { .. } | RenderMode::Density(_)
            ) {
            // Splats and densities hide nothing.
            OcclusionMode::Off
        } else if matches!(opts.mode, RenderMode::Sndf { .. }) {
            // Jittered sampling: only whole covered pixels occlude.
            OcclusionMode::WholePixels
        } else if opts.spp <= 1 {
            OcclusionMode::PixelCentres
        } else {
            OcclusionMode::WholePixels
        },
        // Kernels reach past their nodes' boxes: nodes just outside the view add
        // density inside it.
        support_scale: match &opts.mode {
            RenderMode::Density(d) => d.kernel_scale,
            // Splats reaching farther than their default: nodes just outside the view
            // add light inside it.
            RenderMode::Splat { .. } | RenderMode::SplatOver { .. }
                if opts.splat_support > passes::splat::DEFAULT_SUPPORT =>
            {
                opts.splat_support
            }
            _ => 0.0,
        },
        // Every mode leaves hidden species out of the cut (splats, the volume: the
        // light or density of the species shown).
        hidden: opts.style.hidden_set(file.metadata()),
        // The density volume clips its samples, not the points (DensitySettings::clip).
        clip: match opts.mode {
            RenderMode::Density(_) if !opts.style.clip.is_empty() => {
                return Err(RenderError::InvalidOptions(
                    "the density volume clips its samples (its own clip plane), not the \
                     points: leave the style's clip planes empty"
                        .into(),
                ))
            }
            _ => opts
                .style
                .clip_planes()
                .map_err(RenderError::InvalidOptions)?,
        },
    };
    let settings = FrameSettings {
        width: opts.width,
        height: opts.height,
        spp: opts.spp,
        background_srgb: opts.background,
        transparent: opts.transparent,
        lighting: opts.lighting,
        read_depth: false,
        style: opts.style.clone(),
    };
    Ok((camera, traversal, settings))
}

/// The particles of `draw` whose species the style hides (sphere and S-NDF modes) that
/// are in its runs: only where the traversal cannot leave them out (a hidden species of
/// index 64 or more, past [`TraversalSettings::hidden_species`]); else none.
fn hidden_in_cut(file: &MdlodFile, opts: &RenderOptions, draw: &DrawList) -> u64 {
    let styled = matches!(opts.mode, RenderMode::Spheres | RenderMode::Sndf { .. });
    let meta = file.metadata();
    let hidden: Vec<bool> = meta
        .species
        .iter()
        .map(|s| {
            opts.style
                .species
                .iter()
                .any(|st| st.hidden && st.name == s.name)
        })
        .collect();
    if !styled || !hidden.contains(&true) || opts.style.hidden_mask(&meta.species) != 0 {
        return 0;
    }
    let last = file.level_count() - 1;
    let species = file.species();
    draw.ranges
        .iter()
        .filter(|r| usize::from(r.level) == last)
        .flat_map(|r| species.get(r.first as usize..(r.first + r.count) as usize))
        .flatten()
        .filter(|&&s| hidden.get(usize::from(s)).copied().unwrap_or(false))
        .count() as u64
}

impl RenderReport {
    /// The report of one drawn frame (times other than the GPU's left at zero).
    fn new(
        renderer: &Renderer,
        file: &MdlodFile,
        opts: &RenderOptions,
        camera: Camera,
        traversal: &TraversalSettings,
        draw: &DrawList,
        frame: &RenderedFrame,
    ) -> RenderReport {
        RenderReport {
            width: opts.width,
            height: opts.height,
            spp: opts.spp,
            particles_drawn: draw.particles,
            particles_hidden: hidden_in_cut(file, opts, draw) + draw.hidden_particles,
            clusters_mixed: draw.mixed_drawn,
            particles_clipped: draw.clipped_particles,
            clusters_across: draw.across_drawn,
            species_drawn: opts
                .species_drawn
                .then(|| traversal::species_drawn(file, draw)),
            nodes_drawn: draw.representatives,
            ranges: draw.ranges.len(),
            nodes_opened: draw.opened_nodes,
            nodes_occluded: draw.occluded_nodes,
            particles_occluded: draw.occluded_particles,
            error_px: draw.error_px,
            budget_limited: draw.budget_limited,
            pool_limited: false,
            budget: traversal.budget_points,
            adapter: renderer.ctx.adapter_name().to_string(),
            backend: format!("{:?}", renderer.ctx.backend()),
            camera,
            traversal_time: Duration::ZERO,
            gpu_time: frame.gpu_time,
            total_time: Duration::ZERO,
            frames: 1,
            first_frame_time: None,
            gpu_data_bytes: frame.gpu_data_bytes,
            gpu_target_bytes: frame.gpu_target_bytes,
            exposure: None,
            total_flux: None,
            light_range: None,
            light_extent: None,
            density_stacks: None,
            density_readbacks: None,
            density_host_time: None,
            light_map: None,
        }
    }
}

/// Renders an open file with an existing renderer.
pub fn render_image(
    renderer: &Renderer,
    file: &MdlodFile,
    opts: &RenderOptions,
) -> Result<(RgbaImage, RenderReport), RenderError> {
    render_image_keeping(renderer, file, opts, &mut KeptCut::default())
}

/// The last cut [`render_image_keeping`] chose, with the camera and traversal settings
/// it was chosen for.
///
/// A cut depends on nothing else: lights, colours and the background leave it as it is, and the traversal is most of a frame's time for a
/// large file (on a software driver, 65-90 ms of a 10^6-particle frame's 90-110). A
/// window that re-lights or re-colours a still view draws the kept cut again. It belongs
/// to one open file: use another (or [`KeptCut::clear`]) for another file.
#[derive(Clone, Debug, Default)]
pub struct KeptCut {
    kept: Option<(Camera, TraversalSettings, DrawList)>,
    chosen: u64,
}

impl KeptCut {
    /// Forgets the cut (another file is to be drawn).
    pub fn clear(&mut self) {
        self.kept = None;
    }

    /// How many cuts were chosen (traversals run) through it.
    pub fn chosen(&self) -> u64 {
        self.chosen
    }
}

/// [`render_image`], drawing `kept`'s cut where the frame's camera and traversal settings
/// are those it was chosen for, and keeping this frame's cut otherwise. The report's
/// traversal time is then that of finding the cut kept (next to nothing).
pub fn render_image_keeping(
    renderer: &Renderer,
    file: &MdlodFile,
    opts: &RenderOptions,
    kept: &mut KeptCut,
) -> Result<(RgbaImage, RenderReport), RenderError> {
    let t0 = Instant::now();
    let (camera, traversal, settings) = frame_setup(file, opts)?;
    let entry = match kept.kept.take() {
        Some(k) if k.0 == camera && k.1 == traversal => k,
        _ => {
            renderer.reporter().stage("choosing the cut", None, "nodes");
            let draw = traverse(&camera, file, &traversal);
            renderer.reporter().finish_stage();
            file.node_error()?;
            kept.chosen += 1;
            (camera.clone(), traversal, draw)
        }
    };
    let (_, _, draw) = kept.kept.insert(entry);
    let draw = &*draw;
    let traversal_time = t0.elapsed();
    if let RenderMode::Sndf {
        iterations,
        bins,
        binning,
    } = opts.mode
    {
        let sndf = renderer.sample_sndf_styled(
            file,
            &camera,
            draw,
            &sndf::SndfSettings {
                width: opts.width,
                height: opts.height,
                iterations,
                bins,
                binning,
            },
            0,
            &opts.style,
        )?;
        let sampled = t0.elapsed();
        let image = sndf.shade(&opts.lighting, opts.background);
        let frame = RenderedFrame {
            image,
            depth: None,
            gpu_time: None,
            points: draw.points as u32,
            gpu_data_bytes: sndf.hist.len() as u64 * 16,
            gpu_target_bytes: u64::from(opts.width) * u64::from(opts.height) * 20,
            impostors: None,
        };
        let mut report = RenderReport::new(renderer, file, opts, camera, &traversal, draw, &frame);
        report.traversal_time = traversal_time;
        report.spp = iterations;
        report.total_time = sampled;
        return Ok((frame.image, report));
    }
    let (style, look) = page_style(opts);
    let source = renderer::PackedCut {
        renderer,
        file,
        style,
        look: &look,
    };
    let (image, mut report) = draw_cut(
        renderer, file, &source, &camera, &traversal, draw, opts, &settings,
    )?;
    report.traversal_time = traversal_time;
    report.total_time = t0.elapsed();
    Ok((image, report))
}

/// The packing and look of the points `opts`'s mode draws (what a streaming pool for
/// it must hold: see [`StreamingRenderer::with_style`]).
pub fn page_style(opts: &RenderOptions) -> (PackStyle, PointStyle) {
    match opts.mode {
        RenderMode::Spheres | RenderMode::Sndf { .. } => (PackStyle::Spheres, opts.style.clone()),
        RenderMode::Splat { by_attribute: true } => (
            PackStyle::FluxAttribute,
            PointStyle {
                attribute: opts.style.attribute.clone(),
                attribute_range: opts.style.attribute_range,
                range_derived: opts.style.range_derived,
                // With a colour map the log is the image's (a projection's), not each
                // point's.
                log_scale: opts.style.log_scale && opts.style.colour_map.is_none(),
                ..Default::default()
            },
        ),
        // Splats of species light take the style's species colours (the packer keeps the
        // file's radii, their flux).
        RenderMode::Splat { .. } | RenderMode::SplatOver { .. } => {
            (PackStyle::FluxColour, opts.style.clone())
        }
        // Coloured by the attribute: its place on the scale the colour map spans.
        RenderMode::Density(d) if d.colour_map.is_some() => (
            PackStyle::FluxValue,
            PointStyle {
                attribute: opts.style.attribute.clone(),
                attribute_range: opts.style.attribute_range,
                log_scale: opts.style.log_scale,
                ..Default::default()
            },
        ),
        // The iso-surface takes the species' colours given (the volume's colours are the
        // transfer function's): colours alone, the radii and hiding being the density's.
        RenderMode::Density(_) => (
            PackStyle::FluxColour,
            PointStyle {
                species: opts
                    .style
                    .species
                    .iter()
                    .filter(|s| s.colour.is_some())
                    .map(|s| style::SpeciesStyle {
                        radius: None,
                        hidden: false,
                        ..s.clone()
                    })
                    .collect(),
                palette: opts.style.palette,
                ..Default::default()
            },
        ),
    }
}

/// Draws the cut `draw` in `opts`'s mode (not S-NDFs) from the points `source` binds;
/// the report's times other than the GPU's are left at zero.
#[allow(clippy::too_many_arguments)]
fn draw_cut(
    renderer: &Renderer,
    file: &MdlodFile,
    source: &dyn renderer::CutSource,
    camera: &Camera,
    traversal: &TraversalSettings,
    draw: &DrawList,
    opts: &RenderOptions,
    settings: &FrameSettings,
) -> Result<(RgbaImage, RenderReport), RenderError> {
    let (w, h) = (opts.width, opts.height);
    let pixels = u64::from(w) * u64::from(h);
    let report = |frame: &RenderedFrame| {
        RenderReport::new(renderer, file, opts, camera.clone(), traversal, draw, frame)
    };
    match opts.mode {
        RenderMode::Sndf { .. } => Err(RenderError::InvalidOptions(
            "S-NDFs are sampled by render_image or the S-MIP, not drawn from a cut".into(),
        )),
        RenderMode::Density(settings) => {
            let frame =
                renderer.render_density_from(source, file, camera, draw, w, h, &settings)?;
            let rendered = RenderedFrame {
                image: frame.image((!opts.transparent).then_some(opts.background)),
                depth: None,
                gpu_time: None,
                points: draw.points as u32,
                gpu_data_bytes: frame.gpu_data_bytes,
                gpu_target_bytes: pixels * (32 + 48),
                impostors: None,
            };
            let mut report = report(&rendered);
            report.density_stacks = Some((frame.stacks_run, frame.stacks));
            report.density_readbacks = Some(frame.readbacks);
            report.density_host_time = Some(frame.host_time);
            let mut image = rendered.image;
            draw_cell(file, opts, camera, &mut image, None);
            Ok((image, report))
        }
        RenderMode::Splat { .. } | RenderMode::SplatOver { .. } => {
            let mut light_extent = None;
            let (splats, image, exposure) = match opts.mode {
                RenderMode::SplatOver { opacity, order } => {
                    if !(opacity.is_finite() && opacity > 0.0 && opacity <= 1.0) {
                        return Err(RenderError::InvalidOptions(format!(
                            "opacity {opacity} (must be in (0, 1])"
                        )));
                    }
                    let sorted = traversal::sort_back_to_front_by(file, draw, camera, order);
                    let splats = renderer.render_splats_from(
                        source,
                        camera,
                        &sorted,
                        w,
                        h,
                        SplatBlend::Over { opacity },
                        opts.splat_support,
                    )?;
                    let image =
                        splats.composite_over((!opts.transparent).then_some(opts.background));
                    (splats, image, None::<Result<f32, [f32; 2]>>)
                }
                _ => {
                    let splats = renderer.render_splats_from(
                        source,
                        camera,
                        draw,
                        w,
                        h,
                        SplatBlend::Additive {
                            intensity: 1.0,
                            by_attribute: matches!(
                                opts.mode,
                                RenderMode::Splat { by_attribute: true }
                            ),
                        },
                        opts.splat_support,
                    )?;
                    let (image, tone) = match opts.style.colour_map {
                        // A projection: the image's light through the map.
                        Some(map) => {
                            let (image, range, extent) = splats.colour_mapped(
                                map,
                                opts.style.log_scale,
                                opts.light_range,
                                opts.background,
                            );
                            light_extent = extent;
                            (image, Err(range))
                        }
                        None => {
                            let (image, exposure) = splats.tone_map(opts.exposure, opts.background);
                            (image, Ok(exposure))
                        }
                    };
                    (splats, image, Some(tone))
                }
            };
            let frame = RenderedFrame {
                image,
                depth: None,
                gpu_time: splats.gpu_time,
                points: splats.points,
                gpu_data_bytes: splats.gpu_data_bytes,
                gpu_target_bytes: pixels * 32,
                impostors: None,
            };
            let mut report = report(&frame);
            report.exposure = exposure.and_then(|t| t.ok());
            report.light_range = exposure.and_then(|t| t.err());
            report.light_extent = light_extent;
            report.total_flux = exposure.map(|_| splats.total_light());
            if opts.keep_light_map && exposure.is_some() {
                report.light_map = Some(splats.hdr.iter().map(|p| splats.light(p)).collect());
            }
            let mut image = frame.image;
            draw_cell(file, opts, camera, &mut image, None);
            Ok((image, report))
        }
        RenderMode::Spheres => {
            let cell = opts.cell.is_some() && file.metadata().simulation_box.is_some();
            let settings = FrameSettings {
                read_depth: settings.read_depth || cell,
                ..settings.clone()
            };
            let mut frame = renderer.render_from(source, camera, draw, &settings)?;
            let report = report(&frame);
            draw_cell(file, opts, camera, &mut frame.image, frame.depth.as_deref());
            Ok((frame.image, report))
        }
    }
}

/// Draws the cell's edges over `image` when `opts` asks and the file has a cell, hidden
/// behind the surfaces of `depth` by more than the largest sphere radius drawn.
fn draw_cell(
    file: &MdlodFile,
    opts: &RenderOptions,
    camera: &Camera,
    image: &mut RgbaImage,
    depth: Option<&[f32]>,
) {
    let (Some(lines), Some(cell)) = (opts.cell, &file.metadata().simulation_box) else {
        return;
    };
    let species = &file.metadata().species;
    // The largest drawn: a species' largest particle scaled as the style scales it.
    let radius = opts
        .style
        .species_table(species)
        .map(|t| {
            t.iter()
                .enumerate()
                .map(|(i, s)| file.species_radius_span_at(i, s[3])[1])
                .fold(0.0f32, f32::max)
        })
        .unwrap_or_else(|_| file.max_particle_radius());
    overlay::draw_lines(
        image,
        depth,
        camera,
        &overlay::cell_edges(cell),
        lines.colour,
        lines.width_px,
        radius,
    );
}

/// One frame of a streamed view in `opts`'s mode (not S-NDFs), for callers that show
/// every frame, like the viewer: [`StreamingRenderer::prepare`] (install, traverse,
/// request), then the mode's passes over the resident pages. The pool must have been
/// made for the mode ([`page_style`]).
pub fn render_stream_frame(
    renderer: &Renderer,
    stream: &mut StreamingRenderer,
    opts: &RenderOptions,
) -> Result<(RgbaImage, RenderReport, StreamStats), RenderError> {
    let t0 = Instant::now();
    let file = stream.file().clone();
    let (camera, traversal, settings) = frame_setup(&file, opts)?;
    let (style, look) = page_style(opts);
    if stream.style() != (style, &look) {
        return Err(RenderError::InvalidOptions(
            "the streaming pool holds points packed for another mode or style".into(),
        ));
    }
    let (draw, stats) = stream.prepare(&camera, &traversal)?;
    let traversal_time = t0.elapsed();
    let (image, mut report) = draw_cut(
        renderer, &file, stream, &camera, &traversal, &draw, opts, &settings,
    )?;
    report.pool_limited = stats.pool_limited;
    report.traversal_time = traversal_time;
    report.total_time = t0.elapsed();
    Ok((image, report, stats))
}

/// Renders an open file through a streaming pool of `pool_bytes` of GPU memory: the
/// first frame draws what is resident (the coarse levels), then frames install the
/// pages the view asked for and ask for more until the view is complete (or the pool
/// holds all it can), and the last frame is drawn. Every mode but S-NDFs streams (those
/// go out of core through the S-MIP: `mdlod sample --tiles`).
pub fn render_streaming(
    renderer: &Renderer,
    file: std::sync::Arc<MdlodFile>,
    opts: &RenderOptions,
    pool_bytes: u64,
) -> Result<(RgbaImage, RenderReport), RenderError> {
    if matches!(opts.mode, RenderMode::Sndf { .. }) {
        return Err(RenderError::InvalidOptions(
            "S-NDFs do not stream through the GPU memory pool: leave out the pool, or sample \
             an orthographic view's S-MIP tiles (mdlod sample --tiles)"
                .into(),
        ));
    }
    // A pool that cannot hold the coarsest level draws one sphere for everything.
    let coarsest = file.levels().get(1).map_or(0, |l| l.point_count);
    let page = u64::from(streaming::PAGE_POINTS);
    let need = coarsest.div_ceil(page)
        * StreamingRenderer::slot_bytes(file.position_bits(), streaming::PAGE_POINTS);
    if pool_bytes < need {
        return Err(RenderError::InvalidOptions(format!(
            "a GPU memory pool (--gpu-memory) of {pool_bytes} bytes cannot hold the file's \
             coarsest level ({coarsest} points in {} bytes): give at least {}K",
            need,
            need.div_ceil(1024)
        )));
    }
    let t0 = Instant::now();
    let (camera, traversal, settings) = frame_setup(&file, opts)?;
    let (style, look) = page_style(opts);
    let mut stream = StreamingRenderer::with_style(
        renderer,
        file.clone(),
        pool_bytes,
        streaming::PAGE_POINTS,
        style,
        &look,
    )?;
    let mut frames = 0u32;
    let mut first_frame_time = None;
    let mut traversal_time = Duration::ZERO;
    // Each frame installs what arrived and asks for what is missing; a still view
    // completes in a number of frames bounded by the cut's depth and the pool size.
    const MAX_FRAMES: u32 = 10_000;
    loop {
        let tf = Instant::now();
        let (draw, stats) = stream.prepare(&camera, &traversal)?;
        traversal_time += tf.elapsed();
        frames += 1;
        // Done when the view is complete, or when the pool is full and nothing more
        // arrives or is asked for (the best this pool can hold).
        let last = stats.settled() || frames >= MAX_FRAMES;
        if frames == 1 || last {
            let (image, mut report) = draw_cut(
                renderer, &file, &stream, &camera, &traversal, &draw, opts, &settings,
            )?;
            first_frame_time.get_or_insert_with(|| t0.elapsed());
            if last {
                report.pool_limited = stats.pool_limited;
                report.traversal_time = traversal_time;
                report.total_time = t0.elapsed();
                report.frames = frames;
                report.first_frame_time = first_frame_time;
                return Ok((image, report));
            }
        }
        stream.wait_for_loads(Duration::from_secs(5));
    }
}

/// Renders `file` and writes the image to `out` as a PNG (atomically).
pub fn render_to_png(
    file: &Path,
    out: &Path,
    opts: &RenderOptions,
) -> Result<RenderReport, RenderError> {
    render_to_png_with(file, out, opts, None)
}

/// [`render_to_png`], reporting the choice of the cut and the drawing of a cut in
/// several batches or samples to `progress` ([`Renderer::set_progress`]).
pub fn render_to_png_with(
    file: &Path,
    out: &Path,
    opts: &RenderOptions,
    progress: Option<std::sync::Arc<dyn Progress + Send + Sync>>,
) -> Result<RenderReport, RenderError> {
    let t0 = Instant::now();
    // Before the GPU opens.
    check_numbers(opts)?;
    let file = open_styled(file, &opts.style)?;
    let mut renderer = Renderer::new(GpuContext::with_backends(opts.backends)?);
    renderer.set_progress(progress);
    let mut report = render_file_to_png(&renderer, file, out, opts)?;
    report.total_time = t0.elapsed();
    Ok(report)
}

/// [`render_to_png`] on a renderer that is already open (frames of a movie share one).
pub fn render_file_to_png(
    renderer: &Renderer,
    file: MdlodFile,
    out: &Path,
    opts: &RenderOptions,
) -> Result<RenderReport, RenderError> {
    let t0 = Instant::now();
    let (image, mut report) = render_file_to_image(renderer, file, opts)?;
    image.save_png(out)?;
    report.total_time = t0.elapsed();
    Ok(report)
}

/// [`render_file_to_png`]'s image, before it is written (a movie draws its panels into
/// it first). The report's total time is the drawing's.
pub fn render_file_to_image(
    renderer: &Renderer,
    file: MdlodFile,
    opts: &RenderOptions,
) -> Result<(RgbaImage, RenderReport), RenderError> {
    let t0 = Instant::now();
    check_numbers(opts)?;
    check_before_drawing(&file)?;
    let file = std::sync::Arc::new(file);
    let (image, mut report) = match opts.gpu_memory {
        None => render_image(renderer, &file, opts)?,
        Some(pool) => render_streaming(renderer, file.clone(), opts, pool)?,
    };
    if file.changed_on_disk() {
        return Err(RenderError::Changed {
            path: file.path().to_path_buf(),
        });
    }
    report.total_time = t0.elapsed();
    Ok((image, report))
}

/// Samples the S-NDFs of `file` as `opts` asks (its mode must be [`RenderMode::Sndf`])
/// and writes them, with the camera, to `out` (a `.sndf` file).
pub fn sample_to_file(
    file: &Path,
    out: &Path,
    opts: &RenderOptions,
) -> Result<RenderReport, RenderError> {
    sample_to_file_at(file, out, opts, None, None)
}

/// The most levels [`sample_tiles_to_file`] samples tiles finer than the view's pixels
/// (16 times the image's size), as `mdlod sample --min-samples` samples one image.
pub const MAX_FINER_LEVELS: u32 = 4;

/// Samples the S-MIP tiles an orthographic view of `file` shows (`opts` in the sndf
/// mode: iterations per texel, bins, binning; the screen error and budget apply per
/// sampled rectangle) and writes them to `out` as a `.sndf` file of tiles (version 1.1),
/// with level 0 fine enough that a sphere covers `samples_per_sphere` texels. The tiles
/// are sampled there (at most [`MAX_FINER_LEVELS`] levels finer than the view's pixels)
/// and the view's own level is shaded from them. Returns what the sampling did, the
/// tiles written, and how many levels finer than the view's pixels they were sampled.
pub fn sample_tiles_to_file(
    file: &Path,
    out: &Path,
    opts: &RenderOptions,
    samples_per_sphere: f32,
) -> Result<(smip::SmipStats, usize, u32), RenderError> {
    let RenderMode::Sndf {
        iterations,
        bins,
        binning,
    } = opts.mode
    else {
        return Err(RenderError::InvalidOptions(
            "sampling needs the sndf mode".into(),
        ));
    };
    let (w, h) = (opts.width, opts.height);
    check_numbers(opts)?;
    let mdlod = open_styled(file, &opts.style)?;
    check_before_drawing(&mdlod)?;
    let renderer = Renderer::new(GpuContext::with_backends(opts.backends)?);
    let camera = frame_setup(&mdlod, opts)?.0;
    if camera.projection != Projection::Orthographic {
        return Err(RenderError::InvalidOptions(
            "S-MIP tiles need an orthographic view (--ortho): under perspective a pan moves the eye".into(),
        ));
    }
    let frame = smip::SmipFrame::new(
        &camera,
        w,
        h,
        smip::min_radius(&mdlod, &opts.style),
        samples_per_sphere,
        bins,
        binning,
        file.display().to_string(),
    )?;
    // The level the view shows is `shown` levels above level 0 where `samples_per_sphere`
    // moved level 0 finer than the pixels: the tiles are sampled that much finer (as a
    // one-image file is sampled at a multiple of the image size), up to 16 times the
    // image's size, and the coarser levels shaded from them.
    let pixel = f64::from(camera.view_height_at_target()) / f64::from(h);
    let shown = (pixel / frame.texel0).log2().round().max(0.0) as u32;
    let finer = shown.min(MAX_FINER_LEVELS);
    let (Some(sw), Some(sh)) = (
        w.checked_shl(finer)
            .filter(|&s| s >> finer == w && s <= MAX_IMAGE_SIDE),
        h.checked_shl(finer)
            .filter(|&s| s >> finer == h && s <= MAX_IMAGE_SIDE),
    ) else {
        return Err(RenderError::InvalidOptions(format!(
            "sampling the tiles {}x finer than a {w}x{h} view, as the samples per sphere ask, \
             passes the largest image of {MAX_IMAGE_SIDE} pixels per side: give a smaller \
             --width and --height or fewer --min-samples",
            1u32 << finer
        )));
    };
    let tiles = (sw.div_ceil(sndf::TILE) + 1)
        .checked_mul(sh.div_ceil(sndf::TILE) + 1)
        .ok_or_else(|| {
            RenderError::InvalidOptions(format!("a view of {sw}x{sh} texels has too many tiles"))
        })?;
    let mut cache = smip::Smip::new(
        &renderer,
        bins,
        smip::SmipConfig {
            pool_tiles: tiles,
            error_px: opts.error_px,
            budget_points: opts.budget,
            ..Default::default()
        },
    )?;
    // The pool holds the tiles of a view this size, unless one buffer of the adapter
    // holds fewer tiles of this many bins: say which options to change.
    let capacity = cache.capacity();
    if capacity < tiles {
        let finer_text = match finer {
            0 => String::new(),
            _ => format!(
                " (sampled {}x finer than its pixels for the samples per sphere asked)",
                1u32 << finer
            ),
        };
        return Err(RenderError::InvalidOptions(format!(
            "a {w}x{h} view{finer_text} needs up to {tiles} S-MIP tiles of 64x64 texels, more \
             than the {capacity} tiles of {bins}x{bins} bins ({} MiB each) that one buffer of \
             this GPU holds: give fewer --bins (a tile grows with their square){} or a smaller \
             --width and --height",
            sndf::tile_bytes(bins) as f64 / f64::from(1 << 20),
            if finer > 0 {
                ", fewer --min-samples"
            } else {
                ""
            },
        )));
    }
    let stats = cache.prepare(
        &renderer,
        &mdlod,
        &frame,
        &camera,
        sw,
        sh,
        iterations,
        &opts.style,
    )?;
    let exported = cache.export(&renderer, &camera, sw, sh)?;
    let view = serde_json::to_value(ViewFile::from_camera(&camera))
        .map_err(|e| RenderError::InvalidOptions(e.to_string()))?;
    exported
        .to_data(w, h, view, Some(file.display().to_string()))
        .save(out)?;
    Ok((stats, exported.tiles.len(), finer))
}

/// [`sample_to_file`] recording `display_level`: the S-MIP level that shows the intended
/// image size when the S-NDFs were sampled finer (see [`level0_scale`]), and reporting
/// the choice of the cut and the sampling's iterations to `progress`
/// ([`Renderer::set_progress`]).
pub fn sample_to_file_at(
    file: &Path,
    out: &Path,
    opts: &RenderOptions,
    display_level: Option<u32>,
    progress: Option<std::sync::Arc<dyn Progress + Send + Sync>>,
) -> Result<RenderReport, RenderError> {
    let RenderMode::Sndf {
        iterations,
        bins,
        binning,
    } = opts.mode
    else {
        return Err(RenderError::InvalidOptions(
            "sampling needs the sndf mode".into(),
        ));
    };
    let t0 = Instant::now();
    check_numbers(opts)?;
    let mdlod = open_styled(file, &opts.style)?;
    check_before_drawing(&mdlod)?;
    let mut renderer = Renderer::new(GpuContext::with_backends(opts.backends)?);
    renderer.set_progress(progress);
    let (camera, traversal, _) = frame_setup(&mdlod, opts)?;
    renderer.reporter().stage("choosing the cut", None, "nodes");
    let draw = traverse(&camera, &mdlod, &traversal);
    renderer.reporter().finish_stage();
    mdlod.node_error()?;
    let traversal_time = t0.elapsed();
    let sndf = renderer.sample_sndf_styled(
        &mdlod,
        &camera,
        &draw,
        &sndf::SndfSettings {
            width: opts.width,
            height: opts.height,
            iterations,
            bins,
            binning,
        },
        0,
        &opts.style,
    )?;
    let view = serde_json::to_value(ViewFile::from_camera(&camera))
        .map_err(|e| RenderError::InvalidOptions(e.to_string()))?;
    let mut data = sndf.to_data(view, Some(file.display().to_string()));
    data.header.display_level = display_level;
    data.save(out)?;
    let frame = RenderedFrame {
        image: RgbaImage::new(1, 1),
        depth: None,
        gpu_time: None,
        points: draw.points as u32,
        gpu_data_bytes: sndf.hist.len() as u64 * 16,
        gpu_target_bytes: 0,
        impostors: None,
    };
    let mut report = RenderReport::new(&renderer, &mdlod, opts, camera, &traversal, &draw, &frame);
    report.spp = iterations;
    report.traversal_time = traversal_time;
    report.total_time = t0.elapsed();
    Ok(report)
}

/// The S-MIP level-0 scale for sampling `file` as `opts` asks: the smallest power of two
/// `s ≤ 16` such that sampling at `s` times the image size with `iterations` rays per
/// texel gives every particle sphere at least `min_samples` samples (taking the smallest
/// species radius at the data's far side), with the samples the smallest sphere gets
/// there (fewer than asked where 16 is not enough). 1 when `min_samples` is 0.
pub fn level0_scale(
    file: &MdlodFile,
    opts: &RenderOptions,
    iterations: u32,
    min_samples: u32,
) -> Result<(u32, f32), RenderError> {
    if min_samples == 0 {
        return Ok((1, f32::INFINITY));
    }
    let camera = frame_setup(file, opts)?.0;
    let bounds = data_bounds(file);
    let far = (camera.eye() - bounds.center()).dot(camera.back()) + bounds.radius();
    let r_min = file.min_particle_radius();
    let r_px = r_min * camera.pixels_per_world(far.max(camera.near), opts.height);
    let per_sphere = std::f32::consts::PI * r_px * r_px * iterations.max(1) as f32;
    let mut scale = 1u32;
    while scale < 16 && per_sphere * ((scale * scale) as f32) < min_samples as f32 {
        scale *= 2;
    }
    Ok((scale, per_sphere * (scale * scale) as f32))
}

/// The S-MIP levels [`shade_file`] shades a tiled `.sndf` file's own view from at
/// [`ShadeLevel::Display`] (one level, or two blended, with their weights); `None` for a
/// file of one image, shown at its header's `display_level`.
pub fn sndf_display_levels(
    input: &Path,
    header: &mdlod_format::sndf::SndfHeader,
) -> Result<Option<Vec<(u32, f64)>>, RenderError> {
    if header.smip.is_none() {
        return Ok(None);
    }
    let camera = tile_camera(input, header)?;
    smip::SmipTiles::view_levels(header, &camera, header.width, header.height).map_err(|e| {
        RenderError::Sndf {
            path: input.to_path_buf(),
            message: format!("its view against its S-MIP tiles: {e}"),
        }
    })
}

/// The camera of a tile file's own view. Its `target` and `distance` place and scale the
/// view against the tiles (FORMAT.md, section 10): a view without them, which no data can
/// be fitted to here, is refused.
fn tile_camera(
    input: &Path,
    header: &mdlod_format::sndf::SndfHeader,
) -> Result<Camera, RenderError> {
    let view = sndf_camera(input, &header.view)?;
    let (Some(target), Some(_)) = (view.target, view.distance) else {
        return Err(RenderError::Sndf {
            path: input.to_path_buf(),
            message: "its view has no `target` or no `distance`, which place and scale a \
                      view of S-MIP tiles (mdlod sample and the viewer write both)"
                .into(),
        });
    };
    let target = glam::Vec3::from(target);
    Ok(view.to_camera(
        &Bounds::new(target - 1.0, target + 1.0),
        header.width as f32 / header.height as f32,
    ))
}

/// Which S-MIP level [`shade_file`] shades.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ShadeLevel {
    /// The level the file says shows the intended image size (0 unless it was sampled
    /// finer to give every sphere enough samples).
    Display,
    /// This many levels coarser than sampled (each halves the image).
    Level(u32),
    /// Zoomed out by any factor ≥ 1, trilinear between levels.
    ZoomOut(f32),
}

impl std::fmt::Display for ShadeLevel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ShadeLevel::Display => write!(f, "display level"),
            ShadeLevel::Level(l) => write!(f, "level {l}"),
            ShadeLevel::ZoomOut(z) => write!(f, "zoomed out {z}x"),
        }
    }
}

/// Shades a `.sndf` file under `lights` to a PNG at `level`; reads no particle data.
/// Returns the image size.
pub fn shade_file(
    input: &Path,
    out: &Path,
    lights: &sndf::ShadeLights,
    background_srgb: [f32; 3],
    level: ShadeLevel,
) -> Result<(u32, u32), RenderError> {
    lights.check().map_err(RenderError::InvalidOptions)?;
    let data = mdlod_format::sndf::SndfData::load(input)?;
    // A camera shading could not use is refused before anything is shaded.
    sndf_camera(input, &data.header.view)?;
    // Past the level of one texel, every level is that texel.
    let (w, h) = (data.header.width, data.header.height);
    let coarsest = sndf::coarsest_level(w, h);
    if let ShadeLevel::Level(l) = level {
        if l > coarsest {
            return Err(RenderError::InvalidOptions(format!(
                "level {l}: {}'s {w}x{h} texels halve to one at level {coarsest} (levels 0 \
                 to {coarsest})",
                input.display()
            )));
        }
    }
    // (A tiled file's display level counts levels coarser than its view's pixels.)
    let untiled = data.header.smip.is_none();
    if let Some(l) = data
        .header
        .display_level
        .filter(|&l| untiled && l > coarsest)
    {
        return Err(RenderError::Sndf {
            path: input.to_path_buf(),
            message: format!(
                "its header's display_level {l} is past the level of one texel of its \
                 {w}x{h} texels ({coarsest})"
            ),
        });
    }
    if data.header.smip.is_some() {
        let image = shade_tiles_file(input, &data, lights, background_srgb, level)?;
        image.save_png(out)?;
        return Ok((image.width, image.height));
    }
    let mut s = sndf::Sndf::from_data(&data);
    let image = match level {
        ShadeLevel::ZoomOut(z) => s.shade_zoomed(lights, background_srgb, z),
        ShadeLevel::Display | ShadeLevel::Level(_) => {
            let levels = match level {
                ShadeLevel::Level(l) => l,
                _ => data.header.display_level.unwrap_or(0),
            };
            for _ in 0..levels.min(s.coarsest_level()) {
                s = s.downsample();
            }
            s.shade_with(lights, background_srgb)
        }
    };
    image.save_png(out)?;
    Ok((image.width, image.height))
}

/// The camera an `.sndf` header stores (a view file's JSON), checked as `--view` files
/// are: the shading's directions come from it.
pub fn sndf_camera(path: &Path, view: &serde_json::Value) -> Result<ViewFile, RenderError> {
    let bad = |message: String| RenderError::Sndf {
        path: path.to_path_buf(),
        message: format!("the camera in its header: {message}"),
    };
    let v: ViewFile = serde_json::from_value(view.clone()).map_err(|e| bad(e.to_string()))?;
    v.check().map_err(bad)?;
    Ok(v)
}

/// Shades a file of S-MIP tiles on the host: its view at its size, or `level` levels
/// (or `zoom_out` times) coarser, the image that much smaller; coarser tiles missing
/// from the file are made from the finer ones.
fn shade_tiles_file(
    input: &Path,
    data: &mdlod_format::sndf::SndfData,
    lights: &sndf::ShadeLights,
    background_srgb: [f32; 3],
    level: ShadeLevel,
) -> Result<RgbaImage, RenderError> {
    let bad = |message: String| RenderError::Sndf {
        path: input.to_path_buf(),
        message,
    };
    let (w, h) = (data.header.width, data.header.height);
    // The tiles do not bound the image a header asks for: cap it (512 MiB of pixels).
    if u64::from(w) * u64::from(h) > 1 << 27 {
        return Err(bad(format!(
            "a view of {w}x{h} pixels (at most 2^27 pixels are shaded from tiles)"
        )));
    }
    let camera = tile_camera(input, &data.header)?;
    let mut tiles =
        smip::SmipTiles::from_data(data, &camera).ok_or_else(|| bad("no S-MIP tiles".into()))?;
    let factor = match level {
        ShadeLevel::Display => 1.0,
        ShadeLevel::Level(l) => {
            tiles.level_bias = 0;
            2f32.powi(l as i32)
        }
        ShadeLevel::ZoomOut(z) => z,
    };
    let (w, h) = (
        ((w as f32 / factor).round() as u32).max(1),
        ((h as f32 / factor).round() as u32).max(1),
    );
    smip::shade_tiles(&tiles, &camera, w, h, lights, background_srgb)
        .map_err(|e| bad(format!("shading its S-MIP tiles: {e}")))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Data spanning more than single precision can draw (bounds at ±3·10^38, which
    /// only a damaged or hostile file holds: the converter refuses coordinates past
    /// ±10^37) is said of the file and its bounds, not blamed on options the user never
    /// gave; an error of a fitted view of ordinary data, or of a camera given whole,
    /// stays as it is.
    #[test]
    fn data_too_large_to_frame_is_said_of_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.mdlod");
        let frame = mdlod_preprocess::Frame {
            positions: vec![[0.0; 3], [1.0; 3], [2.0, 0.0, 1.0]],
            species_index: vec![0; 3],
            species: vec![mdlod_preprocess::SpeciesName {
                name: "X".into(),
                ..Default::default()
            }],
            ..Default::default()
        };
        mdlod_preprocess::convert::convert_frame(
            &frame,
            None,
            &path,
            &Default::default(),
            &mdlod_preprocess::progress::NoProgress,
        )
        .unwrap();
        let file = MdlodFile::open(&path).unwrap();
        let error = || RenderError::InvalidOptions("zoom 1e0: the camera, inf from ...".into());
        let huge = Bounds::new(glam::Vec3::splat(-3e38), glam::Vec3::splat(3e38));
        let e = undrawable(&file, &huge, &ViewSpec::default(), error()).to_string();
        assert!(
            e.starts_with(&format!("{}: the data's bounds, [-3e38", path.display()))
                && e.contains("span more than single precision can draw: zoom 1e0"),
            "{e}"
        );
        let ordinary = Bounds::new(glam::Vec3::ZERO, glam::Vec3::ONE);
        assert!(drawable_bounds(&ordinary) && !drawable_bounds(&huge));
        let stars = Bounds::new(glam::Vec3::splat(-1e25), glam::Vec3::splat(1e25));
        assert!(drawable_bounds(&stars));
        for (bounds, view) in [
            (&ordinary, ViewSpec::default()),
            (&huge, ViewSpec::Camera(Camera::default())),
        ] {
            let e = undrawable(&file, bounds, &view, error());
            assert!(matches!(e, RenderError::InvalidOptions(_)), "{e}");
        }
    }

    /// Ends of a shown range read as the decimals their step holds: 1.4999896 with a
    /// step of 5.5e-5 is 1.5; a value no short decimal is within the step of stays.
    #[test]
    fn shown_range_ends_are_the_shortest_decimals_their_step_holds() {
        assert_eq!(super::shortest_within(1.4999896, 2.75e-5), 1.5);
        assert_eq!(super::shortest_within(-3.399_996, 4.6e-6), -3.4);
        assert_eq!(super::shortest_within(-3.399_958, 4.6e-6), -3.39996);
        assert_eq!(super::shortest_within(2.0000153, 3.8e-5), 2.0);
        assert_eq!(super::shortest_within(0.123_456_7, 1e-9), 0.123_456_7);
    }

    /// A header's display level past the level of one texel (4 for 3x2 texels, whose
    /// coarsest is 2) is refused, as `--level` there is; the coarsest itself shades.
    #[test]
    fn a_display_level_past_one_texel_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("v.sndf");
        let out = dir.path().join("v.png");
        let save = |display_level| {
            mdlod_format::sndf::SndfData {
                header: mdlod_format::sndf::SndfHeader {
                    width: 3,
                    height: 2,
                    bins: 2,
                    binning: "projected-normals".into(),
                    rays: 4,
                    view: serde_json::json!({"version": 1}),
                    source: None,
                    display_level: Some(display_level),
                    normal_frame: None,
                    smip: None,
                },
                hist: vec![[0.0; 4]; 24],
            }
            .save(&path)
            .unwrap();
        };
        let lights = sndf::ShadeLights::from(&Lighting::default());
        save(4);
        let e = shade_file(&path, &out, &lights, [1.0; 3], ShadeLevel::Display)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("display_level 4 is past the level of one texel of its 3x2 texels (2)"),
            "{e}"
        );
        save(2);
        assert_eq!(
            shade_file(&path, &out, &lights, [1.0; 3], ShadeLevel::Display).unwrap(),
            (1, 1)
        );
    }

    #[test]
    fn absurd_sizes_and_exposures_are_refused_before_any_work() {
        let opts = |width, height, exposure| RenderOptions {
            width,
            height,
            exposure,
            ..Default::default()
        };
        check_numbers(&opts(1280, 720, Some(2.0))).unwrap();
        check_numbers(&opts(MAX_IMAGE_SIDE, MAX_IMAGE_SIDE, None)).unwrap();
        for (w, h) in [(4_000_000_000, 720), (1280, MAX_IMAGE_SIDE + 1), (0, 1)] {
            let e = check_numbers(&opts(w, h, None)).unwrap_err().to_string();
            assert!(
                e.contains(&format!("{w}x{h}")) && e.contains("32768"),
                "{e}"
            );
        }
        for bad in [f32::NAN, -1.0, 0.0, f32::INFINITY] {
            let e = check_numbers(&opts(64, 64, Some(bad)))
                .unwrap_err()
                .to_string();
            assert!(e.contains("exposure") && e.contains("above 0"), "{e}");
        }
        let e = check_numbers(&RenderOptions {
            error_px: f32::INFINITY,
            ..Default::default()
        })
        .unwrap_err()
        .to_string();
        assert!(e.contains("a finite number, 0 or more"), "{e}");
    }

    #[test]
    fn cameras_too_far_to_draw_from_finite_inputs_are_refused() {
        let bounds = Bounds::new([0.0; 3], [10.0; 3]);
        let orbit = |zoom| ViewSpec::Orbit {
            azimuth_deg: 30.0,
            elevation_deg: 20.0,
            zoom,
            projection: Projection::Perspective,
        };
        camera_in(&bounds, &orbit(1.0), 64, 64).unwrap();
        // The distance overflows to infinity.
        let e = camera_in(&bounds, &orbit(1e-38), 64, 64)
            .unwrap_err()
            .to_string();
        assert!(e.contains("zoom 1e-38") && e.contains("too far"), "{e}");
        // A finite distance whose depth range collapses (near == far in f32).
        let dir = tempfile::tempdir().unwrap();
        let view = dir.path().join("far.json");
        std::fs::write(&view, r#"{"version": 1, "distance": 1e38}"#).unwrap();
        let e = camera_in(&bounds, &ViewSpec::File(view), 64, 64)
            .unwrap_err()
            .to_string();
        assert!(e.contains("far.json") && e.contains("too far"), "{e}");
        let far = Camera {
            distance: 1e38,
            ..Default::default()
        };
        let e = camera_in(&bounds, &ViewSpec::Camera(far), 64, 64)
            .unwrap_err()
            .to_string();
        assert!(e.contains("too far"), "{e}");
    }

    #[test]
    fn colours_parse() {
        assert_eq!(parse_colour("#ff0080").unwrap(), [1.0, 0.0, 128.0 / 255.0]);
        assert_eq!(parse_colour("000000").unwrap(), [0.0; 3]);
        assert_eq!(
            parse_colour("#f08").unwrap(),
            parse_colour("#ff0088").unwrap()
        );
        assert!(parse_colour("f08").is_err());
        assert_eq!(parse_colour("0.5, 1, 0").unwrap(), [0.5, 1.0, 0.0]);
        assert_eq!(parse_colour("Red").unwrap(), [1.0, 0.0, 0.0]);
        assert_eq!(parse_colour("lime").unwrap(), [0.0, 1.0, 0.0]);
        assert_eq!(parse_colour("Navy").unwrap(), [0.0, 0.0, 128.0 / 255.0]);
        assert_eq!(
            parse_colour("grey").unwrap(),
            parse_colour("#808080").unwrap()
        );
        for bad in ["#ff00", "1,2,3", "reddish", "0.1,0.2"] {
            let e = parse_colour(bad).unwrap_err().to_string();
            assert!(e.contains("one of black, white"), "{bad}: {e}");
        }
    }
}
