//! Writes a generated LAMMPS dump and reports the throughput.
//!
//! ```text
//! cargo run --release -p mdlod-datasets --example generate -- KIND PARTICLES [OUT] [SEED] [FRAMES]
//! ```
//! `OUT` defaults to `data/KIND-PARTICLES.lammpstrj`; `-` discards the output (timing only).

use std::io;
use std::time::Instant;

use mdlod_datasets::{write_lammps_dump, GenerateOptions, Kind};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 2 {
        eprintln!("usage: generate KIND PARTICLES [OUT|-] [SEED] [FRAMES]");
        std::process::exit(2);
    }
    let kind: Kind = args[0].parse()?;
    let particles: u64 = args[1].parse()?;
    let mut opts = GenerateOptions::new(kind, particles);
    if let Some(s) = args.get(3) {
        opts.seed = s.parse()?;
    }
    if let Some(f) = args.get(4) {
        opts.frames = f.parse()?;
    }
    let out = args
        .get(2)
        .cloned()
        .unwrap_or_else(|| format!("data/{kind}-{particles}.lammpstrj"));
    let start = Instant::now();
    let summary = if out == "-" {
        write_lammps_dump(&opts, &mut io::sink(), |_| {})?
    } else {
        if let Some(dir) = std::path::Path::new(&out).parent() {
            std::fs::create_dir_all(dir)?;
        }
        let mut file = std::fs::File::create(&out)?;
        write_lammps_dump(&opts, &mut file, |_| {})?
    };
    let secs = start.elapsed().as_secs_f64();
    eprintln!(
        "{} particles x {} frames, {:.1} MB in {:.3} s: {:.2} M particles/s, {:.0} MB/s -> {}",
        summary.particles,
        summary.frames,
        summary.bytes as f64 / 1e6,
        secs,
        summary.total_particles as f64 / secs / 1e6,
        summary.bytes as f64 / secs / 1e6,
        out
    );
    eprintln!("box {:?}", summary.bounds);
    Ok(())
}
