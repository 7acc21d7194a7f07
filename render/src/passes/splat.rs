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
/// Below this sigma (pixels) the kernel's sum over the pixels is taken pixel by pixel;
/// from it on, its integral stands for it.
const EXACT_BELOW: f32 = 2.5;

/// The Gaussian's sigma (pixels) for a point of projected radius `r_px`.
pub fn splat_sigma(r_px: f32) -> f32 {
    (0.5 * r_px).max(MIN_SIGMA_PX)
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

/// The kernel's sum over the pixel centres `(i + 0.5, j + 0.5)` around a splat centred at
/// `(cx, cy)`: exact below 2.5 px of sigma, its integral above (the WGSL's `kernel_sum`).
pub fn kernel_sum(cx: f32, cy: f32, sigma: f32) -> f32 {
    let limit = TRUNCATION * sigma;
    if sigma >= EXACT_BELOW {
        return std::f32::consts::TAU * sigma * sigma * (1.0 - EDGE)
            - std::f32::consts::PI * limit * limit * EDGE;
    }
    let first = [cx, cy].map(|c| (c - 0.5 - limit).ceil());
    let span = [0, 1].map(|k| ([cx, cy][k] - 0.5 + limit).floor() - first[k] + 1.0);
    // Counted, not stepped: past 2^24 px (a splat far off screen) x + 1 == x. An
    // infinite or NaN centre has no pixels.
    if !span.iter().all(|&s| s > 0.0 && s <= 2.0 * limit + 2.0) {
        return 0.0;
    }
    let mut sum = 0.0;
    for j in 0..span[1] as u32 {
        let dy = first[1] + j as f32 + 0.5 - cy;
        for i in 0..span[0] as u32 {
            let dx = first[0] + i as f32 + 0.5 - cx;
            sum += kernel(dx * dx + dy * dy, sigma);
        }
    }
    sum
}

/// The weight a splat of sigma `sigma` centred at `(cx, cy)` (pixels) gives the pixel
/// centre at offset `(dx, dy)` from it (0 from the cut on); the weights over the pixel
/// grid sum to 1.
pub fn splat_weight(dx: f32, dy: f32, cx: f32, cy: f32, sigma: f32) -> f32 {
    kernel(dx * dx + dy * dy, sigma) / kernel_sum(cx, cy, sigma)
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
    fn splats_far_off_screen_end_their_sums() {
        // Past 2^24 px a step of one pixel no longer changes a float: the sum is counted.
        for c in [16_777_216.0, 33_554_432.5, 1e30, f32::INFINITY, f32::NAN] {
            for sigma in [MIN_SIGMA_PX, 1.5, 3.0, 31.0] {
                let s = kernel_sum(c, 10.0, sigma);
                assert!(s.is_finite() && s >= 0.0, "c {c}, sigma {sigma}: {s}");
            }
        }
    }

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
                        sum += f64::from(splat_weight(dx, dy, cx, cy, sigma));
                    }
                }
                // Exact below 2.5 px (up to f32 rounding), the continuous mass above.
                let tol = if sigma < EXACT_BELOW { 1e-5 } else { 1e-4 };
                assert!(
                    (sum - 1.0).abs() < tol,
                    "sigma {sigma}, centre ({cx}, {cy}): {sum}"
                );
            }
        }
    }
}
