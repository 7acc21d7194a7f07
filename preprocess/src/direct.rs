//! Writing the output of an out-of-core conversion past the page cache.
//!
//! Out of core, a conversion writes gigabytes it does not read back (the output).
//! Through the page cache the kernel copies every byte into pages it must first
//! allocate; on this project's benchmark machine, a virtual machine, that copy ran at
//! about 1 GB/s and was most of the final write. With `O_DIRECT` (Linux) the disk reads
//! from this process's own buffers, which are reused. (The partition's cells, which are
//! read back, go through the page cache: there direct I/O was measured no faster.)
//!
//! How it works: [`DirectSink`] copies the caller's bytes into one of a few aligned
//! blocks; each full block goes to a thread of its own, which writes it at its offset
//! while the caller fills the next. An error is reported by the next call after the
//! thread met it. The last partial block goes through an ordinary handle, and so does
//! everything where the filesystem refuses direct I/O (`EINVAL`): the bytes in the file
//! are the same either way.

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
struct Block {
    buf: Vec<u8>,
    start: usize,
    len: usize,
}

impl Block {
    fn new() -> Block {
        Block::with_len(BLOCK)
    }

    /// A block of `len` bytes (zeroed).
    fn with_len(len: usize) -> Block {
        let buf = vec![0u8; len + ALIGN];
        // Always computable for bytes; were it not, direct I/O on this block would be
        // refused and go through the ordinary handle.
        let start = buf.as_ptr().align_offset(ALIGN).min(ALIGN);
        Block { buf, start, len }
    }

    fn data(&self) -> &[u8] {
        &self.buf[self.start..self.start + self.len]
    }

    fn data_mut(&mut self) -> &mut [u8] {
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
#[cfg(target_os = "linux")]
fn open_direct(path: &Path) -> io::Result<Option<File>> {
    use std::os::unix::fs::OpenOptionsExt;
    match OpenOptions::new()
        .write(true)
        .custom_flags(libc::O_DIRECT)
        .open(path)
    {
        Ok(f) => Ok(Some(f)),
        Err(e) if refused(&e) => Ok(None),
        Err(e) => Err(e),
    }
}

#[cfg(not(target_os = "linux"))]
fn open_direct(_: &Path) -> io::Result<Option<File>> {
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

    /// A block one byte off alignment: direct I/O on it is refused (`EINVAL`).
    fn misaligned(len: usize) -> Block {
        let mut b = Block::with_len(len + 1);
        b.start += 1;
        b.len = len;
        b
    }

    #[test]
    fn refused_direct_io_falls_back_to_ordinary_io() {
        // Blocks one byte off alignment, which direct I/O refuses (`EINVAL` on ext4):
        // the writing thread goes on through its ordinary handle, and the bytes are right.
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out");
        File::create(&path).unwrap();
        let want = pattern(2 * BLOCK + 99, 7);
        let (jobs, rx) = channel::<Job>();
        let (back, _free) = channel::<Block>();
        let mut offset = 0;
        for piece in want.chunks(BLOCK) {
            let mut block = misaligned(BLOCK);
            block.data_mut()[..piece.len()].copy_from_slice(piece);
            let len = piece.len();
            jobs.send(Job { block, len, offset }).unwrap();
            offset += len as u64;
        }
        drop(jobs);
        write_jobs(&path.clone(), open_direct(&path).unwrap(), rx, back).unwrap();
        assert!(std::fs::read(&path).unwrap() == want);
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
