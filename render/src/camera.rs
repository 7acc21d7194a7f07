//! The orbit camera: a target point, a direction given by azimuth and elevation, a
//! distance, and a perspective or orthographic projection.
//!
//! How it works: the world is Z-up (as most MD boxes are drawn). The camera sits at
//! `target + distance · (cos e cos a, cos e sin a, sin e)` for azimuth `a` and elevation
//! `e`, and looks at the target. Its right vector is `(−sin a, cos a, 0)` and its up
//! vector completes a right-handed frame, so looking straight down (e = ±90°) is as
//! well defined as any other view. View space is right-handed with the camera looking
//! down −Z; clip space is WebGPU's (depth in [0, 1]), built with
//! `glam::camera::rh::proj::directx` (glam 0.34 dropped `Mat4::perspective_rh`).
//!
//! Orthographic views show a height of `2 · distance · tan(fov_y / 2)` world units, the
//! height a perspective view shows at the target, so zooming (changing the distance)
//! works the same in both and switching projections keeps the target's framing.
//! A fitted view ([`Camera::fit_boxes`]) projects boxes (the data's clusters) as the
//! camera's direction sees them, fills [`FIT_FILL`] of the image with them and centres
//! them, moving the target off the data's centre in perspective. The distance depends on
//! the direction, so a turntable ([`Camera::fit_about_centre`]) takes the largest of its
//! views' distances for all of them.
//! `near`/`far` are explicit; [`Camera::fit_depth_range`] sets them around a box.

use glam::{Mat4, Vec2, Vec3, Vec4};
use serde::{Deserialize, Serialize};

/// The kind of projection.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Projection {
    #[default]
    Perspective,
    Orthographic,
}

/// An axis-aligned box in world space.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bounds {
    pub min: Vec3,
    pub max: Vec3,
}

impl Bounds {
    pub fn new(min: impl Into<Vec3>, max: impl Into<Vec3>) -> Self {
        Bounds {
            min: min.into(),
            max: max.into(),
        }
    }

    pub fn center(&self) -> Vec3 {
        // Halved first: the sum of coordinates near f32::MAX overflows.
        self.min * 0.5 + self.max * 0.5
    }

    /// Radius of the sphere through the corners, around [`Self::center`]. In double
    /// precision: the squared extent of data spanning 10^20 (stars in metres) overflows
    /// single precision.
    pub fn radius(&self) -> f32 {
        ((self.max.as_dvec3() - self.min.as_dvec3()).length() * 0.5) as f32
    }

    /// The radius a view is fitted to: [`Self::radius`], or for bounds of no extent a
    /// millionth of their distance from the origin, so that the fit scales with the data
    /// at any size (data in metres spans 10^-10).
    pub fn fit_radius(&self) -> f32 {
        let r = self.radius();
        if r > 0.0 {
            r
        } else {
            (self.center().abs().max_element() * 1e-6).max(1e-30)
        }
    }
}

/// What a fitted view frames: a box, seen by its eight corners (a cluster, the cell), or
/// a ball, seen by its outline (a particle's sphere as drawn: framed by its box's
/// corners, a lone sphere filled 54-65 % of the image instead of [`FIT_FILL`], off
/// centre).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Framed {
    Box(Bounds),
    Ball { centre: Vec3, radius: f32 },
}

impl From<Bounds> for Framed {
    fn from(b: Bounds) -> Self {
        Framed::Box(b)
    }
}

impl Framed {
    /// The box around it.
    pub fn hull(&self) -> Bounds {
        match *self {
            Framed::Box(b) => b,
            Framed::Ball { centre, radius } => {
                Bounds::new(centre - Vec3::splat(radius), centre + Vec3::splat(radius))
            }
        }
    }

    /// Its points as the fit sees them, in double precision: a box's corners (radius 0),
    /// or a ball's centre with its radius.
    fn points(&self) -> impl Iterator<Item = (glam::DVec3, f64)> {
        let (corners, ball) = match *self {
            Framed::Box(b) => (Some(corners(&b)), None),
            Framed::Ball { centre, radius } => {
                (None, Some((centre.as_dvec3(), f64::from(radius.max(0.0)))))
            }
        };
        corners.into_iter().flatten().map(|c| (c, 0.0)).chain(ball)
    }
}

/// The eight corners of a box, in double precision.
pub fn corners(b: &Bounds) -> [glam::DVec3; 8] {
    std::array::from_fn(|i| {
        let pick = |bit: usize, lo: f32, hi: f32| f64::from(if i & bit == 0 { lo } else { hi });
        glam::DVec3::new(
            pick(1, b.min.x, b.max.x),
            pick(2, b.min.y, b.max.y),
            pick(4, b.min.z, b.max.z),
        )
    })
}

/// The share of the image's width or height a fitted view's data spans, in the tighter of
/// the two: a margin of 5 % on each side.
pub const FIT_FILL: f64 = 0.9;

/// A part of the image a fit frames the data in, in normalised device coordinates (x
/// right, y up; the whole image is −1..1 on both axes): the image less the corner a
/// legend is drawn in, say.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FitWindow {
    pub min: [f64; 2],
    pub max: [f64; 2],
}

impl FitWindow {
    /// The whole image.
    pub const WHOLE: FitWindow = FitWindow {
        min: [-1.0, -1.0],
        max: [1.0, 1.0],
    };

    /// The window's centre and half sizes, in normalised device coordinates; `None` for a
    /// window that is empty, not finite or not inside the image.
    pub fn centre_and_half(&self) -> Option<([f64; 2], [f64; 2])> {
        let ok = (0..2).all(|k| {
            self.min[k].is_finite()
                && self.max[k].is_finite()
                && self.min[k] < self.max[k]
                && self.min[k] >= -1.0
                && self.max[k] <= 1.0
        });
        ok.then(|| {
            (
                [0, 1].map(|k| 0.5 * (self.min[k] + self.max[k])),
                [0, 1].map(|k| 0.5 * (self.max[k] - self.min[k])),
            )
        })
    }
}

/// Steps that move a camera's target until the data's projection lies where it should:
/// each moves the target by the projection's offset as seen at the target's depth. In
/// perspective, corners nearer than the target move further on screen than that depth
/// says, up to twice as far off the image's centre: each axis's step is scaled by the
/// inverse of the response its last step had (a secant step), which settles where a full
/// step would swing from side to side.
struct Recentring {
    gain: [f64; 2],
    /// The last step's offset and step.
    last: Option<([f64; 2], [f64; 2])>,
}

impl Recentring {
    fn new() -> Self {
        Recentring {
            gain: [1.0; 2],
            last: None,
        }
    }

    /// Moves `camera`'s target to undo `off`, the projection's offset (normalised device
    /// coordinates) from where it should be; `tan_x`, `tan_y`: the view's half-angle
    /// tangents.
    fn step(&mut self, camera: &mut Camera, off: [f64; 2], tan_x: f64, tan_y: f64) {
        if let Some((was, step)) = self.last {
            for k in 0..2 {
                let response = (was[k] - off[k]) / step[k];
                if step[k] != 0.0 && response.is_finite() && response > 0.0 {
                    self.gain[k] = (1.0 / response).clamp(0.05, 2.0);
                }
            }
        }
        let step = [0, 1].map(|k| off[k] * self.gain[k]);
        let d = f64::from(camera.distance);
        let shift = camera.right().as_dvec3() * (step[0] * d * tan_x)
            + camera.up().as_dvec3() * (step[1] * d * tan_y);
        camera.target = (camera.target.as_dvec3() + shift).as_vec3();
        self.last = Some((off, step));
    }
}

/// An orbit camera. Angles are in degrees, lengths in world units.
#[derive(Clone, Debug, PartialEq)]
pub struct Camera {
    /// The point looked at and orbited around.
    pub target: Vec3,
    /// Angle around +Z, from +X towards +Y.
    pub azimuth_deg: f32,
    /// Angle above the XY plane, −90 to 90.
    pub elevation_deg: f32,
    /// Distance from the eye to the target (> 0).
    pub distance: f32,
    /// Vertical field of view of the perspective projection; for orthographic views it
    /// sets the visible height at a given distance (see the module docs).
    pub fov_y_deg: f32,
    pub projection: Projection,
    /// Near and far clip distances along the view direction (view-space −Z). For
    /// orthographic views `near` may be negative.
    pub near: f32,
    pub far: f32,
}

impl Default for Camera {
    fn default() -> Self {
        Camera {
            target: Vec3::ZERO,
            azimuth_deg: 30.0,
            elevation_deg: 20.0,
            distance: 10.0,
            fov_y_deg: 30.0,
            projection: Projection::Perspective,
            near: 0.01,
            far: 100.0,
        }
    }
}

impl Camera {
    /// Checks that the camera can be used: finite numbers, a positive distance, a field
    /// of view between 0 and 180 degrees.
    pub fn check(&self) -> Result<(), String> {
        let finite = self.target.is_finite()
            && [
                self.azimuth_deg,
                self.elevation_deg,
                self.distance,
                self.fov_y_deg,
            ]
            .iter()
            .all(|v| v.is_finite());
        if !finite {
            // The values at fault by name (the whole struct's debug print read as a dump).
            let named = [
                ("azimuth", self.azimuth_deg),
                ("elevation", self.elevation_deg),
                ("distance", self.distance),
                ("field of view", self.fov_y_deg),
                ("target x", self.target.x),
                ("target y", self.target.y),
                ("target z", self.target.z),
            ];
            let bad: Vec<String> = named
                .iter()
                .filter(|(_, v)| !v.is_finite())
                .map(|(n, v)| format!("{n} {v}"))
                .collect();
            return Err(format!(
                "the camera's {} not a finite number (moved past the range of single \
                 precision?)",
                bad.join(", ") + if bad.len() == 1 { " is" } else { " are" }
            ));
        }
        if self.distance <= 0.0 {
            return Err(format!(
                "camera distance {} (must be positive)",
                self.distance
            ));
        }
        if !(self.fov_y_deg > 0.0 && self.fov_y_deg < 180.0) {
            return Err(format!(
                "camera fov_y_deg {} (must be above 0 and below 180)",
                self.fov_y_deg
            ));
        }
        Ok(())
    }

    /// Unit vector from the target towards the eye (view-space +Z).
    pub fn back(&self) -> Vec3 {
        let (sa, ca) = self.azimuth_deg.to_radians().sin_cos();
        let (se, ce) = self.elevation_deg.to_radians().sin_cos();
        Vec3::new(ce * ca, ce * sa, se)
    }

    /// The camera's right vector (view-space +X).
    pub fn right(&self) -> Vec3 {
        let (sa, ca) = self.azimuth_deg.to_radians().sin_cos();
        Vec3::new(-sa, ca, 0.0)
    }

    /// The camera's up vector (view-space +Y).
    pub fn up(&self) -> Vec3 {
        self.back().cross(self.right())
    }

    /// The eye position.
    pub fn eye(&self) -> Vec3 {
        self.target + self.back() * self.distance
    }

    /// World to view space (right-handed, looking down −Z).
    pub fn view_from_world(&self) -> Mat4 {
        let (r, u, b, e) = (self.right(), self.up(), self.back(), self.eye());
        Mat4::from_cols(
            Vec4::new(r.x, u.x, b.x, 0.0),
            Vec4::new(r.y, u.y, b.y, 0.0),
            Vec4::new(r.z, u.z, b.z, 0.0),
            Vec4::new(-r.dot(e), -u.dot(e), -b.dot(e), 1.0),
        )
    }

    /// World-space height visible at the target (the orthographic view height).
    pub fn view_height_at_target(&self) -> f32 {
        2.0 * self.distance * (self.fov_y_deg.to_radians() * 0.5).tan()
    }

    /// View to clip space for an image of the given aspect ratio (width / height).
    pub fn clip_from_view(&self, aspect: f32) -> Mat4 {
        match self.projection {
            Projection::Perspective => {
                // Right-handed, depth 0 at near and 1 at far (as glam's DirectX-style
                // matrix), with the translation formed as near · (far / (far − near)):
                // glam forms near · far first, which overflows single precision for data
                // beyond 10^19 (stars in metres) and made every depth NaN.
                let h = 1.0 / (self.fov_y_deg.to_radians() * 0.5).tan();
                let ratio = self.far / (self.far - self.near);
                Mat4::from_cols(
                    Vec4::new(h / aspect, 0.0, 0.0, 0.0),
                    Vec4::new(0.0, h, 0.0, 0.0),
                    Vec4::new(0.0, 0.0, -ratio, -1.0),
                    Vec4::new(0.0, 0.0, -self.near * ratio, 0.0),
                )
            }
            Projection::Orthographic => {
                let hh = self.view_height_at_target() * 0.5;
                let hw = hh * aspect;
                glam::camera::rh::proj::directx::orthographic(-hw, hw, -hh, hh, self.near, self.far)
            }
        }
    }

    /// World to clip space for a `size_px` image, shifted by `jitter_px` pixels
    /// (x right, y down) for supersampling.
    pub fn clip_from_world(&self, size_px: [u32; 2], jitter_px: Vec2) -> Mat4 {
        self.jittered_clip_from_view(size_px, jitter_px) * self.view_from_world()
    }

    /// View to clip space for a `size_px` image, shifted by `jitter_px` pixels.
    pub fn jittered_clip_from_view(&self, size_px: [u32; 2], jitter_px: Vec2) -> Mat4 {
        let [w, h] = size_px.map(|v| v.max(1) as f32);
        let shift = Mat4::from_translation(Vec3::new(
            2.0 * jitter_px.x / w,
            -2.0 * jitter_px.y / h,
            0.0,
        ));
        shift * self.clip_from_view(w / h)
    }

    /// [`Self::jittered_clip_from_view`] with reversed depth, for the depth buffer of the
    /// sphere passes: z/w is 1 at the near plane and 0 at the far one. A 32-bit float
    /// then resolves a relative 10⁻⁷ of the depth everywhere; the usual 0-at-near
    /// mapping crowds every far depth next to 1.0 (steps of several units a thousand
    /// units away once a close-up puts the near plane at 10⁻⁵ of the far one). x, y
    /// and w are those of the usual matrix.
    pub fn depth_clip_from_view(&self, size_px: [u32; 2], jitter_px: Vec2) -> Mat4 {
        let mut m = self.jittered_clip_from_view(size_px, jitter_px);
        let (n, f) = (self.near, self.far);
        // Row z: z_clip = a·z_view + b, with z_view = −depth.
        let (a, b) = match self.projection {
            // z/w = n (f − d) / (d (f − n)), w = d.
            // n · (f / (f − n)), not (n · f) / (f − n): the product overflows single
            // precision for data beyond 10^19 (stars in metres).
            Projection::Perspective => (n / (f - n), n * (f / (f - n))),
            // z/w = (f − d) / (f − n), w = 1.
            Projection::Orthographic => (1.0 / (f - n), f / (f - n)),
        };
        m.x_axis.z = 0.0;
        m.y_axis.z = 0.0;
        m.z_axis.z = a;
        m.w_axis.z = b;
        m
    }

    /// Pixels per world unit at view depth `depth` (distance along the view direction)
    /// in an image `height_px` pixels high.
    pub fn pixels_per_world(&self, depth: f32, height_px: u32) -> f32 {
        let h = height_px as f32;
        match self.projection {
            Projection::Perspective => {
                h / (2.0 * depth.max(f32::MIN_POSITIVE) * (self.fov_y_deg.to_radians() * 0.5).tan())
            }
            Projection::Orthographic => h / self.view_height_at_target(),
        }
    }

    /// Rotates the view around the target.
    pub fn orbit(&mut self, d_azimuth_deg: f32, d_elevation_deg: f32) {
        // (`rem_euclid` of a value a rounding below 0 is 360 itself: said as 0, as a view
        // file keeps it.)
        let azimuth = (self.azimuth_deg + d_azimuth_deg).rem_euclid(360.0);
        self.azimuth_deg = if azimuth >= 360.0 { 0.0 } else { azimuth };
        self.elevation_deg = (self.elevation_deg + d_elevation_deg).clamp(-90.0, 90.0);
    }

    /// Moves the target (and the eye with it) by `dx` right and `dy` up, in world units.
    pub fn pan(&mut self, dx: f32, dy: f32) {
        self.target += self.right() * dx + self.up() * dy;
    }

    /// Moves the target so that the scene follows a drag of `dx_px`, `dy_px` pixels
    /// (x right, y down) at the target's depth.
    pub fn pan_px(&mut self, dx_px: f32, dy_px: f32, height_px: u32) {
        let world_per_px = 1.0 / self.pixels_per_world(self.distance, height_px);
        self.pan(-dx_px * world_per_px, dy_px * world_per_px);
    }

    /// Moves closer by `factor` (2 halves the distance).
    pub fn zoom(&mut self, factor: f32) {
        if factor.is_finite() && factor > 0.0 {
            self.distance /= factor;
        }
    }

    /// Frames `bounds` from the current direction: the box, as this direction sees it,
    /// spans [`FIT_FILL`] of an image of `aspect` (width / height) in its tighter
    /// dimension, centred in the image; sets the depth range around it. In perspective the
    /// box's nearer half looks larger than its farther one, so the target moves off the
    /// box's centre, across the view, until the projected box is centred
    /// ([`Self::fit_about_centre`] keeps it there, for orbits).
    pub fn fit(&mut self, bounds: &Bounds, aspect: f32) {
        self.fit_boxes(bounds, &[Framed::Box(*bounds)], aspect);
    }

    /// [`Self::fit`] of what lies in `boxes` (the data's clusters, say, inside its
    /// `bounds`): every corner of every box in view, the projection of their union
    /// centred and filling [`FIT_FILL`], so that data which does not fill its bounding
    /// box (a sphere of atoms, a disc seen from above) is framed as it looks. The depth
    /// range holds `bounds`. No boxes frame `bounds`.
    pub fn fit_boxes(&mut self, bounds: &Bounds, boxes: &[Framed], aspect: f32) {
        self.fit_boxes_in(bounds, boxes, aspect, &[FitWindow::WHOLE]);
    }

    /// [`Self::fit_boxes`] into the best of `windows`: the one where the data is framed
    /// largest (the smallest fitted distance), the projection centred in it and filling
    /// [`FIT_FILL`] of its tighter dimension. Windows that do not hold the image's centre
    /// are passed over; none left frames the whole image. Returns the centre of the window
    /// chosen (normalized device coordinates), where the data's projection is centred.
    pub fn fit_boxes_in(
        &mut self,
        bounds: &Bounds,
        boxes: &[Framed],
        aspect: f32,
        windows: &[FitWindow],
    ) -> [f64; 2] {
        let start = self.clone();
        let mut best: Option<(Camera, [f64; 2])> = None;
        for w in windows.iter() {
            let Some((centre, _)) = w.centre_and_half() else {
                continue;
            };
            let mut c = start.clone();
            c.fit_window(bounds, boxes, aspect, w);
            if best.as_ref().is_none_or(|(b, _)| c.distance < b.distance) {
                best = Some((c, centre));
            }
        }
        let (c, centre) = best.unwrap_or_else(|| {
            let mut c = start;
            c.fit_window(bounds, boxes, aspect, &FitWindow::WHOLE);
            (c, [0.0; 2])
        });
        *self = c;
        centre
    }

    /// Moves closer by `factor` keeping the point of the target's plane seen at `ndc`
    /// (normalized device coordinates) where it is: the data fitted into a window beside
    /// the image's centre (a legend's room) stays in that window as it grows.
    pub fn zoom_about(&mut self, factor: f32, ndc: [f64; 2], aspect: f32) {
        let before = f64::from(self.distance);
        self.zoom(factor);
        let moved = before - f64::from(self.distance);
        let tan_y = (f64::from(self.fov_y_deg).to_radians() * 0.5).tan();
        let tan_x = tan_y * f64::from(aspect);
        let shift = self.right().as_dvec3() * (ndc[0] * tan_x * moved)
            + self.up().as_dvec3() * (ndc[1] * tan_y * moved);
        if shift.is_finite() {
            self.target += shift.as_vec3();
        }
    }

    /// [`Self::fit_boxes_in`] of one window.
    fn fit_window(&mut self, bounds: &Bounds, boxes: &[Framed], aspect: f32, window: &FitWindow) {
        let Some((centre, half)) = window.centre_and_half() else {
            return;
        };
        if !(0..2).all(|k| window.min[k] < 0.0 && window.max[k] > 0.0) {
            self.fit_off_axis(bounds, boxes, aspect, centre, half);
            return;
        }
        let whole = [Framed::Box(*bounds)];
        let boxes = if boxes.is_empty() { &whole[..] } else { boxes };
        let hull = boxes.iter().skip(1).fold(boxes[0].hull(), |u, b| {
            let b = b.hull();
            Bounds::new(u.min.min(b.min), u.max.max(b.max))
        });
        self.target = hull.center();
        self.distance = self.distance_in(boxes, &hull, aspect, window);
        let tan_y = (f64::from(self.fov_y_deg).to_radians() * 0.5).tan();
        let tan_x = tan_y * f64::from(aspect);
        let before = (self.target, self.distance);
        // Each round moves the target by the projection's offset from the window's
        // centre, as seen at the target's depth ([`Recentring`]), and fits the distance
        // again (one round is exact in orthographic views, where the size does not
        // change with depth).
        let mut recentring = Recentring::new();
        for _ in 0..40 {
            let Some([px, py]) = self.projected_centre(boxes, tan_x, tan_y) else {
                (self.target, self.distance) = before;
                break;
            };
            let off = [px - centre[0], py - centre[1]];
            if off[0].abs().max(off[1].abs()) < 1e-5 {
                break;
            }
            recentring.step(self, off, tan_x, tan_y);
            self.distance = self.distance_in(boxes, &hull, aspect, window);
        }
        if !(self.target.is_finite() && self.distance.is_finite() && self.distance > 0.0) {
            (self.target, self.distance) = before;
        }
        self.fit_depth_range(bounds);
    }

    /// [`Self::fit`] looking at the centre of `bounds`: the fitted distance at which every
    /// corner is in view, the projected box centred only in orthographic views.
    pub fn fit_about_centre(&mut self, bounds: &Bounds, aspect: f32) {
        self.target = bounds.center();
        self.distance = self.fitted_distance(bounds, aspect);
        self.fit_depth_range(bounds);
    }

    /// The centre of the projection of the boxes' corners, in normalised device
    /// coordinates (x right, y up), for the given half-angle tangents; `None` where a
    /// corner lies behind the eye of a perspective view.
    /// [`Self::fit_window`] of a window beside the view's axis (a short, wide image's
    /// part beside a legend), centred at `centre` with half sizes `half`: the target,
    /// on the axis, cannot lie in it, so the distance is not solved for the window's
    /// edges but found by steps: first the fit into a window of the same size about the
    /// image's centre, then the data moved to the window's centre and the distance
    /// scaled by the size it shows there (in perspective, data off the axis shows larger
    /// or smaller), until both settle.
    fn fit_off_axis(
        &mut self,
        bounds: &Bounds,
        boxes: &[Framed],
        aspect: f32,
        centre: [f64; 2],
        half: [f64; 2],
    ) {
        let centred = FitWindow {
            min: [-half[0], -half[1]],
            max: half,
        };
        self.fit_window(bounds, boxes, aspect, &centred);
        let whole = [Framed::Box(*bounds)];
        let boxes = if boxes.is_empty() { &whole[..] } else { boxes };
        let before = (self.target, self.distance);
        let tan_y = (f64::from(self.fov_y_deg).to_radians() * 0.5).tan();
        let tan_x = tan_y * f64::from(aspect);
        let mut recentring = Recentring::new();
        for _ in 0..80 {
            let Some((lo, hi)) = self.projected_extent(boxes, tan_x, tan_y) else {
                (self.target, self.distance) = before;
                break;
            };
            let off = [0, 1].map(|k| 0.5 * (lo[k] + hi[k]) - centre[k]);
            let fill = (0..2)
                .map(|k| (hi[k] - lo[k]) / (2.0 * half[k]))
                .fold(0.0f64, f64::max);
            let scale = fill / FIT_FILL;
            if off[0].abs().max(off[1].abs()) < 1e-6 && (scale - 1.0).abs() < 1e-6 {
                break;
            }
            let d = f64::from(self.distance);
            recentring.step(self, off, tan_x, tan_y);
            if scale.is_finite() && scale > 0.0 {
                self.distance = (d * scale) as f32;
            }
        }
        if !(self.target.is_finite() && self.distance.is_finite() && self.distance > 0.0) {
            (self.target, self.distance) = before;
        }
        self.fit_depth_range(bounds);
    }

    fn projected_centre(&self, boxes: &[Framed], tan_x: f64, tan_y: f64) -> Option<[f64; 2]> {
        let (lo, hi) = self.projected_extent(boxes, tan_x, tan_y)?;
        let c = [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])];
        c.iter().all(|v| v.is_finite()).then_some(c)
    }

    /// The corners of `boxes` (and the outlines of balls) projected: lowest and highest
    /// normalised device coordinates; `None` when one reaches the eye or behind it.
    fn projected_extent(
        &self,
        boxes: &[Framed],
        tan_x: f64,
        tan_y: f64,
    ) -> Option<([f64; 2], [f64; 2])> {
        let (r, u, b) = (
            self.right().as_dvec3(),
            self.up().as_dvec3(),
            self.back().as_dvec3(),
        );
        let d = f64::from(self.distance);
        let eye = self.target.as_dvec3() + b * d;
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for (point, radius) in boxes.iter().flat_map(Framed::points) {
            let q = point - eye;
            let across = [q.dot(r), q.dot(u)];
            let tans = [tan_x, tan_y];
            match self.projection {
                Projection::Perspective => {
                    let depth = -q.dot(b);
                    if depth.is_nan() || depth <= 0.0 {
                        return None;
                    }
                    for k in 0..2 {
                        // A ball's outline along one axis: its disk in the plane of that
                        // axis and the view's, seen from the eye, spans the angles
                        // θ ± asin(R / its distance).
                        let (a_lo, a_hi) = if radius > 0.0 {
                            let theta = across[k].atan2(depth);
                            let dist = across[k].hypot(depth);
                            if dist <= radius {
                                return None;
                            }
                            let alpha = (radius / dist).asin();
                            let right = std::f64::consts::FRAC_PI_2;
                            if theta + alpha >= right || theta - alpha <= -right {
                                return None;
                            }
                            ((theta - alpha).tan(), (theta + alpha).tan())
                        } else {
                            let t = across[k] / depth;
                            (t, t)
                        };
                        lo[k] = lo[k].min(a_lo / tans[k]);
                        hi[k] = hi[k].max(a_hi / tans[k]);
                    }
                }
                // The view's size does not change with depth.
                Projection::Orthographic => {
                    for k in 0..2 {
                        lo[k] = lo[k].min((across[k] - radius) / (d * tans[k]));
                        hi[k] = hi[k].max((across[k] + radius) / (d * tans[k]));
                    }
                }
            }
        }
        (lo.iter().chain(&hi).all(|v| v.is_finite())).then_some((lo, hi))
    }

    /// The eye's distance from the target at which every corner of `bounds` lies inside
    /// the view, one of them at [`FIT_FILL`] of the way from the image's centre to its
    /// edge, looking from this camera's direction. It depends on the direction: a slab
    /// seen edge-on is fitted closer than seen across its diagonal. In double precision
    /// (data may span 10^-10 or 10^36); a box of no extent is fitted as a sphere of
    /// [`Bounds::fit_radius`].
    pub fn fitted_distance(&self, bounds: &Bounds, aspect: f32) -> f32 {
        self.distance_for(&[Framed::Box(*bounds)], bounds, aspect)
    }

    /// [`Self::fitted_distance`] of every corner of `boxes`, whose union is `hull`.
    fn distance_for(&self, boxes: &[Framed], hull: &Bounds, aspect: f32) -> f32 {
        self.distance_in(boxes, hull, aspect, &FitWindow::WHOLE)
    }

    /// [`Self::distance_for`] inside `window`: every corner within [`FIT_FILL`] of the
    /// window's half sizes around its centre. A corner `o` from the target, at depth `z`
    /// from the eye, projects to `o·r / (z·tan_x)`, which must lie between the window's
    /// ends `a_lo` and `a_hi` (one below 0, one above): `z ≥ o·r / (a_hi·tan_x)` for
    /// `o·r > 0`, `z ≥ o·r / (a_lo·tan_x)` for `o·r < 0`; the same upwards. For the
    /// whole image that is `|o·r| / (FIT_FILL·tan_x)`.
    fn distance_in(&self, boxes: &[Framed], hull: &Bounds, aspect: f32, window: &FitWindow) -> f32 {
        let (centre, half) = window.centre_and_half().unwrap_or(([0.0; 2], [1.0; 2]));
        let ends = [0, 1].map(|k| {
            [
                centre[k] - half[k] * FIT_FILL,
                centre[k] + half[k] * FIT_FILL,
            ]
        });
        let tan_y = (f64::from(self.fov_y_deg).to_radians() * 0.5).tan();
        let tan_x = tan_y * f64::from(aspect);
        // The depth a coordinate `v` across the view (world units from the target's ray)
        // needs to lie inside `[lo, hi]` of the view's half-angle tangent `tan`.
        let needs = |v: f64, [lo, hi]: [f64; 2], tan: f64| {
            if v > 0.0 {
                v / (hi * tan)
            } else if v < 0.0 {
                v / (lo * tan)
            } else {
                0.0
            }
        };
        let half = (hull.max.as_dvec3() - hull.min.as_dvec3()) * 0.5;
        let (r, u, b) = (
            self.right().as_dvec3(),
            self.up().as_dvec3(),
            self.back().as_dvec3(),
        );
        let target = self.target.as_dvec3();
        let mut need = 0.0f64;
        // The depth a ball of `radius` (0: a corner) at `v` across the view needs to lie
        // inside `[lo, hi]` of tangent `tan`: the planes through the eye and the view's
        // edges keep its disk inside where its centre lies `radius` within each, which
        // in perspective moves the centre across by `radius · √(1 + slope²)` at the
        // edge's slope.
        let ball_needs = |v: f64, radius: f64, [lo, hi]: [f64; 2], tan: f64| {
            let slant = |end: f64| match self.projection {
                Projection::Perspective => radius * (1.0 + (end * tan).powi(2)).sqrt(),
                Projection::Orthographic => radius,
            };
            let high = (v + slant(hi)).max(0.0);
            let low = (v - slant(lo)).min(0.0);
            needs(high, [lo, hi], tan).max(needs(low, [lo, hi], tan))
        };
        for (point, radius) in boxes.iter().flat_map(Framed::points) {
            // The corner from the target (not the box's centre in a centred fit).
            let o = point - target;
            let across = ball_needs(o.dot(r), radius, ends[0], tan_x).max(ball_needs(
                o.dot(u),
                radius,
                ends[1],
                tan_y,
            ));
            need = need.max(match self.projection {
                // The corner's depth from the eye is the distance less its offset
                // towards the eye (a ball's centre beyond its radius).
                Projection::Perspective => {
                    o.dot(b) + across.max(half.length() * 1e-3).max(radius * 1.001)
                }
                Projection::Orthographic => across,
            });
        }
        let fitted = need as f32;
        if half.max_element() > 0.0 && fitted.is_finite() && fitted > 0.0 {
            return fitted;
        }
        let rad = hull.fit_radius();
        let tan_half = (self.fov_y_deg.to_radians() * 0.5).tan() * aspect.min(1.0);
        match self.projection {
            Projection::Perspective => rad / tan_half.atan().sin(),
            Projection::Orthographic => rad / tan_half,
        }
    }

    /// Sets `near` and `far` to enclose the bounding sphere of `bounds` (with a small
    /// margin); in perspective `near` stays positive, at least `far / 10^5`.
    pub fn fit_depth_range(&mut self, bounds: &Bounds) {
        let r = bounds.fit_radius() * 1.01;
        let depth = (self.eye() - bounds.center()).dot(self.back());
        let far = depth + r;
        let near = depth - r;
        match self.projection {
            Projection::Perspective => {
                // Positive even for data behind the eye, at the data's scale.
                let far = far.max(r * 1e-5);
                self.far = far;
                self.near = near.max(far * 1e-5);
            }
            Projection::Orthographic => {
                self.near = near;
                self.far = if far > near { far } else { near + 1.0 };
            }
        }
    }

    /// The six frustum planes of `clip_from_world` as `(normal, d)` with
    /// `normal · p + d ≥ 0` inside: left, right, bottom, top, near, far.
    pub fn frustum_planes(clip_from_world: &Mat4) -> [Vec4; 6] {
        let m = clip_from_world;
        let (r0, r1, r2, r3) = (m.row(0), m.row(1), m.row(2), m.row(3));
        [r3 + r0, r3 - r0, r3 + r1, r3 - r1, r2, r3 - r2].map(|p| {
            let n = p.truncate().length();
            if n > 0.0 {
                p / n
            } else {
                p
            }
        })
    }

    /// The frustum of this camera for a `size_px` image, as [`Self::frustum_planes`]
    /// gives it, with the near and far planes taken from the camera itself: from the
    /// matrix they are row 3 ∓ row 2, which nearly cancel once the near plane is 10⁻⁵ of
    /// the far one (a close-up), putting the far plane a few tenths of a percent too
    /// near.
    pub fn frustum(&self, size_px: [u32; 2]) -> [Vec4; 6] {
        let mut planes = Self::frustum_planes(&self.clip_from_world(size_px, Vec2::ZERO));
        // View depth: (eye − p)·back, inside between near and far.
        let (back, eye) = (self.back(), self.eye());
        let at = back.dot(eye);
        planes[4] = (-back).extend(at - self.near);
        planes[5] = back.extend(self.far - at);
        planes
    }

    /// [`Self::box_in_frustum`], also telling whether the box lies wholly inside every
    /// plane: `None` outside, `Some(true)` wholly inside (then so is every box inside it),
    /// `Some(false)` crossing a plane.
    pub fn box_against_frustum(planes: &[Vec4; 6], min: Vec3, max: Vec3) -> Option<bool> {
        let mut inside = true;
        for p in planes {
            let n = p.truncate();
            let far = Vec3::new(
                if p.x >= 0.0 { max.x } else { min.x },
                if p.y >= 0.0 { max.y } else { min.y },
                if p.z >= 0.0 { max.z } else { min.z },
            );
            if n.dot(far) + p.w < 0.0 {
                return None;
            }
            let near = Vec3::new(
                if p.x >= 0.0 { min.x } else { max.x },
                if p.y >= 0.0 { min.y } else { max.y },
                if p.z >= 0.0 { min.z } else { max.z },
            );
            inside &= n.dot(near) + p.w >= 0.0;
        }
        Some(inside)
    }

    /// True when the box may intersect the frustum (a conservative test).
    pub fn box_in_frustum(planes: &[Vec4; 6], min: Vec3, max: Vec3) -> bool {
        Self::box_against_frustum(planes, min, max).is_some()
    }
}

#[cfg(test)]
mod tests {
    /// Orbiting back to where a turn began gives an azimuth in [0, 360): a rounding below
    /// 0 was kept as 360.
    #[test]
    fn orbits_keep_the_azimuth_below_360() {
        let mut cam = Camera {
            azimuth_deg: 0.1,
            ..Camera::default()
        };
        cam.orbit(-0.1 - 1e-7, 0.0);
        assert!(
            (0.0..360.0).contains(&cam.azimuth_deg),
            "{}",
            cam.azimuth_deg
        );
        for _ in 0..7 {
            cam.orbit(-51.428_57, 0.0);
        }
        assert!(
            (0.0..360.0).contains(&cam.azimuth_deg),
            "{}",
            cam.azimuth_deg
        );
    }

    use super::*;

    fn close(a: Vec3, b: Vec3) -> bool {
        (a - b).length() < 1e-4
    }

    #[test]
    fn reversed_depth_is_one_at_near_zero_at_far_and_resolves_far_depths() {
        for projection in [Projection::Perspective, Projection::Orthographic] {
            // A close-up: the near plane at 10⁻⁵ of the far one.
            let c = Camera {
                projection,
                near: 0.01,
                far: 1000.0,
                ..Default::default()
            };
            let size = [640, 480];
            let usual = c.jittered_clip_from_view(size, Vec2::new(0.3, -0.2));
            let reversed = c.depth_clip_from_view(size, Vec2::new(0.3, -0.2));
            let z = |m: &Mat4, depth: f32| {
                let p = *m * Vec4::new(1.5, -2.0, -depth, 1.0);
                (p, p.z / p.w)
            };
            assert!((z(&reversed, 0.01).1 - 1.0).abs() < 1e-6, "{projection:?}");
            assert!(z(&reversed, 1000.0).1.abs() < 1e-6, "{projection:?}");
            for depth in [0.5f32, 10.0, 300.0, 999.0] {
                let (pu, du) = z(&usual, depth);
                let (pr, dr) = z(&reversed, depth);
                // x, y and w as the usual matrix; z its complement.
                assert_eq!((pu.x, pu.y, pu.w), (pr.x, pr.y, pr.w));
                assert!(
                    (du + dr - 1.0).abs() < 1e-5,
                    "{projection:?} {depth}: {du} {dr}"
                );
            }
            // Eleven depths 0.1 apart 990 units away: eleven values here, decreasing; in
            // the usual buffer (steps of about 6 units there) at most two.
            let depths: Vec<f32> = (0..11).map(|k| 990.0 + 0.1 * k as f32).collect();
            let r: Vec<f32> = depths.iter().map(|&d| z(&reversed, d).1).collect();
            assert!(r.windows(2).all(|w| w[0] > w[1]), "{projection:?}: {r:?}");
            if projection == Projection::Perspective {
                let mut u: Vec<f32> = depths.iter().map(|&d| z(&usual, d).1).collect();
                u.dedup();
                assert!(u.len() <= 2, "{u:?}");
            }
        }
    }

    #[test]
    fn frame_is_orthonormal_and_right_handed_even_looking_down() {
        for (az, el) in [
            (0.0, 0.0),
            (30.0, 20.0),
            (200.0, -60.0),
            (45.0, 90.0),
            (0.0, -90.0),
        ] {
            let c = Camera {
                azimuth_deg: az,
                elevation_deg: el,
                ..Default::default()
            };
            let (r, u, b) = (c.right(), c.up(), c.back());
            assert!((r.length() - 1.0).abs() < 1e-5 && (u.length() - 1.0).abs() < 1e-5);
            assert!(r.dot(u).abs() < 1e-5 && r.dot(b).abs() < 1e-5 && u.dot(b).abs() < 1e-5);
            assert!(close(r.cross(u), b), "az {az} el {el}");
        }
    }

    #[test]
    fn target_projects_to_the_centre_and_the_eye_is_at_distance() {
        let mut c = Camera {
            target: Vec3::new(1.0, 2.0, 3.0),
            distance: 7.0,
            ..Default::default()
        };
        c.fit_depth_range(&Bounds::new([0.0; 3], [2.0, 4.0, 6.0]));
        assert!(((c.eye() - c.target).length() - 7.0).abs() < 1e-5);
        let v = c.view_from_world().transform_point3(c.target);
        assert!(close(v, Vec3::new(0.0, 0.0, -7.0)), "{v}");
        for p in [Projection::Perspective, Projection::Orthographic] {
            c.projection = p;
            let clip = c.clip_from_world([100, 50], Vec2::ZERO) * c.target.extend(1.0);
            let ndc = clip.truncate() / clip.w;
            assert!(ndc.x.abs() < 1e-5 && ndc.y.abs() < 1e-5);
            assert!(ndc.z > 0.0 && ndc.z < 1.0, "{p:?}: depth {}", ndc.z);
        }
    }

    #[test]
    fn fitted_bounds_are_inside_the_frustum_and_fill_it_at_any_scale() {
        // Data in metres (10^-10), in code units, and stars in metres (10^20, whose
        // squared extent overflows single precision; 10^36 near its largest value). The
        // fit used a radius of at least 10^-6, so data of 10^-10 was a dot, and lengths
        // squared in single precision, so data of 10^19 could not be fitted at all.
        for (scale, p, aspect) in [1e-12f32, 1e-10, 1.0, 1e20, 1e36]
            .into_iter()
            .flat_map(|s| {
                [Projection::Perspective, Projection::Orthographic]
                    .into_iter()
                    .map(move |p| (s, p))
            })
            .flat_map(|(s, p)| [0.5, 1.0, 2.0].into_iter().map(move |a| (s, p, a)))
        {
            let b = Bounds::new(
                Vec3::new(-3.0, 0.0, 10.0) * scale,
                Vec3::new(5.0, 2.0, 12.0) * scale,
            );
            for (azimuth_deg, elevation_deg) in
                [(70.0, -35.0), (0.0, 0.0), (90.0, 90.0), (225.0, 30.0)]
            {
                let mut widest = 0.0f32;
                let mut c = Camera {
                    projection: p,
                    azimuth_deg,
                    elevation_deg,
                    ..Default::default()
                };
                c.fit(&b, aspect);
                let m = c.clip_from_view(aspect) * c.view_from_world();
                let (mut lo, mut hi) = (Vec2::splat(f32::INFINITY), Vec2::splat(f32::NEG_INFINITY));
                for i in 0..8 {
                    let corner = Vec3::new(
                        if i & 1 == 0 { b.min.x } else { b.max.x },
                        if i & 2 == 0 { b.min.y } else { b.max.y },
                        if i & 4 == 0 { b.min.z } else { b.max.z },
                    );
                    let clip = m * corner.extend(1.0);
                    let ndc = clip.truncate() / clip.w;
                    assert!(
                        ndc.x.abs() <= 1.0 && ndc.y.abs() <= 1.0 && (0.0..=1.0).contains(&ndc.z),
                        "scale {scale} {p:?} aspect {aspect}: corner {corner} at {ndc}"
                    );
                    widest = widest.max(ndc.x.abs()).max(ndc.y.abs());
                    lo = lo.min(ndc.truncate());
                    hi = hi.max(ndc.truncate());
                }
                // Centred, in perspective too (the nearer half of the box looks larger).
                let centre = (lo + hi) * 0.5;
                assert!(
                    centre.abs().max_element() < 2e-3,
                    "scale {scale} {p:?} aspect {aspect} ({azimuth_deg}°, {elevation_deg}°): \
                     the box's projection is centred at {centre}"
                );
                // The tighter dimension is filled to FIT_FILL, as the direction sees the
                // box (the bounding sphere's fit left 45-55 %).
                assert!(
                    (widest - FIT_FILL as f32).abs() < 1e-3,
                    "scale {scale} {p:?} aspect {aspect} ({azimuth_deg}°, {elevation_deg}°): \
                     the data spans {widest} of the view"
                );
            }
        }
    }

    /// Fitted into a window (the image less a legend's corner), the box lies inside the
    /// window, centred in it and filling FIT_FILL of its tighter dimension; of two
    /// windows the fit takes the one that frames the box larger; so it does in a window
    /// beside the image's centre.
    #[test]
    fn a_fit_into_a_window_frames_the_box_there() {
        let b = Bounds::new(Vec3::new(-3.0, 0.0, 10.0), Vec3::new(5.0, 2.0, 12.0));
        let below = FitWindow {
            min: [-1.0, -0.6],
            max: [1.0, 1.0],
        };
        let beside = FitWindow {
            min: [-1.0, -1.0],
            max: [0.3, 1.0],
        };
        for p in [Projection::Perspective, Projection::Orthographic] {
            for (azimuth_deg, elevation_deg) in [(70.0, -35.0), (0.0, 0.0), (225.0, 30.0)] {
                let aspect = 16.0 / 9.0;
                let start = Camera {
                    projection: p,
                    azimuth_deg,
                    elevation_deg,
                    ..Default::default()
                };
                let ndc_box = |c: &Camera| {
                    let m = c.clip_from_view(aspect) * c.view_from_world();
                    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
                    for corner in corners(&b) {
                        let clip = m * corner.as_vec3().extend(1.0);
                        for k in 0..2 {
                            let v = f64::from(clip[k] / clip.w);
                            lo[k] = lo[k].min(v);
                            hi[k] = hi[k].max(v);
                        }
                    }
                    (lo, hi)
                };
                let mut fitted = Vec::new();
                for w in [below, beside] {
                    let mut c = start.clone();
                    c.fit_boxes_in(&b, &[], aspect, &[w]);
                    let (lo, hi) = ndc_box(&c);
                    let what = format!("{p:?} ({azimuth_deg}°, {elevation_deg}°) in {w:?}");
                    let mut fill = 0.0f64;
                    for k in 0..2 {
                        assert!(
                            lo[k] >= w.min[k] - 1e-4 && hi[k] <= w.max[k] + 1e-4,
                            "{what}"
                        );
                        let centre = 0.5 * (w.min[k] + w.max[k]);
                        assert!(
                            (0.5 * (lo[k] + hi[k]) - centre).abs() < 2e-3,
                            "{what}: axis {k} from {} to {}",
                            lo[k],
                            hi[k]
                        );
                        fill = fill.max((hi[k] - lo[k]) / (w.max[k] - w.min[k]));
                    }
                    assert!((fill - FIT_FILL).abs() < 2e-3, "{what}: fills {fill}");
                    fitted.push(c);
                }
                // Both offered: the nearer fit, the box drawn larger.
                let mut both = start.clone();
                both.fit_boxes_in(&b, &[], aspect, &[below, beside]);
                let nearest = fitted
                    .iter()
                    .map(|c| c.distance)
                    .fold(f32::INFINITY, f32::min);
                assert_eq!(both.distance, nearest);
                // A window beside the image's centre (a short, wide image's part beside
                // a legend) frames the box there too, centred and filling it.
                for away in [
                    FitWindow {
                        min: [0.2, -1.0],
                        max: [1.0, 1.0],
                    },
                    FitWindow {
                        min: [-1.0, -1.0],
                        max: [-0.1, 0.9],
                    },
                    FitWindow {
                        min: [-0.9, 0.05],
                        max: [0.9, 1.0],
                    },
                ] {
                    let mut c = start.clone();
                    c.fit_boxes_in(&b, &[], aspect, &[away]);
                    let (lo, hi) = ndc_box(&c);
                    let what = format!("{p:?} ({azimuth_deg}°, {elevation_deg}°) in {away:?}");
                    let mut fill = 0.0f64;
                    for k in 0..2 {
                        assert!(
                            lo[k] >= away.min[k] - 1e-4 && hi[k] <= away.max[k] + 1e-4,
                            "{what}: axis {k} from {} to {}",
                            lo[k],
                            hi[k]
                        );
                        let centre = 0.5 * (away.min[k] + away.max[k]);
                        assert!((0.5 * (lo[k] + hi[k]) - centre).abs() < 2e-3, "{what}");
                        fill = fill.max((hi[k] - lo[k]) / (away.max[k] - away.min[k]));
                    }
                    assert!((fill - FIT_FILL).abs() < 2e-3, "{what}: fills {fill}");
                    // Zoomed in about the window's centre, the box stays centred there
                    // (orthographic), or far nearer to it than zoomed about the view's
                    // axis (perspective, where the nearer half grows more); zoomed about
                    // the view's axis, it moved twice as far from the image's centre.
                    let centre = c.clone().fit_boxes_in(&b, &[], aspect, &[away]);
                    let mut axis = c.clone();
                    axis.zoom(2.0);
                    c.zoom_about(2.0, centre, aspect);
                    let mid = |c: &Camera, k: usize| {
                        let (lo, hi) = ndc_box(c);
                        0.5 * (lo[k] + hi[k])
                    };
                    let off = (0..2)
                        .map(|k| (mid(&c, k) - centre[k]).abs())
                        .fold(0.0, f64::max);
                    let off_axis = (0..2)
                        .map(|k| (mid(&axis, k) - centre[k]).abs())
                        .fold(0.0, f64::max);
                    let near = match p {
                        Projection::Orthographic => off < 1e-3,
                        Projection::Perspective => off < 0.5 * off_axis,
                    };
                    assert!(near && off_axis > 0.3, "{what}, zoomed: {off} ({off_axis})");
                }
            }
        }
    }

    /// Boxes inside the bounds (a cloud's clusters) are framed as they lie: every corner
    /// in view, their projection centred and filling FIT_FILL, from closer than the bounds'
    /// fit where they leave its corners empty.
    #[test]
    fn fitted_boxes_are_framed_as_they_lie() {
        let b = Bounds::new([-10.0; 3], [10.0; 3]);
        // Six small boxes at the faces' centres: an octahedron's worth of a sphere.
        let boxes: Vec<Bounds> = [Vec3::X, -Vec3::X, Vec3::Y, -Vec3::Y, Vec3::Z, -Vec3::Z]
            .iter()
            .map(|d| Bounds::new(*d * 9.0 - 1.0, *d * 9.0 + 1.0))
            .collect();
        for p in [Projection::Perspective, Projection::Orthographic] {
            for (azimuth_deg, elevation_deg) in [(30.0, 20.0), (0.0, 90.0), (200.0, -40.0)] {
                let mut c = Camera {
                    projection: p,
                    azimuth_deg,
                    elevation_deg,
                    ..Default::default()
                };
                c.fit(&b, 1.5);
                let whole = c.distance;
                let framed: Vec<Framed> = boxes.iter().copied().map(Framed::Box).collect();
                c.fit_boxes(&b, &framed, 1.5);
                // Never farther; closer seen obliquely (straight down an axis, the
                // face boxes reach the bounds' outline).
                let closer = if elevation_deg == 90.0 { 1.0001 } else { 0.95 };
                assert!(
                    c.distance <= whole * closer,
                    "{p:?} {azimuth_deg}: {} {whole}",
                    c.distance
                );
                let m = c.clip_from_view(1.5) * c.view_from_world();
                let (mut lo, mut hi) = (Vec2::splat(f32::INFINITY), Vec2::splat(f32::NEG_INFINITY));
                for corner in boxes.iter().flat_map(corners) {
                    let clip = m * corner.as_vec3().extend(1.0);
                    let ndc = clip.truncate() / clip.w;
                    assert!(ndc.x.abs() <= 1.0 && ndc.y.abs() <= 1.0, "{p:?}: {ndc}");
                    lo = lo.min(ndc.truncate());
                    hi = hi.max(ndc.truncate());
                }
                let widest = lo.abs().max(hi.abs()).max_element();
                assert!((widest - FIT_FILL as f32).abs() < 2e-3, "{p:?}: {widest}");
                assert!(
                    ((lo + hi) * 0.5).abs().max_element() < 2e-3,
                    "{p:?}: {lo} {hi}"
                );
            }
        }
    }

    /// Balls (a few particles' spheres) are framed by their outlines: points all over
    /// each sphere, projected, reach FIT_FILL of the tighter dimension and are centred,
    /// in perspective and orthographic views from several directions, for a lone sphere
    /// off the origin and for three of different sizes. Framed by their boxes' corners,
    /// a lone sphere filled 54-65 % of the image, off centre.
    #[test]
    fn balls_are_framed_by_their_outlines() {
        // Points on the unit sphere, evenly spread (a Fibonacci lattice).
        let n = 20_000;
        let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
        let unit: Vec<glam::DVec3> = (0..n)
            .map(|i| {
                let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
                let r = (1.0 - z * z).sqrt();
                let t = golden * i as f64;
                glam::DVec3::new(r * t.cos(), r * t.sin(), z)
            })
            .collect();
        let scenes: [Vec<(Vec3, f32)>; 2] = [
            vec![(Vec3::new(3.0, -2.0, 5.0), 1.92)],
            vec![
                (Vec3::new(4.0, 0.0, 0.0), 0.5),
                (Vec3::new(0.0, 4.0, 0.0), 1.0),
                (Vec3::new(0.0, 0.0, 4.0), 2.0),
            ],
        ];
        for balls in scenes {
            let framed: Vec<Framed> = balls
                .iter()
                .map(|&(centre, radius)| Framed::Ball { centre, radius })
                .collect();
            let hull = framed.iter().skip(1).fold(framed[0].hull(), |u, f| {
                let h = f.hull();
                Bounds::new(u.min.min(h.min), u.max.max(h.max))
            });
            for p in [Projection::Perspective, Projection::Orthographic] {
                for (azimuth_deg, elevation_deg) in [(30.0, 20.0), (0.0, 90.0), (200.0, -40.0)] {
                    for aspect in [16.0 / 9.0, 0.5] {
                        let mut c = Camera {
                            projection: p,
                            azimuth_deg,
                            elevation_deg,
                            ..Default::default()
                        };
                        c.fit_boxes(&hull, &framed, aspect);
                        let m = c.clip_from_view(aspect) * c.view_from_world();
                        let (mut lo, mut hi) =
                            (Vec2::splat(f32::INFINITY), Vec2::splat(f32::NEG_INFINITY));
                        for &(centre, radius) in &balls {
                            for u in &unit {
                                let q = centre.as_dvec3() + *u * f64::from(radius);
                                let clip = m * q.as_vec3().extend(1.0);
                                let ndc = clip.truncate().truncate() / clip.w;
                                lo = lo.min(ndc);
                                hi = hi.max(ndc);
                            }
                        }
                        let what =
                            format!("{p:?} {azimuth_deg}/{elevation_deg} {aspect}: {lo} {hi}");
                        let widest = lo.abs().max(hi.abs()).max_element();
                        assert!((widest - FIT_FILL as f32).abs() < 2e-3, "{what}");
                        assert!(((lo + hi) * 0.5).abs().max_element() < 2e-3, "{what}");
                    }
                }
            }
        }
    }

    #[test]
    fn orthographic_scale_and_pan_zoom_orbit() {
        let mut c = Camera {
            projection: Projection::Orthographic,
            distance: 10.0,
            fov_y_deg: 90.0,
            ..Default::default()
        };
        // tan(45°) = 1: 20 world units high.
        assert!((c.view_height_at_target() - 20.0).abs() < 1e-4);
        assert!((c.pixels_per_world(123.0, 200) - 10.0).abs() < 1e-3);
        let before = c.target;
        c.pan_px(10.0, 0.0, 200);
        // Dragging right by 10 px = 1 world unit moves the target left.
        assert!(close(c.target, before - c.right()));
        c.zoom(2.0);
        assert!((c.distance - 5.0).abs() < 1e-6);
        c.orbit(350.0, 100.0);
        assert!((c.azimuth_deg - 20.0).abs() < 1e-4 && c.elevation_deg == 90.0);
    }

    #[test]
    fn jitter_shifts_by_pixels() {
        let mut c = Camera::default();
        c.fit_depth_range(&Bounds::new([-1.0; 3], [1.0; 3]));
        let a = c.clip_from_world([64, 32], Vec2::ZERO) * Vec4::new(0.0, 0.0, 0.0, 1.0);
        let b = c.clip_from_world([64, 32], Vec2::new(0.5, 0.25)) * Vec4::new(0.0, 0.0, 0.0, 1.0);
        let (a, b) = (a.truncate() / a.w, b.truncate() / b.w);
        assert!(((b.x - a.x) * 32.0 - 0.5).abs() < 1e-4);
        assert!(((a.y - b.y) * 16.0 - 0.25).abs() < 1e-4);
    }

    #[test]
    fn frustum_test_is_conservative_and_rejects_far_boxes() {
        let mut c = Camera::default();
        let b = Bounds::new([-1.0; 3], [1.0; 3]);
        c.fit(&b, 1.0);
        let planes = Camera::frustum_planes(&(c.clip_from_view(1.0) * c.view_from_world()));
        assert!(Camera::box_in_frustum(&planes, b.min, b.max));
        assert!(Camera::box_in_frustum(
            &planes,
            Vec3::splat(-0.1),
            Vec3::splat(0.1)
        ));
        // Behind the camera.
        let behind = c.eye() + c.back() * 5.0;
        assert!(!Camera::box_in_frustum(&planes, behind - 0.1, behind + 0.1));
        // Far off to the side.
        let side = c.target + c.right() * 100.0;
        assert!(!Camera::box_in_frustum(&planes, side - 0.1, side + 0.1));
    }
    #[test]
    fn close_up_frustum_keeps_its_far_plane_where_the_camera_puts_it() {
        // The eye inside a box of 10⁴ units: near = far · 10⁻⁵. A point just before the
        // far plane (a hundredth of its margin inside) is in the frustum, one just
        // beyond it is not, and likewise at the near plane.
        let mut c = Camera {
            target: Vec3::new(5000.0, 5000.0, 2000.0),
            distance: 50.0,
            ..Default::default()
        };
        c.fit_depth_range(&Bounds::new([0.0; 3], [10000.0, 10000.0, 4000.0]));
        assert!(c.near <= c.far * 1.01e-5);
        let planes = c.frustum([1280, 720]);
        let along = |depth: f32| c.eye() - c.back() * depth;
        let tiny = Vec3::splat(1e-3);
        for (depth, inside) in [
            (c.far * 0.999, true),
            (c.far * 1.001, false),
            (c.near * 1.5, true),
            (c.near * 0.5, false),
        ] {
            let p = along(depth);
            assert_eq!(
                Camera::box_in_frustum(&planes, p - tiny * depth * 1e-3, p + tiny * depth * 1e-3),
                inside,
                "depth {depth} (near {}, far {})",
                c.near,
                c.far
            );
        }
    }

    /// The three-way test agrees with the two-way one, and a box it finds wholly inside
    /// has every box inside it in the frustum.
    #[test]
    fn wholly_inside_boxes_contain_only_visible_boxes() {
        let mut c = Camera::default();
        let b = Bounds::new([-1.0; 3], [1.0; 3]);
        c.fit(&b, 1.0);
        c.azimuth_deg = 30.0;
        c.elevation_deg = 20.0;
        let planes = Camera::frustum_planes(&(c.clip_from_view(1.0) * c.view_from_world()));
        let mut state = 7u64;
        let mut next = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        let (mut inside, mut crossing, mut outside) = (0, 0, 0);
        for _ in 0..4000 {
            let centre = Vec3::new(next(), next(), next()) * 5.0 - 2.5;
            let half = Vec3::new(next(), next(), next()) * 0.8;
            let (lo, hi) = (centre - half, centre + half);
            let class = Camera::box_against_frustum(&planes, lo, hi);
            assert_eq!(class.is_some(), Camera::box_in_frustum(&planes, lo, hi));
            match class {
                None => outside += 1,
                Some(false) => crossing += 1,
                Some(true) => {
                    inside += 1;
                    for _ in 0..8 {
                        let a = lo + (hi - lo) * Vec3::new(next(), next(), next());
                        let z = lo + (hi - lo) * Vec3::new(next(), next(), next());
                        let (sub_lo, sub_hi) = (a.min(z), a.max(z));
                        assert!(Camera::box_in_frustum(&planes, sub_lo, sub_hi));
                        assert_eq!(
                            Camera::box_against_frustum(&planes, sub_lo, sub_hi),
                            Some(true)
                        );
                    }
                }
            }
        }
        assert!(
            inside > 100 && crossing > 100 && outside > 100,
            "{inside} {crossing} {outside}"
        );
    }
}
