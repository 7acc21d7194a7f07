//! Supersample accumulation and resolve (`accumulate.wgsl`): full-screen passes that add
//! a jittered sample image with weight 1/N to the sum so far (two single-precision
//! targets in turn: the sum is read from one and written to the other), and copy the
//! sum into the sRGB output.

/// WGSL source of the pass.
pub const SHADER: &str = include_str!("accumulate.wgsl");

/// Format of the two accumulation targets: single precision, so that a sum of many
/// equal samples does not round the same way at every step (see `accumulate.wgsl`).
pub const ACCUM_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba32Float;

/// The accumulation format an adapter can render to: [`ACCUM_FORMAT`], else half
/// precision (GL renders to no single-precision target; a sum of many samples then
/// rounds as it did before single precision).
pub fn accum_format(adapter: &wgpu::Adapter) -> wgpu::TextureFormat {
    let features = adapter.get_texture_format_features(ACCUM_FORMAT);
    if features
        .allowed_usages
        .contains(wgpu::TextureUsages::RENDER_ATTACHMENT)
    {
        ACCUM_FORMAT
    } else {
        wgpu::TextureFormat::Rgba16Float
    }
}
/// Format of the final image (sRGB encoding on store).
pub const OUTPUT_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8UnormSrgb;

/// `Params` in the WGSL.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub struct WeightUniforms {
    pub weight: [f32; 4],
}

/// Three pipelines over one layout: the first sample's weighted copy, the sum of the
/// sum so far and a weighted sample, and the plain resolve copy.
pub struct AccumulatePass {
    /// The accumulation targets' format ([`accum_format`]).
    pub format: wgpu::TextureFormat,
    pub first: wgpu::RenderPipeline,
    pub accumulate: wgpu::RenderPipeline,
    pub resolve: wgpu::RenderPipeline,
    pub layout: wgpu::BindGroupLayout,
}

impl AccumulatePass {
    pub fn new(device: &wgpu::Device, format: wgpu::TextureFormat) -> Self {
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("accumulate.wgsl"),
            source: wgpu::ShaderSource::Wgsl(SHADER.into()),
        });
        let image = |binding| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::FRAGMENT,
            ty: wgpu::BindingType::Texture {
                sample_type: wgpu::TextureSampleType::Float { filterable: false },
                view_dimension: wgpu::TextureViewDimension::D2,
                multisampled: false,
            },
            count: None,
        };
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("accumulate"),
            entries: &[
                image(0),
                wgpu::BindGroupLayoutEntry {
                    binding: 1,
                    visibility: wgpu::ShaderStages::FRAGMENT,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Storage { read_only: true },
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                    count: None,
                },
                image(2),
            ],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("accumulate"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let make = |label: &str, format: wgpu::TextureFormat, entry: &str| {
            device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some(label),
                layout: Some(&pipeline_layout),
                vertex: wgpu::VertexState {
                    module: &module,
                    entry_point: Some("vs_fullscreen"),
                    compilation_options: Default::default(),
                    buffers: &[],
                },
                primitive: Default::default(),
                depth_stencil: None,
                multisample: Default::default(),
                fragment: Some(wgpu::FragmentState {
                    module: &module,
                    entry_point: Some(entry),
                    compilation_options: Default::default(),
                    targets: &[Some(wgpu::ColorTargetState {
                        format,
                        blend: None,
                        write_mask: wgpu::ColorWrites::ALL,
                    })],
                }),
                multiview_mask: None,
                cache: None,
            })
        };
        let first = make("accumulate first", format, "fs_weighted");
        let accumulate = make("accumulate", format, "fs_sum");
        let resolve = make("resolve", OUTPUT_FORMAT, "fs_weighted");
        AccumulatePass {
            format,
            first,
            accumulate,
            resolve,
            layout,
        }
    }

    /// A bind group reading `src` with `weight` and the sum so far from `sum` (which
    /// the pass bound to it must not write; the first and resolve passes ignore it).
    pub fn bind(
        &self,
        device: &wgpu::Device,
        src: &wgpu::TextureView,
        weight: f32,
        sum: &wgpu::TextureView,
    ) -> wgpu::BindGroup {
        use wgpu::util::DeviceExt;
        let params = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("accumulate weight"),
            contents: bytemuck::bytes_of(&WeightUniforms {
                weight: [weight, 0.0, 0.0, 0.0],
            }),
            usage: wgpu::BufferUsages::STORAGE,
        });
        device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("accumulate"),
            layout: &self.layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: wgpu::BindingResource::TextureView(src),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: params.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: wgpu::BindingResource::TextureView(sum),
                },
            ],
        })
    }
}
