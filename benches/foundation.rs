//! Benchmarks of the foundation: parsing, hierarchy build, whole conversion, and OVITO's
//! load time side by side. `cargo bench --bench foundation` prints the tables and
//! rewrites the foundation section of BENCHMARKS.md.
//!
//! Sizes: `MDLOD_BENCH_SIZES` (default `1000000,10000000`). Generated inputs are cached
//! in `data/bench/`.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use mdlod_datasets::{write_lammps_dump_to_path, GenerateOptions, Kind};
use mdlod_preprocess::hierarchy::{build, BuildParams, Particles};
use mdlod_preprocess::readers::{DumpFile, ReadOptions};
use mdlod_preprocess::species::species_table;
use mdlod_preprocess::NoProgress;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn repeats_for(n: u64) -> usize {
    if n <= 2_000_000 {
        5
    } else {
        3
    }
}

fn machine() -> String {
    let cpu = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split(':').nth(1))
                .map(|s| s.trim().to_string())
        })
        .unwrap_or_else(|| "unknown CPU".into());
    let mem = std::fs::read_to_string("/proc/meminfo")
        .ok()
        .and_then(|s| {
            s.lines()
                .next()
                .and_then(|l| l.split_whitespace().nth(1))
                .and_then(|k| k.parse::<u64>().ok())
        })
        .map_or(0.0, |kb| kb as f64 / (1 << 20) as f64);
    format!(
        "{} cores ({cpu}), {mem:.0} GiB RAM",
        std::thread::available_parallelism().map_or(1, |n| n.get())
    )
}

fn input(n: u64) -> PathBuf {
    let path = PathBuf::from(format!("data/bench/crater-{n}.lammpstrj"));
    if !path.exists() {
        std::fs::create_dir_all("data/bench").unwrap();
        eprintln!("generating {}", path.display());
        let mut o = GenerateOptions::new(Kind::Crater, n);
        o.seed = 1;
        write_lammps_dump_to_path(&o, &path, |_| {}).unwrap();
    }
    path
}

/// Runs `cmd` under /usr/bin/time; returns (wall seconds, peak RSS in MiB).
fn timed(cmd: &mut Command) -> Option<(f64, f64)> {
    let mut wrapped = Command::new("/usr/bin/time");
    wrapped.arg("-f").arg("%e %M").arg(cmd.get_program());
    wrapped.args(cmd.get_args());
    let out = wrapped.output().ok()?;
    if !out.status.success() {
        eprintln!("{}", String::from_utf8_lossy(&out.stderr));
        return None;
    }
    let err = String::from_utf8_lossy(&out.stderr);
    let last = err.lines().last()?;
    let mut it = last.split_whitespace();
    let wall: f64 = it.next()?.parse().ok()?;
    let kb: f64 = it.next()?.parse().ok()?;
    Some((wall, kb / 1024.0))
}

fn ovito_load(path: &Path, repeats: usize) -> Option<f64> {
    let out = Command::new("python3")
        .arg("benches/ovito_load.py")
        .arg(path)
        .arg(repeats.to_string())
        .output()
        .ok()?;
    if !out.status.success() {
        return None;
    }
    let times: Vec<f64> = String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter_map(|l| l.split_whitespace().next()?.parse().ok())
        .collect();
    (!times.is_empty()).then(|| median(times))
}

struct Row {
    n: u64,
    mb: f64,
    parse_s: f64,
    hier_1t: f64,
    hier_all: f64,
    convert_s: f64,
    convert_rss: f64,
    ovito_s: Option<f64>,
    max_err: f64,
    file_mb: f64,
}

fn main() {
    // `cargo bench` passes `--bench`; ignore arguments.
    let sizes: Vec<u64> = std::env::var("MDLOD_BENCH_SIZES")
        .unwrap_or_else(|_| "1000000,10000000".into())
        .split(',')
        .filter_map(|s| s.trim().parse().ok())
        .collect();
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let exe = env!("CARGO_BIN_EXE_mdlod");
    let mut rows = vec![];
    let mut inputs: Vec<(String, PathBuf)> = sizes
        .iter()
        .map(|&n| (format!("generated crater, {n} atoms"), input(n)))
        .collect();
    // The real LAMMPS dump made by datasets/lammps/make-large.sh, when present.
    if let Ok(dir) = std::fs::read_dir("data") {
        let mut real: Vec<PathBuf> = dir
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| {
                p.file_name()
                    .and_then(|n| n.to_str())
                    .is_some_and(|n| n.starts_with("cu_large_") && n.ends_with(".dump"))
            })
            .collect();
        real.sort();
        for p in real {
            inputs.push((
                "real LAMMPS dump, EAM Cu (make-large.sh), last frame".into(),
                p,
            ));
        }
    }
    let mut labels = vec![];
    for (label, path) in &inputs {
        let mb = std::fs::metadata(path).unwrap().len() as f64 / 1e6;
        let dump = DumpFile::open(path).unwrap();
        let k = dump.frame_count() - 1;
        let opts = ReadOptions::default();
        let probe = dump.read_frame(k, &opts, &NoProgress).unwrap();
        let n = probe.len() as u64;
        let reps = repeats_for(n);
        let parse_s = median(
            (0..reps)
                .map(|_| {
                    let t = Instant::now();
                    let f = dump.read_frame(k, &opts, &NoProgress).unwrap();
                    std::hint::black_box(f);
                    t.elapsed().as_secs_f64()
                })
                .collect(),
        );
        let species = species_table(&probe.species, &[]);
        let particles = Particles {
            positions: &probe.positions,
            species_index: &probe.species_index,
            species: &species,
            attribute: None,
            radii: None,
        };
        let params = BuildParams::default();
        let time_build = |t: usize| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(t)
                .build()
                .unwrap();
            median(
                (0..reps)
                    .map(|_| {
                        let s = Instant::now();
                        let h = pool.install(|| build(particles, &params, &NoProgress).unwrap());
                        std::hint::black_box(h);
                        s.elapsed().as_secs_f64()
                    })
                    .collect(),
            )
        };
        let hier_1t = time_build(1);
        let hier_all = time_build(threads);
        let out = PathBuf::from("data/bench/out.mdlod");
        let runs: Vec<(f64, f64)> = (0..reps)
            .filter_map(|_| {
                timed(
                    Command::new(exe)
                        .arg("convert")
                        .arg(path)
                        .arg("-o")
                        .arg(&out),
                )
            })
            .collect();
        let convert_s = median(runs.iter().map(|r| r.0).collect());
        let convert_rss = runs.iter().map(|r| r.1).fold(0.0, f64::max);
        let file = mdlod_format::MdlodFile::open(&out).unwrap();
        let max_err = file.metadata().max_position_error;
        let file_mb = std::fs::metadata(&out).unwrap().len() as f64 / 1e6;
        let ovito_s = ovito_load(path, reps);
        eprintln!(
            "{label}: parse {parse_s:.3}s hierarchy {hier_1t:.3}s/1t {hier_all:.3}s/{threads}t convert {convert_s:.3}s {convert_rss:.0} MiB ovito {ovito_s:?}"
        );
        labels.push(label.clone());
        rows.push(Row {
            n,
            mb,
            parse_s,
            hier_1t,
            hier_all,
            convert_s,
            convert_rss,
            ovito_s,
            max_err,
            file_mb,
        });
    }

    let mut t = String::new();
    t.push_str(
        "<!-- foundation:begin (generated by `cargo bench --bench foundation`; do not edit) -->\n",
    );
    t.push_str(&format!(
        "Machine: {}. mdlod {}, {threads} worker threads unless noted; medians of {} runs (3 at 10^7 and above).\n\n",
        machine(),
        env!("CARGO_PKG_VERSION"),
        repeats_for(1)
    ));
    t.push_str("| input | particles | dump MB | parse s | parse MB/s | hierarchy s (1 thread) | hierarchy M particles/s per core | hierarchy s (all threads) | convert s (end to end) | convert M particles/s | peak RSS MiB | .mdlod MB | max position error |\n");
    t.push_str("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n");
    for (r, label) in rows.iter().zip(&labels) {
        t.push_str(&format!(
            "| {label} | {} | {:.0} | {:.3} | {:.0} | {:.3} | {:.2} | {:.3} | {:.3} | {:.2} | {:.0} | {:.1} | {:.2e} |\n",
            r.n, r.mb, r.parse_s, r.mb / r.parse_s, r.hier_1t, r.n as f64 / r.hier_1t / 1e6, r.hier_all,
            r.convert_s, r.n as f64 / r.convert_s / 1e6, r.convert_rss, r.file_mb, r.max_err
        ));
    }
    t.push_str("\nSide by side with OVITO (`import_file(path).compute(frame)`, the time OVITO needs just to load the frame; `pip install ovito`). Target: mdlod's whole conversion at most 1.5× OVITO's load.\n\n");
    t.push_str("| input | particles | OVITO load s | mdlod convert s | ratio convert / load | target ≤ 1.5 |\n|---|---:|---:|---:|---:|---|\n");
    for (r, label) in rows.iter().zip(&labels) {
        match r.ovito_s {
            Some(o) => t.push_str(&format!(
                "| {label} | {} | {o:.3} | {:.3} | {:.2} | {} |\n",
                r.n,
                r.convert_s,
                r.convert_s / o,
                if r.convert_s / o <= 1.5 {
                    "met"
                } else {
                    "missed"
                }
            )),
            None => t.push_str(&format!(
                "| {label} | {} | OVITO not installed | {:.3} | — | not measured |\n",
                r.n, r.convert_s
            )),
        }
    }
    t.push_str("\nHierarchy target: at least 2 M particles/s per core from parsed data (PotreeConverter 2 publishes about 1 M points/s per core).\n");
    t.push_str("<!-- foundation:end -->\n");
    println!("{t}");

    let path = Path::new("BENCHMARKS.md");
    let old = std::fs::read_to_string(path).unwrap_or_else(|_| "# Benchmarks\n\n".into());
    let new = match (
        old.find("<!-- foundation:begin"),
        old.find("<!-- foundation:end -->"),
    ) {
        (Some(a), Some(b)) => format!(
            "{}{}{}",
            &old[..a],
            t,
            &old[b + "<!-- foundation:end -->\n".len()..]
        ),
        _ => format!("{old}\n## Foundation: parsing, hierarchy, conversion\n\n{t}"),
    };
    std::fs::write(path, new).unwrap();
    eprintln!("updated BENCHMARKS.md");
}
