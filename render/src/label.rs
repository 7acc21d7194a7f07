//! Text labels drawn into images (`--label "t = {time} ps"`): templates with
//! placeholders filled from each frame's values.
//!
//! How it works. A label is read as a format string is: `{name}` is a value the frame
//! gives (its timestep, time, position in a movie, particle count, file name, the dump
//! it was converted from), `{time:.N}` the time with `N` decimals, `{{` and `}}` a
//! literal brace (a plane family `{{111}}`). [`parts`] cuts a template into text and
//! placeholders and refuses unknown names and stray braces before anything is drawn;
//! [`Values::fill`] writes one frame's label, `?` where the frame lacks a value. A
//! movie's times share one number of decimals ([`time_decimals`]), so a label keeps its
//! width from frame to frame (`0.80`, `1.00`, `1.20`).

/// The values a label fills in, by placeholder name.
pub const FIELDS: &[&str] = &["timestep", "time", "frame", "particles", "file", "source"];

/// The most decimals `{time:.N}` takes.
pub const MAX_DECIMALS: usize = 12;

/// Why a label template cannot be used.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum LabelError {
    #[error("a `{{` opens no placeholder: write `{{{{` for a brace")]
    UnclosedBrace,
    #[error("a `}}` closes no placeholder: write `}}}}` for a brace")]
    StrayBrace,
    #[error(
        "{{{placeholder}}}: `:{spec}` is no number of decimals (write {{{name}:.2}} for two, \
         at most {MAX_DECIMALS})"
    )]
    Decimals {
        placeholder: String,
        spec: String,
        name: String,
    },
    #[error(
        "{{{placeholder}}}: only {{time}} takes a number of decimals ({{{name}}} is a whole \
         number)"
    )]
    DecimalsOfWholeNumber { placeholder: String, name: String },
    #[error(
        "{{{name}}} is no value a label fills in (it has {}; write {{{{{name}}}}} for the \
         braces themselves)",
        FIELDS.iter().map(|f| format!("{{{f}}}")).collect::<Vec<_>>().join(", ")
    )]
    UnknownField { name: String },
}

/// A piece of a label: text as written, or a value to fill in (with the decimals its
/// placeholder asks for: `{time:.2}`).
#[derive(Clone, Debug, PartialEq)]
pub enum Part {
    Text(String),
    Field(&'static str, Option<usize>),
}

/// One image's values for a label.
#[derive(Clone, Debug, Default)]
pub struct Values {
    pub timestep: Option<u64>,
    pub time: Option<f64>,
    /// The image's position in a movie (0 for a still).
    pub frame: usize,
    pub particles: u64,
    /// The `.mdlod` file's name.
    pub file: String,
    /// The name of the input the frame was converted from (the dump), where recorded.
    pub source: Option<String>,
}

/// The file name of a recorded source path (`runs/melt.lammpstrj` → `melt.lammpstrj`).
pub fn source_name(path: &str) -> String {
    std::path::Path::new(path)
        .file_name()
        .map_or_else(|| path.to_string(), |n| n.to_string_lossy().into_owned())
}

impl Values {
    /// The values of the file at `path`, whose metadata is `meta`, shown as image `frame`.
    pub fn of_file(
        path: &std::path::Path,
        meta: &mdlod_format::meta::Metadata,
        frame: usize,
    ) -> Values {
        Values {
            timestep: meta.timestep,
            time: meta.time,
            frame,
            particles: meta.particles,
            file: path
                .file_name()
                .map_or_else(String::new, |n| n.to_string_lossy().into_owned()),
            source: meta.source.as_ref().map(|s| source_name(&s.path)),
        }
    }

    /// `text` with its placeholders filled in; a value the frame lacks (a dump without a
    /// time) shows `?`, and its name is returned. A time takes its placeholder's
    /// decimals, else `time_decimals` (those of a movie's most precise time), else its
    /// shortest form. A template [`parts`] refuses fills in as its text alone.
    pub fn fill(&self, text: &str, time_decimals: Option<usize>) -> (String, Vec<&'static str>) {
        let mut out = String::new();
        let mut missing = Vec::new();
        for part in parts(text).unwrap_or_default() {
            match part {
                Part::Text(t) => out.push_str(&t),
                Part::Field(field, decimals) => {
                    let value = match field {
                        "timestep" => self.timestep.map(|t| t.to_string()),
                        "time" => self.time.map(|t| match decimals.or(time_decimals) {
                            Some(d) => format!("{t:.d$}"),
                            None => shortest(t as f32),
                        }),
                        "frame" => Some(self.frame.to_string()),
                        "particles" => Some(self.particles.to_string()),
                        "source" => self.source.clone(),
                        _ => Some(self.file.clone()),
                    };
                    if value.is_none() && !missing.contains(&field) {
                        missing.push(field);
                    }
                    out.push_str(value.as_deref().unwrap_or("?"));
                }
            }
        }
        (out, missing)
    }
}

/// A number in its shortest decimal form, or in scientific notation outside
/// 10⁻⁴..10⁷ (`1.2`, `3e-9`).
fn shortest(v: f32) -> String {
    if v == 0.0 || !v.is_finite() || (1e-4..1e7).contains(&v.abs()) {
        format!("{v}")
    } else {
        format!("{v:e}")
    }
}

/// A label cut into text and placeholders, as format strings are: `{name}` a value,
/// `{{` and `}}` a literal brace; an error names a placeholder no label fills, or a
/// brace left alone.
pub fn parts(text: &str) -> Result<Vec<Part>, LabelError> {
    let mut parts = Vec::new();
    let mut literal = String::new();
    let mut chars = text.char_indices().peekable();
    while let Some((i, c)) = chars.next() {
        match c {
            '{' if chars.peek().is_some_and(|&(_, d)| d == '{') => {
                chars.next();
                literal.push('{');
            }
            '}' if chars.peek().is_some_and(|&(_, d)| d == '}') => {
                chars.next();
                literal.push('}');
            }
            '{' => {
                let rest = &text[i + 1..];
                let Some(close) = rest.find('}') else {
                    return Err(LabelError::UnclosedBrace);
                };
                let placeholder = &rest[..close];
                // `{time:.2}`: the number of decimals.
                let (name, decimals) = match placeholder.split_once(':') {
                    Some((name, spec)) => {
                        let decimals = spec
                            .strip_prefix('.')
                            .and_then(|d| d.parse::<usize>().ok())
                            .filter(|&d| d <= MAX_DECIMALS)
                            .ok_or_else(|| LabelError::Decimals {
                                placeholder: placeholder.into(),
                                spec: spec.into(),
                                name: name.into(),
                            })?;
                        if name != "time" {
                            return Err(LabelError::DecimalsOfWholeNumber {
                                placeholder: placeholder.into(),
                                name: name.into(),
                            });
                        }
                        (name, Some(decimals))
                    }
                    None => (placeholder, None),
                };
                let Some(&field) = FIELDS.iter().find(|f| **f == name) else {
                    return Err(LabelError::UnknownField { name: name.into() });
                };
                if !literal.is_empty() {
                    parts.push(Part::Text(std::mem::take(&mut literal)));
                }
                parts.push(Part::Field(field, decimals));
                for _ in 0..placeholder.chars().count() + 1 {
                    chars.next();
                }
            }
            '}' => return Err(LabelError::StrayBrace),
            c => literal.push(c),
        }
    }
    if !literal.is_empty() {
        parts.push(Part::Text(literal));
    }
    Ok(parts)
}

/// A template's text without its placeholders: the narrowest its label can be.
pub fn fixed_text(text: &str) -> String {
    parts(text)
        .unwrap_or_default()
        .into_iter()
        .filter_map(|p| match p {
            Part::Text(t) => Some(t),
            Part::Field(..) => None,
        })
        .collect()
}

/// The decimals that show every one of a movie's `times` as its shortest decimal form
/// does, so that the label keeps one width (`0.80`, `1.00`, `1.20`, not `0.8`, `1`, `1.2`;
/// `0.00000` to `0.00015`); `None` where one needs more than [`MAX_DECIMALS`].
pub fn time_decimals(times: impl Iterator<Item = f64>) -> Option<usize> {
    let mut most = 0;
    for t in times {
        // The decimals of the shortest decimal form (`3e-5` is `0.00003`: five).
        let shortest = format!("{}", t as f32);
        most = most.max(shortest.split_once('.').map_or(0, |(_, d)| d.len()));
    }
    (most <= MAX_DECIMALS).then_some(most)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Labels read as format strings: placeholders filled once each where they stand,
    /// doubled braces literal (a plane family, `{{111}}`), a value the frame lacks `?`
    /// and named once, stray braces and unknown names refused.
    #[test]
    fn labels_fill_placeholders_and_keep_doubled_braces() {
        let v = Values {
            timestep: Some(500),
            time: None,
            frame: 3,
            particles: 2552,
            file: "gb.mdlod".into(),
            source: Some("gb.dump".into()),
        };
        let fill = |t: &str| v.fill(t, None);
        assert_eq!(
            fill("step {timestep}, {particles} atoms"),
            ("step 500, 2552 atoms".into(), vec![])
        );
        assert_eq!(
            fill("Σ5 {{310}} boundaries, frame {frame}"),
            ("Σ5 {310} boundaries, frame 3".into(), vec![])
        );
        assert_eq!(
            fill("{{{timestep}}} {{timestep}}"),
            ("{500} {timestep}".into(), vec![])
        );
        assert_eq!(fill("t={time} ({time})"), ("t=? (?)".into(), vec!["time"]));
        assert_eq!(fill("{file} of {source}").0, "gb.mdlod of gb.dump");
        assert_eq!(fixed_text("t = {time:.2} ps, {{hkl}}"), "t =  ps, {hkl}");
        // A time in its shortest form, to a movie's decimals, or to its placeholder's.
        let timed = Values {
            time: Some(1.2),
            ..v.clone()
        };
        assert_eq!(timed.fill("t = {time} ps", None).0, "t = 1.2 ps");
        assert_eq!(timed.fill("t = {time} ps", Some(2)).0, "t = 1.20 ps");
        assert_eq!(timed.fill("t = {time:.3} ps", Some(1)).0, "t = 1.200 ps");
        assert_eq!(timed.fill("{time:.0}", None).0, "1");
        let tiny = Values {
            time: Some(3e-9),
            ..v.clone()
        };
        assert_eq!(tiny.fill("{time}", None).0, "3e-9");
        // A movie's times take the decimals of the most precise: 0.80, 1.00, 1.20.
        assert_eq!(time_decimals([0.8, 1.0, 1.2].into_iter()), Some(1));
        assert_eq!(time_decimals([0.25, 1.0].into_iter()), Some(2));
        assert_eq!(time_decimals([100.0, 200.0].into_iter()), Some(0));
        assert_eq!(time_decimals([1e-9, 2e-9].into_iter()), Some(9));
        assert_eq!(time_decimals([1e-15, 2e-15].into_iter()), None);
        assert_eq!(time_decimals([0.0, 3e-5, 1.5e-4].into_iter()), Some(5));
        for (bad, why) in [
            ("{time:2}", "`:2` is no number of decimals"),
            ("{time:.x}", "`:.x` is no number of decimals"),
            ("{time:.13}", "at most 12"),
            ("{timestep:.2}", "only {time} takes a number of decimals"),
            ("{111} planes", "{111} is no value a label fills in"),
            ("{111} planes", "write {{111}} for the braces themselves"),
            ("{111} planes", "it has {timestep}, {time}, {frame}"),
            (
                "open { brace",
                "a `{` opens no placeholder: write `{{` for a brace",
            ),
            (
                "close } brace",
                "a `}` closes no placeholder: write `}}` for a brace",
            ),
            ("{timestep", "a `{` opens no placeholder"),
        ] {
            let e = parts(bad).unwrap_err().to_string();
            assert!(e.contains(why), "{bad}: {e}");
        }
    }
}
