//! `mdlod view`: the interactive viewer (the work is in the `mdlod-viewer` crate).

use std::path::PathBuf;
use std::time::Duration;

use anyhow::Result;
use mdlod_viewer::worker::GpuMemory;
use mdlod_viewer::{Mode, ViewerOptions};

/// Open a .mdlod file, or a batch directory with dataset.json, in a window: orbit (left
/// drag, arrows), pan (right drag), zoom (wheel, + and -), fit (F), orthographic (O),
/// modes (1-6), timesteps (, and ., space plays).
#[derive(clap::Args)]
#[command(
    allow_negative_numbers = true,
    after_help = "Examples:\n  mdlod view frame.mdlod\n  mdlod view runs/ --mode sndf\n  mdlod view frame.mdlod --script session.json   # play actions, write screenshots, close"
)]
pub struct Args {
    /// A .mdlod file or a directory written by `mdlod batch` (or its dataset.json).
    pub path: PathBuf,
    /// Size of the image area of the window (logical pixels).
    #[arg(long, default_value_t = 1280)]
    pub width: u32,
    /// Height of the image area of the window (logical pixels).
    #[arg(long, default_value_t = 720)]
    pub height: u32,
    /// Start from a view file (as `mdlod render --view` takes).
    #[arg(long)]
    pub view: Option<PathBuf>,
    /// How to draw the points at the start (keys 1-6 switch): ray-cast spheres
    /// (`standard`, also called `spheres`, as render names them), the same supersampled
    /// once the view is still, S-NDFs, splats, the density volume or its iso-surface.
    #[arg(long, value_enum, ignore_case = true, default_value = "standard")]
    pub mode: ModeArg,
    /// Play a script: a JSON array of actions (orbit, pan, zoom, mode, light, step,
    /// screenshot, save_sndf, save_view, ...), then close; any error fails the command.
    #[arg(long)]
    pub script: Option<PathBuf>,
    /// Stream node data through a GPU memory pool of this size (e.g. 512M, 2G); `0`
    /// uploads each frame's cut instead. Default: a 512 MiB pool for files larger than
    /// that, direct otherwise.
    #[arg(long, value_parser = super::render::parse_bytes_or_zero)]
    pub gpu_memory: Option<u64>,
    /// Longest a script may run, seconds.
    #[arg(long, default_value_t = 600)]
    pub script_timeout: u64,
}

#[derive(Clone, Copy, Debug, clap::ValueEnum)]
pub enum ModeArg {
    #[value(alias = "spheres")]
    Standard,
    Supersampled,
    Sndf,
    Splat,
    Density,
    Iso,
}

pub fn run(mut args: Args) -> Result<()> {
    // A batch's dataset.json opens as its directory.
    args.path = super::batch_dir_of(args.path);
    unmerged_batch(&args.path)?;
    let mode = match args.mode {
        ModeArg::Standard => Mode::Standard,
        ModeArg::Supersampled => Mode::Supersampled,
        ModeArg::Sndf => Mode::Sndf,
        ModeArg::Splat => Mode::Splat,
        ModeArg::Density => Mode::Density,
        ModeArg::Iso => Mode::Iso,
    };
    mdlod_viewer::run(ViewerOptions {
        path: args.path,
        window: [args.width.max(16), args.height.max(16)],
        view: args.view,
        mode,
        backends: mdlod_render::BackendChoice::FromEnv,
        gpu_memory: match args.gpu_memory {
            None => GpuMemory::Auto(512 << 20),
            Some(0) => GpuMemory::Direct,
            Some(b) => GpuMemory::Pool(b),
        },
        script: args.script,
        script_timeout: Duration::from_secs(args.script_timeout),
    })?;
    Ok(())
}

/// Refuses a batch directory whose shards have not been merged yet (shard manifests, no
/// dataset.json), saying how to merge them.
pub fn unmerged_batch(path: &std::path::Path) -> Result<()> {
    let manifest = mdlod_preprocess::batch::MANIFEST;
    if !path.is_dir() || path.join(manifest).exists() {
        return Ok(());
    }
    let shard = std::fs::read_dir(path).ok().and_then(|d| {
        d.flatten()
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .find(|n| mdlod_preprocess::batch::is_shard_manifest(n))
    });
    if let Some(shard) = shard {
        anyhow::bail!(
            "{}: no {manifest}, but shard manifests ({shard}, ...): the shards of this \
             batch have not been merged; run `mdlod batch --merge {}` once all of them \
             have finished",
            path.display(),
            path.display()
        );
    }
    Ok(())
}
