//! `mdlod info`: what a `.mdlod` file holds.

use std::path::PathBuf;

use anyhow::Result;
use mdlod_format::MdlodFile;
use serde_json::json;

/// Show what a .mdlod file holds (particles, levels, species, box, build parameters), or
/// a .sndf file (texels, bins, rays, the camera).
#[derive(clap::Args)]
#[command(after_help = "Example:\n  mdlod info frame.mdlod --json | jq .particles")]
pub struct Args {
    pub file: PathBuf,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
}

/// A `.sndf` file's header.
fn sndf_info(args: &Args) -> Result<()> {
    let (header, bytes) = mdlod_format::sndf::SndfData::load_header(&args.file)?;
    let h = &header;
    if args.json {
        let v = json!({
            "file": args.file.display().to_string(),
            "kind": "sndf",
            "width": h.width,
            "height": h.height,
            "bins": h.bins,
            "binning": h.binning,
            "rays": h.rays,
            "display_level": h.display_level.unwrap_or(0),
            "source": h.source,
            "view": h.view,
            "data_bytes": bytes,
        });
        println!("{}", serde_json::to_string_pretty(&v)?);
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
    println!("  shown at     level {}", h.display_level.unwrap_or(0));
    if let Some(s) = &h.source {
        println!("  sampled from {}", shown(s));
    }
    println!("  view         {}", h.view);
    Ok(())
}

pub fn run(args: Args) -> Result<()> {
    // The first 8 bytes tell an S-NDF file from a .mdlod one.
    let is_sndf = std::fs::File::open(&args.file).ok().is_some_and(|mut f| {
        let mut magic = [0u8; 8];
        std::io::Read::read_exact(&mut f, &mut magic).is_ok()
            && magic == mdlod_format::sndf::SNDF_MAGIC
    });
    if is_sndf {
        return sndf_info(&args);
    }
    let f = MdlodFile::open(&args.file)?;
    let m = f.metadata();
    let levels: Vec<u64> = f.levels().iter().map(|l| l.point_count).collect();
    let file_size = std::fs::metadata(&args.file).map(|m| m.len()).unwrap_or(0);
    if args.json {
        let v = json!({
            "file": args.file.display().to_string(),
            "file_size": file_size,
            "format_version": format!("{}.{}", f.header().version_major, f.header().version_minor),
            "particles": m.particles,
            "levels": f.level_count(),
            "level_points": levels,
            "nodes": f.nodes().len(),
            "species": m.species,
            "attribute": m.attribute,
            "box": m.simulation_box,
            "timestep": m.timestep,
            "time": m.time,
            "units": m.units,
            "source": m.source,
            "build": m.build,
            "max_position_error": m.max_position_error,
            "writer": m.writer,
        });
        println!("{}", serde_json::to_string_pretty(&v)?);
        return Ok(());
    }
    println!("{}", args.file.display());
    println!(
        "  format {}.{}, {:.1} MiB, written by {}",
        f.header().version_major,
        f.header().version_minor,
        file_size as f64 / (1 << 20) as f64,
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
    for s in &m.species {
        println!(
            "  species      {:<6} radius {:.3}  colour [{:.2} {:.2} {:.2}]",
            shown(&s.name),
            s.radius,
            s.colour[0],
            s.colour[1],
            s.colour[2]
        );
    }
    if let Some(a) = &m.attribute {
        println!(
            "  attribute    {} in [{}, {}]",
            shown(&a.name),
            a.min,
            a.max
        );
    }
    if let Some(b) = &m.simulation_box {
        println!(
            "  box          origin {:?} a {:?} b {:?} c {:?}",
            b.origin, b.a, b.b, b.c
        );
    }
    if let Some(t) = m.timestep {
        println!("  timestep     {t}");
    }
    if let Some(t) = m.time {
        println!("  time         {t}");
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
    println!(
        "  build        cluster size {}, root points {}, delta_n {}, {}-bit positions",
        m.build.max_cluster_size, m.build.max_root_points, m.build.delta_n, m.build.position_bits
    );
    println!("  max position error {:.4e}", m.max_position_error);
    Ok(())
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
}
