//! Out-of-core conversion: a frame of more than `chunk_points` particles is built in
//! spatial chunks, so that memory stays within a limit whatever the frame's size.
//!
//! How it works:
//! 1. **Partition**, one pass over the input a window of particles at a time. Every
//!    particle goes to one cell of an 8×8×8 grid over the box (finer for frames of more
//!    than 64 chunks: [`first_bits`]; the dump's box, or the particles' bounds when it
//!    has none; particles outside it go to the nearest cell) and is appended to that
//!    cell's working file: position, species, attribute, radius and further
//!    attributes (each read by a pass of its own on a thread of its own, in step with
//!    the particles' windows). A thread of its own sorts
//!    each window by cell and writes it while the next window is read. A cell that ends
//!    with more than `chunk_points` particles is split the same way over its own bounds,
//!    by a grid only as fine as its count needs ([`refine_bits`]; by file order when all
//!    its particles coincide). The leaf cells, in Morton order, are grouped greedily into
//!    chunks of at most `chunk_points` particles.
//! 2. **Chunks.** A reader thread loads the chunks' cells in order, one chunk ahead of
//!    the builds. Each chunk is built into a complete hierarchy by the
//!    in-memory builder ([`crate::hierarchy::build_with`]), as many chunks at a time as
//!    the memory limit allows. Its node table, quantized positions and per-particle data
//!    stay in memory while the limit has room beside the builds at work, and go to
//!    working files otherwise; its cell files are removed. Further attributes are laid
//!    out and averaged per chunk ([`crate::hierarchy::extra`]) over the frame's ranges,
//!    and their roots' sums kept for the top node.
//! 3. **Assembly.** The chunk roots become the children of one top node, in chunk order.
//!    Chunks whose hierarchy is shallower than the deepest are padded under the top with
//!    single-child copies of their root, so that every particle lies on the last level.
//!    The file is then written level by level: node records are copied with their
//!    indices rebased, quantized positions are copied unchanged except on the levels the
//!    top node encodes (re-encoded from the kept unquantized positions), and each working
//!    file is removed as soon as its last part is copied. The file goes out through a
//!    writing thread of its own with direct I/O ([`crate::direct::DirectSink`]).
//!
//! Which chunks' results stay in memory depends on timing; the file never does.
//!
//! The file depends only on the input and `chunk_points` (recorded in the metadata):
//! never on the memory limit or the thread count, which only decide how many chunks are
//! built at once. Working files live in a fresh directory inside
//! [`ChunkOptions::temp_dir`], removed on success and on failure.

use std::collections::HashMap;
use std::fs::{self, File};
use std::io::{BufWriter, Write};
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::time::Instant;

use mdlod_format::layout::{LevelRecord, NodeRecord, SectionKind};
use mdlod_format::meta::{AttributeInfo, Metadata, SimulationBox};
use mdlod_format::{quantize, Writer};
use rayon::prelude::*;

use crate::convert::{ConvertError, ConvertOptions, ConvertReport};
use crate::frame::{Frame, SpeciesName};
use crate::hierarchy::pca_split::Clusters;
use crate::hierarchy::representative::{representatives, LevelPoints, Rep, Source};
use crate::hierarchy::{
    build_with, check_species, position_in_range, BuildError, BuildExtras, Particles, MAX_SPECIES,
};
use crate::progress::{NoProgress, Progress};
use crate::species::species_table;

/// Frames above this many particles are built in chunks of at most this many.
pub const DEFAULT_CHUNK_POINTS: usize = 1 << 22;
/// Working memory of the in-memory builder per particle (measured peak, with margin).
pub const BUILD_BYTES_PER_PARTICLE: u64 = 110;
/// Particles read from the input per window.
const WINDOW: usize = 1 << 22;
/// Cells per axis of a refining partition step, and of the first one for frames of up to
/// 64 chunks' worth of particles ([`first_bits`]), as a power of two.
const GRID_BITS: u32 = 3;
/// The finest first grid: 32×32×32 cells (their ids fit the `u16` of the sort).
const MAX_FIRST_BITS: u32 = 5;

/// Bits per axis of the first partition grid for `count` particles and chunks of `max`:
/// the coarsest grid, 8×8×8 upward, whose cells hold at most an eighth of a chunk on
/// average. A coarser grid leaves most particles in cells too large for a chunk, which
/// go through a second pass (read back and written again); at 10^9 particles that pass
/// was the larger part of the partition.
fn first_bits(count: usize, max: usize) -> u32 {
    let mut bits = GRID_BITS;
    while bits < MAX_FIRST_BITS && (count as u128) * 8 > (max as u128) << (3 * bits) {
        bits += 1;
    }
    bits
}

/// Bits per axis of the grid a cell of `count` particles is split by, when it holds more
/// than `max`: the coarsest grid (2×2×2 upward, at most the partition's own) whose cells
/// hold at most a sixteenth of `max` on average, so that one more pass almost always
/// suffices however uneven the particles. Finer than needed, the split would leave
/// thousands of tiny cells to write and read back one by one.
fn refine_bits(count: usize, max: usize) -> u32 {
    let mut bits = 1;
    while bits < GRID_BITS && (count as u128) * 16 > (max as u128) << (3 * bits) {
        bits += 1;
    }
    bits
}
/// Deeper splits than this go by order (no spatial progress is left in `f32`).
const MAX_SPLIT_DEPTH: u32 = 10;

/// How a chunked conversion runs.
#[derive(Clone, Debug)]
pub struct ChunkOptions {
    /// Frames above this many particles are built in chunks of at most this many.
    pub chunk_points: usize,
    /// Working memory the conversion may use, in bytes.
    pub memory_limit: u64,
    /// Directory for working files (a fresh subdirectory is made and removed); `None`:
    /// the output's directory.
    pub temp_dir: Option<PathBuf>,
    /// Particles read from the input at a time (the file does not depend on it).
    pub window_points: usize,
    /// Largest gzip input (compressed bytes) decompressed in memory; a larger one, or one
    /// whose text is more than 4 times this ([`Self::gzip_text_in_memory_max`]), is
    /// decompressed into a working file and read from there a window at a time. `None`:
    /// an eighth of `memory_limit` (text compresses about 4×, and its text should take
    /// at most half the limit).
    pub gzip_in_memory: Option<u64>,
}

impl Default for ChunkOptions {
    /// Chunks of [`DEFAULT_CHUNK_POINTS`], half of the process's memory ([`default_memory_limit`]), working files
    /// next to the output.
    fn default() -> Self {
        ChunkOptions {
            chunk_points: DEFAULT_CHUNK_POINTS,
            memory_limit: default_memory_limit(),
            temp_dir: None,
            window_points: WINDOW,
            gzip_in_memory: None,
        }
    }
}

impl ChunkOptions {
    /// The directory working files go to when writing `output`.
    /// The largest gzip input decompressed in memory (see [`Self::gzip_in_memory`]).
    pub fn gzip_in_memory_max(&self) -> u64 {
        self.gzip_in_memory.unwrap_or(self.memory_limit / 8)
    }

    /// The most text of gzip inputs held in memory: 4 × [`Self::gzip_in_memory_max`]
    /// (the usual ratio of text). A small input that decompresses to more (a high ratio)
    /// is decompressed into a working file instead, as a large one is.
    pub fn gzip_text_in_memory_max(&self) -> u64 {
        self.gzip_in_memory_max().saturating_mul(4)
    }

    pub fn temp_dir_for(&self, output: &Path) -> PathBuf {
        match (&self.temp_dir, output.parent()) {
            (Some(d), _) => d.clone(),
            (None, Some(d)) if !d.as_os_str().is_empty() => d.to_path_buf(),
            _ => PathBuf::from("."),
        }
    }
}

/// Half of the memory this process may have (Linux): the machine's physical memory, or
/// less where its control group is limited (a Slurm job's allocation, a container's);
/// 4 GiB when neither can be read.
pub fn default_memory_limit() -> u64 {
    let total = fs::read_to_string("/proc/meminfo").ok().and_then(|s| {
        s.lines()
            .find(|l| l.starts_with("MemTotal:"))
            .and_then(|l| l.split_whitespace().nth(1)?.parse::<u64>().ok())
            .map(|kib| kib.saturating_mul(1024))
    });
    let cgroup = fs::read_to_string("/proc/self/cgroup")
        .ok()
        .and_then(|groups| cgroup_memory_limit(&groups, &|p| fs::read_to_string(p).ok()));
    match (total, cgroup) {
        (Some(t), Some(c)) => t.min(c) / 2,
        (Some(m), None) | (None, Some(m)) => m / 2,
        (None, None) => 4 << 30,
    }
}

/// The tightest memory limit of the control groups a process is in (`groups`: its
/// `/proc/self/cgroup`), over every group from its own up to the root: cgroup v2's
/// `memory.max`, v1's `memory.limit_in_bytes` (whose "unlimited" is a number near 2^63,
/// ignored above 2^60). `read` reads a file.
fn cgroup_memory_limit(groups: &str, read: &dyn Fn(&str) -> Option<String>) -> Option<u64> {
    let mut limits = Vec::new();
    for line in groups.lines() {
        let mut parts = line.splitn(3, ':');
        let (Some(_), Some(controllers), Some(path)) = (parts.next(), parts.next(), parts.next())
        else {
            continue;
        };
        let (root, file) = if controllers.is_empty() {
            ("/sys/fs/cgroup", "memory.max")
        } else if controllers.split(',').any(|c| c == "memory") {
            ("/sys/fs/cgroup/memory", "memory.limit_in_bytes")
        } else {
            continue;
        };
        let mut dir = path.trim_end_matches('/').to_string();
        loop {
            let limit = read(&format!("{root}{dir}/{file}"))
                .and_then(|v| v.trim().parse::<u64>().ok())
                .filter(|&v| v < 1 << 60);
            limits.extend(limit);
            match dir.rfind('/') {
                Some(i) => dir.truncate(i),
                None => break,
            }
        }
    }
    limits.into_iter().min()
}

/// The working memory one chunk of `points` particles needs, in bytes.
pub fn chunk_memory(points: usize) -> u64 {
    chunk_memory_with(points, 0)
}

/// [`chunk_memory`] of a chunk keeping `extras` further attributes.
pub fn chunk_memory_with(points: usize, extras: usize) -> u64 {
    points as u64 * build_bytes_per_particle(extras) + (64 << 20)
}

/// Working memory of the in-memory builder per particle, with `extras` further
/// attributes: each adds its column as read and in the file's order (f32 each), its
/// quantized values and its nodes' means (about 12 bytes a particle), and all of them
/// the particles' areas (f64) and the nodes' runs (about 16 bytes a particle).
pub fn build_bytes_per_particle(extras: usize) -> u64 {
    match extras {
        0 => BUILD_BYTES_PER_PARTICLE,
        k => BUILD_BYTES_PER_PARTICLE + 16 + 12 * k as u64,
    }
}

/// A chunk size within `limit` (see [`chunk_memory`]) to suggest: the most particles a
/// chunk may hold, rounded down to two significant digits but never below the build's
/// `root_points`; `None` where not even chunks of the root points fit.
pub(crate) fn chunk_points_within(limit: u64, root_points: u32, extras: usize) -> Option<u64> {
    let points = limit.saturating_sub(chunk_memory(0)) / build_bytes_per_particle(extras);
    let least = u64::from(root_points);
    (points >= least).then(|| {
        let unit = 10u64.pow(points.max(1).ilog10().saturating_sub(1));
        (points / unit * unit).max(least)
    })
}

/// [`size_text`] of a need, rounded up to a whole MiB (from 1 MiB on), so that a limit
/// below it never reads as equal to it (64 MiB "below the 64.0 MiB" needed).
pub(crate) fn need_text(bytes: u64) -> String {
    if bytes < 1 << 20 {
        size_text(bytes)
    } else {
        size_text(bytes.next_multiple_of(1 << 20))
    }
}

/// A size for a message: bytes below a MiB (a limit of `1K` is not "0 MiB"), else MiB.
pub(crate) fn size_text(bytes: u64) -> String {
    if bytes < 1 << 20 {
        format!("{bytes} bytes")
    } else if bytes.is_multiple_of(1 << 20) {
        format!("{} MiB", bytes >> 20)
    } else {
        format!("{:.1} MiB", bytes as f64 / f64::from(1 << 20))
    }
}

/// Where a chunked conversion reads particles from, a range at a time.
pub trait ParticleSource: Sync {
    /// Number of particles in the frame.
    fn len(&self) -> usize;
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// The frame's box, when known.
    fn simulation_box(&self) -> Option<&SimulationBox>;
    /// Calls `f` for consecutive windows of at most `window` particles, in order: the
    /// index of the window's first particle, and its particles as a frame of their own
    /// (with its own species list).
    fn windows(&self, window: usize, f: &mut WindowFn<'_>) -> Result<(), ConvertError>;
    /// The further attributes kept beside the first (`--attribute` given more than
    /// once), in order.
    fn extra_attributes(&self) -> Vec<String> {
        Vec::new()
    }
    /// Calls `f` for the windows [`Self::windows`] gives, with further attribute `k`'s
    /// values instead of the particles (a pass of its own over the input, as a frame
    /// built whole reads each further attribute).
    fn extra_windows(
        &self,
        k: usize,
        window: usize,
        f: &mut ExtraWindowFn<'_>,
    ) -> Result<(), ConvertError> {
        let _ = (window, f);
        Err(ConvertError::Chunked(format!(
            "this input has no further attribute {k}"
        )))
    }
}

/// The callback of [`ParticleSource::extra_windows`].
pub type ExtraWindowFn<'a> =
    dyn FnMut(usize, crate::frame::Attribute) -> Result<(), ConvertError> + 'a;

/// The callback of [`ParticleSource::windows`].
pub type WindowFn<'a> = dyn FnMut(usize, Frame) -> Result<(), ConvertError> + 'a;

/// [`ParticleSource::windows`] of a source that reads any range.
fn windows_by_range(
    n: usize,
    window: usize,
    f: &mut WindowFn<'_>,
    read: impl Fn(Range<usize>) -> Result<Frame, ConvertError>,
) -> Result<(), ConvertError> {
    for start in (0..n).step_by(window.max(1)) {
        f(start, read(start..(start + window).min(n))?)?;
    }
    Ok(())
}

/// A frame already in memory, with the further attributes read beside it.
pub struct FrameSource<'a>(pub &'a Frame, pub &'a [crate::frame::Attribute]);

impl ParticleSource for FrameSource<'_> {
    fn len(&self) -> usize {
        self.0.len()
    }

    fn simulation_box(&self) -> Option<&SimulationBox> {
        self.0.simulation_box.as_ref()
    }

    fn windows(&self, window: usize, f: &mut WindowFn<'_>) -> Result<(), ConvertError> {
        windows_by_range(self.len(), window, f, |r| Ok(self.read(r)))
    }

    fn extra_attributes(&self) -> Vec<String> {
        self.1.iter().map(|a| a.name.clone()).collect()
    }

    fn extra_windows(
        &self,
        k: usize,
        window: usize,
        f: &mut ExtraWindowFn<'_>,
    ) -> Result<(), ConvertError> {
        let a = self.1.get(k).ok_or_else(|| {
            ConvertError::Chunked(format!("this frame has no further attribute {k}"))
        })?;
        for start in (0..self.len()).step_by(window.max(1)) {
            let end = (start + window).min(self.len());
            let values = a.values.get(start..end).ok_or_else(|| {
                ConvertError::Chunked(format!(
                    "attribute {} has {} values for {} particles",
                    a.name,
                    a.values.len(),
                    self.len()
                ))
            })?;
            f(
                start,
                crate::frame::Attribute {
                    name: a.name.clone(),
                    values: values.to_vec(),
                },
            )?;
        }
        Ok(())
    }
}

impl FrameSource<'_> {
    fn read(&self, range: Range<usize>) -> Frame {
        let f = self.0;
        Frame {
            positions: f.positions[range.clone()].to_vec(),
            species_index: f.species_index[range.clone()].to_vec(),
            species: f.species.clone(),
            attribute: f.attribute.as_ref().map(|a| crate::frame::Attribute {
                name: a.name.clone(),
                values: a.values[range.clone()].to_vec(),
            }),
            radii: f.radii.as_ref().map(|r| r[range].to_vec()),
            ..f.clone_header()
        }
    }
}

/// One frame of a dump read a window at a time without holding it whole.
pub struct DumpSource {
    pub path: PathBuf,
    pub frame: usize,
    pub options: crate::readers::ReadOptions,
    pub particles: usize,
    pub simulation_box: Option<SimulationBox>,
    /// How the windows are read.
    pub windows: Windows,
    /// For [`Windows::Text`]: the frame's header, from the dump already opened (indexing
    /// it again would read the whole file once more).
    pub(crate) text_header: Option<crate::readers::Header>,
    /// For [`Windows::Pieces`]: the files the dump already opened read its pieces from
    /// (working files where [`crate::convert::open_bounded`] decompressed them); `None`:
    /// the pieces `path` names.
    pub(crate) pieces: Option<Vec<PathBuf>>,
    /// For [`Windows::Pieces`]: each piece's header of the frame where the piece is
    /// uncompressed text, from the dump already opened (so that no pass over the frame
    /// indexes a piece again).
    pub(crate) piece_headers: Option<Vec<Option<crate::readers::Header>>>,
}

/// How a [`DumpSource`] reads its windows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Windows {
    /// By particle ranges ([`crate::readers::DumpFile::read_part`]: binary dumps, raw
    /// arrays, GSD). The dump is opened afresh for every window, so the pages of the input it
    /// maps are released after each window and resident memory stays bounded.
    Parts,
    /// By lines ([`crate::readers::read_text_windows`]: uncompressed LAMMPS text, XYZ),
    /// mapping the file afresh for every window.
    Text,
    /// A `%` piece set: piece after piece in processor order, each a window at a time
    /// as its own format allows (a compressed piece whole).
    Pieces,
}

impl ParticleSource for DumpSource {
    fn len(&self) -> usize {
        self.particles
    }

    fn extra_attributes(&self) -> Vec<String> {
        self.options.extra_attributes.clone()
    }

    fn extra_windows(
        &self,
        k: usize,
        window: usize,
        f: &mut ExtraWindowFn<'_>,
    ) -> Result<(), ConvertError> {
        let name = self.options.extra_attributes.get(k).ok_or_else(|| {
            ConvertError::Chunked(format!("this input has no further attribute {k}"))
        })?;
        // The same windows, read with the further attribute as the attribute.
        let one = DumpSource {
            path: self.path.clone(),
            frame: self.frame,
            // (A text dump's pass parses that column alone.)
            options: crate::readers::ReadOptions {
                values_only: true,
                ..self.options.reading(name)
            },
            particles: self.particles,
            simulation_box: self.simulation_box.clone(),
            windows: self.windows,
            text_header: self.text_header.clone(),
            pieces: self.pieces.clone(),
            piece_headers: self.piece_headers.clone(),
        };
        one.windows(window, &mut |start, mut part| {
            let n = part.len();
            let a = part.attribute.take().unwrap_or(crate::frame::Attribute {
                name: name.clone(),
                values: Vec::new(),
            });
            // Only the values wait for the partition, not the window's particles.
            drop(part);
            if a.values.len() != n {
                return Err(ConvertError::Chunked(format!(
                    "particles {start}..: attribute {name} gave {} values for {n} particles",
                    a.values.len()
                )));
            }
            f(start, a)
        })
    }

    fn simulation_box(&self) -> Option<&SimulationBox> {
        self.simulation_box.as_ref()
    }

    fn windows(&self, window: usize, f: &mut WindowFn<'_>) -> Result<(), ConvertError> {
        match self.windows {
            Windows::Parts => {
                // Species a part would list differently from the whole frame (GSD radii
                // from the whole frame's diameters), taken once.
                let species =
                    crate::readers::DumpFile::open(&self.path)?.frame_species(self.frame)?;
                windows_by_range(self.particles, window, f, |range| {
                    let dump = crate::readers::DumpFile::open(&self.path)?;
                    let mut part = dump.read_part(self.frame, &self.options, range, &NoProgress)?;
                    if let Some(s) = &species {
                        part.species = s.clone();
                    }
                    Ok(part)
                })
            }
            Windows::Text => crate::readers::read_text_windows(
                &self.path,
                self.frame,
                self.text_header.clone(),
                &self.options,
                window,
                f,
            ),
            Windows::Pieces => {
                // (Not the piece set opened again: that held every gzip piece's text.)
                let pieces = match &self.pieces {
                    Some(p) => p.clone(),
                    None => crate::readers::piece_paths(&self.path)?,
                };
                let mut offset = 0usize;
                for (j, piece) in pieces.into_iter().enumerate() {
                    let known = self
                        .piece_headers
                        .as_ref()
                        .and_then(|h| h.get(j).cloned().flatten());
                    // Uncompressed text is read by lines, with its header: the one the
                    // opened dump gave, else the one taken here (opened again, the piece
                    // would be scanned again, a whole pass over it).
                    let (n, text_header) = match known {
                        Some(header) => (header.info.particles, Some(header)),
                        None => {
                            let dump = crate::readers::DumpFile::open(&piece)?;
                            let n = dump.frame_info(self.frame)?.particles;
                            let mut shifted = |start: usize, part: Frame| f(offset + start, part);
                            if dump.is_compressed() {
                                // A small gzip piece, decompressed: read whole.
                                let part =
                                    dump.read_frame(self.frame, &self.options, &NoProgress)?;
                                drop(dump);
                                shifted(0, part)?;
                                (n, None)
                            } else if dump.reads_parts() {
                                drop(dump);
                                windows_by_range(n, window, &mut shifted, |range| {
                                    let dump = crate::readers::DumpFile::open(&piece)?;
                                    Ok(dump.read_part(
                                        self.frame,
                                        &self.options,
                                        range,
                                        &NoProgress,
                                    )?)
                                })?;
                                (n, None)
                            } else if dump.reads_text_windows() {
                                (n, Some(dump.header(self.frame)?))
                            } else {
                                let part =
                                    dump.read_frame(self.frame, &self.options, &NoProgress)?;
                                drop(dump);
                                shifted(0, part)?;
                                (n, None)
                            }
                        }
                    };
                    if let Some(header) = text_header {
                        let mut shifted = |start: usize, part: Frame| f(offset + start, part);
                        crate::readers::read_text_windows(
                            &piece,
                            self.frame,
                            Some(header),
                            &self.options,
                            window,
                            &mut shifted,
                        )?;
                    }
                    offset = offset.checked_add(n).ok_or_else(|| {
                        ConvertError::Chunked(format!(
                            "{}: frame {}: the pieces hold more atoms than can be counted",
                            piece.display(),
                            self.frame
                        ))
                    })?;
                }
                Ok(())
            }
        }
    }
}

/// A working-file error.
fn temp_err(path: &Path, e: std::io::Error) -> ConvertError {
    ConvertError::Temp {
        path: path.to_path_buf(),
        source: e,
    }
}

/// The species of all windows, merged by name.
#[derive(Default)]
struct SpeciesMerge {
    list: Vec<SpeciesName>,
    by_name: HashMap<String, u16>,
    /// Particles of each merged species so far.
    counts: Vec<u64>,
}

impl SpeciesMerge {
    /// Maps a window's species indices to merged (provisional) ones, adding new names in
    /// [`crate::species::merge_order`].
    fn add(
        &mut self,
        part: &[SpeciesName],
        species_index: &[u16],
    ) -> Result<Vec<u16>, ConvertError> {
        let mut map = vec![0u16; part.len()];
        for i in crate::species::merge_order(part, species_index) {
            let s = &part[i];
            if let Some(&k) = self.by_name.get(&s.name) {
                let known = &mut self.list[usize::from(k)];
                known.numeric_type &= s.numeric_type;
                if s.sized_count > 0 {
                    crate::species::merge_sizes(known, s);
                } else {
                    known.radius = known.radius.or(s.radius);
                }
                map[i] = k;
                continue;
            }
            // (Refused as soon as the frame has more than a file can hold.)
            if self.list.len() >= MAX_SPECIES {
                let e = BuildError::TooManySpecies(self.list.len() + 1);
                return Err(ConvertError::Chunked(e.to_string()));
            }
            map[i] = self.list.len() as u16;
            self.by_name.insert(s.name.clone(), map[i]);
            self.list.push(s.clone());
            self.counts.push(0);
        }
        for (k, c) in crate::species::counts(part.len(), species_index)
            .into_iter()
            .enumerate()
        {
            self.counts[usize::from(map[k])] += c;
        }
        Ok(map)
    }

    /// The final species list (numeric LAMMPS types sorted numerically, others in order
    /// of first appearance, as the whole-frame readers list them), the map from
    /// provisional to final indices, and each final species' particles.
    fn finish(mut self) -> (Vec<SpeciesName>, Vec<u16>, Vec<u64>) {
        let mut order: Vec<usize> = (0..self.list.len()).collect();
        if self.list.iter().all(|s| s.numeric_type) {
            order.sort_by_key(|&i| self.list[i].name.parse::<i64>().unwrap_or(i64::MAX));
            crate::species::slots_as_whole(&mut self.list);
        } else {
            crate::species::not_all_numbers(&mut self.list);
        }
        let mut map = vec![0u16; self.list.len()];
        for (new, &old) in order.iter().enumerate() {
            map[old] = new as u16;
        }
        let list = order.iter().map(|&i| self.list[i].clone()).collect();
        let counts = order.iter().map(|&i| self.counts[i]).collect();
        (list, map, counts)
    }
}

/// Working records: position (3 × f32), species (u16), attribute (f32, when present),
/// the particle's own radius as the input gives it (f32, when present), then the
/// further attributes (f32 each).
#[derive(Clone, Copy)]
struct RecordLayout {
    attribute: bool,
    radius: bool,
    extras: usize,
}

impl RecordLayout {
    fn size(self) -> usize {
        self.extras_at() + 4 * self.extras
    }

    /// Where the radius lies in a record.
    fn radius_at(self) -> usize {
        14 + 4 * usize::from(self.attribute)
    }

    /// Where the further attributes begin in a record.
    fn extras_at(self) -> usize {
        self.radius_at() + 4 * usize::from(self.radius)
    }

    #[inline(always)]
    fn position(self, r: &[u8]) -> [f32; 3] {
        let at = |k: usize| f32::from_le_bytes(r[4 * k..4 * k + 4].try_into().expect("4 bytes"));
        [at(0), at(1), at(2)]
    }
}

/// A cell's working file, appended window after window through the page cache. (Written
/// and read with direct I/O instead, the cells made conversions no faster, timed
/// alternately on the benchmark VM: at 2×10^8 57.6-63.0 s against 56.5-58.7 s, at 10^9
/// 262 s against 253 s; the page cache keeps cells for the chunk loads.)
struct CellFile {
    path: PathBuf,
    /// Closed by [`CellFile::release`] until the next append.
    file: Option<File>,
    len: u64,
}

impl CellFile {
    /// Creates (or truncates) `path`.
    fn create(path: &Path) -> std::io::Result<CellFile> {
        Ok(CellFile {
            path: path.to_path_buf(),
            file: Some(File::create(path)?),
            len: 0,
        })
    }

    /// Appends `bytes` in one write, reopening the file if it was released.
    fn append(&mut self, bytes: &[u8]) -> std::io::Result<()> {
        use std::os::unix::fs::FileExt;
        if self.file.is_none() {
            self.file = Some(fs::OpenOptions::new().write(true).open(&self.path)?);
        }
        let f = self.file.as_ref().expect("opened above");
        f.write_all_at(bytes, self.len)?;
        self.len += bytes.len() as u64;
        Ok(())
    }

    /// Closes the file until the next append: for more cells than may be open at once.
    fn release(&mut self) {
        self.file = None;
    }
}

/// Bytes `offset..offset + len` of the file at `path`, read into `buf` (reused).
fn read_file_range<'b>(
    path: &Path,
    offset: u64,
    len: usize,
    buf: &'b mut Vec<u8>,
) -> std::io::Result<&'b [u8]> {
    use std::os::unix::fs::FileExt;
    buf.resize(len, 0);
    File::open(path)?.read_exact_at(buf, offset)?;
    Ok(buf)
}

/// Descriptors left for everything but the files asked for in [`room_for_open_files`].
const OTHER_FILES: u64 = 256;

/// Whether `files` more files may stay open at once: when the soft open-file limit is too
/// low for them, it is raised as far as needed, if the hard limit allows.
fn room_for_open_files(files: usize) -> bool {
    use rustix::process::{getrlimit, setrlimit, Resource, Rlimit};
    let need = files as u64 + OTHER_FILES;
    let limit = getrlimit(Resource::Nofile);
    if limit.current.is_none_or(|c| c >= need) {
        return true;
    }
    if limit.maximum.is_some_and(|m| m < need) {
        return false;
    }
    let raised = Rlimit {
        current: Some(need),
        maximum: limit.maximum,
    };
    setrlimit(Resource::Nofile, raised).is_ok()
}

/// One cell of the partition: a working file of records.
#[derive(Debug)]
struct Cell {
    path: PathBuf,
    count: usize,
    lo: [f32; 3],
    hi: [f32; 3],
}

/// The cell (Morton code) of `x` in a grid of `2^bits` cells per axis over `lo..hi`.
#[inline(always)]
fn cell_of(x: [f32; 3], lo: [f32; 3], hi: [f32; 3], bits: u32) -> usize {
    let cells = 1u32 << bits;
    let mut code = 0usize;
    for k in 0..3 {
        let ext = hi[k] - lo[k];
        let i = if ext > 0.0 && x[k].is_finite() {
            (((x[k] - lo[k]) / ext * cells as f32).max(0.0) as u32).min(cells - 1)
        } else {
            0
        };
        code |= spread_bits(i) << k;
    }
    code
}

/// The low 10 bits of `i` moved to bits 0, 3, 6, ..., 27: one axis of a Morton code.
#[inline(always)]
fn spread_bits(i: u32) -> usize {
    let mut x = u64::from(i & 0x3ff);
    x = (x | x << 16) & 0x0300_00ff;
    x = (x | x << 8) & 0x0300_f00f;
    x = (x | x << 4) & 0x030c_30c3;
    x = (x | x << 2) & 0x0924_9249;
    x as usize
}

/// Appends windows of records to the cells of a grid over `lo..hi`.
struct Partitioner {
    dir: PathBuf,
    prefix: String,
    layout: RecordLayout,
    lo: [f32; 3],
    hi: [f32; 3],
    /// Bits per axis of the grid.
    bits: u32,
    writers: Vec<Option<CellFile>>,
    /// Whether every cell's file may stay open (else each is closed after each append).
    keep_open: bool,
    cells: Vec<Cell>,
    /// The window's cell ids and its records sorted by cell, kept between windows so
    /// that their memory is touched once.
    ids: Vec<u16>,
    sorted: Vec<u8>,
    /// For grids finer than [`GRID_BITS`]: the window sorted by its coarser cells first.
    coarse: Vec<u8>,
    coarse_ids: Vec<u16>,
}

impl Partitioner {
    fn new(
        dir: &Path,
        prefix: String,
        layout: RecordLayout,
        (lo, hi): ([f32; 3], [f32; 3]),
        bits: u32,
    ) -> Self {
        let cells = 1usize << (3 * bits);
        Partitioner {
            dir: dir.to_path_buf(),
            prefix,
            layout,
            lo,
            hi,
            bits,
            writers: (0..cells).map(|_| None).collect(),
            keep_open: room_for_open_files(cells),
            cells: (0..cells)
                .map(|_| Cell {
                    path: PathBuf::new(),
                    count: 0,
                    lo: [f32::INFINITY; 3],
                    hi: [f32::NEG_INFINITY; 3],
                })
                .collect(),
            ids: Vec::new(),
            sorted: Vec::new(),
            coarse: Vec::new(),
            coarse_ids: Vec::new(),
        }
    }

    /// Appends the records in `bytes`, in order.
    fn add(&mut self, bytes: &[u8]) -> Result<(), ConvertError> {
        let size = self.layout.size();
        let (lo, hi, layout, bits) = (self.lo, self.hi, self.layout, self.bits);
        let cells = self.cells.len();
        let mut ids = std::mem::take(&mut self.ids);
        ids.clear();
        bytes
            .par_chunks_exact(size)
            .map(|r| cell_of(layout.position(r), lo, hi, bits) as u16)
            .collect_into_vec(&mut ids);
        // A stable counting sort of the window by cell, so that each cell's records go
        // out in one write, in input order; the cells' bounds grow on the way.
        let mut start = vec![0usize; cells + 1];
        for &id in &ids {
            start[usize::from(id) + 1] += 1;
        }
        for c in 0..cells {
            start[c + 1] += start[c];
        }
        // A grid finer than 8×8×8 is sorted in two stable passes, by the 512 cells of its
        // high bits and then within them: a scatter over thousands of cells at once
        // touches a new page with almost every record.
        let shift = 3 * bits.saturating_sub(GRID_BITS);
        let mut coarse = std::mem::take(&mut self.coarse);
        let mut coarse_ids = std::mem::take(&mut self.coarse_ids);
        let (records, record_ids) = if shift == 0 {
            (bytes, &ids)
        } else {
            let mut next: Vec<usize> = (0..cells >> shift).map(|c| start[c << shift]).collect();
            coarse.resize(bytes.len(), 0);
            coarse_ids.resize(ids.len(), 0);
            for (r, &id) in bytes.chunks_exact(size).zip(&ids) {
                let at = &mut next[usize::from(id) >> shift];
                coarse[*at * size..(*at + 1) * size].copy_from_slice(r);
                coarse_ids[*at] = id;
                *at += 1;
            }
            (&coarse[..], &coarse_ids)
        };
        let mut next = start.clone();
        let mut sorted = std::mem::take(&mut self.sorted);
        sorted.resize(bytes.len(), 0);
        for (r, &id) in records.chunks_exact(size).zip(record_ids) {
            let id = usize::from(id);
            let at = &mut next[id];
            sorted[*at * size..(*at + 1) * size].copy_from_slice(r);
            *at += 1;
            let x = layout.position(r);
            let cell = &mut self.cells[id];
            for k in 0..3 {
                cell.lo[k] = cell.lo[k].min(x[k]);
                cell.hi[k] = cell.hi[k].max(x[k]);
            }
        }
        let written = (|| {
            for id in 0..cells {
                let (a, b) = (start[id], start[id + 1]);
                if a == b {
                    continue;
                }
                let part = &sorted[a * size..b * size];
                let cell = &mut self.cells[id];
                if self.writers[id].is_none() {
                    cell.path = self.dir.join(format!("{}-{id:03}.cell", self.prefix));
                    let f = CellFile::create(&cell.path).map_err(|e| temp_err(&cell.path, e))?;
                    self.writers[id] = Some(f);
                }
                let w = self.writers[id].as_mut().expect("opened above");
                w.append(part).map_err(|e| temp_err(&cell.path, e))?;
                if !self.keep_open {
                    w.release();
                }
                cell.count += b - a;
            }
            Ok(())
        })();
        self.ids = ids;
        self.sorted = sorted;
        self.coarse = coarse;
        self.coarse_ids = coarse_ids;
        written
    }

    /// The non-empty cells in Morton order.
    fn finish(self) -> Vec<Cell> {
        self.cells.into_iter().filter(|c| c.count > 0).collect()
    }
}

/// A [`Partitioner`] on a thread of its own: windows of records reach it through a
/// channel of one slot, in order, so the next window is read while the last is sorted
/// and written; their buffers come back for reuse.
struct CellWriter<'scope> {
    to: Option<std::sync::mpsc::SyncSender<Vec<u8>>>,
    back: std::sync::mpsc::Receiver<Vec<u8>>,
    thread: std::thread::ScopedJoinHandle<'scope, Result<Vec<Cell>, ConvertError>>,
}

impl<'scope> CellWriter<'scope> {
    fn spawn<'env>(scope: &'scope std::thread::Scope<'scope, 'env>, mut p: Partitioner) -> Self {
        let (to, windows) = std::sync::mpsc::sync_channel::<Vec<u8>>(1);
        let (give_back, back) = std::sync::mpsc::channel();
        let thread = scope.spawn(move || {
            for bytes in windows {
                p.add(&bytes)?;
                // The reader may have finished; then the buffer is simply dropped.
                let _ = give_back.send(bytes);
            }
            Ok(p.finish())
        });
        CellWriter {
            to: Some(to),
            back,
            thread,
        }
    }

    /// A buffer for the next window's records: one that came back, or a new one.
    fn buffer(&self) -> Vec<u8> {
        self.back.try_recv().unwrap_or_default()
    }

    /// Queues a window of records; false when the writer has stopped on an error.
    fn send(&self, bytes: Vec<u8>) -> bool {
        self.to.as_ref().is_some_and(|t| t.send(bytes).is_ok())
    }

    /// Waits for the queued windows and returns the cells, or the writer's error.
    fn finish(mut self) -> Result<Vec<Cell>, ConvertError> {
        drop(self.to.take());
        self.thread
            .join()
            .unwrap_or_else(|panic| std::panic::resume_unwind(panic))
    }
}

/// Reads a cell's records `range` (in records) into `buf`, which is reused.
fn read_records<'b>(
    cell: &Cell,
    layout: RecordLayout,
    range: Range<usize>,
    buf: &'b mut Vec<u8>,
) -> Result<&'b [u8], ConvertError> {
    let size = layout.size();
    read_file_range(
        &cell.path,
        (range.start * size) as u64,
        range.len() * size,
        buf,
    )
    .map_err(|e| temp_err(&cell.path, e))
}

/// Splits `cell` until every leaf holds at most `max` records; leaves in order.
fn refine(
    cell: Cell,
    layout: RecordLayout,
    max: usize,
    depth: u32,
    out: &mut Vec<Cell>,
) -> Result<(), ConvertError> {
    if cell.count <= max {
        out.push(cell);
        return Ok(());
    }
    let flat = (0..3).all(|k| cell.hi[k] <= cell.lo[k]);
    let prefix = format!(
        "{}s",
        cell.path
            .file_stem()
            .map_or_else(String::new, |s| s.to_string_lossy().into_owned())
    );
    let dir = cell.path.parent().unwrap_or(Path::new(".")).to_path_buf();
    let mut children = Vec::new();
    let mut buf = Vec::new();
    if !flat && depth < MAX_SPLIT_DEPTH {
        let bits = refine_bits(cell.count, max);
        let mut p = Partitioner::new(&dir, prefix.clone(), layout, (cell.lo, cell.hi), bits);
        for start in (0..cell.count).step_by(WINDOW) {
            let range = start..(start + WINDOW).min(cell.count);
            p.add(read_records(&cell, layout, range, &mut buf)?)?;
        }
        children = p.finish();
    }
    if children.len() <= 1 {
        // No spatial progress: split by order.
        for c in &children {
            fs::remove_file(&c.path).map_err(|e| temp_err(&c.path, e))?;
        }
        children.clear();
        for (i, start) in (0..cell.count).step_by(max).enumerate() {
            let end = (start + max).min(cell.count);
            let path = dir.join(format!("{prefix}-o{i:05}.cell"));
            let mut w = BufWriter::new(File::create(&path).map_err(|e| temp_err(&path, e))?);
            let mut lo = [f32::INFINITY; 3];
            let mut hi = [f32::NEG_INFINITY; 3];
            for s in (start..end).step_by(WINDOW) {
                let bytes = read_records(&cell, layout, s..(s + WINDOW).min(end), &mut buf)?;
                for r in bytes.chunks_exact(layout.size()) {
                    let x = layout.position(r);
                    for k in 0..3 {
                        lo[k] = lo[k].min(x[k]);
                        hi[k] = hi[k].max(x[k]);
                    }
                }
                w.write_all(bytes).map_err(|e| temp_err(&path, e))?;
            }
            w.flush().map_err(|e| temp_err(&path, e))?;
            children.push(Cell {
                path,
                count: end - start,
                lo,
                hi,
            });
        }
    }
    fs::remove_file(&cell.path).map_err(|e| temp_err(&cell.path, e))?;
    for c in children {
        refine(c, layout, max, depth + 1, out)?;
    }
    Ok(())
}

/// What one chunk's build left behind.
struct ChunkResult {
    levels: Vec<LevelRecord>,
    root: Rep,
    /// The root node's quant_scale (it covers every level the root encodes).
    root_scale: [f32; 3],
    /// Unquantized positions of the chunk's levels `0..δn`.
    top_positions: Vec<Vec<[f32; 3]>>,
    max_error: f64,
    nodes: Kept<NodeRecord>,
    /// The quantized positions of levels 1.., one level after the other.
    positions: Kept<[u16; 3]>,
    species: Kept<u16>,
    attribute: Option<Kept<u16>>,
    radius: Option<Kept<u16>>,
    extras: Vec<ChunkExtra>,
}

/// A further attribute of a chunk: its values in the chunk's particle order, quantized
/// over the frame's range, its nodes' means (in the chunk's node order), and the sums
/// of its root's mean, which the top node's combines.
struct ChunkExtra {
    values: Kept<u16>,
    means: Kept<f32>,
    sums: crate::hierarchy::extra::MeanSums,
}

/// One of a chunk's results waiting for the assembly: kept in memory while the memory
/// limit leaves room for it (no working file to write and read back), else in a
/// working file.
enum Kept<T> {
    Memory(Vec<T>),
    File(PathBuf),
}

impl<T: bytemuck::Pod> Kept<T> {
    /// Keeps `data` in memory, or writes it to `path`.
    fn store(data: Vec<T>, path: PathBuf, in_memory: bool) -> Result<Self, ConvertError> {
        if in_memory {
            return Ok(Kept::Memory(data));
        }
        write_file(&path, bytemuck::cast_slice(&data))?;
        Ok(Kept::File(path))
    }

    fn len_bytes(&self) -> u64 {
        match self {
            Kept::Memory(v) => std::mem::size_of_val(v.as_slice()) as u64,
            Kept::File(p) => fs::metadata(p).map_or(0, |m| m.len()),
        }
    }

    /// The bytes, for the assembly to copy from: borrowed from memory, or the working
    /// file mapped once.
    fn bytes(&self) -> Result<KeptBytes<'_>, ConvertError> {
        Ok(match self {
            Kept::Memory(v) => KeptBytes::Memory(bytemuck::cast_slice(v)),
            Kept::File(p) => KeptBytes::Mapped(map_working_file(p)?, p),
        })
    }

    /// Removes the working file once its last part is copied (memory goes with the
    /// chunk).
    fn remove(&self) -> Result<(), ConvertError> {
        match self {
            Kept::Memory(_) => Ok(()),
            Kept::File(p) => fs::remove_file(p).map_err(|e| temp_err(p, e)),
        }
    }
}

/// What [`Kept::bytes`] gives.
enum KeptBytes<'a> {
    Memory(&'a [u8]),
    Mapped(mdlod_format::mmap::Mmap, &'a Path),
}

impl KeptBytes<'_> {
    fn all(&self) -> &[u8] {
        match self {
            KeptBytes::Memory(b) => b,
            KeptBytes::Mapped(m, _) => m,
        }
    }

    /// Bytes `offset..offset + len`; an error when the result is shorter.
    fn range(&self, offset: u64, len: usize) -> Result<&[u8], ConvertError> {
        let all = self.all();
        usize::try_from(offset)
            .ok()
            .and_then(|o| all.get(o..o.checked_add(len)?))
            .ok_or_else(|| {
                let short = format!("no bytes {offset}..+{len} in {} bytes", all.len());
                match self {
                    KeptBytes::Memory(_) => {
                        ConvertError::Chunked(format!("a chunk result: {short}"))
                    }
                    KeptBytes::Mapped(_, p) => temp_err(p, short_file(short)),
                }
            })
    }
}

/// Maps one of the conversion's own working files (cells, chunk results).
fn map_working_file(path: &Path) -> Result<mdlod_format::mmap::Mmap, ConvertError> {
    File::open(path)
        .and_then(|f| mdlod_format::mmap::map_file(&f))
        .map_err(|e| temp_err(path, e))
}

/// The error of a working file shorter than what was written to it.
fn short_file(message: String) -> std::io::Error {
    std::io::Error::new(std::io::ErrorKind::UnexpectedEof, message)
}

impl ChunkResult {
    fn depth(&self) -> usize {
        self.levels.len()
    }
}

struct ChunkInput<'a> {
    layout: RecordLayout,
    species: &'a [mdlod_format::meta::Species],
    species_map: &'a [u16],
    options: &'a ConvertOptions,
    extras: &'a BuildExtras,
    /// The further attributes, with the frame's ranges.
    extra_infos: &'a [AttributeInfo],
    dir: &'a Path,
    /// Bytes of chunk results the memory limit leaves room for, and those kept so far.
    keep_budget: u64,
    kept: &'a std::sync::atomic::AtomicU64,
}

fn write_file(path: &Path, bytes: &[u8]) -> Result<(), ConvertError> {
    let mut w =
        BufWriter::with_capacity(1 << 20, File::create(path).map_err(|e| temp_err(path, e))?);
    w.write_all(bytes).map_err(|e| temp_err(path, e))?;
    w.flush().map_err(|e| temp_err(path, e))
}

/// The records of a chunk's cells, one buffer each, read while an earlier chunk builds.
fn load_cells(cells: &[Cell], layout: RecordLayout) -> Result<Vec<Vec<u8>>, ConvertError> {
    cells
        .iter()
        .map(|cell| {
            let mut buf = Vec::new();
            read_file_range(&cell.path, 0, cell.count * layout.size(), &mut buf).map_err(|e| {
                match e.kind() {
                    std::io::ErrorKind::UnexpectedEof => temp_err(
                        &cell.path,
                        short_file(format!("holds fewer than its {} records", cell.count)),
                    ),
                    _ => temp_err(&cell.path, e),
                }
            })?;
            Ok(buf)
        })
        .collect()
}

fn build_chunk(
    c: usize,
    cells: &[Cell],
    loaded: Vec<Vec<u8>>,
    input: &ChunkInput<'_>,
) -> Result<ChunkResult, ConvertError> {
    let layout = input.layout;
    let size = layout.size();
    let n: usize = cells.iter().map(|c| c.count).sum();
    let mut positions = Vec::with_capacity(n);
    let mut species_index = Vec::with_capacity(n);
    let mut attribute = layout.attribute.then(|| Vec::with_capacity(n));
    let mut radii = layout.radius.then(|| Vec::with_capacity(n));
    let mut extra_columns: Vec<Vec<f32>> =
        (0..layout.extras).map(|_| Vec::with_capacity(n)).collect();
    let at = layout.radius_at();
    let extras_at = layout.extras_at();
    for (cell, buf) in cells.iter().zip(&loaded) {
        let bytes = &buf[..cell.count * size];
        for r in bytes.chunks_exact(size) {
            positions.push(layout.position(r));
            let s = u16::from_le_bytes([r[12], r[13]]);
            species_index.push(input.species_map[usize::from(s)]);
            if let Some(a) = attribute.as_mut() {
                a.push(f32::from_le_bytes([r[14], r[15], r[16], r[17]]));
            }
            if let Some(a) = radii.as_mut() {
                a.push(f32::from_le_bytes([r[at], r[at + 1], r[at + 2], r[at + 3]]));
            }
            for (k, column) in extra_columns.iter_mut().enumerate() {
                let e = extras_at + 4 * k;
                column.push(f32::from_le_bytes([r[e], r[e + 1], r[e + 2], r[e + 3]]));
            }
        }
    }
    drop(loaded);
    // As the whole frame's table says: own sizes for the species of several.
    let radii = crate::hierarchy::particle_radii(input.species, &species_index, radii.as_deref());
    let particles = Particles {
        positions: &positions,
        species_index: &species_index,
        species: input.species,
        attribute: attribute.as_deref(),
        radii: radii.as_deref(),
    };
    let h =
        build_with(particles, &input.options.build, input.extras, &NoProgress).map_err(|e| {
            ConvertError::Build {
                path: format!("chunk {c}"),
                source: e,
            }
        })?;
    drop((positions, attribute, radii));
    let columns: Vec<(&AttributeInfo, &[f32])> = input
        .extra_infos
        .iter()
        .zip(&extra_columns)
        .map(|(info, v)| (info, v.as_slice()))
        .collect();
    let extras = crate::hierarchy::extra::extra_attributes_over(&h, &columns, input.species)
        .map_err(|e| ConvertError::Build {
            path: format!("chunk {c}"),
            source: e,
        })?;
    drop(columns);
    drop(extra_columns);
    let stem = |ext: &str| input.dir.join(format!("chunk-{c:05}.{ext}"));
    let positions: Vec<[u16; 3]> = h.quantized.iter().skip(1).flatten().copied().collect();
    drop(h.quantized);
    let attribute = h.attribute.map(|(a, _, _)| a);
    let radius = h.radius.map(|(r, _)| r);
    let bytes = std::mem::size_of_val(h.nodes.as_slice())
        + std::mem::size_of_val(positions.as_slice())
        + std::mem::size_of_val(h.species_index.as_slice())
        + attribute
            .as_ref()
            .map_or(0, |a| std::mem::size_of_val(a.as_slice()))
        + radius
            .as_ref()
            .map_or(0, |a| std::mem::size_of_val(a.as_slice()))
        + extras
            .iter()
            .map(|(e, _)| {
                std::mem::size_of_val(e.values.as_slice())
                    + std::mem::size_of_val(e.node_means.as_slice())
            })
            .sum::<usize>();
    let bytes = bytes as u64;
    // Kept in memory if the room left under the limit holds it (which chunks fit
    // depends on timing; the file does not).
    let in_memory = input
        .kept
        .fetch_update(
            std::sync::atomic::Ordering::Relaxed,
            std::sync::atomic::Ordering::Relaxed,
            |k| (k + bytes <= input.keep_budget).then_some(k + bytes),
        )
        .is_ok();
    let root_scale = h.nodes[0].quant_scale;
    let nodes = Kept::store(h.nodes, stem("nodes"), in_memory)?;
    let positions = Kept::store(positions, stem("positions"), in_memory)?;
    let species = Kept::store(h.species_index, stem("species"), in_memory)?;
    let attribute = attribute
        .map(|a| Kept::store(a, stem("attribute"), in_memory))
        .transpose()?;
    let radius = radius
        .map(|a| Kept::store(a, stem("radius"), in_memory))
        .transpose()?;
    let extras = extras
        .into_iter()
        .enumerate()
        .map(|(k, (e, sums))| {
            Ok(ChunkExtra {
                values: Kept::store(e.values, stem(&format!("extra-{k}")), in_memory)?,
                means: Kept::store(e.node_means, stem(&format!("means-{k}")), in_memory)?,
                sums,
            })
        })
        .collect::<Result<Vec<_>, ConvertError>>()?;
    for cell in cells {
        fs::remove_file(&cell.path).map_err(|e| temp_err(&cell.path, e))?;
    }
    Ok(ChunkResult {
        levels: h.levels,
        root: h.root,
        root_scale,
        top_positions: h.top_positions,
        max_error: h.max_position_error,
        nodes,
        positions,
        species,
        attribute,
        radius,
        extras,
    })
}

/// Builds the hierarchy of `source` in chunks and writes it to `output`. `metadata`
/// supplies what the source knows (box, timestep, source file); the species, particle
/// count, attribute range, build parameters and error bound are filled in here.
pub fn convert_chunked(
    source: &dyn ParticleSource,
    mut metadata: Metadata,
    output: &Path,
    options: &ConvertOptions,
    progress: &dyn Progress,
) -> Result<ConvertReport, ConvertError> {
    let chunk = &options.chunks;
    let window = chunk.window_points.max(1);
    let n = source.len();
    let params = &options.build;
    if n == 0 {
        return Err(ConvertError::EmptyFrame(crate::convert::FramePlace::of(
            metadata.source.as_ref(),
            metadata.timestep,
        )));
    }
    crate::convert::check_box(metadata.simulation_box.as_ref(), || {
        crate::convert::FramePlace::of(metadata.source.as_ref(), metadata.timestep)
    })?;
    // Everything that does not need the particles is checked before the partition pass
    // reads them all.
    params.check().map_err(|source| ConvertError::Build {
        path: output.display().to_string(),
        source,
    })?;
    // Where a particle's error is: the input's frame, not the file being written.
    let place =
        crate::convert::FramePlace::of(metadata.source.as_ref(), metadata.timestep).to_string();
    let extra_names = source.extra_attributes();
    let extra_count = extra_names.len();
    if let Some(problem) = crate::convert::too_many_attributes(extra_count) {
        return Err(ConvertError::Attributes {
            place: crate::convert::FramePlace::of(metadata.source.as_ref(), metadata.timestep),
            problem,
        });
    }
    // Each further attribute's pass holds a window of its own (its input mapped, its
    // values parsed) on top of the particles' one: smaller windows, within about a
    // thousandth of the limit per pass, keep the partition's memory about that of one
    // pass, at small limits too.
    let part_window = match extra_count {
        0 => window,
        k => (window / (1 + k))
            .min(((chunk.memory_limit / 1024 / (1 + k as u64)) as usize).max(1 << 16))
            .max(1),
    };
    let per_particle = build_bytes_per_particle(extra_count);
    let chunk_memory = |points: usize| chunk_memory_with(points, extra_count);
    // At most `max_root_points` chunks share the particles: the largest holds at least
    // that share.
    let least = chunk_memory(n.div_ceil(params.max_root_points as usize));
    if least > chunk.memory_limit {
        let place = crate::convert::FramePlace::of(metadata.source.as_ref(), metadata.timestep);
        return Err(ConvertError::Chunked(format!(
            "{place}: the memory limit of {} is below the {} the smallest chunks need ({} of \
             working buffers and about {per_particle} bytes per particle: {n} \
             particles in at most {} chunks, the root points, make chunks of at least {} \
             particles); raise --memory-limit to at least {}{}",
            size_text(chunk.memory_limit),
            need_text(least),
            size_text(chunk_memory(0)),
            params.max_root_points,
            n.div_ceil(params.max_root_points as usize),
            need_text(least),
            // Chunks as large as --chunk-points allows need more: what this run would.
            match chunk_memory(n.min(chunk.chunk_points)) {
                most if most > least => format!(
                    ", and to {} for chunks of up to {} particles (--chunk-points), or lower \
                     --chunk-points",
                    need_text(most),
                    n.min(chunk.chunk_points)
                ),
                _ => String::new(),
            }
        )));
    }
    if chunk.chunk_points < params.max_root_points as usize {
        return Err(ConvertError::Chunked(format!(
            "chunks of {} particles (--chunk-points) are smaller than the {} root points \
             (--root-points): give chunks of at least as many, or fewer root points",
            chunk.chunk_points, params.max_root_points
        )));
    }
    let temp_dir = chunk.temp_dir_for(output);
    let work = tempfile::Builder::new()
        .prefix(".mdlod-convert-")
        .tempdir_in(&temp_dir)
        .map_err(|e| temp_err(&temp_dir, mdlod_format::files::temp_error(e)))?;
    let dir = work.path();

    // 1. Partition.
    let t0 = Instant::now();
    let bounds = match source.simulation_box() {
        Some(b) => box_bounds(b),
        None => {
            progress.stage("finding bounds", Some(n as u64), "particles");
            let mut lo = [f32::INFINITY; 3];
            let mut hi = [f32::NEG_INFINITY; 3];
            source.windows(window, &mut |_, f| {
                for x in &f.positions {
                    for k in 0..3 {
                        lo[k] = lo[k].min(x[k]);
                        hi[k] = hi[k].max(x[k]);
                    }
                }
                progress.advance(f.len() as u64);
                Ok(())
            })?;
            progress.finish_stage();
            (lo, hi)
        }
    };
    progress.stage("partitioning", Some(n as u64), "particles");
    let mut merge = SpeciesMerge::default();
    let mut layout = None;
    let mut attribute_name = None;
    let mut range = (f32::INFINITY, f32::NEG_INFINITY);
    // The further attributes: name (as their reader gives it) and range.
    // (A further attribute kept as its logarithm has the logarithms' range.)
    let mut extra_infos: Vec<AttributeInfo> = extra_names
        .iter()
        .enumerate()
        .map(|(k, name)| AttributeInfo {
            name: name.clone(),
            min: f32::INFINITY,
            max: f32::NEG_INFINITY,
            log10: options.extra_logged(k),
        })
        .collect();
    if let Some(problem) = crate::convert::extra_log10_problem(extra_names.len(), options) {
        return Err(ConvertError::Attributes {
            place: crate::convert::FramePlace::of(metadata.source.as_ref(), metadata.timestep),
            problem,
        });
    }
    // Whether each further attribute holds whole numbers only (ids).
    let mut extra_whole = vec![true; extra_names.len()];
    // How the first and each further attribute's values spread over the octaves (for the
    // note on decades lost, as a frame built whole says it).
    let mut first_octaves = crate::convert::Octaves::default();
    let mut extra_octaves = vec![crate::convert::Octaves::default(); extra_names.len()];
    let mut seen = 0usize;
    // The records are sorted into cells and written on a thread of their own while the
    // next window is read.
    let cells = std::thread::scope(|scope| {
        let mut writer: Option<CellWriter<'_>> = None;
        // Each further attribute is read by a pass of its own, on a thread of its own, in
        // step with the particles' windows: a channel of one slot each.
        let mut extra_rx = Vec::with_capacity(extra_names.len());
        let mut extra_readers = Vec::with_capacity(extra_names.len());
        for k in 0..extra_names.len() {
            let (tx, rx) = std::sync::mpsc::sync_channel::<(usize, crate::frame::Attribute)>(1);
            extra_rx.push(rx);
            extra_readers.push(scope.spawn(move || {
                let mut stopped = false;
                let read = source.extra_windows(k, part_window, &mut |start, a| {
                    if tx.send((start, a)).is_err() {
                        // The partition stopped, on an error of its own.
                        stopped = true;
                        return Err(ConvertError::Chunked("stopped".into()));
                    }
                    Ok(())
                });
                if stopped {
                    Ok(())
                } else {
                    read
                }
            }));
        }
        // Set where a further attribute's reader ended first: its error is the one to say.
        let mut extra_ended = false;
        let read = source.windows(part_window, &mut |start, f| {
            seen += f.len();
            let mut extras = Vec::with_capacity(extra_rx.len());
            for (k, rx) in extra_rx.iter().enumerate() {
                match rx.recv() {
                    Ok((at, a)) if at == start && a.values.len() == f.len() => extras.push(a),
                    Ok((at, a)) => {
                        return Err(ConvertError::Chunked(format!(
                            "particles {start}..: attribute {} was read as {} values from \
                             particle {at}, while the window holds {}",
                            extra_names[k],
                            a.values.len(),
                            f.len()
                        )))
                    }
                    // Its reader stopped; its error is said below.
                    Err(_) => {
                        extra_ended = true;
                        return Err(ConvertError::Chunked(format!(
                            "particles {start}..: the reading of attribute {} ended before \
                             them",
                            extra_names[k]
                        )));
                    }
                }
            }
            if options.attribute_log10 && f.attribute.is_none() {
                return Err(ConvertError::NoAttributeToLog(
                    crate::convert::FramePlace::of(metadata.source.as_ref(), metadata.timestep),
                ));
            }
            if layout.is_none() && !extras.is_empty() {
                // Named as their readers name them (as a frame built whole checks them).
                let names: Vec<&str> = extras.iter().map(|a| a.name.as_str()).collect();
                let first = f.attribute.as_ref().map(|a| a.name.as_str());
                if let Some(problem) = crate::convert::extra_names_problem(first, &names) {
                    return Err(ConvertError::Attributes {
                        place: crate::convert::FramePlace::of(
                            metadata.source.as_ref(),
                            metadata.timestep,
                        ),
                        problem,
                    });
                }
            }
            let lay = *layout.get_or_insert(RecordLayout {
                attribute: f.attribute.is_some(),
                radius: f.radii.is_some(),
                extras: extra_rx.len(),
            });
            if lay.radius != f.radii.is_some() {
                return Err(ConvertError::Chunked(format!(
                    "{}particles {start}..: {} per-particle sizes (a `radius` or `diameter` \
                     column) while the particles before them {}: the parts of a frame (a \
                     parallel run's pieces) must share their columns",
                    metadata
                        .source
                        .as_ref()
                        .map_or(String::new(), |s| format!("{}: ", s.path)),
                    if f.radii.is_some() { "give" } else { "give no" },
                    if lay.radius { "do" } else { "do not" },
                )));
            }
            if lay.attribute != f.attribute.is_some()
                || f.positions.len() != f.species_index.len()
                || f.radii.as_ref().is_some_and(|r| r.len() != f.len())
            {
                return Err(ConvertError::Chunked(format!(
                    "particles {start}..: the window's columns differ from the first window's"
                )));
            }
            let w = writer.get_or_insert_with(|| {
                CellWriter::spawn(
                    scope,
                    Partitioner::new(
                        dir,
                        "cell".into(),
                        lay,
                        bounds,
                        first_bits(n, chunk.chunk_points),
                    ),
                )
            });
            let map = merge.add(&f.species, &f.species_index)?;
            let first_bad =
                |bad: &(dyn Fn(usize) -> bool + Sync)| crate::readers::first_index(f.len(), bad);
            if let Some(index) = first_bad(&|i| f.positions[i].iter().any(|v| !v.is_finite())) {
                return Err(ConvertError::Build {
                    path: place.clone(),
                    source: BuildError::NonFinite {
                        index: start + index,
                        position: f.positions[index],
                    },
                });
            }
            if let Some(index) = first_bad(&|i| !position_in_range(&f.positions[i])) {
                return Err(ConvertError::Build {
                    path: place.clone(),
                    source: BuildError::OutOfRange {
                        index: start + index,
                        position: f.positions[index],
                    },
                });
            }
            if let Some(i) = first_bad(&|i| usize::from(f.species_index[i]) >= map.len()) {
                return Err(ConvertError::Build {
                    path: place.clone(),
                    source: BuildError::BadSpecies {
                        index: start + i,
                        species: f.species_index[i],
                        count: map.len(),
                    },
                });
            }
            // The attribute's range as stored: of its logarithm with `attribute_log10`
            // (the cells keep the values themselves, which the clusters average).
            let values = f.attribute.as_ref().map(|a| a.values.as_slice());
            let stored = match (&f.attribute, options.attribute_log10) {
                (Some(a), true) => Some(crate::convert::log10_range(
                    &a.values,
                    start,
                    &a.name,
                    metadata.source.as_ref(),
                )?),
                (Some(a), false) => Some(finite_range(&a.values, start, || place.clone())?),
                (None, _) => None,
            };
            if let Some((lo, hi)) = stored {
                range = (range.0.min(lo), range.1.max(hi));
            }
            if let Some(a) = f.attribute.as_ref().filter(|_| !options.attribute_log10) {
                first_octaves.add(&crate::convert::Octaves::of(&a.values));
            }
            for (info, a) in extra_infos.iter_mut().zip(&extras) {
                if info.min > info.max {
                    // The name its reader gives (a magnitude's, say).
                    info.name = match info.log10 {
                        true => format!("log10({})", a.name),
                        false => a.name.clone(),
                    };
                }
                let (lo, hi) = if info.log10 {
                    crate::convert::log10_range(
                        &a.values,
                        start,
                        &a.name,
                        metadata.source.as_ref(),
                    )?
                } else {
                    finite_range(&a.values, start, || {
                        format!("{place}: attribute {}", info.name)
                    })?
                };
                info.min = info.min.min(lo);
                info.max = info.max.max(hi);
            }
            // (Not of the columns kept as logarithms, which lose no decades.)
            for ((octaves, a), info) in extra_octaves.iter_mut().zip(&extras).zip(&extra_infos) {
                if !info.log10 {
                    octaves.add(&crate::convert::Octaves::of(&a.values));
                }
            }
            for (whole, a) in extra_whole.iter_mut().zip(&extras) {
                *whole = *whole && a.values.par_iter().all(|v| v.fract() == 0.0);
            }
            let size = lay.size();
            let mut bytes = w.buffer();
            bytes.resize(f.len() * size, 0);
            bytes
                .par_chunks_exact_mut(size)
                .enumerate()
                .for_each(|(i, r)| {
                    for (k, v) in f.positions[i].iter().enumerate() {
                        r[4 * k..4 * k + 4].copy_from_slice(&v.to_le_bytes());
                    }
                    let s = map[usize::from(f.species_index[i])];
                    r[12..14].copy_from_slice(&s.to_le_bytes());
                    if let Some(values) = values {
                        r[14..18].copy_from_slice(&values[i].to_le_bytes());
                    }
                    if let Some(radii) = &f.radii {
                        let at = lay.radius_at();
                        r[at..at + 4].copy_from_slice(&radii[i].to_le_bytes());
                    }
                    for (k, a) in extras.iter().enumerate() {
                        let at = lay.extras_at() + 4 * k;
                        r[at..at + 4].copy_from_slice(&a.values[i].to_le_bytes());
                    }
                });
            if let Some(a) = &f.attribute {
                attribute_name
                    .get_or_insert_with(|| crate::convert::attribute_name(&a.name, options));
            }
            if !w.send(bytes) {
                // The writer stopped on an error, which `finish` returns.
                return Err(ConvertError::Chunked("the cell writer stopped".into()));
            }
            progress.advance(f.len() as u64);
            Ok(())
        });
        let written = writer.map(CellWriter::finish);
        // Every further attribute's pass ends with the particles' (none holds more).
        let mut extra_more = None;
        if read.is_ok() {
            for (k, rx) in extra_rx.iter().enumerate() {
                if let Ok((at, _)) = rx.try_recv() {
                    extra_more.get_or_insert(ConvertError::Chunked(format!(
                        "attribute {} was read for particles from {at} on, past the frame's \
                         {seen}",
                        extra_names[k]
                    )));
                }
            }
        }
        // The readers of further attributes end once their channels close.
        drop(extra_rx);
        let mut extra_error = None;
        for r in extra_readers {
            let r = r.join().unwrap_or_else(|_| {
                Err(ConvertError::Chunked(
                    "the reader of a further attribute stopped".into(),
                ))
            });
            if let Err(e) = r {
                extra_error.get_or_insert(e);
            }
        }
        // A reader's error (a missing column, a short file) is the one to say where the
        // particles' pass stopped for it; else the pass's own, and the cell writer's.
        if let (Some(e), true) = (extra_error, extra_ended || read.is_ok()) {
            return Err(e);
        }
        if let Some(e) = extra_more {
            return Err(e);
        }
        match (read, written) {
            (_, Some(Err(e))) | (Err(e), _) => Err(e),
            (Ok(()), Some(Ok(cells))) => Ok(cells),
            (Ok(()), None) => Err(ConvertError::Chunked("the input has no particles".into())),
        }
    })?;
    progress.finish_stage();
    if seen != n {
        return Err(ConvertError::Chunked(format!(
            "the input announced {n} particles but held {seen}"
        )));
    }
    let layout = layout.expect("at least one window");
    let mut leaves = Vec::new();
    for cell in cells {
        refine(cell, layout, chunk.chunk_points, 0, &mut leaves)?;
    }
    // Greedy grouping in Morton order.
    let mut groups: Vec<Range<usize>> = Vec::new();
    let mut count = 0usize;
    for (i, cell) in leaves.iter().enumerate() {
        match groups.last_mut() {
            Some(g) if count + cell.count <= chunk.chunk_points => {
                g.end = i + 1;
                count += cell.count;
            }
            _ => {
                groups.push(i..i + 1);
                count = cell.count;
            }
        }
    }
    if groups.len() > params.max_root_points as usize {
        return Err(ConvertError::Chunked(format!(
            "{} chunks exceed the {} root points; raise the root points or the chunk size",
            groups.len(),
            params.max_root_points
        )));
    }
    let read_time = t0.elapsed();

    // 2. Chunks.
    let t1 = Instant::now();
    let (names, species_map, counts) = merge.finish();
    // Renamed species (`--species-name`), merged where two take one name: the merged
    // list's indices map on to the renamed list's.
    if !options.radii_may_be_absent {
        crate::species::check_renames(&names, &options.species_names)?;
    }
    let (names, species_map, counts) =
        match crate::species::rename_species(&names, &counts, &options.species_names) {
            (renamed, Some(map)) => {
                let composed = species_map.iter().map(|&i| map[usize::from(i)]).collect();
                let mut merged = vec![0u64; renamed.len()];
                for (old, &new) in map.iter().enumerate() {
                    merged[usize::from(new)] += counts[old];
                }
                (renamed, composed, merged)
            }
            (renamed, None) => (renamed, species_map, counts),
        };
    if !options.radii_may_be_absent {
        crate::species::check_overrides(&names, &options.radii)?;
    }
    crate::convert::check_radii(&names, options, metadata.source.as_ref(), metadata.timestep)?;
    let radius_notes = crate::convert::radius_notes(&names, &options.radii);
    let species = species_table(&names, &options.radii);
    // Each chunk checks its own particles' radii; the top node sums over all of them.
    check_species(n, &species).map_err(|source| ConvertError::Build {
        path: place.clone(),
        source,
    })?;
    let largest = groups
        .iter()
        .map(|g| leaves[g.clone()].iter().map(|c| c.count).sum::<usize>())
        .max()
        .unwrap_or(0);
    let need = chunk_memory(largest);
    if need > chunk.memory_limit {
        let place = crate::convert::FramePlace::of(metadata.source.as_ref(), metadata.timestep);
        return Err(ConvertError::Chunked(format!(
            "{place}: the memory limit of {} is below the {} one chunk of {largest} particles \
             needs ({} of working buffers and about {per_particle} bytes per \
             particle): raise --memory-limit to at least {}{}",
            size_text(chunk.memory_limit),
            need_text(need),
            size_text(chunk_memory(0)),
            need_text(need),
            match chunk_points_within(chunk.memory_limit, params.max_root_points, extra_count) {
                Some(points) => format!(
                    ", or lower --chunk-points to {points} or less (chunks within the limit)"
                ),
                _ => String::new(),
            }
        )));
    }
    // The two chunks read ahead come out of the limit before the builds at work do (a
    // build of 4.2 M particles needs about 500 MiB: at 1G, two of them and the read-ahead
    // passed it).
    let read_ahead = 2 * (largest * layout.size()) as u64;
    let jobs = ((chunk.memory_limit.saturating_sub(read_ahead) / need) as usize)
        .clamp(1, rayon::current_num_threads());
    // Each chunk narrows to about max_root_points / K points under its root, so that the
    // levels under the top grow as gradually as in a single build.
    let mut chunk_options = options.clone();
    chunk_options.build.max_root_points = params
        .max_cluster_size
        .max(params.max_root_points.div_ceil(groups.len() as u32));
    let options = &chunk_options;
    let extras = BuildExtras {
        attribute_range: layout.attribute.then_some(range),
        attribute_log10: options.attribute_log10 && layout.attribute,
        keep_levels: params.delta_n as usize,
        // One range for every chunk, from the whole frame's species.
        radius_range: crate::hierarchy::radius_range(&species, &counts),
    };
    // What the builds at work, the two chunks read ahead and a margin leave under the
    // limit holds finished chunks' results until the assembly.
    let kept = std::sync::atomic::AtomicU64::new(0);
    let input = ChunkInput {
        layout,
        species: &species,
        species_map: &species_map,
        options,
        extras: &extras,
        extra_infos: &extra_infos,
        dir,
        keep_budget: chunk
            .memory_limit
            .saturating_sub(jobs as u64 * need + read_ahead + chunk.memory_limit / 8),
        kept: &kept,
    };
    progress.stage(
        &format!("building {} chunks", groups.len()),
        Some(n as u64),
        "particles",
    );
    // A reader thread loads the chunks' cells in order, one chunk ahead (its disk reads
    // overlap the builds); `jobs` workers take the next loaded chunk as they finish one
    // (each build is parallel itself). Results are kept by chunk index, so the order
    // never depends on timing.
    let failed = std::sync::atomic::AtomicBool::new(false);
    let results: Vec<std::sync::Mutex<Option<Result<ChunkResult, ConvertError>>>> = (0..groups
        .len())
        .map(|_| std::sync::Mutex::new(None))
        .collect();
    type Loaded = (usize, Result<Vec<Vec<u8>>, ConvertError>);
    let (to_builds, loaded) = std::sync::mpsc::sync_channel::<Loaded>(1);
    // Dropped with the last worker, which ends the reader should the workers stop first.
    let loaded = std::sync::Arc::new(std::sync::Mutex::new(loaded));
    std::thread::scope(|scope| {
        let (groups, leaves, failed) = (&groups, &leaves, &failed);
        scope.spawn(move || {
            for (c, g) in groups.iter().enumerate() {
                if failed.load(std::sync::atomic::Ordering::Relaxed) {
                    return;
                }
                let cells = load_cells(&leaves[g.clone()], layout);
                if to_builds.send((c, cells)).is_err() {
                    return;
                }
            }
        });
        for _ in 0..jobs.min(groups.len()) {
            let loaded = loaded.clone();
            let (input, results) = (&input, &results);
            scope.spawn(move || loop {
                use std::sync::atomic::Ordering::Relaxed;
                let next = loaded.lock().unwrap_or_else(|e| e.into_inner()).recv();
                let Ok((c, cells_read)) = next else { return };
                if failed.load(Relaxed) {
                    return;
                }
                let cells = &leaves[groups[c].clone()];
                let r = cells_read.and_then(|l| build_chunk(c, cells, l, input));
                match &r {
                    Ok(_) => progress.advance(cells.iter().map(|c| c.count as u64).sum()),
                    Err(_) => failed.store(true, Relaxed),
                }
                *results[c].lock().unwrap_or_else(|e| e.into_inner()) = Some(r);
            });
        }
        drop(loaded);
    });
    let mut chunks = Vec::with_capacity(groups.len());
    for r in results {
        match r.into_inner().unwrap_or_else(|e| e.into_inner()) {
            Some(Ok(c)) => chunks.push(c),
            Some(Err(e)) => return Err(e),
            None => {}
        }
    }
    if chunks.len() != groups.len() {
        return Err(ConvertError::Chunked("a chunk was not built".into()));
    }
    progress.finish_stage();
    let build_time = t1.elapsed();

    // 3. Assembly.
    let t2 = Instant::now();
    metadata.particles = n as u64;
    metadata.radius = layout
        .radius
        .then(|| crate::hierarchy::radius_range(&species, &counts))
        .flatten();
    metadata.species = species;
    metadata.attributes = extra_infos.clone();
    metadata.attribute_log10 = options.attribute_log10 && layout.attribute;
    if let Some(info) = metadata.attribute.as_mut() {
        info.min = range.0;
        info.max = range.1;
    } else if layout.attribute {
        metadata.attribute = Some(mdlod_format::meta::AttributeInfo {
            name: attribute_name.unwrap_or_else(|| "attribute".into()),
            min: range.0,
            max: range.1,
            log10: false,
        });
    }
    metadata.build = mdlod_format::meta::BuildInfo {
        max_cluster_size: params.max_cluster_size,
        max_root_points: params.max_root_points,
        delta_n: params.delta_n,
        position_bits: params.position_bits,
        chunk_points: Some(chunk.chunk_points as u64),
    };
    let (levels, nodes, max_position_error) =
        assemble(&chunks, &metadata, output, params, progress)?;
    let precision =
        crate::convert::precision_note(max_position_error, params.position_bits, &metadata.species);
    let write_time = t2.elapsed();
    drop(work);
    let file_size = fs::metadata(output).map(|m| m.len()).unwrap_or(0);
    Ok(ConvertReport {
        particles: n as u64,
        levels,
        nodes,
        max_position_error,
        read_time,
        build_time,
        write_time,
        file_size,
        notes: {
            let mut notes: Vec<String> = radius_notes;
            let logged = crate::convert::logged_columns(&metadata);
            if let Some(a) = &metadata.attribute {
                let span = crate::convert::attribute_span_note(
                    &a.name,
                    a.min,
                    a.max,
                    options,
                    &logged,
                    &|| first_octaves.clone(),
                );
                let bulk = (span.is_none() && !options.attribute_log10)
                    .then(|| crate::convert::bulk_note(&a.name, a.min, a.max, &first_octaves))
                    .flatten();
                notes.extend(span.into_iter().chain(bulk));
            }
            for ((e, &whole), octaves) in metadata
                .attributes
                .iter()
                .zip(&extra_whole)
                .zip(&extra_octaves)
                .filter(|((e, _), _)| !e.log10)
            {
                // Ids (of molecules) are told by their whole numbers, as for the first.
                let (note, ids) = crate::convert::extra_range_note(
                    &e.name,
                    e.min,
                    e.max,
                    whole,
                    &logged,
                    &|| octaves.clone(),
                );
                let bulk = (note.is_none() && !ids)
                    .then(|| crate::convert::bulk_note(&e.name, e.min, e.max, octaves))
                    .flatten();
                notes.extend(note.into_iter().chain(bulk));
            }
            notes.extend(crate::convert::elements_in_other_units_note(
                metadata.units.as_deref(),
                &metadata.species,
                &options.radii,
            ));
            // The particles' bounds are the cells'; how many lie outside the box is not
            // counted (the corners of the bounds stand for them).
            let mut lo = [f32::INFINITY; 3];
            let mut hi = [f32::NEG_INFINITY; 3];
            for cell in &leaves {
                for k in 0..3 {
                    lo[k] = lo[k].min(cell.lo[k]);
                    hi[k] = hi[k].max(cell.hi[k]);
                }
            }
            let far = crate::convert::survey_positions(&[lo, hi], metadata.simulation_box.as_ref())
                .2
                .map(|f| crate::convert::FarOutside {
                    count: None,
                    farthest: None,
                    ..f
                });
            notes.extend(crate::convert::position_notes(
                lo,
                hi,
                n as u64,
                &metadata.species,
                far,
                metadata.simulation_box.as_ref(),
                Some(&counts),
                &options.radii,
            ));
            crate::convert::drop_default_radius_note_said_twice(&mut notes);
            notes.extend(crate::convert::delta_n_note(params.delta_n, levels));
            notes.extend(precision);
            notes
        },
        frame: None,
    })
}

/// The smallest and largest of a window's attribute `values` (of particles from `start`
/// on); the first that is not finite is an error of the place `path` names.
fn finite_range(
    values: &[f32],
    start: usize,
    path: impl FnOnce() -> String,
) -> Result<(f32, f32), ConvertError> {
    if let Some(index) =
        crate::readers::first_index(values.len(), |i: usize| !values[i].is_finite())
    {
        return Err(ConvertError::Build {
            path: path(),
            source: BuildError::NonFiniteAttribute {
                index: start + index,
                value: values[index],
            },
        });
    }
    Ok(crate::convert::par_min_max(values))
}

/// The axis-aligned bounds of a (possibly triclinic) box.
pub(crate) fn box_bounds(b: &SimulationBox) -> ([f32; 3], [f32; 3]) {
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for corner in 0..8 {
        for k in 0..3 {
            let mut v = b.origin[k];
            if corner & 1 != 0 {
                v += b.a[k];
            }
            if corner & 2 != 0 {
                v += b.b[k];
            }
            if corner & 4 != 0 {
                v += b.c[k];
            }
            lo[k] = lo[k].min(v as f32);
            hi[k] = hi[k].max(v as f32);
        }
    }
    (lo, hi)
}

/// The global layout of the chunks' levels under one top node.
struct Layout {
    /// Global level of every chunk's local level 0 is `1 + pad[c]`.
    pad: Vec<usize>,
    /// Index of the last level.
    last: usize,
    /// `offset[g][c]`: points of level `g` before chunk `c` (`offset[g][K]` is the count).
    offset: Vec<Vec<u64>>,
    levels: Vec<LevelRecord>,
}

impl Layout {
    fn new(chunks: &[ChunkResult]) -> Result<Layout, ConvertError> {
        let k = chunks.len();
        let last = chunks.iter().map(ChunkResult::depth).max().unwrap_or(1);
        let pad: Vec<usize> = chunks.iter().map(|c| last - c.depth()).collect();
        let mut offset = vec![vec![0u64; k + 1]; last + 1];
        offset[0][k] = 1;
        for g in 1..=last {
            for (c, ch) in chunks.iter().enumerate() {
                let here = if g <= pad[c] {
                    1
                } else {
                    ch.levels[g - 1 - pad[c]].point_count
                };
                offset[g][c + 1] = offset[g][c] + here;
            }
        }
        let mut levels = Vec::with_capacity(last + 1);
        let mut node_first = 0u64;
        for (g, off) in offset.iter().enumerate() {
            let count = off[k];
            if count > u64::from(u32::MAX) {
                return Err(ConvertError::Build {
                    path: format!("level {g}"),
                    source: BuildError::TooMany(count as usize),
                });
            }
            levels.push(LevelRecord {
                point_count: count,
                node_first,
                reserved: [0; 2],
            });
            if g < last {
                node_first += count;
            }
        }
        crate::hierarchy::check_node_total(&levels).map_err(|source| ConvertError::Build {
            path: "the levels above the particles".into(),
            source,
        })?;
        Ok(Layout {
            pad,
            last,
            offset,
            levels,
        })
    }

    /// Global node index of point `i` of chunk `c` on global level `g`.
    fn node(&self, g: usize, c: usize, i: u64) -> u32 {
        (self.levels[g].node_first + self.offset[g][c] + i) as u32
    }

    fn count(&self, g: usize, c: usize) -> u64 {
        self.offset[g][c + 1] - self.offset[g][c]
    }
}

fn assemble(
    chunks: &[ChunkResult],
    metadata: &Metadata,
    output: &Path,
    params: &crate::hierarchy::BuildParams,
    progress: &dyn Progress,
) -> Result<(usize, usize, f64), ConvertError> {
    let lay = Layout::new(chunks)?;
    let k = chunks.len();
    let last = lay.last;
    let dn = params.delta_n as usize;
    let bits = params.position_bits;
    // The points of global level `m` of chunk `c`, unquantized, for the levels the top
    // node encodes (m ≤ δn): padding copies of the root, or the chunk's kept levels.
    let top_points = |c: usize, m: usize| -> Vec<[f32; 3]> {
        if m <= lay.pad[c] {
            vec![chunks[c].root.position]
        } else {
            chunks[c].top_positions[m - 1 - lay.pad[c]].clone()
        }
    };
    // The top node: one cluster of the chunk roots.
    let roots = LevelPoints(chunks.iter().map(|c| c.root).collect());
    let top = representatives(
        &Source::Reps(&roots),
        &Clusters {
            order: (0..k as u32).collect(),
            offsets: vec![0, k as u32],
        },
    )
    .0[0];
    let top_pl = dn.min(last);
    let mut max_off = [0.0f64; 3];
    for m in 1..=top_pl {
        for c in 0..k {
            for x in top_points(c, m) {
                for a in 0..3 {
                    max_off[a] =
                        max_off[a].max((f64::from(x[a]) - f64::from(top.position[a])).abs());
                }
            }
        }
    }
    let top_scale = quantize::scale_for(max_off, bits);
    let mut metadata = metadata.clone();
    metadata.max_position_error = if last <= dn {
        // The particles themselves are encoded by the top node.
        let mut e = 0.0f64;
        for c in 0..k {
            for x in top_points(c, last) {
                let q = [0, 1, 2].map(|a| {
                    quantize::encode(f64::from(x[a]), top.position[a], top_scale[a], bits)
                });
                let d = quantize::decode3(q, top.position, top_scale, bits);
                e = e.max(
                    (0..3)
                        .map(|a| (f64::from(d[a]) - f64::from(x[a])).powi(2))
                        .sum::<f64>()
                        .sqrt(),
                );
            }
        }
        e
    } else {
        chunks.iter().map(|c| c.max_error).fold(0.0, f64::max)
    };

    // The δn in effect (see `Hierarchy::write`).
    metadata.build.delta_n = metadata.build.delta_n.min(last as u32);
    let json = metadata
        .to_json()
        .map_err(|problem| mdlod_format::FormatError::Write {
            path: output.to_path_buf(),
            problem,
        })?;
    let total_bytes: u64 = chunks
        .iter()
        .map(|c| {
            c.nodes.len_bytes()
                + c.positions.len_bytes()
                + c.species.len_bytes()
                + c.attribute.as_ref().map_or(0, Kept::len_bytes)
                + c.radius.as_ref().map_or(0, Kept::len_bytes)
                + c.extras
                    .iter()
                    .map(|e| e.values.len_bytes() + e.means.len_bytes())
                    .sum::<u64>()
        })
        .sum();
    if chunks
        .iter()
        .any(|c| c.extras.len() != metadata.attributes.len())
    {
        return Err(ConvertError::Chunked(format!(
            "a chunk holds another count of further attributes than the {} of the frame",
            metadata.attributes.len()
        )));
    }
    progress.stage("writing", Some(total_bytes), "bytes");
    // Gigabytes: written from a thread of its own, past the page cache.
    let mut w = Writer::create_with(output, bits, crate::direct::open)?;
    w.write_section(SectionKind::Metadata, 0, &json)?;
    w.write_pod_section(SectionKind::Levels, 0, &lay.levels)?;

    // Nodes, level by level.
    let node_count = lay.levels[last].node_first as usize;
    {
        let mut s = w.section(SectionKind::Nodes, 0)?;
        let mut top_node = top.node(0);
        // (The chunks' roots keep their mean values; the file, their logarithm.)
        if metadata.attribute_log10 {
            top_node.attribute = top_node.attribute.log10();
        }
        top_node.quant_scale = top_scale;
        top_node.child_count = k as u32;
        top_node.point_level = top_pl as u8;
        top_node.point_count = lay.levels[top_pl].point_count as u32;
        s.write_pod(&[top_node])?;
        let mut buf: Vec<NodeRecord> = Vec::new();
        for g in 1..last {
            let pl = (g + dn).min(last);
            let enc_level = pl.saturating_sub(dn);
            for (c, ch) in chunks.iter().enumerate() {
                let pad = lay.pad[c];
                let parent_of_root = if pad == 0 { 0 } else { lay.node(pad, c, 0) };
                if g <= pad {
                    // A padding copy of the chunk's root.
                    // rms_radius 0: the one child sits at the centroid.
                    let mut n = NodeRecord {
                        rms_radius: 0.0,
                        ..ch.root.node(g)
                    };
                    if metadata.attribute_log10 {
                        n.attribute = n.attribute.log10();
                    }
                    n.quant_scale = ch.root_scale;
                    n.child_first = lay.offset[g + 1][c] as u32;
                    n.point_first = lay.offset[pl][c] as u32;
                    n.point_count = lay.count(pl, c) as u32;
                    n.point_level = pl as u8;
                    n.parent = if g == 1 { 0 } else { lay.node(g - 1, c, 0) };
                    n.quant_node = if enc_level == 0 {
                        0
                    } else {
                        lay.node(enc_level, c, 0)
                    };
                    s.write_pod(&[n])?;
                    continue;
                }
                let j = g - 1 - pad;
                let local = &ch.levels;
                let first = local[j].node_first;
                let count = local[j].point_count;
                let src = ch.nodes.bytes()?;
                let size = std::mem::size_of::<NodeRecord>();
                let step = 1u64 << 16;
                let mut at = 0u64;
                while at < count {
                    let len = step.min(count - at);
                    buf.resize(len as usize, bytemuck::Zeroable::zeroed());
                    bytemuck::cast_slice_mut(&mut buf).copy_from_slice(
                        src.range((first + at) * size as u64, len as usize * size)?,
                    );
                    for n in &mut buf {
                        n.child_first += lay.offset[g + 1][c] as u32;
                        n.point_first += lay.offset[pl][c] as u32;
                        n.parent = if j == 0 {
                            parent_of_root
                        } else {
                            let i = u64::from(n.parent) - local[j - 1].node_first;
                            lay.node(g - 1, c, i)
                        };
                        n.quant_node = if enc_level > pad {
                            let lj = enc_level - 1 - pad;
                            let i = u64::from(n.quant_node) - local[lj].node_first;
                            lay.node(enc_level, c, i)
                        } else if enc_level == 0 {
                            0
                        } else {
                            lay.node(enc_level, c, 0)
                        };
                        n.level = g as u8;
                        n.point_level = pl as u8;
                    }
                    s.write_pod(&buf)?;
                    progress.advance(len * std::mem::size_of::<NodeRecord>() as u64);
                    at += len;
                }
                if g == last - 1 {
                    ch.nodes.remove()?;
                }
            }
        }
        s.end()?;
    }
    if last == 1 {
        for ch in chunks {
            ch.nodes.remove()?;
        }
    }

    // Positions, level by level.
    let mut qbuf: Vec<[u16; 3]> = Vec::new();
    for m in 1..=last {
        let mut s = w.section(SectionKind::Positions, m as u32)?;
        let put = |s: &mut mdlod_format::writer::SectionWriter<'_>, q: &[[u16; 3]]| {
            if bits == 16 {
                s.write_pod(q)
            } else {
                let b: Vec<[u8; 3]> = q.iter().map(|p| p.map(|v| v as u8)).collect();
                s.write_pod(&b)
            }
        };
        for (c, ch) in chunks.iter().enumerate() {
            let pad = lay.pad[c];
            if m <= dn {
                let q: Vec<[u16; 3]> = top_points(c, m)
                    .iter()
                    .map(|x| {
                        [0, 1, 2].map(|a| {
                            quantize::encode(f64::from(x[a]), top.position[a], top_scale[a], bits)
                        })
                    })
                    .collect();
                put(&mut s, &q)?;
            } else if m <= pad + 1 {
                // A padding copy (or the root itself) encoded by a padding copy.
                let x = ch.root.position;
                let q = [0, 1, 2]
                    .map(|a| quantize::encode(f64::from(x[a]), x[a], ch.root_scale[a], bits));
                put(&mut s, &[q])?;
            } else {
                let j = m - 1 - pad;
                let before: u64 = ch.levels[1..j].iter().map(|l| l.point_count).sum();
                let count = ch.levels[j].point_count;
                let src = ch.positions.bytes()?;
                let step = 1u64 << 18;
                let mut at = 0u64;
                while at < count {
                    let len = step.min(count - at);
                    let part = src.range((before + at) * 6, len as usize * 6)?;
                    if bits == 16 {
                        // Stored as written: straight from memory or the mapping.
                        s.write_bytes(part)?;
                    } else {
                        qbuf.resize(len as usize, [0; 3]);
                        bytemuck::cast_slice_mut(&mut qbuf).copy_from_slice(part);
                        put(&mut s, &qbuf)?;
                    }
                    progress.advance(len * 6);
                    at += len;
                }
            }
            if m == last {
                ch.positions.remove()?;
            }
        }
        s.end()?;
    }

    // Per-particle sections.
    let copy = |w: &mut Writer, kind: SectionKind, parts: Vec<&Kept<u16>>| {
        let mut s = w.section(kind, last as u32)?;
        for part in parts {
            // Written straight from memory or the mapping, no copy in between.
            let bytes = part.bytes()?;
            s.write_bytes(bytes.all())?;
            progress.advance(bytes.all().len() as u64);
            drop(bytes);
            part.remove()?;
        }
        s.end()?;
        Ok::<(), ConvertError>(())
    };
    copy(
        &mut w,
        SectionKind::Species,
        chunks.iter().map(|c| &c.species).collect(),
    )?;
    let attributes: Vec<&Kept<u16>> = chunks.iter().filter_map(|c| c.attribute.as_ref()).collect();
    if !attributes.is_empty() {
        copy(&mut w, SectionKind::Attribute, attributes)?;
    }
    let radii: Vec<&Kept<u16>> = chunks.iter().filter_map(|c| c.radius.as_ref()).collect();
    if !radii.is_empty() {
        let kind = match metadata.radius {
            Some(r) if r.log => SectionKind::RadiusLog,
            _ => SectionKind::Radius,
        };
        copy(&mut w, kind, radii)?;
    }
    let extras = metadata.attributes.len();
    if extras > 0 {
        // Each attribute's values, chunk after chunk.
        copy(
            &mut w,
            SectionKind::Attributes,
            (0..extras)
                .flat_map(|e| chunks.iter().map(move |c| &c.extras[e].values))
                .collect(),
        )?;
        // Each attribute's node means, in the node table's order: the top node's from
        // the chunk roots' sums, a padding copy's its root's, then the chunks' own.
        let mut s = w.section(SectionKind::NodeAttributes, 0)?;
        let mut buf: Vec<f32> = Vec::new();
        for e in 0..extras {
            let top_sums = chunks
                .iter()
                .fold(crate::hierarchy::extra::MeanSums::default(), |a, c| {
                    a.and(c.extras[e].sums)
                });
            // (A logarithm's mean is the logarithm of the linear mean.)
            let mean = top_sums.mean();
            let log10 = metadata.attributes.get(e).is_some_and(|a| a.log10);
            s.write_pod(&[if log10 { mean.log10() } else { mean }])?;
            for g in 1..last {
                for (c, ch) in chunks.iter().enumerate() {
                    let means = ch.extras[e].means.bytes()?;
                    let pad = lay.pad[c];
                    let (first, count) = if g <= pad {
                        (0, 1)
                    } else {
                        let j = g - 1 - pad;
                        (ch.levels[j].node_first, ch.levels[j].point_count)
                    };
                    buf.resize(count as usize, 0.0);
                    bytemuck::cast_slice_mut(&mut buf)
                        .copy_from_slice(means.range(first * 4, count as usize * 4)?);
                    s.write_pod(&buf)?;
                    progress.advance(count * 4);
                }
            }
            for ch in chunks {
                ch.extras[e].means.remove()?;
            }
        }
        s.end()?;
    }
    w.finish()?;
    progress.finish_stage();
    Ok((last + 1, node_count, metadata.max_position_error))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A Slurm job's step in cgroup v2 (the limit on the job, not the task's own group),
    /// and in v1 with v1's "unlimited"; no memory controller, no limit.
    #[test]
    fn the_memory_limit_of_the_control_groups_is_the_tightest_up_to_the_root() {
        let files = [
            ("/sys/fs/cgroup/memory.max", "max"),
            (
                "/sys/fs/cgroup/system.slice/slurmstepd.scope/memory.max",
                "max",
            ),
            (
                "/sys/fs/cgroup/system.slice/slurmstepd.scope/job_7/memory.max",
                "68719476736\n",
            ),
            (
                "/sys/fs/cgroup/system.slice/slurmstepd.scope/job_7/step_0/memory.max",
                "max",
            ),
            (
                "/sys/fs/cgroup/system.slice/slurmstepd.scope/job_7/step_0/user/task_0/memory.max",
                "max",
            ),
            (
                "/sys/fs/cgroup/memory/memory.limit_in_bytes",
                "9223372036854771712",
            ),
            (
                "/sys/fs/cgroup/memory/box/memory.limit_in_bytes",
                "2147483648",
            ),
        ];
        let read = |p: &str| files.iter().find(|f| f.0 == p).map(|f| f.1.to_string());
        let v2 = "0::/system.slice/slurmstepd.scope/job_7/step_0/user/task_0\n";
        assert_eq!(cgroup_memory_limit(v2, &read), Some(64 << 30));
        let v1 = "5:devices:/\n4:memory:/box\n1:cpu,cpuacct:/\n";
        assert_eq!(cgroup_memory_limit(v1, &read), Some(2 << 30));
        assert_eq!(cgroup_memory_limit("4:memory:/\n", &read), None);
        assert_eq!(cgroup_memory_limit("1:cpu:/box\n", &read), None);
    }

    #[test]
    fn a_cell_is_refined_by_the_coarsest_grid_that_leaves_room() {
        let m = 1000;
        // Just over a chunk: 4×4×4 (64 cells of about a sixty-fourth), not 8×8×8.
        assert_eq!(refine_bits(m + 1, m), 2);
        assert_eq!(refine_bits(4 * m, m), 2);
        assert_eq!(refine_bits(4 * m + 1, m), 3);
        // Never finer than the partition's own grid.
        assert_eq!(refine_bits(usize::MAX, m), GRID_BITS);
        // A cell within a sixteenth of a 2×2×2 grid's room.
        assert_eq!(refine_bits(m / 2, m), 1);
    }

    #[test]
    fn the_first_grid_is_refined_only_past_64_chunks() {
        let m = 1000;
        assert_eq!(first_bits(1, m), GRID_BITS);
        assert_eq!(first_bits(64 * m, m), GRID_BITS);
        assert_eq!(first_bits(64 * m + 1, m), 4);
        assert_eq!(first_bits(512 * m, m), 4);
        assert_eq!(first_bits(512 * m + 1, m), 5);
        assert_eq!(first_bits(usize::MAX, m), MAX_FIRST_BITS);
        // The benchmark's sizes with the default chunks: 2×10^8 keeps 8×8×8, 10^9 16×16×16.
        assert_eq!(first_bits(200_000_000, DEFAULT_CHUNK_POINTS), 3);
        assert_eq!(first_bits(1_000_000_000, DEFAULT_CHUNK_POINTS), 4);
    }

    #[test]
    fn cells_closed_between_appends_hold_the_same_records() {
        let layout = RecordLayout {
            attribute: false,
            radius: false,
            extras: 0,
        };
        let records: Vec<u8> = (0..5000u32)
            .flat_map(|i| {
                let x = [(i % 17) as f32, (i % 13) as f32 * 2.0, (i % 7) as f32 * 3.0];
                let mut r: Vec<u8> = x.iter().flat_map(|v| v.to_le_bytes()).collect();
                r.extend_from_slice(&(i as u16).to_le_bytes());
                r
            })
            .collect();
        let cells = |keep_open: bool| {
            let dir = tempfile::tempdir().unwrap();
            let bounds = ([0.0; 3], [16.0, 24.0, 18.0]);
            let mut p = Partitioner::new(dir.path(), "t".into(), layout, bounds, 2);
            p.keep_open = keep_open;
            for window in records.chunks(14 * 700) {
                p.add(window).unwrap();
            }
            let cells = p.finish();
            cells
                .iter()
                .map(|c| (c.count, c.lo, c.hi, fs::read(&c.path).unwrap()))
                .collect::<Vec<_>>()
        };
        let open = cells(true);
        assert!(open.len() > 8, "{} cells", open.len());
        assert_eq!(open.iter().map(|c| c.0).sum::<usize>(), 5000);
        assert_eq!(open, cells(false));
    }

    #[test]
    fn a_cell_file_reads_back_what_was_appended_released_or_not() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("cell");
        let mut f = CellFile::create(&path).unwrap();
        let pieces: Vec<Vec<u8>> = [17usize, 4096, 0, 70_001, 5]
            .iter()
            .enumerate()
            .map(|(i, &n)| (0..n).map(|j| (j * 7 + i * 31) as u8).collect())
            .collect();
        for (i, p) in pieces.iter().enumerate() {
            f.append(p).unwrap();
            if i % 2 == 1 {
                f.release();
            }
        }
        let want = pieces.concat();
        assert!(fs::read(&path).unwrap() == want);
        // Ranges from any offset into one reused buffer; a read past the end fails.
        let mut buf = Vec::new();
        for (at, n) in [
            (0usize, want.len()),
            (17, 5000),
            (4099, 60_000),
            (want.len() - 1, 1),
        ] {
            let got = read_file_range(&path, at as u64, n, &mut buf).unwrap();
            assert!(got == &want[at..at + n], "{at}+{n}");
        }
        let err = read_file_range(&path, 0, want.len() + 1, &mut buf).unwrap_err();
        assert_eq!(err.kind(), std::io::ErrorKind::UnexpectedEof);
    }

    #[test]
    fn spread_bits_interleaves_one_axis() {
        for i in 0..1024u32 {
            let slow = (0..10).fold(0usize, |c, b| c | (((i >> b) & 1) as usize) << (3 * b));
            assert_eq!(spread_bits(i), slow, "{i}");
        }
        assert_eq!(cell_of([1.0, 0.0, 0.0], [0.0; 3], [1.0; 3], 1), 0b001);
        assert_eq!(cell_of([0.0, 1.0, 0.0], [0.0; 3], [1.0; 3], 1), 0b010);
        assert_eq!(cell_of([0.0, 0.0, 1.0], [0.0; 3], [1.0; 3], 1), 0b100);
        // x in column 3 (0b11), y in 0, z in 2 (0b10): bits 0 and 3 from x, 5 from z.
        assert_eq!(cell_of([0.9, 0.1, 0.6], [0.0; 3], [1.0; 3], 2), 0b101_001);
    }

    /// A need is said rounded up to a whole MiB: a limit of 64 MiB is never "below
    /// the 64.0 MiB" a chunk needs.
    #[test]
    fn needs_are_said_rounded_up() {
        assert_eq!(need_text((64 << 20) + 1000), "65 MiB");
        assert_eq!(need_text(64 << 20), "64 MiB");
        assert_eq!(need_text(1000), "1000 bytes");
        assert_eq!(size_text((64 << 20) + 1000), "64.0 MiB");
    }

    #[test]
    fn morton_codes_of_a_coarser_grid_are_the_finer_codes_high_bits() {
        let (lo, hi) = ([0.0f32; 3], [1.0f32; 3]);
        for x in [[0.1f32, 0.7, 0.3], [0.9, 0.2, 0.55], [0.0, 1.0, 0.5]] {
            let fine = cell_of(x, lo, hi, 3);
            assert_eq!(cell_of(x, lo, hi, 2), fine >> 3);
            assert_eq!(cell_of(x, lo, hi, 1), fine >> 6);
        }
    }
}
