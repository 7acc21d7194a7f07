//! What the dump-reading fuzz targets share: a temporary directory for the inputs, the
//! text dumps' file names, and the walk over a dump's first frames with its checks.
// (Each target uses part of it.)
#![allow(dead_code)]

use std::path::Path;
use std::sync::OnceLock;

use mdlod_preprocess::readers::{DumpFile, FrameInfo, ReadError, ReadOptions};
use mdlod_preprocess::{Frame, NoProgress};

/// Text dump names, picked by a mode byte's bits 0-1: format detection by name, or by
/// sniffing the first line without an extension.
pub const TEXT_NAMES: [&str; 4] = ["fuzz.lammpstrj", "fuzz.xyz", "fuzz.xyz.gz", "fuzz-input"];

/// A temporary directory for the whole run.
pub fn temp_dir() -> &'static Path {
    static DIR: OnceLock<tempfile::TempDir> = OnceLock::new();
    DIR.get_or_init(|| tempfile::tempdir().expect("temporary directory"))
        .path()
}

/// An error message must start with the path of the file it is about.
#[track_caller]
pub fn check_error(e: &ReadError, path: &Path) {
    let msg = e.to_string();
    let name = path.display().to_string();
    assert!(
        msg.starts_with(&name),
        "message does not start with the path: {msg}"
    );
}

/// A frame read must be internally consistent: `particles` particles, species indices
/// in range, the attribute asked for (GSD names it by its chunk: `particles/charge` for
/// `charge`) with a value per particle.
#[track_caller]
pub fn check_frame(frame: &Frame, particles: usize, opts: &ReadOptions) {
    let n = frame.len();
    assert_eq!(n, particles);
    assert_eq!(frame.species_index.len(), n);
    assert!(frame
        .species_index
        .iter()
        .all(|&s| usize::from(s) < frame.species.len()));
    if let Some(a) = &frame.attribute {
        assert_eq!(a.values.len(), n);
        let asked = opts.attribute.as_deref().expect("an attribute asked for");
        assert!(a.name == asked || a.name.ends_with(&format!("/{asked}")));
    }
}

/// Reads the first three frames of `dump` (and asks for one past the end), checking each
/// frame with [`check_frame`] and each error with `error`; `more` gets every frame read.
pub fn walk_frames(
    dump: &DumpFile,
    opts: &ReadOptions,
    error: impl Fn(&ReadError),
    mut more: impl FnMut(usize, &FrameInfo, &Frame),
) {
    let frames = dump.frame_count();
    assert!(dump.frame_timestep(frames).is_none());
    for k in 0..frames.min(3) {
        let _ = dump.frame_timestep(k);
        let info = match dump.frame_info(k) {
            Ok(info) => info,
            Err(e) => {
                error(&e);
                continue;
            }
        };
        match dump.read_frame(k, opts, &NoProgress) {
            Err(e) => error(&e),
            Ok(frame) => {
                check_frame(&frame, info.particles, opts);
                more(k, &info, &frame);
            }
        }
    }
    if let Err(e) = dump.read_frame(frames, opts, &NoProgress) {
        error(&e);
    }
}
