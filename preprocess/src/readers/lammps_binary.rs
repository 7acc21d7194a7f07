//! LAMMPS binary dumps: what `dump custom` and `dump atom` write when the file name ends
//! in `.bin`.
//!
//! How it works. A binary dump is a sequence of frames, each a header and the atoms as
//! chunks of native doubles (one chunk per writing process), all little-endian here:
//!
//! | field | type | revision 1-2 ("new", LAMMPS since late 2020) | old (no magic) |
//! | --- | --- | --- | --- |
//! | magic | i64 `−len`, then `len` bytes | `DUMPCUSTOM` / `DUMPATOM` | absent |
//! | endian, revision | i32, i32 | `1`, `1` or `2` | absent |
//! | timestep, atoms | i64, i64 | yes | yes |
//! | triclinic | i32 | 0 or 1 | 0 or 1 |
//! | boundary | 6 × i32 | yes | yes |
//! | box | 6 × f64 (`lo hi` per axis, the `_bound` values when triclinic) | yes | yes |
//! | tilts | 3 × f64 `xy xz yz`, only when triclinic | yes | yes |
//! | values per atom | i32 | yes | yes |
//! | unit style | i32 length + bytes (length 0 after the first frame) | yes | absent |
//! | time | u8 flag, then f64 when 1 | yes | absent |
//! | column names | i32 length + bytes, space separated | yes | absent |
//! | chunks | i32 count, then per chunk i32 `n` and `n` f64 | yes | yes |
//!
//! The old revision names no columns: `dump atom`'s five (`id type xs ys zs`, eight with
//! image flags) are assumed, anything else needs [`crate::readers::ReadOptions::columns`].
//! Assumed scaled coordinates far outside the box (below −0.5 or above 1.5 for more than
//! a few of the frame's first atoms) are refused: they are unscaled ones, which the
//! columns must then name (`--columns "id type x y z"`).
//! Opening scans the headers and skips the chunks by their lengths, checking every count
//! against the file size with checked arithmetic, so a truncated or corrupt file is
//! reported with the byte offset where it goes wrong, and frame `k` is then read without
//! touching the others. Atoms are decoded in parallel, straight from the mapped bytes.

use rayon::prelude::*;

use super::{FrameInfo, ReadError, ReadOptions};
use crate::frame::{Attribute, Frame, SimulationBox, SpeciesName};
use crate::progress::Progress;
use std::path::Path;

/// Coordinate column triples, in order of preference (as for text dumps).
const COORDINATE_STYLES: [([&str; 3], bool); 4] = [
    (["x", "y", "z"], false),
    (["xu", "yu", "zu"], false),
    (["xs", "ys", "zs"], true),
    (["xsu", "ysu", "zsu"], true),
];

/// Most values per atom accepted (LAMMPS writes one per column).
const MAX_VALUES_PER_ATOM: usize = 4096;
/// Longest magic, unit or column string accepted.
const MAX_STRING: usize = 1 << 16;
/// Atoms at the start of a frame whose assumed scaled coordinates are checked to lie
/// near the box, and how many of them may lie far from it (see [`check_assumed_scaled`]).
const SCALED_SAMPLE: usize = 1000;
const SCALED_FAR_ALLOWED: usize = 3;

/// One frame's header, as read.
#[derive(Clone, Debug)]
pub(crate) struct BinHeader {
    pub timestep: u64,
    pub atoms: usize,
    pub simulation_box: SimulationBox,
    pub values_per_atom: usize,
    pub units: Option<String>,
    pub time: Option<f64>,
    pub columns: Option<Vec<String>>,
    /// Byte ranges of the chunks' doubles.
    pub chunks: Vec<std::ops::Range<usize>>,
    /// The frame's byte range, header and chunks.
    pub bytes: std::ops::Range<usize>,
}

/// How a read past the end of the file starts its message.
const TRUNCATED: &str = "truncated:";

/// The frames of a binary dump.
pub(crate) struct Index {
    frames: Vec<BinHeader>,
    /// A last frame the file ends inside (a run still writing it): counted as a frame,
    /// whose every read is a "truncated file?" error ([`ReadError::cut_short`]), so that
    /// a batch leaves it out with a note and converts the frames before it.
    cut: Option<Cut>,
}

/// Where and how the file ends inside its last frame.
struct Cut {
    offset: usize,
    message: String,
    /// Its timestep, where the file holds it (a frame cut inside its chunks): a batch
    /// names the frame by it, not by its place among the inputs.
    timestep: Option<u64>,
}

struct Reader<'a> {
    path: &'a Path,
    data: &'a [u8],
    pos: usize,
}

impl<'a> Reader<'a> {
    fn err(&self, at: usize, message: impl Into<String>) -> ReadError {
        ReadError::Binary {
            path: self.path.to_path_buf(),
            offset: at as u64,
            message: message.into(),
        }
    }

    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], ReadError> {
        let end = self.pos.checked_add(n).filter(|&e| e <= self.data.len());
        let Some(end) = end else {
            return Err(self.err(
                self.pos,
                format!(
                    "{TRUNCATED} {what} needs {n} bytes, {} left",
                    self.data.len() - self.pos
                ),
            ));
        };
        let s = &self.data[self.pos..end];
        self.pos = end;
        Ok(s)
    }

    fn i32(&mut self, what: &str) -> Result<i32, ReadError> {
        Ok(i32::from_le_bytes(
            self.take(4, what)?.try_into().unwrap_or([0; 4]),
        ))
    }

    fn i64(&mut self, what: &str) -> Result<i64, ReadError> {
        Ok(i64::from_le_bytes(
            self.take(8, what)?.try_into().unwrap_or([0; 8]),
        ))
    }

    fn f64(&mut self, what: &str) -> Result<f64, ReadError> {
        let at = self.pos;
        let v = f64::from_le_bytes(self.take(8, what)?.try_into().unwrap_or([0; 8]));
        if !v.is_finite() {
            return Err(self.err(at, format!("{what} is not a finite number ({v})")));
        }
        Ok(v)
    }

    /// A count in `0..=max`.
    fn count(&mut self, what: &str, max: usize) -> Result<usize, ReadError> {
        let at = self.pos;
        let v = self.i32(what)?;
        usize::try_from(v)
            .ok()
            .filter(|&v| v <= max)
            .ok_or_else(|| self.err(at, format!("{what} is {v}, expected 0 to {max}")))
    }

    fn string(&mut self, what: &str) -> Result<String, ReadError> {
        let n = self.count(what, MAX_STRING)?;
        let at = self.pos;
        let bytes = self.take(n, what)?;
        std::str::from_utf8(bytes)
            .map(str::to_string)
            .map_err(|_| self.err(at, format!("{what} is not text")))
    }
}

/// True when `data` starts like a binary dump of the current revision.
pub(crate) fn sniff(data: &[u8]) -> bool {
    data.len() >= 12
        && i64::from_le_bytes(data[..8].try_into().unwrap_or([0; 8])) < 0
        && data[8..12] == *b"DUMP"
}

impl Index {
    pub fn build(path: &Path, data: &[u8]) -> Result<Index, ReadError> {
        let mut r = Reader { path, data, pos: 0 };
        let mut frames = Vec::new();
        let mut units: Option<String> = None;
        let mut cut = None;
        while r.pos < data.len() {
            let start = r.pos;
            let mut timestep = None;
            let mut h = match header(&mut r, &mut timestep) {
                Ok(h) => h,
                // The file ends inside this frame (header or chunks): a run still
                // writing it, or a copy that stopped.
                Err(ReadError::Binary { message, .. }) if message.starts_with(TRUNCATED) => {
                    cut = Some(Cut {
                        offset: start,
                        message,
                        timestep,
                    });
                    break;
                }
                Err(e) => return Err(e),
            };
            // The unit style is written once, in the first frame.
            if h.units.is_some() {
                units.clone_from(&h.units);
            } else {
                h.units.clone_from(&units);
            }
            frames.push(h);
        }
        if frames.is_empty() && cut.is_none() {
            return Err(r.err(0, "no frames"));
        }
        Ok(Index { frames, cut })
    }

    /// The frames, the one the file ends inside included.
    pub fn len(&self) -> usize {
        self.frames.len() + usize::from(self.cut.is_some())
    }

    /// Frame `k`'s timestep; of the frame the file ends inside, where it got that far.
    pub fn timestep(&self, k: usize) -> Option<u64> {
        match self.frames.get(k) {
            Some(h) => Some(h.timestep),
            None if k == self.frames.len() => self.cut.as_ref().and_then(|c| c.timestep),
            None => None,
        }
    }

    /// Frame `k`'s header; for the frame the file ends inside, the error saying so.
    pub fn header(&self, path: &Path, k: usize) -> Result<&BinHeader, ReadError> {
        match (self.frames.get(k), &self.cut) {
            (Some(h), _) => Ok(h),
            (None, Some(c)) => Err(ReadError::Binary {
                path: path.to_path_buf(),
                offset: c.offset as u64,
                message: format!(
                    "frame {k} starts here and the file ends inside it: {} (truncated file?)",
                    c.message
                ),
            }),
            (None, None) => Err(ReadError::NoSuchFrame {
                path: path.to_path_buf(),
                frame: k,
                count: self.len(),
            }),
        }
    }
}

/// Reads one frame header at the reader's position and skips its chunks; `seen` takes
/// the timestep once read, so that a frame the file ends inside is still named by it.
fn header(r: &mut Reader<'_>, seen: &mut Option<u64>) -> Result<BinHeader, ReadError> {
    let start = r.pos;
    let first = r.i64("timestep")?;
    let mut revised = false;
    let timestep = if first < 0 {
        let len = usize::try_from(first.unsigned_abs())
            .ok()
            .filter(|&l| l <= 64)
            .ok_or_else(|| {
                let len = first.unsigned_abs();
                // A revised header's length read in the other byte order (-10 for
                // `DUMPCUSTOM`, written big-endian): the whole file is.
                let swapped = first.swap_bytes();
                if (-64..0).contains(&swapped) {
                    return r.err(
                        start,
                        format!(
                            "the magic string's length reads {swapped} in the other byte \
                             order: written on a big-endian machine, which this reader does \
                             not read; convert it there with LAMMPS' binary2txt"
                        ),
                    );
                }
                r.err(start, format!("bad magic string length {len}"))
            })?;
        let at = r.pos;
        let magic = r.take(len, "magic string")?;
        if !magic.starts_with(b"DUMP") {
            return Err(r.err(
                at,
                format!(
                    "not a LAMMPS binary dump (magic `{}`)",
                    super::shorten(magic)
                ),
            ));
        }
        // LAMMPS writes capital letters (`DUMPATOM`, `DUMPCUSTOM`): another byte is a
        // length read wrong, which took a byte of the next field or left one behind.
        if !magic.iter().all(u8::is_ascii_uppercase) {
            return Err(r.err(
                start,
                format!(
                    "magic string length {len} gives `{}`, not a LAMMPS magic such as \
                     DUMPCUSTOM (a damaged header?)",
                    super::shorten(magic)
                ),
            ));
        }
        let at = r.pos;
        let endian = r.i32("endian flag")?;
        if endian == 1i32.swap_bytes() {
            return Err(r.err(
                at,
                format!("written on a machine of the other byte order (endian flag {endian:#x}); convert it there with LAMMPS' binary2txt"),
            ));
        }
        if endian != 1 {
            // Neither byte order's 1: the header is read wrong here, as by a magic
            // string's length one short.
            return Err(r.err(
                at,
                format!(
                    "endian flag {endian:#x} is 1 in neither byte order: the header is damaged \
                     (read after the magic string `{}` of length {len})",
                    super::shorten(magic)
                ),
            ));
        }
        let at = r.pos;
        let rev = r.i32("format revision")?;
        if !(1..=2).contains(&rev) {
            return Err(r.err(
                at,
                format!("format revision {rev} is not supported (this reader knows 1 and 2)"),
            ));
        }
        revised = true;
        r.i64("timestep")?
    } else {
        first
    };
    let timestep = u64::try_from(timestep)
        .map_err(|_| r.err(start, format!("negative timestep {timestep}")))?;
    *seen = Some(timestep);
    let atoms_at = r.pos;
    let atoms = r.i64("atom count")?;
    let atoms = usize::try_from(atoms)
        .map_err(|_| r.err(atoms_at, format!("negative atom count {atoms}")))?;
    let at = r.pos;
    let triclinic = r.i32("triclinic flag")?;
    if !(0..=1).contains(&triclinic) {
        return Err(r.err(
            at,
            format!("triclinic flag {triclinic} is not supported (0 or 1)"),
        ));
    }
    let mut boundary = [0i32; 6];
    for b in &mut boundary {
        let at = r.pos;
        *b = r.i32("boundary flags")?;
        // LAMMPS writes 0 (p), 1 (f), 2 (s) or 3 (m): another is a header read wrong.
        if !(0..=3).contains(b) {
            return Err(r.err(
                at,
                format!("boundary flag {b} (LAMMPS writes 0 to 3: p, f, s, m)"),
            ));
        }
    }
    let mut bounds = [0f64; 6];
    let bounds_at = r.pos;
    for v in &mut bounds {
        *v = r.f64("box bound")?;
    }
    // As a text dump's: each axis's lower bound at most its upper (both numbers).
    for (k, axis) in ["x", "y", "z"].iter().enumerate() {
        let (lo, hi) = (bounds[2 * k], bounds[2 * k + 1]);
        if !(lo.is_finite() && hi.is_finite() && lo <= hi) {
            return Err(r.err(
                bounds_at + 16 * k,
                format!(
                    "box bounds of timestep {timestep}: {axis} from {} to {} (the lower \
                     bound must be a number at most the upper)",
                    super::shown(lo),
                    super::shown(hi)
                ),
            ));
        }
    }
    let mut simulation_box = if triclinic == 1 {
        let (xy, xz, yz) = (r.f64("tilt xy")?, r.f64("tilt xz")?, r.f64("tilt yz")?);
        // The `_bound` values, as in text dumps, converted to the true box.
        let lo = [
            bounds[0] - 0f64.min(xy).min(xz).min(xy + xz),
            bounds[2] - 0f64.min(yz),
            bounds[4],
        ];
        let hi = [
            bounds[1] - 0f64.max(xy).max(xz).max(xy + xz),
            bounds[3] - 0f64.max(yz),
            bounds[5],
        ];
        if let Some(problem) = super::tilted_box_problem(lo, hi, [xy, xz, yz]) {
            return Err(r.err(
                bounds_at,
                format!("box bounds of timestep {timestep}: {problem}"),
            ));
        }
        SimulationBox::lammps(lo, hi, [xy, xz, yz])
    } else {
        SimulationBox::orthogonal(
            [bounds[0], bounds[2], bounds[4]],
            [bounds[1], bounds[3], bounds[5]],
        )
    };
    // LAMMPS boundary codes per side: 0 periodic, 1 fixed, 2 shrink-wrapped, 3 minimum.
    simulation_box.periodic = Some([0, 1, 2].map(|k| boundary[2 * k] == 0));
    let at = r.pos;
    let values_per_atom = r.count("values per atom", MAX_VALUES_PER_ATOM)?;
    if values_per_atom == 0 {
        return Err(r.err(at, "zero values per atom"));
    }
    let (mut units, mut time, mut columns) = (None, None, None);
    if revised {
        let u = r.string("unit style")?;
        units = (!u.is_empty()).then_some(u);
        let at = r.pos;
        match r.take(1, "time flag")?[0] {
            0 => {}
            1 => time = Some(r.f64("time")?),
            f => return Err(r.err(at, format!("time flag {f}, expected 0 or 1"))),
        }
        let at = r.pos;
        let names: Vec<String> = r
            .string("column names")?
            .split_ascii_whitespace()
            .map(str::to_string)
            .collect();
        if names.len() != values_per_atom {
            return Err(r.err(
                at,
                format!(
                    "{} column names for {values_per_atom} values per atom",
                    names.len()
                ),
            ));
        }
        columns = Some(names);
    }
    let count_at = r.pos;
    let nchunk = r.count("chunk count", i32::MAX as usize)?;
    let expected = atoms.checked_mul(values_per_atom).ok_or_else(|| {
        r.err(
            atoms_at,
            format!("atom count {atoms} overflows at {values_per_atom} values per atom"),
        )
    })?;
    let mut chunks = Vec::with_capacity(nchunk.min(1 << 16));
    let mut total = 0usize;
    for c in 0..nchunk {
        let at = r.pos;
        // (A damaged count reads the next frame as chunks: both places are named.)
        let n = r.count(
            &format!("length of chunk {c} (of the {nchunk} the chunk count at byte {count_at} announces)"),
            i32::MAX as usize,
        )?;
        if n % values_per_atom != 0 {
            return Err(r.err(
                at,
                format!("chunk {c} holds {n} values, not a multiple of {values_per_atom} per atom"),
            ));
        }
        let bytes = n
            .checked_mul(8)
            .ok_or_else(|| r.err(at, "chunk length overflows"))?;
        let begin = r.pos;
        r.take(bytes, &format!("chunk {c} of timestep {timestep}"))?;
        chunks.push(begin..r.pos);
        total = total
            .checked_add(n)
            .ok_or_else(|| r.err(at, "chunk lengths overflow"))?;
    }
    if total != expected {
        return Err(r.err(
            start,
            format!(
                "timestep {timestep}: the header announces {atoms} atoms but its chunks hold {}",
                total / values_per_atom
            ),
        ));
    }
    Ok(BinHeader {
        timestep,
        atoms,
        simulation_box,
        values_per_atom,
        units,
        time,
        columns,
        chunks,
        bytes: start..r.pos,
    })
}

/// Refuses `dump atom`'s scaled coordinates assumed for an old-revision frame `h` (which
/// names no columns) when more than a few of its first atoms lie far outside the box:
/// unscaled coordinates taken for scaled ones would be multiplied by the box silently.
/// Only the frame's first atoms are looked at, so that every part of a frame read in
/// parts gives the same answer.
fn check_assumed_scaled(
    path: &Path,
    data: &[u8],
    h: &BinHeader,
    coords: [usize; 3],
    names: &[String],
) -> Result<(), ReadError> {
    let stride = h.values_per_atom * 8;
    let (mut seen, mut far, mut first_far) = (0usize, 0usize, None);
    'chunks: for chunk in &h.chunks {
        for (j, atom) in data[chunk.clone()].chunks_exact(stride).enumerate() {
            if seen == SCALED_SAMPLE {
                break 'chunks;
            }
            let at = chunk.start + j * stride;
            for &c in &coords {
                let v = f64::from_le_bytes(atom[8 * c..8 * c + 8].try_into().unwrap_or([0; 8]));
                if v.is_finite() && !(-0.5..=1.5).contains(&v) {
                    far += 1;
                    first_far.get_or_insert((seen, c, v, at + 8 * c));
                    break;
                }
            }
            seen += 1;
        }
    }
    match first_far {
        Some((i, c, v, offset)) if far > SCALED_FAR_ALLOWED => Err(ReadError::Binary {
            path: path.to_path_buf(),
            offset: offset as u64,
            message: format!(
                "timestep {}: an old-revision binary dump names no columns, so `dump atom`'s \
                 scaled `{}` were assumed, but {far} of the first {seen} atoms lie far outside \
                 the box (below -0.5 or above 1.5; atom {}: `{}` is {v}): the columns look \
                 unscaled; give the column names (e.g. --columns \"id type x y z\")",
                h.timestep,
                names.join(" "),
                i + 1,
                names[c]
            ),
        }),
        _ => Ok(()),
    }
}

/// The column names of frame `k` as it is read with `opts`.
pub(crate) fn column_names(
    path: &Path,
    index: &Index,
    k: usize,
    opts: &ReadOptions,
) -> Result<Vec<String>, ReadError> {
    columns(path, index.header(path, k)?, opts)
}

/// The column names of a frame: its own, the caller's, or `dump atom`'s defaults.
fn columns(path: &Path, h: &BinHeader, opts: &ReadOptions) -> Result<Vec<String>, ReadError> {
    let err = |message: String| ReadError::Binary {
        path: path.to_path_buf(),
        offset: 0,
        message,
    };
    if let Some(given) = &opts.columns {
        // A dump of the new revision names its own: other names would read its values as
        // what they are not (a `mol` column as the types). Said first, whatever was given.
        if let Some(own) = h.columns.as_ref().filter(|own| *own != given) {
            return Err(err(format!(
                "this dump names its own columns ({}); --columns is for old-revision dumps \
                 that name none: leave it out",
                own.join(" ")
            )));
        }
        if given.len() != h.values_per_atom {
            return Err(err(format!(
                "{} column names given for {} values per atom",
                given.len(),
                h.values_per_atom
            )));
        }
        if let Some((_, c)) = given
            .iter()
            .enumerate()
            .find(|(i, c)| given[..*i].contains(c))
        {
            return Err(err(format!("--columns names `{c}` twice")));
        }
        return Ok(given.clone());
    }
    if let Some(c) = &h.columns {
        return Ok(c.clone());
    }
    let defaults: &[&str] = match h.values_per_atom {
        5 => &["id", "type", "xs", "ys", "zs"],
        8 => &["id", "type", "xs", "ys", "zs", "ix", "iy", "iz"],
        n => {
            return Err(err(format!(
                "an old-revision binary dump names no columns and its {n} values per atom are not `dump atom`'s; give the column names (e.g. --columns \"id type x y z\")"
            )))
        }
    };
    Ok(defaults.iter().map(|s| s.to_string()).collect())
}

pub(crate) fn frame_info(path: &Path, h: &BinHeader, opts: &ReadOptions) -> FrameInfo {
    FrameInfo {
        particles: h.atoms,
        timestep: Some(h.timestep),
        time: h.time,
        units: h.units.clone(),
        simulation_box: Some(h.simulation_box.clone()),
        columns: columns(path, h, opts).unwrap_or_default(),
    }
}

/// Decodes frame `h` of `data`.
pub(crate) fn read_frame(
    path: &Path,
    data: &[u8],
    h: &BinHeader,
    opts: &ReadOptions,
    progress: &dyn Progress,
) -> Result<Frame, ReadError> {
    read_range(path, data, h, opts, 0..h.atoms, progress)
}

/// Decodes atoms `range` (in file order) of frame `h` as a frame of their own; species
/// are the distinct types in the range.
pub(crate) fn read_range(
    path: &Path,
    data: &[u8],
    h: &BinHeader,
    opts: &ReadOptions,
    range: std::ops::Range<usize>,
    progress: &dyn Progress,
) -> Result<Frame, ReadError> {
    let first_chunk = h.chunks.first().map_or(0, |c| c.start) as u64;
    let err = |offset: u64, message: String| ReadError::Binary {
        path: path.to_path_buf(),
        offset,
        message,
    };
    let names = columns(path, h, opts)?;
    let find = |name: &str| names.iter().position(|c| c == name);
    let Some((coords, scaled)) = COORDINATE_STYLES
        .iter()
        .find_map(|(n, scaled)| Some(([find(n[0])?, find(n[1])?, find(n[2])?], *scaled)))
    else {
        return Err(ReadError::NoCoordinates {
            at: super::Location {
                path: path.to_path_buf(),
                line: 0,
            },
            columns: names.join(" "),
        });
    };
    if scaled && opts.columns.is_none() && h.columns.is_none() {
        check_assumed_scaled(path, data, h, coords, &names)?;
    }
    let species_col = match &opts.species_column {
        None => find("type"),
        Some(name) => Some(
            super::species_column_problem(name, &names, coords).map_err(|m| err(first_chunk, m))?,
        ),
    };
    let attribute_col = match &opts.attribute {
        None => None,
        Some(name) => Some(find(name).ok_or_else(|| {
            err(
                first_chunk,
                format!(
                    "no column `{name}` for the attribute; available columns: {}",
                    names.join(" ")
                ),
            )
        })?),
    };
    let stride = h.values_per_atom * 8;
    let n = range.len();
    progress.stage(
        &format!("reading timestep {}", h.timestep),
        Some(n as u64),
        "particles",
    );
    let mut positions = vec![[0f32; 3]; n];
    let mut types = vec![0i64; n];
    let mut attribute = attribute_col.map(|_| vec![0f32; n]);
    // Each particle's size (a granular run's `radius` or `diameter`), as a radius.
    let size_col = opts
        .sizes
        .resolve_beside(&names, coords, species_col)
        .map_err(|m| err(first_chunk, m))?;
    let read = coords
        .iter()
        .copied()
        .chain(species_col)
        .chain(attribute_col)
        .chain(size_col.map(|(c, _)| c));
    if let Some(m) = super::named_twice(&names, read) {
        return Err(err(first_chunk, m));
    }
    if let Some(m) = scaled
        .then(|| super::unscalable(&h.simulation_box))
        .flatten()
    {
        return Err(err(first_chunk, m));
    }
    let mut radii = size_col.map(|_| vec![0f32; n]);
    let value = |atom: &[u8], c: usize| {
        f64::from_le_bytes(atom[8 * c..8 * c + 8].try_into().unwrap_or([0; 8]))
    };
    let bx = &h.simulation_box;
    // Atoms in file order: chunk after chunk; `first` counts the atoms before this chunk.
    let mut first = 0usize;
    for chunk in &h.chunks {
        let in_chunk = chunk.len() / stride;
        let (lo, hi) = (
            range.start.clamp(first, first + in_chunk),
            range.end.clamp(first, first + in_chunk),
        );
        if lo == hi {
            first += in_chunk;
            continue;
        }
        let chunk = chunk.start + (lo - first) * stride..chunk.start + (hi - first) * stride;
        let bytes = &data[chunk.clone()];
        let count = hi - lo;
        let skipped = lo - first;
        let out = lo - range.start;
        let range = out..out + count;
        // Returns the index (within the chunk), the column and the value of the first
        // bad value.
        let block = super::SCAN_BLOCK;
        let bad = positions[range.clone()]
            .par_chunks_mut(block)
            .zip(types[range.clone()].par_chunks_mut(block))
            .zip(bytes.par_chunks(block * stride))
            .enumerate()
            .find_map_first(|(b, ((ps, ts), atoms))| {
                let atoms = atoms.chunks_exact(stride);
                for (o, ((p, t), atom)) in ps.iter_mut().zip(ts.iter_mut()).zip(atoms).enumerate() {
                    let i = b * block + o;
                    let mut x = [0f64; 3];
                    for k in 0..3 {
                        x[k] = value(atom, coords[k]);
                        if !x[k].is_finite() {
                            return Some((i, coords[k], x[k]));
                        }
                    }
                    // Scaled coordinates are Cartesian ones once through the box.
                    let x = if scaled { bx.from_fractional(x) } else { x };
                    for k in 0..3 {
                        p[k] = x[k] as f32;
                        if !p[k].is_finite() {
                            return Some((i, coords[k], x[k]));
                        }
                    }
                    if let Some(c) = species_col {
                        let v = value(atom, c);
                        if !(v.is_finite() && v.fract() == 0.0 && v.abs() < 1e15) {
                            return Some((i, c, f64::NAN));
                        }
                        *t = v as i64;
                    }
                }
                None
            });
        if let Some((i, c, v)) = bad {
            let offset = (chunk.start + i * stride + 8 * c) as u64;
            return Err(err(
                offset,
                format!(
                    "atom {} of timestep {}: column `{}` is not a finite number{}",
                    first + skipped + i + 1,
                    h.timestep,
                    names[c],
                    if Some(c) == species_col && opts.species_column.is_some() {
                        " or not a whole number (--species-column takes a column of \
                         categories; a continuous quantity goes in --attribute)"
                            .to_string()
                    } else if Some(c) == species_col {
                        " or not an integer type".to_string()
                    } else if scaled && v.is_finite() {
                        format!(
                            " in single precision once unscaled through the box ({v:e} is \
                             beyond ±3.4e38)"
                        )
                    } else {
                        super::single_precision_note(v)
                    }
                ),
            ));
        }
        // Reads column `c` times `factor` into `values` (this chunk's part), returning the
        // first value `accept` refuses: its index within the chunk and the value read.
        let scan = |values: &mut [f32], c: usize, factor: f64, accept: fn(f32) -> bool| {
            let block = super::SCAN_BLOCK;
            values[range.clone()]
                .par_chunks_mut(block)
                .zip(bytes.par_chunks(block * stride))
                .enumerate()
                .find_map_first(|(b, (outs, atoms))| {
                    for (o, (out, atom)) in
                        outs.iter_mut().zip(atoms.chunks_exact(stride)).enumerate()
                    {
                        let v = value(atom, c);
                        *out = (v * factor) as f32;
                        if !accept(*out) {
                            return Some((b * block + o, v));
                        }
                    }
                    None
                })
        };
        if let (Some(values), Some((c, factor))) = (radii.as_mut(), size_col) {
            if let Some((i, v)) = scan(values, c, factor, |r| r.is_finite() && r > 0.0) {
                return Err(err(
                    (chunk.start + i * stride + 8 * c) as u64,
                    format!(
                        "atom {} of timestep {}: column `{}` is {v}, no particle size (a \
                         finite number above 0, in single precision)",
                        first + skipped + i + 1,
                        h.timestep,
                        names[c],
                    ),
                ));
            }
        }
        if let (Some(values), Some(c)) = (attribute.as_mut(), attribute_col) {
            if let Some((i, v)) = scan(values, c, 1.0, f32::is_finite) {
                return Err(err(
                    (chunk.start + i * stride + 8 * c) as u64,
                    format!(
                        "atom {} of timestep {}: column `{}` is not a finite number{}",
                        first + skipped + i + 1,
                        h.timestep,
                        names[c],
                        super::single_precision_note(v)
                    ),
                ));
            }
        }
        progress.advance(count as u64);
        first += in_chunk;
    }
    progress.finish_stage();

    // Species: LAMMPS numeric types, sorted numerically.
    let (species, species_index) = match species_col {
        None => (
            vec![SpeciesName {
                name: super::atoms::DEFAULT_SPECIES.into(),
                numeric_type: false,
                radius: None,
                ..Default::default()
            }],
            vec![0u16; n],
        ),
        Some(_) => {
            let mut distinct: Vec<i64> = types.clone();
            distinct.par_sort_unstable();
            distinct.dedup();
            if distinct.len() > 1 << 16 {
                return Err(err(
                    first_chunk,
                    opts.species_column.as_deref().map_or_else(
                        || "more than 65536 distinct types".into(),
                        super::too_many_categories,
                    ),
                ));
            }
            let index: Vec<u16> = types
                .par_iter()
                .map(|t| distinct.binary_search(t).unwrap_or(0) as u16)
                .collect();
            // As the text reader: slots by type number only where every type is a
            // LAMMPS type (1 or more); categories (`--species-column`) take colours by
            // value instead.
            let categories = opts.species_column.is_some();
            let slots = !categories && distinct.first().is_some_and(|&t| t >= 1);
            let names = distinct
                .iter()
                .map(|t| SpeciesName {
                    name: t.to_string(),
                    numeric_type: true,
                    radius: None,
                    palette_slot: super::atoms::type_number_slot(t.to_string().as_bytes())
                        .filter(|_| slots),
                    colour: if categories {
                        crate::species::category_colour(
                            opts.species_column.as_deref().unwrap_or_default(),
                            *t,
                        )
                    } else {
                        None
                    },
                    ..Default::default()
                })
                .collect();
            (names, index)
        }
    };
    let mut species = species;
    if let Some(r) = &radii {
        super::atoms::sized_species(&mut species, &species_index, r);
    }
    Ok(Frame {
        positions,
        species_index,
        species,
        attribute: attribute.zip(attribute_col).map(|(values, c)| Attribute {
            name: names[c].clone(),
            values,
        }),
        radii,
        simulation_box: Some(h.simulation_box.clone()),
        timestep: Some(h.timestep),
        time: h.time,
        units: h.units.clone(),
    })
}
