//! GSD reading: a real file written by the `gsd` package (datasets/gsd/make-samples.py)
//! against extended XYZ files of the same particles, the schema's frame-0 fallback, and
//! damaged files.

use std::path::PathBuf;

use mdlod_datasets::gsd_sample_path;
use mdlod_preprocess::convert::{convert_file, ConvertOptions, FrameSelect};
use mdlod_preprocess::readers::{DumpFile, InputFormat, ReadOptions};
use mdlod_preprocess::NoProgress;

fn charge() -> ReadOptions {
    ReadOptions {
        attribute: Some("charge".into()),
        ..Default::default()
    }
}

#[test]
fn every_frame_matches_the_xyz_written_alongside() {
    let path = gsd_sample_path("hoomd_mixture.gsd");
    let gsd = DumpFile::open(&path).unwrap();
    assert_eq!(gsd.format(), InputFormat::Gsd);
    assert_eq!(gsd.frame_count(), 3);
    let info = gsd.frame_info(2).unwrap();
    assert_eq!(info.particles, 300);
    assert!(info.columns.contains(&"particles/charge".to_string()));
    for k in 0..3 {
        assert_eq!(gsd.frame_timestep(k), Some(100 * k as u64));
        // Frames 1 and 2 hold only positions, charges and the step: the box, types and
        // diameters come from frame 0.
        let g = gsd.read_frame(k, &charge(), &NoProgress).unwrap();
        let x = DumpFile::open(&gsd_sample_path(&format!("hoomd_mixture.{k}.xyz")))
            .unwrap()
            .read_frame(0, &charge(), &NoProgress)
            .unwrap();
        assert_eq!(g.timestep, x.timestep);
        assert_eq!(g.positions, x.positions, "frame {k}");
        let name = |f: &mdlod_preprocess::Frame, i: usize| {
            f.species[usize::from(f.species_index[i])].name.clone()
        };
        for i in 0..300 {
            assert_eq!(name(&g, i), name(&x, i));
        }
        assert_eq!(g.attribute.as_ref().unwrap().name, "particles/charge");
        assert_eq!(
            g.attribute.as_ref().unwrap().values,
            x.attribute.as_ref().unwrap().values
        );
        let (gb, xb) = (g.simulation_box.unwrap(), x.simulation_box.unwrap());
        for (a, b) in [gb.origin, gb.a, gb.b, gb.c]
            .iter()
            .flatten()
            .zip([xb.origin, xb.a, xb.b, xb.c].iter().flatten())
        {
            assert!((a - b).abs() < 1e-6, "box {a} vs {b}");
        }
        // Radii from the diameters (1.0 for A, 1.5 for B).
        let radii: Vec<_> = g
            .species
            .iter()
            .map(|s| (s.name.clone(), s.radius))
            .collect();
        assert_eq!(
            radii,
            [("A".to_string(), Some(0.5)), ("B".to_string(), Some(0.75))]
        );
    }
}

#[test]
fn conversion_keeps_the_gsd_radii_unless_overridden() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("m.mdlod");
    let convert = |radii: Vec<(String, f32)>| {
        convert_file(
            &gsd_sample_path("hoomd_mixture.gsd"),
            &out,
            FrameSelect::Last,
            &ReadOptions::default(),
            &ConvertOptions {
                radii,
                ..Default::default()
            },
            &NoProgress,
        )
        .unwrap();
        let f = mdlod_format::MdlodFile::open(&out).unwrap();
        f.verify().unwrap();
        assert_eq!(f.metadata().timestep, Some(200));
        f.metadata()
            .species
            .iter()
            .map(|s| s.radius)
            .collect::<Vec<_>>()
    };
    assert_eq!(convert(vec![]), [0.5, 0.75]);
    assert_eq!(convert(vec![("B".into(), 2.0)]), [0.5, 2.0]);
}

fn damaged(bytes: &[u8]) -> String {
    let dir = tempfile::tempdir().unwrap();
    let path: PathBuf = dir.path().join("bad.gsd");
    std::fs::write(&path, bytes).unwrap();
    let msg = match DumpFile::open(&path) {
        Err(e) => e.to_string(),
        Ok(d) => (0..d.frame_count())
            .find_map(|k| d.read_frame(k, &charge(), &NoProgress).err())
            .map(|e| e.to_string())
            .unwrap_or_default(),
    };
    if !msg.is_empty() {
        assert!(msg.starts_with(&path.display().to_string()), "{msg}");
    }
    msg
}

/// Byte offset of index entry `i`.
fn entry(bytes: &[u8], i: usize) -> usize {
    u64::from_le_bytes(bytes[8..16].try_into().unwrap()) as usize + 32 * i
}

#[test]
fn damaged_gsd_files_are_errors_naming_the_byte() {
    let good = std::fs::read(gsd_sample_path("hoomd_mixture.gsd")).unwrap();
    // Truncations anywhere: an error (or fewer intact frames), never a panic.
    let mut cut = 1;
    while cut < good.len() {
        let m = damaged(&good[..cut]);
        assert!(m.is_empty() || m.contains("byte "), "cut {cut}: {m}");
        cut += if cut < 300 { 7 } else { 331 };
    }
    assert!(damaged(&good[..100]).contains("truncated"));
    assert!(damaged(&good[..good.len() - 8]).contains("outside the file"));

    let mut bad = good.clone();
    bad[0] ^= 1;
    assert!(damaged(&bad).contains("not a GSD file"));
    let mut bad = good.clone();
    bad[112..117].copy_from_slice(b"other");
    assert!(damaged(&bad).contains("schema `other`: only the `hoomd` schema"));
    let mut bad = good.clone();
    let e0 = entry(&good, 0);
    bad[e0 + 30] = 42;
    assert!(damaged(&bad).contains("unknown chunk type 42"));
    let mut bad = good.clone();
    bad[e0 + 28..e0 + 30].copy_from_slice(&999u16.to_le_bytes());
    assert!(damaged(&bad).contains("name id 999"));

    // Values: a NaN position and a type id past the types, found through the index.
    let find = |name: &str, frame: u64| -> (usize, usize) {
        // Walk the index for the entry's data location.
        let names_at = u64::from_le_bytes(good[24..32].try_into().unwrap()) as usize;
        let names: Vec<&[u8]> = good[names_at..]
            .split(|&b| b == 0)
            .take_while(|s| !s.is_empty())
            .collect();
        let id = names.iter().position(|n| *n == name.as_bytes()).unwrap();
        (0..128)
            .map(|i| entry(&good, i))
            .find(|&at| {
                u64::from_le_bytes(good[at..at + 8].try_into().unwrap()) == frame
                    && usize::from(u16::from_le_bytes([good[at + 28], good[at + 29]])) == id
            })
            .map(|at| {
                (
                    at,
                    u64::from_le_bytes(good[at + 16..at + 24].try_into().unwrap()) as usize,
                )
            })
            .unwrap()
    };
    let (_, pos1) = find("particles/position", 1);
    let mut bad = good.clone();
    let p = pos1 + 12 * 7; // particle 7 of frame 1
    bad[p..p + 4].copy_from_slice(&f32::NAN.to_le_bytes());
    let m = damaged(&bad);
    assert!(
        m.contains("frame 1: particle 7") && m.contains(&format!("byte {p}")),
        "{m}"
    );
    let (_, typeid) = find("particles/typeid", 0);
    let mut bad = good.clone();
    bad[typeid + 4 * 3..typeid + 4 * 4].copy_from_slice(&5u32.to_le_bytes());
    let m = damaged(&bad);
    assert!(
        m.contains("particle 3 has type id 5, but there are 2 types"),
        "{m}"
    );

    // A particle count the positions do not back (4 × 10^9 particles claimed by a
    // 22 kB file): an error before anything is allocated for them, for the species
    // pass of the out-of-core converter as for reading.
    let (_, count) = find("particles/N", 0);
    let mut bad = good.clone();
    bad[count..count + 4].copy_from_slice(&u32::MAX.to_le_bytes());
    let expected = "frame 0: `particles/position` is 300 × 3, expected 4294967295 × 3";
    let m = damaged(&bad);
    assert!(m.contains(expected), "{m}");
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.gsd");
    std::fs::write(&path, &bad).unwrap();
    let d = DumpFile::open(&path).unwrap();
    let m = d.frame_species(0).unwrap_err().to_string();
    assert!(m.contains(expected), "{m}");

    // A count stored as a negative signed number (type 7, int32) is no count (it used to
    // read as an empty frame).
    let (at, count) = find("particles/N", 0);
    let mut bad = good.clone();
    bad[at + 30] = 7;
    bad[count..count + 4].copy_from_slice(&(-1i32).to_le_bytes());
    let m = damaged(&bad);
    assert!(
        m.contains(&format!(
            "byte {count}: frame 0: `particles/N` is -1, not a particle count"
        )),
        "{m}"
    );
}
