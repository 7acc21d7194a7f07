//! Opening the files mdlod reads. Only regular files: opening a FIFO for reading blocks
//! until a writer comes (a `mkfifo` passed as an input hung every command), and a device
//! such as `/dev/zero` never ends (a view file of it grew the process without bound).
//! Files read whole (view files, manifests, images) are read under a size cap.

use std::fs::File;
use std::io::Read;
use std::path::Path;

/// Refuses a path that is not a regular file (following symbolic links), before anything
/// opens it: a directory, a FIFO, a socket or a device.
pub fn check_regular(path: &Path) -> std::io::Result<()> {
    check_kind(std::fs::metadata(path)?.file_type())
}

/// [`check_regular`] of a file's type (also what [`crate::mmap::map_file`] maps).
pub fn check_kind(kind: std::fs::FileType) -> std::io::Result<()> {
    if kind.is_dir() {
        return Err(std::io::Error::new(
            std::io::ErrorKind::IsADirectory,
            "is a directory, not a file",
        ));
    }
    if !kind.is_file() {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            "not a regular file (a pipe or a device cannot be read here: write it to a file \
             first)",
        ));
    }
    Ok(())
}

/// Refuses an output path that exists and is not a regular file: mdlod writes a whole
/// new file and renames it over the path, which would put a regular file in place of a
/// device (`-o /dev/null` run as root), a pipe, or a symbolic link (not the file it
/// points at). A path that does not exist yet, or a regular file, is fine, unless it is
/// read-only: a result its owner protected so would be replaced by the rename, which
/// needs only the directory to be writable ([`check_replaceable_kind`] leaves that to
/// the writer).
pub fn check_replaceable(path: &Path) -> std::io::Result<()> {
    check_replaceable_kind(path)?;
    match std::fs::symlink_metadata(path) {
        Ok(m) if m.permissions().readonly() => Err(std::io::Error::new(
            std::io::ErrorKind::PermissionDenied,
            "is read-only: make it writable (`chmod u+w`) or remove it to replace it",
        )),
        _ => Ok(()),
    }
}

/// [`check_replaceable`] of the kind of file alone, a read-only one passing: for a file
/// that may be kept as it is (a batch's finished frame).
pub fn check_replaceable_kind(path: &Path) -> std::io::Result<()> {
    let kind = match std::fs::symlink_metadata(path) {
        Ok(m) => m.file_type(),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
        Err(e) => return Err(e),
    };
    if kind.is_file() {
        return Ok(());
    }
    let what = if kind.is_dir() {
        "a directory"
    } else if kind.is_symlink() {
        "a symbolic link (the new file would replace the link, not the file it points at; \
         remove the link, or write to the file it points at)"
    } else {
        "not a regular file (a device or a pipe, which the new file would replace)"
    };
    Err(std::io::Error::new(
        std::io::ErrorKind::InvalidInput,
        format!("is {what}; the output must be a new or a regular file"),
    ))
}

/// Gives `new`, the file about to be renamed over `path`, the permissions of the file
/// there, where there is one: a result made private (0600) or shared with a group stays
/// so when a rerun replaces it. (Its owner becomes the one writing it, as with any
/// program that replaces a file by renaming.)
pub fn keep_permissions(path: &Path, new: &File) -> std::io::Result<()> {
    match std::fs::symlink_metadata(path) {
        Ok(m) if m.is_file() => {
            #[allow(unused_mut)]
            let mut permissions = m.permissions();
            // The read, write and execute bits only: a set-user-ID or set-group-ID bit
            // is not handed to new contents (as `cp` without `-p` does not).
            #[cfg(unix)]
            {
                use std::os::unix::fs::PermissionsExt;
                permissions.set_mode(permissions.mode() & 0o777);
            }
            new.set_permissions(permissions)
        }
        _ => Ok(()),
    }
}

/// An error of creating a temporary file or directory, without the name of the hidden
/// file it would have had (`tempfile` appends `at path ".../.mdlod-tmpXXXXXX"`): the
/// messages name the output or the directory it goes to instead.
pub fn temp_error(e: std::io::Error) -> std::io::Error {
    let text = e.to_string();
    match text.split_once(" at path \"") {
        Some((what, _)) => std::io::Error::new(e.kind(), what.to_string()),
        None => e,
    }
}

/// Opens `path` for reading if it is a regular file ([`check_regular`]).
pub fn open(path: &Path) -> std::io::Result<File> {
    check_regular(path)?;
    File::open(path)
}

/// Reads the regular file `path` whole if it holds at most `cap` bytes.
pub fn read_capped(path: &Path, cap: u64) -> std::io::Result<Vec<u8>> {
    let file = open(path)?;
    let too_large = |len: u64| {
        std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!("{len} bytes or more, past the {cap} bytes such a file may hold"),
        )
    };
    let len = file.metadata()?.len();
    if len > cap {
        return Err(too_large(len));
    }
    let mut bytes = Vec::with_capacity(len as usize);
    // (A file growing while it is read stops at the cap.)
    file.take(cap.saturating_add(1)).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > cap {
        return Err(too_large(bytes.len() as u64));
    }
    Ok(bytes)
}

/// [`read_capped`] as UTF-8 text.
pub fn read_capped_string(path: &Path, cap: u64) -> std::io::Result<String> {
    String::from_utf8(read_capped(path, cap)?).map_err(|e| {
        std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!("not UTF-8 text: {e}"),
        )
    })
}

/// The most bytes a JSON file mdlod reads whole may hold where nothing else bounds it
/// (a view file): far past any real one.
pub const SMALL_JSON: u64 = 1 << 20;

/// The most bytes a batch manifest may hold (a million frames take about 400 MB).
pub const MANIFEST_BYTES: u64 = 1 << 30;

#[cfg(test)]
mod tests {
    use super::*;

    /// The hidden temporary name `tempfile` appends to its errors is left out.
    #[test]
    fn temporary_files_errors_name_no_hidden_file() {
        let dir = tempfile::tempdir().unwrap();
        let missing = dir.path().join("missing");
        let e = tempfile::Builder::new()
            .prefix(".mdlod-tmp")
            .tempfile_in(&missing)
            .unwrap_err();
        assert!(e.to_string().contains(".mdlod-tmp"), "{e}");
        let kind = e.kind();
        let plain = temp_error(e);
        assert_eq!(plain.kind(), kind);
        assert!(!plain.to_string().contains(".mdlod-tmp"), "{plain}");
        assert!(plain.to_string().contains("No such file"), "{plain}");
    }

    #[test]
    fn only_regular_files_open_and_whole_reads_are_capped() {
        let dir = tempfile::tempdir().unwrap();
        let e = open(dir.path()).unwrap_err().to_string();
        assert_eq!(e, "is a directory, not a file");
        let e = open(Path::new("/dev/zero")).unwrap_err().to_string();
        assert!(e.starts_with("not a regular file"), "{e}");
        let fifo = dir.path().join("fifo");
        let made = std::process::Command::new("mkfifo").arg(&fifo).status();
        if made.is_ok_and(|s| s.success()) {
            // Refused before it is opened: opening would wait for a writer.
            let e = read_capped(&fifo, 10).unwrap_err().to_string();
            assert!(e.starts_with("not a regular file"), "{e}");
        }
        let path = dir.path().join("v.json");
        std::fs::write(&path, "0123456789").unwrap();
        assert_eq!(read_capped(&path, 10).unwrap(), b"0123456789");
        let e = read_capped(&path, 9).unwrap_err().to_string();
        assert!(e.contains("past the 9 bytes"), "{e}");
        std::fs::write(&path, [0xff, 0xfe]).unwrap();
        assert!(read_capped_string(&path, 10).is_err());
    }
}
