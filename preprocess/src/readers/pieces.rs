//! Per-processor pieces of one dump: LAMMPS writes one file per process when the dump's
//! file name holds a `%` (`dump.%.lammpstrj` → `dump.0.lammpstrj`, `dump.1.lammpstrj`,
//! ...). Opening the name with the `%` opens every piece (text or binary), checks that
//! they hold the same frames, and reading a frame concatenates the pieces' atoms in
//! processor order, merging their species by name.

use std::path::{Path, PathBuf};

use super::{DumpFile, FrameInfo, InputFormat, ReadError, ReadOptions};
use crate::frame::{Attribute, Frame, SpeciesName};
use crate::progress::Progress;

/// The piece files of `pattern` (a path whose file name holds one `%`, standing for
/// the processor number), in processor order.
pub fn piece_paths(pattern: &Path) -> Result<Vec<PathBuf>, ReadError> {
    let io = |message: String| ReadError::Io {
        path: pattern.to_path_buf(),
        source: std::io::Error::new(std::io::ErrorKind::NotFound, message),
    };
    let name = pattern
        .file_name()
        .and_then(|n| n.to_str())
        .ok_or_else(|| io("not a file name".into()))?;
    let (prefix, suffix) = name
        .split_once('%')
        .ok_or_else(|| io("no `%` in the file name".into()))?;
    let dir = match pattern.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let mut found: Vec<(u64, PathBuf)> = std::fs::read_dir(&dir)
        .map_err(|e| ReadError::Io {
            path: dir.clone(),
            source: e,
        })?
        .filter_map(|e| {
            let e = e.ok()?;
            let n = e.file_name().into_string().ok()?;
            let digits = n.strip_prefix(prefix)?.strip_suffix(suffix)?;
            if digits.is_empty() || !digits.bytes().all(|b| b.is_ascii_digit()) {
                return None;
            }
            Some((digits.parse().ok()?, e.path()))
        })
        .collect();
    found.sort();
    if found.is_empty() {
        return Err(io(format!(
            "no files match `{name}` (`%` stands for the processor number)"
        )));
    }
    for (i, (n, _)) in found.iter().enumerate() {
        if *n != i as u64 {
            return Err(io(format!(
                "piece {i} is missing (found {}); the pieces must be numbered from 0",
                found
                    .iter()
                    .map(|(n, _)| n.to_string())
                    .collect::<Vec<_>>()
                    .join(", ")
            )));
        }
    }
    Ok(found.into_iter().map(|(_, p)| p).collect())
}

/// Opens every piece and checks that they agree on the frames. With `text_limit`, `None`
/// when the decompressed text of the gzip pieces is more than that in all.
pub(crate) fn open(
    pattern: &Path,
    format: Option<InputFormat>,
    mut text_limit: Option<u64>,
    progress: &dyn Progress,
) -> Result<Option<Vec<DumpFile>>, ReadError> {
    let mut pieces = Vec::new();
    for p in piece_paths(pattern)? {
        let Some(piece) = DumpFile::open_limited(&p, format, text_limit, progress)? else {
            return Ok(None);
        };
        if let Some(left) = text_limit.as_mut() {
            *left = left.saturating_sub(piece.text_in_memory());
        }
        pieces.push(piece);
    }
    check(pattern, &pieces)?;
    Ok(Some(pieces))
}

/// Checks that the pieces of `pattern` agree on the frames.
pub(crate) fn check(pattern: &Path, pieces: &[DumpFile]) -> Result<(), ReadError> {
    let Some(first) = pieces.first() else {
        return Err(ReadError::Io {
            path: pattern.to_path_buf(),
            source: std::io::Error::new(std::io::ErrorKind::NotFound, "no pieces"),
        });
    };
    for p in &pieces[1..] {
        // About the whole piece, not a line of it (a binary piece has none).
        let mismatch = |message: String| ReadError::Pieces {
            path: p.path().to_path_buf(),
            message,
        };
        // Pieces a run is still writing, each in turn, may hold a frame more than others:
        // the set's frames are those every piece holds ([`frame_count`]), the same
        // timesteps in each. A piece's last frame whose header is cut short (the run is
        // writing it) has no timestep to compare, or a part of one (`50` of `500`): the
        // set's frame is then cut short, left out as a single dump's is when it is not
        // the first.
        let common = p.frame_count().min(first.frame_count());
        if let Some(k) = (0..common).find(|&k| {
            p.frame_timestep(k) != first.frame_timestep(k)
                && !(k > 0 && (header_cut(p, k) || header_cut(first, k)))
        }) {
            let timestep =
                |t: Option<u64>| t.map_or("without a timestep".into(), |t| format!("timestep {t}"));
            // A piece cut short or damaged in its header reads as one without a
            // timestep: said so, with where to look.
            let this = match (p.frame_timestep(k), first.frame_timestep(k)) {
                (None, Some(_)) => format!(
                    "without a timestep that can be read (cut short or damaged? `mdlod convert \
                     {}` of the piece alone says where)",
                    p.path().display()
                ),
                (t, _) => timestep(t),
            };
            return Err(mismatch(format!(
                "frame {k} is {this}, but in {} it is {}",
                first.path().display(),
                timestep(first.frame_timestep(k))
            )));
        }
    }
    Ok(())
}

/// Whether frame `k` is the last of `piece` and cut short in its header or, for a binary
/// piece, anywhere (a run still writing it): reading its header says so
/// ([`ReadError::cut_short`]).
fn header_cut(piece: &DumpFile, k: usize) -> bool {
    k + 1 == piece.frame_count() && piece.frame_info(k).is_err_and(|e| e.cut_short())
}

/// The frames of a set: those every piece holds.
pub(crate) fn frame_count(pieces: &[DumpFile]) -> usize {
    pieces.iter().map(DumpFile::frame_count).min().unwrap_or(0)
}

/// A note on frames some pieces hold and others not yet (a run writing its pieces in
/// turn), said with the set's last frame: they are left out until every piece has them.
pub(crate) fn ahead_note(pattern: &Path, pieces: &[DumpFile]) -> Option<String> {
    let common = frame_count(pieces);
    let most = pieces.iter().map(DumpFile::frame_count).max()?;
    (most > common).then(|| {
        format!(
            "{}: {} frame{} past the last that every piece holds (a run still writing its \
             pieces?) left out until every piece has {}",
            pattern.display(),
            most - common,
            if most - common == 1 { "" } else { "s" },
            if most - common == 1 { "it" } else { "them" }
        )
    })
}

pub(crate) fn frame_info(pieces: &[DumpFile], k: usize) -> Result<FrameInfo, ReadError> {
    let mut info = pieces[0].frame_info(k)?;
    for p in &pieces[1..] {
        let n = p.frame_info(k)?.particles;
        info.particles = info.particles.checked_add(n).ok_or_else(|| {
            // Counts as the headers announce them, not yet backed by atoms.
            ReadError::Malformed {
                at: super::Location {
                    path: p.path().to_path_buf(),
                    line: 1,
                },
                message: format!(
                    "frame {k}: this piece's {n} atoms and the {} of the pieces before it \
                     are more than can be counted",
                    info.particles
                ),
            }
        })?;
    }
    Ok(info)
}

/// Reads frame `k` of every piece and concatenates them.
pub(crate) fn read_frame(
    pieces: &[DumpFile],
    k: usize,
    opts: &ReadOptions,
    progress: &dyn Progress,
) -> Result<Frame, ReadError> {
    let frames = pieces
        .iter()
        .map(|p| p.read_frame(k, opts, progress))
        .collect::<Result<Vec<_>, _>>()?;
    // The pieces of one dump share its columns: sizes in some and not others would leave
    // the particles of those without them no size of their own.
    if let (Some(with), Some(without)) = (
        frames.iter().position(|f| f.radii.is_some()),
        frames.iter().position(|f| f.radii.is_none()),
    ) {
        return Err(ReadError::Malformed {
            at: super::Location {
                path: pieces[without].path().to_path_buf(),
                line: 1,
            },
            message: format!(
                "frame {k}: this piece gives no particle sizes (no `radius` or `diameter` \
                 column) while {} does: the pieces of one run share their columns",
                pieces[with].path().display()
            ),
        });
    }
    // Species: the union by name; numeric LAMMPS types sorted numerically, others in
    // order of first appearance.
    // (Found by name through a map: a column of categories may give thousands.)
    let mut species: Vec<SpeciesName> = Vec::new();
    let mut index: std::collections::HashMap<String, usize> = std::collections::HashMap::new();
    for f in &frames {
        for i in crate::species::merge_order(&f.species, &f.species_index) {
            let s = &f.species[i];
            match index.get(&s.name) {
                Some(&k) => crate::species::merge_sizes(&mut species[k], s),
                None => {
                    index.insert(s.name.clone(), species.len());
                    species.push(s.clone());
                }
            }
        }
        if species.len() > 1 << 16 {
            break;
        }
    }
    if species.iter().all(|s| s.numeric_type) {
        species.sort_by_key(|s| s.name.parse::<i64>().unwrap_or(i64::MAX));
        crate::species::slots_as_whole(&mut species);
    } else {
        crate::species::not_all_numbers(&mut species);
    }
    if species.len() > 1 << 16 {
        return Err(ReadError::TooManySpecies {
            at: super::Location {
                path: pieces[0].path().to_path_buf(),
                line: 1,
            },
        });
    }
    let index: std::collections::HashMap<&str, usize> = species
        .iter()
        .enumerate()
        .map(|(k, s)| (s.name.as_str(), k))
        .collect();
    let total: usize = frames.iter().map(Frame::len).sum();
    let mut out = Frame {
        positions: Vec::with_capacity(total),
        species_index: Vec::with_capacity(total),
        species: species.clone(),
        attribute: None,
        ..frames[0].clone_header()
    };
    let mut attribute: Option<Attribute> = frames[0].attribute.as_ref().map(|a| Attribute {
        name: a.name.clone(),
        values: Vec::with_capacity(total),
    });
    for f in &frames {
        let remap: Vec<u16> = f
            .species
            .iter()
            .map(|s| index.get(s.name.as_str()).copied().unwrap_or(0) as u16)
            .collect();
        out.positions.extend_from_slice(&f.positions);
        out.species_index
            .extend(f.species_index.iter().map(|&i| remap[usize::from(i)]));
        if let (Some(a), Some(fa)) = (attribute.as_mut(), f.attribute.as_ref()) {
            a.values.extend_from_slice(&fa.values);
        }
    }
    out.attribute = attribute;
    // Per-particle sizes where every piece gives them (the pieces of one dump share its
    // columns).
    if frames.iter().all(|f| f.radii.is_some()) {
        out.radii = Some(
            frames
                .iter()
                .flat_map(|f| f.radii.iter().flatten().copied())
                .collect(),
        );
    }
    Ok(out)
}

/// One processor's piece of a `%` set given alone ([`lone_piece`]): only its particles
/// are read.
#[derive(Clone, Debug, PartialEq)]
pub struct LonePiece {
    /// The set it is a piece of (`dump.100.%.bin`).
    pub set: PathBuf,
    name: String,
    /// A piece of the set that starts at the same timestep.
    sibling: String,
    pieces: usize,
    timestep: u64,
}

impl LonePiece {
    /// The note naming `give` (the set, or the pattern of every timestep's sets a batch
    /// over a file per timestep needs) as what to give instead.
    pub fn note(&self, give: &Path) -> String {
        format!(
            "{} may be one processor's piece of a `%` set: {} starts at timestep {} too ({} \
             pieces); if it is, only this piece's particles were read: give '{}' (quoted) \
             for every processor's (replicas started alike read the same)",
            self.name,
            self.sibling,
            self.timestep,
            self.pieces,
            give.display()
        )
    }
}

/// Whether `path`, one file whose first frame is at `timestep`, looks like one
/// processor's piece of a `%` set: with another number in place of its last run of
/// digits it names a set ([`piece_paths`]: numbered from 0), one of whose other pieces
/// starts at the same timestep (a series of timesteps does not), holding other atoms
/// where both are small enough to compare their ids (variants of one run, another
/// column or a replica, hold the same). `given` are the run's inputs: a sibling among
/// them is the batch's own business. At most three siblings are opened.
pub fn lone_piece(path: &Path, timestep: Option<u64>, given: &[PathBuf]) -> Option<LonePiece> {
    let timestep = timestep?;
    let name = path.file_name()?.to_str()?;
    let bytes = name.as_bytes();
    let end = bytes.iter().rposition(u8::is_ascii_digit)? + 1;
    let start = bytes[..end]
        .iter()
        .rposition(|b| !b.is_ascii_digit())
        .map_or(0, |i| i + 1);
    let set = path.with_file_name(format!("{}%{}", &name[..start], &name[end..]));
    let pieces = piece_paths(&set).ok()?;
    let siblings: Vec<&PathBuf> = pieces
        .iter()
        .filter(|p| p.file_name() != path.file_name())
        .collect();
    let canonical = |p: &Path| std::fs::canonicalize(p).ok();
    let given: Vec<PathBuf> = given.iter().filter_map(|g| canonical(g)).collect();
    if siblings.is_empty()
        || siblings
            .iter()
            .any(|p| canonical(p).is_some_and(|p| given.contains(&p)))
    {
        return None;
    }
    let (sibling, dump) = siblings.iter().take(3).find_map(|p| {
        let d = DumpFile::open(p).ok()?;
        (d.frame_timestep(0) == Some(timestep)).then_some((*p, d))
    })?;
    // Pieces hold different atoms, variants of one run the same.
    const ID_CHECK_BYTES: u64 = 64 << 20;
    let small = |p: &Path| std::fs::metadata(p).is_ok_and(|m| m.len() <= ID_CHECK_BYTES);
    if small(path) && small(sibling) {
        let ids = |d: &DumpFile| -> Option<std::collections::HashSet<u32>> {
            let opts = ReadOptions {
                attribute: Some("id".into()),
                ..Default::default()
            };
            let f = d.read_frame(0, &opts, &crate::progress::NoProgress).ok()?;
            Some(f.attribute?.values.iter().map(|v| v.to_bits()).collect())
        };
        let mine = DumpFile::open(path).ok().and_then(|d| ids(&d));
        if let (Some(mine), Some(theirs)) = (mine, ids(&dump)) {
            if mine.intersection(&theirs).count() * 2 > mine.len().min(theirs.len()) {
                return None;
            }
        }
    }
    Some(LonePiece {
        set,
        name: name.to_string(),
        sibling: sibling.file_name()?.to_string_lossy().into_owned(),
        pieces: pieces.len(),
        timestep,
    })
}
