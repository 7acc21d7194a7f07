//! MegaMol particle list files (MMPLD, versions 1.0 to 1.3), so that MegaMol users can
//! bring their data over.
//!
//! Layout (little-endian throughout):
//! - a 60-byte header: `MMPLD\0`, the version as `100 · major + minor` (u16), the frame
//!   count (u32), the data's bounding box and a clipping box (6 f32 each, lower corner
//!   then upper);
//! - a seek table of one u64 byte offset per frame (writers add one more: the end);
//! - per frame: a timestamp (f32, version 1.2 and later), the number of particle lists
//!   (i32), and the lists. A list header holds the vertex type (u8: 1 xyz f32, 2 xyzr
//!   f32, 3 xyz i16, 4 xyz f64), the colour type (u8: 0 none, 1 rgb u8, 2 rgba u8,
//!   3 intensity f32, 4 rgb f32, 5 rgba f32, 6 rgba u16, 7 intensity f64), the global
//!   radius (f32, unless the vertices carry radii), the global colour (4 u8, colour type
//!   0) or the intensity range (2 f32, intensity types), the particle count (u64), and in
//!   version 1.3 the list's bounding box (6 f32). Interleaved particles follow: position
//!   (and radius), then colour. Version 1.1 appends a block of cluster information to
//!   each list (a u32 count and a u64 byte size, then that many bytes), which is skipped.
//!
//! How it maps: each list is a species named by its index (`0`, `1`, ..., numeric, so
//! they sort as numbers), with its global radius, or with the mean of its particles'
//! radii for `xyzr` lists; a radius of zero or below (a list's, or a particle's of an
//! `xyzr` list) is refused by the conversion unless `--radius` names the list. A list's
//! global colour (colour type 0) becomes its species' colour, as MegaMol draws it;
//! per-particle colours are not kept (a species has one colour). The attribute can be
//! `intensity` (intensity lists) or `radius` (`xyzr` lists). The frame's time is the timestamp, its box the file's bounding box (none where that is inverted or not finite); MMPLD
//! records no timestep (a batch numbers the frames by their position among its inputs).
//! Opening walks every frame's list headers with checked arithmetic, so counts and
//! offsets that point past the file are errors naming the byte before any particle is
//! read.

use std::ops::Range;
use std::path::Path;

use rayon::prelude::*;

use super::{FrameInfo, ReadError, ReadOptions};
use crate::frame::{Attribute, Frame, SimulationBox, SpeciesName};
use crate::progress::Progress;

const MAGIC: &[u8; 6] = b"MMPLD\0";
const HEADER: usize = 60;

pub(crate) fn sniff(data: &[u8]) -> bool {
    data.starts_with(MAGIC)
}

fn err(path: &Path, offset: usize, message: impl Into<String>) -> ReadError {
    ReadError::Binary {
        path: path.to_path_buf(),
        offset: offset as u64,
        message: message.into(),
    }
}

/// One particle list of a frame.
#[derive(Clone, Debug)]
struct List {
    /// Byte offset of the list header.
    at: usize,
    /// Byte offset of the first particle.
    data: usize,
    particles: usize,
    stride: usize,
    vertex: u8,
    colour: u8,
    /// The global radius (`xyzr` lists: none).
    radius: Option<f32>,
    /// The global colour (sRGB bytes) of a list whose particles carry no colour.
    global_colour: Option<[u8; 3]>,
}

impl List {
    fn has_radius(&self) -> bool {
        self.vertex == 2
    }

    fn has_intensity(&self) -> bool {
        matches!(self.colour, 3 | 7)
    }

    /// Coordinate `c` of particle `i`.
    fn coordinate(&self, data: &[u8], i: usize, c: usize) -> f64 {
        let at = self.data + i * self.stride;
        match self.vertex {
            3 => f64::from(i16::from_le_bytes(le(data, at + 2 * c))),
            4 => f64::from_le_bytes(le(data, at + 8 * c)),
            _ => f64::from(f32::from_le_bytes(le(data, at + 4 * c))),
        }
    }

    fn particle_radius(&self, data: &[u8], i: usize) -> f32 {
        f32::from_le_bytes(le(data, self.data + i * self.stride + 12))
    }

    /// Particle `i`'s own colour (colour types 1, 2, 4, 5 and 6), its sRGB channels in
    /// [0, 1] (alpha left out, floats clamped, NaN kept); `None` for other types.
    fn particle_colour(&self, data: &[u8], i: usize) -> Option<[f32; 3]> {
        let at = self.data + i * self.stride + vertex_size(self.vertex);
        let f = |k: usize| f32::from_le_bytes(le(data, at + 4 * k));
        let c = match self.colour {
            1 | 2 => [0, 1, 2].map(|k| f32::from(data[at + k]) / 255.0),
            4 | 5 => [f(0), f(1), f(2)],
            6 => [0, 1, 2].map(|k| f32::from(u16::from_le_bytes(le(data, at + 2 * k))) / 65535.0),
            _ => return None,
        };
        // (NaN stays NaN: such a particle has no colour to count.)
        Some(c.map(|v| if v.is_nan() { v } else { v.clamp(0.0, 1.0) }))
    }

    /// The mean colour of particles `lo..hi` of a list whose particles carry colours,
    /// averaged as light (in linear RGB), as sRGB bytes: the one colour its species is
    /// drawn in, exact where the list is of one colour.
    fn mean_colour(&self, data: &[u8], lo: usize, hi: usize) -> Option<[u8; 3]> {
        use crate::species::{linear_channel_to_srgb, srgb_channel_to_linear};
        let mut sum = [0f64; 3];
        let mut counted = 0usize;
        for i in lo..hi {
            let c = self.particle_colour(data, i)?;
            if c.iter().any(|v| v.is_nan()) {
                continue;
            }
            for k in 0..3 {
                sum[k] += f64::from(srgb_channel_to_linear(c[k]));
            }
            counted += 1;
        }
        if counted == 0 {
            return None;
        }
        Some(sum.map(|v| {
            let s = linear_channel_to_srgb((v / counted as f64) as f32);
            (s * 255.0).round().clamp(0.0, 255.0) as u8
        }))
    }

    fn intensity(&self, data: &[u8], i: usize) -> f64 {
        let at = self.data + i * self.stride + vertex_size(self.vertex);
        if self.colour == 7 {
            f64::from_le_bytes(le(data, at))
        } else {
            f64::from(f32::from_le_bytes(le(data, at)))
        }
    }
}

/// `N` bytes at `at` (the index checked every list lies inside the file).
fn le<const N: usize>(data: &[u8], at: usize) -> [u8; N] {
    let mut b = [0u8; N];
    b.copy_from_slice(&data[at..at + N]);
    b
}

fn vertex_size(v: u8) -> usize {
    match v {
        1 => 12,
        2 => 16,
        3 => 6,
        4 => 24,
        _ => 0,
    }
}

fn colour_size(c: u8) -> Option<usize> {
    Some(match c {
        0 => 0,
        1 => 3,
        2 => 4,
        3 => 4,
        4 => 12,
        5 => 16,
        6 => 8,
        7 => 8,
        _ => return None,
    })
}

#[derive(Clone, Debug)]
struct FrameIndex {
    timestamp: Option<f32>,
    lists: Vec<List>,
    /// Bytes between the end of the frame's lists and where the seek table says the
    /// frame ends, which MegaMol passes over (it reads a frame from its seek entry to the
    /// next): padding, or lists a header counting too few left out.
    trailing: usize,
}

/// The frames of an MMPLD file and where their lists are.
pub(crate) struct Index {
    bounding_box: [f32; 6],
    frames: Vec<FrameIndex>,
    /// A frame after complete ones that the file does not hold whole (a writer that
    /// stopped inside it, or before it: a seek-table entry past the end or still 0):
    /// counted as a frame, whose every read is a "truncated file?" error
    /// ([`ReadError::cut_short`]), so that a conversion of the last frame says so and a
    /// batch leaves it out with a note and converts the frames before it. Later frames
    /// of the table, not written either, are not counted.
    cut: Option<(usize, String)>,
}

/// A little-endian reader over the file that turns running off its end into an error.
struct Cursor<'a> {
    path: &'a Path,
    data: &'a [u8],
    at: usize,
}

impl<'a> Cursor<'a> {
    fn take<const N: usize>(&mut self, what: impl std::fmt::Display) -> Result<[u8; N], ReadError> {
        match self.data.get(self.at..self.at + N) {
            Some(b) => {
                self.at += N;
                Ok(le(b, 0))
            }
            None => Err(err(
                self.path,
                self.at,
                format!("file truncated in {what} ({} bytes)", self.data.len()),
            )),
        }
    }
}

/// Whether an error's `message` is a read past the end of the file (a header, a list's
/// particles or its cluster information).
fn runs_past_end(message: &str) -> bool {
    message.contains("run past the end of the file") || message.contains("file truncated in")
}

/// "the header of frame K, list L", written only into an error.
#[derive(Clone, Copy)]
struct ListHeader(usize, usize);

impl std::fmt::Display for ListHeader {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "the header of frame {}, list {}", self.0, self.1)
    }
}

impl Index {
    pub fn build(path: &Path, data: &[u8]) -> Result<Index, ReadError> {
        if !sniff(data) {
            return Err(err(path, 0, "not an MMPLD file (no `MMPLD` signature)"));
        }
        let mut c = Cursor { path, data, at: 6 };
        let version = u16::from_le_bytes(c.take("the header")?);
        if !(100..=103).contains(&version) {
            return Err(err(
                path,
                6,
                format!(
                    "MMPLD version {}.{} (versions 1.0 to 1.3 are read)",
                    version / 100,
                    version % 100
                ),
            ));
        }
        let frames = u32::from_le_bytes(c.take("the header")?) as usize;
        if frames == 0 {
            return Err(err(
                path,
                8,
                "the header counts no frames: the file holds none",
            ));
        }
        let mut bounding_box = [0f32; 6];
        for v in &mut bounding_box {
            *v = f32::from_le_bytes(c.take("the header")?);
        }
        c.at = HEADER;
        // The seek table must fit in the file before anything is allocated for it.
        let table_end = frames
            .checked_mul(8)
            .and_then(|b| b.checked_add(HEADER))
            .filter(|&e| e <= data.len())
            .ok_or_else(|| {
                err(
                    path,
                    8,
                    format!("{frames} frames, but the file is too short for their seek table"),
                )
            })?;
        let mut offsets = Vec::with_capacity(frames);
        // A frame the file does not hold whole, after complete ones: see `Index::cut`.
        let mut cut = None;
        for k in 0..frames {
            let at = c.at;
            let entry = u64::from_le_bytes(c.take("the seek table")?);
            let o = usize::try_from(entry)
                .ok()
                .filter(|&o| o >= table_end && o < data.len());
            match o {
                Some(o) => offsets.push(o),
                None => {
                    let why = if entry == 0 {
                        format!(
                            "frame {k}'s seek-table entry is 0: the writer stopped before \
                             writing it?"
                        )
                    } else if entry >= data.len() as u64 {
                        format!(
                            "frame {k} starts at byte {entry}, past the file's end (byte {}): \
                             the file is cut short?",
                            data.len()
                        )
                    } else {
                        format!(
                            "frame {k} starts at byte {entry}, inside the header or the seek \
                             table (which end at byte {table_end})"
                        )
                    };
                    if k == 0 || entry != 0 && entry < data.len() as u64 {
                        return Err(err(path, at, why));
                    }
                    cut = Some((at, why));
                    break;
                }
            }
        }
        let mut out = Vec::with_capacity(frames);
        // Where the previous frame's lists end: frames follow one another, so that every
        // byte is walked once. (Seek entries pointing into one frame again and again made
        // a small file stand for billions of lists.)
        let mut previous_end = table_end;
        for (k, &start) in offsets.iter().enumerate() {
            // The last frame the file holds, or the frame before a cut one: a read past
            // the file's end inside it is a frame cut short, after complete ones.
            let last = k + 1 == offsets.len();
            let frame = Self::frame_at(
                path,
                data,
                version,
                &offsets,
                table_end,
                k,
                start,
                previous_end,
            );
            let (frame, end) = match frame {
                Ok(f) => f,
                Err(ReadError::Binary {
                    offset, message, ..
                }) if last && k > 0 && runs_past_end(&message) => {
                    // (Frames the seek table names after it, not written at all, are not
                    // counted: the first frame not whole is the one cut short.)
                    cut = Some((offset as usize, message));
                    break;
                }
                Err(e) => return Err(e),
            };
            previous_end = end;
            out.push(frame);
        }
        Ok(Index {
            bounding_box,
            frames: out,
            cut,
        })
    }

    /// Frame `k`, starting at byte `start` (the previous frame ends at `previous_end`),
    /// and where its lists end.
    #[allow(clippy::too_many_arguments)]
    fn frame_at(
        path: &Path,
        data: &[u8],
        version: u16,
        offsets: &[usize],
        table_end: usize,
        k: usize,
        start: usize,
        previous_end: usize,
    ) -> Result<(FrameIndex, usize), ReadError> {
        {
            if start < previous_end {
                return Err(err(
                    path,
                    HEADER + 8 * k,
                    format!(
                        "frame {k} starts at byte {start}, before the end of frame {} \
                         (byte {previous_end}): frames must follow one another",
                        k.saturating_sub(1)
                    ),
                ));
            }
            let mut c = Cursor {
                path,
                data,
                at: start,
            };
            let timestamp = if version >= 102 {
                let t = f32::from_le_bytes(c.take("a frame header")?);
                if !t.is_finite() {
                    return Err(err(
                        path,
                        start,
                        format!("frame {k}: timestamp {t} is not a finite number"),
                    ));
                }
                Some(t)
            } else {
                None
            };
            let lists_at = c.at;
            let count = i32::from_le_bytes(c.take("a frame header")?);
            let count = usize::try_from(count).map_err(|_| {
                err(
                    path,
                    lists_at,
                    format!("frame {k} has {count} particle lists"),
                )
            })?;
            let mut lists = Vec::new();
            for l in 0..count {
                let at = c.at;
                let header = ListHeader(k, l);
                let [vertex, colour] = c.take::<2>(header)?;
                let vsize = vertex_size(vertex);
                let csize = colour_size(colour);
                let Some(csize) = csize.filter(|_| vsize > 0) else {
                    return Err(err(
                        path,
                        at,
                        format!(
                            "frame {k}, list {l}: vertex type {vertex} / colour type {colour} \
                             (positions of type 1 to 4 and colours of type 0 to 7 are read)"
                        ),
                    ));
                };
                let radius = if vertex == 2 {
                    None
                } else {
                    Some(f32::from_le_bytes(c.take(header)?))
                };
                let mut global_colour = None;
                match colour {
                    0 => {
                        let [r, g, b, _] = c.take::<4>(header)?;
                        global_colour = Some([r, g, b]);
                    }
                    3 | 7 => {
                        c.take::<8>(header)?;
                    }
                    _ => {}
                }
                let count_at = c.at;
                let particles = u64::from_le_bytes(c.take(header)?);
                if version == 103 {
                    c.take::<24>(header)?;
                }
                let stride = vsize + csize;
                let end = usize::try_from(particles)
                    .ok()
                    .and_then(|n| n.checked_mul(stride))
                    .and_then(|b| b.checked_add(c.at))
                    .filter(|&e| e <= data.len())
                    .ok_or_else(|| {
                        err(
                            path,
                            count_at,
                            format!(
                                "frame {k}, list {l}: {particles} particles of {stride} bytes \
                                 run past the end of the file"
                            ),
                        )
                    })?;
                // (Zero and below are refused where the radius is used, unless overridden.)
                if let Some(r) = radius.filter(|r| !r.is_finite()) {
                    return Err(err(
                        path,
                        at + 2,
                        format!("frame {k}, list {l}: radius {r}"),
                    ));
                }
                lists.push(List {
                    at,
                    data: c.at,
                    particles: particles as usize,
                    stride,
                    vertex,
                    colour,
                    radius,
                    global_colour,
                });
                c.at = end;
                if version == 101 {
                    // Cluster information, skipped.
                    c.take::<4>("cluster information")?;
                    let size_at = c.at;
                    let size = u64::from_le_bytes(c.take("cluster information")?);
                    c.at = usize::try_from(size)
                        .ok()
                        .and_then(|s| s.checked_add(c.at))
                        .filter(|&e| e <= data.len())
                        .ok_or_else(|| {
                            err(
                                path,
                                size_at,
                                format!("frame {k}, list {l}: {size} bytes of cluster information run past the end of the file"),
                            )
                        })?;
                }
            }
            let total = lists
                .iter()
                .try_fold(0usize, |t, l| t.checked_add(l.particles));
            if total.is_none_or(|t| t > u32::MAX as usize) {
                return Err(err(
                    path,
                    start,
                    format!("frame {k} holds more than 2^32 particles"),
                ));
            }
            // Where the seek table says the frame ends (the next frame's start, or for the
            // last frame the end entry writers add, where the table has room for it):
            // lists ending before it leave bytes MegaMol passes over (padding, or the
            // lists of a count too low), noted.
            let seek_end = match offsets.get(k + 1) {
                Some(&next) => Some(next),
                None if offsets.first().is_some_and(|&f| f >= table_end + 8) => {
                    usize::try_from(u64::from_le_bytes(le(data, table_end)))
                        .ok()
                        .filter(|&e| e <= data.len())
                }
                None => None,
            };
            // The end entry (last frame) before where the lists end: a list count too
            // high, or a table written wrong. (0: a writer that leaves it out.)
            if let Some(end) =
                seek_end.filter(|&e| offsets.get(k + 1).is_none() && e != 0 && e < c.at)
            {
                return Err(err(
                    path,
                    table_end,
                    format!(
                        "the seek table's end entry says frame {k} ends at byte {end}, but its \
                         lists ({count}, as the frame header counts them) end at byte {} \
                         (a damaged table, or a wrong list count?)",
                        c.at
                    ),
                ));
            }
            // Bytes after the lists up to the frame's end: passed over, as MegaMol does,
            // with a note ([`Index::trailing`]).
            let trailing = seek_end.map_or(0, |e| e.saturating_sub(c.at));
            Ok((
                FrameIndex {
                    timestamp,
                    lists,
                    trailing,
                },
                c.at + trailing,
            ))
        }
    }

    /// The bytes between frame `k`'s lists and its end, which the reading passes over as
    /// MegaMol does (0 for most files).
    pub fn trailing(&self, k: usize) -> usize {
        self.frames.get(k).map_or(0, |f| f.trailing)
    }

    /// The frames, the one cut short included ([`Index::cut`]).
    pub fn len(&self) -> usize {
        self.frames.len() + usize::from(self.cut.is_some())
    }

    /// Frame `k`; for the frame cut short, the error saying so.
    fn frame(&self, path: &Path, k: usize) -> Result<&FrameIndex, ReadError> {
        match (self.frames.get(k), &self.cut) {
            (Some(f), _) => Ok(f),
            (None, Some((at, why))) if k == self.frames.len() => {
                Err(err(path, *at, format!("{why} (truncated file?)")))
            }
            _ => Err(ReadError::NoSuchFrame {
                path: path.to_path_buf(),
                frame: k,
                count: self.len(),
            }),
        }
    }

    fn particles(f: &FrameIndex) -> usize {
        f.lists.iter().map(|l| l.particles).sum()
    }

    /// The header's bounding box as the frames' box; none where it is not one (a
    /// corner not finite, or the lower above the upper: a writer's "unset" box, or
    /// damage), so that no cell is drawn inverted.
    fn simulation_box(&self) -> Option<SimulationBox> {
        let b = self.bounding_box.map(f64::from);
        let valid = b.iter().all(|v| v.is_finite()) && (0..3).all(|k| b[k] <= b[k + 3]);
        // It bounds the data rather than being a periodic cell: `--wrap` leaves it alone.
        valid.then(|| SimulationBox {
            periodic: Some([false; 3]),
            ..SimulationBox::orthogonal([b[0], b[1], b[2]], [b[3], b[4], b[5]])
        })
    }
}

pub(crate) fn frame_info(path: &Path, index: &Index, k: usize) -> Result<FrameInfo, ReadError> {
    let f = index.frame(path, k)?;
    let mut columns: Vec<String> = ["x", "y", "z"].map(String::from).to_vec();
    if f.lists.iter().any(List::has_radius) {
        columns.push("radius".into());
    }
    if f.lists.iter().any(List::has_intensity) {
        columns.push("intensity".into());
    }
    Ok(FrameInfo {
        particles: Index::particles(f),
        timestep: None,
        time: f.timestamp.map(f64::from),
        units: None,
        simulation_box: index.simulation_box(),
        columns,
    })
}

/// The species of particles `range` of frame `k`: one per list, with its global radius,
/// or for `xyzr` lists the mean radius of its particles in the range (the first radius of
/// zero or below where there is one, which the conversion refuses unless overridden).
fn species_of(
    path: &Path,
    data: &[u8],
    index: &Index,
    k: usize,
    range: Range<usize>,
) -> Result<Vec<SpeciesName>, ReadError> {
    let mut first = 0usize;
    index
        .frame(path, k)?
        .lists
        .iter()
        .enumerate()
        .map(|(l, list)| {
            let lo = range.start.max(first).min(first + list.particles) - first;
            let hi = range.end.max(first).min(first + list.particles) - first;
            first += list.particles;
            let mut spread: Option<(f32, f32)> = None;
            let radius = match list.radius {
                Some(r) => r,
                None => {
                    let mut sum = 0f64;
                    let mut bad = None;
                    for i in lo..hi {
                        let r = list.particle_radius(data, i);
                        if !r.is_finite() {
                            return Err(err(
                                path,
                                list.data + i * list.stride + 12,
                                format!("frame {k}, list {l}: particle {i} has radius {r}"),
                            ));
                        }
                        if r <= 0.0 {
                            bad.get_or_insert(r);
                        }
                        sum += f64::from(r);
                        spread = Some(spread.map_or((r, r), |(a, b)| (a.min(r), b.max(r))));
                    }
                    if let Some(r) = bad {
                        r
                    } else if hi > lo {
                        (sum / (hi - lo) as f64) as f32
                    } else {
                        0.5
                    }
                }
            };
            Ok(SpeciesName {
                name: l.to_string(),
                numeric_type: true,
                // A list without particles draws nothing: a radius of zero there is no
                // reason to refuse the frame (the default stands in).
                radius: (list.particles > 0 || radius > 0.0).then_some(radius),
                radius_range: spread,
                colour: list
                    .global_colour
                    .or_else(|| list.mean_colour(data, lo, hi)),
                palette_slot: None,
                sized_count: 0,
                sized_sum: 0.0,
            })
        })
        .collect()
}

/// The species of frame `k` as the whole frame lists them (radii of `xyzr` lists averaged
/// over the whole list): what every part read by [`read_range`] takes, so that a frame
/// read in parts converts as the whole one does.
pub(crate) fn frame_species(
    path: &Path,
    data: &[u8],
    index: &Index,
    k: usize,
) -> Result<Vec<SpeciesName>, ReadError> {
    let particles = Index::particles(index.frame(path, k)?);
    species_of(path, data, index, k, 0..particles)
}

/// The attribute `opts` asks for: `intensity`, `radius` or none; another name is an error.
fn wanted(
    path: &Path,
    index: &Index,
    k: usize,
    opts: &ReadOptions,
) -> Result<Option<&'static str>, ReadError> {
    match opts.attribute.as_deref() {
        None => Ok(None),
        Some("intensity") => Ok(Some("intensity")),
        Some("radius") => Ok(Some("radius")),
        Some(other) => Err(err(
            path,
            0,
            format!(
                "no per-particle `{other}` in MMPLD; available: {}",
                frame_info(path, index, k)?.columns.join(" ")
            ),
        )),
    }
}

impl Index {
    /// The lists of frame `k` whose particles carry colours of their own (colour types
    /// 1, 2, 4, 5 and 6), which a species' one colour does not keep.
    pub(crate) fn coloured_lists(&self, k: usize) -> Vec<usize> {
        self.frames.get(k).map_or(vec![], |f| {
            f.lists
                .iter()
                .enumerate()
                .filter(|(_, l)| l.particles > 0 && matches!(l.colour, 1 | 2 | 4 | 5 | 6))
                .map(|(i, _)| i)
                .collect()
        })
    }
}

/// Whether `list` gives the attribute `a` (`intensity` or `radius`) for its particles:
/// per particle, or (a radius) one for the whole list, which each of them takes.
fn carries(list: &List, a: &str) -> bool {
    if a == "radius" {
        list.has_radius() || list.radius.is_some()
    } else {
        list.has_intensity()
    }
}

/// The error for list `l` of frame `k`, which lacks the attribute `a`.
fn lacks(path: &Path, k: usize, l: usize, list: &List, a: &str) -> ReadError {
    err(
        path,
        list.at,
        format!("frame {k}, list {l} has no per-particle `{a}`"),
    )
}

/// The name of the attribute `opts` asks of frame `k` (`None`: none), or the error
/// reading the frame with it gives (a list holding particles without it), without
/// reading a particle.
pub(crate) fn attribute_name(
    path: &Path,
    index: &Index,
    k: usize,
    opts: &ReadOptions,
) -> Result<Option<String>, ReadError> {
    let want = wanted(path, index, k, opts)?;
    if let Some(a) = want {
        for (l, list) in index.frame(path, k)?.lists.iter().enumerate() {
            if list.particles > 0 && !carries(list, a) {
                return Err(lacks(path, k, l, list, a));
            }
        }
    }
    Ok(want.map(String::from))
}

/// Reads particles `range` of frame `k` (the lists one after another) as a frame of its
/// own: every list a species, `xyzr` lists with the mean radius of their particles in the
/// range (see [`frame_species`] for the whole frame's) and each particle with its own
/// radius where some list is of `xyzr` particles (the others at their list's).
pub(crate) fn read_range(
    path: &Path,
    data: &[u8],
    index: &Index,
    k: usize,
    opts: &ReadOptions,
    range: Range<usize>,
    progress: &dyn Progress,
) -> Result<Frame, ReadError> {
    let f = index.frame(path, k)?;
    let want = wanted(path, index, k, opts)?;
    if f.lists.len() > 1 << 16 {
        return Err(err(
            path,
            f.lists.first().map_or(0, |l| l.at),
            format!(
                "frame {k} has {} lists (at most 65536 species)",
                f.lists.len()
            ),
        ));
    }
    progress.stage(
        &format!("reading frame {k}"),
        Some(range.len() as u64),
        "particles",
    );
    let mut positions = Vec::with_capacity(range.len());
    let mut species_index = Vec::with_capacity(range.len());
    let mut values = Vec::new();
    // Each particle's own radius where some list is of `xyzr` particles, unless sizes are
    // left out (--no-sizes: each list at its mean).
    let sized = opts.sizes != super::SizeColumn::Off && f.lists.iter().any(|l| l.has_radius());
    let mut radii = Vec::new();
    let mut first = 0usize;
    for (l, list) in f.lists.iter().enumerate() {
        let lo = range.start.max(first);
        let hi = range.end.min(first + list.particles);
        first += list.particles;
        if lo >= hi {
            continue;
        }
        let local = lo - (first - list.particles)..hi - (first - list.particles);
        let part = super::decode_positions(
            local.len(),
            |i, c| (local.start + i) * 3 + c,
            |j| list.coordinate(data, j / 3, j % 3),
        )
        .map_err(|(j, v)| {
            err(
                path,
                list.data + (j / 3) * list.stride,
                format!(
                    "frame {k}, list {l}: particle {} has a position that is not finite{}",
                    j / 3,
                    super::single_precision_note(v)
                ),
            )
        })?;
        positions.extend(part);
        species_index.extend(std::iter::repeat_n(l as u16, local.len()));
        if sized {
            if list.has_radius() {
                let own: Vec<f32> = local
                    .clone()
                    .into_par_iter()
                    .map(|i| list.particle_radius(data, i))
                    .collect();
                radii.extend(own);
            } else {
                radii.extend(std::iter::repeat_n(list.radius.unwrap_or(0.0), local.len()));
            }
        }
        if let Some(a) = want {
            if !carries(list, a) {
                return Err(lacks(path, k, l, list, a));
            }
            let v: Vec<f32> = local
                .clone()
                .into_par_iter()
                .map(|i| {
                    if a == "radius" {
                        match list.radius {
                            Some(r) if !list.has_radius() => r,
                            _ => list.particle_radius(data, i),
                        }
                    } else {
                        list.intensity(data, i) as f32
                    }
                })
                .collect();
            if let Some(j) = v.iter().position(|x| !x.is_finite()) {
                let i = local.start + j;
                return Err(err(
                    path,
                    list.data + i * list.stride,
                    format!("frame {k}, list {l}: `{a}` of particle {i} is not finite"),
                ));
            }
            values.extend(v);
        }
    }
    let species = species_of(path, data, index, k, range.clone())?;
    progress.advance(range.len() as u64);
    progress.finish_stage();
    Ok(Frame {
        positions,
        species_index,
        species,
        attribute: want.map(|a| Attribute {
            name: a.to_string(),
            values,
        }),
        radii: sized.then_some(radii),
        simulation_box: index.simulation_box(),
        timestep: None,
        time: f.timestamp.map(f64::from),
        units: None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_list_of_two_colours_is_drawn_in_their_mean_as_light() {
        // Two particles of vertex type 1 (three f32) and colour type 1 (RGB bytes): red
        // and blue. Their mean as light is half of each, (188, 0, 188) in sRGB, not the
        // (128, 0, 128) of the bytes' mean.
        let mut data = vec![0u8; 2 * 15];
        data[12..15].copy_from_slice(&[255, 0, 0]);
        data[27..30].copy_from_slice(&[0, 0, 255]);
        let list = List {
            at: 0,
            data: 0,
            particles: 2,
            stride: 15,
            vertex: 1,
            colour: 1,
            radius: Some(1.0),
            global_colour: None,
        };
        assert_eq!(list.mean_colour(&data, 0, 2), Some([188, 0, 188]));
        assert_eq!(list.mean_colour(&data, 1, 2), Some([0, 0, 255]));
        assert_eq!(list.mean_colour(&data, 1, 1), None);
        // Colours that are no numbers are left out of the mean; a list of none has none
        // (a palette colour stands in).
        let mut floats = vec![0u8; 2 * 24];
        for (k, v) in [f32::NAN, 0.0, 0.0, 0.0, 0.0, 1.0].iter().enumerate() {
            let at = 12 * (k / 3 + 1) + 4 * (k % 3) + 12 * (k / 3);
            floats[at..at + 4].copy_from_slice(&v.to_le_bytes());
        }
        let rgb = List {
            stride: 24,
            colour: 4,
            ..list.clone()
        };
        assert_eq!(rgb.mean_colour(&floats, 0, 2), Some([0, 0, 255]));
        assert_eq!(rgb.mean_colour(&floats, 0, 1), None);
        let intensity = List { colour: 3, ..list };
        assert_eq!(intensity.mean_colour(&data, 0, 2), None);
    }
}
