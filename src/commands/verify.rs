//! `mdlod verify`: check every checksum and decode every node of a `.mdlod` file.

use std::path::PathBuf;

use anyhow::Result;
use mdlod_format::MdlodFile;

/// Check a .mdlod file completely: structure, every section checksum, every species
/// index, and the decoding of every point.
#[derive(clap::Args)]
#[command(after_help = "Example:\n  mdlod verify frame.mdlod")]
pub struct Args {
    pub file: PathBuf,
}

pub fn run(args: Args) -> Result<()> {
    let t = std::time::Instant::now();
    let f = MdlodFile::open(&args.file)?;
    let r = f.verify()?;
    println!(
        "{}: ok: {} sections ({:.1} MiB) checksummed, {} points decoded, {} nodes checked in {:.2} s",
        args.file.display(),
        r.sections,
        r.bytes_hashed as f64 / (1 << 20) as f64,
        r.points_decoded,
        f.nodes().len(),
        t.elapsed().as_secs_f64()
    );
    println!(
        "  particle centres within {:.3e} of where their clusters' bounds put them (recorded position error {:.3e})",
        r.max_particle_error_seen,
        f.metadata().max_position_error
    );
    Ok(())
}
