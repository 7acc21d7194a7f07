//! XYZ and extended XYZ reading.

use std::path::{Path, PathBuf};

use mdlod_preprocess::readers::{DumpFile, InputFormat, ReadOptions};
use mdlod_preprocess::{Frame, NoProgress};

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path
}

fn read_k(path: &Path, k: usize, attribute: Option<&str>) -> Frame {
    let dump = DumpFile::open(path).unwrap();
    let opts = ReadOptions {
        attribute: attribute.map(String::from),
        ..Default::default()
    };
    dump.read_frame(k, &opts, &NoProgress).unwrap()
}

fn names(frame: &Frame) -> Vec<&str> {
    frame.species.iter().map(|s| s.name.as_str()).collect()
}

#[test]
fn plain_xyz() {
    let dir = tempfile::tempdir().unwrap();
    let text = "3\nwater molecule\nO 0.0 0.0 0.1173\nH 0.0 0.7572 -0.4692\nH 0.0 -0.7572 -0.4692\n";
    let path = write(dir.path(), "water.xyz", text);
    let dump = DumpFile::open(&path).unwrap();
    assert_eq!(dump.format(), InputFormat::Xyz);
    assert_eq!(dump.frame_count(), 1);
    assert_eq!(dump.frame_timestep(0), None);
    let f = read_k(&path, 0, None);
    assert_eq!(names(&f), vec!["O", "H"]);
    assert!(f.species.iter().all(|s| !s.numeric_type));
    assert_eq!(f.species_index, vec![0, 1, 1]);
    assert_eq!(f.positions[1], [0.0, 0.7572, -0.4692]);
    assert!(f.simulation_box.is_none());
    assert_eq!(
        dump.frame_info(0).unwrap().columns,
        vec!["species", "x", "y", "z"]
    );
}

#[test]
fn plain_xyz_extra_columns_as_attribute() {
    let dir = tempfile::tempdir().unwrap();
    let text = "2\n\nC 1 2 3 0.5 7\nC 4 5 6 -0.5 8\n";
    let path = write(dir.path(), "extra.xyz", text);
    let f = read_k(&path, 0, Some("col5"));
    assert_eq!(f.attribute.unwrap().values, vec![0.5, -0.5]);
    let f = read_k(&path, 0, Some("col6"));
    assert_eq!(f.attribute.unwrap().values, vec![7.0, 8.0]);
}

#[test]
fn extended_xyz_lattice_properties_pbc_time() {
    let dir = tempfile::tempdir().unwrap();
    let text = "2\n\
        Lattice=\"10.0 0.0 0.0 1.0 9.0 0.0 0.5 0.5 8.0\" Properties=id:I:1:pos:R:3:forces:R:3:species:S:1:energy:R:1 pbc=\"T F T\" Time=1.5 Timestep=42 label=\"a b\"\n\
        1 1.0 2.0 3.0 0.1 0.2 0.3 Si -4.5\n\
        2 4.0 5.0 6.0 0.4 0.5 0.6 O -3.25\n";
    let path = write(dir.path(), "ext.extxyz", text);
    let dump = DumpFile::open(&path).unwrap();
    assert_eq!(dump.frame_timestep(0), Some(42));
    let info = dump.frame_info(0).unwrap();
    assert_eq!(
        info.columns,
        vec![
            "id",
            "pos[0]",
            "pos[1]",
            "pos[2]",
            "forces[0]",
            "forces[1]",
            "forces[2]",
            "species",
            "energy"
        ]
    );
    let f = read_k(&path, 0, Some("energy"));
    assert_eq!(f.positions, vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]);
    assert_eq!(names(&f), vec!["Si", "O"]);
    assert_eq!(f.attribute.as_ref().unwrap().values, vec![-4.5, -3.25]);
    assert_eq!(f.attribute.as_ref().unwrap().name, "energy");
    assert_eq!(f.time, Some(1.5));
    assert_eq!(f.timestep, Some(42));
    let b = f.simulation_box.clone().unwrap();
    assert_eq!(b.origin, [0.0; 3]);
    assert_eq!(b.a, [10.0, 0.0, 0.0]);
    assert_eq!(b.b, [1.0, 9.0, 0.0]);
    assert_eq!(b.c, [0.5, 0.5, 8.0]);
    assert_eq!(b.periodic, Some([true, false, true]));
    let f = read_k(&path, 0, Some("forces[1]"));
    assert_eq!(f.attribute.unwrap().values, vec![0.2, 0.5]);
    let f = read_k(&path, 0, Some("id"));
    assert_eq!(f.attribute.unwrap().values, vec![1.0, 2.0]);
}

#[test]
fn extended_xyz_defaults_and_origin() {
    let dir = tempfile::tempdir().unwrap();
    // Lattice without pbc means periodic; no Properties means species:S:1:pos:R:3;
    // lower-case keys and OVITO's Origin are understood.
    let text = "1\nlattice=\"2 0 0 0 2 0 0 0 2\" origin=\"-1 -1 -1\"\nAr 0.5 0.5 0.5\n";
    let path = write(dir.path(), "d.xyz", text);
    let f = read_k(&path, 0, None);
    let b = f.simulation_box.clone().unwrap();
    assert_eq!(b.origin, [-1.0; 3]);
    assert_eq!(b.periodic, Some([true; 3]));
    assert_eq!(f.positions, vec![[0.5; 3]]);
    assert_eq!(names(&f), vec!["Ar"]);
}

#[test]
fn extended_xyz_property_order_is_honoured() {
    let dir = tempfile::tempdir().unwrap();
    let text = "2\nProperties=pos:R:3:Z:I:1 Lattice=\"5 0 0 0 5 0 0 0 5\"\n1 2 3 6\n4 5 6 8\n";
    let path = write(dir.path(), "z.xyz", text);
    let f = read_k(&path, 0, None);
    assert_eq!(f.positions, vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]);
    assert_eq!(names(&f), vec!["6", "8"]);
}

#[test]
fn multi_frame_xyz_random_access() {
    let dir = tempfile::tempdir().unwrap();
    let mut text = String::new();
    for (k, n) in [3usize, 1, 2].iter().enumerate() {
        text += &format!("{n}\nProperties=species:S:1:pos:R:3 step={}\n", k * 10);
        for i in 0..*n {
            text += &format!("X{i} {} {} {}\n", k, i, 0.5);
        }
    }
    text += "\n\n";
    let path = write(dir.path(), "traj.xyz", &text);
    let dump = DumpFile::open(&path).unwrap();
    assert_eq!(dump.frame_count(), 3);
    assert_eq!(
        (0..4).map(|k| dump.frame_timestep(k)).collect::<Vec<_>>(),
        vec![Some(0), Some(10), Some(20), None]
    );
    let f = read_k(&path, 2, None);
    assert_eq!(f.positions, vec![[2.0, 0.0, 0.5], [2.0, 1.0, 0.5]]);
    assert_eq!(names(&f), vec!["X0", "X1"]);
    let f = read_k(&path, 1, None);
    assert_eq!(f.positions, vec![[1.0, 0.0, 0.5]]);
    let f = read_k(&path, 0, None);
    assert_eq!(f.len(), 3);
}

#[test]
fn lammps_xyz_dump_timestep_and_crlf() {
    let dir = tempfile::tempdir().unwrap();
    let text = "2\r\n Atoms. Timestep: 500\r\n1 0 0 0\r\n2 1 1 1\r\n2\r\n Atoms. Timestep: 600\r\n1 2 2 2\r\n2 3 3 3\r\n";
    let path = write(dir.path(), "dump.xyz", text);
    let dump = DumpFile::open(&path).unwrap();
    assert_eq!(dump.frame_timestep(0), Some(500));
    assert_eq!(dump.frame_timestep(1), Some(600));
    let f = read_k(&path, 1, None);
    assert_eq!(f.positions, vec![[2.0; 3], [3.0; 3]]);
    assert_eq!(f.timestep, Some(600));
    assert_eq!(names(&f), vec!["1", "2"]);
    assert_eq!(f.time, None);
    // With `dump_modify time yes`: the time after the timestep.
    let timed = write(
        dir.path(),
        "timed.xyz",
        &text.replace("Timestep: 600", "Timestep: 600 Time: 0.25"),
    );
    let f = read_k(&timed, 1, None);
    assert_eq!((f.timestep, f.time), (Some(600), Some(0.25)));
}

#[test]
fn gzip_xyz() {
    use std::io::Write;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("g.xyz.gz");
    let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
    enc.write_all(b"1\n\nFe 1 2 3\n").unwrap();
    std::fs::write(&path, enc.finish().unwrap()).unwrap();
    let f = read_k(&path, 0, None);
    assert_eq!(f.positions, vec![[1.0, 2.0, 3.0]]);
    // A compressed file cut short (a run still writing it: `dump custom/gz` flushes
    // frame by frame) reads the text before the cut, and says so with its last frame.
    let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
    for i in 0..2000 {
        writeln!(enc, "1\nframe {i}\nFe {i} 2 3").unwrap();
    }
    let whole = enc.finish().unwrap();
    let cut = dir.path().join("cut.xyz.gz");
    std::fs::write(&cut, &whole[..whole.len() / 2]).unwrap();
    let dump = DumpFile::open(&cut).unwrap();
    let n = dump.frame_count();
    assert!(n > 100 && n < 2000, "{n} frames");
    let f = read_k(&cut, 100, None);
    assert_eq!(f.positions, vec![[100.0, 2.0, 3.0]]);
    let notes = dump.frame_notes(n - 1, &ReadOptions::default());
    assert!(
        notes
            .iter()
            .any(|n| n.contains("compressed stream cut short: ")
                && n.contains("cut.xyz.gz ends early")),
        "{notes:?}"
    );
    assert!(dump.frame_notes(0, &ReadOptions::default()).is_empty());
    // Cut inside its first block, nothing decompresses: the error says how to keep text.
    std::fs::write(&cut, &whole[..12]).unwrap();
    let Err(e) = DumpFile::open(&cut) else {
        panic!("a gzip file of no text opened")
    };
    let e = e.to_string();
    assert!(e.contains("ends early") && e.contains("zcat"), "{e}");
}

/// The generator's extended XYZ holds the same frames as its LAMMPS dump: positions,
/// species, the extra column, the box and the timestep (the large-scale XYZ benchmark
/// converts such files).
#[test]
fn generated_xyz_reads_as_the_generated_lammps_dump() {
    use mdlod_datasets::{write_lammps_dump, write_xyz, GenerateOptions, Kind};
    let dir = tempfile::tempdir().unwrap();
    let mut opts = GenerateOptions::new(Kind::Alloy, 3000);
    opts.frames = 2;
    let (mut lammps, mut xyz) = (Vec::new(), Vec::new());
    write_lammps_dump(&opts, &mut lammps, |_| {}).unwrap();
    write_xyz(&opts, &mut xyz, |_| {}).unwrap();
    let lammps_path = dir.path().join("alloy.lammpstrj");
    std::fs::write(&lammps_path, lammps).unwrap();
    let xyz_path = dir.path().join("alloy.xyz");
    std::fs::write(&xyz_path, xyz).unwrap();
    let (l, x) = (
        DumpFile::open(&lammps_path).unwrap(),
        DumpFile::open(&xyz_path).unwrap(),
    );
    assert_eq!(x.format(), InputFormat::Xyz);
    assert_eq!(x.frame_count(), 2);
    for k in 0..2 {
        let a = read_k(&lammps_path, k, Some("c_pe"));
        let b = read_k(&xyz_path, k, Some("c_pe"));
        assert_eq!(a.positions, b.positions, "frame {k}");
        let per_particle = |f: &Frame| -> Vec<String> {
            f.species_index
                .iter()
                .map(|&s| f.species[usize::from(s)].name.clone())
                .collect()
        };
        assert_eq!(per_particle(&a), per_particle(&b), "frame {k}");
        assert!(per_particle(&b).iter().any(|s| s == "2"), "frame {k}");
        assert_eq!(a.attribute, b.attribute, "frame {k}");
        assert_eq!(b.timestep, Some(100 * k as u64));
        assert_eq!(l.frame_timestep(k), x.frame_timestep(k));
        let (ba, bb) = (a.simulation_box.unwrap(), b.simulation_box.unwrap());
        assert_eq!(format!("{ba:?}"), format!("{bb:?}"), "frame {k}");
    }
}

/// Species are ordered as the LAMMPS text reader orders them, so the same data gives the
/// same species table (and colours) in either format: numbers numerically (flagged as
/// numeric types), element symbols and labels in order of first appearance.
#[test]
fn species_are_ordered_as_lammps_text_orders_them() {
    use mdlod_datasets::{write_lammps_dump, write_xyz, GenerateOptions, Kind};
    let dir = tempfile::tempdir().unwrap();
    let numbers = "4\nplain\n10 0 0 0\n2 1 0 0\n9 0 1 0\n2 0 0 1\n";
    let f = read_k(&write(dir.path(), "n.xyz", numbers), 0, None);
    assert_eq!(names(&f), ["2", "9", "10"]);
    assert!(f.species.iter().all(|s| s.numeric_type));
    assert_eq!(f.species_index, [2, 0, 1, 0]);
    let extended = "3\nProperties=pos:R:3:Z:I:1\n0 0 0 29\n1 0 0 8\n0 1 0 29\n";
    let f = read_k(&write(dir.path(), "z.xyz", extended), 0, None);
    assert_eq!(names(&f), ["8", "29"]);
    assert_eq!(f.species_index, [1, 0, 1]);
    // Not all numbers: first appearance, as an `element` column.
    let mixed = "3\nmixed\nO 0 0 0\n1 1 0 0\nH 0 1 0\n";
    let f = read_k(&write(dir.path(), "m.xyz", mixed), 0, None);
    assert_eq!(names(&f), ["O", "1", "H"]);
    assert!(f.species.iter().all(|s| !s.numeric_type));

    // The generator's data (its first atoms are type 2) in both formats.
    let opts = GenerateOptions::new(Kind::Droplets, 3000);
    let xyz = dir.path().join("d.xyz");
    let lammps = dir.path().join("d.lammpstrj");
    write_xyz(&opts, &mut std::fs::File::create(&xyz).unwrap(), |_| {}).unwrap();
    write_lammps_dump(&opts, &mut std::fs::File::create(&lammps).unwrap(), |_| {}).unwrap();
    let (x, l) = (read_k(&xyz, 0, None), read_k(&lammps, 0, None));
    assert_eq!(l.species_index[0], 1, "the data starts with type 2");
    // The same species, in the same order, with the same palette slots.
    let plain = |f: &mdlod_preprocess::Frame| -> Vec<(String, bool, Option<usize>)> {
        f.species
            .iter()
            .map(|s| (s.name.clone(), s.numeric_type, s.palette_slot))
            .collect()
    };
    assert_eq!(plain(&x), plain(&l));
    assert_eq!(x.species_index, l.species_index);
}

/// XYZ numbers that are no type numbers take palette colours by their place: species 0
/// and 1 (0-based), or atomic numbers 1 and 11 (`Z:I:1`), stay apart.
#[test]
fn numeric_xyz_species_take_distinct_palette_colours() {
    let dir = tempfile::tempdir().unwrap();
    for (a, b, properties) in [
        ("0", "1", "numbers"),
        ("1", "11", "Properties=pos:R:3:Z:I:1"),
    ] {
        let text = if properties == "numbers" {
            format!("2\n{properties}\n{a} 0 0 0\n{b} 1 0 0\n")
        } else {
            format!("2\n{properties}\n0 0 0 {a}\n1 0 0 {b}\n")
        };
        let f = read_k(&write(dir.path(), &format!("n{a}{b}.xyz"), &text), 0, None);
        assert!(
            f.species.iter().all(|s| s.palette_slot.is_none()),
            "{a} and {b}"
        );
        let table = mdlod_preprocess::species::species_table(&f.species, &[]);
        assert_ne!(table[0].colour, table[1].colour, "{a} and {b}");
    }
}

/// Positions come from `pos`, `position` or `positions` with three numbers; a
/// `Properties` naming none is an error in extended-XYZ terms, naming the line.
#[test]
fn properties_without_positions_say_what_names_them() {
    let dir = tempfile::tempdir().unwrap();
    let ok = write(
        dir.path(),
        "ok.xyz",
        "2\nProperties=species:S:1:position:R:3\nCu 0 0 0\nCu 1 2 3\n",
    );
    assert_eq!(read_k(&ok, 0, None).positions[1], [1.0, 2.0, 3.0]);
    for (props, says) in [
        (
            "species:S:1:pos:R:2",
            "entry `pos:R:2` is no position: positions are three real numbers (`pos:R:3`; \
             a two-dimensional run writes z as 0)",
        ),
        ("species:S:1:pos:S:3", "entry `pos:S:3` is no position"),
        ("species:S:1:coords:R:3", "names no positions"),
    ] {
        let path = write(
            dir.path(),
            "bad.xyz",
            &format!("1\nProperties={props}\nCu 0 0 0\n"),
        );
        let e = DumpFile::open(&path)
            .err()
            .map(|e| e.to_string())
            .unwrap_or_else(|| {
                DumpFile::open(&path)
                    .unwrap()
                    .read_frame(0, &ReadOptions::default(), &NoProgress)
                    .unwrap_err()
                    .to_string()
            });
        assert!(
            e.contains("bad.xyz:2:") && e.contains(says) && e.contains("`pos:R:3`"),
            "{e}"
        );
    }
}

/// A plain XYZ comment line is free text: CP2K's `i = 0, time = 0.000, E = ...` gives
/// time 0 (its comma ends the value), another tool's `time=1.5fs` the time 1.5 (its unit
/// left out), and `step 5` no timestep, not an error.
#[test]
fn free_text_comment_lines_do_not_stop_a_conversion() {
    let dir = tempfile::tempdir().unwrap();
    let cp2k = "2\n i =        0, time =        0.000, E =       -17.1643)\n\
                O 0 0 0\nH 1 0 0\n\
                2\n i =        1, time =        0.500, E =       -17.1650\n\
                O 0 0 1\nH 1 0 1\n";
    let path = write(dir.path(), "cp2k.xyz", cp2k);
    let f = read_k(&path, 0, None);
    assert_eq!((f.time, f.len()), (Some(0.0), 2));
    assert_eq!(read_k(&path, 1, None).time, Some(0.5));

    let other = "1\nMD step 5 time=1.5fs\nAr 0 0 0\n1\nMD step = 6, time = 2fs\nAr 0 0 1\n";
    let path = write(dir.path(), "other.xyz", other);
    let dump = DumpFile::open(&path).unwrap();
    // `step 5` is no `step=` (and no LAMMPS `Timestep:`); CP2K-style `step = 6,` is.
    assert_eq!(dump.frame_timestep(0), None);
    assert_eq!(dump.frame_timestep(1), Some(6));
    let f = read_k(&path, 0, None);
    assert_eq!((f.time, f.timestep, f.len()), (Some(1.5), None, 1));
    let f = read_k(&path, 1, None);
    assert_eq!((f.time, f.timestep), (Some(2.0), Some(6)));

    // The words of a cell's keys in free text give no cell.
    let words = "1\nCu slab, no lattice or origin given, pbc off\nCu 0 0 0\n";
    let path = write(dir.path(), "words.xyz", words);
    let f = read_k(&path, 0, None);
    assert_eq!((f.len(), f.simulation_box.is_none()), (1, true));
}

/// In extended XYZ (`Properties=`) the comment line is `key=value` pairs: a `Time` that is
/// no number (nor a number with its unit after it, `1.5fs`) is an error naming the key as
/// the file spells it.
#[test]
fn extended_xyz_refuses_a_time_that_is_no_number_naming_its_key() {
    let dir = tempfile::tempdir().unwrap();
    for key in ["time", "Time", "TIME"] {
        let text = format!("1\nProperties=species:S:1:pos:R:3 {key}=fs1.5\nAr 0 0 0\n");
        let path = write(dir.path(), "ext.xyz", &text);
        let e = DumpFile::open(&path)
            .and_then(|d| d.read_frame(0, &ReadOptions::default(), &NoProgress))
            .expect_err("a non-numeric time read")
            .to_string();
        assert!(
            e.contains("ext.xyz:2:") && e.contains(&format!("`{key}` is not a number: `fs1.5`")),
            "{e}"
        );
    }
    // A number is a time, with or without a trailing comma.
    let text = "1\nProperties=species:S:1:pos:R:3 Time=2.5, Timestep=7,\nAr 0 0 0\n";
    let f = read_k(&write(dir.path(), "ok.xyz", text), 0, None);
    assert_eq!((f.time, f.timestep), (Some(2.5), Some(7)));
}

/// Numbered XYZ species take the palette colours LAMMPS gives the same type numbers
/// (type `n`: the `n`-th colour), so that the same data looks the same in either format.
#[test]
fn numbered_xyz_species_take_the_colours_of_the_same_lammps_types() {
    use mdlod_preprocess::species::species_table;
    let dir = tempfile::tempdir().unwrap();
    let lammps = "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n3\n\
                  ITEM: BOX BOUNDS pp pp pp\n0 10\n0 10\n0 10\n\
                  ITEM: ATOMS id type x y z\n1 6 0 0 0\n2 1 1 0 0\n3 8 0 1 0\n";
    let l = read_k(&write(dir.path(), "d.lammpstrj", lammps), 0, None);
    let plain = "3\ntypes\n6 0 0 0\n1 1 0 0\n8 0 1 0\n";
    let extended = "3\nProperties=species:S:1:pos:R:3\n6 0 0 0\n1 1 0 0\n8 0 1 0\n";
    let colours = |f: &Frame| -> Vec<(String, [f32; 3])> {
        species_table(&f.species, &[])
            .into_iter()
            .map(|s| (s.name, s.colour))
            .collect()
    };
    let expected = colours(&l);
    assert_eq!(expected.len(), 3);
    for (name, text) in [("p.xyz", plain), ("e.xyz", extended)] {
        let x = read_k(&write(dir.path(), name, text), 0, None);
        assert_eq!(colours(&x), expected, "{name}");
        assert_eq!(x.species, l.species, "{name}");
    }
}

/// A name that says one text format over content that says the other is read by its
/// content: LAMMPS `dump xyz` output named `dump.water`, a LAMMPS text dump named `.xyz`.
#[test]
fn text_content_decides_over_a_name_that_says_the_other_format() {
    use mdlod_preprocess::readers::{DumpFile, InputFormat, ReadOptions};
    let dir = tempfile::tempdir().unwrap();
    let xyz = dir.path().join("dump.water");
    std::fs::write(&xyz, "2\nwater\nO 0 0 0\nH 0.96 0 0\n").unwrap();
    let d = DumpFile::open(&xyz).unwrap();
    assert_eq!(d.format(), InputFormat::Xyz);
    let f = d
        .read_frame(0, &ReadOptions::default(), &mdlod_preprocess::NoProgress)
        .unwrap();
    assert_eq!(f.len(), 2);
    let lammps = dir.path().join("traj.xyz");
    std::fs::write(
        &lammps,
        "ITEM: TIMESTEP\n5\nITEM: NUMBER OF ATOMS\n1\nITEM: BOX BOUNDS pp pp pp\n0 1\n0 1\n\
         0 1\nITEM: ATOMS id type x y z\n1 1 0.5 0.5 0.5\n",
    )
    .unwrap();
    let d = DumpFile::open(&lammps).unwrap();
    assert_eq!(d.format(), InputFormat::LammpsText);
    assert_eq!(d.frame_timestep(0), Some(5));
}

/// A comment line of megabytes is no extended-XYZ header: refused, naming its line,
/// rather than split into millions of strings (a 260 kB gzip file took 1.6 GB).
#[test]
fn a_comment_line_of_megabytes_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("long.xyz");
    let comment = "x".repeat(2 << 20);
    std::fs::write(&path, format!("1\n{comment}\nCu 0 0 0\n")).unwrap();
    let e = DumpFile::open(&path)
        .and_then(|d| d.read_frame(0, &ReadOptions::default(), &NoProgress))
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with(&format!("{}:2:", path.display()))
            && e.contains("a comment line of 2097152 bytes (at most 1 MiB"),
        "{e}"
    );
}

/// A value of megabytes that is no number is named by its first characters (the whole
/// token was repeated in the message).
#[test]
fn a_huge_bad_value_is_named_briefly() {
    let dir = tempfile::tempdir().unwrap();
    let text = format!("2\nf\nCu 0 0 0\nCu 0 1 {}\n", "x".repeat(5_000_000));
    let path = write(dir.path(), "huge.xyz", &text);
    let e = DumpFile::open(&path)
        .unwrap()
        .read_frame(0, &ReadOptions::default(), &NoProgress)
        .unwrap_err()
        .to_string();
    assert!(
        e.len() < 300 && e.contains("huge.xyz:4:") && e.contains("xxx..."),
        "{}",
        &e[..e.len().min(300)]
    );
}

/// An extended XYZ file's integer property as the species (`--species-column`): each
/// atom keeps its element's size, so a category holding two elements draws each at its
/// own (Cu 1.28, Ag 1.44 Å); and the option is refused where species come by no column.
#[test]
fn a_species_column_keeps_each_atoms_element_size() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("alloy.xyz");
    std::fs::write(
        &path,
        "4\nLattice=\"10 0 0 0 10 0 0 0 10\" Properties=species:S:1:pos:R:3:structure:I:1\n\
         Cu 0 0 0 1\nCu 1 0 0 2\nAg 0 1 0 1\nCu 0 0 1 1\n",
    )
    .unwrap();
    let opts = ReadOptions {
        species_column: Some("structure".into()),
        ..Default::default()
    };
    let f = DumpFile::open(&path)
        .unwrap()
        .read_frame(0, &opts, &NoProgress)
        .unwrap();
    let names: Vec<&str> = f.species.iter().map(|s| s.name.as_str()).collect();
    assert_eq!(names, ["1", "2"]);
    assert_eq!(f.species_index, [0, 1, 0, 0]);
    assert_eq!(f.radii.as_deref(), Some(&[1.28, 1.28, 1.44, 1.28][..]));
    assert_eq!(f.species[0].radius_range, Some((1.28, 1.44)));
    // --no-sizes: no sizes of their own; each category its atoms' mean.
    let off = ReadOptions {
        sizes: mdlod_preprocess::readers::SizeColumn::Off,
        ..opts.clone()
    };
    let f = DumpFile::open(&path)
        .unwrap()
        .read_frame(0, &off, &NoProgress)
        .unwrap();
    assert!(f.radii.is_none());
    let mean = (1.28f64 * 2.0 + 1.44) / 3.0;
    assert!((f64::from(f.species[0].radius.unwrap()) - mean).abs() < 1e-6);
    assert_eq!(f.species[0].radius_range, None);
    assert_eq!(f.species[1].radius, Some(1.28));
}

/// A smoothing-length column (an SPH run's `h`) is not read as sizes by default: a note
/// names the option that reads it, and none is given once it is read.
#[test]
fn a_smoothing_length_column_is_pointed_out() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(
        dir.path(),
        "sph.xyz",
        "2\nProperties=species:S:1:pos:R:3:h:R:1:rho:R:1\ngas 0 0 0 0.1 1\ngas 1 0 0 0.2 2\n",
    );
    let dump = DumpFile::open(&path).unwrap();
    let notes = dump.frame_notes(0, &ReadOptions::default());
    assert!(
        notes
            .iter()
            .any(|n| n.contains("column `h` looks like a smoothing length")
                && n.contains("--radius-column h")),
        "{notes:?}"
    );
    let read = ReadOptions {
        sizes: mdlod_preprocess::readers::SizeColumn::Radius("h".into()),
        ..Default::default()
    };
    assert!(dump.frame_notes(0, &read).is_empty());
}

/// A frame with an atom line missing: the next frame's count is taken for its last atom
/// and its comment line for the next count; the error names the frame short of lines.
#[test]
fn a_frame_short_of_atom_lines_is_named_at_the_next_frames_comment() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("short.xyz");
    let comment = "Lattice=\"10 0 0 0 10 0 0 0 10\" Properties=species:S:1:pos:R:3";
    std::fs::write(
        &path,
        format!("3\n{comment}\nCu 0 0 0\nCu 1 1 1\n3\n{comment}\nCu 0 0 0\nCu 1 1 1\nCu 2 2 2\n"),
    )
    .unwrap();
    let e = mdlod_preprocess::readers::DumpFile::open(&path)
        .err()
        .unwrap()
        .to_string();
    assert!(
        e.contains("short.xyz:6: expected the atom count of frame 1")
            && e.contains(
                "this reads as a frame's comment line: frame 0 (its count at line 1) may hold \
                 fewer than the 3 atom lines it announces"
            ),
        "{e}"
    );
}
