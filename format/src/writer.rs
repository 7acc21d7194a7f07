//! Streaming writer: sections are appended one after another to a temporary file beside
//! the target, each hashed while it is written; [`Writer::finish`] appends the section
//! table, writes the header, syncs and renames the file into place. Dropping a writer
//! without finishing removes the temporary file.
//!
//! The bytes go through a [`Sink`]: a buffered file by default, or one the caller
//! supplies ([`Writer::create_with`]), such as a writer that bypasses the page cache for
//! files of many gigabytes.

use std::fs::File;
use std::io::{BufWriter, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use xxhash_rust::xxh3::{xxh3_64, Xxh3};

use crate::error::FormatError;
use crate::layout::{
    align_up, Header, SectionEntry, SectionKind, FORMAT_VERSION, FORMAT_VERSION_1_2,
    FORMAT_VERSION_RADII, HEADER_SIZE, MAGIC,
};

/// Where a [`Writer`]'s bytes go: appended in order from the start of the file.
pub trait Sink: Send {
    /// Appends `bytes`. An error may also surface at a later call, for bytes appended
    /// before (a sink may write in the background).
    fn write_all(&mut self, bytes: &[u8]) -> std::io::Result<()>;

    /// Writes everything appended so far and returns a handle on the file, through which
    /// the writer fills in the header and syncs.
    fn finish(self: Box<Self>) -> std::io::Result<File>;
}

impl Sink for BufWriter<File> {
    fn write_all(&mut self, bytes: &[u8]) -> std::io::Result<()> {
        Write::write_all(self, bytes)
    }

    fn finish(self: Box<Self>) -> std::io::Result<File> {
        self.into_inner().map_err(|e| e.into_error())
    }
}

/// Writes one `.mdlod` file.
pub struct Writer {
    path: PathBuf,
    tmp: Option<tempfile::NamedTempFile>,
    out: Box<dyn Sink>,
    offset: u64,
    position_bits: u32,
    sections: Vec<SectionEntry>,
}

impl Writer {
    /// Starts writing `path` (created or replaced only by [`Writer::finish`]).
    pub fn create(path: &Path, position_bits: u32) -> Result<Writer, FormatError> {
        Writer::create_with(path, position_bits, |tmp| {
            let file = std::fs::OpenOptions::new().write(true).open(tmp)?;
            Ok(Box::new(BufWriter::with_capacity(1 << 20, file)))
        })
    }

    /// Like [`Writer::create`], with the bytes going to the sink `open` makes for the
    /// temporary file at the path it is given (created, empty).
    pub fn create_with(
        path: &Path,
        position_bits: u32,
        open: impl FnOnce(&Path) -> std::io::Result<Box<dyn Sink>>,
    ) -> Result<Writer, FormatError> {
        if position_bits != 8 && position_bits != 16 {
            return Err(FormatError::Write {
                path: path.into(),
                problem: format!("position bits must be 8 or 16, not {position_bits}"),
            });
        }
        crate::files::check_replaceable(path).map_err(|e| FormatError::io(path, e))?;
        let dir = match path.parent() {
            Some(d) if !d.as_os_str().is_empty() => d,
            _ => Path::new("."),
        };
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| "out".into());
        // The gate is held until the temporary file exists (see `refuse_new_outputs`).
        let gate = outputs_gate()?;
        let tmp = output_file_builder()
            .prefix(&temp_prefix(&name))
            .suffix(".tmp")
            .tempfile_in(dir)
            .map_err(|e| FormatError::io(dir, crate::files::temp_error(e)))?;
        drop(gate);
        let mut out = open(tmp.path()).map_err(|e| FormatError::io(path, e))?;
        out.write_all(&[0u8; HEADER_SIZE])
            .map_err(|e| FormatError::io(path, e))?;
        Ok(Writer {
            path: path.into(),
            tmp: Some(tmp),
            out,
            offset: HEADER_SIZE as u64,
            position_bits,
            sections: Vec::new(),
        })
    }

    /// The path errors name: the file being written (not its temporary stand-in, which
    /// is removed when writing fails), so a full disk reads `out.mdlod: No space left`.
    fn tmp_path(&self) -> PathBuf {
        self.path.clone()
    }

    fn pad_to_alignment(&mut self) -> Result<(), FormatError> {
        let aligned = align_up(self.offset).ok_or_else(|| FormatError::Write {
            path: self.path.clone(),
            problem: "file offset overflow".into(),
        })?;
        let pad = (aligned - self.offset) as usize;
        self.out
            .write_all(&[0u8; 64][..pad])
            .map_err(|e| FormatError::io(self.tmp_path(), e))?;
        self.offset = aligned;
        Ok(())
    }

    /// Begins a section; write its bytes through the returned writer, then call
    /// [`SectionWriter::end`].
    pub fn section(
        &mut self,
        kind: SectionKind,
        level: u32,
    ) -> Result<SectionWriter<'_>, FormatError> {
        self.pad_to_alignment()?;
        Ok(SectionWriter {
            start: self.offset,
            kind,
            level,
            hasher: Xxh3::new(),
            writer: self,
        })
    }

    /// Writes a whole section from one buffer.
    pub fn write_section(
        &mut self,
        kind: SectionKind,
        level: u32,
        bytes: &[u8],
    ) -> Result<(), FormatError> {
        let mut s = self.section(kind, level)?;
        s.write_bytes(bytes)?;
        s.end()
    }

    /// Writes a whole section of plain-old-data records.
    pub fn write_pod_section<T: bytemuck::NoUninit>(
        &mut self,
        kind: SectionKind,
        level: u32,
        items: &[T],
    ) -> Result<(), FormatError> {
        self.write_section(kind, level, bytemuck::cast_slice(items))
    }

    /// Appends the section table and header, syncs, and renames the file into place.
    pub fn finish(mut self) -> Result<(), FormatError> {
        self.pad_to_alignment()?;
        let table_offset = self.offset;
        let table: &[u8] = bytemuck::cast_slice(&self.sections);
        let table_checksum = xxh3_64(table);
        let tmp_path = self.tmp_path();
        self.out
            .write_all(table)
            .map_err(|e| FormatError::io(&tmp_path, e))?;
        let file_size = table_offset + table.len() as u64;
        // A file with per-particle radii is version 1.1; with radii on a log scale or
        // further attributes 1.2; any other 1.0.
        let has = |kind: SectionKind| self.sections.iter().any(|s| s.kind == kind as u32);
        let version = if has(SectionKind::RadiusLog) || has(SectionKind::Attributes) {
            FORMAT_VERSION_1_2
        } else if has(SectionKind::Radius) {
            FORMAT_VERSION_RADII
        } else {
            FORMAT_VERSION
        };
        let mut header = Header {
            magic: MAGIC,
            version_major: version.0,
            version_minor: version.1,
            flags: 0,
            section_count: self.sections.len() as u32,
            position_bits: self.position_bits,
            section_table_offset: table_offset,
            file_size,
            section_table_checksum: table_checksum,
            reserved: 0,
            header_checksum: 0,
        };
        header.header_checksum = xxh3_64(&bytemuck::bytes_of(&header)[..56]);
        let io = |e| FormatError::io(&tmp_path, e);
        let out = std::mem::replace(&mut self.out, Box::new(Finished));
        let mut file = out.finish().map_err(io)?;
        file.seek(SeekFrom::Start(0)).map_err(io)?;
        file.write_all(bytemuck::bytes_of(&header)).map_err(io)?;
        file.sync_all().map_err(io)?;
        let tmp = self
            .tmp
            .take()
            .expect("temporary file present until finish");
        crate::files::keep_permissions(&self.path, tmp.as_file())
            .map_err(|e| FormatError::io(&self.path, e))?;
        tmp.persist(&self.path)
            .map_err(|e| FormatError::io(&self.path, e.error))?;
        Ok(())
    }
}

/// Stands in for a sink that has been finished.
struct Finished;

impl Sink for Finished {
    fn write_all(&mut self, _: &[u8]) -> std::io::Result<()> {
        Err(std::io::Error::other("the file was already finished"))
    }

    fn finish(self: Box<Self>) -> std::io::Result<File> {
        Err(std::io::Error::other("the file was already finished"))
    }
}

/// Writes the bytes of one section; hashes them on the way.
pub struct SectionWriter<'w> {
    writer: &'w mut Writer,
    start: u64,
    kind: SectionKind,
    level: u32,
    hasher: Xxh3,
}

impl SectionWriter<'_> {
    pub fn write_bytes(&mut self, bytes: &[u8]) -> Result<(), FormatError> {
        self.hasher.update(bytes);
        let path = self.writer.tmp_path();
        self.writer
            .out
            .write_all(bytes)
            .map_err(|e| FormatError::io(path, e))?;
        self.writer.offset += bytes.len() as u64;
        Ok(())
    }

    /// Writes a slice of plain-old-data records.
    pub fn write_pod<T: bytemuck::NoUninit>(&mut self, items: &[T]) -> Result<(), FormatError> {
        self.write_bytes(bytemuck::cast_slice(items))
    }

    pub fn end(self) -> Result<(), FormatError> {
        let entry = SectionEntry {
            kind: self.kind as u32,
            level: self.level,
            offset: self.start,
            length: self.writer.offset - self.start,
            checksum: self.hasher.digest(),
        };
        self.writer.sections.push(entry);
        Ok(())
    }
}

/// Whether new `.mdlod` files may begin: `false` once [`refuse_new_outputs`] ran.
static OUTPUTS_OPEN: std::sync::RwLock<bool> = std::sync::RwLock::new(true);

/// Makes every later [`Writer::create`] fail (with [`FormatError::OutputsRefused`]), after
/// waiting for those under way to have created their temporary files. A program being
/// interrupted calls it before it removes its temporary outputs, so that none of its
/// other threads begins one after them. For the life of the process: there is no undo.
pub fn refuse_new_outputs() {
    *OUTPUTS_OPEN.write().unwrap_or_else(|e| e.into_inner()) = false;
}

/// Held while a temporary output file is created: shared by writers, taken whole by
/// [`refuse_new_outputs`].
fn outputs_gate() -> Result<std::sync::RwLockReadGuard<'static, bool>, FormatError> {
    let open = OUTPUTS_OPEN.read().unwrap_or_else(|e| e.into_inner());
    if *open {
        Ok(open)
    } else {
        Err(FormatError::OutputsRefused)
    }
}

/// A builder of the temporary file a finished output is renamed from: created with the
/// permissions any new file gets (0666 less the user's umask: 0644 usually, 0600 under
/// `umask 077`, 0664 for a group's shared space), not a temporary file's private 0600.
pub fn output_file_builder<'a, 'b>() -> tempfile::Builder<'a, 'b> {
    #[allow(unused_mut)]
    let mut builder = tempfile::Builder::new();
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        builder.permissions(std::fs::Permissions::from_mode(0o666));
    }
    builder
}

/// This host's name as the names of temporary files and working directories carry it
/// (from `/proc/sys/kernel/hostname`; `host` where it cannot be read or holds other
/// characters than letters, digits, `-` and `.`).
pub fn host_name() -> &'static str {
    static HOST: std::sync::OnceLock<String> = std::sync::OnceLock::new();
    HOST.get_or_init(|| {
        std::fs::read_to_string("/proc/sys/kernel/hostname")
            .map(|h| h.trim().to_string())
            .ok()
            .filter(|h| {
                !h.is_empty()
                    && h.chars()
                        .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '.')
            })
            .unwrap_or_else(|| "host".into())
    })
}

/// The start of the temporary file's name for an output named `name`:
/// `.NAME.HOST-PID-`, followed by six random letters or digits and `.tmp`. The host and
/// process let a later run tell the file of a killed process from a live one's.
pub fn temp_prefix(name: &str) -> String {
    format!(
        ".{}.{}-{}-",
        temp_name(name),
        host_name(),
        std::process::id()
    )
}

/// The output's name as its temporary file's name holds it: at most [`TEMP_NAME_BYTES`]
/// bytes of it (cut at a character's boundary), so that a name near the file system's
/// 255-byte limit still leaves room for the host, process and random letters.
fn temp_name(name: &str) -> &str {
    let mut end = name.len().min(TEMP_NAME_BYTES);
    while !name.is_char_boundary(end) {
        end -= 1;
    }
    &name[..end]
}

/// See [`temp_name`].
const TEMP_NAME_BYTES: usize = 120;

/// The process that wrote the temporary file `file_name` for the output named `name`,
/// where the name is `.NAME.HOST-PID-XXXXXX.tmp` with this host's name ([`host_name`]);
/// `None` for any other name (another host's, one without a process, not a writer's).
pub fn temp_file_owner(file_name: &str, name: &str) -> Option<u32> {
    let rest = file_name
        .strip_prefix('.')?
        .strip_prefix(temp_name(name))?
        .strip_prefix('.')?
        .strip_prefix(host_name())?
        .strip_prefix('-')?
        .strip_suffix(".tmp")?;
    pid_and_random(rest)
}

/// The process that wrote `file_name` where it is the temporary file of an output of any
/// name (`.NAME.HOST-PID-XXXXXX.tmp` with this host's name, [`temp_file_owner`]): what a
/// run killed outright left beside an output that no later run writes again.
pub fn any_temp_file_owner(file_name: &str) -> Option<u32> {
    let rest = file_name.strip_prefix('.')?.strip_suffix(".tmp")?;
    let at = rest.rfind(&format!(".{}-", host_name()))?;
    if at == 0 {
        return None;
    }
    pid_and_random(&rest[at + host_name().len() + 2..])
}

/// `PID-XXXXXX` (digits, then six random letters or digits, as `tempfile` makes them):
/// the process id.
pub fn pid_and_random(rest: &str) -> Option<u32> {
    let (pid, random) = rest.split_once('-')?;
    if pid.is_empty()
        || !pid.bytes().all(|b| b.is_ascii_digit())
        || random.len() != 6
        || !random.bytes().all(|b| b.is_ascii_alphanumeric())
    {
        return None;
    }
    pid.parse().ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An output named near the file system's 255-byte limit is written: its temporary
    /// file holds the first 120 bytes of the name (it failed, "File name too long", from
    /// about 235 bytes on), and is still told as this process's.
    #[test]
    fn a_long_output_name_leaves_room_for_the_temporary_files() {
        let dir = tempfile::tempdir().unwrap();
        let name = format!("{}é.mdlod", "x".repeat(119));
        assert!(!name.is_char_boundary(120));
        let long = format!("{}.mdlod", "y".repeat(244));
        for name in [name, long] {
            let path = dir.path().join(&name);
            let w = Writer::create(&path, 16).unwrap();
            let temp: Vec<String> = std::fs::read_dir(dir.path())
                .unwrap()
                .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                .filter(|n| n.ends_with(".tmp"))
                .collect();
            assert_eq!(temp.len(), 1, "{temp:?}");
            assert_eq!(temp_file_owner(&temp[0], &name), Some(std::process::id()));
            drop(w);
        }
    }

    #[test]
    fn temporary_files_are_named_after_host_and_process() {
        let dir = tempfile::tempdir().unwrap();
        let w = Writer::create(&dir.path().join("out.mdlod"), 16).unwrap();
        let names: Vec<String> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        assert_eq!(names.len(), 1, "{names:?}");
        assert_eq!(
            temp_file_owner(&names[0], "out.mdlod"),
            Some(std::process::id()),
            "{names:?}"
        );
        assert_eq!(temp_file_owner(&names[0], "out"), None);
        drop(w);
        let host = host_name();
        // Other hosts', other outputs' and names without a process are not owned.
        for other in [
            ".out.mdlod.abc123.tmp".to_string(),
            format!(".out.mdlod.{host}-x-12-abc123.tmp"),
            format!(".out.mdlod.{host}-12-abc12.tmp"),
            format!(".out.mdlod.{host}-12-abc123.tmp.x"),
            format!(".out.mdlod.other{host}-12-abc123.tmp"),
        ] {
            assert_eq!(temp_file_owner(&other, "out.mdlod"), None, "{other}");
            assert_eq!(any_temp_file_owner(&other), None, "{other}");
        }
        // Any output's name, a file of this host's.
        for (name, owner) in [
            (format!(".results v2.mdlod.{host}-12-aB3c9Z.tmp"), Some(12)),
            (format!(".frame-100.mdlod.{host}-7-abc123.tmp"), Some(7)),
            (format!(".dataset.{host}-7-abc123.tmp"), Some(7)),
            (format!(".{host}-7-abc123.tmp"), None),
            (format!("out.{host}-7-abc123.tmp"), None),
        ] {
            assert_eq!(any_temp_file_owner(&name), owner, "{name}");
        }
        assert_eq!(
            temp_file_owner(&format!(".out.mdlod.{host}-12-aB3c9Z.tmp"), "out.mdlod"),
            Some(12)
        );
    }
}
