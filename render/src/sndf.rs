//! Screen-space normal distribution functions (S-NDFs, Ibrahim et al. 2017): sample the
//! particles once, shade and re-light as often as wanted without them.
//!
//! How it works.
//! 1. Sampling: each iteration draws the cut's spheres into a G-buffer (the nearest
//!    hit's view-space normal and the particle's albedo) with one jittered ray per texel
//!    (the same Halton sub-pixel pattern as supersampling), then a compute pass
//!    (`sndf_accumulate.wgsl`) adds the sample to the texel's histogram over the normals:
//!    `bins × bins` cells of a [`Binning`] (projected normals `(n.x, n.y)` in `[−1, 1]²`
//!    by default; spherical coordinates; Lambert azimuthal equal-area). A bin keeps the
//!    sum of the albedos that fell into it and their count, so per-particle colours
//!    shade exactly; rays that hit nothing add nothing, and `1 − Σ counts / rays` is the
//!    texel's background share. The GPU buffer holds the histograms in the S-MIP's
//!    64×64-texel tiles (see [`crate::smip`]), each in 8×8-texel blocks (a workgroup's
//!    writes stay together); they come back in rows. Histograms larger than one storage
//!    binding (1280×720 texels of 8×8 bins are 1 GiB; lavapipe binds 128 MiB) stay one
//!    buffer, accumulated window of tiles by window from the same G-buffer, and resident
//!    ones are then shaded on the host. The G-buffer has several layers,
//!    one iteration each, and one accumulation pass adds them all, so a texel's bins are
//!    read and written once per [`ACCUMULATE_LAYERS`] iterations.
//! 2. Shading ([`Sndf::shade`]) needs no particle: per bin, the lighting averaged over
//!    the bin's part of the normal disk weighted by projected solid angle (the discrete
//!    form of Eq. 12-14; [`Binning::projected_density`]), split into the
//!    part that multiplies the albedo (ambient + Lambert) and the part that does not
//!    (Blinn-Phong highlight); a texel's colour is the bins' colour sums and counts
//!    weighted by those, over the rays, plus the background's share.
//! 3. Coarser S-MIP levels ([`Sndf::downsample`]) add 2×2 blocks of texels' bins (at an odd
//!    edge, the children there are, scaled to four).
//!
//! The paper's screen space sees every texel along the view axis (+z), which is exact in
//! orthographic views (the S-MIP takes no other). In a perspective view each texel sees
//! along its own ray ([`TexelView`]), and its normals are binned in the frame of that ray:
//! the rotation (the shortest arc) that turns the direction towards the eye onto +z, so
//! that the hemisphere of normals the ray can see is the hemisphere a binning covers. (In
//! the camera's frame a normal facing away from the axis but towards its texel, the
//! silhouette of a sphere seen off the axis, was binned with its mirror image across the
//! image plane: a third too bright near the edges of a 90° view.) Shading turns each
//! bin's normals back into the camera's frame; its per-bin table then depends on the
//! texel, so it is tabulated at [`VIEW_GRID`]² view directions across the image and
//! interpolated per texel. Files written before binning along rays
//! ([`TexelView::Perspective`] without `ray_frame`) shade as they were sampled: in the
//! camera's frame, with only the highlights tabulated per view direction.
//!
//! Shading also takes an environment map and the normal-disk explorer
//! ([`ShadeLights`]), and any zoom-out factor, trilinear between levels
//! ([`Sndf::shade_zoomed`]). [`Sndf`] holds a whole view's S-NDFs in host memory; the
//! virtual S-MIP of tiles in a GPU pool, which outlives the view, is [`crate::smip`].

use bytemuck::{Pod, Zeroable};
use glam::Vec3;

use mdlod_format::sndf::{SndfData, SndfHeader};

use crate::image::RgbaImage;
use crate::passes::sphere_raycast::Lighting;
use crate::renderer::{linear_to_srgb, srgb_to_linear};

/// WGSL source of the accumulation pass.
pub const ACCUMULATE_SHADER: &str = include_str!("passes/sndf_accumulate.wgsl");
/// WGSL source of the GPU shading pass.
pub const SHADE_SHADER: &str = include_str!("passes/sndf_shade.wgsl");

/// `ShadeParams` in the WGSL.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct ShadeParams {
    pub width: u32,
    pub height: u32,
    pub bins: u32,
    pub rays: f32,
    pub background: [f32; 4],
    /// 0: histograms in rows; 1: in tiles, as the accumulation stores them.
    pub tiled: u32,
    /// Tiles per row when tiled.
    pub tiles_x: u32,
    /// View directions per axis of the grid ([`shade_table`]); 1: one table.
    pub grid: u32,
    /// 1: binned along each texel's ray (the grid holds albedo factors and highlights).
    pub ray_frame: u32,
}

/// The GPU shading pipeline.
pub struct SndfShadePass {
    pub pipeline: wgpu::ComputePipeline,
    pub layout: wgpu::BindGroupLayout,
}

impl SndfShadePass {
    pub fn new(device: &wgpu::Device) -> SndfShadePass {
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("sndf_shade.wgsl"),
            source: wgpu::ShaderSource::Wgsl(SHADE_SHADER.into()),
        });
        let buffer = |binding, ty| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Buffer {
                ty,
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        };
        let read = wgpu::BufferBindingType::Storage { read_only: true };
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("sndf_shade"),
            entries: &[
                buffer(0, read),
                buffer(1, read),
                buffer(2, read),
                buffer(3, wgpu::BufferBindingType::Storage { read_only: false }),
            ],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("sndf_shade"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("sndf_shade"),
            layout: Some(&pipeline_layout),
            module: &module,
            entry_point: Some("shade"),
            compilation_options: Default::default(),
            cache: None,
        });
        SndfShadePass { pipeline, layout }
    }
}

/// The per-bin table the shading pass reads, and its grid of view directions per axis:
/// two rgba entries per bin (albedo factor, highlight) for the view axis; then, when the
/// lighting depends on the texel, a `grid × grid` grid of view directions (row-major from
/// the image's top left corner), which the texels interpolate bilinearly. Binned along
/// each texel's ray ([`TexelView::binned_along_rays`]), each grid point holds both
/// entries of every bin (`2 · bins²`, bin-major); binned in the camera's frame, only the
/// highlights (`bins²`), and only when there is a highlight.
pub fn shade_table(
    bins: u32,
    binning: Binning,
    lights: &ShadeLights,
    view: TexelView,
) -> (Vec<[f32; 4]>, u32) {
    let rgb = |c: &[f32; 3]| [c[0], c[1], c[2], 0.0];
    let (axis, grid) = axis_and_grid(bins, binning, lights, view);
    let mut table: Vec<[f32; 4]> = axis.iter().flat_map(|(a, s)| [rgb(a), rgb(s)]).collect();
    let g = grid.as_ref().map_or(1, |(g, _)| *g);
    if let Some((_, entries)) = grid {
        if view.binned_along_rays() {
            table.extend(entries.iter().flat_map(|(a, s)| [rgb(a), rgb(s)]));
        } else {
            table.extend(entries.iter().map(|(_, s)| rgb(s)));
        }
    }
    (table, g)
}

/// The lighting of every bin seen along the view axis ([`bin_lighting`]), and the grid of
/// view directions when the lighting differs from texel to texel ([`view_grid`]). Binned
/// along rays, the axis's entries are the grid's middle point (whose bins are not
/// turned), so the lighting, the environment's irradiance included, is worked out once.
fn axis_and_grid(
    bins: u32,
    binning: Binning,
    lights: &ShadeLights,
    view: TexelView,
) -> (Vec<BinLight>, Option<(u32, Vec<BinLight>)>) {
    let grid = view_grid(bins, binning, lights, view);
    let b2 = (bins * bins) as usize;
    let axis = match &grid {
        Some((g, entries)) if view.binned_along_rays() => {
            let middle = (g * g / 2) as usize;
            entries[middle * b2..(middle + 1) * b2].to_vec()
        }
        _ => bin_lighting(bins, binning, lights),
    };
    (axis, grid)
}

/// The direction towards the eye at each texel of a view's S-NDFs, which places the
/// highlights: the view axis, as in the paper's screen space, or each texel's own ray.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum TexelView {
    /// The view axis (+z) everywhere: exact for orthographic views.
    #[default]
    Axis,
    /// The ray through each texel's centre of a perspective view; `tan_half` holds the
    /// tangents of half the field of view, horizontally and vertically. With `ray_frame`
    /// each texel's normals are binned in the frame of its ray (as mdlod samples them
    /// now); without, in the camera's (files written before; `.sndf` version 1.0).
    Perspective { tan_half: [f32; 2], ray_frame: bool },
}

impl TexelView {
    /// The texels of `camera`'s view at `width × height`.
    pub fn of(camera: &crate::camera::Camera, width: u32, height: u32) -> TexelView {
        match camera.projection {
            crate::camera::Projection::Orthographic => TexelView::Axis,
            crate::camera::Projection::Perspective => {
                TexelView::perspective(camera.fov_y_deg, width, height, true)
            }
        }
    }

    /// A perspective view of vertical field of view `fov_y_deg` at `width × height`
    /// (the axis where its tangents are not finite and positive).
    fn perspective(fov_y_deg: f32, width: u32, height: u32, ray_frame: bool) -> TexelView {
        let y = (fov_y_deg.to_radians() * 0.5).tan();
        let x = y * width as f32 / height.max(1) as f32;
        if x.is_finite() && y.is_finite() && x > 0.0 && y > 0.0 {
            TexelView::Perspective {
                tan_half: [x, y],
                ray_frame,
            }
        } else {
            TexelView::Axis
        }
    }

    /// The texels of the view a `.sndf` header stores (a view file's JSON), binned along
    /// each texel's ray or not (the header's `normal_frame`); the axis when it holds no
    /// perspective view.
    pub fn of_view_file(
        view: &serde_json::Value,
        width: u32,
        height: u32,
        ray_frame: bool,
    ) -> TexelView {
        match serde_json::from_value::<crate::view::ViewFile>(view.clone()) {
            Ok(v) if v.projection == crate::camera::Projection::Perspective => {
                TexelView::perspective(v.fov_y_deg, width, height, ray_frame)
            }
            _ => TexelView::Axis,
        }
    }

    /// Whether each texel's normals are binned in the frame of its own ray.
    pub fn binned_along_rays(self) -> bool {
        matches!(
            self,
            TexelView::Perspective {
                ray_frame: true,
                ..
            }
        )
    }

    /// What the accumulation pass takes to bin along each texel's ray: the tangents of
    /// half the field of view, or zeros to bin in the camera's frame.
    pub fn ray_frame_tan_half(self) -> [f32; 2] {
        match self {
            TexelView::Perspective {
                tan_half,
                ray_frame: true,
            } => tan_half,
            _ => [0.0; 2],
        }
    }

    /// The unit direction towards the eye at image point `(u, v)` of `[−1, 1]²` (u to
    /// the right, v up), in view space.
    pub fn towards_eye(self, u: f32, v: f32) -> Vec3 {
        match self {
            TexelView::Axis => Vec3::Z,
            TexelView::Perspective { tan_half, .. } => {
                Vec3::new(-u * tan_half[0], -v * tan_half[1], 1.0).normalize_or(Vec3::Z)
            }
        }
    }

    /// The rotation that turns a view-space normal seen at image point `(u, v)` into the
    /// frame its bin is in: the shortest arc from the direction towards the eye there to
    /// +z when binned along rays (the WGSL's `to_ray_frame`), else none.
    pub fn bin_frame(self, u: f32, v: f32) -> glam::Quat {
        if self.binned_along_rays() {
            glam::Quat::from_rotation_arc(self.towards_eye(u, v), Vec3::Z)
        } else {
            glam::Quat::IDENTITY
        }
    }

    /// [`Self::bin_frame`] at the centre of texel `(x, y)` of a `width × height` image.
    pub fn bin_frame_at(self, x: u32, y: u32, width: u32, height: u32) -> glam::Quat {
        let (u, v) = texel_point(x, y, width, height);
        self.bin_frame(u, v)
    }
}

/// The image point `(u, v)` in `[−1, 1]²` (u to the right, v up) of texel `(x, y)`'s
/// centre.
pub fn texel_point(x: u32, y: u32, width: u32, height: u32) -> (f32, f32) {
    (
        (x as f32 + 0.5) / width.max(1) as f32 * 2.0 - 1.0,
        1.0 - (y as f32 + 0.5) / height.max(1) as f32 * 2.0,
    )
}

/// View directions per axis at which a perspective view's highlights are tabulated:
/// about 3.5° apart across the default 30° field of view.
pub const VIEW_GRID: u32 = 9;

/// Whether the lighting has a part that depends on the direction towards the eye.
fn view_dependent(lights: &ShadeLights) -> bool {
    lights.transfer.is_none()
        && lights.explorer.is_none()
        && lights.specular > 0.0
        && !lights.lights.is_empty()
}

/// The lighting of every bin at [`VIEW_GRID`]² view directions across the image
/// (row-major from the top left corner, `bins²` entries each), when it differs from
/// texel to texel. Binned along rays, all of it: each grid point's bins are turned back
/// into the camera's frame ([`TexelView::bin_frame`]). Binned in the camera's frame, only
/// the highlights (the albedo factors of the entries are zero), and only when there is a
/// highlight.
fn view_grid(
    bins: u32,
    binning: Binning,
    lights: &ShadeLights,
    view: TexelView,
) -> Option<(u32, Vec<BinLight>)> {
    let along_rays = view.binned_along_rays();
    if view == TexelView::Axis || !(along_rays || view_dependent(lights)) {
        return None;
    }
    use rayon::prelude::*;
    let g = VIEW_GRID;
    let at = |k: u32| -1.0 + 2.0 * k as f32 / (g - 1) as f32;
    // In the camera's frame the highlights alone: the rest (ambient, diffuse, and the
    // environment's 512 samples per normal) does not depend on the eye there.
    let highlights_only = ShadeLights {
        ambient: 0.0,
        lights: lights.lights.clone(),
        diffuse: 0.0,
        specular: lights.specular,
        shininess: lights.shininess,
        environment: None,
        explorer: None,
        transfer: None,
    };
    let used = if along_rays { lights } else { &highlights_only };
    let irradiance = used.environment.as_ref().map(EnvironmentMap::irradiance);
    let entries = (0..g * g)
        .into_par_iter()
        .flat_map_iter(|i| {
            let (u, v) = (at(i % g), -at(i / g));
            let eye = view.towards_eye(u, v);
            let to_view = view.bin_frame(u, v).inverse();
            bin_lighting_with(bins, binning, used, irradiance.as_ref(), eye, to_view)
        })
        .collect();
    Some((g, entries))
}

/// The four grid points around texel `(x, y)` of a `width × height` image and their
/// bilinear weights, for a grid of `g × g` view directions (g ≥ 2).
fn grid_weights(x: u32, y: u32, width: u32, height: u32, g: u32) -> [(usize, f32); 4] {
    let axis = |p: u32, n: u32| {
        let f = ((p as f32 + 0.5) / n.max(1) as f32 * (g - 1) as f32).clamp(0.0, (g - 1) as f32);
        let k = (f.floor() as u32).min(g - 2);
        (k, f - k as f32)
    };
    let ((gx, tx), (gy, ty)) = (axis(x, width), axis(y, height));
    let at = |i: u32, j: u32| (j * g + i) as usize;
    [
        (at(gx, gy), (1.0 - tx) * (1.0 - ty)),
        (at(gx + 1, gy), tx * (1.0 - ty)),
        (at(gx, gy + 1), (1.0 - tx) * ty),
        (at(gx + 1, gy + 1), tx * ty),
    ]
}

/// `Params` in the WGSL.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct AccumulateParams {
    /// The sampled rectangle, in texels.
    pub width: u32,
    pub height: u32,
    pub bins: u32,
    /// [`Binning::code`].
    pub binning: u32,
    /// G-buffer layers (iterations) this pass adds.
    pub layers: u32,
    /// The rectangle's width in tiles (the page table's row length).
    pub tiles_x: u32,
    /// [`TexelView::ray_frame_tan_half`]: zeros bin in the camera's frame.
    pub tan_half: [f32; 2],
}

/// Iterations drawn into G-buffer layers before one accumulation pass adds them.
pub const ACCUMULATE_LAYERS: u32 = 4;

/// A page-table entry of a tile that is not being sampled.
pub const NO_SLOT: u32 = u32::MAX;

/// Tile side in texels (the S-MIP's tiles, and the histogram buffer's layout).
pub const TILE: u32 = 64;

/// Index of texel `(lx, ly)` of a tile within its slot (8×8-texel blocks), as the
/// accumulation shader stores it.
pub fn texel_in_tile(lx: u32, ly: u32) -> u32 {
    ((ly / 8) * 8 + lx / 8) * 64 + (ly % 8) * 8 + lx % 8
}

/// Bytes of one tile's histograms.
pub fn tile_bytes(bins: u32) -> u64 {
    u64::from(TILE * TILE)
        .saturating_mul(u64::from(bins).pow(2))
        .saturating_mul(16)
}

/// Bytes of the histogram buffer that S-NDFs of `width × height` texels need (whole
/// tiles).
pub fn sndf_buffer_bytes(width: u32, height: u32, bins: u32) -> u64 {
    (u64::from(width.div_ceil(TILE)) * u64::from(height.div_ceil(TILE)))
        .saturating_mul(tile_bytes(bins))
}

/// How the normals are binned (the cell coordinates `(u, v)` in `[0, 1]²`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Binning {
    /// `(n.x, n.y)` in `[−1, 1]²`: the projected normal disk.
    #[default]
    ProjectedNormals,
    /// Azimuth `atan2(n.y, n.x)` over `[−π, π)` and polar angle `acos(n.z)` over
    /// `[0, π/2]` (the hemisphere facing the viewer).
    Spherical,
    /// Lambert azimuthal equal-area projection about the view axis, the hemisphere onto
    /// the unit disk: `(n.x, n.y) · sqrt(2 / (1 + n.z)) / √2`.
    LambertEqualArea,
}

impl Binning {
    pub fn code(self) -> u32 {
        match self {
            Binning::ProjectedNormals => 0,
            Binning::Spherical => 1,
            Binning::LambertEqualArea => 2,
        }
    }

    /// The name stored in `.sndf` headers.
    pub fn name(self) -> &'static str {
        match self {
            Binning::ProjectedNormals => "projected-normals",
            Binning::Spherical => "spherical",
            Binning::LambertEqualArea => "lambert-equal-area",
        }
    }

    pub fn from_name(name: &str) -> Option<Binning> {
        [
            Binning::ProjectedNormals,
            Binning::Spherical,
            Binning::LambertEqualArea,
        ]
        .into_iter()
        .find(|b| b.name() == name)
    }

    /// The cell coordinates of a unit normal (the WGSL's `bin_coords`).
    pub fn coords(self, n: Vec3) -> (f32, f32) {
        match self {
            Binning::ProjectedNormals => ((n.x + 1.0) * 0.5, (n.y + 1.0) * 0.5),
            Binning::Spherical => (
                n.y.atan2(n.x) / std::f32::consts::TAU + 0.5,
                n.z.clamp(-1.0, 1.0).acos() / std::f32::consts::FRAC_PI_2,
            ),
            Binning::LambertEqualArea => {
                let k = (2.0 / (1.0 + n.z).max(1e-6)).sqrt() / std::f32::consts::SQRT_2;
                ((n.x * k + 1.0) * 0.5, (n.y * k + 1.0) * 0.5)
            }
        }
    }

    /// The projected solid angle σ⊥ per unit of cell area `du dv` at unit normal `n` (up
    /// to a constant factor): how densely the normals a ray hits fall at that point of the
    /// cell, since a surface's normals are seen in proportion to σ⊥ (Eq. 6). Uniform in
    /// the projected disk; `n.z` for the equal-area projection (solid angle is uniform
    /// there); `sin θ · cos θ` for the angles (`dω = sin θ dθ dφ`).
    pub fn projected_density(self, n: Vec3) -> f32 {
        let cos = n.z.clamp(0.0, 1.0);
        match self {
            Binning::ProjectedNormals => 1.0,
            Binning::LambertEqualArea => cos,
            Binning::Spherical => cos * (1.0 - cos * cos).max(0.0).sqrt(),
        }
    }

    /// The unit normal at cell coordinates `(u, v)`, if any normal maps there.
    pub fn normal(self, u: f32, v: f32) -> Option<Vec3> {
        match self {
            Binning::ProjectedNormals => {
                let (x, y) = (2.0 * u - 1.0, 2.0 * v - 1.0);
                let r2 = x * x + y * y;
                (r2 <= 1.0).then(|| Vec3::new(x, y, (1.0 - r2).sqrt()))
            }
            Binning::Spherical => {
                let phi = (u - 0.5) * std::f32::consts::TAU;
                let theta = v * std::f32::consts::FRAC_PI_2;
                Some(Vec3::new(
                    theta.sin() * phi.cos(),
                    theta.sin() * phi.sin(),
                    theta.cos(),
                ))
            }
            Binning::LambertEqualArea => {
                let (x, y) = (
                    (2.0 * u - 1.0) * std::f32::consts::SQRT_2,
                    (2.0 * v - 1.0) * std::f32::consts::SQRT_2,
                );
                let r2 = x * x + y * y;
                (r2 <= 2.0).then(|| {
                    let s = (1.0 - r2 / 4.0).max(0.0).sqrt();
                    Vec3::new(x * s, y * s, 1.0 - r2 / 2.0)
                })
            }
        }
    }
}

/// The accumulation pipeline.
pub struct SndfPass {
    pub pipeline: wgpu::ComputePipeline,
    pub layout: wgpu::BindGroupLayout,
}

impl SndfPass {
    pub fn new(device: &wgpu::Device) -> SndfPass {
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("sndf_accumulate.wgsl"),
            source: wgpu::ShaderSource::Wgsl(ACCUMULATE_SHADER.into()),
        });
        let texture = |binding| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Texture {
                sample_type: wgpu::TextureSampleType::Float { filterable: false },
                view_dimension: wgpu::TextureViewDimension::D2Array,
                multisampled: false,
            },
            count: None,
        };
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("sndf_accumulate"),
            entries: &[
                wgpu::BindGroupLayoutEntry {
                    binding: 0,
                    visibility: wgpu::ShaderStages::COMPUTE,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Storage { read_only: true },
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                    count: None,
                },
                texture(1),
                texture(2),
                wgpu::BindGroupLayoutEntry {
                    binding: 3,
                    visibility: wgpu::ShaderStages::COMPUTE,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Storage { read_only: false },
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                    count: None,
                },
                wgpu::BindGroupLayoutEntry {
                    binding: 4,
                    visibility: wgpu::ShaderStages::COMPUTE,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Storage { read_only: true },
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                    count: None,
                },
            ],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("sndf_accumulate"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("sndf_accumulate"),
            layout: Some(&pipeline_layout),
            module: &module,
            entry_point: Some("accumulate"),
            compilation_options: Default::default(),
            cache: None,
        });
        SndfPass { pipeline, layout }
    }
}

/// What to sample.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SndfSettings {
    /// Texels (the image size).
    pub width: u32,
    pub height: u32,
    /// Jittered rays per texel.
    pub iterations: u32,
    /// Bins per axis (8 by default).
    pub bins: u32,
    pub binning: Binning,
}

/// The sampled S-NDFs of one view: per texel (rows top to bottom), `bins × bins` bins
/// (row `by`, column `bx` of the projected normal disk, `n.y` and `n.x` increasing), each
/// the albedo sum (rgb) and count (a) of the samples that fell into it.
#[derive(Clone, Debug, PartialEq)]
pub struct Sndf {
    pub width: u32,
    pub height: u32,
    pub bins: u32,
    pub binning: Binning,
    /// Rays per texel (iterations).
    pub rays: u32,
    pub hist: Vec<[f32; 4]>,
    /// GPU time of the sampling (all iterations), when measured.
    pub gpu_time: Option<std::time::Duration>,
    /// Where the eye is seen from each texel (the highlights follow it), and whether each
    /// texel's normals are binned in the frame of its ray.
    pub view: TexelView,
}

/// The bin of a unit normal, as the WGSL computes it.
pub fn bin_of(n: Vec3, bins: u32, binning: Binning) -> (u32, u32) {
    let b = bins as f32;
    let (u, v) = binning.coords(n);
    let idx = |c: f32| (c.clamp(0.0, 1.0) * b).min(b - 1.0) as u32;
    (idx(u), idx(v))
}

/// The lights and material S-NDFs are shaded with: any number of coloured directional
/// lights (directions towards the light, in view space), ambient light, Lambert and an
/// optional Blinn-Phong highlight, an optional environment map, or instead of all
/// lighting the normal-disk explorer.
#[derive(Clone, Debug, PartialEq)]
pub struct ShadeLights {
    pub ambient: f32,
    /// (direction towards the light, linear RGB colour).
    pub lights: Vec<(Vec3, [f32; 3])>,
    pub diffuse: f32,
    /// 0 for Lambert only.
    pub specular: f32,
    pub shininess: f32,
    /// Diffuse light from an environment (Lambert irradiance).
    pub environment: Option<EnvironmentMap>,
    /// Colour the normals by direction instead of lighting them.
    pub explorer: Option<Explorer>,
    /// Colour the normals from a painted image of the normal disk instead of lighting
    /// them (see [`TransferImage`]); it takes precedence over the explorer.
    pub transfer: Option<TransferImage>,
}

impl ShadeLights {
    /// Checks the lighting numbers: ambient, diffuse, specular and shininess finite and 0
    /// or more, light colours finite (a NaN shades every pixel black).
    pub fn check(&self) -> Result<(), String> {
        for (what, v) in [
            ("ambient", self.ambient),
            ("diffuse", self.diffuse),
            ("specular", self.specular),
            ("shininess (exponent)", self.shininess),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(format!("{what} {v} (must be a finite number, 0 or more)"));
            }
        }
        if self
            .lights
            .iter()
            .any(|(d, c)| !d.is_finite() || c.iter().any(|v| !v.is_finite()))
        {
            return Err("a light's direction or colour is not finite".into());
        }
        Ok(())
    }
}

/// The linear RGB of every pixel of an sRGB image.
fn linear_rgb(image: &RgbaImage) -> Vec<[f32; 3]> {
    image
        .data
        .chunks_exact(4)
        .map(|p| [0, 1, 2].map(|k| srgb_to_linear(f32::from(p[k]) / 255.0)))
        .collect()
}

/// A transfer function over the normal disk, painted as an image: the disk of projected
/// normals (view space, +x right, +y up) is inscribed in the image, so a normal `n` takes
/// the colour of the texel at `((n.x + 1) / 2 · width, (1 − n.y) / 2 · height)`. Linear
/// RGB.
#[derive(Clone, Debug, PartialEq)]
pub struct TransferImage {
    pub width: u32,
    pub height: u32,
    pub colour: Vec<[f32; 3]>,
}

impl TransferImage {
    /// From an sRGB image (e.g. a PNG painted in any editor).
    pub fn from_image(image: &RgbaImage) -> TransferImage {
        TransferImage {
            width: image.width,
            height: image.height,
            colour: linear_rgb(image),
        }
    }

    /// The colour of the texel a view-space normal falls on.
    pub fn colour(&self, n: Vec3) -> [f32; 3] {
        if self.width == 0 || self.height == 0 {
            return [0.0; 3];
        }
        let x = ((n.x + 1.0) * 0.5 * self.width as f32).clamp(0.0, self.width as f32 - 1.0) as u32;
        let y =
            ((1.0 - n.y) * 0.5 * self.height as f32).clamp(0.0, self.height as f32 - 1.0) as u32;
        self.colour
            .get((y * self.width + x) as usize)
            .copied()
            .unwrap_or([0.0; 3])
    }
}

/// An equirectangular environment in view space (a light probe that turns with the view,
/// like a material capture): column `i` is the azimuth `atan2(d.x, d.z)` from −π to π,
/// row `j` the elevation `asin(d.y)` from π/2 (top) to −π/2; linear RGB radiance.
#[derive(Clone, Debug, PartialEq)]
pub struct EnvironmentMap {
    pub width: u32,
    pub height: u32,
    pub radiance: Vec<[f32; 3]>,
}

impl EnvironmentMap {
    /// From an sRGB image (e.g. a PNG).
    pub fn from_image(image: &RgbaImage) -> EnvironmentMap {
        EnvironmentMap {
            width: image.width,
            height: image.height,
            radiance: linear_rgb(image),
        }
    }

    /// The Lambert irradiance over π of every normal (the mean radiance the hemisphere
    /// around it sends), tabulated on [`Irradiance`]'s grid from [`Self::samples`].
    pub fn irradiance(&self) -> Irradiance {
        let samples = self.samples();
        let (w, h) = (Irradiance::WIDTH, Irradiance::HEIGHT);
        use rayon::prelude::*;
        let values = (0..w * h)
            .into_par_iter()
            .map(|t| {
                let n = Irradiance::direction(t % w, t / w);
                let mut e = [0f32; 3];
                for (d, omega, r) in &samples {
                    let c = n.dot(*d).max(0.0) * omega / std::f32::consts::PI;
                    for k in 0..3 {
                        e[k] += c * r[k];
                    }
                }
                e
            })
            .collect();
        Irradiance { values }
    }

    /// Directions and solid angles of the texels of a copy at most 32×16.
    fn samples(&self) -> Vec<(Vec3, f32, [f32; 3])> {
        let (w, h) = (self.width.clamp(1, 32), self.height.clamp(1, 16));
        let mut out = Vec::with_capacity((w * h) as usize);
        for j in 0..h {
            let elevation =
                std::f32::consts::FRAC_PI_2 - (j as f32 + 0.5) / h as f32 * std::f32::consts::PI;
            let d_omega = (std::f32::consts::TAU / w as f32)
                * (std::f32::consts::PI / h as f32)
                * elevation.cos();
            for i in 0..w {
                let azimuth =
                    (i as f32 + 0.5) / w as f32 * std::f32::consts::TAU - std::f32::consts::PI;
                let d = Vec3::new(
                    elevation.cos() * azimuth.sin(),
                    elevation.sin(),
                    elevation.cos() * azimuth.cos(),
                );
                // The mean radiance of the source texels this one covers.
                let (x0, x1) = (
                    i * self.width / w,
                    ((i + 1) * self.width / w).max(i * self.width / w + 1),
                );
                let (y0, y1) = (
                    j * self.height / h,
                    ((j + 1) * self.height / h).max(j * self.height / h + 1),
                );
                let mut sum = [0f32; 3];
                let mut n = 0.0;
                for y in y0..y1.min(self.height) {
                    for x in x0..x1.min(self.width) {
                        let r = self.radiance[(y * self.width + x) as usize];
                        for k in 0..3 {
                            sum[k] += r[k];
                        }
                        n += 1.0;
                    }
                }
                out.push((d, d_omega, sum.map(|v| v / f32::max(n, 1.0))));
            }
        }
        out
    }
}

/// An environment's irradiance over π per normal direction, on an equirectangular grid
/// of normals ([`EnvironmentMap`]'s parametrisation, at the centres of `WIDTH × HEIGHT`
/// cells), interpolated bilinearly: irradiance is the environment convolved with a
/// cosine lobe, smooth enough that a 2.8° grid holds it to half a per cent of the
/// brightest normal's, and a bin's 256 sub-samples at 81 view directions then cost a
/// lookup each instead of a sum over 512 environment samples.
#[derive(Clone, Debug, PartialEq)]
pub struct Irradiance {
    values: Vec<[f32; 3]>,
}

impl Irradiance {
    const WIDTH: u32 = 128;
    const HEIGHT: u32 = 64;

    /// The unit direction at the centre of cell `(i, j)`.
    fn direction(i: u32, j: u32) -> Vec3 {
        let (azimuth, elevation) = Self::angles(i as f32 + 0.5, j as f32 + 0.5);
        Vec3::new(
            elevation.cos() * azimuth.sin(),
            elevation.sin(),
            elevation.cos() * azimuth.cos(),
        )
    }

    /// Azimuth and elevation at grid coordinates `(x, y)` (cells `[i, i + 1)`).
    fn angles(x: f32, y: f32) -> (f32, f32) {
        (
            x / Self::WIDTH as f32 * std::f32::consts::TAU - std::f32::consts::PI,
            std::f32::consts::FRAC_PI_2 - y / Self::HEIGHT as f32 * std::f32::consts::PI,
        )
    }

    /// The irradiance over π towards unit normal `n`: bilinear between the four cell
    /// centres around it, the azimuth wrapping around, the elevation clamped at the
    /// first and last rows' centres.
    pub fn at(&self, n: Vec3) -> [f32; 3] {
        let (w, h) = (Self::WIDTH, Self::HEIGHT);
        let azimuth = n.x.atan2(n.z);
        let elevation = n.y.clamp(-1.0, 1.0).asin();
        let x = (azimuth + std::f32::consts::PI) / std::f32::consts::TAU * w as f32 - 0.5;
        let y = ((std::f32::consts::FRAC_PI_2 - elevation) / std::f32::consts::PI * h as f32 - 0.5)
            .clamp(0.0, (h - 1) as f32);
        let (xf, yf) = (x.floor(), y.floor().min((h - 2) as f32));
        let (tx, ty) = (x - xf, y - yf);
        let i0 = (xf as i64).rem_euclid(i64::from(w)) as u32;
        let i1 = (i0 + 1) % w;
        let j0 = yf as u32;
        let at = |i: u32, j: u32| self.values[(j * w + i) as usize];
        let (a, b, c, d) = (at(i0, j0), at(i1, j0), at(i0, j0 + 1), at(i1, j0 + 1));
        [0, 1, 2].map(|k| {
            (a[k] * (1.0 - tx) + b[k] * tx) * (1.0 - ty) + (c[k] * (1.0 - tx) + d[k] * tx) * ty
        })
    }
}

/// The S-NDF explorer (it replaces the lighting and the albedos): a normal within
/// `disk_deg` of the view axis gets `disk_colour`;
/// the others get the colour of their azimuthal slice (`slices` equal slices, the first
/// centred on +x), blended to black over `tolerance_deg` at the slice borders so the
/// borders stand out.
#[derive(Clone, Debug, PartialEq)]
pub struct Explorer {
    pub disk_deg: f32,
    pub slices: u32,
    pub tolerance_deg: f32,
    pub disk_colour: [f32; 3],
    pub slice_colours: Vec<[f32; 3]>,
}

impl Explorer {
    /// The pattern with `slices` slices in the default palette (a light grey disk; red,
    /// green, blue, yellow, purple and teal slices, repeating).
    pub fn new(slices: u32, disk_deg: f32, tolerance_deg: f32) -> Explorer {
        Explorer {
            disk_deg,
            slices,
            tolerance_deg,
            disk_colour: [0.9, 0.9, 0.9],
            slice_colours: vec![
                [0.85, 0.1, 0.1],
                [0.1, 0.6, 0.15],
                [0.1, 0.25, 0.85],
                [0.9, 0.7, 0.05],
                [0.6, 0.1, 0.7],
                [0.05, 0.65, 0.7],
            ],
        }
    }

    /// The pattern's colour for a view-space normal.
    pub fn colour(&self, n: Vec3) -> [f32; 3] {
        let from_axis = n.z.clamp(-1.0, 1.0).acos().to_degrees();
        if from_axis <= self.disk_deg {
            return self.disk_colour;
        }
        let slices = self.slices.max(1);
        let width = 360.0 / slices as f32;
        let azimuth = n.y.atan2(n.x).to_degrees().rem_euclid(360.0);
        let shifted = (azimuth + width / 2.0).rem_euclid(360.0);
        let k = ((shifted / width) as u32).min(slices - 1);
        let to_border = (shifted - k as f32 * width).min((k + 1) as f32 * width - shifted);
        let fade = if self.tolerance_deg > 0.0 {
            (to_border / self.tolerance_deg).min(1.0)
        } else {
            1.0
        };
        let c = self
            .slice_colours
            .get(k as usize % self.slice_colours.len().max(1))
            .copied()
            .unwrap_or([1.0; 3]);
        c.map(|v| v * fade)
    }
}

impl From<&Lighting> for ShadeLights {
    /// The sphere renderer's single light.
    fn from(l: &Lighting) -> Self {
        ShadeLights {
            ambient: l.ambient,
            lights: vec![(l.direction_view, l.colour)],
            diffuse: l.diffuse,
            specular: l.specular,
            shininess: l.shininess,
            environment: None,
            explorer: None,
            transfer: None,
        }
    }
}

/// Per bin (row-major, `by * bins + bx`), the lighting averaged over the bin's part of
/// the normal disk with the weight of projected solid angle (Eq. 12-14's L̃(D)/σ⊥(D):
/// the bin's normals are seen in proportion to σ⊥), per colour channel, as (albedo factor: ambient + Σ diffuse ·
/// max(n·l, 0) · colour; highlight: Σ specular · Blinn-Phong · colour), for the view
/// direction +z. Bins outside the disk get the values at the nearest disk edge.
pub fn bin_lighting(bins: u32, binning: Binning, lights: &ShadeLights) -> Vec<BinLight> {
    bin_lighting_towards(bins, binning, lights, Vec3::Z)
}

/// A bin's albedo factor and highlight (linear RGB each).
pub type BinLight = ([f32; 3], [f32; 3]);

/// [`bin_lighting`] with the eye in direction `eye` (a unit vector in view space): the
/// highlights move with it, the rest does not.
pub fn bin_lighting_towards(
    bins: u32,
    binning: Binning,
    lights: &ShadeLights,
    eye: Vec3,
) -> Vec<BinLight> {
    bin_lighting_in(bins, binning, lights, eye, glam::Quat::IDENTITY)
}

/// [`bin_lighting_towards`] for bins whose normals `to_view` turns into view space (the
/// inverse of [`TexelView::bin_frame`]): each of a bin's normals is lit as that view-space
/// normal. The weights of projected solid angle stay the bin frame's, where the eye is
/// on the axis.
pub fn bin_lighting_in(
    bins: u32,
    binning: Binning,
    lights: &ShadeLights,
    eye: Vec3,
    to_view: glam::Quat,
) -> Vec<BinLight> {
    let irradiance = lights.environment.as_ref().map(EnvironmentMap::irradiance);
    bin_lighting_with(bins, binning, lights, irradiance.as_ref(), eye, to_view)
}

/// [`bin_lighting_in`] with the environment's irradiance tabulated beforehand (a grid of
/// view directions shares one table).
fn bin_lighting_with(
    bins: u32,
    binning: Binning,
    lights: &ShadeLights,
    irradiance: Option<&Irradiance>,
    eye: Vec3,
    to_view: glam::Quat,
) -> Vec<BinLight> {
    const SUB: u32 = 16;
    let dirs: Vec<(Vec3, Vec3, [f32; 3])> = lights
        .lights
        .iter()
        .map(|&(d, c)| {
            let l = d.normalize_or(Vec3::Z);
            (l, (l + eye).normalize_or(eye), c)
        })
        .collect();
    let shade = |n: Vec3| {
        if let Some(t) = &lights.transfer {
            // The painted colour per sample, whatever the particle's albedo.
            return ([0.0; 3], t.colour(n));
        }
        if let Some(explorer) = &lights.explorer {
            // The pattern's colour per sample, whatever the particle's albedo.
            return ([0.0; 3], explorer.colour(n));
        }
        let mut a = [lights.ambient; 3];
        let mut s = [0.0f32; 3];
        if let Some(e) = irradiance.map(|t| t.at(n)) {
            for k in 0..3 {
                a[k] += lights.diffuse * e[k];
            }
        }
        for (l, h, c) in &dirs {
            let ndl = n.dot(*l).max(0.0);
            let spec = if ndl > 0.0 && lights.specular > 0.0 {
                lights.specular * n.dot(*h).max(0.0).powf(lights.shininess)
            } else {
                0.0
            };
            for k in 0..3 {
                a[k] += lights.diffuse * ndl * c[k];
                s[k] += spec * c[k];
            }
        }
        (a, s)
    };
    let cell = 1.0 / bins as f32;
    let mut out = Vec::with_capacity((bins * bins) as usize);
    for by in 0..bins {
        for bx in 0..bins {
            let (mut a, mut s, mut n) = ([0f32; 3], [0f32; 3], 0f32);
            // A cell no normal maps to (a corner of a disk binning) takes the lighting
            // of the disk's edge towards its centre.
            let centre = (cell * (bx as f32 + 0.5), cell * (by as f32 + 0.5));
            let fallback = {
                let (du, dv) = (centre.0 - 0.5, centre.1 - 0.5);
                let len = (du * du + dv * dv).sqrt().max(1e-6);
                let edge = binning
                    .normal(0.5 + du / len * 0.4999, 0.5 + dv / len * 0.4999)
                    .or_else(|| binning.normal(0.5, 0.5))
                    .unwrap_or(Vec3::Z);
                shade(to_view * edge)
            };
            for j in 0..SUB {
                for i in 0..SUB {
                    let u = cell * (bx as f32 + (i as f32 + 0.5) / SUB as f32);
                    let v = cell * (by as f32 + (j as f32 + 0.5) / SUB as f32);
                    if let Some(normal) = binning.normal(u, v) {
                        let w = binning.projected_density(normal);
                        let val = shade(to_view * normal);
                        for k in 0..3 {
                            a[k] += w * val.0[k];
                            s[k] += w * val.1[k];
                        }
                        n += w;
                    }
                }
            }
            out.push(if n > 0.0 {
                (a.map(|v| v / n), s.map(|v| v / n))
            } else {
                fallback
            });
        }
    }
    out
}

impl Sndf {
    /// Adds another sampling of the same view (the same size and bins), as progressive
    /// refinement does: histograms and ray counts sum, so the result is one sampling
    /// of all the rays. Returns false, changing nothing, when the two do not match.
    pub fn add(&mut self, other: &Sndf) -> bool {
        if (self.width, self.height, self.bins, self.binning, self.view)
            != (
                other.width,
                other.height,
                other.bins,
                other.binning,
                other.view,
            )
        {
            return false;
        }
        for (a, b) in self.hist.iter_mut().zip(&other.hist) {
            for k in 0..4 {
                a[k] += b[k];
            }
        }
        self.rays += other.rays;
        self.gpu_time = match (self.gpu_time, other.gpu_time) {
            (Some(a), Some(b)) => Some(a + b),
            _ => None,
        };
        true
    }

    /// The bins of texel `(x, y)`.
    pub fn texel(&self, x: u32, y: u32) -> &[[f32; 4]] {
        let b2 = (self.bins * self.bins) as usize;
        let i = (y * self.width + x) as usize * b2;
        &self.hist[i..i + b2]
    }

    /// Shades every texel over `background_srgb`, from the S-NDFs alone: linear RGB per
    /// texel, rows top to bottom.
    pub fn shade_linear(&self, lights: &ShadeLights, background_srgb: [f32; 3]) -> Vec<[f32; 3]> {
        let (table, grid) = axis_and_grid(self.bins, self.binning, lights, self.view);
        let along_rays = self.view.binned_along_rays();
        let bg = background_srgb.map(srgb_to_linear);
        let rays = self.rays.max(1) as f32;
        let b2 = (self.bins * self.bins) as usize;
        use rayon::prelude::*;
        self.hist
            .par_chunks_exact(b2)
            .enumerate()
            .map(|(t, texel)| {
                let mut c = [0f32; 3];
                let mut hits = 0.0;
                // The texel's highlights (and, binned along rays, albedo factors):
                // bilinear between the grid's view directions.
                let corners = grid.as_ref().map(|(g, _)| {
                    let (x, y) = (t as u32 % self.width, t as u32 / self.width);
                    grid_weights(x, y, self.width, self.height, *g)
                });
                for (i, (bin, (a, s))) in texel.iter().zip(&table).enumerate() {
                    let (a, s) = match (&grid, corners) {
                        (Some((_, e)), Some(w)) => {
                            let (ga, gs) = w.iter().fold(([0f32; 3], [0f32; 3]), |acc, &(p, f)| {
                                let (ea, es) = e[p * b2 + i];
                                (
                                    [0, 1, 2].map(|k| acc.0[k] + f * ea[k]),
                                    [0, 1, 2].map(|k| acc.1[k] + f * es[k]),
                                )
                            });
                            (if along_rays { ga } else { *a }, gs)
                        }
                        _ => (*a, *s),
                    };
                    for k in 0..3 {
                        c[k] += bin[k] * a[k] + bin[3] * s[k];
                    }
                    hits += bin[3];
                }
                let miss = (1.0 - hits / rays).max(0.0);
                [0, 1, 2].map(|k| c[k] / rays + miss * bg[k])
            })
            .collect()
    }

    /// [`Self::shade_linear`] as an sRGB image.
    pub fn shade_with(&self, lights: &ShadeLights, background_srgb: [f32; 3]) -> RgbaImage {
        let mut image = RgbaImage::new(self.width, self.height);
        for (i, c) in self
            .shade_linear(lights, background_srgb)
            .iter()
            .enumerate()
        {
            let px = [c[0], c[1], c[2], 1.0]
                .map(|v| (linear_to_srgb(v.clamp(0.0, 1.0)) * 255.0 + 0.5) as u8);
            image.data[4 * i..4 * i + 4].copy_from_slice(&px);
        }
        image
    }

    /// Shades under the sphere renderer's lighting.
    pub fn shade(&self, lighting: &Lighting, background_srgb: [f32; 3]) -> RgbaImage {
        self.shade_with(&ShadeLights::from(lighting), background_srgb)
    }

    /// Shades the view zoomed out by `zoom_out` (≥ 1) into an image `zoom_out` times
    /// smaller, trilinearly: bilinear within the two S-MIP levels around `log2 zoom_out`,
    /// linear between them, on linear colours (shading is linear in the S-NDFs).
    pub fn shade_zoomed(
        &self,
        lights: &ShadeLights,
        background_srgb: [f32; 3],
        zoom_out: f32,
    ) -> RgbaImage {
        let zoom_out = if zoom_out.is_finite() {
            zoom_out.max(1.0)
        } else {
            1.0
        };
        // Past the level of one texel every coarser level is the same texel.
        let f = zoom_out.log2().min(self.coarsest_level() as f32);
        let l0 = f.floor() as u32;
        let t = f - l0 as f32;
        let mut level = self.clone();
        for _ in 0..l0 {
            level = level.downsample();
        }
        let next = level.downsample();
        let images = [
            (
                level.width,
                level.height,
                level.shade_linear(lights, background_srgb),
            ),
            (
                next.width,
                next.height,
                next.shade_linear(lights, background_srgb),
            ),
        ];
        let (w, h) = (
            ((self.width as f32 / zoom_out).round() as u32).max(1),
            ((self.height as f32 / zoom_out).round() as u32).max(1),
        );
        let bilinear = |(lw, lh, img): &(u32, u32, Vec<[f32; 3]>), x: f32, y: f32| {
            let (x, y) = (
                (x - 0.5).clamp(0.0, *lw as f32 - 1.0),
                (y - 0.5).clamp(0.0, *lh as f32 - 1.0),
            );
            let (x0, y0) = (x.floor() as u32, y.floor() as u32);
            let (x1, y1) = ((x0 + 1).min(lw - 1), (y0 + 1).min(lh - 1));
            let (fx, fy) = (x - x0 as f32, y - y0 as f32);
            let at = |x: u32, y: u32| img[(y * lw + x) as usize];
            let mut c = [0f32; 3];
            for k in 0..3 {
                let top = at(x0, y0)[k] * (1.0 - fx) + at(x1, y0)[k] * fx;
                let bottom = at(x0, y1)[k] * (1.0 - fx) + at(x1, y1)[k] * fx;
                c[k] = top * (1.0 - fy) + bottom * fy;
            }
            c
        };
        let mut image = RgbaImage::new(w, h);
        for y in 0..h {
            for x in 0..w {
                // The output pixel's centre in level-0 texels, then in each level's.
                let (px, py) = ((x as f32 + 0.5) * zoom_out, (y as f32 + 0.5) * zoom_out);
                let s0 = 2f32.powi(l0 as i32);
                let a = bilinear(&images[0], px / s0, py / s0);
                let b = bilinear(&images[1], px / (2.0 * s0), py / (2.0 * s0));
                let c = [0, 1, 2].map(|k| a[k] * (1.0 - t) + b[k] * t);
                let px = [c[0], c[1], c[2], 1.0]
                    .map(|v| (linear_to_srgb(v.clamp(0.0, 1.0)) * 255.0 + 0.5) as u8);
                image.set_pixel(x, y, px);
            }
        }
        image
    }

    /// Down-samplings until the image is one texel (each coarser level is that texel).
    pub fn coarsest_level(&self) -> u32 {
        coarsest_level(self.width, self.height)
    }

    /// The next coarser S-MIP level: each texel holds the sum of its 2×2 children's bins
    /// and four times the rays, i.e. their average S-NDF. At an odd edge, where a texel
    /// has one or two children, it holds their average too (their sums scaled by 4 over
    /// their count), as a texture's edge is clamped: the image's last row or column
    /// stands for the half texel past it, which was never sampled. (Counting the missing
    /// children as rays that hit nothing paled the edge towards the background.)
    pub fn downsample(&self) -> Sndf {
        let (w, h) = (self.width.div_ceil(2), self.height.div_ceil(2));
        let b2 = (self.bins * self.bins) as usize;
        // Four times the rays, or, where that passes u32, the same rays and a quarter of
        // the sums (exact in floating point): the same S-NDF either way.
        let (rays, scale) = match self.rays.checked_mul(4) {
            Some(r) => (r, 1.0),
            None => (self.rays, 0.25),
        };
        // Children of texel `i` of the coarse level along one axis of `n` fine texels.
        let children = |i: u32, n: u32| if 2 * i + 1 < n { 2.0 } else { 1.0 };
        let mut hist = vec![[0f32; 4]; w as usize * h as usize * b2];
        for y in 0..self.height {
            for x in 0..self.width {
                let (cx, cy) = (x / 2, y / 2);
                let edge = 4.0 / (children(cx, self.width) * children(cy, self.height));
                let dst = (cy * w + cx) as usize * b2;
                for (d, s) in hist[dst..dst + b2].iter_mut().zip(self.texel(x, y)) {
                    for k in 0..4 {
                        d[k] += s[k] * scale * edge;
                    }
                }
            }
        }
        Sndf {
            width: w,
            height: h,
            bins: self.bins,
            binning: self.binning,
            rays,
            hist,
            gpu_time: None,
            view: self.view,
        }
    }

    /// The file form, with the camera (a view file's JSON) and the source's name.
    pub fn to_data(&self, view: serde_json::Value, source: Option<String>) -> SndfData {
        SndfData {
            header: SndfHeader {
                width: self.width,
                height: self.height,
                bins: self.bins,
                binning: self.binning.name().into(),
                rays: self.rays,
                view,
                source,
                display_level: None,
                normal_frame: self
                    .view
                    .binned_along_rays()
                    .then(|| mdlod_format::sndf::RAY_FRAME.into()),
                smip: None,
            },
            hist: self.hist.clone(),
        }
    }

    /// From the file form (the reader has checked the binning's name).
    pub fn from_data(d: &SndfData) -> Sndf {
        Sndf {
            width: d.header.width,
            height: d.header.height,
            bins: d.header.bins,
            binning: Binning::from_name(&d.header.binning).unwrap_or_default(),
            rays: d.header.rays,
            hist: d.hist.clone(),
            gpu_time: None,
            view: TexelView::of_view_file(
                &d.header.view,
                d.header.width,
                d.header.height,
                d.header.normal_frame.is_some(),
            ),
        }
    }
}

/// Down-samplings of `width`×`height` texels until one texel is left (each coarser
/// level is that texel).
pub fn coarsest_level(width: u32, height: u32) -> u32 {
    let side = width.max(height).max(1);
    u32::BITS - (side - 1).leading_zeros()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lighting_numbers_must_be_finite_and_not_negative() {
        let lights = ShadeLights {
            ambient: 0.15,
            lights: vec![(Vec3::Z, [1.0; 3])],
            diffuse: 0.85,
            specular: 0.25,
            shininess: 32.0,
            environment: None,
            explorer: None,
            transfer: None,
        };
        lights.check().unwrap();
        for bad in [f32::NAN, -0.5, f32::INFINITY] {
            for (name, l) in [
                (
                    "ambient",
                    ShadeLights {
                        ambient: bad,
                        ..lights.clone()
                    },
                ),
                (
                    "diffuse",
                    ShadeLights {
                        diffuse: bad,
                        ..lights.clone()
                    },
                ),
                (
                    "specular",
                    ShadeLights {
                        specular: bad,
                        ..lights.clone()
                    },
                ),
                (
                    "shininess",
                    ShadeLights {
                        shininess: bad,
                        ..lights.clone()
                    },
                ),
            ] {
                let e = l.check().unwrap_err();
                assert!(e.starts_with(name) && e.contains("0 or more"), "{e}");
            }
        }
    }

    /// Numbers uniform in `[0, 1)`, the same for the same seed.
    fn uniform(seed: u64) -> impl FnMut() -> f32 {
        let mut state = seed;
        move || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 40) as f32 / (1u64 << 24) as f32
        }
    }

    /// The normals `n` rays along `−eye` see on a sphere: its projected disk hit
    /// uniformly, so spread by projected solid angle about `eye`.
    fn sphere_hits(seed: u64, n: usize, eye: Vec3) -> Vec<Vec3> {
        let mut next = uniform(seed);
        let (t1, t2) = eye.any_orthonormal_pair();
        std::iter::from_fn(|| Some((next() * 2.0 - 1.0, next() * 2.0 - 1.0)))
            .filter(|(x, y)| x * x + y * y < 1.0)
            .take(n)
            .map(|(x, y)| x * t1 + y * t2 + (1.0 - x * x - y * y).sqrt() * eye)
            .collect()
    }

    fn random_sndf(w: u32, h: u32, bins: u32, rays: u32) -> Sndf {
        let mut next = uniform(7);
        let hist = (0..w * h * bins * bins)
            .map(|_| {
                let n = (next() * 3.0).floor();
                [n * next(), n * next(), n * next(), n]
            })
            .collect();
        Sndf {
            width: w,
            height: h,
            bins,
            binning: Binning::default(),
            rays,
            hist,
            gpu_time: None,
            view: TexelView::Axis,
        }
    }

    #[test]
    fn a_bin_averages_its_lighting_as_the_rays_hitting_a_sphere_see_it() {
        // Rays of an orthographic view hit a sphere uniformly over its projected disk, so
        // the normals they see are spread by projected solid angle, independently of any
        // binning. The table's value of a bin must be the mean lighting of those hits
        // that fall into it.
        let (l, h) = (
            Vec3::new(0.3, -0.5, 0.8).normalize(),
            (Vec3::new(0.3, -0.5, 0.8).normalize() + Vec3::Z).normalize(),
        );
        let lights = ShadeLights {
            ambient: 0.0,
            lights: vec![(l, [1.0; 3])],
            diffuse: 1.0,
            specular: 0.5,
            shininess: 8.0,
            environment: None,
            explorer: None,
            transfer: None,
        };
        let bins = 4u32;
        let hits = sphere_hits(11, 400_000, Vec3::Z);
        for binning in [
            Binning::ProjectedNormals,
            Binning::Spherical,
            Binning::LambertEqualArea,
        ] {
            let mut sums = vec![(0.0f64, 0.0f64, 0u32); (bins * bins) as usize];
            for &n in &hits {
                let (bx, by) = bin_of(n, bins, binning);
                let ndl = n.dot(l).max(0.0);
                let spec = if ndl > 0.0 {
                    0.5 * n.dot(h).max(0.0).powf(8.0)
                } else {
                    0.0
                };
                let s = &mut sums[(by * bins + bx) as usize];
                s.0 += f64::from(ndl);
                s.1 += f64::from(spec);
                s.2 += 1;
            }
            let table = bin_lighting(bins, binning, &lights);
            for (i, &(diffuse, highlight, count)) in sums.iter().enumerate() {
                if count < 2000 {
                    continue;
                }
                let (a, s) = table[i];
                let (ea, es) = (diffuse / f64::from(count), highlight / f64::from(count));
                assert!(
                    (f64::from(a[0]) - ea).abs() < 0.01 && (f64::from(s[0]) - es).abs() < 0.01,
                    "{binning:?}, bin {i} ({count} hits): table {} / {}, hits {ea:.4} / {es:.4}",
                    a[0],
                    s[0]
                );
            }
        }
    }

    #[test]
    fn the_highlight_grid_holds_the_highlights_of_the_full_lighting() {
        let lights = ShadeLights {
            ambient: 0.1,
            lights: vec![(Vec3::new(0.4, 0.5, 0.8), [1.0, 0.8, 0.6])],
            diffuse: 0.7,
            specular: 0.5,
            shininess: 16.0,
            environment: Some(EnvironmentMap::from_image(&RgbaImage::new(8, 4))),
            explorer: None,
            transfer: None,
        };
        // Binned in the camera's frame (files written before binning along rays): the
        // highlights only, towards each grid point's eye.
        let view = TexelView::Perspective {
            tan_half: [0.5, 0.3],
            ray_frame: false,
        };
        let (g, grid) = view_grid(4, Binning::ProjectedNormals, &lights, view).unwrap();
        for (k, corner) in [(0u32, (-1.0, 1.0)), (g * g - 1, (1.0, -1.0))] {
            let eye = view.towards_eye(corner.0, corner.1);
            let full = bin_lighting_towards(4, Binning::ProjectedNormals, &lights, eye);
            for (i, (_, s)) in full.iter().enumerate() {
                assert_eq!(grid[k as usize * 16 + i].1, *s, "grid point {k}, bin {i}");
            }
        }
        // Binned along rays: all of the lighting, of each bin's normals turned back into
        // the camera's frame. The grid's middle looks along the axis, unturned.
        let view = TexelView::Perspective {
            tan_half: [0.5, 0.3],
            ray_frame: true,
        };
        let (g, grid) = view_grid(4, Binning::ProjectedNormals, &lights, view).unwrap();
        let middle = (g * g / 2) as usize;
        let axis = bin_lighting(4, Binning::ProjectedNormals, &lights);
        assert_eq!(&grid[middle * 16..middle * 16 + 16], &axis[..]);
        let eye = view.towards_eye(-1.0, 1.0);
        let turned = bin_lighting_in(
            4,
            Binning::ProjectedNormals,
            &lights,
            eye,
            glam::Quat::from_rotation_arc(Vec3::Z, eye),
        );
        assert_eq!(&grid[..16], &turned[..]);
        assert_ne!(turned, axis);
    }

    /// Rays through a texel near the corner of a 90° view hit a sphere across the disk
    /// it shows them, so the normals they see are spread by projected solid angle about
    /// the direction towards the eye, a quarter of them facing away from the view axis.
    /// Binned along the texel's ray, the shaded texel is their mean lighting (the table
    /// averages each bin as its hits are spread); binned in the camera's frame, the
    /// normals facing away are lit as their mirror images.
    #[test]
    fn a_texel_off_the_axis_of_a_wide_view_shades_a_sphere_as_its_rays_see_it() {
        let lights = ShadeLights {
            ambient: 0.0,
            lights: vec![(Vec3::Z, [1.0; 3])],
            diffuse: 1.0,
            specular: 0.3,
            shininess: 12.0,
            environment: None,
            explorer: None,
            transfer: None,
        };
        // 4×4 texels of a 90° view: texel (0, 0)'s centre, (−0.75, 0.75), is a point of
        // the 9×9 grid, so no interpolation between view directions enters.
        let (w, h, bins) = (4u32, 4u32, 8u32);
        let along = TexelView::Perspective {
            tan_half: [1.0, 1.0],
            ray_frame: true,
        };
        let (u, v) = texel_point(0, 0, w, h);
        assert_eq!((u, v), (-0.75, 0.75));
        let eye = along.towards_eye(u, v);
        let hits = sphere_hits(5, 200_000, eye);
        let away = hits.iter().filter(|n| n.z < 0.0).count() as f64 / hits.len() as f64;
        assert!(away > 0.05, "{away}");
        // Blinn-Phong's half vector of the headlight and this texel's eye.
        let half = (Vec3::Z + eye).normalize();
        let truth = hits
            .iter()
            .map(|n| {
                let ndl = n.z.max(0.0);
                let spec = if ndl > 0.0 {
                    0.3 * n.dot(half).max(0.0).powf(12.0)
                } else {
                    0.0
                };
                f64::from(ndl + spec)
            })
            .sum::<f64>()
            / hits.len() as f64;
        let shaded = |view: TexelView| {
            let mut hist = vec![[0f32; 4]; (w * h * bins * bins) as usize];
            for &n in &hits {
                let (bx, by) = bin_of(view.bin_frame_at(0, 0, w, h) * n, bins, Binning::default());
                let b = &mut hist[(by * bins + bx) as usize];
                *b = [b[0] + 1.0, b[1] + 1.0, b[2] + 1.0, b[3] + 1.0];
            }
            let sndf = Sndf {
                width: w,
                height: h,
                bins,
                binning: Binning::default(),
                rays: hits.len() as u32,
                hist,
                gpu_time: None,
                view,
            };
            f64::from(sndf.shade_linear(&lights, [0.0; 3])[0][0])
        };
        let camera_frame = TexelView::Perspective {
            tan_half: [1.0, 1.0],
            ray_frame: false,
        };
        let (new, old) = (shaded(along), shaded(camera_frame));
        assert!(
            (new - truth).abs() < 0.004 && (old - truth).abs() > 5.0 * (new - truth).abs(),
            "mean lighting {truth:.4}: binned along the ray {new:.4}, in the camera's frame \
             {old:.4} ({:.0} % of the normals face away from the axis)",
            away * 100.0
        );
    }

    #[test]
    fn coarse_levels_past_u32_rays_and_one_texel_shade_like_the_last_one() {
        // The same S-NDFs twice, at 2^30 and at 2^26 rays (the sums scaled alike: powers
        // of two, so exactly).
        let scaled = |rays: u32, factor: f32| {
            let mut s = random_sndf(6, 5, 2, rays);
            s.hist.iter_mut().flatten().for_each(|v| *v *= factor);
            s
        };
        let s = scaled(1 << 30, (1 << 28) as f32);
        assert_eq!(s.coarsest_level(), 3);
        let lights = ShadeLights::from(&Lighting::default());
        let bg = [0.1, 0.2, 0.3];
        // 2^30 rays times 4 passes u32: the sums are quartered instead.
        let (one, two) = (s.downsample(), s.downsample().downsample());
        assert_eq!((one.rays, two.rays), (1 << 30, 1 << 30));
        let expected = scaled(1 << 26, (1 << 24) as f32).downsample().downsample();
        assert_eq!(expected.rays, 1 << 30);
        let image = two.shade_with(&lights, bg);
        assert!(image == expected.shade_with(&lights, bg));
        assert!(
            image.data.chunks(4).any(|p| p != &image.data[..4]),
            "a uniform image"
        );
        // Zooming out past the one-texel level (any factor) shades that texel.
        let last = s.shade_zoomed(&lights, bg, 8.0);
        for zoom in [1e6, 1e30, f32::MAX] {
            assert!(s.shade_zoomed(&lights, bg, zoom) == last, "zoom {zoom}");
        }
    }

    #[test]
    fn downsampling_an_odd_edge_averages_the_children_there_are() {
        // 5 × 3 texels: the coarse level's last column has one column of children, its
        // last row one row, its corner one child; each holds its children's average.
        let s = random_sndf(5, 3, 2, 64);
        let d = s.downsample();
        assert_eq!((d.width, d.height, d.rays), (3, 2, 256));
        for (x, y, children) in [
            (2u32, 0u32, vec![(4u32, 0u32), (4, 1)]),
            (0, 1, vec![(0, 2), (1, 2)]),
            (2, 1, vec![(4, 2)]),
        ] {
            let scale = 4.0 / children.len() as f32;
            for b in 0..4 {
                for k in 0..4 {
                    let sum: f32 = children.iter().map(|&(cx, cy)| s.texel(cx, cy)[b][k]).sum();
                    let want = sum * scale;
                    let got = d.texel(x, y)[b][k];
                    assert!(
                        (got - want).abs() <= 1e-5 * want.abs(),
                        "({x}, {y}): {got} {want}"
                    );
                }
            }
        }
        // An image of one S-NDF throughout stays one at every level, edges included.
        let mut uniform = random_sndf(5, 3, 2, 64);
        let first: Vec<[f32; 4]> = uniform.texel(0, 0).to_vec();
        for t in uniform.hist.chunks_mut(4) {
            t.copy_from_slice(&first);
        }
        let lights = ShadeLights::from(&Lighting::default());
        let mut level = uniform;
        for _ in 0..3 {
            level = level.downsample();
            let shaded = level.shade_with(&lights, [1.0; 3]);
            assert!(
                shaded.data.chunks(4).all(|p| p == &shaded.data[..4]),
                "{}×{}",
                level.width,
                level.height
            );
        }
    }

    #[test]
    fn downsampling_sums_the_two_by_two_children_exactly() {
        let s = random_sndf(6, 4, 4, 64);
        let d = s.downsample();
        assert_eq!((d.width, d.height, d.rays), (3, 2, 256));
        for y in 0..2 {
            for x in 0..3 {
                for b in 0..16 {
                    for k in 0..4 {
                        let sum = s.texel(2 * x, 2 * y)[b][k]
                            + s.texel(2 * x + 1, 2 * y)[b][k]
                            + s.texel(2 * x, 2 * y + 1)[b][k]
                            + s.texel(2 * x + 1, 2 * y + 1)[b][k];
                        assert_eq!(d.texel(x, y)[b][k], sum);
                    }
                }
            }
        }
        // So a coarse texel's linear colour is the average of its children's.
        let lights = ShadeLights::from(&Lighting::default());
        let (fine, coarse) = (
            s.shade_linear(&lights, [0.3; 3]),
            d.shade_linear(&lights, [0.3; 3]),
        );
        for y in 0..2usize {
            for x in 0..3usize {
                for k in 0..3 {
                    let avg = (fine[2 * y * 6 + 2 * x][k]
                        + fine[2 * y * 6 + 2 * x + 1][k]
                        + fine[(2 * y + 1) * 6 + 2 * x][k]
                        + fine[(2 * y + 1) * 6 + 2 * x + 1][k])
                        / 4.0;
                    assert!((coarse[y * 3 + x][k] - avg).abs() < 1e-5);
                }
            }
        }
    }

    #[test]
    fn binnings_invert_and_bin_the_hemisphere() {
        for binning in [
            Binning::ProjectedNormals,
            Binning::Spherical,
            Binning::LambertEqualArea,
        ] {
            for j in 0..20 {
                for i in 0..20 {
                    let (u, v) = ((i as f32 + 0.5) / 20.0, (j as f32 + 0.5) / 20.0);
                    let Some(n) = binning.normal(u, v) else {
                        continue;
                    };
                    assert!((n.length() - 1.0).abs() < 1e-4, "{binning:?}");
                    assert!(n.z >= -1e-6, "{binning:?}: faces away");
                    let (a, b) = binning.coords(n);
                    // Spherical coordinates are singular at the pole.
                    if binning != Binning::Spherical || v > 0.05 {
                        assert!((a - u).abs() < 1e-3 && (b - v).abs() < 1e-3, "{binning:?}");
                    }
                    assert_eq!(Binning::from_name(binning.name()), Some(binning));
                }
            }
        }
        // Equal area: the Lambert cells inside the disk hold equal solid angles, so a
        // uniform hemisphere fills them evenly (checked on the central cells).
        let b = Binning::LambertEqualArea;
        let mut counts = [0u32; 4];
        let n = 400;
        for j in 0..n {
            for i in 0..n {
                // Uniform on the hemisphere: z uniform in [0, 1], azimuth uniform.
                let z = (j as f32 + 0.5) / n as f32;
                let phi = (i as f32 + 0.5) / n as f32 * std::f32::consts::TAU;
                let r = (1.0 - z * z).sqrt();
                let (bx, by) = bin_of(Vec3::new(r * phi.cos(), r * phi.sin(), z), 4, b);
                if (1..3).contains(&bx) && (1..3).contains(&by) {
                    counts[((by - 1) * 2 + bx - 1) as usize] += 1;
                }
            }
        }
        let mean = counts.iter().sum::<u32>() as f32 / 4.0;
        assert!(
            counts
                .iter()
                .all(|&c| (c as f32 - mean).abs() < 0.01 * mean),
            "{counts:?}"
        );
    }

    #[test]
    fn a_painted_transfer_image_colours_each_bin_by_its_normals() {
        // Four quadrants: the disk's upper left red, upper right green, lower left blue,
        // lower right white.
        let image = RgbaImage {
            width: 2,
            height: 2,
            data: vec![
                255, 0, 0, 255, 0, 255, 0, 255, //
                0, 0, 255, 255, 255, 255, 255, 255,
            ],
        };
        let t = TransferImage::from_image(&image);
        assert_eq!(t.colour(Vec3::new(-0.5, 0.5, 0.7)), [1.0, 0.0, 0.0]);
        assert_eq!(t.colour(Vec3::new(0.5, 0.5, 0.7)), [0.0, 1.0, 0.0]);
        assert_eq!(t.colour(Vec3::new(-0.5, -0.5, 0.7)), [0.0, 0.0, 1.0]);
        assert_eq!(t.colour(Vec3::new(0.9, -0.1, 0.4)), [1.0, 1.0, 1.0]);
        let lights = ShadeLights {
            ambient: 0.3,
            lights: vec![(Vec3::Z, [1.0; 3])],
            diffuse: 0.7,
            specular: 0.5,
            shininess: 8.0,
            environment: None,
            explorer: None,
            transfer: Some(t.clone()),
        };
        // 8×8 bins never straddle a quadrant border: every bin on the disk carries its
        // quadrant's colour, in place of the lighting and the albedo.
        let bins = 8;
        let table = bin_lighting(bins, Binning::ProjectedNormals, &lights);
        let mut seen = std::collections::HashSet::new();
        for by in 0..bins {
            for bx in 0..bins {
                let u = (bx as f32 + 0.5) / bins as f32;
                let v = (by as f32 + 0.5) / bins as f32;
                let Some(n) = Binning::ProjectedNormals.normal(u, v) else {
                    continue;
                };
                let (a, s) = table[(by * bins + bx) as usize];
                assert_eq!(a, [0.0; 3]);
                assert_eq!(s, t.colour(n), "bin ({bx}, {by})");
                seen.insert(s.map(|c| c as u8));
            }
        }
        assert_eq!(seen.len(), 4);
    }

    /// The tabulated irradiance is the sum over the environment's samples it stands for,
    /// to a fraction of a per cent, for normals anywhere (the poles and the azimuth's
    /// seam included), under an environment with a small bright lamp and a gradient.
    #[test]
    fn tabulated_irradiance_matches_the_sum_over_the_environment() {
        let mut image = RgbaImage::new(32, 16);
        for y in 0..16 {
            for x in 0..32 {
                let lamp = (5..8).contains(&x) && (3..5).contains(&y);
                let g = (x * 8) as u8;
                image.set_pixel(
                    x,
                    y,
                    if lamp {
                        [255; 4]
                    } else {
                        [g, 40, 255 - g, 255]
                    },
                );
            }
        }
        let env = EnvironmentMap::from_image(&image);
        let (samples, table) = (env.samples(), env.irradiance());
        let direct = |n: Vec3| {
            samples.iter().fold([0f32; 3], |acc, (d, omega, r)| {
                let c = n.dot(*d).max(0.0) * omega / std::f32::consts::PI;
                [0, 1, 2].map(|k| acc[k] + c * r[k])
            })
        };
        let mut unit = uniform(3);
        let mut next = move || unit() * 2.0 - 1.0;
        let normals = [
            Vec3::Y,
            -Vec3::Y,
            -Vec3::Z,
            Vec3::new(-1e-3, 0.2, -1.0).normalize(),
        ]
        .into_iter()
        .chain(std::iter::from_fn(|| {
            Some(Vec3::new(next(), next(), next()).normalize_or(Vec3::X))
        }))
        .take(3000);
        let (mut worst, mut brightest) = (0f32, 0f32);
        for n in normals {
            let (want, got) = (direct(n), table.at(n));
            for k in 0..3 {
                worst = worst.max((want[k] - got[k]).abs());
                brightest = brightest.max(want[k]);
            }
        }
        assert!(
            worst < 0.005 * brightest,
            "largest difference {worst} against irradiance up to {brightest}"
        );
    }

    #[test]
    fn a_uniform_environment_lights_every_normal_alike_and_the_explorer_colours_by_direction() {
        // Lambert irradiance of a constant environment L is L for every normal.
        let env = EnvironmentMap {
            width: 64,
            height: 32,
            radiance: vec![[0.5, 0.25, 1.0]; 64 * 32],
        };
        let lights = ShadeLights {
            ambient: 0.0,
            lights: vec![],
            diffuse: 0.8,
            specular: 0.0,
            shininess: 1.0,
            environment: Some(env),
            explorer: None,
            transfer: None,
        };
        for binning in [Binning::ProjectedNormals, Binning::LambertEqualArea] {
            for (a, s) in bin_lighting(8, binning, &lights) {
                for (k, want) in [0.4f32, 0.2, 0.8].iter().enumerate() {
                    assert!((a[k] - want).abs() < 0.02 * want, "{binning:?}: {a:?}");
                }
                assert_eq!(s, [0.0; 3]);
            }
        }
        // The explorer: the central disk, the slices, dark borders.
        let explorer = Explorer {
            disk_deg: 20.0,
            slices: 4,
            tolerance_deg: 5.0,
            disk_colour: [1.0, 1.0, 1.0],
            slice_colours: vec![
                [1.0, 0.0, 0.0],
                [0.0, 1.0, 0.0],
                [0.0, 0.0, 1.0],
                [1.0, 1.0, 0.0],
            ],
        };
        let at = |from_axis: f32, azimuth: f32| {
            let (t, p) = (from_axis.to_radians(), azimuth.to_radians());
            explorer.colour(Vec3::new(t.sin() * p.cos(), t.sin() * p.sin(), t.cos()))
        };
        assert_eq!(at(10.0, 123.0), [1.0, 1.0, 1.0]);
        assert_eq!(at(60.0, 0.0), [1.0, 0.0, 0.0]);
        assert_eq!(at(60.0, 90.0), [0.0, 1.0, 0.0]);
        assert_eq!(at(60.0, 270.0), [1.0, 1.0, 0.0]);
        assert!(at(60.0, 45.0).iter().all(|&v| v < 0.05), "a border is dark");
        // In the shading table the pattern replaces both the lighting and the albedos:
        // the central bins (normals near the view axis) carry the disk's colour per sample.
        let lights = ShadeLights {
            environment: None,
            explorer: Some(explorer),
            transfer: None,
            ..lights
        };
        let table = bin_lighting(8, Binning::ProjectedNormals, &lights);
        for (b, (a, s)) in table.iter().enumerate() {
            assert_eq!(*a, [0.0; 3]);
            if [27, 28, 35, 36].contains(&b) {
                // (Their corners reach 20.7° from the axis, just past the disk.)
                assert!(s.iter().all(|&v| v > 0.99), "bin {b}: {s:?}");
            }
        }
    }

    #[test]
    fn zooming_out_is_trilinear_between_levels() {
        let s = random_sndf(16, 16, 4, 64);
        let lights = ShadeLights::from(&Lighting::default());
        let bg = [0.2; 3];
        // At a power of two it is that level exactly.
        for level in 0..3u32 {
            let mut l = s.clone();
            for _ in 0..level {
                l = l.downsample();
            }
            assert_eq!(
                s.shade_zoomed(&lights, bg, (1u32 << level) as f32),
                l.shade_with(&lights, bg),
                "level {level}"
            );
        }
        // Between levels the colour lies between the two levels' (per pixel, in the
        // blend of their bilinear samples): at 2^1.5 it is the 50/50 mix.
        let mid = s.shade_zoomed(&lights, bg, 2f32.powf(1.5));
        let (lo, hi) = (
            s.shade_zoomed(&lights, bg, 2.0),
            s.shade_zoomed(&lights, bg, 4.0),
        );
        assert_eq!((mid.width, mid.height), (6, 6));
        let mean =
            |i: &RgbaImage| i.data.iter().map(|&v| f64::from(v)).sum::<f64>() / i.data.len() as f64;
        let (m, a, b) = (mean(&mid), mean(&lo), mean(&hi));
        assert!(
            m >= a.min(b) - 1.0 && m <= a.max(b) + 1.0,
            "{m} not between {a} and {b}"
        );
        // Pixel by pixel at 2^1.25: a quarter of the way from level 1 to level 2, each
        // level sampled bilinearly at the pixel's centre (texel centres at +0.5, clamped
        // at the edges), the linear colours mixed 3:1.
        let zoom = 2f32.powf(1.25);
        let image = s.shade_zoomed(&lights, bg, zoom);
        let levels = [s.downsample(), s.downsample().downsample()];
        let linear = levels
            .each_ref()
            .map(|l| (l.width, l.shade_linear(&lights, bg)));
        let sample = |(w, img): &(u32, Vec<[f32; 3]>), x: f32, y: f32| -> [f32; 3] {
            let h = img.len() as u32 / w;
            let (x, y) = (
                (x - 0.5).clamp(0.0, (w - 1) as f32),
                (y - 0.5).clamp(0.0, (h - 1) as f32),
            );
            let (x0, y0) = (x.floor() as u32, y.floor() as u32);
            let (x1, y1) = ((x0 + 1).min(w - 1), (y0 + 1).min(h - 1));
            let (fx, fy) = (x - x0 as f32, y - y0 as f32);
            let at = |x: u32, y: u32| img[(y * w + x) as usize];
            [0, 1, 2].map(|k| {
                (at(x0, y0)[k] * (1.0 - fx) + at(x1, y0)[k] * fx) * (1.0 - fy)
                    + (at(x0, y1)[k] * (1.0 - fx) + at(x1, y1)[k] * fx) * fy
            })
        };
        for y in 0..image.height {
            for x in 0..image.width {
                let (px, py) = ((x as f32 + 0.5) * zoom, (y as f32 + 0.5) * zoom);
                let a = sample(&linear[0], px / 2.0, py / 2.0);
                let b = sample(&linear[1], px / 4.0, py / 4.0);
                let want = [0, 1, 2].map(|k| {
                    let v = (0.75 * a[k] + 0.25 * b[k]).clamp(0.0, 1.0);
                    (linear_to_srgb(v) * 255.0 + 0.5) as u8
                });
                let got = image.pixel(x, y);
                for k in 0..3 {
                    assert!(
                        got[k].abs_diff(want[k]) <= 1,
                        "pixel ({x}, {y}): {got:?} against {want:?}"
                    );
                }
            }
        }
    }

    #[test]
    fn file_form_round_trips() {
        // 64 bins of counts up to 2: 128 rays, so that a texel's counts stay within them.
        let s = random_sndf(5, 3, 8, 128);
        let s = Sndf {
            hist: s
                .hist
                .iter()
                .map(|b| [b[0].min(b[3]), b[1].min(b[3]), b[2].min(b[3]), b[3]])
                .collect(),
            ..s
        };
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("s.sndf");
        s.to_data(serde_json::json!({"zoom": 1.0}), None)
            .save(&p)
            .unwrap();
        let back = Sndf::from_data(&mdlod_format::sndf::SndfData::load(&p).unwrap());
        assert_eq!(back, s);
    }
}
