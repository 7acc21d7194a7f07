//! Bad input gives a clear error naming the file and line, never a panic.

use std::io::Write;
use std::path::{Path, PathBuf};

use mdlod_preprocess::readers::{DumpFile, ReadError, ReadOptions};
use mdlod_preprocess::NoProgress;

fn write(dir: &Path, name: &str, text: &[u8]) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path
}

/// Opens `text` as `name` and reads frame `k` with `attribute`; returns the error message.
fn error_k(name: &str, text: &str, k: usize, attribute: Option<&str>) -> (PathBuf, String) {
    let dir = tempfile::tempdir().unwrap();
    let path = write(dir.path(), name, text.as_bytes());
    let opts = ReadOptions {
        attribute: attribute.map(String::from),
        ..Default::default()
    };
    let result = DumpFile::open(&path).and_then(|d| d.read_frame(k, &opts, &NoProgress));
    match result {
        Ok(f) => panic!("{name}: expected an error, read {} atoms", f.len()),
        Err(e) => (path, e.to_string()),
    }
}

/// Asserts that reading frame 0 of `text` fails with exactly `path:<message>`.
fn assert_error(name: &str, text: &str, attribute: Option<&str>, message: &str) {
    let (path, got) = error_k(name, text, 0, attribute);
    assert_eq!(got, format!("{}:{message}", path.display()));
}

const HEAD: &str = "\
ITEM: TIMESTEP
0
ITEM: NUMBER OF ATOMS
3
ITEM: BOX BOUNDS pp pp pp
0.0 10.0
0.0 10.0
0.0 10.0
ITEM: ATOMS id type x y z
";
// Atom lines are lines 10, 11, 12.

fn dump(atoms: &str) -> String {
    format!("{HEAD}{atoms}")
}

#[test]
fn empty_file() {
    assert_error("e.lammpstrj", "", None, "1: file is empty");
    assert_error("e.xyz", "  \n\n", None, "1: file is empty");
}

#[test]
fn truncated_frame() {
    assert_error(
        "t.lammpstrj",
        &dump("1 1 0 0 0\n2 1 0 0 0\n"),
        None,
        "11: truncated frame: the header announces 3 atoms but only 2 atom lines follow",
    );
}

#[test]
fn atom_count_larger_than_lines_present_before_next_frame() {
    let text = format!(
        "{}{}",
        dump("1 1 0 0 0\n"),
        dump("1 1 1 1 1\n2 1 2 2 2\n3 1 3 3 3\n")
    );
    let dir = tempfile::tempdir().unwrap();
    let path = write(dir.path(), "mid.lammpstrj", text.as_bytes());
    let d = DumpFile::open(&path).unwrap();
    let got = d
        .read_frame(0, &ReadOptions::default(), &NoProgress)
        .unwrap_err()
        .to_string();
    assert_eq!(
        got,
        format!(
            "{}:10: truncated frame: the header announces 3 atoms but only 1 atom lines follow",
            path.display()
        )
    );
    // The next frame is unaffected.
    assert_eq!(d.frame_count(), 2);
    let f = d
        .read_frame(1, &ReadOptions::default(), &NoProgress)
        .unwrap();
    assert_eq!(f.positions[2], [3.0; 3]);
}

#[test]
fn more_atom_lines_than_announced() {
    assert_error(
        "x.lammpstrj",
        &dump("1 1 0 0 0\n2 1 0 0 0\n3 1 0 0 0\n4 1 0 0 0\n"),
        None,
        "13: more atom lines than the 3 the header announces",
    );
}

/// Numbers too long to print as written are shown in scientific notation (a bound of
/// 1e308 printed 309 digits).
#[test]
fn huge_box_bounds_are_said_in_scientific_notation() {
    assert_error(
        "huge.dump",
        "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n1\nITEM: BOX BOUNDS pp pp pp\n1e308 -1e308\n\
         0 1\n0 1\nITEM: ATOMS id type x y z\n1 1 0 0 0\n",
        None,
        "6: malformed BOX BOUNDS: `1e308 -1e308` has its lower bound 1e308 above its upper bound \
         -1e308",
    );
}

/// A triclinic box whose tilts reach past its bounds is refused, as an orthogonal one
/// whose lower bound is above its upper is (it was converted, its cell inverted).
#[test]
fn a_tilted_box_whose_tilts_reach_past_its_bounds_is_refused() {
    assert_error(
        "tilted.dump",
        "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n1\nITEM: BOX BOUNDS xy xz yz pp pp pp\n\
         0 10 1e30\n0 10 -1e30\n0 10 1e30\nITEM: ATOMS id type x y z\n1 1 0 0 0\n",
        None,
        "5: malformed BOX BOUNDS: the tilts xy xz yz (1e30 -1e30 1e30) reach past the bounds: \
         the box's x edge runs from 1e30 to -1e30 (the `_bound` values hold the tilted box, as \
         LAMMPS writes them)",
    );
}

/// A `dump local` says what it is (it was "frame 0 ends before its `ITEM: ATOMS` line").
#[test]
fn a_dump_local_says_it_holds_entries() {
    assert_error(
        "local.dump",
        "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ENTRIES\n1\nITEM: BOX BOUNDS pp pp pp\n0 1\n\
         0 1\n0 1\nITEM: ENTRIES index c_1[1] c_1[2]\n1 3 4\n",
        None,
        "3: frame 0 is a `dump local` one (`ITEM: NUMBER OF ENTRIES`): its lines are \
         entries, such as bonds or pairs, not particles; `dump custom` writes the atoms",
    );
}

/// A file cut inside an atom line says so; a short line followed by a newline is a
/// wrong column count.
#[test]
fn file_cut_in_the_middle_of_a_line() {
    assert_error(
        "cut.lammpstrj",
        &dump("1 1 0 0 0\n2 1 0 0 0\n3 1 0.5 0."),
        None,
        "12: the file ends inside this atom line, after 4 of its 5 columns (truncated file?)",
    );
    assert_error(
        "short.lammpstrj",
        &dump("1 1 0 0 0\n2 1 0 0 0\n3 1 0\n"),
        None,
        "12: expected 5 columns, found 3",
    );
}

#[test]
fn wrong_column_count() {
    assert_error(
        "c.lammpstrj",
        &dump("1 1 0 0 0\n2 1 0 0\n3 1 0 0 0\n"),
        None,
        "11: expected 5 columns, found 4",
    );
    assert_error(
        "c6.lammpstrj",
        &dump("1 1 0 0 0\n2 1 0 0 0\n3 1 0 0 0 9\n"),
        None,
        "12: expected 5 columns, found 6",
    );
    // Scaled coordinates in a box of no length along x and y: refused, not all put on
    // one line.
    let flat = HEAD
        .replacen("0.0 10.0", "0 0", 2)
        .replace("x y z", "xs ys zs");
    assert_error(
        "flat.lammpstrj",
        &format!("{flat}1 1 0.1 0.2 0.3\n2 1 0.5 0.5 0.5\n3 1 0.9 0.1 0.2\n"),
        None,
        "9: scaled coordinates, but the box has no length along its edges a (x) and b (y): \
         they cannot be unscaled (is the box right?)",
    );
    // One such edge is a flat system's (a 2-D run's Lz of 0): read, on the plane z = 0.
    let plane = HEAD
        .replace("0.0 10.0\nITEM: ATOMS", "0 0\nITEM: ATOMS")
        .replace("x y z", "xs ys zs");
    let dir = tempfile::tempdir().unwrap();
    let path = write(
        dir.path(),
        "plane.lammpstrj",
        format!("{plane}1 1 0.1 0.2 0.3\n2 1 0.5 0.5 0.5\n3 1 0.9 0.1 0.2\n").as_bytes(),
    );
    let f = DumpFile::open(&path)
        .unwrap()
        .read_frame(0, &ReadOptions::default(), &NoProgress)
        .unwrap();
    assert_eq!(f.positions[2], [9.0, 1.0, 0.0]);
    // A position column named twice, its copies differing: refused where they differ
    // (the first used to be taken silently). Copies that agree are read (LIGGGHTS's `id
    // type type`).
    let twice = HEAD.replace("x y z", "x y z x");
    let (path, got) = error_k(
        "twice.lammpstrj",
        &format!("{twice}1 1 0 0 0 0\n2 1 0 0 0 5\n3 1 0 0 0 5\n"),
        0,
        None,
    );
    let path = path.display();
    assert_eq!(
        got,
        format!(
            "{path}:11: column `x` is named 2 times (columns 3 and 6), and they differ here (`0` \
             in column 3, `5` in column 6): which one holds the data cannot be told; rename the \
             others (`sed -i 's/^ITEM: ATOMS .*/ITEM: ATOMS id type x y z x_2/' {path}`)"
        )
    );
    // A header naming twice the columns every line holds: every line is there, so it
    // is a column count, not a frame cut short (which a rerun would wait for).
    let wide = HEAD.replace("x y z", "x y z a b c d e");
    assert_error(
        "c10.lammpstrj",
        &format!("{wide}1 1 0 0 0\n2 1 0 0 0\n3 1 0 0 0\n"),
        None,
        "10: expected 10 columns, found 5",
    );
}

#[test]
fn non_numeric_field() {
    assert_error(
        "n.lammpstrj",
        &dump("1 1 0 0 0\n2 1 0 0 0\n3 1 0 abc 0\n"),
        None,
        "12: column `y`: `abc` is not a number",
    );
}

#[test]
fn nan_or_inf_coordinate() {
    assert_error(
        "nan.lammpstrj",
        &dump("1 1 nan 0 0\n2 1 0 0 0\n3 1 0 0 0\n"),
        None,
        "10: column `x`: `nan` is not a finite number",
    );
    assert_error(
        "inf.lammpstrj",
        &dump("1 1 0 0 0\n2 1 0 0 -inf\n3 1 0 0 0\n"),
        None,
        "11: column `z`: `-inf` is not a finite number",
    );
    assert_error(
        "big.lammpstrj",
        &dump("1 1 0 0 0\n2 1 0 0 0\n3 1 1e300 0 0\n"),
        None,
        "12: position (1e300, 0.0, 0.0) is outside the single-precision range",
    );
    // An attribute past single precision: its column named, as a NaN's is.
    let text = HEAD.replace("id type x y z", "id type x y z c_big")
        + "1 1 0 0 0 1\n2 1 0 0 0 -1e39\n3 1 0 0 0 2\n";
    assert_error(
        "range.lammpstrj",
        &text,
        Some("c_big"),
        "11: column c_big: attribute value -1e39 is outside the single-precision range",
    );
}

#[test]
fn no_coordinate_columns() {
    let text = HEAD.replace("id type x y z", "id type vx vy x y")
        + "1 1 0 0 0 0\n2 1 0 0 0 0\n3 1 0 0 0 0\n";
    assert_error(
        "nc.lammpstrj",
        &text,
        None,
        "9: no coordinate columns (need x y z, xu yu zu, xs ys zs or xsu ysu zsu); columns are: id type vx vy x y",
    );
}

#[test]
fn scaled_coordinates_without_box() {
    let text =
        "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n1\nITEM: ATOMS id type xs ys zs\n1 1 0 0 0\n";
    assert_error(
        "nb.lammpstrj",
        text,
        None,
        "5: scaled coordinates but no ITEM: BOX BOUNDS to unscale them",
    );
}

#[test]
fn malformed_box_bounds() {
    assert_error(
        "b1.lammpstrj",
        &dump("").replace("0.0 10.0\nITEM: ATOMS", "0.0\nITEM: ATOMS"),
        None,
        "8: malformed BOX BOUNDS: expected 2 numbers (lo hi), found `0.0`",
    );
    assert_error(
        "b2.lammpstrj",
        &dump("").replacen("0.0 10.0", "0.0 ten", 1),
        None,
        "6: malformed BOX BOUNDS: `ten` is not a finite number",
    );
    assert_error(
        "b3.lammpstrj",
        &dump("").replace("BOX BOUNDS pp pp pp", "BOX BOUNDS xy xz yz pp pp pp"),
        None,
        "6: malformed BOX BOUNDS: expected 3 numbers (lo_bound hi_bound tilt), found `0.0 10.0`",
    );
}

#[test]
fn malformed_header_values() {
    assert_error(
        "h1.lammpstrj",
        &dump("").replacen("3\n", "three\n", 1),
        None,
        "4: malformed `ITEM: NUMBER OF ATOMS` value `three`",
    );
    assert_error(
        "h2.lammpstrj",
        &dump("").replacen("TIMESTEP\n0", "TIMESTEP\n-1", 1),
        None,
        "2: malformed `ITEM: TIMESTEP` value `-1`",
    );
    assert_error(
        "h3.lammpstrj",
        &dump("").replace("ITEM: NUMBER OF ATOMS\n3\n", ""),
        None,
        "7: no `ITEM: NUMBER OF ATOMS` before `ITEM: ATOMS`",
    );
    assert_error(
        "h4.lammpstrj",
        "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n3\n",
        None,
        "4: frame 0 ends before its `ITEM: ATOMS` line",
    );
    assert_error(
        "h5.lammpstrj",
        "garbage\nITEM: TIMESTEP\n0\n",
        None,
        "1: expected `ITEM: TIMESTEP` to start the dump, found `garbage`",
    );
    assert_error(
        "h6.lammpstrj",
        "ITEM: NUMBER OF ATOMS\n0\n",
        None,
        "1: no `ITEM: TIMESTEP` line found: not a LAMMPS text dump",
    );
}

#[test]
fn unknown_attribute_column() {
    assert_error(
        "a.lammpstrj",
        &dump("1 1 0 0 0\n2 1 0 0 0\n3 1 0 0 0\n"),
        Some("c_pe"),
        "9: no column `c_pe` for the attribute; available columns: id type x y z",
    );
}

#[test]
fn non_numeric_attribute() {
    let text =
        HEAD.replace("id type x y z", "id element x y z") + "1 Cu 0 0 0\n2 Cu 0 0 0\n3 Cu 0 0 0\n";
    assert_error(
        "na.lammpstrj",
        &text,
        Some("element"),
        "10: column `element`: `Cu` is not a number",
    );
}

#[test]
fn unknown_format_and_unsupported_compression() {
    assert_error(
        "mystery.txt",
        "hello world\n",
        None,
        "1: cannot tell the format from the name or the first line `hello world`; expected a LAMMPS text dump (`ITEM: ...`), an XYZ file (atom count) or a raw sidecar (a JSON object with `\"mdlod_raw\": 1`)",
    );
    let dir = tempfile::tempdir().unwrap();
    let path = write(
        dir.path(),
        "z.lammpstrj.zst",
        &[0x28, 0xb5, 0x2f, 0xfd, 0, 0, 0, 0],
    );
    let got = DumpFile::open(&path).unwrap_err().to_string();
    assert!(
        got.starts_with(&format!(
            "{}:1: zstd-compressed dumps are not supported",
            path.display()
        )),
        "{got}"
    );
    // xz (which was taken for text that no format starts with), and a gzip file
    // compressed twice, name their compression.
    let xz = [0xfd, b'7', b'z', b'X', b'Z', 0, 0, 4, 0xe6, 0xd6];
    let path = write(dir.path(), "x.lammpstrj.xz", &xz);
    let got = DumpFile::open(&path).unwrap_err().to_string();
    assert!(
        got.contains("xz-compressed dumps are not supported") && got.contains("gzip"),
        "{got}"
    );
    let gz = |bytes: &[u8]| {
        let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
        enc.write_all(bytes).unwrap();
        enc.finish().unwrap()
    };
    // A tar archive, and one gzipped (a .tar.gz), are named as archives.
    let mut tar = vec![0u8; 1024];
    tar[..13].copy_from_slice(b"d.lammpstrj\0\0");
    tar[257..263].copy_from_slice(b"ustar\0");
    for (name, bytes) in [("a.tar", tar.clone()), ("a.lammpstrj.gz", gz(&tar))] {
        let path = write(dir.path(), name, &bytes);
        let got = DumpFile::open(&path).unwrap_err().to_string();
        assert!(
            got.contains("tar archive") && got.contains("tar -x"),
            "{got}"
        );
    }
    let twice = gz(&gz(dump("1 1 0 0 0\n").as_bytes()));
    let path = write(dir.path(), "twice.lammpstrj.gz", &twice);
    let got = DumpFile::open(&path).unwrap_err().to_string();
    assert!(
        got.starts_with(&path.display().to_string())
            && got.contains("holds gzip-compressed data, not a dump: compressed twice?"),
        "{got}"
    );
}

#[test]
fn corrupt_gzip() {
    let dir = tempfile::tempdir().unwrap();
    let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
    enc.write_all(dump("1 1 0 0 0\n").repeat(50).as_bytes())
        .unwrap();
    let bytes = enc.finish().unwrap();
    // Garbage inside the compressed stream (not a stream that ends early, which reads
    // the text before its end).
    let mut garbled = bytes.clone();
    for b in &mut garbled[12..bytes.len() - 8] {
        *b = 0xff;
    }
    let path = write(dir.path(), "bad.lammpstrj.gz", &garbled);
    let err = DumpFile::open(&path).unwrap_err();
    assert!(matches!(err, ReadError::Io { .. }));
    let got = err.to_string();
    assert!(
        got.starts_with(&format!("{}: gzip decompression failed", path.display())),
        "{got}"
    );
    // Cut in half (50 frames): the frames before the cut read, the one it falls in is
    // cut short, and said to be.
    let path = write(dir.path(), "cut.lammpstrj.gz", &bytes[..bytes.len() / 2]);
    let dump = DumpFile::open(&path).unwrap();
    let n = dump.frame_count();
    assert!((1..50).contains(&n), "{n} frames");
    if n > 1 {
        dump.read_frame(0, &ReadOptions::default(), &NoProgress)
            .unwrap();
    }
    let got = dump
        .read_frame(n - 1, &ReadOptions::default(), &NoProgress)
        .unwrap_err()
        .to_string();
    assert!(got.starts_with(&format!("{}:", path.display())), "{got}");
}

#[test]
fn missing_file_and_missing_frame() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("nothing.lammpstrj");
    let got = DumpFile::open(&path).unwrap_err().to_string();
    assert!(got.starts_with(&format!("{}: ", path.display())), "{got}");
    let (path, got) = error_k(
        "one.lammpstrj",
        &dump("1 1 0 0 0\n2 1 0 0 0\n3 1 0 0 0\n"),
        1,
        None,
    );
    assert_eq!(
        got,
        format!(
            "{}: frame 1 does not exist; the file has 1 frame, counted from 0 (the last is \
             0)",
            path.display()
        )
    );
}

#[test]
fn xyz_errors() {
    assert_error(
        "t.xyz",
        "3\ncomment\nC 0 0 0\nC 1 1 1\n",
        None,
        "4: truncated frame: the header announces 3 atoms but only 2 atom lines follow",
    );
    assert_error(
        "c.xyz",
        "2\ncomment\nC 0 0 0\nC 1 1\n",
        None,
        "4: expected 4 columns, found 3",
    );
    assert_error(
        "c3.xyz",
        "1\n\nC 0 0\n",
        None,
        "3: expected 4 columns, found 3",
    );
    assert_error(
        "n.xyz",
        "1\n\nC 0 x 0\n",
        None,
        "3: column `y`: `x` is not a number",
    );
    assert_error(
        "nan.xyz",
        "1\n\nC 0 NaN 0\n",
        None,
        "3: column `y`: `NaN` is not a finite number",
    );
    assert_error(
        "count.xyz",
        "1\n\nC 0 0 0\nabc\n\nC 0 0 0\n",
        None,
        "4: expected the atom count of frame 1 (an integer), found `abc`",
    );
    assert_error(
        "short.xyz",
        "1\nstep=0\nC 0 0 0\n3\nstep=1\nC 0 0 0\nC 1 1 1\n1\nstep=2\nC 0 0 0\n",
        None,
        "9: expected the atom count of frame 2 (an integer), found `step=2`; this reads as a \
         frame's comment line: frame 1 (its count at line 4) may hold fewer than the 3 atom \
         lines it announces",
    );
    assert_error(
        "lat.xyz",
        "1\nLattice=\"1 2 3\"\nC 0 0 0\n",
        None,
        "2: `Lattice` must be 9 numbers, found `1 2 3`",
    );
    // A key given twice: neither is taken (a plain comment's repeated words are fine).
    assert_error(
        "lat2.xyz",
        "1\nLattice=\"1 0 0 0 1 0 0 0 1\" lattice = \"2 0 0 0 2 0 0 0 2\"\nC 0 0 0\n",
        None,
        "2: `Lattice` is given 2 times in the comment line: which one holds the frame's value \
         cannot be told",
    );
    assert_error(
        "step2.xyz",
        "1\nTimestep=5 step=6\nC 0 0 0\n",
        None,
        "2: `Timestep`/`step` is given 2 times in the comment line: which one holds the \
         frame's value cannot be told",
    );
    let dir = tempfile::tempdir().unwrap();
    let plain = write(dir.path(), "plain.xyz", b"1\ntime 5 time again\nC 0 0 0\n");
    assert!(DumpFile::open(&plain)
        .unwrap()
        .read_frame(0, &ReadOptions::default(), &NoProgress)
        .is_ok());
    // A key written inside a quoted value is that value's text, not a second key; a time
    // with its unit after it is its number.
    for (name, comment, timestep, time) in [
        (
            "q1.xyz",
            r#"step=10 info="restarted from step=5""#,
            Some(10),
            None,
        ),
        (
            "q2.xyz",
            r#"Time=1.5 comment="restart Time=99, \"step=3\"""#,
            None,
            Some(1.5),
        ),
        ("q3.xyz", "Timestep=7 Time=0.25fs", Some(7), Some(0.25)),
        (
            "q4.xyz",
            "Properties=species:S:1:pos:R:3 Time=\"1.5 ps\"",
            None,
            Some(1.5),
        ),
    ] {
        let path = write(
            dir.path(),
            name,
            format!("1\n{comment}\nC 0 0 0\n").as_bytes(),
        );
        let dump = DumpFile::open(&path).unwrap();
        let frame = dump
            .read_frame(0, &ReadOptions::default(), &NoProgress)
            .unwrap_or_else(|e| panic!("{comment}: {e}"));
        assert_eq!((frame.timestep, frame.time), (timestep, time), "{comment}");
    }
    assert_error(
        "prop.xyz",
        "1\nProperties=species:S:1:pos:R\nC 0 0 0\n",
        None,
        "2: malformed `Properties` `species:S:1:pos:R`: expected name:type:count triples",
    );
    // Counts multiply out to columns: a few bytes must not ask for millions of them.
    assert_error(
        "wide.xyz",
        "1\nProperties=species:S:1:pos:R:3:f:R:29999999\nC 0 0 0\n",
        None,
        "2: `Properties` describes more than 4096 columns (`f` alone has 29999999)",
    );
    assert_error(
        "nopos.xyz",
        "1\nProperties=species:S:1:velo:R:3\nC 0 0 0\n",
        None,
        "2: `Properties` names no positions: they are read from a `pos:R:3` (or `position:R:3`, `positions:R:3`) entry; the entries name the columns species velo[0] velo[1] velo[2]",
    );
    assert_error(
        "attr.xyz",
        "1\nProperties=species:S:1:pos:R:3\nC 0 0 0\n",
        Some("charge"),
        "2: no column `charge` for the attribute; available columns: species pos[0] pos[1] pos[2]",
    );
}

/// A header announcing more atoms than its frame's bytes can hold (a count that lies, or
/// a frame cut short) is a truncated frame already in the frame's description, which a
/// conversion reads before it plans memory for that many particles (it asked for
/// 25 GiB chunks and named no file).
#[test]
fn a_count_the_frame_cannot_hold_is_a_truncated_frame_before_reading() {
    let dir = tempfile::tempdir().unwrap();
    let atoms: String = (0..300)
        .map(|i| format!("{} 1 {}.5 0.5 0.5\n", i + 1, i % 10))
        .collect();
    let text = format!(
        "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n1000000000000\nITEM: BOX BOUNDS pp pp pp\n\
         0 10\n0 10\n0 10\nITEM: ATOMS id type x y z\n{atoms}"
    );
    let lammps = write(dir.path(), "lie.lammpstrj", text.as_bytes());
    let xyz_atoms: String = (0..300)
        .map(|i| format!("Cu {}.5 0.5 0.5\n", i % 10))
        .collect();
    let xyz = write(
        dir.path(),
        "lie.xyz",
        format!("1000000000000\ncomment\n{xyz_atoms}").as_bytes(),
    );
    for path in [lammps, xyz] {
        let dump = DumpFile::open(&path).unwrap();
        let e = dump.frame_info(0).unwrap_err();
        assert!(matches!(e, ReadError::Truncated { .. }), "{e}");
        let e = e.to_string();
        assert!(
            e.starts_with(&format!("{}:", path.display()))
                && e.contains("announces 1000000000000 atoms but only 300 atom lines follow"),
            "{e}"
        );
    }
}

/// Files of formats mdlod does not read are named as what they are, with how to write
/// them as one it reads; binary bytes of an unknown first line are shown as `\xNN`.
#[test]
fn foreign_formats_are_named_with_the_way_out() {
    let dir = tempfile::tempdir().unwrap();
    let open = |name: &str, bytes: &[u8]| {
        let path = dir.path().join(name);
        std::fs::write(&path, bytes).unwrap();
        mdlod_preprocess::readers::DumpFile::open(&path)
            .err()
            .unwrap()
            .to_string()
    };
    let e = open(
        "md.traj",
        b"- of UlmASE-Trajectory  \x00\x01\x8f\xfe rest\n",
    );
    assert!(
        e.contains("an ASE trajectory (.traj), which mdlod does not read")
            && e.contains("`ase convert md.traj out.xyz`"),
        "{e}"
    );
    let e = open("cu.cif", b"data_Cu\n_cell_length_a 3.61\n");
    assert!(
        e.contains("a CIF crystal file, which mdlod does not read"),
        "{e}"
    );
    let e = open("POSCAR", b"Cu fcc\n1.0\n3.6 0 0\n");
    assert!(e.contains("a VASP structure file"), "{e}");
    // Its own output given back to convert: said so, with what reads it.
    let mut mdlod = b"\x89MDLOD\r\n".to_vec();
    mdlod.extend([0u8; 56]);
    let e = open("frame.mdlod", &mdlod);
    assert!(
        e.contains("an .mdlod file already, mdlod's own output: `mdlod render")
            && e.contains("frame.mdlod` draws it"),
        "{e}"
    );
    let e = open("blob.dat", b"\x00\x01\x02abc\xff\xfe\n");
    assert!(e.contains(r"first line `\x00\x01\x02abc\xFF\xFE`"), "{e}");
}

/// A damaged byte inside a number is shown as `\xNN`, not as a character that makes
/// the number read right, and a long value is shortened rather than echoed whole.
#[test]
fn damaged_bytes_and_long_values_are_shown_plainly() {
    let dir = tempfile::tempdir().unwrap();
    let mut bytes = HEAD.replace("0.0 10.0\nITEM: ATOMS", "0\u{1}0 10.0\nITEM: ATOMS");
    bytes.push_str("1 1 0 0 0\n2 1 1 1 1\n3 1 2 2 2\n");
    let mut bytes = bytes.into_bytes();
    let at = bytes.iter().position(|&b| b == 1).unwrap();
    bytes[at] = 0xFB;
    let path = write(dir.path(), "d.lammpstrj", &bytes);
    let e = DumpFile::open(&path)
        .and_then(|d| d.read_frame(0, &ReadOptions::default(), &NoProgress))
        .err()
        .unwrap()
        .to_string();
    assert!(
        e.contains(r"malformed BOX BOUNDS: `0\xFB0` is not a finite number"),
        "{e}"
    );
    let lattice = vec!["1"; 50_000].join(" ");
    let text = format!("1\nLattice=\"{lattice}\" Properties=species:S:1:pos:R:3\nCu 0 0 0\n");
    let (_, e) = error_k("l.xyz", &text, 0, None);
    assert!(
        e.contains("`Lattice` must be 9 numbers, found `1 1 1") && e.len() < 300,
        "{} bytes: {}",
        e.len(),
        &e[..e.len().min(300)]
    );
}
