//! The virtual screen-space mipmap of S-NDFs (S-MIP; Ibrahim et al. 2017, section 6):
//! S-NDFs cached in tiles that outlive the view, so panning and zooming sample only what
//! newly comes into view.
//!
//! How it works.
//! 1. **Frame.** An S-MIP belongs to one view direction, one look of the points and one
//!    file ([`SmipFrame`]): a grid parallel to the screen, in the plane coordinates
//!    `(u, v)` = (world · right, world · up) of an orthographic camera. Level 0's texels
//!    are `texel0` world units wide, fine enough that the smallest sphere covers at least
//!    `N` texels (`π r² / texel0² ≥ N`), and aligned with the first view's pixels; level
//!    `L`'s texels are `2^L` times wider. Tiles are 64×64 texels, addressed by
//!    `(level, x, y)` with signed `x`, `y` (the grid is unbounded).
//!    Orthographic views only: under perspective, a pan or zoom moves the eye and the
//!    parallax changes every texel, so there is nothing to reuse.
//! 2. **Levels of a view.** A view whose pixels are `p` world units wide shows level
//!    `f = log2(p / texel0)`: levels `⌊f⌋` and `⌊f⌋ + 1`, blended by the fraction
//!    (trilinear, as a texture mipmap is read), or level 0 alone when zoomed in past
//!    it. The tiles under the view's pixel centres are needed; bilinear neighbours
//!    beyond the view's edge are clamped, as at a texture's edge.
//! 3. **Cache.** A fixed pool of tile slots on the GPU (one buffer) and a page table on
//!    the host (tile → slot, rays per texel, last use). A needed tile that is not
//!    resident gets a free slot, or the least recently used slot of a tile this view
//!    does not need.
//! 4. **Filling a tile.** A tile of level `L + 1` whose four children are resident (with
//!    equal rays) is their 2×2 down-sampling on the GPU (`smip_downsample.wgsl`): no
//!    particle is touched. Otherwise it is sampled: missing tiles are grouped into
//!    rectangles (runs along tile rows, merged down columns); each rectangle is drawn by
//!    an orthographic camera covering exactly its texels, with the hierarchy cut chosen
//!    against that level's texel size and culled to the rectangle, and its histograms
//!    accumulate straight into the pool through the rectangle's page table
//!    (`sndf_accumulate.wgsl`).
//! 5. **Progressive refinement** ([`Smip::refine`]) adds iterations to the view's sampled
//!    tiles, continuing each tile's sub-pixel sequence; tiles with different ray counts
//!    are refined in separate rectangles. Down-sampled tiles are derived again.
//! 6. **Shading** ([`Smip::shade`]) needs no particle: the composite pass
//!    (`smip_composite.wgsl`) maps each pixel to both levels, shades the four nearest
//!    texels of each from their S-NDFs and blends them trilinearly. Re-lighting is this
//!    pass alone.
//!
//! A change of view direction, projection, particle radius or style, bins or file means
//! a new frame: every tile is dropped ([`SmipStats::invalidated`]).

use std::collections::{BTreeMap, HashMap, HashSet};
use std::time::Duration;

use bytemuck::{Pod, Zeroable};
use glam::Vec3;
use mdlod_format::sndf::{SndfData, SndfHeader, SndfTile, SndfTiles};
use mdlod_format::MdlodFile;

use crate::camera::{Bounds, Camera, Projection};
use crate::error::RenderError;
use crate::image::RgbaImage;
use crate::occlusion::OcclusionMode;
use crate::renderer::{linear_to_srgb, srgb_to_linear, Renderer, SndfPassSettings, UploadedCut};
use crate::sndf::{shade_table, tile_bytes, Binning, ShadeLights, TexelView, NO_SLOT, TILE};
use crate::style::PointStyle;
use crate::traversal::{traverse, TraversalSettings};

/// WGSL source of the down-sampling pass.
pub const DOWNSAMPLE_SHADER: &str = include_str!("passes/smip_downsample.wgsl");
/// WGSL source of the composite (shading) pass.
pub const COMPOSITE_SHADER: &str = include_str!("passes/smip_composite.wgsl");

/// Deepest level an S-MIP addresses.
const MAX_LEVEL: u32 = 30;
/// A level fraction this close to a whole number shows one level alone.
const LEVEL_SNAP: f64 = 1e-4;
/// Pixel centres this close to a texel boundary count as inside (rounding of views on
/// texel centres).
const SPAN_SLACK: f64 = 1e-3;

/// `DownParams` in `smip_downsample.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct DownParams {
    pub bins: u32,
    pub parent: u32,
    pub pad: [u32; 2],
    pub children: [u32; 4],
}

/// `Level` in `smip_composite.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct LevelParams {
    pub origin: [f32; 2],
    pub step: f32,
    pub weight: f32,
    pub tiles: [u32; 2],
    pub page_offset: u32,
    pub pad: u32,
}

/// `Params` in `smip_composite.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct CompositeParams {
    pub width: u32,
    pub height: u32,
    pub bins: u32,
    pub levels: u32,
    pub background: [f32; 4],
    pub level: [LevelParams; 2],
}

/// A tile's address: level, and column and row of 64×64-texel tiles (rows go down).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct TileKey {
    pub level: u32,
    pub x: i32,
    pub y: i32,
}

impl TileKey {
    /// The four tiles of the level below, in quadrant order (top left, top right,
    /// bottom left, bottom right).
    pub fn children(self) -> Option<[TileKey; 4]> {
        let level = self.level.checked_sub(1)?;
        let (x, y) = (self.x * 2, self.y * 2);
        Some([(0, 0), (1, 0), (0, 1), (1, 1)].map(|(dx, dy)| TileKey {
            level,
            x: x + dx,
            y: y + dy,
        }))
    }
}

/// What every tile of an S-MIP depends on; a different frame drops them all.
#[derive(Clone, Debug, PartialEq)]
pub struct SmipFrame {
    pub azimuth_deg: f32,
    pub elevation_deg: f32,
    /// The orthographic camera's field of view (it relates distance and view height).
    pub fov_y_deg: f32,
    /// World units per texel of level 0.
    pub texel0: f64,
    /// Plane coordinates `(u, v)` of level 0's texel corner `(0, 0)` (top left).
    pub origin: [f64; 2],
    pub bins: u32,
    pub binning: Binning,
    /// The data and the points' look (the caller's description: file, style).
    pub content: String,
}

impl SmipFrame {
    /// The frame of a file's tiles `t` (header `h`), seen through `camera` (its view).
    fn of_file(h: &SndfHeader, t: &SndfTiles, camera: &Camera) -> SmipFrame {
        SmipFrame {
            azimuth_deg: camera.azimuth_deg,
            elevation_deg: camera.elevation_deg,
            fov_y_deg: camera.fov_y_deg,
            texel0: t.texel0,
            origin: t.origin,
            bins: h.bins,
            binning: Binning::from_name(&h.binning).unwrap_or_default(),
            content: h.source.clone().unwrap_or_default(),
        }
    }

    /// The frame of an orthographic view of `width × height` pixels: level 0 aligned with
    /// its pixels, `2^-k` of their size for the smallest `k` at which a sphere of
    /// `min_radius` covers at least `samples_per_sphere` texels.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        camera: &Camera,
        width: u32,
        height: u32,
        min_radius: f32,
        samples_per_sphere: f32,
        bins: u32,
        binning: Binning,
        content: String,
    ) -> Result<SmipFrame, RenderError> {
        if camera.projection != Projection::Orthographic {
            return Err(RenderError::InvalidOptions(
                "an S-MIP needs an orthographic view (under perspective a pan moves the eye)"
                    .into(),
            ));
        }
        camera.check().map_err(RenderError::InvalidOptions)?;
        if width == 0 || height == 0 || !(1..=32).contains(&bins) {
            return Err(RenderError::InvalidOptions(format!(
                "an S-MIP of a {width}x{height} view with {bins} bins"
            )));
        }
        let p0 = f64::from(camera.view_height_at_target()) / f64::from(height);
        let r = f64::from(min_radius);
        let n = f64::from(samples_per_sphere.max(0.0));
        let mut texel0 = p0;
        let mut k = 0;
        while r.is_finite() && r > 0.0 && std::f64::consts::PI * (r / texel0).powi(2) < n && k < 20
        {
            texel0 *= 0.5;
            k += 1;
        }
        let (uc, vc) = plane_of(camera, camera.target);
        Ok(SmipFrame {
            azimuth_deg: camera.azimuth_deg,
            elevation_deg: camera.elevation_deg,
            fov_y_deg: camera.fov_y_deg,
            texel0,
            origin: [
                uc - f64::from(width) * 0.5 * p0,
                vc + f64::from(height) * 0.5 * p0,
            ],
            bins,
            binning,
            content,
        })
    }

    /// Whether `camera` looks along this frame's direction, orthographically (so that its
    /// views are pans and zooms of the frame's).
    pub fn fits(&self, camera: &Camera) -> bool {
        camera.projection == Projection::Orthographic
            && camera.azimuth_deg == self.azimuth_deg
            && camera.elevation_deg == self.elevation_deg
            && camera.fov_y_deg == self.fov_y_deg
    }

    /// World units per texel of `level`.
    pub fn texel(&self, level: u32) -> f64 {
        self.texel0 * f64::from(1u32 << level.min(MAX_LEVEL))
    }
}

/// The smallest sphere radius of `file` under `style` (the species' smallest particles,
/// scaled as the style scales their species; clusters are larger).
pub fn min_radius(file: &MdlodFile, style: &PointStyle) -> f32 {
    file.metadata()
        .species
        .iter()
        .enumerate()
        .map(|(i, s)| {
            let own = style
                .species
                .iter()
                .find(|x| x.name == s.name)
                .and_then(|x| x.radius);
            file.species_radius_span_at(i, own.unwrap_or(s.radius) * style.radius_scale)[0]
        })
        .fold(f32::INFINITY, f32::min)
}

/// Plane coordinates `(u, v)` of a world point under the camera's orientation.
fn plane_of(camera: &Camera, p: Vec3) -> (f64, f64) {
    (
        f64::from(p.dot(camera.right())),
        f64::from(p.dot(camera.up())),
    )
}

/// Sampling settings of an S-MIP.
#[derive(Clone, Debug, PartialEq)]
pub struct SmipConfig {
    /// Tile slots in the GPU pool (capped by the adapter's largest buffer).
    pub pool_tiles: u32,
    /// Largest projected size, in texels of the level sampled, of a node drawn as its
    /// representative.
    pub error_px: f32,
    /// Most spheres per full rectangle of [`MAX_RECT_TILES`]² tiles; a smaller rectangle
    /// gets its share by area, so that the cut's density does not depend on how tiles
    /// were grouped (clamped to what one GPU buffer holds).
    pub budget_points: u64,
    pub occlusion: OcclusionMode,
}

impl Default for SmipConfig {
    fn default() -> Self {
        SmipConfig {
            pool_tiles: 256,
            error_px: 1.0,
            budget_points: 4_000_000,
            occlusion: OcclusionMode::WholePixels,
        }
    }
}

/// What a call did to the cache.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SmipStats {
    /// The finer level shown and the coarser one's share of the blend.
    pub level: u32,
    pub blend: f32,
    /// Tiles the view needs (both levels).
    pub needed: u32,
    /// Needed tiles that were already resident.
    pub reused: u32,
    /// Tiles sampled from the particles, and rectangles drawn to do it.
    pub sampled: u32,
    pub rects: u32,
    /// Tiles made by down-sampling resident tiles.
    pub downsampled: u32,
    /// Tiles evicted to make room.
    pub evicted: u32,
    /// Spheres drawn per iteration, over the sampled rectangles.
    pub points: u64,
    /// Spheres drawn times iterations.
    pub particle_samples: u64,
    /// All tiles were dropped for a new frame.
    pub invalidated: bool,
    pub gpu_time: Option<Duration>,
}

/// A tile's histograms as read back.
#[derive(Clone, Debug, PartialEq)]
pub struct TileData {
    /// Texels in rows (64 × 64), each `bins²` bins.
    pub hist: Vec<[f32; 4]>,
    /// Rays per texel.
    pub rays: u32,
}

#[derive(Clone, Copy, Debug)]
struct Tile {
    slot: u32,
    rays: u32,
    /// Made by down-sampling its children.
    derived: bool,
    used: u64,
}

/// The levels a view shows, and where its pixels fall in them.
#[derive(Clone, Debug)]
struct LevelPlan {
    level: u32,
    weight: f64,
    /// Texel coordinates of pixel (0, 0)'s centre.
    origin: [f64; 2],
    /// Texels per pixel.
    step: f64,
    /// Tiles needed: x0..x1, y0..y1.
    tiles: [i32; 4],
}

impl LevelPlan {
    fn keys(&self) -> impl Iterator<Item = TileKey> + '_ {
        let [x0, x1, y0, y1] = self.tiles;
        (y0..y1).flat_map(move |y| {
            (x0..x1).map(move |x| TileKey {
                level: self.level,
                x,
                y,
            })
        })
    }
}

/// The S-MIP cache: a pool of tile slots on the GPU and its page table.
pub struct Smip {
    config: SmipConfig,
    frame: Option<SmipFrame>,
    tiles: HashMap<TileKey, Tile>,
    free: Vec<u32>,
    capacity: u32,
    clock: u64,
    pool: wgpu::Buffer,
    bins: u32,
    down: (wgpu::ComputePipeline, wgpu::BindGroupLayout),
    composite: (wgpu::ComputePipeline, wgpu::BindGroupLayout),
    /// The cuts of recently sampled rectangles, on the GPU, with their sphere counts:
    /// refining the same tiles again needs no traversal or upload.
    cuts: HashMap<(u32, [i32; 4]), (UploadedCut, u64)>,
    /// Levels coarser than a view's own that every call uses (see
    /// [`Self::set_level_bias`]).
    level_bias: u32,
}

/// Spheres, over all rectangles, whose uploaded cuts are kept (about 16 bytes each on
/// the GPU).
const KEPT_POINTS: u64 = 16 << 20;

fn compute_pipeline(
    device: &wgpu::Device,
    label: &str,
    source: &str,
    entry: &str,
    buffers: &[wgpu::BufferBindingType],
) -> (wgpu::ComputePipeline, wgpu::BindGroupLayout) {
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(label),
        source: wgpu::ShaderSource::Wgsl(source.into()),
    });
    let entries: Vec<_> = buffers
        .iter()
        .enumerate()
        .map(|(i, &ty)| wgpu::BindGroupLayoutEntry {
            binding: i as u32,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Buffer {
                ty,
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        })
        .collect();
    let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some(label),
        entries: &entries,
    });
    let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some(label),
        bind_group_layouts: &[Some(&layout)],
        immediate_size: 0,
    });
    let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(label),
        layout: Some(&pipeline_layout),
        module: &module,
        entry_point: Some(entry),
        compilation_options: Default::default(),
        cache: None,
    });
    (pipeline, layout)
}

impl Smip {
    /// A cache of `config.pool_tiles` tiles of `bins × bins` bins (fewer when one buffer
    /// of the adapter holds fewer).
    pub fn new(renderer: &Renderer, bins: u32, config: SmipConfig) -> Result<Smip, RenderError> {
        if !(1..=32).contains(&bins) {
            return Err(RenderError::InvalidOptions(format!(
                "{bins} bins per axis (1 to 32)"
            )));
        }
        let device = &renderer.ctx.device;
        let max = renderer.binding_bytes();
        let fit = u32::try_from(max / tile_bytes(bins)).unwrap_or(u32::MAX);
        let capacity = config.pool_tiles.min(fit);
        if capacity == 0 {
            return Err(RenderError::InvalidOptions(format!(
                "an S-MIP tile of {bins}x{bins} bins needs {} bytes, more than one buffer of this adapter holds",
                tile_bytes(bins)
            )));
        }
        let pool = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("smip tile pool"),
            size: u64::from(capacity) * tile_bytes(bins),
            usage: wgpu::BufferUsages::STORAGE
                | wgpu::BufferUsages::COPY_SRC
                | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        use wgpu::BufferBindingType as T;
        let read = T::Storage { read_only: true };
        let write = T::Storage { read_only: false };
        let down = compute_pipeline(
            device,
            "smip_downsample.wgsl",
            DOWNSAMPLE_SHADER,
            "downsample",
            &[read, write],
        );
        let composite = compute_pipeline(
            device,
            "smip_composite.wgsl",
            COMPOSITE_SHADER,
            "composite",
            &[read, read, read, read, read, write],
        );
        Ok(Smip {
            config,
            frame: None,
            tiles: HashMap::new(),
            free: (0..capacity).rev().collect(),
            capacity,
            clock: 0,
            pool,
            bins,
            down,
            composite,
            cuts: HashMap::new(),
            level_bias: 0,
        })
    }

    /// How tiles are sampled.
    pub fn config(&self) -> &SmipConfig {
        &self.config
    }

    /// Tile slots in the pool.
    pub fn capacity(&self) -> u32 {
        self.capacity
    }

    /// Shows views `bias` levels coarser than their pixels (texels `2^bias` pixels
    /// wide, magnified bilinearly): a quicker, blurrier picture while the user drags,
    /// `4^bias` times fewer texels to sample. Applies to every later call until changed.
    pub fn set_level_bias(&mut self, bias: u32) {
        self.level_bias = bias.min(8);
    }

    /// Bins per axis of the pool's tiles.
    pub fn bins(&self) -> u32 {
        self.bins
    }

    /// The fewest rays per texel among the tiles `camera`'s view needs (0 when one is
    /// not resident).
    pub fn view_rays(&self, camera: &Camera, width: u32, height: u32) -> Result<u32, RenderError> {
        let plans = self.plan(camera, width, height)?;
        Ok(plans
            .iter()
            .flat_map(|p| p.keys())
            .map(|k| self.tiles.get(&k).map_or(0, |t| t.rays))
            .min()
            .unwrap_or(0))
    }

    /// Bytes of the tile pool on the GPU.
    pub fn pool_bytes(&self) -> u64 {
        u64::from(self.capacity) * tile_bytes(self.bins)
    }

    /// The frame the cached tiles belong to.
    pub fn frame(&self) -> Option<&SmipFrame> {
        self.frame.as_ref()
    }

    /// Resident tiles.
    pub fn resident(&self) -> usize {
        self.tiles.len()
    }

    /// Rays per texel of a resident tile.
    pub fn rays(&self, key: TileKey) -> Option<u32> {
        self.tiles.get(&key).map(|t| t.rays)
    }

    /// Drops every tile.
    pub fn clear(&mut self) {
        self.tiles.clear();
        self.cuts.clear();
        self.free = (0..self.capacity).rev().collect();
    }

    /// Makes every tile `camera`'s view of `width × height` pixels needs resident:
    /// reused, down-sampled or sampled with `iterations` rays per texel. `frame` must
    /// fit the camera; a frame different from the cached one drops every tile first.
    #[allow(clippy::too_many_arguments)]
    pub fn prepare(
        &mut self,
        renderer: &Renderer,
        file: &MdlodFile,
        frame: &SmipFrame,
        camera: &Camera,
        width: u32,
        height: u32,
        iterations: u32,
        style: &PointStyle,
    ) -> Result<SmipStats, RenderError> {
        let mut stats = SmipStats::default();
        if self.frame.as_ref() != Some(frame) {
            stats.invalidated = !self.tiles.is_empty();
            self.clear();
            self.frame = Some(frame.clone());
        }
        if frame.bins != self.bins {
            return Err(RenderError::InvalidOptions(format!(
                "the S-MIP frame has {} bins, the pool {}",
                frame.bins, self.bins
            )));
        }
        let plans = self.plan(camera, width, height)?;
        stats.level = plans[0].level;
        stats.blend = plans.get(1).map_or(0.0, |p| p.weight as f32);
        let needed: Vec<TileKey> = plans.iter().flat_map(|p| p.keys()).collect();
        stats.needed = needed.len() as u32;
        self.clock += 1;
        let pinned: HashSet<TileKey> = needed.iter().copied().collect();
        for key in &needed {
            if let Some(t) = self.tiles.get_mut(key) {
                t.used = self.clock;
                stats.reused += 1;
            }
        }
        for plan in &plans {
            let missing: Vec<TileKey> = plan
                .keys()
                .filter(|k| !self.tiles.contains_key(k))
                .collect();
            let (derive, sample): (Vec<TileKey>, Vec<TileKey>) =
                missing.into_iter().partition(|k| self.derivable(*k));
            // Down-sampled tiles first, their children pinned until then; once the
            // down-sampling is queued, the children may make room for sampled tiles.
            let mut with_children = pinned.clone();
            with_children.extend(
                derive
                    .iter()
                    .flat_map(|k| k.children().into_iter().flatten()),
            );
            for &key in &derive {
                let slot = self.allocate(&with_children, &mut stats)?;
                self.insert(key, slot);
                self.downsample(renderer, key)?;
                stats.downsampled += 1;
            }
            for &key in &sample {
                let slot = self.allocate(&pinned, &mut stats)?;
                self.insert(key, slot);
            }
            self.clear_slots(renderer, &sample);
            self.sample(
                renderer,
                file,
                frame,
                &sample,
                iterations.max(1),
                style,
                &mut stats,
            )?;
        }
        Ok(stats)
    }

    /// Adds up to `iterations` rays per texel to the tiles of the view (which
    /// [`Self::prepare`] made resident) that have fewer than `target`, without passing
    /// it: sampled tiles continue their sub-pixel sequences, down-sampled tiles are
    /// derived again from their refined children, or sampled further when those are
    /// gone.
    #[allow(clippy::too_many_arguments)]
    pub fn refine(
        &mut self,
        renderer: &Renderer,
        file: &MdlodFile,
        camera: &Camera,
        width: u32,
        height: u32,
        iterations: u32,
        target: u32,
        style: &PointStyle,
    ) -> Result<SmipStats, RenderError> {
        let mut stats = SmipStats::default();
        let frame = self.frame.clone().ok_or_else(|| {
            RenderError::InvalidOptions("refining an S-MIP that has no frame".into())
        })?;
        let plans = self.plan(camera, width, height)?;
        stats.level = plans[0].level;
        stats.blend = plans.get(1).map_or(0.0, |p| p.weight as f32);
        for plan in &plans {
            let keys: Vec<TileKey> = plan.keys().collect();
            stats.needed += keys.len() as u32;
            if let Some(k) = keys.iter().find(|k| !self.tiles.contains_key(k)) {
                return Err(RenderError::InvalidOptions(format!(
                    "refining S-MIP tile {k:?}, which is not resident (prepare the view first)"
                )));
            }
            let (derive, sample): (Vec<TileKey>, Vec<TileKey>) = keys
                .into_iter()
                .partition(|k| self.tiles[k].derived && self.derivable(*k));
            let sample = sample.into_iter().filter(|k| self.tiles[k].rays < target);
            // Tiles with equal rays get equal additions (and are sampled together).
            let mut by_add: BTreeMap<u32, Vec<TileKey>> = BTreeMap::new();
            for k in sample {
                let add = iterations.min(target - self.tiles[&k].rays);
                by_add.entry(add).or_default().push(k);
            }
            for (add, keys) in by_add {
                self.sample(renderer, file, &frame, &keys, add, style, &mut stats)?;
            }
            // Derived tiles follow their children when those changed.
            if stats.sampled > 0 {
                for key in derive {
                    self.downsample(renderer, key)?;
                    stats.downsampled += 1;
                }
            }
        }
        Ok(stats)
    }

    /// Shades the view from the resident tiles: no particle is touched. Returns the
    /// image and the GPU time of the composite pass.
    pub fn shade(
        &self,
        renderer: &Renderer,
        camera: &Camera,
        width: u32,
        height: u32,
        lights: &ShadeLights,
        background_srgb: [f32; 3],
    ) -> Result<(RgbaImage, Option<Duration>), RenderError> {
        let plans = self.plan(camera, width, height)?;
        let mut pages = vec![];
        let mut levels = [LevelParams::default(); 2];
        for (i, plan) in plans.iter().enumerate() {
            let [x0, x1, y0, y1] = plan.tiles;
            levels[i] = LevelParams {
                origin: [
                    (plan.origin[0] - f64::from(x0) * f64::from(TILE)) as f32,
                    (plan.origin[1] - f64::from(y0) * f64::from(TILE)) as f32,
                ],
                step: plan.step as f32,
                weight: plan.weight as f32,
                tiles: [(x1 - x0) as u32, (y1 - y0) as u32],
                page_offset: pages.len() as u32,
                pad: 0,
            };
            for key in plan.keys() {
                let tile = self.tiles.get(&key).ok_or_else(|| {
                    RenderError::InvalidOptions(format!(
                        "shading S-MIP tile {key:?}, which is not resident (prepare the view first)"
                    ))
                })?;
                pages.push(tile.slot);
            }
        }
        let mut rays = vec![0f32; self.capacity as usize];
        for t in self.tiles.values() {
            rays[t.slot as usize] = t.rays as f32;
        }
        let bins = self.bins;
        let binning = self
            .frame
            .as_ref()
            .map_or(Binning::default(), |f| f.binning);
        let bg = background_srgb.map(srgb_to_linear);
        renderer.ctx.scoped(|| {
            use wgpu::util::DeviceExt;
            let device = &renderer.ctx.device;
            let init = |label: &str, contents: &[u8], usage| {
                device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some(label),
                    contents,
                    usage,
                })
            };
            let params = init(
                "smip composite params",
                bytemuck::bytes_of(&CompositeParams {
                    width,
                    height,
                    bins,
                    levels: plans.len() as u32,
                    background: [bg[0], bg[1], bg[2], 0.0],
                    level: levels,
                }),
                wgpu::BufferUsages::STORAGE,
            );
            let storage = wgpu::BufferUsages::STORAGE;
            let table = init(
                "smip shade table",
                bytemuck::cast_slice(&shade_table(bins, binning, lights, TexelView::Axis).0),
                storage,
            );
            let pages = init("smip pages", bytemuck::cast_slice(&pages), storage);
            let rays = init("smip rays", bytemuck::cast_slice(&rays), storage);
            renderer.image_pass(
                "smip composite",
                (&self.composite.0, &self.composite.1),
                &[&params, &table, &self.pool, &pages, &rays],
                [width.div_ceil(8), height.div_ceil(8)],
                (width, height),
            )
        })
    }

    /// A resident tile's histograms and rays.
    pub fn read_tile(
        &self,
        renderer: &Renderer,
        key: TileKey,
    ) -> Result<Option<TileData>, RenderError> {
        let Some(tile) = self.tiles.get(&key) else {
            return Ok(None);
        };
        let bytes = tile_bytes(self.bins);
        let data = renderer.ctx.scoped(|| {
            let device = &renderer.ctx.device;
            let read = crate::renderer::readback_buffer(device, "smip tile readback", bytes);
            let mut enc = device.create_command_encoder(&Default::default());
            enc.copy_buffer_to_buffer(&self.pool, u64::from(tile.slot) * bytes, &read, 0, bytes);
            renderer.ctx.queue.submit([enc.finish()]);
            renderer.read_buffer(&read)
        })?;
        let blocked: Vec<[f32; 4]> = bytemuck::pod_collect_to_vec(&data);
        let b2 = (self.bins * self.bins) as usize;
        let mut rows = Vec::with_capacity(blocked.len());
        for y in 0..TILE {
            for x in 0..TILE {
                let at = crate::sndf::texel_in_tile(x, y) as usize * b2;
                rows.extend_from_slice(&blocked[at..at + b2]);
            }
        }
        Ok(Some(TileData {
            hist: rows,
            rays: tile.rays,
        }))
    }

    /// The levels `camera`'s view shows and the tiles it needs.
    fn plan(
        &self,
        camera: &Camera,
        width: u32,
        height: u32,
    ) -> Result<Vec<LevelPlan>, RenderError> {
        let frame = self.frame.as_ref().ok_or_else(|| {
            RenderError::InvalidOptions("an S-MIP view before any frame was set".into())
        })?;
        plan_view(frame, self.level_bias, camera, width, height)
    }

    /// The tiles `camera`'s view needs, read back from the pool with the frame: what a
    /// `.sndf` file of S-MIP tiles holds and [`shade_tiles`] lights on the host.
    pub fn export(
        &self,
        renderer: &Renderer,
        camera: &Camera,
        width: u32,
        height: u32,
    ) -> Result<SmipTiles, RenderError> {
        let plans = self.plan(camera, width, height)?;
        let frame = self.frame.clone().expect("planned views have a frame");
        let mut tiles = BTreeMap::new();
        for key in plans.iter().flat_map(|p| p.keys()) {
            let data = self.read_tile(renderer, key)?.ok_or_else(|| {
                RenderError::InvalidOptions(format!(
                    "exporting S-MIP tile {key:?}, which is not resident (prepare the view first)"
                ))
            })?;
            tiles.insert(key, data);
        }
        Ok(SmipTiles {
            frame,
            level_bias: self.level_bias,
            tiles,
        })
    }

    /// Whether a tile can be made from its four resident children, which have equal
    /// rays.
    fn derivable(&self, key: TileKey) -> bool {
        let Some(children) = key.children() else {
            return false;
        };
        let rays: Vec<Option<u32>> = children
            .iter()
            .map(|c| self.tiles.get(c).map(|t| t.rays))
            .collect();
        rays.iter().all(|r| r.is_some() && *r == rays[0])
    }

    /// Enters a new, empty tile in the page table.
    fn insert(&mut self, key: TileKey, slot: u32) {
        self.tiles.insert(
            key,
            Tile {
                slot,
                rays: 0,
                derived: false,
                used: self.clock,
            },
        );
    }

    /// A free slot, or the least recently used slot of an unpinned tile.
    fn allocate(
        &mut self,
        pinned: &HashSet<TileKey>,
        stats: &mut SmipStats,
    ) -> Result<u32, RenderError> {
        if let Some(slot) = self.free.pop() {
            return Ok(slot);
        }
        let victim = self
            .tiles
            .iter()
            .filter(|(k, _)| !pinned.contains(k))
            .min_by_key(|(k, t)| (t.used, **k))
            .map(|(k, _)| *k);
        match victim {
            Some(k) => {
                stats.evicted += 1;
                Ok(self.tiles.remove(&k).map(|t| t.slot).unwrap_or(0))
            }
            None => Err(RenderError::InvalidOptions(format!(
                "the view needs more than the S-MIP pool's {} tiles: a smaller view or fewer bins needs fewer",
                self.capacity
            ))),
        }
    }

    fn clear_slots(&self, renderer: &Renderer, keys: &[TileKey]) {
        if keys.is_empty() {
            return;
        }
        let bytes = tile_bytes(self.bins);
        let mut enc = renderer
            .ctx
            .device
            .create_command_encoder(&Default::default());
        for k in keys {
            let slot = self.tiles[k].slot;
            enc.clear_buffer(&self.pool, u64::from(slot) * bytes, Some(bytes));
        }
        renderer.ctx.queue.submit([enc.finish()]);
    }

    /// Samples `iterations` more rays into each of `keys` (resident tiles of one
    /// level), in rectangles of tiles with equal rays.
    #[allow(clippy::too_many_arguments)]
    fn sample(
        &mut self,
        renderer: &Renderer,
        file: &MdlodFile,
        frame: &SmipFrame,
        keys: &[TileKey],
        iterations: u32,
        style: &PointStyle,
        stats: &mut SmipStats,
    ) -> Result<(), RenderError> {
        if keys.is_empty() || iterations == 0 {
            return Ok(());
        }
        let mut groups: BTreeMap<(u32, u32), Vec<(i32, i32)>> = BTreeMap::new();
        for k in keys {
            groups
                .entry((k.level, self.tiles[k].rays))
                .or_default()
                .push((k.x, k.y));
        }
        let bounds = crate::data_bounds(file);
        for ((level, rays), tiles) in groups {
            let set: HashSet<(i32, i32)> = tiles.iter().copied().collect();
            for [x0, x1, y0, y1] in rectangles(&tiles) {
                let (camera, size) = rect_camera(frame, level, [x0, x1, y0, y1], &bounds);
                let key = (level, [x0, x1, y0, y1]);
                if !self.cuts.contains_key(&key) {
                    let draw = traverse(
                        &camera,
                        file,
                        &TraversalSettings {
                            viewport: size,
                            error_px: self.config.error_px,
                            budget_points: (self.config.budget_points
                                * ((x1 - x0) * (y1 - y0)) as u64
                                / (MAX_RECT_TILES * MAX_RECT_TILES) as u64)
                                .max(1),
                            // Culling assumes the file's radii, and occluders the
                            // traversal can tell hidden.
                            occlusion: if !style.culls(&file.metadata().species) {
                                OcclusionMode::Off
                            } else {
                                self.config.occlusion
                            },
                            support_scale: 0.0,
                            hidden: style.hidden_set(file.metadata()),
                            clip: style.clip_planes().map_err(RenderError::InvalidOptions)?,
                        },
                    );
                    file.node_error()?;
                    let cut = renderer
                        .ctx
                        .scoped(|| renderer.upload_cut(file, &draw, style))?;
                    let kept: u64 = self.cuts.values().map(|c| c.1).sum();
                    if kept + draw.points > KEPT_POINTS {
                        self.cuts.clear();
                    }
                    self.cuts.insert(key, (cut, draw.points));
                }
                let (cut, points) = &self.cuts[&key];
                let mut pages = vec![];
                for y in y0..y1 {
                    for x in x0..x1 {
                        let key = TileKey { level, x, y };
                        pages.push(if set.contains(&(x, y)) {
                            self.tiles[&key].slot
                        } else {
                            NO_SLOT
                        });
                    }
                }
                let gpu = renderer.ctx.scoped(|| {
                    renderer.accumulate_uploaded(
                        cut,
                        &camera,
                        &SndfPassSettings {
                            width: size[0],
                            height: size[1],
                            bins: self.bins,
                            binning: frame.binning,
                            iterations,
                            first: rays,
                        },
                        &[(self.pool.as_entire_buffer_binding(), pages.as_slice())],
                    )
                })?;
                let draw_points = *points;
                stats.rects += 1;
                stats.points += draw_points;
                stats.particle_samples += draw_points * u64::from(iterations);
                stats.gpu_time = match (stats.gpu_time, gpu) {
                    (Some(a), Some(b)) => Some(a + b),
                    (None, b) => b,
                    (a, None) => a,
                };
            }
            for (x, y) in tiles {
                let t = self
                    .tiles
                    .get_mut(&TileKey { level, x, y })
                    .expect("sampled tiles are resident");
                t.rays += iterations;
                t.derived = false;
                stats.sampled += 1;
            }
        }
        Ok(())
    }

    /// Makes `key` the 2×2 down-sampling of its resident children.
    fn downsample(&mut self, renderer: &Renderer, key: TileKey) -> Result<(), RenderError> {
        let children = key.children().expect("derivable tiles have children");
        let slots = children.map(|c| self.tiles[&c].slot);
        let rays = self.tiles[&children[0]]
            .rays
            .checked_mul(4)
            .ok_or_else(|| {
                RenderError::InvalidOptions(format!(
                    "S-MIP tile {key:?}: its children's rays per texel times 4 pass 2^32"
                ))
            })?;
        let parent = self.tiles[&key].slot;
        renderer.ctx.scoped(|| {
            use wgpu::util::DeviceExt;
            let device = &renderer.ctx.device;
            let params = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("smip downsample params"),
                contents: bytemuck::bytes_of(&DownParams {
                    bins: self.bins,
                    parent,
                    pad: [0; 2],
                    children: slots,
                }),
                usage: wgpu::BufferUsages::STORAGE,
            });
            let bind = device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("smip downsample"),
                layout: &self.down.1,
                entries: &[
                    wgpu::BindGroupEntry {
                        binding: 0,
                        resource: params.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 1,
                        resource: self.pool.as_entire_binding(),
                    },
                ],
            });
            let mut enc = device.create_command_encoder(&Default::default());
            {
                let mut pass = enc.begin_compute_pass(&Default::default());
                pass.set_pipeline(&self.down.0);
                pass.set_bind_group(0, &bind, &[]);
                pass.dispatch_workgroups(TILE / 8, TILE / 8, 1);
            }
            renderer.ctx.queue.submit([enc.finish()]);
            Ok(())
        })?;
        let t = self.tiles.get_mut(&key).expect("resident");
        t.rays = rays;
        t.derived = true;
        Ok(())
    }
}

/// A view's S-MIP tiles on the host, with their frame (see [`Smip::export`]).
#[derive(Clone, Debug, PartialEq)]
pub struct SmipTiles {
    pub frame: SmipFrame,
    /// The level bias they were shown with.
    pub level_bias: u32,
    pub tiles: BTreeMap<TileKey, TileData>,
}

impl SmipTiles {
    /// The file form: the tiles in key order, the view's camera and size, the source.
    pub fn to_data(
        &self,
        width: u32,
        height: u32,
        view: serde_json::Value,
        source: Option<String>,
    ) -> SndfData {
        let list: Vec<SndfTile> = self
            .tiles
            .iter()
            .map(|(k, t)| SndfTile {
                level: k.level,
                x: k.x,
                y: k.y,
                rays: t.rays,
            })
            .collect();
        SndfData {
            header: SndfHeader {
                width,
                height,
                bins: self.frame.bins,
                binning: self.frame.binning.name().into(),
                rays: list.iter().map(|t| t.rays).min().unwrap_or(1),
                view,
                source,
                display_level: (self.level_bias > 0).then_some(self.level_bias),
                normal_frame: None,
                smip: Some(SndfTiles {
                    texel0: self.frame.texel0,
                    origin: self.frame.origin,
                    tile: TILE,
                    tiles: list,
                }),
            },
            hist: self
                .tiles
                .values()
                .flat_map(|t| t.hist.iter().copied())
                .collect(),
        }
    }

    /// The levels a view of `width`×`height` pixels through `camera` is shaded from, with
    /// their weights (one level, or two blended), for the tiles a header `h` describes
    /// (its display level as the bias); `None` for a file of one image.
    pub fn view_levels(
        h: &SndfHeader,
        camera: &Camera,
        width: u32,
        height: u32,
    ) -> Result<Option<Vec<(u32, f64)>>, RenderError> {
        let Some(t) = h.smip.as_ref() else {
            return Ok(None);
        };
        let frame = SmipFrame::of_file(h, t, camera);
        let plans = plan_view(&frame, h.display_level.unwrap_or(0), camera, width, height)?;
        Ok(Some(plans.iter().map(|p| (p.level, p.weight)).collect()))
    }

    /// From the file form (which the reader has checked) and the camera of its view;
    /// `None` for a file of one image.
    pub fn from_data(d: &SndfData, camera: &Camera) -> Option<SmipTiles> {
        let t = d.header.smip.as_ref()?;
        let per_tile = (TILE * TILE * d.header.bins * d.header.bins) as usize;
        let tiles = t
            .tiles
            .iter()
            .zip(d.hist.chunks_exact(per_tile))
            .map(|(t, hist)| {
                (
                    TileKey {
                        level: t.level,
                        x: t.x,
                        y: t.y,
                    },
                    TileData {
                        hist: hist.to_vec(),
                        rays: t.rays,
                    },
                )
            })
            .collect();
        Some(SmipTiles {
            frame: SmipFrame::of_file(&d.header, t, camera),
            level_bias: d.header.display_level.unwrap_or(0),
            tiles,
        })
    }
}

/// Shades `camera`'s view of the tiles on the host, as the composite pass does on the
/// GPU (the CPU reference of [`Smip::shade`]): each needed tile's texels shaded once
/// from their S-NDFs, then per pixel bilinear within each level (clamped to the needed
/// tiles) and linear between the levels. A needed tile that is missing is made from
/// its children when any are there ([`derive_tile`]), else it shows the background.
pub fn shade_tiles(
    tiles: &SmipTiles,
    camera: &Camera,
    width: u32,
    height: u32,
    lights: &ShadeLights,
    background_srgb: [f32; 3],
) -> Result<RgbaImage, RenderError> {
    let plans = plan_view(&tiles.frame, tiles.level_bias, camera, width, height)?;
    let bg = background_srgb.map(srgb_to_linear);
    let mut shaded: HashMap<TileKey, Vec<[f32; 3]>> = HashMap::new();
    let top = plans.iter().map(|p| p.level).max().unwrap_or(0);
    let above = stored_below(&tiles.tiles, top);
    for key in plans.iter().flat_map(|p| p.keys()) {
        let derived;
        let tile = match tiles.tiles.get(&key) {
            Some(t) => Some(t),
            None => {
                derived = derive_tile(&tiles.tiles, &above, key, tiles.frame.bins);
                derived.as_ref()
            }
        };
        if let Some(t) = tile {
            let sndf = crate::sndf::Sndf {
                width: TILE,
                height: TILE,
                bins: tiles.frame.bins,
                binning: tiles.frame.binning,
                rays: t.rays,
                hist: t.hist.clone(),
                gpu_time: None,
                view: crate::sndf::TexelView::Axis,
            };
            shaded.insert(key, sndf.shade_linear(lights, background_srgb));
        }
    }
    let texel = |plan: &LevelPlan, x: i64, y: i64| -> [f32; 3] {
        let [x0, x1, y0, y1] = plan.tiles.map(i64::from);
        let t = i64::from(TILE);
        let (x, y) = (x.clamp(x0 * t, x1 * t - 1), y.clamp(y0 * t, y1 * t - 1));
        let key = TileKey {
            level: plan.level,
            x: x.div_euclid(t) as i32,
            y: y.div_euclid(t) as i32,
        };
        match shaded.get(&key) {
            Some(c) => c[(y.rem_euclid(t) * t + x.rem_euclid(t)) as usize],
            None => bg,
        }
    };
    let mut image = RgbaImage::new(width, height);
    for py in 0..height {
        for px in 0..width {
            let mut c = [0f32; 3];
            for plan in &plans {
                let tx = plan.origin[0] + f64::from(px) * plan.step - 0.5;
                let ty = plan.origin[1] + f64::from(py) * plan.step - 0.5;
                let (fx, fy) = (tx.floor(), ty.floor());
                let (wx, wy) = ((tx - fx) as f32, (ty - fy) as f32);
                let (ix, iy) = (fx as i64, fy as i64);
                for (dx, dy, w) in [
                    (0, 0, (1.0 - wx) * (1.0 - wy)),
                    (1, 0, wx * (1.0 - wy)),
                    (0, 1, (1.0 - wx) * wy),
                    (1, 1, wx * wy),
                ] {
                    if w > 0.0 {
                        let v = texel(plan, ix + dx, iy + dy);
                        for k in 0..3 {
                            c[k] += plan.weight as f32 * w * v[k];
                        }
                    }
                }
            }
            let p = [c[0], c[1], c[2], 1.0]
                .map(|v| (linear_to_srgb(v.clamp(0.0, 1.0)) * 255.0 + 0.5) as u8);
            image.set_pixel(px, py, p);
        }
    }
    Ok(image)
}

/// The tiles up to level `top` that have stored tiles below them (of finer levels):
/// those [`derive_tile`] can make. At most one per stored tile and level.
pub fn stored_below(tiles: &BTreeMap<TileKey, TileData>, top: u32) -> HashSet<TileKey> {
    let mut above = HashSet::new();
    for k in tiles.keys() {
        let mut a = *k;
        while a.level < top {
            // The parent: halved coordinates, rounded down (children are 2x and 2x + 1).
            a = TileKey {
                level: a.level + 1,
                x: a.x >> 1,
                y: a.y >> 1,
            };
            if !above.insert(a) {
                break;
            }
        }
    }
    above
}

/// A tile made on the host from tiles of finer levels, however many levels down: the
/// 2×2 sums of its children's texels, as the GPU down-samples. A child that is missing
/// counts as texels whose rays hit nothing; children with fewer rays than the most are
/// scaled up to it (the same expected S-NDF). `None` when no descendant is stored
/// (`above`, from [`stored_below`] for a level at least `key`'s, names the tiles that
/// have some: only those are visited, so zooming far out of a few stored tiles costs a
/// tile per level, not 4 per level below).
pub fn derive_tile(
    tiles: &BTreeMap<TileKey, TileData>,
    above: &HashSet<TileKey>,
    key: TileKey,
    bins: u32,
) -> Option<TileData> {
    if let Some(t) = tiles.get(&key) {
        return Some(t.clone());
    }
    if !above.contains(&key) {
        return None;
    }
    let children: Vec<Option<TileData>> = key
        .children()?
        .iter()
        .map(|c| derive_tile(tiles, above, *c, bins))
        .collect();
    let rays = children.iter().flatten().map(|c| c.rays).max()?;
    let b2 = (bins * bins) as usize;
    let half = TILE / 2;
    let mut hist = vec![[0f32; 4]; (TILE * TILE) as usize * b2];
    // Past u32 (4^16 rays: 16 levels above one ray per texel) the sums are kept as
    // means of the children (a quarter of the sums, over as many rays as theirs): the
    // same S-NDFs.
    let (sum_rays, norm) = match rays.checked_mul(4) {
        Some(r) => (r, 1.0),
        None => (rays, 0.25),
    };
    for (q, child) in children.iter().enumerate() {
        let Some(child) = child else { continue };
        let scale = norm * rays as f32 / child.rays.max(1) as f32;
        let (ox, oy) = ((q as u32 % 2) * half, (q as u32 / 2) * half);
        for y in 0..TILE {
            for x in 0..TILE {
                let dst = (((oy + y / 2) * TILE + ox + x / 2) as usize) * b2;
                let src = ((y * TILE + x) as usize) * b2;
                for b in 0..b2 {
                    for k in 0..4 {
                        hist[dst + b][k] += child.hist[src + b][k] * scale;
                    }
                }
            }
        }
    }
    Some(TileData {
        hist,
        rays: sum_rays,
    })
}

/// The levels `camera`'s view of `frame` shows, `bias` levels coarser than its pixels,
/// and the tiles it needs.
fn plan_view(
    frame: &SmipFrame,
    bias: u32,
    camera: &Camera,
    width: u32,
    height: u32,
) -> Result<Vec<LevelPlan>, RenderError> {
    if !frame.fits(camera) {
        return Err(RenderError::InvalidOptions(
            "the view does not fit the S-MIP's frame (direction or projection changed)".into(),
        ));
    }
    if width == 0 || height == 0 {
        return Err(RenderError::InvalidOptions(format!(
            "an S-MIP view of {width}x{height} pixels"
        )));
    }
    let p = f64::from(camera.view_height_at_target()) / f64::from(height);
    let f = (p / frame.texel0).log2() + f64::from(bias);
    let mut levels: Vec<(u32, f64)> = if f.is_nan() || f <= LEVEL_SNAP {
        vec![(0, 1.0)]
    } else {
        let l = f.floor();
        let t = f - l;
        let l = l.min(f64::from(MAX_LEVEL - 1)) as u32;
        if t < LEVEL_SNAP {
            vec![(l, 1.0)]
        } else if t > 1.0 - LEVEL_SNAP {
            vec![(l + 1, 1.0)]
        } else {
            vec![(l, 1.0 - t), (l + 1, t)]
        }
    };
    levels.truncate(2);
    let (uc, vc) = plane_of(camera, camera.target);
    // Pixel (0, 0)'s centre.
    let u = uc + (0.5 - f64::from(width) * 0.5) * p;
    let v = vc - (0.5 - f64::from(height) * 0.5) * p;
    let mut plans = vec![];
    for (level, weight) in levels {
        let t = frame.texel(level);
        let origin = [(u - frame.origin[0]) / t, (frame.origin[1] - v) / t];
        let step = p / t;
        // Texels under the first and last pixel centres. Their bilinear neighbours
        // beyond the view's edge are not needed: the composite clamps to the needed
        // tiles, as a texture clamps at its edge, which saves a ring of tiles.
        let span = |o: f64, n: u32| {
            let first = (o + SPAN_SLACK).floor();
            let last = (o + f64::from(n - 1) * step - SPAN_SLACK)
                .floor()
                .max(first);
            let tile = |c: f64| (c / f64::from(TILE)).floor();
            (tile(first), tile(last) + 1.0)
        };
        let (x0, x1) = span(origin[0], width);
        let (y0, y1) = span(origin[1], height);
        let limit = f64::from(i32::MAX / 2);
        if [x0, x1, y0, y1]
            .iter()
            .any(|c| !c.is_finite() || c.abs() > limit)
        {
            return Err(RenderError::InvalidOptions(format!(
                "the view is too far from the S-MIP's origin ({}, {} in its plane, texels of \
                 {} at level 0) to address its tiles: a view of other data, or a damaged \
                 S-MIP file",
                frame.origin[0],
                frame.origin[1],
                frame.texel(0)
            )));
        }
        // A level's texels are at most twice as fine as the pixels, so a view needs at
        // most about four times its own area in tiles, unless the frame's texels are
        // finer than its coarsest level can make up for (a hostile or corrupt texel
        // size): then the rectangle would hold billions of tiles.
        let most = 4.0
            * (f64::from(width.div_ceil(TILE)) + 2.0)
            * (f64::from(height.div_ceil(TILE)) + 2.0);
        if (x1 - x0) * (y1 - y0) > most {
            return Err(RenderError::InvalidOptions(format!(
                "the S-MIP's texels ({:e} world units at level 0) are too fine for a view of \
                 {:e} units per pixel: level {level} would need {:e} tiles",
                frame.texel0,
                p,
                (x1 - x0) * (y1 - y0)
            )));
        }
        plans.push(LevelPlan {
            level,
            weight,
            origin,
            step,
            tiles: [x0 as i32, x1 as i32, y0 as i32, y1 as i32],
        });
    }
    Ok(plans)
}

/// Largest side, in tiles, of a sampled rectangle. Each rectangle's cut is chosen on its
/// own, and a cut over its point budget coarsens as a whole; small rectangles keep the
/// cut of a tile independent of how many tiles were sampled with it.
pub const MAX_RECT_TILES: i32 = 4;

/// Rectangles `[x0, x1, y0, y1]` (exclusive ends) covering exactly `tiles`: runs along
/// each row, merged with the run below when it spans the same columns, then cut into
/// pieces at most [`MAX_RECT_TILES`] on a side.
pub fn rectangles(tiles: &[(i32, i32)]) -> Vec<[i32; 4]> {
    let mut out = vec![];
    for [x0, x1, y0, y1] in runs(tiles) {
        for ya in (y0..y1).step_by(MAX_RECT_TILES as usize) {
            for xa in (x0..x1).step_by(MAX_RECT_TILES as usize) {
                out.push([
                    xa,
                    (xa + MAX_RECT_TILES).min(x1),
                    ya,
                    (ya + MAX_RECT_TILES).min(y1),
                ]);
            }
        }
    }
    out.sort_unstable();
    out
}

/// Rectangles covering exactly `tiles`, of any size (see [`rectangles`]).
fn runs(tiles: &[(i32, i32)]) -> Vec<[i32; 4]> {
    let mut rows: BTreeMap<i32, Vec<i32>> = BTreeMap::new();
    for &(x, y) in tiles {
        rows.entry(y).or_default().push(x);
    }
    let mut done = vec![];
    // Open rectangles by column span, with the row after their last.
    let mut open: HashMap<(i32, i32), (i32, i32)> = HashMap::new();
    for (y, mut xs) in rows {
        xs.sort_unstable();
        xs.dedup();
        let mut runs = vec![];
        let mut start = xs[0];
        for w in xs.windows(2) {
            if w[1] != w[0] + 1 {
                runs.push((start, w[0] + 1));
                start = w[1];
            }
        }
        runs.push((start, xs[xs.len() - 1] + 1));
        let mut next = HashMap::new();
        for span in runs {
            match open.remove(&span) {
                Some((y0, end)) if end == y => {
                    next.insert(span, (y0, y + 1));
                }
                other => {
                    if let Some((y0, end)) = other {
                        done.push([span.0, span.1, y0, end]);
                    }
                    next.insert(span, (y, y + 1));
                }
            }
        }
        for (span, (y0, end)) in open.drain() {
            done.push([span.0, span.1, y0, end]);
        }
        open = next;
    }
    for (span, (y0, end)) in open {
        done.push([span.0, span.1, y0, end]);
    }
    done.sort_unstable();
    done
}

/// The orthographic camera whose `size` pixels are exactly the texels of tiles
/// `[x0, x1) × [y0, y1)` of `level`.
fn rect_camera(
    frame: &SmipFrame,
    level: u32,
    rect: [i32; 4],
    bounds: &Bounds,
) -> (Camera, [u32; 2]) {
    let [x0, x1, y0, y1] = rect;
    let t = frame.texel(level) * f64::from(TILE);
    let u0 = frame.origin[0] + f64::from(x0) * t;
    let u1 = frame.origin[0] + f64::from(x1) * t;
    let v0 = frame.origin[1] - f64::from(y0) * t;
    let v1 = frame.origin[1] - f64::from(y1) * t;
    let mut camera = Camera {
        azimuth_deg: frame.azimuth_deg,
        elevation_deg: frame.elevation_deg,
        fov_y_deg: frame.fov_y_deg,
        projection: Projection::Orthographic,
        ..Default::default()
    };
    let (uc, vc) = ((u0 + u1) * 0.5, (v0 + v1) * 0.5);
    let depth = bounds.center().dot(camera.back());
    camera.target = camera.right() * uc as f32 + camera.up() * vc as f32 + camera.back() * depth;
    camera.distance =
        ((v0 - v1) / (2.0 * (f64::from(frame.fov_y_deg).to_radians() * 0.5).tan())) as f32;
    camera.fit_depth_range(bounds);
    let size = [(x1 - x0) as u32 * TILE, (y1 - y0) as u32 * TILE];
    (camera, size)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rectangles_cover_exactly_the_tiles() {
        let cases: Vec<Vec<(i32, i32)>> = vec![
            (0..3).flat_map(|y| (0..4).map(move |x| (x, y))).collect(),
            (0..9).flat_map(|y| (-3..7).map(move |x| (x, y))).collect(),
            // An L-shaped strip, as a diagonal pan uncovers.
            (0..4)
                .map(|y| (3, y))
                .chain((0..3).map(|x| (x, 3)))
                .collect(),
            vec![(-2, -1), (5, 7), (6, 7), (-1, -1)],
        ];
        for tiles in cases {
            let rects = rectangles(&tiles);
            let mut covered = vec![];
            for [x0, x1, y0, y1] in &rects {
                for y in *y0..*y1 {
                    for x in *x0..*x1 {
                        covered.push((x, y));
                    }
                }
            }
            covered.sort_unstable();
            let mut want = tiles.clone();
            want.sort_unstable();
            assert_eq!(covered, want, "{rects:?}");
        }
        // A full block is one rectangle, up to the largest side.
        let block: Vec<_> = (0..3).flat_map(|y| (0..4).map(move |x| (x, y))).collect();
        assert_eq!(rectangles(&block), vec![[0, 4, 0, 3]]);
        let big: Vec<_> = (0..5).flat_map(|y| (0..9).map(move |x| (x, y))).collect();
        let rects = rectangles(&big);
        assert_eq!(rects.len(), 6);
        assert!(rects
            .iter()
            .all(|r| r[1] - r[0] <= MAX_RECT_TILES && r[3] - r[2] <= MAX_RECT_TILES));
    }

    /// A tile far above the stored ones (a view zoomed 256× out of two tiles) is made
    /// from them: their rays and counts summed, none lost; a tile with nothing stored
    /// below it is not made.
    #[test]
    fn tiles_are_made_from_stored_tiles_any_number_of_levels_down() {
        let bins = 2u32;
        let texels = (TILE * TILE) as usize;
        let stored = |count: f32| TileData {
            hist: vec![[0.5, 0.25, 0.125, count]; texels * (bins * bins) as usize],
            rays: 4,
        };
        let at = |level, x, y| TileKey { level, x, y };
        let mut tiles = BTreeMap::new();
        tiles.insert(at(0, 0, 0), stored(1.0));
        tiles.insert(at(0, 1, 1), stored(2.0));
        tiles.insert(at(0, -1, 0), stored(1.0));
        let above = stored_below(&tiles, 8);
        // One tile per level and stored tile, shared where their ancestors meet.
        assert!(above.len() <= 3 * 8, "{}", above.len());
        let top = derive_tile(&tiles, &above, at(8, 0, 0), bins).unwrap();
        assert_eq!(top.rays, 4 * 4u32.pow(8));
        let total = |t: &TileData| t.hist.iter().map(|r| f64::from(r[3])).sum::<f64>();
        let per_tile = (texels * 4) as f64;
        assert_eq!(total(&top), per_tile * 3.0, "the counts of (0,0) and (1,1)");
        // (-1, 0) lies under the tile to the left on every level.
        let left = derive_tile(&tiles, &above, at(8, -1, 0), bins).unwrap();
        assert_eq!(total(&left), per_tile);
        assert!(derive_tile(&tiles, &above, at(8, 3, 0), bins).is_none());
        // 16 levels up, the rays would pass u32: the texels keep the same share of
        // counts to rays. The top texel covers 2^16 × 2^16 texels of level 0, of which
        // the two stored tiles' hold counts of 4 and 8 per texel.
        let above = stored_below(&tiles, 16);
        let far = derive_tile(&tiles, &above, at(16, 0, 0), bins).unwrap();
        let hit = far.hist[..4].iter().map(|r| f64::from(r[3])).sum::<f64>();
        let share = hit / f64::from(far.rays);
        let want = (texels as f64 * 12.0) / (4.0 * 4f64.powi(16));
        assert!((share / want - 1.0).abs() < 1e-4, "{share} against {want}");
        assert!(derive_tile(&tiles, &above, at(3, 0, 5), bins).is_none());
    }

    #[test]
    fn children_tile_their_parent() {
        let k = TileKey {
            level: 2,
            x: -1,
            y: 3,
        };
        let c = k.children().unwrap();
        assert_eq!(
            c[0],
            TileKey {
                level: 1,
                x: -2,
                y: 6
            }
        );
        assert_eq!(
            c[3],
            TileKey {
                level: 1,
                x: -1,
                y: 7
            }
        );
        assert!(TileKey {
            level: 0,
            x: 0,
            y: 0
        }
        .children()
        .is_none());
    }

    #[test]
    fn level_zero_gives_every_sphere_its_samples() {
        let mut camera = Camera {
            projection: Projection::Orthographic,
            ..Default::default()
        };
        camera.fit(&Bounds::new([-10.0; 3], [10.0; 3]), 1.0);
        let frame = |r: f32, n: f32| {
            SmipFrame::new(
                &camera,
                100,
                100,
                r,
                n,
                8,
                Binning::default(),
                String::new(),
            )
            .unwrap()
        };
        let p0 = f64::from(camera.view_height_at_target()) / 100.0;
        // A large sphere: the view's own pixels.
        assert_eq!(frame(10.0 * p0 as f32, 4.0).texel0, p0);
        // A small one: halved until π r² / t² ≥ N.
        let f = frame(0.1 * p0 as f32, 4.0);
        assert!(std::f64::consts::PI * (0.1 * p0 / f.texel0).powi(2) >= 4.0);
        assert!(std::f64::consts::PI * (0.1 * p0 / (2.0 * f.texel0)).powi(2) < 4.0);
        // Texels far finer than the coarsest level can make up for (a hostile file's
        // texel size): refused, not a rectangle of billions of tiles to visit.
        let mut hostile = frame(10.0 * p0 as f32, 4.0);
        assert!(plan_view(&hostile, 0, &camera, 100, 100).is_ok());
        hostile.texel0 = p0 * 2f64.powi(-45);
        let e = plan_view(&hostile, 0, &camera, 100, 100).unwrap_err();
        assert!(e.to_string().contains("too fine"), "{e}");
        // Perspective is refused.
        let persp = Camera::default();
        assert!(SmipFrame::new(
            &persp,
            10,
            10,
            1.0,
            1.0,
            8,
            Binning::default(),
            String::new()
        )
        .is_err());
    }
}
