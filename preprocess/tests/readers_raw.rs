//! Raw binary arrays with a JSON sidecar: layouts, types, byte orders, and bad sidecars
//! or arrays.

use std::path::{Path, PathBuf};

use mdlod_preprocess::readers::{DumpFile, InputFormat, ReadOptions};
use mdlod_preprocess::NoProgress;

struct Case {
    dir: tempfile::TempDir,
}

impl Case {
    fn new() -> Case {
        Case {
            dir: tempfile::tempdir().unwrap(),
        }
    }

    fn file(&self, name: &str, bytes: &[u8]) -> PathBuf {
        let p = self.dir.path().join(name);
        std::fs::write(&p, bytes).unwrap();
        p
    }

    fn sidecar(&self, json: &str) -> PathBuf {
        self.file("frame.raw.json", json.as_bytes())
    }
}

fn positions(n: usize) -> Vec<[f64; 3]> {
    (0..n)
        .map(|i| {
            let t = i as f64;
            [t * 0.5, (t * 0.37).sin() * 10.0, -t / 3.0]
        })
        .collect()
}

fn read(path: &Path) -> Result<mdlod_preprocess::Frame, String> {
    DumpFile::open(path)
        .and_then(|d| d.read_frame(0, &ReadOptions::default(), &NoProgress))
        .map_err(|e| e.to_string())
}

#[test]
fn interleaved_f32_with_species_radii_attribute_and_box() {
    let c = Case::new();
    let p = positions(1000);
    let pos: Vec<u8> = p
        .iter()
        .flatten()
        .flat_map(|&v| (v as f32).to_le_bytes())
        .collect();
    c.file("pos.f32", &pos);
    let types: Vec<u8> = (0..1000).map(|i| (i % 3) as u8).collect();
    c.file("type.u8", &types);
    let pe: Vec<u8> = (0..1000)
        .flat_map(|i| (-(i as f64)).to_le_bytes())
        .collect();
    c.file("pe.f64", &pe);
    let path = c.sidecar(
        r#"{ "mdlod_raw": 1, "particles": 1000,
             "positions": { "file": "pos.f32", "type": "f32" },
             "species": { "file": "type.u8", "type": "u8", "names": ["Cu", "Ag", "X"] },
             "radii": [1.28, 1.44, 0.3],
             "attribute": { "file": "pe.f64", "type": "f64", "name": "c_pe" },
             "box": { "origin": [0, 0, 0], "a": [500, 0, 0], "b": [0, 20, 0], "c": [0, 0, 400] },
             "timestep": 1000, "time": 2.5, "units": "metal" }"#,
    );
    let d = DumpFile::open(&path).unwrap();
    assert_eq!(d.format(), InputFormat::Raw);
    assert_eq!((d.frame_count(), d.frame_timestep(0)), (1, Some(1000)));
    let f = read(&path).unwrap();
    for (a, b) in f.positions.iter().zip(&p) {
        assert_eq!(*a, b.map(|v| v as f32));
    }
    assert_eq!(
        f.species_index,
        types.iter().map(|&t| u16::from(t)).collect::<Vec<_>>()
    );
    let radii: Vec<_> = f
        .species
        .iter()
        .map(|s| (s.name.as_str(), s.radius))
        .collect();
    assert_eq!(
        radii,
        [("Cu", Some(1.28)), ("Ag", Some(1.44)), ("X", Some(0.3))]
    );
    let a = f.attribute.unwrap();
    assert_eq!(a.name, "c_pe");
    assert_eq!(a.values[999], -999.0);
    assert_eq!((f.time, f.units.as_deref()), (Some(2.5), Some("metal")));
    assert_eq!(f.simulation_box.unwrap().c, [0.0, 0.0, 400.0]);
}

#[test]
fn planar_big_endian_f64_with_an_offset_and_a_derived_count() {
    let c = Case::new();
    let p = positions(257);
    let mut bytes = vec![0xAB; 16]; // a header to skip
    for k in 0..3 {
        for q in &p {
            bytes.extend_from_slice(&q[k].to_be_bytes());
        }
    }
    c.file("pos.f64be", &bytes);
    let path = c.sidecar(
        r#"{ "mdlod_raw": 1,
             "positions": { "file": "pos.f64be", "type": "f64", "layout": "planar",
                            "byte_order": "big", "offset": 16 } }"#,
    );
    let f = read(&path).unwrap();
    assert_eq!(f.len(), 257);
    for (a, b) in f.positions.iter().zip(&p) {
        assert_eq!(*a, b.map(|v| v as f32));
    }
    assert_eq!(f.species.len(), 1);
    // The same file named as fewer particles would read y from the x values: refused,
    // with the count the array holds; its own count is read as before.
    let fewer = c.sidecar(
        r#"{ "mdlod_raw": 1, "particles": 200,
             "positions": { "file": "pos.f64be", "type": "f64", "layout": "planar",
                            "byte_order": "big", "offset": 16 } }"#,
    );
    let e = read(&fewer).unwrap_err();
    assert!(
        e.contains("frame.raw.json")
            && e.contains("particles: 200")
            && e.contains("hold 771 values")
            && e.contains("array's own count (257)"),
        "{e}"
    );
    let own = c.sidecar(
        r#"{ "mdlod_raw": 1, "particles": 257,
             "positions": { "file": "pos.f64be", "type": "f64", "layout": "planar",
                            "byte_order": "big", "offset": 16 } }"#,
    );
    assert_eq!(read(&own).unwrap().positions, f.positions);
}

#[test]
fn bad_sidecars_and_arrays_are_errors_naming_the_file() {
    let c = Case::new();
    let good: Vec<u8> = positions(10)
        .iter()
        .flatten()
        .flat_map(|&v| (v as f32).to_le_bytes())
        .collect();
    c.file("pos.f32", &good);
    let mut nan = good.clone();
    nan[4 * 7..4 * 8].copy_from_slice(&f32::NAN.to_le_bytes());
    c.file("nan.f32", &nan);
    c.file("type.u8", &[0, 1, 2, 0, 1, 2, 0, 1, 2, 9]);
    // Indices up to 65535 without names: one more species than a file holds.
    let wide: Vec<u8> = [0u16, 1, 2, 3, 4, 5, 6, 7, 8, 65535]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    c.file("type.u16", &wide);
    let pos = |file: &str, extra: &str| {
        format!(
            r#"{{ "mdlod_raw": 1, "positions": {{ "file": "{file}", "type": "f32" }}{extra} }}"#
        )
    };
    let cases: Vec<(String, &str, &str)> = vec![
        (pos("pos.f32", r#", "particles": 11"#), "pos.f32", "truncated?"),
        (pos("pos.f32", r#", "particels": 10"#), "frame.raw.json", "unknown field `particels`"),
        (pos("missing.f32", ""), "missing.f32", "No such file"),
        (pos("nan.f32", ""), "nan.f32", "byte 28: particle 2: a coordinate is not finite"),
        (
            pos("pos.f32", r#", "species": { "file": "type.u8", "type": "u8", "names": ["a", "b", "c"] }"#),
            "type.u8",
            "byte 9: particle 9: species 9 but there are 3 species",
        ),
        (
            pos("pos.f32", r#", "species": { "file": "type.u16", "type": "u16" }"#),
            "type.u16",
            "byte 18: particle 9: species 65535 but there are 65535 species (a file holds at \
             most 65535: indices 0 to 65534)",
        ),
        (
            r#"{ "mdlod_raw": 1, "positions": { "file": "pos.f32", "type": "u8" } }"#.into(),
            "frame.raw.json",
            "type `u8` (use one of f32, f64)",
        ),
        (
            r#"{ "mdlod_raw": 1, "positions": { "file": "pos.f32", "type": "f32", "offset": 4 } }"#.into(),
            "pos.f32",
            "not a whole number of f32 positions",
        ),
        (
            r#"{ "mdlod_raw": 1, "positions": { "file": "pos.f32", "type": "f32", "offset": 999 } }"#.into(),
            "pos.f32",
            "offset 999 is past the end",
        ),
        (
            pos("pos.f32", r#", "species": { "file": "type.u8", "type": "u8", "names": ["a", " ", "c"] }"#),
            "frame.raw.json",
            "species: name 1 is empty",
        ),
        (
            pos("pos.f32", r#", "species": { "file": "type.u8", "type": "u8", "names": ["a", "b", "a"] }"#),
            "frame.raw.json",
            "species: names 0 and 2 are both \"a\"",
        ),
        (pos("pos.f32", r#", "particles": 18446744073709551615"#), "frame.raw.json", ""),
        (r#"{ "mdlod_raw": 2 }"#.into(), "frame.raw.json", ""),
        ("{ not json".into(), "frame.raw.json", "raw sidecar"),
    ];
    for (json, file, needle) in cases {
        let path = c.sidecar(&json);
        let e = read(&path).unwrap_err();
        assert!(e.contains(file) && e.contains(needle), "{json}\n  -> {e}");
    }
}

#[test]
fn f64_positions_past_the_single_precision_range_are_errors_naming_the_array() {
    let c = Case::new();
    let mut p = positions(10);
    p[4][2] = -3e39;
    let pos: Vec<u8> = p.iter().flatten().flat_map(|v| v.to_le_bytes()).collect();
    let file = c.file("pos.f64", &pos);
    let path =
        c.sidecar(r#"{ "mdlod_raw": 1, "positions": { "file": "pos.f64", "type": "f64" } }"#);
    let e = read(&path).unwrap_err();
    let byte = 8 * (3 * 4 + 2);
    assert!(
        e.starts_with(&format!(
            "{}: byte {byte}: particle 4: a coordinate is not finite in single precision \
             (-3e39 is beyond",
            file.display()
        )),
        "{e}"
    );
}

/// A sidecar is recognised by its content whatever its name (as README says the format
/// is sniffed), a damaged one too (so that reading it says what is wrong); other JSON is
/// not taken for one.
#[test]
fn a_sidecar_not_named_raw_json_is_recognised_by_its_content() {
    let c = Case::new();
    let pos: Vec<u8> = positions(10)
        .iter()
        .flatten()
        .flat_map(|&v| (v as f32).to_le_bytes())
        .collect();
    c.file("pos.f32", &pos);
    let json = r#"
        { "mdlod_raw": 1, "positions": { "file": "pos.f32", "type": "f32" }, "timestep": 7 }"#;
    let named = read(&c.sidecar(json)).unwrap();
    let side = c.file("side.json", json.as_bytes());
    let dump = DumpFile::open(&side).unwrap();
    assert_eq!(dump.format(), InputFormat::Raw);
    let sniffed = read(&side).unwrap();
    assert_eq!(sniffed.positions, named.positions);
    assert_eq!(sniffed.timestep, Some(7));
    let bad = c.file("bad.json", br#"{ "mdlod_raw": 1, "positions": 3 }"#);
    let e = read(&bad).unwrap_err();
    assert!(e.contains("bad.json") && e.contains("raw sidecar"), "{e}");
    let other = c.file("view.json", br#"{ "azimuth": 30 }"#);
    let e = read(&other).unwrap_err();
    assert!(
        e.contains("view.json:1: cannot tell the format") && e.contains("raw sidecar"),
        "{e}"
    );
}

/// A key of the wrong kind is said in the sidecar's own words (a file name in quotes, an
/// array's object, a number), with its line, not in the JSON reader's type names.
#[test]
fn a_key_of_the_wrong_kind_is_said_plainly() {
    let c = Case::new();
    c.file("p.f32", &[0u8; 24]);
    for (json, says) in [
        (
            "{ \"mdlod_raw\": 1,\n \"positions\": { \"file\": { \"x\": 1 }, \"type\": \"f32\" } }",
            ":2: raw sidecar: invalid type: an object {...}, expected a file name in quotes",
        ),
        (
            "{ \"mdlod_raw\": 1,\n \"positions\": [\"p.f32\"] }",
            "expected an array's object, { \"file\": ..., \"type\": \"f32\" }",
        ),
        (
            "{ \"mdlod_raw\": 1, \"particles\": \"2\",\n \"positions\": { \"file\": \"p.f32\", \"type\": \"f32\" } }",
            "expected a whole number from 0",
        ),
    ] {
        let e = read(&c.sidecar(json)).unwrap_err();
        assert!(e.contains(says), "{json}: {e}");
    }
}

/// A list of attributes (`attributes`): the first is read without `--attribute`, any
/// other by its name, and further ones beside it (`extra_attributes`); an entry without
/// a name, a name listed twice, or `attribute` beside the list are errors, and a name
/// the list lacks is told with the list.
#[test]
fn a_list_of_attributes_is_read_by_name() {
    let c = Case::new();
    let n = 12usize;
    let pos: Vec<u8> = positions(n)
        .iter()
        .flatten()
        .flat_map(|&v| (v as f32).to_le_bytes())
        .collect();
    c.file("p.f32", &pos);
    let rho: Vec<f32> = (0..n).map(|i| 1e-3 * (i + 1) as f32).collect();
    let temp: Vec<f64> = (0..n).map(|i| 1e4 + 100.0 * i as f64).collect();
    c.file(
        "rho.f32",
        &rho.iter().flat_map(|v| v.to_le_bytes()).collect::<Vec<_>>(),
    );
    c.file(
        "t.f64",
        &temp
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect::<Vec<_>>(),
    );
    let path = c.sidecar(
        r#"{ "mdlod_raw": 1,
  "positions": { "file": "p.f32", "type": "f32" },
  "attributes": [
    { "file": "rho.f32", "type": "f32", "name": "rho" },
    { "file": "t.f64", "type": "f64", "name": "T" } ] }"#,
    );
    let dump = DumpFile::open(&path).unwrap();
    let with = |a: Option<&str>, extra: &[&str]| ReadOptions {
        attribute: a.map(str::to_string),
        extra_attributes: extra.iter().map(|s| s.to_string()).collect(),
        ..Default::default()
    };
    let first = dump.read_frame(0, &with(None, &[]), &NoProgress).unwrap();
    assert_eq!(first.attribute.unwrap().values, rho);
    let t = dump
        .read_frame(0, &with(Some("T"), &[]), &NoProgress)
        .unwrap();
    let t = t.attribute.unwrap();
    assert_eq!(t.name, "T");
    assert_eq!(t.values, temp.iter().map(|&v| v as f32).collect::<Vec<_>>());
    let both = with(Some("T"), &["rho"]);
    let further = mdlod_preprocess::convert::read_extra_attributes(&dump, 0, &both).unwrap();
    assert_eq!(
        (further[0].name.as_str(), &further[0].values),
        ("rho", &rho)
    );
    let e = dump
        .read_frame(0, &with(Some("h"), &[]), &NoProgress)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains(
            ":3: --attribute h: no attribute `h` in the sidecar (its attributes are `rho`, `T`)"
        ),
        "{e}"
    );
    for (json, says) in [
        (
            r#"{ "mdlod_raw": 1, "positions": { "file": "p.f32", "type": "f32" },
  "attributes": [ { "file": "rho.f32", "type": "f32" } ] }"#,
            "entry 0 (rho.f32) has no `name`",
        ),
        (
            r#"{ "mdlod_raw": 1, "positions": { "file": "p.f32", "type": "f32" },
  "attributes": [ { "file": "rho.f32", "type": "f32", "name": "a" },
                  { "file": "rho.f32", "type": "f32", "name": "a" } ] }"#,
            "`a` is listed twice",
        ),
        (
            r#"{ "mdlod_raw": 1, "positions": { "file": "p.f32", "type": "f32" },
  "attribute": { "file": "rho.f32", "type": "f32" },
  "attributes": [ { "file": "t.f64", "type": "f64", "name": "T" } ] }"#,
            "given beside `attribute`",
        ),
    ] {
        let e = read(&c.sidecar(json)).unwrap_err();
        assert!(e.contains(says), "{e}");
    }
}

/// An attribute the sidecar lacks is an error naming the sidecar, the line of its
/// `attribute` entry and the attribute asked for (it named the positions file).
#[test]
fn a_missing_attribute_is_an_error_naming_the_sidecar() {
    let c = Case::new();
    let pos: Vec<u8> = positions(10)
        .iter()
        .flatten()
        .flat_map(|&v| (v as f32).to_le_bytes())
        .collect();
    c.file("plum.pos", &pos);
    c.file("plum.rho", &[0u8; 40]);
    let read_h = |json: &str| {
        let path = c.sidecar(json);
        let e = DumpFile::open(&path)
            .and_then(|d| {
                d.read_frame(
                    0,
                    &ReadOptions {
                        attribute: Some("h".into()),
                        ..Default::default()
                    },
                    &NoProgress,
                )
            })
            .unwrap_err()
            .to_string();
        (path, e)
    };
    let (path, e) = read_h(
        r#"{ "mdlod_raw": 1,
  "positions": { "file": "plum.pos", "type": "f32" },
  "attribute": { "file": "plum.rho", "type": "f32", "name": "density" } }"#,
    );
    assert_eq!(
        e,
        format!(
            "{}:3: --attribute h: no attribute `h` in the sidecar (its attribute is \
             `density`, from {})",
            path.display(),
            c.dir.path().join("plum.rho").display()
        )
    );
    let (path, e) =
        read_h(r#"{ "mdlod_raw": 1, "positions": { "file": "plum.pos", "type": "f32" } }"#);
    assert_eq!(
        e,
        format!(
            "{}:1: --attribute h: no attribute `h` in the sidecar (it names none: add an \
             `attribute` entry)",
            path.display()
        )
    );
}

/// Without `particles`, the positions file says how many particles there are: a species
/// or attribute array of another length (another run's, another frame's) is an error
/// naming both arrays and their counts, not read for its first values. `radii` must give
/// one radius per species name (or one without `species`).
#[test]
fn arrays_of_different_lengths_and_radii_per_name_are_checked() {
    let c = Case::new();
    let pos: Vec<u8> = positions(10)
        .iter()
        .flatten()
        .flat_map(|&v| v.to_le_bytes())
        .collect();
    let pos_path = c.file("pos.f64", &pos);
    c.file("type.u8", &[0u8; 10]);
    let long = c.file("long.u8", &[0u8; 500]);
    let pe = c.file("pe.f32", &[0u8; 4 * 12 + 2]);
    c.file("pe10.f32", &[0u8; 40]);
    let sidecar = |species: &str, extra: &str| {
        format!(
            r#"{{ "mdlod_raw": 1, "positions": {{ "file": "pos.f64", "type": "f64" }},
  "species": {{ "file": "{species}", "type": "u8", "names": ["A", "B"] }}{extra} }}"#
        )
    };
    let path = c.sidecar(&sidecar("long.u8", ""));
    assert_eq!(
        read(&path).unwrap_err(),
        format!(
            "{}: byte 0: species: 500 values from byte 0, but the positions ({}) hold 10 \
             particles: the arrays differ in length",
            long.display(),
            pos_path.display()
        )
    );
    let path = c.sidecar(&sidecar(
        "type.u8",
        r#", "attribute": { "file": "pe.f32", "type": "f32" }"#,
    ));
    assert_eq!(
        read(&path).unwrap_err(),
        format!(
            "{}: byte 0: attribute: 12 values and 2 bytes from byte 0, but the positions ({}) \
             hold 10 particles: the arrays differ in length",
            pe.display(),
            pos_path.display()
        )
    );
    // A missing array: the sidecar's line of the key that names it.
    let path = c.sidecar(&sidecar("typo.u8", ""));
    let e = read(&path).unwrap_err();
    assert!(
        e.starts_with(&format!(
            "{}:2: species: `file` \"typo.u8\": cannot open",
            path.display()
        )),
        "{e}"
    );
    // A file that opens but does not map (one the kernel makes up): the sidecar's key,
    // and why.
    if cfg!(target_os = "linux") {
        let path = c.sidecar(&sidecar("/proc/self/mem", ""));
        let e = read(&path).unwrap_err();
        assert!(
            e.starts_with(&format!(
                "{}:2: species: `file` \"/proc/self/mem\": /proc/self/mem does not map (not a \
                 file on a disk)",
                path.display()
            )),
            "{e}"
        );
    }
    // With `particles` given, arrays holding more are read for their first values.
    let path = c.sidecar(&sidecar("long.u8", r#", "particles": 10"#));
    assert_eq!(read(&path).unwrap().len(), 10);
    // ... and said (a mistyped count reads too few).
    let notes = DumpFile::open(&path)
        .unwrap()
        .frame_notes(0, &ReadOptions::default());
    assert_eq!(
        notes,
        [format!(
            "{}: species: the array holds 490 particles' values past the 10 that `particles` \
             in {} names, which alone are read",
            long.display(),
            path.display()
        )]
    );
    let path = c.sidecar(&sidecar(
        "type.u8",
        r#", "attribute": { "file": "pe10.f32", "type": "f32" }, "radii": [0.5, 0.7]"#,
    ));
    assert_eq!(read(&path).unwrap().species[1].radius, Some(0.7));

    for (radii, message) in [
        ("[0.5]", "radii: 1 given for 2 species names"),
        ("[0.5, 0.7, 0.9]", "radii: 3 given for 2 species names"),
    ] {
        let path = c.sidecar(&sidecar("type.u8", &format!(r#", "radii": {radii}"#)));
        assert_eq!(
            read(&path).unwrap_err(),
            format!(
                "{}:2: {message} (one radius per species, in their order)",
                path.display()
            )
        );
    }
    let path = c.sidecar(
        r#"{ "mdlod_raw": 1, "positions": { "file": "pos.f64", "type": "f64" }, "radii": [1, 2] }"#,
    );
    assert_eq!(
        read(&path).unwrap_err(),
        format!(
            "{}:1: radii: 2 given for 1 species (no `species` array) (one radius per \
             species, in their order)",
            path.display()
        )
    );
}

/// Positions (or an attribute) whose file holds exactly what the other float type needs
/// are likely declared with the wrong `type` (`f32` data declared `f64`, or the reverse):
/// the size error says so, naming the file and the byte, instead of only "truncated?" or
/// "the arrays differ in length".
#[test]
fn a_file_of_the_other_float_types_size_is_said_to_be_of_that_type() {
    let c = Case::new();
    let p = positions(10);
    let f32s: Vec<u8> = p
        .iter()
        .flatten()
        .flat_map(|&v| (v as f32).to_le_bytes())
        .collect();
    let f64s: Vec<u8> = p.iter().flatten().flat_map(|v| v.to_le_bytes()).collect();
    let pos32 = c.file("pos.f32", &f32s);
    c.file("pos.f64", &f64s);
    let odd32 = c.file("odd.f32", &f32s[..5 * 12]);
    c.file("type.u8", &[0u8; 10]);
    let pe64 = c.file("pe.f64", &[0u8; 80]);
    let pe32 = c.file("pe.f32", &[0u8; 40]);
    let sidecar = |file: &str, ty: &str, extra: &str| {
        c.sidecar(&format!(
            r#"{{ "mdlod_raw": 1, "positions": {{ "file": "{file}", "type": "{ty}" }}{extra} }}"#
        ))
    };
    let species = r#", "species": { "file": "type.u8", "type": "u8" }"#;

    // `particles` given: f32 data declared f64 is half the size needed.
    let path = sidecar("pos.f32", "f64", r#", "particles": 10"#);
    assert_eq!(
        read(&path).unwrap_err(),
        format!(
            "{}: byte 120: positions: 10 particles need 240 bytes from byte 0, the file has \
             120; it holds exactly 10 particles of f32: is its type f32, not f64?",
            pos32.display()
        )
    );
    // An attribute of f32 declared f64 (the positions right).
    let attribute = r#", "attribute": { "file": "pe.f32", "type": "f64" }"#;
    let path = sidecar(
        "pos.f32",
        "f32",
        &format!(r#"{attribute}, "particles": 10"#),
    );
    assert_eq!(
        read(&path).unwrap_err(),
        format!(
            "{}: byte 40: attribute: 10 particles need 80 bytes from byte 0, the file has 40; \
             it holds exactly 10 particles of f32: is its type f32, not f64?",
            pe32.display()
        )
    );
    // Without `particles` the sizes fit the data all `f32` (the attribute's type wrong)
    // or all `f64` (the positions'): both are said.
    let path = sidecar("pos.f32", "f32", attribute);
    assert_eq!(
        read(&path).unwrap_err(),
        format!(
            "{}: byte 40: attribute: 10 particles need 80 bytes from byte 0, the file has 40; \
             it holds exactly 10 particles of f32, and the positions read as f64 exactly 5: \
             is its type f32, or theirs f64?",
            pe32.display()
        )
    );
    // A size that fits neither type is still "truncated?".
    let path = sidecar("pos.f32", "f32", r#", "particles": 11"#);
    assert!(read(&path)
        .unwrap_err()
        .ends_with("the file has 120 (truncated?)"));

    // No `particles`: the positions' declared type sets the count, so another array
    // seems of another length, longer (f32 declared f64) or shorter (the reverse).
    let path = sidecar("pos.f32", "f64", species);
    assert_eq!(
        read(&path).unwrap_err(),
        format!(
            "{}: byte 0: species: 10 values from byte 0, but the positions ({}) hold 5 \
             particles: the arrays differ in length; or the positions read as f32 hold \
             exactly 10 particles: is their type f32, not f64?",
            c.dir.path().join("type.u8").display(),
            pos32.display()
        )
    );
    let path = sidecar("pos.f64", "f32", species);
    assert_eq!(
        read(&path).unwrap_err(),
        format!(
            "{}: byte 10: species: 20 particles need 20 bytes from byte 0, the file has 10; \
             the positions read as f64 hold exactly 10 particles: is their type f64, not f32?",
            c.dir.path().join("type.u8").display(),
        )
    );
    // An attribute of f64 declared f32, the positions right.
    let path = sidecar(
        "pos.f32",
        "f32",
        r#", "attribute": { "file": "pe.f64", "type": "f32" }"#,
    );
    assert_eq!(
        read(&path).unwrap_err(),
        format!(
            "{}: byte 0: attribute: 20 values from byte 0, but the positions ({}) hold 10 \
             particles: the arrays differ in length; or it holds exactly 10 particles of \
             f64: is its type f64, not f32?",
            pe64.display(),
            pos32.display()
        )
    );
    // Positions that are no whole number of f64 positions but are of f32 ones.
    let path = sidecar("odd.f32", "f64", "");
    assert_eq!(
        read(&path).unwrap_err(),
        format!(
            "{}: byte 0: 60 bytes are not a whole number of f64 positions, but exactly 5 of \
             f32: is its type f32, not f64? (else give `particles`)",
            odd32.display()
        )
    );
    // The right types read.
    let path = sidecar(
        "pos.f64",
        "f64",
        r#", "attribute": { "file": "pe.f64", "type": "f64" }"#,
    );
    assert_eq!(read(&path).unwrap().len(), 10);
}

/// Double-precision positions declared `f32` with the count given: a coordinate that
/// reads as NaN is refused saying the array holds twice the bytes, and the type.
#[test]
fn double_positions_declared_single_suggest_the_type() {
    let c = Case::new();
    // Read as two f32, 10.0000… (0x40240000_7fc00000) gives a NaN.
    let mut values = [1.0f64; 30];
    values[4] = f64::from_bits(0x4024_0000_7fc0_0000);
    let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
    c.file("pos.f64", &bytes);
    let json = r#"{ "mdlod_raw": 1, "particles": 10,
                    "positions": { "file": "pos.f64", "type": "f32" } }"#;
    let e = read(&c.sidecar(json)).unwrap_err();
    assert!(
        e.contains("a coordinate is not finite")
            && e.contains("the array holds 240 bytes, twice what 10 particles of `f32` x y z take: is its `type` f64?"),
        "{e}"
    );
    // Values that read as numbers either way: converted, with the note saying so.
    let values: Vec<u8> = (0..30).flat_map(|i| (i as f64).to_le_bytes()).collect();
    c.file("grid.f64", &values);
    let json = r#"{ "mdlod_raw": 1, "particles": 10,
                    "positions": { "file": "grid.f64", "type": "f32" } }"#;
    let path = c.sidecar(json);
    assert_eq!(read(&path).unwrap().len(), 10);
    let notes = DumpFile::open(&path)
        .unwrap()
        .frame_notes(0, &ReadOptions::default());
    assert!(
        notes.len() == 1
            && notes[0].ends_with("(exactly twice the bytes of `f32` values: is its `type` f64?)"),
        "{notes:?}"
    );
}

/// Big-endian positions declared little-endian: a coordinate that reads as NaN is
/// refused, naming the particle and saying the other byte order reads a number.
#[test]
fn a_non_finite_coordinate_that_the_other_byte_order_reads_suggests_it() {
    let c = Case::new();
    // 0x4120807f read big-endian is 10.03; read little-endian, a NaN.
    let mut values = [1.0f32; 30];
    values[13] = f32::from_bits(0x4120_807f);
    let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_be_bytes()).collect();
    c.file("pos.f32", &bytes);
    let json = r#"{ "mdlod_raw": 1, "positions": { "file": "pos.f32", "type": "f32" } }"#;
    let e = read(&c.sidecar(json)).unwrap_err();
    assert!(
        e.contains("particle 4: a coordinate is not finite")
            && e.contains("read in the other byte order it is")
            && e.contains("is `byte_order` big?"),
        "{e}"
    );
    // Declared big-endian, it reads.
    let json = r#"{ "mdlod_raw": 1, "positions": { "file": "pos.f32", "type": "f32",
                    "byte_order": "big" } }"#;
    assert_eq!(read(&c.sidecar(json)).unwrap().len(), 10);
    // A NaN of little-endian data read the other way round is a denormal (6.9e-41), no
    // plain number: no suggestion (it printed 330 digits of it).
    let mut values = [1.0f32; 30];
    values[13] = f32::NAN;
    let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
    c.file("pos.f32", &bytes);
    let json = r#"{ "mdlod_raw": 1, "positions": { "file": "pos.f32", "type": "f32" } }"#;
    let e = read(&c.sidecar(json)).unwrap_err();
    assert!(
        e.contains("particle 4: a coordinate is not finite") && !e.contains("other byte order"),
        "{e}"
    );
}

/// A bad value inside an array's object is reported at the line of its own key, not of
/// the object's (a sidecar written one key per line).
#[test]
fn a_bad_value_in_an_array_names_the_line_of_its_key() {
    let c = Case::new();
    c.file("pos.f32", &[0u8; 120]);
    c.file("type.u8", &[0u8; 10]);
    let text = |layout: &str, ty: &str, order: &str| {
        format!(
            "{{\n  \"mdlod_raw\": 1,\n  \"positions\": {{\n    \"file\": \"pos.f32\",\n    \
             \"type\": \"f32\",\n    \"layout\": \"{layout}\"\n  }},\n  \"species\": {{\n    \
             \"file\": \"type.u8\",\n    \"type\": \"{ty}\",\n    \"byte_order\": \"{order}\"\n  \
             }}\n}}\n"
        )
    };
    for (json, line, says) in [
        (
            text("interleave", "u8", "little"),
            6,
            "positions: layout `interleave`",
        ),
        (
            text("interleaved", "u64", "little"),
            10,
            "species: type `u64`",
        ),
        (
            text("interleaved", "u8", "little-endian"),
            11,
            "species: byte_order `little-endian`",
        ),
    ] {
        let path = c.sidecar(&json);
        let e = read(&path).unwrap_err();
        assert!(
            e.starts_with(&format!("{}:{line}: {says}", path.display())),
            "{e}"
        );
    }
}

/// A sidecar value of megabytes is named by its first characters.
#[test]
fn a_huge_bad_sidecar_value_is_named_briefly() {
    let c = Case::new();
    c.file("pos.f32", &[0u8; 12]);
    let path = c.sidecar(&format!(
        r#"{{"mdlod_raw": 1, "positions": {{"file": "pos.f32", "type": "{}"}}}}"#,
        "y".repeat(3_000_000)
    ));
    let e = read(&path).unwrap_err();
    assert!(
        e.len() < 400 && e.contains("positions: type `yyy"),
        "{}",
        &e[..e.len().min(400)]
    );
}

/// An SPH code's smoothing lengths as a `radius` array (or diameters): each particle
/// keeps its own size, a species of one size keeps it as its radius, `--no-sizes`
/// leaves the array unread, and bad sizes name the array and the particle.
#[test]
fn per_particle_sizes_come_from_a_radius_or_diameter_array() {
    let c = Case::new();
    let n = 300usize;
    let pos: Vec<u8> = positions(n)
        .iter()
        .flatten()
        .flat_map(|&v| (v as f32).to_le_bytes())
        .collect();
    c.file("pos.f32", &pos);
    // Gas (0) with sizes 0.1 to 0.4, stars (1) all of size 0.05.
    let types: Vec<u8> = (0..n).map(|i| u8::from(i % 4 == 0)).collect();
    c.file("type.u8", &types);
    let h: Vec<f64> = (0..n)
        .map(|i| match i % 4 {
            0 => 0.05,
            k => 0.1 * k as f64 + 0.001 * (i % 7) as f64,
        })
        .collect();
    c.file(
        "h.f64",
        &h.iter().flat_map(|v| v.to_le_bytes()).collect::<Vec<u8>>(),
    );
    let d2: Vec<u8> = h
        .iter()
        .flat_map(|v| ((2.0 * v) as f32).to_le_bytes())
        .collect();
    c.file("d.f32", &d2);
    let sidecar = |sizes: &str| {
        c.sidecar(&format!(
            r#"{{ "mdlod_raw": 1, "positions": {{ "file": "pos.f32", "type": "f32" }},
                 "species": {{ "file": "type.u8", "type": "u8", "names": ["gas", "star"] }},
                 {sizes} }}"#
        ))
    };
    for sizes in [
        r#""radius": { "file": "h.f64", "type": "f64", "name": "h" }"#,
        r#""diameter": { "file": "d.f32", "type": "f32" }"#,
    ] {
        let path = sidecar(sizes);
        let f = read(&path).unwrap();
        let radii = f.radii.as_ref().expect("per-particle radii");
        for (i, (&r, &want)) in radii.iter().zip(&h).enumerate() {
            assert!(
                (f64::from(r) - want).abs() < 1e-6,
                "{sizes}: particle {i}: {r} against {want}"
            );
        }
        let (gas, star) = (&f.species[0], &f.species[1]);
        let (lo, hi) = gas.radius_range.unwrap();
        assert!(
            (lo - 0.1).abs() < 1e-6 && (hi - 0.306).abs() < 1e-6,
            "{lo} {hi}"
        );
        assert_eq!(star.radius_range, Some((0.05, 0.05)));
        assert!((star.radius.unwrap() - 0.05).abs() < 1e-7);
        let d = DumpFile::open(&path).unwrap();
        let info = d.frame_info(0).unwrap();
        assert!(info.columns.len() == 5, "{:?}", info.columns);
        // --no-sizes: the array is not read.
        let opts = ReadOptions {
            sizes: mdlod_preprocess::readers::SizeColumn::Off,
            ..Default::default()
        };
        let f = d.read_frame(0, &opts, &NoProgress).unwrap();
        assert!(f.radii.is_none() && f.species[0].radius_range.is_none());
    }
    // Both, a negative size, a short array.
    let e = read(&sidecar(
        r#""radius": { "file": "h.f64", "type": "f64" }, "diameter": { "file": "d.f32", "type": "f32" }"#,
    ))
    .unwrap_err();
    assert!(
        e.contains("frame.raw.json:3: diameter: given beside `radius`"),
        "{e}"
    );
    let mut bad = h.clone();
    bad[17] = -1.0;
    c.file(
        "bad.f64",
        &bad.iter()
            .flat_map(|v| v.to_le_bytes())
            .collect::<Vec<u8>>(),
    );
    let e = read(&sidecar(
        r#""radius": { "file": "bad.f64", "type": "f64", "name": "h" }"#,
    ))
    .unwrap_err();
    assert!(
        e.contains("bad.f64") && e.contains("particle 17: `h` -1 is no particle size"),
        "{e}"
    );
    c.file("short.f32", &d2[..400]);
    let e = read(&sidecar(
        r#""diameter": { "file": "short.f32", "type": "f32" }"#,
    ))
    .unwrap_err();
    assert!(e.contains("short.f32") && e.contains("diameter"), "{e}");
}

/// Raw arrays give species by the sidecar's `species` array: a species column is
/// refused, whole and in parts, naming the sidecar and where the species come from.
#[test]
fn a_species_column_is_refused_for_raw_arrays() {
    let c = Case::new();
    let pos: Vec<u8> = positions(10)
        .iter()
        .flatten()
        .flat_map(|&v| (v as f32).to_le_bytes())
        .collect();
    c.file("cat.pos", &pos);
    let path =
        c.sidecar(r#"{ "mdlod_raw": 1, "positions": { "file": "cat.pos", "type": "f32" } }"#);
    let opts = ReadOptions {
        species_column: Some("c_cna".into()),
        ..Default::default()
    };
    let dump = DumpFile::open(&path).unwrap();
    for e in [
        dump.read_frame(0, &opts, &NoProgress).unwrap_err(),
        dump.read_part(0, &opts, 0..5, &NoProgress).unwrap_err(),
        dump.check_named_columns(0, &opts).unwrap_err(),
    ] {
        let e = e.to_string();
        assert!(
            e.contains("frame.raw.json")
                && e.contains("--species-column c_cna names a column of a LAMMPS or XYZ dump")
                && e.contains("sidecar's `species` array"),
            "{e}"
        );
    }
}
