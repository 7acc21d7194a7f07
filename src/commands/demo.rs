//! `mdlod demo`: the main job on built-in data: generate, convert, show what was built.

use std::path::PathBuf;

use anyhow::Result;
use mdlod_datasets::{GenerateOptions, Kind};
use mdlod_format::MdlodFile;

/// Generate a crater data set, convert it to .mdlod, verify it, print what was built and
/// render a picture of it.
#[derive(clap::Args)]
#[command(
    after_help = "Example:\n  mdlod demo --particles 1000000\n  cargo run --release -- demo   (from a source checkout)"
)]
pub struct Args {
    /// Number of particles to generate.
    #[arg(long, short = 'n', default_value_t = 1_000_000,
          value_parser = |s: &str| match super::whole_number(s)? {
              0 => Err("at least 1 particle".to_string()),
              n => Ok(n),
          })]
    pub particles: u64,
    /// Where to put the generated dump and the .mdlod file.
    #[arg(long, default_value = "data/demo")]
    pub dir: PathBuf,
}

pub fn run(args: Args) -> Result<()> {
    if args.dir.exists() && !args.dir.is_dir() {
        anyhow::bail!(
            "--dir {}: exists and is not a directory (the demo writes its dump, .mdlod \
             file and picture into a directory)",
            args.dir.display()
        );
    }
    let dump = args.dir.join("crater.lammpstrj");
    let out = args.dir.join("crater.mdlod");
    let t = std::time::Instant::now();
    let opts = GenerateOptions::new(Kind::Crater, args.particles);
    super::generate::generate(&opts, &dump)?;
    println!(
        "1. generated {} ({} particles) in {:.2} s",
        dump.display(),
        args.particles,
        t.elapsed().as_secs_f64()
    );
    println!("2. converting to {}", out.display());
    super::convert::run(super::convert::Args {
        input: dump,
        output: out.clone(),
        frame: None,
        last: true,
        threads: None,
        json: false,
        memory_limit: None,
        build: super::convert::BuildArgs {
            // The generator writes copper as LAMMPS type 1.
            radii: vec![("1".into(), 1.28)],
            species_names: Vec::new(),
            attribute: vec![Kind::Crater.extra_column().to_string()],
            attribute_log10: None,
            wrap: false,
            columns: None,
            radius_column: None,
            species_column: None,
            diameter_column: None,
            no_sizes: false,
            precision: super::convert::Precision::U16,
            cluster_size: 8,
            root_points: 4096,
            delta_n: 1,
            chunk_points: mdlod_preprocess::chunked::DEFAULT_CHUNK_POINTS,
            temp_dir: None,
        },
    })?;
    let f = MdlodFile::open(&out)?;
    let r = f.verify()?;
    println!(
        "3. verified: {} points decoded, every checksum matches",
        r.points_decoded
    );
    super::info::run(super::info::Args {
        file: out.clone(),
        json: false,
        counts: false,
    })?;
    let png = args.dir.join("crater.png");
    println!("4. rendering {}", png.display());
    super::render::run(super::render::Args {
        file: out,
        output: png,
        camera: super::render::ViewArgs {
            width: 1280,
            height: 720,
            view: None,
            azimuth: Some(30.0),
            elevation: Some(25.0),
            zoom: Some(1.0),
            ortho: false,
            look_along: None,
            target: None,
        },
        spp: 4,
        screen_error: 1.0,
        budget: 4_000_000,
        no_occlusion: false,
        light: None,
        ambient: None,
        diffuse: None,
        brdf: None,
        specular: None,
        exponent: None,
        fit_all: false,
        turntable: None,
        json: false,
        gpu_memory: None,
        background: None,
        mode: super::render::Mode::Spheres,
        iso_value: 0.3,
        slices: 256,
        kernel_scale: None,
        density_max: 0.8,
        density_min: None,
        absorption: 0.5,
        opacity: 0.8,
        sort: super::render::SortArg::Clusters,
        iterations: 16,
        bins: 8,
        binning: super::render::BinningArg::Projected,
        intensity: super::render::Intensity::Species,
        exposure: None,
        light_range: None,
        style: super::render::StyleArgs {
            colour_map: None,
            attribute: None,
            radius_scale: 1.0,
            species_colour: vec![],
            palette: super::render::PaletteArg::Default,
            species_radius: vec![],
            hide_species: vec![],
            hide_attribute: vec![],
            hide_by: None,
            attribute_range: None,
            log_scale: false,
            clip: vec![],
        },
        save_view: None,
        legend: None,
        legend_in_image: None,
        legend_title: None,
        label: vec![],
        legend_category: vec![],
        label_corner: None,
        dt: None,
        scale_bar: false,
        scale_bar_length: None,
        scale_bar_corner: None,
        text_scale: None,
        dpi: None,
        scale_bar_unit: None,
        axes: false,
        axes_corner: None,
        save_map: None,
        frames: None,
        cell: None,
        cell_width: None,
    })?;
    Ok(())
}
