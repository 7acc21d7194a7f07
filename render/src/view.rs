//! The view file (`--view view.json`): a camera saved as JSON.
//!
//! ```json
//! { "version": 1, "projection": "perspective", "azimuth_deg": 30, "elevation_deg": 20,
//!   "target": [10, 10, 5], "distance": 80, "fov_y_deg": 30 }
//! ```
//!
//! Only `version` is required. A file without `target` or `distance` is fitted to the
//! data's bounds; `zoom` then moves closer (2 is twice as close as the fit, or as
//! `distance`: a saved view, whose zoom is 1, is zoomed by editing it, or by `--zoom`
//! with `--view`). Unknown
//! fields are ignored, so later minor versions may add some (the command line names
//! them, in case one is misspelt); a file of another major
//! version is refused with a message naming both. Near and far planes are not stored:
//! they are recomputed from the data's bounds.

use std::path::Path;

use glam::Vec3;
use serde::{Deserialize, Serialize};

use crate::camera::{Bounds, Camera, FitWindow, Framed, Projection};
use crate::error::RenderError;

/// The view file version this crate writes and reads.
pub const VIEW_VERSION: u32 = 1;

fn default_azimuth() -> f32 {
    Camera::default().azimuth_deg
}
fn default_elevation() -> f32 {
    Camera::default().elevation_deg
}
fn default_fov() -> f32 {
    Camera::default().fov_y_deg
}
fn default_zoom() -> f32 {
    1.0
}

/// The JSON type each key of a view file takes, said as a user reads it.
fn check_type(key: &str, v: &serde_json::Value) -> Result<(), String> {
    use serde_json::Value;
    let shown = |v: &Value| {
        let t = v.to_string();
        match t.chars().count() > 40 {
            true => format!("{}…", t.chars().take(40).collect::<String>()),
            false => t,
        }
    };
    let number = |v: &Value| v.is_number();
    let quoted = |v: &Value| v.as_str().is_some_and(|s| s.trim().parse::<f64>().is_ok());
    let expect = |what: &str| {
        let hint = if quoted(v) {
            " (a number is written without quotes)"
        } else {
            ""
        };
        Err(format!("{key} {}: expected {what}{hint}", shown(v)))
    };
    match key {
        "version" => match v.as_u64() {
            Some(_) => Ok(()),
            None => expect("the whole number 1"),
        },
        "projection" => match v.as_str() {
            Some("perspective" | "orthographic") => Ok(()),
            _ => expect("\"perspective\" or \"orthographic\""),
        },
        "azimuth_deg" | "elevation_deg" | "zoom" | "fov_y_deg" | "distance" => match number(v) {
            true => Ok(()),
            false => expect("a number"),
        },
        "target" => match v.as_array() {
            Some(a) if a.len() == 3 && a.iter().all(number) => Ok(()),
            _ => expect("three numbers, [x, y, z]"),
        },
        "image" => match v.as_array() {
            Some(a)
                if a.len() == 2
                    && a.iter()
                        .all(|x| x.as_u64().is_some_and(|n| n <= u64::from(u32::MAX))) =>
            {
                Ok(())
            }
            _ => expect("two whole numbers of pixels, [width, height]"),
        },
        _ => Ok(()),
    }
}

/// A JSON syntax error said with its place, and where it is a NaN or an infinity (which
/// JSON has no words for, though Python's `json.dump` writes them), the key it stands at.
fn json_error(text: &str, e: &serde_json::Error) -> String {
    let line = text.lines().nth(e.line().saturating_sub(1)).unwrap_or("");
    let before: String = line.chars().take(e.column().saturating_sub(1)).collect();
    let at: String = line
        .chars()
        .skip(e.column().saturating_sub(1))
        .take(9)
        .collect();
    let word = ["NaN", "-NaN", "Infinity", "-Infinity", "nan", "inf", "-inf"]
        .into_iter()
        .find(|w| at.starts_with(w) || before.trim_end().ends_with(w));
    match word {
        Some(w) => {
            let key = before
                .rsplit_once("\":")
                .and_then(|(k, _)| k.rsplit_once('"'))
                .map_or(String::new(), |(_, k)| format!(" for {k}"));
            format!(
                "{w}{key} at line {} column {}: JSON has no NaN or infinity (Python's \
                 json.dump writes them; give a finite number, or leave the key out)",
                e.line(),
                e.column()
            )
        }
        None => e.to_string(),
    }
}

/// The first key a view file's top-level object gives twice, if any (a JSON reader keeps
/// the last quietly).
fn duplicate_key(text: &str) -> Option<String> {
    struct Keys(Option<String>);
    impl<'de> serde::Deserialize<'de> for Keys {
        fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Keys, D::Error> {
            struct V;
            impl<'de> serde::de::Visitor<'de> for V {
                type Value = Keys;
                fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                    f.write_str("an object")
                }
                fn visit_map<A: serde::de::MapAccess<'de>>(
                    self,
                    mut map: A,
                ) -> Result<Keys, A::Error> {
                    let mut seen = std::collections::HashSet::new();
                    let mut twice = None;
                    while let Some(k) = map.next_key::<String>()? {
                        map.next_value::<serde::de::IgnoredAny>()?;
                        if !seen.insert(k.clone()) && twice.is_none() {
                            twice = Some(k);
                        }
                    }
                    Ok(Keys(twice))
                }
            }
            d.deserialize_map(V)
        }
    }
    serde_json::from_str::<Keys>(text).ok()?.0
}

/// The widest vertical field of view a view file may ask for, degrees.
pub const MAX_FOV_Y_DEG: f32 = 120.0;

/// A camera as stored in a view file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ViewFile {
    pub version: u32,
    #[serde(default)]
    pub projection: Projection,
    #[serde(default = "default_azimuth")]
    pub azimuth_deg: f32,
    #[serde(default = "default_elevation")]
    pub elevation_deg: f32,
    /// Point looked at; the centre of the data when absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub target: Option<[f32; 3]>,
    /// Eye-to-target distance; fitted to the data when absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub distance: Option<f32>,
    /// Moves closer by this factor: from the fitted distance, or from `distance`.
    #[serde(default = "default_zoom")]
    pub zoom: f32,
    #[serde(default = "default_fov")]
    pub fov_y_deg: f32,
    /// The size in pixels of the image the view was saved from, where known: the same
    /// view drawn at another aspect shows another part of the data (a narrower image,
    /// less of its width), which a render notes. Read for that note only.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub image: Option<[u32; 2]>,
}

impl Default for ViewFile {
    fn default() -> Self {
        ViewFile {
            version: VIEW_VERSION,
            projection: Projection::Perspective,
            azimuth_deg: default_azimuth(),
            elevation_deg: default_elevation(),
            target: None,
            distance: None,
            zoom: 1.0,
            fov_y_deg: default_fov(),
            image: None,
        }
    }
}

impl ViewFile {
    /// Reads and checks a view file.
    pub fn load(path: &Path) -> Result<ViewFile, RenderError> {
        let text = mdlod_format::files::read_capped_string(path, mdlod_format::files::SMALL_JSON)
            .map_err(|e| RenderError::View {
            path: path.to_path_buf(),
            message: format!("cannot read it: {e}"),
        })?;
        Self::parse(&text).map_err(|message| RenderError::View {
            path: path.to_path_buf(),
            message,
        })
    }

    /// The view file at `path` if it is one and gives neither angle (they take the
    /// default view's, which faces flat data square on: [`crate::ViewSpec::Default`]);
    /// `None` otherwise, and for a file that cannot be read (its error is said where it
    /// is loaded for the view).
    pub fn load_angleless(path: &Path) -> Option<ViewFile> {
        let text =
            mdlod_format::files::read_capped_string(path, mdlod_format::files::SMALL_JSON).ok()?;
        let (v, json) = Self::parse_with_json(&text).ok()?;
        let given = ["azimuth_deg", "elevation_deg"]
            .iter()
            .any(|k| json.get(k).is_some());
        (!given).then_some(v)
    }

    /// The fields this version reads.
    pub const FIELDS: [&'static str; 9] = [
        "version",
        "projection",
        "azimuth_deg",
        "elevation_deg",
        "target",
        "distance",
        "zoom",
        "fov_y_deg",
        "image",
    ];

    /// The fields of view-file JSON that this version does not read (ignored: a later
    /// minor version's, or misspelt ones, which the user should hear about); empty when
    /// the text is no JSON object.
    pub fn unknown_fields(text: &str) -> Vec<String> {
        match serde_json::from_str::<serde_json::Value>(text) {
            Ok(serde_json::Value::Object(map)) => map
                .keys()
                .filter(|k| !Self::FIELDS.contains(&k.as_str()))
                .cloned()
                .collect(),
            _ => Vec::new(),
        }
    }

    /// Parses and checks view-file JSON; the error says what is wrong.
    pub fn parse(text: &str) -> Result<ViewFile, String> {
        Self::parse_with_json(text).map(|(v, _)| v)
    }

    /// [`Self::parse`], with the JSON object it was read from.
    fn parse_with_json(text: &str) -> Result<(ViewFile, serde_json::Value), String> {
        // An object, not a list (serde reads a struct from a list of its fields in order).
        let mut value: serde_json::Value =
            serde_json::from_str(text).map_err(|e| json_error(text, &e))?;
        let Some(map) = value.as_object_mut() else {
            return Err("a view file is a JSON object (`{\"version\": 1, ...}`)".into());
        };
        if let Some(key) = duplicate_key(text) {
            return Err(format!(
                "{key} is given twice (which one is meant?): keep one"
            ));
        }
        // `null` is the key left out, for every key but the version.
        map.retain(|k, v| !(v.is_null() && k != "version"));
        for (key, v) in map.iter() {
            check_type(key, v)?;
        }
        let v = ViewFile::deserialize(&value).map_err(|e| e.to_string())?;
        v.check()?;
        Ok((v, value))
    }

    /// Checks the numbers: the version, finite values, angles and distances in range.
    pub fn check(&self) -> Result<(), String> {
        if self.version != VIEW_VERSION {
            return Err(format!(
                "version {} (this mdlod reads view files of version {VIEW_VERSION})",
                self.version
            ));
        }
        // (A number past single precision's range, 1e300 say, reads as infinite.)
        let numbers = [
            ("azimuth_deg", Some(self.azimuth_deg)),
            ("elevation_deg", Some(self.elevation_deg)),
            ("zoom", Some(self.zoom)),
            ("fov_y_deg", Some(self.fov_y_deg)),
            ("distance", self.distance),
        ]
        .into_iter()
        .chain(self.target.iter().flatten().map(|&v| ("target", Some(v))));
        for (key, v) in numbers {
            if let Some(v) = v.filter(|v| !v.is_finite()) {
                return Err(format!(
                    "{key} {v} (not a finite number in single precision: at most about \
                     3.4e38)"
                ));
            }
        }
        if !(-90.0..=90.0).contains(&self.elevation_deg) {
            return Err(format!(
                "elevation_deg {} (must be -90 to 90)",
                self.elevation_deg
            ));
        }
        if !(self.fov_y_deg > 0.0 && self.fov_y_deg <= MAX_FOV_Y_DEG) {
            return Err(format!(
                "fov_y_deg {} (must be above 0 and at most {MAX_FOV_Y_DEG}: wider views \
                 stretch the data towards the edges past what a fit can frame)",
                self.fov_y_deg
            ));
        }
        if let Some(d) = self.distance.filter(|&d| d <= 0.0) {
            return Err(format!("distance {d} (must be positive)"));
        }
        if self.zoom <= 0.0 {
            return Err(format!("zoom {} (must be positive)", self.zoom));
        }
        if let Some([w, h]) = self.image.filter(|&[w, h]| w == 0 || h == 0) {
            return Err(format!(
                "image [{w}, {h}] (the width and height of the image the view was saved \
                 from, each at least 1 pixel; leave the key out where unknown)"
            ));
        }
        Ok(())
    }

    /// Writes the view file (to a temporary file first, then renamed into place).
    pub fn save(&self, path: &Path) -> Result<(), RenderError> {
        let text = serde_json::to_string_pretty(self).map_err(|e| RenderError::View {
            path: path.to_path_buf(),
            message: e.to_string(),
        })?;
        crate::image::write_atomic(path, text.as_bytes())
    }

    /// The view of a camera (the target and distance are stored).
    pub fn from_camera(c: &Camera) -> ViewFile {
        ViewFile {
            version: VIEW_VERSION,
            projection: c.projection,
            azimuth_deg: c.azimuth_deg,
            elevation_deg: c.elevation_deg,
            target: Some(c.target.to_array()),
            distance: Some(c.distance),
            zoom: 1.0,
            fov_y_deg: c.fov_y_deg,
            image: None,
        }
    }

    /// This view, recorded as seen in an image of `width` × `height` pixels.
    pub fn seen_in(self, width: u32, height: u32) -> ViewFile {
        ViewFile {
            image: Some([width, height]),
            ..self
        }
    }

    /// A note where this view, saved from an image of another shape, is drawn in one of
    /// `width` × `height` pixels: it shows another part of the data (`None` within 1 %,
    /// or where the view does not record its image).
    pub fn aspect_note(&self, width: u32, height: u32) -> Option<String> {
        let [w, h] = self.image?;
        if w == 0 || h == 0 || width == 0 || height == 0 {
            return None;
        }
        let (saved, now) = (
            f64::from(w) / f64::from(h),
            f64::from(width) / f64::from(height),
        );
        if (now / saved - 1.0).abs() <= 0.01 {
            return None;
        }
        Some(format!(
            "the view was saved from a {w}×{h} image; drawn {width}×{height}, {} (the height \
             seen stays the view's)",
            if now < saved {
                "the image is narrower: data at the sides may be cut"
            } else {
                "the image is wider: more shows at the sides"
            }
        ))
    }

    /// The camera for data within `bounds` and an image of `aspect` (width / height),
    /// with near and far planes around the bounds.
    pub fn to_camera(&self, bounds: &Bounds, aspect: f32) -> Camera {
        self.to_camera_framing(bounds, &[], aspect)
    }

    /// [`Self::to_camera`] framing `boxes` inside `bounds` where the view is fitted
    /// ([`Camera::fit_boxes`]; none: `bounds`).
    pub fn to_camera_framing(&self, bounds: &Bounds, boxes: &[Framed], aspect: f32) -> Camera {
        self.to_camera_framing_in(bounds, boxes, aspect, &[FitWindow::WHOLE])
    }

    /// [`Self::to_camera_framing`] fitting into the best of `windows`
    /// ([`Camera::fit_boxes_in`]).
    pub fn to_camera_framing_in(
        &self,
        bounds: &Bounds,
        boxes: &[Framed],
        aspect: f32,
        windows: &[FitWindow],
    ) -> Camera {
        let mut c = Camera {
            projection: self.projection,
            azimuth_deg: self.azimuth_deg,
            elevation_deg: self.elevation_deg,
            fov_y_deg: self.fov_y_deg,
            ..Default::default()
        };
        let centre = c.fit_boxes_in(bounds, boxes, aspect, windows);
        if let Some(d) = self.distance {
            c.distance = d;
        }
        c.zoom_about(self.zoom, centre, aspect);
        if let Some(t) = self.target {
            c.target = Vec3::from(t);
        }
        c.fit_depth_range(bounds);
        c
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A view file a script edited wrongly is refused naming the key and what it takes:
    /// a number in quotes, a target of two, a fractional version, a NaN (with its key and
    /// place), a key given twice, an image of no pixels; `null` is the key left out.
    #[test]
    fn wrong_types_name_the_key_and_what_it_takes() {
        for (text, says) in [
            (
                r#"{"version":1,"target":[0,0,"x"]}"#,
                "target [0,0,\"x\"]: expected three numbers",
            ),
            (
                r#"{"version":1,"target":[0,0]}"#,
                "expected three numbers, [x, y, z]",
            ),
            (
                r#"{"version":1,"azimuth_deg":"120"}"#,
                "azimuth_deg \"120\": expected a number (a number is written without quotes)",
            ),
            (
                r#"{"version":1.0}"#,
                "version 1.0: expected the whole number 1",
            ),
            (
                r#"{"version":null}"#,
                "version null: expected the whole number 1",
            ),
            (
                r#"{"version":1,"projection":"ortho"}"#,
                "expected \"perspective\" or",
            ),
            (
                "{\"version\": 1,\n \"zoom\": NaN}",
                "NaN for zoom at line 2 column 10: JSON has no NaN",
            ),
            (
                r#"{"version":1,"azimuth_deg":10,"azimuth_deg":200}"#,
                "azimuth_deg is given twice",
            ),
            (
                r#"{"version":1,"image":[0,0]}"#,
                "image [0, 0] (the width and height",
            ),
            (
                r#"{"version":1,"image":[640.5,480]}"#,
                "expected two whole numbers of pixels",
            ),
            // A field of view past what a fit frames (179°: the data off screen).
            (
                r#"{"version":1,"fov_y_deg":179}"#,
                "fov_y_deg 179 (must be above 0 and at most 120",
            ),
        ] {
            let e = ViewFile::parse(text).unwrap_err();
            assert!(e.contains(says), "{text}: {e}");
        }
        let v = ViewFile::parse(r#"{"version":1,"zoom":null,"azimuth_deg":null,"target":null}"#)
            .unwrap();
        assert_eq!(v, ViewFile::default());
    }

    #[test]
    fn round_trip_through_a_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("view.json");
        let cam = Camera {
            target: Vec3::new(1.0, -2.0, 3.5),
            azimuth_deg: 12.0,
            elevation_deg: -40.0,
            distance: 9.0,
            fov_y_deg: 45.0,
            projection: Projection::Orthographic,
            ..Default::default()
        };
        ViewFile::from_camera(&cam).save(&path).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(text.contains("\"version\": 1") && text.contains("orthographic"));
        let back = ViewFile::load(&path).unwrap();
        let b = Bounds::new([0.0; 3], [1.0; 3]);
        let c2 = back.to_camera(&b, 1.0);
        assert_eq!(c2.target, cam.target);
        assert_eq!(c2.distance, cam.distance);
        assert_eq!(
            (
                c2.azimuth_deg,
                c2.elevation_deg,
                c2.fov_y_deg,
                c2.projection
            ),
            (12.0, -40.0, 45.0, Projection::Orthographic)
        );
    }

    /// A saved view (distance given, zoom 1) is zoomed by editing its zoom: 2 halves the
    /// distance, in either projection (the orthographic height follows the distance).
    #[test]
    fn zoom_applies_to_a_given_distance() {
        let bounds = Bounds {
            min: Vec3::ZERO,
            max: Vec3::splat(10.0),
        };
        for projection in ["perspective", "orthographic"] {
            let text = |zoom: f32| {
                format!(
                    r#"{{"version": 1, "projection": "{projection}", "distance": 100, "zoom": {zoom}}}"#
                )
            };
            let one = ViewFile::parse(&text(1.0)).unwrap().to_camera(&bounds, 1.5);
            let two = ViewFile::parse(&text(2.0)).unwrap().to_camera(&bounds, 1.5);
            assert_eq!((one.distance, two.distance), (100.0, 50.0), "{projection}");
            // Saving the zoomed camera stores the distance it came to, with zoom 1.
            let saved = ViewFile::from_camera(&two);
            assert_eq!((saved.distance, saved.zoom), (Some(50.0), 1.0));
            assert_eq!(saved.to_camera(&bounds, 1.5).distance, 50.0);
        }
    }

    #[test]
    fn minimal_file_fits_and_zooms() {
        let text = r#"{"version": 1, "zoom": 2, "future_field": true, "azimuth": 3}"#;
        let v = ViewFile::parse(text).unwrap();
        assert_eq!(ViewFile::unknown_fields(text), ["azimuth", "future_field"]);
        assert!(ViewFile::unknown_fields(&serde_json::to_string(&v).unwrap()).is_empty());
        let b = Bounds::new([0.0; 3], [10.0; 3]);
        let fitted = ViewFile::parse(r#"{"version": 1}"#)
            .unwrap()
            .to_camera(&b, 1.0);
        let c = v.to_camera(&b, 1.0);
        assert_eq!(c.target, fitted.target);
        assert!((c.distance * 2.0 - fitted.distance).abs() < 1e-4);
    }

    #[test]
    fn bad_files_are_refused_with_a_reason() {
        for (text, needle) in [
            (r#"{"version": 2}"#, "version 2"),
            (r#"{"azimuth_deg": 3}"#, "version"),
            (r#"{"version": 1, "elevation_deg": 120}"#, "elevation"),
            (r#"{"version": 1, "fov_y_deg": 0}"#, "fov_y_deg"),
            (r#"{"version": 1, "distance": -1}"#, "positive"),
            (r#"{"version": 1, "projection": "fisheye"}"#, "fisheye"),
            ("not json", "expected"),
        ] {
            let e = ViewFile::parse(text).unwrap_err();
            assert!(e.contains(needle), "{text}: {e}");
        }
        let e = ViewFile::load(Path::new("/nonexistent/view.json")).unwrap_err();
        assert!(e.to_string().contains("/nonexistent/view.json"));
    }
}
