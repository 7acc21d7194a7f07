//! End-to-end checks of the generated LAMMPS dumps, parsed back as text.

use std::collections::HashSet;

use mdlod_datasets::{write_lammps_dump, BoxBounds, GenerateOptions, Kind, Summary};

/// One parsed frame.
struct Frame {
    timestep: u64,
    bounds: BoxBounds,
    columns: Vec<String>,
    /// (id, type, position, extra) per atom line.
    atoms: Vec<(u64, u32, [f64; 3], f64)>,
    /// The raw position text, for exact-duplicate checks.
    keys: Vec<String>,
}

fn parse(text: &str) -> Vec<Frame> {
    let mut lines = text.lines();
    let mut frames = Vec::new();
    while let Some(l) = lines.next() {
        assert_eq!(l, "ITEM: TIMESTEP");
        let timestep = lines.next().unwrap().trim().parse().unwrap();
        assert_eq!(lines.next().unwrap(), "ITEM: NUMBER OF ATOMS");
        let n: usize = lines.next().unwrap().trim().parse().unwrap();
        assert_eq!(lines.next().unwrap(), "ITEM: BOX BOUNDS pp pp pp");
        let mut lo = [0.0; 3];
        let mut hi = [0.0; 3];
        for k in 0..3 {
            let v: Vec<f64> = lines
                .next()
                .unwrap()
                .split_whitespace()
                .map(|s| s.parse().unwrap())
                .collect();
            lo[k] = v[0];
            hi[k] = v[1];
        }
        let cols = lines.next().unwrap();
        let columns: Vec<String> = cols
            .strip_prefix("ITEM: ATOMS ")
            .unwrap()
            .split_whitespace()
            .map(String::from)
            .collect();
        let mut atoms = Vec::with_capacity(n);
        let mut keys = Vec::with_capacity(n);
        for _ in 0..n {
            let l = lines.next().expect("fewer atom lines than announced");
            let f: Vec<&str> = l.split_whitespace().collect();
            assert_eq!(f.len(), 6, "{l}");
            atoms.push((
                f[0].parse().unwrap(),
                f[1].parse().unwrap(),
                [
                    f[2].parse().unwrap(),
                    f[3].parse().unwrap(),
                    f[4].parse().unwrap(),
                ],
                f[5].parse().unwrap(),
            ));
            keys.push(format!("{} {} {}", f[2], f[3], f[4]));
        }
        frames.push(Frame {
            timestep,
            bounds: BoxBounds { lo, hi },
            columns,
            atoms,
            keys,
        });
    }
    frames
}

fn generate(opts: &GenerateOptions) -> (Vec<u8>, Summary) {
    let mut out = Vec::new();
    let mut last = 0;
    let summary = write_lammps_dump(opts, &mut out, |n| {
        assert!(n >= last);
        last = n;
    })
    .unwrap();
    assert_eq!(last, summary.total_particles);
    assert_eq!(summary.bytes, out.len() as u64);
    (out, summary)
}

fn opts(kind: Kind, particles: u64) -> GenerateOptions {
    GenerateOptions::new(kind, particles)
}

#[test]
fn exact_particle_count_for_many_targets() {
    for kind in Kind::ALL {
        for n in [1, 17, 1000, 1001, 4321, 10_007, 65_537, 200_000] {
            let (out, s) = generate(&opts(kind, n));
            let frames = parse(std::str::from_utf8(&out).unwrap());
            assert_eq!(frames.len(), 1);
            assert_eq!(frames[0].atoms.len() as u64, n, "{kind} {n}");
            assert_eq!(s.particles, n);
            assert_eq!(s.total_particles, n);
            let ids: Vec<u64> = frames[0].atoms.iter().map(|a| a.0).collect();
            assert!(ids.iter().copied().eq(1..=n), "{kind} {n}: ids not 1..=N");
        }
    }
}

#[test]
fn same_seed_same_bytes_different_seed_different_bytes() {
    for kind in Kind::ALL {
        let mut o = opts(kind, 30_000);
        o.seed = 42;
        let (a, _) = generate(&o);
        let (b, _) = generate(&o);
        assert!(a == b, "{kind}: not deterministic");
        o.seed = 43;
        let (c, _) = generate(&o);
        assert!(a != c, "{kind}: seed ignored");
    }
}

#[test]
fn box_contains_all_atoms_and_positions_are_distinct() {
    for kind in Kind::ALL {
        for n in [1000, 50_000] {
            let mut o = opts(kind, n);
            o.frames = 3;
            let (out, s) = generate(&o);
            let frames = parse(std::str::from_utf8(&out).unwrap());
            assert_eq!(frames[0].bounds, s.first_box);
            for fr in &frames {
                for a in &fr.atoms {
                    assert!(
                        fr.bounds.contains(a.2),
                        "{kind}: {:?} outside {:?}",
                        a,
                        fr.bounds
                    );
                    assert!(s.bounds.contains(a.2));
                }
                let distinct: HashSet<&String> = fr.keys.iter().collect();
                assert_eq!(
                    distinct.len(),
                    fr.keys.len(),
                    "{kind} {n}: duplicate positions"
                );
            }
        }
    }
}

#[test]
fn header_columns_and_species() {
    for kind in Kind::ALL {
        let (out, s) = generate(&opts(kind, 20_000));
        let frames = parse(std::str::from_utf8(&out).unwrap());
        let f = &frames[0];
        assert_eq!(
            f.columns,
            ["id", "type", "x", "y", "z", kind.extra_column()]
        );
        let types: HashSet<u32> = f.atoms.iter().map(|a| a.1).collect();
        let want: HashSet<u32> = (1..=s.species).collect();
        assert_eq!(types, want, "{kind}");
        assert!(f.atoms.iter().all(|a| a.3.is_finite()));
    }
    // Two species from the smallest supported size up.
    for n in [1000, 3000, 100_000] {
        let (out, s) = generate(&opts(Kind::Alloy, n));
        assert_eq!(s.species, 2);
        let frames = parse(std::str::from_utf8(&out).unwrap());
        let ag = frames[0].atoms.iter().filter(|a| a.1 == 2).count();
        assert!(ag > 0 && ag < n as usize / 2, "alloy {n}: {ag} Ag atoms");
    }
}

#[test]
fn crystal_planes_are_exactly_repeated() {
    for kind in Kind::ALL {
        let (out, _) = generate(&opts(kind, 40_000));
        let frames = parse(std::str::from_utf8(&out).unwrap());
        let zs: HashSet<u64> = frames[0].atoms.iter().map(|a| a.2[2].to_bits()).collect();
        // Thousands of atoms share each lattice plane height.
        let planes = frames[0].atoms.iter().filter(|a| a.2[2] == 0.0).count();
        assert!(
            planes > 100,
            "{kind}: only {planes} atoms in the z = 0 plane"
        );
        assert!(zs.len() < 40_000, "{kind}");
    }
}

#[test]
fn frames_have_increasing_timesteps_and_move() {
    for kind in Kind::ALL {
        let mut o = opts(kind, 5000);
        o.frames = 4;
        let (out, s) = generate(&o);
        assert_eq!(s.frames, 4);
        assert_eq!(s.total_particles, 20_000);
        let frames = parse(std::str::from_utf8(&out).unwrap());
        let steps: Vec<u64> = frames.iter().map(|f| f.timestep).collect();
        assert_eq!(steps, [0, 100, 200, 300]);
        for w in frames.windows(2) {
            assert_eq!(w[0].atoms.len(), w[1].atoms.len());
            let moved = w[0]
                .atoms
                .iter()
                .zip(&w[1].atoms)
                .filter(|(a, b)| a.2 != b.2)
                .count();
            assert!(moved > w[0].atoms.len() / 2, "{kind}: frames barely differ");
            let max_step = w[0]
                .atoms
                .iter()
                .zip(&w[1].atoms)
                .map(|(a, b)| {
                    assert_eq!((a.0, a.1), (b.0, b.1));
                    (0..2)
                        .map(|k| {
                            // Ignore wraps through the periodic x/y boundary.
                            let d = (a.2[k] - b.2[k]).abs();
                            d.min(w[0].bounds.hi[k] - d)
                        })
                        .fold((a.2[2] - b.2[2]).abs(), f64::max)
                })
                .fold(0.0, f64::max);
            assert!(max_step < 10.0, "{kind}: a particle jumped {max_step} Å");
        }
    }
}

#[test]
fn duplicates_option_repeats_positions() {
    let mut o = opts(Kind::Crater, 10_000);
    o.duplicates = 250;
    let (out, s) = generate(&o);
    assert_eq!(s.particles, 10_000);
    let frames = parse(std::str::from_utf8(&out).unwrap());
    let f = &frames[0];
    assert_eq!(f.atoms.len(), 10_000);
    let distinct: HashSet<&String> = f.keys.iter().collect();
    assert_eq!(distinct.len(), 10_000 - 250);
    o.duplicates = 5001;
    assert!(write_lammps_dump(&o, &mut Vec::new(), |_| {}).is_err());
}

#[test]
fn invalid_options_are_rejected() {
    let mut o = opts(Kind::Alloy, 0);
    assert!(write_lammps_dump(&o, &mut Vec::new(), |_| {}).is_err());
    o.particles = 10;
    o.frames = 0;
    assert!(write_lammps_dump(&o, &mut Vec::new(), |_| {}).is_err());
}

#[test]
fn kind_parses_and_displays() {
    for k in Kind::ALL {
        assert_eq!(k.to_string().parse::<Kind>().unwrap(), k);
        assert_eq!(k.to_string().to_uppercase().parse::<Kind>().unwrap(), k);
    }
    assert!("lava".parse::<Kind>().is_err());
}

/// Many buffer flushes through a counting writer: byte and line counts agree.
#[test]
fn streams_through_a_counting_writer() {
    struct Count(u64, u64);
    impl std::io::Write for Count {
        fn write(&mut self, b: &[u8]) -> std::io::Result<usize> {
            self.0 += b.len() as u64;
            self.1 += b.iter().filter(|&&c| c == b'\n').count() as u64;
            Ok(b.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }
    for kind in Kind::ALL {
        let mut w = Count(0, 0);
        let s = write_lammps_dump(&opts(kind, 300_000), &mut w, |_| {}).unwrap();
        assert_eq!(w.0, s.bytes);
        assert_eq!(w.1, 300_000 + 9);
    }
}
