//! Fuzzes the dump readers (LAMMPS text dumps and XYZ, plain or gzip): whatever the bytes,
//! `DumpFile::open`, `frame_info` and `read_frame` must return a frame that is consistent
//! or an error whose message starts with the file's path, never panic.
//!
//! Input: one mode byte, then the file. Bits 0-1 of the mode byte pick the file name
//! (`.lammpstrj`, `.xyz`, `.xyz.gz` or no extension, which makes the reader sniff the
//! format); bit 2 asks for the attribute column `c_pe` (bit 3: `q`).

#![no_main]

mod common;

use std::path::PathBuf;

use common::{check_error, temp_dir, walk_frames, TEXT_NAMES};
use libfuzzer_sys::fuzz_target;
use mdlod_preprocess::readers::{DumpFile, ReadOptions};

fuzz_target!(|data: &[u8]| {
    let Some((&mode, text)) = data.split_first() else {
        return;
    };
    let path: PathBuf = temp_dir().join(TEXT_NAMES[usize::from(mode & 3)]);
    std::fs::write(&path, text).expect("write the input file");
    let attribute = match (mode >> 2) & 3 {
        1 => Some("c_pe".to_string()),
        2 => Some("q".to_string()),
        _ => None,
    };
    let opts = ReadOptions {
        attribute,
        ..Default::default()
    };
    match DumpFile::open(&path) {
        Ok(dump) => walk_frames(&dump, &opts, |e| check_error(e, &path), |_, _, _| {}),
        Err(e) => check_error(&e, &path),
    }
});
