//! Headless frames: traversal output in, an RGBA8 image (and optionally depth) out.
//!
//! How it works: the draw list is packed and uploaded, in batches when it is too
//! large for one storage binding ([`Renderer::batch_limits`]: about 15.7 M points a
//! batch where bindings hold 128 MiB; the splat, density and S-NDF passes batch theirs
//! too). Each of the `spp` samples draws the spheres, batch after batch into the same
//! targets, with the projection shifted by a sub-pixel offset (Halton 2,3; none for one
//! sample) into a float colour target cleared to the background, then adds that image
//! with weight 1/spp to a single-precision sum (two targets in turn, each pass reading
//! one and writing the other: additive blending into half floats rounded equal samples
//! the same way every time, 4/255 too dark at 256 samples). The sum is copied into an sRGB
//! target (the format encodes) and read back. Later batches are depth-tested against
//! the earlier ones, so the image is the one batch would give, up to exact depth ties
//! between points of different batches. With one sample (and in the splat pass) each
//! batch is packed, uploaded, drawn and dropped in turn (`BatchStream`), so memory
//! holds one batch however large the cut; several samples keep every batch bound.
//! GPU time, when the device has timestamp queries, runs from the start of the first
//! sample's sphere pass to the end of the resolve pass; for batches drawn in turn it is
//! the sum of each batch's span, without the GPU's waits for the next upload.
//! Given a progress reporter ([`Renderer::set_progress`]), a pass of several submissions
//! counts each as the GPU finishes it (`DrawProgress`).

use std::sync::Arc;
use std::time::Duration;

use glam::Vec2;
use mdlod_format::{MdlodFile, NoProgress, Progress};

use crate::camera::{Camera, Projection};
use crate::context::GpuContext;
use crate::error::RenderError;
use crate::image::RgbaImage;
use crate::passes::accumulate::{AccumulatePass, OUTPUT_FORMAT};
use crate::passes::sphere_raycast::{
    FrameUniforms, Lighting, SphereBuffers, SphereRaycastPass, COLOUR_FORMAT, DEPTH_FORMAT,
};
use crate::passes::sphere_raycast::{
    PackStyle, SmallSphereTargets, SmallSpheres, SphereOutput, GBUFFER_FORMAT,
};
use crate::passes::splat::{SplatPass, HDR_FORMAT};
use crate::sndf::{
    shade_table, AccumulateParams, ShadeLights, ShadeParams, Sndf, SndfPass, SndfSettings,
    SndfShadePass,
};
use crate::traversal::DrawList;

/// Most samples per pixel accepted.
pub const MAX_SPP: u32 = 256;

/// A cut bound for the GPU: the point passes' bind group over its points, and what
/// decoding them needs.
pub struct BoundCut {
    pub buffers: SphereBuffers,
    pub position_bits: u32,
    pub species_count: u32,
    /// Bytes of the buffers the points live in.
    pub data_bytes: u64,
}

/// Where a pass gets the points of a draw list, in the list's order: packed from the
/// file and uploaded ([`PackedCut`]), or the resident pages of a streaming pool
/// ([`crate::StreamingRenderer`]).
pub trait CutSource {
    /// What the bound points' attributes carry (each pass needs its own).
    fn style(&self) -> PackStyle;
    /// Binds the points of `draw`, a cut of the source's file.
    fn bind(&self, draw: &DrawList) -> Result<BoundCut, RenderError>;
    /// The batches of `draw`, as draw lists that [`Self::bind`] binds one at a time,
    /// when the source splits it (a cut too large for one storage binding); `None` for
    /// one piece.
    fn batch_lists(&self, _draw: &DrawList) -> Option<Vec<DrawList>> {
        None
    }

    /// Binds the points of `draw` in its consecutive batches ([`Self::batch_lists`]),
    /// for passes that draw every batch more than once; at least one batch.
    fn bind_batches(&self, draw: &DrawList) -> Result<Vec<BoundCut>, RenderError> {
        match self.batch_lists(draw) {
            Some(lists) => lists.iter().map(|list| self.bind(list)).collect(),
            None => Ok(vec![self.bind(draw)?]),
        }
    }

    /// What an intensity of 1 of the bound points stands for in their attribute's units
    /// (splats lit by the attribute: [`crate::passes::sphere_raycast::AttrPacker::light_unit`]).
    fn light_unit(&self) -> f32 {
        1.0
    }

    /// The attribute's scale the bound points' grey values come from, where they are
    /// the attribute's ([`PackStyle::FluxAttribute`], [`PackStyle::FluxValue`]); an
    /// error where the packing cannot be made (a file without the attribute).
    fn value_scale(&self) -> Result<Option<crate::style::AttributeScale>, RenderError> {
        Ok(None)
    }
}

/// The cut packed from the mapped file and uploaded whole.
pub struct PackedCut<'a> {
    pub renderer: &'a Renderer,
    pub file: &'a MdlodFile,
    pub style: PackStyle,
    pub look: &'a crate::style::PointStyle,
}

impl CutSource for PackedCut<'_> {
    fn style(&self) -> PackStyle {
        self.style
    }

    fn light_unit(&self) -> f32 {
        crate::passes::sphere_raycast::AttrPacker::new(self.file, self.style, self.look)
            .map_or(1.0, |p| p.light_unit())
    }

    fn value_scale(&self) -> Result<Option<crate::style::AttributeScale>, RenderError> {
        let packer =
            crate::passes::sphere_raycast::AttrPacker::new(self.file, self.style, self.look)?;
        Ok(packer.value_scale().copied())
    }

    fn bind(&self, draw: &DrawList) -> Result<BoundCut, RenderError> {
        let packed =
            crate::passes::sphere_raycast::pack_styled(self.file, draw, self.style, self.look)?;
        let limits = self.renderer.ctx.device.limits();
        let largest = packed.largest_buffer_bytes();
        if largest > limits.max_storage_buffer_binding_size || largest > limits.max_buffer_size {
            return Err(RenderError::InvalidOptions(format!(
                "the cut of {} points needs a {largest}-byte buffer, more than this adapter \
                 allows ({} bytes): lower the point budget",
                packed.points(),
                limits.max_storage_buffer_binding_size
            )));
        }
        let buffers = self
            .renderer
            .sphere
            .upload(&self.renderer.ctx.device, &packed);
        // The upload's staging copies wait in the queue until its next submission: flush
        // them now, so that a cut bound in several batches does not hold every batch's
        // staging copy (as large as the batch) until its first draw (BENCHMARKS.md,
        // "Drawing every particle of 10^8").
        self.renderer.ctx.queue.submit([]);
        // Reclaims the staging copies of earlier batches whose copies are done (no wait).
        let _ = self.renderer.ctx.device.poll(wgpu::PollType::Poll);
        Ok(BoundCut {
            buffers,
            position_bits: packed.position_bits,
            species_count: packed.species.len() as u32,
            data_bytes: packed.data_bytes(),
        })
    }

    /// Batches within [`Renderer::batch_limits`], each packed and uploaded by its own
    /// [`CutSource::bind`], so the host holds one batch's packing at most.
    fn batch_lists(&self, draw: &DrawList) -> Option<Vec<DrawList>> {
        let (points, ranges) = self.renderer.batch_limits();
        Some(draw.batches(points, ranges)).filter(|b| b.len() > 1)
    }
}

/// One batch of a sphere frame: bound for the whole frame, or bound for its one draw
/// and dropped after it.
enum BatchRef<'a> {
    Kept(&'a SphereBuffers),
    Streamed(BoundCut),
}

impl BatchRef<'_> {
    fn buffers(&self) -> &SphereBuffers {
        match self {
            BatchRef::Kept(b) => b,
            BatchRef::Streamed(c) => &c.buffers,
        }
    }
}

/// A cut's batches for a pass that draws each once, in order: each is bound when it is
/// drawn and dropped after, so host and GPU hold one batch's points however large the
/// cut. The first is bound on opening: its decoding (position bits, species) is every
/// batch's, and the pass's uniforms need it.
struct BatchStream<'s> {
    source: &'s dyn CutSource,
    /// The batches; empty when the source binds the cut in one piece.
    lists: Vec<DrawList>,
    first: Option<BoundCut>,
    /// Points of each batch.
    counts: Vec<u32>,
    decoding: (u32, u32),
    /// The most point data one batch held.
    largest: u64,
}

impl<'s> BatchStream<'s> {
    fn open(source: &'s dyn CutSource, draw: &DrawList) -> Result<Self, RenderError> {
        let lists = source.batch_lists(draw).unwrap_or_default();
        let first = source.bind(lists.first().unwrap_or(draw))?;
        let counts = match lists.len() {
            0 => vec![first.buffers.points],
            _ => lists.iter().map(|l| l.points as u32).collect(),
        };
        Ok(BatchStream {
            source,
            decoding: (first.position_bits, first.species_count),
            lists,
            first: Some(first),
            counts,
            largest: 0,
        })
    }

    /// Batch `b`, bound now (batches are taken in order, each once).
    fn take(&mut self, b: usize) -> Result<BoundCut, RenderError> {
        let cut = match self.first.take() {
            Some(cut) if b == 0 => cut,
            _ => self.source.bind(&self.lists[b])?,
        };
        self.largest = self.largest.max(cut.data_bytes);
        Ok(cut)
    }
}

/// A cut bound in batches ([`CutSource::bind_batches`]): at least one.
struct Batches {
    cuts: Vec<BoundCut>,
}

impl Batches {
    fn of(source: &dyn CutSource, draw: &DrawList) -> Result<Self, RenderError> {
        let cuts = source.bind_batches(draw)?;
        if cuts.is_empty() {
            return Err(RenderError::Gpu("a cut bound in no batch".into()));
        }
        Ok(Batches { cuts })
    }

    /// The first batch; its decoding (position bits, species) is every batch's.
    fn first(&self) -> &BoundCut {
        &self.cuts[0]
    }

    fn buffers(&self) -> impl Iterator<Item = &SphereBuffers> {
        self.cuts.iter().map(|c| &c.buffers)
    }

    fn data_bytes(&self) -> u64 {
        self.cuts.iter().map(|c| c.data_bytes).sum()
    }
}

/// `Clear(value)` for the first draw into a target, `Load` for those that follow it.
fn cleared_if<V>(clear: bool, value: V) -> wgpu::LoadOp<V> {
    if clear {
        wgpu::LoadOp::Clear(value)
    } else {
        wgpu::LoadOp::Load
    }
}

/// The sphere passes' depth target, cleared to the far plane (0: reversed depth) when
/// `clear`, else loaded from the draws before.
fn reversed_depth(
    view: &wgpu::TextureView,
    clear: bool,
) -> wgpu::RenderPassDepthStencilAttachment<'_> {
    wgpu::RenderPassDepthStencilAttachment {
        view,
        depth_ops: Some(wgpu::Operations {
            load: cleared_if(clear, 0.0),
            store: wgpu::StoreOp::Store,
        }),
        stencil_ops: None,
    }
}

/// The packing a splat blend draws from.
pub fn splat_style(blend: SplatBlend) -> PackStyle {
    match blend {
        SplatBlend::Additive {
            by_attribute: true, ..
        } => PackStyle::FluxAttribute,
        _ => PackStyle::FluxColour,
    }
}

/// How the density volume's points are packed: by species colour, or by the attribute's
/// place on its scale where the volume or the iso-surface is coloured by it.
pub fn density_style(settings: &crate::density::DensitySettings) -> PackStyle {
    match settings.colour_map {
        Some(_) => PackStyle::FluxValue,
        None => PackStyle::FluxColour,
    }
}

fn check_source(source: &dyn CutSource, want: PackStyle, what: &str) -> Result<(), RenderError> {
    if source.style() == want {
        Ok(())
    } else {
        Err(RenderError::InvalidOptions(format!(
            "{what} draws points packed as {want:?}, but the source holds {:?}",
            source.style()
        )))
    }
}

/// How to draw a frame.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameSettings {
    pub width: u32,
    pub height: u32,
    /// Samples per pixel: 1 (pixel centres) or more (jittered, averaged).
    pub spp: u32,
    /// Background colour, sRGB-encoded in [0, 1].
    pub background_srgb: [f32; 3],
    pub lighting: Lighting,
    /// Also read back the depth buffer of the last sample.
    pub read_depth: bool,
    /// The points' look (species colours, radii, hiding, colour map).
    pub style: crate::style::PointStyle,
    /// No background: pixels no sphere covers are transparent, and a pixel's alpha is
    /// the share of its samples that hit a sphere (its colour the mean of theirs).
    pub transparent: bool,
}

impl Default for FrameSettings {
    fn default() -> Self {
        FrameSettings {
            width: 1280,
            height: 720,
            spp: 1,
            background_srgb: [1.0, 1.0, 1.0],
            lighting: Lighting::default(),
            read_depth: false,
            style: Default::default(),
            transparent: false,
        }
    }
}

/// A rendered frame.
#[derive(Clone, Debug)]
pub struct RenderedFrame {
    pub image: RgbaImage,
    /// Depth in [0, 1] (WebGPU NDC z of [`Camera::clip_from_view`]: 0 at the near plane, 1
    /// at the far one) per pixel, rows top to bottom, of the last sample; 1 where nothing
    /// was hit. Only with [`FrameSettings::read_depth`]. (The pass itself keeps reversed
    /// depth, [`Camera::depth_clip_from_view`], whose complement this is.)
    pub depth: Option<Vec<f32>>,
    /// GPU time of the frame, when the device measures it.
    pub gpu_time: Option<Duration>,
    /// Points drawn.
    pub points: u32,
    /// With the compute raster of small spheres: how many spheres it left to impostor
    /// quads (the larger ones); `None` when every sphere was an impostor, or when the
    /// cut was drawn in several batches.
    pub impostors: Option<u32>,
    /// Bytes of point data the frame read on the GPU: the uploaded cut, or the
    /// streaming pool's position and attribute buffers plus its range tables.
    pub gpu_data_bytes: u64,
    /// Bytes of the frame's render targets and readback buffer.
    pub gpu_target_bytes: u64,
}

/// How splats combine.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SplatBlend {
    /// Added up: flux-preserving (`intensity` scales every point's flux); coloured by
    /// species, or grey by the scalar attribute (mapped from its range to [0, 1]).
    Additive { intensity: f32, by_attribute: bool },
    /// Translucent discs of peak alpha `opacity`, composited with the over operator in
    /// the order of the draw list (sort it back to front first).
    Over { opacity: f32 },
}

/// A splat accumulation: per pixel (rows top to bottom) the flux in r, g, b and in total
/// (a), before tone mapping.
#[derive(Clone, Debug)]
pub struct SplatFrame {
    pub width: u32,
    pub height: u32,
    pub hdr: Vec<[f32; 4]>,
    /// The points' light is their scalar attribute (`SplatBlend::Additive` with
    /// `by_attribute`): r, g and b carry it (grey), a their disks' flux whatever their
    /// attribute.
    pub by_attribute: bool,
    /// What a light of 1 in `hdr` stands for in the attribute's units, when the light is
    /// the attribute's ([`Self::light`] multiplies by it); 1 otherwise.
    pub light_unit: f32,
    pub gpu_time: Option<Duration>,
    pub points: u32,
    pub gpu_data_bytes: u64,
}

impl SplatFrame {
    /// The image's total flux per channel (r, g, b, total).
    pub fn total_flux(&self) -> [f64; 4] {
        let mut t = [0f64; 4];
        for p in &self.hdr {
            for k in 0..4 {
                t[k] += f64::from(p[k]);
            }
        }
        t
    }

    /// A pixel's flux of light: its total (a) for species light, which the albedos then
    /// split among r, g and b; the attribute's light (r = g = b) when the points' light
    /// is their attribute.
    pub fn light(&self, p: &[f32; 4]) -> f32 {
        if self.by_attribute {
            // (Held at single precision's largest: units past it give no infinities.)
            (f64::from(p[0]) * f64::from(self.light_unit))
                .clamp(-f64::from(f32::MAX), f64::from(f32::MAX)) as f32
        } else {
            p[3]
        }
    }

    /// The image's total flux of light ([`Self::light`] summed over the pixels).
    pub fn total_light(&self) -> f64 {
        self.hdr.iter().map(|p| f64::from(self.light(p))).sum()
    }

    /// Tone maps to an sRGB image over `background_srgb`: each channel's flux `f` adds
    /// `1 − exp(−exposure · f)` of light. Without an exposure, the one that maps the
    /// 99.5th percentile of the lit pixels' light ([`Self::light`]: the total flux, or
    /// the attribute's light) to 0.86 (1 − e⁻²). Returns the image and the exposure
    /// used.
    pub fn tone_map(&self, exposure: Option<f32>, background_srgb: [f32; 3]) -> (RgbaImage, f32) {
        let exposure = exposure.unwrap_or_else(|| {
            let mut lit: Vec<f32> = self
                .hdr
                .iter()
                .map(|p| self.light(p))
                .filter(|v| *v > 0.0)
                .collect();
            if lit.is_empty() {
                return 1.0;
            }
            let k = ((lit.len() as f64 * 0.995) as usize).min(lit.len() - 1);
            let (_, v, _) = lit.select_nth_unstable_by(k, f32::total_cmp);
            2.0 / v.max(f32::MIN_POSITIVE)
        });
        let bg = background_srgb.map(srgb_to_linear);
        // The exposure is of the light in its units (the attribute's, where the points
        // are lit by it), as [`Self::light`] gives it.
        let unit = if self.by_attribute {
            self.light_unit
        } else {
            1.0
        };
        let mut image = RgbaImage::new(self.width, self.height);
        for (i, p) in self.hdr.iter().enumerate() {
            let px: [u8; 4] = [0, 1, 2, 3].map(|k| {
                if k == 3 {
                    return 255;
                }
                let f = (f64::from(p[k].max(0.0)) * f64::from(unit)).min(f64::from(f32::MAX));
                let light = 1.0 - (-exposure * f as f32).exp();
                let v = bg[k] + (1.0 - bg[k]) * light;
                (linear_to_srgb(v.clamp(0.0, 1.0)) * 255.0 + 0.5) as u8
            });
            image.data[4 * i..4 * i + 4].copy_from_slice(&px);
        }
        (image, exposure)
    }
}

impl SplatFrame {
    /// Colours the image's light ([`Self::light`]: the projected flux, or the projected
    /// attribute) through `map`, as a map of column density is drawn: light `lo` and
    /// below takes the map's first colour, `hi` and above its last, linearly between or
    /// with `log` on a log axis. `range` gives `[lo, hi]`, else the image does: `hi` the
    /// 99.5th percentile of the lit pixels' light, `lo` 0 (linear) or their 0.5th
    /// percentile (log). Pixels without light keep the background. Returns the image and
    /// the range used.
    pub fn colour_mapped(
        &self,
        map: crate::style::ColourMap,
        log: bool,
        range: Option<[f32; 2]>,
        background_srgb: [f32; 3],
    ) -> (RgbaImage, [f32; 2], Option<[f32; 2]>) {
        // The faintest and brightest lit pixels: where the range cuts them, the legend
        // marks its ends `≤` and `≥`.
        let extent = self
            .hdr
            .iter()
            .map(|p| self.light(p))
            .filter(|v| *v > 0.0 && v.is_finite())
            .fold(None, |e: Option<[f32; 2]>, v| {
                Some(e.map_or([v, v], |[a, b]| [a.min(v), b.max(v)]))
            });
        let range = range.unwrap_or_else(|| {
            let mut lit: Vec<f32> = self
                .hdr
                .iter()
                .map(|p| self.light(p))
                .filter(|v| *v > 0.0 && v.is_finite())
                .collect();
            if lit.is_empty() {
                return [0.0, 1.0];
            }
            lit.sort_unstable_by(f32::total_cmp);
            let at = |q: f64| lit[((lit.len() as f64 * q) as usize).min(lit.len() - 1)];
            let hi = at(0.995);
            let lo = if log { at(0.005).min(hi * 0.5) } else { 0.0 };
            [lo, hi]
        });
        let [lo, hi] = range;
        let (llo, lhi) = (
            f64::from(lo.max(f32::MIN_POSITIVE)).ln(),
            f64::from(hi).ln(),
        );
        let bg = background_srgb.map(|c| (c.clamp(0.0, 1.0) * 255.0 + 0.5) as u8);
        let mut image = RgbaImage::new(self.width, self.height);
        for (i, p) in self.hdr.iter().enumerate() {
            let light = self.light(p);
            let px = if light.is_nan() || light <= 0.0 {
                [bg[0], bg[1], bg[2], 255]
            } else {
                let t = if log {
                    ((f64::from(light).ln() - llo) / (lhi - llo)) as f32
                } else {
                    (light - lo) / (hi - lo)
                };
                let c = map.colour(if t.is_finite() { t } else { 1.0 });
                let e = c.map(|v| (linear_to_srgb(v.clamp(0.0, 1.0)) * 255.0 + 0.5) as u8);
                [e[0], e[1], e[2], 255]
            };
            image.data[4 * i..4 * i + 4].copy_from_slice(&px);
        }
        (image, range, extent)
    }

    /// An over-blended frame (premultiplied colour and coverage) over `background_srgb`,
    /// or with `None` over nothing (the coverage as alpha, the colour unpremultiplied).
    pub fn composite_over(&self, background_srgb: Option<[f32; 3]>) -> RgbaImage {
        composite_over(&self.hdr, self.width, self.height, background_srgb)
    }
}

/// Premultiplied linear colour and coverage per pixel, composited over
/// `background_srgb` and encoded as sRGB; with `None`, over nothing: the coverage is the
/// alpha and the colour is divided by it (PNG stores straight colour).
fn composite_over(
    rgba: &[[f32; 4]],
    width: u32,
    height: u32,
    background_srgb: Option<[f32; 3]>,
) -> RgbaImage {
    let bg = background_srgb.map(|b| b.map(srgb_to_linear));
    let mut image = RgbaImage::new(width, height);
    for (i, p) in rgba.iter().enumerate() {
        let a = p[3].clamp(0.0, 1.0);
        let px: [u8; 4] = [0, 1, 2, 3].map(|k| {
            let v = match (k, bg) {
                (3, Some(_)) => return 255,
                (3, None) => return (a * 255.0 + 0.5) as u8,
                (_, Some(bg)) => p[k] + (1.0 - a) * bg[k],
                (_, None) if a > 0.0 => p[k] / a,
                (_, None) => 0.0,
            };
            (linear_to_srgb(v.clamp(0.0, 1.0)) * 255.0 + 0.5) as u8
        });
        image.data[4 * i..4 * i + 4].copy_from_slice(&px);
    }
    image
}

/// A rendered density frame: per-pixel premultiplied colour and opacity, and (iso mode)
/// the distance along the ray of the surface.
pub struct DensityFrame {
    pub width: u32,
    pub height: u32,
    pub rgba: Vec<[f32; 4]>,
    pub hit: Vec<f32>,
    /// The points, sorted by distance, as the density saw them.
    pub points: Vec<crate::density::DensityPoint>,
    pub slicing: crate::density::Slicing,
    /// Stacks of slices the volume spans, and how many were run before every ray was
    /// done.
    pub stacks: u32,
    pub stacks_run: u32,
    /// Stacks after which no ray was active (at the precision of the checkpoints).
    pub stacks_needed: u32,
    /// The previous frame's stack count, run as one batch (frame-to-frame coherence).
    pub stacks_hint: Option<u32>,
    /// Batches run, each ending with one read-back of the active rays.
    pub readbacks: u32,
    /// Point splats drawn over all stacks.
    pub splatted: u64,
    pub gpu_data_bytes: u64,
    /// Host work before the first GPU pass: decoding, depth-sorting and packing the
    /// points, and binding them (uploading a packed cut; a pool's pages are resident).
    pub host_time: std::time::Duration,
}

impl DensityFrame {
    /// Composites over the background and encodes sRGB.
    pub fn image(&self, background_srgb: Option<[f32; 3]>) -> RgbaImage {
        composite_over(&self.rgba, self.width, self.height, background_srgb)
    }
}

/// Converts one linear channel to sRGB encoding.
pub fn linear_to_srgb(c: f32) -> f32 {
    if c <= 0.003_130_8 {
        c * 12.92
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }
}

/// Converts one sRGB-encoded channel to linear.
pub fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

fn halton(mut i: u32, base: u32) -> f32 {
    let mut f = 1.0f32;
    let mut r = 0.0f32;
    while i > 0 {
        f /= base as f32;
        r += f * (i % base) as f32;
        i /= base;
    }
    r
}

/// Histograms read back in the accumulation's layout (64×64-texel tiles of 8×8-texel
/// blocks, tiles in rows), reordered to texels in rows.
fn tiles_to_rows(bytes: &[u8], width: u32, height: u32, bins: u32) -> Vec<[f32; 4]> {
    let tiled: Vec<[f32; 4]> = bytemuck::pod_collect_to_vec(bytes);
    let tile = crate::sndf::TILE;
    let b2 = (bins * bins) as usize;
    let tiles_x = width.div_ceil(tile);
    let mut hist = Vec::with_capacity(width as usize * height as usize * b2);
    for y in 0..height {
        for x in 0..width {
            let slot = (y / tile) * tiles_x + x / tile;
            let at =
                (slot * tile * tile + crate::sndf::texel_in_tile(x % tile, y % tile)) as usize * b2;
            hist.extend_from_slice(&tiled[at..at + b2]);
        }
    }
    hist
}

/// S-NDFs of one view kept on the GPU for progressive refinement (see
/// [`Renderer::resident_sndf`]): batches add rays to the resident histograms, shading
/// reads them there, and nothing is read back unless asked.
pub struct ResidentSndf {
    hist: wgpu::Buffer,
    /// Tiles one binding holds: the histograms are accumulated (and shaded) in windows
    /// of that many consecutive tiles when they are larger than one binding.
    window_tiles: u64,
    cut: UploadedCut,
    camera: Camera,
    pub width: u32,
    pub height: u32,
    pub bins: u32,
    pub binning: crate::sndf::Binning,
    /// Rays per texel so far.
    pub rays: u32,
    /// Spheres drawn per iteration.
    pub points: u64,
}

impl ResidentSndf {
    /// Bytes of histograms on the GPU.
    pub fn gpu_bytes(&self) -> u64 {
        self.hist.size()
    }

    /// The histograms' windows, each no larger than one binding: its binding and its
    /// page table (tile `t` of the image to slot `t − first` of the window, the tiles
    /// of other windows to [`crate::sndf::NO_SLOT`]).
    fn windows(&self) -> Vec<(wgpu::BufferBinding<'_>, Vec<u32>)> {
        let tiles = self.tiles();
        let per = self.window_tiles.max(1);
        let tile_bytes = crate::sndf::tile_bytes(self.bins);
        (0..tiles.div_ceil(per))
            .map(|w| {
                let first = w * per;
                let count = per.min(tiles - first);
                let pages = (0..tiles)
                    .map(|t| {
                        if (first..first + count).contains(&t) {
                            (t - first) as u32
                        } else {
                            crate::sndf::NO_SLOT
                        }
                    })
                    .collect();
                let binding = wgpu::BufferBinding {
                    buffer: &self.hist,
                    offset: first * tile_bytes,
                    size: wgpu::BufferSize::new(count * tile_bytes),
                };
                (binding, pages)
            })
            .collect()
    }

    /// True when the histograms are larger than one binding.
    pub fn windowed(&self) -> bool {
        self.tiles() > self.window_tiles
    }

    /// The view's 64×64-texel tiles.
    fn tiles(&self) -> u64 {
        u64::from(self.width.div_ceil(crate::sndf::TILE))
            * u64::from(self.height.div_ceil(crate::sndf::TILE))
    }
}

/// A cut packed and uploaded for S-NDF sampling, kept to sample it again.
pub(crate) struct UploadedCut {
    /// The cut's points in consecutive batches ([`Renderer::batch_limits`]), drawn one
    /// after the other into the same G-buffer.
    batches: Vec<SphereBuffers>,
    position_bits: u32,
    species: u32,
}

/// One sampling pass of S-NDFs into tiles (see [`Renderer::accumulate_uploaded`]).
#[derive(Clone, Copy, Debug)]
pub(crate) struct SndfPassSettings {
    pub width: u32,
    pub height: u32,
    pub bins: u32,
    pub binning: crate::sndf::Binning,
    pub iterations: u32,
    /// The first iteration's index in the sub-pixel sequence.
    pub first: u32,
}

/// Sub-pixel offset of sample `s` of `spp` (pixels, in [−0.5, 0.5)).
pub fn jitter(s: u32, spp: u32) -> Vec2 {
    if spp <= 1 {
        Vec2::ZERO
    } else {
        Vec2::new(halton(s + 1, 2) - 0.5, halton(s + 1, 3) - 0.5)
    }
}

/// A device with the pipelines built.
pub struct Renderer {
    pub ctx: GpuContext,
    sphere: SphereRaycastPass,
    accumulate: AccumulatePass,
    splat: Option<SplatPass>,
    density: Option<crate::passes::density::DensityPass>,
    sndf: SndfPass,
    sndf_shade: SndfShadePass,
    /// Particle samples drawn so far (points × samples), so that tests can check that
    /// re-lighting S-NDFs draws none.
    points_sampled: std::sync::atomic::AtomicU64,
    /// The last density frame's (stacks, width, height, iso) and the stacks it needed:
    /// the next such frame's first batch.
    density_hint: std::sync::Mutex<Option<(DensityHintKey, u32)>>,
    /// Sphere frames draw spheres a few pixels wide with the compute raster
    /// (`small_spheres.wgsl`) where the device has it.
    small_spheres: bool,
    /// That raster's buffers, kept between frames.
    small_targets: std::sync::Mutex<Option<SmallSphereTargets>>,
    /// A smaller cap on the points of one batch than the adapter's (see
    /// [`Self::set_batch_points`]).
    batch_points: Option<u32>,
    /// A smaller cap on the bytes of S-NDF histograms one binding holds than the
    /// adapter's (see [`Self::set_sndf_window_bytes`]).
    sndf_window_bytes: Option<u64>,
    /// Where passes of several submissions report them (see [`Self::set_progress`]).
    progress: Option<Arc<dyn Progress + Send + Sync>>,
}

/// Reports a pass of several submissions (batches, samples) to the renderer's progress
/// reporter as the GPU finishes them: after each submission the one before it is waited
/// for, so the GPU always has the next one queued while the host packs the one after,
/// as without a reporter. Passes of one submission report nothing.
struct DrawProgress<'r> {
    renderer: &'r Renderer,
    on: bool,
    pending: Option<wgpu::SubmissionIndex>,
}

impl<'r> DrawProgress<'r> {
    fn begin(renderer: &'r Renderer, stage: &str, submissions: u64) -> Self {
        let on = renderer.progress.is_some() && submissions > 1;
        if on {
            renderer
                .reporter()
                .stage(stage, Some(submissions), "submissions");
        }
        DrawProgress {
            renderer,
            on,
            pending: None,
        }
    }

    /// `index` was submitted: waits for the submission before it and counts that done.
    fn submitted(&mut self, index: wgpu::SubmissionIndex) {
        if let (true, Some(before)) = (self.on, self.pending.replace(index)) {
            self.done(before);
        }
    }

    /// The pass is over: waits for its last submission and counts it done.
    fn finish(mut self) {
        if let (true, Some(last)) = (self.on, self.pending.take()) {
            self.done(last);
        }
    }

    fn done(&self, index: wgpu::SubmissionIndex) {
        let _ = self.renderer.ctx.device.poll(wgpu::PollType::Wait {
            submission_index: Some(index),
            timeout: None,
        });
        self.renderer.reporter().advance(1);
    }
}

/// The stage ends with the pass, also when an error ends it early.
impl Drop for DrawProgress<'_> {
    fn drop(&mut self) {
        if self.on {
            self.renderer.reporter().finish_stage();
        }
    }
}

impl std::fmt::Debug for Renderer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Renderer")
            .field("ctx", &self.ctx)
            .finish_non_exhaustive()
    }
}

/// What a density frame's stack count carries over between: stacks, width, height,
/// iso-surface or not.
type DensityHintKey = (u32, u32, u32, bool);

/// Two timestamps around a frame's passes.
struct FrameTimer {
    set: wgpu::QuerySet,
    resolve: wgpu::Buffer,
    read: wgpu::Buffer,
    /// Timed spans (begin and end stamps each); the GPU time is their sum.
    spans: u32,
}

impl FrameTimer {
    /// Writes for a pass that begins (`begin`) and/or ends (`end`) the timed span.
    fn writes(&self, begin: bool, end: bool) -> wgpu::RenderPassTimestampWrites<'_> {
        self.span_writes(0, begin, end)
    }

    /// The same for span `span` of a timer of several.
    fn span_writes(
        &self,
        span: u32,
        begin: bool,
        end: bool,
    ) -> wgpu::RenderPassTimestampWrites<'_> {
        wgpu::RenderPassTimestampWrites {
            query_set: &self.set,
            beginning_of_pass_write_index: begin.then_some(2 * span),
            end_of_pass_write_index: end.then_some(2 * span + 1),
        }
    }

    /// The same for a compute pass.
    fn compute_writes(&self, begin: bool, end: bool) -> wgpu::ComputePassTimestampWrites<'_> {
        self.compute_span_writes(0, begin, end)
    }

    fn compute_span_writes(
        &self,
        span: u32,
        begin: bool,
        end: bool,
    ) -> wgpu::ComputePassTimestampWrites<'_> {
        wgpu::ComputePassTimestampWrites {
            query_set: &self.set,
            beginning_of_pass_write_index: begin.then_some(2 * span),
            end_of_pass_write_index: end.then_some(2 * span + 1),
        }
    }

    fn resolve(&self, enc: &mut wgpu::CommandEncoder) {
        enc.resolve_query_set(&self.set, 0..2 * self.spans, &self.resolve, 0);
        enc.copy_buffer_to_buffer(&self.resolve, 0, &self.read, 0, 16 * u64::from(self.spans));
    }
}

/// Copies a whole texture (one aspect) into a readback buffer with rows of `row` bytes.
fn copy_to_buffer(
    enc: &mut wgpu::CommandEncoder,
    texture: &wgpu::Texture,
    aspect: wgpu::TextureAspect,
    buffer: &wgpu::Buffer,
    row: u32,
    size: wgpu::Extent3d,
) {
    enc.copy_texture_to_buffer(
        wgpu::TexelCopyTextureInfo {
            texture,
            mip_level: 0,
            origin: wgpu::Origin3d::ZERO,
            aspect,
        },
        wgpu::TexelCopyBufferInfo {
            buffer,
            layout: wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(row),
                rows_per_image: Some(size.height),
            },
        },
        size,
    );
}

/// Begins a render pass into `views` (no depth), clearing them to transparent.
fn clear_pass<'e>(
    enc: &'e mut wgpu::CommandEncoder,
    label: &str,
    views: &[&wgpu::TextureView],
    timestamp_writes: Option<wgpu::RenderPassTimestampWrites<'_>>,
) -> wgpu::RenderPass<'e> {
    cleared_pass_if(enc, label, views, true, timestamp_writes)
}

/// A render pass into `views` that clears them to transparent when `clear`, else draws
/// over what they hold.
fn cleared_pass_if<'e>(
    enc: &'e mut wgpu::CommandEncoder,
    label: &str,
    views: &[&wgpu::TextureView],
    clear: bool,
    timestamp_writes: Option<wgpu::RenderPassTimestampWrites<'_>>,
) -> wgpu::RenderPass<'e> {
    let attachments: Vec<Option<wgpu::RenderPassColorAttachment<'_>>> = views
        .iter()
        .map(|view| {
            Some(wgpu::RenderPassColorAttachment {
                view,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load: cleared_if(clear, wgpu::Color::TRANSPARENT),
                    store: wgpu::StoreOp::Store,
                },
            })
        })
        .collect();
    enc.begin_render_pass(&wgpu::RenderPassDescriptor {
        label: Some(label),
        color_attachments: &attachments,
        depth_stencil_attachment: None,
        timestamp_writes,
        occlusion_query_set: None,
        multiview_mask: None,
    })
}

/// A buffer to read GPU results back into.
pub(crate) fn readback_buffer(device: &wgpu::Device, label: &str, size: u64) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    })
}

/// The first `row_bytes` of each of `rows` rows of `padded` bytes each.
fn unpad_rows(bytes: &[u8], padded: u32, row_bytes: usize, rows: u32) -> Vec<u8> {
    let mut out = Vec::with_capacity(row_bytes * rows as usize);
    for y in 0..rows as usize {
        out.extend_from_slice(&bytes[y * padded as usize..][..row_bytes]);
    }
    out
}

fn padded_row(bytes_per_row: u32) -> u32 {
    bytes_per_row.div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT) * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT
}

impl Renderer {
    pub fn new(ctx: GpuContext) -> Self {
        let sphere = SphereRaycastPass::new(&ctx.device);
        let accumulate = AccumulatePass::new(
            &ctx.device,
            crate::passes::accumulate::accum_format(&ctx.adapter),
        );
        let splat = SplatPass::new(&ctx.device, &sphere.layout);
        let density = crate::passes::density::DensityPass::new(&ctx.device, &sphere.layout);
        let sndf = SndfPass::new(&ctx.device);
        let sndf_shade = SndfShadePass::new(&ctx.device);
        // `MDLOD_SMALL_SPHERES=0` draws every sphere as an impostor quad (to compare, or
        // to step around a driver's trouble with 64-bit atomics).
        let small_spheres = sphere.small.is_some()
            && std::env::var("MDLOD_SMALL_SPHERES").map_or(true, |v| v.trim() != "0");
        Renderer {
            ctx,
            sphere,
            accumulate,
            splat,
            density,
            sndf,
            sndf_shade,
            points_sampled: Default::default(),
            density_hint: Default::default(),
            small_spheres,
            small_targets: Default::default(),
            batch_points: None,
            sndf_window_bytes: None,
            progress: None,
        }
    }

    /// Reports the traversal of large cuts and every pass of several submissions (a cut
    /// drawn in batches, several samples per pixel) to `progress`, as the GPU finishes
    /// each; `None` reports nothing (the default).
    pub fn set_progress(&mut self, progress: Option<Arc<dyn Progress + Send + Sync>>) {
        self.progress = progress;
    }

    /// The progress reporter ([`NoProgress`] when none is set).
    pub fn reporter(&self) -> &dyn Progress {
        match &self.progress {
            Some(p) => p.as_ref(),
            None => &NoProgress,
        }
    }

    /// The most points and ranges one batch of a packed cut holds: each per-point array
    /// (at most 8 bytes a point, and up to 4 bytes of padding a range) and the ranges
    /// (48 bytes each) must fit one storage binding. Every pass draws a larger packed cut
    /// in several batches ([`CutSource::bind_batches`]; S-NDF sampling packs its own the
    /// same way; a streaming pool's cut too, counting its ranges as split at page
    /// boundaries).
    pub fn batch_limits(&self) -> (u32, usize) {
        let max = self.binding_bytes();
        let ranges = max / 64;
        let points = ((max - 4 * ranges) / 8).min(u64::from(u32::MAX)) as u32;
        let points = self.batch_points.map_or(points, |p| p.clamp(1, points));
        (points, ranges as usize)
    }

    /// Caps the points of one batch below the adapter's limit (`None`: the adapter's
    /// limit): less host memory for packing at once, and the way tests draw small cuts
    /// in several batches.
    pub fn set_batch_points(&mut self, points: Option<u32>) {
        self.batch_points = points;
    }

    /// Caps the bytes of resident S-NDF histograms bound at once below the adapter's
    /// binding size (`None`: the adapter's): the way tests sample small images in
    /// several windows.
    pub fn set_sndf_window_bytes(&mut self, bytes: Option<u64>) {
        self.sndf_window_bytes = bytes;
    }

    /// Tiles of `bins × bins` histograms one storage binding holds (at least 1 where
    /// one tile fits), and the largest buffer the device makes.
    fn sndf_window_tiles(&self, bins: u32) -> (u64, u64) {
        let binding = self.binding_bytes();
        let binding = self.sndf_window_bytes.map_or(binding, |b| b.min(binding));
        (
            binding / crate::sndf::tile_bytes(bins).max(1),
            self.ctx.device.limits().max_buffer_size,
        )
    }

    /// The most bytes one storage binding of the device holds.
    pub fn binding_bytes(&self) -> u64 {
        let l = self.ctx.device.limits();
        l.max_storage_buffer_binding_size.min(l.max_buffer_size)
    }

    /// The small-sphere raster and its buffers for a frame of `points` points at
    /// `size`, when it is on and they fit (the buffers kept from an earlier frame when
    /// large enough); give them back with [`Self::keep_small_targets`].
    fn take_small_targets(
        &self,
        size: [u32; 2],
        points: u32,
    ) -> Option<(&SmallSpheres, SmallSphereTargets)> {
        let pass = self.sphere.small.as_ref().filter(|_| self.small_spheres)?;
        let kept = self.small_targets.lock().ok().and_then(|mut k| k.take());
        let targets = pass.prepare(&self.ctx.device, &self.ctx.queue, size, points, kept)?;
        Some((pass, targets))
    }

    /// The raster's buffers for one batch of `points` points of a frame drawn in
    /// `batches` batches: with several, the batch's point count is written into them
    /// before its submission; with one, they stay as [`Self::take_small_targets`]
    /// prepared them.
    fn small_for_batch<'a>(
        &self,
        small: Option<(&'a SmallSpheres, SmallSphereTargets)>,
        size: [u32; 2],
        points: u32,
        batches: usize,
    ) -> Option<(&'a SmallSpheres, SmallSphereTargets)> {
        match small {
            Some((pass, targets)) if batches > 1 => pass
                .prepare(
                    &self.ctx.device,
                    &self.ctx.queue,
                    size,
                    points,
                    Some(targets),
                )
                .map(|t| (pass, t)),
            small => small,
        }
    }

    /// Keeps a frame's small-sphere buffers for the next frame.
    fn keep_small_targets(&self, small: Option<(&SmallSpheres, SmallSphereTargets)>) {
        if let (Some((_, targets)), Ok(mut kept)) = (small, self.small_targets.lock()) {
            *kept = Some(targets);
        }
    }

    /// Whether sphere frames draw small spheres with the compute raster.
    pub fn small_sphere_raster(&self) -> bool {
        self.small_spheres
    }

    /// Turns the compute raster of small spheres on or off (on only where the device
    /// has 64-bit atomics); returns whether it is on.
    pub fn set_small_sphere_raster(&mut self, on: bool) -> bool {
        self.small_spheres = on && self.sphere.small.is_some();
        self.small_spheres
    }

    fn check(&self, s: &FrameSettings) -> Result<(), RenderError> {
        let max = self.ctx.device.limits().max_texture_dimension_2d;
        if s.width == 0 || s.height == 0 || s.width > max || s.height > max {
            return Err(RenderError::InvalidOptions(format!(
                "image size {}x{} (each side must be 1 to {max} on this adapter)",
                s.width, s.height
            )));
        }
        if s.spp == 0 || s.spp > MAX_SPP {
            return Err(RenderError::InvalidOptions(format!(
                "{} samples per pixel (must be 1 to {MAX_SPP})",
                s.spp
            )));
        }
        if s.background_srgb.iter().any(|c| !c.is_finite()) {
            return Err(RenderError::InvalidOptions(
                "background colour is not finite".into(),
            ));
        }
        Ok(())
    }

    /// Draws `draw` (a cut of `file`) as seen by `camera`.
    pub fn render(
        &self,
        file: &MdlodFile,
        camera: &Camera,
        draw: &DrawList,
        settings: &FrameSettings,
    ) -> Result<RenderedFrame, RenderError> {
        self.check(settings)?;
        let source = PackedCut {
            renderer: self,
            file,
            style: PackStyle::Spheres,
            look: &settings.style,
        };
        self.render_from(&source, camera, draw, settings)
    }

    /// Draws the spheres of `draw` from the points `source` binds (a packed cut or a
    /// streaming pool's pages).
    pub fn render_from(
        &self,
        source: &dyn CutSource,
        camera: &Camera,
        draw: &DrawList,
        settings: &FrameSettings,
    ) -> Result<RenderedFrame, RenderError> {
        check_source(source, PackStyle::Spheres, "the sphere pass")?;
        if settings.spp == 1 {
            return self
                .ctx
                .scoped(|| self.render_streamed(source, draw, camera, settings));
        }
        // Several samples draw every batch each: they stay bound for the frame.
        self.ctx.scoped(|| {
            let cut = Batches::of(source, draw)?;
            let batches: Vec<&SphereBuffers> = cut.buffers().collect();
            let mut frame = self.render_bound(
                &batches,
                cut.first().position_bits,
                cut.first().species_count,
                camera,
                settings,
            )?;
            frame.gpu_data_bytes = cut.data_bytes();
            Ok(frame)
        })
    }

    /// The sphere pass, for callers that bind their own buffers (see
    /// [`SphereRaycastPass::bind`]).
    pub fn sphere_pass(&self) -> &SphereRaycastPass {
        &self.sphere
    }

    /// Draws the points of bound sphere buffers: `batches`, one after the other into the
    /// same colour and depth targets (each sample draws every batch), so a cut larger
    /// than one storage binding draws as one would. Call inside [`GpuContext::scoped`]
    /// to turn GPU errors into [`RenderError::Gpu`].
    pub fn render_bound(
        &self,
        batches: &[&SphereBuffers],
        position_bits: u32,
        species_count: u32,
        camera: &Camera,
        settings: &FrameSettings,
    ) -> Result<RenderedFrame, RenderError> {
        let counts: Vec<u32> = batches.iter().map(|b| b.points).collect();
        self.render_batches(
            &counts,
            &mut |b| Ok(BatchRef::Kept(batches[b])),
            false,
            (position_bits, species_count),
            camera,
            settings,
        )
    }

    /// One sample of a cut, its batches bound, drawn and dropped in turn
    /// ([`BatchStream`]: every particle of 10^8 is nine batches of 250 MB).
    fn render_streamed(
        &self,
        source: &dyn CutSource,
        draw: &DrawList,
        camera: &Camera,
        settings: &FrameSettings,
    ) -> Result<RenderedFrame, RenderError> {
        let mut stream = BatchStream::open(source, draw)?;
        let (counts, decoding) = (stream.counts.clone(), stream.decoding);
        let mut frame = self.render_batches(
            &counts,
            &mut |b| Ok(BatchRef::Streamed(stream.take(b)?)),
            true,
            decoding,
            camera,
            settings,
        )?;
        frame.gpu_data_bytes = stream.largest;
        Ok(frame)
    }

    /// Draws batches of `counts` points, `batch(b)` giving batch `b`'s buffers when it
    /// is drawn (each sample draws every batch, in order).
    fn render_batches<'b>(
        &self,
        counts: &[u32],
        batch: &mut dyn FnMut(usize) -> Result<BatchRef<'b>, RenderError>,
        timed_per_batch: bool,
        (position_bits, species_count): (u32, u32),
        camera: &Camera,
        settings: &FrameSettings,
    ) -> Result<RenderedFrame, RenderError> {
        self.check(settings)?;
        let device = &self.ctx.device;
        let queue = &self.ctx.queue;
        let (w, h) = (settings.width, settings.height);
        let size = wgpu::Extent3d {
            width: w,
            height: h,
            depth_or_array_layers: 1,
        };
        let texture = |label: &str, format: wgpu::TextureFormat, usage: wgpu::TextureUsages| {
            device.create_texture(&wgpu::TextureDescriptor {
                label: Some(label),
                size,
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage,
                view_formats: &[],
            })
        };
        use wgpu::TextureUsages as U;
        let sample = texture(
            "sample",
            COLOUR_FORMAT,
            U::RENDER_ATTACHMENT | U::TEXTURE_BINDING,
        );
        let depth = texture("depth", DEPTH_FORMAT, U::RENDER_ATTACHMENT | U::COPY_SRC);
        let output = texture("output", OUTPUT_FORMAT, U::RENDER_ATTACHMENT | U::COPY_SRC);
        let view = |t: &wgpu::Texture| t.create_view(&Default::default());
        let (sample_v, depth_v, output_v) = (view(&sample), view(&depth), view(&output));
        // Several samples are summed with weight 1/N into two targets in turn (sample
        // `s` writes the sum into `sums[(s + 1) % 2]`, reading the other); one sample
        // needs no sum, and the resolve reads it directly.
        let accumulation = (settings.spp > 1).then(|| {
            let target = |label| {
                view(&texture(
                    label,
                    self.accumulate.format,
                    U::RENDER_ATTACHMENT | U::TEXTURE_BINDING,
                ))
            };
            let sums = [target("sum a"), target("sum b")];
            let weight = 1.0 / settings.spp as f32;
            // Bind group `k` reads the sum from `sums[k]`: for the samples that write
            // `sums[1 - k]`.
            let adds = [
                self.accumulate.bind(device, &sample_v, weight, &sums[0]),
                self.accumulate.bind(device, &sample_v, weight, &sums[1]),
            ];
            (sums, adds)
        });
        let total = accumulation
            .as_ref()
            .map_or(&sample_v, |(sums, _)| &sums[(settings.spp % 2) as usize]);
        let resolve_bg = self.accumulate.bind(device, total, 1.0, total);

        let colour_row = padded_row(w * 4);
        let readback = readback_buffer(
            device,
            "colour readback",
            u64::from(colour_row) * u64::from(h),
        );
        let depth_readback = settings.read_depth.then(|| {
            readback_buffer(
                device,
                "depth readback",
                u64::from(colour_row) * u64::from(h),
            )
        });
        let timing = self.frame_timer_of(if timed_per_batch {
            counts.len() as u32
        } else {
            1
        });
        let points: u32 = counts.iter().sum();
        let most = counts.iter().copied().max().unwrap_or(0);
        // The raster's buffers are sized for the largest batch; each batch writes its
        // own point count into them before its submission.
        let mut small = self.take_small_targets([w, h], most);

        let bg = settings
            .background_srgb
            .map(|c| f64::from(srgb_to_linear(c)));
        let view_from_world = camera.view_from_world();
        let ortho = camera.projection == Projection::Orthographic;
        let mut progress = DrawProgress::begin(
            self,
            "drawing",
            u64::from(settings.spp) * counts.len() as u64,
        );
        for s in 0..settings.spp {
            let uniforms = FrameUniforms::new(
                camera.depth_clip_from_view([w, h], jitter(s, settings.spp)),
                view_from_world,
                ortho,
                &settings.lighting,
                position_bits,
                species_count,
            );
            for b in 0..counts.len() {
                let held = batch(b)?;
                let buffers = held.buffers();
                queue.write_buffer(&buffers.uniforms, 0, bytemuck::bytes_of(&uniforms));
                small = self.small_for_batch(small.take(), [w, h], buffers.points, counts.len());
                let mut enc = device.create_command_encoder(&Default::default());
                // Each batch is its own submission: the raster's point count and the
                // frame uniforms are written before it.
                let first = s == 0 && b == 0;
                let opens = b == 0;
                let last = s + 1 == settings.spp && b + 1 == counts.len();
                let sample_done = b + 1 == counts.len();
                // The timed span this batch's passes stamp: one for the frame, or one per
                // batch when each batch waits for its own upload (the GPU idles between).
                let span = if timed_per_batch { b as u32 } else { 0 };
                let span_opens = first || timed_per_batch;
                let span_closes = timed_per_batch && !last;
                if let Some((pass, targets)) = &small {
                    let writes = timing
                        .as_ref()
                        .filter(|_| span_opens)
                        .map(|t| t.compute_span_writes(span, true, false));
                    pass.raster(&mut enc, buffers, targets, writes);
                }
                {
                    // The first batch of a sample clears the targets; later batches draw
                    // over what the earlier ones left, against their depth.
                    let background = if settings.transparent {
                        // Summed with the samples that hit: premultiplied colour, and
                        // alpha the share of hits.
                        wgpu::Color::TRANSPARENT
                    } else {
                        wgpu::Color {
                            r: bg[0],
                            g: bg[1],
                            b: bg[2],
                            a: 1.0,
                        }
                    };
                    let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                        label: Some("spheres"),
                        color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                            view: &sample_v,
                            depth_slice: None,
                            resolve_target: None,
                            ops: wgpu::Operations {
                                load: cleared_if(opens, background),
                                store: wgpu::StoreOp::Store,
                            },
                        })],
                        depth_stencil_attachment: Some(reversed_depth(&depth_v, opens)),
                        timestamp_writes: timing
                            .as_ref()
                            .filter(|_| (span_opens && small.is_none()) || span_closes)
                            .map(|t| {
                                t.span_writes(span, span_opens && small.is_none(), span_closes)
                            }),
                        occlusion_query_set: None,
                        multiview_mask: None,
                    });
                    match &small {
                        Some((small, targets)) => {
                            small.draw(&mut pass, buffers, targets, SphereOutput::Shaded)
                        }
                        None => self.sphere.draw(&mut pass, buffers),
                    }
                }
                if let (true, Some((sums, adds))) = (sample_done, &accumulation) {
                    let written = ((s + 1) % 2) as usize;
                    let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                        label: Some("accumulate"),
                        color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                            view: &sums[written],
                            depth_slice: None,
                            resolve_target: None,
                            ops: wgpu::Operations {
                                // Every pixel is written.
                                load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT),
                                store: wgpu::StoreOp::Store,
                            },
                        })],
                        depth_stencil_attachment: None,
                        timestamp_writes: None,
                        occlusion_query_set: None,
                        multiview_mask: None,
                    });
                    pass.set_pipeline(if s == 0 {
                        &self.accumulate.first
                    } else {
                        &self.accumulate.accumulate
                    });
                    pass.set_bind_group(0, &adds[1 - written], &[]);
                    pass.draw(0..3, 0..1);
                }
                if last {
                    {
                        let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                            label: Some("resolve"),
                            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                                view: &output_v,
                                depth_slice: None,
                                resolve_target: None,
                                ops: wgpu::Operations {
                                    load: wgpu::LoadOp::Clear(wgpu::Color::BLACK),
                                    store: wgpu::StoreOp::Store,
                                },
                            })],
                            depth_stencil_attachment: None,
                            timestamp_writes: timing
                                .as_ref()
                                .map(|t| t.span_writes(span, false, true)),
                            occlusion_query_set: None,
                            multiview_mask: None,
                        });
                        pass.set_pipeline(&self.accumulate.resolve);
                        pass.set_bind_group(0, &resolve_bg, &[]);
                        pass.draw(0..3, 0..1);
                    }
                    copy_to_buffer(
                        &mut enc,
                        &output,
                        wgpu::TextureAspect::All,
                        &readback,
                        colour_row,
                        size,
                    );
                    if let Some(buf) = &depth_readback {
                        copy_to_buffer(
                            &mut enc,
                            &depth,
                            wgpu::TextureAspect::DepthOnly,
                            buf,
                            colour_row,
                            size,
                        );
                    }
                    if let Some(t) = &timing {
                        t.resolve(&mut enc);
                    }
                    if let Some((_, targets)) = &small {
                        targets.copy_draw_args(&mut enc);
                    }
                }
                progress.submitted(queue.submit([enc.finish()]));
            }
        }

        let bytes = self.read_buffer(&readback)?;
        progress.finish();
        let row = (w * 4) as usize;
        let mut image = RgbaImage::new(w, h);
        image.data = unpad_rows(&bytes, colour_row, row, h);
        if settings.transparent {
            image.unpremultiply();
        }
        let depth = match &depth_readback {
            Some(buf) => {
                let bytes = self.read_buffer(buf)?;
                let reversed: Vec<f32> =
                    bytemuck::pod_collect_to_vec(&unpad_rows(&bytes, colour_row, row, h));
                // The buffer holds reversed depth (`Camera::depth_clip_from_view`); the
                // usual z/w from 0 at near to 1 at far is exactly its complement.
                Some(reversed.into_iter().map(|d| 1.0 - d).collect())
            }
            None => None,
        };
        let impostors = match &small {
            Some((_, targets)) if counts.len() == 1 => {
                let read = self.read_buffer(targets.draw_args_readback())?;
                bytemuck::pod_collect_to_vec::<u8, u32>(&read)
                    .get(1)
                    .copied()
            }
            _ => None,
        };
        let gpu_time = self.gpu_time(timing.as_ref())?;
        // sample (RGBA16F) + depth (f32) + two sums (RGBA32F, several samples) + output
        // (RGBA8) + readback.
        let per_pixel = 8 + 4 + if accumulation.is_some() { 32 } else { 0 } + 4;
        let gpu_target_bytes =
            u64::from(w) * u64::from(h) * per_pixel + u64::from(colour_row) * u64::from(h);
        self.count_samples(points, settings.spp);
        let small_bytes = small.as_ref().map_or(0, |(_, targets)| targets.bytes());
        self.keep_small_targets(small);
        Ok(RenderedFrame {
            image,
            depth,
            gpu_time,
            points,
            impostors,
            gpu_data_bytes: 0,
            gpu_target_bytes: gpu_target_bytes + small_bytes,
        })
    }

    /// Particle samples drawn so far by this renderer (points × samples per pixel).
    pub fn points_sampled(&self) -> u64 {
        self.points_sampled
            .load(std::sync::atomic::Ordering::Relaxed)
    }

    fn count_samples(&self, points: u32, samples: u32) {
        self.points_sampled.fetch_add(
            u64::from(points) * u64::from(samples),
            std::sync::atomic::Ordering::Relaxed,
        );
    }

    /// Samples the S-NDFs of `draw` seen by `camera`: `iterations` jittered rays per
    /// texel, `bins × bins` projected-normal bins (see [`crate::sndf`]).
    pub fn sample_sndf(
        &self,
        file: &MdlodFile,
        camera: &Camera,
        draw: &DrawList,
        settings: &SndfSettings,
    ) -> Result<Sndf, RenderError> {
        self.sample_sndf_from(file, camera, draw, settings, 0)
    }

    /// [`Self::sample_sndf`] continuing a progressive sequence: the rays are those of
    /// iterations `first .. first + iterations` of the sub-pixel pattern, so batches
    /// added with [`Sndf::add`] equal one sampling of all their iterations.
    pub fn sample_sndf_from(
        &self,
        file: &MdlodFile,
        camera: &Camera,
        draw: &DrawList,
        settings: &SndfSettings,
        first: u32,
    ) -> Result<Sndf, RenderError> {
        self.sample_sndf_styled(file, camera, draw, settings, first, &Default::default())
    }

    /// [`Self::sample_sndf_from`] with the points' look changed by `style`.
    pub fn sample_sndf_styled(
        &self,
        file: &MdlodFile,
        camera: &Camera,
        draw: &DrawList,
        settings: &SndfSettings,
        first: u32,
        style: &crate::style::PointStyle,
    ) -> Result<Sndf, RenderError> {
        let SndfSettings {
            width,
            height,
            iterations,
            bins,
            ..
        } = *settings;
        self.check(&FrameSettings {
            width,
            height,
            spp: iterations.clamp(1, MAX_SPP),
            ..Default::default()
        })?;
        if iterations == 0 || !(1..=32).contains(&bins) {
            return Err(RenderError::InvalidOptions(format!(
                "{iterations} iterations and {bins} bins (need at least 1 iteration and 1 to 32 bins)"
            )));
        }
        // The resident S-NDFs of one call, continuing the sequence at `first`.
        let mut resident = self.resident_sndf(file, camera, draw, settings, style)?;
        resident.rays = first;
        let gpu_time = self.refine_resident(&mut resident, iterations)?;
        let mut sndf = self.read_resident(&resident)?;
        sndf.rays = iterations;
        sndf.gpu_time = gpu_time;
        Ok(sndf)
    }

    /// Starts S-NDFs of `draw` seen by `camera` that stay on the GPU
    /// (`settings.iterations` is not used: add rays with [`Self::refine_resident`]).
    pub fn resident_sndf(
        &self,
        file: &MdlodFile,
        camera: &Camera,
        draw: &DrawList,
        settings: &SndfSettings,
        style: &crate::style::PointStyle,
    ) -> Result<ResidentSndf, RenderError> {
        let SndfSettings {
            width,
            height,
            bins,
            binning,
            ..
        } = *settings;
        self.check(&FrameSettings {
            width,
            height,
            ..Default::default()
        })?;
        let bytes = crate::sndf::sndf_buffer_bytes(width, height, bins);
        // One buffer; bound a window of tiles at a time where it is larger than a
        // binding (lavapipe binds 128 MiB: 1280×720 texels of 8×8 bins are 1 GiB).
        let (window_tiles, max_buffer) = self.sndf_window_tiles(bins);
        if !(1..=32).contains(&bins) || window_tiles == 0 || bytes > max_buffer {
            // The most bins this image fits.
            let fits = (1..bins.min(33)).rev().find(|&b| {
                self.sndf_window_tiles(b).0 > 0
                    && crate::sndf::sndf_buffer_bytes(width, height, b) <= max_buffer
            });
            let advice = match fits {
                Some(b) => format!("{b}x{b} bins fit (--bins {b}), or a smaller image"),
                None => "use a smaller image".to_string(),
            };
            return Err(RenderError::InvalidOptions(format!(
                "S-NDFs of {width}x{height} texels with {bins}x{bins} bins need {bytes} bytes, \
                 more than one buffer of this adapter holds ({max_buffer} bytes): {advice}"
            )));
        }
        self.ctx.scoped(|| {
            let hist = self.ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("resident sndf histograms"),
                size: bytes,
                usage: wgpu::BufferUsages::STORAGE
                    | wgpu::BufferUsages::COPY_SRC
                    | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            let mut enc = self.ctx.device.create_command_encoder(&Default::default());
            enc.clear_buffer(&hist, 0, None);
            self.ctx.queue.submit([enc.finish()]);
            Ok(ResidentSndf {
                hist,
                window_tiles,
                cut: self.upload_cut(file, draw, style)?,
                camera: camera.clone(),
                width,
                height,
                bins,
                binning,
                rays: 0,
                points: draw.points,
            })
        })
    }

    /// Adds `iterations` rays per texel to resident S-NDFs, continuing their sub-pixel
    /// sequence. Returns the GPU time when measured.
    pub fn refine_resident(
        &self,
        r: &mut ResidentSndf,
        iterations: u32,
    ) -> Result<Option<Duration>, RenderError> {
        if iterations == 0 {
            return Ok(None);
        }
        let windows = r.windows();
        let windows: Vec<_> = windows
            .iter()
            .map(|(binding, pages)| (binding.clone(), pages.as_slice()))
            .collect();
        let gpu = self.ctx.scoped(|| {
            self.accumulate_uploaded(
                &r.cut,
                &r.camera,
                &SndfPassSettings {
                    width: r.width,
                    height: r.height,
                    bins: r.bins,
                    binning: r.binning,
                    iterations,
                    first: r.rays,
                },
                &windows,
            )
        })?;
        r.rays += iterations;
        Ok(gpu)
    }

    /// Shades resident S-NDFs on the GPU (as [`Sndf::shade_with`] does, to rounding):
    /// no particle is touched and only the image is read back. Histograms larger than
    /// one binding are read back and shaded on the host (no GPU time then).
    pub fn shade_resident(
        &self,
        r: &ResidentSndf,
        lights: &ShadeLights,
        background_srgb: [f32; 3],
    ) -> Result<(RgbaImage, Option<Duration>), RenderError> {
        if r.windowed() {
            let sndf = self.read_resident(r)?;
            return Ok((sndf.shade_with(lights, background_srgb), None));
        }
        self.ctx.scoped(|| {
            self.shade_histograms(
                &r.hist,
                (r.width, r.height, Some(r.width.div_ceil(crate::sndf::TILE))),
                (
                    r.bins,
                    r.binning,
                    r.rays,
                    crate::sndf::TexelView::of(&r.camera, r.width, r.height),
                ),
                lights,
                background_srgb,
            )
        })
    }

    /// Reads resident S-NDFs back to the host.
    pub fn read_resident(&self, r: &ResidentSndf) -> Result<Sndf, RenderError> {
        let bytes = r.hist.size();
        let data = self.ctx.scoped(|| {
            let read = readback_buffer(&self.ctx.device, "resident sndf readback", bytes);
            let mut enc = self.ctx.device.create_command_encoder(&Default::default());
            enc.copy_buffer_to_buffer(&r.hist, 0, &read, 0, bytes);
            self.ctx.queue.submit([enc.finish()]);
            self.read_buffer(&read)
        })?;
        Ok(Sndf {
            width: r.width,
            height: r.height,
            bins: r.bins,
            binning: r.binning,
            rays: r.rays,
            hist: tiles_to_rows(&data, r.width, r.height, r.bins),
            gpu_time: None,
            view: crate::sndf::TexelView::of(&r.camera, r.width, r.height),
        })
    }

    /// Packs `draw` (with `style`) and uploads it, for [`Self::accumulate_uploaded`].
    pub(crate) fn upload_cut(
        &self,
        file: &MdlodFile,
        draw: &DrawList,
        style: &crate::style::PointStyle,
    ) -> Result<UploadedCut, RenderError> {
        let source = PackedCut {
            renderer: self,
            file,
            style: PackStyle::Spheres,
            look: style,
        };
        let cuts = source.bind_batches(draw)?;
        let (position_bits, species) = cuts.first().map_or((file.position_bits(), 0), |c| {
            (c.position_bits, c.species_count)
        });
        Ok(UploadedCut {
            batches: cuts.into_iter().map(|c| c.buffers).collect(),
            position_bits,
            species,
        })
    }

    /// Draws `iterations` G-buffers of an uploaded cut seen by `camera` (a `width ×
    /// height` rectangle of texels) and adds them to the histograms of each window
    /// `(hist, pages)`: tile `i` of the rectangle (rows of 64×64-texel tiles) goes to
    /// slot `pages[i]` of the window's binding `hist`, or nowhere for
    /// [`crate::sndf::NO_SLOT`]. Each G-buffer is drawn once for all windows. Returns the
    /// GPU time when measured.
    pub(crate) fn accumulate_uploaded(
        &self,
        cut: &UploadedCut,
        camera: &Camera,
        settings: &SndfPassSettings,
        windows: &[(wgpu::BufferBinding<'_>, &[u32])],
    ) -> Result<Option<Duration>, RenderError> {
        let SndfPassSettings {
            width,
            height,
            bins,
            binning,
            iterations,
            first,
        } = *settings;
        let tiles_x = width.div_ceil(crate::sndf::TILE);
        debug_assert!(windows
            .iter()
            .all(|(_, pages)| pages.len() as u32 == tiles_x * height.div_ceil(crate::sndf::TILE)));
        let device = &self.ctx.device;
        let queue = &self.ctx.queue;
        let layers = crate::sndf::ACCUMULATE_LAYERS.min(iterations).max(1);
        let texture = |label: &str, format, layers| {
            device.create_texture(&wgpu::TextureDescriptor {
                label: Some(label),
                size: wgpu::Extent3d {
                    width,
                    height,
                    depth_or_array_layers: layers,
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage: wgpu::TextureUsages::RENDER_ATTACHMENT
                    | wgpu::TextureUsages::TEXTURE_BINDING,
                view_formats: &[],
            })
        };
        let normals = texture("sndf normals", GBUFFER_FORMAT, layers);
        let albedos = texture("sndf albedos", GBUFFER_FORMAT, layers);
        let depth = texture("sndf depth", DEPTH_FORMAT, 1);
        let array_view = |t: &wgpu::Texture| {
            t.create_view(&wgpu::TextureViewDescriptor {
                dimension: Some(wgpu::TextureViewDimension::D2Array),
                ..Default::default()
            })
        };
        let layer_view = |t: &wgpu::Texture, l: u32| {
            t.create_view(&wgpu::TextureViewDescriptor {
                dimension: Some(wgpu::TextureViewDimension::D2),
                base_array_layer: l,
                array_layer_count: Some(1),
                ..Default::default()
            })
        };
        let (normals_a, albedos_a) = (array_view(&normals), array_view(&albedos));
        let normal_layers: Vec<_> = (0..layers).map(|l| layer_view(&normals, l)).collect();
        let albedo_layers: Vec<_> = (0..layers).map(|l| layer_view(&albedos, l)).collect();
        let depth_v = depth.create_view(&Default::default());
        use wgpu::util::DeviceExt;
        let params_of = |layers| AccumulateParams {
            width,
            height,
            bins,
            binning: binning.code(),
            layers,
            tiles_x,
            tan_half: crate::sndf::TexelView::of(camera, width, height).ray_frame_tan_half(),
        };
        let params = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("sndf params"),
            contents: bytemuck::bytes_of(&params_of(layers)),
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
        });
        let binds: Vec<wgpu::BindGroup> = windows
            .iter()
            .map(|(hist, pages)| {
                let page_buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some("sndf page table"),
                    contents: bytemuck::cast_slice(pages),
                    usage: wgpu::BufferUsages::STORAGE,
                });
                device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some("sndf accumulate"),
                    layout: &self.sndf.layout,
                    entries: &[
                        wgpu::BindGroupEntry {
                            binding: 0,
                            resource: params.as_entire_binding(),
                        },
                        wgpu::BindGroupEntry {
                            binding: 1,
                            resource: wgpu::BindingResource::TextureView(&normals_a),
                        },
                        wgpu::BindGroupEntry {
                            binding: 2,
                            resource: wgpu::BindingResource::TextureView(&albedos_a),
                        },
                        wgpu::BindGroupEntry {
                            binding: 3,
                            resource: wgpu::BindingResource::Buffer(hist.clone()),
                        },
                        wgpu::BindGroupEntry {
                            binding: 4,
                            resource: page_buffer.as_entire_binding(),
                        },
                    ],
                })
            })
            .collect();
        let timing = self.frame_timer();
        let points: u32 = cut.batches.iter().map(|b| b.points).sum();
        let most = cut.batches.iter().map(|b| b.points).max().unwrap_or(0);
        let mut small = self.take_small_targets([width, height], most);
        let mut progress = DrawProgress::begin(
            self,
            "sampling",
            u64::from(iterations) * cut.batches.len() as u64,
        );
        for s in 0..iterations {
            let layer = s % layers;
            let uniforms = FrameUniforms::new(
                camera.depth_clip_from_view(
                    [width, height],
                    // A lone first iteration is centred, as 1-spp ray casting is.
                    jitter(first + s, if first == 0 { iterations } else { u32::MAX }),
                ),
                camera.view_from_world(),
                camera.projection == Projection::Orthographic,
                &Lighting::default(),
                cut.position_bits,
                cut.species,
            );
            let last = s + 1 == iterations;
            let full = layer + 1 == layers;
            if last && !full {
                // The last group fills only some layers.
                queue.write_buffer(&params, 0, bytemuck::bytes_of(&params_of(layer + 1)));
            }
            // Each batch is its own submission (its point count and uniforms are written
            // before it); the first clears the layer and the depth, the others draw over.
            for (b, buffers) in cut.batches.iter().enumerate() {
                queue.write_buffer(&buffers.uniforms, 0, bytemuck::bytes_of(&uniforms));
                small = self.small_for_batch(
                    small.take(),
                    [width, height],
                    buffers.points,
                    cut.batches.len(),
                );
                let opens = b == 0;
                let closes = b + 1 == cut.batches.len();
                let mut enc = device.create_command_encoder(&Default::default());
                if let Some((pass, targets)) = &small {
                    let writes = timing
                        .as_ref()
                        .filter(|_| s == 0 && opens)
                        .map(|t| t.compute_writes(true, false));
                    pass.raster(&mut enc, buffers, targets, writes);
                }
                {
                    let layer_op = |v| wgpu::RenderPassColorAttachment {
                        view: v,
                        depth_slice: None,
                        resolve_target: None,
                        ops: wgpu::Operations {
                            load: cleared_if(opens, wgpu::Color::TRANSPARENT),
                            store: wgpu::StoreOp::Store,
                        },
                    };
                    let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                        label: Some("sndf sample"),
                        color_attachments: &[
                            Some(layer_op(&normal_layers[layer as usize])),
                            Some(layer_op(&albedo_layers[layer as usize])),
                        ],
                        depth_stencil_attachment: Some(reversed_depth(&depth_v, opens)),
                        timestamp_writes: timing
                            .as_ref()
                            .filter(|_| s == 0 && opens && small.is_none())
                            .map(|t| t.writes(true, false)),
                        occlusion_query_set: None,
                        multiview_mask: None,
                    });
                    if let Some((small, targets)) = &small {
                        small.draw(&mut pass, buffers, targets, SphereOutput::GBuffer);
                    } else if buffers.points > 0 {
                        pass.set_pipeline(&self.sphere.gbuffer);
                        pass.set_bind_group(0, &buffers.bind_group, &[]);
                        pass.draw(0..4, 0..buffers.points);
                    }
                }
                if closes && (full || last) {
                    let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                        label: Some("sndf accumulate"),
                        timestamp_writes: timing
                            .as_ref()
                            .filter(|_| last)
                            .map(|t| t.compute_writes(false, true)),
                    });
                    pass.set_pipeline(&self.sndf.pipeline);
                    for bind in &binds {
                        pass.set_bind_group(0, bind, &[]);
                        pass.dispatch_workgroups(width.div_ceil(8), height.div_ceil(8), 1);
                    }
                }
                if closes && last {
                    if let Some(t) = &timing {
                        t.resolve(&mut enc);
                    }
                }
                progress.submitted(queue.submit([enc.finish()]));
            }
        }
        progress.finish();
        self.keep_small_targets(small);
        let gpu_time = self.gpu_time(timing.as_ref())?;
        self.count_samples(points, iterations);
        Ok(gpu_time)
    }

    /// Shades S-NDFs on the GPU (the same result as [`Sndf::shade_with`], to rounding):
    /// uploads them, then one compute pass. Returns the image and the GPU time of the
    /// shading pass alone (what re-lighting costs once the S-NDFs are on the GPU).
    pub fn shade_sndf(
        &self,
        sndf: &Sndf,
        lights: &ShadeLights,
        background_srgb: [f32; 3],
    ) -> Result<(RgbaImage, Option<Duration>), RenderError> {
        let bytes = sndf.hist.len() as u64 * 16;
        if bytes > self.binding_bytes() {
            // More than one binding holds: shaded on the host (the same result).
            return Ok((sndf.shade_with(lights, background_srgb), None));
        }
        self.ctx.scoped(|| {
            use wgpu::util::DeviceExt;
            let hist = self
                .ctx
                .device
                .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some("sndf histograms"),
                    contents: bytemuck::cast_slice(&sndf.hist),
                    usage: wgpu::BufferUsages::STORAGE,
                });
            self.shade_histograms(
                &hist,
                (sndf.width, sndf.height, None),
                (sndf.bins, sndf.binning, sndf.rays, sndf.view),
                lights,
                background_srgb,
            )
        })
    }

    /// The shading pass over histograms on the GPU: `size` is the image and, for the
    /// accumulation's tiled layout, its tiles per row; `sampling` the bins, binning and
    /// rays per texel.
    fn shade_histograms(
        &self,
        hist: &wgpu::Buffer,
        size: (u32, u32, Option<u32>),
        sampling: (u32, crate::sndf::Binning, u32, crate::sndf::TexelView),
        lights: &ShadeLights,
        background_srgb: [f32; 3],
    ) -> Result<(RgbaImage, Option<Duration>), RenderError> {
        use wgpu::util::DeviceExt;
        let ((width, height, tiles_x), (bins, binning, rays, view)) = (size, sampling);
        let (table, grid) = shade_table(bins, binning, lights, view);
        let device = &self.ctx.device;
        let bg = background_srgb.map(srgb_to_linear);
        let init = |label: &str, contents: &[u8], usage| {
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents,
                usage,
            })
        };
        let params = init(
            "shade params",
            bytemuck::bytes_of(&ShadeParams {
                width,
                height,
                bins,
                rays: rays.max(1) as f32,
                background: [bg[0], bg[1], bg[2], 0.0],
                tiled: u32::from(tiles_x.is_some()),
                tiles_x: tiles_x.unwrap_or(0),
                grid,
                ray_frame: u32::from(view.binned_along_rays()),
            }),
            wgpu::BufferUsages::STORAGE,
        );
        let table = init(
            "shade table",
            bytemuck::cast_slice(&table),
            wgpu::BufferUsages::STORAGE,
        );
        self.image_pass(
            "sndf shade",
            (&self.sndf_shade.pipeline, &self.sndf_shade.layout),
            &[&params, &table, hist],
            [width.div_ceil(8), height.div_ceil(8)],
            (width, height),
        )
    }

    /// Runs a compute pass that writes an RGBA8 image: `inputs` are bound in order,
    /// the image's pixel buffer after them; the image is read back. Returns it and the
    /// pass's GPU time.
    pub(crate) fn image_pass(
        &self,
        label: &str,
        (pipeline, layout): (&wgpu::ComputePipeline, &wgpu::BindGroupLayout),
        inputs: &[&wgpu::Buffer],
        workgroups: [u32; 2],
        (width, height): (u32, u32),
    ) -> Result<(RgbaImage, Option<Duration>), RenderError> {
        let device = &self.ctx.device;
        let out_bytes = (u64::from(width) * u64::from(height) * 4).max(4);
        let pixels = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: out_bytes,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let read = readback_buffer(device, label, out_bytes);
        let entries: Vec<_> = inputs
            .iter()
            .copied()
            .chain([&pixels])
            .enumerate()
            .map(|(i, b)| wgpu::BindGroupEntry {
                binding: i as u32,
                resource: b.as_entire_binding(),
            })
            .collect();
        let bind = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(label),
            layout,
            entries: &entries,
        });
        let timing = self.frame_timer();
        let mut enc = device.create_command_encoder(&Default::default());
        {
            let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some(label),
                timestamp_writes: timing.as_ref().map(|t| t.compute_writes(true, true)),
            });
            pass.set_pipeline(pipeline);
            pass.set_bind_group(0, &bind, &[]);
            pass.dispatch_workgroups(workgroups[0], workgroups[1], 1);
        }
        enc.copy_buffer_to_buffer(&pixels, 0, &read, 0, out_bytes);
        if let Some(t) = &timing {
            t.resolve(&mut enc);
        }
        self.ctx.queue.submit([enc.finish()]);
        let bytes = self.read_buffer(&read)?;
        let mut image = RgbaImage::new(width, height);
        let n = image.data.len();
        image.data.copy_from_slice(&bytes[..n]);
        Ok((image, self.gpu_time(timing.as_ref())?))
    }

    /// Accumulates flux-preserving splats of `draw` (see [`crate::passes::splat`]) into a
    /// float image: per pixel, the flux of every colour channel and in total.
    pub fn render_splats(
        &self,
        file: &MdlodFile,
        camera: &Camera,
        draw: &DrawList,
        width: u32,
        height: u32,
        blend: SplatBlend,
    ) -> Result<SplatFrame, RenderError> {
        let source = PackedCut {
            renderer: self,
            file,
            style: splat_style(blend),
            look: &Default::default(),
        };
        let support = crate::passes::splat::DEFAULT_SUPPORT;
        self.render_splats_from(&source, camera, draw, width, height, blend, support)
    }

    /// [`Self::render_splats`] of the points `source` binds for `draw`, with kernels
    /// reaching `support` radii ([`crate::RenderOptions::splat_support`]).
    #[allow(clippy::too_many_arguments)]
    pub fn render_splats_from(
        &self,
        source: &dyn CutSource,
        camera: &Camera,
        draw: &DrawList,
        width: u32,
        height: u32,
        blend: SplatBlend,
        support: f32,
    ) -> Result<SplatFrame, RenderError> {
        if !(support.is_finite() && support > 0.0) {
            return Err(RenderError::InvalidOptions(format!(
                "splat kernel reach {support} radii (must be a finite number above 0)"
            )));
        }
        let Some(splat) = &self.splat else {
            return Err(RenderError::InvalidOptions(format!(
                "splatting needs additive blending of 32-bit floats, which {} does not offer",
                self.ctx.adapter_name()
            )));
        };
        self.check(&FrameSettings {
            width,
            height,
            ..Default::default()
        })?;
        check_source(source, splat_style(blend), "splatting")?;
        self.ctx.scoped(|| {
            let device = &self.ctx.device;
            let queue = &self.ctx.queue;
            // Batches are drawn in order, each in its own pass over what the ones before
            // left: the blending sees the points in the order one batch would give it.
            let mut stream = BatchStream::open(source, draw)?;
            let batches = stream.counts.len();
            let (position_bits, species_count) = stream.decoding;
            let mut uniforms = FrameUniforms::new(
                camera.clip_from_view(width as f32 / height as f32),
                camera.view_from_world(),
                camera.projection == Projection::Orthographic,
                &Default::default(),
                position_bits,
                species_count,
            );
            let (pipeline, intensity, opacity) = match blend {
                SplatBlend::Additive { intensity, .. } => (&splat.pipeline, intensity, 0.0),
                SplatBlend::Over { opacity } => (&splat.over, 1.0, opacity),
            };
            uniforms.material = [width as f32, height as f32, intensity, opacity];
            // The Gaussian's sigma per projected radius (splat.wgsl).
            uniforms.params[2] = support / crate::passes::splat::TRUNCATION;
            let size = wgpu::Extent3d {
                width,
                height,
                depth_or_array_layers: 1,
            };
            let target = device.create_texture(&wgpu::TextureDescriptor {
                label: Some("splat accumulation"),
                size,
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format: HDR_FORMAT,
                usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
                view_formats: &[],
            });
            let view = target.create_view(&Default::default());
            let row = padded_row(width * 16);
            let readback =
                readback_buffer(device, "splat readback", u64::from(row) * u64::from(height));
            // One span per batch: the GPU waits for the host between them.
            let timing = self.frame_timer_of(batches as u32);
            let mut points = 0u32;
            let mut progress = DrawProgress::begin(self, "splatting", batches as u64);
            for b in 0..batches {
                let cut = stream.take(b)?;
                let buffers = &cut.buffers;
                points += buffers.points;
                queue.write_buffer(&buffers.uniforms, 0, bytemuck::bytes_of(&uniforms));
                let mut enc = device.create_command_encoder(&Default::default());
                {
                    let mut pass = cleared_pass_if(
                        &mut enc,
                        "splat",
                        &[&view],
                        b == 0,
                        timing.as_ref().map(|t| t.span_writes(b as u32, true, true)),
                    );
                    if buffers.points > 0 {
                        pass.set_pipeline(pipeline);
                        pass.set_bind_group(0, &buffers.bind_group, &[]);
                        pass.draw(0..4, 0..buffers.points);
                    }
                }
                if b + 1 == batches {
                    copy_to_buffer(
                        &mut enc,
                        &target,
                        wgpu::TextureAspect::All,
                        &readback,
                        row,
                        size,
                    );
                    if let Some(t) = &timing {
                        t.resolve(&mut enc);
                    }
                }
                progress.submitted(queue.submit([enc.finish()]));
            }
            let bytes = self.read_buffer(&readback)?;
            progress.finish();
            let hdr: Vec<[f32; 4]> = unpad_rows(&bytes, row, width as usize * 16, height)
                .chunks_exact(16)
                .map(bytemuck::pod_read_unaligned)
                .collect();
            let gpu_time = self.gpu_time(timing.as_ref())?;
            self.count_samples(points, 1);
            let by_attribute = splat_style(blend) == PackStyle::FluxAttribute;
            Ok(SplatFrame {
                width,
                height,
                hdr,
                by_attribute,
                light_unit: if by_attribute {
                    source.light_unit()
                } else {
                    1.0
                },
                gpu_time,
                points,
                gpu_data_bytes: stream.largest,
            })
        })
    }

    /// Forgets the last density frame's stack count, so the next density frame starts
    /// without a hint (as a first frame does).
    pub fn clear_density_hint(&self) {
        if let Ok(mut h) = self.density_hint.lock() {
            *h = None;
        }
    }

    /// Renders the density volume of `draw` (see [`crate::density`]): slices splatted a
    /// stack at a time and ray cast after each stack, until every ray is done. Coloured
    /// by the attribute, its scale is the file's range, linear; [`Self::render_density_from`]
    /// with a source packed with a look of its own takes another.
    pub fn render_density(
        &self,
        file: &MdlodFile,
        camera: &Camera,
        draw: &DrawList,
        width: u32,
        height: u32,
        settings: &crate::density::DensitySettings,
    ) -> Result<DensityFrame, RenderError> {
        let source = PackedCut {
            renderer: self,
            file,
            style: density_style(settings),
            look: &Default::default(),
        };
        self.render_density_from(&source, file, camera, draw, width, height, settings)
    }

    /// [`Self::render_density`] of the points `source` binds (packed as
    /// [`density_style`] says); `file` gives the host its positions for the slicing.
    #[allow(clippy::too_many_arguments)]
    pub fn render_density_from(
        &self,
        source: &dyn CutSource,
        file: &MdlodFile,
        camera: &Camera,
        draw: &DrawList,
        width: u32,
        height: u32,
        settings: &crate::density::DensitySettings,
    ) -> Result<DensityFrame, RenderError> {
        check_source(source, density_style(settings), "the density volume")?;
        let t0 = std::time::Instant::now();
        use crate::density::{DensityPoint, Slicing};
        use crate::passes::density::{
            DensityGpu, RayGpu, SLICES_GRADIENT, SLICES_PLAIN, SLICES_VALUED, SLICE_FORMAT,
        };
        let Some(pass) = &self.density else {
            return Err(RenderError::InvalidOptions(format!(
                "the density volume needs additive blending of 32-bit floats, which {} does not offer",
                self.ctx.adapter_name()
            )));
        };
        settings.validate().map_err(RenderError::InvalidOptions)?;
        self.check(&FrameSettings {
            width,
            height,
            ..Default::default()
        })?;
        // Every pixel's ray state is bound in one piece.
        let ray_bytes = u64::from(width) * u64::from(height) * std::mem::size_of::<RayGpu>() as u64;
        let most = self.binding_bytes();
        if ray_bytes > most {
            return Err(RenderError::InvalidOptions(format!(
                "the density volume of {width}x{height} pixels keeps {ray_bytes} bytes of ray \
                 state, more than one buffer of {} holds ({most} bytes): render at most {} pixels",
                self.ctx.adapter_name(),
                most / std::mem::size_of::<RayGpu>() as u64
            )));
        }
        // Ranges (a node's children: compact) sorted by their nearest distance along the
        // rays, so that a stack draws one interval of instances: from the first range
        // after which every range ends before the stack (a running maximum of the ends),
        // to the last range that starts before the stack's end (each widened by the
        // largest support).
        // (A file without an attribute: the packer's own error, naming it.)
        let values = match settings.colour_map {
            Some(_) => Some(source.value_scale()?.ok_or_else(|| {
                RenderError::InvalidOptions(
                    "colouring the density volume by the attribute needs points packed with \
                     the attribute's places on its scale"
                        .into(),
                )
            })?),
            None => None,
        };
        let points = crate::density::density_points(file, draw, values.as_ref());
        let mut spans: Vec<(f32, usize, std::ops::Range<usize>, f32)> =
            Vec::with_capacity(draw.ranges.len());
        let mut at = 0usize;
        for (k, r) in draw.ranges.iter().enumerate() {
            let pts = at..(at + r.count as usize).min(points.len());
            at = pts.end;
            let (lo, hi) = points[pts.clone()].iter().fold(
                (f32::INFINITY, f32::NEG_INFINITY),
                |(lo, hi), p| {
                    let d = crate::density::ray_distance(camera, p.position);
                    (lo.min(d), hi.max(d))
                },
            );
            spans.push((lo, k, pts, hi));
        }
        spans.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        let sorted_draw = DrawList {
            ranges: spans.iter().map(|s| draw.ranges[s.1]).collect(),
            ..draw.clone()
        };
        let sorted: Vec<DensityPoint> = spans
            .iter()
            .flat_map(|s| points[s.2.clone()].iter().copied())
            .collect();
        let starts: Vec<f32> = spans.iter().map(|s| s.0).collect();
        // ends_before[j]: the largest end among ranges 0..j.
        let mut ends_before = Vec::with_capacity(spans.len() + 1);
        ends_before.push(f32::NEG_INFINITY);
        for s in &spans {
            let m = ends_before.last().copied().unwrap_or(f32::NEG_INFINITY);
            ends_before.push(m.max(s.3));
        }
        let mut instance_first = Vec::with_capacity(spans.len() + 1);
        instance_first.push(0u32);
        for s in &spans {
            instance_first.push(instance_first.last().copied().unwrap_or(0) + s.2.len() as u32);
        }
        // The density's reference radius: the largest particle's.
        let r_ref = file.max_particle_radius().max(f32::MIN_POSITIVE);
        let slicing = Slicing::new(&sorted, camera, settings, r_ref);
        let h_max = sorted
            .iter()
            .map(|p| settings.kernel_scale * p.support(r_ref))
            .fold(0.0f32, f32::max);
        // The box of the points' supports: rays stop where they leave it.
        let bounds = sorted.iter().fold(
            (
                glam::Vec3::splat(f32::INFINITY),
                glam::Vec3::splat(f32::NEG_INFINITY),
            ),
            |(lo, hi), p| {
                let h = glam::Vec3::splat(settings.kernel_scale * p.support(r_ref));
                (lo.min(p.position - h), hi.max(p.position + h))
            },
        );
        // An empty cut: a point-sized box (no density anywhere) rather than infinities,
        // which the shader's slab test would multiply by zero.
        let bounds = if bounds.0.cmple(bounds.1).all() {
            bounds
        } else {
            (glam::Vec3::ZERO, glam::Vec3::ZERO)
        };
        // A volume (not an iso-surface) coloured by the attribute.
        let valued = settings.iso.is_none() && settings.colour_map.is_some();
        let per_stack = if settings.iso.is_some() {
            SLICES_GRADIENT
        } else if valued {
            SLICES_VALUED
        } else {
            SLICES_PLAIN
        };
        let stacks = slicing.slices.div_ceil(per_stack);
        // The iso-surface is lit in white here and coloured by its own pass afterwards
        // (where no support reaches a hit: the first species' colour, or the colour
        // map's lowest).
        let fallback_albedo = glam::Vec3::from(
            file.metadata()
                .species
                .first()
                .map_or([0.8; 3], |s| s.colour),
        );
        let albedo = [1.0f32; 3];
        self.ctx.scoped(|| {
            let device = &self.ctx.device;
            let queue = &self.ctx.queue;
            // A cut too large for one storage binding comes in batches: instance `i` of
            // the whole is instance `i − first` of the batch that starts at `first`.
            let cuts = Batches::of(source, &sorted_draw)?;
            let cut = cuts.first();
            let host_time = t0.elapsed();
            let aspect = width as f32 / height as f32;
            let uniforms = FrameUniforms::new(
                camera.clip_from_view(aspect),
                camera.view_from_world(),
                camera.projection == Projection::Orthographic,
                &Default::default(),
                cut.position_bits,
                cut.species_count,
            );
            let mut batch_first = Vec::with_capacity(cuts.cuts.len());
            let mut all_points = 0u32;
            for buffers in cuts.buffers() {
                queue.write_buffer(&buffers.uniforms, 0, bytemuck::bytes_of(&uniforms));
                batch_first.push(all_points);
                all_points += buffers.points;
            }
            // Draws instances `first..last` of the whole cut, batch by batch; the caller
            // has set the pipeline and the other bind groups.
            let draw_instances = |rp: &mut wgpu::RenderPass<'_>, first: u32, last: u32| {
                for (buffers, &at) in cuts.buffers().zip(&batch_first) {
                    let (lo, hi) = (first.max(at), last.min(at + buffers.points));
                    if lo < hi {
                        rp.set_bind_group(0, &buffers.bind_group, &[]);
                        rp.draw(0..4, lo - at..hi - at);
                    }
                }
            };
            let basis = crate::density::ray_basis(camera, width, height);
            let records: Vec<DensityGpu> = (0..stacks)
                .map(|st| DensityGpu {
                    basis: basis.to_cols_array_2d(),
                    slicing: [
                        slicing.lambda_min + (st * per_stack) as f32 * slicing.step,
                        slicing.step,
                        settings.kernel_scale,
                        1.0 / r_ref,
                    ],
                    mode: [
                        per_stack.min(slicing.slices - st * per_stack) as f32,
                        if settings.iso.is_some() { 1.0 } else { 0.0 },
                        crate::density::PEAK_FRACTION / settings.kernel_scale.powi(3),
                        settings.density_min,
                    ],
                    size: [
                        width as f32,
                        height as f32,
                        settings.iso.unwrap_or(0.0),
                        settings.density_max,
                    ],
                    clip: settings.clip.unwrap_or([0.0; 4]),
                    flags: [
                        u32::from(settings.clip.is_some()),
                        st,
                        u32::from(settings.log),
                        u32::from(valued),
                    ],
                    albedo: [albedo[0], albedo[1], albedo[2], settings.opacity],
                    pad: [
                        [bounds.0.x, bounds.0.y, bounds.0.z, 0.0],
                        [bounds.1.x, bounds.1.y, bounds.1.z, 0.0],
                        [0.0; 4],
                        [0.0; 4],
                        [0.0; 4],
                        [0.0; 4],
                    ],
                })
                .collect();
            let stride = std::mem::size_of::<DensityGpu>() as u64;
            let slicing_buf = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("density slicing"),
                size: stride * u64::from(stacks),
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            queue.write_buffer(&slicing_buf, 0, bytemuck::cast_slice(&records));
            let size = wgpu::Extent3d {
                width,
                height,
                depth_or_array_layers: 1,
            };
            let slice_tex = |label| {
                device.create_texture(&wgpu::TextureDescriptor {
                    label: Some(label),
                    size,
                    mip_level_count: 1,
                    sample_count: 1,
                    dimension: wgpu::TextureDimension::D2,
                    format: SLICE_FORMAT,
                    usage: wgpu::TextureUsages::RENDER_ATTACHMENT
                        | wgpu::TextureUsages::TEXTURE_BINDING
                        | wgpu::TextureUsages::COPY_SRC,
                    view_formats: &[],
                })
            };
            let (ta, tb) = (slice_tex("density slices a"), slice_tex("density slices b"));
            let (va, vb) = (
                ta.create_view(&Default::default()),
                tb.create_view(&Default::default()),
            );
            let pixels = u64::from(width) * u64::from(height);
            let ray_bytes = pixels * std::mem::size_of::<RayGpu>() as u64;
            let rays = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("density rays"),
                size: ray_bytes,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            });
            let active = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("density active rays"),
                size: 4,
                usage: wgpu::BufferUsages::STORAGE
                    | wgpu::BufferUsages::COPY_SRC
                    | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            // Active rays after each checkpoint stack of a batch (see below).
            const MAX_CHECKS: u64 = 64;
            let counts = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("density active counts"),
                size: 4 * MAX_CHECKS,
                usage: wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            let counts_read = readback_buffer(device, "active counts readback", 4 * MAX_CHECKS);
            let record = wgpu::BufferBinding {
                buffer: &slicing_buf,
                offset: 0,
                size: std::num::NonZeroU64::new(stride),
            };
            let slicing_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("density slicing"),
                layout: &pass.slicing_layout,
                entries: &[wgpu::BindGroupEntry {
                    binding: 0,
                    resource: wgpu::BindingResource::Buffer(record.clone()),
                }],
            });
            let table = crate::passes::sphere_raycast::storage_buffer(
                device,
                "density colour table",
                bytemuck::cast_slice(&crate::passes::density::colour_table(
                    settings.colour_map.filter(|_| valued),
                )),
            );
            let composite_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("density composite"),
                layout: &pass.composite_layout,
                entries: &[
                    wgpu::BindGroupEntry {
                        binding: 0,
                        resource: wgpu::BindingResource::Buffer(record),
                    },
                    wgpu::BindGroupEntry {
                        binding: 1,
                        resource: wgpu::BindingResource::TextureView(&va),
                    },
                    wgpu::BindGroupEntry {
                        binding: 2,
                        resource: wgpu::BindingResource::TextureView(&vb),
                    },
                    wgpu::BindGroupEntry {
                        binding: 3,
                        resource: rays.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 4,
                        resource: active.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 5,
                        resource: table.as_entire_binding(),
                    },
                ],
            });
            // Early ray termination with frame-to-frame coherence (the paper's section
            // 3.4): the stacks run in batches, and the rays still active are counted at
            // checkpoint stacks (the counter cleared before the stack, copied after it)
            // and read back once per batch. Without a hint the batches are GROUP stacks
            // long. With the previous frame's stack count as a hint, the first batch runs
            // that many at once, with checkpoints every GROUP stacks and just before its
            // end, so a still or slowly moving view reads back once; rays left over go on
            // in batches. The stacks needed (the first checkpoint with no active ray) are
            // the next frame's hint. A wrong hint costs time only: stacks after every ray
            // is done change nothing.
            const GROUP: u32 = 8;
            let hint_key = (stacks, width, height, settings.iso.is_some());
            let hint = self
                .density_hint
                .lock()
                .ok()
                .and_then(|h| h.filter(|h| h.0 == hint_key).map(|h| h.1));
            let mut stacks_run = 0u32;
            let mut needed = None;
            let mut readbacks = 0u32;
            let mut splatted = 0u64;
            let mut st = 0u32;
            // Stacks as they are composited; a frame whose rays all end early stops
            // short of the total.
            let reporter = self.reporter();
            let reported = self.progress.is_some() && stacks > 1;
            if reported {
                reporter.stage("density stacks", Some(u64::from(stacks)), "stacks");
            }
            while st < stacks && needed.is_none() {
                let group_start = st;
                let end = match hint {
                    Some(h) if st == 0 => h.clamp(1, stacks),
                    _ => (st + GROUP).min(stacks),
                };
                let mut checks: Vec<u32> = (st..end)
                    .filter(|k| (k + 1 - st).is_multiple_of(GROUP))
                    .chain(
                        [16, 4, 2, 1, 0]
                            .iter()
                            .filter_map(|&c| (end - 1).checked_sub(c)),
                    )
                    .filter(|&k| k >= st)
                    .collect();
                checks.sort_unstable();
                checks.dedup();
                // Keep the last MAX_CHECKS (the end is always checked).
                let drop = checks.len().saturating_sub(MAX_CHECKS as usize);
                checks.drain(..drop);
                let mut enc = device.create_command_encoder(&Default::default());
                for k in st..end {
                    let slot = checks.binary_search(&k).ok();
                    if slot.is_some() {
                        enc.clear_buffer(&active, 0, None);
                    }
                    let rec = &records[k as usize];
                    let (a, b) = (
                        rec.slicing[0],
                        rec.slicing[0] + (rec.mode[0] - 1.0) * rec.slicing[1],
                    );
                    // The last j whose predecessors all end before the stack.
                    let skip = ends_before
                        .partition_point(|&e| e < a - h_max)
                        .saturating_sub(1);
                    let first = instance_first[skip];
                    let last =
                        instance_first[starts.partition_point(|&d| d <= b + h_max).max(skip)];
                    let offset = (u64::from(k) * stride) as u32;
                    {
                        let mut rp = clear_pass(&mut enc, "density slices", &[&va, &vb], None);
                        if last > first {
                            rp.set_pipeline(&pass.splat);
                            rp.set_bind_group(1, &slicing_group, &[offset]);
                            draw_instances(&mut rp, first, last);
                            splatted += u64::from(last - first);
                        }
                    }
                    {
                        let mut cp = enc.begin_compute_pass(&Default::default());
                        cp.set_pipeline(&pass.composite);
                        cp.set_bind_group(0, &composite_group, &[offset]);
                        cp.dispatch_workgroups(width.div_ceil(8), height.div_ceil(8), 1);
                    }
                    if let Some(j) = slot {
                        enc.copy_buffer_to_buffer(&active, 0, &counts, 4 * j as u64, 4);
                    }
                }
                let n = 4 * checks.len() as u64;
                enc.copy_buffer_to_buffer(&counts, 0, &counts_read, 0, n);
                queue.submit([enc.finish()]);
                readbacks += 1;
                stacks_run = end;
                st = end;
                let bytes = self.read_buffer(&counts_read)?;
                if reported {
                    reporter.advance(u64::from(end - group_start));
                }
                needed = checks
                    .iter()
                    .zip(bytes.chunks_exact(4))
                    .find(|(_, c)| u32::from_le_bytes([c[0], c[1], c[2], c[3]]) == 0)
                    .map(|(&k, _)| k + 1);
            }
            let needed = needed.unwrap_or(stacks_run);
            if reported {
                reporter.finish_stage();
            }
            if let Ok(mut h) = self.density_hint.lock() {
                *h = Some((hint_key, needed));
            }
            let read = readback_buffer(device, "density rays readback", ray_bytes);
            let mut enc = device.create_command_encoder(&Default::default());
            enc.copy_buffer_to_buffer(&rays, 0, &read, 0, ray_bytes);
            // The iso-surface's colour: every point's albedo weighted at the hits.
            let colour_row = padded_row(width * 16);
            let colour_read = settings.iso.is_some().then(|| {
                let target = slice_tex("density iso colour");
                let hits_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some("density hits"),
                    layout: &pass.hits_layout,
                    entries: &[wgpu::BindGroupEntry {
                        binding: 0,
                        resource: rays.as_entire_binding(),
                    }],
                });
                {
                    let view = target.create_view(&Default::default());
                    let mut rp = clear_pass(&mut enc, "density iso colour", &[&view], None);
                    if all_points > 0 {
                        rp.set_pipeline(&pass.colour);
                        rp.set_bind_group(1, &slicing_group, &[0]);
                        rp.set_bind_group(2, &hits_group, &[]);
                        draw_instances(&mut rp, 0, all_points);
                    }
                }
                let read = readback_buffer(
                    device,
                    "density iso colour readback",
                    u64::from(colour_row) * u64::from(height),
                );
                copy_to_buffer(
                    &mut enc,
                    &target,
                    wgpu::TextureAspect::All,
                    &read,
                    colour_row,
                    size,
                );
                read
            });
            queue.submit([enc.finish()]);
            let bytes = self.read_buffer(&read)?;
            let mut rays: Vec<RayGpu> = bytes
                .chunks_exact(48)
                .map(bytemuck::pod_read_unaligned)
                .collect();
            if let Some(read) = &colour_read {
                let bytes = self.read_buffer(read)?;
                let sums = unpad_rows(&bytes, colour_row, width as usize * 16, height);
                for (ray, sum) in rays.iter_mut().zip(sums.chunks_exact(16)) {
                    let sum: [f32; 4] = bytemuck::pod_read_unaligned(sum);
                    let mean =
                        (sum[3] > 0.0).then(|| glam::Vec3::new(sum[0], sum[1], sum[2]) / sum[3]);
                    let albedo = crate::density::surface_albedo(mean, settings, fallback_albedo);
                    for k in 0..3 {
                        ray.colour[k] *= albedo[k];
                    }
                }
            }
            self.count_samples(splatted.min(u64::from(u32::MAX)) as u32, 1);
            Ok(DensityFrame {
                width,
                height,
                rgba: rays.iter().map(|r| r.colour).collect(),
                hit: rays
                    .iter()
                    .map(|r| {
                        if r.state[3] > 0.5 {
                            r.state[1]
                        } else {
                            f32::NAN
                        }
                    })
                    .collect(),
                points: sorted,
                slicing,
                stacks,
                stacks_run,
                stacks_needed: needed,
                stacks_hint: hint,
                readbacks,
                splatted,
                gpu_data_bytes: cuts.data_bytes(),
                host_time,
            })
        })
    }

    /// Timestamp queries for a frame's passes, when the device has them.
    fn frame_timer(&self) -> Option<FrameTimer> {
        self.frame_timer_of(1)
    }

    /// A timer of `spans` spans, whose GPU time is their sum (what the GPU worked, not
    /// the gaps between spans where it waited for the host).
    fn frame_timer_of(&self, spans: u32) -> Option<FrameTimer> {
        let device = &self.ctx.device;
        let spans = spans.max(1);
        self.ctx.timestamps().then(|| FrameTimer {
            set: device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("frame time"),
                ty: wgpu::QueryType::Timestamp,
                count: 2 * spans,
            }),
            resolve: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("timestamps"),
                size: 16 * u64::from(spans),
                usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            }),
            read: readback_buffer(device, "timestamps readback", 16 * u64::from(spans)),
            spans,
        })
    }

    /// The sum of the timer's spans, each between its two stamps (after the frame was
    /// submitted).
    fn gpu_time(&self, timer: Option<&FrameTimer>) -> Result<Option<Duration>, RenderError> {
        let Some(t) = timer else {
            return Ok(None);
        };
        let bytes = self.read_buffer(&t.read)?;
        let stamp =
            |k: usize| u64::from_le_bytes(bytes[8 * k..8 * k + 8].try_into().unwrap_or_default());
        let ticks: u64 = (0..t.spans as usize)
            .map(|k| stamp(2 * k + 1).saturating_sub(stamp(2 * k)))
            .sum();
        let ns = ticks as f64 * f64::from(self.ctx.queue.get_timestamp_period());
        Ok(Some(Duration::from_nanos(ns as u64)))
    }

    pub(crate) fn read_buffer(&self, buffer: &wgpu::Buffer) -> Result<Vec<u8>, RenderError> {
        let (tx, rx) = std::sync::mpsc::channel();
        buffer.map_async(wgpu::MapMode::Read, .., move |r| {
            let _ = tx.send(r);
        });
        self.ctx
            .device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| RenderError::Gpu(format!("waiting for the GPU: {e}")))?;
        rx.recv()
            .map_err(|_| RenderError::Gpu("readback was cancelled".into()))?
            .map_err(|e| RenderError::Gpu(format!("mapping a readback buffer: {e}")))?;
        let data = buffer
            .get_mapped_range(..)
            .map_err(|e| RenderError::Gpu(format!("reading a mapped buffer: {e:?}")))?
            .to_vec();
        buffer.unmap();
        Ok(data)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A projection's colour map: decades evenly on a log axis between the range's ends,
    /// clamped outside them, the background where no light fell; linear from 0 without.
    #[test]
    fn a_projection_maps_its_light_through_the_colour_map() {
        use crate::style::ColourMap;
        let lights = [0.0f32, 1.0, 10.0, 100.0, 1000.0, 5000.0];
        let frame = SplatFrame {
            width: lights.len() as u32,
            height: 1,
            hdr: lights.iter().map(|&l| [l, l, l, l]).collect(),
            by_attribute: true,
            light_unit: 1.0,
            gpu_time: None,
            points: 0,
            gpu_data_bytes: 0,
        };
        let map = ColourMap::Magma;
        let encode = |t: f32| {
            map.colour(t)
                .map(|v| (linear_to_srgb(v) * 255.0 + 0.5) as u8)
        };
        let (image, range, _) =
            frame.colour_mapped(map, true, Some([1.0, 1000.0]), [0.2, 0.4, 0.6]);
        assert_eq!(range, [1.0, 1000.0]);
        let px = |i: usize| {
            [
                image.data[4 * i],
                image.data[4 * i + 1],
                image.data[4 * i + 2],
            ]
        };
        assert_eq!(px(0), [51, 102, 153], "no light: the background");
        for (i, t) in [(1, 0.0), (2, 1.0 / 3.0), (3, 2.0 / 3.0), (4, 1.0), (5, 1.0)] {
            let want = encode(t);
            let got = px(i);
            assert!(
                (0..3).all(|k| got[k].abs_diff(want[k]) <= 1),
                "light {}: {got:?} against {want:?}",
                lights[i]
            );
        }
        // Linear, from the image: 0 to the lit pixels' 99.5th percentile (the brightest
        // of these five).
        let (image, range, _) = frame.colour_mapped(map, false, None, [0.0; 3]);
        assert_eq!(range, [0.0, 5000.0]);
        let got = [image.data[8], image.data[9], image.data[10]];
        assert_eq!(got, encode(10.0 / 5000.0));
    }

    #[test]
    fn jitter_offsets_are_sub_pixel_and_centred() {
        assert_eq!(jitter(0, 1), Vec2::ZERO);
        let n = 64;
        let mut mean = Vec2::ZERO;
        for s in 0..n {
            let j = jitter(s, n);
            assert!(j.x.abs() <= 0.5 && j.y.abs() <= 0.5);
            mean += j / n as f32;
        }
        assert!(mean.length() < 0.03, "{mean}");
    }

    #[test]
    fn srgb_conversion_end_points() {
        assert_eq!(srgb_to_linear(0.0), 0.0);
        assert!((srgb_to_linear(1.0) - 1.0).abs() < 1e-6);
        assert!((srgb_to_linear(0.5) - 0.214).abs() < 1e-3);
    }
}
