//! The JSON metadata section: what the file holds and where it came from.
//!
//! Everything here is descriptive (the renderer needs none of it to draw), so it is
//! stored as UTF-8 JSON that other tools can read without this crate. Unknown fields are
//! ignored on read so later minor versions may add fields.

use serde::{Deserialize, Serialize};

/// A simulation cell: `origin + u·a + v·b + w·c` for u, v, w in [0, 1).
///
/// Orthogonal boxes have `a = (lx,0,0)`, `b = (0,ly,0)`, `c = (0,0,lz)`; LAMMPS triclinic
/// boxes have `a = (lx,0,0)`, `b = (xy,ly,0)`, `c = (xz,yz,lz)`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SimulationBox {
    pub origin: [f64; 3],
    pub a: [f64; 3],
    pub b: [f64; 3],
    pub c: [f64; 3],
    /// Periodicity along a, b, c, when the input says (LAMMPS `pp`, XYZ `pbc=`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub periodic: Option<[bool; 3]>,
}

impl SimulationBox {
    /// An axis-aligned box from its lower and upper corners.
    pub fn orthogonal(lo: [f64; 3], hi: [f64; 3]) -> Self {
        Self::lammps(lo, hi, [0.0; 3])
    }

    /// A LAMMPS box from `xlo..xhi` etc. (the *true* box bounds, not the `_bound` values
    /// a triclinic dump prints) and the tilt factors `xy xz yz`.
    pub fn lammps(lo: [f64; 3], hi: [f64; 3], tilt: [f64; 3]) -> Self {
        let [xy, xz, yz] = tilt;
        SimulationBox {
            origin: lo,
            a: [hi[0] - lo[0], 0.0, 0.0],
            b: [xy, hi[1] - lo[1], 0.0],
            c: [xz, yz, hi[2] - lo[2]],
            periodic: None,
        }
    }

    /// True when the cell vectors are axis-aligned.
    pub fn is_orthogonal(&self) -> bool {
        self.a[1] == 0.0
            && self.a[2] == 0.0
            && self.b[0] == 0.0
            && self.b[2] == 0.0
            && self.c[0] == 0.0
            && self.c[1] == 0.0
    }

    /// Cartesian position of fractional coordinates `(u, v, w)`.
    pub fn from_fractional(&self, f: [f64; 3]) -> [f64; 3] {
        let mut p = self.origin;
        for (k, pk) in p.iter_mut().enumerate() {
            *pk += f[0] * self.a[k] + f[1] * self.b[k] + f[2] * self.c[k];
        }
        p
    }
}

/// One species: how a particle of this kind looks.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Species {
    pub name: String,
    /// Sphere radius in the simulation's length unit.
    #[serde(deserialize_with = "wide::f32")]
    pub radius: f32,
    /// Linear-light RGB albedo in [0, 1].
    #[serde(deserialize_with = "wide::f32x3")]
    pub colour: [f32; 3],
    /// The smallest and largest radius of the species' particles in the input, where they
    /// differ (polydisperse data, drawn at `radius`, their mean); absent otherwise.
    #[serde(
        default,
        skip_serializing_if = "Option::is_none",
        deserialize_with = "wide::f32x2"
    )]
    pub radius_range: Option<[f32; 2]>,
}

impl Species {
    /// The radius of the species' smallest particle (its drawn radius where all are
    /// one size).
    pub fn smallest_radius(&self) -> f32 {
        self.radius_range
            .map_or(self.radius, |[lo, _]| lo.min(self.radius))
    }
}

/// The range over which the per-particle radii are quantized, and how.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct RadiusInfo {
    /// Radius of quantized 0.
    #[serde(deserialize_with = "wide::f32")]
    pub min: f32,
    /// Radius of quantized 65535.
    #[serde(deserialize_with = "wide::f32")]
    pub max: f32,
    /// Quantized on a log scale (the RADIUS_LOG section, the metadata's `radius_log`)
    /// rather than linearly (RADIUS, `radius`). Not a JSON field: the field's name says it.
    #[serde(skip)]
    pub log: bool,
}

impl RadiusInfo {
    /// Radii spanning more than this factor are quantized on a log scale: linear steps
    /// over the range would be more than 0.1 % of the smallest radius (`(max − min) /
    /// 131070`, half a step), while a log scale keeps every radius within
    /// `(max/min)^(1/131070) − 1` of its own size (1.1·10⁻⁴ for radii spanning 10⁶).
    pub const LOG_ABOVE: f32 = 132.0;

    /// The range `min..=max`, on a log scale where it spans more than [`Self::LOG_ABOVE`].
    pub fn for_range(min: f32, max: f32) -> RadiusInfo {
        RadiusInfo {
            min,
            max,
            log: min > 0.0 && max > Self::LOG_ABOVE * min,
        }
    }

    /// Decodes a quantized radius: linearly `min + (max − min) · (q / 65535)` in `f32`; on
    /// a log scale `min · (max / min)^(q / 65535)` in `f64`, rounded to `f32`.
    #[inline]
    pub fn decode(&self, q: u16) -> f32 {
        if self.log {
            let (lo, hi) = (f64::from(self.min), f64::from(self.max));
            (lo * (hi / lo).powf(f64::from(q) / 65535.0)) as f32
        } else {
            self.min + (self.max - self.min) * (f32::from(q) / 65535.0)
        }
    }

    /// The nearest quantized value of `radius` (clamped to the range; on a log scale,
    /// nearest in the logarithm).
    #[inline]
    pub fn encode(&self, radius: f32) -> u16 {
        if self.log {
            let (lo, hi) = (f64::from(self.min), f64::from(self.max));
            let t = (f64::from(radius) / lo).ln() / (hi / lo).ln();
            if t.is_nan() {
                return 0;
            }
            (t * 65535.0).round().clamp(0.0, 65535.0) as u16
        } else {
            encode16(radius, self.min, self.max)
        }
    }

    /// Whether the range is one a reader accepts: finite, `0 ≤ min ≤ max`, and on a log
    /// scale `0 < min`.
    pub fn is_valid(&self) -> bool {
        self.min.is_finite()
            && self.max.is_finite()
            && 0.0 <= self.min
            && self.min <= self.max
            && (!self.log || self.min > 0.0)
    }

    /// The width of a quantization step at radius `r`: the range over 65535 linearly, `r`
    /// times the step's factor less 1 on a log scale.
    pub fn step_at(&self, r: f64) -> f64 {
        let (lo, hi) = (f64::from(self.min), f64::from(self.max));
        if self.log {
            r * ((hi / lo).powf(1.0 / 65535.0) - 1.0)
        } else {
            (hi - lo) / 65535.0
        }
    }

    /// The largest difference between a radius in the range and its decoded value, over
    /// that radius: half a step over the smallest radius linearly, half a step's factor
    /// less 1 on a log scale (rounding aside).
    pub fn worst_relative_error(&self) -> f64 {
        let (lo, hi) = (f64::from(self.min), f64::from(self.max));
        if self.log {
            (hi / lo).powf(1.0 / 131_070.0) - 1.0
        } else if lo > 0.0 {
            (hi - lo) / 131_070.0 / lo
        } else {
            f64::INFINITY
        }
    }
}

/// The nearest 16-bit step of `value` over `[min, max]` (clamped to it; 0 for a range
/// of one value), as writers quantize radii and attributes.
#[inline]
fn encode16(value: f32, min: f32, max: f32) -> u16 {
    let span = max - min;
    if span > 0.0 {
        ((value - min) / span * 65535.0).round().clamp(0.0, 65535.0) as u16
    } else {
        0
    }
}

/// The optional per-particle scalar and its quantization range.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AttributeInfo {
    pub name: String,
    /// Value of quantized 0.
    #[serde(deserialize_with = "wide::f32")]
    pub min: f32,
    /// Value of quantized 65535.
    #[serde(deserialize_with = "wide::f32")]
    pub max: f32,
    /// The values are base-10 logarithms of a column's positive values (named
    /// `log10(NAME)`), and each node's mean is the logarithm of the area-weighted mean
    /// of the values below it, as the metadata's `attribute_log10` says of the first
    /// attribute. Set in a further attribute's entry (`attributes`) only: the first's is
    /// `attribute_log10`, and a file setting it in `attribute` is refused.
    #[serde(
        default,
        skip_serializing_if = "std::ops::Not::not",
        deserialize_with = "null_is_false"
    )]
    pub log10: bool,
}

/// Single-precision fields read as the nearest double, then rounded to single precision
/// (FORMAT.md section 7): a number past single precision becomes infinite, which the
/// metadata's checks refuse naming the field, where the JSON reader's own refusal would
/// name a line and column only.
mod wide {
    use serde::{Deserialize, Deserializer};

    pub fn f32<'de, D: Deserializer<'de>>(d: D) -> Result<f32, D::Error> {
        f64::deserialize(d).map(|v| v as f32)
    }

    pub fn f32x3<'de, D: Deserializer<'de>>(d: D) -> Result<[f32; 3], D::Error> {
        <[f64; 3]>::deserialize(d).map(|a| a.map(|v| v as f32))
    }

    pub fn f32x2<'de, D: Deserializer<'de>>(d: D) -> Result<Option<[f32; 2]>, D::Error> {
        Option::<[f64; 2]>::deserialize(d).map(|o| o.map(|a| a.map(|v| v as f32)))
    }
}

impl AttributeInfo {
    /// Decodes a quantized attribute value.
    pub fn decode(&self, q: u16) -> f32 {
        self.min + (self.max - self.min) * (f32::from(q) / 65535.0)
    }

    /// The quantized value a writer stores for `value`: the nearest, clamped to the
    /// range (0 for a range of one value).
    pub fn encode(&self, value: f32) -> u16 {
        encode16(value, self.min, self.max)
    }

    /// The quantized values a writer stores for the values from `lo` to `hi`
    /// (inclusive; either end may be infinite): the codes of the ends, so that a value
    /// stored for an end is in the range whatever its rounding (`2:2` holds the 2s of a
    /// column of integers). `None` where the range misses the attribute's.
    pub fn codes(&self, [lo, hi]: [f32; 2]) -> Option<(u16, u16)> {
        if lo.is_nan() || hi.is_nan() || lo > hi || hi < self.min || lo > self.max {
            return None;
        }
        let a = if lo <= self.min { 0 } else { self.encode(lo) };
        let b = if hi >= self.max {
            u16::MAX
        } else {
            self.encode(hi)
        };
        Some((a, b))
    }
}

/// Where the particles came from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SourceInfo {
    pub path: String,
    pub size: u64,
    /// Modification time, seconds since the Unix epoch, when the file system gives one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub modified_unix: Option<i64>,
    /// Nanoseconds past `modified_unix` (0-999 999 999), where the file system keeps
    /// them: a file rewritten within the same second is still told apart.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub modified_nanos: Option<u32>,
    /// Index of the frame within the source (0-based; absent or `null` is 0).
    #[serde(default, deserialize_with = "null_is_zero")]
    pub frame: u64,
    /// Where the frame's bytes lie in the source and their checksum: recorded by batch
    /// conversions of uncompressed dumps whose frames are contiguous byte ranges (and of
    /// GSD files, whose frames are their chunks and frame 0's they take), so that a
    /// rerun over a dump that has grown since (a simulation still writing it) keeps the
    /// frames whose bytes are unchanged instead of converting them again.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bytes: Option<FrameBytes>,
}

/// An optional list whose absence means none: `null` is its absence too.
fn null_is_empty<'de, D: serde::Deserializer<'de>, T: Deserialize<'de>>(
    d: D,
) -> Result<Vec<T>, D::Error> {
    Ok(Option::<Vec<T>>::deserialize(d)?.unwrap_or_default())
}

/// An optional flag whose absence means `false`: `null` is its absence too (section 7).
fn null_is_false<'de, D: serde::Deserializer<'de>>(d: D) -> Result<bool, D::Error> {
    Ok(Option::<bool>::deserialize(d)?.unwrap_or(false))
}

/// An optional integer whose absence means 0: `null` is its absence too (section 7: an
/// optional field may be absent or `null`).
fn null_is_zero<'de, D: serde::Deserializer<'de>>(d: D) -> Result<u64, D::Error> {
    Ok(Option::<u64>::deserialize(d)?.unwrap_or(0))
}

impl FrameBytes {
    /// Whether the checksum is written as the format says: 16 lowercase hexadecimal
    /// digits.
    pub fn checksum_well_formed(&self) -> bool {
        self.xxh3.len() == 16
            && self
                .xxh3
                .bytes()
                .all(|b| b.is_ascii_digit() || (b'a'..=b'f').contains(&b))
    }
}

/// A frame's byte range in its source, `[start, end)`, and the XXH3-64 of those bytes.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct FrameBytes {
    pub start: u64,
    pub end: u64,
    /// XXH3-64 (seed 0) of the bytes, as 16 lowercase hexadecimal digits.
    pub xxh3: String,
}

/// The parameters the hierarchy was built with.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BuildInfo {
    /// A cluster is split while it holds more than this many points.
    pub max_cluster_size: u32,
    /// The coarsest real level holds at most this many points (under the single top node).
    pub max_root_points: u32,
    /// Levels between a node and the points it quantizes (δn in the format spec).
    pub delta_n: u32,
    /// Bits per quantized coordinate: 8 or 16.
    pub position_bits: u32,
    /// Present when the hierarchy was built in spatial chunks of at most this many
    /// particles (FORMAT.md, "Chunked builds").
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub chunk_points: Option<u64>,
}

/// The metadata section.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Metadata {
    /// Number of particles (the finest level).
    pub particles: u64,
    #[serde(rename = "box", default, skip_serializing_if = "Option::is_none")]
    pub simulation_box: Option<SimulationBox>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub timestep: Option<u64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub time: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub units: Option<String>,
    pub species: Vec<Species>,
    /// The input column whose values are the species (a structure type such as
    /// `c_cna`), where they do not come from the input's own types or elements.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub species_column: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub attribute: Option<AttributeInfo>,
    /// The attribute is the base-10 logarithm of a column's values (`log10(NAME)`), and
    /// each node's mean is the logarithm of the area-weighted mean of the values below
    /// it, not the mean of their logarithms: so that `10^mean` times a cluster's area is
    /// the light of its particles (splats lit by the attribute). Files that store a
    /// logarithm without this flag hold means of logarithms.
    #[serde(
        default,
        skip_serializing_if = "std::ops::Not::not",
        deserialize_with = "null_is_false"
    )]
    pub attribute_log10: bool,
    /// Further per-particle attributes (version 1.2: the ATTRIBUTES and NODE_ATTRIBUTES
    /// sections), each quantized over its own range as `attribute` is; a reader of
    /// version 1.1 knows the first only.
    #[serde(
        default,
        skip_serializing_if = "Vec::is_empty",
        deserialize_with = "null_is_empty"
    )]
    pub attributes: Vec<AttributeInfo>,
    /// The range of the per-particle radii (the RADIUS or RADIUS_LOG section), where the
    /// particles of a species differ in size. Its JSON field is `radius` for linear
    /// steps, `radius_log` for a log scale (see [`Metadata::to_json`]; the reader moves
    /// `radius_log` here).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub radius: Option<RadiusInfo>,
    /// The JSON field of radii on a log scale (version 1.2); `None` in a metadata read or
    /// to be written, whose `radius` says the scale.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub radius_log: Option<RadiusInfo>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub source: Option<SourceInfo>,
    pub build: BuildInfo,
    /// Largest Euclidean distance between a particle's decoded position and its input
    /// position (as single precision), over all particles.
    pub max_position_error: f64,
    /// The program that wrote the file, e.g. `mdlod 0.1.0`.
    pub writer: String,
    /// The options that changed what was read from the input, as given (`--wrap`,
    /// `--no-sizes`, `--species-name W=SOL`, `--columns ...`, `--radius-column C`,
    /// `--diameter-column C`): the data is the input's only with them. Absent: none.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub input_options: Vec<String>,
}

impl Metadata {
    /// The METADATA section's JSON. JSON has no NaN or infinity: serialized, a non-finite
    /// number becomes `null`, and the file could not be opened (or, for the optional
    /// time, would lose it). A writer refuses such metadata instead of writing it.
    pub fn to_json(&self) -> Result<Vec<u8>, String> {
        let mut numbers: Vec<(&str, f64)> =
            vec![("maximum position error", self.max_position_error)];
        if let Some(t) = self.time {
            numbers.push(("time", t));
        }
        if let Some(b) = &self.simulation_box {
            for v in [b.origin, b.a, b.b, b.c].iter().flatten() {
                numbers.push(("box", *v));
            }
        }
        for s in &self.species {
            numbers.push(("species radius", f64::from(s.radius)));
            for r in s.radius_range.iter().flatten() {
                numbers.push(("species radius range", f64::from(*r)));
            }
            for c in s.colour {
                numbers.push(("species colour", f64::from(c)));
            }
        }
        if let Some(a) = &self.attribute {
            numbers.push(("attribute range", f64::from(a.min)));
            numbers.push(("attribute range", f64::from(a.max)));
        }
        if let Some(r) = &self.radius {
            numbers.push(("radius range", f64::from(r.min)));
            numbers.push(("radius range", f64::from(r.max)));
        }
        if let Some((what, v)) = numbers.iter().find(|(_, v)| !v.is_finite()) {
            return Err(format!("the metadata's {what} is {v}, not a finite number"));
        }
        // Radii on a log scale go under `radius_log`: a reader of version 1.1, which
        // knows `radius` as linear steps, ignores the field and skips the RADIUS_LOG
        // section, drawing each particle at its species' radius.
        if let Some(r) = self.radius.filter(|r| r.log) {
            let mut m = self.clone();
            m.radius = None;
            m.radius_log = Some(r);
            return serde_json::to_vec_pretty(&m).map_err(|e| e.to_string());
        }
        serde_json::to_vec_pretty(self).map_err(|e| e.to_string())
    }
}

/// The converter's palette for numeric types and names of no element (sRGB): its first
/// colours; further slots take [`palette_colour`]'s.
const PALETTE: &[[u8; 3]] = &[
    [230, 102, 51],
    [102, 102, 255],
    [255, 255, 0],
    [255, 102, 255],
    [51, 230, 51],
    [0, 230, 230],
    [255, 153, 0],
    [153, 51, 204],
    [128, 128, 128],
    [51, 153, 102],
];

/// Palette slot `slot`'s colour as linear light, as a file's species table keeps it.
pub fn palette_colour_linear(slot: usize) -> [f32; 3] {
    srgb_to_linear(palette_colour(slot))
}

/// An sRGB colour (8 bits a channel) as linear light.
pub fn srgb_to_linear(c: [u8; 3]) -> [f32; 3] {
    c.map(|v| srgb_channel_to_linear(f32::from(v) / 255.0))
}

/// One sRGB channel in [0, 1] as linear light.
pub fn srgb_channel_to_linear(v: f32) -> f32 {
    if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

/// The sRGB colour of palette slot `slot` (a LAMMPS type's number less one): the fixed
/// palette's first ten, then hues a golden angle (137.5°) apart at two brightnesses, so
/// that a run with many types does not repeat its first ten colours (the palette used to
/// be cycled: type 11 drew as type 1).
pub fn palette_colour(slot: usize) -> [u8; 3] {
    if let Some(c) = PALETTE.get(slot) {
        return *c;
    }
    let k = slot - PALETTE.len();
    let hue = (20.0 + 137.507_76 * k as f64).rem_euclid(360.0);
    let (saturation, value) = if k.is_multiple_of(2) {
        (0.55, 0.95)
    } else {
        (0.8, 0.7)
    };
    // HSV to RGB.
    let c = value * saturation;
    let h = hue / 60.0;
    let x = c * (1.0 - (h.rem_euclid(2.0) - 1.0).abs());
    let (r, g, b) = match h as u32 {
        0 => (c, x, 0.0),
        1 => (x, c, 0.0),
        2 => (0.0, c, x),
        3 => (0.0, x, c),
        4 => (x, 0.0, c),
        _ => (c, 0.0, x),
    };
    let m = value - c;
    [r, g, b].map(|v| ((v + m) * 255.0).round().clamp(0.0, 255.0) as u8)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A range's ends are compared as the writer stores them: a column of integers 1 to 5
    /// keeps 2, 3 and 4 a little off (2.00006), and `2:2` still holds every 2; a decimal
    /// end holds the values stored for it; a range beside the attribute's holds nothing.
    #[test]
    fn value_ranges_hold_the_values_stored_for_their_ends() {
        let info = AttributeInfo {
            name: "c_cna".into(),
            min: 1.0,
            max: 5.0,
            log10: false,
        };
        for v in [1.0f32, 2.0, 3.0, 4.0, 5.0] {
            let q = info.encode(v);
            let (a, b) = info.codes([v, v]).unwrap();
            assert!(a <= q && q <= b, "{v}: {q} outside {a}..{b}");
            // Its neighbours' codes are not in it.
            for w in [v - 1.0, v + 1.0]
                .into_iter()
                .filter(|w| (1.0..=5.0).contains(w))
            {
                let r = info.encode(w);
                assert!(!(a <= r && r <= b), "{v}:{v} holds {w}");
            }
        }
        assert_ne!(
            info.decode(info.encode(2.0)),
            2.0,
            "the test needs an inexact 2"
        );
        let (a, b) = info.codes([1.0, 2.0]).unwrap();
        assert!(a <= info.encode(2.0) && info.encode(2.0) <= b);
        let ke = AttributeInfo {
            name: "c_ke".into(),
            min: 0.0,
            max: 0.7087,
            log10: false,
        };
        let (a, b) = ke.codes([0.1, 0.3]).unwrap();
        assert!(a <= ke.encode(0.3) && ke.encode(0.3) <= b && a <= ke.encode(0.1));
        let (a, _) = ke.codes([0.2, f32::INFINITY]).unwrap();
        assert!(a <= ke.encode(0.2));
        assert_eq!(info.codes([6.0, 9.0]), None);
        assert_eq!(info.codes([f32::NEG_INFINITY, 0.5]), None);
        assert_eq!(
            info.codes([f32::NEG_INFINITY, f32::INFINITY]),
            Some((0, u16::MAX))
        );
        assert_eq!(info.codes([5.0, f32::INFINITY]), Some((u16::MAX, u16::MAX)));
        // One value throughout: held by a range around it.
        let flat = AttributeInfo {
            name: "m".into(),
            min: 2.0,
            max: 2.0,
            log10: false,
        };
        assert_eq!(flat.codes([1.0, 3.0]), Some((0, u16::MAX)));
        assert_eq!(flat.codes([3.0, 4.0]), None);
    }

    fn metadata() -> Metadata {
        Metadata {
            particles: 1,
            simulation_box: None,
            timestep: Some(3),
            time: Some(0.25),
            units: None,
            species: vec![Species {
                name: "Cu".into(),
                radius: 1.28,
                colour: [0.8, 0.5, 0.2],
                radius_range: None,
            }],
            species_column: None,
            attribute: None,
            attribute_log10: false,
            attributes: Vec::new(),
            radius: None,
            radius_log: None,
            source: None,
            build: BuildInfo {
                max_cluster_size: 8,
                max_root_points: 4096,
                delta_n: 1,
                position_bits: 16,
                chunk_points: None,
            },
            max_position_error: 1.5e-5,
            input_options: Vec::new(),
            writer: "mdlod test".into(),
        }
    }

    #[test]
    fn metadata_json_reads_back_or_is_refused() {
        let m = metadata();
        let json = m.to_json().unwrap();
        assert_eq!(serde_json::from_slice::<Metadata>(&json).unwrap(), m);
        // Numbers read as the nearest double (FORMAT.md section 7): this one was read an
        // ulp off by a parser that is not correctly rounded. Every f64 reads back.
        let text = String::from_utf8(json).unwrap();
        let exact = 9.025591881400017e-5f64;
        assert_eq!(exact.to_bits(), 0x3f17_a8f8_e0d8_ada0);
        let with = text.replace("0.000015,", "0.00009025591881400017,");
        assert_ne!(with, text);
        let read = serde_json::from_str::<Metadata>(&with).unwrap();
        assert_eq!(read.max_position_error.to_bits(), exact.to_bits());
        let mut x = 1.234_567_890_123_456_7e-5f64;
        for _ in 0..2000 {
            let m = Metadata {
                max_position_error: x,
                ..metadata()
            };
            let back: Metadata = serde_json::from_slice(&m.to_json().unwrap()).unwrap();
            assert_eq!(back.max_position_error.to_bits(), x.to_bits(), "{x:e}");
            x = x * 1.618_033_988_749_895 + 1e-7;
            if x > 1e6 {
                x *= 1e-11;
            }
        }
        for bad in [
            Metadata {
                max_position_error: f64::INFINITY,
                ..metadata()
            },
            Metadata {
                time: Some(f64::NAN),
                ..metadata()
            },
        ] {
            let e = bad.to_json().unwrap_err();
            assert!(e.contains("not a finite number"), "{e}");
        }
    }
}
