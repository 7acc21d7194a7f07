//! Occlusion culling on the CPU: a conservative depth pyramid built from the spheres the
//! cut has already committed to drawing.
//!
//! How it works. In a dense block of atoms almost every cluster the cut would draw lies
//! behind others; drawing them costs GPU time and streaming them costs memory, although
//! they change no pixel. The traversal therefore visits nodes front to back (nearest
//! first) and keeps, per pixel, an *upper bound* of the depth of what is already drawn
//! there:
//!
//! - When a sphere is committed (a particle, or a representative that will not be
//!   opened), every pixel sample it certainly covers gets a bound of its hit depth
//!   (view-space distance along the view direction). "Certainly covers" uses the sphere's
//!   cross-section through its centre, a disk of radius `r` at depth `d`, which projects
//!   to a circle of radius `r · pixels_per_world(d)` around the projected centre: every
//!   ray through that circle enters the sphere before reaching depth `d`. A ray crossing
//!   the disk at distance `a` from the centre, at angle θ to the view axis, enters at most
//!   at depth `d − cos θ · max(0, √(r² − a²) − a · sin θ)`; with θ bounded by the image
//!   corner's angle (0 in orthographic views) that is the bound stored, so the GPU's
//!   ray-cast impostor writes a depth no larger there. The circle is shrunk by a small
//!   margin and the depth enlarged by one, so float rounding cannot break the bound.
//! - Which samples: with one sample per pixel the GPU samples pixel centres, so a pixel
//!   counts when its centre is inside the circle ([`OcclusionMode::PixelCentres`]); with
//!   jittered supersampling a pixel counts only when the whole pixel square is inside
//!   ([`OcclusionMode::WholePixels`]).
//! - A node is hidden when the nearest depth of its bounding box, grown by the node's
//!   representative radius (radii only grow up the hierarchy, Eq. 2, so this bounds every
//!   sphere drawn for any part of the subtree), is larger than the stored bound at every
//!   sample its projected box can reach. The maximum over a rectangle comes from a max
//!   pyramid (each texel the maximum of its 2×2 children, updated as pixels are written),
//!   read at the level where the rectangle spans at most 2×2 texels, which covers a
//!   superset of the rectangle and so stays conservative.
//!
//! - A sphere (a particle, or a cluster drawn as one sphere) is tested more tightly: its
//!   view-aligned box at its own nearest depth; and when that box spans at most 8×8
//!   pixels with one sample per pixel, sample by sample: each pixel centre whose ray
//!   enters the sphere must have a bound nearer than the entry depth (shrunk by a
//!   relative 10⁻⁵ against rounding). That is the GPU's own depth test, made ahead. The
//!   entry is measured from the ray's point closest to the centre, as the shaders do: a
//!   sphere of a pixel seen whole in a 10⁸-particle set lies thousands of radii from the
//!   eye, where the quadratic taken from the eye (|o − c|² − r²) keeps no digit of the
//!   radius in single precision.
//! - With one sample per pixel, a box that projects to at most 8×8 pixels is tested the
//!   same way: each pixel centre whose ray enters the box (slabs in world space, the box
//!   grown by a relative 10⁻⁵) must have a bound nearer than the entry depth. A cluster of
//!   spheres of a pixel or two, just behind the surface, reaches pixels where the
//!   surface in front is farther (the gaps between its spheres, the surface receding);
//!   its box's nearest corner against the rectangle's maximum keeps it, although no ray
//!   that reaches those pixels passes through the box.
//!
//! Nothing the GPU would show is removed: a culled node's every fragment would fail the
//! depth test against spheres that are drawn. Depths are compared in view space, which
//! is monotone along every ray, as the GPU's depth buffer is.

use glam::{Mat4, Vec3, Vec4Swizzles};

use crate::camera::{Camera, Projection};

/// Which occlusion test the traversal applies.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum OcclusionMode {
    /// No occlusion culling: every node in the frustum is considered.
    Off,
    /// One sample per pixel, at the pixel centre (the renderer's 1-spp mode).
    #[default]
    PixelCentres,
    /// Samples anywhere in the pixel (jittered supersampling): a pixel is occluded only
    /// when the whole pixel square is covered.
    WholePixels,
}

/// Relative shrink of an occluder's circle and absolute shrink in pixels.
const RADIUS_SHRINK_REL: f32 = 1e-3;
const RADIUS_SHRINK_PX: f32 = 0.02;
/// Relative growth of an occluder's depth, and of an occludee's rectangle in pixels.
const DEPTH_GROW_REL: f32 = 1e-5;
/// Units in the last place of a coordinate that the GPU's view-space depths may differ
/// by from these (other rounding of the same single-precision transform).
const POSITION_ULPS: f32 = 4.0 * f32::EPSILON;
const RECT_GROW_PX: f32 = 0.5;

/// Spheres whose projected box is at most this many pixels wide and high are tested
/// sample by sample (one ray per pixel centre) rather than against the box's pyramid
/// maximum.
const EXACT_SPHERE_PX: f32 = 8.0;
/// Boxes whose projection is at most this many pixels wide and high are tested sample
/// by sample (one ray per pixel centre against the box).
const EXACT_BOX_PX: f32 = 8.0;
/// Relative growth of a box in the sample test, against rounding.
const BOX_GROW_REL: f32 = 1e-5;
/// Relative decrease of an occludee's entry depth in the sample test (against the GPU
/// computing the same hit with other rounding).
const SAMPLE_DEPTH_SHRINK_REL: f32 = 1e-5;

/// A query reads the pyramid level where the rectangle spans fewer than this many
/// texels per axis: finer levels bound the rectangle more tightly (less uncovered border
/// swept in) at the price of more reads.
const QUERY_SPAN: u32 = 8;

/// The per-pixel depth bound and its max pyramid, over the whole image or over one
/// rectangular window of it (a tile of the parallel traversal).
pub struct OcclusionBuffer {
    mode: OcclusionMode,
    /// The window's size in pixels; its pixel `(x, y)` is the image's
    /// `(origin[0] + x, origin[1] + y)`.
    width: u32,
    height: u32,
    origin: [u32; 2],
    /// The whole image's size (projections are the image's).
    image: [u32; 2],
    /// `levels[k]` is `dims[k].0 × dims[k].1`, row-major; level 0 is the image.
    levels: Vec<Vec<f32>>,
    dims: Vec<(u32, u32)>,
    clip_from_world: Mat4,
    clip_from_view: Mat4,
    view_from_world: Mat4,
    /// The eye and the view axes in world space (right, up, back): the view-to-world
    /// map, exactly (a general matrix inverse loses digits to the eye's distance).
    eye: Vec3,
    axes: [Vec3; 3],
    /// The largest of the eye's coordinates, in size (see `rounding`).
    eye_size: f32,
    camera: Camera,
    /// Sine and cosine bounds of the angle between any view ray and the view axis.
    sin_max: f32,
    cos_min: f32,
    /// The view-space rays through the window's pixel centres, by column and by row: x
    /// and y of the direction (perspective; the origin is the eye) or of the origin
    /// (orthographic; the direction is −z). Worked out once, as `samples_hidden` did
    /// for every sample.
    ray_x: Vec<f32>,
    ray_y: Vec<f32>,
    /// Pixels written so far (statistics).
    pub pixels_written: u64,
}

impl OcclusionBuffer {
    /// An empty buffer (nothing occludes) for `camera` at `viewport`; `None` for
    /// [`OcclusionMode::Off`] or an empty viewport.
    pub fn new(camera: &Camera, viewport: [u32; 2], mode: OcclusionMode) -> Option<Self> {
        Self::window(camera, viewport, mode, [0, 0], viewport)
    }

    /// An empty buffer for the window of `size` pixels at `origin` of the image
    /// `viewport`: spheres are recorded only where they cover the window, and a box whose
    /// samples all lie outside the window counts as hidden (this window cannot see it).
    /// `None` for [`OcclusionMode::Off`] or an empty window; the window is clipped to
    /// the image.
    pub fn window(
        camera: &Camera,
        viewport: [u32; 2],
        mode: OcclusionMode,
        origin: [u32; 2],
        size: [u32; 2],
    ) -> Option<Self> {
        let width = size[0].min(viewport[0].saturating_sub(origin[0]));
        let height = size[1].min(viewport[1].saturating_sub(origin[1]));
        if mode == OcclusionMode::Off || width == 0 || height == 0 {
            return None;
        }
        let mut dims = vec![(width, height)];
        while let Some(&(w, h)) = dims.last() {
            if w == 1 && h == 1 {
                break;
            }
            dims.push((w.div_ceil(2), h.div_ceil(2)));
        }
        // The widest ray angle: the image corner (perspective); rays are parallel in
        // orthographic views.
        let (sin_max, cos_min) = match camera.projection {
            Projection::Perspective => {
                let t = (camera.fov_y_deg.to_radians() * 0.5).tan()
                    * (1.0 + (viewport[0] as f32 / viewport[1] as f32).powi(2)).sqrt();
                let n = (1.0 + t * t).sqrt();
                // Rounded outwards.
                ((t / n + 1e-4).min(1.0), (1.0 / n - 1e-4).max(0.0))
            }
            Projection::Orthographic => (0.0, 1.0),
        };
        let levels = dims
            .iter()
            .map(|&(w, h)| vec![f32::INFINITY; w as usize * h as usize])
            .collect();
        let clip_from_view = camera.jittered_clip_from_view(viewport, glam::Vec2::ZERO);
        let p = &clip_from_view;
        let (sx, sy) = (p.x_axis.x, p.y_axis.y);
        let perspective = camera.projection == Projection::Perspective;
        let ray_x = (0..width)
            .map(|i| {
                let ndc_x = (i as f32 + origin[0] as f32 + 0.5) / viewport[0] as f32 * 2.0 - 1.0;
                if perspective {
                    (ndc_x + p.z_axis.x) / sx
                } else {
                    (ndc_x - p.w_axis.x) / sx
                }
            })
            .collect();
        let ray_y = (0..height)
            .map(|j| {
                let ndc_y = 1.0 - (j as f32 + origin[1] as f32 + 0.5) / viewport[1] as f32 * 2.0;
                if perspective {
                    (ndc_y + p.z_axis.y) / sy
                } else {
                    (ndc_y - p.w_axis.y) / sy
                }
            })
            .collect();
        Some(OcclusionBuffer {
            mode,
            width,
            height,
            origin,
            image: viewport,
            levels,
            dims,
            clip_from_world: camera.clip_from_world(viewport, glam::Vec2::ZERO),
            clip_from_view,
            view_from_world: camera.view_from_world(),
            eye: camera.eye(),
            axes: [camera.right(), camera.up(), camera.back()],
            eye_size: camera.eye().abs().max_element(),
            camera: camera.clone(),
            sin_max,
            cos_min,
            ray_x,
            ray_y,
            pixels_written: 0,
        })
    }

    /// The stored depth bound of pixel `(x, y)` of the window (rows top to bottom).
    pub fn depth_at(&self, x: u32, y: u32) -> f32 {
        self.levels[0][(y * self.width + x) as usize]
    }

    /// How far the GPU's single-precision view transform of a point with coordinates up
    /// to `coordinate` in size may put it from where this buffer's own transform does: a
    /// few units in the last place of the larger of those and the eye's coordinates.
    fn rounding(&self, coordinate: f32) -> f32 {
        POSITION_ULPS * (self.eye_size + coordinate)
    }

    /// Window pixel coordinates (x right, y down; pixel `i` spans `[i, i + 1)`) of a
    /// point.
    fn to_px(&self, world: Vec3) -> Option<(f32, f32)> {
        let c = self.clip_from_world * world.extend(1.0);
        if c.w.is_nan() || c.w <= 0.0 {
            return None;
        }
        let ndc = c.xy() / c.w;
        Some((
            (ndc.x + 1.0) * 0.5 * self.image[0] as f32 - self.origin[0] as f32,
            (1.0 - ndc.y) * 0.5 * self.image[1] as f32 - self.origin[1] as f32,
        ))
    }

    /// View depth (distance along the view direction) of a point.
    fn depth(&self, world: Vec3) -> f32 {
        -self.view_from_world.transform_point3(world).z
    }

    /// Records a sphere that will be drawn.
    pub fn add_sphere(&mut self, center: Vec3, radius: f32) {
        let d = self.depth(center);
        if !(d.is_finite() && radius.is_finite() && radius > 0.0) {
            return;
        }
        if self.camera.projection == Projection::Perspective && d - radius <= self.camera.near {
            return;
        }
        let Some((cx, cy)) = self.to_px(center) else {
            return;
        };
        let ppw = rho_px_per_world(&self.camera, d, self.image[1]);
        // The GPU computes the same positions and depths from the same single-precision
        // coordinates with other rounding: a few units in the last place of the larger of
        // the eye's and the centre's coordinates, whatever the depth. Its centre may lie
        // that far to any side, so the circle certainly covered shrinks by it too.
        let rounding = self.rounding(center.abs().max_element());
        let rho = (radius - rounding) * ppw;
        let rho = rho * (1.0 - RADIUS_SHRINK_REL) - RADIUS_SHRINK_PX;
        if rho.is_nan() || rho <= 0.0 || !cx.is_finite() || !cy.is_finite() {
            return;
        }
        let r2 = radius * radius;
        let (sin_max, cos_min) = (self.sin_max, self.cos_min);
        // Depth bound at a sample `dist_px` from the projected centre (see `new`), moved
        // away from the eye whatever its sign (orthographic depths may be negative).
        let bound = |dist_px: f32| -> f32 {
            let a = dist_px / ppw;
            let inside = (r2 - a * a).max(0.0).sqrt() - a * sin_max;
            let b = d - cos_min * inside.max(0.0);
            b + b.abs() * DEPTH_GROW_REL + rounding
        };
        let rho2 = rho * rho;
        let (w, h) = (self.width as f32, self.height as f32);
        match self.mode {
            OcclusionMode::Off => {}
            OcclusionMode::PixelCentres => {
                let j0 = ceil_px(cy - rho - 0.5).max(0.0);
                let j1 = floor_px(cy + rho - 0.5).min(h - 1.0);
                let mut j = j0;
                while j <= j1 {
                    let dy = j + 0.5 - cy;
                    let hw2 = rho2 - dy * dy;
                    if hw2 >= 0.0 {
                        let hw = hw2.sqrt();
                        let i0 = ceil_px(cx - hw - 0.5).max(0.0);
                        let i1 = floor_px(cx + hw - 0.5).min(w - 1.0);
                        let mut i = i0;
                        while i <= i1 {
                            let dx = i + 0.5 - cx;
                            self.write(i as u32, j as u32, bound((dx * dx + dy * dy).sqrt()));
                            i += 1.0;
                        }
                    }
                    j += 1.0;
                }
            }
            OcclusionMode::WholePixels => {
                let j0 = ceil_px(cy - rho).max(0.0);
                let j1 = (floor_px(cy + rho) - 1.0).min(h - 1.0);
                let mut j = j0;
                while j <= j1 {
                    let dy = (j - cy).abs().max((j + 1.0 - cy).abs());
                    let hw2 = rho2 - dy * dy;
                    if hw2 >= 0.0 {
                        let hw = hw2.sqrt();
                        let i0 = ceil_px(cx - hw).max(0.0);
                        let i1 = (floor_px(cx + hw) - 1.0).min(w - 1.0);
                        let mut i = i0;
                        while i <= i1 {
                            let dx = (i - cx).abs().max((i + 1.0 - cx).abs());
                            self.write(i as u32, j as u32, bound((dx * dx + dy * dy).sqrt()));
                            i += 1.0;
                        }
                    }
                    j += 1.0;
                }
            }
        }
    }

    fn write(&mut self, x: u32, y: u32, depth: f32) {
        let i = (y * self.width + x) as usize;
        if depth >= self.levels[0][i] {
            return;
        }
        self.levels[0][i] = depth;
        self.pixels_written += 1;
        let (mut x, mut y) = (x, y);
        for k in 1..self.levels.len() {
            let (cw, ch) = self.dims[k - 1];
            let (px, py) = (x / 2, y / 2);
            let child = &self.levels[k - 1];
            let mut m = f32::NEG_INFINITY;
            for cy in 2 * py..(2 * py + 2).min(ch) {
                for cx in 2 * px..(2 * px + 2).min(cw) {
                    m = m.max(child[(cy * cw + cx) as usize]);
                }
            }
            let pw = self.dims[k].0;
            let slot = &mut self.levels[k][(py * pw + px) as usize];
            if m >= *slot {
                break;
            }
            *slot = m;
            (x, y) = (px, py);
        }
    }

    /// Largest stored depth over pixels `x0..=x1 × y0..=y1` (clipped to the image), or
    /// an upper bound of it.
    pub fn max_depth(&self, x0: u32, y0: u32, x1: u32, y1: u32) -> f32 {
        let (x1, y1) = (x1.min(self.width - 1), y1.min(self.height - 1));
        if x0 > x1 || y0 > y1 {
            return f32::NEG_INFINITY;
        }
        let mut k = 0;
        while k + 1 < self.levels.len()
            && ((x1 >> k) - (x0 >> k) >= QUERY_SPAN || (y1 >> k) - (y0 >> k) >= QUERY_SPAN)
        {
            k += 1;
        }
        let w = self.dims[k].0;
        let level = &self.levels[k];
        let mut m = f32::NEG_INFINITY;
        for y in (y0 >> k)..=(y1 >> k) {
            let row = &level[(y * w) as usize..][(x0 >> k) as usize..=(x1 >> k) as usize];
            for &v in row {
                m = m.max(v);
            }
            if m == f32::INFINITY {
                break;
            }
        }
        m
    }

    /// True when nothing inside the box `min..max` grown by `margin` can be seen past
    /// what is recorded.
    pub fn box_hidden(&self, min: Vec3, max: Vec3, margin: f32) -> bool {
        let (min, max) = (min - Vec3::splat(margin), max + Vec3::splat(margin));
        // Clip coordinates and view depths are affine in the point: the corners are the
        // lower corner's plus a sum of the edge vectors' images.
        let e = max - min;
        let (m, v) = (&self.clip_from_world, &self.view_from_world);
        let c0 = *m * min.extend(1.0);
        let (cx, cy, cz) = (m.x_axis * e.x, m.y_axis * e.y, m.z_axis * e.z);
        let d0 = -v.transform_point3(min).z;
        let (dx, dy, dz) = (-v.x_axis.z * e.x, -v.y_axis.z * e.y, -v.z_axis.z * e.z);
        let (w, h) = (self.image[0] as f32, self.image[1] as f32);
        let (ox, oy) = (self.origin[0] as f32, self.origin[1] as f32);
        let perspective = self.camera.projection == Projection::Perspective;
        // The corners' depths and clip coordinates first, then their divisions as one
        // loop over the eight (which the compiler can do four or eight at a time).
        let (mut d, mut qx, mut qy, mut qw) = ([0.0f32; 8], [0.0f32; 8], [0.0f32; 8], [0.0f32; 8]);
        for k in 0..8 {
            let (a, b, c) = (
                (k & 1) as f32, // 0 or 1
                ((k >> 1) & 1) as f32,
                ((k >> 2) & 1) as f32,
            );
            d[k] = d0 + a * dx + b * dy + c * dz;
            let q = c0 + cx * a + cy * b + cz * c;
            (qx[k], qy[k], qw[k]) = (q.x, q.y, q.w);
        }
        let near = self.camera.near;
        if (perspective && d.iter().any(|&d| d <= near))
            || qw.iter().any(|&q| q.is_nan() || q <= 0.0)
        {
            return false;
        }
        let (mut xs, mut ys) = ([0.0f32; 8], [0.0f32; 8]);
        for k in 0..8 {
            xs[k] = (qx[k] / qw[k] + 1.0) * 0.5 * w - ox;
            ys[k] = (1.0 - qy[k] / qw[k]) * 0.5 * h - oy;
        }
        let nearest = d.iter().fold(f32::INFINITY, |m, &v| m.min(v));
        let x0 = xs.iter().fold(f32::INFINITY, |m, &v| m.min(v));
        let y0 = ys.iter().fold(f32::INFINITY, |m, &v| m.min(v));
        let x1 = xs.iter().fold(f32::NEG_INFINITY, |m, &v| m.max(v));
        let y1 = ys.iter().fold(f32::NEG_INFINITY, |m, &v| m.max(v));
        if self.mode == OcclusionMode::PixelCentres
            && x1 - x0 <= EXACT_BOX_PX
            && y1 - y0 <= EXACT_BOX_PX
        {
            return self.box_samples_hidden(min, max, nearest, [x0, y0, x1, y1]);
        }
        self.rect_hidden(nearest, [x0, y0, x1, y1])
    }

    /// The box test of a small box, sample by sample: every pixel centre of the window
    /// inside `rect` whose ray enters the box `min..max` must have a recorded bound
    /// nearer than the depth where it enters.
    fn box_samples_hidden(&self, min: Vec3, max: Vec3, nearest: f32, rect: [f32; 4]) -> bool {
        // Grown against rounding (here, and in the GPU's transform of what the box
        // holds): rays that graze the box count as entering it.
        let coordinate = min.abs().max(max.abs()).max_element();
        let grow = (max - min).abs() * BOX_GROW_REL
            + Vec3::splat(BOX_GROW_REL * coordinate + self.rounding(coordinate));
        let (min, max) = (min - grow, max + grow);
        // The view-to-world map is rigid, so the ray's parameter stays the view depth.
        let [ax, ay, az] = self.axes;
        let to_world = |v: Vec3| ax * v.x + ay * v.y + az * v.z;
        self.samples_hidden(rect, nearest, |origin, dir| {
            let (origin, dir) = (self.eye + to_world(origin), to_world(dir));
            // Slabs: the ray is inside the box for t in [enter, leave].
            let (mut enter, mut leave) = (f32::NEG_INFINITY, f32::INFINITY);
            for k in 0..3 {
                let (o, d) = (origin[k], dir[k]);
                if d == 0.0 {
                    if o < min[k] || o > max[k] {
                        return None;
                    }
                    continue;
                }
                let (ta, tb) = ((min[k] - o) / d, (max[k] - o) / d);
                enter = enter.max(ta.min(tb));
                leave = leave.min(ta.max(tb));
            }
            // NaN anywhere counts as entering.
            let enters = enter.partial_cmp(&leave) != Some(std::cmp::Ordering::Greater);
            enters.then(|| enter.max(nearest))
        })
    }

    /// The sample-by-sample tests' common walk: every pixel centre of the window inside
    /// `rect` (grown by [`RECT_GROW_PX`]) whose recorded bound is not nearer than
    /// `nearest` (the shape's nearest depth: no ray enters it nearer) is given to
    /// `entry` as its view-space ray (origin, direction, parametrised by view depth),
    /// which returns where the ray enters the shape, or `None` on a miss. False as soon
    /// as an entry is not certainly behind its sample's bound (NaN counts as seen).
    fn samples_hidden(
        &self,
        [x0, y0, x1, y1]: [f32; 4],
        nearest: f32,
        entry: impl Fn(Vec3, Vec3) -> Option<f32>,
    ) -> bool {
        if !(nearest.is_finite()
            && x0.is_finite()
            && y0.is_finite()
            && x1.is_finite()
            && y1.is_finite())
        {
            return false;
        }
        let (w, h) = (self.width as f32, self.height as f32);
        let px0 = ceil_px(x0 - RECT_GROW_PX - 0.5).max(0.0);
        let py0 = ceil_px(y0 - RECT_GROW_PX - 0.5).max(0.0);
        let px1 = floor_px(x1 + RECT_GROW_PX - 0.5).min(w - 1.0);
        let py1 = floor_px(y1 + RECT_GROW_PX - 0.5).min(h - 1.0);
        if px0 > px1 || py0 > py1 {
            return true;
        }
        // (Whole numbers inside the window now.)
        let (px0, px1, py0, py1) = (px0 as usize, px1 as usize, py0 as usize, py1 as usize);
        let perspective = self.camera.projection == Projection::Perspective;
        let surely_behind = nearer(nearest);
        for (j, &ray_y) in self.ray_y[py0..=py1].iter().enumerate() {
            let row = &self.levels[0][(py0 + j) * self.width as usize..][px0..=px1];
            for (&bound, &ray_x) in row.iter().zip(&self.ray_x[px0..=px1]) {
                if bound >= surely_behind || bound.is_nan() {
                    let (origin, dir) = if perspective {
                        (Vec3::ZERO, Vec3::new(ray_x, ray_y, -1.0))
                    } else {
                        (Vec3::new(ray_x, ray_y, 0.0), Vec3::new(0.0, 0.0, -1.0))
                    };
                    if let Some(t) = entry(origin, dir) {
                        if bound.partial_cmp(&nearer(t)) != Some(std::cmp::Ordering::Less) {
                            return false;
                        }
                    }
                }
            }
        }
        true
    }

    /// True when nothing of the sphere can be seen past what is recorded: as
    /// [`Self::box_hidden`] for the box around it aligned with the view, whose nearest
    /// depth is the sphere's own (`depth − radius`).
    pub fn sphere_hidden(&self, centre: Vec3, radius: f32) -> bool {
        let v = self.view_from_world.transform_point3(centre);
        // Grown by what the GPU's own transform of the centre may differ by, so that a
        // ray grazing the sphere there is not a miss here.
        let radius = radius + self.rounding(centre.abs().max_element());
        let nearest = -v.z - radius;
        if !(nearest.is_finite() && radius >= 0.0)
            || (self.camera.projection == Projection::Perspective && nearest <= self.camera.near)
        {
            return false;
        }
        // The view-aligned box around the sphere, projected: a point's image x depends
        // on its view x and depth alone (x / depth in perspective, monotone in each), y
        // likewise, so the extremes come from the box's faces.
        let p = &self.clip_from_view;
        let (sx, sy) = (p.x_axis.x, p.y_axis.y);
        let ((nx0, nx1), (ny0, ny1)) = match self.camera.projection {
            Projection::Perspective => {
                let (near_t, far_t) = (nearest, -v.z + radius);
                // With 0 < near_t ≤ far_t the smaller quotient of a non-negative `a` is
                // by the larger depth, of a negative one by the smaller (division rounds
                // monotonically, so one division gives the number `min` of both would).
                let ordered = near_t > 0.0 && far_t >= near_t;
                let lo = |a: f32| match (ordered, a >= 0.0) {
                    (true, true) => a / far_t,
                    (true, false) if a < 0.0 => a / near_t,
                    _ => (a / near_t).min(a / far_t),
                };
                let hi = |a: f32| match (ordered, a >= 0.0) {
                    (true, true) => a / near_t,
                    (true, false) if a < 0.0 => a / far_t,
                    _ => (a / near_t).max(a / far_t),
                };
                (
                    (
                        sx * lo(v.x - radius) - p.z_axis.x,
                        sx * hi(v.x + radius) - p.z_axis.x,
                    ),
                    (
                        sy * lo(v.y - radius) - p.z_axis.y,
                        sy * hi(v.y + radius) - p.z_axis.y,
                    ),
                )
            }
            Projection::Orthographic => (
                (
                    sx * (v.x - radius) + p.w_axis.x,
                    sx * (v.x + radius) + p.w_axis.x,
                ),
                (
                    sy * (v.y - radius) + p.w_axis.y,
                    sy * (v.y + radius) + p.w_axis.y,
                ),
            ),
        };
        let (w, h) = (self.image[0] as f32, self.image[1] as f32);
        let (ox, oy) = (self.origin[0] as f32, self.origin[1] as f32);
        let (x0, x1) = ((nx0 + 1.0) * 0.5 * w - ox, (nx1 + 1.0) * 0.5 * w - ox);
        let (y0, y1) = ((1.0 - ny1) * 0.5 * h - oy, (1.0 - ny0) * 0.5 * h - oy);
        if self.mode == OcclusionMode::PixelCentres
            && x1 - x0 <= EXACT_SPHERE_PX
            && y1 - y0 <= EXACT_SPHERE_PX
        {
            return self.sphere_samples_hidden(v, radius, [x0, y0, x1, y1]);
        }
        self.rect_hidden(nearest, [x0, y0, x1, y1])
    }

    /// The sphere test of a small sphere, sample by sample: every pixel centre of the
    /// window inside `rect` whose ray enters the sphere (centre `v` in view space) must
    /// have a recorded bound nearer than that entry depth.
    fn sphere_samples_hidden(&self, v: Vec3, radius: f32, rect: [f32; 4]) -> bool {
        let r2 = radius * radius;
        self.samples_hidden(rect, -v.z - radius, |origin, dir| {
            // Measured from the ray's point closest to the centre, as the GPU does: the
            // textbook quadratic from the ray's origin loses every digit of a small
            // sphere's radius to its distance (|v|² against r²).
            let a = dir.dot(dir);
            let tc = dir.dot(v - origin) / a;
            let q = v - (origin + dir * tc);
            let disc = r2 - q.dot(q);
            (disc >= 0.0).then(|| tc - (disc / a).sqrt())
        })
    }

    /// True when every sample of the window inside the image rectangle `x0, y0, x1, y1`
    /// (window pixels) has a recorded bound nearer than `nearest`, or when there is none.
    fn rect_hidden(&self, nearest: f32, [x0, y0, x1, y1]: [f32; 4]) -> bool {
        if !(nearest.is_finite() && x0.is_finite() && y0.is_finite()) || x1.is_nan() || y1.is_nan()
        {
            return false;
        }
        let (x0, y0, x1, y1) = (
            x0 - RECT_GROW_PX,
            y0 - RECT_GROW_PX,
            x1 + RECT_GROW_PX,
            y1 + RECT_GROW_PX,
        );
        // Pixels whose samples can fall inside the rectangle.
        let (px0, py0, px1, py1) = match self.mode {
            OcclusionMode::PixelCentres => (
                ceil_px(x0 - 0.5),
                ceil_px(y0 - 0.5),
                floor_px(x1 - 0.5),
                floor_px(y1 - 0.5),
            ),
            _ => (floor_px(x0), floor_px(y0), floor_px(x1), floor_px(y1)),
        };
        let (w, h) = (self.width as f32, self.height as f32);
        let (px0, py0) = (px0.max(0.0), py0.max(0.0));
        let (px1, py1) = (px1.min(w - 1.0), py1.min(h - 1.0));
        if px0 > px1 || py0 > py1 {
            // No sample of the window can see it.
            return true;
        }
        let far = self.max_depth(px0 as u32, py0 as u32, px1 as u32, py1 as u32);
        nearest > far
    }
}

/// `x.floor()` for the pixel coordinates of these tests without a call into libm (the
/// baseline x86-64 target has no rounding instruction). Exact for finite values below
/// 2^31 in magnitude; larger ones and infinities come out at about ±2^31, which every
/// caller clamps to the image as it did the infinities; callers keep NaN out.
#[inline]
fn floor_px(x: f32) -> f32 {
    let t = x as i32 as f32;
    if t > x {
        t - 1.0
    } else {
        t
    }
}

/// `x.ceil()` likewise (see [`floor_px`]).
#[inline]
fn ceil_px(x: f32) -> f32 {
    let t = x as i32 as f32;
    if t < x {
        t + 1.0
    } else {
        t
    }
}

/// A depth moved towards the eye by [`SAMPLE_DEPTH_SHRINK_REL`] of its size, whatever
/// its sign (orthographic depths may be negative).
#[inline]
fn nearer(depth: f32) -> f32 {
    depth - depth.abs() * SAMPLE_DEPTH_SHRINK_REL
}

/// Pixels per world unit at view depth `d`.
fn rho_px_per_world(camera: &Camera, d: f32, height: u32) -> f32 {
    camera.pixels_per_world(d, height)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The libm-free rounding agrees with `floor` and `ceil` wherever it is exact, and
    /// lands beyond any image where it is not.
    #[test]
    fn pixel_rounding_matches_floor_and_ceil() {
        let mut values = vec![
            0.0f32, -0.0, 0.5, -0.5, 1.0, -1.0, 1e-7, -1e-7, 1279.5, -3.25,
        ];
        values.extend([8_388_607.5, 16_777_216.0, -16_777_217.0, 2.0e9, -2.0e9]);
        let mut v = -300.0f32;
        while v < 300.0 {
            values.push(v);
            v += 0.173;
        }
        for x in values {
            assert_eq!(floor_px(x), x.floor(), "{x}");
            assert_eq!(ceil_px(x), x.ceil(), "{x}");
        }
        for x in [3.0e9f32, f32::INFINITY, 1e30] {
            assert!(floor_px(x) >= 2.0e9 && ceil_px(x) >= 2.0e9, "{x}");
            assert!(floor_px(-x) <= -2.0e9 && ceil_px(-x) <= -2.0e9, "{x}");
        }
    }
    use crate::camera::Bounds;
    use glam::DVec3;

    fn camera(projection: Projection) -> Camera {
        let mut c = Camera {
            projection,
            ..Default::default()
        };
        let b = Bounds::new([-10.0; 3], [10.0; 3]);
        c.fit(&b, 1.5);
        c.fit_depth_range(&b);
        c
    }

    #[test]
    fn pyramid_max_matches_brute_force() {
        let cam = camera(Projection::Perspective);
        let mut buf = OcclusionBuffer::new(&cam, [37, 23], OcclusionMode::PixelCentres).unwrap();
        let mut state = 12345u64;
        let mut rnd = move || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 33) as u32
        };
        // Every pixel written (an unwritten one is +inf, which every query would see),
        // then lowered at random.
        for y in 0..23 {
            for x in 0..37 {
                buf.write(x, y, 1000.0 + (rnd() % 1000) as f32);
            }
        }
        for _ in 0..400 {
            let (x, y) = (rnd() % 37, rnd() % 23);
            buf.write(x, y, (rnd() % 1000) as f32);
        }
        let brute = |x0: u32, y0: u32, x1: u32, y1: u32| {
            let mut m = f32::NEG_INFINITY;
            for y in y0..=y1.min(22) {
                for x in x0..=x1.min(36) {
                    m = m.max(buf.depth_at(x, y));
                }
            }
            m
        };
        for _ in 0..2000 {
            let (xa, xb) = (rnd() % 37, rnd() % 37);
            let (ya, yb) = (rnd() % 23, rnd() % 23);
            let (x0, x1, y0, y1) = (xa.min(xb), xa.max(xb), ya.min(yb), ya.max(yb));
            let exact = brute(x0, y0, x1, y1);
            let got = buf.max_depth(x0, y0, x1, y1);
            assert!(got >= exact, "pyramid {got} below the true maximum {exact}");
            // And no more than the maximum over the texels of the level it reads, which
            // cover the rectangle (not, say, the whole image's maximum).
            let mut k = 0;
            while (x1 >> k) - (x0 >> k) >= QUERY_SPAN || (y1 >> k) - (y0 >> k) >= QUERY_SPAN {
                k += 1;
            }
            let cover = brute(
                (x0 >> k) << k,
                (y0 >> k) << k,
                (((x1 >> k) + 1) << k) - 1,
                (((y1 >> k) + 1) << k) - 1,
            );
            assert!(
                got <= cover,
                "pyramid {got} above its texels' maximum {cover}"
            );
            if x0 == x1 && y0 == y1 {
                assert_eq!(got, exact);
            }
        }
        // Fill everything: the root is then the global maximum.
        for y in 0..23 {
            for x in 0..37 {
                buf.write(x, y, 5.0);
            }
        }
        assert_eq!(buf.max_depth(0, 0, 36, 22), 5.0);
    }

    #[test]
    fn a_box_behind_a_large_sphere_is_hidden_and_one_in_front_is_not() {
        for projection in [Projection::Perspective, Projection::Orthographic] {
            for mode in [OcclusionMode::PixelCentres, OcclusionMode::WholePixels] {
                let cam = camera(projection);
                let mut buf = OcclusionBuffer::new(&cam, [96, 64], mode).unwrap();
                let toward_eye = cam.back();
                // A big sphere at the target, a small box well behind it and one in front.
                buf.add_sphere(Vec3::ZERO, 6.0);
                let behind = -toward_eye * 8.0;
                let front = toward_eye * 8.0;
                let half = Vec3::splat(0.5);
                assert!(
                    buf.box_hidden(behind - half, behind + half, 0.0),
                    "{projection:?} {mode:?}"
                );
                assert!(!buf.box_hidden(front - half, front + half, 0.0));
                // Grown past the sphere's silhouette, the box behind shows.
                assert!(!buf.box_hidden(behind - half, behind + half, 7.0));
                // Nothing recorded where the sphere is absent.
                let side = cam.right() * 9.0 - toward_eye * 8.0;
                assert!(!buf.box_hidden(side - half, side + half, 0.0));
            }
        }
    }

    #[test]
    fn a_window_records_and_tests_exactly_what_the_whole_image_does_there() {
        let cam = camera(Projection::Perspective);
        let (w, h) = (96u32, 64u32);
        let (origin, size) = ([40u32, 24u32], [32u32, 32u32]);
        for mode in [OcclusionMode::PixelCentres, OcclusionMode::WholePixels] {
            let mut whole = OcclusionBuffer::new(&cam, [w, h], mode).unwrap();
            let mut tile = OcclusionBuffer::window(&cam, [w, h], mode, origin, size).unwrap();
            let spheres = [
                (Vec3::ZERO, 3.0),
                (cam.right() * 4.0 + cam.up() * 2.0, 2.5),
                (cam.right() * -7.0, 4.0),
            ];
            for &(c, r) in &spheres {
                whole.add_sphere(c, r);
                tile.add_sphere(c, r);
            }
            let mut recorded = 0;
            for y in 0..size[1] {
                for x in 0..size[0] {
                    let d = tile.depth_at(x, y);
                    assert_eq!(d, whole.depth_at(origin[0] + x, origin[1] + y));
                    recorded += usize::from(d.is_finite());
                }
            }
            assert!(recorded > 100, "{mode:?}: {recorded} pixels recorded");
            // A box behind the spheres inside the window: hidden in both. One whose
            // pixels all lie outside the window: the window cannot see it.
            let toward_eye = cam.back();
            let half = Vec3::splat(0.3);
            let behind = -toward_eye * 6.0;
            assert!(whole.box_hidden(behind - half, behind + half, 0.0));
            assert!(tile.box_hidden(behind - half, behind + half, 0.0));
            let outside = cam.right() * -9.0 + cam.up() * 5.0 + toward_eye * 8.0;
            assert!(!whole.box_hidden(outside - half, outside + half, 0.0));
            assert!(tile.box_hidden(outside - half, outside + half, 0.0));
        }
        // Clipped to the image; nothing left is no buffer.
        let clipped = OcclusionBuffer::window(
            &cam,
            [w, h],
            OcclusionMode::PixelCentres,
            [80, 60],
            [32, 32],
        )
        .unwrap();
        assert_eq!((clipped.width, clipped.height), (16, 4));
        assert!(OcclusionBuffer::window(
            &cam,
            [w, h],
            OcclusionMode::PixelCentres,
            [96, 0],
            [8, 8]
        )
        .is_none());
    }

    /// Random occluders, then 400 random shapes around random centres (`make`): whenever
    /// `hidden` says one is hidden, no pixel centre's ray (CPU ray casting; `entry` gives
    /// the ray parameter where a unit-speed ray enters the shape) reaches it nearer than
    /// the bound recorded there; and more than 20 are hidden.
    fn check_hidden_shapes<S>(
        seed: u64,
        make: impl Fn(&mut dyn FnMut() -> f32, Vec3, usize) -> S,
        hidden: impl Fn(&OcclusionBuffer, &S) -> bool,
        entry: impl Fn(&S, Vec3, Vec3) -> Option<f32>,
    ) {
        for projection in [Projection::Perspective, Projection::Orthographic] {
            let cam = camera(projection);
            let (w, h) = (64u32, 48u32);
            let mut buf = OcclusionBuffer::new(&cam, [w, h], OcclusionMode::PixelCentres).unwrap();
            let mut state = seed;
            let mut rnd = move || {
                state = state
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                (state >> 40) as f32 / (1u64 << 24) as f32
            };
            let toward_eye = cam.back();
            for _ in 0..60 {
                let c = cam.right() * (rnd() * 16.0 - 8.0)
                    + cam.up() * (rnd() * 12.0 - 6.0)
                    + toward_eye * (rnd() * 4.0);
                buf.add_sphere(c, 1.0 + rnd() * 2.0);
            }
            let clip_inv = buf.clip_from_world.inverse();
            let mut count = 0;
            for k in 0..400 {
                let c = cam.right() * (rnd() * 18.0 - 9.0) + cam.up() * (rnd() * 14.0 - 7.0)
                    - toward_eye * (rnd() * 8.0 - 2.0);
                let shape = make(&mut rnd, c, k);
                if !hidden(&buf, &shape) {
                    continue;
                }
                count += 1;
                for y in 0..h {
                    for x in 0..w {
                        let ndc_x = (x as f32 + 0.5) / w as f32 * 2.0 - 1.0;
                        let ndc_y = 1.0 - (y as f32 + 0.5) / h as f32 * 2.0;
                        let (eye, dir) = match projection {
                            Projection::Perspective => {
                                let p = clip_inv.project_point3(Vec3::new(ndc_x, ndc_y, 0.5));
                                (cam.eye(), (p - cam.eye()).normalize())
                            }
                            Projection::Orthographic => {
                                let p = clip_inv.project_point3(Vec3::new(ndc_x, ndc_y, 0.0));
                                (p, -toward_eye)
                            }
                        };
                        let Some(t) = entry(&shape, eye, dir) else {
                            continue;
                        };
                        let hit = buf.depth(eye + dir * t);
                        assert!(
                            buf.depth_at(x, y) < hit,
                            "{projection:?}: pixel ({x}, {y}) sees a hidden shape at {hit}"
                        );
                    }
                }
            }
            assert!(count > 20, "{projection:?}: only {count} shapes hidden");
        }
    }

    #[test]
    fn a_hidden_sphere_has_no_pixel_whose_ray_meets_it_before_the_recorded_bound() {
        check_hidden_shapes(
            99,
            |rnd, c, _| (c, 0.2 + rnd()),
            |buf, &(c, r)| buf.sphere_hidden(c, r),
            |&(c, r), eye, dir| {
                let oc = eye - c;
                let b = oc.dot(dir);
                let disc = b * b - (oc.dot(oc) - r * r);
                (disc >= 0.0).then(|| -b - disc.sqrt())
            },
        );
    }

    /// Where the ray `origin + t · dir` enters the box `lo..hi` in double precision: the
    /// smallest `t ≥ t_min` inside it, or `None` when it misses.
    fn slab_entry(o: DVec3, d: DVec3, lo: DVec3, hi: DVec3, t_min: f64) -> Option<f64> {
        let (mut t0, mut t1) = (t_min, f64::INFINITY);
        for k in 0..3 {
            if d[k] == 0.0 {
                if o[k] < lo[k] || o[k] > hi[k] {
                    return None;
                }
                continue;
            }
            let (u, v) = ((lo[k] - o[k]) / d[k], (hi[k] - o[k]) / d[k]);
            t0 = t0.max(u.min(v));
            t1 = t1.min(u.max(v));
        }
        (t0 <= t1 && t0.is_finite()).then_some(t0)
    }

    /// Where the ray `origin + t · dir` enters the box `min..max`: the smallest `t ≥ 0`
    /// inside it (0 when the origin is inside), or `None` when it misses.
    fn ray_box_entry(origin: Vec3, dir: Vec3, min: Vec3, max: Vec3) -> Option<f32> {
        let d = |v: Vec3| v.as_dvec3();
        slab_entry(d(origin), d(dir), d(min), d(max), 0.0).map(|t| t as f32)
    }

    #[test]
    fn a_hidden_box_has_no_pixel_whose_ray_meets_it_before_the_recorded_bound() {
        // Small boxes and, one in four, larger ones; each grown by a random margin.
        check_hidden_shapes(
            7,
            |rnd, c, k| {
                let half = Vec3::new(rnd(), rnd(), rnd()) * if k % 4 == 0 { 3.0 } else { 0.8 };
                (c - half, c + half, rnd() * 0.3)
            },
            |buf, &(lo, hi, margin)| buf.box_hidden(lo, hi, margin),
            |&(lo, hi, margin), eye, dir| {
                ray_box_entry(eye, dir, lo - Vec3::splat(margin), hi + Vec3::splat(margin))
            },
        );
    }

    /// A far camera with a narrow field of view, as for a large data set seen whole:
    /// spheres of about a pixel at thousands of radii from the eye.
    fn far_camera(projection: Projection) -> Camera {
        let mut c = Camera {
            projection,
            fov_y_deg: 0.5,
            ..Default::default()
        };
        let b = Bounds::new([-10.0; 3], [10.0; 3]);
        c.fit(&b, 1.5);
        assert!(c.distance > 3000.0, "{}", c.distance);
        c
    }

    /// The pixel centre `(x, y)`'s ray in view space, exact to double precision,
    /// parametrised by view depth: origin and direction.
    fn exact_view_ray(buf: &OcclusionBuffer, x: u32, y: u32) -> (DVec3, DVec3) {
        let p = buf.clip_from_view.as_dmat4();
        let ndc_x = (f64::from(x) + 0.5) / f64::from(buf.image[0]) * 2.0 - 1.0;
        let ndc_y = 1.0 - (f64::from(y) + 0.5) / f64::from(buf.image[1]) * 2.0;
        match buf.camera.projection {
            Projection::Perspective => (
                DVec3::ZERO,
                DVec3::new(
                    (ndc_x + p.z_axis.x) / p.x_axis.x,
                    (ndc_y + p.z_axis.y) / p.y_axis.y,
                    -1.0,
                ),
            ),
            Projection::Orthographic => (
                DVec3::new(
                    (ndc_x - p.w_axis.x) / p.x_axis.x,
                    (ndc_y - p.w_axis.y) / p.y_axis.y,
                    0.0,
                ),
                DVec3::new(0.0, 0.0, -1.0),
            ),
        }
    }

    /// Where the pixel centre `(x, y)`'s exact ray enters the sphere of view-space
    /// centre `v` (its view depth).
    fn exact_sphere_entry(buf: &OcclusionBuffer, x: u32, y: u32, v: DVec3, r: f64) -> Option<f64> {
        let (origin, dir) = exact_view_ray(buf, x, y);
        let a = dir.dot(dir);
        let tc = dir.dot(v - origin) / a;
        let q = v - (origin + dir * tc);
        let disc = r * r - q.dot(q);
        (disc >= 0.0).then(|| tc - (disc / a).sqrt())
    }

    /// Where the pixel centre `(x, y)`'s exact ray enters the world-space box `lo..hi`
    /// (its view depth).
    fn exact_box_entry(buf: &OcclusionBuffer, x: u32, y: u32, lo: DVec3, hi: DVec3) -> Option<f64> {
        let world_from_view = buf.view_from_world.as_dmat4().inverse();
        let (o, d) = exact_view_ray(buf, x, y);
        let (o, d) = (
            world_from_view.transform_point3(o),
            world_from_view.transform_vector3(d),
        );
        slab_entry(o, d, lo, hi, f64::NEG_INFINITY)
    }

    /// In both projections, from a far camera (64×48): 150 random occluders 2 to 4 units
    /// towards the eye, then 2000 shapes (`make`, around random centres −2 to 2 units
    /// deep). A shape that some pixel sees clearly (`entry` gives its exact entry depth
    /// at a pixel for the shape shrunk or grown by `grow`: shrunk by 1 %, before the
    /// bound) must not be `hidden`; one that no pixel can see (grown by 1 %) must be. At
    /// least 200 of each.
    fn check_far_shapes<S: std::fmt::Debug>(
        seed: u64,
        make: impl Fn(&mut dyn FnMut() -> f32, Vec3) -> S,
        hidden: impl Fn(&OcclusionBuffer, &S) -> bool,
        entry: impl Fn(&OcclusionBuffer, u32, u32, &S, f64) -> Option<f64>,
    ) {
        for projection in [Projection::Perspective, Projection::Orthographic] {
            let cam = far_camera(projection);
            let (w, h) = (64u32, 48u32);
            let mut buf = OcclusionBuffer::new(&cam, [w, h], OcclusionMode::PixelCentres).unwrap();
            let mut state = seed;
            let mut rnd = move || {
                state = state
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                (state >> 40) as f32 / (1u64 << 24) as f32
            };
            let at = |rnd: &mut dyn FnMut() -> f32, depth: f32| {
                cam.right() * (rnd() * 20.0 - 10.0)
                    + cam.up() * (rnd() * 14.0 - 7.0)
                    + cam.back() * depth
            };
            for _ in 0..150 {
                let depth = 2.0 + rnd() * 2.0;
                let c = at(&mut rnd, depth);
                buf.add_sphere(c, 0.3 + rnd() * 0.6);
            }
            let (mut seen, mut unseen) = (0, 0);
            for _ in 0..2000 {
                let depth = rnd() * 4.0 - 2.0;
                let c = at(&mut rnd, depth);
                let shape = make(&mut rnd, c);
                let sees = |grow: f64, bound_scale: f64| {
                    (0..h).any(|y| {
                        (0..w).any(|x| {
                            entry(&buf, x, y, &shape, grow)
                                .is_some_and(|t| f64::from(buf.depth_at(x, y)) >= t * bound_scale)
                        })
                    })
                };
                let got = hidden(&buf, &shape);
                if sees(0.99, 1.0 + 1e-4) {
                    seen += 1;
                    assert!(!got, "{projection:?}: visible {shape:?} is hidden");
                } else if !sees(1.01, 1.0 - 1e-4) {
                    unseen += 1;
                    assert!(
                        got,
                        "{projection:?}: {shape:?}, which no pixel sees, is kept"
                    );
                }
            }
            assert!(
                seen > 200 && unseen > 200,
                "{projection:?}: {seen} seen, {unseen} unseen"
            );
        }
    }

    #[test]
    fn small_spheres_far_from_the_eye_are_tested_as_exactly_as_the_gpu_draws_them() {
        // A sphere of a pixel at 5000 radii from the eye: the textbook ray-sphere
        // quadratic in single precision (|o − c|² − r² with |o − c|² ≈ 2.5·10⁷ r²) keeps
        // no digit of r and both hid visible spheres and showed hidden ones. Against
        // double-precision rays, both ways, so the test also stays tight enough to cull.
        check_far_shapes(
            2024,
            |rnd, c| (c, 0.2 + rnd() * 0.6),
            |buf, &(c, r)| buf.sphere_hidden(c, r),
            |buf, x, y, &(c, r), grow| {
                let v = buf
                    .view_from_world
                    .as_dmat4()
                    .transform_point3(c.as_dvec3());
                exact_sphere_entry(buf, x, y, v, f64::from(r) * grow)
            },
        );
    }

    #[test]
    fn small_boxes_far_from_the_eye_are_tested_pixel_by_pixel() {
        // A small box is hidden exactly when no pixel centre's ray enters it before the
        // recorded bound (double-precision slabs), so a cluster whose box pokes only
        // into gaps between nearer spheres is still dropped whole.
        check_far_shapes(
            77,
            |rnd, c| {
                let half = Vec3::new(rnd(), rnd(), rnd()) * 0.8 + Vec3::splat(0.05);
                (c - half, c + half)
            },
            |buf, &(lo, hi)| buf.box_hidden(lo, hi, 0.0),
            |buf, x, y, &(lo, hi), grow| {
                let g = (hi - lo).as_dvec3() * 0.5 * (grow - 1.0);
                exact_box_entry(buf, x, y, lo.as_dvec3() - g, hi.as_dvec3() + g)
            },
        );
    }

    #[test]
    fn recorded_bounds_stay_behind_the_surface_at_negative_depths() {
        // Orthographic, with the eye's plane 5 units in front of a sphere's centre
        // (depths are negative there): every recorded bound is at or behind the exact
        // hit at its pixel. Growing a bound by a relative 10⁻⁵ moved a negative one
        // nearer, in front of the sphere it came from.
        let mut cam = camera(Projection::Orthographic);
        cam.distance = 2.0;
        cam.near = -50.0;
        cam.far = 50.0;
        let (w, h) = (48u32, 36u32);
        let mut buf = OcclusionBuffer::new(&cam, [w, h], OcclusionMode::PixelCentres).unwrap();
        let c = cam.eye() + cam.back() * 5.0 + cam.right() * 0.7;
        let r = 6.0f64;
        buf.add_sphere(c, r as f32);
        let view = buf.view_from_world.as_dmat4();
        let v = view.transform_point3(c.as_dvec3());
        let mut checked = 0;
        for y in 0..h {
            for x in 0..w {
                let bound = buf.depth_at(x, y);
                if !bound.is_finite() {
                    continue;
                }
                let t = exact_sphere_entry(&buf, x, y, v, r).expect("a recorded pixel's ray hits");
                assert!(t < 0.0, "depth {t}");
                assert!(
                    f64::from(bound) >= t,
                    "({x}, {y}): bound {bound} in front of the hit {t}"
                );
                checked += 1;
            }
        }
        assert!(checked > 300, "{checked} pixels");
    }

    #[test]
    fn recorded_pixels_stay_inside_the_silhouette_wherever_rounding_puts_the_centre() {
        // A sphere of radius 1.5 at coordinates of 10⁴, seen from 40 units through a 3°
        // field (its silhouette nearly its central disk): 23 px per unit, and the GPU's
        // centre may lie about 0.01 units (0.2 px) from this buffer's.
        let cam = Camera {
            target: Vec3::splat(1.0e4),
            distance: 40.0,
            fov_y_deg: 3.0,
            near: 1.0,
            far: 100.0,
            ..Default::default()
        };
        let (w, h) = (64u32, 48u32);
        let mut buf = OcclusionBuffer::new(&cam, [w, h], OcclusionMode::PixelCentres).unwrap();
        let (c, r) = (cam.target, 1.5f64);
        buf.add_sphere(c, r as f32);
        let slack = f64::from(buf.rounding(c.abs().max_element()));
        assert!(slack > 0.005, "{slack}");
        let v = buf
            .view_from_world
            .as_dmat4()
            .transform_point3(c.as_dvec3());
        let mut marked = 0;
        for y in 0..h {
            for x in 0..w {
                if !buf.depth_at(x, y).is_finite() {
                    continue;
                }
                marked += 1;
                let (o, d) = exact_view_ray(&buf, x, y);
                let dist = (v - o).cross(d).length() / d.length();
                assert!(
                    dist <= r - 0.5 * slack,
                    "pixel ({x}, {y}) marked {:.4} from the silhouette (slack {slack:.4})",
                    r - dist
                );
            }
        }
        assert!(marked > 1000, "only {marked} pixels marked");
    }

    #[test]
    fn recorded_pixels_are_inside_the_sphere_silhouette() {
        // Every pixel marked by a sphere has its sample ray hit the sphere at a depth no
        // larger than the recorded one (checked with a CPU ray-sphere intersection).
        let cam = camera(Projection::Perspective);
        let (w, h) = (64u32, 48u32);
        for mode in [OcclusionMode::PixelCentres, OcclusionMode::WholePixels] {
            let mut buf = OcclusionBuffer::new(&cam, [w, h], mode).unwrap();
            let c = cam.right() * 3.0 + cam.up() * 1.5;
            let r = 4.0;
            buf.add_sphere(c, r);
            let clip_inv = buf.clip_from_world.inverse();
            let eye = cam.eye();
            let mut marked = 0;
            for y in 0..h {
                for x in 0..w {
                    let d = buf.depth_at(x, y);
                    if !d.is_finite() {
                        continue;
                    }
                    marked += 1;
                    let samples: &[(f32, f32)] = match mode {
                        OcclusionMode::PixelCentres => &[(0.5, 0.5)],
                        _ => &[(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0), (0.5, 0.5)],
                    };
                    for &(sx, sy) in samples {
                        let ndc_x = (x as f32 + sx) / w as f32 * 2.0 - 1.0;
                        let ndc_y = 1.0 - (y as f32 + sy) / h as f32 * 2.0;
                        let p = clip_inv.project_point3(Vec3::new(ndc_x, ndc_y, 0.5));
                        let dir = (p - eye).normalize();
                        let oc = eye - c;
                        let b = oc.dot(dir);
                        let disc = b * b - (oc.dot(oc) - r * r);
                        assert!(disc >= 0.0, "pixel ({x}, {y}) marked but its ray misses");
                        let t = -b - disc.sqrt();
                        let hit_depth = buf.depth(eye + dir * t);
                        assert!(hit_depth <= d, "hit at {hit_depth} behind the bound {d}");
                    }
                }
            }
            assert!(marked > 40, "{mode:?}: only {marked} pixels marked");
        }
    }
}
