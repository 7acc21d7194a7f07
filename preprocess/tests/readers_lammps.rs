//! LAMMPS text dump reading: coordinate styles, boxes, species, multi-frame access,
//! line endings and compression.

use std::io::Write;
use std::path::{Path, PathBuf};

use mdlod_preprocess::readers::{DumpFile, InputFormat, ReadOptions};
use mdlod_preprocess::{Frame, NoProgress};

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path
}

fn read(path: &Path, attribute: Option<&str>) -> Frame {
    let dump = DumpFile::open(path).unwrap();
    let opts = ReadOptions {
        attribute: attribute.map(String::from),
        ..Default::default()
    };
    dump.read_frame(0, &opts, &NoProgress).unwrap()
}

fn close(a: [f32; 3], b: [f64; 3]) -> bool {
    a.iter()
        .zip(b)
        .all(|(&x, y)| (f64::from(x) - y).abs() < 1e-5 * (1.0 + y.abs()))
}

fn names(frame: &Frame) -> Vec<&str> {
    frame.species.iter().map(|s| s.name.as_str()).collect()
}

const ORTHO: &str = "\
ITEM: TIMESTEP
100
ITEM: NUMBER OF ATOMS
3
ITEM: BOX BOUNDS pp pp ff
0.0 10.0
-5.0 5.0
0.0 20.0
";

#[test]
fn orthogonal_cartesian() {
    let dir = tempfile::tempdir().unwrap();
    let text = format!(
        "{ORTHO}ITEM: ATOMS id type x y z\n1 1 1.5 -2.5 3.0\n2 2 4.0 0.0 19.5\n3 1 9.9 4.9 0.1\n"
    );
    let path = write(dir.path(), "a.lammpstrj", &text);
    let f = read(&path, None);
    assert_eq!(f.len(), 3);
    assert_eq!(f.positions[0], [1.5, -2.5, 3.0]);
    assert_eq!(f.positions[1], [4.0, 0.0, 19.5]);
    assert_eq!(f.positions[2], [9.9, 4.9, 0.1]);
    assert_eq!(f.species_index, vec![0, 1, 0]);
    assert_eq!(names(&f), vec!["1", "2"]);
    assert!(f.species.iter().all(|s| s.numeric_type));
    assert_eq!(f.timestep, Some(100));
    let b = f.simulation_box.unwrap();
    assert_eq!(b.origin, [0.0, -5.0, 0.0]);
    assert_eq!(b.a, [10.0, 0.0, 0.0]);
    assert_eq!(b.b, [0.0, 10.0, 0.0]);
    assert_eq!(b.c, [0.0, 0.0, 20.0]);
    assert_eq!(b.periodic, Some([true, true, false]));
    assert!(f.attribute.is_none());
}

#[test]
fn every_coordinate_style_and_preference() {
    let dir = tempfile::tempdir().unwrap();
    // Box: origin (0,-5,0), lengths (10,10,20).
    let cases = [
        ("x y z", "1.0 2.0 3.0", [1.0, 2.0, 3.0]),
        ("xu yu zu", "11.0 -7.0 23.0", [11.0, -7.0, 23.0]),
        ("xs ys zs", "0.5 0.25 0.75", [5.0, -2.5, 15.0]),
        ("xsu ysu zsu", "1.5 -0.5 0.5", [15.0, -10.0, 10.0]),
        // several styles: x beats xu beats xs beats xsu
        (
            "xsu ysu zsu xs ys zs xu yu zu x y z",
            "0 0 0 0 0 0 1 1 1 2 3 4",
            [2.0, 3.0, 4.0],
        ),
        ("xs ys zs xu yu zu", "0.5 0.5 0.5 7 8 9", [7.0, 8.0, 9.0]),
        (
            "xsu ysu zsu xs ys zs",
            "0 0 0 0.5 0.5 0.5",
            [5.0, 0.0, 10.0],
        ),
    ];
    for (i, (cols, line, want)) in cases.iter().enumerate() {
        let text =
            format!("{ORTHO}ITEM: ATOMS id type {cols}\n1 1 {line}\n2 1 {line}\n3 1 {line}\n");
        let path = write(dir.path(), &format!("c{i}.dump"), &text);
        let f = read(&path, None);
        for p in &f.positions {
            assert!(close(*p, *want), "{cols}: got {p:?}, want {want:?}");
        }
    }
}

/// A restricted triclinic box: the `_bound` values are converted to true bounds, and
/// scaled coordinates go through the tilted cell vectors.
#[test]
fn triclinic_bounds_and_scaled_coordinates() {
    let dir = tempfile::tempdir().unwrap();
    let (xlo, xhi, ylo, yhi, zlo, zhi) = (0.0, 10.0, 1.0, 9.0, -2.0, 4.0);
    let (xy, xz, yz) = (2.0, -3.0, 1.5);
    let xlo_b = xlo + f64::min(0.0, xy).min(xz).min(xy + xz);
    let xhi_b = xhi + f64::max(0.0, xy).max(xz).max(xy + xz);
    let ylo_b = ylo + f64::min(0.0, yz);
    let yhi_b = yhi + f64::max(0.0, yz);
    let text = format!(
        "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n2\nITEM: BOX BOUNDS xy xz yz pp pp pp\n\
         {xlo_b} {xhi_b} {xy}\n{ylo_b} {yhi_b} {xz}\n{zlo} {zhi} {yz}\n\
         ITEM: ATOMS id type xs ys zs\n1 1 0.5 0.5 0.5\n2 1 0 0 1\n"
    );
    let path = write(dir.path(), "tri.lammpstrj", &text);
    let f = read(&path, None);
    let b = f.simulation_box.clone().unwrap();
    assert_eq!(b.origin, [xlo, ylo, zlo]);
    assert_eq!(b.a, [xhi - xlo, 0.0, 0.0]);
    assert_eq!(b.b, [xy, yhi - ylo, 0.0]);
    assert_eq!(b.c, [xz, yz, zhi - zlo]);
    assert_eq!(b.periodic, Some([true; 3]));
    let (lx, ly, lz) = (xhi - xlo, yhi - ylo, zhi - zlo);
    let want0 = [
        xlo + 0.5 * lx + 0.5 * xy + 0.5 * xz,
        ylo + 0.5 * ly + 0.5 * yz,
        zlo + 0.5 * lz,
    ];
    assert!(
        close(f.positions[0], want0),
        "{:?} {want0:?}",
        f.positions[0]
    );
    assert!(close(f.positions[1], [xlo + xz, ylo + yz, zhi]));

    // Same box, unwrapped scaled coordinates.
    let text = text.replace("xs ys zs", "xsu ysu zsu");
    let path = write(dir.path(), "tri_su.lammpstrj", &text);
    let f = read(&path, None);
    assert!(close(f.positions[0], want0));
}

#[test]
fn general_triclinic_box() {
    let dir = tempfile::tempdir().unwrap();
    let text =
        "ITEM: TIMESTEP\n5\nITEM: NUMBER OF ATOMS\n1\nITEM: BOX BOUNDS abc origin pp pp fm\n\
                10 0 0 -1\n1 8 0 -2\n0.5 0.5 6 -3\nITEM: ATOMS id type xs ys zs\n1 1 0.5 0.5 0.5\n";
    let path = write(dir.path(), "gen.lammpstrj", text);
    let f = read(&path, None);
    let b = f.simulation_box.clone().unwrap();
    assert_eq!(b.origin, [-1.0, -2.0, -3.0]);
    assert_eq!(b.a, [10.0, 0.0, 0.0]);
    assert_eq!(b.b, [1.0, 8.0, 0.0]);
    assert_eq!(b.c, [0.5, 0.5, 6.0]);
    assert_eq!(b.periodic, Some([true, true, false]));
    assert!(close(f.positions[0], [4.75, 2.25, 0.0]));
}

#[test]
fn element_wins_over_type_and_unsorted_order_is_kept() {
    let dir = tempfile::tempdir().unwrap();
    let text = format!(
        "{ORTHO}ITEM: ATOMS x y z element type id\n\
         3 3 3 Ni 2 3\n1 1 1 Cu 1 1\n2 2 2 Ni 2 2\n"
    );
    let path = write(dir.path(), "el.lammpstrj", &text);
    let f = read(&path, None);
    assert_eq!(names(&f), vec!["Ni", "Cu"]);
    assert!(f.species.iter().all(|s| !s.numeric_type));
    assert_eq!(f.species_index, vec![0, 1, 0]);
    assert_eq!(f.positions, vec![[3.0; 3], [1.0; 3], [2.0; 3]]);
}

#[test]
fn numeric_types_are_sorted_numerically() {
    let dir = tempfile::tempdir().unwrap();
    let text = format!("{ORTHO}ITEM: ATOMS id type x y z\n1 10 0 0 0\n2 2 0 0 0\n3 1 0 0 0\n");
    let path = write(dir.path(), "types.lammpstrj", &text);
    let f = read(&path, None);
    assert_eq!(names(&f), vec!["1", "2", "10"]);
    assert_eq!(f.species_index, vec![2, 1, 0]);
}

/// A type keeps its palette colour in a frame that lacks the types before it (a
/// deposition run's first frames, an evaporated species): type 2 alone is drawn as type
/// 2 beside type 1, not as a frame's first species.
#[test]
fn a_type_number_keeps_its_colour_whatever_other_types_a_frame_has() {
    let dir = tempfile::tempdir().unwrap();
    let both = format!("{ORTHO}ITEM: ATOMS id type x y z\n1 2 0 0 0\n2 1 0 0 0\n3 2 0 0 0\n");
    let alone = format!("{ORTHO}ITEM: ATOMS id type x y z\n1 2 0 0 0\n2 2 0 0 0\n3 2 0 0 0\n");
    let colour_of_2 = |text: &str, name: &str| {
        let f = read(&write(dir.path(), name, text), None);
        let table = mdlod_preprocess::species::species_table(&f.species, &[]);
        table.iter().find(|s| s.name == "2").unwrap().colour
    };
    let a = colour_of_2(&both, "both.lammpstrj");
    let b = colour_of_2(&alone, "alone.lammpstrj");
    assert_eq!(a, b);
    // And type 1 (the first slot) differs from it.
    let f = read(&dir.path().join("both.lammpstrj"), None);
    let table = mdlod_preprocess::species::species_table(&f.species, &[]);
    assert_ne!(table[0].colour, table[1].colour);
}

#[test]
fn type_labels_keep_first_appearance() {
    let dir = tempfile::tempdir().unwrap();
    let text = format!("{ORTHO}ITEM: ATOMS id type x y z\n1 O 0 0 0\n2 H 0 0 0\n3 H 0 0 0\n");
    let path = write(dir.path(), "labels.lammpstrj", &text);
    let f = read(&path, None);
    assert_eq!(names(&f), vec!["O", "H"]);
    assert!(f.species.iter().all(|s| !s.numeric_type));
}

#[test]
fn no_species_column_gives_one_species() {
    let dir = tempfile::tempdir().unwrap();
    let text = format!("{ORTHO}ITEM: ATOMS x y z\n1 2 3\n4 5 6\n7 8 9\n");
    let path = write(dir.path(), "nospecies.lammpstrj", &text);
    let f = read(&path, None);
    assert_eq!(f.species.len(), 1);
    assert_eq!(f.species_index, vec![0, 0, 0]);
}

#[test]
fn attribute_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let text = format!(
        "{ORTHO}ITEM: ATOMS id type x y z c_pe vx\n1 1 0 0 0 -3.5 1\n2 1 0 0 0 -4.25 2\n3 2 1 1 1 1e-3 3\n"
    );
    let path = write(dir.path(), "attr.lammpstrj", &text);
    let f = read(&path, Some("c_pe"));
    let a = f.attribute.unwrap();
    assert_eq!(a.name, "c_pe");
    assert_eq!(a.values, vec![-3.5, -4.25, 1e-3]);
    // A coordinate or the type column can be the attribute too.
    let f = read(&path, Some("x"));
    assert_eq!(f.attribute.unwrap().values, vec![0.0, 0.0, 1.0]);
    let f = read(&path, Some("type"));
    assert_eq!(f.attribute.as_ref().unwrap().values, vec![1.0, 1.0, 2.0]);
    assert_eq!(names(&f), vec!["1", "2"]);
}

#[test]
fn windows_line_endings() {
    let dir = tempfile::tempdir().unwrap();
    let text = format!(
        "ITEM: UNITS\nmetal\nITEM: TIME\n0.25\n{ORTHO}ITEM: ATOMS id type x y z c_q\n1 1 1.5 2.5 3.5 0.5\n2 2 4 5 6 -1\n3 1 7 8 9 2\n"
    )
    .replace('\n', "\r\n");
    let path = write(dir.path(), "crlf.lammpstrj", &text);
    let f = read(&path, Some("c_q"));
    assert_eq!(
        f.positions,
        vec![[1.5, 2.5, 3.5], [4.0, 5.0, 6.0], [7.0, 8.0, 9.0]]
    );
    assert_eq!(names(&f), vec!["1", "2"]);
    assert_eq!(f.attribute.unwrap().values, vec![0.5, -1.0, 2.0]);
    assert_eq!(f.units.as_deref(), Some("metal"));
    assert_eq!(f.time, Some(0.25));
    assert_eq!(f.timestep, Some(100));
}

fn frame_text(step: u64, time: Option<f64>, n: usize, offset: f64) -> String {
    let mut s = String::new();
    if let Some(t) = time {
        s += &format!("ITEM: TIME\n{t}\n");
    }
    s += &format!(
        "ITEM: TIMESTEP\n{step}\nITEM: NUMBER OF ATOMS\n{n}\nITEM: BOX BOUNDS pp pp pp\n0 100\n0 100\n0 100\nITEM: ATOMS id type x y z\n"
    );
    for i in 0..n {
        s += &format!(
            "{} {} {} {} {}\n",
            i + 1,
            i % 3 + 1,
            offset + i as f64,
            1.0,
            2.0
        );
    }
    s
}

fn three_frames() -> String {
    let mut text = String::from("ITEM: UNITS\nreal\n");
    text += &frame_text(0, Some(0.0), 4, 0.0);
    text += &frame_text(1000, Some(2.5), 5, 10.0);
    text += &frame_text(2000, Some(5.0), 2, 20.0);
    text
}

fn check_three_frames(dump: &DumpFile) {
    assert_eq!(dump.frame_count(), 3);
    assert_eq!(dump.frame_timestep(0), Some(0));
    assert_eq!(dump.frame_timestep(1), Some(1000));
    assert_eq!(dump.frame_timestep(2), Some(2000));
    assert_eq!(dump.frame_timestep(3), None);
    // Frame 2 first: random access without reading frames 0 and 1.
    let f2 = dump
        .read_frame(2, &ReadOptions::default(), &NoProgress)
        .unwrap();
    assert_eq!(f2.len(), 2);
    assert_eq!(f2.positions, vec![[20.0, 1.0, 2.0], [21.0, 1.0, 2.0]]);
    assert_eq!(f2.timestep, Some(2000));
    assert_eq!(f2.time, Some(5.0));
    assert_eq!(
        f2.units.as_deref(),
        Some("real"),
        "UNITS of frame 0 apply to all"
    );
    let f1 = dump
        .read_frame(1, &ReadOptions::default(), &NoProgress)
        .unwrap();
    assert_eq!(f1.len(), 5);
    assert_eq!(f1.positions[4], [14.0, 1.0, 2.0]);
    assert_eq!(f1.time, Some(2.5));
    let f0 = dump
        .read_frame(0, &ReadOptions::default(), &NoProgress)
        .unwrap();
    assert_eq!(f0.len(), 4);
    assert_eq!(f0.time, Some(0.0));
    let info = dump.frame_info(1).unwrap();
    assert_eq!(info.particles, 5);
    assert_eq!(info.columns, vec!["id", "type", "x", "y", "z"]);
}

#[test]
fn multi_frame_random_access() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(dir.path(), "multi.lammpstrj", &three_frames());
    let dump = DumpFile::open(&path).unwrap();
    assert_eq!(dump.format(), InputFormat::LammpsText);
    check_three_frames(&dump);
}

#[test]
fn gzip_transparent() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("multi.lammpstrj.gz");
    // Two gzip members, as `cat a.gz b.gz` would make.
    let text = three_frames();
    let (first, second) = text.split_at(text.len() / 2);
    let mut bytes = Vec::new();
    for part in [first, second] {
        let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
        enc.write_all(part.as_bytes()).unwrap();
        bytes.extend(enc.finish().unwrap());
    }
    std::fs::write(&path, bytes).unwrap();
    let dump = DumpFile::open(&path).unwrap();
    check_three_frames(&dump);
}

#[test]
fn large_frame_parsed_in_parallel_chunks() {
    // Big enough for many parser chunks; checks order and species across chunk seams.
    let n = 60_000;
    let dir = tempfile::tempdir().unwrap();
    let mut text = String::from(
        "ITEM: TIMESTEP\n7\nITEM: NUMBER OF ATOMS\n60000\nITEM: BOX BOUNDS pp pp pp\n0 1\n0 1\n0 1\nITEM: ATOMS id type x y z c_v\n",
    );
    for i in 0..n {
        let t = if i < 40_000 { 5 } else { 1 + i % 4 };
        text += &format!(
            "{} {t} {}.25 {} -{}.5 {}\n",
            n - i,
            i,
            i % 97,
            i % 13,
            i * 2
        );
    }
    let path = write(dir.path(), "big.lammpstrj", &text);
    let f = read(&path, Some("c_v"));
    assert_eq!(f.len(), n);
    assert_eq!(names(&f), vec!["1", "2", "3", "4", "5"]);
    for i in 0..n {
        let t = if i < 40_000 { 5 } else { 1 + i % 4 };
        assert_eq!(
            f.positions[i],
            [i as f32 + 0.25, (i % 97) as f32, -((i % 13) as f32) - 0.5]
        );
        assert_eq!(f.species[f.species_index[i] as usize].name, t.to_string());
        assert_eq!(f.attribute.as_ref().unwrap().values[i], (i * 2) as f32);
    }
}

#[test]
fn format_detection() {
    use InputFormat::*;
    for (name, want) in [
        ("a.lammpstrj", Some(LammpsText)),
        ("a.dump", Some(LammpsText)),
        ("a.lammps", Some(LammpsText)),
        ("dump.melt", Some(LammpsText)),
        ("dump.melt.gz", Some(LammpsText)),
        ("A.LAMMPSTRJ.GZ", Some(LammpsText)),
        ("a.xyz", Some(Xyz)),
        ("dump.xyz", Some(Xyz)),
        ("a.extxyz.gz", Some(Xyz)),
        ("a.txt", None),
    ] {
        assert_eq!(InputFormat::from_path(Path::new(name)), want, "{name}");
    }
    assert_eq!(
        InputFormat::sniff(b"\nITEM: TIMESTEP\n0\n"),
        Some(LammpsText)
    );
    assert_eq!(InputFormat::sniff(b"  12 \ncomment\n"), Some(Xyz));
    assert_eq!(InputFormat::sniff(b"hello\n"), None);

    // Unknown extension: sniffed.
    let dir = tempfile::tempdir().unwrap();
    let text = format!("{ORTHO}ITEM: ATOMS id type x y z\n1 1 0 0 0\n2 1 0 0 0\n3 1 0 0 0\n");
    let path = write(dir.path(), "noext", &text);
    assert_eq!(DumpFile::open(&path).unwrap().format(), LammpsText);
}

#[test]
fn unknown_items_are_skipped() {
    let dir = tempfile::tempdir().unwrap();
    let text = "ITEM: TIMESTEP\n1\nITEM: SOMETHING NEW\na b\nc d\nITEM: NUMBER OF ATOMS\n1\nITEM: BOX BOUNDS\n0 1\n0 1\n0 1\nITEM: ATOMS x y z\n0.5 0.5 0.5\n";
    let path = write(dir.path(), "new.lammpstrj", text);
    let f = read(&path, None);
    assert_eq!(f.positions, vec![[0.5; 3]]);
    assert_eq!(f.simulation_box.unwrap().periodic, None);
}

#[test]
fn empty_frame_is_fine() {
    let dir = tempfile::tempdir().unwrap();
    let text = "ITEM: TIMESTEP\n1\nITEM: NUMBER OF ATOMS\n0\nITEM: BOX BOUNDS pp pp pp\n0 1\n0 1\n0 1\nITEM: ATOMS id type x y z\n";
    let path = write(dir.path(), "zero.lammpstrj", text);
    let f = read(&path, None);
    assert!(f.is_empty());
    assert!(f.species.is_empty());
}

/// A `BOX BOUNDS` line whose lower bound is above its upper bound (`10 0`) is no box
/// (it read as one of negative size): an error naming the line, for `lo hi` and
/// `lo_bound hi_bound tilt` lines alike.
#[test]
fn box_bounds_with_lo_above_hi_are_errors_naming_the_line() {
    let dir = tempfile::tempdir().unwrap();
    let atoms = "ITEM: ATOMS id type x y z\n1 1 0 0 0\n";
    for (bounds, line, text) in [
        ("pp pp pp\n0 10\n10 0\n0 10\n", 7, "10 0"),
        ("xy xz yz pp pp pp\n0 10 0\n0 10 0\n4 -4 0\n", 8, "4 -4 0"),
    ] {
        let dump = format!(
            "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n1\nITEM: BOX BOUNDS {bounds}{atoms}"
        );
        let path = write(dir.path(), "flip.lammpstrj", &dump);
        let e = DumpFile::open(&path)
            .and_then(|d| d.read_frame(0, &ReadOptions::default(), &NoProgress))
            .unwrap_err()
            .to_string();
        let (lo, hi) = {
            let v: Vec<&str> = text.split(' ').collect();
            (v[0], v[1])
        };
        assert_eq!(
            e,
            format!(
                "{}:{line}: malformed BOX BOUNDS: `{text}` has its lower bound {lo} above its \
                 upper bound {hi}",
                path.display()
            )
        );
    }
    // A box of zero width on an axis (a 2D run's) still reads.
    let dump = format!(
        "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n1\nITEM: BOX BOUNDS pp pp pp\n0 10\n0 10\n0 0\n{atoms}"
    );
    let path = write(dir.path(), "flat.lammpstrj", &dump);
    assert_eq!(read(&path, None).len(), 1);
}

/// A column of categories (`--species-column`) written in any notation: a whole number
/// is that number however printed (`1.000000`, `1e0`, `-0`), whole numbers sort as
/// numbers, whole numbers from 0 take colours by value (the same in every frame,
/// with a 0 or without), a value that is no number at all (`nan`) is refused, and a
/// `diameter` column read as the species is no size column by default.
#[test]
fn categories_are_numbers_however_written() {
    let dir = tempfile::tempdir().unwrap();
    let head = "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n7\nITEM: BOX BOUNDS pp pp pp\n0 10\n0 10\n0 10\n";
    let opts = |column: &str| ReadOptions {
        species_column: Some(column.into()),
        ..Default::default()
    };
    let read_with = |text: &str, o: &ReadOptions| {
        let path = write(dir.path(), "c.dump", text);
        DumpFile::open(&path).unwrap().read_frame(0, o, &NoProgress)
    };
    let values = ["5.000000", "1.000000", "1", "1e0", "0", "-0", "2"];
    let mut text = format!("{head}ITEM: ATOMS id type x y z c_ptm\n");
    for (i, v) in values.iter().enumerate() {
        text += &format!("{} 1 {i} 1 1 {v}\n", i + 1);
    }
    let f = read_with(&text, &opts("c_ptm")).unwrap();
    assert_eq!(names(&f), ["0", "1", "2", "5"]);
    assert_eq!(f.species_index, [3, 1, 1, 1, 0, 0, 2]);
    let colours: Vec<Option<[u8; 3]>> = f.species.iter().map(|s| s.colour).collect();
    // ptm/atom: 0 other, 1 fcc, 2 hcp; 5 is simple cubic, the palette's.
    assert_eq!(
        colours,
        [
            Some([242, 242, 242]),
            Some([102, 255, 102]),
            Some([255, 102, 102]),
            Some(mdlod_preprocess::species::palette_colour(5))
        ]
    );
    // A value that is no whole number: every name as it first appears (as frames read
    // in parts merge them), that one coloured by its place past the palette's first ten.
    let h = read_with(&text.replace(" 2\n", " 2.5\n"), &opts("c_ptm")).unwrap();
    assert_eq!(names(&h), ["5", "1", "0", "2.5"]);
    assert_eq!(
        h.species[3].colour,
        Some(mdlod_preprocess::species::palette_colour(13))
    );
    // Without a 0 (and without 2.5), 1 keeps its colour.
    let text1 = text
        .replace(" 0\n", " 1\n")
        .replace(" -0\n", " 1\n")
        .replace(" 2\n", " 1\n");
    let g = read_with(&text1, &opts("c_ptm")).unwrap();
    assert_eq!(names(&g), ["1", "5"]);
    assert_eq!(g.species[0].colour, Some([102, 255, 102]));
    let e = read_with(&text.replace(" 2\n", " nan\n"), &opts("c_ptm"))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("c.dump:16:") && e.contains("--species-column c_ptm: a value `nan`"),
        "{e}"
    );
    // A bidisperse run's diameters as the species: no sizes read from them by default.
    let mut text = format!("{head}ITEM: ATOMS id type x y z diameter\n");
    for i in 0..7 {
        text += &format!("{} 1 {i} 1 1 {}\n", i + 1, 1 + i % 2);
    }
    let f = read_with(&text, &opts("diameter")).unwrap();
    assert_eq!(names(&f), ["1", "2"]);
    assert!(f.radii.is_none());
}

/// A frame without `ITEM: BOX BOUNDS` (its item misspelt, so skipped as unknown) is
/// noted: LAMMPS writes a box in every frame, and the file would have none.
#[test]
fn a_frame_without_a_box_is_noted() {
    let dir = tempfile::tempdir().unwrap();
    let atoms = "ITEM: ATOMS id type x y z\n1 1 0 0 0\n2 1 1 1 1\n";
    let boxed = format!("{ORTHO}{atoms}");
    let misspelt = boxed.replace("ITEM: BOX BOUNDS", "ITEM: BOX BOUND");
    for (text, noted) in [(boxed, false), (misspelt, true)] {
        let text = text.replace("NUMBER OF ATOMS\n3", "NUMBER OF ATOMS\n2");
        let path = write(dir.path(), "b.dump", &text);
        let dump = DumpFile::open(&path).unwrap();
        let notes = dump.frame_notes(0, &ReadOptions::default());
        assert_eq!(
            notes
                .iter()
                .any(|n| n.contains("frame 0 has no `ITEM: BOX BOUNDS`")),
            noted,
            "{notes:?}"
        );
        assert_eq!(
            dump.read_frame(0, &ReadOptions::default(), &NoProgress)
                .unwrap()
                .simulation_box
                .is_none(),
            noted
        );
    }
}

/// Molecule ids as species take the palette by value, not the structure types' colours
/// (molecule 0 and 5 drew light grey, hidden on a white background).
#[test]
fn categories_of_other_columns_take_the_palette_by_value() {
    let dir = tempfile::tempdir().unwrap();
    let head = "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n3\nITEM: BOX BOUNDS pp pp pp\n\
                0 10\n0 10\n0 10\n";
    let text =
        format!("{head}ITEM: ATOMS id type mol x y z\n1 1 0 1 1 1\n2 1 5 2 2 2\n3 1 1 3 3 3\n");
    let path = write(dir.path(), "mol.dump", &text);
    let f = DumpFile::open(&path)
        .unwrap()
        .read_frame(
            0,
            &ReadOptions {
                species_column: Some("mol".into()),
                ..Default::default()
            },
            &NoProgress,
        )
        .unwrap();
    let colours: Vec<Option<[u8; 3]>> = f.species.iter().map(|s| s.colour).collect();
    let by_value = |v: usize| Some(mdlod_preprocess::species::palette_colour(v));
    assert_eq!(colours, [by_value(0), by_value(1), by_value(5)]);
    use mdlod_preprocess::species::{structure_kind, Structure};
    assert_eq!(structure_kind("mol"), None);
    assert_eq!(structure_kind("c_cna"), Some(Structure::Cna));
    // Each compute's own numbers: ackland/atom's 1 is bcc, cna/atom's fcc.
    use mdlod_preprocess::species::category_colour;
    let (fcc, bcc) = (Some([102, 255, 102]), Some([102, 102, 255]));
    assert_eq!(category_colour("c_ackland", 1), bcc);
    assert_eq!(category_colour("c_ackland", 2), fcc);
    assert_eq!(category_colour("c_cna", 1), fcc);
    assert_eq!(category_colour("c_cna", 3), bcc);
    assert_eq!(category_colour("c_cna", 5), Some([242, 242, 242]));
}

/// An `ITEM: ATOMS` line naming no columns (very old LAMMPS) is read as `dump atom`'s
/// scaled `id type xs ys zs`; atom lines of another column count, or whose coordinates
/// lie far outside the box (unscaled ones, which the box would multiply silently), are
/// refused, saying how to name the columns.
#[test]
fn an_atoms_line_naming_no_columns_is_scaled_dump_atom_or_refused() {
    let dir = tempfile::tempdir().unwrap();
    let head = "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n10\nITEM: BOX BOUNDS pp pp pp\n\
                0 10\n0 10\n0 10\nITEM: ATOMS\n";
    let lines = |f: &dyn Fn(usize) -> String| (0..10).map(f).collect::<String>();
    // Scaled: read through the box.
    let scaled = write(
        dir.path(),
        "scaled.dump",
        &format!(
            "{head}{}",
            lines(&|i| format!("{} 1 0.{i} 0.5 0.25\n", i + 1))
        ),
    );
    let frame = read(&scaled, None);
    assert!(
        close(frame.positions[3], [3.0, 5.0, 2.5]),
        "{:?}",
        frame.positions[3]
    );
    // Unscaled, as SPPARKS and old `dump custom` wrote them: refused.
    let unscaled = write(
        dir.path(),
        "unscaled.dump",
        &format!("{head}{}", lines(&|i| format!("{} 1 {i}.5 5 2.5\n", i + 1))),
    );
    let dump = DumpFile::open(&unscaled).unwrap();
    let e = dump
        .read_frame(0, &ReadOptions::default(), &NoProgress)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("10 of the first 10 atoms lie far outside the box")
            && e.contains("the columns look unscaled")
            && e.contains("ITEM: ATOMS id type x y z"),
        "{e}"
    );
    // Eight columns (image flags): refused at the line.
    let eight = write(
        dir.path(),
        "eight.dump",
        &format!(
            "{head}{}",
            lines(&|i| format!("{} 1 0.{i} 0.5 0.25 0 0 0\n", i + 1))
        ),
    );
    let dump = DumpFile::open(&eight).unwrap();
    let e = dump
        .read_frame(0, &ReadOptions::default(), &NoProgress)
        .unwrap_err()
        .to_string();
    assert!(e.contains("this atom line holds 8 columns"), "{e}");
}

/// Runs of other units concatenated into one dump: LAMMPS writes `ITEM: UNITS` in the
/// first frame of each file a dump command opens, so a frame takes the last before it
/// (the second run's later frames were read in the first run's units).
#[test]
fn concatenated_runs_keep_each_runs_units() {
    let dir = tempfile::tempdir().unwrap();
    let frame = |units: Option<&str>, step: u64| {
        let head = units.map_or(String::new(), |u| format!("ITEM: UNITS\n{u}\n"));
        format!(
            "{head}ITEM: TIMESTEP\n{step}\nITEM: NUMBER OF ATOMS\n1\nITEM: BOX BOUNDS pp pp pp\n\
             0 1\n0 1\n0 1\nITEM: ATOMS id type x y z\n1 1 0.5 0.5 0.5\n"
        )
    };
    let text = [
        frame(Some("metal"), 0),
        frame(None, 100),
        frame(Some("lj"), 200),
        frame(None, 300),
    ]
    .concat();
    let path = write(dir.path(), "cat.dump", &text);
    for pass in 0..2 {
        // (The second open takes the frames from the index a batch keeps, where kept.)
        let dump = DumpFile::open(&path).unwrap();
        let units: Vec<Option<String>> =
            (0..4).map(|k| dump.frame_info(k).unwrap().units).collect();
        assert_eq!(
            units,
            ["metal", "metal", "lj", "lj"].map(|u| Some(u.to_string())),
            "pass {pass}"
        );
    }
}
