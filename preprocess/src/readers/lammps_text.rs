//! LAMMPS text dumps (`dump atom`, `dump custom`), as LAMMPS writes them.
//!
//! How it works:
//! - **Index.** One `memchr::memmem` scan finds every line that is exactly
//!   `ITEM: TIMESTEP`; the next line gives the frame's timestep. A file larger than
//!   [`super::SCAN_SEGMENT`] is scanned a segment at a time, each through a fresh mapping
//!   dropped after it, so that the memory resident stays bounded. LAMMPS writes
//!   `ITEM: UNITS` (first frame only) and `ITEM: TIME` *before* `ITEM: TIMESTEP`, so each
//!   frame start is moved back over up to two such two-line blocks; the first `UNITS`
//!   value found is kept for all frames. Frame `k` spans from its start to the next
//!   frame's start.
//! - **Header.** `ITEM:` blocks are read in any order until `ITEM: ATOMS <columns>`:
//!   `UNITS`, `TIME`, `TIMESTEP`, `NUMBER OF ATOMS` and `BOX BOUNDS`; unknown items are
//!   skipped up to the next `ITEM:` line. `BOX BOUNDS` comes in three shapes:
//!   orthogonal (`lo hi` per line), restricted triclinic (`xy xz yz` keywords, lines
//!   `lo_bound hi_bound tilt`, converted to the true bounds as the LAMMPS `dump` docs
//!   describe: `xlo = xlo_bound - min(0, xy, xz, xy+xz)`, `xhi = xhi_bound - max(0, xy, xz,
//!   xy+xz)`, `ylo = ylo_bound - min(0, yz)`, `yhi = yhi_bound - max(0, yz)`) and general
//!   triclinic (`abc origin` keywords, lines `ax ay az originx` etc.); a lower bound above
//!   its upper bound is an error naming the line. Boundary flags
//!   (`pp ff sm`) set [`SimulationBox::periodic`] (periodic where the flag is `pp`).
//! - **Columns.** Coordinates come from the first complete triple in the order
//!   `x y z` > `xu yu zu` > `xs ys zs` > `xsu ysu zsu`: wrapped Cartesian first, then
//!   unwrapped, then scaled (fractional, converted with [`SimulationBox::from_fractional`],
//!   which handles triclinic boxes). Species come from `element` if present, else from
//!   `type` (numeric types are sorted numerically and flagged `numeric_type`; type labels
//!   keep first-appearance order), else every atom is one species. Any column can be the
//!   attribute. An `ITEM: ATOMS` line without names (very old LAMMPS) means `id type xs ys
//!   zs`; atom lines of another column count, or more than a few of the first thousand
//!   lying far outside the box (unscaled coordinates), are refused, as binary dumps are.
//! - **Atoms.** The lines after `ITEM: ATOMS` up to the frame end go to the shared parallel
//!   parser, which checks their count against `NUMBER OF ATOMS` and keeps their order.

use memchr::memmem;

use super::atoms::AtomLayout;
use super::{
    fields, parse_f64, parse_int, shorten, trim, Ctx, Cursor, FrameInfo, Header, ReadError,
};
use crate::frame::SimulationBox;

/// The line every frame has.
const TIMESTEP: &[u8] = b"ITEM: TIMESTEP";

/// Byte range and timestep of one frame.
#[derive(Debug, PartialEq)]
struct Span {
    start: usize,
    end: usize,
    timestep: Option<u64>,
}

/// The frames of a LAMMPS text dump.
#[derive(Debug, PartialEq)]
pub(crate) struct Index {
    frames: Vec<Span>,
    /// Each `ITEM: UNITS` and the frame it heads, in order: LAMMPS writes it in the first
    /// frame of each file a dump command opens, so a frame takes the last one before it
    /// (runs of other units concatenated into one file), frames before the first the
    /// first.
    units: Vec<(usize, String)>,
}

/// Coordinate column triples in order of preference, and whether they are scaled.
const COORDINATE_STYLES: [([&str; 3], bool); 4] = [
    (["x", "y", "z"], false),
    (["xu", "yu", "zu"], false),
    (["xs", "ys", "zs"], true),
    (["xsu", "ysu", "zsu"], true),
];

/// A dump that ends in the first lines of a frame not yet written whole (`ITEM:
/// TIMES`): those lines made a frame of their own in `frames`, cut short, not more atom
/// lines of the frame before.
fn split_cut_header(data: &[u8], frames: &mut Vec<Span>) {
    if let Some(last) = frames.last_mut() {
        if let Some(start) = cut_header_start(data, last.start) {
            last.end = start;
            frames.push(Span {
                start,
                end: data.len(),
                timestep: None,
            });
        }
    }
}

/// Where the dump's last lines begin a frame header that the file ends inside without
/// reaching its `ITEM: TIMESTEP` line whole: optional `ITEM: UNITS` and `ITEM: TIME`
/// lines (each with its value, or the value cut or missing), then possibly the start of
/// a header line cut at the end (`ITEM: TIMES`). `None` when the dump ends otherwise,
/// or only where the frame starting at `floor` began.
fn cut_header_start(data: &[u8], floor: usize) -> Option<usize> {
    const ITEMS: [&[u8]; 3] = [b"ITEM: TIMESTEP", b"ITEM: TIME", b"ITEM: UNITS"];
    // The last five lines, earliest first, the final one without its line end if cut.
    let mut lines: Vec<(usize, &[u8])> = Vec::new();
    let mut end = data.len();
    if data.ends_with(b"\n") {
        end -= 1;
    }
    while lines.len() < 5 && end > floor {
        let start = data[floor..end]
            .iter()
            .rposition(|&b| b == b'\n')
            .map_or(floor, |p| floor + p + 1);
        lines.push((start, &data[start..end]));
        end = start.saturating_sub(1);
    }
    lines.reverse();
    let cut = !data.ends_with(b"\n");
    // The earliest of those lines from which the rest is such a beginning.
    (0..lines.len()).find_map(|first| {
        let rest = &lines[first..];
        let mut i = 0;
        while i < rest.len() {
            let line = trim(rest[i].1);
            let last = i + 1 == rest.len();
            if line == b"ITEM: UNITS" || line == b"ITEM: TIME" {
                i += 2; // Its value, whole, cut or missing.
            } else if last
                && cut
                && !line.is_empty()
                && ITEMS.iter().any(|t| t.starts_with(line))
                // `I` or `ITEM: ` cut after a header line of the frame in progress is
                // that frame's next header line (`ITEM: NUMBER OF ATOMS`), not a new one.
                && !(b"ITEM: ".starts_with(line) && header_in_progress(data, rest[i].0))
            {
                i += 1;
            } else {
                return None;
            }
        }
        (rest[0].0 > floor).then_some(rest[0].0)
    })
}

/// Whether the line starting at `line_start` follows, within a few lines, a frame
/// header's `ITEM: TIMESTEP`, `ITEM: NUMBER OF ATOMS` or `ITEM: BOX BOUNDS` line: it
/// continues that header (rather than following an `ITEM: ATOMS` line or atom lines).
fn header_in_progress(data: &[u8], line_start: usize) -> bool {
    let mut at = line_start;
    for _ in 0..4 {
        let Some((start, line)) = prev_line(data, at) else {
            return false;
        };
        let line = trim(line);
        if line.starts_with(b"ITEM:") {
            return [
                &b"ITEM: TIMESTEP"[..],
                b"ITEM: NUMBER OF ATOMS",
                b"ITEM: BOX BOUNDS",
            ]
            .iter()
            .any(|h| line.starts_with(h));
        }
        at = start;
    }
    false
}

/// The line ending at `line_start - 1` (its start and bytes), if any.
fn prev_line(data: &[u8], line_start: usize) -> Option<(usize, &[u8])> {
    if line_start == 0 {
        return None;
    }
    let end = line_start - 1;
    let start = memchr::memrchr(b'\n', &data[..end]).map_or(0, |p| p + 1);
    Some((start, &data[start..end]))
}

impl Index {
    /// Indexes `ctx.data`. `file`, when given, is the file `ctx.data` maps: a larger one
    /// than `segment` bytes is scanned a segment at a time through fresh mappings of it.
    pub fn build(
        ctx: &Ctx<'_>,
        file: Option<&std::fs::File>,
        segment: usize,
        reached: &super::Reached<'_>,
    ) -> Result<Index, ReadError> {
        let data = ctx.data;
        let mut frames: Vec<Span> = Vec::new();
        let mut units = Vec::new();
        let mut visit = |data: &[u8], p: usize| Index::visit(data, p, &mut frames, &mut units);
        let segment = segment.max(1);
        match file {
            Some(file) if data.len() > segment => {
                let finder = memmem::Finder::new(TIMESTEP);
                let mut start = 0;
                while start < data.len() {
                    let map = super::mapped_again(ctx, file, start)?;
                    let end = (start + segment).min(data.len());
                    // Matches starting in this segment (the last may run into the next).
                    let hay = &map[start..(end + TIMESTEP.len() - 1).min(map.len())];
                    for p in finder.find_iter(hay) {
                        visit(&map, start + p);
                    }
                    start = end;
                    reached.at(start);
                }
            }
            _ => {
                for p in memmem::find_iter(data, TIMESTEP) {
                    visit(data, p);
                }
            }
        }
        Index::finish(ctx, frames, units)
    }

    /// Records the frame whose `ITEM: TIMESTEP` may start at `p`.
    fn visit(data: &[u8], p: usize, frames: &mut Vec<Span>, units: &mut Vec<(usize, String)>) {
        {
            // (A line that is `ITEM: TIMESTEP` from its first byte, as the scan finds them.)
            if (p > 0 && data[p - 1] != b'\n') || !data[p..].starts_with(TIMESTEP) {
                return;
            }
            let mut cursor = Cursor::new(data, p);
            match cursor.next_line() {
                Some((_, line)) if trim(line) == TIMESTEP => {}
                _ => return,
            }
            let timestep = cursor.next_line().and_then(|(_, l)| parse_int::<u64>(l));
            let floor = frames.last().map_or(0, |f| f.start);
            let mut start = p;
            for _ in 0..2 {
                let Some((value_start, value)) = prev_line(data, start) else {
                    break;
                };
                let Some((item_start, item)) = prev_line(data, value_start) else {
                    break;
                };
                let item = trim(item);
                if item_start <= floor && !frames.is_empty() {
                    break;
                }
                if item == b"ITEM: UNITS" {
                    let value = String::from_utf8_lossy(trim(value)).into_owned();
                    units.push((frames.len(), value));
                } else if item != b"ITEM: TIME" {
                    break;
                }
                start = item_start;
            }
            if let Some(last) = frames.last_mut() {
                last.end = start;
            }
            frames.push(Span {
                start,
                end: data.len(),
                timestep,
            });
        }
    }

    /// The index of the frames found, checked: the file starts with the first.
    fn finish(
        ctx: &Ctx<'_>,
        mut frames: Vec<Span>,
        units: Vec<(usize, String)>,
    ) -> Result<Index, ReadError> {
        let data = ctx.data;
        split_cut_header(data, &mut frames);
        let Some(first) = frames.first() else {
            return Err(ctx.malformed(0, "no `ITEM: TIMESTEP` line found: not a LAMMPS text dump"));
        };
        if let Some(p) = data[..first.start]
            .iter()
            .position(|b| !b.is_ascii_whitespace())
        {
            let line = Cursor::new(data, p).next_line().map_or(&[][..], |l| l.1);
            return Err(ctx.malformed(
                p,
                format!(
                    "expected `ITEM: TIMESTEP` to start the dump, found `{}`",
                    shorten(line)
                ),
            ));
        }
        Ok(Index { frames, units })
    }

    /// The dump's first `ITEM: UNITS`.
    fn first_units(&self) -> Option<String> {
        self.units.first().map(|u| u.1.clone())
    }

    /// The units of frame `k`: the last `ITEM: UNITS` at or before it, else the first.
    fn units_of(&self, k: usize) -> Option<String> {
        let before = self.units.iter().rev().find(|(at, _)| *at <= k);
        before.or(self.units.first()).map(|u| u.1.clone())
    }

    /// The index as a cache keeps it ([`super::index_cache`]).
    pub fn to_cached(&self) -> super::index_cache::CachedFrames {
        super::index_cache::CachedFrames {
            units: self.first_units(),
            ..super::index_cache::CachedFrames::of(
                "lammps",
                self.frames.iter().map(|s| (s.start, s.end, s.timestep)),
            )
        }
    }

    /// The index a cache kept for the dump `data`, when it is the one a scan would make
    /// from the frame starts it names: each range holds an `ITEM: TIMESTEP` line in its
    /// first five lines (after at most two two-line `UNITS`/`TIME` blocks), and taking
    /// those lines as the scan's finds gives exactly the ranges, timesteps and units kept
    /// (the last range may be a header cut short, as a scan ends). Only `ITEM: TIMESTEP`
    /// lines inside a frame's atom lines, which no dump LAMMPS writes holds, go unseen.
    pub fn from_cached(data: &[u8], cached: &super::index_cache::CachedFrames) -> Option<Index> {
        if cached.format != "lammps" || !cached.unread_timesteps.is_empty() {
            return None;
        }
        let ranges = cached.checked_ranges(data)?;
        if !data[..ranges.first()?.start]
            .iter()
            .all(u8::is_ascii_whitespace)
        {
            return None;
        }
        let mut frames: Vec<Span> = Vec::with_capacity(ranges.len());
        let mut units = Vec::new();
        for (k, r) in ranges.iter().enumerate() {
            let mut cursor = Cursor::new(&data[..r.end], r.start);
            let mut at = None;
            for _ in 0..5 {
                match cursor.next_line() {
                    Some((p, line)) if trim(line) == TIMESTEP => {
                        at = Some(p);
                        break;
                    }
                    Some(_) => {}
                    None => break,
                }
            }
            match at {
                Some(p) => Index::visit(data, p, &mut frames, &mut units),
                // A header cut short ends the dump: as the scan's end finds it, below.
                None if k + 1 == ranges.len() => {}
                None => return None,
            }
        }
        split_cut_header(data, &mut frames);
        let same = frames.len() == ranges.len()
            && units.first().map(|u| &u.1) == cached.units.as_ref()
            && frames
                .iter()
                .zip(&ranges)
                .zip(&cached.timesteps)
                .all(|((f, r), t)| f.start == r.start && f.end == r.end && f.timestep == *t);
        same.then_some(Index { frames, units })
    }

    pub fn len(&self) -> usize {
        self.frames.len()
    }

    pub fn timestep(&self, k: usize) -> Option<u64> {
        self.frames.get(k)?.timestep
    }

    /// The byte range of frame `k`, up to the next frame's first byte (the last frame's:
    /// up to the end of the file).
    pub fn bytes(&self, k: usize) -> Option<std::ops::Range<usize>> {
        self.frames.get(k).map(|s| s.start..s.end)
    }

    /// Parses the header of frame `k` (which must exist).
    pub fn header(&self, ctx: &Ctx<'_>, k: usize) -> Result<Header, ReadError> {
        let span = &self.frames[k];
        self.parse_header(ctx, k).map_err(|e| {
            // The file ends inside the last frame's header (a run still writing it): told
            // apart from a malformed header by the `ITEM: ATOMS` line it has not reached.
            let text = &ctx.data[span.start..span.end];
            // (A `dump local`'s entries are no atoms to come.)
            let reached_atoms = ["ITEM: ATOMS", "ITEM: ENTRIES"].iter().any(|item| {
                memchr::memmem::find(text, item.as_bytes())
                    .is_some_and(|at| text[at..].contains(&b'\n'))
            });
            if span.end == ctx.data.len()
                && k + 1 == self.frames.len()
                && !reached_atoms
                && !e.cut_short()
            {
                ctx.malformed(
                    span.end,
                    format!("frame {k} ends before its `ITEM: ATOMS` line ({e})"),
                )
            } else {
                e
            }
        })
    }

    fn parse_header(&self, ctx: &Ctx<'_>, k: usize) -> Result<Header, ReadError> {
        let span = &self.frames[k];
        let data = &ctx.data[..span.end];
        let mut cursor = Cursor::new(data, span.start);
        let mut info = FrameInfo {
            particles: 0,
            timestep: None,
            time: None,
            units: None,
            simulation_box: None,
            columns: Vec::new(),
        };
        let mut particles = None;
        let (columns_at, columns) = loop {
            let Some((at, line)) = cursor.next_line() else {
                return Err(ctx.malformed(
                    span.end,
                    format!("frame {k} ends before its `ITEM: ATOMS` line"),
                ));
            };
            let line = trim(line);
            if line.is_empty() {
                continue;
            }
            let Some(item) = line.strip_prefix(b"ITEM:") else {
                return Err(ctx.malformed(
                    at,
                    format!("expected an `ITEM:` line, found `{}`", shorten(line)),
                ));
            };
            let item = trim(item);
            match item {
                b"TIMESTEP" => {
                    info.timestep = Some(value(ctx, &mut cursor, at, "TIMESTEP", |v| {
                        parse_int::<u64>(v)
                    })?);
                }
                b"TIME" => {
                    info.time = Some(value(ctx, &mut cursor, at, "TIME", |v| {
                        parse_f64(v).filter(|t| t.is_finite())
                    })?);
                }
                b"UNITS" => {
                    info.units = Some(value(ctx, &mut cursor, at, "UNITS", |v| {
                        Some(String::from_utf8_lossy(v).into_owned())
                    })?);
                }
                b"NUMBER OF ATOMS" => {
                    particles = Some(value(ctx, &mut cursor, at, "NUMBER OF ATOMS", |v| {
                        parse_int::<usize>(v)
                    })?);
                }
                _ if item.starts_with(b"BOX BOUNDS") => {
                    info.simulation_box = Some(parse_box(ctx, &mut cursor, at, &item[10..])?);
                }
                // `dump local`'s items: entries (bonds, pairs), not atoms.
                _ if item == b"NUMBER OF ENTRIES" || item.starts_with(b"ENTRIES") => {
                    return Err(ctx.malformed(
                        at,
                        format!(
                            "frame {k} is a `dump local` one (`ITEM: {}`): its lines are \
                             entries, such as bonds or pairs, not particles; `dump custom` \
                             writes the atoms",
                            String::from_utf8_lossy(item)
                        ),
                    ));
                }
                _ if item.starts_with(b"ATOMS") => {
                    let mut names: Vec<String> = fields(&item[5..])
                        .map(|f| String::from_utf8_lossy(f).into_owned())
                        .collect();
                    if names.is_empty() {
                        names = ["id", "type", "xs", "ys", "zs"].map(String::from).to_vec();
                        check_assumed_columns(ctx, data, cursor.pos)?;
                    }
                    break (at, names);
                }
                _ => loop {
                    // An item this reader does not know: skip to the next `ITEM:` line.
                    let save = cursor.pos;
                    match cursor.next_line() {
                        None => break,
                        Some((_, l)) if trim(l).starts_with(b"ITEM:") => {
                            cursor.pos = save;
                            break;
                        }
                        Some(_) => {}
                    }
                },
            }
        };
        info.particles = particles.ok_or_else(|| {
            ctx.malformed(
                columns_at,
                "no `ITEM: NUMBER OF ATOMS` before `ITEM: ATOMS`",
            )
        })?;
        if info.units.is_none() {
            info.units = self.units_of(k);
        }
        let find = |name: &str| columns.iter().position(|c| c == name);
        let coords = COORDINATE_STYLES.iter().find_map(|(names, scaled)| {
            Some(([find(names[0])?, find(names[1])?, find(names[2])?], *scaled))
        });
        let element = find("element");
        let layout = AtomLayout {
            columns: columns.clone(),
            coords,
            species: element.or_else(|| find("type")),
            numeric_species: element.is_none(),
            type_numbers: element.is_none(),
            element_sizes: None,
            categories: false,
        };
        info.columns = columns;
        Ok(Header {
            info,
            layout,
            columns_at,
            atoms: cursor.pos..span.end,
        })
    }
}

/// Reads the single value line after `ITEM: <item>` at `item_at`.
fn value<T>(
    ctx: &Ctx<'_>,
    cursor: &mut Cursor<'_>,
    item_at: usize,
    item: &str,
    parse: impl FnOnce(&[u8]) -> Option<T>,
) -> Result<T, ReadError> {
    let Some((at, line)) = cursor.next_line() else {
        return Err(ctx.malformed(item_at, format!("`ITEM: {item}` has no value line")));
    };
    parse(trim(line)).ok_or_else(|| {
        ctx.malformed(
            at,
            format!("malformed `ITEM: {item}` value `{}`", shorten(line)),
        )
    })
}

/// Parses the three lines after `ITEM: BOX BOUNDS<rest>`.
fn parse_box(
    ctx: &Ctx<'_>,
    cursor: &mut Cursor<'_>,
    item_at: usize,
    rest: &[u8],
) -> Result<SimulationBox, ReadError> {
    let words: Vec<&[u8]> = fields(rest).collect();
    let general = words.contains(&&b"abc"[..]);
    let triclinic = words.contains(&&b"xy"[..]);
    let flags: Vec<&[u8]> = words
        .iter()
        .copied()
        .filter(|w| w.len() == 2 && w.iter().all(|b| b"pfsm".contains(b)))
        .collect();
    let (per_line, shape) = if general {
        (4, "ax ay az origin")
    } else if triclinic {
        (3, "lo_bound hi_bound tilt")
    } else {
        (2, "lo hi")
    };
    let mut rows = [[0f64; 4]; 3];
    for (r, row) in rows.iter_mut().enumerate() {
        let Some((at, line)) = cursor.next_line() else {
            return Err(ctx.malformed(
                item_at,
                format!("malformed BOX BOUNDS: expected 3 lines, found {r}"),
            ));
        };
        let values: Vec<&[u8]> = fields(line).collect();
        if values.len() != per_line {
            return Err(ctx.malformed(
                at,
                format!(
                    "malformed BOX BOUNDS: expected {per_line} numbers ({shape}), found `{}`",
                    shorten(line)
                ),
            ));
        }
        for (slot, v) in row.iter_mut().zip(&values) {
            *slot = parse_f64(v).filter(|x| x.is_finite()).ok_or_else(|| {
                ctx.malformed(
                    at,
                    format!(
                        "malformed BOX BOUNDS: `{}` is not a finite number",
                        shorten(v)
                    ),
                )
            })?;
        }
        // (`lo hi` and `lo_bound hi_bound tilt` lines; a general triclinic line is a
        // vector.)
        if !general && row[0] > row[1] {
            return Err(ctx.malformed(
                at,
                format!(
                    "malformed BOX BOUNDS: `{}` has its lower bound {} above its upper bound {}",
                    shorten(line),
                    super::shown(row[0]),
                    super::shown(row[1])
                ),
            ));
        }
    }
    let mut b = if general {
        SimulationBox {
            origin: [rows[0][3], rows[1][3], rows[2][3]],
            a: [rows[0][0], rows[0][1], rows[0][2]],
            b: [rows[1][0], rows[1][1], rows[1][2]],
            c: [rows[2][0], rows[2][1], rows[2][2]],
            periodic: None,
        }
    } else if triclinic {
        let (xy, xz, yz) = (rows[0][2], rows[1][2], rows[2][2]);
        let lo = [
            rows[0][0] - 0f64.min(xy).min(xz).min(xy + xz),
            rows[1][0] - 0f64.min(yz),
            rows[2][0],
        ];
        let hi = [
            rows[0][1] - 0f64.max(xy).max(xz).max(xy + xz),
            rows[1][1] - 0f64.max(yz),
            rows[2][1],
        ];
        if let Some(problem) = super::tilted_box_problem(lo, hi, [xy, xz, yz]) {
            return Err(ctx.malformed(item_at, format!("malformed BOX BOUNDS: {problem}")));
        }
        SimulationBox::lammps(lo, hi, [xy, xz, yz])
    } else {
        SimulationBox::orthogonal(
            [rows[0][0], rows[1][0], rows[2][0]],
            [rows[0][1], rows[1][1], rows[2][1]],
        )
    };
    if flags.len() == 3 {
        b.periodic = Some([flags[0] == b"pp", flags[1] == b"pp", flags[2] == b"pp"]);
    }
    Ok(b)
}

/// Refuses `dump atom`'s `id type xs ys zs`, assumed for an `ITEM: ATOMS` line that names
/// no columns (very old LAMMPS, SPPARKS), where the atom lines (from offset `from`) hold
/// another count of columns, or more than a few of the first thousand lie far outside
/// the box (below −0.5 or above 1.5): unscaled coordinates taken for scaled ones would be
/// multiplied by the box silently, as the binary reader refuses them too.
fn check_assumed_columns(ctx: &Ctx<'_>, data: &[u8], from: usize) -> Result<(), ReadError> {
    const SAMPLE: usize = 1000;
    const FAR_ALLOWED: usize = 3;
    let mut lines = Cursor::new(data, from);
    let (mut seen, mut far, mut first_far) = (0usize, 0usize, None);
    let mend = "write the names after `ITEM: ATOMS` (`sed -i 's/^ITEM: ATOMS *$/ITEM: ATOMS id \
                type x y z/' DUMP` for unscaled positions)";
    while seen < SAMPLE {
        let Some((at, line)) = lines.next_line() else {
            break;
        };
        if line.starts_with(b"ITEM:") {
            break;
        }
        let tokens: Vec<&[u8]> = super::fields(line).collect();
        if tokens.is_empty() {
            continue;
        }
        if tokens.len() != 5 {
            return Err(ctx.malformed(
                at,
                format!(
                    "an `ITEM: ATOMS` line that names no columns (very old LAMMPS) is read as \
                     `dump atom`'s `id type xs ys zs`, but this atom line holds {} columns: {mend}",
                    tokens.len()
                ),
            ));
        }
        for (c, t) in tokens[2..].iter().enumerate() {
            let v = std::str::from_utf8(t)
                .ok()
                .and_then(|t| t.parse::<f64>().ok());
            if let Some(v) = v.filter(|v| v.is_finite() && !(-0.5..=1.5).contains(v)) {
                far += 1;
                first_far.get_or_insert((at, seen, c, v));
                break;
            }
        }
        seen += 1;
    }
    match first_far {
        Some((at, i, c, v)) if far > FAR_ALLOWED => Err(ctx.malformed(
            at,
            format!(
                "an `ITEM: ATOMS` line that names no columns (very old LAMMPS) is read as \
                 `dump atom`'s scaled `id type xs ys zs`, but {far} of the first {seen} atoms \
                 lie far outside the box (below -0.5 or above 1.5; atom {}: `{}` is {v}): the \
                 columns look unscaled; {mend}",
                i + 1,
                ["xs", "ys", "zs"][c]
            ),
        )),
        _ => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_index_built_in_segments_equals_one_built_whole() {
        let frame = |t: u64| {
            format!(
                "ITEM: TIME\n{t}.5\nITEM: TIMESTEP\n{t}\nITEM: NUMBER OF ATOMS\n2\n\
                 ITEM: BOX BOUNDS pp pp pp\n0 1\n0 1\n0 1\nITEM: ATOMS id type x y z\n\
                 1 1 0 0 0\n2 1 0.5 0.5 0.5\n"
            )
        };
        let text = format!(
            "ITEM: UNITS\nmetal\n{}{}{}",
            frame(0),
            frame(100),
            frame(200)
        );
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("d.lammpstrj");
        std::fs::write(&path, &text).unwrap();
        let ctx = Ctx {
            path: &path,
            data: text.as_bytes(),
        };
        // `ITEM: TIMESTEP` and the lines before it straddle a segment's end in every
        // way; the bar moves a segment at a time.
        let whole = super::super::check_segmented_index(&ctx, 0, Index::build);
        assert_eq!(whole.len(), 3);
        assert_eq!(whole.timestep(2), Some(200));
        assert_eq!(whole.first_units().as_deref(), Some("metal"));
        // A file that is not the one indexed (another size) is an error, not a guess.
        let other = dir.path().join("other");
        std::fs::write(&other, "ITEM: TIMESTEP\n0\n").unwrap();
        let other = std::fs::File::open(&other).unwrap();
        let err = Index::build(
            &ctx,
            Some(&other),
            64,
            &super::super::Reached::new(&crate::NoProgress),
        )
        .unwrap_err();
        assert!(err.to_string().contains("changed size"), "{err}");
    }
}
