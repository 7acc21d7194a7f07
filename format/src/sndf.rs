//! `.sndf` files: sampled screen-space normal distribution functions of one view, so a
//! picture can be shaded and re-lit later with no particle data at all. FORMAT.md
//! ("S-NDF files") is the spec; this is its reference implementation.
//!
//! Layout (little-endian): the 8-byte magic `\x89MDSNDF\n`, u16 major and minor version,
//! u32 JSON header length `J`, u64 XXH3-64 of the data, `J` bytes of JSON header
//! ([`SndfHeader`]), zero padding to a multiple of 16, then `width · height · bins²`
//! records of four f32 (albedo sum r, g, b and sample count), texel-major, rows top to
//! bottom, bins row-major (`by · bins + bx`).
//!
//! A file may instead hold S-MIP tiles (version 1.1, [`SndfTiles`]): 64×64-texel tiles
//! of a screen-space mipmap at any levels, each with its own rays, in the order the
//! header lists them. One image of a perspective view whose normals were binned in the
//! frame of each texel's own ray says so in `normal_frame` (version 1.2).
//!
//! A reader checks, before it trusts anything: the magic and version, the JSON header
//! against size caps, every size with checked arithmetic against the file length, the
//! checksum, and every value (finite, non-negative, a bin's count at most the rays and
//! its colour sum at most its count per channel).

use std::io::Write;
use std::path::Path;

use serde::{Deserialize, Serialize};
use xxhash_rust::xxh3::xxh3_64;

use crate::error::FormatError;

/// The first 8 bytes of every `.sndf` file.
pub const SNDF_MAGIC: [u8; 8] = *b"\x89MDSNDF\n";
/// The version written for one image of S-NDFs; readers accept major version 1.
pub const SNDF_VERSION: (u16, u16) = (1, 0);
/// The version written for S-MIP tiles (the header's `smip`).
pub const SNDF_TILES_VERSION: (u16, u16) = (1, 1);
/// The version written for one image whose normals are binned along each texel's ray
/// (the header's `normal_frame`).
pub const SNDF_RAY_FRAME_VERSION: (u16, u16) = (1, 2);
/// The `normal_frame` of S-NDFs binned along each texel's own ray (FORMAT.md, section 10).
pub const RAY_FRAME: &str = "ray";
/// Texels per side of an S-MIP tile.
pub const SNDF_TILE: u32 = 64;
/// Most tiles a file holds.
const MAX_TILES: usize = 1 << 16;
/// Deepest S-MIP level, and the largest tile coordinate, a file may name.
const MAX_LEVEL: u32 = 30;
const MAX_TILE_COORD: i32 = 1 << 24;
const FIXED: usize = 8 + 2 + 2 + 4 + 8;
/// Largest JSON header accepted.
const MAX_HEADER: usize = 1 << 20;
/// Largest image side and bin count accepted.
const MAX_SIDE: u32 = 1 << 16;
const MAX_BINS: u32 = 32;
/// The binnings of the normals a file may use (see FORMAT.md).
pub const BINNINGS: [&str; 3] = ["projected-normals", "spherical", "lambert-equal-area"];

/// What a `.sndf` file says about its S-NDFs.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SndfHeader {
    pub width: u32,
    pub height: u32,
    /// Bins per axis.
    pub bins: u32,
    /// One of [`BINNINGS`] (FORMAT.md, section 10).
    pub binning: String,
    /// Jittered rays per texel.
    pub rays: u32,
    /// The camera, as a view file (JSON) of the renderer.
    pub view: serde_json::Value,
    /// Where the particles came from (the `.mdlod` path), for the record.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub source: Option<String>,
    /// The S-MIP level that shows the intended image size, when the S-NDFs were sampled
    /// finer so that every sphere gets enough samples (absent: 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub display_level: Option<u32>,
    /// S-MIP tiles instead of one image (version 1.1): `width × height` is then the size
    /// of the view they were shown in, and `rays` the fewest rays of any tile.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub smip: Option<SndfTiles>,
    /// `"ray"` (version 1.2): each texel's normals are binned in the frame of its own
    /// ray, which turns the direction towards the eye onto the view axis (absent: the
    /// camera's frame). A string when given: `null` is refused, not read as absent.
    #[serde(
        default,
        skip_serializing_if = "Option::is_none",
        deserialize_with = "present_string"
    )]
    pub normal_frame: Option<String>,
}

/// A key that, when present, must be a string (serde reads `null` as an absent
/// `Option` otherwise).
fn present_string<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Option<String>, D::Error> {
    String::deserialize(d).map(Some)
}

/// The S-MIP a file's tiles belong to, and the tiles (FORMAT.md, section 10).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SndfTiles {
    /// World units per texel of level 0 (level `l`'s texels are `2^l` times wider).
    pub texel0: f64,
    /// Plane coordinates `(u, v)` = (world · right, world · up) of the top-left corner
    /// of level 0's texel (0, 0).
    pub origin: [f64; 2],
    /// Texels per tile side: 64.
    pub tile: u32,
    /// The tiles, in the order of the data block.
    pub tiles: Vec<SndfTile>,
}

/// One tile: level, column and row of tiles (rows go down), rays per texel.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SndfTile {
    pub level: u32,
    pub x: i32,
    pub y: i32,
    pub rays: u32,
}

/// Sampled S-NDFs: the header and, per texel, `bins²` records `[r, g, b, count]`.
#[derive(Clone, Debug, PartialEq)]
pub struct SndfData {
    pub header: SndfHeader,
    pub hist: Vec<[f32; 4]>,
}

fn corrupt(path: &Path, place: &str, problem: impl Into<String>) -> FormatError {
    FormatError::Corrupt {
        path: path.to_path_buf(),
        place: place.into(),
        problem: problem.into(),
    }
}

fn records(h: &SndfHeader) -> Option<usize> {
    let b2 = (h.bins as usize).checked_mul(h.bins as usize)?;
    match &h.smip {
        Some(t) => t
            .tiles
            .len()
            .checked_mul((SNDF_TILE * SNDF_TILE) as usize)?
            .checked_mul(b2),
        None => (h.width as usize)
            .checked_mul(h.height as usize)?
            .checked_mul(b2),
    }
}

/// The rays per texel of every record, in order: one count per run of records.
fn record_rays(h: &SndfHeader) -> Vec<(usize, u32)> {
    let b2 = (h.bins * h.bins) as usize;
    match &h.smip {
        Some(t) => t
            .tiles
            .iter()
            .map(|tile| ((SNDF_TILE * SNDF_TILE) as usize * b2, tile.rays))
            .collect(),
        None => vec![(usize::MAX, h.rays)],
    }
}

fn check_tiles(path: &Path, h: &SndfHeader, t: &SndfTiles) -> Result<(), FormatError> {
    let bad = |problem: String| Err(corrupt(path, "header (smip)", problem));
    if !(t.texel0.is_finite() && t.texel0 > 0.0 && t.origin.iter().all(|v| v.is_finite())) {
        return bad(format!(
            "texel size {} and origin {:?} (finite, the size positive)",
            t.texel0, t.origin
        ));
    }
    if t.tile != SNDF_TILE {
        return bad(format!(
            "tiles of {} texels (this version has {SNDF_TILE})",
            t.tile
        ));
    }
    if t.tiles.is_empty() || t.tiles.len() > MAX_TILES {
        return bad(format!("{} tiles (1 to {MAX_TILES})", t.tiles.len()));
    }
    let mut seen = std::collections::HashSet::new();
    for (i, tile) in t.tiles.iter().enumerate() {
        if tile.level > MAX_LEVEL
            || tile.x.unsigned_abs() > MAX_TILE_COORD as u32
            || tile.y.unsigned_abs() > MAX_TILE_COORD as u32
            || tile.rays == 0
        {
            return bad(format!(
                "tile {i} (level {}, x {}, y {}, {} rays): the level must be at most \
                 {MAX_LEVEL}, the coordinates within ±{MAX_TILE_COORD}, the rays at least one",
                tile.level, tile.x, tile.y, tile.rays
            ));
        }
        if !seen.insert((tile.level, tile.x, tile.y)) {
            return bad(format!(
                "tile {i} (level {}, x {}, y {}) appears twice",
                tile.level, tile.x, tile.y
            ));
        }
    }
    let fewest = t.tiles.iter().map(|t| t.rays).min().unwrap_or(0);
    if h.rays != fewest {
        return bad(format!(
            "rays {} in the header, the fewest of the tiles is {fewest}",
            h.rays
        ));
    }
    Ok(())
}

/// Whether `r` (colour sums r, g, b and the sample count) is a bin of a texel sampled
/// with `rays` rays: finite, not negative, a count at most the rays, colour sums at most
/// the count per channel.
fn valid_bin(r: &[f32; 4], rays: f32) -> bool {
    r.iter().all(|v| v.is_finite() && *v >= 0.0)
        && r[3] <= rays * (1.0 + 1e-6)
        && r[..3].iter().all(|&v| v <= r[3] * (1.0 + 1e-5) + 1e-6)
}

/// The first texel of `hist` (records texel-major, `bins²` per texel) whose bins' counts
/// add up to more than its rays (each ray lands in one bin at most): its index, the sum
/// and the rays.
fn texel_over_rays(h: &SndfHeader, hist: &[[f32; 4]]) -> Option<(usize, f64, u32)> {
    let per_texel = (h.bins as usize).saturating_mul(h.bins as usize).max(1);
    let rays = record_rays(h)
        .into_iter()
        .flat_map(|(len, rays)| std::iter::repeat_n(rays, len / per_texel));
    hist.chunks(per_texel)
        .zip(rays)
        .enumerate()
        .find_map(|(t, (bins, rays))| {
            let sum: f64 = bins.iter().map(|r| f64::from(r[3])).sum();
            // (Relative slack for the counts a coarser S-MIP texel scales up.)
            (sum > f64::from(rays) * (1.0 + 1e-5)).then_some((t, sum, rays))
        })
}

fn check_header(path: &Path, h: &SndfHeader) -> Result<usize, FormatError> {
    if h.width == 0 || h.height == 0 || h.width > MAX_SIDE || h.height > MAX_SIDE {
        return Err(corrupt(
            path,
            "header",
            format!("image {}x{} (each side 1 to {MAX_SIDE})", h.width, h.height),
        ));
    }
    if h.bins == 0 || h.bins > MAX_BINS {
        return Err(corrupt(
            path,
            "header",
            format!("{} bins (1 to {MAX_BINS})", h.bins),
        ));
    }
    if !BINNINGS.contains(&h.binning.as_str()) {
        return Err(corrupt(
            path,
            "header",
            format!(
                "binning `{}` (this reader knows {})",
                h.binning,
                BINNINGS.join(", ")
            ),
        ));
    }
    if h.rays == 0 {
        return Err(corrupt(path, "header", "zero rays per texel"));
    }
    if let Some(frame) = &h.normal_frame {
        if frame != RAY_FRAME {
            return Err(corrupt(
                path,
                "header",
                format!("normal frame `{frame}` (this reader knows `{RAY_FRAME}`)"),
            ));
        }
        if h.smip.is_some() {
            return Err(corrupt(
                path,
                "header",
                "S-MIP tiles with normals binned along each texel's ray (tiles belong to an \
                 orthographic view, whose rays are its axis)",
            ));
        }
    }
    if h.display_level.is_some_and(|l| l > 16) {
        return Err(corrupt(path, "header", "display level above 16"));
    }
    if let Some(t) = &h.smip {
        check_tiles(path, h, t)?;
    }
    records(h).ok_or_else(|| corrupt(path, "header", "size overflows"))
}

impl SndfData {
    /// Writes `self` to `path` atomically (temporary file, then rename).
    pub fn save(&self, path: &Path) -> Result<(), FormatError> {
        let n = check_header(path, &self.header)?;
        if self.hist.len() != n {
            return Err(FormatError::Write {
                path: path.to_path_buf(),
                problem: format!("{} records for a header that needs {n}", self.hist.len()),
            });
        }
        // What a reader would refuse is not written (a NaN from the sampler, say).
        let runs = record_rays(&self.header);
        let rays = runs
            .iter()
            .flat_map(|&(len, rays)| std::iter::repeat_n(rays, len));
        if let Some((i, r)) = self
            .hist
            .iter()
            .zip(rays)
            .enumerate()
            .find_map(|(i, (r, rays))| (!valid_bin(r, rays as f32)).then_some((i, r)))
        {
            return Err(FormatError::Write {
                path: path.to_path_buf(),
                problem: format!("record {i} {r:?} is not a bin (finite, count at most the rays, colour sums at most the count)"),
            });
        }
        if let Some((t, sum, rays)) = texel_over_rays(&self.header, &self.hist) {
            return Err(FormatError::Write {
                path: path.to_path_buf(),
                problem: format!("texel {t}'s counts add up to {sum}, more than its {rays} rays"),
            });
        }
        let json = serde_json::to_vec(&self.header).map_err(|e| FormatError::Write {
            path: path.to_path_buf(),
            problem: e.to_string(),
        })?;
        let data: &[u8] = bytemuck::cast_slice(&self.hist);
        let mut out = Vec::with_capacity(FIXED + json.len() + 16 + data.len());
        // Files of one image binned in the camera's frame stay 1.0, readable by every
        // 1.x reader.
        let version = if self.header.normal_frame.is_some() {
            SNDF_RAY_FRAME_VERSION
        } else if self.header.smip.is_some() {
            SNDF_TILES_VERSION
        } else {
            SNDF_VERSION
        };
        out.extend_from_slice(&SNDF_MAGIC);
        out.extend_from_slice(&version.0.to_le_bytes());
        out.extend_from_slice(&version.1.to_le_bytes());
        out.extend_from_slice(&(json.len() as u32).to_le_bytes());
        out.extend_from_slice(&xxh3_64(data).to_le_bytes());
        out.extend_from_slice(&json);
        out.resize(out.len().div_ceil(16) * 16, 0);
        out.extend_from_slice(data);
        let dir = match path.parent() {
            Some(d) if !d.as_os_str().is_empty() => d,
            _ => Path::new("."),
        };
        let io = |e| FormatError::io(path, e);
        crate::files::check_replaceable(path).map_err(io)?;
        let mut tmp = crate::writer::output_file_builder()
            .prefix(".sndf.")
            .suffix(".tmp")
            .tempfile_in(dir)
            .map_err(|e| io(crate::files::temp_error(e)))?;
        tmp.write_all(&out).map_err(io)?;
        tmp.as_file().sync_all().map_err(io)?;
        crate::files::keep_permissions(path, tmp.as_file()).map_err(io)?;
        tmp.persist(path)
            .map_err(|e| FormatError::io(path, e.error))?;
        Ok(())
    }

    /// Reads and validates `path`.
    pub fn load(path: &Path) -> Result<SndfData, FormatError> {
        // The header first: a file whose length is not the one its header gives is
        // refused before its data is read.
        Self::load_header(path)?;
        let bytes = std::fs::read(path).map_err(|e| FormatError::io(path, e))?;
        Self::parse(path, &bytes)
    }

    /// Reads and validates the header of `path` alone, and that the file has the length
    /// it gives (what `mdlod info` shows; the data is neither read nor checked): the
    /// header and the length of the data in bytes.
    pub fn load_header(path: &Path) -> Result<(SndfHeader, u64), FormatError> {
        use std::io::Read;
        let io = |e| FormatError::io(path, e);
        let mut file = crate::files::open(path).map_err(io)?;
        let len = file.metadata().map_err(io)?.len();
        let mut prefix = Vec::new();
        (&mut file)
            .take((FIXED + MAX_HEADER) as u64)
            .read_to_end(&mut prefix)
            .map_err(io)?;
        let (header, start, n, _) = Self::parse_header(path, &prefix, len)?;
        let expected = n
            .checked_mul(16)
            .and_then(|d| d.checked_add(start))
            .map(|e| e as u64);
        if expected != Some(len) {
            return Err(data_length_error(path, &header, expected, len));
        }
        Ok((header, len - start as u64))
    }

    /// The header of a file whose first bytes are `bytes` (at least the fixed part and
    /// the JSON) and whose length is `file_len`: the header, where the data starts, the
    /// number of records and the data's stored checksum.
    fn parse_header(
        path: &Path,
        bytes: &[u8],
        file_len: u64,
    ) -> Result<(SndfHeader, usize, usize, u64), FormatError> {
        if bytes.get(..8) != Some(&SNDF_MAGIC[..]) {
            return Err(corrupt(
                path,
                "its first bytes",
                "not an .sndf file (no S-NDF signature); `mdlod sample` writes one",
            ));
        }
        if bytes.len() < FIXED {
            return Err(corrupt(
                path,
                "its header",
                format!(
                    "an .sndf file cut short: {} bytes, shorter than the {FIXED}-byte fixed \
                     header",
                    bytes.len()
                ),
            ));
        }
        let u16_at = |o: usize| u16::from_le_bytes([bytes[o], bytes[o + 1]]);
        let (major, minor) = (u16_at(8), u16_at(10));
        if major != SNDF_VERSION.0 {
            return Err(FormatError::UnsupportedVersion {
                path: path.to_path_buf(),
                major,
                minor,
                readable_min: 1,
                readable_max: 1,
                hint: "write it again with this mdlod (mdlod sample)",
            });
        }
        let json_len = u32::from_le_bytes([bytes[12], bytes[13], bytes[14], bytes[15]]) as usize;
        let checksum = u64::from_le_bytes(bytes[16..24].try_into().unwrap_or([0; 8]));
        if json_len > MAX_HEADER {
            return Err(corrupt(
                path,
                "header",
                format!(
                    "header length {json_len} bytes, past the {MAX_HEADER} bytes (1 MiB) an \
                     .sndf header may have"
                ),
            ));
        }
        if FIXED + json_len > bytes.len() {
            return Err(corrupt(
                path,
                "header",
                format!("header length {json_len} does not fit the file ({file_len} bytes)"),
            ));
        }
        let header: SndfHeader =
            serde_json::from_slice(&bytes[FIXED..FIXED + json_len]).map_err(|e| {
                corrupt(
                    path,
                    "S-NDF header (the file starts with the S-NDF signature)",
                    format!("invalid JSON: {e}"),
                )
            })?;
        // S-MIP tiles are version 1.1's: a 1.0 file holding them was not written by a
        // writer of that version. (Later minors add keys, which the header refuses.)
        if minor == 0 && header.smip.is_some() {
            return Err(corrupt(
                path,
                "header",
                "version 1.0 holds `smip` (S-MIP tiles), which version 1.1 added",
            ));
        }
        if minor < 2 && header.normal_frame.is_some() {
            return Err(corrupt(
                path,
                "header",
                format!("version 1.{minor} holds `normal_frame`, which version 1.2 added"),
            ));
        }
        let n = check_header(path, &header)?;
        let start = (FIXED + json_len).div_ceil(16) * 16;
        // The padding up to the data: zero bytes (no checksum covers them).
        let padding = bytes.get(FIXED + json_len..start).unwrap_or(&[]);
        if let Some(k) = padding.iter().position(|&b| b != 0) {
            return Err(corrupt(
                path,
                &format!("byte {}", FIXED + json_len + k),
                "the padding after the header is not zero",
            ));
        }
        Ok((header, start, n, checksum))
    }

    /// Validates and decodes the bytes of a `.sndf` file (`path` names it in errors).
    pub fn parse(path: &Path, bytes: &[u8]) -> Result<SndfData, FormatError> {
        let (header, start, n, checksum) = Self::parse_header(path, bytes, bytes.len() as u64)?;
        let expected = n.checked_mul(16).and_then(|d| d.checked_add(start));
        if expected != Some(bytes.len()) {
            return Err(data_length_error(
                path,
                &header,
                expected.map(|e| e as u64),
                bytes.len() as u64,
            ));
        }
        let data = &bytes[start..];
        let computed = xxh3_64(data);
        if computed != checksum {
            return Err(FormatError::Checksum {
                path: path.to_path_buf(),
                place: "data".into(),
                stored: checksum,
                computed,
            });
        }
        Self::records(path, header, data, n)
    }

    /// The records of `data`, each checked against its rays.
    fn records(
        path: &Path,
        header: SndfHeader,
        data: &[u8],
        n: usize,
    ) -> Result<SndfData, FormatError> {
        let runs = record_rays(&header);
        let mut run = runs
            .iter()
            .flat_map(|&(len, rays)| std::iter::repeat_n(rays, len));
        let mut hist = Vec::with_capacity(n);
        for (i, c) in data.chunks_exact(16).enumerate() {
            let rays = run.next().unwrap_or(header.rays) as f32;
            let r: [f32; 4] = [0, 1, 2, 3]
                .map(|k| f32::from_le_bytes(c[4 * k..4 * k + 4].try_into().unwrap_or([0; 4])));
            if !valid_bin(&r, rays) {
                return Err(corrupt(
                    path,
                    &format!("record {i}"),
                    format!("{r:?} is not a bin (finite, count at most {rays}, colour sums at most the count)"),
                ));
            }
            hist.push(r);
        }
        if let Some((t, sum, rays)) = texel_over_rays(&header, &hist) {
            let per_texel = (header.bins * header.bins) as usize;
            return Err(corrupt(
                path,
                &format!(
                    "records {}..{} (texel {t})",
                    t * per_texel,
                    (t + 1) * per_texel
                ),
                format!("the texel's counts add up to {sum}, more than its {rays} rays (a ray lands in one bin at most)"),
            ));
        }
        Ok(SndfData { header, hist })
    }
}

/// The error of a file whose length is not the one its header gives.
fn data_length_error(
    path: &Path,
    header: &SndfHeader,
    expected: Option<u64>,
    len: u64,
) -> FormatError {
    let what = match &header.smip {
        Some(t) => format!("{} tiles", t.tiles.len()),
        None => format!("{}x{} texels", header.width, header.height),
    };
    corrupt(
        path,
        "data",
        format!(
            "{what} of {}² bins need {} bytes in all, the file has {len}",
            header.bins,
            expected.map_or("too many".into(), |e| e.to_string()),
        ),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> SndfData {
        let header = SndfHeader {
            width: 3,
            height: 2,
            bins: 2,
            binning: "projected-normals".into(),
            rays: 4,
            view: serde_json::json!({"azimuth_deg": 30.0}),
            source: Some("x.mdlod".into()),
            display_level: Some(1),
            normal_frame: None,
            smip: None,
        };
        // Each texel's four bins hold 0, 1, 2 and 1 of its 4 rays.
        let hist = (0..24)
            .map(|i| {
                let c = [0.0, 1.0, 2.0, 1.0][i % 4];
                [0.5 * c, 0.25 * c, 0.0, c]
            })
            .collect();
        SndfData { header, hist }
    }

    /// The bytes of a saved file with record `i` replaced by `r`, its checksum matching.
    fn patched(bytes: &[u8], i: usize, r: [f32; 4]) -> Vec<u8> {
        let json_len = u32::from_le_bytes([bytes[12], bytes[13], bytes[14], bytes[15]]) as usize;
        let start = (FIXED + json_len).div_ceil(16) * 16;
        let mut out = bytes.to_vec();
        for (k, v) in r.iter().enumerate() {
            let at = start + 16 * i + 4 * k;
            out[at..at + 4].copy_from_slice(&v.to_le_bytes());
        }
        let sum = xxh3_64(&out[start..]);
        out[16..24].copy_from_slice(&sum.to_le_bytes());
        out
    }

    #[test]
    fn records_a_reader_would_refuse_are_not_written() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("v.sndf");
        for bad in [
            [f32::NAN, 0.0, 0.0, 1.0],
            [0.0, 0.0, 0.0, 5.0],
            [2.0, 0.0, 0.0, 1.0],
        ] {
            let mut s = sample();
            s.hist[7] = bad;
            let e = s.save(&p).unwrap_err().to_string();
            assert!(e.contains("record 7") && e.contains("is not a bin"), "{e}");
            assert!(!p.exists());
        }
    }

    #[test]
    fn round_trips_and_refuses_damage() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("v.sndf");
        let s = sample();
        s.save(&p).unwrap();
        assert_eq!(SndfData::load(&p).unwrap(), s);
        let good = std::fs::read(&p).unwrap();
        // Every truncation and every flipped byte: an error naming the file, no panic.
        for cut in 0..good.len() {
            let e = SndfData::parse(&p, &good[..cut]).unwrap_err().to_string();
            assert!(e.starts_with(&p.display().to_string()), "{e}");
        }
        for i in 0..good.len() {
            let mut bad = good.clone();
            bad[i] ^= 0x40;
            if let Ok(d) = SndfData::parse(&p, &bad) {
                // Only JSON whitespace or an equivalent spelling can survive.
                assert_eq!(d.hist, s.hist, "byte {i}");
            }
        }
        // A value that no sampling can give, with a matching checksum (written past
        // `save`, which refuses it).
        let mut wrong = s.hist[5];
        wrong[3] = 9.0;
        let q = dir.path().join("w.sndf");
        std::fs::write(&q, patched(&good, 5, wrong)).unwrap();
        let e = SndfData::load(&q).unwrap_err().to_string();
        assert!(
            e.contains("record 5") && e.contains("count at most 4"),
            "{e}"
        );
        // Bins each within the rays whose texel adds up to more: texel 1 (records 4 to
        // 7) gets 0 + 1 + 4 + 1 of its 4 rays.
        std::fs::write(&q, patched(&good, 6, [0.0, 0.0, 0.0, 4.0])).unwrap();
        let e = SndfData::load(&q).unwrap_err().to_string();
        assert!(
            e.contains("records 4..8 (texel 1)") && e.contains("add up to 6, more than its 4 rays"),
            "{e}"
        );
        let mut over = s.clone();
        over.hist[6][3] = 4.0;
        let e = over.save(&q).unwrap_err().to_string();
        assert!(e.contains("texel 1's counts add up to 6"), "{e}");
    }

    /// A header past the cap is refused as such, even where the file would hold it.
    #[test]
    fn a_header_past_the_cap_is_named_as_too_long() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("big.sndf");
        let len = MAX_HEADER + 300;
        let mut bytes = SNDF_MAGIC.to_vec();
        bytes.extend_from_slice(&1u16.to_le_bytes());
        bytes.extend_from_slice(&0u16.to_le_bytes());
        bytes.extend_from_slice(&(len as u32).to_le_bytes());
        bytes.extend_from_slice(&[0; 8]);
        bytes.resize(FIXED + len + 4096, b' ');
        std::fs::write(&p, &bytes).unwrap();
        for e in [
            SndfData::load_header(&p).unwrap_err(),
            SndfData::parse(&p, &bytes).unwrap_err(),
        ] {
            let e = e.to_string();
            assert!(
                e.contains(&format!(
                    "header length {len} bytes, past the {MAX_HEADER} bytes (1 MiB)"
                )),
                "{e}"
            );
        }
    }

    #[test]
    fn the_header_loads_alone_and_a_file_longer_than_it_says_is_refused_unread() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("v.sndf");
        let s = sample();
        s.save(&p).unwrap();
        let (header, bytes) = SndfData::load_header(&p).unwrap();
        assert_eq!(header, s.header);
        assert_eq!(bytes, s.hist.len() as u64 * 16);
        // A sparse tail of a gigabyte: refused by length before the data is read.
        let f = std::fs::OpenOptions::new().write(true).open(&p).unwrap();
        f.set_len(1 << 30).unwrap();
        for e in [
            SndfData::load_header(&p).unwrap_err(),
            SndfData::load(&p).unwrap_err(),
        ] {
            let e = e.to_string();
            assert!(e.contains("the file has 1073741824"), "{e}");
        }
    }

    fn tiled() -> SndfData {
        let tiles = vec![
            SndfTile {
                level: 0,
                x: -1,
                y: 2,
                rays: 3,
            },
            SndfTile {
                level: 1,
                x: 0,
                y: 0,
                rays: 12,
            },
        ];
        let per = (SNDF_TILE * SNDF_TILE) as usize;
        let hist = (0..2 * per)
            .map(|i| {
                let c = ((i % 4) as f32).min(if i < per { 3.0 } else { 12.0 });
                [0.5 * c, 0.0, c, c]
            })
            .collect();
        SndfData {
            header: SndfHeader {
                width: 100,
                height: 60,
                bins: 1,
                binning: "projected-normals".into(),
                rays: 3,
                view: serde_json::json!({"projection": "orthographic"}),
                source: None,
                display_level: None,
                normal_frame: None,
                smip: Some(SndfTiles {
                    texel0: 0.25,
                    origin: [-3.0, 7.5],
                    tile: SNDF_TILE,
                    tiles,
                }),
            },
            hist,
        }
    }

    /// Normals binned along each texel's ray are version 1.2's `normal_frame`: written
    /// as 1.2, refused under an earlier minor, with a frame a reader does not know, and
    /// beside S-MIP tiles (whose views are orthographic).
    #[test]
    fn a_ray_frame_is_version_1_2_and_refused_where_it_cannot_be() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("r.sndf");
        let mut ray = sample();
        ray.header.normal_frame = Some(RAY_FRAME.into());
        ray.save(&p).unwrap();
        let bytes = std::fs::read(&p).unwrap();
        assert_eq!(&bytes[8..12], &[1, 0, 2, 0], "version 1.2");
        assert_eq!(SndfData::load(&p).unwrap(), ray);
        let mut relabelled = bytes.clone();
        relabelled[10] = 1;
        let e = SndfData::parse(&p, &relabelled).unwrap_err().to_string();
        assert!(e.contains("version 1.1 holds `normal_frame`"), "{e}");
        let at = bytes
            .windows(5)
            .position(|w| w == b"\"ray\"")
            .expect("the frame in the header");
        let mut unknown = bytes.clone();
        unknown[at + 3] = b'z';
        let e = SndfData::parse(&p, &unknown).unwrap_err().to_string();
        assert!(e.contains("normal frame `raz`"), "{e}");
        // `null` is not a frame (it is not the key's absence either).
        let mut null = bytes.clone();
        null[at..at + 5].copy_from_slice(b" null");
        let e = SndfData::parse(&p, &null).unwrap_err().to_string();
        assert!(e.contains("invalid type: null, expected a string"), "{e}");
        let mut tiles = tiled();
        tiles.header.normal_frame = Some(RAY_FRAME.into());
        let e = tiles.save(&p).unwrap_err().to_string();
        assert!(e.contains("S-MIP tiles with normals binned along"), "{e}");
    }

    #[test]
    fn tiles_round_trip_with_their_own_rays_and_bad_tiles_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("t.sndf");
        let t = tiled();
        t.save(&p).unwrap();
        let bytes = std::fs::read(&p).unwrap();
        assert_eq!(&bytes[8..12], &[1, 0, 1, 0], "version 1.1");
        assert_eq!(SndfData::load(&p).unwrap(), t);
        // One image stays version 1.0.
        let q = dir.path().join("i.sndf");
        sample().save(&q).unwrap();
        assert_eq!(&std::fs::read(&q).unwrap()[8..12], &[1, 0, 0, 0]);
        // Tiles under a 1.0 header, and padding that is not zero: refused.
        let mut relabelled = bytes.clone();
        relabelled[10] = 0;
        let e = SndfData::parse(&p, &relabelled).unwrap_err().to_string();
        assert!(e.contains("version 1.0 holds `smip`"), "{e}");
        let json_len = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
        let padding = FIXED + json_len..(FIXED + json_len).div_ceil(16) * 16;
        assert!(!padding.is_empty(), "the test needs padding");
        let mut padded = bytes.clone();
        padded[padding.end - 1] = b' ';
        let e = SndfData::parse(&p, &padded).unwrap_err().to_string();
        assert!(e.contains("padding after the header is not zero"), "{e}");
        // A count above its own tile's rays (3), though below the other tile's (12).
        let mut over = t.hist[10];
        over[3] = 5.0;
        std::fs::write(&p, patched(&bytes, 10, over)).unwrap();
        let e = SndfData::load(&p).unwrap_err().to_string();
        assert!(
            e.contains("record 10") && e.contains("count at most 3"),
            "{e}"
        );
        type Damage = Box<dyn Fn(&mut SndfTiles, &mut SndfHeader)>;
        let cases: Vec<(&str, Damage)> = vec![
            ("appears twice", Box::new(|s, _| s.tiles[1] = s.tiles[0])),
            ("tiles of 32", Box::new(|s, _| s.tile = 32)),
            ("texel size", Box::new(|s, _| s.texel0 = -1.0)),
            (
                "tile 0 (level 99, x -1, y 2, 3 rays): the level must be at most 30",
                Box::new(|s, _| s.tiles[0].level = 99),
            ),
            ("fewest of the tiles", Box::new(|_, h| h.rays = 12)),
            ("0 tiles", Box::new(|s, _| s.tiles.clear())),
        ];
        for (want, damage) in cases {
            let mut bad = t.clone();
            let mut header = bad.header.clone();
            let mut smip = header.smip.take().unwrap();
            damage(&mut smip, &mut header);
            header.smip = Some(smip);
            bad.header = header;
            // Written by hand: save refuses such headers too.
            assert!(bad.save(&p).is_err(), "{want}");
            let json = serde_json::to_vec(&bad.header).unwrap();
            let data: &[u8] = bytemuck::cast_slice(&bad.hist);
            let mut raw = vec![];
            raw.extend_from_slice(&SNDF_MAGIC);
            raw.extend_from_slice(&[1, 0, 1, 0]);
            raw.extend_from_slice(&(json.len() as u32).to_le_bytes());
            raw.extend_from_slice(&xxh3_64(data).to_le_bytes());
            raw.extend_from_slice(&json);
            raw.resize(raw.len().div_ceil(16) * 16, 0);
            raw.extend_from_slice(data);
            let e = SndfData::parse(&p, &raw).unwrap_err().to_string();
            assert!(
                e.contains(want) && e.starts_with(&p.display().to_string()),
                "{want}: {e}"
            );
        }
    }
}
