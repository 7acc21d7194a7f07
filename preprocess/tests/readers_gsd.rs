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

/// A file cut short (a run killed while writing) keeps its complete frames: the frame
/// with a chunk past the end fails when read, naming it, and the file still opens.
#[test]
fn a_gsd_file_cut_short_keeps_its_complete_frames() {
    let good = std::fs::read(gsd_sample_path("hoomd_mixture.gsd")).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("cut.gsd");
    std::fs::write(&path, &good[..good.len() - 8]).unwrap();
    let d = DumpFile::open(&path).unwrap();
    assert_eq!(d.frame_count(), 3);
    let read: Vec<Result<_, String>> = (0..3)
        .map(|k| {
            d.read_frame(k, &ReadOptions::default(), &NoProgress)
                .map(|f| f.len())
                .map_err(|e| e.to_string())
        })
        .collect();
    let first_bad = read
        .iter()
        .position(Result::is_err)
        .expect("a damaged frame");
    assert!(first_bad >= 1, "{read:?}");
    assert!(read[..first_bad].iter().all(Result::is_ok), "{read:?}");
    for r in &read[first_bad..] {
        let e = r.as_ref().unwrap_err();
        assert!(
            e.starts_with(&path.display().to_string()) && e.contains("outside the file"),
            "{e}"
        );
    }
}

#[test]
fn frame_numbers_past_the_index_are_errors_not_billions_of_frames() {
    let good = std::fs::read(gsd_sample_path("hoomd_mixture.gsd")).unwrap();
    let e0 = entry(&good, 0);
    let slots = u64::from_le_bytes(good[16..24].try_into().unwrap());
    for frame in [slots, 1u64 << 40, u64::MAX] {
        let mut bad = good.clone();
        bad[e0..e0 + 8].copy_from_slice(&frame.to_le_bytes());
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bad.gsd");
        std::fs::write(&path, &bad).unwrap();
        let m = DumpFile::open(&path).unwrap_err().to_string();
        assert!(
            m.starts_with(&format!("{}: byte {e0}: ", path.display()))
                && m.contains(&format!(
                    "chunk of frame {frame}, but the index has room for {slots} entries"
                )),
            "{m}"
        );
    }
    // The last frame number the index has room for is read (its chunks missing from
    // the frames between fall back to frame 0's).
    let mut last = good.clone();
    last[e0..e0 + 8].copy_from_slice(&(slots - 1).to_le_bytes());
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("last.gsd");
    std::fs::write(&path, &last).unwrap();
    assert_eq!(DumpFile::open(&path).unwrap().frame_count(), slots as usize);
}

/// A GSD 2.0 file of one frame: `names` (0-separated) and `chunks` of
/// (name id, type code, N, M, data).
fn gsd_file(names: &[String], chunks: &[Chunk]) -> Vec<u8> {
    let chunks: Vec<_> = chunks.iter().map(|c| (0, c.clone())).collect();
    gsd_frames(names, &chunks)
}

/// A chunk: name id, type code, N, M, data.
type Chunk = (u16, u8, u64, u32, Vec<u8>);

/// A GSD 2.0 file of `chunks` of (frame, chunk).
fn gsd_frames(names: &[String], chunks: &[(u64, Chunk)]) -> Vec<u8> {
    let mut out = vec![0u8; 256];
    out[..8].copy_from_slice(&0x65DF_65DF_65DF_65DFu64.to_le_bytes());
    out[44..48].copy_from_slice(&(2u32 << 16).to_le_bytes());
    out[112..117].copy_from_slice(b"hoomd");
    let mut locations = Vec::new();
    for (_, c) in chunks {
        locations.push(out.len() as u64);
        out.extend_from_slice(&c.4);
    }
    let index_at = out.len() as u64;
    for ((frame, c), location) in chunks.iter().zip(&locations) {
        out.extend_from_slice(&frame.to_le_bytes());
        out.extend_from_slice(&c.2.to_le_bytes());
        out.extend_from_slice(&location.to_le_bytes());
        out.extend_from_slice(&c.3.to_le_bytes());
        out.extend_from_slice(&c.0.to_le_bytes());
        out.extend_from_slice(&[c.1, 0]);
    }
    let names_at = out.len() as u64;
    let mut list: Vec<u8> = names
        .iter()
        .flat_map(|n| [n.as_bytes(), b"\0"].concat())
        .collect();
    list.resize(list.len().div_ceil(64) * 64 + 64, 0);
    out.extend_from_slice(&list);
    out[8..16].copy_from_slice(&index_at.to_le_bytes());
    out[16..24].copy_from_slice(&(chunks.len() as u64).to_le_bytes());
    out[24..32].copy_from_slice(&names_at.to_le_bytes());
    out[32..40].copy_from_slice(&(list.len() as u64 / 64).to_le_bytes());
    out
}

#[test]
fn a_name_past_the_ids_an_entry_can_hold_is_no_chunk() {
    // Name ids are 16 bits: `particles/diameter`, 65537th name, has no chunk. Taken for
    // name id 65537 mod 65536 = 1, it was read as the positions (2 × 3 numbers).
    let mut names = vec!["particles/N".to_string(), "particles/position".to_string()];
    names.extend((2..65537).map(|i| format!("n{i}")));
    names.push("particles/diameter".into());
    assert_eq!(names[65537], "particles/diameter");
    let positions: Vec<u8> = [0.0f32, 1.0, 2.0, 3.0, 4.0, 5.0]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    let bytes = gsd_file(
        &names,
        &[
            (0, 3, 1, 1, 2u32.to_le_bytes().to_vec()),
            (1, 9, 2, 3, positions),
        ],
    );
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("names.gsd");
    std::fs::write(&path, &bytes).unwrap();
    let f = DumpFile::open(&path)
        .unwrap()
        .read_frame(0, &ReadOptions::default(), &NoProgress)
        .unwrap();
    assert_eq!(f.positions, [[0.0, 1.0, 2.0], [3.0, 4.0, 5.0]]);
    // Without diameters, the default radius 0.5.
    assert_eq!(f.species[0].radius, Some(0.5));
}

#[test]
fn f64_positions_past_the_single_precision_range_are_errors_naming_the_byte() {
    let good = std::fs::read(gsd_sample_path("hoomd_mixture.gsd")).unwrap();
    let names_at = u64::from_le_bytes(good[24..32].try_into().unwrap()) as usize;
    let id = good[names_at..]
        .split(|&b| b == 0)
        .position(|n| n == b"particles/position")
        .unwrap();
    let at = (0..128)
        .map(|i| entry(&good, i))
        .find(|&at| {
            u64::from_le_bytes(good[at..at + 8].try_into().unwrap()) == 0
                && usize::from(u16::from_le_bytes([good[at + 28], good[at + 29]])) == id
        })
        .unwrap();
    let location = u64::from_le_bytes(good[at + 16..at + 24].try_into().unwrap()) as usize;
    // Frame 0's positions again as f64 (type 10) at the end of the file, particle 5's y
    // made 1e39.
    let mut bad = good.clone();
    let end = bad.len();
    for i in 0..300 * 3 {
        let v = f32::from_le_bytes(
            good[location + 4 * i..location + 4 * i + 4]
                .try_into()
                .unwrap(),
        );
        let v = if i == 5 * 3 + 1 { 1e39 } else { f64::from(v) };
        bad.extend_from_slice(&v.to_le_bytes());
    }
    bad[at + 16..at + 24].copy_from_slice(&(end as u64).to_le_bytes());
    bad[at + 30] = 10;
    let m = damaged(&bad);
    let byte = end + 8 * (5 * 3 + 1);
    assert!(
        m.contains(&format!(
            "byte {byte}: frame 0: particle 5 has a position that is not finite in single \
             precision (1e39 is beyond"
        )),
        "{m}"
    );
}

/// The data location of chunk `name` of frame `frame` in a GSD file's bytes.
fn chunk_data(bytes: &[u8], name: &str, frame: u64) -> usize {
    let u64_at = |at: usize| u64::from_le_bytes(bytes[at..at + 8].try_into().unwrap()) as usize;
    let names: Vec<&[u8]> = bytes[u64_at(24)..]
        .split(|&b| b == 0)
        .take_while(|s| !s.is_empty())
        .collect();
    let id = names.iter().position(|n| *n == name.as_bytes()).unwrap();
    (0..128)
        .map(|i| u64_at(8) + 32 * i)
        .find(|&at| {
            u64_at(at) as u64 == frame
                && usize::from(u16::from_le_bytes([bytes[at + 28], bytes[at + 29]])) == id
        })
        .map(|at| u64_at(at + 16))
        .unwrap()
}

/// A frame-0 chunk sized for other particles than frame 0's `particles/N` is an error
/// in the frames that take it, as in frame 0: it used to be passed over for the schema's
/// default in later frames (every particle of type A, the sizes still of both types).
#[test]
fn a_frame_0_chunk_of_the_wrong_length_is_an_error_in_frames_taking_it() {
    let mut bytes = std::fs::read(gsd_sample_path("hoomd_mixture.gsd")).unwrap();
    let u64_at = |b: &[u8], at: usize| u64::from_le_bytes(b[at..at + 8].try_into().unwrap());
    let data = chunk_data(&bytes, "particles/typeid", 0) as u64;
    // The index entry whose data that is: its N, one short.
    let at = (0..128)
        .map(|i| u64_at(&bytes, 8) as usize + 32 * i)
        .find(|&at| u64_at(&bytes, at + 16) == data)
        .unwrap();
    let n = u64_at(&bytes, at + 8);
    bytes[at + 8..at + 16].copy_from_slice(&(n - 1).to_le_bytes());
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("short-typeid.gsd");
    std::fs::write(&path, &bytes).unwrap();
    let dump = DumpFile::open(&path).unwrap();
    for k in [0, dump.frame_count() - 1] {
        let e = dump
            .read_frame(k, &ReadOptions::default(), &NoProgress)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("short-typeid.gsd")
                && e.contains(&format!("`particles/typeid` is {} × 1", n - 1)),
            "frame {k}: {e}"
        );
    }
}

/// Converts frame 1 of `path` (taking frame 0's chunks) with `radii` overridden, in
/// chunks of `chunk_points` when the frame is larger, root levels of at most 64 points.
fn convert_frame_1(
    path: &std::path::Path,
    out: &std::path::Path,
    radii: Vec<(String, f32)>,
    chunk_points: usize,
) -> Result<mdlod_preprocess::convert::ConvertReport, String> {
    let mut options = ConvertOptions {
        radii,
        ..Default::default()
    };
    options.chunks.chunk_points = chunk_points;
    options.build.max_root_points = 64;
    convert_file(
        path,
        out,
        FrameSelect::Index(1),
        &ReadOptions::default(),
        &options,
        &NoProgress,
    )
    .map_err(|e| e.to_string())
}

/// A diameter of zero or below is refused as an MMPLD list radius of zero is: the message
/// names the file, the frame and the type and says `--radius` gives it one, and with that
/// the conversion succeeds (the diameters were checked before the overrides applied).
#[test]
fn a_diameter_of_zero_or_below_is_refused_unless_the_type_is_given_a_radius() {
    let mut bytes = std::fs::read(gsd_sample_path("hoomd_mixture.gsd")).unwrap();
    let (types, diameters) = (
        chunk_data(&bytes, "particles/typeid", 0),
        chunk_data(&bytes, "particles/diameter", 0),
    );
    // The fourth particle of type B (1) gets diameter 0, the sixth -1.
    let mut b = 0;
    for i in 0..300 {
        let t = u32::from_le_bytes(bytes[types + 4 * i..types + 4 * i + 4].try_into().unwrap());
        if t == 1 {
            b += 1;
            let d: f32 = match b {
                4 => 0.0,
                6 => -1.0,
                _ => continue,
            };
            bytes[diameters + 4 * i..diameters + 4 * i + 4].copy_from_slice(&d.to_le_bytes());
        }
    }
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("zero.gsd");
    std::fs::write(&path, &bytes).unwrap();
    let out = dir.path().join("zero.mdlod");
    let convert = |radii: Vec<(String, f32)>, chunk_points: usize| {
        convert_frame_1(&path, &out, radii, chunk_points)
            .map(|_| {
                mdlod_format::MdlodFile::open(&out)
                    .unwrap()
                    .metadata()
                    .species
                    .iter()
                    .map(|s| s.radius)
                    .collect::<Vec<_>>()
            })
            .map_err(|e| e.to_string())
    };
    // In one piece and in chunks of 100 (the frame has 300 particles).
    // The frame built whole names the fourth B particle, the first of diameter 0.
    let fourth_b = (0..300)
        .filter(|&i| bytes[types + 4 * i..types + 4 * i + 4] == [1, 0, 0, 0])
        .nth(3)
        .unwrap();
    for chunk_points in [1 << 22, 100] {
        let e = convert(vec![], chunk_points).unwrap_err();
        let (which, own) = match chunk_points {
            100 => (String::new(), ""),
            _ => (
                format!(
                    " (particle {fourth_b} in the frame's order, counting from 0, is the first)"
                ),
                " (every particle of it then takes R, those of sizes above 0 too: where their \
                 sizes matter, mend the sizes of 0 in the input instead)",
            ),
        };
        assert_eq!(
            e,
            format!(
                "{}: frame 1 (timestep 100), type B: the file gives a particle diameter of \
                 0{which}, and a radius must be a positive number; give the type its radius \
                 with --radius B=R{own}",
                path.display()
            )
        );
        assert!(!out.exists());
        assert_eq!(
            convert(vec![("B".into(), 2.0)], chunk_points),
            Ok(vec![0.5, 2.0])
        );
        std::fs::remove_file(&out).unwrap();
    }
}

/// The attribute error lists the chunks an attribute can be (one number per particle):
/// not the positions, which it would then refuse.
#[test]
fn the_attribute_error_lists_only_chunks_of_one_number_per_particle() {
    let e = DumpFile::open(&gsd_sample_path("hoomd_mixture.gsd"))
        .unwrap()
        .read_frame(
            0,
            &ReadOptions {
                attribute: Some("nosuch".into()),
                ..Default::default()
            },
            &NoProgress,
        )
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("no per-particle chunk `particles/nosuch`")
            && e.contains("particles/charge")
            && !e.contains("particles/position"),
        "{e}"
    );
}

/// Particles of one type with different diameters (a polydisperse colloid) are each drawn
/// at their own radius: the file keeps a RADIUS section (format 1.1), whole and in
/// chunks, with the same radii; the particles' node bounds hold their own spheres
/// (`verify`); `--radius` gives the type one radius again (no section, format 1.0), and
/// so does a file whose types are each of one size.
#[test]
fn differing_diameters_of_a_type_are_kept_per_particle() {
    let sample = std::fs::read(gsd_sample_path("hoomd_mixture.gsd")).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let convert = |bytes: &[u8], radii: Vec<(String, f32)>, chunk_points: usize, name: &str| {
        let path = dir.path().join("poly.gsd");
        std::fs::write(&path, bytes).unwrap();
        let out = dir.path().join(name);
        let overridden = !radii.is_empty();
        let report = convert_frame_1(&path, &out, radii, chunk_points).unwrap();
        // Only `--radius` replacing the type's own sizes is noted, where it does.
        let replaced = |n: &String| n.contains("in place of the sizes the input gives its");
        assert!(
            report.notes.iter().all(replaced) && report.notes.iter().any(replaced) == overridden,
            "{:?}",
            report.notes
        );
        let f = mdlod_format::MdlodFile::open(&out).unwrap();
        f.verify().unwrap();
        f
    };
    for chunk_points in [1 << 22, 100] {
        let f = convert(&sample, vec![], chunk_points, "mono.mdlod");
        assert!(f.radii().is_none() && f.metadata().radius.is_none());
        assert_eq!(f.header().version_minor, 0);
    }
    // The first particle of type A (0) gets diameter 5 (the others 1), in frame 0's
    // chunks, which frame 1 takes.
    let mut bytes = sample.clone();
    let (types, diameters) = (
        chunk_data(&bytes, "particles/typeid", 0),
        chunk_data(&bytes, "particles/diameter", 0),
    );
    let i = (0..300)
        .find(|&i| bytes[types + 4 * i..types + 4 * i + 4] == [0, 0, 0, 0])
        .unwrap();
    bytes[diameters + 4 * i..diameters + 4 * i + 4].copy_from_slice(&5.0f32.to_le_bytes());
    let mut kept = Vec::new();
    for chunk_points in [1 << 22, 100] {
        let f = convert(
            &bytes,
            vec![],
            chunk_points,
            &format!("poly-{chunk_points}.mdlod"),
        );
        assert_eq!(f.header().version_minor, 1);
        let info = f.metadata().radius.expect("a radius range");
        assert_eq!((info.min, info.max), (0.5, 2.5));
        let radii: Vec<f32> = (0..f.particle_count() as usize)
            .map(|i| f.particle_radius(i))
            .collect();
        assert_eq!(radii.iter().filter(|&&r| r == 2.5).count(), 1, "{radii:?}");
        // Type B's 0.75, within half a step of the 16 bits over the range.
        let step = (2.5 - 0.5) / 65535.0;
        assert!(
            radii
                .iter()
                .all(|&r| r == 2.5 || r == 0.5 || (r - 0.75).abs() <= step / 2.0),
            "{radii:?}"
        );
        // The large particle's own sphere lies inside every ancestor's bounds.
        let k = radii.iter().position(|&r| r == 2.5).unwrap();
        let last = f.level_count() - 1;
        let parent = f
            .level_nodes(last - 1)
            .iter()
            .find(|n| (n.child_first..n.child_first + n.child_count).contains(&(k as u32)))
            .unwrap();
        let extent: f32 = (0..3)
            .map(|d| parent.bounds_max[d] - parent.bounds_min[d])
            .fold(f32::INFINITY, f32::min);
        assert!(extent >= 5.0 - 1e-3, "{parent:?}");
        assert!(f.metadata().species[0].radius > 0.5);
        kept.push(radii.len());
        // An override gives the type one radius.
        let f = convert(&bytes, vec![("A".into(), 1.2)], chunk_points, "over.mdlod");
        assert!(f.radii().is_none());
        assert_eq!(f.metadata().species[0].radius, 1.2);
    }
    assert_eq!(kept[0], kept[1]);
}

/// A diameter that is not finite (NaN, infinity) is refused as one of zero or below is,
/// naming the type and saying that `--radius` gives it one; with that, the conversion
/// succeeds. (It used to be an error that `--radius` could not get past.)
#[test]
fn a_diameter_not_finite_is_refused_unless_the_type_is_given_a_radius() {
    for bad in [f32::NAN, f32::INFINITY] {
        let mut bytes = std::fs::read(gsd_sample_path("hoomd_mixture.gsd")).unwrap();
        let (types, diameters) = (
            chunk_data(&bytes, "particles/typeid", 0),
            chunk_data(&bytes, "particles/diameter", 0),
        );
        // The third particle of type B (1) gets the diameter.
        let i = (0..300)
            .filter(|&i| bytes[types + 4 * i..types + 4 * i + 4] == [1, 0, 0, 0])
            .nth(2)
            .unwrap();
        bytes[diameters + 4 * i..diameters + 4 * i + 4].copy_from_slice(&bad.to_le_bytes());
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("nan.gsd");
        std::fs::write(&path, &bytes).unwrap();
        let out = dir.path().join("nan.mdlod");
        for chunk_points in [1 << 22, 100] {
            let e = convert_frame_1(&path, &out, vec![], chunk_points).unwrap_err();
            // Built whole, the frame names the particle (a chunked build reads none whole).
            let (which, own) = match chunk_points {
                100 => (String::new(), ""),
                _ => (
                    format!(" (particle {i} in the frame's order, counting from 0, is the first)"),
                    " (every particle of it then takes R, those of usable sizes too: where \
                     their sizes matter, mend the unusable ones in the input instead)",
                ),
            };
            assert_eq!(
                e,
                format!(
                    "{}: frame 1 (timestep 100), type B: the file gives a particle diameter of \
                     {bad}{which}, and a radius must be a positive number; give the type its \
                     radius with --radius B=R{own}",
                    path.display()
                )
            );
            assert!(!out.exists());
            convert_frame_1(&path, &out, vec![("B".into(), 2.0)], chunk_points).unwrap();
            let radii: Vec<f32> = mdlod_format::MdlodFile::open(&out)
                .unwrap()
                .metadata()
                .species
                .iter()
                .map(|s| s.radius)
                .collect();
            assert_eq!(radii, [0.5, 2.0]);
            std::fs::remove_file(&out).unwrap();
        }
    }
}

/// Chunks of one frame of two particles at (0,0,0) and (1,2,3): `particles/N`, the
/// positions, and `extra` (name, type code, M, data), with the names they need.
fn two_particles(extra: &[(&str, u8, u32, Vec<u8>)]) -> Vec<u8> {
    let mut names = vec!["particles/N".to_string(), "particles/position".to_string()];
    let positions: Vec<u8> = [0.0f32, 0.0, 0.0, 1.0, 2.0, 3.0]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    let mut chunks = vec![
        (0, 3, 1, 1, 2u32.to_le_bytes().to_vec()),
        (1, 9, 2, 3, positions),
    ];
    for (name, ty, m, data) in extra {
        names.push(name.to_string());
        // (The per-type chunks hold a row per type; the others one per particle.)
        let size = match ty {
            2 | 6 => 2,
            3 | 7 | 9 => 4,
            4 | 8 | 10 => 8,
            _ => 1,
        };
        let n = if *name == "particles/types" || *name == "particles/type_shapes" {
            data.len() as u64 / u64::from(*m) / size
        } else {
            2
        };
        chunks.push((names.len() as u16 - 1, *ty, n, *m, data.clone()));
    }
    gsd_file(&names, &chunks)
}

/// Frame 0 of a file of `bytes` written in `dir` (and the file's path).
fn read_frame_0(
    dir: &std::path::Path,
    bytes: &[u8],
    opts: &ReadOptions,
) -> (PathBuf, Result<mdlod_preprocess::Frame, String>) {
    let path = dir.join("two.gsd");
    std::fs::write(&path, bytes).unwrap();
    let f = DumpFile::open(&path)
        .unwrap()
        .read_frame(0, opts, &NoProgress)
        .map_err(|e| e.to_string());
    (path, f)
}

/// Two types of one name, or a type without a name, would be species no one can tell
/// apart (or name with `--radius`): errors naming the file, the frame and the chunk.
#[test]
fn duplicate_or_empty_type_names_are_errors_naming_the_chunk() {
    let dir = tempfile::tempdir().unwrap();
    let typeid: Vec<u8> = [0u32, 1].iter().flat_map(|v| v.to_le_bytes()).collect();
    for (types, expected) in [
        (*b"A\0A\0", "types 0 and 1 are both named `A`"),
        (*b"\0\0B\0", "type 0 has an empty name"),
        (*b"B\0\0\0", "type 1 has an empty name"),
    ] {
        let bytes = two_particles(&[
            ("particles/typeid", 3, 1, typeid.clone()),
            ("particles/types", 5, 2, types.to_vec()),
        ]);
        let (path, f) = read_frame_0(dir.path(), &bytes, &ReadOptions::default());
        let e = f.unwrap_err();
        assert!(
            e.starts_with(&format!("{}: byte ", path.display()))
                && e.ends_with(&format!(
                    "frame 0: `particles/types`: {expected} (each type needs a name of its own)"
                )),
            "{e}"
        );
    }
    // Distinct names read.
    let bytes = two_particles(&[
        ("particles/typeid", 3, 1, typeid),
        ("particles/types", 5, 2, b"A\0B\0".to_vec()),
    ]);
    let f = read_frame_0(dir.path(), &bytes, &ReadOptions::default())
        .1
        .unwrap();
    assert_eq!(f.species_index, [0, 1]);
}

/// An attribute chunk of several numbers per particle (`velocity`) is no damage to
/// report as a size mismatch: the message says how many components it has and lists
/// the chunks `--attribute` can take.
#[test]
fn an_attribute_of_several_components_is_named_as_such() {
    let velocity: Vec<u8> = [1.0f32; 6].iter().flat_map(|v| v.to_le_bytes()).collect();
    let charge: Vec<u8> = [0.5f32, -0.5]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    let bytes = two_particles(&[
        ("particles/velocity", 9, 3, velocity),
        ("particles/charge", 9, 1, charge),
    ]);
    let opts = |name: &str| ReadOptions {
        attribute: Some(name.into()),
        ..Default::default()
    };
    let dir = tempfile::tempdir().unwrap();
    let e = read_frame_0(dir.path(), &bytes, &opts("velocity"))
        .1
        .unwrap_err();
    assert!(
        e.ends_with(
            "frame 0: `particles/velocity` has 3 components per particle; --attribute takes \
             a chunk of one number per particle (particles/body particles/charge \
             particles/diameter particles/mass), or the length of a row: --attribute \
             '|particles/velocity|'"
        ),
        "{e}"
    );
    let f = read_frame_0(dir.path(), &bytes, &opts("charge")).1.unwrap();
    assert_eq!(f.attribute.unwrap().values, [0.5, -0.5]);
}

/// A frame whose `particles/N` is 0 takes no per-particle chunk of frame 0 (of frame 0's
/// particles): it is an empty frame, refused as every reader's is, not a size mismatch.
#[test]
fn a_frame_of_no_particles_is_the_empty_frame_error() {
    let names: Vec<String> = ["configuration/step", "particles/N", "particles/position"]
        .iter()
        .map(|s| s.to_string())
        .collect();
    let positions: Vec<u8> = [0.0f32, 0.0, 0.0, 1.0, 2.0, 3.0]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    let bytes = gsd_frames(
        &names,
        &[
            (0, (0, 4, 1, 1, 0u64.to_le_bytes().to_vec())),
            (0, (1, 3, 1, 1, 2u32.to_le_bytes().to_vec())),
            (0, (2, 9, 2, 3, positions)),
            (1, (0, 4, 1, 1, 10u64.to_le_bytes().to_vec())),
            (1, (1, 3, 1, 1, 0u32.to_le_bytes().to_vec())),
        ],
    );
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("empty.gsd");
    std::fs::write(&path, &bytes).unwrap();
    let d = DumpFile::open(&path).unwrap();
    assert_eq!(d.frame_info(1).unwrap().particles, 0);
    assert!(d
        .read_frame(1, &charge(), &NoProgress)
        .unwrap()
        .positions
        .is_empty());
    let e = convert_frame_1(&path, &dir.path().join("e.mdlod"), vec![], 1 << 22).unwrap_err();
    assert_eq!(
        e,
        format!(
            "{}: frame 1 (timestep 10): no particles, and a .mdlod file needs at least one",
            path.display()
        )
    );
}

/// The GSD documentation's own example: frame 0 of 4 particles with types and
/// diameters, then frames of 5 and 6 particles writing positions only. As HOOMD's
/// `gsd.hoomd` reads them, frame 0's per-particle chunks stand in only for a frame of as
/// many particles; the others take the schema's defaults (type 0, diameter 1). A file
/// recording no `configuration/step` gives its frames no timestep (not 0 each).
#[test]
fn frames_of_another_n_take_defaults_not_frame_0s_chunks() {
    let dir = tempfile::tempdir().unwrap();
    let names: Vec<String> = [
        "particles/N",
        "particles/position",
        "particles/typeid",
        "particles/types",
        "particles/diameter",
    ]
    .map(String::from)
    .to_vec();
    let positions = |n: usize| -> Vec<u8> {
        (0..3 * n)
            .flat_map(|i| (i as f32 * 0.5).to_le_bytes())
            .collect()
    };
    let mut chunks: Vec<(u64, Chunk)> = vec![
        (0, (0, 3, 1, 1, 4u32.to_le_bytes().to_vec())),
        (0, (1, 9, 4, 3, positions(4))),
        (
            0,
            (
                2,
                3,
                4,
                1,
                [0u32, 1, 1, 0]
                    .iter()
                    .flat_map(|v| v.to_le_bytes())
                    .collect(),
            ),
        ),
        (0, (3, 5, 2, 2, b"A\0B\0".to_vec())),
        (
            0,
            (
                4,
                9,
                4,
                1,
                [0.5f32, 2.0, 2.0, 0.5]
                    .iter()
                    .flat_map(|v| v.to_le_bytes())
                    .collect(),
            ),
        ),
    ];
    for (frame, n) in [(1u64, 5usize), (2, 6)] {
        chunks.push((frame, (0, 3, 1, 1, (n as u32).to_le_bytes().to_vec())));
        chunks.push((frame, (1, 9, n as u64, 3, positions(n))));
    }
    let path = dir.path().join("grow.gsd");
    std::fs::write(&path, gsd_frames(&names, &chunks)).unwrap();
    let dump = DumpFile::open(&path).unwrap();
    for (k, n) in [(0, 4), (1, 5), (2, 6)] {
        let f = dump
            .read_frame(k, &ReadOptions::default(), &NoProgress)
            .unwrap_or_else(|e| panic!("frame {k}: {e}"));
        assert_eq!(f.len(), n);
        assert_eq!(f.timestep, None, "frame {k}");
        assert_eq!(dump.frame_timestep(k), None);
        if k > 0 {
            // Type 0 (`A`) for every particle, at the default diameter 1.
            assert!(f.species_index.iter().all(|&s| s == 0), "frame {k}");
            assert_eq!(f.species[0].radius, Some(0.5), "frame {k}");
        }
    }
    // A batch numbers them by position, and verifies: the frames hold no timestep to
    // disagree with the manifest's numbers (they held 0 each, and verify failed).
    use mdlod_preprocess::batch::{batch, verify_dir, BatchOptions};
    let out = dir.path().join("out");
    let opts = BatchOptions {
        memory_limit: 1 << 30,
        ..Default::default()
    };
    let r = batch(std::slice::from_ref(&path), &out, &opts, &NoProgress).unwrap();
    assert_eq!(r.converted, 3);
    let check = verify_dir(&out, &NoProgress).unwrap();
    assert!(check.problems.is_empty(), "{:?}", check.problems);
    assert_eq!(check.frames_ok, 3);
}

/// An HPMC run's sizes: `particles/type_shapes` holds each type's shape as JSON, and
/// `particles/diameter` is left at its default. Sphere shapes give their types' radii
/// (both types were drawn at 0.5); other shapes keep the default.
#[test]
fn hpmc_sphere_shapes_give_the_radii_without_diameters() {
    let dir = tempfile::tempdir().unwrap();
    let typeid: Vec<u8> = [0u32, 1].iter().flat_map(|v| v.to_le_bytes()).collect();
    let shapes = [
        r#"{"type": "Sphere", "diameter": 2.0}"#,
        r#"{"type": "Sphere", "diameter": 0.5}"#,
        r#"{"type": "ConvexPolyhedron", "rounding_radius": 0}"#,
    ];
    let m = shapes.iter().map(|s| s.len() + 1).max().unwrap();
    // Three types A, B, C, with a row of `m` bytes per shape given.
    let with_shapes = |rows: &[&str]| {
        let text: Vec<u8> = rows
            .iter()
            .flat_map(|s| {
                let mut row = s.as_bytes().to_vec();
                row.resize(m, 0);
                row
            })
            .collect();
        two_particles(&[
            ("particles/typeid", 3, 1, typeid.clone()),
            ("particles/types", 5, 2, b"A\0B\0C\0".to_vec()),
            ("particles/type_shapes", 5, m as u32, text),
        ])
    };
    let bytes = with_shapes(&shapes);
    let (path, f) = read_frame_0(dir.path(), &bytes, &ReadOptions::default());
    let f = f.unwrap();
    let radii: Vec<Option<f32>> = f.species.iter().map(|s| s.radius).collect();
    assert_eq!(radii, [Some(1.0), Some(0.25), Some(0.5)]);
    // The shape drawn as a sphere of the default radius is named in a note.
    let notes = DumpFile::open(&path)
        .unwrap()
        .frame_notes(0, &ReadOptions::default());
    assert_eq!(notes.len(), 1, "{notes:?}");
    assert!(
        notes[0].contains("gives no sphere for type C (ConvexPolyhedron): it is drawn")
            && notes[0].contains("radius 0.5"),
        "{notes:?}"
    );
    // So are a type with no entry and one whose entry is no JSON.
    let bytes = with_shapes(&["[not json", shapes[0]]);
    let (path, _) = read_frame_0(dir.path(), &bytes, &ReadOptions::default());
    let notes = DumpFile::open(&path)
        .unwrap()
        .frame_notes(0, &ReadOptions::default());
    assert!(
        notes.len() == 1 && notes[0].contains("types A (an entry not read), C (no entry): they"),
        "{notes:?}"
    );
    // A sphere of diameter 0 is kept as such (the conversion refuses it, as a particle
    // diameter of 0), not silently drawn at the default.
    let mut row = br#"{"type": "Sphere", "diameter": 0}"#.to_vec();
    row.resize(m, 0);
    let mut zero = row.clone();
    zero.extend(row);
    let typeid: Vec<u8> = [0u32, 1].iter().flat_map(|v| v.to_le_bytes()).collect();
    let bytes = two_particles(&[
        ("particles/typeid", 3, 1, typeid),
        ("particles/types", 5, 2, b"A\0B\0".to_vec()),
        ("particles/type_shapes", 5, m as u32, zero),
    ]);
    let (path, f) = read_frame_0(dir.path(), &bytes, &ReadOptions::default());
    assert_eq!(f.unwrap().species[0].radius, Some(0.0));
    // Every type has its sphere: nothing to note.
    let notes = DumpFile::open(&path)
        .unwrap()
        .frame_notes(0, &ReadOptions::default());
    assert!(notes.is_empty(), "{notes:?}");
}

/// HOOMD leaves out a per-particle chunk that holds only the schema's default (a charge
/// of 0 in frame 0, a mass of 1): asked for as the attribute, the frame takes the
/// default (the batch aborted on frame 0); a chunk with no default is still an error.
#[test]
fn an_attribute_left_at_its_schema_default_takes_the_default() {
    let dir = tempfile::tempdir().unwrap();
    let bytes = two_particles(&[]);
    for (name, value) in [("charge", 0.0f32), ("mass", 1.0)] {
        let opts = ReadOptions {
            attribute: Some(name.into()),
            ..Default::default()
        };
        let (_, f) = read_frame_0(dir.path(), &bytes, &opts);
        let a = f.unwrap().attribute.unwrap();
        assert_eq!(a.name, format!("particles/{name}"));
        assert_eq!(a.values, [value, value]);
    }
    let opts = ReadOptions {
        attribute: Some("log/particles/energy".into()),
        ..Default::default()
    };
    // HOOMD's logged per-particle quantities are offered among the chunks available.
    let energies: Vec<u8> = [-1.5f32, -2.5]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    let logged = two_particles(&[("log/particles/md/pair/LJ/energies", 9, 1, energies)]);
    let (_, f) = read_frame_0(dir.path(), &logged, &opts);
    let e = f.unwrap_err();
    assert!(
        e.contains("frame 0: no per-particle chunk `log/particles/energy`")
            && e.contains("available: log/particles/md/pair/LJ/energies"),
        "{e}"
    );
}

/// A HOOMD run still writing its GSD file appends frames: a batch rerun keeps the frames
/// converted before (their chunks, and frame 0's they take, unchanged) and converts only
/// the new ones, as it does for a growing LAMMPS dump. A frame 0 rewritten (another run
/// in the same file) makes every frame that takes its chunks convert again.
#[test]
fn a_batch_over_a_growing_gsd_file_converts_only_the_new_frames() {
    use mdlod_preprocess::batch::{batch, BatchOptions};
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.gsd");
    let names: Vec<String> = [
        "particles/N",
        "particles/position",
        "configuration/step",
        "particles/types",
        "particles/typeid",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    // Frame k: two particles, step 100 k; frame 0 holds the types (`types`) the others
    // take.
    let frames = |count: u64, types: &[u8]| {
        let mut chunks = Vec::new();
        for k in 0..count {
            let x = k as f32;
            let positions: Vec<u8> = [x, 0.0, 0.0, x + 1.5, 1.0, 0.5]
                .iter()
                .flat_map(|v| v.to_le_bytes())
                .collect();
            chunks.push((k, (0u16, 3u8, 1u64, 1u32, 2u32.to_le_bytes().to_vec())));
            chunks.push((k, (1, 9, 2, 3, positions)));
            chunks.push((k, (2, 4, 1, 1, (100 * k).to_le_bytes().to_vec())));
            if k == 0 {
                chunks.push((0, (3, 5, 2, 2, types.to_vec())));
                let ids: Vec<u8> = [0u32, 1].iter().flat_map(|v| v.to_le_bytes()).collect();
                chunks.push((0, (4, 3, 2, 1, ids)));
            }
        }
        gsd_frames(&names, &chunks)
    };
    let opts = BatchOptions {
        memory_limit: 1 << 30,
        ..Default::default()
    };
    let out = dir.path().join("out");
    std::fs::write(&path, frames(2, b"A\0B\0")).unwrap();
    let r = batch(std::slice::from_ref(&path), &out, &opts, &NoProgress).unwrap();
    assert_eq!((r.converted, r.kept_unchanged), (2, 0));
    // Grown by a frame: the first two are kept.
    std::fs::write(&path, frames(3, b"A\0B\0")).unwrap();
    let r = batch(std::slice::from_ref(&path), &out, &opts, &NoProgress).unwrap();
    assert_eq!((r.converted, r.kept_unchanged), (1, 2));
    // Frame 0's types renamed: every frame takes them, every frame converts again.
    std::fs::write(&path, frames(3, b"C\0D\0")).unwrap();
    let r = batch(std::slice::from_ref(&path), &out, &opts, &NoProgress).unwrap();
    assert_eq!((r.converted, r.kept_unchanged), (3, 0));
    let f = mdlod_format::MdlodFile::open(out.join("frame-200.mdlod")).unwrap();
    assert_eq!(f.metadata().species[0].name, "C");
}

/// A `particles/type_shapes` chunk that is not text (floats, say) gives no shapes, and a
/// note says so (the types' non-text names are an error; these were ignored silently).
#[test]
fn a_type_shapes_chunk_that_is_not_text_is_noted() {
    let dir = tempfile::tempdir().unwrap();
    let shapes: Vec<u8> = [2.0f32].iter().flat_map(|v| v.to_le_bytes()).collect();
    let bytes = two_particles(&[("particles/type_shapes", 9, 1, shapes)]);
    let (path, f) = read_frame_0(dir.path(), &bytes, &ReadOptions::default());
    assert_eq!(f.unwrap().species[0].radius, Some(0.5));
    let notes = DumpFile::open(&path)
        .unwrap()
        .frame_notes(0, &ReadOptions::default());
    assert!(
        notes.len() == 1
            && notes[0].contains("particles/type_shapes is not text")
            && notes[0].contains("radius 0.5"),
        "{notes:?}"
    );
}

/// `--attribute '|velocity|'`: each particle's speed, the length of its row of
/// `particles/velocity`, whole and in parts; the chunk named bare is refused with the
/// magnitude suggested.
#[test]
fn a_magnitude_is_the_length_of_each_particles_row() {
    let dir = tempfile::tempdir().unwrap();
    let velocity: Vec<u8> = [3.0f32, 4.0, 0.0, 1.0, 2.0, 2.0]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    let bytes = two_particles(&[("particles/velocity", 9, 3, velocity)]);
    let speed = ReadOptions {
        attribute: Some("|velocity|".into()),
        ..Default::default()
    };
    let (path, f) = read_frame_0(dir.path(), &bytes, &speed);
    let a = f.unwrap().attribute.unwrap();
    assert_eq!(a.name, "|particles/velocity|");
    assert_eq!(a.values, [5.0, 3.0]);
    let dump = DumpFile::open(&path).unwrap();
    let part = dump.read_part(0, &speed, 1..2, &NoProgress).unwrap();
    assert_eq!(part.attribute.unwrap().values, [3.0]);
    assert_eq!(
        dump.attribute_name(0, &speed).unwrap().as_deref(),
        Some("|particles/velocity|")
    );
    let bare = ReadOptions {
        attribute: Some("velocity".into()),
        ..Default::default()
    };
    let e = dump
        .read_frame(0, &bare, &NoProgress)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("3 components per particle") && e.contains("--attribute '|particles/velocity|'"),
        "{e}"
    );
    let none = ReadOptions {
        attribute: Some("|omega|".into()),
        ..Default::default()
    };
    let e = dump
        .read_frame(0, &none, &NoProgress)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("no per-particle chunk `particles/omega` for the magnitude"),
        "{e}"
    );
}

/// A file cut inside frame 1's data: frame 0 reads, frame 1 is the error, and the frames
/// the index lists after it are named as lost with it (not dropped unsaid).
#[test]
fn frames_listed_after_a_cut_are_named_as_lost() {
    let good = std::fs::read(gsd_sample_path("hoomd_mixture.gsd")).unwrap();
    let cut = chunk_data(&good, "particles/position", 1) + 4;
    assert!(cut < chunk_data(&good, "particles/position", 2));
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("cut.gsd");
    std::fs::write(&path, &good[..cut]).unwrap();
    let d = DumpFile::open(&path).unwrap();
    assert_eq!(d.frame_count(), 2);
    assert!(d
        .read_frame(0, &ReadOptions::default(), &NoProgress)
        .is_ok());
    let e = d
        .read_frame(1, &ReadOptions::default(), &NoProgress)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains(
            "outside the file: the file is damaged (a copy cut short?): the index \
                    lists 3 frames, and frame 2 after it is lost with it"
        ),
        "{e}"
    );
    // Damage, not a frame a run is still writing: a batch fails on it.
    let batch_dir = dir.path().join("out");
    let opts = mdlod_preprocess::batch::BatchOptions {
        memory_limit: 1 << 30,
        ..Default::default()
    };
    let e =
        mdlod_preprocess::batch::batch(std::slice::from_ref(&path), &batch_dir, &opts, &NoProgress)
            .unwrap_err()
            .to_string();
    assert!(e.contains("the file is damaged"), "{e}");
}

/// Something else named `.gsd` is no GSD file, however short: not a GSD file cut short.
#[test]
fn a_short_file_of_something_else_is_not_called_a_cut_gsd_file() {
    let dir = tempfile::tempdir().unwrap();
    for (bytes, want) in [
        (
            b"ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n".to_vec(),
            "byte 0: not a GSD file (bad magic number)",
        ),
        (b"abc\n".to_vec(), "not a GSD file: 4 bytes"),
    ] {
        let path = dir.path().join("text.gsd");
        std::fs::write(&path, &bytes).unwrap();
        let e = DumpFile::open(&path).err().unwrap().to_string();
        assert!(e.contains(want), "{e}");
    }
}

/// A velocity written in frame 0 only (HOOMD's default `dynamic` list) colours a later
/// frame by frame 0's values: said, not left silent.
#[test]
fn an_attribute_a_later_frame_takes_from_frame_0_is_noted() {
    let names: Vec<String> = ["particles/N", "particles/position", "particles/charge"]
        .map(String::from)
        .to_vec();
    let f32s = |v: &[f32]| v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>();
    let positions = f32s(&[0.0, 0.0, 0.0, 1.0, 2.0, 3.0]);
    let bytes = gsd_frames(
        &names,
        &[
            (0, (0, 3, 1, 1, 2u32.to_le_bytes().to_vec())),
            (0, (1, 9, 2, 3, positions.clone())),
            (0, (2, 9, 2, 1, f32s(&[0.5, -0.5]))),
            (1, (1, 9, 2, 3, positions)),
        ],
    );
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("static.gsd");
    std::fs::write(&path, &bytes).unwrap();
    let dump = DumpFile::open(&path).unwrap();
    assert_eq!(dump.frame_count(), 2);
    let notes = |k| dump.frame_notes(k, &charge());
    assert!(notes(0).is_empty(), "{:?}", notes(0));
    assert!(
        notes(1)
            .iter()
            .any(|n| n.contains("`particles/charge` is written in frame 0 only")),
        "{:?}",
        notes(1)
    );
    // A frame of another count takes the schema's default (0), not frame 0's: not said.
    let three = f32s(&[0.0, 0.0, 0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
    let bytes = gsd_frames(
        &names,
        &[
            (0, (0, 3, 1, 1, 2u32.to_le_bytes().to_vec())),
            (0, (1, 9, 2, 3, f32s(&[0.0, 0.0, 0.0, 1.0, 2.0, 3.0]))),
            (0, (2, 9, 2, 1, f32s(&[0.5, -0.5]))),
            (1, (0, 3, 1, 1, 3u32.to_le_bytes().to_vec())),
            (1, (1, 9, 3, 3, three)),
        ],
    );
    let path = dir.path().join("grown.gsd");
    std::fs::write(&path, &bytes).unwrap();
    let dump = DumpFile::open(&path).unwrap();
    let frame = dump.read_frame(1, &charge(), &NoProgress).unwrap();
    assert_eq!(frame.attribute.unwrap().values, [0.0; 3]);
    assert!(
        dump.frame_notes(1, &charge()).is_empty(),
        "{:?}",
        dump.frame_notes(1, &charge())
    );
}

/// A box length below 0 (a damaged file's Lx = -10) is refused naming the frame and the
/// axis; 0 (a two-dimensional box's Lz) is read.
#[test]
fn a_negative_box_length_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let boxed = |lz: f32| {
        let v: Vec<u8> = [10.0f32, 10.0, lz, 0.0, 0.0, 0.0]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        two_particles(&[("configuration/box", 9, 3, v)])
    };
    let (_, f) = read_frame_0(dir.path(), &boxed(-10.0), &ReadOptions::default());
    let e = f.unwrap_err();
    assert!(
        e.contains("frame 0: the box's Lz is -10: a box length is 0 or more"),
        "{e}"
    );
    let (_, f) = read_frame_0(dir.path(), &boxed(0.0), &ReadOptions::default());
    assert_eq!(f.unwrap().simulation_box.unwrap().c, [0.0; 3]);
}

/// A chunk written twice in one frame (two `particles/position`): which one holds the
/// positions cannot be told, so the file is refused (a lookup used to take either).
#[test]
fn a_chunk_written_twice_in_a_frame_is_an_error() {
    let names = vec!["particles/N".to_string(), "particles/position".to_string()];
    let at = |v: f32| -> Vec<u8> {
        [v, 0.0, 0.0, v, 1.0, 1.0]
            .iter()
            .flat_map(|x| x.to_le_bytes())
            .collect()
    };
    let bytes = gsd_file(
        &names,
        &[
            (0, 3, 1, 1, 2u32.to_le_bytes().to_vec()),
            (1, 9, 2, 3, at(0.0)),
            (1, 9, 2, 3, at(5.0)),
        ],
    );
    let m = damaged(&bytes);
    assert!(
        m.contains("chunk `particles/position` is written twice in frame 0"),
        "{m}"
    );
}

/// A file cut inside its last frame's step (a copy in progress): that frame has no step
/// to read, and a batch leaves it for a rerun and converts the others. Frame 0's step,
/// taken for it, made it a duplicate of frame 0: the batch stopped, or with
/// `--duplicate-timesteps last` dropped the good frames.
#[test]
fn a_last_frame_cut_inside_its_step_is_left_for_a_rerun() {
    let good = std::fs::read(gsd_sample_path("hoomd_mixture.gsd")).unwrap();
    let cut = chunk_data(&good, "configuration/step", 2) + 4;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("cut.gsd");
    std::fs::write(&path, &good[..cut]).unwrap();
    let d = DumpFile::open(&path).unwrap();
    assert_eq!(d.frame_info(2).ok().and_then(|i| i.timestep), None);
    for duplicates in [None, Some(mdlod_preprocess::batch::Duplicates::Last)] {
        let out = dir.path().join(format!("out-{duplicates:?}"));
        let mut opts = mdlod_preprocess::batch::BatchOptions {
            memory_limit: 1 << 30,
            ..Default::default()
        };
        if let Some(d) = duplicates {
            opts.duplicates = d;
        }
        let report =
            mdlod_preprocess::batch::batch(std::slice::from_ref(&path), &out, &opts, &NoProgress)
                .unwrap();
        let m = mdlod_preprocess::batch::read_manifest(&out).unwrap();
        let steps: Vec<u64> = m.frames.iter().map(|f| f.timestep).collect();
        let want: Vec<u64> = (0..2)
            .map(|k| {
                DumpFile::open(&path)
                    .unwrap()
                    .frame_info(k)
                    .unwrap()
                    .timestep
                    .unwrap()
            })
            .collect();
        assert_eq!(steps, want, "{report:?}");
    }
}

/// A frame that leaves out its positions (as a writer does where every particle is at the
/// origin, the schema's default) is refused, saying why; frame 0 is not said to lack
/// them beside itself.
#[test]
fn a_frame_without_positions_says_why_a_writer_leaves_them_out() {
    let names = vec!["particles/N".to_string()];
    let bytes = gsd_file(&names, &[(0, 3, 1, 1, 8u32.to_le_bytes().to_vec())]);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("origin.gsd");
    std::fs::write(&path, bytes).unwrap();
    let e = DumpFile::open(&path)
        .unwrap()
        .read_frame(0, &ReadOptions::default(), &NoProgress)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("frame 0 has no `particles/position` for its 8 particles: a writer leaves")
            && !e.contains("and frame 0 has none"),
        "{e}"
    );
}

/// Particles turned by `particles/orientation` are noted as drawn without it (spheres);
/// identity quaternions, as HOOMD writes for spheres, say nothing.
#[test]
fn orientations_are_noted_as_not_drawn() {
    let dir = tempfile::tempdir().unwrap();
    let quaternions = |q: [f32; 4]| -> Vec<u8> {
        [q, [1.0, 0.0, 0.0, 0.0]]
            .iter()
            .flatten()
            .flat_map(|v| v.to_le_bytes())
            .collect()
    };
    for (q, says) in [([1.0, 0.0, 0.0, 0.0], false), ([0.6, 0.8, 0.0, 0.0], true)] {
        let bytes = two_particles(&[("particles/orientation", 9, 4, quaternions(q))]);
        let (path, f) = read_frame_0(dir.path(), &bytes, &ReadOptions::default());
        assert_eq!(f.unwrap().len(), 2);
        let notes = DumpFile::open(&path)
            .unwrap()
            .frame_notes(0, &ReadOptions::default());
        assert_eq!(
            notes.iter().any(|n| n.contains(
                "frame 0: particles/orientation turns particles, which are drawn as spheres"
            )),
            says,
            "{notes:?}"
        );
    }
}
