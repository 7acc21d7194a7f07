//! LAMMPS binary dumps: real files written by LAMMPS (datasets/lammps/in.*_binary) read
//! against the text dumps of the same runs, the old header revision, and bad files.

use std::path::{Path, PathBuf};

use mdlod_datasets::lammps_sample_path;
use mdlod_preprocess::readers::{DumpFile, InputFormat, ReadError, ReadOptions};
use mdlod_preprocess::{Frame, NoProgress};

fn read(path: &Path, k: usize, opts: &ReadOptions) -> Frame {
    DumpFile::open(path)
        .unwrap()
        .read_frame(k, opts, &NoProgress)
        .unwrap()
}

fn with_attribute(name: &str) -> ReadOptions {
    ReadOptions {
        attribute: Some(name.into()),
        ..Default::default()
    }
}

/// Positions reordered by atom id (read as the attribute).
fn by_id(frame: &Frame) -> Vec<[f32; 3]> {
    let ids = &frame.attribute.as_ref().unwrap().values;
    let mut order: Vec<usize> = (0..frame.len()).collect();
    order.sort_by(|&a, &b| ids[a].total_cmp(&ids[b]));
    order.iter().map(|&i| frame.positions[i]).collect()
}

fn assert_close(a: &[[f32; 3]], b: &[[f32; 3]], tol: f32, what: &str) {
    assert_eq!(a.len(), b.len(), "{what}");
    for (i, (p, q)) in a.iter().zip(b).enumerate() {
        for k in 0..3 {
            assert!(
                (p[k] - q[k]).abs() <= tol * (1.0 + q[k].abs()),
                "{what}: atom {i} axis {k}: {} vs {}",
                p[k],
                q[k]
            );
        }
    }
}

#[test]
fn custom_binary_matches_the_text_dump_of_the_same_run() {
    let bin = DumpFile::open(&lammps_sample_path("cu_melt.custom.bin")).unwrap();
    assert_eq!(bin.format(), InputFormat::LammpsBinary);
    assert_eq!(bin.frame_count(), 3);
    assert_eq!(
        (0..3).map(|k| bin.frame_timestep(k)).collect::<Vec<_>>(),
        [Some(0), Some(250), Some(500)]
    );
    let info = bin.frame_info(1).unwrap();
    assert_eq!(info.particles, 500);
    assert_eq!(info.columns, ["id", "type", "x", "y", "z", "c_pe"]);
    let text = DumpFile::open(&lammps_sample_path("cu_melt.custom.dump")).unwrap();
    // Steps 0 and 500 are in both (text: every 100 steps, 6 significant digits).
    for (kb, kt) in [(0, 0), (2, 5)] {
        let b = bin
            .read_frame(kb, &with_attribute("c_pe"), &NoProgress)
            .unwrap();
        let t = text
            .read_frame(kt, &with_attribute("c_pe"), &NoProgress)
            .unwrap();
        assert_eq!(b.timestep, t.timestep);
        assert_eq!(b.time, t.time);
        assert_eq!(b.units.as_deref(), Some("metal"));
        assert_eq!(b.units, t.units);
        assert_eq!(b.species, t.species);
        assert_eq!(b.species_index, t.species_index);
        assert_close(&b.positions, &t.positions, 1e-5, "positions");
        let (ba, ta) = (b.attribute.unwrap(), t.attribute.unwrap());
        assert_eq!(ba.name, "c_pe");
        for (x, y) in ba.values.iter().zip(&ta.values) {
            assert!((x - y).abs() <= 1e-5 * (1.0 + y.abs()), "c_pe {x} vs {y}");
        }
        let (bb, tb) = (b.simulation_box.unwrap(), t.simulation_box.unwrap());
        assert_eq!(bb.periodic, Some([true; 3]));
        for k in 0..3 {
            assert!((bb.origin[k] - tb.origin[k]).abs() < 1e-9);
            assert!((bb.a[k] - tb.a[k]).abs() < 1e-9);
        }
    }
}

#[test]
fn atom_binary_is_scaled_and_unsorted_and_agrees_with_custom() {
    let atom = lammps_sample_path("cu_melt.atom.bin");
    let info = DumpFile::open(&atom).unwrap().frame_info(0).unwrap();
    assert_eq!(info.columns, ["id", "type", "xs", "ys", "zs"]);
    for k in 0..3 {
        let a = read(&atom, k, &with_attribute("id"));
        let c = read(
            &lammps_sample_path("cu_melt.custom.bin"),
            k,
            &with_attribute("id"),
        );
        assert_close(&by_id(&a), &by_id(&c), 1e-5, "scaled vs Cartesian");
    }
}

#[test]
fn a_file_set_per_timestep_reads_frame_by_frame() {
    let custom = lammps_sample_path("cu_melt.custom.bin");
    let l = 5.0 * 3.615;
    for (k, step) in [0u64, 250, 500].into_iter().enumerate() {
        let path = lammps_sample_path(&format!("cu_melt.step.{step}.bin"));
        let f = DumpFile::open(&path).unwrap();
        assert_eq!(f.frame_count(), 1);
        assert_eq!(f.frame_timestep(0), Some(step));
        let unwrapped = read(&path, 0, &with_attribute("id"));
        let wrapped = read(&custom, k, &with_attribute("id"));
        // Unwrapped and wrapped coordinates differ by whole box lengths.
        for (u, w) in by_id(&unwrapped).iter().zip(by_id(&wrapped)) {
            for ax in 0..3 {
                let periods = (u[ax] - w[ax]) / l;
                assert!((periods - periods.round()).abs() < 1e-4, "{u:?} vs {w:?}");
            }
        }
    }
}

#[test]
fn triclinic_binary_matches_the_text_dump() {
    let bin = lammps_sample_path("lj_triclinic.custom.bin");
    let text = lammps_sample_path("lj_triclinic.cartesian.dump");
    assert_eq!(DumpFile::open(&bin).unwrap().frame_count(), 4);
    for k in 0..4 {
        let b = read(&bin, k, &with_attribute("v_speed"));
        let t = read(&text, k, &with_attribute("v_speed"));
        assert_eq!(b.timestep, t.timestep);
        assert_close(&b.positions, &t.positions, 2e-5, "positions");
        let (bb, tb) = (b.simulation_box.unwrap(), t.simulation_box.unwrap());
        for (x, y) in [bb.origin, bb.a, bb.b, bb.c]
            .iter()
            .flatten()
            .zip([tb.origin, tb.a, tb.b, tb.c].iter().flatten())
        {
            assert!((x - y).abs() < 1e-5 * (1.0 + y.abs()), "box {x} vs {y}");
        }
        assert!(!bb.is_orthogonal());
    }
}

fn temp_copy(name: &str, bytes: &[u8]) -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join(name);
    std::fs::write(&path, bytes).unwrap();
    (dir, path)
}

#[test]
fn the_old_header_revision_reads_the_same_atoms() {
    for (file, attribute) in [("cu_melt.atom.bin", "id"), ("cu_melt.custom.bin", "c_pe")] {
        let new_path = lammps_sample_path(file);
        let old = mdlod_datasets::to_old_revision(&std::fs::read(&new_path).unwrap());
        let (_d, old_path) = temp_copy("old.bin", &old);
        let old_dump = DumpFile::open(&old_path).unwrap();
        assert_eq!(old_dump.frame_count(), 3);
        let names: Vec<String> = DumpFile::open(&new_path)
            .unwrap()
            .frame_info(0)
            .unwrap()
            .columns;
        let opts = ReadOptions {
            attribute: Some(attribute.into()),
            columns: (file == "cu_melt.custom.bin").then(|| names.clone()),
            ..Default::default()
        };
        for k in 0..3 {
            let a = old_dump.read_frame(k, &opts, &NoProgress).unwrap();
            let b = read(&new_path, k, &with_attribute(attribute));
            assert_eq!(a.positions, b.positions);
            assert_eq!(a.species_index, b.species_index);
            assert_eq!(a.attribute, b.attribute);
            assert_eq!(a.timestep, b.timestep);
            assert_eq!(a.time, None);
        }
        if file == "cu_melt.custom.bin" {
            // Six unnamed values per atom are not `dump atom`'s: the columns are needed.
            let e = old_dump
                .read_frame(0, &ReadOptions::default(), &NoProgress)
                .unwrap_err()
                .to_string();
            assert!(
                e.contains("names no columns") && e.contains("--columns"),
                "{e}"
            );
            assert!(e.starts_with(&old_path.display().to_string()), "{e}");
        }
    }
}

fn open_err(bytes: &[u8]) -> String {
    let (_d, path) = temp_copy("bad.bin", bytes);
    match DumpFile::open(&path) {
        Err(e) => {
            let s = e.to_string();
            assert!(s.starts_with(&path.display().to_string()), "{s}");
            s
        }
        Ok(d) => {
            // Some damage only shows when the atoms are decoded.
            (0..d.frame_count())
                .find_map(|k| {
                    d.read_frame(k, &with_attribute("c_pe"), &NoProgress)
                        .err()
                        .map(|e| e.to_string())
                })
                .unwrap_or_default()
        }
    }
}

#[test]
fn truncated_and_corrupt_binary_dumps_are_errors_naming_the_byte() {
    let good = std::fs::read(lammps_sample_path("cu_melt.custom.bin")).unwrap();
    // Every truncation (in steps, through headers and atoms) is an error, never a panic.
    let mut cut = 1;
    while cut < good.len() {
        let e = open_err(&good[..cut]);
        assert!(e.contains("byte "), "cut at {cut}: {e}");
        cut += if cut < 400 { 1 } else { 997 };
    }
    assert!(open_err(&good[..100]).contains("truncated"));

    // A chunk length that is not a whole number of atoms.
    let mut bad = good.clone();
    let chunk_len_at = 0xa6; // after the chunk count of frame 0
    bad[chunk_len_at..chunk_len_at + 4].copy_from_slice(&2999i32.to_le_bytes());
    let e = open_err(&bad);
    assert!(e.contains("not a multiple of 6"), "{e}");

    // A damaged chunk count reads the next frame as chunks: the count's byte is named
    // with the chunk's.
    let mut bad = good.clone();
    let count_at = chunk_len_at - 4;
    bad[count_at..count_at + 4].copy_from_slice(&(1i32 << 30).to_le_bytes());
    let e = open_err(&bad);
    assert!(
        e.contains(&format!(
            "(of the 1073741824 the chunk count at byte {count_at} announces)"
        )),
        "{e}"
    );

    // A NaN coordinate: the atom, the column and the byte are named.
    let mut bad = good.clone();
    let first_atom = chunk_len_at + 4;
    let x_of_atom_3 = first_atom + 2 * 6 * 8 + 2 * 8;
    bad[x_of_atom_3..x_of_atom_3 + 8].copy_from_slice(&f64::NAN.to_le_bytes());
    let e = open_err(&bad);
    assert!(
        e.contains("atom 3 of timestep 0")
            && e.contains("`x`")
            && e.contains(&format!("byte {x_of_atom_3}")),
        "{e}"
    );

    // Another byte order, another revision, a wrong magic.
    let mut bad = good.clone();
    bad[18..22].copy_from_slice(&0x0100_0000i32.to_le_bytes());
    assert!(open_err(&bad).contains("other byte order"));
    // A whole file written big-endian: its magic string's length reads huge.
    let mut bad = good.clone();
    bad[..8].copy_from_slice(&(-10i64).to_be_bytes());
    let e = open_err(&bad);
    assert!(
        e.contains("byte 0: the magic string's length reads -10 in the other byte order: written on a big-endian machine"),
        "{e}"
    );
    let mut bad = good.clone();
    bad[22..26].copy_from_slice(&3i32.to_le_bytes());
    assert!(open_err(&bad).contains("revision 3"));
    let mut bad = good.clone();
    bad[8..12].copy_from_slice(b"JUNK");
    let e = open_err(&bad);
    assert!(e.contains("not a LAMMPS binary dump"), "{e}");
    // Magic string lengths out of range, down to the most negative one (whose length
    // does not fit the integer it is read as).
    for (first, len) in [(-65i64, "65"), (i64::MIN, "9223372036854775808")] {
        let mut bad = good.clone();
        bad[..8].copy_from_slice(&first.to_le_bytes());
        let e = open_err(&bad);
        assert!(e.contains(&format!("bad magic string length {len}")), "{e}");
    }
    // A length one off takes a byte of the endian flag into the magic, or leaves one
    // behind: said as the length, or as a damaged header (not as the other byte order).
    let mut bad = good.clone();
    bad[..8].copy_from_slice(&(-11i64).to_le_bytes());
    let e = open_err(&bad);
    assert!(
        e.contains(r"byte 0: magic string length 11 gives `DUMPCUSTOM\x01`, not a LAMMPS magic"),
        "{e}"
    );
    let mut bad = good.clone();
    bad[..8].copy_from_slice(&(-9i64).to_le_bytes());
    let e = open_err(&bad);
    assert!(
        e.contains("byte 17: endian flag 0x14d is 1 in neither byte order: the header is damaged (read after the magic string `DUMPCUSTO` of length 9)"),
        "{e}"
    );
    // An atom count the chunks do not hold.
    let mut bad = good.clone();
    bad[0x22..0x2a].copy_from_slice(&501i64.to_le_bytes());
    let e = open_err(&bad);
    assert!(e.contains("announces 501 atoms"), "{e}");
    // One whose values overflow: named at its own byte (34), not the frame's start.
    let mut bad = good.clone();
    bad[0x22..0x2a].copy_from_slice(&(1i64 << 62).to_le_bytes());
    let e = open_err(&bad);
    assert!(
        e.contains("byte 34: atom count 4611686018427387904 overflows at"),
        "{e}"
    );
    // A time that is not a number (the time of frame 0 follows the unit style `metal`).
    let mut bad = good.clone();
    bad[132..140].copy_from_slice(&f64::NAN.to_le_bytes());
    let e = open_err(&bad);
    assert!(
        e.contains("byte 132: time is not a finite number (NaN)"),
        "{e}"
    );
    // A boundary flag LAMMPS does not write (0 to 3): a header read wrong.
    let mut bad = good.clone();
    bad[46..50].copy_from_slice(&7i32.to_le_bytes());
    let e = open_err(&bad);
    assert!(e.contains("byte 46: boundary flag 7"), "{e}");
    // Not a number of values per atom.
    let mut bad = good;
    bad[0x76..0x7a].copy_from_slice(&(-6i32).to_le_bytes());
    assert!(open_err(&bad).contains("values per atom is -6"));
}

#[test]
fn wrong_attribute_and_no_coordinates_are_clear_errors() {
    let path = lammps_sample_path("cu_melt.atom.bin");
    let e = DumpFile::open(&path)
        .unwrap()
        .read_frame(0, &with_attribute("c_pe"), &NoProgress)
        .unwrap_err();
    assert!(matches!(e, ReadError::Binary { .. }));
    assert!(e
        .to_string()
        .contains("available columns: id type xs ys zs"));
    let opts = ReadOptions {
        columns: Some(["id", "type", "a", "b", "c"].map(String::from).to_vec()),
        ..Default::default()
    };
    let e = DumpFile::open(&path)
        .unwrap()
        .read_frame(0, &opts, &NoProgress)
        .unwrap_err()
        .to_string();
    // (This dump names its own columns: other names are refused before any is looked for.)
    assert!(e.contains("this dump names its own columns"), "{e}");
}

/// Byte offset of the first atom of frame 0 of a current-revision binary dump.
fn first_atom(bytes: &[u8]) -> usize {
    let i32_at = |p: usize| i32::from_le_bytes(bytes[p..p + 4].try_into().unwrap());
    let i64_at = |p: usize| i64::from_le_bytes(bytes[p..p + 8].try_into().unwrap());
    let mut p = 8 + (-i64_at(0)) as usize + 8; // magic, endian + revision
    let triclinic = i32_at(p + 16);
    p += 8 + 8 + 4 + 24 + 48 + if triclinic == 1 { 24 } else { 0 } + 4;
    p += 4 + i32_at(p) as usize; // units
    p += if bytes[p] == 1 { 9 } else { 1 }; // time
    p += 4 + i32_at(p) as usize; // columns
    p + 4 + 4 // the chunk count, the first chunk's length
}

#[test]
fn values_past_the_single_precision_range_are_errors_naming_the_input() {
    // A coordinate of 1e39 (a finite f64, an infinite f32): the input's atom, column and
    // byte are named (it used to reach the output as infinity, refused naming that file).
    let good = std::fs::read(lammps_sample_path("cu_melt.custom.bin")).unwrap();
    let first = first_atom(&good);
    assert_eq!(first, 0xa6 + 4);
    let x_of_atom_3 = first + 2 * 6 * 8 + 2 * 8;
    let mut bad = good.clone();
    bad[x_of_atom_3..x_of_atom_3 + 8].copy_from_slice(&1e39f64.to_le_bytes());
    let e = open_err(&bad);
    assert!(
        e.contains(&format!(
            "byte {x_of_atom_3}: atom 3 of timestep 0: column `x` is not a finite number in \
             single precision (1e39 is beyond"
        )),
        "{e}"
    );
    // The attribute (`c_pe`, column 5) of atom 2.
    let pe_of_atom_2 = first + 6 * 8 + 5 * 8;
    let mut bad = good.clone();
    bad[pe_of_atom_2..pe_of_atom_2 + 8].copy_from_slice(&(-2e40f64).to_le_bytes());
    let e = open_err(&bad);
    assert!(
        e.contains(&format!(
            "byte {pe_of_atom_2}: atom 2 of timestep 0: column `c_pe` is not a finite number \
             in single precision (-2e40 is beyond"
        )),
        "{e}"
    );
    // A scaled coordinate that fits single precision until it is unscaled through the
    // box (`dump atom`: id type xs ys zs; the box is 18 wide).
    let atom = std::fs::read(lammps_sample_path("cu_melt.atom.bin")).unwrap();
    let ys_of_atom_1 = first_atom(&atom) + 3 * 8;
    let mut bad = atom.clone();
    bad[ys_of_atom_1..ys_of_atom_1 + 8].copy_from_slice(&1e38f64.to_le_bytes());
    let (_d, path) = temp_copy("scaled.bin", &bad);
    let e = DumpFile::open(&path)
        .unwrap()
        .read_frame(0, &ReadOptions::default(), &NoProgress)
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with(&format!(
            "{}: byte {ys_of_atom_1}: atom 1 of timestep 0",
            path.display()
        )) && e.contains("column `ys` is not a finite number in single precision once unscaled"),
        "{e}"
    );
}

/// Type n keeps palette slot n - 1 only where every type is a LAMMPS type (1 or more),
/// as in the text reader: with a type 0 present, no type takes a slot by number.
#[test]
fn palette_slots_follow_type_numbers_only_from_one_up() {
    let good = std::fs::read(lammps_sample_path("cu_melt.custom.bin")).unwrap();
    let frame = read(
        &lammps_sample_path("cu_melt.custom.bin"),
        0,
        &ReadOptions::default(),
    );
    let slots: Vec<_> = frame.species.iter().map(|s| s.palette_slot).collect();
    assert_eq!(slots, [Some(0)], "{:?}", frame.species);
    // Atom 0's type (column 1, a double) set to 0.
    let type_of_atom_0 = first_atom(&good) + 8;
    let mut zero = good.clone();
    zero[type_of_atom_0..type_of_atom_0 + 8].copy_from_slice(&0f64.to_le_bytes());
    let (_d, path) = temp_copy("type0.bin", &zero);
    let frame = read(&path, 0, &ReadOptions::default());
    let names: Vec<_> = frame.species.iter().map(|s| s.name.as_str()).collect();
    assert_eq!(names, ["0", "1"]);
    assert!(
        frame.species.iter().all(|s| s.palette_slot.is_none()),
        "{:?}",
        frame.species
    );
}

/// An old-revision binary dump (no column names) of one frame: the box 0..30 on every
/// axis, five values per atom (`id type` and the coordinates `coords(i)`), in two chunks.
fn old_revision_dump(atoms: usize, coords: impl Fn(usize) -> [f64; 3]) -> Vec<u8> {
    let mut out = Vec::new();
    out.extend_from_slice(&7i64.to_le_bytes()); // timestep
    out.extend_from_slice(&(atoms as i64).to_le_bytes());
    out.extend_from_slice(&0i32.to_le_bytes()); // orthogonal
    out.extend_from_slice(&[0u8; 24]); // boundary
    for v in [0.0f64, 30.0, 0.0, 30.0, 0.0, 30.0] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out.extend_from_slice(&5i32.to_le_bytes());
    out.extend_from_slice(&2i32.to_le_bytes()); // chunks
    let half = atoms / 2;
    for range in [0..half, half..atoms] {
        out.extend_from_slice(&(5 * range.len() as i32).to_le_bytes());
        for i in range {
            let [x, y, z] = coords(i);
            for v in [(i + 1) as f64, 1.0, x, y, z] {
                out.extend_from_slice(&v.to_le_bytes());
            }
        }
    }
    out
}

/// `dump atom`'s scaled coordinates assumed for an old-revision dump that holds unscaled
/// ones (0 to 30) were multiplied by the box without a word: more than a few atoms far
/// outside the box (below -0.5 or above 1.5) are refused, saying the columns look
/// unscaled and how to name them; with `--columns "id type x y z"` the dump reads.
/// Scaled coordinates a little outside the box (atoms that moved since the last
/// wrapping) still read.
#[test]
fn unscaled_coordinates_read_as_assumed_scaled_ones_are_refused() {
    let at = |i: usize| {
        let t = i as f64;
        [(t * 7.3) % 30.0, (t * 3.1) % 30.0, 29.0 - (t * 1.3) % 28.0]
    };
    let far = (0..40)
        .filter(|&i| at(i).iter().any(|v| !(-0.5..=1.5).contains(v)))
        .count();
    let unscaled = old_revision_dump(40, at);
    let (_d, path) = temp_copy("old.bin", &unscaled);
    let dump = DumpFile::open(&path).unwrap();
    let e = dump
        .read_frame(0, &ReadOptions::default(), &NoProgress)
        .unwrap_err()
        .to_string();
    // Atom 1 is at (0, 0, 29): its `zs` (after the 100 bytes of header and chunk
    // count, the chunk's length and four values) is the first far value.
    let zs_of_atom_1 = 100 + 4 + 4 * 8;
    assert_eq!(
        e,
        format!(
            "{}: byte {zs_of_atom_1}: timestep 7: an old-revision binary dump names no \
             columns, so `dump atom`'s scaled `id type xs ys zs` were assumed, but {far} of \
             the first 40 atoms lie far outside the box (below -0.5 or above 1.5; atom 1: \
             `zs` is 29): the columns look unscaled; give the column names (e.g. --columns \
             \"id type x y z\")",
            path.display()
        )
    );
    // In parts (the out-of-core reader's windows), the same answer.
    let e2 = dump
        .read_part(0, &ReadOptions::default(), 30..40, &NoProgress)
        .unwrap_err()
        .to_string();
    assert_eq!(e, e2);
    let columns = ReadOptions {
        columns: Some(["id", "type", "x", "y", "z"].map(String::from).to_vec()),
        ..Default::default()
    };
    let f = dump.read_frame(0, &columns, &NoProgress).unwrap();
    assert_eq!(f.positions[1], at(1).map(|v| v as f32));

    // Scaled coordinates, three atoms far outside: read, unscaled through the box.
    let scaled = old_revision_dump(40, |i| match i {
        0..=2 => [2.0, 0.5, 0.5],
        _ => [0.5, -0.1, 1.05],
    });
    let (_d, path) = temp_copy("scaled.bin", &scaled);
    let f = DumpFile::open(&path)
        .unwrap()
        .read_frame(0, &ReadOptions::default(), &NoProgress)
        .unwrap();
    assert_eq!(f.positions[0], [60.0, 15.0, 15.0]);
    assert_eq!(f.positions[39], [15.0, -3.0, 31.5]);
}

/// A granular run's grains of their own sizes (`in.granular`): the text dump's `radius`
/// column and the binary dump's `diameter` column of the same run give every grain the
/// same radius, each type its grains' mean and range, and the range the input script
/// drew them from.
#[test]
fn granular_sizes_read_as_radii_from_text_radius_and_binary_diameter_columns() {
    let text_path = lammps_sample_path("granular.dump");
    let bin_path = lammps_sample_path("granular.bin");
    for k in 0..3 {
        let text = read(&text_path, k, &with_attribute("id"));
        let bin = read(&bin_path, k, &with_attribute("id"));
        assert_eq!(text.len(), 252);
        let radii_by_id = |f: &Frame| {
            let ids = &f.attribute.as_ref().unwrap().values;
            let r = f.radii.as_ref().expect("per-particle radii");
            let mut order: Vec<usize> = (0..f.len()).collect();
            order.sort_by(|&a, &b| ids[a].total_cmp(&ids[b]));
            order.iter().map(|&i| r[i]).collect::<Vec<f32>>()
        };
        let (rt, rb) = (radii_by_id(&text), radii_by_id(&bin));
        // The text dump prints 6 significant digits (these radii: 6 decimals).
        for (i, (a, b)) in rt.iter().zip(&rb).enumerate() {
            assert!((a - b).abs() <= 6e-7, "grain {}: {a} against {b}", i + 1);
        }
        assert_close(&by_id(&text), &by_id(&bin), 1e-5, "positions");
        for f in [&text, &bin] {
            let r = f.radii.as_ref().unwrap();
            for (t, (lo, hi)) in [(0usize, (0.3, 0.5)), (1, (0.6, 0.9))] {
                let s = &f.species[t];
                let (a, b) = s.radius_range.expect("a range");
                assert!(lo <= a && a < b && b <= hi, "type {}: {a} to {b}", s.name);
                let own: Vec<f32> = (0..f.len())
                    .filter(|&i| usize::from(f.species_index[i]) == t)
                    .map(|i| r[i])
                    .collect();
                let mean = own.iter().map(|&v| f64::from(v)).sum::<f64>() / own.len() as f64;
                assert!((f64::from(s.radius.unwrap()) - mean).abs() < 1e-6);
            }
        }
    }
}

/// A size that is no size (negative, or not a number) is an error naming the line or the
/// byte, not a sphere of no size.
#[test]
fn a_negative_or_nan_size_is_an_error_naming_its_place() {
    let error_of = |name: &str, bytes: &[u8]| {
        let (_d, path) = temp_copy(name, bytes);
        DumpFile::open(&path)
            .unwrap()
            .read_frame(0, &ReadOptions::default(), &NoProgress)
            .unwrap_err()
            .to_string()
    };
    let text = std::fs::read_to_string(lammps_sample_path("granular.dump")).unwrap();
    let bad = text.replacen("1 1 0.", "1 1 -0.", 1);
    assert_ne!(bad, text);
    let e = error_of("bad.lammpstrj", bad.as_bytes());
    assert!(
        e.contains(":10:") && e.contains("`radius` -0.") && e.contains("no particle size"),
        "{e}"
    );
    // The first atom's diameter: the third of its doubles (`id type diameter x y z`).
    let mut bytes = std::fs::read(lammps_sample_path("granular.bin")).unwrap();
    let at = first_atom(&bytes) + 2 * 8;
    bytes[at..at + 8].copy_from_slice(&f64::NAN.to_le_bytes());
    let e = error_of("bad.bin", &bytes);
    assert!(
        e.contains(&format!(
            "byte {at}: atom 1 of timestep 0: column `diameter` is NaN"
        )) && e.contains("no particle size"),
        "{e}"
    );
}

/// A binary dump's box with an axis's lower bound above its upper (or not a number) is
/// refused at its bytes, as a text dump's BOX BOUNDS line is.
#[test]
fn reversed_or_nan_box_bounds_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let bytes = std::fs::read(mdlod_datasets::lammps_sample_path("cu_melt.custom.bin")).unwrap();
    // The first frame's x bounds: 0 and the cell's edge, one after the other.
    let hi = 18.075000000000003f64.to_le_bytes();
    let pair: Vec<u8> = 0f64.to_le_bytes().iter().chain(&hi).copied().collect();
    let at = bytes
        .windows(16)
        .position(|w| w == pair.as_slice())
        .expect("the x bounds");
    for (lo, name) in [(30.0f64, "reversed"), (f64::NAN, "nan")] {
        let mut b = bytes.clone();
        b[at..at + 8].copy_from_slice(&lo.to_le_bytes());
        let path = dir.path().join(format!("{name}.bin"));
        std::fs::write(&path, &b).unwrap();
        let e = DumpFile::open(&path)
            .and_then(|d| d.read_frame(0, &ReadOptions::default(), &NoProgress))
            .unwrap_err()
            .to_string();
        let why = match name {
            "nan" => "box bound is not a finite number",
            _ => "box bounds of timestep 0: x from 30 to 18.075",
        };
        assert!(
            e.contains(&format!("byte {at}:")) && e.contains(why),
            "{name}: {e}"
        );
    }
}

/// `--columns` names the columns of old-revision dumps, which name none: a dump that
/// names its own refuses other names (its `mol` column was read as the types), and a
/// text dump any; a name given twice is refused.
#[test]
fn column_names_given_for_a_dump_that_names_its_own_are_refused() {
    let read = |path: &std::path::Path, names: &[&str]| {
        DumpFile::open(path)
            .unwrap()
            .read_frame(
                0,
                &ReadOptions {
                    columns: Some(names.iter().map(|n| n.to_string()).collect()),
                    ..Default::default()
                },
                &NoProgress,
            )
            .map(|_| ())
            .map_err(|e| e.to_string())
    };
    let bin = lammps_sample_path("cu_melt.custom.bin");
    let own: Vec<String> = DumpFile::open(&bin).unwrap().frame_info(0).unwrap().columns;
    let own: Vec<&str> = own.iter().map(String::as_str).collect();
    assert_eq!(read(&bin, &own), Ok(()));
    let mut swapped = own.clone();
    swapped.swap(0, 1);
    let e = read(&bin, &swapped).unwrap_err();
    assert!(
        e.contains("this dump names its own columns") && e.contains("leave it out"),
        "{e}"
    );
    // Names of another count: the dump's own are named first, not the count.
    let e = read(&bin, &own[..3]).unwrap_err();
    assert!(e.contains("this dump names its own columns"), "{e}");
    // A name given twice, for an old-revision dump (which names none).
    let dir = tempfile::tempdir().unwrap();
    let old = dir.path().join("old.bin");
    std::fs::write(&old, old_revision_dump(4, |i| [i as f64, 1.0, 2.0])).unwrap();
    let e = read(&old, &["id", "id", "x", "y", "z"]).unwrap_err();
    assert!(e.contains("--columns names `id` twice"), "{e}");
    let e = read(&old, &["id", "type", "x"]).unwrap_err();
    assert!(
        e.contains("3 column names given for 5 values per atom"),
        "{e}"
    );
    let text = lammps_sample_path("cu_melt.custom.dump");
    let e = read(&text, &["id", "type", "x", "y", "z", "c_pe"]).unwrap_err();
    assert!(
        e.contains("a text dump names its own columns (id type x y z c_pe)"),
        "{e}"
    );
}

/// As in text dumps: a column read by name that the header names twice is refused (the
/// first, here the atom ids, used to be read as x), and so are scaled coordinates in a
/// box of no length along two edges (every atom used to land on one line).
#[test]
fn a_column_named_twice_and_a_box_of_no_extent_are_refused() {
    // Every occurrence of `from` in `bytes` (of `to`'s length) replaced.
    let replaced = |bytes: &[u8], from: &[u8], to: &[u8]| {
        let mut out = bytes.to_vec();
        let (mut at, mut n) = (0, 0);
        while let Some(p) = out[at..].windows(from.len()).position(|w| w == from) {
            out[at + p..at + p + to.len()].copy_from_slice(to);
            at += p + to.len();
            n += 1;
        }
        assert!(n > 0, "nothing to replace");
        out
    };
    let read_error = |name: &str, bytes: &[u8]| {
        let (_d, path) = temp_copy(name, bytes);
        DumpFile::open(&path)
            .and_then(|d| d.read_frame(0, &ReadOptions::default(), &NoProgress))
            .unwrap_err()
            .to_string()
    };
    let custom = std::fs::read(lammps_sample_path("cu_melt.custom.bin")).unwrap();
    let twice = replaced(&custom, b"id type x y z c_pe", b"x  type x y z c_pe");
    let e = read_error("twice.bin", &twice);
    assert!(
        e.contains("twice.bin") && e.contains("column `x` is named 2 times (columns 1 and 3)"),
        "{e}"
    );
    let atom = std::fs::read(lammps_sample_path("cu_melt.atom.bin")).unwrap();
    let side = 18.075000000000003f64;
    let pack = |b: [f64; 6]| b.iter().flat_map(|v| v.to_le_bytes()).collect::<Vec<u8>>();
    let flat = replaced(
        &atom,
        &pack([0.0, side, 0.0, side, 0.0, side]),
        &pack([0.0, side, 0.0, 0.0, 0.0, 0.0]),
    );
    let e = read_error("flat.bin", &flat);
    assert!(
        e.contains("flat.bin") && e.contains("no length along its edges b (y) and c (z)"),
        "{e}"
    );
}
