//! The one place in mdlod that memory-maps a file.

use std::fs::File;

/// A read-only file mapping (what [`map_file`] returns), and the access hints it takes.
pub use memmap2::{Advice, Mmap};

/// Maps `file` read-only. A directory, pipe or device is refused with an error that
/// says so (mapping one fails with the kernel's bare "No such device").
///
/// Every reader in mdlod (the `.mdlod` reader and the dump readers) goes through here, so
/// the project holds exactly one `unsafe` block for file mapping.
pub fn map_file(file: &File) -> std::io::Result<memmap2::Mmap> {
    crate::files::check_kind(file.metadata()?.file_type())?;
    #[allow(unsafe_code)]
    // SAFETY: the mapping is read-only and every byte read from it is treated as untrusted
    // (lengths and offsets are validated before use, slices are produced with bytemuck's
    // checked casts). The remaining hazard of any file mapping — another process truncating
    // the file while it is mapped — raises SIGBUS rather than give undefined values (the
    // `mdlod` binary's handler says so and exits); mdlod only maps files it does not
    // write, and its writers always replace files by rename, which leaves existing
    // mappings of the old inode intact.
    let map = unsafe { memmap2::Mmap::map(file)? };
    Ok(map)
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_directory_is_refused_by_name_not_as_a_missing_device() {
        let dir = tempfile::tempdir().unwrap();
        let file = std::fs::File::open(dir.path()).unwrap();
        let e = super::map_file(&file).unwrap_err();
        assert_eq!(e.kind(), std::io::ErrorKind::IsADirectory);
        assert!(e.to_string().contains("directory"), "{e}");
    }

    #[test]
    fn a_regular_file_maps() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("f");
        std::fs::write(&path, b"mdlod").unwrap();
        let map = super::map_file(&std::fs::File::open(&path).unwrap()).unwrap();
        assert_eq!(&map[..], b"mdlod");
    }
}
