//! FORMAT.md is a specification another language can implement: `format/spec/read_mdlod.py`,
//! a reader written in Python from FORMAT.md alone, decodes converted files exactly as
//! `mdlod_format::MdlodFile` does (every point of every level to the f32 bit, species,
//! attributes, node records) and refuses corrupt copies with a message, never a traceback.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::OnceLock;

use mdlod_datasets::lammps_sample_path;
use mdlod_format::{MdlodFile, SectionKind};
use serde_json::Value;

const READER: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/format/spec/read_mdlod.py");

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn mdlod(args: &[&str]) {
    let out = Command::new(env!("CARGO_BIN_EXE_mdlod"))
        .args(args)
        .output()
        .expect("the mdlod binary runs");
    assert!(
        out.status.success(),
        "mdlod {args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// A Python 3 that has the `xxhash` module. `scripts/setup.sh` installs Debian's
/// python3-xxhash, which only the system Python sees: a `python3` earlier on the PATH
/// (pyenv, a virtual environment) may lack it, so /usr/bin/python3 is tried too. Without
/// one the test fails: the spec's companion reader must run where the tests run.
fn python() -> &'static str {
    static PYTHON: OnceLock<Option<&'static str>> = OnceLock::new();
    let found = PYTHON.get_or_init(|| {
        ["python3", "/usr/bin/python3"].into_iter().find(|p| {
            Command::new(p)
                .args(["-c", "import xxhash; xxhash.xxh3_64_intdigest(b'')"])
                .output()
                .is_ok_and(|o| o.status.success())
        })
    });
    found.unwrap_or_else(|| {
        panic!(
            "no python3 with the xxhash module (Debian package python3-xxhash), needed to run \
             format/spec/read_mdlod.py: run `bash scripts/setup.sh`"
        )
    })
}

fn read_mdlod(args: &[&str]) -> Output {
    Command::new(python())
        .arg(READER)
        .args(args)
        .output()
        .expect("python3 runs")
}

/// The Python reader's JSON dump of `file`.
fn python_dump(file: &Path) -> Value {
    let json = file.with_extension("json");
    let out = read_mdlod(&[s(file), "--dump", s(&json)]);
    assert!(
        out.status.success(),
        "read_mdlod.py refused {}: {}",
        file.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap()
}

fn u64_of(v: &Value) -> u64 {
    v.as_u64()
        .unwrap_or_else(|| panic!("{v} is not an unsigned integer"))
}

/// A JSON number written as the `repr` of an f32 value, as that f32. (serde_json's
/// default parsing may miss the nearest f64 by an ulp; rounding to f32 still gives the
/// value written, whose f32 neighbours lie 2^29 f64 ulps away.)
fn f32_of(v: &Value) -> f32 {
    v.as_f64().unwrap_or_else(|| panic!("{v} is not a number")) as f32
}

fn f32s(v: &Value) -> Vec<f32> {
    v.as_array().unwrap().iter().map(f32_of).collect()
}

fn assert_same_f32(py: &[f32], rust: &[f32], what: &str) {
    let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(py), bits(rust), "{what}: Python {py:?}, Rust {rust:?}");
}

/// Everything the Python reader decoded equals what the Rust reader decodes.
fn assert_same_decoding(file: &Path) {
    let py = python_dump(file);
    let f = MdlodFile::open(file).unwrap();
    let name = file.file_name().unwrap().to_string_lossy();

    let h = f.header();
    let ph = &py["header"];
    assert_eq!(u64_of(&ph["version_major"]), u64::from(h.version_major));
    assert_eq!(u64_of(&ph["version_minor"]), u64::from(h.version_minor));
    assert_eq!(u64_of(&ph["position_bits"]), u64::from(h.position_bits));
    assert_eq!(u64_of(&ph["section_count"]), u64::from(h.section_count));
    assert_eq!(u64_of(&ph["section_table_offset"]), h.section_table_offset);
    assert_eq!(u64_of(&ph["file_size"]), h.file_size);
    assert_eq!(u64_of(&ph["header_checksum"]), h.header_checksum);
    let meta = f.metadata();
    assert_eq!(u64_of(&py["metadata"]["particles"]), meta.particles);
    assert_eq!(
        u64_of(&py["metadata"]["build"]["delta_n"]),
        f.delta_n() as u64
    );

    // The levels table and every point of every level.
    let levels = py["levels"].as_array().unwrap();
    assert_eq!(levels.len(), f.level_count(), "{name}: level count");
    for (l, (pl, rl)) in levels.iter().zip(f.levels()).enumerate() {
        assert_eq!(
            u64_of(&pl["point_count"]),
            rl.point_count,
            "{name} level {l}"
        );
        assert_eq!(u64_of(&pl["node_first"]), rl.node_first, "{name} level {l}");
        let rust = if l == 0 {
            vec![f.nodes()[0].centroid]
        } else {
            f.decode_level(l).unwrap()
        };
        let pts = pl["positions"].as_array().unwrap();
        assert_eq!(pts.len(), rust.len(), "{name} level {l}: point count");
        for (i, (p, r)) in pts.iter().zip(&rust).enumerate() {
            assert_same_f32(&f32s(p), r, &format!("{name} level {l} point {i}"));
        }
    }

    // The node records, field by field.
    let nodes = py["nodes"].as_array().unwrap();
    assert_eq!(nodes.len(), f.nodes().len(), "{name}: node count");
    for (i, (p, n)) in nodes.iter().zip(f.nodes()).enumerate() {
        let at = format!("{name} node {i}");
        assert_same_f32(&f32s(&p["centroid"]), &n.centroid, &at);
        assert_same_f32(&f32s(&p["quant_scale"]), &n.quant_scale, &at);
        assert_same_f32(&f32s(&p["bounds_min"]), &n.bounds_min, &at);
        assert_same_f32(&f32s(&p["bounds_max"]), &n.bounds_max, &at);
        let scalars = ["radius", "area_sum", "attribute", "rms_radius"].map(|k| f32_of(&p[k]));
        assert_same_f32(
            &scalars,
            &[n.radius, n.area_sum, n.attribute, n.rms_radius],
            &at,
        );
        let ints = [
            "colour",
            "child_first",
            "child_count",
            "point_first",
            "point_count",
            "parent",
            "quant_node",
            "level",
            "point_level",
            "species",
        ]
        .map(|k| u64_of(&p[k]));
        let rust = [
            n.colour,
            n.child_first,
            n.child_count,
            n.point_first,
            n.point_count,
            n.parent,
            n.quant_node,
            u32::from(n.level),
            u32::from(n.point_level),
            u32::from(n.species),
        ]
        .map(u64::from);
        assert_eq!(ints, rust, "{at}");
    }

    // The particles' species and attribute.
    let particles = &py["particles"];
    let species: Vec<u16> = particles["species"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| u16::try_from(u64_of(v)).unwrap())
        .collect();
    assert_eq!(species, f.species(), "{name}: species");
    match (&meta.attribute, f.attribute()) {
        (Some(info), Some(q)) => {
            let pa = &particles["attribute"];
            assert_eq!(pa["name"].as_str(), Some(info.name.as_str()));
            let pq: Vec<u16> = pa["q"]
                .as_array()
                .unwrap()
                .iter()
                .map(|v| u16::try_from(u64_of(v)).unwrap())
                .collect();
            assert_eq!(pq, q, "{name}: quantized attribute");
            let rust: Vec<f32> = q.iter().map(|&q| info.decode(q)).collect();
            assert_same_f32(&f32s(&pa["values"]), &rust, &format!("{name}: attribute"));
        }
        (None, None) => assert!(particles["attribute"].is_null(), "{name}: attribute"),
        _ => panic!("{name}: the Rust reader's attribute and metadata disagree"),
    }
    match f.radii() {
        Some(q) => {
            let pr = &particles["radius"];
            let pq: Vec<u16> = pr["q"]
                .as_array()
                .unwrap()
                .iter()
                .map(|v| u16::try_from(u64_of(v)).unwrap())
                .collect();
            assert_eq!(pq, q, "{name}: quantized radii");
            let rust: Vec<f32> = (0..q.len()).map(|i| f.particle_radius(i)).collect();
            assert_same_f32(&f32s(&pr["values"]), &rust, &format!("{name}: radii"));
        }
        None => assert!(particles["radius"].is_null(), "{name}: radii"),
    }
    // Further attributes: names, quantized values, decoded values and node means.
    let extras = particles["attributes"].as_array().unwrap();
    assert_eq!(
        extras.len(),
        f.metadata().attributes.len(),
        "{name}: attributes"
    );
    for (k, (pa, info)) in extras.iter().zip(&f.metadata().attributes).enumerate() {
        assert_eq!(pa["name"].as_str(), Some(info.name.as_str()));
        let q = f.extra_values(k).unwrap();
        let pq: Vec<u16> = pa["q"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| u16::try_from(u64_of(v)).unwrap())
            .collect();
        assert_eq!(pq, q, "{name}: attribute {k}'s quantized values");
        let rust: Vec<f32> = q.iter().map(|&q| info.decode(q)).collect();
        assert_same_f32(
            &f32s(&pa["values"]),
            &rust,
            &format!("{name}: attribute {k}"),
        );
        let means = f.extra_node_means(k).unwrap();
        assert_same_f32(
            &f32s(&pa["node_means"]),
            means,
            &format!("{name}: means {k}"),
        );
    }
}

/// Converts a real LAMMPS sample (two species, a `c_pe` column) and a generated data set
/// (8-bit and 16-bit positions, δn > 1, one built in chunks) and checks that both readers
/// decode the same.
#[test]
fn python_reader_decodes_exactly_what_the_rust_reader_decodes() {
    let dir = tempfile::tempdir().unwrap();
    let d = |name: &str| dir.path().join(name);
    let sample = d("cuag.mdlod");
    mdlod(&[
        "convert",
        s(&lammps_sample_path("cuag_alloy.unwrapped.dump")),
        "-o",
        s(&sample),
        "--attribute",
        "c_pe",
        "--root-points",
        "64",
    ]);
    let dump = d("alloy.lammpstrj");
    mdlod(&["generate", "alloy", "-n", "3000", "-o", s(&dump)]);
    let u8_file = d("u8.mdlod");
    mdlod(&[
        "convert",
        s(&dump),
        "-o",
        s(&u8_file),
        "--precision",
        "u8",
        "--delta-n",
        "3",
        "--root-points",
        "16",
        "--attribute",
        "c_pe",
    ]);
    let u16_file = d("u16.mdlod");
    mdlod(&[
        "convert",
        s(&dump),
        "-o",
        s(&u16_file),
        "--delta-n",
        "2",
        "--root-points",
        "16",
        "--chunk-points",
        "1024",
    ]);
    // Particles of their own sizes (version 1.1's RADIUS): MegaMol's `xyzr` list.
    let sized = d("xyzr.mdlod");
    mdlod(&[
        "convert",
        s(&Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("datasets/megamol/test_xyzr_float_none.mmpld")),
        "-o",
        s(&sized),
    ]);
    assert!(MdlodFile::open(&sized).unwrap().radii().is_some());
    // Sizes spanning four decades (smoothing lengths): version 1.2's RADIUS_LOG.
    let xyz = d("sph.xyz");
    let mut text = String::from("512\nProperties=species:S:1:pos:R:3:radius:R:1\n");
    for i in 0..512 {
        let h = 1e-3 * 10f64.powf(4.0 * f64::from((i * 37) % 512) / 511.0);
        let (x, y, z) = (i % 8, i / 8 % 8, i / 64);
        text += &format!("gas {x} {y} {z} {h:.6e}\n");
    }
    std::fs::write(&xyz, text).unwrap();
    let logged = d("sph.mdlod");
    mdlod(&["convert", s(&xyz), "-o", s(&logged)]);
    let f = MdlodFile::open(&logged).unwrap();
    assert!(f.metadata().radius.is_some_and(|r| r.log));
    assert_eq!(f.header().version_minor, 2);
    // Several attributes (version 1.2's ATTRIBUTES and NODE_ATTRIBUTES).
    let several = d("several.mdlod");
    mdlod(&[
        "convert",
        s(&dump),
        "-o",
        s(&several),
        "--attribute",
        "c_pe",
        "--attribute",
        "x",
        "--attribute",
        "z",
    ]);
    assert_eq!(
        MdlodFile::open(&several).unwrap().attribute_names(),
        ["c_pe", "x", "z"]
    );
    for file in [&sample, &u8_file, &u16_file, &sized, &logged, &several] {
        assert_same_decoding(file);
    }
    let bits = |f: &Path| MdlodFile::open(f).unwrap().position_bits();
    assert_eq!((bits(&u8_file), bits(&u16_file)), (8, 16));
    assert!(MdlodFile::open(&u16_file).unwrap().level_count() > 3);
}

/// Corrupt copies: the Python reader exits with status 1 and a message naming the file
/// and the problem, without a traceback, and the Rust reader refuses them too.
#[test]
fn python_reader_refuses_corrupt_files_with_a_message() {
    let dir = tempfile::tempdir().unwrap();
    let dump = dir.path().join("d.lammpstrj");
    mdlod(&["generate", "crater", "-n", "1500", "-o", s(&dump)]);
    let file = dir.path().join("a.mdlod");
    mdlod(&["convert", s(&dump), "-o", s(&file), "--root-points", "16"]);
    let bytes = std::fs::read(&file).unwrap();
    let f = MdlodFile::open(&file).unwrap();
    let table = f.header().section_table_offset as usize;
    let nodes = f
        .sections()
        .iter()
        .find(|s| s.kind == SectionKind::Nodes as u32)
        .unwrap();
    let nodes_byte = (nodes.offset + nodes.length / 2) as usize;

    let flipped = |at: usize| {
        let mut b = bytes.clone();
        b[at] ^= 0x10;
        b
    };
    let cases: [(&str, Vec<u8>, &[&str]); 4] = [
        // file_size's low byte: the header checksum finds it first.
        ("header", flipped(32), &["header", "checksum"]),
        (
            "section table",
            flipped(table + 8),
            &["section table", "checksum"],
        ),
        ("nodes", flipped(nodes_byte), &["NODES", "checksum"]),
        (
            "truncated",
            bytes[..bytes.len() - 1].to_vec(),
            &["file_size", "truncated"],
        ),
    ];
    for (name, data, words) in cases {
        let bad: PathBuf = dir.path().join(format!("{}.mdlod", name.replace(' ', "_")));
        std::fs::write(&bad, data).unwrap();
        let out = read_mdlod(&[s(&bad)]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{name}: {err}");
        assert!(!err.contains("Traceback"), "{name}: {err}");
        assert!(err.starts_with(s(&bad)), "{name}: no file name in {err}");
        for w in words {
            assert!(err.contains(w), "{name}: {w:?} not in {err}");
        }
        assert!(
            MdlodFile::open(&bad).is_err(),
            "{name}: the Rust reader opens it"
        );
    }
}
