//! XYZ and extended XYZ files.
//!
//! How it works:
//! - **Index.** A frame is an atom-count line, a comment line and that many atom lines. The
//!   index walks the file once: it parses each count, reads the comment line (for the
//!   timestep), and skips the atom lines with a vectorised newline count
//!   ([`super::skip_lines`]), never looking inside them. Blank lines between frames and at
//!   the end are allowed.
//! - **Comment line.** Parsed as extended-XYZ `key=value` pairs (values may be quoted with
//!   `"..."` or `{...}`; keys are matched case-insensitively):
//!   `Lattice="ax ay az bx by bz cx cy cz"` gives the cell vectors, `Origin="x y z"`
//!   (OVITO) its origin, `pbc="T T F"` its periodicity (default `T T T` when a lattice is
//!   given, as the extended-XYZ convention says), `Time=` the time, and `Timestep=` or
//!   `step=` (or the `Timestep: N` that LAMMPS `dump xyz` writes, and its `Time: T`
//!   with `dump_modify time yes`) the timestep, `units=`
//!   the length unit (`units=um`, a LAMMPS style such as `metal`, kept as written). Spaces
//!   around `=` and a comma ending a number are allowed, as CP2K writes them
//!   (`i = 0, time = 0.000, E = -17.16`), and a unit written after a time's number
//!   (`Time=1.5fs`) is left out. A timestep that is no whole number (`1e2` is one) is
//!   none, with a note; so is a time that is no number without `Properties`, where the
//!   line is free text; with it, a `Time` that is no number is an error. Keys inside a
//!   quoted value (`info="restarted from step=5"`) are that value's text.
//!   `Properties=name:type:count:...` names the columns in order; types `S`, `R`, `I`, `L`.
//!   Without `Properties` the columns are `species:S:1:pos:R:3` followed by whatever extra
//!   columns the first atom line has, named `col5`, `col6`, ... (1-based position).
//! - **Columns.** Positions come from the `pos` property (Cartesian), species from
//!   `species` (or atomic numbers `Z`) ordered as the LAMMPS text reader orders its
//!   species, so that the same data gives the same species table in either format: when
//!   every name is an integer (type numbers, atomic numbers) numerically, flagged
//!   `numeric_type`, and a species column's numbers (not atomic numbers `Z`) from 1 up
//!   take the palette slots of the same LAMMPS types; else (element symbols, labels) in
//!   order of first appearance. A property with count 1 is one column named after it; a
//!   property with count `n > 1` is `n` columns named `name[0]` ... `name[n-1]`. Any
//!   numeric column can be the attribute.
//! - **Atoms.** The atom lines go to the shared parallel parser.

use super::atoms::AtomLayout;
use super::{
    fields, parse_int, shorten, skip_lines_left, trim, Ctx, Cursor, FrameInfo, Header, ReadError,
};
use crate::frame::SimulationBox;

/// The longest comment line read as a frame's header.
const MAX_COMMENT: usize = 1 << 20;

/// Where the atom lines (from `from`) of a frame that the file ends before it is whole
/// hold a whole line of one integer: no atom line is that (an atom has a species and
/// three coordinates), a frame's count line is. `None` for a frame cut short while it was
/// written.
///
/// A large file (`file` given, longer than `segment`) is read through a fresh mapping
/// of each `segment` bytes, as the index skips lines, so that its pages do not stay
/// resident.
fn overcounted(
    ctx: &Ctx<'_>,
    file: Option<&std::fs::File>,
    from: usize,
    segment: usize,
) -> Result<Option<usize>, ReadError> {
    let len = ctx.data.len();
    let mut pos = from;
    while pos < len {
        let fresh;
        let (data, end) = match file {
            Some(f) if len > segment => {
                fresh = super::mapped_again(ctx, f, pos)?;
                (&fresh[..], (pos + segment.max(1)).min(len))
            }
            _ => (ctx.data, len),
        };
        let mut cursor = Cursor::new(data, pos);
        while cursor.pos < end {
            let Some((at, line)) = cursor.next_line() else {
                return Ok(None);
            };
            // The last line may be cut inside an atom's species ("1" of "1 0.5 ..."); a
            // whole line ends with its newline.
            let whole = at + line.len() < len;
            if whole && parse_int::<u64>(line).is_some() {
                return Ok(Some(at));
            }
        }
        pos = cursor.pos;
    }
    Ok(None)
}

/// Byte range and timestep of one frame.
#[derive(Debug, PartialEq)]
struct Span {
    start: usize,
    end: usize,
    timestep: Option<u64>,
    /// A timestep key whose value is no whole number (`Timestep=x`), as written: the
    /// frame is numbered by its position, which a note says.
    unread_timestep: Option<String>,
}

/// The frames of an XYZ file.
#[derive(Debug, PartialEq)]
pub(crate) struct Index {
    frames: Vec<Span>,
}

impl Index {
    /// Indexes `ctx.data`. `file`, when given, is the file `ctx.data` maps: atom lines are
    /// then skipped through fresh mappings of it, `segment` bytes at a time, so that the
    /// pages read do not stay resident.
    pub fn build(
        ctx: &Ctx<'_>,
        file: Option<&std::fs::File>,
        segment: usize,
        reached: &super::Reached<'_>,
    ) -> Result<Index, ReadError> {
        let data = ctx.data;
        let mut frames = Vec::new();
        let mut cursor = Cursor::new(data, 0);
        // The last frame's atom count and where it stands, for a frame that holds fewer
        // atom lines than it announces.
        let mut announced: Option<(usize, usize)> = None;
        while let Some((at, line)) =
            std::iter::from_fn(|| cursor.next_line()).find(|(_, l)| !trim(l).is_empty())
        {
            let n: usize = parse_int(line).ok_or_else(|| {
                let digits = {
                    let t = trim(line);
                    !t.is_empty() && t.iter().all(u8::is_ascii_digit)
                };
                ctx.malformed(
                    at,
                    if digits {
                        format!(
                            "the atom count of frame {}, `{}`, is too large to be one",
                            frames.len(),
                            shorten(line)
                        )
                    } else {
                        // A frame's comment line where a count should be: the frame before
                        // holds fewer atom lines than it announces, and the line above this
                        // one, taken for its last atom, is this frame's count.
                        // (Any `key=value` line: `step=2` as much as `Properties=`.)
                        let comment = line.contains(&b'=');
                        let short = match announced {
                            Some((count_at, n)) if comment => format!(
                                "; this reads as a frame's comment line: frame {} (its count at \
                                 line {}) may hold fewer than the {n} atom lines it announces",
                                frames.len() - 1,
                                ctx.at(count_at).line
                            ),
                            _ => String::new(),
                        };
                        format!(
                            "expected the atom count of frame {} (an integer), found `{}`{short}",
                            frames.len(),
                            shorten(line)
                        )
                    },
                )
            })?;
            announced = Some((at, n));
            let (timestep, unread_timestep) = match cursor.next_line() {
                Some((_, c)) => comment_timestep(c),
                None => (None, None),
            };
            let (end, left) = match file {
                Some(file) if data.len() > segment => {
                    super::skip_lines_mapped(ctx, file, cursor.pos, n, segment, reached)?
                }
                _ => skip_lines_left(data, cursor.pos, n),
            };
            // A last line without its newline is one of the frame's lines.
            let unterminated = usize::from(end > cursor.pos && !data.ends_with(b"\n"));
            if left > unterminated {
                if let Some(lone) = overcounted(ctx, file, cursor.pos, segment)? {
                    return Err(ctx.malformed(
                        lone,
                        format!(
                            "a line holding one integer among the atom lines of frame {}, whose \
                             count (line {}) announces {n} atoms that the file does not hold: \
                             this looks like a later frame's count line, so frame {}'s count \
                             is too large (the frames after it would be read as its atoms)",
                            frames.len(),
                            ctx.at(at).line,
                            frames.len()
                        ),
                    ));
                }
            }
            cursor.pos = end;
            reached.at(end);
            frames.push(Span {
                start: at,
                end,
                timestep,
                unread_timestep,
            });
        }
        if frames.is_empty() {
            return Err(ctx.malformed(0, "no XYZ frame found"));
        }
        Ok(Index { frames })
    }

    /// The index as a cache keeps it ([`super::index_cache`]).
    pub fn to_cached(&self) -> super::index_cache::CachedFrames {
        super::index_cache::CachedFrames {
            unread_timesteps: self
                .frames
                .iter()
                .enumerate()
                .filter_map(|(k, s)| s.unread_timestep.clone().map(|t| (k, t)))
                .collect(),
            ..super::index_cache::CachedFrames::of(
                "xyz",
                self.frames.iter().map(|s| (s.start, s.end, s.timestep)),
            )
        }
    }

    /// The index a cache kept for the file `data`, when it fits: frames in order inside
    /// the file, each starting with a line holding one whole number (its atom count).
    pub fn from_cached(data: &[u8], cached: &super::index_cache::CachedFrames) -> Option<Index> {
        if cached.format != "xyz" || cached.units.is_some() {
            return None;
        }
        let ranges = cached.checked_ranges(data)?;
        let mut frames = Vec::with_capacity(ranges.len());
        let unread_of: std::collections::HashMap<usize, &String> = cached
            .unread_timesteps
            .iter()
            .map(|(k, t)| (*k, t))
            .collect();
        let mut gap_from = 0;
        for (k, (r, &timestep)) in ranges.iter().zip(&cached.timesteps).enumerate() {
            // Only blank lines between frames, as a scan passes over; each frame ends a
            // line (or the file).
            if !data[gap_from..r.start].iter().all(u8::is_ascii_whitespace)
                || (r.end < data.len() && data[r.end - 1] != b'\n')
            {
                return None;
            }
            gap_from = r.end;
            // Its count line, and its comment line's timestep as kept.
            let mut cursor = Cursor::new(&data[..r.end], r.start);
            let (_, line) = cursor.next_line()?;
            parse_int::<usize>(line)?;
            let (own, unread) = match cursor.next_line() {
                Some((_, c)) => comment_timestep(c),
                None => (None, None),
            };
            if own != timestep || unread.as_ref() != unread_of.get(&k).copied() {
                return None;
            }
            frames.push(Span {
                start: r.start,
                end: r.end,
                timestep,
                unread_timestep: unread,
            });
        }
        if !data[gap_from..].iter().all(u8::is_ascii_whitespace) {
            return None;
        }
        Some(Index { frames })
    }

    pub fn len(&self) -> usize {
        self.frames.len()
    }

    pub fn timestep(&self, k: usize) -> Option<u64> {
        self.frames.get(k)?.timestep
    }

    /// Frame `k`'s timestep key whose value is no whole number, as written.
    pub fn unread_timestep(&self, k: usize) -> Option<&str> {
        self.frames.get(k)?.unread_timestep.as_deref()
    }

    /// The byte range of frame `k`, up to the next frame's first byte (the last frame's:
    /// up to the end of the file).
    pub fn bytes(&self, k: usize) -> Option<std::ops::Range<usize>> {
        self.frames.get(k).map(|s| s.start..s.end)
    }

    /// Parses the count and comment lines of frame `k` (which must exist).
    pub fn header(&self, ctx: &Ctx<'_>, k: usize) -> Result<Header, ReadError> {
        let span = &self.frames[k];
        let data = &ctx.data[..span.end];
        let mut cursor = Cursor::new(data, span.start);
        let (count_at, count) = cursor.next_line().unwrap_or((span.start, &[]));
        let particles: usize =
            parse_int(count).ok_or_else(|| ctx.malformed(count_at, "malformed atom count line"))?;
        let (comment_at, comment) = match cursor.next_line() {
            Some(c) => c,
            None if particles == 0 => (span.end, &[][..]),
            None => {
                return Err(ReadError::Truncated {
                    at: ctx.at(span.end),
                    expected: particles,
                    found: 0,
                })
            }
        };
        let atoms_at = cursor.pos;
        // An extended-XYZ header holds a few keys; a comment line of megabytes is no
        // header (its words would each become a string: a gzip file of 260 kB with a
        // comment of 256 MiB took 1.6 GB to read).
        if comment.len() > MAX_COMMENT {
            return Err(ctx.malformed(
                comment_at,
                format!(
                    "a comment line of {} bytes (at most {} MiB: longer is no XYZ header)",
                    comment.len(),
                    MAX_COMMENT >> 20
                ),
            ));
        }
        let comment_text = String::from_utf8_lossy(comment);
        let marked = marked_key_values(&comment_text);
        let get = |key: &str| {
            marked
                .iter()
                .find(|(k, _, _)| k.eq_ignore_ascii_case(key))
                .map(|(_, v, _)| v.as_str())
        };
        let bad = |message: String| ctx.malformed(comment_at, message);
        // A key read here given twice (`Lattice=` twice): which one the writer meant
        // cannot be told (ASE keeps the last, a first-match reader the first), so neither
        // is taken.
        // (Counted where given with `=`: a plain XYZ comment's free words, which the
        // pairs hold as flags, may repeat; keys inside a quoted value, `info="restarted
        // from step=5"`, are its text.)
        // (`Timestep=` and `step=` both give the timestep: one of them, once.)
        let given_times = |key: &str| {
            marked
                .iter()
                .filter(|(k, _, with_value)| *with_value && k.eq_ignore_ascii_case(key))
                .count()
        };
        for keys in [
            &["Lattice"][..],
            &["Origin"],
            &["pbc"],
            &["Properties"],
            &["Time"],
            &["Timestep", "step"],
        ] {
            let n: usize = keys.iter().map(|k| given_times(k)).sum();
            if n > 1 {
                return Err(bad(format!(
                    "`{}` is given {n} times in the comment line: which one holds the frame's \
                     value cannot be told",
                    keys.join("`/`")
                )));
            }
        }

        // A bare word (`no lattice`, a free-text comment of plain XYZ) is a flag, `T`;
        // a cell needs its numbers given, `Lattice="..."`.
        let given = |key: &str| {
            marked
                .iter()
                .find(|(k, _, _)| k.eq_ignore_ascii_case(key))
                .filter(|(_, _, with_value)| *with_value)
                .map(|(_, v, _)| v.as_str())
        };
        let numbers = |key: &str, n: usize| -> Result<Option<Vec<f64>>, ReadError> {
            let Some(v) = given(key) else { return Ok(None) };
            let values: Option<Vec<f64>> = v
                .split_whitespace()
                .map(|t| t.parse::<f64>().ok().filter(|x| x.is_finite()))
                .collect();
            match values {
                Some(values) if values.len() == n => Ok(Some(values)),
                _ => Err(bad(format!(
                    "`{key}` must be {n} numbers, found `{}`",
                    shorten(v.as_bytes())
                ))),
            }
        };
        let simulation_box = match numbers("Lattice", 9)? {
            None => None,
            Some(l) => {
                let origin = numbers("Origin", 3)?.unwrap_or(vec![0.0; 3]);
                let periodic = match get("pbc") {
                    None => [true; 3],
                    Some(v) => {
                        let flags: Option<Vec<bool>> = v.split_whitespace().map(logical).collect();
                        match flags {
                            Some(f) if f.len() == 3 => [f[0], f[1], f[2]],
                            _ => {
                                return Err(bad(format!(
                                    "`pbc` must be 3 logicals, found `{}`",
                                    shorten(v.as_bytes())
                                )))
                            }
                        }
                    }
                };
                Some(SimulationBox {
                    origin: [origin[0], origin[1], origin[2]],
                    a: [l[0], l[1], l[2]],
                    b: [l[3], l[4], l[5]],
                    c: [l[6], l[7], l[8]],
                    periodic: Some(periodic),
                })
            }
        };
        let properties = get("Properties");
        let time = match marked
            .iter()
            .find(|(k, _, _)| k.eq_ignore_ascii_case("Time"))
        {
            None => None,
            Some((key, v, _)) => match time_value(comment_value(v)) {
                Ok(t) if t.is_finite() => Some(t),
                // Without `Properties` the comment line is free text (`MD step 5
                // time=later`): a `time` in it that is no number is no time, and must not
                // stop a conversion. Extended XYZ promises `key=value` pairs.
                _ if properties.is_none() => None,
                _ => {
                    return Err(bad(format!(
                        "`{key}` is not a number: `{}`",
                        shorten(v.as_bytes())
                    )))
                }
            },
        };

        // LAMMPS `dump xyz` with `time yes`: ` Atoms. Timestep: 100 Time: 0.25`.
        let time = time.or_else(|| {
            let mut words = comment_text.split_whitespace();
            words.find(|w| w.eq_ignore_ascii_case("time:"))?;
            time_value(words.next()?).ok().filter(|t| t.is_finite())
        });
        let layout = match properties {
            Some(p) => properties_layout(p).map_err(bad)?,
            None => {
                // Plain XYZ: species x y z, plus any extra columns of the first atom line.
                let mut columns: Vec<String> =
                    ["species", "x", "y", "z"].map(String::from).to_vec();
                if particles > 0 {
                    let Some((_, first)) = Cursor::new(data, atoms_at).next_line() else {
                        // The file ends after the comment line (a run still writing).
                        return Err(ReadError::Truncated {
                            at: ctx.at(span.end),
                            expected: particles,
                            found: 0,
                        });
                    };
                    let n = fields(first).count();
                    if n < 4 {
                        return Err(ReadError::ColumnCount {
                            at: ctx.at(atoms_at),
                            expected: 4,
                            found: n,
                        });
                    }
                    columns.extend((5..=n).map(|i| format!("col{i}")));
                }
                AtomLayout {
                    columns,
                    coords: Some(([1, 2, 3], false)),
                    species: Some(0),
                    // Numbers sorted as LAMMPS types are, and coloured as they are (type
                    // `n` the palette's `n`-th colour; numbers from 0 by place).
                    numeric_species: true,
                    type_numbers: true,
                    element_sizes: None,
                    categories: false,
                }
            }
        };
        Ok(Header {
            info: FrameInfo {
                particles,
                timestep: span.timestep,
                time,
                // A `units=` key (`units=um`): what the positions are in.
                units: get("units")
                    .map(comment_value)
                    .filter(|u| !u.is_empty())
                    .map(str::to_string),
                simulation_box,
                columns: layout.columns.clone(),
            },
            layout,
            columns_at: comment_at,
            atoms: atoms_at..span.end,
        })
    }
}

/// An extended-XYZ logical: `T`, `True`, `1` or `F`, `False`, `0` (any case).
fn logical(s: &str) -> Option<bool> {
    match s.to_ascii_lowercase().as_str() {
        "t" | "true" | "1" => Some(true),
        "f" | "false" | "0" => Some(false),
        _ => None,
    }
}

/// Most columns a `Properties` key may describe: its counts multiply out to columns, so a
/// few bytes could otherwise ask for millions of them.
const MAX_COLUMNS: usize = 4096;

/// The column layout described by a `Properties=` value.
fn properties_layout(value: &str) -> Result<AtomLayout, String> {
    let parts: Vec<&str> = value.split(':').collect();
    if parts.is_empty() || !parts.chunks_exact(3).remainder().is_empty() {
        return Err(format!(
            "malformed `Properties` `{}`: expected name:type:count triples",
            shorten(value.as_bytes())
        ));
    }
    let mut columns = Vec::new();
    let mut coords = None;
    let mut species = None;
    let mut atomic_number = None;
    for triple in parts.chunks(3) {
        let (name, kind, count) = (triple[0], triple[1], triple[2]);
        let count: usize = count.parse().ok().filter(|&c| c > 0).ok_or_else(|| {
            format!("malformed `Properties`: `{count}` is not a count for `{name}`")
        })?;
        if !matches!(kind, "S" | "R" | "I" | "L") {
            return Err(format!(
                "malformed `Properties`: unknown type `{kind}` for `{name}` (expected S, R, I or L)"
            ));
        }
        let first = columns.len();
        if count > MAX_COLUMNS - first {
            return Err(format!(
                "`Properties` describes more than {MAX_COLUMNS} columns (`{name}` alone has {count})"
            ));
        }
        if count == 1 {
            columns.push(name.to_string());
        } else {
            columns.extend((0..count).map(|i| format!("{name}[{i}]")));
        }
        let numeric = matches!(kind, "R" | "I");
        // A size property is read as each particle's radius: one number.
        if ["radius", "diameter"]
            .iter()
            .any(|p| name.eq_ignore_ascii_case(p))
            && !(count == 1 && numeric)
        {
            return Err(format!(
                "`Properties` entry `{name}:{kind}:{count}` is no particle size: a radius or \
                 diameter is one number per particle (`{name}:R:1`)"
            ));
        }
        if ["pos", "position", "positions"]
            .iter()
            .any(|p| name.eq_ignore_ascii_case(p))
            && count == 3
            && numeric
            && coords.is_none()
        {
            coords = Some(([first, first + 1, first + 2], false));
        } else if name.eq_ignore_ascii_case("species") && count == 1 && species.is_none() {
            species = Some(first);
        } else if name == "Z" && count == 1 && kind == "I" {
            atomic_number = Some(first);
        }
    }
    if coords.is_none() {
        // A position entry of another shape (a 2D run's `pos:R:2`) is named as such.
        let near = parts.chunks(3).find(|t| {
            ["pos", "position", "positions"]
                .iter()
                .any(|p| t[0].eq_ignore_ascii_case(p))
        });
        if let Some(t) = near {
            return Err(format!(
                "`Properties` entry `{}:{}:{}` is no position: positions are three real \
                 numbers (`{}:R:3`; a two-dimensional run writes z as 0)",
                t[0], t[1], t[2], t[0]
            ));
        }
        return Err(format!(
            "`Properties` names no positions: they are read from a `pos:R:3` (or \
             `position:R:3`, `positions:R:3`) entry; the entries name the columns {}",
            columns.join(" ")
        ));
    }
    Ok(AtomLayout {
        columns,
        coords,
        // Numbers sorted as LAMMPS types are; a `species` column's coloured as they are
        // too, atomic numbers `Z` by place (H = 1 and Na = 11 would share a colour).
        type_numbers: species.is_some(),
        species: species.or(atomic_number),
        numeric_species: true,
        element_sizes: None,
        categories: false,
    })
}

/// The timestep recorded in a comment line: `Timestep=N` or `step=N` (any case), or the
/// `Timestep: N` LAMMPS `dump xyz` writes; a whole number written as a float (`1e2`,
/// `7.0`) counts. Else the value of such a key that is no whole number (`x`, `-5`,
/// `2.5`), as written.
fn comment_timestep(comment: &[u8]) -> (Option<u64>, Option<String>) {
    // (A comment line too long to be a header is refused where the frame is read.)
    if comment.len() > MAX_COMMENT {
        return (None, None);
    }
    let text = String::from_utf8_lossy(comment);
    let mut unread = None;
    if text.contains('=') {
        for (k, v) in key_values(&text) {
            if k.eq_ignore_ascii_case("timestep") || k.eq_ignore_ascii_case("step") {
                match whole_number(comment_value(&v)) {
                    Some(t) => return (Some(t), None),
                    None => unread = unread.or_else(|| Some(format!("{k}={v}"))),
                }
            }
        }
    }
    let mut words = text.split_whitespace();
    while let Some(w) = words.next() {
        if w.eq_ignore_ascii_case("timestep:") {
            let v = words.next().unwrap_or_default();
            return match whole_number(v) {
                Some(t) => (Some(t), None),
                None => (None, Some(format!("{w} {v}"))),
            };
        }
    }
    (None, unread)
}

/// A timestep: a whole number from 0, also written as a float (`1e2`, `7.0`).
fn whole_number(v: &str) -> Option<u64> {
    v.parse()
        .ok()
        .or_else(|| u64::try_from(crate::species::whole_number(v)?).ok())
}

/// A comment-line value as a number is written: trimmed, less the comma that ends it in
/// CP2K's `i = 0, time = 0.000, E = -17.16`.
/// A `Time` value: a number, also with a unit written after it (`0.25fs`, `1.5 ps`),
/// which is left out.
fn time_value(v: &str) -> Result<f64, std::num::ParseFloatError> {
    let unit_at = v
        .char_indices()
        .rev()
        .take_while(|(_, c)| c.is_ascii_alphabetic())
        .last()
        .map(|(i, _)| i);
    match unit_at {
        // (Not `1e5` nor `inf`: a unit follows a number that parses alone.)
        Some(i) if i > 0 && v[..i].trim_end().parse::<f64>().is_ok() => v[..i].trim_end().parse(),
        _ => v.parse(),
    }
}

fn comment_value(v: &str) -> &str {
    let v = v.trim();
    v.strip_suffix(',').unwrap_or(v)
}

/// Splits an extended-XYZ comment line into `key=value` pairs. A bare `key` gets value
/// `T`. Values (and keys) may be quoted with `"..."` (backslash escapes the next character)
/// or `{...}`; an unterminated quote runs to the end of the line.
pub(crate) fn key_values(line: &str) -> Vec<(String, String)> {
    marked_key_values(line)
        .into_iter()
        .map(|(k, v, _)| (k, v))
        .collect()
}

/// [`key_values`], each pair marked whether its key was given a value (`key=value`, not
/// a bare `key`).
fn marked_key_values(line: &str) -> Vec<(String, String, bool)> {
    let chars: Vec<char> = line.chars().collect();
    let mut i = 0;
    let mut out = Vec::new();
    let token = |i: &mut usize, stop_at_eq: bool| -> String {
        let mut s = String::new();
        match chars.get(*i) {
            Some('"') => {
                *i += 1;
                while let Some(&c) = chars.get(*i) {
                    *i += 1;
                    match c {
                        '"' => break,
                        '\\' => {
                            if let Some(&n) = chars.get(*i) {
                                s.push(n);
                                *i += 1;
                            }
                        }
                        _ => s.push(c),
                    }
                }
            }
            Some('{') => {
                *i += 1;
                while let Some(&c) = chars.get(*i) {
                    *i += 1;
                    if c == '}' {
                        break;
                    }
                    s.push(c);
                }
            }
            _ => {
                while let Some(&c) = chars.get(*i) {
                    if c.is_whitespace() || (stop_at_eq && c == '=') {
                        break;
                    }
                    s.push(c);
                    *i += 1;
                }
            }
        }
        s
    };
    loop {
        while chars.get(i).is_some_and(|c| c.is_whitespace()) {
            i += 1;
        }
        if i >= chars.len() {
            break;
        }
        let key = token(&mut i, true);
        let mut j = i;
        while chars.get(j).is_some_and(|c| c.is_whitespace()) {
            j += 1;
        }
        let with_value = chars.get(j) == Some(&'=');
        let value = if with_value {
            i = j + 1;
            while chars.get(i).is_some_and(|c| c.is_whitespace()) {
                i += 1;
            }
            token(&mut i, false)
        } else {
            "T".to_string()
        };
        out.push((key, value, with_value));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Timesteps in a comment line: whole numbers, also written as floats; a key whose
    /// value is none is kept as written, for the note that numbers the frame by position.
    #[test]
    fn timesteps_are_whole_numbers_and_others_are_kept_for_a_note() {
        let t = |c: &str| comment_timestep(c.as_bytes());
        assert_eq!(t("Properties=pos:R:3 Timestep=100"), (Some(100), None));
        assert_eq!(t("Properties=pos:R:3 Timestep=1e2"), (Some(100), None));
        assert_eq!(t("step = 7.0, E = -1"), (Some(7), None));
        assert_eq!(t("Timestep: 12"), (Some(12), None));
        assert_eq!(
            t("Properties=pos:R:3 Timestep=x"),
            (None, Some("Timestep=x".into()))
        );
        assert_eq!(t("Timestep=-5"), (None, Some("Timestep=-5".into())));
        assert_eq!(t("Timestep=2.5"), (None, Some("Timestep=2.5".into())));
        assert_eq!(t("Timestep: soon"), (None, Some("Timestep: soon".into())));
        assert_eq!(t("no timestep here"), (None, None));
    }

    #[test]
    fn an_index_skipping_lines_in_segments_equals_one_built_whole() {
        // Frames of 3, 0 and 2 atoms, then one announcing more lines than are left.
        let text = "3\nTimestep=0\nCu 0 0 0\nCu 1 0 0\nCu 0 1 0\n0\nempty\n\
                    2\nstep 5\nAg 0 0 1\nAg 1 1 1\n4\nlast\nCu 2 2 2\n";
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("d.xyz");
        std::fs::write(&path, text).unwrap();
        let ctx = Ctx {
            path: &path,
            data: text.as_bytes(),
        };
        // The bar moves a segment at a time, or over a frame's two header lines (at most
        // 14 bytes here).
        let whole = super::super::check_segmented_index(&ctx, 14, Index::build);
        assert_eq!(whole.len(), 4);
        assert_eq!(whole.frames[3].end, text.len());
    }

    #[test]
    fn a_count_too_large_in_the_middle_is_an_error_and_a_last_frame_cut_short_is_not() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("d.xyz");
        let index = |text: &str| {
            std::fs::write(&path, text).unwrap();
            let ctx = Ctx {
                path: &path,
                data: text.as_bytes(),
            };
            let progress = crate::progress::NoProgress;
            // Whole and through mappings of 8 bytes at a time.
            let whole = Index::build(
                &ctx,
                None,
                usize::MAX,
                &super::super::Reached::new(&progress),
            );
            let file = std::fs::File::open(&path).unwrap();
            let mapped = Index::build(&ctx, Some(&file), 8, &super::super::Reached::new(&progress));
            assert_eq!(
                whole.as_ref().map_err(ToString::to_string),
                mapped.as_ref().map_err(ToString::to_string)
            );
            whole
        };
        // A count past any machine's: too large, not "no integer".
        let e = index("99999999999999999999\nx\n").unwrap_err().to_string();
        assert!(
            e.contains("d.xyz:1: the atom count of frame 0, `99999999999999999999`, is too large"),
            "{e}"
        );
        // Frame 1 says 50 atoms and holds 2: frame 2's count line is read as its third,
        // and the file ends before its 50th.
        let e = index(
            "2\nstep=0\n1 0 0 0\n1 1 0 0\n50\nstep=1\n1 0 0 0\n1 1 0 0\n\
             2\nstep=2\n1 0 0 0\n1 1 0 0\n",
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("d.xyz:9:") && e.contains("frame 1's count is too large"),
            "{e}"
        );
        assert!(e.contains("count (line 5) announces 50 atoms"), "{e}");
        // A last frame cut while it was written, inside a line or after one, even just
        // after a numeric species: the frames before it, and it as cut.
        for text in [
            "1\nstep=0\n1 0 0 0\n3\nstep=1\n1 0 0 0\n1 1",
            "1\nstep=0\n1 0 0 0\n3\nstep=1\n1 0 0 0\n",
            "1\nstep=0\n1 0 0 0\n3\nstep=1\n1 0 0 0\n1",
            "1\nstep=0\n1 0 0 0\n2\nstep=1\n1 0 0 0\n1 2 3 4",
        ] {
            assert_eq!(index(text).unwrap().len(), 2, "{text:?}");
        }
    }
}
