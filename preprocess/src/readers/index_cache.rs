//! Frame indexes kept between runs, so that a text dump is scanned once.
//!
//! How it works. Listing the frames of a LAMMPS text dump or an XYZ file reads every
//! byte of it (the frames' starts are found only by scanning the lines). A batch lists
//! every input on every run and in every shard of a job array, although each converts
//! only its own frames: without a cache, N shards over a terabyte of dumps read N
//! terabytes before any of them converts a frame.
//!
//! An [`IndexCache`] keeps, per uncompressed text input (by its absolute path), the byte
//! range and timestep of each frame, with the identity of the file it was taken from:
//! its size, its modification and change times to the nanosecond and its inode. An
//! input whose identity is unchanged is not scanned again; any change (a dump a running
//! simulation appended to, a file replaced or touched) scans it afresh. A file modified
//! or changed within [`SETTLED`] of its scan, or dated ahead of the clock, is not kept
//! (a write later in the same tick of the file system's clock would not change its
//! identity). Binary formats, whose frames
//! come from their headers, and gzip files, whose text is decompressed anyway, are not
//! kept.
//!
//! The cache is a JSON file (`{"mdlod_frame_index": 1, "inputs": {...}}`), read with a
//! size cap and taken as untrusted: an entry is used only when its checksum (of the
//! entry as written) holds, its ranges lie in order inside the file and each starts with
//! the frame header it claims (an `ITEM: TIMESTEP` line with the timestep kept; an XYZ
//! count line and a comment line giving the timestep kept, only blank lines between
//! frames), else the input is scanned as if there were none; an unreadable or foreign
//! file is an empty cache. It is written by temporary file and rename, so processes
//! writing it at once (the shards of an array) each leave a whole file.
//!
//! Readers find the cache through [`IndexCache::scope`], which makes it the one every
//! [`super::DumpFile`] opened on this thread consults until the scope ends.

use std::cell::RefCell;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

use serde::{Deserialize, Serialize};

/// The cache file's format version.
const VERSION: u32 = 1;

/// A cache file larger than this is not read (a hostile or foreign file).
const MAX_FILE_BYTES: u64 = 256 << 20;

/// A file modified less than this long before it is scanned is not kept: a write in the
/// same tick of the file system's clock after the scan (a dump written in place, its
/// size set first, as LAMMPS's MPI-IO dumps do) would leave its identity unchanged.
const SETTLED: std::time::Duration = std::time::Duration::from_secs(2);

/// What a file is, for telling whether it changed since it was indexed. (Not its device
/// number: a network file system's differs between the machines that mount it, such as
/// a cluster's login node and compute nodes.)
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
struct Identity {
    len: u64,
    modified_s: i64,
    modified_ns: u32,
    /// The inode's change time, which any write sets and `touch -d` cannot put back.
    changed_s: i64,
    changed_ns: u32,
    inode: u64,
}

impl Identity {
    fn of(meta: &std::fs::Metadata) -> Identity {
        use std::os::unix::fs::MetadataExt;
        Identity {
            len: meta.len(),
            modified_s: meta.mtime(),
            modified_ns: u32::try_from(meta.mtime_nsec()).unwrap_or(u32::MAX),
            changed_s: meta.ctime(),
            changed_ns: u32::try_from(meta.ctime_nsec()).unwrap_or(u32::MAX),
            inode: meta.ino(),
        }
    }
}

/// One input's frames as its reader indexed them.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub(crate) struct CachedFrames {
    /// `lammps` or `xyz`.
    pub format: String,
    /// Each frame's byte range `[start, end)`.
    pub ranges: Vec<[u64; 2]>,
    /// Each frame's timestep, where it records one.
    pub timesteps: Vec<Option<u64>>,
    /// LAMMPS: the `ITEM: UNITS` value.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub units: Option<String>,
    /// XYZ: frames whose timestep key holds no whole number, with the text written.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub unread_timesteps: Vec<(usize, String)>,
}

impl CachedFrames {
    /// The frames of a `format` input, each its byte range and timestep, with no units
    /// and no unread timesteps (which the caller sets where its format has them).
    pub fn of(format: &str, frames: impl Iterator<Item = (usize, usize, Option<u64>)>) -> Self {
        let (ranges, timesteps) = frames
            .map(|(start, end, t)| ([start as u64, end as u64], t))
            .unzip();
        CachedFrames {
            format: format.into(),
            ranges,
            timesteps,
            units: None,
            unread_timesteps: Vec::new(),
        }
    }

    /// The ranges as offsets into `data`, when they lie in order inside it (each at least
    /// one byte, none overlapping the next) and each starts a line.
    pub fn checked_ranges(&self, data: &[u8]) -> Option<Vec<std::ops::Range<usize>>> {
        if self.ranges.is_empty() || self.timesteps.len() != self.ranges.len() {
            return None;
        }
        let mut out = Vec::with_capacity(self.ranges.len());
        let mut floor = 0usize;
        for &[start, end] in &self.ranges {
            let (start, end) = (usize::try_from(start).ok()?, usize::try_from(end).ok()?);
            if start < floor || start >= end || end > data.len() {
                return None;
            }
            if start > 0 && data[start - 1] != b'\n' {
                return None;
            }
            floor = end;
            out.push(start..end);
        }
        if self
            .unread_timesteps
            .iter()
            .any(|(k, _)| *k >= self.ranges.len())
        {
            return None;
        }
        Some(out)
    }
}

#[derive(Clone, Debug, Serialize, Deserialize)]
struct Entry {
    identity: Identity,
    frames: CachedFrames,
    /// [`Entry::checksum`] of the rest, as written: an entry whose ranges were altered
    /// (a last range widened over the frame after it passes every check of the ranges,
    /// and hid that frame) is not used.
    #[serde(default)]
    check: u64,
}

impl Entry {
    fn new(identity: Identity, frames: CachedFrames) -> Entry {
        let mut e = Entry {
            identity,
            frames,
            check: 0,
        };
        e.check = e.checksum();
        e
    }

    /// FNV-1a of `[identity, frames]` as JSON values ([`entry_checksum`]).
    fn checksum(&self) -> u64 {
        entry_checksum(
            &serde_json::to_value(self.identity).unwrap_or_default(),
            &serde_json::to_value(&self.frames).unwrap_or_default(),
        )
    }
}

#[derive(Serialize, Deserialize)]
struct CacheFile {
    mdlod_frame_index: u32,
    inputs: BTreeMap<String, Entry>,
}

/// The checksum an entry of the cache file keeps (`check`): FNV-1a of the JSON text of
/// `[identity, frames]`, its two other fields as JSON values.
pub fn entry_checksum(identity: &serde_json::Value, frames: &serde_json::Value) -> u64 {
    let bytes = serde_json::to_vec(&serde_json::json!([identity, frames])).unwrap_or_default();
    bytes.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

/// Frame indexes of text inputs, read from and written to one file.
#[derive(Debug)]
pub struct IndexCache {
    path: PathBuf,
    /// Entries read from the file.
    read: BTreeMap<String, Entry>,
    /// Entries used or made this run: what [`IndexCache::save`] writes.
    kept: Mutex<BTreeMap<String, Entry>>,
    /// Inputs whose index came from the cache, and those scanned.
    hits: AtomicUsize,
    scanned: AtomicUsize,
    /// Inputs scanned but not kept: modified or changed moments ago, or dated ahead.
    unsettled: AtomicUsize,
}

thread_local! {
    static CURRENT: RefCell<Option<Arc<IndexCache>>> = const { RefCell::new(None) };
}

/// While it lives, [`IndexCache::scope`]'s cache is the one readers on this thread use.
pub struct IndexScope {
    previous: Option<Arc<IndexCache>>,
    /// Not `Send`: the cache is this thread's.
    _thread: std::marker::PhantomData<*const ()>,
}

impl Drop for IndexScope {
    fn drop(&mut self) {
        let previous = self.previous.take();
        CURRENT.with(|c| *c.borrow_mut() = previous);
    }
}

/// The cache of the innermost [`IndexCache::scope`] on this thread.
pub(crate) fn current() -> Option<Arc<IndexCache>> {
    CURRENT.with(|c| c.borrow().clone())
}

/// The key an input is kept under: its absolute path.
fn key_of(path: &Path) -> String {
    std::fs::canonicalize(path)
        .unwrap_or_else(|_| path.to_path_buf())
        .to_string_lossy()
        .into_owned()
}

impl IndexCache {
    /// The cache kept in `path`: empty when there is none, or it cannot be read, is too
    /// large, is not JSON of this version.
    pub fn load(path: &Path) -> IndexCache {
        let read = mdlod_format::files::read_capped(path, MAX_FILE_BYTES)
            .ok()
            .and_then(|bytes| serde_json::from_slice::<CacheFile>(&bytes).ok())
            .filter(|c| c.mdlod_frame_index == VERSION)
            .map(|c| c.inputs)
            .unwrap_or_default()
            .into_iter()
            .filter(|(_, e)| e.check == e.checksum())
            .collect();
        IndexCache {
            path: path.to_path_buf(),
            read,
            kept: Mutex::new(BTreeMap::new()),
            hits: AtomicUsize::new(0),
            scanned: AtomicUsize::new(0),
            unsettled: AtomicUsize::new(0),
        }
    }

    /// The file this cache is read from and written to.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// No cache for readers opened on this thread until the scope is dropped (a working
    /// file decompressed from a gzip input, which no later run reads).
    pub fn suspend() -> IndexScope {
        IndexScope {
            previous: CURRENT.with(|c| c.borrow_mut().take()),
            _thread: std::marker::PhantomData,
        }
    }

    /// Makes this the cache readers opened on this thread consult, until the scope is
    /// dropped.
    pub fn scope(self: &Arc<Self>) -> IndexScope {
        let previous = CURRENT.with(|c| c.borrow_mut().replace(self.clone()));
        IndexScope {
            previous,
            _thread: std::marker::PhantomData,
        }
    }

    /// Inputs whose frames came from the cache so far.
    pub fn hits(&self) -> usize {
        self.hits.load(Ordering::Relaxed)
    }

    /// Inputs scanned so far (kept, or [`IndexCache::unsettled`]).
    pub fn scanned(&self) -> usize {
        self.scanned.load(Ordering::Relaxed)
    }

    /// Inputs scanned but not kept: modified or changed less than [`SETTLED`] before
    /// (a run may still be writing them), or dated ahead of this machine's clock (a
    /// network file system's server ahead of it). The next run scans them again.
    pub fn unsettled(&self) -> usize {
        self.unsettled.load(Ordering::Relaxed)
    }

    /// Whether saving would change the file: an input scanned, or one it holds unused.
    pub fn changed(&self) -> bool {
        let kept = self.kept.lock().unwrap_or_else(|e| e.into_inner());
        kept.len() != self.read.len()
            || kept.iter().any(|(k, e)| {
                self.read
                    .get(k)
                    .is_none_or(|r| r.identity != e.identity || r.frames != e.frames)
            })
    }

    /// The frames kept for `path` of the given format, when `meta` (of the file now
    /// open) says it is the file they were taken from. The caller checks them against
    /// the file's bytes and calls [`IndexCache::rejected`] when they do not fit.
    pub(crate) fn lookup(
        &self,
        path: &Path,
        meta: &std::fs::Metadata,
        format: &str,
    ) -> Option<CachedFrames> {
        let key = key_of(path);
        let entry = self.read.get(&key)?;
        if entry.identity != Identity::of(meta) || entry.frames.format != format {
            return None;
        }
        self.hits.fetch_add(1, Ordering::Relaxed);
        self.kept
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .insert(key, entry.clone());
        Some(entry.frames.clone())
    }

    /// The frames [`IndexCache::lookup`] gave for `path` did not fit the file: not a hit.
    pub(crate) fn rejected(&self, path: &Path) {
        self.hits.fetch_sub(1, Ordering::Relaxed);
        self.kept
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .remove(&key_of(path));
    }

    /// Drops the entry of `path` (a dump listed from it whose frame could not be read):
    /// saved again, the cache makes the next run scan the dump.
    pub fn forget(&self, path: &Path) {
        self.kept
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .remove(&key_of(path));
    }

    /// Keeps the frames just indexed for `path`, whose metadata `meta` was taken before
    /// (not a file modified or changed within [`SETTLED`] of now, nor one dated ahead:
    /// the change time counts too, as a copy keeping its modification time, `cp -p`,
    /// sets it).
    pub(crate) fn insert(&self, path: &Path, meta: &std::fs::Metadata, frames: CachedFrames) {
        use std::os::unix::fs::MetadataExt;
        self.scanned.fetch_add(1, Ordering::Relaxed);
        let changed = u64::try_from(meta.ctime()).ok().map(|s| {
            std::time::UNIX_EPOCH
                + std::time::Duration::new(s, u32::try_from(meta.ctime_nsec()).unwrap_or(0))
        });
        let latest = match (meta.modified().ok(), changed) {
            (Some(m), Some(c)) => Some(m.max(c)),
            (m, c) => m.or(c),
        };
        let settled = latest
            .and_then(|t| t.elapsed().ok())
            .is_some_and(|age| age >= SETTLED);
        if !settled {
            self.unsettled.fetch_add(1, Ordering::Relaxed);
            return;
        }
        self.kept
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .insert(key_of(path), Entry::new(Identity::of(meta), frames));
    }

    /// Writes the inputs used or scanned since [`IndexCache::load`] (others are dropped)
    /// by a temporary file and rename, when that changes the file.
    pub fn save(&self) -> std::io::Result<()> {
        if !self.changed() {
            return Ok(());
        }
        let inputs = self.kept.lock().unwrap_or_else(|e| e.into_inner()).clone();
        let text = serde_json::to_vec(&CacheFile {
            mdlod_frame_index: VERSION,
            inputs,
        })
        .map_err(std::io::Error::other)?;
        let dir = match self.path.parent() {
            Some(d) if !d.as_os_str().is_empty() => d,
            _ => Path::new("."),
        };
        // `.dataset.HOST-PID-XXXXXX.tmp`, as a manifest's: a run killed while writing it
        // leaves one that the next run removes.
        let mut tmp = mdlod_format::writer::output_file_builder()
            .prefix(&mdlod_format::writer::temp_prefix("dataset"))
            .suffix(".tmp")
            .tempfile_in(dir)?;
        std::io::Write::write_all(&mut tmp, &text)?;
        tmp.persist(&self.path).map_err(|e| e.error)?;
        Ok(())
    }
}
