//! `mdlod info`: what a `.mdlod` file holds.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use mdlod_format::MdlodFile;
use serde_json::json;

/// Show what a .mdlod file holds (particles, levels, species, box, build parameters), a
/// .sndf file (texels, bins, rays, the camera), or a batch directory (its trajectory:
/// frames, timesteps, times, particles, species, attribute range, what is missing).
#[derive(clap::Args)]
#[command(after_help = "Example:\n  mdlod info frame.mdlod --json | jq .particles")]
pub struct Args {
    /// The .mdlod or .sndf file to describe, or a batch directory (or its dataset.json).
    pub file: PathBuf,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
    /// Count each species' particles also in files above 2×10^7 particles (it reads
    /// every particle's species: 2 bytes each); smaller files are always counted.
    #[arg(long)]
    pub counts: bool,
}

/// Files of at most this many particles have their species counted by default.
const COUNT_UP_TO: u64 = 20_000_000;

/// The particles of each species; an index past the table is corruption, named (the
/// counts would not add up to the particles).
fn species_counts(f: &MdlodFile) -> Result<Vec<u64>, mdlod_format::FormatError> {
    // (Counting reads the whole section: its checksum costs little more, and a flipped
    // byte gave wrong counts.)
    f.check_checksums_of(mdlod_format::layout::SectionKind::Species)?;
    let mut counts = vec![0u64; f.metadata().species.len()];
    for (k, &s) in f.species().iter().enumerate() {
        match counts.get_mut(usize::from(s)) {
            Some(c) => *c += 1,
            None => {
                return Err(mdlod_format::FormatError::Corrupt {
                    path: f.path().to_path_buf(),
                    place: format!("SPECIES, particle {k}"),
                    problem: format!(
                        "species index {s} but only {} species (`mdlod verify` checks the \
                         whole file)",
                        counts.len()
                    ),
                })
            }
        }
    }
    Ok(counts)
}

/// What a batch directory `dir` holds, from its manifest and its frames' metadata:
/// frames, timesteps and times, particles, species, the attribute's range over every
/// frame, the files' size, and what is missing or failed.
/// The progress of a sharded batch whose shards are not merged yet (a Slurm array
/// still running): each shard manifest's frames against those its shard owns, and the
/// shards with none yet; false where the directory has no shard manifest.
fn shards_info(dir: &std::path::Path, args: &Args) -> Result<bool> {
    use mdlod_preprocess::batch::{is_shard_manifest, parse_manifest};
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .with_context(|| format!("cannot list {}", dir.display()))?
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| is_shard_manifest(n))
        .collect();
    if names.is_empty() {
        return Ok(false);
    }
    names.sort_by(|a, b| mdlod_preprocess::batch::natural_cmp(a, b));
    let mut rows = Vec::new();
    let mut counts = std::collections::BTreeSet::new();
    // The lists of input frames the shards split (a merge refuses shards that saw
    // different ones).
    let mut lists = std::collections::BTreeSet::new();
    // Frame files a shard lists that are not there (moved away, deleted): a fault, as in
    // a merged directory, not progress.
    let mut gone: Vec<String> = Vec::new();
    for name in &names {
        let path = dir.join(name);
        let text = mdlod_format::files::read_capped(&path, mdlod_format::files::MANIFEST_BYTES)
            .with_context(|| format!("cannot read {}", path.display()))?;
        let m = parse_manifest(&path, &text, "shard")?;
        let Some([i, n]) = m.shard else { continue };
        counts.insert(n);
        if let Some(l) = &m.input_frames {
            lists.insert((l.count, l.xxh3.clone()));
        }
        let listed = m.frames.len() as u64;
        gone.extend(
            m.frames
                .iter()
                .filter(|f| !dir.join(&f.file).exists())
                .map(|f| f.file.clone()),
        );
        rows.push((i, n, listed, m.expected_frames, m.failed.len()));
    }
    // Shards of different array sizes (a task resubmitted alone runs as shard 0 of 1).
    let mixed = (counts.len() > 1).then(|| {
        format!(
            "the manifests are of different shard counts ({}): a merge refuses them",
            counts
                .iter()
                .map(u32::to_string)
                .collect::<Vec<_>>()
                .join(", ")
        )
    });
    gone.sort_by(|a, b| mdlod_preprocess::batch::natural_cmp(a, b));
    let gone_error = (!gone.is_empty()).then(|| {
        format!(
            "{}: {} frame file{} the shards list {} not there ({}): `mdlod verify {}` \
             checks every frame",
            dir.display(),
            gone.len(),
            if gone.len() == 1 { "" } else { "s" },
            if gone.len() == 1 { "is" } else { "are" },
            gone.join(", "),
            dir.display()
        )
    });
    if args.json {
        let shards: Vec<serde_json::Value> = rows
            .iter()
            .map(|(i, n, listed, expected, failed)| {
                json!({ "shard": [i, n], "frames": listed, "expected_frames": expected,
                        "failed": failed })
            })
            .collect();
        let mut v = json!({
            "ok": true,
            "kind": "shards",
            "merged": false,
            "shards": shards,
            "shard_counts": counts,
            "missing_files": gone,
            "notes": mixed.iter().collect::<Vec<_>>(),
        });
        if let Some(e) = gone_error {
            v["ok"] = false.into();
            v["error"] = e.clone().into();
            crate::print_json(v);
            bail!(e);
        }
        println!("{}", serde_json::to_string(&v)?);
        return Ok(true);
    }
    println!(
        "{}: a sharded batch, not merged yet ({} shard manifest{})",
        dir.display(),
        rows.len(),
        if rows.len() == 1 { "" } else { "s" }
    );
    let mut complete = true;
    for (i, n, listed, expected, failed) in &rows {
        let state = match expected {
            Some(e) if listed >= e && *failed == 0 => "complete".to_string(),
            // As the merge counts it: every frame it could convert is listed; those that
            // failed (`--keep-going`) are reported, and a rerun tries them again.
            Some(e) if listed >= e => "finished; its failed frames a rerun tries again".to_string(),
            Some(e) => {
                complete = false;
                format!("{} of {e}: still running, failed or killed", listed)
            }
            None => {
                complete = false;
                "its count unknown".to_string()
            }
        };
        let failed = match failed {
            0 => String::new(),
            k => format!(", {k} failed"),
        };
        println!("  shard {i} of {n}  {listed} frames{failed} ({state})");
    }
    // Shards with no manifest yet (not started, or started elsewhere still indexing).
    if let [n] = counts.iter().copied().collect::<Vec<u32>>()[..] {
        let missing: Vec<String> = (0..n)
            .filter(|k| !rows.iter().any(|(i, ..)| i == k))
            .map(|k| k.to_string())
            .collect();
        if !missing.is_empty() {
            complete = false;
            println!("  no manifest yet: shard {} of {n}", missing.join(", "));
        }
    } else {
        complete = false;
        if let Some(note) = &mixed {
            println!("  note: {note}");
        }
    }
    if lists.len() > 1 {
        println!(
            "  note: the shards split different lists of input frames (inputs added or \
             deleted between their runs): a merge refuses them; rerun the shards over the \
             same inputs"
        );
    } else if complete {
        // (Complete shards a merge still refuses: frames built with other settings.)
        match mdlod_preprocess::batch::merged_manifest(dir) {
            Ok(_) => println!(
                "  every shard is complete: `mdlod batch --merge {}` joins them",
                dir.display()
            ),
            Err(e) => println!("  every shard is complete, but a merge refuses them: {e}"),
        }
    } else {
        println!(
            "  once every shard is complete, `mdlod batch --merge {}` joins them",
            dir.display()
        );
    }
    match gone_error {
        Some(e) => bail!(e),
        None => Ok(true),
    }
}

fn batch_info(dir: &std::path::Path, args: &Args) -> Result<()> {
    let m = mdlod_preprocess::batch::read_manifest(dir)?;
    let frames = &m.frames;
    let mut species: Vec<String> = Vec::new();
    let mut attribute: Option<(String, f32, f32)> = None;
    let mut attributes_differ = false;
    // Further attributes, each with its range over the frames that keep it.
    let mut extras: Vec<(String, f32, f32)> = Vec::new();
    // The attributes some frame keeps as logarithms (the metadata's `attribute_log10`, an
    // entry's `log10`), by name.
    let mut logged: std::collections::BTreeSet<String> = Default::default();
    // How many frames keep each of `extras`, and how many frames opened.
    let mut extras_kept: Vec<usize> = Vec::new();
    let mut opened = 0usize;
    let mut bytes = 0u64;
    let mut unreadable = Vec::new();
    for f in frames {
        let path = dir.join(&f.file);
        bytes += std::fs::metadata(&path).map_or(0, |m| m.len());
        // (Its metadata only: a few pages of each frame, not megabytes around each.)
        let file = match MdlodFile::open_sparse(&path) {
            Ok(file) => file,
            Err(e) => {
                unreadable.push(format!("{}: {e}", f.file));
                continue;
            }
        };
        let meta = file.metadata();
        opened += 1;
        for s in &meta.species {
            if !species.contains(&s.name) {
                species.push(s.name.clone());
            }
        }
        logged.extend(
            meta.attribute
                .iter()
                .filter(|_| meta.attribute_log10)
                .chain(meta.attributes.iter().filter(|a| a.log10))
                .map(|a| a.name.clone()),
        );
        for a in &meta.attributes {
            match extras.iter().position(|(n, _, _)| *n == a.name) {
                Some(i) => {
                    let (_, lo, hi) = &mut extras[i];
                    *lo = lo.min(a.min);
                    *hi = hi.max(a.max);
                    extras_kept[i] += 1;
                }
                None => {
                    extras.push((a.name.clone(), a.min, a.max));
                    extras_kept.push(1);
                }
            }
        }
        match (&mut attribute, &meta.attribute) {
            (None, Some(a)) if !attributes_differ => {
                attribute = Some((a.name.clone(), a.min, a.max));
            }
            (Some((name, lo, hi)), Some(a)) if *name == a.name => {
                *lo = lo.min(a.min);
                *hi = hi.max(a.max);
            }
            (None, None) => {}
            _ => {
                attribute = None;
                attributes_differ = true;
            }
        }
    }
    let first = frames.iter().map(|f| f.timestep).min();
    let last = frames.iter().map(|f| f.timestep).max();
    let times: Vec<f64> = frames.iter().filter_map(|f| f.time).collect();
    let particles: Vec<u64> = frames.iter().map(|f| f.particles).collect();
    let (fewest, most) = (
        particles.iter().copied().min().unwrap_or(0),
        particles.iter().copied().max().unwrap_or(0),
    );
    let missing = m
        .expected_frames
        .map_or(0, |e| e.saturating_sub(frames.len() as u64));
    let column = frames.iter().find_map(|f| f.species_column.clone());
    if args.json {
        // An attribute's entry, with `log10` where it is a logarithm (as a file's entries).
        let entry = |n: &String, lo: f32, hi: f32| {
            let mut e = json!({ "name": n, "min": lo, "max": hi });
            if logged.contains(n) {
                e["log10"] = true.into();
            }
            e
        };
        let v = json!({
            "ok": true,
            "kind": "batch",
            "batch": dir.display().to_string(),
            "frames": frames.len(),
            "timesteps": first.zip(last).map(|(a, b)| [a, b]),
            "times": (!times.is_empty()).then(|| [
                times.iter().copied().fold(f64::INFINITY, f64::min),
                times.iter().copied().fold(f64::NEG_INFINITY, f64::max),
            ]),
            "particles": [fewest, most],
            "species": species,
            "species_column": column,
            "attribute": attribute.as_ref().map(|(n, lo, hi)| entry(n, *lo, *hi)),
            "attributes": extras.iter().map(|(n, lo, hi)| entry(n, *lo, *hi)).collect::<Vec<_>>(),
            "bytes": bytes,
            "expected_frames": m.expected_frames,
            "failed": m.failed.iter().map(|f| json!({
                "timestep": f.timestep, "input": f.input, "frame": f.frame, "reason": f.reason
            })).collect::<Vec<_>>(),
            "unreadable": unreadable,
            // Frames without particles, left out.
            "empty": m.empty.iter().map(|e| json!({
                "timestep": e.timestep, "input": e.input, "frame": e.frame
            })).collect::<Vec<_>>(),
            // Frames of deleted dumps converted with other settings: on disk, not listed.
            "unlisted": m.unlisted.iter().map(|f| json!({
                "timestep": f.timestep, "file": f.file
            })).collect::<Vec<_>>(),
        });
        // The ranges are the frames' f32s: written as a file's own `info` writes them.
        let mut v = v;
        shortest_f32(&mut v["attribute"]);
        shortest_f32(&mut v["attributes"]);
        if let Some(e) = unreadable_error(dir, unreadable.len()) {
            // The description, as a check's result that found faults.
            v["ok"] = false.into();
            v["error"] = e.clone().into();
            crate::print_json(v);
            bail!(e);
        }
        v["ok"] = true.into();
        println!("{}", serde_json::to_string(&v)?);
        return Ok(());
    }
    println!("{} (batch directory)", dir.display());
    match (first, last) {
        (Some(a), Some(b)) => {
            // A regular interval where the timesteps have one.
            let mut steps: Vec<u64> = frames.iter().map(|f| f.timestep).collect();
            steps.sort_unstable();
            let gaps: std::collections::BTreeSet<u64> =
                steps.windows(2).map(|w| w[1] - w[0]).collect();
            // A timestep listed twice (a manifest edited or damaged: `verify` refuses
            // it) is said, not read as an interval of 0.
            let repeated = steps.windows(2).filter(|w| w[0] == w[1]).count();
            let every = match gaps.len() {
                _ if repeated > 0 => format!(
                    "; {repeated} frame{} repeat{} a timestep listed before: `mdlod verify` \
                     names them",
                    if repeated == 1 { "" } else { "s" },
                    if repeated == 1 { "s" } else { "" }
                ),
                1 => format!(", every {}", gaps.iter().next().copied().unwrap_or(0)),
                _ => String::new(),
            };
            if frames.len() == 1 {
                println!("  frames       1 (timestep {a})");
            } else {
                println!(
                    "  frames       {} (timesteps {a} to {b}{every})",
                    frames.len()
                );
            }
        }
        _ => println!("  frames       0"),
    }
    if !times.is_empty() {
        let lo = times.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = times.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let of = if times.len() < frames.len() {
            format!(" ({} of the frames record one)", times.len())
        } else {
            String::new()
        };
        println!(
            "  times        {} to {}{of}",
            super::Num(lo as f32),
            super::Num(hi as f32)
        );
    }
    // (A batch that lists no frame yet has no particles or species to describe.)
    match opened {
        0 => {}
        _ if fewest == most => println!("  particles    {most} per frame"),
        _ => println!("  particles    {fewest} to {most} per frame"),
    }
    let names: Vec<String> = species.iter().map(|s| shown(s)).collect();
    if !names.is_empty() {
        println!("  species      {} (of any frame)", names.join(", "));
    }
    if let Some(c) = &column {
        println!(
            "  (species are the values of the input's column {}, not its types)",
            shown(c)
        );
    }
    // (Frames that could not be read add nothing to a range: it is over those read.)
    let every = match unreadable.len() {
        0 => "every frame".to_string(),
        _ => format!(
            "the {opened} frame{} read (not the {} unreadable)",
            if opened == 1 { "" } else { "s" },
            unreadable.len()
        ),
    };
    match (&attribute, attributes_differ) {
        (Some((n, lo, hi)), _) => println!(
            "  attribute    {} in [{}, {}] over {every}",
            shown(n),
            super::Num(*lo),
            super::Num(*hi)
        ),
        (None, true) => println!("  attribute    not the same in every frame"),
        (None, false) => {}
    }
    for ((n, lo, hi), kept) in extras.iter().zip(&extras_kept) {
        let over = if *kept == opened {
            every.clone()
        } else {
            format!(
                "the {kept} frame{} keeping it",
                if *kept == 1 { "" } else { "s" }
            )
        };
        println!(
            "  attribute    {} in [{}, {}] over {over}",
            shown(n),
            super::Num(*lo),
            super::Num(*hi)
        );
    }
    println!("  size         {}", super::size_text(bytes));
    if !m.failed.is_empty() {
        println!(
            "  failed       {} frame{} the batch could not convert: {} (`mdlod verify {}` \
             says why)",
            m.failed.len(),
            if m.failed.len() == 1 { "" } else { "s" },
            m.failed_names(),
            dir.display()
        );
    }
    if !m.empty.is_empty() {
        let n = m.empty.len();
        let steps = m.empty.iter().map(|e| e.timestep).collect();
        println!(
            "  empty        {n} frame{} without particles, not converted (a .mdlod file needs \
             one): {}",
            if n == 1 { "" } else { "s" },
            mdlod_preprocess::batch::timesteps_text(&steps)
        );
    }
    if !m.unlisted.is_empty() {
        let n = m.unlisted.len();
        println!(
            "  unlisted     {n} frame{} of deleted dumps, converted with other settings than \
             the last run's, kept on disk (a batch with their settings lists {} again)",
            if n == 1 { "" } else { "s" },
            if n == 1 { "it" } else { "them" }
        );
    }
    if missing > 0 {
        println!(
            "  missing      {missing} of the {} frames the run is to convert (still running, \
             or stopped: rerun the batch)",
            m.expected_frames.unwrap_or(0)
        );
    }
    for u in &unreadable {
        println!("  unreadable   {u}");
    }
    match unreadable_error(dir, unreadable.len()) {
        Some(e) => bail!(e),
        None => Ok(()),
    }
}

/// The failure of describing a batch directory some of whose listed frames could not be
/// read (moved away, deleted, damaged): described as far as it could be, then an error,
/// as a script reading its counts would take them for the whole data set's.
fn unreadable_error(dir: &std::path::Path, unreadable: usize) -> Option<String> {
    (unreadable > 0).then(|| {
        format!(
            "{}: {unreadable} listed frame{} could not be read (the counts and ranges are \
             over the others); `mdlod verify {}` checks every frame",
            dir.display(),
            if unreadable == 1 { "" } else { "s" },
            dir.display()
        )
    })
}

/// A `.sndf` file's header.
fn sndf_info(args: &Args) -> Result<()> {
    let (header, bytes) = mdlod_format::sndf::SndfData::load_header(&args.file)?;
    let h = &header;
    // A camera shade could not use is refused here as there.
    mdlod_render::sndf_camera(&args.file, &h.view)?;
    // A tiled file's display level is a bias over the level of its view's pixels: the
    // level shown is worked out from the view as `shade` does.
    let levels_shown = mdlod_render::sndf_display_levels(&args.file, h)?;
    let shown_text = |levels: &[(u32, f64)]| match levels {
        [(l, _)] => format!("level {l}"),
        [(a, wa), (b, wb)] => format!(
            "levels {a} and {b} blended ({:.0} % and {:.0} %)",
            wa * 100.0,
            wb * 100.0
        ),
        _ => "level 0".to_string(),
    };
    // The camera's numbers are f32s: their shortest form (63.43495, not 63.4349479675293).
    let mut view = h.view.clone();
    shortest_f32(&mut view);
    if args.json {
        let v = json!({
            "ok": true,
            "file": args.file.display().to_string(),
            "kind": "sndf",
            "width": h.width,
            "height": h.height,
            "bins": h.bins,
            "binning": h.binning,
            "rays": h.rays,
            "normal_frame": h.normal_frame.as_deref().unwrap_or("camera"),
            "display_level": h.display_level.unwrap_or(0),
            "shown_at_levels": levels_shown.as_ref().map(|levels| {
                levels
                    .iter()
                    .map(|&(l, w)| json!({"level": l, "weight": w}))
                    .collect::<Vec<_>>()
            }),
            "source": h.source,
            "view": view,
            "data_bytes": bytes,
        });
        let mut v = v;
        v["ok"] = true.into();
        println!("{}", serde_json::to_string(&v)?);
        return Ok(());
    }
    println!("{}", args.file.display());
    println!(
        "  S-NDFs       {}x{} texels, {}x{} {} bins, {} rays each, {:.1} MiB",
        h.width,
        h.height,
        h.bins,
        h.bins,
        h.binning,
        h.rays,
        bytes as f64 / (1 << 20) as f64
    );
    match &levels_shown {
        Some(levels) => println!("  shown at     {} of its S-MIP tiles", shown_text(levels)),
        None => println!("  shown at     level {}", h.display_level.unwrap_or(0)),
    }
    if let Some(s) = &h.source {
        println!("  sampled from {}", shown(s));
    }
    println!("  view         {view}");
    if h.normal_frame.is_some() {
        println!("  normals      binned along each texel's ray");
    } else if let Some(n) = super::shade::camera_frame_note(h) {
        println!("{n}");
    }
    Ok(())
}

pub fn run(args: Args) -> Result<()> {
    if args.json {
        crate::json_errors();
    }
    // The first 8 bytes tell an S-NDF file from a .mdlod one.
    let is_sndf =
        super::file_head(&args.file).is_some_and(|h| h[..] == mdlod_format::sndf::SNDF_MAGIC[..]);
    if is_sndf {
        return sndf_info(&args);
    }
    // A batch directory (or its manifest): the trajectory.
    let dir = super::batch_dir_of(args.file.clone());
    if dir != args.file {
        return batch_info(&dir, &args);
    }
    if args.file.is_dir() && !args.file.join(mdlod_preprocess::batch::MANIFEST).exists() {
        // A sharded batch not merged yet: how far each shard is.
        if shards_info(&args.file, &args)? {
            return Ok(());
        }
    }
    if args.file.is_dir() {
        super::view::unmerged_batch(&args.file)?;
        if args.file.join(mdlod_preprocess::batch::MANIFEST).is_file() {
            return batch_info(&args.file, &args);
        }
        // A directory a `batch --index-only` has indexed: no frame converted yet.
        if args
            .file
            .join(mdlod_preprocess::batch::INDEX_CACHE)
            .is_file()
        {
            bail!(
                "{}: a batch directory whose inputs are indexed ({}) but of which no frame \
                 is converted yet: `mdlod batch` with the same inputs converts them and \
                 writes its {}",
                args.file.display(),
                mdlod_preprocess::batch::INDEX_CACHE,
                mdlod_preprocess::batch::MANIFEST
            );
        }
        // (Said as `render` and `view` say it.)
        bail!(
            "{}: a directory is described as the frames of a batch, listed in its {}; there \
             is none here (`mdlod batch` writes one; a dump is converted first)",
            args.file.display(),
            mdlod_preprocess::batch::MANIFEST
        );
    }
    let f = MdlodFile::open(&args.file)?;
    let m = f.metadata();
    let levels: Vec<u64> = f.levels().iter().map(|l| l.point_count).collect();
    let file_size = std::fs::metadata(&args.file).map(|m| m.len()).unwrap_or(0);
    let counts = (args.counts || m.particles <= COUNT_UP_TO)
        .then(|| species_counts(&f))
        .transpose()?;
    // What the particles' spheres span: the top node's box.
    let extent = f.nodes().first().map(|n| (n.bounds_min, n.bounds_max));
    // Positions are single precision: far from the origin their own spacing, not the
    // quantization, bounds how far they may lie from an input of more digits. (The
    // extent holds the spheres: every centre lies at least the smallest radius inside.)
    let smallest_radius = m
        .species
        .iter()
        .map(mdlod_format::meta::Species::smallest_radius)
        .fold(f32::INFINITY, f32::min);
    let spacing = extent.map_or(0.0, |(lo, hi)| {
        let r = if smallest_radius.is_finite() {
            smallest_radius.max(0.0)
        } else {
            0.0
        };
        if (0..3).all(|k| lo[k] + r <= hi[k] - r) {
            single_precision_spacing(lo.map(|v| v + r), hi.map(|v| v - r))
        } else {
            single_precision_spacing(lo, hi)
        }
    });
    let rounded_first = f64::from(spacing) / 2.0 > m.max_position_error;
    // Two-dimensional data (every centre in one plane), which views face square on.
    let flat = mdlod_render::flat_axis(&f);
    // Or a line of them (the spheres' box no wider than the largest sphere across two
    // axes), which views look across, along the flat axis.
    let largest_radius = m
        .species
        .iter()
        .map(|s| s.radius)
        .chain(m.radius.map(|r| r.max))
        .fold(0.0f32, f32::max);
    let line = flat.is_some()
        && extent.is_some_and(|(lo, hi)| {
            let thin = |k: usize| {
                hi[k] - lo[k]
                    <= 2.0 * largest_radius * 1.001
                        + 8.0 * f32::EPSILON * hi[k].abs().max(lo[k].abs())
            };
            (0..3).filter(|&k| thin(k)).count() >= 2
        });
    if args.json {
        let mut v = json!({
            "ok": true,
            "kind": "mdlod",
            "file": args.file.display().to_string(),
            "file_size": file_size,
            "format_version": format!("{}.{}", f.header().version_major, f.header().version_minor),
            "particles": m.particles,
            "levels": f.level_count(),
            "level_points": levels,
            "nodes": f.nodes().len(),
            "species": m.species,
            // (The first's logarithm, the metadata's `attribute_log10`, said in its entry as
            // the further attributes' are.)
            "attribute": m.attribute.as_ref().map(|a| {
                let mut e = json!(a);
                if m.attribute_log10 {
                    e["log10"] = true.into();
                }
                e
            }),
            "attributes": m.attributes,
            "radius": m.radius.map(|r| json!({
                "min": r.min,
                "max": r.max,
                "scale": if r.log { "log" } else { "linear" },
            })),
            "species_column": m.species_column,
            "box": m.simulation_box,
            "extent": extent.map(|(lo, hi)| json!({ "min": lo, "max": hi })),
            "flat_axis": flat.map(|k| ["x", "y", "z"][k]),
            "timestep": m.timestep,
            "time": m.time,
            "units": m.units,
            "source": m.source,
            "build": m.build,
            "max_position_error": m.max_position_error,
            "single_precision_spacing": spacing,
            "writer": m.writer,
            "input_options": m.input_options,
        });
        // Radii, colours and the attribute's range are f32s: their shortest form, not
        // their f64 widening (1.28, not 1.2799999713897705).
        shortest_f32(&mut v["species"]);
        shortest_f32(&mut v["attribute"]);
        shortest_f32(&mut v["attributes"]);
        shortest_f32(&mut v["radius"]);
        shortest_f32(&mut v["extent"]);
        if let (Some(counts), Some(list)) = (&counts, v["species"].as_array_mut()) {
            for (s, c) in list.iter_mut().zip(counts) {
                s["count"] = json!(c);
            }
        }
        v["ok"] = true.into();
        println!("{}", serde_json::to_string(&v)?);
        return Ok(());
    }
    println!("{}", args.file.display());
    println!(
        "  format {}.{}, {}, written by {}",
        f.header().version_major,
        f.header().version_minor,
        super::size_text(file_size),
        shown(&m.writer)
    );
    println!("  particles    {}", m.particles);
    println!(
        "  levels       {} (points per level, top first: {})",
        f.level_count(),
        levels
            .iter()
            .map(u64::to_string)
            .collect::<Vec<_>>()
            .join(" ")
    );
    println!("  nodes        {}", f.nodes().len());
    for (k, s) in m.species.iter().enumerate() {
        let count = counts.as_ref().map_or(String::new(), |c| match c[k] {
            1 => "  1 particle".to_string(),
            n => format!("  {n} particles"),
        });
        // Polydisperse species: each particle drawn at its own radius where the file
        // keeps them (files of format 1.0 kept only the mean).
        let range = s.radius_range.map_or(String::new(), |[lo, hi]| {
            format!(
                "  (particles {}, {})",
                radius_range_text(lo, hi),
                if m.radius.is_some() {
                    "each drawn at its own"
                } else {
                    "drawn at their mean"
                }
            )
        });
        // The stored linear colour, and the sRGB `#rrggbb` that --species-colour takes.
        let [r, g, b] = s.colour.map(|c| {
            (mdlod_render::renderer::linear_to_srgb(c.clamp(0.0, 1.0)) * 255.0).round() as u8
        });
        println!(
            "  species      {:<6} radius {:<6}  colour [{:.2} {:.2} {:.2}] linear, \
             #{r:02x}{g:02x}{b:02x}{count}{range}",
            shown(&s.name),
            radius_text(s.radius),
            s.colour[0],
            s.colour[1],
            s.colour[2]
        );
    }
    if let Some(column) = &m.species_column {
        println!(
            "  (species are the values of the input's column {}, not its types)",
            shown(column)
        );
    }
    if counts.is_none() {
        println!(
            "  (species not counted above {COUNT_UP_TO} particles: --counts reads each \
             particle's species, {})",
            super::size_text(m.particles.saturating_mul(2))
        );
    }
    if let Some(r) = &m.radius {
        println!(
            "  radii        each particle's own, {} (16 bits over that range{}: each within \
             {:.1e} × its size of it)",
            radius_range_text(r.min, r.max),
            if r.log { " on a log scale" } else { "" },
            r.worst_relative_error()
        );
    }
    if let Some(a) = &m.attribute {
        println!(
            "  attribute    {} in [{}, {}]{}",
            shown(&a.name),
            super::Num(a.min),
            super::Num(a.max),
            if m.attributes.is_empty() {
                ""
            } else {
                " (the first; render --attribute NAME colours by another)"
            }
        );
    }
    for a in &m.attributes {
        println!(
            "  attribute    {} in [{}, {}]",
            shown(&a.name),
            super::Num(a.min),
            super::Num(a.max)
        );
    }
    if let Some(b) = &m.simulation_box {
        // Edges of length 0 (a two-dimensional system's c, as GSD writes Lz = 0).
        let flat: Vec<&str> = ["a", "b", "c"]
            .into_iter()
            .zip([b.a, b.b, b.c])
            .filter_map(|(n, v)| (v == [0.0; 3]).then_some(n))
            .collect();
        // Which of a, b, c wrap, where the input says (an edge of length 0 wraps nothing).
        let periodic = match b.periodic {
            Some(p) => {
                let axes: Vec<&str> = ["a", "b", "c"]
                    .into_iter()
                    .zip(p)
                    .filter_map(|(n, w)| (w && !flat.contains(&n)).then_some(n))
                    .collect();
                if axes.is_empty() {
                    ", not periodic".to_string()
                } else {
                    format!(", periodic along {}", axes.join(", "))
                }
            }
            None => String::new(),
        };
        let periodic = match flat.as_slice() {
            [] => periodic,
            [one] => format!("{periodic}; {one} has length 0 (a two-dimensional box)"),
            many => format!("{periodic}; {} have length 0", many.join(" and ")),
        };
        println!(
            "  box          origin {} a {} b {} c {}{periodic}",
            vector(b.origin),
            vector(b.a),
            vector(b.b),
            vector(b.c)
        );
    }
    if let Some((lo, hi)) = extent {
        // Six significant digits (the corners are sums in single precision: 5.7200003),
        // or more where the span along an axis is small beside its distance from the
        // origin: three of the span's, up to single precision's nine (grains of a
        // millimetre at UTM coordinates read as a box of no width, and 3 m off).
        let digits: [usize; 3] = std::array::from_fn(|k| {
            let (a, b) = (f64::from(lo[k]), f64::from(hi[k]));
            let ratio = a.abs().max(b.abs()) / (b - a);
            match (ratio.is_finite(), ratio > 0.0) {
                (true, true) => (ratio.log10().ceil() as usize + 3).clamp(6, 9),
                // No span away from 0: every digit the position has.
                (false, true) => 9,
                _ => 6,
            }
        });
        let n =
            |x: f32, d: usize| number(format!("{x:.*e}", d - 1).parse().unwrap_or(f64::from(x)));
        let v = |p: [f32; 3]| {
            format!(
                "[{}, {}, {}]",
                n(p[0], digits[0]),
                n(p[1], digits[1]),
                n(p[2], digits[2])
            )
        };
        // With radii of their own, the box also holds each particle's species' sphere
        // (what a reader of format 1.0 draws), so it may reach past the spheres drawn.
        let what = if m.radius.is_some() {
            "the particles' spheres, and their species' mean spheres"
        } else {
            "the particles' spheres"
        };
        println!("  extent       {} to {} ({what})", v(lo), v(hi));
    }
    match flat {
        Some(k) if line => println!(
            "  flat         every particle's centre on one line (one-dimensional data: the \
             default view looks across it, along {})",
            ["x", "y", "z"][k]
        ),
        Some(k) => println!(
            "  flat         every particle's centre at one {} (two-dimensional data: the \
             default view faces it square on)",
            ["x", "y", "z"][k]
        ),
        None => {}
    }
    if let Some(t) = m.timestep {
        println!("  timestep     {t}");
    }
    if let Some(t) = m.time {
        println!("  time         {}", number(t));
    }
    if let Some(u) = &m.units {
        println!("  units        {}", shown(u));
    }
    if let Some(s) = &m.source {
        println!(
            "  source       {} (frame {}, {} bytes)",
            shown(&s.path),
            s.frame,
            s.size
        );
    }
    if !m.input_options.is_empty() {
        let given: Vec<String> = m.input_options.iter().map(|o| shown(o)).collect();
        println!("  read with    {}", given.join(" "));
    }
    let chunks = m.build.chunk_points.map_or(String::new(), |c| {
        format!(", built in chunks of {c} particles")
    });
    println!(
        "  build        cluster size {}, root points {}, delta_n {}, {}-bit positions{chunks}",
        m.build.max_cluster_size, m.build.max_root_points, m.build.delta_n, m.build.position_bits
    );
    println!("  max position error {:.4e}", m.max_position_error);
    if rounded_first {
        println!(
            "  note: the error is measured from the positions in single precision, which \
             this far from the origin are {spacing:.3e} apart: an input of more digits (f64) \
             was first rounded to them, by up to {:.3e} along each axis ({:.3e} in all)",
            spacing / 2.0,
            f64::from(spacing) / 2.0 * 3f64.sqrt()
        );
    }
    Ok(())
}

/// The spacing of single-precision numbers at the largest coordinate of `lo..hi` (the
/// power of two at or below it times the machine epsilon): how far apart positions can
/// be there, whatever their quantization.
fn single_precision_spacing(lo: [f32; 3], hi: [f32; 3]) -> f32 {
    let largest = lo
        .iter()
        .chain(&hi)
        .map(|v| v.abs())
        .filter(|v| v.is_finite())
        .fold(0.0f32, f32::max);
    f32::from_bits(largest.to_bits() & 0x7f80_0000) * f32::EPSILON
}

/// A species radius: three decimals where that shows it (`1.280`), else its shortest
/// form in scientific notation (`2e-12` for atoms in metres, not `0.000`; `1e16`).
fn radius_text(r: f32) -> String {
    if (1e-2..1e5).contains(&r.abs()) {
        format!("{r:.3}")
    } else {
        format!("{r:e}")
    }
}

/// `lo to hi` as [`radius_text`] writes them, both in one notation (`1e-3 to 1e1`, not
/// `1e-3 to 10.000`).
pub(crate) fn radius_range_text(lo: f32, hi: f32) -> String {
    let plain = |r: f32| (1e-2..1e5).contains(&r.abs());
    if plain(lo) && plain(hi) {
        format!("{lo:.3} to {hi:.3}")
    } else {
        format!("{lo:.3e} to {hi:.3e}")
    }
}

/// A number as printed: an f32 widened to f64 (MMPLD and GSD boxes) as the f32's shortest
/// form, others to 15 significant digits, the most an f64 holds exactly, so that
/// rounding noise (LAMMPS writes `1.8075000000000003e+01`) does not show.
fn number(x: f64) -> String {
    // (−0, a two-dimensional cell's origin from −Lz/2 of Lz = 0, reads as 0.)
    let x = if x == 0.0 { 0.0 } else { x };
    if !x.is_finite() {
        return format!("{x}");
    }
    if f64::from(x as f32) == x {
        return format!("{:?}", x as f32);
    }
    let rounded: f64 = format!("{x:.14e}").parse().unwrap_or(x);
    format!("{rounded:?}")
}

/// Every fractional number of `v` (each an f32 widened to f64, possibly a unit of the last
/// place off it once read back from text) as the f64 nearest to the f32's shortest
/// decimal form.
fn shortest_f32(v: &mut serde_json::Value) {
    use serde_json::Value;
    match v {
        Value::Number(n) if !n.is_i64() && !n.is_u64() => {
            if let Some(m) = n
                .as_f64()
                .filter(|x| x.is_finite())
                .and_then(|x| (x as f32).to_string().parse().ok())
                .and_then(serde_json::Number::from_f64)
            {
                *n = m;
            }
        }
        Value::Array(a) => a.iter_mut().for_each(shortest_f32),
        Value::Object(o) => o.values_mut().for_each(shortest_f32),
        _ => {}
    }
}

/// A box vector as printed: `[x, y, z]`.
fn vector(v: [f64; 3]) -> String {
    format!("[{}, {}, {}]", number(v[0]), number(v[1]), number(v[2]))
}

/// A name from the file as printed: control characters (a hostile file's terminal escape
/// sequences) shown escaped, not sent to the terminal.
fn shown(s: &str) -> String {
    s.chars()
        .flat_map(|c| {
            let escaped: Vec<char> = if c.is_control() {
                c.escape_default().collect()
            } else {
                vec![c]
            };
            escaped
        })
        .collect()
}

#[cfg(test)]
mod tests {
    #[test]
    fn control_characters_of_names_are_shown_escaped() {
        assert_eq!(super::shown("Cu"), "Cu");
        assert_eq!(super::shown("a\u{1b}[2Jb\n"), "a\\u{1b}[2Jb\\n");
        assert_eq!(super::shown("Å µm"), "Å µm");
    }

    #[test]
    fn radii_of_any_scale_print_readably() {
        use super::radius_text;
        assert_eq!(radius_text(1.28), "1.280");
        assert_eq!(radius_text(2e-12), "2e-12");
        assert_eq!(radius_text(1e16), "1e16");
        assert_eq!(radius_text(0.5), "0.500");
    }

    #[test]
    fn numbers_print_without_rounding_noise() {
        use super::number;
        assert_eq!(number(18.075000000000003), "18.075");
        assert_eq!(number(f64::from(0.1f32)), "0.1");
        assert_eq!(number(0.0), "0.0");
        assert_eq!(number(-2.0), "-2.0");
        assert_eq!(number(0.1 + 0.2), "0.3");
        assert_eq!(number(1234.5678901234), "1234.5678901234");
        assert_eq!(number(1e-300), "1e-300");
    }

    #[test]
    fn f32_numbers_of_json_get_their_shortest_form() {
        let mut v = serde_json::json!({"radius": 1.28f32, "colour": [0.1f32, 1.0f32, 0], "n": 7});
        super::shortest_f32(&mut v);
        assert_eq!(
            v.to_string(),
            r#"{"colour":[0.1,1.0,0],"n":7,"radius":1.28}"#
        );
    }
}
