//! `mdlod render`: a `.mdlod` file to a PNG, headless.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use mdlod_render::{
    parse_colour, render_to_png_with, Camera, Projection, RenderMode, RenderOptions, ViewFile,
    ViewSpec,
};

use mdlod_render::label;

use super::Num;
use crate::progress::Bar;

/// Render a .mdlod file to a PNG with no window: a level-of-detail cut chosen by
/// screen-space error, drawn as ray-cast spheres, splats, S-NDFs, a density volume or its
/// iso-surface (--mode).
#[derive(clap::Args)]
#[command(
    allow_negative_numbers = true,
    after_help = "Examples:\n  mdlod render frame.mdlod -o frame.png --azimuth 30 --elevation 20 --spp 4\n  mdlod render frame.mdlod -o close.png --zoom 4 --screen-error 0.5 --save-view close.json\n  mdlod render frame.mdlod -o close-lit.png --view close.json --spp 4 --light 1,0,1\n  mdlod render frame.mdlod -o big.png --gpu-memory 512M\n  mdlod render run.d -o movie/frame-%05d.png --colour-map viridis   # a batch's frames (batch --attribute)"
)]
pub struct Args {
    /// The .mdlod file to render, or a batch directory or its dataset.json (every frame
    /// it lists, one image each: -o must number them, e.g. movie/frame-%05d.png).
    pub file: PathBuf,
    /// The PNG to write.
    #[arg(short, long)]
    pub output: PathBuf,
    #[command(flatten)]
    pub camera: ViewArgs,
    /// Samples per pixel (jittered supersampling).
    #[arg(long, default_value_t = 1, value_parser = super::whole_number_u32)]
    pub spp: u32,
    /// Largest on-screen size, in pixels, of a cluster drawn as one sphere.
    #[arg(long, default_value_t = 1.0)]
    pub screen_error: f32,
    /// Most spheres to draw (at least 1); refinement stops there, largest on screen first.
    #[arg(long, default_value_t = 4_000_000, value_parser = parse_budget)]
    pub budget: u64,
    /// Draw clusters hidden behind nearer spheres too (occlusion culling is exact, so
    /// the image is the same and this costs time, unless --budget or --gpu-memory then
    /// stops the larger cut coarser; for comparisons, or a legend key listing species
    /// wholly hidden behind others).
    #[arg(long)]
    pub no_occlusion: bool,
    /// The light of the spheres and S-NDF modes: direction towards it in view space (x
    /// right, y up, z to the viewer), optionally with a colour, e.g. `-1,1,1` or
    /// `1,0,0.5:#ffe0c0` [default: white, from the upper left]. One light here; `mdlod
    /// shade` lights sampled S-NDFs with several.
    #[arg(long, value_name = "X,Y,Z[:COLOUR]", allow_hyphen_values = true)]
    pub light: Option<String>,
    /// Ambient light, spheres and S-NDF modes [default: 0.15].
    #[arg(long)]
    pub ambient: Option<f32>,
    /// Lambert weight, spheres and S-NDF modes [default: 0.85].
    #[arg(long)]
    pub diffuse: Option<f32>,
    /// Reflectance, spheres and S-NDF modes: Lambert only, or Lambert plus a Blinn-Phong
    /// highlight [default: blinn-phong].
    #[arg(long, value_enum, ignore_case = true)]
    pub brdf: Option<super::shade::Brdf>,
    /// Blinn-Phong highlight weight (with --brdf blinn-phong) [default: 0.25].
    #[arg(long)]
    pub specular: Option<f32>,
    /// Blinn-Phong highlight exponent: larger is a smaller, sharper highlight [default:
    /// 32].
    #[arg(long)]
    pub exponent: Option<f32>,
    /// Fit the view to every particle: by default particles far from the rest (lost
    /// atoms flying off a non-periodic box, a sparse vapour) are left out of the fit
    /// when they would shrink the material to a fraction of the image (a note says how
    /// many).
    #[arg(long)]
    pub fit_all: bool,
    /// Render N views turning a full circle about the vertical axis (z) from the view's
    /// azimuth, for a talk's turntable: -o must number them (e.g. spin/view-%03d.png).
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(2..=100_000))]
    pub turntable: Option<u32>,
    /// Print what each image drew as a line of JSON on standard output (the image, its
    /// size and samples, the particles and clusters drawn and hidden, the error reached,
    /// the camera, the times, the adapter, and the notes since the last), the text lines
    /// going to standard error: for scripts and regression pictures. A movie or turntable
    /// prints one line per image
    #[arg(long)]
    pub json: bool,
    /// Of a batch directory, draw only frames START to END (0-based positions in its
    /// dataset.json, END not included; either may be left out), every STEP-th: `::10`
    /// previews every tenth, `0:250` and `250:500` split a movie between two jobs. The
    /// camera, colour range and image numbers are those of the whole movie, so pieces
    /// rendered apart join up
    #[arg(long, value_name = "START:END[:STEP]", value_parser = parse_frames,
          allow_hyphen_values = true)]
    pub frames: Option<FrameSelection>,
    /// Stream node data through a GPU memory pool of this size (e.g. 512M, 2G).
    #[arg(long, value_parser = parse_bytes)]
    pub gpu_memory: Option<u64>,
    /// How to draw the points: opaque ray-cast spheres; additive flux-preserving splats
    /// (SPH, astrophysics), tone mapped; translucent splats sorted back to front and
    /// over-blended, for data that needs depth order; spheres sampled into S-NDFs and
    /// shaded from them; the image-space density volume (density) or its iso-surface
    /// (iso).
    #[arg(long, value_enum, ignore_case = true, default_value = "spheres")]
    pub mode: Mode,
    /// iso mode: the surface's volume fraction (φ: 0.74 in a close packing of the
    /// largest species' spheres).
    #[arg(long, default_value_t = 0.3)]
    pub iso_value: f32,
    /// density and iso modes: slices from the data's nearest to its farthest point.
    #[arg(long, default_value_t = 256, value_parser = super::whole_number_u32)]
    pub slices: u32,
    /// How far a point's kernel reaches, in its radii [density and iso modes: 2.5;
    /// splat modes: 1.75, a Gaussian of sigma r/2 cut at 3.5 sigma]. For an SPH run
    /// converted with --radius-column h, the code's kernel convention: 1 where h is the
    /// kernel's full support (Gadget), 2 where the support is 2h (Phantom); a splat's
    /// light stays its disk's area. Above 0, at most 100
    #[arg(long, value_parser = parse_kernel_scale)]
    pub kernel_scale: Option<f32>,
    /// density mode: the volume fraction at the top of the transfer function.
    #[arg(long, default_value_t = 0.8)]
    pub density_max: f32,
    /// density mode: the volume fraction at the bottom of the transfer function, clear
    /// at and below it [default: 0; with --log-scale four decades below --density-max]
    #[arg(long)]
    pub density_min: Option<f32>,
    /// density mode: absorption, the optical depth per reference radius of path at the top
    /// density (an opacity of 1 − e^−A over one radius: 0.39 at 0.5).
    #[arg(long, default_value_t = 0.5)]
    pub absorption: f32,
    /// sndf mode: jittered rays per pixel accumulated into the S-NDFs.
    #[arg(long, default_value_t = 16, value_parser = super::whole_number_u32)]
    pub iterations: u32,
    /// sndf mode: bins per axis of the normal parametrisation.
    #[arg(long, default_value_t = 8, value_parser = super::whole_number_u32)]
    pub bins: u32,
    /// sndf mode: how normals are binned.
    #[arg(long, value_enum, ignore_case = true, default_value = "projected")]
    pub binning: BinningArg,
    /// splat-over mode: the splats' peak opacity, in (0, 1].
    #[arg(long, default_value_t = 0.8)]
    pub opacity: f32,
    /// splat-over mode: the back-to-front order: the hierarchy's clusters bucket-sorted
    /// by depth with each cluster's points sorted (fast), or every point sorted (exact).
    #[arg(long, value_enum, ignore_case = true, default_value = "clusters")]
    pub sort: SortArg,
    /// Splat mode: each point's light is its species colour, or its scalar attribute
    /// (the file's per-particle column: from 0, so that light is proportional to the
    /// value, where no value is below 0, else over the file's range; --attribute-range
    /// sets another; a constant column, equal-mass SPH particles say, gives every point
    /// its value).
    #[arg(long, value_enum, ignore_case = true, default_value = "species")]
    pub intensity: Intensity,
    /// Splat mode: light added per unit of flux (default: chosen from the image's light,
    /// the attribute's with --intensity attribute).
    #[arg(long)]
    pub exposure: Option<f32>,
    /// Splat mode with --colour-map (a projection): the image's light at the map's two
    /// ends, e.g. 0:250 (on a log scale, above 0), instead of the image's own range, so
    /// that projections made apart (a zoom and its overview, two runs) share one scale.
    #[arg(long, value_name = "MIN:MAX", allow_hyphen_values = true, value_parser = parse_range)]
    pub light_range: Option<[f32; 2]>,
    /// Background colour: #rrggbb, r,g,b in [0, 1], or a name such as white or grey
    /// (default black for splats and the density volume, white otherwise); `none` for a
    /// transparent one (a PNG with alpha: spheres, with edges partly transparent at
    /// --spp above 1, splat-over, density and iso; not additive splats nor S-NDFs).
    #[arg(long)]
    pub background: Option<String>,
    #[command(flatten)]
    pub style: StyleArgs,
    /// Draw the simulation cell's edges (triclinic too), hidden behind the spheres in
    /// front of them (splats and the volume: over them); optionally in a colour given
    /// with `=` (`--cell=#1f77b4`; default: dark grey on light backgrounds, light grey on
    /// dark ones), so that `--cell frame.mdlod` reads the file.
    #[arg(
        long,
        value_name = "COLOUR",
        num_args = 0..=1,
        require_equals = true,
        default_missing_value = "auto"
    )]
    pub cell: Option<String>,
    /// The cell's lines' width in pixels [default: the image's shorter side / 360, at
    /// least 1.5].
    #[arg(long, value_name = "PX")]
    pub cell_width: Option<f32>,
    /// Write the camera used as a view file.
    #[arg(long)]
    pub save_view: Option<PathBuf>,
    /// --mode splat: write each pixel's light as 32-bit floats, a NumPy array of shape
    /// (height, width), row 0 at the image's top: the projected flux, or with
    /// --intensity attribute the projected attribute in its units (with m/(pi r^2) as
    /// the attribute, the column density). Stills only
    #[arg(long, value_name = "FILE.npy")]
    pub save_map: Option<PathBuf>,
    /// Write what the image's colours mean as an SVG, for a figure: the colour map's bar
    /// (its range, round ticks, log scale), the density volume's transfer function, or a
    /// key of the species shown in their colours. A movie or turntable writes one.
    #[arg(long, value_name = "FILE.svg")]
    pub legend: Option<PathBuf>,
    /// Draw the legend (what --legend writes) into the image itself, on a light panel in
    /// a corner: --legend-in-image=top-left, top-right, bottom-left or bottom-right (the
    /// default), enlarged in whole steps per 1280x720 of the image. Every image of a movie
    /// or turntable gets it.
    #[arg(
        long,
        value_name = "CORNER",
        num_args = 0..=1,
        require_equals = true,
        default_missing_value = "bottom-right",
        ignore_case = true
    )]
    pub legend_in_image: Option<LegendCorner>,
    /// The colour bar's title instead of the attribute's name, e.g. "E_kin (eV)".
    #[arg(long, value_name = "TEXT")]
    pub legend_title: Option<String>,
    /// A line of text drawn into the image on a light panel (OVITO's text label), with
    /// each frame's values put in for {timestep}, {time}, {frame} (the image's number),
    /// {particles}, {file} (the .mdlod) and {source} (the dump it was converted from):
    /// `--label "t = {time} ps"` on a movie; `{time:.2}` gives
    /// the time two decimals (a movie's times otherwise all take as many as the most
    /// precise needs, so the text keeps its width); `{{` and `}}` are braces themselves
    /// (`--label "{{111}} planes"`); repeatable, a line each
    #[arg(long, value_name = "TEXT")]
    pub label: Vec<String>,
    /// The simulation's timestep size in its time unit (LAMMPS `timestep`): `{time}` in
    /// --label is then each frame's timestep times DT, for dumps that record no time
    /// (LAMMPS records it with `dump_modify time yes`); it replaces a recorded time
    #[arg(long, value_name = "DT")]
    pub dt: Option<f64>,
    /// A key of named values instead of the colour bar, for an attribute of categories
    /// (a CNA column's structure types): `--legend-category 1=FCC --legend-category
    /// 2=HCP ...`, each name beside a disc of the colour --colour-map gives its value;
    /// repeatable. Values --hide-attribute hides are left out of the key
    #[arg(long, value_name = "VALUE=NAME", allow_hyphen_values = true)]
    pub legend_category: Vec<String>,
    /// Where --label draws its panel [default: top-left]
    #[arg(long, value_name = "CORNER", ignore_case = true)]
    pub label_corner: Option<LegendCorner>,
    /// Draw a scale bar into the image: a round length of the world (about a fifth of
    /// the image's width, or --scale-bar-length) under its size in the file's units
    /// (`metal`, `real`: Å). Orthographic views only (in perspective, sizes depend on
    /// depth); stills, movies and turntables
    #[arg(long)]
    pub scale_bar: bool,
    /// The scale bar's length, in the data's units [default: a round length, about a
    /// fifth of the image's width]
    #[arg(long, value_name = "LENGTH")]
    pub scale_bar_length: Option<f32>,
    /// Where --scale-bar draws its panel [default: bottom-left]
    #[arg(long, value_name = "CORNER", ignore_case = true)]
    pub scale_bar_corner: Option<LegendCorner>,
    /// The scale bar's unit, where the file records none or another name is wanted
    /// (`nm`, `Å`, `σ`; a LAMMPS unit style such as `real` gives its length unit)
    /// [default: the file's unit style's length unit]
    #[arg(long, value_name = "UNIT")]
    pub scale_bar_unit: Option<String>,
    /// Draw the directions of the data's x, y and z axes into the image, as the view
    /// sees them (red, green and blue, as OVITO and VMD draw them): which way y points in
    /// a slab or a view along an axis; stills, movies and turntables (turning with the
    /// data)
    #[arg(long)]
    pub axes: bool,
    /// Where --axes draws its panel [default: bottom-right, or the first corner of
    /// bottom-left, top-right and top-left that no other panel takes]
    #[arg(long, value_name = "CORNER", ignore_case = true)]
    pub axes_corner: Option<LegendCorner>,
    /// Draw the in-image legend, the label, the scale bar and the axes N times their size (their
    /// text is a 7×13-pixel font), 1 to 8: for print, where a figure's panels read small
    /// [default: by the image's size, one step per 1280×720 rounded: 1 below 1920×1080,
    /// 2 from it, 3 from 3200×1800]
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..=8))]
    pub text_scale: Option<u32>,
    /// Record this resolution in the PNGs (dots per inch, a `pHYs` chunk), so that a
    /// journal's figure check and page layout read their printed size: 3000 pixels at
    /// 600 dpi print 5 inches wide. The pixels are the same with or without it
    #[arg(long, value_name = "DPI", value_parser = parse_dpi)]
    pub dpi: Option<f32>,
}

impl Args {
    /// Where --label draws.
    fn label_corner(&self) -> LegendCorner {
        self.label_corner.unwrap_or(LegendCorner::TopLeft)
    }

    /// Where --scale-bar draws.
    fn scale_bar_corner(&self) -> LegendCorner {
        self.scale_bar_corner.unwrap_or(LegendCorner::BottomLeft)
    }

    /// Where --axes draws: its corner, else the first of bottom-right, bottom-left,
    /// top-right and top-left no other panel takes (a label, often wide, lies along the
    /// top).
    fn axes_corner(&self) -> LegendCorner {
        let taken = [
            (!self.label.is_empty()).then(|| self.label_corner()),
            self.legend_in_image,
            self.scale_bar.then(|| self.scale_bar_corner()),
        ];
        self.axes_corner.unwrap_or_else(|| {
            [
                LegendCorner::BottomRight,
                LegendCorner::BottomLeft,
                LegendCorner::TopRight,
                LegendCorner::TopLeft,
            ]
            .into_iter()
            .find(|c| !taken.contains(&Some(*c)))
            .unwrap_or(LegendCorner::BottomRight)
        })
    }
}

/// The length unit of a unit style (LAMMPS `units`), as a scale bar names it, in the
/// image font's glyphs (`A` where it has no `Å`); any other name (a raw sidecar's
/// `Mpc/h`) as it is where short and drawable; empty for none.
fn length_unit(units: Option<&str>) -> String {
    let has = |c: char| mdlod_render::font::has_glyph(c);
    let Some(units) = units else {
        return String::new();
    };
    // (The converter's table, which its notes say the units by.)
    match mdlod_preprocess::convert::length_unit_of(units) {
        Some("Å") if !has('Å') => "A".to_string(),
        Some("σ") if !has('σ') => "sigma".to_string(),
        Some("µm") if !has('µ') => "um".to_string(),
        Some(unit) => unit.to_string(),
        // Not a unit the table knows: a length unit of its own (a raw sidecar's
        // `Mpc/h`), as written where it is short and drawable.
        None => {
            let own = units.trim();
            match own.chars().count() <= 12 && own.chars().all(|c| c == ' ' || has(c)) {
                true => own.to_string(),
                false => String::new(),
            }
        }
    }
}

/// A length below 1 of a metric `unit` (m, cm, mm) said with the prefix that makes it a
/// number from 1 on: a DEM run's `units si` bar of 0.02 m reads 20 mm, 5e-6 m 5 µm (down
/// to nm). Other lengths and units as they are.
fn metric_length(length: f64, unit: &str) -> (f64, String) {
    let metres = match unit {
        "m" => 1.0,
        "cm" => 1e-2,
        "mm" => 1e-3,
        _ => return (length, unit.to_string()),
    };
    if !(length > 0.0 && length < 1.0) {
        return (length, unit.to_string());
    }
    let micro = match mdlod_render::font::has_glyph('µ') {
        true => "µm",
        false => "um",
    };
    let si = length * metres;
    let prefixed = [(1e-3, "mm"), (1e-6, micro), (1e-9, "nm")]
        .into_iter()
        .find(|(m, _)| si >= m * (1.0 - 1e-9));
    match prefixed {
        // (Rounded: 0.02 m is 20.000000000000004 mm.)
        Some((m, u)) => (((si / m) * 1e9).round() / 1e9, u.to_string()),
        None => (length, unit.to_string()),
    }
}

/// The scale bar of an orthographic `camera` in an image `width` × `height`: a length of
/// `length` world units, else the largest of 1, 2 and 5 times a power of 10 within a
/// fifth of the width, drawn at the legend scale the image takes. An error for a
/// perspective camera, a length that does not fit, or one below a pixel.
fn scale_bar(
    camera: &mdlod_render::Camera,
    width: u32,
    height: u32,
    length: Option<f32>,
    units: Option<&str>,
    text_scale: Option<u32>,
) -> Result<mdlod_render::legend::Legend> {
    if camera.projection != mdlod_render::Projection::Orthographic {
        anyhow::bail!(
            "--scale-bar needs an orthographic view (--ortho, or a view file's \
             \"projection\": \"orthographic\"): in perspective, sizes depend on depth"
        );
    }
    let per_px = f64::from(camera.view_height_at_target()) / f64::from(height.max(1));
    let world = match length {
        Some(l) if l.is_finite() && l > 0.0 => f64::from(l),
        Some(l) => {
            anyhow::bail!("--scale-bar-length {l}: a length must be a finite number above 0")
        }
        None => {
            let most = per_px * f64::from(width) / 5.0;
            let decade = 10f64.powf(most.log10().floor());
            [5.0, 2.0, 1.0]
                .into_iter()
                .map(|m| m * decade)
                .find(|&l| l <= most)
                .unwrap_or(decade)
        }
    };
    let unit = length_unit(units);
    if unit.is_empty() {
        // A dump without `units` (LAMMPS writes them with `dump_modify ... units yes`).
        println!(
            "  note: the scale bar's length has no unit: the file records none; \
             --scale-bar-unit names it (Å for LAMMPS metal or real units, σ for lj)"
        );
    }
    let (shown, shown_unit) = metric_length(world, &unit);
    let label = format!(
        "{}{}{shown_unit}",
        super::Num(shown as f32),
        if shown_unit.is_empty() { "" } else { " " }
    );
    // The legend's scale for this image, then the bar's length in legend pixels.
    let probe = mdlod_render::legend::Legend::Scale {
        length: 1.0,
        label: label.clone(),
    };
    let s = f64::from(probe.scale_in(width, height, text_scale).unwrap_or(1));
    let pixels = world / per_px;
    let widest = f64::from(width) - 16.0 * s - 14.0 * s;
    // Four significant digits.
    let short = |v: f64| match v.abs() {
        a if (1e-3..1e5).contains(&a) => {
            let digits = (3 - a.log10().floor() as i32).max(0) as usize;
            format!("{v:.digits$}")
        }
        _ => format!("{v:.3e}"),
    };
    let unit_words = match unit.as_str() {
        "" => String::new(),
        u => format!("{u} "),
    };
    if pixels < 1.0 || pixels > widest {
        anyhow::bail!(
            "--scale-bar-length {}: too {} for a {width}-pixel image: {pixels:.1} pixels at \
             {} {unit_words}per pixel; from {} to {} fit{}",
            super::Num(world as f32),
            if pixels < 1.0 { "short" } else { "long" },
            short(per_px),
            short(per_px),
            short(widest.max(1.0) * per_px),
            " (leave the length out for a round one)"
        );
    }
    let bar = mdlod_render::legend::Legend::Scale {
        length: (pixels / s) as f32,
        label,
    };
    if bar.scale_in(width, height, text_scale).is_none() {
        let (w, h) = bar.room_needed(text_scale.unwrap_or(1));
        anyhow::bail!(
            "--scale-bar: a {width}×{height} image cannot hold the scale bar (at least {w}×{h} \
             pixels with its margin); draw a larger image"
        );
    }
    Ok(bar)
}

/// The `--axes` panel of a view from `camera`.
fn axes_panel(camera: &mdlod_render::Camera) -> mdlod_render::legend::Legend {
    mdlod_render::legend::axes_tripod(
        camera.right().to_array(),
        camera.up().to_array(),
        camera.back().to_array(),
    )
}

/// The library's corner of a command-line corner.
fn legend_corner(corner: LegendCorner) -> mdlod_render::legend::Corner {
    use mdlod_render::legend::Corner;
    match corner {
        LegendCorner::TopLeft => Corner::TopLeft,
        LegendCorner::TopRight => Corner::TopRight,
        LegendCorner::BottomLeft => Corner::BottomLeft,
        LegendCorner::BottomRight => Corner::BottomRight,
    }
}

/// The name a corner is given on the command line.
fn corner_name(corner: LegendCorner) -> String {
    clap::ValueEnum::to_possible_value(&corner).map_or_else(String::new, |v| v.get_name().into())
}

/// Refuses, before anything is drawn, panels drawn into the image (the in-image legend
/// of `legend` pixels, the label of `label`, the scale bar) that would cover one
/// another: each lies in its corner, over the room it needs with its margin. (Two in
/// one corner are refused where they are named.)
fn check_panels_apart(
    args: &Args,
    legend: Option<[u32; 2]>,
    label: Option<[u32; 2]>,
    bar: Option<&mdlod_render::legend::Legend>,
    axes: Option<&mdlod_render::legend::Legend>,
) -> Result<()> {
    let (w, h) = (args.camera.width, args.camera.height);
    // The axes refused before anything is drawn where the image cannot hold them (at
    // the --text-scale given, which is never dropped for a smaller one).
    if let Some(a) = axes.filter(|a| a.scale_in(w, h, args.text_scale).is_none()) {
        let scale = args.text_scale.unwrap_or(1);
        let (nw, nh) = a.room_needed(scale);
        anyhow::bail!(
            "--axes: a {w}×{h} image cannot hold the axes (at least {nw}×{nh} pixels with \
             their margin{}): draw a larger image{}",
            match args.text_scale {
                Some(s) => format!(", at --text-scale {s}"),
                None => String::new(),
            },
            match args.text_scale {
                Some(s) if s > 1 => ", or a smaller --text-scale",
                _ => "",
            }
        );
    }
    let mut panels: Vec<(&str, LegendCorner, [u32; 2])> = Vec::new();
    if let (Some(corner), Some(size)) = (args.legend_in_image, legend) {
        panels.push(("--legend-in-image", corner, size));
    }
    if let Some(size) = label {
        panels.push(("--label", args.label_corner(), size));
    }
    if let Some((bar, scale)) = bar.and_then(|b| Some((b, b.scale_in(w, h, args.text_scale)?))) {
        let (bw, bh) = bar.room_needed(scale);
        panels.push(("--scale-bar", args.scale_bar_corner(), [bw, bh]));
    }
    if let Some((a, scale)) = axes.and_then(|a| Some((a, a.scale_in(w, h, args.text_scale)?))) {
        let (aw, ah) = a.room_needed(scale);
        panels.push(("--axes", args.axes_corner(), [aw, ah]));
    }
    let corners: Vec<_> = panels.iter().map(|p| (legend_corner(p.1), p.2)).collect();
    if let Some((i, j)) = mdlod_render::legend::overlapping(&corners, w, h) {
        let (a, b) = (&panels[i], &panels[j]);
        let shorter = match (a.0, b.0) {
            ("--scale-bar", _) | (_, "--scale-bar") => ", or a shorter bar (--scale-bar-length)",
            _ => "",
        };
        anyhow::bail!(
            "{} and {} would cover one another in a {w}×{h} image: {}×{} pixels at \
             the {} corner and {}×{} at the {} (each with its margin); draw a larger \
             image, put one in another corner{shorter}",
            a.0,
            b.0,
            a.2[0],
            a.2[1],
            corner_name(a.1),
            b.2[0],
            b.2[1],
            corner_name(b.1),
        );
    }
    Ok(())
}

/// `--legend-category VALUE=NAME` entries, in the order given.
fn legend_categories(args: &Args) -> Result<Vec<(f32, String)>> {
    args.legend_category
        .iter()
        .map(|entry| {
            let (value, name) = entry
                .split_once('=')
                .filter(|(_, n)| !n.trim().is_empty())
                .ok_or_else(|| {
                    anyhow::anyhow!("--legend-category {entry:?}: expected VALUE=NAME, e.g. 1=FCC")
                })?;
            let value: f32 = value
                .trim()
                .parse()
                .ok()
                .filter(|v: &f32| v.is_finite())
                .ok_or_else(|| {
                    anyhow::anyhow!("--legend-category {entry:?}: {value:?} is not a finite number")
                })?;
            Ok((value, name.trim().to_string()))
        })
        .collect::<Result<Vec<_>>>()
        .and_then(|entries| {
            for (k, (v, _)) in entries.iter().enumerate() {
                if let Some((_, first)) = entries[..k].iter().find(|(w, _)| w == v) {
                    anyhow::bail!(
                        "--legend-category: the value {v} is named twice (first {first:?})"
                    );
                }
            }
            Ok(entries)
        })
}

/// Refuses a `--label` naming a placeholder it does not fill, or drawn where the legend
/// is, before anything is drawn.
fn check_label(args: &Args) -> Result<()> {
    if let Some(dt) = args.dt {
        if !(dt.is_finite() && dt > 0.0) {
            anyhow::bail!("--dt {dt}: the timestep size must be a finite number above 0");
        }
        if args.label.is_empty() {
            anyhow::bail!(
                "--dt has no effect without --label: it gives the time {{time}} shows \
                 (--label \"t = {{time}} ps\")"
            );
        }
    }
    for text in &args.label {
        if let Err(why) = label::parts(text) {
            anyhow::bail!("--label {text:?}: {why}");
        }
    }
    if !args.label.is_empty() {
        // The narrowest the panel can be: each line without its placeholders (the
        // values filled in only widen it; a panel they make too wide is refused where
        // it is drawn).
        let panel = mdlod_render::legend::Legend::Text {
            lines: args.label.iter().map(|t| label::fixed_text(t)).collect(),
        };
        if panel
            .scale_in(args.camera.width, args.camera.height, args.text_scale)
            .is_none()
        {
            let (w, h) = panel.room_needed(args.text_scale.unwrap_or(1));
            anyhow::bail!(
                "--label: a {}×{} image cannot hold the label (at least {w}×{h} pixels with \
                 its margin); draw a larger image, or a shorter label",
                args.camera.width,
                args.camera.height
            );
        }
    }
    if !args.label.is_empty() && args.legend_in_image == Some(args.label_corner()) {
        anyhow::bail!(
            "--label and --legend-in-image both draw at the {} corner: give --label-corner \
             another",
            clap::ValueEnum::to_possible_value(&args.label_corner())
                .map_or_else(String::new, |v| v.get_name().to_string())
        );
    }
    Ok(())
}

/// Says, for splats lit by an attribute spanning more than four decades in the file's
/// 16-bit linear steps, that its small values' light is off (an SPH column of m/(π h²)
/// over a halo: most particles of the background at one step), which the conversion
/// noted only.
fn decades_light_note(a: &mdlod_format::meta::AttributeInfo) -> Option<String> {
    let decades = (f64::from(a.max) / f64::from(a.min)).log10();
    (a.min > 0.0 && decades > 4.0).then(|| {
        let step = (f64::from(a.max) - f64::from(a.min)) / 65535.0;
        format!(
            "  note: {} spans {decades:.1} decades, kept in 16-bit steps of {step:.2e}: \
             particles of values below about {:.0e} are lit by the nearest step, so the \
             light where they dominate is off (by up to half a step each); a column of \
             fewer decades (the mass alone, with equal radii) keeps it",
            a.name,
            100.0 * step
        )
    })
}

/// Says, for the modes that spread each particle over a kernel (splats, the density
/// volume and its iso-surface), that a periodic cell's faces do not wrap the kernels: a
/// cosmological box's projection reads low within a kernel's reach of its faces, and a
/// halo across a face shows in two pieces, where a projection that wraps (yt's) does not.
/// Axes the cell says are periodic count, less an edge of no length (a two-dimensional
/// run's), and only where `drawn` (the box the kernels reach,
/// [`mdlod_render::drawn_bounds`]) crosses the cell's faces across that axis (of its
/// axis-aligned box, for a triclinic cell).
fn periodic_kernels_note(
    mode: Mode,
    cell: Option<&mdlod_format::meta::SimulationBox>,
    drawn: Option<mdlod_render::Bounds>,
) -> Option<String> {
    if !matches!(
        mode,
        Mode::Splat | Mode::SplatOver | Mode::Density | Mode::Iso
    ) {
        return None;
    }
    let (cell, drawn) = (cell?, drawn?);
    let periodic = cell.periodic?;
    // The cell's corners, in f32 as the particles are.
    let corner = |i: usize| {
        [0, 1, 2].map(|k| {
            let pick = |bit: usize, e: [f64; 3]| if i >> bit & 1 == 1 { e[k] } else { 0.0 };
            (cell.origin[k] + pick(0, cell.a) + pick(1, cell.b) + pick(2, cell.c)) as f32
        })
    };
    let crosses = |k: usize| {
        let (lo, hi) = (0..8)
            .map(corner)
            .fold((f32::MAX, f32::MIN), |(lo, hi), c| {
                (lo.min(c[k]), hi.max(c[k]))
            });
        drawn.min[k] < lo || drawn.max[k] > hi
    };
    let axes: Vec<&str> = ["x", "y", "z"]
        .into_iter()
        .zip(periodic)
        .zip([cell.a, cell.b, cell.c])
        .enumerate()
        .filter_map(|(k, ((name, p), edge))| (p && edge != [0.0; 3] && crosses(k)).then_some(name))
        .collect();
    let axes = match axes[..] {
        [] => return None,
        [one] => one.to_string(),
        [ref first @ .., last] => format!("{} and {last}", first.join(", ")),
    };
    let what = match mode {
        Mode::Density | Mode::Iso => "the density",
        _ => "the splats' light",
    };
    Some(format!(
        "  note: the cell is periodic along {axes}, but kernels are not wrapped across its \
         faces: within a kernel's reach of a face {what} reads low (only the particles on \
         this side add to it), and a structure across a face shows in pieces"
    ))
}

/// `v` to three significant digits, in plain decimals (0.0200, 2.95, 450).
fn three_digits(v: f32) -> String {
    // (Nudged up, so that 0.01 stored as 0.0099999998 counts as 0.01.)
    let magnitude = (f64::from(v.abs()) * (1.0 + 1e-6)).log10().floor();
    let decimals = (2 - magnitude as i32).clamp(0, 12) as usize;
    format!("{:.*}", decimals, v)
}

/// `--hide-attribute`'s ranges with the attribute each reads in `file` (opened with the
/// style, [`mdlod_render::open_styled`]), as the style's hidden set gives their slots: a
/// plain range the hiding attribute, a named one its own; ranges of an attribute the
/// file lacks are left out.
fn hidden_ranges<'f>(
    style: &mdlod_render::PointStyle,
    file: &'f mdlod_format::reader::MdlodFile,
) -> Vec<(&'f mdlod_format::meta::AttributeInfo, [f32; 2], u8)> {
    let set = style.hidden_set(file.metadata());
    set.ranges()
        .iter()
        .zip(set.slots())
        .filter_map(|(&r, &slot)| Some((file.hidden_slot_attribute(slot)?, r, slot)))
        .collect()
}

/// Says of each attribute `--hide-attribute` reads when its ranges all miss its values,
/// and of ranges given by a column's own name where the file keeps its logarithm.
fn hides_nothing_notes(
    style: &mdlod_render::PointStyle,
    file: &mdlod_format::reader::MdlodFile,
) -> Vec<String> {
    let mut notes = logarithm_end_notes(style, file);
    notes.extend(hides_nothing_text(&hidden_range_hits(style, file), "here"));
    notes
}

/// Notes for ranges of an attribute named by its column (`sigma`) that the file keeps as
/// `log10(sigma)`: their ends are logarithms, which a range of values typed as values
/// (`--hide-attribute sigma=0.01:`) misreads silently.
fn logarithm_end_notes(
    style: &mdlod_render::PointStyle,
    file: &mdlod_format::reader::MdlodFile,
) -> Vec<String> {
    let names = file.attribute_names();
    let logged = |given: &str| {
        let stored = mdlod_format::reader::attribute_named(&names, given)?;
        (stored != given && stored == format!("log10({given})")).then_some(stored)
    };
    let mut ranges: Vec<(String, &str, [f32; 2])> = Vec::new();
    for (given, range) in &style.hidden_named {
        ranges.push((format!("--hide-attribute {given}="), given, *range));
    }
    // Unnamed ranges read `--hide-by`, else the attribute coloured by.
    if let Some(given) = style.hide_by.as_ref().or(style.attribute.as_ref()) {
        for range in &style.hidden_values {
            ranges.push(("--hide-attribute ".to_string(), given, *range));
        }
    }
    if let (Some(given), Some(range), false) =
        (&style.attribute, style.attribute_range, style.range_derived)
    {
        ranges.push(("--attribute-range ".to_string(), given, range));
    }
    let mut notes = Vec::new();
    for (flag, given, range) in ranges {
        let Some(stored) = logged(given) else {
            continue;
        };
        let Some(end) = range.into_iter().find(|v| v.is_finite()) else {
            continue;
        };
        let note = format!(
            "  note: {flag}{}: {given} is kept as {stored}, so the range's ends are logarithms \
             ({} stands for {given} = {})",
            range_text(range),
            super::Num(end),
            super::Num(10f64.powf(f64::from(end)) as f32)
        );
        if !notes.contains(&note) {
            notes.push(note);
        }
    }
    notes
}

/// Each attribute `--hide-attribute` reads in `file`, whether some range of it meets its
/// values, and its range.
fn hidden_range_hits(
    style: &mdlod_render::PointStyle,
    file: &mdlod_format::reader::MdlodFile,
) -> Vec<RangeHits> {
    let mut hits: Vec<RangeHits> = Vec::new();
    for (a, r, slot) in hidden_ranges(style, file) {
        // Within the attribute's range a range may still fall between its values (2:4
        // of a structure type holding only 1 and 5): the values are looked at.
        let codes = a.codes(r);
        let within = codes.is_some();
        let hit = codes.is_some_and(|codes| file.slot_values_meet(slot, codes));
        let missed: Vec<String> = (!hit).then(|| range_text(r)).into_iter().collect();
        match hits.iter_mut().find(|h| h.name == a.name) {
            Some(h) => {
                h.hit |= hit;
                h.within |= within;
                h.missed.extend(missed);
            }
            None => hits.push(RangeHits {
                name: a.name.clone(),
                hit,
                within,
                missed,
                min: a.min,
                max: a.max,
            }),
        }
    }
    hits
}

/// A hidden range as `--hide-attribute` takes it (`2:4`, `:0.2`, `2.5:`).
fn range_text([lo, hi]: [f32; 2]) -> String {
    let end = |v: f32| {
        if v.is_finite() {
            super::Num(v).to_string()
        } else {
            String::new()
        }
    };
    format!("{}:{}", end(lo), end(hi))
}

/// Whether an attribute's hidden ranges meet its values, over one file or several.
struct RangeHits {
    name: String,
    hit: bool,
    /// Some range lies within the attribute's range (its values may still all miss it).
    within: bool,
    /// The ranges that meet none of its values, as given.
    missed: Vec<String>,
    min: f32,
    max: f32,
}

/// `more`'s attributes joined into `all` (a movie's frames): met where met in any frame,
/// over the frames' joint range.
fn join_range_hits(all: &mut Vec<RangeHits>, more: Vec<RangeHits>) {
    for m in more {
        match all.iter_mut().find(|h| h.name == m.name) {
            Some(h) => {
                h.hit |= m.hit;
                h.within |= m.within;
                // Missed in every frame.
                h.missed.retain(|r| m.missed.contains(r));
                h.min = h.min.min(m.min);
                h.max = h.max.max(m.max);
            }
            None => all.push(m),
        }
    }
}

/// The notes on attributes whose hidden ranges meet none of their values (`where`: "here",
/// "in any frame").
fn hides_nothing_text(hits: &[RangeHits], place: &str) -> Vec<String> {
    // Ranges that miss beside others of their attribute that hide some.
    let some_missed = hits
        .iter()
        .filter(|h| h.hit && !h.missed.is_empty())
        .map(|h| {
            let (s, lies) = match h.missed.len() {
                1 => ("", "it"),
                _ => ("s", "any of them"),
            };
            format!(
                "  note: --hide-attribute range{s} {} hide{} no particle: no value of {} lies in \
             {lies} {place}",
                h.missed.join(", "),
                if h.missed.len() == 1 { "s" } else { "" },
                h.name
            )
        });
    let all_missed = hits.iter().filter(|h| !h.hit).map(|h| {
        let which = match hits.len() {
            1 => String::new(),
            _ => format!(" (of {})", h.name),
        };
        let between = if h.within {
            ", and none of its values lies in the range"
        } else {
            ""
        };
        format!(
            "  note: --hide-attribute{which} hides no particle: {} lies from {} to {} \
                 {place}{between}",
            h.name,
            super::Num(h.min),
            super::Num(h.max)
        )
    });
    all_missed.chain(some_missed).collect()
}

/// The background's colour as `--background` gives it, or the mode's default.
fn background_text(args: &Args) -> &str {
    args.background
        .as_deref()
        .filter(|b| !transparent(Some(b)))
        .unwrap_or(match args.mode {
            Mode::Spheres | Mode::Sndf | Mode::Iso => "#ffffff",
            Mode::Splat | Mode::SplatOver | Mode::Density => "#000000",
        })
}

/// The background as the images hold it (sRGB, 8 bits), or `None` for a transparent
/// one: what [`draw_panel`] tells data from.
fn backdrop(args: &Args) -> Option<[u8; 3]> {
    if transparent(args.background.as_deref()) {
        return None;
    }
    let c = parse_colour(background_text(args)).ok()?;
    Some(c.map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8))
}

/// The images in which a panel covered drawn pixels, for one note.
#[derive(Default)]
struct Covered {
    images: usize,
    most: u64,
}

impl Covered {
    fn add(&mut self, pixels: u64) {
        if pixels > 0 {
            self.images += 1;
            self.most = self.most.max(pixels);
        }
    }

    /// The note on `option`'s panel drawn into `of` images.
    fn note(&self, option: &str, of: usize, args: &Args) -> Option<String> {
        (self.images > 0).then(|| {
            let which = match of {
                1 => "the image".to_string(),
                _ => format!("{} of the {of} images", self.images),
            };
            let why = match &args.camera.view {
                Some(v) => format!(
                    ": the view {} gives is not fitted around the panel (without --view, or \
                     with the file's target and distance left out, the fit keeps the data \
                     clear of it)",
                    v.display()
                ),
                None if args.camera.zoom.is_some_and(|z| z > 1.0)
                    || args.camera.target.is_some() =>
                {
                    ": --zoom or --target frame the data past the fit".to_string()
                }
                None => ": the image leaves the data too little room beside the panel (a larger \
                         image, a smaller --text-scale or another corner keeps it clear), or \
                         particles far from the rest lie under it"
                    .to_string(),
            };
            format!(
                "  note: {option} covers drawn particles in {which} (up to {} pixels under \
                 its panel){why}",
                self.most
            )
        })
    }
}

/// Says when a `--hide-attribute` range is narrower than one of the file's 16-bit steps
/// of the attribute (a molecule id of a column of 200 000, stored 3.16 apart) and those
/// steps reach whole numbers past it (other ids): it hides every particle of the steps
/// it touches, the values those steps hold being named.
fn coarse_range_notes(
    style: &mdlod_render::PointStyle,
    file: &mdlod_format::reader::MdlodFile,
) -> Vec<String> {
    hidden_ranges(style, file)
        .into_iter()
        .filter_map(|(a, range, _)| {
            let step = (f64::from(a.max) - f64::from(a.min)) / 65535.0;
            let [lo, hi] = range;
            if !(lo.is_finite() && hi.is_finite() && f64::from(hi - lo) < step) {
                return None;
            }
            let (first, last) = a.codes(range)?;
            let value = |code: u16, side: f64| {
                (f64::from(a.min) + (f64::from(code) + side) * step)
                    .clamp(f64::from(a.min), f64::from(a.max))
            };
            let (from, to) = (value(first, -0.5), value(last, 0.5));
            // Said where the steps reach a whole number past the range (ids, types): a
            // range of values closer than a step apart hides what it names.
            let (lo, hi) = (f64::from(range[0]), f64::from(range[1]));
            if from.ceil() >= lo.ceil() && to.floor() <= hi.floor() {
                return None;
            }
            Some(format!(
                "  note: --hide-attribute {}:{} is narrower than one 16-bit step of {} in this \
                 file ({step:.3}): it hides every particle of the steps it touches, values \
                 from {:.3} to {:.3}",
                Num(range[0]),
                Num(range[1]),
                a.name,
                from,
                to
            ))
        })
        .collect()
}

/// Draws a legend or label panel into the PNG `image` at `corner`, enlarged as the
/// image's size and `--text-scale` ask; `option` names what asked for it in an error.
/// Returns how many pixels it covered that showed something other than the background
/// ([`backdrop`]), which is data under the panel.
fn draw_panel(
    args: &Args,
    image: &Path,
    panel: &mdlod_render::legend::Legend,
    corner: LegendCorner,
    option: &str,
) -> Result<u64> {
    let mut png = mdlod_render::image::RgbaImage::load_png(image)?;
    let covered = draw_panel_in(args, &mut png, image, panel, corner, option)?;
    png.save_png(image)?;
    Ok(covered)
}

/// [`draw_panel`] into the image `png` in memory, which is to be written to `image`.
fn draw_panel_in(
    args: &Args,
    png: &mut mdlod_render::image::RgbaImage,
    image: &Path,
    panel: &mdlod_render::legend::Legend,
    corner: LegendCorner,
    option: &str,
) -> Result<u64> {
    let (background, text_scale) = (backdrop(args), args.text_scale);
    let corner = legend_corner(corner);
    let scale = panel
        .scale_in(png.width, png.height, text_scale)
        .unwrap_or(1);
    let covered = panel.covers(png, corner, scale, background);
    panel
        .draw(png, corner, scale)
        .map_err(|e| anyhow::anyhow!("{option}: {}: {e}", image.display()))?;
    Ok(covered)
}

/// The panels a movie draws into each image as it is rendered, before the image is
/// written: its `--label` with the frame's values, `--scale-bar` and `--axes` (one PNG
/// encoding per image; drawn into the written files, each panel took a decoding and an
/// encoding more, about 85 ms a panel at 1280×720). What each covered, for the notes.
struct FramePanels {
    labels: Vec<mdlod_render::legend::Legend>,
    missing: std::collections::BTreeSet<&'static str>,
    bar: Option<mdlod_render::legend::Legend>,
    axes: Option<mdlod_render::legend::Legend>,
    /// Of the label, the scale bar and the axes.
    covered: [Covered; 3],
    glyphs: std::collections::BTreeSet<char>,
}

impl FramePanels {
    /// The panels of images whose label values are `values` (in the order the images
    /// are drawn), of a movie whose frames' values are `movie`.
    fn new(
        args: &Args,
        values: &[&label::Values],
        movie: &[&label::Values],
        bar: Option<mdlod_render::legend::Legend>,
        axes: Option<mdlod_render::legend::Legend>,
    ) -> FramePanels {
        let (labels, missing) = match args.label.is_empty() {
            true => (Vec::new(), Default::default()),
            false => label_panels(args, values, movie),
        };
        FramePanels {
            labels,
            missing,
            bar,
            axes,
            covered: Default::default(),
            glyphs: Default::default(),
        }
    }

    /// Draws the `k`th image's panels into `png`, to be written to `image`.
    fn draw(
        &mut self,
        args: &Args,
        k: usize,
        png: &mut mdlod_render::image::RgbaImage,
        image: &Path,
    ) -> Result<()> {
        let panels = [
            (self.labels.get(k), args.label_corner(), "--label"),
            (self.bar.as_ref(), args.scale_bar_corner(), "--scale-bar"),
            (self.axes.as_ref(), args.axes_corner(), "--axes"),
        ];
        for (j, (panel, corner, option)) in panels.into_iter().enumerate() {
            if let Some(panel) = panel {
                if j == 0 {
                    self.glyphs.extend(panel.missing_glyphs());
                }
                let pixels = draw_panel_in(args, png, image, panel, corner, option)?;
                self.covered[j].add(pixels);
            }
        }
        Ok(())
    }

    /// The notes on what the panels of `images` images covered and lacked.
    fn notes(&self, args: &Args, images: usize, movie: &[&label::Values]) {
        for (covered, option) in self
            .covered
            .iter()
            .zip(["--label", "--scale-bar", "--axes"])
        {
            if let Some(note) = covered.note(option, images, args) {
                println!("{note}");
            }
        }
        if !args.label.is_empty() {
            label_notes(args, &self.missing, movie, &self.glyphs);
        }
    }
}

/// The `--label` panel of each image with its values (each frame's time the timestep
/// times `--dt` where given; a movie's times with one number of decimals, those of every
/// frame of `movie`, so that a piece of it, `--frames`, writes its times as the whole
/// run does), and the values some frame lacks.
fn label_panels(
    args: &Args,
    values: &[&label::Values],
    movie: &[&label::Values],
) -> (
    Vec<mdlod_render::legend::Legend>,
    std::collections::BTreeSet<&'static str>,
) {
    let timed = |v: &label::Values| label::Values {
        time: match (args.dt, v.timestep) {
            (Some(dt), Some(t)) => Some(t as f64 * dt),
            _ => v.time,
        },
        ..v.clone()
    };
    let values: Vec<label::Values> = values.iter().map(|v| timed(v)).collect();
    let decimals = label::time_decimals(movie.iter().filter_map(|v| timed(v).time));
    let mut missing = std::collections::BTreeSet::new();
    let panels = values
        .iter()
        .map(|v| mdlod_render::legend::Legend::Text {
            lines: args
                .label
                .iter()
                .map(|t| {
                    let (line, lacking) = v.fill(t, decimals);
                    missing.extend(lacking);
                    line
                })
                .collect(),
        })
        .collect();
    (panels, missing)
}

/// Refuses, before anything is drawn, a `--label` that the values of some image (`values`)
/// widen past what the image holds (a placeholder's text is known only with the file).
fn check_label_room(args: &Args, values: &[&label::Values]) -> Result<Option<[u32; 2]>> {
    if args.label.is_empty() {
        return Ok(None);
    }
    let (panels, _) = label_panels(args, values, values);
    let mut room = [0u32; 2];
    for (i, panel) in panels.iter().enumerate() {
        let scale = panel.scale_in(args.camera.width, args.camera.height, args.text_scale);
        if let Some(scale) = scale {
            let (w, h) = panel.room_needed(scale);
            room = [room[0].max(w), room[1].max(h)];
        } else {
            let (w, h) = panel.room_needed(args.text_scale.unwrap_or(1));
            anyhow::bail!(
                "--label: a {}×{} image cannot hold the label with {}'s values (at least \
                 {w}×{h} pixels with its margin); draw a larger image, or a shorter label",
                args.camera.width,
                args.camera.height,
                if values.len() == 1 {
                    "the file".to_string()
                } else {
                    format!("frame {} of {}", i + 1, values.len())
                }
            );
        }
    }
    Ok(Some(room))
}

/// Draws `--label` into each image, with its own values.
fn write_labels(
    args: &Args,
    images: &[(PathBuf, label::Values)],
    movie: Option<&[label::Values]>,
) -> Result<()> {
    if args.label.is_empty() {
        return Ok(());
    }
    let mut glyphs = std::collections::BTreeSet::new();
    let values: Vec<&label::Values> = images.iter().map(|(_, v)| v).collect();
    let movie: Vec<&label::Values> = match movie {
        Some(all) => all.iter().collect(),
        None => values.clone(),
    };
    let (panels, missing) = label_panels(args, &values, &movie);
    let mut covered = Covered::default();
    for ((image, _), label) in images.iter().zip(&panels) {
        glyphs.extend(label.missing_glyphs());
        covered.add(draw_panel(
            args,
            image,
            label,
            args.label_corner(),
            "--label",
        )?);
    }
    if let Some(note) = covered.note("--label", images.len(), args) {
        println!("{note}");
    }
    label_notes(args, &missing, &movie, &glyphs);
    Ok(())
}

/// `--label`'s notes: the fields the files record no value of, a recorded time `--dt`
/// replaces, and characters the font lacks.
fn label_notes(
    args: &Args,
    missing: &std::collections::BTreeSet<&'static str>,
    movie: &[&label::Values],
    glyphs: &std::collections::BTreeSet<char>,
) {
    for field in missing {
        let hint = match *field {
            "time" => " (--dt DT gives it as the timestep times DT)",
            _ => "",
        };
        println!("  note: --label: the file records no {field}: {{{field}}} shows ?{hint}");
    }
    // A recorded time replaced (a run of variable timestep records the true one).
    let recorded: Vec<f64> = movie.iter().filter_map(|v| v.time).collect();
    if let (Some(dt), Some(first), Some(last)) = (args.dt, recorded.first(), recorded.last()) {
        let times = match recorded.len() {
            1 => format!("time {first}"),
            _ => format!("times, {first} to {last}"),
        };
        println!(
            "  note: --label: --dt {dt} replaces the recorded {times}: {{time}} shows the \
             timestep times {dt} (leave out --dt to show the recorded time)"
        );
    }
    if !glyphs.is_empty() {
        let list: Vec<String> = glyphs.iter().map(|c| format!("{c:?}")).collect();
        println!(
            "  note: --label: the image's font has no {} (drawn as ?)",
            list.join(", ")
        );
    }
}

/// A species name of a list (`--hide-species W, NA`): trimmed; an empty one is a stray
/// comma, and one of several words no input writes.
fn species_name(s: &str) -> Result<String, String> {
    let name = s.trim();
    if name.is_empty() {
        return Err("an empty name (a stray comma?): list names as W,NA,CL".into());
    }
    if name.contains(char::is_whitespace) {
        return Err(format!(
            "{s:?}: a species name holds no spaces; list several with commas (W,NA,CL)"
        ));
    }
    Ok(name.to_string())
}

/// The points' look, shared by `render` and `sample` (sphere and S-NDF modes).
#[derive(clap::Args, Clone, Debug)]
pub struct StyleArgs {
    /// Colour the particles by the file's scalar attribute through this colour map
    /// (clusters by their mean) instead of by species.
    #[arg(long, value_enum, ignore_case = true)]
    pub colour_map: Option<ColourMapArg>,
    /// Multiply every radius by this (occlusion culling is then off).
    #[arg(long, default_value_t = 1.0)]
    pub radius_scale: f32,
    /// A species' colour, e.g. `Cu=#c87533`; repeatable. Exact for particles, and for
    /// clusters where the file has at most four species of affinely independent colours
    /// (else a least-squares fit of their mixtures). With --colour-map, the species named
    /// keep their colour and the others take the map's (walls grey beside grains
    /// coloured by speed; clusters mixing both take the map's colour of their mean)
    #[arg(long = "species-colour", value_name = "NAME=COLOUR")]
    pub species_colour: Vec<String>,
    /// The colours of species that take mdlod's palette (type numbers, names of no
    /// element) where --species-colour gives none: `okabe-ito`, Okabe and Ito's seven,
    /// told apart with the common colour-vision deficiencies, the first three also in
    /// grey print (an element's colour stays; types past the seventh repeat them)
    #[arg(long, value_enum, ignore_case = true, default_value_t = PaletteArg::Default)]
    pub palette: PaletteArg,
    /// A species' radius, e.g. `Ag=1.6`; repeatable. Particles of their own sizes keep
    /// their proportions (the species' mean becomes R).
    #[arg(long = "species-radius", value_name = "NAME=R")]
    pub species_radius: Vec<String>,
    /// Leave out the particles of a species, and the clusters of them (a cluster holding
    /// them and others is refined until it holds none); repeatable, or a list
    /// (`--hide-species W,NA,CL`).
    #[arg(
        long = "hide-species",
        value_name = "NAME",
        value_delimiter = ',',
        value_parser = species_name
    )]
    pub hide_species: Vec<String>,
    /// Leave out the particles whose attribute value lies from MIN to MAX (inclusive;
    /// an end left empty is open: `:0.2`, `2.5:`), as OVITO's expression selection and
    /// delete: `--hide-attribute 0.5:1.5` leaves out the atoms a common-neighbour
    /// analysis column calls fcc (1), showing the defects and surfaces; clusters holding
    /// them and others are refined until they hold none; repeatable (up to 4). The file
    /// must keep an attribute (convert with --attribute). NAME=MIN:MAX reads the
    /// attribute NAME, so that one image hides by several: `--hide-attribute
    /// c_cna=0.5:1.5 --hide-attribute c_pe=:-3.5` leaves out the fcc atoms and the low
    /// energies
    #[arg(
        long = "hide-attribute",
        value_name = "[NAME=]MIN:MAX",
        allow_hyphen_values = true,
        value_parser = parse_hide_range
    )]
    pub hide_attribute: Vec<HideRange>,
    /// The attribute --hide-attribute reads, where it is not the one --attribute
    /// colours by (a file of several): `--hide-by c_cna --hide-attribute 0.5:1.5
    /// --attribute c_pe --colour-map viridis` leaves out the fcc atoms and colours the
    /// rest by their energy [default: --attribute's, else the first]
    #[arg(long, value_name = "NAME")]
    pub hide_by: Option<String>,
    /// Which of the file's attributes --colour-map, --hide-attribute and
    /// --attribute-range read (and splats lit by the attribute), for a file that keeps
    /// several (`convert --attribute c_pe --attribute c_ke`); default: the first.
    /// `mdlod info` lists them
    #[arg(long, value_name = "NAME")]
    pub attribute: Option<String>,
    /// The attribute values at the ends of --colour-map (and of --intensity attribute),
    /// e.g. `0:2.5`, instead of the file's own range (a movie's default: the range over
    /// all its frames), so that images made apart compare.
    #[arg(long, value_name = "MIN:MAX", allow_hyphen_values = true, value_parser = parse_range)]
    pub attribute_range: Option<[f32; 2]>,
    /// Map the attribute's logarithm (densities, energies spanning decades) with
    /// --colour-map or --intensity attribute; values from 0 (kinetic energies of frozen
    /// atoms) start at the smallest value above 0, a range given from 0 four decades
    /// below its top. In density mode, the volume fraction's logarithm from --density-min
    /// to --density-max (an SPH or n-body run's core and halo in one image).
    #[arg(long)]
    pub log_scale: bool,
    /// Cut the data away beyond a plane, as OVITO's Slice: nx,ny,nz,d keeps the particles
    /// whose centres p have n·p ≤ d, n the unit normal (nx,ny,nz made unit) and d the
    /// plane's distance from the origin along it (world units, as `mdlod info` gives the
    /// box); repeatable (two facing planes keep a slab, the clearest cross-section; up
    /// to 6). Clusters across a plane are refined down to particles, so the cut face is
    /// exact. The camera is unchanged: look from the cut side (n·eye > d) to see the
    /// face. The density and iso modes take one plane and clip their samples instead:
    /// particles beyond it still add density inside it.
    #[arg(long, value_name = "NX,NY,NZ,D", value_parser = parse_plane, allow_hyphen_values = true)]
    pub clip: Vec<[f32; 4]>,
}

/// `MIN:MAX` where either end may be left empty (open: infinite), `MIN ≤ MAX`.
/// One `--hide-attribute`: a range of values, and the attribute it reads where named.
#[derive(Clone, Debug, PartialEq)]
pub struct HideRange {
    pub by: Option<String>,
    pub range: [f32; 2],
}

/// `--hide-attribute [NAME=]MIN:MAX`.
pub fn parse_hide_range(s: &str) -> Result<HideRange, String> {
    match s.split_once('=') {
        Some((name, range)) => {
            let name = name.trim();
            if name.is_empty() {
                return Err(format!(
                    "{s:?}: expected NAME=MIN:MAX with the attribute's name before `=`"
                ));
            }
            Ok(HideRange {
                by: Some(name.to_string()),
                range: parse_open_range(range)
                    .map_err(|e| format!("{s:?}: {}", e.split_once(": ").map_or(&*e, |p| p.1)))?,
            })
        }
        None => Ok(HideRange {
            by: None,
            range: parse_open_range(s)?,
        }),
    }
}

pub fn parse_open_range(s: &str) -> Result<[f32; 2], String> {
    let (lo, hi) = s
        .split_once(':')
        .ok_or_else(|| format!("{s:?}: expected MIN:MAX, e.g. 0.5:1.5, :0.2 or 2.5:"))?;
    let num = |v: &str, open: f32| -> Result<f32, String> {
        if v.trim().is_empty() {
            return Ok(open);
        }
        v.trim()
            .parse::<f32>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| {
                format!("{s:?}: {v:?} is not a number in single precision (finite, within ±3.4e38)")
            })
    };
    if hi.contains(':') {
        return Err(format!(
            "{s:?}: expected one MIN:MAX range; repeat --hide-attribute for more"
        ));
    }
    let (lo, hi) = (num(lo, f32::NEG_INFINITY)?, num(hi, f32::INFINITY)?);
    if lo.is_infinite() && hi.is_infinite() {
        return Err(format!("{s:?}: both ends open would hide every value"));
    }
    if hi < lo {
        return Err(format!("{s:?}: MAX must not be below MIN"));
    }
    Ok([lo, hi])
}

/// Parses `MIN:MAX` (finite, MAX above MIN).
/// `--frames START:END[:STEP]`: positions in a batch's frame list.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FrameSelection {
    pub start: Option<usize>,
    pub end: Option<usize>,
    pub step: usize,
}

impl FrameSelection {
    /// Whether the frame at position `i` is drawn.
    fn takes(&self, i: usize) -> bool {
        let start = self.start.unwrap_or(0);
        i >= start && self.end.is_none_or(|e| i < e) && (i - start).is_multiple_of(self.step)
    }
}

fn parse_frames(s: &str) -> Result<FrameSelection, String> {
    let parts: Vec<&str> = s.split(':').collect();
    if !(2..=3).contains(&parts.len()) {
        return Err(format!(
            "{s:?}: give START:END or START:END:STEP (e.g. 0:100, ::10)"
        ));
    }
    let number = |p: &str, what: &str| -> Result<Option<usize>, String> {
        let kind = match what {
            "STEP" => "no step between frames (1, 2, ...: a movie runs forward only)",
            _ => "no frame position (0, 1, ...)",
        };
        match p.trim() {
            "" => Ok(None),
            t => t
                .parse::<usize>()
                .map(Some)
                .map_err(|_| format!("{s:?}: {what} {t:?} is {kind}")),
        }
    };
    let (start, end) = (number(parts[0], "START")?, number(parts[1], "END")?);
    let step = match parts.get(2) {
        Some(p) => number(p, "STEP")?.unwrap_or(1),
        None => 1,
    };
    if step == 0 {
        return Err(format!("{s:?}: STEP must be 1 or more"));
    }
    if let (Some(a), Some(b)) = (start, end) {
        if b <= a {
            return Err(format!(
                "{s:?}: END ({b}) must be above START ({a}); END is not drawn"
            ));
        }
    }
    Ok(FrameSelection { start, end, step })
}

pub fn parse_range(s: &str) -> Result<[f32; 2], String> {
    let (lo, hi) = s
        .split_once(':')
        .ok_or_else(|| format!("{s:?}: expected MIN:MAX, e.g. 0:2.5"))?;
    if lo.trim().is_empty() || hi.trim().is_empty() {
        return Err(format!(
            "{s:?}: give both ends, MIN:MAX (no end is left open here; `mdlod info` prints \
             the file's own range)"
        ));
    }
    let num = |v: &str| -> Result<f32, String> {
        v.trim()
            .parse::<f32>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| format!("{s:?}: {v:?} is not a finite number"))
    };
    let (lo, hi) = (num(lo)?, num(hi)?);
    if hi <= lo {
        return Err(format!("{s:?}: MAX must be above MIN"));
    }
    Ok([lo, hi])
}

#[derive(Clone, Copy, Debug, clap::ValueEnum)]
pub enum ColourMapArg {
    Viridis,
    Magma,
    Cividis,
    CoolWarm,
    #[value(alias = "gray")]
    Grey,
}

#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum PaletteArg {
    Default,
    OkabeIto,
}

impl ColourMapArg {
    pub fn map(self) -> mdlod_render::ColourMap {
        use mdlod_render::ColourMap;
        match self {
            ColourMapArg::Viridis => ColourMap::Viridis,
            ColourMapArg::Magma => ColourMap::Magma,
            ColourMapArg::Cividis => ColourMap::Cividis,
            ColourMapArg::CoolWarm => ColourMap::CoolWarm,
            ColourMapArg::Grey => ColourMap::Grey,
        }
    }
}

impl StyleArgs {
    pub fn style(&self) -> Result<mdlod_render::PointStyle> {
        use mdlod_render::SpeciesStyle;
        let mut species: Vec<SpeciesStyle> = vec![];
        let mut entry = |name: &str| -> usize {
            match species.iter().position(|s| s.name == name) {
                Some(i) => i,
                None => {
                    species.push(SpeciesStyle {
                        name: name.to_string(),
                        ..Default::default()
                    });
                    species.len() - 1
                }
            }
        };
        let split = |s: &str, what: &str| -> Result<(String, String)> {
            let (name, value) = s
                .split_once('=')
                .map(|(a, b)| (a.trim().to_string(), b.trim().to_string()))
                .with_context(|| format!("{s:?}: expected NAME={what}"))?;
            if name.is_empty() {
                anyhow::bail!("{s:?}: expected NAME={what}, a species' name before `=`");
            }
            Ok((name, value))
        };
        // A species styled twice by one option would take the last silently.
        let once = |option: &str, given: &[String]| -> Result<()> {
            let names: Vec<&str> = given
                .iter()
                .map(|g| g.split_once('=').map_or(g.as_str(), |(n, _)| n).trim())
                .collect();
            if let Some((i, n)) = names
                .iter()
                .enumerate()
                .find(|(i, n)| names[..*i].contains(n))
            {
                let first = names.iter().position(|m| m == n).unwrap_or(0);
                anyhow::bail!(
                    "{option} names {n:?} twice ({:?}, then {:?}): give it once",
                    given[first],
                    given[i]
                );
            }
            Ok(())
        };
        once("--species-colour", &self.species_colour)?;
        once("--species-radius", &self.species_radius)?;
        let mut colours = vec![];
        for c in &self.species_colour {
            let (name, colour) = split(c, "COLOUR")?;
            let rgb = parse_colour(&colour)
                .with_context(|| format!("--species-colour {c:?}"))?
                .map(mdlod_render::renderer::srgb_to_linear);
            colours.push((entry(&name), rgb));
        }
        let mut radii = vec![];
        for r in &self.species_radius {
            let (name, radius) = split(r, "R")?;
            let v: f32 = radius
                .parse()
                .with_context(|| format!("--species-radius {r:?}: the radius is not a number"))?;
            if !(v.is_finite() && v > 0.0) {
                anyhow::bail!("--species-radius {r:?}: the radius must be a positive number");
            }
            radii.push((entry(&name), v));
        }
        let hidden: Vec<usize> = self.hide_species.iter().map(|n| entry(n)).collect();
        if self.hide_by.is_some() && !self.hide_attribute.iter().any(|h| h.by.is_none()) {
            anyhow::bail!(
                "--hide-by has no effect without --hide-attribute MIN:MAX: it names what that \
                 reads (a range of its own, NAME=MIN:MAX, reads NAME)"
            );
        }
        if self.hide_attribute.len() > mdlod_format::reader::MAX_HIDDEN_RANGES {
            anyhow::bail!(
                "--hide-attribute given {} times: at most {} ranges (join neighbouring ones, \
                 or leave an end open: `:0.2`, `2.5:`)",
                self.hide_attribute.len(),
                mdlod_format::reader::MAX_HIDDEN_RANGES
            );
        }
        for (i, c) in colours {
            species[i].colour = Some(c);
        }
        for (i, r) in radii {
            species[i].radius = Some(r);
        }
        for i in hidden {
            species[i].hidden = true;
        }
        Ok(mdlod_render::PointStyle {
            species,
            attribute: self.attribute.clone(),
            radius_scale: self.radius_scale,
            attribute_range: self.attribute_range,
            range_derived: false,
            log_scale: self.log_scale,
            clip: self.clip.clone(),
            hidden_values: self
                .hide_attribute
                .iter()
                .filter(|h| h.by.is_none())
                .map(|h| h.range)
                .collect(),
            hide_by: self.hide_by.clone(),
            hidden_named: self
                .hide_attribute
                .iter()
                .filter_map(|h| Some((h.by.clone()?, h.range)))
                .collect(),
            colour_map: self.colour_map.map(ColourMapArg::map),
            palette: match self.palette {
                PaletteArg::Default => mdlod_render::style::Palette::Default,
                PaletteArg::OkabeIto => mdlod_render::style::Palette::OkabeIto,
            },
        })
    }
}

/// The image size when neither `--width` nor `--height` is given (nor a view file's).
const DEFAULT_WIDTH: u32 = 1280;
const DEFAULT_HEIGHT: u32 = 720;

/// The image size and the camera, shared by `render` and `sample`.
#[derive(clap::Args, Clone, Debug)]
pub struct ViewArgs {
    /// Image width, pixels (given alone, the height keeps the default shape, or a
    /// --view file's).
    #[arg(long, default_value_t = DEFAULT_WIDTH, value_parser = clap::value_parser!(u32).range(1..))]
    pub width: u32,
    /// Image height, pixels (given alone, the width keeps the default shape, or a
    /// --view file's).
    #[arg(long, default_value_t = DEFAULT_HEIGHT, value_parser = clap::value_parser!(u32).range(1..))]
    pub height: u32,
    /// A JSON view file (as written by --save-view); --azimuth, --elevation, --zoom and
    /// --ortho given with it change the saved view.
    #[arg(long)]
    pub view: Option<PathBuf>,
    /// Orbit angle around the vertical axis (z), degrees [default: 30; with --view, the
    /// file's; without either angle here or in the file, data whose particles lie in one
    /// plane (a 2D simulation) is seen square on: straight down on an x-y layer].
    #[arg(long, allow_hyphen_values = true)]
    pub azimuth: Option<f32>,
    /// Angle above the horizontal (the x-y plane), degrees [default: 20; with --view, the
    /// file's; flat data as for --azimuth].
    #[arg(long, allow_hyphen_values = true)]
    pub elevation: Option<f32>,
    /// 1 fits the data; 2 is twice as close (with --view: twice as close as the saved
    /// view) [default: 1].
    #[arg(long)]
    pub zoom: Option<f32>,
    /// Orthographic instead of perspective projection.
    #[arg(long)]
    pub ortho: bool,
    /// Look in the direction X,Y,Z (world axes; e.g. `1,1,1` along a cubic crystal's
    /// [111], `0,0,-1` straight down) instead of --azimuth and --elevation; z stays up
    /// on screen (looking straight down or up, y is; x points right looking down, left
    /// looking up).
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_direction, allow_hyphen_values = true, conflicts_with_all = ["azimuth", "elevation"])]
    pub look_along: Option<[f32; 3]>,
    /// The point looked at and orbited around, X,Y,Z in world units (a pan: with
    /// --zoom, a close-up of one place), instead of the data's centre [default: with
    /// --view, the file's]; the distance is fitted as without it.
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_point, allow_hyphen_values = true)]
    pub target: Option<[f32; 3]>,
}

/// Parses a point `X,Y,Z` (finite).
fn parse_point(s: &str) -> Result<[f32; 3], String> {
    let p = parse_numbers::<f32, 3>(s, "X,Y,Z")?;
    match p.iter().all(|c| c.is_finite()) {
        true => Ok(p),
        false => Err(format!("{s:?}: a point needs finite numbers")),
    }
}

/// Parses `N` comma-separated numbers; `what` names them in the error (`X,Y,Z`).
fn parse_numbers<T: std::str::FromStr, const N: usize>(
    s: &str,
    what: &str,
) -> Result<[T; N], String> {
    let expected = || format!("{s:?}: expected {N} numbers {what}");
    let v: Vec<T> = s
        .split(',')
        .map(|t| t.trim().parse::<T>())
        .collect::<Result<_, _>>()
        .map_err(|_| expected())?;
    <[T; N]>::try_from(v).map_err(|_| expected())
}

/// Parses a direction `X,Y,Z` (finite, not zero). One of a length whose square single
/// precision cannot hold (`1e20,0,0`, `1e-30,0,0`) is scaled to a largest component of
/// 1, the same direction: its square overflowed or vanished, and the light with it.
fn parse_direction(s: &str) -> Result<[f32; 3], String> {
    let d = parse_numbers::<f32, 3>(s, "X,Y,Z")?;
    if d.iter().any(|c| !c.is_finite()) || d.iter().all(|&c| c == 0.0) {
        return Err(format!(
            "{s:?}: a direction needs finite numbers, not all 0"
        ));
    }
    let largest = d.iter().fold(0.0f32, |m, c| m.max(c.abs()));
    if !(1e-15..=1e15).contains(&largest) {
        return Ok(d.map(|c| (f64::from(c) / f64::from(largest)) as f32));
    }
    Ok(d)
}

/// The azimuth and elevation (degrees) of a camera looking in direction `d`: its eye
/// lies towards `-d` from the target.
pub fn angles_looking_along(d: [f32; 3]) -> (f32, f32) {
    let v = mdlod_render::glam::DVec3::new(f64::from(d[0]), f64::from(d[1]), f64::from(d[2]))
        .normalize();
    let back = -v;
    let elevation = back.z.clamp(-1.0, 1.0).asin().to_degrees();
    // Straight down or up: any azimuth; -90 puts +y up on screen looking down (x to the
    // right), 90 looking up (x then to the left: the view is not mirrored).
    let azimuth = if back.x.hypot(back.y) < 1e-9 {
        if back.z > 0.0 {
            -90.0
        } else {
            90.0
        }
    } else {
        back.y.atan2(back.x).to_degrees()
    };
    // (+ 0.0: no -0 in a saved view.)
    (azimuth as f32 + 0.0, elevation as f32 + 0.0)
}

impl ViewArgs {
    /// The files a command reads, for [`super::check_output`]: `file` and the view file.
    pub fn inputs<'a>(
        &'a self,
        file: &'a std::path::Path,
    ) -> Vec<(&'static str, &'a std::path::Path)> {
        [("", file)]
            .into_iter()
            .chain(self.view.as_deref().map(|v| ("--view", v)))
            .collect()
    }

    /// Says which fields of the view file this version does not read (a misspelt
    /// `azimuth` would otherwise leave the default angle without a word).
    pub fn note_unknown_fields(&self) {
        let Some(path) = &self.view else { return };
        let Ok(text) =
            mdlod_format::files::read_capped_string(path, mdlod_format::files::SMALL_JSON)
        else {
            return; // (The render says why it cannot read it.)
        };
        for field in ViewFile::unknown_fields(&text) {
            println!(
                "note: {}: field {field:?} is not one this mdlod reads, ignored (a view file \
                 has {})",
                path.display(),
                ViewFile::FIELDS.join(", ")
            );
        }
        // (From the text read: the same checks as a load's.)
        let note = ViewFile::parse(&text)
            .ok()
            .and_then(|v| v.aspect_note(self.width, self.height));
        if let Some(note) = note {
            println!("note: {}: {note}", path.display());
        }
    }

    pub fn spec(&self) -> ViewSpec {
        let (azimuth, elevation) = match self.look_along.map(angles_looking_along) {
            Some((a, e)) => (Some(a), Some(e)),
            None => (self.azimuth, self.elevation),
        };
        let changes = mdlod_render::ViewChanges {
            azimuth_deg: azimuth,
            elevation_deg: elevation,
            zoom: self.zoom,
            orthographic: self.ortho,
            target: self.target,
        };
        let projection = if self.ortho {
            Projection::Orthographic
        } else {
            Projection::Perspective
        };
        match (&self.view, self.target) {
            (Some(p), _) if changes.is_empty() => ViewSpec::File(p.clone()),
            (Some(p), _) => ViewSpec::FileWith(p.clone(), changes),
            // No angle given: the data's default view (square on to flat data), panned to
            // the target if one is given.
            (None, target) if azimuth.is_none() && elevation.is_none() => ViewSpec::Default {
                zoom: self.zoom.unwrap_or(1.0),
                projection,
                target,
            },
            // A pan: the fitted distance, looking at the target.
            (None, Some(t)) => ViewSpec::View(ViewFile {
                projection,
                azimuth_deg: azimuth.unwrap_or(30.0),
                elevation_deg: elevation.unwrap_or(20.0),
                zoom: self.zoom.unwrap_or(1.0),
                target: Some(t),
                ..Default::default()
            }),
            (None, None) => ViewSpec::Orbit {
                azimuth_deg: azimuth.unwrap_or(30.0),
                elevation_deg: elevation.unwrap_or(20.0),
                zoom: self.zoom.unwrap_or(1.0),
                projection,
            },
        }
    }
}

/// Where `--legend-in-image` draws the legend.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum LegendCorner {
    TopLeft,
    TopRight,
    BottomLeft,
    BottomRight,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Mode {
    #[value(alias = "standard")]
    Spheres,
    Splat,
    SplatOver,
    Sndf,
    Density,
    Iso,
}

/// The options that only some modes read, by argument id, with those modes. Given on
/// the command line with another mode, such an option would be silently ignored (a
/// `--radius-scale 2` that the density volume never sees): that is an error instead.
const MODE_OPTIONS: &[(&str, &[Mode])] = {
    use Mode::*;
    const STYLED: &[Mode] = &[Spheres, Sndf];
    const VOLUME: &[Mode] = &[Density, Iso];
    &[
        ("spp", &[Spheres]),
        ("no_occlusion", STYLED),
        ("iso_value", &[Iso]),
        ("slices", VOLUME),
        ("kernel_scale", &[Density, Iso, Splat, SplatOver]),
        ("density_max", &[Density]),
        ("density_min", &[Density]),
        ("absorption", &[Density]),
        ("iterations", &[Sndf]),
        ("bins", &[Sndf]),
        ("binning", &[Sndf]),
        ("opacity", &[SplatOver]),
        ("sort", &[SplatOver]),
        ("intensity", &[Splat]),
        ("exposure", &[Splat]),
        ("light_range", &[Splat]),
        ("colour_map", &[Spheres, Sndf, Splat, Density, Iso]),
        ("radius_scale", STYLED),
        ("species_colour", &[Spheres, Sndf, Splat, SplatOver, Iso]),
        ("palette", &[Spheres, Sndf, Splat, SplatOver, Iso]),
        ("species_radius", STYLED),
        ("attribute_range", &[Spheres, Sndf, Splat, Density, Iso]),
        ("log_scale", &[Spheres, Sndf, Splat, Density, Iso]),
        ("cell", &[Spheres, Splat, SplatOver, Density, Iso]),
        ("light", STYLED),
        ("ambient", STYLED),
        ("diffuse", STYLED),
        ("brdf", STYLED),
        ("specular", STYLED),
        ("exponent", STYLED),
    ]
};

/// The spheres' and S-NDFs' lighting the options ask for (the renderer's default where
/// they give none).
fn lighting(args: &Args) -> Result<mdlod_render::Lighting> {
    let mut l = mdlod_render::Lighting::default();
    if let Some(s) = &args.light {
        let (direction, colour) = super::shade::parse_light(s).context("--light")?;
        l.direction_view = direction;
        l.colour = colour;
    }
    for (option, given, slot) in [
        ("--ambient", args.ambient, &mut l.ambient),
        ("--diffuse", args.diffuse, &mut l.diffuse),
        ("--specular", args.specular, &mut l.specular),
        ("--exponent", args.exponent, &mut l.shininess),
    ] {
        if let Some(v) = given {
            super::shade::check_weights(&[(option, v)])?;
            *slot = v;
        }
    }
    if matches!(args.brdf, Some(super::shade::Brdf::Lambert)) {
        if let Some(option) = [
            (args.specular.is_some(), "--specular"),
            (args.exponent.is_some(), "--exponent"),
        ]
        .iter()
        .find_map(|&(given, o)| given.then_some(o))
        {
            anyhow::bail!(
                "{option} has no effect with --brdf lambert: it sets the Blinn-Phong highlight"
            );
        }
        l.specular = 0.0;
    }
    Ok(l)
}

fn mode_name(mode: Mode) -> String {
    use clap::ValueEnum;
    mode.to_possible_value()
        .map_or_else(|| format!("{mode:?}"), |v| v.get_name().to_string())
}

/// Refuses an option given on the command line (`matches`: the `render` subcommand's)
/// that the chosen mode does not read.
/// Whether a view is fitted to the data: orbit options, or a view file without a target
/// or a distance (which the fit then gives).
fn view_fits(view: &ViewSpec) -> bool {
    match view {
        ViewSpec::Orbit { .. } | ViewSpec::Default { .. } => true,
        // (A file that cannot be read fails where it is loaded, saying why.)
        ViewSpec::File(p) | ViewSpec::FileWith(p, _) => match ViewFile::load(p) {
            Ok(v) => v.target.is_none() || v.distance.is_none(),
            Err(_) => true,
        },
        ViewSpec::View(v) => v.target.is_none() || v.distance.is_none(),
        ViewSpec::Camera(_) => false,
    }
}

/// Whether `--background` asks for none.
fn transparent(background: Option<&str>) -> bool {
    background.is_some_and(|b| {
        let b = b.trim();
        b.eq_ignore_ascii_case("none") || b.eq_ignore_ascii_case("transparent")
    })
}

/// Whether the picture maps the scalar attribute: a colour map, or splats of attribute
/// light.
fn by_attribute(args: &Args) -> bool {
    match args.mode {
        Mode::Splat => matches!(args.intensity, Intensity::Attribute),
        _ => args.style.colour_map.is_some(),
    }
}

/// Writes `--save-view`'s file. A movie's or turntable's view may go into a directory
/// that does not exist yet, as its images do (a still's was checked up front).
/// Refuses, before drawing, a file written beside the image (`option`'s, `what` it
/// holds) that cannot be: an input or a directory, the `-o` image itself, or, for a
/// still (`single`), one in a directory that does not exist (as for -o and --legend).
fn check_side_output(
    option: &str,
    what: &str,
    p: &Path,
    output: &Path,
    inputs: &[(&str, &Path)],
    single: bool,
) -> Result<()> {
    super::check_output(option, p, inputs)?;
    super::check_writable_beside(option, p)?;
    if p == output || super::same_file(p, output) {
        anyhow::bail!(
            "{option} {} is the -o output too: give {what} another name",
            p.display()
        );
    }
    if let Some(dir) = p.parent().filter(|d| single && !d.as_os_str().is_empty()) {
        if !dir.is_dir() {
            anyhow::bail!(
                "{option} {}: the directory {} does not exist",
                p.display(),
                dir.display()
            );
        }
    }
    Ok(())
}

/// Writes `values` (row by row) as a NumPy `.npy` array of little-endian 32-bit floats
/// of shape (`rows`, `columns`) (format version 1.0: the magic, a header dictionary
/// padded to a multiple of 64 bytes, the data).
fn write_npy(p: &Path, rows: u32, columns: u32, values: &[f32]) -> Result<()> {
    anyhow::ensure!(
        values.len() as u64 == u64::from(rows) * u64::from(columns),
        "{} values for {rows}×{columns}",
        values.len()
    );
    let dict =
        format!("{{'descr': '<f4', 'fortran_order': False, 'shape': ({rows}, {columns}), }}");
    // Magic (6), version (2), header length (2), then the header ending in a line end.
    let unpadded = 10 + dict.len() + 1;
    let header = format!(
        "{dict}{}\n",
        " ".repeat(unpadded.next_multiple_of(64) - unpadded)
    );
    let mut bytes = Vec::with_capacity(10 + header.len() + 4 * values.len());
    bytes.extend_from_slice(b"\x93NUMPY\x01\x00");
    bytes.extend_from_slice(&(header.len() as u16).to_le_bytes());
    bytes.extend_from_slice(header.as_bytes());
    for v in values {
        bytes.extend_from_slice(&v.to_le_bytes());
    }
    // (Renamed into place: an interrupted write leaves no partial array.)
    mdlod_render::image::write_atomic(p, &bytes)?;
    Ok(())
}

fn save_view(p: &Path, camera: &Camera, [width, height]: [u32; 2]) -> Result<()> {
    if let Some(dir) = p.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    }
    ViewFile::from_camera(camera)
        .seen_in(width, height)
        .save(p)
        .with_context(|| format!("cannot write {}", p.display()))
}

/// Density mode's bottom of the transfer function: as given, else 0, or four decades
/// below the top on a log scale.
fn density_min(args: &Args) -> f32 {
    args.density_min.unwrap_or(if args.style.log_scale {
        // Rounded once (0.002 for a top of 20, where 20 × 1e-4 in single precision
        // prints 0.0019999999).
        (f64::from(args.density_max) * 1e-4) as f32
    } else {
        0.0
    })
}

/// Whether the splats' image goes through a colour map (a projection's map).
fn projected(args: &Args) -> bool {
    args.mode == Mode::Splat && args.style.colour_map.is_some()
}

/// A view file's recorded image size, where `--width` and `--height` are both left to
/// their defaults: the saved view then draws the picture it was saved from; where one of
/// them is given, the other keeps the saved shape, or without a saved size the default
/// one (16:9: `--width 640` alone draws 640×360, not 640×720). (A view file that cannot
/// be read fails where it is rendered.)
pub fn size_from_view(camera: &mut ViewArgs, matches: &clap::ArgMatches) {
    let defaulted =
        |id: &str| matches.value_source(id) == Some(clap::parser::ValueSource::DefaultValue);
    let saved = camera.view.as_deref().and_then(|p| ViewFile::load(p).ok());
    let [w, h] = saved
        .and_then(|v| v.image)
        .filter(|&[w, h]| w > 0 && h > 0)
        .unwrap_or([DEFAULT_WIDTH, DEFAULT_HEIGHT]);
    // One of them given: the other keeps the saved (or default) shape.
    let scaled = |given: u32, of: u32, other: u32| {
        ((f64::from(given) * f64::from(other) / f64::from(of)).round() as u32).max(1)
    };
    match (defaulted("width"), defaulted("height")) {
        (true, true) => (camera.width, camera.height) = (w, h),
        (false, true) => camera.height = scaled(camera.width, w, h),
        (true, false) => camera.width = scaled(camera.height, h, w),
        (false, false) => {}
    }
}

pub fn check_mode_options(args: &Args, matches: &clap::ArgMatches) -> Result<()> {
    if args.cell_width.is_some() && args.cell.is_none() {
        anyhow::bail!(
            "--cell-width has no effect without --cell: it sets the width of the cell's \
             edges, which --cell draws"
        );
    }
    // A projection colours the image's light, which holds no species colour.
    if projected(args) && !args.style.species_colour.is_empty() {
        anyhow::bail!(
            "--species-colour has no effect on a projection (--mode splat with \
             --colour-map colours each pixel's light, not the particles)"
        );
    }
    if args.style.palette != PaletteArg::Default
        && (args.style.colour_map.is_some() || lit_by_value(args))
    {
        anyhow::bail!(
            "--palette has no effect with {}: it colours species, which the attribute's \
             colours replace",
            if args.style.colour_map.is_some() {
                "--colour-map"
            } else {
                "--intensity attribute"
            }
        );
    }
    if args.mode == Mode::Iso
        && args.style.colour_map.is_some()
        && !args.style.species_colour.is_empty()
    {
        anyhow::bail!(
            "--species-colour has no effect on an iso-surface coloured by --colour-map: each \
             point of it takes the map's colour of the attribute's mean around it"
        );
    }
    if lit_by_value(args) && !args.style.species_colour.is_empty() {
        anyhow::bail!(
            "--species-colour has no effect on splats lit by the attribute: their light has \
             no species colour (--intensity species draws the species' colours)"
        );
    }
    if lit_by_value(args)
        && args.style.colour_map.is_none()
        && (args.legend.is_some() || args.legend_in_image.is_some())
    {
        anyhow::bail!(
            "{}: splats lit by the attribute without --colour-map are white light, tone \
             mapped by each image's exposure, which no legend can read values from; add \
             --colour-map (grey keeps it white) to map the projected attribute through a \
             scale the legend shows",
            if args.legend.is_some() {
                "--legend"
            } else {
                "--legend-in-image"
            }
        );
    }
    if projected(args) {
        if args.exposure.is_some() {
            anyhow::bail!(
                "--exposure has no effect with --mode splat --colour-map: the map spans the \
                 image's light; --light-range MIN:MAX sets its ends"
            );
        }
        if let Some([lo, _]) = args
            .light_range
            .filter(|[lo, _]| args.style.log_scale && *lo <= 0.0)
        {
            anyhow::bail!("--light-range {lo}:..: on a log scale the light's range starts above 0");
        }
        if args.style.attribute_range.is_some() && !by_attribute(args) {
            anyhow::bail!(
                "--attribute-range has no effect on a projection of species light: the map \
                 spans the projected light, whose ends --light-range MIN:MAX sets \
                 (--intensity attribute projects the attribute, over --attribute-range)"
            );
        }
    } else if args.light_range.is_some() {
        anyhow::bail!(
            "--light-range sets the ends of a projection's colour map: it needs --mode splat \
             and --colour-map"
        );
    }
    for (given, name) in [
        (args.style.attribute_range.is_some(), "--attribute-range"),
        (
            args.style.log_scale && !projected(args) && args.mode != Mode::Density,
            "--log-scale",
        ),
    ] {
        if given && !by_attribute(args) {
            let density = match name {
                "--log-scale" => {
                    "; with --mode density and no colour map it takes the volume \
                     fraction's logarithm"
                }
                _ => "",
            };
            anyhow::bail!(
                "{name} has no effect without --colour-map (spheres, sndf, splat, density, iso) or \
                 --intensity attribute (splat){density}"
            );
        }
    }
    // --attribute chooses what those read, and --hide-attribute reads it too.
    // (--hide-by takes --hide-attribute's reading from it.)
    if args.style.attribute.is_some()
        && !by_attribute(args)
        && (!args.style.hide_attribute.iter().any(|h| h.by.is_none())
            || args.style.hide_by.is_some())
    {
        anyhow::bail!(
            "--attribute has no effect without --colour-map (spheres, sndf, splat, density, iso), \
             --intensity attribute (splat) or --hide-attribute MIN:MAX: it chooses which \
             attribute they read (a range NAME=MIN:MAX reads NAME itself)"
        );
    }
    if args.scale_bar_length.is_some() && !args.scale_bar {
        anyhow::bail!("--scale-bar-length has no effect without --scale-bar");
    }
    if args.scale_bar_corner.is_some() && !args.scale_bar {
        anyhow::bail!("--scale-bar-corner has no effect without --scale-bar");
    }
    if args.axes_corner.is_some() && !args.axes {
        anyhow::bail!("--axes-corner has no effect without --axes");
    }
    if args.axes {
        let taken = [
            (!args.label.is_empty()).then_some((args.label_corner(), "--label")),
            args.legend_in_image.map(|c| (c, "--legend-in-image")),
            args.scale_bar
                .then_some((args.scale_bar_corner(), "--scale-bar")),
        ];
        if let Some((_, other)) = taken
            .into_iter()
            .flatten()
            .find(|(c, _)| *c == args.axes_corner())
        {
            anyhow::bail!(
                "--axes and {other} both draw at the {} corner: give --axes-corner another",
                corner_name(args.axes_corner())
            );
        }
    }
    if args.label.iter().any(|l| l.trim().is_empty()) {
        anyhow::bail!("--label \"\": an empty label draws an empty panel; give its text");
    }
    if args.label_corner.is_some() && args.label.is_empty() {
        anyhow::bail!("--label-corner has no effect without --label");
    }
    if args.scale_bar {
        let taken = [
            (!args.label.is_empty()).then_some((args.label_corner(), "--label")),
            args.legend_in_image.map(|c| (c, "--legend-in-image")),
        ];
        if let Some((_, other)) = taken
            .into_iter()
            .flatten()
            .find(|(c, _)| *c == args.scale_bar_corner())
        {
            anyhow::bail!(
                "--scale-bar and {other} both draw at the {} corner: give \
                 --scale-bar-corner another",
                clap::ValueEnum::to_possible_value(&args.scale_bar_corner())
                    .map_or_else(String::new, |v| v.get_name().to_string())
            );
        }
    }
    // --dt gives the time {time} shows.
    let shows_time = args.label.iter().any(|l| {
        label::parts(l)
            .unwrap_or_default()
            .iter()
            .any(|p| matches!(p, label::Part::Field("time", _)))
    });
    // (A label that does not parse is refused as such, naming its fault, further on.)
    let parsed = args.label.iter().all(|l| label::parts(l).is_ok());
    if args.dt.is_some() && !args.label.is_empty() && !shows_time && parsed {
        anyhow::bail!(
            "--dt has no effect without {{time}} in a --label: it gives the time {{time}} shows"
        );
    }
    for (id, modes) in MODE_OPTIONS {
        let given = matches!(
            matches.value_source(id),
            Some(clap::parser::ValueSource::CommandLine)
        );
        if given && !modes.contains(&args.mode) {
            let names: Vec<String> = modes.iter().map(|&m| mode_name(m)).collect();
            anyhow::bail!(
                "--{} has no effect with --mode {}: it applies to --mode {}",
                id.replace('_', "-"),
                mode_name(args.mode),
                names.join(" or ")
            );
        }
    }
    // Additive splats add their light to the background: on white (a print figure's)
    // every pixel is white already, and the image would be blank.
    let white = parse_colour(background_text(args)).is_ok_and(|c| c.iter().all(|&v| v >= 0.999));
    if args.mode == Mode::Splat && args.style.colour_map.is_none() && white {
        anyhow::bail!(
            "--mode splat adds the splats' light to the background, and on white nothing \
             can show: give a dark --background, --colour-map (which colours the light over \
             any background), or --mode splat-over (splats blended over it)"
        );
    }
    Ok(())
}

/// Parses a point budget: a count of spheres, at least 1 (a budget of 0 would draw
/// nothing; the traversal always draws at least the top node).
pub fn parse_budget(s: &str) -> Result<u64, String> {
    const ZERO: &str = "0 spheres draw nothing: the budget is at least 1 (1 draws the whole \
                        data set as one sphere)";
    match super::whole_number(s)? {
        0 => Err(ZERO.into()),
        n => Ok(n),
    }
}

/// Parses `nx,ny,nz,d` as OVITO's Slice reads it: the plane at distance `d` from the
/// origin along the unit normal `n/|n|` (so `1,1,0,d` and `2,2,0,d` are one plane); the
/// result's normal is unit. A zero normal is left for the plane's check to refuse.
fn parse_plane(s: &str) -> Result<[f32; 4], String> {
    let [x, y, z, d] = parse_numbers::<f64, 4>(s, "nx,ny,nz,d")?;
    // In double precision, scaled first: a normal of 1e-38 or 3e38 is one direction too.
    let m = x.abs().max(y.abs()).max(z.abs());
    if !(m.is_finite() && m > 0.0 && d.is_finite()) {
        return Err(format!(
            "{s:?}: a plane needs finite numbers and a normal nx,ny,nz that is not zero"
        ));
    }
    let n = mdlod_render::glam::DVec3::new(x / m, y / m, z / m).normalize();
    if d.abs() > f64::from(f32::MAX) {
        return Err(format!("{s:?}: the distance d is beyond single precision"));
    }
    Ok([n.x as f32, n.y as f32, n.z as f32, d as f32])
}

/// The S-NDF binnings.
#[derive(Clone, Copy, Debug, clap::ValueEnum)]
pub enum BinningArg {
    /// Projected normals (n.x, n.y) on the unit disk.
    Projected,
    /// Spherical coordinates: azimuth and polar angle.
    Spherical,
    /// Lambert azimuthal equal-area.
    Lambert,
}

impl BinningArg {
    pub fn binning(self) -> mdlod_render::sndf::Binning {
        use mdlod_render::sndf::Binning;
        match self {
            BinningArg::Projected => Binning::ProjectedNormals,
            BinningArg::Spherical => Binning::Spherical,
            BinningArg::Lambert => Binning::LambertEqualArea,
        }
    }
}

#[derive(Clone, Copy, Debug, clap::ValueEnum)]
pub enum SortArg {
    Clusters,
    Points,
}

#[derive(Clone, Copy, Debug, clap::ValueEnum)]
pub enum Intensity {
    Species,
    Attribute,
}

/// Parses `512M`, `2G`, `1048576`, `64KiB`; a size below one byte (0) is refused: no
/// memory limit or pool can be empty.
pub fn parse_bytes(s: &str) -> Result<u64, String> {
    let bytes = size_in_bytes(s)? as u64;
    if bytes == 0 {
        return Err(format!("{s:?} leaves no room: give a size such as 512M"));
    }
    Ok(bytes)
}

/// The bytes a size such as `512M` names, exactly (before rounding down to whole
/// bytes), below 2^64.
fn size_in_bytes(s: &str) -> Result<f64, String> {
    let t = s.trim();
    let split = t
        .find(|c: char| !(c.is_ascii_digit() || c == '.'))
        .unwrap_or(t.len());
    let (num, unit) = t.split_at(split);
    let v: f64 = num
        .parse()
        .map_err(|_| format!("{s:?} is not a size such as 512M"))?;
    let mult = match unit.trim().to_ascii_uppercase().as_str() {
        "" | "B" => 1u64,
        "K" | "KB" | "KIB" => 1 << 10,
        "M" | "MB" | "MIB" => 1 << 20,
        "G" | "GB" | "GIB" => 1 << 30,
        "T" | "TB" | "TIB" => 1 << 40,
        // `4e9`: an exponent, not a unit.
        u if u.starts_with('E')
            && u.len() > 1
            && u[1..]
                .trim_start_matches(['+', '-'])
                .chars()
                .all(|c| c.is_ascii_digit()) =>
        {
            return Err(format!(
                "{s:?}: give a size with a unit (K, M, G or T: 4G), not an exponent"
            ))
        }
        _ => return Err(format!("unknown unit in {s:?} (use K, M, G or T)")),
    };
    let exact = v * mult as f64;
    // (A float's cast saturates: 2^64 and beyond would read as 16 EiB.)
    if exact.is_nan() || exact >= u64::MAX as f64 {
        return Err(format!("{s:?} is beyond any memory (at most 16 EiB)"));
    }
    Ok(exact)
}

/// The most radii `--kernel-scale` reaches: SPH codes' conventions take 1 or 2, and a
/// kernel 10^10 radii wide drew every particle over the whole image for minutes, black.
pub const MAX_KERNEL_SCALE: f32 = 100.0;

/// `--kernel-scale`: a finite number of radii above 0, at most [`MAX_KERNEL_SCALE`].
fn parse_kernel_scale(s: &str) -> Result<f32, String> {
    match s.trim().parse::<f32>() {
        Ok(v) if v > 0.0 && v <= MAX_KERNEL_SCALE => Ok(v),
        _ => Err(format!(
            "{s:?}: radii above 0, at most {MAX_KERNEL_SCALE} (an SPH kernel's support is 1 \
             or 2 smoothing lengths)"
        )),
    }
}

/// [`parse_bytes`] that takes `0` too (the viewer's `--gpu-memory 0`: no pool, each
/// frame's cut uploaded).
pub fn parse_bytes_or_zero(s: &str) -> Result<u64, String> {
    if size_in_bytes(s)? == 0.0 {
        return Ok(0);
    }
    parse_bytes(s)
}

/// A resolution in dots per inch: above 0, and at most 100 000 (a PNG keeps pixels per
/// metre in 32 bits).
fn parse_dpi(s: &str) -> Result<f32, String> {
    match s.trim().parse::<f32>() {
        Ok(d) if d.is_finite() && d > 0.0 && d <= 100_000.0 => Ok(d),
        Ok(_) => Err(format!(
            "{s:?}: a resolution above 0 and at most 100000 dpi"
        )),
        Err(_) => Err(format!("{s:?} is not a number of dots per inch, e.g. 300")),
    }
}

pub fn run(mut args: Args) -> Result<()> {
    mdlod_render::image::set_png_dpi(args.dpi);
    if args.json {
        crate::json_output();
    }
    // A batch's dataset.json renders as its directory.
    args.file = super::batch_dir_of(args.file);
    // `--cell red frame.mdlod`: the colour takes `=`, so `red` was read as the file.
    let named = args.file.to_string_lossy();
    if args.cell.as_deref() == Some("auto") && !args.file.exists() && parse_colour(&named).is_ok() {
        anyhow::bail!(
            "{named}: no such file; is it --cell's colour? A colour goes with `=`: --cell={named}"
        );
    }
    args.camera.note_unknown_fields();
    let inputs = args.camera.inputs(&args.file);
    super::check_output("-o", &args.output, &inputs)?;
    super::check_png_name("-o", &args.output)?;
    let single = !args.file.is_dir() && args.turntable.is_none();
    if args.frames.is_some() && !args.file.is_dir() {
        anyhow::bail!(
            "--frames picks frames of a batch directory; {} is one file",
            args.file.display()
        );
    }
    if single && frame_output(&args.output, 0).is_ok() {
        anyhow::bail!(
            "-o {}: a name numbered for a series, but {} is one file and renders one image: \
             give a plain name, or --turntable N for numbered views (a batch directory \
             renders one image per frame)",
            args.output.display(),
            args.file.display()
        );
    }
    if let Some(p) = &args.save_map {
        if !matches!(args.mode, Mode::Splat) {
            anyhow::bail!(
                "--save-map writes the light of additive splats: give --mode splat (the \
                 other modes' pixels are colours, not amounts)"
            );
        }
        if !single {
            anyhow::bail!(
                "--save-map writes one still's map, not a movie's or a turntable's: render \
                 the frame wanted alone"
            );
        }
        check_side_output("--save-map", "the map", p, &args.output, &inputs, single)?;
        if !p.extension().is_some_and(|e| e.eq_ignore_ascii_case("npy")) {
            anyhow::bail!(
                "--save-map {}: the map is a NumPy array: name it .npy",
                p.display()
            );
        }
    }
    if let Some(p) = &args.save_view {
        check_side_output(
            "--save-view",
            "the view file",
            p,
            &args.output,
            &inputs,
            single,
        )?;
    }
    check_label(&args)?;
    legend_categories(&args)?;
    if args.mode == Mode::Density
        && args.style.log_scale
        && args.density_min.is_none()
        && density_min(&args) < f32::MIN_POSITIVE
    {
        anyhow::bail!(
            "--density-max {}: four decades below it (a log scale's default bottom) is below \
             single precision; give --density-min",
            args.density_max
        );
    }
    let mapped_spheres =
        matches!(args.mode, Mode::Spheres | Mode::Sndf) && args.style.colour_map.is_some();
    if !args.legend_category.is_empty() && !mapped_spheres {
        anyhow::bail!(
            "--legend-category names the colours --colour-map gives values: it needs \
             --colour-map, with --mode spheres or sndf"
        );
    }
    if !args.legend_category.is_empty() && args.legend.is_none() && args.legend_in_image.is_none() {
        anyhow::bail!(
            "--legend-category makes a legend's key: give --legend FILE.svg or --legend-in-image"
        );
    }
    if args.legend_title.is_some() && args.legend.is_none() && args.legend_in_image.is_none() {
        anyhow::bail!(
            "--legend-title titles a legend: give --legend FILE.svg or --legend-in-image"
        );
    }
    if let Some(unit) = &args.scale_bar_unit {
        if !args.scale_bar {
            anyhow::bail!("--scale-bar-unit names the scale bar's unit: give --scale-bar");
        }
        if length_unit(Some(unit)).is_empty() {
            anyhow::bail!(
                "--scale-bar-unit {unit:?}: a unit of at most 12 characters the image's font \
                 draws (Å, nm, σ, µm, Mpc/h)"
            );
        }
    }
    if args.text_scale.is_some()
        && args.legend_in_image.is_none()
        && args.label.is_empty()
        && !args.scale_bar
        && !args.axes
    {
        anyhow::bail!(
            "--text-scale sizes the panels drawn into the image: give --legend-in-image, \
             --label, --scale-bar or --axes"
        );
    }
    if let Some(p) = &args.legend {
        super::check_output("--legend", p, &inputs)?;
        super::check_writable_beside("--legend", p)?;
        // One legend for a movie's or turntable's images, not one per image.
        if p.file_name()
            .is_some_and(|n| n.to_string_lossy().contains('%'))
        {
            anyhow::bail!(
                "--legend {}: the legend is one file, for every image a movie or turntable \
                 writes (a name without %)",
                p.display()
            );
        }
        // As for -o: a single image's legend goes into a directory that exists.
        if let Some(dir) = p.parent().filter(|d| single && !d.as_os_str().is_empty()) {
            if !dir.is_dir() {
                anyhow::bail!(
                    "--legend {}: the directory {} does not exist",
                    p.display(),
                    dir.display()
                );
            }
        }
        if !p.extension().is_some_and(|e| e.eq_ignore_ascii_case("svg")) {
            anyhow::bail!(
                "--legend {}: the legend is written as SVG: name it .svg",
                p.display()
            );
        }
    }
    let view = args.camera.spec();
    if args.fit_all && !view_fits(&view) {
        anyhow::bail!(
            "--fit-all has no effect with --view {}: the view file gives the target and the \
             distance, so nothing is fitted (leave them out of the file to fit the data)",
            args.camera
                .view
                .as_deref()
                .unwrap_or(Path::new(""))
                .display()
        );
    }
    let mut opts = RenderOptions {
        width: args.camera.width,
        height: args.camera.height,
        view,
        spp: args.spp,
        error_px: args.screen_error,
        budget: args.budget,
        lighting: lighting(&args)?,
        transparent: transparent(args.background.as_deref()),
        background: parse_colour(background_text(&args)).context("--background")?,
        mode: match args.mode {
            Mode::Spheres => RenderMode::Spheres,
            Mode::Splat => RenderMode::Splat {
                by_attribute: matches!(args.intensity, Intensity::Attribute),
            },
            Mode::SplatOver => RenderMode::SplatOver {
                opacity: args.opacity,
                order: match args.sort {
                    SortArg::Clusters => mdlod_render::DepthOrder::Clusters,
                    SortArg::Points => mdlod_render::DepthOrder::Points,
                },
            },
            Mode::Sndf => RenderMode::Sndf {
                iterations: args.iterations,
                bins: args.bins,
                binning: args.binning.binning(),
            },
            Mode::Density | Mode::Iso => {
                RenderMode::Density(mdlod_render::density::DensitySettings {
                    iso: matches!(args.mode, Mode::Iso).then_some(args.iso_value),
                    slices: args.slices,
                    kernel_scale: args.kernel_scale.unwrap_or(2.5),
                    density_max: args.density_max,
                    density_min: density_min(&args),
                    // (In iso mode --log-scale is the colour map's.)
                    log: args.style.log_scale && matches!(args.mode, Mode::Density),
                    opacity: args.absorption,
                    colour_map: args.style.colour_map.map(ColourMapArg::map),
                    clip: match args.style.clip[..] {
                        [] => None,
                        [plane] => Some(plane),
                        _ => anyhow::bail!(
                            "--mode {} takes one --clip plane ({} given): the volume's \
                             samples are clipped by one plane",
                            mode_name(args.mode),
                            args.style.clip.len()
                        ),
                    },
                })
            }
        },
        exposure: args.exposure,
        light_range: args.light_range,
        gpu_memory: args.gpu_memory,
        splat_support: args
            .kernel_scale
            .filter(|_| matches!(args.mode, Mode::Splat | Mode::SplatOver))
            .unwrap_or(mdlod_render::passes::splat::DEFAULT_SUPPORT),
        occlusion: !args.no_occlusion,
        style: {
            let mut style = args.style.style()?;
            // The volume modes clip their samples (DensitySettings::clip), not the points,
            // and density mode's log scale is its transfer function's, not an attribute's
            // (the iso-surface's is its colour map's).
            if matches!(args.mode, Mode::Density | Mode::Iso) {
                style.clip.clear();
            }
            if args.mode == Mode::Density {
                style.log_scale = false;
            }
            style
        },
        fit_all: args.fit_all,
        // The legend's key lists the species the picture shows.
        species_drawn: args.legend.is_some() || args.legend_in_image.is_some(),
        keep_light_map: args.save_map.is_some(),
        ..Default::default()
    };
    if let Some(colour) = &args.cell {
        let srgb = match colour.as_str() {
            // Contrast with the background (a transparent one is laid over anything).
            "auto" => {
                let [r, g, b] = opts.background;
                let light = 0.2126 * r + 0.7152 * g + 0.0722 * b > 0.5 || opts.transparent;
                if light {
                    [0.2; 3]
                } else {
                    [0.8; 3]
                }
            }
            c => parse_colour(c).with_context(|| format!("--cell {c:?}"))?,
        };
        opts.cell = Some(mdlod_render::CellLines {
            colour: srgb.map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8),
            width_px: match args.cell_width {
                Some(w) if w.is_finite() && w > 0.0 && w <= 256.0 => w,
                Some(w) => {
                    anyhow::bail!("--cell-width {w}: a width of more than 0 and at most 256 pixels")
                }
                None => (args.camera.width.min(args.camera.height) as f32 / 360.0).max(1.5),
            },
        });
    }
    let (legend_room, legend_size) = check_legend_room(&args, &opts)?;
    let windows = scale_bar_room(&args, &opts, legend_room);
    let windows = axes_room(&args, &opts, windows);
    opts.fit_windows = label_room(&args, &opts, windows);
    if args.file.is_dir() {
        if args.turntable.is_some() {
            anyhow::bail!(
                "--turntable spins one file; {} is a batch directory (render one of its \
                 frame files, e.g. {})",
                args.file.display(),
                mdlod_preprocess::batch::read_manifest(&args.file)
                    .ok()
                    .and_then(|m| m.frames.first().map(|f| args.file.join(&f.file)))
                    .unwrap_or_else(|| args.file.join("frame-<timestep>.mdlod"))
                    .display()
            );
        }
        render_frames(&args, opts, legend_size)?;
        series_json(&args);
        return Ok(());
    }
    drop_absent_categories(&args.file, &mut opts.style)?;
    // (A projection's log is the image's, not the points'.)
    let derived = derive_range(
        &mut opts.style,
        &args.file,
        by_attribute(&args) && !projected(&args),
        lit_linearly(&args),
    )?;
    let mut label_size = None;
    let (bar, axes) = if args.label.is_empty() && !args.scale_bar && !args.axes {
        (None, None)
    } else {
        // (A turntable's images share the file's values but the frame number.)
        let file = mdlod_render::open_styled(&args.file, &opts.style)?;
        let images = args.turntable.unwrap_or(1).max(1) as usize;
        let values: Vec<label::Values> = (0..images)
            .map(|i| label::Values::of_file(&args.file, file.metadata(), i))
            .collect();
        label_size = check_label_room(&args, &values.iter().collect::<Vec<_>>())?;
        // The scale bar and axes of the view drawn, refused before drawing where they
        // cannot be.
        let camera = match args.scale_bar || args.axes {
            true => Some(mdlod_render::frame_setup(&file, &opts)?.0),
            false => None,
        };
        let bar = match (args.scale_bar, &camera) {
            (true, Some(camera)) => Some(scale_bar(
                camera,
                opts.width,
                opts.height,
                args.scale_bar_length,
                args.scale_bar_unit
                    .as_deref()
                    .or(file.metadata().units.as_deref()),
                args.text_scale,
            )?),
            _ => None,
        };
        (bar, camera.filter(|_| args.axes).as_ref().map(axes_panel))
    };
    check_panels_apart(&args, legend_size, label_size, bar.as_ref(), axes.as_ref())?;
    if let Some(n) = args.turntable {
        render_turntable(&args, opts, n, derived)?;
        series_json(&args);
        return Ok(());
    }
    // A bar for the choice of the cut and for cuts drawn in several batches or samples
    // (every particle of 10^8 is nine batches).
    let r = render_to_png_with(&args.file, &args.output, &opts, Bar::for_renderer())?;
    // The S-NDF mode reports its iterations as spp (--spp is refused there).
    // Spheres and S-NDFs sample pixels; splats and the volume draw each point once.
    let samples = match args.mode {
        Mode::Sndf => format!(", {} rays per pixel", r.spp),
        Mode::Spheres => format!(", {} spp", r.spp),
        Mode::Splat | Mode::SplatOver | Mode::Density | Mode::Iso => String::new(),
    };
    // The file again (a mapping, and its metadata) for what the summary explains.
    let file = mdlod_render::open_styled(&args.file, &opts.style)?;
    let species = &file.metadata().species;
    let points = point_noun(args.mode);
    let hidden = hidden_text(&r, &args.style);
    let limits = limits_text(&r, coarsest_points(&file), args.budget);
    let occluded = if r.nodes_occluded + r.particles_occluded > 0 {
        format!(
            " ({} clusters and {} particles left out behind nearer spheres or between pixel centres)",
            r.nodes_occluded, r.particles_occluded
        )
    } else {
        String::new()
    };
    println!(
        "wrote {} ({}x{}{samples}) on {} ({}): {} particle{}{hidden} and {} {} in {} draw range{}{occluded}, error {:.2} px{limits}",
        args.output.display(),
        r.width,
        r.height,
        r.adapter,
        r.backend,
        r.particles_drawn,
        if r.particles_drawn == 1 { "" } else { "s" },
        r.nodes_drawn,
        counted(points, r.nodes_drawn),
        r.ranges,
        if r.ranges == 1 { "" } else { "s" },
        r.error_px,
    );
    if let Some(n) = sndf_of_clusters_note(args.mode, &r) {
        println!("{n}");
    }
    // What the colours (or splat intensities) mean: a picture's legend.
    if by_attribute(&args) {
        if let Some(a) = &file.metadata().attribute {
            let ([lo, hi], whose) = match (opts.style.attribute_range, &derived) {
                (Some(range), Some(why)) => {
                    (range, format!("{why}; --attribute-range sets another"))
                }
                (Some(range), None) => (range, "--attribute-range".to_string()),
                (None, _) => ([a.min, a.max], "the file's range".to_string()),
            };
            let shown = match args.style.colour_map.filter(|_| args.mode != Mode::Splat) {
                Some(m) => {
                    use clap::ValueEnum;
                    let name = m.to_possible_value().map(|v| v.get_name().to_string());
                    format!("colour map {}", name.unwrap_or_default())
                }
                None => "splat intensity".to_string(),
            };
            println!(
                "  {shown}: {} from {} to {} ({whose}){}",
                a.name,
                Num(lo),
                Num(hi),
                log_text(a, &opts.style, &args) + &white_text(&opts.style)
            );
            // A diverging map on a log scale has no 0 to centre on: the values of both
            // signs it is meant for lose their negative half to its first colour.
            if matches!(args.style.colour_map, Some(ColourMapArg::CoolWarm))
                && opts.style.log_scale
                && a.min < 0.0
                && log_applies(a, &opts.style)
            {
                println!(
                    "  note: cool-warm is a diverging map, centred on 0, but --log-scale has no \
                     0 nor negative values: {}'s values at or below 0 all take its first colour \
                     (leave out --log-scale for a scale about 0)",
                    a.name
                );
            }
            // A diverging map centred on 0 over values of one sign uses half of itself.
            let drawn = [a.min, a.max];
            if matches!(args.style.colour_map, Some(ColourMapArg::CoolWarm))
                && args.mode != Mode::Splat
                && lo < 0.0
                && hi > 0.0
                && (drawn[1] <= 0.0 || drawn[0] >= 0.0)
            {
                println!(
                    "  note: cool-warm is a diverging map, centred on 0, and {} is {} \
                     everywhere: its values take one half of the map; viridis or magma \
                     spread them over a whole one",
                    a.name,
                    if drawn[1] <= 0.0 {
                        "at or below 0"
                    } else {
                        "at or above 0"
                    }
                );
            }
            if lo >= hi {
                // Splats lit by a constant all give the same light; a colour map over the
                // particles gives them its last colour.
                let fate = match args.mode {
                    Mode::Splat if lo > 0.0 => {
                        "every splat is lit alike (its light the value times its disk's area)"
                    }
                    Mode::Splat => "every splat is lit alike (its light its disk's area)",
                    _ => {
                        "every particle takes the map's last colour, which means nothing on its own"
                    }
                };
                // A logarithm's quantity said beside it (`log10(m)` of 0.5486: m = 3.54).
                let quantity = a
                    .name
                    .strip_prefix("log10(")
                    .and_then(|s| s.strip_suffix(')'))
                    .map(|inner| format!(", {inner} = {}", Num(10f64.powf(f64::from(lo)) as f32)))
                    .unwrap_or_default();
                println!(
                    "  note: {} is constant in this file ({}{quantity}): {fate}; \
                     --attribute-range places the value on a scale (the range of the frames it \
                     is compared with)",
                    a.name,
                    Num(lo)
                );
            }
            // (Of the particles drawn: values below 0 all hidden or cut away say nothing.)
            let lowest = || match opts.style.leaves_some_out() {
                true => mdlod_render::shown_attribute_range(&file, &opts.style)
                    .map_or(a.min, |[lo, _]| lo),
                false => a.min,
            };
            let below = (opts.style.log_scale
                && !projected(&args)
                && a.min < 0.0
                && log_applies(a, &opts.style))
            .then(lowest)
            .filter(|lo| *lo < 0.0);
            if let Some(lo) = below {
                let fate = if args.mode == Mode::Splat {
                    "give no light"
                } else {
                    "take the map's first colour"
                };
                println!(
                    "  note: {} takes values below 0 (down to {}): on a log scale they {fate}; \
                     a log scale suits quantities above 0 (cool-warm without it centres a \
                     signed one on 0)",
                    a.name, lo
                );
            }
            if let Some([lo, hi]) = opts.style.attribute_range {
                if hi < a.min || lo > a.max {
                    println!(
                        "  note: the range {} to {} misses the file's values ({} from {} to \
                         {}): every particle takes one end of the map",
                        Num(lo),
                        Num(hi),
                        a.name,
                        Num(a.min),
                        Num(a.max)
                    );
                }
            }
        }
    }
    let every_species_hidden = species
        .iter()
        .all(|s| args.style.hide_species.contains(&s.name));
    if every_species_hidden {
        println!("  note: every species is hidden: the image shows the background only");
    }
    for note in hides_nothing_notes(&opts.style, &file) {
        println!("{note}");
    }
    // Spheres of sizes spanning decades (an SPH run's smoothing lengths): the largest
    // cover the rest, which a projection or the density shows.
    let lit_by_area = matches!(args.mode, Mode::Splat | Mode::SplatOver)
        && !matches!(args.intensity, Intensity::Attribute);
    if let Some(rad) = file
        .metadata()
        .radius
        .filter(|r| r.min > 0.0 && r.max / r.min >= 100.0)
    {
        let span = format!(
            "the particles' own sizes span {} to {} ({:.0}×)",
            three_digits(rad.min),
            three_digits(rad.max),
            rad.max / rad.min
        );
        // (A projection of mass: each splat's light m, spread over its disk.)
        let projection = "--mode splat --intensity attribute with a column of m / (π h²) \
                          (the column density)";
        match args.mode {
            Mode::Spheres | Mode::Sndf => println!(
                "  note: {span}: as spheres, the largest cover the rest; smoothing lengths \
                 (SPH) are better projected, {projection}, or drawn as a density, --mode \
                 density"
            ),
            _ if lit_by_area => println!(
                "  note: {span}: splats lit by their disks' area (π r²) let the largest \
                 outshine the rest by as much squared; smoothing lengths (SPH) project their \
                 mass with {projection}"
            ),
            // The volume fraction counts each particle's volume against the largest's.
            Mode::Density | Mode::Iso => println!(
                "  note: {span}: the volume fraction φ is each particle's sphere against \
                 spheres of the largest radius, so crowds of small ones reach far above \
                 --density-max (one colour) and the large ones' sparse space far below its \
                 bottom (clear); with --log-scale, a --density-min and --density-max decades \
                 apart show both, and a projection, {projection}, shows a column density"
            ),
            _ => {}
        }
    }
    for note in coarse_range_notes(&opts.style, &file) {
        println!("{note}");
    }
    if let Some(note) = file
        .metadata()
        .attribute
        .as_ref()
        .filter(|_| lit_by_value(&args))
        .and_then(decades_light_note)
    {
        println!("{note}");
    }
    let drawn = mdlod_render::drawn_bounds(&file, &opts);
    if let Some(note) =
        periodic_kernels_note(args.mode, file.metadata().simulation_box.as_ref(), drawn)
    {
        println!("{note}");
    }
    if view_fits(&opts.view) {
        if let Some(note) = far_note(mdlod_render::fit_for(&file, &opts).far_particles, None) {
            println!("{note}");
        }
    }
    if r.nodes_drawn > 0 {
        if matches!(args.mode, Mode::Spheres | Mode::Sndf) {
            let miss = opts.style.recolour_miss(species);
            if let Some(note) = recolour_note(miss, species.len()) {
                println!("{note}");
            }
        }
        // What stopped the refinement: the point budget, or a full streaming pool.
        let stopped = |pronoun: &str| match (r.budget_limited, r.pool_limited) {
            (false, true) => format!(
                "the GPU memory pool, full, stopped refining {pronoun}; a larger --gpu-memory \
                 refines {pronoun}"
            ),
            (true, true) => format!(
                "the point budget and the full GPU memory pool stopped refining {pronoun}; a \
                 larger --budget and --gpu-memory refine {pronoun}"
            ),
            _ => format!(
                "the point budget stopped refining {pronoun}; a larger --budget refines \
                 {pronoun}"
            ),
        };
        if r.clusters_mixed > 0 {
            let (s, verb, pronoun) = match r.clusters_mixed {
                1 => ("", "s", "it"),
                _ => ("s", "", "them"),
            };
            println!(
                "  note: {} {}{s} still hold{verb} hidden species or values: {}",
                r.clusters_mixed,
                point_noun(args.mode).trim_end_matches('s'),
                stopped(pronoun)
            );
        }
        if opts.style.hides_past_the_mask(species) {
            println!(
                "  note: clusters still hold the hidden species (only the first 64 species \
                 can be left out of clusters, and occlusion culling is off for the others), \
                 and their particles, drawn at radius 0, count among those drawn; \
                 --screen-error 0 draws particles only, and --hide-attribute over a column \
                 of their ids leaves them out as the first 64 are"
            );
        }
        if r.clusters_across > 0 {
            let (s, is, pronoun) = match r.clusters_across {
                1 => ("", "is", "it"),
                _ => ("s", "are", "them"),
            };
            println!(
                "  note: {} {}{s} across a --clip plane {is} drawn whole: {}",
                r.clusters_across,
                point_noun(args.mode).trim_end_matches('s'),
                stopped(pronoun)
            );
        }
    }
    // Whether a note has said the image is empty (and why).
    let mut said_empty = false;
    if r.particles_drawn + r.nodes_drawn == 0 && !every_species_hidden {
        said_empty = true;
        // Data far smaller than its distance from the origin: the view's single-precision
        // arithmetic cannot place it (grains of a millimetre at UTM coordinates).
        let b = mdlod_render::data_bounds(&file);
        let (span, far) = (
            (b.max - b.min).max_element(),
            b.min.abs().max(b.max.abs()).max_element(),
        );
        let unplaced = format!(
            "the data spans {:.3e} at {:.3e} from the origin, finer than single precision (in which \
             the view is worked out) resolves there: shift the data near the origin \
             (subtract its centre) before converting",
            span,
            far
        );
        // Where the data lies along each plane's normal, to set `d` from (a slab's
        // coordinates from a larger data set of the same kind cut a smaller one away).
        let spans: Vec<String> = opts
            .style
            .clip
            .iter()
            .map(|&[nx, ny, nz, d]| {
                let n = mdlod_render::glam::Vec3::new(nx, ny, nz);
                let (lo, hi) = (0..8).fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), k| {
                    let corner = mdlod_render::glam::Vec3::new(
                        if k & 1 == 0 { b.min.x } else { b.max.x },
                        if k & 2 == 0 { b.min.y } else { b.max.y },
                        if k & 4 == 0 { b.min.z } else { b.max.z },
                    );
                    let v = n.dot(corner);
                    (lo.min(v), hi.max(v))
                });
                format!(
                    "n·p of the data runs from {} to {} for the plane {},{},{},{}",
                    super::Num(lo),
                    super::Num(hi),
                    super::Num(nx),
                    super::Num(ny),
                    super::Num(nz),
                    super::Num(d)
                )
            })
            .collect();
        let cut_all = format!("{CLIP_CUTS_ALL}; {}", spans.join("; "));
        let why = match (
            opts.style.clip.is_empty(),
            r.nodes_occluded + r.particles_occluded,
        ) {
            _ if span < far * 1e-5 => unplaced.as_str(),
            // Every sphere in view fell between pixel centres.
            (true, n) if n > 0 => {
                "every sphere in view is narrower than the pixels and falls between their \
                 centres (atoms far away fitted with --fit-all shrink the rest to a dot?): \
                 --zoom, --radius-scale or a larger image shows them"
            }
            (true, _) if !args.style.hide_attribute.is_empty() => {
                "every particle in view has a value --hide-attribute hides (or the view \
                 looks elsewhere)"
            }
            (true, _) => {
                "none of the data is in view (a --target, --zoom or view file that looks \
                     elsewhere?)"
            }
            // (A slab may keep particles of the hidden species only.)
            (false, _)
                if !args.style.hide_species.is_empty() || !args.style.hide_attribute.is_empty() =>
            {
                "the --clip planes keep no particle that is not hidden (--hide-species, \
                 --hide-attribute), or cut every particle away (each keeps n·p ≤ d, d the \
                 distance from the origin along the unit normal: check its sign)"
            }
            (false, _) => cut_all.as_str(),
        };
        println!("  note: nothing is drawn: {why}");
    } else if let (Mode::Density | Mode::Iso, [[nx, ny, nz, d]]) = (args.mode, &args.style.clip[..])
    {
        // The volume keeps the samples with n·p ≤ d: none where every corner of the data's
        // box lies beyond the plane.
        let b = mdlod_render::data_bounds(&file);
        let nearest: f32 = [
            (nx, b.min.x, b.max.x),
            (ny, b.min.y, b.max.y),
            (nz, b.min.z, b.max.z),
        ]
        .iter()
        .map(|&(n, lo, hi)| (n * lo).min(n * hi))
        .sum();
        if nearest > *d {
            said_empty = true;
            println!(
                "  note: nothing is drawn: the --clip plane cuts away every sample of the \
                 volume (it keeps n·p ≤ d, d the distance from the origin along the unit \
                 normal: check its sign)"
            );
        }
    } else if let Some(note) =
        clip_side_note(&opts.style.clip, &r.camera).filter(|_| r.particles_clipped > 0)
    {
        println!("{note}");
    }
    // Spheres all narrower than a pixel (a chain a thousand atoms long across the image)
    // can miss every pixel centre: an empty image with nothing said. (The image is read
    // back only then.)
    if matches!(args.mode, Mode::Spheres | Mode::Sndf)
        && !said_empty
        && r.particles_drawn + r.nodes_drawn > 0
    {
        let c = &r.camera;
        let depth = (c.distance - mdlod_render::data_bounds(&file).radius()).max(c.near);
        let across = 2.0
            * file.max_particle_radius()
            * opts.style.radius_scale
            * c.pixels_per_world(depth, r.height);
        if across < 1.0 {
            let bg = backdrop(&args);
            let empty = mdlod_render::image::RgbaImage::load_png(&args.output).is_ok_and(|img| {
                img.data.chunks(4).all(|p| match bg {
                    Some(c) => p[..3].iter().zip(c).all(|(a, b)| a.abs_diff(b) <= 1),
                    None => p[3] == 0,
                })
            });
            if empty {
                println!(
                    "  note: nothing shows: the spheres drawn are at most {across:.2} px \
                     across, narrower than the pixels, and fall between their centres \
                     (--radius-scale, --zoom, --spp 16 or a larger image shows them)"
                );
            }
        }
    }
    if args.cell.is_some() && file.metadata().simulation_box.is_none() {
        println!("  note: the file records no simulation cell (its input gave none): --cell draws nothing");
    }
    let gpu = r.gpu_time.map_or(String::new(), |t| {
        format!(", GPU {:.1} ms", t.as_secs_f64() * 1e3)
    });
    if let (Some([lo, hi]), Some(m)) = (r.light_range, opts.style.colour_map) {
        let light = format!(
            "the {}",
            projected_light(&args, &opts, file.metadata().attribute.as_ref())
        );
        let (scale, from) = match (opts.style.log_scale, args.light_range.is_some()) {
            (true, false) => (
                " on a log scale",
                "its lit pixels' 0.5th to 99.5th percentile; --light-range sets another",
            ),
            (false, false) => (
                "",
                "0 to its lit pixels' 99.5th percentile; --light-range sets another",
            ),
            (true, true) => (" on a log scale", "--light-range"),
            (false, true) => ("", "--light-range"),
        };
        println!(
            "  colour map {}: the image's light ({light}) from {lo:.4e} to {hi:.4e}{scale} \
             ({from}; unlit pixels show the background)",
            m.name(),
        );
        // A cusp's core past the top (the percentile's cut), or a faint halo below a
        // log map's bottom, takes the end's colour: said, as the legend marks it.
        if let Some([faint, bright]) = r.light_extent {
            let slack = 1e-6 * hi.abs().max(lo.abs());
            let mut cut = Vec::new();
            if bright > hi + slack {
                cut.push(format!(
                    "the brightest pixels, up to {bright:.4e}, take the top colour"
                ));
            }
            if opts.style.log_scale && faint < lo - slack {
                cut.push(format!(
                    "the faintest lit ones, down to {faint:.4e}, the bottom colour"
                ));
            }
            if !cut.is_empty() {
                let marks = match (bright > hi + slack, cut.len()) {
                    (true, 2) => "its ends ≥ and ≤",
                    (true, _) => "its top ≥",
                    (false, _) => "its bottom ≤",
                };
                println!(
                    "  note: {} (a legend marks {marks}; --light-range {}:{} shows them all)",
                    cut.join(", and "),
                    Num(if opts.style.log_scale { faint } else { lo }),
                    Num(bright.max(hi))
                );
            }
        }
    }
    if let (Some(e), Some(f)) = (r.exposure, r.total_flux) {
        println!(
            "  splats: total flux {f:.4e} (the light summed over the image's pixels, each \
             splat's area in pixels times its intensity: it grows as the zoom enlarges the \
             data, and stays with the screen error while the splats fall within the image: \
             a coarse cut's wide splats spill past its edges), exposure {e:.4e}"
        );
    }
    if let Some((run, all)) = r.density_stacks {
        let saved = if run < all {
            format!(
                "the other {} skipped: every ray was opaque or past the data",
                all - run
            )
        } else {
            "rays reached the last".to_string()
        };
        println!(
            "  density: {run} of {all} slice stacks run, {saved} ({} read-backs)",
            r.density_readbacks.unwrap_or(0)
        );
        // What the colours mean: the particles' own packing, not an attribute.
        match args.mode {
            Mode::Iso => {
                let colours = match args.style.colour_map {
                    Some(_) => "the mean of the attribute around it (the colour map line)",
                    None => "the particles around it",
                };
                println!(
                    "  iso-surface where the particles' spheres fill a volume fraction of {} \
                     (0.74: close-packed spheres of the largest species), coloured by {colours}",
                    args.iso_value
                );
                // No ray met the surface: a value the packing never reaches, or below
                // what any gap holds. (Every pixel the background's: an image of one
                // other colour is a view from inside the surface.)
                let bg = backdrop(&args);
                let background = |p: &[u8]| match bg {
                    Some(c) => p[..3].iter().zip(c).all(|(a, b)| a.abs_diff(b) <= 1),
                    None => p[3] == 0,
                };
                let empty = mdlod_render::image::RgbaImage::load_png(&args.output)
                    .is_ok_and(|img| img.data.chunks(4).all(background));
                if empty && !said_empty && opts.style.clip.is_empty() {
                    println!(
                        "  note: no ray meets a volume fraction of {}: the image shows the \
                         background only (the spheres' packing stays below it; a smaller \
                         --iso-value finds a surface)",
                        args.iso_value
                    );
                } else if empty && !said_empty {
                    println!(
                        "  note: no ray meets a volume fraction of {} in what the --clip \
                         planes keep: the image shows the background only",
                        args.iso_value
                    );
                }
            }
            _ => {
                let log = if args.style.log_scale {
                    " on a log scale"
                } else {
                    ""
                };
                let (lo, hi) = (super::Num(density_min(&args)), super::Num(args.density_max));
                let k = args.absorption;
                match args.style.colour_map {
                    Some(_) => println!(
                        "  colours: the attribute's mean at each sample, weighted by the \
                         particles' densities there, through the colour map (the colour map \
                         line); opacity: the volume fraction the particles' spheres fill, from \
                         {lo} (clear) to {hi} (--density-max){log}, optical depth {k} per \
                         radius at the top"
                    ),
                    None => println!(
                        "  colours: the volume fraction the particles' spheres fill (not an \
                         attribute), from {lo} (clear) through dark blue and red to yellow at \
                         {hi} (--density-max; 0.74: close-packed spheres of the largest \
                         species){log}, optical depth {k} per radius at the top"
                    ),
                }
            }
        }
        if let Some(note) = reference_radius_note(&file) {
            println!("{note}");
        }
    }
    let stream = match r.first_frame_time {
        Some(t) => format!(
            ", first image after {:.0} ms, complete after {} frames",
            t.as_secs_f64() * 1e3,
            r.frames
        ),
        None => String::new(),
    };
    println!(
        "  total {:.0} ms (traversal {:.0} ms{gpu}){stream}",
        r.total_time.as_secs_f64() * 1e3,
        r.traversal_time.as_secs_f64() * 1e3
    );
    if let Some(p) = &args.save_view {
        save_view(p, &r.camera, [args.camera.width, args.camera.height])?;
        println!("  view saved to {}", p.display());
    }
    if let (Some(p), Some(map)) = (&args.save_map, &r.light_map) {
        write_npy(p, r.height, r.width, map)
            .with_context(|| format!("--save-map {}", p.display()))?;
        println!(
            "  light map ({}×{} floats) saved to {}",
            r.width,
            r.height,
            p.display()
        );
    }
    let shown_attribute = legend_attribute(&file, &opts);
    write_legend(
        &args,
        &opts,
        shown_attribute.as_ref(),
        species,
        r.light_range
            .map(|range| (range, r.light_extent.unwrap_or(range))),
        &drawn_names(&r, species, Default::default()),
        std::slice::from_ref(&args.output),
    )?;
    write_labels(
        &args,
        &[(
            args.output.clone(),
            label::Values::of_file(&args.file, file.metadata(), 0),
        )],
        None,
    )?;
    if let Some(bar) = &bar {
        draw_panels(
            &args,
            &[(&args.output, bar)],
            args.scale_bar_corner(),
            "--scale-bar",
        )?;
    }
    if let Some(axes) = &axes {
        draw_panels(&args, &[(&args.output, axes)], args.axes_corner(), "--axes")?;
    }
    if args.json {
        crate::print_json(report_json(
            &args.output,
            &r,
            &args,
            &opts,
            shown_json(&args, &opts, &file),
        ));
    }
    Ok(())
}

/// Draws each image's panel (`--scale-bar`, `--axes`: `option`) at `corner`, and says
/// how much data they covered.
fn draw_panels(
    args: &Args,
    images: &[(&Path, &mdlod_render::legend::Legend)],
    corner: LegendCorner,
    option: &str,
) -> Result<()> {
    let mut covered = Covered::default();
    for (image, panel) in images {
        covered.add(draw_panel(args, image, panel, corner, option)?);
    }
    if let Some(note) = covered.note(option, images.len(), args) {
        println!("{note}");
    }
    Ok(())
}

/// The file's attribute as a legend shows it: where the image maps a range of its own,
/// with the range of the values drawn (hidden particles' lie beyond no end of the bar);
/// else the file's, as the image maps it.
fn legend_attribute(
    file: &mdlod_format::MdlodFile,
    opts: &RenderOptions,
) -> Option<mdlod_format::meta::AttributeInfo> {
    let a = file.metadata().attribute.clone()?;
    Some(
        match opts
            .style
            .attribute_range
            .and_then(|_| mdlod_render::shown_attribute_range(file, &opts.style))
        {
            Some([min, max]) => mdlod_format::meta::AttributeInfo { min, max, ..a },
            None => a,
        },
    )
}

/// `drawn` with the names of the species the render `r` of a file of `species` showed.
fn drawn_names(
    r: &mdlod_render::RenderReport,
    species: &[mdlod_format::meta::Species],
    mut drawn: std::collections::BTreeSet<String>,
) -> std::collections::BTreeSet<String> {
    for (s, shown) in species.iter().zip(r.species_drawn.iter().flatten()) {
        if *shown {
            drawn.insert(s.name.clone());
        }
    }
    drawn
}

/// A projection's light as its legend shows it: the map's range, and the light of the
/// faintest and brightest lit pixels of the images it maps.
type Light = ([f32; 2], [f32; 2]);

/// The light of the faintest and brightest lit pixels of two sets of images.
fn lit_union(a: Option<[f32; 2]>, b: Option<[f32; 2]>) -> Option<[f32; 2]> {
    match (a, b) {
        (Some([a0, a1]), Some([b0, b1])) => Some([a0.min(b0), a1.max(b1)]),
        (a, b) => a.or(b),
    }
}

/// Writes `--legend` and draws `--legend-in-image` into the PNGs `images`: the bar of
/// the colour map over the attribute (`attribute`, as `opts` shows it) or over a
/// projection's light (`light`), the density volume's transfer function, or a key
/// of the species shown (`drawn`, of `species`) in the colours drawn ([`build_legend`]).
fn write_legend(
    args: &Args,
    opts: &RenderOptions,
    attribute: Option<&mdlod_format::meta::AttributeInfo>,
    species: &[mdlod_format::meta::Species],
    light: Option<Light>,
    drawn: &std::collections::BTreeSet<String>,
    images: &[PathBuf],
) -> Result<()> {
    if args.legend.is_none() && args.legend_in_image.is_none() {
        return Ok(());
    }
    let (drawn_legend, what) = build_legend(args, opts, attribute, species, light, drawn)?;
    if let Some(path) = &args.legend {
        if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
            std::fs::create_dir_all(parent)
                .with_context(|| format!("cannot create {}", parent.display()))?;
        }
        mdlod_render::image::write_atomic(path, drawn_legend.svg().as_bytes())
            .with_context(|| format!("cannot write {}", path.display()))?;
        println!("  legend written to {} ({what})", path.display());
    }
    if let Some(corner) = args.legend_in_image {
        let mut covered = Covered::default();
        for image in images {
            covered.add(draw_panel(
                args,
                image,
                &drawn_legend,
                corner,
                "--legend-in-image",
            )?);
        }
        println!(
            "  legend drawn into {} ({what})",
            match images {
                [one] => one.display().to_string(),
                _ => format!("each of the {} images", images.len()),
            }
        );
        if let Some(note) = covered.note("--legend-in-image", images.len(), args) {
            println!("{note}");
        }
        let missing = drawn_legend.missing_glyphs();
        if !missing.is_empty() {
            let list: Vec<String> = missing.iter().map(|c| format!("{c:?}")).collect();
            println!(
                "  note: the image's font has no {} (drawn as ?; an SVG legend, --legend, \
                 keeps {})",
                list.join(", "),
                if missing.len() == 1 { "it" } else { "them" }
            );
        }
    }
    Ok(())
}

/// The most particles [`check_legend_room`] looks at one by one for species a hidden
/// value range leaves without any (a few milliseconds).
const KEY_SCAN_PARTICLES: u64 = 1 << 22;

/// Refuses `--legend-in-image` before anything is drawn where the image cannot hold the
/// legend: a colour bar's, or a key of every species the file (a batch's first frame)
/// shows unhidden, which holds at least the species the picture will show.
///
/// Returns where a fitted view places the data so that the legend covers none of it: the
/// image less a band along the legend's side, above or below it, or beside it, whichever
/// frames the data larger ([`RenderOptions::fit_windows`]); none without a legend.
fn check_legend_room(
    args: &Args,
    opts: &RenderOptions,
) -> Result<(Vec<mdlod_render::FitWindow>, Option<[u32; 2]>)> {
    let Some(corner) = args.legend_in_image else {
        return Ok((Vec::new(), None));
    };
    // (A file or directory that cannot be read fails where it is rendered, saying why.)
    let Some(path) = first_file(&args.file) else {
        return Ok((Vec::new(), None));
    };
    let Ok(file) = mdlod_render::open_styled(&path, &opts.style) else {
        return Ok((Vec::new(), None));
    };
    let meta = file.metadata();
    // Species whose every particle a hidden value range leaves out show in no key: where
    // a look at each particle is cheap, they are left out of the room asked for too.
    let test = file.hidden_test(&opts.style.hidden_set(meta));
    let shown: Option<Vec<bool>> =
        (opts.style.hides_values() && file.particle_count() <= KEY_SCAN_PARTICLES).then(|| {
            let mut shown = vec![false; meta.species.len()];
            for (i, &s) in file.species().iter().enumerate() {
                if !file.hides_particle(&test, i) {
                    if let Some(x) = shown.get_mut(usize::from(s)) {
                        *x = true;
                    }
                }
            }
            shown
        });
    let mut all: std::collections::BTreeSet<String> = meta
        .species
        .iter()
        .enumerate()
        .filter(|(k, _)| shown.as_ref().is_none_or(|v| v[*k]))
        .map(|(_, s)| s.name.clone())
        .collect();
    // A movie's key names the species of every frame (ions that come later, say): the
    // room is kept for all of them, with the looks the movie gives them.
    let mut species = meta.species.clone();
    if let Some(frames) = movie_species(&args.file) {
        species = mdlod_render::style::trajectory_looks(
            &frames.iter().map(Vec::as_slice).collect::<Vec<_>>(),
        );
        all.extend(frames.iter().flatten().map(|s| s.name.clone()));
    }
    let (legend, _) = build_legend(
        args,
        opts,
        meta.attribute.as_ref(),
        &species,
        // (Marked ends, `≤` and `≥`, as wide as a legend's can be.)
        Some(([1.0, 2.0], [0.5, 3.0])),
        &all,
    )?;
    let Some(scale) = legend.scale_in(opts.width, opts.height, args.text_scale) else {
        let (w, h) = legend.room_needed(args.text_scale.unwrap_or(1));
        anyhow::bail!(
            "--legend-in-image: a {}×{} image cannot hold the legend (at least {w}×{h} \
             pixels with its margin); draw a larger image, or write the legend beside it \
             with --legend FILE.svg",
            opts.width,
            opts.height
        );
    };
    let (w, h) = legend.room_needed(scale);
    let windows = legend_windows(corner, [w, h], [opts.width, opts.height]);
    // The data needs a part of the image of its own, or the fit falls back to the whole
    // image, under the panel.
    let size = [f64::from(opts.width), f64::from(opts.height)];
    let room = |win: &mdlod_render::FitWindow| {
        [0, 1].map(|k| ((win.max[k] - win.min[k]) * 0.5 * size[k]).round().max(0.0) as u32)
    };
    if !windows
        .iter()
        .any(|win| room(win).iter().all(|&px| px >= MIN_DATA_ROOM))
    {
        // (`legend_windows` gives the band above or below the panel, then the one beside.)
        let [[aw, ah], [bw, bh]] = [room(&windows[0]), room(&windows[1])];
        anyhow::bail!(
            "--legend-in-image: a {}×{} image holds the legend ({w}×{h} pixels with its \
             margin) but leaves the data only {aw}×{ah} pixels {} it or {bw}×{bh} beside it \
             (at least {MIN_DATA_ROOM}×{MIN_DATA_ROOM}, or the legend would cover the data); \
             draw a larger image, or write the legend beside it with --legend FILE.svg",
            opts.width,
            opts.height,
            if matches!(corner, LegendCorner::TopLeft | LegendCorner::TopRight) {
                "below"
            } else {
                "above"
            }
        );
    }
    Ok((windows, Some([w, h])))
}

/// The file a still renders, or a batch directory's first frame (what panels are
/// checked against before drawing); `None` for a directory whose manifest cannot be
/// read or lists no frame.
fn first_file(file: &Path) -> Option<PathBuf> {
    if !file.is_dir() {
        return Some(file.to_path_buf());
    }
    let manifest = mdlod_preprocess::batch::read_manifest(file).ok()?;
    manifest.frames.first().map(|f| file.join(&f.file))
}

/// Each frame's species, for a batch directory of more than one frame (`None` for a
/// file, or a directory whose frames cannot all be read: those fail where they are
/// rendered).
fn movie_species(dir: &Path) -> Option<Vec<Vec<mdlod_format::meta::Species>>> {
    if !dir.is_dir() {
        return None;
    }
    let manifest = mdlod_preprocess::batch::read_manifest(dir).ok()?;
    if manifest.frames.len() < 2 {
        return None;
    }
    manifest
        .frames
        .iter()
        .map(|f| {
            // (The species only: the top node's record checked, not every level's.)
            let file = mdlod_format::MdlodFile::open_sparse(dir.join(&f.file)).ok()?;
            Some(file.metadata().species.clone())
        })
        .collect()
}

/// Where a fitted view places the data so that the scale bar's panel covers none of it
/// either (a still's or a movie's first frame's fit): `windows` (the legend's, or the
/// whole image) each intersected with the two the panel leaves free, as the legend's
/// are; `windows` as they are without a scale bar, or where that leaves the data too
/// little room. The panel is taken at its widest: a fifth of the image, or the length
/// asked for at the scale of the fit without it (the fit with it frames the data
/// smaller, and the bar with it).
fn scale_bar_room(
    args: &Args,
    opts: &RenderOptions,
    windows: Vec<mdlod_render::FitWindow>,
) -> Vec<mdlod_render::FitWindow> {
    if !args.scale_bar {
        return windows;
    }
    let (w, h) = (opts.width, opts.height);
    // (A file that cannot be read fails where it is rendered, saying why.)
    let Some(path) = first_file(&args.file) else {
        return windows;
    };
    let Ok(file) = mdlod_render::open_styled(&path, &opts.style) else {
        return windows;
    };
    let pixels = match args.scale_bar_length {
        None => f64::from(w) / 5.0,
        Some(length) => {
            let o = RenderOptions {
                fit_windows: windows.clone(),
                ..opts.clone()
            };
            match mdlod_render::frame_setup(&file, &o) {
                Ok((c, _, _)) => {
                    f64::from(length) * f64::from(h) / f64::from(c.view_height_at_target())
                }
                Err(_) => return windows,
            }
        }
    };
    // The label's widest: a number of up to seven characters (`1.25e-5`) and the unit.
    let label = format!(
        "0000000 {}",
        length_unit(
            args.scale_bar_unit
                .as_deref()
                .or(file.metadata().units.as_deref())
        )
    );
    let probe = mdlod_render::legend::Legend::Scale {
        length: 1.0,
        label: label.clone(),
    };
    let Some(s) = probe.scale_in(w, h, args.text_scale) else {
        return windows;
    };
    let panel = mdlod_render::legend::Legend::Scale {
        length: (pixels / f64::from(s)) as f32,
        label,
    };
    let (pw, ph) = panel.room_needed(s);
    keep_clear(windows, args.scale_bar_corner(), [pw, ph], [w, h])
}

/// `windows` kept clear of the `--axes` panel, as [`scale_bar_room`] keeps them of the
/// scale bar's.
fn axes_room(
    args: &Args,
    opts: &RenderOptions,
    windows: Vec<mdlod_render::FitWindow>,
) -> Vec<mdlod_render::FitWindow> {
    if !args.axes {
        return windows;
    }
    let (w, h) = (opts.width, opts.height);
    let panel =
        mdlod_render::legend::axes_tripod([1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]);
    let Some(s) = panel.scale_in(w, h, args.text_scale) else {
        return windows;
    };
    keep_clear(
        windows,
        args.axes_corner(),
        panel.room_needed(s).into(),
        [w, h],
    )
}

/// `windows` (none: the whole image) each intersected with the two parts of a `size`
/// image that a panel of `room` pixels in `corner` leaves free; `windows` as they are
/// where that leaves the data too little room.
fn keep_clear(
    windows: Vec<mdlod_render::FitWindow>,
    corner: LegendCorner,
    room: [u32; 2],
    size: [u32; 2],
) -> Vec<mdlod_render::FitWindow> {
    let free = legend_windows(corner, room, size);
    let whole = [mdlod_render::FitWindow::WHOLE];
    let given: &[mdlod_render::FitWindow] = if windows.is_empty() { &whole } else { &windows };
    let size = size.map(f64::from);
    let both: Vec<mdlod_render::FitWindow> = given
        .iter()
        .flat_map(|a| {
            free.iter().map(move |b| mdlod_render::FitWindow {
                min: [0, 1].map(|k| a.min[k].max(b.min[k])),
                max: [0, 1].map(|k| a.max[k].min(b.max[k])),
            })
        })
        .filter(|win| {
            (0..2).all(|k| (win.max[k] - win.min[k]) * 0.5 * size[k] >= f64::from(MIN_DATA_ROOM))
        })
        .collect();
    if both.is_empty() {
        windows
    } else {
        both
    }
}

/// Where a fitted view places the data so that the label's panel covers none of it
/// either: [`keep_clear`] of the panel with the values of the file (a movie's first
/// frame), at its widest line.
fn label_room(
    args: &Args,
    opts: &RenderOptions,
    windows: Vec<mdlod_render::FitWindow>,
) -> Vec<mdlod_render::FitWindow> {
    if args.label.is_empty() {
        return windows;
    }
    // (A file that cannot be read fails where it is rendered, saying why.)
    let Some(path) = first_file(&args.file) else {
        return windows;
    };
    // (The metadata only: the top node's record checked, not every level's.)
    let Ok(file) = mdlod_format::MdlodFile::open_with_eager_nodes(&path, 1) else {
        return windows;
    };
    let values = label::Values::of_file(&path, file.metadata(), 0);
    let (panels, _) = label_panels(args, &[&values], &[&values]);
    let (w, h) = (opts.width, opts.height);
    let Some((panel, s)) = panels
        .first()
        .and_then(|p| Some((p, p.scale_in(w, h, args.text_scale)?)))
    else {
        return windows;
    };
    let (pw, ph) = panel.room_needed(s);
    keep_clear(windows, args.label_corner(), [pw, ph], [w, h])
}

/// The fewest pixels, across and down, of the part of the image an in-image legend
/// leaves the data.
const MIN_DATA_ROOM: u32 = 48;

/// The two parts of a `size` image that leave a legend of `room` pixels in `corner` free:
/// all but a band of its height (at the top or bottom), all but a band of its width (at
/// the side), in normalised device coordinates (y up).
fn legend_windows(
    corner: LegendCorner,
    room: [u32; 2],
    size: [u32; 2],
) -> Vec<mdlod_render::FitWindow> {
    let band = [0, 1].map(|k| 2.0 * f64::from(room[k]) / f64::from(size[k].max(1)));
    let (top, left) = match corner {
        LegendCorner::TopLeft => (true, true),
        LegendCorner::TopRight => (true, false),
        LegendCorner::BottomLeft => (false, true),
        LegendCorner::BottomRight => (false, false),
    };
    let mut below_or_above = mdlod_render::FitWindow::WHOLE;
    if top {
        below_or_above.max[1] = 1.0 - band[1];
    } else {
        below_or_above.min[1] = -1.0 + band[1];
    }
    let mut beside = mdlod_render::FitWindow::WHOLE;
    if left {
        beside.min[0] = -1.0 + band[0];
    } else {
        beside.max[0] = 1.0 - band[0];
    }
    vec![below_or_above, beside]
}

/// What the light of splats is, in the units the legend and summary give it: the
/// projected attribute (`projected rho`; `projected (vz + 3.5)` where its range starts
/// elsewhere than 0: the light is the value less the range's low end), or the projected
/// flux (species light, or an attribute whose light is no quantity in its units).
fn projected_light(
    args: &Args,
    opts: &RenderOptions,
    attribute: Option<&mdlod_format::meta::AttributeInfo>,
) -> String {
    let Some(a) = attribute.filter(|_| matches!(args.intensity, Intensity::Attribute)) else {
        return "projected flux".to_string();
    };
    let (_, style) = mdlod_render::page_style(opts);
    // A logarithm lights by its quantity (`log10(rho)`: the projected rho).
    let inner = a
        .name
        .strip_prefix("log10(")
        .and_then(|s| s.strip_suffix(')'));
    let scale =
        mdlod_render::style::AttributeScale::with_range(a, style.light_range(a, inner.is_some()));
    let (name, scale) = match inner {
        Some(inner) => (inner, scale.lighting_by_quantity()),
        None => (a.name.as_str(), scale.with_log(style.log_scale)),
    };
    match scale.light_zero() {
        Some(0.0) => format!("projected {name}"),
        Some(lo) if lo < 0.0 => format!("projected ({name} + {})", Num(-lo)),
        Some(lo) => format!("projected ({name} − {})", Num(lo)),
        None => format!("projected flux ({name} constant)"),
    }
}

/// The legend `--legend` and `--legend-in-image` show, and what it is (for the summary).
fn build_legend(
    args: &Args,
    opts: &RenderOptions,
    attribute: Option<&mdlod_format::meta::AttributeInfo>,
    species: &[mdlod_format::meta::Species],
    light: Option<Light>,
    drawn: &std::collections::BTreeSet<String>,
) -> Result<(mdlod_render::legend::Legend, String)> {
    use mdlod_render::legend;
    let name = match (&args.legend, args.legend_in_image) {
        (Some(p), _) => format!("--legend {}", p.display()),
        _ => "--legend-in-image".to_string(),
    };
    let map = opts.style.colour_map;
    let (drawn_legend, what) = match (args.mode, map, attribute) {
        (Mode::Density, None, _) => (
            legend::density_bar(
                density_min(args),
                args.density_max,
                args.style.log_scale,
                args.legend_title.as_deref(),
            ),
            "the volume fraction's colours".to_string(),
        ),
        (Mode::Splat, Some(map), _) => {
            let title = match &args.legend_title {
                Some(t) => t.clone(),
                None => projected_light(args, opts, attribute),
            };
            let Some((range, lit)) = light else {
                anyhow::bail!("{name}: the image has no light to map (nothing drawn)");
            };
            (
                legend::light_bar(map, &title, range, opts.style.log_scale, lit),
                format!("the colour map over the {title}"),
            )
        }
        (Mode::Spheres | Mode::Sndf, Some(map), Some(a)) if !args.legend_category.is_empty() => {
            let scale =
                mdlod_render::style::AttributeScale::with_range(a, opts.style.attribute_range)
                    .with_log(opts.style.log_scale);
            let mut entries = Vec::new();
            // Hidden values of this attribute (not of another --hide-by names).
            let same = opts
                .style
                .hide_by
                .as_deref()
                .is_none_or(|h| mdlod_format::reader::attribute_named(&[&a.name], h).is_some());
            // (And the ranges naming it.)
            let named =
                opts.style.hidden_named.iter().filter(|(n, _)| {
                    mdlod_format::reader::attribute_named(&[&a.name], n).is_some()
                });
            let ranges: Vec<[f32; 2]> = opts
                .style
                .hidden_values
                .iter()
                .filter(|_| same)
                .copied()
                .chain(named.map(|(_, r)| *r))
                .collect();
            for (value, label) in legend_categories(args)? {
                let hidden = ranges.iter().any(|&[lo, hi]| lo <= value && value <= hi);
                if !hidden {
                    entries.push((label, map.colour(scale.of_value(value))));
                }
            }
            let what = format!(
                "{} categor{} of {} in the colour map's colours",
                entries.len(),
                if entries.len() == 1 { "y" } else { "ies" },
                a.name
            );
            let title = args.legend_title.as_deref().unwrap_or(&a.name);
            (legend::species_key(&entries, Some(title)), what)
        }
        (Mode::Spheres | Mode::Sndf | Mode::Density | Mode::Iso, Some(map), Some(a)) => {
            let scale =
                mdlod_render::style::AttributeScale::with_range(a, opts.style.attribute_range)
                    .with_log(opts.style.log_scale);
            let range = opts.style.attribute_range.unwrap_or([a.min, a.max]);
            let title = args.legend_title.as_deref().unwrap_or(&a.name);
            (
                legend::colour_bar(map, &scale, title, range, [a.min, a.max]),
                format!("the colour map over {}", a.name),
            )
        }
        _ => {
            // Spheres, S-NDFs, splats and the iso-surface draw the style's colours; the
            // density volume the transfer function's (keyed by its bar).
            let styled = matches!(
                args.mode,
                Mode::Spheres | Mode::Sndf | Mode::Splat | Mode::SplatOver | Mode::Iso
            );
            let table = opts.style.species_table(species).ok();
            let mut shown: Vec<(String, [f32; 3])> = species
                .iter()
                .enumerate()
                .filter(|(_, s)| {
                    drawn.contains(&s.name)
                        && !opts
                            .style
                            .species
                            .iter()
                            .any(|st| st.name == s.name && st.hidden)
                })
                .map(|(i, s)| {
                    let colour = match (&table, styled) {
                        (Some(t), true) => [t[i][0], t[i][1], t[i][2]],
                        _ => s.colour,
                    };
                    (s.name.clone(), colour)
                })
                .collect();
            // One order for every frame of a run, stills and movies alike.
            shown.sort_by(|a, b| legend::key_order(&a.0, &b.0));
            let what = match shown.len() {
                // (Every species hidden, or none in view.)
                0 => "an empty key: no species is shown".to_string(),
                n => format!("{n} species in their colours"),
            };
            (
                legend::species_key(&shown, args.legend_title.as_deref()),
                what,
            )
        }
    };
    Ok((drawn_legend, what))
}

/// What a cut's nodes are drawn as: spheres and S-NDFs ray cast cluster spheres, splats
/// and the volume draw each point once.
fn point_noun(mode: Mode) -> &'static str {
    match mode {
        Mode::Spheres | Mode::Sndf => "cluster spheres",
        Mode::Splat | Mode::SplatOver => "cluster splats",
        Mode::Density | Mode::Iso => "cluster kernels",
    }
}

/// `noun` (a plural, as [`point_noun`] gives it) for `n` of them: singular for one.
fn counted(noun: &str, n: u64) -> &str {
    if n == 1 {
        noun.strip_suffix('s').unwrap_or(noun)
    } else {
        noun
    }
}

/// A note when clusters took new species colours only approximately (`miss`: the
/// largest channel error of [`mdlod_render::PointStyle::recolour_miss`]).
fn recolour_note(miss: Option<f32>, species: usize) -> Option<String> {
    let miss = miss.filter(|&m| m > 0.02)?;
    Some(format!(
        "  note: clusters of several species took the new species colours approximately \
         (off by up to {:.0}% in a channel; clusters of one species take theirs exactly): \
         the {species} species' colours allow no exact mixture map (exact for up to four \
         shown species of affinely independent colours); a lower --screen-error draws more \
         particles in their own colours",
        miss * 100.0
    ))
}

/// The range the attribute is shown over when none is given and the file's own would
/// mislead (`mapped`: a colour map or attribute splats draw it): a diverging map over
/// signed values is centred on 0 ([`mdlod_render::style::ColourMap::centred_range`]); a
/// log scale of values from 0 or below starts at the smallest positive one
/// ([`mdlod_render::log_floor`]). Sets the style's range and says why, for the legend.
pub fn derive_range(
    style: &mut mdlod_render::PointStyle,
    path: &std::path::Path,
    mapped: bool,
    light: bool,
) -> Result<Option<String>> {
    if !mapped && !light {
        return Ok(None);
    }
    let file = mdlod_render::open_styled(path, style)?;
    let Some(a) = &file.metadata().attribute else {
        return Ok(None);
    };
    check_not_logged(style, a, path, light, file.metadata().attribute_log10)?;
    let Some((range, why)) = mdlod_render::default_range_of(&file, style, mapped, light) else {
        return Ok(None);
    };
    style.attribute_range = Some(range);
    style.range_derived = true;
    Ok(Some(format!(
        "{}; the file's range is {} to {}",
        why.why(),
        Num(a.min),
        Num(a.max)
    )))
}

/// Whether the splats are lit by the attribute's value (`--intensity attribute`, through
/// a projection's colour map or not).
fn lit_by_value(args: &Args) -> bool {
    args.mode == Mode::Splat && matches!(args.intensity, Intensity::Attribute)
}

/// Splats lit by values on a linear scale: no `--log-scale`, or a projection's (the
/// image's log, not each splat's).
fn lit_linearly(args: &Args) -> bool {
    lit_by_value(args) && (!args.style.log_scale || projected(args))
}

/// `--log-scale` of an attribute stored as its logarithm (`--attribute-log10`) would take
/// the log of the log; splats lit by it (`lit`) light by the quantity itself where the
/// file's clusters hold the logarithms of their mean values (`log10_means`, the metadata's
/// `attribute_log10`), and are refused in a file of an older mdlod, whose clusters hold
/// means of logarithms, naming what to do instead.
fn check_not_logged(
    style: &mdlod_render::PointStyle,
    a: &mdlod_format::meta::AttributeInfo,
    path: &Path,
    lit: bool,
    log10_means: bool,
) -> Result<()> {
    if lit && a.name.starts_with("log10(") && !log10_means {
        anyhow::bail!(
            "--intensity attribute: {} holds {}, a logarithm, whose clusters hold the means \
             of their particles' logarithms (a file of an earlier mdlod): no sum of them is \
             the projection of the values; convert it again with this mdlod (its clusters \
             then keep the logarithm of their mean value, and splats light by the value)",
            path.display(),
            a.name
        );
    }
    // A range of logarithms whose ends stand for no single-precision quantity: linear
    // values typed for logarithms (`0.01:1e4`), most likely.
    if let (Some([lo, hi]), Some(inner)) = (
        style.attribute_range,
        a.name
            .strip_prefix("log10(")
            .and_then(|s| s.strip_suffix(')')),
    ) {
        // (The logarithms of single precision's largest and smallest numbers.)
        if let Some(end) = [lo, hi].into_iter().find(|e| !(-45.0..=38.5).contains(e)) {
            anyhow::bail!(
                "--attribute-range {}:{}: {} holds {}, logarithms (converted with \
                 --attribute-log10), so the range's ends are logarithms too, and {} stands \
                 for 10^{}, beyond single precision; for {inner} from 0.01 to 10000 give \
                 -2:4",
                Num(lo),
                Num(hi),
                path.display(),
                a.name,
                Num(end),
                Num(end)
            );
        }
    }
    // (Splats lit by the quantity map their image's light on the log scale, not the
    // logarithms.)
    if style.log_scale && a.name.starts_with("log10(") && !(lit && log10_means) {
        anyhow::bail!(
            "--log-scale: {} holds {}, already a logarithm (converted with \
             --attribute-log10): without --log-scale the map spreads its decades evenly \
             (and --attribute-range takes log10 units)",
            path.display(),
            a.name
        );
    }
    Ok(())
}

/// How a log scale (`--log-scale`) maps the attribute, after the legend's range: the ends
/// it spans, where the low end is not the range's own (0 or below), or why it is linear.
/// Nothing where the points' values are not on it (a splat projection's map takes the
/// log of the image instead).
fn log_text(
    a: &mdlod_format::meta::AttributeInfo,
    style: &mdlod_render::PointStyle,
    args: &Args,
) -> String {
    if !style.log_scale || projected(args) {
        return String::new();
    }
    let fate = if args.mode == Mode::Splat {
        "give no light"
    } else {
        "take the map's first colour"
    };
    let scale =
        mdlod_render::style::AttributeScale::with_range(a, style.attribute_range).with_log(true);
    let low = style.attribute_range.map_or(a.min, |r| r[0]);
    // The file keeps 16-bit steps of the linear range: the scale's lowest decades may hold
    // only a few of them.
    let step = (f64::from(a.max) - f64::from(a.min)) / 65535.0;
    // Values within half a step of the file's lowest are stored as it: the scale's
    // decades below one step hold no value of their own.
    let coarse = |[lo, hi]: [f64; 2]| {
        if a.name.starts_with("log10(") || step <= 10.0 * lo {
            return String::new();
        }
        let all = (hi / lo).log10();
        let empty = (step.min(hi) / lo).log10().clamp(0.0, all);
        let few = format!(
            "{empty:.0} of the scale's {all:.0} decades show no step of their own and those \
             up to {} a few each (convert with --attribute-log10={} to keep them)",
            Num((step * 1000.0) as f32),
            a.name
        );
        // Where the file's lowest is the scale's start or below it, what is stored as it
        // takes the start's colour.
        if a.min >= 0.0 && f64::from(a.min) <= lo {
            format!(
                "; the file stores the values linearly in steps of {}: values below about {} \
                 are all stored as {} and {fate}, so {few}",
                Num(step as f32),
                Num((f64::from(a.min) + step / 2.0) as f32),
                Num(a.min),
            )
        } else {
            format!(
                "; the file stores the values linearly in steps of {}, so {few}",
                Num(step as f32)
            )
        }
    };
    match scale.log_range() {
        Some(r) if f64::from(low) > 0.0 => format!(", on a log scale{}", coarse(r)),
        Some([lo, hi]) => format!(
            ", on a log scale from {:.4e} ({} decades below {}): values at or below it \
             {fate}{}",
            lo as f32,
            mdlod_render::style::AttributeScale::LOG_DECADES,
            hi as f32,
            coarse([lo, hi]),
        ),
        None if style.attribute_range.is_none() && a.min >= a.max => {
            ", linear (--log-scale left unused: the attribute is constant)".to_string()
        }
        None => ", linear (--log-scale left unused: no value of the range is above 0, and a \
                  log scale shows only those)"
            .to_string(),
    }
}

/// The attribute's range has values above 0, so `--log-scale` maps their logarithm.
fn log_applies(a: &mdlod_format::meta::AttributeInfo, style: &mdlod_render::PointStyle) -> bool {
    mdlod_render::style::AttributeScale::with_range(a, style.attribute_range)
        .with_log(true)
        .log_range()
        .is_some()
}

/// Where a diverging map's white falls when a range given puts it off 0 (cool-warm over
/// `--attribute-range -2:10`: white at 4).
fn white_text(style: &mdlod_render::PointStyle) -> String {
    match (style.colour_map, style.attribute_range) {
        (Some(map), Some([lo, hi])) if map.is_diverging() && !style.log_scale => {
            let mid = lo * 0.5 + hi * 0.5;
            if mid == 0.0 {
                String::new()
            } else {
                format!(
                    ", the map's white at {mid} (not 0: a range symmetric about 0 puts it there)"
                )
            }
        }
        _ => String::new(),
    }
}

/// The note for particles a fitted view left out of its fit as far from the rest
/// (`frames`: in how many frames of a movie).
fn far_note(far: u64, frames: Option<usize>) -> Option<String> {
    if far == 0 {
        return None;
    }
    let (s, verb) = if far == 1 { ("", "is") } else { ("s", "are") };
    let whose = match frames {
        Some(1) => " (in 1 frame)".to_string(),
        Some(n) => format!(" (in {n} frames together)"),
        None => String::new(),
    };
    Some(format!(
        "  note: {far} particle{s}{whose} far from the rest {verb} left out of the view's \
         fit, or framed only near it where their spheres reach far past it (an SPH void's \
         smoothing lengths) (they would shrink the material to a fraction of the image): \
         --fit-all fits every particle, --zoom below 1 widens the view"
    ))
}

/// A note where a batch left frames out (without particles, or failed): a movie's images
/// are numbered without them, so its time jumps there (a focus lost for one frame of a
/// microscope's series, a run's empty frames).
fn missing_frames_note(m: &mdlod_preprocess::batch::Manifest, dir: &Path) -> Option<String> {
    // `3 frames without particles (timesteps 2, 5, 9)`, at most eight timesteps named.
    let said = |count: usize, what: &str, t: Vec<u64>| {
        let frames = if count == 1 { "frame" } else { "frames" };
        let shown: Vec<String> = t.iter().take(8).map(u64::to_string).collect();
        let more = match t.len() > 8 {
            true => format!(" and {} more", t.len() - 8),
            false => String::new(),
        };
        match t.len() {
            0 => format!("{count} {frames} {what}"),
            1 => format!("{count} {frames} {what} (timestep {})", shown[0]),
            _ => format!(
                "{count} {frames} {what} (timesteps {}{more})",
                shown.join(", ")
            ),
        }
    };
    let mut parts = Vec::new();
    if !m.empty.is_empty() {
        let t = m.empty.iter().map(|e| e.timestep).collect();
        parts.push(said(m.empty.len(), "without particles", t));
    }
    if !m.failed.is_empty() {
        let t = m.failed.iter().filter_map(|f| f.timestep).collect();
        parts.push(said(m.failed.len(), "that failed to convert", t));
    }
    // Failed frames: why, and how they come back.
    let mend = match m.failed.len() {
        0 => String::new(),
        1 => format!(
            "; `mdlod verify {}` says why the frame failed, and a rerun of the batch converts \
             it once its input is mended",
            dir.display()
        ),
        _ => format!(
            "; `mdlod verify {}` says why the frames failed, and a rerun of the batch \
             converts them once their inputs are mended",
            dir.display()
        ),
    };
    (!parts.is_empty()).then(|| {
        format!(
            "  note: the batch left out {}: the images are numbered without them, so the \
             movie's time jumps there (a {{time}} or {{timestep}} label shows it){mend}",
            parts.join(" and ")
        )
    })
}

/// A note where the density's reference radius (the largest particle's) is well above a
/// species' radius: volume fractions are of spheres of that radius, so a packing of the
/// smaller species reads high by the radii's ratio (one stray large atom doubled every
/// value of a crystal of small ones).
fn reference_radius_note(file: &mdlod_format::MdlodFile) -> Option<String> {
    let r_ref = file.max_particle_radius();
    let m = file.metadata();
    // Particles of their own sizes (grains of a DEM run) by the smallest of each species;
    // sizes spanning a hundred times and more (an SPH run's smoothing lengths) have a
    // note of their own.
    let own = m.radius.is_some();
    if m.radius
        .is_some_and(|r| r.min > 0.0 && r.max / r.min >= 100.0)
    {
        return None;
    }
    let (name, r) = m
        .species
        .iter()
        .map(|s| (&s.name, if own { s.smallest_radius() } else { s.radius }))
        .filter(|(_, r)| *r > 0.0)
        .min_by(|a, b| a.1.total_cmp(&b.1))?;
    let ratio = r_ref / r;
    let (what, mend) = match own {
        true => (
            format!(
                "particles of radius {} (the smallest, of species {name})",
                Num(r)
            ),
            "",
        ),
        false => (
            format!("species {name} (radius {})", Num(r)),
            " (--radius giving the species one size makes the values its packing's)",
        ),
    };
    (ratio >= 1.5 && ratio.is_finite()).then(|| {
        format!(
            "  note: volume fractions are of spheres of the largest radius, {} (the density's \
             reference): a particle of radius r adds {}/r times its own volume, so a close \
             packing of {what} reads {:.2}, not 0.74{mend}",
            Num(r_ref),
            Num(r_ref),
            0.7405 * ratio
        )
    })
}

/// A note where S-NDFs were sampled from cluster spheres wider than a pixel or two: their
/// normals are the spheres', not the particles' (the paper chooses the cut against the
/// texels of the S-MIP level sampled, so that S-NDFs hold the data's normals).
fn sndf_of_clusters_note(mode: Mode, r: &mdlod_render::RenderReport) -> Option<String> {
    (mode == Mode::Sndf && r.nodes_drawn > 0 && r.error_px > 2.0).then(|| {
        format!(
            "  note: the S-NDFs sample {} cluster spheres up to {:.1} px wide, whose normals \
             are the spheres', not their particles': shaded, the image is a coarse sphere \
             image's; --screen-error 1 samples the data's own normals (`mdlod sample` at full \
             detail, then `shade --level`, shades coarser S-MIP levels of them)",
            r.nodes_drawn, r.error_px
        )
    })
}

/// After the particle count: how many particles of hidden species, or cut away by the
/// clip planes, were left out.
fn hidden_text(r: &mdlod_render::RenderReport, style: &StyleArgs) -> String {
    let mut parts = vec![];
    if r.particles_hidden > 0 {
        let what = match (
            style.hide_species.is_empty(),
            style.hide_attribute.is_empty(),
        ) {
            (false, true) => "of hidden species",
            (true, false) => "with hidden values (--hide-attribute)",
            _ => "of hidden species or with hidden values",
        };
        parts.push(format!(
            "{} {what} left out of the clusters opened; clusters of them only, and those \
             behind nearer spheres, are left out whole",
            r.particles_hidden
        ));
    }
    if r.particles_clipped > 0 {
        parts.push(format!(
            "{} cut away by --clip from the clusters opened across it; clusters beyond it, \
             and those behind nearer spheres, are left out whole",
            r.particles_clipped
        ));
    }
    match parts.is_empty() {
        true => String::new(),
        false => format!(" (and {})", parts.join("; ")),
    }
}

/// Why a cut with clip planes holds nothing.
pub const CLIP_CUTS_ALL: &str = "the --clip planes cut every particle away (each keeps n·p ≤ d, \
     d the distance from the origin along the unit normal: check its sign)";

/// A note when the camera looks at a clip plane from the side it keeps: the cut face
/// then faces away, hidden behind the material kept (`n·eye ≤ d`).
fn clip_side_note(planes: &[[f32; 4]], camera: &mdlod_render::Camera) -> Option<String> {
    // A slab's two faces look opposite ways: one faces the camera whatever its side.
    let eye = camera.eye();
    let kept_side = |c: &[f32; 4]| mdlod_render::glam::Vec3::new(c[0], c[1], c[2]).dot(eye) <= c[3];
    // A plane seen edge-on (within 5°: a 2D layer seen square on, cut across) shows its
    // cut face from neither side.
    let edge_on = |c: &[f32; 4]| {
        let n = mdlod_render::glam::Vec3::new(c[0], c[1], c[2]).normalize_or_zero();
        n.dot(camera.back()).abs() < 5f32.to_radians().sin()
    };
    let noted = planes.iter().all(|c| kept_side(c) && !edge_on(c));
    (!planes.is_empty() && noted).then(|| {
        format!(
            "  note: the camera is on the kept side of {}: the cut face{} away, \
             behind the material kept; view from the side cut away (--azimuth turned by 180, \
             or --look-along reversed)",
            match planes.len() {
                1 => "the --clip plane".to_string(),
                n => format!("all {n} --clip planes"),
            },
            if planes.len() == 1 {
                " looks"
            } else {
                "s look"
            }
        )
    })
}

/// The points of a file's coarsest level below its top node.
pub(super) fn coarsest_points(file: &mdlod_format::MdlodFile) -> Option<u64> {
    file.levels().get(1).map(|l| l.point_count)
}

/// Why a cut stopped refining before the screen error, and what would refine it, as
/// " (reason; reason)"; empty when nothing stopped it. `coarsest`: the points of the
/// file's coarsest level ([`coarsest_points`]); `budget` is the --budget asked for (the
/// GPU may allow fewer points).
pub(super) fn limits_text(
    r: &mdlod_render::RenderReport,
    coarsest: Option<u64>,
    budget: u64,
) -> String {
    let mut limits = vec![];
    if r.budget_limited {
        // The top node opens into the whole coarsest level at once: a budget below it
        // leaves the data set one sphere.
        let drawn = r.particles_drawn + r.nodes_drawn;
        limits.push(match coarsest {
            Some(c) if drawn == 1 && r.budget < c => format!(
                "point budget of {}: below the {c} points the top node opens into (level 1, \
                 as `mdlod info` counts levels), so the whole data set is one sphere; a \
                 budget of {c} or more refines",
                r.budget
            ),
            _ if r.budget < budget => format!(
                "point budget reached: {} points, the most this GPU draws at once",
                r.budget
            ),
            _ => format!(
                "point budget of {} reached: a larger --budget refines further",
                r.budget
            ),
        });
    }
    if r.pool_limited {
        limits.push("GPU memory pool full: a larger --gpu-memory refines further".to_string());
    }
    if limits.is_empty() {
        String::new()
    } else {
        format!(" ({})", limits.join("; "))
    }
}

/// A note naming the images numbered past the last of the `n` just written to `pattern`
/// that an earlier run left (a longer movie or turntable into the same names): a player
/// or `ffmpeg -i` reading the numbered series would take them as more frames.
fn stale_images_note(pattern: &Path, n: usize) -> Option<String> {
    let first = frame_output(pattern, n).ok().filter(|p| p.exists())?;
    let mut last = first.clone();
    let mut count = 1usize;
    while let Some(p) = frame_output(pattern, n + count).ok().filter(|p| p.exists()) {
        last = p;
        count += 1;
    }
    let which = if count == 1 {
        format!("{} remains", first.display())
    } else {
        format!(
            "{count} images remain, {} to {}",
            first.display(),
            last.display()
        )
    };
    Some(format!(
        "  note: {which} from an earlier run, numbered past the last image written: a \
         player or `ffmpeg -i` reading the series would show {} as more frames; delete {}",
        if count == 1 { "it" } else { "them" },
        if count == 1 { "it" } else { "them" }
    ))
}

/// Refuses, before any image is drawn, a movie's or turntable's image `0..n` whose path
/// holds a symbolic link, a pipe or a device (`check_output` judges `-o` itself, whose
/// name is a pattern).
fn check_numbered_outputs(pattern: &Path, n: usize) -> Result<()> {
    for i in 0..n {
        let out = frame_output(pattern, i)?;
        if let Err(e) = mdlod_format::files::check_replaceable(&out) {
            anyhow::bail!("-o {}: image {}: {e}", pattern.display(), out.display());
        }
    }
    Ok(())
}

/// The image of frame `index` of a movie: `pattern` with its `%d` or `%0Nd` (as
/// ffmpeg reads them) replaced by the index.
fn frame_output(pattern: &Path, index: usize) -> Result<PathBuf> {
    let name = pattern
        .file_name()
        .and_then(|n| n.to_str())
        .with_context(|| format!("-o {}: no file name", pattern.display()))?;
    let bad = || {
        anyhow::anyhow!(
            "-o {}: a batch directory renders one image per frame: give a name with one %d \
             or %05d for the frame's number, e.g. movie/frame-%05d.png (a still of one \
             frame is rendered from its file in the directory, frame-<timestep>.mdlod)",
            pattern.display()
        )
    };
    let start = name.find('%').ok_or_else(bad)?;
    let rest = &name[start + 1..];
    let digits = rest.bytes().take_while(u8::is_ascii_digit).count();
    // `%d` or `%0Nd`: digits without a leading 0 would pad with spaces.
    let padded = digits == 0 || rest.starts_with('0');
    if !padded || rest.as_bytes().get(digits) != Some(&b'd') || rest[digits + 1..].contains('%') {
        return Err(bad());
    }
    let width: usize = if digits == 0 {
        0
    } else {
        rest[..digits].parse().map_err(|_| bad())?
    };
    // A frame number has at most 20 digits.
    if width > 20 {
        anyhow::bail!(
            "-o {}: frame numbers padded to {width} digits: give at most 20, e.g. %05d",
            pattern.display()
        );
    }
    let file = format!("{}{index:0width$}{}", &name[..start], &rest[digits + 1..]);
    Ok(pattern.with_file_name(file))
}

/// The line for one image of a movie or a turntable (`which` names it): what it drew.
/// The attribute the colours or splat light of `file` show, by name, and the range they
/// span (the style's, else the file's), where they show one: `--json`'s keys.
fn shown_json(
    args: &Args,
    opts: &RenderOptions,
    file: &mdlod_format::reader::MdlodFile,
) -> serde_json::Value {
    let a = file
        .metadata()
        .attribute
        .as_ref()
        .filter(|_| by_attribute(args));
    serde_json::json!({
        "attribute": a.map(|a| a.name.clone()),
        "attribute_range": a.map(|a| opts.style.attribute_range.unwrap_or([a.min, a.max])),
    })
}

/// With `--json`, the last line of a movie or turntable: what it wrote, with the notes
/// said after its images (on the whole series).
fn series_json(args: &Args) {
    if args.json {
        crate::print_json(serde_json::json!({
            "ok": true,
            "series": args.output.display().to_string(),
            "file": args.file.display().to_string(),
        }));
    }
}

/// The `--json` object of one image, with `more` (an object: a frame's or view's place)
/// added.
fn report_json(
    out: &Path,
    r: &mdlod_render::RenderReport,
    args: &Args,
    opts: &RenderOptions,
    more: serde_json::Value,
) -> serde_json::Value {
    use clap::ValueEnum;
    let c = &r.camera;
    let ms = |d: std::time::Duration| d.as_secs_f64() * 1e3;
    let mut value = serde_json::json!({
        "ok": true,
        "output": out.display().to_string(),
        "file": args.file.display().to_string(),
        "mode": args.mode.to_possible_value().map(|v| v.get_name().to_string()),
        "width": r.width,
        "height": r.height,
        "spp": r.spp,
        "particles_drawn": r.particles_drawn,
        "particles_hidden": r.particles_hidden,
        "particles_clipped": r.particles_clipped,
        "clusters_drawn": r.nodes_drawn,
        "draw_ranges": r.ranges,
        "clusters_occluded": r.nodes_occluded,
        "particles_occluded": r.particles_occluded,
        "error_px": r.error_px,
        "budget": r.budget,
        "budget_limited": r.budget_limited,
        // The GPU memory pool filled before the view was complete (`--gpu-memory`): the
        // image is coarser than the error asked.
        "pool_limited": r.pool_limited,
        "camera": {
            "projection": match c.projection {
                mdlod_render::camera::Projection::Perspective => "perspective",
                mdlod_render::camera::Projection::Orthographic => "orthographic",
            },
            "azimuth_deg": c.azimuth_deg,
            "elevation_deg": c.elevation_deg,
            "target": c.target.to_array(),
            "distance": c.distance,
            "fov_y_deg": c.fov_y_deg,
        },
        "milliseconds": {
            "total": ms(r.total_time),
            "traversal": ms(r.traversal_time),
            "gpu": r.gpu_time.map(ms),
        },
        "adapter": r.adapter,
        "backend": r.backend,
        // What the colours show: the attribute and the range its map spans (a figure's
        // to reproduce), a projection's light range, and where a legend went.
        "attribute": by_attribute(args).then(|| opts.style.attribute.clone()).flatten(),
        "attribute_range": opts.style.attribute_range.filter(|_| by_attribute(args)),
        "light_range": r.light_range,
        // Splats: the exposure chosen (which pieces of a movie share) and the light.
        "exposure": r.exposure,
        "total_flux": r.total_flux,
        "legend": args.legend.as_ref().map(|p| p.display().to_string()),
        "legend_in_image": args.legend_in_image.map(|c| {
            use clap::ValueEnum;
            c.to_possible_value().map(|v| v.get_name().to_string())
        }),
    });
    if let (serde_json::Value::Object(v), serde_json::Value::Object(m)) = (&mut value, more) {
        v.extend(m);
    }
    value
}

fn image_line(
    out: &Path,
    which: &str,
    r: &mdlod_render::RenderReport,
    args: &Args,
    coarsest: Option<u64>,
) -> String {
    format!(
        "wrote {} ({which}): {} particle{}{} and {} {}{}, error {:.2} px, {:.0} ms",
        out.display(),
        r.particles_drawn,
        if r.particles_drawn == 1 { "" } else { "s" },
        hidden_text(r, &args.style),
        r.nodes_drawn,
        counted(point_noun(args.mode), r.nodes_drawn),
        limits_text(r, coarsest, args.budget),
        r.error_px,
        r.total_time.as_secs_f64() * 1e3
    )
}

/// `--turntable N`: `n` views of one file, the azimuth turning by 360°/n from view to
/// view around the fitted (or saved) target, the same distance throughout (where fitted,
/// the largest of the views' fitted distances); for splats the
/// first view's exposure holds for all.
fn render_turntable(
    args: &Args,
    mut opts: RenderOptions,
    n: u32,
    derived: Option<String>,
) -> Result<()> {
    frame_output(&args.output, 0).map_err(|_| {
        anyhow::anyhow!(
            "-o {}: --turntable renders one image per view: give a name with one %d or %03d \
             for the view's number, e.g. spin/view-%03d.png",
            args.output.display()
        )
    })?;
    check_numbered_outputs(&args.output, n as usize)?;
    // A direction looked along sets the first view's angles.
    let along = args.camera.look_along.map(angles_looking_along);
    let start = match (
        &args.camera.view,
        args.camera.azimuth.or(along.map(|a| a.0)),
    ) {
        (Some(p), None) => ViewFile::load(p)?.azimuth_deg,
        (_, a) => a.unwrap_or(30.0),
    };
    if let Some(parent) = args.output.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent)
            .with_context(|| format!("cannot create {}", parent.display()))?;
    }
    let t0 = std::time::Instant::now();
    let renderer =
        mdlod_render::Renderer::new(mdlod_render::GpuContext::with_backends(opts.backends)?);
    let (mut limited, mut first_camera) = (0usize, None);
    // The faintest and brightest lit pixels over the views, for the legend's ends.
    let mut lit = None;
    // The species any view shows, for the legend's key.
    let mut drawn = std::collections::BTreeSet::new();
    let azimuth = |i: u32| start + 360.0 * i as f32 / n as f32;
    let mut views: Vec<ViewSpec> = (0..n)
        .map(|i| {
            ViewArgs {
                azimuth: Some(azimuth(i)),
                elevation: args.camera.elevation.or(along.map(|a| a.1)),
                look_along: None,
                ..args.camera.clone()
            }
            .spec()
        })
        .collect();
    // A fitted distance depends on the direction: every view takes the largest, so the
    // data keeps its size on screen through the turn and no view crops it. A fitted
    // target is the data's centre in every view (a still's fit moves it to centre the
    // picture in perspective, which would make the turn wobble).
    if view_fits(&args.camera.spec()) {
        let file = mdlod_render::open_styled(&args.file, &opts.style)?;
        let bounds = mdlod_render::fit_for(&file, &opts).bounds;
        let fitted_target = args.camera.target.is_none()
            && args
                .camera
                .view
                .as_ref()
                .is_none_or(|p| ViewFile::load(p).map_or(true, |v| v.target.is_none()));
        views = mdlod_render::movie::turntable_cameras(
            &bounds,
            &views,
            opts.width,
            opts.height,
            fitted_target,
            &opts.fit_windows,
        )?
        .into_iter()
        .map(ViewSpec::Camera)
        .collect();
    }
    // Every view is seen from one distance: one scale bar for all, an orthographic
    // view's, measured on a camera of the turn.
    let turn_bar = |c: &mdlod_render::Camera| -> Result<mdlod_render::legend::Legend> {
        let units = mdlod_render::open_styled(&args.file, &opts.style)?
            .metadata()
            .units
            .clone();
        scale_bar(
            c,
            opts.width,
            opts.height,
            args.scale_bar_length,
            args.scale_bar_unit.as_deref().or(units.as_deref()),
            args.text_scale,
        )
    };
    // (A fitted turn's: a perspective one is refused here, before any view is drawn.)
    let bar = match (&views[..], args.scale_bar) {
        ([ViewSpec::Camera(c), ..], true) => Some(turn_bar(c)?),
        _ => None,
    };
    let mut written = Vec::new();
    // Each view's camera, for its axes.
    let mut cameras = Vec::new();
    for (i, view) in (0..n).zip(views) {
        let azimuth = azimuth(i);
        opts.view = view;
        let out = frame_output(&args.output, i as usize)?;
        written.push(out.clone());
        let file = mdlod_render::open_styled(&args.file, &opts.style)?;
        let coarsest = coarsest_points(&file);
        let species = file.metadata().species.clone();
        let shown = shown_json(args, &opts, &file);
        // (Once: every view is of the one file.)
        let periodic_note = (i == 0)
            .then(|| {
                let drawn = mdlod_render::drawn_bounds(&file, &opts);
                periodic_kernels_note(args.mode, file.metadata().simulation_box.as_ref(), drawn)
            })
            .flatten();
        let r = mdlod_render::render_file_to_png(&renderer, file, &out, &opts)?;
        drawn = drawn_names(&r, &species, drawn);
        if i == 0 {
            first_camera = Some(r.camera.clone());
        }
        cameras.push(r.camera.clone());
        // Splats: one exposure (a projection's map: one range) for every view, or the
        // brightness flickers: the first view that shows anything sets it.
        if r.particles_drawn + r.nodes_drawn > 0 {
            opts.exposure = opts.exposure.or(r.exposure);
            opts.light_range = opts.light_range.or(r.light_range);
            lit = lit_union(lit, r.light_extent);
        }
        limited += usize::from(r.budget_limited || r.pool_limited);
        let which = format!(
            "view {i} of 0-{}, azimuth {:.1}°",
            n - 1,
            azimuth.rem_euclid(360.0)
        );
        println!("{}", image_line(&out, &which, &r, args, coarsest));
        if let Some(note) = periodic_note {
            println!("{note}");
        }
        if args.json {
            crate::print_json_part(report_json(&out, &r, args, &opts, {
                let mut more = shown;
                more["view"] = i.into();
                more["views"] = n.into();
                more
            }));
        }
    }
    let exposure = opts
        .exposure
        .filter(|_| matches!(args.mode, Mode::Splat))
        .map_or(String::new(), |e| format!(", splat exposure {e:.4e}"));
    let limited = match limited {
        0 => String::new(),
        k => format!("; {k} coarsened by the point budget or the GPU memory pool"),
    };
    let derived = match (derived, opts.style.attribute_range) {
        (Some(why), Some([lo, hi])) => format!(
            ", the attribute shown from {} to {} ({why})",
            Num(lo),
            Num(hi)
        ),
        _ => String::new(),
    };
    println!(
        "rendered {n} views in {:.1} s, a full turn about the vertical axis (z) from azimuth \
         {}°{exposure}{derived}{limited}",
        t0.elapsed().as_secs_f64(),
        start.rem_euclid(360.0)
    );
    if let Some(note) = stale_images_note(&args.output, n as usize) {
        println!("{note}");
    }
    let file = mdlod_render::open_styled(&args.file, &opts.style)?;
    for note in hides_nothing_notes(&opts.style, &file) {
        println!("{note}");
    }
    if view_fits(&args.camera.spec()) {
        if let Some(note) = far_note(mdlod_render::fit_for(&file, &opts).far_particles, None) {
            println!("{note}");
        }
    }
    if let (Some(p), Some(camera)) = (&args.save_view, first_camera) {
        save_view(p, &camera, [args.camera.width, args.camera.height])?;
        println!("  the first view saved to {}", p.display());
    }
    if args.legend.is_some() || args.legend_in_image.is_some() {
        let file = mdlod_render::open_styled(&args.file, &opts.style)?;
        let meta = file.metadata();
        let shown_attribute = legend_attribute(&file, &opts);
        write_legend(
            args,
            &opts,
            shown_attribute.as_ref(),
            &meta.species,
            opts.light_range.map(|range| (range, lit.unwrap_or(range))),
            &drawn,
            &written,
        )?;
    }
    if !args.label.is_empty() {
        let file = mdlod_render::open_styled(&args.file, &opts.style)?;
        let labelled: Vec<(PathBuf, label::Values)> = written
            .iter()
            .enumerate()
            .map(|(i, p)| {
                (
                    p.clone(),
                    label::Values::of_file(&args.file, file.metadata(), i),
                )
            })
            .collect();
        write_labels(args, &labelled, None)?;
    }
    // (A view not fitted, a view file's distance, is measured on the first view drawn.)
    let bar = match (bar, cameras.first()) {
        (None, Some(c)) if args.scale_bar => Some(turn_bar(c)?),
        (bar, _) => bar,
    };
    if let Some(bar) = &bar {
        let images: Vec<(&Path, &mdlod_render::legend::Legend)> =
            written.iter().map(|i| (i.as_path(), bar)).collect();
        draw_panels(args, &images, args.scale_bar_corner(), "--scale-bar")?;
    }
    if args.axes {
        // Each view its own tripod, turning with the data.
        let panels: Vec<_> = cameras.iter().map(axes_panel).collect();
        let images: Vec<(&Path, &mdlod_render::legend::Legend)> =
            written.iter().map(PathBuf::as_path).zip(&panels).collect();
        draw_panels(args, &images, args.axes_corner(), "--axes")?;
    }
    Ok(())
}

/// A note where a movie of a batch lacks frames an unfinished run has yet to write,
/// which would jump in time or end early without a sign (the frames the batch left out,
/// [`missing_frames_note`] names).
fn unfinished_note(manifest: &mdlod_preprocess::batch::Manifest) -> Option<String> {
    let listed = manifest.frames.len() as u64;
    let expected = manifest.expected_frames.filter(|&e| e > listed)?;
    Some(format!(
        "  note: the batch lists {listed} of the {expected} frames its run is to convert \
         (still running, or stopped: rerun it to finish): the images show only those, \
         with gaps in time or ending early"
    ))
}

/// A file whose species are the values of a column (structure types) holds only those
/// of its frame: a style naming another (a figure script run over every frame, hiding
/// HCP from a frame without any) does nothing there, and is dropped with a note instead
/// of refusing the frame. Files of types or elements likewise drop a style of a species
/// named as theirs are (a type number among type numbers, a name among names) that they
/// lack: ions that come later in the run, hidden or coloured by one script over every
/// frame. A name one of the frame's species spells in another case is refused as a
/// misspelling, and so is an element's name among type numbers (with a hint).
fn drop_absent_categories(path: &Path, style: &mut mdlod_render::PointStyle) -> Result<()> {
    // (The species only: the file as it is, whichever attribute the style reads.)
    let file = mdlod_format::MdlodFile::open(path)?;
    let m = file.metadata();
    let column = m.species_column.as_ref();
    let absent: std::collections::BTreeSet<String> = style
        .species
        .iter()
        .filter(|st| !m.species.iter().any(|s| s.name == st.name))
        .filter(|st| {
            // Only hidden, and named as the frame's species are (a type number among
            // type numbers, a name among names): a species of another frame of the run.
            let numbered = |n: &str| n.parse::<i64>().is_ok();
            let kind = m
                .species
                .iter()
                .all(|s| numbered(&s.name) == numbered(&st.name))
                || m.species
                    .iter()
                    .any(|s| numbered(&s.name) == numbered(&st.name))
                    && m.species
                        .iter()
                        .any(|s| numbered(&s.name) != numbered(&st.name));
            column.is_some() || kind
        })
        .map(|st| st.name.clone())
        .collect();
    if absent.is_empty() {
        return Ok(());
    }
    // A name one of the frame's spells otherwise is a misspelling, not an absent type;
    // so is an element's symbol in another case (`li`), where every species of the frame
    // is an element (not among Martini beads, whose `NA` is no sodium).
    let elements = m
        .species
        .iter()
        .all(|s| mdlod_preprocess::species::element_symbol(&s.name) == Some(s.name.as_str()));
    for name in &absent {
        let near = m
            .species
            .iter()
            .find(|s| s.name.eq_ignore_ascii_case(name))
            .map(|s| s.name.as_str())
            .or_else(|| {
                mdlod_preprocess::species::element_symbol(name).filter(|&e| elements && e != name)
            });
        if let Some(near) = near {
            anyhow::bail!(
                "{}: no species named {name:?}; did you mean {near:?}? (names are matched exactly)",
                path.display(),
            );
        }
    }
    let only_hidden = style
        .species
        .iter()
        .filter(|st| absent.contains(&st.name))
        .all(|st| st.hidden && st.colour.is_none() && st.radius.is_none());
    style.species.retain(|st| !absent.contains(&st.name));
    let names: Vec<&str> = m.species.iter().map(|s| s.name.as_str()).collect();
    let absent: Vec<String> = absent.into_iter().collect();
    match column {
        None if !only_hidden => println!(
            "  note: no particle of this frame is {} (its species are {}): the options \
             naming {} do nothing here",
            absent.join(" or "),
            names.join(", "),
            if absent.len() == 1 { "it" } else { "them" }
        ),
        Some(column) => println!(
            "  note: no particle of this frame is {} (its species are the values of \
             {column}: {}): the options naming {} do nothing here",
            absent.join(" or "),
            names.join(", "),
            if absent.len() == 1 { "it" } else { "them" }
        ),
        None => println!(
            "  note: --hide-species {}: no particle of this frame is {} (its species are {}): \
             nothing of {} to hide here",
            absent.join(","),
            absent.join(" or "),
            names.join(", "),
            if absent.len() == 1 { "it" } else { "them" }
        ),
    }
    Ok(())
}

/// Renders every frame of a batch directory (`args.file`) in its manifest's order, one
/// image each, all with one camera (fitted to every frame's clusters, within the union of
/// their bounds, so that nothing leaves the picture) and, for splats, the first frame's
/// exposure: a movie.
fn render_frames(
    args: &Args,
    mut opts: RenderOptions,
    legend_size: Option<[u32; 2]>,
) -> Result<()> {
    let dir = &args.file;
    super::view::unmerged_batch(dir)?;
    // A batch rewriting the frames would mix old and new ones into the movie: refused
    // (status 75, as a batch refused beside another: try again once it ends).
    if let Some(holder) = mdlod_preprocess::batch::batch_running(dir) {
        return Err(mdlod_preprocess::batch::BatchError::Busy {
            dir: dir.clone(),
            shard: String::new(),
            holder,
        }
        .into());
    }
    let manifest = mdlod_preprocess::batch::read_manifest(dir).with_context(|| {
        format!(
            "{}: a directory renders as the frames of a batch, listed in its dataset.json",
            dir.display()
        )
    })?;
    let n = manifest.frames.len();
    if n == 0 {
        anyhow::bail!("{}: dataset.json lists no frames", dir.display());
    }
    frame_output(&args.output, 0)?;
    check_numbered_outputs(&args.output, n)?;
    let fitted = view_fits(&opts.view);
    // One camera and one colour range for every frame. Species may come and go in a
    // trajectory (a deposition, an evaporation): a style names any species of some
    // frame, and applies in the frames that hold it.
    let mut survey = mdlod_render::movie::Survey::new();
    // Whether each attribute's hidden ranges meet its values in some frame.
    let mut range_hits = Vec::new();
    // (Every frame is opened first, about a millisecond each: seconds for thousands.)
    let progress = crate::progress::Bar::new();
    use mdlod_preprocess::Progress as _;
    progress.stage("framing the frames", Some(n as u64), "frames");
    for (i, f) in manifest.frames.iter().enumerate() {
        progress.advance(1);
        let path = dir.join(&f.file);
        // (Something else in its place, a directory say, the reader names.)
        if std::fs::symlink_metadata(&path).is_err() {
            anyhow::bail!(
                "{}: lists {} (timestep {}), but the file is missing (deleted or moved \
                 since the batch wrote it): rerun the batch, which converts missing frames \
                 again, or check the directory with `mdlod verify {}`",
                dir.join(mdlod_preprocess::batch::MANIFEST).display(),
                f.file,
                f.timestep,
                dir.display()
            );
        }
        let file = mdlod_render::open_styled(&path, &opts.style)
            .map_err(|e| damaged_frame(e.into(), dir, (i, n), f, &path))?;
        // A manifest edited or mixed with another run's frames labels the images wrongly.
        if let Some(t) = file.metadata().timestep.filter(|&t| t != f.timestep) {
            anyhow::bail!(
                "{}: lists {} as timestep {}, but the file holds timestep {t}: the manifest \
                 and the frame files disagree (`mdlod verify {}` checks them all)",
                dir.join(mdlod_preprocess::batch::MANIFEST).display(),
                f.file,
                f.timestep,
                dir.display()
            );
        }
        // A frame file replaced after the batch listed it (another frame converted in its
        // place): the manifest's checksum is its section table's, read on open.
        let checksum = format!("{:016x}", file.header().section_table_checksum);
        if checksum != f.checksum {
            anyhow::bail!(
                "{}: lists {} (timestep {}) with checksum {}, but the file's is {checksum}: \
                 it was replaced after the batch wrote the manifest (`mdlod verify {}` \
                 checks them all; delete it and rerun the batch to convert it again)",
                dir.join(mdlod_preprocess::batch::MANIFEST).display(),
                f.file,
                f.timestep,
                f.checksum,
                dir.display()
            );
        }
        // The labels' times come from the manifest: an edited one would label wrongly.
        if file.metadata().time != f.time {
            let time = |t: Option<f64>| t.map_or("none".to_string(), |t| format!("{t}"));
            anyhow::bail!(
                "{}: lists {} with time {}, but the file holds {}: the manifest and the \
                 frame files disagree (`mdlod verify {}` checks them all)",
                dir.join(mdlod_preprocess::batch::MANIFEST).display(),
                f.file,
                time(f.time),
                time(file.metadata().time),
                dir.display()
            );
        }
        if let Some(a) = file
            .metadata()
            .attribute
            .as_ref()
            .filter(|_| by_attribute(args))
        {
            check_not_logged(
                &opts.style,
                a,
                &path,
                lit_linearly(args),
                file.metadata().attribute_log10,
            )?;
        }
        join_range_hits(&mut range_hits, hidden_range_hits(&opts.style, &file));
        survey.add(&file, &opts);
    }
    progress.finish_stage();
    for note in hides_nothing_text(&range_hits, "in any frame") {
        println!("{note}");
    }
    let bounds = survey.bounds().expect("at least one frame");
    let names = survey.names();
    let attribute = survey.attribute();
    // A name no frame has is a misspelling (the movie knows every frame's species; a
    // still hides a species its frame lacks with a note, for a script over a run).
    if let Some(st) = opts.style.species.iter().find(|s| !names.contains(&s.name)) {
        let near = names.iter().find(|n| n.eq_ignore_ascii_case(&st.name));
        anyhow::bail!(
            "no frame of {} has a species named {:?}{} (its frames have {})",
            dir.display(),
            st.name,
            near.map_or_else(String::new, |n| format!("; did you mean {n:?}?")),
            names.iter().cloned().collect::<Vec<_>>().join(", ")
        );
    }
    let mut range_note = String::new();
    let chosen = attribute.and_then(|a| {
        // (A projection's log is the image's, not the points', as for a still.)
        mdlod_render::style::default_range(
            [a.min, a.max],
            lit_linearly(args),
            by_attribute(args) && !projected(args),
            opts.style.log_scale,
            opts.style.colour_map,
            survey.log_floor(),
        )
        .map(|(range, why)| (a, range, why))
    });
    if let Some((a, range, why)) = chosen.filter(|_| opts.style.attribute_range.is_none()) {
        // (Centred: a diverging map over signed values, white 0 in every frame.)
        opts.style.attribute_range = Some(range);
        opts.style.range_derived = true;
        range_note = format!(
            ", {} from {} to {} ({}; every frame's range is {} to {}; --attribute-range sets \
             another)",
            a.name,
            Num(range[0]),
            Num(range[1]),
            why.why(),
            Num(a.min),
            Num(a.max)
        );
    }
    // (Over the particles drawn where some are hidden or cut away: a movie of one frame
    // too, as a still maps them, which its legend said while its image took the file's
    // range.)
    let partial = opts.style.leaves_some_out();
    if by_attribute(args) && opts.style.attribute_range.is_none() {
        // Where the frames' union is no range (a constant attribute), each frame keeps
        // its own constant look.
        if let Some(a) = attribute.filter(|_| n > 1 || partial) {
            if a.max > a.min {
                opts.style.attribute_range = Some([a.min, a.max]);
                opts.style.range_derived = true;
                let whose = match !partial {
                    true => "every frame's range",
                    false => "every frame's particles drawn, those hidden or cut away left out",
                };
                range_note = format!(
                    ", {} from {} to {} ({whose}; --attribute-range sets another)",
                    a.name,
                    Num(a.min),
                    Num(a.max)
                );
            } else {
                // As a still says it: the map places no value of a constant attribute.
                let fate = match args.mode {
                    Mode::Splat if a.min > 0.0 => {
                        "every splat is lit alike (its light the value times its disk's area)"
                    }
                    Mode::Splat => "every splat is lit alike (its light its disk's area)",
                    _ => "every particle takes the map's last colour",
                };
                range_note = format!(
                    "; {} is {} in every frame (constant): {fate}; --attribute-range places \
                     it on a scale",
                    a.name,
                    Num(a.min)
                );
            }
        }
    }
    if let Some(a) = attribute {
        if by_attribute(args) {
            range_note.push_str(&log_text(a, &opts.style, args));
            range_note.push_str(&white_text(&opts.style));
        }
    }
    // Each frame's file fixed its species' looks alone: a name keeps one look throughout.
    let looks = mdlod_render::style::trajectory_looks(
        &survey
            .species()
            .iter()
            .map(Vec::as_slice)
            .collect::<Vec<_>>(),
    );
    let (mut restyled, mut restyled_names) = (0usize, std::collections::BTreeSet::new());
    // Each name's smallest and largest radius as drawn: a frame's own radii are data.
    let mut radii: std::collections::BTreeMap<String, [f32; 2]> = Default::default();
    let mut worst_miss: Option<(f32, usize)> = None;
    let style = opts.style.clone();
    opts.view = opts.view.with_flat_axis(survey.flat_axis());
    let camera = mdlod_render::camera_for_framing_in(
        &bounds,
        survey.boxes(),
        &opts.view,
        opts.width,
        opts.height,
        &opts.fit_windows,
    )
    .map_err(|e| match e {
        // Frames whose data spans more than single precision draws: said of the directory
        // (only a damaged frame file holds such bounds), not of options never given.
        mdlod_render::RenderError::InvalidOptions(m) if !mdlod_render::drawable_bounds(&bounds) => {
            anyhow::anyhow!(
                "{}: the frames' data spans {}, more than single precision can draw (a \
                 damaged frame file? `mdlod verify {}` checks every frame): {m}",
                dir.display(),
                mdlod_render::bounds_text(&bounds),
                dir.display()
            )
        }
        e => e.into(),
    })?;
    opts.view = ViewSpec::Camera(camera.clone());
    if let Some(parent) = args.output.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent)
            .with_context(|| format!("cannot create {}", parent.display()))?;
    }
    let frame_values: Vec<label::Values> = manifest
        .frames
        .iter()
        .enumerate()
        .map(|(i, f)| label::Values {
            timestep: Some(f.timestep),
            time: f.time,
            frame: i,
            particles: f.particles,
            file: f.file.clone(),
            source: Some(label::source_name(&f.source.path)).filter(|s| !s.is_empty()),
        })
        .collect();
    let label_size = check_label_room(args, &frame_values.iter().collect::<Vec<_>>())?;
    // One camera for every frame: one scale bar, in the first frame's units.
    let bar = match args.scale_bar {
        true => {
            let first = mdlod_format::MdlodFile::open(dir.join(&manifest.frames[0].file))?;
            Some(scale_bar(
                &camera,
                opts.width,
                opts.height,
                args.scale_bar_length,
                args.scale_bar_unit
                    .as_deref()
                    .or(first.metadata().units.as_deref()),
                args.text_scale,
            )?)
        }
        false => None,
    };
    let axes = args.axes.then(|| axes_panel(&camera));
    check_panels_apart(args, legend_size, label_size, bar.as_ref(), axes.as_ref())?;
    let t0 = std::time::Instant::now();
    let mut limited_frames = 0usize;
    // The faintest and brightest lit pixels over the frames, for the legend's ends.
    let mut lit = None;
    // The species any frame shows, for the legend's key.
    let mut drawn = std::collections::BTreeSet::new();
    let renderer =
        mdlod_render::Renderer::new(mdlod_render::GpuContext::with_backends(opts.backends)?);
    let mut written = Vec::new();
    // The timesteps of the frames that drew nothing.
    let mut empty_frames = Vec::new();
    let selected: Vec<usize> = (0..n)
        .filter(|&i| args.frames.is_none_or(|sel| sel.takes(i)))
        .collect();
    if selected.is_empty() {
        anyhow::bail!(
            "--frames selects none of the {n} frames of {} (positions 0 to {})",
            dir.display(),
            n - 1
        );
    }
    // (Each image its own frame's values, also of a piece of the movie, whose times are
    // written as the whole movie's.)
    let movie_values: Vec<&label::Values> = frame_values.iter().collect();
    let drawn_values: Vec<&label::Values> = selected.iter().map(|&i| &frame_values[i]).collect();
    let mut panels = FramePanels::new(args, &drawn_values, &movie_values, bar, axes);
    for (i, f) in manifest.frames.iter().enumerate() {
        if args.frames.is_some_and(|sel| !sel.takes(i)) {
            continue;
        }
        let out = frame_output(&args.output, i)?;
        written.push(out.clone());
        let path = dir.join(&f.file);
        let damaged = |e| damaged_frame(e, dir, (i, n), f, &path);
        let file = mdlod_render::open_styled(&path, &opts.style).map_err(|e| damaged(e.into()))?;
        opts.style.species = mdlod_render::style::frame_styles(
            &file.metadata().species,
            &looks,
            &style.species,
            opts.style.colour_map.is_some(),
            opts.style.palette,
        );
        let changed: Vec<String> = opts
            .style
            .species
            .iter()
            .filter(|st| !style.species.contains(st))
            .map(|st| st.name.clone())
            .collect();
        restyled += usize::from(!changed.is_empty());
        restyled_names.extend(changed);
        for sp in &file.metadata().species {
            let style = opts.style.species.iter().rfind(|st| st.name == sp.name);
            // (A hidden species is drawn at no radius.)
            if style.is_some_and(|st| st.hidden) {
                continue;
            }
            let drawn = style.and_then(|st| st.radius).unwrap_or(sp.radius);
            let span = radii.entry(sp.name.clone()).or_insert([drawn; 2]);
            *span = [span[0].min(drawn), span[1].max(drawn)];
        }
        if matches!(args.mode, Mode::Spheres | Mode::Sndf) {
            let miss = opts.style.recolour_miss(&file.metadata().species);
            if miss.is_some_and(|m| m > worst_miss.map_or(0.0, |w: (f32, usize)| w.0)) {
                worst_miss = miss.map(|m| (m, file.metadata().species.len()));
            }
        }
        let coarsest = coarsest_points(&file);
        let species = file.metadata().species.clone();
        let shown = shown_json(args, &opts, &file);
        // (Once, of the first frame's cell.)
        let periodic_note = (i == 0)
            .then(|| {
                let drawn = mdlod_render::drawn_bounds(&file, &opts);
                periodic_kernels_note(args.mode, file.metadata().simulation_box.as_ref(), drawn)
            })
            .flatten();
        let started = std::time::Instant::now();
        let (mut image, mut r) = mdlod_render::render_file_to_image(&renderer, file, &opts)
            .map_err(|e| damaged(e.into()))?;
        panels.draw(args, written.len() - 1, &mut image, &out)?;
        image.save_png(&out)?;
        r.total_time = started.elapsed();
        drawn = drawn_names(&r, &species, drawn);
        // Splats: one exposure (a projection's map: one range) for every frame, or the
        // brightness drifts: the first frame that shows anything sets it.
        if r.particles_drawn + r.nodes_drawn > 0 {
            opts.exposure = opts.exposure.or(r.exposure);
            opts.light_range = opts.light_range.or(r.light_range);
            lit = lit_union(lit, r.light_extent);
        } else {
            empty_frames.push(f.timestep);
        }
        limited_frames += usize::from(r.budget_limited || r.pool_limited);
        // (Counted from 0, as the images' numbers and --frames count them.)
        let which = format!("frame {i} of 0-{}, timestep {}", n - 1, f.timestep);
        println!("{}", image_line(&out, &which, &r, args, coarsest));
        if let Some(note) = periodic_note {
            println!("{note}");
        }
        if args.json {
            crate::print_json_part(report_json(&out, &r, args, &opts, {
                let mut more = shown;
                more["frame"] = i.into();
                more["frames"] = n.into();
                more["timestep"] = f.timestep.into();
                // (`--dt` replaces a recorded time, as in the label.)
                more["time"] = args.dt.map(|dt| f.timestep as f64 * dt).or(f.time).into();
                more["frame_file"] = dir.join(&f.file).display().to_string().into();
                more
            }));
        }
    }
    let exposure = opts
        .exposure
        .map_or(String::new(), |e| format!(", splat exposure {e:.4e}"));
    // A projection's light range, where the first frame chose it: said, so that a
    // collapse whose later frames saturate is set right with it.
    let exposure = match (opts.light_range, args.light_range) {
        (Some([lo, hi]), None) if projected(args) => format!(
            "{exposure}, light range {}:{} (the first frame's; --light-range MIN:MAX gives \
             one)",
            super::Num(lo),
            super::Num(hi)
        ),
        _ => exposure,
    };
    let framing = match &args.camera.view {
        Some(v) => format!("{}", v.display()),
        None if args.fit_all => "fitted to every frame's particles".to_string(),
        None => "fitted to every frame's material".to_string(),
    };
    // Splats and the density volume draw the files' own colours.
    let looks_note = match restyled {
        0 => String::new(),
        _ if !matches!(args.mode, Mode::Spheres | Mode::Sndf) => String::new(),
        k => format!(
            "; {k} frame{} whose files gave a species another colour (a name read \
             otherwise, or a palette colour another species has in other frames) drawn with \
             its one look ({})",
            if k == 1 { "" } else { "s" },
            restyled_names.into_iter().collect::<Vec<_>>().join(", ")
        ),
    };
    let changing: Vec<String> = radii
        .iter()
        .filter(|(_, [lo, hi])| hi > &(lo * 1.01))
        .map(|(name, [lo, hi])| format!("{name}: {}", super::info::radius_range_text(*lo, *hi)))
        .collect();
    let radii_note = match changing.is_empty() {
        true => String::new(),
        false => format!(
            "; species' radii change over the frames ({}): each frame is drawn with its own",
            changing.join(", ")
        ),
    };
    let limited = match limited_frames {
        0 => String::new(),
        k => format!("; {k} coarsened by the point budget or the GPU memory pool"),
    };
    let count = match selected.len() {
        k if k == n => format!("{n} frame{}", if n == 1 { "" } else { "s" }),
        k => format!("{k} of the {n} frames (--frames)"),
    };
    println!(
        "rendered {count} in {:.1} s, one camera for all ({framing}){exposure}{range_note}{looks_note}{radii_note}{limited}",
        t0.elapsed().as_secs_f64()
    );
    if let Some(note) = missing_frames_note(&manifest, dir) {
        println!("{note}");
    }
    // (A piece of a movie leaves the others' images alone.)
    if let Some(note) = stale_images_note(&args.output, n).filter(|_| args.frames.is_none()) {
        println!("{note}");
    }
    // Splats: the first frame drawn chose the exposure (a projection's range), which
    // another piece's first frame would choose otherwise.
    let chosen_here = (args.exposure.is_none() && args.mode == Mode::Splat && !projected(args))
        || (projected(args) && args.light_range.is_none());
    if args.frames.is_some() && selected[0] != 0 && chosen_here {
        println!(
            "  note: this piece's first frame chose the splats' {}: pieces rendered apart \
             match when each is given the same (the first piece's: {})",
            if projected(args) {
                "light range"
            } else {
                "exposure"
            },
            if projected(args) {
                "--light-range MIN:MAX"
            } else {
                "--exposure E"
            }
        );
    }
    if names.iter().all(|n| args.style.hide_species.contains(n)) {
        println!("  note: every species is hidden: the images show the background only");
    } else if !empty_frames.is_empty() {
        let shown: Vec<String> = empty_frames.iter().take(8).map(u64::to_string).collect();
        let more = match empty_frames.len() {
            k if k > 8 => format!(" and {} more", k - 8),
            _ => String::new(),
        };
        println!(
            "  note: {} of the {n} frames draw nothing (timestep {}{more}): every particle \
             hidden (--hide-species, --hide-attribute), cut away (--clip) or out of view",
            empty_frames.len(),
            shown.join(", ")
        );
    }
    if let Some(note) = worst_miss.and_then(|(m, n)| recolour_note(Some(m), n)) {
        println!("{note}");
    }
    if let Some(note) = unfinished_note(&manifest) {
        println!("{note}");
    }
    let (far, far_frames) = survey.far();
    if let Some(note) = far_note(far, Some(far_frames)).filter(|_| fitted) {
        println!("{note}");
    }
    if let (Some([lo, hi]), Some(a)) = (args.style.attribute_range, attribute) {
        if by_attribute(args) && (hi < a.min || lo > a.max) {
            println!(
                "  note: the range {} to {} misses every frame's values ({} from {} to {}): \
                 every particle takes one end of the map",
                Num(lo),
                Num(hi),
                a.name,
                Num(a.min),
                Num(a.max)
            );
        }
    }
    if let Some(p) = &args.save_view {
        save_view(p, &camera, [args.camera.width, args.camera.height])?;
        println!("  view saved to {}", p.display());
    }
    // The movie's range (every frame's, or the one given) and its names' looks.
    // The user's styles over the names' looks (each frame's own styles were for it).
    opts.style.species = style.species;
    // A piece of the movie keys every species of the movie's frames but those hidden
    // (it drew only its own frames; another piece would key others).
    if args.frames.is_some_and(|_| selected.len() < n) {
        drawn = names
            .iter()
            .filter(|name| {
                !opts
                    .style
                    .species
                    .iter()
                    .any(|st| &st.name == *name && st.hidden)
            })
            .cloned()
            .collect();
    }
    write_legend(
        args,
        &opts,
        attribute,
        &looks,
        opts.light_range.map(|range| (range, lit.unwrap_or(range))),
        &drawn,
        &written,
    )?;
    panels.notes(args, written.len(), &movie_values);
    Ok(())
}

/// `e`, from frame `i` of `n` of the batch directory `dir` (its file `path`), with what
/// mends it when it says the file is damaged.
fn damaged_frame(
    e: anyhow::Error,
    dir: &Path,
    (i, n): (usize, usize),
    frame: &mdlod_preprocess::batch::FrameEntry,
    path: &Path,
) -> anyhow::Error {
    if !is_damage(&e) {
        return e;
    }
    // (A frame whose dump is gone cannot be converted again: deleting its file loses it.)
    e.context(format!(
        "frame {i} of 0-{} (timestep {}) is damaged: while its dump {} is at hand, delete \
         {} and rerun `mdlod batch` with the same inputs, which converts it again (`mdlod \
         verify {}` checks every frame)",
        n - 1,
        frame.timestep,
        frame.source.path,
        path.display(),
        dir.display()
    ))
}

/// Whether `e` says a file's bytes are damaged (a checksum that does not match, a value
/// out of its place, metadata that is no JSON), not that it could not be read.
fn is_damage(e: &anyhow::Error) -> bool {
    use mdlod_format::FormatError;
    let damage = |f: &FormatError| {
        matches!(
            f,
            FormatError::Checksum { .. }
                | FormatError::Corrupt { .. }
                | FormatError::Metadata { .. }
        )
    };
    e.chain().any(|c| {
        c.downcast_ref::<FormatError>().is_some_and(damage)
            || matches!(
                c.downcast_ref::<mdlod_render::RenderError>(),
                Some(mdlod_render::RenderError::Format(f)) if damage(f)
            )
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Args as _;

    /// `--kernel-scale` within (0, 100]; light and view directions finite, not zero,
    /// and scaled where their squares would leave single precision.
    #[test]
    fn kernel_scales_and_directions_parse_within_their_ranges() {
        assert_eq!(parse_kernel_scale("2.5"), Ok(2.5));
        assert_eq!(parse_kernel_scale("100"), Ok(100.0));
        for bad in ["0", "-1", "1e10", "NaN", "inf", "x"] {
            assert!(parse_kernel_scale(bad).is_err(), "{bad}");
        }
        // A direction too long or too short for single precision's squares keeps its
        // direction, its largest component 1; an ordinary one is kept as given.
        assert_eq!(parse_direction("1e20,0,0"), Ok([1.0, 0.0, 0.0]));
        assert_eq!(parse_direction("0,-1e-30,0"), Ok([0.0, -1.0, 0.0]));
        assert_eq!(parse_direction("-0.35,0.45,1"), Ok([-0.35, 0.45, 1.0]));
        assert!(parse_direction("0,0,0").is_err());
        assert!(parse_direction("1,NaN,0").is_err());
    }

    /// Sizes: units, 0 refused where a pool or limit cannot be empty (and taken where
    /// it means "no pool"), 2^64 bytes and beyond refused rather than saturated.
    #[test]
    fn sizes_parse_with_units_and_stay_within_64_bits() {
        assert_eq!(parse_bytes("512M"), Ok(512 << 20));
        assert_eq!(parse_bytes("1.5G"), Ok(3 << 29));
        assert_eq!(parse_bytes("64KiB"), Ok(64 << 10));
        assert!(parse_bytes("0").unwrap_err().contains("leaves no room"));
        assert!(parse_bytes("18446744073709551616")
            .unwrap_err()
            .contains("beyond any memory"));
        assert!(parse_bytes("16777216T").is_err());
        assert!(parse_bytes("1e30").unwrap_err().contains("not an exponent"));
        assert_eq!(parse_bytes_or_zero("0"), Ok(0));
        assert_eq!(parse_bytes_or_zero("0M"), Ok(0));
        assert_eq!(parse_bytes_or_zero("2G"), Ok(2 << 30));
        assert!(parse_bytes_or_zero("x").is_err());
        assert!(parse_bytes_or_zero("0Q").is_err());
    }

    /// Splats lit by a logarithm: a file whose clusters keep the logarithm of their mean
    /// value lights by the quantity; one of an earlier mdlod (means of logarithms) is
    /// refused, saying to convert it again; a log scale of the logarithm itself is
    /// refused where no splat lights by it.
    #[test]
    fn splats_by_a_logarithm_need_its_clusters_mean_values() {
        let a = mdlod_format::meta::AttributeInfo {
            name: "log10(rho)".into(),
            min: -6.0,
            max: 2.0,
            log10: false,
        };
        let style = mdlod_render::PointStyle::default();
        let path = std::path::Path::new("sph.mdlod");
        assert!(check_not_logged(&style, &a, path, true, true).is_ok());
        let e = check_not_logged(&style, &a, path, true, false)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("sph.mdlod holds log10(rho)") && e.contains("convert it again"),
            "{e}"
        );
        let logged = mdlod_render::PointStyle {
            log_scale: true,
            ..Default::default()
        };
        assert!(check_not_logged(&logged, &a, path, true, true).is_ok());
        let e = check_not_logged(&logged, &a, path, false, true)
            .unwrap_err()
            .to_string();
        assert!(e.contains("already a logarithm"), "{e}");
    }

    /// A scale bar names LAMMPS unit styles by their length, and a unit of another name
    /// (a raw sidecar's) as written, where the image font can draw it.
    #[test]
    fn scale_bars_name_their_units() {
        assert_eq!(length_unit(Some("metal")), "Å");
        assert_eq!(length_unit(Some("LJ")), "σ");
        assert_eq!(length_unit(Some("nano")), "nm");
        assert_eq!(length_unit(Some("Mpc/h")), "Mpc/h");
        assert_eq!(length_unit(Some("kpc")), "kpc");
        assert_eq!(length_unit(Some("Mpc h^-1")), "Mpc h^-1");
        assert_eq!(length_unit(Some("a unit far too long")), "");
        assert_eq!(length_unit(None), "");
        // Metric lengths below 1 take a prefix.
        let shown = |l, u| {
            let (v, u) = metric_length(l, u);
            format!("{} {u}", crate::commands::Num(v as f32))
        };
        assert_eq!(shown(0.02, "m"), "20 mm");
        assert_eq!(shown(5e-6, "m"), "5 µm");
        assert_eq!(shown(0.5, "cm"), "5 mm");
        assert_eq!(shown(2.0, "cm"), "2 cm");
        assert_eq!(shown(0.001, "m"), "1 mm");
        assert_eq!(shown(2e-12, "m"), "2e-12 m");
        assert_eq!(shown(0.5, "nm"), "0.5 nm");
        assert_eq!(shown(0.5, "Å"), "0.5 Å");
    }

    /// The kernel modes say that a periodic cell's faces do not wrap their kernels,
    /// naming the periodic axes; spheres, and cells of no periodic axis, say nothing.
    #[test]
    fn kernels_of_a_periodic_cell_are_noted_as_not_wrapped() {
        let cell = |periodic, c| mdlod_format::meta::SimulationBox {
            origin: [0.0; 3],
            a: [10.0, 0.0, 0.0],
            b: [0.0, 10.0, 0.0],
            c,
            periodic,
        };
        let cube = |p| cell(p, [0.0, 0.0, 10.0]);
        // Kernels reaching past every face, and kernels inside the cell but past x = 0.
        let everywhere = Some(mdlod_render::Bounds::new([-1.0; 3], [11.0; 3]));
        let at_x = Some(mdlod_render::Bounds::new([-0.5, 4.0, 4.0], [6.0; 3]));
        let note = |mode, cell: &mdlod_format::meta::SimulationBox, drawn| {
            periodic_kernels_note(mode, Some(cell), drawn)
        };
        let said = note(Mode::Splat, &cube(Some([true, true, false])), everywhere).unwrap();
        assert!(said.contains("periodic along x and y, but kernels are not wrapped"));
        assert!(said.contains("the splats' light reads low"), "{said}");
        let said = note(Mode::Density, &cube(Some([true; 3])), everywhere).unwrap();
        assert!(said.contains("along x, y and z") && said.contains("the density reads low"));
        // Only the axes whose faces the kernels cross.
        let said = note(Mode::Splat, &cube(Some([true; 3])), at_x).unwrap();
        assert!(said.contains("periodic along x, but"), "{said}");
        assert_eq!(
            note(Mode::Splat, &cube(Some([false, true, true])), at_x),
            None
        );
        // A two-dimensional run's cell: no edge along z, periodic in the plane only.
        let said = note(Mode::Splat, &cell(Some([true; 3]), [0.0; 3]), everywhere).unwrap();
        assert!(said.contains("along x and y,"), "{said}");
        assert_eq!(
            note(Mode::Spheres, &cube(Some([true; 3])), everywhere),
            None
        );
        assert_eq!(note(Mode::Splat, &cube(Some([false; 3])), everywhere), None);
        assert_eq!(note(Mode::Iso, &cube(None), everywhere), None);
        assert_eq!(periodic_kernels_note(Mode::Iso, None, everywhere), None);
    }

    /// Splats lit by a column spanning decades say its small values' light is off.
    #[test]
    fn splats_of_a_column_of_many_decades_are_noted() {
        let a = |min: f32, max: f32| mdlod_format::meta::AttributeInfo {
            name: "sigma".into(),
            min,
            max,
            log10: false,
        };
        let note = decades_light_note(&a(0.117, 7.3e5)).expect("a note");
        assert!(note.contains("sigma spans 6.8 decades"), "{note}");
        assert_eq!(decades_light_note(&a(1.0, 9000.0)), None);
        assert_eq!(decades_light_note(&a(0.0, 1e9)), None);
    }

    /// `--look-along D` puts the eye towards `-D` from the target: the camera's `back`
    /// is `-D` normalised, straight down included.
    #[test]
    fn looking_along_a_direction_puts_the_eye_behind_it() {
        for d in [
            [1.0, 1.0, 1.0],
            [-1.0, 0.0, 0.0],
            [0.0, 0.0, -1.0],
            [0.0, 0.0, 2.0],
            [1.0, -2.0, 0.5],
        ] {
            let (azimuth_deg, elevation_deg) = angles_looking_along(d);
            let c = mdlod_render::Camera {
                azimuth_deg,
                elevation_deg,
                ..Default::default()
            };
            let want = -mdlod_render::glam::Vec3::from(d).normalize();
            assert!((c.back() - want).length() < 1e-5, "{d:?}: {:?}", c.back());
        }
        assert_eq!(angles_looking_along([-1.0, 0.0, 0.0]), (0.0, 0.0));
        // Straight down or up, +y is up on screen.
        for d in [[0.0, 0.0, -1.0], [0.0, 0.0, 3.0]] {
            let (azimuth_deg, elevation_deg) = angles_looking_along(d);
            let c = mdlod_render::Camera {
                azimuth_deg,
                elevation_deg,
                ..Default::default()
            };
            assert!(c.up().y > 0.9999, "{d:?}: {:?}", c.up());
        }
        assert!(parse_direction("0,0,0").is_err() && parse_direction("1,2").is_err());
    }

    /// The camera on the kept side of a plane is told to look from the other side,
    /// unless it sees the plane edge-on (a 2D layer seen square on, cut across), where
    /// neither side shows the cut face.
    #[test]
    fn the_kept_side_note_leaves_out_planes_seen_edge_on() {
        let camera = |azimuth_deg: f32, elevation_deg: f32| mdlod_render::Camera {
            target: mdlod_render::glam::Vec3::new(30.0, 20.0, 0.0),
            azimuth_deg,
            elevation_deg,
            ..Default::default()
        };
        let plane = [[1.0, 0.0, 0.0, 40.0]];
        assert_eq!(clip_side_note(&plane, &camera(-90.0, 90.0)), None);
        assert!(clip_side_note(&plane, &camera(30.0, 20.0)).is_some());
        // A plane facing the camera square on is noted looking down too.
        assert!(clip_side_note(&[[0.0, 0.0, 1.0, 100.0]], &camera(-90.0, 90.0)).is_some());
    }

    #[test]
    fn images_left_past_the_last_frame_by_an_earlier_run_are_named() {
        let dir = tempfile::tempdir().unwrap();
        let pattern = dir.path().join("f-%03d.png");
        let touch = |i: usize| std::fs::write(frame_output(&pattern, i).unwrap(), b"").unwrap();
        for i in 0..5 {
            touch(i);
        }
        assert_eq!(stale_images_note(&pattern, 5), None);
        touch(5);
        let one = stale_images_note(&pattern, 5).unwrap();
        assert!(
            one.contains("f-005.png remains from an earlier run"),
            "{one}"
        );
        for i in 6..12 {
            touch(i);
        }
        let many = stale_images_note(&pattern, 5).unwrap();
        assert!(
            many.contains("7 images remain")
                && many.contains("f-005.png to ")
                && many.contains("f-011.png"),
            "{many}"
        );
    }

    #[test]
    fn movie_names_take_the_frame_number_as_ffmpeg_reads_them() {
        let name = |p: &str, i| frame_output(Path::new(p), i).map(|p| p.display().to_string());
        assert_eq!(name("m/f-%05d.png", 7).unwrap(), "m/f-00007.png");
        assert_eq!(name("%d.png", 12).unwrap(), "12.png");
        assert_eq!(name("x%03dy.png", 4).unwrap(), "x004y.png");
        for bad in [
            "m/f.png",
            "f-%s.png",
            "f-%d-%d.png",
            "f-%5.png",
            "f-%3d.png",
        ] {
            let e = name(bad, 0).unwrap_err().to_string();
            assert!(e.contains("one image per frame"), "{bad}: {e}");
        }
        assert_eq!(name("%020d", 1).unwrap(), format!("{:020}", 1));
        for huge in [
            "f-%021d.png",
            "f-%070000d.png",
            "f-%099999999999999999999999d.png",
        ] {
            let e = name(huge, 0).unwrap_err().to_string();
            assert!(
                e.contains("at most 20") || e.contains("one image"),
                "{huge}: {e}"
            );
        }
    }

    #[test]
    fn every_mode_option_names_an_argument_of_render() {
        let cmd = Args::augment_args(clap::Command::new("render"));
        for (id, modes) in MODE_OPTIONS {
            assert!(
                cmd.get_arguments().any(|a| a.get_id() == *id),
                "{id} is no argument of render"
            );
            assert!(!modes.is_empty());
        }
    }
}
