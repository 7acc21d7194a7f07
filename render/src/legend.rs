//! Legends as SVG: what an image's colours mean, for a figure (`mdlod render --legend`).
//!
//! How it works. A colour bar is drawn from the same functions that colour the image:
//! the gradient samples the colour map (or the density volume's transfer function) at
//! evenly spaced positions of the bar, and each tick sits where the renderer maps its
//! value ([`AttributeScale::of_value`] for an attribute, linear or logarithmic), so the
//! bar cannot disagree with the picture. Ticks fall on round values: steps of 1, 2 or 5
//! times a power of ten, or decades on a log scale; the ends carry their own values. A
//! species key lists the species shown with the colours they are drawn in. The SVG is
//! plain text (a gradient, rectangles, lines and `<text>`), so it can be edited and
//! placed beside the PNG in any figure tool; colours are sRGB hex.

use std::fmt::Write;

use crate::font;
use crate::image::RgbaImage;
use crate::renderer::linear_to_srgb;
use crate::style::{AttributeScale, ColourMap};

/// Width of a colour bar's SVG, px.
const WIDTH: f32 = 360.0;
/// The bar's left and right ends, px.
const BAR: [f32; 2] = [20.0, 340.0];
/// Samples of the gradient along the bar.
const GRADIENT_STOPS: usize = 33;

/// The 8-bit sRGB of a linear RGB colour.
fn srgb8(linear: [f32; 3]) -> [u8; 3] {
    linear.map(|v| (linear_to_srgb(v.clamp(0.0, 1.0)) * 255.0).round() as u8)
}

/// `#rrggbb` of a linear RGB colour.
fn hex(linear: [f32; 3]) -> String {
    let c = srgb8(linear);
    format!("#{:02x}{:02x}{:02x}", c[0], c[1], c[2])
}

/// Text safe inside an SVG element or attribute.
fn escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// `v` in scientific notation with three significant digits at most, without trailing
/// zeros (1.00e-3 → 1e-3, 2.50e4 → 2.5e4); 0 is "0".
fn scientific(v: f64) -> String {
    if v == 0.0 {
        return "0".into();
    }
    let text = format!("{v:.2e}");
    match text.split_once('e') {
        Some((mantissa, exp)) => {
            let mantissa = mantissa.trim_end_matches('0').trim_end_matches('.');
            format!("{mantissa}e{exp}")
        }
        None => text,
    }
}

/// Whether a bar whose largest magnitude is `m` writes its numbers in scientific
/// notation.
fn needs_scientific(m: f64) -> bool {
    m != 0.0 && !(1e-3..1e5).contains(&m)
}

/// A number's label as SVG text: escaped, with the typographic minus sign (U+2212) a
/// figure prints rather than a hyphen. (The in-image font draws the hyphen.)
fn number(label: &str) -> String {
    escape(label).replace('-', "\u{2212}")
}

/// A value as a tick label: as many decimals as the step between ticks needs, or
/// scientific notation for very large and very small magnitudes.
pub fn tick_label(v: f64, step: f64) -> String {
    if v == 0.0 {
        return "0".into();
    }
    if needs_scientific(v.abs()) {
        return scientific(v);
    }
    let decimals = if step > 0.0 && step.is_finite() {
        (-step.log10().floor()).max(0.0) as usize
    } else {
        3
    };
    let text = format!("{v:.decimals$}");
    if text
        .trim_start_matches('-')
        .chars()
        .all(|c| c == '0' || c == '.')
    {
        "0".into()
    } else {
        text
    }
}

/// The labels of a bar's ends, in one notation: three significant digits of each
/// (`0.0348`, `0.7177`: an end rounded to the ticks' step would misstate the range),
/// without trailing zeros; scientific notation where the larger magnitude is below 10^-3
/// or from 10^5.
pub fn end_labels(lo: f64, hi: f64) -> [String; 2] {
    let m = lo.abs().max(hi.abs());
    if m == 0.0 || !m.is_finite() {
        return [lo, hi].map(|v| format!("{v}"));
    }
    let scientific = || [lo, hi].map(scientific);
    if needs_scientific(m) {
        return scientific();
    }
    // Decimals for `digits` significant digits of `v`.
    let decimals = |v: f64, digits: i32| {
        if v == 0.0 {
            0
        } else {
            (digits - 1 - v.abs().log10().floor() as i32).clamp(0, 12) as usize
        }
    };
    let fixed = |v: f64, d: usize| {
        let text = format!("{v:.d$}");
        let text = if text.contains('.') {
            text.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            text
        };
        if text == "-0" {
            "0".into()
        } else {
            text
        }
    };
    // The decimals the smaller end needs, shared, but no end past four significant
    // digits (0.00148 and 14.81, not 14.806337).
    let d = decimals(lo, 3).max(decimals(hi, 3)).min(6);
    let mut labels = [lo, hi].map(|v| fixed(v, d.min(decimals(v, 4))));
    // A narrow range keeps its ends apart: more decimals until they differ.
    let mut more = d;
    while lo < hi && labels[0] == labels[1] && more < 12 {
        more += 1;
        labels = [lo, hi].map(|v| fixed(v, more));
    }
    // An end far below the other (a log scale's decades) loses its digits to the shared
    // decimals, down to "0" for 3·10⁻⁹: each end then takes its own three digits, in
    // scientific notation where its magnitude needs it (`3.2e-9` … `8.16`, not `8.16e0`).
    let lost = [lo, hi].iter().zip(&labels).any(|(&v, label)| {
        v != 0.0
            && label
                .parse::<f64>()
                .map_or(true, |shown| ((shown - v) / v).abs() > 0.05)
    });
    if lost {
        return [lo, hi].map(|v| match needs_scientific(v.abs()) {
            true => self::scientific(v),
            false => fixed(v, decimals(v, 3)),
        });
    }
    labels
}

/// The labels of a log bar's ends: each in its own notation, as the decade ticks
/// between them are (`6.81e-5` … `4.46`, not `0.000068` … `4.463`, whose shared
/// decimals widen the lower end past the first ticks' labels).
pub fn log_end_labels(lo: f64, hi: f64) -> [String; 2] {
    [lo, hi].map(|v| {
        if v == 0.0 || !v.is_finite() {
            return format!("{v}");
        }
        if needs_scientific(v.abs()) {
            return scientific(v);
        }
        let d = (2 - v.abs().log10().floor() as i32).clamp(0, 12) as usize;
        let text = format!("{v:.d$}");
        match text.contains('.') {
            true => text.trim_end_matches('0').trim_end_matches('.').to_string(),
            false => text,
        }
    })
}

/// Round values from `lo` to `hi` (inclusive) about `count` steps apart: steps of 1, 2
/// or 5 times a power of ten. Returns the ticks and the step.
pub fn linear_ticks(lo: f64, hi: f64, count: usize) -> (Vec<f64>, f64) {
    let span = hi - lo;
    if !(span > 0.0 && span.is_finite()) {
        return (vec![lo], 0.0);
    }
    let raw = span / count.max(1) as f64;
    let power = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|m| m * power)
        .find(|&s| s >= raw)
        .unwrap_or(10.0 * power);
    let first = (lo / step).ceil() as i64;
    let last = (hi / step).floor() as i64;
    let ticks = (first..=last).map(|k| k as f64 * step).collect();
    (ticks, step)
}

/// A linear bar's tick labels and end labels in one notation: every tick in scientific
/// notation where the largest is (no `20000 … 1e5`), and ends written in fixed
/// notation given at least the ticks' decimals (`-3.0 … -3.5`, not `-3 … -3.5`).
fn linear_labels(
    ticks: Vec<f64>,
    step: f64,
    [lo, hi]: [f64; 2],
) -> (Vec<(f64, String)>, [String; 2]) {
    let largest = ticks.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let ends = end_labels(lo, hi);
    if needs_scientific(largest) {
        return (
            ticks.into_iter().map(|v| (v, scientific(v))).collect(),
            ends,
        );
    }
    // Fixed notation throughout, as many decimals as the step needs (0.0005 beside
    // 0.0010, not 5e-4).
    let places = if step > 0.0 && step.is_finite() {
        ((-step.log10().floor()).max(0.0) as usize).min(12)
    } else {
        3
    };
    let labels: Vec<(f64, String)> = ticks
        .into_iter()
        .map(|v| {
            let text = format!("{v:.places$}");
            let zero = text
                .trim_start_matches('-')
                .chars()
                .all(|c| c == '0' || c == '.');
            (v, if zero { "0".to_string() } else { text })
        })
        .collect();
    let decimals = |text: &str| text.split_once('.').map_or(0, |(_, d)| d.len());
    let wanted = labels.iter().map(|(_, t)| decimals(t)).max().unwrap_or(0);
    let pad = |v: f64, text: String| {
        if text.contains('e') || text == "0" || decimals(&text) >= wanted {
            return text;
        }
        let padded = format!("{v:.wanted$}");
        // Padding only: an end whose digits the ticks' decimals would round keeps them.
        if padded.parse::<f64>().ok() == text.parse::<f64>().ok() {
            padded
        } else {
            text
        }
    };
    let [low, high] = ends;
    (labels, [pad(lo, low), pad(hi, high)])
}

/// A log bar's tick labels, in one notation: scientific for all where some tick needs it
/// (`1e-4 … 1e-1`, not `1e-4, 0.001, …`), else each value's own shortest text.
fn log_labels(ticks: Vec<f64>) -> Vec<(f64, String)> {
    let scientific_all = ticks.iter().any(|v| needs_scientific(v.abs()));
    ticks
        .into_iter()
        .map(|v| match scientific_all {
            true => (v, scientific(v)),
            false => (v, tick_label(v, v)),
        })
        .collect()
}

/// Powers of ten from `lo` to `hi` (both above 0); with fewer than two of them, also 2
/// and 5 times each power.
pub fn log_ticks(lo: f64, hi: f64) -> Vec<f64> {
    if !(lo > 0.0 && hi > lo && hi.is_finite()) {
        return vec![];
    }
    // Ends read from single precision (1e-3 is 1.0000000475e-3) still hold their decade.
    let (a, b) = (
        (lo.log10() - 1e-6).ceil() as i32,
        (hi.log10() + 1e-6).floor() as i32,
    );
    // At most about eight ticks, evenly spaced: every decade, or every k-th (multiples
    // of k, so 10⁻⁶, 10⁰, 10⁶, ... over 60 decades), so the labels the bar has room for
    // are regular.
    let step = ((b - a + 1) as usize).div_ceil(8).max(1) as i32;
    let decades: Vec<f64> = (a..=b)
        .filter(|k| k.rem_euclid(step) == 0)
        .map(|k| 10f64.powi(k))
        .collect();
    if decades.len() >= 2 {
        return decades;
    }
    let (a, b) = (lo.log10().floor() as i32, hi.log10().ceil() as i32);
    let within = |v: f64| v >= lo * (1.0 - 1e-9) && v <= hi * (1.0 + 1e-9);
    let steps: Vec<f64> = (a..=b)
        .flat_map(|k| [1.0, 2.0, 5.0].map(|m| m * 10f64.powi(k)))
        .filter(|&v| within(v))
        .collect();
    if steps.len() >= 2 {
        return steps;
    }
    // A range within a factor of about two (0.3 to 0.5): round numbers evenly spaced,
    // as a linear bar's, placed on the log axis.
    let (linear, _) = linear_ticks(lo, hi, 4);
    linear
        .into_iter()
        .filter(|&v| v > 0.0 && within(v))
        .collect()
}

/// Where a legend drawn into an image sits.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Corner {
    TopLeft,
    TopRight,
    BottomLeft,
    BottomRight,
}

/// The first two of `panels` (each at its corner, over the room it needs with its margin,
/// as [`Legend::room_needed`] gives it) that would cover one another in a `width` ×
/// `height` image, by their places in the list. Two at one corner are not compared (a
/// caller refuses those by name).
pub fn overlapping(
    panels: &[(Corner, [u32; 2])],
    width: u32,
    height: u32,
) -> Option<(usize, usize)> {
    // The pixels a panel covers, as half-open ranges across and down.
    let span = |corner: Corner, [pw, ph]: [u32; 2]| {
        let left = matches!(corner, Corner::TopLeft | Corner::BottomLeft);
        let top = matches!(corner, Corner::TopLeft | Corner::TopRight);
        let x = if left {
            [0, pw]
        } else {
            [width.saturating_sub(pw), width]
        };
        let y = if top {
            [0, ph]
        } else {
            [height.saturating_sub(ph), height]
        };
        (x, y)
    };
    for (i, a) in panels.iter().enumerate() {
        for (j, b) in panels.iter().enumerate().skip(i + 1) {
            if a.0 == b.0 {
                continue;
            }
            let ((ax, ay), (bx, by)) = (span(a.0, a.1), span(b.0, b.1));
            if ax[0] < bx[1] && bx[0] < ax[1] && ay[0] < by[1] && by[0] < ay[1] {
                return Some((i, j));
            }
        }
    }
    None
}

/// A legend: what an image's colours mean, written as SVG ([`Legend::svg`]) or drawn
/// into the image ([`Legend::draw`]) from one layout, so the two cannot disagree. Lengths
/// are in the SVG's pixels; text is 12 px high, its width taken as 7 px a character,
/// which is the width of the bitmap font an image is drawn with.
#[derive(Clone, Debug, PartialEq)]
pub enum Legend {
    /// A horizontal colour bar, [`WIDTH`] × [`BAR_HEIGHT`].
    Bar {
        title: String,
        /// The colours (linear RGB) at `BAR_SAMPLES` evenly spaced positions along the
        /// bar, its ends included.
        colours: Vec<[f32; 3]>,
        /// Each tick's x, and its label where it leaves room to the ends' and the ticks'
        /// before it.
        ticks: Vec<(f32, Option<String>)>,
        /// The labels under the bar's ends.
        ends: [String; 2],
    },
    /// A key: a disc of each entry's colour (linear RGB) and its name, under the title;
    /// `more` entries left out are said on a last line.
    Key {
        title: Option<String>,
        entries: Vec<(String, [f32; 3])>,
        more: usize,
    },
    /// Lines of text (a movie's timestep, a figure's caption), drawn into images only.
    Text { lines: Vec<String> },
    /// A scale bar `length` legend pixels long (at the scale it is drawn at, the length
    /// in the world `label` names), under its label; drawn into images only.
    Scale { length: f32, label: String },
    /// The directions of the data's x, y and z axes as the view shows them (a tripod, as
    /// OVITO draws one): for each axis, its image direction (right, down) and how far it
    /// points towards the viewer, unit length in all; from [`axes_tripod`].
    Axes { dirs: [[f32; 3]; 3] },
}

/// The side of [`Legend::Axes`]' square panel, px.
const AXES_SIZE: f32 = 84.0;
/// An axis' length when it lies in the image's plane, px.
const AXIS_LENGTH: f32 = 24.0;
/// The axes' colours (sRGB): x red, y green, z blue, as OVITO and VMD draw them.
const AXIS_COLOURS: [[u8; 3]; 3] = [[214, 39, 40], [44, 160, 44], [31, 119, 180]];

/// The tripod of the data's axes as a view with image directions `right` and `up`
/// (world unit vectors; the third, towards the viewer, is `back`) shows them.
pub fn axes_tripod(right: [f32; 3], up: [f32; 3], back: [f32; 3]) -> Legend {
    let dirs = [0, 1, 2].map(|k| [right[k], -up[k], back[k]]);
    Legend::Axes { dirs }
}

/// An axis of [`Legend::Axes`] as drawn.
struct AxisDrawn {
    /// 0, 1, 2: x, y, z.
    k: usize,
    /// Its end (legend px); the centre for an axis along the view.
    end: [f32; 2],
    /// Its label's centre.
    label: [f32; 2],
    /// Along the view (less than a fifth of its length shows): drawn as a ring round
    /// the centre with a dot (towards the viewer, ⊙) or a cross (away, ⊗), as
    /// engineering drawings mark an axis out of or into the page.
    along: Option<bool>,
}

/// The radius of the ring that marks an axis along the view, px.
const ALONG_RING: f32 = 5.5;

impl Legend {
    /// [`Legend::Axes`]' axes in the order they are drawn (farthest first, so that the
    /// nearest lies on top).
    fn axes_drawn(dirs: &[[f32; 3]; 3]) -> Vec<AxisDrawn> {
        let c = AXES_SIZE / 2.0;
        let mut order = [0usize, 1, 2];
        order.sort_by(|&a, &b| dirs[a][2].total_cmp(&dirs[b][2]));
        order
            .iter()
            .map(|&k| {
                let [x, y, z] = dirs[k];
                let len = x.hypot(y);
                if len > 0.2 {
                    let reach = AXIS_LENGTH * len + 8.0;
                    return AxisDrawn {
                        k,
                        end: [c + AXIS_LENGTH * x, c + AXIS_LENGTH * y],
                        label: [c + reach * x / len, c + reach * y / len],
                        along: None,
                    };
                }
                // Its letter where the other two leave room: opposite their sum.
                let (a, b) = ((k + 1) % 3, (k + 2) % 3);
                let away = [-(dirs[a][0] + dirs[b][0]), -(dirs[a][1] + dirs[b][1])];
                let n = away[0].hypot(away[1]);
                let unit = if n > 1e-3 {
                    [away[0] / n, away[1] / n]
                } else {
                    [
                        -std::f32::consts::FRAC_1_SQRT_2,
                        std::f32::consts::FRAC_1_SQRT_2,
                    ]
                };
                AxisDrawn {
                    k,
                    end: [c, c],
                    label: [c + 15.0 * unit[0], c + 15.0 * unit[1]],
                    along: Some(z > 0.0),
                }
            })
            .collect()
    }
}

/// The least room between two labels under a bar, px: wider than a space, so that
/// neighbours never read as one number (`5 6.57`).
const LABEL_GAP: f32 = 7.0;

/// Baseline step of [`Legend::Text`]'s lines, px.
const TEXT_ROW: f32 = 16.0;

/// Height of a colour bar, px.
const BAR_HEIGHT: f32 = 66.0;
/// The bar's top and bottom, px.
const BAR_Y: [f32; 2] = [22.0, 42.0];
/// Baselines of the title and of the labels under the bar, px.
const TITLE_ROW: f32 = 14.0;
const LABEL_ROW: f32 = BAR_Y[1] + 17.0;
/// Samples of a bar's colours: one at each end of each of its pixels.
const BAR_SAMPLES: usize = (BAR[1] - BAR[0]) as usize + 1;
/// A key's row height, px.
const KEY_ROW: f32 = 20.0;
/// Width of a character, px (the image font's; an estimate for the SVG's sans-serif).
const CHAR_WIDTH: f32 = 7.0;

/// The middle of a key's row `k` (or, for `k` = the entries' count, of the row after the
/// last), below a title's row when it has one.
fn key_row(titled: bool, k: usize) -> f32 {
    let top = if titled { KEY_ROW } else { 0.0 };
    5.0 + top + KEY_ROW * (k as f32 + 0.5)
}

/// How a text sits on its x.
#[derive(Clone, Copy)]
enum Anchor {
    Start,
    Middle,
    End,
}

/// A horizontal colour bar: `title` above it, the gradient `colour(t)` for `t` in
/// [0, 1] along it, and ticks at `ticks` (value, label), each at `position(value)` in
/// [0, 1]; the ends labelled `ends` (with `≤`/`≥` where values beyond them take the
/// ends' colours).
fn bar(
    title: &str,
    colour: &dyn Fn(f32) -> [f32; 3],
    position: &dyn Fn(f64) -> f32,
    ticks: &[(f64, String)],
    ends: [String; 2],
) -> Legend {
    let colours = (0..BAR_SAMPLES)
        .map(|k| colour(k as f32 / (BAR_SAMPLES - 1) as f32))
        .collect();
    let x_of = |t: f32| BAR[0] + t.clamp(0.0, 1.0) * (BAR[1] - BAR[0]);
    // The ticks' labels that leave room to the ends' and to each other.
    let width_of = |text: &str| CHAR_WIDTH * text.chars().count() as f32;
    let mut free_from = BAR[0] + width_of(&ends[0]) + LABEL_GAP;
    let free_to = BAR[1] - width_of(&ends[1]) - LABEL_GAP;
    // (A tick under an end's label, unlabelled, would read as that end: left out, but
    // for one at the end itself, which the label names.)
    let (under_low, under_high) = (free_from - LABEL_GAP, free_to + LABEL_GAP);
    let at_end = |x: f32| x <= BAR[0] + 0.5 || x >= BAR[1] - 0.5;
    let ticks = ticks
        .iter()
        .map(|(v, label)| (x_of(position(*v)), label))
        .filter(|&(x, _)| at_end(x) || (x >= under_low && x <= under_high))
        .map(|(x, label)| {
            let half = width_of(label) / 2.0;
            let fits = x - half >= free_from && x + half <= free_to;
            if fits {
                free_from = x + half + LABEL_GAP;
            }
            (x, fits.then(|| label.clone()))
        })
        .collect();
    Legend::Bar {
        title: title.to_string(),
        colours,
        ticks,
        ends,
    }
}

impl Legend {
    /// Width and height, px.
    pub fn size(&self) -> (f32, f32) {
        match self {
            // Wider than the bar where the title needs it.
            Legend::Bar { title, .. } => (
                WIDTH.max(2.0 * BAR[0] + CHAR_WIDTH * title.chars().count() as f32),
                BAR_HEIGHT,
            ),
            Legend::Key {
                title,
                entries,
                more,
            } => {
                let rows = entries.len() + usize::from(*more > 0);
                let height = key_row(title.is_some(), rows.max(1)) - KEY_ROW / 2.0 + 5.0;
                let width = 40.0
                    + entries
                        .iter()
                        .map(|(n, _)| n.chars().count() as f32 * 7.5)
                        .chain(
                            (*more > 0)
                                .then(|| more_line(*more).chars().count() as f32 * 7.5 - 20.0),
                        )
                        .chain(title.iter().map(|t| t.chars().count() as f32 * 7.5 - 30.0))
                        .fold(60.0, f32::max);
                (width, height)
            }
            Legend::Text { lines } => {
                let longest = lines.iter().map(|l| l.chars().count()).max().unwrap_or(0);
                (
                    14.0 + CHAR_WIDTH * longest as f32,
                    6.0 + TEXT_ROW * lines.len().max(1) as f32,
                )
            }
            Legend::Scale { length, label } => (
                14.0 + length.max(CHAR_WIDTH * label.chars().count() as f32),
                SCALE_BAR[1] + 6.0,
            ),
            Legend::Axes { .. } => (AXES_SIZE, AXES_SIZE),
        }
    }

    /// The legend as an SVG document: plain text (a gradient, rectangles, circles, lines
    /// and `<text>`), to edit and place beside the PNG in a figure tool.
    pub fn svg(&self) -> String {
        let (width, height) = self.size();
        let mut svg = String::new();
        let _ = writeln!(
            svg,
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" viewBox="0 0 {width} {height}" font-family="sans-serif" font-size="12">"#
        );
        match self {
            Legend::Bar {
                title,
                colours,
                ticks,
                ends,
            } => {
                let _ = writeln!(
                    svg,
                    r#"<defs><linearGradient id="bar" x1="0" x2="1" y1="0" y2="0">"#
                );
                let every = (BAR_SAMPLES - 1) / (GRADIENT_STOPS - 1);
                for k in 0..GRADIENT_STOPS {
                    let t = k as f32 / (GRADIENT_STOPS - 1) as f32;
                    let _ = writeln!(
                        svg,
                        r#"<stop offset="{t:.4}" stop-color="{}"/>"#,
                        hex(colours[k * every])
                    );
                }
                let _ = writeln!(svg, "</linearGradient></defs>");
                let _ = writeln!(
                    svg,
                    r#"<text x="{}" y="{TITLE_ROW}">{}</text>"#,
                    BAR[0],
                    escape(title)
                );
                let [y0, y1] = BAR_Y;
                let _ = writeln!(
                    svg,
                    r##"<rect x="{}" y="{y0}" width="{}" height="{}" fill="url(#bar)" stroke="#000" stroke-width="0.5"/>"##,
                    BAR[0],
                    BAR[1] - BAR[0],
                    y1 - y0
                );
                let _ = writeln!(
                    svg,
                    r#"<text x="{}" y="{LABEL_ROW}" text-anchor="start">{}</text>"#,
                    BAR[0],
                    number(&ends[0])
                );
                let _ = writeln!(
                    svg,
                    r#"<text x="{}" y="{LABEL_ROW}" text-anchor="end">{}</text>"#,
                    BAR[1],
                    number(&ends[1])
                );
                for (x, label) in ticks {
                    let _ = writeln!(
                        svg,
                        r##"<line class="tick" x1="{x:.2}" y1="{y1}" x2="{x:.2}" y2="{}" stroke="#000" stroke-width="1"/>"##,
                        y1 + 5.0
                    );
                    if let Some(label) = label {
                        let _ = writeln!(
                            svg,
                            r#"<text class="tick" x="{x:.2}" y="{LABEL_ROW}" text-anchor="middle">{}</text>"#,
                            number(label)
                        );
                    }
                }
            }
            Legend::Key {
                title,
                entries,
                more,
            } => {
                if let Some(t) = title {
                    let _ = writeln!(svg, r#"<text x="7" y="16">{}</text>"#, escape(t));
                }
                for (k, (name, colour)) in entries.iter().enumerate() {
                    let y = key_row(title.is_some(), k);
                    let _ = writeln!(
                        svg,
                        r##"<circle cx="14" cy="{y}" r="7" fill="{}" stroke="#000" stroke-width="0.5"/>"##,
                        hex(*colour)
                    );
                    let _ = writeln!(
                        svg,
                        r#"<text x="28" y="{}">{}</text>"#,
                        y + 4.0,
                        escape(name)
                    );
                }
                if *more > 0 {
                    let y = key_row(title.is_some(), entries.len());
                    let _ = writeln!(
                        svg,
                        r#"<text x="7" y="{}">{}</text>"#,
                        y + 4.0,
                        escape(&more_line(*more))
                    );
                }
            }
            Legend::Text { lines } => {
                for (k, line) in lines.iter().enumerate() {
                    let _ = writeln!(
                        svg,
                        r#"<text x="7" y="{}">{}</text>"#,
                        text_row(k),
                        escape(line)
                    );
                }
            }
            Legend::Scale { length, label } => {
                let _ = writeln!(
                    svg,
                    r#"<text x="7" y="{}">{}</text>"#,
                    text_row(0),
                    escape(label)
                );
                let _ = writeln!(
                    svg,
                    r#"<rect x="7" y="{}" width="{length}" height="{}" fill="black"/>"#,
                    SCALE_BAR[0],
                    SCALE_BAR[1] - SCALE_BAR[0]
                );
            }
            Legend::Axes { dirs } => {
                let c = AXES_SIZE / 2.0;
                for a in Legend::axes_drawn(dirs) {
                    let [r, g, b] = AXIS_COLOURS[a.k];
                    let colour = format!("#{r:02x}{g:02x}{b:02x}");
                    match a.along {
                        None => {
                            let _ = writeln!(
                                svg,
                                r#"<line x1="{c}" y1="{c}" x2="{}" y2="{}" stroke="{colour}" stroke-width="2.5" stroke-linecap="round"/>"#,
                                a.end[0], a.end[1]
                            );
                        }
                        Some(towards) => {
                            let _ = writeln!(
                                svg,
                                r#"<circle cx="{c}" cy="{c}" r="{ALONG_RING}" fill="none" stroke="{colour}" stroke-width="1.5"/>"#
                            );
                            if towards {
                                let _ = writeln!(
                                    svg,
                                    r#"<circle cx="{c}" cy="{c}" r="1.8" fill="{colour}"/>"#
                                );
                            } else {
                                let d = ALONG_RING * std::f32::consts::FRAC_1_SQRT_2;
                                for (x1, y1, x2, y2) in
                                    [(c - d, c - d, c + d, c + d), (c - d, c + d, c + d, c - d)]
                                {
                                    let _ = writeln!(
                                        svg,
                                        r#"<line x1="{x1}" y1="{y1}" x2="{x2}" y2="{y2}" stroke="{colour}" stroke-width="1.5"/>"#
                                    );
                                }
                            }
                        }
                    }
                    let _ = writeln!(
                        svg,
                        r#"<text x="{}" y="{}" text-anchor="middle">{}</text>"#,
                        a.label[0],
                        a.label[1] + 4.0,
                        ["x", "y", "z"][a.k]
                    );
                }
            }
        }
        svg.push_str("</svg>\n");
        svg
    }

    /// The smallest image (width, height) that holds the legend drawn at `scale`, with its
    /// margin.
    pub fn room_needed(&self, scale: u32) -> (u32, u32) {
        let s = scale.max(1);
        let (w, h) = self.size();
        let (pw, ph) = ((w * s as f32).ceil() as u32, (h * s as f32).ceil() as u32);
        (pw + 16 * s, ph + 16 * s)
    }

    /// [`Self::scale_for`], or `fixed` where given (a figure's panels enlarged for
    /// print) and the image holds the legend at it; `None` where it does not.
    pub fn scale_in(&self, width: u32, height: u32, fixed: Option<u32>) -> Option<u32> {
        match fixed {
            Some(s) => {
                let (w, h) = self.room_needed(s);
                (w <= width && h <= height).then_some(s)
            }
            None => self.scale_for(width, height),
        }
    }

    /// The scale to draw the legend at in a `width` × `height` image: whole steps of one
    /// image pixel per legend pixel for each 1280 × 720 of the image (rounded to the
    /// nearest, so that a 1920 × 1080 slide's text is drawn twice as large, readable on a
    /// projector), less where the image cannot hold it; `None` where it cannot hold it at
    /// 1.
    pub fn scale_for(&self, width: u32, height: u32) -> Option<u32> {
        let steps = (f64::from(width) / 1280.0)
            .min(f64::from(height) / 720.0)
            .round()
            .max(1.0) as u32;
        (1..=steps).rev().find(|&s| {
            let (w, h) = self.room_needed(s);
            w <= width && h <= height
        })
    }

    /// The characters of the legend's texts the image font has no glyph for (drawn as
    /// `?`), each once.
    pub fn missing_glyphs(&self) -> Vec<char> {
        let texts: Vec<&str> = match self {
            Legend::Bar {
                title, ticks, ends, ..
            } => std::iter::once(title.as_str())
                .chain(ends.iter().map(String::as_str))
                .chain(ticks.iter().filter_map(|(_, l)| l.as_deref()))
                .collect(),
            Legend::Key { title, entries, .. } => title
                .iter()
                .map(String::as_str)
                .chain(entries.iter().map(|(n, _)| n.as_str()))
                .collect(),
            Legend::Text { lines } => lines.iter().map(String::as_str).collect(),
            Legend::Scale { label, .. } => vec![label.as_str()],
            Legend::Axes { .. } => vec!["xyz"],
        };
        let mut missing: Vec<char> = texts
            .iter()
            .flat_map(|t| t.chars())
            .filter(|&c| !font::has_glyph(c))
            .collect();
        missing.sort_unstable();
        missing.dedup();
        missing
    }

    /// The rectangle (left, top, width, height, in pixels) the legend's panel covers in
    /// an image of `width` × `height` at `corner` and `scale`, margin excluded; `None`
    /// where the image cannot hold it.
    pub fn panel_rect(
        &self,
        width: u32,
        height: u32,
        corner: Corner,
        scale: u32,
    ) -> Option<[u32; 4]> {
        let s = scale.max(1);
        let (w, h) = self.size();
        let (pw, ph) = ((w * s as f32).ceil() as u32, (h * s as f32).ceil() as u32);
        let margin = 8 * s;
        let (need_w, need_h) = self.room_needed(s);
        if need_w > width || need_h > height {
            return None;
        }
        let x0 = match corner {
            Corner::TopLeft | Corner::BottomLeft => margin,
            Corner::TopRight | Corner::BottomRight => width - margin - pw,
        };
        let y0 = match corner {
            Corner::TopLeft | Corner::TopRight => margin,
            Corner::BottomLeft | Corner::BottomRight => height - margin - ph,
        };
        Some([x0, y0, pw, ph])
    }

    /// How many pixels of `image` under the panel [`Self::draw`] would draw show
    /// something other than the background: `background` (sRGB, 8 bits, within 2
    /// levels), or no pixel
    /// with any opacity where it is `None` (a transparent background). Those are data
    /// the panel would cover.
    pub fn covers(
        &self,
        image: &RgbaImage,
        corner: Corner,
        scale: u32,
        background: Option<[u8; 3]>,
    ) -> u64 {
        let Some([x0, y0, pw, ph]) = self.panel_rect(image.width, image.height, corner, scale)
        else {
            return 0;
        };
        let mut n = 0;
        for y in y0..y0 + ph {
            for x in x0..x0 + pw {
                let i = 4 * (y as usize * image.width as usize + x as usize);
                let px = &image.data[i..i + 4];
                let data = match background {
                    // (Within 2 levels: another rounding of the same colour.)
                    Some(b) => px[..3].iter().zip(b).any(|(p, q)| p.abs_diff(q) > 2),
                    None => px[3] != 0,
                };
                n += u64::from(data);
            }
        }
        n
    }

    /// Draws the legend into `image` at `corner`, `scale` image pixels to one of its own
    /// (text in the 7×13 bitmap font of [`crate::font`]), on a white panel at 85 %
    /// opacity so that it reads over any picture. Refuses an image too small to hold it
    /// with a margin, saying how large it must be.
    pub fn draw(&self, image: &mut RgbaImage, corner: Corner, scale: u32) -> Result<(), String> {
        let s = scale.max(1);
        let (w, h) = self.size();
        let Some([x0, y0, pw, ph]) = self.panel_rect(image.width, image.height, corner, s) else {
            let margin = 8 * s;
            let (pw, ph) = ((w * s as f32).ceil() as u32, (h * s as f32).ceil() as u32);
            let (need_w, need_h) = self.room_needed(s);
            return Err(format!(
                "a {}×{} image cannot hold the {} ({pw}×{ph} pixels and a margin of \
                 {margin}: at least {need_w}×{need_h})",
                image.width,
                image.height,
                match self {
                    Legend::Text { .. } => "label",
                    Legend::Scale { .. } => "scale bar",
                    Legend::Axes { .. } => "axes",
                    _ => "legend",
                }
            ));
        };
        let mut panel = Painter {
            image,
            x0,
            y0,
            s,
            size: (pw, ph),
        };
        panel.fill([0.0, 0.0], [w, h], [255; 3], 0.85);
        let black = [0u8; 3];
        match self {
            Legend::Bar {
                title,
                colours,
                ticks,
                ends,
            } => {
                panel.text(BAR[0], TITLE_ROW, title, Anchor::Start);
                // The gradient, one sample per image pixel's centre.
                let [y0, y1] = BAR_Y;
                let span = (BAR[1] - BAR[0]) * s as f32;
                for px in 0..span.round() as u32 {
                    let t = (px as f32 + 0.5) / span;
                    let c = colours[(t * (BAR_SAMPLES - 1) as f32).round() as usize];
                    let srgb = srgb8(c);
                    let x = BAR[0] + (px as f32 + 0.5) / s as f32;
                    panel.fill(
                        [x - 0.5 / s as f32, y0],
                        [x + 0.5 / s as f32, y1],
                        srgb,
                        1.0,
                    );
                }
                let line = 1.0 / s as f32;
                panel.fill([BAR[0], y0], [BAR[1], y0 + line], black, 1.0);
                panel.fill([BAR[0], y1 - line], [BAR[1], y1], black, 1.0);
                panel.fill([BAR[0], y0], [BAR[0] + line, y1], black, 1.0);
                panel.fill([BAR[1] - line, y0], [BAR[1], y1], black, 1.0);
                panel.text(BAR[0], LABEL_ROW, &ends[0], Anchor::Start);
                panel.text(BAR[1], LABEL_ROW, &ends[1], Anchor::End);
                for (x, label) in ticks {
                    panel.fill([x - 0.5, y1], [x + 0.5, y1 + 5.0], black, 1.0);
                    if let Some(label) = label {
                        panel.text(*x, LABEL_ROW, label, Anchor::Middle);
                    }
                }
            }
            Legend::Key {
                title,
                entries,
                more,
            } => {
                if let Some(t) = title {
                    panel.text(7.0, 16.0, t, Anchor::Start);
                }
                for (k, (name, colour)) in entries.iter().enumerate() {
                    let y = key_row(title.is_some(), k);
                    let srgb = srgb8(*colour);
                    panel.disc([14.0, y], 7.0, srgb);
                    panel.text(28.0, y + 4.0, name, Anchor::Start);
                }
                if *more > 0 {
                    let y = key_row(title.is_some(), entries.len());
                    panel.text(7.0, y + 4.0, &more_line(*more), Anchor::Start);
                }
            }
            Legend::Text { lines } => {
                for (k, line) in lines.iter().enumerate() {
                    panel.text(7.0, text_row(k), line, Anchor::Start);
                }
            }
            Legend::Scale { length, label } => {
                panel.text(7.0, text_row(0), label, Anchor::Start);
                panel.fill(
                    [7.0, SCALE_BAR[0]],
                    [7.0 + length, SCALE_BAR[1]],
                    black,
                    1.0,
                );
            }
            Legend::Axes { dirs } => {
                let c = AXES_SIZE / 2.0;
                for a in Legend::axes_drawn(dirs) {
                    let colour = AXIS_COLOURS[a.k];
                    match a.along {
                        None => panel.line([c, c], a.end, 2.5, colour),
                        Some(towards) => {
                            panel.ring([c, c], ALONG_RING, 1.5, colour);
                            if towards {
                                panel.ring([c, c], 0.0, 3.6, colour);
                            } else {
                                let d = ALONG_RING * std::f32::consts::FRAC_1_SQRT_2;
                                panel.line([c - d, c - d], [c + d, c + d], 1.5, colour);
                                panel.line([c - d, c + d], [c + d, c - d], 1.5, colour);
                            }
                        }
                    }
                    panel.text(
                        a.label[0],
                        a.label[1] + 4.0,
                        ["x", "y", "z"][a.k],
                        Anchor::Middle,
                    );
                }
            }
        }
        Ok(())
    }
}

/// The top and bottom of a scale bar, legend px.
const SCALE_BAR: [f32; 2] = [22.0, 26.0];

/// The baseline of [`Legend::Text`]'s line `k`, px.
fn text_row(k: usize) -> f32 {
    TEXT_ROW * (k + 1) as f32
}

/// Paints a legend's shapes, in its own pixels, into an image region.
struct Painter<'a> {
    image: &'a mut RgbaImage,
    /// The region's top left corner in the image.
    x0: u32,
    y0: u32,
    /// Image pixels to one legend pixel.
    s: u32,
    /// The region's size in image pixels; nothing is painted outside it.
    size: (u32, u32),
}

impl Painter<'_> {
    /// Lays `colour` with coverage `a` over the image pixels whose centres lie in the
    /// rectangle from `lo` to `hi` (legend pixels).
    fn fill(&mut self, lo: [f32; 2], hi: [f32; 2], colour: [u8; 3], a: f32) {
        let s = self.s as f32;
        let range = |lo: f32, hi: f32, size: u32| {
            let first = (lo * s - 0.5).ceil().max(0.0) as u32;
            let end = ((hi * s - 0.5).ceil().max(0.0) as u32).min(size);
            first..end
        };
        for y in range(lo[1], hi[1], self.size.1) {
            for x in range(lo[0], hi[0], self.size.0) {
                self.image.blend_over(self.x0 + x, self.y0 + y, colour, a);
            }
        }
    }

    /// A line of `colour` and `width` (legend px) with round ends from `a` to `b`,
    /// anti-aliased by each pixel centre's distance to it.
    fn line(&mut self, a: [f32; 2], b: [f32; 2], width: f32, colour: [u8; 3]) {
        let s = self.s as f32;
        let r = width / 2.0;
        let lo = [a[0].min(b[0]) - r - 1.0, a[1].min(b[1]) - r - 1.0];
        let hi = [a[0].max(b[0]) + r + 1.0, a[1].max(b[1]) + r + 1.0];
        let (d, len2) = (
            [b[0] - a[0], b[1] - a[1]],
            (b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2),
        );
        let first = |v: f32| (v * s).floor().max(0.0) as u32;
        for y in first(lo[1])..((hi[1] * s).ceil().max(0.0) as u32).min(self.size.1) {
            for x in first(lo[0])..((hi[0] * s).ceil().max(0.0) as u32).min(self.size.0) {
                let p = [(x as f32 + 0.5) / s, (y as f32 + 0.5) / s];
                let t = if len2 > 0.0 {
                    (((p[0] - a[0]) * d[0] + (p[1] - a[1]) * d[1]) / len2).clamp(0.0, 1.0)
                } else {
                    0.0
                };
                let dist = (p[0] - a[0] - t * d[0]).hypot(p[1] - a[1] - t * d[1]);
                let cover = ((r - dist) * s + 0.5).clamp(0.0, 1.0);
                if cover > 0.0 {
                    self.image
                        .blend_over(self.x0 + x, self.y0 + y, colour, cover);
                }
            }
        }
    }

    /// A ring of `colour`, radius `r` and `width` round `c` (radius 0: a dot of diameter
    /// `width`), anti-aliased as [`Self::line`].
    fn ring(&mut self, c: [f32; 2], r: f32, width: f32, colour: [u8; 3]) {
        let s = self.s as f32;
        let reach = r + width / 2.0 + 1.0;
        let first = |v: f32| (v * s).floor().max(0.0) as u32;
        let last = |v: f32, size: u32| ((v * s).ceil().max(0.0) as u32).min(size);
        for y in first(c[1] - reach)..last(c[1] + reach, self.size.1) {
            for x in first(c[0] - reach)..last(c[0] + reach, self.size.0) {
                let d = ((x as f32 + 0.5) / s - c[0]).hypot((y as f32 + 0.5) / s - c[1]);
                let cover = ((width / 2.0 - (d - r).abs()) * s + 0.5).clamp(0.0, 1.0);
                if cover > 0.0 {
                    self.image
                        .blend_over(self.x0 + x, self.y0 + y, colour, cover);
                }
            }
        }
    }

    /// A disc of `colour` with a black rim, centred at `c`.
    fn disc(&mut self, c: [f32; 2], r: f32, colour: [u8; 3]) {
        let s = self.s as f32;
        let (lo, hi) = (((c[1] - r - 1.0) * s) as u32, ((c[1] + r + 1.0) * s) as u32);
        for y in lo..hi.min(self.size.1) {
            for x in ((c[0] - r - 1.0) * s) as u32..(((c[0] + r + 1.0) * s) as u32).min(self.size.0)
            {
                let d = ((x as f32 + 0.5) / s - c[0]).hypot((y as f32 + 0.5) / s - c[1]);
                let (fill, rim) = if d <= r - 0.5 {
                    (colour, 1.0)
                } else {
                    ([0; 3], (r + 0.5 - d).clamp(0.0, 1.0))
                };
                self.image.blend_over(self.x0 + x, self.y0 + y, fill, rim);
            }
        }
    }

    /// `text` in black on the baseline `y`, anchored at `x` (legend pixels).
    fn text(&mut self, x: f32, y: f32, text: &str, anchor: Anchor) {
        let s = self.s;
        let width = CHAR_WIDTH * text.chars().count() as f32;
        let left = match anchor {
            Anchor::Start => x,
            Anchor::Middle => x - width / 2.0,
            Anchor::End => x - width,
        };
        // The font's baseline is 11 of its 13 rows down.
        let top = ((y - 11.0) * s as f32).round().max(0.0) as u32;
        let mut gx = (left * s as f32).round().max(0.0) as u32;
        for c in text.chars() {
            for (row, bits) in font::glyph(c).iter().enumerate() {
                for col in 0..font::GLYPH_WIDTH {
                    if bits & (0x40 >> col) == 0 {
                        continue;
                    }
                    for dy in 0..s {
                        for dx in 0..s {
                            let (px, py) = (gx + col * s + dx, top + row as u32 * s + dy);
                            if px < self.size.0 && py < self.size.1 {
                                self.image
                                    .blend_over(self.x0 + px, self.y0 + py, [0; 3], 1.0);
                            }
                        }
                    }
                }
            }
            gx += font::GLYPH_WIDTH * s;
        }
    }
}

/// The colour bar of `map` over an attribute named `name`, as `scale` (the renderer's,
/// with the shown range and log flag) maps it; `range` is the range shown, `data` the
/// smallest and largest value the particles hold: an end past which some lie (drawn in
/// the end's colour) is labelled `≤` or `≥`.
pub fn colour_bar(
    map: ColourMap,
    scale: &AttributeScale,
    name: &str,
    range: [f32; 2],
    data: [f32; 2],
) -> Legend {
    let colour = |t: f32| map.colour(t);
    let position = |v: f64| scale.of_value(v as f32);
    // A constant attribute shown over no range: every particle takes the map's last
    // colour, and no scale places it.
    if range[0] >= range[1] {
        let top = map.colour(1.0);
        return bar(
            &format!("{name}: every value {} (constant)", range[0]),
            &|_| top,
            &|_| 1.0,
            &[],
            [String::new(), String::new()],
        );
    }
    match scale.log_range() {
        Some([lo, hi]) => {
            let ticks = log_labels(log_ticks(lo, hi));
            // A range from 0 or below starts the scale decades below its top: values at
            // or below that take its colour.
            let [low, high] = log_end_labels(lo, hi);
            let [low, high] = beyond_marks([low, high], [lo, hi], data);
            let low = match range[0] <= 0.0 && !low.starts_with('≤') {
                true => format!("≤ {low}"),
                false => low,
            };
            bar(&log_titled(name), &colour, &position, &ticks, [low, high])
        }
        None => {
            let [lo, hi] = range.map(f64::from);
            let (ticks, step) = linear_ticks(lo, hi, 5);
            let (ticks, ends) = linear_labels(ticks, step, [lo, hi]);
            let labels = beyond_marks(ends, [lo, hi], data);
            bar(name, &colour, &position, &ticks, labels)
        }
    }
}

/// End labels marked `≤` (`≥`) where `data` reaches below (above) the bar's ends
/// `[lo, hi]`: particles there take the end's colour.
fn beyond_marks([low, high]: [String; 2], [lo, hi]: [f64; 2], data: [f32; 2]) -> [String; 2] {
    // (A range derived from the data is the data's own ends, up to rounding.)
    let slack = 1e-6 * lo.abs().max(hi.abs());
    let below = f64::from(data[0]) < lo - slack;
    let above = f64::from(data[1]) > hi + slack;
    [
        if below { format!("≤ {low}") } else { low },
        if above { format!("≥ {high}") } else { high },
    ]
}

/// The bar of a projected image's colour map: `title` (what the light is) over
/// `[lo, hi]`, on a log scale when `log` (as `SplatFrame::colour_mapped` maps it);
/// `lit` is the light of the faintest and brightest lit pixels, an end that cuts them
/// marked `≤` or `≥` (a cusp's core brighter than the map's top takes the top colour).
pub fn light_bar(
    map: ColourMap,
    title: &str,
    [lo, hi]: [f32; 2],
    log: bool,
    lit: [f32; 2],
) -> Legend {
    let info = mdlod_format::meta::AttributeInfo {
        name: String::new(),
        min: lo,
        max: hi,
        log10: false,
    };
    let scale = AttributeScale::new(&info).with_log(log && lo > 0.0);
    // (Unlit pixels show the background, not the bottom colour: a linear map from 0
    // cuts nothing below.)
    let lit = [if log { lit[0] } else { lit[0].max(lo) }, lit[1]];
    colour_bar(map, &scale, title, [lo, hi], lit)
}

/// A log scale's bar title: `title (log scale)`, unless the title says so itself (a
/// `--legend-title "E_kin (eV, log scale)"` read "... log scale) (log scale)").
fn log_titled(title: &str) -> String {
    match title.to_ascii_lowercase().contains("log") {
        true => title.to_string(),
        false => format!("{title} (log scale)"),
    }
}

/// The density volume's transfer function: volume fraction φ from `density_min` (clear
/// at and below it) to `density_max`, or its logarithm between them when `log`
/// ([`crate::density::transfer_t`]), under `title` (by default "volume fraction φ").
pub fn density_bar(density_min: f32, density_max: f32, log: bool, title: Option<&str>) -> Legend {
    let title = title.unwrap_or("volume fraction φ");
    let (min, max) = (f64::from(density_min), f64::from(density_max));
    let colour = |t: f32| crate::density::transfer_colour(t).to_array();
    if log && min > 0.0 && max > min {
        let [low, high] = log_end_labels(min, max);
        let ticks = log_labels(log_ticks(min, max));
        let span = (max / min).ln();
        // (Below the bottom the volume is clear, not the bottom's colour: no `≤`.)
        return bar(
            &log_titled(title),
            &colour,
            &|v| ((v / min).ln() / span) as f32,
            &ticks,
            [low, format!("≥ {high}")],
        );
    }
    let (ticks, step) = linear_ticks(min, max, 4);
    let (ticks, [low, high]) = linear_labels(ticks, step, [min, max]);
    let high = format!("≥ {high}");
    bar(
        title,
        &colour,
        &|v| ((v - min) / (max - min)) as f32,
        &ticks,
        [low, high],
    )
}

/// The order a key of species lists their names in, the same for every frame of a run
/// whatever order its particles came in (a file's species table follows the order in
/// which they first appear in the dump): type numbers by value, before names, and
/// names alphabetically, case aside, then exactly.
pub fn key_order(a: &str, b: &str) -> std::cmp::Ordering {
    match (a.parse::<i64>(), b.parse::<i64>()) {
        (Ok(x), Ok(y)) => x.cmp(&y),
        (Ok(_), Err(_)) => std::cmp::Ordering::Less,
        (Err(_), Ok(_)) => std::cmp::Ordering::Greater,
        _ => a.to_lowercase().cmp(&b.to_lowercase()).then(a.cmp(b)),
    }
}

/// A key of the species shown: a disc of each one's colour (linear RGB) and its name,
/// under `title` when given; past [`KEY_ENTRIES`] (a column of molecule ids as species),
/// the first ones and a line saying how many more.
pub fn species_key(entries: &[(String, [f32; 3])], title: Option<&str>) -> Legend {
    let kept = if entries.len() > KEY_ENTRIES {
        KEY_ENTRIES - 1
    } else {
        entries.len()
    };
    Legend::Key {
        title: title.map(str::to_string),
        entries: entries[..kept].to_vec(),
        more: entries.len() - kept,
    }
}

/// The most entries a key lists.
pub const KEY_ENTRIES: usize = 24;

/// The last line of a key that leaves `more` entries out.
fn more_line(more: usize) -> String {
    format!("... and {more} more")
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Panels at two corners overlap where their rooms meet across the image: side by
    /// side when their widths add past it, diagonally only when both sums do; rooms that
    /// just touch do not.
    /// The axes of a view down z: x to the right, y up, z at the centre (towards the
    /// viewer, drawn last, on top), in the SVG as in the image.
    #[test]
    fn axes_point_where_the_view_shows_the_data_axes() {
        let tripod = axes_tripod([1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]);
        let svg = tripod.svg();
        let lines: Vec<&str> = svg.lines().filter(|l| l.starts_with("<line")).collect();
        assert_eq!(lines.len(), 2, "{svg}");
        let c = AXES_SIZE / 2.0;
        assert!(
            lines[0].contains(&format!(r#"x2="{}" y2="{c}""#, c + AXIS_LENGTH)),
            "{svg}"
        );
        assert!(
            lines[1].contains(&format!(r#"x2="{c}" y2="{}""#, c - AXIS_LENGTH)),
            "{svg}"
        );
        // z at the viewer: a ring with a dot, its letter down and left of the centre,
        // away from x and y.
        assert!(
            svg.contains(&format!(r#"<circle cx="{c}" cy="{c}" r="{ALONG_RING}""#)),
            "{svg}"
        );
        assert!(svg.contains(r#"r="1.8""#), "{svg}");
        let z = svg.lines().find(|l| l.ends_with(">z</text>")).expect("z");
        let x: f32 = z.split('"').nth(1).unwrap().parse().unwrap();
        assert!(x < c - 5.0, "{z}");
        // Seen from below (z away): a ring with a cross, not a dot.
        let below = axes_tripod([1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]).svg();
        assert!(!below.contains(r#"r="1.8""#), "{below}");
        assert_eq!(
            below.lines().filter(|l| l.starts_with("<line")).count(),
            4,
            "{below}"
        );
        let mut image = RgbaImage::new(200, 200);
        tripod.draw(&mut image, Corner::TopLeft, 1).unwrap();
        let [x0, y0, _, _] = tripod.panel_rect(200, 200, Corner::TopLeft, 1).unwrap();
        let at = |dx: f32, dy: f32| {
            let (x, y) = (x0 + (c + dx) as u32, y0 + (c + dy) as u32);
            let i = 4 * (y * 200 + x) as usize;
            [image.data[i], image.data[i + 1], image.data[i + 2]]
        };
        assert_eq!(at(AXIS_LENGTH / 2.0, 0.0), AXIS_COLOURS[0]);
        assert_eq!(at(0.0, -AXIS_LENGTH / 2.0), AXIS_COLOURS[1]);
    }

    #[test]
    fn species_keys_list_types_by_number_and_names_alphabetically() {
        let mut names = vec!["O", "10", "Li", "h", "2", "C", "H"];
        names.sort_by(|a, b| key_order(a, b));
        assert_eq!(names, ["2", "10", "C", "H", "h", "Li", "O"]);
    }

    #[test]
    fn panels_at_two_corners_overlap_where_their_rooms_cross() {
        use Corner::*;
        let (w, h) = (800, 600);
        assert_eq!(
            overlapping(&[(BottomRight, [376, 82]), (BottomLeft, [626, 48])], w, h),
            Some((0, 1))
        );
        assert_eq!(
            overlapping(&[(BottomRight, [376, 82]), (BottomLeft, [424, 48])], w, h),
            None
        );
        assert_eq!(
            overlapping(&[(BottomRight, [500, 82]), (TopLeft, [400, 48])], w, h),
            None
        );
        assert_eq!(
            overlapping(&[(BottomRight, [500, 400]), (TopLeft, [400, 300])], w, h),
            Some((0, 1))
        );
        assert_eq!(
            overlapping(&[(TopLeft, [100, 400]), (BottomLeft, [100, 201])], w, h),
            Some((0, 1))
        );
        assert_eq!(
            overlapping(&[(TopLeft, [100, 400]), (TopLeft, [700, 500])], w, h),
            None
        );
        assert_eq!(
            overlapping(
                &[
                    (TopLeft, [10, 10]),
                    (BottomLeft, [10, 10]),
                    (BottomRight, [791, 9])
                ],
                w,
                h
            ),
            Some((1, 2))
        );
    }

    /// What a panel covers: the pixels under its rectangle that are not the background
    /// (within 2 levels), or that have any opacity on a transparent one; none past it.
    #[test]
    fn a_panel_counts_the_data_it_would_cover() {
        let key = Legend::Text {
            lines: vec!["t = 5 ps".into()],
        };
        let mut image = RgbaImage::new(200, 100);
        for px in image.data.chunks_mut(4) {
            px.copy_from_slice(&[255, 255, 255, 255]);
        }
        let [x0, y0, pw, ph] = key.panel_rect(200, 100, Corner::BottomRight, 1).unwrap();
        assert_eq!((x0 + pw + 8, y0 + ph + 8), (200, 100));
        let white = Some([255u8; 3]);
        assert_eq!(key.covers(&image, Corner::BottomRight, 1, white), 0);
        // A 3×2 particle under the panel, one just outside it, and one level off white.
        let mut paint = |x: u32, y: u32, c: [u8; 4]| {
            let i = 4 * (y * 200 + x) as usize;
            image.data[i..i + 4].copy_from_slice(&c);
        };
        for (dx, dy) in [(0, 0), (1, 0), (2, 0), (0, 1), (1, 1), (2, 1)] {
            paint(x0 + 2 + dx, y0 + 1 + dy, [200, 30, 30, 255]);
        }
        paint(x0 - 1, y0, [0, 0, 0, 255]);
        paint(x0 + 10, y0 + 2, [254, 254, 253, 255]);
        assert_eq!(key.covers(&image, Corner::BottomRight, 1, white), 6);
        assert_eq!(key.covers(&image, Corner::TopLeft, 1, white), 0);
        // Transparent: opacity is data.
        let mut clear = RgbaImage::new(200, 100);
        let i = 4 * ((y0 + 3) * 200 + x0 + 3) as usize;
        clear.data[i + 3] = 40;
        assert_eq!(key.covers(&clear, Corner::BottomRight, 1, None), 1);
    }

    /// A key of many species (a column of molecule ids) lists the first ones and says how
    /// many more, in the SVG and in an image, at the height of a key of that many.
    #[test]
    fn a_key_of_many_species_says_how_many_more() {
        let entries: Vec<(String, [f32; 3])> = (0..100)
            .map(|i| (format!("{i}"), [0.5, 0.2, 0.1]))
            .collect();
        let key = species_key(&entries, Some("molecule"));
        let Legend::Key {
            entries: kept,
            more,
            ..
        } = &key
        else {
            panic!("not a key");
        };
        assert_eq!(
            (kept.len(), *more),
            (KEY_ENTRIES - 1, 100 - KEY_ENTRIES + 1)
        );
        let svg = key.svg();
        assert_eq!(svg.matches("<circle").count(), KEY_ENTRIES - 1);
        assert!(
            svg.contains(&format!("... and {} more", 100 - KEY_ENTRIES + 1)),
            "{svg}"
        );
        let small = species_key(&entries[..KEY_ENTRIES], None);
        let full = species_key(&entries[..KEY_ENTRIES], Some("molecule"));
        assert!(matches!(small, Legend::Key { more: 0, .. }));
        assert_eq!(key.room_needed(1).1, full.room_needed(1).1);
    }

    #[test]
    fn ticks_fall_on_round_values_inside_the_range() {
        let (t, step) = linear_ticks(0.0, 1.0, 5);
        let labels: Vec<String> = t.iter().map(|&v| tick_label(v, step)).collect();
        assert_eq!(labels, ["0", "0.2", "0.4", "0.6", "0.8", "1.0"]);
        let (t, step) = linear_ticks(-2.95, 2.95, 5);
        assert_eq!(step, 2.0);
        assert_eq!(t, vec![-2.0, 0.0, 2.0]);
        let (t, step) = linear_ticks(0.0348, 0.7177, 5);
        assert_eq!(step, 0.2);
        assert_eq!(t.len(), 3);
        assert_eq!(log_ticks(1e-3, 1e3).len(), 7);
        assert_eq!(log_ticks(2.0, 60.0), vec![2.0, 5.0, 10.0, 20.0, 50.0]);
        // Within a factor of two, round numbers between the ends.
        let narrow = log_ticks(0.3, 0.5);
        assert!(
            narrow.len() >= 3 && narrow.iter().all(|&v| (0.3..=0.5).contains(&v)),
            "{narrow:?}"
        );
        assert!(log_ticks(0.0, 1.0).is_empty());
    }

    /// The x of every tick line and the text of every tick label in an SVG.
    fn ticks_of(svg: &str) -> (Vec<f32>, Vec<String>) {
        let xs = svg
            .lines()
            .filter(|l| l.starts_with(r#"<line class="tick""#))
            .map(|l| l.split('"').nth(3).unwrap().parse().unwrap())
            .collect();
        let labels = svg
            .lines()
            .filter(|l| l.starts_with(r#"<text class="tick""#))
            .map(|l| {
                l.split('>')
                    .nth(1)
                    .unwrap()
                    .trim_end_matches("</text")
                    .to_string()
            })
            .collect();
        (xs, labels)
    }

    fn stops_of(svg: &str) -> Vec<String> {
        svg.lines()
            .filter(|l| l.starts_with("<stop"))
            .map(|l| l.split('"').nth(3).unwrap().to_string())
            .collect()
    }

    /// The bar is the renderer's mapping: its gradient the colour map's colours, each tick
    /// where [`AttributeScale::of_value`] puts its value, linear and logarithmic.
    #[test]
    fn a_colour_bar_places_ticks_where_the_renderer_maps_their_values() {
        let info = mdlod_format::meta::AttributeInfo {
            name: "c_ke".into(),
            min: 0.0,
            max: 2.5,
            log10: false,
        };
        let scale = AttributeScale::with_range(&info, None);
        let svg = colour_bar(ColourMap::Viridis, &scale, "c_ke", [0.0, 2.5], [0.0, 2.5]).svg();
        let stops = stops_of(&svg);
        assert_eq!(stops.len(), GRADIENT_STOPS);
        assert_eq!(stops[0], hex(ColourMap::Viridis.colour(0.0)));
        assert_eq!(stops[16], hex(ColourMap::Viridis.colour(0.5)));
        assert_eq!(stops[32], hex(ColourMap::Viridis.colour(1.0)));
        let (xs, labels) = ticks_of(&svg);
        // Steps of 0.5 from 0 to 2.5; the ends carry their own labels.
        assert_eq!(xs.len(), 6);
        for (k, x) in xs.iter().enumerate() {
            let want = BAR[0] + (BAR[1] - BAR[0]) * scale.of_value(k as f32 * 0.5);
            assert!((x - want).abs() < 0.01, "{k}: {x} {want}");
        }
        assert_eq!(labels, ["0.5", "1.0", "1.5", "2.0"]);
        assert!(svg.contains(">c_ke</text>") && svg.contains(">2.5</text>"));
        // A tick a label's width and a gap past the end's label is labelled (500 beside
        // 280, a gap of 8.7 px).
        let info = mdlod_format::meta::AttributeInfo {
            name: "v_temp".into(),
            min: 280.1653,
            max: 2029.0062,
            log10: false,
        };
        let scale = AttributeScale::with_range(&info, None);
        let range = [info.min, info.max];
        let svg = colour_bar(ColourMap::Viridis, &scale, "v_temp", range, range).svg();
        assert_eq!(ticks_of(&svg).1, ["500", "1000", "1500"]);

        // Log: decades, the middle one at the middle of the bar.
        let info = mdlod_format::meta::AttributeInfo {
            name: "rho".into(),
            min: 1e-3,
            max: 10.0,
            log10: false,
        };
        let scale = AttributeScale::with_range(&info, None).with_log(true);
        let svg = colour_bar(ColourMap::Magma, &scale, "rho", [1e-3, 10.0], [1e-3, 10.0]).svg();
        let (xs, labels) = ticks_of(&svg);
        assert_eq!(xs.len(), 5);
        assert!((xs[2] - (BAR[0] + BAR[1]) / 2.0).abs() < 0.01, "{xs:?}");
        assert_eq!(labels, ["0.01", "0.1", "1"]);
        assert!(svg.contains("rho (log scale)") && !svg.contains('≤'));
        // From 0: the scale starts four decades below its top, values below take its
        // colour.
        let from_zero = AttributeScale::with_range(&info, Some([0.0, 10.0])).with_log(true);
        let svg = colour_bar(
            ColourMap::Magma,
            &from_zero,
            "rho",
            [0.0, 10.0],
            [0.0, 10.0],
        )
        .svg();
        assert!(svg.contains(">≤ 0.001</text>"), "{svg}");
        // Data reaching below the log scale's start (zeros: frozen atoms) or past its
        // end takes the end colours: marked, as a linear range narrower than the data.
        let from_data = AttributeScale::with_range(&info, Some([1e-3, 1.0])).with_log(true);
        let svg = colour_bar(
            ColourMap::Magma,
            &from_data,
            "rho",
            [1e-3, 1.0],
            [0.0, 10.0],
        )
        .svg();
        assert!(
            svg.contains(">≤ 0.001</text>") && svg.contains(">≥ 1</text>"),
            "{svg}"
        );
        let info = mdlod_format::meta::AttributeInfo {
            name: "vx".into(),
            min: -1.0,
            max: 1.0,
            log10: false,
        };
        let narrow = AttributeScale::with_range(&info, Some([-0.5, 0.5]));
        let svg = colour_bar(ColourMap::CoolWarm, &narrow, "vx", [-0.5, 0.5], [-1.0, 1.0]).svg();
        assert!(
            svg.contains(">≤ \u{2212}0.5</text>") && svg.contains(">≥ 0.5</text>"),
            "{svg}"
        );
        let svg = colour_bar(ColourMap::CoolWarm, &narrow, "vx", [-0.5, 0.5], [-0.5, 0.2]).svg();
        assert!(!svg.contains('≤') && !svg.contains('≥'), "{svg}");
        // A name with markup is escaped.
        let svg = colour_bar(
            ColourMap::Grey,
            &scale,
            "a<b & c",
            [1e-3, 10.0],
            [1e-3, 10.0],
        )
        .svg();
        assert!(svg.contains("a&lt;b &amp; c (log scale)"));
    }

    #[test]
    fn the_density_bar_and_species_key_show_the_colours_drawn() {
        let svg = density_bar(0.0, 0.8, false, None).svg();
        let stops = stops_of(&svg);
        assert_eq!(
            stops[0],
            hex(crate::density::transfer_colour(0.0).to_array())
        );
        assert_eq!(
            stops[32],
            hex(crate::density::transfer_colour(1.0).to_array())
        );
        assert!(
            svg.contains(">≥ 0.80</text>") || svg.contains(">≥ 0.8</text>"),
            "{svg}"
        );
        // On a log scale from 10⁻³ to 10: a tick per decade, evenly spaced, and the
        // colour at each tick the transfer function's there.
        let s = crate::density::DensitySettings {
            density_min: 1e-3,
            density_max: 10.0,
            log: true,
            ..Default::default()
        };
        let svg = density_bar(s.density_min, s.density_max, true, None).svg();
        assert!(svg.contains("volume fraction φ (log scale)"), "{svg}");
        // A title that says it is a log scale is kept as it is.
        assert_eq!(log_titled("E_kin (eV, log scale)"), "E_kin (eV, log scale)");
        assert_eq!(log_titled("log10 rho"), "log10 rho");
        assert_eq!(log_titled("E_kin (eV)"), "E_kin (eV) (log scale)");
        assert!(
            svg.contains(">0.001</text>") && svg.contains(">≥ 10</text>"),
            "{svg}"
        );
        let (xs, labels) = ticks_of(&svg);
        assert_eq!(xs.len(), 5, "{svg}");
        let gaps: Vec<f32> = xs.windows(2).map(|w| w[1] - w[0]).collect();
        assert!(gaps.iter().all(|g| (g - gaps[0]).abs() < 0.01), "{xs:?}");
        assert!(labels.contains(&"0.1".to_string()), "{labels:?}");
        let t = crate::density::transfer_t(0.1, &s);
        assert!((t - 0.5).abs() < 1e-6, "{t}");
        let stops = stops_of(&svg);
        assert_eq!(
            stops[16],
            hex(crate::density::transfer_colour(0.5).to_array())
        );
        // A linear bar from above 0 marks its low end as a bound.
        let svg = density_bar(0.2, 0.8, false, Some("rho")).svg();
        assert!(
            svg.contains(">0.2</text>") && svg.contains(">rho</text>"),
            "{svg}"
        );
        let key = species_key(
            &[
                ("Cu".into(), [1.0, 0.0, 0.0]),
                ("Ag".into(), [0.0, 0.0, 1.0]),
            ],
            None,
        )
        .svg();
        assert!(key.contains(r##"fill="#ff0000""##) && key.contains(">Ag</text>"));
        let titled = species_key(&[("Cu".into(), [1.0, 0.0, 0.0])], Some("Alloy & grain")).svg();
        assert!(titled.contains(">Alloy &amp; grain</text>"), "{titled}");
    }

    /// Ends keep three significant digits in one notation, so the range is not misstated.
    #[test]
    fn end_labels_state_the_range() {
        assert_eq!(end_labels(0.0348, 0.7177), ["0.0348", "0.7177"]);
        assert_eq!(end_labels(0.1595, 3.3), ["0.16", "3.3"]);
        assert_eq!(end_labels(3.12e-4, 0.74), ["0.000312", "0.74"]);
        assert_eq!(end_labels(-3.5972, -1.5666), ["-3.6", "-1.57"]);
        assert_eq!(end_labels(1.36e-5, 1.56e-4), ["1.36e-5", "1.56e-4"]);
        assert_eq!(end_labels(0.0, 2.5), ["0", "2.5"]);
        // A log bar's ends, each in its own notation.
        assert_eq!(log_end_labels(6.809446e-5, 4.46257), ["6.81e-5", "4.46"]);
        assert_eq!(log_end_labels(0.0348, 120.0), ["0.0348", "120"]);
        assert_eq!(log_end_labels(1e-9, 3e6), ["1e-9", "3e6"]);
        assert_eq!(end_labels(12345.0, 250000.0), ["1.23e4", "2.5e5"]);
        // No end past four significant digits; a narrow range keeps its ends apart.
        assert_eq!(end_labels(0.00148, 14.806337), ["0.00148", "14.81"]);
        assert_eq!(end_labels(0.30001, 0.30002), ["0.30001", "0.30002"]);
        assert_eq!(end_labels(-0.5, 12345.678), ["-0.5", "12346"]);
        // A log scale's low end decades below the top keeps its digits.
        assert_eq!(end_labels(3.1968022e-9, 0.9997898), ["3.2e-9", "1"]);
        assert_eq!(end_labels(1.3159e-14, 8.16), ["1.32e-14", "8.16"]);
        assert_eq!(end_labels(3.7752e-6, 0.5), ["3.78e-6", "0.5"]);
    }

    /// A constant attribute: one colour, the map's last, and the value in the title.
    #[test]
    fn a_constant_attribute_gets_one_colour_and_its_value() {
        let info = mdlod_format::meta::AttributeInfo {
            name: "c_pe".into(),
            min: -3.54,
            max: -3.54,
            log10: false,
        };
        let scale = AttributeScale::with_range(&info, None);
        let svg = colour_bar(
            ColourMap::Viridis,
            &scale,
            "c_pe",
            [-3.54, -3.54],
            [-3.54, -3.54],
        )
        .svg();
        let stops = stops_of(&svg);
        assert!(stops
            .iter()
            .all(|c| *c == hex(ColourMap::Viridis.colour(1.0))));
        assert!(svg.contains("c_pe: every value -3.54 (constant)"), "{svg}");
        assert_eq!(ticks_of(&svg).0.len(), 0);
    }

    /// Drawn into an image, the bar shows the colour map at each pixel's position along
    /// it, its ticks and labels in black, on a light panel in the corner asked for; the
    /// rest of the image is untouched, at any scale.
    #[test]
    fn a_legend_drawn_into_an_image_shows_the_bar_where_the_svg_does() {
        assert_eq!(CHAR_WIDTH, font::GLYPH_WIDTH as f32);
        let info = mdlod_format::meta::AttributeInfo {
            name: "c_ke".into(),
            min: 0.0,
            max: 2.5,
            log10: false,
        };
        let scale = AttributeScale::with_range(&info, None);
        let legend = colour_bar(ColourMap::Viridis, &scale, "c_ke", [0.0, 2.5], [0.0, 2.5]);
        for s in [1u32, 2] {
            let (w, h) = (400 * s, 100 * s);
            let mut image = RgbaImage::new(w, h);
            for p in image.data.chunks_mut(4) {
                p.copy_from_slice(&[10, 20, 30, 255]);
            }
            legend.draw(&mut image, Corner::BottomRight, s).unwrap();
            let (x0, y0) = (w - 8 * s - 360 * s, h - 8 * s - 66 * s);
            // Outside the panel: untouched; the panel's corner: lightened.
            assert_eq!(image.pixel(x0 - 1, y0 - 1), [10, 20, 30, 255]);
            assert!(image.pixel(x0 + 1, y0 + 1)[0] > 200);
            // Along the bar's middle row, the map's colour where the bar maps it.
            let row = y0 + 32 * s;
            for t in [0.1f32, 0.5, 0.9] {
                let x = x0 + ((BAR[0] + t * (BAR[1] - BAR[0])) * s as f32) as u32;
                let at = ((x - x0) as f32 + 0.5) / s as f32;
                let want = ColourMap::Viridis
                    .colour((at - BAR[0]) / (BAR[1] - BAR[0]))
                    .map(|v| (linear_to_srgb(v) * 255.0).round() as u8);
                let got = image.pixel(x, row);
                for k in 0..3 {
                    assert!(
                        got[k].abs_diff(want[k]) <= 6,
                        "s {s} t {t}: {got:?} {want:?}"
                    );
                }
            }
            // The tick at 1.0 is black just under the bar; labels are black text.
            let Legend::Bar { ticks, .. } = &legend else {
                unreachable!()
            };
            let (x, _) = ticks[2];
            let at = x0 + (x * s as f32) as u32;
            assert!(
                [at - 1, at]
                    .iter()
                    .any(|&x| image.pixel(x, y0 + 44 * s) == [0, 0, 0, 255]),
                "s {s}: no tick at {at}"
            );
            let dark = (y0 + 48 * s..y0 + 62 * s)
                .flat_map(|y| (x0..x0 + 360 * s).map(move |x| (x, y)))
                .filter(|&(x, y)| image.pixel(x, y) == [0, 0, 0, 255])
                .count();
            assert!(dark > 40 * (s * s) as usize, "s {s}: {dark} label pixels");
        }
        // Too small an image is refused with the size it needs.
        let mut small = RgbaImage::new(300, 200);
        let e = legend.draw(&mut small, Corner::TopLeft, 1).unwrap_err();
        assert!(e.contains("at least 376×82"), "{e}");
        // Whole steps per 1280 × 720, rounded to the nearest; less where the image is
        // narrow.
        for ((w, h), want) in [
            ((1280, 720), Some(1)),
            ((1600, 900), Some(1)),
            ((1920, 1080), Some(2)),
            ((2560, 1440), Some(2)),
            ((3840, 2160), Some(3)),
            ((600, 1200), Some(1)),
            ((376, 82), Some(1)),
            ((375, 82), None),
        ] {
            assert_eq!(legend.scale_for(w, h), want, "{w}×{h}");
        }
        // A long title widens the panel rather than being cut; the font's gaps are named.
        let long = "Temperature of the liquid droplets after 200 ps, per-atom mean (K)";
        let titled = colour_bar(ColourMap::Viridis, &scale, long, [0.0, 2.5], [0.0, 2.5]);
        assert!(titled.size().0 >= 2.0 * BAR[0] + 7.0 * long.chars().count() as f32);
        assert!(titled.missing_glyphs().is_empty());
        let odd = colour_bar(
            ColourMap::Viridis,
            &scale,
            "s⁻¹ cm⁻³ ± ö – 日本",
            [0.0, 2.5],
            [0.0, 2.5],
        );
        assert_eq!(odd.missing_glyphs(), vec!['日', '本']);
    }

    /// Text is the font's glyphs, each bit a square of `scale` pixels, on its baseline.
    #[test]
    fn a_key_draws_its_names_in_the_bitmap_font() {
        let key = species_key(&[("H".into(), [1.0, 0.0, 0.0])], None);
        let mut image = RgbaImage::new(300, 120);
        key.draw(&mut image, Corner::TopLeft, 2).unwrap();
        // A margin of 8 legend pixels; the name's baseline at y = 5 + 10 + 4 = 19, its
        // glyph's top 11 rows above it.
        let (left, top) = (16 + 28 * 2, 16 + (19 - 11) * 2);
        for (row, bits) in font::glyph('H').iter().enumerate() {
            for col in 0..font::GLYPH_WIDTH {
                let set = bits & (0x40 >> col) != 0;
                for (dx, dy) in [(0, 0), (1, 1)] {
                    let p = image.pixel(left + col * 2 + dx, top + row as u32 * 2 + dy);
                    assert_eq!(p == [0, 0, 0, 255], set, "row {row} col {col}: {p:?}");
                }
            }
        }
        // The disc: red at its centre, (14, 15) legend pixels from the panel's corner.
        assert_eq!(image.pixel(16 + 28, 16 + 30), [255, 0, 0, 255]);
        // Every printable character has its own glyph.
        for c in ' '..='~' {
            assert!(font::GLYPHS.iter().any(|(g, _)| *g == c), "{c:?}");
        }
        assert_eq!(font::glyph('\u{1F600}'), font::glyph('?'));
    }

    /// No unlabelled tick stands under an end's label (where it would read as the end's
    /// value, 2-5× off): a log bar of wide marked ends keeps only the ticks clear of them
    /// and those at the ends themselves.
    #[test]
    fn no_tick_hides_under_an_end_label() {
        let legend = light_bar(
            ColourMap::Viridis,
            "flux",
            [4.96e-10, 4.87e-5],
            true,
            [1e-12, 1e-2],
        );
        let Legend::Bar { ticks, ends, .. } = &legend else {
            panic!("a bar")
        };
        assert!(
            ends[0].starts_with('≤') && ends[1].starts_with('≥'),
            "{ends:?}"
        );
        let width = |t: &str| CHAR_WIDTH * t.chars().count() as f32;
        let (low, high) = (BAR[0] + width(&ends[0]), BAR[1] - width(&ends[1]));
        assert!(!ticks.is_empty());
        for (x, label) in ticks {
            let end = *x <= BAR[0] + 0.5 || *x >= BAR[1] - 0.5;
            assert!(
                end || (*x > low && *x < high),
                "tick at {x} ({label:?}) under {ends:?}"
            );
        }
    }

    /// A projection's bar marks an end `≥` (`≤`, on a log scale) where the image's lit
    /// pixels reach past it, and neither where they lie within (a linear map from 0
    /// cuts nothing below: unlit pixels show the background).
    #[test]
    fn a_light_bar_marks_the_ends_its_pixels_pass() {
        let text = |range, log, lit| {
            light_bar(ColourMap::Viridis, "flux", range, log, lit)
                .svg()
                .replace("&lt;", "<")
        };
        let cut = text([1e-3, 10.0], true, [1e-6, 40.0]);
        assert!(cut.contains("≥ 10") && cut.contains("≤ 0.001"), "{cut}");
        let within = text([1e-3, 10.0], true, [1e-3, 10.0]);
        assert!(!within.contains('≥') && !within.contains('≤'), "{within}");
        let linear = text([0.0, 10.0], false, [1e-6, 12.0]);
        assert!(linear.contains("≥ 10") && !linear.contains('≤'), "{linear}");
    }

    #[test]
    fn a_bar_writes_its_numbers_in_one_notation() {
        let labels = |lo: f32, hi: f32| {
            let svg = light_bar(ColourMap::Viridis, "x", [lo, hi], false, [lo, hi]).svg();
            let ends: Vec<String> = svg
                .lines()
                .filter(|l| {
                    l.contains(r#"text-anchor="start""#) || l.contains(r#"text-anchor="end""#)
                })
                .map(|l| {
                    l.split('>')
                        .nth(1)
                        .unwrap()
                        .trim_end_matches("</text")
                        .to_string()
                })
                .collect();
            (ticks_of(&svg).1, ends)
        };
        // Large values: every tick in scientific notation, and 0 written as 0.
        let (ticks, ends) = labels(0.0, 1e5);
        assert_eq!(ends, ["0", "1e5"]);
        assert!(
            ticks.iter().all(|t| t.contains('e') || t == "0"),
            "{ticks:?}"
        );
        let (_, ends) = labels(-1e6, 0.0);
        assert_eq!(ends, ["\u{2212}1e6", "0"]);
        // Ends take the ticks' decimals (a typographic minus in the SVG).
        let (ticks, ends) = labels(-3.5, -3.0);
        assert_eq!(ends, ["\u{2212}3.5", "\u{2212}3.0"]);
        assert!(
            ticks
                .iter()
                .all(|t| t.starts_with('\u{2212}') && t.contains('.')),
            "{ticks:?}"
        );
        // Padding never drops an end's own digits.
        let (_, ends) = labels(0.0348, 0.7177);
        assert_eq!(ends, ["0.0348", "0.7177"]);
        // Small values: fixed notation throughout (no 5e-4 beside 0.0010).
        let (ticks, ends) = labels(0.0, 0.002);
        assert!(ticks.iter().all(|t| !t.contains('e')), "{ticks:?}");
        assert_eq!(ends[0], "0");
        assert!(ticks.contains(&"0.0005".to_string()), "{ticks:?}");
        // A log bar over decades below 10⁻³: every tick scientific.
        let svg = density_bar(1e-4, 0.5, true, None).svg();
        let (_, ticks) = ticks_of(&svg);
        assert!(
            ticks.len() >= 3 && ticks.iter().all(|t| t.contains('e')),
            "{ticks:?}"
        );
    }

    #[test]
    fn labels_have_the_decimals_their_step_needs() {
        assert_eq!(tick_label(0.4, 0.2), "0.4");
        assert_eq!(tick_label(-2.0, 1.0), "-2");
        assert_eq!(tick_label(0.0001, 0.0001), "1e-4");
        assert_eq!(tick_label(250000.0, 50000.0), "2.5e5");
        assert_eq!(tick_label(1.0e-16, 0.2), "1e-16");
        assert_eq!(tick_label(0.0, 0.2), "0");
    }
}
