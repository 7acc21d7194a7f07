//! Writes seed inputs for the fuzz targets into `corpus/<target>/` (relative to the
//! current directory, normally `fuzz/`): small valid `.mdlod` files made by
//! `convert_frame`; small LAMMPS and XYZ dumps; the project's real LAMMPS binary dumps and
//! GSD file (`datasets/`), small MMPLD files and small `.sndf` files. Each seed is one mode byte (see the
//! targets) followed by the file. Runs on stable: `cargo run --example make_seeds`.

use std::path::Path;

use mdlod_format::sndf::{SndfData, SndfHeader, SndfTile, SndfTiles, SNDF_TILE};
use mdlod_preprocess::convert::{convert_frame, ConvertOptions};
use mdlod_preprocess::hierarchy::BuildParams;
use mdlod_preprocess::{Attribute, Frame, NoProgress, SpeciesName};

fn frame(n: usize, attribute: bool) -> Frame {
    let mut s = 0x9E3779B97F4A7C15u64;
    let mut r = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 40) as f32 / (1u64 << 24) as f32 * 20.0
    };
    let positions: Vec<[f32; 3]> = (0..n).map(|_| [r(), r(), r()]).collect();
    Frame {
        species_index: (0..n).map(|i| (i % 3 == 0) as u16).collect(),
        species: ["Cu", "Ag"]
            .map(|name| SpeciesName {
                name: name.into(),
                numeric_type: false,
                radius: None,
                ..Default::default()
            })
            .to_vec(),
        attribute: attribute.then(|| Attribute {
            name: "c_pe".into(),
            values: positions.iter().map(|p| p[0] - p[1]).collect(),
        }),
        positions,
        ..Default::default()
    }
}

/// An MMPLD file (format version `version`, 100-103) of `frames` frames, each of four
/// particle lists with different vertex and colour types: intensities in every list
/// (`intensity`), or mixed colour types.
fn mmpld(version: u16, frames: usize, intensity: bool) -> Vec<u8> {
    let mut out = b"MMPLD\0".to_vec();
    out.extend_from_slice(&version.to_le_bytes());
    out.extend_from_slice(&(frames as u32).to_le_bytes());
    for v in [
        0.0f32, 0.0, 0.0, 4.0, 4.0, 4.0, -1.0, -1.0, -1.0, 5.0, 5.0, 5.0,
    ] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    let table = out.len();
    out.resize(table + 8 * (frames + 1), 0);
    for k in 0..=frames {
        let at = out.len() as u64;
        out[table + 8 * k..table + 8 * k + 8].copy_from_slice(&at.to_le_bytes());
        if k == frames {
            break;
        }
        if version >= 102 {
            out.extend_from_slice(&(k as f32).to_le_bytes());
        }
        // (vertex type, colour type, particles): float xyzr, float xyz, double xyz and
        // short xyz, with float or double intensities, or a global colour and RGBA bytes.
        let lists = if intensity {
            [(2u8, 3u8, 3usize), (1, 7, 2), (4, 3, 2), (3, 7, 2)]
        } else {
            [(2, 3, 3), (1, 0, 2), (4, 7, 2), (3, 2, 2)]
        };
        out.extend_from_slice(&(lists.len() as i32).to_le_bytes());
        for (vertex, colour, n) in lists {
            out.extend_from_slice(&[vertex, colour]);
            if vertex != 2 {
                out.extend_from_slice(&0.5f32.to_le_bytes());
            }
            match colour {
                0 => out.extend_from_slice(&[200, 100, 50, 255]),
                3 | 7 => [0f32, 10.0]
                    .iter()
                    .for_each(|v| out.extend_from_slice(&v.to_le_bytes())),
                _ => {}
            }
            out.extend_from_slice(&(n as u64).to_le_bytes());
            if version == 103 {
                for v in [0f32, 0.0, 0.0, 4.0, 4.0, 4.0] {
                    out.extend_from_slice(&v.to_le_bytes());
                }
            }
            for i in 0..n {
                let p = [i as f64, (i + k) as f64 * 0.5, 1.0];
                match vertex {
                    3 => p
                        .iter()
                        .for_each(|&v| out.extend_from_slice(&(v as i16).to_le_bytes())),
                    4 => p
                        .iter()
                        .for_each(|&v| out.extend_from_slice(&v.to_le_bytes())),
                    _ => p
                        .iter()
                        .for_each(|&v| out.extend_from_slice(&(v as f32).to_le_bytes())),
                }
                if vertex == 2 {
                    out.extend_from_slice(&0.75f32.to_le_bytes());
                }
                match colour {
                    2 => out.extend_from_slice(&[1, 2, 3, 4]),
                    3 => out.extend_from_slice(&(i as f32).to_le_bytes()),
                    7 => out.extend_from_slice(&(i as f64).to_le_bytes()),
                    _ => {}
                }
            }
            if version == 101 {
                // No cluster information: a count and a byte size of 0.
                out.extend_from_slice(&0u32.to_le_bytes());
                out.extend_from_slice(&0u64.to_le_bytes());
            }
        }
    }
    out
}

fn put(dir: &Path, name: &str, mode: u8, bytes: &[u8]) {
    let mut seed = vec![mode];
    seed.extend_from_slice(bytes);
    std::fs::write(dir.join(name), seed).unwrap();
}

fn main() {
    let mdlod = Path::new("corpus/mdlod_reader");
    let dumps = Path::new("corpus/lammps_dump");
    let binary = Path::new("corpus/binary_dump");
    std::fs::create_dir_all(mdlod).unwrap();
    std::fs::create_dir_all(dumps).unwrap();
    std::fs::create_dir_all(binary).unwrap();

    // Real files (written by LAMMPS and by the `gsd` package; see `datasets/`), and
    // MMPLD files. Mode bits 0-1 pick the name (.bin, .gsd, .mmpld, none: sniffed),
    // bits 2-3 the attribute (c_pe, charge, intensity).
    for (name, mode) in [
        ("lammps/cu_melt.step.0.bin", 1 << 2),
        ("lammps/cu_melt.atom.bin", 3),
        ("lammps/lj_triclinic.custom.bin", 0),
        ("gsd/hoomd_mixture.gsd", 1 | 2 << 2),
    ] {
        let bytes = std::fs::read(Path::new("../datasets").join(name)).unwrap();
        put(binary, &name.replace('/', "-"), mode, &bytes);
    }
    for version in [100, 101, 102, 103] {
        let frames = if version >= 102 { 2 } else { 1 };
        put(
            binary,
            &format!("mmpld-{version}-intensity"),
            2 | 3 << 2,
            &mmpld(version, frames, true),
        );
        put(
            binary,
            &format!("mmpld-{version}"),
            2,
            &mmpld(version, frames, false),
        );
    }
    put(binary, "mmpld-sniffed", 3, &mmpld(103, 1, false));
    // Raw-array sidecars (mode bit 4) naming the arrays the target writes beside them.
    let raw_full = r#"{"mdlod_raw": 1, "particles": 10,
        "positions": {"file": "pos.f32", "type": "f32", "layout": "interleaved"},
        "species": {"file": "type.u8", "type": "u8", "names": ["Cu", "Ag", "Ni"]},
        "radii": [1.28, 1.44, 1.25],
        "attribute": {"file": "pe.f32", "type": "f32", "name": "c_pe"},
        "box": {"origin": [0, 0, 0], "a": [10, 0, 0], "b": [0, 10, 0], "c": [0, 0, 10]},
        "timestep": 1000, "time": 2.0, "units": "metal"}"#;
    let raw_planar = r#"{"mdlod_raw": 1,
        "positions": {"file": "pos.f64", "type": "f64", "layout": "planar", "offset": 0,
                      "byte_order": "little"}}"#;
    put(binary, "raw-full", 16 | 1 << 2, raw_full.as_bytes());
    put(binary, "raw-planar", 16, raw_planar.as_bytes());

    let tmp = tempfile::tempdir().unwrap();
    let cases = [
        (1, false, BuildParams::default()),
        (9, false, BuildParams::default()),
        (
            300,
            true,
            BuildParams {
                max_root_points: 8,
                ..Default::default()
            },
        ),
        (
            300,
            false,
            BuildParams {
                max_cluster_size: 4,
                max_root_points: 6,
                delta_n: 2,
                position_bits: 8,
            },
        ),
        // Node levels of more than one block of lazily checked records (256 nodes):
        // mutations reach the block boundaries.
        (
            1200,
            false,
            BuildParams {
                max_cluster_size: 2,
                max_root_points: 8,
                ..Default::default()
            },
        ),
    ];
    for (i, (n, attribute, build)) in cases.into_iter().enumerate() {
        let path = tmp.path().join("seed.mdlod");
        let opts = ConvertOptions {
            build,
            radii: vec![],
            ..Default::default()
        };
        convert_frame(&frame(n, attribute), None, &path, &opts, &NoProgress).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        // Mode 1 (checksums recomputed) lets mutations reach the structural checks; mode 0
        // keeps the file as it is; mode 3 also leaves the node records to be checked as
        // they are read (as for large files).
        put(mdlod, &format!("valid-{i}-resealed"), 1, &bytes);
        put(mdlod, &format!("valid-{i}"), 0, &bytes);
        put(mdlod, &format!("valid-{i}-resealed-lazy"), 3, &bytes);
    }

    let lammps_custom = "ITEM: UNITS\nmetal\nITEM: TIME\n0.5\nITEM: TIMESTEP\n100\n\
        ITEM: NUMBER OF ATOMS\n3\nITEM: BOX BOUNDS pp pp ff\n0 10\n0 10\n0 10\n\
        ITEM: ATOMS id type x y z c_pe q\n1 1 0.5 0.5 0.5 -3.2 0.1\n2 2 1.5 1.5 1.5 -3.1 -0.1\n\
        3 1 2.5 2.5 2.5 -3.0 0\nITEM: TIMESTEP\n200\nITEM: NUMBER OF ATOMS\n1\n\
        ITEM: BOX BOUNDS pp pp pp\n0 10\n0 10\n0 10\nITEM: ATOMS id element xu yu zu\n1 Cu 1 2 3\n";
    let lammps_triclinic = "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n2\n\
        ITEM: BOX BOUNDS xy xz yz pp pp pp\n-1 11 1\n0 10 0\n0 10 0\n\
        ITEM: ATOMS id type xs ys zs\n1 1 0.1 0.2 0.3\n2 1 0.9 0.8 0.7\n";
    let lammps_general = "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n1\n\
        ITEM: BOX BOUNDS abc origin pp pp pp\n10 0 0 0\n1 10 0 0\n0 0 10 0\n\
        ITEM: ATOMS id type xsu ysu zsu\n1 1 0.5 0.5 0.5\n";
    let lammps_old =
        "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n2\nITEM: BOX BOUNDS\n0 1\n0 1\n0 1\n\
        ITEM: ATOMS\n1 1 0.1 0.1 0.1\n2 2 0.2 0.2 0.2\n";
    let xyz = "3\nLattice=\"10 0 0 0 10 0 0 0 10\" Properties=species:S:1:pos:R:3:q:R:1 \
        Time=1.5 pbc=\"T T F\"\nCu 0 0 0 0.1\nAg 1 1 1 -0.1\nCu 2 2 2 0\n\
        1\nplain comment\nH 0.5 0.5 0.5\n";
    // Mode bits 0-1 pick the file name, bits 2-3 the attribute (see lammps_dump.rs).
    put(dumps, "lammps-custom", 1 << 2, lammps_custom.as_bytes());
    put(
        dumps,
        "lammps-custom-q",
        3 | 2 << 2,
        lammps_custom.as_bytes(),
    );
    put(dumps, "lammps-triclinic", 0, lammps_triclinic.as_bytes());
    put(dumps, "lammps-general", 0, lammps_general.as_bytes());
    put(dumps, "lammps-old", 3, lammps_old.as_bytes());
    put(dumps, "xyz", 1 | 2 << 2, xyz.as_bytes());
    put(dumps, "xyz-sniffed", 3, xyz.as_bytes());
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
    std::io::Write::write_all(&mut gz, xyz.as_bytes()).unwrap();
    put(dumps, "xyz-gz", 2, &gz.finish().unwrap());
    // Whole conversions of text dumps (see convert_dump.rs): the seeds of the text
    // readers, and a 300-atom frame of a real LAMMPS dump (built in chunks of 64).
    let conversions = Path::new("corpus/convert_dump");
    std::fs::create_dir_all(conversions).unwrap();
    for entry in std::fs::read_dir(dumps).unwrap() {
        let entry = entry.unwrap();
        std::fs::copy(entry.path(), conversions.join(entry.file_name())).unwrap();
    }
    let melt = std::fs::read_to_string("../datasets/lammps/cu_melt.custom.dump").unwrap();
    let lines: Vec<&str> = melt.lines().collect();
    let atoms = lines
        .iter()
        .position(|l| l.starts_with("ITEM: ATOMS"))
        .unwrap();
    let mut frame: Vec<String> = lines[..=atoms].iter().map(|l| l.to_string()).collect();
    let count = lines
        .iter()
        .position(|l| *l == "ITEM: NUMBER OF ATOMS")
        .unwrap()
        + 1;
    frame[count] = "300".into();
    frame.extend(lines[atoms + 1..atoms + 301].iter().map(|l| l.to_string()));
    put(
        conversions,
        "melt-300",
        1 << 2,
        (frame.join("\n") + "\n").as_bytes(),
    );

    // Particles for the converter (see convert_frame.rs): a jittered lattice, in memory
    // and in chunks, with an attribute; coincident points; radii from the first record.
    let particles = Path::new("corpus/convert_frame");
    std::fs::create_dir_all(particles).unwrap();
    let record = |p: [f32; 3], species: u8, value: u16| {
        let mut r = Vec::with_capacity(16);
        p.iter().for_each(|v| r.extend_from_slice(&v.to_le_bytes()));
        r.push(species);
        r.push(0);
        r.extend_from_slice(&value.to_le_bytes());
        r
    };
    let lattice: Vec<u8> = (0..300)
        .flat_map(|i| {
            let p = [(i % 7) as f32, ((i / 7) % 6) as f32, (i / 42) as f32];
            record(
                p.map(|v| v * 2.5 + (i % 3) as f32 * 0.1),
                (i % 5 == 0) as u8,
                i as u16,
            )
        })
        .collect();
    let same: Vec<u8> = (0..100).flat_map(|_| record([1.0; 3], 0, 0)).collect();
    let mut radii = record([1.5, 0.25, 0.0], 0, 0);
    radii.extend_from_slice(&lattice[..16 * 80]);
    for (name, mode, bytes) in [
        ("lattice", 2 | 32, &lattice),
        ("lattice-chunked", 2 | 32 | 64, &lattice),
        ("lattice-u8-dn2", 1 | 4 | 8, &lattice),
        ("coincident", 2 | 64, &same),
        ("radii", 2 | 128, &radii),
    ] {
        let mut seed = vec![mode, 40];
        seed.extend_from_slice(bytes);
        std::fs::write(particles.join(name), seed).unwrap();
    }
    // S-NDF files (see sndf_file.rs): one image of 6x4 texels and S-MIP tiles (one of
    // level 0, one of level 1) of an orthographic view, 2x2 bins; checksums intact (mode
    // bit 0 reseals mutated ones).
    let sndfs = Path::new("corpus/sndf_file");
    std::fs::create_dir_all(sndfs).unwrap();
    // Up to a quarter of the rays per bin: a texel's four bins add up to at most its rays.
    let bin = |i: usize, rays: f32| {
        let count = (i % 5) as f32 / 16.0 * rays;
        [0.5 * count, 0.25 * count, 0.125 * count, count]
    };
    let image = SndfData {
        header: SndfHeader {
            width: 6,
            height: 4,
            bins: 2,
            binning: "projected-normals".into(),
            rays: 4,
            view: serde_json::json!({"version": 1, "azimuth_deg": 30.0}),
            source: Some("crater.mdlod".into()),
            display_level: None,
            normal_frame: None,
            smip: None,
        },
        hist: (0..6 * 4 * 4).map(|i| bin(i, 4.0)).collect(),
    };
    let tile_texels = (SNDF_TILE * SNDF_TILE * 4) as usize;
    let tiles = SndfData {
        header: SndfHeader {
            width: 96,
            height: 64,
            bins: 2,
            binning: "lambert-equal-area".into(),
            rays: 2,
            view: serde_json::json!({
                "version": 1, "projection": "orthographic", "azimuth_deg": 30.0,
                "elevation_deg": 20.0, "target": [0.0, 0.0, 0.0], "distance": 10.0,
                "zoom": 1.0, "fov_y_deg": 30.0
            }),
            source: None,
            display_level: Some(0),
            normal_frame: None,
            smip: Some(SndfTiles {
                texel0: 0.05,
                origin: [-2.4, 1.6],
                tile: SNDF_TILE,
                tiles: vec![
                    SndfTile {
                        level: 0,
                        x: 0,
                        y: 0,
                        rays: 4,
                    },
                    SndfTile {
                        level: 1,
                        x: 0,
                        y: 0,
                        rays: 2,
                    },
                ],
            }),
        },
        hist: (0..2 * tile_texels)
            .map(|i| bin(i, if i < tile_texels { 4.0 } else { 2.0 }))
            .collect(),
    };
    let scratch = tempfile::tempdir().unwrap();
    for (name, data) in [("image", &image), ("tiles", &tiles)] {
        let file = scratch.path().join("seed.sndf");
        data.save(&file).unwrap();
        put(sndfs, name, 1, &std::fs::read(&file).unwrap());
    }

    println!(
        "seeds written to {}, {}, {}, {} and {}",
        mdlod.display(),
        dumps.display(),
        binary.display(),
        particles.display(),
        sndfs.display()
    );
}
