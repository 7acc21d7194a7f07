//! Parse throughput on a generated ~50 MB dump. Ignored by default; run with
//! `cargo test --release -p mdlod-preprocess --test readers_throughput -- --ignored --nocapture`.

use std::fmt::Write as _;
use std::time::Instant;

use mdlod_preprocess::readers::{DumpFile, ReadOptions};
use mdlod_preprocess::NoProgress;

fn generate(n: usize, columns: &str, line: impl Fn(usize, &mut String)) -> String {
    let mut s = format!(
        "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n{n}\nITEM: BOX BOUNDS pp pp pp\n0 200\n0 200\n0 200\nITEM: ATOMS {columns}\n"
    );
    for i in 0..n {
        line(i, &mut s);
    }
    s
}

/// CPU time of all threads of this process, in seconds (Linux `schedstat`; 0 elsewhere).
fn cpu_seconds() -> f64 {
    let Ok(tasks) = std::fs::read_dir("/proc/self/task") else {
        return 0.0;
    };
    let ns: u64 = tasks
        .flatten()
        .filter_map(|t| std::fs::read_to_string(t.path().join("schedstat")).ok())
        .filter_map(|s| s.split_whitespace().next()?.parse::<u64>().ok())
        .sum();
    ns as f64 * 1e-9
}

fn measure(name: &str, text: &str, attribute: Option<&str>) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join(format!("{name}.lammpstrj"));
    std::fs::write(&path, text).unwrap();
    let mb = text.len() as f64 / 1e6;
    let opts = ReadOptions {
        attribute: attribute.map(String::from),
        ..Default::default()
    };
    for threads in [1, rayon::current_num_threads()] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        let (mut open, mut parse, mut cpu) = (f64::INFINITY, f64::INFINITY, f64::INFINITY);
        pool.install(|| {
            for _ in 0..10 {
                let t = Instant::now();
                let dump = DumpFile::open(&path).unwrap();
                let t_open = t.elapsed().as_secs_f64();
                let c = cpu_seconds();
                let f = dump.read_frame(0, &opts, &NoProgress).unwrap();
                let c = cpu_seconds() - c;
                assert!(!f.is_empty());
                let total = t.elapsed().as_secs_f64();
                if total < open + parse {
                    (open, parse) = (t_open, total - t_open);
                }
                cpu = cpu.min(c);
            }
        });
        println!(
            "{name}: {mb:.1} MB, {threads} thread(s): open+index {open:.3} s, read_frame {parse:.3} s \
             = {:.0} MB/s wall; read_frame {:.0} MB per CPU-second",
            mb / (open + parse),
            mb / cpu,
        );
    }
}

#[test]
#[ignore]
fn throughput() {
    let n = 1_300_000;
    // `%g`-style coordinates as LAMMPS writes by default.
    let text = generate(n, "id type x y z", |i, s| {
        let x = (i as f64 * 0.618_034).fract() * 200.0;
        let y = (i as f64 * 0.414_214).fract() * 200.0;
        let z = (i as f64 * 0.732_051).fract() * 200.0;
        writeln!(s, "{} {} {x:.4} {y:.5} {z:.4}", i + 1, i % 3 + 1).unwrap();
    });
    measure("g6", &text, None);
    // Full double precision (`%.16e`): most numbers take the standard-library path.
    let text = generate(n / 2, "id type x y z c_pe", |i, s| {
        let x = (i as f64 * 0.618_034).fract() * 200.0;
        let y = (i as f64 * 0.414_214).fract() * 200.0;
        let z = (i as f64 * 0.732_051).fract() * 200.0;
        writeln!(
            s,
            "{} {} {x:.16e} {y:.16e} {z:.16e} {:.6e}",
            i + 1,
            i % 3 + 1,
            -x
        )
        .unwrap();
    });
    measure("e16", &text, Some("c_pe"));
}
