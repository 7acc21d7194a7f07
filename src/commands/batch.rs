//! `mdlod batch`: every frame of a trajectory to its own `.mdlod` file, plus a manifest.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use mdlod_preprocess::batch::{batch, expand_patterns_noting, merge, natural_cmp, BatchOptions};

use super::convert::{with_threads, BuildArgs};
use super::render::parse_bytes;
use crate::progress::Bar;

/// Convert every frame of one or more inputs (multi-frame dumps, file sets such as
/// dump.*.bin, % piece sets) into DIR/frame-<timestep>.mdlod with a manifest
/// DIR/dataset.json. Reruns skip finished frames whose source and build settings are
/// unchanged; frames without particles are skipped and reported.
#[derive(clap::Args)]
#[command(after_help = "Examples:\n  \
    mdlod batch run/dump.*.lammpstrj -o run.d --radius 1=1.28 --attribute c_ke\n  \
    mdlod batch traj.bin -o traj.d --shard 3/16        # one node of 16\n  \
    mdlod batch --merge traj.d                          # after all shards\n\n\
    In a Slurm job array the shard defaults to the task's position in the array \
    (from SLURM_ARRAY_TASK_ID, _MIN and _STEP) of SLURM_ARRAY_TASK_COUNT.")]
pub struct Args {
    /// The inputs: files, file sets (shell globs, or quoted patterns with * and ?), `%`
    /// piece sets.
    #[arg(required_unless_present = "merge")]
    pub inputs: Vec<PathBuf>,
    /// The batch directory to write.
    #[arg(short, long, required_unless_present = "merge")]
    pub output: Option<PathBuf>,
    /// Join the shard manifests of this batch directory into dataset.json.
    #[arg(long, value_name = "DIR", conflicts_with_all = ["inputs", "output", "shard"])]
    pub merge: Option<PathBuf>,
    /// Convert only shard I of N (0-based), e.g. 3/16; `none`: every frame into
    /// dataset.json, whatever a Slurm job array's variables say.
    #[arg(long, value_name = "I/N", allow_hyphen_values = true,
          value_parser = |s: &str| parse_shard(s).map_err(|e| format!("{e:#}")))]
    pub shard: Option<ShardArg>,
    /// Memory all concurrent conversions may use together (e.g. 4G; default: half of
    /// the memory this process may have: the machine's, or the Slurm job's allocation).
    #[arg(long, value_parser = parse_bytes, allow_hyphen_values = true)]
    pub memory_limit: Option<u64>,
    /// Worker threads (default: all cores).
    #[arg(long, value_parser = super::parse_threads)]
    pub threads: Option<usize>,
    /// Frames with the same timestep (a run restarted into the same dump, or inputs
    /// that overlap): an error, or convert the first or the last of each (in the order
    /// of the inputs and their frames) and leave the others out; with `last`, a restart
    /// also leaves out the earlier frames past its timestep that it did not reach.
    #[arg(long, value_enum, ignore_case = true, default_value = "error")]
    pub duplicate_timesteps: DuplicatesArg,
    /// A frame that cannot be converted for what it holds (a NaN, a bad box, a damaged
    /// older file, an input that holds no dump) is reported and the others are
    /// converted (as `make -k`); the command
    /// still ends with an error status, and a rerun tries those frames again. Errors of
    /// the output, such as a full disk, still stop the batch.
    #[arg(long)]
    pub keep_going: bool,
    /// Print the run's counts as one line of JSON on standard output (frames in the
    /// inputs, converted, already done, left for a rerun, failed with their places, the
    /// manifest, and the notes), the text lines going to standard error: for scripts
    #[arg(long)]
    pub json: bool,
    /// List the inputs' frames and keep the text dumps' frame indexes in
    /// DIR/.dataset.index.json, converting nothing: run it once before a job array, so
    /// that no task reads every dump to find its frames (each reads its own). Every
    /// batch keeps the indexes too, so that a rerun scans only dumps that changed
    #[arg(long, conflicts_with_all = ["merge", "shard"])]
    pub index_only: bool,
    #[command(flatten)]
    pub build: BuildArgs,
}

#[derive(Clone, Copy, Debug, clap::ValueEnum)]
pub enum DuplicatesArg {
    Error,
    First,
    Last,
}

/// `--shard`: one shard of N, or the whole run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ShardArg {
    /// `none`: the whole run, in a job array's task too.
    Whole,
    Part(u32, u32),
}

/// Parses `I/N`, or `none`.
fn parse_shard(s: &str) -> Result<ShardArg> {
    if s.trim().eq_ignore_ascii_case("none") {
        return Ok(ShardArg::Whole);
    }
    let (i, n) = s
        .split_once('/')
        .with_context(|| format!("shard {s:?}: expected I/N, e.g. 3/16"))?;
    let (i, n): (u32, u32) = (
        i.trim()
            .parse()
            .with_context(|| format!("shard {s:?}: the index is not a number from 0"))?,
        n.trim()
            .parse()
            .with_context(|| format!("shard {s:?}: the count is not a number from 1"))?,
    );
    let (i, n) = check_shard(i, n).with_context(|| format!("shard {s:?}"))?;
    Ok(ShardArg::Part(i, n))
}

fn check_shard(i: u32, n: u32) -> Result<(u32, u32)> {
    if n == 0 {
        bail!("the count must be at least 1");
    }
    if i >= n {
        bail!("the index {i} must be below the count {n} (shards are numbered from 0)");
    }
    Ok((i, n))
}

/// The shard from the command line, else from a Slurm job array's environment.
fn shard(args: &Args) -> Result<Option<(u32, u32)>> {
    match args.shard {
        Some(ShardArg::Part(i, n)) => Ok(Some((i, n))),
        Some(ShardArg::Whole) => Ok(None),
        None => slurm_shard(|name| std::env::var(name).ok()),
    }
}

/// The shard of a Slurm job array task: the task's position in the array, of the array's
/// task count. Array indices may start anywhere and step (`--array=1-31:2` runs tasks 1,
/// 3, ..., 31: 16 tasks, the task with ID 5 is shard 2 of 16). An environment that names
/// no position (one of the two main variables without the other, a value that is no
/// number, an array given as a list such as `--array=1,3,7`, whose positions Slurm does
/// not tell) is an error naming the variables: each task would otherwise convert every
/// frame.
fn slurm_shard(var: impl Fn(&str) -> Option<String>) -> Result<Option<(u32, u32)>> {
    const HINT: &str =
        "give the shard with --shard I/N, or --shard none to convert every frame into dataset.json";
    let number = |name: &str| -> Result<Option<u32>> {
        match var(name) {
            None => Ok(None),
            Some(v) => match v.trim().parse::<u32>() {
                Ok(n) => Ok(Some(n)),
                Err(_) => bail!("{name} is {v:?}, not a task number: {HINT}"),
            },
        }
    };
    let (id, count) = match (
        number("SLURM_ARRAY_TASK_ID")?,
        number("SLURM_ARRAY_TASK_COUNT")?,
    ) {
        (None, None) => return Ok(None),
        (Some(id), Some(count)) => (id, count),
        (Some(_), None) => {
            bail!("SLURM_ARRAY_TASK_ID is set but not SLURM_ARRAY_TASK_COUNT: {HINT}")
        }
        (None, Some(_)) => {
            bail!("SLURM_ARRAY_TASK_COUNT is set but not SLURM_ARRAY_TASK_ID: {HINT}")
        }
    };
    let min = number("SLURM_ARRAY_TASK_MIN")?.unwrap_or(0);
    let step = number("SLURM_ARRAY_TASK_STEP")?.unwrap_or(1).max(1);
    let offset = id
        .checked_sub(min)
        .with_context(|| format!("SLURM_ARRAY_TASK_ID {id} is below SLURM_ARRAY_TASK_MIN {min}"))?;
    if offset % step != 0 {
        bail!("SLURM_ARRAY_TASK_ID {id} is not on the array's step {step} from {min}: {HINT}");
    }
    if let Some(max) = number("SLURM_ARRAY_TASK_MAX")? {
        // A range MIN-MAX:STEP holds (MAX - MIN) / STEP + 1 tasks; a list does not.
        let range = max.checked_sub(min).map(|d| d / step + 1);
        if range != Some(count) {
            bail!(
                "SLURM_ARRAY_TASK_COUNT {count} is not the number of tasks from \
                 SLURM_ARRAY_TASK_MIN {min} to SLURM_ARRAY_TASK_MAX {max} in steps of {step} \
                 (an array given as a list, such as --array=1,3,7?): {HINT}"
            );
        }
    }
    check_shard(offset / step, count)
        .with_context(|| {
            format!(
                "SLURM_ARRAY_TASK_ID {id} (SLURM_ARRAY_TASK_MIN {min}, step {step}) is past \
             SLURM_ARRAY_TASK_COUNT {count}: {HINT}"
            )
        })
        .map(Some)
}

/// Refuses options given with `--merge` other than `--json`: the merge joins the shards'
/// manifests as they are, so conversion settings (`--radius`, `--precision`, ...) would
/// be ignored without a word.
pub fn check_merge_options(matches: &clap::ArgMatches) -> Result<()> {
    if matches.get_one::<PathBuf>("merge").is_none() {
        return Ok(());
    }
    // (Refused in JSON too where asked: `run` has not turned it on yet.)
    if matches.get_flag("json") {
        crate::json_output();
    }
    // The options as spelt on the command line (argument groups are no options).
    let command = <Args as clap::Args>::augment_args(clap::Command::new("batch"));
    let long = |id: &str| {
        command
            .get_arguments()
            .find(|a| a.get_id() == id)
            .map(|a| match a.get_long() {
                Some(l) => format!("--{l}"),
                None => a.get_id().to_string(),
            })
    };
    let given: Vec<String> = matches
        .ids()
        .map(|id| id.as_str())
        .filter(|id| !matches!(*id, "merge" | "json"))
        .filter(|id| {
            matches!(
                matches.value_source(id),
                Some(clap::parser::ValueSource::CommandLine)
            )
        })
        .filter_map(long)
        .collect();
    if !given.is_empty() {
        bail!(
            "{} given with --merge, which joins the shards' manifests as they are and converts \
             nothing: give {} to the shards' runs",
            given.join(", "),
            if given.len() == 1 { "it" } else { "them" }
        );
    }
    Ok(())
}

pub fn run(args: Args) -> Result<()> {
    if args.json {
        crate::json_output();
    }
    if let Some(dir) = &args.merge {
        // A directory of a whole run (or merged, its shard manifests since removed):
        // nothing to merge, which a pipeline's merge step run after any batch must not
        // take for a failure.
        let manifest = dir.join(mdlod_preprocess::batch::MANIFEST);
        let sharded = std::fs::read_dir(dir).is_ok_and(|entries| {
            entries.flatten().any(|e| {
                mdlod_preprocess::batch::is_shard_manifest(&e.file_name().to_string_lossy())
            })
        });
        if !sharded && manifest.is_file() {
            let m = mdlod_preprocess::batch::read_manifest(dir)?;
            println!(
                "nothing to merge: no shard manifests beside {}, which lists {} frame{}",
                manifest.display(),
                m.frames.len(),
                if m.frames.len() == 1 { "" } else { "s" },
            );
            if args.json {
                crate::print_json(serde_json::json!({
                    "ok": true,
                    "manifest": manifest.display().to_string(),
                    "merged": 0,
                    "frames": m.frames.len(),
                    "missing": m.failed.len(),
                }));
            }
            return Ok(());
        }
        let m = merge(dir)?;
        println!(
            "merged {} frame{} into {}",
            m.frames.len(),
            if m.frames.len() == 1 { "" } else { "s" },
            dir.join(mdlod_preprocess::batch::MANIFEST).display()
        );
        for f in &m.failed {
            println!(
                "note: {} is missing: its shard could not convert it ({})",
                mdlod_preprocess::batch::failed_place(f),
                f.reason
            );
        }
        if args.json {
            crate::print_json(serde_json::json!({
                "ok": true,
                "manifest": dir.join(mdlod_preprocess::batch::MANIFEST).display().to_string(),
                "merged": m.frames.len(),
                "frames": m.frames.len(),
                "missing": m.failed.len(),
            }));
        }
        return Ok(());
    }
    let Some(out) = &args.output else {
        bail!("give the batch directory with -o DIR");
    };
    if out.as_os_str() == "-" {
        bail!("-o -: a batch writes a directory, not standard output; give its name (./- for a directory named -)");
    }
    // Before anything is created: a Slurm environment that names no shard fails here.
    let shard = shard(&args)?;
    // Said before the work, not only at --merge: shards of another array size beside.
    if let Some((i, n)) = shard {
        let others = mdlod_preprocess::batch::other_shardings(out, n);
        if !others.is_empty() {
            let sizes: Vec<String> = others.iter().map(u32::to_string).collect();
            let alone = if n == 1 {
                " (a task resubmitted alone, sbatch --array=K, runs as shard 0 of 1: give \
                 it its place in the whole array with --shard K/N)"
            } else {
                ""
            };
            println!(
                "note: {} holds shard manifests of {} shards; this run is shard {i} of {n}, \
                 another sharding, which `mdlod batch --merge` refuses to join with them{alone}",
                out.display(),
                sizes.join(" and ")
            );
        }
    }
    // A batch directory this run creates and leaves empty (it failed before converting
    // a frame: a missing input, a bad option) is removed again; not by a shard, whose
    // siblings may be using it (with their working files elsewhere, it stays empty
    // while they index their inputs).
    let created = !out.exists() && shard.is_none();
    let result = run_batch(&args, out, shard);
    if result.is_err() && created {
        // Fails, leaving it, unless it is empty (but for this run's lock file and the
        // frame index it kept).
        let ours = [
            out.join(mdlod_preprocess::batch::lock_file_name(None)),
            out.join(mdlod_preprocess::batch::INDEX_CACHE),
        ];
        let only_ours = std::fs::read_dir(out)
            .is_ok_and(|entries| entries.flatten().all(|e| ours.contains(&e.path())));
        // (`--index-only` keeps the index of what it could list.)
        if only_ours && !args.index_only {
            for f in &ours {
                let _ = std::fs::remove_file(f);
            }
        }
        let _ = std::fs::remove_dir(out);
    }
    result
}

fn run_batch(args: &Args, out: &std::path::Path, shard: Option<(u32, u32)>) -> Result<()> {
    args.build.check_log10_inputs(&args.inputs)?;
    let mut pattern_notes = Vec::new();
    let mut inputs = expand_patterns_noting(&args.inputs, out, &mut pattern_notes)?;
    for n in &pattern_notes {
        println!("note: {n}");
    }
    // Frames without timesteps are numbered by their input's place in the list: a file
    // set the shell expanded (`water.1 water.10 water.2`) goes in its numbers' order.
    inputs.sort_by(|a, b| natural_cmp(&a.to_string_lossy(), &b.to_string_lossy()));
    for input in &inputs {
        super::check_input_file(input)?;
    }
    super::check_batch_output(out, &inputs)?;
    args.build.check()?;
    let (mut convert, read) = args.build.options();
    // Working files of out-of-core frames: a directory of this run's own, removed on
    // Ctrl-C and SIGTERM (partial frames are redone by the next run).
    std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    let temp_parent = convert.chunks.temp_dir_for(&out.join("frame"));
    let temp_given = convert.chunks.temp_dir.is_some();
    // What runs killed outright left (no handler could remove it): working directories
    // in the batch directory and the working one, and outputs' temporary files
    // (`.frame-<timestep>.mdlod.HOST-PID-XXXXXX.tmp`, a manifest's
    // `.dataset.HOST-PID-XXXXXX.tmp`, those of a `convert` killed there).
    let temp_owner = mdlod_format::writer::any_temp_file_owner;
    crate::interrupt::remove_and_report_leftovers(&[out, &temp_parent], &temp_owner);
    // A directory of finished frames made read-only (an archive) still checks as current:
    // the working directory goes to the system's then (a frame that needs converting is
    // refused before it is built).
    let work = match crate::interrupt::work_dir(&temp_parent) {
        Err(e)
            if !temp_given
                && matches!(
                    e.kind(),
                    std::io::ErrorKind::PermissionDenied | std::io::ErrorKind::ReadOnlyFilesystem
                ) =>
        {
            crate::interrupt::work_dir(&std::env::temp_dir())
        }
        made => made,
    }
    .with_context(|| super::work_dir_context(&temp_parent, temp_given))?;
    // The frames being written when the batch is interrupted go too.
    crate::interrupt::remove_on_interrupt(work.path(), out, temp_owner);
    crate::interrupt::on_interrupt_say(
        "the frames finished are kept, and a rerun of the same command converts only the rest",
    );
    convert.chunks.temp_dir = Some(work.path().to_path_buf());
    // A scheduler's time limit (SIGTERM) or Ctrl-C: the manifest lists every frame
    // finished, also those of the last second, which the batch had yet to write.
    let handle = mdlod_preprocess::batch::ManifestHandle::default();
    crate::interrupt::on_interrupt_run({
        let handle = handle.clone();
        move || {
            if let Err(e) = handle.save_now() {
                eprintln!("could not write the manifest of the frames finished: {e}");
            }
        }
    });
    // `--json`: the counts so far, as a batch that fails gives them.
    crate::interrupt::on_interrupt_json({
        let handle = handle.clone();
        move || {
            let mut map = serde_json::Map::new();
            if let Some((converted, skipped, to_convert)) = handle.counts() {
                map.insert("converted".into(), converted.into());
                map.insert("already_done".into(), skipped.into());
                map.insert("to_convert".into(), to_convert.into());
            }
            map
        }
    });
    let opts = BatchOptions {
        convert,
        read,
        shard,
        memory_limit: args.memory_limit.map_or_else(
            mdlod_preprocess::chunked::default_memory_limit,
            |limit| {
                super::note_memory_limit(limit);
                limit
            },
        ),
        max_jobs: None,
        duplicates: match args.duplicate_timesteps {
            DuplicatesArg::Error => mdlod_preprocess::batch::Duplicates::Error,
            DuplicatesArg::First => mdlod_preprocess::batch::Duplicates::First,
            DuplicatesArg::Last => mdlod_preprocess::batch::Duplicates::Last,
        },
        handle: Some(handle),
        manifest_interval: None,
        keep_going: args.keep_going,
        index_only: args.index_only,
    };
    let report = with_threads(args.threads, || batch(&inputs, out, &opts, &Bar::new()))??;
    if args.index_only {
        return report_index_only(args, out, &inputs, &report);
    }
    if let (Some(e), true) = (&report.index.unsaved, report.index.scanned > 0) {
        println!(
            "note: the frame index could not be kept in {} ({e}): a rerun scans the text \
             dumps again",
            report.index.file.display()
        );
    }
    if let Some(merged) = &report.removed_merged {
        println!(
            "removed {}, which the frames converted now outdate: run `mdlod batch --merge {}` \
             once every shard has finished",
            merged.display(),
            out.display()
        );
    }
    if !report.removed_shard_manifests.is_empty() {
        println!(
            "removed {}, which {} supersedes (a later --merge of them would put their older \
             frames back)",
            report.removed_shard_manifests.join(", "),
            report.manifest.display()
        );
    }
    if !report.duplicates.is_empty() {
        let n = report.duplicates.len();
        println!(
            "note: {n} frame{} left out as duplicate timesteps: {}{}",
            if n == 1 { "" } else { "s" },
            report.duplicates[..n.min(3)].join("; "),
            if n > 3 {
                format!("; and {} more", n - 3)
            } else {
                String::new()
            }
        );
    }
    if !report.strays.is_empty() {
        let files = match report.strays.len() {
            1 => "1 frame file".to_string(),
            n => format!("{n} frame files"),
        };
        let (belong, them) = match report.strays.len() {
            1 => ("belongs", "it"),
            _ => ("belong", "them"),
        };
        println!(
            "note: {files} in {} {belong} to no frame of these inputs (a run over other or \
             longer inputs wrote {them}; left alone, not in the manifest): {}",
            out.display(),
            first_five(&report.strays)
        );
    }
    let one = |n: usize, single: &'static str, plural: &'static str| {
        if n == 1 {
            single
        } else {
            plural
        }
    };
    if !report.kept_gone.is_empty() {
        let n = report.kept_gone.len();
        println!(
            "note: {n} frame{} converted from dumps that are gone since stay{} listed \
             (timestep{} {})",
            one(n, "", "s"),
            one(n, "s", ""),
            one(n, "", "s"),
            first_five(&report.kept_gone)
        );
    }
    if !report.vanished.is_empty() {
        let n = report.vanished.len();
        println!(
            "note: {n} frame{} listed before {} gone with {} dump{} (frame file{} deleted): \
             no longer listed (timestep{} {})",
            one(n, "", "s"),
            one(n, "is", "are"),
            one(n, "its", "their"),
            one(n, "", "s"),
            one(n, "", "s"),
            one(n, "", "s"),
            first_five(&report.vanished)
        );
    }
    if !report.gone_other.is_empty() {
        let n = report.gone_other.len();
        println!(
            "note: {n} frame file{} in {} {} converted from dumps that are gone since, with \
             other settings than this run's (or listed by no manifest): left alone and not \
             listed, as no rerun can convert {} again (a rerun with the settings {} {} \
             converted with lists {} again): {}",
            one(n, "", "s"),
            out.display(),
            one(n, "was", "were"),
            one(n, "it", "them"),
            one(n, "it", "they"),
            one(n, "was", "were"),
            one(n, "it", "them"),
            first_five(&report.gone_other)
        );
    }
    for e in &report.empty {
        println!("{e}");
    }
    for n in &report.notes {
        println!("note: {n}");
    }
    for e in &report.incomplete {
        println!("note: {e}");
    }
    for e in &report.failed {
        eprintln!("error: {e}");
    }
    match report.kept_unchanged {
        0 => {}
        n => println!(
            "note: {n} frame{} of inputs changed since their conversion (appended to, touched or \
             copied) still hold the same bytes: kept",
            if n == 1 { "" } else { "s" }
        ),
    }
    let again = report.redone;
    let n = again.source + again.settings + again.unrecorded;
    // (Frames found outdated and then cut short are left for a rerun, not converted.)
    if n > 0 && report.converted > 0 {
        let mut why = Vec::new();
        if again.source > 0 {
            why.push(format!("{} whose source changed", again.source));
        }
        if again.settings > 0 {
            why.push(format!(
                "{} built with other settings ({})",
                again.settings,
                again.changed.names().join(", ")
            ));
        }
        if again.unrecorded > 0 {
            why.push(format!(
                "{} that no manifest records (a run stopped before it listed {})",
                again.unrecorded,
                if again.unrecorded == 1 { "it" } else { "them" }
            ));
        }
        let (s, verb) = if n == 1 { ("", "was") } else { ("s", "were") };
        println!(
            "note: {n} frame{s} already converted {verb} converted again: {}",
            why.join("; ")
        );
    }
    let empty = match report.empty.len() {
        0 => String::new(),
        1 => ", 1 empty frame skipped".to_string(),
        n => format!(", {n} empty frames skipped"),
    };
    // A newest input still empty holds no frame yet: not among the frames counted.
    let empty_inputs = report.incomplete.iter().filter(|i| i.empty_file).count();
    let empty = match report.incomplete.len() - empty_inputs {
        0 => empty,
        n => format!("{empty}, {n} cut short and left for a rerun"),
    };
    let empty = match report.failed.len() {
        0 => empty,
        n => format!("{empty}, {n} failed (said above; not in the manifest)"),
    };
    // Frames left out as duplicate timesteps are not among the frames to convert.
    let kept = match (report.duplicates.len(), empty_inputs) {
        (0, 0) => String::new(),
        (d, 0) => format!(" ({d} more left out as duplicate timesteps)"),
        (0, 1) => " (and an input still empty, left for a rerun)".to_string(),
        (0, e) => format!(" (and {e} inputs still empty, left for a rerun)"),
        (d, e) => format!(
            " ({d} more left out as duplicate timesteps, and {e} input{} still empty, left \
             for a rerun)",
            if e == 1 { "" } else { "s" }
        ),
    };
    // A shard's share of the frames; without shards every frame is this run's.
    // (Named where it came from when a Slurm job array gave it: a rule that hands each
    // task a whole trajectory of its own converts only a share of it.)
    let share = opts.shard.map_or(String::new(), |(i, n)| {
        let from = match args.shard {
            None => {
                " (from the Slurm job array's variables: `mdlod batch --merge` joins the \
                 shards' manifests once every task has ended; --shard none converts every \
                 frame into dataset.json)"
            }
            Some(_) => "",
        };
        format!(", {} in shard {i} of {n}{from}", report.frames_in_shard)
    });
    // Failed before they could be listed (an input that holds no dump, a header read
    // short of its timestep): frames of the inputs too, so that the counts add up.
    let total = report.frames_total
        + report
            .failed
            .iter()
            .filter(|f| f.listed_timestep.is_none())
            .count();
    // (How many at a time only where something was converted.)
    let jobs = match report.converted + report.failed.len() {
        0 => String::new(),
        _ => format!("; {} at a time", report.jobs),
    };
    println!(
        "{} frame{} in the inputs{kept}{share}: {} converted, {} already done{empty}{jobs}; manifest {}",
        total,
        if total == 1 { "" } else { "s" },
        report.converted,
        report.skipped,
        report.manifest.display()
    );
    // Nothing listed, every frame left for a rerun: said plainly (a file cut short that
    // no run is writing any more converts nothing, however often it is run).
    if report.converted + report.skipped + report.kept_gone.len() == 0
        && !report.incomplete.is_empty()
        && report.failed.is_empty()
    {
        println!(
            "note: {} lists no frame yet: every frame of the inputs is cut short or empty, \
             left for a rerun once the run writing them has written more (if no run is \
             writing them, they are damaged: `mdlod convert` of one says where)",
            report.manifest.display()
        );
    }
    if args.json {
        crate::print_json(serde_json::json!({
            "output": out.display().to_string(),
            "ok": report.failed.is_empty(),
            "manifest": report.manifest.display().to_string(),
            "frames": total,
            "frames_in_shard": report.frames_in_shard,
            "shard": opts.shard.map(|(i, n)| [i, n]),
            "converted": report.converted,
            "already_done": report.skipped,
            "empty": report.empty.len(),
            "left_for_rerun": report.incomplete.iter().map(ToString::to_string).collect::<Vec<_>>(),
            "failed": report.failed.iter().map(ToString::to_string).collect::<Vec<_>>(),
            // Still missing, as a failed or interrupted batch counts them.
            "to_convert": report.failed.len() + report.incomplete.len(),
            "duplicates": report.duplicates.len(),
            "at_a_time": report.jobs,
            "index": index_json(&report.index),
        }));
    }
    if !report.failed.is_empty() {
        let n = report.failed.len();
        let others = if report.converted + report.skipped > 0 {
            " (--keep-going converted the others)"
        } else {
            " (no frame was converted)"
        };
        bail!(
            "{n} frame{} could not be converted{others}; fix or replace {} and run the batch \
             again: it converts only what is missing",
            if n == 1 { "" } else { "s" },
            if n == 1 { "its input" } else { "their inputs" }
        );
    }
    Ok(())
}

/// The JSON of how a batch listed its inputs: `file` is null where no index was kept
/// (no text dump to index, every one still being written, or the file not writable).
fn index_json(index: &mdlod_preprocess::batch::IndexUse) -> serde_json::Value {
    let text = index.from_cache + index.scanned;
    let kept = text > index.unsettled && index.unsaved.is_none();
    serde_json::json!({
        "file": kept.then(|| index.file.display().to_string()),
        "from_cache": index.from_cache,
        "scanned": index.scanned,
        "not_kept_unsettled": index.unsettled,
        "not_indexed": index.not_kept,
        "unsaved": index.unsaved,
    })
}

/// What `--index-only` says: the frames found, the cache written, and the inputs that
/// could not be listed.
fn report_index_only(
    args: &Args,
    out: &std::path::Path,
    inputs: &[PathBuf],
    report: &mdlod_preprocess::batch::BatchReport,
) -> Result<()> {
    for n in &report.notes {
        println!("note: {n}");
    }
    for e in &report.incomplete {
        println!("note: {e}");
    }
    for e in &report.failed {
        println!("{e}");
    }
    if !report.duplicates.is_empty() {
        let n = report.duplicates.len();
        println!(
            "note: {n} frame{} left out as duplicates of a timestep ({}): the runs into this \
             directory leave them out the same way with the same --duplicate-timesteps",
            if n == 1 { "" } else { "s" },
            first_five(&report.duplicates)
        );
    }
    let index = &report.index;
    let text = index.from_cache + index.scanned;
    let plural = |n: usize| if n == 1 { "" } else { "s" };
    let frames = format!(
        "{} frame{} in {} input{}",
        report.frames_total,
        plural(report.frames_total),
        inputs.len(),
        plural(inputs.len()),
    );
    // Binary dumps give their frames from their headers; gzip files are decompressed
    // by every run.
    let others = match index.not_kept {
        0 => String::new(),
        n => format!(
            "; {n} input{} not indexed (binary dumps, GSD, MMPLD and raw arrays give their \
             frames from their headers, gzip files are decompressed by every run)",
            plural(n)
        ),
    };
    if text == 0 {
        println!("{frames}; no text dump to index{others}");
    } else if index.unsettled >= text {
        println!("{frames}; no frame index kept{others}");
    } else {
        println!(
            "{frames}; the frame index of {}{text} text file{} kept in {} ({} scanned, {} \
             unchanged since they were){others}: runs and shards of a batch into {} list \
             them from it",
            match text - index.unsettled.min(text) {
                kept if kept < text => format!("{kept} of "),
                _ => String::new(),
            },
            plural(text),
            index.file.display(),
            index.scanned,
            index.from_cache,
            out.display(),
        );
    }
    if let Some(e) = &index.unsaved {
        println!("note: {e}");
    }
    if index.unsettled > 0 {
        let n = index.unsettled;
        println!(
            "note: {n} file{} scanned but not kept in the index: modified in the last \
             seconds (a run may still be writing {}) or dated ahead of this machine's clock; \
             index again once {} settled",
            if n == 1 { "" } else { "s" },
            if n == 1 { "it" } else { "them" },
            if n == 1 { "it has" } else { "they have" },
        );
    }
    if args.json {
        crate::print_json(serde_json::json!({
            "output": out.display().to_string(),
            "ok": report.failed.is_empty(),
            "frames": report.frames_total,
            "inputs": inputs.len(),
            "duplicates": report.duplicates.len(),
            "left_for_rerun": report.incomplete.iter().map(ToString::to_string).collect::<Vec<_>>(),
            "failed": report.failed.iter().map(ToString::to_string).collect::<Vec<_>>(),
            "index": index_json(index),
        }));
    }
    if !report.failed.is_empty() {
        bail!(
            "{} input{} could not be listed; fix or replace them and index again",
            report.failed.len(),
            plural(report.failed.len())
        );
    }
    Ok(())
}

/// The first five of `items`, comma-separated, with how many more (`a, b and 3 more`).
fn first_five<T: std::fmt::Display>(items: &[T]) -> String {
    let shown: Vec<String> = items.iter().take(5).map(T::to_string).collect();
    match items.len().saturating_sub(5) {
        0 => shown.join(", "),
        more => format!("{} and {more} more", shown.join(", ")),
    }
}

#[cfg(test)]
mod tests {
    use super::slurm_shard;

    fn env<'a>(vars: &'a [(&'a str, &'a str)]) -> impl Fn(&str) -> Option<String> + 'a {
        move |name| {
            vars.iter()
                .find(|(n, _)| *n == name)
                .map(|(_, v)| v.to_string())
        }
    }

    #[test]
    fn slurm_arrays_with_an_offset_and_a_step_give_every_shard_once() {
        // --array=1-31:2: 16 tasks with IDs 1, 3, ..., 31.
        let mut shards = vec![];
        for id in (1..=31).step_by(2) {
            let id = id.to_string();
            let vars = [
                ("SLURM_ARRAY_TASK_ID", id.as_str()),
                ("SLURM_ARRAY_TASK_MIN", "1"),
                ("SLURM_ARRAY_TASK_STEP", "2"),
                ("SLURM_ARRAY_TASK_COUNT", "16"),
            ];
            shards.push(slurm_shard(env(&vars)).unwrap().unwrap());
        }
        assert_eq!(shards, (0..16).map(|i| (i, 16)).collect::<Vec<_>>());
        // Without a step or a minimum: the ID itself.
        let vars = [
            ("SLURM_ARRAY_TASK_ID", "3"),
            ("SLURM_ARRAY_TASK_COUNT", "4"),
        ];
        assert_eq!(slurm_shard(env(&vars)).unwrap(), Some((3, 4)));
        // Not in an array: no shard.
        assert_eq!(slurm_shard(env(&[])).unwrap(), None);
    }

    #[test]
    fn slurm_ids_off_the_array_are_errors_not_wrong_shards() {
        let off_step = [
            ("SLURM_ARRAY_TASK_ID", "4"),
            ("SLURM_ARRAY_TASK_MIN", "1"),
            ("SLURM_ARRAY_TASK_STEP", "2"),
            ("SLURM_ARRAY_TASK_COUNT", "16"),
        ];
        let e = slurm_shard(env(&off_step)).unwrap_err().to_string();
        assert!(e.contains("not on the array's step 2"), "{e}");
        let below = [
            ("SLURM_ARRAY_TASK_ID", "0"),
            ("SLURM_ARRAY_TASK_MIN", "1"),
            ("SLURM_ARRAY_TASK_COUNT", "2"),
        ];
        let e = slurm_shard(env(&below)).unwrap_err().to_string();
        assert!(e.contains("below SLURM_ARRAY_TASK_MIN"), "{e}");
        let past = [
            ("SLURM_ARRAY_TASK_ID", "5"),
            ("SLURM_ARRAY_TASK_COUNT", "4"),
        ];
        let e = format!("{:#}", slurm_shard(env(&past)).unwrap_err());
        assert!(
            e.contains("SLURM_ARRAY_TASK_ID 5") && e.contains("past SLURM_ARRAY_TASK_COUNT 4"),
            "{e}"
        );
    }

    /// An environment that names no position fails, naming the variables, instead of
    /// converting every frame in every task.
    #[test]
    fn incomplete_or_unusable_slurm_variables_are_errors() {
        let cases: [(&[(&str, &str)], &str); 5] = [
            (
                &[("SLURM_ARRAY_TASK_ID", "1")],
                "SLURM_ARRAY_TASK_ID is set but not SLURM_ARRAY_TASK_COUNT",
            ),
            (
                &[("SLURM_ARRAY_TASK_COUNT", "4")],
                "SLURM_ARRAY_TASK_COUNT is set but not SLURM_ARRAY_TASK_ID",
            ),
            (
                &[
                    ("SLURM_ARRAY_TASK_ID", "abc"),
                    ("SLURM_ARRAY_TASK_COUNT", "4"),
                ],
                "SLURM_ARRAY_TASK_ID is \"abc\"",
            ),
            (
                &[
                    ("SLURM_ARRAY_TASK_ID", "1"),
                    ("SLURM_ARRAY_TASK_COUNT", "4"),
                    ("SLURM_ARRAY_TASK_MIN", "x"),
                ],
                "SLURM_ARRAY_TASK_MIN is \"x\"",
            ),
            // --array=1,3,7: Slurm says MIN 1, MAX 7, COUNT 3.
            (
                &[
                    ("SLURM_ARRAY_TASK_ID", "3"),
                    ("SLURM_ARRAY_TASK_COUNT", "3"),
                    ("SLURM_ARRAY_TASK_MIN", "1"),
                    ("SLURM_ARRAY_TASK_MAX", "7"),
                    ("SLURM_ARRAY_TASK_STEP", "1"),
                ],
                "given as a list",
            ),
        ];
        for (vars, want) in cases {
            let e = slurm_shard(env(vars)).unwrap_err().to_string();
            assert!(
                e.contains(want) && e.contains("--shard I/N"),
                "{vars:?}: {e}"
            );
        }
        // A range with its MAX agrees.
        let vars = [
            ("SLURM_ARRAY_TASK_ID", "7"),
            ("SLURM_ARRAY_TASK_COUNT", "4"),
            ("SLURM_ARRAY_TASK_MIN", "1"),
            ("SLURM_ARRAY_TASK_MAX", "7"),
            ("SLURM_ARRAY_TASK_STEP", "2"),
        ];
        assert_eq!(slurm_shard(env(&vars)).unwrap(), Some((3, 4)));
        // Shards on the command line: a count of 0 is named as such.
        let e = format!("{:#}", super::parse_shard("1/0").unwrap_err());
        assert!(e.contains("count must be at least 1"), "{e}");
        let e = format!("{:#}", super::parse_shard("4/4").unwrap_err());
        assert!(e.contains("index 4 must be below the count 4"), "{e}");
        assert_eq!(
            super::parse_shard("3/16").unwrap(),
            super::ShardArg::Part(3, 16)
        );
        // `none`: the whole run, which a job array's task gets no other way.
        assert_eq!(super::parse_shard("none").unwrap(), super::ShardArg::Whole);
    }
}
