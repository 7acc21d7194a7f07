//! The splat pass (`splat.wgsl`): additive, flux-preserving Gaussian splats of the points
//! of a cut into a 32-bit float target, for data where particles add light (SPH,
//! astrophysics) rather than hide each other. See the WGSL for the kernel; the CPU twin
//! [`splat_weight`] is what the tests compare against.
//!
//! The pass shares the sphere pass's bind group layout, so a packed cut is bound the same
//! way; representatives are packed with `sqrt(area_sum)` as their radius so that each
//! carries exactly the flux of its particles (Eq. 1).

/// WGSL source of the pass: `points.wgsl` followed by `splat.wgsl`.
pub const SHADER: &str = concat!(
    include_str!("points.wgsl"),
    "\n",
    include_str!("splat.wgsl")
);

/// The accumulation target: additive blending of f32 needs `FLOAT32_BLENDABLE`.
pub const HDR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba32Float;

/// Kernel constants, as in the WGSL.
pub const TRUNCATION: f32 = 3.5;
pub const MIN_SIGMA_PX: f32 = 0.7;
const AXIS_MASS: f32 = 2.505_463;
const EXACT_BELOW: f32 = 32.0;

/// The Gaussian's sigma (pixels) for a point of projected radius `r_px`.
pub fn splat_sigma(r_px: f32) -> f32 {
    (0.5 * r_px).max(MIN_SIGMA_PX)
}

/// Sum over pixel centres `i + 0.5` within the truncation of the unnormalised Gaussian
/// along one axis, for a splat centred at `c` (the WGSL's `axis_sum`).
pub fn axis_sum(c: f32, sigma: f32) -> f32 {
    if sigma >= EXACT_BELOW {
        return AXIS_MASS * sigma;
    }
    let limit = TRUNCATION * sigma;
    let inv = 1.0 / (2.0 * sigma * sigma);
    let mut sum = 0.0;
    let first = (c - 0.5 - limit).ceil();
    let span = (c - 0.5 + limit).floor() - first + 1.0;
    // Counted, not stepped: past 2^24 px (a splat far off screen) x + 1 == x. An
    // infinite or NaN centre has no pixels.
    if !(span > 0.0 && span <= 2.0 * limit + 2.0) {
        return 0.0;
    }
    for k in 0..span as u32 {
        let d = first + k as f32 + 0.5 - c;
        sum += (-d * d * inv).exp();
    }
    sum
}

/// The weight a splat of sigma `sigma` centred at `(cx, cy)` (pixels) gives the pixel
/// centre at offset `(dx, dy)` from it (0 outside the truncation square); the weights
/// over the pixel grid sum to 1.
pub fn splat_weight(dx: f32, dy: f32, cx: f32, cy: f32, sigma: f32) -> f32 {
    let limit = TRUNCATION * sigma;
    if dx.abs() > limit || dy.abs() > limit {
        return 0.0;
    }
    (-(dx * dx + dy * dy) / (2.0 * sigma * sigma)).exp()
        / (axis_sum(cx, sigma) * axis_sum(cy, sigma))
}

/// The alpha a translucent splat (over-blending) gives a pixel centre at offset
/// `(dx, dy)`: `opacity · exp(−d²/2σ²)`, attenuated by the squared diameter below one
/// pixel (Eq. 3); 0 outside the truncation square.
pub fn over_alpha(dx: f32, dy: f32, r_px: f32, opacity: f32) -> f32 {
    let sigma = splat_sigma(r_px);
    let limit = TRUNCATION * sigma;
    if dx.abs() > limit || dy.abs() > limit {
        return 0.0;
    }
    let diameter = 2.0 * r_px;
    opacity * (diameter * diameter).min(1.0) * (-(dx * dx + dy * dy) / (2.0 * sigma * sigma)).exp()
}

/// The splat pipelines: additive (flux) and over (sorted, translucent).
pub struct SplatPass {
    pub pipeline: wgpu::RenderPipeline,
    pub over: wgpu::RenderPipeline,
}

impl SplatPass {
    /// The pass over `layout` (the sphere pass's bind group layout); `None` when the
    /// device cannot blend 32-bit floats.
    pub fn new(device: &wgpu::Device, layout: &wgpu::BindGroupLayout) -> Option<SplatPass> {
        if !device
            .features()
            .contains(wgpu::Features::FLOAT32_BLENDABLE)
        {
            return None;
        }
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("splat.wgsl"),
            source: wgpu::ShaderSource::Wgsl(SHADER.into()),
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("splat"),
            bind_group_layouts: &[Some(layout)],
            immediate_size: 0,
        });
        let over = wgpu::BlendComponent {
            src_factor: wgpu::BlendFactor::One,
            dst_factor: wgpu::BlendFactor::OneMinusSrcAlpha,
            operation: wgpu::BlendOperation::Add,
        };
        let make = |entry: &str, blend: wgpu::BlendComponent| {
            super::quad_pipeline(
                device,
                entry,
                &pipeline_layout,
                &module,
                ("vs_main", entry),
                &[Some(wgpu::ColorTargetState {
                    format: HDR_FORMAT,
                    blend: Some(wgpu::BlendState {
                        color: blend,
                        alpha: blend,
                    }),
                    write_mask: wgpu::ColorWrites::ALL,
                })],
            )
        };
        let pipeline = make("fs_main", super::ADD);
        let over = make("fs_over", over);
        Some(SplatPass { pipeline, over })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn splats_far_off_screen_end_their_sums() {
        // Past 2^24 px a step of one pixel no longer changes a float: the sum is counted.
        for c in [16_777_216.0, 33_554_432.5, 1e30, f32::INFINITY, f32::NAN] {
            for sigma in [MIN_SIGMA_PX, 3.0, 31.0] {
                let s = axis_sum(c, sigma);
                assert!(s.is_finite() && s >= 0.0, "c {c}, sigma {sigma}: {s}");
            }
        }
        // Where steps are exact, counting sums what stepping did.
        let s = axis_sum(1000.3, 2.0);
        let stepped: f32 = (990..=1010)
            .map(|x| x as f32 + 0.5 - 1000.3)
            .filter(|d| d.abs() <= TRUNCATION * 2.0)
            .map(|d| (-d * d / 8.0).exp())
            .sum();
        assert!((s - stepped).abs() < 1e-5, "{s} against {stepped}");
    }

    #[test]
    fn weights_sum_to_one_on_a_pixel_grid() {
        for sigma in [MIN_SIGMA_PX, 1.0, 2.5, 7.9, 31.0, 32.0, 40.0] {
            for (cx, cy) in [(150.5f32, 150.5f32), (150.0, 150.0), (150.3, 150.77)] {
                let mut sum = 0.0f64;
                for y in 0..301 {
                    for x in 0..301 {
                        let (dx, dy) = (x as f32 + 0.5 - cx, y as f32 + 0.5 - cy);
                        sum += f64::from(splat_weight(dx, dy, cx, cy, sigma));
                    }
                }
                // Exact below 32 px (up to f32 rounding), the continuous mass above.
                let tol = if sigma < EXACT_BELOW { 1e-5 } else { 1e-4 };
                assert!(
                    (sum - 1.0).abs() < tol,
                    "sigma {sigma}, centre ({cx}, {cy}): {sum}"
                );
            }
        }
    }
}
