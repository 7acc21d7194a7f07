//! RGBA8 images: PNG output (written atomically), PNG input (for golden tests).

use std::io::Write;
use std::path::Path;

use crate::error::RenderError;

/// The resolution, in dots per inch (its bits; 0 for none), every PNG this process
/// writes records ([`set_png_dpi`]): `mdlod render --dpi`, for stills, movies and
/// turntables alike.
static PNG_DPI: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);

/// Sets the resolution every PNG this process writes records (`None`: none, the
/// default). A finite resolution above 0 only.
pub fn set_png_dpi(dpi: Option<f32>) {
    let bits = dpi
        .filter(|d| d.is_finite() && *d > 0.0)
        .map_or(0, f32::to_bits);
    PNG_DPI.store(bits, std::sync::atomic::Ordering::Relaxed);
}

fn png_dpi() -> Option<f32> {
    match PNG_DPI.load(std::sync::atomic::Ordering::Relaxed) {
        0 => None,
        bits => Some(f32::from_bits(bits)),
    }
}

/// An 8-bit RGBA image, rows top to bottom, sRGB-encoded colour.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RgbaImage {
    pub width: u32,
    pub height: u32,
    /// `width * height * 4` bytes.
    pub data: Vec<u8>,
}

impl RgbaImage {
    /// Turns sRGB-encoded premultiplied colour (the mean of a pixel's samples over a
    /// transparent background) into the straight colour PNG stores with its alpha: each
    /// channel decoded, divided by the alpha, and encoded again. Opaque and empty pixels
    /// are left as they are.
    pub fn unpremultiply(&mut self) {
        use crate::renderer::{linear_to_srgb, srgb_to_linear};
        for p in self.data.chunks_exact_mut(4) {
            let a = p[3];
            if a == 0 || a == 255 {
                continue;
            }
            let alpha = f32::from(a) / 255.0;
            for c in &mut p[..3] {
                let straight = srgb_to_linear(f32::from(*c) / 255.0) / alpha;
                *c = (linear_to_srgb(straight.min(1.0)) * 255.0).round() as u8;
            }
        }
    }

    pub fn new(width: u32, height: u32) -> Self {
        RgbaImage {
            width,
            height,
            data: vec![0; width as usize * height as usize * 4],
        }
    }

    /// The pixel at column `x`, row `y` (from the top).
    pub fn pixel(&self, x: u32, y: u32) -> [u8; 4] {
        let i = (y as usize * self.width as usize + x as usize) * 4;
        [
            self.data[i],
            self.data[i + 1],
            self.data[i + 2],
            self.data[i + 3],
        ]
    }

    pub fn set_pixel(&mut self, x: u32, y: u32, p: [u8; 4]) {
        let i = (y as usize * self.width as usize + x as usize) * 4;
        self.data[i..i + 4].copy_from_slice(&p);
    }

    /// The mean sRGB level (0-255, over r, g and b) of the image's outer band, `1/share`
    /// of each side wide, and of the rest inside it: how a picture's edges and middle
    /// compare with a reference's. A part with no pixel gives 0.
    pub fn band_and_middle_levels(&self, share: u32) -> [f64; 2] {
        let (w, h, k) = (self.width, self.height, share.max(1));
        let mut sums = [(0u64, 0u64); 2];
        for y in 0..h {
            for x in 0..w {
                let edge = x < w / k || x >= w - w / k || y < h / k || y >= h - h / k;
                let p = self.pixel(x, y);
                let s = &mut sums[usize::from(!edge)];
                s.0 += p[..3].iter().map(|&c| u64::from(c)).sum::<u64>();
                s.1 += 3;
            }
        }
        sums.map(|(sum, n)| sum as f64 / n.max(1) as f64)
    }

    /// Lays `colour` (sRGB) with coverage `a` in [0, 1] over the pixel at column `x`, row
    /// `y`, whose alpha is straight (not premultiplied), as the PNG stores it; pixels
    /// outside the image are left alone.
    pub fn blend_over(&mut self, x: u32, y: u32, colour: [u8; 3], a: f32) {
        if x >= self.width || y >= self.height || a <= 0.0 {
            return;
        }
        let i = (y as usize * self.width as usize + x as usize) * 4;
        let px = &mut self.data[i..i + 4];
        let a = a.min(1.0);
        let below = f32::from(px[3]) / 255.0 * (1.0 - a);
        let alpha = a + below;
        for c in 0..3 {
            px[c] = ((f32::from(colour[c]) * a + f32::from(px[c]) * below) / alpha).round() as u8;
        }
        px[3] = (alpha * 255.0).round() as u8;
    }

    /// Encodes the image as a PNG (sRGB chunk set), with the resolution [`set_png_dpi`]
    /// gave this process's images, if any.
    pub fn to_png(&self) -> Result<Vec<u8>, String> {
        self.to_png_with_dpi(png_dpi())
    }

    /// [`Self::to_png`] with a resolution in dots per inch (a `pHYs` chunk, in pixels
    /// per metre as PNG keeps it), which a journal's figure checks and page layout read
    /// for the printed size.
    pub fn to_png_with_dpi(&self, dpi: Option<f32>) -> Result<Vec<u8>, String> {
        let mut out = Vec::new();
        {
            let mut enc = png::Encoder::new(&mut out, self.width, self.height);
            enc.set_color(png::ColorType::Rgba);
            enc.set_depth(png::BitDepth::Eight);
            enc.set_source_srgb(png::SrgbRenderingIntent::Perceptual);
            if let Some(dpi) = dpi {
                let per_metre = (f64::from(dpi) / 0.0254).round() as u32;
                enc.set_pixel_dims(Some(png::PixelDimensions {
                    xppu: per_metre,
                    yppu: per_metre,
                    unit: png::Unit::Meter,
                }));
            }
            let mut w = enc.write_header().map_err(|e| e.to_string())?;
            w.write_image_data(&self.data).map_err(|e| e.to_string())?;
            w.finish().map_err(|e| e.to_string())?;
        }
        Ok(out)
    }

    /// Writes the image as a PNG file, atomically.
    pub fn save_png(&self, path: &Path) -> Result<(), RenderError> {
        let bytes = self.to_png().map_err(|message| RenderError::Png {
            path: path.to_path_buf(),
            action: "writing",
            message,
        })?;
        write_atomic(path, &bytes)
    }

    /// Reads an 8-bit RGB or RGBA PNG of at most [`MAX_LOAD_PIXELS`] pixels (checked
    /// from its header, before the pixels are allocated: a few kilobytes of compressed
    /// zeros can declare gigabytes of them).
    pub fn load_png(path: &Path) -> Result<RgbaImage, RenderError> {
        // (A PNG of the largest image is far below this; a device or a huge file is not
        // read whole.)
        let bytes = mdlod_format::files::read_capped(path, 1 << 30)
            .map_err(|e| RenderError::io(path, e))?;
        let png_err = |message: String| RenderError::Png {
            path: path.to_path_buf(),
            action: "reading",
            message,
        };
        let mut dec = png::Decoder::new(std::io::Cursor::new(bytes));
        dec.set_transformations(png::Transformations::EXPAND);
        let mut reader = dec.read_info().map_err(|e| png_err(e.to_string()))?;
        let (w, h) = (reader.info().width, reader.info().height);
        if u64::from(w) * u64::from(h) > MAX_LOAD_PIXELS {
            return Err(png_err(format!(
                "{w}×{h} pixels, more than the {MAX_LOAD_PIXELS} an environment map or transfer function may have"
            )));
        }
        let size = reader
            .output_buffer_size()
            .ok_or_else(|| png_err("image too large".into()))?;
        let mut buf = vec![0; size];
        let info = reader
            .next_frame(&mut buf)
            .map_err(|e| png_err(e.to_string()))?;
        if info.bit_depth != png::BitDepth::Eight {
            return Err(png_err(format!("bit depth {:?} (need 8)", info.bit_depth)));
        }
        let (w, h) = (info.width, info.height);
        let data = match info.color_type {
            png::ColorType::Rgba => buf[..w as usize * h as usize * 4].to_vec(),
            png::ColorType::Rgb => buf[..w as usize * h as usize * 3]
                .chunks_exact(3)
                .flat_map(|p| [p[0], p[1], p[2], 255])
                .collect(),
            other => return Err(png_err(format!("colour type {other:?} (need RGB or RGBA)"))),
        };
        Ok(RgbaImage {
            width: w,
            height: h,
            data,
        })
    }
}

/// Most pixels [`RgbaImage::load_png`] reads (8192 × 8192).
pub const MAX_LOAD_PIXELS: u64 = 1 << 26;

/// Writes `bytes` to a temporary file beside `path`, then renames it into place, so a
/// failed write never leaves a partial file at `path`.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), RenderError> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    if !dir.is_dir() {
        let missing = format!("the directory {} does not exist", dir.display());
        return Err(RenderError::io(
            path,
            std::io::Error::new(std::io::ErrorKind::NotFound, missing),
        ));
    }
    mdlod_format::files::check_replaceable(path).map_err(|e| RenderError::io(path, e))?;
    let mut builder = tempfile::Builder::new();
    builder.prefix(".mdlod-tmp");
    // Temporary files are private (0600); the result should be an ordinary file: 0666
    // less the user's umask, as any new file.
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        builder.permissions(std::fs::Permissions::from_mode(0o666));
    }
    let mut tmp = builder
        .tempfile_in(dir)
        .map_err(|e| RenderError::io(path, mdlod_format::files::temp_error(e)))?;
    tmp.write_all(bytes)
        .and_then(|_| tmp.as_file().sync_all())
        .map_err(|e| RenderError::io(path, e))?;
    mdlod_format::files::keep_permissions(path, tmp.as_file())
        .map_err(|e| RenderError::io(path, e))?;
    tmp.persist(path)
        .map_err(|e| RenderError::io(path, e.error))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    /// The `pHYs` chunk of a PNG: pixels per unit on x and y, and the unit byte.
    pub(crate) fn phys(png: &[u8]) -> Option<(u32, u32, u8)> {
        let at = png.windows(4).position(|w| w == b"pHYs")? + 4;
        let word = |k: usize| u32::from_be_bytes(png[at + k..at + k + 4].try_into().unwrap());
        Some((word(0), word(4), png[at + 8]))
    }

    /// A resolution asked for is written as pixels per metre (300 dpi: 11811), read
    /// back by the decoder; none by default.
    #[test]
    fn a_resolution_is_recorded_in_pixels_per_metre() {
        let img = super::RgbaImage::new(4, 3);
        let png = img.to_png_with_dpi(Some(300.0)).unwrap();
        assert_eq!(phys(&png), Some((11811, 11811, 1)));
        let decoder = png::Decoder::new(std::io::Cursor::new(&png));
        let info = decoder.read_info().unwrap();
        let dims = info.info().pixel_dims.unwrap();
        assert_eq!((dims.xppu, dims.unit), (11811, png::Unit::Meter));
        assert_eq!(phys(&img.to_png_with_dpi(None).unwrap()), None);
    }

    /// The outer band a sixth of each side wide of a 12×6 image, and its middle.
    #[test]
    fn band_and_middle_levels_split_the_image_by_its_border() {
        let mut img = super::RgbaImage::new(12, 6);
        for y in 0..6 {
            for x in 0..12 {
                let middle = (2..10).contains(&x) && (1..5).contains(&y);
                img.set_pixel(
                    x,
                    y,
                    if middle {
                        [90, 90, 90, 255]
                    } else {
                        [30, 60, 0, 255]
                    },
                );
            }
        }
        assert_eq!(img.band_and_middle_levels(6), [30.0, 90.0]);
        // One part only: the other gives 0.
        assert_eq!(
            super::RgbaImage::new(1, 1).band_and_middle_levels(6)[0],
            0.0
        );
    }

    use super::*;

    #[test]
    fn png_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.png");
        let mut img = RgbaImage::new(3, 2);
        img.set_pixel(2, 1, [10, 20, 30, 255]);
        img.set_pixel(0, 0, [1, 2, 3, 4]);
        img.save_png(&path).unwrap();
        assert_eq!(RgbaImage::load_png(&path).unwrap(), img);
    }

    /// A PNG of the given header and one byte of pixel data (a zlib stream of one stored
    /// block holding a single filter byte): enough for the header to be read.
    fn header_only(path: &Path, width: u32, height: u32) {
        let chunk = |kind: &[u8], data: &[u8]| {
            let mut c = (data.len() as u32).to_be_bytes().to_vec();
            c.extend_from_slice(kind);
            c.extend_from_slice(data);
            let crc = crc32(&[kind, data].concat());
            c.extend_from_slice(&crc.to_be_bytes());
            c
        };
        let mut ihdr = width.to_be_bytes().to_vec();
        ihdr.extend_from_slice(&height.to_be_bytes());
        ihdr.extend_from_slice(&[8, 6, 0, 0, 0]);
        let mut bytes = b"\x89PNG\r\n\x1a\n".to_vec();
        bytes.extend(chunk(b"IHDR", &ihdr));
        let zlib = [
            0x78, 0x01, 0x01, 0x01, 0x00, 0xfe, 0xff, 0x00, 0x00, 0x01, 0x00, 0x01,
        ];
        bytes.extend(chunk(b"IDAT", &zlib));
        bytes.extend(chunk(b"IEND", &[]));
        std::fs::write(path, bytes).unwrap();
    }

    /// CRC-32 (IEEE) as PNG chunks carry it.
    fn crc32(bytes: &[u8]) -> u32 {
        let mut c = !0u32;
        for &b in bytes {
            c ^= u32::from(b);
            for _ in 0..8 {
                c = if c & 1 == 1 {
                    0xEDB8_8320 ^ (c >> 1)
                } else {
                    c >> 1
                };
            }
        }
        !c
    }

    #[test]
    fn unreadable_pngs_are_errors_that_say_reading() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("in.png");
        // 10^5 × 10^5 pixels declared in 69 bytes: refused before 40 GB are allocated.
        header_only(&path, 100_000, 100_000);
        let e = RgbaImage::load_png(&path).unwrap_err().to_string();
        assert!(
            e.contains("reading PNG: 100000×100000 pixels, more than"),
            "{e}"
        );
        // A plausible size with no pixel data, and an empty file.
        header_only(&path, 4, 4);
        let e = RgbaImage::load_png(&path).unwrap_err().to_string();
        assert!(
            e.starts_with(&format!("{}: reading PNG", path.display())),
            "{e}"
        );
        std::fs::write(&path, b"").unwrap();
        let e = RgbaImage::load_png(&path).unwrap_err().to_string();
        assert!(e.contains("reading PNG"), "{e}");
    }

    #[test]
    fn unwritable_target_is_an_error_naming_it() {
        let img = RgbaImage::new(1, 1);
        let e = img
            .save_png(Path::new("/nonexistent-dir/x.png"))
            .unwrap_err();
        assert!(e.to_string().contains("/nonexistent-dir/x.png"), "{e}");
    }
}
