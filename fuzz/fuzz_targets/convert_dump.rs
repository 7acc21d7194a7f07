//! Fuzzes whole conversions of text dumps, the way `mdlod convert` runs them: whatever
//! the bytes, `convert_file` either fails, leaving neither an output nor a working file
//! behind, or writes a file that opens and passes `verify`. Frames over 64 particles are
//! built out of core, read 16 atom lines at a time (the windowed text path), so the
//! partition, the chunk builds and the assembly all meet hostile input.
//!
//! Input: one mode byte, then the file. Bits 0-1 pick the file name (`.lammpstrj`,
//! `.xyz`, `.xyz.gz` or no extension); bit 2 asks for the attribute column `c_pe`; bit 3
//! converts the first frame instead of the last.

#![no_main]

mod common;

use std::path::PathBuf;

use common::{temp_dir, TEXT_NAMES};
use libfuzzer_sys::fuzz_target;
use mdlod_format::MdlodFile;
use mdlod_preprocess::chunked::ChunkOptions;
use mdlod_preprocess::convert::{convert_file, ConvertOptions, FrameSelect};
use mdlod_preprocess::hierarchy::BuildParams;
use mdlod_preprocess::readers::ReadOptions;
use mdlod_preprocess::NoProgress;

fuzz_target!(|data: &[u8]| {
    let Some((&mode, text)) = data.split_first() else {
        return;
    };
    // Input and output in a directory of their own, so that any file left is seen.
    let work = temp_dir().join("work");
    let _ = std::fs::remove_dir_all(&work);
    std::fs::create_dir_all(&work).expect("a working directory");
    let input: PathBuf = work.join(TEXT_NAMES[usize::from(mode & 3)]);
    std::fs::write(&input, text).expect("write the input file");
    let output = work.join("out.mdlod");
    let read = ReadOptions {
        attribute: (mode & 4 != 0).then(|| "c_pe".to_string()),
        ..Default::default()
    };
    let opts = ConvertOptions {
        build: BuildParams {
            max_root_points: 32,
            ..Default::default()
        },
        chunks: ChunkOptions {
            chunk_points: 64,
            memory_limit: 1 << 30,
            temp_dir: None,
            window_points: 16,
            gzip_in_memory: None,
        },
        ..Default::default()
    };
    let frame = if mode & 8 != 0 {
        FrameSelect::Index(0)
    } else {
        FrameSelect::Last
    };
    let left = || -> Vec<String> {
        std::fs::read_dir(&work)
            .expect("the working directory")
            .map(|e| {
                e.expect("an entry")
                    .file_name()
                    .to_string_lossy()
                    .into_owned()
            })
            .filter(|n| n != TEXT_NAMES[usize::from(mode & 3)])
            .collect()
    };
    match convert_file(&input, &output, frame, &read, &opts, &NoProgress) {
        Err(e) => {
            let _ = e.to_string();
            let left = left();
            assert!(left.is_empty(), "a failed conversion left {left:?}");
        }
        Ok(report) => {
            let f = MdlodFile::open(&output)
                .unwrap_or_else(|e| panic!("the converter wrote a file it cannot open: {e}"));
            f.verify()
                .unwrap_or_else(|e| panic!("the converter wrote a file that fails verify: {e}"));
            assert_eq!(f.particle_count(), report.particles);
            let left = left();
            assert_eq!(left, ["out.mdlod"], "working files left");
        }
    }
});
