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
/// `exp(−TRUNCATION² / 2)`: the Gaussian's value at the cut, taken off the whole kernel so
/// that it falls continuously to 0 there.
pub const EDGE: f32 = 0.002_187_491_1;
/// How far a splat's kernel reaches by default, in radii: σ = r / 2, cut at 3.5 σ.
pub const DEFAULT_SUPPORT: f32 = 0.5 * TRUNCATION;

/// The Gaussian's sigma (pixels) for a point of projected radius `r_px`, by default.
pub fn splat_sigma(r_px: f32) -> f32 {
    splat_sigma_reaching(r_px, DEFAULT_SUPPORT)
}

/// The Gaussian's sigma (pixels) for a point of projected radius `r_px` whose kernel
/// reaches `support` radii.
pub fn splat_sigma_reaching(r_px: f32, support: f32) -> f32 {
    (support / TRUNCATION * r_px).max(MIN_SIGMA_PX)
}

/// The unnormalised kernel at squared distance `d2` (px²) from a splat's centre: the
/// Gaussian less its value at the cut radius `TRUNCATION · sigma`, 0 from there on (the
/// WGSL's `kernel`).
pub fn kernel(d2: f32, sigma: f32) -> f32 {
    let limit = TRUNCATION * sigma;
    if d2.is_nan() || d2 >= limit * limit {
        return 0.0;
    }
    (-d2 / (2.0 * sigma * sigma)).exp() - EDGE
}

/// The kernel's integral over the plane, `2π σ² (1 − EDGE) − π R² EDGE`, which normalises
/// it (the WGSL's `kernel_mass`): its samples at the pixel centres sum to it within
/// 1.7e-4 from σ = 1.5 px and 1.1e-3 below, by where the centre falls in its pixel.
pub fn kernel_mass(sigma: f32) -> f32 {
    let limit = TRUNCATION * sigma;
    std::f32::consts::TAU * sigma * sigma * (1.0 - EDGE)
        - std::f32::consts::PI * limit * limit * EDGE
}

/// The weight a splat of sigma `sigma` centred at `(cx, cy)` (pixels) gives the pixel
/// centre at offset `(dx, dy)` from it (0 from the cut on); the weights over the pixel
/// grid sum to 1 within [`kernel_mass`]'s bounds.
pub fn splat_weight(dx: f32, dy: f32, sigma: f32) -> f32 {
    kernel(dx * dx + dy * dy, sigma) / kernel_mass(sigma)
}

/// The alpha a translucent splat (over-blending) gives a pixel centre at offset
/// `(dx, dy)`: `opacity` times the kernel over its peak, attenuated by the squared
/// diameter below one pixel (Eq. 3); 0 from the cut on.
pub fn over_alpha(dx: f32, dy: f32, r_px: f32, opacity: f32) -> f32 {
    let sigma = splat_sigma(r_px);
    let diameter = 2.0 * r_px;
    opacity * (diameter * diameter).min(1.0) * kernel(dx * dx + dy * dy, sigma) / (1.0 - EDGE)
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
    fn the_edge_is_the_gaussian_at_the_cut() {
        assert!((EDGE - (-TRUNCATION * TRUNCATION / 2.0).exp()).abs() < 1e-9);
        // The kernel reaches 0 on the cut's circle, in every direction alike (round).
        let sigma = 10.0;
        for angle in [0.0f32, 0.4, 0.785, 1.2] {
            let r = TRUNCATION * sigma * 0.9999;
            let (x, y) = (r * angle.cos(), r * angle.sin());
            assert!(kernel(x * x + y * y, sigma).abs() < 1e-5, "{angle}");
        }
        // A point past the circle but inside its square gets nothing.
        let corner = TRUNCATION * sigma * 0.8;
        assert_eq!(kernel(2.0 * corner * corner, sigma), 0.0);
    }

    /// Averaged over where the centre falls in its pixel, the weights sum to 1 (the
    /// sampled sum's mean is the integral): many small splats keep their total flux.
    #[test]
    fn weights_sum_to_one_on_average_over_the_pixel() {
        for sigma in [MIN_SIGMA_PX, 0.75, 0.9, 1.2] {
            let steps = 24;
            let mut mean = 0.0f64;
            for a in 0..steps {
                for b in 0..steps {
                    let (cx, cy) = (
                        20.0 + a as f32 / steps as f32,
                        20.0 + b as f32 / steps as f32,
                    );
                    let mut sum = 0.0f64;
                    for y in 0..41 {
                        for x in 0..41 {
                            let (dx, dy) = (x as f32 + 0.5 - cx, y as f32 + 0.5 - cy);
                            sum += f64::from(splat_weight(dx, dy, sigma));
                        }
                    }
                    mean += sum / f64::from(steps * steps);
                }
            }
            assert!((mean - 1.0).abs() < 5e-5, "sigma {sigma}: mean {mean}");
        }
    }

    #[test]
    fn weights_sum_to_one_on_a_pixel_grid() {
        for sigma in [
            MIN_SIGMA_PX,
            0.75,
            0.9,
            1.0,
            1.99,
            2.06,
            2.49,
            2.5,
            2.56,
            7.9,
            31.0,
            40.0,
        ] {
            for (cx, cy) in [
                (150.5f32, 150.5f32),
                (150.0, 150.0),
                (150.3, 150.77),
                (150.9, 150.13),
            ] {
                let mut sum = 0.0f64;
                for y in 0..301 {
                    for x in 0..301 {
                        let (dx, dy) = (x as f32 + 0.5 - cx, y as f32 + 0.5 - cy);
                        sum += f64::from(splat_weight(dx, dy, sigma));
                    }
                }
                // Within 1.1e-3 below 1.5 px, 1.7e-4 from there on.
                let tol = if sigma < 1.5 { 1.1e-3 } else { 1.7e-4 };
                assert!(
                    (sum - 1.0).abs() < tol,
                    "sigma {sigma}, centre ({cx}, {cy}): {sum}"
                );
            }
        }
    }
}
