//! Out-of-core conversion from dumps read a window at a time: the file equals the one
//! built from the whole frame in memory with the same chunks, for raw arrays, real LAMMPS
//! binary and text dumps, `%` piece sets, GSD and XYZ files; a truncated text dump read in windows still names
//! the file and line.

use std::path::Path;

use mdlod_format::MdlodFile;
use mdlod_preprocess::chunked::ChunkOptions;
use mdlod_preprocess::convert::{
    convert_file, convert_frame, source_info, ConvertOptions, FrameSelect,
};
use mdlod_preprocess::hierarchy::BuildParams;
use mdlod_preprocess::readers::{DumpFile, ReadOptions};
use mdlod_preprocess::NoProgress;

fn options(chunk_points: usize) -> ConvertOptions {
    ConvertOptions {
        build: BuildParams {
            max_root_points: 64,
            ..Default::default()
        },
        radii: vec![("1".into(), 1.28)],
        chunks: ChunkOptions {
            chunk_points,
            memory_limit: 1 << 30,
            temp_dir: None,
            window_points: 128,
            gzip_in_memory: None,
        },
        // Some inputs here have no type 1.
        radii_may_be_absent: true,
        species_names: Vec::new(),
        attribute_log10: false,
        extra_log10: Vec::new(),
        species_column: None,
        input_options: Vec::new(),
    }
}

/// Converts `input` out of core (window by window) and from the whole frame in memory,
/// both in chunks of `chunk_points`, and checks the two files are identical. The first
/// has room to keep the chunks' results in memory until the assembly; the second's limit
/// is the least its chunks need, so they go through working files.
fn streamed_equals_in_memory(input: &Path, read: &ReadOptions, chunk_points: usize) -> MdlodFile {
    let dir = tempfile::tempdir().unwrap();
    let streamed = dir.path().join("streamed.mdlod");
    let mut opts = options(chunk_points);
    let dump = DumpFile::open(input).unwrap();
    assert!(dump.reads_parts() || dump.reads_text_windows() || dump.piece_paths().is_some());
    // Read a window at a time, not whole.
    let last = dump.frame_count() - 1;
    let info = dump.frame_info(last).unwrap();
    assert!(mdlod_preprocess::convert::window_source(&dump, last, read, &info).is_some());
    let k = dump.frame_count() - 1;
    let n = dump.frame_info(k).unwrap().particles;
    assert!(
        n > chunk_points,
        "{n} particles do not need chunks of {chunk_points}"
    );
    let frame = dump.read_frame(k, read, &NoProgress).unwrap();
    let further = mdlod_preprocess::convert::read_extra_attributes(&dump, k, read).unwrap();
    // The radius override of LAMMPS type 1, for the inputs that have it (an override
    // naming no species is an error).
    opts.radii
        .retain(|(name, _)| frame.species.iter().any(|s| &s.name == name));
    convert_file(
        input,
        &streamed,
        FrameSelect::Last,
        read,
        &opts,
        &NoProgress,
    )
    .unwrap();
    let whole = dir.path().join("whole.mdlod");
    let mut tight = opts.clone();
    tight.chunks.memory_limit =
        mdlod_preprocess::chunked::chunk_memory_with(chunk_points, further.len());
    // (`convert_file` records the species column of its read options; a frame read
    // here is converted with it given.)
    tight.species_column = read.species_column.clone();
    // (And its input as a batch fingerprints it: every piece, a sidecar and its arrays.)
    mdlod_preprocess::convert::convert_frame_with(
        &frame,
        &further,
        Some(mdlod_preprocess::batch::fingerprint(input, k as u64)),
        &whole,
        &tight,
        &NoProgress,
    )
    .unwrap();
    let (a, b) = (
        std::fs::read(&streamed).unwrap(),
        std::fs::read(&whole).unwrap(),
    );
    assert!(
        a == b,
        "{}: streamed and in-memory chunked files differ",
        input.display()
    );
    let f = MdlodFile::open(&streamed).unwrap();
    f.verify().unwrap();
    assert_eq!(f.particle_count() as usize, n);
    assert_eq!(f.metadata().build.chunk_points, Some(chunk_points as u64));
    // Only the two outputs remain: the working files are gone.
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 2);
    f
}

#[test]
fn lammps_binary_dump_streams_into_the_same_file() {
    let path = mdlod_datasets::lammps_sample_path("cu_melt.custom.bin");
    let read = ReadOptions {
        attribute: Some("c_pe".into()),
        ..Default::default()
    };
    let f = streamed_equals_in_memory(&path, &read, 300);
    assert!(f.metadata().attribute.is_some());
}

/// `n` pseudo-random positions from 0 to about 168 (xorshift from `seed`), as the
/// little-endian `f32` x y z a raw positions file holds.
fn raw_positions(n: usize, seed: u64) -> Vec<u8> {
    let mut s = seed;
    let mut pos = Vec::with_capacity(12 * n);
    for _ in 0..3 * n {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        pos.extend_from_slice(&((s >> 40) as f32 / 1e5).to_le_bytes());
    }
    pos
}

#[test]
fn raw_arrays_stream_into_the_same_file() {
    let dir = tempfile::tempdir().unwrap();
    let n = 5000usize;
    let pos = raw_positions(n, 0x2545F4914F6CDD1D);
    let species: Vec<u8> = (0..n).map(|i| (i % 3) as u8).collect();
    std::fs::write(dir.path().join("pos.f32"), &pos).unwrap();
    std::fs::write(dir.path().join("type.u8"), &species).unwrap();
    let sidecar = dir.path().join("frame.raw.json");
    std::fs::write(
        &sidecar,
        r#"{"mdlod_raw": 1, "positions": {"file": "pos.f32", "type": "f32"},
            "species": {"file": "type.u8", "type": "u8", "names": ["Cu", "Ag", "Ni"]}}"#,
    )
    .unwrap();
    let f = streamed_equals_in_memory(&sidecar, &ReadOptions::default(), 700);
    let names: Vec<&str> = f
        .metadata()
        .species
        .iter()
        .map(|s| s.name.as_str())
        .collect();
    assert_eq!(names, ["Cu", "Ag", "Ni"]);
}

/// Raw arrays with each particle's size: chunks keep every radius, as a whole build does.
#[test]
fn raw_arrays_with_sizes_stream_into_the_same_file() {
    let dir = tempfile::tempdir().unwrap();
    let n = 5000usize;
    let pos = raw_positions(n, 0x9E3779B97F4A7C15);
    let h: Vec<u8> = (0..n)
        .flat_map(|i| (0.5 + (i % 11) as f32 * 0.05).to_le_bytes())
        .collect();
    std::fs::write(dir.path().join("pos.f32"), &pos).unwrap();
    std::fs::write(dir.path().join("h.f32"), &h).unwrap();
    let sidecar = dir.path().join("frame.raw.json");
    std::fs::write(
        &sidecar,
        r#"{"mdlod_raw": 1, "positions": {"file": "pos.f32", "type": "f32"},
            "radius": {"file": "h.f32", "type": "f32", "name": "h"}}"#,
    )
    .unwrap();
    let f = streamed_equals_in_memory(&sidecar, &ReadOptions::default(), 700);
    let radii = f.radii().expect("per-particle radii");
    assert_eq!(radii.len(), n);
}

/// Smoothing lengths spanning five decades (an SPH run's dense core and its halo) are
/// kept on a log scale (RADIUS_LOG, format 1.2): every particle within 1.1·10⁻⁴ of its
/// own size, whole or in chunks (16-bit linear steps drew the smallest at a tenth of
/// theirs, or several times).
#[test]
fn smoothing_lengths_spanning_decades_keep_their_sizes_on_a_log_scale() {
    let dir = tempfile::tempdir().unwrap();
    let n = 5000usize;
    let pos = raw_positions(n, 0x51_7CC1_B727_220A);
    let h: Vec<f32> = (0..n)
        .map(|i| 1e-3 * 10f32.powf(5.0 * ((i * 7919) % n) as f32 / (n - 1) as f32))
        .collect();
    std::fs::write(dir.path().join("pos.f32"), &pos).unwrap();
    let bytes: Vec<u8> = h.iter().flat_map(|v| v.to_le_bytes()).collect();
    std::fs::write(dir.path().join("h.f32"), bytes).unwrap();
    let sidecar = dir.path().join("frame.raw.json");
    std::fs::write(
        &sidecar,
        r#"{"mdlod_raw": 1, "positions": {"file": "pos.f32", "type": "f32"},
            "radius": {"file": "h.f32", "type": "f32", "name": "h"}}"#,
    )
    .unwrap();
    let f = streamed_equals_in_memory(&sidecar, &ReadOptions::default(), 700);
    assert_eq!(
        (f.header().version_major, f.header().version_minor),
        mdlod_format::FORMAT_VERSION_1_2
    );
    let info = f.metadata().radius.expect("per-particle radii");
    assert!(info.log, "{info:?}");
    assert_eq!(
        [info.min, info.max],
        [1e-3, h.iter().copied().fold(0.0, f32::max)]
    );
    // Particles are in hierarchy order: each decoded radius is some particle's own, and
    // sorted they match the input's one for one.
    let mut decoded: Vec<f32> = f.radii().unwrap().iter().map(|&q| info.decode(q)).collect();
    let mut input = h.clone();
    decoded.sort_by(f32::total_cmp);
    input.sort_by(f32::total_cmp);
    let worst = decoded
        .iter()
        .zip(&input)
        .map(|(d, r)| f64::from((d - r).abs() / r))
        .fold(0.0, f64::max);
    assert!(worst <= 1.1e-4, "{worst}");
    assert!(info.worst_relative_error() < 1.1e-4);
    // Renders decode through a table: the same radii.
    for q in (0..=u16::MAX).step_by(97).chain([u16::MAX]) {
        assert_eq!(f.radius_of(q), info.decode(q), "{q}");
    }
    // The metadata's JSON names the scale by its field, which a reader of version 1.1
    // does not know (it skips the RADIUS_LOG section and draws the species' mean).
    let json = f.metadata().to_json().unwrap();
    let v: serde_json::Value = serde_json::from_slice(&json).unwrap();
    assert!(
        v.get("radius").is_none() && v["radius_log"]["min"].as_f64().is_some(),
        "{v}"
    );
}

#[test]
fn lammps_text_dump_streams_into_the_same_file() {
    let path = mdlod_datasets::lammps_sample_path("cu_melt.custom.dump");
    let read = ReadOptions {
        attribute: Some("c_pe".into()),
        ..Default::default()
    };
    streamed_equals_in_memory(&path, &read, 300);
}

/// A binary dump's further attributes (format 1.2's ATTRIBUTES) stream in chunks as the
/// first does: each read by a pass of its own, in step with the particles' windows.
#[test]
fn lammps_binary_dump_streams_further_attributes_into_the_same_file() {
    let path = mdlod_datasets::lammps_sample_path("cu_melt.custom.bin");
    let read = ReadOptions {
        attribute: Some("c_pe".into()),
        extra_attributes: vec!["id".into(), "x".into()],
        ..Default::default()
    };
    let f = streamed_equals_in_memory(&path, &read, 300);
    assert_eq!(f.attribute_names(), ["c_pe", "id", "x"]);
    assert_eq!(f.header().version_minor, 2);
    let ids = f.metadata().attributes[0].clone();
    assert_eq!((ids.min, ids.max), (1.0, 500.0));
}

/// `n` particles of a LAMMPS text dump with columns `c_pe`, `c_ke` and `copy` (the
/// `c_pe` column again), in a box of 40.
fn dump_with_columns(n: usize) -> String {
    let mut text = format!(
        "ITEM: TIMESTEP\n7\nITEM: NUMBER OF ATOMS\n{n}\nITEM: BOX BOUNDS pp pp pp\n0 40\n0 40\n\
         0 40\nITEM: ATOMS id type x y z c_pe c_ke copy\n"
    );
    let pos = raw_positions(n, 0x5DEECE66D);
    let at = |i: usize| f32::from_le_bytes(pos[4 * i..4 * i + 4].try_into().unwrap()) / 4.3;
    for i in 0..n {
        let (x, y, z) = (at(3 * i), at(3 * i + 1), at(3 * i + 2));
        let pe = -3.5 + (0.3 * x).sin() + 0.01 * z;
        let ke = (i % 97) as f32 * 0.01 + 0.001 * y;
        text += &format!("{} {} {x} {y} {z} {pe} {ke} {pe}\n", i + 1, 1 + i % 2);
    }
    text
}

/// Further attributes of a frame built in chunks: the same file streamed from a text dump
/// and from the frame in memory; a copy of the first keeps its values and, node by node
/// (the top node and the padding copies of chunk roots among them), its means to
/// rounding; a column of its own has the range, the values and the top node's mean of
/// the same frame built whole.
#[test]
fn further_attributes_stream_in_chunks_as_a_frame_built_whole_keeps_them() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("columns.lammpstrj");
    std::fs::write(&input, dump_with_columns(5000)).unwrap();
    let read = ReadOptions {
        attribute: Some("c_pe".into()),
        extra_attributes: vec!["c_ke".into(), "copy".into()],
        ..Default::default()
    };
    streamed_equals_in_memory(&input, &read, 700);
    // (The helper's files are gone with its directory: the streamed file again, here.)
    let chunked = dir.path().join("chunked.mdlod");
    convert_file(
        &input,
        &chunked,
        FrameSelect::Last,
        &read,
        &options(700),
        &NoProgress,
    )
    .unwrap();
    let f = MdlodFile::open(&chunked).unwrap();
    assert_eq!(f.metadata().build.chunk_points, Some(700));
    assert_eq!(f.attribute_names(), ["c_pe", "c_ke", "copy"]);
    let first = f.attribute().unwrap().to_vec();
    let nodes = f.nodes().to_vec();
    let copy = MdlodFile::open(&chunked)
        .unwrap()
        .select_attribute("copy")
        .unwrap();
    assert_eq!(copy.attribute().unwrap(), &first[..]);
    assert_eq!(copy.nodes().len(), nodes.len());
    for (i, (a, b)) in nodes.iter().zip(copy.nodes()).enumerate() {
        let tol = 1e-5 * (1.0 + a.attribute.abs());
        assert!(
            (a.attribute - b.attribute).abs() <= tol,
            "node {i} (level {}): {} against {}",
            a.level,
            a.attribute,
            b.attribute
        );
    }
    // The same frame built whole.
    let whole = dir.path().join("whole.mdlod");
    convert_file(
        &input,
        &whole,
        FrameSelect::Last,
        &read,
        &options(1 << 20),
        &NoProgress,
    )
    .unwrap();
    let w = MdlodFile::open(&whole).unwrap();
    assert_eq!(w.metadata().build.chunk_points, None);
    assert_eq!(w.metadata().attributes, f.metadata().attributes);
    let (wk, fk) = (
        w.select_attribute("c_ke").unwrap(),
        MdlodFile::open(&chunked)
            .unwrap()
            .select_attribute("c_ke")
            .unwrap(),
    );
    let sorted = |m: &MdlodFile| {
        let mut v = m.attribute().unwrap().to_vec();
        v.sort_unstable();
        v
    };
    assert_eq!(sorted(&wk), sorted(&fk));
    let (a, b) = (wk.nodes()[0].attribute, fk.nodes()[0].attribute);
    assert!(
        (a - b).abs() <= 1e-6 * a.abs(),
        "top node: {a} whole, {b} in chunks"
    );
}

/// A bead-spring dump in LJ units: molecule ids kept as a further attribute get no
/// advice to take their logarithm (ids within 16 bits are kept exactly), built whole
/// or in chunks; bead types renamed to names that are element symbols are noted as read
/// with ångström radii, unless --radius gives their size; the note of species drawn at
/// the default radius lists a few of thousands.
#[test]
fn bead_names_and_molecule_ids_in_lj_units_are_noted_as_such() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("melt.lammpstrj");
    let n = 3000;
    let mut text = format!(
        "ITEM: UNITS\nlj\nITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n{n}\nITEM: BOX BOUNDS pp pp \
         pp\n0 20\n0 20\n0 20\nITEM: ATOMS id mol type x y z c_pe\n"
    );
    for i in 0..n {
        // Molecules of 50 beads, the last one numbered far up (ids need not be dense).
        let mol = if i >= n - 50 { 40_000 } else { 1 + i / 50 };
        text += &format!(
            "{} {mol} {} {} {} {} {}\n",
            i + 1,
            1 + i % 3,
            (i % 20) as f32 + 0.5,
            ((i / 20) % 20) as f32 + 0.5,
            (i / 400) as f32 * 2.5 + 0.5,
            -4.0 + (i % 7) as f32 * 0.1
        );
    }
    std::fs::write(&input, text).unwrap();
    let read = ReadOptions {
        attribute: Some("c_pe".into()),
        extra_attributes: vec!["mol".into()],
        ..Default::default()
    };
    let mut opts = options(1 << 20);
    opts.radii.clear();
    opts.species_names = vec![("1".into(), "P".into()), ("2".into(), "H".into())];
    for chunk_points in [1 << 20, 700] {
        opts.chunks.chunk_points = chunk_points;
        let out = dir.path().join(format!("melt-{chunk_points}.mdlod"));
        let r = convert_file(&input, &out, FrameSelect::Last, &read, &opts, &NoProgress).unwrap();
        let said = r.notes.join("\n");
        assert!(
            !said.contains("attribute mol spans"),
            "{chunk_points}: {said}"
        );
        assert!(
            said.contains("species P (1.1), H (0.46): read as chemical elements")
                && said.contains("units are lj"),
            "{chunk_points}: {said}"
        );
    }
    // Sized by --radius: nothing to say.
    opts.radii = vec![("P".into(), 0.5), ("H".into(), 0.5)];
    let r = convert_file(
        &input,
        &dir.path().join("sized.mdlod"),
        FrameSelect::Last,
        &read,
        &opts,
        &NoProgress,
    )
    .unwrap();
    assert!(
        !r.notes
            .iter()
            .any(|n| n.contains("read as chemical elements")),
        "{:?}",
        r.notes
    );
    // Molecules as species: thousands drawn at the default radius, a few named.
    let by_mol = ReadOptions {
        species_column: Some("mol".into()),
        ..Default::default()
    };
    let mut opts = options(1 << 20);
    opts.radii.clear();
    let r = convert_file(
        &input,
        &dir.path().join("mol.mdlod"),
        FrameSelect::Last,
        &by_mol,
        &opts,
        &NoProgress,
    )
    .unwrap();
    let note = r
        .notes
        .iter()
        .find(|n| n.contains("the default: no size was read"))
        .expect("a default radius note");
    assert!(note.contains("(60 in all)") && note.len() < 400, "{note}");
}

/// A further attribute the dump lacks, or a vector for a magnitude, named before anything
/// is read; one named as the first: refused; a damaged value that only a further
/// attribute's pass reads, windows in: that pass's error, naming the line, not a wait
/// on a pass that stopped.
#[test]
fn a_missing_further_attribute_read_in_chunks_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("columns.lammpstrj");
    let text = dump_with_columns(3000);
    std::fs::write(&input, &text).unwrap();
    // The same with a damaged c_ke value far into the atoms (line 9 + 2500): only the
    // pass that reads c_ke meets it, windows after the particles' pass began.
    let damaged = dir.path().join("damaged.lammpstrj");
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    let mut fields: Vec<String> = lines[9 + 2500].split(' ').map(str::to_string).collect();
    fields[6] = "0.3x".into();
    lines[9 + 2500] = fields.join(" ");
    std::fs::write(&damaged, lines.join("\n") + "\n").unwrap();
    let out = dir.path().join("out.mdlod");
    for (input, extras, want) in [
        (&input, vec!["c_ke", "v_missing"], "v_missing"),
        (&input, vec!["c_pe"], "attribute c_pe is given twice"),
        (&input, vec!["|fx|"], "no vector `fx`"),
        (&damaged, vec!["copy", "c_ke"], "damaged.lammpstrj:2510"),
    ] {
        let read = ReadOptions {
            attribute: Some("c_pe".into()),
            extra_attributes: extras.iter().map(|s| s.to_string()).collect(),
            ..Default::default()
        };
        let e = convert_file(
            input,
            &out,
            FrameSelect::Last,
            &read,
            &options(700),
            &NoProgress,
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains(want), "{extras:?}: {e}");
        assert!(!out.exists());
    }
    // Only the inputs remain: the working files are gone.
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 2);
}

#[test]
fn xyz_file_streams_into_the_same_file() {
    let path = mdlod_datasets::lammps_sample_path("cu_melt.xyz");
    streamed_equals_in_memory(&path, &ReadOptions::default(), 300);
}

/// Numbered species from 0, the 0 only in later windows: the whole frame gives no
/// species a palette slot by number (a 0 is no LAMMPS type), and neither may the merge
/// of windows whose own numbers all start at 1.
#[test]
fn numbers_from_zero_in_later_windows_colour_as_the_whole_frame() {
    let dir = tempfile::tempdir().unwrap();
    let n = 1000;
    let mut text = format!("{n}\nnumbered\n");
    for i in 0..n {
        let name = match i {
            _ if i >= 600 && i % 3 == 0 => "0",
            _ if i % 2 == 0 => "2",
            _ => "1",
        };
        let (x, y, z) = (i % 10, (i / 10) % 10, i / 100);
        text.push_str(&format!("{name} {x}.25 {y}.5 {z}.75\n"));
    }
    let path = dir.path().join("numbered.xyz");
    std::fs::write(&path, text).unwrap();
    let f = streamed_equals_in_memory(&path, &ReadOptions::default(), 300);
    let colours: Vec<[f32; 3]> = f.metadata().species.iter().map(|s| s.colour).collect();
    let frame = DumpFile::open(&path)
        .unwrap()
        .read_frame(0, &ReadOptions::default(), &NoProgress)
        .unwrap();
    let whole: Vec<[f32; 3]> = mdlod_preprocess::species::species_table(&frame.species, &[])
        .iter()
        .map(|s| s.colour)
        .collect();
    assert_eq!(colours, whole);
    assert_eq!(colours.len(), 3);
    assert!(colours[0] != colours[1] && colours[1] != colours[2]);
}

/// Species that are type numbers in the first windows and a name later: the whole-frame
/// reader lists them in order of first appearance (not all are numbers), and so must the
/// merge of the windows' lists, each of which the window's reader sorted numerically.
#[test]
fn mixed_numeric_and_named_species_keep_the_whole_frame_order_in_windows() {
    let dir = tempfile::tempdir().unwrap();
    let n = 1000;
    let mut text = format!("{n}\nmixed species\n");
    for i in 0..n {
        // Type 2 before type 1 in every window; oxygen only from the fourth window on.
        let name = match i {
            _ if i >= 600 && i % 3 == 0 => "O",
            _ if i % 2 == 0 => "2",
            _ => "1",
        };
        let (x, y, z) = (i % 10, (i / 10) % 10, i / 100);
        text.push_str(&format!("{name} {x}.25 {y}.5 {z}.75\n"));
    }
    let path = dir.path().join("mixed.xyz");
    std::fs::write(&path, text).unwrap();
    let f = streamed_equals_in_memory(&path, &ReadOptions::default(), 300);
    let names: Vec<&str> = f
        .metadata()
        .species
        .iter()
        .map(|s| s.name.as_str())
        .collect();
    assert_eq!(names, ["2", "1", "O"]);
}

/// `--species-name` renames and merges species the same way whether the frame is built
/// whole, in chunks from memory, or in chunks read a window at a time: types 1 and 3
/// become one species `Cu` with copper's looks, type 2 `Ag`.
#[test]
fn renamed_and_merged_species_are_the_same_whole_chunked_and_streamed() {
    let dir = tempfile::tempdir().unwrap();
    let n = 1000;
    let mut text = format!(
        "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n{n}\nITEM: BOX BOUNDS pp pp pp\n0 10\n0 10\n\
         0 10\nITEM: ATOMS id type x y z\n"
    );
    let mut types = Vec::new();
    for i in 0..n {
        // Type 3 only from the second window on, type 2 before type 1 in each.
        let t = if i >= 400 && i % 5 == 0 { 3 } else { 2 - i % 2 };
        types.push(t);
        let (x, y, z) = (i % 10, (i / 10) % 10, i / 100);
        text.push_str(&format!("{} {t} {x}.25 {y}.5 {z}.75\n", i + 1));
    }
    let path = dir.path().join("alloy.lammpstrj");
    std::fs::write(&path, text).unwrap();
    let mut opts = options(300);
    opts.radii = vec![("Ag".into(), 1.6)];
    opts.radii_may_be_absent = false;
    opts.species_names = vec![
        ("1".into(), "Cu".into()),
        ("3".into(), "Cu".into()),
        ("2".into(), "Ag".into()),
    ];
    let read = ReadOptions::default();
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
    let dump = DumpFile::open(&path).unwrap();
    let frame = dump.read_frame(0, &read, &NoProgress).unwrap();
    let chunked = dir.path().join("chunked.mdlod");
    let source = || Some(source_info(&path, 0));
    convert_frame(&frame, source(), &chunked, &opts, &NoProgress).unwrap();
    assert!(
        std::fs::read(&streamed).unwrap() == std::fs::read(&chunked).unwrap(),
        "streamed and in-memory chunked files differ"
    );
    let mut whole_opts = opts.clone();
    whole_opts.chunks.chunk_points = 1 << 20;
    let whole = dir.path().join("whole.mdlod");
    convert_frame(&frame, source(), &whole, &whole_opts, &NoProgress).unwrap();
    let cu = mdlod_preprocess::species::element("Cu").unwrap();
    let want_cu = types.iter().filter(|&&t| t != 2).count();
    for p in [&streamed, &whole] {
        let f = MdlodFile::open(p).unwrap();
        f.verify().unwrap();
        let species = &f.metadata().species;
        let names: Vec<&str> = species.iter().map(|s| s.name.as_str()).collect();
        assert_eq!(names, ["Cu", "Ag"], "{}", p.display());
        assert_eq!((species[0].radius, species[0].colour), cu);
        assert_eq!(species[1].radius, 1.6);
        let copper = f.species().iter().filter(|&&s| s == 0).count();
        assert_eq!(copper, want_cu, "{}", p.display());
        assert_eq!(f.species().len(), n);
    }
    // A name the input lacks is an error that lists its species.
    let mut bad = whole_opts.clone();
    bad.species_names.push(("4".into(), "O".into()));
    let e = convert_file(&path, &whole, FrameSelect::Last, &read, &bad, &NoProgress)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("alloy.lammpstrj: --species-name 4=O: no species named \"4\"")
            && e.contains("named 1, 2, 3"),
        "{e}"
    );
}

#[test]
fn a_truncated_text_dump_read_in_windows_names_the_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    let text =
        std::fs::read_to_string(mdlod_datasets::lammps_sample_path("cu_melt.custom.dump")).unwrap();
    // The first frame, cut 100 atoms short of the 500 its header announces.
    let lines: Vec<&str> = text.lines().collect();
    let atoms_at = lines
        .iter()
        .position(|l| l.starts_with("ITEM: ATOMS"))
        .unwrap()
        + 1;
    let cut = lines[..atoms_at + 400].join("\n") + "\n";
    let path = dir.path().join("cut.lammpstrj");
    std::fs::write(&path, cut).unwrap();
    let out = dir.path().join("cut.mdlod");
    let err = convert_file(
        &path,
        &out,
        FrameSelect::Last,
        &ReadOptions::default(),
        &options(300),
        &NoProgress,
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("cut.lammpstrj"), "{err}");
    assert!(err.contains("line"), "{err}");
    // The frame's counts, not those of the window that found the end.
    assert!(
        err.contains("the header announces 500 atoms but only 400 atom lines follow"),
        "{err}"
    );
    assert!(!out.exists());
    assert_eq!(
        std::fs::read_dir(dir.path()).unwrap().count(),
        1,
        "working files left"
    );
}

/// The data location of chunk `name` of frame `frame` in a GSD file's bytes.
fn gsd_chunk(bytes: &[u8], name: &str, frame: u64) -> usize {
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

#[test]
fn gsd_streams_into_the_same_file() {
    // Frame 2 stores only positions, charges and the step: the rest comes from frame 0.
    // Diameters made to differ along the file (each type's first 40 particles twice as
    // wide): a part alone would give its types other radii than the whole frame's.
    let mut bytes = std::fs::read(mdlod_datasets::gsd_sample_path("hoomd_mixture.gsd")).unwrap();
    let (types, diameters) = (
        gsd_chunk(&bytes, "particles/typeid", 0),
        gsd_chunk(&bytes, "particles/diameter", 0),
    );
    let mut seen = [0; 2];
    for i in 0..300 {
        let t = u32::from_le_bytes(bytes[types + 4 * i..types + 4 * i + 4].try_into().unwrap());
        seen[t as usize] += 1;
        let d = if t == 0 { 1.0f32 } else { 1.5 };
        let d = if seen[t as usize] <= 40 { 2.0 * d } else { d };
        bytes[diameters + 4 * i..diameters + 4 * i + 4].copy_from_slice(&d.to_le_bytes());
    }
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("mixture.gsd");
    std::fs::write(&path, &bytes).unwrap();
    let read = ReadOptions {
        attribute: Some("charge".into()),
        ..Default::default()
    };
    let f = streamed_equals_in_memory(&path, &read, 100);
    let radii: Vec<(&str, f32)> = f
        .metadata()
        .species
        .iter()
        .map(|s| (s.name.as_str(), s.radius))
        .collect();
    let mean = |t: usize, d: f32| 0.5 * d * (2.0 * 40.0 + (seen[t] as f32 - 40.0)) / seen[t] as f32;
    let expected = [("A", mean(0, 1.0)), ("B", mean(1, 1.5))];
    for ((name, r), (en, er)) in radii.iter().zip(expected) {
        assert!(
            *name == en && (r - er).abs() < 1e-5,
            "{radii:?} against {expected:?}"
        );
    }
    assert!(f.metadata().attribute.is_some());
}

#[test]
fn piece_sets_stream_piece_by_piece_into_the_same_file() {
    // LAMMPS `dump ... %` output of a 2-process run, as text and as binary pieces.
    for name in ["cu_melt_mpi.%.dump", "cu_melt_mpi.%.bin"] {
        let pattern = mdlod_datasets::lammps_sample_path(name);
        let dump = DumpFile::open(&pattern).unwrap();
        assert_eq!(dump.piece_paths().map(|p| p.len()), Some(2), "{name}");
        let n = dump.frame_info(dump.frame_count() - 1).unwrap().particles;
        // Chunks (and windows of 128) smaller than one piece.
        streamed_equals_in_memory(&pattern, &ReadOptions::default(), n / 3);
    }
}

#[test]
fn a_large_gzip_dump_is_decompressed_into_a_working_file_and_read_in_windows() {
    let gz = mdlod_datasets::lammps_sample_path("cu_melt.custom.dump.gz");
    let read = ReadOptions {
        attribute: Some("c_ke".into()),
        ..Default::default()
    };
    let dir = tempfile::tempdir().unwrap();
    let work = dir.path().join("work");
    std::fs::create_dir(&work).unwrap();
    let mut opts = options(300);
    opts.chunks.temp_dir = Some(work.clone());
    let in_memory = dir.path().join("a.mdlod");
    convert_file(
        &gz,
        &in_memory,
        FrameSelect::Last,
        &read,
        &opts,
        &NoProgress,
    )
    .unwrap();
    // Every gzip input counts as large: decompressed into a working file, read from it a
    // window at a time, into the same file.
    opts.chunks.gzip_in_memory = Some(0);
    let spooled = dir.path().join("b.mdlod");
    convert_file(&gz, &spooled, FrameSelect::Last, &read, &opts, &NoProgress).unwrap();
    assert!(std::fs::read(&in_memory).unwrap() == std::fs::read(&spooled).unwrap());
    assert_eq!(
        std::fs::read_dir(&work).unwrap().count(),
        0,
        "working files left"
    );

    // A damaged frame: the error names the input, the decompressed text and its line.
    let mut text = Vec::new();
    std::io::Read::read_to_end(
        &mut flate2::read::MultiGzDecoder::new(std::fs::File::open(&gz).unwrap()),
        &mut text,
    )
    .unwrap();
    text.truncate(text.len() - 200);
    let bad = dir.path().join("bad.dump.gz");
    let mut enc = flate2::write::GzEncoder::new(
        std::fs::File::create(&bad).unwrap(),
        flate2::Compression::fast(),
    );
    std::io::Write::write_all(&mut enc, &text).unwrap();
    enc.finish().unwrap();
    let err = convert_file(
        &bad,
        &dir.path().join("c.mdlod"),
        FrameSelect::Last,
        &read,
        &opts,
        &NoProgress,
    )
    .unwrap_err();
    // No source either, whose message (printed after it by the binary) named the working
    // copy's path.
    let mut chain = vec![err.to_string()];
    let mut cause = std::error::Error::source(&err);
    while let Some(c) = cause {
        chain.push(c.to_string());
        cause = c.source();
    }
    assert!(
        !chain.iter().any(|m| m.contains(".mdlod-convert")),
        "{chain:?}"
    );
    let e = err.to_string();
    // The place as a line of the input's text, not of its working copy, gone by now.
    assert!(
        e.starts_with(&format!("{}: line ", bad.display()))
            && e.contains(" of its decompressed text: "),
        "{e}"
    );
    assert!(
        !e.contains("bad.dump:") && !e.contains(".mdlod-convert"),
        "{e}"
    );
    assert_eq!(
        std::fs::read_dir(&work).unwrap().count(),
        0,
        "working files left"
    );

    // Notes about the text name the input, not its working copy: a last line without a
    // line end.
    let mut text = Vec::new();
    std::io::Read::read_to_end(
        &mut flate2::read::MultiGzDecoder::new(std::fs::File::open(&gz).unwrap()),
        &mut text,
    )
    .unwrap();
    while text.last() == Some(&b'\n') {
        text.pop();
    }
    let open = dir.path().join("open.dump.gz");
    let mut enc = flate2::write::GzEncoder::new(
        std::fs::File::create(&open).unwrap(),
        flate2::Compression::fast(),
    );
    std::io::Write::write_all(&mut enc, &text).unwrap();
    enc.finish().unwrap();
    let r = convert_file(
        &open,
        &dir.path().join("d.mdlod"),
        FrameSelect::Last,
        &read,
        &opts,
        &NoProgress,
    )
    .unwrap();
    let note = r
        .notes
        .iter()
        .find(|n| n.contains("its last line has no line end"))
        .expect("the note on the last line");
    assert!(note.starts_with(&open.display().to_string()), "{note}");
}

/// The first frame of the sample text dump (500 atoms) as lines, and the index of its
/// first atom line.
fn first_frame_lines() -> (Vec<String>, usize) {
    let text =
        std::fs::read_to_string(mdlod_datasets::lammps_sample_path("cu_melt.custom.dump")).unwrap();
    let lines: Vec<String> = text.lines().map(String::from).collect();
    let atoms_at = lines
        .iter()
        .position(|l| l.starts_with("ITEM: ATOMS"))
        .unwrap()
        + 1;
    (lines[..atoms_at + 500].to_vec(), atoms_at)
}

#[test]
fn an_extra_atom_line_read_in_windows_is_the_error_whole_frame_reading_gives() {
    let dir = tempfile::tempdir().unwrap();
    let (mut lines, atoms_at) = first_frame_lines();
    // One atom line more than the 500 announced, then blank space (which is allowed).
    lines.push(lines[atoms_at].clone());
    let path = dir.path().join("extra.lammpstrj");
    std::fs::write(&path, lines.join("\n") + "\n\n  \n").unwrap();
    let whole = DumpFile::open(&path)
        .unwrap()
        .read_frame(0, &ReadOptions::default(), &NoProgress)
        .unwrap_err()
        .to_string();
    assert_eq!(
        whole,
        format!(
            "{}:{}: more atom lines than the 500 the header announces",
            path.display(),
            atoms_at + 501
        )
    );
    let out = dir.path().join("extra.mdlod");
    // Windows of 128 lines, chunks of 300: the frame is read in windows.
    let err = convert_file(
        &path,
        &out,
        FrameSelect::Last,
        &ReadOptions::default(),
        &options(300),
        &NoProgress,
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains(&whole), "{err}");
    assert!(!out.exists());

    // Without the extra line, blank space after the atoms converts.
    lines.pop();
    std::fs::write(&path, lines.join("\n") + "\n\n  \n").unwrap();
    convert_file(
        &path,
        &out,
        FrameSelect::Last,
        &ReadOptions::default(),
        &options(300),
        &NoProgress,
    )
    .unwrap();
}

#[test]
fn a_text_dump_that_shrinks_between_windows_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let (lines, atoms_at) = first_frame_lines();
    let path = dir.path().join("shrinks.lammpstrj");
    std::fs::write(&path, lines.join("\n") + "\n").unwrap();
    let dump = DumpFile::open(&path).unwrap();
    let read = ReadOptions::default();
    let info = dump.frame_info(0).unwrap();
    let source = mdlod_preprocess::convert::window_source(&dump, 0, &read, &info).unwrap();
    drop(dump);
    // After the first window, the file is cut inside the atoms of that window.
    let cut = lines[..atoms_at + 10].join("\n").len() as u64;
    let mut windows = 0;
    let e = source
        .windows(128, &mut |first, part| {
            assert_eq!((first, part.len()), (0, 128));
            windows += 1;
            std::fs::OpenOptions::new()
                .write(true)
                .open(&path)
                .unwrap()
                .set_len(cut)
                .unwrap();
            Ok(())
        })
        .unwrap_err()
        .to_string();
    assert_eq!(windows, 1);
    assert!(
        e.starts_with(&path.display().to_string())
            && e.contains(&format!(
                "the file changed size while frame 0 was being read ({cut} bytes now)"
            )),
        "{e}"
    );
}

/// A dump a running simulation appends to while a large frame is read in windows: the
/// frame reads whole (what is appended lies past it).
#[test]
fn a_text_dump_appended_to_between_windows_reads_its_frame() {
    let dir = tempfile::tempdir().unwrap();
    let (lines, _) = first_frame_lines();
    let path = dir.path().join("grows.lammpstrj");
    let text = lines.join("\n") + "\n";
    std::fs::write(&path, &text).unwrap();
    let dump = DumpFile::open(&path).unwrap();
    let read = ReadOptions::default();
    let info = dump.frame_info(0).unwrap();
    let whole = dump.read_frame(0, &read, &NoProgress).unwrap();
    let source = mdlod_preprocess::convert::window_source(&dump, 0, &read, &info).unwrap();
    drop(dump);
    let mut positions = Vec::new();
    source
        .windows(128, &mut |first, part| {
            assert_eq!(first, positions.len());
            positions.extend_from_slice(&part.positions);
            // The next frame arrives.
            use std::io::Write;
            let mut f = std::fs::OpenOptions::new()
                .append(true)
                .open(&path)
                .unwrap();
            f.write_all(text.as_bytes()).unwrap();
            Ok(())
        })
        .unwrap();
    assert!(
        positions == whole.positions,
        "the frame read in windows differs"
    );
}

/// A one-frame LAMMPS text dump of atoms `ids` on a lattice, with a constant column: text
/// that compresses far better than 4 to 1.
fn lattice_dump(ids: std::ops::Range<usize>, total: usize) -> String {
    let mut s = format!(
        "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n{}\nITEM: BOX BOUNDS pp pp pp\n0 20\n0 20\n\
         0 {}\nITEM: ATOMS id type x y z q\n",
        ids.len(),
        total / 400 + 1
    );
    for i in ids {
        s += &format!(
            "{} {} {}.5 {}.5 {}.5 0.000000000000\n",
            i + 1,
            1 + i % 2,
            i % 20,
            (i / 20) % 20,
            i / 400
        );
    }
    s
}

fn gzip(path: &Path, text: &str) -> u64 {
    let mut enc = flate2::write::GzEncoder::new(
        std::fs::File::create(path).unwrap(),
        flate2::Compression::best(),
    );
    std::io::Write::write_all(&mut enc, text.as_bytes()).unwrap();
    enc.finish().unwrap();
    std::fs::metadata(path).unwrap().len()
}

#[test]
fn a_small_gzip_dump_of_much_text_is_decompressed_into_a_working_file() {
    use mdlod_preprocess::convert::open_bounded;
    let dir = tempfile::tempdir().unwrap();
    let work = dir.path().join("work");
    std::fs::create_dir(&work).unwrap();
    let text = lattice_dump(0..6000, 6000);
    let gz = dir.path().join("lattice.dump.gz");
    let compressed = gzip(&gz, &text);
    assert!(
        text.len() as u64 > 8 * compressed,
        "{} / {compressed}",
        text.len()
    );
    let mut opts = options(1000);
    opts.chunks.temp_dir = Some(work.clone());
    let out = dir.path().join("out.mdlod");
    // Within both limits: in memory.
    let b = open_bounded(&gz, &opts.chunks, &out, &NoProgress).unwrap();
    assert!(b.text.is_none() && b.dump.is_compressed());
    drop(b);
    // Under the limit of compressed bytes, but more than 4 times that of text: not held
    // in memory (a 1000:1 file expanded past any memory), decompressed into a file.
    opts.chunks.gzip_in_memory = Some(compressed);
    assert!(opts.chunks.gzip_text_in_memory_max() < text.len() as u64);
    let b = open_bounded(&gz, &opts.chunks, &out, &NoProgress).unwrap();
    let spooled = b.text.clone().unwrap();
    assert!(spooled.starts_with(&work) && spooled.ends_with("lattice.dump"));
    assert!(!b.dump.is_compressed());
    assert_eq!(b.dump.frame_info(0).unwrap().particles, 6000);
    assert_eq!(std::fs::read(&spooled).unwrap(), text.as_bytes());
    drop(b);
    assert_eq!(
        std::fs::read_dir(&work).unwrap().count(),
        0,
        "working files left"
    );
    // And it converts as from memory.
    let read = ReadOptions::default();
    convert_file(&gz, &out, FrameSelect::Last, &read, &opts, &NoProgress).unwrap();
    opts.chunks.gzip_in_memory = None;
    let in_memory = dir.path().join("in_memory.mdlod");
    convert_file(
        &gz,
        &in_memory,
        FrameSelect::Last,
        &read,
        &opts,
        &NoProgress,
    )
    .unwrap();
    assert!(std::fs::read(&out).unwrap() == std::fs::read(&in_memory).unwrap());
}

#[test]
fn gzip_pieces_are_opened_within_the_memory_limit_piece_by_piece() {
    use mdlod_preprocess::convert::open_bounded;
    let dir = tempfile::tempdir().unwrap();
    let work = dir.path().join("work");
    std::fs::create_dir(&work).unwrap();
    let (t0, t1) = (lattice_dump(0..3000, 5500), lattice_dump(3000..5500, 5500));
    let p0 = dir.path().join("run.0.dump.gz");
    gzip(&p0, &t0);
    gzip(&dir.path().join("run.1.dump.gz"), &t1);
    let pattern = dir.path().join("run.%.dump.gz");
    let mut opts = options(1000);
    opts.chunks.temp_dir = Some(work.clone());
    let out = dir.path().join("out.mdlod");
    let (t0, t1) = (t0.len() as u64, t1.len() as u64);

    // The readers' limit holds for the text of all the pieces together.
    use mdlod_preprocess::readers::DumpFile;
    assert!(DumpFile::open_within(&pattern, t0 + t1 - 1, &NoProgress)
        .unwrap()
        .is_none());
    let d = DumpFile::open_within(&pattern, t0 + t1, &NoProgress)
        .unwrap()
        .unwrap();
    assert_eq!((d.text_in_memory(), d.is_compressed()), (t0 + t1, true));
    drop(d);

    // Room for the text of piece 0, not of both: piece 1 goes to a working file (the
    // pattern names no file: its size was taken as 0 and every piece held in memory).
    opts.chunks.gzip_in_memory = Some(t0.div_ceil(4));
    let b = open_bounded(&pattern, &opts.chunks, &out, &NoProgress).unwrap();
    let pieces = b.dump.piece_paths().unwrap();
    assert_eq!(pieces[0], p0);
    assert!(pieces[1].starts_with(&work) && pieces[1].ends_with("run.1.dump"));
    assert_eq!(b.text.as_deref(), pieces[1].parent());
    assert!(b.dump.is_compressed());
    assert_eq!(b.dump.text_in_memory(), t0);
    assert_eq!(b.dump.frame_info(0).unwrap().particles, 5500);
    drop(b);
    // Every piece too large: both in working files.
    opts.chunks.gzip_in_memory = Some(0);
    let b = open_bounded(&pattern, &opts.chunks, &out, &NoProgress).unwrap();
    let pieces = b.dump.piece_paths().unwrap();
    assert!(pieces.iter().all(|p| p.starts_with(&work)), "{pieces:?}");
    assert_eq!(b.dump.text_in_memory(), 0);
    drop(b);
    assert_eq!(
        std::fs::read_dir(&work).unwrap().count(),
        0,
        "working files left"
    );

    // Converted (in windows: 5500 particles, chunks of 1000) from memory, partly from a
    // working file, and wholly from working files: the same file.
    let read = ReadOptions::default();
    let mut files = Vec::new();
    for limit in [None, Some(t0.div_ceil(4)), Some(0)] {
        opts.chunks.gzip_in_memory = limit;
        let out = dir.path().join(format!("out-{limit:?}.mdlod"));
        convert_file(&pattern, &out, FrameSelect::Last, &read, &opts, &NoProgress).unwrap();
        files.push(std::fs::read(&out).unwrap());
    }
    assert!(files[0] == files[1] && files[1] == files[2]);
    assert_eq!(
        MdlodFile::open(dir.path().join("out-Some(0).mdlod"))
            .unwrap()
            .particle_count(),
        5500
    );
    assert_eq!(
        std::fs::read_dir(&work).unwrap().count(),
        0,
        "working files left"
    );
}

/// Converts `path` to `out` (the last frame), checking no note says decades are lost.
fn converted_saying_no_decades(path: &Path, out: &Path, read: &ReadOptions, opts: &ConvertOptions) {
    let r = convert_file(path, out, FrameSelect::Last, read, opts, &NoProgress).unwrap();
    assert!(
        !r.notes.iter().any(|n| n.contains("decades")),
        "{:?}",
        r.notes
    );
}

/// Every level's clusters of `f`, an attribute kept as its logarithm, their areas times
/// 10^mean, add up to `total`, the particles' `Σ r² v` (what splats lit by the attribute
/// draw): the means are the logarithms of the area-weighted means, not means of the
/// logarithms.
fn assert_light_adds_up(f: &MdlodFile, total: f64) {
    assert!(f.metadata().attribute_log10);
    for l in 0..f.level_count() - 1 {
        let level = &f.levels()[l];
        let first = level.node_first as usize;
        let nodes = &f.nodes()[first..first + level.point_count as usize];
        let sum: f64 = nodes
            .iter()
            .map(|n| f64::from(n.area_sum) * 10f64.powf(f64::from(n.attribute)))
            .sum();
        assert!(
            (sum / total - 1.0).abs() < 1e-4,
            "{}: level {l}: {sum} against {total}",
            f.path().display()
        );
    }
}

/// `attribute_log10`: the attribute's logarithm is stored, named `log10(NAME)`, every
/// decade in 16 bits alike, streamed out of core as in memory; a value not above 0 is an
/// error naming the particle; without it, a note says the lowest decades lose digits.
#[test]
fn an_attribute_spanning_decades_keeps_its_logarithm() {
    let dir = tempfile::tempdir().unwrap();
    let n = 1000;
    let mut text = format!(
        "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n{n}\nITEM: BOX BOUNDS pp pp pp\n0 10\n0 10\n\
         0 10\nITEM: ATOMS id type x y z rho\n"
    );
    // Densities from 1e-6 to 1e3, nine decades.
    let rho = |i: usize| 10f64.powf(-6.0 + 9.0 * i as f64 / (n - 1) as f64);
    for i in 0..n {
        let (x, y, z) = (i % 10, (i / 10) % 10, i / 100);
        text.push_str(&format!("{} 1 {x}.25 {y}.5 {z}.75 {:e}\n", i + 1, rho(i)));
    }
    let path = dir.path().join("sph.lammpstrj");
    std::fs::write(&path, &text).unwrap();
    let read = ReadOptions {
        attribute: Some("rho".into()),
        ..Default::default()
    };
    let mut opts = options(300);
    opts.attribute_log10 = true;
    let (streamed, whole) = (dir.path().join("s.mdlod"), dir.path().join("w.mdlod"));
    converted_saying_no_decades(&path, &streamed, &read, &opts);
    let dump = DumpFile::open(&path).unwrap();
    let frame = dump.read_frame(0, &read, &NoProgress).unwrap();
    convert_frame(
        &frame,
        Some(source_info(&path, 0)),
        &whole,
        &opts,
        &NoProgress,
    )
    .unwrap();
    assert_eq!(
        std::fs::read(&streamed).unwrap(),
        std::fs::read(&whole).unwrap()
    );
    let f = MdlodFile::open(&streamed).unwrap();
    let info = f.metadata().attribute.clone().unwrap();
    assert_eq!(info.name, "log10(rho)");
    assert!(
        (info.min + 6.0).abs() < 1e-5 && (info.max - 3.0).abs() < 1e-5,
        "{info:?}"
    );
    // Every particle's value within a 16-bit step of its logarithm: 1e-6 and 1e-5 told
    // apart as well as 100 and 1000.
    let step = 9.0 / 65535.0;
    let mut seen: Vec<f64> = f
        .attribute()
        .unwrap()
        .iter()
        .map(|&q| f64::from(info.decode(q)))
        .collect();
    seen.sort_by(f64::total_cmp);
    for (i, v) in seen.iter().enumerate() {
        assert!((v - rho(i).log10()).abs() <= step, "particle {i}: {v}");
    }
    // Every node holds the logarithm of its particles' area-weighted mean value, not the
    // mean of their logarithms: each level's clusters, their areas times 10^mean, add up
    // to the particles' total (what splats lit by the attribute draw), the top node's
    // whole (built in chunks here: the top from the chunks' roots).
    assert!(f.metadata().attribute_log10);
    let r2 = f64::from(f.metadata().species[0].radius).powi(2);
    let total: f64 = (0..n).map(|i| r2 * rho(i)).sum();
    assert_light_adds_up(&f, total);

    // Stored as they are: a note, in memory and streamed.
    opts.attribute_log10 = false;
    let r = convert_file(
        &path,
        &streamed,
        FrameSelect::Last,
        &read,
        &opts,
        &NoProgress,
    )
    .unwrap();
    assert!(
        r.notes
            .iter()
            .any(|n| n.contains("attribute rho spans 9.0 decades")
                && n.contains("--attribute-log10")),
        "{:?}",
        r.notes
    );
    let r = convert_frame(&frame, None, &whole, &opts, &NoProgress).unwrap();
    assert!(
        r.notes.iter().any(|n| n.contains("spans 9.0 decades")),
        "{:?}",
        r.notes
    );

    // A density of 0 has no logarithm.
    std::fs::write(&path, text.replacen(" 1e-6\n", " 0\n", 1)).unwrap();
    opts.attribute_log10 = true;
    let e = convert_file(
        &path,
        &streamed,
        FrameSelect::Last,
        &read,
        &opts,
        &NoProgress,
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains(
            "attribute rho: particle 0 (counting from 0, in the input's order) has the value 0"
        ) && e.contains("above 0"),
        "{e}"
    );

    // No attribute kept (no column named): an error streamed and in memory, not a file
    // silently without the logarithm asked for.
    std::fs::write(&path, &text).unwrap();
    let plain = ReadOptions::default();
    let e = convert_file(
        &path,
        &streamed,
        FrameSelect::Last,
        &plain,
        &opts,
        &NoProgress,
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("sph.lammpstrj") && e.contains("--attribute-log10: the input keeps no"),
        "{e}"
    );
    let bare = dump.read_frame(0, &plain, &NoProgress).unwrap();
    let e = convert_frame(&bare, None, &whole, &opts, &NoProgress)
        .unwrap_err()
        .to_string();
    assert!(e.contains("name its column with --attribute COLUMN"), "{e}");
}

/// A box whose bounds overflow (`-1e308 1e308`: an extent past the largest double) is
/// refused naming the input and its frame, streamed and in memory, before any particle
/// is built (it used to reach the writer, whose message named the output).
#[test]
fn a_box_that_is_not_finite_is_refused_naming_the_input() {
    let dir = tempfile::tempdir().unwrap();
    let text = grid_dump(7, 400, "-1e308 1e308");
    let path = dir.path().join("wide.lammpstrj");
    std::fs::write(&path, &text).unwrap();
    let out = dir.path().join("w.mdlod");
    for chunk_points in [100, 1 << 20] {
        let e = convert_file(
            &path,
            &out,
            FrameSelect::Last,
            &ReadOptions::default(),
            &options(chunk_points),
            &NoProgress,
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("wide.lammpstrj")
                && e.contains("timestep 7")
                && e.contains("the simulation box is not finite (its a vector holds inf)"),
            "{chunk_points}: {e}"
        );
        assert!(!out.exists());
    }
    // Finite vectors whose sum is not: an XYZ origin and lattice of 1e308 each.
    let xyz = dir.path().join("far.xyz");
    std::fs::write(
        &xyz,
        "1\nLattice=\"1e308 0 0 0 1e308 0 0 0 1\" Origin=\"1e308 0 0\"\nCu 0 0 0\n",
    )
    .unwrap();
    let e = convert_file(
        &xyz,
        &out,
        FrameSelect::Last,
        &ReadOptions::default(),
        &options(1 << 20),
        &NoProgress,
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("far.xyz") && e.contains("its far corner, origin + a + b + c, reaches inf"),
        "{e}"
    );
}

/// A memory limit no chunk fits in says what a chunk needs (its fixed working buffers
/// and its particles), the limit that would do, and names the input: "64 MiB is below
/// the 64.0 MiB a chunk needs … a chunk of at least 1 particles" read as a contradiction.
#[test]
fn a_limit_no_chunk_fits_says_what_a_chunk_needs_and_names_the_input() {
    let dir = tempfile::tempdir().unwrap();
    let text = grid_dump(3, 1000, "0 10");
    let path = dir.path().join("tight.lammpstrj");
    std::fs::write(&path, &text).unwrap();
    let mut opts = options(100);
    opts.chunks.memory_limit = 64 << 20;
    let e = convert_file(
        &path,
        &dir.path().join("t.mdlod"),
        FrameSelect::Last,
        &ReadOptions::default(),
        &opts,
        &NoProgress,
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("tight.lammpstrj")
            && e.contains("timestep 3")
            && e.contains("64 MiB of working buffers")
            && e.contains("raise --memory-limit to at least"),
        "{e}"
    );
}

/// A LAMMPS text dump of `n` atoms on a grid of 10 per row in a 10-unit box whose x
/// bounds are `x_bounds`, at `timestep`.
fn grid_dump(timestep: u64, n: usize, x_bounds: &str) -> String {
    let mut text = format!(
        "ITEM: TIMESTEP\n{timestep}\nITEM: NUMBER OF ATOMS\n{n}\nITEM: BOX BOUNDS pp pp pp\n\
         {x_bounds}\n0 10\n0 10\nITEM: ATOMS id type x y z\n"
    );
    for i in 0..n {
        text.push_str(&format!(
            "{} 1 {}.5 {}.5 {}.5\n",
            i + 1,
            i % 10,
            (i / 10) % 10,
            i / 100
        ));
    }
    text
}

/// Structure types as species (`--species-column c_cna`) read a window at a time, text
/// and binary: the same file as the whole frame's, each window's types merged into the
/// frame's list, the text dump's atoms keeping their element's size.
#[test]
fn a_species_column_streams_into_the_same_file() {
    let read = ReadOptions {
        species_column: Some("c_cna".into()),
        ..Default::default()
    };
    for name in ["cu_gb.cna.dump", "cu_gb.cna.bin"] {
        let path = mdlod_datasets::lammps_sample_path(name);
        let f = streamed_equals_in_memory(&path, &read, 1000);
        let species: Vec<(&str, f32)> = f
            .metadata()
            .species
            .iter()
            .map(|s| (s.name.as_str(), s.radius))
            .collect();
        // Type 1 (fcc) takes the override of `options`; 5 its element's size, or a
        // type's default in a binary dump.
        let other = if name.ends_with(".dump") { 1.28 } else { 0.5 };
        assert_eq!(species, [("1", 1.28), ("5", other)], "{name}");
    }
}

/// A particle that cannot be built, met in the partition pass of an out-of-core
/// conversion, is named in the input's frame, not in the file being written.
#[test]
fn a_bad_particle_out_of_core_is_named_in_the_input() {
    let dir = tempfile::tempdir().unwrap();
    let n = 3000usize;
    let mut pos = raw_positions(n, 0x9E3779B97F4A7C15);
    pos[12 * 1500..12 * 1500 + 4].copy_from_slice(&3e38f32.to_le_bytes());
    std::fs::write(dir.path().join("pos.f32"), &pos).unwrap();
    let sidecar = dir.path().join("frame.raw.json");
    std::fs::write(
        &sidecar,
        r#"{"mdlod_raw": 1, "positions": {"file": "pos.f32", "type": "f32"}, "timestep": 7}"#,
    )
    .unwrap();
    let out = dir.path().join("out.mdlod");
    let mut opts = options(1000);
    opts.radii.clear();
    let e = convert_file(
        &sidecar,
        &out,
        FrameSelect::Last,
        &ReadOptions::default(),
        &opts,
        &NoProgress,
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.starts_with(&format!(
            "{}: frame 0 (timestep 7): particle 1500 at [3e38",
            sidecar.display()
        )) && e.contains("lies beyond ±1e37")
            && !e.contains("out.mdlod"),
        "{e}"
    );
    assert!(!out.exists());
}

/// `wrap` reads the same wrapped particles a window at a time as whole: unwrapped
/// coordinates of a melt streamed into the file a whole read builds.
#[test]
fn wrapped_unwrapped_coordinates_stream_into_the_same_file() {
    let path = mdlod_datasets::lammps_sample_path("cuag_alloy.unwrapped.dump");
    let read = ReadOptions {
        wrap: true,
        ..Default::default()
    };
    let f = streamed_equals_in_memory(&path, &read, 300);
    let b = f.metadata().simulation_box.clone().unwrap();
    let top = f.nodes()[0];
    // The particles' spheres (radius below 1.5) inside the box grown by a radius.
    for d in 0..3 {
        let (lo, hi) = (b.origin[d], b.origin[d] + [b.a[0], b.b[1], b.c[2]][d]);
        assert!(f64::from(top.bounds_min[d]) >= lo - 1.5, "{top:?}");
        assert!(f64::from(top.bounds_max[d]) <= hi + 1.5, "{top:?}");
    }
}

/// A further attribute kept as its logarithm (`extra_log10`): named `log10(NAME)`, its
/// values the logarithms to a 16-bit step, each node's mean the logarithm of its
/// particles' area-weighted mean (the clusters' light adds up to the particles' at every
/// level, the top node's made from the chunks' roots), the same streamed out of core as
/// from the frame in memory, and built whole alike; selected, it is the first attribute
/// with `attribute_log10`, as a copy of the first so kept holds the first's values and
/// means; no note of decades lost; a value not above 0 is an error naming the column and
/// the particle, streamed or whole; a logarithm asked past the further attributes is
/// refused.
#[test]
fn a_further_attribute_spanning_decades_keeps_its_logarithm() {
    let dir = tempfile::tempdir().unwrap();
    let n = 1000;
    let mut text = format!(
        "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n{n}\nITEM: BOX BOUNDS pp pp pp\n0 10\n0 10\n\
         0 10\nITEM: ATOMS id type x y z rho t sigma copy\n"
    );
    // A density over nine decades; a column density over eight, in another order.
    let rho = |i: usize| 10f64.powf(-6.0 + 9.0 * i as f64 / (n - 1) as f64);
    let sigma = |i: usize| 10f64.powf(-2.0 + 8.0 * ((i * 37) % n) as f64 / (n - 1) as f64);
    for i in 0..n {
        let (x, y, z) = (i % 10, (i / 10) % 10, i / 100);
        text.push_str(&format!(
            "{} {} {x}.25 {y}.5 {z}.75 {:e} {} {:e} {:e}\n",
            i + 1,
            1 + i % 2,
            rho(i),
            i as f32 * 0.5,
            sigma(i),
            rho(i)
        ));
    }
    let path = dir.path().join("sph.lammpstrj");
    std::fs::write(&path, &text).unwrap();
    let read = ReadOptions {
        attribute: Some("rho".into()),
        extra_attributes: vec!["t".into(), "sigma".into(), "copy".into()],
        ..Default::default()
    };
    let mut opts = options(300);
    opts.radii = vec![("1".into(), 1.28), ("2".into(), 0.7)];
    opts.attribute_log10 = true;
    opts.extra_log10 = vec![false, true, true];
    let dump = DumpFile::open(&path).unwrap();
    let frame = dump.read_frame(0, &read, &NoProgress).unwrap();
    let further = mdlod_preprocess::convert::read_extra_attributes(&dump, 0, &read).unwrap();
    let (streamed, in_memory, whole) = (
        dir.path().join("s.mdlod"),
        dir.path().join("m.mdlod"),
        dir.path().join("w.mdlod"),
    );
    converted_saying_no_decades(&path, &streamed, &read, &opts);
    let convert_whole =
        |frame: &mdlod_preprocess::frame::Frame, out: &Path, opts: &ConvertOptions| {
            mdlod_preprocess::convert::convert_frame_with(
                frame,
                &further,
                Some(source_info(&path, 0)),
                out,
                opts,
                &NoProgress,
            )
        };
    convert_whole(&frame, &in_memory, &opts).unwrap();
    assert_eq!(
        std::fs::read(&streamed).unwrap(),
        std::fs::read(&in_memory).unwrap()
    );
    let mut one = opts.clone();
    one.chunks.chunk_points = 1 << 20;
    let r = convert_whole(&frame, &whole, &one).unwrap();
    assert!(
        !r.notes.iter().any(|n| n.contains("decades")),
        "{:?}",
        r.notes
    );

    for path in [&streamed, &whole] {
        let f = MdlodFile::open(path).unwrap();
        f.verify().unwrap();
        let kept = &f.metadata().attributes;
        let named: Vec<(&str, bool)> = kept.iter().map(|a| (a.name.as_str(), a.log10)).collect();
        assert_eq!(
            named,
            [("t", false), ("log10(sigma)", true), ("log10(copy)", true)]
        );
        assert!(
            (kept[1].min + 2.0).abs() < 1e-5 && (kept[1].max - 6.0).abs() < 1e-5,
            "{:?}",
            kept[1]
        );
        let radius = |name: &str| {
            let s = f.metadata().species.iter().find(|s| s.name == name);
            f64::from(s.unwrap().radius)
        };
        let (r1, r2) = (radius("1"), radius("2"));
        let first: Vec<u16> = f.attribute().unwrap().to_vec();
        let first_nodes: Vec<f32> = f.nodes().iter().map(|n| n.attribute).collect();

        // Selected by the column's own name.
        let s = MdlodFile::open(path)
            .unwrap()
            .select_attribute("sigma")
            .unwrap();
        let info = s.metadata().attribute.clone().unwrap();
        assert_eq!(info.name, "log10(sigma)");
        assert!(s.metadata().attribute_log10 && !info.log10);
        let step = 8.0 / 65535.0;
        let mut seen: Vec<f64> = s
            .attribute()
            .unwrap()
            .iter()
            .map(|&q| f64::from(info.decode(q)))
            .collect();
        seen.sort_by(f64::total_cmp);
        let mut want: Vec<f64> = (0..n).map(|i| sigma(i).log10()).collect();
        want.sort_by(f64::total_cmp);
        for (i, (v, w)) in seen.iter().zip(&want).enumerate() {
            assert!(
                (v - w).abs() <= step,
                "{}: value {i}: {v} against {w}",
                path.display()
            );
        }
        let total: f64 = (0..n)
            .map(|i| if i % 2 == 0 { r1 * r1 } else { r2 * r2 } * sigma(i))
            .sum();
        assert_light_adds_up(&s, total);

        // A copy of the first, kept alike, holds its values and, node by node, its means.
        let copy = MdlodFile::open(path)
            .unwrap()
            .select_attribute("copy")
            .unwrap();
        assert_eq!(copy.attribute().unwrap(), &first[..]);
        for (i, (a, b)) in first_nodes.iter().zip(copy.nodes()).enumerate() {
            assert!(
                (a - b.attribute).abs() <= 1e-5,
                "{}: node {i}: {a} against {}",
                path.display(),
                b.attribute
            );
        }
    }

    // Kept as it is: the note says how to keep its decades, and the others' logarithms.
    let mut linear = opts.clone();
    linear.extra_log10 = vec![false, false, true];
    let r = convert_whole(&frame, &whole, &linear).unwrap();
    assert!(
        r.notes
            .iter()
            .any(|n| n.contains("attribute sigma spans 8.0 decades")
                && n.contains("--attribute-log10=rho,copy,sigma keeps its logarithm")),
        "{:?}",
        r.notes
    );

    // A column density of 0 has no logarithm: streamed and whole, the column and the
    // particle named.
    let zero = text.replacen(&format!(" {:e} ", sigma(5)), " 0 ", 1);
    assert_ne!(zero, text);
    std::fs::write(&path, &zero).unwrap();
    let frame = DumpFile::open(&path)
        .unwrap()
        .read_frame(0, &read, &NoProgress)
        .unwrap();
    let dump = DumpFile::open(&path).unwrap();
    let zeroed = mdlod_preprocess::convert::read_extra_attributes(&dump, 0, &read).unwrap();
    let e = convert_file(
        &path,
        &streamed,
        FrameSelect::Last,
        &read,
        &opts,
        &NoProgress,
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("attribute sigma: particle 5 ") && e.contains("needs values above 0"),
        "{e}"
    );
    let e = mdlod_preprocess::convert::convert_frame_with(
        &frame,
        &zeroed,
        None,
        &whole,
        &one,
        &NoProgress,
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("attribute sigma: particle 5 ") && e.contains("needs values above 0"),
        "{e}"
    );

    // A logarithm asked for past the further attributes.
    let mut past = one.clone();
    past.extra_log10 = vec![false, false, false, true];
    let e = mdlod_preprocess::convert::convert_frame_with(
        &frame,
        &zeroed,
        None,
        &whole,
        &past,
        &NoProgress,
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("further attribute 4"), "{e}");
}

/// A column whose values spread over decades lose digits where many lie in the lowest:
/// said, built whole or in chunks alike; a score from 0.5 to 1 with one value of 1e-6
/// (a failed fit's) spans as many decades, but loses nothing worth a note.
#[test]
fn decades_lost_are_noted_where_many_values_lie_there() {
    let dir = tempfile::tempdir().unwrap();
    let n = 1000;
    let mut text = format!(
        "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n{n}\nITEM: BOX BOUNDS pp pp pp\n0 10\n0 10\n\
         0 10\nITEM: ATOMS id type x y z q r s\n"
    );
    for i in 0..n {
        let (x, y, z) = (i % 10, (i / 10) % 10, i / 100);
        let q = if i == 7 {
            1e-6
        } else {
            0.5 + 0.5 * i as f64 / n as f64
        };
        let r = 10f64.powf(-6.0 + 6.0 * i as f64 / (n - 1) as f64);
        text.push_str(&format!(
            "{} 1 {x}.25 {y}.5 {z}.75 {q:e} {r:e} {q:e}\n",
            i + 1
        ));
    }
    let path = dir.path().join("scores.lammpstrj");
    std::fs::write(&path, &text).unwrap();
    let read = ReadOptions {
        attribute: Some("q".into()),
        extra_attributes: vec!["r".into(), "s".into()],
        ..Default::default()
    };
    let out = dir.path().join("o.mdlod");
    for chunk_points in [300, 1 << 20] {
        let r = convert_file(
            &path,
            &out,
            FrameSelect::Last,
            &read,
            &options(chunk_points),
            &NoProgress,
        )
        .unwrap();
        let said = |name: &str| {
            r.notes
                .iter()
                .any(|n| n.contains(&format!("attribute {name} spans 6.0 decades")))
        };
        assert!(
            said("r") && !said("q") && !said("s"),
            "chunks of {chunk_points}: {:?}",
            r.notes
        );
    }
}
