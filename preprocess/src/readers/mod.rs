//! Readers for particle dumps: LAMMPS text dumps and (extended) XYZ, plain or gzip-compressed.
//!
//! How it works:
//! - [`DumpFile::open`] memory-maps the file (gzip files, recognised by their magic bytes,
//!   are decompressed into memory instead), picks the [`InputFormat`] from the file name or,
//!   failing that, from the first line, and builds a *frame index* in one scan: LAMMPS
//!   frames are found with `memchr::memmem` as lines starting `ITEM: TIMESTEP`; XYZ frames
//!   by reading each frame's atom count and skipping that many lines with a vectorised
//!   newline count. The index holds each frame's byte range and timestep, so
//!   [`DumpFile::frame_count`] and [`DumpFile::frame_timestep`] need no further parsing and
//!   frame `k` is read without touching the frames before it.
//! - [`DumpFile::read_frame`] parses that frame's header (box, counts, column names), maps
//!   the columns onto positions, species and the optional attribute, and hands the atom
//!   lines to the shared parallel parser (`atoms.rs`), which splits them into chunks at line
//!   boundaries and parses the chunks with rayon into preallocated output arrays.
//! - Every error is a [`ReadError`] whose message starts `path:line:` (1-based line of the
//!   decompressed text). Line numbers are computed only when an error is built, by counting
//!   newlines up to the error's byte offset, so the fast path never tracks them.
//!
//! What is read:
//! - **LAMMPS text dumps**: `ITEM: UNITS`, `TIME`, `TIMESTEP`, `NUMBER OF ATOMS`,
//!   `BOX BOUNDS` (orthogonal, restricted triclinic `xy xz yz` with the `_bound` values
//!   converted to the true box, general triclinic `abc origin`) and `ATOMS <columns>` in
//!   any column order. Coordinates come from the first complete triple of `x y z`, `xu yu
//!   zu`, `xs ys zs`, `xsu ysu zsu` (in that order of preference: wrapped Cartesian, then
//!   unwrapped, then scaled; scaled ones are converted through the possibly triclinic
//!   box). Species come from `element` if present, else `type` (numeric types sorted
//!   numerically), else all atoms are one species named `atom`.
//! - **XYZ / extended XYZ**: `Lattice`, `Origin`, `pbc`, `Time`, `Timestep`/`step` and
//!   `Properties` (column order and counts honoured; a property of count `n > 1` is `n`
//!   columns `name[0]`...); plain XYZ columns are `species x y z col5 col6 ...`. Species
//!   are ordered as LAMMPS text orders them: numerically when every name is an integer,
//!   else by first appearance.
//! - Any numeric column can be the per-particle attribute ([`ReadOptions::attribute`]).
//!   NaN and infinite numbers in used columns are errors. Atom order is kept.
//! - **LAMMPS binary dumps** (`.bin`, both header revisions): see `lammps_binary.rs`.
//!   Errors name the byte offset instead of a line.
//! - **GSD** (HOOMD-blue, `hoomd` schema, file layers 1.x and 2.x): see `gsd.rs`.
//! - **Raw arrays** described by a JSON sidecar (`*.raw.json`, or any file whose content
//!   is a JSON object with the key `mdlod_raw`): see `raw.rs`.
//! - **MegaMol MMPLD** particle lists (`.mmpld`, versions 1.0-1.3): see `mmpld.rs`.
//! - **Per-processor pieces**: a LAMMPS file name with `%` opens all its pieces as one
//!   dump (see `pieces.rs`).
//! - Files are memory-mapped; gzip files (single or multi-member) are decompressed into
//!   memory. zstd, bzip2, xz, lz4 and zip files are recognised and refused with a clear
//!   error, as is a gzip file compressed again inside.

mod atoms;
mod float;
mod gsd;
pub mod index_cache;
mod lammps_binary;
mod lammps_text;
mod mmpld;
mod pieces;
pub(crate) mod raw;
mod xyz;

use std::fmt;
use std::fs::File;
use std::io::Read;
use std::ops::Range;
use std::path::{Path, PathBuf};

pub use float::parse_f64;
pub use pieces::{lone_piece, piece_paths, LonePiece};

use crate::frame::{Attribute, Frame, SimulationBox};
use crate::progress::{NoProgress, Progress};

/// A position in an input file: the path and a 1-based line number. Displays as `path:line`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Location {
    pub path: PathBuf,
    pub line: u64,
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}", self.path.display(), self.line)
    }
}

/// Everything that can go wrong reading a dump. Every message starts with the file path and,
/// where there is one, the line (`dump.lammpstrj:1042: expected 5 columns, found 4`).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ReadError {
    /// Opening, mapping or decompressing the file failed.
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{at}: file is empty")]
    Empty { at: Location },
    /// Not a format this module reads (or a compression it does not decompress).
    #[error("{at}: {message}")]
    Unsupported { at: Location, message: String },
    #[error("{}: frame {frame} does not exist; the file has {count} frame{}, counted from 0 (the last is {})", path.display(), if *count == 1 { "" } else { "s" }, count.saturating_sub(1))]
    NoSuchFrame {
        path: PathBuf,
        frame: usize,
        count: usize,
    },
    #[error("{}: frame -{back} does not exist; the file has {count} frame{}", path.display(), if *count == 1 { "" } else { "s" })]
    NoSuchFrameFromEnd {
        path: PathBuf,
        back: usize,
        count: usize,
    },
    /// A header line (LAMMPS `ITEM:` block, XYZ count or comment line) is not as expected.
    #[error("{at}: {message}")]
    Malformed { at: Location, message: String },
    #[error("{at}: expected {expected} columns, found {found}")]
    ColumnCount {
        at: Location,
        expected: usize,
        found: usize,
    },
    #[error("{at}: column `{column}`: `{text}` is not a number")]
    NotANumber {
        at: Location,
        column: String,
        text: String,
    },
    #[error("{at}: column `{column}`: `{text}` is not a finite number")]
    NonFinite {
        at: Location,
        column: String,
        text: String,
    },
    /// Fewer atom lines than the header announced.
    #[error("{at}: truncated frame: the header announces {expected} atoms but only {found} atom lines follow")]
    Truncated {
        at: Location,
        expected: usize,
        found: usize,
    },
    /// More atom lines than the header announced (`at` is the first extra line).
    #[error("{at}: more atom lines than the {expected} the header announces")]
    ExtraLines { at: Location, expected: usize },
    #[error("{at}: no coordinate columns (need x y z, xu yu zu, xs ys zs or xsu ysu zsu); columns are: {columns}")]
    NoCoordinates { at: Location, columns: String },
    #[error("{at}: no column `{name}` for the attribute; available columns: {available}")]
    UnknownAttribute {
        at: Location,
        name: String,
        available: String,
    },
    #[error("{at}: more than 65536 distinct species")]
    TooManySpecies { at: Location },
    /// The pieces of a `%` set disagree (in their frames, their timesteps): about the
    /// whole piece, so no line or byte is named.
    #[error("{}: {message}", path.display())]
    Pieces { path: PathBuf, message: String },
    /// A binary input is malformed; `offset` is the byte where the problem is.
    #[error("{}: byte {offset}: {message}", path.display())]
    Binary {
        path: PathBuf,
        offset: u64,
        message: String,
    },
}

impl ReadError {
    /// Whether the error is a file cut short: a frame's atom lines, an atom line or a
    /// frame header missing at the end, or a GSD chunk past the end of the file (what a
    /// run still writing, or a copy that stopped, leaves).
    pub fn cut_short(&self) -> bool {
        if matches!(self, ReadError::Truncated { .. }) {
            return true;
        }
        let m = self.to_string();
        m.contains("(truncated file?)")
            || m.contains("(truncated?)")
            || m.contains("ends before its")
    }
}

/// The dump formats this module reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum InputFormat {
    /// LAMMPS text dump (`dump atom`, `dump custom`).
    LammpsText,
    /// XYZ or extended XYZ.
    Xyz,
    /// LAMMPS binary dump (`dump custom` / `dump atom` to a `.bin` file).
    LammpsBinary,
    /// GSD (HOOMD-blue), `hoomd` schema.
    Gsd,
    /// Raw binary arrays described by a JSON sidecar (`*.raw.json`).
    Raw,
    /// MegaMol particle lists (`.mmpld`, versions 1.0 to 1.3).
    Mmpld,
}

impl InputFormat {
    /// The format implied by a file name, ignoring a compression's suffix (`.gz`, `.bz2`,
    /// `.zst`, `.xz`, `.lz4`, `.zip`):
    /// `.lammpstrj`, `.dump`, `.lammps` and `dump.*` are LAMMPS text; `.bin` is LAMMPS
    /// binary (as LAMMPS itself decides); `.gsd` is GSD; `.xyz` and `.extxyz` are XYZ.
    pub fn from_path(path: &Path) -> Option<InputFormat> {
        let name = path.file_name()?.to_str()?.to_ascii_lowercase();
        let name = [".gz", ".bz2", ".zst", ".xz", ".lz4", ".zip"]
            .iter()
            .find_map(|s| name.strip_suffix(s))
            .unwrap_or(&name);
        if name.ends_with(".xyz") || name.ends_with(".extxyz") {
            Some(InputFormat::Xyz)
        } else if name.ends_with(".bin") {
            Some(InputFormat::LammpsBinary)
        } else if name.ends_with(".gsd") {
            Some(InputFormat::Gsd)
        } else if name.ends_with(".raw.json") {
            Some(InputFormat::Raw)
        } else if name.ends_with(".mmpld") {
            Some(InputFormat::Mmpld)
        } else if name.ends_with(".lammpstrj")
            || name.ends_with(".dump")
            || name.ends_with(".lammps")
            || name.starts_with("dump.")
        {
            Some(InputFormat::LammpsText)
        } else {
            None
        }
    }

    /// The format implied by the first non-blank line: `ITEM:` is LAMMPS, an integer is XYZ.
    pub fn sniff(data: &[u8]) -> Option<InputFormat> {
        let mut cursor = Cursor::new(data, 0);
        while let Some((_, line)) = cursor.next_line() {
            let line = trim(line);
            if line.is_empty() {
                continue;
            }
            if line.starts_with(b"ITEM:") {
                return Some(InputFormat::LammpsText);
            }
            return parse_int::<u64>(line).map(|_| InputFormat::Xyz);
        }
        None
    }
}

impl fmt::Display for InputFormat {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            InputFormat::LammpsText => "LAMMPS text dump",
            InputFormat::Xyz => "XYZ",
            InputFormat::LammpsBinary => "LAMMPS binary dump",
            InputFormat::Gsd => "GSD",
            InputFormat::Raw => "raw arrays with a JSON sidecar",
            InputFormat::Mmpld => "MegaMol MMPLD",
        })
    }
}

/// Wraps `frame`'s particles into its cell along the cell's periodic axes (all three where
/// the input does not say; none without a cell): each position's fractional coordinate
/// along such an axis taken modulo 1, in `f64`. A cell without volume is left alone.
pub fn wrap_into_cell(frame: &mut Frame) {
    let Some(cell) = &frame.simulation_box else {
        return;
    };
    wrap_positions(&mut frame.positions, cell);
}

/// [`wrap_into_cell`] of `positions` in `cell`.
pub fn wrap_positions(positions: &mut [[f32; 3]], cell: &mdlod_format::meta::SimulationBox) {
    let mut periodic = cell.periodic.unwrap_or([true; 3]);
    // An edge of length 0 (a two-dimensional system's c, as HOOMD writes Lz = 0) wraps
    // nothing; the unit normal of the other two stands in for it, so that the in-plane
    // axes still wrap.
    let mut edges = [cell.a, cell.b, cell.c];
    let flat: Vec<usize> = (0..3).filter(|&k| edges[k] == [0.0; 3]).collect();
    if let [k] = flat[..] {
        let (u, v) = (edges[(k + 1) % 3], edges[(k + 2) % 3]);
        let n = [
            u[1] * v[2] - u[2] * v[1],
            u[2] * v[0] - u[0] * v[2],
            u[0] * v[1] - u[1] * v[0],
        ];
        let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        if len.is_finite() && len > 0.0 {
            edges[k] = n.map(|x| x / len);
        }
        periodic[k] = false;
    }
    if !periodic.iter().any(|&p| p) {
        return;
    }
    let [a, b, c] = edges;
    // Columns a, b, c; the inverse by the adjugate.
    let m = [[a[0], b[0], c[0]], [a[1], b[1], c[1]], [a[2], b[2], c[2]]];
    let det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
        - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
    if !(det.is_finite() && det.abs() > 0.0) {
        return;
    }
    let inv = [
        [
            (m[1][1] * m[2][2] - m[1][2] * m[2][1]) / det,
            (m[0][2] * m[2][1] - m[0][1] * m[2][2]) / det,
            (m[0][1] * m[1][2] - m[0][2] * m[1][1]) / det,
        ],
        [
            (m[1][2] * m[2][0] - m[1][0] * m[2][2]) / det,
            (m[0][0] * m[2][2] - m[0][2] * m[2][0]) / det,
            (m[0][2] * m[1][0] - m[0][0] * m[1][2]) / det,
        ],
        [
            (m[1][0] * m[2][1] - m[1][1] * m[2][0]) / det,
            (m[0][1] * m[2][0] - m[0][0] * m[2][1]) / det,
            (m[0][0] * m[1][1] - m[0][1] * m[1][0]) / det,
        ],
    ];
    let fractional = |p: [f32; 3]| {
        let d = [0, 1, 2].map(|k| f64::from(p[k]) - cell.origin[k]);
        [0, 1, 2].map(|r| inv[r][0] * d[0] + inv[r][1] * d[1] + inv[r][2] * d[2])
    };
    let place = |f: [f64; 3]| {
        [0, 1, 2]
            .map(|r| (cell.origin[r] + m[r][0] * f[0] + m[r][1] * f[1] + m[r][2] * f[2]) as f32)
    };
    for p in positions.iter_mut() {
        let mut f = fractional(*p);
        let mut moved = false;
        for k in 0..3 {
            if periodic[k] && f[k].is_finite() && !(0.0..1.0).contains(&f[k]) {
                f[k] -= f[k].floor();
                // (A tiny negative one rounds to 1: the lower face is the same place.)
                if f[k] >= 1.0 {
                    f[k] = 0.0;
                }
                moved = true;
            }
        }
        if moved {
            let mut q = place(f);
            // Rounded to single precision, a point just inside the upper face can land on
            // it (10 − 10⁻⁷ is 10.0 in a box of 10): the lower face is the same place.
            let back = fractional(q);
            let mut onto = false;
            for k in 0..3 {
                if periodic[k] && back[k] >= 1.0 {
                    f[k] = 0.0;
                    onto = true;
                }
            }
            if onto {
                q = place(f);
            }
            *p = q;
        }
    }
}

/// What the note on a gzip dump cut short starts with: it is about the file, not the
/// frames that carry it (the last two, as the cut may fall inside the last).
pub const GZIP_CUT: &str = "compressed stream cut short";

/// The inside of an attribute asked for as a magnitude, `|NAME|` (`|forces|`, `|v|`,
/// `|vx,vy,vz|`): the length of a vector per particle, which no column holds.
pub fn magnitude_of(name: &str) -> Option<&str> {
    name.strip_prefix('|')?
        .strip_suffix('|')
        .filter(|s| !s.trim().is_empty())
}

/// The columns of a magnitude `|inner|` among `columns`: the list given (`vx,vy,vz`), or
/// the components of a vector: `inner[0..2]` (extended XYZ), `inner[1..3]` (a LAMMPS
/// compute's), `inner` + `x`, `y`, `z` (LAMMPS `vx vy vz`, `fx fy fz`, `mux muy muz`).
/// The error lists what there is.
pub fn magnitude_columns(inner: &str, columns: &[String]) -> Result<Vec<String>, String> {
    let has = |n: &str| columns.iter().any(|c| c == n);
    let listed: Vec<String> = inner.split(',').map(|c| c.trim().to_string()).collect();
    if listed.len() > 1 {
        if listed.len() > 4 {
            return Err(format!(
                "|{inner}| names {} columns (at most 4)",
                listed.len()
            ));
        }
        if let Some((_, c)) = listed
            .iter()
            .enumerate()
            .find(|(i, c)| listed[..*i].contains(c))
        {
            return Err(format!("|{inner}| names `{c}` twice"));
        }
        return match listed.iter().find(|c| !has(c)) {
            Some(c) => Err(format!(
                "no column `{c}` for the magnitude |{inner}|; the columns are {}",
                columns.join(" ")
            )),
            None => Ok(listed),
        };
    }
    let name = listed[0].as_str();
    let candidates = [
        (0..3).map(|i| format!("{name}[{i}]")).collect::<Vec<_>>(),
        (1..4).map(|i| format!("{name}[{i}]")).collect(),
        ["x", "y", "z"]
            .iter()
            .map(|a| format!("{name}{a}"))
            .collect(),
    ];
    candidates
        .into_iter()
        .find(|c| c.iter().all(|n| has(n)))
        // One column: its absolute value (`|vz|`).
        .or_else(|| has(name).then(|| vec![name.to_string()]))
        .ok_or_else(|| {
            format!(
                "no vector `{name}` for the magnitude |{name}| ({name}[0] {name}[1] {name}[2], \
                 {name}[1] {name}[2] {name}[3] or {name}x {name}y {name}z); name its columns, \
                 as |vx,vy,vz|; the columns are {}",
                columns.join(" ")
            )
        })
}

/// Choices for [`DumpFile::read_frame`].
#[derive(Clone, Debug, Default)]
pub struct ReadOptions {
    /// Name of a column to read as [`Frame::attribute`] (LAMMPS column name such as `c_pe`,
    /// or extended-XYZ property name, `name[i]` for component `i` of a vector property).
    pub attribute: Option<String>,
    /// Further columns to keep beside `attribute` (a file of format 1.2 keeps several:
    /// [`crate::convert::convert_frame_with`]); each is read as `attribute` is, by a pass
    /// of its own over the frame ([`crate::convert::read_extra_attributes`]).
    pub extra_attributes: Vec<String>,
    /// Column names for inputs that do not name their columns (old-revision LAMMPS
    /// binary dumps); a dump that names its own refuses other names, a text dump any.
    pub columns: Option<Vec<String>>,
    /// Which column of a LAMMPS or XYZ dump gives each particle's size.
    pub sizes: SizeColumn,
    /// A column of a LAMMPS or XYZ dump to take each particle's species from instead of
    /// its `type` or `element`: a column of categories, such as the structure type of a
    /// common-neighbour analysis (`c_cna`), so that each category is a species of its
    /// own, with its own colour, averaged in clusters as species colours are, hidden
    /// and named as species are. Each distinct value is one species.
    pub species_column: Option<String>,
    /// Wrap every particle into the simulation cell along its periodic axes (all three
    /// where the input does not say which are), as OVITO's "wrap at periodic
    /// boundaries": unwrapped coordinates (`xu yu zu`) of atoms that crossed the cell's
    /// faces come back inside it. Frames without a cell are read as they are.
    pub wrap: bool,
    /// Read the attribute's values only: text dumps (LAMMPS, XYZ) parse that one column
    /// and leave the frame's positions at 0 and its particles of one species, for the
    /// passes that read further attributes ([`crate::convert::read_extra_attributes`],
    /// chunked builds), which keep only the values; other formats read as ever.
    pub values_only: bool,
}

impl ReadOptions {
    /// These options reading the column `name` as the attribute, alone (no further
    /// attributes): how each further attribute, and each component of a magnitude, is
    /// read by a pass of its own.
    pub fn reading(&self, name: &str) -> ReadOptions {
        ReadOptions {
            attribute: Some(name.to_string()),
            extra_attributes: Vec::new(),
            ..self.clone()
        }
    }
}

/// Which column gives each particle's size ([`Frame::radii`]).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub enum SizeColumn {
    /// A dump's `radius` column, else its `diameter` column (any case), where it has one;
    /// GSD diameters and MMPLD `xyzr` radii.
    #[default]
    Auto,
    /// No sizes of their own: a dump's size columns are not read (its species take their
    /// radii as without them), and GSD and MMPLD particles are drawn at their species'
    /// mean.
    Off,
    /// This column of a LAMMPS or XYZ dump holds each particle's radius (an SPH run's
    /// smoothing length `h`, a compute's `c_rad`).
    Radius(String),
    /// This column holds each particle's diameter.
    Diameter(String),
}

impl SizeColumn {
    /// The size column among `columns` and the factor that makes it a radius, `None`
    /// where there is none to read; an error names a column asked for and not there.
    pub fn resolve(&self, columns: &[String]) -> Result<Option<(usize, f64)>, String> {
        let named = |name: &str, factor: f64, option: &str| {
            columns
                .iter()
                .position(|c| c == name)
                .map(|c| Some((c, factor)))
                .ok_or_else(|| {
                    format!(
                        "no column `{name}` for {option}; the columns are {}",
                        columns.join(" ")
                    )
                })
        };
        // By default `radius` (a granular LAMMPS run's, OVITO's `Radius`), else
        // `diameter`, in any case.
        let find = |name: &str| columns.iter().position(|c| c.eq_ignore_ascii_case(name));
        match self {
            SizeColumn::Auto => Ok(find("radius")
                .map(|c| (c, 1.0))
                .or_else(|| find("diameter").map(|c| (c, 0.5)))),
            SizeColumn::Off => Ok(None),
            SizeColumn::Radius(name) => named(name, 1.0, "--radius-column"),
            SizeColumn::Diameter(name) => named(name, 0.5, "--diameter-column"),
        }
    }

    /// [`Self::resolve`], refusing a column that holds the coordinates or the species
    /// (which a named size column would silently not be read from).
    pub fn resolve_beside(
        &self,
        columns: &[String],
        coords: [usize; 3],
        species: Option<usize>,
    ) -> Result<Option<(usize, f64)>, String> {
        let size = self.resolve(columns)?;
        // A `radius` or `diameter` column read as the species (`--species-column`) is
        // no size column the default finds.
        if *self == SizeColumn::Auto && size.is_some_and(|(c, _)| species == Some(c)) {
            return Ok(None);
        }
        if let Some((c, _)) = size {
            let role = if coords.contains(&c) {
                Some("a coordinate")
            } else if species == Some(c) {
                Some("the species")
            } else {
                None
            };
            if let Some(role) = role {
                return Err(format!(
                    "column `{}` holds {role}, not the particles' sizes",
                    columns[c]
                ));
            }
        }
        Ok(size)
    }

    /// How a batch manifest records the choice (`None`: the default).
    pub fn record(&self) -> Option<String> {
        match self {
            SizeColumn::Auto => None,
            SizeColumn::Off => Some("none".into()),
            SizeColumn::Radius(n) => Some(format!("radius {n}")),
            SizeColumn::Diameter(n) => Some(format!("diameter {n}")),
        }
    }

    /// An error for inputs whose sizes come from no column (GSD, MMPLD, raw arrays):
    /// `None` unless a column is named.
    pub fn named_column(&self) -> Option<String> {
        match self {
            SizeColumn::Radius(n) => Some(format!("--radius-column {n}")),
            SizeColumn::Diameter(n) => Some(format!("--diameter-column {n}")),
            _ => None,
        }
    }
}

/// What a frame's header says, without its atoms.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameInfo {
    /// Number of atoms the header announces.
    pub particles: usize,
    pub timestep: Option<u64>,
    pub time: Option<f64>,
    pub units: Option<String>,
    pub simulation_box: Option<SimulationBox>,
    /// Column names of the atom lines (LAMMPS `ITEM: ATOMS` names; XYZ property names).
    pub columns: Vec<String>,
}

/// A frame's parsed header: the public part plus where its atoms are and how to read them.
#[derive(Clone, Debug)]
pub(crate) struct Header {
    pub info: FrameInfo,
    pub layout: atoms::AtomLayout,
    /// Offset of the line naming the columns, for column errors.
    pub columns_at: usize,
    /// Byte range of the atom lines.
    pub atoms: Range<usize>,
}

/// The bytes of an opened dump: a memory map or a decompressed buffer.
enum Bytes {
    /// The file, mapped.
    Map(mdlod_format::mmap::Mmap),
    /// Decompressed text (or nothing, for a piece set).
    Text(Vec<u8>),
}

impl AsRef<[u8]> for Bytes {
    fn as_ref(&self) -> &[u8] {
        match self {
            Bytes::Map(m) => m,
            Bytes::Text(t) => t,
        }
    }
}

enum Index {
    Lammps(lammps_text::Index),
    Xyz(xyz::Index),
    LammpsBinary(lammps_binary::Index),
    Gsd(gsd::Index),
    /// Per-processor pieces of one dump (a file name with `%`).
    Pieces(Vec<DumpFile>),
    Raw(Box<raw::Index>),
    Mmpld(mmpld::Index),
}

/// An opened dump file and its frame index.
pub struct DumpFile {
    path: PathBuf,
    bytes: Bytes,
    /// True when `bytes` were decompressed (not a map of the file).
    compressed: bool,
    /// The gzip file whose compressed stream ended early (a run still writing it, a copy
    /// cut short): the text decompressed before the cut is what is read.
    gzip_cut: Option<PathBuf>,
    /// The file the user named, where this dump reads a working copy of it (a large
    /// gzip file decompressed to disk): what notes name.
    named: Option<PathBuf>,
    format: InputFormat,
    index: Index,
    /// Its frames were listed from a frame index ([`index_cache`]), not by a scan.
    from_index: bool,
}

impl fmt::Debug for DumpFile {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("DumpFile")
            .field("path", &self.path)
            .field("format", &self.format)
            .field("frames", &self.frame_count())
            .finish()
    }
}

impl DumpFile {
    /// Opens a dump, detecting its format from the name or first line, and indexes its frames.
    pub fn open(path: &Path) -> Result<DumpFile, ReadError> {
        DumpFile::open_with(path, None, &NoProgress)
    }

    /// Like [`DumpFile::open`], with the format given (or `None` to detect it) and progress
    /// reported for decompression and indexing.
    pub fn open_with(
        path: &Path,
        format: Option<InputFormat>,
        progress: &dyn Progress,
    ) -> Result<DumpFile, ReadError> {
        // (Without a limit, every file opens or fails.)
        DumpFile::open_limited(path, format, None, progress)?.ok_or_else(|| ReadError::Io {
            path: path.to_path_buf(),
            source: std::io::Error::other("internal error: no dump opened without a limit"),
        })
    }

    /// Like [`DumpFile::open`], except for gzip files whose text is larger than
    /// `text_limit` bytes: `None`, after decompressing no more than `text_limit + 1`
    /// bytes of it (the caller can then decompress it into a file with
    /// [`gunzip_to_file`]). For a `%` piece set, the limit holds for the text of all
    /// its pieces together.
    pub fn open_within(
        path: &Path,
        text_limit: u64,
        progress: &dyn Progress,
    ) -> Result<Option<DumpFile>, ReadError> {
        DumpFile::open_limited(path, None, Some(text_limit), progress)
    }

    /// The `%` piece set `pattern` made of its pieces, opened one by one (in processor
    /// order, as [`piece_paths`] lists them, or from files they were decompressed into):
    /// checked to hold the same frames.
    pub fn from_pieces(pattern: &Path, pieces: Vec<DumpFile>) -> Result<DumpFile, ReadError> {
        pieces::check(pattern, &pieces)?;
        let Some(first) = pieces.first() else {
            return Err(ReadError::Io {
                path: pattern.to_path_buf(),
                source: std::io::Error::new(std::io::ErrorKind::NotFound, "no pieces"),
            });
        };
        Ok(DumpFile {
            path: pattern.to_path_buf(),
            bytes: Bytes::Text(Vec::new()),
            compressed: pieces.iter().any(DumpFile::is_compressed),
            gzip_cut: pieces.iter().find_map(|p| p.gzip_cut.clone()),
            named: None,
            format: first.format,
            from_index: pieces.iter().any(|p| p.from_index),
            index: Index::Pieces(pieces),
        })
    }

    /// Bytes of decompressed text this dump holds in memory (0 for mapped files).
    pub fn text_in_memory(&self) -> u64 {
        match &self.index {
            Index::Pieces(p) => p.iter().map(DumpFile::text_in_memory).sum(),
            _ if self.compressed => self.bytes().len() as u64,
            _ => 0,
        }
    }

    /// [`DumpFile::open_with`], or with `text_limit`, [`DumpFile::open_within`].
    fn open_limited(
        path: &Path,
        format: Option<InputFormat>,
        text_limit: Option<u64>,
        progress: &dyn Progress,
    ) -> Result<Option<DumpFile>, ReadError> {
        if is_piece_pattern(path) {
            let Some(pieces) = pieces::open(path, format, text_limit, progress)? else {
                return Ok(None);
            };
            return DumpFile::from_pieces(path, pieces).map(Some);
        }
        let io = |source| ReadError::Io {
            path: path.to_path_buf(),
            source,
        };
        let first_line = || Location {
            path: path.to_path_buf(),
            line: 1,
        };
        let file = mdlod_format::files::open(path).map_err(io)?;
        let size = file.metadata().map_err(io)?.len();
        if size == 0 {
            return Err(ReadError::Empty { at: first_line() });
        }
        let map = mdlod_format::mmap::map_file(&file).map_err(io)?;
        // With a frame index at hand, the file is mapped without read-ahead until its
        // frames are listed: a listing from the index reads the first lines of each
        // frame (and this, its first bytes), and a page touched would read megabytes
        // around it, of frames another shard converts. Any other listing reads ahead
        // again (below).
        let indexing = index_cache::current().is_some();
        let read_ahead = |map: &mdlod_format::mmap::Mmap| {
            // (Advice only: a kernel that refuses it reads as it would.)
            let _ = map.advise(mdlod_format::mmap::Advice::Normal);
        };
        if indexing {
            let _ = map.advise(mdlod_format::mmap::Advice::Random);
        }
        let compressed = map.starts_with(&[0x1f, 0x8b]);
        if indexing && compressed {
            read_ahead(&map);
        }
        let mut gzip_cut = None;
        let bytes: Bytes = if compressed {
            match gunzip(path, &map, text_limit, progress)? {
                Some((text, cut)) => {
                    gzip_cut = cut.then(|| path.to_path_buf());
                    Bytes::Text(text)
                }
                None => return Ok(None),
            }
        } else if let Some(kind) = other_compression(&map) {
            return Err(ReadError::Unsupported {
                at: first_line(),
                message: if kind == "tar" {
                    "a tar archive, not a dump: unpack it (`tar -xf`) and give the dumps it \
                     holds"
                        .into()
                } else {
                    format!(
                        "{kind}-compressed dumps are not supported (gzip is); decompress the \
                         file or recompress it with gzip"
                    )
                },
            });
        } else {
            Bytes::Map(map)
        };
        let data = bytes.as_ref();
        // A gzip file whose content is compressed again (gzipped twice, a `.tar.gz`'s
        // members are not: a tar file is refused as no dump below).
        if compressed {
            let inner = if data.starts_with(&[0x1f, 0x8b]) {
                Some("gzip")
            } else {
                other_compression(data)
            };
            if let Some(kind) = inner {
                return Err(ReadError::Unsupported {
                    at: first_line(),
                    message: if kind == "tar" {
                        "its gzip stream holds a tar archive (a .tar.gz), not a dump: unpack \
                         it (`tar -xzf`) and give the dumps it holds"
                            .into()
                    } else {
                        format!(
                            "its gzip stream holds {kind}-compressed data, not a dump: \
                             compressed twice? decompress it (`gunzip -c`) and read the result"
                        )
                    },
                });
            }
        }
        if data.iter().all(|b| b.is_ascii_whitespace()) {
            return Err(ReadError::Empty { at: first_line() });
        }
        // A name that says one text format over a first line that says the other (LAMMPS
        // `dump xyz` output named `dump.water`, a LAMMPS dump named `.xyz`; a text dump
        // named `.bin`): the content decides, as no file starts both ways.
        // Likewise a file that starts with a signature (GSD's, MMPLD's) whatever its name
        // says (an MMPLD file named `.bin`).
        let by_name = InputFormat::from_path(path).map(|f| match (f, InputFormat::sniff(data)) {
            (InputFormat::LammpsText, Some(InputFormat::Xyz)) => InputFormat::Xyz,
            (InputFormat::Xyz | InputFormat::LammpsBinary, Some(InputFormat::LammpsText)) => {
                InputFormat::LammpsText
            }
            _ if mmpld::sniff(data) => InputFormat::Mmpld,
            _ if gsd::sniff(data) => InputFormat::Gsd,
            _ => f,
        });
        let format = format
            .or(by_name)
            .or_else(|| lammps_binary::sniff(data).then_some(InputFormat::LammpsBinary))
            .or_else(|| gsd::sniff(data).then_some(InputFormat::Gsd))
            .or_else(|| mmpld::sniff(data).then_some(InputFormat::Mmpld))
            .or_else(|| raw::sniff(data).then_some(InputFormat::Raw))
            .or_else(|| InputFormat::sniff(data))
            .ok_or_else(|| {
                let mut cursor = Cursor::new(data, 0);
                let line = std::iter::from_fn(|| cursor.next_line())
                    .map(|(_, l)| trim(l))
                    .find(|l| !l.is_empty())
                    .unwrap_or_default();
                let message = match foreign_format(path, data) {
                    _ if data.starts_with(&mdlod_format::layout::MAGIC) => format!(
                        "an .mdlod file already, mdlod's own output: `mdlod render {0}` draws \
                         it and `mdlod info {0}` describes it; convert reads particle dumps",
                        path.display()
                    ),
                    Some(kind) => format!(
                        "{kind}, which mdlod does not read: write it as extended XYZ (ASE: \
                         `ase convert {} out.xyz`; or from OVITO or VMD), a LAMMPS dump or GSD",
                        path.file_name().map_or(String::new(), |n| n.to_string_lossy().into_owned())
                    ),
                    None => format!(
                        "cannot tell the format from the name or the first line `{}`; expected a LAMMPS text dump (`ITEM: ...`), an XYZ file (atom count) or a raw sidecar (a JSON object with `\"mdlod_raw\": 1`)",
                        shorten(line)
                    ),
                };
                ReadError::Unsupported {
                    at: first_line(),
                    message,
                }
            })?;
        let ctx = Ctx { path, data };
        progress.stage("indexing frames", Some(data.len() as u64), "bytes");
        // Text is scanned a segment at a time: the bar moves with each.
        let reached = Reached::new(progress);
        // An uncompressed text dump's frames, as a batch's cache kept them where the file
        // is the one they were taken from (the metadata of the file mapped).
        let cache = index_cache::current()
            .filter(|_| !compressed)
            .filter(|_| matches!(format, InputFormat::LammpsText | InputFormat::Xyz));
        let meta = match &cache {
            Some(_) => Some(file.metadata().map_err(io)?),
            None => None,
        };
        let kept = match (&cache, &meta) {
            (Some(c), Some(m)) => {
                let name = if format == InputFormat::Xyz {
                    "xyz"
                } else {
                    "lammps"
                };
                c.lookup(path, m, name).and_then(|cached| {
                    let index = match format {
                        InputFormat::Xyz => xyz::Index::from_cached(data, &cached).map(Index::Xyz),
                        _ => lammps_text::Index::from_cached(data, &cached).map(Index::Lammps),
                    };
                    if index.is_none() {
                        c.rejected(path);
                    }
                    index
                })
            }
            _ => None,
        };
        let from_cache = kept.is_some();
        // Listed from the index: a frame read whole asks for its bytes at once
        // (`will_need`). Scanned, or a format whose frames come from its headers: read
        // ahead as usual.
        if let (true, false, Bytes::Map(m)) = (indexing, from_cache, &bytes) {
            read_ahead(m);
        }
        let index = if let Some(index) = kept {
            index
        } else {
            match format {
                InputFormat::LammpsText => Index::Lammps(lammps_text::Index::build(
                    &ctx,
                    (!compressed).then_some(&file),
                    SCAN_SEGMENT,
                    &reached,
                )?),
                InputFormat::Xyz => Index::Xyz(xyz::Index::build(
                    &ctx,
                    (!compressed).then_some(&file),
                    SCAN_SEGMENT,
                    &reached,
                )?),
                InputFormat::LammpsBinary => {
                    Index::LammpsBinary(lammps_binary::Index::build(path, data)?)
                }
                InputFormat::Gsd => Index::Gsd(gsd::Index::build(path, data)?),
                InputFormat::Raw => Index::Raw(Box::new(raw::Index::build(path, data)?)),
                InputFormat::Mmpld => Index::Mmpld(mmpld::Index::build(path, data)?),
            }
        };
        // (Kept only when the file is as long as the bytes scanned: one a running
        // simulation appended to meanwhile must be scanned again next time.)
        if let (Some(c), Some(m)) = (&cache, &meta) {
            match &index {
                _ if m.len() != data.len() as u64 => {}
                Index::Lammps(i) if !from_cache => c.insert(path, m, i.to_cached()),
                Index::Xyz(i) if !from_cache => c.insert(path, m, i.to_cached()),
                _ => {}
            }
        }
        reached.at(data.len());
        progress.finish_stage();
        Ok(Some(DumpFile {
            path: path.to_path_buf(),
            bytes,
            compressed,
            gzip_cut,
            named: None,
            format,
            index,
            from_index: from_cache,
        }))
    }

    /// The gzip input whose compressed stream ended early (a run still writing it), whose
    /// text before the cut this dump reads.
    pub fn gzip_cut(&self) -> Option<&Path> {
        self.gzip_cut.as_deref()
    }

    /// Marks this dump, read from the working file `input` was decompressed into
    /// ([`gunzip_to_file`]), as the text before a cut in `input`'s compressed stream.
    pub fn with_gzip_cut(mut self, input: &Path) -> DumpFile {
        self.gzip_cut = Some(input.to_path_buf());
        self
    }

    /// This dump reads a working copy of `input` (a gzip file decompressed to disk): its
    /// notes name `input`, not the copy.
    pub fn named_as(mut self, input: &Path) -> DumpFile {
        self.named = Some(input.to_path_buf());
        self
    }

    /// `notes` with the working copy's path replaced by the file the user named.
    fn as_named(&self, notes: Vec<String>) -> Vec<String> {
        match &self.named {
            Some(named) => {
                let (copy, named) = (self.path.display().to_string(), named.display().to_string());
                notes
                    .into_iter()
                    .map(|n| n.replace(&copy, &named))
                    .collect()
            }
            None => notes,
        }
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// True when the dump was decompressed into memory (a gzip file, or a piece set
    /// with a gzip piece).
    pub fn is_compressed(&self) -> bool {
        self.compressed
    }

    pub fn format(&self) -> InputFormat {
        self.format
    }

    /// The dump's bytes (decompressed when the file is gzip-compressed).
    fn bytes(&self) -> &[u8] {
        self.bytes.as_ref()
    }

    /// Whether its frames (a piece's, of a `%` set) were listed from a frame index rather
    /// than by a scan.
    pub fn listed_from_index(&self) -> bool {
        self.from_index
    }

    /// The files a frame index keeps for this dump: its pieces', or its own.
    pub fn indexed_files(&self) -> Vec<PathBuf> {
        self.piece_paths()
            .unwrap_or_else(|| vec![self.path.clone()])
    }

    /// Asks the kernel to read frame `k`'s bytes ahead, all at once, before they are read
    /// whole: a dump listed from a frame index ([`index_cache`]) is mapped without
    /// read-ahead (each frame's first lines are all a listing reads, and a page touched
    /// would read megabytes around it, of frames another shard converts).
    fn will_need(&self, k: usize) {
        match (&self.bytes, &self.index) {
            (_, Index::Pieces(p)) => p.iter().for_each(|d| d.will_need(k)),
            (Bytes::Map(m), Index::Lammps(_) | Index::Xyz(_)) => {
                if let Some(r) = self.frame_bytes(k) {
                    // (Advice only: a kernel that refuses it reads as it would.)
                    let (start, len) = (r.start as usize, (r.end - r.start) as usize);
                    let _ = m.advise_range(mdlod_format::mmap::Advice::WillNeed, start, len);
                }
            }
            _ => {}
        }
    }

    /// Number of frames in the file.
    pub fn frame_count(&self) -> usize {
        match &self.index {
            Index::Lammps(i) => i.len(),
            Index::Xyz(i) => i.len(),
            Index::LammpsBinary(i) => i.len(),
            Index::Gsd(i) => i.len(),
            Index::Pieces(p) => pieces::frame_count(p),
            Index::Raw(_) => 1,
            Index::Mmpld(i) => i.len(),
        }
    }

    /// Timestep of frame `k` from the index (no parsing). `None` when `k` is out of range or
    /// the frame does not record one (XYZ files without `Timestep=`/`step=`, raw sidecars
    /// without `timestep`, MMPLD files, GSD files without any `configuration/step`).
    pub fn frame_timestep(&self, k: usize) -> Option<u64> {
        match &self.index {
            Index::Lammps(i) => i.timestep(k),
            Index::Xyz(i) => i.timestep(k),
            Index::LammpsBinary(i) => i.timestep(k),
            Index::Gsd(i) => i.recorded_timestep(self.bytes(), k),
            Index::Pieces(p) => p[0].frame_timestep(k),
            Index::Raw(r) => (k == 0).then(|| r.timestep()).flatten(),
            Index::Mmpld(_) => None,
        }
    }

    /// Parses frame `k`'s header only: counts, box, time and column names.
    pub fn frame_info(&self, k: usize) -> Result<FrameInfo, ReadError> {
        if let Index::Gsd(i) = &self.index {
            self.check_frame(k)?;
            return gsd::frame_info(&self.path, self.bytes(), i, k);
        }
        if let Index::Pieces(p) = &self.index {
            self.check_frame(k)?;
            return pieces::frame_info(p, k);
        }
        if let Index::Raw(r) = &self.index {
            self.check_frame(k)?;
            return Ok(r.frame_info());
        }
        if let Index::Mmpld(i) = &self.index {
            self.check_frame(k)?;
            return mmpld::frame_info(&self.path, i, k);
        }
        if let Index::LammpsBinary(i) = &self.index {
            self.check_frame(k)?;
            return Ok(lammps_binary::frame_info(
                &self.path,
                i.header(&self.path, k)?,
                &ReadOptions::default(),
            ));
        }
        Ok(self.header(k)?.info)
    }

    fn check_frame(&self, k: usize) -> Result<(), ReadError> {
        if k >= self.frame_count() {
            return Err(ReadError::NoSuchFrame {
                path: self.path.clone(),
                frame: k,
                count: self.frame_count(),
            });
        }
        Ok(())
    }

    /// What a conversion of frame `k` read with `read` should say about what the input
    /// holds and the conversion does not read: a raw sidecar's arrays holding values past
    /// its `particles`; a dump's `diameter` column beside the `radius` column read as the
    /// particles' sizes; the last frame of a text dump whose last line has no line end
    /// ([`DumpFile::ends_mid_line`]).
    /// Frame `k`'s timestep key whose value is no whole number, as written
    /// (`Timestep=x` in an XYZ comment line): the frame is numbered by its position.
    pub fn unread_timestep(&self, k: usize) -> Option<&str> {
        match &self.index {
            Index::Xyz(x) => x.unread_timestep(k),
            _ => None,
        }
    }

    pub fn frame_notes(&self, k: usize, read: &ReadOptions) -> Vec<String> {
        let mut notes = Vec::new();
        if let Index::Raw(r) = &self.index {
            notes.extend(r.notes().iter().cloned());
        }
        // A timestep that is no whole number, which the frame's position stands in for.
        if let Some(v) = self.unread_timestep(k) {
            notes.push(format!(
                "{}: frame {k}'s comment line gives `{v}`, no whole number: the frame is \
                 numbered by its position, {k}",
                self.path.display()
            ));
        }
        // Bytes after an MMPLD frame's lists, passed over as MegaMol does.
        if let Index::Mmpld(m) = &self.index {
            let bytes = m.trailing(k);
            if bytes > 0 {
                notes.push(format!(
                    "{}: frame {k} holds {bytes} bytes after its lists, up to where the seek \
                     table says it ends: passed over, as MegaMol reads a frame (padding; or \
                     lists its header's count leaves out, if the file was written wrong)",
                    self.path.display()
                ));
            }
        }
        // A GSD attribute a later frame takes from frame 0: the colours are frame 0's.
        if let (Index::Gsd(i), Some(name)) = (&self.index, &read.attribute) {
            let full = gsd::chunk_name(name);
            if i.takes_from_frame_0(self.bytes(), k, &full) {
                notes.push(format!(
                    "{}: `{full}` is written in frame 0 only (HOOMD writes quantities \
                     outside its `dynamic` list once), and later frames take frame 0's values \
                     for their attribute",
                    self.path.display()
                ));
            }
        }

        let named = read.sizes == SizeColumn::Auto
            && matches!(
                self.format,
                InputFormat::LammpsText | InputFormat::LammpsBinary | InputFormat::Xyz
            );
        // (Read once, where a note below needs it.)
        let lammps_text = matches!(
            (self.format, &self.index),
            (InputFormat::LammpsText, Index::Lammps(_))
        );
        let info = (named || lammps_text || read.wrap)
            .then(|| self.frame_info(k).ok())
            .flatten();
        // `--wrap` of a frame without a cell (a plain XYZ file): nothing to wrap into.
        if let Some(i) = info.as_ref().filter(|i| read.wrap && i.particles > 0) {
            let why = match &i.simulation_box {
                None if self.format == InputFormat::Xyz => {
                    Some("has no simulation cell (an extended XYZ file gives one as `Lattice=`)")
                }
                None => Some("has no simulation cell"),
                Some(b) if b.periodic == Some([false; 3]) => Some(
                    "has a box periodic along no axis (an MMPLD file's bounds its data, a \
                     LAMMPS dump's `ff ff ff` or `ss ss ss`)",
                ),
                Some(_) => None,
            };
            if let Some(why) = why {
                notes.push(format!(
                    "{}: frame {k} {why}, so --wrap has nothing to wrap the particles into: \
                     they are kept where they are",
                    self.path.display()
                ));
            }
        }
        if let Some(info) = info.as_ref().filter(|_| named) {
            let has = |n: &str| info.columns.iter().find(|c| c.eq_ignore_ascii_case(n));
            if let (Some(r), Some(d)) = (has("radius"), has("diameter")) {
                notes.push(format!(
                    "{}: the particles' sizes are read from column `{r}`; column `{d}` is \
                     left alone",
                    self.path.display()
                ));
            }
            // An SPH run's smoothing length, which sizes are not read from by default.
            let smoothing = ["h", "hsml", "smoothing_length", "smoothinglength"]
                .iter()
                .find_map(|n| has(n));
            if let (Some(h), None, None) = (smoothing, has("radius"), has("diameter")) {
                notes.push(format!(
                    "{}: column `{h}` looks like a smoothing length, which is not read as the \
                     particles' sizes by default: --radius-column {h} draws each particle at \
                     its own",
                    self.path.display()
                ));
            }
        }
        // LAMMPS writes a box in every frame: one without was likely misspelt, and its
        // item skipped as unknown.
        let boxless = info
            .as_ref()
            .filter(|i| i.simulation_box.is_none() && i.particles > 0);
        if boxless.is_some() && lammps_text {
            notes.push(format!(
                "{}: frame {k} has no `ITEM: BOX BOUNDS` (LAMMPS writes one in every frame; an \
                 item it does not know, such as a misspelt one, is skipped): converted without \
                 a box, so --cell draws none",
                self.path.display()
            ));
        }
        // Columns read that are named twice, their copies agreeing (LIGGGHTS).
        if lammps_text {
            if let Ok(header) = self.header(k) {
                if let Ok((coords, _, attribute, size, layout)) =
                    text_columns(&self.ctx(), &header, read)
                {
                    let read = columns_read(coords, layout.species, attribute, size);
                    if let Some(note) = copies_read_note(&header, read) {
                        notes.push(format!("{}: `ITEM: ATOMS` {note}", self.path.display()));
                    }
                }
            }
        }
        if let Index::Gsd(i) = &self.index {
            notes.extend(gsd::shape_note(&self.path, self.bytes(), i, k));
            notes.extend(gsd::orientation_note(&self.path, self.bytes(), i, k));
        }
        if let Index::Mmpld(i) = &self.index {
            let lists = i.coloured_lists(k);
            if !lists.is_empty() {
                let names: Vec<String> = lists.iter().map(|l| l.to_string()).collect();
                notes.push(format!(
                    "{}: the particles of list{} {} carry colours of their own, which are not \
                     kept: each list is a species, drawn in one colour, their mean (exact \
                     where a list is of one colour; render's --species-colour {}=COLOUR sets \
                     another)",
                    self.path.display(),
                    if lists.len() == 1 { "" } else { "s" },
                    names.join(", "),
                    names[0]
                ));
            }
        }
        // With the last frame and the one before it: the cut may fall inside the last,
        // which is then left out, its notes unsaid.
        if let Some(gz) = self
            .gzip_cut
            .as_ref()
            .filter(|_| k + 2 >= self.frame_count())
        {
            // (Said first what it is: a batch groups notes by what precedes their first
            // `: `, and other notes about this file would hide it.)
            notes.push(format!(
                "{GZIP_CUT}: {} ends early (a run still writing it, or a \
                 copy cut short): the text before the cut is read, a frame it cuts is left \
                 out, and a rerun reads the rest once the file is complete",
                gz.display()
            ));
        }
        if let Some(path) = self.mid_line_file().filter(|_| k + 1 == self.frame_count()) {
            notes.push(format!(
                "{}: its last line has no line end: if a run is still writing it, the last \
                 atom's values may be cut inside a number (`0.41` of `0.4156`)",
                path.display()
            ));
        }
        self.as_named(notes)
    }

    /// True for a text dump (LAMMPS text, XYZ) whose last line has no line end: a run
    /// still writing it may have stopped inside a number (`0.41` of `0.4156`), which
    /// reads as a whole value. For a `%` set, one of the pieces whose last frame is the
    /// set's last (a number of its header, its timestep `50` of `500`, may be cut too).
    pub fn ends_mid_line(&self) -> bool {
        self.mid_line_file().is_some()
    }

    /// The file [`DumpFile::ends_mid_line`] is true for, as the user named it: this one,
    /// or the piece of a set.
    pub fn mid_line_file(&self) -> Option<&Path> {
        match &self.index {
            Index::Lammps(_) | Index::Xyz(_) => self
                .bytes()
                .last()
                .is_some_and(|&b| b != b'\n')
                .then(|| self.named.as_deref().unwrap_or(&self.path)),
            Index::Pieces(p) => p
                .iter()
                .filter(|d| d.frame_count() == pieces::frame_count(p))
                .find_map(DumpFile::mid_line_file),
            _ => None,
        }
    }

    /// Frame `k`'s byte range in the file, for uncompressed single files whose frames
    /// are contiguous ranges (LAMMPS text and binary dumps, XYZ files); `None` for
    /// others and for a `k` out of range.
    /// For a `%` piece set, the sums of its pieces' frame `k` starts and ends (the
    /// pieces' frames hashed one after another: [`DumpFile::frame_ranges`]).
    pub fn frame_bytes(&self, k: usize) -> Option<std::ops::Range<u64>> {
        if let Index::Pieces(p) = &self.index {
            let mut sum = 0..0u64;
            for piece in p {
                let r = piece.frame_bytes(k)?;
                sum = sum.start.checked_add(r.start)?..sum.end.checked_add(r.end)?;
            }
            return Some(sum);
        }
        if self.compressed {
            return None;
        }
        let r = match &self.index {
            Index::Lammps(i) => i.bytes(k)?,
            Index::Xyz(i) => i.bytes(k)?,
            Index::LammpsBinary(i) => i.header(&self.path, k).ok()?.bytes.clone(),
            // The span of the frame's own chunks (a GSD writer appends a frame's chunks
            // together); what the frame is read from is [`DumpFile::frame_ranges`].
            Index::Gsd(i) if k < i.len() => {
                let own = i.own_ranges(k);
                own.first()?.start..own.iter().map(|r| r.end).max()?
            }
            _ => return None,
        };
        Some(r.start as u64..r.end as u64)
    }

    /// The byte ranges frame `k` is read from, in order, with the files they lie in,
    /// where they are not just [`DumpFile::frame_bytes`] of this file: a GSD frame's own
    /// chunks, then the chunks of frame 0 it may take (the types, say, which a HOOMD run
    /// writes once); a `%` piece set's pieces' frames in processor order. `None` for the
    /// other formats.
    pub fn frame_ranges(&self, k: usize) -> Option<Vec<(PathBuf, std::ops::Range<u64>)>> {
        match &self.index {
            Index::Gsd(i) if !self.compressed && k < i.len() => Some(
                i.frame_ranges(k)
                    .into_iter()
                    .map(|r| (self.path.clone(), r.start as u64..r.end as u64))
                    .collect(),
            ),
            Index::Pieces(p) => {
                let mut all = Vec::new();
                for piece in p {
                    match piece.frame_ranges(k) {
                        Some(r) => all.extend(r),
                        None => all.push((piece.path().to_path_buf(), piece.frame_bytes(k)?)),
                    }
                }
                Some(all)
            }
            _ => None,
        }
    }

    /// True when [`DumpFile::read_part`] can read this dump's frames a range of particles
    /// at a time (binary formats with fixed-size records).
    pub fn reads_parts(&self) -> bool {
        matches!(
            self.index,
            Index::Raw(_) | Index::LammpsBinary(_) | Index::Gsd(_) | Index::Mmpld(_)
        )
    }

    /// Notes on the input as a whole, said once whichever of its frames are read: a `%`
    /// set's frames that some pieces hold and others not yet (left out).
    pub fn input_notes(&self) -> Vec<String> {
        match &self.index {
            Index::Pieces(p) => {
                self.as_named(pieces::ahead_note(&self.path, p).into_iter().collect())
            }
            _ => Vec::new(),
        }
    }

    /// For a `%` piece set, each piece's header of frame `k` where the piece is
    /// uncompressed text read by lines (`None` for the others, and where it cannot be
    /// read: that piece is opened again and reports it); `None` for other dumps.
    pub(crate) fn piece_headers(&self, k: usize) -> Option<Vec<Option<Header>>> {
        match &self.index {
            Index::Pieces(p) => Some(
                p.iter()
                    .map(|d| d.reads_text_windows().then(|| d.header(k).ok()).flatten())
                    .collect(),
            ),
            _ => None,
        }
    }

    /// The piece files of a `%` piece set, in processor order (`None` for one file).
    pub fn piece_paths(&self) -> Option<Vec<PathBuf>> {
        match &self.index {
            Index::Pieces(p) => Some(p.iter().map(|d| d.path().to_path_buf()).collect()),
            _ => None,
        }
    }

    /// The species every part of frame `k` read by [`DumpFile::read_part`] should list
    /// for the parts to convert as the whole frame does, where a part's own would differ:
    /// GSD radii are half the mean diameter of each type over the whole frame (one pass
    /// over the type ids and diameters). `None` where a part's species are right as read.
    pub fn frame_species(
        &self,
        k: usize,
    ) -> Result<Option<Vec<crate::frame::SpeciesName>>, ReadError> {
        self.check_frame(k)?;
        match &self.index {
            Index::Gsd(i) => gsd::frame_species(&self.path, self.bytes(), i, k).map(Some),
            Index::Mmpld(i) => mmpld::frame_species(&self.path, self.bytes(), i, k).map(Some),
            _ => Ok(None),
        }
    }

    /// The radii frame `k`'s file gives its species, by name: GSD types (half their mean
    /// diameter), MMPLD lists, a raw sidecar's `radii`; empty for formats that give none
    /// (the species then take their element's radius or the default). A radius of zero or
    /// below is listed as it is (a conversion refuses it unless overridden). GSD and
    /// MMPLD `xyzr` lists take one pass over the frame's types and sizes.
    pub fn given_radii(&self, k: usize) -> Result<Vec<(String, f32)>, ReadError> {
        self.check_frame(k)?;
        Ok(match &self.index {
            Index::Raw(r) => r.given_radii(),
            _ => self
                .frame_species(k)?
                .unwrap_or_default()
                .into_iter()
                .filter_map(|s| Some((s.name, s.radius?)))
                .collect(),
        })
    }

    /// How frame `k` names its species, from its header and first atom (see
    /// [`SpeciesNaming`](crate::species::SpeciesNaming)): LAMMPS text with an `element`
    /// column names them by element; LAMMPS text with a `type` column of numbers (no
    /// `element`) and LAMMPS binary dumps with a `type` column by type number; anything
    /// else (type labels, XYZ, GSD, raw arrays, MMPLD, a frame without atoms) as given.
    /// `opts` supplies the column names of old-revision binary dumps.
    pub fn species_naming(
        &self,
        k: usize,
        opts: &ReadOptions,
    ) -> Result<crate::species::SpeciesNaming, ReadError> {
        use crate::species::{is_type_number, SpeciesNaming};
        self.check_frame(k)?;
        // A column of categories (`--species-column`) may hold any value.
        if opts.species_column.is_some() {
            return Ok(SpeciesNaming::Given);
        }
        match &self.index {
            Index::Lammps(_) => {
                let header = self.header(k)?;
                let (Some(col), true) = (header.layout.species, header.info.particles > 0) else {
                    return Ok(SpeciesNaming::Given);
                };
                let first = Cursor::new(&self.bytes()[..header.atoms.end], header.atoms.start)
                    .next_line()
                    .map_or(&[][..], |(_, l)| l);
                let field = |c: usize| {
                    fields(first)
                        .nth(c)
                        .map(|f| String::from_utf8_lossy(f).into_owned())
                };
                let Some(token) = field(col) else {
                    return Ok(SpeciesNaming::Given);
                };
                let columns = &header.info.columns;
                Ok(if columns[col] == "element" {
                    SpeciesNaming::ElementColumn {
                        first: token,
                        first_type: columns.iter().position(|c| c == "type").and_then(field),
                    }
                } else if header.layout.numeric_species && is_type_number(&token) {
                    SpeciesNaming::TypeNumbers { first: token }
                } else {
                    SpeciesNaming::Given
                })
            }
            Index::LammpsBinary(i) => {
                let info = lammps_binary::frame_info(&self.path, i.header(&self.path, k)?, opts);
                if !info.columns.iter().any(|c| c == "type") || info.particles == 0 {
                    return Ok(SpeciesNaming::Given);
                }
                let plain = ReadOptions {
                    attribute: None,
                    extra_attributes: Vec::new(),
                    columns: opts.columns.clone(),
                    sizes: SizeColumn::Off,
                    species_column: None,
                    wrap: false,
                    values_only: false,
                };
                let part = self.read_part(k, &plain, 0..1, &NoProgress)?;
                Ok(match part.species.first() {
                    Some(s) if s.numeric_type => SpeciesNaming::TypeNumbers {
                        first: s.name.clone(),
                    },
                    _ => SpeciesNaming::Given,
                })
            }
            // (A piece may hold no atoms: the first that tells.)
            Index::Pieces(p) => {
                for piece in p {
                    let naming = piece.species_naming(k, opts)?;
                    if naming != SpeciesNaming::Given {
                        return Ok(naming);
                    }
                }
                Ok(SpeciesNaming::Given)
            }
            Index::Xyz(_) | Index::Gsd(_) | Index::Raw(_) | Index::Mmpld(_) => {
                Ok(SpeciesNaming::Given)
            }
        }
    }

    /// The name frame `k`'s attribute gets when read with `opts` (`None`: no attribute),
    /// or the error reading it gives, such as a column the frame lacks. Reads the header
    /// only (binary formats: no particle at all).
    pub fn attribute_name(
        &self,
        k: usize,
        opts: &ReadOptions,
    ) -> Result<Option<String>, ReadError> {
        self.check_frame(k)?;
        if let Some((inner, _)) = self.magnitude_parts(k, opts)? {
            return Ok(Some(format!("|{inner}|")));
        }
        match &self.index {
            // A raw sidecar's attribute is read also when none is asked for.
            Index::Raw(_) => {}
            _ if opts.attribute.is_none() => return Ok(None),
            _ => {}
        }
        match &self.index {
            Index::Lammps(_) | Index::Xyz(_) => {
                let header = self.header(k)?;
                let (_, _, attribute, _, _) = text_columns(&self.ctx(), &header, opts)?;
                Ok(attribute.map(|c| header.info.columns[c].clone()))
            }
            // Every piece is read (each may lack it); the first's names it.
            Index::Pieces(p) => {
                let mut name = None;
                for (i, piece) in p.iter().enumerate() {
                    let n = piece.attribute_name(k, opts)?;
                    if i == 0 {
                        name = n;
                    }
                }
                Ok(name)
            }
            // (Each list of a frame may or may not carry it.)
            Index::Mmpld(i) => mmpld::attribute_name(&self.path, i, k, opts),
            Index::Raw(_) | Index::LammpsBinary(_) | Index::Gsd(_) => Ok(self
                .read_part(k, opts, 0..0, &NoProgress)?
                .attribute
                .map(|a| a.name)),
        }
    }

    /// Reads particles `range` (in file order) of frame `k` as a frame of their own, for
    /// dumps where [`DumpFile::reads_parts`] holds. Species are those the range uses, in
    /// the order the whole frame would list them.
    pub fn read_part(
        &self,
        k: usize,
        opts: &ReadOptions,
        range: Range<usize>,
        progress: &dyn Progress,
    ) -> Result<Frame, ReadError> {
        let mut frame = self.read_part_as_stored(k, opts, range, progress)?;
        if opts.wrap {
            wrap_into_cell(&mut frame);
        }
        Ok(frame)
    }

    /// [`Self::read_part`] without the wrapping into the cell.
    fn read_part_as_stored(
        &self,
        k: usize,
        opts: &ReadOptions,
        range: Range<usize>,
        progress: &dyn Progress,
    ) -> Result<Frame, ReadError> {
        self.check_frame(k)?;
        let total = self.frame_info(k)?.particles;
        if range.start > range.end || range.end > total {
            return Err(ReadError::Binary {
                path: self.path.clone(),
                offset: 0,
                message: format!(
                    "particles {}..{} requested of a frame of {total}",
                    range.start, range.end
                ),
            });
        }
        self.check_sizes(opts)?;
        self.check_species_column(opts)?;
        match &self.index {
            Index::Raw(r) => r.read_range(opts, range, progress),
            Index::LammpsBinary(i) => lammps_binary::read_range(
                &self.path,
                self.bytes(),
                i.header(&self.path, k)?,
                opts,
                range,
                progress,
            ),
            Index::Gsd(i) => gsd::read_range(&self.path, self.bytes(), i, k, opts, range, progress),
            Index::Mmpld(i) => {
                mmpld::read_range(&self.path, self.bytes(), i, k, opts, range, progress)
            }
            _ => Err(ReadError::Binary {
                path: self.path.clone(),
                offset: 0,
                message: "this format is read a whole frame at a time".into(),
            }),
        }
    }

    /// Whether frame `k` has the size and species columns `opts` names (a batch checks
    /// every frame before converting any, as it does the attribute): an error names a
    /// column the frame lacks, or an input that gives sizes or species by no column.
    pub fn check_named_columns(&self, k: usize, opts: &ReadOptions) -> Result<(), ReadError> {
        if opts.sizes.named_column().is_none() && opts.species_column.is_none() {
            return Ok(());
        }
        self.check_sizes(opts)?;
        self.check_species_column(opts)?;
        let info = self.frame_info(k)?;
        // (Columns named nowhere, as an old binary dump's without --columns, and empty
        // frames are judged where the frame is read.)
        if info.columns.is_empty() || info.particles == 0 {
            return Ok(());
        }
        let err = |message: String| ReadError::Binary {
            path: self.path.clone(),
            offset: 0,
            message: format!("frame {k}: {message}"),
        };
        if let Some(name) = opts.species_column.as_ref() {
            species_column_problem(name, &info.columns, [usize::MAX; 3]).map_err(err)?;
        }
        opts.sizes.resolve(&info.columns).map(|_| ()).map_err(err)
    }

    /// Refuses a size column named for an input that gives sizes by no column: GSD
    /// (`particles/diameter`), MMPLD (`xyzr` lists) and raw arrays (their sidecar's
    /// `radius` or `diameter` array).
    fn check_sizes(&self, opts: &ReadOptions) -> Result<(), ReadError> {
        let named = opts.sizes.named_column();
        let how = match &self.index {
            Index::Gsd(_) => "a GSD file gives each particle's size by `particles/diameter`",
            Index::Mmpld(_) => "an MMPLD file gives each particle's size in its `xyzr` lists",
            Index::Raw(_) => {
                "raw arrays give each particle's size by the sidecar's `radius` or `diameter` \
                 array"
            }
            _ => return Ok(()),
        };
        match named {
            Some(option) => Err(ReadError::Binary {
                path: self.path.clone(),
                offset: 0,
                message: format!(
                    "{option} names a column of a LAMMPS or XYZ dump; {how} (--no-sizes draws \
                     each species at one radius)"
                ),
            }),
            None => Ok(()),
        }
    }

    /// Refuses a species column named for an input whose species come by no column:
    /// GSD (`particles/typeid`), MMPLD (its lists) and raw arrays (the sidecar's
    /// `species` array).
    pub fn check_species_column(&self, opts: &ReadOptions) -> Result<(), ReadError> {
        let how = match &self.index {
            Index::Gsd(_) => "a GSD file gives each particle's type by `particles/typeid`",
            Index::Mmpld(_) => "an MMPLD file gives each particle's kind by its list",
            Index::Raw(_) => {
                "raw arrays give each particle's species by the sidecar's `species` array"
            }
            _ => return Ok(()),
        };
        match &opts.species_column {
            Some(name) => Err(ReadError::Binary {
                path: self.path.clone(),
                offset: 0,
                message: format!(
                    "--species-column {name} names a column of a LAMMPS or XYZ dump; {how}"
                ),
            }),
            None => Ok(()),
        }
    }

    /// True when [`read_text_windows`] can read this dump's frames a window of lines at a
    /// time (uncompressed LAMMPS text and XYZ files).
    pub fn reads_text_windows(&self) -> bool {
        matches!(self.index, Index::Lammps(_) | Index::Xyz(_)) && !self.compressed
    }

    /// Reads frame `k`.
    pub fn read_frame(
        &self,
        k: usize,
        opts: &ReadOptions,
        progress: &dyn Progress,
    ) -> Result<Frame, ReadError> {
        self.will_need(k);
        let mut frame = match self.magnitude_parts(k, opts)? {
            Some((inner, columns)) => self.read_magnitude(k, opts, &inner, &columns, progress)?,
            None => self.read_frame_as_stored(k, opts, progress)?,
        };
        if opts.wrap {
            wrap_into_cell(&mut frame);
        }
        Ok(frame)
    }

    /// For an attribute asked for as a magnitude (`|forces|`) of a LAMMPS or XYZ frame,
    /// its inside and the columns it is taken over; `None` for any other attribute and for
    /// GSD, whose reader takes a chunk's rows itself (and `%` sets, whose pieces each do).
    /// Raw arrays and MMPLD lists have no vectors: an error.
    fn magnitude_parts(
        &self,
        k: usize,
        opts: &ReadOptions,
    ) -> Result<Option<(String, Vec<String>)>, ReadError> {
        let Some(inner) = opts.attribute.as_deref().and_then(magnitude_of) else {
            return Ok(None);
        };
        let (columns, at) = match &self.index {
            Index::Gsd(_) | Index::Pieces(_) => return Ok(None),
            Index::Lammps(_) | Index::Xyz(_) => {
                let header = self.header(k)?;
                let at = self.ctx().at(header.columns_at);
                (header.info.columns, at)
            }
            Index::LammpsBinary(i) => (
                lammps_binary::column_names(&self.path, i, k, opts)?,
                Location {
                    path: self.path.clone(),
                    line: 0,
                },
            ),
            Index::Raw(_) | Index::Mmpld(_) => {
                return Err(ReadError::Unsupported {
                    at: Location {
                        path: self.path.clone(),
                        line: 0,
                    },
                    message: format!(
                        "a magnitude (--attribute |{inner}|) is taken over the columns of \
                         LAMMPS, XYZ and GSD inputs; this input has no vectors"
                    ),
                })
            }
        };
        let columns = magnitude_columns(inner, &columns)
            .map_err(|message| ReadError::Malformed { at, message })?;
        Ok(Some((inner.to_string(), columns)))
    }

    /// Frame `k` with the magnitude over `columns` as its attribute, named `|inner|`: the
    /// frame read with the first column, then each further column by a pass of its own.
    fn read_magnitude(
        &self,
        k: usize,
        opts: &ReadOptions,
        inner: &str,
        columns: &[String],
        progress: &dyn Progress,
    ) -> Result<Frame, ReadError> {
        let with = |c: &String| ReadOptions {
            wrap: false,
            ..opts.reading(c)
        };
        let mut frame = self.read_frame_as_stored(k, &with(&columns[0]), progress)?;
        let mut sums: Vec<f64> = frame
            .attribute
            .as_ref()
            .map(|a| {
                a.values
                    .iter()
                    .map(|&v| f64::from(v) * f64::from(v))
                    .collect()
            })
            .unwrap_or_default();
        for c in &columns[1..] {
            // (Its values only: a text dump's pass parses that one column.)
            let values = ReadOptions {
                values_only: true,
                ..with(c)
            };
            let other = self.read_frame_as_stored(k, &values, &NoProgress)?;
            if let Some(a) = other.attribute {
                for (s, v) in sums.iter_mut().zip(a.values) {
                    *s += f64::from(v) * f64::from(v);
                }
            }
        }
        frame.attribute = frame.attribute.map(|_| Attribute {
            name: format!("|{inner}|"),
            values: sums.iter().map(|s| s.sqrt() as f32).collect(),
        });
        Ok(frame)
    }

    /// [`Self::read_frame`] without the wrapping into the cell.
    fn read_frame_as_stored(
        &self,
        k: usize,
        opts: &ReadOptions,
        progress: &dyn Progress,
    ) -> Result<Frame, ReadError> {
        if let Index::Gsd(_) | Index::Mmpld(_) = &self.index {
            // The whole frame is its one part.
            let n = self.frame_info(k)?.particles;
            return self.read_part_as_stored(k, opts, 0..n, progress);
        }
        if let Index::Pieces(p) = &self.index {
            self.check_frame(k)?;
            // (Wrapped once, whole, by `read_frame`: not piece by piece too.)
            let stored = ReadOptions {
                wrap: false,
                ..opts.clone()
            };
            return pieces::read_frame(p, k, &stored, progress);
        }
        if let Index::Raw(r) = &self.index {
            self.check_frame(k)?;
            self.check_sizes(opts)?;
            self.check_species_column(opts)?;
            return r.read_frame(opts, progress);
        }
        if let Index::LammpsBinary(i) = &self.index {
            self.check_frame(k)?;
            return lammps_binary::read_frame(
                &self.path,
                self.bytes(),
                i.header(&self.path, k)?,
                opts,
                progress,
            );
        }
        let ctx = self.ctx();
        let header = self.header(k)?;
        let (coords, fractional, attribute, size, layout) = text_columns(&ctx, &header, opts)?;
        let columns = &header.info.columns;
        let atoms = atoms::parse(
            &ctx,
            header.atoms.clone(),
            header.info.particles,
            &layout,
            coords,
            fractional,
            attribute,
            size,
            opts.values_only,
            &format!("reading frame {k}"),
            progress,
        )
        .map_err(|e| categories_note(e, opts))?;
        let attribute = atoms.attribute.map(|values| Attribute {
            name: columns[attribute.unwrap_or_default()].clone(),
            values,
        });
        let info = header.info;
        Ok(Frame {
            positions: atoms.positions,
            species_index: atoms.species_index,
            species: atoms.species,
            attribute,
            radii: atoms.radii,
            simulation_box: info.simulation_box,
            timestep: info.timestep,
            time: info.time,
            units: info.units,
        })
    }
}

/// The coordinate columns (and whether they are scaled), the box to unscale them with,
/// and the attribute column of a text frame.
#[allow(clippy::type_complexity)]
fn text_columns<'h>(
    ctx: &Ctx<'_>,
    header: &'h Header,
    opts: &ReadOptions,
) -> Result<TextColumns<'h>, ReadError> {
    {
        let columns = &header.info.columns;
        // (Said rather than passed over: the names would change nothing.)
        if opts.columns.is_some() {
            return Err(ReadError::Malformed {
                at: ctx.at(header.columns_at),
                message: format!(
                    "a text dump names its own columns ({}); --columns is for old-revision \
                     binary dumps that name none: leave it out",
                    columns.join(" ")
                ),
            });
        }
        let (coords, scaled) = header
            .layout
            .coords
            .ok_or_else(|| ReadError::NoCoordinates {
                at: ctx.at(header.columns_at),
                columns: columns.join(" "),
            })?;
        let fractional = match (scaled, &header.info.simulation_box) {
            (false, _) => None,
            // A cell of no length along two edges puts every scaled coordinate on one line
            // (a box written as `0 0`): nothing a picture could show, so refused. One such
            // edge is a flat system's (a 2-D run's Lz of 0), drawn flat.
            (true, Some(b)) => match unscalable(b) {
                Some(message) => {
                    return Err(ReadError::Malformed {
                        at: ctx.at(header.columns_at),
                        message,
                    })
                }
                None => Some(b),
            },
            (true, None) => {
                return Err(ReadError::Malformed {
                    at: ctx.at(header.columns_at),
                    message: "scaled coordinates but no ITEM: BOX BOUNDS to unscale them".into(),
                })
            }
        };
        let attribute = match &opts.attribute {
            None => None,
            Some(name) => Some(columns.iter().position(|c| c == name).ok_or_else(|| {
                ReadError::UnknownAttribute {
                    at: ctx.at(header.columns_at),
                    name: name.clone(),
                    available: columns.join(" "),
                }
            })?),
        };
        let layout = species_layout(ctx, header, opts)?;
        let size = opts
            .sizes
            .resolve_beside(columns, coords, layout.species)
            .map_err(|message| ReadError::Malformed {
                at: ctx.at(header.columns_at),
                message,
            })?;
        let read = columns_read(coords, layout.species, attribute, size);
        // (Copies that agree are read from the first: LIGGGHTS's `id type type`.)
        if let Some((at, message)) = disagreeing_copies(ctx, header, read) {
            return Err(ReadError::Malformed {
                at: ctx.at(at),
                message,
            });
        }
        Ok((coords, fractional, attribute, size, layout))
    }
}

/// A number from a file as a message shows it: as written where that is short, else in
/// scientific notation (a box bound of 1e308 printed 309 digits, a denormal 50).
pub(crate) fn shown(v: f64) -> String {
    match v == 0.0 || (1e-5..1e16).contains(&v.abs()) || !v.is_finite() {
        true => v.to_string(),
        false => format!("{v:e}"),
    }
}

/// What is wrong with a triclinic LAMMPS box whose tilts reach past its `_bound` values,
/// given as the box's `lo` and `hi` they make: an edge of negative length, which the
/// tilts' own bounds would leave out (an orthogonal box's lower bound above its upper is
/// refused the same way; this one was converted, its cell inverted).
pub(crate) fn tilted_box_problem(lo: [f64; 3], hi: [f64; 3], tilts: [f64; 3]) -> Option<String> {
    let k = (0..2).find(|&k| lo[k].partial_cmp(&hi[k]).is_none_or(|o| o.is_gt()))?;
    Some(format!(
        "the tilts xy xz yz ({} {} {}) reach past the bounds: the box's {} edge runs from {} to \
         {} (the `_bound` values hold the tilted box, as LAMMPS writes them)",
        shown(tilts[0]),
        shown(tilts[1]),
        shown(tilts[2]),
        ["x", "y"][k],
        shown(lo[k]),
        shown(hi[k])
    ))
}

/// How many atom lines of a text frame [`disagreeing_copies`] compares.
pub(crate) const COPIES_SAMPLE: usize = 1000;

/// The columns of `read` (indices into the frame's columns) that the text frame's header
/// names more than once, each with every place it is named (0-based).
fn copied_columns(header: &Header, read: impl IntoIterator<Item = usize>) -> Vec<Vec<usize>> {
    let columns = &header.info.columns;
    let mut copies: Vec<Vec<usize>> = Vec::new();
    for c in read {
        let Some(name) = columns.get(c) else { continue };
        let at: Vec<usize> = (0..columns.len())
            .filter(|&i| columns[i] == *name)
            .collect();
        if at.len() > 1 && !copies.contains(&at) {
            copies.push(at);
        }
    }
    copies
}

/// Of the columns `read` that a text frame names more than once (LIGGGHTS writes `id
/// type type ...` in its examples), the first whose copies differ in the frame's first
/// [`COPIES_SAMPLE`] atom lines, said with the line where they do and how to rename one;
/// copies that agree there are read from the first.
fn disagreeing_copies(
    ctx: &Ctx<'_>,
    header: &Header,
    read: impl IntoIterator<Item = usize>,
) -> Option<(usize, String)> {
    let copies = copied_columns(header, read);
    if copies.is_empty() {
        return None;
    }
    let columns = &header.info.columns;
    let value = |t: &[u8]| std::str::from_utf8(t).ok()?.parse::<f64>().ok();
    let same =
        |a: &[u8], b: &[u8]| a == b || matches!((value(a), value(b)), (Some(x), Some(y)) if x == y);
    let end = header.atoms.end.min(ctx.data.len());
    let mut lines = Cursor::new(&ctx.data[..end], header.atoms.start);
    let mut seen = 0;
    while seen < COPIES_SAMPLE {
        let Some((at, line)) = lines.next_line() else {
            break;
        };
        let tokens: Vec<&[u8]> = fields(line).collect();
        if tokens.is_empty() {
            continue;
        }
        seen += 1;
        for at_columns in &copies {
            let first = tokens.get(at_columns[0]).copied();
            let other = at_columns[1..]
                .iter()
                .find(|&&c| match (first, tokens.get(c)) {
                    (Some(a), Some(b)) => !same(a, b),
                    _ => false,
                });
            if let (Some(a), Some(&c)) = (first, other) {
                let name = &columns[at_columns[0]];
                let renamed: Vec<String> = columns
                    .iter()
                    .enumerate()
                    .map(|(i, n)| match at_columns.iter().position(|&k| k == i) {
                        Some(k) if k > 0 => format!("{n}_{}", k + 1),
                        _ => n.clone(),
                    })
                    .collect();
                return Some((
                    at,
                    format!(
                        "column `{name}` is named {} times (columns {}), and they differ here \
                         (`{}` in column {}, `{}` in column {}): which one holds the data \
                         cannot be told; rename the others (`sed -i 's/^ITEM: ATOMS .*/ITEM: \
                         ATOMS {}/' {}`)",
                        at_columns.len(),
                        at_columns
                            .iter()
                            .map(|i| (i + 1).to_string())
                            .collect::<Vec<_>>()
                            .join(" and "),
                        String::from_utf8_lossy(a),
                        at_columns[0] + 1,
                        String::from_utf8_lossy(tokens[c]),
                        c + 1,
                        renamed.join(" "),
                        ctx.path.display()
                    ),
                ));
            }
        }
    }
    None
}

/// The note for a text frame whose columns read name a column more than once, their
/// copies agreeing ([`disagreeing_copies`]): the first is read.
pub(crate) fn copies_read_note(
    header: &Header,
    read: impl IntoIterator<Item = usize>,
) -> Option<String> {
    let columns = &header.info.columns;
    let said: Vec<String> = copied_columns(header, read)
        .iter()
        .map(|at| {
            format!(
                "`{}` (columns {})",
                columns[at[0]],
                at.iter()
                    .map(|i| (i + 1).to_string())
                    .collect::<Vec<_>>()
                    .join(" and ")
            )
        })
        .collect();
    let atoms = match header.info.particles {
        n if n <= COPIES_SAMPLE => format!("all {n} atoms"),
        _ => format!("the first {COPIES_SAMPLE} atoms"),
    };
    (!said.is_empty()).then(|| {
        format!(
            "names {} more than once (as LIGGGHTS writes `id type type`): the copies agree in \
             {atoms}, and the first is read",
            said.join(", ")
        )
    })
}

/// Of the columns `read` (indices into `columns`), the first that `columns` names more
/// than once (`x y z x`), said: which of them holds the data cannot be told, so neither
/// is taken (LAMMPS text and binary dumps alike).
pub(crate) fn named_twice(
    columns: &[String],
    read: impl IntoIterator<Item = usize>,
) -> Option<String> {
    read.into_iter().find_map(|c| {
        let name = columns.get(c)?;
        let at: Vec<String> = (0..columns.len())
            .filter(|&i| columns[i] == *name)
            .map(|i| (i + 1).to_string())
            .collect();
        (at.len() > 1).then(|| {
            format!(
                "column `{name}` is named {} times (columns {}): which one holds the data \
                 cannot be told",
                at.len(),
                at.join(" and ")
            )
        })
    })
}

/// Refuses scaled coordinates in `cell` where two or more of its edges have no length
/// (every particle on one line; one such edge is a flat system's, drawn flat).
pub(crate) fn unscalable(cell: &SimulationBox) -> Option<String> {
    let zero = zero_edges(cell);
    (zero.len() >= 2).then(|| {
        let names = ["a (x)", "b (y)", "c (z)"];
        let axes: Vec<&str> = zero.iter().map(|&k| names[k]).collect();
        format!(
            "scaled coordinates, but the box has no length along its edges {}: they cannot be \
             unscaled (is the box right?)",
            axes.join(" and ")
        )
    })
}

/// The edges of `cell` of no length (or not a number): 0 for `a`, 1 for `b`, 2 for `c`.
pub(crate) fn zero_edges(cell: &SimulationBox) -> Vec<usize> {
    [cell.a, cell.b, cell.c]
        .iter()
        .enumerate()
        .filter(|(_, v)| {
            let length2: f64 = v.iter().map(|x| x * x).sum();
            length2.is_nan() || length2 <= 0.0
        })
        .map(|(k, _)| k)
        .collect()
}

/// A species column of more distinct values than a file holds species is no column of
/// categories: the error says what the option takes.
fn categories_note(e: ReadError, opts: &ReadOptions) -> ReadError {
    match (e, &opts.species_column) {
        (ReadError::TooManySpecies { at }, Some(name)) => ReadError::Malformed {
            at,
            message: too_many_categories(name),
        },
        (e, _) => e,
    }
}

/// What every reader says of a `--species-column` of more values than species fit.
pub(crate) fn too_many_categories(name: &str) -> String {
    format!(
        "more than 65536 distinct values in --species-column {name}: it takes a column of \
         categories (a structure type, a molecule kind); a continuous quantity goes in \
         --attribute"
    )
}

/// The index of the column `--species-column` names among `columns`, or what every
/// reader says of one the frame lacks or of a coordinate's.
pub(crate) fn species_column_problem(
    name: &str,
    columns: &[String],
    coords: [usize; 3],
) -> Result<usize, String> {
    match columns.iter().position(|c| c == name) {
        None => Err(format!(
            "no column `{name}` for --species-column; the columns are {}",
            columns.join(" ")
        )),
        Some(c) if coords.contains(&c) => Err(format!(
            "--species-column {name}: `{name}` holds the positions"
        )),
        Some(c) => Ok(c),
    }
}

/// The layout of a text frame's atom lines with the species taken from the column
/// [`ReadOptions::species_column`] names, where it names one: its values are species
/// names, sorted as numbers and coloured as type numbers where they all are integers.
fn species_layout(
    ctx: &Ctx<'_>,
    header: &Header,
    opts: &ReadOptions,
) -> Result<atoms::AtomLayout, ReadError> {
    let mut layout = header.layout.clone();
    let Some(name) = &opts.species_column else {
        return Ok(layout);
    };
    let columns = &header.info.columns;
    // (Without coordinates the frame is refused where they are looked for.)
    let coords = layout.coords.map_or([usize::MAX; 3], |(xyz, _)| xyz);
    let c =
        species_column_problem(name, columns, coords).map_err(|message| ReadError::Malformed {
            at: ctx.at(header.columns_at),
            message,
        })?;
    // Each atom keeps its element's size where the dump names elements (a LAMMPS
    // dump's `element` column, an XYZ file's species); with --no-sizes each category
    // takes its atoms' mean.
    layout.element_sizes = header
        .layout
        .species
        .filter(|&e| {
            columns[e] == "element"
                || (header.layout.type_numbers && columns[e].eq_ignore_ascii_case("species"))
        })
        .map(|e| (e, opts.sizes != SizeColumn::Off));
    layout.species = Some(c);
    layout.numeric_species = true;
    layout.type_numbers = false;
    layout.categories = true;
    Ok(layout)
}

/// What [`text_columns`] finds: the coordinate columns, the box that unscales them
/// (scaled coordinates), the attribute's column, the size column with its factor, and
/// the layout the atom lines are read with (the species column [`species_layout`] gives).
/// The columns a text frame's atoms are read from: the coordinates, then those of the
/// species, the attribute and the size where read.
fn columns_read(
    coords: [usize; 3],
    species: Option<usize>,
    attribute: Option<usize>,
    size: Option<(usize, f64)>,
) -> impl Iterator<Item = usize> {
    coords
        .into_iter()
        .chain(species)
        .chain(attribute)
        .chain(size.map(|(c, _)| c))
}

type TextColumns<'h> = (
    [usize; 3],
    Option<&'h SimulationBox>,
    Option<usize>,
    Option<(usize, f64)>,
    atoms::AtomLayout,
);

/// Reads frame `k` of the uncompressed text dump `path` (LAMMPS or XYZ) a window of at
/// most `window` atom lines at a time, calling `f` with each window's first atom index and
/// its atoms as a frame of their own (their own species list). The file is mapped afresh
/// for every window, so the pages already parsed are released and resident memory stays
/// bounded whatever the frame's size. Errors name the file and line as whole-frame
/// reading does. `header`, when given, is frame `k`'s header from a [`DumpFile`] of the
/// same uncompressed file, which then is not indexed again (a whole pass over it).
pub(crate) fn read_text_windows<E: From<ReadError>>(
    path: &Path,
    k: usize,
    header: Option<Header>,
    opts: &ReadOptions,
    window: usize,
    mut f: impl FnMut(usize, Frame) -> Result<(), E>,
) -> Result<(), E> {
    let (header, compressed) = match header {
        Some(h) => (h, false),
        None => {
            let dump = DumpFile::open(path)?;
            (dump.header(k)?, dump.compressed)
        }
    };
    if compressed {
        return Err(ReadError::Unsupported {
            at: Location {
                path: path.to_path_buf(),
                line: 1,
            },
            message: "compressed dumps are read whole, not in windows".into(),
        }
        .into());
    }
    let io = |source| ReadError::Io {
        path: path.to_path_buf(),
        source,
    };
    let file = File::open(path).map_err(io)?;
    let total = header.info.particles;
    let mut pos = header.atoms.start;
    let mut first = 0usize;
    let window = window.max(1);
    // The file's length when the first window is mapped: every window must find at
    // least that much, the frame's atoms inside it (a simulation still running may
    // append frames; a file cut short or replaced by a shorter one is an error).
    let mut length: Option<usize> = None;
    while first < total {
        let map = mdlod_format::mmap::map_file(&file).map_err(io)?;
        let data: &[u8] = &map;
        let ctx = Ctx { path, data };
        if *length.get_or_insert(data.len()) > data.len() || header.atoms.end > data.len() {
            return Err(ctx
                .malformed(
                    pos,
                    format!(
                        "the file changed size while frame {k} was being read ({} bytes now)",
                        data.len()
                    ),
                )
                .into());
        }
        let (coords, fractional, attribute, size, layout) = text_columns(&ctx, &header, opts)?;
        let want = window.min(total - first);
        let end_limit = header.atoms.end;
        // The end of the `want`-th line from `pos` (or the block's end).
        let end = memchr::memchr_iter(b'\n', &data[pos..end_limit])
            .nth(want - 1)
            .map_or(end_limit, |i| pos + i + 1);
        // Past the last announced atom only blank space may be left of the frame, as
        // whole-frame reading requires (the first extra line is named).
        if first + want == total && !data[end..end_limit].iter().all(u8::is_ascii_whitespace) {
            return Err(ReadError::ExtraLines {
                at: ctx.at(end),
                expected: total,
            }
            .into());
        }
        let atoms = atoms::parse(
            &ctx,
            pos..end,
            want,
            &layout,
            coords,
            fractional,
            attribute,
            size,
            opts.values_only,
            &format!("reading frame {k}"),
            &NoProgress,
        )
        // The window's counts, told as the frame's (what the header announced).
        .map_err(|e| match categories_note(e, opts) {
            ReadError::Truncated { at, found, .. } => ReadError::Truncated {
                at,
                expected: total,
                found: first + found,
            },
            ReadError::ExtraLines { at, .. } => ReadError::ExtraLines {
                at,
                expected: total,
            },
            other => other,
        })?;
        let attribute = atoms.attribute.map(|values| Attribute {
            name: header.info.columns[attribute.unwrap_or_default()].clone(),
            values,
        });
        let mut part = Frame {
            positions: atoms.positions,
            species_index: atoms.species_index,
            species: atoms.species,
            attribute,
            radii: atoms.radii,
            simulation_box: header.info.simulation_box.clone(),
            timestep: header.info.timestep,
            time: header.info.time,
            units: header.info.units.clone(),
        };
        if opts.wrap {
            wrap_into_cell(&mut part);
        }
        f(first, part)?;
        pos = end;
        first += want;
    }
    Ok(())
}

impl DumpFile {
    fn ctx(&self) -> Ctx<'_> {
        Ctx {
            path: &self.path,
            data: self.bytes(),
        }
    }

    pub(crate) fn header(&self, k: usize) -> Result<Header, ReadError> {
        self.check_frame(k)?;
        let ctx = self.ctx();
        let header = match &self.index {
            Index::Lammps(i) => i.header(&ctx, k),
            Index::Xyz(i) => i.header(&ctx, k),
            Index::LammpsBinary(_)
            | Index::Gsd(_)
            | Index::Pieces(_)
            | Index::Raw(_)
            | Index::Mmpld(_) => Err(ReadError::Binary {
                path: self.path.clone(),
                offset: 0,
                message: "internal error: text header of a binary dump".into(),
            }),
        }?;
        // An atom line holds at least one character and a separator per column: a count
        // the frame's bytes cannot hold is a frame cut short (or a header that lies),
        // said here, before a conversion plans its memory for that many particles.
        let atoms = &ctx.data[header.atoms.clone()];
        let room = atoms.len() / (2 * header.layout.columns.len().max(1)) + 1;
        if header.info.particles > room {
            let lines = memchr::memchr_iter(b'\n', atoms).count()
                + usize::from(atoms.last().is_some_and(|&b| b != b'\n'));
            // Every line there, but shorter than the columns the header names: lines of
            // fewer columns (damage no rerun mends), not a frame cut short.
            if lines >= header.info.particles {
                let columns = header.layout.columns.len();
                let mut at = header.atoms.start;
                for line in atoms.split(|&b| b == b'\n').take(header.info.particles) {
                    let tokens = line
                        .split(|b| b.is_ascii_whitespace())
                        .filter(|t| !t.is_empty())
                        .count();
                    if tokens != columns {
                        return Err(ReadError::ColumnCount {
                            at: ctx.at(at),
                            expected: columns,
                            found: tokens,
                        });
                    }
                    at += line.len() + 1;
                }
            }
            // At the last atom line, as the reading's own check says.
            let last = header.atoms.end.saturating_sub(1).max(header.atoms.start);
            return Err(ReadError::Truncated {
                at: ctx.at(last),
                expected: header.info.particles,
                found: lines,
            });
        }
        Ok(header)
    }
}

/// Particles per parallel task of a checked decoding pass. The first bad value is
/// searched block by block: rayon's `find_first` and `position_first` check a shared
/// flag before every item, which costs more than decoding one.
pub(crate) const SCAN_BLOCK: usize = 1 << 14;

/// The first `i < n` for which `bad(i)` holds, searched on every core a block at a time.
pub(crate) fn first_index(n: usize, bad: impl Fn(usize) -> bool + Sync) -> Option<usize> {
    use rayon::prelude::*;
    (0..n.div_ceil(SCAN_BLOCK))
        .into_par_iter()
        .find_map_first(|b| (b * SCAN_BLOCK..((b + 1) * SCAN_BLOCK).min(n)).find(|&i| bad(i)))
}

/// What follows "is not finite" in an error about the value `v` read from a file: nothing
/// for NaN and infinities, the value for a finite one past the single-precision range
/// (which the conversion to `f32` would make infinite).
pub(crate) fn single_precision_note(v: f64) -> String {
    if v.is_finite() {
        format!(" in single precision ({v:e} is beyond ±3.4e38)")
    } else {
        String::new()
    }
}

/// Decodes `n` positions in parallel: coordinate `k` of particle `i` is `value(at(i, k))`.
/// On a value that is not finite as an `f32` (NaN, infinite, or past the single-precision
/// range), the `at` index and the value of the first one (in particle order).
pub(crate) fn decode_positions(
    n: usize,
    at: impl Fn(usize, usize) -> usize + Sync,
    value: impl Fn(usize) -> f64 + Sync,
) -> Result<Vec<[f32; 3]>, (usize, f64)> {
    use rayon::prelude::*;
    let mut positions = vec![[0f32; 3]; n];
    let bad = positions
        .par_chunks_mut(SCAN_BLOCK)
        .enumerate()
        .find_map_first(|(b, block)| {
            for (o, p) in block.iter_mut().enumerate() {
                let i = b * SCAN_BLOCK + o;
                for k in 0..3 {
                    let j = at(i, k);
                    let v = value(j);
                    let single = v as f32;
                    if !single.is_finite() {
                        return Some((j, v));
                    }
                    p[k] = single;
                }
            }
            None
        });
    match bad {
        Some(bad) => Err(bad),
        None => Ok(positions),
    }
}

/// The file being read, for building errors with line numbers.
pub(crate) struct Ctx<'a> {
    pub path: &'a Path,
    pub data: &'a [u8],
}

impl Ctx<'_> {
    /// The location of byte `offset`: its 1-based line number, by counting newlines. The end
    /// of a file that ends with a newline counts as its last line.
    pub fn at(&self, offset: usize) -> Location {
        let mut offset = offset.min(self.data.len());
        if offset == self.data.len() && self.data.ends_with(b"\n") {
            offset -= 1;
        }
        let line = memchr::memchr_iter(b'\n', &self.data[..offset]).count() as u64 + 1;
        Location {
            path: self.path.to_path_buf(),
            line,
        }
    }

    pub fn malformed(&self, offset: usize, message: impl Into<String>) -> ReadError {
        ReadError::Malformed {
            at: self.at(offset),
            message: message.into(),
        }
    }
}

/// Reads lines (without `\n`, with any `\r` left for [`trim`]) from a byte offset.
pub(crate) struct Cursor<'a> {
    data: &'a [u8],
    pub pos: usize,
}

impl<'a> Cursor<'a> {
    pub fn new(data: &'a [u8], pos: usize) -> Self {
        Cursor { data, pos }
    }

    /// The next line and its start offset, or `None` at the end.
    pub fn next_line(&mut self) -> Option<(usize, &'a [u8])> {
        if self.pos >= self.data.len() {
            return None;
        }
        let start = self.pos;
        match memchr::memchr(b'\n', &self.data[start..]) {
            Some(p) => {
                self.pos = start + p + 1;
                Some((start, &self.data[start..start + p]))
            }
            None => {
                self.pos = self.data.len();
                Some((start, &self.data[start..]))
            }
        }
    }
}

/// `s` without leading and trailing ASCII whitespace (including `\r`).
pub(crate) fn trim(s: &[u8]) -> &[u8] {
    s.trim_ascii()
}

/// Whitespace-separated fields of a line.
pub(crate) fn fields(line: &[u8]) -> impl Iterator<Item = &[u8]> {
    line.split(|b| b.is_ascii_whitespace())
        .filter(|t| !t.is_empty())
}

pub(crate) fn parse_int<T: std::str::FromStr>(s: &[u8]) -> Option<T> {
    std::str::from_utf8(trim(s)).ok()?.parse().ok()
}

/// A line for an error message: lossy UTF-8, trimmed, at most 60 characters.
/// What a file of a format mdlod does not read is, told from its name or first bytes
/// (an ASE trajectory, a CIF, a POSCAR, ...): `None` for anything else.
fn foreign_format(path: &Path, data: &[u8]) -> Option<&'static str> {
    let head = &data[..data.len().min(256)];
    let has = |needle: &[u8]| head.windows(needle.len()).any(|w| w == needle);
    if has(b"UlmASE-Trajectory") {
        return Some("an ASE trajectory (.traj)");
    }
    let name = path.file_name()?.to_str()?.to_ascii_lowercase();
    let ext = name.rsplit_once('.').map_or("", |(_, e)| e);
    Some(match ext {
        "cif" => "a CIF crystal file",
        "pdb" | "ent" => "a PDB file",
        "gro" => "a GROMACS .gro file",
        "xtc" | "trr" => "a GROMACS trajectory",
        "dcd" => "a DCD trajectory",
        "xsf" | "axsf" => "an XCrySDen .xsf file",
        "h5" | "h5md" | "hdf5" => "an HDF5 file (H5MD?)",
        "nc" | "netcdf" => "a NetCDF file (AMBER or LAMMPS netcdf dump?)",
        "vasp" => "a VASP structure file",
        _ if name.starts_with("poscar") || name.starts_with("contcar") || name == "xdatcar" => {
            "a VASP structure file"
        }
        _ => return None,
    })
}

pub(crate) fn shorten(line: &[u8]) -> String {
    // Control characters and bytes that are no UTF-8 (a binary file's, a damaged byte
    // in a number) as `\xNN`, a byte each, so that a token that reads wrong does not
    // look right. At most 60 characters or escapes are shown (a binary file's first
    // "line" may be the whole file).
    const SHOWN: usize = 60;
    let mut s = String::new();
    let mut shown = 0usize;
    'chunks: for chunk in trim(line).utf8_chunks() {
        let valid = chunk.valid().chars().map(Ok);
        let invalid = chunk.invalid().iter().map(|&b| Err(b));
        for c in valid.chain(invalid) {
            if shown == SHOWN {
                s.push_str("...");
                break 'chunks;
            }
            shown += 1;
            match c {
                Ok(c) if c.is_control() && c != '\t' => {
                    for b in c.encode_utf8(&mut [0; 4]).bytes() {
                        s.push_str(&format!("\\x{b:02X}"));
                    }
                }
                Ok(c) => s.push(c),
                Err(b) => s.push_str(&format!("\\x{b:02X}")),
            }
        }
    }
    s
}

/// The offset just after the `n`-th newline from `pos`, or `data.len()` when there are fewer.
/// Counts newlines a block at a time (vectorised), so skipping is several GB/s.
pub(crate) fn skip_lines(data: &[u8], pos: usize, n: usize) -> usize {
    skip_lines_left(data, pos, n).0
}

/// [`skip_lines`], and how many of the `n` newlines the data did not hold (a last line
/// without its newline counts among them).
pub(crate) fn skip_lines_left(data: &[u8], mut pos: usize, mut n: usize) -> (usize, usize) {
    const BLOCK: usize = 1 << 16;
    while n > 0 && pos < data.len() {
        let end = (pos + BLOCK).min(data.len());
        let block = &data[pos..end];
        let count = memchr::memchr_iter(b'\n', block).count();
        if count < n {
            n -= count;
            pos = end;
            continue;
        }
        for p in memchr::memchr_iter(b'\n', block) {
            n -= 1;
            if n == 0 {
                return (pos + p + 1, 0);
            }
        }
    }
    if n == 0 {
        (pos, 0)
    } else {
        (data.len(), n)
    }
}

/// Bytes of a large uncompressed file scanned through one mapping while indexing it: each
/// segment gets a fresh mapping, dropped after it, so that the pages read leave this
/// process's resident memory (they stay in the page cache). Indexed through the one
/// mapping a reader keeps, a 9 GB dump counted 9 GB of resident memory.
pub(crate) const SCAN_SEGMENT: usize = 256 << 20;

/// [`skip_lines`] over `ctx.data`, read through fresh mappings of `file` (the file
/// `ctx.data` maps) a `segment` of bytes at a time.
pub(crate) fn skip_lines_mapped(
    ctx: &Ctx<'_>,
    file: &File,
    mut pos: usize,
    mut n: usize,
    segment: usize,
    reached: &Reached<'_>,
) -> Result<(usize, usize), ReadError> {
    let len = ctx.data.len();
    while n > 0 && pos < len {
        let map = mapped_again(ctx, file, pos)?;
        let end = (pos + segment.max(1)).min(len);
        let count = memchr::memchr_iter(b'\n', &map[pos..end]).count();
        if count >= n {
            return Ok(skip_lines_left(&map[..end], pos, n));
        }
        n -= count;
        pos = end;
        reached.at(pos);
    }
    Ok(if n == 0 { (pos, 0) } else { (len, n) })
}

/// The progress of a scan through a file: advances a stage's bar (counted in bytes) to
/// each offset the scan reaches.
pub(crate) struct Reached<'a> {
    progress: &'a dyn Progress,
    done: std::cell::Cell<usize>,
}

impl<'a> Reached<'a> {
    pub(crate) fn new(progress: &'a dyn Progress) -> Self {
        Reached {
            progress,
            done: std::cell::Cell::new(0),
        }
    }

    /// The scan has reached byte `pos` (offsets before the furthest reached add nothing).
    pub(crate) fn at(&self, pos: usize) {
        let done = self.done.get();
        if pos > done {
            self.progress.advance((pos - done) as u64);
            self.done.set(pos);
        }
    }
}

/// Indexes `text` (written to a file, `ctx.path`) whole, then in segments of every size
/// from 1 byte up, so that each line straddles a segment's end in every way: each
/// segmented index must equal the whole one, and the bar move at most a segment plus
/// `slack` bytes at a time. Returns the whole index.
#[cfg(test)]
pub(crate) fn check_segmented_index<I: PartialEq + std::fmt::Debug>(
    ctx: &Ctx<'_>,
    slack: usize,
    build: impl Fn(&Ctx<'_>, Option<&File>, usize, &Reached<'_>) -> Result<I, ReadError>,
) -> I {
    let whole = build(ctx, None, usize::MAX, &Reached::new(&crate::NoProgress)).unwrap();
    let file = File::open(ctx.path).unwrap();
    let len = ctx.data.len();
    for segment in 1..=len {
        let steps = Steps::default();
        let reached = Reached::new(&steps);
        let segmented = build(ctx, Some(&file), segment, &reached).unwrap();
        assert_eq!(segmented, whole, "segment of {segment} bytes");
        steps.check(&reached, len, segment, segment + slack);
    }
    whole
}

/// The steps a scan advanced its bar by (tests).
#[cfg(test)]
#[derive(Default)]
pub(crate) struct Steps(std::sync::Mutex<Vec<u64>>);

#[cfg(test)]
impl Steps {
    /// Checks that a scan of `len` bytes in segments of `segment` moved the bar by at
    /// most `max_step` at a time and, with `Reached::at(len)` at its end, to `len`.
    pub(crate) fn check(&self, reached: &Reached<'_>, len: usize, segment: usize, max_step: usize) {
        let before: u64 = self.0.lock().unwrap().iter().sum();
        assert!(before <= len as u64, "segment of {segment} bytes");
        reached.at(len);
        let steps = self.0.lock().unwrap();
        assert_eq!(steps.iter().sum::<u64>(), len as u64);
        assert!(
            steps.iter().all(|&s| s as usize <= max_step),
            "segment of {segment} bytes: steps {steps:?}"
        );
    }
}

#[cfg(test)]
impl Progress for Steps {
    fn stage(&self, _name: &str, _total: Option<u64>, _unit: &'static str) {}
    fn advance(&self, amount: u64) {
        self.0.lock().unwrap().push(amount);
    }
}

/// A fresh mapping of `file`, which must still be as long as `ctx.data` (`at`: where the
/// reader is, for the error).
pub(crate) fn mapped_again(
    ctx: &Ctx<'_>,
    file: &File,
    at: usize,
) -> Result<mdlod_format::mmap::Mmap, ReadError> {
    let map = mdlod_format::mmap::map_file(file).map_err(|source| ReadError::Io {
        path: ctx.path.to_path_buf(),
        source,
    })?;
    if map.len() != ctx.data.len() {
        return Err(ctx.malformed(at, "the file changed size while it was being indexed"));
    }
    Ok(map)
}

/// The format of the file `path` as its name tells, else as its first bytes tell the
/// binary formats (GSD, MMPLD, LAMMPS binary); `None` when neither does. For messages:
/// nothing is indexed.
pub fn format_of_file(path: &Path) -> Option<InputFormat> {
    if let Some(f) = InputFormat::from_path(path) {
        return Some(f);
    }
    let mut head = Vec::with_capacity(64);
    mdlod_format::files::open(path)
        .ok()?
        .take(64)
        .read_to_end(&mut head)
        .ok()?;
    if gsd::sniff(&head) {
        Some(InputFormat::Gsd)
    } else if mmpld::sniff(&head) {
        Some(InputFormat::Mmpld)
    } else {
        None
    }
}

/// True when `path` names a `%` piece set (a file name with `%` that is no file itself).
pub fn is_piece_pattern(path: &Path) -> bool {
    path.file_name()
        .and_then(|n| n.to_str())
        .is_some_and(|n| n.contains('%'))
        && !path.exists()
}

/// The compression other than gzip that `data` starts with the signature of, where it
/// does: zstd, bzip2, xz, lz4 (frame format) or zip; or `tar` for a tar archive (its
/// `ustar` mark at byte 257).
fn other_compression(data: &[u8]) -> Option<&'static str> {
    if data.starts_with(&[0x28, 0xb5, 0x2f, 0xfd]) {
        Some("zstd")
    } else if is_bzip2(data) {
        Some("bzip2")
    } else if data.starts_with(&[0xfd, b'7', b'z', b'X', b'Z', 0x00]) {
        Some("xz")
    } else if data.starts_with(&[0x04, 0x22, 0x4d, 0x18]) {
        Some("lz4")
    } else if data.starts_with(b"PK\x03\x04") {
        Some("zip")
    } else if data.get(257..262) == Some(b"ustar") {
        Some("tar")
    } else {
        None
    }
}

fn is_bzip2(data: &[u8]) -> bool {
    data.len() >= 10
        && data.starts_with(b"BZh")
        && (b'1'..=b'9').contains(&data[3])
        && data[4..10] == [0x31, 0x41, 0x59, 0x26, 0x53, 0x59]
}

/// True when `path` starts with the gzip magic bytes.
pub fn is_gzip(path: &Path) -> Result<bool, ReadError> {
    let mut magic = [0u8; 2];
    let mut f = mdlod_format::files::open(path).map_err(|source| ReadError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let n = f.read(&mut magic).map_err(|source| ReadError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    Ok(n == 2 && magic == [0x1f, 0x8b])
}

/// Whether `path` plainly holds no dump: a file of text whose first line is neither a
/// LAMMPS `ITEM:` nor an XYZ count (a run's log, notes) and of no binary format. A file
/// that cannot be read, is empty, compressed or binary is not plainly so. The newest
/// input of a set is told among the others.
pub fn plainly_no_dump(path: &Path) -> bool {
    let Ok(file) = mdlod_format::files::open(path) else {
        return false;
    };
    let mut head = Vec::with_capacity(4096);
    if file.take(4096).read_to_end(&mut head).is_err() || head.is_empty() {
        return false;
    }
    let compressed = head.starts_with(&[0x1f, 0x8b])
        || head.starts_with(b"BZh")
        || head.starts_with(&[0x28, 0xb5, 0x2f, 0xfd]);
    let binary = head.contains(&0)
        || gsd::sniff(&head)
        || mmpld::sniff(&head)
        || lammps_binary::sniff(&head)
        || raw::sniff(&head)
        || InputFormat::from_path(path) == Some(InputFormat::Raw)
        || head.trim_ascii_start().starts_with(b"{");
    !compressed && !binary && head.contains(&b'\n') && InputFormat::sniff(&head).is_none()
}

/// True for a gzip file whose compressed stream ends before any text (a run has just
/// opened it and written the gzip header, or a few bytes more): as good as empty.
pub fn gzip_without_text(path: &Path) -> bool {
    if !is_gzip(path).unwrap_or(false) {
        return false;
    }
    let Ok(file) = mdlod_format::files::open(path) else {
        return false;
    };
    let mut byte = [0u8; 1];
    match flate2::read::MultiGzDecoder::new(file).read(&mut byte) {
        Ok(n) => n == 0,
        Err(e) => ends_early(&e),
    }
}

/// Decompresses the gzip file `path` (single or multi-member) into the file `out` as a
/// stream, holding a buffer's worth at a time; returns the decompressed size, and whether
/// the compressed stream ended early (a run still writing it: what precedes the cut is
/// kept). Errors name `path` (decompression) or `out` (writing).
pub fn gunzip_to_file(
    path: &Path,
    out: &Path,
    progress: &dyn Progress,
) -> Result<(u64, bool), ReadError> {
    let input = mdlod_format::files::open(path).map_err(|source| ReadError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let total = input.metadata().map(|m| m.len()).ok();
    struct Counting<'p> {
        inner: File,
        progress: &'p dyn Progress,
    }
    impl Read for Counting<'_> {
        fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
            let n = self.inner.read(buf)?;
            self.progress.advance(n as u64);
            Ok(n)
        }
    }
    progress.stage("decompressing", total, "bytes");
    let mut decoder = flate2::read::MultiGzDecoder::new(std::io::BufReader::with_capacity(
        1 << 20,
        Counting {
            inner: input,
            progress,
        },
    ));
    let file = File::create(out).map_err(|source| ReadError::Io {
        path: out.to_path_buf(),
        source,
    })?;
    let mut writer = std::io::BufWriter::with_capacity(1 << 20, file);
    let mut buf = vec![0u8; 1 << 20];
    let mut written = 0u64;
    let mut cut = false;
    loop {
        let n = match decoder.read(&mut buf) {
            Ok(n) => n,
            Err(e) if ends_early(&e) && written > 0 => {
                cut = true;
                0
            }
            Err(e) => return Err(gzip_error(path, e)),
        };
        if n == 0 {
            break;
        }
        std::io::Write::write_all(&mut writer, &buf[..n]).map_err(|source| ReadError::Io {
            path: out.to_path_buf(),
            source,
        })?;
        written += n as u64;
    }
    std::io::Write::flush(&mut writer).map_err(|source| ReadError::Io {
        path: out.to_path_buf(),
        source,
    })?;
    progress.finish_stage();
    Ok((written, cut))
}

/// The first 4 bytes of `b` (at least 4 long).
fn le4(b: &[u8]) -> [u8; 4] {
    [b[0], b[1], b[2], b[3]]
}

/// A compressed stream that ends before its end (no more input inside a block, or no
/// trailer): what was decompressed before it is sound.
fn ends_early(e: &std::io::Error) -> bool {
    e.kind() == std::io::ErrorKind::UnexpectedEof
}

/// A failed decompression of `path`: a stream that ends early (a file cut short, as a
/// copy or a job killed while compressing leaves it) says how to keep what precedes the
/// cut.
fn gzip_error(path: &Path, e: std::io::Error) -> ReadError {
    let message = if e.kind() == std::io::ErrorKind::UnexpectedEof {
        format!(
            "gzip decompression failed: {e}: the compressed file ends early (cut short?); \
             `zcat {} > part` keeps the text before the cut, whose complete frames convert",
            path.display()
        )
    } else if e.to_string().contains("checksum") {
        // (flate2 says "checksum" for a trailer whose CRC or length does not match.)
        format!(
            "gzip decompression failed: {e}: the trailer's CRC-32 or length (ISIZE) does not \
             match the text decompressed (a damaged or altered file)"
        )
    } else {
        format!("gzip decompression failed: {e}")
    };
    ReadError::Io {
        path: path.to_path_buf(),
        source: std::io::Error::new(e.kind(), message),
    }
}

/// The most a deflate stream expands: 1032 bytes of text per compressed byte (258
/// bytes per match of a bit or two).
const MAX_DEFLATE_RATIO: usize = 1032;

/// The buffer to reserve for the text of `compressed` gzip bytes whose trailer gives
/// the length `trailer`, of which at most `take` bytes are kept: the trailer's length
/// when deflate can expand that much (a trailer that claims more is none: a file cut
/// short ends in compressed bytes, which read as up to 4 GiB; a file over 4 MB may still
/// claim that much, which is reserved if the system grants it and given back once the
/// text is read), else four times the compressed size.
fn text_capacity(compressed: usize, trailer: usize, take: u64) -> usize {
    let trailer = if trailer / MAX_DEFLATE_RATIO <= compressed {
        trailer
    } else {
        0
    };
    compressed
        .saturating_mul(4)
        .max(trailer)
        .min(usize::try_from(take).unwrap_or(usize::MAX))
}

/// The capacity a text buffer of `capacity` bytes grows to when it must hold `needed`:
/// twice its capacity (at least 1 MiB), but never past `cap` (the most the reader lets
/// through), nor less than `needed`.
fn text_growth(capacity: usize, needed: usize, cap: usize) -> usize {
    capacity.saturating_mul(2).max(1 << 20).min(cap).max(needed)
}

/// Decompresses the gzip bytes `compressed` of `path` (single or multi-member) into
/// memory, with whether the stream ended early (what precedes the cut is kept); `None`
/// when the text is larger than `limit` bytes (of which at most one byte more is
/// decompressed: a small file of a high ratio can expand far past memory).
fn gunzip(
    path: &Path,
    compressed: &[u8],
    limit: Option<u64>,
    progress: &dyn Progress,
) -> Result<Option<(Vec<u8>, bool)>, ReadError> {
    struct Counting<'a, 'p> {
        inner: &'a [u8],
        progress: &'p dyn Progress,
    }
    impl Read for Counting<'_, '_> {
        fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
            let n = self.inner.read(buf)?;
            self.progress.advance(n as u64);
            Ok(n)
        }
    }
    progress.stage("decompressing", Some(compressed.len() as u64), "bytes");
    let reader = Counting {
        inner: compressed,
        progress,
    };
    let take = limit.map_or(u64::MAX, |l| l.saturating_add(1));
    // The gzip trailer's last 4 bytes give the (last member's) text length modulo 2^32:
    // exact for the usual single-member file under 4 GiB, whose text then fills one
    // buffer of its size instead of doubling into one of up to twice it (a 1 GiB text
    // peaked at 2.1 GB).
    let trailer = compressed
        .len()
        .checked_sub(4)
        .map_or(0, |at| u32::from_le_bytes(le4(&compressed[at..])) as usize);
    let hint = text_capacity(compressed.len(), trailer, take);
    // Reserved if it can be (a refusal is no error: the buffer grows as the text comes).
    let mut out = Vec::new();
    let _ = out.try_reserve_exact(hint);
    let mut decoder =
        flate2::read::MultiGzDecoder::new(std::io::BufReader::with_capacity(1 << 20, reader))
            .take(take);
    // The buffer grows by doubling, but never past the bytes `take` lets through: a text
    // of a high ratio (a gzip bomb) stops at the limit itself, not at a doubling of it
    // (a 2 GiB limit reached for 4 GiB and aborted where less was free), and memory that
    // runs out is an error naming the file.
    let mut chunk = vec![0u8; 1 << 20];
    let cap = usize::try_from(take).unwrap_or(usize::MAX);
    let cut = loop {
        let n = match decoder.read(&mut chunk) {
            Ok(0) => break false,
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            // (What was read before the cut is kept.)
            Err(e) if ends_early(&e) && !out.is_empty() => break true,
            Err(e) => return Err(gzip_error(path, e)),
        };
        if out.capacity() - out.len() < n {
            let grow = text_growth(out.capacity(), out.len() + n, cap) - out.len();
            out.try_reserve_exact(grow).map_err(|_| {
                gzip_error(
                    path,
                    std::io::Error::new(
                        std::io::ErrorKind::OutOfMemory,
                        format!(
                            "out of memory holding {} MiB of decompressed text; a smaller \
                             --memory-limit decompresses large texts into a working file",
                            out.len() >> 20
                        ),
                    ),
                )
            })?;
        }
        out.extend_from_slice(&chunk[..n]);
    };
    progress.finish_stage();
    if limit.is_some_and(|l| out.len() as u64 > l) {
        return Ok(None);
    }
    // A trailer that claimed more than the text (a file cut short or altered): the
    // reserve beyond it given back.
    if out.capacity() - out.len() > out.len() / 8 {
        out.shrink_to_fit();
    }
    Ok(Some((out, cut)))
}

#[cfg(test)]
mod gunzip_tests {
    /// A text of a high ratio fills a buffer of its own length (the trailer's), not one
    /// doubled past it, and a multi-member file (whose trailer gives its last member's
    /// length only) still reads whole.
    #[test]
    fn gzip_text_is_read_into_a_buffer_of_its_length() {
        let gz = |text: &[u8]| {
            let mut e = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
            std::io::Write::write_all(&mut e, text).unwrap();
            e.finish().unwrap()
        };
        let text = vec![b' '; 1_000_003];
        let one = gz(&text);
        let path = std::path::Path::new("t.gz");
        let (out, cut) = super::gunzip(path, &one, None, &crate::NoProgress)
            .unwrap()
            .unwrap();
        assert_eq!(
            (out.len(), out.capacity(), cut),
            (text.len(), text.len(), false)
        );
        // A trailer whose length lies is an error that says what the trailer holds.
        let mut lying = one.clone();
        let n = lying.len();
        lying[n - 4..].copy_from_slice(&7u32.to_le_bytes());
        let e = super::gunzip(path, &lying, None, &crate::NoProgress).unwrap_err();
        assert!(e.to_string().contains("CRC-32 or length (ISIZE)"), "{e}");
        let mut two = one.clone();
        two.extend_from_slice(&gz(b"tail\n"));
        let (out, _) = super::gunzip(path, &two, None, &crate::NoProgress)
            .unwrap()
            .unwrap();
        assert_eq!(out.len(), text.len() + 5);
    }

    /// The text buffer doubles, but never past the most the reader lets through (the
    /// limit and one byte): a gzip bomb under a 2 GiB limit stops near 2 GiB, not at a
    /// doubling to 4 GiB.
    #[test]
    fn a_text_buffer_grows_no_further_than_its_limit() {
        use super::text_growth;
        assert_eq!(text_growth(0, 10, usize::MAX), 1 << 20);
        assert_eq!(text_growth(4 << 20, (4 << 20) + 1, usize::MAX), 8 << 20);
        let cap = (2usize << 30) + 1;
        assert_eq!(text_growth(3 << 29, (3 << 29) + 7, cap), cap);
        assert_eq!(text_growth(cap - 5, cap, cap), cap);
        // What must be held is held, whatever the cap.
        assert_eq!(text_growth(100, 5 << 20, 1000), 5 << 20);
    }

    /// Control characters and bytes that are no UTF-8 are shown a byte each as `\xNN`
    /// (a two-byte control character as its two bytes), tabs as they are, and at most 60
    /// characters or escapes.
    #[test]
    fn shortened_lines_escape_what_does_not_print() {
        assert_eq!(super::shorten(b"  1.0\t2\xFB3\x00  "), r"1.0	2\xFB3\x00");
        assert_eq!(super::shorten("a\u{85}b".as_bytes()), r"a\xC2\x85b");
        assert_eq!(super::shorten("é".as_bytes()), "é");
        let long = [b'7'; 61];
        assert_eq!(super::shorten(&long), format!("{}...", "7".repeat(60)));
        assert_eq!(super::shorten(&long[..60]), "7".repeat(60));
        assert_eq!(
            super::shorten(&[0xFF; 100]),
            format!("{}...", r"\xFF".repeat(60))
        );
    }

    /// The text's buffer takes the trailer's length only where deflate can expand that
    /// much: the last 4 bytes of a file cut short (compressed bytes) or altered claim up
    /// to 4 GiB, which reserved at once aborted a process under an address-space limit.
    #[test]
    fn a_trailer_claiming_more_than_deflate_expands_to_is_not_reserved() {
        assert_eq!(super::text_capacity(100, 3_858_415_415, u64::MAX), 400);
        assert_eq!(
            super::text_capacity(83_858, u32::MAX as usize, u64::MAX),
            335_432
        );
        assert_eq!(super::text_capacity(4_000, 1_000_003, u64::MAX), 1_000_003);
        assert_eq!(super::text_capacity(4_000, 1_000_003, 500_001), 500_001);
        assert_eq!(super::text_capacity(10, 0, u64::MAX), 40);
    }
}

#[cfg(test)]
mod wrap_tests {
    /// A point a hair below the lower face wraps inside the cell, not onto its upper face,
    /// where single precision would round it (10 − 10⁻⁷ is 10.0): the lower face is the
    /// same place.
    #[test]
    fn a_wrapped_point_never_lands_on_the_upper_face() {
        let cell = mdlod_format::meta::SimulationBox::orthogonal([0.0; 3], [10.0; 3]);
        let mut positions = [
            [-1e-7, 5.0, 5.0],
            [10.0 + 1e-6, -3.0, 12.5],
            [2.5, 5.0, 5.0],
        ];
        super::wrap_positions(&mut positions, &cell);
        for p in positions {
            assert!(p.iter().all(|&x| (0.0..10.0).contains(&x)), "{p:?}");
        }
        assert_eq!(positions[0], [0.0, 5.0, 5.0]);
        assert_eq!(positions[1][1..], [7.0, 2.5]);
        assert_eq!(positions[2], [2.5, 5.0, 5.0]);
    }
}
