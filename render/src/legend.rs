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

use crate::renderer::linear_to_srgb;
use crate::style::{AttributeScale, ColourMap};

/// Width of a colour bar's SVG, px.
const WIDTH: f32 = 360.0;
/// The bar's left and right ends, px.
const BAR: [f32; 2] = [20.0, 340.0];
/// Samples of the gradient along the bar.
const GRADIENT_STOPS: usize = 33;

/// `#rrggbb` of a linear RGB colour.
fn hex(linear: [f32; 3]) -> String {
    let c = linear.map(|v| (linear_to_srgb(v.clamp(0.0, 1.0)) * 255.0).round() as u8);
    format!("#{:02x}{:02x}{:02x}", c[0], c[1], c[2])
}

/// Text safe inside an SVG element or attribute.
fn escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// A value as a tick label: as many decimals as the step between ticks needs, or
/// scientific notation for very large and very small magnitudes.
pub fn tick_label(v: f64, step: f64) -> String {
    if v == 0.0 {
        return "0".into();
    }
    let m = v.abs();
    if !(1e-3..1e5).contains(&m) {
        let text = format!("{v:.2e}");
        // 1.00e-3 → 1e-3, 2.50e4 → 2.5e4.
        return match text.split_once('e') {
            Some((mantissa, exp)) => {
                let mantissa = mantissa.trim_end_matches('0').trim_end_matches('.');
                format!("{mantissa}e{exp}")
            }
            None => text,
        };
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
    if !(1e-3..1e5).contains(&m) {
        return [lo, hi].map(|v| {
            let text = format!("{v:.2e}");
            match text.split_once('e') {
                Some((mantissa, exp)) => {
                    let mantissa = mantissa.trim_end_matches('0').trim_end_matches('.');
                    format!("{mantissa}e{exp}")
                }
                None => text,
            }
        });
    }
    let decimals = |v: f64| {
        if v == 0.0 {
            0
        } else {
            (2 - v.abs().log10().floor() as i32).clamp(0, 6) as usize
        }
    };
    let d = decimals(lo).max(decimals(hi));
    [lo, hi].map(|v| {
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
    let decades: Vec<f64> = (a..=b).map(|k| 10f64.powi(k)).collect();
    if decades.len() >= 2 {
        return decades;
    }
    let (a, b) = (lo.log10().floor() as i32, hi.log10().ceil() as i32);
    (a..=b)
        .flat_map(|k| [1.0, 2.0, 5.0].map(|m| m * 10f64.powi(k)))
        .filter(|&v| v >= lo * (1.0 - 1e-9) && v <= hi * (1.0 + 1e-9))
        .collect()
}

/// A horizontal colour bar: `title` above it, the gradient `colour(t)` for `t` in
/// [0, 1] along it, and ticks at `ticks` (value, label), each at `position(value)` in
/// [0, 1]; the ends labelled `ends` (with `≤`/`≥` where values beyond them take the
/// ends' colours).
fn bar_svg(
    title: &str,
    colour: &dyn Fn(f32) -> [f32; 3],
    position: &dyn Fn(f64) -> f32,
    ticks: &[(f64, String)],
    ends: [String; 2],
) -> String {
    let height = 66.0;
    let mut svg = String::new();
    let _ = writeln!(
        svg,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{WIDTH}" height="{height}" viewBox="0 0 {WIDTH} {height}" font-family="sans-serif" font-size="12">"#
    );
    let _ = writeln!(
        svg,
        r#"<defs><linearGradient id="bar" x1="0" x2="1" y1="0" y2="0">"#
    );
    for k in 0..GRADIENT_STOPS {
        let t = k as f32 / (GRADIENT_STOPS - 1) as f32;
        let _ = writeln!(
            svg,
            r#"<stop offset="{t:.4}" stop-color="{}"/>"#,
            hex(colour(t))
        );
    }
    let _ = writeln!(svg, "</linearGradient></defs>");
    let _ = writeln!(
        svg,
        r#"<text x="{}" y="14">{}</text>"#,
        BAR[0],
        escape(title)
    );
    let (y0, y1) = (22.0, 42.0);
    let _ = writeln!(
        svg,
        r##"<rect x="{}" y="{y0}" width="{}" height="{}" fill="url(#bar)" stroke="#000" stroke-width="0.5"/>"##,
        BAR[0],
        BAR[1] - BAR[0],
        y1 - y0
    );
    let x_of = |t: f32| BAR[0] + t.clamp(0.0, 1.0) * (BAR[1] - BAR[0]);
    // End labels, then the ticks' labels that leave room to them and to each other
    // (widths estimated at 7 px a character).
    let width_of = |text: &str| 7.0 * text.chars().count() as f32;
    let row = y1 + 17.0;
    let _ = writeln!(
        svg,
        r#"<text x="{}" y="{row}" text-anchor="start">{}</text>"#,
        BAR[0],
        escape(&ends[0])
    );
    let _ = writeln!(
        svg,
        r#"<text x="{}" y="{row}" text-anchor="end">{}</text>"#,
        BAR[1],
        escape(&ends[1])
    );
    let mut free_from = BAR[0] + width_of(&ends[0]) + 10.0;
    let free_to = BAR[1] - width_of(&ends[1]) - 10.0;
    for (v, label) in ticks {
        let x = x_of(position(*v));
        let _ = writeln!(
            svg,
            r##"<line class="tick" x1="{x:.2}" y1="{y1}" x2="{x:.2}" y2="{}" stroke="#000" stroke-width="1"/>"##,
            y1 + 5.0
        );
        let half = width_of(label) / 2.0;
        if x - half >= free_from && x + half <= free_to {
            let _ = writeln!(
                svg,
                r#"<text class="tick" x="{x:.2}" y="{row}" text-anchor="middle">{}</text>"#,
                escape(label)
            );
            free_from = x + half + 10.0;
        }
    }
    svg.push_str("</svg>\n");
    svg
}

/// The colour bar of `map` over an attribute named `name`, as `scale` (the renderer's,
/// with the shown range and log flag) maps it; `range` is the range shown.
pub fn colour_bar(map: ColourMap, scale: &AttributeScale, name: &str, range: [f32; 2]) -> String {
    let colour = |t: f32| map.colour(t);
    let position = |v: f64| scale.of_value(v as f32);
    // A constant attribute shown over no range: every particle takes the map's last
    // colour, and no scale places it.
    if range[0] >= range[1] {
        let top = map.colour(1.0);
        return bar_svg(
            &format!("{name}: every value {} (constant)", range[0]),
            &|_| top,
            &|_| 1.0,
            &[],
            [String::new(), String::new()],
        );
    }
    match scale.log_range() {
        Some([lo, hi]) => {
            let ticks: Vec<(f64, String)> = log_ticks(lo, hi)
                .into_iter()
                .map(|v| (v, tick_label(v, v)))
                .collect();
            // A range from 0 or below starts the scale decades below its top: values at
            // or below that take its colour.
            let [low, high] = end_labels(lo, hi);
            let low = match range[0] <= 0.0 {
                true => format!("≤ {low}"),
                false => low,
            };
            bar_svg(
                &format!("{name} (log scale)"),
                &colour,
                &position,
                &ticks,
                [low, high],
            )
        }
        None => {
            let [lo, hi] = range.map(f64::from);
            let (ticks, step) = linear_ticks(lo, hi, 5);
            let ticks: Vec<(f64, String)> = ticks
                .into_iter()
                .map(|v| (v, tick_label(v, step)))
                .collect();
            bar_svg(name, &colour, &position, &ticks, end_labels(lo, hi))
        }
    }
}

/// The bar of a projected image's colour map: `title` (what the light is) over
/// `[lo, hi]`, on a log scale when `log` (as `SplatFrame::colour_mapped` maps it).
pub fn light_bar(map: ColourMap, title: &str, [lo, hi]: [f32; 2], log: bool) -> String {
    let info = mdlod_format::meta::AttributeInfo {
        name: String::new(),
        min: lo,
        max: hi,
    };
    let scale = AttributeScale::new(&info).with_log(log && lo > 0.0);
    colour_bar(map, &scale, title, [lo, hi])
}

/// The density volume's transfer function: volume fraction φ from 0 to `density_max`.
pub fn density_bar(density_max: f32) -> String {
    let max = f64::from(density_max);
    let (ticks, step) = linear_ticks(0.0, max, 4);
    let ticks: Vec<(f64, String)> = ticks
        .into_iter()
        .map(|v| (v, tick_label(v, step)))
        .collect();
    bar_svg(
        "volume fraction φ",
        &|t| crate::density::transfer_colour(t).to_array(),
        &|v| (v / max) as f32,
        &ticks,
        ["0".into(), format!("≥ {}", end_labels(0.0, max)[1])],
    )
}

/// A key of the species shown: a disc of each one's colour (linear RGB) and its name,
/// under `title` when given.
pub fn species_key(entries: &[(String, [f32; 3])], title: Option<&str>) -> String {
    let row = 20.0;
    let top = if title.is_some() { row } else { 0.0 };
    let height = 10.0 + top + row * entries.len().max(1) as f32;
    let width = 40.0
        + entries
            .iter()
            .map(|(n, _)| n.chars().count() as f32 * 7.5)
            .chain(title.map(|t| t.chars().count() as f32 * 7.5 - 30.0))
            .fold(60.0, f32::max);
    let mut svg = String::new();
    let _ = writeln!(
        svg,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" viewBox="0 0 {width} {height}" font-family="sans-serif" font-size="12">"#
    );
    if let Some(t) = title {
        let _ = writeln!(svg, r#"<text x="7" y="16">{}</text>"#, escape(t));
    }
    for (k, (name, colour)) in entries.iter().enumerate() {
        let y = 5.0 + top + row * (k as f32 + 0.5);
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
    svg.push_str("</svg>\n");
    svg
}

#[cfg(test)]
mod tests {
    use super::*;

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
        };
        let scale = AttributeScale::with_range(&info, None);
        let svg = colour_bar(ColourMap::Viridis, &scale, "c_ke", [0.0, 2.5]);
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

        // Log: decades, the middle one at the middle of the bar.
        let info = mdlod_format::meta::AttributeInfo {
            name: "rho".into(),
            min: 1e-3,
            max: 10.0,
        };
        let scale = AttributeScale::with_range(&info, None).with_log(true);
        let svg = colour_bar(ColourMap::Magma, &scale, "rho", [1e-3, 10.0]);
        let (xs, labels) = ticks_of(&svg);
        assert_eq!(xs.len(), 5);
        assert!((xs[2] - (BAR[0] + BAR[1]) / 2.0).abs() < 0.01, "{xs:?}");
        assert_eq!(labels, ["0.01", "0.1", "1"]);
        assert!(svg.contains("rho (log scale)") && !svg.contains('≤'));
        // From 0: the scale starts four decades below its top, values below take its
        // colour.
        let from_zero = AttributeScale::with_range(&info, Some([0.0, 10.0])).with_log(true);
        let svg = colour_bar(ColourMap::Magma, &from_zero, "rho", [0.0, 10.0]);
        assert!(svg.contains(">≤ 0.001</text>"), "{svg}");
        // A name with markup is escaped.
        let svg = colour_bar(ColourMap::Grey, &scale, "a<b & c", [1e-3, 10.0]);
        assert!(svg.contains("a&lt;b &amp; c (log scale)"));
    }

    #[test]
    fn the_density_bar_and_species_key_show_the_colours_drawn() {
        let svg = density_bar(0.8);
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
        let key = species_key(
            &[
                ("Cu".into(), [1.0, 0.0, 0.0]),
                ("Ag".into(), [0.0, 0.0, 1.0]),
            ],
            None,
        );
        assert!(key.contains(r##"fill="#ff0000""##) && key.contains(">Ag</text>"));
        let titled = species_key(&[("Cu".into(), [1.0, 0.0, 0.0])], Some("Alloy & grain"));
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
        assert_eq!(end_labels(12345.0, 250000.0), ["1.23e4", "2.5e5"]);
    }

    /// A constant attribute: one colour, the map's last, and the value in the title.
    #[test]
    fn a_constant_attribute_gets_one_colour_and_its_value() {
        let info = mdlod_format::meta::AttributeInfo {
            name: "c_pe".into(),
            min: -3.54,
            max: -3.54,
        };
        let scale = AttributeScale::with_range(&info, None);
        let svg = colour_bar(ColourMap::Viridis, &scale, "c_pe", [-3.54, -3.54]);
        let stops = stops_of(&svg);
        assert!(stops
            .iter()
            .all(|c| *c == hex(ColourMap::Viridis.colour(1.0))));
        assert!(svg.contains("c_pe: every value -3.54 (constant)"), "{svg}");
        assert_eq!(ticks_of(&svg).0.len(), 0);
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
