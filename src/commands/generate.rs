//! `mdlod generate`: deterministic MD-like test data as a LAMMPS text dump, extended XYZ
//! or raw arrays.

use std::io::IsTerminal;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use mdlod_datasets::{write_lammps_dump, write_xyz, GenerateOptions, Kind};

/// Write deterministic MD-like particle data as a LAMMPS text dump (or extended XYZ, or raw
/// arrays): an FCC copper slab
/// with a laser-ablation crater (crater), a copper block with silver spheres (alloy), or a
/// liquid layer torn into droplets (droplets).
#[derive(clap::Args)]
#[command(
    allow_negative_numbers = true,
    after_help = "Example:\n  mdlod generate crater --particles 1000000 -o data/crater.lammpstrj"
)]
pub struct Args {
    /// crater, alloy or droplets.
    pub kind: Kind,
    /// Number of particles per frame.
    #[arg(long, short = 'n', default_value_t = 100_000, value_parser = super::whole_number)]
    pub particles: u64,
    /// The file to write: a LAMMPS dump, an extended XYZ file, or the NAME.raw.json
    /// sidecar of raw arrays (--format).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Random seed.
    #[arg(long, default_value_t = 1, value_parser = super::whole_number)]
    pub seed: u64,
    /// Number of frames (timesteps 0, 100, 200, ...).
    #[arg(long, default_value_t = 1, value_parser = super::whole_number_u32)]
    pub frames: u32,
    /// Output format: a LAMMPS text dump, extended XYZ (the same values, the type
    /// number as species), or raw arrays with a sidecar (give the output as
    /// NAME.raw.json; one frame; the fastest input for huge conversions).
    #[arg(long, value_enum, ignore_case = true, default_value = "lammps")]
    pub format: OutputFormat,
}

/// Refuses an output that is a file mdlod made from data (a `.mdlod` or `.sndf` file, a
/// PNG given as `-o` by mistake, say after a copied command): the generated dump would
/// replace it without a word, as `convert` and `sample` refuse to. A dump is replaced.
fn refuse_replacing_made_files(output: &Path) -> Result<()> {
    let Some(head) = super::file_head(output) else {
        return Ok(());
    };
    let kind = if head[..] == mdlod_format::MAGIC[..] {
        ".mdlod"
    } else if head[..] == mdlod_format::sndf::SNDF_MAGIC[..] {
        ".sndf"
    } else if head[..] == b"\x89PNG\r\n\x1a\n"[..] {
        "PNG"
    } else {
        return Ok(());
    };
    anyhow::bail!(
        "-o {}: exists and is a {kind} file, which the generated dump would replace: give \
         another name, or remove it first",
        output.display()
    )
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum OutputFormat {
    Lammps,
    Xyz,
    Raw,
}

pub fn run(args: Args) -> Result<()> {
    super::check_output("-o", &args.output, &[])?;
    refuse_replacing_made_files(&args.output)?;
    // Before the output is created: a rejected count must not empty an existing file.
    if args.particles == 0 {
        anyhow::bail!("--particles 0 (must be at least 1)");
    }
    if args.frames == 0 {
        anyhow::bail!("--frames 0 (must be at least 1)");
    }
    check_room(&args)?;
    let mut opts = GenerateOptions::new(args.kind, args.particles);
    opts.seed = args.seed;
    opts.frames = args.frames;
    let summary = match args.format {
        OutputFormat::Lammps => generate(&opts, &args.output)?,
        OutputFormat::Xyz => generate_text(&opts, &args.output, OutputFormat::Xyz)?,
        OutputFormat::Raw => generate_raw(&opts, &args.output)?,
    };
    println!(
        "wrote {}: {} frame{} of {} particles ({} species, extra column {}), {}",
        args.output.display(),
        summary.frames,
        if summary.frames == 1 { "" } else { "s" },
        summary.particles,
        summary.species,
        summary.extra_column,
        super::size_text(summary.bytes)
    );
    Ok(())
}

/// Bytes per particle of each output format, a little below what the generator writes
/// (text: about 41 for a LAMMPS dump and 36 for XYZ; raw arrays 17), so that a refusal
/// is sure.
fn bytes_per_particle(format: OutputFormat) -> u64 {
    match format {
        OutputFormat::Lammps => 36,
        OutputFormat::Xyz => 32,
        OutputFormat::Raw => 16,
    }
}

/// Refuses, before writing, data that cannot fit on the output's file system (a count
/// mistyped by a few digits filled the disk with a 48 GB file before failing).
fn check_room(args: &Args) -> Result<()> {
    // In floating point: a count past 64 bits of bytes saturated to 18.4 EB.
    let need =
        args.particles as f64 * f64::from(args.frames) * bytes_per_particle(args.format) as f64;
    let dir = match args.output.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    // Where the space cannot be read (the directory is missing: writing says so), go on.
    let Ok(fs) = rustix::fs::statvfs(&dir) else {
        return Ok(());
    };
    let free = fs.f_bavail.saturating_mul(fs.f_frsize);
    // The output replaces an existing file, whose space comes back.
    let replaced = std::fs::metadata(&args.output).map_or(0, |m| m.len());
    if need > free.saturating_add(replaced) as f64 {
        // Sizes in the unit that reads (a small disk's free space is no "0.0 GB").
        let size = |b: f64| match b {
            b if b >= 1e12 => format!("{:.3e} GB", b / 1e9),
            b if b >= 1e9 => format!("{:.1} GB", b / 1e9),
            b => format!("{:.1} MB", b / 1e6),
        };
        anyhow::bail!(
            "{} frame{} of {} particles need about {}, more than the {} free in {}",
            args.frames,
            if args.frames == 1 { "" } else { "s" },
            args.particles,
            size(need),
            size(free as f64),
            dir.display()
        );
    }
    Ok(())
}

fn generate_raw(
    opts: &GenerateOptions,
    output: &std::path::Path,
) -> Result<mdlod_datasets::Summary> {
    let name = output
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let Some(stem) = name.strip_suffix(".raw.json").filter(|s| !s.is_empty()) else {
        anyhow::bail!(
            "{}: raw arrays need an output named NAME.raw.json (the sidecar)",
            output.display()
        );
    };
    let dir = match output.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let bar = bar(opts.particles);
    let (_, summary) = mdlod_datasets::write_raw_arrays(opts, &dir, stem, |n| {
        if let Some(b) = &bar {
            b.set_position(n);
        }
    })
    .with_context(|| format!("cannot write the arrays of {}", output.display()))?;
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    Ok(summary)
}

fn bar(total: u64) -> Option<indicatif::ProgressBar> {
    std::io::stderr().is_terminal().then(|| {
        let b = indicatif::ProgressBar::new(total);
        b.set_style(
            indicatif::ProgressStyle::with_template(
                "{msg:>20} [{bar:30}] {human_pos}/{human_len} {per_sec:0} ETA {eta}",
            )
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
            .progress_chars("=> "),
        );
        b.set_message("generating");
        b
    })
}

pub fn generate(
    opts: &GenerateOptions,
    output: &std::path::Path,
) -> Result<mdlod_datasets::Summary> {
    generate_text(opts, output, OutputFormat::Lammps)
}

/// A LAMMPS text dump or extended XYZ at `output`, with a progress bar on a terminal.
fn generate_text(
    opts: &GenerateOptions,
    output: &std::path::Path,
    format: OutputFormat,
) -> Result<mdlod_datasets::Summary> {
    if let Some(dir) = output.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    }
    let bar = bar(opts.particles * u64::from(opts.frames));
    let progress = |n| {
        if let Some(b) = &bar {
            b.set_position(n);
        }
    };
    // Written to a temporary file beside the output and renamed into place when
    // complete: a generation stopped half way leaves no dump under the output's name
    // (which a batch would take for a run still writing it), and Ctrl-C removes it.
    let dir = match output.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let name = output
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let owner_name = name.clone();
    crate::interrupt::remove_partials_on_interrupt(&dir, move |file| {
        mdlod_format::writer::temp_file_owner(file, &owner_name)
    });
    let mut file = mdlod_format::writer::output_file_builder()
        .prefix(&mdlod_format::writer::temp_prefix(&name))
        .suffix(".tmp")
        .tempfile_in(&dir)
        .map_err(mdlod_format::files::temp_error)
        .with_context(|| format!("cannot create {}", output.display()))?;
    let summary = match format {
        OutputFormat::Xyz => write_xyz(opts, file.as_file_mut(), progress),
        _ => write_lammps_dump(opts, file.as_file_mut(), progress),
    }
    .with_context(|| format!("cannot write {}", output.display()))?;
    mdlod_format::files::keep_permissions(output, file.as_file())
        .with_context(|| format!("cannot write {}", output.display()))?;
    file.persist(output)
        .with_context(|| format!("cannot write {}", output.display()))?;
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    Ok(summary)
}
