//! The one place in mdlod that memory-maps a file.

use std::fs::File;

/// A read-only file mapping (what [`map_file`] returns), and the access hints it takes.
pub use memmap2::{Advice, Mmap};

/// Maps `file` read-only.
///
/// Every reader in mdlod (the `.mdlod` reader and the dump readers) goes through here, so
/// the project holds exactly one `unsafe` block for file mapping.
pub fn map_file(file: &File) -> std::io::Result<memmap2::Mmap> {
    #[allow(unsafe_code)]
    // SAFETY: the mapping is read-only and every byte read from it is treated as untrusted
    // (lengths and offsets are validated before use, slices are produced with bytemuck's
    // checked casts). The remaining hazard of any file mapping — another process truncating
    // the file while it is mapped — would raise SIGBUS rather than give undefined values;
    // mdlod only maps files it does not write, and writers always replace files by rename,
    // which leaves existing mappings of the old inode intact.
    let map = unsafe { memmap2::Mmap::map(file)? };
    Ok(map)
}
