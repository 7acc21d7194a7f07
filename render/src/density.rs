//! The image-space density volume (Falk et al. 2010, section 3): the metaball density
//! of the points of a cut, reconstructed on demand at the sampling positions of ray
//! casting and rendered as a volume (`--mode density`) or an iso-surface (`--mode iso`).
//!
//! How it works:
//! - **Density.** `φ(p) = V · Σ_j m_j W(|p − p_j|, h_j)` with the normalised smooth-step
//!   (poly6) kernel `W(r, h) = 315 / (64 π h³) · (1 − r²/h²)³` for `r < h`. A point's mass
//!   is its area relative to the largest particle radius `r_ref` (the largest species'
//!   radius, or particle's own where the file keeps them), `m_j = (ρ_j / r_ref)²`
//!   with `ρ_j = sqrt(area_sum)` (a particle's own radius; a representative carries its
//!   particles' mass, Eq. 1), and `V = 4/3 π r_ref³`. A particle's support is
//!   `h_j = kernel_scale · ρ_j`; a representative's is `kernel_scale · s_j` with
//!   `s_j = (r_ref ρ_j²)^{1/3}`, the radius of a sphere of its particles' volume (`n`
//!   particles of radius `r_ref`: `n^{1/3} r_ref`), so a coarse cut spreads the same
//!   volume over the same space as its particles do: φ is a volume fraction (a close
//!   packing of reference spheres has φ ≈ 0.74), the same for every zoom and level. (A
//!   support of `kernel_scale · ρ_j`, which grows as `√n`, thinned solids out at coarse
//!   cuts, as `n^{-1/2}`.)
//! - **Slices.** Each pixel's ray `p = o + λ v` (o: the eye in perspective, so the slices
//!   are concentric spherical shells; the eye's plane in orthographic views, where λ may
//!   be negative down to the near plane) is sampled at `λ_s = λ_min + s Δλ` from the
//!   data's nearest distance (not nearer than the near plane) to its farthest. A pass splats
//!   every point whose support reaches a stack of slices as a perspective-correct
//!   footprint (the projected box of its support sphere) into several float targets at
//!   once (multiple render targets: 8 density slices, or 2 slices with gradients for the
//!   iso-surface, whose gradients are summed the same way), additively blended. Points are
//!   sorted by distance on the host, so each stack draws only the interval of points that
//!   can reach it.
//! - **Ray casting.** A compute pass composites each stack front to back into a per-pixel
//!   state: emission and absorption from a transfer function of φ, or the first crossing
//!   of the iso-value (interpolated between slices, across stacks too) shaded with the
//!   interpolated gradient. The iso-surface's colour comes from one more pass over the
//!   points once the hits are known: each adds its albedo weighted by `m_j W_j` at its
//!   pixels' hit positions ([`colour_at`]), so each species shows its own colour and
//!   blends where species meet. Rays stop when their opacity saturates or the data ends; a
//!   counter of active rays, read back every few stacks, ends the frame once none is
//!   left (early ray termination). As in the paper's section 3.4, frames are coherent:
//!   the renderer keeps the stacks the last frame needed and runs that many at once in
//!   the next, with counts taken at checkpoints near the end and read back once, so a
//!   still or slowly moving view waits on the GPU once per frame.
//! - **Clipping.** A plane `n · p ≤ d` removes samples, not particles: points outside it
//!   still add density inside, so a cut shows the true density at the cut.
//!
//! [`reference()`] is the CPU twin of the whole pipeline (the tests' oracle).

use glam::Vec3;

/// How to render the density volume.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DensitySettings {
    /// Iso-surface at this volume fraction instead of direct volume rendering.
    pub iso: Option<f32>,
    /// Number of slices from the nearest to the farthest point of the data.
    pub slices: u32,
    /// Kernel support in units of a point's radius.
    pub kernel_scale: f32,
    /// Volume fraction shown at the top of the transfer function.
    pub density_max: f32,
    /// Volume fraction at the bottom of the transfer function: nothing at or below it
    /// is shown (0 in linear scale; above 0 and below `density_max` in log scale).
    pub density_min: f32,
    /// The transfer function takes the logarithm of φ between `density_min` and
    /// `density_max` (SPH and astrophysical densities spanning decades).
    pub log: bool,
    /// Absorption: the optical depth per reference radius of path at `density_max` (an
    /// opacity of `1 − e^−absorption` over one radius).
    pub opacity: f32,
    /// Keep samples with `n · p ≤ d` (`[n.x, n.y, n.z, d]`, world units).
    pub clip: Option<[f32; 4]>,
    /// Colour by the attribute through this map: the points are packed as
    /// [`PackStyle::FluxValue`]; an iso-surface's hit takes the map's colour of their
    /// kernel-weighted mean place on the scale ([`surface_albedo`]) instead of their
    /// species' colours, and a volume's sample the map's colour of its density-weighted
    /// mean place (`Σ φ_j t_j / Σ φ_j`) instead of the transfer function's,
    /// its opacity still the density's.
    ///
    /// [`PackStyle::FluxValue`]: crate::passes::sphere_raycast::PackStyle::FluxValue
    pub colour_map: Option<crate::style::ColourMap>,
}

impl Default for DensitySettings {
    fn default() -> Self {
        DensitySettings {
            iso: None,
            slices: 256,
            kernel_scale: 2.5,
            density_max: 0.8,
            density_min: 0.0,
            log: false,
            opacity: 0.5,
            clip: None,
            colour_map: None,
        }
    }
}

impl DensitySettings {
    pub fn validate(&self) -> Result<(), String> {
        if !(1..=16384).contains(&self.slices) {
            return Err(format!("{} slices (1 to 16384)", self.slices));
        }
        let positive = |v: f32, what: &str| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(format!("{what} {v} (must be a finite number above 0)"))
            }
        };
        positive(self.kernel_scale, "kernel scale")?;
        positive(self.density_max, "--density-max")?;
        if !(self.density_min.is_finite() && self.density_min >= 0.0) {
            return Err(format!(
                "--density-min {} (must be 0 or above)",
                self.density_min
            ));
        }
        if self.density_min >= self.density_max {
            return Err(format!(
                "--density-min {} at or above --density-max {}",
                self.density_min, self.density_max
            ));
        }
        // (Not subnormal either: a GPU may flush it to 0, and log(φ / 0) is no scale.)
        if self.log && self.density_min < f32::MIN_POSITIVE {
            return Err(format!(
                "--density-min {} on a log scale (must be above 0, at least {:e})",
                self.density_min,
                f32::MIN_POSITIVE
            ));
        }
        // Named as `mdlod render` names it.
        positive(self.opacity, "--absorption")?;
        if let Some(v) = self.iso {
            positive(v, "iso-value")?;
        }
        if let Some(c) = self.clip {
            let n = Vec3::new(c[0], c[1], c[2]);
            if !(c.iter().all(|v| v.is_finite()) && n.length() > 0.0) {
                return Err(format!("clip plane {c:?} (needs a non-zero normal)"));
            }
        }
        Ok(())
    }
}

/// Opacity at which a ray stops (the paper's threshold).
pub const OPAQUE: f32 = 0.99;

/// `(4/3) · 315/64`: the volume fraction `V · m · W(0, h)` at the centre of a point of
/// radius `r = r_ref` and kernel scale 1 (see [`fraction`]).
pub const PEAK_FRACTION: f32 = 4.0 / 3.0 * 315.0 / 64.0;

/// The volume fraction a point adds at offset `d` from its centre, and its gradient:
/// `V · m · W(|d|, h)` with `V = 4/3 π r_ref³`, `m = (ρ / r_ref)²` and `h = k s` (`s` its
/// [`DensityPoint::support`]), which is `PEAK_FRACTION / (k³ x) · t³` with
/// `x = s³ / (ρ² r_ref)` ([`DensityPoint::spread`]: `r / r_ref` for a particle, 1 for a
/// representative) and `t = 1 − |d|²/h²`. Evaluated in that form, so that no power of a
/// large radius is formed: stars in metres (a coarse node's radius of 10¹³) would
/// overflow `h³` in single precision.
pub fn fraction(d: Vec3, support: f32, spread: f32, k: f32) -> (f32, Vec3) {
    let h = k * support;
    let h2 = h * h;
    let r2 = d.length_squared();
    if r2.partial_cmp(&h2) != Some(std::cmp::Ordering::Less) {
        return (0.0, Vec3::ZERO);
    }
    let t = 1.0 - r2 / h2;
    let norm = PEAK_FRACTION / (k * k * k) / spread;
    (norm * t * t * t, d * (-6.0 * norm / h2 * t * t))
}

/// The transfer function: colour (linear RGB) of a volume fraction `t = φ / φ_max`
/// clamped to [0, 1], blue through red to yellow.
pub fn transfer_colour(t: f32) -> Vec3 {
    let t = t.clamp(0.0, 1.0);
    let stops = [
        Vec3::new(0.02, 0.05, 0.45),
        Vec3::new(0.75, 0.08, 0.06),
        Vec3::new(1.0, 0.85, 0.25),
    ];
    if t < 0.5 {
        stops[0].lerp(stops[1], t * 2.0)
    } else {
        stops[1].lerp(stops[2], t * 2.0 - 1.0)
    }
}

/// Where a volume fraction `phi` falls on the transfer function, in [0, 1]: linearly
/// between `density_min` and `density_max`, or by its logarithm between them.
/// `transfer_t` in `density_common.wgsl` is the GPU's twin.
pub fn transfer_t(phi: f32, s: &DensitySettings) -> f32 {
    let (lo, hi) = (s.density_min, s.density_max);
    if s.log {
        if phi <= lo {
            return 0.0;
        }
        return ((phi / lo).ln() / (hi / lo).ln()).clamp(0.0, 1.0);
    }
    ((phi - lo) / (hi - lo)).clamp(0.0, 1.0)
}

/// Opacity of one sample of volume fraction `phi` over a step `step / r_ref`.
pub fn sample_alpha(phi: f32, s: &DensitySettings, step_over_ref: f32) -> f32 {
    let t = transfer_t(phi, s);
    1.0 - (-s.opacity * t * step_over_ref).exp()
}

/// One point as the density sees it: position, radius (`sqrt(area_sum)`), albedo.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DensityPoint {
    pub position: Vec3,
    pub radius: f32,
    /// Linear RGB: a particle's species colour, a representative's mixture; coloured
    /// by the attribute ([`DensitySettings::colour_map`]), its place on the attribute's
    /// scale in every channel (a representative's, of its particles' mean).
    pub albedo: Vec3,
    /// A representative of several particles (its support spreads their volume).
    pub cluster: bool,
}

impl DensityPoint {
    /// The kernel's support radius in units of the kernel scale: the particle's radius,
    /// or a representative's volume-equivalent radius `(r_ref ρ²)^{1/3}`, formed as
    /// `r_ref (ρ / r_ref)^{2/3}` (no power of a large radius).
    pub fn support(&self, r_ref: f32) -> f32 {
        if self.cluster {
            r_ref * (self.radius / r_ref).powf(2.0 / 3.0)
        } else {
            self.radius
        }
    }

    /// `s³ / (ρ² r_ref)` ([`fraction`]'s `x`): `r / r_ref` for a particle, 1 for a
    /// representative.
    pub fn spread(&self, r_ref: f32) -> f32 {
        if self.cluster {
            1.0
        } else {
            self.radius / r_ref
        }
    }
}

/// What the frame's rays share: their origins and directions come from the camera;
/// `lambda_min` and `step` place the slices.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Slicing {
    pub lambda_min: f32,
    pub step: f32,
    pub slices: u32,
    pub r_ref: f32,
}

impl Slicing {
    /// Slices covering the points' supports along the rays of `camera`.
    pub fn new(
        points: &[DensityPoint],
        camera: &crate::camera::Camera,
        s: &DensitySettings,
        r_ref: f32,
    ) -> Slicing {
        let mut lo = f32::INFINITY;
        let mut hi = f32::NEG_INFINITY;
        for p in points {
            let l = ray_distance(camera, p.position);
            let h = s.kernel_scale * p.support(r_ref);
            lo = lo.min(l - h);
            hi = hi.max(l + h);
        }
        if !lo.is_finite() {
            lo = 0.0;
            hi = 1.0;
        }
        // Nothing nearer than the near plane is drawn: in perspective the eye (distances
        // are never negative), in orthographic views the near plane, which may lie
        // behind the eye's plane (a view zoomed into the data).
        let lo = match camera.projection {
            crate::camera::Projection::Perspective => lo.max(0.0),
            crate::camera::Projection::Orthographic => lo.max(camera.near),
        };
        let step = ((hi - lo) / s.slices as f32).max(f32::MIN_POSITIVE);
        Slicing {
            lambda_min: lo,
            step,
            slices: s.slices,
            r_ref,
        }
    }
}

/// The distance along the rays at which `p` lies: from the eye in perspective (shells),
/// from the near plane's plane through the eye in orthographic views (planes).
pub fn ray_distance(camera: &crate::camera::Camera, p: Vec3) -> f32 {
    let view = camera.view_from_world().transform_point3(p);
    match camera.projection {
        // In double precision: the square of a distance past 1.8·10^19 (data in
        // centimetres or metres at galactic scales) overflows single precision.
        crate::camera::Projection::Perspective => view.as_dvec3().length() as f32,
        crate::camera::Projection::Orthographic => -view.z,
    }
}

/// Ray origin and unit direction through pixel centre `(x, y)` of a `width × height`
/// image: world space, as the GPU reconstructs them.
pub fn pixel_ray(
    camera: &crate::camera::Camera,
    x: f32,
    y: f32,
    width: u32,
    height: u32,
) -> (Vec3, Vec3) {
    let b = ray_basis(camera, width, height);
    let ndc = glam::Vec2::new(2.0 * x / width as f32 - 1.0, 1.0 - 2.0 * y / height as f32);
    let across =
        b.x_axis.truncate() * (ndc.x * b.x_axis.w) + b.y_axis.truncate() * (ndc.y * b.y_axis.w);
    let (back, eye) = (b.z_axis.truncate(), b.w_axis.truncate());
    match camera.projection {
        crate::camera::Projection::Perspective => (eye, (across - back).normalize()),
        // The point on the ray in the plane through the eye (view z = 0).
        crate::camera::Projection::Orthographic => (eye + across, -back),
    }
}

/// The camera's basis for pixel rays, as the density passes take it (`DensityGpu::basis`):
/// columns right, up, back and eye in world space, the w of right and up the view's
/// half-extents (at unit depth in perspective), 1 / `clip_from_view`'s x and y scales,
/// the eye's w 1 for orthographic views, else 0.
pub fn ray_basis(camera: &crate::camera::Camera, width: u32, height: u32) -> glam::Mat4 {
    let p = camera.clip_from_view(width as f32 / height as f32);
    glam::Mat4::from_cols(
        camera.right().extend(1.0 / p.x_axis.x),
        camera.up().extend(1.0 / p.y_axis.y),
        camera.back().extend(0.0),
        camera.eye().extend(
            if camera.projection == crate::camera::Projection::Orthographic {
                1.0
            } else {
                0.0
            },
        ),
    )
}

/// The CPU reference of a density frame.
pub struct Reference {
    /// Linear RGB and alpha, premultiplied, per pixel.
    pub rgba: Vec<[f32; 4]>,
    /// Iso mode: the distance along the ray of the first crossing (NaN where none).
    pub hit: Vec<f32>,
}

/// Volume fraction and its gradient at `p` (brute force over `points`).
pub fn density_at(
    points: &[DensityPoint],
    p: Vec3,
    s: &DensitySettings,
    r_ref: f32,
) -> (f32, Vec3) {
    let (phi, grad, _) = sums_at(points, p, s, r_ref);
    (phi, grad)
}

/// [`density_at`]'s `φ` and gradient, and `Σ φ_j t_j`: each point's volume fraction at
/// `p` times its place on the attribute's scale (its albedo's first channel), which over
/// `φ` is the density-weighted mean place a volume coloured by the attribute shows; in
/// one pass.
fn sums_at(points: &[DensityPoint], p: Vec3, s: &DensitySettings, r_ref: f32) -> (f32, Vec3, f32) {
    let mut phi = 0.0;
    let mut grad = Vec3::ZERO;
    let mut valued = 0.0;
    for q in points {
        let (f, g) = fraction(
            p - q.position,
            q.support(r_ref),
            q.spread(r_ref),
            s.kernel_scale,
        );
        phi += f;
        grad += g;
        valued += f * q.albedo.x;
    }
    (phi, grad, valued)
}

/// The colour of the iso-surface at `p`: the points' albedos weighted by their mass
/// times kernel, `Σ m_j W_j c_j / Σ m_j W_j` (the density's own weights, so the colour
/// blends where species meet and a representative's colour stands for its particles);
/// `None` where no support reaches `p`.
pub fn colour_at(
    points: &[DensityPoint],
    p: Vec3,
    s: &DensitySettings,
    r_ref: f32,
) -> Option<Vec3> {
    let (mut sum, mut weight) = (Vec3::ZERO, 0.0f32);
    for q in points {
        let h = s.kernel_scale * q.support(r_ref);
        let (r2, h2) = (p.distance_squared(q.position), h * h);
        if r2.partial_cmp(&h2) != Some(std::cmp::Ordering::Less) {
            continue;
        }
        // m W up to constant factors, which cancel: t³ / x (`fraction`'s form, no power
        // of a large radius).
        let t = 1.0 - r2 / h2;
        let w = t * t * t / q.spread(r_ref);
        sum += w * q.albedo;
        weight += w;
    }
    (weight > 0.0).then(|| sum / weight)
}

/// The albedo of an iso-surface hit from the kernel-weighted mean of the points'
/// albedos there (`None` where no support reaches it): that mean itself, or, coloured by
/// the attribute, the colour map's colour of the mean place on the scale (its first
/// channel). `fallback` stands in where no support reaches: the first species' colour,
/// or the map's lowest.
pub fn surface_albedo(mean: Option<Vec3>, s: &DensitySettings, fallback: Vec3) -> Vec3 {
    match (s.colour_map, mean) {
        (Some(map), Some(m)) => Vec3::from(map.colour(m.x)),
        (Some(map), None) => Vec3::from(map.colour(0.0)),
        (None, Some(m)) => m,
        (None, None) => fallback,
    }
}

/// Whether `p` is kept by the clip plane.
pub fn kept(clip: Option<[f32; 4]>, p: Vec3) -> bool {
    clip.is_none_or(|c| Vec3::new(c[0], c[1], c[2]).dot(p) <= c[3])
}

/// Shades an iso-surface hit: Lambert from a headlight with a little ambient.
pub fn iso_shade(albedo: Vec3, gradient: Vec3, dir: Vec3) -> Vec3 {
    let n = -gradient.normalize_or_zero();
    albedo * (0.25 + 0.75 * n.dot(-dir).max(0.0))
}

/// Renders the density frame on the CPU, exactly as the GPU pipeline does. `albedo`
/// colours an iso-surface hit that no point's support reaches (see [`colour_at`]).
pub fn reference(
    points: &[DensityPoint],
    camera: &crate::camera::Camera,
    width: u32,
    height: u32,
    s: &DensitySettings,
    slicing: &Slicing,
    albedo: Vec3,
) -> Reference {
    let mut rgba = vec![[0.0f32; 4]; (width * height) as usize];
    let mut hit = vec![f32::NAN; (width * height) as usize];
    for y in 0..height {
        for x in 0..width {
            let i = (y * width + x) as usize;
            let (o, v) = pixel_ray(camera, x as f32 + 0.5, y as f32 + 0.5, width, height);
            let mut c = Vec3::ZERO;
            let mut a = 0.0f32;
            let mut prev: Option<(f32, Vec3)> = None;
            for k in 0..slicing.slices {
                let lambda = slicing.lambda_min + k as f32 * slicing.step;
                let p = o + v * lambda;
                let (phi, g, valued) = if kept(s.clip, p) {
                    sums_at(points, p, s, slicing.r_ref)
                } else {
                    (0.0, Vec3::ZERO, 0.0)
                };
                match s.iso {
                    None => {
                        let alpha = sample_alpha(phi, s, slicing.step / slicing.r_ref);
                        let colour = match s.colour_map {
                            Some(map) if phi > 0.0 => Vec3::from(map.colour(valued / phi)),
                            Some(map) => Vec3::from(map.colour(0.0)),
                            None => transfer_colour(transfer_t(phi, s)),
                        };
                        c += (1.0 - a) * alpha * colour;
                        a += (1.0 - a) * alpha;
                        if a >= OPAQUE {
                            break;
                        }
                    }
                    Some(iso) => {
                        if let Some((p0, g0)) = prev {
                            if p0 < iso && phi >= iso {
                                let t = (iso - p0) / (phi - p0);
                                hit[i] = lambda - slicing.step + t * slicing.step;
                                let albedo = surface_albedo(
                                    colour_at(points, o + v * hit[i], s, slicing.r_ref),
                                    s,
                                    albedo,
                                );
                                c = iso_shade(albedo, g0.lerp(g, t), v);
                                a = 1.0;
                                break;
                            }
                        } else if phi >= iso {
                            hit[i] = lambda;
                            let albedo =
                                surface_albedo(colour_at(points, p, s, slicing.r_ref), s, albedo);
                            c = iso_shade(albedo, g, v);
                            a = 1.0;
                            break;
                        }
                        prev = Some((phi, g));
                    }
                }
            }
            rgba[i] = [c.x, c.y, c.z, a];
        }
    }
    Reference { rgba, hit }
}

/// The points of `draw` in order, as the density pass packs them: a particle at its own
/// radius where the file keeps one, else its species', a representative at `sqrt(area_sum)` (it carries its particles' mass).
/// With `values` (the attribute's scale, coloured by the attribute), each point's albedo
/// is its place on that scale, as [`PackStyle::FluxValue`] packs it.
///
/// [`PackStyle::FluxValue`]: crate::passes::sphere_raycast::PackStyle::FluxValue
pub fn density_points(
    file: &mdlod_format::MdlodFile,
    draw: &crate::traversal::DrawList,
    values: Option<&crate::style::AttributeScale>,
) -> Vec<DensityPoint> {
    let positions = crate::traversal::point_positions(file, draw);
    let last = file.level_count() - 1;
    let species = file.species();
    let table = &file.metadata().species;
    let attribute = file.attribute().unwrap_or_default();
    let mut out = Vec::with_capacity(positions.len());
    let mut p = positions.iter();
    for r in &draw.ranges {
        let level = usize::from(r.level);
        for i in r.first..r.first + r.count {
            let (radius, mut albedo) = if level == last {
                let s = species.get(i as usize).copied().unwrap_or(0);
                table.get(usize::from(s)).map_or((0.0, Vec3::ZERO), |sp| {
                    (file.particle_radius(i as usize), Vec3::from(sp.colour))
                })
            } else {
                let n = &file.level_nodes(level)[i as usize];
                let c = n.colour.to_le_bytes();
                (
                    n.area_sum.max(0.0).sqrt(),
                    Vec3::new(c[0].into(), c[1].into(), c[2].into()) / 255.0,
                )
            };
            if let Some(scale) = values {
                albedo = Vec3::splat(if level == last {
                    scale.of_quantized(attribute.get(i as usize).copied().unwrap_or(0))
                } else {
                    scale.of_value(file.level_nodes(level)[i as usize].attribute)
                });
            }
            if let Some(&position) = p.next() {
                out.push(DensityPoint {
                    position,
                    radius,
                    albedo,
                    cluster: level != last,
                });
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::{Bounds, Camera, Projection};
    use glam::DVec3;

    #[test]
    fn an_iso_surface_by_attribute_takes_the_map_colour_of_the_mean_value() {
        // Two equal particles, one at the scale's bottom, one at its top: midway between
        // them the mean place is one half, and the colour the map's there (not the mean
        // of its two ends' colours); nearer the first, below the half.
        let point = |x: f32, t: f32| DensityPoint {
            position: Vec3::new(x, 0.0, 0.0),
            radius: 1.0,
            albedo: Vec3::splat(t),
            cluster: false,
        };
        let points = [point(-1.0, 0.0), point(1.0, 1.0)];
        let map = crate::style::ColourMap::Viridis;
        let s = DensitySettings {
            iso: Some(0.3),
            colour_map: Some(map),
            ..Default::default()
        };
        let fallback = Vec3::ONE;
        let mid = surface_albedo(colour_at(&points, Vec3::ZERO, &s, 1.0), &s, fallback);
        assert!((mid - Vec3::from(map.colour(0.5))).abs().max_element() < 1e-6);
        let ends = (Vec3::from(map.colour(0.0)) + Vec3::from(map.colour(1.0))) / 2.0;
        assert!((mid - ends).abs().max_element() > 0.05, "{mid} {ends}");
        let near = colour_at(&points, Vec3::new(-0.5, 0.0, 0.0), &s, 1.0).unwrap();
        assert!(near.x > 0.0 && near.x < 0.5, "{near}");
        // Out of every support: the map's bottom; by species, the fallback.
        let far = Vec3::new(10.0, 0.0, 0.0);
        let none = colour_at(&points, far, &s, 1.0);
        assert_eq!(none, None);
        assert_eq!(
            surface_albedo(none, &s, fallback),
            Vec3::from(map.colour(0.0))
        );
        let by_species = DensitySettings {
            colour_map: None,
            ..s
        };
        assert_eq!(surface_albedo(none, &by_species, fallback), fallback);
        // A volume takes a map too (its samples' colours).
        let volume = DensitySettings { iso: None, ..s };
        assert!(volume.validate().is_ok() && s.validate().is_ok());
    }

    #[test]
    fn the_transfer_function_places_densities_linearly_or_by_decade() {
        let linear = DensitySettings {
            density_min: 0.2,
            density_max: 1.0,
            ..Default::default()
        };
        for (phi, t) in [(0.0, 0.0), (0.2, 0.0), (0.6, 0.5), (1.0, 1.0), (3.0, 1.0)] {
            assert!((transfer_t(phi, &linear) - t).abs() < 1e-6, "{phi}");
        }
        let log = DensitySettings {
            density_min: 1e-2,
            density_max: 1e2,
            log: true,
            ..Default::default()
        };
        for (phi, t) in [
            (0.0, 0.0),
            (1e-3, 0.0),
            (1e-1, 0.25),
            (1.0, 0.5),
            (1e3, 1.0),
        ] {
            assert!((transfer_t(phi, &log) - t).abs() < 1e-6, "{phi}");
        }
        // Below the bottom nothing is absorbed.
        assert_eq!(sample_alpha(0.005, &log, 1.0), 0.0);
        assert!(sample_alpha(1.0, &log, 1.0) > 0.0);
        // A log scale needs a bottom above 0 and below the top.
        assert!(DensitySettings {
            density_min: 0.0,
            ..log
        }
        .validate()
        .is_err());
        assert!(DensitySettings {
            density_min: 1e3,
            ..log
        }
        .validate()
        .is_err());
        assert!(log.validate().is_ok() && linear.validate().is_ok());
    }

    #[test]
    fn pixel_rays_keep_their_direction_in_a_close_up() {
        // The eye inside the data's bounds (a close-up): the near plane comes to 10⁻⁵ of
        // the far one, where rays unprojected through an inverse of clip_from_world
        // were off by milliradians (pixels at 720p); from the camera's basis they agree
        // with double precision to 10⁻⁶.
        for projection in [Projection::Perspective, Projection::Orthographic] {
            let mut cam = Camera {
                projection,
                azimuth_deg: 37.0,
                elevation_deg: 21.0,
                target: Vec3::new(3000.0, 2000.0, 500.0),
                distance: 40.0,
                fov_y_deg: 35.0,
                ..Default::default()
            };
            cam.fit_depth_range(&Bounds::new([0.0; 3], [6000.0, 4000.0, 1000.0]));
            assert!(cam.near <= cam.far * 1.01e-5, "{} {}", cam.near, cam.far);
            let (w, h) = (1280u32, 720u32);
            let (a, e) = (
                f64::from(cam.azimuth_deg).to_radians(),
                f64::from(cam.elevation_deg).to_radians(),
            );
            let back = DVec3::new(e.cos() * a.cos(), e.cos() * a.sin(), e.sin());
            let right = DVec3::new(-a.sin(), a.cos(), 0.0);
            let up = back.cross(right);
            let eye = cam.target.as_dvec3() + back * f64::from(cam.distance);
            let half_h = match projection {
                Projection::Perspective => (f64::from(cam.fov_y_deg).to_radians() / 2.0).tan(),
                Projection::Orthographic => f64::from(cam.view_height_at_target()) / 2.0,
            };
            let half_w = half_h * f64::from(w) / f64::from(h);
            for (x, y) in [(0.5, 0.5), (640.5, 360.5), (1279.5, 200.5), (17.5, 719.5)] {
                let (o, d) = pixel_ray(&cam, x as f32, y as f32, w, h);
                let ndc_x = 2.0 * x / f64::from(w) - 1.0;
                let ndc_y = 1.0 - 2.0 * y / f64::from(h);
                let across = right * (ndc_x * half_w) + up * (ndc_y * half_h);
                let (o_ref, d_ref) = match projection {
                    Projection::Perspective => (eye, (across - back).normalize()),
                    Projection::Orthographic => (eye + across, -back),
                };
                let angle = d.as_dvec3().normalize().cross(d_ref).length();
                assert!(angle < 1e-6, "{projection:?} ({x}, {y}): {angle} rad off");
                let off = (o.as_dvec3() - o_ref).length();
                assert!(off < 1e-3, "{projection:?} ({x}, {y}): origin {off} off");
            }
        }
    }
}
