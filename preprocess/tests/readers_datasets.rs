//! Cross-checks on real LAMMPS outputs in `datasets/lammps/` (see `make-samples.sh` there):
//! the same run dumped in different styles must give the same positions. The files are
//! committed: a missing one fails its test (a rename must not turn it into a no-op).

use std::collections::HashMap;
use std::path::PathBuf;

use mdlod_preprocess::readers::{DumpFile, ReadOptions};
use mdlod_preprocess::{Frame, NoProgress};

fn sample(name: &str) -> Option<PathBuf> {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../datasets/lammps")
        .join(name);
    assert!(
        path.exists(),
        "{} is missing (committed with the repository)",
        path.display()
    );
    Some(path)
}

fn read(dump: &DumpFile, k: usize, attribute: Option<&str>) -> Frame {
    let opts = ReadOptions {
        attribute: attribute.map(String::from),
        ..Default::default()
    };
    dump.read_frame(k, &opts, &NoProgress).unwrap()
}

/// Positions by atom id (the `id` column read as the attribute).
fn by_id(frame: &Frame) -> HashMap<u32, [f32; 3]> {
    let ids = &frame.attribute.as_ref().unwrap().values;
    ids.iter()
        .zip(&frame.positions)
        .map(|(&id, &p)| (id as u32, p))
        .collect()
}

/// Wrapped positions of the same atoms agree up to the dumps' 6 significant digits, or
/// differ by a lattice vector (an atom just across a periodic face).
fn assert_same_positions(a: &Frame, b: &Frame, tolerance: f32) {
    let (a_ids, b_ids) = (by_id(a), by_id(b));
    assert_eq!(a_ids.len(), b_ids.len());
    let cell = a.simulation_box.as_ref().unwrap();
    for (id, pa) in &a_ids {
        let pb = b_ids[id];
        let mut best = f32::INFINITY;
        for i in -1..=1 {
            for j in -1..=1 {
                for k in -1..=1 {
                    let shift: [f64; 3] = std::array::from_fn(|d| {
                        f64::from(i) * cell.a[d]
                            + f64::from(j) * cell.b[d]
                            + f64::from(k) * cell.c[d]
                    });
                    let dist = (0..3)
                        .map(|d| (pa[d] - pb[d] - shift[d] as f32).abs())
                        .fold(0f32, f32::max);
                    best = best.min(dist);
                }
            }
        }
        assert!(best < tolerance, "atom {id}: {pa:?} vs {pb:?}");
    }
}

#[test]
fn lj_triclinic_scaled_matches_cartesian() {
    let (Some(scaled), Some(cartesian)) = (
        sample("lj_triclinic.scaled.dump"),
        sample("lj_triclinic.cartesian.dump"),
    ) else {
        return;
    };
    let scaled = DumpFile::open(&scaled).unwrap();
    let cartesian = DumpFile::open(&cartesian).unwrap();
    assert_eq!(scaled.frame_count(), cartesian.frame_count());
    for k in 0..scaled.frame_count() {
        assert_eq!(scaled.frame_timestep(k), cartesian.frame_timestep(k));
        let s = read(&scaled, k, Some("id"));
        let c = read(&cartesian, k, Some("id"));
        assert_eq!(s.simulation_box, c.simulation_box);
        assert!(!c.simulation_box.as_ref().unwrap().is_orthogonal());
        assert_same_positions(&s, &c, 2e-4);
    }
    let c = read(&cartesian, 1, Some("v_speed"));
    assert_eq!(c.attribute.unwrap().values.len(), c.positions.len());
}

#[test]
fn cu_melt_all_styles_agree() {
    let (Some(atom), Some(custom), Some(gz), Some(xyz)) = (
        sample("cu_melt.atom.dump"),
        sample("cu_melt.custom.dump"),
        sample("cu_melt.custom.dump.gz"),
        sample("cu_melt.xyz"),
    ) else {
        return;
    };
    let atom = DumpFile::open(&atom).unwrap();
    let custom = DumpFile::open(&custom).unwrap();
    let gz = DumpFile::open(&gz).unwrap();
    let xyz = DumpFile::open(&xyz).unwrap();
    let n = custom.frame_count();
    assert!(n > 1);
    for d in [&atom, &gz, &xyz] {
        assert_eq!(d.frame_count(), n);
    }
    for k in 0..n {
        let step = custom.frame_timestep(k);
        assert!(step.is_some());
        for d in [&atom, &gz, &xyz] {
            assert_eq!(d.frame_timestep(k), step);
        }
        let a = read(&atom, k, Some("id"));
        let c = read(&custom, k, Some("id"));
        let g = read(&gz, k, Some("id"));
        let x = read(&xyz, k, None);
        assert_eq!(c.units.as_deref(), Some("metal"));
        assert!(c.time.is_some());
        assert_same_positions(&a, &c, 2e-4);
        assert_same_positions(&g, &c, 2e-4);
        // The xyz and custom dumps are both sorted by id.
        assert_eq!(x.len(), c.len());
        assert_eq!(x.species.len(), 1);
        assert_eq!(x.species[0].name, "Cu");
        assert_eq!(c.species[0].name, "1");
        assert!(c.species[0].numeric_type);
        for (p, q) in x.positions.iter().zip(&c.positions) {
            assert!((0..3).all(|d| (p[d] - q[d]).abs() < 2e-4), "{p:?} {q:?}");
        }
    }
    assert!(read(&custom, n - 1, Some("c_pe")).attribute.is_some());
    assert!(read(&gz, n - 1, Some("c_ke")).attribute.is_some());
}

#[test]
fn cuag_alloy_elements_and_unwrapped() {
    let Some(path) = sample("cuag_alloy.unwrapped.dump") else {
        return;
    };
    let dump = DumpFile::open(&path).unwrap();
    for k in 0..dump.frame_count() {
        let f = read(&dump, k, Some("c_pe"));
        let mut names: Vec<&str> = f.species.iter().map(|s| s.name.as_str()).collect();
        names.sort();
        assert_eq!(names, vec!["Ag", "Cu"]);
        assert!(f.species.iter().all(|s| !s.numeric_type));
        assert_eq!(f.attribute.as_ref().unwrap().values.len(), f.len());
    }
    // Unwrapped coordinates (xu yu zu): by the last frame some atoms of the melt have
    // left the periodic box [0, 21.69)³, where wrapped coordinates would keep them.
    let last = read(&dump, dump.frame_count() - 1, None);
    let outside = last
        .positions
        .iter()
        .filter(|p| p.iter().any(|&c| !(0.0..21.69).contains(&c)))
        .count();
    assert!(
        outside > 0,
        "every atom inside the box: coordinates wrapped?"
    );
    // `wrap`: every atom back inside the periodic box, each moved by whole box lengths.
    let opts = ReadOptions {
        wrap: true,
        ..Default::default()
    };
    let k = dump.frame_count() - 1;
    let wrapped = dump.read_frame(k, &opts, &NoProgress).unwrap();
    let b = wrapped.simulation_box.clone().unwrap();
    let lo = b.origin;
    let len = [b.a[0], b.b[1], b.c[2]];
    for (p, q) in wrapped.positions.iter().zip(&last.positions) {
        for d in 0..3 {
            let (p, q) = (f64::from(p[d]), f64::from(q[d]));
            assert!(
                p >= lo[d] - 1e-4 && p <= lo[d] + len[d] + 1e-4,
                "{p} outside"
            );
            let shifts = (q - p) / len[d];
            assert!((shifts - shifts.round()).abs() < 1e-4, "{q} to {p}");
        }
    }
}

/// `wrap_positions`: fractional coordinates along the periodic axes of a triclinic cell
/// taken modulo 1; a non-periodic axis is left alone.
#[test]
fn wrapping_into_a_triclinic_cell() {
    let cell = mdlod_format::meta::SimulationBox {
        origin: [1.0, 2.0, 3.0],
        a: [10.0, 0.0, 0.0],
        b: [3.0, 10.0, 0.0],
        c: [1.0, 2.0, 10.0],
        periodic: Some([true, true, false]),
    };
    let at = |f: [f64; 3]| -> [f32; 3] {
        [0, 1, 2].map(|r| {
            (cell.origin[r] + cell.a[r] * f[0] + cell.b[r] * f[1] + cell.c[r] * f[2]) as f32
        })
    };
    let mut p = vec![at([1.5, -0.25, 1.5]), at([0.25, 0.5, 0.5])];
    mdlod_preprocess::readers::wrap_positions(&mut p, &cell);
    let want = [at([0.5, 0.75, 1.5]), at([0.25, 0.5, 0.5])];
    for (got, want) in p.iter().zip(&want) {
        for d in 0..3 {
            assert!((got[d] - want[d]).abs() < 1e-4, "{got:?} against {want:?}");
        }
    }
}

/// A two-dimensional cell (HOOMD's Lz = 0, tilted in plane) wraps its in-plane axes and
/// leaves z alone: its c of length 0 made the cell's matrix singular, and nothing wrapped.
#[test]
fn wrapping_into_a_flat_cell() {
    let cell = mdlod_format::meta::SimulationBox {
        origin: [-25.0, -25.0, 0.0],
        a: [50.0, 0.0, 0.0],
        b: [15.0, 50.0, 0.0],
        c: [0.0, 0.0, 0.0],
        periodic: Some([true, true, true]),
    };
    let at = |f: [f64; 2], z: f64| -> [f32; 3] {
        [0, 1]
            .map(|r| (cell.origin[r] + cell.a[r] * f[0] + cell.b[r] * f[1]) as f32)
            .into_iter()
            .chain([z as f32])
            .collect::<Vec<_>>()
            .try_into()
            .unwrap()
    };
    let mut p = vec![
        at([1.75, -0.5], 0.0),
        at([0.25, 0.5], 0.0),
        at([-1.25, 2.25], 0.0),
    ];
    mdlod_preprocess::readers::wrap_positions(&mut p, &cell);
    let want = [
        at([0.75, 0.5], 0.0),
        at([0.25, 0.5], 0.0),
        at([0.75, 0.25], 0.0),
    ];
    for (got, want) in p.iter().zip(&want) {
        for d in 0..3 {
            assert!((got[d] - want[d]).abs() < 1e-3, "{got:?} against {want:?}");
        }
    }
}

/// `--wrap` of a frame without a cell (a plain XYZ file) says it has nothing to wrap
/// into; of a frame with one, nothing is said.
#[test]
fn wrapping_without_a_cell_is_noted() {
    let wrap = ReadOptions {
        wrap: true,
        ..Default::default()
    };
    let xyz = DumpFile::open(&sample("cu_melt.xyz").unwrap()).unwrap();
    let notes = xyz.frame_notes(0, &wrap);
    assert!(
        notes
            .iter()
            .any(|n| n.contains("has no simulation cell") && n.contains("--wrap")),
        "{notes:?}"
    );
    assert!(!xyz
        .frame_notes(0, &ReadOptions::default())
        .iter()
        .any(|n| n.contains("--wrap")));
    let dump = DumpFile::open(&sample("cu_melt.custom.dump").unwrap()).unwrap();
    assert!(!dump
        .frame_notes(0, &wrap)
        .iter()
        .any(|n| n.contains("--wrap")));
}

#[test]
fn cu_slab_shrink_wrapped_boundary() {
    let Some(path) = sample("cu_slab.shrinkwrap.dump") else {
        return;
    };
    let dump = DumpFile::open(&path).unwrap();
    let f = read(&dump, dump.frame_count() - 1, Some("c_ke"));
    let b = f.simulation_box.unwrap();
    assert_eq!(b.periodic, Some([true, true, false]));
    assert_eq!(f.units.as_deref(), Some("metal"));
}

/// How an input names its species, told from its first atom: what a radius override can
/// call them (`Cu` never names a LAMMPS type number, `1` never an `element` column's).
#[test]
fn species_naming_follows_the_species_column() {
    use mdlod_preprocess::species::SpeciesNaming;
    let naming = |path: &std::path::Path| {
        DumpFile::open(path)
            .unwrap()
            .species_naming(0, &ReadOptions::default())
            .unwrap()
    };
    let numbers = SpeciesNaming::TypeNumbers { first: "1".into() };
    for name in [
        "cu_melt.custom.dump",
        "cu_melt.custom.dump.gz",
        "cu_melt.atom.dump",
        "cu_melt.custom.bin",
        "cu_melt.atom.bin",
    ] {
        assert_eq!(naming(&sample(name).unwrap()), numbers, "{name}");
    }
    for pieces in ["cu_melt_mpi.%.dump", "cu_melt_mpi.%.bin"] {
        let path = sample("cu_melt_mpi.0.dump").unwrap().with_file_name(pieces);
        assert_eq!(naming(&path), numbers, "{pieces}");
    }
    assert_eq!(
        naming(&sample("cuag_alloy.unwrapped.dump").unwrap()),
        SpeciesNaming::ElementColumn {
            first: "Cu".into(),
            first_type: Some("1".into())
        }
    );
    assert_eq!(
        naming(&sample("cu_melt.xyz").unwrap()),
        SpeciesNaming::Given
    );
    // Type labels, no species column, no atoms: any name may occur.
    let dir = tempfile::tempdir().unwrap();
    let header = "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n";
    let box_ = "ITEM: BOX BOUNDS pp pp pp\n0 1\n0 1\n0 1\n";
    for (name, text) in [
        (
            "labels",
            format!("{header}1\n{box_}ITEM: ATOMS id type x y z\n1 Cu 0 0 0\n"),
        ),
        (
            "untyped",
            format!("{header}1\n{box_}ITEM: ATOMS id x y z\n1 0 0 0\n"),
        ),
        (
            "empty",
            format!("{header}0\n{box_}ITEM: ATOMS id type x y z\n"),
        ),
    ] {
        let path = dir.path().join(format!("{name}.lammpstrj"));
        std::fs::write(&path, text).unwrap();
        assert_eq!(naming(&path), SpeciesNaming::Given, "{name}");
    }
    let only_element = dir.path().join("element.lammpstrj");
    std::fs::write(
        &only_element,
        format!("{header}1\n{box_}ITEM: ATOMS id element x y z\n1 Ag 0 0 0\n"),
    )
    .unwrap();
    assert_eq!(
        naming(&only_element),
        SpeciesNaming::ElementColumn {
            first: "Ag".into(),
            first_type: None
        }
    );
}

/// `--species-column c_cna` on the real bicrystal, text and binary: every atom's species
/// is its own common-neighbour-analysis value, the text dump's atoms keep their element's
/// size (Cu, 1.28 Å), and both dumps agree atom by atom.
#[test]
fn a_species_column_makes_the_structure_types_species() {
    let text_path = sample("cu_gb.cna.dump").unwrap();
    let expected = mdlod_datasets::lammps_sample_column("cu_gb.cna.dump", "c_cna");
    assert_eq!(expected.len(), 2552);
    let opts = ReadOptions {
        species_column: Some("c_cna".into()),
        ..Default::default()
    };
    let from_text = DumpFile::open(&text_path)
        .unwrap()
        .read_frame(0, &opts, &NoProgress)
        .unwrap();
    let from_binary = DumpFile::open(&sample("cu_gb.cna.bin").unwrap())
        .unwrap()
        .read_frame(0, &opts, &NoProgress)
        .unwrap();
    for frame in [&from_text, &from_binary] {
        let names: Vec<&str> = frame.species.iter().map(|s| s.name.as_str()).collect();
        assert_eq!(names, ["1", "5"]);
        assert!(frame.species.iter().all(|s| s.numeric_type));
        let got: Vec<&str> = frame
            .species_index
            .iter()
            .map(|&s| names[usize::from(s)])
            .collect();
        // (Both dumps are sorted by id.)
        assert_eq!(got, expected);
    }
    let radii = from_text
        .radii
        .as_ref()
        .expect("sizes from the element column");
    assert!(radii.iter().all(|&r| r == 1.28), "{:?}", &radii[..4]);
    // Structure types in the colours OVITO gives them, by value: fcc green, other grey.
    for frame in [&from_text, &from_binary] {
        let colours: Vec<Option<[u8; 3]>> = frame.species.iter().map(|s| s.colour).collect();
        assert_eq!(colours, [Some([102, 255, 102]), Some([242, 242, 242])]);
    }
    assert!(from_text.species.iter().all(|s| s.radius == Some(1.28)));
    // A binary dump names no elements: its categories take their radii as types do.
    assert!(from_binary.radii.is_none());
    // Without the option the species are the dump's own.
    let own = read(&DumpFile::open(&text_path).unwrap(), 0, None);
    assert_eq!(own.species.len(), 1);
    assert_eq!(own.species[0].name, "Cu");
}

/// Mistakes with `--species-column` name the file, the place and what the option takes.
#[test]
fn species_column_mistakes_are_named() {
    let text = sample("cu_gb.cna.dump").unwrap();
    let binary = sample("cu_gb.cna.bin").unwrap();
    let err = |path: &std::path::Path, column: &str| {
        let opts = ReadOptions {
            species_column: Some(column.into()),
            ..Default::default()
        };
        DumpFile::open(path)
            .unwrap()
            .read_frame(0, &opts, &NoProgress)
            .unwrap_err()
            .to_string()
    };
    let e = err(&text, "c_nope");
    assert!(
        e.contains("cu_gb.cna.dump:9:")
            && e.contains("no column `c_nope` for --species-column")
            && e.contains("id type element x y z c_cna c_cs c_pe"),
        "{e}"
    );
    let e = err(&binary, "c_nope");
    assert!(
        e.contains("cu_gb.cna.bin") && e.contains("no column `c_nope` for --species-column"),
        "{e}"
    );
    for path in [&text, &binary] {
        let e = err(path, "y");
        assert!(
            e.contains("--species-column y: `y` holds the positions"),
            "{e}"
        );
    }
    // A binary dump's continuous column is no category.
    let e = err(&binary, "c_pe");
    assert!(
        e.contains("atom 1 of timestep 100: column `c_pe`")
            && e.contains("not a whole number (--species-column takes a column of categories"),
        "{e}"
    );
}

/// A text column of more distinct values than a file holds species is refused with what
/// the option takes, at the line where the count ran out.
#[test]
fn a_species_column_of_continuous_values_is_refused_at_its_line() {
    let dir = tempfile::tempdir().unwrap();
    let n = 70_000;
    let mut dump = format!(
        "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n{n}\nITEM: BOX BOUNDS pp pp pp\n0 1\n0 1\n0 1\n\
         ITEM: ATOMS id type x y z c_pe\n"
    );
    for i in 0..n {
        dump += &format!("{} 1 0.5 0.5 0.5 -3.{i:06}\n", i + 1);
    }
    let path = dir.path().join("pe.dump");
    std::fs::write(&path, dump).unwrap();
    let opts = ReadOptions {
        species_column: Some("c_pe".into()),
        ..Default::default()
    };
    let e = DumpFile::open(&path)
        .unwrap()
        .read_frame(0, &opts, &NoProgress)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("pe.dump:")
            && e.contains("more than 65536 distinct values in --species-column c_pe")
            && e.contains("goes in --attribute"),
        "{e}"
    );
}

/// A pass for one attribute's values only (`values_only`, what further attributes are
/// read by) gives the values a full read gives, of a column of its own or of a
/// coordinate, in LAMMPS text (whole and in windows) and in other formats, which read as
/// ever.
#[test]
fn a_values_only_pass_reads_the_values_a_full_read_does() {
    for (name, column) in [
        ("cu_melt.custom.dump", "c_pe"),
        ("cu_melt.custom.dump", "z"),
        ("cu_melt.custom.dump", "type"),
        ("cu_melt.custom.bin", "c_pe"),
    ] {
        let path = sample(name).unwrap();
        let dump = DumpFile::open(&path).unwrap();
        let k = dump.frame_count() - 1;
        let full = read(&dump, k, Some(column));
        let only = ReadOptions {
            attribute: Some(column.into()),
            values_only: true,
            ..Default::default()
        };
        let fast = dump.read_frame(k, &only, &NoProgress).unwrap();
        assert_eq!(
            fast.attribute.as_ref().unwrap().values,
            full.attribute.as_ref().unwrap().values,
            "{name} {column}"
        );
        assert_eq!(fast.len(), full.len());
        if name.ends_with(".dump") {
            // (Text: the positions are not parsed.)
            assert!(fast.positions.iter().all(|p| *p == [0.0; 3]), "{name}");
            let info = dump.frame_info(k).unwrap();
            let source = mdlod_preprocess::convert::window_source(&dump, k, &only, &info).unwrap();
            let mut windows = Vec::new();
            source
                .windows(128, &mut |_, f| {
                    windows.extend(f.attribute.unwrap().values);
                    Ok(())
                })
                .unwrap();
            assert_eq!(windows, full.attribute.as_ref().unwrap().values, "{name}");
        } else {
            assert_eq!(fast.positions, full.positions, "{name}");
        }
    }
}
