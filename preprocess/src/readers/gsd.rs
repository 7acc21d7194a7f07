//! GSD files (HOOMD-blue's General Simulation Data), `hoomd` schema.
//!
//! How it works. A GSD file is a 256-byte header, an index of 32-byte entries (frame,
//! N, M, location, name id, type) pointing at raw little-endian data chunks, and a list
//! of chunk names (64-byte slots in file layer 1.0, 0-separated in 2.x). Opening reads
//! the header, the names and the index, checking every entry's data range against the
//! file size with checked arithmetic; reading frame `k` looks up its chunks:
//!
//! - `particles/N` (u32), `particles/position` (f32 or f64, N×3), `particles/typeid`
//!   (u32, default 0), `particles/types` (N×M characters, default `A`),
//!   `particles/diameter` (f32, default 1: each particle's radius is half its own, kept
//!   where a type's particles differ in size, and the species' radius half the type's
//!   mean; without it, an HPMC run's `particles/type_shapes` gives a `Sphere` type's
//!   diameter; a type with a diameter of zero, below or not finite is refused by the
//!   conversion unless `--radius` names it), `configuration/step` (u64, default 0),
//!   `configuration/box` (f32 ×6: `Lx Ly Lz xy xz yz`, centred on the origin).
//! - The type names must be distinct and not empty (the species are told by them).
//! - As the schema says, a chunk missing from frame `k` is taken from frame 0, and one
//!   missing from both has its default: writers store only what changed. A file with no
//!   `configuration/step` at all has no timesteps for a batch to number its frames by
//!   ([`crate::readers::DumpFile::frame_timestep`] is `None`, and the frames record none).
//!   Frame 0's per-particle chunk stands in for a missing one only in a frame of as many
//!   particles, as HOOMD's `gsd.hoomd` reads them; a frame of another N has the default.
//! - The attribute may be any per-particle chunk of N numbers (`charge`, `mass`,
//!   `particles/charge`, ...); one of several components (`velocity`) is refused.
//! - A frame whose `particles/N` is 0 has no particles: the chunks it takes from frame 0
//!   (of frame 0's particles) do not apply to it.
//!
//! Errors name the byte offset of the damaged entry or value.

use std::ops::Range;
use std::path::Path;

use rayon::prelude::*;

use super::{FrameInfo, ReadError, ReadOptions};
use crate::frame::{Attribute, Frame, SimulationBox, SpeciesName};
use crate::progress::Progress;

const MAGIC: u64 = 0x65DF_65DF_65DF_65DF;
const HEADER: usize = 256;
const ENTRY: usize = 32;
/// Name slot size of file layer 1.0 (and the unit of the name list size in 2.x).
const NAME_SLOT: usize = 64;

/// GSD chunk element types.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Ty {
    U8,
    U16,
    U32,
    U64,
    I8,
    I16,
    I32,
    I64,
    F32,
    F64,
    Char,
}

impl Ty {
    fn from_code(c: u8) -> Option<Ty> {
        Some(match c {
            1 => Ty::U8,
            2 => Ty::U16,
            3 => Ty::U32,
            4 => Ty::U64,
            5 => Ty::I8,
            6 => Ty::I16,
            7 => Ty::I32,
            8 => Ty::I64,
            9 => Ty::F32,
            10 => Ty::F64,
            11 => Ty::Char,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Ty::U8 | Ty::I8 | Ty::Char => 1,
            Ty::U16 | Ty::I16 => 2,
            Ty::U32 | Ty::I32 | Ty::F32 => 4,
            Ty::U64 | Ty::I64 | Ty::F64 => 8,
        }
    }

    /// Element `i` of `bytes` as f64.
    fn get(self, bytes: &[u8], i: usize) -> f64 {
        let b = &bytes[i * self.size()..(i + 1) * self.size()];
        let a = |n: usize| -> [u8; 8] {
            let mut out = [0u8; 8];
            out[..n].copy_from_slice(&b[..n]);
            out
        };
        match self {
            Ty::U8 | Ty::Char => f64::from(b[0]),
            Ty::I8 => f64::from(b[0] as i8),
            Ty::U16 => f64::from(u16::from_le_bytes([b[0], b[1]])),
            Ty::I16 => f64::from(i16::from_le_bytes([b[0], b[1]])),
            Ty::U32 => f64::from(u32::from_le_bytes([b[0], b[1], b[2], b[3]])),
            Ty::I32 => f64::from(i32::from_le_bytes([b[0], b[1], b[2], b[3]])),
            Ty::F32 => f64::from(f32::from_le_bytes([b[0], b[1], b[2], b[3]])),
            Ty::U64 => u64::from_le_bytes(a(8)) as f64,
            Ty::I64 => i64::from_le_bytes(a(8)) as f64,
            Ty::F64 => f64::from_le_bytes(a(8)),
        }
    }
}

/// One index entry: an N×M chunk of `ty` at `location` (checked to lie in the file).
#[derive(Clone, Copy, Debug)]
struct Entry {
    frame: u64,
    n: usize,
    m: usize,
    location: usize,
    name: u16,
    ty: Ty,
    /// Byte offset of the entry in the index, for errors.
    at: usize,
}

/// The chunks of a GSD file.
pub(crate) struct Index {
    names: Vec<String>,
    /// Sorted by (frame, name).
    entries: Vec<Entry>,
    frames: usize,
    /// Whether any frame records `configuration/step` (see [`Index::records_steps`]).
    records_steps: bool,
    /// The first frame (after frame 0) with a chunk outside the file, where the error
    /// about it points and says: a file cut short (a run killed while writing, a copy
    /// that stopped) still has its complete frames; that frame fails when read, and the
    /// frames after it are lost.
    damaged: Option<(usize, usize, String)>,
}

/// The chunk an attribute asked for by `name` is read from: `name` itself where it names
/// a group (`log/particles/speed`), else of `particles/` (`charge`); a magnitude's
/// (`|velocity|`) the chunk inside its bars.
pub(crate) fn chunk_name(name: &str) -> String {
    let base = crate::readers::magnitude_of(name).map_or(name, str::trim);
    if base.contains('/') {
        base.to_string()
    } else {
        format!("particles/{base}")
    }
}

/// True when `data` starts with the GSD magic number.
pub(crate) fn sniff(data: &[u8]) -> bool {
    data.len() >= 8 && u64::from_le_bytes(data[..8].try_into().unwrap_or([0; 8])) == MAGIC
}

fn err(path: &Path, offset: usize, message: impl Into<String>) -> ReadError {
    ReadError::Binary {
        path: path.to_path_buf(),
        offset: offset as u64,
        message: message.into(),
    }
}

fn u64_at(data: &[u8], at: usize) -> u64 {
    u64::from_le_bytes(data[at..at + 8].try_into().unwrap_or([0; 8]))
}

impl Index {
    pub fn build(path: &Path, data: &[u8]) -> Result<Index, ReadError> {
        // The magic number first: a short file of something else is no GSD file cut short.
        if data.len() >= 8 && u64_at(data, 0) != MAGIC {
            return Err(err(path, 0, "not a GSD file (bad magic number)"));
        }
        if data.len() < 8 {
            return Err(err(
                path,
                0,
                format!(
                    "not a GSD file: {} bytes, and a GSD file starts with a {HEADER}-byte header",
                    data.len()
                ),
            ));
        }
        if data.len() < HEADER {
            return Err(err(
                path,
                data.len(),
                format!("truncated: the GSD header needs {HEADER} bytes"),
            ));
        }
        if u64_at(data, 0) != MAGIC {
            return Err(err(path, 0, "not a GSD file (bad magic number)"));
        }
        let version = u32::from_le_bytes(data[44..48].try_into().unwrap_or([0; 4]));
        let major = version >> 16;
        if !(1..=2).contains(&major) {
            return Err(err(
                path,
                44,
                format!(
                    "GSD file layer {}.{} is not supported (1.x and 2.x are)",
                    major,
                    version & 0xffff
                ),
            ));
        }
        let schema = String::from_utf8_lossy(&data[112..176]);
        let schema = schema.trim_end_matches('\0');
        if schema != "hoomd" {
            return Err(err(
                path,
                112,
                format!("schema `{schema}`: only the `hoomd` schema holds particles"),
            ));
        }
        let block = |loc_at: usize, count_at: usize, unit: usize, what: &str| {
            let loc = u64_at(data, loc_at);
            let count = u64_at(data, count_at);
            let range = usize::try_from(loc).ok().and_then(|l| {
                let len = usize::try_from(count).ok()?.checked_mul(unit)?;
                let end = l.checked_add(len)?;
                (end <= data.len()).then_some(l..end)
            });
            range.ok_or_else(|| {
                err(
                    path,
                    loc_at,
                    format!("the {what} ({count} × {unit} bytes at {loc}) lies outside the file"),
                )
            })
        };
        let names_range =
            block(24, 32, NAME_SLOT, "name list").or_else(|_| block(24, 32, 1, "name list"))?;
        let names_bytes = &data[names_range.clone()];
        let names: Vec<String> = if major == 1 {
            names_bytes
                .chunks(NAME_SLOT)
                .take_while(|s| s.first().is_some_and(|&b| b != 0))
                .map(|s| {
                    let end = s.iter().position(|&b| b == 0).unwrap_or(s.len());
                    String::from_utf8_lossy(&s[..end]).into_owned()
                })
                .collect()
        } else {
            names_bytes
                .split(|&b| b == 0)
                .take_while(|s| !s.is_empty())
                .map(|s| String::from_utf8_lossy(s).into_owned())
                .collect()
        };
        let index_range = block(8, 16, ENTRY, "index")?;
        // The most frames the index can describe. A frame that writes no chunk takes all
        // of frame 0's (the schema's fallback), so frames without entries can exist, but
        // a frame number past the index's room is no file a writer made: it would make
        // a few bytes stand for billions of frames to read.
        let slots = index_range.len() / ENTRY;
        let mut entries = Vec::new();
        let mut damaged: Option<(usize, usize, String)> = None;
        // The last frame the index lists, whether or not its chunks are in the file.
        let mut last_listed = 0u64;
        for (k, e) in data[index_range.clone()].chunks_exact(ENTRY).enumerate() {
            let at = index_range.start + k * ENTRY;
            let location = u64_at(e, 16);
            if location == 0 {
                break; // The end of the used entries.
            }
            let frame = u64_at(e, 0);
            if usize::try_from(frame).map_or(true, |f| f >= slots) {
                return Err(err(
                    path,
                    at,
                    format!(
                        "chunk of frame {frame}, but the index has room for {slots} entries \
                         (frame numbers past it are not a GSD file's)"
                    ),
                ));
            }
            let n = u64_at(e, 8);
            let m = u32::from_le_bytes(e[24..28].try_into().unwrap_or([0; 4]));
            let name = u16::from_le_bytes([e[28], e[29]]);
            let ty = Ty::from_code(e[30])
                .ok_or_else(|| err(path, at + 30, format!("unknown chunk type {}", e[30])))?;
            if usize::from(name) >= names.len() {
                return Err(err(
                    path,
                    at + 28,
                    format!(
                        "chunk name id {name}, but the name list has {}",
                        names.len()
                    ),
                ));
            }
            last_listed = last_listed.max(frame);
            let fits = usize::try_from(n).ok().and_then(|n| {
                let bytes = n.checked_mul(m as usize)?.checked_mul(ty.size())?;
                let l = usize::try_from(location).ok()?;
                (l.checked_add(bytes)? <= data.len()).then_some((n, l))
            });
            let Some((n, location)) = fits else {
                let message = format!(
                    "chunk `{}` of frame {frame} ({n} × {m} values at byte {location}) lies outside the file (truncated?)",
                    names[usize::from(name)]
                );
                // (`frame` is below `slots`, so it fits a usize.)
                let f = usize::try_from(frame).unwrap_or(usize::MAX);
                if f == 0 {
                    return Err(err(path, at, message));
                }
                if damaged.as_ref().is_none_or(|d| f < d.0) {
                    damaged = Some((f, at, message));
                }
                continue;
            };
            entries.push(Entry {
                frame,
                n,
                m: m as usize,
                location,
                name,
                ty,
                at,
            });
        }
        entries.sort_by_key(|e| (e.frame, e.name));
        // A frame writes each chunk once: a name twice in one frame leaves which one holds
        // the data untold (a lookup would take either), so the file is refused.
        if let Some(w) = entries
            .windows(2)
            .find(|w| (w[0].frame, w[0].name) == (w[1].frame, w[1].name))
        {
            return Err(err(
                path,
                w[0].at.max(w[1].at),
                format!(
                    "chunk `{}` is written twice in frame {} (index entries at bytes {} and {}): \
                     which one holds the data cannot be told",
                    names[usize::from(w[0].name)],
                    w[0].frame,
                    w[0].at.min(w[1].at),
                    w[0].at.max(w[1].at)
                ),
            ));
        }
        if let Some((f, _, message)) = &mut damaged {
            entries.retain(|e| e.frame <= *f as u64);
            // Frames the index lists after it are lost with it: said, not dropped unsaid.
            let after = last_listed.saturating_sub(*f as u64);
            if after > 0 {
                let frames = match after {
                    1 => format!("frame {}", last_listed),
                    _ => format!("frames {} to {last_listed}", *f + 1),
                };
                // Not a frame a run is writing (a writer adds a frame's index entries
                // after its data): a damaged file, an error rather than a frame to wait
                // for.
                *message = message.replace(" (truncated?)", "");
                message.push_str(&format!(
                    ": the file is damaged (a copy cut short?): the index lists {} frames, \
                     and {frames} after it {} lost with it",
                    last_listed + 1,
                    if after == 1 { "is" } else { "are" }
                ));
            }
        }
        // (Each frame number was checked to be below `slots`, itself below `usize::MAX`.)
        let frames = entries
            .last()
            .and_then(|e| usize::try_from(e.frame).ok()?.checked_add(1))
            .unwrap_or(0)
            .max(damaged.as_ref().map_or(0, |d| d.0 + 1));
        if frames == 0 {
            return Err(err(path, index_range.start, "no frames"));
        }
        // Found once: a batch asks for every frame's timestep, and a file recording no
        // step would have every entry walked each time.
        let records_steps = names
            .iter()
            .position(|n| n == "configuration/step")
            .is_some_and(|id| entries.iter().any(|e| usize::from(e.name) == id));
        Ok(Index {
            names,
            entries,
            frames,
            records_steps,
            damaged,
        })
    }

    pub fn len(&self) -> usize {
        self.frames
    }

    /// Whether frame `k` (past 0), holding positions of its own, takes chunk `name` from
    /// frame 0 (the schema's rule for a chunk a frame leaves out): HOOMD writes
    /// quantities outside its `dynamic` list in frame 0 only, so a velocity read for a
    /// later frame is frame 0's. A frame of another particle count takes the schema's
    /// default instead, as `gsd.hoomd` reads it (its particles are not frame 0's).
    pub(crate) fn takes_from_frame_0(&self, data: &[u8], k: usize, name: &str) -> bool {
        let n = |k: usize| self.particles(Path::new(""), data, k).ok();
        k > 0
            && self.chunk(k, name).is_some_and(|e| e.frame == 0)
            && self
                .chunk(k, "particles/position")
                .is_some_and(|e| e.frame == k as u64)
            && n(k).is_some()
            && n(k) == n(0)
    }

    /// The chunk `name` of frame `k`, else of frame 0 (the schema's rule).
    fn chunk(&self, k: usize, name: &str) -> Option<&Entry> {
        let id = u16::try_from(self.names.iter().position(|n| n == name)?).ok()?;
        let find = |f: u64| {
            self.entries
                .binary_search_by_key(&(f, id), |e| (e.frame, e.name))
                .ok()
                .map(|i| &self.entries[i])
        };
        find(k as u64).or_else(|| find(0))
    }

    /// The byte ranges of frame `k`'s own chunks, in the file's order.
    pub fn own_ranges(&self, k: usize) -> Vec<Range<usize>> {
        let first = self.entries.partition_point(|e| e.frame < k as u64);
        let mut ranges: Vec<Range<usize>> = self.entries[first..]
            .iter()
            .take_while(|e| e.frame == k as u64)
            .map(|e| e.location..e.location.saturating_add(e.n * e.m * e.ty.size()))
            .collect();
        ranges.sort_by_key(|r| (r.start, r.end));
        ranges
    }

    /// The byte ranges frame `k` may be read from, in the file's order: its own chunks,
    /// then frame 0's chunks of the names frame `k` leaves out (which it may take).
    pub fn frame_ranges(&self, k: usize) -> Vec<Range<usize>> {
        let mut ranges = self.own_ranges(k);
        if k > 0 {
            let first = self.entries.partition_point(|e| e.frame < k as u64);
            let own: Vec<u16> = self.entries[first..]
                .iter()
                .take_while(|e| e.frame == k as u64)
                .map(|e| e.name)
                .collect();
            let mut taken: Vec<Range<usize>> = self
                .entries
                .iter()
                .take_while(|e| e.frame == 0)
                .filter(|e| !own.contains(&e.name))
                .map(|e| e.location..e.location.saturating_add(e.n * e.m * e.ty.size()))
                .collect();
            taken.sort_by_key(|r| (r.start, r.end));
            ranges.extend(taken);
        }
        ranges
    }

    /// Whether any frame of the file records `configuration/step`. A file where none
    /// does has no timesteps to number its frames by (the schema's default 0 would give
    /// every frame the same one).
    pub fn records_steps(&self) -> bool {
        self.records_steps
    }

    /// Frame `k`'s timestep where the file records timesteps ([`Self::records_steps`]),
    /// else none: a frame of such a file holds no timestep (not the schema's default 0,
    /// which every frame would share), as a batch numbers it by position.
    pub fn recorded_timestep(&self, data: &[u8], k: usize) -> Option<u64> {
        self.records_steps()
            .then(|| self.timestep(data, k))
            .flatten()
    }

    pub fn timestep(&self, data: &[u8], k: usize) -> Option<u64> {
        if k >= self.frames {
            return None;
        }
        // A frame cut short whose step was cut with it has no step to read: frame 0's,
        // taken for it, made it a duplicate of frame 0.
        let cut = self.damaged.as_ref().is_some_and(|d| k >= d.0);
        match self
            .chunk(k, "configuration/step")
            .filter(|e| !cut || e.frame == k as u64)
        {
            None if cut => None,
            Some(e) if e.ty == Ty::U64 && e.n * e.m >= 1 => Some(u64_at(data, e.location)),
            Some(_) => None,
            None => Some(0),
        }
    }

    /// Particle count of frame `k`.
    fn particles(&self, path: &Path, data: &[u8], k: usize) -> Result<usize, ReadError> {
        if let Some((f, at, message)) = &self.damaged {
            if k >= *f {
                return Err(err(path, *at, message.clone()));
            }
        }
        match self.chunk(k, "particles/N") {
            Some(e) if e.n * e.m == 1 => {
                let v = e.ty.get(&data[e.location..], 0);
                // A count: integral and not negative (a float or signed chunk could hold
                // anything, which `as` would quietly turn into 0 or a huge count).
                if v >= 0.0 && v.fract() == 0.0 && v <= u32::MAX as f64 {
                    Ok(v as usize)
                } else {
                    Err(err(
                        path,
                        e.location,
                        format!(
                            "frame {k}: `particles/N` is {}, not a particle count",
                            super::shown(v)
                        ),
                    ))
                }
            }
            Some(e) => Err(err(path, e.at, "`particles/N` is not a single number")),
            None => Ok(0),
        }
    }

    fn simulation_box(
        &self,
        path: &Path,
        data: &[u8],
        k: usize,
    ) -> Result<SimulationBox, ReadError> {
        let v: Vec<f64> = match self.chunk(k, "configuration/box") {
            Some(e) if e.n * e.m == 6 => (0..6).map(|i| e.ty.get(&data[e.location..], i)).collect(),
            Some(e) => {
                return Err(err(
                    path,
                    e.at,
                    "`configuration/box` does not hold 6 numbers",
                ))
            }
            None => vec![1.0, 1.0, 1.0, 0.0, 0.0, 0.0],
        };
        if v.iter().any(|x| !x.is_finite()) {
            return Err(err(
                path,
                0,
                format!("frame {k}: the box {v:?} is not finite"),
            ));
        }
        let (lx, ly, lz, xy, xz, yz) = (v[0], v[1], v[2], v[3], v[4], v[5]);
        if let Some((axis, l)) = [("Lx", lx), ("Ly", ly), ("Lz", lz)]
            .into_iter()
            .find(|&(_, l)| l < 0.0)
        {
            let at = self.chunk(k, "configuration/box").map_or(0, |e| e.at);
            return Err(err(
                path,
                at,
                format!("frame {k}: the box's {axis} is {l}: a box length is 0 or more"),
            ));
        }
        // The box is single precision: vectors and origin derived from it are rounded to
        // it too, so that a tilt of 0.1 gives 1.1, not the 1.10000001639 of its f32.
        let single = |x: f64| f64::from(x as f32);
        let a = [lx, 0.0, 0.0];
        let b = [single(xy * ly), ly, 0.0];
        let c = [single(xz * lz), single(yz * lz), lz];
        Ok(SimulationBox {
            origin: [0, 1, 2].map(|i| single(-0.5 * (a[i] + b[i] + c[i]))),
            a,
            b,
            c,
            periodic: Some([true; 3]),
        })
    }
}

pub(crate) fn frame_info(
    path: &Path,
    data: &[u8],
    index: &Index,
    k: usize,
) -> Result<FrameInfo, ReadError> {
    let particles = index.particles(path, data, k)?;
    let columns = particle_chunks(index, k, particles, false);
    Ok(FrameInfo {
        particles,
        timestep: index.recorded_timestep(data, k),
        time: None,
        units: None,
        simulation_box: Some(index.simulation_box(path, data, k)?),
        columns,
    })
}

/// The chunks of frame `k` (of `particles` particles) an attribute can be: one number
/// per particle.
fn attribute_chunks(index: &Index, k: usize, particles: usize) -> Vec<String> {
    let mut names = particle_chunks(index, k, particles, true);
    // Those left out at their schema default are taken too.
    for name in [
        "particles/body",
        "particles/charge",
        "particles/diameter",
        "particles/mass",
    ] {
        if !names.iter().any(|n| n == name) {
            names.push(name.to_string());
        }
    }
    names.sort();
    names
}

/// The names of frame `k`'s numeric per-particle chunks (of `particles` rows; with
/// `single`, of one number each), sorted.
fn particle_chunks(index: &Index, k: usize, particles: usize, single: bool) -> Vec<String> {
    let mut names: Vec<String> = index
        .names
        .iter()
        .filter(|n| {
            // HOOMD logs per-particle quantities (energies, virials) as `log/particles/...`.
            (n.starts_with("particles/") || n.starts_with("log/particles/"))
                && index
                    .chunk(k, n)
                    .is_some_and(|e| e.n == particles && (!single || e.m == 1) && e.ty != Ty::Char)
        })
        .cloned()
        .collect();
    names.sort();
    names
}

/// Frame `k` of an opened file, with its `n` particles.
struct FrameData<'a> {
    path: &'a Path,
    data: &'a [u8],
    index: &'a Index,
    k: usize,
    n: usize,
}

impl<'a> FrameData<'a> {
    fn new(path: &'a Path, data: &'a [u8], index: &'a Index, k: usize) -> Result<Self, ReadError> {
        let n = index.particles(path, data, k)?;
        let f = FrameData {
            path,
            data,
            index,
            k,
            n,
        };
        // Every per-particle array is sized by N: a count that the file's positions do
        // not back fails here, before anything is allocated for it.
        if let Some(e) = f.chunk("particles/position", 3, true)? {
            if !matches!(e.ty, Ty::F32 | Ty::F64) {
                return Err(err(
                    path,
                    e.at,
                    "`particles/position` is not floating point",
                ));
            }
        }
        Ok(f)
    }

    /// A per-particle chunk checked to be `n × m` (`None` when the frame and frame 0
    /// lack it and it is optional).
    fn chunk(&self, name: &str, m: usize, required: bool) -> Result<Option<&'a Entry>, ReadError> {
        let (path, k, n) = (self.path, self.k, self.n);
        // Frame 0's chunk stands in for a missing one only where frame 0 has as many
        // particles (as HOOMD's `gsd.hoomd` reads it: a frame of another N that leaves a
        // chunk out has the schema's default, as its particles are not frame 0's); an
        // empty frame takes nothing of frame 0's particles. Frame 0's count is its
        // `particles/N`, not the chunk's own length: a chunk of frame 0 sized for other
        // particles is an error, as it is when frame 0 itself is read.
        let frame0_n = || self.index.particles(path, self.data, 0).ok();
        let entry = self
            .index
            .chunk(k, name)
            .filter(|e| e.frame == k as u64 || (n > 0 && frame0_n() == Some(n)));
        match entry {
            None if required && n > 0 => Err(err(
                path,
                0,
                format!(
                    "frame {k} has no `{name}` for its {n} particles{}{}",
                    if k > 0 {
                        " (and frame 0 has none for as many)"
                    } else {
                        ""
                    },
                    // (The schema's default, which a writer leaves out: all at the origin.)
                    if name == "particles/position" {
                        ": a writer leaves positions out where every particle is at the \
                         origin, a frame with nothing to draw"
                    } else {
                        ""
                    }
                ),
            )),
            None => Ok(None),
            Some(e) if e.n != n || e.m != m => Err(err(
                path,
                e.at,
                format!(
                    "frame {k}: `{name}` is {} × {}, expected {n} × {m} for {n} particles",
                    e.n, e.m
                ),
            )),
            Some(e) => Ok(Some(e)),
        }
    }

    /// The type names: `particles/types` (N names of M characters), or one type `A`.
    fn type_names(&self) -> Result<Vec<String>, ReadError> {
        let names: Vec<String> = match self.index.chunk(self.k, "particles/types") {
            Some(e) if matches!(e.ty, Ty::I8 | Ty::U8 | Ty::Char) => self.data
                [e.location..e.location + e.n * e.m]
                .chunks(e.m.max(1))
                .map(|s| {
                    let end = s.iter().position(|&b| b == 0).unwrap_or(s.len());
                    String::from_utf8_lossy(&s[..end]).into_owned()
                })
                .collect(),
            Some(e) => return Err(err(self.path, e.at, "`particles/types` is not text")),
            None => vec!["A".to_string()],
        };
        if names.is_empty() || names.len() > 1 << 16 {
            return Err(err(
                self.path,
                0,
                format!(
                    "frame {}: {} particle types (1 to 65536 allowed)",
                    self.k,
                    names.len()
                ),
            ));
        }
        if let Some(e) = self.index.chunk(self.k, "particles/types") {
            let at = |t: usize| e.location + t * e.m;
            let mut seen = std::collections::HashMap::with_capacity(names.len());
            for (t, name) in names.iter().enumerate() {
                let message = if name.is_empty() {
                    format!("type {t} has an empty name")
                } else if let Some(first) = seen.insert(name.as_str(), t) {
                    format!("types {first} and {t} are both named `{name}`")
                } else {
                    continue;
                };
                return Err(err(
                    self.path,
                    at(t),
                    format!(
                        "frame {}: `particles/types`: {message} (each type needs a name of \
                         its own)",
                        self.k
                    ),
                ));
            }
        }
        Ok(names)
    }

    /// The type ids of particles `range` (all 0 without `particles/typeid`).
    fn type_ids(&self, range: Range<usize>, count: usize) -> Result<Vec<u16>, ReadError> {
        let mut species_index = vec![0u16; range.len()];
        if let Some(e) = self.chunk("particles/typeid", 1, false)? {
            let bytes = &self.data[e.location..e.location + self.n * e.ty.size()];
            let first = range.start;
            let bad = species_index
                .par_chunks_mut(super::SCAN_BLOCK)
                .enumerate()
                .find_map_first(|(b, block)| {
                    for (o, s) in block.iter_mut().enumerate() {
                        let j = b * super::SCAN_BLOCK + o;
                        let t = e.ty.get(bytes, first + j);
                        if t >= 0.0 && (t as usize) < count && t.fract() == 0.0 {
                            *s = t as u16;
                        } else {
                            return Some((first + j, t));
                        }
                    }
                    None
                });
            if let Some((i, t)) = bad {
                return Err(err(
                    self.path,
                    e.location + i * e.ty.size(),
                    format!(
                        "frame {}: particle {i} has type id {t}, but there are {count} types",
                        self.k
                    ),
                ));
            }
        }
        Ok(species_index)
    }

    /// The species of particles `range` (type ids `ids`): every type, in the file's
    /// order, with the radius half the mean diameter of the type's particles in the range
    /// (default diameter 1). A type with a particle of diameter zero, below or not finite
    /// gets half the first such diameter, which the conversion refuses unless `--radius`
    /// gives the type its radius.
    fn species(
        &self,
        range: Range<usize>,
        names: &[String],
        ids: &[u16],
    ) -> Result<Vec<SpeciesName>, ReadError> {
        let mut sum = vec![0f64; names.len()];
        let mut count = vec![0u64; names.len()];
        let mut bad: Vec<Option<f64>> = vec![None; names.len()];
        let mut spread = vec![(f64::INFINITY, f64::NEG_INFINITY); names.len()];
        if let Some(e) = self.chunk("particles/diameter", 1, false)? {
            let bytes = &self.data[e.location..e.location + self.n * e.ty.size()];
            for (j, &s) in ids.iter().enumerate() {
                let i = range.start + j;
                let d = e.ty.get(bytes, i);
                // (A diameter whose half rounds to 0 in single precision is 0.)
                if !(d.is_finite() && (0.5 * d) as f32 > 0.0) {
                    bad[usize::from(s)].get_or_insert(d);
                }
                if !d.is_finite() {
                    continue;
                }
                sum[usize::from(s)] += d;
                count[usize::from(s)] += 1;
                let r = &mut spread[usize::from(s)];
                *r = (r.0.min(d), r.1.max(d));
            }
        }
        // Without diameters, an HPMC run's sphere shapes give the types' sizes (read only
        // where some type has no diameter).
        let shapes = if count.contains(&0) {
            self.sphere_shapes(names.len())
        } else {
            Vec::new()
        };
        Ok(names
            .iter()
            .enumerate()
            .map(|(t, name)| SpeciesName {
                name: name.clone(),
                numeric_type: false,
                radius: Some(match bad[t] {
                    Some(d) => (0.5 * d) as f32,
                    None if count[t] > 0 => (0.5 * sum[t] / count[t] as f64) as f32,
                    None => shapes.get(t).copied().flatten().map_or(0.5, |d| 0.5 * d),
                    // (A shape's diameter of zero or below gives a radius the conversion
                    // refuses, naming the type, unless --radius gives one.)
                }),
                radius_range: (count[t] > 0)
                    .then(|| ((0.5 * spread[t].0) as f32, (0.5 * spread[t].1) as f32)),
                ..Default::default()
            })
            .collect())
    }
}

impl FrameData<'_> {
    /// Each type's sphere diameter from `particles/type_shapes` (HPMC writes one JSON
    /// object per type there, `{"type": "Sphere", "diameter": 2.0}`, and leaves
    /// `particles/diameter` at its default); `None` for other shapes or none given.
    fn sphere_shapes(&self, types: usize) -> Vec<Option<f32>> {
        let mut shapes: Vec<Option<f32>> = self
            .shapes()
            .unwrap_or_default()
            .into_iter()
            .map(|s| match s {
                Shape::Sphere(d) => Some(d),
                Shape::Other(_) | Shape::Unreadable => None,
            })
            .collect();
        shapes.resize(types, None);
        shapes
    }

    /// The entries of `particles/type_shapes`, one per type listed; `None` without the
    /// chunk (or one not of text).
    fn shapes(&self) -> Option<Vec<Shape>> {
        let e = self.index.chunk(self.k, "particles/type_shapes")?;
        if !matches!(e.ty, Ty::I8 | Ty::U8 | Ty::Char) {
            return None;
        }
        let bytes = self.data.get(e.location..e.location + e.n * e.m)?;
        Some(
            bytes
                .chunks(e.m.max(1))
                .map(|s| {
                    let end = s.iter().position(|&b| b == 0).unwrap_or(s.len());
                    let Ok(v) = serde_json::from_slice::<serde_json::Value>(&s[..end]) else {
                        return Shape::Unreadable;
                    };
                    let Some(kind) = v.get("type").and_then(|t| t.as_str()) else {
                        return Shape::Unreadable;
                    };
                    // (A diameter of zero, below or not finite is kept, and refused as a
                    // particle's would be.)
                    match (kind, v.get("diameter").and_then(|d| d.as_f64())) {
                        ("Sphere", Some(d)) => Shape::Sphere(d as f32),
                        ("Sphere", None) => Shape::Unreadable,
                        (other, _) => Shape::Other(other.to_string()),
                    }
                })
                .collect(),
        )
    }

    /// What the frame's `particles/type_shapes` says that the conversion does not draw:
    /// types without a sphere there (another shape, an entry not read, no entry) where
    /// the shapes give the sizes (no `particles/diameter`), each then drawn at the
    /// default radius 0.5.
    fn shape_note(&self) -> Option<String> {
        let e = self.index.chunk(self.k, "particles/type_shapes")?;
        if self.chunk("particles/diameter", 1, false).ok()?.is_some() {
            return None;
        }
        if !matches!(e.ty, Ty::I8 | Ty::U8 | Ty::Char) {
            return Some(format!(
                "{}: frame {}: particles/type_shapes is not text (a JSON object per type), so \
                 no type's shape is read: every type is drawn at radius 0.5, the default, \
                 unless --radius NAME=R gives one",
                self.path.display(),
                self.k
            ));
        }
        let shapes = self.shapes()?;
        let names = self.type_names().ok()?;
        let missed: Vec<String> = names
            .iter()
            .enumerate()
            .filter_map(|(t, name)| match shapes.get(t) {
                Some(Shape::Sphere(_)) => None,
                Some(Shape::Other(kind)) => Some(format!("{name} ({kind})")),
                Some(Shape::Unreadable) => Some(format!("{name} (an entry not read)")),
                None => Some(format!("{name} (no entry)")),
            })
            .collect();
        if missed.is_empty() {
            return None;
        }
        Some(format!(
            "{}: frame {}: particles/type_shapes gives no sphere for type{} {}: {} drawn as \
             spheres of radius 0.5, the default, unless --radius NAME=R gives one",
            self.path.display(),
            self.k,
            if missed.len() == 1 { "" } else { "s" },
            missed.join(", "),
            if missed.len() == 1 {
                "it is"
            } else {
                "they are"
            }
        ))
    }
}

/// An entry of `particles/type_shapes`.
enum Shape {
    /// A sphere of this diameter.
    Sphere(f32),
    /// Another shape (`ConvexPolyhedron`, `Ellipsoid`, ...).
    Other(String),
    /// No JSON object with a `type` (or a sphere without a diameter).
    Unreadable,
}

/// A note where frame `k` turns particles (`particles/orientation`, its own or frame 0's
/// taken for it, with some quaternion other than the identity): mdlod draws spheres, so
/// the orientations of anisotropic shapes and rigid bodies are not shown. `None` where
/// the frame cannot be read or turns none.
pub(crate) fn orientation_note(
    path: &Path,
    data: &[u8],
    index: &Index,
    k: usize,
) -> Option<String> {
    let f = FrameData::new(path, data, index, k).ok()?;
    let e = f.chunk("particles/orientation", 4, false).ok()??;
    if !matches!(e.ty, Ty::F32 | Ty::F64) {
        return None;
    }
    let bytes = data.get(e.location..e.location + f.n * 4 * e.ty.size())?;
    let identity = [1.0, 0.0, 0.0, 0.0];
    let turned = (0..f.n).any(|i| (0..4).any(|c| e.ty.get(bytes, 4 * i + c) != identity[c]));
    turned.then(|| {
        format!(
            "{}: frame {k}: particles/orientation turns particles, which are drawn as \
             spheres: the orientations of anisotropic shapes and rigid bodies are not shown",
            path.display()
        )
    })
}

/// [`FrameData::shape_note`] of frame `k`, if the frame can be read.
pub(crate) fn shape_note(path: &Path, data: &[u8], index: &Index, k: usize) -> Option<String> {
    FrameData::new(path, data, index, k).ok()?.shape_note()
}

/// The `hoomd` schema's default of a per-particle chunk of one number, which a writer
/// leaves out where every particle has it.
fn schema_default(name: &str) -> Option<f32> {
    match name {
        "particles/mass" | "particles/diameter" => Some(1.0),
        "particles/charge" => Some(0.0),
        "particles/body" => Some(-1.0),
        _ => None,
    }
}

/// The species of frame `k` as the whole frame lists them (radii from the whole frame's
/// diameters), from one pass over the type ids and diameters alone: what every part of
/// the frame read by [`read_range`] takes, so that a frame read in parts converts as the
/// whole one does.
pub(crate) fn frame_species(
    path: &Path,
    data: &[u8],
    index: &Index,
    k: usize,
) -> Result<Vec<SpeciesName>, ReadError> {
    let f = FrameData::new(path, data, index, k)?;
    let names = f.type_names()?;
    let ids = f.type_ids(0..f.n, names.len())?;
    f.species(0..f.n, &names, &ids)
}

/// Reads particles `range` of frame `k` as a frame of their own: every type listed, radii
/// from the range's diameters (see [`frame_species`] for the whole frame's).
pub(crate) fn read_range(
    path: &Path,
    data: &[u8],
    index: &Index,
    k: usize,
    opts: &ReadOptions,
    range: Range<usize>,
    progress: &dyn Progress,
) -> Result<Frame, ReadError> {
    let f = FrameData::new(path, data, index, k)?;
    let n = f.n;
    let first = range.start;
    let len = range.len();
    progress.stage(&format!("reading frame {k}"), Some(len as u64), "particles");
    let mut positions = vec![[0f32; 3]; len];
    // (Checked to be N × 3 floating-point numbers by `FrameData::new`.)
    if let Some(e) = f.chunk("particles/position", 3, true)? {
        let bytes = &data[e.location..e.location + n * 3 * e.ty.size()];
        positions =
            super::decode_positions(len, |i, c| 3 * (first + i) + c, |j| e.ty.get(bytes, j))
                .map_err(|(j, v)| {
                    err(
                        path,
                        e.location + j * e.ty.size(),
                        format!(
                            "frame {k}: particle {} has a position that is not finite{}",
                            j / 3,
                            super::single_precision_note(v)
                        ),
                    )
                })?;
    }
    progress.advance(len as u64);
    let names = f.type_names()?;
    let species_index = f.type_ids(range.clone(), names.len())?;
    let species = f.species(range.clone(), &names, &species_index)?;
    // Each particle's own radius, half its diameter (kept where a type's differ), unless
    // sizes are left out (--no-sizes: each type at its mean).
    let diameters = match opts.sizes {
        super::SizeColumn::Off => None,
        _ => f.chunk("particles/diameter", 1, false)?,
    };
    let radii = match diameters {
        Some(e) => {
            let bytes = &data[e.location..e.location + n * e.ty.size()];
            Some(
                range
                    .clone()
                    .map(|i| (0.5 * e.ty.get(bytes, i)) as f32)
                    .collect(),
            )
        }
        None => None,
    };

    let attribute = match &opts.attribute {
        // (An empty frame has no values to take.)
        Some(_) if n == 0 => None,
        None => None,
        Some(name) => {
            let magnitude = crate::readers::magnitude_of(name);
            let full = chunk_name(name);
            if let Some(e) = index
                .chunk(k, &full)
                .filter(|e| e.n == n && e.m != 1 && magnitude.is_none())
            {
                let available = attribute_chunks(index, k, n).join(" ");
                return Err(err(
                    path,
                    e.at,
                    format!(
                        "frame {k}: `{full}` has {} components per particle; --attribute \
                         takes a chunk of one number per particle ({available}), or the \
                         length of a row: --attribute '|{full}|'",
                        e.m
                    ),
                ));
            }
            if magnitude.is_none() {
                let values = match f.chunk(&full, 1, false)? {
                    // Writers leave out a chunk that holds only its schema default (HOOMD's
                    // charge of 0 in frame 0, a mass of 1): the default is every value.
                    None => match schema_default(&full) {
                        Some(default) => vec![default; range.len()],
                        None => {
                            let available = attribute_chunks(index, k, n).join(" ");
                            return Err(err(
                                path,
                                0,
                                format!(
                                    "frame {k}: no per-particle chunk `{full}` for the attribute; \
                                 available: {available}"
                                ),
                            ));
                        }
                    },
                    Some(e) => {
                        if e.ty == Ty::Char {
                            return Err(err(path, e.at, format!("`{full}` is text, not numbers")));
                        }
                        let bytes = &data[e.location..e.location + n * e.ty.size()];
                        let values: Vec<f32> =
                            range.clone().map(|i| e.ty.get(bytes, i) as f32).collect();
                        if let Some(j) = values.iter().position(|v| !v.is_finite()) {
                            let i = first + j;
                            return Err(err(
                                path,
                                e.location + i * e.ty.size(),
                                format!("frame {k}: `{full}` of particle {i} is not finite"),
                            ));
                        }
                        values
                    }
                };
                Some(Attribute { name: full, values })
            } else {
                // The length of each particle's row (a velocity's speed).
                let m = index.chunk(k, &full).map_or(1, |e| e.m.max(1));
                let Some(e) = f.chunk(&full, m, false)? else {
                    let available = particle_chunks(index, k, n, false).join(" ");
                    return Err(err(
                        path,
                        0,
                        format!(
                            "frame {k}: no per-particle chunk `{full}` for the magnitude; \
                             available: {available}"
                        ),
                    ));
                };
                if e.ty == Ty::Char {
                    return Err(err(path, e.at, format!("`{full}` is text, not numbers")));
                }
                let bytes = &data[e.location..e.location + n * m * e.ty.size()];
                let mut values = Vec::with_capacity(range.len());
                for i in range.clone() {
                    let sum: f64 = (0..m)
                        .map(|j| {
                            let v = e.ty.get(bytes, i * m + j);
                            v * v
                        })
                        .sum();
                    if !sum.is_finite() {
                        return Err(err(
                            path,
                            e.location + i * m * e.ty.size(),
                            format!("frame {k}: `{full}` of particle {i} is not finite"),
                        ));
                    }
                    values.push(sum.sqrt() as f32);
                }
                Some(Attribute {
                    name: format!("|{full}|"),
                    values,
                })
            }
        }
    };
    progress.finish_stage();
    Ok(Frame {
        positions,
        species_index,
        species,
        attribute,
        radii,
        simulation_box: Some(index.simulation_box(path, data, k)?),
        timestep: index.recorded_timestep(data, k),
        time: None,
        units: None,
    })
}
