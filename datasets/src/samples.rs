//! The small real LAMMPS dumps committed in `datasets/lammps/` (see its README), with what
//! a reader should find in each, for other crates' tests.

use std::path::PathBuf;

/// One committed LAMMPS output file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LammpsSample {
    /// File name inside `datasets/lammps/`.
    pub file: &'static str,
    /// The input script (in the same folder) that wrote it.
    pub input: &'static str,
    /// Atoms per frame (constant).
    pub atoms: u64,
    /// Timesteps of the frames, in file order.
    pub timesteps: &'static [u64],
    /// Column names of `ITEM: ATOMS` (empty for XYZ).
    pub columns: &'static [&'static str],
    /// Text after `ITEM: BOX BOUNDS` (`xy xz yz pp pp pp` for a triclinic box; empty for XYZ).
    pub box_bounds: &'static str,
    /// Gzip-compressed.
    pub gzip: bool,
    /// `ITEM: UNITS` value (written once, before the first frame).
    pub units: Option<&'static str>,
    /// Has `ITEM: TIME` in every frame (timestep × 0.002 ps).
    pub time: bool,
    /// Atom lines sorted by id in every frame.
    pub sorted: bool,
}

const STEPS_6: &[u64] = &[0, 100, 200, 300, 400, 500];
const STEPS_5: &[u64] = &[0, 100, 200, 300, 400];
const STEPS_4: &[u64] = &[0, 100, 200, 300];
const ORTHO: &str = "pp pp pp";
const TRICLINIC: &str = "xy xz yz pp pp pp";

/// Every committed sample.
pub const LAMMPS_SAMPLES: &[LammpsSample] = &[
    LammpsSample {
        file: "cu_melt.custom.dump",
        input: "in.cu_melt",
        atoms: 500,
        timesteps: STEPS_6,
        columns: &["id", "type", "x", "y", "z", "c_pe"],
        box_bounds: ORTHO,
        gzip: false,
        units: Some("metal"),
        time: true,
        sorted: true,
    },
    LammpsSample {
        file: "cu_melt.atom.dump",
        input: "in.cu_melt",
        atoms: 500,
        timesteps: STEPS_6,
        columns: &["id", "type", "xs", "ys", "zs"],
        box_bounds: ORTHO,
        gzip: false,
        units: None,
        time: false,
        sorted: false,
    },
    LammpsSample {
        file: "cu_melt.custom.dump.gz",
        input: "in.cu_melt",
        atoms: 500,
        timesteps: STEPS_6,
        columns: &["id", "type", "x", "y", "z", "vx", "vy", "vz", "c_ke"],
        box_bounds: ORTHO,
        gzip: true,
        units: None,
        time: false,
        sorted: true,
    },
    LammpsSample {
        file: "cu_melt.xyz",
        input: "in.cu_melt",
        atoms: 500,
        timesteps: STEPS_6,
        columns: &[],
        box_bounds: "",
        gzip: false,
        units: None,
        time: false,
        sorted: false,
    },
    LammpsSample {
        file: "cuag_alloy.unwrapped.dump",
        input: "in.cuag_alloy",
        atoms: 864,
        timesteps: STEPS_5,
        columns: &["id", "type", "element", "xu", "yu", "zu", "c_pe"],
        box_bounds: ORTHO,
        gzip: false,
        units: None,
        time: false,
        sorted: true,
    },
    LammpsSample {
        file: "lj_triclinic.scaled.dump",
        input: "in.lj_triclinic",
        atoms: 256,
        timesteps: STEPS_4,
        columns: &["id", "type", "xs", "ys", "zs"],
        box_bounds: TRICLINIC,
        gzip: false,
        units: None,
        time: false,
        sorted: false,
    },
    LammpsSample {
        file: "lj_triclinic.cartesian.dump",
        input: "in.lj_triclinic",
        atoms: 256,
        timesteps: STEPS_4,
        columns: &["id", "type", "x", "y", "z", "v_speed"],
        box_bounds: TRICLINIC,
        gzip: false,
        units: None,
        time: false,
        sorted: true,
    },
    LammpsSample {
        file: "cu_slab.shrinkwrap.dump",
        input: "in.cu_slab",
        atoms: 648,
        timesteps: STEPS_4,
        columns: &["id", "type", "x", "y", "z", "ix", "iy", "iz", "c_ke"],
        box_bounds: "pp pp ss",
        gzip: false,
        units: Some("metal"),
        time: false,
        sorted: true,
    },
];

/// The folder holding the committed samples (`datasets/lammps/` of this source tree).
pub fn lammps_samples_dir() -> PathBuf {
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/lammps"))
}

/// Path of the committed sample `file` (e.g. `"cu_melt.custom.dump"`).
pub fn lammps_sample_path(file: &str) -> PathBuf {
    lammps_samples_dir().join(file)
}

/// The values of `column`, atom by atom, in the first frame of the committed LAMMPS text
/// sample `file` (as written: `1`, `-3.48859`), for tests to check readers against.
pub fn lammps_sample_column(file: &str, column: &str) -> Vec<String> {
    let text = std::fs::read_to_string(lammps_sample_path(file)).expect("a committed sample");
    let mut lines = text.lines();
    let count: usize = lines
        .by_ref()
        .skip_while(|l| !l.starts_with("ITEM: NUMBER OF ATOMS"))
        .nth(1)
        .and_then(|l| l.trim().parse().ok())
        .expect("an atom count");
    let c = lines
        .find(|l| l.starts_with("ITEM: ATOMS"))
        .and_then(|l| l.split_whitespace().skip(2).position(|c| c == column))
        .unwrap_or_else(|| panic!("{file} has no column {column}"));
    lines
        .take(count)
        .map(|l| {
            l.split_whitespace()
                .nth(c)
                .expect("a full line")
                .to_string()
        })
        .collect()
}

/// Path of a committed GSD sample in `datasets/gsd/` (written by the `gsd` Python
/// package; see `datasets/gsd/make-samples.py`).
pub fn gsd_sample_path(file: &str) -> PathBuf {
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/gsd")).join(file)
}

/// The sample entry for `file`, if there is one.
pub fn lammps_sample(file: &str) -> Option<&'static LammpsSample> {
    LAMMPS_SAMPLES.iter().find(|s| s.file == file)
}

/// Rewrites a current-revision binary dump in the old layout (no magic, endian, revision,
/// units, time or column names): how LAMMPS wrote binary dumps before late 2020 (the samples are of
/// the current revision; tests of the old one rewrite them).
pub fn to_old_revision(new: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    let mut p = 0usize;
    let i32_at = |p: usize| i32::from_le_bytes(new[p..p + 4].try_into().unwrap());
    let i64_at = |p: usize| i64::from_le_bytes(new[p..p + 8].try_into().unwrap());
    while p < new.len() {
        let len = (-i64_at(p)) as usize;
        p += 8 + len + 8; // marker, magic, endian + revision
        let triclinic = i32_at(p + 16);
        let fixed = 8 + 8 + 4 + 24 + 48 + if triclinic == 1 { 24 } else { 0 } + 4;
        out.extend_from_slice(&new[p..p + fixed]);
        p += fixed;
        let units = i32_at(p) as usize;
        p += 4 + units;
        p += if new[p] == 1 { 9 } else { 1 };
        let columns = i32_at(p) as usize;
        p += 4 + columns;
        let start = p;
        let nchunk = i32_at(p) as usize;
        p += 4;
        for _ in 0..nchunk {
            p += 4 + 8 * i32_at(p) as usize;
        }
        out.extend_from_slice(&new[start..p]);
    }
    out
}
