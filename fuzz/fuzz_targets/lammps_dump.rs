//! Fuzzes the dump readers (LAMMPS text dumps and XYZ, plain or gzip): whatever the bytes,
//! `DumpFile::open`, `frame_info` and `read_frame` must return a frame that is consistent
//! or an error whose message starts with the file's path, never panic.
//!
//! Input: one mode byte, then the file. Bits 0-1 of the mode byte pick the file name
//! (`.lammpstrj`, `.xyz`, `.xyz.gz` or no extension, which makes the reader sniff the
//! format); bit 2 asks for the attribute column `c_pe` (bit 3: `q`).

#![no_main]

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use libfuzzer_sys::fuzz_target;
use mdlod_preprocess::readers::{DumpFile, ReadError, ReadOptions};
use mdlod_preprocess::NoProgress;

const NAMES: [&str; 4] = ["fuzz.lammpstrj", "fuzz.xyz", "fuzz.xyz.gz", "fuzz-input"];

fn dir() -> &'static Path {
    static DIR: OnceLock<tempfile::TempDir> = OnceLock::new();
    DIR.get_or_init(|| tempfile::tempdir().expect("temporary directory"))
        .path()
}

#[track_caller]
fn check_error(e: &ReadError, path: &Path) {
    let msg = e.to_string();
    let name = path.display().to_string();
    assert!(
        msg.starts_with(&name),
        "message does not start with the path: {msg}"
    );
}

fuzz_target!(|data: &[u8]| {
    let Some((&mode, text)) = data.split_first() else {
        return;
    };
    let path: PathBuf = dir().join(NAMES[usize::from(mode & 3)]);
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
    let dump = match DumpFile::open(&path) {
        Ok(d) => d,
        Err(e) => return check_error(&e, &path),
    };
    let frames = dump.frame_count();
    assert!(dump.frame_timestep(frames).is_none());
    for k in 0..frames.min(3) {
        let _ = dump.frame_timestep(k);
        let info = match dump.frame_info(k) {
            Ok(info) => info,
            Err(e) => {
                check_error(&e, &path);
                continue;
            }
        };
        match dump.read_frame(k, &opts, &NoProgress) {
            Err(e) => check_error(&e, &path),
            Ok(frame) => {
                let n = frame.len();
                assert_eq!(n, info.particles);
                assert_eq!(frame.species_index.len(), n);
                assert!(frame
                    .species_index
                    .iter()
                    .all(|&s| usize::from(s) < frame.species.len()));
                if let Some(a) = &frame.attribute {
                    assert_eq!(a.values.len(), n);
                    assert_eq!(Some(&a.name), opts.attribute.as_ref());
                }
            }
        }
    }
    if let Err(e) = dump.read_frame(frames, &opts, &NoProgress) {
        check_error(&e, &path);
    }
});
