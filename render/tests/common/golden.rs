//! Golden-image comparison.
//!
//! `check("name", &image, Tolerance {..})` compares with `render/tests/golden/name.png`.
//! A pixel fails when any channel differs by more than `per_channel`; the test fails when
//! more than `max_failing_share` of the pixels fail (or the sizes differ). On failure the
//! actual image and a difference image (failing pixels red, the others the difference
//! magnified 8×) are written to `target/golden-failures/`. With `MDLOD_UPDATE_GOLDEN=1`
//! the golden image is (re)written instead and the check passes.

use std::path::PathBuf;

use mdlod_render::RgbaImage;

#[derive(Clone, Copy, Debug)]
pub struct Tolerance {
    /// Largest difference of a channel (0-255) for a pixel to pass.
    pub per_channel: u8,
    /// Largest share (0-1) of failing pixels.
    pub max_failing_share: f64,
}

pub fn golden_path(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/golden")
        .join(format!("{name}.png"))
}

pub fn failures_dir() -> PathBuf {
    // CARGO_TARGET_TMPDIR is <target>/tmp.
    let tmp = PathBuf::from(env!("CARGO_TARGET_TMPDIR"));
    tmp.parent().unwrap_or(&tmp).join("golden-failures")
}

/// Difference statistics of two images of the same size.
pub fn compare(expected: &RgbaImage, actual: &RgbaImage, per_channel: u8) -> (usize, RgbaImage) {
    assert_eq!(
        (actual.width, actual.height),
        (expected.width, expected.height),
        "the images differ in size"
    );
    let mut diff = RgbaImage::new(actual.width, actual.height);
    let mut failing = 0;
    for y in 0..actual.height {
        for x in 0..actual.width {
            let (e, a) = (expected.pixel(x, y), actual.pixel(x, y));
            let d = (0..4).map(|k| e[k].abs_diff(a[k])).max().unwrap_or(0);
            if d > per_channel {
                failing += 1;
                diff.set_pixel(x, y, [255, 0, 0, 255]);
            } else {
                let v = d.saturating_mul(8);
                diff.set_pixel(x, y, [v, v, v, 255]);
            }
        }
    }
    (failing, diff)
}

pub fn check(name: &str, actual: &RgbaImage, tol: Tolerance) {
    let path = golden_path(name);
    if std::env::var("MDLOD_UPDATE_GOLDEN").is_ok_and(|v| v == "1") {
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        actual.save_png(&path).unwrap();
        eprintln!("golden image {} written", path.display());
        return;
    }
    let out = failures_dir();
    let write_failure = |diff: Option<&RgbaImage>| {
        std::fs::create_dir_all(&out).unwrap();
        actual
            .save_png(&out.join(format!("{name}-actual.png")))
            .unwrap();
        if let Some(d) = diff {
            d.save_png(&out.join(format!("{name}-difference.png")))
                .unwrap();
        }
    };
    let expected = match RgbaImage::load_png(&path) {
        Ok(e) => e,
        Err(e) => {
            write_failure(None);
            panic!(
                "golden image {name}: {e}. Run with MDLOD_UPDATE_GOLDEN=1 to create it \
                 (the actual image is in {})",
                out.display()
            );
        }
    };
    if (expected.width, expected.height) != (actual.width, actual.height) {
        write_failure(None);
        panic!(
            "golden image {name}: size {}x{}, rendered {}x{} (actual image in {})",
            expected.width,
            expected.height,
            actual.width,
            actual.height,
            out.display()
        );
    }
    let (failing, diff) = compare(&expected, actual, tol.per_channel);
    let share = failing as f64 / (actual.width as f64 * actual.height as f64);
    if share > tol.max_failing_share {
        write_failure(Some(&diff));
        panic!(
            "golden image {name}: {failing} pixels ({:.3}%) differ by more than {} \
             (at most {:.3}% allowed); actual and difference images in {}",
            share * 100.0,
            tol.per_channel,
            tol.max_failing_share * 100.0,
            out.display()
        );
    }
}
