//! The density passes (`density.wgsl`, `density_composite.wgsl`): kernel splatting into
//! a stack of slices, and ray casting through each stack. See [`crate::density`] for the
//! method and its CPU twin.

use bytemuck::{Pod, Zeroable};

/// WGSL of the splatting pass: `points.wgsl`, `density_common.wgsl`, `density.wgsl`.
pub const SHADER: &str = concat!(
    include_str!("points.wgsl"),
    "\n",
    include_str!("density_common.wgsl"),
    "\n",
    include_str!("density.wgsl")
);

/// WGSL of the ray-casting pass: `density_common.wgsl` followed by
/// `density_composite.wgsl`.
pub const COMPOSITE_SHADER: &str = concat!(
    include_str!("density_common.wgsl"),
    "\n",
    include_str!("density_composite.wgsl")
);

/// The slice targets: additive blending of f32 needs `FLOAT32_BLENDABLE`.
pub const SLICE_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba32Float;

/// Slices per stack: 8 densities, 2 densities with gradients (iso-surfaces), or 4
/// densities with their sums of the attribute's place (a volume coloured by it).
pub const SLICES_PLAIN: u32 = 8;
pub const SLICES_GRADIENT: u32 = 2;
pub const SLICES_VALUED: u32 = 4;

/// Entries of the colour map's table the volume coloured by the attribute looks its
/// colours up in (linear RGB, interpolated between entries).
pub const COLOUR_TABLE: usize = 256;

/// The colour map's table for the composite pass (`lut` in `density_composite.wgsl`):
/// `COLOUR_TABLE` linear colours evenly over [0, 1]; black without a map.
pub fn colour_table(map: Option<crate::style::ColourMap>) -> Vec<[f32; 4]> {
    (0..COLOUR_TABLE)
        .map(|i| {
            let t = i as f32 / (COLOUR_TABLE - 1) as f32;
            let c = map.map_or([0.0; 3], |m| m.colour(t));
            [c[0], c[1], c[2], 1.0]
        })
        .collect()
}

/// `Density` in `density_common.wgsl`: one stack's slicing (256 bytes, a dynamic-offset
/// stride).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct DensityGpu {
    /// The camera's basis in world space, columns right, up, back and eye; the w of
    /// right and up are the view's half-extents at unit depth (perspective) or in world
    /// units (orthographic), 1 / clip_from_view's x and y scales, the eye's is 1 for
    /// orthographic views (`density::ray_basis`). Rays built from these
    /// keep their digits at any distance, where an inverse of clip_from_world does not
    /// (its depth row nearly cancels once the near plane is 10⁻⁵ of the far one).
    pub basis: [[f32; 4]; 4],
    pub slicing: [f32; 4],
    pub mode: [f32; 4],
    pub size: [f32; 4],
    pub clip: [f32; 4],
    pub flags: [u32; 4],
    pub albedo: [f32; 4],
    pub pad: [[f32; 4]; 6],
}

// The dynamic-offset stride of the uniform buffer.
const _: () = assert!(std::mem::size_of::<DensityGpu>() == 256);

/// `Ray` in the composite WGSL: per-pixel state between stacks.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct RayGpu {
    pub colour: [f32; 4],
    pub prev: [f32; 4],
    pub state: [f32; 4],
}

/// The pipelines and the layouts of their own bindings.
pub struct DensityPass {
    pub splat: wgpu::RenderPipeline,
    /// The iso-surface's colour pass: albedos weighted at the hits, summed.
    pub colour: wgpu::RenderPipeline,
    pub slicing_layout: wgpu::BindGroupLayout,
    /// Group 2 of the colour pass: the rays' states, read-only.
    pub hits_layout: wgpu::BindGroupLayout,
    pub composite: wgpu::ComputePipeline,
    pub composite_layout: wgpu::BindGroupLayout,
}

impl DensityPass {
    /// The passes; `points_layout` is the sphere pass's bind group layout (the packed
    /// cut). `None` when the device cannot blend 32-bit floats.
    pub fn new(device: &wgpu::Device, points_layout: &wgpu::BindGroupLayout) -> Option<Self> {
        if !device
            .features()
            .contains(wgpu::Features::FLOAT32_BLENDABLE)
        {
            return None;
        }
        let uniform = |binding, visibility, dynamic: bool| wgpu::BindGroupLayoutEntry {
            binding,
            visibility,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Storage { read_only: true },
                has_dynamic_offset: dynamic,
                min_binding_size: None,
            },
            count: None,
        };
        let slicing_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("density slicing"),
            entries: &[uniform(
                0,
                wgpu::ShaderStages::VERTEX | wgpu::ShaderStages::FRAGMENT,
                true,
            )],
        });
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("density.wgsl"),
            source: wgpu::ShaderSource::Wgsl(SHADER.into()),
        });
        let target = Some(wgpu::ColorTargetState {
            format: SLICE_FORMAT,
            blend: Some(wgpu::BlendState {
                color: super::ADD,
                alpha: super::ADD,
            }),
            write_mask: wgpu::ColorWrites::ALL,
        });
        // Both passes draw every point's support box (`vs_splat`) into additively
        // blended float targets.
        let pipeline = |label: &str,
                        groups: &[Option<&wgpu::BindGroupLayout>],
                        fragment: &str,
                        targets: &[Option<wgpu::ColorTargetState>]| {
            let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some(label),
                bind_group_layouts: groups,
                immediate_size: 0,
            });
            super::quad_pipeline(
                device,
                label,
                &layout,
                &module,
                ("vs_splat", fragment),
                targets,
            )
        };
        let splat = pipeline(
            "density splat",
            &[Some(points_layout), Some(&slicing_layout)],
            "fs_splat",
            &[target.clone(), target.clone()],
        );
        let hits_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("density hits"),
            entries: &[wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::FRAGMENT,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Storage { read_only: true },
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                count: None,
            }],
        });
        let colour = pipeline(
            "density colour",
            &[
                Some(points_layout),
                Some(&slicing_layout),
                Some(&hits_layout),
            ],
            "fs_colour",
            &[target],
        );
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
        let storage = |binding, read_only| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Storage { read_only },
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        };
        let composite_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("density composite"),
            entries: &[
                uniform(0, wgpu::ShaderStages::COMPUTE, true),
                texture(1),
                texture(2),
                storage(3, false),
                storage(4, false),
                storage(5, true),
            ],
        });
        let cmodule = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("density_composite.wgsl"),
            source: wgpu::ShaderSource::Wgsl(COMPOSITE_SHADER.into()),
        });
        let clayout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("density composite"),
            bind_group_layouts: &[Some(&composite_layout)],
            immediate_size: 0,
        });
        let composite = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("density composite"),
            layout: Some(&clayout),
            module: &cmodule,
            entry_point: Some("cs_composite"),
            compilation_options: Default::default(),
            cache: None,
        });
        Some(DensityPass {
            splat,
            colour,
            slicing_layout,
            hits_layout,
            composite,
            composite_layout,
        })
    }
}
