//! `mdlod convert`: one frame of a dump to a `.mdlod` file.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use mdlod_preprocess::chunked::ChunkOptions;
use mdlod_preprocess::convert::{convert_file, ConvertOptions, ConvertReport, FrameSelect};
use mdlod_preprocess::hierarchy::BuildParams;
use mdlod_preprocess::readers::{ReadOptions, SizeColumn};
use mdlod_preprocess::species::{parse_radius_override, parse_species_name};

use crate::progress::Bar;

/// Convert one frame of a particle dump (LAMMPS text or binary, `%` piece sets, GSD,
/// MegaMol MMPLD, XYZ, extended XYZ, raw arrays with a .raw.json sidecar; .gz too) into a
/// level-of-detail .mdlod file.
#[derive(clap::Args)]
#[command(
    after_help = "Example:\n  mdlod convert dump.lammpstrj.gz -o frame.mdlod --last --radius Cu=1.28 --attribute c_pe\n  mdlod convert water.dump -o water.mdlod --species-name 1=O --species-name 2=H"
)]
pub struct Args {
    /// The dump to read.
    pub input: PathBuf,
    /// The .mdlod file to write (replaced atomically).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Frame to convert (0-based; -1 is the last, -2 the one before).
    #[arg(long, conflicts_with = "last", allow_negative_numbers = true)]
    pub frame: Option<i64>,
    /// Convert the last frame, refusing it when it is cut short. The default converts
    /// the last frame too, but takes the one before, with a note, when a run is still
    /// writing the last.
    #[arg(long)]
    pub last: bool,
    /// Worker threads (default: all cores).
    #[arg(long, value_parser = super::parse_threads)]
    pub threads: Option<usize>,
    /// Print what was written as one line of JSON on standard output (the file, its
    /// counts, error bound and times, and the notes), the text lines going to standard
    /// error: for scripts
    #[arg(long)]
    pub json: bool,
    /// Memory the conversion may use (e.g. 4G; default: half of the memory this process may
    /// have: the machine's, or a Slurm job's or container's allocation).
    /// Frames above the chunk size are built out of core, as many chunks at a time as
    /// fit; the file does not depend on it.
    #[arg(long, value_parser = crate::commands::render::parse_bytes, allow_hyphen_values = true)]
    pub memory_limit: Option<u64>,
    #[command(flatten)]
    pub build: BuildArgs,
}

/// How frames are read and built, shared by `convert` and `batch`.
#[derive(clap::Args, Clone, Debug)]
pub struct BuildArgs {
    /// Radius of a species, NAME=RADIUS, the species named as the input names it: by
    /// element symbol where a LAMMPS dump has an `element` column, else by type number
    /// (XYZ: its species column; GSD: type name), or by the name --species-name gives it;
    /// `'*=R'` gives every species no --radius names its own; repeatable.
    #[arg(long = "radius", value_name = "NAME=R", value_parser = parse_radius_override)]
    pub radii: Vec<(String, f32)>,
    /// Give a species another name, NAME=NEW: a LAMMPS type number its element (`1=O`,
    /// `2=H`), so that it is drawn with the element's radius and colour and named by it
    /// everywhere (--radius, and render's --species-colour and --hide-species, take the
    /// new name); two species given one name become one (`1=O` with `3=O`); repeatable.
    #[arg(long = "species-name", value_name = "NAME=NEW", value_parser = parse_species_name)]
    pub species_names: Vec<(String, String)>,
    /// Dump column to keep as the per-particle scalar attribute, or the length of a
    /// vector between bars (`'|v|'` over vx vy vz, `'|forces|'` over an XYZ file's
    /// forces[0..2], `'|velocity|'` over a GSD row, `'|vx,vy|'` over the columns
    /// named); repeat it to keep several (`--attribute c_pe --attribute c_ke`: render's
    /// `--attribute c_ke` then colours by the second; format 1.2; each further column is
    /// a pass over the frame of its own)
    #[arg(long, value_name = "COLUMN")]
    pub attribute: Vec<String>,
    /// Keep the attribute's base-10 logarithm instead (named log10(NAME); every value
    /// must be above 0): the file keeps 16 bits per value, evenly over its range, so a
    /// quantity spanning many decades (an SPH density) keeps only its top four or five
    /// otherwise. Alone, it applies to the first column --attribute names, or to the
    /// attribute an input keeps by itself (a raw sidecar's first); with names
    /// (`--attribute-log10=rho,sigma`, the equals sign needed), to each --attribute column
    /// named, the first or further ones
    #[arg(
        long,
        value_name = "COLUMNS",
        num_args = 0..=1,
        require_equals = true,
        value_delimiter = ',',
        action = clap::ArgAction::Append
    )]
    pub attribute_log10: Option<Vec<String>>,
    /// Wrap the particles into the simulation cell along its periodic axes (OVITO's
    /// "wrap at periodic boundaries"): unwrapped coordinates (`xu yu zu`) of atoms that
    /// crossed the cell's faces come back inside it, so a liquid stays in its box
    /// through a movie. Axes the input does not call periodic or not (LAMMPS `pp`, XYZ
    /// `pbc=`) are all wrapped; frames without a cell are read as they are
    #[arg(long)]
    pub wrap: bool,
    /// Column names, space separated, for dumps that do not name them (old-revision
    /// LAMMPS binary dumps other than `dump atom`), e.g. "id type x y z c_pe"; a dump
    /// that names its own refuses other names.
    #[arg(long, value_name = "NAMES")]
    pub columns: Option<String>,
    /// Column of a LAMMPS dump (or extended-XYZ property) holding each particle's radius:
    /// an SPH run's smoothing length `h`, a compute's `c_rad`. The default reads a
    /// `radius` column, else a `diameter` one. (Splats' light grows as the radius
    /// squared: a splat is a disk of that radius.)
    #[arg(long, value_name = "NAME", conflicts_with_all = ["diameter_column", "no_sizes"])]
    pub radius_column: Option<String>,
    /// Column of a LAMMPS dump (or extended-XYZ property) to take each particle's species
    /// from instead of its `type` or `element`: a column of categories, such as a
    /// common-neighbour analysis's structure type (`c_cna`: 1 fcc, 2 hcp, 3 bcc, 4
    /// icosahedral, 5 other; ptm/atom's 0 is other). Each distinct value, however printed
    /// (1, 1.000000), becomes a species: named (`--species-name 1=FCC`; a value the frame
    /// lacks is noted), sized (atoms keep their element's size where the dump names
    /// elements; else `--radius 1=1.28`), hidden and keyed as species are, coloured by
    /// value (structure types as OVITO colours them, fcc green, hcp red, bcc blue, ico
    /// gold, by the numbers of the cna, ptm or ackland compute the name names; other
    /// columns, molecule ids, the palette's), and averaged in clusters as species colours
    /// are (an attribute's values would be averaged, mixing categories).
    #[arg(long, value_name = "NAME")]
    pub species_column: Option<String>,
    /// Column of a LAMMPS dump (or extended-XYZ property) holding each particle's
    /// diameter.
    #[arg(long, value_name = "NAME", conflicts_with = "no_sizes")]
    pub diameter_column: Option<String>,
    /// No sizes of their own: a dump's `radius`/`diameter` columns are not read (each
    /// species takes its radius as without them), and GSD and MMPLD particles are drawn
    /// at their species' mean size.
    #[arg(long)]
    pub no_sizes: bool,
    /// Bits per quantized coordinate.
    #[arg(long, value_enum, ignore_case = true, default_value = "u16")]
    pub precision: Precision,
    /// A cluster is split while it holds more than this many points.
    #[arg(long, default_value_t = 8, value_parser = super::whole_number_u32)]
    pub cluster_size: u32,
    /// The coarsest level holds at most this many points.
    #[arg(long, default_value_t = 4096, value_parser = super::whole_number_u32)]
    pub root_points: u32,
    /// Levels between a node and the points it is drawn with (δn), 1 to 8.
    #[arg(long, default_value_t = 1, value_parser = super::whole_number_u32)]
    pub delta_n: u32,
    /// Frames above this many particles are built out of core, in spatial chunks of at
    /// most this many (the choice is recorded in the file).
    #[arg(long, default_value_t = mdlod_preprocess::chunked::DEFAULT_CHUNK_POINTS,
          value_parser = super::whole_number_usize)]
    pub chunk_points: usize,
    /// Directory for the working files of out-of-core builds (default: the output's
    /// directory); they are removed on success, on failure and on Ctrl-C or SIGTERM, and
    /// those of a run killed outright by the next run on this host.
    #[arg(long, value_name = "DIR")]
    pub temp_dir: Option<PathBuf>,
}

impl BuildArgs {
    /// Checks the build options before any input is read (a library check of the same
    /// rules comes only after an out-of-core frame's partition pass).
    pub fn check(&self) -> Result<()> {
        if let Some((_, a)) = self
            .attribute
            .iter()
            .enumerate()
            .find(|(k, a)| self.attribute[..*k].contains(a))
        {
            bail!("--attribute {a} is given twice: each column is kept once");
        }
        self.logarithms()?;
        if self.cluster_size < 2 {
            bail!("--cluster-size {} (must be at least 2)", self.cluster_size);
        }
        if self.root_points < self.cluster_size {
            bail!(
                "--root-points {} is below --cluster-size {} (must be at least that)",
                self.root_points,
                self.cluster_size
            );
        }
        if !(1..=8).contains(&self.delta_n) {
            bail!("--delta-n {} (must be 1 to 8)", self.delta_n);
        }
        // One species renamed or sized twice: which was meant?
        let (names, radii) = self.named();
        for (k, (old, new)) in names.iter().enumerate() {
            if let Some((_, other)) = names[..k].iter().find(|(o, _)| o == old) {
                bail!("--species-name names {old} twice ({old}={other} and {old}={new}): give one");
            }
        }
        for (k, (name, r)) in radii.iter().enumerate() {
            if let Some((_, other)) = radii[..k].iter().find(|(n, _)| n == name) {
                bail!("--radius names {name} twice ({name}={other} and {name}={r}): give one");
            }
        }
        Ok(())
    }

    /// A name meant for --attribute-log10 given after a space (`--attribute-log10 sigma`),
    /// which the command line reads as an input: an error saying to join them, where no
    /// such file is there.
    pub fn check_log10_inputs(&self, inputs: &[std::path::PathBuf]) -> Result<()> {
        if self.attribute_log10.as_ref().is_some_and(|n| n.is_empty()) {
            if let Some(input) = inputs
                .iter()
                .find(|i| !i.exists() && self.attribute.iter().any(|a| i.as_os_str() == a.as_str()))
            {
                let name = input.display();
                bail!(
                    "{name} is taken as an input, and there is no such file: \
                     --attribute-log10 takes its column names after an equals sign \
                     (--attribute-log10={name})"
                );
            }
        }
        Ok(())
    }

    /// Which attributes --attribute-log10 keeps as logarithms: the first, and each further
    /// one in turn. A name that is no --attribute column is an error listing them.
    fn logarithms(&self) -> Result<(bool, Vec<bool>)> {
        let Some(names) = &self.attribute_log10 else {
            return Ok((false, Vec::new()));
        };
        // Alone (no names): the first.
        let mut first = names.is_empty();
        let mut further = vec![false; self.attribute.len().saturating_sub(1)];
        for name in names {
            if name.is_empty() {
                bail!(
                    "--attribute-log10= names no column: give --attribute columns after the \
                     equals sign (--attribute-log10=rho,sigma), or the flag alone for the first"
                );
            }
            match self.attribute.iter().position(|a| a == name) {
                Some(0) => first = true,
                Some(k) => further[k - 1] = true,
                None if self.attribute.is_empty() => bail!(
                    "--attribute-log10={name}: no column is kept by --attribute; name it with \
                     --attribute {name}, or give --attribute-log10 alone for the attribute the \
                     input keeps by itself"
                ),
                None => bail!(
                    "--attribute-log10={name}: {name} is not a column --attribute names (those \
                     are {}); each name must be one of them",
                    self.attribute.join(", ")
                ),
            }
        }
        Ok((first, further))
    }

    /// The renames and radii as given, their names taken as a column of categories
    /// names its values (`1.0` is `1`) where the species come from one.
    fn named(&self) -> (Renames, Radii) {
        let name = |n: &String| match self.species_column {
            Some(_) => mdlod_preprocess::species::category_name(n),
            None => n.clone(),
        };
        (
            self.species_names
                .iter()
                .map(|(old, new)| (name(old), new.clone()))
                .collect(),
            self.radii.iter().map(|(n, r)| (name(n), *r)).collect(),
        )
    }

    /// The options given that change what is read from the input, as the metadata
    /// records them (`input_options`); those the file records otherwise (radii, the
    /// species column, logarithms, the frame) are left out.
    fn input_options(&self) -> Vec<String> {
        let mut given = Vec::new();
        if self.wrap {
            given.push("--wrap".to_string());
        }
        if self.no_sizes {
            given.push("--no-sizes".to_string());
        }
        for (old, new) in &self.species_names {
            given.push(format!("--species-name {old}={new}"));
        }
        if let Some(c) = &self.columns {
            given.push(format!("--columns {c:?}"));
        }
        if let Some(c) = &self.radius_column {
            given.push(format!("--radius-column {c}"));
        }
        if let Some(c) = &self.diameter_column {
            given.push(format!("--diameter-column {c}"));
        }
        given
    }

    /// The library options these arguments ask for.
    pub fn options(&self) -> (ConvertOptions, ReadOptions) {
        let (species_names, radii) = self.named();
        // (Checked by `check` first.)
        let (attribute_log10, extra_log10) = self.logarithms().unwrap_or_default();
        let convert = ConvertOptions {
            build: BuildParams {
                max_cluster_size: self.cluster_size,
                max_root_points: self.root_points,
                delta_n: self.delta_n,
                position_bits: match self.precision {
                    Precision::U8 => 8,
                    Precision::U16 => 16,
                },
            },
            radii,
            chunks: ChunkOptions {
                chunk_points: self.chunk_points,
                temp_dir: self.temp_dir.clone(),
                ..ChunkOptions::default()
            },
            // A column of categories need not hold every value named in one frame (a
            // script names all five structure types): noted after the conversion.
            radii_may_be_absent: self.species_column.is_some(),
            species_names,
            attribute_log10,
            extra_log10,
            species_column: self.species_column.clone(),
            input_options: self.input_options(),
        };
        let read = ReadOptions {
            attribute: self.attribute.first().cloned(),
            extra_attributes: self.attribute.iter().skip(1).cloned().collect(),
            columns: self
                .columns
                .as_ref()
                .map(|c| c.split_whitespace().map(str::to_string).collect()),
            sizes: match (&self.radius_column, &self.diameter_column, self.no_sizes) {
                (Some(c), _, _) => SizeColumn::Radius(c.clone()),
                (_, Some(c), _) => SizeColumn::Diameter(c.clone()),
                (_, _, true) => SizeColumn::Off,
                _ => SizeColumn::Auto,
            },
            species_column: self.species_column.clone(),
            wrap: self.wrap,
            values_only: false,
        };
        (convert, read)
    }
}

/// `--species-name` renames, old name to new.
type Renames = Vec<(String, String)>;
/// `--radius` overrides, name to radius.
type Radii = Vec<(String, f32)>;

/// Refuses an output that exists and is not a `.mdlod` file (a PNG, a dump given as
/// `-o` by mistake): the conversion would replace it without a word. An earlier
/// `.mdlod` file, whole or cut short, is replaced as the option says.
fn check_replaces_only_mdlod(output: &std::path::Path) -> Result<()> {
    // (A FIFO in its place is not opened here: that would wait for a writer. None
    // there, unreadable or no file: the write says why; an empty file is replaced.)
    let Some(head) = super::file_head(output).filter(|h| !h.is_empty()) else {
        return Ok(());
    };
    if head[..] != mdlod_format::MAGIC[..] {
        bail!(
            "-o {}: exists and is no .mdlod file; converting would replace it: remove it \
             first or give another name",
            output.display()
        );
    }
    Ok(())
}

#[derive(Clone, Copy, Debug, clap::ValueEnum)]
pub enum Precision {
    U8,
    U16,
}

pub fn run(args: Args) -> Result<()> {
    if args.json {
        crate::json_output();
    }
    let report = with_threads(args.threads, || convert(&args))??;
    print_report(&args.output, &report);
    if let Some(column) = &args.build.species_column {
        let file = mdlod_format::MdlodFile::open(&args.output)?;
        let species: Vec<&str> = file
            .metadata()
            .species
            .iter()
            .map(|s| s.name.as_str())
            .collect();
        let (renames, radii) = args.build.named();
        for note in
            mdlod_preprocess::species::category_notes(column, &renames, &radii, &species, true)
        {
            println!("  note: {note}");
        }
    }
    if args.json {
        crate::print_json(report_json(&args.output, &report));
    }
    Ok(())
}

/// The `--json` object of a conversion.
pub fn report_json(output: &std::path::Path, r: &ConvertReport) -> serde_json::Value {
    // The frame's timestep and time, as the file written records them.
    let (timestep, time) = mdlod_format::MdlodFile::open(output)
        .map(|f| (f.metadata().timestep, f.metadata().time))
        .unwrap_or_default();
    serde_json::json!({
        "ok": true,
        "output": output.display().to_string(),
        "frame": r.frame.map(|(k, _)| k),
        "timestep": timestep,
        "time": time,
        "frames_in_input": r.frame.map(|(_, n)| n),
        "particles": r.particles,
        "levels": r.levels,
        "nodes": r.nodes,
        "bytes": r.file_size,
        "max_position_error": r.max_position_error,
        "seconds": {
            "read": r.read_time.as_secs_f64(),
            "hierarchy": r.build_time.as_secs_f64(),
            "write": r.write_time.as_secs_f64(),
        },
        "peak_memory_mib": peak_memory_mib(),
    })
}

/// Runs `f` with `threads` worker threads. The process's global pool takes the count, so
/// that work started from threads of the conversion's own (the readers of further
/// attributes, the cell writer) keeps to it too; a pool of its own where the global one
/// is already running.
pub fn with_threads<T: Send>(threads: Option<usize>, f: impl FnOnce() -> T + Send) -> Result<T> {
    match threads {
        Some(n) => {
            if rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .build_global()
                .is_ok()
            {
                return Ok(f());
            }
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .build()
                .context("cannot start the worker threads")?;
            Ok(pool.install(f))
        }
        None => Ok(f()),
    }
}

/// Refuses an image's or a dump's name for the output: a `.mdlod` file named `a.png` or
/// `a.xyz` is a mistake (the picture comes from `mdlod render`).
fn check_not_an_image(output: &std::path::Path) -> Result<()> {
    const IMAGES: &[&str] = &[
        "png", "jpg", "jpeg", "svg", "tif", "tiff", "gif", "webp", "bmp", "ppm", "pdf",
    ];
    let Some(ext) = output
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
    else {
        return Ok(());
    };
    // A dump's name: the output named as the input format's (`-o frame.xyz`).
    const DUMPS: &[&str] = &["xyz", "extxyz", "lammpstrj", "dump", "gsd", "mmpld", "gz"];
    if DUMPS.contains(&ext.as_str()) {
        bail!(
            "-o {}: convert writes a .mdlod file, and this is a dump's name; write {}",
            output.display(),
            output.with_extension("mdlod").display()
        );
    }
    // Text and other files' names (`-o frame.txt` where a listing was meant).
    const OTHERS: &[&str] = &["txt", "csv", "json", "dat", "log", "sndf", "md"];
    // (An existing such file is refused as no .mdlod file, which keeps it, below.)
    if OTHERS.contains(&ext.as_str()) && !output.exists() {
        bail!(
            "-o {}: convert writes a binary .mdlod file, and this names a file of another \
             kind; write {} (`mdlod info` lists what it holds)",
            output.display(),
            output.with_extension("mdlod").display()
        );
    }
    if IMAGES.contains(&ext.as_str()) {
        let file = output.with_extension("mdlod");
        bail!(
            "-o {}: convert writes a .mdlod file, not an image; write {} and draw it with \
             `mdlod render {} -o {}`",
            output.display(),
            file.display(),
            file.display(),
            output.display()
        );
    }
    Ok(())
}

fn convert(args: &Args) -> Result<ConvertReport> {
    super::check_output("-o", &args.output, &[("", &args.input)])?;
    check_not_an_image(&args.output)?;
    check_replaces_only_mdlod(&args.output)?;
    super::check_input_file(&args.input)?;
    // A quoted pattern of files (`'dump.*.lammpstrj'`), which `batch` expands.
    let name = args.input.to_string_lossy();
    if !args.input.exists() && (name.contains('*') || name.contains('?')) {
        bail!(
            "{name}: no such file: convert takes one file (or a `%` set of one timestep's \
             pieces); a pattern of files, one frame each, is `mdlod batch '{name}' -o DIR`"
        );
    }
    args.build.check()?;
    let (mut options, read) = args.build.options();
    if let Some(limit) = args.memory_limit {
        super::note_memory_limit(limit);
        options.chunks.memory_limit = limit;
    }
    // Working files of an out-of-core build live in a directory of this run's own, which
    // a Ctrl-C (or SIGTERM from a scheduler) removes together with the partial output.
    if let Some(dir) = args.output.parent().filter(|d| !d.as_os_str().is_empty()) {
        if !dir.is_dir() {
            bail!(
                "{}: the directory {} does not exist",
                args.output.display(),
                dir.display()
            );
        }
    }
    let temp_parent = options.chunks.temp_dir_for(&args.output);
    let temp_given = options.chunks.temp_dir.is_some();
    // What runs killed outright left (no handler could remove it): working directories
    // in the output's directory and the working one, and outputs' temporary files (of
    // this output or any other: a run killed outright may never be run again).
    let output_dir = ChunkOptions::default().temp_dir_for(&args.output);
    let temp_owner = mdlod_format::writer::any_temp_file_owner;
    crate::interrupt::remove_and_report_leftovers(&[&output_dir, &temp_parent], &temp_owner);
    let work = crate::interrupt::work_dir(&temp_parent)
        .with_context(|| super::work_dir_context(&temp_parent, temp_given))?;
    crate::interrupt::remove_on_interrupt(work.path(), &output_dir, temp_owner);
    options.chunks.temp_dir = Some(work.path().to_path_buf());
    let frame = match args.frame {
        Some(k) if k < 0 => {
            FrameSelect::FromEnd(usize::try_from(k.unsigned_abs()).unwrap_or(usize::MAX))
        }
        Some(k) => FrameSelect::Index(usize::try_from(k).unwrap_or(usize::MAX)),
        None => FrameSelect::Last,
    };
    let run = |frame| {
        convert_file(
            &args.input,
            &args.output,
            frame,
            &read,
            &options,
            &Bar::new(),
        )
    };
    match run(frame) {
        // The default, the last frame, of a dump a run is still writing: the last
        // complete one, said (--last asks for the last one only).
        Err(mdlod_preprocess::convert::ConvertError::LastFrameIncomplete { frame: k, source })
            if args.frame.is_none() && !args.last =>
        {
            println!(
                "note: the last frame ({k}) is incomplete (a run still writing it?): converting \
                 frame {}, the last complete one ({source})",
                k - 1
            );
            Ok(run(FrameSelect::Index(k - 1))?)
        }
        // The default, the last frame, holds no particles (the box emptied): the last
        // frame that holds some, said.
        Err(mdlod_preprocess::convert::ConvertError::LastFrameEmpty {
            place,
            with_particles: Some((j, timestep)),
        }) if args.frame.is_none() && !args.last => {
            let at = |t: Option<u64>| t.map_or(String::new(), |t| format!(" (timestep {t})"));
            let empty = place.frame.map_or(1, |k| k as usize - j);
            println!(
                "note: the last {} hold{} no particles: converting frame {j}{}, the last with \
                 particles",
                if empty == 1 {
                    format!("frame{}", at(place.timestep))
                } else {
                    format!("{empty} frames (from frame {})", j + 1)
                },
                if empty == 1 { "s" } else { "" },
                at(timestep)
            );
            Ok(run(FrameSelect::Index(j))?)
        }
        r => Ok(r?),
    }
}

pub fn print_report(output: &std::path::Path, r: &ConvertReport) {
    let total = r.read_time + r.build_time + r.write_time;
    // Which frame, where the input has several (the last by default).
    let which = match r.frame {
        Some((k, n)) if n > 1 && k + 1 == n => format!(" (frame {k}, the last of {n})"),
        Some((k, n)) if n > 1 => format!(" (frame {k} of {n}, counted from 0)"),
        _ => String::new(),
    };
    let count = |n: u64, noun: &str| format!("{n} {noun}{}", if n == 1 { "" } else { "s" });
    println!(
        "wrote {}{which}: {}, {}, {}, {}, max position error {:.3e}",
        output.display(),
        count(r.particles, "particle"),
        count(r.levels as u64, "level"),
        count(r.nodes as u64, "node"),
        super::size_text(r.file_size),
        r.max_position_error
    );
    let peak = peak_memory_mib().map_or(String::new(), |m| format!(", peak memory {m:.0} MiB"));
    println!(
        "  read {:.2} s, hierarchy {:.2} s, write {:.2} s ({:.2} M particles/s overall{peak})",
        r.read_time.as_secs_f64(),
        r.build_time.as_secs_f64(),
        r.write_time.as_secs_f64(),
        r.particles as f64 / total.as_secs_f64().max(1e-9) / 1e6
    );
    for n in &r.notes {
        println!("  note: {n}");
    }
}

/// Peak resident memory of this process so far (Linux), in MiB.
fn peak_memory_mib() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb / 1024.0)
}
