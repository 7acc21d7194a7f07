//! Fuzzes the binary dump readers (LAMMPS binary dumps, GSD, MegaMol MMPLD, raw arrays
//! with a JSON sidecar): whatever the bytes, `DumpFile::open`, `frame_info`, `frame_species`, `read_frame` and
//! `read_part` must return frames that are consistent, or an error whose message starts
//! with the file's path; never panic, never allocate for particles the file cannot hold.
//!
//! Input: one mode byte, then the file. Bits 0-1 of the mode byte pick the file name
//! (`.bin`, `.gsd`, `.mmpld`, or no extension, which makes the reader sniff the format by
//! its magic bytes); bits 2-3 the attribute (`c_pe`, `charge`, `intensity` or none).
//! Bit 4 makes the file a raw-array sidecar (`.raw.json`) instead: the arrays it may name
//! lie beside it (`pos.f32`, `pos.f64`, `type.u8`, `pe.f32`; see [`ARRAYS`]).
//! Each frame read whole is also read in two parts, as the out-of-core converter reads
//! it, and the parts must add up to the frame.

#![no_main]

mod common;

use std::path::{Path, PathBuf};
use std::sync::Once;

use common::{check_frame, temp_dir, walk_frames};
use libfuzzer_sys::fuzz_target;
use mdlod_preprocess::readers::{DumpFile, ReadError, ReadOptions};
use mdlod_preprocess::NoProgress;

const NAMES: [&str; 4] = ["fuzz.bin", "fuzz.gsd", "fuzz.mmpld", "fuzz-input"];
const ATTRIBUTES: [Option<&str>; 4] = [None, Some("c_pe"), Some("charge"), Some("intensity")];

/// The arrays a fuzzed sidecar may name, written once beside it: 10 particles'
/// positions (interleaved) in single and double precision, species indices 0-2 and an
/// attribute.
const ARRAYS: [&str; 4] = ["pos.f32", "pos.f64", "type.u8", "pe.f32"];

/// The temporary directory, with [`ARRAYS`] in it.
fn dir() -> &'static Path {
    static ONCE: Once = Once::new();
    let dir = temp_dir();
    ONCE.call_once(|| {
        let values: Vec<f64> = (0..30).map(|i| f64::from(i) * 0.5).collect();
        let f32s: Vec<u8> = values
            .iter()
            .flat_map(|&v| (v as f32).to_le_bytes())
            .collect();
        let f64s: Vec<u8> = values.iter().flat_map(|&v| v.to_le_bytes()).collect();
        let types: Vec<u8> = (0..10).map(|i| i % 3).collect();
        for (name, bytes) in ARRAYS
            .iter()
            .zip([&f32s, &f64s, &types, &f32s[..40].to_vec()])
        {
            std::fs::write(dir.join(name), bytes).expect("write an array");
        }
    });
    dir
}

#[track_caller]
fn check_error(e: &ReadError, path: &Path) {
    // A sidecar's arrays are files of their own: an error in one names that file (a
    // missing one, a bad value's byte), which lies beside the sidecar.
    let beside = path.extension().is_some_and(|x| x == "json")
        && e.to_string().starts_with(&dir().display().to_string());
    if !beside {
        common::check_error(e, path);
    }
}

fuzz_target!(|data: &[u8]| {
    let Some((&mode, bytes)) = data.split_first() else {
        return;
    };
    let name = if mode & 16 != 0 {
        "fuzz.raw.json"
    } else {
        NAMES[usize::from(mode & 3)]
    };
    let path: PathBuf = dir().join(name);
    std::fs::write(&path, bytes).expect("write the input file");
    let opts = ReadOptions {
        attribute: ATTRIBUTES[usize::from((mode >> 2) & 3)].map(str::to_string),
        ..Default::default()
    };
    let dump = match DumpFile::open(&path) {
        Ok(d) => d,
        Err(e) => return check_error(&e, &path),
    };
    walk_frames(
        &dump,
        &opts,
        |e| check_error(e, &path),
        |k, info, whole| {
            if let Err(e) = dump.frame_species(k) {
                check_error(&e, &path);
            }
            if !dump.reads_parts() {
                return;
            }
            let n = info.particles;
            let mut read = 0;
            for range in [0..n / 3, n / 3..n] {
                match dump.read_part(k, &opts, range.clone(), &NoProgress) {
                    Err(e) => check_error(&e, &path),
                    Ok(part) => {
                        check_frame(&part, range.len(), &opts);
                        read += part.len();
                    }
                }
            }
            // Both parts of a frame that was read whole are readable.
            assert_eq!(read, whole.len());
            if let Err(e) = dump.read_part(k, &opts, n..n + 1, &NoProgress) {
                check_error(&e, &path);
            } else {
                panic!("a part past the frame's {n} particles was read");
            }
        },
    );
});
