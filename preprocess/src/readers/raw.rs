//! Raw binary arrays described by a small JSON sidecar (`*.raw.json`, or any name: a
//! JSON object with the key `mdlod_raw` is recognised by its content): for codes that
//! can dump their arrays but have no standard format (or for a quick `numpy.tofile`).
//!
//! The sidecar names the files (relative to itself) and how to read them:
//!
//! ```json
//! {
//!   "mdlod_raw": 1,
//!   "particles": 1000000,
//!   "positions": { "file": "pos.f32", "type": "f32", "layout": "interleaved" },
//!   "species":   { "file": "type.u8", "type": "u8", "names": ["Cu", "Ag"] },
//!   "radii":     [1.28, 1.44],
//!   "attribute": { "file": "pe.f32", "type": "f32", "name": "c_pe" },
//!   "radius":    { "file": "h.f32", "type": "f32", "name": "h" },
//!   "box":       { "origin": [0, 0, 0], "a": [10, 0, 0], "b": [0, 10, 0], "c": [0, 0, 10] },
//!   "timestep": 1000, "time": 2.0, "units": "metal"
//! }
//! ```
//!
//! - `positions` is required: `type` `f32` or `f64`; `layout` `interleaved` (x y z per
//!   particle, the default) or `planar` (all x, then all y, then all z). `particles` may
//!   be left out when the positions file holds exactly the particles; then every other
//!   array must hold exactly as many values (arrays of different lengths are an error).
//!   With it, longer arrays are read for their first values, except planar positions:
//!   their y follow every particle's x, so a shorter count would read y from x values.
//! - `species` (optional): one integer per particle (`u8`, `u16`, `u32` or `i32`), an
//!   index into `names` (distinct, not empty; default names are the numbers); `radii`
//!   optionally gives each species' radius (one per name, or one without `species`).
//! - `attribute` (optional): one `f32` or `f64` per particle; or `attributes`, a list of
//!   such arrays, each with its own `name` (an SPH run's density, temperature and mass),
//!   of which `--attribute NAME` picks one and takes more given again (the first without
//!   it).
//! - `radius` or `diameter` (optional, not both): each particle's size, one `f32` or
//!   `f64` per particle (an SPH code's smoothing length `h` as `radius`; `name` says what
//!   it is). Its particles are drawn at their own sizes, as a dump's size column's; a
//!   size of 0 passes here and is refused by species unless `--radius` gives the
//!   species one; `--no-sizes` leaves the array unread.
//! - Every array may have `offset` (bytes to skip, default 0) and `byte_order`
//!   (`little`, the default, or `big`).
//! - Unknown keys are errors (a misspelt key must not be ignored silently); every size is
//!   checked against the file with checked arithmetic; non-finite values and species
//!   indices past `names` are errors naming the file and the byte.

use std::path::{Path, PathBuf};

use rayon::prelude::*;
use serde::Deserialize;

use super::{FrameInfo, ReadError, ReadOptions};
use crate::frame::{Attribute, Frame, SimulationBox, SpeciesName};
use crate::progress::Progress;

/// `ENODEV`, what mapping a file that only the kernel holds (`/proc/...`) fails with.
const NO_SUCH_DEVICE: i32 = 19;

/// The array files a raw sidecar at `path` names (resolved next to it), when `path` is
/// such a sidecar (a small JSON object with `mdlod_raw`); `None` otherwise. The arrays
/// are the data: a batch rerun compares them as well as the sidecar.
pub(crate) fn data_files(path: &Path) -> Option<Vec<PathBuf>> {
    if std::fs::metadata(path).ok()?.len() > 1 << 20 {
        return None;
    }
    let sidecar: Sidecar = serde_json::from_slice(&std::fs::read(path).ok()?).ok()?;
    let dir = path.parent().unwrap_or(Path::new(""));
    let arrays = [
        Some(&sidecar.positions),
        sidecar.species.as_ref(),
        sidecar.attribute.as_ref(),
        sidecar.radius.as_ref(),
        sidecar.diameter.as_ref(),
    ];
    Some(
        arrays
            .into_iter()
            .flatten()
            .chain(sidecar.attributes.iter().flatten())
            .map(|a| dir.join(&a.file))
            .collect(),
    )
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Sidecar {
    mdlod_raw: u32,
    #[serde(default)]
    particles: Option<u64>,
    positions: Array,
    #[serde(default)]
    species: Option<Array>,
    #[serde(default)]
    radii: Option<Vec<f32>>,
    #[serde(default)]
    attribute: Option<Array>,
    #[serde(default)]
    attributes: Option<Vec<Array>>,
    #[serde(default)]
    radius: Option<Array>,
    #[serde(default)]
    diameter: Option<Array>,
    #[serde(default, rename = "box")]
    simulation_box: Option<BoxSpec>,
    #[serde(default)]
    timestep: Option<u64>,
    #[serde(default)]
    time: Option<f64>,
    #[serde(default)]
    units: Option<String>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Array {
    file: PathBuf,
    #[serde(rename = "type")]
    ty: String,
    #[serde(default)]
    offset: u64,
    #[serde(default)]
    layout: Option<String>,
    #[serde(default)]
    byte_order: Option<String>,
    #[serde(default)]
    names: Option<Vec<String>>,
    #[serde(default)]
    name: Option<String>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct BoxSpec {
    origin: [f64; 3],
    a: [f64; 3],
    b: [f64; 3],
    c: [f64; 3],
    #[serde(default)]
    periodic: Option<[bool; 3]>,
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Ty {
    F32,
    F64,
    U8,
    U16,
    U32,
    I32,
}

impl Ty {
    fn size(self) -> usize {
        match self {
            Ty::U8 => 1,
            Ty::U16 => 2,
            Ty::F32 | Ty::U32 | Ty::I32 => 4,
            Ty::F64 => 8,
        }
    }

    /// The type's name, as a sidecar writes it.
    fn name(self) -> &'static str {
        match self {
            Ty::F32 => "f32",
            Ty::F64 => "f64",
            Ty::U8 => "u8",
            Ty::U16 => "u16",
            Ty::U32 => "u32",
            Ty::I32 => "i32",
        }
    }

    /// The float type a float array declared as this one may really hold: `f32` data
    /// declared `f64` (or the reverse) is the commonest slip writing a sidecar.
    fn other_float(self) -> Option<Ty> {
        match self {
            Ty::F32 => Some(Ty::F64),
            Ty::F64 => Some(Ty::F32),
            _ => None,
        }
    }

    /// Value `i` of an array of this type in `b`, read in place.
    #[inline(always)]
    fn get(self, b: &[u8], i: usize, big: bool) -> f64 {
        fn at<const N: usize>(b: &[u8], i: usize, big: bool) -> [u8; N] {
            let mut w: [u8; N] = b[i * N..(i + 1) * N].try_into().expect("N bytes");
            if big {
                w.reverse();
            }
            w
        }
        match self {
            Ty::U8 => f64::from(b[i]),
            Ty::U16 => f64::from(u16::from_le_bytes(at(b, i, big))),
            Ty::U32 => f64::from(u32::from_le_bytes(at(b, i, big))),
            Ty::I32 => f64::from(i32::from_le_bytes(at(b, i, big))),
            Ty::F32 => f64::from(f32::from_le_bytes(at(b, i, big))),
            Ty::F64 => f64::from_le_bytes(at(b, i, big)),
        }
    }
}

/// One array, mapped and checked.
struct Mapped {
    path: PathBuf,
    map: mdlod_format::mmap::Mmap,
    ty: Ty,
    offset: usize,
    big: bool,
}

impl Mapped {
    fn bytes(&self) -> &[u8] {
        &self.map[self.offset..]
    }

    /// Asks the kernel to read elements `range` (of `per` values each) ahead, in large
    /// requests, while earlier ones are being decoded: a mapping read by page faults
    /// alone waits on one small read-ahead at a time (about 150 MB/s from the disk of
    /// this project's benchmark machine). Only a hint; its failure changes nothing.
    fn read_ahead(&self, range: std::ops::Range<usize>, per: usize) {
        let size = per * self.ty.size();
        let len = self.map.len();
        let start = self
            .offset
            .saturating_add(range.start.saturating_mul(size))
            .min(len);
        let end = self
            .offset
            .saturating_add(range.end.saturating_mul(size))
            .min(len);
        #[cfg(unix)]
        if end > start {
            let _ = self
                .map
                .advise_range(mdlod_format::mmap::Advice::WillNeed, start, end - start);
        }
    }
}

/// True when `data` is a raw sidecar whatever its name: a small JSON object with the
/// key `mdlod_raw` (a damaged one too, so that reading it says what is wrong).
pub(crate) fn sniff(data: &[u8]) -> bool {
    // (A sidecar is a few lines; a large file is none, and is not searched.)
    data.len() <= 1 << 20
        && data.trim_ascii_start().starts_with(b"{")
        && memchr::memmem::find(data, b"\"mdlod_raw\"").is_some()
}

/// The other float type of `m`'s declared one when `m` holds exactly `count` particles
/// (`per` values each) of it: a file of that exact size is no truncated or foreign one,
/// but one whose `type` the sidecar gives wrong.
fn other_type_fits(m: &Mapped, per: usize, count: usize) -> Option<Ty> {
    let t = m.ty.other_float()?;
    let bytes = count.checked_mul(per)?.checked_mul(t.size())?;
    (bytes == m.bytes().len()).then_some(t)
}

/// An opened sidecar and its arrays.
pub(crate) struct Index {
    /// The sidecar, and the line of its `attribute` (or `attributes`) key (1 without
    /// one), for errors.
    sidecar: PathBuf,
    attribute_line: u64,
    particles: usize,
    positions: Mapped,
    planar: bool,
    species: Option<(Mapped, Vec<String>)>,
    radii: Option<Vec<f32>>,
    /// The attributes, each with its name (the first is read unless another is asked for).
    attributes: Vec<(Mapped, String)>,
    /// Each particle's size: the array, its name, and the factor to a radius (1 for a
    /// `radius` array, 0.5 for a `diameter` one).
    sizes: Option<(Mapped, String, f64)>,
    simulation_box: Option<SimulationBox>,
    timestep: Option<u64>,
    time: Option<f64>,
    units: Option<String>,
    /// What a conversion should say about the arrays (values past `particles`).
    notes: Vec<String>,
}

fn err(path: &Path, offset: u64, message: impl Into<String>) -> ReadError {
    ReadError::Binary {
        path: path.to_path_buf(),
        offset,
        message: message.into(),
    }
}

/// The sidecar's line of its first `"key"` (a key without spaces).
fn key_line(text: &[u8], key: &str) -> Option<u64> {
    if key.is_empty() || key.contains(' ') {
        return None;
    }
    let at = memchr::memmem::find(text, format!("\"{key}\"").as_bytes())?;
    Some(memchr::memchr_iter(b'\n', &text[..at]).count() as u64 + 1)
}

/// The sidecar's line of `"child"` inside the object that its first `"parent"` key
/// holds; `None` where that object has no such key.
fn nested_key_line(text: &[u8], parent: &str, child: &str) -> Option<u64> {
    if parent.is_empty() || child.is_empty() || parent.contains(' ') || child.contains(' ') {
        return None;
    }
    let at = memchr::memmem::find(text, format!("\"{parent}\"").as_bytes())?;
    let open = at + memchr::memchr(b'{', &text[at..])?;
    // The object's end: its matching brace, outside strings.
    let (mut depth, mut in_string, mut escaped, mut end) = (0usize, false, false, None);
    for (i, &b) in text[open..].iter().enumerate() {
        match (in_string, b) {
            (true, _) if escaped => escaped = false,
            (true, b'\\') => escaped = true,
            (true, b'"') => in_string = false,
            (true, _) => {}
            (false, b'"') => in_string = true,
            (false, b'{') => depth += 1,
            (false, b'}') => {
                depth -= 1;
                if depth == 0 {
                    end = Some(open + i);
                    break;
                }
            }
            _ => {}
        }
    }
    let object = &text[open..end?];
    let inside = memchr::memmem::find(object, format!("\"{child}\"").as_bytes())?;
    Some(memchr::memchr_iter(b'\n', &text[..open + inside]).count() as u64 + 1)
}

/// A sidecar error at the line of the key the message starts with (`attribute: ...` at
/// the line of `"attribute"`), else at its first line.
fn malformed_in(path: &Path, text: &[u8], message: impl Into<String>) -> ReadError {
    let message = message.into();
    let (key, rest) = message.split_once(':').unwrap_or((message.as_str(), ""));
    let key = key.trim();
    // `positions: layout ...`: the line of `"layout"` inside the positions' object.
    let child = rest
        .trim_start()
        .split([' ', ':'])
        .next()
        .unwrap_or_default()
        .trim_matches('`');
    let line = nested_key_line(text, key, child)
        .or_else(|| key_line(text, key))
        .unwrap_or(1);
    ReadError::Malformed {
        at: super::Location {
            path: path.to_path_buf(),
            line,
        },
        message,
    }
}

/// A JSON reader's message about a sidecar in the sidecar's own words: what a key takes
/// (a file name in quotes, an array's object, a number), not the reader's type names.
fn plain_json_error(message: &str) -> String {
    const WORDS: [(&str, &str); 8] = [
        ("expected path string", "expected a file name in quotes"),
        (
            "expected struct Array with 7 elements",
            "expected an array's object, { \"file\": ..., \"type\": \"f32\" }",
        ),
        (
            "expected struct Array",
            "expected an array's object, { \"file\": ..., \"type\": \"f32\" }",
        ),
        (
            "expected struct BoxSpec",
            "expected the box's object, { \"origin\": [...], \"a\": [...], ... }",
        ),
        ("expected f32", "expected a number"),
        ("expected f64", "expected a number"),
        ("expected u64", "expected a whole number from 0"),
        ("expected u32", "expected a whole number from 0"),
    ];
    let mut out = message.to_string();
    for (from, to) in WORDS {
        if out.contains(from) {
            out = out.replacen(from, to, 1);
            break;
        }
    }
    out.replace("a sequence", "a list [...]")
        .replace("invalid type: map", "invalid type: an object {...}")
}

impl Index {
    pub fn build(path: &Path, text: &[u8]) -> Result<Index, ReadError> {
        let sidecar: Sidecar = serde_json::from_slice(text).map_err(|e| ReadError::Malformed {
            at: super::Location {
                path: path.to_path_buf(),
                line: e.line() as u64,
            },
            message: format!("raw sidecar: {}", plain_json_error(&e.to_string())),
        })?;
        if sidecar.mdlod_raw != 1 {
            return Err(malformed_in(
                path,
                text,
                format!(
                    "raw sidecar version {} (this reader knows 1)",
                    sidecar.mdlod_raw
                ),
            ));
        }
        let dir = path.parent().unwrap_or(Path::new("."));
        let map = |a: &Array, what: &str, allowed: &[&str]| -> Result<Mapped, ReadError> {
            let ty = match a.ty.as_str() {
                "f32" => Ty::F32,
                "f64" => Ty::F64,
                "u8" => Ty::U8,
                "u16" => Ty::U16,
                "u32" => Ty::U32,
                "i32" => Ty::I32,
                t => {
                    return Err(malformed_in(
                        path,
                        text,
                        format!(
                            "{what}: type `{}` (use one of {})",
                            super::shorten(t.as_bytes()),
                            allowed.join(", ")
                        ),
                    ))
                }
            };
            if !allowed.contains(&a.ty.as_str()) {
                return Err(malformed_in(
                    path,
                    text,
                    format!(
                        "{what}: type `{}` (use one of {})",
                        a.ty,
                        allowed.join(", ")
                    ),
                ));
            }
            let big = match a.byte_order.as_deref() {
                None | Some("little") => false,
                Some("big") => true,
                Some(o) => {
                    return Err(malformed_in(
                        path,
                        text,
                        format!(
                            "{what}: byte_order `{}` (use little or big)",
                            super::shorten(o.as_bytes())
                        ),
                    ))
                }
            };
            let file_path = dir.join(&a.file);
            // The sidecar and its key name the file: said with which asked for it.
            let named = |problem: std::fmt::Arguments| {
                malformed_in(
                    path,
                    text,
                    format!(
                        "{what}: `file` \"{}\": {problem}",
                        super::shorten(a.file.as_os_str().as_encoded_bytes())
                    ),
                )
            };
            let shown = super::shorten(file_path.as_os_str().as_encoded_bytes());
            let file = mdlod_format::files::open(&file_path)
                .map_err(|e| named(format_args!("cannot open {shown}: {e}")))?;
            let map = mdlod_format::mmap::map_file(&file).map_err(|e| {
                // A file the kernel makes up (`/proc`) is regular but does not map: the
                // sidecar's key names the wrong file. Another failure (memory) is the
                // system's.
                if e.raw_os_error() == Some(NO_SUCH_DEVICE) {
                    named(format_args!(
                        "{shown} does not map (not a file on a disk): {e}"
                    ))
                } else {
                    ReadError::Io {
                        path: file_path.clone(),
                        source: e,
                    }
                }
            })?;
            let offset = usize::try_from(a.offset)
                .ok()
                .filter(|&o| o <= map.len())
                .ok_or_else(|| {
                    err(
                        &file_path,
                        a.offset,
                        format!(
                            "{what}: offset {} is past the end ({} bytes)",
                            a.offset,
                            map.len()
                        ),
                    )
                })?;
            Ok(Mapped {
                path: file_path,
                map,
                ty,
                offset,
                big,
            })
        };
        let positions = map(&sidecar.positions, "positions", &["f32", "f64"])?;
        let planar = match sidecar.positions.layout.as_deref() {
            None | Some("interleaved") => false,
            Some("planar") => true,
            Some(l) => {
                return Err(malformed_in(
                    path,
                    text,
                    format!(
                        "positions: layout `{}` (use interleaved or planar)",
                        super::shorten(l.as_bytes())
                    ),
                ))
            }
        };
        let available = positions.bytes().len() / (3 * positions.ty.size());
        let particles = match sidecar.particles {
            Some(n) => {
                usize::try_from(n).map_err(|_| malformed_in(path, text, "particles: too many"))?
            }
            None => {
                let len = positions.bytes().len();
                if len % (3 * positions.ty.size()) != 0 {
                    let declared = positions.ty.name();
                    // (Only `f64` declared can be `f32` here: a whole number of `f64`
                    // positions is one of `f32` positions.)
                    let advice = match positions.ty.other_float() {
                        Some(t) if len.is_multiple_of(3 * t.size()) => format!(
                            ", but exactly {} of {t}: is its type {t}, not {declared}? (else \
                             give `particles`)",
                            len / (3 * t.size()),
                            t = t.name()
                        ),
                        _ => "; give `particles`".to_string(),
                    };
                    return Err(err(
                        &positions.path,
                        positions.offset as u64,
                        format!(
                            "{len} bytes are not a whole number of {declared} positions{advice}"
                        ),
                    ));
                }
                available
            }
        };
        // Planar positions put y after every particle's x: with fewer particles named than
        // the array holds, y and z would be read from the middle of the x and y values.
        if planar && sidecar.particles.is_some() {
            let values = positions.bytes().len() / positions.ty.size();
            if values > 3 * particles {
                return Err(malformed_in(
                    path,
                    text,
                    format!(
                        "particles: {particles}, but the planar positions in {} hold {values} \
                         values: planar arrays are read as every particle's x, then every y, \
                         then every z, so `particles` must be the array's own count ({}); \
                         leave it out to read them all",
                        positions.path.display(),
                        values / 3
                    ),
                ));
            }
        }
        // Why `m` may be of the wrong size, when its size or the positions' is that of the
        // other float type: `m`'s own `type` wrong or, without `particles`, the positions'
        // (their `type` sets the count). Both fit when the two are declared of different
        // float types (the data all `f32`, or all `f64`): then both are said.
        let wrong_type = |m: &Mapped, per: usize| -> Option<String> {
            let own = other_type_fits(m, per, particles);
            let size = per * m.ty.size();
            let count = m.bytes().len() / size;
            let theirs = (sidecar.particles.is_none() && m.bytes().len().is_multiple_of(size))
                .then(|| other_type_fits(&positions, 3, count))
                .flatten();
            let (d, pd) = (m.ty.name(), positions.ty.name());
            match (own.map(Ty::name), theirs.map(Ty::name)) {
                (Some(t), None) => Some(format!(
                    "it holds exactly {particles} particles of {t}: is its type {t}, not {d}?"
                )),
                (None, Some(pt)) => Some(format!(
                    "the positions read as {pt} hold exactly {count} particles: is their type \
                     {pt}, not {pd}?"
                )),
                (Some(t), Some(pt)) => Some(format!(
                    "it holds exactly {particles} particles of {t}, and the positions read as \
                     {pt} exactly {count}: is its type {t}, or theirs {pt}?"
                )),
                (None, None) => None,
            }
        };
        let need = |m: &Mapped, per: usize, what: &str| -> Result<(), ReadError> {
            let bytes = particles
                .checked_mul(per)
                .and_then(|v| v.checked_mul(m.ty.size()))
                .ok_or_else(|| malformed_in(path, text, format!("{what}: size overflows")))?;
            if bytes > m.bytes().len() {
                let cause =
                    wrong_type(m, per).map_or(" (truncated?)".to_string(), |c| format!("; {c}"));
                return Err(err(
                    &m.path,
                    m.map.len() as u64,
                    format!(
                        "{what}: {particles} particles need {bytes} bytes from byte {}, the file \
                         has {}{cause}",
                        m.offset,
                        m.bytes().len()
                    ),
                ));
            }
            // Without `particles`, the positions file says how many there are, and every
            // other array must hold as many (a longer one is another frame's, or another
            // run's, not these particles').
            if sidecar.particles.is_none() && bytes != m.bytes().len() {
                let size = m.ty.size();
                let (values, rest) = (m.bytes().len() / size, m.bytes().len() % size);
                let cause = wrong_type(m, per).map_or(String::new(), |c| format!("; or {c}"));
                return Err(err(
                    &m.path,
                    m.offset as u64,
                    format!(
                        "{what}: {values} values{} from byte {}, but the positions ({}) hold \
                         {particles} particles: the arrays differ in length{cause}",
                        if rest > 0 {
                            format!(" and {rest} bytes")
                        } else {
                            String::new()
                        },
                        m.offset,
                        positions.path.display()
                    ),
                ));
            }
            Ok(())
        };
        need(&positions, 3, "positions")?;
        let species = match &sidecar.species {
            None => None,
            Some(a) => {
                let m = map(a, "species", &["u8", "u16", "u32", "i32"])?;
                need(&m, 1, "species")?;
                let names = a.names.clone().unwrap_or_default();
                if names.len() > 1 << 16 {
                    return Err(malformed_in(path, text, "species: more than 65536 names"));
                }
                // The species are told apart, and named in styles, by their names.
                if let Some(k) = names.iter().position(|n| n.trim().is_empty()) {
                    return Err(malformed_in(
                        path,
                        text,
                        format!("species: name {k} is empty (each species needs a name)"),
                    ));
                }
                let mut seen = std::collections::HashMap::new();
                for (k, n) in names.iter().enumerate() {
                    if let Some(j) = seen.insert(n.as_str(), k) {
                        return Err(malformed_in(
                            path,
                            text,
                            format!(
                                "species: names {j} and {k} are both \"{}\" (each species needs \
                                 a name of its own)",
                                super::shorten(n.as_bytes())
                            ),
                        ));
                    }
                }
                Some((m, names))
            }
        };
        let listed = match (&sidecar.attribute, &sidecar.attributes) {
            (Some(_), Some(_)) => {
                return Err(malformed_in(
                    path,
                    text,
                    "attributes: given beside `attribute`; list every attribute in \
                     `attributes`",
                ))
            }
            (Some(a), None) => vec![(a, "attribute".to_string())],
            (None, Some(list)) => {
                let mut named = Vec::with_capacity(list.len());
                for (k, a) in list.iter().enumerate() {
                    let Some(name) = a.name.clone() else {
                        return Err(malformed_in(
                            path,
                            text,
                            format!(
                                "attributes: entry {k} ({}) has no `name`: each attribute of \
                                 the list needs one, for --attribute to pick it",
                                a.file.display()
                            ),
                        ));
                    };
                    if named.iter().any(|(_, n): &(&Array, String)| *n == name) {
                        return Err(malformed_in(
                            path,
                            text,
                            format!("attributes: `{name}` is listed twice"),
                        ));
                    }
                    named.push((a, name));
                }
                named
            }
            (None, None) => Vec::new(),
        };
        let mut attributes = Vec::with_capacity(listed.len());
        for (a, default_name) in listed {
            let m = map(a, "attribute", &["f32", "f64"])?;
            need(&m, 1, "attribute")?;
            attributes.push((m, a.name.clone().unwrap_or(default_name)));
        }
        let sizes = match (&sidecar.radius, &sidecar.diameter) {
            (Some(_), Some(_)) => {
                return Err(malformed_in(
                    path,
                    text,
                    "diameter: given beside `radius`; give each particle's size once",
                ))
            }
            (Some(a), None) | (None, Some(a)) => {
                let (what, factor) = match sidecar.radius.is_some() {
                    true => ("radius", 1.0),
                    false => ("diameter", 0.5),
                };
                let m = map(a, what, &["f32", "f64"])?;
                need(&m, 1, what)?;
                Some((m, a.name.clone().unwrap_or_else(|| what.into()), factor))
            }
            (None, None) => None,
        };
        if let Some(r) = &sidecar.radii {
            if r.iter().any(|v| !(v.is_finite() && *v > 0.0)) {
                return Err(malformed_in(
                    path,
                    text,
                    "radii: every radius must be a positive number",
                ));
            }
            // One radius per species: by name, or the one species without `species`.
            // (Species numbered by the data itself are counted only when it is read.)
            let names = match &species {
                None => Some(1),
                Some((_, names)) => (!names.is_empty()).then_some(names.len()),
            };
            if let Some(names) = names.filter(|&n| n != r.len()) {
                return Err(malformed_in(
                    path,
                    text,
                    format!(
                        "radii: {} given for {names} species{} (one radius per species, in \
                         their order)",
                        r.len(),
                        if sidecar.species.is_some() {
                            " names"
                        } else {
                            " (no `species` array)"
                        }
                    ),
                ));
            }
        }
        let simulation_box = match sidecar.simulation_box {
            None => None,
            Some(b) => {
                if [b.origin, b.a, b.b, b.c]
                    .iter()
                    .flatten()
                    .any(|v| !v.is_finite())
                {
                    return Err(malformed_in(path, text, "box: not finite"));
                }
                Some(SimulationBox {
                    origin: b.origin,
                    a: b.a,
                    b: b.b,
                    c: b.c,
                    periodic: b.periodic,
                })
            }
        };
        let attribute_line = key_line(text, "attribute")
            .or_else(|| key_line(text, "attributes"))
            .unwrap_or(1);
        // With `particles` given, longer arrays are read for their first values (a file of
        // several frames' values, one at a time): said, as a count mistyped reads too few.
        let mut notes = Vec::new();
        if sidecar.particles.is_some() {
            let arrays = [(Some(&positions), 3, "positions")]
                .into_iter()
                .chain([(species.as_ref().map(|s| &s.0), 1, "species")])
                .chain(attributes.iter().map(|a| (Some(&a.0), 1, "attribute")))
                .chain([(sizes.as_ref().map(|a| &a.0), 1, "sizes")]);
            for (m, per, what) in arrays {
                let Some(m) = m else { continue };
                let read = particles.saturating_mul(per).saturating_mul(m.ty.size());
                let more = m.bytes().len().saturating_sub(read) / m.ty.size() / per;
                if more > 0 {
                    // Exactly twice the bytes of single-precision values: double ones
                    // declared single, read as garbage (`more` is the count then).
                    let doubled = m.ty == Ty::F32 && m.bytes().len() == 2 * read;
                    notes.push(format!(
                        "{}: {what}: the array holds {more} particles' values past the \
                         {particles} that `particles` in {} names, which alone are read{}",
                        m.path.display(),
                        path.display(),
                        if doubled {
                            " (exactly twice the bytes of `f32` values: is its `type` f64?)"
                        } else {
                            ""
                        }
                    ));
                }
            }
        }
        Ok(Index {
            notes,
            sidecar: path.to_path_buf(),
            attribute_line,
            particles,
            positions,
            planar,
            species,
            radii: sidecar.radii,
            attributes,
            sizes,
            simulation_box,
            timestep: sidecar.timestep,
            time: sidecar.time.filter(|t| t.is_finite()),
            units: sidecar.units,
        })
    }

    pub fn timestep(&self) -> Option<u64> {
        self.timestep
    }

    /// Values `first..first + n` of a one-value-per-particle float array, as `f64`.
    /// (The attribute and the sizes, in the single precision a frame keeps them in.)
    fn floats(&self, m: &Mapped, first: usize, n: usize) -> Vec<f32> {
        let b = m.bytes();
        match (m.ty, m.big, b.get(4 * first..4 * (first + n))) {
            // Little-endian `f32`: read in place.
            (Ty::F32, false, Some(b)) => b
                .par_chunks_exact(4)
                .map(|c| f32::from_le_bytes(c.try_into().expect("4 bytes")))
                .collect(),
            _ => (first..first + n)
                .into_par_iter()
                .map(|i| m.ty.get(b, i, m.big) as f32)
                .collect(),
        }
    }

    /// The radii the sidecar gives its species, by name (as [`Index::read_range`] names
    /// them).
    pub fn given_radii(&self) -> Vec<(String, f32)> {
        let Some(radii) = &self.radii else {
            return Vec::new();
        };
        match &self.species {
            None => radii
                .first()
                .map(|&r| (super::atoms::DEFAULT_SPECIES.to_string(), r))
                .into_iter()
                .collect(),
            Some((_, names)) if !names.is_empty() => {
                names.iter().cloned().zip(radii.iter().copied()).collect()
            }
            Some(_) => radii
                .iter()
                .enumerate()
                .map(|(i, &r)| (i.to_string(), r))
                .collect(),
        }
    }

    /// What a conversion should say about the arrays.
    pub fn notes(&self) -> &[String] {
        &self.notes
    }

    pub fn frame_info(&self) -> FrameInfo {
        let mut columns = vec!["x".to_string(), "y".into(), "z".into()];
        if self.species.is_some() {
            columns.push("species".into());
        }
        for (_, name) in &self.attributes {
            columns.push(name.clone());
        }
        if let Some((_, name, _)) = &self.sizes {
            columns.push(name.clone());
        }
        FrameInfo {
            particles: self.particles,
            timestep: self.timestep,
            time: self.time,
            units: self.units.clone(),
            simulation_box: self.simulation_box.clone(),
            columns,
        }
    }

    pub fn read_frame(
        &self,
        opts: &ReadOptions,
        progress: &dyn Progress,
    ) -> Result<Frame, ReadError> {
        self.read_range(opts, 0..self.particles, progress)
    }

    /// The attribute array `opts` reads: the one it names, else the first.
    fn attribute_read(&self, opts: &ReadOptions) -> Option<&(Mapped, String)> {
        match &opts.attribute {
            Some(w) => self.attributes.iter().find(|(_, n)| n == w),
            None => self.attributes.first(),
        }
    }

    /// Particles `range` (within `0..particles`) as a frame of their own. Without species
    /// names, the species are named by index up to the largest in the range.
    pub fn read_range(
        &self,
        opts: &ReadOptions,
        range: std::ops::Range<usize>,
        progress: &dyn Progress,
    ) -> Result<Frame, ReadError> {
        let total = self.particles;
        let first = range.start;
        let n = range.len();
        progress.stage("reading raw arrays", Some(n as u64), "particles");
        // This range and, for a caller reading window after window, the next one.
        let ahead = first..(first + 2 * n).min(total);
        if self.planar {
            for k in 0..3 {
                let r = k * total + ahead.start..k * total + ahead.end;
                self.positions.read_ahead(r, 1);
            }
        } else {
            self.positions.read_ahead(ahead.clone(), 3);
        }
        if let Some((m, _)) = &self.species {
            m.read_ahead(ahead.clone(), 1);
        }
        if let Some((m, _)) = self.attribute_read(opts) {
            m.read_ahead(ahead.clone(), 1);
        }
        if let Some((m, _, _)) = self
            .sizes
            .as_ref()
            .filter(|_| opts.sizes != super::SizeColumn::Off)
        {
            m.read_ahead(ahead, 1);
        }
        let p = &self.positions;
        let bytes = p.bytes();
        let size = p.ty.size();
        let planar = self.planar;
        let interleaved_f32 = (p.ty == Ty::F32 && !p.big && !planar)
            .then(|| bytes.get(12 * first..12 * (first + n)))
            .flatten();
        let positions = if let Some(b) = interleaved_f32 {
            // The common layout, x y z as little-endian `f32` side by side, read in place.
            let at = |c: &[u8], k: usize| {
                f32::from_le_bytes(c[4 * k..4 * k + 4].try_into().expect("4 bytes"))
            };
            let mut v = Vec::new();
            b.par_chunks_exact(12)
                .map(|c| [at(c, 0), at(c, 1), at(c, 2)])
                .collect_into_vec(&mut v);
            match super::first_index(n, |i| !v[i].iter().all(|c| c.is_finite())) {
                Some(i) => {
                    let k = v[i].iter().position(|c| !c.is_finite()).unwrap_or(0);
                    Err((3 * (first + i) + k, f64::from(v[i][k])))
                }
                None => Ok(v),
            }
        } else {
            super::decode_positions(
                n,
                |i, k| {
                    if planar {
                        k * total + first + i
                    } else {
                        3 * (first + i) + k
                    }
                },
                |j| p.ty.get(bytes, j, p.big),
            )
        }
        .map_err(|(j, v)| {
            err(
                &p.path,
                (p.offset + j * size) as u64,
                format!(
                    "particle {}: a coordinate is not finite{}{}{}",
                    if planar { j % total } else { j / 3 },
                    super::single_precision_note(v),
                    // Double-precision data declared single holds twice the bytes
                    // its count needs (a sidecar giving `particles`): the type is the
                    // likelier mistake than the byte order.
                    if p.ty == Ty::F32 && bytes.len() as u64 == 2 * 12 * total as u64 {
                        format!(
                            "; the array holds {} bytes, twice what {total} particles of \
                             `f32` x y z take: is its `type` f64?",
                            bytes.len()
                        )
                    } else {
                        String::new()
                    },
                    // Big-endian data read as little (or the reverse) is mostly garbage
                    // that is now and then not finite: say so where the other order
                    // reads a plain number.
                    match p.ty.get(bytes, j, !p.big) {
                        // (A plain number: not a denormal, which is what a NaN's
                        // bytes read the other way round make.)
                        o if o == 0.0 || (1e-12..1e12).contains(&o.abs()) => format!(
                            "; read in the other byte order it is {o}: is `byte_order` {}?",
                            if p.big { "little" } else { "big" }
                        ),
                        _ => String::new(),
                    }
                ),
            )
        })?;
        progress.advance(n as u64);
        let (species, species_index) = match &self.species {
            None => (
                vec![SpeciesName {
                    name: super::atoms::DEFAULT_SPECIES.into(),
                    numeric_type: false,
                    radius: self.radii.as_ref().and_then(|r| r.first().copied()),
                    ..Default::default()
                }],
                vec![0u16; n],
            ),
            Some((m, names)) => {
                let b = m.bytes();
                let raw: Vec<f64> = match (m.ty, b.get(first..first + n)) {
                    // One byte per particle: read in place.
                    (Ty::U8, Some(b)) => b.par_iter().map(|&v| f64::from(v)).collect(),
                    _ => (first..first + n)
                        .into_par_iter()
                        .map(|i| m.ty.get(b, i, m.big))
                        .collect(),
                };
                let count = if names.is_empty() {
                    // (At most as many as a file holds: an index from 0 to one less.)
                    raw.iter()
                        .fold(0.0f64, |a, &v| a.max(v + 1.0))
                        .min(crate::hierarchy::MAX_SPECIES as f64) as usize
                } else {
                    names.len()
                };
                if let Some(i) = raw.iter().position(|&v| v < 0.0 || v as usize >= count) {
                    return Err(err(
                        &m.path,
                        (m.offset + (first + i) * m.ty.size()) as u64,
                        format!(
                            "particle {}: species {} but there are {count} species{}",
                            first + i,
                            raw[i],
                            if names.is_empty() {
                                " (a file holds at most 65535: indices 0 to 65534)"
                            } else {
                                " names"
                            }
                        ),
                    ));
                }
                let names: Vec<String> = if names.is_empty() {
                    (0..count).map(|i| i.to_string()).collect()
                } else {
                    names.clone()
                };
                let species = names
                    .iter()
                    .enumerate()
                    .map(|(i, name)| SpeciesName {
                        name: name.clone(),
                        numeric_type: false,
                        radius: self.radii.as_ref().and_then(|r| r.get(i).copied()),
                        ..Default::default()
                    })
                    .collect();
                (species, raw.iter().map(|&v| v as u16).collect())
            }
        };
        // Each particle's own size (a radius), unless sizes are left out (--no-sizes).
        let mut species = species;
        let radii = match self
            .sizes
            .as_ref()
            .filter(|_| opts.sizes != super::SizeColumn::Off)
        {
            None => None,
            Some((m, name, factor)) => {
                let values = self.floats(m, first, n);
                let radii: Vec<f32> = values.iter().map(|&v| v * *factor as f32).collect();
                // (0 passes: a species of size 0 is refused by name later, unless --radius
                // gives it one.)
                if let Some(i) = radii.iter().position(|r| !(r.is_finite() && *r >= 0.0)) {
                    let at = first + i;
                    return Err(err(
                        &m.path,
                        (m.offset + at * m.ty.size()) as u64,
                        format!(
                            "particle {at}: `{name}` {} is no particle size (a finite number \
                             from 0 up, in single precision)",
                            values[i]
                        ),
                    ));
                }
                super::atoms::sized_species(&mut species, &species_index, &radii);
                Some(radii)
            }
        };
        let attribute = match (self.attribute_read(opts), &opts.attribute) {
            (Some((m, name)), _) => {
                let values = self.floats(m, first, n);
                if let Some(i) = values.iter().position(|v| !v.is_finite()) {
                    let i = first + i;
                    return Err(err(
                        &m.path,
                        (m.offset + i * m.ty.size()) as u64,
                        format!(
                            "particle {i}: `{name}` is not finite in single precision (NaN, \
                             infinite, or beyond ±3.4e38: give it in other units)"
                        ),
                    ));
                }
                Some(Attribute {
                    name: name.clone(),
                    values,
                })
            }
            (None, Some(wanted)) => {
                return Err(ReadError::Malformed {
                    at: super::Location {
                        path: self.sidecar.clone(),
                        line: self.attribute_line,
                    },
                    message: format!(
                        "--attribute {wanted}: no attribute `{wanted}` in the sidecar ({})",
                        match self.attributes.as_slice() {
                            [] => "it names none: add an `attribute` entry".to_string(),
                            [(m, n)] =>
                                format!("its attribute is `{n}`, from {}", m.path.display()),
                            more => format!(
                                "its attributes are {}",
                                more.iter()
                                    .map(|(_, n)| format!("`{n}`"))
                                    .collect::<Vec<_>>()
                                    .join(", ")
                            ),
                        }
                    ),
                })
            }
            (None, None) => None,
        };
        progress.finish_stage();
        Ok(Frame {
            positions,
            species_index,
            species,
            attribute,
            radii,
            simulation_box: self.simulation_box.clone(),
            timestep: self.timestep,
            time: self.time,
            units: self.units.clone(),
        })
    }
}
