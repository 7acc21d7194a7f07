//! Whole trajectories: every frame of a set of inputs to `DIR/frame-<timestep>.mdlod`,
//! with a manifest `DIR/dataset.json`, resumable, and shardable over a cluster.
//!
//! How it works.
//! 1. Every input is opened in turn (multi-frame files, `%` piece sets and binary dumps
//!    alike; a gzip input's text is dropped again, and the worker converting its frames
//!    reopens it, decompressing a large one into a working file) and its frames listed
//!    with their timesteps (an input without timesteps numbers its
//!    frames by their position in the whole list). Frames are sorted by timestep; two
//!    frames with the same timestep are an error naming both sources.
//!    While an input is open, how its first frame names species is noted (a radius
//!    override that no frame can hold, such as `Cu` for LAMMPS type numbers, is refused
//!    before anything is converted), and every frame's attribute is resolved (its name as
//!    the reader records it; a column the frame lacks is an error then).
//! 2. With a shard `I/N`, this process takes the frames at positions `I, I + N, ...` of
//!    that sorted list, so N processes (a Slurm job array) split the work without talking
//!    to each other; each writes its own manifest `dataset.shard-I-of-N.json`, and
//!    [`merge`] joins them into `dataset.json`. Each records which list it split
//!    ([`InputFrames`]): shards started before and after a file set grew take every N-th
//!    frame of different lists, leaving frames to none, and the merge refuses them.
//! 3. A frame without particles cannot be a `.mdlod` file: it is left out (not written,
//!    not listed, not expected of the shard) and reported ([`BatchReport::empty`]), told
//!    from its header alone on every run. A frame whose output exists, opens (the reader
//!    validates its structure), records the same source (path, frame, size and
//!    modification time, to the nanosecond where the file system keeps it) and was built
//!    with the same settings is skipped; anything else is converted again, except that
//!    a frame whose input changed but whose own bytes did not is kept: the frames of an
//!    uncompressed LAMMPS text or binary dump or XYZ file are byte ranges of it, each
//!    recorded with its range and checksum ([`FrameBytes`]; a GSD frame's checksum is of
//!    its chunks and frame 0's it takes), so a rerun over a dump a
//!    running simulation has appended to reads the old frames once to compare them
//!    and converts only the new ones (and lists the kept ones with the input's size and
//!    time now, so the next rerun need not read them again). The settings
//!    are everything the file depends on ([`same_build`]): cluster size, root points, δn,
//!    position bits, the chunk size where the frame is above it (a chunked build differs
//!    from a whole one), every species' radius (as given now, else as the input gives it
//!    or its default), the attribute asked for now (or none), and for LAMMPS binary dumps
//!    the column names given (`--columns`; the file does not record them, the manifests
//!    do: a frame no manifest lists with its checksum is converted again). Leftover
//!    temporary files of killed runs are removed first: only this shard's own frames' (a
//!    shard running beside it never writes those) and temporary manifests older than
//!    [`STALE_TEMP`].
//!    Frame files no frame of the inputs is written to are named and left alone, except
//!    those converted from dumps that are gone since (users delete dumps once converted
//!    and add new ones): a manifest's record of one, with the file's checksum and this
//!    run's settings, is listed again ([`BatchReport::kept_gone`]; in a sharded run by
//!    every shard, and [`merge`] lists each once), so the data set keeps every frame it
//!    has.
//! 4. Frames are converted by a few workers at once, as many as the memory limit allows
//!    (about [`BYTES_PER_PARTICLE`] per particle each, or one chunk's build for a frame
//!    above the chunk size, at most one per thread); each
//!    conversion is itself parallel. Outputs appear by atomic rename only when complete,
//!    and the manifest is rewritten (temporary file + rename) as frames complete, at most
//!    once a second ([`MANIFEST_INTERVAL`]) and once at the end, listing only complete
//!    ones: killing a batch at any moment leaves no file that looks complete and a
//!    manifest that is true (it may miss the frames of its last second, which a rerun
//!    finds complete and lists). A run that fails before any output is written (an
//!    error every frame meets, such as a binary dump's missing `--columns`) puts the
//!    manifest back as it was (none, if there was none). A handler of SIGTERM (a scheduler's time limit) or
//!    Ctrl-C lists those too before the program exits, through a [`ManifestHandle`].

use std::fmt::Display;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Mutex;

use mdlod_format::meta::{BuildInfo, FrameBytes, SimulationBox, SourceInfo};
use mdlod_format::MdlodFile;
use serde::{Deserialize, Serialize};

use crate::convert::{ConvertError, ConvertOptions};
use crate::progress::Progress;
use crate::readers::{DumpFile, InputFormat, ReadError, ReadOptions};
use crate::species::SpeciesNaming;

/// Peak memory of one frame's conversion per particle (measured with the `mdlod`
/// binary's allocator in huge pages: 125 MiB for 10^6 particles, 0.96 GiB for 10^7),
/// with some headroom.
pub const BYTES_PER_PARTICLE: u64 = 140;

/// Least time between two rewrites of the manifest while frames are converted (it is
/// rewritten once more at the end). Every rewrite writes the whole list: after every
/// frame, a batch of thousands of small frames spent its time rewriting it.
pub const MANIFEST_INTERVAL: std::time::Duration = std::time::Duration::from_secs(1);

/// Age from which a leftover temporary manifest is removed: writing one takes
/// milliseconds, so one this old belongs to no live run (a temporary manifest's name
/// does not say which shard writes it, so a younger one may be another shard's).
pub const STALE_TEMP: std::time::Duration = std::time::Duration::from_secs(600);

/// The manifest's file name in a batch directory.
pub const MANIFEST: &str = "dataset.json";

/// Where a shard that converts moves the merged manifest it outdates: no manifest any
/// more, but a record of how its frames were converted (see [`BatchReport::kept_gone`]).
pub const PREVIOUS_MANIFEST: &str = ".dataset.previous.json";

/// The frame indexes of the inputs' text dumps, kept between runs and shared by shards
/// ([`crate::readers::index_cache`]): a text input unchanged since is not scanned again.
pub const INDEX_CACHE: &str = ".dataset.index.json";

/// One converted frame in a manifest.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FrameEntry {
    pub timestep: u64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub time: Option<f64>,
    pub particles: u64,
    #[serde(default, rename = "box", skip_serializing_if = "Option::is_none")]
    pub simulation_box: Option<SimulationBox>,
    /// File name inside the batch directory.
    pub file: String,
    /// The file's section-table checksum (XXH3-64, hex): it covers every section's
    /// checksum, so it identifies the whole content.
    pub checksum: String,
    pub source: SourceInfo,
    /// The column names given for a LAMMPS binary dump (`--columns`), which decide what
    /// its values are and which the file does not record; absent when none were given.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub columns: Option<Vec<String>>,
    /// The `--radius` overrides that named species of the frame when it was converted:
    /// a rerun compares them with its own instead of reading the input again to learn
    /// the radii it gives (absent in manifests of earlier versions).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub radii: Option<Vec<(String, f32)>>,
    /// The `--species-name` renames the frame was converted with; absent when none were
    /// given (and in manifests of earlier versions).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub species_names: Option<Vec<(String, String)>>,
    /// Where the particles' sizes were read from when not by default
    /// ([`crate::readers::SizeColumn::record`]: `radius NAME`, `diameter NAME`, `none`);
    /// absent for the default (and in manifests of earlier versions).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sizes: Option<String>,
    /// The column the particles' species were read from (`--species-column`), when not
    /// the input's own `type` or `element`; absent then (and in manifests of earlier
    /// versions).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub species_column: Option<String>,
    /// Converted with the particles wrapped into the cell (`--wrap`); absent otherwise
    /// (and in manifests of earlier versions).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub wrap: bool,
    /// The source's absolute path when the frame was converted or last kept (the
    /// directory resolved; a `%` set's pattern as named there): whether its dump is gone
    /// is told by it, whatever directory a rerun starts in (absent in manifests of
    /// earlier versions).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub source_abs: Option<String>,
}

/// `dataset.json`: the frames of a batch directory, by timestep.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    pub mdlod_dataset: u32,
    /// `[I, N]` for a shard's manifest; absent in a whole one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shard: Option<[u32; 2]>,
    /// How many frames the run writing this manifest is responsible for (its shard's
    /// share of the inputs, less the frames without particles, which are never listed).
    /// A manifest that lists fewer is incomplete: its run is still going, failed or was
    /// killed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub expected_frames: Option<u64>,
    /// The list of input frames the run split into shards (every shard's frames and the
    /// others'), which every shard of one sharding must have seen alike: a file set that
    /// grew between two array tasks' starts gives them different lists, and taking every
    /// N-th frame of each leaves some frames to no shard. Absent in manifests of earlier
    /// versions (unknown: not compared).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub input_frames: Option<InputFrames>,
    pub frames: Vec<FrameEntry>,
    /// In a shard's manifest, the frames converted from dumps that are gone since, which
    /// every shard keeps ([`BatchReport::kept_gone`]) and the merge lists once; empty in
    /// a whole one, whose `frames` list them.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub gone: Vec<FrameEntry>,
    /// Frames converted from dumps that are gone since, with other settings than the last
    /// run's: on disk, not listed, recorded so that a later run with their settings lists
    /// them again.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub unlisted: Vec<FrameEntry>,
    /// Frames a run with `--keep-going` could not convert, each with why: not among
    /// `frames` nor expected, and what `verify` names as missing until a rerun converts
    /// them. Absent when none failed.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub failed: Vec<FailedEntry>,
    /// Frames without particles the run left out (a `.mdlod` file needs one): a box
    /// emptied by the end of a run, a pour not started. Not among `frames` nor
    /// expected; listed so that the trajectory's whole length is known. Absent when none
    /// (and in manifests of earlier versions).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub empty: Vec<EmptyEntry>,
    /// Which frame of a timestep given twice the run converted (`--duplicate-timesteps`:
    /// `first` or `last`); absent for the default, which refuses them. Shards must agree:
    /// merged, others would mix a restart's frames with the abandoned run's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub duplicates: Option<String>,
}

impl Manifest {
    /// The frames the run could not convert, named (`timestep 400`, `frame 3 of
    /// run.dump` where the timestep could not be read), at most six, with how many more
    /// (`and 4 more`).
    pub fn failed_names(&self) -> String {
        let named: Vec<String> = self
            .failed
            .iter()
            .take(6)
            .map(|f| match f.timestep {
                Some(t) => format!("timestep {t}"),
                None => format!("frame {} of {}", f.frame, f.input),
            })
            .collect();
        match self.failed.len() {
            k if k > 6 => format!("{} and {} more", named.join(", "), k - 6),
            _ => named.join(", "),
        }
    }
}

/// A frame of [`Manifest::empty`].
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct EmptyEntry {
    /// The frame's number in the batch: its timestep, else its position in the inputs.
    pub timestep: u64,
    /// The input and the frame's index in it.
    pub input: String,
    pub frame: u64,
}

impl From<&EmptyFrame> for EmptyEntry {
    fn from(e: &EmptyFrame) -> EmptyEntry {
        EmptyEntry {
            timestep: e.number,
            input: e.input.display().to_string(),
            frame: e.frame as u64,
        }
    }
}

/// A frame of [`Manifest::failed`].
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct FailedEntry {
    /// The frame's timestep, as the manifest would list it; absent where its header
    /// could not be read that far.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub timestep: Option<u64>,
    /// The input and the frame's index in it.
    pub input: String,
    pub frame: u64,
    /// The error.
    pub reason: String,
}

/// What identifies the list of input frames a batch split into shards
/// ([`Manifest::input_frames`]).
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct InputFrames {
    /// How many frames the inputs held (less the duplicates left out), in all shards.
    pub count: u64,
    /// XXH3-64 (hex) of the ordered list of the frames' (input file name, timestep). The
    /// file name without its directory: a requeued task may name the same inputs from
    /// another directory.
    pub xxh3: String,
}

impl InputFrames {
    /// The identity of the list of frames `(input, timestep)`, in the order the shards
    /// take them.
    fn of<'a>(frames: impl Iterator<Item = (&'a Path, u64)>) -> Self {
        let mut hasher = xxhash_rust::xxh3::Xxh3::new();
        let mut count = 0u64;
        for (input, timestep) in frames {
            let name = input.file_name().unwrap_or(input.as_os_str());
            let name = name.to_string_lossy();
            // Length-prefixed: no two lists hash the same bytes.
            hasher.update(&(name.len() as u64).to_le_bytes());
            hasher.update(name.as_bytes());
            hasher.update(&timestep.to_le_bytes());
            count += 1;
        }
        InputFrames {
            count,
            xxh3: format!("{:016x}", hasher.digest()),
        }
    }
}

/// Where shard manifests (name, list of input frames) record different lists of input
/// frames, the message saying which shards saw which; manifests that record none (of
/// earlier versions) are passed over.
fn different_input_lists(manifests: &[(String, Option<InputFrames>)]) -> Option<String> {
    // The distinct lists in order of first appearance, each with its manifests.
    let mut groups: Vec<(&InputFrames, Vec<&str>)> = Vec::new();
    for (name, list) in manifests {
        let Some(list) = list else { continue };
        match groups.iter_mut().find(|(l, _)| *l == list) {
            Some((_, names)) => names.push(name),
            None => groups.push((list, vec![name])),
        }
    }
    if groups.len() < 2 {
        return None;
    }
    let counts: Vec<u64> = groups.iter().map(|(l, _)| l.count).collect();
    let saw: Vec<String> = groups
        .iter()
        .map(|(l, names)| {
            // The same count twice: the lists differ in their files or timesteps.
            let same_count = counts.iter().filter(|&&c| c == l.count).count() > 1;
            format!(
                "{} saw {} frame{}{}",
                names.join(", "),
                l.count,
                if l.count == 1 { "" } else { "s" },
                if same_count {
                    " (of other files or timesteps)"
                } else {
                    ""
                }
            )
        })
        .collect();
    Some(format!(
        "the shards split different lists of input frames: {}. The inputs changed between \
         the shards' runs (a file set that grew, a dump still being written), so some \
         frames belong to no shard and others to two: rerun every shard over the same, \
         complete inputs (each converts only what it lacks), then merge",
        saw.join("; ")
    ))
}

/// How to run a batch.
#[derive(Clone, Debug, Default)]
pub struct BatchOptions {
    pub convert: ConvertOptions,
    pub read: ReadOptions,
    /// `(I, N)`: convert only shard I of N (0-based).
    pub shard: Option<(u32, u32)>,
    /// Memory all concurrent conversions may use together, in bytes.
    pub memory_limit: u64,
    /// Most concurrent conversions (default: the number of threads).
    pub max_jobs: Option<usize>,
    /// What to do with frames of one timestep (a run restarted into the same dump).
    pub duplicates: Duplicates,
    /// Through this, a handler of SIGTERM (a scheduler's time limit) or Ctrl-C writes
    /// the manifest of the frames completed so far before the program exits
    /// ([`ManifestHandle::save_now`]).
    pub handle: Option<ManifestHandle>,
    /// Least time between two rewrites of the manifest while frames are converted
    /// (default [`MANIFEST_INTERVAL`]).
    pub manifest_interval: Option<std::time::Duration>,
    /// A frame that cannot be converted for what it holds (a NaN, a line cut short in an
    /// older file, a bad box) is reported ([`BatchReport::failed`]) and the others are
    /// converted: `make -k`. Errors of the output (a full disk) still stop the batch.
    pub keep_going: bool,
    /// Index the inputs into [`INDEX_CACHE`] and convert nothing: run once before the
    /// shards of a job array, so that none of them scans the text dumps.
    pub index_only: bool,
}

/// The manifest of a running batch, for an interruption handler to write at once: the
/// batch rewrites it at most every [`MANIFEST_INTERVAL`], so frames of the last second
/// before an interruption would otherwise go unlisted until a rerun.
#[derive(Clone, Default)]
pub struct ManifestHandle(std::sync::Arc<ManifestSlot>);

/// Where the running batch keeps its manifest, the manifest's path, and how many frames
/// it listed as the batch began converting (those already done).
type ManifestSlot = Mutex<Option<(PathBuf, std::sync::Arc<Mutex<Manifest>>, usize)>>;

impl std::fmt::Debug for ManifestHandle {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("ManifestHandle")
    }
}

impl ManifestHandle {
    /// Writes the running batch's manifest as it is now (complete frames only); `false`
    /// when no batch is running with this handle.
    pub fn save_now(&self) -> Result<bool, BatchError> {
        let slot = self.0.lock().unwrap_or_else(|e| e.into_inner());
        let Some((path, manifest, _)) = slot.as_ref() else {
            return Ok(false);
        };
        let mut m = manifest.lock().unwrap_or_else(|e| e.into_inner());
        m.frames.sort_by_key(|f| f.timestep);
        write_json(path, &*m)?;
        Ok(true)
    }

    fn set(&self, value: Option<(PathBuf, std::sync::Arc<Mutex<Manifest>>, usize)>) {
        *self.0.lock().unwrap_or_else(|e| e.into_inner()) = value;
    }

    /// The running batch's counts as they are now: frames converted by this run, frames
    /// it found done, and frames still to convert (of those its manifest expects);
    /// `None` when no batch is running with this handle.
    pub fn counts(&self) -> Option<(usize, usize, u64)> {
        let slot = self.0.lock().unwrap_or_else(|e| e.into_inner());
        let (_, manifest, at_start) = slot.as_ref()?;
        let m = manifest.lock().unwrap_or_else(|e| e.into_inner());
        let listed = m.frames.len();
        let expected = m.expected_frames.unwrap_or(listed as u64);
        Some((
            listed.saturating_sub(*at_start),
            *at_start,
            expected.saturating_sub(listed as u64),
        ))
    }
}

/// What a batch does with frames that have the same timestep (in the order the inputs
/// and their frames are given).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Duplicates {
    /// Refuse the batch, naming two of them.
    #[default]
    Error,
    /// Convert the first and leave out the others.
    First,
    /// Convert the last (a restarted run's frames supersede the ones before the restart)
    /// and leave out the others.
    Last,
}

/// A frame without particles, which a batch leaves out: a `.mdlod` file needs at least
/// one particle.
#[derive(Clone, Debug, PartialEq)]
pub struct EmptyFrame {
    pub input: PathBuf,
    /// The frame's index in the input.
    pub frame: usize,
    /// The input's own timestep of the frame, where it records one.
    pub timestep: Option<u64>,
    /// The frame's number in the batch (its timestep, else its position in the inputs).
    pub number: u64,
}

impl std::fmt::Display for EmptyFrame {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}: frame {}", self.input.display(), self.frame)?;
        match self.timestep {
            Some(t) => write!(f, " (timestep {t})")?,
            None => write!(f, " (number {} in the batch)", self.number)?,
        }
        write!(
            f,
            " has no particles: skipped, as a .mdlod file needs at least one \
             (not written; listed as empty in the manifest)"
        )
    }
}

/// What a batch did.
#[derive(Clone, Debug, PartialEq)]
pub struct BatchReport {
    /// Frames of all inputs.
    pub frames_total: usize,
    /// Frames this shard is responsible for (empty ones included).
    pub frames_in_shard: usize,
    pub converted: usize,
    pub skipped: usize,
    /// This shard's frames without particles, left out (in timestep order).
    pub empty: Vec<EmptyFrame>,
    /// What the conversions of this run said the user should know, each once (see
    /// [`crate::convert::ConvertReport::notes`]).
    pub notes: Vec<String>,
    /// Concurrent conversions used.
    pub jobs: usize,
    pub manifest: PathBuf,
    /// The merged manifest a shard run removed, as the frames it converted outdate it.
    pub removed_merged: Option<PathBuf>,
    /// Shard manifests of an earlier sharded run that this whole run's `dataset.json`
    /// supersedes, removed: a later `--merge` of them would put the older frames back.
    pub removed_shard_manifests: Vec<String>,
    /// Files named like frames in the batch directory that no frame of the inputs (in
    /// any shard) is written to: left by a run over other or longer inputs.
    pub strays: Vec<String>,
    /// Timesteps of frames this run lists although no input holds them: converted by an
    /// earlier run from dumps that are gone since (deleted once converted), with this
    /// run's settings. (Not counted in `skipped`.)
    pub kept_gone: Vec<u64>,
    /// Frame files converted from dumps that are gone, which this run cannot list: built
    /// with other settings than this run's, or listed by no manifest (not in `strays`).
    pub gone_other: Vec<String>,
    /// Timesteps an earlier run listed whose frame files are gone as well as their
    /// dumps (deleted): no longer listed.
    pub vanished: Vec<u64>,
    /// The frames left out as duplicates of a timestep ([`BatchOptions::duplicates`]),
    /// each with the one converted instead.
    pub duplicates: Vec<String>,
    /// Frames whose outputs existed and were converted again.
    pub redone: Redone,
    /// Frames whose input changed since they were converted (a dump a simulation has
    /// appended frames to since, a file touched) but whose own bytes did not: kept
    /// (counted in `skipped` too).
    pub kept_unchanged: usize,
    /// Last frames of the newest input that are cut short (a run still writing them),
    /// and a newest input of a set that is empty: left out, not expected of this run,
    /// converted by a rerun once complete. (An older input cut short is an error,
    /// [`BatchError::CutShortBeforeNewest`].)
    pub incomplete: Vec<IncompleteFrame>,
    /// Frames that could not be converted for what they hold, with
    /// [`BatchOptions::keep_going`]: not in the manifest, not expected of this run, tried
    /// again by a rerun. (Without it, the first such frame is the batch's error.)
    pub failed: Vec<FailedFrame>,
    /// How the inputs' frames were listed.
    pub index: IndexUse,
}

/// How a batch listed its inputs' frames ([`INDEX_CACHE`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct IndexUse {
    /// The cache file.
    pub file: PathBuf,
    /// Text files whose frames the cache gave (unchanged since they were scanned; each
    /// piece of a `%` set counts).
    pub from_cache: usize,
    /// Text files scanned, line by line.
    pub scanned: usize,
    /// Of those, files not kept: modified moments ago (a run may still write them) or
    /// dated ahead of this machine's clock; the next run scans them again.
    pub unsettled: usize,
    /// Inputs whose frames no cache keeps: binary dumps, GSD, MMPLD and raw arrays (their
    /// frames come from their headers) and gzip files (decompressed by every run).
    pub not_kept: usize,
    /// Why the cache could not be written, where it could not (a read-only directory).
    pub unsaved: Option<String>,
}

/// `timestep T (frame K of INPUT)`, or `frame K of INPUT` without a timestep.
pub fn failed_place(f: &FailedEntry) -> String {
    match f.timestep {
        Some(t) => format!("timestep {t} (frame {} of {})", f.frame, f.input),
        None => format!("frame {} of {}", f.frame, f.input),
    }
}

/// A frame a batch with [`BatchOptions::keep_going`] could not convert.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FailedFrame {
    pub input: PathBuf,
    /// The frame's index in the input.
    pub frame: usize,
    /// The input's own timestep of the frame, where it records one.
    pub timestep: Option<u64>,
    /// The timestep the manifest would list it at (its own, or its position); `None`
    /// where its LAMMPS header could not be read as far as its timestep.
    pub listed_timestep: Option<u64>,
    /// The error, which names the file and the place.
    pub reason: String,
}

impl std::fmt::Display for FailedFrame {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}: frame {}", self.input.display(), self.frame)?;
        if let Some(t) = self.timestep {
            write!(f, " (timestep {t})")?;
        }
        write!(f, " not converted: {}", self.reason)
    }
}

/// Frames of a rerun whose outputs existed and were converted again, by why.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Redone {
    /// The source changed: a file replaced, a frame's bytes changed (an input whose
    /// frames are not byte ranges of their own, such as a gzip dump, changed in size or
    /// modification time).
    pub source: usize,
    /// The settings changed (a build option, a radius, the attribute, renames, the
    /// columns).
    pub settings: usize,
    /// No manifest records how the frame file was built (a run killed within a second
    /// of finishing it, before it was listed): converted again, as the file alone cannot
    /// say which renames, wrapping or columns it was read with.
    pub unrecorded: usize,
    /// Which settings differed, over those frames.
    pub changed: SettingsChanged,
}

/// Which of a rerun's settings differ from those a frame was converted with.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SettingsChanged {
    /// The build options, each: `--cluster-size`, `--root-points`, `--delta-n`,
    /// `--precision`, `--chunk-points`.
    pub cluster_size: bool,
    pub root_points: bool,
    pub delta_n: bool,
    pub precision: bool,
    pub chunk_points: bool,
    pub radius: bool,
    /// The first `--attribute` (or `--attribute-log10`).
    pub attribute: bool,
    /// The further `--attribute` columns.
    pub further_attributes: bool,
    pub species_name: bool,
    pub columns: bool,
    pub size_column: bool,
    pub species_column: bool,
    pub wrap: bool,
}

impl std::ops::BitOrAssign for SettingsChanged {
    fn bitor_assign(&mut self, o: Self) {
        self.cluster_size |= o.cluster_size;
        self.root_points |= o.root_points;
        self.delta_n |= o.delta_n;
        self.precision |= o.precision;
        self.chunk_points |= o.chunk_points;
        self.radius |= o.radius;
        self.attribute |= o.attribute;
        self.further_attributes |= o.further_attributes;
        self.species_name |= o.species_name;
        self.columns |= o.columns;
        self.size_column |= o.size_column;
        self.species_column |= o.species_column;
        self.wrap |= o.wrap;
    }
}

impl SettingsChanged {
    /// The options that differ, as the command line names them.
    pub fn names(&self) -> Vec<&'static str> {
        [
            (self.cluster_size, "--cluster-size"),
            (self.root_points, "--root-points"),
            (self.delta_n, "--delta-n"),
            (self.precision, "--precision"),
            (self.chunk_points, "--chunk-points"),
            (self.radius, "--radius"),
            (self.attribute, "--attribute"),
            (self.further_attributes, "the further --attribute columns"),
            (self.species_name, "--species-name"),
            (self.columns, "--columns"),
            (self.size_column, "the size column"),
            (self.species_column, "--species-column"),
            (self.wrap, "--wrap"),
        ]
        .into_iter()
        .filter_map(|(changed, name)| changed.then_some(name))
        .collect()
    }
}

/// The last frame of an input, cut short, which a batch leaves out (see
/// [`BatchReport::incomplete`]).
#[derive(Clone, Debug, PartialEq)]
pub struct IncompleteFrame {
    pub input: PathBuf,
    /// The frame's index in the input.
    pub frame: usize,
    /// The input's own timestep of the frame, where it records one.
    pub timestep: Option<u64>,
    /// What the reader said.
    pub reason: String,
    /// Whether the whole input is empty (the newest file of a set, just opened): no
    /// frame of it is known.
    pub empty_file: bool,
}

impl std::fmt::Display for IncompleteFrame {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.empty_file {
            return write!(
                f,
                "{}, the newest input, is empty (a run still writing it?): left out; a rerun \
                 converts its frames once written",
                self.input.display()
            );
        }
        write!(f, "{}: frame {}", self.input.display(), self.frame)?;
        if let Some(t) = self.timestep {
            write!(f, " (timestep {t})")?;
        }
        write!(
            f,
            ", the input's last, is cut short (a run still writing it?): left out; a rerun \
             converts it once complete ({})",
            self.reason
        )
    }
}

#[derive(Debug, thiserror::Error)]
pub enum BatchError {
    #[error(transparent)]
    Read(#[from] ReadError),
    #[error(transparent)]
    Convert(#[from] ConvertError),
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("timestep {timestep} appears twice: {first} and {second} ({why})")]
    DuplicateTimestep {
        timestep: u64,
        first: String,
        second: String,
        /// What may have caused it, and the way out.
        why: String,
    },
    #[error("the frames of two runs would interleave: {what}: a run restarted from an earlier timestep than its last frame's? --duplicate-timesteps last keeps {last_keeps}; first keeps every frame in timestep order")]
    Interleaved { what: String, last_keeps: String },
    #[error("{}: {message}", path.display())]
    Manifest { path: PathBuf, message: String },
    /// An input some of whose frames give a timestep and some none: numbered by their
    /// position, the frames without one would fall among the others out of order.
    #[error(
        "{}: {with} a timestep, but {without} none: a batch orders frames by \
         timestep and numbers those without one by their position, which would put them \
         out of order; give every frame of the input a timestep (`Timestep=` or `step=` \
         in an XYZ comment line), or none",
        path.display()
    )]
    MixedTimesteps {
        path: PathBuf,
        with: String,
        without: String,
    },
    /// An input cut short that is not the newest ([`newest_inputs`]): a run writes one
    /// file of a set at a time, so an older one is damaged (a copy that stopped), not
    /// being written, and leaving its frame out would lose it unnoticed.
    #[error(
        "{} is cut short, but it is not the newest input ({newest}), and \
         only the newest may be one a run is still writing: replace it with a complete copy, \
         or leave it out of the inputs; {reason}",
        input.display()
    )]
    CutShortBeforeNewest {
        input: PathBuf,
        /// The newest input.
        newest: String,
        /// What is cut short, as the reader said.
        reason: String,
    },
    /// A quoted file-name pattern that names no inputs.
    #[error("{}: {message}", pattern.display())]
    Pattern { pattern: PathBuf, message: String },
    #[error("shard {0}/{1}: the shard index must be below the shard count")]
    BadShard(u32, u32),
    /// Another process is running this batch (this shard of it) into the directory.
    #[error(
        "{}: another mdlod batch is writing this directory ({holder}), beside which this \
         run{shard} must not: wait for it to end, or stop it first (a resubmitted job?)",
        dir.display()
    )]
    Busy {
        dir: PathBuf,
        /// " (shard i of n)" or empty.
        shard: String,
        /// What the lock file says of its holder (`pid P on HOST`).
        holder: String,
    },
    /// Frames whose files were converted from another input, which is still where it
    /// was: the directory holds another run's frames (`-o` reused), or inputs numbered
    /// by their place were left out or added. Replacing them would lose them unnoticed.
    #[error(
        "{}: {frame}: the directory holds the frames of other inputs; convert into \
         another directory, or delete its frames (frame-*.mdlod and dataset.json) to \
         convert into it afresh{renumbered}",
        dir.display()
    )]
    OtherInputs {
        dir: PathBuf,
        /// The first such frame: `FILE holds timestep T of OLD, which is still there,
        /// and this run would replace it with frame K of INPUT` (and how many more).
        frame: String,
        /// A word on renumbering where the new frame is numbered by its place.
        renumbered: &'static str,
    },
    /// A frame failed (the first error); the frames converted before it, or beside it
    /// on other workers, are in the manifest (no new frame starts after a failure).
    #[error(
        "{source}\n  ({})",
        match (converted, manifest_unsaved) {
            (0, _) => format!("none of the {todo} frames to convert was converted"),
            (_, None) => format!(
                "{converted} of the {todo} frames to convert {} converted and {} listed in \
                 the manifest; once the cause is mended, a rerun converts only what is missing",
                if *converted == 1 { "was" } else { "were" },
                if *converted == 1 { "is" } else { "are" }
            ),
            (_, Some(why)) => format!(
                "{converted} of the {todo} frames to convert {} converted, but the manifest \
                 listing them could not be saved ({why}); once the cause is mended, a rerun \
                 keeps the frames the last manifest saved lists and converts the others \
                 again (a frame file alone does not record the settings it was read with)",
                if *converted == 1 { "was" } else { "were" }
            ),
        }
    )]
    Incomplete {
        converted: usize,
        todo: usize,
        /// Why the manifest could not be saved after the failure, if it could not.
        manifest_unsaved: Option<String>,
        #[source]
        source: Box<BatchError>,
    },
    /// Every frame was converted, but an option names a species no frame holds (a
    /// misspelt name): the frames converted are complete and listed in the manifest.
    #[error(
        "{source}; the frames converted ({converted}) and already done ({skipped}) are \
         complete and listed in the manifest: with the option mended, a rerun converts \
         again only the frames it changes"
    )]
    NamesUnused {
        converted: usize,
        skipped: usize,
        #[source]
        source: Box<BatchError>,
    },
    /// A radius override names a species no frame of the inputs can hold (they name
    /// their species another way): refused before any frame is converted.
    #[error(
        "{inputs}: --radius {name}={radius}: no species named {name:?} can occur there: {reason}"
    )]
    ImpossibleSpecies {
        /// The input (or inputs) named.
        inputs: String,
        name: String,
        radius: f32,
        /// How the inputs name species instead, and what to write.
        reason: String,
    },
    /// A rename names a species no frame of the inputs can hold: refused before any frame
    /// is converted (it would do nothing, or fail after every frame).
    #[error(
        "{inputs}: --species-name {old}={new}: no species named {old:?} can occur there: \
         {reason}"
    )]
    ImpossibleRename {
        inputs: String,
        old: String,
        new: String,
        reason: String,
    },
}

impl BatchError {
    /// Whether the error is an input cut short (see [`ReadError::cut_short`]).
    fn cut_short(&self) -> bool {
        fn convert(e: &ConvertError) -> bool {
            match e {
                ConvertError::Read(r) => r.cut_short(),
                ConvertError::LastFrameIncomplete { .. } => true,
                ConvertError::Decompressed { inner: source, .. }
                | ConvertError::GzipCut { source, .. } => convert(source),
                _ => false,
            }
        }
        match self {
            BatchError::Read(r) => r.cut_short(),
            BatchError::Convert(c) => convert(c),
            _ => false,
        }
    }

    /// Whether the error is the frame's own (what its input holds), which
    /// [`BatchOptions::keep_going`] passes over, rather than the output's or the run's
    /// (a full disk, the memory limit), which would stop every frame after it.
    fn frames_own(&self) -> bool {
        // (Reading or writing a file failing is no fault of the frame: a full disk
        // under a decompressed working copy fails every frame after it.)
        fn read(r: &ReadError) -> bool {
            !matches!(r, ReadError::Io { .. })
        }
        fn convert(e: &ConvertError) -> bool {
            match e {
                ConvertError::Read(r) => read(r),
                ConvertError::AttributeNotPositive { .. }
                | ConvertError::BadBox { .. }
                | ConvertError::NoAttributeToLog(_)
                | ConvertError::LastFrameIncomplete { .. }
                | ConvertError::Build { .. }
                | ConvertError::EmptyFrame(_)
                | ConvertError::LastFrameEmpty { .. }
                | ConvertError::Attributes { .. }
                | ConvertError::UnusableRadius(_) => true,
                ConvertError::Decompressed { inner: source, .. }
                | ConvertError::GzipCut { source, .. } => convert(source),
                _ => false,
            }
        }
        match self {
            BatchError::Read(r) => read(r),
            BatchError::CutShortBeforeNewest { .. } => true,
            BatchError::Convert(c) => convert(c),
            _ => false,
        }
    }
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> BatchError + '_ {
    move |source| BatchError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// Size and modification time of an input; for a `%` piece set, the total size and the
/// latest modification of its pieces; for a raw sidecar, of it and the arrays it names
/// (new arrays behind an unchanged sidecar are new data). `convert` records the same (it
/// recorded a piece set's size as 0, and a sidecar's alone).
pub fn fingerprint(input: &Path, frame: u64) -> SourceInfo {
    let files = match crate::readers::piece_paths(input) {
        Ok(p) if !input.exists() => p,
        _ => std::iter::once(input.to_path_buf())
            .chain(crate::readers::raw::data_files(input).into_iter().flatten())
            .collect(),
    };
    let mut size = 0u64;
    // The latest (seconds, nanoseconds) of the pieces.
    let mut modified: Option<(i64, Option<u32>)> = None;
    for f in &files {
        let s = crate::convert::source_info(f, frame);
        size = size.saturating_add(s.size);
        let this = s.modified_unix.map(|t| (t, s.modified_nanos));
        modified = modified.max(this);
    }
    SourceInfo {
        path: input.display().to_string(),
        size,
        modified_unix: modified.map(|m| m.0),
        modified_nanos: modified.and_then(|m| m.1),
        frame,
        bytes: None,
    }
}

/// Whether an output's recorded source is `now`'s: the same frame, size and
/// modification time, of a file of the same name. The path is recorded as it was typed,
/// relative to where that run started: the same input named from another directory (a
/// requeued cluster job) or by another path is the same file when its name, size and
/// modification time to the nanosecond agree. A file written before sources recorded
/// nanoseconds is compared to the second.
fn same_source(recorded: &SourceInfo, now: &SourceInfo) -> bool {
    let nanos = match recorded.modified_nanos {
        Some(_) => now.modified_nanos,
        None => None,
    };
    // Another path with the same name is the same file only where the time tells files
    // apart: not when it has no nanoseconds (file systems of whole seconds, files
    // unpacked from an archive), where two replicas' dumps share name, size and second.
    let fine_time = recorded.modified_nanos.is_some_and(|n| n != 0);
    let same_file = recorded.path == now.path || (fine_time && same_name(recorded, now));
    same_file
        && *recorded
            == SourceInfo {
                path: recorded.path.clone(),
                modified_nanos: nanos,
                bytes: recorded.bytes.clone(),
                ..now.clone()
            }
}

/// Whether two sources name files of the same name (the frame's bytes tell the rest).
fn same_name(recorded: &SourceInfo, now: &SourceInfo) -> bool {
    let name = |p: &str| Path::new(p).file_name().map(|n| n.to_os_string());
    name(&recorded.path).is_some() && name(&recorded.path) == name(&now.path)
}

/// The XXH3-64 of `range` of the file at `path`, read through a buffer (the pages read
/// do not stay mapped into the process), as [`FrameBytes::xxh3`] writes it.
pub fn range_checksum(
    path: &Path,
    range: std::ops::Range<u64>,
    progress: &dyn Progress,
) -> std::io::Result<String> {
    ranges_checksum(path, std::slice::from_ref(&range), progress)
}

/// The XXH3-64 of `ranges` of the file at `path`, one after another.
pub fn ranges_checksum(
    path: &Path,
    ranges: &[std::ops::Range<u64>],
    progress: &dyn Progress,
) -> std::io::Result<String> {
    let files: Vec<(PathBuf, std::ops::Range<u64>)> = ranges
        .iter()
        .map(|r| (path.to_path_buf(), r.clone()))
        .collect();
    files_checksum(&files, progress)
}

/// The XXH3-64 of byte ranges of files, one after another (a GSD frame's chunks, a `%`
/// piece set's pieces' frames: [`DumpFile::frame_ranges`]); a file named twice in a row
/// is opened once.
pub fn files_checksum(
    ranges: &[(PathBuf, std::ops::Range<u64>)],
    progress: &dyn Progress,
) -> std::io::Result<String> {
    let mut open: Option<(&Path, std::fs::File)> = None;
    let mut hasher = xxhash_rust::xxh3::Xxh3::new();
    let mut buffer = vec![0u8; 1 << 20];
    for (path, range) in ranges {
        let file = match open.take() {
            Some((p, f)) if p == path.as_path() => (p, f),
            _ => (path.as_path(), std::fs::File::open(path)?),
        };
        let (p, mut f) = file;
        hash_range(&mut f, range.clone(), &mut hasher, &mut buffer, progress)?;
        open = Some((p, f));
    }
    Ok(format!("{:016x}", hasher.digest()))
}

/// Feeds `range` of `file` to `hasher` through `buffer`.
fn hash_range(
    file: &mut std::fs::File,
    range: std::ops::Range<u64>,
    hasher: &mut xxhash_rust::xxh3::Xxh3,
    buffer: &mut [u8],
    progress: &dyn Progress,
) -> std::io::Result<()> {
    use std::io::{Read, Seek};
    file.seek(std::io::SeekFrom::Start(range.start))?;
    let mut at = range.start;
    while at < range.end {
        let want = usize::try_from(range.end - at).map_or(buffer.len(), |n| n.min(buffer.len()));
        let n = match file.read(&mut buffer[..want]) {
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            r => r?,
        };
        if n == 0 {
            return Err(std::io::Error::new(
                std::io::ErrorKind::UnexpectedEof,
                format!(
                    "ends at byte {at}, before the frame's end at byte {}",
                    range.end
                ),
            ));
        }
        hasher.update(&buffer[..n]);
        at += n as u64;
        progress.advance(n as u64);
    }
    Ok(())
}

/// The checksum [`FrameBytes::xxh3`] records of frame `frame` of `input` (whose bytes
/// span `range`): of the range, or of a GSD frame's chunks or a `%` piece set's pieces'
/// frames ([`DumpFile::frame_ranges`]).
fn frame_checksum(
    input: &Path,
    dump: Option<&DumpFile>,
    frame: usize,
    range: std::ops::Range<u64>,
    progress: &dyn Progress,
) -> std::io::Result<String> {
    match dump.and_then(|d| d.frame_ranges(frame)) {
        Some(ranges) => files_checksum(&ranges, progress),
        None => range_checksum(input, range, progress),
    }
}

/// A frame's byte range and checksum in its input, for inputs whose frames are
/// contiguous byte ranges ([`DumpFile::frame_bytes`]); `None` for others.
fn frame_bytes(
    input: &Path,
    dump: Option<&DumpFile>,
    frame: usize,
) -> Result<Option<FrameBytes>, BatchError> {
    let Some(range) = dump.and_then(|d| d.frame_bytes(frame)) else {
        return Ok(None);
    };
    let xxh3 = frame_checksum(
        input,
        dump,
        frame,
        range.clone(),
        &crate::progress::NoProgress,
    )
    .map_err(io(input))?;
    Ok(Some(FrameBytes {
        start: range.start,
        end: range.end,
        xxh3,
    }))
}

/// The lock file of a batch directory's run (of one shard of it), hidden: two runs of
/// one shard into one directory (a job resubmitted while the first still runs) would
/// each take the other's temporary frames for a dead run's and remove them.
pub fn lock_file_name(shard: Option<(u32, u32)>) -> String {
    match shard {
        Some((i, n)) => format!(".batch.shard-{i}-of-{n}.lock"),
        None => ".batch.lock".into(),
    }
}

/// Takes the batch directory's locks for this run (advisory `flock`s, which the system
/// lets go when the process ends however it ends): a whole run holds `.batch.lock`
/// alone; a shard holds it shared with the other shards, and its own shard's lock
/// alone, so that a whole run and a shard, or two runs of one shard, never write the
/// directory together. A file system without locks runs unlocked. The files are left
/// in place (removing one would let a third run lock a new file while a second still
/// holds the old one).
fn lock_batch(out_dir: &Path, shard: Option<(u32, u32)>) -> Result<Vec<std::fs::File>, BatchError> {
    let mut held = Vec::new();
    let whole = lock_file(out_dir, &lock_file_name(None), shard.is_some(), shard)?;
    held.extend(whole);
    if shard.is_some() {
        held.extend(lock_file(out_dir, &lock_file_name(shard), false, shard)?);
    }
    Ok(held)
}

/// Who is running a batch, whole or a shard of it, into `out_dir` now (what its lock
/// says: `pid P on HOST`; shards hold it together and say nothing), where one is; `None`
/// where none is or the locks cannot tell. For a render that would read the directory
/// while a batch rewrites it.
pub fn batch_running(out_dir: &Path) -> Option<String> {
    use std::io::Read;
    let mut file = std::fs::File::open(out_dir.join(lock_file_name(None))).ok()?;
    match file.try_lock() {
        Err(std::fs::TryLockError::WouldBlock) => {
            let mut holder = String::new();
            let _ = file.read_to_string(&mut holder);
            Some(match holder.trim() {
                "" => "shards of a batch".to_string(),
                h => h.to_string(),
            })
        }
        _ => None,
    }
}

/// One lock of [`lock_batch`]: `shared` or alone; `Busy` naming the holder when
/// another process holds it so that this one cannot.
fn lock_file(
    out_dir: &Path,
    name: &str,
    shared: bool,
    shard: Option<(u32, u32)>,
) -> Result<Option<std::fs::File>, BatchError> {
    use std::io::{Read, Seek, Write};
    let path = out_dir.join(name);
    let mut file = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .create(true)
        .truncate(false)
        .open(&path)
        .map_err(io(&path))?;
    let locked = match shared {
        true => file.try_lock_shared(),
        false => file.try_lock(),
    };
    match locked {
        Ok(()) => {}
        Err(std::fs::TryLockError::WouldBlock) => {
            let mut holder = String::new();
            let _ = file.read_to_string(&mut holder);
            let holder = holder.trim();
            return Err(BatchError::Busy {
                dir: out_dir.to_path_buf(),
                shard: shard.map_or(String::new(), |(i, n)| format!(" (shard {i} of {n})")),
                holder: match holder.is_empty() {
                    // (Shards hold the whole run's lock together, and empty it.)
                    true if shard.is_none() => "shards of it, which `mdlod verify DIR` \
                                                 lists"
                        .into(),
                    true => "it has not said which".into(),
                    false => holder.to_string(),
                },
            });
        }
        // No locks here (some network file systems): as before locks.
        Err(std::fs::TryLockError::Error(_)) => return Ok(None),
    }
    // The holder of a lock alone says who it is; shared holders (several) leave it
    // empty, so that a whole run they keep out does not name an earlier one.
    let holder = match shared {
        false => format!(
            "pid {} on {}",
            std::process::id(),
            mdlod_format::writer::host_name()
        ),
        true => String::new(),
    };
    let written = file
        .set_len(0)
        .and_then(|()| file.rewind())
        .and_then(|()| file.write_all(holder.as_bytes()));
    written.map_err(io(&path))?;
    Ok(Some(file))
}

/// The `%` piece set two files' names say they belong to: the same directory and name
/// but for one number (`dump.0.bin`, `dump.1.bin`: `dump.%.bin`); `None` otherwise.
fn piece_pattern(a: &Path, b: &Path) -> Option<PathBuf> {
    if a.parent() != b.parent() {
        return None;
    }
    let (na, nb) = (a.file_name()?.to_str()?, b.file_name()?.to_str()?);
    // Shared characters (not bytes: names of other scripts share leading bytes).
    let prefix: usize = na
        .chars()
        .zip(nb.chars())
        .take_while(|(x, y)| x == y)
        .map(|(x, _)| x.len_utf8())
        .sum();
    let suffix: usize = na[prefix..]
        .chars()
        .rev()
        .zip(nb[prefix..].chars().rev())
        .take_while(|(x, y)| x == y)
        .map(|(x, _)| x.len_utf8())
        .sum();
    // Digits shared at the edges belong to the number (`dump.10.bin` and `dump.11.bin`,
    // `dump.0.bin` and `dump.10.bin`).
    let prefix = na[..prefix]
        .trim_end_matches(|c: char| c.is_ascii_digit())
        .len();
    let suffix = na[na.len() - suffix..]
        .trim_start_matches(|c: char| c.is_ascii_digit())
        .len();
    let digits = |n: &str| {
        let middle = &n[prefix..n.len() - suffix];
        !middle.is_empty() && middle.bytes().all(|c| c.is_ascii_digit())
    };
    if !(digits(na) && digits(nb)) {
        return None;
    }
    let name = format!("{}%{}", &na[..prefix], &na[na.len() - suffix..]);
    Some(a.with_file_name(name))
}

/// A `%` set's name with its other runs of digits written `*` (`dump.0.%.bin`:
/// `dump.*.%.bin`), where other inputs are pieces of other sets of that pattern (a
/// file per timestep, each in pieces); `None` where `set` is the only one.
fn every_timesteps_set(set: &Path, inputs: &[&Path]) -> Option<PathBuf> {
    let name = set.file_name()?.to_str()?;
    let (before, after) = name.split_once('%')?;
    let star = |part: &str| {
        let mut out = String::new();
        let mut digits = false;
        for c in part.chars() {
            if c.is_ascii_digit() {
                if !digits {
                    out.push('*');
                }
                digits = true;
            } else {
                out.push(c);
                digits = false;
            }
        }
        out
    };
    let pattern = format!("{}%{}", star(before), star(after));
    if pattern == name {
        return None;
    }
    let other = inputs.iter().any(|p| {
        p.parent() == set.parent()
            && p.file_name()
                .and_then(|n| n.to_str())
                .and_then(|n| piece_set_of(&pattern, n))
                .is_some_and(|s| s != name)
    });
    other.then(|| set.with_file_name(pattern))
}

/// The output file name of a timestep.
pub fn frame_file_name(timestep: u64) -> String {
    format!("frame-{timestep}.mdlod")
}

/// The timestep whose frame file `name` is ([`frame_file_name`] exactly: `frame-07.mdlod`
/// is none).
pub fn frame_file_number(name: &str) -> Option<u64> {
    let number: u64 = name
        .strip_prefix("frame-")?
        .strip_suffix(".mdlod")?
        .parse()
        .ok()?;
    (frame_file_name(number) == name).then_some(number)
}

fn manifest_name(shard: Option<(u32, u32)>) -> String {
    match shard {
        None => MANIFEST.to_string(),
        Some((i, n)) => format!("dataset.shard-{i}-of-{n}.json"),
    }
}

/// Whether a file name is a shard's manifest ([`manifest_name`] of a shard).
pub fn is_shard_manifest(name: &str) -> bool {
    name.starts_with("dataset.shard-") && name.ends_with(".json")
}

/// Where a run keeps the records of frame files its manifest does not list (frames it
/// is about to convert again, frame files of other inputs), so that a rerun still knows
/// how they were built if this run stops before it replaces them: hidden, one per
/// manifest (`.dataset.records.json`, `.dataset.shard-I-of-N.records.json`).
fn side_records_name(shard: Option<(u32, u32)>) -> String {
    format!(
        ".{}",
        manifest_name(shard).replace(".json", ".records.json")
    )
}

/// Writes the records of `known` that `manifest` (about to replace this run's manifest)
/// does not list, of frame files in `out_dir` as they are now (file name and checksum),
/// nor any other manifest in `out_dir` does (another shard's), to [`side_records_name`]:
/// a frame about to be converted again keeps its record until it is, and a frame file of
/// inputs this run was not given keeps its record for a run over them. Without them a
/// rerun converts such frames again ([`Redone::unrecorded`]).
fn keep_side_records(
    out_dir: &Path,
    shard: Option<(u32, u32)>,
    known: &RecordMap,
    manifest: &Manifest,
) -> Result<(), BatchError> {
    let mut listed: std::collections::HashSet<(String, String)> = manifest
        .frames
        .iter()
        .chain(&manifest.gone)
        .chain(&manifest.unlisted)
        .map(|f| (f.file.clone(), f.checksum.clone()))
        .collect();
    // Records the other manifests keep (the other shards' frames) are theirs to keep.
    let own = manifest_name(shard);
    for (name, m) in manifests_in(out_dir) {
        if name == own {
            continue;
        }
        listed.extend(
            m.frames
                .into_iter()
                .chain(m.gone)
                .chain(m.unlisted)
                .map(|f| (f.file, f.checksum)),
        );
    }
    let mut keep: Vec<&FrameEntry> = known
        .values()
        .filter(|f| !listed.contains(&(f.file.clone(), f.checksum.clone())))
        .filter(|f| frame_file_number(&f.file).is_some())
        .filter(|f| {
            MdlodFile::open_sparse(out_dir.join(&f.file))
                .is_ok_and(|m| format!("{:016x}", m.header().section_table_checksum) == f.checksum)
        })
        .collect();
    keep.sort_by(|a, b| (a.timestep, &a.checksum).cmp(&(b.timestep, &b.checksum)));
    let path = out_dir.join(side_records_name(shard));
    if keep.is_empty() {
        return match std::fs::remove_file(&path) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(io(&path)(e)),
            _ => Ok(()),
        };
    }
    write_json(&path, &keep)
}

/// Whether `name` is a file of [`side_records_name`].
fn is_side_records(name: &str) -> bool {
    name.starts_with(".dataset") && name.ends_with(".records.json")
}

/// The shard counts of the shard manifests in `out_dir` other than `n`, in order: the
/// shardings a run of `n` shards would not merge with (a failed task resubmitted alone
/// runs as shard 0 of 1 beside its array's).
pub fn other_shardings(out_dir: &Path, n: u32) -> Vec<u32> {
    let mut counts: Vec<u32> = std::fs::read_dir(out_dir)
        .into_iter()
        .flatten()
        .flatten()
        .filter_map(|e| shard_of(e.file_name().to_str()?))
        .map(|(_, m)| m)
        .filter(|&m| m != n)
        .collect();
    counts.sort_unstable();
    counts.dedup();
    counts
}

/// `(I, N)` of a shard manifest's name (`dataset.shard-I-of-N.json`).
fn shard_of(name: &str) -> Option<(u32, u32)> {
    let rest = name.strip_prefix("dataset.shard-")?.strip_suffix(".json")?;
    let (i, n) = rest.split_once("-of-")?;
    Some((i.parse().ok()?, n.parse().ok()?))
}

/// Writes `value` as JSON to `path` atomically (temporary file + rename).
fn write_json<T: Serialize>(path: &Path, value: &T) -> Result<(), BatchError> {
    // Serialized in memory and written at once: the writer's many small writes would
    // each be a system call on the unbuffered file.
    let mut text = serde_json::to_vec_pretty(value).map_err(|e| BatchError::Io {
        path: path.to_path_buf(),
        source: e.into(),
    })?;
    text.push(b'\n');
    write_bytes(path, &text)
}

/// Writes `text` to `path` atomically (temporary file + rename), readable by all as the
/// manifests are.
fn write_bytes(path: &Path, text: &[u8]) -> Result<(), BatchError> {
    let dir = path.parent().unwrap_or(Path::new("."));
    // The same bytes already there (a rerun with nothing to do) are left as they are: a
    // directory of finished frames that is read-only (an archive) checks as current.
    if std::fs::read(path).is_ok_and(|old| old == text) {
        return Ok(());
    }
    mdlod_format::files::check_replaceable(path).map_err(io(path))?;
    // `.dataset.HOST-PID-XXXXXX.tmp`: an interrupted run removes its own, a later run
    // those of processes that are gone.
    let mut tmp = mdlod_format::writer::output_file_builder()
        .prefix(&mdlod_format::writer::temp_prefix("dataset"))
        .suffix(".tmp")
        .tempfile_in(dir)
        .map_err(|e| io(dir)(mdlod_format::files::temp_error(e)))?;
    use std::io::Write;
    tmp.write_all(text).map_err(io(path))?;
    tmp.as_file().sync_all().map_err(io(path))?;
    mdlod_format::files::keep_permissions(path, tmp.as_file()).map_err(io(path))?;
    tmp.persist(path).map_err(|e| BatchError::Io {
        path: path.to_path_buf(),
        source: e.error,
    })?;
    Ok(())
}

/// The manifest entry of a complete output file of `timestep` (the input's own, or the
/// frame's position in the whole list for an input without timesteps), read with
/// `columns` given.
fn entry_of(
    input: &Path,
    path: &Path,
    file: &MdlodFile,
    timestep: u64,
    columns: Option<Vec<String>>,
    options: &ConvertOptions,
    read: &crate::readers::ReadOptions,
) -> FrameEntry {
    let overrides = &options.radii;
    let m = file.metadata();
    let radii = m
        .species
        .iter()
        .filter_map(|s| {
            crate::species::radius_override(overrides, &s.name).map(|r| (s.name.clone(), r))
        })
        .collect();
    FrameEntry {
        timestep,
        time: m.time,
        particles: m.particles,
        simulation_box: m.simulation_box.clone(),
        file: path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default(),
        checksum: format!("{:016x}", file.header().section_table_checksum),
        source: m.source.clone().unwrap_or(SourceInfo {
            path: String::new(),
            size: 0,
            modified_unix: None,
            modified_nanos: None,
            frame: 0,
            bytes: None,
        }),
        columns,
        radii: Some(radii),
        species_names: (!options.species_names.is_empty()).then(|| options.species_names.clone()),
        sizes: read.sizes.record(),
        species_column: read.species_column.clone(),
        wrap: read.wrap,
        source_abs: Some(absolute_source(input).display().to_string()),
    }
}

/// Frames named by their indices, with the verb "give": `frame 3 gives`, `frames 0 and 3
/// give`, `frames 0, 1, 2, 5 and 7 more give`.
fn frames_text(frames: &[usize]) -> String {
    const NAMED: usize = 4;
    let named: Vec<String> = frames.iter().take(NAMED).map(|k| k.to_string()).collect();
    match frames.len() {
        1 => format!("frame {} gives", named[0]),
        n if n <= NAMED => format!(
            "frames {} and {} give",
            named[..n - 1].join(", "),
            named[n - 1]
        ),
        n => format!("frames {} and {} more give", named.join(", "), n - NAMED),
    }
}

/// `input` with its directory resolved ([`FrameEntry::source_abs`]).
fn absolute_source(input: &Path) -> PathBuf {
    let (dir, name) = input_key(input);
    dir.join(name)
}

/// Whether `file` was built with the settings a conversion with `options` would use: the
/// hierarchy parameters, the chunk size where the frame is above it (the file records it
/// then, and a chunked build differs from a whole one), `attribute` (the name the reader
/// gives the attribute asked for now; `None`: none) and every species' radius: the one
/// `options` give it, else the one the input gives (`given`, asked only when needed:
/// the radii the frame's file gives by species, `None` when they cannot be read), else
/// its element's or the default. (A radius given by an earlier run and left out now
/// must not survive: the species takes the input's own again.) Where the manifest
/// recorded the overrides the file was built with (`recorded_radii`), those are compared
/// with `options`' instead, and the input is not read.
fn same_build(
    file: &MdlodFile,
    options: &ConvertOptions,
    attribute: Option<&str>,
    recorded_radii: Option<&[(String, f32)]>,
    given: impl FnOnce() -> Option<Vec<(String, f32)>>,
) -> bool {
    build_difference(file, options, attribute, recorded_radii, given).is_none()
}

/// What [`same_build`] found different: `None` where nothing is.
fn build_difference(
    file: &MdlodFile,
    options: &ConvertOptions,
    attribute: Option<&str>,
    recorded_radii: Option<&[(String, f32)]>,
    given: impl FnOnce() -> Option<Vec<(String, f32)>>,
) -> Option<SettingsChanged> {
    let (m, b) = (file.metadata(), &options.build);
    let chunk = options.chunks.chunk_points as u64;
    let chunked = (m.particles > chunk).then_some(chunk);
    // The file records the δn in effect: at most its levels below the top.
    let last = u32::try_from(file.level_count().saturating_sub(1)).unwrap_or(u32::MAX);
    let changed = SettingsChanged {
        cluster_size: m.build.max_cluster_size != b.max_cluster_size,
        root_points: m.build.max_root_points != b.max_root_points,
        delta_n: m.build.delta_n != b.delta_n.min(last),
        precision: m.build.position_bits != b.position_bits,
        chunk_points: m.build.chunk_points != chunked,
        // (A logarithm written before its clusters kept the logarithm of their mean
        // value, `attribute_log10` unset, is converted again: splats refuse it.)
        attribute: m.attribute.as_ref().map(|a| a.name.clone())
            != attribute.map(|a| crate::convert::attribute_name(a, options))
            || (options.attribute_log10 && m.attribute.is_some() && !m.attribute_log10),
        radius: !same_radii(file, options, recorded_radii, given),
        ..Default::default()
    };
    (changed != SettingsChanged::default()).then_some(changed)
}

/// Whether `file`'s species have the radii `options` give them now ([`same_build`]).
fn same_radii(
    file: &MdlodFile,
    options: &ConvertOptions,
    recorded_radii: Option<&[(String, f32)]>,
    given: impl FnOnce() -> Option<Vec<(String, f32)>>,
) -> bool {
    let m = file.metadata();
    // (An override naming none of the frame's species changes nothing in it: a species
    // may appear in some frames of a trajectory only.)
    if let Some(recorded) = recorded_radii {
        // The manifest says which overrides the file was built with: the others' radii
        // came from the input, which is unchanged (its source was compared). The input
        // is read again (a GSD frame's every diameter) only for a species whose override
        // was left out, to learn its own radius.
        let mut needs_input = false;
        let same = m.species.iter().all(|s| {
            let now = crate::species::radius_override(&options.radii, &s.name);
            match (now, crate::species::radius_override(recorded, &s.name)) {
                (n, r) if n == r => true,
                (Some(n), _) => n == s.radius,
                (None, _) => {
                    needs_input = true;
                    true
                }
            }
        });
        if !same || !needs_input {
            return same;
        }
    }
    let mut given = Some(given);
    let mut from_input: Option<Option<Vec<(String, f32)>>> = None;
    let labels = crate::species::letters_are_labels(m.species.iter().map(|s| s.name.as_str()));
    m.species.iter().all(|s| {
        let want = match crate::species::radius_override(&options.radii, &s.name) {
            Some(r) => r,
            None => {
                let Some(radii) = from_input.get_or_insert_with(|| given.take().and_then(|f| f()))
                else {
                    return false;
                };
                // (The input names species as it did before any renames.)
                let own = radii
                    .iter()
                    .find(|(n, _)| crate::species::renamed(&options.species_names, n) == s.name)
                    .map(|(_, r)| *r);
                if own.is_some_and(|r| !(r.is_finite() && r > 0.0)) {
                    // A conversion now refuses it: converted again, to say so.
                    return false;
                }
                crate::species::radius_without_override(&s.name, own, labels)
            }
        };
        want == s.radius
    })
}

/// What the planning decided about an existing output.
enum Verdict {
    /// Complete and current: kept, listed with the manifest's record of its source when
    /// that is newer than the file's own (see [`FrameBytes`]).
    Keep(MdlodFile, Option<SourceInfo>),
    /// Built with the same settings from an input that changed since: kept when the
    /// frame's bytes are unchanged; with the other input it was converted from, where
    /// that is still there ([`other_input`]), refused if they differ.
    CheckBytes(MdlodFile, FrameBytes, Option<PathBuf>),
    Redo,
    /// Converted from another input, which is still there ([`other_input`]): refused.
    Other(PathBuf),
}

/// The input a frame file was converted from (`recorded`, as a manifest records it),
/// where that is another file than `input` (frame `own` of it, `now` its source now)
/// and still there: a frame of another run, or of an input numbered by its place that
/// now numbers another. Not so: a source that is gone (dumps moved, or deleted once
/// converted), whose frames are converted again from the input given now; one of this
/// run's own inputs (`run_inputs`) when the frame has a timestep of its own (a restart
/// whose duplicate timesteps `--duplicate-timesteps last` takes from the later file);
/// and a copy of an input whose frames' bytes are not recorded (a gzip dump: the same
/// name and size, copied to scratch without its times; a copy of another input is
/// told by its frames' bytes, which are the same).
fn other_input(
    recorded: &Recorded,
    input: &Path,
    own: Option<u64>,
    now: &SourceInfo,
    run_inputs: &std::collections::HashSet<(PathBuf, std::ffi::OsString)>,
) -> Option<PathBuf> {
    let old = PathBuf::from(recorded.source_abs.as_deref()?);
    if old == absolute_source(input)
        || (own.is_some() && run_inputs.contains(&input_key(&old)))
        || (recorded.source.bytes.is_none()
            && recorded.source.size == now.size
            && same_name(&recorded.source, now))
    {
        return None;
    }
    let present = if old.to_string_lossy().contains('%') {
        crate::readers::piece_paths(&old).is_ok_and(|p| !p.is_empty())
    } else {
        // (The same file by another name, a link, is the same input.)
        match (std::fs::canonicalize(&old), std::fs::canonicalize(input)) {
            (Ok(a), Ok(b)) => a != b && !same_inode(&a, &b),
            (Ok(_), Err(_)) => true,
            (Err(_), _) => false,
        }
    };
    present.then_some(old)
}

/// Whether `a` and `b` are one file under two names (hard links).
fn same_inode(a: &Path, b: &Path) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        match (std::fs::metadata(a), std::fs::metadata(b)) {
            (Ok(x), Ok(y)) => x.dev() == y.dev() && x.ino() == y.ino(),
            _ => false,
        }
    }
    #[cfg(not(unix))]
    {
        let _ = (a, b);
        false
    }
}

/// What a listed frame was converted with that its file does not record.
struct Recorded {
    /// The source as the manifest lists it.
    source: SourceInfo,
    /// Its absolute path, where the manifest records it ([`FrameEntry::source_abs`]).
    source_abs: Option<String>,
    columns: Option<Vec<String>>,
    radii: Option<Vec<(String, f32)>>,
    species_names: Option<Vec<(String, String)>>,
    sizes: Option<String>,
    species_column: Option<String>,
    wrap: bool,
}

/// Records of frame files by file name and checksum.
type RecordMap = std::collections::HashMap<(String, String), FrameEntry>;

/// Every record of a frame file in `out_dir`, by file name and checksum, read once a run:
/// `listed`, those of the manifests (whole, shards', of this run's earlier attempts or of
/// other shardings, and the merged one a shard moved aside; listed, kept by a shard or
/// kept unlisted), and `side`, those of the side records ([`side_records_name`]).
/// Unreadable files are passed over.
struct Records {
    listed: RecordMap,
    side: RecordMap,
}

impl Records {
    fn read(out_dir: &Path) -> Records {
        let mut r = Records {
            listed: RecordMap::new(),
            side: RecordMap::new(),
        };
        let Ok(dir) = std::fs::read_dir(out_dir) else {
            return r;
        };
        for e in dir.flatten() {
            let name = e.file_name().to_string_lossy().into_owned();
            if is_side_records(&name) {
                let records = read_manifest_bytes(&e.path())
                    .ok()
                    .and_then(|t| serde_json::from_slice::<Vec<FrameEntry>>(&t).ok());
                for f in records.into_iter().flatten() {
                    r.side.insert((f.file.clone(), f.checksum.clone()), f);
                }
            } else if let Some(m) = manifest_of(out_dir, &name) {
                for f in m.frames.into_iter().chain(m.gone).chain(m.unlisted) {
                    r.listed.insert((f.file.clone(), f.checksum.clone()), f);
                }
            }
        }
        r
    }

    /// Every record, a manifest's before a side record of the same file.
    fn all(&self) -> RecordMap {
        let mut all = self.side.clone();
        all.extend(self.listed.iter().map(|(k, f)| (k.clone(), f.clone())));
        all
    }
}

/// The manifests of `out_dir` (whole, shards', and the merged one a shard moved aside),
/// by file name; unreadable ones are passed over.
fn manifests_in(out_dir: &Path) -> Vec<(String, Manifest)> {
    let Ok(dir) = std::fs::read_dir(out_dir) else {
        return Vec::new();
    };
    dir.flatten()
        .filter_map(|e| {
            let name = e.file_name().to_string_lossy().into_owned();
            let m = manifest_of(out_dir, &name)?;
            Some((name, m))
        })
        .collect()
}

/// The manifest `name` in `out_dir`, where it is one ([`manifests_in`]) and reads.
fn manifest_of(out_dir: &Path, name: &str) -> Option<Manifest> {
    if !(name == MANIFEST || name == PREVIOUS_MANIFEST || is_shard_manifest(name)) {
        return None;
    }
    let path = out_dir.join(name);
    read_manifest_bytes(&path)
        .ok()
        .and_then(|t| parse_manifest(&path, &t, "dataset").ok())
}

/// The column names and radius overrides each recorded frame was converted with
/// ([`Records`]), by file name and checksum.
fn recorded_entries(frames: &RecordMap) -> std::collections::HashMap<(String, String), Recorded> {
    frames
        .iter()
        .map(|(key, f)| {
            let f = f.clone();
            let r = Recorded {
                source: f.source,
                source_abs: f.source_abs,
                columns: f.columns,
                radii: f.radii,
                species_names: f.species_names,
                sizes: f.sizes,
                species_column: f.species_column,
                wrap: f.wrap,
            };
            (key.clone(), r)
        })
        .collect()
}

/// What became of the recorded source of a frame no input of this run holds
/// ([`source_gone`]).
#[derive(Clone, Debug, PartialEq, Eq)]
enum Source {
    /// Still there, and no input of this run: another trajectory's dump.
    There,
    /// No file at its path.
    Missing,
    /// A file there that is one of this run's inputs (this key), which holds other
    /// frames now: a restart writing into the same file name, or a dump written again.
    Rewritten((PathBuf, std::ffi::OsString)),
}

/// What became of a recorded source of a frame no input of this run holds: no file at
/// its path (as the run that converted it was given it, from wherever it started: a
/// relative path is also looked for beside this run's inputs), nor, for a `%` set, any
/// piece; or a file there that is one of this run's inputs, which holds other frames now
/// (a restart writing into the same file name). An empty path (a file recording none) is
/// not taken for gone.
fn source_gone(
    source: &SourceInfo,
    absolute: Option<&str>,
    inputs: &[(PathBuf, std::ffi::OsString)],
) -> Source {
    if source.path.is_empty() {
        return Source::There;
    }
    let of = |p: &Path| {
        let key = input_key(p);
        if inputs.contains(&key) {
            Source::Rewritten(key)
        } else {
            Source::There
        }
    };
    let present = |path: &Path| {
        path.exists()
            || (source.path.contains('%')
                && crate::readers::piece_paths(path).is_ok_and(|p| !p.is_empty()))
    };
    let path = Path::new(&source.path);
    // The path as resolved when the frame was converted tells, where recorded.
    if let Some(abs) = absolute {
        let abs = Path::new(abs);
        return if present(abs) {
            of(abs)
        } else {
            Source::Missing
        };
    }
    let found = if present(path) {
        Some(path.to_path_buf())
    } else if path.is_relative() {
        path.file_name().and_then(|name| {
            inputs
                .iter()
                .map(|(dir, _)| dir.join(name))
                .find(|p| present(p))
        })
    } else {
        None
    };
    match found {
        None => Source::Missing,
        Some(p) => of(&p),
    }
}

/// An input as [`source_gone`] compares it: its directory, resolved, and its name (a `%`
/// set's pattern names no file to resolve).
fn input_key(path: &Path) -> (PathBuf, std::ffi::OsString) {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    (
        std::fs::canonicalize(dir).unwrap_or_else(|_| dir.to_path_buf()),
        path.file_name()
            .map(|n| n.to_os_string())
            .unwrap_or_default(),
    )
}

/// The frame files among `strays` (frame files no frame of this run's inputs is written
/// to) whose dumps are gone ([`source_gone`]), by what a rerun does with them: those a
/// manifest of `out_dir` lists with the file's checksum and with the settings of this run
/// (`attribute`: the attribute's name as this run's frames give it), listed again, and
/// the others (built with other settings, or listed by no manifest), named. Users delete
/// dumps once converted ("convert once") and add new ones: the frames of the deleted
/// dumps are still the data set's.
#[allow(clippy::too_many_arguments)]
fn gone_source_frames(
    out_dir: &Path,
    listed: &RecordMap,
    strays: &[String],
    inputs: &[PathBuf],
    numbers: &std::collections::HashSet<u64>,
    first_timesteps: &std::collections::HashMap<(PathBuf, std::ffi::OsString), u64>,
    superseded: &std::collections::HashSet<u64>,
    opts: &BatchOptions,
    attribute: Option<&str>,
) -> GoneFrames {
    let inputs: Vec<(PathBuf, std::ffi::OsString)> = inputs.iter().map(|p| input_key(p)).collect();
    // Frames this run's own manifest lists whose files are gone too, of no frame of this
    // run: said by the run that stops listing them, once (not from the merged manifest,
    // which every shard reads, nor the records a shard moved aside).
    let own = out_dir.join(manifest_name(opts.shard));
    let mut vanished: Vec<u64> = read_manifest_bytes(&own)
        .ok()
        .and_then(|text| parse_manifest(&own, &text, "dataset").ok())
        .into_iter()
        .flat_map(|m| m.frames.into_iter().chain(m.gone))
        .filter(|f| !numbers.contains(&f.timestep) && !out_dir.join(&f.file).exists())
        .map(|f| f.timestep)
        .collect();
    vanished.sort_unstable();
    vanished.dedup();
    let (mut kept, mut other, mut records) = (Vec::new(), Vec::new(), Vec::new());
    let mut species = std::collections::BTreeSet::new();
    for name in strays {
        let path = out_dir.join(name);
        let Ok(file) = MdlodFile::open_sparse(&path) else {
            continue;
        };
        let Some(own) = file.metadata().source.clone() else {
            continue;
        };
        let checksum = format!("{:016x}", file.header().section_table_checksum);
        let entry = listed.get(&(name.clone(), checksum));
        let absolute = entry.and_then(|e| e.source_abs.as_deref());
        let timestep = frame_file_number(name);
        // A timestep a restart of these inputs supersedes (`--duplicate-timesteps
        // last`) is no data of its own, whatever became of its dump.
        if timestep.is_some_and(|t| superseded.contains(&t)) {
            continue;
        }
        match source_gone(&own, absolute, &inputs) {
            Source::There => continue,
            Source::Missing => {}
            // Written again: only the frames before the first it holds now are the
            // earlier run's alone (a restart from 500 into the same file name keeps
            // 0 to 400); those from it on were superseded, or are of another run. (One
            // that holds no frame yet, a restart that has only just begun it, keeps
            // them all.)
            Source::Rewritten(key) => {
                let first = first_timesteps.get(&key).copied();
                if let (Some(t), Some(f)) = (timestep, first) {
                    if t >= f {
                        continue;
                    }
                }
            }
        }
        let same = entry.is_some_and(|r| {
            let renames = &opts.convert.species_names;
            let same_names = match &r.species_names {
                Some(names) => names == renames,
                None => renames.is_empty(),
            };
            let same_columns = r.columns.is_none() || r.columns == opts.read.columns;
            let same_attributes = same_further(&file.metadata().attributes, opts);
            same_names
                && same_columns
                && same_attributes
                && r.sizes == opts.read.sizes.record()
                && r.species_column == opts.read.species_column
                && r.wrap == opts.read.wrap
                // (Without a record of the overrides, the radii the dump gave cannot be
                // learnt: not the same.)
                && r.radii.is_some()
                && same_build(&file, &opts.convert, attribute, r.radii.as_deref(), || None)
                && frame_file_number(name) == Some(r.timestep)
        });
        match entry {
            Some(e) if same => {
                species.extend(file.metadata().species.iter().map(|s| s.name.clone()));
                kept.push(e.clone());
            }
            Some(e) => {
                other.push(name.clone());
                records.push(e.clone());
            }
            None => other.push(name.clone()),
        }
    }
    kept.sort_by_key(|e| e.timestep);
    records.sort_by_key(|e| e.timestep);
    GoneFrames {
        kept,
        other,
        records,
        vanished,
        species,
    }
}

/// What [`gone_source_frames`] found of frames whose dumps are gone.
struct GoneFrames {
    /// Listed again (their records).
    kept: Vec<FrameEntry>,
    /// Named, not listed: built with other settings, or recorded nowhere.
    other: Vec<String>,
    /// The records of `other` that have one, kept in the manifest
    /// ([`Manifest::unlisted`]) for a later run with their settings.
    records: Vec<FrameEntry>,
    /// Timesteps recorded whose frame files are gone too.
    vanished: Vec<u64>,
    /// The species of the frames of `kept`.
    species: std::collections::BTreeSet<String>,
}

/// The inputs of a batch as an error names them: the one, or the first and how many more.
fn describe_inputs(inputs: &[PathBuf]) -> String {
    match inputs {
        [] => "the inputs".into(),
        [one] => one.display().to_string(),
        [first, rest @ ..] => format!(
            "{} (and {} more input{})",
            first.display(),
            rest.len(),
            if rest.len() == 1 { "" } else { "s" }
        ),
    }
}

/// Removes what killed runs left in `out_dir`: temporary outputs of `timesteps` (this
/// run's frames, which no other shard writes) and temporary manifests older than
/// [`STALE_TEMP`]. A file already gone (a concurrent run removed it) is no error.
fn remove_leftovers(
    out_dir: &Path,
    timesteps: &std::collections::HashSet<u64>,
) -> Result<(), BatchError> {
    for e in std::fs::read_dir(out_dir).map_err(io(out_dir))?.flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        let Some(stem) = name.strip_suffix(".tmp") else {
            continue;
        };
        // Only files are ours (a directory of that name is somebody else's).
        if !e.file_type().is_ok_and(|t| t.is_file()) {
            continue;
        }
        let leftover = if let Some(rest) = stem.strip_prefix(".frame-") {
            // `.frame-<timestep>.mdlod.<random>.tmp` (the writer's temporary file).
            rest.split_once(".mdlod.")
                .and_then(|(t, _)| t.parse::<u64>().ok())
                .is_some_and(|t| timesteps.contains(&t))
        } else if stem.starts_with(".dataset.") {
            e.metadata()
                .and_then(|m| m.modified())
                .ok()
                .and_then(|t| t.elapsed().ok())
                .is_some_and(|age| age > STALE_TEMP)
        } else {
            false
        };
        if leftover {
            match std::fs::remove_file(e.path()) {
                Err(err) if err.kind() != std::io::ErrorKind::NotFound => {
                    return Err(io(&e.path())(err))
                }
                _ => {}
            }
        }
    }
    Ok(())
}

/// The first sign, in `jobs` (in the order of the inputs and their frames), of two runs
/// whose frames would interleave by timestep with none in common: a frame of an input
/// at a timestep below the one before it (a run restarted into the same dump), or two
/// inputs whose timesteps overlap without meeting (a restart written to a file of its
/// own, from a timestep between two the first run wrote). Inputs that merely follow one
/// another, in whatever order their names give, frames numbered by their place (no
/// timestep of their own) and a last frame cut short are no sign.
fn interleaved_runs(jobs: &[Job<'_>], place: &dyn Fn(&Job<'_>) -> String) -> Option<BatchError> {
    // (Not a dump's last frame cut inside a line, or a compressed dump's last frame, which
    // may be cut so too: their timesteps may be cut short, and they are left for a rerun.)
    let timed: Vec<(usize, &Job<'_>)> = jobs
        .iter()
        .enumerate()
        .filter(|(_, j)| j.own_timestep.is_some())
        .filter(|(_, j)| !(j.last_of_input && j.dump.is_none_or(DumpFile::ends_mid_line)))
        .collect();
    for w in timed.windows(2) {
        let ((_, a), (_, b)) = (w[0], w[1]);
        if a.input == b.input && b.timestep < a.timestep {
            return Some(BatchError::Interleaved {
                what: format!(
                    "{} at timestep {} follows {} at timestep {}",
                    place(b),
                    b.timestep,
                    place(a),
                    a.timestep
                ),
                last_keeps: format!(
                    "the restart's frames (from timestep {} on, leaving out the earlier \
                     run's from there)",
                    b.timestep
                ),
            });
        }
    }
    // Each input's first and last frame by timestep, with its place in the order of the
    // inputs.
    struct Span<'j, 'a> {
        order: usize,
        lo: &'j Job<'a>,
        hi: &'j Job<'a>,
    }
    let mut spans: Vec<Span<'_, '_>> = Vec::new();
    for (order, j) in timed {
        match spans.last_mut() {
            Some(s) if s.lo.input == j.input => {
                if j.timestep < s.lo.timestep {
                    s.lo = j;
                }
                if j.timestep > s.hi.timestep {
                    s.hi = j;
                }
            }
            _ => spans.push(Span {
                order,
                lo: j,
                hi: j,
            }),
        }
    }
    // By first timestep: a span starting before the latest end so far overlaps it (a
    // start equal to another's is a timestep twice, said before this).
    spans.sort_by_key(|s| s.lo.timestep);
    let mut latest: Option<&Span<'_, '_>> = None;
    for s in &spans {
        if let Some(end) = latest.filter(|e| s.lo.timestep < e.hi.timestep) {
            // `last` takes the inputs in their order: the later one's frames supersede
            // the earlier one's from its first timestep on, whichever is the restart.
            let (later, earlier) = if s.order > end.order {
                (s, end)
            } else {
                (end, s)
            };
            return Some(BatchError::Interleaved {
                what: format!(
                    "{} at timestep {} falls before {} at timestep {}",
                    place(s.lo),
                    s.lo.timestep,
                    place(end.hi),
                    end.hi.timestep
                ),
                last_keeps: format!(
                    "the frames of {}, the later input in their order (their paths' natural \
                     order), from its first timestep {} on, leaving out those of {} from \
                     there",
                    later.lo.input.display(),
                    later.lo.timestep,
                    earlier.lo.input.display()
                ),
            });
        }
        if latest.is_none_or(|e| s.hi.timestep > e.hi.timestep) {
            latest = Some(s);
        }
    }
    None
}

/// The inputs with file-name patterns (`dump.*.bin`) expanded where the shell left
/// them (quoted in a job script): `*` and `?` in the last component, matching files of
/// its directory, in natural order (see [`natural_cmp`]). A path that exists is taken as
/// it is. A pattern matches files only, as the inputs must be: not directories (the
/// batch directory itself, for `'run/*' -o run/out`), not hidden files unless it starts
/// with a dot (as the shell's), and not what a batch writes in `out_dir` (frames,
/// manifests, temporary files), which a rerun would otherwise take for inputs. The
/// newest timestep of a `%` piece set short of a piece, or with an empty one, is left
/// out ([`expand_patterns_noting`] says so).
pub fn expand_patterns(inputs: &[PathBuf], out_dir: &Path) -> Result<Vec<PathBuf>, BatchError> {
    expand_patterns_noting(inputs, out_dir, &mut Vec::new())
}

/// [`expand_patterns`], with a note in `notes` for each newest timestep of a `%` piece
/// set left out: one a run is still writing (a piece not there yet, or still empty),
/// which a rerun converts once complete. An older timestep short of a piece is refused.
pub fn expand_patterns_noting(
    inputs: &[PathBuf],
    out_dir: &Path,
    notes: &mut Vec<String>,
) -> Result<Vec<PathBuf>, BatchError> {
    let out_dir = std::fs::canonicalize(out_dir).ok();
    let mut out = Vec::with_capacity(inputs.len());
    for input in inputs {
        let name = input.file_name().and_then(|n| n.to_str()).unwrap_or("");
        // A wildcard in a directory's name (`runs/f*/sig.raw.json`): patterns match file
        // names in one directory.
        let wild_dir = input.parent().is_some_and(|d| {
            !d.as_os_str().is_empty()
                && !d.is_dir()
                && d.to_str().is_some_and(|d| d.contains(['*', '?', '[']))
        });
        if wild_dir {
            return Err(BatchError::Pattern {
                pattern: input.clone(),
                message: "a quoted pattern matches file names in one directory, not \
                          directory names (leave it unquoted for the shell to expand, or \
                          list the files)"
                    .into(),
            });
        }
        if input.exists() || !name.contains(['*', '?', '[']) {
            out.push(input.clone());
            continue;
        }
        let err = |message: String| BatchError::Pattern {
            pattern: input.clone(),
            message,
        };
        if name.contains('[') {
            return Err(err(
                "a quoted pattern takes * and ? only, not [...] (leave it unquoted for the \
                 shell to expand)"
                    .into(),
            ));
        }
        let dir = match input.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        if name.matches('%').count() > 1 {
            return Err(err(
                "a file name holds one `%` (the processor number of a piece set)".into(),
            ));
        }
        let entries = std::fs::read_dir(&dir)
            .map_err(|e| err(format!("cannot list {}: {e}", dir.display())))?;
        // The batch directory's own files, where the pattern's directory is it.
        let in_out_dir = out_dir.is_some() && std::fs::canonicalize(&dir).ok() == out_dir;
        let mut found: Vec<PathBuf> = entries
            .flatten()
            .filter_map(|e| {
                let n = e.file_name().to_str()?.to_owned();
                // With a `%` (`dump.*.%.bin`, LAMMPS's per-processor pieces of each
                // timestep's file), the piece set a piece belongs to: its name with a
                // run of digits written `%`.
                let n = if name.contains('%') {
                    piece_set_of(name, &n)?
                } else {
                    n
                };
                let keep = wildcard(name, &n)
                    && (name.starts_with('.') || !n.starts_with('.'))
                    && !(in_out_dir && written_by_batch(&n))
                    // (Following links: a link to a file is one.)
                    && (name.contains('%') || e.path().is_file());
                keep.then(|| input.with_file_name(n))
            })
            .collect();
        if found.is_empty() {
            return Err(err("no file matches the pattern".into()));
        }
        found.sort_by(|a, b| natural_cmp(&a.to_string_lossy(), &b.to_string_lossy()));
        found.dedup();
        // Every timestep's set in as many pieces (one deleted or not yet written would
        // give its frame part of the atoms, unnoticed).
        if name.contains('%') {
            let counts: Vec<(usize, &PathBuf)> = found
                .iter()
                .map(|set| {
                    crate::readers::piece_paths(set)
                        .map(|p| (p.len(), set))
                        .map_err(|e| err(e.to_string()))
                })
                .collect::<Result<_, _>>()?;
            let most = counts.iter().map(|(c, _)| *c).max().unwrap_or(0);
            let plural = |c: usize| if c == 1 { "" } else { "s" };
            // The newest timestep's set (the last in order), as a running simulation
            // leaves it: a piece not written yet, or one still empty.
            let newest = counts.len().saturating_sub(1);
            let empty_piece = |set: &PathBuf| {
                crate::readers::piece_paths(set).is_ok_and(|pieces| {
                    pieces
                        .iter()
                        .any(|p| std::fs::metadata(p).is_ok_and(|m| m.len() == 0))
                })
            };
            let mut writing = None;
            for (k, (c, set)) in counts.iter().enumerate() {
                let short = *c < most;
                if counts.len() > 1 && k == newest && (short || empty_piece(set)) {
                    writing = Some(match short {
                        true => format!(
                            "{}, the newest timestep, is in {c} piece{} where the others are in {most}",
                            set.display(),
                            plural(*c)
                        ),
                        false => format!(
                            "{}, the newest timestep, has an empty piece",
                            set.display()
                        ),
                    });
                } else if short {
                    return Err(err(format!(
                        "{} is in {c} piece{}, where another timestep's set is in {most}: a \
                         piece missing (deleted, or not written yet)",
                        set.display(),
                        plural(*c)
                    )));
                }
            }
            if let Some(why) = writing {
                notes.push(format!(
                    "{why} (a run still writing it?): left out; a rerun converts it once \
                     every piece is written"
                ));
                found.truncate(newest);
            }
        }
        out.extend(found);
    }
    Ok(out)
}

/// Whether a file of this name in a batch directory is one a batch writes: a frame, a
/// manifest (whole, a shard's) or a temporary file.
pub fn written_by_batch(name: &str) -> bool {
    (name.starts_with("frame-") && name.ends_with(".mdlod"))
        || (name.starts_with("dataset") && name.ends_with(".json"))
        || name.ends_with(".tmp")
        || name == INDEX_CACHE
}

/// The name of the `%` piece set of `pattern` (which holds one `%`) that the file `name`
/// is a piece of: `name` with its last run of digits for which the pattern then matches
/// written `%` (`dump.100.3.bin` of `dump.*.%.bin` is a piece of `dump.100.%.bin`).
fn piece_set_of(pattern: &str, name: &str) -> Option<String> {
    let bytes = name.as_bytes();
    let mut end = bytes.len();
    while end > 0 {
        if !bytes[end - 1].is_ascii_digit() {
            end -= 1;
            continue;
        }
        let start = bytes[..end]
            .iter()
            .rposition(|b| !b.is_ascii_digit())
            .map_or(0, |i| i + 1);
        let set = format!("{}%{}", &name[..start], &name[end..]);
        if wildcard(pattern, &set) {
            return Some(set);
        }
        end = start;
    }
    None
}

/// Whether `name` matches `pattern`, where `*` stands for any run of characters and `?`
/// for one.
fn wildcard(pattern: &str, name: &str) -> bool {
    let (p, n): (Vec<char>, Vec<char>) = (pattern.chars().collect(), name.chars().collect());
    // Greedy with backtracking to the last `*`.
    let (mut i, mut j, mut star, mut mark) = (0, 0, None, 0);
    while j < n.len() {
        if i < p.len() && (p[i] == '?' || p[i] == n[j]) {
            i += 1;
            j += 1;
        } else if i < p.len() && p[i] == '*' {
            star = Some(i);
            mark = j;
            i += 1;
        } else if let Some(s) = star {
            i = s + 1;
            mark += 1;
            j = mark;
        } else {
            return false;
        }
    }
    p[i..].iter().all(|&c| c == '*')
}

/// Orders paths as people number file sets: runs of digits by their value, so that
/// `water.2.xyz` comes before `water.10.xyz` (the shell's order puts it after), the rest
/// character by character.
pub fn natural_cmp(a: &str, b: &str) -> std::cmp::Ordering {
    let (mut a, mut b) = (a.as_bytes(), b.as_bytes());
    loop {
        match (a.first(), b.first()) {
            (None, None) => return std::cmp::Ordering::Equal,
            (None, Some(_)) => return std::cmp::Ordering::Less,
            (Some(_), None) => return std::cmp::Ordering::Greater,
            (Some(x), Some(y)) if x.is_ascii_digit() && y.is_ascii_digit() => {
                let run = |s: &[u8]| s.iter().take_while(|c| c.is_ascii_digit()).count();
                let (na, nb) = (run(a), run(b));
                let trim = |s: &[u8]| -> usize { s.iter().take_while(|&&c| c == b'0').count() };
                let (da, db) = (
                    &a[trim(&a[..na]).min(na)..na],
                    &b[trim(&b[..nb]).min(nb)..nb],
                );
                // By value (length, then digits), then by the zeros in front (`01` after `1`).
                let order = da
                    .len()
                    .cmp(&db.len())
                    .then_with(|| da.cmp(db))
                    .then_with(|| na.cmp(&nb));
                if order != std::cmp::Ordering::Equal {
                    return order;
                }
                (a, b) = (&a[na..], &b[nb..]);
            }
            (Some(x), Some(y)) => {
                if x != y {
                    return x.cmp(y);
                }
                (a, b) = (&a[1..], &b[1..]);
            }
        }
    }
}

/// One frame to convert.
struct Job<'a> {
    input: &'a Path,
    /// The opened input; `None` for a gzip input, which is opened again by the worker
    /// that converts it (its text is not kept in memory between).
    dump: Option<&'a DumpFile>,
    format: InputFormat,
    frame: usize,
    /// The input's own timestep of the frame, where it records one.
    own_timestep: Option<u64>,
    timestep: u64,
    /// The particle count (known from indexing for a gzip input; for others, read from
    /// the frame's header when needed).
    particles: u64,
    /// The frame's attribute as the reader names it (`None`: no attribute).
    attribute: Option<String>,
    /// For a gzip input whose frame has an output already: the radii the frame gives its
    /// species (see [`DumpFile::given_radii`]; `None` when they cannot be read).
    given_radii: Option<Vec<(String, f32)>>,
    /// Whether the frame is its input's last (one a running simulation may be writing).
    last_of_input: bool,
    /// Whether its input is the newest of the inputs ([`newest_inputs`]), the only one
    /// whose last frame may be cut short.
    newest: bool,
    /// The units of an earlier input (LAMMPS text), for a frame that records none: a
    /// `dump.*` set's `ITEM: UNITS` is in its first file only (LAMMPS writes it once per
    /// dump command).
    carried_units: Option<String>,
}

impl Job<'_> {
    /// Whether the frame may be one a running simulation is still writing: the last of
    /// the newest input. A file set's older files are complete (a run writes one file at
    /// a time), so one of them cut short is damaged, and an error.
    fn may_be_cut(&self) -> bool {
        self.last_of_input && self.newest
    }
}

/// Which inputs are the newest, given their frames as listed: those holding the greatest
/// timestep of the inputs, and `last`, the last input as inputs are given in their order
/// (the CLI sorts them by their numbers) that is not plainly something other than a dump
/// ([`crate::readers::plainly_no_dump`]): a file cut in its first frame's header records no
/// timestep, or a part of one (`50` of `500`, the line cut short), and formats without
/// timesteps have none.
fn newest_inputs(listed: &[Vec<Listed>], last: Option<usize>) -> Vec<bool> {
    let latest: Vec<Option<u64>> = listed
        .iter()
        .map(|frames| frames.iter().filter_map(|f| f.0).max())
        .collect();
    let greatest = latest.iter().flatten().max().copied();
    latest
        .iter()
        .enumerate()
        .map(|(i, t)| Some(i) == last || (t.is_some() && *t == greatest))
        .collect()
}

/// A frame as it was listed while its input was open: (the input's own timestep, the
/// batch's number, particles, attribute, given radii, its index in the input); see
/// [`Job`].
type Listed = (
    Option<u64>,
    u64,
    u64,
    Option<String>,
    Option<Vec<(String, f32)>>,
    usize,
);

/// Converts every frame of `inputs` (this shard's share) into `out_dir`.
pub fn batch(
    inputs: &[PathBuf],
    out_dir: &Path,
    opts: &BatchOptions,
    progress: &dyn Progress,
) -> Result<BatchReport, BatchError> {
    if let Some((i, n)) = opts.shard {
        if n == 0 || i >= n {
            return Err(BatchError::BadShard(i, n));
        }
    }
    // A radius given to a species by the name a rename takes from it would leave every
    // frame converted without that radius before the check at the end refused the run:
    // refused before any frame is touched.
    if let Some(e) = crate::species::radius_of_a_renamed_species(
        &opts.convert.radii,
        &opts.convert.species_names,
    ) {
        return Err(BatchError::Convert(ConvertError::Species(Box::new(
            crate::species::UnknownSpecies {
                input: Some(describe_inputs(inputs)),
                ..e
            },
        ))));
    }
    crate::convert::check_attribute_count(&opts.read, &describe_inputs(inputs))?;
    std::fs::create_dir_all(out_dir).map_err(io(out_dir))?;
    // (Indexing alone writes only the cache, by rename: it runs beside anything.)
    let _lock = match opts.index_only {
        true => Vec::new(),
        false => lock_batch(out_dir, opts.shard)?,
    };
    // Text inputs unchanged since a run (or a shard beside this one) scanned them are
    // listed from the cache.
    let index_cache = std::sync::Arc::new(crate::readers::index_cache::IndexCache::load(
        &out_dir.join(INDEX_CACHE),
    ));
    let index_scope = index_cache.scope();
    let mut not_kept = 0;

    // Inputs are indexed one at a time. Mapped files stay open; the text of a gzip input
    // is dropped after indexing (with its frames' particle counts noted), so a batch of
    // many compressed files never holds more than one at a time per worker.
    let mut dumps: Vec<Option<DumpFile>> = Vec::with_capacity(inputs.len());
    // Which inputs are gzip files whose compressed stream ends early.
    let mut gzip_cut: Vec<bool> = Vec::with_capacity(inputs.len());
    // Notes on inputs as a whole (a `%` set's pieces written unevenly), said once.
    let mut input_notes: Vec<String> = Vec::new();
    let mut formats: Vec<InputFormat> = Vec::with_capacity(inputs.len());
    let mut listed: Vec<Vec<Listed>> = Vec::with_capacity(inputs.len());
    // Frames whose header cannot be read far enough to give their timestep (a LAMMPS
    // frame always records one): with --keep-going, failed before they are listed, so
    // that a number made up for them takes no real frame's place among the timesteps.
    let mut unlisted_failures: Vec<FailedFrame> = Vec::new();
    // How the first frame of each input names its species (for the radius overrides).
    let mut namings: Vec<SpeciesNaming> = Vec::with_capacity(inputs.len());
    let mut position = 0u64;
    // Indexing has the whole memory limit: one input at a time, before any conversion.
    let mut index_chunks = opts.convert.chunks.clone();
    index_chunks.memory_limit = opts.memory_limit;
    // The newest input of a set, as empty files are told (see [`newest_inputs`]).
    // (A run's log a pattern matched, sorted after the dumps, is not it: the last input
    // that is not plainly something else is.)
    let last_input = inputs
        .iter()
        .rposition(|p| !crate::readers::plainly_no_dump(p))
        .or(inputs.len().checked_sub(1));
    let mut empty_inputs = Vec::new();
    // Each input's size and modification time as it was indexed, taken before it is
    // opened: what its frames are converted from (a mapped input keeps those bytes even
    // where the file is replaced by another under its name, as rsync does) and what
    // their files record, so that a rerun finds such frames stale. Taken again when
    // they are converted, a replaced input's new size and time were recorded beside
    // the old data, and reruns and `verify` kept the stale frames.
    let mut indexed: std::collections::HashMap<&Path, SourceInfo> =
        std::collections::HashMap::new();
    for (i, p) in inputs.iter().enumerate() {
        indexed.insert(p.as_path(), fingerprint(p, 0));
        // An empty newest file of a set is one LAMMPS has just opened: left out with a
        // note, as a frame cut short is. (Elsewhere, or alone, it is the reader's error.)
        let newest_of_set = inputs.len() > 1 && Some(i) == last_input;
        let empty =
            newest_of_set && std::fs::metadata(p).is_ok_and(|m| m.is_file() && m.len() == 0);
        let no_text = newest_of_set && !empty && crate::readers::gzip_without_text(p);
        if empty || no_text {
            empty_inputs.push(IncompleteFrame {
                input: p.clone(),
                frame: 0,
                timestep: None,
                reason: if no_text {
                    "its compressed stream ends before any text (a run has just opened it?)"
                } else {
                    "the file is empty (a run has just opened it?)"
                }
                .into(),
                empty_file: true,
            });
            // No frames: the format and dump stand in for none.
            listed.push(Vec::new());
            formats.push(InputFormat::LammpsText);
            dumps.push(None);
            gzip_cut.push(false);
            continue;
        }
        // A large gzip input is decompressed into a working file (removed again below),
        // not into memory.
        let bounded =
            match crate::convert::open_bounded(p, &index_chunks, &out_dir.join(MANIFEST), progress)
            {
                Ok(b) => b,
                Err(e) => {
                    // With --keep-going, an input that holds no dump it can read (a log
                    // file a pattern matched, a damaged header) fails alone; a file that
                    // cannot be read at all (a wrong path, a full disk) stops the batch.
                    let e = BatchError::from(e);
                    if !(opts.keep_going && e.frames_own()) {
                        return Err(e);
                    }
                    unlisted_failures.push(FailedFrame {
                        input: p.to_path_buf(),
                        frame: 0,
                        timestep: None,
                        listed_timestep: None,
                        reason: e.to_string(),
                    });
                    listed.push(Vec::new());
                    formats.push(InputFormat::LammpsText);
                    dumps.push(None);
                    gzip_cut.push(false);
                    continue;
                }
            };
        let compressed = bounded.text.is_some() || bounded.dump.is_compressed();
        let dump = &bounded.dump;
        not_kept += usize::from(
            compressed || !matches!(dump.format(), InputFormat::LammpsText | InputFormat::Xyz),
        );
        let mut frames = Vec::with_capacity(dump.frame_count());
        let lammps = matches!(
            dump.format(),
            InputFormat::LammpsText | InputFormat::LammpsBinary
        );
        // Frames with and without a timestep in one input (a last frame cut short before
        // its comment line aside) cannot be put in order.
        let count = dump.frame_count();
        let (with, without): (Vec<usize>, Vec<usize>) =
            (0..count).partition(|&k| dump.frame_timestep(k).is_some());
        // (A frame whose timestep is no whole number, `Timestep=x`, is numbered by its
        // position with a note of its own.)
        let without: Vec<usize> = without
            .into_iter()
            .filter(|&k| dump.unread_timestep(k).is_none())
            .filter(|&k| !(k + 1 == count && dump.frame_info(k).is_err_and(|e| e.cut_short())))
            .collect();
        if !lammps && !with.is_empty() && !without.is_empty() {
            return Err(BatchError::MixedTimesteps {
                path: p.to_path_buf(),
                with: frames_text(&with),
                without: frames_text(&without),
            });
        }
        for k in 0..dump.frame_count() {
            let own = dump.frame_timestep(k);
            let timestep = own.unwrap_or(position);
            position += 1;
            // (An input's last frame cut short, a run still writing it, is left for a
            // rerun below; one whose header is damaged otherwise fails here, as any
            // other: numbered by its place, it could take a real frame's timestep.)
            let last = k + 1 == dump.frame_count();
            if own.is_none() && lammps {
                match dump.frame_info(k) {
                    Err(e) if !(last && e.cut_short()) => {
                        let e = BatchError::Convert(bounded.context(p, e.into()));
                        if !opts.keep_going {
                            return Err(e);
                        }
                        unlisted_failures.push(FailedFrame {
                            input: p.to_path_buf(),
                            frame: k,
                            timestep: None,
                            listed_timestep: None,
                            reason: e.to_string(),
                        });
                        continue;
                    }
                    _ => {}
                }
            }
            // A last frame cut short in its atoms (a run still writing the input) is left
            // out where it is read, with a note, as for an uncompressed input: its
            // description is not needed here.
            // (Read once, where it is needed: a compressed input's every frame, the last.)
            let info = (compressed || k + 1 == dump.frame_count()).then(|| dump.frame_info(k));
            if k + 1 == dump.frame_count()
                && matches!(info, Some(Err(crate::readers::ReadError::Truncated { .. })))
            {
                frames.push((own, timestep, u64::MAX, None, None, k));
                continue;
            }
            let (particles, given) = if let (true, Some(info)) = (compressed, info) {
                // (With --keep-going, a frame whose header cannot be read is converted
                // like the others, and its conversion reports it.)
                let info = match info {
                    // (Its count unknown, as a cut-short last frame's: not taken for an
                    // empty frame, so its conversion runs and reports it.)
                    Err(_) if opts.keep_going => {
                        frames.push((own, timestep, u64::MAX, None, None, k));
                        continue;
                    }
                    info => info.map_err(|e| bounded.context(p, e.into()))?,
                };
                // What a rerun compares an existing output's radii with (the text is
                // gone later).
                let given = out_dir
                    .join(frame_file_name(timestep))
                    .is_file()
                    .then(|| dump.given_radii(k).ok())
                    .flatten();
                (info.particles as u64, given)
            } else {
                (0, None)
            };
            // The attribute asked for, resolved now (a gzip input's text is gone later): a
            // column the frame lacks is an error before anything is converted.
            let attribute = match dump.attribute_name(k, &opts.read) {
                Ok(a) => a,
                // An empty frame is skipped, and its header may not name the column (a
                // plain XYZ frame's extra columns come from its first atom line).
                Err(_) if dump.frame_info(k).is_ok_and(|i| i.particles == 0) => None,
                // With --keep-going, the frame's conversion says it, and the others go on.
                Err(_) if opts.keep_going => None,
                Err(e) => return Err(bounded.context(p, e.into()).into()),
            };
            // So is a further attribute's.
            for extra in &opts.read.extra_attributes {
                match dump.attribute_name(k, &opts.read.reading(extra)) {
                    Ok(_) => {}
                    Err(_) if dump.frame_info(k).is_ok_and(|i| i.particles == 0) => {}
                    Err(_) if opts.keep_going => {}
                    Err(e) => return Err(bounded.context(p, e.into()).into()),
                }
            }
            // So is a size column a frame lacks.
            if let Err(e) = dump.check_named_columns(k, &opts.read) {
                if !opts.keep_going {
                    return Err(bounded.context(p, e.into()).into());
                }
            }
            frames.push((own, timestep, particles, attribute, given, k));
        }
        if (!opts.convert.radii.is_empty() || !opts.convert.species_names.is_empty())
            && dump.frame_count() > 0
        {
            // (Advisory: a frame that cannot be read fails where it is converted.)
            namings.push(
                dump.species_naming(0, &opts.read)
                    .unwrap_or(SpeciesNaming::Given),
            );
        }
        input_notes.extend(dump.input_notes());
        // (Said of the first input: one processor's pieces of every timestep read alike;
        // the set to give is every timestep's where the inputs are a file per timestep.)
        if i == 0 && dump.piece_paths().is_none() {
            // (Other files, not this run's inputs: no index of theirs is kept.)
            let _uncached = crate::readers::index_cache::IndexCache::suspend();
            if let Some(lone) = crate::readers::lone_piece(p, dump.frame_timestep(0), inputs) {
                let others: Vec<&Path> = inputs.iter().map(PathBuf::as_path).collect();
                let give = every_timesteps_set(&lone.set, &others).unwrap_or(lone.set.clone());
                input_notes.push(lone.note(&give));
            }
        }
        listed.push(frames);
        formats.push(dump.format());
        gzip_cut.push(dump.gzip_cut().is_some());
        dumps.push((!compressed).then_some(bounded.dump));
    }
    drop(index_scope);
    let index = IndexUse {
        file: index_cache.path().to_path_buf(),
        from_cache: index_cache.hits(),
        scanned: index_cache.scanned(),
        unsettled: index_cache.unsettled(),
        not_kept,
        unsaved: match index_cache.save() {
            Ok(()) => None,
            // (Only a cache: a read-only archive of finished frames still checks.)
            Err(e) if !opts.index_only => Some(e.to_string()),
            Err(e) => return Err(io(index_cache.path())(e)),
        },
    };
    let newest = newest_inputs(&listed, last_input);
    // The newest input, as an error about an older one cut short names it (the last of
    // them in order, where the one holding the latest timestep is not the last).
    let newest_text = inputs
        .iter()
        .zip(&newest)
        .filter(|(_, n)| **n)
        .map(|(p, _)| p.display().to_string())
        .next_back()
        .unwrap_or_default();
    // A gzip input cut short that is not the newest: its frames past the cut would be
    // lost without a trace (no run writes an older file of a set any more).
    if let Some((input, _)) = inputs
        .iter()
        .zip(gzip_cut.iter().zip(&newest))
        .find(|(_, (cut, newest))| **cut && !**newest)
    {
        return Err(BatchError::CutShortBeforeNewest {
            input: input.to_path_buf(),
            newest: newest_text.clone(),
            reason: "its compressed stream ends early: the frames past the cut are missing".into(),
        });
    }
    let mut jobs: Vec<Job<'_>> = Vec::new();
    // The last units an input (in the inputs' order) recorded, carried to those after it
    // that record none.
    let mut units: Option<String> = None;
    for ((((input, dump), format), frames), newest) in inputs
        .iter()
        .zip(&dumps)
        .zip(&formats)
        .zip(listed)
        .zip(newest)
    {
        // (A frame failed before it was listed is never an input's last.)
        let count = frames.last().map_or(0, |f| f.5 + 1);
        let text = *format == InputFormat::LammpsText;
        let own_units = dump
            .as_ref()
            .filter(|_| text)
            .and_then(|d| d.frame_info(0).ok()?.units);
        let carried_units = match own_units {
            Some(u) => {
                units = Some(u);
                None
            }
            None => units.clone().filter(|_| text),
        };
        for (own, timestep, particles, attribute, given, k) in frames {
            jobs.push(Job {
                input,
                dump: dump.as_ref(),
                format: *format,
                frame: k,
                own_timestep: own,
                timestep,
                particles,
                attribute,
                given_radii: given,
                last_of_input: k + 1 == count,
                newest,
                carried_units: carried_units.clone(),
            });
        }
    }
    // A species may appear in later frames only (checked at the end), but a name the
    // inputs cannot hold (`Cu` where species are LAMMPS type numbers) is refused now,
    // in every shard.
    if !namings.is_empty() {
        // A name a rename gives (`--species-name 1=Cu --radius Cu=1.28`) is no input's
        // own: the renames are checked against the inputs where the frames are read.
        let renamed_to = |name: &str| {
            opts.convert
                .species_names
                .iter()
                .any(|(_, new)| new == name)
        };
        for (old, new) in &opts.convert.species_names {
            let reasons: Option<Vec<String>> =
                namings.iter().map(|n| n.excludes_rename(old)).collect();
            if let Some(reason) = reasons.and_then(|r| r.into_iter().next()) {
                return Err(BatchError::ImpossibleRename {
                    inputs: describe_inputs(inputs),
                    old: old.clone(),
                    new: new.clone(),
                    reason,
                });
            }
        }
        let any = crate::species::ANY_SPECIES;
        for (name, radius) in opts
            .convert
            .radii
            .iter()
            .filter(|(n, _)| !renamed_to(n) && n != any)
        {
            let reasons: Option<Vec<String>> =
                namings.iter().map(|n| n.excludes(name, *radius)).collect();
            if let Some(reason) = reasons.and_then(|r| r.into_iter().next()) {
                return Err(BatchError::ImpossibleSpecies {
                    inputs: describe_inputs(inputs),
                    name: name.clone(),
                    radius: *radius,
                    reason,
                });
            }
        }
    }
    let place = |j: &Job<'_>| format!("{} frame {}", j.input.display(), j.frame);
    // An input's last frame cut short before its timestep could be read, beside frames
    // that record theirs (a GSD file cut inside its last frame's step): numbered by its
    // place, it is no restart and no twin, and is left for a rerun when it is read.
    let timed: std::collections::HashSet<&Path> = jobs
        .iter()
        .filter(|j| j.own_timestep.is_some())
        .map(|j| j.input)
        .collect();
    let (cut_unnumbered, numbered): (Vec<Job<'_>>, Vec<Job<'_>>) = jobs
        .into_iter()
        .partition(|j| j.own_timestep.is_none() && j.last_of_input && timed.contains(j.input));
    let mut jobs = numbered;
    let mut duplicates = Vec::new();
    // Timesteps a restart supersedes (`--duplicate-timesteps last`): their frame files
    // from an earlier run are not listed as frames of gone dumps.
    let mut superseded = std::collections::HashSet::new();
    // A restart (a frame, in the order of the inputs and their frames, at a timestep no
    // later than one before it) supersedes every earlier frame from its timestep on,
    // with a later twin or not: the abandoned run's frames past the restart's newest
    // would otherwise sit between the restarted run's.
    if opts.duplicates == Duplicates::Last {
        let mut kept: Vec<Job<'_>> = Vec::with_capacity(jobs.len());
        for j in jobs {
            if kept.last().is_some_and(|k| j.timestep <= k.timestep) {
                // (Those from the restart's timestep on, and those before it.)
                let (new, old): (Vec<Job<'_>>, Vec<Job<'_>>) =
                    kept.into_iter().partition(|k| k.timestep >= j.timestep);
                for k in &new {
                    // (Twins of one timestep are said below, as before.)
                    if k.timestep != j.timestep {
                        superseded.insert(k.timestep);
                        duplicates.push(format!(
                            "timestep {}: {} left out, superseded by the restart at timestep \
                             {} ({})",
                            k.timestep,
                            place(k),
                            j.timestep,
                            place(&j)
                        ));
                    }
                }
                kept = old;
                kept.extend(new.into_iter().filter(|k| k.timestep == j.timestep));
            }
            kept.push(j);
        }
        jobs = kept;
    }
    // Two runs' frames that would interleave with no timestep in common (a restart from
    // a timestep between two the first run wrote): refused as twins are, unless asked.
    let interleaved = (opts.duplicates == Duplicates::Error)
        .then(|| interleaved_runs(&jobs, &place))
        .flatten();
    // Stable: frames of one timestep stay in the order of the inputs and their frames.
    jobs.sort_by_key(|j| j.timestep);
    if opts.duplicates == Duplicates::Error {
        if let Some(w) = jobs.windows(2).find(|w| w[0].timestep == w[1].timestep) {
            // Two files of the same timesteps, named alike but for a number: the pieces
            // each processor of one run wrote (`dump.*.bin` matching `dump.0.bin` and
            // `dump.1.bin`), which keeping either file's frames would halve.
            let steps = |input: &Path| -> Vec<u64> {
                jobs.iter()
                    .filter(|j| j.input == input)
                    .map(|j| j.timestep)
                    .collect()
            };
            // (A set numbered from 0, as LAMMPS numbers its processors: replicas of an
            // ensemble numbered from 1 are no pieces.)
            let pieces = (w[0].input != w[1].input && steps(w[0].input) == steps(w[1].input))
                .then(|| piece_pattern(w[0].input, w[1].input))
                .flatten()
                .filter(|set| crate::readers::piece_paths(set).is_ok());
            let restart = "--duplicate-timesteps last keeps the later frame of each, first \
                           the earlier";
            // A file per timestep in pieces (`dump.0.0.bin`, `dump.0.1.bin`,
            // `dump.50.0.bin`, ...): the pattern of every timestep's set.
            let pieces = pieces.map(|set| {
                let inputs: Vec<&Path> = jobs.iter().map(|j| j.input).collect();
                every_timesteps_set(&set, &inputs).unwrap_or(set)
            });
            // A frame that records no timestep (an XYZ frame without `Timestep=`, an
            // MMPLD frame) is numbered by its place among the inputs' frames, which can
            // be a real frame's timestep: no restart, and keeping either loses data.
            let numbered = w.iter().find(|j| j.own_timestep.is_none()).map(&place);
            let why = match (pieces, numbered) {
                (_, Some(p)) if w.iter().any(|j| j.own_timestep.is_some()) => format!(
                    "{p} records no timestep and is numbered by its place among the inputs' \
                     frames, which another frame's own timestep is: frames with and without \
                     timesteps go into batches of their own"
                ),
                (Some(set), _) => format!(
                    "the two files hold the same timesteps: pieces of one run written per \
                     processor? Give the pieces as one set, quoted: '{}'; separate runs \
                     (replicas) go into batches of their own; for a run restarted into \
                     them, {restart}",
                    set.display()
                ),
                (None, _) => format!("a run restarted into the same dump? {restart}"),
            };
            return Err(BatchError::DuplicateTimestep {
                timestep: w[0].timestep,
                first: place(&w[0]),
                second: place(&w[1]),
                why,
            });
        }
        if let Some(e) = interleaved {
            return Err(e);
        }
    } else {
        let mut kept: Vec<Job<'_>> = Vec::with_capacity(jobs.len());
        let mut rest = jobs.into_iter().peekable();
        while let Some(first) = rest.next() {
            let mut group = vec![first];
            while let Some(next) = rest.next_if(|j| j.timestep == group[0].timestep) {
                group.push(next);
            }
            let keep = match opts.duplicates {
                Duplicates::Last => group.len() - 1,
                _ => 0,
            };
            for (_, j) in group.iter().enumerate().filter(|(i, _)| *i != keep) {
                duplicates.push(format!(
                    "timestep {}: {} left out, {} converted",
                    j.timestep,
                    place(j),
                    place(&group[keep])
                ));
            }
            kept.extend(group.into_iter().nth(keep));
        }
        jobs = kept;
    }
    jobs.extend(cut_unnumbered);
    jobs.sort_by_key(|j| j.timestep);
    let frames_total = jobs.len();
    // Indexing alone ends here, its inputs checked as a shard's run would check them.
    if opts.index_only {
        return Ok(BatchReport {
            frames_total,
            frames_in_shard: 0,
            converted: 0,
            skipped: 0,
            empty: Vec::new(),
            notes: input_notes,
            jobs: 0,
            manifest: out_dir.join(MANIFEST),
            removed_merged: None,
            removed_shard_manifests: Vec::new(),
            strays: Vec::new(),
            kept_gone: Vec::new(),
            gone_other: Vec::new(),
            vanished: Vec::new(),
            duplicates,
            redone: Redone::default(),
            kept_unchanged: 0,
            incomplete: empty_inputs,
            failed: unlisted_failures,
            index,
        });
    }
    // The list the shards split: the same in every shard only when the inputs were.
    let input_frames = InputFrames::of(jobs.iter().map(|j| (j.input, j.timestep)));
    // Frame files no frame of these inputs is written to (a run over other or longer
    // inputs left them): named, left alone.
    let numbers: std::collections::HashSet<u64> = jobs.iter().map(|j| j.timestep).collect();
    // This run's inputs, as [`other_input`] compares a frame's recorded source (those
    // whose every frame a later input supersedes too).
    let run_inputs: std::collections::HashSet<(PathBuf, std::ffi::OsString)> =
        inputs.iter().map(|p| input_key(p)).collect();
    let mut strays: Vec<String> = std::fs::read_dir(out_dir)
        .map_err(io(out_dir))?
        .flatten()
        .filter_map(|e| {
            let name = e.file_name().into_string().ok()?;
            let number = frame_file_number(&name)?;
            (!numbers.contains(&number)).then_some(name)
        })
        .collect();
    strays.sort_by_key(|n| frame_file_number(n));
    // Frames of dumps deleted since they were converted stay listed: by every shard of a
    // sharded run, apart from its own ([`Manifest::gone`]), so that each shard's
    // manifest keeps their records whichever runs first, and the merge lists each once.
    let attribute = jobs.first().and_then(|j| j.attribute.clone());
    let records = Records::read(out_dir);
    // The first timestep each input holds now.
    let mut first_timesteps = std::collections::HashMap::new();
    for j in &jobs {
        first_timesteps
            .entry(input_key(j.input))
            .and_modify(|t: &mut u64| *t = (*t).min(j.timestep))
            .or_insert(j.timestep);
    }
    let GoneFrames {
        kept: gone,
        other: gone_other,
        records: unlisted,
        vanished,
        species: gone_species,
    } = gone_source_frames(
        out_dir,
        // (The manifests' records only: the side records keep frames of other inputs,
        // which a run over these never lists as its own, their dumps gone or not.)
        &records.listed,
        &strays,
        inputs,
        &numbers,
        &first_timesteps,
        &superseded,
        opts,
        attribute.as_deref(),
    );
    let not_strays: std::collections::HashSet<&String> =
        gone.iter().map(|e| &e.file).chain(&gone_other).collect();
    strays.retain(|n| !not_strays.contains(n));
    let mut mine: Vec<Job<'_>> = match opts.shard {
        None => jobs,
        Some((i, n)) => jobs
            .into_iter()
            .enumerate()
            .filter(|(p, _)| *p as u64 % u64::from(n) == u64::from(i))
            .map(|(_, j)| j)
            .collect(),
    };
    let frames_in_shard = mine.len();
    remove_leftovers(out_dir, &mine.iter().map(|j| j.timestep).collect())?;

    // What is already done.
    let manifest_path = out_dir.join(manifest_name(opts.shard));
    let mut done = Vec::new();
    let mut todo = Vec::new();
    let mut empty = Vec::new();
    // Frame `frame` of `input` as its input was indexed (a raw sidecar's is read).
    let indexed_source = |input: &Path, frame: usize| SourceInfo {
        frame: frame as u64,
        ..indexed
            .get(input)
            .cloned()
            .unwrap_or_else(|| fingerprint(input, 0))
    };
    // The species names the frames hold, for the radius overrides' check at the end.
    let seen = Mutex::new(std::collections::BTreeSet::<String>::new());
    // Notes by what they are about (the text before the first `: `, e.g. `species A`),
    // each with the distinct texts the frames gave, and the timesteps that gave them.
    type Notes = std::collections::BTreeMap<
        String,
        std::collections::BTreeMap<String, std::collections::BTreeSet<u64>>,
    >;
    let notes = Mutex::new(Notes::new());
    let keep_notes = |timestep: u64, n: Vec<String>| {
        let mut notes = notes.lock().unwrap_or_else(|e| e.into_inner());
        for text in n {
            let about = note_key(&text);
            notes
                .entry(about)
                .or_default()
                .entry(text)
                .or_default()
                .insert(timestep);
        }
    };
    // A frame converted again with another particle count than before: a piece of a
    // `%` set gone or added, another run's file under the old name.
    let note_count_change = |job: &Job<'_>, f: &MdlodFile| {
        let before = f.particle_count();
        if job.particles != u64::MAX && job.particles != before {
            keep_notes(
                job.timestep,
                vec![format!(
                    "particle counts changed since the last run: timestep {} holds {} \
                     particles, {before} before (a piece of a `%` set missing or added, \
                     another run's file?)",
                    job.timestep, job.particles
                )],
            );
        }
    };
    let note_species = |f: &MdlodFile| {
        let mut seen = seen.lock().unwrap_or_else(|e| e.into_inner());
        seen.extend(f.metadata().species.iter().map(|s| s.name.clone()));
    };
    // The column names given apply to LAMMPS binary dumps only; what an existing output
    // was read with, the manifests tell.
    let columns_for = |job: &Job<'_>| {
        (job.format == InputFormat::LammpsBinary)
            .then(|| opts.read.columns.clone())
            .flatten()
    };
    let known_frames = records.all();
    let known = recorded_entries(&known_frames);
    let mut redone = Redone::default();
    // Outputs whose input changed, to be compared by their frames' bytes.
    let mut unsure = Vec::new();
    // Frames converted from other inputs still there, with those inputs: refused.
    let mut others: Vec<(Job<'_>, PathBuf)> = Vec::new();
    for mut job in mine.drain(..) {
        if let Some(dump) = job.dump {
            // (A header that cannot be read fails where the frame is converted.)
            match dump.frame_info(job.frame) {
                Ok(info) => job.particles = info.particles as u64,
                Err(_) => job.particles = u64::MAX,
            }
        }
        if job.particles == 0 {
            empty.push(EmptyFrame {
                input: job.input.to_path_buf(),
                frame: job.frame,
                timestep: job.own_timestep,
                number: job.timestep,
            });
            continue;
        }
        let out = out_dir.join(frame_file_name(job.timestep));
        // A link, pipe or device in a frame file's place is refused before any frame is
        // converted (it would be replaced, not written through).
        mdlod_format::files::check_replaceable_kind(&out).map_err(io(&out))?;
        let want = indexed_source(job.input, job.frame);
        let columns = columns_for(&job);
        let verdict = MdlodFile::open_sparse(&out).ok().map(|f| {
            let mut given = || match job.dump {
                Some(d) => d.given_radii(job.frame).ok(),
                None => job.given_radii.take(),
            };
            let recorded = known.get(&(
                frame_file_name(job.timestep),
                format!("{:016x}", f.header().section_table_checksum),
            ));
            // A frame file no manifest records (a run killed within a second of
            // finishing it, before it listed it) is converted again: the file alone
            // cannot say which renames, wrapping or columns it was read with.
            let Some(recorded) = recorded else {
                redone.unrecorded += 1;
                return Verdict::Redo;
            };
            let same_columns =
                job.format != InputFormat::LammpsBinary || recorded.columns == columns;
            // Renames change the file: a frame converted with others is converted again.
            // A record without them (converted without renames, or listed by a version
            // that recorded none): the file's own species tell, as a frame converted
            // without the renames asked for now still holds a species of an old name.
            let renames = &opts.convert.species_names;
            let same_names = match recorded.species_names.as_ref() {
                Some(names) => names == renames,
                None => renames.iter().all(|(old, new)| {
                    let species = &f.metadata().species;
                    species.iter().all(|s| &s.name != old) && species.iter().any(|s| &s.name == new)
                }),
            };
            // So does another choice of size column.
            let same_sizes = recorded.sizes == opts.read.sizes.record();
            // And another species column.
            let same_species_column =
                recorded.species_column.as_ref() == opts.read.species_column.as_ref();
            let same_wrap = recorded.wrap == opts.read.wrap;
            let own = f.metadata().source.as_ref();
            // The source as the manifest lists it: a frame kept by its bytes is listed
            // with the input's size and time then, so the next rerun need not read it.
            // (The same bytes: their checksum and length, wherever they lie now.)
            let same_bytes = |a: &Option<FrameBytes>, b: &Option<FrameBytes>| match (a, b) {
                (Some(a), Some(b)) => {
                    a.xxh3 == b.xxh3 && a.end.checked_sub(a.start) == b.end.checked_sub(b.start)
                }
                _ => false,
            };
            let listed = Some(&recorded.source)
                .filter(|l| own.is_some_and(|o| same_bytes(&o.bytes, &l.bytes)));
            let source = if own.is_some_and(|s| same_source(s, &want)) {
                None
            } else if let Some(l) = listed.filter(|l| same_source(l, &want)) {
                Some(Ok(l.clone()))
            } else {
                match own.and_then(|s| s.bytes.clone().filter(|_| same_name(s, &want))) {
                    Some(b) => Some(Err(b)),
                    None => {
                        let other =
                            other_input(recorded, job.input, job.own_timestep, &want, &run_inputs);
                        match (other, own.and_then(|s| s.bytes.clone())) {
                            // Under another name, the same bytes (a copy, a set joined
                            // into one file) are kept as a moved frame's are.
                            (Some(_), Some(b)) => Some(Err(b)),
                            (Some(old), None) => return Verdict::Other(old),
                            (None, _) => {
                                redone.source += 1;
                                note_count_change(&job, &f);
                                return Verdict::Redo;
                            }
                        }
                    }
                }
            };
            // The further attributes asked for, by name, in order.
            let same_attributes = same_further(&f.metadata().attributes, opts);
            let mut changed = SettingsChanged {
                columns: !same_columns,
                species_name: !same_names,
                size_column: !same_sizes,
                species_column: !same_species_column,
                wrap: !same_wrap,
                further_attributes: !same_attributes,
                ..Default::default()
            };
            // (Once another setting redoes the frame, its radii are not read from the
            // input again to learn whether they changed too: a species whose override
            // was left out counts as changed.)
            let other = changed != SettingsChanged::default();
            if let Some(c) = build_difference(
                &f,
                &opts.convert,
                job.attribute.as_deref(),
                recorded.radii.as_deref(),
                move || if other { None } else { given() },
            ) {
                changed |= c;
            }
            if changed != SettingsChanged::default() {
                redone.settings += 1;
                redone.changed |= changed;
                return Verdict::Redo;
            }
            match source {
                None => Verdict::Keep(f, None),
                Some(Ok(listed)) => Verdict::Keep(f, Some(listed)),
                Some(Err(bytes)) => Verdict::CheckBytes(
                    f,
                    bytes,
                    other_input(recorded, job.input, job.own_timestep, &want, &run_inputs),
                ),
            }
        });
        match verdict {
            Some(Verdict::Keep(f, listed)) => {
                note_species(&f);
                let mut entry = entry_of(
                    job.input,
                    &out,
                    &f,
                    job.timestep,
                    columns,
                    &opts.convert,
                    &opts.read,
                );
                if let Some(l) = listed {
                    entry.source = l;
                }
                done.push(entry);
            }
            Some(Verdict::CheckBytes(f, bytes, other)) => unsure.push((job, f, bytes, want, other)),
            Some(Verdict::Other(old)) => others.push((job, old)),
            Some(Verdict::Redo) | None => {
                if job.particles == u64::MAX {
                    job.particles = 0;
                }
                todo.push(job);
            }
        }
    }
    // Outputs of frames whose input changed since (a dump a simulation has appended
    // frames to since, a file touched) are kept when the frame's bytes are the ones
    // converted: read again and compared by checksum.
    let mut kept_unchanged = 0;
    if !unsure.is_empty() {
        let total = unsure.iter().fold(0u64, |t, u| {
            t.saturating_add(u.2.end.saturating_sub(u.2.start))
        });
        progress.stage(
            &format!(
                "checking {} frame{} of changed inputs",
                unsure.len(),
                if unsure.len() == 1 { "" } else { "s" }
            ),
            Some(total),
            "bytes",
        );
        for (mut job, f, bytes, want, other) in unsure {
            let dump = job.dump;
            // Where the frame lies now: the same bytes moved (a line inserted in an
            // earlier frame) are the same frame.
            let now = dump.and_then(|d| d.frame_bytes(job.frame)).filter(|r| {
                r.end.checked_sub(r.start) == bytes.end.checked_sub(bytes.start)
                    && want.size >= r.end
            });
            let unchanged = match now.clone() {
                Some(range) => {
                    // A text dump's unit style is written in its first frame only.
                    dump.and_then(|d| d.frame_info(job.frame).ok())
                        .map(|i| i.units)
                        == Some(f.metadata().units.clone())
                        && frame_checksum(job.input, dump, job.frame, range, progress)
                            .map_err(io(job.input))?
                            == bytes.xxh3
                }
                None => false,
            };
            let bytes = match now {
                Some(r) => FrameBytes {
                    start: r.start,
                    end: r.end,
                    ..bytes
                },
                None => bytes,
            };
            if unchanged {
                kept_unchanged += 1;
                note_species(&f);
                let mut entry = entry_of(
                    job.input,
                    &out_dir.join(frame_file_name(job.timestep)),
                    &f,
                    job.timestep,
                    columns_for(&job),
                    &opts.convert,
                    &opts.read,
                );
                entry.source = SourceInfo {
                    bytes: Some(bytes),
                    ..want
                };
                done.push(entry);
            } else if let Some(old) = other {
                others.push((job, old));
            } else {
                redone.source += 1;
                note_count_change(&job, &f);
                if job.particles == u64::MAX {
                    job.particles = 0;
                }
                todo.push(job);
            }
        }
        progress.finish_stage();
        done.sort_by_key(|e| e.timestep);
        todo.sort_by_key(|j| j.timestep);
    }
    others.sort_by_key(|(j, _)| j.timestep);
    if let Some((job, old)) = others.first() {
        let more = match others.len() - 1 {
            0 => String::new(),
            1 => ", and 1 more frame so".into(),
            n => format!(", and {n} more frames so"),
        };
        return Err(BatchError::OtherInputs {
            dir: out_dir.to_path_buf(),
            frame: format!(
                "{} holds timestep {} of {}, which is still there, and this run would \
                 replace it with frame {} of {}{more}",
                frame_file_name(job.timestep),
                job.timestep,
                old.display(),
                job.frame,
                job.input.display()
            ),
            renumbered: if job.own_timestep.is_none() {
                " (frames that give no timestep are numbered by their place among the \
                 inputs: an input left out or added numbers those after it anew)"
            } else {
                ""
            },
        });
    }
    // The last frame of a text dump whose last line has no line end may be cut inside a
    // number: left for the rerun.
    let (cut, rest): (Vec<Job<'_>>, Vec<Job<'_>>) = todo
        .into_iter()
        .partition(|j| j.last_of_input && j.dump.is_some_and(DumpFile::ends_mid_line));
    todo = rest;
    // Not the newest input: a file of a set that no run is writing any more.
    if let Some(job) = cut.iter().find(|j| !j.newest) {
        return Err(BatchError::CutShortBeforeNewest {
            input: job.input.to_path_buf(),
            newest: newest_text.clone(),
            reason: "its last line has no line end: the run writing it may have stopped \
                     inside a number (if the file is complete, add a line end to it)"
                .into(),
        });
    }
    let ends_mid_line: Vec<IncompleteFrame> = cut
        .into_iter()
        .map(|job| {
            // (Of a `%` set, the piece that ends so.)
            let file = job
                .dump
                .and_then(DumpFile::mid_line_file)
                .filter(|f| *f != job.input)
                .map_or("its".into(), |f| format!("{}'s", f.display()));
            IncompleteFrame {
                input: job.input.to_path_buf(),
                frame: job.frame,
                timestep: job.own_timestep,
                reason: format!(
                    "{file} last line has no line end: the run writing it may have stopped \
                     inside a number (if the file is complete, add a line end to it)"
                ),
                empty_file: false,
            }
        })
        .collect();
    let skipped = done.len();
    let kept_gone: Vec<u64> = gone.iter().map(|e| e.timestep).collect();
    seen.lock()
        .unwrap_or_else(|e| e.into_inner())
        .extend(gone_species);
    // A whole run lists them; a shard keeps them apart, for the merge to list once.
    let (gone, listed_gone) = match opts.shard {
        None => {
            done.extend(gone);
            (Vec::new(), kept_gone.len())
        }
        Some(_) => (gone, 0),
    };
    let manifest = std::sync::Arc::new(Mutex::new(Manifest {
        mdlod_dataset: MANIFEST_VERSION,
        shard: opts.shard.map(|(i, n)| [i, n]),
        expected_frames: Some((frames_in_shard - empty.len() + listed_gone) as u64),
        input_frames: Some(input_frames),
        frames: done,
        gone,
        unlisted,
        failed: Vec::new(),
        empty: empty.iter().map(EmptyEntry::from).collect(),
        duplicates: match opts.duplicates {
            Duplicates::Error => None,
            Duplicates::First => Some("first".into()),
            Duplicates::Last => Some("last".into()),
        },
    }));
    // Unset again when the batch returns, however it returns.
    struct Unset<'a>(Option<&'a ManifestHandle>);
    impl Drop for Unset<'_> {
        fn drop(&mut self) {
            if let Some(h) = self.0 {
                h.set(None);
            }
        }
    }
    let _unset = Unset(opts.handle.as_ref());
    if let Some(h) = &opts.handle {
        let at_start = manifest
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .frames
            .len();
        h.set(Some((manifest_path.clone(), manifest.clone(), at_start)));
    }
    let save = |m: &mut Manifest| -> Result<(), BatchError> {
        m.frames.sort_by_key(|f| f.timestep);
        write_json(&manifest_path, m)
    };
    // The manifest as it was before this run (its bytes; `Err(NotFound)`: none), put
    // back where the run fails before any output was written: an error every frame
    // meets (an option the inputs need, such as `--columns` for an old-revision binary
    // dump) would otherwise leave a manifest without the frames it is to convert again,
    // and the corrected rerun, finding no record of how they were read, would convert
    // every one again for "other settings".
    // Frames to write into a directory that takes none (an archive made read-only) are
    // refused before any is built.
    if !todo.is_empty() {
        mdlod_format::writer::output_file_builder()
            .prefix(&mdlod_format::writer::temp_prefix("dataset"))
            .suffix(".tmp")
            .tempfile_in(out_dir)
            .map_err(mdlod_format::files::temp_error)
            .map_err(|e| BatchError::Io {
                path: out_dir.to_path_buf(),
                source: std::io::Error::new(
                    e.kind(),
                    format!(
                        "{e}: {} frame{} to convert cannot be written there",
                        todo.len(),
                        if todo.len() == 1 { "" } else { "s" }
                    ),
                ),
            })?;
        // So are frame files made read-only that are to be replaced (a kept frame may
        // stay so): refused before any frame is built, not when the first reaches them.
        for job in &todo {
            let out = out_dir.join(frame_file_name(job.timestep));
            mdlod_format::files::check_replaceable(&out).map_err(io(&out))?;
        }
    }
    let previous = read_manifest_bytes(&manifest_path).map_err(|e| e.kind());
    // (Best effort: without them a later run converts such frames again; a directory
    // that takes no file fails the manifest's own write, which says so.)
    let _ = keep_side_records(
        out_dir,
        opts.shard,
        &known_frames,
        &manifest.lock().unwrap_or_else(|e| e.into_inner()),
    );
    save(&mut manifest.lock().unwrap_or_else(|e| e.into_inner()))?;
    // A shard that converts anything outdates the merged manifest of an earlier merge
    // (its checksums, its frames' sources): moved aside before the first frame changes,
    // so that no `dataset.json` lists what is not there; `--merge` writes it again. Its
    // records stay readable there ([`PREVIOUS_MANIFEST`]) for frames whose dumps are
    // deleted before another shard runs.
    let mut removed_merged = None;
    if opts.shard.is_some() && !todo.is_empty() {
        let merged = out_dir.join(MANIFEST);
        // Shards starting together race for it: gone already is as good.
        match std::fs::rename(&merged, out_dir.join(PREVIOUS_MANIFEST)) {
            Ok(()) => removed_merged = Some(merged),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => return Err(io(&merged)(e)),
        }
    }
    // When the manifest was last written: workers rewrite it at most every
    // `MANIFEST_INTERVAL`, and once more at the end.
    let saved_at = Mutex::new(std::time::Instant::now());

    // As many conversions at once as memory and threads allow.
    let threads = rayon::current_num_threads().max(1);
    // What one frame's conversion needs, which each frame's share of the limit must
    // hold (the conversion refuses less): in memory, about `BYTES_PER_PARTICLE` each; a
    // frame above the chunk size is built a chunk at a time, and one chunk's build needs
    // `chunk_memory`, whose fixed part dominates small chunks (dividing the limit by the
    // particles alone, a batch of such frames ran too many at once, and each failed).
    let chunk_points = opts.convert.chunks.chunk_points as u64;
    let need = |particles: u64| {
        let in_memory = particles
            .min(chunk_points)
            .saturating_mul(BYTES_PER_PARTICLE);
        if particles > chunk_points {
            let chunk = usize::try_from(chunk_points).unwrap_or(usize::MAX);
            in_memory.max(crate::chunked::chunk_memory_with(
                chunk,
                opts.read.extra_attributes.len(),
            ))
        } else {
            in_memory
        }
    };
    let largest = todo
        .iter()
        .map(|j| need(j.particles))
        .max()
        .unwrap_or(1)
        .max(1);
    // At least one: a frame that does not fit the whole limit fails, naming it.
    let by_memory = (opts.memory_limit / largest).max(1);
    let by_memory = usize::try_from(by_memory).unwrap_or(usize::MAX);
    let jobs = by_memory
        .min(threads)
        .min(opts.max_jobs.unwrap_or(usize::MAX))
        .min(todo.len())
        .max(1);
    let total_particles = todo.iter().fold(0u64, |t, j| t.saturating_add(j.particles));
    let mut convert = opts.convert.clone();
    // A species may appear in some frames of a trajectory only.
    convert.radii_may_be_absent = true;
    convert.species_column = opts.read.species_column.clone();
    convert.chunks.memory_limit = opts.memory_limit / jobs as u64;
    let convert = &convert;
    progress.stage(
        &format!(
            "converting {} frame{}, {jobs} at a time",
            todo.len(),
            if todo.len() == 1 { "" } else { "s" }
        ),
        Some(total_particles),
        "particles",
    );
    let queue = Mutex::new(todo.iter());
    let failed = AtomicBool::new(false);
    let first_error: Mutex<Option<BatchError>> = Mutex::new(None);
    // Dumps listed from the frame index whose frames could not be read: dropped from it,
    // so that the next run scans them (an index at fault, however unlikely, mends).
    let unindexed: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());
    let incomplete: Mutex<Vec<IncompleteFrame>> = Mutex::new(ends_mid_line);
    // (The frames no shard could list, an input holding no dump, are shard 0's to
    // report: each shard failing on them double-counted them, and failed every task of
    // an array, so that a merge run `afterok` never ran.)
    if opts.shard.is_some_and(|(i, _)| i != 0) {
        unlisted_failures.clear();
    }
    let unlisted = unlisted_failures.len();
    let failed_frames: Mutex<Vec<FailedFrame>> = Mutex::new(unlisted_failures);
    let converted = std::sync::atomic::AtomicUsize::new(0);
    // Whether any conversion has written its output (renamed into place).
    let wrote = AtomicBool::new(false);
    let quiet = crate::progress::NoProgress;
    // The calling thread is one of the workers (one job: the only one), so that a
    // single conversion allocates on the threads a lone `convert` would: each thread
    // more keeps freed memory in an arena of its own (BENCHMARKS.md, "The memory limit
    // at small limits").
    let worker = || {
        // This worker's last opened gzip input (frames of one file come in
        // timestep order, so consecutive jobs often share it).
        let mut opened: Option<(PathBuf, crate::convert::BoundedDump)> = None;
        loop {
            if failed.load(Ordering::Relaxed) {
                return;
            }
            let Some(job) = queue.lock().unwrap_or_else(|e| e.into_inner()).next() else {
                return;
            };
            let result = (|| -> Result<FrameEntry, BatchError> {
                let out = out_dir.join(frame_file_name(job.timestep));
                // Its bytes first: they are read into the page cache for the conversion.
                let bytes = frame_bytes(job.input, job.dump, job.frame)?;
                let source = SourceInfo {
                    bytes,
                    ..indexed_source(job.input, job.frame)
                };
                let (dump, bounded) = match job.dump {
                    Some(d) => (d, None),
                    None => {
                        let b = match &mut opened {
                            Some((p, b)) if p == job.input => &*b,
                            slot => {
                                // Release the previous input before opening this.
                                *slot = None;
                                let b = crate::convert::open_bounded(
                                    job.input,
                                    &convert.chunks,
                                    &out,
                                    &quiet,
                                )?;
                                &slot.insert((job.input.to_path_buf(), b)).1
                            }
                        };
                        (&b.dump, Some(b))
                    }
                };
                let in_context = |e: BatchError| match (bounded, e) {
                    (Some(b), BatchError::Convert(c)) => {
                        BatchError::Convert(b.context(job.input, c))
                    }
                    (Some(b), BatchError::Read(r)) => {
                        BatchError::Convert(b.context(job.input, r.into()))
                    }
                    (_, e) => e,
                };
                (|| -> Result<FrameEntry, BatchError> {
                    keep_notes(job.timestep, dump.frame_notes(job.frame, &opts.read));
                    let streamed = if job.particles as usize > convert.chunks.chunk_points {
                        let info = dump.frame_info(job.frame)?;
                        let problem = crate::convert::chunked_magnitude_problem(
                            dump,
                            &opts.read,
                            job.particles,
                            convert.chunks.chunk_points,
                        );
                        if let Some(problem) = problem {
                            return Err(ConvertError::Attributes {
                                place: crate::convert::FramePlace {
                                    path: job.input.display().to_string(),
                                    frame: Some(job.frame as u64),
                                    timestep: job.own_timestep,
                                },
                                problem,
                            }
                            .into());
                        }
                        crate::convert::window_source(dump, job.frame, &opts.read, &info)
                            .map(|s| (s, info))
                    } else {
                        None
                    };
                    if let Some((src, info)) = streamed {
                        // Out of core: the frame is read a window at a time.
                        let mut header = crate::convert::header_of(&info);
                        if header.units.is_none() {
                            header.units.clone_from(&job.carried_units);
                        }
                        let report = crate::chunked::convert_chunked(
                            src.as_ref(),
                            crate::convert::base_metadata(&header, Some(source), convert),
                            &out,
                            convert,
                            &quiet,
                        )?;
                        wrote.store(true, Ordering::Relaxed);
                        keep_notes(job.timestep, report.notes);
                    } else {
                        // Refused before the frame is read, not after.
                        if let Ok(particles) = usize::try_from(job.particles) {
                            crate::convert::check_in_memory(
                                particles,
                                opts.read.extra_attributes.len(),
                                convert,
                                || crate::convert::FramePlace {
                                    path: job.input.display().to_string(),
                                    frame: Some(job.frame as u64),
                                    timestep: job.own_timestep,
                                },
                            )?;
                        }
                        let mut frame = dump.read_frame(job.frame, &opts.read, &quiet)?;
                        if frame.units.is_none() {
                            frame.units.clone_from(&job.carried_units);
                        }
                        let further =
                            crate::convert::read_extra_attributes(dump, job.frame, &opts.read)?;
                        let report = crate::convert::convert_frame_with(
                            &frame,
                            &further,
                            Some(source),
                            &out,
                            convert,
                            &quiet,
                        )?;
                        wrote.store(true, Ordering::Relaxed);
                        keep_notes(job.timestep, report.notes);
                    }
                    let f = MdlodFile::open(&out).map_err(ConvertError::from)?;
                    note_species(&f);
                    Ok(entry_of(
                        job.input,
                        &out,
                        &f,
                        job.timestep,
                        columns_for(job),
                        convert,
                        &opts.read,
                    ))
                })()
                .map_err(in_context)
            })();
            let recorded = result.and_then(|entry| {
                let mut m = manifest.lock().unwrap_or_else(|e| e.into_inner());
                m.frames.push(entry);
                let mut at = saved_at.lock().unwrap_or_else(|e| e.into_inner());
                if at.elapsed() < opts.manifest_interval.unwrap_or(MANIFEST_INTERVAL) {
                    return Ok(());
                }
                save(&mut m)?;
                *at = std::time::Instant::now();
                Ok(())
            });
            match recorded {
                Ok(()) => {
                    converted.fetch_add(1, Ordering::Relaxed);
                    progress.advance(job.particles);
                }
                // The last frame of a dump a running simulation is writing: left
                // for a rerun, not a failure of the others.
                Err(e) if job.may_be_cut() && e.cut_short() => {
                    incomplete
                        .lock()
                        .unwrap_or_else(|e| e.into_inner())
                        .push(IncompleteFrame {
                            input: job.input.to_path_buf(),
                            frame: job.frame,
                            timestep: job.own_timestep,
                            reason: e.to_string(),
                            empty_file: false,
                        });
                    progress.advance(job.particles);
                }
                Err(e) => {
                    if e.frames_own() {
                        if let Some(d) = job.dump.filter(|d| d.listed_from_index()) {
                            unindexed
                                .lock()
                                .unwrap_or_else(|e| e.into_inner())
                                .extend(d.indexed_files());
                        }
                    }
                    // An older file of a set cut short: damaged, not being written.
                    let e = if job.last_of_input && e.cut_short() {
                        BatchError::CutShortBeforeNewest {
                            input: job.input.to_path_buf(),
                            newest: newest_text.clone(),
                            reason: e.to_string(),
                        }
                    } else {
                        e
                    };
                    if opts.keep_going && e.frames_own() {
                        failed_frames
                            .lock()
                            .unwrap_or_else(|e| e.into_inner())
                            .push(FailedFrame {
                                input: job.input.to_path_buf(),
                                frame: job.frame,
                                timestep: job.own_timestep,
                                listed_timestep: Some(job.timestep),
                                reason: e.to_string(),
                            });
                        progress.advance(job.particles);
                        continue;
                    }
                    failed.store(true, Ordering::Relaxed);
                    first_error
                        .lock()
                        .unwrap_or_else(|e| e.into_inner())
                        .get_or_insert(e);
                    return;
                }
            }
        }
    };
    std::thread::scope(|s| {
        for _ in 1..jobs {
            s.spawn(worker);
        }
        worker();
    });
    progress.finish_stage();
    let unindexed = unindexed.into_inner().unwrap_or_else(|e| e.into_inner());
    if !unindexed.is_empty() {
        unindexed.iter().for_each(|p| index_cache.forget(p));
        // (Only a cache: the error said is the frame's.)
        let _ = index_cache.save();
    }
    let mut incomplete = incomplete.into_inner().unwrap_or_else(|e| e.into_inner());
    incomplete.sort_by(|a, b| (&a.input, a.frame).cmp(&(&b.input, b.frame)));
    let mut failed_frames = failed_frames
        .into_inner()
        .unwrap_or_else(|e| e.into_inner());
    failed_frames.sort_by(|a, b| (&a.input, a.frame).cmp(&(&b.input, b.frame)));
    // Every frame converted, also when another failed (and no new one started after);
    // frames cut short are not expected of this run.
    let last_save = {
        let mut m = manifest.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(e) = m.expected_frames.as_mut() {
            // (Frames failed before they were listed were never expected.)
            *e = e.saturating_sub((incomplete.len() + failed_frames.len() - unlisted) as u64);
        }
        m.failed = failed_frames
            .iter()
            .map(|f| FailedEntry {
                timestep: f.listed_timestep,
                input: f.input.display().to_string(),
                frame: f.frame as u64,
                reason: f.reason.clone(),
            })
            .collect();
        save(&mut m)
    };
    // (An empty newest file has no frames to expect.)
    incomplete.extend(empty_inputs);
    if let Some(e) = first_error.into_inner().unwrap_or_else(|e| e.into_inner()) {
        if !wrote.load(Ordering::Relaxed) {
            // No output changed: the earlier manifest is as true as it was. (Where it
            // cannot be put back, the one written stands, also true.)
            if let Some(h) = &opts.handle {
                h.set(None);
            }
            let _ = match previous {
                Ok(bytes) => write_bytes(&manifest_path, &bytes),
                Err(std::io::ErrorKind::NotFound) => {
                    std::fs::remove_file(&manifest_path).map_err(io(&manifest_path))
                }
                Err(_) => Ok(()),
            };
        }
        return Err(BatchError::Incomplete {
            converted: converted.load(Ordering::Relaxed),
            todo: todo.len(),
            manifest_unsaved: last_save.err().map(|e| e.to_string()),
            source: Box::new(e),
        });
    }
    last_save?;
    // A whole run's manifest lists every frame: shard manifests of an earlier sharding
    // are stale, and merging them would overwrite it with what they knew.
    let mut removed_shard_manifests = Vec::new();
    if opts.shard.is_none() {
        let names = std::fs::read_dir(out_dir)
            .map_err(io(out_dir))?
            .flatten()
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .filter(|n| is_shard_manifest(n));
        for name in names {
            let path = out_dir.join(&name);
            match std::fs::remove_file(&path) {
                Ok(()) => removed_shard_manifests.push(name),
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
                Err(e) => return Err(io(&path)(e)),
            }
        }
        removed_shard_manifests.sort();
        // And the merged manifest a shard moved aside: this one supersedes its records.
        match std::fs::remove_file(out_dir.join(PREVIOUS_MANIFEST)) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                return Err(io(&out_dir.join(PREVIOUS_MANIFEST))(e))
            }
            _ => {}
        }
    }
    // A species may appear in some frames only, but a radius override that names none
    // of any frame's is a misspelt name. (A shard sees only its own frames; a column of
    // categories need not hold every value a script names, say all five structure
    // types.)
    let seen = seen.into_inner().unwrap_or_else(|e| e.into_inner());
    let whole = opts.shard.is_none_or(|(_, n)| n == 1);
    let unused = |e| BatchError::NamesUnused {
        converted: converted.load(Ordering::Relaxed),
        skipped,
        source: Box::new(e),
    };
    if whole && !seen.is_empty() && opts.read.species_column.is_none() {
        let any = crate::species::ANY_SPECIES;
        if let Some((name, radius)) = opts
            .convert
            .radii
            .iter()
            .find(|(n, _)| !seen.contains(n) && n != any)
        {
            return Err(unused(BatchError::Convert(ConvertError::Species(
                Box::new(crate::species::UnknownSpecies {
                    name: name.clone(),
                    radius: *radius,
                    known: seen.into_iter().collect(),
                    input: Some(describe_inputs(inputs)),
                    // How the inputs name species, where they all agree.
                    naming: namings
                        .first()
                        .filter(|n| namings.iter().all(|m| m == *n))
                        .cloned(),
                    renamed: opts.convert.species_names.clone(),
                }),
            ))));
        }
        // The same for a rename: its new name is in no file (unless another species
        // had it already, which this cannot tell apart).
        if let Some((from, to)) = opts
            .convert
            .species_names
            .iter()
            .find(|(_, to)| !seen.contains(to))
        {
            return Err(unused(BatchError::Convert(ConvertError::UnknownRename(
                Box::new(crate::species::UnknownRename {
                    from: from.clone(),
                    to: to.clone(),
                    known: seen.into_iter().collect(),
                    input: Some(describe_inputs(inputs)),
                }),
            ))));
        }
    }
    // With a column of categories, names for values no frame holds are said, not refused.
    let absent = match (&opts.read.species_column, whole && !seen.is_empty()) {
        (Some(column), true) => crate::species::category_notes(
            column,
            &opts.convert.species_names,
            &opts.convert.radii,
            &seen.iter().map(String::as_str).collect::<Vec<_>>(),
            false,
        ),
        _ => Vec::new(),
    };
    let converted_frames = converted.load(Ordering::Relaxed);
    Ok(BatchReport {
        index,
        removed_merged,
        removed_shard_manifests,
        strays,
        kept_gone,
        gone_other,
        vanished,
        duplicates,
        incomplete,
        failed: failed_frames,
        redone,
        kept_unchanged,
        frames_total,
        frames_in_shard,
        converted: converted.into_inner(),
        skipped,
        empty,
        notes: notes
            .into_inner()
            .unwrap_or_else(|e| e.into_inner())
            .into_values()
            .map(|texts| {
                // The text of the earliest frame.
                let (first, first_steps) = texts
                    .iter()
                    .min_by_key(|(_, steps)| steps.first().copied())
                    .map(|(t, steps)| (t.clone(), steps.clone()))
                    .unwrap_or_default();
                let about = first.split(": ").next().unwrap_or_default();
                let steps: std::collections::BTreeSet<u64> =
                    texts.values().flatten().copied().collect();
                // Which frames, when not every one converted (and the note is about
                // frames, not about a whole file).
                let which = if steps.len() == converted_frames || about == crate::readers::GZIP_CUT
                {
                    String::new()
                } else {
                    format!(" ({})", timesteps_text(&steps))
                };
                match (texts.len(), first_steps.first()) {
                    (1, _) | (_, None) => format!("{first}{which}"),
                    // Frames of a trajectory differ in their numbers: one line, not one
                    // per frame.
                    (_, Some(t)) => format!(
                        "{first} (the figures are timestep {t}'s; {} frame{}{which} have this \
                         note, with their own)",
                        steps.len(),
                        if steps.len() == 1 { "" } else { "s" }
                    ),
                }
            })
            .chain(absent)
            .chain(input_notes)
            .collect(),
        jobs,
        manifest: manifest_path,
    })
}

/// What a note says, its figures aside, to say a note once where frames differ in its
/// figures alone: its first two words as they are (`species 1`, `attribute c_ke`: the
/// subject, which may be a number), then the whole text with each number (`12`, `-3.5`,
/// `2.5e-4`) as `#` ([`note_kind`]).
fn note_key(text: &str) -> String {
    let subject: Vec<&str> = text.split_whitespace().take(2).collect();
    format!("{}\u{0}{}", subject.join(" "), note_kind(text))
}

/// `text` with each number as `#` (see [`note_key`]).
fn note_kind(about: &str) -> String {
    let mut out = String::with_capacity(about.len());
    let mut chars = about.chars().peekable();
    while let Some(c) = chars.next() {
        let starts_number = c.is_ascii_digit()
            || (matches!(c, '-' | '+' | '.') && chars.peek().is_some_and(char::is_ascii_digit));
        if !starts_number {
            out.push(c);
            continue;
        }
        while chars
            .peek()
            .is_some_and(|&d| d.is_ascii_digit() || matches!(d, '.' | 'e' | 'E' | '-' | '+'))
        {
            chars.next();
        }
        out.push('#');
    }
    out
}

/// `timestep 5` or `timesteps 0, 100, 200 and 7 more`.
pub fn timesteps_text(steps: &std::collections::BTreeSet<u64>) -> String {
    let shown: Vec<String> = steps.iter().take(3).map(u64::to_string).collect();
    match steps.len() {
        1 => format!("timestep {}", shown[0]),
        n if n <= 3 => format!("timesteps {}", shown.join(", ")),
        n => format!("timesteps {} and {} more", shown.join(", "), n - 3),
    }
}

/// Joins the shard manifests of `out_dir` into `dataset.json`: every shard `0..N` must be
/// present, and every listed file must exist.
pub fn merge(out_dir: &Path) -> Result<Manifest, BatchError> {
    // Not while shards (or a whole run) still write the directory: they hold its lock,
    // and a merge now would join manifests not yet complete ([`BatchError::Busy`]).
    let _locks = match shard_manifests(out_dir)?.is_empty() {
        true => Vec::new(),
        false => lock_batch(out_dir, None)?,
    };
    let merged = merged_manifest(out_dir)?;
    write_json(&out_dir.join(MANIFEST), &merged)?;
    // The merged manifest a shard moved aside is superseded (its records too).
    let previous = out_dir.join(PREVIOUS_MANIFEST);
    match std::fs::remove_file(&previous) {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => return Err(io(&previous)(e)),
        _ => {}
    }
    Ok(merged)
}

/// The shard manifests of `out_dir`: shard, count and path, in no order.
fn shard_manifests(out_dir: &Path) -> Result<Vec<(u32, u32, PathBuf)>, BatchError> {
    let mut shards: Vec<(u32, u32, PathBuf)> = Vec::new();
    let entries = std::fs::read_dir(out_dir).map_err(|e| match e.kind() {
        std::io::ErrorKind::NotFound => BatchError::Manifest {
            path: out_dir.to_path_buf(),
            message: "no such directory: --merge takes the output directory the shards \
                      wrote their manifests to (the -o of `mdlod batch --shard I/N`)"
                .into(),
        },
        _ => io(out_dir)(e),
    })?;
    for e in entries.flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        if let Some((i, n)) = shard_of(&name) {
            shards.push((i, n, e.path()));
        }
    }
    Ok(shards)
}

/// The manifest [`merge`] writes for `out_dir`, with every check it makes (shards
/// complete, the same settings and inputs, no timestep twice), written nowhere: what
/// `info` asks of shards before it says a merge joins them.
pub fn merged_manifest(out_dir: &Path) -> Result<Manifest, BatchError> {
    let mut shards = shard_manifests(out_dir)?;
    let manifest_err = |path: &Path, message: String| BatchError::Manifest {
        path: path.to_path_buf(),
        message,
    };
    if shards.is_empty() {
        return Err(manifest_err(
            out_dir,
            "no shard manifests (dataset.shard-I-of-N.json) to merge".into(),
        ));
    }
    shards.sort();
    let named: Vec<(u32, u32, String)> = shards
        .iter()
        .map(|(i, n, p)| (*i, *n, file_name_of(p)))
        .collect();
    if let Some(message) = different_shardings(&named) {
        return Err(manifest_err(out_dir, message));
    }
    let n = shards[0].1;
    let present: Vec<u32> = shards.iter().map(|s| s.0).collect();
    let missing: Vec<String> = (0..n)
        .filter(|i| !present.contains(i))
        .map(|i| i.to_string())
        .collect();
    if !missing.is_empty() {
        let (s, has) = match missing.len() {
            1 => ("", "has"),
            _ => ("s", "have"),
        };
        return Err(manifest_err(
            out_dir,
            format!(
                "shard{s} {} of {n} {has} no manifest yet (the manifests of shard{} {} are \
                 there): run or rerun {} before merging",
                missing.join(", "),
                if present.len() == 1 { "" } else { "s" },
                present
                    .iter()
                    .map(u32::to_string)
                    .collect::<Vec<_>>()
                    .join(", "),
                if missing.len() == 1 { "it" } else { "them" }
            ),
        ));
    }
    let mut manifests = Vec::with_capacity(shards.len());
    for (i, n, path) in &shards {
        let text = read_manifest_bytes(path).map_err(io(path))?;
        let m = parse_manifest(path, &text, "shard")?;
        if let Some(problem) = shard_field_problem(Some([*i, *n]), m.shard) {
            return Err(manifest_err(path, problem));
        }
        manifests.push((path, m));
    }
    // Before the frames: shards over different lists of frames have each converted
    // frames of their own list, which no merge can join (checked where the manifests
    // record their lists).
    let lists: Vec<(String, Option<InputFrames>)> = manifests
        .iter()
        .map(|(p, m)| (file_name_of(p), m.input_frames.clone()))
        .collect();
    if let Some(message) = different_input_lists(&lists) {
        return Err(manifest_err(out_dir, message));
    }
    let input_frames = match lists.first() {
        Some((_, Some(l))) if lists.iter().all(|(_, x)| x.is_some()) => Some(l.clone()),
        _ => None,
    };
    let mut frames = Vec::new();
    let mut failed: Vec<FailedEntry> = Vec::new();
    let mut empty: Vec<EmptyEntry> = Vec::new();
    let mut expected_total = Some(0u64);
    let mut settings = MergeSettings::default();
    let mut choices: Vec<(String, Option<String>)> = Vec::new();
    // The frames of deleted dumps every shard keeps, and the records of those kept
    // unlisted.
    let (mut gone, mut unlisted): (Vec<(PathBuf, FrameEntry)>, Vec<FrameEntry>) =
        (Vec::new(), Vec::new());
    for (path, m) in manifests {
        let path = path.as_path();
        for f in &m.frames {
            if !out_dir.join(&f.file).is_file() {
                return Err(manifest_err(
                    path,
                    format!("lists {} but the file is missing", f.file),
                ));
            }
            settings
                .check(out_dir, path, f)
                .map_err(|message| manifest_err(out_dir, message))?;
        }
        if let Some(expected) = m.expected_frames {
            let listed = m.frames.len() as u64;
            if listed < expected {
                return Err(manifest_err(
                    path,
                    format!(
                        "lists {listed} of the shard's {expected} frames: the shard has not \
                         finished (it is still running, failed or was killed; rerun it, and \
                         it converts only what is missing)"
                    ),
                ));
            }
        }
        choices.push((path.display().to_string(), m.duplicates.clone()));
        if let Some(message) = different_duplicate_choices(&choices) {
            return Err(manifest_err(
                out_dir,
                format!("{message}; rerun the shards with one choice, then merge"),
            ));
        }
        // Known only when every shard says (manifests of older runs do not).
        expected_total = expected_total
            .zip(m.expected_frames)
            .map(|(t, e)| t.saturating_add(e));
        frames.extend(m.frames);
        failed.extend(m.failed);
        empty.extend(m.empty);
        gone.extend(m.gone.into_iter().map(|f| (path.to_path_buf(), f)));
        unlisted.extend(m.unlisted);
    }
    let duplicates = choices.into_iter().next().and_then(|(_, d)| d);
    // The frames of deleted dumps ([`Manifest::gone`]): listed once, and expected, where
    // no shard lists the timestep and the file is still there.
    let own: std::collections::HashSet<u64> = frames.iter().map(|f| f.timestep).collect();
    gone.sort_by(|a, b| (a.1.timestep, &a.1.file).cmp(&(b.1.timestep, &b.1.file)));
    gone.dedup_by(|a, b| a.1.timestep == b.1.timestep && a.1.checksum == b.1.checksum);
    let mut extra = 0u64;
    for (path, f) in gone {
        if own.contains(&f.timestep) || !out_dir.join(&f.file).is_file() {
            continue;
        }
        settings
            .check(out_dir, &path, &f)
            .map_err(|message| manifest_err(out_dir, message))?;
        frames.push(f);
        extra += 1;
    }
    expected_total = expected_total.map(|t| t.saturating_add(extra));
    frames.sort_by_key(|f| f.timestep);
    let listed: std::collections::HashSet<u64> = frames.iter().map(|f| f.timestep).collect();
    unlisted.retain(|f| !listed.contains(&f.timestep));
    unlisted.sort_by(|a, b| (a.timestep, &a.checksum).cmp(&(b.timestep, &b.checksum)));
    unlisted.dedup_by(|a, b| a.timestep == b.timestep && a.checksum == b.checksum);
    failed.sort_by(|a, b| (&a.input, a.frame, a.timestep).cmp(&(&b.input, b.frame, b.timestep)));
    failed.dedup_by(|a, b| a.input == b.input && a.frame == b.frame);
    failed.sort_by_key(|f| f.timestep);
    if let Some(w) = frames.windows(2).find(|w| w[0].timestep == w[1].timestep) {
        return Err(manifest_err(
            out_dir,
            format!("timestep {} is listed by two shards", w[0].timestep),
        ));
    }
    let merged = Manifest {
        mdlod_dataset: MANIFEST_VERSION,
        shard: None,
        expected_frames: expected_total,
        input_frames,
        frames,
        gone: Vec::new(),
        unlisted,
        failed,
        empty: {
            empty.sort_by_key(|e| e.timestep);
            empty.dedup();
            empty
        },
        duplicates,
    };
    Ok(merged)
}

/// Where shard manifests `(name, --duplicate-timesteps choice)` chose differently among
/// frames of one timestep (merged, a restart's frames would mix with the abandoned
/// run's), the message naming two of them.
fn different_duplicate_choices(choices: &[(String, Option<String>)]) -> Option<String> {
    let (first, d) = choices.first()?;
    let (other, e) = choices.iter().find(|(_, e)| e != d)?;
    let name = |d: &Option<String>| d.clone().unwrap_or_else(|| "error (the default)".into());
    Some(format!(
        "the shards chose differently among frames of one timestep: {first} with \
         --duplicate-timesteps {}, {other} with {}",
        name(d),
        name(e)
    ))
}

/// Where shard manifests `(I, N, file name)` are of different shard counts N, the
/// message naming them and what to do. The sharding with the most manifests is taken
/// for the array's, the others for strays: a task resubmitted alone (`sbatch --array=2`)
/// finds SLURM_ARRAY_TASK_COUNT 1 and runs as shard 0 of 1.
fn different_shardings(shards: &[(u32, u32, String)]) -> Option<String> {
    let mut by_count: std::collections::BTreeMap<u32, Vec<(u32, &str)>> =
        std::collections::BTreeMap::new();
    for (i, n, name) in shards {
        by_count.entry(*n).or_default().push((*i, name));
    }
    if by_count.len() < 2 {
        return None;
    }
    let (&n, main) = by_count.iter().max_by_key(|(n, v)| (v.len(), **n))?;
    let strays: Vec<&str> = by_count
        .iter()
        .filter(|(m, _)| **m != n)
        .flat_map(|(_, v)| v.iter().map(|(_, name)| *name))
        .collect();
    let missing: Vec<u32> = (0..n)
        .filter(|i| !main.iter().any(|(j, _)| j == i))
        .collect();
    let listed = |names: &[&str]| match names {
        [] => String::new(),
        [one] => (*one).to_string(),
        [first @ .., last] => format!("{} and {last}", first.join(", ")),
    };
    const SHOWN: usize = 3;
    let main_names: Vec<&str> = main.iter().map(|(_, name)| *name).take(SHOWN).collect();
    let rerun = match missing.as_slice() {
        [] => "rerun the stray task with its place in the whole array".to_string(),
        [i] => format!("rerun the task with --shard {i}/{n}"),
        more if more.len() <= SHOWN => format!(
            "rerun the tasks with --shard {}",
            more.iter()
                .map(|i| format!("{i}/{n}"))
                .collect::<Vec<_>>()
                .join(", ")
        ),
        more => format!("rerun the {} missing tasks with --shard I/{n}", more.len()),
    };
    // A stray sharding of one task is most likely a failed task resubmitted alone.
    let why = if by_count.keys().any(|&m| m == 1 && m != n) {
        "A failed task resubmitted alone (sbatch --array=2) runs as shard 0 of 1, as \
         SLURM_ARRAY_TASK_COUNT is 1 then: "
    } else {
        "Runs of another array size wrote the others: "
    };
    Some(format!(
        "shard manifests of different shardings: {} {} of {n} shards, but {} {} of {}. \
         {why}{rerun} (or resubmit it with the array's whole range; it converts only what \
         is missing), then delete {} and merge",
        listed(&main_names),
        if main.len() > SHOWN {
            format!("(and {} more) are", main.len() - SHOWN)
        } else if main.len() == 1 {
            "is".to_string()
        } else {
            "are".to_string()
        },
        listed(&strays),
        if strays.len() == 1 { "is" } else { "are" },
        by_count
            .keys()
            .filter(|m| **m != n)
            .map(u32::to_string)
            .collect::<Vec<_>>()
            .join(" and "),
        listed(&strays),
    ))
}

/// The file name of `path`, as messages name manifests.
fn file_name_of(path: &Path) -> String {
    path.file_name().map_or_else(
        || path.display().to_string(),
        |n| n.to_string_lossy().into_owned(),
    )
}

/// The build settings of the frames a merge has seen, which every frame of a batch
/// must share: shards run with other options (`--precision`, `--radius`, ...) make
/// frames that differ in more than their particles.
#[derive(Default)]
struct MergeSettings {
    /// The first frame: its name (with its manifest's), build parameters, attribute,
    /// and size and species columns.
    #[allow(clippy::type_complexity)]
    first: Option<(
        String,
        BuildInfo,
        Option<String>,
        (Option<String>, Option<String>, bool),
    )>,
    /// A frame with a chunked build: its name and chunk size.
    chunked: Option<(String, u64)>,
    /// The first frame's `--species-name` renames (none: none given), and its name.
    renames: Option<(String, Vec<(String, String)>)>,
    /// Every species' radius, the first frame holding it, and whether a `--radius`
    /// override set it there.
    radii: std::collections::HashMap<String, (f32, String, bool)>,
    /// Every source file's size and modification time as the first frame converted
    /// from it saw them, with that frame.
    sources: std::collections::HashMap<String, (SourceVersion, String)>,
}

/// A source file's size, modification time in seconds, and nanoseconds past it.
type SourceVersion = (u64, Option<i64>, Option<u32>);

impl MergeSettings {
    /// Compares the frame `f` of the shard manifest `manifest` with the frames before;
    /// the error names the two frames and the setting they differ in.
    fn check(&mut self, out_dir: &Path, manifest: &Path, f: &FrameEntry) -> Result<(), String> {
        let file = MdlodFile::open_sparse(out_dir.join(&f.file)).map_err(|e| e.to_string())?;
        let m = file.metadata();
        let shard = manifest
            .file_name()
            .map_or(String::new(), |n| n.to_string_lossy().into_owned());
        let this = format!("{} (in {shard})", f.file);
        // The file the shard wrote, not one converted again since (by a whole run, or a
        // run of another sharding, killed before it removed the shard manifests).
        let holds = format!("{:016x}", file.header().section_table_checksum);
        if holds != f.checksum {
            return Err(format!(
                "{shard} lists {} with checksum {}, but the file holds {holds}: it was converted \
                 again since the shard ran (by a whole run or another sharding); rerun the \
                 shards, which convert only what changed, then merge",
                f.file, f.checksum
            ));
        }
        // Shards run before and after an input changed convert two versions of it.
        let src = &f.source;
        let version = (src.size, src.modified_unix, src.modified_nanos);
        // Nanoseconds count where both frames have them (earlier runs recorded none).
        let changed = |v: &SourceVersion| {
            v.0 != version.0 || v.1 != version.1 || v.2.zip(version.2).is_some_and(|(a, b)| a != b)
        };
        match self.sources.get(&src.path) {
            Some((v, first)) if changed(v) => {
                return Err(format!(
                    "{first} and {this} were converted from two versions of {} (it changed \
                     between the shards' runs: {} and {} bytes, modified at {} and {} s): \
                     rerun the shards whose frames are older, which convert only what changed, \
                     then merge",
                    src.path,
                    v.0,
                    version.0,
                    v.1.map_or("?".into(), |t| t.to_string()),
                    version.1.map_or("?".into(), |t| t.to_string()),
                ));
            }
            Some(_) => {}
            None => {
                self.sources
                    .insert(src.path.clone(), (version, this.clone()));
            }
        }
        // The attribute with any further ones: shards must keep the same.
        let attribute = m.attribute.as_ref().map(|a| {
            std::iter::once(a.name.as_str())
                .chain(m.attributes.iter().map(|x| x.name.as_str()))
                .collect::<Vec<_>>()
                .join(", ")
        });
        let Some((first, build, first_attribute, (first_sizes, first_species, first_wrap))) =
            &self.first
        else {
            self.first = Some((
                this.clone(),
                m.build.clone(),
                attribute,
                (f.sizes.clone(), f.species_column.clone(), f.wrap),
            ));
            return self.check_renames_chunks_and_radii(m, f, this);
        };
        if *first_wrap != f.wrap {
            let name = |w: bool| if w { "--wrap" } else { "no --wrap" };
            return Err(differ(
                first,
                &this,
                "wrapping into the cell",
                name(*first_wrap),
                name(f.wrap),
            ));
        }
        if *first_sizes != f.sizes {
            let name = |s: &Option<String>| s.clone().unwrap_or_else(|| "the default".into());
            return Err(differ(
                first,
                &this,
                "size column",
                name(first_sizes),
                name(&f.sizes),
            ));
        }
        if *first_species != f.species_column {
            let name = |s: &Option<String>| {
                s.clone()
                    .unwrap_or_else(|| "none (the input's own species)".into())
            };
            return Err(differ(
                first,
                &this,
                "species column",
                name(first_species),
                name(&f.species_column),
            ));
        }
        let b = &m.build;
        for (setting, a, x) in [
            ("cluster size", build.max_cluster_size, b.max_cluster_size),
            ("root points", build.max_root_points, b.max_root_points),
            ("delta n", build.delta_n, b.delta_n),
            ("position bits", build.position_bits, b.position_bits),
        ] {
            if a != x {
                return Err(differ(first, &this, setting, a, x));
            }
        }
        if *first_attribute != attribute {
            let name = |a: &Option<String>| a.as_ref().map_or("none".into(), |a| format!("{a:?}"));
            return Err(differ(
                first,
                &this,
                "attribute",
                name(first_attribute),
                name(&attribute),
            ));
        }
        self.check_renames_chunks_and_radii(m, f, this)
    }

    fn check_renames_chunks_and_radii(
        &mut self,
        m: &mdlod_format::meta::Metadata,
        f: &FrameEntry,
        this: String,
    ) -> Result<(), String> {
        // Renames give species other names, radii and colours: a movie of frames renamed
        // and not flips between the two looks.
        let renames = f.species_names.clone().unwrap_or_default();
        match &self.renames {
            Some((other, r)) if *r != renames => {
                let text = |r: &[(String, String)]| {
                    if r.is_empty() {
                        "none".to_string()
                    } else {
                        r.iter()
                            .map(|(a, b)| format!("{a}={b}"))
                            .collect::<Vec<_>>()
                            .join(" ")
                    }
                };
                return Err(differ(
                    other,
                    &this,
                    "--species-name",
                    text(r),
                    text(&renames),
                ));
            }
            Some(_) => {}
            None => self.renames = Some((this.clone(), renames)),
        }
        // Only a frame above the chunk size records it.
        if let Some(chunk) = m.build.chunk_points {
            match &self.chunked {
                Some((other, c)) if *c != chunk => {
                    return Err(differ(other, &this, "chunk size", c, chunk))
                }
                Some(_) => {}
                None => self.chunked = Some((this.clone(), chunk)),
            }
        }
        for s in &m.species {
            // Without overrides (in either frame, or where the manifest does not record
            // them) a radius is the input's own, which may differ between frames (the
            // mean of a polydisperse species); an override is the same in every frame.
            let overridden = f
                .radii
                .as_ref()
                .is_some_and(|r| crate::species::radius_override(r, &s.name).is_some());
            match self.radii.get(&s.name) {
                Some((r, other, o)) if (*o || overridden) && *r != s.radius => {
                    return Err(differ(
                        other,
                        &this,
                        &format!("radius of species {}", s.name),
                        r,
                        s.radius,
                    ));
                }
                Some(_) => {}
                None => {
                    self.radii
                        .insert(s.name.clone(), (s.radius, this.clone(), overridden));
                }
            }
        }
        Ok(())
    }
}

/// The error of a merge whose frames `other` and `this` were built with `setting` `a`
/// and `b`.
fn differ(other: &str, this: &str, setting: &str, a: impl Display, b: impl Display) -> String {
    format!(
        "the shards were built with different settings: {other} has {setting} {a}, {this} \
         has {setting} {b}; rerun the shards with the same options (a rerun converts again \
         the frames whose settings changed), then merge"
    )
}

/// What [`verify_dir`] found in a batch directory.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DirCheck {
    /// The manifests read: `dataset.json`, or the shards' where it is absent.
    pub manifests: Vec<String>,
    /// Listed frames whose file verified and matched its entry.
    pub frames_ok: usize,
    /// What is wrong, each naming the frame or manifest.
    pub problems: Vec<String>,
    /// Frame files no manifest lists (left alone by batches: a run over other inputs).
    pub unlisted: Vec<String>,
    /// Frame files of deleted dumps a manifest keeps unlisted ([`Manifest::unlisted`]:
    /// converted with other settings than the last run's).
    pub kept_unlisted: Vec<String>,
}

/// Checks a batch directory: every frame a manifest lists is there, verifies completely
/// ([`MdlodFile::verify`]) and is the file the manifest describes (checksum, timestep,
/// particles); every manifest lists the frames it expects; and which frame files no
/// manifest lists. Without `dataset.json` the shards' manifests are checked (not merged
/// yet). `progress` advances by frame.
pub fn verify_dir(dir: &Path, progress: &dyn Progress) -> Result<DirCheck, BatchError> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .map_err(io(dir))?
        .flatten()
        .filter_map(|e| e.file_name().into_string().ok())
        .collect();
    names.sort();
    let manifests: Vec<String> = if names.iter().any(|n| n == MANIFEST) {
        vec![MANIFEST.to_string()]
    } else {
        names
            .iter()
            .filter(|n| is_shard_manifest(n))
            .cloned()
            .collect()
    };
    if manifests.is_empty() {
        return Err(BatchError::Manifest {
            path: dir.to_path_buf(),
            message: "no dataset.json nor shard manifests: not a batch directory".into(),
        });
    }
    let mut check = DirCheck {
        manifests: manifests.clone(),
        ..Default::default()
    };
    // Not merged: every shard of one sharding must have written its manifest.
    let shards: Vec<(u32, u32)> = manifests.iter().filter_map(|m| shard_of(m)).collect();
    if let Some(&(_, n)) = shards.first() {
        let named: Vec<(u32, u32, String)> = manifests
            .iter()
            .filter_map(|m| shard_of(m).map(|(i, n)| (i, n, m.clone())))
            .collect();
        if let Some(message) = different_shardings(&named) {
            check.problems.push(message);
        } else {
            // N comes from a file name: count the missing, and list the first few.
            let present: std::collections::BTreeSet<u32> =
                shards.iter().map(|s| s.0).filter(|&i| i < n).collect();
            let count = u64::from(n) - present.len() as u64;
            if count > 0 {
                const LISTED: usize = 10;
                let mut missing: Vec<String> = (0..n)
                    .filter(|i| !present.contains(i))
                    .take(LISTED)
                    .map(|i| i.to_string())
                    .collect();
                if count > LISTED as u64 {
                    missing.push(format!("and {} more", count - LISTED as u64));
                }
                check.problems.push(format!(
                    "shard{} {} of {n} wrote no manifest: not run yet, or failed before \
                     converting (run it: --shard I/{n})",
                    if count == 1 { "" } else { "s" },
                    missing.join(", ")
                ));
            }
        }
    }
    let running = batch_running(dir);
    let mut listed = std::collections::HashSet::new();
    let mut kept_unlisted = std::collections::BTreeSet::new();
    let mut entries = Vec::new();
    let mut lists = Vec::new();
    let mut choices: Vec<(String, Option<String>)> = Vec::new();
    for name in &manifests {
        let path = dir.join(name);
        let text = read_manifest_bytes(&path).map_err(io(&path))?;
        let m = parse_manifest(&path, &text, "dataset")?;
        // Those kept unlisted are named apart.
        kept_unlisted.extend(m.unlisted.iter().map(|f| f.file.clone()));
        let named = shard_of(name).map(|(i, n)| [i, n]);
        if let Some(problem) = shard_field_problem(named, m.shard) {
            check.problems.push(format!("{name}: {problem}"));
        }
        if let Some(expected) = m.expected_frames {
            if (m.frames.len() as u64) < expected {
                // (A batch still writing the directory says who it is.)
                let why = match &running {
                    Some(who) => format!(
                        "a batch is writing the directory now ({who}): verify it once that \
                         ends"
                    ),
                    None => "that run has not finished (rerun it: it converts only what is \
                             missing)"
                        .to_string(),
                };
                check.problems.push(format!(
                    "{name} lists {} of the {expected} frames its run expects: {why}",
                    m.frames.len()
                ));
            }
        }
        // The frames by timestep, each once (FORMAT.md, section 11): what readers that
        // step through a data set rely on, and what batches write.
        if let Some(w) = m.frames.windows(2).find(|w| w[0].timestep >= w[1].timestep) {
            check.problems.push(if w[0].timestep == w[1].timestep {
                format!(
                    "{name} lists timestep {} twice ({} and {})",
                    w[0].timestep, w[0].file, w[1].file
                )
            } else {
                format!(
                    "{name} does not list its frames by timestep: {} (timestep {}) follows \
                     {} (timestep {})",
                    w[1].file, w[1].timestep, w[0].file, w[0].timestep
                )
            });
        }
        // Frames a run with --keep-going could not convert are missing.
        for f in &m.failed {
            check.problems.push(format!(
                "{} could not be converted, in {name}: {}",
                failed_place(f),
                f.reason
            ));
        }
        lists.push((name.clone(), m.input_frames));
        if is_shard_manifest(name) {
            choices.push((name.clone(), m.duplicates.clone()));
        }
        for f in m.frames {
            listed.insert(f.file.clone());
            entries.push((name.clone(), f));
        }
        // A shard's frames of deleted dumps are the data set's (the merge lists them):
        // checked once, whichever shard keeps them.
        for f in m.gone {
            if listed.insert(f.file.clone()) {
                entries.push((name.clone(), f));
            }
        }
    }
    // Shards not merged yet: they must have split one list of frames (see [`merge`]),
    // made one choice among duplicate timesteps, and built their frames alike, or
    // `--merge` refuses them.
    check.problems.extend(different_input_lists(&lists));
    if let Some(message) = different_duplicate_choices(&choices) {
        check
            .problems
            .push(format!("the shards would not merge: {message}"));
    }
    let mut settings = MergeSettings::default();
    for (manifest, f) in entries.iter().filter(|(m, _)| is_shard_manifest(m)) {
        // (A missing or damaged file is reported below, by itself.)
        if !dir.join(&f.file).is_file() {
            continue;
        }
        if let Err(message) = settings.check(dir, &dir.join(manifest), f) {
            check
                .problems
                .push(format!("the shards would not merge: {message}"));
            break;
        }
    }
    // A file listed by more than one manifest (shards of two shardings side by side)
    // is read and counted once, and checked against each of its entries.
    let mut files: Vec<(String, Vec<(&String, &FrameEntry)>)> = Vec::new();
    let mut index = std::collections::HashMap::new();
    for (manifest, f) in &entries {
        let i = *index.entry(f.file.clone()).or_insert_with(|| {
            files.push((f.file.clone(), Vec::new()));
            files.len() - 1
        });
        files[i].1.push((manifest, f));
    }
    progress.stage("verifying frames", Some(files.len() as u64), "frames");
    for (name, listings) in &files {
        let path = dir.join(name);
        let opened = MdlodFile::open(&path).and_then(|file| file.verify().map(|_| file));
        let mut problems = Vec::new();
        for (manifest, f) in listings {
            let place = format!("{} (timestep {}, in {manifest})", f.file, f.timestep);
            let problem = match &opened {
                Err(e) if !path.exists() => Some(format!("{place}: listed but missing ({e})")),
                // (A rerun trusts a frame that opens, without reading all its data.)
                Err(e) => Some(format!(
                    "{place}: {e}; delete it and rerun the batch, which converts it again"
                )),
                Ok(file) => {
                    let checksum = format!("{:016x}", file.header().section_table_checksum);
                    let m = file.metadata();
                    if checksum != f.checksum {
                        Some(format!(
                            "{place}: checksum {checksum}, the manifest says {} (the file was \
                         replaced after the manifest was written)",
                            f.checksum
                        ))
                    } else if m.timestep.is_some_and(|t| t != f.timestep)
                        || file.particle_count() != f.particles
                    {
                        // (A frame of an input without timesteps holds none: the manifest
                        // numbers it by its position.)
                        Some(format!(
                            "{place}: the file holds {} and {} particles, the manifest says \
                         timestep {} and {} particles",
                            m.timestep
                                .map_or("no timestep".into(), |t| format!("timestep {t}")),
                            file.particle_count(),
                            f.timestep,
                            f.particles
                        ))
                    } else if m.time != f.time || m.simulation_box != f.simulation_box {
                        // (A movie's labels and `info DIR` read the manifest's.)
                        let what = if m.time != f.time { "time" } else { "box" };
                        Some(format!(
                            "{place}: the file's {what} is not the one the manifest lists for \
                             it (file: {}, manifest: {}): the manifest was edited, or the \
                             file replaced",
                            match what {
                                "time" => m.time.map_or("none".into(), |t| t.to_string()),
                                _ => format!("{:?}", m.simulation_box),
                            },
                            match what {
                                "time" => f.time.map_or("none".into(), |t| t.to_string()),
                                _ => format!("{:?}", f.simulation_box),
                            }
                        ))
                    } else {
                        None
                    }
                }
            };
            problems.extend(problem);
        }
        if problems.is_empty() {
            check.frames_ok += 1;
        }
        check.problems.extend(problems);
        progress.advance(1);
    }
    progress.finish_stage();
    let (kept, unlisted): (Vec<String>, Vec<String>) = names
        .into_iter()
        .filter(|n| frame_file_number(n).is_some() && !listed.contains(n))
        .partition(|n| kept_unlisted.contains(n));
    check.unlisted = unlisted;
    check.kept_unlisted = kept;
    Ok(check)
}

/// Reads a batch directory's `dataset.json`.
pub fn read_manifest(out_dir: &Path) -> Result<Manifest, BatchError> {
    let path = out_dir.join(MANIFEST);
    let text = read_manifest_bytes(&path).map_err(io(&path))?;
    parse_manifest(&path, &text, "dataset")
}

/// A manifest's bytes: a regular file of at most [`mdlod_format::files::MANIFEST_BYTES`]
/// (a FIFO or a device in its place would block or never end).
fn read_manifest_bytes(path: &Path) -> std::io::Result<Vec<u8>> {
    mdlod_format::files::read_capped(path, mdlod_format::files::MANIFEST_BYTES)
}

/// A manifest's JSON (`what`: "dataset" or "shard", for the message), checked: its
/// version, its shard, and every frame's file a plain name inside the directory (a
/// manifest is read from wherever a batch directory comes from: a `file` of `/etc/…` or
/// `../…` would have a render or a verify read outside it).
pub fn parse_manifest(path: &Path, text: &[u8], what: &str) -> Result<Manifest, BatchError> {
    let bad = |message: String| BatchError::Manifest {
        path: path.to_path_buf(),
        message,
    };
    let m: Manifest =
        serde_json::from_slice(text).map_err(|e| bad(format!("not a {what} manifest: {e}")))?;
    if m.mdlod_dataset != MANIFEST_VERSION {
        return Err(bad(format!(
            "mdlod_dataset {} (this mdlod reads version {MANIFEST_VERSION})",
            m.mdlod_dataset
        )));
    }
    if let Some([i, n]) = m.shard.filter(|[i, n]| i >= n) {
        return Err(bad(format!(
            "shard [{i}, {n}] (the index must be below the count)"
        )));
    }
    if let Some(f) = m.frames.iter().find(|f| {
        let mut parts = Path::new(&f.file).components();
        !matches!(
            (parts.next(), parts.next()),
            (Some(std::path::Component::Normal(_)), None)
        )
    }) {
        return Err(bad(format!(
            "frame of timestep {}: file {:?} is not a file name inside the directory",
            f.timestep, f.file
        )));
    }
    Ok(m)
}

/// A shard manifest says which shard it is twice, in its name (`named`; `None`: the
/// merged `dataset.json`) and its `shard` field: where they disagree, how.
fn shard_field_problem(named: Option<[u32; 2]>, field: Option<[u32; 2]>) -> Option<String> {
    let text = |f: Option<[u32; 2]>| f.map_or("absent".to_string(), |[a, b]| format!("[{a}, {b}]"));
    (named != field).then(|| match named {
        Some([i, n]) => format!(
            "its shard field is {} but its name says shard {i} of {n}",
            text(field)
        ),
        None => format!("a shard field {} in the merged manifest", text(field)),
    })
}

/// The manifest version this mdlod writes and reads.
const MANIFEST_VERSION: u32 = 1;

/// Whether a file's further attributes are those `opts` asks for: by name as the file
/// gives them (`log10(NAME)` for a logarithm), in order.
fn same_further(kept: &[mdlod_format::meta::AttributeInfo], opts: &BatchOptions) -> bool {
    kept.iter().map(|a| a.name.clone()).eq(opts
        .read
        .extra_attributes
        .iter()
        .enumerate()
        .map(|(k, name)| crate::convert::extra_attribute_name(name, k, &opts.convert)))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Notes that differ in their figures alone are one kind; other words, another.
    #[test]
    fn a_notes_kind_leaves_out_its_figures() {
        let a = "attribute c_ke spans 5.2 decades (1e-9 to 16), kept in 16-bit steps of 2.44e-4";
        let b = "attribute c_ke spans 12.0 decades (2.5e-12 to 1.6e1), kept in 16-bit steps \
                 of 7e-5";
        assert_eq!(note_kind(a), note_kind(b));
        assert_eq!(
            note_kind(a),
            "attribute c_ke spans # decades (# to #), kept in #bit steps of #"
        );
        assert_eq!(note_kind("box -3.5 to +7"), "box # to #");
        assert_ne!(note_kind(a), note_kind("attribute v_speed spans 5 decades"));
        assert_ne!(note_kind("species Cu2"), note_kind("species Cu"));
        // Notes about numbered species, or two notes about one attribute, stay apart.
        let radius = |s: &str| format!("species {s}: --radius {s}=0.4 draws every particle");
        assert_ne!(note_key(&radius("1")), note_key(&radius("2")));
        assert_ne!(
            note_key("attribute c_ke: 23 of the 50 values above 0 lie below one step"),
            note_key("attribute c_ke: at particles' resolution its steps change the total")
        );
        assert_eq!(
            note_key("attribute c_ke spans 5.2 decades (1e-9 to 16): the values"),
            note_key("attribute c_ke spans 12.0 decades (2.5e-12 to 1.6e1): the values")
        );
    }

    /// FORMAT.md's section 11 names every field a manifest and its frames write (the
    /// struct literals list every field, so a field added here must be added there).
    #[test]
    fn format_md_names_every_manifest_field() {
        let source = SourceInfo {
            path: "run.dump".into(),
            size: 1,
            modified_unix: None,
            modified_nanos: None,
            frame: 0,
            bytes: None,
        };
        let frame = FrameEntry {
            timestep: 0,
            time: Some(0.5),
            particles: 1,
            simulation_box: None,
            file: "frame-0.mdlod".into(),
            checksum: "0".repeat(16),
            source,
            columns: Some(vec!["id".into()]),
            radii: Some(vec![("Cu".into(), 1.28)]),
            species_names: Some(vec![("1".into(), "Cu".into())]),
            sizes: Some("none".into()),
            species_column: Some("c_cna".into()),
            wrap: true,
            source_abs: Some("/runs/run.dump".into()),
        };
        let manifest = Manifest {
            mdlod_dataset: 1,
            shard: Some([0, 2]),
            expected_frames: Some(1),
            input_frames: Some(InputFrames {
                count: 1,
                xxh3: "0".repeat(16),
            }),
            frames: vec![frame.clone()],
            gone: vec![frame.clone()],
            unlisted: vec![frame],
            failed: vec![FailedEntry {
                timestep: Some(1),
                input: "run.dump".into(),
                frame: 1,
                reason: "cut".into(),
            }],
            empty: vec![EmptyEntry {
                timestep: 2,
                input: "run.dump".into(),
                frame: 2,
            }],
            duplicates: Some("last".into()),
        };
        let json = serde_json::to_value(&manifest).unwrap();
        let spec = std::fs::read_to_string(
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../FORMAT.md"),
        )
        .unwrap();
        let section = &spec[spec.find("## 11. Batch manifests").expect("section 11")..];
        let mut keys: Vec<String> = json.as_object().unwrap().keys().cloned().collect();
        keys.extend(json["frames"][0].as_object().unwrap().keys().cloned());
        // The box is optional and `None` above; it is named too.
        keys.push("box".into());
        for key in keys {
            assert!(
                section.contains(&format!("| `{key}` |")),
                "FORMAT.md lacks `{key}`"
            );
        }
    }

    /// A failed batch whose manifest could not be saved after the failure (the disk
    /// that stopped a frame full for it too) does not claim the frames are listed.
    #[test]
    fn an_unsaved_manifest_is_not_said_to_list_the_frames() {
        let e = |unsaved: Option<&str>| {
            BatchError::Incomplete {
                converted: 3,
                todo: 5,
                manifest_unsaved: unsaved.map(str::to_owned),
                source: Box::new(BatchError::BadShard(2, 1)),
            }
            .to_string()
        };
        assert!(e(None).contains("3 of the 5 frames to convert were converted and are listed"));
        let text = e(Some("No space left on device (os error 28)"));
        assert!(
            text.contains("but the manifest listing them could not be saved (No space left")
                && text.contains("converts the others again")
                && !text.contains("are listed"),
            "{text}"
        );
    }

    /// The advice for a stray sharding: a task resubmitted alone where a stray is of one
    /// task, not where it is of another array size.
    #[test]
    fn stray_shardings_get_advice_that_fits_them() {
        let named = |v: &[(u32, u32)]| -> Vec<(u32, u32, String)> {
            v.iter()
                .map(|&(i, n)| (i, n, format!("dataset.shard-{i}-of-{n}.json")))
                .collect()
        };
        let alone = different_shardings(&named(&[(0, 3), (1, 3), (0, 1)])).unwrap();
        assert!(
            alone.contains("resubmitted alone") && alone.contains("--shard 2/3"),
            "{alone}"
        );
        let other = different_shardings(&named(&[(0, 3), (2, 3), (1, 5)])).unwrap();
        assert!(
            !other.contains("resubmitted alone")
                && other.contains("Runs of another array size wrote the others")
                && other.contains("--shard 1/3"),
            "{other}"
        );
        assert_eq!(different_shardings(&named(&[(0, 3), (1, 3)])), None);
    }

    #[test]
    fn patterns_with_a_percent_name_piece_sets() {
        let set = |p: &str, n: &str| piece_set_of(p, n);
        assert_eq!(
            set("dump.*.%.bin", "dump.100.3.bin").as_deref(),
            Some("dump.100.%.bin")
        );
        assert_eq!(set("dump.*.%.bin", "dump.100.bin"), None);
        assert_eq!(
            set("dump.%.*", "dump.3.lammpstrj").as_deref(),
            Some("dump.%.lammpstrj")
        );
        assert_eq!(set("d*.%.bin", "d7.12.bin").as_deref(), Some("d7.%.bin"));
        assert_eq!(set("dump.*.%.bin", "dump.1.2.txt"), None);
        let dir = tempfile::tempdir().unwrap();
        for n in [
            "d.0.0.bin",
            "d.0.1.bin",
            "d.50.0.bin",
            "d.50.1.bin",
            "d.7.bin",
            "x.0.0.bin",
        ] {
            std::fs::write(dir.path().join(n), b"x").unwrap();
        }
        let got = expand_patterns(&[dir.path().join("d.*.%.bin")], &dir.path().join("o")).unwrap();
        assert_eq!(
            got,
            [dir.path().join("d.0.%.bin"), dir.path().join("d.50.%.bin")]
        );
        assert!(expand_patterns(&[dir.path().join("d.*.%.%.bin")], dir.path()).is_err());
        // The newest timestep missing a piece, or with one still empty (a run writing
        // it): left out, with a note.
        std::fs::remove_file(dir.path().join("d.50.1.bin")).unwrap();
        let noted = || {
            let mut notes = Vec::new();
            let got = expand_patterns_noting(
                &[dir.path().join("d.*.%.bin")],
                &dir.path().join("o"),
                &mut notes,
            )
            .unwrap();
            (got, notes)
        };
        let (got, notes) = noted();
        assert_eq!(got, [dir.path().join("d.0.%.bin")]);
        assert!(
            notes.len() == 1
                && notes[0].contains(
                    "d.50.%.bin, the newest timestep, is in 1 piece where the others are in 2"
                )
                && notes[0].contains("left out"),
            "{notes:?}"
        );
        std::fs::write(dir.path().join("d.50.1.bin"), b"").unwrap();
        let (got, notes) = noted();
        assert_eq!(got, [dir.path().join("d.0.%.bin")]);
        assert!(notes[0].contains("has an empty piece"), "{notes:?}");
        // An older timestep missing a piece: refused, naming its set.
        std::fs::write(dir.path().join("d.50.1.bin"), b"x").unwrap();
        std::fs::remove_file(dir.path().join("d.0.1.bin")).unwrap();
        let e = expand_patterns(&[dir.path().join("d.*.%.bin")], &dir.path().join("o"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("d.0.%.bin is in 1 piece, where another timestep's set is in 2"),
            "{e}"
        );
        assert!(expand_patterns(&[dir.path().join("q.*.%.bin")], dir.path()).is_err());
    }

    #[test]
    fn pieces_of_files_per_timestep_are_named_by_their_pattern() {
        let set = Path::new("bin/dump.0.%.bin");
        let inputs = ["bin/dump.0.0.bin", "bin/dump.0.1.bin", "bin/dump.50.0.bin"].map(Path::new);
        assert_eq!(
            every_timesteps_set(set, &inputs).as_deref(),
            Some(Path::new("bin/dump.*.%.bin"))
        );
        // One timestep's pieces alone: its own set.
        assert_eq!(every_timesteps_set(set, &inputs[..2]), None);
        assert_eq!(every_timesteps_set(Path::new("d.%.bin"), &inputs), None);
    }

    #[test]
    fn files_named_alike_but_for_a_number_are_a_piece_set() {
        let p = |a: &str, b: &str| {
            piece_pattern(Path::new(a), Path::new(b)).map(|p| p.display().to_string())
        };
        assert_eq!(
            p("bin/dump.0.bin", "bin/dump.1.bin").as_deref(),
            Some("bin/dump.%.bin")
        );
        assert_eq!(p("d.10.bin", "d.11.bin").as_deref(), Some("d.%.bin"));
        assert_eq!(p("d.0.bin", "d.10.bin").as_deref(), Some("d.%.bin"));
        assert_eq!(p("run.3", "run.12").as_deref(), Some("run.%"));
        assert_eq!(p("a/d.0.bin", "b/d.1.bin"), None);
        assert_eq!(p("melt.dump", "cu_melt.step.0.bin"), None);
        assert_eq!(p("d.0a.bin", "d.1b.bin"), None);
        assert_eq!(p("d.0.bin", "d.0.bin"), None);
        // Names of other scripts: characters, not bytes (α and β share a first byte).
        assert_eq!(p("run_α.dump", "run_β.dump"), None);
        assert_eq!(p("xé.1", "xĩ.1"), None);
        assert_eq!(p("α.0.bin", "α.1.bin").as_deref(), Some("α.%.bin"));
    }

    #[test]
    fn quoted_patterns_match_file_names() {
        use super::wildcard;
        assert!(wildcard("dump.*.bin", "dump.1000.bin"));
        assert!(wildcard("dump.*.bin", "dump..bin"));
        assert!(!wildcard("dump.*.bin", "dump.1000.bin.gz"));
        assert!(wildcard("d?mp*", "dump.1"));
        assert!(wildcard("*a*b", "xxaxxb"));
        assert!(!wildcard("*a*b", "xxaxxbc"));
        let dir = tempfile::tempdir().unwrap();
        for n in ["dump.20.bin", "dump.10.bin", "other.bin"] {
            std::fs::write(dir.path().join(n), "").unwrap();
        }
        let found =
            super::expand_patterns(&[dir.path().join("dump.*.bin")], Path::new("out")).unwrap();
        let names: Vec<_> = found
            .iter()
            .map(|p| p.file_name().unwrap().to_owned())
            .collect();
        assert_eq!(names, ["dump.10.bin", "dump.20.bin"]);
        let mut set = vec![
            "w.10.xyz", "w.2.xyz", "w.1.xyz", "w.02.xyz", "v.xyz", "w.1a.xyz",
        ];
        set.sort_by(|a, b| super::natural_cmp(a, b));
        assert_eq!(
            set,
            ["v.xyz", "w.1.xyz", "w.1a.xyz", "w.2.xyz", "w.02.xyz", "w.10.xyz"]
        );
        let e = super::expand_patterns(&[dir.path().join("none.*")], Path::new("out")).unwrap_err();
        assert!(e.to_string().contains("no file matches"), "{e}");
        let e = super::expand_patterns(&[dir.path().join("dump.[12]*.bin")], Path::new("out"))
            .unwrap_err();
        assert!(e.to_string().contains("* and ? only"), "{e}");
    }

    #[test]
    fn sources_differ_by_nanoseconds_unless_recorded_without_them() {
        let now = SourceInfo {
            path: "dump.lammpstrj".into(),
            size: 1000,
            modified_unix: Some(1_700_000_000),
            modified_nanos: Some(250),
            frame: 3,
            bytes: None,
        };
        assert!(same_source(&now, &now));
        let other_nanos = SourceInfo {
            modified_nanos: Some(251),
            ..now.clone()
        };
        assert!(!same_source(&other_nanos, &now));
        // Written by a version that kept whole seconds only.
        let seconds_only = SourceInfo {
            modified_nanos: None,
            ..now.clone()
        };
        assert!(same_source(&seconds_only, &now));
        let other_second = SourceInfo {
            modified_unix: Some(1_700_000_001),
            ..seconds_only
        };
        assert!(!same_source(&other_second, &now));
        let other_frame = SourceInfo {
            frame: 4,
            ..now.clone()
        };
        assert!(!same_source(&other_frame, &now));
        // Another path of the same name: the same file where the time has nanoseconds,
        // not where it has none or they are 0 (whole-second file systems, archives).
        let elsewhere = |nanos| SourceInfo {
            path: "/scratch/run2/dump.lammpstrj".into(),
            modified_nanos: nanos,
            ..now.clone()
        };
        assert!(same_source(&now, &elsewhere(Some(250))));
        assert!(same_source(&elsewhere(Some(250)), &now));
        assert!(!same_source(&now, &elsewhere(Some(251))));
        let whole = |n| SourceInfo {
            modified_nanos: n,
            ..now.clone()
        };
        assert!(!same_source(&whole(Some(0)), &elsewhere(Some(0))));
        assert!(!same_source(&whole(None), &elsewhere(Some(0))));
        let renamed = SourceInfo {
            path: "/scratch/run2/other.lammpstrj".into(),
            ..now.clone()
        };
        assert!(!same_source(&now, &renamed));
        // The frame's bytes recorded: the same source when size and time agree.
        let with_bytes = SourceInfo {
            bytes: Some(FrameBytes {
                start: 10,
                end: 900,
                xxh3: "0123456789abcdef".into(),
            }),
            ..now.clone()
        };
        assert!(same_source(&with_bytes, &now));
    }
}
