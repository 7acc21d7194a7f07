//! `mdlod sample`: S-NDFs of one view to a `.sndf` file, to shade later without the
//! particles.

use std::path::PathBuf;

use anyhow::Result;
use mdlod_render::{sample_to_file_at, RenderMode, RenderOptions};

use crate::progress::Bar;

use super::render::ViewArgs;

/// Sample the screen-space normal distributions of one view of a .mdlod file and store
/// them (with the camera) in a .sndf file; `mdlod shade` then lights it any number of
/// times with no particle data.
#[derive(clap::Args)]
#[command(
    allow_negative_numbers = true,
    // The style options are render's; their help speaks of what sample has.
    mut_arg("attribute_range", |a| {
        let text = "The attribute values at the ends of --colour-map, e.g. `0:2.5`, instead \
                    of the file's own range, so that views sampled apart compare";
        a.help(text).long_help(text)
    }),
    mut_arg("log_scale", |a| {
        let text = "Map the attribute's logarithm with --colour-map (densities, energies \
                    spanning decades); values from 0 start at the smallest value above 0, a \
                    range given from 0 four decades below its top";
        a.help(text).long_help(text)
    }),
    mut_arg("clip", |a| {
        let text = "Cut the data away beyond a plane, as OVITO's Slice: nx,ny,nz,d keeps the \
                    particles whose centres p have n·p ≤ d, n the unit normal and d the \
                    plane's distance from the origin along it (world units); repeatable (up \
                    to 6). Clusters across a plane are refined down to particles, so the cut \
                    face is exact; look from the cut side to see it";
        a.help(text).long_help(text)
    }),
    after_help = "Example:\n  \
    mdlod sample frame.mdlod -o view.sndf --iterations 64 --width 640 --height 360\n  \
    mdlod shade view.sndf -o lit.png --light -1,1,1 --light 1,0,0.5:#4060ff"
)]
pub struct Args {
    /// The .mdlod file to sample.
    pub file: PathBuf,
    /// The .sndf file to write.
    #[arg(short, long)]
    pub output: PathBuf,
    #[command(flatten)]
    pub camera: ViewArgs,
    /// Jittered rays per pixel.
    #[arg(long, default_value_t = 64, value_parser = super::whole_number_u32)]
    pub iterations: u32,
    /// Bins per axis of the normal parametrisation (1 to 32).
    #[arg(long, default_value_t = 8, value_parser = clap::value_parser!(u32).range(1..=32))]
    pub bins: u32,
    /// How normals are binned.
    #[arg(long, value_enum, ignore_case = true, default_value = "projected")]
    pub binning: super::render::BinningArg,
    /// Sample finer than the image (up to 16× per axis) until every particle sphere gets
    /// at least this many samples; `shade` then shows the image size by default.
    #[arg(long, default_value_t = 0)]
    pub min_samples: u32,
    /// Largest on-screen size, in pixels, of a cluster drawn as one sphere.
    #[arg(long, default_value_t = 1.0)]
    pub screen_error: f32,
    /// Most spheres to draw.
    #[arg(long, value_parser = super::render::parse_budget, default_value_t = 4_000_000)]
    pub budget: u64,
    #[command(flatten)]
    pub style: super::render::StyleArgs,
    /// Store the S-MIP tiles the view shows (orthographic views, `--ortho`), with the
    /// S-MIP's grid, instead of one image of S-NDFs; `--min-samples` then sets how fine
    /// level 0 is.
    #[arg(long)]
    pub tiles: bool,
}

/// Refuses, before sampling, an output in a directory that does not exist, and one that
/// exists and is no S-NDF file (a `.mdlod` or an image given as `-o` by mistake, which
/// the file would replace without a word).
fn check_replaces_only_sndf(output: &std::path::Path) -> Result<()> {
    if let Some(dir) = output.parent().filter(|d| !d.as_os_str().is_empty()) {
        if !dir.is_dir() {
            anyhow::bail!(
                "-o {}: the directory {} does not exist",
                output.display(),
                dir.display()
            );
        }
    }
    // (A FIFO in its place was refused by check_output; this opens regular files only.)
    let Some(head) = super::file_head(output) else {
        return Ok(());
    };
    if head[..] != mdlod_format::sndf::SNDF_MAGIC[..] {
        anyhow::bail!(
            "-o {} exists and is no .sndf file: give another name, or remove it first",
            output.display()
        );
    }
    Ok(())
}

/// The size from which `sample` says, before sampling, how large its file will be.
const LARGE_SNDF: u64 = 256 << 20;

pub fn run(args: Args) -> Result<()> {
    let inputs = args.camera.inputs(&args.file);
    super::check_output("-o", &args.output, &inputs)?;
    check_replaces_only_sndf(&args.output)?;
    if args.style.attribute_range.is_some() && args.style.colour_map.is_none() {
        anyhow::bail!("--attribute-range has no effect without --colour-map");
    }
    if args.style.log_scale && args.style.colour_map.is_none() {
        anyhow::bail!("--log-scale has no effect without --colour-map");
    }
    let mut opts = RenderOptions {
        width: args.camera.width,
        height: args.camera.height,
        view: {
            args.camera.note_unknown_fields();
            args.camera.spec()
        },
        error_px: args.screen_error,
        budget: args.budget,
        mode: RenderMode::Sndf {
            iterations: args.iterations,
            bins: args.bins,
            binning: args.binning.binning(),
        },
        style: args.style.style()?,
        ..Default::default()
    };
    mdlod_render::check_image_size(opts.width, opts.height)?;
    let mapped = opts.style.colour_map.is_some();
    let given = opts.style.attribute_range;
    let derived = super::render::derive_range(&mut opts.style, &args.file, mapped, false)?;
    // What the colours mean, as `mdlod render` says it: the attribute, its range and
    // whose it is, and the scale.
    if let Some(map) = opts.style.colour_map {
        let file = mdlod_render::open_styled(&args.file, &opts.style)?;
        if let Some(a) = &file.metadata().attribute {
            let ([lo, hi], whose) = match (opts.style.attribute_range, derived) {
                (Some(r), Some(why)) if given.is_none() => {
                    (r, format!("{why}; --attribute-range sets another"))
                }
                (Some(r), _) => (r, "--attribute-range".to_string()),
                (None, _) => ([a.min, a.max], "the file's range".to_string()),
            };
            // (As the scale colours them: no log scale where none fits the range, a
            // constant attribute's or one with no value above 0.)
            let scale = mdlod_render::style::AttributeScale::with_range(a, Some([lo, hi]))
                .with_log(opts.style.log_scale);
            let log = match (opts.style.log_scale, scale.log_range()) {
                (false, _) => "",
                (true, Some(_)) => ", on a log scale",
                (true, None) => {
                    ", linear (--log-scale left unused: no log scale fits the range, which \
                     has no value above 0 or is one value)"
                }
            };
            println!(
                "colour map {}: {} from {} to {} ({whose}){log}",
                map.name(),
                a.name,
                super::Num(lo),
                super::Num(hi)
            );
        }
    }
    if args.tiles {
        // Samples per sphere: texels times rays, as a one-image file counts them.
        let (stats, tiles, finer) = mdlod_render::sample_tiles_to_file(
            &args.file,
            &args.output,
            &opts,
            args.min_samples as f32 / args.iterations.max(1) as f32,
        )?;
        let size = std::fs::metadata(&args.output).map_or(0, |m| m.len());
        println!(
            "wrote {} ({:.1} MiB: {tiles} S-MIP tiles of 64x64 texels at level {}, {}x{} bins, {} rays each): {} rectangles, {} spheres drawn per iteration",
            args.output.display(),
            size as f64 / f64::from(1u32 << 20),
            stats.level,
            args.bins,
            args.bins,
            args.iterations,
            stats.rects,
            stats.points,
        );
        // (Levels of the tiles, 0 the finest; `shade --level` counts from the view's.)
        if finer > 0 {
            let reach = if stats.level > 0 {
                format!(
                    "the finest --min-samples takes (the smallest spheres get fewer than {})",
                    args.min_samples
                )
            } else {
                format!(
                    "so that every sphere gets at least {} samples",
                    args.min_samples
                )
            };
            println!(
                "  sampled at {}x the image size, {reach}; `shade` draws the view's size from \
                 them (level {} of the tiles, its --level 0)",
                1u32 << finer,
                stats.level + finer
            );
        }
        return Ok(());
    }
    let (scale, samples) = mdlod_render::level0_scale(
        &mdlod_render::open_styled(&args.file, &opts.style)?,
        &opts,
        args.iterations,
        args.min_samples,
    )?;
    let scaled = |side: u32| {
        side.checked_mul(scale)
            .filter(|s| *s <= mdlod_render::MAX_IMAGE_SIDE)
    };
    let (Some(width), Some(height)) = (scaled(opts.width), scaled(opts.height)) else {
        anyhow::bail!(
            "--min-samples {} asks for sampling at {scale}x the image size of {}x{}, past \
             the largest image of {} pixels per side: give a smaller --width and --height \
             or fewer --min-samples",
            args.min_samples,
            opts.width,
            opts.height,
            mdlod_render::MAX_IMAGE_SIDE
        );
    };
    let opts = RenderOptions {
        width,
        height,
        ..opts
    };
    // 16 bytes a bin (FORMAT.md, S-NDF files): said before a large file is sampled.
    let bytes = u64::from(width) * u64::from(height) * u64::from(args.bins).pow(2) * 16;
    if bytes >= LARGE_SNDF {
        println!(
            "  note: {width}x{height} texels of {b}x{b} bins make a .sndf of {:.1} GiB (16 bytes \
             a bin); a smaller image or fewer --bins{} make it smaller",
            bytes as f64 / f64::from(1u32 << 30),
            if scale > 1 { " or --min-samples" } else { "" },
            b = args.bins,
        );
    }
    let r = sample_to_file_at(
        &args.file,
        &args.output,
        &opts,
        (scale > 1).then(|| scale.trailing_zeros()),
        Bar::for_renderer(),
    )?;
    if scale > 1 && samples < args.min_samples as f32 {
        println!(
            "  sampled at {scale}x the image size, the finest --min-samples takes: the \
             smallest spheres get about {samples:.0} samples, not {}; shown at level {} (a \
             closer view, or more --iterations, gives them more)",
            args.min_samples,
            scale.trailing_zeros()
        );
    } else if scale > 1 {
        println!(
            "  sampled at {scale}x the image size so that every sphere gets at least {} samples; shown at level {}",
            args.min_samples,
            scale.trailing_zeros()
        );
    } else if args.min_samples > 0 {
        println!(
            "  --min-samples {}: every sphere gets that many samples at the image size \
             already ({} rays per texel), so it is sampled there",
            args.min_samples, args.iterations
        );
    }
    let size = std::fs::metadata(&args.output).map_or(0, |m| m.len());
    // Where the cut stopped before the screen error asked for, as `render` says.
    let coarsest = mdlod_format::MdlodFile::open(&args.file)
        .ok()
        .and_then(|f| super::render::coarsest_points(&f));
    let limits = super::render::limits_text(&r, coarsest, args.budget);
    println!(
        "wrote {} ({:.1} MiB: {}x{} texels, {}x{} bins, {} rays each) on {}: {} particles and {} cluster spheres, error {:.2} px{limits}, {:.0} ms",
        args.output.display(),
        size as f64 / f64::from(1u32 << 20),
        r.width,
        r.height,
        args.bins,
        args.bins,
        r.spp,
        r.adapter,
        r.particles_drawn,
        r.nodes_drawn,
        r.error_px,
        r.total_time.as_secs_f64() * 1e3
    );
    if args.bins == 1 {
        println!(
            "  note: one bin per texel keeps no normals: `shade` lights every texel as its \
             mean over the hemisphere, whatever the lights' directions; --bins 2 or more \
             re-light"
        );
    }
    let every_species_hidden = mdlod_format::MdlodFile::open(&args.file).is_ok_and(|f| {
        f.metadata()
            .species
            .iter()
            .all(|s| args.style.hide_species.contains(&s.name))
    });
    if every_species_hidden {
        println!("  note: every species is hidden: nothing is sampled");
    } else if !args.style.clip.is_empty() && r.particles_drawn + r.nodes_drawn == 0 {
        println!(
            "  note: nothing is sampled: {}",
            super::render::CLIP_CUTS_ALL
        );
    }
    Ok(())
}
