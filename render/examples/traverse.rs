//! Times the CPU traversal alone (no GPU) of a file for the default view at 1280×720,
//! the figures quoted for the traversal in BENCHMARKS.md:
//!
//! ```sh
//! cargo run --release -p mdlod-render --example traverse -- FILE [ERROR_PX] [BUDGET] [REPEATS]
//! ```
//!
//! `RAYON_NUM_THREADS` sets the number of threads of the tiled traversal.
use std::time::Instant;

use mdlod_format::MdlodFile;
use mdlod_render::{camera_for, traverse, TraversalSettings, ViewSpec};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let Some(path) = args.get(1) else {
        return Err("usage: traverse FILE [ERROR_PX] [BUDGET] [REPEATS]".into());
    };
    let error_px: f32 = args.get(2).map_or(Ok(1.0), |s| s.parse())?;
    let budget: u64 = args.get(3).map_or(Ok(4_000_000), |s| s.parse())?;
    let repeats: usize = args.get(4).map_or(Ok(3), |s| s.parse())?;
    let t = Instant::now();
    let file = MdlodFile::open(path)?;
    println!("open {:.0} ms", t.elapsed().as_secs_f64() * 1e3);
    let camera = camera_for(&file, &ViewSpec::default(), 1280, 720)?;
    let settings = TraversalSettings {
        error_px,
        budget_points: budget,
        ..Default::default()
    };
    for _ in 0..repeats {
        let t = Instant::now();
        let d = traverse(&camera, &file, &settings);
        // FNV-1a over the ranges: one number that tells whether two builds of the
        // traversal made the same cut.
        let digest = d.ranges.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, r| {
            [u32::from(r.level), r.first, r.count, r.quant_node]
                .iter()
                .fold(h, |h, &v| (h ^ u64::from(v)).wrapping_mul(0x100_0000_01b3))
        });
        println!(
            "traverse {:.1} ms: {} points ({} particles), {} ranges, {} opened, {} hidden nodes, {} hidden particles, error {:.2} px, {} restarts, cut {digest:016x}",
            t.elapsed().as_secs_f64() * 1e3,
            d.points,
            d.particles,
            d.ranges.len(),
            d.opened_nodes,
            d.occluded_nodes,
            d.occluded_particles,
            d.error_px,
            d.restarts
        );
    }
    Ok(())
}
