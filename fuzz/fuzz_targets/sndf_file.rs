//! Fuzzes the `.sndf` reader and the shading of what it accepts: whatever the bytes,
//! `SndfData::load` returns an error naming the file, or S-NDFs that save and read back
//! unchanged and that `shade_file` (what `mdlod shade` runs) turns into a picture or an
//! error naming the file; never a panic, a hang or an unbounded allocation.
//!
//! Input: one mode byte, then the file. Bit 0: recompute the data checksum first (random
//! bytes almost never match XXH3-64, so without it mutations stop at the checksum);
//! bits 1-2: shade at the display level, one level coarser, zoomed out 1.5×, or not at
//! all. Views of more than 2^20 pixels are read but not shaded (the shading of a file of
//! tiles is capped at 2^27 pixels, which takes seconds: too slow to fuzz). Seeds made by
//! `cargo run --example make_seeds` (one image, and S-MIP tiles) have mode 1.

#![no_main]

mod common;

use libfuzzer_sys::fuzz_target;
use mdlod_format::sndf::SndfData;
use mdlod_render::sndf::ShadeLights;
use mdlod_render::{Lighting, ShadeLevel};
use xxhash_rust::xxh3::xxh3_64;

/// Offset of the data checksum and of the JSON header's length in the fixed header.
const CHECKSUM_AT: usize = 16;
const JSON_LEN_AT: usize = 12;
const FIXED: usize = 24;

/// Recomputes the data checksum where the stated header length lies inside the bytes.
fn reseal(b: &mut [u8]) {
    if b.len() < FIXED {
        return;
    }
    let json = u32::from_le_bytes(b[JSON_LEN_AT..JSON_LEN_AT + 4].try_into().unwrap()) as usize;
    let start = (FIXED + json).div_ceil(16) * 16;
    if start <= b.len() {
        let sum = xxh3_64(&b[start..]);
        b[CHECKSUM_AT..CHECKSUM_AT + 8].copy_from_slice(&sum.to_le_bytes());
    }
}

fuzz_target!(|data: &[u8]| {
    let Some((&mode, file)) = data.split_first() else {
        return;
    };
    let mut bytes = file.to_vec();
    if mode & 1 != 0 {
        reseal(&mut bytes);
    }
    let dir = common::temp_dir();
    let path = dir.join("fuzz-input.sndf");
    std::fs::write(&path, &bytes).expect("write the input");
    let names = |message: String| {
        assert!(
            message.contains("fuzz-input.sndf"),
            "an error that does not name the file: {message}"
        )
    };
    let sndf = match SndfData::load(&path) {
        Ok(s) => s,
        Err(e) => return names(e.to_string()),
    };
    // What was accepted saves and reads back unchanged.
    let again = dir.join("fuzz-again.sndf");
    sndf.save(&again)
        .unwrap_or_else(|e| panic!("an accepted file does not save: {e}"));
    let back = SndfData::load(&again).unwrap_or_else(|e| panic!("a saved file is refused: {e}"));
    assert!(
        back.header == sndf.header
            && back.hist.len() == sndf.hist.len()
            && back
                .hist
                .iter()
                .zip(&sndf.hist)
                .all(|(a, b)| a.map(f32::to_bits) == b.map(f32::to_bits)),
        "the file read back differs"
    );
    let level = match (mode >> 1) & 3 {
        0 => ShadeLevel::Display,
        1 => ShadeLevel::Level(1),
        2 => ShadeLevel::ZoomOut(1.5),
        _ => return,
    };
    if u64::from(sndf.header.width) * u64::from(sndf.header.height) > 1 << 20 {
        return;
    }
    let lights = ShadeLights::from(&Lighting::default());
    let out = dir.join("fuzz-out.png");
    match mdlod_render::shade_file(&path, &out, &lights, [0.1, 0.1, 0.1], level) {
        Ok((w, h)) => assert!(w >= 1 && h >= 1, "an empty picture: {w}x{h}"),
        Err(e) => names(e.to_string()),
    }
});
