//! The `.mdlod` file format: a level-of-detail particle hierarchy laid out for memory
//! mapping. `FORMAT.md` at the repository root is the normative spec; this crate is its
//! reference implementation.
//!
//! How it works:
//! - [`layout`] holds the fixed-size little-endian records (header, section table entry,
//!   level, node) as `#[repr(C)]` plain-old-data types, so the reader can hand out
//!   zero-copy slices of the mapped file.
//! - [`writer::Writer`] streams sections into a temporary file next to the target,
//!   hashing as it goes, then writes the section table and header and renames the file
//!   into place: an interrupted write never leaves a file that looks complete.
//! - [`reader::MdlodFile`] maps a file, validates everything it will later index (header,
//!   section bounds with checked arithmetic, level and node ranges) in time linear in the
//!   node count, and then gives typed slices without copying. [`reader::MdlodFile::verify`]
//!   additionally checks every section checksum and decodes every point.
//!
//! This crate knows nothing of threads, command lines or GPUs.

pub mod error;
pub mod files;
pub mod layout;
pub mod meta;
pub mod mmap;
pub mod progress;
pub mod quantize;
pub mod reader;
pub mod sndf;
pub mod writer;

pub use error::FormatError;
pub use layout::{
    LevelRecord, NodeRecord, SectionKind, FORMAT_VERSION, FORMAT_VERSION_1_2, FORMAT_VERSION_RADII,
    MAGIC, MAX_EXTRA_ATTRIBUTES,
};
pub use meta::Metadata;
pub use progress::{NoProgress, Progress};
pub use reader::MdlodFile;
pub use writer::Writer;
