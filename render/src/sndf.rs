//! Screen-space normal distribution functions (S-NDFs, Ibrahim et al. 2017): sample the
//! particles once, shade and re-light as often as wanted without them.
//!
//! How it works.
//! 1. Sampling: each iteration draws the cut's spheres into a G-buffer (the nearest
//!    hit's view-space normal and the particle's albedo) with one jittered ray per texel
//!    (the same Halton sub-pixel pattern as supersampling), then a compute pass
//!    (`sndf_accumulate.wgsl`) adds the sample to the texel's histogram over the
//!    projected normal disk: `bins × bins` cells of `(n.x, n.y)` in `[−1, 1]²`
//!    ("projected normals"). A bin keeps the sum of the albedos that fell into it and
//!    their count, so per-particle colours shade exactly; rays that hit nothing add
//!    nothing, and `1 − Σ counts / rays` is the texel's background share.
//! 2. Shading ([`Sndf::shade`]) needs no particle: per bin, the lighting averaged over
//!    the bin's part of the normal disk (the discrete form of Eq. 12-14), split into the
//!    part that multiplies the albedo (ambient + Lambert) and the part that does not
//!    (Blinn-Phong highlight); a texel's colour is the bins' colour sums and counts
//!    weighted by those, over the rays, plus the background's share.
//!
//! What is not here yet: the virtual S-MIP (tiles, levels, a tile pool), the binnings
//! other than projected normals, environment maps and the `.sndf` file.

use bytemuck::{Pod, Zeroable};
use glam::Vec3;

use crate::image::RgbaImage;
use crate::passes::sphere_raycast::Lighting;
use crate::renderer::{linear_to_srgb, srgb_to_linear};

/// WGSL source of the accumulation pass.
pub const ACCUMULATE_SHADER: &str = include_str!("passes/sndf_accumulate.wgsl");

/// `Params` in the WGSL.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct AccumulateParams {
    pub width: u32,
    pub height: u32,
    pub bins: u32,
    pub pad: u32,
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
                view_dimension: wgpu::TextureViewDimension::D2,
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
                        ty: wgpu::BufferBindingType::Uniform,
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
    /// Bins per axis of the projected normal disk (8 by default).
    pub bins: u32,
}

/// The sampled S-NDFs of one view: per texel (rows top to bottom), `bins × bins` bins
/// (row `by`, column `bx` of the projected normal disk, `n.y` and `n.x` increasing), each
/// the albedo sum (rgb) and count (a) of the samples that fell into it.
#[derive(Clone, Debug, PartialEq)]
pub struct Sndf {
    pub width: u32,
    pub height: u32,
    pub bins: u32,
    /// Rays per texel (iterations).
    pub rays: u32,
    pub hist: Vec<[f32; 4]>,
}

/// The bin of a projected normal `(x, y)`, as the WGSL computes it.
pub fn bin_of(x: f32, y: f32, bins: u32) -> (u32, u32) {
    let b = bins as f32;
    let idx = |v: f32| (((v + 1.0) * 0.5).clamp(0.0, 1.0) * b).min(b - 1.0) as u32;
    (idx(x), idx(y))
}

/// Per bin (row-major, `by * bins + bx`), the lighting averaged over the bin's part of
/// the normal disk, as (albedo factor: ambient + diffuse · max(n·l, 0); highlight:
/// specular · Blinn-Phong), for the view direction +z. Bins outside the disk get the
/// values at the nearest disk edge.
pub fn bin_lighting(bins: u32, lighting: &Lighting) -> Vec<(f32, f32)> {
    const SUB: u32 = 16;
    let l = lighting.direction_view.normalize_or(Vec3::Z);
    let h = (l + Vec3::Z).normalize_or(Vec3::Z);
    let shade = |x: f32, y: f32| {
        let r2 = x * x + y * y;
        let (x, y, r2) = if r2 > 1.0 {
            let r = r2.sqrt() * 1.0001;
            (x / r, y / r, r2 / (r * r))
        } else {
            (x, y, r2)
        };
        let n = Vec3::new(x, y, (1.0 - r2).max(0.0).sqrt());
        let ndl = n.dot(l).max(0.0);
        let spec = if ndl > 0.0 {
            n.dot(h).max(0.0).powf(lighting.shininess)
        } else {
            0.0
        };
        (
            lighting.ambient + lighting.diffuse * ndl,
            lighting.specular * spec,
        )
    };
    let cell = 2.0 / bins as f32;
    let mut out = Vec::with_capacity((bins * bins) as usize);
    for by in 0..bins {
        for bx in 0..bins {
            let (mut a, mut s, mut n) = (0.0, 0.0, 0u32);
            let mut fallback = (0.0, 0.0);
            for j in 0..SUB {
                for i in 0..SUB {
                    let x = -1.0 + cell * (bx as f32 + (i as f32 + 0.5) / SUB as f32);
                    let y = -1.0 + cell * (by as f32 + (j as f32 + 0.5) / SUB as f32);
                    let v = shade(x, y);
                    if x * x + y * y <= 1.0 {
                        a += v.0;
                        s += v.1;
                        n += 1;
                    } else {
                        fallback = v;
                    }
                }
            }
            out.push(if n > 0 {
                (a / n as f32, s / n as f32)
            } else {
                fallback
            });
        }
    }
    out
}

impl Sndf {
    /// The bins of texel `(x, y)`.
    pub fn texel(&self, x: u32, y: u32) -> &[[f32; 4]] {
        let b2 = (self.bins * self.bins) as usize;
        let i = (y * self.width + x) as usize * b2;
        &self.hist[i..i + b2]
    }

    /// Shades every texel under `lighting` over `background_srgb`, from the S-NDFs alone.
    pub fn shade(&self, lighting: &Lighting, background_srgb: [f32; 3]) -> RgbaImage {
        let table = bin_lighting(self.bins, lighting);
        let bg = background_srgb.map(srgb_to_linear);
        let rays = self.rays.max(1) as f32;
        let mut image = RgbaImage::new(self.width, self.height);
        for y in 0..self.height {
            for x in 0..self.width {
                let mut c = [0f32; 3];
                let mut hits = 0.0;
                for (bin, &(a, s)) in self.texel(x, y).iter().zip(&table) {
                    for k in 0..3 {
                        c[k] += bin[k] * a + bin[3] * s;
                    }
                    hits += bin[3];
                }
                let miss = (1.0 - hits / rays).max(0.0);
                let px: [u8; 4] = [0, 1, 2, 3].map(|k| {
                    if k == 3 {
                        return 255;
                    }
                    let v = c[k] / rays + miss * bg[k];
                    (linear_to_srgb(v.clamp(0.0, 1.0)) * 255.0 + 0.5) as u8
                });
                image.set_pixel(x, y, px);
            }
        }
        image
    }
}
