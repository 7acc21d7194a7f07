//! MegaMol MMPLD reading, on files written here to the format's layout (versions 1.0 to
//! 1.3, every vertex and colour type): positions, species and radii per list, the
//! `intensity` and `radius` attributes, frames and their timestamps, reading in parts,
//! conversion, and damaged files; and on the MegaMol project's own test files, written by
//! MegaMol's MMPLD writer (`datasets/megamol/`).

use std::path::{Path, PathBuf};

use mdlod_format::MdlodFile;
use mdlod_preprocess::convert::{convert_file, ConvertOptions, FrameSelect};
use mdlod_preprocess::readers::{DumpFile, InputFormat, ReadOptions};
use mdlod_preprocess::NoProgress;

/// One particle list: vertex type, colour type, global radius, and per particle the
/// position, radius (`xyzr`) and intensity (intensity colours).
struct List {
    vertex: u8,
    colour: u8,
    radius: f32,
    particles: Vec<([f64; 3], f32, f64)>,
}

fn list(vertex: u8, colour: u8, radius: f32, n: usize, seed: f64) -> List {
    List {
        vertex,
        colour,
        radius,
        particles: (0..n)
            .map(|i| {
                let t = i as f64 + seed;
                (
                    [(t * 1.7) % 9.0, (t * 2.3) % 7.0, (t * 0.9) % 5.0].map(|v| v.round()),
                    0.5 + (i % 3) as f32 * 0.25,
                    t * 0.125,
                )
            })
            .collect(),
    }
}

/// An MMPLD file of `frames` as the format lays it out (with the seek table's end entry
/// writers add, and cluster information in version 1.1).
fn write(version: u16, frames: &[Vec<List>]) -> Vec<u8> {
    let mut out = Vec::new();
    out.extend_from_slice(b"MMPLD\0");
    out.extend_from_slice(&version.to_le_bytes());
    out.extend_from_slice(&(frames.len() as u32).to_le_bytes());
    for v in [-1.0f32, -1.0, -1.0, 10.0, 8.0, 6.0] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    for v in [-2.0f32, -2.0, -2.0, 11.0, 9.0, 7.0] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    let table = out.len();
    out.resize(table + 8 * (frames.len() + 1), 0);
    for (k, lists) in frames.iter().enumerate() {
        let at = out.len() as u64;
        out[table + 8 * k..table + 8 * k + 8].copy_from_slice(&at.to_le_bytes());
        if version >= 102 {
            out.extend_from_slice(&(0.5 * k as f32).to_le_bytes());
        }
        out.extend_from_slice(&(lists.len() as i32).to_le_bytes());
        for l in lists {
            out.extend_from_slice(&[l.vertex, l.colour]);
            if l.vertex != 2 {
                out.extend_from_slice(&l.radius.to_le_bytes());
            }
            match l.colour {
                0 => out.extend_from_slice(&[200, 100, 50, 255]),
                3 | 7 => {
                    out.extend_from_slice(&0f32.to_le_bytes());
                    out.extend_from_slice(&100f32.to_le_bytes());
                }
                _ => {}
            }
            out.extend_from_slice(&(l.particles.len() as u64).to_le_bytes());
            if version == 103 {
                for v in [0f32, 0.0, 0.0, 9.0, 7.0, 5.0] {
                    out.extend_from_slice(&v.to_le_bytes());
                }
            }
            for &(p, r, intensity) in &l.particles {
                match l.vertex {
                    1 | 2 => p
                        .iter()
                        .for_each(|&v| out.extend_from_slice(&(v as f32).to_le_bytes())),
                    3 => p
                        .iter()
                        .for_each(|&v| out.extend_from_slice(&(v as i16).to_le_bytes())),
                    _ => p
                        .iter()
                        .for_each(|&v| out.extend_from_slice(&v.to_le_bytes())),
                }
                if l.vertex == 2 {
                    out.extend_from_slice(&r.to_le_bytes());
                }
                match l.colour {
                    1 => out.extend_from_slice(&[1, 2, 3]),
                    2 => out.extend_from_slice(&[1, 2, 3, 4]),
                    3 => out.extend_from_slice(&(intensity as f32).to_le_bytes()),
                    4 => (0..3).for_each(|_| out.extend_from_slice(&0.5f32.to_le_bytes())),
                    5 => (0..4).for_each(|_| out.extend_from_slice(&0.5f32.to_le_bytes())),
                    6 => (0..4).for_each(|_| out.extend_from_slice(&7u16.to_le_bytes())),
                    7 => out.extend_from_slice(&intensity.to_le_bytes()),
                    _ => {}
                }
            }
            if version == 101 {
                out.extend_from_slice(&2u32.to_le_bytes());
                out.extend_from_slice(&5u64.to_le_bytes());
                out.extend_from_slice(&[9; 5]);
            }
        }
    }
    let end = out.len() as u64;
    let k = frames.len();
    out[table + 8 * k..table + 8 * k + 8].copy_from_slice(&end.to_le_bytes());
    out
}

fn save(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    path
}

/// Every vertex type with the colour types around it, in two frames.
fn mixed() -> Vec<Vec<List>> {
    (0..2)
        .map(|k| {
            vec![
                list(1, 0, 1.25, 40, k as f64),
                list(2, 3, 0.0, 30, 3.0 + k as f64),
                list(3, 2, 0.5, 20, 5.0),
                list(4, 5, 2.0, 10, 7.0),
                list(1, 1, 1.0, 5, 1.0),
                list(1, 4, 1.0, 5, 2.0),
                list(4, 6, 1.0, 5, 3.0),
                list(3, 7, 1.0, 5, 4.0),
            ]
        })
        .collect()
}

#[test]
fn every_version_and_type_reads_positions_species_and_radii() {
    let dir = tempfile::tempdir().unwrap();
    let frames = mixed();
    for version in [100u16, 101, 102, 103] {
        let path = save(
            dir.path(),
            &format!("v{version}.mmpld"),
            &write(version, &frames),
        );
        let dump = DumpFile::open(&path).unwrap();
        assert_eq!(dump.format(), InputFormat::Mmpld);
        assert_eq!(dump.frame_count(), 2);
        assert!(dump.reads_parts());
        for k in 0..2 {
            let info = dump.frame_info(k).unwrap();
            assert_eq!(info.particles, 120);
            // MMPLD records no timestep (a batch numbers frames by position).
            assert_eq!(info.timestep, None);
            assert_eq!(info.time, (version >= 102).then_some(0.5 * k as f64));
            assert_eq!(info.columns, ["x", "y", "z", "radius", "intensity"]);
            let f = dump
                .read_frame(k, &ReadOptions::default(), &NoProgress)
                .unwrap();
            let expected: Vec<[f32; 3]> = frames[k]
                .iter()
                .flat_map(|l| l.particles.iter().map(|p| p.0.map(|v| v as f32)))
                .collect();
            assert_eq!(f.positions, expected, "version {version}, frame {k}");
            let ids: Vec<u16> = frames[k]
                .iter()
                .enumerate()
                .flat_map(|(l, list)| std::iter::repeat_n(l as u16, list.particles.len()))
                .collect();
            assert_eq!(f.species_index, ids);
            let radii: Vec<f32> = f.species.iter().map(|s| s.radius.unwrap()).collect();
            // The xyzr list: its particles' mean radius (0.5, 0.75, 1.0 repeating).
            let mean = frames[k][1].particles.iter().map(|p| p.1).sum::<f32>() / 30.0;
            assert_eq!(radii, [1.25, mean, 0.5, 2.0, 1.0, 1.0, 1.0, 1.0]);
            // Only the xyzr list's particles differ in radius: the conversion notes it.
            let ranges: Vec<Option<(f32, f32)>> =
                f.species.iter().map(|s| s.radius_range).collect();
            assert_eq!(ranges[1], Some((0.5, 1.0)));
            assert!(ranges
                .iter()
                .enumerate()
                .all(|(i, r)| i == 1 || r.is_none()));
            // The list with a global colour (colour type 0) gives its species that colour,
            // as MegaMol draws it; lists whose particles carry colours give the mean of
            // theirs, averaged as light (one colour each here: exactly it); intensity
            // lists none (the palette's).
            let colours: Vec<Option<[u8; 3]>> = f.species.iter().map(|s| s.colour).collect();
            assert_eq!(
                colours,
                [
                    Some([200, 100, 50]),
                    None,
                    Some([1, 2, 3]),
                    Some([128; 3]),
                    Some([1, 2, 3]),
                    Some([128; 3]),
                    Some([0; 3]),
                    None
                ]
            );
            let table = mdlod_preprocess::species::species_table(&f.species, &[]);
            let linear = [200u8, 100, 50].map(|c| {
                let v = f32::from(c) / 255.0;
                ((v + 0.055) / 1.055).powf(2.4)
            });
            for c in 0..3 {
                assert!((table[0].colour[c] - linear[c]).abs() < 1e-6);
            }
            assert_ne!(table[1].colour, table[0].colour);
            let names: Vec<&str> = f.species.iter().map(|s| s.name.as_str()).collect();
            assert_eq!(names, ["0", "1", "2", "3", "4", "5", "6", "7"]);
            let b = f.simulation_box.unwrap();
            assert_eq!(
                (b.origin, b.a[0], b.b[1], b.c[2]),
                ([-1.0; 3], 11.0, 9.0, 7.0)
            );
        }
    }
}

/// A header bounding box whose lower corner lies above its upper one (or not finite)
/// gives the frames no box, rather than a cell of negative size.
#[test]
fn an_inverted_bounding_box_gives_no_box() {
    let dir = tempfile::tempdir().unwrap();
    let frames = vec![vec![list(1, 3, 1.0, 12, 0.0)]];
    let mut bytes = write(103, &frames);
    // The box's lower x (after the magic, version and frame count), past its upper.
    bytes[12..16].copy_from_slice(&1e6f32.to_le_bytes());
    let path = save(dir.path(), "inverted.mmpld", &bytes);
    let dump = DumpFile::open(&path).unwrap();
    let f = dump
        .read_frame(0, &ReadOptions::default(), &NoProgress)
        .unwrap();
    assert!(f.simulation_box.is_none());
    assert!(dump.frame_info(0).unwrap().simulation_box.is_none());
    let good = save(dir.path(), "good.mmpld", &write(103, &frames));
    let dump = DumpFile::open(&good).unwrap();
    let f = dump
        .read_frame(0, &ReadOptions::default(), &NoProgress)
        .unwrap();
    assert!(f.simulation_box.is_some());
    // The box bounds the data, it is no periodic cell: --wrap moves nothing, and says so.
    let wrap = ReadOptions {
        wrap: true,
        ..Default::default()
    };
    let wrapped = dump.read_frame(0, &wrap, &NoProgress).unwrap();
    assert_eq!(wrapped.positions, f.positions);
    let notes = dump.frame_notes(0, &wrap);
    assert!(
        notes.iter().any(|n| n.contains("periodic along no axis")),
        "{notes:?}"
    );
}

#[test]
fn intensity_and_radius_attributes_come_from_the_lists_that_carry_them() {
    let dir = tempfile::tempdir().unwrap();
    let frames = vec![vec![list(1, 3, 1.0, 12, 0.0), list(4, 7, 1.0, 8, 1.0)]];
    let path = save(dir.path(), "i.mmpld", &write(103, &frames));
    let dump = DumpFile::open(&path).unwrap();
    let read = |a: &str| {
        dump.read_frame(
            0,
            &ReadOptions {
                attribute: Some(a.into()),
                ..Default::default()
            },
            &NoProgress,
        )
    };
    let f = read("intensity").unwrap();
    let a = f.attribute.unwrap();
    let expected: Vec<f32> = frames[0]
        .iter()
        .flat_map(|l| l.particles.iter().map(|p| p.2 as f32))
        .collect();
    assert_eq!((a.name.as_str(), a.values), ("intensity", expected));
    // A list's global radius is each of its particles' radius.
    let f = read("radius").unwrap();
    assert_eq!(f.attribute.unwrap().values, [1.0; 20]);
    let e = read("c_pe").unwrap_err().to_string();
    assert!(e.contains("available: x y z intensity"), "{e}");

    let frames = vec![vec![list(2, 0, 0.0, 9, 0.0)]];
    let path = save(dir.path(), "r.mmpld", &write(100, &frames));
    let f = DumpFile::open(&path)
        .unwrap()
        .read_frame(
            0,
            &ReadOptions {
                attribute: Some("radius".into()),
                ..Default::default()
            },
            &NoProgress,
        )
        .unwrap();
    let r: Vec<f32> = frames[0][0].particles.iter().map(|p| p.1).collect();
    assert_eq!(f.attribute.unwrap().values, r);
}

#[test]
fn parts_concatenate_to_the_frame_and_the_frame_converts() {
    let dir = tempfile::tempdir().unwrap();
    let path = save(dir.path(), "m.mmpld", &write(102, &mixed()));
    let dump = DumpFile::open(&path).unwrap();
    let whole = dump
        .read_frame(1, &ReadOptions::default(), &NoProgress)
        .unwrap();
    // Parts cut across lists.
    let mut positions = vec![];
    let mut ids = vec![];
    for start in (0..120).step_by(17) {
        let part = dump
            .read_part(
                1,
                &ReadOptions::default(),
                start..(start + 17).min(120),
                &NoProgress,
            )
            .unwrap();
        assert_eq!(part.species.len(), 8);
        positions.extend(part.positions);
        ids.extend(part.species_index);
    }
    assert_eq!((positions, ids), (whole.positions, whole.species_index));
    // Every part takes the whole frame's radii.
    assert_eq!(dump.frame_species(1).unwrap(), Some(whole.species.clone()));

    let f = convert_verified(&path, &dir.path().join("m.mdlod"));
    assert_eq!(f.particle_count(), 120);
    let radii: Vec<f32> = f.metadata().species.iter().map(|s| s.radius).collect();
    let expected: Vec<f32> = whole.species.iter().map(|s| s.radius.unwrap()).collect();
    assert_eq!(radii, expected);
}

/// Converts the last frame of `path` with the default options and checks the whole file.
fn convert_verified(path: &Path, out: &Path) -> MdlodFile {
    convert_file(
        path,
        out,
        FrameSelect::Last,
        &ReadOptions::default(),
        &ConvertOptions::default(),
        &NoProgress,
    )
    .unwrap();
    let f = MdlodFile::open(out).unwrap();
    f.verify().unwrap();
    f
}

fn damaged(dir: &Path, bytes: &[u8]) -> String {
    let path = save(dir, "bad.mmpld", bytes);
    let msg = match DumpFile::open(&path) {
        Err(e) => e.to_string(),
        Ok(d) => (0..d.frame_count())
            .find_map(|k| d.read_frame(k, &ReadOptions::default(), &NoProgress).err())
            .map(|e| e.to_string())
            .unwrap_or_default(),
    };
    if !msg.is_empty() {
        assert!(msg.starts_with(&path.display().to_string()), "{msg}");
    }
    msg
}

#[test]
fn damaged_files_are_errors_naming_the_byte() {
    let dir = tempfile::tempdir().unwrap();
    let good = write(101, &mixed());
    // Truncations anywhere: an error naming a byte, never a panic.
    let mut cut = 1;
    while cut < good.len() - 8 {
        let m = damaged(dir.path(), &good[..cut]);
        assert!(m.contains("byte "), "cut {cut}: {m}");
        cut += if cut < 200 { 3 } else { 97 };
    }
    let patch = |at: usize, bytes: &[u8]| {
        let mut b = good.clone();
        b[at..at + bytes.len()].copy_from_slice(bytes);
        damaged(dir.path(), &b)
    };
    assert!(patch(6, &104u16.to_le_bytes()).contains("MMPLD version 1.4"));
    assert!(patch(8, &u32::MAX.to_le_bytes()).contains("too short for their seek table"));
    assert!(patch(60, &u64::MAX.to_le_bytes())
        .contains("frame 0 starts at byte 18446744073709551615, past the file's end"));
    assert!(patch(60, &8u64.to_le_bytes()).contains("inside the header or the seek table"));
    assert!(patch(60, &0u64.to_le_bytes()).contains("seek-table entry is 0"));
    let frame0 = u64::from_le_bytes(good[60..68].try_into().unwrap()) as usize;
    let m = patch(frame0, &(-3i32).to_le_bytes());
    assert!(
        m.contains(&format!("byte {frame0}: frame 0 has -3 particle lists")),
        "{m}"
    );
    let list0 = frame0 + 4;
    assert!(patch(list0, &[9]).contains("vertex type 9"));
    assert!(patch(list0 + 1, &[8]).contains("colour type 8"));
    // Vertex 1, colour 0: radius (4), colour (4), then the count.
    let m = patch(list0 + 10, &u64::MAX.to_le_bytes());
    assert!(m.contains("run past the end of the file"), "{m}");
    assert!(patch(list0 + 2, &f32::NAN.to_le_bytes()).contains("radius NaN"));
    let first = list0 + 18;
    let m = patch(first + 4, &f32::NAN.to_le_bytes());
    assert!(
        m.contains(&format!(
            "byte {first}: frame 0, list 0: particle 0 has a position"
        )),
        "{m}"
    );
    assert!(damaged(dir.path(), b"MMPLE\0abc").contains("not an MMPLD file"));

    // Version 1.2 frames start with a timestamp, which must be a number.
    let v102 = write(102, &mixed());
    let frame0 = u64::from_le_bytes(v102[60..68].try_into().unwrap()) as usize;
    let mut bad = v102.clone();
    bad[frame0..frame0 + 4].copy_from_slice(&f32::NAN.to_le_bytes());
    let m = damaged(dir.path(), &bad);
    assert!(
        m.contains(&format!(
            "byte {frame0}: frame 0: timestamp NaN is not a finite number"
        )),
        "{m}"
    );
}

#[test]
fn a_frame_larger_than_a_chunk_streams_into_the_file_the_whole_frame_makes() {
    use mdlod_preprocess::chunked::ChunkOptions;
    use mdlod_preprocess::convert::{convert_frame, source_info, window_source};
    let dir = tempfile::tempdir().unwrap();
    // An xyzr list whose radii differ along it: a window alone would average others.
    let frames = vec![vec![
        list(1, 0, 1.0, 150, 0.0),
        list(2, 3, 0.0, 250, 1.0),
        list(4, 0, 0.8, 100, 2.0),
    ]];
    let path = save(dir.path(), "big.mmpld", &write(103, &frames));
    let dump = DumpFile::open(&path).unwrap();
    let info = dump.frame_info(0).unwrap();
    let read = ReadOptions::default();
    assert!(window_source(&dump, 0, &read, &info).is_some());
    let opts = ConvertOptions {
        build: mdlod_preprocess::hierarchy::BuildParams {
            max_root_points: 64,
            ..Default::default()
        },
        chunks: ChunkOptions {
            chunk_points: 120,
            memory_limit: 1 << 30,
            temp_dir: None,
            window_points: 64,
            gzip_in_memory: None,
        },
        ..Default::default()
    };
    let streamed = dir.path().join("streamed.mdlod");
    convert_file(
        &path,
        &streamed,
        FrameSelect::Last,
        &read,
        &opts,
        &NoProgress,
    )
    .unwrap();
    let whole = dir.path().join("whole.mdlod");
    let frame = dump.read_frame(0, &read, &NoProgress).unwrap();
    convert_frame(
        &frame,
        Some(source_info(&path, 0)),
        &whole,
        &opts,
        &NoProgress,
    )
    .unwrap();
    assert!(std::fs::read(&streamed).unwrap() == std::fs::read(&whole).unwrap());
    assert_eq!(
        MdlodFile::open(&streamed)
            .unwrap()
            .metadata()
            .build
            .chunk_points,
        Some(120)
    );
}

/// The MegaMol project's own sphere-renderer test files, written by MegaMol's MMPLD
/// writer (`datasets/megamol/README.md`): every vertex type and colour type it writes.
fn megamol_files() -> Vec<PathBuf> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../datasets/megamol");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "mmpld"))
        .collect();
    files.sort();
    files
}

#[test]
fn files_written_by_megamol_read_as_written_and_convert() {
    let files = megamol_files();
    assert_eq!(files.len(), 17, "{files:?}");
    let dir = tempfile::tempdir().unwrap();
    // Lists 1 to 3: five particles each along a box edge through (-2, -2, -2), at the
    // coordinates the writer's loop reaches in Perl doubles (2.0, less 0.2 each step),
    // stored as f32.
    let edge: Vec<f64> = std::iter::successors(Some(2.0f64), |x| Some(x - 0.2))
        .take(5)
        .collect();
    let mut expected: Vec<[f32; 3]> = vec![
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, 0.0, 1.0],
    ];
    for axis in 0..3 {
        for &v in &edge {
            let mut p = [-2.0f32; 3];
            p[axis] = v as f32;
            expected.push(p);
        }
    }
    let ids: Vec<u16> = [0u16, 1, 2, 3]
        .iter()
        .flat_map(|&l| std::iter::repeat_n(l, if l == 0 { 4 } else { 5 }))
        .collect();
    for path in &files {
        let name = path.file_stem().unwrap().to_str().unwrap().to_owned();
        let xyzr = name.starts_with("test_xyzr_");
        let intensity = name.contains("_int_");
        let dump = DumpFile::open(path).unwrap();
        assert_eq!(dump.format(), InputFormat::Mmpld, "{name}");
        assert_eq!(dump.frame_count(), 1, "{name}");
        let info = dump.frame_info(0).unwrap();
        assert_eq!(info.particles, 19, "{name}");
        assert_eq!(info.timestep, None, "{name}");
        assert_eq!(info.time, Some(f64::from(1.23f32)), "{name}");
        let mut columns = vec!["x", "y", "z"];
        if xyzr {
            columns.push("radius");
        }
        if intensity {
            columns.push("intensity");
        }
        assert_eq!(info.columns, columns, "{name}");

        let f = dump
            .read_frame(0, &ReadOptions::default(), &NoProgress)
            .unwrap();
        assert_eq!(f.positions, expected, "{name}");
        assert_eq!(f.species_index, ids, "{name}");
        let names: Vec<&str> = f.species.iter().map(|s| s.name.as_str()).collect();
        assert_eq!(names, ["0", "1", "2", "3"], "{name}");
        let radii: Vec<f32> = f.species.iter().map(|s| s.radius.unwrap()).collect();
        // List 0: the global radius 0.1, or the mean of its particles' radii 0.5, 0.2,
        // 0.3 and 0.4.
        let first = if xyzr { 0.35 } else { 0.1 };
        assert!((radii[0] - first).abs() < 1e-6, "{name}: {radii:?}");
        assert_eq!(radii[1..], [0.1; 3], "{name}");
        let b = f.simulation_box.unwrap();
        assert_eq!(
            (b.origin, b.a, b.b, b.c),
            ([-2.0; 3], [4.0, 0.0, 0.0], [0.0, 4.0, 0.0], [0.0, 0.0, 4.0]),
            "{name}"
        );

        // Only list 0 can carry intensities: asked for them, the error names the first
        // list that lacks them.
        let read = |attribute: &str| {
            dump.read_frame(
                0,
                &ReadOptions {
                    attribute: Some(attribute.into()),
                    ..Default::default()
                },
                &NoProgress,
            )
        };
        let e = read("intensity").unwrap_err().to_string();
        let lacking = if intensity { 1 } else { 0 };
        let want = format!("list {lacking} has no per-particle `intensity`");
        assert!(e.contains(&want), "{name}: {e}");
        assert!(e.contains(&name), "{name}: {e}");
        // List 0's own colours (RGB or RGBA of any type) are noted as not kept.
        let coloured = name.contains("_rgb");
        let notes = dump.frame_notes(0, &ReadOptions::default());
        assert_eq!(
            notes
                .iter()
                .any(|n| n.contains("list 0 carry colours of their own")),
            coloured,
            "{name}: {notes:?}"
        );
        // Radii: list 0's particles' own (xyzr) or its global one, the others' 0.1.
        let radii_read = read("radius").unwrap().attribute.unwrap().values;
        let own: &[f32] = if xyzr {
            &[0.5, 0.2, 0.3, 0.4]
        } else {
            &[0.1; 4]
        };
        assert_eq!(radii_read[..4], *own, "{name}");
        assert!(
            radii_read[4..].iter().all(|&r| r == 0.1),
            "{name}: {radii_read:?}"
        );

        let m = convert_verified(path, &dir.path().join(format!("{name}.mdlod")));
        assert_eq!(m.particle_count(), 19, "{name}");
        let stored: Vec<f32> = m.metadata().species.iter().map(|s| s.radius).collect();
        assert_eq!(stored, radii, "{name}");
    }
}

#[test]
fn seek_entries_pointing_back_into_a_frame_are_errors() {
    let dir = tempfile::tempdir().unwrap();
    let good = write(102, &mixed());
    let seek = |k: usize| u64::from_le_bytes(good[60 + 8 * k..68 + 8 * k].try_into().unwrap());
    let (frame0, frame1) = (seek(0), seek(1));
    // Every frame the same frame 0 (100 000 such entries made 10^10 lists of a 2 MB file).
    let mut bad = good.clone();
    bad[68..76].copy_from_slice(&frame0.to_le_bytes());
    let m = damaged(dir.path(), &bad);
    assert!(
        m.contains(&format!(
            "byte 68: frame 1 starts at byte {frame0}, before the end of frame 0 (byte {frame1})"
        )),
        "{m}"
    );
    // Frames in the wrong order, and a frame starting inside the one before.
    let mut bad = good.clone();
    bad[60..68].copy_from_slice(&frame1.to_le_bytes());
    bad[68..76].copy_from_slice(&frame0.to_le_bytes());
    assert!(damaged(dir.path(), &bad).contains("frame 1 starts at byte"));
    let mut bad = good.clone();
    bad[68..76].copy_from_slice(&(frame1 - 1).to_le_bytes());
    assert!(damaged(dir.path(), &bad).contains("before the end of frame 0"));
}

#[test]
fn f64_positions_past_the_single_precision_range_are_errors_naming_the_byte() {
    let dir = tempfile::tempdir().unwrap();
    // Vertex type 4 (x y z as f64), no colour: 24 bytes a particle after an 18-byte list
    // header.
    let mut bytes = write(100, &[vec![list(4, 0, 1.0, 10, 0.0)]]);
    let frame0 = u64::from_le_bytes(bytes[60..68].try_into().unwrap()) as usize;
    let particle3 = frame0 + 4 + 18 + 3 * 24;
    bytes[particle3 + 8..particle3 + 16].copy_from_slice(&1e39f64.to_le_bytes());
    let m = damaged(dir.path(), &bytes);
    assert!(
        m.contains(&format!(
            "byte {particle3}: frame 0, list 0: particle 3 has a position that is not finite \
             in single precision (1e39 is beyond"
        )),
        "{m}"
    );
}

/// A radius of zero or below from the file (a list's, or a particle's of an `xyzr` list)
/// is refused as a GSD diameter of zero is, naming the file, the frame and the list and
/// saying `--radius` gives it one (it became the default 0.5 unsaid, and a negative list
/// radius failed the opening whatever the overrides); with the override the conversion
/// succeeds, in one piece and in chunks.
#[test]
fn a_radius_of_zero_or_below_is_refused_unless_the_list_is_given_one() {
    let mut xyzr = list(2, 0, 0.0, 300, 2.0);
    xyzr.particles[5].1 = -1.0;
    let frames = vec![vec![
        list(1, 0, 0.0, 300, 0.0),
        list(1, 0, -2.0, 300, 1.0),
        xyzr,
        list(1, 0, 0.4, 300, 3.0),
    ]];
    let dir = tempfile::tempdir().unwrap();
    let path = save(dir.path(), "r0.mmpld", &write(102, &frames));
    let out = dir.path().join("r0.mdlod");
    let convert = |radii: &[(&str, f32)], chunk_points: usize| {
        let mut options = ConvertOptions {
            radii: radii.iter().map(|(n, r)| (n.to_string(), *r)).collect(),
            ..Default::default()
        };
        options.chunks.chunk_points = chunk_points;
        options.build.max_root_points = 64;
        convert_file(
            &path,
            &out,
            FrameSelect::Last,
            &ReadOptions::default(),
            &options,
            &NoProgress,
        )
        .map(|_| {
            MdlodFile::open(&out)
                .unwrap()
                .metadata()
                .species
                .iter()
                .map(|s| s.radius)
                .collect::<Vec<_>>()
        })
        .map_err(|e| e.to_string())
    };
    let refused = |list: usize, radius: &str| {
        format!(
            "{}: frame 0, list {list}: the file gives radius {radius}, and a radius must be a \
             positive number; give the list its radius with --radius {list}=R",
            path.display()
        )
    };
    for chunk_points in [1 << 22, 500] {
        assert_eq!(convert(&[], chunk_points), Err(refused(0, "0")));
        assert_eq!(convert(&[("0", 0.3)], chunk_points), Err(refused(1, "-2")));
        // An `xyzr` list's particle of radius -1 among others of their own sizes is
        // named where the frame is built whole.
        let named = match chunk_points {
            500 => refused(2, "-1"),
            _ => format!(
                "{}: frame 0, list 2: the file gives radius -1 (particle 605 in the frame's \
                 order, counting from 0, is the first), and a radius must be a positive number; give the list \
                 its radius with --radius 2=R (every particle of it then takes R, those of \
                 usable sizes too: where their sizes matter, mend the unusable ones in the \
                 input instead)",
                path.display()
            ),
        };
        assert_eq!(convert(&[("0", 0.3), ("1", 0.2)], chunk_points), Err(named));
        assert!(!out.exists());
        assert_eq!(
            convert(&[("0", 0.3), ("1", 0.2), ("2", 0.1)], chunk_points),
            Ok(vec![0.3, 0.2, 0.1, 0.4])
        );
        std::fs::remove_file(&out).unwrap();
    }
    // A list without particles draws nothing: its radius of zero refuses nothing (the
    // default 0.5 stands in).
    let frames = vec![vec![list(1, 0, 0.0, 0, 0.0), list(1, 0, 0.4, 300, 3.0)]];
    // (Written over the file `convert` reads.)
    save(dir.path(), "r0.mmpld", &write(102, &frames));
    for chunk_points in [1 << 22, 500] {
        assert_eq!(convert(&[], chunk_points), Ok(vec![0.5, 0.4]));
        std::fs::remove_file(&out).unwrap();
    }
}

/// Bytes after a frame's lists, up to where the seek table says the frame ends (the next
/// frame's start, or the end entry for the last frame), are passed over as MegaMol reads
/// a frame, with a note naming the frame and the bytes: padding a writer adds, or the
/// lists a count too low leaves out (2 lists, counted 1). A count too high runs into a
/// list header that the file does not hold, named with its frame and list.
#[test]
fn bytes_after_a_frames_lists_are_passed_over_as_megamol_does() {
    let dir = tempfile::tempdir().unwrap();
    let frames: Vec<Vec<List>> = (0..2)
        .map(|k| vec![list(1, 0, 0.5, 30, k as f64), list(1, 0, 0.8, 20, 2.0)])
        .collect();
    let good = write(103, &frames);
    assert_eq!(damaged(dir.path(), &good), "");
    let starts: Vec<usize> = (0..3)
        .map(|k| u64::from_le_bytes(good[60 + 8 * k..68 + 8 * k].try_into().unwrap()) as usize)
        .collect();
    // Frame k's count (after its timestamp), and where its first list ends: its header
    // (2 + 4 + 4 + 8 + 24 bytes) and 30 particles of 12 bytes.
    for k in 0..2 {
        let count = starts[k] + 4;
        let mut bad = good.clone();
        bad[count..count + 4].copy_from_slice(&1i32.to_le_bytes());
        let end = count + 4 + 42 + 30 * 12;
        assert_eq!(damaged(dir.path(), &bad), "");
        let path = save(dir.path(), "low.mmpld", &bad);
        let dump = DumpFile::open(&path).unwrap();
        for j in 0..2 {
            let frame = dump
                .read_frame(j, &ReadOptions::default(), &NoProgress)
                .unwrap();
            assert_eq!(frame.len(), if j == k { 30 } else { 50 });
            let notes = dump.frame_notes(j, &ReadOptions::default());
            let said = notes.iter().any(|n| {
                n.contains(&format!(
                    "frame {k} holds {} bytes after its lists, up to where the seek table says \
                     it ends: passed over, as MegaMol reads a frame",
                    starts[k + 1] - end
                ))
            });
            assert_eq!(said, j == k, "frame {j}: {notes:?}");
        }
    }
    // One frame counting 3 lists: the third's header lies past the end of the file.
    let one = write(103, &frames[..1]);
    let mut bad = one.clone();
    let count = u64::from_le_bytes(one[60..68].try_into().unwrap()) as usize + 4;
    bad[count..count + 4].copy_from_slice(&3i32.to_le_bytes());
    let m = damaged(dir.path(), &bad);
    assert!(
        m.ends_with(&format!(
            "byte {}: file truncated in the header of frame 0, list 2 ({} bytes)",
            one.len(),
            one.len()
        )),
        "{m}"
    );
}

/// A file a writer stopped inside its last frame, or before writing the last frames:
/// the complete frames read, the first missing one counts as a frame cut short (so that
/// converting the last frame says so, and a batch leaves it out), the later ones not.
#[test]
fn a_last_frame_cut_short_leaves_the_frames_before_it_readable() {
    let dir = tempfile::tempdir().unwrap();
    let frames: Vec<Vec<List>> = (0..3)
        .map(|k| vec![list(1, 0, 0.5, 20 + k, k as f64)])
        .collect();
    let good = write(102, &frames);
    let start = |k: usize| u64::from_le_bytes(good[60 + 8 * k..68 + 8 * k].try_into().unwrap());
    // Cut inside frame 2's particles.
    let inside = save(dir.path(), "inside.mmpld", &good[..start(2) as usize + 30]);
    // Cut inside frame 1: frame 2's seek-table entry lies past the end too.
    let earlier = save(dir.path(), "earlier.mmpld", &good[..start(1) as usize + 30]);
    // The seek table's entries for frames 1 and 2 still 0, the file ending after frame 0.
    let mut unwritten = good[..start(1) as usize].to_vec();
    unwritten[68..84].fill(0);
    let unwritten = save(dir.path(), "unwritten.mmpld", &unwritten);
    for (path, complete) in [(&inside, 2), (&unwritten, 1), (&earlier, 1)] {
        let d = DumpFile::open(path).unwrap();
        assert_eq!(d.frame_count(), complete + 1, "{}", path.display());
        for k in 0..complete {
            let f = d
                .read_frame(k, &ReadOptions::default(), &NoProgress)
                .unwrap();
            assert_eq!(f.positions.len(), 20 + k);
        }
        let e = d
            .read_frame(complete, &ReadOptions::default(), &NoProgress)
            .unwrap_err();
        assert!(e.cut_short(), "{e}");
        assert!(
            e.to_string().starts_with(&path.display().to_string()),
            "{e}"
        );
        // Converting the last frame says it is incomplete; the one before converts.
        let out = dir.path().join("out.mdlod");
        let convert = |frame| {
            convert_file(
                path,
                &out,
                frame,
                &ReadOptions::default(),
                &ConvertOptions::default(),
                &NoProgress,
            )
        };
        let last = convert(FrameSelect::Last);
        assert!(
            last.unwrap_err().to_string().contains("incomplete"),
            "{}",
            path.display()
        );
        convert(FrameSelect::Index(complete - 1)).unwrap();
        assert_eq!(
            MdlodFile::open(&out).unwrap().metadata().particles,
            20 + complete as u64 - 1
        );
    }
    // A file whose first frame is cut has nothing to read: an error.
    let first = save(dir.path(), "first.mmpld", &good[..start(0) as usize + 30]);
    assert!(DumpFile::open(&first).is_err());
}

/// A file that starts with MMPLD's signature is read as MMPLD whatever its name says (a
/// `.bin` was read as a LAMMPS binary dump: "negative atom count").
#[test]
fn the_signature_decides_over_the_name() {
    let dir = tempfile::tempdir().unwrap();
    let path = save(dir.path(), "frames.bin", &write(102, &mixed()));
    let d = DumpFile::open(&path).unwrap();
    assert_eq!(d.format(), InputFormat::Mmpld);
    assert_eq!(d.frame_count(), 2);
}

/// The seek table's end entry before where the last frame's lists end is an error naming
/// the table; an end entry of 0 (a writer that leaves it out) is not.
#[test]
fn an_end_entry_before_the_last_frames_end_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let good = write(102, &mixed());
    let table_end = 60 + 8 * 2;
    let patched = |v: u64| {
        let mut b = good.clone();
        b[table_end..table_end + 8].copy_from_slice(&v.to_le_bytes());
        save(dir.path(), "end.mmpld", &b)
    };
    let e = DumpFile::open(&patched(1300)).unwrap_err().to_string();
    assert!(
        e.contains(&format!(
            "byte {table_end}: the seek table's end entry says frame 1 ends at byte 1300"
        )),
        "{e}"
    );
    let d = DumpFile::open(&patched(0)).unwrap();
    assert_eq!(d.frame_count(), 2);
}
