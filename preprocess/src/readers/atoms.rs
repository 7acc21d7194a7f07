//! Parallel parsing of a block of whitespace-separated atom lines, shared by the LAMMPS and
//! XYZ readers.
//!
//! How it works:
//! 1. The block (the bytes of one frame's atom lines, trailing whitespace trimmed) is cut
//!    into chunks of about [`CHUNK_BYTES`], each cut moved forward to just after a `\n`, so
//!    every chunk holds whole lines.
//! 2. The lines of every chunk are counted in parallel (`memchr`, several GB/s). Their sum
//!    is checked against the count the header announced *before* any number is parsed, so a
//!    truncated frame is reported at once. The counts also tell each chunk where its atoms
//!    go in the output arrays, which are allocated once and split into disjoint slices.
//! 3. Chunks are parsed in parallel with rayon. Each walks its bytes once: per line, per
//!    field, it finds the field's end and acts on the field by its [`Role`] (coordinate,
//!    species, attribute, or skip). Numbers go through [`parse_f64`]; species tokens are
//!    looked up in a small per-chunk table and stored as chunk-local ids.
//! 4. The per-chunk species tables are merged in chunk order (so "first appearance" order
//!    is kept), optionally sorted numerically (LAMMPS `type`, XYZ species, when every name
//!    is an integer), and every chunk's local ids
//!    are rewritten to global ids in parallel.
//!
//! Errors carry the byte offset of the offending field or line; the line number is only
//! computed (by counting newlines from the start of the file) when an error is reported.

use std::borrow::Cow;
use std::collections::HashMap;
use std::ops::Range;

use rayon::prelude::*;

use super::float::{parse_prefix, parse_slow};
use super::{Ctx, ReadError};
use crate::frame::{SimulationBox, SpeciesName};
use crate::progress::Progress;

/// Target chunk size for parallel parsing.
const CHUNK_BYTES: usize = 1 << 19;

/// Species name used when a dump has no species column.
pub(crate) const DEFAULT_SPECIES: &str = "atom";

/// How the columns of a frame's atom lines map onto a [`crate::Frame`].
#[derive(Clone, Debug)]
pub(crate) struct AtomLayout {
    /// One name per whitespace-separated field.
    pub columns: Vec<String>,
    /// Coordinate column indices and whether they are fractional (scaled), if any.
    pub coords: Option<([usize; 3], bool)>,
    /// Column holding the species (element or type), if any.
    pub species: Option<usize>,
    /// Species names that all parse as integers are sorted numerically and flagged
    /// `numeric_type` (LAMMPS `type` column without `element`, XYZ species).
    pub numeric_species: bool,
    /// The species are type numbers (from 1), LAMMPS's or an XYZ species column's: type
    /// `n` takes palette slot `n − 1`, as in every reader of type numbers, so that the
    /// same types look the same in every format (not for atomic numbers, XYZ `Z`, where
    /// H = 1 and Na = 11 would share a colour; numbers from 0 take none either).
    pub type_numbers: bool,
    /// A column of element symbols whose radii are the particles' sizes where no column
    /// gives sizes: the dump's `element` column when the species come from another
    /// column (`--species-column`), so that each atom keeps its element's size; with
    /// `false`, each species takes its particles' mean (`--no-sizes`).
    pub element_sizes: Option<(usize, bool)>,
    /// The species column holds categories (`--species-column`): a value written as a
    /// whole number in any notation (`1`, `1.0`, `1.000000e+00`) is that number, values
    /// are sorted as numbers, and whole numbers from 0 take colours by value
    /// ([`crate::species::category_colour`]), the same in every frame.
    pub categories: bool,
}

/// Gives every species of particles with sizes its particles' mean radius and their
/// range (the range kept for [`crate::frame::SpeciesName::radius_range`] even where
/// they agree; the conversion keeps each particle's own where they differ). A species
/// with a particle of size 0 takes radius 0 instead, which the conversion refuses
/// naming the species unless `--radius` gives it one (as GSD and MMPLD sizes of 0 are).
pub(crate) fn sized_species(species: &mut [SpeciesName], species_index: &[u16], radii: &[f32]) {
    let mut sum = vec![0f64; species.len()];
    let mut count = vec![0u64; species.len()];
    let mut range = vec![(f32::INFINITY, f32::NEG_INFINITY); species.len()];
    for (&s, &r) in species_index.iter().zip(radii) {
        let s = usize::from(s);
        if s < species.len() {
            sum[s] += f64::from(r);
            count[s] += 1;
            range[s] = (range[s].0.min(r), range[s].1.max(r));
        }
    }
    for (k, sp) in species.iter_mut().enumerate() {
        if count[k] > 0 {
            let zero = range[k].0 <= 0.0;
            sp.radius = Some(if zero {
                0.0
            } else {
                (sum[k] / count[k] as f64) as f32
            });
            sp.radius_range = Some(range[k]);
            sp.sized_count = count[k];
            sp.sized_sum = sum[k];
        }
    }
}

/// What a chunk parser does with one field.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Role {
    Skip,
    Coord(usize),
    Species,
    Attr,
    CoordAttr(usize),
    SpeciesAttr,
    /// The particle's size, times the factor.
    Size(f64),
    /// The size, and the attribute too.
    SizeAttr(f64),
    /// An element symbol, whose radius is the size.
    ElementSize,
}

/// Everything a chunk parser needs besides its bytes.
struct Plan<'p> {
    roles: Vec<Role>,
    /// The size column and its factor, when read.
    size: Option<(usize, f64)>,
    columns: &'p [String],
    fractional: Option<&'p SimulationBox>,
}

/// The parsed atoms of one frame.
pub(crate) struct Atoms {
    pub positions: Vec<[f32; 3]>,
    pub species_index: Vec<u16>,
    pub species: Vec<SpeciesName>,
    pub attribute: Option<Vec<f32>>,
    /// Each particle's radius, where the layout has a size column.
    pub radii: Option<Vec<f32>>,
}

/// Parses `expected` atom lines from `block` (byte range into `ctx.data`, starting at a line
/// start), with the particles' sizes from column `size` (its factor making it a radius)
/// where given. `count_line` is the offset of the header line that announced `expected`, for
/// error messages.
#[allow(clippy::too_many_arguments)]
pub(crate) fn parse(
    ctx: &Ctx<'_>,
    block: Range<usize>,
    expected: usize,
    layout: &AtomLayout,
    coords: [usize; 3],
    fractional: Option<&SimulationBox>,
    attribute: Option<usize>,
    size: Option<(usize, f64)>,
    values_only: bool,
    label: &str,
    progress: &dyn Progress,
) -> Result<Atoms, ReadError> {
    let data = ctx.data;
    let mut end = block.end;
    while end > block.start && data[end - 1].is_ascii_whitespace() {
        end -= 1;
    }
    let start = block.start;
    progress.stage(label, Some((end - start) as u64), "bytes");

    // 1. chunks at line boundaries
    let mut chunks: Vec<Range<usize>> = Vec::new();
    let mut at = start;
    while at < end {
        let mut cut = (at + CHUNK_BYTES).min(end);
        if cut < end {
            cut = match memchr::memchr(b'\n', &data[cut..end]) {
                Some(p) => cut + p + 1,
                None => end,
            };
        }
        chunks.push(at..cut);
        at = cut;
    }

    // 2. line counts, checked against the announced count
    let counts: Vec<usize> = chunks
        .par_iter()
        .map(|c| {
            let n = memchr::memchr_iter(b'\n', &data[c.clone()]).count();
            if c.end == end {
                n + 1
            } else {
                n
            }
        })
        .collect();
    let found: usize = counts.iter().sum();
    if found < expected {
        // A file a run is still writing ends with complete lines and perhaps a part of
        // one; a line of another column count before the last is damage (two lines run
        // together), which no rerun mends: said as such, not as a frame cut short.
        let columns = layout.columns.len();
        let mut line_start = start;
        while line_start < end {
            let line_end =
                memchr::memchr(b'\n', &data[line_start..end]).map_or(end, |p| line_start + p);
            let tokens = data[line_start..line_end]
                .split(|b| b.is_ascii_whitespace())
                .filter(|t| !t.is_empty())
                .count();
            let last = line_end == end;
            if tokens > columns || (!last && tokens != columns) {
                return Err(ReadError::ColumnCount {
                    at: ctx.at(line_start),
                    expected: columns,
                    found: tokens,
                });
            }
            line_start = line_end + 1;
        }
        return Err(ReadError::Truncated {
            at: ctx.at(end),
            expected,
            found,
        });
    }
    if found > expected {
        let extra = super::skip_lines(data, start, expected);
        return Err(ReadError::ExtraLines {
            at: ctx.at(extra),
            expected,
        });
    }

    // 3. parse into disjoint output slices (with `values_only`, the attribute's column
    // alone: its number parsed, the others' tokens counted)
    let mut roles = vec![Role::Skip; layout.columns.len()];
    if let (Some(s), false) = (layout.species, values_only) {
        roles[s] = Role::Species;
    }
    for (k, &c) in coords.iter().enumerate().filter(|_| !values_only) {
        roles[c] = Role::Coord(k);
    }
    match (size, layout.element_sizes) {
        _ if values_only => {}
        (Some((c, factor)), _) => {
            if roles[c] == Role::Skip {
                roles[c] = Role::Size(factor);
            }
        }
        (None, Some((c, _))) => {
            if roles[c] == Role::Skip {
                roles[c] = Role::ElementSize;
            }
        }
        (None, None) => {}
    }
    if let Some(a) = attribute {
        roles[a] = match roles[a] {
            Role::Coord(k) => Role::CoordAttr(k),
            Role::Species => Role::SpeciesAttr,
            Role::Size(f) => Role::SizeAttr(f),
            _ => Role::Attr,
        };
    }
    let sized = roles
        .iter()
        .any(|r| matches!(r, Role::Size(_) | Role::SizeAttr(_) | Role::ElementSize));
    let plan = Plan {
        size: size.filter(|_| sized),
        roles,
        columns: &layout.columns,
        fractional,
    };
    let mut positions = vec![[0f32; 3]; expected];
    let mut species_index = vec![0u16; expected];
    let mut attr_values = attribute.map(|_| vec![0f32; expected]);
    let mut radii = sized.then(|| vec![0f32; expected]);
    let mut work = Vec::with_capacity(chunks.len());
    {
        let mut pos_rest = positions.as_mut_slice();
        let mut sp_rest = species_index.as_mut_slice();
        let mut attr_rest = attr_values.as_deref_mut();
        let mut size_rest = radii.as_deref_mut();
        for (chunk, &n) in chunks.iter().zip(&counts) {
            let (p, pr) = pos_rest.split_at_mut(n);
            let (s, sr) = sp_rest.split_at_mut(n);
            pos_rest = pr;
            sp_rest = sr;
            let a = split_off(&mut attr_rest, n);
            let z = split_off(&mut size_rest, n);
            work.push((chunk.clone(), p, s, (a, z)));
        }
    }
    let tables: Vec<Result<SpeciesTable<'_>, ReadError>> = work
        .into_par_iter()
        .map(|(chunk, p, s, (a, z))| {
            let len = chunk.len() as u64;
            let r = parse_chunk(ctx, chunk, &plan, p, s, a, z);
            progress.advance(len);
            r
        })
        .collect();
    let mut local = Vec::with_capacity(tables.len());
    for t in tables {
        local.push(t?);
    }

    // 4. merge species
    let species = if layout.species.is_some() && !values_only {
        merge_species(ctx, start, &local, &counts, layout, &mut species_index)?
    } else if expected > 0 {
        vec![SpeciesName {
            name: DEFAULT_SPECIES.to_string(),
            numeric_type: false,
            radius: None,
            ..Default::default()
        }]
    } else {
        Vec::new()
    };
    let mut species = species;
    if let Some(r) = &radii {
        sized_species(&mut species, &species_index, r);
    }
    // Element sizes as each species' mean only (--no-sizes).
    let radii = match layout.element_sizes {
        Some((c, false)) if plan.roles.get(c) == Some(&Role::ElementSize) => {
            for s in &mut species {
                s.radius_range = None;
            }
            None
        }
        _ => radii,
    };
    progress.finish_stage();
    Ok(Atoms {
        positions,
        species_index,
        species,
        attribute: attr_values,
        radii,
    })
}

/// The first `n` values of an optional output, leaving the rest in `rest`.
fn split_off<'a>(rest: &mut Option<&'a mut [f32]>, n: usize) -> Option<&'a mut [f32]> {
    let (part, after) = rest.take()?.split_at_mut(n);
    *rest = Some(after);
    Some(part)
}

/// Merges per-chunk species tables and rewrites `species_index` to global ids.
fn merge_species(
    ctx: &Ctx<'_>,
    block_start: usize,
    local: &[SpeciesTable<'_>],
    counts: &[usize],
    layout: &AtomLayout,
    species_index: &mut [u16],
) -> Result<Vec<SpeciesName>, ReadError> {
    let (numeric, type_numbers, categories) = (
        layout.numeric_species,
        layout.type_numbers,
        layout.categories,
    );
    let column = layout
        .species
        .and_then(|c| layout.columns.get(c))
        .map_or("", String::as_str);
    let mut names: Vec<Cow<'_, [u8]>> = Vec::new();
    let mut ids: HashMap<Cow<'_, [u8]>, u16> = HashMap::new();
    let mut luts: Vec<Vec<u16>> = Vec::with_capacity(local.len());
    for table in local {
        let mut lut = Vec::with_capacity(table.names.len());
        for &token in &table.names {
            let name = if categories {
                category_name(token).map_err(|value| ReadError::Malformed {
                    // The token is the chunk's first of its kind, where it lies in the
                    // file (chunks are taken in order): its line.
                    at: ctx.at((token.as_ptr() as usize)
                        .checked_sub(ctx.data.as_ptr() as usize)
                        .filter(|&o| o < ctx.data.len())
                        .unwrap_or(block_start)),
                    message: format!(
                        "--species-column {column}: a value `{value}` in the frame is no \
                         category (a structure type's number or name)"
                    ),
                })?
            } else {
                Cow::Borrowed(token)
            };
            let id = match ids.get(&name) {
                Some(&id) => id,
                None => {
                    let id = u16::try_from(names.len()).map_err(|_| ReadError::TooManySpecies {
                        at: ctx.at(block_start),
                    })?;
                    names.push(name.clone());
                    ids.insert(name, id);
                    id
                }
            };
            lut.push(id);
        }
        luts.push(lut);
    }
    let values: Option<Vec<i64>> = if numeric {
        names
            .iter()
            .map(|n| std::str::from_utf8(n).ok()?.parse::<i64>().ok())
            .collect()
    } else {
        None
    };
    let numeric_type = values.is_some();
    // LAMMPS types start at 1; a 0 or below is no type number to take a slot by.
    let slots = type_numbers && values.as_ref().is_some_and(|v| v.iter().all(|&n| n >= 1));
    if let Some(values) = values {
        let mut order: Vec<usize> = (0..names.len()).collect();
        order.sort_by_key(|&i| values[i]);
        let mut rank = vec![0u16; names.len()];
        for (new, &old) in order.iter().enumerate() {
            rank[old] = new as u16;
        }
        names = order.iter().map(|&i| names[i].clone()).collect();
        for lut in &mut luts {
            for id in lut.iter_mut() {
                *id = rank[*id as usize];
            }
        }
    }
    let mut slices = Vec::with_capacity(counts.len());
    let mut rest = species_index;
    for (&n, lut) in counts.iter().zip(&luts) {
        let (s, r) = rest.split_at_mut(n);
        rest = r;
        slices.push((s, lut));
    }
    slices.into_par_iter().for_each(|(s, lut)| {
        if lut.iter().enumerate().any(|(i, &g)| g as usize != i) {
            for v in s.iter_mut() {
                *v = lut[*v as usize];
            }
        }
    });
    Ok(names
        .into_iter()
        .enumerate()
        .map(|(place, n)| {
            let name = String::from_utf8_lossy(&n).into_owned();
            SpeciesName {
                numeric_type,
                radius: None,
                palette_slot: if slots { type_number_slot(&n) } else { None },
                // Categories that are no whole number from 0 take colours by place from
                // past the palette's first ten, none of which a structure type takes.
                colour: if categories {
                    name.parse::<i64>()
                        .ok()
                        .and_then(|v| crate::species::category_colour(column, v))
                        .or_else(|| Some(crate::species::palette_colour(10 + place)))
                } else {
                    None
                },
                name,
                ..Default::default()
            }
        })
        .collect())
}

/// A category's name: a whole number in any notation as that number (`1.000000` is
/// `1`, `-0` is `0`); other tokens as written. `Err` with the token for a number that is
/// not finite (`nan`, `inf`).
fn category_name(token: &[u8]) -> Result<Cow<'_, [u8]>, String> {
    let Ok(text) = std::str::from_utf8(token) else {
        return Ok(Cow::Borrowed(token));
    };
    if text.parse::<f64>().is_ok_and(|v| !v.is_finite()) {
        return Err(text.to_string());
    }
    match crate::species::whole_number(text).map(|v| v.to_string()) {
        Some(whole) if whole != text => Ok(Cow::Owned(whole.into_bytes())),
        _ => Ok(Cow::Borrowed(token)),
    }
}

/// Distinct species tokens of one chunk, in order of first appearance.
struct SpeciesTable<'a> {
    names: Vec<&'a [u8]>,
    last: usize,
    map: HashMap<&'a [u8], u16>,
}

impl<'a> SpeciesTable<'a> {
    /// Linear search up to this many names, a hash map beyond.
    const LINEAR: usize = 16;

    fn new() -> Self {
        SpeciesTable {
            names: Vec::new(),
            last: 0,
            map: HashMap::new(),
        }
    }

    /// The chunk-local id of `token`, or `None` when there are too many species.
    #[inline]
    fn id(&mut self, token: &'a [u8]) -> Option<u16> {
        if self.names.get(self.last) == Some(&token) {
            return Some(self.last as u16);
        }
        let found = if self.names.len() <= Self::LINEAR {
            self.names.iter().position(|&n| n == token)
        } else {
            self.map.get(token).map(|&i| i as usize)
        };
        let i = match found {
            Some(i) => i,
            None => {
                let i = self.names.len();
                let id = u16::try_from(i).ok()?;
                self.names.push(token);
                if self.names.len() > Self::LINEAR {
                    if self.map.is_empty() {
                        for (j, &n) in self.names.iter().enumerate() {
                            self.map.insert(n, j as u16);
                        }
                    } else {
                        self.map.insert(token, id);
                    }
                }
                i
            }
        };
        self.last = i;
        Some(i as u16)
    }
}

/// Parses the lines of one chunk into the given output slices (one line per element).
fn parse_chunk<'a>(
    ctx: &Ctx<'a>,
    chunk: Range<usize>,
    plan: &Plan<'_>,
    positions: &mut [[f32; 3]],
    species: &mut [u16],
    mut attribute: Option<&mut [f32]>,
    mut sizes: Option<&mut [f32]>,
) -> Result<SpeciesTable<'a>, ReadError> {
    let bytes: &'a [u8] = &ctx.data[..chunk.end];
    let roles = plan.roles.as_slice();
    let mut table = SpeciesTable::new();
    // The element symbols met and their radii (a frame names a few elements; the last
    // is tried first, as atoms of one element come in runs).
    let mut elements: Vec<(&[u8], f64)> = Vec::new();
    let mut last_element = 0usize;
    let mut i = chunk.start;
    for (a, (pos_out, sp_out)) in positions.iter_mut().zip(species.iter_mut()).enumerate() {
        let line_start = i;
        let mut col = 0usize;
        let mut p = [0f64; 3];
        let mut attr = 0f64;
        let mut size = 0f64;
        let mut sp = 0u16;
        loop {
            while i < bytes.len() && bytes[i] <= b' ' && bytes[i] != b'\n' {
                i += 1;
            }
            if i >= bytes.len() || bytes[i] == b'\n' {
                break;
            }
            let t0 = i;
            let Some(&role) = roles.get(col) else {
                return Err(column_count(ctx, line_start, roles.len()));
            };
            match role {
                Role::Skip => {
                    while i < bytes.len() && bytes[i] > b' ' {
                        i += 1;
                    }
                }
                Role::Coord(k) => p[k] = number(ctx, plan, bytes, &mut i, col)?,
                Role::Attr => attr = number(ctx, plan, bytes, &mut i, col)?,
                Role::CoordAttr(k) => {
                    p[k] = number(ctx, plan, bytes, &mut i, col)?;
                    attr = p[k];
                }
                Role::Size(factor) => size = factor * number(ctx, plan, bytes, &mut i, col)?,
                Role::SizeAttr(factor) => {
                    attr = number(ctx, plan, bytes, &mut i, col)?;
                    size = factor * attr;
                }
                Role::ElementSize => {
                    while i < bytes.len() && bytes[i] > b' ' {
                        i += 1;
                    }
                    let token = &bytes[t0..i];
                    let radius_of = |token: &[u8]| {
                        let radius = std::str::from_utf8(token)
                            .ok()
                            .and_then(crate::species::element)
                            .map_or(crate::species::DEFAULT_RADIUS, |(r, _)| r);
                        f64::from(radius)
                    };
                    if elements.get(last_element).is_none_or(|e| e.0 != token) {
                        last_element = match elements.iter().position(|e| e.0 == token) {
                            Some(k) => k,
                            // (Past the elements there are, tokens are not remembered:
                            // a column of distinct junk would make the search quadratic.)
                            None if elements.len() >= 128 => usize::MAX,
                            None => {
                                elements.push((token, radius_of(token)));
                                elements.len() - 1
                            }
                        };
                    }
                    size = elements
                        .get(last_element)
                        .map_or_else(|| radius_of(token), |e| e.1);
                }
                Role::Species | Role::SpeciesAttr => {
                    while i < bytes.len() && bytes[i] > b' ' {
                        i += 1;
                    }
                    let token = &bytes[t0..i];
                    sp = table
                        .id(token)
                        .ok_or_else(|| ReadError::TooManySpecies { at: ctx.at(t0) })?;
                    if role == Role::SpeciesAttr {
                        let mut j = t0;
                        attr = number(ctx, plan, bytes, &mut j, col)?;
                    }
                }
            }
            col += 1;
        }
        if col != roles.len() {
            return Err(column_count(ctx, line_start, roles.len()));
        }
        i += 1;
        let q = match plan.fractional {
            Some(b) => b.from_fractional(p),
            None => p,
        };
        let q = [q[0] as f32, q[1] as f32, q[2] as f32];
        if !q.iter().all(|v| v.is_finite()) {
            return Err(ReadError::Malformed {
                at: ctx.at(line_start),
                message: format!(
                    "position ({:?}, {:?}, {:?}) is outside the single-precision range",
                    p[0], p[1], p[2]
                ),
            });
        }
        *pos_out = q;
        *sp_out = sp;
        if let Some(out) = attribute.as_deref_mut() {
            let v = attr as f32;
            if !v.is_finite() {
                // (The column named, as a NaN's message names it.)
                let column = plan
                    .roles
                    .iter()
                    .position(|r| {
                        matches!(
                            r,
                            Role::Attr | Role::CoordAttr(_) | Role::SpeciesAttr | Role::SizeAttr(_)
                        )
                    })
                    .and_then(|c| plan.columns.get(c));
                return Err(ReadError::Malformed {
                    at: ctx.at(line_start),
                    message: match column {
                        Some(c) => format!(
                            "column {c}: attribute value {attr:?} is outside the \
                             single-precision range"
                        ),
                        None => format!(
                            "attribute value {attr:?} is outside the single-precision range"
                        ),
                    },
                });
            }
            out[a] = v;
        }
        if let Some(out) = sizes.as_deref_mut() {
            let v = size as f32;
            // A size of 0 passes: a type of such particles (an SPH dump's stars and dark
            // matter beside its gas, h = 0) is refused by name later, unless --radius
            // gives it one (`species::unusable_radius`).
            if !(v.is_finite() && v >= 0.0) {
                let (c, factor) = plan.size.unwrap_or((0, 1.0));
                return Err(ReadError::Malformed {
                    at: ctx.at(line_start),
                    message: format!(
                        "`{}` {} is no particle size (a finite number from 0 up, in single \
                         precision; a type of size 0 needs --radius)",
                        plan.columns.get(c).map_or("size", String::as_str),
                        size / factor
                    ),
                });
            }
            out[a] = v;
        }
    }
    Ok(table)
}

/// Parses the numeric field starting at `*i` and moves `*i` past it; NaN and infinities
/// are errors. The fast path parses while scanning, without finding the field's end first.
#[inline(always)]
fn number(
    ctx: &Ctx<'_>,
    plan: &Plan<'_>,
    bytes: &[u8],
    i: &mut usize,
    col: usize,
) -> Result<f64, ReadError> {
    let rest = &bytes[*i..];
    if let Some((v, n)) = parse_prefix(rest) {
        if rest.get(n).is_none_or(|&b| b <= b' ') && v.is_finite() {
            *i += n;
            return Ok(v);
        }
    }
    number_slow(ctx, plan, bytes, i, col)
}

/// [`number`] for fields the fast path does not take: the standard library's parse, and
/// the errors.
#[cold]
#[inline(never)]
fn number_slow(
    ctx: &Ctx<'_>,
    plan: &Plan<'_>,
    bytes: &[u8],
    i: &mut usize,
    col: usize,
) -> Result<f64, ReadError> {
    let start = *i;
    while *i < bytes.len() && bytes[*i] > b' ' {
        *i += 1;
    }
    let token = &bytes[start..*i];
    // (A token of megabytes is named by its first characters.)
    let text = || super::shorten(token);
    match parse_slow(token) {
        Some(v) if v.is_finite() => Ok(v),
        Some(_) => Err(ReadError::NonFinite {
            at: ctx.at(start),
            column: plan.columns[col].clone(),
            text: text(),
        }),
        None => Err(ReadError::NotANumber {
            at: ctx.at(start),
            column: plan.columns[col].clone(),
            text: text(),
        }),
    }
}

/// The error for a line whose field count differs from the header's (slow path).
#[cold]
fn column_count(ctx: &Ctx<'_>, line_start: usize, expected: usize) -> ReadError {
    let data = ctx.data;
    let line_end =
        memchr::memchr(b'\n', &data[line_start..]).map_or(data.len(), |p| line_start + p);
    let line = &data[line_start..line_end];
    let found = line.split(|&b| b <= b' ').filter(|t| !t.is_empty()).count();
    if line.starts_with(b"ITEM:") {
        return ReadError::Malformed {
            at: ctx.at(line_start),
            message: format!(
                "found `{}` where an atom line was expected (truncated frame?)",
                String::from_utf8_lossy(line).trim_end()
            ),
        };
    }
    if line_end == data.len() && found < expected {
        // No newline after it: the file stops inside the line.
        return ReadError::Malformed {
            at: ctx.at(line_start),
            message: format!(
                "the file ends inside this atom line, after {found} of its {expected} \
                 columns (truncated file?)"
            ),
        };
    }
    ReadError::ColumnCount {
        at: ctx.at(line_start),
        expected,
        found,
    }
}

/// The palette place of LAMMPS type `name` (a number from 1): `n − 1`.
pub(crate) fn type_number_slot(name: &[u8]) -> Option<usize> {
    let n: u64 = std::str::from_utf8(name).ok()?.trim().parse().ok()?;
    usize::try_from(n.checked_sub(1)?).ok()
}
