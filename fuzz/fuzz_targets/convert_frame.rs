//! Fuzzes the converter on arbitrary particles: whatever the positions (NaN, infinities,
//! duplicates, the extremes of single precision), radii and build parameters,
//! `convert_frame` either refuses the frame, leaving no output, or writes a file that
//! opens and passes `verify` with every particle. The converter must never write a file
//! its own reader rejects.
//!
//! Input: a mode byte, a parameter byte, then 16 bytes per particle (at most 1024): the
//! position as three little-endian f32 and a species byte (two species) followed by three
//! bytes of an attribute value. Mode bits 0-1: cluster size 2, 4, 8 or 16; bit 2: 8-bit
//! positions; bits 3-4: δn 1-4; bit 5: an attribute; bit 6: built in chunks of 64
//! particles (out of core, root points 32); bit 7: the first particle's position bits
//! give the species radii instead (two f32).

#![no_main]

mod common;

use std::path::PathBuf;

use libfuzzer_sys::fuzz_target;
use mdlod_format::MdlodFile;
use mdlod_preprocess::chunked::ChunkOptions;
use mdlod_preprocess::convert::{convert_frame, ConvertOptions};
use mdlod_preprocess::hierarchy::BuildParams;
use mdlod_preprocess::{Attribute, Frame, NoProgress, SpeciesName};

const MAX_PARTICLES: usize = 1024;

fn f32_at(b: &[u8]) -> f32 {
    f32::from_le_bytes([b[0], b[1], b[2], b[3]])
}

fuzz_target!(|data: &[u8]| {
    let &[mode, param, ref rest @ ..] = data else {
        return;
    };
    let records: Vec<&[u8]> = rest.chunks_exact(16).take(MAX_PARTICLES).collect();
    let mut positions: Vec<[f32; 3]> = records
        .iter()
        .map(|r| [f32_at(&r[0..]), f32_at(&r[4..]), f32_at(&r[8..])])
        .collect();
    let species_index: Vec<u16> = records.iter().map(|r| u16::from(r[12] & 1)).collect();
    let mut radii = vec![("A".to_string(), 1.0f32), ("B".to_string(), 0.5f32)];
    if mode & 128 != 0 && !positions.is_empty() {
        let p = positions.remove(0);
        radii = vec![("A".to_string(), p[0]), ("B".to_string(), p[1])];
    }
    let n = positions.len();
    let attribute = (mode & 32 != 0).then(|| Attribute {
        name: "a".into(),
        values: records
            .iter()
            .rev()
            .take(n)
            .rev()
            .map(|r| f32::from_le_bytes([0, r[13], r[14], r[15]]))
            .collect(),
    });
    let frame = Frame {
        positions,
        species_index: species_index[species_index.len() - n..].to_vec(),
        species: ["A", "B"]
            .map(|name| SpeciesName {
                name: name.into(),
                numeric_type: false,
                radius: None,
                ..Default::default()
            })
            .to_vec(),
        attribute,
        ..Default::default()
    };
    let chunked = mode & 64 != 0;
    let opts = ConvertOptions {
        build: BuildParams {
            max_cluster_size: 2 << (mode & 3),
            max_root_points: if chunked { 32 } else { 16 + u32::from(param) },
            delta_n: 1 + u32::from((mode >> 3) & 3),
            position_bits: if mode & 4 != 0 { 8 } else { 16 },
        },
        // Radii that are not positive and finite are refused by the CLI's parser; the
        // library takes them as given.
        radii: radii
            .into_iter()
            .filter(|(_, r)| r.is_finite() && *r > 0.0)
            .collect(),
        chunks: ChunkOptions {
            chunk_points: if chunked { 64 } else { usize::MAX },
            memory_limit: 1 << 30,
            temp_dir: None,
            window_points: 64,
            gzip_in_memory: None,
        },
        radii_may_be_absent: true,
    };
    let path: PathBuf = common::temp_dir().join("fuzz.mdlod");
    let _ = std::fs::remove_file(&path);
    match convert_frame(&frame, None, &path, &opts, &NoProgress) {
        Err(e) => {
            let _ = e.to_string();
            assert!(!path.exists(), "a refused frame left {}", path.display());
        }
        Ok(report) => {
            let f = MdlodFile::open(&path)
                .unwrap_or_else(|e| panic!("the converter wrote a file it cannot open: {e}"));
            f.verify()
                .unwrap_or_else(|e| panic!("the converter wrote a file that fails verify: {e}"));
            assert_eq!(f.particle_count() as usize, n);
            assert_eq!(report.particles as usize, n);
        }
    }
});
