//! `mdlod batch`: every frame of a trajectory to its own `.mdlod` file, plus a manifest.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use mdlod_preprocess::batch::{batch, merge, BatchOptions};

use super::convert::{with_threads, BuildArgs};
use super::render::parse_bytes;
use crate::progress::Bar;

/// Convert every frame of one or more inputs (multi-frame dumps, file sets such as
/// dump.*.bin, % piece sets) into DIR/frame-<timestep>.mdlod with a manifest
/// DIR/dataset.json. Reruns skip finished frames whose source is unchanged.
#[derive(clap::Args)]
#[command(after_help = "Examples:\n  \
    mdlod batch run/dump.*.lammpstrj -o run.mdlod.d --radius Cu=1.28\n  \
    mdlod batch traj.bin -o traj.d --shard 3/16        # one node of 16\n  \
    mdlod batch --merge traj.d                          # after all shards\n\n\
    In a Slurm job array the shard defaults to SLURM_ARRAY_TASK_ID of \
    SLURM_ARRAY_TASK_COUNT.")]
pub struct Args {
    /// The inputs: files, file sets (shell globs), `%` piece sets.
    #[arg(required_unless_present = "merge")]
    pub inputs: Vec<PathBuf>,
    /// The batch directory to write.
    #[arg(short, long, required_unless_present = "merge")]
    pub output: Option<PathBuf>,
    /// Join the shard manifests of this batch directory into dataset.json.
    #[arg(long, value_name = "DIR", conflicts_with_all = ["inputs", "output", "shard"])]
    pub merge: Option<PathBuf>,
    /// Convert only shard I of N (0-based), e.g. 3/16.
    #[arg(long, value_name = "I/N")]
    pub shard: Option<String>,
    /// Memory all concurrent conversions may use together (e.g. 4G; default: half of
    /// the machine's memory).
    #[arg(long, value_parser = parse_bytes)]
    pub memory_limit: Option<u64>,
    /// Worker threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    #[command(flatten)]
    pub build: BuildArgs,
}

/// Parses `I/N`.
fn parse_shard(s: &str) -> Result<(u32, u32)> {
    let (i, n) = s
        .split_once('/')
        .with_context(|| format!("shard {s:?}: expected I/N, e.g. 3/16"))?;
    let (i, n): (u32, u32) = (
        i.trim()
            .parse()
            .with_context(|| format!("shard {s:?}: bad index"))?,
        n.trim()
            .parse()
            .with_context(|| format!("shard {s:?}: bad count"))?,
    );
    if n == 0 || i >= n {
        bail!("shard {s:?}: the index must be below the count (0-based)");
    }
    Ok((i, n))
}

/// The shard from the command line, else from a Slurm job array's environment.
fn shard(args: &Args) -> Result<Option<(u32, u32)>> {
    if let Some(s) = &args.shard {
        return parse_shard(s).map(Some);
    }
    let var = |name: &str| {
        std::env::var(name)
            .ok()
            .and_then(|v| v.trim().parse::<u32>().ok())
    };
    match (var("SLURM_ARRAY_TASK_ID"), var("SLURM_ARRAY_TASK_COUNT")) {
        (Some(id), Some(count)) => {
            // Array indices may start anywhere (--array=1-16).
            let i = id.saturating_sub(var("SLURM_ARRAY_TASK_MIN").unwrap_or(0));
            parse_shard(&format!("{i}/{count}")).map(Some)
        }
        _ => Ok(None),
    }
}

pub fn run(args: Args) -> Result<()> {
    if let Some(dir) = &args.merge {
        let m = merge(dir)?;
        println!(
            "merged {} frames into {}",
            m.frames.len(),
            dir.join(mdlod_preprocess::batch::MANIFEST).display()
        );
        return Ok(());
    }
    let Some(out) = &args.output else {
        bail!("give the batch directory with -o DIR");
    };
    let (mut convert, read) = args.build.options();
    // Working files of out-of-core frames: a directory of this run's own, removed on
    // Ctrl-C and SIGTERM (partial frames are redone by the next run).
    std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    let temp_parent = convert.chunks.temp_dir_for(&out.join("frame"));
    let work = crate::interrupt::work_dir(&temp_parent).with_context(|| {
        format!(
            "cannot create a working directory in {}",
            temp_parent.display()
        )
    })?;
    crate::interrupt::remove_on_interrupt(work.path(), None);
    convert.chunks.temp_dir = Some(work.path().to_path_buf());
    let opts = BatchOptions {
        convert,
        read,
        shard: shard(&args)?,
        memory_limit: args
            .memory_limit
            .unwrap_or_else(mdlod_preprocess::chunked::default_memory_limit),
        max_jobs: None,
    };
    let report = with_threads(args.threads, || {
        batch(&args.inputs, out, &opts, &Bar::new())
    })??;
    let shard = opts
        .shard
        .map_or(String::new(), |(i, n)| format!(" (shard {i} of {n})"));
    println!(
        "{} frames in the inputs, {} here{shard}: {} converted, {} already done; {} at a time; manifest {}",
        report.frames_total,
        report.frames_in_shard,
        report.converted,
        report.skipped,
        report.jobs,
        report.manifest.display()
    );
    Ok(())
}
