//! What a movie's frames share: one camera and one colour range over every frame.
//!
//! How it works. A movie of a batch is drawn with one camera and one attribute range, or
//! the picture would jump and its colours drift from frame to frame. Before anything is
//! drawn, every frame's file is opened once and [`Survey::add`] folds it in: the bounds
//! its fitted view would frame (frames whose particles are all hidden apart, used only
//! when no frame shows any), its clusters' boxes (up to [`FRAMING_BOXES`], past which the
//! frames' bounds alone frame the movie), the particles a fit leaves out as far from the
//! rest, the species names of every frame, the union of the attribute's ranges (where
//! every frame has the same attribute), the smallest value above 0 (a log scale's
//! floor) and the axis every frame is flat across (2D data faces square on).
//!
//! A turntable is a movie of views: [`turntable_cameras`] gives its orbit one distance,
//! the largest any view's fit needs, so the data keeps its size through the turn.

use std::collections::BTreeSet;

use mdlod_format::meta::{AttributeInfo, Species};
use mdlod_format::MdlodFile;

use crate::{Bounds, Camera, RenderOptions};

/// Past this many cluster boxes, a movie is framed by its frames' bounds alone.
pub const FRAMING_BOXES: usize = 1 << 18;

/// The frames' common facts, gathered one file at a time.
#[derive(Debug, Default)]
pub struct Survey {
    shown: Option<Bounds>,
    hidden: Option<Bounds>,
    /// `None` once past [`FRAMING_BOXES`].
    boxes: Option<Vec<crate::camera::Framed>>,
    far_particles: u64,
    far_frames: usize,
    log_floor: Option<f32>,
    names: BTreeSet<String>,
    species: Vec<Vec<Species>>,
    /// `None` before the first frame; then the union, `None` once a frame lacks the
    /// attribute or names another.
    attribute: Option<Option<AttributeInfo>>,
    /// `None` before the first frame; then the common flat axis, if any.
    flat: Option<Option<usize>>,
}

fn union(a: Option<Bounds>, b: Bounds) -> Bounds {
    match a {
        None => b,
        Some(a) => Bounds::new(a.min.min(b.min), a.max.max(b.max)),
    }
}

impl Survey {
    pub fn new() -> Survey {
        Survey {
            boxes: Some(Vec::new()),
            ..Survey::default()
        }
    }

    /// Folds in one frame, as `opts` would draw it.
    pub fn add(&mut self, file: &MdlodFile, opts: &RenderOptions) {
        let own_flat = crate::flat_axis(file);
        self.flat = Some(match self.flat {
            None => own_flat,
            Some(a) => a.filter(|_| a == own_flat),
        });
        let meta = file.metadata();
        self.names
            .extend(meta.species.iter().map(|s| s.name.clone()));
        self.species.push(meta.species.clone());
        // (Over the particles drawn, where some are hidden or cut away: a solvent's values
        // stretch no frame's map, and a frame that draws nothing adds none.)
        let drawn =
            meta.attribute
                .clone()
                .map(|a| match crate::drawn_attribute(file, &opts.style) {
                    crate::DrawnValues::Range([min, max]) => Some(AttributeInfo { min, max, ..a }),
                    crate::DrawnValues::Nothing => None,
                    crate::DrawnValues::All | crate::DrawnValues::One => Some(a),
                });
        if drawn != Some(None) {
            let own = drawn.flatten();
            self.attribute = Some(match (self.attribute.take(), own) {
                (None, own) => own,
                (Some(Some(a)), Some(b)) if a.name == b.name => Some(AttributeInfo {
                    min: a.min.min(b.min),
                    max: a.max.max(b.max),
                    ..a
                }),
                _ => None,
            });
        }
        if opts.style.log_scale {
            if let Some(f) = crate::log_floor(file) {
                self.log_floor = Some(self.log_floor.map_or(f, |g| g.min(f)));
            }
        }
        let fit = crate::fit_for(file, opts);
        if fit.far_particles > 0 {
            self.far_particles += fit.far_particles;
            self.far_frames += 1;
        }
        // A frame whose every particle is hidden shows nothing to fit (its whole box
        // stands in only when no frame shows anything).
        if !fit.shows_any {
            self.hidden = Some(union(self.hidden, fit.bounds));
            return;
        }
        self.shown = Some(union(self.shown, fit.bounds));
        if let Some(all) = &mut self.boxes {
            all.extend(crate::framing_boxes(file, opts, &fit.bounds));
            if all.len() > FRAMING_BOXES {
                self.boxes = None;
            }
        }
    }

    /// The frames folded in.
    pub fn frames(&self) -> usize {
        self.species.len()
    }

    /// The bounds the movie's fit frames: the union of the frames that show particles,
    /// else of all; `None` before the first frame.
    pub fn bounds(&self) -> Option<Bounds> {
        self.shown.or(self.hidden)
    }

    /// Every shown frame's cluster boxes, or none where they were too many.
    pub fn boxes(&self) -> &[crate::camera::Framed] {
        self.boxes.as_deref().unwrap_or_default()
    }

    /// Particles the frames' fits leave out as far from the rest, and in how many frames.
    pub fn far(&self) -> (u64, usize) {
        (self.far_particles, self.far_frames)
    }

    /// The smallest attribute value above 0 of any frame (gathered under a log scale).
    pub fn log_floor(&self) -> Option<f32> {
        self.log_floor
    }

    /// The species names of every frame.
    pub fn names(&self) -> &BTreeSet<String> {
        &self.names
    }

    /// Each frame's species, in the order added.
    pub fn species(&self) -> &[Vec<Species>] {
        &self.species
    }

    /// The attribute with every frame's range, where every frame has the same one.
    pub fn attribute(&self) -> Option<&AttributeInfo> {
        self.attribute.as_ref().and_then(Option::as_ref)
    }

    /// The axis every frame is flat across.
    pub fn flat_axis(&self) -> Option<usize> {
        self.flat.flatten()
    }
}

/// The cameras of a turntable's `views` (orbit views of one data set at other
/// azimuths) fitted to `bounds`: every view takes the largest fitted distance, so the
/// data keeps its size on screen through the turn and no view crops it. Where
/// `fitted_target`, the target is the data's centre in every view (a still's fit moves
/// it to centre the picture in perspective, which would make the turn wobble), at the
/// zoom each view asks for. Where `fit_windows` name parts of the image (the image less
/// an in-image legend's corner), the turn is fitted into the one that shows the data
/// largest, each view panned so that the data's centre lies at that part's centre.
pub fn turntable_cameras(
    bounds: &Bounds,
    views: &[crate::ViewSpec],
    width: u32,
    height: u32,
    fitted_target: bool,
    fit_windows: &[crate::FitWindow],
) -> Result<Vec<Camera>, crate::RenderError> {
    let aspect = width.max(1) as f32 / height.max(1) as f32;
    let cameras = views
        .iter()
        .map(|v| {
            let mut c = crate::camera_for_bounds(bounds, v, width, height)?;
            if fitted_target {
                // The zoom asked for: the fitted distance over the one given.
                let mut fitted = c.clone();
                fitted.fit(bounds, aspect);
                let zoom = fitted.distance / c.distance;
                c.fit_about_centre(bounds, aspect);
                c.distance /= zoom;
            }
            Ok(c)
        })
        .collect::<Result<Vec<_>, crate::RenderError>>()?;
    let farthest = cameras.iter().map(|c| c.distance).fold(0.0f32, f32::max);
    // The zoom asked for (`--zoom`, the same in every view): the part a legend leaves is
    // fitted as without it, and the zoom then taken from there, as a still does; 1 for
    // views whose zoom is not at hand (a view file's).
    let zoom = views
        .iter()
        .zip(&cameras)
        .filter_map(|(v, c)| {
            let mut whole = crate::camera_for_bounds(bounds, &unzoomed(v)?, width, height).ok()?;
            if fitted_target {
                whole.fit_about_centre(bounds, aspect);
            }
            Some(whole.distance / c.distance.max(f32::MIN_POSITIVE))
        })
        .fold(None, |z: Option<f32>, k| Some(z.map_or(k, |z| z.min(k))))
        .filter(|z| z.is_finite() && *z > 0.0)
        .unwrap_or(1.0);
    // The part a legend leaves is as much farther as it is smaller. The data's reach
    // across the image, over the turn at the farthest distance, says how much farther
    // each part needs it: a part as wide as the image but short shrinks a cube that a
    // narrow, full-height part beside the legend holds whole.
    let reach = turn_reach(&cameras, farthest * zoom, bounds, aspect);
    let window = fit_windows
        .iter()
        .filter_map(|w| w.centre_and_half())
        .map(|(centre, half)| {
            let shrink = (0..2)
                .map(|k| half[k] * crate::camera::FIT_FILL / reach[k].max(1e-9))
                .fold(1.0f64, f64::min);
            (centre, shrink)
        })
        .max_by(|a, b| a.1.total_cmp(&b.1));
    let farthest = match window {
        Some((_, shrink)) => farthest / shrink as f32,
        None => farthest,
    };
    Ok(cameras
        .into_iter()
        .map(|c| {
            let mut c = Camera {
                distance: farthest,
                ..c
            };
            // The data's centre dragged to the window's centre, in pixels (y down); a
            // target given stays where it is, as in a still.
            if let Some((centre, _)) = window.filter(|_| fitted_target) {
                let (w, h) = (f64::from(width), f64::from(height));
                c.pan_px(
                    (centre[0] * 0.5 * w) as f32,
                    (-centre[1] * 0.5 * h) as f32,
                    height,
                );
            }
            c
        })
        .collect())
}

/// `view` at zoom 1, where its zoom is at hand (not a view file's).
fn unzoomed(view: &crate::ViewSpec) -> Option<crate::ViewSpec> {
    use crate::ViewSpec;
    Some(match view.clone() {
        ViewSpec::Orbit {
            azimuth_deg,
            elevation_deg,
            projection,
            ..
        } => ViewSpec::Orbit {
            azimuth_deg,
            elevation_deg,
            zoom: 1.0,
            projection,
        },
        ViewSpec::Default {
            projection, target, ..
        } => ViewSpec::Default {
            zoom: 1.0,
            projection,
            target,
        },
        ViewSpec::View(v) => ViewSpec::View(crate::ViewFile { zoom: 1.0, ..v }),
        _ => return None,
    })
}

/// How far the corners of `bounds` reach from the image's centre (normalised device
/// coordinates, x and y) over the views of a turn, each seen from `distance` looking at
/// the data's centre (a target given is put in place after the fit, as in a still).
fn turn_reach(cameras: &[Camera], distance: f32, bounds: &Bounds, aspect: f32) -> [f64; 2] {
    let mut reach = [0.0f64; 2];
    for c in cameras {
        let c = Camera {
            distance,
            target: bounds.center(),
            ..c.clone()
        };
        let m = c.clip_from_view(aspect) * c.view_from_world();
        for p in crate::camera::corners(bounds) {
            let clip = m * p.as_vec3().extend(1.0);
            if clip.w > 0.0 {
                for k in 0..2 {
                    reach[k] = reach[k].max(f64::from((clip[k] / clip.w).abs()));
                }
            }
        }
    }
    reach
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{camera::Projection, FitWindow, ViewSpec};
    use glam::Vec3;

    fn turn(n: u32, zoom: f32) -> Vec<ViewSpec> {
        (0..n)
            .map(|i| ViewSpec::Orbit {
                azimuth_deg: 30.0 + 360.0 * i as f32 / n as f32,
                elevation_deg: 20.0,
                zoom,
                projection: Projection::Perspective,
            })
            .collect()
    }

    /// The corners of `b` in normalised device coordinates, seen by `c`.
    fn projected(c: &Camera, b: &Bounds, aspect: f32) -> Vec<[f32; 2]> {
        let m = c.clip_from_view(aspect) * c.view_from_world();
        crate::camera::corners(b)
            .into_iter()
            .map(|p| {
                let q = m * p.as_vec3().extend(1.0);
                [q.x / q.w, q.y / q.w]
            })
            .collect()
    }

    /// A long box turned about: one distance for every view, the box's centre as the
    /// target, no corner out of the picture in any view; a zoom of 2 halves the
    /// distance; a window left by a legend takes the whole turn, centred in it.
    #[test]
    fn a_turn_keeps_one_distance_and_every_view_holds_the_data() {
        let b = Bounds::new(Vec3::new(0.0, 0.0, 0.0), Vec3::new(100.0, 20.0, 10.0));
        let (w, h) = (640, 360);
        let aspect = w as f32 / h as f32;
        let cams = turntable_cameras(&b, &turn(12, 1.0), w, h, true, &[]).unwrap();
        assert_eq!(cams.len(), 12);
        for c in &cams {
            assert_eq!(c.distance, cams[0].distance);
            assert!((c.target - b.center()).length() < 1e-3, "{:?}", c.target);
            for [x, y] in projected(c, &b, aspect) {
                assert!(x.abs() <= 1.0 && y.abs() <= 1.0, "({x}, {y})");
            }
        }
        // The widest view needs it: some view's corners reach the fit's fill.
        let reach = cams
            .iter()
            .flat_map(|c| projected(c, &b, aspect))
            .map(|[x, y]| x.abs().max(y.abs()))
            .fold(0.0f32, f32::max);
        assert!(reach > 0.8, "{reach}");
        let closer = turntable_cameras(&b, &turn(12, 2.0), w, h, true, &[]).unwrap();
        assert!((closer[0].distance * 2.0 - cams[0].distance).abs() < 1e-3 * cams[0].distance);
        // The image less its left third (a legend there): every corner in the window.
        let window = FitWindow {
            min: [-1.0 / 3.0, -1.0],
            max: [1.0, 1.0],
        };
        let left = turntable_cameras(&b, &turn(12, 1.0), w, h, true, &[window]).unwrap();
        assert!(left[0].distance > cams[0].distance);
        for c in &left {
            assert_eq!(c.distance, left[0].distance);
            for [x, y] in projected(c, &b, aspect) {
                assert!(
                    (-1.0 / 3.0..=1.0).contains(&x) && y.abs() <= 1.0,
                    "({x}, {y})"
                );
            }
            // The data's centre at the window's centre.
            let m = c.clip_from_view(aspect) * c.view_from_world();
            let q = m * b.center().extend(1.0);
            let centre = [q.x / q.w, q.y / q.w];
            assert!(
                (centre[0] - 1.0 / 3.0).abs() < 1e-3 && centre[1].abs() < 1e-3,
                "{centre:?}"
            );
        }
        // Zoomed into a window: the window's fit, then the zoom (not the whole data
        // fitted into the window again from the zoomed distance), the centre in it.
        let zoomed = turntable_cameras(&b, &turn(12, 4.0), w, h, true, &[window]).unwrap();
        let ratio = left[0].distance / zoomed[0].distance;
        assert!((ratio - 4.0).abs() < 1e-3, "{ratio}");
        // A target given stays the target, at the window's fit over the zoom.
        let target = Vec3::new(10.0, 5.0, 2.0);
        let aimed: Vec<ViewSpec> = (0..12)
            .map(|i| {
                ViewSpec::View(crate::ViewFile {
                    azimuth_deg: 30.0 + 30.0 * i as f32,
                    elevation_deg: 20.0,
                    zoom: 4.0,
                    target: Some(target.to_array()),
                    ..Default::default()
                })
            })
            .collect();
        let plain = turntable_cameras(&b, &aimed, w, h, false, &[]).unwrap();
        let aimed = turntable_cameras(&b, &aimed, w, h, false, &[window]).unwrap();
        for (a, p) in aimed.iter().zip(&plain) {
            assert!((a.target - target).length() < 1e-4, "{:?}", a.target);
            let ratio = a.distance / p.distance;
            assert!((1.0..2.0).contains(&ratio), "{ratio}");
        }
    }
}
