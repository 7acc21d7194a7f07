//! `mdlod verify`: check every checksum and decode every node of a `.mdlod` file.

use std::path::PathBuf;

use anyhow::Result;
use mdlod_format::MdlodFile;

/// Check a .mdlod file completely: structure, every section checksum, every species
/// index, and the decoding of every point. A batch directory: every frame its manifest
/// lists, against the manifest, and what is missing or unlisted.
#[derive(clap::Args)]
#[command(after_help = "Examples:\n  mdlod verify frame.mdlod\n  mdlod verify traj.d")]
pub struct Args {
    /// A .mdlod file, or a batch directory (with dataset.json, or shard manifests) or
    /// its dataset.json.
    pub file: PathBuf,
    /// Print the result as one line of JSON on standard output (`ok`, what was checked,
    /// and a directory's problems), the text lines going to standard error: for scripts
    #[arg(long)]
    pub json: bool,
}

fn run_dir(args: &Args) -> Result<()> {
    let t = std::time::Instant::now();
    let dir = &args.file;
    let c = mdlod_preprocess::batch::verify_dir(dir, &crate::progress::Bar::new())?;
    for p in &c.problems {
        println!("{}: {p}", dir.display());
    }
    if !c.unlisted.is_empty() {
        let shown: Vec<&str> = c.unlisted.iter().take(5).map(String::as_str).collect();
        println!(
            "{}: note: {} frame file{} no manifest lists (left alone): {}{}",
            dir.display(),
            c.unlisted.len(),
            if c.unlisted.len() == 1 { "" } else { "s" },
            shown.join(", "),
            if c.unlisted.len() > 5 { ", ..." } else { "" }
        );
    }
    if !c.kept_unlisted.is_empty() {
        let n = c.kept_unlisted.len();
        println!(
            "{}: note: {n} frame file{} of deleted dumps, converted with other settings than \
             the last run's, {} kept unlisted (a batch with their settings lists {} again): {}",
            dir.display(),
            if n == 1 { "" } else { "s" },
            if n == 1 { "is" } else { "are" },
            if n == 1 { "it" } else { "them" },
            c.kept_unlisted
                .iter()
                .take(5)
                .map(String::as_str)
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    let merged = if c.manifests.len() == 1 && c.manifests[0] == mdlod_preprocess::batch::MANIFEST {
        String::new()
    } else {
        format!(
            " (not merged: {} shard manifest{}; once every shard has finished, `mdlod batch \
             --merge {}` joins them)",
            c.manifests.len(),
            if c.manifests.len() == 1 { "" } else { "s" },
            dir.display()
        )
    };
    if args.json {
        crate::print_json(serde_json::json!({
            "file": dir.display().to_string(),
            "ok": c.problems.is_empty(),
            "frames_ok": c.frames_ok,
            "problems": c.problems.iter().map(ToString::to_string).collect::<Vec<_>>(),
            "unlisted": c.unlisted,
            "manifests": c.manifests,
            "seconds": t.elapsed().as_secs_f64(),
        }));
    }
    if !c.problems.is_empty() {
        anyhow::bail!(
            "{}: {} problem{} ({} frame{} verified){merged}",
            dir.display(),
            c.problems.len(),
            if c.problems.len() == 1 { "" } else { "s" },
            c.frames_ok,
            if c.frames_ok == 1 { "" } else { "s" }
        );
    }
    println!(
        "{}: ok: {} frame{} verified against {} in {:.2} s{merged}",
        dir.display(),
        c.frames_ok,
        if c.frames_ok == 1 { "" } else { "s" },
        c.manifests.join(", "),
        t.elapsed().as_secs_f64()
    );
    Ok(())
}

pub fn run(mut args: Args) -> Result<()> {
    if args.json {
        crate::json_output();
    }
    // A batch's dataset.json verifies as its directory.
    args.file = super::batch_dir_of(args.file);
    if args.file.is_dir() {
        return run_dir(&args);
    }
    run_file(&args)
}

fn run_file(args: &Args) -> Result<()> {
    let t = std::time::Instant::now();
    let f = MdlodFile::open(&args.file)?;
    let r = f.verify()?;
    if f.changed_on_disk() {
        anyhow::bail!(
            "{}: the file changed while it was verified (another program rewrote it in \
             place): verify it again once it is written whole",
            args.file.display()
        );
    }
    println!(
        "{}: ok: {} sections ({}) checksummed, {} points decoded, {} node{} checked in {:.2} s",
        args.file.display(),
        r.sections,
        super::size_text(r.bytes_hashed),
        r.points_decoded,
        f.nodes().len(),
        if f.nodes().len() == 1 { "" } else { "s" },
        t.elapsed().as_secs_f64()
    );
    println!(
        "  particle centres within {:.3e} of where their clusters' bounds put them (recorded position error {:.3e})",
        r.max_particle_error_seen,
        f.metadata().max_position_error
    );
    if args.json {
        crate::print_json(serde_json::json!({
            "file": args.file.display().to_string(),
            "ok": true,
            "sections": r.sections,
            "bytes_hashed": r.bytes_hashed,
            "points_decoded": r.points_decoded,
            "nodes_checked": f.nodes().len(),
            "max_particle_error_seen": r.max_particle_error_seen,
            "max_position_error": f.metadata().max_position_error,
            "seconds": t.elapsed().as_secs_f64(),
        }));
    }
    Ok(())
}
