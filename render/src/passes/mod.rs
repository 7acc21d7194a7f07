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

#[cfg(test)]
mod tests {
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
        // The conservative-depth variant of the sphere pass.
        let src = super::sphere_raycast::shader_source(true);
        assert_eq!(
            src.matches("@fragment @early_depth_test(greater_equal)")
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
