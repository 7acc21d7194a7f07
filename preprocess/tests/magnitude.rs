//! Attributes asked for as magnitudes (`--attribute '|forces|'`, `'|v|'`, `'|vx,vy,vz|'`):
//! the length of a vector per particle, from the columns of LAMMPS text and binary dumps
//! and extended XYZ files, named as asked; columns that are not there are errors naming
//! them. (GSD rows: `readers_gsd.rs`.)

use mdlod_datasets::lammps_sample_path;
use mdlod_preprocess::readers::{magnitude_columns, DumpFile, ReadOptions};
use mdlod_preprocess::NoProgress;

fn asking(name: &str) -> ReadOptions {
    ReadOptions {
        attribute: Some(name.into()),
        ..Default::default()
    }
}

fn values(path: &std::path::Path, name: &str) -> Result<(String, Vec<f32>), String> {
    let dump = DumpFile::open(path).map_err(|e| e.to_string())?;
    let f = dump
        .read_frame(0, &asking(name), &NoProgress)
        .map_err(|e| e.to_string())?;
    let a = f.attribute.unwrap();
    assert_eq!(
        dump.attribute_name(0, &asking(name)).unwrap().as_deref(),
        Some(a.name.as_str())
    );
    Ok((a.name, a.values))
}

#[test]
fn lammps_velocities_give_speeds_by_prefix_or_by_list() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("v.dump");
    std::fs::write(
        &path,
        "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n3\nITEM: BOX BOUNDS pp pp pp\n0 10\n0 10\n\
         0 10\nITEM: ATOMS id type x y z vx vy vz c_f[1] c_f[2] c_f[3]\n\
         1 1 1 1 1 3 4 0 1 0 0\n2 1 2 2 2 1 2 2 0 -2 0\n3 1 3 3 3 0 0 0 0 0 0.5\n",
    )
    .unwrap();
    assert_eq!(
        values(&path, "|v|").unwrap(),
        ("|v|".into(), vec![5.0, 3.0, 0.0])
    );
    assert_eq!(
        values(&path, "|vx, vy|").unwrap().1,
        [5.0, 5.0_f32.sqrt(), 0.0]
    );
    // A compute's vector, numbered from 1.
    assert_eq!(values(&path, "|c_f|").unwrap().1, [1.0, 2.0, 0.5]);
    let e = values(&path, "|f|").unwrap_err();
    assert!(
        e.contains("v.dump:9: no vector `f` for the magnitude |f|")
            && e.contains("name its columns, as |vx,vy,vz|")
            && e.contains("the columns are id type x y z vx vy vz"),
        "{e}"
    );
    // One column: its absolute value.
    assert_eq!(values(&path, "|c_f[2]|").unwrap().1, [0.0, 2.0, 0.0]);
    let e = values(&path, "|vx,vx|").unwrap_err();
    assert!(e.contains("|vx,vx| names `vx` twice"), "{e}");
    let e = values(&path, "|vx,speed|").unwrap_err();
    assert!(
        e.contains("no column `speed` for the magnitude |vx,speed|"),
        "{e}"
    );
}

#[test]
fn extended_xyz_vector_properties_give_their_lengths() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("f.xyz");
    std::fs::write(
        &path,
        "2\nLattice=\"10 0 0 0 10 0 0 0 10\" Properties=species:S:1:pos:R:3:forces:R:3\n\
         Cu 0 0 0 0.6 0 0.8\nCu 1 1 1 -2 0 0\n",
    )
    .unwrap();
    let (name, v) = values(&path, "|forces|").unwrap();
    assert_eq!(name, "|forces|");
    assert!((v[0] - 1.0).abs() < 1e-6 && v[1] == 2.0, "{v:?}");
}

/// A binary dump's columns by list: the distance of each atom from the origin, against
/// its positions as read.
#[test]
fn binary_dump_columns_by_list() {
    let path = lammps_sample_path("cu_melt.custom.bin");
    let dump = DumpFile::open(&path).unwrap();
    let frame = dump
        .read_frame(0, &ReadOptions::default(), &NoProgress)
        .unwrap();
    let (name, v) = values(&path, "|x,y,z|").unwrap();
    assert_eq!(name, "|x,y,z|");
    assert_eq!(v.len(), frame.positions.len());
    for (p, d) in frame.positions.iter().zip(&v) {
        let want = p.iter().map(|c| f64::from(*c).powi(2)).sum::<f64>().sqrt();
        assert!(
            (f64::from(*d) - want).abs() <= 1e-5 * want.max(1.0),
            "{d} {want}"
        );
    }
}

#[test]
fn magnitude_columns_resolve_vectors_and_refuse_long_lists() {
    let cols: Vec<String> = ["x", "fx", "fy", "fz", "a[0]", "a[1]", "a[2]"]
        .map(String::from)
        .to_vec();
    assert_eq!(magnitude_columns("f", &cols).unwrap(), ["fx", "fy", "fz"]);
    assert_eq!(
        magnitude_columns("a", &cols).unwrap(),
        ["a[0]", "a[1]", "a[2]"]
    );
    assert!(magnitude_columns("x,fx,fy,fz,a[0]", &cols)
        .unwrap_err()
        .contains("5 columns (at most 4)"));
}
