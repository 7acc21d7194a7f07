//! Writing and reading the files of an out-of-core conversion past the page cache.
//!
//! Out of core, a conversion writes gigabytes it does not read back (the output).
//! Through the page cache the kernel copies every byte into pages it must first
//! allocate; on this project's benchmark machine, a virtual machine, that copy ran at
//! about 1 GB/s and was most of the final write. With `O_DIRECT` (Linux) the disk reads
//! from and writes into this process's own buffers, which are reused. The partition's
//! cells, which are read back, use the same [`Appender`] and [`read_at`] through the page
//! cache (`direct` false): there direct I/O was measured no faster, and the page cache
//! keeps cells for their next reader.
//!
//! How it works:
//! - [`DirectSink`], the output: the caller's bytes are copied into one of a few aligned
//!   blocks; each full block goes to a thread of its own, which writes it at its offset
//!   while the caller fills the next. An error is reported by the next call after the
//!   thread met it.
//! - [`Appender`], a file appended piece after piece in whole aligned blocks through a
//!   scratch block shared by many files; the last partial block waits in a small tail.
//! - [`read_whole`] and [`read_at`], such a file read back in large reads (direct ones
//!   first make the kernel write back whatever of it went through the page cache).
//!
//! A file's last partial block goes through an ordinary handle, and so does everything
//! where the filesystem refuses direct I/O (`EINVAL`): the bytes in the file are the
//! same either way.

use std::fs::{File, OpenOptions};
use std::io;
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};
use std::sync::mpsc::{channel, Receiver, Sender};
use std::thread::JoinHandle;

use mdlod_format::writer::Sink;

/// Alignment of direct-I/O buffers, offsets and lengths (the largest logical block size
/// in common use).
const ALIGN: usize = 4096;
/// Bytes per write.
const BLOCK: usize = 8 << 20;
/// Blocks in rotation: one being filled, the others queued or being written.
const BLOCKS: usize = 3;

/// `len` bytes at an `ALIGN`-aligned address inside an ordinary vector.
pub struct Block {
    buf: Vec<u8>,
    start: usize,
    len: usize,
}

impl Block {
    fn new() -> Block {
        Block::with_len(BLOCK)
    }

    /// A block of `len` bytes (zeroed).
    pub fn with_len(len: usize) -> Block {
        let buf = vec![0u8; len + ALIGN];
        // Always computable for bytes; were it not, direct I/O on this block would be
        // refused and go through the ordinary handle.
        let start = buf.as_ptr().align_offset(ALIGN).min(ALIGN);
        Block { buf, start, len }
    }

    pub fn data(&self) -> &[u8] {
        &self.buf[self.start..self.start + self.len]
    }

    pub fn data_mut(&mut self) -> &mut [u8] {
        &mut self.buf[self.start..self.start + self.len]
    }
}

/// One block to write: its first `len` bytes at `offset`.
struct Job {
    block: Block,
    len: usize,
    offset: u64,
}

/// Writes a file from the start through a thread of its own, with direct I/O where the
/// system allows.
pub struct DirectSink {
    fill: Block,
    len: usize,
    offset: u64,
    blocks: usize,
    jobs: Option<Sender<Job>>,
    free: Receiver<Block>,
    thread: Option<JoinHandle<io::Result<File>>>,
}

/// Opens `path` (an existing, empty file) for writing through a [`DirectSink`]; the
/// signature [`mdlod_format::Writer::create_with`] takes.
pub fn open(path: &Path) -> io::Result<Box<dyn Sink>> {
    Ok(Box::new(DirectSink::open(path)?))
}

impl DirectSink {
    pub fn open(path: &Path) -> io::Result<DirectSink> {
        let direct = open_direct(path)?;
        let (jobs, rx) = channel::<Job>();
        let (back, free) = channel::<Block>();
        let path = path.to_path_buf();
        let thread = std::thread::Builder::new()
            .name("mdlod-write".into())
            .spawn(move || write_jobs(&path, direct, rx, back))?;
        Ok(DirectSink {
            fill: Block::new(),
            len: 0,
            offset: 0,
            blocks: 1,
            jobs: Some(jobs),
            free,
            thread: Some(thread),
        })
    }

    /// Hands the block being filled to the thread and takes an empty one.
    fn send(&mut self) -> io::Result<()> {
        let next = match self.free.try_recv() {
            Ok(b) => b,
            Err(_) if self.blocks < BLOCKS => {
                self.blocks += 1;
                Block::new()
            }
            Err(_) => match self.free.recv() {
                Ok(b) => b,
                Err(_) => return Err(self.stopped()),
            },
        };
        let job = Job {
            block: std::mem::replace(&mut self.fill, next),
            len: self.len,
            offset: self.offset,
        };
        let sent = self.jobs.as_ref().map(|j| j.send(job));
        if !matches!(sent, Some(Ok(()))) {
            return Err(self.stopped());
        }
        self.offset += self.len as u64;
        self.len = 0;
        Ok(())
    }

    /// The error that stopped the writing thread.
    fn stopped(&mut self) -> io::Error {
        self.jobs = None;
        match self.thread.take().map(JoinHandle::join) {
            Some(Ok(Err(e))) => e,
            Some(Err(_)) => io::Error::other("the writing thread panicked"),
            _ => io::Error::other("the writing thread stopped"),
        }
    }
}

impl Sink for DirectSink {
    fn write_all(&mut self, mut bytes: &[u8]) -> io::Result<()> {
        while !bytes.is_empty() {
            let n = (BLOCK - self.len).min(bytes.len());
            self.fill.data_mut()[self.len..self.len + n].copy_from_slice(&bytes[..n]);
            self.len += n;
            bytes = &bytes[n..];
            if self.len == BLOCK {
                self.send()?;
            }
        }
        Ok(())
    }

    fn finish(mut self: Box<Self>) -> io::Result<File> {
        if self.len > 0 {
            self.send()?;
        }
        self.jobs = None;
        match self.thread.take().map(JoinHandle::join) {
            Some(Ok(r)) => r,
            Some(Err(_)) => Err(io::Error::other("the writing thread panicked")),
            None => Err(io::Error::other("the writing thread stopped")),
        }
    }
}

impl Drop for DirectSink {
    /// Unfinished (an error elsewhere): the thread writes what it was given and stops
    /// before the caller goes on to remove the file.
    fn drop(&mut self) {
        self.jobs = None;
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// `path` opened for writing with direct I/O; `None` where the filesystem refuses it.
fn open_direct(path: &Path) -> io::Result<Option<File>> {
    open_direct_with(OpenOptions::new().write(true), path)
}

#[cfg(target_os = "linux")]
fn open_direct_with(options: &mut OpenOptions, path: &Path) -> io::Result<Option<File>> {
    use std::os::unix::fs::OpenOptionsExt;
    match options.custom_flags(libc::O_DIRECT).open(path) {
        Ok(f) => Ok(Some(f)),
        Err(e) if refused(&e) => Ok(None),
        Err(e) => Err(e),
    }
}

#[cfg(not(target_os = "linux"))]
fn open_direct_with(_: &mut OpenOptions, _: &Path) -> io::Result<Option<File>> {
    Ok(None)
}

fn refused(e: &io::Error) -> bool {
    #[cfg(target_os = "linux")]
    {
        e.raw_os_error() == Some(libc::EINVAL)
    }
    #[cfg(not(target_os = "linux"))]
    {
        let _ = e;
        false
    }
}

/// Writes `data` (aligned, whole blocks) at `offset` through the direct handle: false
/// where there is none, or where the filesystem refuses it (the handle is then dropped
/// and the caller writes through an ordinary one).
fn write_direct(direct: &mut Option<File>, data: &[u8], offset: u64) -> io::Result<bool> {
    let Some(f) = direct else { return Ok(false) };
    match f.write_all_at(data, offset) {
        Ok(()) => Ok(true),
        Err(e) if refused(&e) => {
            *direct = None;
            Ok(false)
        }
        Err(e) => Err(e),
    }
}

/// The writing thread: whole aligned blocks through the direct handle, the rest (and
/// everything once direct I/O is refused) through an ordinary one, which it returns.
fn write_jobs(
    path: &PathBuf,
    mut direct: Option<File>,
    jobs: Receiver<Job>,
    back: Sender<Block>,
) -> io::Result<File> {
    let plain = OpenOptions::new().write(true).open(path)?;
    for job in jobs {
        let data = &job.block.data()[..job.len];
        let whole = job.len / ALIGN * ALIGN;
        let done = if whole > 0 && write_direct(&mut direct, &data[..whole], job.offset)? {
            whole
        } else {
            0
        };
        if done < job.len {
            plain.write_all_at(&data[done..], job.offset + done as u64)?;
        }
        // The sink may already be gone (finished or dropped).
        let _ = back.send(job.block);
    }
    Ok(plain)
}

/// Bytes of the scratch block an [`Appender`] copies through.
pub const SCRATCH: usize = 1 << 20;

/// A file written from the start by appending, in whole aligned blocks with direct I/O
/// where the filesystem allows.
pub struct Appender {
    path: PathBuf,
    direct: Option<File>,
    plain: Option<File>,
    /// Bytes after the last whole block written (fewer than `ALIGN`).
    tail: Vec<u8>,
    offset: u64,
}

impl Appender {
    /// Creates (or truncates) `path`; with `direct` false, through the page cache.
    pub fn create(path: &Path, direct: bool) -> io::Result<Appender> {
        let direct = if direct {
            open_direct_with(
                OpenOptions::new().write(true).create(true).truncate(true),
                path,
            )?
        } else {
            None
        };
        let plain = match direct {
            Some(_) => None,
            None => Some(File::create(path)?),
        };
        Ok(Appender {
            path: path.to_path_buf(),
            direct,
            plain,
            tail: Vec::with_capacity(ALIGN),
            offset: 0,
        })
    }

    fn plain(&mut self) -> io::Result<&File> {
        if self.plain.is_none() {
            self.plain = Some(OpenOptions::new().write(true).open(&self.path)?);
        }
        Ok(self.plain.as_ref().expect("opened above"))
    }

    /// Appends `bytes`: for direct I/O, copying them through `scratch` (a block of
    /// [`SCRATCH`] bytes); otherwise in one write.
    pub fn append(&mut self, mut bytes: &[u8], scratch: &mut Block) -> io::Result<()> {
        if self.direct.is_none() {
            let (offset, tail) = (self.offset, std::mem::take(&mut self.tail));
            let f = self.plain()?;
            f.write_all_at(&tail, offset)?;
            f.write_all_at(bytes, offset + tail.len() as u64)?;
            self.offset += (tail.len() + bytes.len()) as u64;
            return Ok(());
        }
        while !bytes.is_empty() {
            let s = scratch.data_mut();
            let t = self.tail.len();
            s[..t].copy_from_slice(&self.tail);
            let n = (s.len() - t).min(bytes.len());
            s[t..t + n].copy_from_slice(&bytes[..n]);
            bytes = &bytes[n..];
            let whole = (t + n) / ALIGN * ALIGN;
            self.tail.clear();
            self.tail.extend_from_slice(&s[whole..t + n]);
            if whole == 0 {
                continue;
            }
            let data = &scratch.data()[..whole];
            if !write_direct(&mut self.direct, data, self.offset)? {
                let offset = self.offset;
                self.plain()?.write_all_at(data, offset)?;
            }
            self.offset += whole as u64;
        }
        Ok(())
    }

    /// Closes an ordinary handle until the next append reopens it: for a caller
    /// appending to more files than may be open at once. A direct handle stays open.
    pub fn release(&mut self) {
        if self.direct.is_none() {
            self.plain = None;
        }
    }

    /// Writes the tail; the file then holds every byte appended.
    pub fn finish(mut self) -> io::Result<()> {
        if !self.tail.is_empty() {
            let (offset, tail) = (self.offset, std::mem::take(&mut self.tail));
            self.plain()?.write_all_at(&tail, offset)?;
        }
        Ok(())
    }
}

/// Descriptors left for everything but the files asked for in [`room_for_open_files`].
const OTHER_FILES: u64 = 256;

/// Whether `files` more files may stay open at once: when the soft open-file limit is too
/// low for them, it is raised as far as needed, if the hard limit allows.
pub fn room_for_open_files(files: usize) -> bool {
    use rustix::process::{getrlimit, setrlimit, Resource};
    let need = files as u64 + OTHER_FILES;
    let limit = getrlimit(Resource::Nofile);
    if limit.current.is_none_or(|c| c >= need) {
        return true;
    }
    if limit.maximum.is_some_and(|m| m < need) {
        return false;
    }
    let raised = rustix::process::Rlimit {
        current: Some(need),
        maximum: limit.maximum,
    };
    setrlimit(Resource::Nofile, raised).is_ok()
}

/// The first `len` bytes of the file at `path`, read with direct I/O where the filesystem
/// allows, into `buf` (grown as needed): the returned slice of it. Fewer bytes in the
/// file is an `UnexpectedEof` error.
pub fn read_whole<'b>(
    path: &Path,
    len: usize,
    buf: &'b mut Block,
    direct: bool,
) -> io::Result<&'b [u8]> {
    read_at(path, 0, len, buf, direct)
}

/// Bytes `offset..offset + len` of the file at `path`, as [`read_whole`] reads them (from
/// the aligned offset below `offset`); with `direct` false, through the page cache.
pub fn read_at<'b>(
    path: &Path,
    offset: u64,
    len: usize,
    buf: &'b mut Block,
    direct: bool,
) -> io::Result<&'b [u8]> {
    let skip = (offset % ALIGN as u64) as usize;
    let base = offset - skip as u64;
    let len = skip + len;
    let rounded = len.div_ceil(ALIGN) * ALIGN;
    if buf.len < rounded {
        *buf = Block::with_len(rounded);
    }
    let direct = if direct {
        open_direct_with(OpenOptions::new().read(true), path)?
    } else {
        None
    };
    let mut got = 0usize;
    if let Some(f) = &direct {
        let data = &mut buf.data_mut()[..rounded];
        loop {
            // Whole blocks from an aligned offset; the file's end may cut the last one.
            match f.read_at(&mut data[got..], base + got as u64) {
                Ok(0) => break,
                Ok(n) => {
                    got += n;
                    if got >= len || !got.is_multiple_of(ALIGN) {
                        break;
                    }
                }
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) if refused(&e) && got == 0 => break,
                Err(e) => return Err(e),
            }
        }
    }
    if got < len {
        // No direct I/O here (or it stopped short of `len`): the rest, read plainly.
        let f = File::open(path)?;
        f.read_exact_at(&mut buf.data_mut()[got..len], base + got as u64)?;
    }
    Ok(&buf.data()[skip..len])
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pattern(n: usize, seed: u64) -> Vec<u8> {
        let mut x = seed;
        (0..n)
            .map(|_| {
                x = x
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                (x >> 56) as u8
            })
            .collect()
    }

    #[test]
    fn writes_exactly_the_bytes_given_in_pieces_of_any_size() {
        let dir = tempfile::tempdir().unwrap();
        // Pieces straddling block and alignment boundaries, one larger than a block,
        // and an unaligned tail.
        let sizes = [1, ALIGN - 1, 3, BLOCK - 7, 2 * BLOCK + 5, 0, 12345, 64];
        let pieces: Vec<Vec<u8>> = sizes
            .iter()
            .enumerate()
            .map(|(i, &n)| pattern(n, i as u64))
            .collect();
        let path = dir.path().join("out");
        File::create(&path).unwrap();
        let mut sink: Box<dyn Sink> = open(&path).unwrap();
        for p in &pieces {
            sink.write_all(p).unwrap();
        }
        let mut file = sink.finish().unwrap();
        // The handle returned writes over what is there, as the header is written.
        use std::io::{Seek, SeekFrom, Write};
        file.seek(SeekFrom::Start(2)).unwrap();
        file.write_all(b"hd").unwrap();
        drop(file);
        let mut want: Vec<u8> = pieces.concat();
        want[2..4].copy_from_slice(b"hd");
        let got = std::fs::read(&path).unwrap();
        assert_eq!(got.len(), want.len());
        assert!(got == want, "contents differ");
    }

    #[test]
    fn an_appended_file_reads_back_whole() {
        // Direct and through the page cache alike.
        for direct in [true, false] {
            appended_file_reads_back_whole(direct);
        }
    }

    fn appended_file_reads_back_whole(direct: bool) {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("cell");
        let mut scratch = Block::with_len(SCRATCH);
        let mut a = Appender::create(&path, direct).unwrap();
        let sizes = [17, ALIGN, 3 * SCRATCH + 11, 0, ALIGN - 17, 5];
        let pieces: Vec<Vec<u8>> = sizes
            .iter()
            .enumerate()
            .map(|(i, &n)| pattern(n, 100 + i as u64))
            .collect();
        for p in &pieces {
            a.append(p, &mut scratch).unwrap();
        }
        a.finish().unwrap();
        let want = pieces.concat();
        assert!(std::fs::read(&path).unwrap() == want);
        // Read back whole, and a prefix, into a block too small at first.
        let mut buf = Block::with_len(1);
        assert!(read_whole(&path, want.len(), &mut buf, direct).unwrap() == want.as_slice());
        assert!(read_whole(&path, 100, &mut buf, direct).unwrap() == &want[..100]);
        // From unaligned offsets, to the end and short of it.
        for (at, n) in [
            (17usize, 5000usize),
            (ALIGN + 3, want.len() - ALIGN - 3),
            (want.len() - 1, 1),
        ] {
            assert!(read_at(&path, at as u64, n, &mut buf, direct).unwrap() == &want[at..at + n]);
        }
        let err = read_whole(&path, want.len() + 1, &mut buf, direct).unwrap_err();
        assert_eq!(err.kind(), io::ErrorKind::UnexpectedEof);
    }

    /// A block one byte off alignment: direct I/O on it is refused (`EINVAL`).
    fn misaligned(len: usize) -> Block {
        let mut b = Block::with_len(len + 1);
        b.start += 1;
        b.len = len;
        b
    }

    #[test]
    fn refused_direct_io_falls_back_to_ordinary_io() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("cell");
        let mut scratch = misaligned(SCRATCH);
        let mut a = Appender::create(&path, true).unwrap();
        let want = pattern(2 * SCRATCH + 99, 7);
        a.append(&want[..5000], &mut scratch).unwrap();
        a.append(&want[5000..], &mut scratch).unwrap();
        a.finish().unwrap();
        assert!(std::fs::read(&path).unwrap() == want);
        let mut buf = misaligned(want.len().div_ceil(ALIGN) * ALIGN);
        assert!(read_whole(&path, want.len(), &mut buf, true).unwrap() == want.as_slice());
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn an_error_of_the_writing_thread_reaches_the_caller() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out");
        File::create(&path).unwrap();
        let mut sink = DirectSink::open(&path).unwrap();
        // A block the thread cannot write: its file offset is past the largest file.
        sink.offset = u64::MAX - BLOCK as u64;
        sink.write_all(&[1u8; 100]).unwrap();
        let err = Box::new(sink).finish().unwrap_err();
        assert_eq!(err.raw_os_error(), Some(libc::EINVAL), "{err:?}");
    }
}
