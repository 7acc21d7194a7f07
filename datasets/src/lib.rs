//! Deterministic, seeded generators of MD-like particle data, written as LAMMPS text dumps.
//!
//! Three [`Kind`]s of sample, each sized by a particle target (any count from 1; meant
//! for 10^3 to 10^8 and beyond), are written frame by frame to any [`std::io::Write`]:
//!
//! - [`Kind::Crater`]: a Cu(001) slab (FCC, a = 3.615 Å) with a hemispherical crater, a
//!   crown of atoms thrown up around the rim (denser at its foot, thinning with height,
//!   with azimuthal fingers) and small spherical FCC droplets flying above. One species;
//!   extra column `c_ke` (hot near the crater bottom, hotter in crown and droplets).
//! - [`Kind::Alloy`]: a Cu FCC block with embedded Ag spheres (type 2, each on its own
//!   Ag lattice, a = 4.086 Å, centred on the sphere). Extra column `c_pe`.
//! - [`Kind::Droplets`]: a "liquid" film (an FCC lattice jittered by up to ±0.35 Å per
//!   axis) with holes, on a four-plane Cu substrate (type 2), torn into spheroidal liquid
//!   droplets above it. Extra column `v_temp`.
//!
//! The crate also indexes the small real LAMMPS dumps committed in `datasets/lammps/`
//! ([`LAMMPS_SAMPLES`], [`lammps_sample_path`]) so that reader tests can find them.
//!
//! # How it works
//!
//! - **Exact counts without storing particles.** Each sample is a short list of components
//!   (lattice blocks cut by spheres, craters and cylinders; lattice clusters inside
//!   ellipsoids; a random crown). An FCC lattice is `h·(X, Y, Z)` with `X + Y + Z` even, so
//!   each row of a cut lattice is an integer interval, and the number of sites in any
//!   component is a sum of O(1) terms per row: no pass over the sites, no memory. All
//!   fixed parts are counted exactly first; one "filler" lattice (slab, block, film) then
//!   stacks atomic planes until the total is exactly the target, its last plane partly
//!   filled (a terrace). Writing walks the very same rows, so the header count is right.
//! - **Streaming.** Atoms are formatted one by one into a 256 KiB buffer that is handed
//!   to the writer; memory does not grow with the particle count. Floats are written as
//!   fixed-point with 4 decimals by a small hand-written formatter (well over ten million
//!   lines per CPU-second; see the crate README for measured numbers).
//! - **Crystal lattices.** Lattice sites are written exactly: the slab/block/substrate
//!   sites of frame 0 at multiples of `a/2` (later frames: times the frame's scale), so
//!   whole planes of atoms share one x, y or z value, which octree builders must
//!   survive. Positions are otherwise distinct: separate components do not overlap, random
//!   (crown) positions are continuous, and liquid jitter is far below half the neighbour
//!   distance. [`GenerateOptions::duplicates`] deliberately repeats positions.
//! - **Periodic box.** `pp pp pp` with the lower corner at the origin. x and y are
//!   wrapped into `[0, L)` after rounding, so every written coordinate is inside the
//!   written box; z has vacuum above the highest particle.
//! - **Frames.** Frame `f` has timestep `100·f`. The whole sample expands slowly and
//!   homogeneously (by at most 0.3 %, so lattice planes stay exactly planar), droplets fly
//!   (about 0.3–2 Å per frame), the crown grows, liquid atoms rattle, and the scalar
//!   column is redrawn. Ids and order are the same in every frame.
//! - **Determinism.** A hand-written SplitMix64 generator, seeded per component and frame
//!   from [`GenerateOptions::seed`]: same options, same bytes (on one platform; only libm's
//!   `ln`/`exp`/`sin`/`cos` in the crown could differ in the last bit elsewhere).

mod kinds;
mod lattice;
mod plan;
mod rng;
mod samples;
mod sink;

use std::fmt;
use std::io::{self, Write};
use std::path::Path;
use std::str::FromStr;

pub use kinds::{AG_LATTICE, CU_LATTICE};
pub use samples::{
    gsd_sample_path, lammps_sample, lammps_sample_column, lammps_sample_path, lammps_samples_dir,
    to_old_revision, LammpsSample, LAMMPS_SAMPLES,
};
/// Digits after the decimal point of every coordinate and scalar written.
pub use sink::DECIMALS;

/// Which kind of sample to generate.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
pub enum Kind {
    /// Cu slab with a laser-ablation-like crater, crown and droplets (1 species).
    #[default]
    Crater,
    /// Cu block with embedded Ag spheres (2 species).
    Alloy,
    /// Liquid film with holes on a substrate, and droplets above (2 species).
    Droplets,
}

impl Kind {
    /// All kinds, in a fixed order.
    pub const ALL: [Kind; 3] = [Kind::Crater, Kind::Alloy, Kind::Droplets];

    /// Lower-case name, as accepted by [`FromStr`].
    pub fn name(self) -> &'static str {
        match self {
            Kind::Crater => "crater",
            Kind::Alloy => "alloy",
            Kind::Droplets => "droplets",
        }
    }

    /// Name of the extra scalar column after `id type x y z`.
    pub fn extra_column(self) -> &'static str {
        match self {
            Kind::Crater => "c_ke",
            Kind::Alloy => "c_pe",
            Kind::Droplets => "v_temp",
        }
    }
}

impl fmt::Display for Kind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Error of [`Kind::from_str`].
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ParseKindError(pub String);

impl fmt::Display for ParseKindError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "unknown dataset kind '{}' (expected crater, alloy or droplets)",
            self.0
        )
    }
}

impl std::error::Error for ParseKindError {}

impl FromStr for Kind {
    type Err = ParseKindError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Kind::ALL
            .into_iter()
            .find(|k| k.name().eq_ignore_ascii_case(s.trim()))
            .ok_or_else(|| ParseKindError(s.to_string()))
    }
}

/// What to generate.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct GenerateOptions {
    pub kind: Kind,
    /// Exact number of particles per frame (lines after `ITEM: ATOMS`), at least 1.
    pub particles: u64,
    /// Seed of every random choice; the same options always give the same bytes.
    pub seed: u64,
    /// Number of frames, at least 1; timesteps are 0, 100, 200, ...
    pub frames: u32,
    /// How many of the `particles` lines repeat the position (and type and scalar) of
    /// the line just before them, with their own id; spread evenly through each frame.
    /// At most `particles / 2`. Default 0: all positions distinct.
    pub duplicates: u64,
}

impl GenerateOptions {
    /// `particles` of `kind`, seed 1, one frame, no duplicates.
    pub fn new(kind: Kind, particles: u64) -> Self {
        GenerateOptions {
            kind,
            particles,
            seed: 1,
            frames: 1,
            duplicates: 0,
        }
    }

    fn validate(&self) -> io::Result<()> {
        let bad = |msg: String| Err(io::Error::new(io::ErrorKind::InvalidInput, msg));
        if self.particles == 0 {
            return bad("particles must be at least 1".into());
        }
        if self.frames == 0 {
            return bad("frames must be at least 1".into());
        }
        if self.duplicates > self.particles / 2 {
            return bad(format!(
                "duplicates ({}) must be at most half of particles ({})",
                self.duplicates, self.particles
            ));
        }
        Ok(())
    }
}

impl Default for GenerateOptions {
    fn default() -> Self {
        GenerateOptions::new(Kind::Crater, 1_000_000)
    }
}

/// An orthogonal box, `lo` inclusive and `hi` exclusive, as written (rounded to 4
/// decimals).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BoxBounds {
    pub lo: [f64; 3],
    pub hi: [f64; 3],
}

impl BoxBounds {
    fn rounded(self) -> Self {
        let r = |v: [f64; 3]| v.map(|x| sink::quantize(x) as f64 / 10_000.0);
        BoxBounds {
            lo: r(self.lo),
            hi: r(self.hi),
        }
    }

    fn union(self, o: BoxBounds) -> Self {
        BoxBounds {
            lo: [0, 1, 2].map(|k| self.lo[k].min(o.lo[k])),
            hi: [0, 1, 2].map(|k| self.hi[k].max(o.hi[k])),
        }
    }

    /// True when `p` lies in `[lo, hi)` on every axis.
    pub fn contains(&self, p: [f64; 3]) -> bool {
        (0..3).all(|k| self.lo[k] <= p[k] && p[k] < self.hi[k])
    }
}

/// What [`write_lammps_dump`] wrote.
#[derive(Clone, Debug, PartialEq)]
pub struct Summary {
    /// Particles in each frame (= `GenerateOptions::particles`).
    pub particles: u64,
    pub frames: u32,
    /// Atom lines in all frames.
    pub total_particles: u64,
    pub bytes: u64,
    /// Number of atom types (1 or 2).
    pub species: u32,
    /// Name of the extra column.
    pub extra_column: &'static str,
    /// Box of frame 0.
    pub first_box: BoxBounds,
    /// Smallest box holding the boxes of all frames (they grow slightly).
    pub bounds: BoxBounds,
}

/// Writes a LAMMPS text dump (`ITEM: ATOMS id type x y z <extra>`) to `out`.
///
/// `progress` is called with the number of atom lines written so far (all frames
/// together) every 65 536 lines and once at the end. The writer is flushed at the end;
/// pass a raw `File`, the generator buffers by itself.
///
/// ```
/// use mdlod_datasets::{write_lammps_dump, GenerateOptions, Kind};
///
/// let mut opts = GenerateOptions::new(Kind::Alloy, 2000);
/// opts.frames = 2;
/// let mut out = Vec::new();
/// let summary = write_lammps_dump(&opts, &mut out, |_| {}).unwrap();
/// let text = String::from_utf8(out).unwrap();
/// assert_eq!(summary.total_particles, 4000);
/// assert_eq!(text.lines().count(), 2 * (9 + 2000));
/// assert!(text.contains("ITEM: ATOMS id type x y z c_pe\n"));
/// assert_eq!(summary.species, 2);
/// ```
pub fn write_lammps_dump<W: Write + ?Sized>(
    opts: &GenerateOptions,
    out: &mut W,
    progress: impl FnMut(u64),
) -> io::Result<Summary> {
    write_text(opts, out, progress, TextFormat::Lammps)
}

/// Writes the same frames as [`write_lammps_dump`] as extended XYZ to `out`: per frame
/// the atom count, a comment line with the box (`Lattice`, `Origin`, `pbc="T T T"`),
/// `Properties=species:S:1:pos:R:3:<extra>:R:1` and `Timestep`, then one line per atom
/// (`<type> x y z <extra>`: the LAMMPS type number as the species name, the values
/// exactly those of the dump, without the ids).
///
/// ```
/// use mdlod_datasets::{write_xyz, GenerateOptions, Kind};
///
/// let mut out = Vec::new();
/// let summary = write_xyz(&GenerateOptions::new(Kind::Crater, 500), &mut out, |_| {}).unwrap();
/// let text = String::from_utf8(out).unwrap();
/// assert_eq!(summary.total_particles, 500);
/// assert_eq!(text.lines().count(), 2 + 500);
/// assert!(text.lines().nth(1).unwrap().contains("Properties=species:S:1:pos:R:3:c_ke:R:1"));
/// ```
pub fn write_xyz<W: Write + ?Sized>(
    opts: &GenerateOptions,
    out: &mut W,
    progress: impl FnMut(u64),
) -> io::Result<Summary> {
    write_text(opts, out, progress, TextFormat::Xyz)
}

/// The text formats the generator writes.
#[derive(Clone, Copy, PartialEq, Eq)]
enum TextFormat {
    Lammps,
    Xyz,
}

fn write_text<W: Write + ?Sized>(
    opts: &GenerateOptions,
    out: &mut W,
    mut progress: impl FnMut(u64),
    format: TextFormat,
) -> io::Result<Summary> {
    opts.validate()?;
    let base = opts.particles - opts.duplicates;
    let plan = match opts.kind {
        Kind::Crater => kinds::crater(base, opts.seed),
        Kind::Alloy => kinds::alloy(base, opts.seed),
        Kind::Droplets => kinds::droplets(base, opts.seed),
    };
    debug_assert!(plan.total() >= base);
    let mut sink = sink::Sink::new(out, &mut progress);
    if format == TextFormat::Xyz {
        sink.set_without_ids();
    }
    let first_box = plan.bounds(0).rounded();
    let mut bounds = first_box;
    let column = opts.kind.extra_column();
    for f in 0..opts.frames {
        let bx = plan.bounds(f).rounded();
        bounds = bounds.union(bx);
        let v = sink::format_fixed4;
        let header = match format {
            TextFormat::Lammps => format!(
                "ITEM: TIMESTEP\n{}\nITEM: NUMBER OF ATOMS\n{}\nITEM: BOX BOUNDS pp pp pp\n\
                 {} {}\n{} {}\n{} {}\nITEM: ATOMS id type x y z {column}\n",
                100 * f as u64,
                opts.particles,
                v(bx.lo[0]),
                v(bx.hi[0]),
                v(bx.lo[1]),
                v(bx.hi[1]),
                v(bx.lo[2]),
                v(bx.hi[2]),
            ),
            TextFormat::Xyz => format!(
                "{}\nLattice=\"{} 0 0 0 {} 0 0 0 {}\" Origin=\"{} {} {}\" pbc=\"T T T\" \
                 Properties=species:S:1:pos:R:3:{column}:R:1 Timestep={}\n",
                opts.particles,
                v(bx.hi[0] - bx.lo[0]),
                v(bx.hi[1] - bx.lo[1]),
                v(bx.hi[2] - bx.lo[2]),
                v(bx.lo[0]),
                v(bx.lo[1]),
                v(bx.lo[2]),
                100 * f as u64,
            ),
        };
        sink.raw(header.as_bytes())?;
        sink.begin_frame(base, opts.duplicates, [bx.hi[0], bx.hi[1]]);
        plan.emit(opts.seed, f, &mut sink)?;
        if sink.base_written != base {
            return Err(io::Error::other(format!(
                "internal error: generated {} of {} particles",
                sink.base_written, base
            )));
        }
    }
    sink.finish()?;
    Ok(Summary {
        particles: opts.particles,
        frames: opts.frames,
        total_particles: sink.total_lines,
        bytes: sink.bytes,
        species: plan.species,
        extra_column: column,
        first_box,
        bounds,
    })
}

/// Writes one frame as raw arrays with a `*.raw.json` sidecar (the input for the
/// largest conversions: no parsing, a window at a time): `STEM.pos.f32` (x y z per
/// particle), `STEM.type.u8` (LAMMPS type − 1, named by the type number),
/// `STEM.EXTRA.f32` (the extra column) and `STEM.raw.json`. The values are exactly those
/// the text dump of the same options holds. Returns the sidecar's path with the summary.
pub fn write_raw_arrays(
    opts: &GenerateOptions,
    dir: &Path,
    stem: &str,
    mut progress: impl FnMut(u64),
) -> io::Result<(std::path::PathBuf, Summary)> {
    opts.validate()?;
    if opts.frames != 1 {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            "raw arrays hold one frame",
        ));
    }
    let base = opts.particles - opts.duplicates;
    let plan = match opts.kind {
        Kind::Crater => kinds::crater(base, opts.seed),
        Kind::Alloy => kinds::alloy(base, opts.seed),
        Kind::Droplets => kinds::droplets(base, opts.seed),
    };
    let column = opts.kind.extra_column();
    let names = [
        format!("{stem}.pos.f32"),
        format!("{stem}.type.u8"),
        format!("{stem}.{column}.f32"),
    ];
    // A sidecar of an earlier generation goes first, and the new one is written last,
    // through a temporary file renamed into place: arrays stopped half way are never
    // described by a sidecar (a batch reads a frame by its sidecar).
    let path = dir.join(format!("{stem}.raw.json"));
    match std::fs::remove_file(&path) {
        Err(e) if e.kind() != io::ErrorKind::NotFound => return Err(e),
        _ => {}
    }
    let create = |n: &str| {
        std::fs::File::create(dir.join(n)).map(|f| io::BufWriter::with_capacity(1 << 20, f))
    };
    let (mut pos, mut types, mut extra) = (
        std::fs::File::create(dir.join(&names[0]))?,
        create(&names[1])?,
        create(&names[2])?,
    );
    let mut sink = sink::Sink::new(&mut pos, &mut progress);
    sink.set_binary(sink::BinaryOut::new(&mut types, &mut extra));
    let bx = plan.bounds(0).rounded();
    sink.begin_frame(base, opts.duplicates, [bx.hi[0], bx.hi[1]]);
    plan.emit(opts.seed, 0, &mut sink)?;
    sink.finish()?;
    let total = sink.total_lines;
    drop(sink);
    let type_names: Vec<String> = (1..=plan.species).map(|t| t.to_string()).collect();
    let sidecar = serde_json::json!({
        "mdlod_raw": 1,
        "particles": total,
        "positions": { "file": names[0], "type": "f32" },
        "species": { "file": names[1], "type": "u8", "names": type_names },
        "attribute": { "file": names[2], "type": "f32", "name": column },
        "box": {
            "origin": bx.lo,
            "a": [bx.hi[0] - bx.lo[0], 0.0, 0.0],
            "b": [0.0, bx.hi[1] - bx.lo[1], 0.0],
            "c": [0.0, 0.0, bx.hi[2] - bx.lo[2]],
        },
        "timestep": 0,
    });
    let temp = dir.join(format!(".{stem}.raw.json.tmp"));
    std::fs::write(&temp, serde_json::to_vec_pretty(&sidecar)?)?;
    std::fs::rename(&temp, &path)?;
    let bytes = names
        .iter()
        .map(|n| std::fs::metadata(dir.join(n)).map_or(0, |m| m.len()))
        .sum();
    Ok((
        path,
        Summary {
            particles: opts.particles,
            frames: 1,
            total_particles: total,
            bytes,
            species: plan.species,
            extra_column: column,
            first_box: bx,
            bounds: bx,
        },
    ))
}

/// [`write_lammps_dump`] into a new file at `path` (truncated if it exists).
pub fn write_lammps_dump_to_path(
    opts: &GenerateOptions,
    path: impl AsRef<Path>,
    progress: impl FnMut(u64),
) -> io::Result<Summary> {
    let mut file = std::fs::File::create(path)?;
    write_lammps_dump(opts, &mut file, progress)
}

/// The sites of an FCC block of `cells[0] × cells[1] × cells[2]` unit cells with lattice
/// constant `a`, starting at the origin, in cell order (x outermost, then y, z, then the
/// four basis sites): a small exact lattice for tests.
pub fn fcc_block(cells: [usize; 3], a: f32) -> Vec<[f32; 3]> {
    const BASIS: [[f32; 3]; 4] = [
        [0.0, 0.0, 0.0],
        [0.5, 0.5, 0.0],
        [0.5, 0.0, 0.5],
        [0.0, 0.5, 0.5],
    ];
    let mut sites = Vec::with_capacity(4 * cells[0] * cells[1] * cells[2]);
    for i in 0..cells[0] {
        for j in 0..cells[1] {
            for k in 0..cells[2] {
                for b in BASIS {
                    sites.push([
                        (i as f32 + b[0]) * a,
                        (j as f32 + b[1]) * a,
                        (k as f32 + b[2]) * a,
                    ]);
                }
            }
        }
    }
    sites
}
