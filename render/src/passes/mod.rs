//! GPU passes, each a Rust file beside its WGSL file. The `#[repr(C)]` structs that the
//! shaders read are defined next to the pipeline that binds them.

pub mod accumulate;
pub mod density;
pub mod sphere_raycast;
pub mod splat;

/// Every WGSL source of the crate, by file name (validated with naga in the tests).
pub const SHADERS: &[(&str, &str)] = &[
    ("sphere_raycast.wgsl", sphere_raycast::SHADER),
    ("accumulate.wgsl", accumulate::SHADER),
    ("splat.wgsl", splat::SHADER),
    ("density.wgsl", density::SHADER),
    ("density_composite.wgsl", density::COMPOSITE_SHADER),
    ("sndf_accumulate.wgsl", crate::sndf::ACCUMULATE_SHADER),
    ("sndf_shade.wgsl", crate::sndf::SHADE_SHADER),
    ("smip_downsample.wgsl", crate::smip::DOWNSAMPLE_SHADER),
    ("smip_composite.wgsl", crate::smip::COMPOSITE_SHADER),
];

/// Additive blending (`src + dst`), for sums of float targets.
pub(crate) const ADD: wgpu::BlendComponent = wgpu::BlendComponent {
    src_factor: wgpu::BlendFactor::One,
    dst_factor: wgpu::BlendFactor::One,
    operation: wgpu::BlendOperation::Add,
};

/// A pipeline that draws a 4-vertex triangle strip per instance (a point's screen quad)
/// with no vertex buffers and no depth: the splat and density passes.
pub(crate) fn quad_pipeline(
    device: &wgpu::Device,
    label: &str,
    layout: &wgpu::PipelineLayout,
    module: &wgpu::ShaderModule,
    entries: (&str, &str),
    targets: &[Option<wgpu::ColorTargetState>],
) -> wgpu::RenderPipeline {
    strip_pipeline(device, label, layout, module, entries, targets, None)
}

/// A pipeline that draws triangle strips with no vertex buffers, from `(vertex,
/// fragment)` of `module`, with the depth state `depth` when given.
pub(crate) fn strip_pipeline(
    device: &wgpu::Device,
    label: &str,
    layout: &wgpu::PipelineLayout,
    module: &wgpu::ShaderModule,
    (vertex, fragment): (&str, &str),
    targets: &[Option<wgpu::ColorTargetState>],
    depth: Option<wgpu::DepthStencilState>,
) -> wgpu::RenderPipeline {
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some(label),
        layout: Some(layout),
        vertex: wgpu::VertexState {
            module,
            entry_point: Some(vertex),
            compilation_options: Default::default(),
            buffers: &[],
        },
        fragment: Some(wgpu::FragmentState {
            module,
            entry_point: Some(fragment),
            compilation_options: Default::default(),
            targets,
        }),
        primitive: wgpu::PrimitiveState {
            topology: wgpu::PrimitiveTopology::TriangleStrip,
            ..Default::default()
        },
        depth_stencil: depth,
        multisample: Default::default(),
        multiview_mask: None,
        cache: None,
    })
}

#[cfg(test)]
mod tests {
    /// No shader reads a uniform buffer: with parameters in uniform buffers, Mesa's
    /// software Vulkan driver compiled shader code every frame and kept it (about a
    /// megabyte a frame; `tests/memory.rs`). Parameters are read-only storage.
    #[test]
    fn no_shader_reads_a_uniform_buffer() {
        let all = super::SHADERS
            .iter()
            .map(|(name, src)| (*name, src.to_string()))
            .chain([
                (
                    "small_spheres.wgsl",
                    super::sphere_raycast::SMALL_SPHERES_SHADER.to_string(),
                ),
                (
                    "sphere_raycast.wgsl, conservative depth",
                    super::sphere_raycast::shader_source(true),
                ),
            ]);
        for (name, src) in all {
            assert!(
                !src.contains("var<uniform>"),
                "{name} reads a uniform buffer"
            );
        }
    }

    #[test]
    fn every_shader_validates_with_naga() {
        for (name, src) in super::SHADERS {
            let module = naga::front::wgsl::parse_str(src)
                .unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(src)));
            naga::valid::Validator::new(
                naga::valid::ValidationFlags::all(),
                naga::valid::Capabilities::empty(),
            )
            .validate(&module)
            .unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(src)));
        }
        // The small-sphere raster, with the 64-bit atomics it needs.
        let src = super::sphere_raycast::SMALL_SPHERES_SHADER;
        let module = naga::front::wgsl::parse_str(src)
            .unwrap_or_else(|e| panic!("small_spheres.wgsl: {}", e.emit_to_string(src)));
        naga::valid::Validator::new(
            naga::valid::ValidationFlags::all(),
            naga::valid::Capabilities::SHADER_INT64
                | naga::valid::Capabilities::SHADER_INT64_ATOMIC_MIN_MAX,
        )
        .validate(&module)
        .unwrap_or_else(|e| panic!("small_spheres.wgsl: {}", e.emit_to_string(src)));
        // The conservative-depth variant of the sphere pass.
        let src = super::sphere_raycast::shader_source(true);
        assert_eq!(
            src.matches("@fragment @early_depth_test(less_equal)")
                .count(),
            2
        );
        let module = naga::front::wgsl::parse_str(&src)
            .unwrap_or_else(|e| panic!("{}", e.emit_to_string(&src)));
        naga::valid::Validator::new(
            naga::valid::ValidationFlags::all(),
            naga::valid::Capabilities::EARLY_DEPTH_TEST,
        )
        .validate(&module)
        .unwrap_or_else(|e| panic!("{}", e.emit_to_string(&src)));
    }
}
