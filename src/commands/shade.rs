//! `mdlod shade`: light stored S-NDFs (a `.sndf` file) and write a PNG; no particle data,
//! no GPU.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use mdlod_render::glam::Vec3;
use mdlod_render::parse_colour;
use mdlod_render::sndf::ShadeLights;

/// Shade a .sndf file (written by `mdlod sample`) under new lights, at its own resolution
/// or a coarser S-MIP level, without the particles.
#[derive(clap::Args)]
#[command(
    allow_negative_numbers = true,
    after_help = "Example:\n  \
    mdlod shade view.sndf -o lit.png --light -1,1,1 --light 1,0,0.5:#4060ff --brdf lambert"
)]
pub struct Args {
    /// The .sndf file to shade (written by `mdlod sample`).
    pub input: PathBuf,
    /// The PNG to write.
    #[arg(short, long)]
    pub output: PathBuf,
    /// A directional light: direction towards it in view space (x right, y up, z to the
    /// viewer), optionally with a colour, e.g. `-1,1,1` or `1,0,0.5:#4060ff`; repeatable.
    /// Default: one white light from the upper left.
    #[arg(
        long = "light",
        value_name = "X,Y,Z[:COLOUR]",
        allow_hyphen_values = true
    )]
    pub lights: Vec<String>,
    /// Ambient light.
    #[arg(long, default_value_t = 0.15)]
    pub ambient: f32,
    /// Lambert weight.
    #[arg(long, default_value_t = 0.85)]
    pub diffuse: f32,
    /// Reflectance: Lambert only, or Lambert plus a Blinn-Phong highlight.
    #[arg(long, value_enum, ignore_case = true, default_value = "blinn-phong")]
    pub brdf: Brdf,
    /// Blinn-Phong highlight weight (with --brdf blinn-phong).
    #[arg(long, default_value_t = 0.25)]
    pub specular: f32,
    /// Blinn-Phong highlight exponent: larger is a smaller, sharper highlight.
    #[arg(long, default_value_t = 32.0)]
    pub exponent: f32,
    /// An environment map (equirectangular PNG in view space, like a material capture):
    /// adds its Lambert irradiance. Without --light, it is the only light besides the
    /// ambient.
    #[arg(long, value_name = "PNG")]
    pub envmap: Option<PathBuf>,
    /// Colour the normals instead of lighting them: the explorer pattern with this many
    /// azimuthal slices around a central disk.
    #[arg(long, value_name = "SLICES")]
    pub explorer: Option<u32>,
    /// Colour the normals instead of lighting them from a painted transfer function: a
    /// PNG with the disk of projected normals inscribed in it (view space: +x right, +y
    /// up).
    #[arg(long, value_name = "PNG", conflicts_with = "explorer")]
    pub transfer: Option<PathBuf>,
    /// Explorer: the central disk's angular radius, degrees (above 0, at most 90).
    #[arg(long, default_value_t = 20.0, value_parser = explorer_disk)]
    pub explorer_disk: f32,
    /// Explorer: the dark border width between slices, degrees (0 up to 45).
    #[arg(long, default_value_t = 3.0, value_parser = explorer_tolerance)]
    pub explorer_tolerance: f32,
    /// S-MIP levels coarser than sampled: each halves the image (2×2 averages of S-NDFs).
    /// Default: the level the file was sampled for (0 unless `sample --min-samples`
    /// sampled finer). A file of S-MIP tiles (`sample --tiles`) counts from its view's
    /// size: level 0 draws the view, finer tiles stored or not.
    #[arg(long, conflicts_with = "zoom_out")]
    pub level: Option<u32>,
    /// Zoom out by this factor (≥ 1, any value) from the sampled resolution (level 0,
    /// as --level counts: a file sampled finer with `sample --min-samples` is shown at a
    /// coarser level by default, so a factor below that level's makes a larger image
    /// than the default); trilinear between the two S-MIP levels around it.
    #[arg(long, value_name = "FACTOR")]
    pub zoom_out: Option<f32>,
    /// Background colour for rays that hit nothing.
    #[arg(long, default_value = "#ffffff")]
    pub background: String,
}

#[derive(Clone, Copy, Debug, clap::ValueEnum)]
pub enum Brdf {
    Lambert,
    BlinnPhong,
}

/// Refuses a lighting weight or exponent that is not a finite number, 0 or more.
pub(super) fn check_weights(weights: &[(&str, f32)]) -> Result<()> {
    for &(option, v) in weights {
        if !(v.is_finite() && v >= 0.0) {
            bail!("{option} {v} (must be a finite number, 0 or more)");
        }
    }
    Ok(())
}

/// Parses `x,y,z` or `x,y,z:colour`.
pub(super) fn parse_light(s: &str) -> Result<(Vec3, [f32; 3])> {
    let (dir, colour) = match s.split_once(':') {
        Some((d, c)) => (d, Some(c)),
        None => (s, None),
    };
    let v: Vec<f32> = dir
        .split(',')
        .map(|p| p.trim().parse::<f32>())
        .collect::<Result<_, _>>()
        .with_context(|| format!("light {s:?}: the direction is not three numbers"))?;
    if v.len() != 3 || v.iter().any(|x| !x.is_finite()) || v.iter().all(|x| *x == 0.0) {
        bail!("light {s:?}: the direction must be three finite numbers, not all zero");
    }
    let colour = match colour {
        Some(c) => parse_colour(c)
            .with_context(|| format!("light {s:?}"))?
            .map(mdlod_render::renderer::srgb_to_linear),
        None => [1.0; 3],
    };
    // Normalised in double precision: a direction such as 1e20,0,0 or 1e-30,0,0, whose
    // square single precision cannot hold, is still the direction it says.
    let unit = mdlod_render::glam::DVec3::new(f64::from(v[0]), f64::from(v[1]), f64::from(v[2]))
        .normalize()
        .as_vec3();
    Ok((unit, colour))
}

/// Refuses options given on the command line that change nothing in the image the others
/// ask for: lights under a colouring of the normals, a highlight's settings with
/// `--brdf lambert`, the explorer's settings without `--explorer`.
pub fn check_options(matches: &clap::ArgMatches) -> Result<()> {
    let given = |id: &str| {
        matches!(
            matches.value_source(id),
            Some(clap::parser::ValueSource::CommandLine)
        )
    };
    let colouring = if given("explorer") {
        Some("--explorer")
    } else if given("transfer") {
        Some("--transfer")
    } else {
        None
    };
    let lighting = [
        "lights", "ambient", "diffuse", "brdf", "specular", "exponent", "envmap",
    ];
    for id in lighting {
        if let Some(colouring) = colouring.filter(|_| given(id)) {
            bail!(
                "--{} has no effect with {colouring}: the normals are coloured, not lit",
                option_name(id)
            );
        }
    }
    let lambert = matches
        .get_one::<Brdf>("brdf")
        .is_some_and(|b| matches!(b, Brdf::Lambert));
    for id in ["specular", "exponent"] {
        if lambert && given(id) {
            bail!(
                "--{} has no effect with --brdf lambert: it sets the Blinn-Phong highlight",
                option_name(id)
            );
        }
    }
    // An environment map lights by its Lambert irradiance alone: without a --light the
    // highlight has nothing to reflect.
    if given("envmap") && !given("lights") {
        for id in ["brdf", "specular", "exponent"] {
            if given(id) {
                bail!(
                    "--{} has no effect with --envmap and no --light: the environment map \
                     lights by its Lambert irradiance; the highlight is of the --light \
                     directions",
                    option_name(id)
                );
            }
        }
    }
    for id in ["explorer_disk", "explorer_tolerance"] {
        if given(id) && !given("explorer") {
            bail!("--{} has no effect without --explorer", option_name(id));
        }
    }
    Ok(())
}

/// `--explorer-disk`: an angle on the hemisphere of normals, above 0 and at most 90°.
fn explorer_disk(s: &str) -> Result<f32, String> {
    match s.trim().parse::<f32>() {
        Ok(v) if v > 0.0 && v <= 90.0 => Ok(v),
        _ => Err(format!("{s:?}: degrees above 0, at most 90")),
    }
}

/// `--explorer-tolerance`: a border between slices, from 0 to 45° (half a slice of the
/// fewest).
fn explorer_tolerance(s: &str) -> Result<f32, String> {
    match s.trim().parse::<f32>() {
        Ok(v) if (0.0..=45.0).contains(&v) => Ok(v),
        _ => Err(format!("{s:?}: degrees from 0 to 45")),
    }
}

/// The command-line spelling of argument `id`.
fn option_name(id: &str) -> String {
    match id {
        "lights" => "light".into(),
        _ => id.replace('_', "-"),
    }
}

/// The angle between the view axis and the image's corners above which S-NDFs binned in
/// the camera's frame are noted as approximate towards the image's edges (a 16:9 image
/// at a vertical field of view of 45°; the default 30° reaches 29°).
const CAMERA_FRAME_WIDE_CORNER_DEG: f32 = 40.0;

/// A note for S-NDFs of a wide perspective view that an earlier mdlod sampled, binning
/// the normals in the camera's frame (no `normal_frame` in the header): a normal facing
/// away from the view axis but towards its texel was binned with its mirror image, so
/// shading is approximate towards the edges (measured under a headlight against the
/// ray-cast spheres: 3 % brighter at 60°, up to a third at 90°). Sampling again bins
/// along each texel's ray, which is exact.
pub fn camera_frame_note(header: &mdlod_format::sndf::SndfHeader) -> Option<String> {
    if header.normal_frame.is_some() || header.smip.is_some() {
        return None;
    }
    let view: mdlod_render::view::ViewFile = serde_json::from_value(header.view.clone()).ok()?;
    // The widest angle any texel looks off the axis: at the corners, so a wide image at a
    // modest vertical field of view counts as much as a square one at a wide one.
    let ty = (view.fov_y_deg.to_radians() / 2.0).tan();
    let tx = ty * header.width as f32 / header.height.max(1) as f32;
    let corner = tx.hypot(ty).atan().to_degrees();
    (view.projection == mdlod_render::camera::Projection::Perspective
        && corner > CAMERA_FRAME_WIDE_CORNER_DEG)
        .then(|| {
            format!(
                "  note: an earlier mdlod sampled these S-NDFs binning the normals in the \
                 camera's frame: in their {:.0}° perspective view ({corner:.0}° off the axis \
                 at the corners), normals facing away from the view axis are lit as their \
                 mirror images (a few per cent too bright towards the edges at 60°, up to a \
                 third at 90°); `mdlod sample` bins them along each texel's ray",
                view.fov_y_deg
            )
        })
}

pub fn run(args: Args) -> Result<()> {
    let inputs = [("", args.input.as_path())]
        .into_iter()
        .chain(args.envmap.as_deref().map(|p| ("--envmap", p)))
        .chain(args.transfer.as_deref().map(|p| ("--transfer", p)))
        .collect::<Vec<_>>();
    super::check_output("-o", &args.output, &inputs)?;
    super::check_png_name("-o", &args.output)?;
    check_weights(&[
        ("--ambient", args.ambient),
        ("--diffuse", args.diffuse),
        ("--specular", args.specular),
        ("--exponent", args.exponent),
    ])?;
    let mut lights = args
        .lights
        .iter()
        .map(|l| parse_light(l))
        .collect::<Result<Vec<_>>>()?;
    let environment = match &args.envmap {
        Some(p) => Some(mdlod_render::sndf::EnvironmentMap::from_image(
            &mdlod_render::RgbaImage::load_png(p)?,
        )),
        None => None,
    };
    if lights.is_empty() && environment.is_none() {
        lights.push((mdlod_render::Lighting::default().direction_view, [1.0; 3]));
    }
    let explorer = match args.explorer {
        Some(0) => bail!("--explorer needs at least one slice"),
        Some(n) => Some(mdlod_render::sndf::Explorer::new(
            n,
            args.explorer_disk,
            args.explorer_tolerance,
        )),
        None => None,
    };
    if args.level.is_some_and(|l| l > 16) {
        bail!("--level {} (at most 16)", args.level.unwrap_or_default());
    }
    let shade = ShadeLights {
        ambient: args.ambient,
        lights,
        diffuse: args.diffuse,
        specular: match args.brdf {
            Brdf::Lambert => 0.0,
            Brdf::BlinnPhong => args.specular,
        },
        shininess: args.exponent,
        environment,
        explorer,
        transfer: match &args.transfer {
            Some(p) => Some(mdlod_render::sndf::TransferImage::from_image(
                &mdlod_render::RgbaImage::load_png(p)?,
            )),
            None => None,
        },
    };
    let level = match args.zoom_out {
        Some(z) if !(z.is_finite() && z >= 1.0) => {
            bail!("--zoom-out {z} (must be a finite number, 1 or more)")
        }
        Some(z) => mdlod_render::ShadeLevel::ZoomOut(z),
        None => match args.level {
            Some(l) => mdlod_render::ShadeLevel::Level(l),
            None => mdlod_render::ShadeLevel::Display,
        },
    };
    let (w, h) = mdlod_render::shade_file(
        &args.input,
        &args.output,
        &shade,
        parse_colour(&args.background).context("--background")?,
        level,
    )?;
    let lights = match shade.lights.len() {
        1 => "1 light".to_string(),
        n => format!("{n} lights"),
    };
    let lit = match (args.explorer, &args.envmap) {
        (Some(slices), _) => format!("normals coloured by an explorer of {slices} slices"),
        _ if args.transfer.is_some() => format!(
            "normals coloured by the transfer function {}",
            args.transfer
                .as_deref()
                .map_or(String::new(), |p| p.display().to_string())
        ),
        (None, Some(map)) if shade.lights.is_empty() => {
            format!("lit by the environment map {}", map.display())
        }
        (None, Some(map)) => format!("lit by the environment map {} and {lights}", map.display()),
        (None, None) => lights,
    };
    println!(
        "wrote {} ({w}x{h}, {level}) from {}, {lit}, no particle data read",
        args.output.display(),
        args.input.display(),
    );
    if let Some(n) = mdlod_format::sndf::SndfData::load_header(&args.input)
        .ok()
        .and_then(|(h, _)| camera_frame_note(&h))
    {
        println!("{n}");
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    /// The explorer's angles within the hemisphere of normals; a light's direction, however
    /// long or short, normalised to the direction it names.
    #[test]
    fn explorer_angles_and_light_directions_parse_as_they_read() {
        assert_eq!(super::explorer_disk("20"), Ok(20.0));
        assert_eq!(super::explorer_tolerance("0"), Ok(0.0));
        for bad in ["0", "90.5", "NaN", "1e30", "-3"] {
            assert!(super::explorer_disk(bad).is_err(), "{bad}");
        }
        for bad in ["-1", "46", "NaN"] {
            assert!(super::explorer_tolerance(bad).is_err(), "{bad}");
        }
        for (given, want) in [
            ("1e20,0,0", [1.0, 0.0, 0.0]),
            ("0,0,1e-30", [0.0, 0.0, 1.0]),
        ] {
            let (d, _) = super::parse_light(given).unwrap();
            assert!(
                (d - mdlod_render::glam::Vec3::from(want)).length() < 1e-6,
                "{given}: {d}"
            );
        }
        assert!(super::parse_light("0,0,0").is_err());
    }
}
